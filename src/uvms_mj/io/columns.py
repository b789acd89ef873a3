"""Names of the components of a log's vector signals, from the robot's layout in the log's metadata.

:func:`component_names` gives, for each per-sample vector signal of a log (a
:func:`~uvms_mj.io.reader.read_log` result or a RunResult with ``meta``), the name of each
component, which the exports use as column names (``q_true[alpha_shoulder]``,
``thrust_force[bluerov2_t7]``, ``tip_true[z]``; :mod:`uvms_mj.io.export`):

* ``q_true``, ``q_measured`` (qpos): a free vehicle's ``base_x``, ``base_y``, ``base_z`` (world
  [m]) and ``base_qw`` .. ``base_qz`` (attitude quaternion); a planar base's (the paper's)
  ``base_x``, ``base_y``, ``base_yaw`` (the angle about z, phi0); then the joints by name.
* ``qd_true``, ``qdd_desired``, ``zeta_ref``, ``reference_lead`` (qvel): a free vehicle's
  ``base_vx`` .. ``base_vz`` (world) and ``base_wx`` .. ``base_wz`` (body frame); a planar base's
  as qpos; then the joints by name.
* ``tip_true``, ``tip_desired``, ``tip_measured``, ``e_position``, ``e_tip``, ``wave_velocity``,
  ``tether_pull``:
  ``x``, ``y``, ``z`` (the paper's tip: ``x``, ``y``).
* ``base_desired``: ``x``, ``y``, ``z``, ``qw``, ``qx``, ``qy``, ``qz``.
* ``e_attitude``: ``roll``, ``pitch``, ``yaw``: rotation-vector components about x, y, z (for
  small errors, the roll, pitch and yaw errors).
* ``thrust_command``, ``thrust_force``, ``thrust_saturated``: the thrusters by name.
* ``torques``: the joint motors by name; ``joints_desired``, ``e_posture``, ``f_M_hat``: the
  joints by name.
* ``u_B``, ``u_B_applied``, ``f_E_hat``, ``wrench_body``, ``wrench_achieved``: a free vehicle's
  ``fx``, ``fy``, ``fz``, ``mx``, ``my``, ``mz``; a planar base's ``fx``, ``fy``, ``mz``.
* ``p_desired``, ``p_measured``, ``e_p``, ``e_v``, ``v_desired``, ``a_desired``: the task
  coordinates: the paper's ``base_x``, ``base_y``, ``base_yaw``, ``tip_x``, ``tip_y``; a free
  vehicle's (rac, rac_dob, pd: their shared task vector) ``base_x`` .. ``base_z``, ``base_roll``
  .. ``base_yaw`` (rotation vector, world axes), ``tip_x`` .. ``tip_z`` (and ``tip_roll`` ..
  ``tip_yaw`` with a tip attitude task).

The robot's layout: ``meta["robot"]["layout"]`` (every floating robot's log: joint, thruster and
motor names and the qpos / qvel addresses, as ``uvms-mj info`` shows), else, for the paper's robot
(``meta["scenario"]["robot"] == "paper"`` or a log with ``robot_params``), the paper model's names
(thrusters from ``robot_params``, else ``thruster1`` .. ``thruster3``; joints ``joint1``,
``joint2``: :mod:`uvms_mj.plant.params`). **Fallback**: a signal not in the table, or whose size
does not match the layout (another controller's signal of the same name, a log without a
layout), has no names (None): its columns stay ``x[0]``, ``x[1]``...
"""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np

__all__ = ["component_names", "robot_layout"]

_XYZ = ["x", "y", "z"]
_RPY = ["roll", "pitch", "yaw"]
_WRENCH_3D = ["fx", "fy", "fz", "mx", "my", "mz"]
_WRENCH_PLANAR = ["fx", "fy", "mz"]
_TIP = ("tip_true", "tip_desired", "tip_measured", "e_position", "e_tip", "wave_velocity", "tether_pull")
_THRUST = ("thrust_command", "thrust_force", "thrust_saturated")
_JOINT = ("joints_desired", "e_posture", "f_M_hat")
_WRENCH = ("u_B", "u_B_applied", "f_E_hat", "wrench_body", "wrench_achieved")
_TASK = ("p_desired", "p_measured", "e_p", "e_v", "v_desired", "a_desired")


def robot_layout(meta: Mapping[str, Any]) -> dict | None:
    """The robot's layout from a log's metadata: ``{"free", "joints", "thrusters", "motors",
    "base_qpos", "base_qvel", "joint_qpos", "joint_qvel"}``, or None (module docstring)."""
    robot = meta.get("robot")
    lay = robot.get("layout") if isinstance(robot, Mapping) else None
    if isinstance(lay, Mapping) and "joints" in lay:
        return {"free": True, "joints": [str(j) for j in lay.get("joints", [])],
                "thrusters": [str(t) for t in lay.get("thrusters", [])],
                "motors": [str(m) for m in lay.get("motors", [])],
                "base_qpos": int(lay.get("base_qpos", 0)), "base_qvel": int(lay.get("base_qvel", 0)),
                "joint_qpos": [int(i) for i in lay.get("joint_qpos", [])],
                "joint_qvel": [int(i) for i in lay.get("joint_qvel", [])]}
    scenario = meta.get("scenario")
    params = meta.get("robot_params")
    paper = (isinstance(scenario, Mapping) and scenario.get("robot") == "paper") or isinstance(params, Mapping)
    if not paper:
        return None
    from uvms_mj.plant.params import JOINT_MOTORS, THRUSTERS

    thrusters = list(THRUSTERS)
    if isinstance(params, Mapping) and isinstance(params.get("thrusters"), list):
        named = [t.get("name") for t in params["thrusters"] if isinstance(t, Mapping)]
        if named and all(isinstance(n, str) for n in named):
            thrusters = named
    # the paper's qpos = qvel = (p0x, p0y, phi0, phi1, phi2); its motors are named as their joints
    return {"free": False, "joints": list(JOINT_MOTORS), "thrusters": thrusters, "motors": list(JOINT_MOTORS),
            "base_qpos": 0, "base_qvel": 0, "joint_qpos": [3, 4], "joint_qvel": [3, 4]}


def _placed(size: int, base: list[str], base_at: int, joints: list[str], joint_at: list[int]) -> list[str] | None:
    """Names of a qpos / qvel vector: the base's at ``base_at``, the joints' at their addresses."""
    out: list[str | None] = [None] * size
    for i, n in enumerate(base):
        if base_at + i >= size:
            return None
        out[base_at + i] = n
    for n, i in zip(joints, joint_at):
        if not 0 <= i < size:
            return None
        out[i] = n
    return [n if n is not None else f"{i}" for i, n in enumerate(out)]


def _names(signal: str, size: int, lay: dict, controller: str) -> list[str] | None:
    free = lay["free"]
    joints = lay["joints"]
    if signal in ("q_true", "q_measured"):
        base = ["base_" + c for c in (_XYZ + ["qw", "qx", "qy", "qz"] if free else ["x", "y", "yaw"])]
        return _placed(size, base, lay["base_qpos"], joints, lay["joint_qpos"])
    if signal in ("qd_true", "qdd_desired", "zeta_ref", "reference_lead"):
        base = ["base_" + c for c in (["vx", "vy", "vz", "wx", "wy", "wz"] if free else ["x", "y", "yaw"])]
        return _placed(size, base, lay["base_qvel"], joints, lay["joint_qvel"])
    if signal in _TIP:
        return _XYZ[:size] if size in (2, 3) else None
    if signal == "base_desired":
        return _XYZ + ["qw", "qx", "qy", "qz"]
    if signal == "e_attitude":
        return list(_RPY)
    if signal in _THRUST:
        return list(lay["thrusters"])
    if signal in ("torques", "torques_applied"):
        return list(lay["motors"])
    if signal in _JOINT:
        return list(joints)
    if signal in _WRENCH:
        return list(_WRENCH_3D if free else _WRENCH_PLANAR)
    if signal in _TASK:
        if not free:
            return ["base_x", "base_y", "base_yaw", "tip_x", "tip_y"]
        if controller in ("rac", "rac_dob", "pd"):  # their shared task vector (uvms_mj.control.rac)
            task = ["base_" + c for c in _XYZ + _RPY] + ["tip_" + c for c in _XYZ]
            return task + ["tip_" + c for c in _RPY] if size == 12 else task
    return None


def component_names(log) -> dict[str, list[str] | None]:
    """Signal name -> the names of its components (one per entry of a per-sample vector), or None
    where unknown (scalars, matrices, signals not in the table, sizes that do not match): see the
    module docstring."""
    meta = getattr(log, "meta", None) or {}
    lay = robot_layout(meta)
    controller = meta.get("controller")
    if not controller:  # a log read as a stream: the status record (with "controller") comes last
        scenario = meta.get("scenario")
        ctrl = scenario.get("controller") if isinstance(scenario, Mapping) else None
        controller = ctrl.get("name") if isinstance(ctrl, Mapping) else ""
    controller = str(controller or "")
    out: dict[str, list[str] | None] = {}
    for signal, arr in log.signals.items():
        a = np.asarray(arr)
        names = None
        if lay is not None and a.ndim == 2:
            names = _names(signal, int(a.shape[1]), lay, controller)
            if names is not None and (len(names) != a.shape[1] or len(set(names)) != len(names)):
                names = None
        out[signal] = names
    return out
