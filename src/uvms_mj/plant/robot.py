"""Any robot: built-in names, the named layout of a model, overrides by name, initial states.

The paper's planar robot has its own plant (:class:`uvms_mj.plant.plant.Plant`, numbers fixed by the
reproduction). Every other robot -- any MJCF file whose vehicle is a body on a free joint,
carrying its hydrodynamics as ``uvms.water`` / ``uvms.hydro`` plugin attributes and its
thrusters as site actuators (``docs/hydrodynamics.md``) -- goes through :class:`RobotPlant`,
which gives the sampled loop, the recorder and the renderer the same interface by name:

* :func:`robot_path` -- a built-in name (:data:`BUILTIN_ROBOTS`) or a path to an MJCF file;
* :class:`Layout` -- the named pieces of a compiled model: the vehicle body and its free joint,
  the arm joints, the thrusters (site actuators, in model order), the joint actuators, the
  end-effector site;
* :func:`apply_overrides` -- parameter changes addressed by element name
  (``"<body>.mass"``, ``"<body>.volume"``, ``"<joint>.damping"``, ``"<actuator>.forcerange"``,
  ``"water.density"``...; :data:`OVERRIDE_FIELDS`), applied to the MjSpec before compiling, with
  errors that name the element and suggest close names;
* :class:`InitialState` -- the base pose (position world [m], orientation as a unit quaternion
  w x y z or roll/pitch/yaw), joint angles by name, velocities; applied to ``qpos`` / ``qvel``.

State layout (MuJoCo's free joint): ``qpos`` = (x, y, z [m] world, qw, qx, qy, qz, joint angles
[rad]); ``qvel`` = (linear velocity [m/s] WORLD frame, angular velocity [rad/s] BODY frame, joint
rates). Roll/pitch/yaw are the z-y-x (yaw, then pitch, then roll) Tait-Bryan angles of the
vehicle's body axes relative to the world (z up): R = Rz(yaw) Ry(pitch) Rx(roll).
"""

from __future__ import annotations

import difflib
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

import mujoco
import numpy as np

from uvms_mj.planar.hydro import HydroTerms
from uvms_mj.plant.params import ParameterError
from uvms_mj.physics import model as _pm
from uvms_mj.rotations import quat_from_rpy, rpy_from_quat  # noqa: F401  (part of this module's API)
from uvms_mj.plant.plant import (
    Plant,
    _finite,
    _resolve_backend,
    install_mujoco_warning_handler,
    models_dir,
    set_integration,
    water_terms,
)
from uvms_mj.physics.thrusters import CurveInverse, thruster_actuators, thruster_curves

__all__ = [
    "BUILTIN_ROBOTS",
    "OVERRIDE_FIELDS",
    "InitialState",
    "Layout",
    "Payload",
    "RobotPlant",
    "apply_overrides",
    "compile_robot_spec",
    "quat_from_rpy",
    "robot_path",
    "rpy_from_quat",
]

#: Built-in robots: name -> file in ``models/``, one folder per robot (``models/README.md``;
#: "paper" is the planar robot of the paper, with its scene, and runs on
#: :class:`uvms_mj.plant.plant.Plant`).
BUILTIN_ROBOTS: dict[str, str] = {
    "paper": "paper/scene.xml",
    "bluerov2_heavy": "bluerov2_heavy/bluerov2_heavy.xml",
    "bluerov2_alpha": "bluerov2_alpha/bluerov2_alpha.xml",
    "hinsdale2023": "hinsdale2023/hinsdale2023.xml",
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


def robot_path(robot: str | Path, base_dir: str | Path | None = None) -> Path:
    """The MJCF file of a robot: a built-in name (:data:`BUILTIN_ROBOTS`) or a path (relative
    paths are taken relative to ``base_dir``, e.g. the scenario file's folder, then to the
    current folder).

    Raises:
        ParameterError: not a built-in name and no such file (the message lists the built-ins).
    """
    key = str(robot)
    if key in BUILTIN_ROBOTS:
        return models_dir() / BUILTIN_ROBOTS[key]
    p = Path(key).expanduser()
    cands = [p] if p.is_absolute() else ([Path(base_dir) / p] if base_dir is not None else []) + [p]
    for c in cands:
        if c.is_file():
            return c.resolve()
    close = difflib.get_close_matches(key, list(BUILTIN_ROBOTS), n=1, cutoff=0.6)
    hint = f" (did you mean {close[0]!r}?)" if close else ""
    raise ParameterError(f"robot = {key!r}: neither a built-in robot{hint} ({', '.join(BUILTIN_ROBOTS)}) "
                         "nor an existing MJCF file")


# --------------------------------------------------------------------------- layout


def _name(m: mujoco.MjModel, obj, i: int) -> str:
    return mujoco.mj_id2name(m, obj, i) or f"{obj.name.removeprefix('mjOBJ_').lower()}{i}"


@dataclass(frozen=True)
class Layout:
    """The named pieces of a compiled robot model (ids and addresses into MuJoCo's arrays).

    Attributes:
        base_body, base_name: the vehicle: the body carrying the free joint (or, for a planar
            model, the base joints).
        base_qadr, base_dadr: its free joint's ``qpos`` (7) and ``qvel`` (6) addresses (first
            addresses for joint bases).
        base_free: the vehicle is on a free joint; base_dofs: its dofs (6, or one per joint).
        joints: the other joints (hinge/slide), model order: names, ``qpos`` and ``qvel`` addresses.
        thrusters: thruster actuator names (site transmission, model order) and ids.
        motors: joint actuators: names, ids, and the joint each drives.
        tip_site: the end-effector site id (-1: none) and its name.
        bodies: every body but the world: names (for ``/tf``).
    """

    base_body: int
    base_name: str
    base_qadr: int
    base_dadr: int
    joint_names: tuple[str, ...]
    joint_qadr: np.ndarray
    joint_dadr: np.ndarray
    thruster_names: tuple[str, ...]
    thruster_ids: np.ndarray
    motor_names: tuple[str, ...]
    motor_ids: np.ndarray
    motor_joints: tuple[str, ...]
    tip_site: int
    tip_name: str
    body_names: tuple[str, ...] = field(default=())
    base_free: bool = True
    base_dofs: np.ndarray = field(default_factory=lambda: np.arange(6))

    @classmethod
    def of(cls, m: mujoco.MjModel, tip_site: str | None = None, allow_planar: bool = False) -> "Layout":
        """The layout of ``m``; ``tip_site``: the end-effector site (default: the first site
        whose name ends in "tip", or none).

        The vehicle is the body carrying a free joint; without one (``allow_planar``), the first
        child of the world that carries joints, with all its joints (slides and hinges, e.g. the
        paper's planar base: slide x, slide y, hinge z).

        Raises:
            ParameterError: no free joint (and not ``allow_planar``), more than one, or an
                unknown ``tip_site``.
        """
        free = [j for j in range(m.njnt) if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE]
        if len(free) > 1 or (not free and not allow_planar):
            raise ParameterError(f"the robot model must have exactly one free joint (the vehicle), it has {len(free)}")
        if free:
            base_joints = [free[0]]
        else:
            roots = [b for b in range(1, m.nbody) if m.body_parentid[b] == 0 and m.body_jntnum[b] > 0]
            if not roots:
                raise ParameterError("the robot model has no vehicle: no body on a free joint nor a child of the "
                                     "world with joints")
            b0 = roots[0]
            base_joints = list(range(m.body_jntadr[b0], m.body_jntadr[b0] + m.body_jntnum[b0]))
        jf = base_joints[0]
        others = [j for j in range(m.njnt) if j not in base_joints]
        for j in others:
            if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_BALL:
                raise ParameterError(f"joint {_name(m, mujoco.mjtObj.mjOBJ_JOINT, j)!r}: ball joints are not "
                                     "supported (use hinges)")
        thr = thruster_actuators(m) if any(int(m.actuator_trntype[a]) == int(mujoco.mjtTrn.mjTRN_SITE)
                                           for a in range(m.nu)) else []
        mot = [a for a in range(m.nu) if int(m.actuator_trntype[a]) == int(mujoco.mjtTrn.mjTRN_JOINT)]
        site_names = [_name(m, mujoco.mjtObj.mjOBJ_SITE, s) for s in range(m.nsite)]
        if tip_site is None:
            tips = [i for i, n in enumerate(site_names) if n.endswith("tip")]
            tip = tips[0] if tips else -1
        else:
            tip = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, tip_site)
            if tip < 0:
                close = difflib.get_close_matches(tip_site, site_names, n=1, cutoff=0.6)
                hint = f" (did you mean {close[0]!r}?)" if close else ""
                raise ParameterError(f"tip_site = {tip_site!r}: no site of that name{hint}")
        J = mujoco.mjtObj.mjOBJ_JOINT
        A = mujoco.mjtObj.mjOBJ_ACTUATOR
        base_dofs = [int(m.jnt_dofadr[j]) + i for j in base_joints
                     for i in range(6 if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE else 1)]
        return cls(
            base_free=bool(free), base_dofs=np.array(base_dofs, dtype=int),
            base_body=int(m.jnt_bodyid[jf]), base_name=_name(m, mujoco.mjtObj.mjOBJ_BODY, int(m.jnt_bodyid[jf])),
            base_qadr=int(m.jnt_qposadr[jf]), base_dadr=int(m.jnt_dofadr[jf]),
            joint_names=tuple(_name(m, J, j) for j in others),
            joint_qadr=np.array([m.jnt_qposadr[j] for j in others], dtype=int),
            joint_dadr=np.array([m.jnt_dofadr[j] for j in others], dtype=int),
            thruster_names=tuple(_name(m, A, a) for a in thr), thruster_ids=np.array(thr, dtype=int),
            motor_names=tuple(_name(m, A, a) for a in mot), motor_ids=np.array(mot, dtype=int),
            motor_joints=tuple(_name(m, J, int(m.actuator_trnid[a][0])) for a in mot),
            tip_site=int(tip), tip_name=site_names[tip] if tip >= 0 else "",
            body_names=tuple(_name(m, mujoco.mjtObj.mjOBJ_BODY, b) for b in range(1, m.nbody)),
        )

    def describe(self) -> dict:
        """JSON-able summary (for log metadata)."""
        return {"base": self.base_name, "base_qpos": self.base_qadr, "base_qvel": self.base_dadr,
                "joint_qpos": self.joint_qadr.tolist(), "joint_qvel": self.joint_dadr.tolist(),
                "joints": list(self.joint_names), "thrusters": list(self.thruster_names),
                "motors": list(self.motor_names), "motor_joints": list(self.motor_joints),
                "tip_site": self.tip_name, "bodies": list(self.body_names)}


# --------------------------------------------------------------------------- overrides


def _elements(spec: mujoco.MjSpec) -> dict[str, list[str]]:
    return {
        "body": [b.name for b in spec.bodies if b.name and b.name != "world"],
        "joint": [j.name for j in spec.joints if j.name],
        "actuator": [a.name for a in spec.actuators if a.name],
        "water": ["water"],
    }


def _numbers(key: str, value: Any, n: int | None, what: str) -> np.ndarray:
    arr = np.atleast_1d(np.asarray(value, dtype=float)) if not isinstance(value, (str, bool)) else None
    if arr is None or arr.ndim != 1 or not np.all(np.isfinite(arr)):
        raise ParameterError(f"{key} = {value!r}: expected {what}")
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


def apply_overrides(spec: mujoco.MjSpec, overrides: Mapping[str, Any]) -> None:
    """Apply ``{"<element>.<field>": value}`` to an MjSpec (before compiling); see
    :data:`OVERRIDE_FIELDS` for the fields of bodies, joints, actuators and the water.

    Raises:
        ParameterError: unknown element or field, or a value of the wrong size or sign.
    """
    elements = _elements(spec)
    for key, value in overrides.items():
        kind, name, fld = split_key(key, elements)
        what, n = OVERRIDE_FIELDS[kind][fld]
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
            apply_overrides(spec, overrides)
        if edit is not None:
            edit(spec)
        return _pm.compile_spec(spec, native=native, source=path.name)
    except _pm.ModelError as exc:
        raise ParameterError(str(exc)) from None


# --------------------------------------------------------------------------- initial state


@dataclass(frozen=True)
class InitialState:
    """An initial state by name (every field optional: None keeps the model's ``qpos0`` /
    keyframe value).

    Attributes:
        position: vehicle origin, world [m] (3).
        quat: vehicle orientation, unit quaternion (w, x, y, z) (normalised here).
        joints: joint name -> angle [rad] (or [m] for a slide).
        linear_velocity: vehicle origin velocity, WORLD frame [m/s] (3).
        angular_velocity: vehicle angular velocity, BODY frame [rad/s] (3).
        joint_velocities: joint name -> rate [rad/s].
        keyframe: a model keyframe to start from before the fields above.
    """

    position: tuple[float, ...] | None = None
    quat: tuple[float, ...] | None = None
    joints: Mapping[str, float] = field(default_factory=dict)
    linear_velocity: tuple[float, ...] | None = None
    angular_velocity: tuple[float, ...] | None = None
    joint_velocities: Mapping[str, float] = field(default_factory=dict)
    keyframe: str | None = None

    def apply(self, m: mujoco.MjModel, d: mujoco.MjData, layout: Layout) -> None:
        """Write the state into ``d`` (after a reset to ``qpos0`` or the keyframe).

        Raises:
            ParameterError: unknown keyframe or joint name (did-you-mean), wrong sizes, a zero
                quaternion, a joint angle outside a limited joint's range.
        """
        if self.keyframe is not None:
            k = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, self.keyframe)
            if k < 0:
                keys = [_name(m, mujoco.mjtObj.mjOBJ_KEY, i) for i in range(m.nkey)]
                raise ParameterError(f"initial.keyframe = {self.keyframe!r}: no such keyframe; "
                                     f"the model has: {', '.join(keys) or 'none'}")
            mujoco.mj_resetDataKeyframe(m, d, k)
        else:
            mujoco.mj_resetData(m, d)
        qa, da = layout.base_qadr, layout.base_dadr
        for name, val, n, arr, adr in (("position", self.position, 3, d.qpos, qa),
                                       ("quat", self.quat, 4, d.qpos, qa + 3),
                                       ("linear_velocity", self.linear_velocity, 3, d.qvel, da),
                                       ("angular_velocity", self.angular_velocity, 3, d.qvel, da + 3)):
            if val is None:
                continue
            v = np.asarray(val, dtype=float).ravel()
            if v.shape != (n,) or not np.all(np.isfinite(v)):
                raise ParameterError(f"initial.{name} = {list(val)!r}: expected {n} finite numbers")
            if name == "quat":
                nv = float(np.linalg.norm(v))
                if nv < 1e-9:
                    raise ParameterError(f"initial.quat = {list(val)!r}: must not be zero")
                v = v / nv
            arr[adr:adr + n] = v
        names = list(layout.joint_names)
        for label, values, arr, adrs in (("joints", self.joints, d.qpos, layout.joint_qadr),
                                         ("joint_velocities", self.joint_velocities, d.qvel, layout.joint_dadr)):
            for jn, val in values.items():
                if jn not in names:
                    close = difflib.get_close_matches(str(jn), names, n=1, cutoff=0.6)
                    hint = f" (did you mean {close[0]!r}?)" if close else ""
                    raise ParameterError(f"initial.{label}.{jn}: no joint of that name{hint}; joints: "
                                         f"{', '.join(names) or 'none'}")
                x = float(val)
                if not math.isfinite(x):
                    raise ParameterError(f"initial.{label}.{jn} = {val!r}: must be finite")
                j = names.index(jn)
                if label == "joints":
                    jid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, jn)
                    lo, hi = m.jnt_range[jid]
                    if m.jnt_limited[jid] and not lo - 1e-9 <= x <= hi + 1e-9:
                        raise ParameterError(f"initial.joints.{jn} = {x:.6g} rad is outside the joint's range "
                                             f"[{lo:.6g}, {hi:.6g}] rad")
                arr[adrs[j]] = x


# --------------------------------------------------------------------------- payload


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
            b.plugin.plugin_name = "uvms.hydro"
            b.plugin.active = True
            b.plugin.config = {"volume": _pm.fmt([self.volume])}

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


# --------------------------------------------------------------------------- plant


class RobotPlant(Plant):
    """Any floating robot (one free joint) in water, through the uvms plugins.

    The same interface as the paper's :class:`~uvms_mj.plant.plant.Plant` (``step``, ``q``, ``qd``,
    ``tip_position``, ``thruster_forces``, ``set_thrust``, ``set_joint_torques``, divergence
    detection, ``energy``), by name for any layout (:attr:`layout`).

    Args:
        model: robot name (:data:`BUILTIN_ROBOTS`, not "paper") or MJCF path.
        overrides: ``{"<element>.<field>": value}`` (:func:`apply_overrides`).
        terms: hydrodynamic terms (``added_mass`` "exact" | "off"; ``drag`` "strip" | "off";
            ``buoyancy``); damping and Froude-Krylov are always on.
        gravity: apply gravity (and buoyancy).
        current: uniform water current, world (vx, vy, vz) [m/s]; None: the model's.
        timestep, integrator: override the model's.
        initial: the initial state (:class:`InitialState`); default the model's ``qpos0``.
        tip_site: end-effector site (default: the first site whose name ends in "tip").
        max_speed: runaway threshold on sum |qvel_i|.
        backend: "native" | "python" | "auto" (as Plant).

    Thrusters are commanded in newtons (:meth:`set_thrust`): the plant converts each thrust to
    the actuator's command with the inverse of the model's own thrust curve (as a thruster
    driver with a calibrated lookup table would); thrusts beyond the curve clamp.
    """

    def __init__(
        self,
        model: str | Path,
        *,
        overrides: Mapping[str, Any] | None = None,
        terms: HydroTerms = HydroTerms(),
        gravity: bool = True,
        current: Sequence[float] | None = None,
        timestep: float | None = None,
        integrator: str | None = None,
        initial: InitialState | None = None,
        tip_site: str | None = None,
        max_speed: float = 100.0,
        backend: str | None = None,
        payload: Payload | None = None,
    ) -> None:
        install_mujoco_warning_handler()
        path = robot_path(model)
        if path == models_dir() / BUILTIN_ROBOTS["paper"]:
            raise ParameterError("robot 'paper' runs on uvms_mj.plant.plant.Plant, not RobotPlant")
        if terms.added_mass not in ("exact", "off") or terms.drag not in ("strip", "off"):
            raise ParameterError(f"terms = {terms!r}: RobotPlant supports added_mass exact|off, drag strip|off")
        if not (max_speed > 0):
            raise ParameterError(f"max_speed = {max_speed!r} must be > 0")
        native = _resolve_backend(backend, terms)

        def edit(spec: mujoco.MjSpec) -> None:
            if not gravity:
                spec.option.gravity = [0.0, 0.0, 0.0]
            if current is not None:
                cur = np.asarray(current, dtype=float).ravel()
                if cur.shape != (3,) or not np.all(np.isfinite(cur)):
                    raise ParameterError(f"current = {current!r} must be 3 finite numbers (m/s, world frame)")
                _pm.set_water(spec, current=_pm.fmt(cur))
            _pm.set_water(spec, terms=water_terms(terms))
            if payload is not None:
                site = payload.site or tip_site or next(
                    (x.name for x in spec.sites if x.name and x.name.endswith("tip")), None)
                if site is None:
                    raise ParameterError("payload: the robot has no tip site; give payload.site")
                payload.add_to(spec, site)

        if payload is not None and not (payload.mass > 0 and payload.t >= 0):
            raise ParameterError(f"payload = {payload!r}: mass must be > 0 and t >= 0")
        self.payload = payload
        self.model = compile_robot_spec(path, overrides, native=native, edit=edit)
        self.model_path = path
        m = self.model
        set_integration(m, timestep, integrator)
        self.backend = "native" if native else "python"
        self.hydro_info = _pm.hydro_of(m)
        self.params = None  # the paper robot's RobotParams; none here
        self.terms = terms
        self.dead_zone = False
        self.max_speed = float(max_speed)
        self.layout = Layout.of(m, tip_site)
        self.initial = initial if initial is not None else InitialState()
        lay = self.layout
        self.data = mujoco.MjData(m)
        self._scratch = mujoco.MjData(m)
        self._thr = lay.thruster_ids
        self._mot = lay.motor_ids
        self._thr_act = np.array([m.actuator_actadr[a] for a in self._thr], dtype=int)
        self._thr_lagged = bool(np.all(self._thr_act >= 0)) and len(self._thr) > 0
        self._thr_lo, self._thr_hi = (m.actuator_forcerange[self._thr].T.copy() if len(self._thr)
                                      else (np.zeros(0), np.zeros(0)))
        self._curves = thruster_curves(m) if len(self._thr) else []
        # Thrusters sharing a curve and command range are inverted / evaluated together.
        groups: dict = {}
        for k, (c, a) in enumerate(zip(self._curves, self._thr)):
            rng = tuple(m.actuator_ctrlrange[a]) if m.actuator_ctrllimited[a] else (None, None)
            groups.setdefault((c, rng), []).append(k)
        self._groups = [(np.array(ks), c, CurveInverse(c, *rng)) for (c, rng), ks in groups.items()]
        self._tip = lay.tip_site
        self._body_ids = list(range(1, m.nbody))
        self._diverged = None
        self._serving = {}
        if not native:
            self._serve(self.data)
        self.reset()

    # ---------------------------------------------------------------- state

    def on_sample(self, t: float) -> None:
        """Called by the sampled loop at every control sample (time t): scheduled events
        (the payload's pick-up)."""
        if self.payload is not None and not self._picked and t >= self.payload.t - 1e-12:
            self.payload.apply(self.model)
            self._picked = True
            mujoco.mj_forward(self.model, self.data)

    def reset(self, keyframe: str | None = None) -> None:  # noqa: ARG002 - the initial state decides
        """Reset time, state and actuator states to :attr:`initial`."""
        m, d = self.model, self.data
        if getattr(self, "_picked", False):
            raise ParameterError("reset after the payload was picked up: create a new RobotPlant")
        self._picked = False
        self.initial.apply(m, d, self.layout)
        d.time = 0.0
        self._diverged = None
        served = self._serving.get(d._address)
        if served is not None:
            served.reset(float(d.time))
        mujoco.mj_forward(m, d)

    def set_state(self, qpos: Sequence[float] | None = None, qvel: Sequence[float] | None = None) -> None:  # type: ignore[override]
        """Set ``qpos`` / ``qvel`` (MuJoCo's layout, see the module docstring) and ``mj_forward``."""
        d = self.data
        for name, val, arr in (("qpos", qpos, d.qpos), ("qvel", qvel, d.qvel)):
            if val is None:
                continue
            v = np.asarray(val, dtype=float).ravel()
            if v.shape != arr.shape or not np.all(np.isfinite(v)):
                raise ValueError(f"{name} must be {arr.size} finite numbers")
            arr[:] = v
        mujoco.mj_forward(self.model, d)

    @property
    def base_pose(self) -> np.ndarray:
        """(x, y, z [m] world, qw, qx, qy, qz) of the vehicle (copy)."""
        a = self.layout.base_qadr
        return self.data.qpos[a:a + 7].copy()

    @property
    def joint_angles(self) -> np.ndarray:
        """Arm joint angles [rad] in :attr:`Layout.joint_names` order (copy)."""
        return self.data.qpos[self.layout.joint_qadr].copy()

    @property
    def tip_position(self) -> np.ndarray:
        """End-effector site position, world [m] (3); NaN when the robot has no tip site."""
        if self._tip < 0:
            return np.full(3, np.nan)
        s = self._scratch
        s.qpos[:] = self.data.qpos
        mujoco.mj_kinematics(self.model, s)
        return s.site_xpos[self._tip].copy()

    @property
    def thruster_forces(self) -> np.ndarray:
        """Thrust of each thruster [N] now: the curve at the lagged command, clamped to the
        force range."""
        if not len(self._thr):
            return np.zeros(0)
        u = self.data.act[self._thr_act] if self._thr_lagged else self.data.ctrl[self._thr]
        f = np.empty(u.size)
        for ks, c, _ in self._groups:
            f[ks] = c(u[ks])
        return np.clip(f, self._thr_lo, self._thr_hi)

    @property
    def thruster_commands(self) -> np.ndarray:
        """The actuators' commands (``ctrl``, e.g. normalised voltage), not newtons."""
        return self.data.ctrl[self._thr].copy()

    def thrust_to_ctrl(self, thrust: Sequence[float]) -> np.ndarray:
        """Actuator commands for thrusts [N] (inverse of the model's curve, clamped)."""
        f = np.asarray(thrust, dtype=float).ravel()
        u = np.empty(f.size)
        for ks, _, inv in self._groups:
            u[ks] = inv(f[ks])
        return u

    def warm_start(self, thrust: Sequence[float]) -> None:
        """Start the thrusters' lag states at the commands for ``thrust`` (holding station)."""
        if self._thr_lagged:
            self.data.act[self._thr_act] = self.thrust_to_ctrl(thrust)

    # ---------------------------------------------------------------- inputs

    def set_thrust(self, commands: Sequence[float]) -> None:
        """Command each thruster's thrust [N] (in :attr:`Layout.thruster_names` order)."""
        u = self._thrust_ctrl(commands)
        if u.size:
            self.data.ctrl[self._thr] = u

    def _thrust_ctrl(self, commands: Sequence[float], finite: bool = False) -> np.ndarray:
        c = np.asarray(commands, dtype=float).ravel()
        n = len(self._thr)
        if c.shape != (n,) or not (finite or _finite(c)):
            raise ValueError(f"thruster commands {list(np.ravel(commands))!r} must be {n} finite numbers [N]")
        return self.thrust_to_ctrl(c) if n else c

    def set_joint_torques(self, torques: Sequence[float]) -> None:
        """Command the joint actuators (:attr:`Layout.motor_names` order) [N m]."""
        t = self._torque_ctrl(torques)
        if t.size:
            self.data.ctrl[self._mot] = t

    def _torque_ctrl(self, torques: Sequence[float], finite: bool = False) -> np.ndarray:
        t = np.asarray(torques, dtype=float).ravel()
        n = len(self._mot)
        if t.shape != (n,) or not (finite or _finite(t)):
            raise ValueError(f"joint torques {list(np.ravel(torques))!r} must be {n} finite numbers [N m]")
        return t

    def _io_layout(self) -> tuple:
        # the tip (3 numbers) when there is one; the thrusts through the model's curves, after
        # the commands (they follow them without a lag state)
        return max(self._tip, 0), 3 if self._tip >= 0 else 0, None, None, None

    def mass_matrix(self) -> np.ndarray:
        """Full nv x nv generalized mass matrix at the current state, added mass included."""
        return super().mass_matrix()
