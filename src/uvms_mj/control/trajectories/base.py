"""The trajectory interface and what every kind shares.

:class:`Trajectory` (the interface), :func:`min_jerk` (the profile of the package docstring),
the ramped clock of the periodic curves, the field checks every kind uses, and
:class:`Shifted` / :func:`starting_at` (a trajectory translated to start at a point).
"""

from __future__ import annotations

import difflib
import math
from abc import ABC, abstractmethod
from typing import Any, Callable, Sequence

import numpy as np

__all__ = ["Trajectory", "Shifted", "min_jerk", "starting_at"]


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


# --------------------------------------------------------------------------- translated


class Shifted(Trajectory):
    """A trajectory translated by a constant offset [m] (world frame): position + offset, the
    same velocity, acceleration and orientation."""

    def __init__(self, base: Trajectory, offset: Any) -> None:
        self.base, self.offset = base, np.asarray(offset, dtype=float)
        self._off = self.offset.tolist() if self.offset.ndim == 1 else None  # (position's float path)

    def __repr__(self) -> str:
        return f"{type(self.base).__name__} shifted by {np.round(self.offset, 6).tolist()} m"

    def position(self, t: Any) -> np.ndarray:
        floats = getattr(self.base, "_eval_floats", None)  # one time: the same sums on floats
        if floats is not None and type(t) is float and self._off is not None:
            row = floats(t, 0)
            if row is not None and len(row) == len(self._off):
                return np.array([x + o for x, o in zip(row, self._off)])
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
