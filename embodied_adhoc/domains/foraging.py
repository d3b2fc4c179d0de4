"""Level-based foraging (thesis section 6.2.1, Christianos et al. 2020) on the shared grid rules."""

from __future__ import annotations

from embodied_adhoc.domains.grid_rules import GridConfig, Task, rotation_tasks


def foraging_config(**overrides) -> GridConfig:
    """The thesis's LBF setting (5x5, 4 foragers, one apple) with any :class:`GridConfig` field overridden."""
    return GridConfig(**{"domain": "foraging", **overrides})


def foraging_tasks(n_agents: int = 4) -> tuple[Task, ...]:
    """The four N/S/W/E forage-position tasks and their rotations (section 6.2.2)."""
    return rotation_tasks(n_agents)
