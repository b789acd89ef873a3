"""Scenario sections that apply to every robot: the initial state, the water current, thruster
failures, the vehicle's setpoint and trajectory.

Each is validated here on its own (types, bounds, one of two alternatives); names (joints,
thrusters) are checked against the robot's model by the scenario that uses the section.
Angles are in the section's ``angle_unit`` (deg by default); positions world [m].
"""

from __future__ import annotations

import math
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import Field, model_validator

from uvms_mj.physics.current import Current
from uvms_mj.physics.waves import DEFAULT_COMPONENTS, DEFAULT_GAMMA, MAX_COMPONENTS, MAX_SPREADING, Waves
from uvms_mj.plant.errors import ParameterError
from uvms_mj.plant.layout import InitialState
from uvms_mj.plant.plant import ThrusterFailure
from uvms_mj.rotations import quat_from_rpy
from uvms_mj.scenario.base import _NO_VALUE as _NO
from uvms_mj.scenario.base import (ANGLE_MAX, ANGULAR_SPEED_MAX, CURRENT_MAX, DURATION_MAX, FORCE_MAX, PARAM_ABS_MAX,
                                   SEED_MAX, SIZE_MIN, TAU_MAX, Hydro, _Issues, _Section)

__all__ = ["CurrentSection", "Failure", "Initial", "Orientation", "PayloadSection", "PlantSection", "Setpoint",
           "TetherSection", "ThrustersSection", "Vehicle", "WavesSection"]

#: Bounds (as the paper scenario's).
POSITION_MAX = 1000.0  # [m] |initial.position|, |vehicle.setpoint.position|
VELOCITY_MAX = 10.0  # [m/s], [rad/s] initial velocities
#: [s] the shortest wave period (ours: capillary ripples are below 0.1 s; 1e-300 overflowed the spectrum: a traceback)
WAVE_PERIOD_MIN = 0.1

Vec3 = Annotated[list[Annotated[float, Field(ge=-POSITION_MAX, le=POSITION_MAX)]], Field(min_length=3, max_length=3)]
Vel3 = Annotated[list[Annotated[float, Field(ge=-VELOCITY_MAX, le=VELOCITY_MAX)]], Field(min_length=3, max_length=3)]
Cur3 = Annotated[list[Annotated[float, Field(ge=-CURRENT_MAX, le=CURRENT_MAX)]], Field(min_length=2, max_length=3)]


class Orientation(_Section):
    """The vehicle's initial orientation: a quaternion or roll/pitch/yaw (not both)."""

    quat: Annotated[list[Annotated[float, Field(ge=-PARAM_ABS_MAX, le=PARAM_ABS_MAX)]],
                    Field(min_length=4, max_length=4)] | None = Field(
        None, description="[w, x, y, z], normalised (components within +-1e6: 1e308 overflowed the norm)")
    rpy: Annotated[list[Annotated[float, Field(ge=-720, le=720)]], Field(min_length=3, max_length=3)] | None = Field(
        None, description="roll, pitch, yaw in initial.angle_unit (z-y-x convention)")

    @model_validator(mode="after")
    def _one(self) -> "Orientation":
        if self.quat is not None and self.rpy is not None:
            raise _Issues([((), "give either quat or rpy, not both", {"quat": self.quat, "rpy": self.rpy})])
        if self.quat is not None and float(np.linalg.norm(self.quat)) < 1e-9:
            raise _Issues([(("quat",), "must not be zero", self.quat)])
        return self


class Initial(_Section):
    """The initial state (every field optional)."""

    keyframe: str | None = Field(None, description="a model keyframe to start from")
    position: Vec3 | None = Field(None, description="vehicle origin, world [m]")
    orientation: Orientation | None = None
    joints: dict[str, Annotated[float, Field(ge=-ANGLE_MAX, le=ANGLE_MAX)]] = Field(
        default_factory=dict, description="joint name -> angle [angle_unit], within +-720")
    angle_unit: Literal["deg", "rad"] = Field("deg", description="unit of rpy, joints and joint_velocities")
    linear_velocity: Vel3 | None = Field(None, description="world [m/s]")
    angular_velocity: Vel3 | None = Field(None, description="body frame [rad/s]")
    joint_velocities: dict[str, Annotated[float, Field(ge=-ANGULAR_SPEED_MAX, le=ANGULAR_SPEED_MAX)]] = Field(
        default_factory=dict, description="joint name -> [angle_unit/s], within +-3600")

    def state(self) -> InitialState:
        """As :class:`uvms_mj.plant.layout.InitialState` (radians)."""
        k = math.pi / 180.0 if self.angle_unit == "deg" else 1.0
        quat = None
        if self.orientation is not None:
            if self.orientation.quat is not None:
                quat = tuple(self.orientation.quat)
            elif self.orientation.rpy is not None:
                quat = tuple(quat_from_rpy(*(k * v for v in self.orientation.rpy)))
        return InitialState(
            position=tuple(self.position) if self.position is not None else None, quat=quat,
            joints={n: k * v for n, v in self.joints.items()},
            linear_velocity=tuple(self.linear_velocity) if self.linear_velocity is not None else None,
            angular_velocity=tuple(self.angular_velocity) if self.angular_velocity is not None else None,
            joint_velocities={n: k * v for n, v in self.joint_velocities.items()},
            keyframe=self.keyframe)




class GaussMarkov(_Section):
    """A first-order Gauss-Markov current (:class:`uvms_mj.physics.current.Current`)."""

    mean: Cur3 | None = Field(None, description="mu, world [m/s]; null: the plugin's default (0)")
    sigma: Cur3 | None = Field(None, description="stationary std per axis [m/s]; null: the plugin's default")
    tau: Annotated[list[Annotated[float, Field(gt=0, le=1e6)]], Field(min_length=2, max_length=3)] | None = Field(
        None, description="correlation time per axis [s]; null: the plugin's default")
    min: Cur3 | None = Field(None, description="clipping bound per axis [m/s]")
    max: Cur3 | None = Field(None, description="clipping bound per axis [m/s]")
    seed: int | None = Field(None, ge=0, le=SEED_MAX, description="random stream; null: the scenario's seed")


class Knot(_Section):
    z: float = Field(ge=-11000.0, le=1000.0, description="depth coordinate, world z [m] (up)")
    velocity: Cur3 = Field(description="current at z, world [m/s]")


class CurrentSection(_Section):
    """The water current: one of the water plugin's models, set from the scenario."""

    model: Literal["constant", "gauss_markov", "profile"] = "constant"
    velocity: Cur3 = Field(default_factory=lambda: [0.0, 0.0, 0.0],
                           description="world [m/s]: the constant current, or the Gauss-Markov start")
    gauss_markov: GaussMarkov | None = Field(None, description="with model: gauss_markov")
    profile: list[Knot] | None = Field(None, description="with model: profile (z strictly increasing)")

    @model_validator(mode="after")
    def _consistent(self) -> "CurrentSection":
        if self.gauss_markov is not None and self.model != "gauss_markov":
            raise _Issues([(("gauss_markov",), f"applies to model: gauss_markov (model is {self.model!r})", _NO)])
        if self.profile is not None and self.model != "profile":
            raise _Issues([(("profile",), f"applies to model: profile (model is {self.model!r})", _NO)])
        if self.model == "profile":
            if not self.profile:
                raise _Issues([(("profile",), "model: profile needs knots [{z, velocity}, ...]", _NO)])
            for i, (a, b) in enumerate(zip(self.profile, self.profile[1:])):
                if not b.z > a.z:
                    raise _Issues([(("profile", i + 1, "z"), f"must be greater than the previous knot's {a.z:g} m",
                                    b.z)])
        gm = self.gauss_markov
        if gm is not None and gm.min is not None and gm.max is not None:
            if any(a > b for a, b in zip(gm.min, gm.max)):
                raise _Issues([(("gauss_markov",), "min must not exceed max in any axis", {"min": gm.min, "max": gm.max})])
        return self

    def current(self, seed: int) -> Current:
        """As :class:`uvms_mj.physics.current.Current` (``seed``: the scenario's, unless given)."""
        gm = self.gauss_markov or GaussMarkov()
        return Current(model=self.model, velocity=tuple(self.velocity), mean=gm.mean, sigma=gm.sigma, tau=gm.tau,
                       vmin=gm.min, vmax=gm.max, seed=int(gm.seed if gm.seed is not None else seed) % 2**64,
                       profile=[(k.z, *(list(k.velocity) + [0.0] * (3 - len(k.velocity)))) for k in self.profile or []])


class WavesSection(_Section):
    """Linear waves (:class:`uvms_mj.physics.waves.Waves`; docs/hydrodynamics.md "Waves"): a regular
    Airy wave or an irregular sea from a JONSWAP or Pierson-Moskowitz spectrum; the current adds to
    them. ``height``/``hs`` and ``period``/``tp`` are two spellings of one field each (give one)."""

    model: Literal["airy", "jonswap", "pierson_moskowitz"]
    height: float | None = Field(None, ge=SIZE_MIN, le=30.0, description="airy: wave height H = 2a; spectra: Hs [m]")
    hs: float | None = Field(None, ge=SIZE_MIN, le=30.0, description="the significant wave height Hs [m] (= height)")
    period: float | None = Field(None, ge=WAVE_PERIOD_MIN, le=60.0,
                                 description="airy: period T; spectra: peak period Tp [s]")
    tp: float | None = Field(None, ge=WAVE_PERIOD_MIN, le=60.0, description="the peak period Tp [s] (= period)")
    gamma: float = Field(DEFAULT_GAMMA, ge=1.0, le=7.0, description="JONSWAP peak enhancement factor")
    direction: float = Field(0.0, ge=-360.0, le=360.0, description="mean direction of travel, world, from +x "
                             "towards +y, in angle_unit")
    angle_unit: Literal["deg", "rad"] = "deg"
    spreading: float = Field(0.0, ge=0.0, le=MAX_SPREADING, description="cos^n spreading exponent n (0: "
                             "long-crested)")
    depth: float | None = Field(None, ge=0.01, le=11000.0,
                                description="water depth [m] (at least 1 cm); null: deep water")
    surface: float = Field(0.0, ge=-11000.0, le=1000.0, description="world z of the mean surface [m]")
    seed: int | None = Field(None, ge=0, le=SEED_MAX, description="random phases; null: the scenario's seed")
    n_components: int = Field(DEFAULT_COMPONENTS, ge=1, le=MAX_COMPONENTS, description="components of a spectrum")

    @model_validator(mode="after")
    def _one_spelling(self) -> "WavesSection":
        for a, b in (("height", "hs"), ("period", "tp")):
            va, vb = getattr(self, a), getattr(self, b)
            if va is not None and vb is not None:
                raise _Issues([((b,), f"give {a} or {b}, not both", vb)])
            if va is None and vb is None:
                raise _Issues([((a,), f"waves need {a} (or {b})", _NO)])
        if self.model == "airy" and self.hs is not None:
            raise _Issues([(("hs",), "a regular (airy) wave takes height (H = 2a), not hs", self.hs)])
        return self

    def waves(self, seed: int) -> Waves:
        """As :class:`uvms_mj.physics.waves.Waves` (``seed``: the scenario's, unless given)."""
        d = self.direction if self.angle_unit == "rad" else math.radians(self.direction)
        return Waves(model=self.model, height=float(self.height if self.height is not None else self.hs),
                     period=float(self.period if self.period is not None else self.tp), gamma=self.gamma,
                     direction=d, spreading=self.spreading, depth=0.0 if self.depth is None else self.depth,
                     surface=self.surface, seed=int(self.seed if self.seed is not None else seed) % 2**64,
                     n_components=self.n_components)


class Failure(_Section):
    """A thruster failing during the run: zero force from time t (the controller is not told)."""

    thruster: str = Field(min_length=1, description="the thruster actuator's name")
    t: float = Field(ge=0, le=DURATION_MAX, description="failure time [s]")

    def failure(self) -> ThrusterFailure:
        return ThrusterFailure(thruster=self.thruster, t=float(self.t))


class PayloadSection(_Section):
    """A payload picked up during the run (:class:`uvms_mj.plant.robot.Payload`), unknown to the
    nominal model."""

    mass: float = Field(ge=SIZE_MIN, le=1000.0, description="[kg] (at least 1e-9: smaller is no payload)")
    t: float = Field(0.0, ge=0, le=DURATION_MAX, description="pick-up time [s]")
    site: str | None = Field(None, min_length=1, description="site it is welded to; null: the tip site")
    radius: float = Field(0.02, ge=SIZE_MIN, le=1.0, description="for its inertia (solid sphere) [m]")
    volume: float = Field(0.0, ge=0, le=1.0, description="displaced volume [m^3]: 0, or at least 1e-9")
    offset: Annotated[list[Annotated[float, Field(ge=-1.0, le=1.0)]], Field(min_length=3, max_length=3)] = Field(
        default_factory=lambda: [0.0, 0.0, 0.0], description="centre in the site frame [m], within +-1 m")

    @model_validator(mode="after")
    def _volume(self) -> "PayloadSection":
        if 0 < self.volume < SIZE_MIN:
            raise _Issues([(("volume",), f"must be 0 or at least {SIZE_MIN:g} m^3", self.volume)])
        return self

    def payload(self):
        from uvms_mj.plant.robot import Payload

        return Payload(mass=self.mass, t=self.t, site=self.site, offset=tuple(self.offset), radius=self.radius,
                       volume=self.volume)


class TetherSection(_Section):
    """A tether from a surface point to the vehicle (:class:`uvms_mj.plant.tether.Tether`, MJCF robots with a free
    vehicle), unknown to the nominal model; defaults: von Benzon et al. 2022's tether (J. Mar. Sci. Eng. 10(12)
    1898)."""

    length: float = Field(gt=0, le=POSITION_MAX, description="[m]")
    segments: int = Field(20, ge=2, le=200, description="rigid segments of length / segments")
    anchor: Vec3 | None = Field(None, description="world point of the upper end [m]; null: straight above the "
                                "vehicle's initial attachment point at z = surface")
    attach: Vec3 = Field(default_factory=lambda: [0.0, 0.0, 0.0], description="on the vehicle, body frame [m]")
    diameter: float = Field(0.0075, gt=0, le=1.0, description="[m] (von Benzon et al. 2022: 7.5 mm)")
    mass_per_length: float = Field(0.043, gt=0, le=100.0, description="[kg/m] (von Benzon et al. 2022: 0.043)")
    cn: float = Field(1.2, ge=0, le=10.0, description="normal drag coefficient (von Benzon et al. 2022: 1.2)")
    ct: float = Field(0.01, ge=0, le=10.0, description="tangential drag coefficient (von Benzon et al. 2022: 0.01)")
    added_mass: bool = Field(True, description="the segments' potential-flow added mass (Ca = 1 across)")
    damping: float = Field(0.0, ge=0, le=100.0, description="joint damping of the chain [N m s/rad] (ours; 0: none)")
    surface: float = Field(0.0, ge=-POSITION_MAX, le=POSITION_MAX, description="world z of the default anchor [m]")

    def tether(self):
        from uvms_mj.plant.tether import Tether

        return Tether(length=self.length, segments=self.segments,
                      anchor=tuple(self.anchor) if self.anchor is not None else None, attach=tuple(self.attach),
                      diameter=self.diameter, mass_per_length=self.mass_per_length, cn=self.cn, ct=self.ct,
                      added_mass=self.added_mass, damping=self.damping, surface=self.surface)


class PlantSection(_Section):
    """The simulated truth, for every robot (what applies to one kind only says so)."""

    model_mismatch: bool | None = Field(None, description="the paper's robot: experiment.truth_overrides() and "
                                        "MuJoCo ellipsoid drag (null: true); not for other robots")
    overrides: dict[str, Any] = Field(default_factory=dict, description="'<element>.<field>': value (the vehicle "
                                      "role, factors 'x1.3'; the paper's robot: its own keys too), applied on top")
    hydro: Hydro = Field(default_factory=Hydro)
    gravity: bool = True
    current: Cur3 | None = Field(None, description="a uniform current, world [m/s] (the older spelling of "
                                 "current: {velocity: ...}); null: the model's (the paper's robot: still water)")
    overrides_file: str | None = Field(None, min_length=1, max_length=4096, description=(
        "MJCF robots: a YAML file of '<element>.<field>': value overrides (e.g. what uvms-mj identify writes), "
        "relative to the scenario file; applied before overrides"))
    payload: PayloadSection | None = Field(None, description="a payload picked up during the run")
    seabed_depth: float | None = Field(None, gt=0, le=11000.0, description=(
        "robots with a free vehicle: a flat seabed (a plane geom, no contacts) at world z = -seabed_depth [m], "
        "for the navigation DVL's beams; null: the model's own scene"))
    tether: TetherSection | None = Field(None, description="MJCF robots: a tether from a surface point to the "
                                         "vehicle (von Benzon et al. 2022's by default)")


class ThrustersSection(_Section):
    """The plant's thrusters, for every robot (the controller allocates with the nominal model's,
    as if ideal); null: the model file's."""

    tau: float | None = Field(None, ge=0, le=TAU_MAX, description="first-order lag [s] of every thruster")
    force_range: Annotated[list[Annotated[float, Field(ge=-FORCE_MAX, le=FORCE_MAX)]],
                           Field(min_length=2, max_length=2)] | None = Field(None, description="[min, max] [N]")
    dead_zone: bool | Annotated[list[float], Field(min_length=2, max_length=2)] | None = Field(
        None, description="[low, high]: commands strictly inside give no thrust (the thrusters' command units: "
        "newtons for the paper's robot, the thruster plugin's for curve thrusters); the paper's robot also "
        "true / false (its band, dead_zone_band)")
    dead_zone_band: Annotated[list[Annotated[float, Field(ge=-FORCE_MAX, le=FORCE_MAX)]],
                              Field(min_length=2, max_length=2)] | None = Field(
        None, description="the paper's robot: the band of dead_zone: true, [low, high] [N]")
    failures: list[Failure] = Field(default_factory=list, description="thrusters failing during the run")

    def overrides(self) -> dict:
        """An MJCF robot's thrusters as ``thrusters.*`` overrides (:func:`uvms_mj.plant.robot.apply_overrides`)."""
        return {f"thrusters.{k}": v for k, v in (("tau", self.tau), ("dead_zone", self.dead_zone),
                                                ("forcerange", self.force_range))
                if v is not None and not isinstance(v, bool)}


class Setpoint(_Section):
    """A pose the vehicle is to hold; what is not given stays the initial state's."""

    position: Vec3 | None = Field(None, description="vehicle origin, world [m] (planar robots: along the base's slides)")
    orientation: Orientation | None = None
    angle_unit: Literal["deg", "rad"] = Field("deg", description="unit of orientation.rpy")

    def pose(self, plant) -> list[float]:
        """The setpoint as the base's qpos (free: x, y, z, qw, qx, qy, qz; planar: one per base
        joint): the plant's initial state with the setpoint's position and orientation
        (:meth:`uvms_mj.plant.layout.InitialState.apply`, which also maps a pose onto a planar
        base's joints).

        Raises:
            uvms_mj.plant.errors.ParameterError: a pose a planar base cannot take."""
        import dataclasses

        import mujoco

        k = math.pi / 180.0 if self.angle_unit == "deg" else 1.0
        st = plant.initial
        if self.position is not None:
            st = dataclasses.replace(st, position=tuple(self.position))
        if self.orientation is not None:
            st = dataclasses.replace(st, quat=(tuple(self.orientation.quat) if self.orientation.quat is not None
                                               else tuple(quat_from_rpy(*(k * v for v in self.orientation.rpy)))))
        d = mujoco.MjData(plant.model)
        st.apply(plant.model, d, plant.layout)
        a = plant.layout.base_qadr
        return d.qpos[a:a + plant.layout.base_nq].tolist()


class Vehicle(_Section):
    """What the vehicle is to do: hold a setpoint, or follow a trajectory of its origin."""

    setpoint: Setpoint | None = Field(None, description="the pose to hold; null: the first measurement's "
                                        "(a floating vehicle's position and yaw, level: station_attitude)")
    trajectory: dict[str, Any] | None = Field(
        None, description="the vehicle origin's path (world; uvms_mj.control.trajectories kinds), started at "
        "the setpoint (or the initial position); for controllers that take base_trajectory")

    @model_validator(mode="after")
    def _trajectory(self) -> "Vehicle":
        if self.trajectory is not None:
            from uvms_mj.control.trajectories import make_trajectory

            try:
                make_trajectory(self.trajectory)
            except ValueError as exc:
                msg = str(exc)
                raise _Issues([(("trajectory",), msg[len("trajectory."):] if msg.startswith("trajectory.") else msg,
                                _NO)]) from None
        return self



def _takers(param: str) -> list[str]:
    from uvms_mj.control import available
    from uvms_mj.scenario.base import _controller_signature

    out = []
    for n in available():
        try:
            if param in _controller_signature(n)[0]:
                out.append(n)
        except Exception:  # noqa: BLE001 - a broken plug-in is not offered
            continue
    return out


def vehicle_issues(vehicle: Vehicle, controller: str, params: dict | None = None) -> list:
    """Problems of the vehicle section with the scenario's controller: a setpoint needs a
    controller taking ``base_reference``, a trajectory one taking ``base_trajectory``; neither
    may be given twice (section and controller.params), nor a setpoint with
    ``controller.params.station_attitude`` (:mod:`uvms_mj.control.station`)."""
    from uvms_mj.scenario.base import _controller_signature

    try:
        named, _ = _controller_signature(controller)
    except Exception:  # noqa: BLE001 - an unknown controller is reported elsewhere
        return []
    issues = []
    for field, param, value in (("setpoint", "base_reference", vehicle.setpoint),
                                ("trajectory", "base_trajectory", vehicle.trajectory)):
        if value is None:
            continue
        if param not in named:
            issues.append((("vehicle", field), f"controller {controller!r} takes no vehicle {field} ({param}); "
                           f"controllers that do: {', '.join(_takers(param)) or 'none'}", _NO))
        elif params and params.get(param) is not None:
            issues.append((("vehicle", field), f"give either vehicle.{field} or controller.params.{param}, not both",
                           _NO))
    if vehicle.setpoint is not None and params and params.get("station_attitude") is not None:
        issues.append((("vehicle", "setpoint"), "give either vehicle.setpoint or controller.params.station_attitude "
                       "(the attitude of the default station, without a setpoint), not both", _NO))
    return issues


def vehicle_params(vehicle: Vehicle, plant, base_dir: str | None = None) -> dict:
    """The controller parameters of the vehicle section on a built plant: ``base_reference``
    (the setpoint as the base's qpos, missing parts from the initial state) and
    ``base_trajectory`` (the path started at the setpoint's position, else the initial one)."""
    out: dict = {}
    q0 = plant.q
    if vehicle.setpoint is not None:
        try:
            out["base_reference"] = vehicle.setpoint.pose(plant)
        except ParameterError as exc:
            raise ParameterError(f"vehicle.setpoint: {str(exc).removeprefix('initial.')}") from None
    if vehicle.trajectory is not None:
        from uvms_mj.control.trajectories import make_trajectory, starting_at

        lay = plant.layout
        start = (np.asarray(vehicle.setpoint.position, dtype=float) if vehicle.setpoint is not None
                 and vehicle.setpoint.position is not None else np.asarray(q0[lay.base_qadr:lay.base_qadr + 3]))
        out["base_trajectory"] = starting_at(make_trajectory(vehicle.trajectory, base_dir=base_dir), start)
    return out
