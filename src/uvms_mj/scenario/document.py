"""The scenario: one validated YAML document for every robot.

A scenario is a YAML mapping loaded with a safe loader (:mod:`uvms_mj.scenario.schema`) and
validated by :class:`Scenario`; every section rejects unknown keys. ``robot`` picks the robot: a
built-in name (:data:`uvms_mj.plant.files.BUILTIN_ROBOTS`; ``paper``, the default, is the
paper's planar robot) or an MJCF file (relative to the scenario file). Every section applies to
every robot; the few values that apply to one robot only say so in one line when given to
another (:mod:`uvms_mj.scenario.paper`: the paper robot's own parameter keys, model mismatch,
lagged added mass, MuJoCo drag; :mod:`uvms_mj.scenario.robot`: an overrides file). Element
names (joints, thrusters, sites, keyframes) are checked against the robot's model, with
did-you-mean suggestions. Units SI; world frame (the paper's: X horizontal, Y up; the
BlueROV2 models': z up).

A null default is the robot's own, filled in when the scenario is validated (``uvms-mj validate
--resolved`` shows them all):

.. code-block:: yaml

    name: paper                 # [A-Za-z0-9_.-]; default in files: the file name
    description: ""
    robot: paper                # built-in name or MJCF path
    tip_site: null              # end-effector site; null: the first site named *tip
    duration: null              # [s]; null: 40 on the paper's robot (its experiment), 20 on others
    seed: 0                     # random seed (sensor noise, Gauss-Markov current)
    physics:
      timestep: null            # plant step [s]; null: the model's (paper 1/120 s, bluerov2_heavy 5 ms, bluerov2_alpha 4 ms)
      integrator: null          # euler | rk4 | implicit | implicitfast; null: the model's
      backend: auto             # auto (native if it builds; $UVMS_MJ_COMPILED=off: python) | native | python
      gravity: null             # the plant's gravity [m/s^2, world], e.g. [0, 0, -9.82]; null: the model's
    plant:                      # the truth
      model_mismatch: null      # paper's robot: experiment.truth_overrides() + MuJoCo drag (null: true)
      overrides: {}             # '<element>.<field>': value or factor 'x1.3'; the vehicle role
                                #   (vehicle.added_mass); the paper's robot: its own keys (base.volume)
      overrides_file: null      # MJCF robots: a YAML file of overrides (uvms-mj identify writes one)
      hydro: {added_mass: exact, drag: null, buoyancy: true}
      gravity: true
      current: null             # world [m/s] (older spelling of current.velocity); null: still water
      payload: null             # {mass, t, site, ...}: picked up during the run
      tether: null              # MJCF robots: {length, segments, anchor, attach, diameter, mass_per_length,
                                #   cn, ct, added_mass, damping, surface} (von Benzon et al. 2022's defaults)
    current: null               # {velocity} | {gauss_markov: {...}} | {profile: [...]}
    waves: null                 # {model: airy|jonswap|pierson_moskowitz, height|hs, period|tp, gamma,
                                #   direction, spreading, depth (null: deep), surface, seed, n_components}
    thrusters:                  # lag, limits, dead zone (null: the model's), failures
      tau: null
      force_range: null
      dead_zone: null
      failures: []              # [{thruster: name, t: s}]
    nominal:                    # the controller's model: the robot FILE plus these, never the plant
      overrides: {}
      gravity: true
    initial: {}                 # pose, joints by name, velocities (null: the model's keyframe)
    sensors: {}                 # flat fields, or per signal: position / attitude / joints / velocity
    navigation: null            # {imu, dvl, depth, fix}: navigation sensors on sites (MJCF robots;
                                #   uvms_mj.scenario.navigation); to the controller with controller.feedback: estimate
    vehicle:                    # the vehicle's setpoint or trajectory (controller's base reference)
      setpoint: null
      trajectory: null
    trajectory:                 # the end-effector's path (uvms_mj.scenario.paths); absent: the
      kind: line                #   paper's robot: this line (0.3 m along x); others: hold the tip
      displacement: [0.3, 0.0]
    arm: {waypoints: []}        # joint waypoints (for controllers taking arm_trajectory)
    control_period: null        # T [s]; null: the controller's own on the paper's robot (1/60 s),
                                #   0.02 s on others (a multiple of the BlueROV2 models' 2 ms step)
    controller:
      name: null                # null: rac_dob on the paper's robot (the paper's method), station_pid on others
      params: {}                # keyword arguments of the controller (params.T: the period)
      base_reference: measured  # measured | truth | nominal
      feedback: truth           # truth (the sensors section's measured truth) | estimate (the ESKF on the
                                #   navigation section's samples, online; needs navigation.imu and a fix or depth)
    controllers: {}             # name -> params, for compare / --set controller.name=...
    warm_start: true            # thrusters start at the first command (holding station)
    outputs: {log: null, video: false, video_fps: 30, video_size: [640, 480], plots: true}

Every numeric field is bounded (:mod:`uvms_mj.scenario.base`); booleans are never numbers.
Errors (:class:`uvms_mj.scenario.base.ScenarioError`) name the file, the field path, the bad
value and what is allowed, one line per problem.
"""

from __future__ import annotations

import inspect
import math
from functools import lru_cache
from pathlib import Path
from typing import Any

import mujoco
from pydantic import Field, ValidationInfo, field_validator, model_validator

from uvms_mj.control import ControllerError, available, create
from uvms_mj.plant.errors import ParameterError
from uvms_mj.plant.files import nominal_model_path, robot_path
from uvms_mj.plant.layout import Layout
from uvms_mj.scenario.base import (
    _NO_VALUE,
    DESCRIPTION_MAX,
    DURATION_MAX,
    LAG_STABILITY,
    NAME_MAX,
    PARAM_ABS_MAX,
    PERIOD_RANGE,
    SEED_MAX,
    SIZE_MIN,
    TIMESTEP_RANGE,
    ControllerSection,
    NominalSection,
    Outputs,
    PhysicsSection,
    Sensors,
    _controller_signature,
    _factory,
    _has_bool,
    _Issues,
    _is_number,
    _non_finite,
    _out_of_range,
    _Section,
    _suggest,
    _take_controller_params,
    creation_errors,
    sensor_issues,
    takes_argument,
)
from uvms_mj.scenario.paper import (
    paper_fill,
    paper_issues,
    paper_nominal_issues,
    paper_plant_issues,
    paper_thrusters_issues,
)
from uvms_mj.scenario.navigation import NavigationSection, navigation_issues
from uvms_mj.scenario.paths import Arm, TrajectorySection, tip_path
from uvms_mj.scenario.robot import mjcf_nominal_issues, mjcf_plant_issues, mjcf_thrusters_issues
from uvms_mj.scenario.sections import (CurrentSection, Initial, PlantSection, ThrustersSection, Vehicle, WavesSection,
                                       vehicle_issues)

__all__ = ["DEFAULT_CONTROLLER", "DEFAULT_DURATION", "DEFAULT_PERIOD", "Scenario", "controllers_for", "robot_model"]

#: The default controller: the paper's method on its robot; the baseline on every other robot
#: (whose model the paper's gains were not chosen for).
DEFAULT_CONTROLLER = {"paper": "rac_dob", None: "station_pid"}
#: The default duration [s]: the paper's experiment (40 s) on its robot, 20 s on others.
DEFAULT_DURATION = {"paper": 40.0, None: 20.0}
#: The default controller period [s] on robots other than the paper's: 50 Hz, a whole multiple
#: of the BlueROV2 models' 2 ms step (the paper's 1/60 s is not). The paper's robot: the
#: controller's own default (1/60 s for the built-ins, the paper's).
DEFAULT_PERIOD = 0.02


def _by_robot(table: dict, robot: str) -> Any:
    return table["paper"] if robot == "paper" else table[None]


_MODELS: dict[str, tuple] = {}


def robot_model(robot: str, base_dir: str | None = None) -> tuple[Path, mujoco.MjModel, Layout]:
    """(path, compiled model file without overrides, layout) of a scenario's robot, cached by
    path (callers copy the model before changing it).

    Raises:
        ParameterError: no such robot, or a model the plant cannot take."""
    path = robot_path(robot, base_dir)
    key = str(path)
    if key not in _MODELS:
        from uvms_mj.plant.robot import compile_robot_spec

        m = compile_robot_spec(path)
        _MODELS[key] = (path, m, Layout.of(m, allow_planar=True))
    return _MODELS[key]


_NOMINALS: dict[tuple, Any] = {}


def _nominal(robot: str, base_dir: str | None, tip_site: str | None):
    from uvms_mj.control.nominal import NominalRobot

    path = nominal_model_path(robot, base_dir)
    key = (str(path), tip_site)
    if key not in _NOMINALS:
        _NOMINALS[key] = NominalRobot(path, tip_site=tip_site)
    return _NOMINALS[key]


def _works_on(name: str, robot: str) -> bool | None:
    """Whether controller ``name`` works on ``robot`` (as :func:`controllers_for` decides), None if no
    controller has that name. A built-in's answer needs no entry-point scan (importlib.metadata, tens of
    ms of validate's time): only the messages that list the controllers do."""
    try:
        f = _factory(name)
    except Exception:  # noqa: BLE001 - unknown, or a broken plug-in (not offered by controllers_for)
        return None
    return robot == "paper" or getattr(f, "robots", "paper") in ("floating", "any")


def controllers_for(robot: str) -> list[str]:
    """The registered controllers that work on ``robot``: every one on the paper's robot; on
    others those whose class says ``robots = "floating"`` or ``"any"``."""
    if robot == "paper":
        return available()
    out = []
    for n in available():
        try:
            f = _factory(n)
        except Exception:  # noqa: BLE001 - a broken plug-in is not offered
            continue
        if getattr(f, "robots", "paper") in ("floating", "any"):
            out.append(n)
    return out


@lru_cache(maxsize=1)
def _probe_path():
    from uvms_mj.control.trajectories import Line3D

    return Line3D(start=(0.0, 0.0, 0.0), target=(0.3, 0.0, 0.0))


def check_controller_params(name: str, params: dict, nominal) -> list[tuple[tuple, str, Any]]:
    """Unknown parameters (with did-you-mean), non-finite, boolean or out-of-range numbers, and
    the controller's own errors when created on ``nominal`` (each attributed to the parameter
    that causes it, found by creating the controller with it alone)."""
    named, var_kw = _controller_signature(name)
    allowed = named  # (without the arguments the scenario gives: robot, trajectory, arm_trajectory)
    # Unknown keys are errors, except for plug-in controllers taking **kwargs (which may use them).
    strict = not var_kw or getattr(_factory(name), "__module__", "").startswith("uvms_mj.control.")
    issues = []
    for key, value in params.items():
        if strict and key not in allowed:
            issues.append(((key,), f"{key!r} is not a parameter of controller {name!r}{_suggest(key, allowed)}; "
                           "allowed: " + ", ".join(allowed), _NO_VALUE))
        elif _non_finite(value):
            issues.append(((key,), "must be finite", value))
        elif _has_bool(value) and not (key in named and isinstance(named[key].default, bool)):
            issues.append(((key,), "must be a number, not a boolean (true/false)", value))
        elif _out_of_range(value):
            issues.append(((key,), f"numbers must be 0 or within {SIZE_MIN:g} to {PARAM_ABS_MAX:g} in magnitude",
                           value))
    if issues:
        return issues
    extra = {}
    if takes_argument(name, "trajectory") and nominal.layout.tip_site >= 0:
        extra["trajectory"] = _probe_path()
    return creation_errors(lambda kw: create(name, robot=nominal, **extra, **kw), params)


class Scenario(_Section):
    """A whole scenario, for any robot (module docstring)."""

    name: str = Field("scenario", pattern=r"^[A-Za-z0-9][A-Za-z0-9_.-]*$", max_length=NAME_MAX,
                      description="letters, digits, _ . -; default in files: the file name")
    description: str = Field("", max_length=DESCRIPTION_MAX)
    base_dir: str | None = Field(None, exclude=True, description="(set by the loader) the scenario file's folder")
    robot: str = Field("paper", min_length=1, max_length=4096, description="a built-in robot "
                       "(uvms_mj.plant.files.BUILTIN_ROBOTS; paper: the paper's planar robot) or an MJCF path")
    tip_site: str | None = Field(None, description="end-effector site; null: the first site named *tip")
    duration: float | None = Field(None, gt=0, le=DURATION_MAX, description="simulated time [s]; null: 40 on the "
                                   "paper's robot (its experiment), 20 on others")
    seed: int = Field(0, ge=0, le=SEED_MAX, description="random seed (sensor noise, Gauss-Markov current)")
    physics: PhysicsSection = Field(default_factory=PhysicsSection)
    plant: PlantSection = Field(default_factory=PlantSection)
    thrusters: ThrustersSection = Field(default_factory=ThrustersSection)
    nominal: NominalSection = Field(default_factory=NominalSection)
    initial: Initial = Field(default_factory=Initial, description="the initial state (default: the model's "
                             "initial keyframe, else qpos0)")
    current: CurrentSection | None = Field(None, description="the water current (constant, gauss_markov, profile); "
                                           "plant.current is the older spelling of a constant one")
    waves: WavesSection | None = Field(None, description="linear waves (airy, jonswap, pierson_moskowitz); the "
                                       "current adds to them; null: the model's (none in the shipped models)")
    vehicle: Vehicle = Field(default_factory=Vehicle, description="the vehicle's setpoint or trajectory")
    sensors: Sensors = Field(default_factory=Sensors)
    navigation: NavigationSection | None = Field(None, description="navigation sensors (IMU, DVL, depth, fixes) on "
                                                 "sites of the model (uvms_mj.scenario.navigation); logged; fed to "
                                                 "the controller through the ESKF with controller.feedback: estimate")
    trajectory: TrajectorySection | None = Field(
        None, description="the end-effector's path (uvms_mj.scenario.paths); absent: the paper's line on the "
        "paper's robot, none (hold the initial tip) on others; null: hold the initial tip")
    arm: Arm = Field(default_factory=Arm)
    control_period: float | None = Field(None, ge=PERIOD_RANGE[0], le=PERIOD_RANGE[1], description=(
        "controller period T [s] (controller.params.T wins); null: the controller's own on the paper's robot "
        "(1/60 s), 0.02 s on others"))
    controller: ControllerSection = Field(default_factory=ControllerSection)
    controllers: dict[str, dict[str, Any]] = Field(
        default_factory=dict, description="per-controller parameters for compare / --set controller.name: "
        "name -> params (controller.params belong to controller.name)")
    warm_start: bool = Field(True, description="thrusters start at the first command (holding station)")
    outputs: Outputs = Field(default_factory=Outputs)

    @model_validator(mode="before")
    @classmethod
    def _older_spellings(cls, data: Any) -> Any:
        """``trajectory_origin`` (the older spelling of ``trajectory.origin``)."""
        if isinstance(data, dict) and "trajectory_origin" in data:
            data = dict(data)
            origin = data.pop("trajectory_origin")
            traj = data.get("trajectory")
            if isinstance(traj, dict):
                if "origin" in traj and traj["origin"] != origin:
                    raise _Issues([(("trajectory_origin",), "the older spelling of trajectory.origin: give one",
                                    origin)])
                data["trajectory"] = {**traj, "origin": origin}
            elif origin not in ("tip", "world"):
                raise _Issues([(("trajectory_origin",), "must be tip or world (trajectory.origin)", origin)])
        return data

    # Each section's robot-dependent checks run as the section's own validator (so that they are
    # reported beside the other sections' errors); what spans sections, in _robot_rules.

    @field_validator("robot")
    @classmethod
    def _robot(cls, v: str, info: ValidationInfo) -> str:
        try:
            robot_model(v, info.data.get("base_dir"))
        except (ParameterError, ValueError) as exc:
            raise _Issues([((), str(exc).split(": ", 1)[-1], v)]) from None
        return v

    @field_validator("plant")
    @classmethod
    def _plant(cls, v: PlantSection, info: ValidationInfo) -> PlantSection:
        r = _robot_of(info)
        if r is not None:
            _raise(paper_plant_issues(v) if r[0] == "paper" else mjcf_plant_issues(v, r[2], r[1]))
        return v

    @field_validator("nominal")
    @classmethod
    def _nominal(cls, v: NominalSection, info: ValidationInfo) -> NominalSection:
        r = _robot_of(info)
        if r is not None:
            _raise(paper_nominal_issues(v) if r[0] == "paper" else mjcf_nominal_issues(v, r[2]))
        return v

    @field_validator("thrusters")
    @classmethod
    def _thrusters(cls, v: ThrustersSection, info: ValidationInfo) -> ThrustersSection:
        r = _robot_of(info)
        if r is not None:
            _raise(paper_thrusters_issues(v) if r[0] == "paper" else mjcf_thrusters_issues(v, r[2]))
        return v

    @field_validator("controllers")
    @classmethod
    def _controllers(cls, v: dict, info: ValidationInfo) -> dict:
        r = _robot_of(info)
        if r is not None:
            _raise(_controllers_issues(v, r[0], _nominal_or_none(r, info)))
        return v

    @field_validator("controller")
    @classmethod
    def _controller(cls, v: ControllerSection, info: ValidationInfo) -> ControllerSection:
        r = _robot_of(info)
        if r is not None:
            if v.name is None:
                v.name = _by_robot(DEFAULT_CONTROLLER, r[0])
            _raise(_controller_section_issues(v, r[0], _nominal_or_none(r, info)))
        return v

    @model_validator(mode="after")
    def _robot_rules(self) -> "Scenario":
        paper_robot = self.robot == "paper"
        if self.duration is None:
            self.duration = _by_robot(DEFAULT_DURATION, self.robot)
        if "trajectory" not in self.model_fields_set and paper_robot:
            self.trajectory = TrajectorySection.model_validate({})
        if self.controller.name is None:
            self.controller.name = _by_robot(DEFAULT_CONTROLLER, self.robot)
        if paper_robot:
            paper_fill(self)
        _, m, _ = robot_model(self.robot, self.base_dir)
        ph = self.physics
        if ph.timestep is None:
            lo, hi = TIMESTEP_RANGE
            if not lo <= float(m.opt.timestep) <= hi:  # the model file's <option timestep>
                _raise([(("physics", "timestep"), f"the robot file's <option timestep> = {float(m.opt.timestep):g} s "
                         f"is outside [{lo:g}, {hi:g}] s; give physics.timestep or fix the file", _NO_VALUE)])
            ph.timestep = float(m.opt.timestep)
        if ph.integrator is None:
            ph.integrator = mujoco.mjtIntegrator(m.opt.integrator).name.removeprefix("mjINT_").lower()
        issues = paper_issues(self) if paper_robot else []
        issues += _common_issues(self, m)
        _raise(issues)
        return self


def _raise(issues: list) -> None:
    if issues:
        raise _Issues(issues)


def _robot_of(info: ValidationInfo) -> tuple[str, str | None, Path] | None:
    """(robot, base_dir, model path) of the scenario being validated; None when the robot
    field itself is invalid (reported there)."""
    robot = info.data.get("robot")
    if robot is None:
        return None
    base_dir = info.data.get("base_dir")
    return robot, base_dir, robot_model(robot, base_dir)[0]


def _nominal_or_none(r: tuple, info: ValidationInfo):
    """The controller's nominal model of the robot for checking parameters; None when the
    tip_site is invalid (reported there)."""
    if "tip_site" not in info.data:
        return None
    try:
        return _nominal(r[0], r[1], info.data["tip_site"])
    except (ParameterError, ValueError):
        return None


def _common_issues(sc: Scenario, m: mujoco.MjModel) -> list:
    """What every robot checks: names against the model, the trajectory, the controller and its
    parameters, the vehicle section, the period and the sensors."""
    issues: list = []
    lay = Layout.of(m, allow_planar=True)
    if sc.tip_site is not None:
        try:
            lay = Layout.of(m, sc.tip_site, allow_planar=True)
        except ParameterError as exc:
            issues.append((("tip_site",), str(exc), _NO_VALUE))
    try:
        sc.initial.state().apply(m, mujoco.MjData(m), lay)
    except ParameterError as exc:
        issues.append((("initial",), str(exc).removeprefix("initial."), _NO_VALUE))
    if sc.current is not None and sc.plant.current is not None and any(sc.plant.current):
        issues.append((("plant", "current"), "give the current in one place: the current section "
                       "(current.velocity) or plant.current, not both", sc.plant.current))
    for i, f in enumerate(sc.thrusters.failures):
        if f.thruster not in lay.thruster_names:
            issues.append((("thrusters", "failures", i, "thruster"), f"not a thruster of {sc.robot}"
                           f"{_suggest(f.thruster, lay.thruster_names)}; thrusters: "
                           f"{', '.join(lay.thruster_names) or 'none'}", f.thruster))
    names = list(lay.joint_names)
    if sc.arm.waypoints and not names:
        issues.append((("arm",), f"robot {sc.robot!r} has no arm joints", _NO_VALUE))
    for i, w in enumerate(sc.arm.waypoints):
        for jn in w.joints:
            if jn not in names:
                issues.append((("arm", "waypoints", i, "joints", jn), f"not a joint of {sc.robot}"
                               f"{_suggest(jn, names)}; joints: {', '.join(names) or 'none'}", _NO_VALUE))
    issues += _trajectory_issues(sc, lay)
    issues += _controller_issues(sc)
    if issues:
        return issues
    T = controller_period(sc)
    dt = sc.physics.timestep
    sub = T / dt
    if not (math.isfinite(T) and PERIOD_RANGE[0] <= T <= PERIOD_RANGE[1]):
        issues.append((("controller", "params", "T"), f"the controller period must be within "
                       f"[{PERIOD_RANGE[0]:g}, {PERIOD_RANGE[1]:g}] s", T))
    elif abs(sub - round(sub)) > 1e-9 or round(sub) < 1:
        issues.append((("controller", "params", "T") if "T" in sc.controller.params else ("control_period",),
                       f"the controller period must be a whole multiple of physics.timestep = {dt!r} s", T))
    tau = sc.thrusters.tau
    if tau is not None and tau > 0:
        # The thrusters' first-order lag is integrated by the plant's integrator: explicitly (Euler;
        # RK4 with its larger stability region), so dt / tau beyond the integrator's bound diverges.
        bound = LAG_STABILITY[sc.physics.integrator]
        if dt / tau >= bound:
            issues.append((("thrusters", "tau"), f"unstable with the {sc.physics.integrator} integrator at "
                           f"physics.timestep = {dt:.6g} s: the lag integrates stably only for tau > timestep / "
                           f"{bound} = {dt / bound:.6g} s", tau))
    issues += sensor_issues(sc.sensors, T)
    issues += navigation_issues(sc, m, dt)
    return issues


def _trajectory_issues(sc: Scenario, lay: Layout) -> list:
    tr = sc.trajectory
    if tr is None:
        return []
    issues = []
    if lay.tip_site < 0:
        return [(("trajectory",), f"robot {sc.robot!r} has no end-effector site (tip_site)", _NO_VALUE)]
    if lay.base_free:
        for k, v in tr.vectors().items():
            if len(v) != 3:
                issues.append((("trajectory", k), f"must be 3 numbers (world x, y, z) on robot {sc.robot!r} "
                               "(2 numbers only on a planar robot)", v))
    if not issues:
        try:
            tip_path(tr, (0.0, 0.0, 0.0), sc.base_dir)
        except ValueError as exc:
            msg = str(exc)
            issues.append((("trajectory",), msg[len("trajectory."):] if msg.startswith("trajectory.") else msg,
                           _NO_VALUE))
    return issues


def _controllers_issues(controllers: dict, robot: str, nominal) -> list:
    """The controllers section (paths below it): registered, for this robot, valid parameters."""
    from uvms_mj.control.registry import unknown_message

    issues = []
    where = "the paper's robot" if robot == "paper" else "floating robots"
    for name, params in controllers.items():
        works = _works_on(name, robot)
        if works is None and name not in available():
            issues.append(((name,), unknown_message(name).replace(f"controller {name!r}", "controller", 1), _NO_VALUE))
        elif not (works or (works is None and name in controllers_for(robot))):
            allowed = controllers_for(robot)
            issues.append(((name,), f"not a controller for {where}{_suggest(name, allowed)}; for {where}: "
                           f"{', '.join(allowed)}", _NO_VALUE))
        elif not isinstance(params, dict):
            issues.append(((name,), "must be a mapping of parameter names to values", params))
        elif nominal is not None:
            issues += [((name,) + p, msg, v) for p, msg, v in check_controller_params(name, params, nominal)]
    return issues


def _controller_section_issues(c: ControllerSection, robot: str, nominal) -> list:
    """The controller section (paths below it): a controller for this robot, its parameters."""
    from uvms_mj.control.registry import RETIRED, unknown_message

    where = "the paper's robot" if robot == "paper" else "floating robots"
    works = _works_on(c.name, robot)
    if works is None:  # not a working controller: the registry's full answer (entry points included)
        if c.name not in available():
            return [(("name",), unknown_message(c.name) if c.name in RETIRED or robot == "paper"
                     else f"unknown controller{_suggest(c.name, available())}; for {where}: "
                     f"{', '.join(controllers_for(robot))}", c.name)]
        works = c.name in controllers_for(robot)
    if not works:
        return [(("name",), f"works on the paper robot only; for {where}: {', '.join(controllers_for(robot))}",
                 c.name)]
    issues = []
    if nominal is not None:
        issues += [(("params",) + p, msg, v) for p, msg, v in check_controller_params(c.name, c.params, nominal)]
    if c.base_reference != "measured":
        named, _ = _controller_signature(c.name)
        if "base_reference" not in named:
            issues.append((("base_reference",), f"controller {c.name!r} takes no base reference; allowed: measured",
                           c.base_reference))
        elif c.params.get("base_reference") is not None:
            issues.append((("base_reference",), "give one base reference, not both: controller.base_reference, "
                           "controller.params.base_reference or vehicle.setpoint", c.base_reference))
    return issues


def _controller_issues(sc: Scenario) -> list:
    """The controller with the other sections: controllers[name] as its parameters, the
    vehicle section, arm waypoints, one base reference."""
    issues = []
    try:
        _take_controller_params(sc)
    except _Issues as exc:
        issues += exc.items
    c = sc.controller
    issues += vehicle_issues(sc.vehicle, c.name, c.params)
    if sc.arm.waypoints:
        if not takes_argument(c.name, "arm_trajectory"):
            issues.append((("arm",), f"controller {c.name!r} takes no arm waypoints (arm_trajectory)", _NO_VALUE))
        elif not issues:
            nominal = _nominal(sc.robot, sc.base_dir, sc.tip_site)
            lay = nominal.layout
            try:  # the controller's own word on arm waypoints (rac and pd follow the tip instead)
                arm = sc.arm.joint_trajectory(lay.joint_names, [0.0] * len(lay.joint_names))
                extra = {"trajectory": _probe_path()} if takes_argument(c.name, "trajectory") and lay.tip_site >= 0 \
                    else {}
                create(c.name, robot=nominal, arm_trajectory=arm, **extra, **c.params)
            except (ControllerError, ParameterError, ValueError, TypeError) as exc:
                issues.append((("arm",), str(exc), _NO_VALUE))
    if c.base_reference != "measured" and sc.vehicle.setpoint is not None:
        issues.append((("controller", "base_reference"), "give one base reference, not both: "
                       "controller.base_reference, controller.params.base_reference or vehicle.setpoint",
                       c.base_reference))
    return issues


def controller_period(sc: Scenario) -> float:
    """The controller period T [s]: controller.params.T, else control_period, else the robot's
    default (:data:`DEFAULT_PERIOD`; the paper's robot: the controller's own default, 1/60 s for
    the built-ins)."""
    params = sc.controller.params
    if "T" in params:
        return float(params["T"])
    if sc.control_period is not None:
        return float(sc.control_period)
    if sc.robot != "paper":
        return DEFAULT_PERIOD
    named, _ = _controller_signature(sc.controller.name)
    p = named.get("T")
    if p is not None and p.default is not inspect.Parameter.empty and _is_number(p.default):
        return float(p.default)
    from uvms_mj.control.digital import PAPER_T

    return PAPER_T
