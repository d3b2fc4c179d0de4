"""Scripted teammate types with their labels: the grid domains' teams (``foraging_teams``, ``pursuit_teams``:
:class:`~embodied_adhoc.domains.grid_rules_team.TeamSpec` instances). This layer sits above ``domains/`` (it
parameterises the domains' rules) and below ``envs/``; the lab's human is one of the lab's rules, so it lives in
``domains/lab_human.py``. Allowed import directions: ``tests/test_layers.py``."""
