"""Many foraging or pursuit grid envs stepped at once in numpy, for training (ATLPO, thesis chapter 6).

:class:`GridVectorEnv` is a ``gymnasium.vector.VectorEnv`` equivalent to ``SyncVectorEnv`` over copies of
``EmbodiedAdhoc/ForagingGrid-v0`` or ``EmbodiedAdhoc/PursuitGrid-v0`` (abstract backend, grid observations),
step for step and draw for draw: each sub-env keeps its own seeded ``numpy.random.Generator`` and consumes it
exactly as the single env does (the episode draw at reset through the env's own
:meth:`~embodied_adhoc.envs.grid_world_env.GridWorldCore.draw_episode`, the draws of its ``reset``; per
step ``TEAM_DRAWS`` uniforms per member for the scripted team, then two per prey in pursuit). The rules, the
scripted teams (tau0-tau2 and the others) and the observations are the single env's own batched implementation
(:meth:`GridRules.plan_batch`, :class:`TeamPlanner`, :func:`egocentric_batch`), called once for all sub-envs
instead of once per env.

Speed: a sub-env's step uniforms are drawn ``DRAW_BLOCK`` steps at a time (one ``random`` call per sub-env every
``DRAW_BLOCK`` steps instead of every step; a Generator's doubles come out the same however the calls split
them). When a sub-env resets with part of its block unused, its Generator is put back where the single env's
would be (the state before the block, then the used draws drawn again), so the reset draws what the single env
draws. Every step plans all sub-envs at once, the resetting ones included (their results are discarded), which
avoids gathering a sub-batch. The sub-envs that reset at a step draw their episodes' numbers one by one (each
from its own Generator, the same numbers in the same order as the single env); their start states are built from
those numbers at once (:meth:`GridRules.sample_states`) and their state, task, team and step count written at
once.

Policy teams: a team given by plug-in spec in ``teams`` whose factory returns a policy object rather than a
``TeamSpec`` (:mod:`~embodied_adhoc.teammates.grid_plugins`; the benchmark's seats, sticky and learned members,
``TeammateSpec.trial_options``'s ``teams``) cannot go through the batched planner. Each sub-env holds its own
object of each such team, built by the single env's own builder (``with_plugin_teams``), and a sub-env whose
episode has one asks it for the teammates' actions with its own Generator, then draws the prey's uniforms, as the
single env does; those sub-envs draw no uniform blocks. A team's memory (a sticky member's last actions, a learned
member's GRU state) lives in its object and restarts when it is handed another Generator, as in the single env:
at every seeded reset, not at an autoreset; a resumed training checkpoint restarts them too.

Autoreset: gymnasium's default ``AutoresetMode.NEXT_STEP``. The step that ends an episode returns its last
observation with ``terminated``/``truncated`` set; the next ``step`` ignores that sub-env's action, resets it and
returns the first observation of the new episode with reward 0 and both flags False. ``truncated`` comes from
``max_episode_steps`` (the registered spec's TimeLimit, 200, unless given), as the TimeLimit wrapper does.

``infos``: ``task`` (1-based) and ``team`` (index into ``team_names``) of every sub-env's current episode, with
their ``_task``/``_team`` masks (ground truth for evaluation and for training per-environment policies).
With ``teammate_info=True`` (for training only: LIAM's reconstruction targets, never an agent's input) every
``step`` adds ``teammate_observations`` (num_envs, N-1, channels, view, view), the teammates' egocentric windows of
the state they acted in (the state the previous step's observation shows), and ``teammate_actions``
(num_envs, N-1), the actions they took in it; their masks ``_teammate_observations``/``_teammate_actions`` are
False on a sub-env's reset step, where no one acts.
"""

from __future__ import annotations

import gymnasium
import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space

from embodied_adhoc.domains.grid_rules import GridBatch
from embodied_adhoc.domains.grid_rules_obs import egocentric_batch
from embodied_adhoc.domains.grid_rules_team import TEAM_DRAWS, TeamSpec, TeamTable, planner_for
from embodied_adhoc.errors import ConfigError

GRID_IDS = {"foraging": "EmbodiedAdhoc/ForagingGrid-v0", "pursuit": "EmbodiedAdhoc/PursuitGrid-v0"}
DRAW_BLOCK = 64  # steps of uniforms drawn per sub-env at once


def sub_env_seeds(seed: int | list[int | None] | None, num_envs: int) -> list[int | None]:
    """One seed per sub-env: ``seed + i`` for sub-env ``i`` of an int (as ``SyncVectorEnv``), all None for None,
    or the list given (one per sub-env)."""
    if seed is None or isinstance(seed, int):
        return [None if seed is None else seed + i for i in range(num_envs)]
    seeds = list(seed)
    if len(seeds) != num_envs:
        raise ConfigError(f"seed: {len(seeds)} seeds for {num_envs} sub-envs; give one each or an int")
    return seeds


class GridVectorEnv(gymnasium.vector.VectorEnv):
    """``num_envs`` ad hoc grid envs (``domain`` foraging or pursuit; ``env_kwargs`` as for the single env's
    ``gymnasium.make``: tasks, teams, rows, cols, n_agents, toroidal, view, ...). Agent 0 of each sub-env is the
    learner (the action), agents 1..N-1 its episode's scripted team."""

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(
        self,
        domain: str,
        num_envs: int,
        max_episode_steps: int | None = None,
        environments: list[tuple[int, str]] | None = None,
        teammate_info: bool = False,
        **env_kwargs,
    ) -> None:
        import embodied_adhoc.envs  # noqa: F401  (registers the ids)

        if domain not in GRID_IDS:
            raise ConfigError(f"domain={domain!r}: use one of {sorted(GRID_IDS)}")
        if not isinstance(num_envs, int) or num_envs < 1:
            raise ConfigError(f"num_envs={num_envs!r}: give a positive integer")
        for key in ("backend", "obs_mode", "render_mode"):
            if key in env_kwargs:
                raise ConfigError(
                    f"{key}: the vector env is the abstract grid twin with grid observations only"
                )
        probe = gymnasium.make(GRID_IDS[domain], **env_kwargs)
        self.max_episode_steps = int(max_episode_steps or probe.spec.max_episode_steps or 10**9)
        if self.max_episode_steps < 1:
            raise ConfigError(f"max_episode_steps={max_episode_steps}: give a positive integer")
        self.core = probe.unwrapped.core  # its reset draws every episode (one mechanism with the single env)
        self.rules, self.view = self.core.rules, self.core.view
        self.planner = planner_for(self.rules)
        self.offsets = np.array([task.offsets for task in self.core.tasks], dtype=np.int64)  # (T, N, 2)
        self.interchangeable = self.core.tasks[0].interchangeable
        self.team_names = tuple(self.core.teams)
        self.team_number = {name: i for i, name in enumerate(self.team_names)}
        teams = [self.core.teams[name] for name in self.team_names]
        # a policy team's row of the table is a stand-in: the planner's actions for its sub-envs are replaced
        stand_in = next((t for t in teams if isinstance(t, TeamSpec)), TeamSpec("stand-in", "unused"))
        self.team_table = TeamTable.of([t if isinstance(t, TeamSpec) else stand_in for t in teams])
        self.policy_team = np.array([not isinstance(t, TeamSpec) for t in teams])
        cfg = self.rules.config
        self.draws = TEAM_DRAWS * cfg.n_agents + self.rules.prey_draws()

        self.num_envs = num_envs
        self.single_observation_space = self.core.observation_space()
        self.single_action_space = gymnasium.spaces.Discrete(5)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.batch = GridBatch(
            np.zeros((num_envs, cfg.n_agents, 2), np.int64),
            np.ones((num_envs, cfg.n_agents), np.int64),
            np.zeros((num_envs, cfg.n_targets, 2), np.int64),
            np.ones((num_envs, cfg.n_targets), np.int64),
            np.ones((num_envs, cfg.n_targets), bool),
        )
        self.task_index = np.zeros(num_envs, np.int64)  # 0-based into core.tasks
        self.team_index = np.zeros(num_envs, np.int64)
        self.steps = np.zeros(num_envs, np.int64)
        self.needs_reset = np.zeros(num_envs, bool)
        self.rngs: list[np.random.Generator] = []
        self.observers = np.zeros((num_envs, 1), np.int64)
        self.teammate_info = bool(teammate_info)
        self.teammates = np.broadcast_to(
            np.arange(1, cfg.n_agents, dtype=np.int64), (num_envs, cfg.n_agents - 1)
        )
        self._teammate_step: dict = {}
        # the current episode's task offsets and team parameters per sub-env, rewritten row by row at resets
        self.episode_offsets = self.offsets[self.task_index]
        self.episode_teams = self.team_table.take(self.team_index)
        # DRAW_BLOCK steps of uniforms per sub-env, how many of them are used and the Generator state before them
        self.uniforms = np.zeros((num_envs, DRAW_BLOCK, self.draws))
        self.team_policies = self._team_policies(num_envs)
        self.used = np.full(num_envs, DRAW_BLOCK, np.int64)
        self.block_states: list[dict | None] = [None] * num_envs
        # optional (task, team) pairs drawn per episode instead of the product tasks x teams; one extra draw
        # from the sub-env's Generator before the single env's own (the step-for-step match holds without it)
        self.environments = None if environments is None else [(int(t), str(m)) for t, m in environments]
        if self.environments is not None:
            if not self.environments:
                raise ConfigError("environments=[]: give (task, team) pairs, or None for tasks x teams")
            for task, team in self.environments:
                if not 1 <= task <= len(self.core.tasks) or team not in self.core.teams:
                    raise ConfigError(
                        f"environments: ({task}, {team!r}) is not a task 1..{len(self.core.tasks)} "
                        f"with a team of {sorted(self.core.teams)}"
                    )

    def _team_policies(self, num_envs: int) -> list[dict]:
        """Per sub-env, its own object of every policy team (see the module docstring)."""
        from embodied_adhoc.teammates.grid_plugins import with_plugin_teams

        names = [name for name, policy in zip(self.team_names, self.policy_team, strict=True) if policy]
        if not names:
            return [{} for _ in range(num_envs)]
        return [with_plugin_teams({}, names, self.rules) for _ in range(num_envs)]

    def _policy_actions(self, rows: np.ndarray, team: np.ndarray, prey_uniforms) -> None:
        """The teammates' actions of the sub-envs ``rows`` (policy teams) into ``team``, then their prey uniforms:
        the single env's draws in its order."""
        n, members = self.rules.config.n_agents, list(range(1, self.rules.config.n_agents))
        for index in rows.tolist():
            rng = self.rngs[index]
            policy = self.team_policies[index][self.team_names[self.team_index[index]]]
            task = self.core.tasks[self.task_index[index]]
            team[index, 1:n] = policy.actions(self.batch.state(index), task, rng, members)
            if prey_uniforms is not None:
                prey_uniforms[index] = rng.random(prey_uniforms.shape[1:])

    def _rewind(self, index: int) -> None:
        """Put sub-env ``index``'s Generator where the single env's is: after the used steps of its block."""
        used = int(self.used[index])
        if used < DRAW_BLOCK and self.block_states[index] is not None:
            rng = self.rngs[index]
            rng.bit_generator.state = self.block_states[index]
            rng.random(used * self.draws)
        self.used[index], self.block_states[index] = DRAW_BLOCK, None

    def _draw(self, stepping: np.ndarray) -> np.ndarray:
        """(num_envs, draws) this step's uniforms (rows of sub-envs not in ``stepping`` are stale, unused)."""
        for index in np.flatnonzero(stepping & (self.used >= DRAW_BLOCK)).tolist():
            rng = self.rngs[index]
            self.block_states[index] = rng.bit_generator.state
            self.uniforms[index] = rng.random((DRAW_BLOCK, self.draws))
            self.used[index] = 0
        uniforms = self.uniforms[np.arange(self.num_envs), np.minimum(self.used, DRAW_BLOCK - 1)]
        self.used += stepping
        return uniforms

    def _reset_rows(self, rows: list[int], options: dict | None) -> None:
        """Reset the sub-envs ``rows``: each Generator draws what the single env's reset draws, in row order;
        the episodes' bookkeeping is then written for all of them at once."""
        if options is None and self.environments is None:
            self._reset_rows_batched(rows)
            return
        tasks, teams, states = [], [], []
        for index in rows:
            self._rewind(index)
            rng, chosen = self.rngs[index], options
            if self.environments is not None:
                task, team = self.environments[int(rng.integers(len(self.environments)))]
                chosen = {"task": task, "team": team, **(options or {})}
            if chosen:
                self.core.reset(rng, chosen)
                episode = self.core.episode
                task, team, state = episode.task_number, episode.team, episode.state
            else:  # the same draws without the option checks and the Episode
                task, team, state = self.core.draw_episode(rng)
            tasks.append(task)
            teams.append(self.team_number[team])
            states.append(state)
        index = np.asarray(rows, dtype=np.int64)
        self.batch.put_rows(index, states)
        self._write_episodes(index, tasks, teams)

    def _reset_rows_batched(self, rows: list[int]) -> None:
        """:meth:`_reset_rows` without options or listed environments: every Generator draws what the single
        env's ``draw_episode`` draws (task, team, then the state's integers), and the states are built at once
        by :meth:`GridRules.sample_states`."""
        for index in rows:
            self._rewind(index)
        states, drawn = self.rules.sample_states(
            [self.rngs[index] for index in rows], first=self.core.draw_task_team
        )
        index = np.asarray(rows, dtype=np.int64)
        self.batch.put_batch(index, states)
        self._write_episodes(index, [task for task, _ in drawn], [self.team_number[t] for _, t in drawn])

    def _write_episodes(self, index: np.ndarray, tasks: list[int], teams: list[int]) -> None:
        """The reset rows' task, team, step count and episode parameters."""
        self.task_index[index] = np.asarray(tasks, dtype=np.int64) - 1
        self.team_index[index] = teams
        self.steps[index] = 0
        self.needs_reset[index] = False
        self.episode_offsets[index] = self.offsets[self.task_index[index]]
        for name in ("target", "slot_closest", "ring", "greedy"):
            getattr(self.episode_teams, name)[index] = getattr(self.team_table, name)[self.team_index[index]]

    def _observations(self) -> np.ndarray:
        return egocentric_batch(self.rules, self.batch, self.observers, self.view)[:, 0]

    def _infos(self) -> dict:
        every = np.ones(self.num_envs, bool)
        return {"task": self.task_index + 1, "_task": every, "team": self.team_index.copy(), "_team": every}

    def reset(self, *, seed: int | list[int | None] | None = None, options: dict | None = None):
        """Reset every sub-env; ``seed`` an int (sub-env ``i`` gets ``seed + i``, as ``SyncVectorEnv``) or one
        seed per sub-env; ``options`` as the single env's (task, team, state), applied to every sub-env."""
        seeds = sub_env_seeds(seed, self.num_envs)
        if not self.rngs or seed is not None:
            self.rngs = [seeding.np_random(s)[0] for s in seeds]
            self.used[:], self.block_states = DRAW_BLOCK, [None] * self.num_envs
        self._reset_rows(list(range(self.num_envs)), options)
        return self._observations(), self._infos()

    def step(self, actions):
        if not self.rngs:
            raise gymnasium.error.ResetNeeded("call reset() before step()")
        actions = np.asarray(actions)
        if (
            actions.shape != (self.num_envs,)
            or actions.dtype.kind not in "iu"
            or np.any((actions < 0) | (actions > 4))
        ):
            raise ConfigError(
                f"actions {actions.tolist()!r}: need {self.num_envs} integers in 0..4 "
                "(up, down, left, right, interact)"
            )
        resetting = self.needs_reset.copy()
        stepping = ~resetting
        terminated, truncated = np.zeros(self.num_envs, bool), np.zeros(self.num_envs, bool)
        if stepping.any():
            self._step_batch(stepping, actions.astype(np.int64), terminated, truncated)
        if resetting.any():
            self._reset_rows(np.flatnonzero(resetting).tolist(), None)
        infos = self._infos()
        if self.teammate_info:
            if not stepping.any():  # every sub-env reset: nobody acted, the (masked) arrays are zeros
                shape = (self.num_envs, self.teammates.shape[1])
                self._teammate_step = {
                    "teammate_observations": np.zeros(
                        (*shape, *self.single_observation_space.shape), np.float32
                    ),
                    "teammate_actions": np.zeros(shape, np.int64),
                }
            infos.update(self._teammate_step)
            infos.update({"_teammate_observations": stepping, "_teammate_actions": stepping.copy()})
        return self._observations(), terminated.astype(np.float64), terminated, truncated, infos

    def _step_batch(self, stepping: np.ndarray, actions: np.ndarray, terminated, truncated) -> None:
        """One step of every sub-env in ``stepping``; the others are planned too but keep their state."""
        cfg = self.rules.config
        n, b = cfg.n_agents, self.batch
        policy = stepping & self.policy_team[self.team_index]
        uniforms = self._draw(stepping & ~policy)  # the policy teams' sub-envs draw from their Generators
        team_uniforms = uniforms[:, : TEAM_DRAWS * n].reshape(self.num_envs, n, TEAM_DRAWS)
        prey_uniforms = (
            uniforms[:, TEAM_DRAWS * n :].reshape(self.num_envs, cfg.n_targets, 2)
            if self.rules.prey_draws()
            else None
        )
        offsets, teams = self.episode_offsets, self.episode_teams
        team = self.planner.actions(b, offsets, self.interchangeable, teams, team_uniforms)
        if policy.any():
            self._policy_actions(np.flatnonzero(policy), team, prey_uniforms)
        team[:, 0] = actions
        if self.teammate_info:  # before the move: the windows the teammates chose their actions from
            self._teammate_step = {
                "teammate_observations": egocentric_batch(self.rules, b, self.teammates, self.view),
                "teammate_actions": team[:, 1:].copy(),
            }
        plan = self.rules.plan_batch(b, offsets, self.interchangeable, team, prey_uniforms)
        keep = ~stepping
        b.agents[...] = np.where(keep[:, None, None], b.agents, plan.agents)
        b.targets[...] = np.where(keep[:, None, None], b.targets, plan.targets)
        b.alive &= keep[:, None] | ~plan.completed
        self.steps += stepping
        terminated |= stepping & ~b.alive.any(axis=1)
        truncated |= stepping & (self.steps >= self.max_episode_steps)
        self.needs_reset |= terminated | truncated

    def close_extras(self, **kwargs) -> None:
        self.core.backend.close()
