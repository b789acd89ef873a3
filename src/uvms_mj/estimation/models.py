"""Measurement models of the ESKF (:mod:`uvms_mj.estimation.eskf`): predicted measurement ``h(x)`` and its Jacobian
``H`` against the 15-dim error state (dp, dv, dtheta, da_b, dw_b), ``dtheta`` local (``R_true = R Exp(dtheta)``).

Solà (arXiv:1711.02508, 2017) Sec. 6.1.1, Eq. 278-280 write ``H = H_x X_dx``; here the product is derived by hand
with ``R Exp(dtheta) u ~ R u + R [dtheta]x u = R u - R [u]x dtheta`` (first order, Eq. 196's small-angle
``Exp(dtheta) ~ I + [dtheta]x``). ``x`` is the nominal vector (p 0:3, v 3:6, q 6:10, a_b 10:13, w_b 13:16).
"""

from __future__ import annotations

import math

import numpy as np

from uvms_mj.rotations import quat_to_mat

__all__ = ["EstimatorError", "cross", "depth_model", "dvl_model", "fix_model", "skew", "so3_exp", "yaw_model"]


class EstimatorError(ValueError):
    """Bad estimator parameter or sample; the message names the field, the value and what is allowed."""


def skew(u: np.ndarray) -> np.ndarray:
    """[u]x, the cross-product matrix: skew(u) @ v = u x v."""
    return np.array([[0.0, -u[2], u[1]], [u[2], 0.0, -u[0]], [-u[1], u[0], 0.0]])


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b for (3,) vectors (a lean np.cross)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def so3_exp(rv: np.ndarray) -> np.ndarray:
    """Rotation matrix of a rotation vector (Rodrigues, Solà Eq. 77)."""
    a = float(np.linalg.norm(rv))
    K = skew(rv)
    if a < 1e-8:
        return np.eye(3) + K + 0.5 * K @ K
    return np.eye(3) + math.sin(a) / a * K + (1.0 - math.cos(a)) / (a * a) * K @ K


def dvl_model(x: np.ndarray, w: np.ndarray, R_imu: np.ndarray, r_dvl: np.ndarray, R_dvl: np.ndarray):
    """Velocity over ground of the DVL site in its frame, ``v_dvl = R_m^T (R^T v + w x r)`` [m/s]; ``w`` the body
    rate (vehicle body frame, from the gyro: ``w = R_imu (w_m - w_b)``), ``r_dvl``/``R_dvl`` the DVL mount."""
    R = quat_to_mat(x[6:10])
    vb = R.T @ x[3:6]
    h = R_dvl.T @ (vb + cross(w, r_dvl))
    H = np.zeros((3, 15))
    H[:, 3:6] = R_dvl.T @ R.T
    H[:, 6:9] = R_dvl.T @ skew(vb)
    H[:, 12:15] = R_dvl.T @ skew(r_dvl) @ R_imu
    return h, H


def depth_model(x: np.ndarray, r: np.ndarray):
    """Depth [m, positive down] of the sensor at ``r`` (body): ``-(p + R r)_z``; H (15,)."""
    R = quat_to_mat(x[6:10])
    h = -(x[2] + R[2] @ r)
    H = np.zeros(15)
    H[2] = -1.0
    H[6:9] = R[2] @ skew(r)
    return float(h), H


def fix_model(x: np.ndarray, r: np.ndarray):
    """World position of the fix site at ``r`` (body): ``p + R r``; H (3, 15)."""
    R = quat_to_mat(x[6:10])
    H = np.zeros((3, 15))
    H[:, 0:3] = np.eye(3)
    H[:, 6:9] = -R @ skew(r)
    return x[0:3] + R @ r, H


def yaw_model(x: np.ndarray, R_fix: np.ndarray):
    """Yaw [rad] (z-y-x, world) of the fix site's frame ``M = R R_fix``: ``atan2(M10, M00)``; H (15,) from
    ``dM = [R dtheta]x M``: d yaw / d phi = (-M00 M20, -M10 M20, M00^2 + M10^2) / (M00^2 + M10^2)."""
    R = quat_to_mat(x[6:10])
    M = R @ R_fix
    n = M[0, 0] ** 2 + M[1, 0] ** 2
    if n < 1e-9:
        raise EstimatorError("yaw fix: the fix frame's x axis is vertical (pitch +-90 deg), yaw undefined")
    dphi = np.array([-M[0, 0] * M[2, 0] / n, -M[1, 0] * M[2, 0] / n, 1.0])
    H = np.zeros(15)
    H[6:9] = dphi @ R
    return math.atan2(M[1, 0], M[0, 0]), H
