"""The water current of a model, as the ``uvms.water`` plugin's attributes.

:class:`Current` is one of the plugin's three current models (docs/hydrodynamics.md, "Currents"),
world frame, m/s, z up for the 3-D robots (the paper's plane: x horizontal, y up):

* ``constant``: v_c = ``velocity``;
* ``gauss_markov``: a first-order Gauss-Markov (Ornstein-Uhlenbeck) process per axis, sampled
  every timestep h from v_0 = ``velocity``:
  v_{k+1} = mu + (v_k - mu) e^{-h/tau} + sigma sqrt(1 - e^{-2h/tau}) n_k, clipped to
  [``vmin``, ``vmax``], n_k a counter-based normal of (``seed``, k, axis); the current
  accelerates, so the plugin's Froude-Krylov and added-mass terms see a_c;
* ``profile``: v_c(z) piecewise linear through the knots (z, vx, vy, vz), z strictly increasing,
  constant beyond the end knots (a steady shear current).

:meth:`Current.attributes` gives the plugin's attributes; a plant applies them to the model
before compiling (:class:`uvms_mj.plant.plant.Plant` ``current=``), so plain MuJoCo simulates
the same current from the compiled model.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

from uvms_mj.physics.config import CURRENT_MODELS
from uvms_mj.physics.model import fmt

__all__ = ["Current"]


def _vec3(name: str, v: Sequence[float] | None) -> tuple[float, float, float] | None:
    if v is None:
        return None
    t = tuple(float(x) for x in v)
    if len(t) == 2:  # a planar robot's (vx, vy)
        t = (*t, 0.0)
    if len(t) != 3 or not all(math.isfinite(x) for x in t):
        raise ValueError(f"current.{name} = {list(v)!r}: expected 2 or 3 finite numbers (world, m/s)")
    return t


@dataclass(frozen=True)
class Current:
    """A current model (module docstring). Every vector is world frame [m/s] (2 numbers: a planar
    robot's (vx, vy), vz = 0).

    Attributes:
        model: "constant" | "gauss_markov" | "profile".
        velocity: the constant current, or the Gauss-Markov start v_0.
        mean, sigma, tau: Gauss-Markov mean mu [m/s], noise std sigma [m/s] (stationary std of
            each axis) and correlation time tau [s] (per axis); None: the plugin's defaults.
        vmin, vmax: Gauss-Markov clipping bounds [m/s]; None: none.
        seed: Gauss-Markov random stream (same seed, same current).
        profile: knots (z [m], vx, vy, vz [m/s]) of a depth profile.

    Raises:
        ValueError: an unknown model, a vector that is not 2 or 3 finite numbers, sigma < 0,
            tau <= 0, vmin > vmax, a profile with fewer than one knot or z not increasing.
    """

    model: str = "constant"
    velocity: Sequence[float] = (0.0, 0.0, 0.0)
    mean: Sequence[float] | None = None
    sigma: Sequence[float] | None = None
    tau: Sequence[float] | None = None
    vmin: Sequence[float] | None = None
    vmax: Sequence[float] | None = None
    seed: int = 0
    profile: Sequence[Sequence[float]] = ()

    def __post_init__(self) -> None:
        if self.model not in CURRENT_MODELS:
            raise ValueError(f"current.model = {self.model!r}; allowed: {', '.join(CURRENT_MODELS)}")
        for name in ("velocity", "mean", "sigma", "tau", "vmin", "vmax"):
            object.__setattr__(self, name, _vec3(name, getattr(self, name)))
        if self.sigma is not None and min(self.sigma) < 0:
            raise ValueError(f"current.sigma = {list(self.sigma)!r}: must be >= 0 [m/s]")
        if self.tau is not None and min(self.tau) <= 0:
            raise ValueError(f"current.tau = {list(self.tau)!r}: must be > 0 [s]")
        if self.vmin is not None and self.vmax is not None and any(a > b for a, b in zip(self.vmin, self.vmax)):
            raise ValueError(f"current.vmin = {list(self.vmin)!r} > vmax = {list(self.vmax)!r} in some axis")
        if not (isinstance(self.seed, int) and not isinstance(self.seed, bool) and 0 <= self.seed < 2**64):
            raise ValueError(f"current.seed = {self.seed!r}: expected an integer in [0, 2^64)")
        knots = tuple(tuple(float(x) for x in k) for k in self.profile)
        if self.model == "profile":
            if not knots or any(len(k) != 4 or not all(map(math.isfinite, k)) for k in knots):
                raise ValueError(f"current.profile = {self.profile!r}: expected knots [z, vx, vy, vz] (m, m/s)")
            if any(b[0] <= a[0] for a, b in zip(knots, knots[1:])):
                raise ValueError("current.profile: the knots' z must be strictly increasing")
        object.__setattr__(self, "profile", knots)

    def attributes(self) -> dict[str, str]:
        """The ``uvms.water`` attributes of this current (strings, as in the MJCF)."""
        out = {"current_model": self.model, "current": fmt(self.velocity)}
        if self.model == "gauss_markov":
            for key, v in (("gm_mean", self.mean), ("gm_sigma", self.sigma), ("gm_tau", self.tau),
                           ("gm_min", self.vmin), ("gm_max", self.vmax)):
                if v is not None:
                    out[key] = fmt(v)
            out["gm_seed"] = str(int(self.seed))
        elif self.model == "profile":
            out["profile"] = "; ".join(fmt(k) for k in self.profile)
        return out
