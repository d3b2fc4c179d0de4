"""The grid arenas' benchmark teams (level-based foraging, predator-prey): grid team plug-ins
(:mod:`~embodied_adhoc.teammates.grid_plugins`, ``factory(rules)``) built from a member's parameters (``family``):

* ``named``: a thesis team of the arena (``team``: tau0-tau2), the scripted :class:`TeamSpec` itself;
* ``spec``: a scripted team of other parameters (``target``, ``slot``, ``goal``, ``navigation`` of
  :class:`TeamSpec`): a target rule or a way of moving the thesis's teams do not combine;
* ``seats``: teammate ``i`` plays the thesis team ``teams[i % len(teams)]`` (one team: an ordinary team; several:
  a mixed team, seat 0's type first), each member's action replaced by a uniformly drawn one with probability
  ``noise``: the held-out teams of the ATLPO split (``learning.atlpo_heldout``), draw for draw;
* ``sticky``: the thesis team ``team``, each member repeating its own previous action instead with probability
  ``p``.

A sticky member remembers its previous actions within an episode; it starts afresh whenever the generator it is
handed changes, which happens at every seeded reset (the env's ``np_random``) and with every episode of the
``original`` agent (its own generator). Every draw comes from that generator, so the same seed gives the same
episode. The learned teammates (recurrent PPO agents in the teammate seats) are torch code and live in
:mod:`embodied_adhoc.learning.bench_members`. A plug-in spec ``embodied_adhoc.teammates.grid_members:<domain>/<member>``
names a scripted member.
"""

from __future__ import annotations

import numpy as np

from embodied_adhoc.domains.grid_rules_team import TeamSpec, team_actions
from embodied_adhoc.errors import ConfigError

__all__ = ["FAMILIES", "GridMemberFactory", "SeatTeam", "StickyTeam"]

FAMILIES = ("named", "spec", "seats", "sticky")
N_ACTIONS = 5


def arena_teams(domain: str) -> dict[str, TeamSpec]:
    """The thesis teams of ``domain`` (foraging or pursuit) by name."""
    if domain == "foraging":
        from embodied_adhoc.teammates.foraging_teams import FORAGING_TEAMS

        return FORAGING_TEAMS
    if domain == "pursuit":
        from embodied_adhoc.teammates.pursuit_teams import PURSUIT_TEAMS

        return PURSUIT_TEAMS
    raise ConfigError(f"grid benchmark team: domain {domain!r} is not a grid arena (foraging, pursuit)")


class SeatTeam:
    """Seat ``i`` plays ``specs[i % len(specs)]``; with ``noise`` each listed member's action is replaced by a
    uniform one with that probability (the member's plan, then the replacement actions, then the coins: drawn
    every call, so the generator's use does not depend on the outcome)."""

    def __init__(self, rules, specs: tuple[TeamSpec, ...], noise: float = 0.0) -> None:
        if not 0.0 <= noise <= 1.0:
            raise ConfigError(f"grid benchmark team: noise={noise}, a probability in [0, 1]")
        self.rules, self.specs, self.noise = rules, tuple(specs), float(noise)

    def actions(self, state, task, rng: np.random.Generator, members) -> np.ndarray:
        members = list(members)
        planned = np.array(
            [
                team_actions(self.rules, state, task, self.specs[i % len(self.specs)], rng, [i])[0]
                for i in members
            ],
            dtype=np.int64,
        )
        replaced = rng.integers(N_ACTIONS, size=len(members))
        return np.where(rng.random(len(members)) < self.noise, replaced, planned)


class StickyTeam:
    """The thesis team ``spec``; each member repeats its own previous action of the episode with probability ``p``
    (the plan and the coin drawn every call; the first step has no previous action)."""

    def __init__(self, rules, spec: TeamSpec, p: float) -> None:
        if not 0.0 <= p <= 1.0:
            raise ConfigError(f"grid benchmark team: p={p}, a probability in [0, 1]")
        self.rules, self.spec, self.p = rules, spec, float(p)
        self._rng: np.random.Generator | None = None
        self._previous: dict[int, int] = {}

    def actions(self, state, task, rng: np.random.Generator, members) -> np.ndarray:
        if rng is not self._rng:  # a new episode (see the module docstring)
            self._rng, self._previous = rng, {}
        members = list(members)
        planned = team_actions(self.rules, state, task, self.spec, rng, members)
        coins = rng.random(len(members))
        chosen = np.array(
            [
                self._previous[i] if i in self._previous and coin < self.p else int(action)
                for i, action, coin in zip(members, planned, coins, strict=True)
            ],
            dtype=np.int64,
        )
        self._previous.update(zip(members, chosen.tolist(), strict=True))
        return chosen


class GridMemberFactory:
    """``factory(rules)`` of one scripted member (the grid team plug-in interface)."""

    def __init__(self, name: str, params: dict) -> None:
        self.name, self.params = name, dict(params)
        if self.params.get("family") not in FAMILIES:
            raise ConfigError(
                f"grid benchmark team {name}: family {self.params.get('family')!r}; choose from "
                f"{', '.join(FAMILIES)}"
            )

    def _team(self, teams: dict, name: str) -> TeamSpec:
        if name not in teams:
            raise ConfigError(
                f"grid benchmark team {self.name}: team {name!r}; choose from {', '.join(teams)}"
            )
        return teams[name]

    def __call__(self, rules):
        params, teams = self.params, arena_teams(rules.config.domain)
        family = params["family"]
        if family == "named":
            return self._team(teams, params["team"])
        if family == "spec":
            fields = {k: params[k] for k in ("target", "slot", "goal", "navigation")}
            return TeamSpec(self.name, f"benchmark team {self.name}", **fields)
        if family == "seats":
            specs = tuple(self._team(teams, name) for name in params["teams"])
            return SeatTeam(rules, specs, float(params.get("noise", 0.0)))
        return StickyTeam(rules, self._team(teams, params["team"]), float(params["p"]))

    def __repr__(self) -> str:
        return f"GridMemberFactory({self.name!r})"


def __getattr__(name: str) -> GridMemberFactory:
    """``embodied_adhoc.teammates.grid_members:<domain>/<member>``: the factory of that scripted member."""
    from embodied_adhoc.teammates.populations import find_member

    domain, _, member = name.partition("/")
    spec = find_member(domain, member) if member else None
    if spec is None or spec.params.get("family") not in FAMILIES:
        raise AttributeError(name)
    return GridMemberFactory(spec.name, spec.params)
