"""The vehicle's station and path, for every floating-robot controller (``rac``, ``rac_dob``,
``pd``, ``station_pid``, ``task_priority``): the parameters they share, checked once.

* ``base_reference``: the pose to hold, the base's qpos (floating: x, y, z [m] world, qw, qx, qy,
  qz; planar: one number per base joint) -- a scenario's ``vehicle.setpoint`` or
  ``controller.base_reference: truth | nominal``.
* ``base_trajectory``: the vehicle origin's path, an object with ``position(t)`` (world [m]; and
  ``velocity(t)`` [m/s] for the controllers with a velocity feed-forward, ``station_pid`` and
  ``task_priority``) -- a scenario's ``vehicle.trajectory``. The desired position moves along
  it; the desired orientation stays the station's.
* ``station_attitude``: the attitude of the DEFAULT station (no ``base_reference``), on a
  floating (free-joint) vehicle:

  - ``"level"`` (default, :data:`DEFAULT_STATION_ATTITUDE`): roll = pitch = 0 at the first
    measurement's yaw (z-y-x convention, :func:`uvms_mj.rotations.rpy_from_quat`), with the first
    measurement's position. Our assumption, named here: an ROV is trimmed to be level (a
    neutrally buoyant vehicle with its centre of buoyancy above its centre of gravity has a
    passively stable, level roll/pitch), so a controller that starts tilted -- after a
    disturbance, a launch, a tilted initial state -- is to bring it level rather than hold the
    tilt. The level is the MEASUREMENT's: an attitude sensor with a bias levels the vehicle to
    minus that bias. Where the body x axis is vertical (|pitch| = 90 deg) the yaw is atan2 of
    round-off; the level station there has an arbitrary yaw.
  - ``"measured"``: the first measurement's attitude as it is (the station-keeping of the
    first measurement; what every controller did before the level default).

  A planar base (the paper's robot: its one rotation angle phi0 is a rotation in the vertical
  plane) always holds its first measurement (the paper's reference), so ``station_attitude``
  does not apply there (giving it is an error). Given with ``base_reference``, it is an error
  too (the reference's attitude is the one held).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from uvms_mj.control.base import ControllerError
from uvms_mj.rotations import quat_from_rpy, quat_to_mat, rpy_from_quat

__all__ = ["DEFAULT_STATION_ATTITUDE", "STATION_ATTITUDES", "check_base_reference", "check_base_trajectory",
           "check_station_attitude", "level_quaternion", "station_pose", "station_reference"]

#: The allowed ``station_attitude`` values (module docstring).
STATION_ATTITUDES = ("level", "measured")
#: The default station's attitude on a floating vehicle: level at the measured yaw (module docstring).
DEFAULT_STATION_ATTITUDE = "level"


def check_station_attitude(value: Any, free: bool, base_reference=None) -> str:
    """``station_attitude`` resolved: None -> :data:`DEFAULT_STATION_ATTITUDE` on a floating
    base, ``"measured"`` on a planar one (the paper's first measurement).

    Raises:
        ControllerError: not one of :data:`STATION_ATTITUDES`; given for a planar base; given
            with a ``base_reference``."""
    if value is None:
        return DEFAULT_STATION_ATTITUDE if free else "measured"
    if not isinstance(value, str) or value not in STATION_ATTITUDES:
        raise ControllerError(f"station_attitude = {value!r}; allowed: {', '.join(STATION_ATTITUDES)}")
    if not free:
        raise ControllerError(f"station_attitude = {value!r} applies to floating robots only (a planar base holds "
                              "its first measurement)")
    if base_reference is not None:
        raise ControllerError(f"station_attitude = {value!r} applies to the default station only; give either "
                              "station_attitude or base_reference (vehicle.setpoint), not both")
    return value


def level_quaternion(quat) -> np.ndarray:
    """The unit quaternion (w, x, y, z) with roll = pitch = 0 and ``quat``'s yaw (z-y-x):
    (cos(yaw/2), 0, 0, sin(yaw/2))."""
    return quat_from_rpy(0.0, 0.0, float(rpy_from_quat(quat)[2]))


def station_pose(base_q, base_reference=None, station_attitude: str = DEFAULT_STATION_ATTITUDE
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The floating vehicle's station: ``base_reference`` (7 numbers) if given, else the first
    measurement's pose ``base_q`` (x, y, z, qw, qx, qy, qz), levelled with ``station_attitude``
    "level". Returns the position (world [m]), the unit quaternion (w, x, y, z) and its
    rotation matrix."""
    pose = np.asarray(base_q if base_reference is None else base_reference, dtype=float)
    quat = pose[3:7] / np.linalg.norm(pose[3:7])
    if base_reference is None and station_attitude == "level":
        quat = level_quaternion(quat)
    return pose[:3].copy(), quat, quat_to_mat(quat)


def station_reference(q: np.ndarray, layout, base_reference=None, station_attitude: str = DEFAULT_STATION_ATTITUDE
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`station_pose` of the first measurement ``q`` (qpos), and the arm joint angles
    [rad] of ``q``: (position, quaternion, rotation matrix, joint angles)."""
    a = layout.base_qadr
    p, quat, R = station_pose(q[a:a + 7], base_reference, station_attitude)
    return p, quat, R, q[layout.joint_qadr].copy()


def check_base_reference(base_reference, size: int = 7) -> np.ndarray | None:
    """``base_reference`` as ``size`` numbers (floating, 7: x, y, z [m] world, qw, qx, qy, qz,
    a non-zero quaternion; planar: one per base joint), or None.

    Raises:
        ControllerError: not ``size`` finite numbers, or a zero quaternion."""
    if base_reference is None:
        return None
    try:
        ref = np.asarray(base_reference, dtype=float).ravel()
    except (TypeError, ValueError):
        ref = None
    what = ("7 finite numbers (x, y, z [m] world, qw, qx, qy, qz; a non-zero quaternion)" if size == 7
            else f"{size} finite numbers (one per base joint)")
    if ref is None or ref.shape != (size,) or not np.all(np.isfinite(ref)) or (
            size == 7 and np.linalg.norm(ref[3:]) < 1e-9):
        raise ControllerError(f"base_reference = {base_reference!r} must be {what}")
    return ref


def check_base_trajectory(base_trajectory, velocity: bool = False):
    """``base_trajectory`` as given (None, or an object with ``position(t)`` and, with
    ``velocity``, ``velocity(t)``).

    Raises:
        ControllerError: a method missing."""
    need = ("position", "velocity") if velocity else ("position",)
    if base_trajectory is not None and not all(callable(getattr(base_trajectory, n, None)) for n in need):
        raise ControllerError(f"base_trajectory = {base_trajectory!r} must have "
                              f"{' and '.join(n + '(t)' for n in need)} (world [m], [m/s]; the scenario's "
                              "vehicle.trajectory)")
    return base_trajectory
