"""Why our Fig. 7.12 differs from the thesis's: the original experiment's model and protocol, as ablations.

The thesis's Fig. 7.12 numbers are exactly the four result files of the original experiment
(``jmribeiro/HOTSPOT-An-Ad-Hoc-Teamwork-Platform-for-Mixed-Human-Robot-Teams``,
``empirical_evaluation/resources/results/pursuit-task-{optimal,partial-baseline,comms,random}-32.npy``: means
6.75, 10.22, 12.84, 76.06 and population sds 4.55, 6.12, 7.29, 52.65). Its code (``run_envs.py``, ``agents.py``,
``backend/environments/pursuit.py``) differs from ours in four ways, each a switch here:

* **model** ``"original"``: the original generator's toroidal offset wrap (``toroidal_check``) maps an offset
  d with ``size // 2 < |d| < size`` to ``-d - size // 2`` (d < 0) or ``size // 2 - d`` (d > 0): on the 5 x 5 torus
  +3 becomes -1 and +4 becomes -2 instead of -2 and -1. A teammate or prey crossing the torus edge lands one cell
  closer than it is, and the capture test (teammate-to-prey offset through the same wrap) accepts teammates two
  cells away: 4 goal states per task for N+S / W+E and 8 for SW+NE / NW+SE instead of 2. The original's
  transition generator (greedy teammate to its closest capture cell, columns first, random prey) is our
  ``pursuit-task`` builder with that wrap (:func:`~embodied_adhoc.domains.chapter5.pursuit.build_pursuit`'s
  ``wrap="original"``, :func:`~embodied_adhoc.domains.chapter5.pursuit.wrap_offsets`), so the wrap is the only
  model difference (:func:`original_library`).
* **tasks** 2: the original built ``pomdps = [... for i in range(2)]``: the library and the draws are N+S and W+E
  only (our figure uses all four).
* **count**: the original stops when the reward 1 arrives, and its reward ``R(x, a)`` is paid in the step taken
  *from* the capture state, so its steps are ours + 1. The ablation runs on the chapter-5 ``LibraryEnv`` (episode
  over on entering the absorbing state), which counts the original's way; our Fig. 7.12 env ends on entering the
  capture state.
* **reward gain** of HOTSPOT's information reward (``HotspotConfig.reward_gain``): the original's code has the
  ``ΔR`` factor commented out (``"none"``), the thesis's equation has it (``"thesis"``); ours defaults to
  ``"conditional"``.

The original's known-task agent is TEBOPA with a one-model library (the true task's), i.e. our HOTSPOT with a
one-hot prior. The original's models for TEBOPA and the known-task agent had a sixth action, "locate" (the stay
move; the teammate read at any distance as its direction), which our library has not: :func:`with_locate` adds
it (the thesis's |A_0| = 6).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np
import scipy.sparse as sp

from embodied_adhoc.errors import ConfigError

__all__ = ["ABLATION_AGENTS", "ablation_steps", "locate_observations", "original_library", "with_locate"]

ABLATION_AGENTS = ("oracle", "known-task", "hotspot", "random")


def locate_observations(library) -> sp.csr_matrix:
    """The original's sixth action "locate" (its ``comms`` models): the stay move, observed as after any action
    except that the teammate is read at any distance as its direction (the sign of its offset, a cell of the 3x3
    neighbourhood) w.p. ``1 - eps`` (else the agent's own cell, as a miss)."""
    size = int(library.settings.get("size", 5))
    half, eps = size // 2, float(library.noise)
    absorbing = library.absorbing_state
    rows, cols, probabilities = [], [], []
    for state in range(absorbing):
        mate, prey = divmod(state, size * size)
        mate_offset = np.array(divmod(mate, size)) - half
        prey_offset = np.array(divmod(prey, size)) - half
        if (mate_offset == 0).all():
            mate_reading = {4: 1.0}
        else:
            sign = np.sign(mate_offset)
            mate_reading = {int(3 * (sign[0] + 1) + sign[1] + 1): 1.0 - eps, 4: eps}
        if (prey_offset == 0).all() or np.abs(prey_offset).max() > 1:
            prey_reading = {4: 1.0}
        else:
            prey_reading = {int(3 * (prey_offset[0] + 1) + prey_offset[1] + 1): 1.0 - eps, 4: eps}
        for t, p_t in mate_reading.items():
            for q, p_q in prey_reading.items():
                rows.append(state)
                cols.append(9 * t + q)
                probabilities.append(p_t * p_q)
    last = library.pomdps[0].observations[4].getrow(absorbing).tocoo()
    rows += [absorbing] * last.nnz
    cols += last.col.tolist()
    probabilities += last.data.tolist()
    matrix = sp.csr_matrix((probabilities, (rows, cols)), shape=(absorbing + 1, library.n_observations))
    matrix.sum_duplicates()
    return matrix


def with_locate(library):
    """``library`` with the original's "locate" action (:func:`locate_observations`) added to every model."""
    from embodied_adhoc.decision.models import POMDP

    observation = locate_observations(library)
    pomdps = tuple(
        POMDP(
            tuple(p.transitions) + (p.transitions[4],),
            np.hstack([p.rewards, p.rewards[:, 4:5]]),
            p.discount,
            p.state_names,
            tuple(p.action_names) + ("locate",),
            tuple(p.observations) + (observation,),
            p.initial_belief,
            p.observation_names,
        )
        for p in library.pomdps
    )
    return dataclasses.replace(library, domain=f"{library.domain}-locate", pomdps=pomdps)


def original_library(library, wrap: str = "original", n_tasks: int | None = None):
    """The pursuit ``library`` (its variant, size, noise, horizon and beliefs) rebuilt with the torus ``wrap``
    (``build_pursuit(..., wrap=wrap)``; ``"original"``: the original experiment's generator), named
    ``<domain>-<wrap>-wrap``; its MMDPs and named teammates follow the wrap too. ``n_tasks`` keeps the first tasks
    only (the original used 2)."""
    from embodied_adhoc.domains.chapter5.pursuit import PURSUIT_VARIANTS, build_pursuit

    variant = library.settings.get("variant")
    if variant not in PURSUIT_VARIANTS or "models" in library.settings:
        raise ConfigError(
            f"{library.domain}: not a whole pursuit library (build_pursuit's); the ablation rebuilds one"
        )
    keep = library.n_models if n_tasks is None else int(n_tasks)
    if not 1 <= keep <= library.n_models:
        raise ConfigError(f"n_tasks={n_tasks}: the library has {library.n_models} tasks")
    rebuilt = build_pursuit(
        variant,
        size=int(library.settings["size"]),
        noise=library.noise,
        horizon=library.horizon,
        n_beliefs=library.n_beliefs,
        wrap=wrap,
    )
    if keep < rebuilt.n_models:
        rebuilt = rebuilt.subset(range(keep))
    return dataclasses.replace(rebuilt, domain=f"{library.domain}-{wrap}-wrap")


def ablation_steps(
    library,
    agents: Sequence[str] = ABLATION_AGENTS,
    episodes: int = 32,
    seed: int = 0,
    cap: int = 150,
    reward_gain: str | None = None,
) -> dict[str, np.ndarray]:
    """Steps per episode (the original's count: to the capture reward) of each agent on ``library``, tasks drawn
    uniformly from its models and starts from their initial beliefs, the same draws for every agent."""
    from embodied_adhoc.decision.agents.factory import make_agent
    from embodied_adhoc.decision.agents.hotspot import HotspotConfig
    from embodied_adhoc.envs.library_env import LibraryEnv
    from embodied_adhoc.episodes.loop import run_episode_loop

    unknown = sorted(set(agents) - set(ABLATION_AGENTS))
    if unknown:
        raise ConfigError(f"agents {','.join(unknown)}: choose from {','.join(ABLATION_AGENTS)}")
    hotspot = HotspotConfig() if reward_gain is None else HotspotConfig(reward_gain=reward_gain)
    specs = []
    for episode in range(episodes):
        rng = np.random.default_rng([seed, episode])
        task = int(rng.integers(library.n_models))
        initial = library.pomdps[task].initial_belief
        specs.append((task, int(rng.choice(initial.size, p=initial))))
    env = LibraryEnv(library)
    steps = {}
    for name in agents:
        counts = []
        for episode, (task, start) in enumerate(specs):
            agent = make_agent(name, library, true_task=task, hotspot=hotspot)
            trace = run_episode_loop(
                env,
                agent,
                env_seed=seed * 100_003 + episode,
                agent_rng=np.random.default_rng([seed, episode, 1]),
                reset_options={"task": task, "start": start},
                max_steps=cap,
                observation_index=int,  # LibraryEnv: the observation is the index
            )
            counts.append(len(trace.actions))
        steps[name] = np.array(counts)
    return steps
