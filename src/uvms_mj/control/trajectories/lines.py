"""Rest-to-rest kinds: :class:`Line3D` (trapezoidal speed) and :class:`Waypoints` (minimum jerk)."""

from __future__ import annotations

import math

import bisect
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np

from uvms_mj.control.trajectories.base import Trajectory, _nonneg, _positive, _set, _vec3, min_jerk

__all__ = ["Line3D", "Waypoints"]


# --------------------------------------------------------------------------- Line3D


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

    def positions(self, ts: Any) -> np.ndarray:
        """:meth:`position` at each of the times ``ts`` (shape ``(len(ts), 3)``): the same
        element-wise operations, so the same numbers (a sampled controller reads its desired
        points from such blocks)."""
        return self.position(np.asarray(ts, dtype=float).ravel())

    def cruise_velocity(self) -> np.ndarray:
        """The cruise velocity vector (world, m/s): the profile's peak speed along the line (what
        Eq. 12 gives the base to follow)."""
        return self.profile[0] * self.direction

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
