"""Configuration of the `uvms.water` and `uvms.hydro` plugins: parsing and validation.

The MJCF carries every hydrodynamic parameter as plugin configuration strings
(docs/hydrodynamics.md). This module turns them into frozen dataclasses with numpy arrays and
checks every rule of the spec, raising :class:`HydroConfigError` with a message that names the
plugin, the body, the attribute, the value and what is allowed, e.g.

    uvms.hydro: body 'link1': added_mass = "1 2 3": expected 6, 21 or 36 numbers

Sources of configuration:

* :func:`parse_water` / :func:`parse_body`: a mapping attribute -> string (an `MjsPlugin.config`
  dict or anything else);
* :func:`read_spec`: an `mujoco.MjSpec` (needs the plugins registered, as parsing does);
* :func:`read_model`: a compiled `mujoco.MjModel` (decodes `m.plugin_attr`).

:func:`resolve` fills the defaults that depend on the model (origin of the hydrodynamic frame =
the body's centre of mass, centre of buoyancy = that origin).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping

import mujoco
import numpy as np

from uvms_mj.physics.waves import WAVE_MODELS, Waves

WATER_PLUGIN = "uvms.water"
HYDRO_PLUGIN = "uvms.hydro"

#: Declared attribute order of the plugins (fixed: `m.plugin_attr` stores values in this order).
WATER_ATTRIBUTES = (
    "density", "current", "current_model", "gm_mean", "gm_sigma", "gm_tau",
    "gm_min", "gm_max", "gm_seed", "profile", "terms",
    "wave_model", "wave_height", "wave_period", "wave_gamma", "wave_direction", "wave_spreading",
    "wave_depth", "surface", "wave_seed", "wave_components",
)
#: The wave attributes and the :class:`~uvms_mj.physics.waves.Waves` field each one sets.
WAVE_FIELDS = {
    "wave_height": "height", "wave_period": "period", "wave_gamma": "gamma", "wave_direction": "direction",
    "wave_spreading": "spreading", "wave_depth": "depth", "surface": "surface",
}
HYDRO_ATTRIBUTES = (
    "pos", "quat", "added_mass", "linear_damping", "quadratic_damping", "strips", "volume", "cob",
)

CURRENT_MODELS = ("constant", "gauss_markov", "profile")
TERMS = ("added_mass", "damping", "strips", "buoyancy", "froude_krylov")
AXES = ("x", "y", "z")


class HydroConfigError(ValueError):
    """A plugin configuration that breaks a rule of docs/hydrodynamics.md."""


def _ro(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class WaterParams:
    """The `uvms.water` instance: the water and its current (world frame, SI units).

    Attributes:
        density: rho > 0 [kg/m^3].
        current: (3,) the constant current, or the initial value for `gauss_markov` [m/s].
        current_model: "constant", "gauss_markov" or "profile".
        gm_mean, gm_sigma, gm_tau, gm_min, gm_max: (3,) each, Gauss-Markov parameters
            (gm_mean defaults to `current`).
        gm_seed: integer >= 0, seed of the counter-based noise.
        profile: (n, 4) knots (z, vx, vy, vz) with z strictly increasing; (0, 4) if none.
        terms: the terms that are on (a subset of :data:`TERMS`).
        waves: the waves (:class:`~uvms_mj.physics.waves.Waves`; model "none": still water).
    """

    density: float = 1000.0
    current: np.ndarray = None  # type: ignore[assignment]
    current_model: str = "constant"
    gm_mean: np.ndarray = None  # type: ignore[assignment]
    gm_sigma: np.ndarray = None  # type: ignore[assignment]
    gm_tau: np.ndarray = None  # type: ignore[assignment]
    gm_min: np.ndarray = None  # type: ignore[assignment]
    gm_max: np.ndarray = None  # type: ignore[assignment]
    gm_seed: int = 0
    profile: np.ndarray = None  # type: ignore[assignment]
    terms: frozenset = frozenset(TERMS)
    waves: Waves = Waves()

    def __post_init__(self) -> None:
        defaults = {
            "current": np.zeros(3), "gm_sigma": np.zeros(3), "gm_tau": np.full(3, 10.0),
            "gm_min": np.full(3, -1e3), "gm_max": np.full(3, 1e3), "profile": np.zeros((0, 4)),
        }
        for key, value in defaults.items():
            object.__setattr__(self, key, _ro(value if getattr(self, key) is None else getattr(self, key)))
        if self.gm_mean is None:
            object.__setattr__(self, "gm_mean", self.current)
        else:
            object.__setattr__(self, "gm_mean", _ro(self.gm_mean))
        object.__setattr__(self, "terms", frozenset(self.terms))


@dataclass(frozen=True)
class BodyHydro:
    """One body's `uvms.hydro` instance (frames and units as in docs/hydrodynamics.md).

    Attributes:
        body: the body's name.
        pos: (3,) origin of the hydrodynamic frame h in the body frame, or None (= body_ipos).
        quat: (4,) orientation of h in the body frame (w x y z), normalised.
        added_mass: (6, 6) M_A in frame h, Fossen order, symmetric PSD.
        linear_damping, quadratic_damping: (6,) diagonal D_L, D_Q >= 0.
        strips: tuple of (axis_index, s0, s1, cd1, cd2).
        volume: displaced volume V >= 0 [m^3].
        cob: (3,) centre of buoyancy in the body frame, or None (= pos).
    """

    body: str = ""
    pos: np.ndarray | None = None
    quat: np.ndarray = None  # type: ignore[assignment]
    added_mass: np.ndarray = None  # type: ignore[assignment]
    linear_damping: np.ndarray = None  # type: ignore[assignment]
    quadratic_damping: np.ndarray = None  # type: ignore[assignment]
    strips: tuple = ()
    volume: float = 0.0
    cob: np.ndarray | None = None

    def __post_init__(self) -> None:
        q = np.array([1.0, 0, 0, 0]) if self.quat is None else np.asarray(self.quat, float)
        object.__setattr__(self, "quat", _ro(q / np.linalg.norm(q)))
        for key, default in (("added_mass", np.zeros((6, 6))), ("linear_damping", np.zeros(6)),
                             ("quadratic_damping", np.zeros(6))):
            v = getattr(self, key)
            object.__setattr__(self, key, _ro(default if v is None else v))
        for key in ("pos", "cob"):
            v = getattr(self, key)
            if v is not None:
                object.__setattr__(self, key, _ro(v))
        object.__setattr__(self, "strips", tuple(tuple(s) for s in self.strips))


# ------------------------------------------------------------------------------------ parsing


#: The largest magnitude of a plugin attribute's numbers (ours, SI: the scenario overrides' bound; 1e308 as a
#: volume compiled and then made the controller's first command NaN: exit 1), and tighter ones by attribute:
#: positions within 10 km, a volume up to 1000 m^3 (a 1e6 kg ship).
VALUE_MAX = 1e9
VALUE_LIMITS = {"pos": 1e4, "cob": 1e4, "volume": 1e3}


class _Ctx:
    """Formats error messages: `<plugin>: [body '<name>': ]<key> = "<value>": <reason>`."""

    def __init__(self, plugin: str, body: str | None = None) -> None:
        self.prefix = f"{plugin}: " + (f"body {body!r}: " if body is not None else "")

    def error(self, key: str, value: str, reason: str) -> HydroConfigError:
        return HydroConfigError(f'{self.prefix}{key} = "{value}": {reason}')

    def numbers(self, key: str, value: str, counts: tuple[int, ...] | None = None) -> np.ndarray:
        try:
            x = np.array([float(t) for t in value.split()], dtype=float)
        except ValueError:
            raise self.error(key, value, "expected numbers") from None
        if counts is not None and x.size not in counts:
            allowed = " or ".join(str(c) for c in counts) if len(counts) < 3 else (
                ", ".join(str(c) for c in counts[:-1]) + f" or {counts[-1]}")
            plural = "" if counts == (1,) else "s"
            raise self.error(key, value, f"expected {allowed} number{plural}")
        if not np.all(np.isfinite(x)):
            raise self.error(key, value, "numbers must be finite")
        limit = VALUE_LIMITS.get(key, VALUE_MAX)
        if np.any(np.abs(x) > limit):
            raise self.error(key, value, f"each number must be at most {limit:g} in magnitude")
        return x

    def check_keys(self, config: Mapping[str, str], allowed: tuple[str, ...]) -> None:
        for key in config:
            if key not in allowed:
                raise HydroConfigError(
                    f"{self.prefix}unknown attribute {key!r}; allowed: {', '.join(allowed)}")


def _added_mass(ctx: _Ctx, value: str) -> np.ndarray:
    x = ctx.numbers("added_mass", value, (6, 21, 36))
    if x.size == 6:
        A = np.diag(x)
    elif x.size == 21:
        A = np.zeros((6, 6))
        A[np.triu_indices(6)] = x  # upper triangle row by row
        A = A + np.triu(A, 1).T
    else:
        A = x.reshape(6, 6)
    scale = float(np.max(np.abs(A)))
    if np.max(np.abs(A - A.T)) > 1e-12 * scale:
        raise ctx.error("added_mass", value, "the 6x6 matrix must be symmetric")
    A = 0.5 * (A + A.T)
    if scale > 0 and np.min(np.linalg.eigvalsh(A)) < -1e-12 * scale:
        raise ctx.error("added_mass", value,
                        f"must be positive semi-definite (smallest eigenvalue "
                        f"{np.min(np.linalg.eigvalsh(A)):.6g})")
    return A


def _strips(ctx: _Ctx, value: str) -> tuple:
    out = []
    for part in value.split(";"):
        words = part.split()
        if not words:
            continue
        if len(words) != 5:
            raise ctx.error("strips", value,
                            f"each strip is 'axis s0 s1 cd1 cd2' (5 words), got {part.strip()!r}")
        if words[0] not in AXES:
            raise ctx.error("strips", value, f"strip axis {words[0]!r}: allowed x, y, z")
        try:
            s0, s1, cd1, cd2 = (float(w) for w in words[1:])
        except ValueError:
            raise ctx.error("strips", value, f"strip {part.strip()!r}: expected numbers") from None
        if not all(math.isfinite(x) for x in (s0, s1, cd1, cd2)):
            raise ctx.error("strips", value, f"strip {part.strip()!r}: numbers must be finite")
        if not s0 < s1:
            raise ctx.error("strips", value, f"strip {part.strip()!r}: s0 < s1 required")
        if cd1 < 0 or cd2 < 0:
            raise ctx.error("strips", value, f"strip {part.strip()!r}: cd1, cd2 must be >= 0")
        out.append((AXES.index(words[0]), float(s0), float(s1), float(cd1), float(cd2)))
    return tuple(out)


def _set(config: Mapping[str, str], key: str) -> str | None:
    """The value of `key`, or None when absent or empty (= unset)."""
    v = config.get(key)
    if v is None or not str(v).strip():
        return None
    return str(v)


def parse_body(body_name: str, config: Mapping[str, str]) -> BodyHydro:
    """A body's `uvms.hydro` configuration (attribute -> string; empty = unset) as BodyHydro."""
    ctx = _Ctx(HYDRO_PLUGIN, body_name)
    ctx.check_keys(config, HYDRO_ATTRIBUTES)
    kw: dict = {"body": body_name}
    if (v := _set(config, "pos")) is not None:
        kw["pos"] = ctx.numbers("pos", v, (3,))
    if (v := _set(config, "quat")) is not None:
        q = ctx.numbers("quat", v, (4,))
        if np.linalg.norm(q) == 0:
            raise ctx.error("quat", v, "must not be zero")
        kw["quat"] = q
    if (v := _set(config, "added_mass")) is not None:
        kw["added_mass"] = _added_mass(ctx, v)
    for key in ("linear_damping", "quadratic_damping"):
        if (v := _set(config, key)) is not None:
            x = ctx.numbers(key, v, (6,))
            if np.any(x < 0):
                raise ctx.error(key, v, "coefficients must be >= 0")
            kw[key] = x
    if (v := _set(config, "strips")) is not None:
        kw["strips"] = _strips(ctx, v)
    if (v := _set(config, "volume")) is not None:
        (vol,) = ctx.numbers("volume", v, (1,))
        if vol < 0:
            raise ctx.error("volume", v, "must be >= 0")
        kw["volume"] = float(vol)
    if (v := _set(config, "cob")) is not None:
        kw["cob"] = ctx.numbers("cob", v, (3,))
    return BodyHydro(**kw)


def _parse_waves(ctx: "_Ctx", config: Mapping[str, str]) -> Waves:
    kw: dict = {}
    if (v := _set(config, "wave_model")) is not None:
        if v.strip() not in WAVE_MODELS:
            raise ctx.error("wave_model", v, f"allowed: {', '.join(WAVE_MODELS)}")
        kw["model"] = v.strip()
    for key, field in WAVE_FIELDS.items():
        if (v := _set(config, key)) is not None:
            (kw[field],) = ctx.numbers(key, v, (1,))
    for key, field in (("wave_seed", "seed"), ("wave_components", "n_components")):
        if (v := _set(config, key)) is not None:
            try:
                kw[field] = int(v.strip())
            except ValueError:
                raise ctx.error(key, v, "expected one integer") from None
    model = kw.get("model", "none")
    for key, what in (("wave_height", "H for airy, Hs for a spectrum"),
                      ("wave_period", "T for airy, Tp for a spectrum")):
        if model != "none" and WAVE_FIELDS[key] not in kw:
            raise ctx.error("wave_model", model, f"needs {key} (> 0: {what})")
    try:
        return Waves(**kw)
    except ValueError as exc:  # "waves.<field> = <value>: <reason>": name the attribute instead
        field, _, reason = str(exc).partition(" = ")
        attrs = {f: k for k, f in WAVE_FIELDS.items()} | {"seed": "wave_seed", "n_components": "wave_components"}
        key = attrs.get(field.removeprefix("waves."), "wave_model")
        value, _, reason = reason.partition(": ")
        raise ctx.error(key, str(config.get(key, value)), reason) from None


def parse_water(config: Mapping[str, str]) -> WaterParams:
    """The `uvms.water` configuration (attribute -> string; empty = unset) as WaterParams."""
    ctx = _Ctx(WATER_PLUGIN)
    ctx.check_keys(config, WATER_ATTRIBUTES)
    kw: dict = {}
    if (v := _set(config, "density")) is not None:
        (rho,) = ctx.numbers("density", v, (1,))
        if not rho > 0:
            raise ctx.error("density", v, "must be > 0")
        kw["density"] = float(rho)
    for key in ("current", "gm_mean", "gm_min", "gm_max"):
        if (v := _set(config, key)) is not None:
            kw[key] = ctx.numbers(key, v, (3,))
    if (v := _set(config, "current_model")) is not None:
        if v.strip() not in CURRENT_MODELS:
            raise ctx.error("current_model", v, f"allowed: {', '.join(CURRENT_MODELS)}")
        kw["current_model"] = v.strip()
    if (v := _set(config, "gm_sigma")) is not None:
        x = ctx.numbers("gm_sigma", v, (3,))
        if np.any(x < 0):
            raise ctx.error("gm_sigma", v, "must be >= 0")
        kw["gm_sigma"] = x
    if (v := _set(config, "gm_tau")) is not None:
        x = ctx.numbers("gm_tau", v, (3,))
        if not np.all(x > 0):
            raise ctx.error("gm_tau", v, "must be > 0")
        kw["gm_tau"] = x
    lo = kw.get("gm_min", np.full(3, -1e3))
    hi = kw.get("gm_max", np.full(3, 1e3))
    if np.any(lo > hi):
        key = "gm_min" if "gm_min" in kw else "gm_max"
        raise ctx.error(key, str(config[key]), "gm_min <= gm_max required for each component "
                        f"(gm_min = {lo.tolist()}, gm_max = {hi.tolist()})")
    if (v := _set(config, "gm_seed")) is not None:
        try:
            seed = int(v.strip())
        except ValueError:
            raise ctx.error("gm_seed", v, "expected one integer >= 0") from None
        if not 0 <= seed < 2**64:
            raise ctx.error("gm_seed", v, "expected one integer in [0, 2^64)")
        kw["gm_seed"] = seed
    if (v := _set(config, "profile")) is not None:
        knots = []
        for part in v.split(";"):
            if part.strip():
                knots.append(ctx.numbers("profile", part, (4,)))
        if not knots:
            raise ctx.error("profile", v, "expected knots 'z vx vy vz; ...'")
        P = np.array(knots)
        if np.any(np.diff(P[:, 0]) <= 0):
            raise ctx.error("profile", v, "knot heights z must be strictly increasing")
        kw["profile"] = P
    # An empty value is "unset" (m.plugin_attr cannot tell them apart): all terms on.
    if (v := _set(config, "terms")) is not None:
        words = v.split()
        if words == ["none"]:  # every term off (an empty value means "unset": all on)
            words = []
        for w in words:
            if w not in TERMS:
                raise ctx.error("terms", v, f"unknown term {w!r}; allowed: {', '.join(TERMS)}, or none")
        kw["terms"] = frozenset(words)
    kw["waves"] = _parse_waves(ctx, config)
    model = kw.get("current_model", "constant")
    if model == "profile" and "profile" not in kw:
        raise ctx.error("current_model", model, "the profile model needs a 'profile'")
    return WaterParams(**kw)


# ------------------------------------------------------------------------------ spec and model


def read_spec(spec: mujoco.MjSpec) -> tuple[WaterParams | None, dict[str, BodyHydro]]:
    """Parse the `uvms.water` instance and every body's active `uvms.hydro` instance of a spec.

    Raises HydroConfigError for more than one `uvms.water` instance.
    """
    water = None
    for p in spec.plugins:
        if p.plugin_name == WATER_PLUGIN:
            if water is not None:
                raise HydroConfigError(f"{WATER_PLUGIN}: more than one instance in the model")
            water = parse_water(dict(p.config))
    named = {p.name: p for p in spec.plugins if p.name}
    bodies: dict[str, BodyHydro] = {}
    for b in spec.bodies:
        pl = b.plugin
        # Only touch .config when a plugin is attached (MuJoCo 3.17 crashes otherwise); a body
        # that references a top-level instance by name (<plugin instance="..."/>, or
        # uvms_mj.plant.robot.add_hydro_instance) has its attributes there (reading the body's own
        # .config then crashes MuJoCo 3.17's bindings too).
        if pl.active and pl.plugin_name == HYDRO_PLUGIN:
            src = named.get(pl.name) if pl.name else None
            bodies[b.name] = parse_body(b.name, dict((src if src is not None else pl).config))
    return water, bodies


def _instance_values(m: mujoco.MjModel, i: int) -> list[str]:
    start = m.plugin_attradr[i]
    end = m.plugin_attradr[i + 1] if i + 1 < m.nplugin else m.npluginattr
    raw = bytes(np.asarray(m.plugin_attr[start:end], dtype=np.uint8))
    return raw.decode().split("\0")[:-1]  # every value ends in NUL


def read_model(m: mujoco.MjModel) -> tuple[WaterParams | None, dict[int, BodyHydro]]:
    """Decode the `uvms.water` and `uvms.hydro` instances of a compiled model.

    `m.plugin_attr` holds, per instance, one NUL-terminated value per declared attribute, in the
    declared order (empty = unset). The Python API exposes no name for a plugin slot, so
    instances are identified by what references them and by their attribute count: an instance
    referenced by a body with 8 values is `uvms.hydro`; the (single) instance of the slot that
    is referenced by no body, actuator, sensor or geom and has 11 values is `uvms.water`.
    """
    referenced = set()
    for arr in (m.actuator_plugin, m.sensor_plugin, m.geom_plugin):
        referenced.update(int(i) for i in np.asarray(arr) if i >= 0)
    hydro_slots = set()
    bodies: dict[int, BodyHydro] = {}
    for b in range(m.nbody):
        i = int(m.body_plugin[b])
        if i < 0:
            continue
        vals = _instance_values(m, i)
        if len(vals) != len(HYDRO_ATTRIBUTES):
            continue  # another body plugin
        hydro_slots.add(int(m.plugin[i]))
        name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b) or f"body{b}"
        bodies[b] = parse_body(name, {k: v for k, v in zip(HYDRO_ATTRIBUTES, vals)})
    body_instances = {int(i) for i in np.asarray(m.body_plugin) if i >= 0}
    water = None
    for i in range(m.nplugin):
        if i in referenced or i in body_instances or int(m.plugin[i]) in hydro_slots:
            continue
        vals = _instance_values(m, i)
        if len(vals) != len(WATER_ATTRIBUTES):
            continue
        if water is not None:
            raise HydroConfigError(f"{WATER_PLUGIN}: more than one instance in the model")
        water = parse_water({k: v for k, v in zip(WATER_ATTRIBUTES, vals)})
    return water, bodies


def resolve(m: mujoco.MjModel, body_id: int, hydro: BodyHydro) -> BodyHydro:
    """`hydro` with its defaults filled: pos = m.body_ipos[body_id], cob = pos, quat normalised."""
    pos = np.array(m.body_ipos[body_id], float) if hydro.pos is None else np.array(hydro.pos)
    cob = pos.copy() if hydro.cob is None else np.array(hydro.cob)
    q = np.asarray(hydro.quat, float)
    q = q / math.sqrt(float(q @ q))
    return BodyHydro(
        body=hydro.body, pos=pos, quat=q, added_mass=hydro.added_mass,
        linear_damping=hydro.linear_damping, quadratic_damping=hydro.quadratic_damping,
        strips=hydro.strips, volume=hydro.volume, cob=cob,
    )
