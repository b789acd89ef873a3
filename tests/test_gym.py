"""Gymnasium registration of the environments (uvms_mj.rl.gym, the [gym] extra)."""

import numpy as np
import pytest

gymnasium = pytest.importorskip("gymnasium")
pytest.importorskip("shimmy")

import uvms_mj.rl.gym as ugym  # noqa: E402
from gymnasium.utils.env_checker import check_env  # noqa: E402


@pytest.mark.parametrize("residual", [False, True])
@pytest.mark.filterwarnings("error:.*symmetric and normalized space")
def test_check_env(residual):
    env_id = next(k for k, v in ugym.ENV_IDS.items() if v == residual)
    env = gymnasium.make(env_id, time_limit=0.5)
    try:
        check_env(env.unwrapped, skip_render_check=True)
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
    obs, _ = env.reset(seed=0)
    assert {"tip", "target", "base_pose"} <= set(obs)
    n, truncated, terminated = 0, False, False
    while not (truncated or terminated):
        obs, r, terminated, truncated, _ = env.step(np.zeros(5))
        n += 1
        assert np.isfinite(r)
    assert truncated and not terminated and n == 12  # 0.2 s at 60 Hz
    env.close()


def test_residual_zero_action_is_rac_dob():
    """A zero residual in [-1, 1] is zero in the residual's symmetric bounds: the rac_dob command."""
    env = gymnasium.make("uvms_mj/TrackingResidual-v0", time_limit=0.5)
    obs, _ = env.reset(seed=1)
    for _ in range(10):
        obs, *_ = env.step(np.zeros(5))
    from uvms_mj.rl import env as uvms_env

    dm = uvms_env.load(residual=True, time_limit=0.5, random=1)
    ts = dm.reset()
    for _ in range(10):
        ts = dm.step(np.zeros(5))
    np.testing.assert_allclose(obs["tip"], ts.observation["tip"], rtol=0, atol=1e-12)
    env.close()


def test_module_style_id():
    env = gymnasium.make("uvms_mj.rl.gym:uvms_mj/Tracking-v0", time_limit=0.1)
    assert env.action_space.shape == (5,)
    env.close()


def test_rgb_array_render():
    """render_mode="rgb_array" (dm_control's renderer) in a fresh process, where importing
    uvms_mj first chooses the headless backend (here mujoco was imported before uvms_mj)."""
    import os
    import subprocess
    import sys

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
