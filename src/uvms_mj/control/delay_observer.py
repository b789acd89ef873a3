"""Our predictive state observer over a known measurement delay (``rac``/``rac_dob``
``delay_compensation`` = d with ``delay_observer_pole`` = p; off by default).

Per generalized coordinate (qvel space) a state (q, v, b): position, velocity and an
acceleration mismatch b (the plant's realised acceleration minus the nominal one: an inertia
mismatch kappa != 1, a slow disturbance), the nominal model's response to the commanded
acceleration a(j) held over each sample (computed torque; :meth:`DelayPredictor.record`):

    q(j+1) = q(j) (+) (T v + T^2/2 (a(j) + b)),  v(j+1) = v + T (a(j) + b),  b(j+1) = b

Each delayed measurement y(k) = q(k - d) corrects the estimate of sample k - d (innovation
y (-) q_hat(k-d), gain L), which is then propagated d samples to k with a(k-d) .. a(k-1):

    x_hat+(k-d) = x_hat-(k-d) + L (y(k) (-) q_hat-(k-d)),   x_hat(k) = F^d x_hat+ + inputs

The controller receives q_hat(k) and the filtered velocity v_hat(k) (``Measurement.qd``: RAC then
uses J v_hat as the task velocity instead of the backward difference).

Gain rule (ours): L places the three eigenvalues of the estimation error's dynamics
F (I - L C) at one real pole p (``delay_observer_pole``, default :data:`DELAY_OBSERVER_POLE`),
by Ackermann's formula on the dual; p = 0 is deadbeat. 0.85: the fastest pole, on a 0.05 grid,
at which the sampled loop of one task coordinate (:func:`observed_loop_matrix`) with the paper's
gains, T = 1/60 s, one sample of delay, with and without the observer (rac_dob), is stable for
plant gains kappa in [0.7, 2.5] on the tip rows (0.2 and 0.3, no lag) and in [0.7, 1.4] on the
base rows (0.3, the paper's 0.02 s thruster lag; above about 1.5 the undelayed loop itself is
unstable through the lag) (docs/paper-reading.md "Gains and delay"). Faster poles pass more noise
and lose that range (pole 0.5: unstable at kappa 1.5 on the base rows).
"""

from __future__ import annotations

import math

import numpy as np

from uvms_mj.control.margins import DelayPredictor, _plant

__all__ = ["DELAY_OBSERVER_POLE", "DelayObserver", "observed_loop_matrix", "observer_gain"]

#: Default triple pole of the estimation error (module docstring: the rule that gives it).
DELAY_OBSERVER_POLE = 0.85


def _model(T: float) -> tuple[np.ndarray, np.ndarray]:
    """(F, G) of (q, v, b) with the acceleration a held over T."""
    return np.array([[1.0, T, T * T / 2], [0.0, 1.0, T], [0.0, 0.0, 1.0]]), np.array([T * T / 2, T, 0.0])


def observer_gain(T: float, pole: float) -> np.ndarray:
    """L = (l_q, l_v, l_b) with eig(F (I - L C)) = {pole, pole, pole}, C = (1, 0, 0): Ackermann's
    formula K' = phi(F) O^-1 e_3 (O = [C; C F; C F^2], phi the wanted characteristic polynomial)
    on F - K' C, then L = F^-1 K'."""
    if not (isinstance(pole, (int, float)) and not isinstance(pole, bool) and 0.0 <= pole < 1.0):
        from uvms_mj.control.base import ControllerError

        raise ControllerError(f"delay_observer_pole = {pole!r} must be a number in [0, 1)")
    F, _ = _model(T)
    C = np.array([1.0, 0.0, 0.0])
    O = np.vstack((C, C @ F, C @ F @ F))
    c = np.poly([float(pole)] * 3)
    phi = sum(c[i] * np.linalg.matrix_power(F, 3 - i) for i in range(4))
    return np.linalg.solve(F, phi @ np.linalg.solve(O, np.array([0.0, 0.0, 1.0])))


class DelayObserver(DelayPredictor):
    """The predictive observer of the module docstring (``record``/``command`` as
    :class:`DelayPredictor`'s: a(j) the commanded acceleration corrected for the base force the
    thrusters' limits and lag do not deliver). With a velocity sensor (qd given) it is ignored:
    the observer's velocity is handed on."""

    def __init__(self, model, T: float, delay: int, base_dofs=(), tau: float = 0.0,
                 pole: float = DELAY_OBSERVER_POLE) -> None:
        self.pole = float(pole)
        self.L = observer_gain(T, pole)
        super().__init__(model, T, delay, base_dofs, tau)

    def reset(self, q) -> None:
        super().reset(q)
        nv = self.model.nv
        self.post = None if q is None else (np.array(q, dtype=float), np.zeros(nv), np.zeros(nv))

    def _step(self, q, v, b, a):
        import mujoco

        q = q.copy()
        mujoco.mj_integratePos(self.model, q, v + 0.5 * self.T * (a + b), self.T)
        return q, v + self.T * (a + b), b

    def predict(self, q, qd=None) -> tuple[np.ndarray, np.ndarray]:
        """(q_hat(k), v_hat(k)) from the delayed measurement q(k - d)."""
        import mujoco

        y = np.array(q, dtype=float)
        if self.post is None:
            self.post = (y, np.zeros(self.model.nv), np.zeros(self.model.nv))
        qe, ve, be = self._step(*self.post, self.acc[0])  # the prior of sample k - d
        innov = np.zeros(self.model.nv)
        mujoco.mj_differentiatePos(self.model, innov, 1.0, qe, y)
        mujoco.mj_integratePos(self.model, qe, self.L[0] * innov, 1.0)
        ve, be = ve + self.L[1] * innov, be + self.L[2] * innov
        self.post = (qe, ve, be)
        for a in self.acc[1:]:
            qe, ve, be = self._step(qe, ve, be, a)
        self.b_hat = be
        return qe, ve


def observed_loop_matrix(gamma: float, lam: float, T: float, delay: int, pole: float, plant_gain: float = 1.0,
                         tau: float = 0.0, observer: bool = False, tf: float = 10.0) -> np.ndarray:
    """A of x(k+1) = A x(k) for one task coordinate of the digital RAC (the loop of
    :mod:`uvms_mj.control.margins`, regulation, mass 1) with :class:`DelayObserver`: the
    controller's position is q_hat(k), its velocity v_hat(k) (instead of the backward
    difference), a_d(k) = (-gamma q_hat(k) + gamma q_hat(k-1) + lam (-gamma q_hat(k-1) - T v_hat)) / T^2,
    u = a_d + f_hat with rac_dob's f_hat = z - g v_hat, z(k+1) = h z + (1 - h)(u + g v_hat); the
    plant x_ddot = plant_gain x f (f = u, or through the lag tau); the observer's input a_d.

    State: plant (x, v[, f]); x(k-1) .. x(k-d); the observer's prior at k - d; a_d(k-d) ..
    a_d(k-1); q_hat(k-1); z. Built column by column from the (linear) sample map."""
    Phi, Gam = _plant(T, tau, "zoh")
    F, G = _model(T)
    L = observer_gain(T, pole)
    h, g = math.exp(-T / tf), 1.0 / tf
    npl, d = Phi.shape[0], int(delay)
    n = npl + d + 3 + d + 2

    def step(s: np.ndarray) -> np.ndarray:
        p, ch = s[:npl], s[npl:npl + d]
        xo, ah, qp, z = s[npl + d:npl + d + 3], s[npl + d + 3:npl + 2 * d + 3], s[-2], s[-1]
        y = p[0] if d == 0 else ch[d - 1]
        xp = xo + L * (y - xo[0])
        x = xp.copy()
        for a in ah:
            x = F @ x + G * a
        ad = (-gamma * x[0] + gamma * qp + lam * (-gamma * qp - T * x[1])) / (T * T)
        u = ad + (z - g * x[1] if observer else 0.0)
        out = np.zeros(n)
        out[:npl] = Phi @ p + plant_gain * Gam * u
        if d:
            out[npl] = p[0]
            out[npl + 1:npl + d] = ch[:d - 1]
            out[npl + d + 3:npl + 2 * d + 3] = np.r_[ah[1:], ad]
        out[npl + d:npl + d + 3] = F @ xp + G * (ah[0] if d else ad)
        out[-2] = x[0]
        out[-1] = h * z + (1.0 - h) * (u + g * x[1]) if observer else 0.0
        return out

    return np.column_stack([step(e) for e in np.eye(n)])
