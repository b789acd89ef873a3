"""What a plant sets on its model around compiling: which hydrodynamics backend, the water
plugin's terms, the integration (timestep, integrator)."""

from __future__ import annotations

import math

import mujoco

from uvms_mj.physics import build as _build
from uvms_mj.physics.terms import BACKENDS, HydroTerms, default_backend
from uvms_mj.plant.errors import ParameterError

__all__ = ["resolve_backend", "set_integration", "water_terms"]


def resolve_backend(requested: str | None, terms: HydroTerms) -> bool:
    """Whether to use the native (C plugin) backend for the requested one (None: the one
    :func:`default_backend` gives).

    Raises:
        uvms_mj.plant.errors.ParameterError: an unknown backend.
        uvms_mj.physics.build.PluginUnavailableError: "native" asked for, and the plugins cannot be
            built."""
    if requested is None:
        requested = default_backend()  # UVMS_MJ_COMPILED; a bad value raises CompiledModeError
    if requested not in BACKENDS:
        raise ParameterError(f"backend = {requested!r}; allowed: {', '.join(BACKENDS)}")
    if requested == "python" or terms.added_mass == "lagged":  # lagged exists only in Python
        return False
    if requested == "native":
        if not _build.register_plugins():
            raise _build.PluginUnavailableError(f"backend 'native': {_build.unavailable_reason()}")
        return True
    return _build.register_plugins()


def water_terms(terms: HydroTerms) -> str:
    """The ``uvms.water`` ``terms`` word list for :class:`HydroTerms` (damping and
    Froude-Krylov always on)."""
    words = ["damping", "froude_krylov"]
    if terms.added_mass != "off":
        words.append("added_mass")
    if terms.drag == "strip":
        words.append("strips")
    if terms.buoyancy:
        words.append("buoyancy")
    return " ".join(sorted(words))


def set_integration(m: mujoco.MjModel, timestep: float | None, integrator: str | None) -> None:
    """Override a compiled model's timestep [s] and integrator (by name, e.g. "rk4"); None keeps
    the model's.

    Raises:
        uvms_mj.plant.errors.ParameterError: a timestep that is not finite and > 0, an unknown
            integrator name."""
    if timestep is not None:
        if not (math.isfinite(timestep) and timestep > 0):
            raise ParameterError(f"timestep = {timestep!r} s must be finite and > 0")
        m.opt.timestep = timestep
    if integrator is not None:
        names = {k.removeprefix("mjINT_").lower(): v for k, v in mujoco.mjtIntegrator.__members__.items()}
        key = integrator.lower()
        if key not in names:
            raise ParameterError(f"integrator = {integrator!r}; allowed: {', '.join(names)}")
        m.opt.integrator = names[key]
