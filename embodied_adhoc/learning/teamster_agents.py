"""The seven chapter-4 ad hoc agents on pursuit (thesis section 4.1.2), built by name.

=====================  ===============================  ==========================================
name                   environment model                team library (plus one online team model)
=====================  ===============================  ==========================================
``teamster``           learned (Eq. 4.3 + reward net)   learned (Eq. 4.1), frozen online models
``plastic-model``      exact rules                      exact team models of the teams met
``learns-team``        exact rules                      learned
``learns-environment`` learned                          exact
``plastic-policy``     none: one DQN per team (Table 4.3), chosen by the belief over learned team models
``random``             uniform actions
``original``           the current team's own policy in the ad hoc seat
=====================  ===============================  ==========================================

plus the scripted types ``teammate-aware``, ``greedy`` and ``probabilistic-destinations`` in the ad hoc seat
(the rows of the PLASTIC reference). Every model-based agent plans with the same batched UCT (Table 4.1) and
tracks the team with the same belief update (Algorithm 2).
"""

from __future__ import annotations

import numpy as np

from embodied_adhoc.decision.agents.teamwork import (
    CHAPTER4_AGENTS,
    MODEL_BASED,
    ModelBasedAgent,
    OriginalTeammate,
    RandomAgent,
    TeamTracking,
)
from embodied_adhoc.decision.uct import UctConfig
from embodied_adhoc.domains.pursuit4 import N_ACTIONS, ExactEnvironment, ExactTeam, Pursuit4
from embodied_adhoc.errors import ConfigError
from embodied_adhoc.learning.dqn import Dqn, DqnConfig
from embodied_adhoc.learning.teamster import LearnedEnvironment, LearnedTeam
from embodied_adhoc.learning.teamster_navigation import dqn_config, features_for

AGENTS = CHAPTER4_AGENTS  # its last three are the teams' own policies (TEAMS) in the ad hoc seat
TABLE_4_1 = {"pursuit": (100, 5), "ntu": (100, 10), "isr": (300, 50), "pentagon": (300, 25)}
"""Table 4.1: UCT (iterations, maximum rollout depth) per domain (exploration sqrt(2), discount 0.95)."""


class PlasticPolicy(TeamTracking):
    """PLASTIC-Policy: a library of (learned team model, DQN) pairs; the DQN of the most likely team acts.
    While playing a team it trains a new team model and a new DQN (epsilon-greedy when that DQN acts)."""

    def __init__(
        self,
        world: Pursuit4,
        rng: np.random.Generator,
        horizon: int,
        eta: float = 0.1,
        rule: str = "plastic",
        config: DqnConfig | None = None,
    ) -> None:
        self.name, self.world, self.rng, self.horizon = "plastic-policy", world, rng, horizon
        self.features = features_for(world)
        self.eta, self.rule, self.config = eta, rule, config
        self.library: list[tuple[LearnedTeam, Dqn]] = []
        self.online = LearnedTeam(world, rng, features=self.features)
        self.dqn = self._new_dqn()

    def _new_dqn(self) -> Dqn:
        return Dqn(self.features.agent_width, N_ACTIONS, self.rng, self.config, decay_steps=self.horizon)

    @property
    def pairs(self) -> list[tuple[LearnedTeam, Dqn]]:
        return self.library + [(self.online, self.dqn)]

    @property
    def models(self) -> list:
        return [team for team, _ in self.pairs]

    def start_team(self, rng: np.random.Generator) -> None:
        self.rng = rng
        self.online.reset()
        self.dqn = self._new_dqn()
        self.belief = self.uniform_belief()

    def act(self, state: np.ndarray) -> int:
        chosen = int(np.argmax(self.belief))
        dqn = self.pairs[chosen][1]
        explore = self.learning and dqn is self.dqn
        return dqn.act(self.features.agent(np.asarray(state)[None])[0], explore)

    def observe(self, state, joint_action, reward, next_state, terminal) -> None:
        state, joint_action = np.asarray(state), np.asarray(joint_action)
        self.track(state, joint_action[1:])
        if self.learning:
            self.online.update(state, joint_action[1:])
            x = self.features.agent(state[None])[0]
            y = self.features.agent(np.asarray(next_state)[None])[0]
            self.dqn.update(x, int(joint_action[0]), float(reward), y, bool(terminal))

    def finish_team(self, team: str) -> None:
        self.library.append((self.online.frozen_copy(name=team), self.dqn))
        self.online = LearnedTeam(self.world, self.rng, features=self.features)


def build_agent(
    name: str,
    world: Pursuit4,
    rng: np.random.Generator,
    horizon: int,
    uct: UctConfig | None = None,
    eta: float = 0.1,
    rule: str = "plastic",
):
    """A fresh agent ``name`` (see the module table) for ``world`` (pursuit or a navigation map: its teams,
    exact models and network encodings); ``horizon`` is the interaction length per team (the DQN's epsilon
    decays over it); ``uct`` defaults to the world's row of Table 4.1."""
    exact = {team: ExactTeam(world, team) for team in world.teams}
    if uct is None:  # Table 4.1's row of the world (pursuit's for a map file of one's own)
        iterations, depth = TABLE_4_1.get(getattr(world, "name", "pursuit"), TABLE_4_1["pursuit"])
        uct = UctConfig(iterations=iterations, depth=depth)
    if name in MODEL_BASED:
        learned_env = name in ("teamster", "learns-environment")
        features = features_for(world)
        environment = (
            LearnedEnvironment(world, rng, features=features) if learned_env else ExactEnvironment(world)
        )
        exact_library = exact if name in ("plastic-model", "learns-environment") else None
        return ModelBasedAgent(
            name, environment, LearnedTeam(world, rng, features=features), exact_library, uct, eta, rule
        )
    if name == "plastic-policy":
        return PlasticPolicy(world, rng, horizon, eta, rule, dqn_config(world, horizon))
    if name == "random":
        return RandomAgent(N_ACTIONS)
    policies = {team: model.seat for team, model in exact.items()}
    if name == "original":
        return OriginalTeammate(policies)
    if name in world.teams:
        return OriginalTeammate(policies, name=name, fixed=name)
    from embodied_adhoc.plugins import names_plugin

    if names_plugin("agent", name):
        return plugin_agent(name, world, rng, horizon)
    raise ConfigError(f"agent {name!r}: choose from {', '.join(AGENTS[:7] + tuple(world.teams))}")


TEAMWORK_METHODS = ("start_team", "act", "observe", "set_evaluation", "finish_team")


def plugin_agent(spec: str, world: Pursuit4, rng: np.random.Generator, horizon: int):
    """A user's chapter-4 agent: ``factory(world, rng=rng, horizon=horizon)`` (the ``embodied_adhoc.plugins`` spec
    ``spec``) returning a :class:`~embodied_adhoc.decision.agents.teamwork.TeamworkAgent`; refused with the
    methods it lacks."""
    from embodied_adhoc.plugins import resolve

    agent = resolve("agent", spec, builtin=AGENTS, flag="--agents").factory(world, rng=rng, horizon=horizon)
    missing = [m for m in TEAMWORK_METHODS if not callable(getattr(agent, m, None))]
    if missing or not isinstance(getattr(agent, "name", None), str):
        lacks = [f"{m}()" for m in missing] + (
            [] if isinstance(getattr(agent, "name", None), str) else ["name"]
        )
        raise ConfigError(
            f"agent {spec!r}: {type(agent).__name__} does not meet the chapter-4 TeamworkAgent protocol "
            f"(decision.agents.teamwork): it lacks {', '.join(lacks)}"
        )
    return agent
