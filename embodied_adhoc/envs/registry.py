"""The one registry of Gymnasium env ids. ``import embodied_adhoc.envs`` registers them all.

To add an env, append an :class:`EnvSpec` to ``ENV_SPECS`` (entry points are import strings, so registering
imports neither mujoco nor the env module). ``embodied-adhoc envs`` lists ids with their descriptions.

The step cap of every id is its ``max_episode_steps`` here, applied by gymnasium's ``TimeLimit`` (override it
with ``gymnasium.make(id, max_episode_steps=N)``); the ``trials`` command defaults to the same cap
(:func:`registered_cap`). The thesis states 100 steps for the toxic-waste simulations (Sec. 7.2) and 150 for
Fig. 7.12's pursuit; chapter 6 (foraging, pursuit) states none: 200 here. Every id also gets
:class:`~embodied_adhoc.envs.contract.EpisodeEndGuard` (no step after the episode ended).
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class EnvSpec:
    id: str
    entry_point: str
    description: str
    kwargs: dict = field(default_factory=dict)
    max_episode_steps: int | None = None
    backend: str = "abstract"  # "abstract" (tabular/grid) or "mujoco" (physics)


ENV_SPECS: list[EnvSpec] = [
    # Each area appends its envs here, e.g.
    # EnvSpec("EmbodiedAdhoc/ToxicWaste-v0", "embodied_adhoc.envs.toxic_waste:ToxicWasteEnv", "...", backend="mujoco"),
    EnvSpec(
        "EmbodiedAdhoc/ToxicWasteAbstract-v0",
        "embodied_adhoc.envs.toxic_waste_abstract:ToxicWasteAbstractEnv",
        "HOTSPOT toxic-waste lab, abstract (5 nodes, 2 tasks, speech confusion matrix); truncated at 100 steps",
        max_episode_steps=100,
    ),
    EnvSpec(
        "EmbodiedAdhoc/ToxicWaste-v0",
        "embodied_adhoc.envs.toxic_waste:ToxicWasteEnv",
        "HOTSPOT toxic-waste lab on MuJoCo: wheeled container robot on odometry, walking human, balls, RFID, speech",
        max_episode_steps=100,
        backend="mujoco",
    ),
    # the arenas: level-based foraging and predator-prey, grid twin + MuJoCo arena
    EnvSpec(
        "EmbodiedAdhoc/ForagingGrid-v0",
        "embodied_adhoc.envs.foraging:ForagingEnv",
        "Level-based foraging grid twin: 5x5, 4 foragers, N/S/W/E tasks, teams tau0-2, egocentric 5x5 view",
        max_episode_steps=200,
    ),
    EnvSpec(
        "EmbodiedAdhoc/Foraging-v0",
        "embodied_adhoc.envs.foraging:ForagingEnv",
        "Level-based foraging MuJoCo arena: diff-drive robots cell to cell, apples sized by level",
        kwargs={"backend": "mujoco"},
        max_episode_steps=200,
        backend="mujoco",
    ),
    EnvSpec(
        "EmbodiedAdhoc/PursuitGrid-v0",
        "embodied_adhoc.envs.pursuit:PursuitEnv",
        "Predator-prey grid twin: 5x5, 4 predators, random prey, N/S/W/E tasks, teams tau0-2",
        max_episode_steps=200,
    ),
    EnvSpec(
        "EmbodiedAdhoc/Pursuit-v0",
        "embodied_adhoc.envs.pursuit:PursuitEnv",
        "Predator-prey MuJoCo arena: predator robots and a randomly moving prey robot",
        kwargs={"backend": "mujoco"},
        max_episode_steps=200,
        backend="mujoco",
    ),
    EnvSpec(
        "EmbodiedAdhoc/PursuitPairGrid-v0",
        "embodied_adhoc.envs.pursuit:PursuitEnv",
        "Fig. 7.12 two-predator pursuit grid twin: capture pairs N+S, W+E, SW+NE, NW+SE; greedy/aware teammate",
        kwargs={"pairs": True},
        max_episode_steps=150,
    ),
    EnvSpec(
        "EmbodiedAdhoc/PursuitPair-v0",
        "embodied_adhoc.envs.pursuit:PursuitEnv",
        "Fig. 7.12 two-predator pursuit in the MuJoCo arena",
        kwargs={"pairs": True, "backend": "mujoco"},
        max_episode_steps=150,
        backend="mujoco",
    ),
    # Fig. 7.12 with the pursuit POMDP's own dynamics and observations (HOTSPOT, ATPO, ... drive it)
    EnvSpec(
        "EmbodiedAdhoc/PursuitPairPomdpGrid-v0",
        "embodied_adhoc.envs.pursuit_pomdp:PursuitPomdpEnv",
        "Fig. 7.12 two-predator pursuit on the 5x5 torus, the pursuit-task POMDP as rules; Discrete(81) obs",
        max_episode_steps=150,
    ),
    EnvSpec(
        "EmbodiedAdhoc/PursuitPairPomdp-v0",
        "embodied_adhoc.envs.pursuit_pomdp:PursuitPomdpEnv",
        "Fig. 7.12 pursuit POMDP executed by robots in the MuJoCo arena; observation from the physical poses",
        kwargs={"backend": "mujoco"},
        max_episode_steps=150,
        backend="mujoco",
    ),
    # chapter 4's pursuit (TEAMSTER, PLASTIC-Model), its rules on the grid twin and in the arena
    EnvSpec(
        "EmbodiedAdhoc/Pursuit4Grid-v0",
        "embodied_adhoc.envs.teamwork:TeamworkEnv",
        "Chapter-4 pursuit: 5x5 torus, 4 predators, teams teammate-aware/greedy/probabilistic destinations",
        max_episode_steps=100,
    ),
    EnvSpec(
        "EmbodiedAdhoc/Pursuit4-v0",
        "embodied_adhoc.envs.teamwork:TeamworkEnv",
        "Chapter-4 pursuit executed by five robots in the MuJoCo arena (waypoint controller, torus teleports)",
        kwargs={"backend": "mujoco"},
        max_episode_steps=100,
        backend="mujoco",
    ),
]


GUARD = ("EpisodeEndGuard", "embodied_adhoc.envs.contract:EpisodeEndGuard")


def registered_cap(env_id: str) -> int | None:
    """The registered step cap (``max_episode_steps``) of ``env_id``."""
    for spec in ENV_SPECS:
        if spec.id == env_id:
            return spec.max_episode_steps
    raise KeyError(env_id)


def register_all() -> None:
    import gymnasium
    from gymnasium.envs.registration import WrapperSpec

    for spec in ENV_SPECS:
        if spec.id in gymnasium.registry:
            continue
        gymnasium.register(
            id=spec.id,
            entry_point=spec.entry_point,
            kwargs=dict(spec.kwargs),
            max_episode_steps=spec.max_episode_steps,
            additional_wrappers=(WrapperSpec(*GUARD, {}),),
        )
