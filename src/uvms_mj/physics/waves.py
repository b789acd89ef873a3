"""Linear (Airy) water waves: regular waves and irregular seas, the numpy twin of ``plugin/waves.c``.

The ``uvms.water`` plugin simulates them (attributes ``wave_model``, ``wave_height``, ... in
docs/hydrodynamics.md, "Waves"); this module states the same rules for reading, for the Python
backend (:mod:`uvms_mj.physics.reference`), for logging (the elevation and the wave velocity at
the vehicle) and for the tests, which compare it with the C code (1e-12) and both with closed
forms. World frame, z up, SI units; angles in radians.

A sea is a sum of components (a_i, omega_i, k_i, theta_i, phi_i): amplitude [m], angular
frequency [rad/s], wavenumber [rad/m] from the dispersion relation omega^2 = g k tanh(k h)
(Faltinsen 1990 table 2.1; DNV-RP-C205 sec. 3.2.2; deep water omega^2 = g k), direction of travel
(from +x towards +y) and phase. With psi = k (x cos theta + y sin theta) - omega t + phi and
zeta = z - surface (Faltinsen 1990 table 2.1; DNV-RP-C205 sec. 3.2.2):

    eta = sum a cos psi
    u_h = sum a omega C cos psi,   w = sum a omega S sin psi
    du_h/dt = sum a omega^2 C sin psi,   dw/dt = -sum a omega^2 S cos psi

C = cosh(k (zeta + h)) / sinh(k h), S = sinh(k (zeta + h)) / sinh(k h) (finite depth h), C = S =
e^{k zeta} (deep water). Components: :meth:`Waves.components` (the discretisation rule).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from uvms_mj.physics.rng import MASK, splitmix64

__all__ = [
    "BAND",
    "DEFAULT_COMPONENTS",
    "DEFAULT_GAMMA",
    "Sea",
    "WAVE_MODELS",
    "Waves",
    "sea_of",
    "wave_uniform",
    "wavenumber",
]

WAVE_MODELS = ("none", "airy", "jonswap", "pierson_moskowitz")
#: Components of an irregular sea unless ``n_components`` says otherwise (ours: 100 over
#: [0.5, 4] omega_p puts 3.5% of omega_p between components, a few across JONSWAP's peak; the
#: realised Hs is then within ~1.5% of the spectrum's, tests/test_waves.py).
DEFAULT_COMPONENTS = 100
#: The discretised band [lo, hi] in units of omega_p (ours): below 0.5 omega_p a JONSWAP/PM
#: spectrum holds < 1e-8 of m0, above 4 omega_p about 0.5% (the omega^-5 tail).
BAND = (0.5, 4.0)
#: JONSWAP's peak enhancement factor when not given (DNV-RP-C205 sec. 3.5.5, the mean of the JONSWAP experiment).
DEFAULT_GAMMA = 3.3
MAX_SPREADING = 100.0
MAX_COMPONENTS = 10000


def wave_uniform(seed: int, i: int, c: int) -> float:
    """Uniform number c of component i of the stream ``seed``, in [0, 1):
    (splitmix64(seed ^ splitmix64(4096 i + c)) >> 11) 2^-53."""
    return (splitmix64((seed & MASK) ^ splitmix64((4096 * i + c) & MASK)) >> 11) * 2.0**-53


def wavenumber(omega, depth: float, g: float):
    """k of omega^2 = g k tanh(k h) (depth h > 0), or omega^2 / g (depth <= 0: deep water).

    Newton's method on x tanh x = y (x = k h, y = omega^2 h / g) from Eckart's x = y / sqrt(tanh y),
    as the C code does; the tests solve the relation independently (scipy's brentq)."""
    om = np.asarray(omega, float)
    k0 = om * om / g
    if not depth > 0:
        return k0
    y = k0 * depth
    x = y / np.sqrt(np.tanh(y))
    for _ in range(100):
        th = np.tanh(x)
        dx = (x * th - y) / (th + x * (1.0 - th * th))
        x = x - dx
        if np.all(np.abs(dx) <= 1e-16 * x):
            break
    return x / depth


def _number(name: str, v, lo: float | None = None, hi: float | None = None, strict: bool = False) -> float:
    try:
        x = float(v)
    except (TypeError, ValueError):
        raise ValueError(f"waves.{name} = {v!r}: expected a number") from None
    bad = not math.isfinite(x) or (lo is not None and (x <= lo if strict else x < lo)) or (hi is not None and x > hi)
    if bad:
        rng = f"{'>' if strict else '>='} {lo:g}" if lo is not None else "finite"
        if hi is not None:
            rng += f" and <= {hi:g}"
        raise ValueError(f"waves.{name} = {v!r}: must be {rng}")
    return x


@dataclass(frozen=True)
class Waves:
    """A sea state as the ``uvms.water`` plugin's wave attributes (module docstring).

    Attributes:
        model: "none", "airy" (a regular wave), "jonswap" or "pierson_moskowitz".
        height: airy: the wave height H = 2a [m]; spectra: the significant wave height Hs [m].
        period: airy: the period T [s]; spectra: the peak period Tp [s].
        gamma: JONSWAP's peak enhancement factor, 1..7 (default 3.3).
        direction: mean direction of travel, world, from +x towards +y [rad].
        spreading: cos^n spreading exponent n (0 = long-crested, the default), 0..100.
        depth: water depth h [m] (finite depth), 0 = deep water (the default).
        surface: world height z of the mean free surface [m] (default 0, the models' convention).
        seed: the random frequency offsets, phases and directions (same seed, same sea).
        n_components: components of an irregular sea (default :data:`DEFAULT_COMPONENTS`).

    Raises:
        ValueError: a field outside its range, naming it, the value and what is allowed.
    """

    model: str = "none"
    height: float = 0.0
    period: float = 0.0
    gamma: float = DEFAULT_GAMMA
    direction: float = 0.0
    spreading: float = 0.0
    depth: float = 0.0
    surface: float = 0.0
    seed: int = 0
    n_components: int = DEFAULT_COMPONENTS

    def __post_init__(self) -> None:
        if self.model not in WAVE_MODELS:
            raise ValueError(f"waves.model = {self.model!r}; allowed: {', '.join(WAVE_MODELS)}")
        on = self.model != "none"
        object.__setattr__(self, "height", _number("height", self.height, 0.0, None, strict=on))
        object.__setattr__(self, "period", _number("period", self.period, 0.0, None, strict=on))
        object.__setattr__(self, "gamma", _number("gamma", self.gamma, 1.0, 7.0))
        object.__setattr__(self, "direction", _number("direction", self.direction))
        object.__setattr__(self, "spreading", _number("spreading", self.spreading, 0.0, MAX_SPREADING))
        object.__setattr__(self, "depth", _number("depth", self.depth, 0.0))
        object.__setattr__(self, "surface", _number("surface", self.surface))
        if not (isinstance(self.seed, int) and not isinstance(self.seed, bool) and 0 <= self.seed < 2**64):
            raise ValueError(f"waves.seed = {self.seed!r}: expected an integer in [0, 2^64)")
        n = self.n_components
        if not (isinstance(n, int) and not isinstance(n, bool) and 1 <= n <= MAX_COMPONENTS):
            raise ValueError(f"waves.n_components = {n!r}: expected an integer in [1, {MAX_COMPONENTS}]")

    @property
    def on(self) -> bool:
        return self.model != "none"

    def attributes(self) -> dict[str, str]:
        """The ``uvms.water`` attributes of these waves (strings, as in the MJCF)."""
        out = {"wave_model": self.model, "surface": repr(self.surface)}
        if self.on:
            out.update(wave_height=repr(self.height), wave_period=repr(self.period), wave_gamma=repr(self.gamma),
                       wave_direction=repr(self.direction), wave_spreading=repr(self.spreading),
                       wave_depth=repr(self.depth), wave_seed=str(self.seed),
                       wave_components=str(self.n_components))
        return out

    def spectrum(self, omega):
        """One-sided spectrum S(omega) [m^2 s/rad] (DNV-RP-C205 3.5.5), omega_p = 2 pi / Tp:

            S_PM = 5/16 Hs^2 omega_p^4 omega^-5 exp(-5/4 (omega/omega_p)^-4)
            S_J = (1 - 0.287 ln gamma) S_PM gamma^exp(-(omega - omega_p)^2 / (2 sigma^2 omega_p^2)),
            sigma = 0.07 (omega <= omega_p), 0.09 (omega > omega_p).
        """
        om = np.asarray(omega, float)
        wp = 2.0 * math.pi / self.period
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            r4 = (wp / om) ** 4
            s = 5.0 / 16.0 * self.height**2 * wp**4 / om**5 * np.exp(-1.25 * r4)
            if self.model == "jonswap":
                sig = np.where(om <= wp, 0.07, 0.09)
                q = (om - wp) / (sig * wp)
                s = s * (1.0 - 0.287 * math.log(self.gamma)) * self.gamma ** np.exp(-0.5 * q * q)
        return np.where(om > 0, s, 0.0)

    def components(self, g: float) -> np.ndarray:
        """The components, (n, 7): a, omega, k, cos theta, sin theta, phi, 1/(1 - e^{-2kh}) (1 deep).

        * airy: a = H/2, omega = 2 pi/T, theta = direction, phi = 0 (a crest at the origin at t = 0);
        * spectra: equal spacing with random offsets over [BAND] omega_p, d_omega = (hi - lo) omega_p / n:
          omega_i = lo omega_p + (i + u_i0) d_omega, a_i = sqrt(2 S(omega_i) d_omega), phi_i = 2 pi u_i1,
          theta_i = direction + delta_i, delta_i ~ cos^n(delta) on |delta| <= pi/2 by rejection
          (delta = pi (u_{i,2+2j} - 1/2) accepted when u_{i,3+2j} <= cos^n delta, j < 2000, else 0);
          u_ic = :func:`wave_uniform` (seed, i, c).
        """
        if not self.on:
            return np.zeros((0, 7))
        if not g > 0:
            raise ValueError("waves need gravity along -z (opt.gravity = (0, 0, -g), g > 0)")
        wp = 2.0 * math.pi / self.period
        if self.model == "airy":
            a = np.array([0.5 * self.height])
            om = np.array([wp])
            ph = np.zeros(1)
            dth = np.zeros(1)
        else:
            n = self.n_components
            dw = (BAND[1] - BAND[0]) * wp / n
            u0 = np.array([wave_uniform(self.seed, i, 0) for i in range(n)])
            om = BAND[0] * wp + (np.arange(n) + u0) * dw
            a = np.sqrt(2.0 * self.spectrum(om) * dw)
            ph = 2.0 * math.pi * np.array([wave_uniform(self.seed, i, 1) for i in range(n)])
            dth = np.zeros(n)
            if self.spreading > 0:
                for i in range(n):
                    for j in range(2000):
                        d = math.pi * (wave_uniform(self.seed, i, 2 + 2 * j) - 0.5)
                        if wave_uniform(self.seed, i, 3 + 2 * j) <= math.cos(d) ** self.spreading:
                            dth[i] = d
                            break
        th = self.direction + dth
        k = wavenumber(om, self.depth, g)
        inv = 1.0 / (1.0 - np.exp(-2.0 * k * self.depth)) if self.depth > 0 else np.ones_like(k)
        return np.column_stack([a, om, k, np.cos(th), np.sin(th), ph, inv])


@dataclass(frozen=True)
class Sea:
    """The components of a :class:`Waves` for a gravity g, evaluated (module docstring)."""

    waves: Waves
    g: float
    c: np.ndarray

    def elevation(self, t: float, x: float, y: float) -> float:
        """eta [m] above the mean surface at the horizontal (x, y), time t."""
        c = self.c
        return float(np.sum(c[:, 0] * np.cos(c[:, 2] * (x * c[:, 3] + y * c[:, 4]) - c[:, 1] * t + c[:, 5])))

    def kinematics(self, t: float, p, gradient: bool = False):
        """Particle velocity v and local acceleration dv/dt (world, m/s and m/s^2) at the point p, time t
        (below the seabed zeta is clamped to -h); with ``gradient`` also grad v (3 x 3, [i, j] = dv_i/dx_j,
        1/s; symmetric and trace-free: the flow is irrotational and incompressible):

            du_h/dx_j = -A d_j,  du_h/dz = B,  dw/dx_j = B d_j,  dw/dz = A,
            A = sum a omega k C sin psi d,  B = sum a omega k S cos psi  (d = (cos theta, sin theta)).
        """
        c = self.c
        x, y, z = (float(v) for v in p)
        zeta = z - self.waves.surface
        h = self.waves.depth
        if h > 0 and zeta < -h:
            zeta = -h
        k, om = c[:, 2], c[:, 1]
        psi = k * (x * c[:, 3] + y * c[:, 4]) - om * t + c[:, 5]
        cp, sp = np.cos(psi), np.sin(psi)
        if h > 0:
            e1, e2 = np.exp(k * zeta), np.exp(-k * (zeta + 2.0 * h))
            C, S = (e1 + e2) * c[:, 6], (e1 - e2) * c[:, 6]
        else:
            C = S = np.exp(k * zeta)
        aw = c[:, 0] * om
        aw2 = aw * om
        uh, dh = aw * C * cp, aw2 * C * sp
        v = np.array([np.sum(uh * c[:, 3]), np.sum(uh * c[:, 4]), np.sum(aw * S * sp)])
        a = np.array([np.sum(dh * c[:, 3]), np.sum(dh * c[:, 4]), -np.sum(aw2 * S * cp)])
        if not gradient:
            return v, a
        A, B = aw * k * C * sp, aw * k * S * cp
        cx, cy = c[:, 3], c[:, 4]
        gxx, gxy, gyy = np.sum(A * cx * cx), np.sum(A * cx * cy), np.sum(A * cy * cy)
        bx, by = np.sum(B * cx), np.sum(B * cy)
        grad = np.array([[-gxx, -gxy, bx], [-gxy, -gyy, by], [bx, by, np.sum(A)]])
        return v, a, grad


@functools.lru_cache(maxsize=32)
def sea_of(waves: Waves, g: float) -> Sea:
    """The :class:`Sea` of ``waves`` under gravity g (cached)."""
    c = waves.components(g)
    c.setflags(write=False)
    return Sea(waves, float(g), c)
