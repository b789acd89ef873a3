"""What the environments read from a robot's model: the action layout and bounds, the observation
layout and the name of every component (:mod:`uvms_mj.rl.env`), for any robot.

Actions: the thrusters (:attr:`~uvms_mj.plant.layout.Layout.thruster_names` order, thrust [N] along
each thruster's axis), then the joint motors (:attr:`~uvms_mj.plant.layout.Layout.motor_names`
order, torque [N m]). Bounds (:func:`action_bounds`):

* thrust: the model's thruster force range (``actuator_forcerange``); for a unit-gain thruster
  (whose command is the thrust itself, e.g. the paper's) intersected with its ``ctrlrange``.
  The paper's: -8.849 / +15.978 N; the BlueROV2's T200: +-30.622 N. A thruster without either
  range is refused (ValueError naming it).
* torque: +-``torque_limit`` (default 20 N m, :data:`uvms_mj.rl.env.DEFAULT_TORQUE_LIMIT`)
  intersected with the motor's ``ctrlrange`` and ``forcerange`` where the model gives them (the
  paper's motors have none: +-20 N m; the Alpha's: +-9 N m and +-5 N m for the wrist).

Observation components are named (:func:`observation_names`): positions by world axis (``x``,
``y``, ``z``), a free vehicle's attitude by its quaternion (``qw``, ``qx``, ``qy``, ``qz``), a
planar base's hinge by the angle about its axis (``roll``, ``pitch``, ``yaw`` about x, y, z), its
velocities ``vx``.. (world) and ``wx``.. (a free vehicle's: body frame), joints by joint name,
thrusters and motors by actuator name.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

__all__ = ["action_bounds", "action_names", "observation_names"]

_AXES = "xyz"
_ANGLES = ("roll", "pitch", "yaw")


def action_names(layout) -> list[str]:
    """The action's components: thruster names, then motor names."""
    return [*layout.thruster_names, *layout.motor_names]


def action_bounds(m: mujoco.MjModel, layout, torque_limit: float, direct: bool) -> tuple[np.ndarray, np.ndarray]:
    """(low, high) of the plain action (module docstring); ``direct``: the thrusters' command is the
    thrust [N] (:attr:`uvms_mj.plant.plant.Plant` of unit-gain thrusters).

    Raises:
        ValueError: a thruster with no force range (and, unit-gain, no ctrlrange); a bad torque_limit.
    """
    if not (math.isfinite(torque_limit) and torque_limit > 0):
        raise ValueError(f"torque_limit = {torque_limit!r} N m must be finite and > 0")
    thr = np.asarray(layout.thruster_ids, dtype=int)
    lo, hi = np.full(thr.size, -np.inf), np.full(thr.size, np.inf)
    for k, a in enumerate(thr):
        if m.actuator_forcelimited[a]:
            lo[k], hi[k] = m.actuator_forcerange[a]
        if direct and m.actuator_ctrllimited[a]:
            lo[k], hi[k] = max(lo[k], m.actuator_ctrlrange[a, 0]), min(hi[k], m.actuator_ctrlrange[a, 1])
        if not (math.isfinite(lo[k]) and math.isfinite(hi[k])):
            raise ValueError(f"thruster {layout.thruster_names[k]!r} has no force range (actuator forcerange): "
                             "the action's bounds need one")
    mot = np.asarray(layout.motor_ids, dtype=int)
    tlo, thi = np.full(mot.size, -float(torque_limit)), np.full(mot.size, float(torque_limit))
    for k, a in enumerate(mot):
        for limited, rng in ((m.actuator_ctrllimited[a], m.actuator_ctrlrange[a]),
                             (m.actuator_forcelimited[a], m.actuator_forcerange[a])):
            if limited:
                tlo[k], thi[k] = max(tlo[k], rng[0]), min(thi[k], rng[1])
    return np.r_[lo, tlo], np.r_[hi, thi]


def _base_names(m: mujoco.MjModel, layout) -> tuple[list[str], list[str]]:
    """Names of the base's qpos and qvel components."""
    if layout.base_free:
        return [*_AXES, "qw", "qx", "qy", "qz"], ["vx", "vy", "vz", "wx", "wy", "wz"]
    pos, vel = [], []
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)
    for j in range(m.njnt):
        if m.jnt_bodyid[j] != layout.base_body:
            continue
        axis = int(np.argmax(np.abs(d.xaxis[j])))
        if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_SLIDE:
            pos.append(_AXES[axis])
            vel.append("v" + _AXES[axis])
        else:
            pos.append(_ANGLES[axis])
            vel.append("w" + _AXES[axis])
    return pos, vel


def observation_names(m: mujoco.MjModel, layout, residual: bool) -> dict[str, list[str]]:
    """Observation key -> the names of its components (the order of :class:`uvms_mj.rl.env.TrackingTask`'s
    observation spec; ``tip``, ``target`` and ``goal`` only for a robot with a tip site, the joint
    entries only for one with arm joints)."""
    pos, vel = _base_names(m, layout)
    joints = list(layout.joint_names)
    names = {"base_pose": pos, "joint_angles": joints, "base_velocity": vel, "joint_velocities": joints}
    if layout.tip_site >= 0:
        axes = [_AXES[a] for a in layout.plane_axes]
        names.update(tip=axes, target=list(axes), goal=list(axes))
    names.update(time_to_go=["t"], thrust=list(layout.thruster_names))
    if residual:
        names["base_command"] = action_names(layout)
    return {k: v for k, v in names.items() if v}  # a vehicle without arm: no joint entries
