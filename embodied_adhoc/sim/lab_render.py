"""Offscreen rendering of the lab: what ``LabWorld.render`` draws, and the same picture of a snapshot drawn later on
another thread (``run --record`` renders its video there, beside the simulation).

:class:`LabRenderer` draws an ``MjData`` of the lab model from a named camera, with the belief markers on the
overhead camera if asked. ``LabWorld.render`` uses one on its own data. For rendering off the simulation thread,
``LabWorld.snapshot_renderer()`` gives a :class:`SnapshotRenderer`: it holds its own copy of the model (its GL
context and the per-render material switch touch no state the simulation reads), :meth:`SnapshotRenderer.take`
copies what a frame shows on the simulation thread (``mj_copyData`` into a recycled ``MjData``: a few
microseconds), and :meth:`SnapshotRenderer.render` draws it on the rendering thread, pixel for pixel the picture
``LabWorld.render`` would have drawn at the instant of the snapshot.
"""

from __future__ import annotations

import copy
import queue
from dataclasses import dataclass

import mujoco
import numpy as np

from embodied_adhoc.errors import ConfigError
from embodied_adhoc.sim.lab_model import CAMERA_ALIASES, LAB_SCENE, LabIds

__all__ = ["BeliefMarkers", "LabRenderer", "LabSnapshot", "SnapshotRenderer", "check_render_size"]

FAST_TESSELLATION = (10, 6, 1)
"""Slices and stacks of round shapes and quads per plane side of "fast" renders (``<quality numslices numstacks
numquads>``; the scene's own values serve "high")."""
MARKER_HEIGHT = 1.3
MAX_PARTICLE_MARKERS = 50


@dataclass(frozen=True)
class BeliefMarkers:
    """What the robot believes, drawn above it on overhead renders: the localiser's particles (xy, already thinned
    to at most ``MAX_PARTICLE_MARKERS``) and estimate (x, y, yaw), None without a localiser, and the odometry
    pose."""

    particles: np.ndarray | None
    estimate: tuple[float, float, float] | None
    odometry: tuple[float, float, float]


@dataclass(frozen=True)
class LabSnapshot:
    """A frame's content copied at one simulated instant (:meth:`SnapshotRenderer.take`)."""

    data: mujoco.MjData
    markers: BeliefMarkers | None


class LabRenderer:
    """Offscreen renders of ``model`` (one ``mujoco.Renderer`` per size and quality, made on first use). Use it
    from one thread only: its GL contexts are made current on the calling thread."""

    def __init__(self, model: mujoco.MjModel, ids: LabIds):
        self.model, self.ids = model, ids
        self._renderers: dict[tuple[int, int, bool], mujoco.Renderer] = {}
        # images show the world, not the sensors: no lidar rays (MuJoCo draws every rangefinder by default)
        self._scene_option = mujoco.MjvOption()
        self._scene_option.flags[mujoco.mjtVisFlag.mjVIS_RANGEFINDER] = False

    def render(
        self,
        data: mujoco.MjData,
        camera: str,
        width: int,
        height: int,
        high: bool,
        markers: BeliefMarkers | None = None,
    ) -> np.ndarray:
        """An RGB image (uint8, H x W x 3) of ``data`` from ``camera`` ("overhead", "perspective", "robot");
        ``high``: shadows, reflections, the textured floor and the scene's anti-aliasing and tessellation;
        ``markers`` are drawn on the overhead camera only."""
        name = CAMERA_ALIASES.get(camera, camera)
        if mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_CAMERA, name) < 0:
            cameras = [self.model.camera(i).name for i in range(self.model.ncam)]
            raise ConfigError(f"no camera '{camera}' in the lab scene; available: {cameras} (or 'robot')")
        _check_size(width, height, self.model.vis.global_.offwidth, self.model.vis.global_.offheight)
        renderer = self.prepare(width, height, high)
        self.model.geom_matid[self.ids.floor_tiles] = (
            self.ids.floor_textured if high else self.ids.floor_plain
        )
        renderer.update_scene(data, camera=name, scene_option=self._scene_option)
        renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = high
        renderer.scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = high
        if markers is not None and name == "overhead":
            _draw_markers(renderer.scene, markers)
        return renderer.render()

    def prepare(self, width: int, height: int, high: bool) -> mujoco.Renderer:
        """The renderer for frames of this size and quality, made now if it is new (making its GL context is
        slow with software EGL, so each size and quality gets one, kept for later frames)."""
        renderer = self._renderers.get((width, height, high))
        if renderer is None:
            renderer = self._make_renderer(width, height, high)
            self._renderers[(width, height, high)] = renderer
        return renderer

    def close(self) -> None:
        """Release the offscreen renderers (their GL contexts); call it on the thread that rendered."""
        for renderer in self._renderers.values():
            renderer.close()
        self._renderers.clear()

    def _make_renderer(self, width: int, height: int, high: bool) -> mujoco.Renderer:
        """An offscreen renderer whose framebuffer is exactly ``width`` x ``height``; "fast" quality also drops
        multisample anti-aliasing and tessellates round shapes more coarsely. MuJoCo sizes the framebuffer from
        ``<global offwidth offheight>`` and ``<quality offsamples>`` (1920x1536 and 4 samples in
        ``scenes/lab.xml``, for stills) when the context is made; with software EGL, clearing and resolving that
        buffer would dominate the cost of a small frame. Spheres, capsules and cylinders are drawn with
        ``FAST_TESSELLATION`` (slices, stacks, quads per plane side) instead of the scene's 28/16/4: at the
        overhead camera's scale (a ball is ~10 px) it looks the same and software rendering has fewer triangles
        to draw. The model's values are restored right after."""
        visual = self.model.vis
        settings = [(visual.global_, "offwidth", width), (visual.global_, "offheight", height)]
        if not high:
            slices, stacks, quads = FAST_TESSELLATION
            quality = visual.quality
            settings += [(quality, "offsamples", 0), (quality, "numslices", slices)]
            settings += [(quality, "numstacks", stacks), (quality, "numquads", quads)]
        saved = [(owner, name, getattr(owner, name)) for owner, name, _ in settings]
        for owner, name, value in settings:
            setattr(owner, name, value)
        try:
            return mujoco.Renderer(self.model, height=height, width=width)
        finally:
            for owner, name, value in saved:
                setattr(owner, name, value)


def _check_size(width: int, height: int, max_width: int, max_height: int) -> None:
    if not (1 <= width <= max_width and 1 <= height <= max_height):
        raise ConfigError(
            f"render size {width}x{height} outside 1x1..{max_width}x{max_height} (the scene's offscreen "
            "buffer, <visual><global offwidth offheight> in scenes/lab.xml)"
        )


def check_render_size(width: int, height: int, scene: str = LAB_SCENE) -> None:
    """Refuse a frame size the renderer would refuse, before any model is compiled: the limit is the scene's
    ``<visual><global offwidth offheight>``, read from its parsed MJCF (``MjSpec``, milliseconds)."""
    from embodied_adhoc import paths

    visual = mujoco.MjSpec.from_file(str(paths.scene(scene))).visual.global_
    _check_size(width, height, visual.offwidth, visual.offheight)


class SnapshotRenderer:
    """Render snapshots of a world on another thread (module docstring). :meth:`take` runs on the simulation
    thread, :meth:`render` and :meth:`close` on the rendering thread. A rendered snapshot's ``MjData`` goes back to
    a free list, so a recording allocates only as many as are in flight."""

    def __init__(self, model: mujoco.MjModel, ids: LabIds):
        self._source_model = model
        self._renderer = LabRenderer(copy.deepcopy(model), ids)
        self._free: queue.SimpleQueue = queue.SimpleQueue()

    def take(self, data: mujoco.MjData, markers: BeliefMarkers | None) -> LabSnapshot:
        """Copy ``data`` (everything a render reads) and the markers to draw; simulation thread."""
        try:
            copied = self._free.get_nowait()
        except queue.Empty:
            copied = mujoco.MjData(self._source_model)
        mujoco.mj_copyData(copied, self._source_model, data)
        return LabSnapshot(copied, markers)

    def render(
        self, snapshot: LabSnapshot, camera: str, width: int, height: int, high: bool, markers: bool
    ) -> np.ndarray:
        """The picture of ``snapshot`` (with its markers if ``markers``); rendering thread. The snapshot is spent:
        its ``MjData`` is reused by a later :meth:`take`."""
        try:
            return self._renderer.render(
                snapshot.data, camera, width, height, high, snapshot.markers if markers else None
            )
        finally:
            self._free.put(snapshot.data)

    def prepare(self, width: int, height: int, high: bool) -> None:
        """Make the GL context for frames of this size and quality ahead of the first frame; rendering thread."""
        self._renderer.prepare(width, height, high)

    def close(self) -> None:
        """Release the GL contexts; rendering thread."""
        self._renderer.close()


def _draw_markers(scene: mujoco.MjvScene, markers: BeliefMarkers) -> None:
    """Append the belief markers to ``scene`` as decor geoms (drawn, never simulated): particles as blue dots, the
    estimate as a blue square with a heading bar, the odometry pose as an orange one; flat boxes, the cheapest geoms
    for software rendering."""
    identity = np.eye(3).ravel()
    height = MARKER_HEIGHT

    def add(kind: int, size, pos, rgba, mat=identity) -> None:
        if scene.ngeom >= scene.maxgeom:
            return  # the scene is full: the markers are decoration, the image stays valid without them
        mujoco.mjv_initGeom(
            scene.geoms[scene.ngeom],
            kind,
            np.asarray(size, float),
            np.asarray(pos, float),
            np.asarray(mat, float),
            np.asarray(rgba, np.float32),
        )
        scene.ngeom += 1

    def pose_marker(pose, rgba, z) -> None:
        x, y, yaw = pose
        c, s = np.cos(yaw), np.sin(yaw)
        rotation = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).ravel()
        add(mujoco.mjtGeom.mjGEOM_BOX, (0.08, 0.08, 0.005), (x, y, z), rgba, rotation)
        add(
            mujoco.mjtGeom.mjGEOM_BOX,
            (0.12, 0.02, 0.006),
            (x + 0.16 * c, y + 0.16 * s, z),
            rgba,
            rotation,
        )

    if markers.particles is not None:
        for x, y in markers.particles:
            add(mujoco.mjtGeom.mjGEOM_BOX, (0.02, 0.02, 0.004), (x, y, height), (0.35, 0.6, 1.0, 0.9))
    if markers.estimate is not None:
        pose_marker(markers.estimate, (0.1, 0.35, 1.0, 1.0), height + 0.02)
    pose_marker(markers.odometry, (1.0, 0.55, 0.0, 1.0), height + 0.04)
