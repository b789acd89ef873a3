"""The dm_control environment (uvms_mj.rl.env): dm_env conformance, the physics is the plant
(hydrodynamics included, stepping bit for bit), a zero residual is run_closed_loop with rac_dob
bit for bit, specs from the model, determinism, divergence handling."""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import dm_env
import mujoco
import numpy as np
import pytest
from absl.testing import absltest
from dm_env import test_utils

from uvms_mj import Plant

with warnings.catch_warnings():
    # dm_control probes GLFW when it is imported; headless (conftest imports mujoco before
    # uvms_mj can choose MUJOCO_GL) that only warns about DISPLAY. These tests do not render.
    warnings.simplefilter("ignore")
    from uvms_mj.rl import env as uvms_env
from uvms_mj.control.digital import PAPER_T
from uvms_mj.sim.experiment import PaperExperiment
from uvms_mj.sim.loop import SensorModel, run_closed_loop
from uvms_mj.scenario.schema import build, validate_scenario

OBS_SHAPES = {"base_pose": 3, "joint_angles": 2, "base_velocity": 3, "joint_velocities": 2, "tip": 2,
              "target": 2, "goal": 2, "time_to_go": 1, "thrust": 3}


# --------------------------------------------------------------------------- dm_env conformance


class _Conformance(test_utils.EnvironmentTestMixin):
    """dm_env's own contract tests; 0.1 s episodes (6 steps) so that the 20-action sequence
    crosses several episode ends."""

    residual = False
    scale = 1.0

    def make_object_under_test(self):
        return uvms_env.load(residual=self.residual, time_limit=0.1, random=0)

    def make_action_sequence(self):
        spec = self.environment.action_spec()
        rng = np.random.default_rng(1)
        for _ in range(20):
            yield self.scale * rng.uniform(spec.minimum, spec.maximum)


class PlainEnvConformanceTest(_Conformance, absltest.TestCase):
    pass


class ResidualEnvConformanceTest(_Conformance, absltest.TestCase):
    residual = True
    scale = 0.05


# --------------------------------------------------------------------------- zero residual = rac_dob


def _rollout(env, actions=None):
    """Observations of one episode (FIRST included) and the LAST time step."""
    ts = env.reset()
    obs = [ts.observation]
    zero = np.zeros(env.action_spec().shape)
    k = 0
    while not ts.last():
        ts = env.step(zero if actions is None else actions[k])
        obs.append(ts.observation)
        k += 1
    return {key: np.array([o[key] for o in obs]) for key in obs[0]}, ts


def _assert_same_run(obs, res):
    s = res.signals
    assert res.status == "ok"
    assert obs["base_pose"].shape[0] == s["q_true"].shape[0]
    # Bit for bit: same plant configuration, same measurements, same warm start, same stepping --
    # the same code on both sides (the controller object, mj_step; the loop's compiled sample only
    # copies), so no operation order that could differ with the CPU's vector instructions.
    np.testing.assert_array_equal(np.c_[obs["base_pose"], obs["joint_angles"]], s["q_true"])
    np.testing.assert_array_equal(np.c_[obs["base_velocity"], obs["joint_velocities"]], s["qd_true"])
    np.testing.assert_array_equal(obs["tip"], s["tip_true"])
    np.testing.assert_array_equal(obs["thrust"][1:], s["thrust_force"][1:])  # [0]: before the warm start
    np.testing.assert_array_equal(obs["base_command"], np.c_[s["thrust_command"], s["torques"]])


def test_zero_residual_reproduces_rac_dob_paper_experiment():
    # 4 s: through the start of the path (1 s) and Eq. 12's singular handling (|det B| = Js at 2.1 s).
    duration = 4.0
    env = uvms_env.load(residual=True, scenario=PaperExperiment(duration=duration), random=0)
    obs, last = _rollout(env)
    plant, ctrl = PaperExperiment(duration=duration).build()
    assert ctrl.name == "rac_dob"
    res = run_closed_loop(plant, ctrl, duration, T=ctrl.T)
    _assert_same_run(obs, res)
    assert last.discount == 1.0
    assert obs["base_pose"].shape[0] == round(duration / PAPER_T) + 1
    np.testing.assert_allclose(obs["target"], res.signals["p_desired"][:, 3:5], rtol=0, atol=1e-15)


def test_zero_residual_reproduces_rac_dob_with_noisy_delayed_sensor():
    # The controller's measurements go through the scenario's sensor model, with the episode's
    # generator: run_closed_loop(seed=task.sensor_seed) draws the same noise.
    sc = validate_scenario({"sensors": {"position_noise": 1e-4, "angle_noise": 1e-4, "delay": 1}}, "test")
    env = uvms_env.load(residual=True, scenario=sc, time_limit=1.5, random=7)
    obs, _ = _rollout(env)
    seed = env.task.sensor_seed
    plant, ctrl = build(sc)
    s = sc.sensors
    sensor = SensorModel(position_noise=s.position_noise, angle_noise=s.angle_noise, delay=s.delay)
    _assert_same_run(obs, run_closed_loop(plant, ctrl, 1.5, T=ctrl.T, sensor=sensor, seed=seed))


def test_residual_changes_the_run():
    env = uvms_env.load(residual=True, time_limit=0.5, random=0)
    base, _ = _rollout(env)
    n = base["tip"].shape[0] - 1
    pushed, _ = _rollout(env, [np.array([0.0, 0.0, 0.0, 0.5, 0.0])] * n)
    assert np.max(np.abs(pushed["joint_angles"] - base["joint_angles"])) > 1e-3
    np.testing.assert_array_equal(pushed["base_pose"][0], base["base_pose"][0])


# --------------------------------------------------------------------------- the physics is the plant


@pytest.mark.parametrize("integrator", ["rk4", "euler"])
@pytest.mark.parametrize("legacy_step", [True, False])
def test_physics_step_equals_plant_step(integrator, legacy_step):
    # dm_control's legacy step would run mj_step2/mj_step1 for Euler; ours is mj_step always
    # (plus a state-neutral mj_step1 with legacy_step): bit for bit the plant's own stepping.
    sc = validate_scenario({"physics": {"integrator": integrator}}, "test")
    env = uvms_env.load(scenario=sc, time_limit=1.0, legacy_step=legacy_step)
    env.reset()
    physics = env.physics
    assert isinstance(physics, uvms_env.Physics) and physics.data.ptr is physics.plant.data
    ref, _ = build(sc)
    rng = np.random.default_rng(3)
    q0 = physics.plant.q + rng.uniform(-0.2, 0.2, 5)
    qd0 = rng.uniform(-0.3, 0.3, 5)
    for p in (physics.plant, ref):
        p.set_state(base_pose=q0[:3], joint_angles=q0[3:], base_velocity=qd0[:3], joint_velocities=qd0[3:])
    for _ in range(5):
        u = rng.uniform(-3, 3, 5)
        for p in (physics.plant, ref):
            p.set_thrust(u[:3])
            p.set_joint_torques(u[3:])
        physics.step(2)
        ref.step(2)
        np.testing.assert_array_equal(physics.data.qpos, ref.data.qpos)
        np.testing.assert_array_equal(physics.data.qvel, ref.data.qvel)
        np.testing.assert_array_equal(physics.data.act, ref.data.act)
        assert physics.data.time == ref.data.time


def test_physics_includes_added_mass():
    # A generalized force F on the base's x slide changes the acceleration by M^-1 F e_x with M the
    # plant's mass matrix, added mass included (for the base alone: F / (m + m_A)), not the rigid one.
    env = uvms_env.load(time_limit=1.0)
    env.reset()
    physics = env.physics
    plant = physics.plant
    m = plant.model
    physics.forward()
    a0 = physics.data.qacc.copy()
    F = 5.0
    physics.data.qfrc_applied[0] = F
    physics.forward()
    da = physics.data.qacc - a0
    physics.data.qfrc_applied[0] = 0.0
    M = plant.mass_matrix()
    rigid_data = mujoco.MjData(m)
    rigid_data.qpos[:] = physics.data.qpos
    mujoco.mj_fwdPosition(m, rigid_data)  # no passive stage: MuJoCo's rigid mass matrix only
    M_rigid = np.zeros((5, 5))
    mujoco.mj_fullM(m, rigid_data, M_rigid)
    e = np.eye(5)[0]
    np.testing.assert_allclose(da, np.linalg.solve(M, F * e), rtol=1e-9, atol=1e-12)
    assert M[0, 0] - M_rigid[0, 0] > 1.0  # the base's added mass along x (kg)
    assert da[0] < 0.9 * np.linalg.solve(M_rigid, F * e)[0]


def test_physics_copy_is_served_by_the_plant():
    env = uvms_env.load(time_limit=1.0)
    env.reset()
    physics = env.physics
    physics.plant.set_thrust([3.0, -2.0, 1.0])
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # an unregistered data of the plant's model would warn
        twin = physics.copy()
        assert twin.data.ptr is not physics.data.ptr and not twin.owns_plant_data
        physics.step(4)
        twin.step(4)
    np.testing.assert_array_equal(twin.data.qpos, physics.data.qpos)
    np.testing.assert_array_equal(twin.data.qvel, physics.data.qvel)
    with pytest.raises(ValueError, match="share_model"):
        physics.copy(share_model=False)


def test_plant_attach_data():
    plant = Plant()
    other = Plant()
    served = plant.attach_data(mujoco.MjData(plant.model))
    assert plant.attach_data(served) is served and plant.attach_data(plant.data) is plant.data
    ref = plant.make_data()
    for d in (served, ref):
        mujoco.mj_resetDataKeyframe(plant.model, d, 0)
        d.ctrl[:3] = [4.0, 1.0, -2.0]
        mujoco.mj_step(plant.model, d, 10)
    np.testing.assert_array_equal(served.qpos, ref.qpos)
    with pytest.raises(ValueError, match="plant.model"):
        plant.attach_data(mujoco.MjData(other.model))
    with pytest.raises(TypeError):
        plant.attach_data(plant.model)


# --------------------------------------------------------------------------- specs, episodes


def test_specs_match_the_model():
    env = uvms_env.load(time_limit=0.5, random=0)
    plant = env.physics.plant
    m = plant.model
    spec = env.action_spec()
    assert spec.shape == (5,) and spec.dtype == np.float64
    assert spec.name.split("\t") == [m.actuator(i).name for i in range(m.nu)]
    np.testing.assert_array_equal(spec.minimum[:3], m.actuator_ctrlrange[:3, 0])
    np.testing.assert_array_equal(spec.maximum[:3], m.actuator_ctrlrange[:3, 1])
    assert spec.minimum[0] == -8.849 and spec.maximum[0] == 15.978  # asymmetric
    np.testing.assert_array_equal(spec.minimum[3:], -uvms_env.DEFAULT_TORQUE_LIMIT)
    np.testing.assert_array_equal(spec.maximum[3:], uvms_env.DEFAULT_TORQUE_LIMIT)
    obs_spec = env.observation_spec()
    assert {k: s.shape for k, s in obs_spec.items()} == {k: (n,) for k, n in OBS_SHAPES.items()}
    assert env.control_timestep() == pytest.approx(PAPER_T, abs=1e-15)
    assert env.physics.timestep() == pytest.approx(PAPER_T / 2, abs=1e-15)

    res = uvms_env.load(residual=True, time_limit=0.5)
    rspec = res.action_spec()
    span = m.actuator_ctrlrange[:3, 1] - m.actuator_ctrlrange[:3, 0]
    np.testing.assert_array_equal(rspec.maximum, np.r_[span, 20.0, 20.0])
    np.testing.assert_array_equal(rspec.minimum, -rspec.maximum)
    assert set(res.observation_spec()) == set(OBS_SHAPES) | {"base_command"}


def test_random_episode_rewards_and_time_limit():
    time_limit = 1.0
    env = uvms_env.load(time_limit=time_limit, random=0)
    spec = env.action_spec()
    rng = np.random.default_rng(0)
    ts = env.reset()
    assert ts.first()
    np.testing.assert_array_equal(ts.observation["base_pose"],
                                  [0.0, 0.0, -np.pi / 2])  # the paper's initial state
    np.testing.assert_array_equal(ts.observation["time_to_go"], [time_limit])
    rewards, steps = [], 0
    while not ts.last():
        ts = env.step(rng.uniform(spec.minimum, spec.maximum))
        rewards.append(ts.reward)
        steps += 1
        for key, s in env.observation_spec().items():
            s.validate(ts.observation[key])
            assert np.all(np.isfinite(ts.observation[key]))
    assert steps == round(time_limit / PAPER_T)
    assert ts.discount == 1.0 and ts.observation["time_to_go"][0] == pytest.approx(0.0, abs=1e-12)
    assert all(math.isfinite(r) and r <= 0 for r in rewards)
    assert env.step(np.zeros(5)).first()


def test_flat_observation():
    env = uvms_env.load(residual=True, time_limit=0.1, flat_observation=True)
    spec = env.observation_spec()["observations"]
    assert spec.shape == (sum(OBS_SHAPES.values()) + 5,)
    spec.validate(env.reset().observation["observations"])
    spec.validate(env.step(np.zeros(5)).observation["observations"])


def test_reward_formula():
    w = uvms_env.RewardWeights(tip=2.0, base=0.3, attitude=0.7)
    env = uvms_env.load(time_limit=1.0, reward_weights=w)
    env.reset()
    ts = env.step(np.array([5.0, 5.0, 2.0, 1.0, -1.0]))
    o = ts.observation
    e_tip = np.linalg.norm(o["tip"] - o["target"])
    e_base = np.linalg.norm(o["base_pose"][:2])  # initial base position (0, 0)
    e_att = abs(o["base_pose"][2] + np.pi / 2)
    assert ts.reward == pytest.approx(-(2.0 * e_tip + 0.3 * e_base + 0.7 * e_att), rel=1e-12)


def test_deterministic_given_seed():
    sc = validate_scenario({"sensors": {"position_noise": 1e-4}}, "test")
    actions = list(0.05 * np.random.default_rng(5).uniform(-1, 1, (30, 5)))
    runs = []
    for _ in range(2):
        env = uvms_env.load(residual=True, scenario=sc, time_limit=0.5, random=11)
        runs.append([_rollout(env, actions)[0] for _ in range(2)])  # two episodes each
    for a, b in zip(runs[0], runs[1]):
        for key in a:
            np.testing.assert_array_equal(a[key], b[key])
    # Each episode draws its own sensor noise.
    assert not np.array_equal(runs[0][0]["base_command"], runs[0][1]["base_command"])


def test_divergence_ends_the_episode():
    env = uvms_env.load(residual=True, time_limit=1.0, random=0)
    env.reset()
    env.physics.data.qvel[3] = 1e3  # runaway: above the plant's max_speed
    ts = env.step(np.zeros(5))
    assert ts.last() and ts.discount == 0.0 and ts.reward == -100.0
    assert isinstance(env.physics.divergence, Exception)
    assert all(np.all(np.isfinite(v)) for v in ts.observation.values())
    ts = env.step(np.zeros(5))  # the next step starts a new, healthy episode
    assert ts.step_type is dm_env.StepType.FIRST and env.physics.divergence is None
    assert env.step(np.zeros(5)).mid()


def test_bad_arguments():
    with pytest.raises(ValueError, match="time_limit"):
        uvms_env.load(time_limit=0.001)
    with pytest.raises(TypeError, match="scenario"):
        uvms_env.load(scenario=3)
    env = uvms_env.load(time_limit=1.0)
    env.reset()
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(4))
    with pytest.raises(ValueError, match="finite"):
        env.step(np.full(5, np.nan))


def test_scenario_file_source():
    path = Path(__file__).resolve().parents[1] / "scenarios" / "paper.yaml"
    env = uvms_env.load(scenario=path, time_limit=0.1)
    default = uvms_env.load(time_limit=0.1)
    assert env.task.trajectory == default.task.trajectory
    assert env.reset().observation["goal"].tolist() == list(default.task.trajectory.target[:2])  # the plane
