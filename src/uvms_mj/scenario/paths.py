"""Scenario sections of the desired motion, for every robot: the end-effector's ``trajectory``
and the ``arm``'s joint waypoints.

``trajectory`` is any :mod:`uvms_mj.control.trajectories` kind, written as that kind's keys
(``{kind: circle, centre: [0, 0, -1], radius: 0.05, period: 20}``), plus ``origin`` (``tip``,
the default: the path is translated to start at the initial tip; ``world``: as written). The
kind ``line`` (the default kind: the paper's end-tip line, Section 4) may leave out ``start``:
it then starts at the initial tip and ends at ``target`` (world) or at the initial tip plus
``displacement`` (exactly one of the two; neither: ``displacement: [0.3, 0.0]``, the paper's
0.3 m along x). Positions are world [m]; on a planar robot 2 numbers (x, y; z ignored: the
robot's plane), on others 3. ``curve: {...}`` is the older spelling of a non-line kind.
"""

from __future__ import annotations

import copy
from dataclasses import MISSING, fields
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import ConfigDict, Field, model_serializer, model_validator

from uvms_mj.scenario.base import (
    _NO_VALUE,
    ACCEL_MAX,
    ANGLE_MAX,
    DURATION_MAX,
    LENGTH_MAX,
    PARAM_ABS_MAX,
    SIZE_MIN,
    SPEED_MAX,
    _Issues,
    _non_finite,
    _out_of_range,
    _Section,
    _suggest,
)

__all__ = ["Arm", "PAPER_DISPLACEMENT", "TrajectorySection", "Waypoint", "tip_path"]

#: The line's default end point relative to the initial tip [m] (the paper's Section 4: 0.3 m
#: along x).
PAPER_DISPLACEMENT = (0.3, 0.0)

LengthVec = Annotated[list[Annotated[float, Field(ge=-LENGTH_MAX, le=LENGTH_MAX)]], Field(min_length=2, max_length=3)]

#: The keys of kind ``line`` in a scenario (Line3D's fields, displacement and origin).
LINE_KEYS = ("kind", "origin", "start", "target", "displacement", "cruise_speed", "accel", "t_start")
_LINE_ONLY = ("start", "target", "displacement")


def _line_defaults() -> dict:
    from uvms_mj.control.trajectories import Line3D

    return {f.name: f.default for f in fields(Line3D) if f.default is not MISSING}


class TrajectorySection(_Section):
    """The end-effector's desired path (module docstring): a trajectory kind's keys, ``origin``,
    and for a ``line`` the paper's ``target`` / ``displacement`` alternatives."""

    model_config = ConfigDict(extra="allow", strict=True, allow_inf_nan=False, validate_default=False,
                              defer_build=True)

    kind: str = Field("line", description="line | waypoints | circle | lemniscate | helix | csv "
                      "(uvms_mj.control.trajectories.KINDS); the kind's own keys beside it")
    origin: Literal["tip", "world"] = Field("tip", description="tip: translated to start at the initial tip; "
                                            "world: as written")
    start: LengthVec | None = Field(None, description="line: first point, world [m]; null: the initial tip")
    target: LengthVec | None = Field(None, description="line: end point, world [m]")
    displacement: LengthVec | None = Field(None, description="line: end point minus the start [m]; default "
                                           "[0.3, 0.0] when neither target nor start is given")
    cruise_speed: float | None = Field(None, ge=SIZE_MIN, le=SPEED_MAX, description="[m/s] (line: 0.02)")
    accel: float | None = Field(None, ge=SIZE_MIN, le=ACCEL_MAX, description="[m/s^2] (line: 0.02)")
    t_start: float | None = Field(None, ge=0, le=DURATION_MAX, description="rest before moving [s] (line: 1)")

    @model_validator(mode="before")
    @classmethod
    def _older_curve(cls, data: Any) -> Any:
        """``{curve: {kind: ..., ...}}`` (the older spelling) as the curve's own keys."""
        if isinstance(data, dict) and "curve" in data:
            data = dict(data)
            curve = data.pop("curve")
            if curve is None:
                return data
            if not isinstance(curve, dict):
                raise _Issues([(("curve",), "must be a trajectory mapping {kind: ..., ...}", curve)])
            others = [k for k in data if k not in ("origin",)]
            if others:
                raise _Issues([(("curve",), "trajectory.curve is the older spelling of a curve's keys written in "
                                "trajectory itself ({kind: circle, ...}); the line's keys (" + ", ".join(others)
                                + ") do not apply to a curve", _NO_VALUE)])
            data.update(curve)
        return data

    @model_validator(mode="after")
    def _check(self) -> "TrajectorySection":
        from uvms_mj.control.trajectories import KINDS

        kinds = list(KINDS)
        if self.kind not in kinds:
            raise _Issues([(("kind",), f"must be one of {', '.join(kinds)}{_suggest(self.kind, kinds)}", self.kind)])
        extra = dict(self.__pydantic_extra__ or {})
        if self.kind == "line":
            for k in extra:
                raise _Issues([((k,), f"unknown key {k!r} for kind 'line'{_suggest(k, LINE_KEYS)}; allowed: "
                                + ", ".join(LINE_KEYS), _NO_VALUE)])
            if self.target is not None and self.displacement is not None:
                raise _Issues([((), "give exactly one of target (world) and displacement (from the start), not both",
                                {"target": self.target, "displacement": self.displacement})])
            if self.target is None and self.displacement is None:
                if self.start is not None:
                    raise _Issues([((), "a line with a start needs a target or a displacement", _NO_VALUE)])
                self.displacement = list(PAPER_DISPLACEMENT)
            for k, v in _line_defaults().items():
                if getattr(self, k) is None:
                    setattr(self, k, v)
        else:
            for k, v in extra.items():  # a kind's own numbers (radius, period, points...): 1e308 ran as if fine
                if _out_of_range(v) or _non_finite(v):
                    raise _Issues([((k,), f"numbers must be finite, and 0 or within {SIZE_MIN:g} to "
                                    f"{PARAM_ABS_MAX:g} in magnitude", v)])
            given = [k for k in _LINE_ONLY if getattr(self, k) is not None]
            if given:
                raise _Issues([((given[0],), f"applies to kind 'line' only; kind {self.kind!r} takes its own keys "
                                "(uvms_mj.control.trajectories)", getattr(self, given[0]))])
        return self

    @model_serializer(mode="wrap")
    def _dump(self, handler):  # noqa: ANN001 - pydantic's signature
        return {k: v for k, v in handler(self).items() if v is not None}

    def vectors(self) -> dict[str, list]:
        """The position-like keys given (for the robot's 2-or-3-number check)."""
        out = {k: getattr(self, k) for k in _LINE_ONLY if getattr(self, k) is not None}
        out.update({k: v for k, v in (self.__pydantic_extra__ or {}).items()
                    if isinstance(v, list) and v and all(isinstance(x, (int, float)) for x in v)})
        return out


def _xyz(v) -> np.ndarray:
    a = np.asarray(v, dtype=float)
    return np.r_[a, 0.0] if a.size == 2 else a


def tip_path(section: TrajectorySection | None, tip0, base_dir: str | None = None):
    """The scenario's end-effector path (None: hold the initial tip), world [m].

    ``tip0``: the initial tip position (3 numbers, world; a planar robot's z is 0). A line
    without ``start`` runs from ``tip0`` to ``target``, or to ``tip0 + displacement``; every
    other path (and a line with a start) is translated to start at ``tip0`` with origin ``tip``.

    Raises:
        ValueError: the kind's own errors (naming ``trajectory.<key>``).
    """
    if section is None:
        return None
    from uvms_mj.control.trajectories import Line3D, make_trajectory, starting_at

    tip0 = _xyz(tip0)
    s = section
    if s.kind == "line" and s.start is None:
        target = tip0 + _xyz(s.displacement) if s.displacement is not None else _xyz(s.target)
        return Line3D(start=tuple(tip0.tolist()), target=tuple(target.tolist()), cruise_speed=s.cruise_speed,
                      accel=s.accel, t_start=s.t_start)
    spec = {k: v for k, v in s.model_dump().items() if k not in ("origin", "displacement")}
    if s.kind == "line":
        spec["start"] = _xyz(s.start).tolist()
        spec["target"] = (_xyz(s.start) + _xyz(s.displacement) if s.displacement is not None
                          else _xyz(s.target)).tolist()
    tr = make_trajectory(copy.deepcopy(spec), base_dir=base_dir)
    return starting_at(tr, tip0) if s.origin == "tip" else tr


class Waypoint(_Section):
    t: float = Field(gt=0, le=DURATION_MAX, description="[s]")
    joints: dict[str, Annotated[float, Field(ge=-ANGLE_MAX, le=ANGLE_MAX)]] = Field(
        description="joint name -> angle [arm.angle_unit], within +-720")


class Arm(_Section):
    """Desired arm motion: timed waypoints, minimum-jerk between them (at rest at each); for
    controllers that take ``arm_trajectory``."""

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

    def joint_trajectory(self, names, start):
        """As :class:`uvms_mj.control.nominal.JointTrajectory` from the start angles [rad]."""
        import math

        from uvms_mj.control.nominal import JointTrajectory

        k = math.pi / 180.0 if self.angle_unit == "deg" else 1.0
        return JointTrajectory.from_waypoints(names, start, [(w.t, {n: k * v for n, v in w.joints.items()})
                                                             for w in self.waypoints])
