"""``rac`` and ``rac_dob``: the paper's digital RAC and disturbance observer for any robot.

One implementation for the paper's planar robot and for any floating vehicle with an arm
(``robots = "floating"``). Its nominal model is its own MuJoCo model
(:class:`uvms_mj.control.nominal.NominalRobot`: the robot FILE with nominal parameters, still
water, never the plant), evaluated at the measured state with MuJoCo's functions: ``mj_fullM``
and ``qfrc_bias - qfrc_passive`` for Eqs. 6, 7 and 13, ``mj_jacBody`` / ``mj_jacSite`` for the
task Jacobian. The planar closed form of the paper's robot (``tests/oracles/planar``: its nominal
model, Eqs. 6-7, and the planar RAC) is the test oracle: on the paper's robot both give the same run.

Task (the paper's p = (x0, pe), Eq. 1, generalised):

* planar base (slides and a hinge, the paper): p = (base joint coordinates, tip position along
  the base's slide axes); the base rows of J are the identity on the base dofs;
* floating base (free joint): p = (vehicle origin position [world], vehicle orientation, tip
  position [world] and, with ``tip_orientation``, tip orientation). Orientation errors are
  rotation vectors in WORLD axes, e = log(R_d R^T) (so e is the rotation taking the measured
  attitude to the desired one, and p_dot = omega in world axes): exact for any error angle below
  pi, equal to the paper's angle difference in the plane. The base rows of J map qvel (linear
  world, angular body) to (v, R omega).

Digital RAC (Eqs. 10-11), J_dot by backward difference (Eq. 9), then (block form of Eq. 9)

    q_ddot_B = S_B^-1 rhs_B                       (S_B: the base rows on the base dofs)
    q_ddot_M = B# (rhs_T - J_TB q_ddot_B) + (I - B# B) q_ddot_0,    rhs = a_d - J_dot q_dot

with B = J_TM the arm Jacobian (tip rows, arm dofs). Square B (the paper): B# = B^-1, or damped
least squares below ``dls_threshold`` of the manipulability. Redundant arm (more joints than tip
rows): the weighted pseudo-inverse B# = W^-1 B^T (B W^-1 B^T + mu^2 I)^-1 with W = the nominal
arm inertia M_MM (dynamically consistent; the null-space motion does not load the task), and a
null-space posture term q_ddot_0 = k_null (q_rest - q) - d_null q_dot on the arm joints,
q_rest the initial angles. Eq. 12 moves the base's desired position while the manipulability
sqrt(det(B B^T)) (= |det B| for the paper's square B) is below ``js`` (by default the paper's
fraction of the arm's largest manipulability, as is ``dls_threshold``: :mod:`.manipulability`).
Inputs (Eqs. 13-15) by computed torque on the nominal model; the observer (Eqs. 14-15
corrected, Fig. 3(b)) acts on the base's generalized force (planar: world fx, fy, tau0; free
joint: world force, body moment: MuJoCo's free-joint dofs). The base force goes to the thrusters as a body-frame wrench
(``allocation``: "clip" -- least squares then clipped to the limits, the paper code's -- or
"wls", :class:`uvms_mj.physics.thrusters.Allocator`, weighted least squares with redistribution; "auto":
clip for a square allocation, wls otherwise).
"""

from __future__ import annotations

import math
from typing import Any

import mujoco
import numpy as np

from uvms_mj.control.delay_observer import DELAY_OBSERVER_POLE, DelayObserver
from uvms_mj.control.margins import GAIN_MARGIN, DelayPredictor, auto_gains, check_margin_settings, thruster_lag
from uvms_mj.control.limits import JOINT_LIMIT_MARGIN, JOINT_LIMIT_TIME, JointLimits
from uvms_mj.control.manipulability import DLS_RATIO, PAPER_JS_RATIO, manipulability, resolve_thresholds, small_inv
from uvms_mj.control.nominal import NominalRobot
from uvms_mj.control.rac_compiled import CompiledSamples
from uvms_mj.control.rac_task import RACTaskSpace
from uvms_mj.physics.thrusters import Allocator
from uvms_mj.control.base import Command, Controller, ControllerError, Measurement, check_positive, register
from uvms_mj.control.digital import (
    PAPER_T,
    PAPER_TF,
    LowPassZOH,
    CARRY_MODES,
    SingularHandler,
    check_rac_settings,
)
from uvms_mj.control.station import check_base_reference, check_base_trajectory, check_station_attitude, level_quaternion
from uvms_mj.rotations import mat_to_quat, quat_to_mat


#: Default gains per task block (the paper's Gamma = Lambda = diag(0.3, 0.3, 0.2, 0.2, 0.2) on
#: its planar task: 0.3 for the base position, 0.2 for the base rotation and the tip).
GAIN_BASE_POSITION, GAIN_BASE_ROTATION, GAIN_TIP = 0.3, 0.2, 0.2


def _is_auto(value: Any) -> bool:
    return value is None or (isinstance(value, str) and value == "auto")


def _gains(name: str, value: Any, default: np.ndarray) -> np.ndarray:
    if _is_auto(value):
        return default.copy()
    if isinstance(value, str):
        raise ControllerError(f"{name} = {value!r}: allowed: \"auto\", 1 or {default.size} numbers in (0, 1)")
    arr = np.atleast_1d(np.asarray(value, dtype=float))
    if arr.size == 1:
        arr = np.full(default.size, float(arr[0]))
    if arr.shape != default.shape:
        raise ControllerError(f"{name} = {value!r} must be 1 or {default.size} numbers (the task size)")
    for i, v in enumerate(arr):
        if not (0.0 < v < 1.0):
            raise ControllerError(f"{name}[{i}] = {float(v)!r} is outside the allowed range (0, 1)")
    return arr


def paper_nominal_robot() -> NominalRobot:
    """The paper robot's :class:`NominalRobot`: its model file (``models/uvms.xml``) as is."""
    from uvms_mj.plant.files import models_dir

    return NominalRobot(models_dir() / "uvms.xml")


@register("rac")
class RAC(CompiledSamples, RACTaskSpace, Controller):
    """Digital RAC (Eqs. 10-11) with Eq. 12 and computed torque on the nominal MuJoCo model
    (Eqs. 13, 15; no observer), for any robot (module docstring).

    Args:
        trajectory: desired tip path: any object with ``position(t)`` (world [m]; a
            any :class:`uvms_mj.control.trajectories.Trajectory`),
            ``velocity(t)`` if it has no ``cruise_velocity()``; ``orientation(t)`` with
            ``tip_orientation``. None: hold the initial tip position. Optional
            ``positions(ts)``: ``position`` at each time of an array, the same numbers bit for bit
            (read in blocks of ``rac_task.TIP_BLOCK`` samples).
        robot: the controller's :class:`NominalRobot` (given by the scenario; default the paper's
            robot's model file, :func:`paper_nominal_robot`).
        T: sampling period [s] (paper 1/60).
        gamma, lam: Gamma, Lambda (1 or task-size numbers in (0, 1)) or "auto" (default): on a
            planar base (the paper's robot) the paper's 0.3 base position, 0.2 base rotation and
            tip; on a floating base our margin rule, per block: min(the paper's block gain, the
            largest gain stable with a one-sample measurement delay / ``gain_margin``, rounded down
            to 0.005), the base
            blocks through the model's thruster lag, the tip without
            (:func:`uvms_mj.control.margins.largest_stable_gain`; docs/paper-reading.md "Gains and
            delay"). Resolved numbers: ``resolved_params``.
        gain_margin: the margin factor of "auto" gains (ours, default
            :data:`uvms_mj.control.margins.GAIN_MARGIN` = 1.5).
        delay_compensation: samples d of a known measurement delay to predict over with the
            nominal model (ours, off by default: 0; :class:`uvms_mj.control.margins.DelayPredictor`):
            the measurement is advanced d samples by the commanded accelerations of the previous
            samples before the per-sample algebra. It does not predict the thrusters' lag, the
            observer's estimate or a disturbance.
        delay_observer_pole: (ours) with delay_compensation > 0: the triple pole p of the
            predictive state observer :class:`uvms_mj.control.delay_observer.DelayObserver`
            (position, velocity, acceleration mismatch per coordinate, corrected by each delayed
            measurement; the controller gets its predicted q and filtered velocity), default
            0.85 (:data:`~uvms_mj.control.delay_observer.DELAY_OBSERVER_POLE`: the fastest pole
            stable for plant gains 0.7..2.5 with the paper's gains); None: the open-loop
            :class:`~uvms_mj.control.margins.DelayPredictor`.
        js, js_high: Eq. 12 thresholds on the manipulability w: "auto" (js's default) = js_ratio
            (js_high_ratio, default js_ratio) x the arm's largest w over its joint ranges -- 0.72,
            the paper's 0.045 on its arm (:mod:`uvms_mj.control.manipulability`) -- or a number
            [m^r]; js_high default js. Resolved numbers: ``resolved_params``.
        n_ramp: samples of the Eq. 12 velocity ramps (ours: 30).
        carry: Eq. 12's carry velocity (:class:`uvms_mj.control.digital.SingularHandler`):
            "cruise" (the paper's reading: the tip's cruise velocity, taken at k1, held until k2),
            "path" (ours: the tip path's velocity at every sample of the carry, so the base moves
            with the path and stops when it stops) or "auto" (default: "cruise" on a planar base,
            the paper's robot, "path" on a floating one: in 3-D a posture can sit below js without
            being stretched and k2 then never comes; docs/controllers.md).
        base_trajectory: the vehicle origin's desired path (``position(t)``, world [m]; a scenario's
            ``vehicle.trajectory``): the base's desired position moves along it (plus the Eq. 12
            offset), its orientation stays the reference's; planar: the path's coordinates along the
            base's slides. None: a fixed base reference.
        base_reference: base desired pose: planar (x, y, phi0); floating (x, y, z, qw, qx, qy,
            qz); default the first measurement (floating: with ``station_attitude``).
        station_attitude: the default station's attitude on a floating base, "level" (default:
            roll = pitch = 0 at the measured yaw) | "measured" (:mod:`uvms_mj.control.station`).
        dls_threshold, dls_damping: damped least squares below this manipulability: "auto" =
            dls_ratio (ours 0.16, 0.01 on the paper's arm) x the largest, or a number.
        allocation: "auto" | "clip" | "wls" (module docstring).
        tf, observer_gain, observer_input: the observer (as the paper code's).
        tip_orientation: also control the tip's orientation (floating robots; needs 6 arm dofs
            for full rank, else the DLS/pseudo-inverse handles the deficiency).
        null_kp, null_kd: null-space posture gains [1/s^2, 1/s] for a redundant arm.
        arm_trajectory: the scenario's arm motion, not used: the arm follows the tip task (a
            redundant arm's null space rests at the initial angles); a scenario warns when it
            has arm waypoints (``uses_arm_waypoints``).
        observer_arm, tf_arm: (rac_dob; our extension, off by default) the same observer
            (Eq. 14 corrected, Fig. 3(b)) on the arm's rows, with filter time constant tf_arm
            (default tf): f_M_hat = F(s)(u_M - f_tM + g M_MM phi_dot) - g M_MM phi_dot,
            f_tM = M_MB x0_ddot_d + h_M, the torques clipped to the motors' ranges.
        joint_limits, joint_limit_margin, joint_limit_time: (ours) keep the arm joints inside
            their nominal ranges minus the margin (default true, 2 deg, 0.1 s): each arm joint's
            desired acceleration q_ddot_d is clamped by the discrete velocity damper of
            :mod:`uvms_mj.control.limits` (after Eq. 9, before Eqs. 13 and 15, so the base's
            inputs see the clamped arm motion); inert for unlimited joints (the paper's).
            The joint torques are always clipped to the motors' ranges (``robot.motor_lo`` /
            ``motor_hi``; unlimited on the paper's robot).
    """

    observer = False
    robots = "floating"
    #: Joint waypoints (a scenario's ``arm``) do not move the arm: it follows the tip task.
    uses_arm_waypoints = False
    #: Run the samples through the compiled kernel when it is available (:mod:`.kernel`; the
    #: numbers are the Python code's to round-off). False: always the Python code below.
    use_kernel = True
    _ws = None
    #: The defaults the paper's robot gets for the parameters whose default depends on the robot
    #: (what a resolved paper scenario shows).
    PAPER_DEFAULTS = {"gamma": [0.3, 0.3, 0.2, 0.2, 0.2], "lam": [0.3, 0.3, 0.2, 0.2, 0.2]}

    def __init__(
        self,
        trajectory=None,
        robot: NominalRobot | None = None,
        T: float = PAPER_T,
        gamma="auto",
        lam="auto",
        js: float | str = "auto",
        js_high: float | str | None = None,
        n_ramp: int = 30,
        base_reference=None,
        base_trajectory=None,
        station_attitude: str | None = None,
        dls_threshold: float | str = "auto",
        dls_damping: float = 0.01,
        allocation: str = "auto",
        tf: float = PAPER_TF,
        observer_gain: str = "1/Tf",
        observer_input: str = "allocated",
        tip_orientation: bool = False,
        null_kp: float = 4.0,
        null_kd: float = 4.0,
        arm_trajectory=None,
        observer_arm: bool = False,
        tf_arm: float | None = None,
        js_ratio: float = PAPER_JS_RATIO,
        js_high_ratio: float | None = None,
        dls_ratio: float = DLS_RATIO,
        carry: str = "auto",
        gain_margin: float = GAIN_MARGIN,
        delay_compensation: int = 0,
        delay_observer_pole: float | None = DELAY_OBSERVER_POLE,
        joint_limits: bool = True,
        joint_limit_margin: float = JOINT_LIMIT_MARGIN,
        joint_limit_time: float = JOINT_LIMIT_TIME,
    ) -> None:
        if robot is None:
            robot = paper_nominal_robot()
        if not isinstance(robot, NominalRobot):
            raise ControllerError(f"robot = {robot!r} must be a NominalRobot")
        self.robot = robot
        lay = robot.layout
        if lay.tip_site < 0:
            raise ControllerError("rac needs an end-effector site (the robot has no site named *tip; "
                                  "set the scenario's tip_site)")
        self.trajectory = trajectory
        self.T = check_positive("T", T)
        self.free = bool(lay.base_free)
        self.tip_orientation = bool(tip_orientation)
        if self.tip_orientation and not self.free:
            raise ControllerError("tip_orientation applies to floating robots only")
        m = robot.model
        self.base_dofs = np.asarray(lay.base_dofs, dtype=int)
        self.arm_dofs = np.array([d for d in range(m.nv) if d not in set(self.base_dofs)], dtype=int)
        nb = self.base_dofs.size
        self.arm_qadr = np.array([int(m.jnt_qposadr[m.dof_jntid[d]]) for d in self.arm_dofs], dtype=int)
        #: The arm's joint-limit handling on the nominal model (:mod:`uvms_mj.control.limits`).
        self.limits = JointLimits(m, self.arm_qadr, self.T, joint_limits, joint_limit_margin, joint_limit_time)
        if self.free:
            self.tip_rows = np.arange(3)
            self.lin = np.arange(3)  # base position coordinates inside the base block
            blocks = [np.full(3, GAIN_BASE_POSITION), np.full(3, GAIN_BASE_ROTATION), np.full(3, GAIN_TIP)]
            if self.tip_orientation:
                blocks.append(np.full(3, GAIN_TIP))
        else:
            jids = [int(m.dof_jntid[d]) for d in self.base_dofs]
            self.base_qpos = np.array([m.jnt_qposadr[j] for j in jids], dtype=int)
            slides = [i for i, j in enumerate(jids) if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_SLIDE]
            self.lin = np.array(slides, dtype=int)
            mujoco.mj_kinematics(m, robot.data)
            self.tip_rows = np.array(sorted({int(np.argmax(np.abs(robot.data.xaxis[jids[i]]))) for i in slides}),
                                     dtype=int)
            base_gain = np.array([GAIN_BASE_POSITION if i in slides else GAIN_BASE_ROTATION for i in range(nb)])
            blocks = [base_gain, np.full(self.tip_rows.size, GAIN_TIP)]
        default = np.concatenate(blocks)
        self.ntask = default.size
        self.nbt = 6 if self.free else nb  # base rows of the task
        check_margin_settings(gain_margin, delay_compensation)
        if self.free and (_is_auto(gamma) or _is_auto(lam)):
            default = auto_gains(default, 6, self.T, thruster_lag(m), self.observer, tf, float(gain_margin))
        self.gamma = _gains("gamma", gamma, default)
        self.lam = _gains("lambda", lam, default)
        self.delay_compensation = int(delay_compensation)
        self.delay_observer_pole = delay_observer_pole
        if not self.delay_compensation:
            self._predictor = None
        elif delay_observer_pole is None:  # the open-loop prediction
            self._predictor = DelayPredictor(m, self.T, self.delay_compensation, self.base_dofs, thruster_lag(m))
        else:
            self._predictor = DelayObserver(m, self.T, self.delay_compensation, self.base_dofs, thruster_lag(m),
                                            delay_observer_pole)
        # B's rows of [jacp; jacr]: the tip rows of the task
        rows = self.tip_rows if not self.free else np.arange(6 if self.tip_orientation else 3)
        #: The thresholds as numbers ("auto" resolved; what a run records: sim.loop's meta["controller_params"]).
        self.resolved_params = resolve_thresholds(robot, self.arm_dofs, rows, js, js_high, dls_threshold, js_ratio,
                                                  js_high_ratio, dls_ratio)
        js, js_high, dls_threshold = (self.resolved_params[k] for k in ("js", "js_high", "dls_threshold"))
        self.resolved_params.update(gamma=[float(v) for v in self.gamma], lam=[float(v) for v in self.lam])
        auto = [k for k, v in (("gamma", gamma), ("lam", lam)) if _is_auto(v)] if self.free else []
        if auto:  # the margin rule's inputs (docs/paper-reading.md "Gains and delay")
            self.resolved_params.update(auto_gains=auto, gain_margin=float(gain_margin),
                                        thruster_lag=thruster_lag(m))
        check_rac_settings(self, js, js_high, n_ramp, dls_threshold, dls_damping, tf, observer_gain, observer_input)
        if carry not in ("auto",) + CARRY_MODES:
            raise ControllerError(f"carry = {carry!r}; allowed: auto, {', '.join(CARRY_MODES)}")
        #: Eq. 12's carry velocity as used ("auto" resolved; recorded in resolved_params).
        self.carry = ("path" if self.free else "cruise") if carry == "auto" else carry
        self.resolved_params["carry"] = self.carry
        size = 7 if self.free else nb
        self.base_trajectory = check_base_trajectory(base_trajectory)
        self.base_reference = check_base_reference(base_reference, size)
        self.station_attitude = check_station_attitude(station_attitude, self.free, self.base_reference)
        self.null_kp = float(null_kp)
        self.null_kd = float(null_kd)
        if not (math.isfinite(self.null_kp) and self.null_kp >= 0 and math.isfinite(self.null_kd) and self.null_kd >= 0):
            raise ControllerError(f"null_kp = {null_kp!r}, null_kd = {null_kd!r} must be finite and >= 0")
        self.filter = LowPassZOH(self.T, self.tf, size=nb)
        self.g = 1.0 / self.tf if observer_gain == "1/Tf" else (1.0 - self.filter.h) / self.T
        # Our extension (off by default, not in the paper): the same observer on the arm's rows.
        if not isinstance(observer_arm, bool):
            raise ControllerError(f"observer_arm = {observer_arm!r} must be true or false")
        self.observer_arm = bool(observer_arm) and self.observer
        self.tf_arm = self.tf if tf_arm is None else check_positive("tf_arm", tf_arm)
        n_arm = m.nv - nb
        self.filter_arm = LowPassZOH(self.T, self.tf_arm, size=n_arm)
        self.g_arm = 1.0 / self.tf_arm if observer_gain == "1/Tf" else (1.0 - self.filter_arm.h) / self.T
        # thrusters: body-frame allocation on the rows the base can move
        if allocation not in ("auto", "clip", "wls"):
            raise ControllerError(f"allocation = {allocation!r}; allowed: auto, clip, wls")
        B = robot.allocation()
        robot._set(m.qpos0.copy())
        Jb = self._base_jac(robot.jacobians())
        self._Jb_const = None
        if not self.free:  # the paper's base (slides, then a hinge at the origin): constant; checked
            q1 = m.qpos0.copy()
            q1[self.base_qpos] += np.random.default_rng(0).uniform(-1.0, 1.0, self.base_qpos.size)
            robot._set(q1)
            if np.allclose(self._base_jac(robot.jacobians()), Jb, rtol=0, atol=1e-12):
                self._Jb_const = Jb.copy()
                self._Jb_pinvT = np.linalg.pinv(Jb.T)
            robot._set(m.qpos0.copy())
            self._J_template = np.zeros((self.ntask, m.nv))
            self._J_template[np.arange(nb), self.base_dofs] = 1.0
        R0 = robot.data.xmat[lay.base_body].reshape(3, 3)
        mob = np.vstack((R0.T @ Jb[:3], R0.T @ Jb[3:]))
        self.wrench_rows = np.flatnonzero(np.linalg.norm(mob, axis=1) > 1e-9)
        Bc = B[self.wrench_rows]
        if allocation == "auto":
            allocation = "clip" if Bc.shape[0] == Bc.shape[1] or B.shape[1] == 0 else "wls"
        self.allocation = allocation
        self.B = B
        self.lo, self.hi = robot.thruster_lo, robot.thruster_hi
        self.B_pinv = np.linalg.pinv(Bc)
        self.allocator = (Allocator(B, self.lo, self.hi, dofs=self.wrench_rows)
                          if allocation == "wls" and B.shape[1] else None)

    # ---------------------------------------------------------------- interface

    def reset(self, m: Measurement) -> None:
        r, lay = self.robot, self.robot.layout
        q = np.asarray(m.q, dtype=float)
        qd0 = np.zeros(r.model.nv) if m.qd is None else np.asarray(m.qd, dtype=float)
        M, _ = r.dynamics(q, qd0)
        jac = r.jacobians()
        self._tip0 = jac["tip"][:3].copy() if self.free else jac["tip"][self.tip_rows].copy()
        self._tip_R0 = jac["R_tip"].copy()
        if self.free:
            a = lay.base_qadr
            ref = q[a:a + 7] if self.base_reference is None else self.base_reference
            self._ref_pos = np.array(ref[:3], dtype=float)
            level = self.base_reference is None and self.station_attitude == "level"
            self._ref_R = quat_to_mat(level_quaternion(ref[3:7]) if level else ref[3:7])
        else:
            self._ref_pos = (q[self.base_qpos] if self.base_reference is None else self.base_reference).astype(float).copy()
        self.q_rest = q[self.arm_qadr].copy()
        b, a = self.base_dofs, self.arm_dofs
        self._ix = {"bb": np.ix_(b, b), "ba": np.ix_(b, a), "ab": np.ix_(a, b), "aa": np.ix_(a, a)}
        pos = {int(d): i for i, d in enumerate(a)}
        self._motor_idx = np.array([pos[int(d)] for d in r.motor_dofs], dtype=int)
        self._Jb_key = None
        self.singular = SingularHandler(self.js, self.js_high, self.n_ramp,
                                        self._v_path if self.carry == "path" else self._v_event,
                                        size=3 if self.free else self.lin.size, carry=self.carry)
        self._base_offset = {m.k: np.zeros(3 if self.free else self.lin.size)}
        self._base_d = None  # (offset, base part of p_d) of the last _desired
        self._tip_blk = None  # (first sample, desired tips) of _tip_k
        self._k0 = m.k
        self._pd_prev = self._desired(m.k)
        self._pd_next = None
        self._e_p_prev = np.zeros(self.ntask)
        self._q_prev = q.copy()
        self._p_prev = self._task(q, jac)
        self._J_prev = self._jacobian(jac)
        b = self.base_dofs
        self.filter.reset(self.g * M[np.ix_(b, b)] @ qd0[b])  # f_E_hat(0) = 0
        self.filter_arm.reset(self.g_arm * M[np.ix_(a, a)] @ qd0[a])
        self._ws = self._kernel_workspace() if self.use_kernel else None
        if self._predictor is not None:
            self._predictor.reset(q)

    def _velocity(self, q: np.ndarray) -> np.ndarray:
        """Backward difference of the measured coordinates as qvel (quaternions included)."""
        qd = np.zeros(self.robot.model.nv)
        mujoco.mj_differentiatePos(self.robot.model, qd, self.T, self._q_prev, q)
        return qd

    def compute(self, m: Measurement) -> Command:
        if self._predictor is not None and not self._predictor.active:  # delay_compensation (ours)
            return self._predictor.command(self, m)
        if self._ws is not None:
            return self._compute_kernel(m)
        T, k, r = self.T, m.k, self.robot
        q = np.asarray(m.q, dtype=float)
        first = k <= self._k0
        if m.qd is None:
            qd = np.zeros(r.model.nv) if first else self._velocity(q)
        else:
            qd = np.asarray(m.qd, dtype=float)
        M, h = r.dynamics(q, qd)  # nominal model at the measured state (Eqs. 6-7)
        jac = r.jacobians()
        J = self._jacobian(jac)
        p = self._task(q, jac)
        if m.qd is None:
            pd_meas = np.zeros(self.ntask) if first else self._diff(p, self._p_prev) / T
        else:
            pd_meas = J @ qd
        b, a = self.base_dofs, self.arm_dofs
        nbt = self.nbt
        Bm = J[nbt:][:, a]  # arm Jacobian: tip rows, arm dofs
        manip, detb = manipulability(Bm)

        # Eq. 12: the base carries the arm while the manipulability is below js.
        v_base = self.singular.update(k, manip)
        self._base_offset[k + 1] = self._base_offset[k] + T * v_base

        # p_d(k) was computed as p_d(k + 1) at the previous sample (same offset: the Eq. 12 offset
        # of k + 1 is fixed before p_d(k + 1) is formed)
        cached = self._pd_next
        p_d = cached[1] if cached is not None and cached[0] == k else self._desired(k)
        p_d_next = self._desired(k + 1)
        self._pd_next = (k + 1, p_d_next)
        e_p = self._diff(p_d, p)
        v_d = (self._diff(p_d, self._pd_prev) + self.gamma * self._e_p_prev) / T  # Eq. 11
        v_d_next = (self._diff(p_d_next, p_d) + self.gamma * e_p) / T  # Eq. 11 at k + 1
        e_v = v_d - pd_meas
        a_d = (v_d_next - v_d + self.lam * e_v) / T  # Eq. 10

        # q_ddot_d from J q_ddot = a_d - J_dot q_dot, J_dot by backward difference (Eq. 9)
        rhs = a_d.copy()
        if not first:
            rhs -= (J - self._J_prev) @ qd / T
        qdd_d = np.zeros(r.model.nv)
        if self.free:  # S = [[I, 0], [0, R]]: its inverse in closed form
            qdd_d[b[:3]] = rhs[:3]
            qdd_d[b[3:]] = jac["R_base"].T @ rhs[3:6]
        else:  # the base rows of J are the identity on the base dofs
            qdd_d[b] = rhs[:nbt]
        r_m = rhs[nbt:] - J[nbt:][:, b] @ qdd_d[b]
        dls = manip < self.dls_threshold
        mu2 = self.dls_damping ** 2 * (1.0 - (manip / self.dls_threshold) ** 2) if dls else 0.0
        if Bm.shape[0] == Bm.shape[1]:
            if dls:
                qdd_d[a] = Bm.T @ (small_inv(Bm @ Bm.T + mu2 * np.eye(Bm.shape[0])) @ r_m)
            else:
                qdd_d[a] = small_inv(Bm) @ r_m
        else:
            ix = self._ix
            X = np.linalg.solve(M[ix["aa"]], Bm.T)  # W^-1 B^T, W = M_MM
            G = Bm @ X
            if mu2:
                G = G + mu2 * np.eye(G.shape[0])
            Bp = X @ small_inv(G)
            q0dd = self.null_kp * (self.q_rest - q[self.arm_qadr]) - self.null_kd * qd[a]
            qdd_d[a] = Bp @ r_m + q0dd - Bp @ (Bm @ q0dd)
        if self.limits.active:  # ours: the arm inside its joint ranges (discrete velocity damper)
            qdd_d[a] = self.limits.clamp_acceleration(q[self.arm_qadr], qd[a], qdd_d[a])

        # Computed torque on the nominal model (Eq. 7 blocks), Eqs. 13 and 15.
        ix = self._ix
        M_BB, M_BM = M[ix["bb"]], M[ix["ba"]]
        M_MB, M_MM = M[ix["ab"]], M[ix["aa"]]
        f_tM = M_MB @ qdd_d[b] + h[a]
        f_m_hat = (self.filter_arm.output() - self.g_arm * M_MM @ qd[a]) if self.observer_arm else None
        u_M = M_MM @ qdd_d[a] + f_tM + (f_m_hat if f_m_hat is not None else 0.0)
        f_t = M_BM @ qdd_d[a] + h[b]  # Eq. 13
        f_e_hat = self.filter.output() - self.g * M_BB @ qd[b] if self.observer else np.zeros(b.size)
        u_B = M_BB @ qdd_d[b] + f_t + f_e_hat  # Eq. 15
        thrust, saturated, u_applied = self._allocate(u_B, jac)
        if self.observer:
            # Eq. 14 corrected (Fig. 3(b)): w = u_B - f_t + g M_BB x0_dot; z(k+1) = h z + (1-h) w.
            applied = u_applied if self.observer_input == "allocated" else u_B
            self.filter.advance(applied - f_t + self.g * M_BB @ qd[b])
        if self.observer_arm:
            # the same structure on the arm rows, with the torques the motors can give
            tau = u_M.copy()
            tau[self._motor_idx] = np.clip(u_M[self._motor_idx], r.motor_lo, r.motor_hi)
            self.filter_arm.advance(tau - f_tM + self.g_arm * M_MM @ qd[a])

        self._pd_prev, self._e_p_prev = p_d, e_p
        self._q_prev, self._p_prev, self._J_prev = q, p, J
        # joint torques for the motors' joints (in the motors' order), inside the motors' ranges
        torques = np.clip(u_M[self._motor_idx], r.motor_lo, r.motor_hi)
        signals = {"e_p": e_p, "e_v": e_v, "v_desired": v_d, "a_desired": a_d, "qdd_desired": qdd_d,
                   "u_B": u_B, "u_B_applied": u_applied, "f_E_hat": f_e_hat, "manipulability": manip,
                   "singular_phase": self.singular.phase, "dls_active": dls, "thrust_saturated": saturated}
        if f_m_hat is not None:
            signals["f_M_hat"] = f_m_hat
        if self.free:
            signals["base_desired"] = np.concatenate((p_d[0][:3], mat_to_quat(p_d[1][0])))
            signals["tip_desired"] = p_d[0][3:6].copy()
            signals["tip_measured"] = p[0][3:6].copy()
        else:
            signals = {"p_desired": p_d[0], "p_measured": p[0], **signals, "det_B": detb}
        return Command(thrust=thrust, torques=torques, signals=signals)

    def _allocate(self, u_B: np.ndarray, jac: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Generalized base force -> thrusts; returns (thrust, saturated, achieved base force)."""
        R = jac["R_base"]
        # u_B = Jb^T w (w: the world wrench at the vehicle origin); free joint: Jb = [[I, 0], [0, R]]
        if self.free:
            body = np.concatenate((R.T @ u_B[:3], u_B[3:]))
            Jb = None
        else:
            if self._Jb_const is not None:
                Jb = self._Jb_const
            else:
                Jb = self._base_jac(jac)
                key = Jb.tobytes()
                if key != self._Jb_key:
                    self._Jb_key, self._Jb_pinvT = key, np.linalg.pinv(Jb.T)
            w = self._Jb_pinvT @ u_B
            body = np.concatenate((R.T @ w[:3], R.T @ w[3:]))
        if self.allocator is not None:
            res = self.allocator(body[self.wrench_rows])
            f, sat = res.thrust, res.saturated
        else:
            f = self.B_pinv @ body[self.wrench_rows]
            sat = (f < self.lo) | (f > self.hi)
            if sat.any():
                f = np.clip(f, self.lo, self.hi)
        produced = self.B @ f  # body axes
        if self.free:
            return f, sat, np.concatenate((R @ produced[:3], produced[3:]))
        w_out = np.concatenate((R @ produced[:3], R @ produced[3:]))
        return f, sat, Jb.T @ w_out


@register("rac_dob")
class RACDOB(RAC):
    """RAC plus the digital disturbance observer on the base (Eq. 14 corrected, Fig. 3(b)),
    h = exp(-T / Tf), Tf = 10 s (paper), for any robot."""

    observer = True
