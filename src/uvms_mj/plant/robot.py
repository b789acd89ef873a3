"""A robot's model file, edited by name: overrides (absolute or factors, by element name or the
``vehicle`` role), compiling, a payload picked up during a run.

* :func:`apply_overrides` -- parameter changes addressed by element name
  (``"<body>.mass"``, ``"<body>.volume"``, ``"<joint>.damping"``, ``"<actuator>.forcerange"``,
  ``"water.density"``...; :data:`OVERRIDE_FIELDS`), applied to the MjSpec before compiling, with
  errors that name the element and suggest close names. ``vehicle`` names the robot's vehicle
  whatever its body is called (``vehicle.added_mass``: the body on the free joint, or a planar
  robot's base). A value is a number or list (absolute) or a factor ``"x1.3"`` that multiplies
  the model's own value (every entry of a vector).
* :func:`compile_robot_spec` -- load, override, edit, compile;
* :class:`Payload` -- a point mass welded to a site, appearing at a time.

Where the files are: :mod:`uvms_mj.plant.files`; the named layout and initial states:
:mod:`uvms_mj.plant.layout`; the plant: :mod:`uvms_mj.plant.plant`.
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import mujoco
import numpy as np

from uvms_mj.plant import params as _params
from uvms_mj.plant.errors import ParameterError
from uvms_mj.plant.params import read_params
from uvms_mj.physics import model as _pm

__all__ = ["OVERRIDE_FIELDS", "ROLES", "Payload", "add_hydro_instance", "apply_model_overrides", "apply_overrides", "compile_robot_spec",
           "factor_of", "resolve_role"]

#: Roles an override key may start with instead of an element name: the vehicle's body, every
#: thruster (site actuator) at once.
ROLES = ("vehicle", "thrusters")

#: Fields of the ``thrusters`` role: {field: (what, size)}.
THRUSTER_FIELDS = {
    "tau": ("first-order lag time constant [s] (uvms.thruster tau; a filter actuator's dynprm)", 1),
    "dead_zone": ("[low, high] command band giving no thrust (uvms.thruster dead_zone, command units)", 2),
    "forcerange": ("[min, max] thrust [N] (every thruster's forcerange)", 2),
}

#: Override fields by element kind -> {field: (what, expected shape or None for a string)}.
OVERRIDE_FIELDS: dict[str, dict[str, tuple[str, int | None]]] = {
    "body": {
        "mass": ("body mass [kg]", 1),
        "inertia": ("principal moments of inertia [kg m^2] (diaginertia)", 3),
        "ipos": ("centre of mass in the body frame [m]", 3),
        "volume": ("displaced volume [m^3] (uvms.hydro)", 1),
        "cob": ("centre of buoyancy, body frame [m] (uvms.hydro)", 3),
        "added_mass": ("6x6 added mass: 6, 21 or 36 numbers (uvms.hydro)", -1),
        "linear_damping": ("6 linear damping coefficients (uvms.hydro)", 6),
        "quadratic_damping": ("6 quadratic damping coefficients (uvms.hydro)", 6),
    },
    "joint": {
        "damping": ("joint damping [N m s/rad]", 1),
        "armature": ("armature [kg m^2]", 1),
        "frictionloss": ("dry friction [N m]", 1),
        "range": ("[min, max] [rad]", 2),
    },
    "actuator": {
        "forcerange": ("[min, max] [N or N m]", 2),
        "ctrlrange": ("[min, max] (command units)", 2),
    },
    "water": {
        "density": ("water density [kg/m^3]", 1),
    },
}
_HYDRO_FIELDS = ("volume", "cob", "added_mass", "linear_damping", "quadratic_damping")


# --------------------------------------------------------------------------- overrides


def _elements(spec: mujoco.MjSpec) -> dict[str, list[str]]:
    return {
        "body": [b.name for b in spec.bodies if b.name and b.name != "world"],
        "joint": [j.name for j in spec.joints if j.name],
        "actuator": [a.name for a in spec.actuators if a.name],
        "water": ["water"],
    }


#: The largest magnitude an override value may have (ours: 1e9 in SI units -- beyond any mass,
#: inertia, damping or force of an underwater robot; 1e308 passed validation and then made the
#: first step non-finite).
OVERRIDE_MAX = 1e9
#: The smallest non-zero magnitude an override value may have (ours, as the scenario's SIZE_MIN: 1e-300 kg passed
#: and ran as if massless; MuJoCo's own floor for masses and inertias is mjMINVAL = 1e-15).
OVERRIDE_MIN = 1e-9
#: The fields OVERRIDE_MIN applies to: scales whose tiny non-zero value makes no body (a mass, an inertia,
#: a volume, a density) or divides (a time constant tau). A position, a centre of buoyancy, a range or a
#: damping coefficient may be as small as it likes: an identified cob of 1e-12 m or a roll damping of
#: 1e-10 N m s/rad is a fit that reached zero (sim2real identification, bound 0).
SCALE_FIELDS = frozenset({"mass", "inertia", "volume", "density", "tau"})


def _numbers(key: str, value: Any, n: int | None, what: str) -> np.ndarray:
    try:
        arr = np.atleast_1d(np.asarray(value, dtype=float)) if not isinstance(value, (str, bool, dict)) else None
    except (TypeError, ValueError, OverflowError):
        arr = None
    if arr is None or arr.ndim != 1 or not np.all(np.isfinite(arr)):
        raise ParameterError(f"{key} = {value!r}: expected {what}")
    if np.any(np.abs(arr) > OVERRIDE_MAX):
        raise ParameterError(f"{key} = {value!r}: |value| must be <= {OVERRIDE_MAX:g} ({what})")
    if key.rpartition(".")[2] in SCALE_FIELDS and np.any((arr != 0) & (np.abs(arr) < OVERRIDE_MIN)):
        raise ParameterError(f"{key} = {value!r}: each value must be 0 or at least {OVERRIDE_MIN:g} in magnitude "
                             f"({what})")
    if n is not None and n > 0 and arr.size != n:
        raise ParameterError(f"{key} = {value!r}: expected {n} number{'s' if n > 1 else ''} ({what})")
    if n == -1 and arr.size not in (6, 21, 36):
        raise ParameterError(f"{key} = {value!r}: expected 6, 21 or 36 numbers ({what})")
    return arr


def split_key(key: str, elements: Mapping[str, Sequence[str]]) -> tuple[str, str, str]:
    """(kind, element name, field) of an override key ``"<name>.<field>"`` (names may contain
    dots: the field is the part after the last dot).

    Raises:
        ParameterError: unknown element or field, with a did-you-mean suggestion.
    """
    if not isinstance(key, str) or "." not in key:
        raise ParameterError(f"override {key!r}: expected '<element name>.<field>', e.g. 'bluerov2.mass'")
    name, _, fld = key.rpartition(".")
    kinds = [k for k, names in elements.items() if name in names]
    if not kinds:
        every = [n for names in elements.values() for n in names]
        close = difflib.get_close_matches(name, every, n=1, cutoff=0.6)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise ParameterError(f"override {key!r}: the model has no body, joint or actuator named {name!r}{hint}")
    for kind in kinds:
        if fld in OVERRIDE_FIELDS[kind]:
            return kind, name, fld
    allowed = sorted({f for k in kinds for f in OVERRIDE_FIELDS[k]})
    close = difflib.get_close_matches(fld, allowed, n=1, cutoff=0.6)
    hint = f" (did you mean {close[0]!r}?)" if close else ""
    raise ParameterError(f"override {key!r}: unknown field {fld!r} for {'/'.join(kinds)} {name!r}{hint}; "
                         f"allowed: {', '.join(allowed)}")


def vehicle_body(spec: mujoco.MjSpec) -> str:
    """The name of the robot's vehicle body: the body on the free joint, else (a planar robot)
    the first child of the world that carries joints.

    Raises:
        ParameterError: no such body."""
    free = [j for j in spec.joints if j.type == mujoco.mjtJoint.mjJNT_FREE]
    if free:
        return free[0].parent.name
    for b in spec.worldbody.bodies:
        if b.joints:
            return b.name
    raise ParameterError("the model has no vehicle (no body on a free joint, no child of the world with joints)")


def resolve_role(spec: mujoco.MjSpec, key: str) -> str:
    """``key`` with a leading role (:data:`ROLES`: ``vehicle.``) replaced by the element's name."""
    if isinstance(key, str):
        head, dot, rest = key.partition(".")
        if dot and head == "vehicle" and spec.body("vehicle") is None:
            return f"{vehicle_body(spec)}.{rest}"
    return key


def _thrusters_role(spec: mujoco.MjSpec, key: str, value: Any) -> None:
    """``thrusters.<field>`` (:data:`THRUSTER_FIELDS`) on every thruster actuator."""
    fld = key.partition(".")[2]
    if fld not in THRUSTER_FIELDS:
        close = difflib.get_close_matches(fld, list(THRUSTER_FIELDS), n=1, cutoff=0.6)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise ParameterError(f"override {key!r}: unknown field {fld!r} of the thrusters{hint}; allowed: "
                             f"{', '.join(THRUSTER_FIELDS)}")
    what, n = THRUSTER_FIELDS[fld]
    if factor_of(value) is not None:
        raise ParameterError(f"override {key!r} = {value!r}: give an absolute value for the thrusters ({what})")
    v = _numbers(key, value, n, what)
    if fld == "tau" and not v[0] >= 0:
        raise ParameterError(f"{key} = {value!r}: must be >= 0 s")
    if n == 2 and not v[0] <= v[1]:
        raise ParameterError(f"{key} = {value!r}: must satisfy min <= max")
    thr = [a for a in spec.actuators if a.trntype == mujoco.mjtTrn.mjTRN_SITE]
    if not thr:
        raise ParameterError(f"override {key!r}: the model has no thrusters (site actuators)")
    instances = {p.name: p for p in spec.plugins if p.plugin_name == "uvms.thruster" and p.name}
    done: set[str] = set()
    for a in thr:
        if fld == "forcerange":
            a.forcerange = v
            a.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
            continue
        inst = instances.get(a.plugin.name) if a.plugin.name else None
        own = inst is None and a.plugin.active and a.plugin.plugin_name == "uvms.thruster"
        if (inst is not None or own) and fld == "tau":
            # uvms.thruster: tau = 0 is a static thrust (no lag state: actdim 0), tau > 0 a lag
            # state (actdim 1) -- the plugin refuses any other pairing
            a.actdim = 0 if v[0] == 0 else 1
        if inst is not None:
            if inst.name not in done:
                inst.config = {**inst.config, fld: _pm.fmt(v)}
                done.add(inst.name)
        elif own:
            a.plugin.config = {**a.plugin.config, fld: _pm.fmt(v)}
        elif fld == "tau" and a.dyntype == mujoco.mjtDyn.mjDYN_FILTER:
            prm = list(a.dynprm)
            prm[0] = float(v[0])
            a.dynprm = prm
        else:
            raise ParameterError(f"override {key!r}: thruster {a.name!r} is not a uvms.thruster plugin actuator "
                                 f"(a plain actuator has no {fld}; see docs/hydrodynamics.md)")


def factor_of(value: Any) -> float | None:
    """The factor of a relative override value ``"x1.3"`` (also ``"*1.3"``), else None.

    Raises:
        ParameterError: a string that starts like a factor but is not a finite number >= 0."""
    if not isinstance(value, str) or not value[:1] in ("x", "*", "\u00d7"):
        return None
    try:
        f = float(value[1:])
    except ValueError:
        raise ParameterError(f"{value!r}: a factor is 'x' followed by a number, e.g. 'x1.3'") from None
    if not (np.isfinite(f) and f >= 0):
        raise ParameterError(f"{value!r}: the factor must be finite and >= 0")
    return f


def _model_value(spec: mujoco.MjSpec, key: str, kind: str, name: str, fld: str) -> np.ndarray:
    """The model's own value of an override field (what a factor multiplies): read from the
    compiled model (inertias MuJoCo infers from geoms included) or the plugin's attributes."""
    if kind == "water" or (kind == "body" and fld in _HYDRO_FIELDS):
        cfg = _pm.water_config(spec) if kind == "water" else _pm.body_config(spec, name)
        text = cfg.get(fld)
        if text is None:
            raise ParameterError(f"override {key!r}: the model gives no {fld} to scale (set an absolute value)")
        return np.array([float(x) for x in str(text).split()])
    m = _pm.compile_spec(spec, source="model")  # (compiling leaves the spec as it is)
    obj = {"body": mujoco.mjtObj.mjOBJ_BODY, "joint": mujoco.mjtObj.mjOBJ_JOINT,
           "actuator": mujoco.mjtObj.mjOBJ_ACTUATOR}[kind]
    i = mujoco.mj_name2id(m, obj, name)
    arr = {("body", "mass"): m.body_mass, ("body", "inertia"): m.body_inertia, ("body", "ipos"): m.body_ipos,
           ("joint", "range"): m.jnt_range, ("actuator", "forcerange"): m.actuator_forcerange,
           ("actuator", "ctrlrange"): m.actuator_ctrlrange}.get((kind, fld))
    if arr is None:  # joint damping, armature, frictionloss: per dof
        arr = {"damping": m.dof_damping, "armature": m.dof_armature, "frictionloss": m.dof_frictionloss}[fld]
        i = int(m.jnt_dofadr[i])
    return np.atleast_1d(np.array(arr[i], dtype=float))


def apply_overrides(spec: mujoco.MjSpec, overrides: Mapping[str, Any]) -> None:
    """Apply ``{"<element>.<field>": value}`` to an MjSpec (before compiling); see
    :data:`OVERRIDE_FIELDS` for the fields of bodies, joints, actuators and the water.

    Raises:
        ParameterError: unknown element or field, or a value of the wrong size or sign.
    """
    elements = _elements(spec)
    for key, value in overrides.items():
        key = resolve_role(spec, key)
        if isinstance(key, str) and key.startswith("thrusters.") and "thrusters" not in elements["actuator"]:
            _thrusters_role(spec, key, value)
            continue
        kind, name, fld = split_key(key, elements)
        what, n = OVERRIDE_FIELDS[kind][fld]
        f = factor_of(value)
        if f is not None:
            value = f * _model_value(spec, key, kind, name, fld)
        v = _numbers(key, value, n, what)
        if kind == "water":
            if not v[0] > 0:
                raise ParameterError(f"{key} = {value!r}: must be > 0")
            _pm.set_water(spec, **{fld: _pm.fmt(v)})
        elif kind == "body":
            b = spec.body(name)
            if fld in _HYDRO_FIELDS:
                if fld == "volume" and v[0] < 0:
                    raise ParameterError(f"{key} = {value!r}: must be >= 0")
                _pm.set_body(spec, name, **{fld: _pm.fmt(v)})
            elif fld == "mass":
                if not v[0] > 0:
                    raise ParameterError(f"{key} = {value!r}: must be > 0 kg")
                b.mass = float(v[0])
                b.explicitinertial = True
            elif fld == "inertia":
                if not np.all(v > 0):
                    raise ParameterError(f"{key} = {value!r}: must be > 0")
                b.inertia = v
                b.explicitinertial = True
            else:
                b.ipos = v
                b.explicitinertial = True
        elif kind == "joint":
            j = spec.joint(name)
            if fld == "range":
                if not v[0] < v[1]:
                    raise ParameterError(f"{key} = {value!r}: must satisfy min < max")
                j.range = v
            else:
                if v[0] < 0:
                    raise ParameterError(f"{key} = {value!r}: must be >= 0")
                if fld == "damping":
                    j.damping = np.full(np.shape(j.damping), v[0]) if np.ndim(j.damping) else float(v[0])
                else:
                    setattr(j, fld, float(v[0]))
        else:
            a = spec.actuator(name)
            if not v[0] < v[1]:
                raise ParameterError(f"{key} = {value!r}: must satisfy min < max")
            setattr(a, fld, v)
            setattr(a, "forcelimited" if fld == "forcerange" else "ctrllimited", mujoco.mjtLimited.mjLIMITED_TRUE)


def _is_planar_spec(spec: mujoco.MjSpec) -> bool:
    """No free joint: a planar base (the paper's parameter vocabulary applies to its overrides)."""
    return not any(j.type == mujoco.mjtJoint.mjJNT_FREE for j in spec.joints)


def _planar_key(key: str) -> bool:
    """A key of the paper robot's parameter vocabulary (:data:`uvms_mj.plant.params.OVERRIDE_KEYS`)."""
    head, _, fld = str(key).partition(".")
    return (key == "water_density" or key.startswith("thrusters.")
            or (head in _params.HYDRO_BODIES and fld in ("mass", "inertia", "added_mass", "drag_coef", "volume", "cob")))


def apply_model_overrides(spec: mujoco.MjSpec, overrides: Mapping[str, Any]) -> None:
    """Parameter overrides of any robot, in order: on a planar robot (the paper's) the keys of
    its parameter vocabulary (:data:`uvms_mj.plant.params.OVERRIDE_KEYS`: ``base.added_mass`` =
    [m_Ax, m_Ay, I_A], ``thrusters.tau``...) go to :func:`uvms_mj.plant.params.apply_planar_overrides`;
    every other key is by element name (:func:`apply_overrides`: bodies,
    joints, actuators, the water, the ``vehicle`` role, factors).

    Raises:
        ParameterError: as the two functions."""
    planar = _is_planar_spec(spec)
    for key, value in overrides.items():
        key = resolve_role(spec, key)
        if planar and _planar_key(key):
            f = factor_of(value)
            if f is not None:
                value = (f * _planar_value(spec, key)).tolist()
            _params.apply_planar_overrides(spec, {key: value})
        else:
            apply_overrides(spec, {key: value})


def _planar_value(spec: mujoco.MjSpec, key: str) -> np.ndarray:
    """The paper robot's own value of a parameter key (what a factor multiplies)."""
    p = read_params(_pm.compile_spec(spec, source="model"))  # (compiling leaves the spec as it is)
    head, _, fld = key.partition(".")
    if key == "water_density":
        return np.array([p.rho])
    if head == "thrusters":
        t = p.thrusters[0]
        return np.atleast_1d(np.array({"tau": t.tau, "force_range": t.force_range, "dead_zone": p.dead_zone}[fld],
                                      dtype=float))
    b = p.body(head)
    vals = {"mass": b.mass, "inertia": b.inertia, "added_mass": [b.added_mass[0], b.added_mass[1], b.added_inertia],
            "drag_coef": b.drag_coef, "volume": b.volume, "cob": b.cob[:2]}
    return np.atleast_1d(np.array(vals[fld], dtype=float))


def compile_robot_spec(path: str | Path, overrides: Mapping[str, Any] | None = None, *,
                       native: bool | None = None, edit=None) -> mujoco.MjModel:
    """Load a robot file, apply named overrides (and ``edit(spec)``), compile.

    Raises:
        ParameterError: a missing file, a bad override or a model that does not compile.
    """
    path = Path(path)
    try:
        spec = _pm.load_spec(path)
        if overrides:
            apply_model_overrides(spec, overrides)
        if edit is not None:
            edit(spec)
        return _pm.compile_spec(spec, native=native, source=path.name)
    except _pm.ModelError as exc:
        raise ParameterError(str(exc)) from None


# --------------------------------------------------------------------------- payload


def add_hydro_instance(spec: mujoco.MjSpec, body, name: str, config: dict[str, str]) -> None:
    """Give a body added to ``spec`` at run time its own ``uvms.hydro`` instance ``name`` with the
    attributes ``config`` (strings, as in the MJCF), like ``<plugin instance="name"/>`` in a body.

    A MuJoCo 3.17 fact (docs/mujoco-facts.md): assigning ``body.plugin.config`` on a body made by
    ``add_body`` crashes the Python process; a top-level instance (``spec.add_plugin``) referenced
    by name from the body compiles and applies its attributes."""
    p = spec.add_plugin()
    p.name, p.plugin_name, p.active = name, "uvms.hydro", True
    p.config = dict(config)
    body.plugin.name = name
    body.plugin.plugin_name = "uvms.hydro"
    body.plugin.active = True



@dataclass(frozen=True)
class Payload:
    """A payload picked up during a run: a point mass welded to a site of the robot (the
    end-effector site by default) whose mass appears at time ``t`` (before: 1e-9 kg).

    The plant adds it as a welded child body ``payload`` of the site's body (MjSpec edit before
    compiling) and, at the first control sample at or after ``t``, sets its mass and inertia
    (a solid sphere of ``radius``) in the MjModel and the ancestors' subtree masses: MuJoCo
    recomputes the mass matrix and gravity from them every step. The payload displaces no water
    (dense; ``volume`` adds buoyancy at its centre). The controller's nominal model never has it.

    Attributes:
        mass: [kg] (> 0); t: pick-up time [s] (>= 0); site: the site it is welded to (None: tip);
        offset: its centre in the site's frame [m]; radius: for its inertia [m]; volume: [m^3].
    """

    mass: float
    t: float = 0.0
    site: str | None = None
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    radius: float = 0.02
    volume: float = 0.0

    def add_to(self, spec: mujoco.MjSpec, site_name: str) -> None:
        site = spec.site(site_name)
        if site is None:
            raise ParameterError(f"payload.site = {site_name!r}: no such site")
        parent = site.parent
        R = np.zeros(9)
        q = np.asarray(site.quat, dtype=float)
        mujoco.mju_quat2Mat(R, q / np.linalg.norm(q))
        pos = np.asarray(site.pos, dtype=float) + R.reshape(3, 3) @ np.asarray(self.offset, dtype=float)
        b = parent.add_body(name="payload", pos=pos)
        b.mass = 1e-9
        b.inertia = [1e-12, 1e-12, 1e-12]
        b.explicitinertial = True
        if self.volume > 0:
            add_hydro_instance(spec, b, "payload_hydro", {"volume": _pm.fmt([self.volume])})

    def apply(self, m: mujoco.MjModel) -> None:
        """Give the payload body its mass (in the compiled model)."""
        b = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "payload")
        dm = self.mass - float(m.body_mass[b])
        m.body_mass[b] = self.mass
        m.body_inertia[b] = 0.4 * self.mass * self.radius ** 2
        a = b
        while a > 0:
            m.body_subtreemass[a] += dm
            a = int(m.body_parentid[a])
        m.body_subtreemass[0] += dm
