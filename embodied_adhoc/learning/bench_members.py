"""The grid arenas' learned benchmark teammates: a trained recurrent agent (``ppo-generalist`` or ``liam`` weights)
in one teammate seat beside a thesis team in the others, as a grid team plug-in
(:mod:`~embodied_adhoc.teammates.grid_plugins`).

The learned seats (``seats``, default seat 1) play the agent; every other seat, the ego's included when the
``original`` agent asks for it, plays the thesis team ``others`` (``teammates.grid_members.arena_teams``). A whole
team of agents trained beside scripted teams rarely finishes the task (they wait for teammates who do the work), so
the learned agent is one teammate among scripted ones.

Each learned seat holds its own :class:`~embodied_adhoc.learning.generalist.GeneralistAgent` (its own GRU state),
fed the seat's egocentric observation of the state (``domains.grid_rules_obs``, the window the agent was trained
on, seen from that seat) and the seat's previous action, and acting by a draw from the policy with the generator
the env hands the team. A seat's memory starts afresh whenever that generator changes, which happens at every
seeded reset (the env's ``np_random``) and with every episode of the ``original`` agent (its own generator), so
the same seed gives the same episode. A member's weights path is relative to the package's data
(``paths.assets_dir``).

A plug-in spec ``embodied_adhoc.learning.bench_members:<domain>/<member>`` names a learned member of the population
(``teammates.populations``).
"""

from __future__ import annotations

import numpy as np

from embodied_adhoc.domains.grid_rules_obs import egocentric_observation
from embodied_adhoc.domains.grid_rules_team import team_actions
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.learning.generalist import generalist_agent
from embodied_adhoc.paths import assets_dir

__all__ = ["KINDS", "LearnedTeam", "LearnedTeamFactory"]

KINDS = ("ppo-generalist", "liam")


class LearnedTeam:
    """The agent of ``weights`` (of ``kind``) in ``seats``, the thesis team ``others`` (a ``TeamSpec``) in the
    other seats (see the module docstring)."""

    def __init__(self, rules, weights, kind: str, others, seats=(1,)) -> None:
        if kind not in KINDS:
            raise ConfigError(f"learned benchmark teammate: kind {kind!r}; choose from {', '.join(KINDS)}")
        n = rules.config.n_agents
        if not seats or any(not 1 <= int(i) < n for i in seats):
            raise ConfigError(
                f"learned benchmark teammate: seats {list(seats)}; teammate seats are 1..{n - 1}"
            )
        self.rules, self.weights, self.kind = rules, weights, kind
        self.others, self.learned_seats = others, frozenset(int(i) for i in seats)
        probe = self._agent()  # checks the weights' domain and grid now, before any episode
        self.view = int(probe.model.config.view)
        self._rng: np.random.Generator | None = None
        self._seats: dict[int, object] = {}
        self._previous: dict[int, int] = {}

    def _agent(self):
        config = self.rules.config
        return generalist_agent(config.domain, self.weights, config, name=self.kind, kind=self.kind)

    def actions(self, state, task, rng: np.random.Generator, members) -> np.ndarray:
        if rng is not self._rng:  # a new episode
            self._rng, self._seats, self._previous = rng, {}, {}
        chosen = []
        for i in members:
            if i not in self.learned_seats:
                chosen.append(int(team_actions(self.rules, state, task, self.others, rng, [i])[0]))
                continue
            observation = egocentric_observation(self.rules, state, int(i), self.view)
            agent = self._seats.get(i)
            if agent is None:
                agent = self._seats[i] = self._agent()
                agent.reset(rng)
                agent.start(observation)
            else:
                agent.observe(self._previous[i], observation)
            self._previous[i] = int(agent.act())
            chosen.append(self._previous[i])
        return np.array(chosen, dtype=np.int64)


class LearnedTeamFactory:
    """``factory(rules)`` of one learned member: ``params`` ``weights`` (relative to the package's data), ``kind``,
    ``others`` (a thesis team's name) and ``seats``."""

    def __init__(self, name: str, params: dict) -> None:
        self.name, self.params = name, dict(params)
        path = assets_dir() / str(self.params.get("weights", ""))
        if not path.is_file():
            raise ConfigError(f"learned benchmark teammate {name}: no weights file {path}")
        self.path = path

    def __call__(self, rules) -> LearnedTeam:
        from embodied_adhoc.teammates.grid_members import arena_teams

        teams, others = arena_teams(rules.config.domain), self.params.get("others")
        if others not in teams:
            raise ConfigError(
                f"learned benchmark teammate {self.name}: others {others!r}; choose from {', '.join(teams)}"
            )
        kind = str(self.params.get("kind", "ppo-generalist"))
        return LearnedTeam(rules, self.path, kind, teams[others], tuple(self.params.get("seats", (1,))))

    def __repr__(self) -> str:
        return f"LearnedTeamFactory({self.name!r})"


def __getattr__(name: str) -> LearnedTeamFactory:
    """``embodied_adhoc.learning.bench_members:<domain>/<member>``: the factory of that learned member."""
    from embodied_adhoc.teammates.populations import find_member

    domain, _, member = name.partition("/")
    spec = find_member(domain, member) if member else None
    if spec is None or spec.params.get("family") != "learned":
        raise AttributeError(name)
    return LearnedTeamFactory(spec.name, spec.params)
