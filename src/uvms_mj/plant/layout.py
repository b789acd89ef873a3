"""The named layout of a compiled robot model and initial states by name.

* :class:`Layout` -- the named pieces of a compiled model: the vehicle body and its base joints
  (a free joint, or the slides and hinges of a planar base such as the paper's), the arm joints,
  the thrusters (site actuators, in model order), the joint actuators, the end-effector site;
* :class:`InitialState` -- the base pose (position world [m], orientation as a unit quaternion
  w x y z), joint angles by name, velocities; applied to ``qpos`` / ``qvel``.

State layout (MuJoCo's free joint): ``qpos`` = (x, y, z [m] world, qw, qx, qy, qz, joint angles
[rad]); ``qvel`` = (linear velocity [m/s] WORLD frame, angular velocity [rad/s] BODY frame, joint
rates). A planar base (slides along world axes, one hinge) keeps its joint coordinates: the
pose's components along the slides' axes and the rotation about the hinge's axis.
"""

from __future__ import annotations

import difflib
import math
from dataclasses import dataclass, field
from typing import Mapping

import mujoco
import numpy as np

from uvms_mj.plant.errors import ParameterError
from uvms_mj.physics.thrusters import thruster_actuators

__all__ = ["InitialState", "Layout", "motor_clamps", "motor_torque_range", "motor_torques"]


# --------------------------------------------------------------------------- layout


def _name(m: mujoco.MjModel, obj, i: int) -> str:
    return mujoco.mj_id2name(m, obj, i) or f"{obj.name.removeprefix('mjOBJ_').lower()}{i}"


@dataclass(frozen=True)
class Layout:
    """The named pieces of a compiled robot model (ids and addresses into MuJoCo's arrays).

    Attributes:
        base_body, base_name: the vehicle: the body carrying the free joint (or, for a planar
            model, the base joints).
        base_qadr, base_dadr: its free joint's ``qpos`` (7) and ``qvel`` (6) addresses (first
            addresses for joint bases).
        base_free: the vehicle is on a free joint; base_dofs: its dofs (6, or one per joint).
        joints: the other joints (hinge/slide), model order: names, ``qpos`` and ``qvel`` addresses.
        thrusters: thruster actuator names (site transmission, model order) and ids.
        motors: joint actuators: names, ids, and the joint each drives.
        tip_site: the end-effector site id (-1: none) and its name.
        bodies: every body but the world: names (for ``/tf``).
        plane_axes: the world axes positions are reported along (:attr:`Plant.tip_position`):
            (0, 1, 2) for a free vehicle; for a planar base the axes of its slides (the paper's:
            x and y).
        base_hinge: a planar base's hinge joint id (-1: none or a free vehicle).
        initial_key: the model's initial keyframe: the first keyframe whose name ends in
            "initial" (the paper's ``paper_initial``), None: start from ``qpos0``.
    """

    base_body: int
    base_name: str
    base_qadr: int
    base_dadr: int
    joint_names: tuple[str, ...]
    joint_qadr: np.ndarray
    joint_dadr: np.ndarray
    thruster_names: tuple[str, ...]
    thruster_ids: np.ndarray
    motor_names: tuple[str, ...]
    motor_ids: np.ndarray
    motor_joints: tuple[str, ...]
    tip_site: int
    tip_name: str
    body_names: tuple[str, ...] = field(default=())
    base_free: bool = True
    base_dofs: np.ndarray = field(default_factory=lambda: np.arange(6))
    plane_axes: tuple[int, ...] = (0, 1, 2)
    base_hinge: int = -1
    initial_key: str | None = None

    @property
    def base_nq(self) -> int:
        """Number of ``qpos`` entries of the base: 7 (free joint) or one per base joint."""
        return 7 if self.base_free else int(self.base_dofs.size)

    @classmethod
    def of(cls, m: mujoco.MjModel, tip_site: str | None = None, allow_planar: bool = False,
           exclude: str | None = None) -> "Layout":
        """The layout of ``m``; ``tip_site``: the end-effector site (default: the first site
        whose name ends in "tip", or none); ``exclude``: a body whose subtree is not the robot's
        (a tether's chain, :mod:`uvms_mj.plant.tether`: its joints and bodies are left out).

        The vehicle is the body carrying a free joint; without one (``allow_planar``), the first
        child of the world that carries joints, with all its joints (slides and hinges, e.g. the
        paper's planar base: slide x, slide y, hinge z).

        Raises:
            ParameterError: no free joint (and not ``allow_planar``), more than one, or an
                unknown ``tip_site``.
        """
        out = set()
        if exclude is not None:
            root = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, exclude)
            if root < 0:
                raise ParameterError(f"exclude = {exclude!r}: no body of that name")
            for b in range(root, m.nbody):  # a subtree's bodies follow its root in body order
                if b == root or int(m.body_parentid[b]) in out:
                    out.add(b)
        robot_joints = [j for j in range(m.njnt) if int(m.jnt_bodyid[j]) not in out]
        free = [j for j in robot_joints if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE]
        if len(free) > 1 or (not free and not allow_planar):
            raise ParameterError(f"the robot model must have exactly one free joint (the vehicle), it has {len(free)}")
        if free:
            base_joints = [free[0]]
        else:
            roots = [b for b in range(1, m.nbody) if m.body_parentid[b] == 0 and m.body_jntnum[b] > 0 and b not in out]
            if not roots:
                raise ParameterError("the robot model has no vehicle: no body on a free joint nor a child of the "
                                     "world with joints")
            b0 = roots[0]
            base_joints = list(range(m.body_jntadr[b0], m.body_jntadr[b0] + m.body_jntnum[b0]))
        jf = base_joints[0]
        others = [j for j in robot_joints if j not in base_joints]
        for j in others:
            if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_BALL:
                raise ParameterError(f"joint {_name(m, mujoco.mjtObj.mjOBJ_JOINT, j)!r}: ball joints are not "
                                     "supported (use hinges)")
        thr = thruster_actuators(m) if any(int(m.actuator_trntype[a]) == int(mujoco.mjtTrn.mjTRN_SITE)
                                           for a in range(m.nu)) else []
        mot = [a for a in range(m.nu) if int(m.actuator_trntype[a]) == int(mujoco.mjtTrn.mjTRN_JOINT)]
        site_names = [_name(m, mujoco.mjtObj.mjOBJ_SITE, s) for s in range(m.nsite)]
        if tip_site is None:
            tips = [i for i, n in enumerate(site_names) if n.endswith("tip")]
            tip = tips[0] if tips else -1
        else:
            tip = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, tip_site)
            if tip < 0:
                close = difflib.get_close_matches(tip_site, site_names, n=1, cutoff=0.6)
                hint = f" (did you mean {close[0]!r}?)" if close else ""
                raise ParameterError(f"tip_site = {tip_site!r}: no site of that name{hint}")
        J = mujoco.mjtObj.mjOBJ_JOINT
        A = mujoco.mjtObj.mjOBJ_ACTUATOR
        base_dofs = [int(m.jnt_dofadr[j]) + i for j in base_joints
                     for i in range(6 if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE else 1)]
        axes: tuple[int, ...] = (0, 1, 2)
        hinge = -1
        if not free:
            d = mujoco.MjData(m)
            mujoco.mj_kinematics(m, d)
            slides = [j for j in base_joints if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_SLIDE]
            axes = tuple(sorted({int(np.argmax(np.abs(d.xaxis[j]))) for j in slides})) or (0, 1, 2)
            hinges = [j for j in base_joints if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE]
            hinge = hinges[0] if len(hinges) == 1 else -1
        keys = [_name(m, mujoco.mjtObj.mjOBJ_KEY, k) for k in range(m.nkey)]
        initial_key = next((k for k in keys if k.endswith("initial")), None)
        return cls(
            plane_axes=axes, base_hinge=int(hinge), initial_key=initial_key,
            base_free=bool(free), base_dofs=np.array(base_dofs, dtype=int),
            base_body=int(m.jnt_bodyid[jf]), base_name=_name(m, mujoco.mjtObj.mjOBJ_BODY, int(m.jnt_bodyid[jf])),
            base_qadr=int(m.jnt_qposadr[jf]), base_dadr=int(m.jnt_dofadr[jf]),
            joint_names=tuple(_name(m, J, j) for j in others),
            joint_qadr=np.array([m.jnt_qposadr[j] for j in others], dtype=int),
            joint_dadr=np.array([m.jnt_dofadr[j] for j in others], dtype=int),
            thruster_names=tuple(_name(m, A, a) for a in thr), thruster_ids=np.array(thr, dtype=int),
            motor_names=tuple(_name(m, A, a) for a in mot), motor_ids=np.array(mot, dtype=int),
            motor_joints=tuple(_name(m, J, int(m.actuator_trnid[a][0])) for a in mot),
            tip_site=int(tip), tip_name=site_names[tip] if tip >= 0 else "",
            body_names=tuple(_name(m, mujoco.mjtObj.mjOBJ_BODY, b) for b in range(1, m.nbody) if b not in out),
        )

    def describe(self) -> dict:
        """JSON-able summary (for log metadata)."""
        return {"base": self.base_name, "base_qpos": self.base_qadr, "base_qvel": self.base_dadr,
                "joint_qpos": self.joint_qadr.tolist(), "joint_qvel": self.joint_dadr.tolist(),
                "joints": list(self.joint_names), "thrusters": list(self.thruster_names),
                "motors": list(self.motor_names), "motor_joints": list(self.motor_joints),
                "tip_site": self.tip_name, "bodies": list(self.body_names)}


def motor_torque_range(model: mujoco.MjModel, actuator_ids) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) of the joint torque [N m] (or force [N]) each motor can give: MuJoCo's clamps of a
    motor, the control range (where ``ctrllimited``) times the gain, then the force range (where
    ``forcelimited``), times the gear; -inf / +inf where not limited (the paper's motors)."""
    ids = np.asarray(actuator_ids, dtype=int).ravel()
    lo, hi = np.full(ids.size, -np.inf), np.full(ids.size, np.inf)
    for i, a in enumerate(ids):
        g = float(model.actuator_gainprm[a, 0])
        f0, f1 = -np.inf, np.inf
        if model.actuator_ctrllimited[a]:
            c = g * model.actuator_ctrlrange[a]
            f0, f1 = float(min(c)), float(max(c))
        if model.actuator_forcelimited[a]:
            f0, f1 = max(f0, float(model.actuator_forcerange[a, 0])), min(f1, float(model.actuator_forcerange[a, 1]))
        gear = float(model.actuator_gear[a, 0])
        t = sorted((gear * f0, gear * f1)) if gear else [0.0, 0.0]
        lo[i], hi[i] = (0.0 if math.isnan(t[0]) else t[0]), (0.0 if math.isnan(t[1]) else t[1])
    return lo, hi

def motor_clamps(model: mujoco.MjModel, actuator_ids) -> tuple[np.ndarray, ...]:
    """(ctrl_lo, ctrl_hi, gain, force_lo, force_hi, gear) per motor of ``actuator_ids``: what
    :func:`motor_torques` applies, read once (-inf / +inf where a range is not limited: clamping to
    them leaves every number as it is)."""
    ids = np.asarray(actuator_ids, dtype=int).ravel()
    clo, chi = np.full(ids.size, -np.inf), np.full(ids.size, np.inf)
    flo, fhi = clo.copy(), chi.copy()
    lim = model.actuator_ctrllimited[ids].astype(bool)
    clo[lim], chi[lim] = model.actuator_ctrlrange[ids[lim], 0], model.actuator_ctrlrange[ids[lim], 1]
    lim = model.actuator_forcelimited[ids].astype(bool)
    flo[lim], fhi[lim] = model.actuator_forcerange[ids[lim], 0], model.actuator_forcerange[ids[lim], 1]
    return clo, chi, model.actuator_gainprm[ids, 0].copy(), flo, fhi, model.actuator_gear[ids, 0].copy()


def motor_torques(model: mujoco.MjModel, actuator_ids, ctrl, clamps: tuple | None = None) -> np.ndarray:
    """The joint torque [N m] (force [N] on a slide) each motor applies for the commands ``ctrl``
    (one per actuator of ``actuator_ids``), as MuJoCo computes a motor's force: the command
    clamped to ``ctrlrange`` (where ``ctrllimited``), times the gain, clamped to ``forcerange``
    (where ``forcelimited``), times the gear (``data.actuator_force`` x gear after a step).
    ``clamps``: :func:`motor_clamps` of the same model and ids (read once by a plant)."""
    clo, chi, gain, flo, fhi, gear = motor_clamps(model, actuator_ids) if clamps is None else clamps
    c = np.array(ctrl, dtype=float).ravel()
    f = gain * np.minimum(np.maximum(c, clo), chi)
    return gear * np.minimum(np.maximum(f, flo), fhi)


# --------------------------------------------------------------------------- initial state


@dataclass(frozen=True)
class InitialState:
    """An initial state by name (every field optional: None keeps the initial keyframe's or
    ``qpos0``'s value).

    Attributes:
        position: vehicle origin, world [m] (3).
        quat: vehicle orientation, unit quaternion (w, x, y, z) (normalised here).
        joints: joint name -> angle [rad] (or [m] for a slide).
        linear_velocity: vehicle origin velocity, WORLD frame [m/s] (3).
        angular_velocity: vehicle angular velocity, BODY frame [rad/s] (3).
        joint_velocities: joint name -> rate [rad/s].
        keyframe: a model keyframe to start from before the fields above; None: the model's
            initial keyframe (:attr:`Layout.initial_key`) if it has one, else ``qpos0``.

    On a planar base (the paper's) the position and velocities are taken along the base's
    slides and about its hinge: anything else must be zero (a clear error otherwise).
    """

    position: tuple[float, ...] | None = None
    quat: tuple[float, ...] | None = None
    joints: Mapping[str, float] = field(default_factory=dict)
    linear_velocity: tuple[float, ...] | None = None
    angular_velocity: tuple[float, ...] | None = None
    joint_velocities: Mapping[str, float] = field(default_factory=dict)
    keyframe: str | None = None

    def apply(self, m: mujoco.MjModel, d: mujoco.MjData, layout: Layout) -> None:
        """Write the state into ``d`` (after a reset to ``qpos0`` or the keyframe).

        Raises:
            ParameterError: unknown keyframe or joint name (did-you-mean), wrong sizes, a zero
                quaternion, a joint angle outside a limited joint's range.
        """
        key = self.keyframe if self.keyframe is not None else layout.initial_key
        if key is not None:
            k = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, key)
            if k < 0:
                keys = [_name(m, mujoco.mjtObj.mjOBJ_KEY, i) for i in range(m.nkey)]
                raise ParameterError(f"initial.keyframe = {key!r}: no such keyframe; "
                                     f"the model has: {', '.join(keys) or 'none'}")
            mujoco.mj_resetDataKeyframe(m, d, k)
        else:
            mujoco.mj_resetData(m, d)
        vals = {}
        for name, val, n in (("position", self.position, 3), ("quat", self.quat, 4),
                             ("linear_velocity", self.linear_velocity, 3),
                             ("angular_velocity", self.angular_velocity, 3)):
            if val is None:
                continue
            v = np.asarray(val, dtype=float).ravel()
            if v.shape != (n,) or not np.all(np.isfinite(v)):
                raise ParameterError(f"initial.{name} = {list(val)!r}: expected {n} finite numbers")
            if name == "quat":
                nv = float(np.linalg.norm(v))
                if nv < 1e-9:
                    raise ParameterError(f"initial.quat = {list(val)!r}: must not be zero")
                v = v / nv
            vals[name] = v
        if layout.base_free:
            qa, da = layout.base_qadr, layout.base_dadr
            for name, arr, adr in (("position", d.qpos, qa), ("quat", d.qpos, qa + 3),
                                   ("linear_velocity", d.qvel, da), ("angular_velocity", d.qvel, da + 3)):
                if name in vals:
                    arr[adr:adr + vals[name].size] = vals[name]
        else:
            _apply_planar(m, d, layout, vals)
        names = list(layout.joint_names)
        for label, values, arr, adrs in (("joints", self.joints, d.qpos, layout.joint_qadr),
                                         ("joint_velocities", self.joint_velocities, d.qvel, layout.joint_dadr)):
            for jn, val in values.items():
                if jn not in names:
                    close = difflib.get_close_matches(str(jn), names, n=1, cutoff=0.6)
                    hint = f" (did you mean {close[0]!r}?)" if close else ""
                    raise ParameterError(f"initial.{label}.{jn}: no joint of that name{hint}; joints: "
                                         f"{', '.join(names) or 'none'}")
                x = float(val)
                if not math.isfinite(x):
                    raise ParameterError(f"initial.{label}.{jn} = {val!r}: must be finite")
                j = names.index(jn)
                if label == "joints":
                    jid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, jn)
                    lo, hi = m.jnt_range[jid]
                    if m.jnt_limited[jid] and not lo - 1e-9 <= x <= hi + 1e-9:
                        raise ParameterError(f"initial.joints.{jn} = {x:.6g} rad is outside the joint's range "
                                             f"[{lo:.6g}, {hi:.6g}] rad")
                arr[adrs[j]] = x




def _apply_planar(m: mujoco.MjModel, d: mujoco.MjData, layout: Layout, vals: dict) -> None:
    """A pose and velocity on a planar base: each slide takes the component of the position
    (linear velocity) along its world axis; the hinge the rotation about its axis (the yaw of
    the paper's base, whose hinge is about world z). Components the base cannot take (out of
    the plane, a tilt) must be zero."""
    mujoco.mj_kinematics(m, d)
    jids = [int(m.dof_jntid[i]) for i in layout.base_dofs]
    for name, lin in (("position", True), ("linear_velocity", True), ("quat", False), ("angular_velocity", False)):
        if name not in vals:
            continue
        v = vals[name]
        if name == "quat":  # rotation vector of the quaternion
            rv = np.zeros(3)
            mujoco.mju_quat2Vel(rv, v, 1.0)
            v = rv
        covered = np.zeros(3)
        for j in jids:
            kind = m.jnt_type[j]
            if (kind == mujoco.mjtJoint.mjJNT_SLIDE) != lin:
                continue
            axis = np.asarray(d.xaxis[j], dtype=float)
            arr, adr = (d.qpos, m.jnt_qposadr[j]) if name in ("position", "quat") else (d.qvel, m.jnt_dofadr[j])
            arr[adr] = float(axis @ v)
            covered += np.abs(axis)
        rest = v * (covered < 0.5)
        if np.any(np.abs(rest) > 1e-12):
            what = "position" if lin else "rotation"
            raise ParameterError(f"initial.{name} = {[float(x) for x in vals[name]]!r}: the planar base of this "
                                 f"robot cannot take that {what} (only along or about its joints' axes: "
                                 f"world axes {', '.join('xyz'[i] for i in range(3) if covered[i] >= 0.5) or 'none'})")
