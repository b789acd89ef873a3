"""``station_pid``: PID station keeping of the vehicle with joint PD of the arm, for any robot.

What most UVMS labs run as their baseline: the vehicle holds a pose with a PID per axis on the
pose error, its output allocated to the thrusters; each arm joint follows its desired angle with
a PD; both add the nominal model's hold force (gravity minus buoyancy) as a feed-forward.
Reference: Antonelli, *Underwater Robots*, 4th ed., Springer 2018, ch. 7 (PID-like control of
the vehicle; the arm's independent joint control), and Fossen, *Handbook of Marine Craft
Hydrodynamics and Motion Control*, 2nd ed., 2021, ch. 15 (PID with restoring-force
compensation).

At sample k (period T), with the measured vehicle position p (world) and orientation R, the
desired pose (p_d, R_d) (the station: ``base_reference``, else the first measurement's position
with a level attitude at its yaw, ``station_attitude``; :mod:`uvms_mj.control.station`) and
joint angles q (desired
q_d(t), rates qd_d(t) from the scenario's arm waypoints):

    e_p = p_d - p                          (world, m)
    e_R = log(R^T R_d)                     (rotation vector, body axes, rad)
    F   = Kp_p e_p + Ki_p sum(e_p) T - Kd_p v          (world, N; v: world velocity)
    M   = Kp_R e_R + Ki_R sum(e_R) T - Kd_R omega      (body, N m; omega: body rate)
    (F, M) += h_base(q)                    (nominal hold force, MuJoCo's free-joint rows)
    thrusts = allocate([R^T F; M])         (weighted least squares, saturating)
    tau_j = Kp_j (q_d - q) + Kd_j (qd_d - qd) + h_joints(q), clipped to the motors' ranges

Velocities come from the velocity sensor when the scenario has one, else from backward
differences of the measured poses. Gains, unless given, come from the nominal mass matrix M at
the initial state and a closed-loop bandwidth: Kp = M_ii w^2, Kd = 2 zeta w M_ii, Ki = Kp / T_i
(critically damped second-order loop per axis when the axes decouple). The integrators are
clamped (anti-windup) to ``integral_limit`` times the largest thrust / torque each axis can get.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from uvms_mj.control.limits import JOINT_LIMIT_MARGIN, JointLimits
from uvms_mj.control.nominal import JointTrajectory, NominalRobot
from uvms_mj.rotations import quat_to_mat, rotation_log
from uvms_mj.physics.thrusters import Allocator
from uvms_mj.control.base import Command, Controller, ControllerError, Measurement, check_positive, register
from uvms_mj.control.station import check_base_reference, check_base_trajectory, check_station_attitude, station_reference

#: Default controller period [s]: 50 Hz, a usual ROV control rate and a whole multiple of the
#: BlueROV2 models' 2 ms step (the paper's 1/60 s is not).
DEFAULT_T = 0.02


def _gains(name: str, value: Any, size: int) -> np.ndarray | None:
    if value is None:
        return None
    arr = np.atleast_1d(np.asarray(value, dtype=float))
    if arr.size == 1:
        arr = np.full(size, float(arr[0]))
    if arr.shape != (size,) or not np.all(np.isfinite(arr)) or np.any(arr < 0):
        raise ControllerError(f"{name} = {value!r} must be 1 or {size} finite numbers >= 0")
    return arr


@register("station_pid")
class StationPID(Controller):
    """PID station keeping + joint PD for any floating robot (module docstring).

    Args:
        robot: the controller's :class:`~uvms_mj.control.nominal.NominalRobot` (given by the
            scenario; never the plant).
        arm_trajectory: desired joint motion (None: hold the initial angles).
        T: controller period [s].
        bandwidth_base: closed-loop bandwidth of the vehicle's position axes [rad/s] (gains
            from it).
        bandwidth_attitude: of its rotation axes [rad/s] (stiffer than position by default: the
            Munk moments of a vehicle moving through the water are destabilising).
        bandwidth_joints: of the arm joints [rad/s].
        damping_ratio: zeta of every loop.
        integral_time: T_i of the vehicle's integrators [s] (0: no integral action).
        kp_position, kd_position, ki_position, kp_attitude, kd_attitude, ki_attitude: explicit
            vehicle gains (1 or 3 numbers; N/m, N s/m, N/(m s), N m/rad, ...), overriding the
            bandwidth ones.
        kp_joints, kd_joints: explicit joint gains (1 or n numbers; N m/rad, N m s/rad).
        integral_limit: anti-windup bound, as a fraction of each axis' largest wrench.
        feedforward: add the nominal hold force (gravity minus buoyancy).
        trajectory: an end-effector path (world): the arm's joint targets then come from
            resolved-rate inverse kinematics relative to the station (the vehicle at its reference
            pose), gain ``ik_gain`` [1/s], damping ``ik_damping`` [m] (default 0.05, ours: with
            0.01 a target beyond the reach made the IK jump across the stretched arm, its step
            there ik_gain T |e| / (2 ik_damping) = 0.5 rad a sample, and the run diverged at
            10.8 s in scenarios/bluerov2_alpha_beyond_reach.yaml; 0.05 holds the arm stretched,
            the tip 142 mm short of the target); otherwise
            ``arm_trajectory`` (joint waypoints) or the initial angles.
        base_reference: the station (x, y, z [m] world, qw, qx, qy, qz; the scenario's
            ``vehicle.setpoint``); default the first measurement's vehicle position, its attitude
            by ``station_attitude``.
        base_trajectory: the vehicle origin's path (``position(t)``, ``velocity(t)``, world [m],
            [m/s]; the scenario's ``vehicle.trajectory``): p_d(t) and, in the D term, v_d(t)
            (F = Kp e_p + Ki sum(e_p) T + Kd (v_d - v)); the orientation stays the station's.
        station_attitude: the default station's attitude: "level" (default: roll = pitch = 0 at
            the measured yaw) | "measured" (the first measurement's as it is;
            :mod:`uvms_mj.control.station`).
        joint_limits, joint_limit_margin: (ours; default true, 2 deg) clamp the joints' reference
            (the initial posture, the arm waypoints, the tip path's IK state) into the nominal
            ranges minus the margin (:mod:`uvms_mj.control.limits`).
    """

    robots = "floating"

    def __init__(self, robot: NominalRobot, arm_trajectory: JointTrajectory | None = None, trajectory=None,
                 T: float = DEFAULT_T, ik_gain: float = 5.0, ik_damping: float = 0.05,
                 bandwidth_base: float = 1.0, bandwidth_attitude: float = 2.0, bandwidth_joints: float = 6.0, damping_ratio: float = 1.0,
                 integral_time: float = 5.0, kp_position=None, kd_position=None, ki_position=None,
                 kp_attitude=None, kd_attitude=None, ki_attitude=None, kp_joints=None, kd_joints=None,
                 integral_limit: float = 0.5, feedforward: bool = True, base_reference=None,
                 base_trajectory=None, station_attitude: str | None = None, joint_limits: bool = True,
                 joint_limit_margin: float = JOINT_LIMIT_MARGIN) -> None:
        if not isinstance(robot, NominalRobot):
            raise ControllerError("station_pid needs robot= a NominalRobot (a floating robot scenario)")
        self.base_reference = check_base_reference(base_reference)
        self.base_trajectory = check_base_trajectory(base_trajectory, velocity=True)
        self.station_attitude = check_station_attitude(station_attitude, bool(robot.layout.base_free), self.base_reference)
        self.robot = robot
        self.T = check_positive("T", T)
        self.bandwidth_base = check_positive("bandwidth_base", bandwidth_base)
        self.bandwidth_attitude = check_positive("bandwidth_attitude", bandwidth_attitude)
        self.bandwidth_joints = check_positive("bandwidth_joints", bandwidth_joints)
        self.zeta = check_positive("damping_ratio", damping_ratio)
        if not (math.isfinite(integral_time) and integral_time >= 0):
            raise ControllerError(f"integral_time = {integral_time!r} must be finite and >= 0 (0: off)")
        self.integral_time = float(integral_time)
        if not (math.isfinite(integral_limit) and integral_limit >= 0):
            raise ControllerError(f"integral_limit = {integral_limit!r} must be finite and >= 0")
        self.integral_limit = float(integral_limit)
        self.feedforward = bool(feedforward)
        lay = robot.layout
        self.nj = len(lay.joint_names)
        #: The arm joints' bounds on the nominal model (:mod:`uvms_mj.control.limits`).
        self.limits = JointLimits(robot.model, lay.joint_qadr, self.T, joint_limits, joint_limit_margin)
        self.explicit = {k: _gains(k, v, 3) for k, v in (("kp_position", kp_position), ("kd_position", kd_position),
                                                          ("ki_position", ki_position), ("kp_attitude", kp_attitude),
                                                          ("kd_attitude", kd_attitude), ("ki_attitude", ki_attitude))}
        nm = len(lay.motor_ids)
        self.explicit["kp_joints"] = _gains("kp_joints", kp_joints, nm)
        self.explicit["kd_joints"] = _gains("kd_joints", kd_joints, nm)
        if arm_trajectory is not None and tuple(arm_trajectory.names) != tuple(lay.joint_names):
            raise ControllerError("arm_trajectory joints differ from the robot's")
        self.arm = arm_trajectory
        self.trajectory = trajectory
        if trajectory is not None and lay.tip_site < 0:
            raise ControllerError("trajectory given but the robot has no end-effector site")
        self.ik_gain = check_positive("ik_gain", ik_gain)
        self.ik_damping = check_positive("ik_damping", ik_damping)
        B = robot.allocation()
        self.allocator = Allocator(B, robot.thruster_lo, robot.thruster_hi) if B.shape[1] else None
        # The largest wrench per axis (for anti-windup): |B| times the force limits.
        fmax = np.maximum(np.abs(robot.thruster_lo), np.abs(robot.thruster_hi))
        self.wrench_max = np.abs(B) @ fmax if B.shape[1] else np.zeros(6)

    # ------------------------------------------------------------------ interface

    def reset(self, measurement: Measurement) -> None:
        r, lay = self.robot, self.robot.layout
        q = np.asarray(measurement.q, dtype=float)
        self.p_ref, self.quat_ref, self.R_ref, self.q_joint0 = station_reference(q, lay, self.base_reference, self.station_attitude)
        M = r.mass_matrix(q)
        d = lay.base_dadr
        mb = np.diag(M)[d:d + 6]
        w, z = self.bandwidth_base, self.zeta
        ex = self.explicit
        self.kp_p = ex["kp_position"] if ex["kp_position"] is not None else mb[:3] * w * w
        self.kd_p = ex["kd_position"] if ex["kd_position"] is not None else 2 * z * w * mb[:3]
        wa = self.bandwidth_attitude
        self.kp_r = ex["kp_attitude"] if ex["kp_attitude"] is not None else mb[3:] * wa * wa
        self.kd_r = ex["kd_attitude"] if ex["kd_attitude"] is not None else 2 * z * wa * mb[3:]
        Ti = self.integral_time
        self.ki_p = ex["ki_position"] if ex["ki_position"] is not None else (self.kp_p / Ti if Ti > 0 else 0 * self.kp_p)
        self.ki_r = ex["ki_attitude"] if ex["ki_attitude"] is not None else (self.kp_r / Ti if Ti > 0 else 0 * self.kp_r)
        mj = np.diag(M)[r.motor_dofs] if len(r.motor_dofs) else np.zeros(0)
        wj = self.bandwidth_joints
        self.kp_j = ex["kp_joints"] if ex["kp_joints"] is not None else mj * wj * wj
        self.kd_j = ex["kd_joints"] if ex["kd_joints"] is not None else 2 * z * wj * mj
        self.int_p = np.zeros(3)
        self.int_r = np.zeros(3)
        self.prev = q.copy()
        self.first = True
        # the motors' joints inside the arm-joint list
        self.motor_in_arm = np.array([lay.joint_names.index(j) for j in lay.motor_joints], dtype=int)
        self.q_ik = self.q_joint0.copy()
        self.q_station = q.copy()

    def _ik_step(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Resolved-rate inverse kinematics of the tip path relative to the station (the vehicle
        at its reference pose, the arm at the IK state): qd = B^T (B B^T + d^2 I)^-1
        (v_d + K (p_d - p(q_ik))), q_ik += T qd (B: tip Jacobian on the arm joints, nominal model)."""
        r, lay = self.robot, self.robot.layout
        qs = self.q_station.copy()
        qs[lay.joint_qadr] = self.q_ik
        r._set(qs)
        jac = r.jacobians()
        B = jac["tip_p"][:, lay.joint_dadr]
        p_d = np.asarray(self.trajectory.position(t), dtype=float)[:3]
        v_d = np.asarray(self.trajectory.velocity(t), dtype=float)[:3]
        v = v_d + self.ik_gain * (p_d - jac["tip"])
        qd = B.T @ np.linalg.solve(B @ B.T + self.ik_damping ** 2 * np.eye(3), v)
        q_new = self.limits.clamp_position(self.q_ik + self.T * qd)  # inside the ranges (ours)
        qd = (q_new - self.q_ik) / self.T
        self.q_ik = q_new
        return self.q_ik.copy(), qd

    def compute(self, measurement: Measurement) -> Command:
        r, lay = self.robot, self.robot.layout
        q = np.asarray(measurement.q, dtype=float)
        a, d, T = lay.base_qadr, lay.base_dadr, self.T
        p = q[a:a + 3]
        R = quat_to_mat(q[a + 3:a + 7])
        qj = q[lay.joint_qadr]
        if measurement.qd is not None:
            qd = np.asarray(measurement.qd, dtype=float)
            v, omega, qdj = qd[d:d + 3], qd[d + 3:d + 6], qd[lay.joint_dadr]
        elif self.first:
            v, omega, qdj = np.zeros(3), np.zeros(3), np.zeros(self.nj)
        else:  # backward differences of the measured poses
            pp = self.prev
            v = (p - pp[a:a + 3]) / T
            omega = rotation_log(quat_to_mat(pp[a + 3:a + 7]).T @ R) / T
            qdj = (qj - pp[lay.joint_qadr]) / T
        self.prev = q.copy()
        self.first = False

        v_ref = np.zeros(3)
        if self.base_trajectory is not None:  # the vehicle's path: position and velocity references
            t = measurement.t
            self.p_ref = np.asarray(self.base_trajectory.position(t), dtype=float)[:3].copy()
            v_ref = np.asarray(self.base_trajectory.velocity(t), dtype=float)[:3]
        e_p = self.p_ref - p
        e_r = rotation_log(R.T @ self.R_ref)
        lim = self.integral_limit * self.wrench_max
        if np.any(self.ki_p):
            self.int_p = np.clip(self.int_p + e_p * T, -lim[:3] / np.maximum(self.ki_p, 1e-12),
                                 lim[:3] / np.maximum(self.ki_p, 1e-12))
        if np.any(self.ki_r):
            self.int_r = np.clip(self.int_r + e_r * T, -lim[3:] / np.maximum(self.ki_r, 1e-12),
                                 lim[3:] / np.maximum(self.ki_r, 1e-12))
        F = self.kp_p * e_p + self.ki_p * self.int_p + self.kd_p * (v_ref - v)
        Mb = self.kp_r * e_r + self.ki_r * self.int_r - self.kd_r * omega
        h = r.hold_force(q) if self.feedforward else np.zeros(r.model.nv)
        F = F + h[d:d + 3]
        Mb = Mb + h[d + 3:d + 6]
        wrench = np.concatenate((R.T @ F, Mb))
        if self.allocator is not None:
            res = self.allocator(wrench)
            thrust, saturated = res.thrust, res.saturated
            achieved = res.wrench
        else:
            thrust, achieved, saturated = np.zeros(0), np.zeros(6), np.zeros(0, dtype=bool)

        if self.trajectory is not None:
            qj_d, qdj_d = self._ik_step(measurement.t)
        elif self.arm is not None:
            qj_d, qdj_d = self.arm(measurement.t)
        else:
            qj_d, qdj_d = self.q_joint0, np.zeros(self.nj)
        if self.limits.active:  # the joints' reference inside the nominal ranges (ours)
            q_in = self.limits.clamp_position(qj_d)
            qdj_d = np.where(q_in != qj_d, 0.0, qdj_d)
            qj_d = q_in
        mi = self.motor_in_arm
        tau = (self.kp_j * (qj_d[mi] - qj[mi]) + self.kd_j * (qdj_d[mi] - qdj[mi])
               + h[r.motor_dofs])
        tau = np.clip(tau, r.motor_lo, r.motor_hi)
        signals = {
            "base_desired": np.concatenate((self.p_ref, self.quat_ref)),
            "joints_desired": np.asarray(qj_d, dtype=float).copy(),
            "e_position": e_p, "e_attitude": e_r,
            "wrench_body": wrench, "wrench_achieved": np.asarray(achieved, dtype=float),
            "thrust_saturated": np.asarray(saturated, dtype=bool),
        }
        if self.trajectory is not None:
            signals["tip_desired"] = np.asarray(self.trajectory.position(measurement.t), dtype=float)[:3].copy()
        return Command(thrust=np.asarray(thrust, dtype=float), torques=tau, signals=signals)
