"""The held-out benchmark: teammate populations with train, validation and held-out splits, best-response bounds,
normalised scores and one ``evaluate`` over any agents (``docs/benchmark.md``).

* :mod:`~embodied_adhoc.teammates.populations` (below the learners, which train on its train split): the members
  (``TeammateSpec``) per domain and split, versioned, and (``teammates.lab_members``, ``teammates.chapter5_members``)
  the policies they name;
* :mod:`~embodied_adhoc.bench.bounds`: random-ego and exact best-response returns per member, cached;
* :mod:`~embodied_adhoc.bench.scores`: IQM, mean, stratified bootstrap, probability of improvement, profiles;
* :mod:`~embodied_adhoc.bench.evaluate`: the runs (through the trial runner, resumable) and the summary.
"""
