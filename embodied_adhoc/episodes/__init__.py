"""The episode layer: the one episode loop (``loop``), the frame sources of the simulated worlds (``frames``),
the recording observers (``recording``), the per-domain presenters (``presenters``) and the recorded-run driver
(``recorded``) shared by ``run``, ``live`` and the trial runner.

It sits above ``envs/`` and ``record/`` (which never import it) and below ``experiments/``; where it sits and
what it may import: docs/layout.md."""
