"""Predator-prey / pursuit (thesis sections 6.2.1 and 5.2.5) on the shared grid rules."""

from __future__ import annotations

from embodied_adhoc.domains.grid_rules import GridConfig, Task, pair_tasks, rotation_tasks


def pursuit_config(**overrides) -> GridConfig:
    """The chapter-6 predator-prey setting (5x5, 4 predators, one prey, Capture action), fields overridable."""
    return GridConfig(**{"domain": "pursuit", **overrides})


def two_predator_config(**overrides) -> GridConfig:
    """Fig. 7.12 / section 5.2.5: 5x5, two predators, one prey, capture as soon as the pair is in position
    (action 4 is Stay)."""
    return GridConfig(**{"domain": "pursuit", "n_agents": 2, "interact_required": False, **overrides})


def pursuit_tasks(n_agents: int = 4, pairs: bool = False) -> tuple[Task, ...]:
    """The N/S/W/E capture tasks (section 6.2.2), or the interchangeable capture pairs of Fig. 7.12."""
    return pair_tasks() if pairs else rotation_tasks(n_agents)
