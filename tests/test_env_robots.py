"""The dm_control environment (uvms_mj.rl.env) on any robot: the BlueROV2 + Alpha studies built as
``uvms-mj run`` builds them, action bounds and names from the MJCF (read here with mujoco alone),
a zero residual reproducing run_closed_loop bit for bit, named observations, clear errors."""

from __future__ import annotations

import warnings

import mujoco
import numpy as np
import pytest
from dm_env import test_utils
from absl.testing import absltest

with warnings.catch_warnings():
    warnings.simplefilter("ignore")  # dm_control probes GLFW at import (headless: a DISPLAY warning)
    from uvms_mj.rl import env as uvms_env
from uvms_mj.scenario.packaged import resolve_scenario, scenarios_dir
from uvms_mj.scenario.schema import ScenarioError, build, load_scenario, sensor_model
from uvms_mj.sim.loop import run_closed_loop

CIRCLE = "bluerov2_alpha_circle_current"


class RobotEnvConformanceTest(test_utils.EnvironmentTestMixin, absltest.TestCase):
    """dm_env's contract on the 3-D robot, residual mode; 0.1 s episodes (5 steps at T = 0.02 s)."""

    def make_object_under_test(self):
        return uvms_env.load(residual=True, scenario=CIRCLE, time_limit=0.1, random=0)

    def make_action_sequence(self):
        spec = self.environment.action_spec()
        rng = np.random.default_rng(1)
        for _ in range(12):
            yield 0.05 * rng.uniform(spec.minimum, spec.maximum)


def _mjcf_actuators(robot_xml):
    """(thruster names, motor names, {name: (ctrlrange or None, forcerange or None)}) read from the
    model file with mujoco alone (site transmission: thrusters; joint transmission: motors)."""
    m = mujoco.MjModel.from_xml_path(str(robot_xml))
    thr, mot, ranges = [], [], {}
    for a in range(m.nu):
        name = m.actuator(a).name
        (thr if m.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_SITE else mot).append(name)
        ranges[name] = (tuple(m.actuator_ctrlrange[a]) if m.actuator_ctrllimited[a] else None,
                        tuple(m.actuator_forcerange[a]) if m.actuator_forcelimited[a] else None)
    joints = [m.joint(j).name for j in range(m.njnt) if m.jnt_type[j] != mujoco.mjtJoint.mjJNT_FREE]
    return thr, mot, ranges, joints


def test_action_bounds_and_names_from_the_model():
    sc = load_scenario(resolve_scenario(CIRCLE))
    plant, _ = build(sc)
    xml = plant.model_path if hasattr(plant, "model_path") else None
    from uvms_mj.plant.files import robot_path

    thr, mot, ranges, joints = _mjcf_actuators(robot_path(sc.robot, sc.base_dir) if xml is None else xml)
    env = uvms_env.load(scenario=CIRCLE, time_limit=0.1)
    spec = env.action_spec()
    assert spec.name.split("\t") == thr + mot == env.task.action_names
    assert spec.shape == (len(thr) + len(mot),) == (12,)
    for i, name in enumerate(thr):  # a curve thruster: its force range (N), not the normalised ctrlrange
        assert (spec.minimum[i], spec.maximum[i]) == ranges[name][1]
    for i, name in enumerate(mot):  # the motor's ctrlrange (N m), inside the default +-20 N m
        lo, hi = ranges[name][0]
        assert (spec.minimum[len(thr) + i], spec.maximum[len(thr) + i]) == (max(lo, -20.0), min(hi, 20.0))
    np.testing.assert_array_equal(spec.maximum[:8], 30.622)  # models/bluerov2: the T200's +-30.622 N
    np.testing.assert_array_equal(spec.maximum[8:], [9.0, 9.0, 9.0, 5.0])  # models/alpha_arm
    names = env.task.observation_names
    assert names["joint_angles"] == names["joint_velocities"] == joints
    assert names["base_pose"] == ["x", "y", "z", "qw", "qx", "qy", "qz"]
    assert names["tip"] == names["target"] == ["x", "y", "z"]
    assert names["thrust"] == thr
    res = uvms_env.load(residual=True, scenario=CIRCLE, time_limit=0.1)
    assert res.task.observation_names["base_command"] == thr + mot
    obs = res.reset().observation
    assert {k: v.shape for k, v in obs.items()} == {k: (len(v),) for k, v in res.task.observation_names.items()}
    np.testing.assert_array_equal(res.action_spec().maximum[:8], 2 * 30.622)  # full authority
    np.testing.assert_array_equal(res.action_spec().maximum[8:], [9.0, 9.0, 9.0, 5.0])


@pytest.mark.parametrize("name", [CIRCLE, "bluerov2_alpha_station", "bluerov2_alpha_waves"])
def test_zero_residual_reproduces_the_cli_run(name):
    """The environment's plant and controller are those of `uvms-mj run` (scenario.build): a zero
    residual is run_closed_loop bit for bit (the same code on both sides: the controller object,
    mj_step, the same measurement draws)."""
    sc = load_scenario(resolve_scenario(name), ["duration=0.6"])
    env = uvms_env.load(residual=True, scenario=sc, random=3)
    ts = env.reset()
    obs = [ts.observation]
    while not ts.last():
        ts = env.step(np.zeros(env.action_spec().shape))
        obs.append(ts.observation)
    plant, ctrl = build(sc)
    res = run_closed_loop(plant, ctrl, sc.duration, T=ctrl.T, sensor=sensor_model(sc), seed=env.task.sensor_seed,
                          warm_start=sc.warm_start)
    s = res.signals
    assert res.status == "ok" and len(obs) == s["q_true"].shape[0] == 31  # 0.6 s at T = 0.02 s
    stack = lambda key: np.array([o[key] for o in obs])  # noqa: E731
    np.testing.assert_array_equal(np.c_[stack("base_pose"), stack("joint_angles")], s["q_true"])
    np.testing.assert_array_equal(np.c_[stack("base_velocity"), stack("joint_velocities")], s["qd_true"])
    np.testing.assert_array_equal(stack("tip"), s["tip_true"])
    np.testing.assert_array_equal(stack("thrust")[1:], s["thrust_force"][1:])
    np.testing.assert_array_equal(stack("base_command"), np.c_[s["thrust_command"], s["torques"]])


def test_reward_on_a_free_vehicle():
    """r = -(w_tip |e_tip| + w_base |p - p_ref| + w_att angle(q_ref^-1 q)), checked against the
    observation: the attitude angle from the quaternions' dot product (2 acos |<q, q_ref>|)."""
    w = uvms_env.RewardWeights(tip=2.0, base=0.3, attitude=0.7)
    env = uvms_env.load(scenario=CIRCLE, time_limit=0.2, reward_weights=w)
    o0 = env.reset().observation
    ts = env.step(np.r_[np.full(8, 10.0), np.zeros(4)])
    for _ in range(3):
        ts = env.step(np.r_[np.linspace(-20, 20, 8), 0.05, -0.05, 0.02, 0.01])  # small torques: a light arm
    o = ts.observation
    e_tip = np.linalg.norm(o["tip"] - o["target"])
    e_base = np.linalg.norm(o["base_pose"][:3] - o0["base_pose"][:3])
    e_att = 2 * np.arccos(min(1.0, abs(np.dot(o["base_pose"][3:], o0["base_pose"][3:]))))
    assert e_base > 1e-4 and e_att > 1e-4  # the thrust moved the vehicle
    assert ts.reward == pytest.approx(-(2.0 * e_tip + 0.3 * e_base + 0.7 * e_att), rel=1e-9)


def test_vehicle_without_arm_and_payload_episodes():
    env = uvms_env.load(scenario="bluerov2_heavy_current", time_limit=0.1)
    names = env.task.observation_names
    assert "joint_angles" not in names and "tip" not in names and env.action_spec().shape == (8,)
    assert set(env.reset().observation) == set(names)
    # a payload picked up at t: every episode starts from the model before the pick-up
    sc = load_scenario(resolve_scenario("bluerov2_alpha_payload"))
    t_pick = sc.plant.payload.t
    env = uvms_env.load(residual=True, scenario=sc, time_limit=t_pick + 0.1, random=0)
    m = env.physics.plant.model
    mass0 = m.body_mass.copy()
    for _ in range(2):
        ts = env.reset()
        np.testing.assert_array_equal(m.body_mass, mass0)
        while not ts.last():
            ts = env.step(np.zeros(12))
        assert m.body_mass.sum() > mass0.sum() + 0.4  # the 0.5 kg payload
    env.reset()
    np.testing.assert_array_equal(m.body_mass, mass0)


def test_scenario_names_and_errors(tmp_path):
    env = uvms_env.load(scenario="paper", time_limit=0.1)  # a packaged name, as `uvms-mj run paper`
    assert env.action_spec().shape == (5,)
    env = uvms_env.load(scenario=scenarios_dir() / f"{CIRCLE}.yaml", time_limit=0.1, sets=["controller.name=rac"])
    assert env.action_spec().shape == (12,)
    with pytest.raises(ScenarioError, match="nosuch.*no such file, nor a packaged scenario") as exc:
        uvms_env.load(scenario="nosuch")
    assert "\n" not in str(exc.value) and len(str(exc.value)) < 600
    bad = tmp_path / "bad.yaml"
    bad.write_text("robot: bluerov2_alpha\nduration: -1\n")
    with pytest.raises(ScenarioError, match="bad.yaml.*duration") as exc:
        uvms_env.load(scenario=bad)
    assert len(str(exc.value)) < 600
    with pytest.raises(TypeError, match="got int") as exc:
        uvms_env.load(scenario=3)
    with pytest.raises(ValueError, match="time_limit"):
        uvms_env.load(scenario=CIRCLE, time_limit=0.001)


def test_flat_observation_names():
    env = uvms_env.load(residual=True, scenario=CIRCLE, time_limit=0.1, flat_observation=True)
    names = env.task.flat_observation_names
    spec = env.observation_spec()["observations"]
    assert spec.shape == (len(names),) == (7 + 4 + 6 + 4 + 3 * 3 + 1 + 8 + 12,)
    assert names[:3] == ["base_pose.x", "base_pose.y", "base_pose.z"] and "joint_angles.alpha_elbow" in names
    flat = env.reset().observation["observations"]
    dict_env = uvms_env.load(residual=True, scenario=CIRCLE, time_limit=0.1)
    obs = dict_env.reset().observation
    np.testing.assert_array_equal(flat[names.index("tip.z")], obs["tip"][2])
    np.testing.assert_array_equal(flat[names.index("base_command.alpha_wrist")], obs["base_command"][11])
