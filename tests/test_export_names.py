"""Named export columns (uvms_mj.io.columns, uvms_mj.io.export) and read_log(as_dataframe=True):
column names against the model's joint, thruster and motor names read from the MJCF with mujoco
alone, values against the log's arrays, on a paper log and a BlueROV2 + Alpha log."""

from __future__ import annotations

import json

import mujoco
import numpy as np
import pytest
from click.testing import CliRunner

from uvms_mj.cli.main import main
from uvms_mj.io.columns import component_names
from uvms_mj.io.export import export_log, tables
from uvms_mj.io.reader import read_log
from uvms_mj.plant.files import default_model_path, robot_path
from uvms_mj.scenario.packaged import scenarios_dir

pd = pytest.importorskip("pandas")


def _run(tmp_path_factory, scenario: str, duration: str) -> str:
    out = tmp_path_factory.mktemp("names") / f"{scenario}.mcap"
    result = CliRunner().invoke(main, ["run", scenario, "-o", str(out), "--no-plots", "--set", f"duration={duration}"])
    assert result.exit_code == 0, result.output
    return str(out)


@pytest.fixture(scope="module")
def paper_log(tmp_path_factory):
    return _run(tmp_path_factory, "paper", "0.2")


@pytest.fixture(scope="module")
def robot_log(tmp_path_factory):
    return _run(tmp_path_factory, "bluerov2_alpha_circle_current", "0.2")


def _mjcf(path) -> dict:
    """Names and addresses read from the model file with mujoco alone."""
    m = mujoco.MjModel.from_xml_path(str(path))
    free = [j for j in range(m.njnt) if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE]
    base_joints = free or [j for j in range(m.njnt) if m.jnt_bodyid[j] == m.jnt_bodyid[0]]
    joints = [j for j in range(m.njnt) if j not in base_joints]
    site = [a for a in range(m.nu) if m.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_SITE]
    return {"joints": {m.joint(j).name: (int(m.jnt_qposadr[j]), int(m.jnt_dofadr[j])) for j in joints},
            "thrusters": [m.actuator(a).name for a in site],
            "motors": [m.actuator(a).name for a in range(m.nu) if a not in site]}


def test_robot_log_columns_named_by_the_model(robot_log):
    log = read_log(robot_log)
    sc = log.meta["scenario"]
    model = _mjcf(robot_path(sc["robot"], str(scenarios_dir())))
    df = read_log(robot_log, as_dataframe=True)
    assert df.index.name == "t" and len(df) == len(log.t) == 11  # 0.2 s at T = 0.02 s
    np.testing.assert_array_equal(df.index.to_numpy(), log.t)
    for joint, (qadr, dadr) in model["joints"].items():
        np.testing.assert_array_equal(df[f"q_true[{joint}]"].to_numpy(), log.signals["q_true"][:, qadr])
        np.testing.assert_array_equal(df[f"qd_true[{joint}]"].to_numpy(), log.signals["qd_true"][:, dadr])
    for i, name in enumerate(model["thrusters"]):
        np.testing.assert_array_equal(df[f"thrust_force[{name}]"].to_numpy(), log.signals["thrust_force"][:, i])
        np.testing.assert_array_equal(df[f"thrust_saturated[{name}]"].to_numpy(),
                                      log.signals["thrust_saturated"][:, i])
    assert df["thrust_saturated[" + model["thrusters"][0] + "]"].dtype == bool
    for i, name in enumerate(model["motors"]):
        np.testing.assert_array_equal(df[f"torques[{name}]"].to_numpy(), log.signals["torques"][:, i])
    # the free joint: world position, then the attitude quaternion (qpos 0..6); qvel v world, omega body
    for i, c in enumerate(["x", "y", "z", "qw", "qx", "qy", "qz"]):
        np.testing.assert_array_equal(df[f"q_true[base_{c}]"].to_numpy(), log.signals["q_true"][:, i])
    for i, c in enumerate(["vx", "vy", "vz", "wx", "wy", "wz"]):
        np.testing.assert_array_equal(df[f"qd_true[base_{c}]"].to_numpy(), log.signals["qd_true"][:, i])
    for i, c in enumerate("xyz"):
        np.testing.assert_array_equal(df[f"tip_true[{c}]"].to_numpy(), log.signals["tip_true"][:, i])
    assert [c for c in df.columns if c.startswith("e_p[")] == [
        f"e_p[{n}]" for n in ("base_x", "base_y", "base_z", "base_roll", "base_pitch", "base_yaw",
                              "tip_x", "tip_y", "tip_z")]
    assert [c for c in df.columns if c.startswith("u_B[")] == [f"u_B[{n}]" for n in
                                                                ("fx", "fy", "fz", "mx", "my", "mz")]
    assert not [c for c in df.columns if c[-3:-1] == "[0" or "[0]" in c]  # every component has a name
    assert df.attrs["status"] == "ok" and df.attrs["meta"]["controller"] == "rac_dob"
    # every signal's every component is a column, once
    n = sum(int(np.prod(a.shape[1:])) for a in log.signals.values())
    assert df.shape[1] == n and df.columns.is_unique


def test_paper_log_columns(paper_log, tmp_path):
    log = read_log(paper_log)
    model = _mjcf(default_model_path())
    assert list(model["joints"]) == ["joint1", "joint2"]
    df = read_log(paper_log, as_dataframe=True)
    names = component_names(log)
    assert names["q_true"] == ["base_x", "base_y", "base_yaw", *model["joints"]]
    assert names["thrust_force"] == model["thrusters"] and names["torques"] == model["motors"]
    assert names["tip_true"] == ["x", "y"] and names["u_B"] == ["fx", "fy", "mz"]
    assert names["p_desired"] == ["base_x", "base_y", "base_yaw", "tip_x", "tip_y"]
    for i, name in enumerate(names["q_true"]):
        np.testing.assert_array_equal(df[f"q_true[{name}]"].to_numpy(), log.signals["q_true"][:, i])
    for i, name in enumerate(model["thrusters"]):
        np.testing.assert_array_equal(df[f"thrust_command[{name}]"].to_numpy(), log.signals["thrust_command"][:, i])
    np.testing.assert_array_equal(df["p_desired[tip_y]"].to_numpy(), log.signals["p_desired"][:, 4])
    np.testing.assert_array_equal(df["det_B"].to_numpy(), log.signals["det_B"])  # a scalar: its own name
    # the CSV export has the same columns (t first) and values; parquet keeps them too
    out = export_log(log, "csv", tmp_path / "p.csv")[0]
    back = pd.read_csv(out, index_col="t")
    assert list(back.columns) == list(df.columns)
    np.testing.assert_allclose(back.to_numpy(dtype=float), df.to_numpy(dtype=float), rtol=0, atol=0)
    pytest.importorskip("pyarrow")
    pq = pd.read_parquet(export_log(log, "parquet", tmp_path / "p.parquet")[0])
    assert list(pq.columns) == ["t", *df.columns]


def test_fallback_to_the_index(robot_log, tmp_path):
    """A signal not in the table, or a log without a layout, keeps x[i]; --columns index everywhere;
    npz carries columns_json (null for unknown signals)."""
    log = read_log(robot_log)
    log.signals["my_signal"] = np.zeros((len(log.t), 2))
    log.signals["torques_wrong_size"] = np.zeros((len(log.t), 3))
    cols = tables(log)["wide"]
    assert "my_signal[0]" in cols and "my_signal[1]" in cols
    log.signals["torques"] = np.zeros((len(log.t), 3))  # not the layout's 4 motors
    assert "torques[0]" in tables(log)["wide"]
    assert "q_true[0]" in tables(log, columns="index")["wide"]
    log.meta = {}
    assert "q_true[0]" in tables(log)["wide"]
    z = np.load(export_log(read_log(robot_log), "npz", tmp_path / "r.npz")[0])
    names = json.loads(str(z["columns_json"]))
    assert names["q_true"][7:] == list(_mjcf(robot_path("bluerov2_alpha", str(scenarios_dir())))["joints"])
    assert names["manipulability"] is None
    with pytest.raises(ValueError, match="columns"):
        tables(log, columns="bogus")
