"""The trial domains: one plug-in per domain of ``embodied-adhoc trials`` (what an episode is, its agents, its
options and tables), registered by name in :mod:`embodied_adhoc.experiments.registry`. The modules one level up
are the infrastructure every domain shares (runner, executors, storage, seeding, statistics, tables, plots, the
policy cache, run identity)."""
