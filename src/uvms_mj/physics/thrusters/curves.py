"""Thrust curves F(u) of ``uvms.thruster`` (docs/hydrodynamics.md, "Thrusters") and their inverse.

:class:`ThrustCurve`, :func:`invert_curve`, :class:`CurveInverse` (precomputed, every control
sample), and a compiled model's curves and commands: :func:`thruster_curves`,
:func:`thrust_commands`.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass
from typing import Sequence

import mujoco
import numpy as np

from uvms_mj.physics.thrusters.matrix import _finite_array, thruster_actuators

__all__ = ["ThrustCurve", "invert_curve", "CurveInverse", "thruster_curves", "thrust_commands"]


# ---------------------------------------------------------------------------- thrust curves


class _Poly:
    """c0 + c1 u + ... + cn u^n by Horner's rule, faster than numpy.polynomial's polyval on small
    arrays; an odd or even polynomial (every other coefficient zero, as the T200 curve and its
    derivative) is evaluated in u^2, half the operations. A vector of up to 32 commands (one per
    thruster, every control sample) runs the same Horner steps on Python floats (the same numbers,
    without numpy's cost per call on 8 values). Built once per coefficient tuple."""

    def __init__(self, coeffs) -> None:
        c = tuple(float(x) for x in coeffs) or (0.0,)
        self.kind, self.c = "plain", c
        if len(c) > 2 and not any(c[0::2]):
            self.kind, self.c = "odd", c[1::2]
        elif len(c) > 2 and not any(c[1::2]):
            self.kind, self.c = "even", c[0::2]
        self.rev = self.c[-2::-1]
        self.top = self.c[-1]

    def __call__(self, u) -> np.ndarray:
        u = np.asarray(u, dtype=float)
        x = u * u if self.kind != "plain" else u
        if 0 < u.ndim == 1 and u.size <= 32:  # a command vector (one per thruster): Horner on floats
            top, rev = self.top, self.rev
            out = []
            for xv in x.tolist():
                y = top
                for c in rev:
                    y = y * xv + c
                out.append(y)
            y = np.array(out)
        else:
            y = np.full(u.shape, self.top)
            for c in self.rev:
                y = y * x + c
        return u * y if self.kind == "odd" else y

    def at(self, u: float) -> float:
        """The polynomial at one float (the same steps as :meth:`__call__`)."""
        x = u * u if self.kind != "plain" else u
        y = self.top
        for c in self.rev:
            y = y * x + c
        return u * y if self.kind == "odd" else y


_POLYS: dict[tuple, _Poly] = {}


def _poly(coeffs) -> _Poly:
    """The cached :class:`_Poly` of the coefficients c0..cn."""
    key = tuple(coeffs)
    p = _POLYS.get(key)
    if p is None:
        p = _POLYS[key] = _Poly(key)
    return p


def _horner(coeffs, u: np.ndarray) -> np.ndarray:
    """Evaluate the polynomial with coefficients c0..cn at u (cached :class:`_Poly`)."""
    return _poly(coeffs)(u)


@dataclass(frozen=True)
class ThrustCurve:
    """A ``uvms.thruster`` thrust curve F(u) [N] of the command u (docs/hydrodynamics.md).

    ``poly c0 c1 ... cn``: F(u) = sum_j c_j u^j (u the normalised command, usually in
    [-1, 1]); ``table u0 F0 u1 F1 ...``: piecewise linear through the points (u strictly
    increasing), constant beyond the ends (the command is clamped to the table's range).

    Attributes:
        kind: ``"poly"`` or ``"table"``.
        coeffs: polynomial coefficients c0..cn (poly).
        u, F: the table's points (table).
    """

    kind: str
    coeffs: tuple[float, ...] = ()
    u: tuple[float, ...] = ()
    F: tuple[float, ...] = ()

    @classmethod
    def parse(cls, text: str) -> "ThrustCurve":
        """Parse the ``curve`` attribute text, e.g. ``"poly 0 8.9 0 176"`` or ``"table -1 -10 1 20"``."""
        if isinstance(text, ThrustCurve):
            return text
        if not isinstance(text, str) or not text.split():
            raise ValueError(f"curve = {text!r}: expected 'poly c0 c1 ...' or 'table u0 F0 u1 F1 ...'")
        kind, *rest = text.split()
        try:
            nums = [float(v) for v in rest]
        except ValueError:
            raise ValueError(f"curve = {text!r}: non-numeric values") from None
        if not all(np.isfinite(nums)):
            raise ValueError(f"curve = {text!r}: values must be finite")
        if kind == "poly":
            if not nums:
                raise ValueError(f"curve = {text!r}: poly needs at least one coefficient")
            return cls("poly", coeffs=tuple(nums))
        if kind == "table":
            if len(nums) < 4 or len(nums) % 2:
                raise ValueError(f"curve = {text!r}: table needs pairs u F, at least two")
            u, F = nums[0::2], nums[1::2]
            if np.any(np.diff(u) <= 0):
                raise ValueError(f"curve = {text!r}: table u values must be strictly increasing")
            return cls("table", u=tuple(u), F=tuple(F))
        raise ValueError(f"curve = {text!r}: kind {kind!r}; allowed: poly, table")

    def __call__(self, u) -> np.ndarray:
        u = np.asarray(u, dtype=float)
        if self.kind == "poly":
            return _horner(self.coeffs, u)
        return np.interp(u, self.u, self.F)

    def derivative(self, u) -> np.ndarray:
        """dF/du (poly; for a table the slope of the segment, right-continuous)."""
        u = np.asarray(u, dtype=float)
        if self.kind == "poly":
            return np.polynomial.polynomial.polyval(u, np.polynomial.polynomial.polyder(self.coeffs))
        slopes = np.diff(self.F) / np.diff(self.u)
        i = np.clip(np.searchsorted(self.u, u, side="right") - 1, 0, len(slopes) - 1)
        return slopes[i]

    def default_range(self) -> tuple[float, float]:
        """The command range: [-1, 1] for a poly (normalised command), the table's ends."""
        return (-1.0, 1.0) if self.kind == "poly" else (self.u[0], self.u[-1])

    def monotone_range(self, lo: float | None = None, hi: float | None = None) -> tuple[float, float, int]:
        """The branch of [lo, hi] on which F is strictly monotone and that holds u = 0 (or the
        point of [lo, hi] nearest 0): returns (a, b, sign), sign +1 increasing, -1 decreasing.

        Poly: the real zeros of F' inside (lo, hi) at which F' changes sign split the range
        (zeros where F' touches 0 without a sign change keep F strictly monotone); a table
        must be strictly monotone on all of its range (else ValueError naming it).
        """
        dlo, dhi = self.default_range()
        lo = dlo if lo is None else float(lo)
        hi = dhi if hi is None else float(hi)
        linear = self.kind == "poly" and len(np.trim_zeros(np.asarray(self.coeffs[1:]), "b")) == 1
        if np.isnan(lo) or np.isnan(hi) or not lo < hi or (not linear and not (np.isfinite(lo) and np.isfinite(hi))):
            raise ValueError(f"command range lo = {lo}, hi = {hi}: need lo < hi, finite unless the curve is linear")
        if linear:  # F = c0 + c1 u: monotone everywhere
            return lo, hi, int(np.sign(self.coeffs[1]))
        if self.kind == "table":
            dF = np.diff(self.F)
            if np.all(dF > 0):
                sign = 1
            elif np.all(dF < 0):
                sign = -1
            else:
                raise ValueError(f"curve = table {self.u} -> {self.F}: F not strictly monotone, cannot invert")
            return max(lo, self.u[0]), min(hi, self.u[-1]), sign
        der = np.polynomial.polynomial.polyder(self.coeffs)
        der = np.trim_zeros(np.asarray(der, float), "b") if len(der) else np.zeros(0)
        if der.size == 0 or not np.any(der):
            raise ValueError(f"curve = poly {self.coeffs}: constant, cannot invert")
        crit = []
        if der.size > 1:
            roots = np.polynomial.polynomial.polyroots(der)
            dder = np.polynomial.polynomial.polyder(der)
            for z in roots[np.abs(roots.imag) <= 1e-9 * (1 + np.abs(roots.real))].real:
                for _ in range(3):  # polish simple roots (Newton on F')
                    s = np.polynomial.polynomial.polyval(z, dder)
                    if s == 0:
                        break
                    z = z - np.polynomial.polynomial.polyval(z, der) / s
                if lo < z < hi:
                    crit.append(float(z))
        edges = np.unique(np.r_[lo, np.sort(crit), hi])
        mids = 0.5 * (edges[:-1] + edges[1:])
        signs = np.sign(np.polynomial.polynomial.polyval(mids, der)).astype(int)
        # merge neighbouring pieces of equal sign
        pieces = []
        for a, b, s in zip(edges[:-1], edges[1:], signs):
            if pieces and pieces[-1][2] == s:
                pieces[-1][1] = b
            else:
                pieces.append([a, b, s])
        u0 = min(max(0.0, lo), hi)
        for a, b, s in pieces:
            if a <= u0 <= b and s != 0:
                return float(a), float(b), int(s)
        raise ValueError(f"curve = poly {self.coeffs}: no monotone branch around u = {u0}")


def invert_curve(curve, F, lo: float | None = None, hi: float | None = None) -> np.ndarray:
    """The command u with curve(u) = F, vectorised over thrusters.

    Args:
        curve: a :class:`ThrustCurve` or its text (``"poly c0 ..."``, ``"table u0 F0 ..."``),
            or a sequence of those, one per element of F.
        F: desired thrust(s) [N], any shape.
        lo, hi: command range (default [-1, 1] for a poly, the table's ends for a table).

    Returns:
        u, the shape of F. The inverse is taken on the monotone branch
        [a, b] = ``curve.monotone_range(lo, hi)`` (the whole range when F is monotone on it; for
        the T200 polynomial on [-1, 1]: |u| <= 0.97166, where F peaks at +-30.62 N, above
        F(+-1) = +-30.40 N: beyond 0.97166 more command gives less thrust). Thrusts outside the reachable range [F(a), F(b)] clamp to the branch ends.
        A table inverts exactly (piecewise linear); a polynomial by vectorised Newton steps
        safeguarded by bisection inside the bracket [a, b] (converged to machine precision).

    Raises:
        ValueError: bad curve, NaN in F, a curve without a monotone branch.
    """
    if not isinstance(curve, (str, ThrustCurve)):
        curves = list(curve)
        F = _finite_array("F", F)
        if F.shape != (len(curves),):
            raise ValueError(f"F: shape {F.shape}; expected ({len(curves)},) for {len(curves)} curves")
        return np.array([invert_curve(c, f, lo, hi) for c, f in zip(curves, F)])
    c = ThrustCurve.parse(curve)
    F = _finite_array("F", F)
    a, b, sign = c.monotone_range(lo, hi)
    if c.kind == "poly" and len(np.trim_zeros(np.asarray(c.coeffs[1:]), "b")) == 1:
        return np.clip((F - c.coeffs[0]) / c.coeffs[1], a, b)  # linear: exact, any range
    Fa, Fb = float(c(a)), float(c(b))
    target = np.clip(F, min(Fa, Fb), max(Fa, Fb))
    if c.kind == "table":
        uu, FF = np.asarray(c.u), np.asarray(c.F)
        if sign < 0:
            uu, FF = uu[::-1], FF[::-1]
        return np.clip(np.interp(target, FF, uu), a, b)
    # poly: safeguarded Newton in [a, b]; g(u) = sign * (F(u) - target) is increasing
    t = target.ravel()
    left, right = np.full(t.shape, a), np.full(t.shape, b)
    x = np.full(t.shape, 0.5 * (a + b)) if not (a <= 0.0 <= b) else np.zeros(t.shape)
    Fscale = max(abs(Fa), abs(Fb), float(np.max(np.abs(c.coeffs))), 1e-300)
    ftol = 2 * np.finfo(float).eps * Fscale  # F is known to about this
    xtol = 4 * np.finfo(float).eps * max(1.0, abs(a), abs(b))
    g_prev = np.full(t.shape, np.inf)
    for _ in range(300):
        g = sign * (c(x) - t)
        conv = np.abs(g) <= ftol
        right = np.where((g > 0) & ~conv, x, right)
        left = np.where((g < 0) & ~conv, x, left)
        done = conv | (right - left <= xtol)
        if done.all():
            break
        dg = sign * c.derivative(x)
        with np.errstate(divide="ignore", invalid="ignore"):
            xn = x - g / dg
        # bisect when Newton leaves the bracket or does not halve |g| (rtsafe-style safeguard)
        bad = ~np.isfinite(xn) | (xn < left) | (xn > right) | (np.abs(g) > 0.5 * g_prev)
        xn = np.where(bad, 0.5 * (left + right), xn)
        g_prev = np.where(bad, np.inf, np.abs(g))
        x = np.where(done, x, xn)
    x = np.clip(x, a, b)
    x = np.where(t <= min(Fa, Fb), a if sign > 0 else b, x)  # the branch ends exactly
    x = np.where(t >= max(Fa, Fb), b if sign > 0 else a, x)
    return x.reshape(target.shape)


# ---------------------------------------------------------------------------- curves of a model

_THRUSTER_ATTRIBUTES = ("curve", "dead_zone", "tau")  # thruster.c kAttributes, in that order
_thruster_slot: list[int] = []


def _uvms_thruster_slot() -> int:
    """The plugin slot of `uvms.thruster` in this process (-1 when it is not registered),
    learnt once by compiling a one-site probe model."""
    if not _thruster_slot:
        xml = ('<mujoco><extension><plugin plugin="uvms.thruster"/></extension><worldbody><body><freejoint/><geom size="0.1"/><site name="s"/></body>'
               '</worldbody><actuator><plugin plugin="uvms.thruster" site="s"/></actuator></mujoco>')
        try:
            _thruster_slot.append(int(mujoco.MjModel.from_xml_string(xml).plugin[0]))
        except ValueError:
            return -1
    return _thruster_slot[0]


def thruster_curves(model: mujoco.MjModel, actuator_names: Sequence[str] | None = None) -> list[ThrustCurve]:
    """The thrust curve F(u) [N] of each thruster actuator (same selection and order as
    :func:`allocation_matrix`): the ``curve`` of a ``uvms.thruster`` plugin actuator (default
    ``poly 0 1``), or for a plain actuator with a fixed gain and no bias (``motor``, or
    ``general`` with ``gainprm[0] = g``) the line ``poly 0 g``.

    The curve maps the (lagged) command to the actuator force; the steady state of a lagged
    thruster is F(u). The dead zone is not part of the curve (a command strictly inside it
    gives 0).

    Raises:
        ValueError: an actuator of another plugin, or a plain one with a bias or a non-fixed
            gain (its force is not a function of the command alone).
    """
    curves = []
    for a in thruster_actuators(model, actuator_names):
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, a) or f"#{a}"
        i = int(model.actuator_plugin[a])
        if i >= 0:
            if int(model.plugin[i]) != _uvms_thruster_slot():
                raise ValueError(f"actuator {name!r}: a plugin actuator that is not uvms.thruster")
            start = int(model.plugin_attradr[i])
            end = int(model.plugin_attradr[i + 1]) if i + 1 < model.nplugin else int(model.npluginattr)
            vals = bytes(np.asarray(model.plugin_attr[start:end], dtype=np.uint8)).decode().split("\0")[:-1]
            cfg = dict(zip(_THRUSTER_ATTRIBUTES, vals))
            curves.append(ThrustCurve.parse(cfg.get("curve") or "poly 0 1"))
            continue
        if (int(model.actuator_gaintype[a]) != int(mujoco.mjtGain.mjGAIN_FIXED)
                or int(model.actuator_biastype[a]) != int(mujoco.mjtBias.mjBIAS_NONE)):
            raise ValueError(f"actuator {name!r}: force is not a fixed gain times the command (gain or bias type)")
        curves.append(ThrustCurve("poly", coeffs=(0.0, float(model.actuator_gainprm[a][0]))))
    return curves


def thrust_commands(model: mujoco.MjModel, thrust, actuator_names: Sequence[str] | None = None) -> np.ndarray:
    """Commands (``ctrl``) that make the thrusters produce ``thrust`` [N] in steady state:
    :func:`invert_curve` of each :func:`thruster_curves` curve, on the actuator's
    ``ctrlrange`` when it is limited (else the curve's default range: [-1, 1] for a
    non-linear poly, unbounded for a line); unreachable thrusts clamp to the range."""
    ids = thruster_actuators(model, actuator_names)
    curves = thruster_curves(model, actuator_names)
    thrust = _finite_array("thrust", thrust, ndim=1)
    if thrust.shape != (len(ids),):
        raise ValueError(f"thrust = {thrust.tolist()}: expected {len(ids)} values (one per thruster)")
    out = np.empty(len(ids))
    for k, (a, c) in enumerate(zip(ids, curves)):
        lo = hi = None
        if model.actuator_ctrllimited[a]:
            lo, hi = (float(v) for v in model.actuator_ctrlrange[a])
        elif c.kind == "poly" and len(np.trim_zeros(np.asarray(c.coeffs[1:]), "b")) == 1:
            lo, hi = -np.inf, np.inf
        out[k] = invert_curve(c, thrust[k], lo, hi)
    return out


class CurveInverse:
    """A precomputed, vectorised inverse of one thrust curve on a command range, for use every
    control sample (:func:`invert_curve` finds the monotone branch each call; this does it
    once).

    The branch [a, b] and the clamping are those of :func:`invert_curve`. A table inverts
    exactly by interpolation; a polynomial starts from the interpolated inverse of a
    ``grid``-point table (uniform in u) and takes Newton steps (``newton``) safeguarded to
    [a, b]. Measured on the T200 curve against :func:`invert_curve`: 2e-14 in u for |F| < 30 N,
    9e-11 within 0.001 N of its 30.62 N peak (where dF/du -> 0; ``newton=2``: 1.3e-13); the
    tests check 1e-12 on a 0.1 N grid.
    """

    def __init__(self, curve, lo: float | None = None, hi: float | None = None, grid: int = 20001,
                 newton: int = 1) -> None:
        self.curve = ThrustCurve.parse(curve)
        a, b, sign = self.curve.monotone_range(lo, hi)
        c = self.curve
        if c.kind == "poly" and len(np.trim_zeros(np.asarray(c.coeffs[1:]), "b")) == 1:
            self._linear = (float(c.coeffs[0]), float(c.coeffs[1]), a, b)
            return
        self._linear = None
        u = np.linspace(a, b, grid) if c.kind == "poly" else np.unique(np.r_[a, [x for x in c.u if a < x < b], b])
        F = c(u)
        if sign < 0:
            u, F = u[::-1], F[::-1]
        self.u, self.F, self.a, self.b = u, F, a, b
        self.newton = int(newton) if c.kind == "poly" else 0
        self.der = np.polynomial.polynomial.polyder(c.coeffs) if c.kind == "poly" else None
        if c.kind == "poly":
            self._F, self._dF = _Poly(c.coeffs), _Poly(self.der)
        # the tables as floats for :meth:`_floats` (a command vector every control sample)
        self._Fl, self._ul = self.F.tolist(), self.u.tolist()

    def __call__(self, F) -> np.ndarray:
        """Commands u for thrusts F [N] (array), clamped to the reachable thrusts."""
        F = np.asarray(F, dtype=float)
        if self._linear is None and F.ndim == 1 and F.size <= 32:
            vals = F.tolist()
            if math.isfinite(sum(vals)):  # every value finite: the same steps on floats
                return np.array(self._floats(vals))
        # np.minimum / np.maximum: the same clamping as np.clip, several times cheaper on a few values
        if self._linear is not None:
            c0, c1, a, b = self._linear
            return np.minimum(np.maximum((F - c0) / c1, min(a, b)), max(a, b))
        Fc = np.minimum(np.maximum(F, self.F[0]), self.F[-1])
        u = np.interp(Fc, self.F, self.u)
        F_of, dF_of = (self._F, self._dF) if self.newton else (None, None)  # a table: none
        for _ in range(self.newton):
            d = dF_of(u)
            step = np.zeros(u.shape)
            np.divide(F_of(u) - Fc, d, out=step, where=d != 0)  # no step where dF/du = 0
            u = np.minimum(np.maximum(u - step, self.a), self.b)
        return u

    def _floats(self, vals: list) -> list:
        """:meth:`__call__` of a few finite thrusts as Python floats, step for step the same
        arithmetic (np.interp's: the segment j with F[j] <= x < F[j + 1], its slope, x = F[j]
        exactly giving u[j]; the same Horner steps; the same clamps), without numpy's cost per call
        on a handful of values."""
        Ft, ut = self._Fl, self._ul
        F0, F1, last = Ft[0], Ft[-1], len(Ft) - 1
        a, b, newton = self.a, self.b, self.newton
        if newton:  # _Poly.at of F and dF/du, inlined (u * u shared)
            Fp, dp = self._F, self._dF
            fk, ftop, frev, dk, dtop, drev = Fp.kind, Fp.top, Fp.rev, dp.kind, dp.top, dp.rev
        search = bisect.bisect_right
        out = []
        for x in vals:
            x = F0 if F0 > x else x  # min(max(x, F0), F1), as np.minimum(np.maximum(...))
            x = F1 if F1 < x else x
            j = search(Ft, x) - 1
            if j >= last:
                u = ut[last]
            elif Ft[j] == x:
                u = ut[j]
            else:
                slope = (ut[j + 1] - ut[j]) / (Ft[j + 1] - Ft[j])
                u = slope * (x - Ft[j]) + ut[j]
                if u != u:  # as np.interp: from the other end of the segment
                    u = slope * (x - Ft[j + 1]) + ut[j + 1]
                    if u != u and ut[j] == ut[j + 1]:
                        u = ut[j]
            for _ in range(newton):
                uu = u * u
                xv = uu if dk != "plain" else u
                d = dtop
                for c in drev:
                    d = d * xv + c
                if dk == "odd":
                    d = u * d
                xv = uu if fk != "plain" else u
                y = ftop
                for c in frev:
                    y = y * xv + c
                if fk == "odd":
                    y = u * y
                u = u - ((y - x) / d if d != 0 else 0.0)
                u = a if a > u else u
                u = b if b < u else u
            out.append(u)
        return out
