"""Robot parameters, read from the compiled MuJoCo model (the single source of truth).

Every number here comes from ``models/uvms.xml`` (see the comments there for which come from
the paper's Table 1 and which are our documented assumptions). This module only *reads* and
*validates*; :func:`apply_planar_overrides` lets a caller change a parameter in the compiled model
before the plant is built, with the same validation.

Conventions: SI units. "Body frame" is the body's own MuJoCo frame: x along the link, y across
it, z out of the plane. World frame: X horizontal, Y up.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping

import mujoco
import numpy as np

from uvms_mj.plant.errors import ParameterError  # noqa: F401  (this module's error, re-exported)

# Names the plant relies on (see models/uvms.xml).
BASE_JOINTS = ("base_x", "base_y", "base_phi")
ARM_JOINTS = ("joint1", "joint2")
THRUSTERS = ("thruster1", "thruster2", "thruster3")
JOINT_MOTORS = ("joint1", "joint2")
TIP_SITE = "tip"
HYDRO_BODIES = ("base", "link1", "link2")


@dataclass(frozen=True)
class BodyParams:
    """Rigid-body and hydrodynamic parameters of one body, in its own (body) frame.

    Attributes:
        name: MuJoCo body name.
        mass: rigid mass m_i [kg].
        inertia: rigid moment of inertia about the centre of mass, axis normal to the plane [kg m^2].
        com: centre of mass (x, y) in the body frame [m].
        joint_offset: position (x, y) of this body's frame origin in its parent's frame [m]
            (for the base: its initial world position; unused by the dynamics).
        box_center: centre (x, y) of the body's geom box in the body frame [m]; the point where
            added mass and added inertia act (our assumption, docs/paper-reading.md).
        box_half: half extents (x, y) of the box in the plane [m] (strip lengths are 2x these).
        width: D_i, the box's out-of-plane extent [m] (Eqs. 2-3).
        added_mass: (m_Ax, m_Ay) along body x and y [kg] (Table 1).
        added_inertia: I_A about the axis normal to the plane [kg m^2] (Table 1).
        drag_coef: (C_Dx, C_Dy) for flow along body x and y (Table 1).
        volume: displaced volume V_i [m^3].
        cob: centre of buoyancy (x, y) in the body frame [m].
    """

    name: str
    mass: float
    inertia: float
    com: tuple[float, float]
    joint_offset: tuple[float, float]
    box_center: tuple[float, float]
    box_half: tuple[float, float]
    width: float
    added_mass: tuple[float, float]
    added_inertia: float
    drag_coef: tuple[float, float]
    volume: float
    cob: tuple[float, float]

    @property
    def length(self) -> float:
        """Box length along the body x axis [m] (Table 1 'Link length (x)')."""
        return 2.0 * self.box_half[0]


@dataclass(frozen=True)
class ThrusterParams:
    """One thruster: a MuJoCo site actuator thrusting along the site's x axis.

    Attributes:
        name: actuator (and site) name.
        position: site position (x, y) in the base frame [m].
        direction: unit thrust direction (x, y) in the base frame.
        tau: first-order lag time constant [s].
        force_range: (min, max) thrust [N]; asymmetric (reverse thrust is weaker).
    """

    name: str
    position: tuple[float, float]
    direction: tuple[float, float]
    tau: float
    force_range: tuple[float, float]


@dataclass(frozen=True)
class RobotParams:
    """All parameters of the robot, read from a compiled model.

    Attributes:
        bodies: base, link1, link2 (in chain order).
        thrusters: the three base thrusters.
        rho: water density [kg/m^3].
        gravity: world gravity vector (x, y) [m/s^2] as set in the model.
        tip_offset: end-tip site (x, y) in the link2 frame [m].
        dead_zone: (low, high) thrust band [N] that the optional dead zone maps to 0.
    """

    bodies: tuple[BodyParams, ...]
    thrusters: tuple[ThrusterParams, ...]
    rho: float
    gravity: tuple[float, float]
    tip_offset: tuple[float, float]
    dead_zone: tuple[float, float]

    def body(self, name: str) -> BodyParams:
        for b in self.bodies:
            if b.name == name:
                return b
        raise KeyError(f"no body named {name!r}; bodies are {[b.name for b in self.bodies]}")

    @property
    def link_lengths(self) -> tuple[float, float]:
        """(l1, l2): joint-to-joint (joint-to-tip) lengths of the arm [m]."""
        return (self.bodies[2].joint_offset[0], self.tip_offset[0])

    @property
    def joint1_offset(self) -> tuple[float, float]:
        """Joint 1 position in the base frame [m]."""
        return self.bodies[1].joint_offset


def _id(model: mujoco.MjModel, obj: mujoco.mjtObj, name: str, what: str) -> int:
    i = mujoco.mj_name2id(model, obj, name)
    if i < 0:
        raise ParameterError(f"model has no {what} named {name!r}, which uvms_mj requires")
    return i


def _numeric(model: mujoco.MjModel, name: str, size: int) -> tuple[float, ...]:
    i = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_NUMERIC, name)
    if i < 0:
        raise ParameterError(f"model has no <numeric name={name!r}> (expected {size} value(s))")
    adr, n = model.numeric_adr[i], model.numeric_size[i]
    if n != size:
        raise ParameterError(f"<numeric name={name!r}> has {n} value(s), expected {size}")
    vals = tuple(float(v) for v in model.numeric_data[adr : adr + n])
    for v in vals:
        if not math.isfinite(v):
            raise ParameterError(f"<numeric name={name!r}> = {vals} is not finite")
    return vals


def _check_planar(model: mujoco.MjModel) -> None:
    """The dynamics code assumes the model's planar structure; check it instead of trusting it."""
    jids = [_id(model, mujoco.mjtObj.mjOBJ_JOINT, n, "joint") for n in BASE_JOINTS + ARM_JOINTS]
    if model.nv != 5 or list(model.jnt_dofadr[jids]) != [0, 1, 2, 3, 4]:
        raise ParameterError(
            f"expected exactly 5 dofs in the order {BASE_JOINTS + ARM_JOINTS}, "
            f"got nv={model.nv}"
        )
    expected = [
        (mujoco.mjtJoint.mjJNT_SLIDE, (1, 0, 0)),
        (mujoco.mjtJoint.mjJNT_SLIDE, (0, 1, 0)),
        (mujoco.mjtJoint.mjJNT_HINGE, (0, 0, 1)),
        (mujoco.mjtJoint.mjJNT_HINGE, (0, 0, 1)),
        (mujoco.mjtJoint.mjJNT_HINGE, (0, 0, 1)),
    ]
    for j, (typ, axis) in zip(jids, expected):
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j)
        if model.jnt_type[j] != typ or not np.allclose(model.jnt_axis[j], axis):
            raise ParameterError(f"joint {name!r} must be {typ.name} about {axis}")
        if not np.allclose(model.jnt_pos[j], 0.0):
            raise ParameterError(f"joint {name!r} must sit at its body's origin")
    for name in HYDRO_BODIES:
        b = _id(model, mujoco.mjtObj.mjOBJ_BODY, name, "body")
        if not np.allclose(model.body_quat[b], (1, 0, 0, 0)) or abs(model.body_pos[b][2]) > 0:
            raise ParameterError(f"body {name!r} must lie in the z=0 plane with no rotation")


def _strip_coefs(name: str, bh, half: np.ndarray, width: float, center: np.ndarray) -> tuple[float, float]:
    """(C_Dx, C_Dy) of a body of the planar model from its strips (``uvms.hydro strips``).

    The paper's strips (Eqs. 2-3) lie along the box through its centre: along body x over the
    box length with C_Dy D for flow along y, and along body y over the box height with C_Dx D
    for flow along x (D = the box's out-of-plane extent). Strip coefficients for flow along z
    do not enter planar motion."""
    cdx = cdy = 0.0
    for axis, s0, s1, cd1, _cd2 in bh.strips:
        if axis not in (0, 1):
            raise ParameterError(f"body {name!r}: the planar model takes strips along x or y only")
        h = half[axis]
        if abs(s0 + h) > 1e-12 or abs(s1 - h) > 1e-12:
            raise ParameterError(f"body {name!r}: a strip along {'xy'[axis]} must span the box "
                                 f"({-h:g} to {h:g} m), got {s0:g} to {s1:g} m")
        if axis == 0:
            cdy = cd1 / width
        else:
            cdx = cd1 / width
    if not np.allclose(bh.pos, [center[0], center[1], 0.0], atol=1e-12, rtol=0):
        raise ParameterError(f"body {name!r}: the hydrodynamic frame must sit at the box centre {tuple(center)}")
    return cdx, cdy


def read_params(model: mujoco.MjModel) -> RobotParams:
    """Read and validate the robot parameters of a compiled model.

    The hydrodynamic parameters come from the model's ``uvms.water`` and ``uvms.hydro``
    plugin attributes (:func:`uvms_mj.physics.model.hydro_of`), read as the paper's planar
    quantities: added mass (Xu, Yv) and added inertia Nr, C_D = strip coefficient / D.

    Raises:
        ParameterError: a required element is missing, or a value is non-physical
            (mass <= 0, inertia <= 0, volume < 0, added mass < 0, drag coefficient < 0,
            density <= 0, thruster tau < 0 ...). The message names the parameter.
    """
    from uvms_mj.physics.model import hydro_of

    _check_planar(model)
    try:
        info = hydro_of(model)
    except ValueError as exc:
        raise ParameterError(str(exc)) from None
    if info.water is None:
        raise ParameterError("model has no uvms.water plugin instance (water density, current)")
    rho = float(info.water.density)

    bodies = []
    for name in HYDRO_BODIES:
        b = _id(model, mujoco.mjtObj.mjOBJ_BODY, name, "body")
        g = _id(model, mujoco.mjtObj.mjOBJ_GEOM, name, "geom (box)")
        if b not in info.bodies:
            raise ParameterError(f"body {name!r} has no uvms.hydro plugin (its hydrodynamic parameters)")
        bh = info.bodies[b]
        if model.geom_type[g] != mujoco.mjtGeom.mjGEOM_BOX or model.geom_bodyid[g] != b:
            raise ParameterError(f"geom {name!r} must be a box on body {name!r}")
        if not np.allclose(model.geom_quat[g], (1, 0, 0, 0)):
            raise ParameterError(f"geom {name!r} must not be rotated in its body frame")
        mass = float(model.body_mass[b])
        if not mass > 0:
            raise ParameterError(f"{name}.mass = {mass} kg must be > 0")
        inertia = float(model.body_inertia[b][2])
        if not inertia > 0:
            raise ParameterError(f"{name}.inertia = {inertia} kg m^2 must be > 0")
        if not np.allclose(model.body_iquat[b], (1, 0, 0, 0)):
            raise ParameterError(f"body {name!r}: principal inertia axes must be the body axes")
        if not np.allclose(bh.quat, (1, 0, 0, 0), atol=1e-12, rtol=0):
            raise ParameterError(f"body {name!r}: the hydrodynamic frame must have the body's axes")
        ma = np.asarray(bh.added_mass, dtype=float)
        planar = [(0, 0), (1, 1), (5, 5)]
        off = [(i, j) for i in range(6) for j in range(6) if (i, j) not in planar and i != j and ma[i, j] != 0.0
               and (i in (0, 1, 5) or j in (0, 1, 5))]
        if off:
            raise ParameterError(f"body {name!r}: the planar model takes a diagonal added mass (Xu, Yv, Nr); "
                                 f"entry {off[0]} is {ma[off[0]]}")
        am = (float(ma[0, 0]), float(ma[1, 1]), float(ma[5, 5]))
        size = model.geom_size[g]
        cd = _strip_coefs(name, bh, size[:2], float(2 * size[2]), model.geom_pos[g][:2])
        vol = float(bh.volume)
        for label, vals in (("added_mass", am), ("drag_coef", cd)):
            if min(vals) < 0:
                raise ParameterError(f"{name}.{label} = {vals} must be >= 0")
        bodies.append(
            BodyParams(
                name=name,
                mass=mass,
                inertia=inertia,
                com=(float(model.body_ipos[b][0]), float(model.body_ipos[b][1])),
                joint_offset=(float(model.body_pos[b][0]), float(model.body_pos[b][1])),
                box_center=(float(model.geom_pos[g][0]), float(model.geom_pos[g][1])),
                box_half=(float(size[0]), float(size[1])),
                width=float(2 * size[2]),
                added_mass=(am[0], am[1]),
                added_inertia=am[2],
                drag_coef=cd,
                volume=vol,
                cob=(float(bh.cob[0]), float(bh.cob[1])),
            )
        )
    # The arm must be a chain base -> link1 -> link2 with its joints on the link x axes.
    ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, n) for n in HYDRO_BODIES]
    if model.body_parentid[ids[1]] != ids[0] or model.body_parentid[ids[2]] != ids[1]:
        raise ParameterError("bodies must form the chain base -> link1 -> link2")
    if abs(bodies[2].joint_offset[1]) > 0:
        raise ParameterError("joint 2 must lie on the x axis of link 1")

    thrusters = []
    base_id = ids[0]
    for name in THRUSTERS:
        a = _id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, name, "actuator (thruster)")
        s = _id(model, mujoco.mjtObj.mjOBJ_SITE, name, "site (thruster)")
        if model.actuator_trntype[a] != mujoco.mjtTrn.mjTRN_SITE or model.actuator_trnid[a][0] != s:
            raise ParameterError(f"actuator {name!r} must act on site {name!r}")
        if model.site_bodyid[s] != base_id:
            raise ParameterError(f"thruster site {name!r} must be on the base")
        if int(model.actuator_dyntype[a]) not in (int(mujoco.mjtDyn.mjDYN_FILTER), int(mujoco.mjtDyn.mjDYN_FILTEREXACT)):
            raise ParameterError(f"thruster {name!r} must use dyntype filter or filterexact (first-order lag)")
        if (model.actuator_gaintype[a] != mujoco.mjtGain.mjGAIN_FIXED or model.actuator_gainprm[a][0] != 1
                or model.actuator_biastype[a] != mujoco.mjtBias.mjBIAS_NONE):
            raise ParameterError(f"thruster {name!r} must have gainprm='1' and no bias (thrust = lag state)")
        tau = float(model.actuator_dynprm[a][0])
        if not tau > 0:
            raise ParameterError(f"{name}.tau = {tau} s must be > 0")
        lo, hi = (float(v) for v in model.actuator_forcerange[a])
        if not (model.actuator_forcelimited[a] and lo < 0 < hi):
            raise ParameterError(f"{name}.force_range = ({lo}, {hi}) N must satisfy min < 0 < max")
        mat = np.empty(9)
        mujoco.mju_quat2Mat(mat, model.site_quat[s])
        gear = model.actuator_gear[a]
        if not np.allclose(gear, (1, 0, 0, 0, 0, 0)):
            raise ParameterError(f"thruster {name!r} must have gear='1 0 0 0 0 0'")
        direction = (float(mat[0]), float(mat[3]))  # site x axis in the base frame
        if abs(mat[6]) > 1e-12:
            raise ParameterError(f"thruster {name!r} must thrust in the plane")
        thrusters.append(
            ThrusterParams(
                name=name,
                position=(float(model.site_pos[s][0]), float(model.site_pos[s][1])),
                direction=direction,
                tau=tau,
                force_range=(lo, hi),
            )
        )

    tip = _id(model, mujoco.mjtObj.mjOBJ_SITE, TIP_SITE, "site (end tip)")
    if model.site_bodyid[tip] != ids[2] or abs(model.site_pos[tip][1]) > 0:
        raise ParameterError("site 'tip' must be on link2's x axis")
    dz = _numeric(model, "thruster:dead_zone", 2)
    if not dz[0] <= 0 <= dz[1]:
        raise ParameterError(f"thruster:dead_zone = {dz} N must satisfy low <= 0 <= high")
    return RobotParams(
        bodies=tuple(bodies),
        thrusters=tuple(thrusters),
        rho=rho,
        gravity=(float(model.opt.gravity[0]), float(model.opt.gravity[1])),
        tip_offset=(float(model.site_pos[tip][0]), float(model.site_pos[tip][1])),
        dead_zone=dz,
    )


# --------------------------------------------------------------------------- overrides

#: Keys accepted by :func:`apply_planar_overrides`, with their meaning. BODY is base, link1 or link2.
OVERRIDE_KEYS = {
    "water_density": "water density rho [kg/m^3]",
    "BODY.mass": "rigid mass [kg]",
    "BODY.inertia": "rigid moment of inertia about the CoM, z axis [kg m^2]",
    "BODY.added_mass": "[m_Ax, m_Ay, I_A] in the body frame [kg, kg, kg m^2]",
    "BODY.drag_coef": "[C_Dx, C_Dy]",
    "BODY.volume": "displaced volume [m^3]",
    "BODY.cob": "centre of buoyancy [x, y] in the body frame [m]",
    "thrusters.tau": "thruster first-order lag time constant [s]",
    "thrusters.force_range": "[min, max] thrust [N]",
    "thrusters.dead_zone": "[low, high] thrust band mapped to 0 [N]",
}


def _vector(key: str, value: Any, size: int) -> np.ndarray:
    arr = np.atleast_1d(np.asarray(value, dtype=float))
    if arr.shape != (size,):
        raise ParameterError(f"override {key!r} = {value!r} must have {size} value(s)")
    if not np.all(np.isfinite(arr)):
        raise ParameterError(f"override {key!r} = {value!r} must be finite")
    return arr


def _spec_numeric(spec: mujoco.MjSpec, name: str, values: np.ndarray) -> None:
    for n in spec.numerics:
        if n.name == name:
            n.data = [float(v) for v in values]
            return
    raise ParameterError(f"model has no <numeric name={name!r}> to override")


def _box(spec: mujoco.MjSpec, body: str):
    g = spec.geom(body)
    if g is None or g.type != mujoco.mjtGeom.mjGEOM_BOX:
        raise ParameterError(f"model has no box geom named {body!r}")
    return g


def _strips(cdx: float, cdy: float, half: np.ndarray, width: float) -> str:
    """The paper's strips of a box (see :func:`_strip_coefs`) as a ``uvms.hydro strips`` value."""
    hx, hy, cdx, cdy, width = (float(v) for v in (half[0], half[1], cdx, cdy, width))
    parts = []
    if cdy:
        parts.append(f"x {-hx!r} {hx!r} {cdy * width!r} 0")
    if cdx:
        parts.append(f"y {-hy!r} {hy!r} {cdx * width!r} 0")
    return "; ".join(parts)


def apply_planar_overrides(spec: mujoco.MjSpec, overrides: Mapping[str, Any]) -> None:
    """Change parameters of a model spec in place, before it is compiled (then
    :func:`read_params` re-validates the compiled model).

    Keys are listed in :data:`OVERRIDE_KEYS`, e.g. ``{"base.volume": 0.03,
    "link1.added_mass": [1.3, 3.6, 0.11], "thrusters.tau": 0.1}``. Hydrodynamic keys edit the
    bodies' ``uvms.hydro`` attributes (added mass (Xu, Yv, Nr); the strips from C_D and the box;
    volume; centre of buoyancy) and ``water_density`` the ``uvms.water`` density.

    Raises:
        ParameterError: unknown key (with the allowed keys) or a value of the wrong shape.
    """
    from uvms_mj.physics import model as pm

    def positive(label: str, vals: np.ndarray, unit: str, strict: bool) -> None:
        bad = np.any(vals <= 0) if strict else np.any(vals < 0)
        if bad:
            shown = float(vals[0]) if vals.size == 1 else tuple(float(v) for v in vals)
            raise ParameterError(f"{label} = {shown}{unit} must be {'>' if strict else '>='} 0")

    for key, value in overrides.items():
        head, _, field = key.partition(".")
        if key == "water_density":
            rho = _vector(key, value, 1)
            positive("water_density", rho, " kg/m^3", True)
            pm.set_water(spec, density=pm.fmt(rho))
        elif head in HYDRO_BODIES and field in ("mass", "inertia", "added_mass", "drag_coef", "volume", "cob"):
            b = spec.body(head)
            if b is None:
                raise ParameterError(f"model has no body named {head!r}")
            if field == "mass":
                v = _vector(key, value, 1)
                positive(key, v, " kg", True)
                b.mass = float(v[0])
            elif field == "inertia":
                # Out-of-plane inertias follow I_zz, as in the model file.
                v = _vector(key, value, 1)
                positive(key, v, " kg m^2", True)
                b.inertia = [float(v[0])] * 3
            elif field == "added_mass":
                v = _vector(key, value, 3)
                positive(key, v, "", False)
                mx, my, ia = v
                try:
                    old = [float(v) for v in pm.body_config(spec, head).get("added_mass", "0 0 0 0 0 0").split()]
                except ValueError:
                    old = [0.0] * 6
                diag = old if len(old) == 6 else [0.0] * 6
                diag[0], diag[1], diag[5] = mx, my, ia
                pm.set_body(spec, head, added_mass=pm.fmt(diag))
            elif field == "drag_coef":
                v = _vector(key, value, 2)
                positive(key, v, "", False)
                cdx, cdy = v
                g = _box(spec, head)
                pm.set_body(spec, head, strips=_strips(cdx, cdy, np.asarray(g.size[:2]), 2.0 * float(g.size[2])))
            elif field == "volume":
                v = _vector(key, value, 1)
                positive(key, v, " m^3", False)
                pm.set_body(spec, head, volume=pm.fmt(v))
            else:
                x, y = _vector(key, value, 2)
                pm.set_body(spec, head, cob=pm.fmt([x, y, 0.0]))
        elif key in ("thrusters.tau", "thrusters.force_range"):
            vals = _vector(key, value, 1 if key == "thrusters.tau" else 2)
            for name in THRUSTERS:
                a = spec.actuator(name)
                if a is None:
                    raise ParameterError(f"model has no actuator named {name!r}")
                if key == "thrusters.tau":
                    prm = list(a.dynprm)
                    prm[0] = float(vals[0])
                    a.dynprm = prm
                else:
                    a.forcerange = [float(v) for v in vals]
                    a.ctrlrange = [float(v) for v in vals]
        elif key == "thrusters.dead_zone":
            _spec_numeric(spec, "thruster:dead_zone", _vector(key, value, 2))
        else:
            raise ParameterError(
                f"unknown parameter override {key!r}; allowed: "
                + ", ".join(k.replace("BODY", "{" + ",".join(HYDRO_BODIES) + "}") for k in OVERRIDE_KEYS)
            )


def compile_robot(path: Any = None, overrides: Mapping[str, Any] | None = None, *,
                  native: bool | None = None) -> mujoco.MjModel:
    """Load a model file (default: the package's ``models/uvms.xml``), apply parameter
    overrides (:func:`apply_planar_overrides`) and compile it (C plugins when available).

    Raises:
        ParameterError: missing file, bad override, or a model that does not compile."""
    from uvms_mj.physics import model as pm
    from uvms_mj.plant.files import models_dir

    path = path if path is not None else models_dir() / "uvms.xml"
    try:
        spec = pm.load_spec(path)
        if overrides:
            apply_planar_overrides(spec, overrides)
        return pm.compile_spec(spec, native=native, source=str(getattr(path, "name", path)))
    except pm.ModelError as exc:
        raise ParameterError(str(exc)) from None
