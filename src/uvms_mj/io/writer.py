"""The recorder that writes a run to MCAP as it happens (:class:`McapRecorder`; the layout is
described in :mod:`uvms_mj.io.recorder`)."""

from __future__ import annotations

import contextlib

import dataclasses
import datetime as _dt
import json
import math
import operator
import os
import re
import time
import warnings
from itertools import repeat
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping

import numpy as np
from mcap.writer import CompressionType

from uvms_mj.io.encoding import (_IDENTITY, _NUMPY, _PAPER_PATHS, _TF_KEYS, _ZERO3, _PathSpec, _batch_bodies, _color,
                                 _dumps, _enc, _entity, _layout_entry, _meta_value, _ns, _orjson, _paper_scene,
                                 _path_value, _point, _sample_body, _stamp, _tf_template)
from uvms_mj.io.interrupts import _CRITICAL, _critical
from uvms_mj.io.mcap_writer import LeanWriter
from uvms_mj.io.nav_channels import NavigationChannels
from uvms_mj.io.paths import _open_locked
from uvms_mj.io.provenance import _version, provenance
from uvms_mj.io.robot_channels import _RobotChannels, _tip_site_of
from uvms_mj.io.schemas import (LOG_FORMAT, METADATA_NAME, PAPER_JOINT_NAMES, RESERVED_KEYS, SCHEMAS, STATE_SIGNALS,
                                STATUS_NAME, TOPIC_CONTROL, TOPIC_JOINTS, TOPIC_PATHS, TOPIC_SCENE, TOPIC_STATE,
                                TOPIC_TF, _sample_schema)
from uvms_mj.io.sinks import Tee
from uvms_mj.io.writer_process import _WriterProcess, process_wanted
from uvms_mj.plant.params import RobotParams

if TYPE_CHECKING:
    import mujoco
    from uvms_mj.io.live import LiveServer


class McapRecorder(NavigationChannels):
    """Writes a run to an MCAP file as it happens (the layout: :mod:`uvms_mj.io.recorder`).

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
        model: any floating robot's compiled model (a free vehicle's :class:`~uvms_mj.plant.plant.Plant`
            ``model``; ``params`` must then be None): ``/tf``, ``/scene``, ``/joint_states``,
            ``/thrusters`` and ``/scene/paths`` come from it by name (:mod:`uvms_mj.io.recorder`, robot
            logs). The tip site is ``metadata["robot"]["layout"]["tip_site"]`` when given, else
            :meth:`~uvms_mj.plant.robot.Layout.of`'s default.
        live: a second sink (:class:`~uvms_mj.io.live.LiveServer`: to Foxglove), fed as the file is, pacing the run.
        writer: "process": after the first sample, a forked writer process encodes, compresses and
            writes the samples (:mod:`uvms_mj.io.writer_process`: the same bytes, off the
            simulation's core); "inline": this process does; "auto" (default): "process" where it
            pays (Linux, 2 or more cores, flush_interval > 0, no live sink, not in a pool's worker).

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
        live: "LiveServer | None" = None,
        writer: str = "auto",
    ) -> None:
        if not (flush_interval >= 0 and math.isfinite(flush_interval)):
            raise ValueError(f"flush_interval = {flush_interval!r} s must be finite and >= 0")
        self._proc: _WriterProcess | None = None
        self._proc_wanted = process_wanted(writer, float(flush_interval), live)
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
            self._live, self._writer = live, (Tee(self._writer, live) if live is not None else self._writer)
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
            with contextlib.suppress(OSError):  # a header cut short (full disk...): no half-written log left
                self.path.unlink()
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
                '{"name":%s,"position":%%s,"velocity":%%s}' % json.dumps(n).replace("%", "%%") for n in PAPER_JOINT_NAMES) + "]}"
            self._js_tmpl_pos = '{"timestamp":%s,"joints":[' + ",".join(
                '{"name":%s,"position":%%s}' % json.dumps(n).replace("%", "%%") for n in PAPER_JOINT_NAMES) + "]}"
            # as bytes, with the columns of [stamp, *numbers of _encode_frames] each one takes
            self._tf_pos_b = self._tf_pos.encode()
            self._tf_cols = list(self._tf_args(list(range(19))))
            self._js_tmpl_b, self._js_tmpl_pos_b = self._js_tmpl.encode(), self._js_tmpl_pos.encode()
            self._js_cols = [0] + [1 + j for q in range(5) for j in (8 + q, 13 + q)]
            self._js_cols_pos = [0] + [1 + j for j in range(8, 13)]
        if self.params is not None:
            self._writer.add_message(self._channel(TOPIC_SCENE, "foxglove.SceneUpdate",
                                                   SCHEMAS["foxglove.SceneUpdate"]),
                                     ns, _dumps(_paper_scene(self.params, stamp)), ns, 0)
        self._path_sent_t = ns * 1e-9
        self._path_specs = _PAPER_PATHS
        self._want_paths = self.params is not None and (
            np.shape(row.get("p_desired", ())) == (5,) or np.shape(row.get("tip_true", ())) == (2,))
        if self._want_paths:
            self._channel(TOPIC_PATHS, "foxglove.SceneUpdate", SCHEMAS["foxglove.SceneUpdate"])

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
            proc = self._proc
            if proc is not None:  # the writer process's batch (uvms_mj.io.writer_process)
                proc.add((t, dict(row), same))
            else:
                self._pending.append((t, ns, self.samples, dict(row), same))
            self.samples += 1
            self._last_ns = ns
            if self.samples == 1 or time.monotonic() - self._last_flush >= self.flush_interval:
                if proc is not None:
                    proc.send(True)
                    self._last_flush = time.monotonic()
                else:
                    self.flush()
                    if self.samples == 1 and self._proc_wanted:
                        self._proc = _WriterProcess(self, row)
        if self._live is not None and self._live.pace(t):  # (outside the critical section: Ctrl-C ends a wait)
            with _CRITICAL:
                self._write_pending()

    def _write_pending(self) -> None:
        """Encode and write the samples kept since the last flush, in order (with the paths)."""
        self._write_navigation()  # the navigation samples since the last flush (uvms_mj.io.nav_channels)
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
            self._robot.write_batch(out, [x.decode() for x in stamps], [x.decode() for x in heads],
                                    [r[3] for r in rows])
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
                xs = _path_value(spec, row)
                if xs is not None:
                    self._paths.setdefault(key, []).append(_point(*xs))
                    kept_t = self._path_kept_t[key] = t
                    self._path_last[key] = None
                    recent = self._path_recent[key] = []
                    self._path_dirty = True
                j += 1

    def _settle_paths(self) -> None:
        """The strips' last points from the rows kept since each strip's last point."""
        for spec in self._path_specs:
            recent = self._path_recent.get(spec.key)
            if not recent:
                continue
            for row in reversed(recent):
                xs = _path_value(spec, row)
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
            if self._proc is not None:
                self._proc.flush()  # (waits for the writer process's flush)
            else:
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
            if self._proc is not None:  # the writer process closes the log
                try:
                    self._proc.close(status, reason, meta)
                finally:
                    self._file.close()
                return
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
