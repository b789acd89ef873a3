"""Build any trajectory kind from a dict (a scenario section): :data:`KINDS`, :func:`make_trajectory`."""

from __future__ import annotations

from dataclasses import MISSING, fields
from pathlib import Path
from typing import Any, Mapping

from uvms_mj.control.trajectories.base import Trajectory, _suggest
from uvms_mj.control.trajectories.curves import Circle, Helix, Lemniscate
from uvms_mj.control.trajectories.lines import Line3D, Waypoints
from uvms_mj.control.trajectories.sampled import CsvTrajectory

__all__ = ["KINDS", "make_trajectory"]


# --------------------------------------------------------------------------- factory


#: kind name -> class, for :func:`make_trajectory`.
KINDS: dict[str, type[Trajectory]] = {
    "line": Line3D,
    "waypoints": Waypoints,
    "circle": Circle,
    "lemniscate": Lemniscate,
    "helix": Helix,
    "csv": CsvTrajectory,
}

#: Keys that are "exactly one of" groups rather than individually required.
_ONE_OF = {"durations", "cruise_speed", "omega", "period", "axial_speed", "pitch"}


def _keys(cls: type) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """(all keys, required keys) of a kind."""
    if cls is CsvTrajectory:
        return ("path", "bc_type"), ("path",)
    fs = [f for f in fields(cls) if f.init]
    keys = tuple(f.name for f in fs)
    req = tuple(
        f.name for f in fs if f.default is MISSING and f.default_factory is MISSING and f.name not in _ONE_OF
    )
    return keys, req



def make_trajectory(spec: Mapping[str, Any], *, base_dir: str | Path | None = None) -> Trajectory:
    """Build a trajectory from a dict: ``{"kind": <one of KINDS>, <that class's fields>...}``.

    Example: ``{"kind": "circle", "centre": [0.5, 0, -1], "radius": 0.1, "period": 20, "t_ramp": 5}``.
    A ``csv`` kind's relative ``path`` is resolved against ``base_dir`` (e.g. the scenario file's
    folder) when given. Raises ValueError naming the field, the value and what is allowed (with a
    did-you-mean for unknown kinds and keys).
    """
    if not isinstance(spec, Mapping):
        raise ValueError(f"trajectory = {spec!r} must be a mapping with a 'kind' key, one of {list(KINDS)}")
    if "kind" not in spec:
        raise ValueError(f"trajectory.kind is required: one of {list(KINDS)}")
    kind = spec["kind"]
    if not isinstance(kind, str) or kind not in KINDS:
        raise ValueError(f"trajectory.kind = {kind!r} must be one of {list(KINDS)}{_suggest(str(kind), list(KINDS))}")
    cls = KINDS[kind]
    keys, required = _keys(cls)
    args = {k: v for k, v in spec.items() if k != "kind"}
    for k in args:
        if k not in keys:
            raise ValueError(
                f"trajectory.{k}: unknown key for kind {kind!r}{_suggest(str(k), keys)}; allowed: {list(keys)}"
            )
    for k in required:
        if k not in args:
            raise ValueError(f"trajectory.{k} is required for kind {kind!r} (keys: {list(keys)})")
    if cls is CsvTrajectory:
        path = args["path"]
        if not isinstance(path, (str, Path)) or not str(path):
            raise ValueError(f"trajectory.path = {path!r} must be a file path (string)")
        p = Path(path)
        if base_dir is not None and not p.is_absolute():
            p = Path(base_dir) / p
        return CsvTrajectory(p, **({"bc_type": args["bc_type"]} if "bc_type" in args else {}))
    return cls(**args)  # every class validates and converts its fields (lists -> tuples)
