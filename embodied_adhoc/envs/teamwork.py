"""Chapter 4's fully observable teamwork worlds as a Gymnasium env: pursuit on the grid twin
(``EmbodiedAdhoc/Pursuit4Grid-v0``) and in the MuJoCo arena (``EmbodiedAdhoc/Pursuit4-v0``), with the rules of
:mod:`embodied_adhoc.domains.pursuit4` (the ones TEAMSTER and PLASTIC-Model plan with) executed by robots through
the shared waypoint controller; any other chapter-4 world object (``world=``) on the abstract backend. The
sequential-teams protocol and the ``trials pursuit4`` sweep both run their episodes in it through the one
episode loop (:mod:`embodied_adhoc.episodes.loop`).
"""

from __future__ import annotations

import gymnasium
import numpy as np

from embodied_adhoc import checks
from embodied_adhoc.decision.agents.teamwork import sample_rows
from embodied_adhoc.domains.pursuit4 import N_ACTIONS, ExactTeam, Pursuit4
from embodied_adhoc.envs import contract
from embodied_adhoc.errors import ConfigError

__all__ = ["NO_ACTION", "TeamworkEnv", "state_code"]

ACTION_MEANING = "0 up, 1 down, 2 left, 3 right, 4 stay"
NO_ACTION = N_ACTIONS  # a teammate action not seen yet (the observation right after reset)
RESET_OPTIONS = ("team", "state")
COLOURS = ((240, 140, 20), (40, 90, 220), (40, 90, 220), (40, 90, 220), (220, 40, 40))


def state_code(cells, cells_per_agent: int) -> int:
    """One integer per state (the agents' cells in base ``cells_per_agent``): the observation index the trial
    runner records."""
    return int(np.ravel_multi_index(tuple(int(c) for c in cells), (cells_per_agent,) * len(cells)))


class TeamworkEnv(gymnasium.Env):
    """Four predators and a prey on the 5 x 5 torus of thesis section 4.1.1 (or any chapter-4 world given as
    ``world``), fully observable, the teammates' actions visible.

    ## Description
    The ad hoc predator (agent 0) and three teammates of one team (``teammate-aware``, ``greedy``,
    ``probabilistic-destinations``: :class:`~embodied_adhoc.domains.pursuit4.ExactTeam`) hunt a prey that
    moves to a uniformly random neighbour. Agents move one at a time in a random order, each into its target
    cell if it is free then (:meth:`Pursuit4.step`); the prey is captured when the four predators hold the four
    cells around it. ``slip`` > 0 is the changed environment of section 4.1.4 (each predator's move fails with
    that probability).

    ``backend="mujoco"``: five robots in the grid arena
    (:class:`~embodied_adhoc.sim.pursuit_pomdp_arena.PursuitPomdpArena`
    with four predators), each step's cells driven to by the waypoint controller, a move across an edge of the
    torus executed as a teleport, no robot contacts (the rules keep agents on distinct cells). The cells are
    read back from the robots' poses, and the observation, the capture and the next step start from *those*.

    ## Action space
    ``Discrete(5)``: 0 up (row - 1), 1 down, 2 left, 3 right, 4 stay.

    ## Observation space
    ``MultiDiscrete([25] * 5 + [6] * 3)``: the flat cells ``row * 5 + col`` of the ad hoc agent, the three
    teammates and the prey (the state ``X_t``), then the teammates' actions of the last step (``A^{-alpha}``;
    5 = none yet, right after reset). Another world: its state's cells, then its teammates' actions.

    ## Rewards
    1.0 on the step of the capture, else 0.0 (another world: its own ``step`` rewards).

    ## Starting state
    Five distinct random cells that are not a capture (:meth:`Pursuit4.sample_states`); the team drawn
    uniformly from ``teams``.

    ## Episode end
    Terminated on capture; truncated by the registered ``TimeLimit`` (100 steps).

    ## Arguments
    ``gymnasium.make("EmbodiedAdhoc/Pursuit4Grid-v0", teams=None, slip=0.0, backend="abstract",
    render_mode=None, physics=None, world=None)``; ``teams``: the team names drawn from (default the world's);
    ``world``: a chapter-4 world object (``teams``, ``cells``, ``sample_states``, ``step``, ``team_policy``;
    default ``Pursuit4(5, slip)``; abstract backend only);
    ``reset(options={"team": name, "state": [5 cells]})`` imposes either.

    ## Info
    ``state`` (the five cells), ``team``, ``steps``; after a step ``teammate_actions``, ``intended_state`` (what
    the rules drew; differs from ``state`` where physics did not execute a move); on ``backend="mujoco"`` also
    ``sim_time`` (s) and ``poses`` (x, y, yaw of the five robots).

    ## Version history
    v0: initial release.
    """

    metadata = {"render_modes": list(contract.RENDER_MODES), "render_fps": 4}

    @contract.keywords()
    def __init__(
        self,
        teams=None,
        slip: float = 0.0,
        backend: str = "abstract",
        render_mode: str | None = None,
        physics=None,
        world=None,
    ) -> None:
        slip = checks.number("slip", slip, 0.0, 1.0)
        if world is not None and slip:
            raise ConfigError("slip: give the world its slip (world=...) or use the default pursuit world")
        self.world = Pursuit4(5, slip=slip) if world is None else world  # Pursuit4 refuses slip 1
        if teams is not None and not isinstance(teams, (str, list, tuple)):
            raise ConfigError(
                f"teams={teams!r}: give a team name or a list of them from {', '.join(self.world.teams)}"
            )
        chosen = self.world.teams if teams is None else ((teams,) if isinstance(teams, str) else tuple(teams))
        self.teams = tuple(checks.choice("teams", team, self.world.teams) for team in chosen)
        if not self.teams:
            raise ConfigError(f"teams=[]: choose from {', '.join(self.world.teams)}")
        self.models = {team: ExactTeam(self.world, team) for team in self.world.teams}
        self.backend_name = checks.choice("backend", backend, ("abstract", "mujoco"))
        self.pursuit = isinstance(self.world, Pursuit4)
        probe = self.world.sample_states(np.random.default_rng(0), 1)
        self.n_agents = probe.shape[1]
        self.n_mates = self.models[self.teams[0]].probs(probe).shape[1]
        self.render_mode = contract.render_mode(render_mode)
        self.action_space = gymnasium.spaces.Discrete(N_ACTIONS)
        self.observation_space = gymnasium.spaces.MultiDiscrete(
            [self.world.cells] * self.n_agents + [N_ACTIONS + 1] * self.n_mates
        )
        self.arena = None
        if self.backend_name == "mujoco":
            if not (self.pursuit and self.world.size == 5):
                raise ConfigError(f"backend='mujoco': the arena runs 5x5 pursuit only (world={self.world!r})")
            from embodied_adhoc.sim.pursuit_pomdp_arena import PursuitPomdpArena

            self.arena = PursuitPomdpArena(physics, predators=self.n_mates + 1)
        elif physics is not None:
            raise ConfigError("physics: an option of the MuJoCo arena only (backend='mujoco')")
        self._episode = contract.EpisodeGate(type(self).__name__)
        self.team, self.steps = self.teams[0], 0
        self.state = np.zeros(self.n_agents, dtype=np.int64)
        self.mates = np.full(self.n_mates, NO_ACTION, dtype=np.int64)

    def observation_index(self, observation) -> int:
        """The state's :func:`state_code` (for the episode loop's trace), from the observation alone."""
        return state_code(np.asarray(observation)[: self.n_agents], self.world.cells)

    def privileged_state(self) -> np.ndarray:
        """The true state, as ``info["state"]`` holds it: the one channel through which the episode loop gives it to
        privileged agents (``observes_state``); agents never read ``info``."""
        return self.state.copy()

    def _observation(self) -> np.ndarray:
        return np.concatenate([self.state, self.mates]).astype(np.int64)

    def _info(self) -> dict:
        info = {"state": self.state.copy(), "team": self.team, "steps": self.steps}
        if self.arena is not None:
            info["sim_time"] = self.arena.sim_time
            info["poses"] = self.arena.poses().tolist()
        return info

    def _physical(self, state: np.ndarray, target: np.ndarray | None = None) -> np.ndarray:
        """The flat cells physics shows after placing the robots on ``state`` (reset) or driving them from it to
        ``target``."""
        rows_cols = np.stack(np.divmod(state, self.world.size), axis=1)
        if target is None:
            shown = self.arena.reset(rows_cols)
        else:
            shown = self.arena.execute(rows_cols, np.stack(np.divmod(target, self.world.size), axis=1))
        return (shown[:, 0] * self.world.size + shown[:, 1]).astype(np.int64)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        options = dict(options or {})
        checks.refuse_unknown("reset options", options, RESET_OPTIONS, what="option")
        rng = self.np_random
        self.team = self.teams[int(rng.integers(len(self.teams)))]
        state = self.world.sample_states(rng, 1)[0]
        if "team" in options:
            self.team = checks.choice("reset option team", options["team"], self.world.teams)
        if "state" in options:
            state = np.array(
                [checks.integer("reset option state", c, 0, self.world.cells - 1) for c in options["state"]],
                dtype=np.int64,
            )
            if (
                state.size != self.n_agents
                or np.unique(state).size != self.n_agents
                or (self.pursuit and self.world.captured(state[None])[0])
            ):
                raise ConfigError(
                    f"reset option state={options['state']}: give {self.n_agents} distinct cells "
                    "(the ad hoc agent first) that do not end the episode"
                )
        self.state = state if self.arena is None else self._physical(state)
        self.mates = np.full(self.n_mates, NO_ACTION, dtype=np.int64)
        self.steps = 0
        self._episode.open()
        return self._observation(), self._info()

    def step(self, action):
        self._episode.check()
        action = contract.action(action, N_ACTIONS, ACTION_MEANING)
        rng = self.np_random
        self.mates = sample_rows(self.models[self.team].probs(self.state[None])[0], rng)
        joint = np.concatenate([[action], self.mates])[None]
        intended, reward, done = (column[0] for column in self.world.step(self.state[None], joint, rng))
        if self.arena is None:
            self.state, reward, terminated = intended, float(reward), bool(done)
        else:  # physics decides: the capture is read from the cells the robots reached
            self.state = self._physical(self.state, intended)
            terminated = bool(self.world.captured(self.state[None])[0])
            reward = 1.0 if terminated else 0.0
        self.steps += 1
        self._episode.close_if(terminated)
        info = self._info()
        info.update(teammate_actions=self.mates.tolist(), intended_state=intended.tolist())
        return self._observation(), reward, terminated, False, info

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        if self.arena is not None:
            return self.arena.render_top()
        if not self.pursuit:
            raise ConfigError(f"render: pictures of pursuit only (world={self.world!r})")
        from embodied_adhoc.envs.pursuit_pomdp import draw_cells

        return draw_cells(np.stack(np.divmod(self.state, self.world.size), axis=1), colours=COLOURS)

    def close(self) -> None:
        if self.arena is not None:
            self.arena.close()
