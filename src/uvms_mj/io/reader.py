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


def _records(path: str | os.PathLike) -> tuple[list, bool]:
    """All records of a log in file order (chunks broken up), and whether it was truncated.
    Stops at the first incomplete or corrupt record."""
    state: dict = {}
    out = list(_iter_records(path, state))
    return out, state["truncated"]


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


#: Messages of a sample channel decoded at a time by :func:`read_log` (bounds the JSON objects in memory).
_BATCH = 2048


class _Columns:
    """One sample channel's messages as columns: per message its sequence and time, per signal
    the values (numpy blocks of :data:`_BATCH` messages, converted as one list each) and whether
    the message had it. Memory: the arrays plus one batch of decoded JSON."""

    def __init__(self, layout: list[dict]) -> None:
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



def read_log(path: str | os.PathLike, as_dataframe: bool = False) -> LogData:
    """Read a log written by :class:`McapRecorder` (complete, or cut off by ``kill -9``).

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
                    columns[r.id] = _Columns(json.loads(r.metadata["uvms_mj.signals"]))
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
    signals: dict[str, np.ndarray] = {}
    for _, name, dtype, shape, cid in order:
        want = np.dtype(dtype)
        arr = columns[cid].values(name, picks[cid])
        if arr is None:
            signals[name] = np.zeros((0,) + shape, dtype=want)
            continue
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
    log = LogData(t=t, signals=signals, status=status, reason=reason, meta=meta, truncated=truncated, path=str(path))
    if as_dataframe:
        from uvms_mj.io.export import to_dataframe

        return to_dataframe(log)
    return log


def log_info(path: str | os.PathLike) -> dict:
    """Summary of a log: metadata, status, truncation, channels (schema, encodings, message
    counts), time range and number of complete samples. Works on truncated logs."""
    head = check_log_file(path)
    recs, truncated = _records(path)
    scan = _scan(recs)
    sample_chs = _sample_channels(scan)
    check_log_content(path, head, len(sample_chs), METADATA_NAME in scan["metadata"])
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
