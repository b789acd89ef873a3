"""Scenario files: loading, validation, resolution, building and running, for every robot.

A scenario is a YAML mapping (read with a safe loader: no aliases, bounded size and depth)
validated by the one schema, :class:`uvms_mj.scenario.document.Scenario` (where the format is
documented); its sections (:mod:`uvms_mj.scenario.sections`, :mod:`uvms_mj.scenario.paths`,
:mod:`uvms_mj.scenario.base`) apply to every robot, and the paper's robot and MJCF robots add
their own defaults and checks (:mod:`uvms_mj.scenario.paper`, :mod:`uvms_mj.scenario.robot`).
:func:`load_scenario` / :func:`validate_scenario` give a validated scenario; :func:`build`,
:func:`run_scenario`, :func:`resolved` and :func:`controller_period` take any.

Overrides from the command line (``sets``) are ``key.path=value`` strings, the value parsed as
YAML (``controller.name=rac``, ``trajectory.displacement=[0.2,0]``, ``plant.current=[0.1,0]``,
``plant.overrides.base.volume=0.03``: inside ``overrides`` the rest of the path is one key). They
are applied to the raw mapping before validation; setting ``trajectory.target`` removes
``trajectory.displacement`` and vice versa (they are alternatives).
"""

from __future__ import annotations

import copy
import inspect
import re
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Sequence

import mujoco
import numpy as np
import yaml
from pydantic import BaseModel, ValidationError

from uvms_mj.control import ControllerError, create
from uvms_mj.physics.terms import HydroTerms
from uvms_mj.control.nominal import NominalRobot
from uvms_mj.plant.params import (
    ParameterError,
    RobotParams,
    read_params,
)
from uvms_mj.plant.files import nominal_model_path, robot_path
from uvms_mj.plant.layout import InitialState
from uvms_mj.plant.plant import Plant
from uvms_mj.scenario.paths import tip_path
from uvms_mj.scenario.sections import vehicle_params
from uvms_mj.scenario.navigation import nav_config, resolved_navigation
if TYPE_CHECKING:  # imported where used: validate needs neither the loop nor the navigation sensors
    from uvms_mj.sim.loop import RunResult
from uvms_mj.scenario.base import (  # noqa: F401  (LAG_STABILITY, log_path, sensor_model: importable from here as before)
    _NO_VALUE,
    LAG_STABILITY,
    ScenarioError,
    log_path,
    sensor_model,
    _controller_signature,
    _factory,
    _Issues,
    _jsonable,
    _suggest,
    named_argument,
    takes_argument,
)

__all__ = [
    "Scenario",
    "ScenarioError",
    "build",
    "controller_period",
    "dump_yaml",
    "load_scenario",
    "log_path",
    "nominal_params",
    "plant_overrides",
    "resolved",
    "run_scenario",
    "validate_scenario",
]


from uvms_mj.scenario.document import Scenario, controller_period  # noqa: F401  (importable from here)


def _fmt_value(v: Any) -> str:
    s = repr(v)
    return s if len(s) <= 80 else s[:77] + "..."


def _fmt_path(loc: Sequence) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int) and not isinstance(part, bool):
            out += f"[{part}]"
        else:
            out += ("." if out else "") + str(part)
    return out or "(top level)"


# --------------------------------------------------------------------------- validation, loading

def _model_at(loc: Sequence) -> type[BaseModel] | None:
    """The section model at a location (for the allowed keys of an unknown-key error)."""
    model: Any = Scenario
    for part in loc:
        if not (isinstance(model, type) and issubclass(model, BaseModel)):
            return None
        f = model.model_fields.get(part)
        if f is None:
            return None
        model = f.annotation
        args = [a for a in getattr(model, "__args__", ()) if isinstance(a, type) and issubclass(a, BaseModel)]
        if args:  # X | None
            model = args[0]
    return model if isinstance(model, type) and issubclass(model, BaseModel) else None


def _format(exc: ValidationError, source: str) -> str:
    lines = []
    for err in exc.errors():
        loc = tuple(err["loc"])
        inner = (err.get("ctx") or {}).get("error")
        if isinstance(inner, _Issues):
            for sub, msg, value in inner.items:
                got = "" if value is _NO_VALUE else f" (got {_fmt_value(value)})"
                lines.append(f"{source}: {_fmt_path(loc + tuple(sub))}: {msg}{got}")
            continue
        if err["type"] == "extra_forbidden":
            model = _model_at(loc[:-1])
            allowed = [k for k, f in model.model_fields.items() if not f.exclude] if model else []
            lines.append(f"{source}: {_fmt_path(loc)}: unknown key {loc[-1]!r}{_suggest(loc[-1], allowed)}; allowed: "
                         + ", ".join(allowed))
            continue
        msg = err["msg"].removeprefix("Value error, ")
        lines.append(f"{source}: {_fmt_path(loc)}: {msg} (got {_fmt_value(err.get('input'))})")
    return "\n".join(lines)


def validate_scenario(data: Any, source: str = "<scenario>", base_dir: str | Path | None = None) -> Scenario:
    """Validate a raw mapping (:class:`Scenario`, any robot); raise :class:`ScenarioError`
    naming ``source`` on any problem. ``base_dir``: the scenario file's folder (a robot, an
    overrides file or a csv trajectory given as a relative path is found there)."""
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ScenarioError(f"{source}: a scenario must be a mapping of keys to values, got {_fmt_value(data)}")
    if "base_dir" in data:
        raise ScenarioError(f"{source}: base_dir: unknown key 'base_dir' (set by the loader)")
    from uvms_mj.plant.files import BUILTIN_ROBOTS

    robot = data.get("robot", "paper")
    # The scenario file's folder matters only for what is given as a relative path.
    plant = data.get("plant") if isinstance(data.get("plant"), dict) else {}
    traj = data.get("trajectory") if isinstance(data.get("trajectory"), dict) else {}
    curve = traj.get("curve") if isinstance(traj.get("curve"), dict) else {}
    if base_dir is not None and (not isinstance(robot, str) or robot in BUILTIN_ROBOTS) \
            and plant.get("overrides_file") is None and "csv" not in (traj.get("kind"), curve.get("kind")):
        base_dir = None
    try:
        return Scenario.model_validate({**data, "base_dir": None if base_dir is None else str(base_dir)})
    except ValidationError as exc:
        raise ScenarioError(_format(exc, source)) from None
    except (ArithmeticError, FloatingPointError) as exc:  # a number no bound caught made a check overflow
        raise ScenarioError(f"{source}: a number is out of the range the checks can compute with "
                            f"({type(exc).__name__}: {' '.join(str(exc).split())})") from None


#: Limits on scenario files (a scenario is a few kB): size, nesting depth; aliases are refused.
FILE_SIZE_MAX = 1 << 20  # bytes
DEPTH_MAX = 32  # nested mappings / lists


class _Loader(yaml.SafeLoader):
    """safe_load that rejects duplicate keys (YAML keeps the last one silently), aliases
    (``*name``: alias bombs, recursive structures) and nesting deeper than :data:`DEPTH_MAX`, and
    reports bad values of explicit tags (``!!float 'abc'``) and over-long integers as YAML errors
    with their line."""

    _depth = 0

    def compose_node(self, parent, index):  # noqa: ANN001 - PyYAML's signature
        if self.check_event(yaml.events.AliasEvent):
            event = self.peek_event()
            raise yaml.composer.ComposerError(
                None, None, f"aliases (*{event.anchor}) are not allowed in scenario files; write the value out",
                event.start_mark)
        if self._depth >= DEPTH_MAX:
            event = self.peek_event()
            raise yaml.composer.ComposerError(
                None, None, f"nesting deeper than {DEPTH_MAX} levels", event.start_mark)
        self._depth += 1
        try:
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1


def _checked(construct: Callable) -> Callable:
    def wrapped(loader: _Loader, node: yaml.Node) -> Any:
        try:
            return construct(loader, node)
        except (ValueError, OverflowError) as exc:
            raise yaml.constructor.ConstructorError(
                None, None, f"bad {node.tag.rsplit(':', 1)[-1]} value {_fmt_value(node.value)}: "
                f"{str(exc).splitlines()[0] if str(exc) else type(exc).__name__}", node.start_mark) from None

    return wrapped


for _tag, _construct in list(yaml.SafeLoader.yaml_constructors.items()):
    if _tag is not None and _tag.startswith("tag:yaml.org,2002:") and _tag.rsplit(":", 1)[-1] in (
            "int", "float", "bool", "binary", "timestamp", "null", "str"):
        _Loader.add_constructor(_tag, _checked(_construct))


def _construct_mapping(loader: _Loader, node: yaml.MappingNode, deep: bool = False) -> dict:
    seen = set()
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=deep)
        try:
            dup = key in seen
        except TypeError:
            dup = False
        if dup:
            raise yaml.constructor.ConstructorError(
                "while constructing a mapping", node.start_mark, f"found duplicate key {key!r}", key_node.start_mark)
        try:
            seen.add(key)
        except TypeError:
            pass
    return yaml.SafeLoader.construct_mapping(loader, node, deep=deep)


_Loader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)
# YAML 1.1 (PyYAML) reads 1e-4 as a string (it wants 1.0e-4): accept exponent floats without a dot.
_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float", re.compile(r"^[-+]?[0-9][0-9_]*[eE][-+]?[0-9]+$"), list("-+0123456789"))


def _yaml_load(text: str, source: str) -> Any:
    try:
        return yaml.load(text, Loader=_Loader)  # noqa: S506 - a SafeLoader subclass
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        where = f"{source}:{mark.line + 1}:{mark.column + 1}" if mark else source
        line = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        what = str(exc.problem or "")
        if exc.context:
            cm = exc.context_mark
            opened = f" (line {cm.line + 1}, column {cm.column + 1})" if cm is not None and cm is not mark else ""
            what = f"{exc.context}{opened}: {what}"
        kind = "YAML error" if isinstance(exc, yaml.constructor.ConstructorError) else "YAML syntax error"
        raise ScenarioError(f"{where}: {kind}{line}: {what}") from None
    except yaml.YAMLError as exc:
        raise ScenarioError(f"{source}: YAML error: {exc}") from None
    except (ValueError, OverflowError, RecursionError, MemoryError) as exc:
        raise ScenarioError(f"{source}: YAML error: {type(exc).__name__}: {str(exc)[:200]}") from None


#: Free-form mappings whose keys contain dots: inside them a --set path is one key.
_FLAT_MAPS = {("plant", "overrides"), ("nominal", "overrides")}
_ALTERNATIVES = {("trajectory", "target"): "displacement", ("trajectory", "displacement"): "target"}


def apply_sets(raw: dict, sets: Sequence[str]) -> dict:
    """Apply ``key.path=value`` overrides (value parsed as YAML) to a raw scenario mapping."""
    out = copy.deepcopy(raw)
    for item in sets:
        key, sep, text = str(item).partition("=")
        key = key.strip()
        parts = key.split(".")
        if not sep or not key or any(not p for p in parts):
            raise ScenarioError(f"--set {item!r}: expected KEY.PATH=VALUE, e.g. controller.name=rac or "
                                "trajectory.displacement=[0.2,0]")
        try:
            value = yaml.load(text, Loader=_Loader)  # noqa: S506 - a SafeLoader subclass
        except (yaml.YAMLError, ValueError, OverflowError, RecursionError) as exc:
            raise ScenarioError(f"--set {item!r}: the value is not valid YAML: "
                                f"{getattr(exc, 'problem', None) or exc}") from None
        node, path, i = out, [], 0
        while True:
            if tuple(path) in _FLAT_MAPS:
                last = ".".join(parts[i:])
                break
            if i == len(parts) - 1:
                last = parts[i]
                break
            child = node.get(parts[i])
            if child is None:
                child = node[parts[i]] = {}
            elif not isinstance(child, dict):
                raise ScenarioError(f"--set {item!r}: {'.'.join(path + [parts[i]])} is not a mapping "
                                    f"(it is {_fmt_value(child)})")
            node = child
            path.append(parts[i])
            i += 1
        if tuple(path) == ("trajectory",) and last == "curve" and isinstance(value, dict):
            # a curve replaces the line (its keys do not apply to a curve)
            for k in [k for k in node if k != "origin"]:
                node.pop(k)
        other = _ALTERNATIVES.get((*path, last))
        if other is not None and value is not None:
            node.pop(other, None)
        node[last] = value
    return out


def apply_scenario_sets(raw: dict, sets: Sequence[str]) -> dict:
    """:func:`apply_sets` on a scenario mapping, where controller.params belong to the
    scenario's controller: a ``controller.name`` set that changes the controller (and sets no
    ``controller.params``) gives the new one its own parameters from the controllers section,
    else its defaults (what ``run``, ``compare`` and ``sweep`` do alike)."""
    before = _controller_name(raw)
    raw = apply_sets(raw, sets)
    after = _controller_name(raw)
    touched = any(str(x).partition("=")[0].strip().startswith("controller.params") for x in sets)
    if after != before and not touched and isinstance(raw.get("controller"), dict):
        own = raw.get("controllers", {}).get(after) if isinstance(raw.get("controllers"), dict) else None
        raw["controller"]["params"] = copy.deepcopy(own) if own is not None else {}
    return raw


def _controller_name(raw: dict) -> Any:
    from uvms_mj.scenario.document import DEFAULT_CONTROLLER

    c = raw.get("controller")
    default = DEFAULT_CONTROLLER["paper" if raw.get("robot", "paper") == "paper" else None]
    return c.get("name", default) if isinstance(c, dict) else default


def load_scenario(path: str | Path, sets: Sequence[str] = ()) -> Scenario:
    """Load and validate a scenario file, with ``key.path=value`` overrides applied first.

    The name defaults to the file name without its extension.

    Raises:
        ScenarioError: unreadable file, YAML syntax error (with line and column), bad --set, or
            invalid content (one line per problem, each with the field path and what is allowed).
    """
    p = Path(path)
    source = str(p)
    try:
        with open(p, "rb") as f:
            data = f.read(FILE_SIZE_MAX + 1)
        if len(data) > FILE_SIZE_MAX:
            raise ScenarioError(f"{source}: larger than {FILE_SIZE_MAX // 1024} KiB: not a scenario file")
        text = data.decode("utf-8")
    except FileNotFoundError:
        raise ScenarioError(f"{source}: no such scenario file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ScenarioError(f"{source}: cannot read the scenario file: {exc}") from None
    if "\0" in text:
        raise ScenarioError(f"{source}: contains NUL bytes: not a scenario file (YAML text)")
    raw = _yaml_load(text, source)
    if raw is None:
        raw = {}
    if not isinstance(raw, dict):
        raise ScenarioError(f"{source}: a scenario must be a mapping of keys to values, got {_fmt_value(raw)}")
    if sets:
        raw = apply_scenario_sets(raw, sets)
        source = f"{source} (with --set {' '.join(sets)})"
    if "name" not in raw:
        raw = {"name": re.sub(r"[^A-Za-z0-9_.-]", "_", p.stem) or "scenario", **raw}
    return validate_scenario(raw, source, base_dir=p.parent)


def dump_yaml(scenario: Scenario) -> str:
    """The scenario as YAML (loads back to an equal scenario)."""
    return yaml.safe_dump(scenario.model_dump(), sort_keys=False)


# --------------------------------------------------------------------------- resolution, build, run


def drag_model(scenario: Scenario) -> str:
    """The plant's drag model with the default resolved (the paper's robot: ``mujoco`` with its
    model mismatch, else ``strip``; others ``strip``)."""
    d = scenario.plant.hydro.drag
    return d if d is not None else ("mujoco" if scenario.plant.model_mismatch else "strip")


def plant_overrides(scenario: Scenario) -> dict:
    """Every parameter override the plant gets (:func:`uvms_mj.scenario.paper.paper_plant_overrides`
    on the paper's robot, :func:`uvms_mj.scenario.robot.mjcf_plant_overrides` on others)."""
    from uvms_mj.scenario.paper import paper_plant_overrides
    from uvms_mj.scenario.robot import mjcf_plant_overrides

    return paper_plant_overrides(scenario) if scenario.robot == "paper" else mjcf_plant_overrides(scenario)


def nominal_params(scenario: Scenario) -> RobotParams:
    """The paper robot's controller parameters (:class:`uvms_mj.plant.params.RobotParams`): its
    model FILE plus nominal.overrides (never the plant)."""
    from uvms_mj.plant.robot import compile_robot_spec

    return read_params(compile_robot_spec(nominal_model_path(scenario.robot), scenario.nominal.overrides))


def nominal_robot(scenario: Scenario) -> NominalRobot:
    """The controller's own model (:class:`uvms_mj.control.nominal.NominalRobot`): the robot's
    model FILE (:func:`uvms_mj.plant.files.nominal_model_path`: the paper's ``models/uvms.xml``)
    plus nominal.overrides, with or without gravity and buoyancy (nominal.gravity); never the
    plant."""
    return NominalRobot(nominal_model_path(scenario.robot, scenario.base_dir), scenario.nominal.overrides,
                        gravity=scenario.nominal.gravity, tip_site=scenario.tip_site)


def _controller_defaults(scenario: Scenario) -> dict:
    """The controller's keyword defaults (the paper robot's PAPER_DEFAULTS on it), without
    the arguments the scenario supplies."""
    named, _ = _controller_signature(scenario.controller.name)
    params = {k: p.default for k, p in named.items() if p.default is not inspect.Parameter.empty}
    if scenario.robot == "paper":
        params.update(getattr(_factory(scenario.controller.name), "PAPER_DEFAULTS", {}))
    return params


def resolved(scenario: Scenario) -> dict:
    """The fully resolved scenario, JSON-serialisable (for log metadata): every default filled
    in, the drag model and log path resolved, the controller's parameters completed with the
    controller's own defaults. It is itself a valid scenario describing the same run."""
    d = scenario.model_dump(mode="json")
    d["plant"]["hydro"]["drag"] = drag_model(scenario)
    d["outputs"]["log"] = log_path(scenario).as_posix()
    named, var_kw = _controller_signature(scenario.controller.name)
    params = _controller_defaults(scenario)
    params.update(scenario.controller.params)
    T = controller_period(scenario)
    if "T" in named or "T" in params:
        params["T"] = T
    d["control_period"] = T
    d["controller"]["params"] = _jsonable(params)
    if d.get("navigation") is not None:
        d["navigation"] = resolved_navigation(scenario)
    return _jsonable(d)


def _add_to_spec(nav):
    from uvms_mj.sim.navsensors import add_to_spec

    return add_to_spec(nav)


def build(scenario: Scenario) -> tuple[Plant, Any]:
    """The plant (truth) and the controller of a scenario, for any robot.

    Raises:
        ScenarioError: a combination that only fails when built (e.g. overrides that conflict
            with the truth differences); the message names the scenario.
    """
    sc = scenario
    try:
        ph, pl, th = sc.physics, sc.plant, sc.thrusters
        plant = Plant(
            robot_path(sc.robot, sc.base_dir),
            overrides=plant_overrides(sc),
            terms=HydroTerms(added_mass=pl.hydro.added_mass, drag=drag_model(sc), buoyancy=pl.hydro.buoyancy),
            gravity=pl.gravity if not pl.gravity or ph.gravity is None else tuple(ph.gravity),
            current=(sc.current.current(sc.seed) if sc.current is not None
                     else tuple(pl.current) if pl.current is not None else None),
            waves=sc.waves.waves(sc.seed) if sc.waves is not None else None,
            # the paper's thrusters: the plant's dead-zone switch (the band is in its parameters, above);
            # MJCF thrusters: the thruster plugin's band (an override, above)
            dead_zone=bool(th.dead_zone) if sc.robot == "paper" else False,
            timestep=ph.timestep,
            integrator=ph.integrator,
            backend=None if ph.backend == "auto" else ph.backend,
            initial=sc.initial.state(),
            tip_site=sc.tip_site,
            failures=[f.failure() for f in th.failures],
            payload=pl.payload.payload() if pl.payload is not None else None,
            spec_edits=[_add_to_spec(nav)] if (nav := nav_config(sc)) is not None else (),
            tether=pl.tether.tether() if pl.tether is not None else None,
        )
        robot = nominal_robot(sc)
        name = sc.controller.name
        params = dict(sc.controller.params)
        if takes_argument(name, "T"):
            params["T"] = controller_period(sc)
        if takes_argument(name, "trajectory"):
            tip0 = robot.tip_at(plant.q) if robot.layout.tip_site >= 0 else None  # on the nominal geometry
            params["trajectory"] = None if tip0 is None else tip_path(sc.trajectory, tip0, sc.base_dir)
        names = plant.layout.joint_names
        if names and (named_argument(name, "arm_trajectory") or sc.arm.waypoints):
            params["arm_trajectory"] = sc.arm.joint_trajectory(names, plant.joint_angles)
        ref = sc.controller.base_reference
        if ref != "measured":
            a, n = plant.layout.base_qadr, plant.layout.base_nq
            if ref == "truth":
                params["base_reference"] = [float(v) for v in plant.q[a:a + n]]
            else:  # the model file's initial state (its initial keyframe, else qpos0)
                d = mujoco.MjData(robot.model)
                InitialState().apply(robot.model, d, robot.layout)
                params["base_reference"] = [float(v) for v in d.qpos[a:a + n]]
        params.update(vehicle_params(sc.vehicle, plant, sc.base_dir))
        ctrl = create(name, robot=robot, **params)
    except (ParameterError, ControllerError, ValueError, TypeError) as exc:
        raise ScenarioError(f"scenario {sc.name!r}: {exc}") from None
    return plant, ctrl


#: With sensors.delay = 1, the built-in RAC controllers stay stable only for Gamma and Lambda
#: entries up to this (measured on the paper scenario over 10 s: 0.15 holds, 0.2 diverges at
#: 2.8 s, the paper's 0.3 at 0.9 s).
DELAY_GAIN_MARGIN = 0.15


def scenario_warnings(scenario: Scenario) -> list[str]:
    """Warnings about valid but known-unstable combinations (one line each, naming the field)."""
    out = []
    c, s = scenario.controller, scenario.sensors
    if scenario.arm.waypoints and not getattr(_factory(c.name), "uses_arm_waypoints", True):
        out.append(f"arm.waypoints: controller {c.name!r} moves the arm by the tip task, not by joint waypoints "
                   "(they apply to joint-space controllers such as station_pid and task_priority)")
    if s.delay and c.name in ("rac", "rac_dob") and int(c.params.get("delay_compensation", 0) or 0) < s.delay:
        named, _ = _controller_signature(c.name)
        robot_defaults = getattr(_factory(c.name), "PAPER_DEFAULTS", {}) if scenario.robot == "paper" else {}
        gains = {k: c.params.get(k, robot_defaults.get(k, named[k].default if k in named else "auto"))
                 for k in ("gamma", "lam")}
        given = [v for v in gains.values() if not (v is None or isinstance(v, str))]  # "auto": has its margin
        g = max((float(np.max(np.asarray(v, dtype=float))) for v in given), default=0.0)
        if g > DELAY_GAIN_MARGIN:
            out.append(f"sensors.delay = {s.delay} with controller {c.name!r} and gains up to {g:g} (gamma, lam): "
                       "known to diverge within a few seconds; with one sample of delay the loop stays stable "
                       f"only for gains up to about {DELAY_GAIN_MARGIN:g} (measured on the paper scenario: 0.15 "
                       "holds, 0.2 diverges at 2.8 s, the paper's 0.3 at 0.9 s; docs/paper-reading.md \"Gains and "
                       "delay\"); \"auto\" gains or delay_compensation avoid it")
    return out


def run_scenario(
    scenario: Scenario,
    sink: Callable[[float, dict], None] | None = None,
    on_sample: Callable[[int, int], None] | None = None,
    built: tuple | None = None,
    nav_sink: Callable[[str, Any, dict], None] | None = None,
    keep: bool = True,
) -> RunResult:
    """Build and run a scenario (:func:`uvms_mj.sim.loop.run_closed_loop`). ``result.meta`` gains
    ``scenario`` (:func:`resolved`), ``name`` and ``backend``. ``built``: the (plant,
    controller) of :func:`build` if the caller built them already (fresh, never run).
    ``nav_sink``: receives the navigation samples; ``keep``: False streams the run (its rows to
    ``sink`` only, its metrics accumulated: memory that does not grow with the duration; see
    :func:`uvms_mj.sim.loop.run_closed_loop`)."""
    from uvms_mj.sim.loop import run_closed_loop

    plant, ctrl = built if built is not None else build(scenario)
    sensor = sensor_model(scenario)
    T = float(getattr(ctrl, "T", controller_period(scenario)))
    res = run_closed_loop(plant, ctrl, scenario.duration, T=T, sensor=sensor, seed=scenario.seed,
                          warm_start=scenario.warm_start, on_sample=on_sample, sink=sink,
                          navigation=nav_config(scenario), nav_sink=nav_sink,
                          feedback=scenario.controller.feedback, keep=keep)
    res.meta.update(name=scenario.name, backend=plant.backend, scenario=resolved(scenario))
    if plant.layout.base_free:  # a floating robot's logs describe it from its model
        from uvms_mj.scenario.robot import robot_info

        res.meta["robot"] = robot_info(scenario, plant)
    return res
