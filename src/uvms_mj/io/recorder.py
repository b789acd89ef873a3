"""Record closed-loop runs to MCAP (Foxglove-ready) and read them back.

A log is written incrementally while the run goes (:class:`McapRecorder`, whose
:meth:`~McapRecorder.write_sample` is the loop's ``sink``) and can be read back into an object
that works wherever a :class:`~uvms_mj.sim.loop.RunResult` does (:func:`read_log`), including a log
cut short by ``kill -9`` (it is then read up to the last flush and marked ``truncated``).

Encoding: every channel is JSON (``message_encoding="json"``) with a JSON schema
(``schema_encoding="jsonschema"``), in zstd-compressed chunks. Floats are written with Python's
shortest round-trip repr, so float64 values come back bit for bit; NaN is written as ``null``
and +-inf as ``+-1e999`` (both read back as such by Python and by Foxglove's JSON parser).

Channel layout (times are simulation time: ``log_time = publish_time = round(t * 1e9)`` ns
from the run's start, so Foxglove shows 1970-01-01 00:00:00 + t; the MCAP message ``sequence``
is the sample index k):

=====================  =======================  ==============================================
topic                  schema                   content and rate
=====================  =======================  ==============================================
``/tf``                foxglove.FrameTransforms ``view -> world -> base -> link1 -> link2 ->
                                                tip``: ``world -> ...`` from ``q_true`` and the
                                                robot parameters; ``view -> world`` is a fixed
                                                +90 deg about x, so that with display frame
                                                ``view`` the world's Y-up plane stands upright
                                                in Foxglove's Z-up 3D view (display frame
                                                ``world`` shows it from above). One message per
                                                sample (60 Hz with the paper's T).
``/scene``             foxglove.SceneUpdate     the robot: frame-locked cubes ``base``,
                                                ``link1``, ``link2`` (box sizes and centres from
                                                the parameters), thruster axes, a tip sphere;
                                                once, at the first sample.
``/scene/paths``       foxglove.SceneUpdate     line strips in ``world``: desired tip path
                                                (from ``p_desired[3:5]``, green) and true tip
                                                path (``tip_true``, red), points every
                                                ``path_resolution`` s; the whole path so far,
                                                re-sent every ``path_period`` s of run time and
                                                at close (so seeking in Foxglove always shows it).
``/joint_states``      foxglove.JointStates     ``joints``: one {``name``, ``position`` (q_true),
                                                ``velocity`` (qd_true)} per joint; one per
                                                sample. (Logs written before Foxglove had this
                                                schema used ``uvms_mj.JointStates``, with
                                                ``name``/``position``/``velocity`` arrays;
                                                :func:`read_log` never reads this channel, so
                                                both read back alike.)
``/state/true``        uvms_mj.TrueState        ``t`` and the true plant state ``q_true``,
                                                ``qd_true``, ``tip_true``; one per sample.
``/control``           uvms_mj.ControlSample    ``t`` and every other per-sample signal (the
                                                controller's signals, ``q_measured``, thruster
                                                and torque commands...) as top-level fields;
                                                one per sample.
=====================  =======================  ==============================================

Robot logs (any floating robot: ``McapRecorder(path, None, metadata, model=plant.model)``
with a free vehicle's :class:`~uvms_mj.plant.plant.Plant` model; World z up, so no ``view`` frame) have the
same ``/state/true`` and ``/control`` channels and, by the model's own names
(:class:`~uvms_mj.plant.robot.Layout`):

=====================  =======================  ==============================================
topic                  schema                   content and rate
=====================  =======================  ==============================================
``/tf``                foxglove.FrameTransforms ``world -> <body>`` for every body (parent
                                                ``world``, pose of the body frame in the world
                                                from ``q_true`` through ``mj_kinematics``);
                                                one message per sample.
``/scene``             foxglove.SceneUpdate     per body a frame-locked entity (id and frame =
                                                the body's name) with its geoms of groups 0-2
                                                (box -> cube, sphere/ellipsoid -> sphere,
                                                cylinder/capsule -> cylinder, mesh -> its
                                                bounding box; planes left out; colour from
                                                ``geom_rgba``), ``thrusters`` (an arrow along
                                                each thruster site's x axis: positive thrust),
                                                ``tip`` (a sphere at the tip site); once, at
                                                the first sample.
``/scene/paths``       foxglove.SceneUpdate     3-D line strips in ``world``: desired tip path
                                                (``tip_desired``, green, when logged), tip path
                                                (``tip_true``, red, when the robot has a tip)
                                                and base path (``q_true[0:3]``, blue); as for
                                                the paper's paths.
``/joint_states``      foxglove.JointStates     the arm joints (Layout.joint_names): position
                                                [rad] from ``q_true``, velocity [rad/s] from
                                                ``qd_true``; one per sample (none for a robot
                                                without joints).
``/thrusters``         uvms_mj.Thrusters        ``t`` and, per thruster actuator name,
                                                ``{"command", "force"}`` [N] (from
                                                ``thrust_command`` / ``thrust_force``); plot
                                                e.g. ``/thrusters.bluerov2_t1.force``. One per
                                                sample.
=====================  =======================  ==============================================

Per-sample signals are plotted in Foxglove's Plot panel with message paths such as
``/control.e_p[3]``, ``/control.det_B`` or ``/state/true.q_true[2]``. Booleans are written as
0/1 integers (so that they plot) and arrays of two or more dimensions are flattened row-major
(Foxglove's JSON-schema parser rejects nested arrays); each sample channel's metadata
(``uvms_mj.signals``) keeps every signal's dtype, shape and position in the row, which
:func:`read_log` uses to give back exactly the loop's arrays (same names, order, shapes and
dtypes). Signals are discovered from
the first row; a name that first appears later is dropped with a warning, and non-numeric values
are not recorded.

Metadata records: ``uvms_mj`` (written at creation) holds the caller's metadata dict plus
``versions`` (uvms_mj, mujoco, numpy, mcap, python), ``git_commit`` / ``git_dirty`` (from git
when the package runs from a checkout, else written into the wheel when it was built, else
``git_commit`` = "unknown"), ``robot_params``, ``created_utc`` and ``log_format``;
``uvms_mj.status`` (written at close) holds ``status`` ("ok", "diverged", "interrupted",
"error"...), ``reason`` and any run metadata given to :meth:`McapRecorder.close`. Each value
is stored as JSON text (MCAP metadata is string -> string).

Durability: data reaches the file at least every ``flush_interval`` seconds of wall-clock time
while samples arrive (checked at each sample, and always after the first one: the samples since
the last flush are encoded and written, the chunk in progress is finished and the file object
flushed), so a process killed with ``kill -9`` leaves a log readable (by :func:`read_log`, not
by MCAP's indexed readers) up to the last flush. Exceptions, KeyboardInterrupt and (inside
:func:`handle_sigterm`) SIGTERM close the log cleanly with a status record.

Speed: the samples are encoded in batches at each flush (per batch one orjson call for the
sample channels and one for the paper's /tf and /joint_states numbers, whose templates are then
filled for the whole batch in one operation each; the same bytes as one sample at a time, which
irregular rows -- a non-finite number, a missing or late signal -- still take), added to the
chunk in one call per batch, and compressed by one reused zstd compressor
at level 1 (:class:`uvms_mj.io.mcap_writer.LeanWriter`). A row is kept (a shallow copy) until its
batch is written: its arrays must not be changed in place after :meth:`McapRecorder.write_sample`.

Typical use (e.g. in the CLI)::

    with handle_sigterm(), McapRecorder(path, plant.params, metadata) as rec:
        result = run_closed_loop(plant, ctrl, duration, sink=rec.write_sample)
        rec.close(result.status, result.reason, meta=result.meta)
    log = read_log(path)      # log.t, log.signals, log.status, log.meta, log.truncated
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import io
import json
import math
import operator
import os
import platform
import re
import signal
import struct
import subprocess
import sys
import threading
import time
import warnings
from contextlib import contextmanager
from dataclasses import dataclass
from importlib import metadata as _importlib_metadata
from itertools import repeat
from pathlib import Path
from typing import TYPE_CHECKING, Any, Iterator, Mapping

import numpy as np
from mcap.exceptions import McapError
from mcap.records import Channel, Chunk, Message, Metadata, Schema
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap.writer import CompressionType

from uvms_mj.sim.loop import RunResult
from uvms_mj.io.mcap_writer import LeanWriter

if TYPE_CHECKING:
    import mujoco
from uvms_mj.plant.params import ARM_JOINTS, BASE_JOINTS, BodyParams, RobotParams, ThrusterParams

__all__ = [
    "LOG_FORMAT",
    "LogData",
    "McapRecorder",
    "Terminated",
    "format_info",
    "handle_sigterm",
    "iter_messages",
    "log_info",
    "provenance",
    "read_log",
]

#: Version of the layout described in the module docstring (stored in the metadata).
LOG_FORMAT = 1
METADATA_NAME = "uvms_mj"
STATUS_NAME = "uvms_mj.status"
#: Signals that go to ``/state/true``; every other signal goes to ``/control``.
STATE_SIGNALS = ("q_true", "qd_true", "tip_true")
TOPIC_CONTROL = "/control"
TOPIC_STATE = "/state/true"
TOPIC_TF = "/tf"
TOPIC_SCENE = "/scene"
TOPIC_PATHS = "/scene/paths"
TOPIC_JOINTS = "/joint_states"
#: Per-sample channels whose messages make up the signals (a sample is complete when all the
#: log's sample channels hold its message).
SAMPLE_TOPICS = (TOPIC_CONTROL, TOPIC_STATE)
#: Metadata keys the recorder adds itself (a caller's metadata must not use them).
RESERVED_KEYS = ("versions", "git_commit", "git_dirty", "robot_params", "created_utc", "log_format")
JOINT_NAMES = BASE_JOINTS + ARM_JOINTS
_MAGIC = b"\x89MCAP0\r\n"
_OP_FOOTER = 0x02

# --------------------------------------------------------------------------- JSON schemas
# The foxglove.* schemas follow the published JSON schemas (github.com/foxglove/foxglove-sdk,
# schemas/jsonschema), without descriptions and without the optional message_id/lineage fields.


def _num() -> dict:
    return {"type": "number"}


def _obj(title: str | None, props: dict, required: bool = True, description: str | None = None) -> dict:
    out: dict = {}
    if title:
        out["title"] = title
    if description:
        out["description"] = description
    out["type"] = "object"
    out["properties"] = props
    if required:
        out["required"] = list(props)
    return out


def _arr(items: dict, description: str | None = None) -> dict:
    out = {"type": "array", "items": items}
    if description:
        out["description"] = description
    return out


def _time_schema() -> dict:
    return {"type": "object", "title": "time", "properties": {
        "sec": {"type": "integer", "minimum": 0},
        "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999}}}


def _duration_schema() -> dict:
    return {"type": "object", "title": "duration", "properties": {
        "sec": {"type": "integer"},
        "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999}}}


def _vec3() -> dict:
    return _obj("foxglove.Vector3", {"x": _num(), "y": _num(), "z": _num()})


def _point3() -> dict:
    return _obj("foxglove.Point3", {"x": _num(), "y": _num(), "z": _num()})


def _quat() -> dict:
    return _obj("foxglove.Quaternion", {"x": _num(), "y": _num(), "z": _num(), "w": _num()})


def _color_schema() -> dict:
    return _obj("foxglove.Color", {"r": _num(), "g": _num(), "b": _num(), "a": _num()})


def _pose() -> dict:
    return _obj("foxglove.Pose", {"position": _vec3(), "orientation": _quat()})


def _enum(title: str, names: tuple[str, ...]) -> dict:
    return {"title": title, "oneOf": [{"title": n, "const": i} for i, n in enumerate(names)]}


def _frame_transforms_schema() -> dict:
    tf = _obj("foxglove.FrameTransform", {
        "timestamp": _time_schema(), "parent_frame_id": {"type": "string"},
        "child_frame_id": {"type": "string"}, "translation": _vec3(), "rotation": _quat()})
    return _obj("foxglove.FrameTransforms", {"transforms": _arr(tf)},
                description="An array of FrameTransform messages")


def _scene_update_schema() -> dict:
    idx = _arr({"type": "integer", "minimum": 0})
    prims = {
        "arrows": _obj("foxglove.ArrowPrimitive", {
            "pose": _pose(), "shaft_length": _num(), "shaft_diameter": _num(), "head_length": _num(),
            "head_diameter": _num(), "color": _color_schema()}),
        "cubes": _obj("foxglove.CubePrimitive", {"pose": _pose(), "size": _vec3(), "color": _color_schema()}),
        "spheres": _obj("foxglove.SpherePrimitive", {"pose": _pose(), "size": _vec3(), "color": _color_schema()}),
        "cylinders": _obj("foxglove.CylinderPrimitive", {
            "pose": _pose(), "size": _vec3(), "bottom_scale": _num(), "top_scale": _num(), "color": _color_schema()}),
        "lines": _obj("foxglove.LinePrimitive", {
            "type": _enum("foxglove.LineType", ("LINE_STRIP", "LINE_LOOP", "LINE_LIST")),
            "pose": _pose(), "thickness": _num(), "scale_invariant": {"type": "boolean"},
            "points": _arr(_point3()), "color": _color_schema(), "colors": _arr(_color_schema()), "indices": idx}),
        "triangles": _obj("foxglove.TriangleListPrimitive", {
            "pose": _pose(), "points": _arr(_point3()), "color": _color_schema(), "colors": _arr(_color_schema()),
            "indices": idx}),
        "texts": _obj("foxglove.TextPrimitive", {
            "pose": _pose(), "billboard": {"type": "boolean"}, "font_size": _num(),
            "scale_invariant": {"type": "boolean"}, "color": _color_schema(), "text": {"type": "string"}}),
        "models": _obj("foxglove.ModelPrimitive", {
            "pose": _pose(), "scale": _vec3(), "color": _color_schema(), "override_color": {"type": "boolean"},
            "url": {"type": "string"}, "media_type": {"type": "string"},
            "data": {"type": "string", "contentEncoding": "base64"}}),
    }
    entity = _obj("foxglove.SceneEntity", {
        "timestamp": _time_schema(), "frame_id": {"type": "string"}, "id": {"type": "string"},
        "lifetime": _duration_schema(), "frame_locked": {"type": "boolean"},
        "metadata": _arr(_obj("foxglove.KeyValuePair", {"key": {"type": "string"}, "value": {"type": "string"}})),
        **{k: _arr(v) for k, v in prims.items()}})
    deletion = _obj("foxglove.SceneEntityDeletion", {
        "timestamp": _time_schema(), "type": _enum("foxglove.SceneEntityDeletionType", ("MATCHING_ID", "ALL")),
        "id": {"type": "string"}})
    return _obj("foxglove.SceneUpdate", {"deletions": _arr(deletion), "entities": _arr(entity)},
                description="An update to the entities displayed in a 3D scene")


def _joint_states_schema() -> dict:
    joint = _obj("foxglove.JointState", {
        "name": {"type": "string"}, "position": _num(), "velocity": _num(), "acceleration": _num(),
        "effort": _num()})
    joint["required"] = ["name"]
    return _obj("foxglove.JointStates", {"timestamp": _time_schema(), "joints": _arr(joint)},
                description="The state of a set of joints at a given time.")


#: Logs written before foxglove.JointStates existed used this schema name on /joint_states
#: ({"timestamp", "name": [...], "position": [...], "velocity": [...]}); they read back the same.
LEGACY_JOINT_STATES = "uvms_mj.JointStates"


_JSON_TYPE = {"b": "integer", "i": "integer", "u": "integer", "f": "number"}


def _sample_schema(title: str, description: str, layout: list[dict]) -> dict:
    props: dict = {"timestamp": _time_schema(),
                   "t": {"type": "number", "description": "sample time [s] (exact float)"}}
    for sig in layout:
        item: dict = {"type": _JSON_TYPE[np.dtype(sig["dtype"]).kind]}
        notes = ["boolean as 0/1"] if sig["dtype"] == "bool" else []
        shape = sig["shape"]
        if len(shape) > 1:
            notes.append(f"shape {tuple(shape)} flattened row-major")
        if notes:
            item["description"] = "; ".join(notes)
        if shape:
            n = int(np.prod(shape))
            item = {"type": "array", "items": item, "minItems": n, "maxItems": n}
        props[sig["name"]] = item
    return _obj(title, props, description=description + " (null = NaN, +-1e999 = +-inf)")


#: Published-schema equivalents, by schema name (exposed for tests and tools).
SCHEMAS: dict[str, dict] = {
    "foxglove.FrameTransforms": _frame_transforms_schema(),
    "foxglove.SceneUpdate": _scene_update_schema(),
    "foxglove.JointStates": _joint_states_schema(),
}

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


# --------------------------------------------------------------------------- provenance


def _version(dist: str, module: str | None = None) -> str | None:
    try:
        return _importlib_metadata.version(dist)
    except Exception:
        pass
    if module:
        try:
            return str(__import__(module).__version__)
        except Exception:
            pass
    return None


def _git_info() -> dict:
    """Commit (and whether the tree is dirty) of the checkout this package runs from, else the
    one written into the wheel at build time (``uvms_mj/_build_info.py``, see ``hatch_build.py``),
    else ``{"git_commit": "unknown"}`` (never raises)."""
    info = _git_checkout_info()
    if info:
        return info
    try:
        from uvms_mj import _build_info  # type: ignore[attr-defined]

        commit = str(getattr(_build_info, "GIT_COMMIT", "") or "unknown")
        dirty = getattr(_build_info, "GIT_DIRTY", None)
        return {"git_commit": commit, **({"git_dirty": dirty} if isinstance(dirty, bool) else {})}
    except Exception:
        return {"git_commit": "unknown"}


def _git_checkout_info() -> dict:
    """Commit and dirtiness of the git checkout this package runs from; {} when it does not run
    from a git checkout of its own (an editable install), or git is missing (never raises)."""
    pkg = Path(__file__).resolve().parents[1]  # the uvms_mj package folder
    try:
        out = subprocess.run(["git", "-C", str(pkg), "rev-parse", "--show-toplevel", "HEAD"],
                             capture_output=True, text=True, timeout=5)
        if out.returncode != 0:
            return {}
        top, commit = out.stdout.split()
        top = Path(top).resolve()
        # Only the package's own repository (an editable install), not a repository that
        # happens to contain a site-packages directory.
        if pkg.parent.parent != top or not (top / "pyproject.toml").is_file():
            return {}
        info: dict = {"git_commit": commit}
        st = subprocess.run(["git", "-C", str(top), "status", "--porcelain", "--untracked-files=no"],
                            capture_output=True, text=True, timeout=5)
        if st.returncode == 0:
            info["git_dirty"] = bool(st.stdout.strip())
        return info
    except Exception:
        return {}


def provenance() -> dict:
    """Package versions and, when available, the git commit of the uvms_mj checkout."""
    from uvms_mj import __version__

    versions = {
        "uvms_mj": _version("uvms-mj") or __version__,
        "mujoco": _version("mujoco", "mujoco"),
        "numpy": np.__version__,
        "mcap": _version("mcap"),
        "python": platform.python_version(),
    }
    return {"versions": versions, **_git_info()}


# --------------------------------------------------------------------------- signals

_critical_depth = 0
_pending: BaseException | None = None


class Terminated(KeyboardInterrupt):
    """Raised (inside :func:`handle_sigterm`) when the process gets SIGTERM."""


def _deliver_pending() -> None:
    global _pending
    if _critical_depth == 0 and _pending is not None:
        exc, _pending = _pending, None
        raise exc


class _CriticalSection:
    """A section that the handlers of :func:`handle_sigterm` do not interrupt (the signal's
    exception is raised when the section ends). Reentrant; one shared instance (a class rather
    than a generator: it is entered at every sample)."""

    __slots__ = ()

    def __enter__(self) -> None:
        global _critical_depth
        _critical_depth += 1

    def __exit__(self, exc_type, exc, tb) -> None:
        global _critical_depth
        _critical_depth -= 1
        _deliver_pending()


_CRITICAL = _CriticalSection()


def _critical() -> _CriticalSection:
    """The critical section (``with _critical(): ...``), see :class:`_CriticalSection`."""
    return _CRITICAL


@contextmanager
def handle_sigterm(sigint: bool = True) -> Iterator[None]:
    """Turn SIGTERM into :class:`Terminated` (a KeyboardInterrupt) while the block runs, so that
    ``with`` blocks (an :class:`McapRecorder`) close cleanly; the old handlers come back after.

    With ``sigint`` (default) SIGINT is handled the same way (raising KeyboardInterrupt). Either
    signal arriving while a recorder is writing a sample or closing is held back until that
    write is over, so a log is never left with half a record. Outside the main thread (where
    Python cannot set handlers) this does nothing.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def on_signal(signum, frame):  # noqa: ARG001
        global _pending
        if signum == signal.SIGTERM:
            exc: BaseException = Terminated("terminated by SIGTERM")
        else:
            exc = KeyboardInterrupt("interrupted by SIGINT")
        if _critical_depth:
            if _pending is None:
                _pending = exc
            return
        raise exc

    old = {signal.SIGTERM: signal.signal(signal.SIGTERM, on_signal)}
    if sigint:
        old[signal.SIGINT] = signal.signal(signal.SIGINT, on_signal)
    try:
        yield
    finally:
        global _pending
        for sig, handler in old.items():
            # None: a handler not set from Python, which cannot be put back; use the default.
            signal.signal(sig, signal.SIG_DFL if handler is None else handler)
        held, _pending = _pending, None
        if held is not None and sys.exc_info()[0] is None:
            raise held  # a signal held back by the last write: deliver it now


# --------------------------------------------------------------------------- recorder


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


# --------------------------------------------------------------------------- any robot (model given)

TOPIC_THRUSTERS = "/thrusters"
#: Geom types drawn on ``/scene`` for robot logs (the others -- plane, height field, SDF -- are
#: left out); meshes are drawn as their bounding box.
_GEOM_PRIMITIVE = {"box": "cubes", "sphere": "spheres", "ellipsoid": "spheres", "cylinder": "cylinders",
                   "capsule": "cylinders", "mesh": "cubes"}
_DEFAULT_RGBA = (0.5, 0.5, 0.5, 1.0)  # MuJoCo's default geom colour: the material's then wins


def _tip_site_of(metadata: Mapping[str, Any]) -> str | None:
    robot = metadata.get("robot")
    layout = robot.get("layout") if isinstance(robot, Mapping) else None
    tip = layout.get("tip_site") if isinstance(layout, Mapping) else None
    return str(tip) if tip else None


def _fox_quat(q_wxyz) -> dict:
    w, x, y, z = (float(v) for v in q_wxyz)
    return {"x": x, "y": y, "z": z, "w": w}


def _fox_pose(pos, q_wxyz) -> dict:
    return {"position": {"x": float(pos[0]), "y": float(pos[1]), "z": float(pos[2])},
            "orientation": _fox_quat(q_wxyz)}


def _thrusters_schema(names: tuple[str, ...], fields: tuple[str, ...]) -> dict:
    what = {"command": "commanded thrust [N]", "force": "actual thrust [N] (lagged, saturated)"}
    props: dict = {"timestamp": _time_schema(), "t": {"type": "number", "description": "sample time [s]"}}
    for n in names:
        props[n] = _obj(None, {f: {"type": "number", "description": what[f]} for f in fields})
    return _obj("uvms_mj.Thrusters", props, description="Thrust of each thruster [N], by actuator name "
                "(null = NaN)")


def geom_primitive(model, g: int) -> tuple[str, dict] | None:
    """The Foxglove primitive (list name, primitive) of geom ``g`` in its body's frame, or None
    for geoms that are not drawn (plane, height field, SDF, group >= 3, fully transparent).

    Sizes [m]: box -> cube of the full edges; sphere / ellipsoid -> sphere of the diameters;
    cylinder -> cylinder (Foxglove's axis is z, as MuJoCo's); capsule -> cylinder of the total
    length (the caps approximated); mesh -> cube of its bounding box.
    """
    import mujoco

    kind = mujoco.mjtGeom(int(model.geom_type[g])).name.removeprefix("mjGEOM_").lower()
    if kind not in _GEOM_PRIMITIVE or int(model.geom_group[g]) >= 3:
        return None
    rgba = tuple(float(v) for v in model.geom_rgba[g])
    mat = int(model.geom_matid[g])
    if mat >= 0 and np.allclose(rgba, _DEFAULT_RGBA):
        rgba = tuple(float(v) for v in model.mat_rgba[mat])
    if rgba[3] <= 0:
        return None
    size = np.asarray(model.geom_size[g], dtype=float)
    pos, quat = np.asarray(model.geom_pos[g], dtype=float), np.asarray(model.geom_quat[g], dtype=float)
    if kind == "box":
        dims = 2 * size
    elif kind == "sphere":
        dims = np.full(3, 2 * size[0])
    elif kind == "ellipsoid":
        dims = 2 * size
    elif kind == "cylinder":
        dims = np.array([2 * size[0], 2 * size[0], 2 * size[1]])
    elif kind == "capsule":
        dims = np.array([2 * size[0], 2 * size[0], 2 * (size[1] + size[0])])
    else:  # mesh: its bounding box (centre and half sizes in the geom frame)
        aabb = np.asarray(model.geom_aabb[g], dtype=float)
        rot = np.empty(9)
        mujoco.mju_quat2Mat(rot, quat)
        pos = pos + rot.reshape(3, 3) @ aabb[:3]
        dims = 2 * aabb[3:]
    prim: dict = {"pose": _fox_pose(pos, quat), "size": {"x": float(dims[0]), "y": float(dims[1]),
                                                          "z": float(dims[2])},
                  "color": _color(*rgba)}
    if _GEOM_PRIMITIVE[kind] == "cylinders":
        prim["bottom_scale"] = 1.0
        prim["top_scale"] = 1.0
    return _GEOM_PRIMITIVE[kind], prim


class _RobotChannels:
    """The Foxglove channels of any robot's log, by the model's own names: ``/tf`` (world ->
    every body, from ``q_true`` through ``mj_kinematics``), ``/scene`` (geoms, thruster arrows,
    tip), ``/joint_states`` (the arm joints), ``/thrusters`` (command and force per thruster)
    and the specs of the ``/scene/paths`` line strips."""

    def __init__(self, model, tip_site: str | None) -> None:
        import mujoco

        from uvms_mj.plant.layout import Layout

        if not isinstance(model, mujoco.MjModel):
            raise TypeError(f"McapRecorder: model must be a mujoco.MjModel, not {type(model).__name__}")
        self.model = model
        self.layout = Layout.of(model, tip_site)
        self.data = mujoco.MjData(model)
        self._pose_buf = np.empty((model.nbody - 1, 7))
        self.bodies = list(range(1, model.nbody))
        self.body_names = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, b) or f"body{b}" for b in self.bodies]
        self.body_name = {b: n for b, n in zip(self.bodies, self.body_names)}
        self.body_name[0] = "world"
        self.has_tf = self.has_joints = False
        self.thr_fields: tuple[str, ...] = ()

    # ---------------------------------------------------------------- setup

    def start(self, channel, writer, ns: int, stamp: dict, row: Mapping[str, Any]) -> None:
        m, lay = self.model, self.layout
        self.has_tf = np.shape(row.get("q_true", ())) == (m.nq,)
        if "q_true" in row and not self.has_tf:
            warnings.warn(f"recorder: q_true has shape {np.shape(row['q_true'])}, the model {m.nq} positions: "
                          "no /tf or /joint_states", stacklevel=4)
        if self.has_tf:
            self.tf_id = channel(TOPIC_TF, "foxglove.FrameTransforms", SCHEMAS["foxglove.FrameTransforms"])
            self._tf_heads = ['{"timestamp":%%s,"parent_frame_id":"world","child_frame_id":%s,'
                              % json.dumps(n).replace("%", "%%") for n in self.body_names]
            # One template for the whole message: "\0" stands for the stamp, %s for the numbers.
            self._tf_tmpl = '{"transforms":[' + ",".join(
                (h % "\0") + '"translation":{"x":%s,"y":%s,"z":%s},"rotation":{"x":%s,"y":%s,"z":%s,"w":%s}}'
                for h in self._tf_heads) + "]}"
        self.has_joints = self.has_tf and len(lay.joint_names) > 0
        if self.has_joints:
            self.js_id = channel(TOPIC_JOINTS, "foxglove.JointStates", SCHEMAS["foxglove.JointStates"])
            self._js_names = [json.dumps(n) for n in lay.joint_names]
            self._js_vel = np.shape(row.get("qd_true", ())) == (m.nv,)
        n_thr = len(lay.thruster_names)
        self.thr_fields = tuple(f for f, sig in (("command", "thrust_command"), ("force", "thrust_force"))
                                if n_thr and np.shape(row.get(sig, ())) == (n_thr,))
        self._thr_sig = {"command": "thrust_command", "force": "thrust_force"}
        if self.thr_fields:
            self.thr_id = channel(TOPIC_THRUSTERS, "uvms_mj.Thrusters",
                                  _thrusters_schema(lay.thruster_names, self.thr_fields))
            self._thr_names = [json.dumps(n) for n in lay.thruster_names]
            one = "{" + ",".join('"%s":%%s' % f for f in self.thr_fields) + "}"
            self._thr_tmpl = ",".join(n.replace("%", "%%") + ":" + one for n in self._thr_names) + "}"
        scene_id = channel(TOPIC_SCENE, "foxglove.SceneUpdate", SCHEMAS["foxglove.SceneUpdate"])
        writer.add_message(scene_id, ns, _dumps(self.scene(stamp)), ns, 0)

    def path_specs(self, row: Mapping[str, Any]) -> tuple[_PathSpec, ...]:
        specs = []
        if np.shape(row.get("tip_desired", ())) == (3,):
            specs.append(_PathSpec("tip_desired", "tip_desired", 0, 3, (0.1, 0.8, 0.2), "desired_tip_path"))
        if np.shape(row.get("tip_true", ())) == (3,) and self.layout.tip_site >= 0:
            specs.append(_PathSpec("tip_true", "tip_true", 0, 3, (0.95, 0.2, 0.2), "true_tip_path"))
        if self.has_tf:
            specs.append(_PathSpec("base", "q_true", self.layout.base_qadr, 3, (0.2, 0.5, 1.0), "base_path"))
        return tuple(specs)

    def scene(self, stamp: dict) -> dict:
        """The robot's SceneUpdate: per body a frame-locked entity (id = frame = the body's name)
        with its drawn geoms; the thruster arrows (along each thruster site's x axis, the
        direction of positive thrust); a sphere at the tip site."""
        m, lay = self.model, self.layout
        per_body: dict[int, dict[str, list]] = {}
        for g in range(m.ngeom):
            prim = geom_primitive(m, g)
            if prim is not None:
                per_body.setdefault(int(m.geom_bodyid[g]), {}).setdefault(prim[0], []).append(prim[1])
        ents = [_entity(self.body_name[b], self.body_name[b], stamp, **prims) for b, prims in sorted(per_body.items())]
        arrows: dict[int, list] = {}
        for a in lay.thruster_ids:
            s = int(m.actuator_trnid[a][0])
            arrows.setdefault(int(m.site_bodyid[s]), []).append(
                {"pose": _fox_pose(m.site_pos[s], m.site_quat[s]), "shaft_length": 0.12, "shaft_diameter": 0.015,
                 "head_length": 0.04, "head_diameter": 0.035, "color": _color(0.2, 0.6, 1.0)})
        for b, arr in sorted(arrows.items()):
            eid = "thrusters" if len(arrows) == 1 else f"thrusters/{self.body_name[b]}"
            ents.append(_entity(self.body_name[b], eid, stamp, arrows=arr))
        if lay.tip_site >= 0:
            s = lay.tip_site
            tip = {"pose": _fox_pose(m.site_pos[s], (1.0, 0.0, 0.0, 0.0)), "size": {"x": 0.025, "y": 0.025, "z": 0.025},
                   "color": _color(1.0, 0.2, 0.2)}
            ents.append(_entity(self.body_name[int(m.site_bodyid[s])], "tip", stamp, spheres=[tip]))
        return {"deletions": [], "entities": ents}

    # ---------------------------------------------------------------- per sample

    def write(self, out: list, stamp: str, head: str, row: Mapping[str, Any]) -> None:
        """Append this sample's /tf, /joint_states and /thrusters messages (channel, data) to ``out``."""
        import mujoco

        lay = self.layout
        if self.has_tf and "q_true" in row:
            q = np.asarray(row["q_true"], dtype=float)
            if math.isfinite(float(q.sum())):
                d = self.data
                d.qpos[:] = q
                mujoco.mj_kinematics(self.model, d)
                pose = self._pose_buf  # x y z, qx qy qz qw per body
                pose[:, :3] = d.xpos[1:]
                pose[:, 3:6] = d.xquat[1:, 1:]
                pose[:, 6] = d.xquat[1:, 0]
                nums = _enc(pose.ravel().tolist())[1:-1].split(",")
                msg = self._tf_tmpl.replace("\0", stamp) % tuple(nums)
                out.append((self.tf_id, msg.encode()))
            if self.has_joints:
                pos = _enc(q[lay.joint_qadr].tolist())[1:-1].split(",")
                vel = None
                if self._js_vel and "qd_true" in row:
                    vel = _enc(np.asarray(row["qd_true"], dtype=float)[lay.joint_dadr].tolist())[1:-1].split(",")
                joints = ",".join('{"name":%s,"position":%s%s}' % (n, pos[i], "" if vel is None else
                                                                  ',"velocity":' + vel[i])
                                  for i, n in enumerate(self._js_names))
                out.append((self.js_id, ('{"timestamp":%s,"joints":[%s]}' % (stamp, joints)).encode()))
        if self.thr_fields:
            if all(self._thr_sig[f] in row for f in self.thr_fields):
                cols = [_enc(np.asarray(row[self._thr_sig[f]], dtype=float).tolist())[1:-1].split(",")
                        for f in self.thr_fields]
                args = tuple(x for vals in zip(*cols) for x in vals)  # per thruster: its fields in order
                out.append((self.thr_id, (head + "," + self._thr_tmpl % args).encode()))
            else:
                cols = [_enc(np.asarray(row[self._thr_sig[f]], dtype=float).tolist())[1:-1].split(",")
                        if self._thr_sig[f] in row else None for f in self.thr_fields]
                items = []
                for i, n in enumerate(self._thr_names):
                    vals = ",".join('"%s":%s' % (f, c[i]) for f, c in zip(self.thr_fields, cols) if c is not None)
                    items.append('%s:{%s}' % (n, vals))
                out.append((self.thr_id, (head + "," + ",".join(items) + "}").encode()))


class OutputPathError(ValueError):
    """An output path that cannot or must not be written (the message says why)."""


class LogInUseError(OSError):
    """Another process is writing the same log (it holds the file's lock)."""


_NO_WRITE_ROOTS = ("/proc", "/sys", "/dev")


def check_output_path(path: str | os.PathLike, protect: tuple = (), kind: str = "log",
                      magic: bytes | None = b"\x89MCAP") -> Path:
    """Refuse an output path that would fail or destroy something, before anything is written.

    Refused: a path under /proc, /sys or /dev (except /dev/shm); a symbolic link; an existing directory, device
    or other non-regular file; an existing non-empty file that does not start with ``magic``
    (not one of our outputs: never overwritten); a file in ``protect`` (e.g. the scenario
    file); a parent that is a file or is not writable; a name longer than the file system
    allows. Raises :class:`OutputPathError`; returns the path.
    """
    p = Path(path)
    absolute = Path(os.path.abspath(p))
    for root in _NO_WRITE_ROOTS:
        if Path("/dev/shm") in absolute.parents:  # a tmpfs: fine
            break
        if absolute == Path(root) or Path(root) in absolute.parents:
            raise OutputPathError(f"{p}: {root} is not a place to write a {kind} to")
    for part in absolute.parts:
        if len(os.fsencode(part)) > 255:
            raise OutputPathError(f"{p}: a file name is {len(os.fsencode(part))} bytes long; "
                                  "the file system allows 255")
    if p.is_symlink():
        raise OutputPathError(f"{p}: is a symbolic link; give the path of a regular file (the link's target "
                              "is not overwritten)")
    if p.exists():
        if not p.is_file():
            raise OutputPathError(f"{p}: exists and is not a regular file")
        for other in protect:
            try:
                if other is not None and os.path.samefile(p, other):
                    raise OutputPathError(f"{p}: is the input file {other}; choose another output path")
            except OSError:
                pass
        if magic is not None:
            try:
                with open(p, "rb") as f:
                    head = f.read(len(magic))
            except OSError as exc:
                raise OutputPathError(f"{p}: cannot be read back ({exc.strerror or exc})") from None
            if head and head != magic[: len(head)]:
                raise OutputPathError(f"{p}: exists and is not a {kind} written by uvms-mj; not overwriting it "
                                      "(delete it or choose another path)")
        if not os.access(p, os.W_OK):
            raise OutputPathError(f"{p}: is not writable")
        return p
    _check_creatable(p, absolute.parent)
    return p


def _check_creatable(p: Path, start: Path) -> None:
    """``start`` (a folder to write into) exists, or can be created: its nearest existing
    ancestor is a writable folder (no dangling symbolic link on the way)."""
    parent = start
    while not parent.exists():
        if parent.is_symlink():
            raise OutputPathError(f"{p}: {parent} is a dangling symbolic link")
        parent = parent.parent
    if not parent.is_dir():
        raise OutputPathError(f"{p}: {parent} is a file, not a folder")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputPathError(f"{p}: the folder {parent} is not writable")


def check_output_dir(path: str | os.PathLike) -> Path:
    """Refuse an output folder under /proc, /sys or /dev (except /dev/shm), one that exists
    as something else, or one whose nearest existing parent is a file or not writable.
    Raises :class:`OutputPathError`; returns the path."""
    p = Path(path)
    absolute = Path(os.path.abspath(p))
    if Path("/dev/shm") not in absolute.parents:
        for root in _NO_WRITE_ROOTS:
            if absolute == Path(root) or Path(root) in absolute.parents:
                raise OutputPathError(f"{p}: {root} is not a place to write results to")
    if p.exists() and not p.is_dir():
        raise OutputPathError(f"{p}: exists and is not a folder")
    _check_creatable(p, absolute)
    return p


def _open_locked(path: Path):
    """Open ``path`` for writing under an exclusive lock (never following a symbolic link),
    then truncate it: a second writer of the same log fails with :class:`LogInUseError`
    instead of interleaving its records with the first one's."""
    flags = os.O_WRONLY | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
    fd = os.open(path, flags, 0o666)
    try:
        try:
            import fcntl
        except ImportError:  # not POSIX: no lock
            fcntl = None
        if fcntl is not None:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                raise LogInUseError(f"{path}: another process is writing this log now") from None
            except OSError:  # a file system without locks (some network mounts): write unlocked
                pass
        os.ftruncate(fd, 0)
        return os.fdopen(fd, "wb")
    except BaseException:
        os.close(fd)
        raise


class McapRecorder:
    """Writes a run to an MCAP file as it happens (see the module docstring for the layout).

    Args:
        path: output file (parent directories are created; an existing file is replaced). It is
            written under an exclusive lock (flock): a second recorder on the same path raises
            :class:`LogInUseError` instead of corrupting it; a symbolic link is not followed.
        params: the paper plant's robot parameters (geometry of the frames and the scene);
            None for any other robot (give ``model``).
        metadata: JSON-able run description (resolved scenario, seed, ...), stored in the
            ``uvms_mj`` metadata record; keys in :data:`RESERVED_KEYS` are not allowed.
        flush_interval: the longest wall-clock time [s] between flushes to the file (0: flush
            after every sample).
        path_period: run time [s] between re-sends of the tip paths on ``/scene/paths``.
        path_resolution: run time [s] between stored path points.
        chunk_size: MCAP chunk size [bytes] (a chunk is also finished at every flush).
        compression: "zstd", "lz4" or "none".
        model: any floating robot's compiled model (a :class:`~uvms_mj.plant.plant.Plant`'s
            ``model``; ``params`` must then be None): ``/tf``, ``/scene``, ``/joint_states``,
            ``/thrusters`` and ``/scene/paths`` come from it by name (module docstring, robot
            logs). The tip site is ``metadata["robot"]["layout"]["tip_site"]`` when given, else
            :meth:`~uvms_mj.plant.robot.Layout.of`'s default.

    Use it as a context manager: leaving the block closes the log, with status "ok", or
    "interrupted" on KeyboardInterrupt (and SIGTERM inside :func:`handle_sigterm`), or "error"
    on another exception, unless :meth:`close` was called first with the run's status.
    """

    def __init__(
        self,
        path: str | os.PathLike,
        params: RobotParams,
        metadata: Mapping[str, Any] | None = None,
        flush_interval: float = 1.0,
        *,
        path_period: float = 1.0,
        path_resolution: float = 0.1,
        chunk_size: int = 512 * 1024,
        compression: str = "zstd",
        model: "mujoco.MjModel | None" = None,
    ) -> None:
        if not (flush_interval >= 0 and math.isfinite(flush_interval)):
            raise ValueError(f"flush_interval = {flush_interval!r} s must be finite and >= 0")
        metadata = dict(metadata or {})
        self._robot = None
        if model is not None:
            if params is not None:
                raise ValueError("McapRecorder: give params (the paper's planar robot) or model (any robot), "
                                 "not both")
            self._robot = _RobotChannels(model, _tip_site_of(metadata))
        clash = sorted(set(metadata) & set(RESERVED_KEYS + ("status", "reason")))
        if clash:
            raise ValueError(f"metadata keys {clash} are reserved by the recorder")
        comp = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}
        if compression not in comp:
            raise ValueError(f"compression = {compression!r}; allowed: {sorted(comp)}")
        self.path = Path(path)
        self.params = params
        self.flush_interval = float(flush_interval)
        self.path_period = float(path_period)
        self.path_resolution = float(path_resolution)
        self.samples = 0
        self.closed = False
        self.status: str | None = None
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = _open_locked(self.path)
        try:
            self._writer = LeanWriter(self._file, chunk_size=chunk_size, compression=comp[compression])
            self._writer.start(profile="", library=f"uvms_mj {_version('uvms-mj') or ''} / mcap")
            record = dict(metadata)
            record.update(provenance())
            record["robot_params"] = dataclasses.asdict(params) if params is not None else None
            record["created_utc"] = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
            record["log_format"] = LOG_FORMAT
            self._writer.add_metadata(METADATA_NAME, {k: _meta_value(v) for k, v in record.items()})
            self._writer.flush()
        except BaseException:
            self._file.close()
            raise
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._sample_channels: list[tuple[int, list[tuple[str, bool, bool]]]] = []
        self._known: set[str] | None = None
        self._warned: set[str] = set()
        self._last_flush = time.monotonic()
        self._t0_stamp: dict | None = None
        self._paths: dict[str, list[str]] = {}
        self._path_last: dict[str, tuple[float, ...] | None] = {}
        self._path_kept_t: dict[str, float] = {}
        self._path_recent: dict[str, list] = {}  # rows since the last kept point (their last finite value ends the strip)
        self._path_specs: tuple[_PathSpec, ...] = ()
        self._path_sent_t = 0.0
        self._path_dirty = False
        self._last_ns = 0
        self._pending: list[tuple] = []  # samples written since the last flush, not yet encoded

    # ---------------------------------------------------------------- channels

    def _channel(self, topic: str, schema_name: str, schema: dict, metadata: dict | None = None) -> int:
        if schema_name not in self._schemas:
            self._schemas[schema_name] = self._writer.register_schema(
                name=schema_name, encoding="jsonschema", data=json.dumps(schema).encode())
        cid = self._writer.register_channel(topic=topic, message_encoding="json",
                                            schema_id=self._schemas[schema_name], metadata=metadata or {})
        self._channels[topic] = cid
        return cid

    def _start(self, ns: int, row: Mapping[str, Any]) -> None:
        """First sample: signal layout, channels, static transforms and the robot scene."""
        groups: dict[str, list[dict]] = {TOPIC_CONTROL: [], TOPIC_STATE: []}
        for i, (name, value) in enumerate(row.items()):
            entry = _layout_entry(name, value, i)
            if entry is None:
                warnings.warn(f"recorder: signal {name!r} is not numeric "
                              f"({type(value).__name__}); it is not recorded", stacklevel=3)
                self._warned.add(name)
                continue
            groups[TOPIC_STATE if name in STATE_SIGNALS else TOPIC_CONTROL].append(entry)
        self._known = {e["name"] for g in groups.values() for e in g} | self._warned
        info = {
            TOPIC_CONTROL: ("uvms_mj.ControlSample", "Controller signals and commands, one per control sample"),
            TOPIC_STATE: ("uvms_mj.TrueState", "True plant state, one per control sample"),
        }
        for topic, layout in groups.items():
            if not layout:
                continue
            name, desc = info[topic]
            cid = self._channel(topic, name, _sample_schema(name, desc, layout),
                                {"uvms_mj.signals": json.dumps(layout)})
            self._sample_channels.append(
                (cid, [(e["name"], e["dtype"] == "bool", len(e["shape"]) > 1) for e in layout]))
        # per sample channel, for rows with exactly the first row's signals: the row's other
        # signals (dropped from a copy of the row) and its fields needing conversion, when that is
        # cheaper than picking the fields
        self._row_plans = []
        for cid, fields in self._sample_channels:
            mine = {f[0] for f in fields}
            drop = tuple(n for n in row if n not in mine)
            special = tuple((n, b) for n, b, fl in fields if b or fl)
            self._row_plans.append((drop, special) if len(drop) < len(fields) else
                                   (None, tuple((n, b, fl) for n, b, fl in fields)))

        stamp = _stamp(ns)
        self._t0_stamp = stamp
        if self._robot is not None:
            self._has_q = False
            self._robot.start(self._channel, self._writer, ns, stamp, row)
            self._path_sent_t = ns * 1e-9
            self._path_specs = self._robot.path_specs(row)
            self._want_paths = bool(self._path_specs)
            if self._want_paths:
                self._channel(TOPIC_PATHS, "foxglove.SceneUpdate", SCHEMAS["foxglove.SceneUpdate"])
            return
        self._has_q = "q_true" in row and np.shape(row["q_true"]) == (5,) and self.params is not None
        if self._has_q:
            self._channel(TOPIC_TF, "foxglove.FrameTransforms", SCHEMAS["foxglove.FrameTransforms"])
            self._channel(TOPIC_JOINTS, "foxglove.JointStates", SCHEMAS["foxglove.JointStates"])
            s45 = math.sqrt(0.5)
            b = self.params.bodies
            self._tf_chain = [
                ("view", "world", (0.0, 0.0), {"x": s45, "y": 0.0, "z": 0.0, "w": s45}),
                ("world", b[0].name, None, None),
                (b[0].name, b[1].name, b[1].joint_offset, None),
                (b[1].name, b[2].name, b[2].joint_offset, None),
                (b[2].name, "tip", self.params.tip_offset, dict(_IDENTITY)),
            ]
            self._tf_tmpl = _tf_template(self._tf_chain)
            # the same template with positional fields: its keys' positions in [stamp, *_TF_KEYS numbers]
            order = re.findall(r"%\((\w+)\)s", self._tf_tmpl)
            self._tf_pos = re.sub(r"%\((\w+)\)s", "%s", self._tf_tmpl)
            self._tf_args = operator.itemgetter(*[0 if key == "stamp" else 1 + _TF_KEYS.index(key) for key in order])
            self._js_tmpl = '{"timestamp":%s,"joints":[' + ",".join(
                '{"name":%s,"position":%%s,"velocity":%%s}' % json.dumps(n).replace("%", "%%") for n in JOINT_NAMES) + "]}"
            self._js_tmpl_pos = '{"timestamp":%s,"joints":[' + ",".join(
                '{"name":%s,"position":%%s}' % json.dumps(n).replace("%", "%%") for n in JOINT_NAMES) + "]}"
            # as bytes, with the columns of [stamp, *numbers of _encode_frames] each one takes
            self._tf_pos_b = self._tf_pos.encode()
            self._tf_cols = list(self._tf_args(list(range(19))))
            self._js_tmpl_b, self._js_tmpl_pos_b = self._js_tmpl.encode(), self._js_tmpl_pos.encode()
            self._js_cols = [0] + [1 + j for q in range(5) for j in (8 + q, 13 + q)]
            self._js_cols_pos = [0] + [1 + j for j in range(8, 13)]
        if self.params is not None:
            self._writer.add_message(self._channel(TOPIC_SCENE, "foxglove.SceneUpdate",
                                                   SCHEMAS["foxglove.SceneUpdate"]),
                                     ns, _dumps(self._robot_scene(stamp)), ns, 0)
        self._path_sent_t = ns * 1e-9
        self._path_specs = _PAPER_PATHS
        self._want_paths = self.params is not None and (
            np.shape(row.get("p_desired", ())) == (5,) or np.shape(row.get("tip_true", ())) == (2,))
        if self._want_paths:
            self._channel(TOPIC_PATHS, "foxglove.SceneUpdate", SCHEMAS["foxglove.SceneUpdate"])

    def _robot_scene(self, stamp: dict) -> dict:
        colors = {"base": _color(0.85, 0.55, 0.15, 0.9)}
        ents = []
        for b in self.params.bodies:
            cube = {"pose": {"position": {"x": b.box_center[0], "y": b.box_center[1], "z": 0.0},
                             "orientation": dict(_IDENTITY)},
                    "size": {"x": 2 * b.box_half[0], "y": 2 * b.box_half[1], "z": b.width},
                    "color": colors.get(b.name, _color(0.6, 0.6, 0.65, 0.9))}
            ents.append(_entity(b.name, b.name, stamp, cubes=[cube]))
        arrows = []
        for th in self.params.thrusters:
            ang = math.atan2(th.direction[1], th.direction[0])
            arrows.append({"pose": {"position": {"x": th.position[0], "y": th.position[1], "z": 0.0},
                                    "orientation": _quat_z(ang)},
                           "shaft_length": 0.12, "shaft_diameter": 0.015, "head_length": 0.04,
                           "head_diameter": 0.035, "color": _color(0.2, 0.6, 1.0)})
        if arrows:
            ents.append(_entity(self.params.bodies[0].name, "thrusters", stamp, arrows=arrows))
        tip = {"pose": {"position": dict(_ZERO3), "orientation": dict(_IDENTITY)},
               "size": {"x": 0.025, "y": 0.025, "z": 0.025}, "color": _color(1.0, 0.2, 0.2)}
        ents.append(_entity("tip", "tip", stamp, spheres=[tip]))
        return {"deletions": [], "entities": ents}

    # ---------------------------------------------------------------- writing

    def write_sample(self, t: float, row: Mapping[str, Any]) -> None:
        """Record one sample (the loop's ``sink``): ``row`` maps signal names to numbers,
        booleans or numpy arrays.

        The samples are encoded and written in batches, at each flush (after the first sample,
        then at least every ``flush_interval`` s, and at close): the row (a shallow copy of it) is
        kept until then, so its arrays must not be changed in place after the call (the loop and
        every built-in controller give new arrays each sample). What reaches the file, and when,
        is the same as writing each sample at once."""
        if self.closed:
            raise RuntimeError(f"recorder for {self.path} is closed")
        with _CRITICAL:
            t = float(t)
            ns = int(round(t * 1e9))
            if ns < 0:
                _ns(t)  # says why
            same = True  # the row has exactly the first row's signals
            if self._known is None:
                self._start(ns, row)
            elif row.keys() != self._known:
                same = False
                for name in row.keys() - self._known - self._warned:
                    self._warned.add(name)
                    warnings.warn(f"recorder: signal {name!r} first appeared after the first "
                                  "sample; it is not recorded", stacklevel=3)
            self._pending.append((t, ns, self.samples, dict(row), same))
            self.samples += 1
            self._last_ns = ns
            if self.samples == 1 or time.monotonic() - self._last_flush >= self.flush_interval:
                self.flush()

    def _write_pending(self) -> None:
        """Encode and write the samples kept since the last flush, in order (with the paths)."""
        rows, self._pending = self._pending, []
        if not rows:
            return
        try:
            encoded = self._encode_rows(rows)
        except Exception:  # a row that cannot be encoded: write the rows before it, then raise
            encoded = []
            for n, row in enumerate(rows):
                try:
                    encoded += self._encode_rows([row])
                except Exception:
                    rows = rows[:n]
                    self._write_encoded(rows, encoded)
                    raise
        self._write_encoded(rows, encoded)

    def _write_encoded(self, rows: list[tuple], encoded: list[list[tuple[int, bytes]]]) -> None:
        w = self._writer
        if not self._want_paths:
            w.add_samples([(out, ns, k) for (_, ns, k, _, _), out in zip(rows, encoded)])
            return
        start = 0
        period = self.path_period - 1e-9
        for n, r in enumerate(rows):
            if r[0] - self._path_sent_t >= period:  # the paths follow this sample's messages
                self._add_path_rows(rows, start, n + 1)
                w.add_samples([(o, x[1], x[2]) for x, o in zip(rows[start:n + 1], encoded[start:n + 1])])
                start = n + 1
                self._write_paths(r[1], r[2])
        self._add_path_rows(rows, start, len(rows))
        w.add_samples([(o, x[1], x[2]) for x, o in zip(rows[start:], encoded[start:])])

    def _encode_rows(self, rows: list[tuple]) -> list[list[tuple[int, bytes]]]:
        """Each pending sample's messages (channel, data). The sample channels of rows holding
        the first row's signals, and the paper's /tf and /joint_states, are encoded for the whole
        batch by one orjson call each (the same bytes as :func:`_sample_body` row by row, which
        encodes the others and any row with a non-finite number, see ``tests/test_recorder.py``)."""
        n = len(rows)
        stamps = [b'{"sec":%d,"nsec":%d}' % divmod(ns, 1_000_000_000) for _, ns, _, _, _ in rows]
        heads = [b'{"timestamp":%s,"t":%a' % (st, r[0]) for st, r in zip(stamps, rows)]  # (%a: a float's repr)
        out: list[list[tuple[int, bytes]]] = [[] for _ in range(n)]
        chans = [(cid, fields, plan) for (cid, fields), plan in zip(self._sample_channels, self._row_plans)]
        batch = [i for i, r in enumerate(rows) if r[4]] if _orjson is not None else []
        got = _batch_bodies([rows[i][3] for i in batch], [c[2] for c in chans]) if batch and chans else None
        pieces, nulls = got if got is not None else (None, False)
        if pieces is None:
            batch = []
        fast = set(batch)
        nc = len(chans)
        cids = [c[0] for c in chans]
        if batch:
            datas = [b"%s,%s}" % (heads[i], piece) for i, piece in zip((i for i in batch for _ in cids), pieces)]
            if len(batch) == n and not nulls and self._robot is None:
                every = self._every_row_at_once(rows, stamps, cids, datas)
                if every is not None:
                    return every
            for b, i in enumerate(batch):
                out[i] = list(zip(cids, datas[b * nc:(b + 1) * nc]))
            if nulls:  # a non-finite number: the general encoding
                for b, i in enumerate(batch):
                    for j, (cid, fields, _) in enumerate(chans):
                        if b"null" in pieces[b * nc + j]:
                            body = _sample_body(rows[i][3], fields)
                            out[i][j] = (cid, heads[i] + (b"," + body[1:] if len(body) > 2 else b"}"))
        for i in (range(n) if len(fast) < n else ()):
            if i not in fast:
                row = rows[i][3]
                for cid, fields, _ in chans:
                    body = _sample_body(row, fields)
                    out[i].append((cid, heads[i] + (b"," + body[1:] if len(body) > 2 else b"}")))
        if self._has_q:
            self._encode_paper_frames(rows, stamps, out)
        if self._robot is not None:
            for i, (_, _, _, row, _) in enumerate(rows):
                self._robot.write(out[i], stamps[i].decode(), heads[i].decode(), row)
        return out

    def _every_row_at_once(self, rows: list[tuple], stamps: list[bytes], cids: list[int],
                           datas: list[bytes]) -> list[tuple] | None:
        """:meth:`_encode_rows` of a batch of regular rows (the first row's signals, all finite,
        the paper's pose and velocities in each): the sample channels' messages ``datas`` (row by
        row, channel by channel) and the /tf and /joint_states messages put together by zips.
        None where the rows are not all like that."""
        nc = len(cids)
        cols = [zip(repeat(cid), datas[j::nc]) for j, cid in enumerate(cids)]
        if self._has_q:
            try:
                Q = np.array([r[3]["q_true"] for r in rows], dtype=float)
                Qd = np.array([r[3]["qd_true"] for r in rows], dtype=float)
            except (KeyError, ValueError, TypeError):
                return None
            if Q.shape != (len(rows), 5) or Qd.shape != Q.shape:
                return None
            both = self._frames_at_once(*self._frame_numbers(Q, Qd), stamps, True)
            if both is None:
                return None
            cols += [zip(repeat(self._channels[TOPIC_TF]), both[0]), zip(repeat(self._channels[TOPIC_JOINTS]), both[1])]
        return list(zip(*cols))

    def _encode_paper_frames(self, rows: list[tuple], stamps: list[bytes], out: list[list]) -> None:
        """The paper robot's /tf and /joint_states messages of a batch: the numbers of every row
        at once (numpy's sin and cos of the half angles, one orjson call), then one template each.
        A row without a finite pose gets no /tf (as for any robot), its joint states the general
        encoding of its numbers (+-inf as +-1e999)."""
        have = [i for i, r in enumerate(rows) if np.shape(r[3].get("q_true", ())) == (5,)]  # (others: none)
        with_qd = [i for i in have if np.shape(rows[i][3].get("qd_true", ())) == (5,)]
        if len(with_qd) == len(have):
            groups = [(have, True)]
        else:  # rows without the velocities: positions only
            got = set(with_qd)
            groups = [(with_qd, True), ([i for i in have if i not in got], False)]
        for group, vel in groups:
            if group:
                self._encode_frames(rows, stamps, out, group, vel)

    def _frame_numbers(self, Q: np.ndarray, Qd: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, bytes]:
        """The numbers of the paper's /tf and /joint_states messages for poses ``Q`` (n, 5) and
        velocities ``Qd`` (n, 5; None: positions only): (the matrix of them, which rows have a
        finite pose, their orjson text)."""
        M = np.empty((len(Q), 18 if Qd is not None else 13))
        M[:, 0:2] = Q[:, :2]
        H = 0.5 * Q[:, 2:5]
        ok = np.isfinite(M[:, 0:2]).all(axis=1) & np.isfinite(H).all(axis=1)
        H[~ok] = 0.0
        M[:, 2:8:2], M[:, 3:8:2] = np.sin(H), np.cos(H)  # (z_i, w_i) of each rotation about +Z
        M[:, 8:13] = Q
        if Qd is not None:
            M[:, 13:18] = Qd
        return M, ok, (_orjson.dumps(M, option=_NUMPY) if _orjson is not None else b"")

    def _frames_at_once(self, M: np.ndarray, ok: np.ndarray, text: bytes, stamps: list[bytes],
                        vel: bool) -> tuple[list[bytes], list[bytes]] | None:
        """The /tf and /joint_states messages of rows whose numbers are all finite, at once:
        each channel's template repeated for the batch (rows separated by NUL bytes, which JSON
        text never holds raw) and formatted in one operation with the stamps and numbers of all
        rows, picked by an object array. None where a row is not like that."""
        n, w = M.shape
        nums = text[2:-2].replace(b"],[", b",").split(b",") if text else []
        if len(nums) != n * w or not ok.all() or b"null" in text:
            return None
        A = np.empty((n, 1 + w), dtype=object)
        A[:, 0] = stamps
        A[:, 1:] = np.array(nums, dtype=object).reshape(n, w)
        js_tmpl, js_cols = (self._js_tmpl_b, self._js_cols) if vel else (self._js_tmpl_pos_b, self._js_cols_pos)
        tf = ((self._tf_pos_b + b"\0") * n % tuple(A[:, self._tf_cols].ravel().tolist())).split(b"\0")
        js = ((js_tmpl + b"\0") * n % tuple(A[:, js_cols].ravel().tolist())).split(b"\0")
        return tf[:n], js[:n]

    def _encode_frames(self, rows: list[tuple], stamps: list[bytes], out: list[list], group: list[int],
                       vel: bool) -> None:
        Q = np.array([np.asarray(rows[i][3]["q_true"], dtype=float) for i in group])
        Qd = np.array([np.asarray(rows[i][3]["qd_true"], dtype=float) for i in group]) if vel else None
        M, ok, text = self._frame_numbers(Q, Qd)
        tf_id, js_id = self._channels[TOPIC_TF], self._channels[TOPIC_JOINTS]
        both = self._frames_at_once(M, ok, text, [stamps[i] for i in group], vel)
        if both is not None:
            for i, tf_i, js_i in zip(group, *both):
                out[i].append((tf_id, tf_i))
                out[i].append((js_id, js_i))
            return
        tf_pos, tf_args = self._tf_pos_b, self._tf_args
        js_tmpl = self._js_tmpl_b if vel else self._js_tmpl_pos_b
        js_args = operator.itemgetter(*[c - 1 for c in (self._js_cols if vel else self._js_cols_pos)[1:]])
        parts = text[2:-2].split(b"],[") if text else []
        if len(parts) != len(group):
            parts = [None] * len(group)
        for b, (part, i) in enumerate(zip(parts, group)):
            if part is None or b"null" in part:
                part = _enc(M[b].tolist())[1:-1].encode()  # non-finite numbers: the general encoding
            xs = part.split(b",")
            stamp = stamps[i]
            if ok[b]:
                out[i].append((tf_id, tf_pos % tf_args([stamp] + xs)))
            out[i].append((js_id, js_tmpl % ((stamp,) + js_args(xs))))

    def _add_path_rows(self, rows: list[tuple], lo: int, hi: int) -> None:
        """The paths' points from the pending rows ``rows[lo:hi]``, in order: a point every
        ``path_resolution`` s of run time (the first finite value from then on); the rows between
        are only kept (found by their times, kept in one step): the last finite value among them
        ends the strip when it is sent (:meth:`_settle_paths`)."""
        res = self.path_resolution - 1e-9
        for spec in self._path_specs:
            key = spec.key
            kept_t = self._path_kept_t.get(key, -math.inf)
            recent = self._path_recent.setdefault(key, [])
            j = lo
            while j < hi:
                if rows[j][0] - kept_t < res:
                    j2 = j + 1
                    while j2 < hi and rows[j2][0] - kept_t < res:
                        j2 += 1
                    recent.extend(r[3] for r in rows[j:j2])
                    j = j2
                    continue
                t, row = rows[j][0], rows[j][3]
                xs = self._path_value(spec, row)
                if xs is not None:
                    self._paths.setdefault(key, []).append(_point(*xs))
                    kept_t = self._path_kept_t[key] = t
                    self._path_last[key] = None
                    recent = self._path_recent[key] = []
                    self._path_dirty = True
                j += 1

    @staticmethod
    def _path_value(spec: "_PathSpec", row: Mapping[str, Any]) -> list | None:
        v = row.get(spec.signal)
        if v is None:
            return None
        i = spec.start
        xs = (v[i:i + spec.dims].tolist() if type(v) is np.ndarray and v.dtype == np.float64
              else [float(v[i + j]) for j in range(spec.dims)])
        return xs if all(map(math.isfinite, xs)) else None

    def _settle_paths(self) -> None:
        """The strips' last points from the rows kept since each strip's last point."""
        for spec in self._path_specs:
            recent = self._path_recent.get(spec.key)
            if not recent:
                continue
            for row in reversed(recent):
                xs = self._path_value(spec, row)
                if xs is not None:
                    self._path_last[spec.key] = xs
                    self._path_dirty = True
                    break
            self._path_recent[spec.key] = []

    def _write_paths(self, ns: int, sequence: int | None = None) -> None:
        self._settle_paths()
        stamp = _stamp(ns)
        ents, pts = [], {}
        for spec in self._path_specs:
            key, color, eid = spec.key, _color(*spec.rgba), spec.entity
            points = list(self._paths.get(key, ()))
            if self._path_last.get(key) is not None:
                points.append(_point(*self._path_last[key]))
            if len(points) < 2:
                continue
            line = {"type": 0, "pose": {"position": dict(_ZERO3), "orientation": dict(_IDENTITY)},
                    "thickness": 0.004, "scale_invariant": False, "points": f"@@{key}@@", "color": color,
                    "colors": [], "indices": []}
            ents.append(_entity("world", eid, self._t0_stamp or stamp, frame_locked=False, lines=[line]))
            pts[key] = "[" + ",".join(points) + "]"
        self._path_sent_t = ns * 1e-9
        self._path_dirty = False
        if not ents:
            return
        data = _dumps({"deletions": [], "entities": ents}).decode()
        for key, arr in pts.items():
            data = data.replace(f'"@@{key}@@"', arr, 1)
        self._writer.add_message(self._channels[TOPIC_PATHS], ns, data.encode(), ns,
                                 self.samples if sequence is None else sequence)

    def flush(self) -> None:
        """Finish the chunk in progress and flush the file (done automatically every
        ``flush_interval`` s)."""
        if self.closed:
            return
        with _critical():
            self._write_pending()
            self._writer.flush()
            self._last_flush = time.monotonic()

    def close(self, status: str = "ok", reason: str = "", meta: Mapping[str, Any] | None = None) -> None:
        """Write the status record (with ``meta``, e.g. the RunResult's meta) and the summary,
        and close the file. Later calls do nothing."""
        if self.closed:
            return
        with _critical():
            self.closed = True
            failed = None
            try:
                try:
                    self._write_pending()
                except Exception as exc:  # a sample that cannot be encoded: finish the log, then raise
                    failed = exc
                    status, reason = "error", f"recorder: {exc!r}" + (f" ({reason})" if reason else "")
                self.status = status
                if self._want_paths_pending():
                    self._write_paths(self._last_ns)
                self._writer.flush()  # the last chunk goes before the status record
                rec = {"status": status, "reason": reason, "samples": self.samples}
                for key, value in dict(meta or {}).items():
                    rec.setdefault(key, value)
                self._writer.add_metadata(STATUS_NAME, {k: _meta_value(v) for k, v in rec.items()})
                self._writer.finish()
                self._file.flush()
            finally:
                self._file.close()
            if failed is not None:
                raise failed

    def _want_paths_pending(self) -> bool:
        if not getattr(self, "_want_paths", False):
            return False
        self._settle_paths()
        return bool(self._path_dirty)

    def __enter__(self) -> "McapRecorder":
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        if exc_type is None:
            self.close("ok")
        elif issubclass(exc_type, KeyboardInterrupt):
            self.close("interrupted", str(exc) or "interrupted (KeyboardInterrupt)")
        else:
            self.close("error", f"{exc_type.__name__}: {exc}")
        return False


# --------------------------------------------------------------------------- reading


@dataclass
class LogData(RunResult):
    """A run read back from a log; usable wherever a :class:`RunResult` is.

    Attributes (besides RunResult's ``t``, ``signals``, ``status``, ``reason``, ``meta``):
        truncated: the file ends without its summary (the writer was killed); the data is
            what was flushed before that.
        path: the file read.
    """

    truncated: bool = False
    path: str = ""

    @property
    def params(self) -> RobotParams | None:
        """The recorded robot parameters (``meta["robot_params"]``), or None if absent."""
        return _params_from_dict(self.meta.get("robot_params"))


def _params_from_dict(d: Mapping[str, Any] | None) -> RobotParams | None:
    if not d:
        return None

    def tup(v):
        return tuple(tup(x) for x in v) if isinstance(v, list) else v

    try:
        return RobotParams(
            bodies=tuple(BodyParams(**{k: tup(v) for k, v in b.items()}) for b in d["bodies"]),
            thrusters=tuple(ThrusterParams(**{k: tup(v) for k, v in t.items()}) for t in d["thrusters"]),
            **{k: tup(v) for k, v in d.items() if k not in ("bodies", "thrusters")},
        )
    except (KeyError, TypeError):
        return None


def _complete_prefix(data: bytes) -> tuple[int, bool]:
    """Length of the longest prefix made of whole top-level records, and whether the file is
    complete (footer and closing magic present)."""
    if len(data) < len(_MAGIC) or data[: len(_MAGIC)] != _MAGIC:
        raise McapError("not an MCAP file (bad magic)")
    pos, n = len(_MAGIC), len(data)
    while pos + 9 <= n:
        op, length = struct.unpack_from("<BQ", data, pos)
        end = pos + 9 + length
        if end > n:
            break
        pos = end
        if op == _OP_FOOTER:
            return pos, data[pos: pos + len(_MAGIC)] == _MAGIC
    return pos, False


def _records(path: str | os.PathLike) -> tuple[list, bool]:
    """All records of a log in file order (chunks broken up), and whether it was truncated.
    Stops at the first incomplete or corrupt record."""
    with open(path, "rb") as f:
        data = f.read()
    end, complete = _complete_prefix(data)
    out: list = []
    # A complete file keeps its closing magic (the stream reader checks it after the footer).
    body = data[: end + len(_MAGIC)] if complete else data[:end]
    reader = StreamReader(io.BytesIO(body), emit_chunks=True, validate_crcs=False)
    try:
        for rec in reader.records:
            if isinstance(rec, Chunk):
                try:
                    out.extend(breakup_chunk(rec, validate_crc=True))
                except Exception:
                    complete = False
                    break
            else:
                out.append(rec)
    except Exception:
        # McapError (EndOfFile at the cut) or a record that does not parse: keep what came before.
        complete = False
    return out, not complete


def iter_messages(path: str | os.PathLike) -> Iterator[tuple[Channel, Schema | None, Message]]:
    """(channel, schema, message) of every message in file order; works on truncated logs."""
    recs, _ = _records(path)
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    for r in recs:
        if isinstance(r, Schema):
            schemas[r.id] = r
        elif isinstance(r, Channel):
            channels[r.id] = r
        elif isinstance(r, Message) and r.channel_id in channels:
            ch = channels[r.channel_id]
            yield ch, schemas.get(ch.schema_id), r


def _decode_meta(d: Mapping[str, str]) -> dict:
    out = {}
    for k, v in d.items():
        try:
            out[k] = json.loads(v)
        except (ValueError, TypeError):
            out[k] = v
    return out


def _scan(recs: list) -> dict:
    """Metadata, channels and per-channel messages of a record list."""
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    msgs: dict[int, list[Message]] = {}
    metas: dict[str, dict] = {}
    for r in recs:
        if isinstance(r, Message):
            msgs.setdefault(r.channel_id, []).append(r)
        elif isinstance(r, Channel):
            channels.setdefault(r.id, r)
        elif isinstance(r, Schema):
            schemas.setdefault(r.id, r)
        elif isinstance(r, Metadata):
            metas.setdefault(r.name, _decode_meta(r.metadata))
    return {"schemas": schemas, "channels": channels, "messages": msgs, "metadata": metas}


def _sample_channels(scan: dict) -> list[tuple[Channel, list[dict]]]:
    out = []
    for ch in scan["channels"].values():
        if ch.topic in SAMPLE_TOPICS and "uvms_mj.signals" in ch.metadata:
            out.append((ch, json.loads(ch.metadata["uvms_mj.signals"])))
    return out


def _complete_sequences(scan: dict, sample_chs: list) -> list[int]:
    if not sample_chs:
        return []
    seqs = None
    for ch, _ in sample_chs:
        s = {m.sequence for m in scan["messages"].get(ch.id, [])}
        seqs = s if seqs is None else seqs & s
    return sorted(seqs)


def _status(scan: dict, truncated: bool, t_end: float | None) -> tuple[str, str, dict]:
    st = dict(scan["metadata"].get(STATUS_NAME, {}))
    if st:
        return str(st.pop("status", "")), str(st.pop("reason", "")), st
    if truncated:
        where = f"t = {t_end:.4f} s" if t_end is not None else "the start"
        return "truncated", f"log ends at {where} without a status record (writer killed?)", {}
    return "unknown", "no status record", {}


def read_log(path: str | os.PathLike) -> LogData:
    """Read a log written by :class:`McapRecorder` (complete, or cut off by ``kill -9``).

    Returns a :class:`LogData` with the sample times, the signals (the same names, order,
    shapes and dtypes as the run's :class:`RunResult`; only samples whose every per-sample
    message was flushed), the status and reason from the status record ("truncated" when it
    is missing from a cut-off log) and ``meta``: the ``uvms_mj`` metadata (the caller's dict,
    versions, git commit, robot parameters...), plus the keys of the status record's extra
    ``meta`` (e.g. the RunResult's T, dt, seed, controller) that it does not already have,
    plus ``T`` (inferred from the sample times if recorded nowhere).
    """
    recs, truncated = _records(path)
    scan = _scan(recs)
    sample_chs = _sample_channels(scan)
    seqs = _complete_sequences(scan, sample_chs)
    keep = set(seqs)
    payloads: list[dict[int, dict]] = [dict() for _ in seqs]
    pos = {s: i for i, s in enumerate(seqs)}
    for ch, _ in sample_chs:
        for m in scan["messages"].get(ch.id, []):
            if m.sequence in keep:
                payloads[pos[m.sequence]].setdefault(ch.id, json.loads(m.data))
    order = sorted((e["index"], e["name"], e["dtype"], tuple(e["shape"]), ch.id)
                   for ch, layout in sample_chs for e in layout)
    rec: dict[str, list] = {}
    times: list[float] = []
    for p in payloads:
        first = next(iter(p.values()))
        times.append(float(first["t"]) if "t" in first else
                     first["timestamp"]["sec"] + 1e-9 * first["timestamp"]["nsec"])
        for _, name, _, _, cid in order:
            msg = p[cid]
            if name in msg:
                rec.setdefault(name, []).append(msg[name])
    signals: dict[str, np.ndarray] = {}
    for _, name, dtype, shape, _ in order:
        want = np.dtype(dtype)
        if name not in rec:
            signals[name] = np.zeros((0,) + shape, dtype=want)
            continue
        arr = np.asarray(rec[name])
        if arr.dtype == object:  # null (NaN) among the values
            arr = np.array(rec[name], dtype=float)
        if len(shape) > 1 and arr.ndim == 2 and arr.shape[1] == int(np.prod(shape)):
            arr = arr.reshape((len(arr),) + shape)
        if want.kind == "b":
            arr = arr.astype(bool)
        elif want.kind == "f" and arr.dtype.kind == "f" and arr.dtype != want:
            arr = arr.astype(want)
        signals[name] = arr
    t = np.asarray(times, dtype=float)
    status, reason, extra = _status(scan, truncated, float(t[-1]) if len(t) else None)
    meta = dict(scan["metadata"].get(METADATA_NAME, {}))
    for key, value in extra.items():  # the creation-time metadata wins on a clash
        meta.setdefault(key, value)
    if "T" not in meta and len(t) > 1:
        meta["T"] = float(np.median(np.diff(t)))
    return LogData(t=t, signals=signals, status=status, reason=reason, meta=meta,
                   truncated=truncated, path=str(path))


def log_info(path: str | os.PathLike) -> dict:
    """Summary of a log: metadata, status, truncation, channels (schema, encodings, message
    counts), time range and number of complete samples. Works on truncated logs."""
    recs, truncated = _records(path)
    scan = _scan(recs)
    sample_chs = _sample_channels(scan)
    seqs = _complete_sequences(scan, sample_chs)
    channels = []
    t_min = t_max = None
    for cid, ch in sorted(scan["channels"].items()):
        ms = scan["messages"].get(cid, [])
        sc = scan["schemas"].get(ch.schema_id)
        channels.append({"topic": ch.topic, "schema": sc.name if sc else "",
                         "schema_encoding": sc.encoding if sc else "",
                         "message_encoding": ch.message_encoding, "messages": len(ms)})
        if ms:
            lo, hi = min(m.log_time for m in ms), max(m.log_time for m in ms)
            t_min = lo if t_min is None else min(t_min, lo)
            t_max = hi if t_max is None else max(t_max, hi)
    sample_times = []
    if sample_chs and seqs:
        first = {m.sequence: m.log_time for m in scan["messages"].get(sample_chs[0][0].id, [])}
        sample_times = [first[seqs[0]] * 1e-9, first[seqs[-1]] * 1e-9]
    status, reason, extra = _status(scan, truncated, sample_times[-1] if sample_times else None)
    start = t_min * 1e-9 if t_min is not None else None
    end = t_max * 1e-9 if t_max is not None else None
    return {
        "path": str(path),
        "size_bytes": os.path.getsize(path),
        "truncated": truncated,
        "status": status,
        "reason": reason,
        "metadata": scan["metadata"].get(METADATA_NAME, {}),
        "status_record": scan["metadata"].get(STATUS_NAME, {}),
        "channels": channels,
        "start_time": start,
        "end_time": end,
        "duration": (end - start) if start is not None else 0.0,
        "samples": len(seqs),
        "signals": {e["name"]: {"dtype": e["dtype"], "shape": e["shape"], "topic": ch.topic}
                    for ch, layout in sample_chs for e in sorted(layout, key=lambda e: e["index"])},
    }


def format_info(info: Mapping[str, Any]) -> str:
    """Human-readable text of :func:`log_info`'s result."""
    def fmt_t(x):
        return "-" if x is None else f"{x:.4f} s"

    lines = [f"log:       {info['path']} ({info['size_bytes'] / 1024:.1f} KiB)"]
    state = "TRUNCATED (read up to the last flush)" if info["truncated"] else "complete"
    lines.append(f"file:      {state}")
    lines.append(f"status:    {info['status']}" + (f" ({info['reason']})" if info.get("reason") else ""))
    lines.append(f"time:      {fmt_t(info['start_time'])} .. {fmt_t(info['end_time'])} "
                 f"(duration {info['duration']:.4f} s, {info['samples']} samples)")
    meta = dict(info.get("metadata", {}))
    versions = meta.pop("versions", None)
    meta.pop("robot_params", None)
    if versions:
        lines.append("versions:  " + ", ".join(f"{k} {v}" for k, v in versions.items()))
    if "git_commit" in meta:
        dirty = " (dirty)" if meta.pop("git_dirty", False) else ""
        lines.append(f"git:       {meta.pop('git_commit')}{dirty}")
    def add_mapping(items: Mapping[str, Any]) -> None:
        for k, v in items.items():
            if isinstance(v, Mapping) and v:  # e.g. the resolved scenario: indented YAML
                import yaml

                text = yaml.safe_dump(json.loads(json.dumps(v, default=str)), sort_keys=False,
                                      default_flow_style=None, width=100)
                lines.append(f"  {k}:")
                lines.extend("    " + line for line in text.rstrip("\n").splitlines())
            else:
                lines.append(f"  {k}: {json.dumps(v, sort_keys=True, default=str)}")

    if meta:
        lines.append("metadata:")
        add_mapping(meta)
    extra = {k: v for k, v in info.get("status_record", {}).items() if k not in ("status", "reason")}
    if extra:
        flat = {k: v for k, v in extra.items() if not isinstance(v, Mapping)}
        if flat:
            lines.append("run:       " + ", ".join(f"{k}={v}" for k, v in flat.items()))
        nested = {k: v for k, v in extra.items() if isinstance(v, Mapping)}
        if nested:
            lines.append("run metadata:")
            add_mapping(nested)
    lines.append("channels:")
    width = max((len(c["topic"]) for c in info["channels"]), default=5)
    for c in info["channels"]:
        lines.append(f"  {c['topic']:<{width}}  {c['messages']:>7} msgs  {c['schema']} "
                     f"({c['message_encoding']}/{c['schema_encoding']})")
    if info.get("signals"):
        import textwrap

        lines.extend(textwrap.wrap(", ".join(f"{n}{tuple(s['shape']) if s['shape'] else ''}"
                                             for n, s in info["signals"].items()),
                                   width=100, initial_indent="signals:   ", subsequent_indent=" " * 11))
    return "\n".join(lines)
