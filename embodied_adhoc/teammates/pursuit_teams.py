"""Predator-prey teams (thesis sections 6.2.2 and 5.2.5) as :class:`TeamSpec` parameters.

tau0-tau2 are the four-predator teams of chapter 6; ``greedy`` and ``aware`` are the two teammates of the
two-predator variant (section 5.2.5, Fig. 7.12): the greedy one heads for its closest capture position along a
shortest path that ignores the ad hoc agent, the teammate-aware one runs A* around it and takes the capture
position that minimises the pair's summed distance.

Three pursuits, three "greedy" and "teammate-aware" teammates. The thesis defines its pursuit teammates once per
chapter, each for that chapter's rules, and the project keeps each definition where its rules are, because each
is exact for its own world and model (so none is a copy of another):

* here, the grid arenas (chapters 6-7, ``trials foraging|pursuit``, ``PursuitPair*-v0``): walls and collisions,
  a greedy walker that moves along the axis of the larger gap four times in five (``grid_rules_plan.navigate``),
  the aware one on shortest paths around every agent;
* :mod:`embodied_adhoc.domains.chapter5.pursuit` (section 5.2.5, the pursuit POMDP that HOTSPOT and ATPO plan
  with, ``--rules pomdp``): two predators on a torus without collisions, deterministic: greedy steps columns
  first, then rows; aware takes a breadth-first path around the agent only;
* :mod:`embodied_adhoc.domains.pursuit4` (section 4.1.1, TEAMSTER): four predators moved one at a time in a
  random order; ``greedy`` picks the nearest free cell around the prey and moves uniformly among the moves that
  shorten the distance, ``teammate-aware`` assigns the four cells by the least total distance: exact action
  distributions, which the team belief scores.

The arena's pair teams against the POMDP's are the model mismatch of ``--rules grid`` (docs/arenas.md).
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
