"""Predator-prey teams (thesis sections 6.2.2 and 5.2.5) as :class:`TeamSpec` parameters.

tau0-tau2 are the four-predator teams of chapter 6; ``greedy`` and ``aware`` are the two teammates of the
two-predator variant (section 5.2.5, Fig. 7.12): the greedy one heads for its closest capture position along a
shortest path that ignores the ad hoc agent, the teammate-aware one runs A* around it and takes the capture
position that minimises the pair's summed distance.
"""

from __future__ import annotations

from embodied_adhoc.domains.grid_rules_team import TeamSpec

PURSUIT_TEAMS: dict[str, TeamSpec] = {
    "tau0": TeamSpec(
        "tau0",
        "closest prey, greedy moves ignoring obstacles",
        target="closest",
        slot="closest",
        goal="slot",
        navigation="greedy",
    ),
    "tau1": TeamSpec(
        "tau1",
        "prey closest to the team, shortest path around obstacles, teammates assumed alike",
        target="team_closest",
        slot="assigned",
        goal="slot",
        navigation="path",
    ),
    "tau2": TeamSpec(
        "tau2",
        "prey closest to the team, joins its ray on a circle of radius 2, then closes in",
        target="team_closest",
        slot="assigned",
        goal="ring",
        navigation="path",
    ),
    "greedy": TeamSpec(
        "greedy",
        "two-predator greedy teammate: closest capture position, ignores the other agent",
        target="closest",
        slot="closest",
        goal="slot",
        navigation="greedy",
    ),
    "aware": TeamSpec(
        "aware",
        "two-predator teammate-aware A*: pair-optimal positions, paths around the agent",
        target="closest",
        slot="assigned",
        goal="slot",
        navigation="path",
    ),
}
