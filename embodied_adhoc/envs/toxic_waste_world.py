"""Build the MuJoCo lab world of ``EmbodiedAdhoc/ToxicWaste-v0`` from the env's kwargs (one place for the mapping)."""

from __future__ import annotations

import dataclasses

from embodied_adhoc.errors import ConfigError


def make_world(
    encoder_noise: float | None,
    wheel_slip: float | None,
    rfid_miss: float,
    macro_timeout: float,
    frame_rate: float,
    width: int,
    height: int,
    render_quality: str = "fast",
    localisation: bool = True,
    lidar_noise: float | None = None,
    lidar_dropout: float | None = None,
    area_accuracy: float = 1.0,
):
    """A ``sim.lab_world.LabWorld`` with the env's odometry noise, RFID miss rate, timeout, frame rate,
    rendering settings, lidar noise/dropout, localiser (``localisation=False``: wheel odometry alone) and the
    accuracy of the robot's area sensor (``sim.area_sensor``)."""
    from embodied_adhoc.sim.lab_world import LabWorld, LabWorldConfig
    from embodied_adhoc.sim.lidar import LidarConfig
    from embodied_adhoc.sim.localisation import LocalisationConfig
    from embodied_adhoc.sim.odometry import OdometryConfig

    if not float(frame_rate) > 0:
        raise ConfigError(f"frame_rate must be > 0 frames per simulated second, got {frame_rate}")
    odometry = OdometryConfig()
    if encoder_noise is not None:
        odometry = dataclasses.replace(odometry, encoder_noise=float(encoder_noise))
    if wheel_slip is not None:
        odometry = dataclasses.replace(odometry, wheel_slip=float(wheel_slip))
    lidar = LidarConfig()
    if lidar_noise is not None:
        lidar = dataclasses.replace(lidar, noise=float(lidar_noise))
    if lidar_dropout is not None:
        lidar = dataclasses.replace(lidar, dropout=float(lidar_dropout))
    config = LabWorldConfig(
        odometry=odometry,
        lidar=lidar,
        localisation=LocalisationConfig() if localisation else None,
        rfid_miss_probability=float(rfid_miss),
        area_accuracy=float(area_accuracy),
        macro_timeout=float(macro_timeout),
        video_fps=float(frame_rate),
        render_width=int(width),
        render_height=int(height),
        render_quality=render_quality,
    )
    return LabWorld(config)
