"""Rotations: quaternions (w, x, y, z), rotation matrices, rotation vectors, roll/pitch/yaw.

Small pure functions shared by the robots, the sampled loop and the controllers. Roll/pitch/yaw
are the z-y-x (yaw, then pitch, then roll) Tait-Bryan angles of a body's axes relative to the
world: R = Rz(yaw) Ry(pitch) Rx(roll). A rotation vector is axis times angle [rad].
"""

from __future__ import annotations

import math
from typing import Sequence

import mujoco
import numpy as np

__all__ = ["mat_to_quat", "quat_from_rotvec", "quat_from_rpy", "quat_mul", "quat_to_mat", "rotation_log",
           "rpy_from_quat"]


def quat_from_rpy(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of R = Rz(yaw) Ry(pitch) Rx(roll) [rad]."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return np.array([cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
                     cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy])


def rpy_from_quat(q: Sequence[float]) -> np.ndarray:
    """(roll, pitch, yaw) [rad] of a quaternion (w, x, y, z) (z-y-x convention, as
    :func:`quat_from_rpy`; pitch in [-pi/2, pi/2])."""
    w, x, y, z = np.asarray(q, dtype=float) / np.linalg.norm(q)
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return np.array([roll, pitch, yaw])


def quat_to_mat(q: Sequence[float]) -> np.ndarray:
    """Rotation matrix of a quaternion (w, x, y, z) (normalised here)."""
    w, x, y, z = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def mat_to_quat(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a rotation matrix (``mju_mat2Quat``)."""
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(R, dtype=float).ravel())
    return q


def rotation_log(R: np.ndarray) -> np.ndarray:
    """Rotation vector (axis times angle [rad], angle in [0, pi]) of a rotation matrix."""
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = np.asarray(R, dtype=float).tolist()
    c = max(-1.0, min(1.0, 0.5 * (r00 + r11 + r22 - 1.0)))
    a = math.acos(c)
    wx, wy, wz = r21 - r12, r02 - r20, r10 - r01
    if a < 1e-6:
        return np.array([0.5 * wx, 0.5 * wy, 0.5 * wz])
    if math.pi - a < 1e-6:  # near pi: axis from the symmetric part
        B = 0.5 * (np.asarray(R, dtype=float) + np.eye(3))
        axis = np.sqrt(np.clip(np.diag(B), 0.0, None))
        i = int(np.argmax(axis))
        axis = B[i] / max(axis[i], 1e-12)
        return a * axis / np.linalg.norm(axis)
    k = a / (2.0 * math.sin(a))
    return np.array([k * wx, k * wy, k * wz])


def quat_from_rotvec(rv: np.ndarray) -> np.ndarray:
    """Quaternion (w, x, y, z) of the rotation vector rv [rad]."""
    a = float(np.linalg.norm(rv))
    if a < 1e-300:
        return np.array([1.0, 0.0, 0.0, 0.0])
    return np.concatenate(([math.cos(a / 2)], math.sin(a / 2) * np.asarray(rv, dtype=float) / a))


def quat_mul(a: Sequence[float], b: Sequence[float]) -> np.ndarray:
    """Hamilton product a b of two quaternions (w, x, y, z)."""
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])
