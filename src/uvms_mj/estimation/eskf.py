"""Error-state Kalman filter (ESKF) for the vehicle's pose, velocity and IMU biases (issue 21, item 2).

Reference: J. Solà, "Quaternion kinematics for the error-state Kalman filter", arXiv:1711.02508 (2017), Sec. 5-7;
equation numbers below are that text's. Nominal state ``x`` (Sec. 5.3):

* ``p``  position of the vehicle body origin [m], world;
* ``v``  its velocity [m/s], world;
* ``q``  orientation, world <- vehicle body, unit quaternion (w, x, y, z);
* ``a_b`` accelerometer bias [m/s^2], IMU site frame;
* ``w_b`` gyro bias [rad/s], IMU site frame.

Error state ``dx = (dp, dv, dtheta, da_b, dw_b)`` (15), ``dtheta`` the *local* (body-frame) angle error,
``q_true = q (x) q{dtheta}`` (Sec. 5.3.2, Eq. 235 ff.). Gravity is not estimated: it is the caller's ``gravity``.

IMU on a mount (site position ``r`` and rotation ``R_m``, site -> body, in the vehicle body frame). With the
bias-corrected site rate and specific force, the vehicle body's rate and the specific force at the body origin are::

    w     = R_m (w_m - w_b)                                   [rad/s], body
    f     = R_m (a_m - a_b) - alpha x r - w x (w x r)         [m/s^2], body (rigid-body acceleration transport)

``alpha`` is the body angular acceleration, taken as the difference of consecutive bias-corrected rates over the
IMU period (``angular_acceleration="difference"``, the default; ``"none"`` drops the term). Its noise is not in
``Q``: integrated into velocity, the differenced gyro noise telescopes to ``(n_k - n_0) x r`` (bounded, of size
``sigma_gyro_discrete |r|``), not a random walk. Gyro noise entering through ``w x (w x r)`` is also neglected in
``Q`` (second order in ``|r| |w|``). Consecutive samples are averaged over each interval (trapezoidal hold).

Propagation (Sec. 5.4.1 nominal, Eq. 260; Sec. 5.4.3 error-state covariance, Eq. 269 ``F_x``, ``F_i``, ``Q_i``),
with ``R = R{q}``::

    p <- p + v dt + (R f + g) dt^2 / 2
    v <- v + (R f + g) dt
    q <- q (x) q{w dt}
    P <- F_x P F_x^T + F_i Q_i F_i^T

Noise (Eq. 269's ``Q_i`` from the sensors' continuous-time densities: ``sigma_discrete^2 = density^2 / dt``, so
the velocity and angle impulses have variance ``density^2 dt`` and the bias impulses ``rw^2 dt``):
``accel_noise_density`` [m/s^2/sqrt(Hz)], ``gyro_noise_density`` [rad/s/sqrt(Hz)] (Allan-variance VRW, ARW),
``accel_bias_rw`` [m/s^3/sqrt(Hz)], ``gyro_bias_rw`` [rad/s^2/sqrt(Hz)] (bias random walk).

Updates (Sec. 6.1, Eq. 272-278; Joseph form of Eq. 276), injection (Sec. 6.2, Eq. 282-283) and reset
(Sec. 6.3, Eq. 284-287: ``P <- G P G^T``, ``G = diag(I6, I - [dtheta/2]x, I6)``). ``H`` is derived directly
against the error state (the chain ``H_x X_dx`` of Eq. 278-280 done by hand), see :mod:`.models`.

Delayed measurements: the filter keeps, per IMU sample over the last ``buffer_s`` seconds, the IMU sample, the
state and covariance after propagation to it, and the measurements assigned to it. A measurement is assigned to
the IMU time nearest its measurement time ``t``; one in the past rewinds to that time, is applied there, and the
IMU samples and measurements after it are replayed (exact re-propagation, the "buffer and re-propagate" method).
A measurement ahead of the last IMU sample waits until the IMU reaches it. One older than the buffer is rejected
(counted in ``ESKF.rejected``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from uvms_mj.estimation.measurements import DepthSample, DvlSample, FixSample, ImuSample, Mount
from uvms_mj.estimation.models import (EstimatorError, cross, depth_model, dvl_model, fix_model, skew, so3_exp,
                                       yaw_model)
from uvms_mj.rotations import quat_from_rotvec, quat_mul, quat_to_mat

__all__ = ["ESKF", "EskfParams", "NavEstimate", "NavState"]

_IDENTITY_MOUNT = Mount(position=np.zeros(3), quat=np.array([1.0, 0.0, 0.0, 0.0]))


@dataclass(frozen=True)
class NavState:
    """Nominal state: position [m] and velocity [m/s] of the vehicle body origin (world), orientation world <- body
    (w, x, y, z), accelerometer bias [m/s^2] and gyro bias [rad/s] (IMU site frame)."""
    position: np.ndarray
    velocity: np.ndarray
    quat: np.ndarray
    accel_bias: np.ndarray = field(default_factory=lambda: np.zeros(3))
    gyro_bias: np.ndarray = field(default_factory=lambda: np.zeros(3))


@dataclass(frozen=True)
class NavEstimate:
    """The estimate at time ``t`` [s]: the nominal state, the body rate (vehicle body frame, bias-corrected, from
    the latest IMU sample) and the 15 x 15 error-state covariance (order dp, dv, dtheta, da_b, dw_b)."""
    t: float
    position: np.ndarray
    velocity: np.ndarray
    quat: np.ndarray
    accel_bias: np.ndarray
    gyro_bias: np.ndarray
    angular_velocity: np.ndarray
    covariance: np.ndarray

    @property
    def sigma(self) -> np.ndarray:
        """Standard deviations of the 15 error-state components."""
        return np.sqrt(np.diag(self.covariance))


@dataclass(frozen=True)
class EskfParams:
    """Filter parameters (SI). Defaults are ours, a MEMS-class IMU and Water Linked A50-class DVL order of
    magnitude; the scenario should set them from the sensors' datasheets.

    ``gravity``: (3,) world [m/s^2] (the caller's, e.g. the model's ``opt.gravity``). Mounts: the sensors' sites in
    the vehicle body frame (the depth sensor's and fix site's rotations matter only for the fix's yaw).
    ``dvl_sigma`` [m/s] per DVL-frame axis, ``depth_sigma`` [m], ``fix_sigma`` [m] per world axis, ``yaw_sigma``
    [rad]. ``buffer_s`` [s]: how far back a delayed measurement is replayed. ``angular_acceleration``:
    "difference" or "none" (the lever arm's alpha x r term). ``fix_gate`` / ``dvl_gate``: outlier gates on the
    normalised innovation squared (e.g. ``scipy.stats.chi2.ppf(0.999, 3)`` = 16.27 for a position fix; 4 dof with
    yaw), None = off."""
    gravity: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, -9.81]))
    imu_mount: Mount = _IDENTITY_MOUNT
    dvl_mount: Mount = _IDENTITY_MOUNT
    depth_mount: Mount = _IDENTITY_MOUNT
    fix_mount: Mount = _IDENTITY_MOUNT
    accel_noise_density: float = 2.0e-3
    gyro_noise_density: float = 3.0e-4
    accel_bias_rw: float = 1.0e-4
    gyro_bias_rw: float = 1.0e-5
    dvl_sigma: float | tuple = 0.01
    depth_sigma: float = 0.02
    fix_sigma: float | tuple = 0.1
    yaw_sigma: float = 0.02
    buffer_s: float = 2.0
    angular_acceleration: str = "difference"
    fix_gate: Optional[float] = None
    dvl_gate: Optional[float] = None


def _vec(name: str, value, n: int) -> np.ndarray:
    a = np.asarray(value, dtype=float)
    if a.shape == ():
        a = np.full(n, float(a))
    if a.shape != (n,) or not np.all(np.isfinite(a)):
        raise EstimatorError(f"{name} = {value!r}: expected {n} finite numbers")
    return a


def _positive(name: str, value) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = float("nan")
    if not (v > 0.0 and math.isfinite(v)):
        raise EstimatorError(f"{name} = {value!r}: expected a positive finite number")
    return v


def _mount(name: str, m: Mount) -> tuple[np.ndarray, np.ndarray]:
    r = _vec(f"{name}.position", m.position, 3)
    qm = _vec(f"{name}.quat", m.quat, 4)
    if abs(np.linalg.norm(qm) - 1.0) > 1e-6:
        raise EstimatorError(f"{name}.quat = {m.quat!r}: expected a unit quaternion (w, x, y, z)")
    return r, quat_to_mat(qm)


class ESKF:
    """Error-state Kalman filter: ``ESKF(initial_state, P0, params)``; feed ``on_imu`` at the IMU rate and
    ``on_dvl`` / ``on_depth`` / ``on_fix`` when the samples arrive (any order, by their measurement time);
    ``state()`` gives the estimate. See the module docstring for the equations."""

    def __init__(self, initial_state: NavState, P0: np.ndarray, params: EskfParams = EskfParams()):
        self.params = params
        x = np.concatenate([_vec("initial_state.position", initial_state.position, 3),
                            _vec("initial_state.velocity", initial_state.velocity, 3),
                            _vec("initial_state.quat", initial_state.quat, 4),
                            _vec("initial_state.accel_bias", initial_state.accel_bias, 3),
                            _vec("initial_state.gyro_bias", initial_state.gyro_bias, 3)])
        if np.linalg.norm(x[6:10]) < 1e-9:
            raise EstimatorError(f"initial_state.quat = {initial_state.quat!r}: expected a non-zero quaternion")
        x[6:10] /= np.linalg.norm(x[6:10])
        P = np.asarray(P0, dtype=float)
        if P.shape != (15, 15) or not np.all(np.isfinite(P)) or np.any(np.linalg.eigvalsh(0.5 * (P + P.T)) < 0):
            raise EstimatorError(f"P0 shape {P.shape}: expected a finite symmetric positive semi-definite 15 x 15")
        self._g = _vec("params.gravity", params.gravity, 3)
        self._ri, self._Rmi = _mount("params.imu_mount", params.imu_mount)
        self._rd, self._Rmd = _mount("params.dvl_mount", params.dvl_mount)
        self._rp, _ = _mount("params.depth_mount", params.depth_mount)
        self._rf, self._Rmf = _mount("params.fix_mount", params.fix_mount)
        self._na2 = _positive("params.accel_noise_density", params.accel_noise_density) ** 2
        self._ng2 = _positive("params.gyro_noise_density", params.gyro_noise_density) ** 2
        self._nab2 = _positive("params.accel_bias_rw", params.accel_bias_rw) ** 2
        self._ngb2 = _positive("params.gyro_bias_rw", params.gyro_bias_rw) ** 2
        self._Vdvl = np.diag(_vec("params.dvl_sigma", params.dvl_sigma, 3) ** 2)
        self._Vdepth = _positive("params.depth_sigma", params.depth_sigma) ** 2
        self._Vfix = np.diag(_vec("params.fix_sigma", params.fix_sigma, 3) ** 2)
        self._Vyaw = _positive("params.yaw_sigma", params.yaw_sigma) ** 2
        self._buffer_s = _positive("params.buffer_s", params.buffer_s)
        if params.angular_acceleration not in ("difference", "none"):
            raise EstimatorError(f"params.angular_acceleration = {params.angular_acceleration!r}: "
                                 "expected 'difference' or 'none'")
        self._alpha = params.angular_acceleration == "difference"
        for name in ("fix_gate", "dvl_gate"):
            if getattr(params, name) is not None:
                _positive(f"params.{name}", getattr(params, name))
        self._gated_ids: set = set()
        self._x, self._P = x, 0.5 * (P + P.T)
        self._F, self._I3, self._skew_r = np.eye(15), np.eye(3), skew(self._ri)
        self._qidx = np.arange(3, 15)
        self._qdiag = np.repeat([self._na2, self._ng2, self._nab2, self._ngb2], 3)
        # history, one entry per IMU sample: sample, (x, P) after propagation to it, measurements assigned to it
        self._imu: list[ImuSample] = []
        self._pre: list[tuple[np.ndarray, np.ndarray]] = []
        self._meas: list[list] = []
        self._pending: list = []
        self.rejected = 0
        self._dt_nominal = None

    # ---------------------------------------------------------------- propagation
    def _body_rate(self, x: np.ndarray, s: ImuSample) -> np.ndarray:
        return self._Rmi @ (np.asarray(s.gyro, dtype=float) - x[13:16])

    def _propagate(self, x: np.ndarray, P: np.ndarray, s0: ImuSample, s1: ImuSample):
        """Nominal (Eq. 260) and covariance (Eq. 269) from sample s0's time to s1's, the samples averaged."""
        dt = s1.t - s0.t
        ab, wb = x[10:13], x[13:16]
        Rmi = self._Rmi
        w0 = Rmi @ (s0.gyro - wb)
        w1 = Rmi @ (s1.gyro - wb)
        w = 0.5 * (w0 + w1)
        f_site = Rmi @ (0.5 * (s0.acc + s1.acc) - ab)
        r = self._ri
        wr = cross(w, r)
        f = f_site - cross(w, wr)
        if self._alpha:
            f = f - cross((w1 - w0) / dt, r)
        R = quat_to_mat(x[6:10])
        dR = so3_exp(w * dt)
        # f rotated with the mid-interval attitude R Exp(w dt / 2) (second order; R alone drifts ~1 cm in 10 s)
        a = R @ (so3_exp(0.5 * w * dt) @ f) + self._g
        xn = x.copy()
        xn[0:3] = x[0:3] + x[3:6] * dt + 0.5 * a * dt * dt
        xn[3:6] = x[3:6] + a * dt
        q = quat_mul(x[6:10], quat_from_rotvec(w * dt))
        xn[6:10] = q / math.sqrt(q @ q)
        # F_x (Eq. 269) with the mount: df/dtheta via R, df/da_b = -R_m, df/dw_b = (dc/dw) R_m where
        # c = w x (w x r), dc/dw = -[w x r]x - [w]x [r]x
        F = self._F
        F[0:3, 3:6] = self._I3 * dt
        F[3:6, 6:9] = -(R @ skew(f)) * dt
        RRm = R @ Rmi
        F[3:6, 9:12] = -RRm * dt
        F[3:6, 12:15] = (R @ (-skew(wr) - skew(w) @ self._skew_r) @ Rmi) * dt
        F[6:9, 6:9] = dR.T
        F[6:9, 12:15] = -Rmi * dt
        Pn = F @ P @ F.T
        # F_i Q_i F_i^T (Eq. 269): isotropic densities, so the rotations into world/body drop out
        idx = self._qidx
        Pn[idx, idx] += self._qdiag * dt
        return xn, 0.5 * (Pn + Pn.T)

    # ---------------------------------------------------------------- update, injection, reset
    def _update(self, x: np.ndarray, P: np.ndarray, innovation: np.ndarray, H: np.ndarray, V: np.ndarray,
                gate: Optional[float] = None, m=None):
        """Eq. 272-276 (Joseph form), injection Eq. 282-283, reset Eq. 284-287. With ``gate``, a measurement whose
        normalised innovation squared exceeds it is skipped (an outlier) and remembered in ``gated``."""
        S = H @ P @ H.T + V
        if gate is not None and innovation @ np.linalg.solve(S, innovation) > gate:
            self._gated_ids.add(id(m))
            return x, P
        K = np.linalg.solve(S, H @ P).T
        dx = K @ innovation
        IKH = np.eye(15) - K @ H
        P = IKH @ P @ IKH.T + K @ V @ K.T
        x = x.copy()
        x[0:6] += dx[0:6]
        q = quat_mul(x[6:10], quat_from_rotvec(dx[6:9]))
        x[6:10] = q / np.linalg.norm(q)
        x[10:16] += dx[9:15]
        G = np.eye(15)
        G[6:9, 6:9] -= skew(0.5 * dx[6:9])
        P = G @ P @ G.T
        return x, 0.5 * (P + P.T)

    def _apply(self, x: np.ndarray, P: np.ndarray, m, s: ImuSample):
        if isinstance(m, DvlSample):
            h, H = dvl_model(x, self._body_rate(x, s), self._Rmi, self._rd, self._Rmd)
            return self._update(x, P, np.asarray(m.velocity, dtype=float) - h, H, self._Vdvl, self.params.dvl_gate, m)
        if isinstance(m, DepthSample):
            h, H = depth_model(x, self._rp)
            return self._update(x, P, np.array([float(m.depth) - h]), H[None, :], np.array([[self._Vdepth]]))
        h, H = fix_model(x, self._rf)
        innov, V = np.asarray(m.position, dtype=float) - h, self._Vfix
        if m.yaw is not None:
            hy, Hy = yaw_model(x, self._Rmf)
            dy = math.remainder(float(m.yaw) - hy, 2.0 * math.pi)
            innov, H = np.concatenate([innov, [dy]]), np.vstack([H, Hy])
            V = np.diag(np.concatenate([np.diag(V), [self._Vyaw]]))
        return self._update(x, P, innov, H, V, self.params.fix_gate, m)

    # ---------------------------------------------------------------- public interface
    def on_imu(self, s: ImuSample) -> None:
        """An IMU sample (site frame, the mount's): propagate to its time, apply the measurements due."""
        if not (np.shape(s.acc) == (3,) and np.shape(s.gyro) == (3,)):
            raise EstimatorError(f"ImuSample at t = {s.t}: acc and gyro must be (3,) arrays")
        s = ImuSample(t=float(s.t), acc=np.asarray(s.acc, dtype=float), gyro=np.asarray(s.gyro, dtype=float))
        if self._imu:
            if not s.t > self._imu[-1].t:
                raise EstimatorError(f"ImuSample.t = {s.t}: expected after the previous sample's {self._imu[-1].t}")
            self._x, self._P = self._propagate(self._x, self._P, self._imu[-1], s)
        self._imu.append(s)
        self._pre.append((self._x, self._P))
        self._meas.append([])
        if len(self._imu) >= 2 and self._dt_nominal is None:
            self._dt_nominal = self._imu[1].t - self._imu[0].t
        while len(self._imu) > 2 and self._imu[-1].t - self._imu[1].t > self._buffer_s:
            del self._imu[0], self._pre[0], self._meas[0]
        waiting = [self._slot(m.t) is None for m in self._pending]
        due = [m for m, w in zip(self._pending, waiting) if not w]
        self._pending = [m for m, w in zip(self._pending, waiting) if w]
        for m in sorted(due, key=lambda m: m.t):
            self._insert(m)

    def _slot(self, t: float) -> Optional[int]:
        """Index of the IMU sample nearest t; None when t is ahead of the last one by more than half a period."""
        half = 0.5 * (self._dt_nominal or 0.0)
        if t > self._imu[-1].t + half:
            return None
        times = np.fromiter((s.t for s in self._imu), float, len(self._imu))
        j = int(np.searchsorted(times, t))
        if j >= len(times) or (j > 0 and t - times[j - 1] <= times[j] - t):
            j = max(j - 1, 0)
        return j

    def _insert(self, m) -> bool:
        if not self._imu:
            self._pending.append(m)
            return True
        j = self._slot(m.t)
        if j is None:
            self._pending.append(m)
            return True
        if j == 0 and m.t < self._imu[0].t - 0.5 * (self._dt_nominal or 0.0) and len(self._imu) > 1:
            self.rejected += 1
            return False
        self._meas[j].append(m)
        self._meas[j].sort(key=lambda mm: mm.t)
        x, P = self._pre[j]
        for i in range(j, len(self._imu)):
            if i > j:
                x, P = self._propagate(x, P, self._imu[i - 1], self._imu[i])
                self._pre[i] = (x, P)
            for mm in self._meas[i]:
                x, P = self._apply(x, P, mm, self._imu[i])
        self._x, self._P = x, P
        return True

    def on_dvl(self, s: DvlSample) -> bool:
        """A DVL sample (velocity over ground in the DVL frame); a dropout (velocity None) is ignored. Returns
        False when it is older than the buffer (rejected)."""
        if s.velocity is None:
            return True
        if np.shape(s.velocity) != (3,) or not np.all(np.isfinite(s.velocity)):
            raise EstimatorError(f"DvlSample.velocity = {s.velocity!r}: expected (3,) finite [m/s] or None")
        return self._insert(s)

    def on_depth(self, s: DepthSample) -> bool:
        """A depth sample [m, positive down]. Returns False when older than the buffer."""
        if not math.isfinite(float(s.depth)):
            raise EstimatorError(f"DepthSample.depth = {s.depth!r}: expected a finite number [m]")
        return self._insert(s)

    def on_fix(self, s: FixSample) -> bool:
        """A position fix (world, of the fix site), with yaw when given. Returns False when older than the
        buffer."""
        if np.shape(s.position) != (3,) or not np.all(np.isfinite(s.position)):
            raise EstimatorError(f"FixSample.position = {s.position!r}: expected (3,) finite [m]")
        return self._insert(s)

    def state(self, t: Optional[float] = None) -> NavEstimate:
        """The estimate at the last IMU sample (``t`` None or equal to it), or extrapolated to a later ``t`` with
        the last IMU sample held (the filter is not changed)."""
        x, P = self._x, self._P
        if not self._imu:
            return self._estimate(0.0 if t is None else t, x, P, np.zeros(3))
        last = self._imu[-1]
        if t is not None and t > last.t + 1e-12:
            x, P = self._propagate(x, P, last, ImuSample(t=t, acc=last.acc, gyro=last.gyro))
        elif t is not None and t < last.t - 1e-12:
            raise EstimatorError(f"state(t = {t}): expected t >= the last IMU sample's {last.t}")
        return self._estimate(last.t if t is None else t, x, P, self._body_rate(x, last))

    @property
    def gated(self) -> int:
        """How many measurements the outlier gates rejected."""
        return len(self._gated_ids)

    @staticmethod
    def _estimate(t, x, P, w) -> NavEstimate:
        return NavEstimate(t=float(t), position=x[0:3].copy(), velocity=x[3:6].copy(), quat=x[6:10].copy(),
                           accel_bias=x[10:13].copy(), gyro_bias=x[13:16].copy(), angular_velocity=w,
                           covariance=P.copy())
