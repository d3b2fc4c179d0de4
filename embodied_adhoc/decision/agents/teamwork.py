"""Chapter-4 ad hoc agents over fully observed states with the teammates' actions visible (Algorithm 1).

The chapter-4 setting extends the project's :class:`~embodied_adhoc.decision.agents.base.Agent` protocol: the
agent is given the state ``X_t`` (an integer array) when it acts, and after the step it observes the
teammates' actions ``A_t^{-alpha}``, the reward ``R_{t+1}`` and ``X_{t+1}`` (:class:`TeamworkAgent`). One
interaction with a team spans many episodes: :meth:`TeamworkAgent.start_team` begins it (Algorithm 1, lines
1-4), ``act``/``observe`` are lines 6-12.

Models are duck-typed so that this module stays free of torch and of any domain:

* a *team model* has ``probs(states (B, S)) -> (B, N, A)``, the teammates' individual action distributions
  ``pi^n(a | x)`` (Eq. 4.2's factors); a learnable one also ``update(state, teammate_actions)`` and ``reset()``;
* an *environment model* has ``step(states, joint_actions (B, N + 1), rng) -> (next, reward, terminal)``; a
  learnable one also ``update(state, joint_action, reward, next_state, terminal)``.

:class:`ModelBasedAgent` is TEAMSTER, PLASTIC-Model, Learns Team and Learns Environment: they differ only in
which of those models are exact and which are learned (built in ``learning/teamster_agents.py``).
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from embodied_adhoc.decision.agents.base import AgentBase
from embodied_adhoc.decision.uct import BatchedUct, UctConfig, update_team_belief

MODEL_BASED = ("teamster", "plastic-model", "learns-team", "learns-environment")
CHAPTER4_AGENTS = MODEL_BASED + (
    "plastic-policy",
    "random",
    "original",
    "teammate-aware",
    "greedy",
    "probabilistic-destinations",
)
"""The chapter-4 agents by name (built in ``learning/teamster_agents.py``); the last three are scripted team
policies in the ad hoc seat."""


class TeamworkAgent(Protocol):
    name: str

    def start_team(self, rng: np.random.Generator) -> None:
        """Begin the interaction with a (possibly new) team: a fresh online team model, a uniform belief."""

    def act(self, state: np.ndarray) -> int:
        """The ad hoc agent's action in the observed state."""

    def observe(
        self,
        state: np.ndarray,
        joint_action: np.ndarray,
        reward: float,
        next_state: np.ndarray,
        terminal: bool,
    ) -> None:
        """The step's outcome: all agents' actions (the ad hoc agent's first), reward and next state."""

    def set_evaluation(self, evaluating: bool) -> None:
        """Start (True) or end (False) an evaluation: learning paused and the team belief restarted uniform,
        then learning resumed and the interaction's belief restored (section 4.1.4, steps 3 and 5)."""

    def finish_team(self, team: str) -> None:
        """Store what was learned about ``team`` in the library (section 4.1.4, step 4)."""


def joint_likelihood(probs: np.ndarray, teammate_actions: np.ndarray) -> np.ndarray:
    """Eq. 4.2: ``pi(A^{-alpha} | x) = prod_n pi^n(a^n | x)`` for each model, from ``probs`` (K, N, A)."""
    picked = np.take_along_axis(probs, teammate_actions[None, :, None], axis=2)[..., 0]
    return picked.prod(axis=1)


class TeamTracking:
    """The belief over the team models ``self.models`` (library + online), shared by every agent that keeps
    one: uniform at the start of an interaction and of an evaluation, updated by Algorithm 2."""

    eta: float = 0.1
    rule: str = "plastic"
    learning: bool = True
    belief: np.ndarray = np.ones(1)
    saved_belief: np.ndarray = np.ones(1)

    @property
    def models(self) -> list:
        raise NotImplementedError

    def uniform_belief(self) -> np.ndarray:
        return np.full(len(self.models), 1.0 / len(self.models))

    def set_evaluation(self, evaluating: bool) -> None:
        self.learning = not evaluating
        if evaluating:
            self.saved_belief, self.belief = self.belief, self.uniform_belief()
        else:
            self.belief = self.saved_belief

    def track(self, state: np.ndarray, mates: np.ndarray) -> None:
        """Line 10 of Algorithm 1: score the observed teammates' actions under every model (Eq. 4.2)."""
        probs = np.stack([model.probs(state[None])[0] for model in self.models])
        self.belief = update_team_belief(self.belief, joint_likelihood(probs, mates), self.eta, self.rule)


class ModelBasedAgent(TeamTracking):
    """Algorithm 1: UCT over an environment model with the most likely team model of the library (augmented
    with the team model learned online), the belief updated by Algorithm 2."""

    def __init__(
        self,
        name: str,
        environment,
        online,
        exact_teams: dict | None = None,
        uct: UctConfig | None = None,
        eta: float = 0.1,
        rule: str = "plastic",
    ) -> None:
        self.name, self.environment, self.online, self.exact_teams = name, environment, online, exact_teams
        self.library: list = []
        self.planner = BatchedUct(uct or UctConfig())
        self.eta, self.rule = eta, rule
        self.rng = np.random.default_rng(0)

    @property
    def models(self) -> list:
        return self.library + [self.online]

    def start_team(self, rng: np.random.Generator) -> None:
        self.rng = rng
        self.online.reset()
        self.belief = self.uniform_belief()

    def team_model(self):
        """Line 7: the argmax of the belief (the first on ties)."""
        return self.models[int(np.argmax(self.belief))]

    def act(self, state: np.ndarray) -> int:
        team = self.team_model()
        environment = self.environment
        fused = getattr(environment, "simulator", None)  # a model may fuse the team's draws into its step
        simulate = fused(team) if fused is not None else None
        if simulate is None:

            def simulate(states, actions, rng):
                mates = sample_rows(team.probs(states), rng)
                return environment.step(states, np.concatenate([actions[:, None], mates], axis=1), rng)

        return int(self.planner.plan(np.asarray(state), simulate, self.rng))

    def observe(self, state, joint_action, reward, next_state, terminal) -> None:
        state, joint_action = np.asarray(state), np.asarray(joint_action)
        mates = joint_action[1:]
        self.track(state, mates)
        if self.learning:
            if hasattr(self.environment, "update"):
                self.environment.update(state, joint_action, reward, next_state, terminal)
            self.online.update(state, mates)

    def finish_team(self, team: str) -> None:
        """Section 4.1.4 step 4: the team joins the library, as its exact model when the designer provides
        them (PLASTIC-Model, Learns Environment), else as the frozen online model (TEAMSTER, Learns Team); the
        online model starts afresh with the next team."""
        self.library.append(
            self.exact_teams[team] if self.exact_teams is not None else self.online.frozen_copy(name=team)
        )


def sample_rows(probs: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """One draw per row of ``probs`` (..., A) by inverse CDF, one uniform each."""
    cdf = np.cumsum(probs, axis=-1)
    u = rng.random(probs.shape[:-1])[..., None] * cdf[..., -1:]
    return np.minimum((u >= cdf).sum(-1), probs.shape[-1] - 1)


class RandomAgent:
    """The lower bound of section 4.1.2: uniform actions."""

    def __init__(self, actions: int = 5, name: str = "random") -> None:
        self.name, self.actions, self.rng = name, actions, np.random.default_rng(0)

    def start_team(self, rng):
        self.rng = rng

    def act(self, state):
        return int(self.rng.integers(self.actions))

    def observe(self, *args) -> None:
        pass

    def set_evaluation(self, evaluating):
        pass

    def finish_team(self, team):
        pass


class OriginalTeammate(RandomAgent):
    """A scripted policy in the ad hoc seat (``policies[team](states) -> (B, A)`` for seat 0): ``original`` is
    re-bound to the team it plays with (:meth:`bind`); a fixed type (``fixed``) always plays that team's
    policy (the teammate-aware / greedy / probabilistic-destinations rows of the PLASTIC reference)."""

    def __init__(self, policies: dict, name: str = "original", fixed: str | None = None) -> None:
        super().__init__(name=name)
        self.policies, self.fixed = policies, fixed
        self.policy = policies[fixed] if fixed is not None else None

    def bind(self, team: str) -> None:
        if self.fixed is None:
            self.policy = self.policies[team]

    def act(self, state):
        return int(sample_rows(self.policy(np.asarray(state)[None]), self.rng)[0])


class EpisodeSeat(AgentBase):
    """A chapter-4 agent (:class:`TeamworkAgent`) in the project's one episode loop
    (:func:`embodied_adhoc.episodes.loop.run_episode_loop`), over
    :class:`~embodied_adhoc.envs.teamwork.TeamworkEnv`
    observations ``[state cells..., teammates' last actions...]``.

    It declares ``observes_raw`` (it gets those arrays) and ``observes_reward`` (Algorithm 1, line 11 learns the
    reward model from ``R_{t+1}``), and translates the loop's ``act()`` / ``observe(action, observation,
    reward=..., terminated=...)`` into ``act(X_t)`` / ``observe(X_t, (A_t, A_t^{-alpha}), R_{t+1}, X_{t+1},
    terminal)``. ``reset(rng)`` makes ``rng`` the agent's source of draws for the episode and, with
    ``evaluation=True``, starts an evaluation episode (section 4.1.4: learning paused, the team belief restarted
    uniform, so episodes are independent of each other's order); otherwise whether the agent learns is the
    caller's (``set_evaluation``). ``task_posterior`` is the team belief (library, then the online model), so the
    trial runner records team identification."""

    observes_raw = True
    observes_reward = True
    observes_state = False

    def __init__(self, agent: TeamworkAgent, n_agents: int, evaluation: bool = False) -> None:
        self.agent, self.n_agents, self.evaluation = agent, n_agents, evaluation
        self.name = agent.name
        self.state: np.ndarray | None = None

    def reset(self, rng: np.random.Generator, state=None) -> None:
        self.agent.rng = rng
        if self.evaluation:
            self.agent.set_evaluation(True)

    def start(self, observation) -> None:
        self.state = np.asarray(observation[: self.n_agents], dtype=np.int64)

    def act(self) -> int:
        return int(self.agent.act(self.state))

    def observe(
        self, action: int, observation, state=None, reward: float = 0.0, terminated: bool = False
    ) -> None:
        observation = np.asarray(observation, dtype=np.int64)
        following = observation[: self.n_agents]
        joint = np.concatenate([[action], observation[self.n_agents :]])
        self.agent.observe(self.state, joint, float(reward), following, bool(terminated))
        self.state = following

    @property
    def task_posterior(self) -> np.ndarray | None:
        belief = getattr(self.agent, "belief", None)
        return None if belief is None or not hasattr(self.agent, "models") else np.asarray(belief)
