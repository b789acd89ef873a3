from __future__ import annotations
from dataclasses import dataclass
import numpy as np

@dataclass(frozen=True)
class ImuSample:          # at the IMU's mount site, body(IMU) frame = the mount site's frame
    t: float              # measurement time [s]
    acc: np.ndarray       # (3,) specific force [m/s^2], site frame (MuJoCo accelerometer: includes -gravity, i.e. +9.81 up at rest)
    gyro: np.ndarray      # (3,) angular velocity [rad/s], site frame

@dataclass(frozen=True)
class DvlSample:
    t: float              # measurement time [s]
    t_arrival: float      # when the controller gets it [s]
    velocity: np.ndarray | None   # (3,) velocity over ground of the DVL site, DVL site frame [m/s]; None = dropout
    beams_valid: tuple[bool, ...] = ()

@dataclass(frozen=True)
class DepthSample:
    t: float
    t_arrival: float
    depth: float          # [m], positive down: depth = -(z_world of the sensor site)

@dataclass(frozen=True)
class FixSample:          # USBL / camera position fix
    t: float              # measurement time [s]
    t_arrival: float      # arrival time [s] (t_arrival - t = latency)
    position: np.ndarray  # (3,) world position of the vehicle's reference point (the fix site) [m]
    yaw: float | None = None   # [rad], world, when the fix gives heading (camera)

@dataclass(frozen=True)
class Mount:              # a sensor's mount on the vehicle: the site's pose in the vehicle body frame
    position: np.ndarray  # (3,) [m], vehicle body frame
    quat: np.ndarray      # (4,) w x y z, site frame -> vehicle body frame
