"""Reading logs back: :func:`read_log` (a :class:`LogData`, usable wherever a RunResult is, also
from a log cut short by ``kill -9``), :func:`iter_messages`, :func:`log_info` and
:func:`format_info`."""

from __future__ import annotations

import json
import os
import struct
from array import array
from dataclasses import dataclass
from typing import Any, Iterator, Mapping

import numpy as np
from mcap.exceptions import McapError
from mcap.records import Channel, Chunk, Message, Metadata, Schema
from mcap.stream_reader import StreamReader, breakup_chunk

from uvms_mj.io.logfile import check_log_content, check_log_file
from uvms_mj.io.schemas import METADATA_NAME, SAMPLE_TOPICS, STATUS_NAME
from uvms_mj.plant.params import BodyParams, RobotParams, ThrusterParams
from uvms_mj.sim.loop import RunResult

_MAGIC = b"\x89MCAP0\r\n"
_OP_FOOTER = 0x02


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


def _complete_prefix(f) -> tuple[int, bool]:
    """Length of the longest prefix of the open file ``f`` made of whole top-level records, and
    whether the file is complete (footer and closing magic present); reads only record headers."""
    size = os.fstat(f.fileno()).st_size
    f.seek(0)
    if size < len(_MAGIC) or f.read(len(_MAGIC)) != _MAGIC:
        raise McapError("not an MCAP file (bad magic)")
    pos = len(_MAGIC)
    while pos + 9 <= size:
        f.seek(pos)
        op, length = struct.unpack("<BQ", f.read(9))
        if op == 0:  # not an MCAP opcode (zeros): the end of the readable records
            break
        end = pos + 9 + length
        if end > size:
            break
        pos = end
        if op == _OP_FOOTER:
            f.seek(pos)
            return pos, f.read(len(_MAGIC)) == _MAGIC
    return pos, False


class _Prefix:
    """The first ``limit`` bytes of an open file, as a stream (what the MCAP reader reads)."""

    def __init__(self, f, limit: int) -> None:
        self._f, self._left = f, limit

    def read(self, n: int = -1) -> bytes:
        n = self._left if n is None or n < 0 else min(n, self._left)
        data = self._f.read(n)
        self._left -= len(data)
        return data


def _iter_records(path: str | os.PathLike, state: dict) -> Iterator:
    """The records of a log in file order (chunks broken up), one chunk in memory at a time;
    stops at the first incomplete or corrupt record. When exhausted, ``state["truncated"]``
    says whether the file was cut short."""
    with open(path, "rb") as f:
        end, complete = _complete_prefix(f)
        f.seek(0)
        # A complete file keeps its closing magic (the stream reader checks it after the footer).
        reader = StreamReader(_Prefix(f, end + len(_MAGIC) if complete else end), emit_chunks=True,
                              validate_crcs=False)
        try:
            for rec in reader.records:
                if isinstance(rec, Chunk):
                    try:
                        inner = breakup_chunk(rec, validate_crc=True)
                    except Exception:
                        complete = False
                        break
                    yield from inner
                else:
                    yield rec
        except Exception:
            # McapError (EndOfFile at the cut) or a record that does not parse: keep what came before.
            complete = False
    state["truncated"] = not complete


def iter_messages(path: str | os.PathLike) -> Iterator[tuple[Channel, Schema | None, Message]]:
    """(channel, schema, message) of every message in file order; works on truncated logs."""
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    for r in _iter_records(path, {}):
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


def _status(scan: dict, truncated: bool, t_end: float | None) -> tuple[str, str, dict]:
    st = dict(scan["metadata"].get(STATUS_NAME, {}))
    if st:
        return str(st.pop("status", "")), str(st.pop("reason", "")), st
    if truncated:
        where = f"t = {t_end:.4f} s" if t_end is not None else "the start"
        return "truncated", f"log ends at {where} without a status record (writer killed?)", {}
    return "unknown", "no status record", {}


#: Messages of a sample channel decoded at a time by :func:`read_log` (bounds the JSON objects in memory).
_BATCH = 2048


class _Columns:
    """One sample channel's messages as columns: per message its sequence and time, per signal
    the values (numpy blocks of :data:`_BATCH` messages, converted as one list each) and whether
    the message had it. Memory: the arrays plus one batch of decoded JSON."""

    def __init__(self, layout: list[dict], wanted: frozenset | None = None) -> None:
        layout = [e for e in layout if wanted is None or e["name"] in wanted]
        self.layout = layout
        self._names = [e["name"] for e in layout]
        self._seqs = array("q")
        self._times = array("d")
        self._batch: list[dict] = []
        self._blocks: dict[str, list[np.ndarray]] = {n: [] for n in self._names}
        self._present: dict[str, list[np.ndarray]] = {n: [] for n in self._names}

    def add(self, m: Message) -> None:
        msg = json.loads(m.data)
        self._seqs.append(m.sequence)
        if "t" in msg:
            t = float(msg["t"])
        else:
            stamp = msg.get("timestamp") or {}
            t = stamp["sec"] + 1e-9 * stamp["nsec"] if "sec" in stamp and "nsec" in stamp else float("nan")
        self._times.append(t)
        self._batch.append(msg)
        if len(self._batch) >= _BATCH:
            self._decode()

    def _decode(self) -> None:
        batch, self._batch = self._batch, []
        for name in self._names:
            has = np.fromiter((name in msg for msg in batch), dtype=bool, count=len(batch))
            vals = [msg[name] for msg in batch if name in msg]
            self._present[name].append(has)
            if vals:
                arr = np.asarray(vals)
                if arr.dtype == object:  # null (NaN) among the values
                    arr = np.array(vals, dtype=float)
                self._blocks[name].append(arr)

    def finish(self) -> None:
        if self._batch:
            self._decode()
        self.seqs = np.frombuffer(self._seqs, dtype=np.int64) if len(self._seqs) else np.zeros(0, np.int64)
        self.times = np.frombuffer(self._times, dtype=float) if len(self._times) else np.zeros(0)

    def unique_seqs(self) -> np.ndarray:
        return np.unique(self.seqs)

    def pick(self, keep: np.ndarray) -> np.ndarray:
        """Indices of this channel's first message of each sequence in ``keep`` (sorted)."""
        uniq, first = np.unique(self.seqs, return_index=True)
        return first[np.isin(uniq, keep)]

    def values(self, name: str, picked: np.ndarray) -> np.ndarray | None:
        """The values of ``name`` in the picked messages that have it (None: none has)."""
        blocks = self._blocks[name]
        if not blocks:
            return None
        has = np.concatenate(self._present[name])
        where = np.cumsum(has) - 1  # message index -> index of its value
        idx = where[picked[has[picked]]]
        if not len(idx):
            return None
        vals = blocks[0] if len(blocks) == 1 else np.concatenate(blocks)
        return vals[idx]


def _names(signals) -> list[str]:
    if isinstance(signals, str):
        return [signals]
    names = list(signals)
    bad = [n for n in names if not isinstance(n, str)]
    if bad:
        raise TypeError(f"signals: {bad[0]!r} is not a signal name (a str)")
    return names


def _as_logged(arr: np.ndarray | None, dtype: str, shape: tuple) -> np.ndarray:
    """A signal's decoded values with its logged dtype and shape (an empty array: none)."""
    want = np.dtype(dtype)
    if arr is None:
        return np.zeros((0,) + shape, dtype=want)
    if len(shape) > 1 and arr.ndim == 2 and arr.shape[1] == int(np.prod(shape)):
        arr = arr.reshape((len(arr),) + shape)
    if want.kind == "b":
        arr = arr.astype(bool)
    elif want.kind == "f" and arr.dtype.kind == "f" and arr.dtype != want:
        arr = arr.astype(want)
    return arr


def read_log(path: str | os.PathLike, as_dataframe: bool = False, signals=None) -> LogData:
    """Read a log written by :class:`McapRecorder` (complete, or cut off by ``kill -9``).

    ``signals``: the names of the signals to read (an iterable; None: all). Only those are
    kept (a name the log does not have is simply absent from the result), which bounds the
    memory of a reader that needs a few signals of a long log (the plots, the video:
    :data:`PLOT_SIGNALS` in :mod:`uvms_mj.analysis.plots`); the sample times and the complete
    samples are the same as with every signal read.

    ``as_dataframe=True``: the per-sample signals as a pandas DataFrame instead, indexed by the
    sample time ``t`` [s], one column per signal component named by joint, axis and thruster
    (``q_true[alpha_shoulder]``, ``thrust_force[bluerov2_t1]``, ``tip_true[z]``; ``x[i]`` where a
    name is unknown), the metadata in ``df.attrs["meta"]`` (:func:`uvms_mj.io.export.to_dataframe`;
    needs pandas, ``pip install 'uvms-mj[export]'``).

    Returns a :class:`LogData` with the sample times, the signals (the same names, order,
    shapes and dtypes as the run's :class:`RunResult`; only samples whose every per-sample
    message was flushed), the status and reason from the status record ("truncated" when it
    is missing from a cut-off log) and ``meta``: the ``uvms_mj`` metadata (the caller's dict,
    versions, git commit, robot parameters...), plus the keys of the status record's extra
    ``meta`` (e.g. the RunResult's T, dt, seed, controller) that it does not already have,
    plus ``T`` (inferred from the sample times if recorded nowhere).
    """
    head = check_log_file(path)  # a FIFO, device, foreign or empty file: LogFileError, one line
    wanted = None if signals is None else frozenset(_names(signals))
    state: dict = {}
    channels: dict[int, Channel] = {}
    metas: dict[str, dict] = {}
    columns: dict[int, _Columns] = {}  # sample channel id -> its messages, decoded a batch at a time
    early: dict[int, list[Message]] = {}  # messages met before their channel record (none from our writer)
    for r in _iter_records(path, state):
        if isinstance(r, Message):
            col = columns.get(r.channel_id)
            if col is not None:
                col.add(r)
            elif r.channel_id not in channels:
                early.setdefault(r.channel_id, []).append(r)
        elif isinstance(r, Channel):
            if r.id not in channels:
                channels[r.id] = r
                before = early.pop(r.id, [])
                if r.topic in SAMPLE_TOPICS and "uvms_mj.signals" in r.metadata:
                    columns[r.id] = _Columns(json.loads(r.metadata["uvms_mj.signals"]), wanted)
                    for m in before:
                        columns[r.id].add(m)
        elif isinstance(r, Metadata):
            metas.setdefault(r.name, _decode_meta(r.metadata))
    truncated = state["truncated"]
    check_log_content(path, head, len(columns), METADATA_NAME in metas)
    scan = {"metadata": metas}
    sample = [(cid, columns[cid]) for cid in channels if cid in columns]  # in the order of the channel records
    for _, col in sample:
        col.finish()
    keep = None
    for _, col in sample:
        keep = col.unique_seqs() if keep is None else np.intersect1d(keep, col.unique_seqs())
    keep = np.zeros(0, dtype=np.int64) if keep is None else keep
    order = sorted((e["index"], e["name"], e["dtype"], tuple(e["shape"]), cid)
                   for cid, col in sample for e in col.layout)
    picks = {cid: col.pick(keep) for cid, col in sample}  # per channel: its message of each kept sequence
    times = sample[0][1].times[picks[sample[0][0]]] if sample else np.zeros(0)
    out: dict[str, np.ndarray] = {}
    for _, name, dtype, shape, cid in order:
        out[name] = _as_logged(columns[cid].values(name, picks[cid]), dtype, shape)
    t = np.asarray(times, dtype=float)
    status, reason, extra = _status(scan, truncated, float(t[-1]) if len(t) else None)
    meta = dict(scan["metadata"].get(METADATA_NAME, {}))
    for key, value in extra.items():  # the creation-time metadata wins on a clash
        meta.setdefault(key, value)
    if "T" not in meta and len(t) > 1:
        meta["T"] = float(np.median(np.diff(t)))
    log = LogData(t=t, signals=out, status=status, reason=reason, meta=meta, truncated=truncated, path=str(path))
    if as_dataframe:
        from uvms_mj.io.export import to_dataframe

        return to_dataframe(log)
    return log


#: Samples per block given by :func:`iter_samples` by default.
CHUNK_SAMPLES = 4096


@dataclass
class SampleBlock:
    """Consecutive complete samples of a log (:func:`iter_samples`): ``t`` (n,) [s] and
    ``signals`` (name -> array of n rows, the logged dtype and shape, the log's order)."""

    t: np.ndarray
    signals: dict[str, np.ndarray]


@dataclass
class LogStream:
    """What :func:`iter_samples` learns of a log besides its samples: ``layout`` (signal name ->
    (dtype, shape), the log's order; known once the first block is given, or at the end),
    ``meta``, ``status``, ``reason``, ``truncated`` and ``samples`` (given so far); ``meta``,
    ``status``, ``reason`` and ``truncated`` are final once the iteration is exhausted (the
    status record is the log's last record). ``max_in_flight``: the most samples held at once
    (pending and assembled), what bounds the reader's memory."""

    path: str = ""
    layout: dict = None  # type: ignore[assignment]
    meta: dict = None  # type: ignore[assignment]
    status: str = "unknown"
    reason: str = ""
    truncated: bool = False
    samples: int = 0
    max_in_flight: int = 0


def iter_samples(path: str | os.PathLike, signals=None, chunk: int = CHUNK_SAMPLES,
                 stream: LogStream | None = None) -> Iterator[SampleBlock]:
    """The complete samples of a log in blocks of at most ``chunk`` samples, in file order,
    holding at most about ``chunk`` samples (and one MCAP chunk) in memory at a time: what
    :func:`read_log` gives, cut into pieces (the same times, signals, dtypes and shapes; the
    blocks concatenated are :func:`read_log`'s arrays). ``signals``: as in :func:`read_log`.
    ``stream``: a :class:`LogStream` filled with the layout, metadata and status.

    A sample is complete when every sample channel has its message (its sequence number); our
    writer registers the sample channels before the first sample and writes each sample's
    messages together, in increasing sequence, which is what this assumes: a sample still
    incomplete when a later one completes is dropped (read_log would drop it too), a message
    whose sequence is not above the last completed one is ignored (the first message of a
    sequence wins, as in read_log)."""
    if chunk < 1:
        raise ValueError(f"chunk = {chunk!r}: at least 1 sample")
    file_head = check_log_file(path)  # a FIFO, device, foreign or empty file: LogFileError, one line
    wanted = None if signals is None else frozenset(_names(signals))
    st = stream if stream is not None else LogStream()
    st.path, st.meta, st.samples, st.max_in_flight = str(path), {}, 0, 0
    state: dict = {}
    channels: dict[int, Channel] = {}
    metas: dict[str, dict] = {}
    layouts: dict[int, list[dict]] = {}  # sample channel id -> its (wanted) layout
    pending: dict[int, dict[int, Message]] = {}  # sample channel id -> sequence -> message
    ready: list[tuple[Message, ...]] = []
    last = -1  # the last completed sequence
    order: list[tuple] = []
    t_end = None
    head: list[float] = []  # the first sample times (T, when recorded nowhere)
    for r in _iter_records(path, state):
        if isinstance(r, Message):
            box = pending.get(r.channel_id)
            seq = r.sequence
            if box is None or seq <= last or seq in box:
                continue
            box[seq] = r
            if any(seq not in b for b in pending.values()):
                continue
            ready.append(tuple(pending[cid].pop(seq) for cid in layouts))
            last = seq
            for b in pending.values():  # older incomplete samples never complete (in-order writes)
                for old in [k for k in b if k < seq]:
                    del b[old]
            st.max_in_flight = max(st.max_in_flight, len(ready) + sum(len(b) for b in pending.values()))
            if len(ready) >= chunk:
                if not order:
                    order = _block_order(layouts, st)
                block = _block(ready, layouts, order)
                t_end = float(block.t[-1])
                if len(head) < CHUNK_SAMPLES:
                    head.extend(block.t[:CHUNK_SAMPLES].tolist())
                yield block
                st.samples += len(ready)
                ready = []
        elif isinstance(r, Channel):
            if r.id not in channels:
                channels[r.id] = r
                if r.topic in SAMPLE_TOPICS and "uvms_mj.signals" in r.metadata and last < 0:
                    layouts[r.id] = [e for e in json.loads(r.metadata["uvms_mj.signals"])
                                     if wanted is None or e["name"] in wanted]
                    pending[r.id] = {}
        elif isinstance(r, Metadata):
            metas.setdefault(r.name, _decode_meta(r.metadata))
            if r.name == METADATA_NAME:
                st.meta = dict(metas[METADATA_NAME])
    if not order:
        order = _block_order(layouts, st)
    check_log_content(path, file_head, len(layouts), METADATA_NAME in metas)
    if ready:
        block = _block(ready, layouts, order)
        t_end = float(block.t[-1])
        if len(head) < CHUNK_SAMPLES:
            head.extend(block.t[:CHUNK_SAMPLES].tolist())
        yield block
        st.samples += len(ready)
    st.truncated = state["truncated"]
    st.status, st.reason, extra = _status({"metadata": metas}, st.truncated, t_end)
    meta = dict(metas.get(METADATA_NAME, {}))
    for key, value in extra.items():
        meta.setdefault(key, value)
    if "T" not in meta and len(head) > 1:  # as read_log (from the first samples' spacing)
        meta["T"] = float(np.median(np.diff(head)))
    st.meta = meta


def _block_order(layouts: dict[int, list[dict]], st: LogStream) -> list[tuple]:
    """(index in the sample's messages, name, dtype, shape) of every signal, in the log's order."""
    order = sorted((e["index"], e["name"], e["dtype"], tuple(e["shape"]), k)
                   for k, layout in enumerate(layouts.values()) for e in layout)
    st.layout = {name: (dtype, shape) for _, name, dtype, shape, _ in order}
    return [(k, name, dtype, shape) for _, name, dtype, shape, k in order]


def _block(ready: list[tuple[Message, ...]], layouts: dict[int, list[dict]], order: list[tuple]) -> SampleBlock:
    cols = []
    for k, layout in enumerate(layouts.values()):
        col = _Columns(layout)
        for msgs in ready:
            col.add(msgs[k])
        col.finish()
        cols.append(col)
    every = np.arange(len(ready))
    t = np.asarray(cols[0].times, dtype=float) if cols else np.zeros(0)
    signals = {name: _as_logged(cols[k].values(name, every), dtype, shape) for k, name, dtype, shape in order}
    return SampleBlock(t=t.copy(), signals=signals)


def log_info(path: str | os.PathLike) -> dict:
    """Summary of a log: metadata, status, truncation, channels (schema, encodings, message
    counts), time range and number of complete samples. Works on truncated logs. One streaming
    pass that decodes no message (per message it keeps its sequence and log time: 16 bytes)."""
    head = check_log_file(path)
    state: dict = {}
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    metas: dict[str, dict] = {}
    counts: dict[int, int] = {}
    t_min = t_max = None
    seqs: dict[int, array] = {}  # sample channel id -> sequences, in file order
    stamps: dict[int, array] = {}  # and their log times [ns]
    early: dict[int, list[tuple[int, int]]] = {}  # sample messages met before their channel record
    for r in _iter_records(path, state):
        if isinstance(r, Message):
            cid = r.channel_id
            counts[cid] = counts.get(cid, 0) + 1
            lt = r.log_time
            t_min = lt if t_min is None or lt < t_min else t_min
            t_max = lt if t_max is None or lt > t_max else t_max
            if cid in seqs:
                seqs[cid].append(r.sequence)
                stamps[cid].append(lt)
            elif cid not in channels:
                early.setdefault(cid, []).append((r.sequence, lt))
        elif isinstance(r, Channel):
            if r.id not in channels:
                channels[r.id] = r
                before = early.pop(r.id, [])
                if r.topic in SAMPLE_TOPICS and "uvms_mj.signals" in r.metadata:
                    seqs[r.id] = array("q", [q for q, _ in before])
                    stamps[r.id] = array("q", [lt for _, lt in before])
        elif isinstance(r, Schema):
            schemas.setdefault(r.id, r)
        elif isinstance(r, Metadata):
            metas.setdefault(r.name, _decode_meta(r.metadata))
    truncated = state["truncated"]
    check_log_content(path, head, len(seqs), METADATA_NAME in metas)
    scan = {"metadata": metas}
    sample_chs = [(channels[cid], json.loads(channels[cid].metadata["uvms_mj.signals"])) for cid in seqs]
    complete = None
    for cid in seqs:
        u = np.unique(np.frombuffer(seqs[cid], dtype=np.int64)) if len(seqs[cid]) else np.zeros(0, np.int64)
        complete = u if complete is None else np.intersect1d(complete, u)
    complete = np.zeros(0, np.int64) if complete is None else complete
    out_channels = []
    for cid, ch in sorted(channels.items()):
        sc = schemas.get(ch.schema_id)
        out_channels.append({"topic": ch.topic, "schema": sc.name if sc else "",
                             "schema_encoding": sc.encoding if sc else "",
                             "message_encoding": ch.message_encoding, "messages": counts.get(cid, 0)})
    sample_times = []
    if sample_chs and len(complete):
        first = next(iter(seqs))
        sq = np.frombuffer(seqs[first], dtype=np.int64)
        ts = np.frombuffer(stamps[first], dtype=np.int64)
        uniq, idx = np.unique(sq, return_index=True)  # the first message of each sequence
        at = ts[idx[np.searchsorted(uniq, complete[[0, -1]])]]
        sample_times = [int(at[0]) * 1e-9, int(at[1]) * 1e-9]
    status, reason, extra = _status(scan, truncated, sample_times[-1] if sample_times else None)
    start = t_min * 1e-9 if t_min is not None else None
    end = t_max * 1e-9 if t_max is not None else None
    return {
        "path": str(path),
        "size_bytes": os.path.getsize(path),
        "truncated": truncated,
        "status": status,
        "reason": reason,
        "metadata": metas.get(METADATA_NAME, {}),
        "status_record": metas.get(STATUS_NAME, {}),
        "channels": out_channels,
        "start_time": start,
        "end_time": end,
        "duration": (end - start) if start is not None else 0.0,
        "samples": int(len(complete)),
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
