"""Which hydrodynamic terms a plant applies, and which implementation computes them.

:class:`HydroTerms` switches the terms of the ``uvms.water`` plugin (``terms`` attribute) and the
two options of the paper's planar robot (lagged added mass, MuJoCo's ellipsoid drag);
:func:`default_backend` is the backend ``UVMS_MJ_COMPILED`` implies (:mod:`uvms_mj.physics.build`).
"""

from __future__ import annotations

from dataclasses import dataclass

from uvms_mj.physics import build as _build

__all__ = ["BACKENDS", "HydroTerms", "default_backend"]

#: Hydrodynamics backends of a plant: the C plugins ("native"), the numpy reference ("python"),
#: or native where it builds ("auto").
BACKENDS = ("auto", "python", "native")


@dataclass(frozen=True)
class HydroTerms:
    """Which hydrodynamic terms the plant applies (all on by default).

    Attributes:
        added_mass: "exact" (in the mass matrix, every step), "lagged" (-M_A times the previous
            step's acceleration, as some peer simulators do: kept only to show that it
            diverges), or "off".
        drag: "strip" (paper Eqs. 2-3), "mujoco" (MuJoCo's ellipsoid model with its
            virtual-mass terms removed, since added mass is ours), or "off".
        buoyancy: apply -rho V g at each centre of buoyancy.
    """

    added_mass: str = "exact"
    drag: str = "strip"
    buoyancy: bool = True

    def __post_init__(self) -> None:
        allowed = {"added_mass": ("exact", "lagged", "off"), "drag": ("strip", "mujoco", "off")}
        for field, values in allowed.items():
            v = getattr(self, field)
            if v not in values:
                raise ValueError(f"HydroTerms.{field} = {v!r}; allowed: {', '.join(values)}")
        if not isinstance(self.buoyancy, bool):
            raise ValueError(f"HydroTerms.buoyancy = {self.buoyancy!r}; allowed: True, False")


def default_backend() -> str:
    """The hydrodynamics backend that ``UVMS_MJ_COMPILED`` implies when none is asked for:
    "auto" (auto), "native" (on) or "python" (off).

    Raises:
        uvms_mj.physics.build.CompiledModeError: a bad value, or a former switch set."""
    return {"auto": "auto", "on": "native", "off": "python"}[_build.compiled_mode()]
