"""MJCF names of the lab scene in one place, and the ids they resolve to (style of mujoco_playground's
``go1_constants.py``). Loading goes through :mod:`embodied_adhoc.paths`, so it works from a wheel too."""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from embodied_adhoc import paths
from embodied_adhoc.errors import SceneError

LAB_SCENE = "lab.xml"
ROBOT_BASE = "base"
ROBOT_ROOT_JOINT = "root"
WHEEL_JOINTS = ("left_wheel", "right_wheel")
WHEEL_ACTUATORS = ("left_wheel", "right_wheel")
WHEEL_POSITION_SENSORS = ("left_wheel_pos", "right_wheel_pos")
WHEEL_VELOCITY_SENSORS = ("left_wheel_vel", "right_wheel_vel")
GYRO_SENSOR = "gyro"
RFID_SITE = "rfid"
HUMAN_BODY = "human"
HUMAN_HAND = "human_hand"
BALLS = ("ball_0", "ball_1", "ball_2")
BALL_COLOURS = ("red", "yellow", "blue")
GRASP_WELDS = ("grasp_0", "grasp_1", "grasp_2")
WALL_PREFIXES = ("wall_", "partition_")
CAMERA_ALIASES = {"robot": "robot_camera"}
FLOOR_TILES = ("floor_door", "floor_open", "floor_station", "floor_single", "floor_double")
"""Visual floor geoms; each has a textured material of the same name and a ``<name>_plain`` one."""


def load_lab_model(scene: str = LAB_SCENE) -> mujoco.MjModel:
    """Compile a scene from ``scenes/``; a SceneError names the file and MuJoCo's message."""
    path = paths.scene(scene)
    try:
        return mujoco.MjModel.from_xml_path(str(path))
    except ValueError as error:
        raise SceneError(f"{path}: MuJoCo could not compile the scene: {error}") from error


def _id(model: mujoco.MjModel, kind: mujoco.mjtObj, name: str) -> int:
    index = mujoco.mj_name2id(model, kind, name)
    if index < 0:
        raise SceneError(
            f"scene has no {kind.name[6:].lower()} named '{name}' (see embodied_adhoc/sim/lab_model.py)"
        )
    return index


@dataclass(frozen=True)
class LabIds:
    """Indices into the model/data arrays for everything the world reads or writes."""

    base_body: int
    root_qpos: int  # qpos address of the robot's free joint (x y z qw qx qy qz)
    root_dof: int
    wheel_qpos: np.ndarray
    wheel_actuators: np.ndarray
    wheel_position_sensors: np.ndarray  # sensordata addresses
    wheel_velocity_sensors: np.ndarray
    gyro_sensor: int
    rfid_site: int
    human_mocap: int
    hand_mocap: int
    ball_bodies: np.ndarray
    ball_qpos: np.ndarray  # (n_balls,) qpos address of each free joint
    ball_dof: np.ndarray
    grasp_welds: np.ndarray
    robot_geoms: np.ndarray
    wall_geoms: np.ndarray
    robot_geom_mask: np.ndarray  # (ngeom,) bool lookup tables for contact checks
    wall_geom_mask: np.ndarray
    floor_tiles: np.ndarray  # geom ids of the visual floor tiles
    floor_textured: np.ndarray  # their textured materials ("high" render quality)
    floor_plain: np.ndarray  # their plain materials ("fast")

    @classmethod
    def resolve(cls, model: mujoco.MjModel) -> LabIds:
        obj = mujoco.mjtObj
        base = _id(model, obj.mjOBJ_BODY, ROBOT_BASE)
        root = _id(model, obj.mjOBJ_JOINT, ROBOT_ROOT_JOINT)
        wheels = [_id(model, obj.mjOBJ_JOINT, name) for name in WHEEL_JOINTS]
        ball_joints = [_id(model, obj.mjOBJ_JOINT, name) for name in BALLS]
        geom_names = [mujoco.mj_id2name(model, obj.mjOBJ_GEOM, g) or "" for g in range(model.ngeom)]
        robot_geoms = np.flatnonzero(model.body_rootid[model.geom_bodyid] == base)
        wall_geoms = np.array([g for g, name in enumerate(geom_names) if name.startswith(WALL_PREFIXES)])

        robot_mask = np.zeros(model.ngeom, dtype=bool)
        robot_mask[robot_geoms] = True
        wall_mask = np.zeros(model.ngeom, dtype=bool)
        wall_mask[wall_geoms] = True

        def sensor_address(name: str) -> int:
            return int(model.sensor_adr[_id(model, obj.mjOBJ_SENSOR, name)])

        return cls(
            base_body=base,
            root_qpos=int(model.jnt_qposadr[root]),
            root_dof=int(model.jnt_dofadr[root]),
            wheel_qpos=model.jnt_qposadr[wheels].copy(),
            wheel_actuators=np.array([_id(model, obj.mjOBJ_ACTUATOR, n) for n in WHEEL_ACTUATORS]),
            wheel_position_sensors=np.array([sensor_address(n) for n in WHEEL_POSITION_SENSORS]),
            wheel_velocity_sensors=np.array([sensor_address(n) for n in WHEEL_VELOCITY_SENSORS]),
            gyro_sensor=sensor_address(GYRO_SENSOR),
            rfid_site=_id(model, obj.mjOBJ_SITE, RFID_SITE),
            human_mocap=int(model.body_mocapid[_id(model, obj.mjOBJ_BODY, HUMAN_BODY)]),
            hand_mocap=int(model.body_mocapid[_id(model, obj.mjOBJ_BODY, HUMAN_HAND)]),
            ball_bodies=np.array([_id(model, obj.mjOBJ_BODY, name) for name in BALLS]),
            ball_qpos=model.jnt_qposadr[ball_joints].copy(),
            ball_dof=model.jnt_dofadr[ball_joints].copy(),
            grasp_welds=np.array([_id(model, obj.mjOBJ_EQUALITY, name) for name in GRASP_WELDS]),
            robot_geoms=robot_geoms,
            wall_geoms=wall_geoms,
            robot_geom_mask=robot_mask,
            wall_geom_mask=wall_mask,
            floor_tiles=np.array([_id(model, obj.mjOBJ_GEOM, name) for name in FLOOR_TILES]),
            floor_textured=np.array([_id(model, obj.mjOBJ_MATERIAL, name) for name in FLOOR_TILES]),
            floor_plain=np.array([_id(model, obj.mjOBJ_MATERIAL, f"{name}_plain") for name in FLOOR_TILES]),
        )


def yaw_of(quat: np.ndarray) -> float:
    """Heading (rad) of a (w, x, y, z) quaternion: rotation about world z of the body x axis."""
    w, x, y, z = quat
    return float(np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z)))
