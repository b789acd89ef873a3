"""The paper's digital building blocks, shared by ``rac`` / ``rac_dob`` (:mod:`uvms_mj.control.rac`)
and ``pd``: the zero-order-hold low-pass of the observer (Eq. 14), the Eq. 12 handling of the
singular configuration, a damped inverse, the checks of the RAC settings and the paper's
Section 4 constants.

Equation numbers refer to the paper; the reading of each equation (typos, missing values,
assumptions) is the one in docs/paper-reading.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from uvms_mj.control.base import ControllerError, check_positive

#: Section 4 of the paper.
PAPER_T = 1.0 / 60.0
PAPER_GAINS = (0.3, 0.3, 0.2, 0.2, 0.2)  # Gamma; Lambda printed with 4 entries, read as the same 5
PAPER_TF = 10.0
PAPER_JS = 0.045
#: Eq. 12's carry velocity (:class:`SingularHandler`): the paper's reading, and ours for 3-D arms.
CARRY_MODES = ("cruise", "path")


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

    ``carry`` (:data:`CARRY_MODES`): "cruise" (default, the paper's reading: the velocity taken
    at k1 is held until k2) or "path" (ours, for 3-D arms): the callable ``v_cruise`` is
    evaluated at EVERY sample of phase 1, the target of the ramp being the path's velocity over
    [k, k+1), so the base moves with the tip's path and stops when it stops. Why: in 3-D a
    posture can be below js without being stretched (the Alpha arm's tip near its base-yaw axis:
    w = 0.125 w_max at the shipped posture), and k2 then never comes; with "cruise" the base
    kept carrying the arm at the cruise speed long after the tip stopped (measured: the base
    0.78 m past a 0.3 m line, the tip 220 mm from its target, the shoulder at its limit;
    scenarios/bluerov2_alpha_beyond_reach.yaml's header).
    """

    js_low: float
    js_high: float
    n: int
    v_cruise: Any
    size: int | None = None
    carry: str = "cruise"

    def __post_init__(self) -> None:
        if self.carry not in CARRY_MODES:
            raise ControllerError(f"carry = {self.carry!r}; allowed: {', '.join(CARRY_MODES)}")
        if self.carry == "path" and not callable(self.v_cruise):
            raise ControllerError("carry = 'path' needs v_cruise as a callable k -> the path's velocity")
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
        elif self.phase == 1 and self.carry == "path":  # the ramp's target follows the path
            self.v_to = np.array(self.v_cruise(k), dtype=float)
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


