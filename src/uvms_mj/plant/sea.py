"""The waves seen by a plant: the logged signals and the free-surface check.

:class:`SeaMonitor` reads the waves from the compiled model's ``uvms.water`` attributes (set by
a scenario's ``waves:`` section or declared in the model file) and, per sample, gives

* ``wave_elevation`` [m]: the surface elevation eta above the mean surface at the vehicle's
  horizontal position (the origin of the base body's hydrodynamic frame, world x, y);
* ``wave_velocity`` [m/s]: the waves' water particle velocity (world) at that origin, the current
  not included (the plugin adds the two);

from :mod:`uvms_mj.physics.waves` (the numpy twin of the plugin's waves.c, equal to 1e-12 in
tests/test_waves.py). It also checks every ``uvms.hydro`` body's centre of buoyancy against the
mean surface: a body crossing the free surface is outside the model (linear waves below a fixed
mean surface, full submergence), so the plant refuses an initial state with a centre of buoyancy
above the mean surface (:class:`SurfaceError`) and warns once (``RuntimeWarning``) when one rises
above it during a run.
"""

from __future__ import annotations

import warnings

import mujoco
import numpy as np

from uvms_mj.physics import model as _pm
from uvms_mj.physics import reference as _ref

__all__ = ["SeaMonitor", "SurfaceError"]


class SurfaceError(ValueError):
    """A body's centre of buoyancy is above the mean water surface (out of the waves' scope)."""


class SeaMonitor:
    """The waves of a compiled model, evaluated at its vehicle (module docstring).

    Args:
        m: the compiled model; base_body: the vehicle's body id (its hydrodynamic frame, if it has
            one, else its body frame, is where the waves are evaluated).
    """

    def __init__(self, m: mujoco.MjModel, base_body: int) -> None:
        info = _pm.hydro_of(m)
        water = info.water
        self.m = m
        self.sea = _ref.sea(m, water) if water is not None and water.waves.on else None
        self.surface = float(water.waves.surface) if water is not None else 0.0
        self._bodies = info.bodies
        self._base = int(base_body)
        hb = info.bodies.get(self._base)
        self._pos = np.zeros(3) if hb is None else np.asarray(hb.pos, float)
        self._d = mujoco.MjData(m) if self.sea is not None else None
        self._warned = False

    @property
    def on(self) -> bool:
        return self.sea is not None

    def _kinematics(self, qpos: np.ndarray) -> mujoco.MjData:
        d = self._d
        d.qpos[:] = qpos
        mujoco.mj_kinematics(self.m, d)
        return d

    def highest_cob(self, qpos: np.ndarray) -> tuple[float, str]:
        """(height above the mean surface [m], body name) of the highest centre of buoyancy."""
        d = self._kinematics(qpos)
        best, name = -np.inf, ""
        for b, hb in self._bodies.items():
            if hb.volume <= 0:
                continue
            z = float(d.xpos[b][2] + d.xmat[b].reshape(3, 3)[2] @ hb.cob) - self.surface
            if z > best:
                best, name = z, mujoco.mj_id2name(self.m, mujoco.mjtObj.mjOBJ_BODY, b) or str(b)
        return best, name

    def check_initial(self, qpos: np.ndarray) -> None:
        """Raises :class:`SurfaceError` if a centre of buoyancy is above the mean surface."""
        if not self.on:
            return
        z, name = self.highest_cob(qpos)
        if z > 0:
            raise SurfaceError(f"waves: the centre of buoyancy of body {name!r} is {z:.3g} m above the mean surface "
                               f"(z = {self.surface:g} m); a body crossing the free surface is outside the model: "
                               "start the robot deeper (initial state) or raise waves.surface")

    def signals(self, t: float, qpos: np.ndarray) -> dict[str, object]:
        """``wave_elevation`` and ``wave_velocity`` at the vehicle at time t (empty without waves);
        warns once if a centre of buoyancy is above the mean surface."""
        if not self.on:
            return {}
        d = self._kinematics(qpos)
        b = self._base
        p = d.xpos[b] + d.xmat[b].reshape(3, 3) @ self._pos
        v, _ = self.sea.kinematics(t, p)
        if not self._warned:
            z, name = self.highest_cob(qpos)
            if z > 0:
                self._warned = True
                warnings.warn(f"waves: at t = {t:.3f} s the centre of buoyancy of body {name!r} is {z:.3g} m above "
                              f"the mean surface (z = {self.surface:g} m): a body crossing the free surface is outside "
                              "the model (its buoyancy and wave forces are those of a submerged body)",
                              RuntimeWarning, stacklevel=2)
        return {"wave_elevation": self.sea.elevation(t, float(p[0]), float(p[1])), "wave_velocity": v}
