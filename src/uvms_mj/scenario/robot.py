"""What a scenario on an MJCF robot (``robot:`` a built-in other than ``paper``, or a model
file) adds to the one schema (:class:`uvms_mj.scenario.document.Scenario`): its overrides
checked on its model, an overrides file, and one-line refusals of what applies to the paper's
robot only (``plant.model_mismatch``, ``lagged`` added mass, ``mujoco`` drag, a dead zone of
``true``).

.. code-block:: yaml

    name: station_arm_sweep
    robot: bluerov2_alpha        # built-in name or MJCF path (relative: to the scenario file)
    initial:
      position: [0, 0, -1]       # vehicle origin, world [m]
      orientation: {rpy: [0, 0, 0]}
      joints: {alpha_shoulder: 90}
    arm:                         # desired arm motion (min-jerk segments, at rest at each waypoint)
      waypoints:
        - {t: 3.0, joints: {alpha_base: 60, alpha_shoulder: 120}}
    trajectory: {kind: circle, centre: [0, 0, 0], radius: 0.05, normal: [1, 0, 0], period: 20}
    controller: {name: station_pid}

A controller works on these robots when its class says ``robots = "floating"`` (or ``"any"``).
"""

from __future__ import annotations

from pathlib import Path

from uvms_mj.plant.files import robot_path
from uvms_mj.plant.params import ParameterError
from uvms_mj.plant.robot import compile_robot_spec
from uvms_mj.scenario.base import _NO_VALUE, _jsonable

__all__ = ["mjcf_nominal_issues", "mjcf_plant_issues", "mjcf_plant_overrides", "mjcf_thrusters_issues", "read_overrides_file",
           "robot_info"]


def _override_issues(overrides: dict, path: Path) -> list:
    issues = []
    for key, value in overrides.items():
        try:
            compile_robot_spec(path, {key: value})
        except ParameterError as exc:
            msg = str(exc)
            msg = msg.split(": ", 1)[1] if msg.startswith("override ") and ": " in msg else msg
            issues.append((("overrides", key), msg, value))
    return issues


def mjcf_plant_issues(pl, path: Path, base_dir: str | None) -> list:
    """The plant section on an MJCF robot (paths below ``plant``): each override applied alone
    to the model file (to find the culprit), the overrides file, and what applies to the
    paper's robot only."""
    issues: list = []
    if pl.overrides_file is not None:
        try:
            compile_robot_spec(path, read_overrides_file(pl.overrides_file, base_dir))
        except ParameterError as exc:
            issues.append((("overrides_file",), str(exc), _NO_VALUE))
    issues += _override_issues(pl.overrides, path)
    if pl.model_mismatch:
        issues.append((("model_mismatch",), "applies to the paper's robot only (give the truth's differences as "
                       "plant.overrides)", True))
    hy = pl.hydro
    if hy.added_mass == "lagged":
        issues.append((("hydro", "added_mass"), "'lagged' applies to the paper's robot only; allowed here: exact, off",
                       hy.added_mass))
    if hy.drag == "mujoco":
        issues.append((("hydro", "drag"), "'mujoco' applies to the paper's robot only; allowed here: strip, off",
                       hy.drag))
    return issues


def mjcf_nominal_issues(nom, path: Path) -> list:
    """The nominal section on an MJCF robot (paths below ``nominal``)."""
    return _override_issues(nom.overrides, path)


def mjcf_thrusters_issues(th, path: Path) -> list:
    """The thrusters section on an MJCF robot (paths below ``thrusters``): applied as
    overrides of its thrusters; the paper robot's true / band refused."""
    issues = []
    if isinstance(th.dead_zone, bool) and th.dead_zone:
        issues.append((("dead_zone",), "give the band [low, high] in the thrusters' command units "
                       "(true means the paper robot's band)", True))
    if th.dead_zone_band is not None:
        issues.append((("dead_zone_band",), "applies to the paper's robot (with dead_zone: true); "
                       "give dead_zone: [low, high]", th.dead_zone_band))
    for key, value in th.overrides().items():
        try:
            compile_robot_spec(path, {key: value})
        except ParameterError as exc:
            issues.append(((key.partition(".")[2].replace("forcerange", "force_range"),),
                           str(exc).split(": ", 1)[-1], value))
    return issues


#: The largest overrides file read [bytes] (ours: 1 MB, thousands of overrides; `identify` writes a
#: few hundred bytes): a bigger file is refused rather than parsed.
OVERRIDES_FILE_MAX = 1_000_000


def read_overrides_file(path: str, base_dir: str | None) -> dict:
    """The overrides of a YAML file (a mapping of "<element>.<field>" to values).

    Raises:
        ParameterError: missing or unreadable file, not a mapping of strings to numbers/lists.
    """
    import yaml

    try:
        p = Path(path).expanduser()
    except RuntimeError as exc:
        raise ParameterError(f"{path}: cannot expand '~' ({exc})") from None
    if not p.is_absolute() and base_dir is not None:
        p = Path(base_dir) / p
    try:
        st = p.stat()
        if p.is_dir():
            raise ParameterError(f"{path}: is a folder; an overrides file is a YAML file")
        if not p.is_file():  # a FIFO, a device (/dev/zero): reading could never end
            raise ParameterError(f"{path}: not a regular file; an overrides file is a YAML file")
        if st.st_size > OVERRIDES_FILE_MAX:
            raise ParameterError(f"{path}: {st.st_size} bytes; an overrides file is at most {OVERRIDES_FILE_MAX} bytes")
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


def mjcf_plant_overrides(sc) -> dict:
    """An MJCF robot plant's overrides: the overrides file's, then plant.overrides, then the
    thrusters section's."""
    over = {}
    if sc.plant.overrides_file is not None:
        over.update(read_overrides_file(sc.plant.overrides_file, sc.base_dir))
    over.update(sc.plant.overrides)
    over.update(sc.thrusters.overrides())
    return over


def robot_info(sc, plant=None) -> dict:
    """An MJCF robot's run for logs: {name, path, overrides, layout}."""
    from uvms_mj.plant.layout import Layout

    path = robot_path(sc.robot, sc.base_dir)
    lay = plant.layout if plant is not None else Layout.of(compile_robot_spec(path), sc.tip_site, allow_planar=True)
    return {"name": sc.robot, "path": str(path), "overrides": _jsonable(mjcf_plant_overrides(sc)),
            "layout": lay.describe()}
