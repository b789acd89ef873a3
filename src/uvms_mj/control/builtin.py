"""Built-in controllers: digital RAC (``rac``), RAC + disturbance observer (``rac_dob``) and a
task-space PD baseline (``pd``).

Equation numbers refer to the paper; the reading of each equation (typos, missing values,
assumptions) is the one in docs/paper-reading.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from uvms_mj.planar.allocation import Allocator
from uvms_mj.planar.kinematics import det_b, jacobians, task_jacobian, tip_position
from uvms_mj.planar.nominal import NominalModel
from uvms_mj.planar.trajectory import StraightLine
from uvms_mj.control.base import (
    Command,
    Controller,
    ControllerError,
    Measurement,
    check_gains,
    check_positive,
    register,
)

#: Section 4 of the paper.
PAPER_T = 1.0 / 60.0
PAPER_GAINS = (0.3, 0.3, 0.2, 0.2, 0.2)  # Gamma; Lambda printed with 4 entries, read as the same 5
PAPER_TF = 10.0
PAPER_JS = 0.045


# ------------------------------------------------------------------ building blocks


class LowPassZOH:
    """F(s) = 1 / (Tf s + 1) discretized with a zero-order hold and the one-sample delay of
    Fig. 3(b): z(k) = h z(k-1) + (1 - h) w(k-1), h = exp(-T / Tf).

    (The paper prints h = e^{-Tf/T}: a typo, see docs/paper-reading.md.)
    """

    def __init__(self, T: float, tf: float, size: int = 3) -> None:
        self.h = math.exp(-T / tf)
        self.z = np.zeros(size)
        self._w_prev = np.zeros(size)

    def reset(self, z0: np.ndarray) -> None:
        self.z = np.array(z0, dtype=float)
        self._w_prev = np.array(z0, dtype=float)  # consistent with a steady input

    def output(self) -> np.ndarray:
        """z(k) (after :meth:`advance` was fed w(k-1))."""
        return self.z

    def advance(self, w: np.ndarray) -> None:
        """Feed w(k); z becomes z(k+1)."""
        self.z = self.h * self.z + (1.0 - self.h) * np.asarray(w, dtype=float)


@dataclass
class SingularHandler:
    """Eq. 12 as read in docs/paper-reading.md: the base carries the arm near det B = 0.

    Phases: 0 normal (base desired velocity 0); 1 carry: from k1, the first sample with
    |det B| < js_low, the base desired velocity ramps linearly over n samples to the tip's cruise
    velocity and holds it; 2 release: from k2, the first sample after k1 with |det B| > js_high,
    it ramps back to 0 over n samples, then phase 0 again. js_high = js_low is the paper; a
    larger js_high adds hysteresis (our option against noise re-triggering).

    For any robot (``rac``), ``detb`` is the arm's manipulability, ``v_cruise`` may be a callable
    k -> velocity (evaluated at k1: the trajectory's velocity then) and ``size`` the number of
    base position axes (default: the size of ``v_cruise``).
    """

    js_low: float
    js_high: float
    n: int
    v_cruise: Any
    size: int | None = None

    def __post_init__(self) -> None:
        size = self.size if self.size is not None else int(np.size(self.v_cruise))
        self.phase = 0
        self.k_event = 0
        self.v_from = np.zeros(size)
        self.v_to = np.zeros(size)
        self.v = np.zeros(size)
        self._settled = False  # the current ramp has reached its end (v no longer changes)

    @property
    def at_rest(self) -> bool:
        """Normal phase with its ramp over: the base's desired velocity is exactly 0."""
        return self.phase == 0 and self._settled

    def update(self, k: int, detb: float) -> np.ndarray:
        """Base desired linear velocity (world, m/s) for the interval [k, k+1)."""
        a = abs(detb)
        if self.phase != 1 and a < self.js_low:  # k1 (again, if it re-enters during release)
            v = self.v_cruise(k) if callable(self.v_cruise) else self.v_cruise
            self.phase, self.k_event, self.v_from, self.v_to = 1, k, self.v.copy(), np.array(v, dtype=float)
        elif self.phase == 1 and a > self.js_high:  # k2
            self.phase, self.k_event, self.v_from, self.v_to = 2, k, self.v.copy(), np.zeros_like(self.v)
        elif self._settled:  # no event and the ramp is over: v as computed at its end
            return self.v
        frac = min(1.0, (k - self.k_event + 1) / self.n)
        self.v = self.v_from + frac * (self.v_to - self.v_from)
        self._settled = frac >= 1.0
        if self.phase == 2 and frac >= 1.0:
            self.phase = 0
        return self.v


def check_rac_settings(ctrl, js, js_high, n_ramp, dls_threshold, dls_damping, tf, observer_gain,
                       observer_input) -> None:
    """Check the RAC settings shared by every RAC implementation and set them on ``ctrl``: js,
    js_high (Eq. 12 thresholds), n_ramp, dls_threshold, dls_damping, tf, observer_input (the
    observer gain's name is checked; the caller computes g from it).

    Raises:
        ControllerError: naming the parameter, its value and what is allowed."""
    ctrl.js = check_positive("js", js)
    ctrl.js_high = ctrl.js if js_high is None else check_positive("js_high", js_high)
    if ctrl.js_high < ctrl.js:
        raise ControllerError(f"js_high = {js_high!r} must be >= js = {js!r}")
    if int(n_ramp) != n_ramp or n_ramp < 1:
        raise ControllerError(f"n_ramp = {n_ramp!r} must be an integer >= 1")
    ctrl.n_ramp = int(n_ramp)
    ctrl.dls_threshold = check_positive("dls_threshold", dls_threshold)
    ctrl.dls_damping = check_positive("dls_damping", dls_damping)
    ctrl.tf = check_positive("tf", tf)
    if observer_gain not in ("1/Tf", "(1-h)/T"):
        raise ControllerError(f"observer_gain = {observer_gain!r}; allowed: 1/Tf, (1-h)/T")
    if observer_input not in ("allocated", "commanded"):
        raise ControllerError(f"observer_input = {observer_input!r}; allowed: allocated, commanded")
    ctrl.observer_input = observer_input


def _inv2(a: float, b: float, c: float, d: float) -> np.ndarray:
    """Inverse of [[a, b], [c, d]] in closed form."""
    det = a * d - b * c
    return np.array([[d / det, -b / det], [-c / det, a / det]])


def damped_inverse(B: np.ndarray, threshold: float, damping: float) -> tuple[np.ndarray, bool]:
    """B^-1, or damped least squares B^T (B B^T + mu^2 I)^-1 when |det B| < threshold, with
    mu^2 = damping^2 (1 - (det / threshold)^2): never inf or NaN (Nakamura-Hanafusa)."""
    (a, b), (c, d_) = B.tolist()
    det = a * d_ - b * c
    if abs(det) >= threshold:
        return _inv2(a, b, c, d_), False
    mu2 = damping * damping * (1.0 - (det / threshold) ** 2)
    # B B^T + mu^2 I is symmetric positive definite (mu > 0 whenever det B = 0).
    G = _inv2(a * a + b * b + mu2, a * c + b * d_, a * c + b * d_, c * c + d_ * d_ + mu2)
    return B.T @ G, True


# ------------------------------------------------------------------ RAC


@register("rac_planar")
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
        if not isinstance(trajectory, StraightLine):
            raise ControllerError(f"trajectory = {trajectory!r} must be a StraightLine (this planar oracle follows "
                                  "a straight line only; rac and rac_dob take any trajectory)")
        self.trajectory = trajectory
        self.nominal = nominal or NominalModel()
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


@register("rac_dob_planar")
class RACDOB(RAC):
    """RAC plus the digital disturbance observer on the base (Eq. 14 corrected, Fig. 3(b)),
    h = exp(-T / Tf), Tf = 10 s (paper)."""

    observer = True


# ------------------------------------------------------------------ PD baseline


@register("pd")
class TaskPD(Controller):
    """Task-space PD with nominal gravity/buoyancy compensation, a baseline to show what RAC buys:
    u = J^T (Kp e_p - Kd p_dot) + g_bar (no feed-forward, no dynamics model beyond g_bar).

    Gains: Kp = omega^2 Lambda_t, Kd = 2 zeta omega Lambda_t with Lambda_t the diagonal of the
    nominal task-space inertia (J M^-1 J^T)^-1 at the first sample (ours: omega = 2 rad/s,
    zeta = 1).
    """

    def __init__(self, trajectory: StraightLine, nominal: NominalModel | None = None, T: float = PAPER_T,
                 omega: float = 2.0, zeta: float = 1.0, allocation: str = "clip", **_ignored) -> None:
        if not isinstance(trajectory, StraightLine):
            raise ControllerError(f"controller 'pd' follows a straight line only (trajectory = {trajectory!r}); "
                                  "rac and rac_dob take any trajectory")
        self.trajectory = trajectory
        self.nominal = nominal or NominalModel()
        self.T = check_positive("T", T)
        self.omega = check_positive("omega", omega)
        self.zeta = check_positive("zeta", zeta)
        self.allocator = Allocator(self.nominal.params.thrusters, allocation)
        self.geom = self.nominal.geometry

    def reset(self, m: Measurement) -> None:
        q = np.asarray(m.q, dtype=float)
        J = task_jacobian(self.geom, q)
        lam_t = np.linalg.inv(J @ np.linalg.inv(self.nominal.mass_matrix(q)) @ J.T)
        self.kp = self.omega**2 * np.diag(lam_t)
        self.kd = 2 * self.zeta * self.omega * np.diag(lam_t)
        self._x0_ref = q[:3].copy()
        self._q_prev = q.copy()
        self._k0 = m.k

    def compute(self, m: Measurement) -> Command:
        q = np.asarray(m.q, dtype=float)
        qd = (np.asarray(m.qd) if m.qd is not None
              else ((q - self._q_prev) / self.T if m.k > self._k0 else np.zeros(5)))
        J = task_jacobian(self.geom, q)
        p = np.r_[q[:3], tip_position(self.geom, q)]
        p_d = np.r_[self._x0_ref, self.trajectory.position(m.k * self.T)]
        e_p = p_d - p
        u = J.T @ (self.kp * e_p - self.kd * (J @ qd)) + self.nominal.gravity_buoyancy(q)
        alloc = self.allocator(u[:3], q[2])
        self._q_prev = q
        return Command(
            thrust=alloc.thrust,
            torques=u[3:],
            signals={"p_desired": p_d, "p_measured": p, "e_p": e_p, "u_B": u[:3], "u_B_applied": alloc.wrench,
                     "det_B": det_b(self.geom, q), "thrust_saturated": alloc.saturated},
        )
