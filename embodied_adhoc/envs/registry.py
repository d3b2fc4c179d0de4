"""The one registry of Gymnasium env ids. ``import embodied_adhoc.envs`` registers them all.

To add an env, append an :class:`EnvSpec` to ``ENV_SPECS`` (entry points are import strings, so registering
imports neither mujoco nor the env module). ``embodied-adhoc envs`` lists ids with their descriptions.
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
    ),
    EnvSpec(
        "EmbodiedAdhoc/ToxicWaste-v0",
        "embodied_adhoc.envs.toxic_waste:ToxicWasteEnv",
        "HOTSPOT toxic-waste lab on MuJoCo: wheeled container robot on odometry, walking human, balls, RFID, speech",
        backend="mujoco",
    ),
]


def register_all() -> None:
    import gymnasium

    for spec in ENV_SPECS:
        if spec.id in gymnasium.registry:
            continue
        gymnasium.register(
            id=spec.id,
            entry_point=spec.entry_point,
            kwargs=dict(spec.kwargs),
            max_episode_steps=spec.max_episode_steps,
        )
