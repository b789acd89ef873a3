"""Where the robots' model files are: the built-in names and the models folder.

A robot is a built-in name (:data:`BUILTIN_ROBOTS`) or the path of an MJCF file; the built-in
files live in the repository's ``models/`` folder (or the copy packaged in the wheel).
"""

from __future__ import annotations

import difflib
from pathlib import Path

from uvms_mj.plant.errors import ParameterError

__all__ = ["BUILTIN_ROBOTS", "ROBOT_FILES", "default_model_path", "models_dir", "nominal_model_path", "robot_path"]

_PKG = Path(__file__).resolve().parents[1]  # the uvms_mj package folder


def models_dir() -> Path:
    """Folder of the robot models, one sub-folder per robot, and ``uvms.xml`` (the paper's robot)
    (the repository's ``models/``, or the packaged copy)."""
    for cand in (_PKG.parents[1] / "models", _PKG / "models"):
        if (cand / "uvms.xml").is_file():
            return cand
    raise FileNotFoundError("cannot find the uvms_mj models folder (models/uvms.xml)")


def default_model_path() -> Path:
    """The default plant model: ``models/paper/scene.xml`` (robot + floor, lights, cameras)."""
    return models_dir() / "paper" / "scene.xml"


#: Built-in robots: name -> file in ``models/``, one folder per robot (``models/README.md``;
#: "paper": the paper's planar robot in its scene; every robot runs on
#: :class:`uvms_mj.plant.plant.Plant`).
BUILTIN_ROBOTS: dict[str, str] = {
    "paper": "paper/scene.xml",
    "bluerov2_heavy": "bluerov2_heavy/bluerov2_heavy.xml",
    "bluerov2_alpha": "bluerov2_alpha/bluerov2_alpha.xml",
    "hinsdale2023": "hinsdale2023/hinsdale2023.xml",
}


def robot_path(robot: str | Path, base_dir: str | Path | None = None) -> Path:
    """The MJCF file of a robot: a built-in name (:data:`BUILTIN_ROBOTS`) or a path (relative
    paths are taken relative to ``base_dir``, e.g. the scenario file's folder, then to the
    current folder).

    Raises:
        ParameterError: not a built-in name and no such file (the message lists the built-ins).
    """
    key = str(robot)
    if key in BUILTIN_ROBOTS:
        return models_dir() / BUILTIN_ROBOTS[key]
    try:
        p = Path(key).expanduser()
    except RuntimeError as exc:  # '~nosuchuser/...': no such user's home
        raise ParameterError(f"robot = {key!r}: cannot expand '~' ({exc}); give the file's path") from None
    cands = [p] if p.is_absolute() else ([Path(base_dir) / p] if base_dir is not None else []) + [p]
    for c in cands:
        if c.is_file():
            size = c.stat().st_size
            if size > MJCF_FILE_MAX:
                raise ParameterError(f"robot = {key!r}: {size} bytes; an MJCF file is at most {MJCF_FILE_MAX} bytes")
            return c.resolve()
        if c.exists():  # a folder, a FIFO, a device (/dev/zero): MuJoCo's reader would block or never end
            what = "a folder" if c.is_dir() else "not a regular file"
            raise ParameterError(f"robot = {key!r}: {what}; give an MJCF file or a built-in robot "
                                 f"({', '.join(BUILTIN_ROBOTS)})")
    close = difflib.get_close_matches(key, list(BUILTIN_ROBOTS), n=1, cutoff=0.6)
    hint = f" (did you mean {close[0]!r}?)" if close else ""
    raise ParameterError(f"robot = {key!r}: neither a built-in robot{hint} ({', '.join(BUILTIN_ROBOTS)}) "
                         "nor an existing MJCF file")


#: The largest MJCF file a robot may be [bytes] (ours: the built-in robots' files are below 50 kB, their meshes
#: are separate files; a larger file is not a robot description written by hand).
MJCF_FILE_MAX = 10_000_000

#: Built-in robots whose robot file is separate from the scene they run in (mujoco_menagerie's
#: convention): name -> the robot file in ``models/`` (the paper's ``models/paper/scene.xml``
#: includes ``models/uvms.xml``). The others' files are the robot itself.
ROBOT_FILES: dict[str, str] = {"paper": "uvms.xml"}


def nominal_model_path(robot: str | Path, base_dir: str | Path | None = None) -> Path:
    """The robot's own model file, without its scene: what the controller's nominal model reads
    (:class:`uvms_mj.control.nominal.NominalRobot`); :data:`ROBOT_FILES`, else :func:`robot_path`.

    Raises:
        ParameterError: as :func:`robot_path`.
    """
    key = str(robot)
    if key in ROBOT_FILES:
        return models_dir() / ROBOT_FILES[key]
    return robot_path(robot, base_dir)
