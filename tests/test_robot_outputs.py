"""Outputs of any-robot runs (bluerov2_alpha, bluerov2_heavy): the MCAP log (exact round trip,
/tf against MuJoCo's kinematics, /scene from the model's geoms, /joint_states and /thrusters by
name, 3-D paths), the replay video (both follow cameras keep the vehicle in view) and the
figures, with and without the controller's optional signals. A paper log keeps its channels.

Runs are made here with constant thrusts and joint torques (no controller), as the closed loop
would record them. Rendering needs the headless GL packages, as tests/test_render.py.
"""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import mujoco
import numpy as np
import pytest
from click.testing import CliRunner

from uvms_mj.sim.loop import RunResult
from uvms_mj.plant.params import ParameterError
from uvms_mj.io.recorder import McapRecorder, iter_messages, log_info, read_log
from uvms_mj.plant.plant import Plant

T = 1 / 60  # s, the sample period
DURATION = 2.0  # s
OPTIONAL = ("base_desired", "joints_desired", "e_position", "e_attitude", "wrench_body", "tip_desired")
ROBOT_TOPICS = {"/control", "/state/true", "/tf", "/joint_states", "/thrusters", "/scene", "/scene/paths"}
PAPER_TOPICS = {"/control", "/state/true", "/tf", "/joint_states", "/scene", "/scene/paths"}


def _simulate(name: str, duration: float = DURATION, optional: bool = True):
    """(plant, RunResult, rows): ``name`` driven by constant thrusts [N] and torques [N m]."""
    plant = Plant(name)
    lay = plant.layout
    thrust = np.linspace(-4.0, 6.0, len(lay.thruster_names))
    tau = np.full(len(lay.motor_names), 0.05)
    plant.set_thrust(thrust)
    plant.set_joint_torques(tau)
    sub = int(round(T / plant.model.opt.timestep))
    q0 = plant.data.qpos.copy()
    rows, ts = [], []
    for k in range(int(round(duration / T)) + 1):
        t = k * T
        q = plant.data.qpos.copy()
        row = {"q_true": q, "qd_true": plant.data.qvel.copy(), "tip_true": plant.tip_position,
               "q_measured": q.copy(), "thrust_command": thrust.copy(), "thrust_force": plant.thruster_forces,
               "torques": tau.copy()}
        if optional:
            row["base_desired"] = np.r_[q0[:3] + [0.1 * t, 0.0, 0.0], 1.0, 0.0, 0.0, 0.0]
            row["joints_desired"] = np.zeros(len(lay.joint_names))
            row["e_position"] = row["base_desired"][:3] - q[:3]
            row["e_attitude"] = np.zeros(3)
            row["wrench_body"] = np.zeros(6)
            if lay.tip_site >= 0:
                row["tip_desired"] = row["tip_true"] + [0.01, 0.0, 0.0]
        rows.append(row)
        ts.append(t)
        plant.step(sub)
    signals = {k: np.array([r[k] for r in rows]) for k in rows[0]}
    robot = {"name": name, "path": str(plant.model_path), "overrides": {}, "layout": lay.describe()}
    run = RunResult(t=np.array(ts), signals=signals, meta={"controller": "constant", "robot": robot})
    return plant, run, rows


def _record(path: Path, plant, run: RunResult, rows) -> None:
    with McapRecorder(path, None, metadata={"robot": run.meta["robot"], "controller": "constant"},
                      model=plant.model) as rec:
        for t, row in zip(run.t, rows):
            rec.write_sample(float(t), row)
        rec.close(run.status, run.reason, meta=run.meta)


def _bare(run: RunResult) -> RunResult:
    """The run without the controller's optional signals."""
    return RunResult(t=run.t, signals={k: v for k, v in run.signals.items() if k not in OPTIONAL},
                     meta=dict(run.meta))


@pytest.fixture(scope="module")
def alpha():
    return _simulate("bluerov2_alpha")


@pytest.fixture(scope="module")
def recorded(alpha, tmp_path_factory):
    plant, run, rows = alpha
    path = tmp_path_factory.mktemp("robot") / "alpha.mcap"
    _record(path, plant, run, rows)
    return path, plant, run


def _messages(path: Path, topic: str) -> list[dict]:
    return [json.loads(m.data) for c, _, m in iter_messages(path) if c.topic == topic]


def _check_schema(value, schema: dict, where: str = "$") -> None:
    """The subset of JSON Schema the recorder's schemas use."""
    if "oneOf" in schema:
        assert sum(s.get("const") == value for s in schema["oneOf"]) == 1, where
        return
    typ = schema.get("type")
    if typ == "object":
        assert isinstance(value, dict), where
        assert set(schema.get("required", [])) <= set(value), where
        for key, sub in schema.get("properties", {}).items():
            if key in value:
                _check_schema(value[key], sub, f"{where}.{key}")
    elif typ == "array":
        assert isinstance(value, list), where
        for i, item in enumerate(value):
            _check_schema(item, schema["items"], f"{where}[{i}]")
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


# ------------------------------------------------------------------ the log


def test_round_trip_bit_for_bit(recorded) -> None:
    path, _, run = recorded
    log = read_log(path)
    assert log.status == "ok" and not log.truncated
    assert np.array_equal(log.t, run.t)
    assert list(log.signals) == list(run.signals)
    for name, v in run.signals.items():
        got = log.signals[name]
        assert got.dtype == v.dtype and got.shape == v.shape, name
        assert np.array_equal(got, v, equal_nan=True), name
    assert log.meta["robot"] == run.meta["robot"]
    assert log.meta["robot_params"] is None


def test_channels_and_schemas(recorded) -> None:
    path, _, run = recorded
    n = len(run.t)
    chans = {c["topic"]: c for c in log_info(path)["channels"]}
    assert set(chans) == ROBOT_TOPICS
    assert {t: chans[t]["messages"] for t in ("/tf", "/joint_states", "/thrusters", "/scene")} == \
        {"/tf": n, "/joint_states": n, "/thrusters": n, "/scene": 1}
    assert chans["/thrusters"]["schema"] == "uvms_mj.Thrusters"
    for ch, schema, msg in iter_messages(path):
        _check_schema(json.loads(msg.data), json.loads(schema.data), ch.topic)


def test_tf_equals_mujoco_kinematics(recorded) -> None:
    """/tf is the model's tree (view -> world, then each body in its parent body's frame): the parent's
    world pose from MuJoCo times the logged transform is the body's world pose, to 1e-12 (float64
    rounding of one rigid transform of positions below ~10 m)."""
    path, plant, run = recorded
    m = plant.model
    names = [m.body(b).name for b in range(1, m.nbody)]
    tfs = _messages(path, "/tf")
    d = mujoco.MjData(m)  # a fresh one: independent of the recorder's
    for k in (0, 37, len(run.t) - 1):
        d.qpos[:] = run.signals["q_true"][k]
        mujoco.mj_kinematics(m, d)
        view, *tr = tfs[k]["transforms"]
        assert (view["parent_frame_id"], view["child_frame_id"]) == ("view", "world")
        assert view["rotation"] == {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}  # this world is z up already
        assert [x["child_frame_id"] for x in tr] == names
        assert [x["parent_frame_id"] for x in tr] == \
            ["world" if m.body_parentid[b] == 0 else m.body(int(m.body_parentid[b])).name for b in range(1, m.nbody)]
        sec, nsec = divmod(int(round(run.t[k] * 1e9)), 1_000_000_000)
        assert tr[0]["timestamp"] == view["timestamp"] == {"sec": sec, "nsec": nsec}
        for b, x in enumerate(tr, start=1):
            p = int(m.body_parentid[b])
            rp = d.xmat[p].reshape(3, 3)
            pos = d.xpos[p] + rp @ [x["translation"][c] for c in "xyz"]
            rel = np.empty(9)
            mujoco.mju_quat2Mat(rel, np.array([x["rotation"][c] for c in "wxyz"]))
            np.testing.assert_allclose(pos, d.xpos[b], rtol=0, atol=1e-12)
            np.testing.assert_allclose(rp @ rel.reshape(3, 3), d.xmat[b].reshape(3, 3), rtol=0, atol=1e-12)


def test_scene_has_the_models_geoms(recorded) -> None:
    path, plant, _ = recorded
    m, lay = plant.model, plant.layout
    (scene,) = _messages(path, "/scene")
    ents = {e["id"]: e for e in scene["entities"]}
    visible = [g for g in range(m.ngeom) if m.geom_group[g] < 3 and m.geom_type[g] != mujoco.mjtGeom.mjGEOM_PLANE]
    body_ents = [e for i, e in ents.items() if i not in ("thrusters", "tip")]
    kinds = ("cubes", "spheres", "cylinders")
    assert sum(len(e[k]) for e in body_ents for k in kinds) == len(visible)
    for b in {int(m.geom_bodyid[g]) for g in visible}:
        e = ents[m.body(b).name]
        assert e["frame_id"] == m.body(b).name and e["frame_locked"] is True
        assert sum(len(e[k]) for k in kinds) == sum(int(m.geom_bodyid[g]) == b for g in visible)
    # a box: full edges, pose in its body frame
    g = m.geom("bluerov2_panel_l").id
    cube = next(c for c in ents[m.body(int(m.geom_bodyid[g])).name]["cubes"]
                if np.allclose([c["pose"]["position"][a] for a in "xyz"], m.geom_pos[g]))
    np.testing.assert_allclose([cube["size"][a] for a in "xyz"], 2 * m.geom_size[g])
    np.testing.assert_allclose([cube["color"][c] for c in "rgba"], m.geom_rgba[g])
    arrows = ents["thrusters"]["arrows"]
    assert len(arrows) == len(lay.thruster_names) == 8
    s = m.site("bluerov2_t5").id  # thrust along the site's x axis: here straight up the body z
    a5 = arrows[lay.thruster_names.index("bluerov2_t5")]
    np.testing.assert_allclose([a5["pose"]["position"][c] for c in "xyz"], m.site_pos[s])
    q = [a5["pose"]["orientation"][c] for c in "wxyz"]
    rot = np.empty(9)
    mujoco.mju_quat2Mat(rot, np.asarray(q))
    np.testing.assert_allclose(rot.reshape(3, 3)[:, 0], [0, 0, 1], atol=1e-9)
    assert ents["tip"]["frame_id"] == m.body(int(m.site_bodyid[lay.tip_site])).name


def test_joint_states_and_thrusters_by_name(recorded) -> None:
    path, plant, run = recorded
    m = plant.model
    hinges = [m.joint(j).name for j in range(m.njnt) if m.jnt_type[j] != mujoco.mjtJoint.mjJNT_FREE]
    js = _messages(path, "/joint_states")
    assert [j["name"] for j in js[0]["joints"]] == hinges == ["alpha_base", "alpha_shoulder", "alpha_elbow",
                                                              "alpha_wrist"]
    q, qd = run.signals["q_true"], run.signals["qd_true"]
    assert np.array_equal([[j["position"] for j in msg["joints"]] for msg in js], q[:, 7:])
    assert np.array_equal([[j["velocity"] for j in msg["joints"]] for msg in js], qd[:, 6:])
    thr = _messages(path, "/thrusters")
    names = plant.layout.thruster_names
    assert set(thr[0]) == {"timestamp", "t", *names}
    assert [msg["t"] for msg in thr] == run.t.tolist()
    for i, n in enumerate(names):
        assert np.array_equal([msg[n]["command"] for msg in thr], run.signals["thrust_command"][:, i])
        assert np.array_equal([msg[n]["force"] for msg in thr], run.signals["thrust_force"][:, i])


def test_paths_are_3d(recorded) -> None:
    path, _, run = recorded
    last = _messages(path, "/scene/paths")[-1]
    ents = {e["id"]: e["lines"][0]["points"] for e in last["entities"]}
    assert set(ents) == {"desired_tip_path", "true_tip_path", "base_path"}
    tip = ents["true_tip_path"]
    np.testing.assert_allclose([tip[-1][c] for c in "xyz"], run.signals["tip_true"][-1], atol=1e-6)
    np.testing.assert_allclose([ents["base_path"][-1][c] for c in "xyz"], run.signals["q_true"][-1, :3], atol=1e-6)
    assert len({round(p["z"], 6) for p in tip}) > 5  # not in a plane


def test_robot_without_arm_or_tip(tmp_path) -> None:
    plant, run, rows = _simulate("bluerov2_heavy", duration=0.5, optional=False)
    path = tmp_path / "heavy.mcap"
    _record(path, plant, run, rows)
    topics = {c["topic"] for c in log_info(path)["channels"]}
    assert topics == ROBOT_TOPICS - {"/joint_states"}  # no arm joints
    (scene,) = _messages(path, "/scene")
    assert "tip" not in {e["id"] for e in scene["entities"]}
    assert {e["id"] for e in _messages(path, "/scene/paths")[-1]["entities"]} == {"base_path"}
    log = read_log(path)
    assert all(np.array_equal(log.signals[k], v, equal_nan=True) for k, v in run.signals.items())


def test_paper_log_keeps_its_channels(tmp_path) -> None:
    from uvms_mj.sim.experiment import PaperExperiment
    from oracles.planar.nominal import params_from_file

    run = PaperExperiment(duration=0.5).run()
    path = tmp_path / "paper.mcap"
    with McapRecorder(path, params_from_file(), {"controller": "rac"}) as rec:
        for k, t in enumerate(run.t):
            rec.write_sample(float(t), {n: v[k] for n, v in run.signals.items()})  # numpy scalars too
    assert {c["topic"] for c in log_info(path)["channels"]} == PAPER_TOPICS
    assert "robot" not in read_log(path).meta


def test_recorder_rejects_bad_models(tmp_path, alpha) -> None:
    plant = alpha[0]
    from oracles.planar.nominal import params_from_file

    with pytest.raises(ValueError, match="not both"):
        McapRecorder(tmp_path / "a.mcap", params_from_file(), model=plant.model)
    with pytest.raises(TypeError, match="MjModel"):
        McapRecorder(tmp_path / "b.mcap", None, model="bluerov2_alpha")
    fixed = mujoco.MjModel.from_xml_string("<mujoco><worldbody><body><joint type='hinge'/><geom size='0.1'/>"
                                           "</body></worldbody></mujoco>")
    with pytest.raises(ParameterError, match="free joint"):
        McapRecorder(tmp_path / "c.mcap", None, model=fixed)
    assert not (tmp_path / "c.mcap").exists()


# ------------------------------------------------------------------ errors and interpolation


def test_attitude_error_matches_mujoco() -> None:
    from uvms_mj.analysis.plots import attitude_error

    rng = np.random.default_rng(3)
    qd, q = rng.normal(size=(20, 4)), rng.normal(size=(20, 4))
    got = attitude_error(qd, q)
    for k in range(20):
        want = np.empty(3)
        a, b = qd[k] / np.linalg.norm(qd[k]), q[k] / np.linalg.norm(q[k])
        if a @ b < 0:
            a = -a
        mujoco.mju_subQuat(want, a, b)  # b * quat(want) = a: body-frame rotation from q to qd
        np.testing.assert_allclose(got[k], want, atol=1e-12)


def test_interp_qpos_quaternions() -> None:
    from uvms_mj.analysis.render import interp_qpos

    half = np.radians(30.0) / 2
    q1 = np.r_[1.0, 2.0, 3.0, np.cos(half), 0.0, 0.0, np.sin(half), 0.5]
    q0 = np.r_[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0]
    q1_flipped = q1.copy()
    q1_flipped[3:7] *= -1  # the same rotation
    out = interp_qpos(np.array([0.5]), np.array([0.0, 1.0]), np.vstack([q0, q1_flipped]), [3])
    np.testing.assert_allclose(out[0, :3], [0.5, 1.0, 1.5])
    np.testing.assert_allclose(out[0, 7], 0.25)
    quarter = np.radians(15.0) / 2
    np.testing.assert_allclose(out[0, 3:7], [np.cos(quarter), 0, 0, np.sin(quarter)], atol=1e-12)


# ------------------------------------------------------------------ video


def _robot_pixels(frame: np.ndarray) -> np.ndarray:
    """Dark grey pixels: the vehicle's black frame and thrusters (the water, the fogged sand
    floor and the sky are coloured or bright)."""
    f = frame.astype(int)
    mx, mn = f.max(axis=2), f.min(axis=2)
    return (mx < 80) & (mx - mn < 20)


@pytest.mark.parametrize("camera", ["follow_three_quarter", "follow_side"])
def test_follow_cameras_keep_the_vehicle_in_view(recorded, camera) -> None:
    from uvms_mj.analysis.render import render_frames

    log = read_log(recorded[0])
    assert np.linalg.norm(log.signals["q_true"][-1, :3] - log.signals["q_true"][0, :3]) > 0.1  # it moved
    frames = [(t, f.copy()) for t, f in render_frames(log, fps=1, size=(160, 120), camera=camera, clock=False,
                                                      labels=False)]
    assert [t for t, _ in frames] == [0.0, 1.0]
    for _, f in frames:
        assert f.shape == (120, 160, 3) and f.std() > 10
        centre = _robot_pixels(f)[30:90, 40:120]
        assert centre.mean() > 0.05, f"{camera}: only {centre.mean():.1%} of the centre shows the vehicle"


def test_render_video_and_compare(recorded, alpha, tmp_path) -> None:
    from uvms_mj.analysis.render import render_compare_video, render_video

    log = read_log(recorded[0])
    info = render_video(log, tmp_path / "a.mp4", fps=4, size=(160, 120), max_seconds=0.5)
    assert info["frames"] == 2 and (tmp_path / "a.mp4").stat().st_size > 500
    with pytest.raises(ValueError, match="follow_side"):
        render_video(log, tmp_path / "b.mp4", fps=4, size=(160, 120), camera="above")
    bare = _bare(alpha[1])
    info = render_compare_video(log, bare, tmp_path / "c.mp4", fps=4, size=(320, 120), max_seconds=0.5)
    assert info["frames"] == 2 and info["size"] == (320, 150)
    paper = SimpleNamespace(t=np.arange(3) * T, signals={"q_true": np.zeros((3, 5))}, meta={})
    with pytest.raises(ValueError, match="not supported"):
        render_compare_video(log, paper, tmp_path / "d.mp4", fps=4, size=(320, 120))


def test_render_robot_without_tip(tmp_path) -> None:
    from uvms_mj.analysis.render import render_frames

    _, run, _ = _simulate("bluerov2_heavy", duration=0.5, optional=False)
    frames = [f.copy() for _, f in render_frames(run, fps=2, size=(160, 120), labels=False, clock=False)]
    assert len(frames) == 1 and _robot_pixels(frames[0])[30:90, 40:120].mean() > 0.05


def test_cli_render_camera(recorded, tmp_path) -> None:
    from uvms_mj.cli.main import main

    out = tmp_path / "cli.mp4"
    res = CliRunner().invoke(main, ["render", str(recorded[0]), "--camera", "follow_side", "--fps", "1",
                                    "--size", "160", "120", "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert out.is_file()
    res = CliRunner().invoke(main, ["render", str(recorded[0]), "--camera", "nope", "-o", str(tmp_path / "x.mp4")])
    assert res.exit_code == 2 and "follow_three_quarter" in res.output and "Traceback" not in res.output


# ------------------------------------------------------------------ figures


@pytest.mark.slow
def test_plots_with_and_without_optional_signals(recorded, alpha, tmp_path) -> None:
    from uvms_mj.analysis.plots import plot_comparison, plot_run

    full = read_log(recorded[0])
    bare = _bare(alpha[1])
    for stem, log in (("full", full), ("bare", bare)):
        paths = plot_run(log, tmp_path, stem)
        assert [p.name for p in paths] == [f"{stem}_tracking.png", f"{stem}_actuation.png"]
        assert all(p.stat().st_size > 20_000 for p in paths)
    out = plot_comparison({"full": full, "bare": bare}, tmp_path / "cmp" / "compare.png")
    assert out.is_file() and out.stat().st_size > 20_000
    paper = SimpleNamespace(t=np.arange(3) * T, signals={"q_true": np.zeros((3, 5))}, meta={"controller": "rac"})
    with pytest.raises(ValueError, match="not supported"):
        plot_comparison({"full": full, "paper": paper}, tmp_path / "mixed.png")


def test_robot_model_file_fallbacks(alpha) -> None:
    from uvms_mj.analysis.render import _robot_file

    robot = dict(alpha[1].meta["robot"], path="/nonexistent/bluerov2_alpha.xml")
    assert _robot_file(robot, None).name == "bluerov2_alpha.xml"  # the built-in of that name
    with pytest.raises(ValueError, match="model_path"):
        _robot_file(dict(robot, name="my_rov"), None)
