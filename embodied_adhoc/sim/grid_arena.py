"""MJCF of the grid arenas (level-based foraging, predator-prey): a checkered cell floor, boundary walls, N
copies of the small differential-drive robot (``assets/robots/grid_robot``), apples or prey robots, an overhead
camera and an overhead camera. The arena carries its map: cell <-> world.

Composed with ``dm_control.mjcf`` (each robot attached under its own namespace ``agent<i>/`` or ``prey<m>/``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from embodied_adhoc import paths
from embodied_adhoc.domains.grid_rules import GridConfig

ROBOT_FILE = "robots/grid_robot/grid_robot.xml"
OFFSCREEN_SIZE = 640
"""Side of the arenas' offscreen framebuffer (``<visual><global offwidth offheight>``): the largest frame."""
AGENT_RGBA = ((0.95, 0.55, 0.1, 1.0), (0.2, 0.4, 0.9, 1.0), (0.3, 0.7, 0.9, 1.0), (0.5, 0.3, 0.9, 1.0))
PREY_RGBA = (0.85, 0.1, 0.1, 1.0)


@dataclass(frozen=True)
class ArenaLayout:
    """Geometry of one arena: the map between grid cells and world metres (row 0 is north, +y)."""

    rows: int
    cols: int
    cell: float = 0.25  # m, cell side
    wall_height: float = 0.08

    def cell_xy(self, cells: np.ndarray) -> np.ndarray:
        """World (x, y) of cell centres, (..., 2)."""
        cells = np.asarray(cells, dtype=float)
        x = (cells[..., 1] - (self.cols - 1) / 2) * self.cell
        y = ((self.rows - 1) / 2 - cells[..., 0]) * self.cell
        return np.stack([x, y], axis=-1)

    def xy_cell(self, xy: np.ndarray) -> np.ndarray:
        """Cells containing world points (nearest centre, clipped to the grid), (..., 2) int."""
        xy = np.asarray(xy, dtype=float)
        col = np.rint(xy[..., 0] / self.cell + (self.cols - 1) / 2)
        row = np.rint((self.rows - 1) / 2 - xy[..., 1] / self.cell)
        cells = np.stack([row, col], axis=-1).astype(np.int64)
        return np.clip(cells, 0, [self.rows - 1, self.cols - 1])


def apple_radius(layout: ArenaLayout, level: int, max_level: int) -> float:
    """Apples grow with their level: from 0.18 to 0.4 cell widths."""
    return layout.cell * (0.18 + 0.22 * (level - 1) / max(1, max_level - 1))


def apple_rgba(level: int, max_level: int) -> tuple[float, float, float, float]:
    """Light green (level 1) to dark green (the highest level)."""
    shade = (level - 1) / max(1, max_level - 1)
    return (0.45 - 0.35 * shade, 0.9 - 0.45 * shade, 0.35 - 0.25 * shade, 1.0)


def build_arena(config: GridConfig, layout: ArenaLayout, timestep: float = 0.005):
    """The arena's ``mjcf.RootElement`` for ``config`` (agents ``agent<i>/``, prey ``prey<m>/``, apples
    ``apple<m>``), with the camera ``overhead``. (The ad hoc robot's egocentric view is a free camera placed
    above it at render time: see ``GridArenaBackend.egocentric_image``.)"""
    from dm_control import mjcf

    arena = mjcf.RootElement(model=f"{config.domain}_arena_{config.rows}x{config.cols}")
    arena.compiler.angle = "radian"
    arena.option.timestep = timestep
    arena.option.integrator = "implicitfast"
    visual_global = getattr(arena.visual, "global")
    visual_global.offwidth, visual_global.offheight = OFFSCREEN_SIZE, OFFSCREEN_SIZE
    arena.asset.add(
        "texture",
        name="cells",
        type="2d",
        builtin="checker",
        width=64,
        height=64,
        rgb1=[0.62, 0.62, 0.6],
        rgb2=[0.5, 0.52, 0.5],
    )
    arena.asset.add("material", name="cells", texture="cells", texrepeat=[config.cols / 2, config.rows / 2])
    width, height = layout.cols * layout.cell, layout.rows * layout.cell
    arena.worldbody.add(
        "light",
        name="sun",
        pos=[0, 0, 3],
        dir=[0, 0, -1],
        directional=True,
        diffuse=[0.5, 0.5, 0.5],
        specular=[0.1, 0.1, 0.1],
    )
    arena.worldbody.add(
        "geom",
        name="floor",
        type="plane",
        size=[width / 2, height / 2, 0.05],
        material="cells",
        friction=[1.0, 0.005, 0.0001],
    )
    thickness = 0.02
    for name, pos, size in (
        (
            "wall_north",
            [0, height / 2 + thickness, layout.wall_height / 2],
            [width / 2 + 2 * thickness, thickness],
        ),
        (
            "wall_south",
            [0, -height / 2 - thickness, layout.wall_height / 2],
            [width / 2 + 2 * thickness, thickness],
        ),
        ("wall_east", [width / 2 + thickness, 0, layout.wall_height / 2], [thickness, height / 2]),
        ("wall_west", [-width / 2 - thickness, 0, layout.wall_height / 2], [thickness, height / 2]),
    ):
        arena.worldbody.add(
            "geom",
            name=name,
            type="box",
            pos=pos,
            size=[*size, layout.wall_height / 2],
            rgba=[0.35, 0.3, 0.25, 1],
        )
    span = max(width, height)
    arena.worldbody.add(
        "camera",
        name="overhead",
        pos=[0, 0, 0.5 * span / math.tan(math.radians(22.5)) + 0.1],
        xyaxes=[1, 0, 0, 0, 1, 0],
        fovy=45,
    )

    robot_path = paths.asset(ROBOT_FILE)
    names = [f"agent{i}" for i in range(config.n_agents)]
    if config.domain == "pursuit":
        names += [f"prey{m}" for m in range(config.n_targets)]
    for index, name in enumerate(names):
        robot = mjcf.from_path(str(robot_path))
        robot.model = name
        rgba = PREY_RGBA if name.startswith("prey") else AGENT_RGBA[index % len(AGENT_RGBA)]
        robot.find("geom", "shell").rgba = list(rgba)
        frame = arena.attach(robot)
        frame.add("freejoint", name=f"{name}_free")
    if config.domain == "foraging":
        for m in range(config.n_targets):
            apple = arena.worldbody.add("body", name=f"apple{m}", mocap=True, pos=[0, 0, 0.05])
            apple.add(
                "geom",
                name=f"apple{m}",
                type="sphere",
                size=[0.05],
                contype=0,
                conaffinity=0,
                rgba=list(apple_rgba(1, 2)),
            )
    return arena
