"""Physical numbers of a compiled model that MuJoCo accepts but no robot has (issue 23, item 4): a
mass of 1e308 or -1, an inertia of NaN, a gravity of 1e308 compiled and then ended the run with
NaN (exit 1) or ran as if nothing were wrong. :func:`check_model_numbers` refuses them after
compiling, naming the element, the attribute, the value and the allowed range.

The bounds are ours, far beyond any underwater robot and its test tank (SI units): they only
separate a number from a typing error or an overflow.
"""

from __future__ import annotations

import mujoco
import numpy as np

__all__ = ["LENGTH_MAX", "MASS_MAX", "GRAVITY_MAX", "check_model_numbers", "check_spec_numbers"]

#: [kg] a body's mass; [kg m^2] its principal inertias (ours: a ship is 1e6 kg).
MASS_MAX = 1e6
#: [m] positions and sizes in the model file (ours: 10 km).
LENGTH_MAX = 1e4
#: [m/s^2] |<option gravity>| (ours: 10 g).
GRAVITY_MAX = 100.0
#: joint damping, armature, dry friction, actuator gear (ours: the override bound, 1e9 SI).
COEF_MAX = 1e9

# (MjModel array, element kind, attribute as written in MJCF, low, high, unit)
_CHECKS = (
    ("body_mass", mujoco.mjtObj.mjOBJ_BODY, "mass", 0.0, MASS_MAX, "kg"),
    ("body_inertia", mujoco.mjtObj.mjOBJ_BODY, "inertia", 0.0, MASS_MAX, "kg m^2"),
    ("body_pos", mujoco.mjtObj.mjOBJ_BODY, "pos", -LENGTH_MAX, LENGTH_MAX, "m"),
    ("body_ipos", mujoco.mjtObj.mjOBJ_BODY, "inertial pos", -LENGTH_MAX, LENGTH_MAX, "m"),
    ("body_quat", mujoco.mjtObj.mjOBJ_BODY, "quat", -1.0, 1.0, ""),
    ("geom_pos", mujoco.mjtObj.mjOBJ_GEOM, "pos", -LENGTH_MAX, LENGTH_MAX, "m"),
    ("geom_size", mujoco.mjtObj.mjOBJ_GEOM, "size", 0.0, LENGTH_MAX, "m"),
    ("site_pos", mujoco.mjtObj.mjOBJ_SITE, "pos", -LENGTH_MAX, LENGTH_MAX, "m"),
    ("dof_damping", mujoco.mjtObj.mjOBJ_DOF, "damping", 0.0, COEF_MAX, "SI"),
    ("dof_armature", mujoco.mjtObj.mjOBJ_DOF, "armature", 0.0, COEF_MAX, "SI"),
    ("dof_frictionloss", mujoco.mjtObj.mjOBJ_DOF, "frictionloss", 0.0, COEF_MAX, "SI"),
    ("actuator_gear", mujoco.mjtObj.mjOBJ_ACTUATOR, "gear", -COEF_MAX, COEF_MAX, ""),
    ("qpos0", None, "qpos0", -LENGTH_MAX, LENGTH_MAX, ""),
)


#: MuJoCo's own medium (<option density, viscosity, wind>; uvms.water models the water, so these are
#: normally 0): (attribute, low, high, unit), ours: ten times mercury's density, a thousand times water's viscosity.
_OPTIONS = (
    ("density", 0.0, 1.4e5, "kg/m^3"),
    ("viscosity", 0.0, 1.0, "Pa s"),
    ("wind", -1e3, 1e3, "m/s"),
    ("magnetic", -1e3, 1e3, "T"),
)


def _name(m: mujoco.MjModel, kind, i: int) -> str:
    if kind is None:
        return f"[{i}]"
    if kind == mujoco.mjtObj.mjOBJ_DOF:
        j = int(m.dof_jntid[i])
        return f"joint {mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j) or j!r}"
    what = str(kind.name).removeprefix("mjOBJ_").lower()
    return f"{what} {mujoco.mj_id2name(m, kind, i) or f'#{i}'!r}"


def check_model_numbers(m: mujoco.MjModel, source: str = "model") -> str | None:
    """The first number of ``m`` outside its physical range (see :data:`_CHECKS`), as one line naming
    ``source``, the element, the attribute, the value and the range; None when all are in range."""
    g = np.asarray(m.opt.gravity, dtype=float)
    if not np.all(np.isfinite(g)) or float(np.max(np.abs(g))) > GRAVITY_MAX:
        return (f"{source}: <option gravity> = {' '.join(f'{x:g}' for x in g)} m/s^2: each component must be "
                f"within +- {GRAVITY_MAX:g}")
    for attr, lo, hi, unit in _OPTIONS:
        v = np.atleast_1d(np.asarray(getattr(m.opt, attr), dtype=float))
        if not np.all(np.isfinite(v)) or np.any(v < lo) or np.any(v > hi):
            return (f"{source}: <option {attr}> = {' '.join(f'{x:g}' for x in v)} {unit} is outside "
                    f"[{lo:g}, {hi:g}] (finite)")
    for field, kind, attr, lo, hi, unit in _CHECKS:
        a = np.asarray(getattr(m, field), dtype=float)
        if not a.size:
            continue
        rows = a.reshape(a.shape[0], -1) if kind is not None else a.reshape(-1, 1)
        bad = ~np.isfinite(rows) | (rows < lo) | (rows > hi)
        if kind == mujoco.mjtObj.mjOBJ_BODY:
            bad[0] = False  # the world body
        hit = np.argwhere(bad)
        if len(hit):
            i = int(hit[0][0])
            vals = " ".join(f"{x:g}" for x in rows[i])
            return (f"{source}: {_name(m, kind, i)}: {attr} = {vals}{' ' + unit if unit else ''} is outside "
                    f"[{lo:g}, {hi:g}] (finite)")
    return None


def check_spec_numbers(spec: mujoco.MjSpec, source: str = "model") -> str | None:
    """What MuJoCo changes without a word when compiling: a negative ``<inertial mass>`` or
    ``diaginertia`` (compiled as 0: a massless vehicle that still ran). One line naming ``source``,
    the body and the value, or None."""
    for b in spec.bodies:
        if b.name == "world":
            continue
        mass = float(b.mass)
        if mass < 0 or not np.isfinite(mass) or mass > MASS_MAX:
            return f"{source}: body {b.name!r}: mass = {mass:g} kg is outside [0, {MASS_MAX:g}] (finite)"
        inertia = np.asarray(b.inertia, dtype=float)
        if np.any(inertia < 0) or not np.all(np.isfinite(inertia)):
            return (f"{source}: body {b.name!r}: diaginertia = {' '.join(f'{x:g}' for x in inertia)} kg m^2 must be "
                    "finite and >= 0")
    return None
