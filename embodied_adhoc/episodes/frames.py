"""Frame sources: the one way a recording takes pictures of a simulated world while an episode runs.

A :class:`FrameSource` tells the recorder when a frame is due and gives it the picture of that instant, in two
halves so that drawing can run beside the simulation:

* :meth:`~FrameSource.listen` registers a callback the world calls on the simulation thread at every frame
  instant (``period`` simulated seconds apart) with a snapshot dict: ``sim_time``, optionally ``step``, and the
  poses the rerun recording shows (the lab: robot, odometry, localiser, human, balls; an arena: ``poses`` of
  every robot);
* :meth:`~FrameSource.take` copies what a picture shows, on the simulation thread (cheap);
  :meth:`~FrameSource.render` draws it, on the recorder's render thread, which also owns the GL context
  (:meth:`~FrameSource.prepare` when it starts, :meth:`~FrameSource.release` when it stops).

:class:`LabFrameSource` is the lab's (the env's frame sink and the world's snapshot renderer: ``mj_copyData`` on
the simulation thread, MuJoCo drawing on the render thread, where it releases the GIL). :class:`ArenaFrameSource`
is the grid arenas' (the backend's control-tick hook; the arena changes its model as well as its data, e.g. the
apples' sizes and colours, so a copy of the data alone would not show it: it draws on the simulation thread and
hands the finished picture over).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol, runtime_checkable

import numpy as np

__all__ = ["ArenaFrameSource", "FrameListener", "FrameSource", "LabFrameSource"]

FrameListener = Callable[[dict], None]


@runtime_checkable
class FrameSource(Protocol):
    """What a recording needs of a world (module docstring); ``width`` x ``height`` is the picture's size."""

    width: int
    height: int

    def sim_time(self) -> float: ...

    def listen(self, listener: FrameListener | None) -> None: ...

    def take(self, camera: str, markers: bool) -> Any: ...

    def render(self, taken: Any) -> np.ndarray: ...

    def prepare(self) -> None: ...

    def release(self) -> None: ...


class LabFrameSource:
    """The physics lab (``EmbodiedAdhoc/ToxicWaste-v0``, unwrapped ``env``) as a frame source: the env calls the
    listener ``frame_rate`` times per simulated second (its keyword argument, which the recorded run sets to the
    video's rate); cameras are the lab's ("overhead", "robot", ...); ``markers`` draws what the robot believes on
    the overhead camera."""

    def __init__(self, env, width: int, height: int):
        self.env, self.world = env, env.world
        self.width, self.height = int(width), int(height)
        self.high = self.world.config.render_quality == "high"
        self._renderer = self.world.snapshot_renderer()

    def sim_time(self) -> float:
        return float(self.world.data.time)

    def listen(self, listener: FrameListener | None) -> None:
        self.env.set_frame_sink(listener)

    def take(self, camera: str, markers: bool) -> tuple:
        world = self.world
        return camera, markers, self._renderer.take(world.data, world.belief_markers() if markers else None)

    def render(self, taken: tuple) -> np.ndarray:
        camera, markers, snapshot = taken
        return self._renderer.render(snapshot, camera, self.width, self.height, self.high, markers)

    def prepare(self) -> None:
        self._renderer.prepare(self.width, self.height, self.high)

    def release(self) -> None:
        self._renderer.close()


class ArenaFrameSource:
    """A grid arena as a frame source: ``view`` draws (``render_top(size)``) and gives the robots' poses
    (``poses()``), ``backend`` is its :class:`~embodied_adhoc.sim.grid_arena_world.GridArenaBackend` (control-tick
    hook), ``clock()`` the simulated time. A frame is due ``period`` simulated seconds after the last picture taken
    (a frame instant's or one the recorder takes after a step); the picture is the overhead camera (square,
    ``size`` pixels), drawn when taken."""

    def __init__(self, view, backend, clock: Callable[[], float], size: int, period: float):
        self.view, self.backend, self.clock = view, backend, clock
        self.width = self.height = int(size)
        self.period = float(period)
        self._next = 0.0
        self._listener: FrameListener | None = None

    def sim_time(self) -> float:
        return float(self.clock())

    def listen(self, listener: FrameListener | None) -> None:
        self._listener = listener
        self.backend.on_tick = None if listener is None else self._on_tick

    def _on_tick(self, _seconds_into_step: float) -> None:
        sim_time = self.sim_time()
        if sim_time + 1e-9 >= self._next:
            self._listener({"sim_time": sim_time, "poses": self.view.poses()})

    def take(self, camera: str, markers: bool) -> np.ndarray:
        self._next = self.sim_time() + self.period
        return self.view.render_top(self.width)

    def render(self, taken: np.ndarray) -> np.ndarray:
        return taken

    def prepare(self) -> None:
        """Nothing to make: the arena draws on the simulation thread, with the env's own renderer."""

    def release(self) -> None:
        """Nothing to release (the env closes its renderer)."""
