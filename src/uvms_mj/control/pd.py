"""``pd``: a task-space PD baseline on the nominal MuJoCo model, to show what RAC buys.

    u = J^T (Kp e_p - Kd p_dot) + g_bar(q)

with the task p, its Jacobian J and the error e_p = p_d - p of :class:`uvms_mj.control.rac.RAC`
(planar base: base joint coordinates and the tip in the plane; free vehicle: vehicle position,
orientation as a world rotation vector, tip position), g_bar the nominal hold force (gravity
minus buoyancy, :meth:`uvms_mj.control.nominal.NominalRobot.hold_force`), no feed-forward and no
dynamics model beyond g_bar. The base's generalized force goes to the thrusters as RAC's does
(``allocation``). The desired base pose is ``base_reference``, else the first measurement's
(a floating base: levelled by ``station_attitude``, as RAC's); Eq. 12 is not used.

Gains: Kp = omega^2 Lambda_t, Kd = 2 zeta omega Lambda_t with Lambda_t the diagonal of the
nominal task-space inertia (J M^-1 J^T)^-1 at the first sample (ours: omega = 2 rad/s,
zeta = 1: a critically damped 2 rad/s loop per task axis where the axes decouple).
"""

from __future__ import annotations

import numpy as np

from uvms_mj.control.base import Command, ControllerError, Measurement, check_positive, register
from uvms_mj.control.digital import PAPER_T
from uvms_mj.control.nominal import NominalRobot
from uvms_mj.control.rac import RAC

__all__ = ["TaskPD"]


@register("pd")
class TaskPD(RAC):
    """Task-space PD with nominal gravity/buoyancy compensation (module docstring).

    Args:
        trajectory: desired tip path (``position(t)``, world [m]); None: hold the initial tip.
        robot: the controller's :class:`NominalRobot` (default the paper's robot's model file).
        T: sampling period [s].
        omega: closed-loop bandwidth [rad/s] of every task axis.
        zeta: damping ratio.
        allocation: "auto" | "clip" | "wls" (as :class:`~uvms_mj.control.rac.RAC`).
        base_reference: the base's desired pose (planar: one number per base joint; free:
            x, y, z, qw, qx, qy, qz); default the first measurement's.
        base_trajectory: the vehicle origin's desired path (as RAC's).
        station_attitude: the default station's attitude on a floating base (as RAC's): "level"
            (default) | "measured".
    """

    observer = False
    robots = "any"
    use_kernel = False

    def __init__(self, trajectory=None, robot: NominalRobot | None = None, T: float = PAPER_T, omega: float = 2.0,
                 zeta: float = 1.0, allocation: str = "auto", base_reference=None, base_trajectory=None,
                 arm_trajectory=None, station_attitude: str | None = None) -> None:
        if arm_trajectory is not None and len(getattr(arm_trajectory, "times", ())):
            raise ControllerError("pd follows a tip trajectory, not arm joint waypoints (arm_trajectory)")
        super().__init__(trajectory=trajectory, robot=robot, T=T, allocation=allocation,
                         base_reference=base_reference, base_trajectory=base_trajectory,
                         station_attitude=station_attitude)
        self.omega = check_positive("omega", omega)
        self.zeta = check_positive("zeta", zeta)

    def reset(self, m: Measurement) -> None:
        super().reset(m)
        r = self.robot
        q = np.asarray(m.q, dtype=float)
        M = r.mass_matrix(q)
        J = self._jacobian(r.jacobians())
        lam_t = np.diag(np.linalg.inv(J @ np.linalg.solve(M, J.T)))
        self.kp = self.omega ** 2 * lam_t
        self.kd = 2.0 * self.zeta * self.omega * lam_t

    def compute(self, m: Measurement) -> Command:
        r = self.robot
        q = np.asarray(m.q, dtype=float)
        first = m.k <= self._k0
        if m.qd is not None:
            qd = np.asarray(m.qd, dtype=float)
        else:
            qd = np.zeros(r.model.nv) if first else self._velocity(q)
        g_bar = r.hold_force(q)  # also leaves the nominal model at q for the Jacobians
        jac = r.jacobians()
        J = self._jacobian(jac)
        p = self._task(q, jac)
        p_d = self._desired_fixed_base(m.k)
        e_p = self._diff(p_d, p)
        u = J.T @ (self.kp * e_p - self.kd * (J @ qd)) + g_bar
        b, a = self.base_dofs, self.arm_dofs
        thrust, saturated, u_applied = self._allocate(u[b], jac)
        self._q_prev = q
        signals = {"e_p": e_p, "u_B": u[b], "u_B_applied": u_applied, "thrust_saturated": saturated}
        if self.free:
            from uvms_mj.rotations import mat_to_quat

            signals["base_desired"] = np.concatenate((p_d[0][:3], mat_to_quat(p_d[1][0])))
            signals["tip_desired"] = p_d[0][3:6].copy()
            signals["tip_measured"] = p[0][3:6].copy()
        else:
            Bm = J[self.nbt:][:, a]
            signals = {"p_desired": p_d[0], "p_measured": p[0], **signals,
                       "det_B": float(np.linalg.det(Bm)) if Bm.shape[0] == Bm.shape[1] else float("nan")}
        return Command(thrust=thrust, torques=u[a][self._motor_idx], signals=signals)

    def _desired_fixed_base(self, k: int):
        """p_d(k) with the base at its reference (no Eq. 12 offset)."""
        self._base_offset.setdefault(k, next(iter(self._base_offset.values())) * 0.0)
        return self._desired(k)
