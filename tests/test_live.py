"""`uvms-mj run --live`: the run streamed over Foxglove's WebSocket protocol (uvms_mj.io.live).

A WebSocket client (the `websockets` package, a dependency of mujoco) speaks the protocol itself
(subprotocol ``foxglove.sdk.v1``: JSON ``serverInfo`` / ``advertise`` from the server, a JSON
``subscribe`` from the client, binary message frames: opcode 0x01, subscription id u32, log time
u64 ns, the message) against the CLI in a subprocess, and checks what it decodes against the run's
own log and the paper robot's frames."""

from __future__ import annotations

import json
import os
import select
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from uvms_mj.cli.main import main as cli
from uvms_mj.io import live as live_mod

SRC = Path(__file__).resolve().parents[1] / "src"


def _read_line(proc, prefix: str, timeout: float) -> str:
    """The first stderr line of ``proc`` starting with ``prefix`` (the others are kept for the report)."""
    seen, buf, end = [], b"", time.monotonic() + timeout
    fd = proc.stderr.fileno()
    while time.monotonic() < end:
        ready, _, _ = select.select([fd], [], [], 0.5)
        if not ready:
            if proc.poll() is not None:
                break
            continue
        chunk = os.read(fd, 4096)
        if not chunk:
            break
        buf += chunk
        *lines, buf = buf.split(b"\n")
        for line in lines:
            text = line.decode(errors="replace")
            if text.startswith(prefix):
                return text
            seen.append(text)
    raise AssertionError(f"no {prefix!r} line on stderr; got: {seen + [buf.decode(errors='replace')]}")


def _stream(tmp_path, scenario: str, duration: float, wanted: set[str]):
    """`run SCENARIO --live --pace fast` in a subprocess and a client subscribed to the ``wanted``
    topics until the run ends: (log path, {subscription id: advertised channel}, [(topic, log time
    [ns], decoded JSON message)] in arrival order)."""
    pytest.importorskip("foxglove", reason="foxglove-sdk (the [live] extra) is not installed")
    ws_client = pytest.importorskip("websockets.sync.client")
    out = tmp_path / "live.mcap"
    env = dict(os.environ, PYTHONPATH=str(SRC) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    # --live-wait: the run starts when the client has subscribed (or after 60 s: the test then fails on the count)
    cmd = [sys.executable, "-m", "uvms_mj.cli.main", "run", scenario, "--set", f"duration={duration}", "-o", str(out),
           "--no-plots", "--no-video", "--live", "--live-port", "0", "--live-wait", "60", "--pace", "fast"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    try:
        url = _read_line(proc, "live: ", 120).split()[1]
        assert url.startswith("ws://127.0.0.1:")
        frames, channels = [], {}
        with ws_client.connect(url, subprotocols=["foxglove.sdk.v1"], open_timeout=30) as ws:
            assert ws.subprotocol == "foxglove.sdk.v1"
            info = json.loads(ws.recv(timeout=30))
            assert info["op"] == "serverInfo" and "time" in info["capabilities"]
            while not wanted <= {c["topic"] for c in channels.values()}:
                msg = ws.recv(timeout=60)
                if isinstance(msg, str) and json.loads(msg)["op"] == "advertise":
                    for c in json.loads(msg)["channels"]:
                        channels[c["id"]] = c
            subs = {i: c for i, c in enumerate(c for c in channels.values() if c["topic"] in wanted)}
            ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": i, "channelId": c["id"]}
                                                                     for i, c in subs.items()]}))
            try:
                while True:  # until the run ends (the server stops)
                    msg = ws.recv(timeout=60)
                    if isinstance(msg, bytes) and msg[0] == 0x01:
                        sub, log_time = struct.unpack_from("<IQ", msg, 1)
                        frames.append((subs[sub]["topic"], log_time, json.loads(msg[13:])))
                    elif isinstance(msg, str) and "Unknown channel ID" in msg:
                        # foxglove-sdk 0.30.3 advertises a channel a moment before it accepts subscriptions
                        # to it (seen here for about 1 run in 12: {"op":"status","level":2,"message":"Unknown
                        # channel ID: 5"}): subscribe again, as a robust client does (the server re-sends
                        # the scene to a new subscriber)
                        cid = int(json.loads(msg)["message"].rsplit(":", 1)[1])
                        ws.send(json.dumps({"op": "subscribe", "subscriptions": [
                            {"id": i, "channelId": c["id"]} for i, c in subs.items() if c["id"] == cid]}))
            except Exception as exc:  # ConnectionClosed at the end of the run
                assert "ConnectionClosed" in type(exc).__name__, repr(exc)
        assert proc.wait(timeout=60) == 0, proc.stderr.read().decode()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return out, subs, frames


def _check_channels(out, subs) -> None:
    """The advertised channels are the log's: topic, schema name, schema, encodings."""
    from mcap.reader import make_reader

    with open(out, "rb") as f:
        summary = make_reader(f).get_summary()
    logged = {ch.topic: (ch, summary.schemas[ch.schema_id]) for ch in summary.channels.values()}
    for c in subs.values():
        ch, schema = logged[c["topic"]]
        assert (c["encoding"], c["schemaName"], c["schemaEncoding"]) == (ch.message_encoding, schema.name,
                                                                          schema.encoding)
        assert json.loads(c["schema"]) == json.loads(schema.data)


def test_live_stream_decoded_against_the_log(tmp_path):
    from uvms_mj.io.recorder import read_log

    out, subs, frames = _stream(tmp_path, "paper", 0.5, {"/tf", "/joint_states", "/scene"})
    _check_channels(out, subs)
    log = read_log(out)
    n = len(log.t)
    assert n == 31  # 0.5 s at the paper's T = 1/60 s, both ends
    tf = [(lt, m) for topic, lt, m in frames if topic == "/tf"]
    js = [(lt, m) for topic, lt, m in frames if topic == "/joint_states"]
    # fast pace, one client, 3 channels x 31 samples: far below the server's 1024-message backlog, nothing dropped
    assert len(tf) == len(js) == n
    assert [lt for lt, _ in tf] == [round(t * 1e9) for t in log.t]  # log time = simulation time [ns]
    assert any(topic == "/scene" for topic, _, _ in frames)
    q = log.signals["q_true"]
    for k in (0, n // 2, n - 1):
        lt, m = tf[k]
        stamp = m["transforms"][0]["timestamp"]
        assert stamp["sec"] * 10**9 + stamp["nsec"] == lt
        chain = [(x["parent_frame_id"], x["child_frame_id"]) for x in m["transforms"]]
        assert chain == [("view", "world"), ("world", "base"), ("base", "link1"), ("link1", "link2"), ("link2", "tip")]
        base = m["transforms"][1]
        # the base frame: position (x, y) = q_true[0:2], a rotation about +z by q_true[2]
        # (tolerance 1e-12: JSON carries float64 repr, the half-angle sin/cos round once)
        np.testing.assert_allclose([base["translation"]["x"], base["translation"]["y"]], q[k, 0:2], rtol=0, atol=1e-12)
        r = base["rotation"]
        np.testing.assert_allclose(2 * np.arctan2(r["z"], r["w"]), q[k, 2], rtol=0, atol=1e-12)
        lt_j, mj = js[k]
        assert lt_j == lt
        np.testing.assert_allclose([j["position"] for j in mj["joints"]], q[k], rtol=0, atol=0)


def test_live_without_foxglove_sdk_exits_2_in_one_line(monkeypatch, tmp_path):
    monkeypatch.setitem(sys.modules, "foxglove", None)  # import foxglove -> ImportError
    res = CliRunner().invoke(cli, ["run", "paper", "--set", "duration=0.1", "-o", str(tmp_path / "a.mcap"), "--live"])
    assert res.exit_code == 2
    lines = [x for x in res.output.splitlines() if x.strip()]
    assert lines == [f"error: {live_mod.INSTALL_HINT}"]
    assert "pip install" in lines[0]
    assert not (tmp_path / "a.mcap").exists()  # nothing ran


def test_pace_needs_live(tmp_path):
    res = CliRunner().invoke(cli, ["run", "paper", "--pace", "fast", "-o", str(tmp_path / "a.mcap")])
    assert res.exit_code == 2 and "--pace needs --live" in res.output


def test_realtime_pacing_sleeps_to_simulation_time(monkeypatch):
    """pace(t) in realtime: the fake wall clock after each call equals the simulation time since
    the first sample when the run is faster than real time, and is never slowed when it is behind."""
    pytest.importorskip("foxglove", reason="foxglove-sdk (the [live] extra) is not installed")
    clock = [100.0]
    monkeypatch.setattr(live_mod, "_monotonic", lambda: clock[0])
    slept = []

    def sleep(s):
        slept.append(s)
        clock[0] += s

    monkeypatch.setattr(live_mod, "_sleep", sleep)
    with live_mod.LiveServer(port=0, pace="realtime", push_interval=0.05) as srv:
        pushes = []
        for k in range(7):
            t = 2.0 + k * 0.02
            clock[0] += 0.001  # the simulation step itself: 1 ms of wall time per 20 ms sample
            pushes.append(srv.pace(t))
            assert clock[0] - 100.001 == pytest.approx(t - 2.0, abs=1e-12)  # (100.001: the first sample's wall time)
        clock[0] += 1.0  # a slow step (behind real time by 0.88 s): no sleep
        n = len(slept)
        srv.pace(2.14)
        assert len(slept) == n
    assert pushes == [True, False, False, True, False, False, True]  # the first, then after >= 0.05 s (at 0.06, 0.12)
    with pytest.raises(ValueError, match="pace = 'slow'"):
        live_mod.LiveServer(pace="slow")


@pytest.mark.slow  # about 5 s: a subprocess that builds the BlueROV2 + Alpha plant
def test_live_robot_stream_is_the_log(tmp_path):
    """A floating robot (BlueROV2 Heavy + Alpha): every message of the subscribed channels arrives,
    the same (decoded) as the log's message of that topic and log time, stamped with that time."""
    from uvms_mj.io.recorder import iter_messages

    wanted = {"/tf", "/joint_states", "/thrusters", "/scene"}
    out, subs, frames = _stream(tmp_path, "bluerov2_alpha_station", 0.2, wanted)
    _check_channels(out, subs)
    logged = {(ch.topic, m.log_time): json.loads(m.data) for ch, _, m in iter_messages(out) if ch.topic in wanted}
    got = {(topic, lt): m for topic, lt, m in frames}  # (/scene: the first send and the re-send to the new subscriber)
    assert got.keys() == logged.keys()
    assert got == logged
    assert len({lt for topic, lt in got if topic == "/tf"}) == 11  # 0.2 s at the robot's 50 Hz control rate, both ends
    for (topic, lt), m in got.items():
        stamps = [x["timestamp"] for x in m["transforms"]] if topic == "/tf" else (
            [m["timestamp"]] if topic in ("/joint_states", "/thrusters") else [])
        assert all(st["sec"] * 10**9 + st["nsec"] == lt for st in stamps)


class _ListSink:
    """A second sink (uvms_mj.io.sinks.MessageSink) that keeps what it gets; pace(): a send every 5th sample."""

    def __init__(self) -> None:
        self.channels, self.messages, self.paced = {}, [], 0

    def open_channel(self, channel_id, topic, message_encoding, schema_name, schema_encoding, schema_data, metadata):
        assert channel_id not in self.channels
        self.channels[channel_id] = (topic, message_encoding, schema_name, schema_encoding, schema_data, metadata)

    def add_message(self, channel_id, log_time, data):
        assert channel_id in self.channels
        self.messages.append((channel_id, log_time, bytes(data)))

    def add_samples(self, samples):
        for messages, log_time, _ in samples:
            for cid, data in messages:
                assert cid in self.channels
                self.messages.append((cid, log_time, bytes(data)))

    def pace(self, t):
        self.paced += 1
        return self.paced % 5 == 0


def test_second_sink_gets_the_files_channels_and_messages(tmp_path):
    """Without foxglove-sdk: McapRecorder(live=sink) gives the sink every channel of the file (topic,
    encodings, schema, metadata) and every message, in the file's order (uvms_mj.io.sinks.Tee)."""
    from mcap.reader import make_reader

    from uvms_mj.io.recorder import McapRecorder
    from uvms_mj.sim.experiment import PaperExperiment
    from uvms_mj.sim.loop import run_closed_loop

    plant, ctrl = PaperExperiment(duration=0.5).build()
    sink, path = _ListSink(), tmp_path / "tee.mcap"
    with McapRecorder(path, plant.params, {}, live=sink) as rec:
        res = run_closed_loop(plant, ctrl, 0.5, T=ctrl.T, sink=rec.write_sample)
        rec.close(res.status, res.reason, meta=res.meta)
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        file_msgs = [(m.channel_id, m.log_time, m.data) for _, _, m in reader.iter_messages(log_time_order=False)]
    assert sink.paced == len(res.t) == 31
    assert {cid: c[0] for cid, c in sink.channels.items()} == {cid: c.topic for cid, c in summary.channels.items()}
    for cid, (topic, enc, sname, senc, sdata, meta) in sink.channels.items():
        ch = summary.channels[cid]
        schema = summary.schemas[ch.schema_id]
        assert (enc, sname, senc, sdata, meta) == (ch.message_encoding, schema.name, schema.encoding, schema.data,
                                                   ch.metadata)
    assert sink.messages == file_msgs
