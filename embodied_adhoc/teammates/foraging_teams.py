"""Level-based foraging teams tau0, tau1, tau2 (thesis section 6.2.2) as :class:`TeamSpec` parameters."""

from __future__ import annotations

from embodied_adhoc.domains.grid_rules_team import TeamSpec

FORAGING_TEAMS: dict[str, TeamSpec] = {
    "tau0": TeamSpec(
        "tau0",
        "closest apple, greedy moves ignoring obstacles",
        target="closest",
        slot="closest",
        goal="slot",
        navigation="greedy",
    ),
    "tau1": TeamSpec(
        "tau1",
        "highest-level apple, shortest path around obstacles, teammates assumed alike",
        target="highest_level",
        slot="assigned",
        goal="slot",
        navigation="path",
    ),
    "tau2": TeamSpec(
        "tau2",
        "apple closest to the team, joins its ray on a circle of radius 2, then closes in",
        target="team_closest",
        slot="assigned",
        goal="ring",
        navigation="path",
    ),
}
