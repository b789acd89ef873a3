"""Uniform water current (world frame, MuJoCo's opt.wind)."""

import mujoco
import numpy as np
import pytest

from uvms_mj import Plant

CURRENT = np.array([0.1, 0.05])


def neutral_plant(**kw) -> Plant:
    """Every body neutrally buoyant (rho V = m) with its centre of buoyancy at its centre of mass."""
    base = Plant()
    over = {f"{b.name}.volume": b.mass / base.params.rho for b in base.params.bodies}
    return Plant(overrides=over, current=CURRENT, **kw)


def test_drifting_with_the_current_feels_no_force():
    """Moving with the water (relative velocity 0, no rotation): no hydrodynamic force at all
    (1e-12), so the robot keeps drifting: q_ddot = 0."""
    plant = neutral_plant()
    plant.set_state(base_pose=(0.3, -0.2, 0.4), joint_angles=(0.5, -1.0), base_velocity=(*CURRENT, 0.0))
    mujoco.mj_forward(plant.model, plant.data)
    np.testing.assert_allclose(plant.data.qfrc_passive - plant.data.qfrc_bias, 0.0, atol=1e-12)
    np.testing.assert_allclose(plant.data.qacc, 0.0, atol=1e-12)


def test_body_at_rest_approaches_the_current_velocity():
    """From rest, drag carries the neutrally buoyant robot towards the current's velocity:
    the relative speed decreases monotonically (sampled each second) and is under 15 % of the
    current after 60 s. (Quadratic drag: v_rel ~ 1 / (1 + k t), not exponential.)"""
    plant = neutral_plant()
    plant.reset()
    rel = []
    for _ in range(60):
        plant.step(round(1 / plant.model.opt.timestep))
        rel.append(np.linalg.norm(plant.qd[:2] - CURRENT))
    assert rel[0] < np.linalg.norm(CURRENT)
    assert all(b <= a + 1e-9 for a, b in zip(rel, rel[1:]))
    assert rel[-1] < 0.15 * np.linalg.norm(CURRENT)


def test_current_is_model_wind():
    plant = Plant(current=(0.2, -0.1))
    np.testing.assert_array_equal(plant.model.opt.wind, [0.2, -0.1, 0.0])
    with pytest.raises(Exception, match="current"):
        Plant(current=(np.nan, 0.0))
