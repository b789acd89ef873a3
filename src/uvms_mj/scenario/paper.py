"""The paper robot's scenario schema (``robot: paper``, the default): everything a study of the
paper's experiment varies, in one validated YAML file.

A scenario is a YAML mapping loaded with ``yaml.safe_load`` and validated by the pydantic models
below (every section rejects unknown keys). Every field has an explicit default; the defaults
are the paper experiment (:class:`uvms_mj.sim.experiment.PaperExperiment`), so an empty file runs
exactly what ``PaperExperiment().run()`` runs. Units SI, world frame X horizontal, Y up.

.. code-block:: yaml

    name: paper                 # [A-Za-z0-9_.-]; default: the file name without .yaml
    description: ""
    duration: 40.0              # simulated time [s]
    seed: 0                     # sensor-noise random seed
    physics:
      timestep: 0.008333333333333333  # plant step [s] (the model's 1/120 s)
      integrator: rk4           # euler | rk4 | implicit | implicitfast (the model's rk4)
      backend: auto             # auto (native if it builds; $UVMS_MJ_COMPILED=off: python) | native | python
    plant:                      # the truth
      model_mismatch: true      # experiment.truth_overrides() (potential-flow added mass, +1 % base
                                #   volume, offset centre of buoyancy) and MuJoCo ellipsoid drag
      overrides: {}             # OVERRIDE_KEYS entries on top, e.g. {base.volume: 0.03}
      hydro:
        added_mass: exact       # exact | lagged | off
        drag: null              # strip | mujoco | off; null: mujoco if model_mismatch else strip
        buoyancy: true
      gravity: true
      current: [0.0, 0.0]       # uniform water current, world [vx, vy] [m/s]
    thrusters:                  # the plant's thrusters (the controller allocates as if ideal)
      tau: 0.02                 # first-order lag [s] (the model's)
      force_range: [-8.849, 15.978]  # [min, max] [N] (the model's)
      dead_zone: false          # zero commands inside dead_zone_band
      dead_zone_band: [-0.07772, 0.26944]  # [low, high] [N] (the model's)
    nominal:                    # the controller's model: the model FILE plus these, never the plant
      overrides: {}             # same keys as plant.overrides (thrusters.* included)
      gravity: true             # the controller compensates gravity and buoyancy
    sensors:                    # uvms_mj.sim.loop.SensorModel
      position_noise: 0.0       # std [m]
      angle_noise: 0.0          # std [rad]: shorthand for the two below
      attitude_noise: null      # std on the base attitude phi0 [rad]; null: angle_noise
      joint_noise: null         # std on the joint encoders phi1, phi2 [rad]; null: angle_noise
      position_quantum: 0.0     # [m], 0: none
      angle_quantum: 0.0        # [rad], 0: none
      delay: 0                  # samples: 0 | 1
      velocity_sensor: false
      velocity_noise: 0.0       # std [m/s, rad/s]
    controller:
      name: rac_dob             # uvms_mj.control.available()
      params: {}                # keyword arguments of the controller, e.g. {gamma: [0.3, 0.3, 0.2, 0.2, 0.2]}
      base_reference: measured  # the base's reference pose: measured (the first measurement) |
                                #   truth (the plant's initial pose) | nominal (the model file's keyframe)
    trajectory:                 # straight end-tip line with a trapezoidal speed profile
      curve: null               # or any uvms_mj.control.trajectories kind, e.g. {kind: circle, centre: [0, 0, 0],
                                #   radius: 0.05, period: 20}: world, z ignored, started at the initial tip
      target: null              # [x, y] world [m], or
      displacement: [0.3, 0.0]  # [dx, dy] from the initial tip position [m] (exactly one of the two)
      cruise_speed: 0.02        # [m/s]
      accel: 0.02               # [m/s^2]
      t_start: 1.0              # rest before moving [s]
    warm_start: true            # thrusters start at the first command (holding station)
    outputs:
      log: null                 # MCAP path; null: logs/<name>-<controller>.mcap
      video: false
      video_fps: 30
      video_size: [640, 480]    # [width, height] pixels
      plots: true

Loading, dispatch, resolution and building: :mod:`uvms_mj.scenario.schema`; the sections every
robot has (``initial``, ``current``, ``thrusters.failures``, ``vehicle``):
:mod:`uvms_mj.scenario.sections`.

The controller period T is ``controller.params.T`` (default: the controller's own, 1/60 s for
the built-ins); it must be a whole multiple of ``physics.timestep``.

Every numeric field is bounded (the constants below: ``DURATION_MAX``, ``TIMESTEP_RANGE``,
``PERIOD_RANGE``, ...; ``thrusters.tau`` also by ``LAG_STABILITY``); booleans are never
numbers. Files are read with ``FILE_SIZE_MAX``, ``DEPTH_MAX`` and without YAML aliases.
:func:`scenario_warnings` lists valid but known-unstable combinations.

Errors (:class:`ScenarioError`, a ValueError) name the file, the field path (e.g.
``controller.params.gamma``), the bad value and what is allowed, one line per problem; unknown
keys come with a did-you-mean suggestion; YAML syntax errors with line and column.

``controller.params`` belong to ``controller.name``; ``controllers: {name: params, ...}`` gives
any controller its own parameters (used by ``compare`` and by ``--set controller.name=...``:
a controller named on the command line gets ``controllers[name]``, else its defaults, never the
file controller's parameters).

Overrides from the command line (``sets``, ``key.path=value``): :func:`uvms_mj.scenario.schema.apply_sets`.
"""

from __future__ import annotations

import copy
import inspect
import math
from functools import lru_cache
from typing import Annotated, Any, Callable, Literal, Sequence

import mujoco
from pydantic import Field, field_validator, model_validator

from uvms_mj.control import available, create
from uvms_mj.control.nominal import NominalRobot
from uvms_mj.control.trajectories import Line3D
from uvms_mj.plant.params import (
    HYDRO_BODIES,
    OVERRIDE_KEYS,
    ParameterError,
    compile_robot,
    read_params,
)
from uvms_mj.plant.plant import default_model_path, models_dir
from uvms_mj.scenario.sections import (
    CurrentSection,
    Failure,
    Initial,
    PlantSection,
    ThrustersSection,
    Vehicle,
    vehicle_issues,
)
from uvms_mj.scenario.base import (  # noqa: F401  (shared names, used here and by uvms_mj.scenario.robot)
    ControllerSection,
    Hydro,
    NominalSection,
    PhysicsSection,
    sensor_issues,
    _NO_VALUE,
    ACCEL_MAX,
    CURRENT_MAX,
    DESCRIPTION_MAX,
    DURATION_MAX,
    LAG_STABILITY,
    NAME_MAX,
    PARAM_ABS_MAX,
    PERIOD_RANGE,
    SEED_MAX,
    SIZE_MIN,
    SPEED_MAX,
    TAU_MAX,
    TIMESTEP_RANGE,
    ForceVec2,
    LengthVec2,
    Outputs,
    Sensors,
    _take_controller_params,
    _controller_signature,
    _factory,
    _has_bool,
    _is_number,
    _Issues,
    _non_finite,
    _out_of_range,
    _Section,
    _suggest,
    creation_errors,
)

__all__ = ["ControllerSection", "NominalSection", "PhysicsSection", "PlantSection", "Scenario", "Thrusters",
           "TrajectorySection", "paper_controller_period"]


# --------------------------------------------------------------------------- model-file defaults


@lru_cache(maxsize=1)
def _plant_model() -> mujoco.MjModel:
    """The default plant model (compiled once; callers copy it before changing it)."""
    return compile_robot(default_model_path())


@lru_cache(maxsize=1)
def _robot_file_model() -> mujoco.MjModel:
    """The robot model file the nominal model is read from (compiled once; copy before use)."""
    return compile_robot(models_dir() / "uvms.xml")


@lru_cache(maxsize=1)
def _model_defaults() -> dict:
    m = _plant_model()
    p = read_params(m)
    thr = p.thrusters[0]
    return {
        "timestep": float(m.opt.timestep),
        "integrator": mujoco.mjtIntegrator(m.opt.integrator).name.removeprefix("mjINT_").lower(),
        "tau": float(thr.tau),
        "force_range": [float(v) for v in thr.force_range],
        "dead_zone_band": [float(v) for v in p.dead_zone],
    }


def _default(key: str) -> Callable[[], Any]:
    return lambda: copy.deepcopy(_model_defaults()[key])


#: Parameter override keys with the body placeholder expanded (base.mass, link1.mass, ...).
OVERRIDE_NAMES: tuple[str, ...] = tuple(
    k2 for k in OVERRIDE_KEYS for k2 in ([k.replace("BODY", b) for b in HYDRO_BODIES] if "BODY" in k else [k])
)


# --------------------------------------------------------------------------- helpers


def _check_overrides(overrides: dict, allow_thrusters: bool) -> list[tuple[tuple, str, Any]]:
    """Each override is valid on its own (applied to a copy of the model file, then re-read
    with read_params' physical checks): a key of the paper robot's vocabulary (OVERRIDE_KEYS:
    ``base.added_mass`` = [m_Ax, m_Ay, I_A], ...) or any element by name
    (:func:`uvms_mj.plant.robot.apply_overrides`: ``joint1.damping``, the ``vehicle`` role), a
    value absolute or a factor ``"x1.3"``."""
    from uvms_mj.plant.robot import compile_robot_spec, factor_of

    issues = []
    for key, value in overrides.items():
        if not isinstance(key, str):
            issues.append(((key,), "an override key is '<element>.<field>' or a key of the paper robot's "
                           "parameters", _NO_VALUE))
            continue
        planar = key in OVERRIDE_NAMES
        if planar and not allow_thrusters and key.startswith("thrusters."):
            field = key.partition(".")[2]
            field = "dead_zone_band" if field == "dead_zone" else field
            issues.append(((key,), f"set the plant's thrusters in the thrusters section (thrusters.{field})", value))
            continue
        try:
            is_factor = factor_of(value) is not None
        except ParameterError as exc:
            issues.append(((key,), str(exc), _NO_VALUE))
            continue
        what = OVERRIDE_KEYS[_generic(key)] if planar else "see uvms_mj.plant.robot.OVERRIDE_FIELDS"
        if not is_factor:
            ok = _is_number(value) or (isinstance(value, list) and value and all(_is_number(v) for v in value))
            if not ok:
                issues.append(((key,), f"must be a number, a list of numbers or a factor 'x1.3' ({what})", value))
                continue
            if _non_finite(value):
                issues.append(((key,), "must be finite", value))
                continue
            if _out_of_range(value):
                issues.append(((key,), f"numbers must be 0 or within {SIZE_MIN:g} to {PARAM_ABS_MAX:g} in magnitude",
                               value))
                continue
        try:
            read_params(compile_robot_spec(models_dir() / "uvms.xml", {key: value}))
        except ParameterError as exc:
            msg = str(exc)
            if "the model has no body, joint or actuator named" in msg:
                msg += ("; or a key of the paper robot's parameters: "
                        + ", ".join(k.replace("BODY", "{" + ",".join(HYDRO_BODIES) + "}") for k in OVERRIDE_KEYS))
                issues.append(((key,), msg, _NO_VALUE))
            else:
                issues.append(((key,), f"{msg} ({what})", value))
    return issues


def _generic(key: str) -> str:
    head, _, field = key.partition(".")
    return f"BODY.{field}" if head in HYDRO_BODIES else key


@lru_cache(maxsize=1)
def _file_nominal() -> NominalRobot:
    return NominalRobot(models_dir() / "uvms.xml")


_PROBE_PATH = Line3D(start=(0.0, 0.0, 0.0), target=(0.3, 0.0, 0.0))


def _check_controller_params(name: str, params: dict) -> list[tuple[tuple, str, Any]]:
    """Unknown parameters (with did-you-mean) and the controller's own errors, each attributed
    to the parameter that causes it (found by creating the controller with it alone)."""
    named, var_kw = _controller_signature(name)
    # Unknown keys are errors, except for plug-in controllers taking **kwargs (which may use them);
    # the built-in pd swallows other controllers' parameters, so a typo there would pass unseen.
    strict = not var_kw or getattr(_factory(name), "__module__", "").startswith("uvms_mj.control.")
    issues = []
    for key, value in params.items():
        if strict and key not in named:
            issues.append(((key,), f"{key!r} is not a parameter of controller {name!r}{_suggest(key, named)}; allowed: "
                           + ", ".join(named), _NO_VALUE))
        elif _non_finite(value):
            issues.append(((key,), "must be finite", value))
        elif _has_bool(value) and not (key in named and isinstance(named[key].default, bool)):
            issues.append(((key,), "must be a number, not a boolean (true/false)", value))
        elif _out_of_range(value):
            issues.append(((key,), f"numbers must be 0 or within {SIZE_MIN:g} to {PARAM_ABS_MAX:g} in "
                           "magnitude", value))
    if issues:
        return issues

    return creation_errors(lambda kw: create(name, trajectory=_PROBE_PATH, robot=_file_nominal(), **kw), params)


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


# --------------------------------------------------------------------------- schema

class PaperPlantSection(PlantSection):
    """The plant section (:class:`uvms_mj.scenario.sections.PlantSection`, every robot's) with the
    paper robot's checks: its overrides against its model file, no overrides file."""

    @field_validator("overrides")
    @classmethod
    def _overrides(cls, v: dict) -> dict:
        issues = _check_overrides(v, allow_thrusters=False)
        if issues:
            raise _Issues(issues)
        return v

    @field_validator("overrides_file")
    @classmethod
    def _no_file(cls, v: str | None) -> str | None:
        if v is not None:
            raise ValueError("applies to MJCF robots; on the paper's robot give plant.overrides")
        return v


class PaperNominalSection(NominalSection):
    """The nominal section (every robot's) with the paper robot's check of its overrides."""

    @field_validator("overrides")
    @classmethod
    def _overrides(cls, v: dict) -> dict:
        issues = _check_overrides(v, allow_thrusters=True)
        if issues:
            raise _Issues(issues)
        return v


class Thrusters(ThrustersSection):
    """The thrusters section (:class:`uvms_mj.scenario.sections.ThrustersSection`, every robot's) on
    the paper's robot: tau, force_range and dead_zone_band default to the model file's (filled in),
    dead_zone true / false / a band [N]."""

    @model_validator(mode="after")
    def _ranges(self) -> "Thrusters":
        _fill_thrusters(self)
        issues = []
        lo, hi = self.force_range
        if not lo < 0 < hi:
            issues.append((("force_range",), "must satisfy min < 0 < max [N]", self.force_range))
        if self.tau <= 0:
            issues.append((("tau",), "must be > 0 s (the paper's thrusters are lagged)", self.tau))
        for key in ("dead_zone_band",) + (("dead_zone",) if isinstance(self.dead_zone, list) else ()):
            lo, hi = getattr(self, key)
            if not lo <= 0 <= hi:
                issues.append(((key,), "must satisfy low <= 0 <= high [N]", getattr(self, key)))
        if issues:
            raise _Issues(issues)
        return self


def _fill_thrusters(th: ThrustersSection) -> None:
    """The paper robot's thruster defaults: the model file's tau, force range and dead-zone band."""
    if th.tau is None:
        th.tau = _default("tau")()
    if th.force_range is None:
        th.force_range = _default("force_range")()
    if th.dead_zone_band is None:
        th.dead_zone_band = _default("dead_zone_band")()
    if th.dead_zone is None:
        th.dead_zone = False


class PaperControllerSection(ControllerSection):
    """The controller section (:class:`uvms_mj.scenario.base.ControllerSection`, every robot's) on
    the paper's robot: default ``rac_dob``, its parameters checked by creating it."""

    name: str = Field("rac_dob", description="one of uvms_mj.control.available()")

    @field_validator("name")
    @classmethod
    def _name(cls, v: str) -> str:
        names = available()
        if v not in names:
            from uvms_mj.control.registry import unknown_message

            raise ValueError(unknown_message(v))
        return v

    @model_validator(mode="after")
    def _params(self) -> "PaperControllerSection":
        issues = _check_controller_params(self.name, self.params)
        if issues:
            raise _Issues([(("params",) + p, m, v) for p, m, v in issues])
        if self.base_reference != "measured":
            named, _ = _controller_signature(self.name)
            if "base_reference" not in named:
                raise _Issues([(("base_reference",), f"controller {self.name!r} takes no base reference; "
                                "allowed: measured", self.base_reference)])
            if self.params.get("base_reference") is not None:
                raise _Issues([(("base_reference",), "give either base_reference or params.base_reference, "
                                "not both", self.base_reference)])
        return self


class TrajectorySection(_Section):
    """Straight end-tip line in the plane (:class:`uvms_mj.control.trajectories.Line3D`, z = 0)."""

    target: LengthVec2 | None = Field(None, description="end point, world [x, y] [m]")
    displacement: LengthVec2 | None = Field(None, description="end point minus the initial tip position [m]; "
                                      "default [0.3, 0.0] when target is not given")
    cruise_speed: float = Field(0.02, ge=SIZE_MIN, le=SPEED_MAX, description="[m/s]")
    accel: float = Field(0.02, ge=SIZE_MIN, le=ACCEL_MAX, description="[m/s^2]")
    t_start: float = Field(1.0, ge=0, le=DURATION_MAX, description="rest before moving [s]")
    curve: dict[str, Any] | None = Field(
        None, description="instead of the line: any uvms_mj.control.trajectories kind ({kind: waypoints|circle|lemniscate|"
        "helix|csv|line, ...}, world [x, y, z], z ignored: the paper's plane), shifted to start at the initial tip; "
        "for controllers that take any trajectory (rac, rac_dob)")

    @field_validator("curve")
    @classmethod
    def _curve(cls, v: dict | None) -> dict | None:
        if v is not None:
            from uvms_mj.control.trajectories import make_trajectory

            try:
                make_trajectory(v)
            except ValueError as exc:
                msg = str(exc)
                raise _Issues([((), msg[len("trajectory."):] if msg.startswith("trajectory.") else msg, _NO_VALUE)]) \
                    from None
        return v

    @model_validator(mode="after")
    def _one_end(self) -> "TrajectorySection":
        if self.target is not None and self.displacement is not None:
            raise _Issues([((), "give exactly one of target (world [x, y]) and displacement ([dx, dy] from the "
                            "initial tip), not both", {"target": self.target, "displacement": self.displacement})])
        if self.target is None and self.displacement is None:
            self.displacement = [0.3, 0.0]
        return self


class Scenario(_Section):
    """A whole scenario (defaults: the paper experiment)."""

    name: str = Field("scenario", pattern=r"^[A-Za-z0-9][A-Za-z0-9_.-]*$", max_length=NAME_MAX,
                      description="letters, digits, _ . -; default in files: the file name")
    description: str = Field("", max_length=DESCRIPTION_MAX)
    robot: Literal["paper"] = Field("paper", description="the paper's planar robot (other robots: "
                                    "uvms_mj.scenario.robot.RobotScenario)")
    duration: float = Field(40.0, gt=0, le=DURATION_MAX, description="simulated time [s]")
    seed: int = Field(0, ge=0, le=SEED_MAX, description="random seed of the sensor noise")
    physics: PhysicsSection = Field(default_factory=PhysicsSection)
    plant: PaperPlantSection = Field(default_factory=PaperPlantSection)
    thrusters: Thrusters = Field(default_factory=Thrusters)
    nominal: PaperNominalSection = Field(default_factory=PaperNominalSection)
    sensors: Sensors = Field(default_factory=Sensors)
    controller: PaperControllerSection = Field(default_factory=PaperControllerSection)
    trajectory: TrajectorySection = Field(default_factory=TrajectorySection)
    initial: Initial = Field(default_factory=Initial, description="the initial state (default: the model's "
                             "keyframe paper_initial); joints by name (joint1, joint2)")
    current: CurrentSection | None = Field(None, description="the water current (constant, gauss_markov, profile); "
                                           "plant.current is the older spelling of a constant one")
    vehicle: Vehicle = Field(default_factory=Vehicle, description="the base's setpoint")
    controllers: dict[str, dict[str, Any]] = Field(
        default_factory=dict, description="per-controller parameters for compare / --set controller.name: "
        "name -> params (controller.params belong to controller.name)")
    warm_start: bool = Field(True, description="thrusters start at the first command (holding station)")
    outputs: Outputs = Field(default_factory=Outputs)

    @field_validator("controllers")
    @classmethod
    def _controllers(cls, v: dict) -> dict:
        issues = []
        names = available()
        for name, params in v.items():
            if name not in names:
                from uvms_mj.control.registry import unknown_message

                issues.append(((name,), unknown_message(name).replace(f"controller {name!r}", "controller", 1),
                               _NO_VALUE))
            elif not isinstance(params, dict):
                issues.append(((name,), "must be a mapping of parameter names to values", params))
            else:
                issues += [((name,) + p, m, x) for p, m, x in _check_controller_params(name, params)]
        if issues:
            raise _Issues(issues)
        return v

    @model_validator(mode="after")
    def _period(self) -> "Scenario":
        if self.plant.model_mismatch is None:  # (a default plant section: no field validator ran)
            self.plant.model_mismatch = True
        if self.plant.current is None:
            self.plant.current = [0.0, 0.0]
        _fill_thrusters(self.thrusters)  # (a default thrusters section: no validator ran)
        ph = self.physics  # null: the model file's (what a resolved scenario shows)
        if ph.timestep is None:
            ph.timestep = _default("timestep")()
        if ph.integrator is None:
            ph.integrator = _default("integrator")()
        _take_controller_params(self)
        T = paper_controller_period(self)
        dt = self.physics.timestep
        if not (math.isfinite(T) and PERIOD_RANGE[0] <= T <= PERIOD_RANGE[1]):
            raise _Issues([(("controller", "params", "T"),
                            f"the controller period must be within [{PERIOD_RANGE[0]:g}, {PERIOD_RANGE[1]:g}] s", T)])
        sub = T / dt
        if abs(sub - round(sub)) > 1e-9 or round(sub) < 1:
            raise _Issues([(("controller", "params", "T"),
                            f"the controller period must be a whole multiple of physics.timestep = {dt!r} s", T)])
        # The thrusters' first-order lag is integrated by the plant's integrator: explicitly (Euler;
        # RK4 with its larger stability region), so dt / tau beyond the integrator's bound diverges.
        bound = LAG_STABILITY[self.physics.integrator]
        tau = self.thrusters.tau
        if dt / tau >= bound:
            raise _Issues([(("thrusters", "tau"),
                            f"unstable with the {self.physics.integrator} integrator at physics.timestep = "
                            f"{dt:.6g} s: the lag integrates stably only for tau > timestep / {bound} = "
                            f"{dt / bound:.6g} s", tau)])
        issues = _robot_sections_issues(self) + sensor_issues(self.sensors, T)
        if issues:
            raise _Issues(issues)
        return self


def _robot_sections_issues(sc: "Scenario") -> list:
    """The sections every robot has (initial, current, thrusters.failures, vehicle), checked
    against the paper robot's model."""
    from uvms_mj.plant.layout import Layout

    m = _plant_model()
    lay = Layout.of(m, allow_planar=True)
    issues = []
    try:
        sc.initial.state().apply(m, mujoco.MjData(m), lay)
    except ParameterError as exc:
        issues.append((("initial",), str(exc).removeprefix("initial."), _NO_VALUE))
    if sc.current is not None and any(sc.plant.current):
        issues.append((("plant", "current"), "give the current in one place: the current section "
                       "(current.velocity) or plant.current, not both", sc.plant.current))
    for i, f in enumerate(sc.thrusters.failures):
        if f.thruster not in lay.thruster_names:
            issues.append((("thrusters", "failures", i, "thruster"), f"not a thruster of the paper's robot"
                           f"{_suggest(f.thruster, lay.thruster_names)}; thrusters: {', '.join(lay.thruster_names)}",
                           f.thruster))
    if sc.vehicle.trajectory is not None:
        issues.append((("vehicle", "trajectory"), "the paper's robot takes a vehicle setpoint only (its controllers "
                       "carry the arm's tip on the trajectory section)", _NO_VALUE))
    if sc.vehicle.setpoint is not None and sc.controller.base_reference != "measured":
        issues.append((("vehicle", "setpoint"), "give either vehicle.setpoint or controller.base_reference, not both",
                       _NO_VALUE))
    issues += vehicle_issues(Vehicle(setpoint=sc.vehicle.setpoint), sc.controller.name, sc.controller.params)
    return issues


def paper_controller_period(scenario: "Scenario") -> float:
    """The paper scenario's controller period T [s]: controller.params.T, else the controller's
    default (1/60 s for the built-ins)."""
    params = scenario.controller.params
    if "T" in params:
        return float(params["T"])
    named, _ = _controller_signature(scenario.controller.name)
    p = named.get("T")
    if p is not None and p.default is not inspect.Parameter.empty and _is_number(p.default):
        return float(p.default)
    from uvms_mj.control.digital import PAPER_T

    return PAPER_T
