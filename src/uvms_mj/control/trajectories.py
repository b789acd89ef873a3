"""Desired end-effector trajectories in 3-D behind one interface.

Every trajectory is a :class:`Trajectory`: world frame, SI units, and

* ``position(t)``, ``velocity(t)``, ``acceleration(t)``: 3-vectors [m, m/s, m/s^2]. ``t`` may be
  a float (result shape ``(3,)``) or an array of any shape ``S`` (result shape ``S + (3,)``).
* ``duration``: the time [s] after which the trajectory is at rest (:class:`Line3D`,
  :class:`Waypoints`, :class:`CsvTrajectory`) or in its steady periodic motion (:class:`Circle`,
  :class:`Lemniscate`; :class:`Helix`: steady screw motion, periodic up to a translation).
* ``has_orientation`` and ``orientation(t)``: a unit quaternion ``(w, x, y, z)`` (shape ``(4,)``
  or ``S + (4,)``) for those that carry one (a :class:`CsvTrajectory` with quaternion columns);
  ``None`` otherwise.

Kinds:

* :class:`Line3D`: straight line with the trapezoidal speed profile of
  the paper's planar line (its 2-D scalar code: the test oracle ``tests/oracles/planar/trajectory.py``).
* :class:`Waypoints`: minimum-jerk (quintic) segments, at rest at every waypoint.
* :class:`Circle`, :class:`Lemniscate` (of Gerono), :class:`Helix`: periodic curves whose angular
  rate ramps up from 0 with a minimum-jerk profile over ``t_ramp`` (so they start at rest).
* :class:`CsvTrajectory`: samples from a CSV file, C2 cubic spline in position, slerp in attitude.

:func:`make_trajectory` builds any of them from a dict (a scenario section), e.g.
``{"kind": "circle", "centre": [0.5, 0, -1], "radius": 0.1, "period": 20}``.

The minimum-jerk profile used throughout (rest-to-rest in unit time, tau in [0, 1])::

    s(tau)   = 10 tau^3 - 15 tau^4 + 6 tau^5
    s'(tau)  = 30 tau^2 - 60 tau^3 + 30 tau^4         (peak s'(1/2) = 1.875)
    s''(tau) = 60 tau - 180 tau^2 + 120 tau^3
    s(0) = s'(0) = s''(0) = 0,  s(1) = 1,  s'(1) = s''(1) = 0.
"""

from __future__ import annotations

import bisect
import csv
import difflib
import math
from abc import ABC, abstractmethod
from dataclasses import MISSING, dataclass, fields
from functools import cached_property
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np


__all__ = [
    "Trajectory",
    "Line3D",
    "Waypoints",
    "Circle",
    "Lemniscate",
    "Helix",
    "CsvTrajectory",
    "Shifted",
    "KINDS",
    "make_trajectory",
    "min_jerk",
    "starting_at",
    "write_csv",
]



def trapezoid_profile(cruise_speed: float, accel: float, length: float) -> tuple[float, float, float]:
    """(peak speed v [m/s], ramp time t_r [s], cruise time t_c [s]) of a rest-to-rest move over
    ``length`` with constant acceleration ``accel`` up to ``cruise_speed`` (triangular, with
    v = sqrt(accel length), when the line is too short to reach it)."""
    v, a, L = cruise_speed, accel, length
    if v * v / a > L:  # triangular
        v = math.sqrt(a * L)
    t_ramp = v / a
    t_cruise = (L - v * t_ramp) / v if v > 0 else 0.0
    return v, t_ramp, t_cruise

# --------------------------------------------------------------------------- validation helpers


def _suggest(word: str, options: Sequence[str]) -> str:
    close = difflib.get_close_matches(str(word), list(options), n=1, cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, (bool, np.bool_))


def _number(name: str, v: Any, what: str, ok: Callable[[float], bool]) -> float:
    if not _is_number(v) or not math.isfinite(float(v)) or not ok(float(v)):
        raise ValueError(f"trajectory.{name} = {v!r} must be a finite number {what}")
    return float(v)


def _positive(name: str, v: Any, unit: str) -> float:
    return _number(name, v, f"> 0 [{unit}]", lambda x: x > 0)


def _nonneg(name: str, v: Any, unit: str) -> float:
    return _number(name, v, f">= 0 [{unit}]", lambda x: x >= 0)


def _finite(name: str, v: Any, unit: str) -> float:
    return _number(name, v, f"[{unit}]", lambda x: True)


def _vec3(name: str, v: Any, unit: str, nonzero: bool = False) -> tuple[float, float, float]:
    ok = (
        isinstance(v, (list, tuple, np.ndarray))
        and len(v) == 3
        and all(_is_number(x) and math.isfinite(float(x)) for x in v)
    )
    if not ok:
        raise ValueError(f"trajectory.{name} = {v!r} must be 3 finite numbers [{unit}]")
    out = (float(v[0]), float(v[1]), float(v[2]))
    if nonzero and not any(out):
        raise ValueError(f"trajectory.{name} = {v!r} must be a non-zero vector")
    return out


def _set(obj: Any, name: str, value: Any) -> None:
    object.__setattr__(obj, name, value)


# --------------------------------------------------------------------------- shared maths


def min_jerk(tau: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Minimum-jerk rest-to-rest profile on tau in [0, 1] (clipped outside): (s, s', s'').

    s = 10 tau^3 - 15 tau^4 + 6 tau^5 (derivatives with respect to tau, see the module docstring).
    """
    x = np.clip(np.asarray(tau, dtype=float), 0.0, 1.0)
    s = x**3 * (10.0 + x * (-15.0 + 6.0 * x))
    ds = 30.0 * x**2 * (1.0 + x * (-2.0 + x))
    dds = 60.0 * x * (1.0 + x * (-3.0 + 2.0 * x))
    return s, ds, dds


def _ramped_time(t: np.ndarray, t_start: float, t_ramp: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ramped clock g(t) with g' = min-jerk ramp of the rate from 0 to 1: (g, g', g'').

    With t' = t - t_start and tau = t'/t_ramp::

        t' <= 0:            g = 0,                                  g' = 0,      g'' = 0
        0 < t' < t_ramp:    g = t_ramp (5/2 tau^4 - 3 tau^5 + tau^6), g' = s(tau), g'' = s'(tau)/t_ramp
        t' >= t_ramp:       g = t' - t_ramp/2,                      g' = 1,      g'' = 0

    g is C3 (g''' = s''(tau)/t_ramp^2 vanishes at both ends), so a curve driven by the phase
    omega*g(t) starts at rest with zero acceleration and has continuous acceleration and jerk.
    With t_ramp = 0, g = max(t', 0): the rate steps to 1 at t_start.
    """
    tp = t - t_start
    if t_ramp <= 0:
        moving = tp > 0
        return np.where(moving, tp, 0.0), moving.astype(float), np.zeros_like(tp)
    tau = np.clip(tp / t_ramp, 0.0, 1.0)
    s, ds, _ = min_jerk(tau)
    g_ramp = t_ramp * tau**4 * (2.5 + tau * (-3.0 + tau))
    after = tp >= t_ramp
    g = np.where(after, tp - 0.5 * t_ramp, g_ramp)
    dg = np.where(after, 1.0, s)
    ddg = np.where(after, 0.0, ds / t_ramp)
    return g, dg, ddg


def _ramped_time_scalar(t: float, t_start: float, t_ramp: float) -> tuple[float, float, float]:
    """:func:`_ramped_time` for one time (same formulas, plain floats)."""
    tp = t - t_start
    if t_ramp <= 0:
        return (tp, 1.0, 0.0) if tp > 0 else (0.0, 0.0, 0.0)
    if tp >= t_ramp:
        return tp - 0.5 * t_ramp, 1.0, 0.0
    x = min(max(tp / t_ramp, 0.0), 1.0)
    s = x ** 3 * (10.0 + x * (-15.0 + 6.0 * x))
    ds = 30.0 * x ** 2 * (1.0 + x * (-2.0 + x))
    return t_ramp * x ** 4 * (2.5 + x * (-3.0 + x)), s, ds / t_ramp


def _plane_basis(normal: tuple[float, float, float], phase_axis: tuple[float, float, float] | None, field: str):
    """Orthonormal (u, v, n) with u x v = n; u: phase_axis (default world X, else world Y) projected."""
    n = np.asarray(normal, dtype=float)
    n = n / np.linalg.norm(n)
    candidates = [np.asarray(phase_axis, dtype=float)] if phase_axis is not None else [np.eye(3)[0], np.eye(3)[1]]
    for c in candidates:
        p = c - np.dot(c, n) * n
        norm = np.linalg.norm(p)
        if norm > 1e-9 * max(1.0, np.linalg.norm(c)):
            u = p / norm
            return u, np.cross(n, u), n
    raise ValueError(
        f"trajectory.{field} = {tuple(phase_axis)!r} is parallel to the normal {tuple(normal)!r}; "
        "it must have a component in the plane"
    )


# --------------------------------------------------------------------------- interface


class Trajectory(ABC):
    """A desired end-effector trajectory (world frame, SI units); see the module docstring."""

    @abstractmethod
    def position(self, t: Any) -> np.ndarray:
        """p_d(t) [m]: shape (3,) for a float t, t.shape + (3,) for an array."""

    @abstractmethod
    def velocity(self, t: Any) -> np.ndarray:
        """dp_d/dt [m/s]."""

    @abstractmethod
    def acceleration(self, t: Any) -> np.ndarray:
        """d^2 p_d/dt^2 [m/s^2]."""

    @property
    @abstractmethod
    def duration(self) -> float:
        """Time [s] after which the trajectory is at rest or in its steady periodic motion."""

    @property
    def has_orientation(self) -> bool:
        """Whether :meth:`orientation` returns a quaternion."""
        return False

    def orientation(self, t: Any) -> np.ndarray | None:
        """Desired attitude as a unit quaternion (w, x, y, z), or None if this trajectory has none."""
        return None


# --------------------------------------------------------------------------- Line3D


@dataclass(frozen=True)
class Line3D(Trajectory):
    """Straight line from ``start`` to ``target`` with a trapezoidal speed profile (3-D).

    The paper's end-tip line (Section 4) in 3-D: at rest until ``t_start``,
    constant acceleration ``accel`` up to the peak speed v, cruise, constant deceleration to rest
    exactly at ``target``. With L = |target - start|::

        v = cruise_speed, or sqrt(accel L) if cruise_speed^2/accel > L (triangular profile)
        t_r = v / accel (ramp time),  t_c = (L - v t_r) / v (cruise time)
        duration = t_start + 2 t_r + t_c

    and, with t' = t - t_start, the arc length d(t) and p(t) = start + d(t) (target - start)/L::

        t' <= 0:                 d = 0,                  d' = 0,      d'' = 0
        0 < t' < t_r:            d = a t'^2 / 2,         d' = a t',   d'' = a
        t_r <= t' < t_r + t_c:   d = v t_r/2 + v(t'-t_r), d' = v,     d'' = 0
        t_r + t_c <= t' < T':    d = L - a td^2 / 2,     d' = a td,   d'' = -a   (td = T' - t', T' = 2t_r + t_c)
        t' >= T':                d = L,                  d' = 0,      d'' = 0

    The acceleration is discontinuous at the four corners (a trapezoid), the velocity continuous.

    Attributes:
        start, target: end points [m].
        cruise_speed: speed while cruising [m/s] (default 0.02).
        accel: acceleration and deceleration [m/s^2] (default 0.02: 1 s ramps).
        t_start: time at rest before moving [s] (default 1).
    """

    start: tuple[float, float, float]
    target: tuple[float, float, float]
    cruise_speed: float = 0.02
    accel: float = 0.02
    t_start: float = 1.0

    def __post_init__(self) -> None:
        _set(self, "start", _vec3("start", self.start, "m"))
        _set(self, "target", _vec3("target", self.target, "m"))
        _set(self, "cruise_speed", _positive("cruise_speed", self.cruise_speed, "m/s"))
        _set(self, "accel", _positive("accel", self.accel, "m/s^2"))
        _set(self, "t_start", _nonneg("t_start", self.t_start, "s"))

    @cached_property
    def length(self) -> float:
        """L = |target - start| [m]."""
        return float(np.linalg.norm(np.subtract(self.target, self.start)))

    @cached_property
    def direction(self) -> np.ndarray:
        """Unit vector from start to target (zeros if they coincide)."""
        d = np.subtract(self.target, self.start).astype(float)
        n = np.linalg.norm(d)
        return d / n if n > 0 else np.zeros(3)

    @cached_property
    def profile(self) -> tuple[float, float, float]:
        """(peak speed v [m/s], ramp time t_r [s], cruise time t_c [s]): the planar line's profile."""
        return trapezoid_profile(self.cruise_speed, self.accel, self.length)

    @property
    def duration(self) -> float:
        """Time at which the tip reaches the target [s]."""
        _, tr, tc = self.profile
        return self.t_start + 2 * tr + tc

    def distance(self, t: Any) -> np.ndarray:
        """(d, d', d''): arc length travelled [m], speed [m/s], and its rate [m/s^2] at t."""
        v, tr, tc = self.profile
        a = self.accel if tr > 0 else 0.0
        L = self.length
        tp = np.asarray(t, dtype=float) - self.t_start
        td = 2 * tr + tc - tp
        c0 = (tp <= 0) | (L == 0)
        c1 = tp < tr
        c2 = tp < tr + tc
        c3 = tp < 2 * tr + tc
        d = np.select([c0, c1, c2, c3], [0.0, 0.5 * a * tp * tp, 0.5 * v * tr + v * (tp - tr), L - 0.5 * a * td * td], L)
        dd = np.select([c0, c1, c2, c3], [0.0, a * tp, v, a * td], 0.0)
        ddd = np.select([c0, c1, c2, c3], [0.0, a, 0.0, -a], 0.0)
        return d, dd, ddd

    @cached_property
    def _start(self) -> np.ndarray:
        return np.asarray(self.start, dtype=float)

    def position(self, t: Any) -> np.ndarray:
        d = self.distance(t)[0]
        return self._start + d[..., None] * self.direction

    def cruise_velocity(self) -> np.ndarray:
        """The cruise velocity vector (world, m/s): the profile's peak speed along the line (what
        Eq. 12 gives the base to follow)."""
        return self.profile[0] * self.direction

    def positions(self, ts: Any) -> np.ndarray:
        """:meth:`position` at each of the times ``ts`` (shape ``(len(ts), 3)``): the same
        element-wise operations, so the same numbers (a sampled controller reads its desired
        points from such blocks)."""
        return self.position(np.asarray(ts, dtype=float).ravel())

    def velocity(self, t: Any) -> np.ndarray:
        return self.distance(t)[1][..., None] * self.direction

    def acceleration(self, t: Any) -> np.ndarray:
        return self.distance(t)[2][..., None] * self.direction


# --------------------------------------------------------------------------- Waypoints


@dataclass(frozen=True)
class Waypoints(Trajectory):
    """Minimum-jerk segments through waypoints P_0 .. P_N, at rest at each one.

    Segment i (P_i to P_{i+1}, duration T_i, start time t_i = t_start + T_0 + ... + T_{i-1}),
    with tau = (t - t_i)/T_i and the minimum-jerk s(tau) of :func:`min_jerk`::

        p = P_i + (P_{i+1} - P_i) s(tau)
        v = (P_{i+1} - P_i) s'(tau) / T_i
        a = (P_{i+1} - P_i) s''(tau) / T_i^2

    so velocity and acceleration are exactly zero at every waypoint and the peak speed of a
    segment is 1.875 L_i/T_i at its middle (L_i = |P_{i+1} - P_i|). Before ``t_start`` the
    trajectory rests at P_0, after the last segment at P_N.

    Attributes:
        points: the waypoints, N+1 >= 2 rows of 3 numbers [m].
        durations: the N segment durations [s] (> 0), or
        cruise_speed: the peak speed of every segment [m/s] (exactly one of the two):
            T_i = 1.875 L_i / cruise_speed, so the speed never exceeds cruise_speed.
        t_start: time at rest at P_0 before moving [s] (default 0).
    """

    points: tuple[tuple[float, float, float], ...]
    durations: tuple[float, ...] | None = None
    cruise_speed: float | None = None
    t_start: float = 0.0

    def __post_init__(self) -> None:
        pts = self.points
        if not isinstance(pts, (list, tuple, np.ndarray)) or len(pts) < 2:
            raise ValueError(f"trajectory.points = {pts!r} must be a list of at least 2 points [x, y, z] [m]")
        pts = tuple(_vec3(f"points[{i}]", p, "m") for i, p in enumerate(pts))
        _set(self, "points", pts)
        _set(self, "t_start", _nonneg("t_start", self.t_start, "s"))
        if (self.durations is None) == (self.cruise_speed is None):
            raise ValueError(
                "trajectory: give exactly one of durations (segment durations [s]) and cruise_speed "
                f"(peak segment speed [m/s]); got durations = {self.durations!r}, cruise_speed = {self.cruise_speed!r}"
            )
        n = len(pts) - 1
        if self.durations is not None:
            d = self.durations
            if not isinstance(d, (list, tuple, np.ndarray)) or len(d) != n:
                raise ValueError(
                    f"trajectory.durations = {d!r} must be {n} segment durations [s] (one per pair of points)"
                )
            durs = tuple(_positive(f"durations[{i}]", x, "s") for i, x in enumerate(d))
            _set(self, "durations", durs)
        else:
            v = _positive("cruise_speed", self.cruise_speed, "m/s")
            _set(self, "cruise_speed", v)
            durs = []
            for i in range(n):
                L = float(np.linalg.norm(np.subtract(pts[i + 1], pts[i])))
                if L == 0:
                    raise ValueError(
                        f"trajectory.points[{i + 1}] = {list(pts[i + 1])!r} equals points[{i}]: a zero-length "
                        "segment has no duration from cruise_speed; give durations instead"
                    )
                durs.append(1.875 * L / v)
            durs = tuple(durs)
        _set(self, "_durs", np.asarray(durs, dtype=float))
        _set(self, "_P", np.asarray(pts, dtype=float))
        _set(self, "knots", self.t_start + np.concatenate([[0.0], np.cumsum(durs)]))

    @property
    def segment_durations(self) -> np.ndarray:
        """T_i [s] (given, or from cruise_speed)."""
        return self._durs.copy()

    @property
    def duration(self) -> float:
        return float(self.knots[-1])

    def _eval_scalar(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`_eval` for one time (the controllers' per-sample call; same formulas)."""
        knots, P = self.knots, self._P
        z = np.zeros(3)
        if t < knots[0]:
            return P[0].copy(), z, z.copy()
        if t >= knots[-1]:
            return P[-1].copy(), z, z.copy()
        i = min(bisect.bisect_right(knots, t) - 1, len(self._durs) - 1)
        T = float(self._durs[i])
        x = min(max((t - knots[i]) / T, 0.0), 1.0)
        s = x ** 3 * (10.0 + x * (-15.0 + 6.0 * x))
        ds = 30.0 * x ** 2 * (1.0 + x * (-2.0 + x))
        dds = 60.0 * x * (1.0 + x * (-3.0 + 2.0 * x))
        dP = P[i + 1] - P[i]
        return P[i] + dP * s, dP * (ds / T), dP * (dds / T ** 2)

    def _eval(self, t: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if isinstance(t, (float, int)) and not isinstance(t, bool):
            return self._eval_scalar(float(t))
        t = np.asarray(t, dtype=float)
        n = len(self._durs)
        i = np.clip(np.searchsorted(self.knots, t, side="right") - 1, 0, n - 1)
        T = self._durs[i]
        tau = np.clip((t - self.knots[i]) / T, 0.0, 1.0)
        s, ds, dds = min_jerk(tau)
        before = t < self.knots[0]
        after = t >= self.knots[-1]
        s = np.where(before, 0.0, s)
        i = np.where(after, n - 1, i)
        P0 = self._P[i]
        dP = self._P[i + 1] - P0
        p = np.where(after[..., None], self._P[-1], P0 + dP * s[..., None])
        moving = ~(before | after)
        v = dP * (np.where(moving, ds, 0.0) / T)[..., None]
        a = dP * (np.where(moving, dds, 0.0) / T**2)[..., None]
        return p, v, a

    def position(self, t: Any) -> np.ndarray:
        return self._eval(t)[0]

    def velocity(self, t: Any) -> np.ndarray:
        return self._eval(t)[1]

    def acceleration(self, t: Any) -> np.ndarray:
        return self._eval(t)[2]


# --------------------------------------------------------------------------- planar periodic curves


class _PhaseCurve(Trajectory):
    """A planar curve f(theta) (in the u, v basis) driven by theta(t) = phase + omega g(t).

    p = centre + [u v] f(theta) (+ axial term for the helix);
    v = [u v] f_theta theta',  a = [u v] (f_thetatheta theta'^2 + f_theta theta''),
    theta' = omega g'(t), theta'' = omega g''(t), g from :func:`_ramped_time`.
    """

    centre: tuple[float, float, float]
    normal: tuple[float, float, float]
    omega: float | None
    period: float | None
    phase: float
    t_ramp: float
    t_start: float
    phase_axis: tuple[float, float, float] | None

    def _validate_common(self) -> None:
        _set(self, "centre", _vec3("centre", self.centre, "m"))
        _set(self, "normal", _vec3("normal", self.normal, "-", nonzero=True))
        if self.phase_axis is not None:
            _set(self, "phase_axis", _vec3("phase_axis", self.phase_axis, "-", nonzero=True))
        if (self.omega is None) == (self.period is None):
            raise ValueError(
                "trajectory: give exactly one of omega (angular rate [rad/s], non-zero, signed) and period "
                f"([s], > 0); got omega = {self.omega!r}, period = {self.period!r}"
            )
        if self.omega is not None:
            w = _number("omega", self.omega, "!= 0 [rad/s]", lambda x: x != 0)
            _set(self, "omega", w)
            _set(self, "_w", w)
            _set(self, "_T", 2 * math.pi / abs(w))
        else:
            T = _positive("period", self.period, "s")
            _set(self, "period", T)
            _set(self, "_w", 2 * math.pi / T)
            _set(self, "_T", T)
        _set(self, "phase", _finite("phase", self.phase, "rad"))
        _set(self, "t_ramp", _nonneg("t_ramp", self.t_ramp, "s"))
        _set(self, "t_start", _nonneg("t_start", self.t_start, "s"))
        u, v, n = _plane_basis(self.normal, self.phase_axis, "phase_axis")
        _set(self, "_U", np.stack([u, v], axis=1))  # 3x2
        _set(self, "_n", n)
        _set(self, "_c", np.asarray(self.centre, dtype=float))

    @property
    def basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(u, v, n): in-plane phase-0 direction, in-plane 90-degree direction, unit normal (u x v = n)."""
        return self._U[:, 0].copy(), self._U[:, 1].copy(), self._n.copy()

    @property
    def angular_rate(self) -> float:
        """Steady signed angular rate omega [rad/s] (given, or 2 pi / period)."""
        return self._w

    @property
    def cycle_period(self) -> float:
        """Steady period 2 pi / |omega| [s] (given, or from omega)."""
        return self._T

    @property
    def duration(self) -> float:
        """t_start + t_ramp: after it the motion is steady (periodic with ``cycle_period``)."""
        return self.t_start + self.t_ramp

    def theta(self, t: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(theta, theta', theta''): phase [rad] and its rates; theta = phase + omega g(t)."""
        if isinstance(t, (float, int)) and not isinstance(t, bool):
            g, dg, ddg = _ramped_time_scalar(float(t), self.t_start, self.t_ramp)
        else:
            g, dg, ddg = _ramped_time(np.asarray(t, dtype=float), self.t_start, self.t_ramp)
        w = self._w
        return self.phase + w * g, w * dg, w * ddg

    @abstractmethod
    def _f(self, th: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(f, f_theta, f_thetatheta), each th.shape + (2,)."""

    def _axial(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        return None

    @property
    def _axial_none(self) -> bool:
        return type(self)._axial is _PhaseCurve._axial

    def _f_scalar(self, th: float) -> tuple[tuple[float, float], ...] | None:
        """(f, f_theta, f_thetatheta) as (x, y) pairs for one angle (None: use :meth:`_f`)."""
        return None

    def _eval(self, t: Any, order: int) -> np.ndarray:
        if isinstance(t, (float, int)) and not isinstance(t, bool) and self._axial_none:
            th, dth, ddth = self.theta(float(t))
            fs = self._f_scalar(th)
            if fs is not None:  # the same formulas on floats (the controllers' per-sample call)
                (fx, fy), (gx, gy), (hx, hy) = fs
                if order == 0:
                    px, py = fx, fy
                elif order == 1:
                    px, py = gx * dth, gy * dth
                else:
                    d2 = dth * dth
                    px, py = hx * d2 + gx * ddth, hy * d2 + gy * ddth
                out = self._U[:, 0] * px + self._U[:, 1] * py
                return out + self._c if order == 0 else out
        t = np.asarray(t, dtype=float)
        th, dth, ddth = self.theta(t)
        f, f1, f2 = self._f(th)
        if order == 0:
            planar = f
        elif order == 1:
            planar = f1 * dth[..., None]
        else:
            planar = f2 * (dth**2)[..., None] + f1 * ddth[..., None]
        out = planar @ self._U.T
        if order == 0:
            out = out + self._c
        ax = self._axial(t)
        if ax is not None:
            out = out + ax[order][..., None] * self._n
        return out

    def position(self, t: Any) -> np.ndarray:
        return self._eval(t, 0)

    def velocity(self, t: Any) -> np.ndarray:
        return self._eval(t, 1)

    def acceleration(self, t: Any) -> np.ndarray:
        return self._eval(t, 2)


@dataclass(frozen=True)
class Circle(_PhaseCurve):
    """Circle of ``radius`` about ``centre`` in the plane normal to ``normal``.

    With the in-plane basis (u, v), u x v = n (u: ``phase_axis`` projected onto the plane, default
    world X, or world Y if X is along the normal)::

        p(t) = centre + r (cos theta u + sin theta v)
        v(t) = r theta' (-sin theta u + cos theta v)
        a(t) = r theta'' (-sin theta u + cos theta v) - r theta'^2 (cos theta u + sin theta v)
        theta(t) = phase + omega g(t)

    g is the ramped clock of :func:`_ramped_time`: the angular rate theta' = omega g' rises from 0
    at ``t_start`` to omega at ``t_start + t_ramp`` with a minimum-jerk profile, so the tip starts
    at rest (v = a = 0) and, once steady, |v| = |omega| r and |a| = omega^2 r (centripetal).
    Positive omega turns counter-clockwise about n.

    Attributes:
        centre [m], radius [m] (> 0), normal (non-zero; normalised).
        omega: signed angular rate [rad/s], or period: [s] (> 0, counter-clockwise); exactly one.
        phase: theta at rest (before and at t_start) [rad] (default 0).
        t_ramp: ramp time of the angular rate [s] (default 0: the rate steps at t_start).
        t_start: time at rest before moving [s] (default 0).
        phase_axis: in-plane direction of phase 0 (projected onto the plane; default None).
    """

    centre: tuple[float, float, float]
    radius: float
    normal: tuple[float, float, float] = (0.0, 0.0, 1.0)
    omega: float | None = None
    period: float | None = None
    phase: float = 0.0
    t_ramp: float = 0.0
    t_start: float = 0.0
    phase_axis: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        self._validate_common()
        _set(self, "radius", _positive("radius", self.radius, "m"))

    def _f(self, th):
        r = self.radius
        c, s = np.cos(th), np.sin(th)
        return (r * np.stack([c, s], -1), r * np.stack([-s, c], -1), -r * np.stack([c, s], -1))

    def _f_scalar(self, th: float):
        r = self.radius
        c, s = math.cos(th), math.sin(th)
        return (r * c, r * s), (-r * s, r * c), (-r * c, -r * s)


@dataclass(frozen=True)
class Lemniscate(_PhaseCurve):
    """Figure-eight: the lemniscate of Gerono, in the plane normal to ``normal``.

    With a = ``size`` (half the width along u; the height along v is a, i.e. y in [-a/2, a/2])::

        x(theta) = a sin theta,        y(theta) = a sin theta cos theta = (a/2) sin 2 theta
        x' = a cos theta,              y' = a cos 2 theta                  (d/dtheta)
        x'' = -a sin theta,            y'' = -2 a sin 2 theta
        p = centre + x u + y v,  v = (x' u + y' v) theta',  a = (x'' u + y'' v) theta'^2 + (x' u + y' v) theta''

    It satisfies x^4 = a^2 (x^2 - y^2); theta = 0 and pi are the crossing at the centre (tangent
    directions (1, 1) and (-1, 1)), theta = pi/2 and 3 pi/2 the tips (+-a, 0), theta = pi/4 the
    top of a lobe (a/sqrt 2, a/2). One period of theta (``period``) traces the whole eight.
    theta(t) = phase + omega g(t) with the same minimum-jerk ramp as :class:`Circle`.

    Attributes: as :class:`Circle`, with ``size`` [m] (> 0) in place of ``radius``.
    """

    centre: tuple[float, float, float]
    size: float
    normal: tuple[float, float, float] = (0.0, 0.0, 1.0)
    omega: float | None = None
    period: float | None = None
    phase: float = 0.0
    t_ramp: float = 0.0
    t_start: float = 0.0
    phase_axis: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        self._validate_common()
        _set(self, "size", _positive("size", self.size, "m"))

    def _f(self, th):
        a = self.size
        s, c = np.sin(th), np.cos(th)
        s2, c2 = np.sin(2 * th), np.cos(2 * th)
        return (
            np.stack([a * s, 0.5 * a * s2], -1),
            np.stack([a * c, a * c2], -1),
            np.stack([-a * s, -2 * a * s2], -1),
        )

    def _f_scalar(self, th: float):
        a = self.size
        s, c = math.sin(th), math.cos(th)
        s2, c2 = math.sin(2 * th), math.cos(2 * th)
        return (a * s, 0.5 * a * s2), (a * c, a * c2), (-a * s, -2 * a * s2)


@dataclass(frozen=True)
class Helix(_PhaseCurve):
    """Helix: a :class:`Circle` plus motion along the normal at constant axial speed.

    ::

        p(t) = centre + r (cos theta u + sin theta v) + w g(t) n
        v(t) = (circle) + w g'(t) n,   a(t) = (circle) + w g''(t) n

    with the same ramped clock g as the phase (theta = phase + omega g), so the axial speed ramps
    up with the angular rate and the tip starts at rest. Once steady, the axial speed is w and the
    pitch (advance per turn) is w * period = 2 pi w / |omega|; |v| = sqrt((omega r)^2 + w^2).

    Attributes: as :class:`Circle`, plus axial_speed w [m/s] (signed, along n) or pitch [m per
    turn] (signed); exactly one of the two.
    """

    centre: tuple[float, float, float]
    radius: float
    normal: tuple[float, float, float] = (0.0, 0.0, 1.0)
    omega: float | None = None
    period: float | None = None
    axial_speed: float | None = None
    pitch: float | None = None
    phase: float = 0.0
    t_ramp: float = 0.0
    t_start: float = 0.0
    phase_axis: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        self._validate_common()
        _set(self, "radius", _positive("radius", self.radius, "m"))
        if (self.axial_speed is None) == (self.pitch is None):
            raise ValueError(
                "trajectory: give exactly one of axial_speed ([m/s], signed along the normal) and pitch "
                f"([m] per turn, signed); got axial_speed = {self.axial_speed!r}, pitch = {self.pitch!r}"
            )
        if self.axial_speed is not None:
            w = _finite("axial_speed", self.axial_speed, "m/s")
            _set(self, "axial_speed", w)
            _set(self, "_ax", w)
        else:
            h = _finite("pitch", self.pitch, "m per turn")
            _set(self, "pitch", h)
            _set(self, "_ax", h / self._T)

    @property
    def axial_rate(self) -> float:
        """Steady axial speed w along n [m/s] (given, or pitch / period)."""
        return self._ax

    @property
    def pitch_per_turn(self) -> float:
        """Advance along n per turn, w * 2 pi / |omega| [m] (given, or from axial_speed)."""
        return self._ax * self._T

    @property
    def duration(self) -> float:
        """t_start + t_ramp: after it the motion is a steady screw (periodic up to a translation)."""
        return self.t_start + self.t_ramp

    def _f(self, th):
        return Circle._f(self, th)  # type: ignore[arg-type]

    def _axial(self, t):
        g, dg, ddg = _ramped_time(t, self.t_start, self.t_ramp)
        w = self._ax
        return w * g, w * dg, w * ddg


# --------------------------------------------------------------------------- CSV


_CSV_POS = ("t", "x", "y", "z")
_CSV_QUAT = ("qw", "qx", "qy", "qz")
_BC_TYPES = ("not-a-knot", "natural", "clamped")


def _read_csv(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    if not path.is_file():
        raise ValueError(f"trajectory.path = {str(path)!r}: no such file")
    rows: list[tuple[int, list[str]]] = []
    with path.open(newline="") as fh:
        reader = csv.reader(fh)
        for row in reader:
            if not row or all(not c.strip() for c in row) or row[0].lstrip().startswith("#"):
                continue
            rows.append((reader.line_num, row))
    if not rows:
        raise ValueError(f"{path}: empty file; expected a header row {','.join(_CSV_POS)}[,{','.join(_CSV_QUAT)}]")
    hline, header = rows[0]
    names = tuple(c.strip().lower() for c in header)
    if names not in (_CSV_POS, _CSV_POS + _CSV_QUAT):
        raise ValueError(
            f"{path}, line {hline}: header {','.join(c.strip() for c in header)!r} must be "
            f"{','.join(_CSV_POS)!r} or {','.join(_CSV_POS + _CSV_QUAT)!r}"
        )
    ncol = len(names)
    data = []
    prev_t, prev_line = None, None
    for line, row in rows[1:]:
        if len(row) != ncol:
            raise ValueError(f"{path}, line {line}: {len(row)} columns, expected {ncol} ({','.join(names)})")
        vals = []
        for j, (cell, name) in enumerate(zip(row, names)):
            try:
                x = float(cell)
            except ValueError:
                x = math.nan
            if not math.isfinite(x):
                raise ValueError(f"{path}, line {line}, column {j + 1} ({name}): {cell.strip()!r} is not a finite number")
            vals.append(x)
        if prev_t is not None and not vals[0] > prev_t:
            raise ValueError(
                f"{path}, line {line}, column 1 (t): {vals[0]!r} is not greater than the previous "
                f"t = {prev_t!r} (line {prev_line}); t must be strictly increasing"
            )
        if ncol == 8 and not any(vals[4:]):
            raise ValueError(f"{path}, line {line}, columns 5-8 (qw,qx,qy,qz): the zero quaternion has no attitude")
        prev_t, prev_line = vals[0], line
        data.append(vals)
    if len(data) < 2:
        raise ValueError(f"{path}: {len(data)} data row(s); a spline needs at least 2")
    arr = np.asarray(data, dtype=float)
    return arr[:, 0], arr[:, 1:4], (arr[:, 4:8] if ncol == 8 else None)


class CsvTrajectory(Trajectory):
    """Samples (t_k, p_k[, q_k]) from a CSV file, interpolated.

    File: a header row ``t,x,y,z`` or ``t,x,y,z,qw,qx,qy,qz`` (case and spaces ignored), then one
    row per sample, t strictly increasing [s], positions [m], quaternions (w, x, y, z) of any
    non-zero norm. Blank lines and lines starting with ``#`` are skipped. Bad rows raise
    ValueError naming the file, line and column.

    Position: a C2 cubic spline through the samples (``scipy.interpolate.CubicSpline``, end
    condition ``bc_type``, default not-a-knot); velocity and acceleration are its first and second
    derivatives. Outside [t_0, t_N] the trajectory holds the end sample, at rest (so velocity and
    acceleration jump there unless the data start and end at rest).

    Orientation: the quaternions are normalised and made sign-continuous (q_k -> -q_k when
    q_k . q_{k-1} < 0), then interpolated by slerp with the linear fraction u = (t - t_k)/(t_{k+1} - t_k)::

        q(t) = [sin((1-u) W) q_k + sin(u W) q_{k+1}] / sin W,   cos W = q_k . q_{k+1}

    (normalised linear interpolation when W < 1e-9), held at the ends.

    ``duration`` is t_N. Needs scipy (``pip install uvms-mj[export]`` or scipy itself).
    """

    def __init__(self, path: str | Path, *, bc_type: str = "not-a-knot") -> None:
        p = Path(path)
        t, pos, quat = _read_csv(p)
        self._init(t, pos, quat, bc_type, str(p))

    @classmethod
    def from_samples(
        cls,
        t: Any,
        positions: Any,
        quaternions: Any = None,
        *,
        bc_type: str = "not-a-knot",
    ) -> CsvTrajectory:
        """The same interpolation from arrays: t (N,), positions (N, 3), quaternions (N, 4) or None."""
        t = np.asarray(t, dtype=float)
        pos = np.asarray(positions, dtype=float)
        if t.ndim != 1 or len(t) < 2 or not np.all(np.isfinite(t)) or not np.all(np.diff(t) > 0):
            raise ValueError("samples: t must be at least 2 finite, strictly increasing times [s]")
        if pos.shape != (len(t), 3) or not np.all(np.isfinite(pos)):
            raise ValueError(f"samples: positions must be finite with shape ({len(t)}, 3), got {pos.shape}")
        q = None
        if quaternions is not None:
            q = np.asarray(quaternions, dtype=float)
            if q.shape != (len(t), 4) or not np.all(np.isfinite(q)) or np.any(np.linalg.norm(q, axis=1) == 0):
                raise ValueError(f"samples: quaternions must be finite, non-zero, shape ({len(t)}, 4)")
        obj = cls.__new__(cls)
        obj._init(t, pos, q, bc_type, "<samples>")
        return obj

    def _init(self, t: np.ndarray, pos: np.ndarray, quat: np.ndarray | None, bc_type: str, source: str) -> None:
        if bc_type not in _BC_TYPES:
            raise ValueError(f"trajectory.bc_type = {bc_type!r} must be one of {list(_BC_TYPES)}{_suggest(bc_type, _BC_TYPES)}")
        try:
            from scipy.interpolate import CubicSpline
        except ImportError as e:  # pragma: no cover - scipy is in the test and export extras
            raise ImportError("CsvTrajectory needs scipy: pip install scipy (or uvms-mj[export])") from e
        self.source = source
        self.bc_type = bc_type
        self.times = t.copy()
        self.samples = pos.copy()
        self._spline = CubicSpline(t, pos, axis=0, bc_type=bc_type)
        self._d1 = self._spline.derivative(1)
        self._d2 = self._spline.derivative(2)
        if quat is not None:
            q = quat / np.linalg.norm(quat, axis=1, keepdims=True)
            for k in range(1, len(q)):
                if np.dot(q[k], q[k - 1]) < 0:
                    q[k] = -q[k]
            self.quaternions: np.ndarray | None = q
        else:
            self.quaternions = None

    def __repr__(self) -> str:
        return f"CsvTrajectory({self.source!r}, {len(self.times)} samples, t in [{self.times[0]}, {self.times[-1]}])"

    @property
    def duration(self) -> float:
        return float(self.times[-1])

    @property
    def has_orientation(self) -> bool:
        return self.quaternions is not None

    def _clamped(self, t: Any) -> tuple[np.ndarray, np.ndarray]:
        t = np.asarray(t, dtype=float)
        inside = (t >= self.times[0]) & (t <= self.times[-1])
        return np.clip(t, self.times[0], self.times[-1]), inside

    def position(self, t: Any) -> np.ndarray:
        tc, _ = self._clamped(t)
        return self._spline(tc)

    def velocity(self, t: Any) -> np.ndarray:
        tc, inside = self._clamped(t)
        return self._d1(tc) * inside[..., None]

    def acceleration(self, t: Any) -> np.ndarray:
        tc, inside = self._clamped(t)
        return self._d2(tc) * inside[..., None]

    def orientation(self, t: Any) -> np.ndarray | None:
        if self.quaternions is None:
            return None
        tc, _ = self._clamped(t)
        ts, Q = self.times, self.quaternions
        k = np.clip(np.searchsorted(ts, tc, side="right") - 1, 0, len(ts) - 2)
        u = ((tc - ts[k]) / (ts[k + 1] - ts[k]))[..., None]
        q0, q1 = Q[k], Q[k + 1]
        cosw = np.clip(np.sum(q0 * q1, axis=-1, keepdims=True), -1.0, 1.0)
        w = np.arccos(cosw)
        sinw = np.sin(w)
        small = w < 1e-9
        safe = np.where(small, 1.0, sinw)
        a = np.where(small, 1.0 - u, np.sin((1.0 - u) * w) / safe)
        b = np.where(small, u, np.sin(u * w) / safe)
        q = a * q0 + b * q1
        return q / np.linalg.norm(q, axis=-1, keepdims=True)


def write_csv(path: str | Path, times: Any, positions: Any, quaternions: Any = None) -> None:
    """Write samples in the :class:`CsvTrajectory` format (full float precision, ``%.17g``)."""
    t = np.asarray(times, dtype=float)
    cols = [t[:, None], np.asarray(positions, dtype=float)]
    header = list(_CSV_POS)
    if quaternions is not None:
        cols.append(np.asarray(quaternions, dtype=float))
        header += list(_CSV_QUAT)
    np.savetxt(path, np.hstack(cols), delimiter=",", header=",".join(header), comments="", fmt="%.17g")


# --------------------------------------------------------------------------- factory


#: kind name -> class, for :func:`make_trajectory`.
KINDS: dict[str, type[Trajectory]] = {
    "line": Line3D,
    "waypoints": Waypoints,
    "circle": Circle,
    "lemniscate": Lemniscate,
    "helix": Helix,
    "csv": CsvTrajectory,
}

#: Keys that are "exactly one of" groups rather than individually required.
_ONE_OF = {"durations", "cruise_speed", "omega", "period", "axial_speed", "pitch"}


def _keys(cls: type) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """(all keys, required keys) of a kind."""
    if cls is CsvTrajectory:
        return ("path", "bc_type"), ("path",)
    fs = [f for f in fields(cls) if f.init]
    keys = tuple(f.name for f in fs)
    req = tuple(
        f.name for f in fs if f.default is MISSING and f.default_factory is MISSING and f.name not in _ONE_OF
    )
    return keys, req


class Shifted(Trajectory):
    """A trajectory translated by a constant offset [m] (world frame): position + offset, the
    same velocity, acceleration and orientation."""

    def __init__(self, base: Trajectory, offset: Any) -> None:
        self.base, self.offset = base, np.asarray(offset, dtype=float)

    def __repr__(self) -> str:
        return f"{type(self.base).__name__} shifted by {np.round(self.offset, 6).tolist()} m"

    def position(self, t: Any) -> np.ndarray:
        return np.asarray(self.base.position(t)) + self.offset

    def velocity(self, t: Any) -> np.ndarray:
        return self.base.velocity(t)

    def acceleration(self, t: Any) -> np.ndarray:
        return self.base.acceleration(t)

    @property
    def duration(self) -> float:
        return self.base.duration

    @property
    def has_orientation(self) -> bool:
        return self.base.has_orientation

    def orientation(self, t: Any) -> np.ndarray | None:
        return self.base.orientation(t)


def starting_at(trajectory: Trajectory, point: Any) -> Shifted:
    """``trajectory`` translated so that it starts (t = 0) at ``point`` [m, world]."""
    return Shifted(trajectory, np.asarray(point, dtype=float) - np.asarray(trajectory.position(0.0), dtype=float))


def make_trajectory(spec: Mapping[str, Any], *, base_dir: str | Path | None = None) -> Trajectory:
    """Build a trajectory from a dict: ``{"kind": <one of KINDS>, <that class's fields>...}``.

    Example: ``{"kind": "circle", "centre": [0.5, 0, -1], "radius": 0.1, "period": 20, "t_ramp": 5}``.
    A ``csv`` kind's relative ``path`` is resolved against ``base_dir`` (e.g. the scenario file's
    folder) when given. Raises ValueError naming the field, the value and what is allowed (with a
    did-you-mean for unknown kinds and keys).
    """
    if not isinstance(spec, Mapping):
        raise ValueError(f"trajectory = {spec!r} must be a mapping with a 'kind' key, one of {list(KINDS)}")
    if "kind" not in spec:
        raise ValueError(f"trajectory.kind is required: one of {list(KINDS)}")
    kind = spec["kind"]
    if not isinstance(kind, str) or kind not in KINDS:
        raise ValueError(f"trajectory.kind = {kind!r} must be one of {list(KINDS)}{_suggest(str(kind), list(KINDS))}")
    cls = KINDS[kind]
    keys, required = _keys(cls)
    args = {k: v for k, v in spec.items() if k != "kind"}
    for k in args:
        if k not in keys:
            raise ValueError(
                f"trajectory.{k}: unknown key for kind {kind!r}{_suggest(str(k), keys)}; allowed: {list(keys)}"
            )
    for k in required:
        if k not in args:
            raise ValueError(f"trajectory.{k} is required for kind {kind!r} (keys: {list(keys)})")
    if cls is CsvTrajectory:
        path = args["path"]
        if not isinstance(path, (str, Path)) or not str(path):
            raise ValueError(f"trajectory.path = {path!r} must be a file path (string)")
        p = Path(path)
        if base_dir is not None and not p.is_absolute():
            p = Path(base_dir) / p
        return CsvTrajectory(p, **({"bc_type": args["bc_type"]} if "bc_type" in args else {}))
    return cls(**args)  # every class validates and converts its fields (lists -> tuples)
