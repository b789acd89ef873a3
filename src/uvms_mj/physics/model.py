"""Loading robot files that carry their hydrodynamics (the uvms plugins), with or without C.

A model file declares its water and per-body hydrodynamics through the ``uvms.water``,
``uvms.hydro`` and ``uvms.thruster`` plugins (``docs/hydrodynamics.md``). With the compiled plugin
library registered (:func:`uvms_mj.physics.build.register_plugins`, which :func:`load_spec` calls
on first use, as every loader of such a file must; ``import uvms_mj`` does not), plain MuJoCo loads
such a file and simulates it in water. Where the library cannot be built (no
C compiler), :func:`compile_spec` strips the uvms plugins from a copy of the spec, compiles the
rest and remembers the parsed parameters, and :mod:`uvms_mj.physics.python_backend` applies
the numpy reference implementation through ``mjcb_passive``.

Functions here never simulate: they read, validate, edit and compile.
"""

from __future__ import annotations

import json
import math
import weakref
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import mujoco

from uvms_mj.physics import build, config
from uvms_mj.physics.mjwarnings import install_mujoco_warning_handler
from uvms_mj.physics.modelcheck import check_model_numbers, check_spec_numbers

WATER, HYDRO, THRUSTER = "uvms.water", "uvms.hydro", "uvms.thruster"
PLUGINS = (WATER, HYDRO, THRUSTER)


class ModelError(ValueError):
    """A robot file that is missing, malformed or has non-physical hydrodynamic parameters."""


@dataclass(frozen=True)
class HydroInfo:
    """The hydrodynamics of a compiled model.

    Attributes:
        water: the model-wide parameters (``uvms.water``), or None if the model has none.
        bodies: body id -> parameters of that body (``uvms.hydro``), defaults resolved
            (``pos`` = the body's centre of mass, ``cob`` = ``pos``, ``quat`` normalised).
        native: True when the C plugins are compiled into the model (plain MuJoCo applies the
            hydrodynamics); False when they were stripped and the Python backend must serve it.
    """

    water: Any
    bodies: dict
    native: bool


# Compiled models whose uvms plugins were stripped (Python backend), or whose parameters were
# already parsed: model -> HydroInfo. Weak keys: the entry goes with the model.
_INFO: "weakref.WeakKeyDictionary[mujoco.MjModel, HydroInfo]" = weakref.WeakKeyDictionary()


def plugins_available() -> bool:
    """Whether the C plugins are registered in this process: builds and registers them on first
    call (:func:`uvms_mj.physics.build.register_plugins`, idempotent; ``UVMS_MJ_COMPILED``)."""
    return build.register_plugins()


def load_spec(path: str | Path) -> mujoco.MjSpec:
    """Parse an MJCF file into an :class:`mujoco.MjSpec` (not compiled).

    Without the C plugins MuJoCo's parser refuses any file that names them, so the file (with
    its includes inlined) is first stripped of the uvms plugins at the XML level; their
    attributes travel in the spec as ``<custom><text>`` elements (see :func:`_text_name`),
    which :func:`compile_spec`, :func:`set_water` and :func:`set_body` understand.

    Raises:
        ModelError: the file does not exist or is not valid MJCF.
    """
    install_mujoco_warning_handler()  # a warning while parsing: not into ./MUJOCO_LOG.TXT
    p = Path(path)
    if not p.is_file():
        raise ModelError(f"model file {str(p)!r} does not exist")
    native = plugins_available()  # builds and registers them on first use (UVMS_MJ_COMPILED)
    try:
        if native:
            return mujoco.MjSpec.from_file(str(p))
        xml, water, bodies = _strip_xml(p)
        spec = mujoco.MjSpec.from_string(xml)
        spec.modelfiledir = str(p.resolve().parent)
    except ModelError:
        raise
    except Exception as exc:  # noqa: BLE001 - MuJoCo raises ValueError with the parser's text
        raise ModelError(f"cannot read model file {str(p)!r}: {exc}") from None
    if water is not None:
        spec.add_text(name=_text_name(), data=json.dumps(water))
    for body, cfg in bodies.items():
        spec.add_text(name=_text_name(body), data=json.dumps(cfg))
    return spec


def _text_name(body: str | None = None) -> str:
    """Name of the ``<custom><text>`` that carries a stripped plugin's attributes (JSON)."""
    return WATER if body is None else f"{HYDRO}:{body}"


def _inline(path: Path) -> ET.Element:
    """The MJCF tree of ``path`` with every ``<include file=...>`` replaced by the children of
    the included file's root (paths relative to the including file), recursively."""
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError) as exc:
        raise ModelError(f"cannot read model file {str(path)!r}: {exc}") from None

    def expand(elem: ET.Element) -> None:
        for i, child in enumerate(list(elem)):
            if child.tag == "include":
                inc = _inline(path.parent / child.get("file", ""))
                elem.remove(child)
                for j, sub in enumerate(list(inc)):
                    elem.insert(i + j, sub)
            else:
                expand(child)

    expand(root)
    return root


def _strip_xml(path: Path) -> tuple[str, dict | None, dict[str, dict]]:
    """(MJCF text without the uvms plugins, the uvms.water attributes, {body: uvms.hydro
    attributes}) of a file and its includes."""
    root = _inline(path)
    water, instances, bodies = None, {}, {}
    for ext in root.findall("extension"):
        for pl in list(ext.findall("plugin")):
            name = pl.get("plugin", "")
            if name == THRUSTER:
                raise ModelError(f"{path.name}: the uvms.thruster plugin needs the compiled uvms plugin library "
                                 f"({build.unavailable_reason() or 'not built'})")
            if name in PLUGINS:
                for inst in pl.findall("instance"):
                    cfg = {c.get("key"): c.get("value", "") for c in inst.findall("config")}
                    instances[inst.get("name")] = (name, cfg)
                    if name == WATER:
                        if water is not None:
                            raise ModelError(f"{path.name}: {WATER}: more than one instance in the model")
                        water = cfg
                ext.remove(pl)
        if len(ext) == 0:
            root.remove(ext)
    for body in root.iter("body"):
        for pl in list(body.findall("plugin")):
            kind, cfg = pl.get("plugin", ""), {c.get("key"): c.get("value", "") for c in pl.findall("config")}
            if pl.get("instance") in instances:
                kind, cfg = instances[pl.get("instance")]
            if kind == HYDRO:
                bodies[body.get("name", "")] = cfg
                body.remove(pl)
    return ET.tostring(root, encoding="unicode"), water, bodies


def _texts(spec: mujoco.MjSpec) -> dict[str, Any]:
    return {t.name: t for t in spec.texts if t.name == WATER or t.name.startswith(HYDRO + ":")}


def _read(spec: mujoco.MjSpec) -> tuple[Any, dict]:
    """(WaterParams or None, {body name: BodyHydro}) of a spec, in either representation."""
    texts = _texts(spec)
    if not texts:
        return config.read_spec(spec)
    water = config.parse_water(json.loads(texts[WATER].data)) if WATER in texts else None
    bodies = {name.partition(":")[2]: config.parse_body(name.partition(":")[2], json.loads(t.data))
              for name, t in texts.items() if name != WATER}
    return water, bodies


def uses_plugins(spec: mujoco.MjSpec) -> bool:
    """Whether the spec declares any uvms plugin (as plugins, or stripped into texts)."""
    return any(p.plugin_name in PLUGINS for p in spec.plugins) or bool(_texts(spec))


def compile_spec(spec: mujoco.MjSpec, *, native: bool | None = None, source: str = "model",
                 check_keyframes: bool = True) -> mujoco.MjModel:
    """Validate the uvms plugin parameters of ``spec`` and compile it.

    Args:
        spec: the model (not modified).
        native: compile the C plugins into the model (True), strip them for the Python backend
            (False), or: C when the plugin library is available, else Python (None).
        source: how to name the model in error messages (e.g. its file name).
        check_keyframes: refuse a keyframe whose qpos / qvel / act / ctrl is neither empty nor of
            the model's size (the file as written; False for a spec that gained joints at run
            time, whose keyframes MuJoCo pads with qpos0).

    Raises:
        ModelError: a bad hydrodynamic parameter (the message names the body, the attribute,
            the value and what is allowed), or a model MuJoCo cannot compile.
    """
    install_mujoco_warning_handler()  # a warning while compiling: not into ./MUJOCO_LOG.TXT
    try:
        water, bodies = _read(spec)
    except config.HydroConfigError as exc:
        raise ModelError(f"{source}: {exc}") from None
    if bodies and water is None:
        raise ModelError(f"{source}: bodies carry uvms.hydro parameters but the model declares no "
                         "uvms.water instance (add <extension><plugin plugin=\"uvms.water\"><instance name=\"water\"/>"
                         "</plugin></extension>)")
    for p in spec.plugins:  # top-level instances (reading them is safe; see config.read_spec)
        if p.plugin_name in PLUGINS:
            empty = sorted(k for k, v in dict(p.config).items() if not str(v).strip())
            if empty:
                raise ModelError(f"{source}: {p.plugin_name} instance {p.name!r}: attribute {empty[0]!r} = '': give a "
                                 "value or leave the attribute out (its default)")
    bad = check_spec_numbers(spec, source)  # compiled as 0 by MuJoCo: refused before
    if bad:
        raise ModelError(bad)
    if native is None:
        native = plugins_available() or not uses_plugins(spec)
    stripped = bool(_texts(spec))
    # the keyframes' sizes as written (compiling pads the spec's own arrays)
    key_sizes = [(k.name, {f: len(getattr(k, f)) for f in ("qpos", "qvel", "act", "ctrl")}) for k in spec.keys]
    if native and uses_plugins(spec) and (stripped or not plugins_available()):
        raise ModelError(f"{source}: the uvms plugins are not available: {build.unavailable_reason()}")
    try:
        if native or stripped or not uses_plugins(spec):
            m = spec.compile()
        else:
            # The Python backend on a model whose plugins are registered: compile them with every
            # term off ("none"), so that the C code adds nothing and Python adds everything.
            # (MjSpec.copy loses plugin instances in MuJoCo 3.17, and detaching body plugins
            # from a spec can crash it: switching the terms off is the safe way.)
            inst = next(p for p in spec.plugins if p.plugin_name == WATER)
            saved = dict(inst.config)
            inst.config = {**saved, "terms": "none"}
            try:
                m = spec.compile()
            finally:
                inst.config = saved
    except ModelError:
        raise
    except Exception as exc:  # noqa: BLE001
        raise ModelError(f"cannot compile {source}: {exc}") from None
    if check_keyframes:
        for name, given in key_sizes:  # MuJoCo pads a short keyframe with qpos0 without a word
            for fld, size in (("qpos", m.nq), ("qvel", m.nv), ("act", m.na), ("ctrl", m.nu)):
                if given[fld] not in (0, size):
                    raise ModelError(f"{source}: keyframe {name!r}: {fld} has {given[fld]} values; the model "
                                     f"needs {size}")
    bad = check_model_numbers(m, source)  # a mass of 1e308 or -1, a NaN inertia: MuJoCo compiles them
    if bad:
        raise ModelError(bad)
    resolved = {}
    for name, bh in bodies.items():
        bid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, name)
        if bid == 0:
            raise ModelError(f"{source}: uvms.hydro on the world body: the world does not move; put it on the "
                             "body that displaces the water")
        if bid < 0:
            raise ModelError(f"{source}: uvms.hydro parameters for body {name!r}, which the model does not have")
        if m.body_simple[bid] and any(bh.added_mass.ravel()):
            # Same rule as the C plugin: M of a "simple" body has only a diagonal, so the
            # off-diagonal terms of J^T M_A J would be dropped silently.
            raise ModelError(f"{source}: uvms.hydro: body {name!r}: added_mass on a simple body (a childless body "
                             "on a free joint, whose mass matrix MuJoCo keeps diagonal) is refused; weld a "
                             "child body to it (e.g. a tiny massless geom in a child <body>)")
        resolved[bid] = config.resolve(m, bid, bh)
    _INFO[m] = HydroInfo(water, resolved, bool(native) and uses_plugins(spec))
    return m


def load_model(path: str | Path, *, native: bool | None = None) -> mujoco.MjModel:
    """Load, validate and compile a robot file (see :func:`compile_spec`)."""
    return compile_spec(load_spec(path), native=native, source=Path(path).name)


def hydro_of(m: mujoco.MjModel) -> HydroInfo:
    """The hydrodynamic parameters of a compiled model (also of one loaded by plain MuJoCo)."""
    info = _INFO.get(m)
    if info is None:
        water, bodies = config.read_model(m)
        info = HydroInfo(water, {b: config.resolve(m, b, bh) for b, bh in bodies.items()}, water is not None)
        _INFO[m] = info
    return info


def copy_model(m: mujoco.MjModel) -> mujoco.MjModel:
    """A copy of a compiled model that keeps its hydrodynamic parameters."""
    import copy

    c = copy.deepcopy(m)
    info = _INFO.get(m)
    if info is not None:
        _INFO[c] = info
    return c


# --------------------------------------------------------------------------- spec edits


def set_water(spec: mujoco.MjSpec, **values: str) -> None:
    """Set attributes of the spec's ``uvms.water`` instance (strings, as in the MJCF).

    Raises:
        ModelError: the spec has none."""
    t = _texts(spec).get(WATER)
    if t is not None:
        t.data = json.dumps({**json.loads(t.data), **values})
        return
    for p in spec.plugins:
        if p.plugin_name == WATER:
            p.config = {**p.config, **values}
            return
    raise ModelError("the model declares no uvms.water instance")


def water_config(spec: mujoco.MjSpec) -> dict[str, str]:
    """The ``uvms.water`` attributes of a spec (a copy).

    Raises:
        ModelError: the spec has none."""
    t = _texts(spec).get(WATER)
    if t is not None:
        return json.loads(t.data)
    for p in spec.plugins:
        if p.plugin_name == WATER:
            return dict(p.config)
    raise ModelError("the model declares no uvms.water instance")


def body_config(spec: mujoco.MjSpec, body: str) -> dict[str, str]:
    """The ``uvms.hydro`` attributes of a body (a copy).

    Raises:
        ModelError: no such body, or it has no uvms.hydro parameters."""
    t = _texts(spec).get(_text_name(body))
    if t is not None:
        return json.loads(t.data)
    b = spec.body(body)
    if b is None:
        raise ModelError(f"the model has no body named {body!r}")
    # Only touch .config when a plugin is attached (MuJoCo 3.17 crashes otherwise).
    if not (b.plugin.active and b.plugin.plugin_name == HYDRO):
        raise ModelError(f"body {body!r} has no uvms.hydro parameters")
    return dict(b.plugin.config)


def set_body(spec: mujoco.MjSpec, body: str, **values: str) -> None:
    """Set ``uvms.hydro`` attributes of a body (strings, as in the MJCF)."""
    cfg = {**body_config(spec, body), **values}
    t = _texts(spec).get(_text_name(body))
    if t is not None:
        t.data = json.dumps(cfg)
    else:
        spec.body(body).plugin.config = cfg


def fmt(values: Any) -> str:
    """Numbers as an MJCF attribute string (repr precision: round-trips exactly)."""
    try:
        seq = list(values)
    except TypeError:
        seq = [values]
    out = []
    for v in seq:
        f = float(v)
        if not math.isfinite(f):
            raise ModelError(f"value {v!r} is not finite")
        out.append(repr(f))
    return " ".join(out)



# --------------------------------------------------------------------------- plugin state

#: Size of the ``uvms.water`` plugin state (see plugin/water.c): t_k, k, v_k (3), v_next (3), h.
WATER_NSTATE = 9


def water_state_address(m: mujoco.MjModel) -> int | None:
    """Address in ``d.plugin_state`` of the ``uvms.water`` state, or None (no C water)."""
    used = {int(i) for arr in (m.body_plugin, m.actuator_plugin, m.sensor_plugin, m.geom_plugin)
            for i in arr if i >= 0}
    for i in range(m.nplugin):
        if i not in used and m.plugin_statenum[i] == WATER_NSTATE:
            return int(m.plugin_stateadr[i])
    return None


def current_state_of(m: mujoco.MjModel, d: mujoco.MjData):
    """The sampled current of the C plugin in ``d``, as (t_k, k, v_k, v_next) (world, m/s),
    the layout :mod:`uvms_mj.physics.reference` takes; None where the model has no C water."""
    adr = water_state_address(m)
    if adr is None:
        return None
    s = d.plugin_state[adr : adr + WATER_NSTATE]
    return (float(s[0]), int(s[1]), s[2:5].copy(), s[5:8].copy())
