"""Reading logs back: :func:`read_log` (a :class:`LogData`, usable wherever a RunResult is, also
from a log cut short by ``kill -9``), :func:`iter_messages`, :func:`log_info` and
:func:`format_info`."""

from __future__ import annotations

import io
import json
import os
import struct
from dataclasses import dataclass
from typing import Any, Iterator, Mapping

import numpy as np
from mcap.exceptions import McapError
from mcap.records import Channel, Chunk, Message, Metadata, Schema
from mcap.stream_reader import StreamReader, breakup_chunk

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
    log = LogData(t=t, signals=signals, status=status, reason=reason, meta=meta, truncated=truncated, path=str(path))
    if as_dataframe:
        from uvms_mj.io.export import to_dataframe

        return to_dataframe(log)
    return log


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
