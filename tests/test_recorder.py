"""MCAP recorder: exact round trip, Foxglove channels and schemas, truncation (kill -9), clean
close on exceptions and SIGTERM, metadata."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import time
import textwrap
from pathlib import Path

import mujoco
import numpy as np
import pytest
from mcap.reader import make_reader

from uvms_mj.sim.experiment import PaperExperiment, metrics
from uvms_mj.sim.loop import RunResult, run_closed_loop
from oracles.planar.nominal import params_from_file
from uvms_mj.io.recorder import (
    SCHEMAS,
    LogData,
    McapRecorder,
    Terminated,
    format_info,
    handle_sigterm,
    iter_messages,
    log_info,
    read_log,
)

SRC = str(Path(__file__).resolve().parents[1] / "src")


@pytest.fixture(scope="module")
def params():
    return params_from_file()


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """A 2 s paper run recorded through the loop's sink, and its RunResult."""
    path = tmp_path_factory.mktemp("rec") / "run.mcap"
    plant, ctrl = PaperExperiment(duration=2).build()
    meta = {"scenario": {"name": "paper", "duration": 2.0, "gains": [0.3, 0.2]}, "seed": 7}
    with McapRecorder(path, plant.params, meta) as rec:
        result = run_closed_loop(plant, ctrl, 2.0, T=ctrl.T, sink=rec.write_sample)
        rec.close(result.status, result.reason, meta=result.meta)
    return path, result, plant.params, meta


def synthetic_row(k: int, T: float = 1 / 60) -> dict:
    t = k * T
    q = np.array([0.1 * t, -0.05 * t, 0.3 * math.sin(t), 1.0 + 0.2 * t, -0.8 + 0.1 * math.cos(t)])
    return {
        "p_desired": np.r_[q[:3], 0.5 + 0.01 * t, 0.2],
        "det_B": 0.05 * math.sin(q[4]),
        "singular_phase": k % 3,
        "dls_active": bool(k % 2),
        "thrust_saturated": np.array([k % 2 == 0, False, True]),
        "q_true": q,
        "qd_true": np.full(5, 0.01 * k),
        "tip_true": np.array([0.5 + 0.01 * t, 0.2]),
    }


def assert_same_signals(got: dict, want: dict) -> None:
    assert list(got) == list(want)
    for name, a in want.items():
        b = got[name]
        assert b.dtype == a.dtype, name
        assert b.shape == a.shape, name
        assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), name


# ----------------------------------------------------------------------------- round trip


def test_round_trip_is_exact(recorded):
    path, result, _, _ = recorded
    log = read_log(path)
    assert isinstance(log, LogData) and isinstance(log, RunResult)
    assert not log.truncated
    assert (log.status, log.reason) == (result.status, result.reason) == ("ok", "")
    assert np.array_equal(log.t, result.t) and log.t.dtype == result.t.dtype
    # Every signal: same names and order, dtypes, shapes, and values bit for bit (JSON floats
    # are written with repr).
    assert_same_signals(log.signals, result.signals)
    for key, value in result.meta.items():
        if key != "seed":  # the creation-time metadata's seed (7) wins over the run's (0)
            assert log.meta[key] == value
    assert log.meta["seed"] == 7
    # A saved log works where a RunResult does.
    assert metrics(log) == metrics(result)


def test_generic_signals_round_trip(tmp_path, params):
    """Other controllers' signals: ints, bools, float32, 2-D arrays, NaN and +-inf."""
    rows = []
    for k in range(50):
        row = {
            "count": k,
            "ratio": float(k) / 7.0,
            "flag": k % 3 == 0,
            "vec32": np.array([k, k + 0.5], dtype=np.float32),
            "mat": np.arange(6.0).reshape(2, 3) * k,
            "weird": np.array([np.nan if k % 5 == 0 else 1.0, np.inf, -np.inf]),
            "q_true": np.array([0.0, 0.0, 0.1 * k, 0.2, 0.3]),
        }
        rows.append(row)
    with McapRecorder(tmp_path / "g.mcap", params, {}) as rec:
        for k, row in enumerate(rows):
            rec.write_sample(k * 0.01, row)
    want = {}
    for row in rows:  # exactly what run_closed_loop does
        for key, val in row.items():
            want.setdefault(key, []).append(val)
    want = {key: np.asarray(v) for key, v in want.items()}
    log = read_log(tmp_path / "g.mcap")
    assert_same_signals(log.signals, want)
    assert log.meta["T"] == pytest.approx(0.01)
    # The file is strict JSON (no NaN/Infinity tokens): Foxglove's parser accepts it.
    for _, _, msg in iter_messages(tmp_path / "g.mcap"):
        json.loads(msg.data, parse_constant=lambda c: pytest.fail(f"non-JSON constant {c}"))


def test_late_and_non_numeric_signals_are_skipped(tmp_path, params):
    with pytest.warns(UserWarning, match="not numeric"):
        with McapRecorder(tmp_path / "w.mcap", params) as rec:
            rec.write_sample(0.0, {"a": 1.0, "label": "x"})
            with pytest.warns(UserWarning, match="'b' first appeared") as caught:
                rec.write_sample(0.1, {"a": 2.0, "label": "y", "b": 3.0})
                rec.write_sample(0.2, {"a": 3.0, "label": "z", "b": 4.0})
            assert len(caught) == 1  # once per name
    log = read_log(tmp_path / "w.mcap")
    assert list(log.signals) == ["a"] and log.signals["a"].tolist() == [1.0, 2.0, 3.0]


# ----------------------------------------------------------------------------- foxglove channels


def compose(tfs: list[dict], frames: list[str]) -> tuple[np.ndarray, float]:
    """Pose (x, y, angle about +Z) of frames[-1] in frames[0] from planar transforms."""
    by_child = {tf["child_frame_id"]: tf for tf in tfs}
    pos, ang = np.zeros(2), 0.0
    for child in frames[1:]:
        tf = by_child[child]
        r, tr = tf["rotation"], tf["translation"]
        assert r["x"] == 0.0 and r["y"] == 0.0 and tr["z"] == 0.0
        assert math.isclose(r["z"] ** 2 + r["w"] ** 2, 1.0, rel_tol=1e-12)
        c, s = math.cos(ang), math.sin(ang)
        pos = pos + np.array([c * tr["x"] - s * tr["y"], s * tr["x"] + c * tr["y"]])
        ang += 2.0 * math.atan2(r["z"], r["w"])
    return pos, ang


def test_tf_reproduces_the_tip(recorded):
    path, result, _, _ = recorded
    tips, joints = [], []
    for ch, _, msg in iter_messages(path):
        if ch.topic == "/tf":
            tfs = json.loads(msg.data)["transforms"]
            assert [(tf["parent_frame_id"], tf["child_frame_id"]) for tf in tfs] == [
                ("view", "world"), ("world", "base"), ("base", "link1"), ("link1", "link2"), ("link2", "tip")]
            # view -> world: +90 deg about x (world Y up in Foxglove's Z-up view).
            assert tfs[0]["rotation"] == {"x": math.sqrt(0.5), "y": 0.0, "z": 0.0, "w": math.sqrt(0.5)}
            assert all(tf["timestamp"] == tfs[0]["timestamp"] for tf in tfs)
            tfs = tfs[1:]
            assert msg.sequence == len(tips)
            tips.append(compose(tfs, ["world", "base", "link1", "link2", "tip"])[0])
        elif ch.topic == "/joint_states":
            js = json.loads(msg.data)
            assert set(js) == {"timestamp", "joints"}
            assert [j["name"] for j in js["joints"]] == ["base_x", "base_y", "base_phi", "joint1", "joint2"]
            joints.append(([j["position"] for j in js["joints"]], [j["velocity"] for j in js["joints"]]))
    assert len(tips) == len(result.t)
    tips = np.array(tips)
    # The tip of the logged q_true, by MuJoCo's own kinematics: to 1e-9.
    model = PaperExperiment(duration=2).build()[0].model
    data = mujoco.MjData(model)
    tip_id = model.site("tip").id
    for q, tip in zip(result.signals["q_true"], tips, strict=True):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        assert np.max(np.abs(tip - data.site_xpos[tip_id, :2])) < 1e-9
    # and the loop's tip_true (Plant.tip_position, kinematics of the current qpos): to 1e-9.
    assert np.max(np.abs(tips - result.signals["tip_true"])) < 1e-9
    assert np.array_equal([j[0] for j in joints], result.signals["q_true"])
    assert np.array_equal([j[1] for j in joints], result.signals["qd_true"])


def check_schema(value, schema: dict, where: str = "$") -> None:
    """The subset of JSON Schema the recorder's schemas use (jsonschema may be absent)."""
    if "oneOf" in schema:
        matches = [s for s in schema["oneOf"] if "const" in s and s["const"] == value]
        assert len(matches) == 1, f"{where}: {value!r} matches none of oneOf"
        return
    typ = schema.get("type")
    if typ == "object":
        assert isinstance(value, dict), where
        for key in schema.get("required", []):
            assert key in value, f"{where}: missing required {key!r}"
        for key, sub in schema.get("properties", {}).items():
            if key in value:
                check_schema(value[key], sub, f"{where}.{key}")
    elif typ == "array":
        assert isinstance(value, list), where
        assert len(value) >= schema.get("minItems", 0), where
        assert len(value) <= schema.get("maxItems", len(value)), where
        for i, item in enumerate(value):
            check_schema(item, schema["items"], f"{where}[{i}]")
    elif typ == "number":
        assert isinstance(value, (int, float)) and not isinstance(value, bool), where
    elif typ == "integer":
        assert isinstance(value, int) and not isinstance(value, bool), where
    elif typ == "boolean":
        assert isinstance(value, bool), where
    elif typ == "string":
        assert isinstance(value, str), where
    else:
        raise AssertionError(f"{where}: unexpected schema {schema}")
    if "minimum" in schema:
        assert value >= schema["minimum"], where
    if "maximum" in schema:
        assert value <= schema["maximum"], where


def test_channels_schemas_and_messages(recorded):
    path, result, params, _ = recorded
    info = log_info(path)
    n = len(result.t)
    chans = {c["topic"]: c for c in info["channels"]}
    expected = {
        "/tf": ("foxglove.FrameTransforms", n),
        "/scene": ("foxglove.SceneUpdate", 1),
        "/scene/paths": ("foxglove.SceneUpdate", 2),  # at t = 1 s and at close (t = 2 s)
        "/joint_states": ("foxglove.JointStates", n),
        "/state/true": ("uvms_mj.TrueState", n),
        "/control": ("uvms_mj.ControlSample", n),
    }
    assert set(chans) == set(expected)
    for topic, (schema, count) in expected.items():
        c = chans[topic]
        assert (c["schema"], c["schema_encoding"], c["message_encoding"], c["messages"]) == \
            (schema, "jsonschema", "json", count), topic
    # The foxglove.* schemas in the file carry the published schemas' structure.
    with open(path, "rb") as f:
        schemas = {s.name: json.loads(s.data) for s in make_reader(f).get_summary().schemas.values()}
    for name in ("foxglove.FrameTransforms", "foxglove.SceneUpdate", "foxglove.JointStates"):
        assert schemas[name]["title"] == name and schemas[name] == SCHEMAS[name]
    # foxglove.JointStates as published (foxglove-sdk schemas/jsonschema/JointStates.json)
    js = schemas["foxglove.JointStates"]
    assert js["required"] == ["timestamp", "joints"]
    assert list(js["properties"]["timestamp"]["properties"]) == ["sec", "nsec"]
    joint = js["properties"]["joints"]["items"]
    assert joint["title"] == "foxglove.JointState" and joint["required"] == ["name"]
    assert {k: v["type"] for k, v in joint["properties"].items()} == {
        "name": "string", "position": "number", "velocity": "number", "acceleration": "number", "effort": "number"}
    entity = schemas["foxglove.SceneUpdate"]["properties"]["entities"]["items"]
    assert set(entity["required"]) == {"timestamp", "frame_id", "id", "lifetime", "frame_locked", "metadata",
                                       "arrows", "cubes", "spheres", "cylinders", "lines", "triangles",
                                       "texts", "models"}
    tf_item = schemas["foxglove.FrameTransforms"]["properties"]["transforms"]["items"]
    assert list(tf_item["properties"]["rotation"]["properties"]) == ["x", "y", "z", "w"]
    # Every message validates against its channel's schema.
    seen = set()
    for ch, schema, msg in iter_messages(path):
        check_schema(json.loads(msg.data), json.loads(schema.data), ch.topic)
        assert msg.log_time == msg.publish_time
        seen.add(ch.topic)
    assert seen == set(expected)
    # Per-sample messages are stamped with the sample time; the signals are in /control and
    # the true state in /state/true.
    ctrl = [json.loads(m.data) for c, _, m in iter_messages(path) if c.topic == "/control"]
    state = [json.loads(m.data) for c, _, m in iter_messages(path) if c.topic == "/state/true"]
    assert [m["t"] for m in ctrl] == result.t.tolist()
    assert ctrl[30]["timestamp"] == {"sec": 0, "nsec": 500_000_000}
    assert set(state[0]) == {"timestamp", "t", "q_true", "qd_true", "tip_true"}
    assert "q_true" not in ctrl[0] and ctrl[0]["e_p"] == result.signals["e_p"][0].tolist()
    assert ctrl[5]["dls_active"] in (0, 1)


def test_scene_matches_the_parameters(recorded):
    path, result, params, _ = recorded
    scenes = [json.loads(m.data) for c, _, m in iter_messages(path) if c.topic == "/scene"]
    ents = {e["id"]: e for e in scenes[0]["entities"]}
    for b in params.bodies:
        e = ents[b.name]
        assert e["frame_id"] == b.name and e["frame_locked"] is True
        assert e["lifetime"] == {"sec": 0, "nsec": 0}
        (cube,) = e["cubes"]
        assert cube["size"] == {"x": 2 * b.box_half[0], "y": 2 * b.box_half[1], "z": b.width}
        assert cube["pose"]["position"] == {"x": b.box_center[0], "y": b.box_center[1], "z": 0.0}
    assert len(ents["thrusters"]["arrows"]) == len(params.thrusters)
    assert ents["tip"]["frame_id"] == "tip"
    # The last path update holds the whole desired tip path, in the world frame.
    paths = [json.loads(m.data) for c, _, m in iter_messages(path) if c.topic == "/scene/paths"]
    lines = {e["id"]: e for e in paths[-1]["entities"]}
    desired = lines["desired_tip_path"]
    assert desired["frame_id"] == "world"
    pts = np.array([[p["x"], p["y"]] for p in desired["lines"][0]["points"]])
    pd = result.signals["p_desired"][:, 3:5]
    assert np.allclose(pts[0], pd[0], atol=1e-6) and np.allclose(pts[-1], pd[-1], atol=1e-6)
    assert len(pts) == 21  # every 0.1 s over 2 s, both ends included
    assert np.allclose(pts, pd[::6], atol=1e-6)
    true_pts = np.array([[p["x"], p["y"]] for p in lines["true_tip_path"]["lines"][0]["points"]])
    assert np.allclose(true_pts, result.signals["tip_true"][::6], atol=1e-6)


# ----------------------------------------------------------------------------- metadata


def test_metadata(recorded):
    path, result, params, meta = recorded
    log = read_log(path)
    for key, value in meta.items():
        assert log.meta[key] == value
    versions = log.meta["versions"]
    assert set(versions) >= {"uvms_mj", "mujoco", "numpy", "python"}
    import mujoco

    assert versions["mujoco"] == mujoco.__version__ and versions["numpy"] == np.__version__
    commit = log.meta["git_commit"]  # always there: from git, from the wheel, or "unknown"
    if commit != "unknown":
        assert len(commit) == 40 and int(commit, 16) >= 0
        assert isinstance(log.meta["git_dirty"], bool)
    assert log.meta["robot_params"]["tip_offset"] == list(params.tip_offset)
    assert log.params == params  # the robot parameters come back as a RobotParams
    assert log.meta["log_format"] == 1
    # Both records, as MCAP metadata, readable with the normal reader.
    with open(path, "rb") as f:
        records = {m.name: m.metadata for m in make_reader(f).iter_metadata()}
    assert json.loads(records["uvms_mj"]["seed"]) == 7
    assert json.loads(records["uvms_mj.status"]["status"]) == "ok"
    assert json.loads(records["uvms_mj.status"]["samples"]) == len(result.t)
    with pytest.raises(ValueError, match="reserved"):
        McapRecorder(path.parent / "x.mcap", params, {"versions": 1})


def test_log_info_and_format(recorded):
    path, result, _, _ = recorded
    info = log_info(path)
    assert info["samples"] == len(result.t) and not info["truncated"] and info["status"] == "ok"
    assert info["start_time"] == 0.0 and info["end_time"] == pytest.approx(result.t[-1], abs=1e-9)
    assert info["duration"] == pytest.approx(2.0, abs=1e-9)
    assert info["signals"]["q_true"] == {"dtype": "float64", "shape": [5], "topic": "/state/true"}
    text = format_info(info)
    for word in ("complete", "status:    ok", "/control", "uvms_mj.ControlSample", "mujoco", str(len(result.t))):
        assert word in text


# ----------------------------------------------------------------------------- truncation


def test_truncated_at_any_byte(tmp_path, params):
    """A file cut anywhere reads back the samples up to the last flush before the cut."""
    path = tmp_path / "cut.mcap"
    rows = [synthetic_row(k) for k in range(120)]
    flush_points = []  # (file size after the flush, samples flushed)
    rec = McapRecorder(path, params, {"case": "cut"}, flush_interval=1e9)
    for k, row in enumerate(rows):
        rec.write_sample(k / 60, row)
        if k % 25 == 24:
            rec.flush()
            flush_points.append((path.stat().st_size, k + 1))
    rec.close()
    full = path.read_bytes()
    ref = read_log(path)
    assert ref.status == "ok" and not ref.truncated and len(ref.t) == 120
    rng = np.random.default_rng(1)
    # Each flush point exactly, and random cuts in between.
    cuts = [size for size, _ in flush_points] + list(rng.integers(flush_points[0][0], len(full) - 1, 25))
    for cut in cuts:
        path.write_bytes(full[:cut])
        flushed = max(n for size, n in flush_points if size <= cut)
        log = read_log(path)
        assert log.truncated, cut
        # Everything flushed before the cut; also the next flush's samples when the cut
        # only removes the message index records that follow their chunk.
        after = min([n for size, n in flush_points if size > cut] + [120])
        assert len(log.t) in (flushed, after), cut
        if cut in [size for size, _ in flush_points]:
            assert len(log.t) == flushed
        expected = len(log.t)
        if expected < 120 or log.status != "ok":  # (a cut in the summary keeps the status record)
            assert log.status == "truncated" and "without a status record" in log.reason
        assert log.meta["case"] == "cut"
        for name, arr in log.signals.items():
            assert np.array_equal(arr, ref.signals[name][:expected]), name
        info = log_info(path)
        assert info["truncated"] and info["samples"] == expected and info["status"] == log.status
        assert "TRUNCATED" in format_info(info)


def run_child(script: str, path: Path) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=SRC + os.pathsep + os.environ.get("PYTHONPATH", ""))
    code = textwrap.dedent("""
        import math, sys, time
        import numpy as np
        sys.path.insert(0, {tests!r})
        from oracles.planar.nominal import params_from_file
        from uvms_mj.io.recorder import McapRecorder, handle_sigterm
        from test_recorder import synthetic_row
        path = {path!r}
    """).format(tests=str(Path(__file__).parent), path=str(path)) + textwrap.dedent(script)
    return subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env)


def test_kill9_leaves_a_log_readable_up_to_the_last_flush(tmp_path):
    path = tmp_path / "killed.mcap"
    proc = run_child("""
        rec = McapRecorder(path, params_from_file(), {"case": "kill"}, flush_interval=1e9)
        for k in range(300):
            rec.write_sample(k / 60, synthetic_row(k))
            if k == 199:
                rec.flush()
                print("flushed", k + 1, flush=True)
        time.sleep(120)
    """, path)
    try:
        line = proc.stdout.readline()
        assert line.split() == ["flushed", "200"], (line, proc.stderr.read() if proc.poll() is not None else "")
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    log = read_log(path)
    assert log.truncated and log.status == "truncated"
    assert len(log.t) == 200 and log.t[-1] == 199 / 60
    assert log.meta["case"] == "kill" and "versions" in log.meta
    assert np.array_equal(log.signals["q_true"][-1], synthetic_row(199)["q_true"])
    assert log_info(path)["truncated"]


def test_sigterm_closes_the_log_cleanly(tmp_path):
    path = tmp_path / "term.mcap"
    proc = run_child("""
        try:
            with handle_sigterm(), McapRecorder(path, params_from_file(), {"case": "term"}) as rec:
                k = 0
                while True:
                    rec.write_sample(k / 60, synthetic_row(k))
                    if k == 10:
                        print("running", flush=True)
                    k += 1
                    time.sleep(0.001)
        except KeyboardInterrupt as exc:
            print(type(exc).__name__, flush=True)
            sys.exit(143)
    """, path)
    try:
        assert proc.stdout.readline().strip() == "running"
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 143, err
    assert out.strip() == "Terminated"
    # The normal (indexed) reader opens it: summary and status record present.
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        status = {m.name: m.metadata for m in reader.iter_metadata()}["uvms_mj.status"]
        n_ctrl = sum(1 for _ in reader.iter_messages(topics=["/control"]))
    assert summary is not None and summary.statistics.message_count > 0
    assert json.loads(status["status"]) == "interrupted"
    assert "SIGTERM" in json.loads(status["reason"])
    log = read_log(path)
    assert not log.truncated and log.status == "interrupted" and len(log.t) == n_ctrl > 10


def test_exception_closes_with_error_status(tmp_path, params):
    path = tmp_path / "err.mcap"
    with pytest.raises(ZeroDivisionError):
        with McapRecorder(path, params, {}) as rec:
            for k in range(5):
                rec.write_sample(k / 60, synthetic_row(k))
            _ = 1 / 0
    log = read_log(path)
    assert not log.truncated and len(log.t) == 5
    assert log.status == "error" and "ZeroDivisionError" in log.reason
    with pytest.raises(RuntimeError, match="closed"):
        rec.write_sample(1.0, synthetic_row(60))


def test_keyboard_interrupt_closes_as_interrupted(tmp_path, params):
    path = tmp_path / "int.mcap"
    with pytest.raises(KeyboardInterrupt):
        with McapRecorder(path, params, {}) as rec:
            rec.write_sample(0.0, synthetic_row(0))
            raise KeyboardInterrupt
    assert read_log(path).status == "interrupted"


def test_handle_sigterm_restores_the_handler():
    before = signal.getsignal(signal.SIGTERM)
    with handle_sigterm():
        assert signal.getsignal(signal.SIGTERM) is not before
        with pytest.raises(Terminated):
            os.kill(os.getpid(), signal.SIGTERM)
            for _ in range(1000):  # the Python-level handler runs between bytecodes
                pass
    assert signal.getsignal(signal.SIGTERM) is before
    assert issubclass(Terminated, KeyboardInterrupt)


@pytest.mark.parametrize("sig, exc", [(signal.SIGTERM, Terminated), (signal.SIGINT, KeyboardInterrupt)])
def test_a_signal_inside_a_finalizer_is_not_lost(monkeypatch, sig, exc):
    """A signal whose handler runs inside a finalizer (a weakref callback: Python prints "Exception
    ignored in ..." and drops what it raises; a sweep worker's rare stray line) interrupts the code
    that runs after the finalizer, and nothing is printed."""
    import weakref

    from uvms_mj.io import interrupts

    dropped = []
    monkeypatch.setattr(sys, "unraisablehook", dropped.append)
    monkeypatch.setattr(interrupts, "_signalled", False)

    class Box:
        pass

    after = []
    with handle_sigterm():
        with pytest.raises(exc):
            box = Box()
            weakref.finalize(box, interrupts._on_signal, sig, None)  # the handler, as a finalizer runs it
            del box  # the finalizer runs here and its exception is dropped by Python
            after.append("finalized")
            deadline = time.monotonic() + 5.0  # raised again 1 ms later (interrupts._AGAIN_S)
            while time.monotonic() < deadline:
                pass
            after.append("not interrupted")
    assert after == ["finalized"] and dropped == []
    assert interrupts._again is None


def test_flush_interval_bounds_the_data_at_risk(tmp_path, params):
    """With flush_interval=0 every sample reaches the file as it is written."""
    path = tmp_path / "f.mcap"
    rec = McapRecorder(path, params, {}, flush_interval=0.0)
    for k in range(7):
        rec.write_sample(k / 60, synthetic_row(k))
    assert len(read_log(path).t) == 7  # still open: read as a cut-off file
    rec.close()
    assert not read_log(path).truncated


def test_schemas_parse_like_foxglove(recorded, tmp_path, params):
    """Foxglove turns a JSON schema into datatypes with a parser that accepts only objects
    whose fields are booleans, strings, numbers, integers, objects, oneOf of numeric consts,
    and arrays of those (no nested arrays): every schema in our logs must pass it."""

    def parse(schema: dict, where: str) -> None:
        assert schema["type"] == "object", where
        for name, field in schema["properties"].items():
            here = f"{where}.{name}"
            if "oneOf" in field:
                assert all(isinstance(alt["const"], int) for alt in field["oneOf"]), here
            elif field["type"] == "object":
                parse(field, here)
            elif field["type"] == "array":
                item = field["items"]
                assert item["type"] in ("boolean", "string", "number", "integer", "object"), here
                if item["type"] == "object":
                    parse(item, here)
                elif item["type"] == "string":
                    assert "contentEncoding" not in item, here
            else:
                assert field["type"] in ("boolean", "string", "number", "integer"), here

    path = tmp_path / "m.mcap"
    with McapRecorder(path, params) as rec:
        for k in range(3):
            rec.write_sample(k * 0.1, {"mat": np.ones((2, 3)) * k, "flags": np.eye(2, dtype=bool)})
    for log in (recorded[0], path):
        for _, schema, _ in iter_messages(log):
            parse(json.loads(schema.data), schema.name)
    ctrl = [json.loads(m.data) for c, _, m in iter_messages(path) if c.topic == "/control"]
    assert ctrl[2]["mat"] == [2.0] * 6 and ctrl[0]["flags"] == [1, 0, 0, 1]
    log = read_log(path)
    assert log.signals["mat"].shape == (3, 2, 3) and log.signals["flags"].dtype == bool
    assert np.array_equal(log.signals["flags"][1], np.eye(2, dtype=bool))


def test_a_signal_during_a_write_waits_for_the_write(tmp_path, params):
    """SIGTERM arriving while a sample is being written is raised only once the sample is
    complete in the log."""
    path = tmp_path / "held.mcap"
    with pytest.raises(Terminated):
        # flush_interval 0: each sample is encoded and written by its own write_sample
        with handle_sigterm(), McapRecorder(path, params, {}, flush_interval=0) as rec:
            rec.write_sample(0.0, synthetic_row(0))
            add_samples = rec._writer.add_samples
            calls = []

            def add_and_signal(samples, *args, **kwargs):
                calls.append(sum(len(m) for m, _, _ in samples))
                if len(calls) == 1:
                    os.kill(os.getpid(), signal.SIGTERM)
                    for _ in range(1000):  # the Python handler runs here, between bytecodes
                        pass
                return add_samples(samples, *args, **kwargs)

            rec._writer.add_samples = add_and_signal
            rec.write_sample(1 / 60, synthetic_row(1))
            pytest.fail("SIGTERM was not raised after the write")
    assert calls[0] >= 4  # /control, /state/true, /tf, /joint_states in one call
    log = read_log(path)
    assert len(log.t) == 2 and log.status == "interrupted" and "SIGTERM" in log.reason


def test_git_commit_outside_a_checkout(monkeypatch):
    """Not in a git checkout: the commit written into the wheel at build time, else "unknown"."""
    import sys as _sys
    import types

    from uvms_mj.io import provenance

    monkeypatch.setattr(provenance, "_git_checkout_info", lambda: {})
    monkeypatch.setitem(_sys.modules, "uvms_mj._build_info", None)  # no build info: import fails
    assert provenance._git_info() == {"git_commit": "unknown"}
    built = types.ModuleType("uvms_mj._build_info")
    built.GIT_COMMIT, built.GIT_DIRTY = "a" * 40, False
    monkeypatch.setitem(_sys.modules, "uvms_mj._build_info", built)
    import uvms_mj

    monkeypatch.setattr(uvms_mj, "_build_info", built, raising=False)
    assert provenance._git_info() == {"git_commit": "a" * 40, "git_dirty": False}
    assert provenance.provenance()["git_commit"] == "a" * 40


def test_legacy_joint_states_log_reads_back(recorded, tmp_path):
    """A log written before foxglove.JointStates (uvms_mj.JointStates with name/position/velocity
    arrays on /joint_states) reads back exactly like the new one."""
    from mcap.writer import Writer

    from uvms_mj.io.recorder import LEGACY_JOINT_STATES

    path, result, _, _ = recorded
    old = tmp_path / "old.mcap"
    legacy_schema = {"title": LEGACY_JOINT_STATES, "type": "object", "properties": {
        "timestamp": {"type": "object"}, "name": {"type": "array"}, "position": {"type": "array"},
        "velocity": {"type": "array"}}}
    with open(path, "rb") as f, open(old, "wb") as g:
        reader = make_reader(f)
        summary = reader.get_summary()
        w = Writer(g)
        w.start()
        sids, cids = {}, {}
        for sid, sc in summary.schemas.items():
            if sc.name == "foxglove.JointStates":
                sids[sid] = w.register_schema(LEGACY_JOINT_STATES, "jsonschema", json.dumps(legacy_schema).encode())
            else:
                sids[sid] = w.register_schema(sc.name, sc.encoding, sc.data)
        for cid, ch in summary.channels.items():
            cids[cid] = w.register_channel(ch.topic, ch.message_encoding, sids[ch.schema_id], ch.metadata)
        for sc, ch, msg in reader.iter_messages(log_time_order=False):
            data = msg.data
            if ch.topic == "/joint_states":
                js = json.loads(data)
                data = json.dumps({"timestamp": js["timestamp"], "name": [j["name"] for j in js["joints"]],
                                   "position": [j["position"] for j in js["joints"]],
                                   "velocity": [j["velocity"] for j in js["joints"]]}).encode()
            w.add_message(cids[ch.id], msg.log_time, data, msg.publish_time, msg.sequence)
        for m in reader.iter_metadata():
            w.add_metadata(m.name, m.metadata)
        w.finish()
    new, legacy = read_log(path), read_log(old)
    assert np.array_equal(new.t, legacy.t) and new.status == legacy.status
    assert set(new.signals) == set(legacy.signals)
    for k in new.signals:
        assert np.array_equal(new.signals[k], legacy.signals[k], equal_nan=True), k
    chans = {c["topic"]: c["schema"] for c in log_info(old)["channels"]}
    assert chans["/joint_states"] == LEGACY_JOINT_STATES


# ----------------------------------------------------------------------------- fast writing


def _writer_bytes(cls, compression, batched=False, **kw):
    """A file of 600 messages on 2 channels with flushes, chunks of ~2 KB: by add_message
    (``batched`` False; None: publish time = log time), add_sample (True) or add_samples of up
    to 61 samples ("samples", publish time = log time)."""
    import io

    buf = io.BytesIO()
    w = cls(buf, chunk_size=2000, compression=compression, **kw)
    w.start("", "test")
    sid = w.register_schema("s", "jsonschema", b"{}")
    c1, c2 = w.register_channel("/a", "json", sid), w.register_channel("/b", "json", sid)
    pending = []
    for i in range(300):
        msgs = [(c1 if i % 3 else c2, b'{"i":%d}' % i * (i % 5 + 1)), (c2, b"[%d]" % i)]
        t = (i * 7919) % 1000 * 10  # not monotonic: the start/end times are min/max
        if batched == "samples":  # publish time = log time
            pending.append((msgs, t, i))
            if i % 61 == 60 or i % 97 == 0:  # batches spanning several chunks
                w.add_samples(pending)
                pending = []
        elif batched:
            w.add_sample(msgs, t, i, t + 1)
        else:
            for cid, data in msgs:
                w.add_message(cid, t, data, t if batched is None else t + 1, i)
        if i % 97 == 0:
            w.flush()
    if pending:
        w.add_samples(pending)
    w.finish()
    return buf.getvalue()


def _all_records(data: bytes):
    import io

    from mcap.stream_reader import StreamReader

    return [r for r in StreamReader(io.BytesIO(data), skip_magic=False).records]


@pytest.mark.parametrize("compression", ["NONE", "LZ4", "ZSTD"])
def test_lean_writer_writes_what_mcaps_writer_writes(compression):
    """The recorder's writer against mcap's own Writer on the same calls: byte for byte without
    compression and with lz4; with zstd (level 1, one compressor) every record but the chunks'
    compressed bytes and sizes is identical and the chunks decompress to the same bytes. One
    add_sample is the same as its messages' add_message calls."""
    from mcap.records import Chunk, ChunkIndex
    from mcap.writer import CompressionType, Writer

    from uvms_mj.io.mcap_writer import LeanWriter

    comp = CompressionType[compression]
    stock = _writer_bytes(Writer, comp)
    lean = _writer_bytes(LeanWriter, comp)
    assert _writer_bytes(LeanWriter, comp, batched=True) == lean
    # add_samples (many samples, several chunks at once) against add_message one at a time
    assert _writer_bytes(LeanWriter, comp, batched="samples") == _writer_bytes(LeanWriter, comp, batched=None)
    if compression != "ZSTD":
        assert _writer_bytes(LeanWriter, comp, batched="samples") == _writer_bytes(Writer, comp, batched=None)
    if compression != "ZSTD":
        assert lean == stock
        return
    a, b = _all_records(stock), _all_records(lean)
    assert [type(r) for r in a] == [type(r) for r in b]
    import zstandard

    for x, y in zip(a, b):
        if isinstance(x, Chunk):
            assert zstandard.ZstdDecompressor().decompress(y.data, max_output_size=x.uncompressed_size) == \
                zstandard.decompress(x.data, max_output_size=x.uncompressed_size)
            assert (x.uncompressed_crc, x.uncompressed_size, x.message_start_time, x.message_end_time) == \
                (y.uncompressed_crc, y.uncompressed_size, y.message_start_time, y.message_end_time)
        elif not isinstance(x, ChunkIndex) and type(x).__name__ not in ("Footer", "SummaryOffset", "DataEnd"):
            assert x == y, type(x).__name__
    # and mcap's indexed reader finds every message through the lean file's summary
    got = [(c.topic, m.log_time, m.sequence, m.data) for _, c, m in make_reader(__import__("io").BytesIO(lean))
           .iter_messages(log_time_order=False)]
    want = [(c.topic, m.log_time, m.sequence, m.data) for _, c, m in make_reader(__import__("io").BytesIO(stock))
            .iter_messages(log_time_order=False)]
    assert got == want


def _irregular_rows(n: int = 200, layout: str = "2-D") -> list:
    """Rows with every kind the recorder takes (floats, ints, bools, bool and 2-D arrays, float32),
    and, here and there, a non-finite number, a missing signal and a late one. ``layout``:
    "2-D" (a 2-D signal, state signals last), "loop" (no 2-D signal, the state signals between
    others as the loop's rows have them; numpy scalars; every 29th row in another order) or
    "state first"."""
    rows = []
    for k in range(n):
        r = synthetic_row(k)
        if layout == "2-D":
            r["gain"] = np.array([[1.0, 2.0], [3.0, 0.1 * k]])
        r["f32"] = np.array([0.1, 0.2 * k], dtype=np.float32)
        r["count"] = np.int64(k)
        if layout == "loop":
            state = {name: r.pop(name) for name in ("q_true", "qd_true", "tip_true")}
            ctrl = {name: r.pop(name) for name in ("f32", "count")}
            r = {**r, **state, **ctrl, "scalar": np.float64(0.5 * k), "flag": np.bool_(k % 3 == 0)}
            if k % 29 == 3:
                r = dict(reversed(r.items()))
        elif layout == "state first":
            r = {name: r[name] for name in ("q_true", "qd_true", "tip_true")} | r
        if k % 37 == 5:
            r["det_B"] = math.inf if k % 2 else math.nan
        if k % 41 == 7:
            r["q_true"] = np.array([0.0, np.nan, 0.1, -np.inf, 0.2])
        if k % 53 == 11:
            del r["singular_phase"]
        if k % 61 == 13:
            del r["qd_true"]  # /joint_states without velocities
        if k == 150:
            r["late"] = 1.0
        rows.append((k / 60, r))
    return rows


@pytest.mark.parametrize("layout", ["2-D", "loop", "state first"])
def test_batched_encoding_is_the_per_sample_encoding(tmp_path, params, layout):
    """The recorder encodes the samples since its last flush at once; flushing after every sample
    (batches of one) or once per 200 samples gives the same messages, for regular rows and for
    every irregular one (non-finite numbers, missing and late signals, another order), whatever
    the place of the state signals in the row and with numpy scalars."""
    logs = {}
    for label, interval in (("each", 0.0), ("batch", 1e9)):
        path = tmp_path / f"{label}.mcap"
        with pytest.warns(UserWarning, match="first appeared after the first sample"):
            with McapRecorder(path, params, {}, flush_interval=interval) as rec:
                for t, r in _irregular_rows(layout=layout):
                    rec.write_sample(t, r)
                rec.close()
        logs[label] = [(c.topic, m.log_time, m.sequence, m.data) for c, _, m in iter_messages(path)]
    assert len(logs["each"]) > 700  # /scene, 4 per sample (3 with a non-finite pose), the paths
    assert logs["each"] == logs["batch"]
    back = read_log(tmp_path / "batch.mcap")
    assert back.signals["det_B"][5] == math.inf and math.isnan(back.signals["det_B"][42])
    assert np.isnan(back.signals["q_true"][7][1]) and back.signals["q_true"][7][3] == -np.inf
    assert "late" not in back.signals


def test_regular_batches_are_the_per_sample_encoding(tmp_path, params, monkeypatch):
    """A batch of regular rows (the first row's signals, all finite) is put together at once
    (sample channels, /tf and /joint_states by zips): the same messages as one sample at a time,
    and that path is the one taken."""
    taken = []
    orig = McapRecorder._every_row_at_once

    def spy(self, *a):
        out = orig(self, *a)
        taken.append(out is not None and len(out))
        return out

    monkeypatch.setattr(McapRecorder, "_every_row_at_once", spy)
    logs = {}
    for label, interval in (("each", 0.0), ("batch", 1e9)):
        path = tmp_path / f"{label}.mcap"
        with McapRecorder(path, params, {}, flush_interval=interval, writer="inline") as rec:  # (spied: inline)
            for k in range(300):
                r = synthetic_row(k)
                r = {**{n: r.pop(n) for n in ("q_true", "qd_true", "tip_true")}, **r, "count": np.int64(k)}
                rec.write_sample(k / 60, r)
            rec.close()
        logs[label] = [(c.topic, m.log_time, m.sequence, m.data) for c, _, m in iter_messages(path)]
    assert max(taken) == 299  # the batch after the first sample (flushed at once) went that way
    assert len(logs["each"]) > 4 * 300
    assert logs["each"] == logs["batch"]


def test_rows_are_copied_until_their_batch_is_written(tmp_path, params):
    """The recorder keeps a copy of each row until the next flush: a caller that reuses one dict
    for every sample still gets every sample."""
    path = tmp_path / "reuse.mcap"
    row: dict = {}
    with McapRecorder(path, params, {}, flush_interval=1e9) as rec:
        for k in range(30):
            row.update(synthetic_row(k))
            rec.write_sample(k / 60, row)
        rec.close()
    want = [synthetic_row(k)["det_B"] for k in range(30)]
    assert read_log(path).signals["det_B"].tolist() == want


def test_a_row_that_cannot_be_encoded_ends_the_log_cleanly(tmp_path, params):
    """A value the encoder cannot take (None for a boolean signal) at sample 10 of a batch: the
    samples before it are written, the log is finished with status "error" naming the problem,
    and the exception reaches the caller."""
    path = tmp_path / "bad.mcap"
    rec = McapRecorder(path, params, {}, flush_interval=1e9)
    for k in range(20):
        row = synthetic_row(k)
        if k == 10:
            row["dls_active"] = None
        rec.write_sample(k / 60, row)
    with pytest.raises(TypeError):
        rec.close()
    log = read_log(path)
    assert len(log.t) == 10 and not log.truncated
    assert log.status == "error" and "recorder: TypeError" in log.reason
