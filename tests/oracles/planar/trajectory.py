"""Test oracle: the paper's planar straight line with a trapezoidal speed profile (scalar code, 2-D).

The tip starts at rest at ``start``, waits ``t_start`` seconds, accelerates at ``accel`` to
``cruise_speed``, cruises, and decelerates to rest exactly at ``target`` (a triangular profile
if the line is too short to reach cruise speed). World frame, SI units.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from uvms_mj.control.trajectories import trapezoid_profile


@dataclass(frozen=True)
class StraightLine:
    """Straight end-tip path from ``start`` to ``target`` (world frame, m).

    Attributes:
        start, target: end points [m].
        cruise_speed: speed along the line while cruising [m/s] (our default 0.02 m/s).
        accel: acceleration and deceleration [m/s^2] (our default 0.02 m/s^2: 1 s ramps).
        t_start: time at rest before moving [s].
    """

    start: tuple[float, float]
    target: tuple[float, float]
    cruise_speed: float = 0.02
    accel: float = 0.02
    t_start: float = 1.0

    def __post_init__(self) -> None:
        for name in ("start", "target"):
            v = getattr(self, name)
            if len(v) != 2 or not all(math.isfinite(float(x)) for x in v):
                raise ValueError(f"trajectory.{name} = {v!r} must be 2 finite numbers [m]")
        for name in ("cruise_speed", "accel"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"trajectory.{name} = {v!r} must be finite and > 0")
        if not (math.isfinite(self.t_start) and self.t_start >= 0):
            raise ValueError(f"trajectory.t_start = {self.t_start!r} must be finite and >= 0")

    @cached_property
    def length(self) -> float:
        return float(np.hypot(self.target[0] - self.start[0], self.target[1] - self.start[1]))

    @cached_property
    def direction(self) -> np.ndarray:
        d = np.subtract(self.target, self.start).astype(float)
        n = np.linalg.norm(d)
        return d / n if n > 0 else np.zeros(2)

    @cached_property
    def _start(self) -> np.ndarray:
        return np.asarray(self.start, dtype=float)

    def _profile(self) -> tuple[float, float, float]:
        return self._profile_cached

    @cached_property
    def _profile_cached(self) -> tuple[float, float, float]:
        """(peak speed, ramp time, cruise time)."""
        return trapezoid_profile(self.cruise_speed, self.accel, self.length)

    @property
    def duration(self) -> float:
        """Time at which the tip reaches the target [s]."""
        _, tr, tc = self._profile()
        return self.t_start + 2 * tr + tc

    def distance(self, t: float) -> float:
        """Arc length travelled at time t [m]."""
        v, tr, tc = self._profile()
        a = self.accel if tr > 0 else 0.0
        t = t - self.t_start
        if t <= 0 or self.length == 0:
            return 0.0
        if t < tr:
            return 0.5 * a * t * t
        if t < tr + tc:
            return 0.5 * v * tr + v * (t - tr)
        if t < 2 * tr + tc:
            td = 2 * tr + tc - t
            return self.length - 0.5 * a * td * td
        return self.length

    def position(self, t: float) -> np.ndarray:
        """Desired tip position p_ed(t) (world, m)."""
        d = self.distance(t)
        sd = self._start_dir
        if sd is None:
            return self._start + d * self.direction
        (sx, sy), (ux, uy) = sd
        return np.array([sx + d * ux, sy + d * uy])  # start + d direction, on floats (the same numbers)

    def positions(self, ts) -> np.ndarray:
        """:meth:`position` at each of the times ``ts`` (shape ``(len(ts), 2)``), the same numbers
        bit for bit (the same operations in the same order, element by element): a sampled
        controller reads its desired points from such blocks."""
        v, tr, tc = self._profile()
        a = self.accel if tr > 0 else 0.0
        t = np.asarray(ts, dtype=float).ravel() - self.t_start
        L = self.length
        d = np.full(t.shape, L)
        te = 2 * tr + tc
        td = te - t
        dec = t < te  # the phases of distance(), the later masks taking precedence
        d[dec] = L - 0.5 * a * td[dec] * td[dec]
        cru = t < tr + tc
        d[cru] = 0.5 * v * tr + v * (t[cru] - tr)
        acc = t < tr
        d[acc] = 0.5 * a * t[acc] * t[acc]
        d[t <= 0] = 0.0
        if L == 0:
            d[:] = 0.0
        sd = self._start_dir
        if sd is None:
            return self._start + d[:, None] * self.direction
        (sx, sy), (ux, uy) = sd
        return np.stack((sx + d * ux, sy + d * uy), axis=-1)

    @cached_property
    def _start_dir(self) -> tuple | None:
        s, u = self._start.tolist(), self.direction.tolist()
        return (tuple(s), tuple(u)) if len(s) == len(u) == 2 else None

    def cruise_velocity(self) -> np.ndarray:
        """The cruise velocity vector (world, m/s): what Eq. 12 gives the base to follow."""
        return self._profile()[0] * self.direction
