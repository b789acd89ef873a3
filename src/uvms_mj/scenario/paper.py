"""What a scenario on the paper's robot (``robot: paper``, the default) adds to the one schema
(:class:`uvms_mj.scenario.document.Scenario`): its own defaults and checks.

The defaults are the paper experiment (:class:`uvms_mj.sim.experiment.PaperExperiment`), so an
empty file runs exactly what ``PaperExperiment().run()`` runs:

- ``plant.model_mismatch`` null: true (experiment.truth_overrides(): potential-flow added mass,
  +1 % base volume, offset centre of buoyancy; and MuJoCo ellipsoid drag unless
  ``plant.hydro.drag`` says otherwise); ``plant.current`` null: still water [0, 0];
- ``thrusters`` tau, force_range and dead_zone_band null: the model file's (filled in),
  ``dead_zone`` true / false (its band) or a band [N];
- the trajectory: the paper's end-tip line (:mod:`uvms_mj.scenario.paths`), the controller
  ``rac_dob`` at its own period (1/60 s), 40 s.

The robot's own parameter keys (:data:`OVERRIDE_NAMES`: ``base.added_mass`` = [m_Ax, m_Ay,
I_A], ``base.volume``, ...) are accepted in ``plant.overrides`` / ``nominal.overrides`` beside
element names and roles; thruster keys belong in the thrusters section (plant) and in
``nominal.overrides`` (the controller's model). What applies to other robots only (an overrides
file, a vehicle trajectory) is refused in one line.
"""

from __future__ import annotations

import copy
from functools import lru_cache
from typing import Any

import mujoco

from uvms_mj.plant.params import HYDRO_BODIES, OVERRIDE_KEYS, ParameterError, compile_robot, read_params
from uvms_mj.plant.plant import default_model_path, models_dir
from uvms_mj.scenario.base import (
    _NO_VALUE,
    PARAM_ABS_MAX,
    SIZE_MIN,
    _is_number,
    _non_finite,
    _out_of_range,
)

__all__ = ["OVERRIDE_NAMES", "check_overrides", "paper_fill", "paper_issues", "paper_nominal_issues", "paper_plant_issues",
           "paper_plant_overrides", "paper_thrusters_issues"]


@lru_cache(maxsize=1)
def _plant_model() -> mujoco.MjModel:
    """The default plant model (compiled once; callers copy it before changing it)."""
    return compile_robot(default_model_path())


@lru_cache(maxsize=1)
def _thruster_defaults() -> dict:
    p = read_params(_plant_model())
    thr = p.thrusters[0]
    return {"tau": float(thr.tau), "force_range": [float(v) for v in thr.force_range],
            "dead_zone_band": [float(v) for v in p.dead_zone]}


#: Parameter override keys with the body placeholder expanded (base.mass, link1.mass, ...).
OVERRIDE_NAMES: tuple[str, ...] = tuple(
    k2 for k in OVERRIDE_KEYS for k2 in ([k.replace("BODY", b) for b in HYDRO_BODIES] if "BODY" in k else [k])
)


def _generic(key: str) -> str:
    head, _, field = key.partition(".")
    return f"BODY.{field}" if head in HYDRO_BODIES else key


def check_overrides(overrides: dict, allow_thrusters: bool) -> list[tuple[tuple, str, Any]]:
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


def paper_fill(sc) -> None:
    """The paper robot's defaults of the plant and thrusters sections (module docstring)."""
    pl, th = sc.plant, sc.thrusters
    if pl.model_mismatch is None:
        pl.model_mismatch = True
    if pl.current is None:
        pl.current = [0.0, 0.0]
    _fill_thrusters(th)


def _fill_thrusters(th) -> None:
    for key, value in _thruster_defaults().items():
        if getattr(th, key) is None:
            setattr(th, key, copy.deepcopy(value))
    if th.dead_zone is None:
        th.dead_zone = False


def paper_plant_issues(pl) -> list:
    """The plant section on the paper's robot (paths below ``plant``): its own override keys,
    no overrides file."""
    issues = [(("overrides",) + p, m, v) for p, m, v in check_overrides(pl.overrides, allow_thrusters=False)]
    if pl.overrides_file is not None:
        issues.append((("overrides_file",), "applies to MJCF robots; on the paper's robot give plant.overrides",
                       pl.overrides_file))
    if pl.tether is not None:
        issues.append((("tether",), "applies to MJCF robots with a free vehicle (the paper's planar robot has no "
                       "tether)", _NO_VALUE))
    return issues


def paper_nominal_issues(nom) -> list:
    """The nominal section on the paper's robot (paths below ``nominal``)."""
    return [(("overrides",) + p, m, v) for p, m, v in check_overrides(nom.overrides, allow_thrusters=True)]


def paper_thrusters_issues(th) -> list:
    """The thrusters section on the paper's robot (paths below ``thrusters``), its defaults
    filled in: the model file's tau, force range and band."""
    _fill_thrusters(th)
    issues = []
    lo, hi = th.force_range
    if not lo < 0 < hi:
        issues.append((("force_range",), "must satisfy min < 0 < max [N]", th.force_range))
    if th.tau <= 0:
        issues.append((("tau",), "must be > 0 s (the paper's thrusters are lagged)", th.tau))
    for key in ("dead_zone_band",) + (("dead_zone",) if isinstance(th.dead_zone, list) else ()):
        lo, hi = getattr(th, key)
        if not lo <= 0 <= hi:
            issues.append(((key,), "must satisfy low <= 0 <= high [N]", getattr(th, key)))
    return issues


def paper_issues(sc) -> list:
    """What the paper's robot refuses across sections: a vehicle trajectory."""
    if sc.vehicle.trajectory is not None:
        return [(("vehicle", "trajectory"), "the paper's robot takes a vehicle setpoint only (its controllers "
                 "carry the arm's tip on the trajectory section)", _NO_VALUE)]
    return []


@lru_cache(maxsize=1)
def _truth() -> dict:
    from uvms_mj.sim.experiment import truth_overrides

    return truth_overrides()


def paper_plant_overrides(sc) -> dict:
    """Every parameter override the paper robot's plant gets: the truth differences (if
    model_mismatch), then plant.overrides, then the thrusters section (as its own keys)."""
    over = copy.deepcopy(_truth()) if sc.plant.model_mismatch else {}
    over.update(copy.deepcopy(sc.plant.overrides))
    th = sc.thrusters
    over["thrusters.tau"] = th.tau
    over["thrusters.force_range"] = list(th.force_range)
    over["thrusters.dead_zone"] = list(th.dead_zone) if isinstance(th.dead_zone, list) else list(th.dead_zone_band)
    return over
