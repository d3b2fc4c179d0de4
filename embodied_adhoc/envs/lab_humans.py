"""The lab envs' ``human=`` keyword: who the human teammate of the toxic-waste lab is in the world.

The interface of a lab human (the default is the thesis's scripted cleaner, :class:`~embodied_adhoc.domains.
lab_human.LabHuman`, one per task of the library)::

    factory(library, task) -> human      # library: the env's LabLibrary; task: index into library.tasks
    human.step(rng, human_node, ball_status) -> HumanOutcome(probability, next_node, picked_ball)

``step`` is called once per env step with the env's generator, the human's node and the balls' status (0 on the
ground, 1 held, 2 in the container); it returns where the human goes (a neighbour of ``human_node`` on
``library.graph``, or ``human_node`` to stay) and the ball it picks up at its node (``-1``: none). The env applies
it with the lab's rules (a human holding a ball waits for the robot; ``domains.lab.apply_step``), and an outcome
with ``dropped=True`` while the human holds a ball puts that ball back on the ground. A human may also define
``answer(rng, human_node) -> node or None``: what it says when the robot asks "where are you?" (both lab envs
pass that node through their speech channel; ``None`` is no reply); without it the human says where it is. The
agents keep their models: a different human is a model mismatch, which is what a user's human is for.

``human`` is ``None`` or ``"scripted"`` (the library's), a plug-in spec of :mod:`embodied_adhoc.plugins` (kind
``human``: ``module:callable``, ``path/to/file.py:callable`` or an ``embodied_adhoc.humans`` entry point), or
the factory itself.
"""

from __future__ import annotations

from embodied_adhoc.errors import ConfigError

__all__ = ["HUMAN_NAMES", "human_option", "lab_humans"]

HUMAN_NAMES = ("scripted",)


def lab_humans(library, human) -> tuple:
    """One human per task of ``library`` for the env's ``human=`` value (see the module docstring)."""
    if human is None or human == "scripted":
        return tuple(library.humans)
    label = f"human={human!r}"
    if isinstance(human, str):
        from embodied_adhoc.plugins import resolve

        factory = resolve("human", human, builtin=HUMAN_NAMES, flag="human=").factory
    elif callable(human):
        factory = human
    else:
        raise ConfigError(
            f"{label}: give 'scripted', a plug-in spec (module:callable) or a factory(library, task)"
        )
    humans = []
    for task in range(library.n_tasks):
        try:
            made = factory(library, task)
        except ConfigError:
            raise
        except Exception as error:
            raise ConfigError(
                f"{label}: factory(library, task={task}) failed: {type(error).__name__}: {error}"
            ) from error
        if not callable(getattr(made, "step", None)):
            raise ConfigError(
                f"{label}: factory(library, task={task}) returned {type(made).__name__}, which has no "
                "step(rng, human_node, ball_status) method (see embodied_adhoc.envs.lab_humans)"
            )
        humans.append(made)
    return tuple(humans)


def human_option(spec: str | None, flag: str = "--human") -> dict:
    """``{"human": spec}`` for a plug-in human (resolved now, so a bad spec stops before any work), ``{}`` for the
    scripted one: the lab envs' kwargs and a trial run's options, which name the human only when it differs."""
    if spec is None or spec == "scripted":
        return {}
    from embodied_adhoc.plugins import resolve

    resolve("human", spec, builtin=HUMAN_NAMES, flag=flag)
    return {"human": str(spec)}
