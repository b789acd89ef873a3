"""Gymnasium registration and environments (uvms_mj.rl.gym, the [gym] extra) on the paper's robot
and the BlueROV2 + Alpha: check_env for each id, normalised actions, named observations, the ids
registered by `import uvms_mj` (either import order), vectorised environments over processes,
one-line errors for bad scenarios."""

import os
import subprocess
import sys

import numpy as np
import pytest

gymnasium = pytest.importorskip("gymnasium")
pytest.importorskip("shimmy")

import uvms_mj.rl.gym as ugym  # noqa: E402
from gymnasium.utils.env_checker import check_env  # noqa: E402

CIRCLE = "bluerov2_alpha_circle_current"


@pytest.mark.parametrize("scenario", [None, CIRCLE])
@pytest.mark.parametrize("env_id", sorted(ugym.ENV_IDS))
@pytest.mark.filterwarnings("error:.*symmetric and normalized space")
def test_check_env(env_id, scenario):
    kwargs = {} if scenario is None else {"scenario": scenario}
    env = gymnasium.make(env_id, time_limit=0.2, **kwargs)
    try:
        check_env(env.unwrapped, skip_render_check=True)
        n = 12 if scenario else 5
        assert env.action_space.shape == (n,) and len(env.unwrapped.action_names) == n
        names = env.unwrapped.observation_names
        assert set(env.observation_space.spaces) == set(names)
        for key, space in env.observation_space.spaces.items():
            assert space.shape == (len(names[key]),)
    finally:
        env.close()


def test_normalised_actions_and_bounds():
    env = gymnasium.make("uvms_mj/Tracking-v0", time_limit=0.2)
    space = env.action_space
    assert space.shape == (5,)
    np.testing.assert_array_equal(space.low, -1.0)
    np.testing.assert_array_equal(space.high, 1.0)
    # -1 and +1 map to the dm_control bounds: thrust -8.849 / +15.978 N, torque +-20 N m
    low, high = env.unwrapped.action_low, env.unwrapped.action_high
    assert low[0] == pytest.approx(-8.849) and high[0] == pytest.approx(15.978)
    assert high[3] == pytest.approx(20.0)
    assert env.unwrapped.action_names == ["thruster1", "thruster2", "thruster3", "joint1", "joint2"]
    assert env.unwrapped.observation_names["base_pose"] == ["x", "y", "yaw"]
    obs, _ = env.reset(seed=0)
    assert {"tip", "target", "base_pose"} <= set(obs)
    n, truncated, terminated = 0, False, False
    while not (truncated or terminated):
        obs, r, terminated, truncated, _ = env.step(np.zeros(5))
        n += 1
        assert np.isfinite(r)
    assert truncated and not terminated and n == 12  # 0.2 s at 60 Hz
    env.close()


def test_3d_normalised_action_maps_to_thrust_and_torque():
    """+1 is each thruster's full force (the T200's 30.622 N) and each motor's ctrlrange bound;
    the plant receives those (set_thrust maps newtons to the thruster's command through its curve)."""
    env = gymnasium.make("uvms_mj/Tracking-v0", scenario=CIRCLE, time_limit=0.1)
    u = env.unwrapped
    np.testing.assert_array_equal(u.action_high, np.r_[np.full(8, 30.622), 9.0, 9.0, 9.0, 5.0])
    np.testing.assert_array_equal(u.action_low, -u.action_high)
    env.reset(seed=0)
    a = np.r_[np.linspace(-1, 1, 8), 0.5, -0.5, 0.0, 1.0]
    env.step(a)
    plant = u._env.physics.plant
    expected = 0.5 * (a + 1) * (u.action_high - u.action_low) + u.action_low
    np.testing.assert_allclose(plant.data.ctrl[plant.layout.motor_ids], expected[8:], rtol=0, atol=1e-12)
    np.testing.assert_allclose(plant.thrust_to_ctrl(expected[:8]), plant.data.ctrl[plant.layout.thruster_ids],
                               rtol=0, atol=1e-12)
    env.close()


def test_residual_zero_action_is_the_controller():
    """A zero residual in [-1, 1] is zero in the residual's symmetric bounds: the controller's command."""
    for scenario, n in ((None, 5), (CIRCLE, 12)):
        kwargs = {} if scenario is None else {"scenario": scenario}
        env = gymnasium.make("uvms_mj/TrackingResidual-v0", time_limit=0.5, **kwargs)
        obs, _ = env.reset(seed=1)
        for _ in range(10):
            obs, *_ = env.step(np.zeros(n))
        from uvms_mj.rl import env as uvms_env

        dm = uvms_env.load(residual=True, time_limit=0.5, random=1, **kwargs)
        ts = dm.reset()
        for _ in range(10):
            ts = dm.step(np.zeros(n))
        np.testing.assert_allclose(obs["tip"], ts.observation["tip"], rtol=0, atol=1e-12)
        env.close()


def test_module_style_id():
    env = gymnasium.make("uvms_mj.rl.gym:uvms_mj/Tracking-v0", time_limit=0.1)
    assert env.action_space.shape == (5,)
    env.close()


def _python(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("order", ["import uvms_mj, gymnasium", "import gymnasium, uvms_mj"])
def test_ids_registered_by_importing_uvms_mj(order):
    out = _python(f"{order}\n"
                  "env = gymnasium.make('uvms_mj/TrackingResidual-v0', scenario='bluerov2_alpha_station', "
                  "time_limit=0.1)\n"
                  "print(env.action_space.shape)\n")
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip() == "(12,)"


def test_importing_uvms_mj_imports_no_gymnasium():
    out = _python("import sys, uvms_mj\n"
                  "print(sorted(m for m in ('gymnasium', 'dm_control', 'shimmy', 'mujoco') if m in sys.modules))\n")
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip() == "[]"


def test_bad_scenarios_give_one_line(tmp_path):
    from uvms_mj.scenario.schema import ScenarioError

    with pytest.raises(ScenarioError, match="'nosuch': no such file, nor a packaged scenario") as exc:
        gymnasium.make("uvms_mj/Tracking-v0", scenario="nosuch")
    assert "\n" not in str(exc.value) and len(str(exc.value)) < 600
    bad = tmp_path / "bad.yaml"
    bad.write_text("robot: bluerov2_alpha\ncontroler: {name: rac}\n")
    with pytest.raises(ScenarioError, match="bad.yaml.*controler") as exc:
        gymnasium.make("uvms_mj/Tracking-v0", scenario=str(bad))
    assert len(str(exc.value)) < 600


def test_make_vec_async_uses_processes():
    envs = gymnasium.make_vec("uvms_mj/Tracking-v0", num_envs=2, vectorization_mode="async",
                              scenario=CIRCLE, time_limit=0.1)
    try:
        assert isinstance(envs, gymnasium.vector.AsyncVectorEnv)
        pids = {p.pid for p in envs.processes}
        assert len(pids) == 2 and os.getpid() not in pids
        obs, _ = envs.reset(seed=0)
        assert obs["base_pose"].shape == (2, 7)
        obs, r, term, trunc, _ = envs.step(np.zeros((2, 12)))
        assert r.shape == (2,) and np.all(np.isfinite(r))
    finally:
        envs.close()


@pytest.mark.slow
def test_make_vec_spawn():
    """uvms_mj.rl.gym.make_vec's environment functions pickle: a spawned process builds its own."""
    envs = ugym.make_vec(2, residual=True, context="spawn", scenario="paper", time_limit=0.1)
    try:
        obs, _ = envs.reset(seed=0)
        assert obs["base_command"].shape == (2, 5)
        _, r, *_ = envs.step(np.zeros((2, 5)))
        assert np.all(np.isfinite(r))
    finally:
        envs.close()


def test_rgb_array_render():
    """render_mode="rgb_array" (dm_control's renderer) in a fresh process, where importing
    uvms_mj first chooses the headless backend (here mujoco was imported before uvms_mj)."""
    code = ("import gymnasium, uvms_mj.rl.gym\n"
            "env = gymnasium.make('uvms_mj/Tracking-v0', time_limit=0.1, render_mode='rgb_array')\n"
            "env.reset(seed=0); f = env.render()\n"
            "print(f.shape, float(f.std()))\n")
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM", "DISPLAY",
                                                           "WAYLAND_DISPLAY")}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    shape, std = out.stdout.strip().rsplit(" ", 1)
    assert shape == "(240, 320, 3)" and float(std) > 5  # not blank
