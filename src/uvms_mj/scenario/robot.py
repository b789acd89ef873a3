"""Scenario files for any floating robot (``robot:`` other than ``paper``).

A scenario whose ``robot`` field names a built-in robot other than the paper's
(:data:`uvms_mj.plant.robot.BUILTIN_ROBOTS`) or an MJCF file is validated by :class:`RobotScenario`
and runs on :class:`uvms_mj.plant.plant.Plant`. Every section rejects unknown keys and names the
field, the value and what is allowed; element names (bodies, joints, actuators, keyframes) are
checked against the model with did-you-mean suggestions. Units SI unless the field says
otherwise; world frame z up.

.. code-block:: yaml

    name: station_arm_sweep
    robot: bluerov2_alpha        # built-in name or MJCF path (relative: to the scenario file)
    tip_site: null               # end-effector site; null: the first site named *tip
    duration: 20.0               # [s]
    seed: 0
    physics:
      timestep: null             # [s]; null: the model's (2 ms for the BlueROV2 models)
      integrator: null           # euler | rk4 | implicit | implicitfast; null: the model's
      backend: auto
    plant:                       # the truth
      overrides: {}              # "<element>.<field>": value, e.g. {bluerov2.mass: 13.7}
      hydro: {added_mass: exact, drag: strip, buoyancy: true}   # added_mass exact|off, drag strip|off
      gravity: true
      current: null              # world [vx, vy, vz] m/s; null: the model's
    nominal:                     # the controller's model: the robot FILE plus these, never the plant
      overrides: {}
      gravity: true
    initial:                     # every field optional (null: the model's qpos0 / keyframe)
      keyframe: null             # a model keyframe to start from
      position: [0, 0, -1]       # vehicle origin, world [m]
      orientation:               # give quat OR rpy, not both
        quat: null               # [w, x, y, z] (normalised)
        rpy: [0, 0, 0]           # roll, pitch, yaw (z-y-x: R = Rz(yaw) Ry(pitch) Rx(roll))
      joints: {alpha_shoulder: 90}   # joint name -> angle
      angle_unit: deg            # deg | rad: the unit of rpy, joints and joint_velocities
      linear_velocity: [0, 0, 0]     # world [m/s]
      angular_velocity: [0, 0, 0]    # BODY frame [rad/s] (MuJoCo's free joint)
      joint_velocities: {}       # joint name -> rate [angle_unit/s]
    arm:                         # desired arm motion (min-jerk segments, at rest at each waypoint)
      angle_unit: deg
      waypoints:
        - {t: 3.0, joints: {alpha_base: 60, alpha_shoulder: 120}}
        - {t: 8.0, joints: {alpha_base: -60}}
    sensors: {...}               # as the paper scenario (position, attitude, joint noise...)
    controller:
      name: station_pid          # a controller for floating robots
      params: {}
    warm_start: true
    outputs: {...}               # as the paper scenario

The controller is created as ``create(name, robot=NominalRobot(...), arm_trajectory=...,
**params)``; a controller works on these scenarios when its class says ``robots = "floating"``.
"""

from __future__ import annotations

import inspect
import math
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import Field, field_validator, model_validator

from uvms_mj.control import ControllerError, available, create
from uvms_mj.physics.terms import HydroTerms
from uvms_mj.sim.loop import RunResult, run_closed_loop
from uvms_mj.control.nominal import JointTrajectory, NominalRobot
from uvms_mj.plant.params import ParameterError
from uvms_mj.plant.files import robot_path
from uvms_mj.plant.layout import InitialState, Layout
from uvms_mj.plant.plant import Plant
from uvms_mj.plant.robot import compile_robot_spec

#: Default controller period [s]: 50 Hz, a whole multiple of the BlueROV2 models' 2 ms step
#: (the paper's 1/60 s is not); every controller of a robot scenario runs at it.
DEFAULT_PERIOD = 0.02

from uvms_mj.scenario import base as _S  # noqa: E402  (the shared sections and helpers)
from uvms_mj.scenario.sections import (  # noqa: E402
    CurrentSection,
    Failure,
    PlantSection,
    ThrustersSection,
    Initial,
    Vehicle,
    vehicle_issues,
    vehicle_params,
)

_Section = _S._Section
_Issues = _S._Issues
_NO_VALUE = _S._NO_VALUE
_suggest = _S._suggest


def _model_of(robot: str, base_dir: str | None):
    """(path, compiled model file without overrides, layout) for validation (cached by path)."""
    path = robot_path(robot, base_dir)
    return path, _compiled(str(path))


_CACHE: dict[str, Any] = {}


def _compiled(path: str):
    if path not in _CACHE:
        m = compile_robot_spec(path)
        _CACHE[path] = (m, Layout.of(m))
    return _CACHE[path]


class Waypoint(_Section):
    t: float = Field(gt=0, le=_S.DURATION_MAX, description="[s]")
    joints: dict[str, float] = Field(description="joint name -> angle [arm.angle_unit]")


class Arm(_Section):
    """Desired arm motion: timed waypoints, minimum-jerk between them."""

    angle_unit: Literal["deg", "rad"] = "deg"
    waypoints: list[Waypoint] = Field(default_factory=list)

    @model_validator(mode="after")
    def _increasing(self) -> "Arm":
        last = 0.0
        for i, w in enumerate(self.waypoints):
            if not w.t > last:
                raise _Issues([(("waypoints", i, "t"), f"times must be strictly increasing (previous {last:g} s)", w.t)])
            last = w.t
        return self


class RobotControllerSection(_S.ControllerSection):
    """The controller section (every robot's) on an MJCF robot: default ``station_pid``."""

    name: str = Field("station_pid", description="a controller for floating robots")


def floating_controllers() -> list[str]:
    """Registered controllers that work on floating-robot scenarios (``robots = "floating"``)."""
    out = []
    for n in available():
        try:
            f = _S._factory(n)
        except Exception:  # noqa: BLE001 - a broken plug-in is not offered
            continue
        if getattr(f, "robots", "paper") in ("floating", "any"):
            out.append(n)
    return out


class RobotScenario(_Section):
    """A scenario for a floating robot (module docstring)."""

    name: str = Field("scenario", pattern=r"^[A-Za-z0-9][A-Za-z0-9_.-]*$", max_length=_S.NAME_MAX)
    description: str = Field("", max_length=_S.DESCRIPTION_MAX)
    robot: str = Field(min_length=1, max_length=4096, description="built-in robot or MJCF path")
    base_dir: str | None = Field(None, exclude=True, description="(set by the loader) the scenario file's folder")
    tip_site: str | None = None
    duration: float = Field(20.0, gt=0, le=_S.DURATION_MAX)
    seed: int = Field(0, ge=0, le=_S.SEED_MAX)
    physics: _S.PhysicsSection = Field(default_factory=_S.PhysicsSection)
    plant: PlantSection = Field(default_factory=PlantSection)
    nominal: _S.NominalSection = Field(default_factory=_S.NominalSection)
    initial: Initial = Field(default_factory=Initial)
    arm: Arm = Field(default_factory=Arm)
    trajectory: dict[str, Any] | None = Field(
        None, description="desired end-effector path: {kind: line|waypoints|circle|lemniscate|helix|csv, ...} "
        "(uvms_mj.control.trajectories.make_trajectory); null: hold the initial tip position")
    trajectory_origin: Literal["tip", "world"] = Field(
        "tip", description="tip: the path is shifted so that it starts at the initial tip position; world: as given")
    control_period: float = Field(DEFAULT_PERIOD, ge=_S.PERIOD_RANGE[0], le=_S.PERIOD_RANGE[1],
                                  description="controller period T [s] of every controller (a whole multiple of "
                                  "the timestep)")
    current: CurrentSection | None = Field(None, description="the water current (constant, gauss_markov, profile); "
                                           "plant.current is the older spelling of a constant one")
    thrusters: ThrustersSection = Field(default_factory=ThrustersSection)
    vehicle: Vehicle = Field(default_factory=Vehicle)
    sensors: _S.Sensors = Field(default_factory=_S.Sensors)
    controller: RobotControllerSection = Field(default_factory=RobotControllerSection)
    controllers: dict[str, dict[str, Any]] = Field(default_factory=dict, description="per-controller parameters")
    warm_start: bool = True
    outputs: _S.Outputs = Field(default_factory=_S.Outputs)

    @field_validator("robot")
    @classmethod
    def _robot(cls, v: str) -> str:
        if v == "paper":
            raise ValueError("robot 'paper' uses the paper scenario schema")
        return v

    @model_validator(mode="after")
    def _check_model(self) -> "RobotScenario":
        try:
            path, (m, lay) = _model_of(self.robot, self.base_dir)
        except ParameterError as exc:
            raise _Issues([(("robot",), str(exc).split(": ", 1)[-1], self.robot)]) from None
        issues: list = []
        # overrides, by element name (each applied alone to find the culprit)
        if self.plant.overrides_file is not None:
            try:
                compile_robot_spec(path, read_overrides_file(self.plant.overrides_file, self.base_dir))
            except ParameterError as exc:
                issues.append((("plant", "overrides_file"), str(exc), _NO_VALUE))
        for sec in ("plant", "nominal"):
            for key, value in getattr(self, sec).overrides.items():
                try:
                    compile_robot_spec(path, {key: value})
                except ParameterError as exc:
                    msg = str(exc)
                    msg = msg.split(": ", 1)[1] if msg.startswith("override ") and ": " in msg else msg
                    issues.append(((sec, "overrides", key), msg, value))
        if self.tip_site is not None:
            try:
                Layout.of(m, self.tip_site)
            except ParameterError as exc:
                issues.append((("tip_site",), str(exc), _NO_VALUE))
        try:
            import mujoco

            st = self.initial.state()
            st.apply(m, mujoco.MjData(m), lay)
        except ParameterError as exc:
            issues.append((("initial",), str(exc).removeprefix("initial."), _NO_VALUE))
        names = list(lay.joint_names)
        for i, w in enumerate(self.arm.waypoints):
            for jn in w.joints:
                if jn not in names:
                    issues.append((("arm", "waypoints", i, "joints", jn),
                                   f"not a joint of {self.robot}{_suggest(jn, names)}; joints: {', '.join(names) or 'none'}",
                                   _NO_VALUE))
        if self.trajectory is not None:
            from uvms_mj.control.trajectories import make_trajectory

            try:
                make_trajectory(self.trajectory, base_dir=self.base_dir)
            except ValueError as exc:
                msg = str(exc)
                msg = msg[len("trajectory."):] if msg.startswith("trajectory.") else msg
                issues.append((("trajectory",), msg, _NO_VALUE))
            if lay.tip_site < 0:
                issues.append((("trajectory",), f"robot {self.robot!r} has no end-effector site (tip_site)", _NO_VALUE))
        if self.arm.waypoints and not names:
            issues.append((("arm",), f"robot {self.robot!r} has no arm joints", _NO_VALUE))
        if self.plant.model_mismatch:
            issues.append((("plant", "model_mismatch"), "applies to the paper's robot only (give the truth's "
                           "differences as plant.overrides)", True))
        hy = self.plant.hydro
        if hy.added_mass == "lagged":
            issues.append((("plant", "hydro", "added_mass"), "'lagged' applies to the paper's robot only; allowed "
                           "here: exact, off", hy.added_mass))
        if hy.drag == "mujoco":
            issues.append((("plant", "hydro", "drag"), "'mujoco' applies to the paper's robot only; allowed here: "
                           "strip, off", hy.drag))
        if self.current is not None and self.plant.current is not None:
            issues.append((("plant", "current"), "give the current in one place: the current section "
                           "(current.velocity) or plant.current, not both", self.plant.current))
        if isinstance(self.thrusters.dead_zone, bool) and self.thrusters.dead_zone:
            issues.append((("thrusters", "dead_zone"), "give the band [low, high] in the thrusters' command units "
                           "(true means the paper robot's band)", True))
        if self.thrusters.dead_zone_band is not None:
            issues.append((("thrusters", "dead_zone_band"), "applies to the paper's robot (with dead_zone: true); "
                           "give dead_zone: [low, high]", self.thrusters.dead_zone_band))
        for key, value in self.thrusters.overrides().items():
            try:
                compile_robot_spec(path, {key: value})
            except ParameterError as exc:
                issues.append((("thrusters", key.partition(".")[2].replace("forcerange", "force_range")),
                               str(exc).split(": ", 1)[-1], value))
        for i, f in enumerate(self.thrusters.failures):
            if f.thruster not in lay.thruster_names:
                issues.append((("thrusters", "failures", i, "thruster"), f"not a thruster of {self.robot}"
                               f"{_suggest(f.thruster, lay.thruster_names)}; thrusters: "
                               f"{', '.join(lay.thruster_names) or 'none'}", f.thruster))
        # controller: registered, for floating robots, its parameters valid
        for name, params in self.controllers.items():
            if name not in floating_controllers():
                issues.append((("controllers", name), f"not a controller for floating robots{_suggest(name, floating_controllers())}; "
                               f"for floating robots: {', '.join(floating_controllers())}", _NO_VALUE))
            elif not isinstance(params, dict):
                issues.append((("controllers", name), "must be a mapping of parameter names to values", params))
            else:
                found = _check_params(name, params) or _try_create(name, params, path)
                issues += [(("controllers", name) + (sub[2:] if sub[:2] == ("controller", "params") else sub), msg, v)
                           for sub, msg, v in found]
        try:
            _S._take_controller_params(self)
        except _Issues as exc:
            issues += exc.items
        c = self.controller
        allowed = floating_controllers()
        if c.name not in available():
            from uvms_mj.control.registry import RETIRED, unknown_message

            issues.append((("controller", "name"), unknown_message(c.name) if c.name in RETIRED else
                           f"unknown controller{_suggest(c.name, available())}; for floating robots: "
                           f"{', '.join(allowed)}", c.name))
        elif c.name not in allowed:
            issues.append((("controller", "name"), f"works on the paper robot only; for floating robots: "
                           f"{', '.join(allowed)}", c.name))
        else:
            found = _check_params(c.name, c.params)
            for sub, msg, value in found:
                issues.append((("controller", "params") + sub, msg, value))
            if not found and not issues:
                issues += _try_create(c.name, c.params, path)
        issues += vehicle_issues(self.vehicle, self.controller.name, self.controller.params)
        if c.base_reference != "measured" and c.name in allowed:
            named, _ = _S._controller_signature(c.name)
            if "base_reference" not in named:
                issues.append((("controller", "base_reference"), f"controller {c.name!r} takes no base reference; "
                               "allowed: measured", c.base_reference))
            elif c.params.get("base_reference") is not None or self.vehicle.setpoint is not None:
                issues.append((("controller", "base_reference"), "give one base reference: controller.base_reference, "
                               "controller.params.base_reference or vehicle.setpoint", c.base_reference))
        if not issues:
            dt = self.physics.timestep or float(m.opt.timestep)
            T = robot_controller_period(self)
            sub = T / dt
            if abs(sub - round(sub)) > 1e-9 or round(sub) < 1:
                issues.append((("controller", "params", "T"), f"the controller period must be a whole multiple of "
                               f"the timestep {dt!r} s", T))
            issues += _S.sensor_issues(self.sensors, T)
        if issues:
            raise _Issues(issues)
        return self


def read_overrides_file(path: str, base_dir: str | None) -> dict:
    """The overrides of a YAML file (a mapping of "<element>.<field>" to values).

    Raises:
        ParameterError: missing or unreadable file, not a mapping of strings to numbers/lists.
    """
    import yaml

    p = Path(path).expanduser()
    if not p.is_absolute() and base_dir is not None:
        p = Path(base_dir) / p
    try:
        data = yaml.safe_load(p.read_text())
    except FileNotFoundError:
        raise ParameterError(f"{path}: no such overrides file") from None
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        raise ParameterError(f"{path}: cannot read the overrides file: {exc}") from None
    if data is None:
        return {}
    if not isinstance(data, dict) or not all(isinstance(k, str) for k in data):
        raise ParameterError(f"{path}: an overrides file is a mapping of '<element>.<field>' to values")
    return data


def robot_plant_overrides(sc: "RobotScenario") -> dict:
    """The plant's overrides: the overrides file's, then plant.overrides on top."""
    over = {}
    if sc.plant.overrides_file is not None:
        over.update(read_overrides_file(sc.plant.overrides_file, sc.base_dir))
    over.update(sc.plant.overrides)
    over.update(sc.thrusters.overrides())
    return over


def _check_params(name: str, params: dict) -> list:
    named, var_kw = _S._controller_signature(name)
    named.pop("robot", None)
    named.pop("arm_trajectory", None)
    issues = []
    for key, value in params.items():
        if not var_kw and key not in named:
            issues.append(((key,), f"{key!r} is not a parameter of controller {name!r}{_suggest(key, named)}; "
                           "allowed: " + ", ".join(named), _NO_VALUE))
        elif _S._non_finite(value):
            issues.append(((key,), "must be finite", value))
    return issues


def _try_create(name: str, params: dict, path: Path) -> list:
    """The controller's own parameter errors, each attributed to the parameter that causes it."""
    nominal = _nominal_for(str(path))
    found = _S.creation_errors(lambda kw: create(name, robot=nominal, arm_trajectory=None, **kw), params)
    return [(("controller", "params") + sub, msg, v) for sub, msg, v in found]


_NOMINAL: dict[str, NominalRobot] = {}


def _nominal_for(path: str) -> NominalRobot:
    if path not in _NOMINAL:
        _NOMINAL[path] = NominalRobot(path)
    return _NOMINAL[path]


def robot_controller_period(sc: RobotScenario) -> float:
    """controller.params.T if given, else the scenario's control_period."""
    if "T" in sc.controller.params:
        return float(sc.controller.params["T"])
    return float(sc.control_period)


def trajectory_of(sc: RobotScenario, tip0: np.ndarray):
    """The scenario's end-effector trajectory (None: none), shifted to start at ``tip0`` (the
    initial tip position, world) with trajectory_origin "tip"."""
    if sc.trajectory is None:
        return None
    from uvms_mj.control.trajectories import make_trajectory, starting_at

    tr = make_trajectory(sc.trajectory, base_dir=sc.base_dir)
    return starting_at(tr, tip0) if sc.trajectory_origin == "tip" else tr


def robot_info(sc: RobotScenario, plant: Plant | None = None) -> dict:
    """The run's robot for logs: {name, path, overrides, layout}."""
    path = robot_path(sc.robot, sc.base_dir)
    lay = plant.layout if plant is not None else _compiled(str(path))[1]
    return {"name": sc.robot, "path": str(path), "overrides": _S._jsonable(robot_plant_overrides(sc)),
            "layout": lay.describe()}


def resolve_robot_scenario(sc: RobotScenario) -> dict:
    """The resolved scenario (JSON-able, for log metadata): defaults filled in (the robot's file
    is in :func:`robot_info`). It is itself a valid scenario describing the same run."""
    d = sc.model_dump(mode="json")
    d["outputs"]["log"] = _S.log_path(sc).as_posix()
    d["controller"]["params"].setdefault("T", robot_controller_period(sc))
    return _S._jsonable(d)


def build_robot_scenario(sc: RobotScenario) -> tuple[Plant, Any]:
    """The plant (truth) and the controller.

    Raises:
        uvms_mj.scenario.schema.ScenarioError: a combination that fails only when built.
    """
    try:
        ph, pl = sc.physics, sc.plant
        plant = Plant(
            robot_path(sc.robot, sc.base_dir), overrides=robot_plant_overrides(sc),
            terms=HydroTerms(added_mass=pl.hydro.added_mass, drag=pl.hydro.drag or "strip", buoyancy=pl.hydro.buoyancy),
            gravity=pl.gravity, current=sc.current.current(sc.seed) if sc.current is not None else pl.current,
            timestep=ph.timestep, integrator=ph.integrator,
            initial=sc.initial.state(), tip_site=sc.tip_site, backend=None if ph.backend == "auto" else ph.backend,
            payload=pl.payload.payload() if pl.payload is not None else None,
            failures=[f.failure() for f in sc.thrusters.failures])
        nominal = NominalRobot(robot_path(sc.robot, sc.base_dir), sc.nominal.overrides, gravity=sc.nominal.gravity,
                               tip_site=sc.tip_site)
        arm = None
        names = plant.layout.joint_names
        if names:
            k = math.pi / 180.0 if sc.arm.angle_unit == "deg" else 1.0
            arm = JointTrajectory.from_waypoints(names, plant.joint_angles,
                                                 [(w.t, {n: k * v for n, v in w.joints.items()})
                                                  for w in sc.arm.waypoints])
        params = dict(sc.controller.params)
        params.setdefault("T", float(sc.control_period))
        named, var_kw = _S._controller_signature(sc.controller.name)
        if "trajectory" in inspect.signature(_S._factory(sc.controller.name)).parameters or var_kw:
            params["trajectory"] = trajectory_of(sc, plant.tip_position)
        params.update(vehicle_params(sc.vehicle, plant, sc.base_dir))
        ref = sc.controller.base_reference
        if ref != "measured":
            a, n = plant.layout.base_qadr, plant.layout.base_nq
            if ref == "truth":
                params["base_reference"] = [float(v) for v in plant.q[a:a + n]]
            else:  # the model file's initial state (its initial keyframe, else qpos0)
                import mujoco

                d = mujoco.MjData(nominal.model)
                InitialState().apply(nominal.model, d, nominal.layout)
                params["base_reference"] = [float(v) for v in d.qpos[a:a + n]]
        ctrl = create(sc.controller.name, robot=nominal, arm_trajectory=arm, **params)
    except (ParameterError, ControllerError, ValueError, TypeError) as exc:
        raise _S.ScenarioError(f"scenario {sc.name!r}: {exc}") from None
    return plant, ctrl


def run_robot_scenario(sc: RobotScenario, sink=None, on_sample=None, built: tuple | None = None) -> RunResult:
    """Build and run (:func:`uvms_mj.sim.loop.run_closed_loop`); ``meta`` gains ``scenario``,
    ``name``, ``backend`` and ``robot``."""
    plant, ctrl = built if built is not None else build_robot_scenario(sc)
    T = float(getattr(ctrl, "T", robot_controller_period(sc)))
    res = run_closed_loop(plant, ctrl, sc.duration, T=T, sensor=_S.sensor_model(sc), seed=sc.seed,
                          warm_start=sc.warm_start, on_sample=on_sample, sink=sink)
    res.meta.update(name=sc.name, backend=plant.backend, scenario=resolve_robot_scenario(sc), robot=robot_info(sc, plant))
    return res
