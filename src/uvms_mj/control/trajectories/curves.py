"""Periodic planar curves with a ramped angular rate: :class:`Circle`, :class:`Lemniscate`, :class:`Helix`."""

from __future__ import annotations

import math
from abc import abstractmethod
from dataclasses import dataclass
from typing import Any

import numpy as np

from uvms_mj.control.trajectories.base import (
    Trajectory,
    _finite,
    _nonneg,
    _number,
    _plane_basis,
    _positive,
    _ramped_time,
    _ramped_time_scalar,
    _set,
    _vec3,
)

__all__ = ["Circle", "Lemniscate", "Helix"]


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
        _set(self, "_Ul", tuple(tuple(r) for r in self._U.tolist()))  # the same numbers as floats (_eval_floats)
        _set(self, "_cl", tuple(self._c.tolist()))

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

    def _eval_floats(self, t: float, order: int) -> list | None:
        """:meth:`_eval` at one time as Python floats (the same formulas and operations: the
        controllers' per-sample call), or None where the curve has no scalar form."""
        if not self._axial_none:
            return None
        th, dth, ddth = self.theta(t)
        fs = self._f_scalar(th)
        if fs is None:
            return None
        (fx, fy), (gx, gy), (hx, hy) = fs
        if order == 0:
            px, py = fx, fy
        elif order == 1:
            px, py = gx * dth, gy * dth
        else:
            d2 = dth * dth
            px, py = hx * d2 + gx * ddth, hy * d2 + gy * ddth
        out = [a * px + b * py for a, b in self._Ul]  # [U_i0 px + U_i1 py], as U[:, 0] px + U[:, 1] py
        return [x + c for x, c in zip(out, self._cl)] if order == 0 else out

    def _eval(self, t: Any, order: int) -> np.ndarray:
        if isinstance(t, (float, int)) and not isinstance(t, bool):
            row = self._eval_floats(float(t), order)
            if row is not None:
                return np.array(row)
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
