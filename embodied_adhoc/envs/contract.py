"""The env contract, written once (docs/envs.md, "The env contract"); every env of the package goes through
it: the toxic-waste lab (``ToxicWasteAbstract-v0``, ``ToxicWaste-v0``), the arenas (grid twins and MuJoCo) and
the PettingZoo :class:`~embodied_adhoc.envs.multiagent.GridParallelEnv`.

* **Actions** are integers: a Python ``int``, a numpy integer of any width or a 0-d integer array, inside the
  action space. Bools, floats, strings, ``None`` and arrays with a shape get one :class:`ConfigError`
  (:func:`action`).
* **Kwargs and reset options** are checked by name and type (:mod:`embodied_adhoc.checks`): unknown names and
  wrong types (``{"task": 1.9}``, ``communication="no"``) are refused, never truncated or ignored.
* **Episodes**: ``step`` before the first ``reset`` or after the episode ended raises :class:`EpisodeOverError`.
  An env ends its episode itself when it terminates (:class:`EpisodeGate`); truncation is gymnasium's
  ``TimeLimit`` from the registered ``max_episode_steps`` (``gymnasium.make(id, max_episode_steps=N)``
  overrides it), and :class:`EpisodeEndGuard`, which ``gymnasium.make`` adds from the spec, refuses steps after
  it. No env has a step-cap kwarg of its own.
* **Rendering**: ``render_mode`` is ``None`` or ``"rgb_array"`` (:func:`render_mode`) and every env declares
  ``render_fps`` in its metadata, so wrappers and vector envs (e.g. stable-baselines3's ``make_vec_env``) work.
"""

from __future__ import annotations

import functools
import inspect

import gymnasium

from embodied_adhoc.checks import choice, integer, refuse_unknown
from embodied_adhoc.errors import ConfigError

__all__ = [
    "RENDER_MODES",
    "EpisodeEndGuard",
    "EpisodeGate",
    "EpisodeOverError",
    "action",
    "keywords",
    "render_mode",
]

RENDER_MODES = ("rgb_array",)


class EpisodeOverError(ConfigError, gymnasium.error.ResetNeeded):
    """``step`` called with no running episode (never reset, terminated or truncated): call ``reset`` first."""


def action(value, n: int, meaning: str = "") -> int:
    """The action as a Python int in ``0..n-1`` (see the module docstring for what is accepted)."""
    try:
        return integer("action", value, 0, n - 1)
    except ConfigError as error:
        raise ConfigError(f"{error}" + (f" ({meaning})" if meaning else "")) from None


STEP_CAP_KEYWORD = (
    "max_episode_steps is gymnasium.make's keyword, not an env kwarg: use gymnasium.make(id, "
    "max_episode_steps=N) (the step cap is the spec's TimeLimit)"
)


def keywords(*passed_on: str):
    """Decorator of an env's ``__init__``: keyword arguments it does not accept get one ConfigError that names
    them and the accepted ones (its explicit parameters plus ``passed_on``, those it takes through ``**kwargs``).
    The accepted names are kept as ``__init__.accepted`` (e.g. for the PettingZoo env that wraps an env)."""

    def decorate(init):
        kinds = (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)
        own = [n for n, p in inspect.signature(init).parameters.items() if p.kind in kinds and n != "self"]
        accepted = tuple(own) + tuple(n for n in passed_on if n not in own)

        @functools.wraps(init)
        def checked(self, *args, **kwargs):
            if "max_episode_steps" in kwargs:
                raise ConfigError(f"{type(self).__name__}: {STEP_CAP_KEYWORD}")
            refuse_unknown(type(self).__name__, kwargs, accepted)
            init(self, *args, **kwargs)

        checked.accepted = accepted
        return checked

    return decorate


def render_mode(value, modes: tuple[str, ...] = RENDER_MODES) -> str | None:
    """``None`` or one of ``modes`` (every env offers :data:`RENDER_MODES`)."""
    if value is None:
        return None
    return choice("render_mode", value, modes)


class EpisodeGate:
    """Whether an episode is running: opened by ``reset``, closed when the env reports the end."""

    __slots__ = ("name", "running")

    def __init__(self, name: str) -> None:
        self.name, self.running = name, False

    def open(self) -> None:
        self.running = True

    def check(self) -> None:
        if not self.running:
            raise EpisodeOverError(
                f"{self.name}.step(): no episode is running (not reset yet, or it terminated or was "
                "truncated); call reset() first"
            )

    def close_if(self, ended: bool) -> None:
        if ended:
            self.running = False


class EpisodeEndGuard(gymnasium.Wrapper, gymnasium.utils.RecordConstructorArgs):
    """Refuses ``step`` after a step returned ``terminated`` or ``truncated`` (notably the ``TimeLimit``'s
    truncation, which the env underneath does not see) until ``reset``. Registered with every id."""

    def __init__(self, env: gymnasium.Env) -> None:
        gymnasium.utils.RecordConstructorArgs.__init__(self)
        gymnasium.Wrapper.__init__(self, env)
        self._gate = EpisodeGate(type(env.unwrapped).__name__)

    def reset(self, **kwargs):
        result = self.env.reset(**kwargs)
        self._gate.open()
        return result

    def step(self, action):
        self._gate.check()
        observation, reward, terminated, truncated, info = self.env.step(action)
        self._gate.close_if(bool(terminated) or bool(truncated))
        return observation, reward, terminated, truncated, info
