"""Joint and torque limits as a controller sees them: on its NOMINAL model only.

Every controller keeps the arm inside the joint ranges of its own model (``jnt_range`` of the
limited joints, :class:`uvms_mj.control.nominal.NominalRobot`; never the plant's) minus a margin,
and its joint torques inside the motors' ranges (:func:`uvms_mj.plant.layout.motor_torque_range`).

**The discrete velocity damper** (ours; :func:`clamp_joint_acceleration`, used by ``rac`` and
``rac_dob`` in their Python code and their compiled kernel alike). A joint of the nominal model
is a double integrator under the zero-order hold over T: with the acceleration a held,

    q(k+1) = q + T qd + T^2 a / 2,     qd(k+1) = qd + T a.

With d = hi - q the distance to the upper bound hi (the range minus the margin), we require the
velocity at k + 1 to be at most the fraction beta = T / ``tau`` of the distance left then,
qd(k+1) <= beta d(k+1) / T (a velocity damper: qd <= d / tau), which is the bound

    a <= a_hi = (beta (hi - q) / T - (1 + beta) qd) / (T (1 + beta / 2))

(and a >= a_lo, the same with lo). Why it holds the range: at the bound the distance becomes
d(k+1) = (2 d - T qd) / (2 + beta), >= 0 whenever T qd <= 2 d, which the constraint itself
keeps (beta <= 2): once inside the damper's region a joint approaches its bound geometrically,
d(k+1) / d(k) = (1 - beta/2) / (1 + beta/2), and never passes it (on the nominal model, with the
torque it needs); a joint outside its bound is pushed back the same way. a_lo < a_hi always
(lo < hi), so the clamp is well defined. Far from the bounds (d > tau |qd| roughly) it is inactive
and the controller's own acceleration passes unchanged. Unlimited joints (a range not limited in
the model) have infinite bounds: never clamped.

Defaults (ours, named below): the margin :data:`JOINT_LIMIT_MARGIN` = 2 deg and the damper's time
constant :data:`JOINT_LIMIT_TIME` = 0.1 s (beta = 0.2 at 50 Hz, a per-sample approach ratio of
0.82): a joint at 1 rad/s starts braking 0.1 rad before its bound, with about 10 rad/s^2.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from uvms_mj.control.base import ControllerError
from uvms_mj.plant.layout import motor_torque_range

__all__ = ["JOINT_LIMIT_MARGIN", "JOINT_LIMIT_TIME", "JointLimits", "clamp_joint_acceleration", "nominal_joint_range"]

#: Margin kept inside every limited joint's range [rad] (ours: 2 deg): the controller's bounds are
#: (lo + margin, hi - margin) of its nominal model, so that the plant's joint, which differs from
#: the nominal one (mass, drag, torque saturation, sensor noise), stays inside its true range.
JOINT_LIMIT_MARGIN = math.radians(2.0)
#: Time constant of the discrete velocity damper [s] (ours): near a bound the joint's velocity is
#: kept below (distance to the bound) / tau (module docstring).
JOINT_LIMIT_TIME = 0.1


def nominal_joint_range(model: mujoco.MjModel, qadr, margin: float = JOINT_LIMIT_MARGIN) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) [rad or m] of the joints at qpos addresses ``qadr`` (hinge or slide joints of
    ``model``): the limited joints' ``jnt_range`` shrunk by ``margin`` on each side, -inf / +inf
    for the others. Raises ControllerError for a range narrower than twice the margin."""
    qadr = np.asarray(qadr, dtype=int).ravel()
    lo, hi = np.full(qadr.size, -np.inf), np.full(qadr.size, np.inf)
    by_adr = {int(model.jnt_qposadr[j]): j for j in range(model.njnt)}
    for i, a in enumerate(qadr):
        j = by_adr.get(int(a))
        if j is None or not model.jnt_limited[j] or int(model.jnt_type[j]) not in (
                int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE)):
            continue
        r0, r1 = (float(v) for v in model.jnt_range[j])
        if r1 - r0 <= 2.0 * margin:
            name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j) or f"joint {j}"
            raise ControllerError(f"joint_limit_margin = {margin!r}: joint {name}'s range [{r0:g}, {r1:g}] is "
                                  f"narrower than twice the margin; allowed: a margin below {(r1 - r0) / 2:g}")
        lo[i], hi[i] = r0 + margin, r1 - margin
    return lo, hi


def clamp_joint_acceleration(q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                             T: float, beta: float) -> np.ndarray:
    """The desired joint accelerations ``qdd`` clamped to the discrete velocity damper's bounds
    [a_lo, a_hi] (module docstring) for joints at ``q`` moving at ``qd``, bounds ``lo``, ``hi``
    (+-inf: none), period T, beta = T / tau in (0, 2]. A new array."""
    den = T * (1.0 + 0.5 * beta)
    a_hi = (beta * (hi - q) / T - (1.0 + beta) * qd) / den
    a_lo = (beta * (lo - q) / T - (1.0 + beta) * qd) / den
    return np.minimum(np.maximum(qdd, a_lo), a_hi)


class JointLimits:
    """A controller's joint-limit settings on its nominal model (module docstring).

    Args:
        model: the controller's nominal MjModel.
        qadr: qpos addresses of the arm joints the controller commands.
        T: the control period [s].
        enabled: keep the joints inside their ranges (False: no clamping).
        margin: :data:`JOINT_LIMIT_MARGIN` [rad] (m for a slide joint), >= 0.
        tau: :data:`JOINT_LIMIT_TIME` [s], >= T / 2 (beta = T / tau <= 2).
    """

    def __init__(self, model: mujoco.MjModel, qadr, T: float, enabled: bool = True,
                 margin: float = JOINT_LIMIT_MARGIN, tau: float = JOINT_LIMIT_TIME) -> None:
        if not isinstance(enabled, bool):
            raise ControllerError(f"joint_limits = {enabled!r} must be true or false")
        try:
            margin, tau = float(margin), float(tau)
        except (TypeError, ValueError):
            raise ControllerError(f"joint_limit_margin = {margin!r}, joint_limit_time = {tau!r} must be numbers") from None
        if not (math.isfinite(margin) and margin >= 0):
            raise ControllerError(f"joint_limit_margin = {margin!r} must be finite and >= 0 [rad]")
        if not (math.isfinite(tau) and tau >= 0.5 * T):
            raise ControllerError(f"joint_limit_time = {tau!r} must be finite and >= T / 2 = {0.5 * T:g} s")
        self.enabled, self.margin, self.tau, self.T = enabled, margin, tau, float(T)
        self.beta = self.T / tau
        self.lo, self.hi = nominal_joint_range(model, qadr, margin)
        #: Whether any joint has a finite bound (else nothing to clamp).
        self.active = bool(enabled and (np.isfinite(self.lo).any() or np.isfinite(self.hi).any()))

    def clamp_acceleration(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
        """:func:`clamp_joint_acceleration` with these bounds (``qdd`` itself when inactive)."""
        if not self.active:
            return qdd
        return clamp_joint_acceleration(q, qd, qdd, self.lo, self.hi, self.T, self.beta)

    def clamp_position(self, q: np.ndarray) -> np.ndarray:
        """Joint positions (references) clamped into the bounds (a new array; ``q`` when inactive)."""
        if not self.active:
            return q
        return np.minimum(np.maximum(q, self.lo), self.hi)

    def clamp_rate(self, q_ref: np.ndarray, rate: np.ndarray) -> np.ndarray:
        """Reference rates such that q_ref + T rate stays inside the bounds (a new array)."""
        if not self.active:
            return rate
        return np.minimum(np.maximum(rate, (self.lo - q_ref) / self.T), (self.hi - q_ref) / self.T)

    def describe(self) -> dict:
        """The settings as numbers (a run's ``controller_params``)."""
        return {"joint_limits": self.enabled, "joint_limit_margin": self.margin, "joint_limit_time": self.tau}
