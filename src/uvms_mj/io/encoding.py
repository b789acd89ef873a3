"""How the recorder writes numbers and messages: compact JSON (NaN as null, +-inf as +-1e999,
shortest round-trip floats; orjson when installed), the samples' fields, Foxglove stamps, colours
and scene entities, and the templates of the paper robot's /tf messages and path strips."""

from __future__ import annotations

import dataclasses
import json
import math
import re
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np


# --------------------------------------------------------------------------- encoding helpers

_NONFINITE = re.compile(r'"(?:[^"\\]|\\.)*"|-?Infinity|NaN')


def _nonfinite_sub(m: re.Match) -> str:
    s = m.group(0)
    if s[0] == '"':
        return s
    return "null" if s == "NaN" else s.replace("Infinity", "1e999")


_ENCODER = json.JSONEncoder(separators=(",", ":"), allow_nan=False)
_ENCODER_NAN = json.JSONEncoder(separators=(",", ":"), allow_nan=True)


try:  # orjson: the same text (shortest round-trip floats) about 20x faster than json
    import orjson as _orjson
except ImportError:  # pragma: no cover - orjson is a dependency; keep working without it
    _orjson = None


def _enc(obj: Any) -> str:
    """Compact JSON text of a list or dict; NaN -> null, +-inf -> +-1e999 (valid JSON that
    Python and JavaScript parse back to +-inf)."""
    if _orjson is not None:
        out = _orjson.dumps(obj)
        if b"null" not in out:  # orjson writes NaN and +-inf as null: let json handle those
            return out.decode()
    try:
        return _ENCODER.encode(obj)
    except ValueError:
        return _NONFINITE.sub(_nonfinite_sub, _ENCODER_NAN.encode(obj))


def _dumps(obj: Any) -> bytes:
    return _enc(obj).encode()


def _json_default(o: Any) -> Any:
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    if dataclasses.is_dataclass(o) and not isinstance(o, type):
        return dataclasses.asdict(o)
    if hasattr(o, "model_dump"):  # pydantic
        return o.model_dump(mode="json")
    if isinstance(o, (set, frozenset)):
        return sorted(o, key=str)
    return str(o)


def _meta_value(v: Any) -> str:
    return json.dumps(v, sort_keys=True, default=_json_default)


def _ns(t: float) -> int:
    ns = int(round(float(t) * 1e9))
    if ns < 0:
        raise ValueError(f"sample time t = {t!r} s must be >= 0")
    return ns


def _stamp(ns: int) -> dict:
    sec, nsec = divmod(ns, 1_000_000_000)
    return {"sec": sec, "nsec": nsec}


def _quat_z(angle: float) -> dict:
    """Rotation by ``angle`` about +Z, Foxglove order (x, y, z, w)."""
    h = 0.5 * float(angle)
    return {"x": 0.0, "y": 0.0, "z": math.sin(h), "w": math.cos(h)}


_IDENTITY = {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}
_ZERO3 = {"x": 0.0, "y": 0.0, "z": 0.0}


def _color(r: float, g: float, b: float, a: float = 1.0) -> dict:
    return {"r": r, "g": g, "b": b, "a": a}


def _entity(frame_id: str, id: str, stamp: dict, frame_locked: bool = True, **prims: list) -> dict:
    ent = {"timestamp": stamp, "frame_id": frame_id, "id": id, "lifetime": {"sec": 0, "nsec": 0},
           "frame_locked": frame_locked, "metadata": []}
    for key in ("arrows", "cubes", "spheres", "cylinders", "lines", "triangles", "texts", "models"):
        ent[key] = list(prims.pop(key, []))
    if prims:
        raise TypeError(f"unknown primitive lists {sorted(prims)}")
    return ent


# --------------------------------------------------------------------------- samples


def _layout_entry(name: str, value: Any, index: int) -> dict | None:
    arr = np.asarray(value)
    if arr.dtype.kind not in "biuf":
        return None
    return {"name": name, "dtype": arr.dtype.name, "shape": list(arr.shape), "index": index}


def _encode(value: Any, is_bool: bool, flat: bool) -> Any:
    """A signal value as JSON-ready Python numbers: booleans as 0/1, arrays of 2 or more
    dimensions flattened (row-major; Foxglove's JSON-schema parser rejects nested arrays)."""
    if type(value) is np.ndarray and not flat:
        return (value.astype(np.uint8) if is_bool else value).tolist()
    if not (is_bool or flat) and isinstance(value, (float, int)) and not isinstance(value, bool):
        return value.item() if isinstance(value, np.generic) else value  # np.float64: orjson wants a float
    arr = np.asarray(value)
    if is_bool:
        arr = arr.astype(np.uint8)
    return (arr.ravel() if flat else arr).tolist()


_MISSING = object()
_NUMPY = _orjson.OPT_SERIALIZE_NUMPY if _orjson is not None else 0


def _special(v: Any, is_bool: bool) -> Any:
    """A boolean signal as 0/1, an array of 2 or more dimensions flattened (for orjson)."""
    if is_bool:
        if type(v) is bool:
            return int(v)
        if type(v) is np.ndarray and v.dtype == np.bool_:
            return (v.view(np.uint8) if v.ndim == 1 else v.ravel().view(np.uint8)) if v.ndim else int(v)
        v = np.asarray(v).astype(np.uint8)
        return int(v) if not v.ndim else v.ravel()
    return np.ravel(v)


def _batch_bodies(rows: list, plans: list) -> tuple[list[bytes], bool] | None:
    """The sample-channel bodies of rows holding the first row's signals, without their braces,
    row by row then channel by channel (what :func:`_sample_body` gives each, from one orjson
    call): per channel either the row without the other signals (``drop``) or its few fields
    picked; ``special`` fields converted (booleans to 0/1, 2-D arrays flattened). With them,
    whether any body holds a ``null`` (a non-finite number). None where the batch cannot be
    encoded at once (a value orjson cannot take)."""
    bodies = []
    for row in rows:
        for drop, special in plans:
            if drop is None:  # few fields: pick them
                body = {name: (row[name] if not (is_bool or flat) else _special(row[name], is_bool))
                        for name, is_bool, flat in special}
            else:  # most of the row: drop the others
                body = dict(row)
                for name in drop:
                    del body[name]
                for name, is_bool in special:
                    body[name] = _special(body[name], is_bool)
            bodies.append(body)
    try:
        text = _orjson.dumps(bodies, option=_NUMPY)
    except TypeError:
        return None
    parts = text.split(b"},{")
    # no body holds an object (values are numbers and arrays): one "{" per body
    if len(parts) != len(bodies) or text.count(b"{") != len(bodies):
        return None
    parts[0] = parts[0][2:]  # the list's "[{" and "}]"
    parts[-1] = parts[-1][:-2]
    return parts, text.find(b"null") >= 0


def _sample_body(row: Mapping[str, Any], fields: list[tuple[str, bool, bool]]) -> bytes:
    """The JSON object of one sample channel's fields present in ``row`` (as :func:`_encode`
    and :func:`_enc` write them). Fast path: orjson serialises the numpy arrays itself (the same
    shortest round-trip floats), booleans as 0/1 and 2-D arrays flattened; any value it cannot
    take (a non-contiguous or 0-d array...) or a non-finite number (orjson writes ``null``: our
    encoding writes +-inf as +-1e999) takes the general path."""
    if _orjson is not None:
        body = {name: (v if not (is_bool or flat) else _special(v, is_bool))
                for name, is_bool, flat in fields if (v := row.get(name, _MISSING)) is not _MISSING}
        try:
            out = _orjson.dumps(body, option=_NUMPY)
        except TypeError:
            out = b"null"
        if b"null" not in out:
            return out
    return _enc({name: _encode(row[name], is_bool, flat) for name, is_bool, flat in fields if name in row}).encode()


def _point(x: float, y: float, z: float | None = None) -> str:
    """A foxglove.Point3 (JSON text), rounded to 1 um; without ``z``, in the plane z = 0."""
    if z is None:
        return '{"x":%r,"y":%r,"z":0.0}' % (round(x, 6), round(y, 6))
    return '{"x":%r,"y":%r,"z":%r}' % (round(x, 6), round(y, 6), round(z, 6))


@dataclass(frozen=True)
class _PathSpec:
    """A line strip of ``/scene/paths``: ``dims`` numbers of signal ``signal`` from ``start``."""

    key: str
    signal: str
    start: int
    dims: int
    rgba: tuple[float, float, float]
    entity: str


_PAPER_PATHS = (_PathSpec("desired", "p_desired", 3, 2, (0.1, 0.8, 0.2), "desired_tip_path"),
                _PathSpec("true", "tip_true", 0, 2, (0.95, 0.2, 0.2), "true_tip_path"))


#: The number keys of the paper's /tf template, in the order :meth:`McapRecorder.write_sample` encodes them.
_TF_KEYS = ("x", "y", "z0", "w0", "z1", "w1", "z2", "w2")


def _tf_template(chain: list[tuple[str, str, tuple[float, float] | None, dict | None]]) -> str:
    """``%``-template of a /tf message. Each link is (parent, child, translation, rotation):
    translation None is the base's (x, y) (template keys ``x``, ``y``), rotation None the
    i-th variable rotation about +Z (keys ``z<i>``, ``w<i>``); fixed values are baked in."""
    parts, var = [], 0
    for parent, child, off, rot in chain:
        head = '{"timestamp":%%(stamp)s,"parent_frame_id":%s,"child_frame_id":%s,' % (
            json.dumps(parent), json.dumps(child))
        if off is None:
            tr = '"translation":{"x":%(x)s,"y":%(y)s,"z":0.0},'
        else:
            tr = '"translation":{"x":%r,"y":%r,"z":0.0},' % (float(off[0]), float(off[1]))
        if rot is None:
            rt = '"rotation":{"x":0.0,"y":0.0,"z":%%(z%d)s,"w":%%(w%d)s}}' % (var, var)
            var += 1
        else:
            rt = '"rotation":' + json.dumps(rot, separators=(",", ":")).replace("%", "%%") + "}"
        parts.append(head + tr + rt)
    return '{"transforms":[' + ",".join(parts) + "]}"


def _paper_scene(params, stamp: dict) -> dict:
    """The paper robot's SceneUpdate: its bodies' boxes, thruster arrows and the tip."""
    colors = {"base": _color(0.85, 0.55, 0.15, 0.9)}
    ents = []
    for b in params.bodies:
        cube = {"pose": {"position": {"x": b.box_center[0], "y": b.box_center[1], "z": 0.0},
                         "orientation": dict(_IDENTITY)},
                "size": {"x": 2 * b.box_half[0], "y": 2 * b.box_half[1], "z": b.width},
                "color": colors.get(b.name, _color(0.6, 0.6, 0.65, 0.9))}
        ents.append(_entity(b.name, b.name, stamp, cubes=[cube]))
    arrows = []
    for th in params.thrusters:
        ang = math.atan2(th.direction[1], th.direction[0])
        arrows.append({"pose": {"position": {"x": th.position[0], "y": th.position[1], "z": 0.0},
                                "orientation": _quat_z(ang)},
                       "shaft_length": 0.12, "shaft_diameter": 0.015, "head_length": 0.04,
                       "head_diameter": 0.035, "color": _color(0.2, 0.6, 1.0)})
    if arrows:
        ents.append(_entity(params.bodies[0].name, "thrusters", stamp, arrows=arrows))
    tip = {"pose": {"position": dict(_ZERO3), "orientation": dict(_IDENTITY)},
           "size": {"x": 0.025, "y": 0.025, "z": 0.025}, "color": _color(1.0, 0.2, 0.2)}
    ents.append(_entity("tip", "tip", stamp, spheres=[tip]))
    return {"deletions": [], "entities": ents}


def _path_value(spec: _PathSpec, row: Mapping[str, Any]) -> list | None:
    """A path strip's point of ``row`` (its ``dims`` numbers), or None where it is not finite."""
    v = row.get(spec.signal)
    if v is None:
        return None
    i = spec.start
    xs = (v[i:i + spec.dims].tolist() if type(v) is np.ndarray and v.dtype == np.float64
          else [float(v[i + j]) for j in range(spec.dims)])
    return xs if all(map(math.isfinite, xs)) else None
