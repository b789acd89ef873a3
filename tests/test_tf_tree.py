"""/tf is the model's kinematic tree (issue 22 item 4): in a short run's log, for the paper's robot and
bluerov2_alpha, every body's frame has its parent body as parent frame (the root ``world``, above it a fixed
``view``), and composing the logged chain of transforms from ``world`` gives the body's world pose that MuJoCo's
own kinematics (``mj_kinematics`` on the logged ``q_true``, a fresh MjData) gives.

Tolerance 1e-9 m / rad: the logged numbers are float64 written as shortest round-trip reprs (exact), and a
chain of at most ~7 float64 rigid transforms of unit quaternions and positions below ~10 m loses a few ulps
per step (~1e-15 relative), so 1e-9 leaves six orders of margin while catching any wrong parent or frame
(errors of centimetres / tenths of a radian)."""

from __future__ import annotations

import json

import mujoco
import numpy as np
import pytest
from click.testing import CliRunner

from uvms_mj.cli.main import main as cli
from uvms_mj.io.recorder import iter_messages, read_log
from uvms_mj.scenario.packaged import resolve_scenario
from uvms_mj.scenario.schema import build, load_scenario

TOL = 1e-9  # m and rad (module docstring)


def _quat_mat(q_wxyz) -> np.ndarray:
    m = np.empty(9)
    mujoco.mju_quat2Mat(m, np.asarray(q_wxyz, dtype=float))
    return m.reshape(3, 3)


@pytest.fixture(scope="module", params=["paper", "bluerov2_alpha_station"])
def short_log(request, tmp_path_factory):
    path = tmp_path_factory.mktemp("tf") / f"{request.param}.mcap"
    res = CliRunner().invoke(cli, ["run", request.param, "--set", "duration=0.5", "--no-plots", "--no-video",
                                   "-o", str(path)])
    assert res.exit_code == 0, res.output
    log = read_log(path)
    tfs = [json.loads(m.data)["transforms"] for c, _, m in iter_messages(path) if c.topic == "/tf"]
    plant, _ = build(load_scenario(resolve_scenario(request.param), ["duration=0.5"]))
    return plant.model, log, tfs


def test_parents_are_the_models_parent_bodies(short_log) -> None:
    m, log, tfs = short_log
    parents = {m.body(b).name: m.body(int(m.body_parentid[b])).name for b in range(1, m.nbody)}
    parents = {c: ("world" if p == m.body(0).name else p) for c, p in parents.items()}
    assert len(tfs) == len(log.t) > 10
    for tr in tfs:
        got = {x["child_frame_id"]: x["parent_frame_id"] for x in tr}
        assert got.pop("world") == "view"
        got.pop("tip", None)  # the paper's tip site frame (below link2)
        assert got == parents


def test_composed_chain_is_mujocos_world_pose(short_log) -> None:
    m, log, tfs = short_log
    d = mujoco.MjData(m)
    for k in (0, len(tfs) // 2, len(tfs) - 1):
        d.qpos[:] = log.signals["q_true"][k]
        mujoco.mj_kinematics(m, d)
        by_child = {x["child_frame_id"]: x for x in tfs[k]}
        for b in range(1, m.nbody):
            frame, pos, rot = m.body(b).name, np.zeros(3), np.eye(3)
            chain = []
            while frame != "world":
                chain.append(by_child[frame])
                frame = by_child[frame]["parent_frame_id"]
            for x in reversed(chain):  # from the world down: T = T_parent * T_rel
                t = np.array([x["translation"][c] for c in "xyz"])
                r = _quat_mat([x["rotation"][c] for c in "wxyz"])
                pos, rot = pos + rot @ t, rot @ r
            np.testing.assert_allclose(pos, d.xpos[b], rtol=0, atol=TOL, err_msg=m.body(b).name)
            np.testing.assert_allclose(rot, d.xmat[b].reshape(3, 3), rtol=0, atol=TOL, err_msg=m.body(b).name)
