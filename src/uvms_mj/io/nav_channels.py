"""The navigation sensors' MCAP channels (:mod:`uvms_mj.sim.navsensors`) and reading them back.

Each sample is one message whose ``timestamp`` (and field ``t``) is its MEASUREMENT time and
whose MCAP ``log_time`` / ``publish_time`` is its ARRIVAL time (field ``t_arrival``), so that
Foxglove plays it when the controller would get it. JSON messages with JSON schemas (as every
channel of the log; ``null``: none / NaN):

==========================  ======================  ===========================================
topic                       schema                  fields
==========================  ======================  ===========================================
``/navigation/imu``         uvms_mj.ImuSample       ``acc`` (specific force [m/s^2]) and ``gyro``
                                                    ([rad/s]) in the IMU site's frame, the true
                                                    biases ``gyro_bias_true``, ``accel_bias_true``
``/navigation/dvl``         uvms_mj.DvlSample       ``velocity`` (over ground, DVL site frame
                                                    [m/s]; null: dropout), ``valid`` (0/1),
                                                    ``beams_valid`` (0/1 each), ``ranges`` [m]
                                                    (null: no hit), ``altitude`` [m]
``/navigation/depth``       uvms_mj.DepthSample     ``depth`` [m] (positive down), ``pressure``
                                                    (gauge [Pa])
``/navigation/fix``         foxglove.PoseInFrame    the fix in ``world`` (orientation: the yaw
                                                    when the fix has one, else identity)
``/navigation/fix/sample``  uvms_mj.FixSample       ``position`` world [m], ``yaw`` [rad] or null,
                                                    ``outlier`` (0/1, the truth)
==========================  ======================  ===========================================

Every message also has ``frame_id``: the sensor's site (``world`` for fixes). The mounts (site
pose in the vehicle body frame) are in the status record's ``navigation`` entry.
:func:`read_navigation` reads the channels back into a
:class:`~uvms_mj.sim.navsensors.NavigationRecord`.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from uvms_mj.io.encoding import _dumps, _stamp

__all__ = ["NAV_TOPICS", "NavigationChannels", "read_navigation"]

TOPIC_IMU = "/navigation/imu"
TOPIC_DVL = "/navigation/dvl"
TOPIC_DEPTH = "/navigation/depth"
TOPIC_FIX = "/navigation/fix"
TOPIC_FIX_SAMPLE = "/navigation/fix/sample"
NAV_TOPICS = (TOPIC_IMU, TOPIC_DVL, TOPIC_DEPTH, TOPIC_FIX, TOPIC_FIX_SAMPLE)


def _n(desc: str = "") -> dict:
    return {"type": "number", **({"description": desc} if desc else {})}


def _v(n: int, desc: str, item: str = "number", nullable: bool = False) -> dict:
    return {"type": ["array", "null"] if nullable else "array", "items": {"type": [item, "null"]}, "minItems": n,
            "maxItems": n, "description": desc}


def _schema(title: str, desc: str, props: dict) -> dict:
    from uvms_mj.io.schemas import _time_schema

    base = {"timestamp": _time_schema(), "t": _n("measurement time [s]"),
            "t_arrival": _n("arrival time [s] (the MCAP log time)"), "frame_id": {"type": "string"}}
    return {"title": title, "type": "object", "description": desc, "properties": {**base, **props}}


def _schemas(nbeams: int = 4) -> dict:
    from uvms_mj.io.schemas import _pose, _time_schema

    return {
        "uvms_mj.ImuSample": _schema("uvms_mj.ImuSample", "IMU sample, IMU site frame", {
            "acc": _v(3, "specific force [m/s^2]"), "gyro": _v(3, "angular velocity [rad/s]"),
            "gyro_bias_true": _v(3, "true gyro bias [rad/s]"), "accel_bias_true": _v(3, "true accel bias [m/s^2]")}),
        "uvms_mj.DvlSample": _schema("uvms_mj.DvlSample", "DVL ping: velocity over ground, DVL site frame", {
            "valid": {"type": "integer"}, "velocity": _v(3, "[m/s]; null: dropout", nullable=True),
            "beams_valid": _v(nbeams, "0/1 per beam", "integer"), "ranges": _v(nbeams, "slant range [m]; null: no hit"),
            "altitude": {"type": ["number", "null"], "description": "[m] along the boresight"}}),
        "uvms_mj.DepthSample": _schema("uvms_mj.DepthSample", "depth from pressure", {
            "depth": _n("[m], positive down"), "pressure": _n("gauge pressure [Pa]")}),
        "uvms_mj.FixSample": _schema("uvms_mj.FixSample", "position fix (USBL / camera)", {
            "site": {"type": "string"}, "position": _v(3, "world [m]"),
            "yaw": {"type": ["number", "null"], "description": "world [rad]"}, "outlier": {"type": "integer"}}),
        "foxglove.PoseInFrame": {"title": "foxglove.PoseInFrame", "type": "object", "properties": {
            "timestamp": _time_schema(),
            "frame_id": {"type": "string"}, "pose": _pose()}, "description": "A timestamped pose in a named frame"},
    }


def _list(x) -> list | None:
    if x is None:
        return None
    return [float(v) if math.isfinite(float(v)) else None for v in np.asarray(x, dtype=float).ravel()]


class NavigationChannels:
    """The recorder's part for the navigation channels (a base of
    :class:`uvms_mj.io.writer.McapRecorder`: it needs ``_channel`` and ``_writer``)."""

    def write_navigation(self, kind: str, sample: Any, extra: dict) -> None:
        """Record one navigation sample (the loop's ``nav_sink``); written at the next flush."""
        if getattr(self, "closed", False):
            raise RuntimeError("recorder is closed")
        proc = self.__dict__.get("_proc")
        pend = proc.navs if proc is not None else self.__dict__.setdefault("_nav_pending", [])
        pend.append((kind, sample, dict(extra)))

    def _write_navigation(self) -> None:
        pend = self.__dict__.get("_nav_pending")
        if not pend:
            return
        self._nav_pending = []
        ids = self.__dict__.setdefault("_nav_ids", {})
        seq = self.__dict__.setdefault("_nav_seq", {})
        schemas = None
        for kind, s, extra in pend:
            t = float(s.t)
            ta = float(extra.get("t_arrival", getattr(s, "t_arrival", t)))
            site = str(extra.get("site", kind))
            head = {"timestamp": _stamp(int(round(t * 1e9))), "t": t, "t_arrival": ta, "frame_id": site}
            msgs = []
            if kind == "imu":
                msgs.append((TOPIC_IMU, "uvms_mj.ImuSample", {
                    **head, "acc": _list(s.acc), "gyro": _list(s.gyro), "gyro_bias_true": _list(extra.get("gyro_bias")),
                    "accel_bias_true": _list(extra.get("accel_bias"))}))
            elif kind == "dvl":
                msgs.append((TOPIC_DVL, "uvms_mj.DvlSample", {
                    **head, "valid": int(s.velocity is not None), "velocity": _list(s.velocity),
                    "beams_valid": [int(b) for b in s.beams_valid], "ranges": extra.get("ranges", []),
                    "altitude": extra.get("altitude")}))
            elif kind == "depth":
                msgs.append((TOPIC_DEPTH, "uvms_mj.DepthSample", {**head, "depth": float(s.depth),
                                                                  "pressure": float(extra.get("pressure", 0.0))}))
            elif kind == "fix":
                p = _list(s.position)
                yaw = None if s.yaw is None else float(s.yaw)
                half = 0.0 if yaw is None else 0.5 * yaw
                msgs.append((TOPIC_FIX, "foxglove.PoseInFrame", {
                    "timestamp": head["timestamp"], "frame_id": "world", "pose": {
                        "position": {"x": p[0], "y": p[1], "z": p[2]},
                        "orientation": {"x": 0.0, "y": 0.0, "z": math.sin(half), "w": math.cos(half)}}}))
                msgs.append((TOPIC_FIX_SAMPLE, "uvms_mj.FixSample", {
                    **head, "frame_id": "world", "site": site, "position": p, "yaw": yaw,
                    "outlier": int(bool(extra.get("outlier", False)))}))
            ns = int(round(ta * 1e9))
            for topic, name, msg in msgs:
                if topic not in ids:
                    schemas = schemas or _schemas(len(getattr(s, "beams_valid", ())) or 4)
                    ids[topic] = self._channel(topic, name, schemas[name], {"uvms_mj.site": site})
                k = seq.get(topic, 0)
                seq[topic] = k + 1
                self._writer.add_message(ids[topic], ns, _dumps(msg), ns, k)


def read_navigation(path: str | Path):
    """The navigation channels of a log as a :class:`~uvms_mj.sim.navsensors.NavigationRecord`
    (samples in log order; the mounts from the status record when present)."""
    from uvms_mj.estimation.measurements import DepthSample, DvlSample, FixSample, ImuSample, Mount
    from uvms_mj.io.reader import iter_messages
    from uvms_mj.sim.navsensors import NavigationRecord

    rec = NavigationRecord()
    arr = lambda x: np.asarray([np.nan if v is None else v for v in x], dtype=float)  # noqa: E731
    for topic, msg in _nav_messages(path, iter_messages):
        if topic == TOPIC_IMU:
            rec.imu.append(ImuSample(t=msg["t"], acc=arr(msg["acc"]), gyro=arr(msg["gyro"])))
            rec.imu_arrival.append(msg["t_arrival"])
            rec.imu_gyro_bias.append(arr(msg["gyro_bias_true"] or [np.nan] * 3))
            rec.imu_accel_bias.append(arr(msg["accel_bias_true"] or [np.nan] * 3))
        elif topic == TOPIC_DVL:
            v = msg["velocity"]
            rec.dvl.append(DvlSample(t=msg["t"], t_arrival=msg["t_arrival"], velocity=None if v is None else arr(v),
                                     beams_valid=tuple(bool(b) for b in msg["beams_valid"])))
            rec.dvl_ranges.append(arr(msg["ranges"]))
        elif topic == TOPIC_DEPTH:
            rec.depth.append(DepthSample(t=msg["t"], t_arrival=msg["t_arrival"], depth=msg["depth"]))
        elif topic == TOPIC_FIX_SAMPLE:
            rec.fix.append(FixSample(t=msg["t"], t_arrival=msg["t_arrival"], position=arr(msg["position"]),
                                     yaw=msg["yaw"]))
            rec.fix_outlier.append(bool(msg["outlier"]))
    try:
        from uvms_mj.io.reader import read_log

        nav = (read_log(path).meta or {}).get("navigation") or {}
    except Exception:  # noqa: BLE001 - a log without a readable status record: no mounts
        nav = {}
    for kind, m in nav.items():
        rec.mounts[kind] = Mount(position=np.asarray(m["position"], dtype=float),
                                 quat=np.asarray(m["quat"], dtype=float))
        rec.sites[kind] = m["site"]
    return rec


def _nav_messages(path, iter_messages):
    for ch, _, msg in iter_messages(path):
        if ch.topic in NAV_TOPICS:
            yield ch.topic, json.loads(msg.data)
