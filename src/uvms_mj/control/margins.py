"""Stability margins of the digital RAC's gains: the sampled closed loop of one task coordinate.

Under computed torque on an exact nominal model, each task coordinate of the digital RAC
(Eqs. 9-11, 13, 15; :mod:`uvms_mj.control.rac`) is a scalar sampled loop, with the mass
normalised to 1 (u is an acceleration [m/s^2 or rad/s^2]):

* plant: a double integrator x_ddot = f driven through a zero-order hold of the command u(k)
  over [kT, (k+1)T), optionally through the thrusters' first-order lag tau f_dot = u - f
  (tau = 0: f = u), discretised exactly (matrix exponential);
* measurement: y(k) = x(k - d), d samples of delay (``sensors.delay``);
* optional prediction over the delay (``delay_compensation`` = c samples, :class:`DelayPredictor`):
  v_hat = (y(k) - y(k-1)) / T + T/2 u(k-c-1), then c steps x_hat += T v_hat + T^2/2 u(j),
  v_hat += T u(j) for j = k-c .. k-1 (exact for the ZOH double integrator without lag; the
  controller's :class:`DelayPredictor` also corrects for the lag, this model does not);
* controller (regulation, p_d = 0), with y_hat the (predicted) measurement:
  s(k) = (y_hat(k) - y_hat(k-1)) / T                                (backward difference)
  v_d(k) = -gamma y_hat(k-1) / T,  v_d(k+1) = -gamma y_hat(k) / T   (Eq. 11)
  a_d(k) = (v_d(k+1) - v_d(k) + lambda (v_d(k) - s(k))) / T         (Eq. 10)
  u(k) = a_d(k) + f_hat(k)                                          (Eq. 15)
* observer (``rac_dob``; Eq. 14 corrected, Fig. 3(b), :class:`uvms_mj.control.digital.LowPassZOH`):
  f_hat(k) = z(k) - g s(k),  z(k+1) = h z(k) + (1 - h)(u(k) + g s(k)),  h = exp(-T/Tf), g = 1/Tf.

The loop is x(k+1) = A x(k); it is stable when the spectral radius of A is below 1.

With the paper's idealisation (``plant="ideal"``: the backward-difference velocity realises
a_d over a sample, s(k+1) = s(k) + T a_d(k)), no delay and no lag, A's eigenvalues are exactly
1 - gamma and 1 - lambda (docs/paper-reading.md, Eqs. 10-11). Under a zero-order hold
(``plant="zoh"``, the simulator's) the no-delay characteristic polynomial is the cubic

    z^3 - (2 + c0/2) z^2 + (1 - (c0 + c1)/2) z - c1/2,   c0 = -(gamma + lambda),
    c1 = gamma + lambda - gamma lambda.

Limits of the model: linear (no thrust saturation, no dead zone), decoupled coordinates (the
coupling of the tip rows to a lagging base through J_TB and M_MB is ignored: the tip rows see
the arm motors, without lag), an exact nominal model (f_hat only reacts to the loop itself).
docs/paper-reading.md "Gains and delay" compares its numbers with simulation.
"""

from __future__ import annotations

import functools
import math

import numpy as np

__all__ = ["DelayPredictor", "GAIN_MARGIN", "GAIN_STEP", "auto_gains", "check_margin_settings", "closed_loop_matrix",
           "largest_stable_gain", "spectral_radius", "thruster_lag"]

#: Our margin factor: a robot's default gain (``gamma``/``lam`` = "auto" off the paper's robot) is the
#: largest gain stable with a one-sample measurement delay (and the model's thruster lag) divided by it.
#: 1.5: the gain may be 50 % larger before a one-sample delay destabilises the loop.
GAIN_MARGIN = 1.5

#: "auto" gains are rounded down to a multiple of this (readable numbers; rac and rac_dob then agree).
GAIN_STEP = 0.005

#: Bisection tolerance on the gain of :func:`largest_stable_gain`.
GAIN_TOL = 1e-4


def _plant(T: float, tau: float, plant: str) -> tuple[np.ndarray, np.ndarray]:
    """(Phi, Gamma) of the sampled plant: state (x, v) or (x, v, f), input u held over T."""
    if plant == "ideal":  # x(k+1) = x + T v + T^2 u, v(k+1) = v + T u (s = v: the paper's idealisation)
        return np.array([[1.0, T], [0.0, 1.0]]), np.array([T * T, T])
    if plant != "zoh":
        raise ValueError(f"plant = {plant!r}; allowed: zoh, ideal")
    if tau <= 0:  # x(k+1) = x + T v + T^2/2 u, v(k+1) = v + T u
        return np.array([[1.0, T], [0.0, 1.0]]), np.array([T * T / 2, T])
    # Double integrator behind a first-order lag: x' = v, v' = f, f' = (u - f)/tau, u held over T.
    # Integrating f(s) = e^(-s/tau) f0 + (1 - e^(-s/tau)) u twice over [0, T] (a = T/tau):
    #   f(T) = e^-a f0 + (1 - e^-a) u
    #   v(T) = v0 + tau (1 - e^-a) f0 + tau (a - 1 + e^-a) u
    #   x(T) = x0 + T v0 + tau^2 (a - 1 + e^-a) f0 + tau^2 (a^2/2 - a + 1 - e^-a) u
    # (the exact zero-order-hold discretisation, exp([[A, B], [0, 0]] T), in closed form: scipy's expm
    # would cost ~0.15 s of import in every ``validate``, issue 22 item 7; tests check it against expm).
    a = T / tau
    c1, c2, c3 = _lag_phi(a)
    Phi = np.array([[1.0, T, tau * tau * c2], [0.0, 1.0, tau * c1], [0.0, 0.0, 1.0 - c1]])
    return Phi, np.array([tau * tau * c3, tau * c2, c1])


def _lag_phi(a: float) -> tuple[float, float, float]:
    """(1 - e^-a, a - 1 + e^-a, a^2/2 - a + 1 - e^-a) for a >= 0, each without cancellation.

    They are -(tails of e^-a = sum_k (-a)^k / k!) from k = 1, 2, 3 on, with signs -, +, -: summed as
    series for a < 1 (the terms fall by a/k; 30 terms leave less than 1e-32 relative), from expm1 for
    a >= 1 (where the subtractions lose at most a few ulps).
    """
    if a >= 1.0:
        c1 = -math.expm1(-a)
        return c1, a - c1, a * a / 2 - a + c1
    # e^-a = sum (-a)^k / k!; c1 = -sum_{k>=1}, c2 = sum_{k>=2}, c3 = -sum_{k>=3}
    terms = [1.0]
    for k in range(1, 30):
        terms.append(terms[-1] * (-a) / k)
    c1 = -math.fsum(terms[1:])
    c2 = math.fsum(terms[2:])
    c3 = -math.fsum(terms[3:])
    return c1, c2, c3


def closed_loop_matrix(gamma: float, lam: float, T: float, delay: int = 0, tau: float = 0.0,
                       observer: bool = False, tf: float = 10.0, compensation: int = 0,
                       plant: str = "zoh", plant_gain: float = 1.0) -> np.ndarray:
    """A of x(k+1) = A x(k) for one task coordinate of the digital RAC (module docstring).

    Args:
        gamma, lam: Gamma and Lambda of that coordinate (Eqs. 10-11).
        T: control period [s]. delay: samples of measurement delay d >= 0.
        tau: thruster first-order lag [s] (0: none). observer: rac_dob's observer, filter time
            constant tf [s] (g = 1/tf). compensation: samples c predicted over (0: none).
        plant: "zoh" (the simulator's zero-order hold) or "ideal" (the paper's idealisation).
        plant_gain: kappa, the plant's acceleration per commanded acceleration (1: an exact
            nominal model; M_true^-1 M_nominal's eigenvalues for an inertia mismatch).

    State: plant (x, v[, f]); x(k-1) .. x(k-d-1); u(k-1) .. u(k-c-1) where c > 0; y_hat(k-1) where
    c > 0; z where observer.
    """
    if not (isinstance(delay, (int, np.integer)) and delay >= 0):
        raise ValueError(f"delay = {delay!r} must be a whole number of samples >= 0")
    if not (isinstance(compensation, (int, np.integer)) and compensation >= 0):
        raise ValueError(f"compensation = {compensation!r} must be a whole number of samples >= 0")
    Phi, Gam = _plant(T, tau if plant == "zoh" else 0.0, plant)
    npl = Phi.shape[0]
    ih = npl + np.arange(delay + 1)  # x(k-1-i)
    nu = compensation + 1 if compensation else 0
    iu = npl + delay + 1 + np.arange(nu)  # u(k-1-i)
    iyp = npl + delay + 1 + nu if compensation else None  # y_hat(k-1)
    iz = npl + delay + 1 + nu + (1 if compensation else 0) if observer else None
    n = npl + delay + 1 + nu + (1 if compensation else 0) + (1 if observer else 0)

    def e(i: int) -> np.ndarray:
        r = np.zeros(n)
        r[i] = 1.0
        return r

    y = e(0) if delay == 0 else e(ih[delay - 1])  # x(k-d)
    y1 = e(ih[delay])  # x(k-d-1)
    if compensation:
        v = (y - y1) / T + T / 2 * e(iu[compensation])  # v(k-c) estimate
        yh = y.copy()
        for j in range(compensation - 1, -1, -1):  # u(k-1-j), oldest first
            yh = yh + T * v + T * T / 2 * e(iu[j])
            v = v + T * e(iu[j])
        yh1 = e(iyp)
    else:
        yh, yh1 = y, y1
    s = (yh - yh1) / T
    vd, vdn = -gamma * yh1 / T, -gamma * yh / T
    ad = (vdn - vd + lam * (vd - s)) / T
    u = ad + (e(iz) - s / tf if observer else 0.0)
    A = np.zeros((n, n))
    A[:npl, :npl] = Phi
    A[:npl] += plant_gain * np.outer(Gam, u)
    A[ih[0]] = e(0)
    for i in range(1, delay + 1):
        A[ih[i]] = e(ih[i - 1])
    if compensation:
        A[iu[0]] = u
        for i in range(1, nu):
            A[iu[i]] = e(iu[i - 1])
        A[iyp] = yh
    if observer:
        h = math.exp(-T / tf)
        A[iz] = h * e(iz) + (1.0 - h) * (u + s / tf)
    return A


def spectral_radius(A: np.ndarray) -> float:
    """max |eig(A)|: the sampled loop is asymptotically stable when it is below 1."""
    return float(np.max(np.abs(np.linalg.eigvals(A))))


@functools.lru_cache(maxsize=256)  # a pure function of its numbers: validate creates a RAC up to 3 times
def largest_stable_gain(T: float, delay: int = 0, tau: float = 0.0, observer: bool = False, tf: float = 10.0,
                        compensation: int = 0, plant: str = "zoh", ratio: float = 1.0, tol: float = GAIN_TOL,
                        hi: float = 1.0, plant_gain: float = 1.0) -> float:
    """The largest gamma (lambda = ratio x gamma; the paper's Gamma = Lambda: ratio 1) in (0, hi)
    with spectral radius below 1, by bisection to ``tol``: the loop is stable at the lower end of
    the interval returned. Returns ``hi`` where every gain up to it is stable.

    Raises:
        ValueError: unstable already at gain tol (nothing to bisect)."""

    def stable(g: float) -> bool:
        return spectral_radius(closed_loop_matrix(g, ratio * g, T, delay, tau, observer, tf, compensation,
                                                  plant, plant_gain)) < 1.0

    lo = tol
    if not stable(lo):
        raise ValueError(f"unstable already at gain {lo:g} (T = {T:g} s, delay = {delay}, tau = {tau:g} s)")
    if stable(hi - tol):
        return hi
    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if stable(mid) else (lo, mid)
    return lo


def thruster_lag(model) -> float:
    """The largest first-order lag time constant [s] of a MuJoCo model's thrusters (site
    actuators): a ``uvms.thruster`` plugin's ``tau`` or a ``filter`` actuator's dynprm[0]; 0
    without thrusters or lag."""
    import mujoco

    from uvms_mj.physics.thrusters.curves import _THRUSTER_ATTRIBUTES

    taus = [0.0]
    for a in range(model.nu):
        if model.actuator_trntype[a] != mujoco.mjtTrn.mjTRN_SITE:
            continue
        i = int(model.actuator_plugin[a])
        if i >= 0:
            start = int(model.plugin_attradr[i])
            end = int(model.plugin_attradr[i + 1]) if i + 1 < model.nplugin else int(model.npluginattr)
            vals = bytes(np.asarray(model.plugin_attr[start:end], dtype=np.uint8)).decode().split("\0")[:-1]
            cfg = dict(zip(_THRUSTER_ATTRIBUTES, vals))
            taus.append(float(cfg.get("tau") or 0.0))
        elif int(model.actuator_dyntype[a]) in (int(mujoco.mjtDyn.mjDYN_FILTER), int(mujoco.mjtDyn.mjDYN_FILTEREXACT)):
            taus.append(float(model.actuator_dynprm[a][0]))
    return max(taus)


def check_margin_settings(gain_margin, delay_compensation) -> None:
    """RAC's ``gain_margin`` (a number >= 1) and ``delay_compensation`` (a whole number >= 0).

    Raises:
        ControllerError: naming the parameter, its value and what is allowed."""
    from uvms_mj.control.base import ControllerError

    if not (isinstance(gain_margin, (int, float)) and not isinstance(gain_margin, bool)
            and math.isfinite(gain_margin) and gain_margin >= 1.0):
        raise ControllerError(f"gain_margin = {gain_margin!r} must be a number >= 1")
    if not (isinstance(delay_compensation, (int, np.integer)) and not isinstance(delay_compensation, bool)
            and delay_compensation >= 0):
        raise ControllerError(f"delay_compensation = {delay_compensation!r} must be a whole number of samples >= 0")


def auto_gains(paper: np.ndarray, n_base: int, T: float, tau: float, observer: bool = False, tf: float = 10.0,
               margin: float = GAIN_MARGIN) -> np.ndarray:
    """Our default-gain rule ("auto" gains of ``rac``/``rac_dob`` on a floating robot): per task
    row min(the paper's block gain ``paper``, the largest gain stable with a one-sample
    measurement delay / ``margin``, rounded down to GAIN_STEP); the first ``n_base`` rows (the
    vehicle's) through the thrusters' lag ``tau`` [s], the others (the tip's, arm motors) without."""
    base = largest_stable_gain(T, 1, tau, observer, tf) / margin
    tip = largest_stable_gain(T, 1, 0.0, observer, tf) / margin
    bound = np.floor(np.where(np.arange(paper.size) < n_base, base, tip) / GAIN_STEP) * GAIN_STEP
    return np.minimum(paper, bound)


class DelayPredictor:
    """Our delay compensation (off by default; ``rac``/``rac_dob`` ``delay_compensation`` = d):
    the measured configuration q_m(k) = q(k - d) predicted d samples ahead with the nominal model.

    The nominal model's acceleration over sample j: computed torque realises the commanded
    a(j) = q_ddot_d(j) (qvel coordinates), except for the base force it cannot deliver -- the
    thrusters' saturation (u_B_applied - u_B) and, with ``tau`` > 0, their first-order lag (the
    sample's mean delivered force, f_mean = u + (f - u) (tau/T)(1 - exp(-T/tau)), f the lag's
    state): a(j) = q_ddot_d(j) + M^-1 S_B^T (f_mean(j) - u_B(j)). Each acceleration held over its
    sample:

        v(k-d) = (q_m(k) (-) q_m(k-1)) / T + T/2 a(k-d-1)   (the backward difference is the mean
                                                             velocity over [k-d-1, k-d])
        for j = k-d .. k-1:  q <- q (+) (T v + T^2/2 a(j)),  v <- v + T a(j)

    with (-) / (+) ``mj_differentiatePos`` / ``mj_integratePos`` (quaternions on the manifold).
    Exact for the nominal zero-order-hold double integrator; it does not know the observer's
    estimate or a disturbance (their effect over the d samples is not predicted), and the
    backward difference carries the measurement noise into the prediction (about 2.6 x the
    velocity noise of the undelayed loop for d = 1). With a velocity sensor (qd given)
    v(k-d) = qd (taken as delayed as q) and qd is predicted too.
    """

    def __init__(self, model, T: float, delay: int, base_dofs=(), tau: float = 0.0) -> None:
        self.model, self.T, self.delay = model, float(T), int(delay)
        self.base_dofs = np.asarray(base_dofs, dtype=int)
        self.tau = float(tau)
        r = T / tau if tau > 0 else math.inf
        self._h = math.exp(-r)  # the lag over one sample
        self._c = (1.0 - self._h) / r if tau > 0 else 0.0  # (tau/T)(1 - exp(-T/tau)): the mean's weight
        self.reset(None)

    def reset(self, q) -> None:
        """Forget the history; ``q``: the first measurement (or None)."""
        nv = self.model.nv
        self.acc = [np.zeros(nv) for _ in range(self.delay + 1)]  # a(k-d-1) .. a(k-1), oldest first
        self.q_prev = None if q is None else np.array(q, dtype=float)
        self.f = None  # the thrusters' lag state, as a base generalized force
        self.active = False  # True while the controller computes on a predicted measurement

    def predict(self, q, qd=None) -> tuple[np.ndarray, np.ndarray | None]:
        """(q_hat(k), qd_hat(k)) from the delayed measurement (q, qd) of sample k."""
        import mujoco

        m, T = self.model, self.T
        q = np.array(q, dtype=float)
        if qd is not None:
            v = np.array(qd, dtype=float)
        elif self.q_prev is None:
            v = np.zeros(m.nv)
        else:
            v = np.zeros(m.nv)
            mujoco.mj_differentiatePos(m, v, T, self.q_prev, q)
            v += 0.5 * T * self.acc[0]
        self.q_prev = q
        qh = q.copy()
        for a in self.acc[1:]:
            mujoco.mj_integratePos(m, qh, v + 0.5 * T * a, T)
            v = v + T * a
        return qh, (v if qd is not None else None)

    def command(self, ctrl, m):
        """One sample of ``ctrl`` (a RAC) on the measurement ``m`` predicted over the delay; the
        sample's nominal acceleration is recorded for the next predictions."""
        from uvms_mj.control.base import Measurement

        q, qd = self.predict(m.q, m.qd)
        self.active = True
        try:
            cmd = ctrl.compute(Measurement(k=m.k, t=m.t, q=q, qd=qd))
        finally:
            self.active = False
        sig = cmd.signals
        self.record(sig["qdd_desired"], sig["u_B"], sig["u_B_applied"], lambda: ctrl.robot.mass_matrix(q))
        return cmd

    def record(self, qdd, u_B=None, u_applied=None, mass=None) -> None:
        """The nominal acceleration a(k) of the sample just computed: its commanded q_ddot_d,
        corrected by the base force not delivered (u_B commanded, u_applied after the thrusters'
        limits, ``mass()`` the nominal M at the sample; see the class docstring)."""
        a = np.array(qdd, dtype=float)
        if u_B is not None and self.base_dofs.size:
            u = np.asarray(u_applied, dtype=float)
            f0 = u if self.f is None else self.f
            f_mean = u + (f0 - u) * self._c
            self.f = u + (f0 - u) * self._h
            short = f_mean - np.asarray(u_B, dtype=float)
            if np.any(np.abs(short) > 1e-12 * (1.0 + np.abs(u))):
                rhs = np.zeros(self.model.nv)
                rhs[self.base_dofs] = short
                a += np.linalg.solve(mass(), rhs)
        self.acc = self.acc[1:] + [a]
