"""What every scenario schema shares: errors, bounds, the base section, helpers, the sensors and
outputs sections, the controller registry's signatures.

Errors (:class:`ScenarioError`, a ValueError) name the file, the field path, the bad value and
what is allowed, one line per problem; validators raise :class:`_Issues` with sub-paths.
"""

from __future__ import annotations

import difflib
import inspect
import math
from typing import TYPE_CHECKING, Annotated, Any, Callable, Iterable, Literal

import copy
from pathlib import Path

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from uvms_mj.control import ControllerError

if TYPE_CHECKING:  # imported where used (validate needs no loop)
    from uvms_mj.sim.loop import SensorModel

__all__ = ["ControllerSection", "Hydro", "NominalSection", "Outputs", "PhysicsSection", "ScenarioError", "Sensors", "creation_errors",
           "log_path", "sensor_model"]


class ScenarioError(ValueError):
    """An invalid scenario: the message names the file, the field path, the bad value and what
    is allowed (one line per problem)."""


#: "no value to show" in an error line
_NO_VALUE = object()


class _Issues(ValueError):
    """Raised inside validators: problems below the validator's own location.

    ``items`` are (sub-path, message, value) triples (value ``_NO_VALUE``: not shown); the
    formatter extends pydantic's location with the sub-path, so that e.g. the controller's own
    error for ``gamma`` is reported at ``controller.params.gamma``.
    """

    def __init__(self, items: list[tuple[tuple, str, Any]]) -> None:
        super().__init__("; ".join(f"{'.'.join(map(str, p)) or '.'}: {m}" for p, m, _ in items))
        self.items = items



#: Bounds of the numeric fields (physically sensible; documented in the README's testbed section).
DURATION_MAX = 3600.0  # [s] duration, t_start
TIMESTEP_RANGE = (1e-5, 0.1)  # [s] physics.timestep
PERIOD_RANGE = (1e-4, 1.0)  # [s] the controller period T
TAU_MAX = 10.0  # [s] thrusters.tau
FORCE_MAX = 1e4  # [N] |force_range|, |dead_zone_band|
CURRENT_MAX = 10.0  # [m/s] |plant.current|
LENGTH_MAX = 100.0  # [m] |trajectory.target|, |trajectory.displacement|
SPEED_MAX = 10.0  # [m/s] trajectory.cruise_speed
ACCEL_MAX = 100.0  # [m/s^2] trajectory.accel
POSITION_SIZE_MAX = 1.0  # [m] position noise and quantum
ANGLE_SIZE_MAX = math.pi  # [rad] angle noise and quantum
VELOCITY_NOISE_MAX = 10.0  # [m/s, rad/s]
SIZE_MIN = 1e-9  # smallest non-zero noise, quantum, speed, acceleration
#: |joint angle| in a robot scenario [deg, or rad with angle_unit: rad] (ours: two turns, as
#: initial.orientation.rpy; 2^64 + 1 passed validation)
ANGLE_MAX = 720.0
ANGULAR_SPEED_MAX = 3600.0  # |joint velocity| [angle_unit/s] (ours: ten turns a second)
SEED_MAX = 2**63 - 1
NAME_MAX = 100  # characters (the default log name must fit in a file name)
DESCRIPTION_MAX = 10_000  # characters
VIDEO_FPS_MAX = 120
VIDEO_SIZE_MAX = (3840, 2160)  # [px] width, height
#: |value| of a numeric controller parameter or parameter override: at most this, and 0 or at least 1e-9
PARAM_ABS_MAX = 1e6
#: Largest timestep / tau for which the plant integrator keeps the thruster lag stable: explicit
#: Euler |1 - x| < 1; RK4 |1 - x + x^2/2 - x^3/6 + x^4/24| < 1 (MuJoCo integrates activations
#: explicitly with every integrator except rk4, which integrates them with the rest of the state).
LAG_STABILITY = {"euler": 2.0, "implicit": 2.0, "implicitfast": 2.0, "rk4": 2.785}

Vec2 = Annotated[list[float], Field(min_length=2, max_length=2)]
ForceVec2 = Annotated[list[Annotated[float, Field(ge=-FORCE_MAX, le=FORCE_MAX)]], Field(min_length=2, max_length=2)]
LengthVec2 = Annotated[list[Annotated[float, Field(ge=-LENGTH_MAX, le=LENGTH_MAX)]], Field(min_length=2, max_length=2)]


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False, validate_default=False,
                              defer_build=True)  # schemas built on first use: ~0.07 s of validate



def _suggest(word: str, options: Iterable[str]) -> str:
    close = difflib.get_close_matches(str(word), list(options), n=1, cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, (bool, np.bool_))


def _non_finite(value: Any, path: tuple = ()) -> list[tuple]:
    """Paths of non-finite floats inside nested lists/dicts."""
    if isinstance(value, (float, np.floating)) and not math.isfinite(float(value)):
        return [path]
    if isinstance(value, dict):
        return [p for k, v in value.items() for p in _non_finite(v, path + (k,))]
    if isinstance(value, (list, tuple)):
        return [p for i, v in enumerate(value) for p in _non_finite(v, path + (i,))]
    return []


def _has_bool(value: Any) -> bool:
    """A boolean inside nested lists/dicts (YAML true/false, which Python would take as 1/0)."""
    if isinstance(value, (bool, np.bool_)):
        return True
    if isinstance(value, dict):
        return any(_has_bool(v) for v in value.values())
    if isinstance(value, (list, tuple)):
        return any(_has_bool(v) for v in value)
    return False


def _out_of_range(value: Any) -> bool:
    """A number inside nested lists/dicts outside 0 or [SIZE_MIN, PARAM_ABS_MAX] in magnitude."""
    if _is_number(value):
        try:
            a = abs(float(value))
        except OverflowError:
            return True
        return a != 0 and not SIZE_MIN <= a <= PARAM_ABS_MAX
    if isinstance(value, dict):
        return any(_out_of_range(v) for v in value.values())
    if isinstance(value, (list, tuple)):
        return any(_out_of_range(v) for v in value)
    return False


def _factory(name: str) -> Callable:
    from uvms_mj.control.registry import factory

    return factory(name)


def _controller_signature(name: str) -> tuple[dict[str, inspect.Parameter], bool]:
    """(named keyword parameters except those the scenario gives -- trajectory, nominal, robot,
    arm_trajectory --, whether it takes **kwargs)."""
    factory = _factory(name)
    try:
        sig = inspect.signature(factory)
    except (TypeError, ValueError):
        return {}, True
    named = {
        p.name: p for p in sig.parameters.values()
        if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)
        and p.name not in ("trajectory", "nominal", "robot", "arm_trajectory", "self")
    }
    return named, any(p.kind == p.VAR_KEYWORD for p in sig.parameters.values())


def takes_argument(name: str, arg: str) -> bool:
    """Whether controller ``name``'s factory takes keyword ``arg`` (by name or **kwargs), the
    arguments the scenario gives included."""
    try:
        params = inspect.signature(_factory(name)).parameters
    except (TypeError, ValueError):
        return True
    return arg in params or any(p.kind == p.VAR_KEYWORD for p in params.values())


def named_argument(name: str, arg: str) -> bool:
    """Whether controller ``name``'s factory names keyword ``arg`` in its signature."""
    try:
        return arg in inspect.signature(_factory(name)).parameters
    except (TypeError, ValueError):
        return False


def creation_errors(make: Callable[[dict], Any], params: dict) -> list[tuple[tuple, str, Any]]:
    """The errors ``make(params)`` raises (ControllerError, ValueError, TypeError), each
    attributed to the parameter that causes it alone (found by calling ``make`` with it alone):
    ((key,), message, value) items, or ((), message, params) when no single parameter does."""

    def attempt(kwargs: dict) -> str | None:
        try:
            make(kwargs)
        except (ControllerError, ValueError, TypeError) as exc:
            return str(exc)
        return None

    err = attempt(params)
    if err is None:
        return []
    issues = [((key,), e, value) for key, value in params.items() if (e := attempt({key: value})) is not None]
    return issues or [((), err, params)]


class PhysicsSection(_Section):
    """MuJoCo integration settings; null: the model file's (the paper's robot: 1/120 s, rk4,
    filled in when the scenario is validated)."""

    timestep: float | None = Field(None, ge=TIMESTEP_RANGE[0], le=TIMESTEP_RANGE[1], description="plant step [s]")
    integrator: Literal["euler", "rk4", "implicit", "implicitfast"] | None = Field(
        None, description="MuJoCo integrator")
    backend: Literal["auto", "native", "python"] = Field(
        "auto", description="hydrodynamics backend; auto: native if it builds ($UVMS_MJ_COMPILED=off: python)")
    gravity: list[Annotated[float, Field(ge=-100.0, le=100.0)]] | None = Field(
        None, min_length=3, max_length=3,
        description="the plant's gravity [m/s^2, world]; null: the model file's (e.g. [0, 0, -9.82]: "
        "von Benzon et al.'s BlueROV2 simulator); the nominal model keeps its file's; plant.gravity: false "
        "still switches gravity off")


class Hydro(_Section):
    """Which hydrodynamic terms the plant applies (:class:`uvms_mj.physics.terms.HydroTerms`);
    ``lagged`` added mass and ``mujoco`` drag exist for the paper's planar robot only."""

    added_mass: Literal["exact", "lagged", "off"] = "exact"
    drag: Literal["strip", "mujoco", "off"] | None = Field(
        None, description="null: the paper's robot 'mujoco' if plant.model_mismatch else 'strip'; others 'strip'")
    buoyancy: bool = True


class NominalSection(_Section):
    """The controller's nominal model: the robot's model FILE plus these overrides (never the
    plant)."""

    overrides: dict[str, Any] = Field(default_factory=dict, description="'<element>.<field>': value, e.g. a 30 % "
                                      "error as x1.3 (the paper's robot: its own keys too)")
    gravity: bool = Field(True, description="the nominal model includes gravity and buoyancy")


class ControllerSection(_Section):
    """A registered controller, its keyword parameters and the base's reference, for every robot."""

    name: str | None = Field(None, description="one of uvms_mj.control.available(); null: the robot's default "
                             "(uvms_mj.scenario.document.DEFAULT_CONTROLLER: rac_dob on the paper's robot, "
                             "station_pid on others)")
    params: dict[str, Any] = Field(default_factory=dict, description="keyword arguments of the controller")
    base_reference: Literal["measured", "truth", "nominal"] = Field(
        "measured", description="the base's reference pose: the first (noisy) measurement, the plant's true "
        "initial pose, or the model file's initial pose (its initial keyframe, the paper's paper_initial; else "
        "qpos0)")
    feedback: Literal["truth", "estimate"] = Field(
        "truth", description="the vehicle pose the controller gets: truth (the true state through the sensors "
        "section) or estimate (the ESKF on the navigation section's samples as they arrive, "
        "uvms_mj.estimation.online; needs navigation.imu and navigation.fix or navigation.depth)")


class SignalSection(_Section):
    """One measured signal (:class:`uvms_mj.sim.sensors.Signal`): noise, bias, quantization, rate,
    delay in samples or seconds."""

    noise: float = Field(0.0, ge=0, le=10.0, description="std (the signal's units: m, rad, m/s or rad/s)")
    bias: float | list[float] | None = Field(None, description="constant offset: one number or one per component")
    quantum: float = Field(0.0, ge=0, le=1.0, description="quantization step, 0: none")
    rate: float | None = Field(None, gt=0, le=10_000.0, description="refresh rate [Hz]; null: every control sample")
    delay: int | None = Field(None, ge=0, le=1000, description="delay [control samples]")
    delay_s: float | None = Field(None, ge=0, le=100.0, description="delay [s] (a whole number of control periods)")

    @model_validator(mode="after")
    def _one_delay(self) -> "SignalSection":
        if self.delay is not None and self.delay_s is not None:
            raise _Issues([((), "give the delay in samples (delay) or in seconds (delay_s), not both",
                            {"delay": self.delay, "delay_s": self.delay_s})])
        return self

    def signal(self):
        from uvms_mj.sim.sensors import Signal

        bias = () if self.bias is None else self.bias
        return Signal(noise=self.noise, bias=bias, quantum=self.quantum, rate=self.rate, delay=self.delay,
                      delay_s=self.delay_s)


#: The per-signal sections of ``sensors`` (:data:`uvms_mj.sim.sensors.SIGNALS`).
SIGNAL_FIELDS = ("position", "attitude", "joints", "velocity")


class Sensors(_Section):
    """The measurement model (:class:`uvms_mj.sim.loop.SensorModel`; all off by default)."""

    position_noise: float = Field(0.0, ge=0, le=POSITION_SIZE_MAX, description="std on p0x, p0y [m]")
    angle_noise: float = Field(0.0, ge=0, le=ANGLE_SIZE_MAX,
                               description="std on phi0, phi1, phi2 [rad] (shorthand: sets both below)")
    attitude_noise: float | None = Field(None, ge=0, le=ANGLE_SIZE_MAX,
                                         description="std on the base attitude phi0 [rad]; null: angle_noise")
    joint_noise: float | None = Field(None, ge=0, le=ANGLE_SIZE_MAX,
                                      description="std on the joint encoders phi1, phi2 [rad]; null: angle_noise")
    position_quantum: float = Field(0.0, ge=0, le=POSITION_SIZE_MAX, description="[m], 0: none")
    angle_quantum: float = Field(0.0, ge=0, le=ANGLE_SIZE_MAX, description="[rad], 0: none")
    delay: int = Field(0, ge=0, le=1, description="samples of measurement delay: 0 or 1")
    velocity_sensor: bool = False
    velocity_noise: float = Field(0.0, ge=0, le=VELOCITY_NOISE_MAX, description="std [m/s, rad/s] (with velocity_sensor)")
    position: SignalSection | None = Field(None, description="per signal: the base/vehicle position (world)")
    attitude: SignalSection | None = Field(None, description="per signal: the base/vehicle attitude")
    joints: SignalSection | None = Field(None, description="per signal: the joint encoders")
    velocity: SignalSection | None = Field(None, description="per signal: a velocity sensor (qvel)")

    def signal_sections(self) -> dict:
        """The per-signal sections given (name -> SignalSection)."""
        return {n: getattr(self, n) for n in SIGNAL_FIELDS if getattr(self, n) is not None}

    @model_validator(mode="after")
    def _tiny(self) -> "Sensors":
        issues = []
        if self.signal_sections():
            flat = [k for k in ("position_noise", "angle_noise", "attitude_noise", "joint_noise", "position_quantum",
                                "angle_quantum", "delay", "velocity_sensor", "velocity_noise") if getattr(self, k)]
            if flat:
                issues.append(((flat[0],), "give either the per-signal sections (position, attitude, joints, "
                               "velocity) or the flat fields, not both", getattr(self, flat[0])))
        for key in ("position_noise", "angle_noise", "attitude_noise", "joint_noise", "position_quantum",
                    "angle_quantum", "velocity_noise"):
            v = getattr(self, key)
            if v is not None and 0 < v < SIZE_MIN:
                issues.append(((key,), f"must be 0 (off) or at least {SIZE_MIN:g}", v))
        if issues:
            raise _Issues(issues)
        return self



class Outputs(_Section):
    """What a run writes."""

    log: str | None = Field(None, min_length=1, max_length=4096,
                            description="MCAP path; null: logs/<name>-<controller>.mcap")
    video: bool = False
    video_fps: int = Field(30, ge=1, le=VIDEO_FPS_MAX)
    video_size: Annotated[list[int], Field(min_length=2, max_length=2)] = Field(
        default_factory=lambda: [640, 480], description="[width, height] pixels, even, 16 to 3840 x 2160")
    plots: bool = True

    @field_validator("video_size")
    @classmethod
    def _size(cls, v: list[int]) -> list[int]:
        issues = []
        for i, (n, hi) in enumerate(zip(v, VIDEO_SIZE_MAX)):
            if not 16 <= n <= hi or n % 2:
                issues.append(((i,), f"must be an even number of pixels from 16 to {hi} "
                                     "(H.264 needs even sizes)", n))
        if issues:
            raise _Issues(issues)
        return v



def _jsonable(v: Any) -> Any:
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, np.ndarray):
        return _jsonable(v.tolist())
    if isinstance(v, (np.bool_, bool)):
        return bool(v)
    if isinstance(v, np.integer):
        return int(v)
    if isinstance(v, (np.floating, float)):
        return float(v)
    if v is None or isinstance(v, (int, str)):
        return v
    return repr(v)


def _take_controller_params(sc) -> None:
    """controller.params from ``controllers[controller.name]`` when only the latter is given;
    both given and different is an error."""
    own = sc.controllers.get(sc.controller.name)
    if own is None:
        return
    if not sc.controller.params:
        sc.controller.params = copy.deepcopy(own)
    elif sc.controller.params != own:
        raise _Issues([(("controller", "params"), f"parameters of {sc.controller.name!r} are given both here and in "
                        f"controllers.{sc.controller.name} (differently); give them in one place",
                        sc.controller.params)])


def sensor_issues(sensors, T: float) -> list:
    """Problems of the per-signal sensors with the control period T [s] (rates and delays in
    seconds must be whole numbers of periods)."""
    issues = []
    sections = sensors.signal_sections()
    if not sections:
        return issues
    from uvms_mj.sim.sensors import samples_of  # (here: validate imports no sensor module for a scenario without)

    for name, sec in sections.items():
        try:
            samples_of(sec.signal(), T)
        except ValueError as exc:
            key = "rate" if str(exc).startswith("rate") else "delay_s"
            issues.append((("sensors", name, key), str(exc).split(": ", 1)[-1], getattr(sec, key)))
    return issues


def log_path(scenario) -> Path:
    """outputs.log, or logs/<name>-<controller>.mcap."""
    return Path(scenario.outputs.log or f"logs/{scenario.name}-{scenario.controller.name}.mcap")


def sensor_model(scenario) -> SensorModel:
    """The scenario's sensors as a :class:`~uvms_mj.sim.loop.SensorModel` (per-signal sensors
    when the section has any)."""
    from uvms_mj.sim.loop import SensorModel

    s = scenario.sensors
    sections = s.signal_sections()
    if sections:
        return SensorModel(signals={n: sec.signal() for n, sec in sections.items()})
    return SensorModel(position_noise=s.position_noise, angle_noise=s.angle_noise,
                       attitude_noise=s.attitude_noise, joint_noise=s.joint_noise,
                       position_quantum=s.position_quantum, angle_quantum=s.angle_quantum, delay=s.delay,
                       velocity_sensor=s.velocity_sensor, velocity_noise=s.velocity_noise)
