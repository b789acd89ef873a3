"""Test oracle: the paper's digital RAC and RAC + DOB on the planar closed form (Eqs. 1, 6-15).

The first implementation of the reproduction, on the planar nominal model (:mod:`.nominal`),
kinematics (:mod:`.kinematics`) and allocator (:mod:`.allocation`): the generic ``rac`` /
``rac_dob`` (uvms_mj.control.rac, on the controller's own MuJoCo model) must give the same run
on the paper's robot. Registered for the tests as ``rac_planar`` / ``rac_dob_planar``
(:func:`register_oracles`, called by tests/conftest.py); the product does not ship it.

It takes the scenario's controller arguments: ``robot`` (the nominal MuJoCo model, whose
compiled parameters make the planar nominal model) and a straight line (a Line3D in the plane, or
the oracle's own StraightLine).
"""

from __future__ import annotations

import numpy as np

from oracles.planar.allocation import Allocator
from oracles.planar.kinematics import jacobians, tip_position
from oracles.planar.nominal import NominalModel
from oracles.planar.trajectory import StraightLine
from uvms_mj.control.base import Command, Controller, ControllerError, Measurement, check_gains, check_positive
from uvms_mj.control.digital import (
    PAPER_GAINS,
    PAPER_JS,
    PAPER_T,
    PAPER_TF,
    LowPassZOH,
    SingularHandler,
    check_rac_settings,
    damped_inverse,
)
from uvms_mj.control.trajectories import Line3D
from uvms_mj.plant.params import read_params


def _as_line(trajectory):
    """A planar StraightLine for a Line3D in the plane (else as given)."""
    if isinstance(trajectory, Line3D):
        return StraightLine(start=tuple(trajectory.start[:2]), target=tuple(trajectory.target[:2]),
                            cruise_speed=trajectory.cruise_speed, accel=trajectory.accel, t_start=trajectory.t_start)
    return trajectory


def _nominal_of(robot, nominal):
    """The planar nominal model: given, or made from the nominal MuJoCo model's parameters."""
    if nominal is not None or robot is None:
        return nominal or NominalModel()
    g = robot.model.opt.gravity
    return NominalModel(read_params(robot.model), gravity=(float(g[0]), float(g[1])))


class RAC(Controller):
    """Digital resolved acceleration control (Eqs. 10-11) with the singular-configuration
    handling of Eq. 12, computed torque on the nominal model for the joints and Eqs. 13, 15 for
    the base (f_E_hat = 0: no observer).

    Args:
        nominal: the controller's nominal model (default: from the model file).
        trajectory: the desired end-tip path.
        T: sampling period [s] (paper 1/60).
        gamma, lam: Gamma and Lambda, 5 numbers in (0, 1) each (paper 0.3, 0.3, 0.2, 0.2, 0.2).
        js: singular threshold on |det B| (paper 0.045); js_high: release threshold (default js).
        n_ramp: samples of the Eq. 12 velocity ramps (ours: 30 = 0.5 s).
        base_reference: base desired pose (p0x, p0y, phi0); default the first measured pose.
        dls_threshold, dls_damping: damped least squares below this |det B| (ours: 0.01, 0.01).
        allocation: "clip" or "scale" (see :class:`~uvms_mj.planar.allocation.Allocator`).
    """

    observer = False

    def __init__(
        self,
        trajectory: StraightLine,
        nominal: NominalModel | None = None,
        robot=None,
        T: float = PAPER_T,
        gamma=PAPER_GAINS,
        lam=PAPER_GAINS,
        js: float = PAPER_JS,
        js_high: float | None = None,
        n_ramp: int = 30,
        base_reference=None,
        dls_threshold: float = 0.01,
        dls_damping: float = 0.01,
        allocation: str = "clip",
        tf: float = PAPER_TF,
        observer_gain: str = "1/Tf",
        observer_input: str = "allocated",
    ) -> None:
        trajectory = _as_line(trajectory)
        if not isinstance(trajectory, StraightLine):
            raise ControllerError(f"trajectory = {trajectory!r} must be a StraightLine (this planar oracle follows "
                                  "a straight line only; rac and rac_dob take any trajectory)")
        self.trajectory = trajectory
        self.nominal = _nominal_of(robot, nominal)
        self.T = check_positive("T", T)
        self.gamma = check_gains("gamma", gamma)
        self.lam = check_gains("lambda", lam)
        check_rac_settings(self, js, js_high, n_ramp, dls_threshold, dls_damping, tf, observer_gain, observer_input)
        self.base_reference = None if base_reference is None else np.asarray(base_reference, dtype=float)
        if self.base_reference is not None and (
            self.base_reference.shape != (3,) or not np.all(np.isfinite(self.base_reference))
        ):
            raise ControllerError(f"base_reference = {base_reference!r} must be 3 finite numbers")
        self.allocator = Allocator(self.nominal.params.thrusters, allocation)
        self.filter = LowPassZOH(self.T, self.tf)
        self.g = 1.0 / self.tf if observer_gain == "1/Tf" else (1.0 - self.filter.h) / self.T
        self.geom = self.nominal.geometry

    # ---------------------------------------------------------------- helpers

    def _task(self, q: np.ndarray) -> np.ndarray:
        """p = (x0, pe) (world frame)."""
        p = np.empty(5)
        p[:3] = q[:3]
        p[3:] = tip_position(self.geom, q)
        return p

    def _desired(self, k: int) -> np.ndarray:
        """p_d(k): base desired pose (reference + Eq. 12 offset) and the tip path."""
        p = np.empty(5)
        p[:3] = self._x0_ref
        p[:2] += self._base_offset[k]
        p[3:] = self.trajectory.position(k * self.T)
        return p

    # ---------------------------------------------------------------- interface

    def reset(self, m: Measurement) -> None:
        q = np.asarray(m.q, dtype=float)
        self._x0_ref = q[:3].copy() if self.base_reference is None else self.base_reference.copy()
        self.singular = SingularHandler(self.js, self.js_high, self.n_ramp, self.trajectory.cruise_velocity())
        self._base_offset = {m.k: np.zeros(2)}
        self._k0 = m.k
        p_d = self._desired(m.k)
        self._p_d_prev = p_d
        self._e_p_prev = np.zeros(5)
        self._q_prev = q.copy()
        self._p_prev = self._task(q)
        A, B = jacobians(self.geom, q)
        self._AB_prev = np.hstack((A, B))
        qd0 = np.zeros(5) if m.qd is None else np.asarray(m.qd, dtype=float)
        M = self.nominal.dynamics(q, qd0).M
        self.filter.reset(self.g * M[:3, :3] @ qd0[:3])  # f_E_hat(0) = 0

    def compute(self, m: Measurement) -> Command:
        T, k = self.T, m.k
        q = np.asarray(m.q, dtype=float)
        p = self._task(q)
        # Velocities: a velocity sensor, or backward differences of the measured positions.
        A, B = jacobians(self.geom, q)
        AB = np.hstack((A, B))  # the tip rows of J = [[I, 0], [A, B]]
        if m.qd is None:
            qd = (q - self._q_prev) / T if k > self._k0 else np.zeros(5)
            pd_meas = (p - self._p_prev) / T if k > self._k0 else np.zeros(5)
        else:
            qd = np.asarray(m.qd, dtype=float)
            pd_meas = np.concatenate((qd[:3], AB @ qd))

        # Eq. 12: singular-configuration handling moves the base's desired position.
        detb = float(B[0, 0] * B[1, 1] - B[0, 1] * B[1, 0])
        v_base = self.singular.update(k, detb)
        self._base_offset[k + 1] = self._base_offset[k] + T * v_base

        p_d = self._desired(k)
        p_d_next = self._desired(k + 1)
        e_p = p_d - p
        v_d = (p_d - self._p_d_prev + self.gamma * self._e_p_prev) / T  # Eq. 11
        v_d_next = (p_d_next - p_d + self.gamma * e_p) / T  # Eq. 11 at k + 1
        e_v = v_d - pd_meas
        a_d = (v_d_next - v_d + self.lam * e_v) / T  # Eq. 10

        # q_ddot_d = J^-1 (a_d - J_dot q_dot), J_dot by backward difference (Eq. 9); J_dot has
        # only the tip rows, since the base rows of J are constant.
        rhs = a_d.copy()
        if k > self._k0:
            rhs[3:] -= (AB - self._AB_prev) @ qd / T
        B_inv, dls = damped_inverse(B, self.dls_threshold, self.dls_damping)
        qdd_d = np.empty(5)
        qdd_d[:3] = rhs[:3]
        qdd_d[3:] = B_inv @ (rhs[3:] - A @ rhs[:3])

        # Computed torque on the nominal model (Eq. 7 blocks).
        dyn = self.nominal.dynamics(q, qd)
        M_BB, M_BM, M_MB, M_MM, h_B, h_M = dyn.blocks()
        u_M = M_MB @ qdd_d[:3] + M_MM @ qdd_d[3:] + h_M
        f_t = M_BM @ qdd_d[3:] + h_B  # Eq. 13 (with gravity/buoyancy, docs/paper-reading.md)
        f_e_hat = self.filter.output() - self.g * M_BB @ qd[:3] if self.observer else np.zeros(3)
        u_B = M_BB @ qdd_d[:3] + f_t + f_e_hat  # Eq. 15
        alloc = self.allocator(u_B, q[2])
        if self.observer:
            # Eq. 14 corrected (Fig. 3(b)): w = u_B - f_t + g M_BB x0_dot; z(k+1) = h z + (1-h) w.
            applied = alloc.wrench if self.observer_input == "allocated" else u_B
            self.filter.advance(applied - f_t + self.g * M_BB @ qd[:3])

        self._p_d_prev, self._e_p_prev = p_d, e_p
        self._q_prev, self._p_prev, self._AB_prev = q, p, AB
        return Command(
            thrust=alloc.thrust,
            torques=u_M,
            signals={
                "p_desired": p_d,
                "p_measured": p,
                "e_p": e_p,
                "e_v": e_v,
                "v_desired": v_d,
                "a_desired": a_d,
                "qdd_desired": qdd_d,
                "u_B": u_B,
                "u_B_applied": alloc.wrench,
                "f_E_hat": f_e_hat,
                "det_B": detb,
                "singular_phase": self.singular.phase,
                "dls_active": dls,
                "thrust_saturated": alloc.saturated,
            },
        )


class RACDOB(RAC):
    """RAC plus the digital disturbance observer on the base (Eq. 14 corrected, Fig. 3(b)),
    h = exp(-T / Tf), Tf = 10 s (paper)."""

    observer = True


def register_oracles() -> None:
    """Register the oracle as controllers ``rac_planar`` and ``rac_dob_planar`` (idempotent)."""
    from uvms_mj.control import base

    base._REGISTRY.setdefault("rac_planar", RAC)
    base._REGISTRY.setdefault("rac_dob_planar", RACDOB)
