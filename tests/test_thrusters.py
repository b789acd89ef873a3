"""Thrusters: first-order lag, asymmetric saturation, dead zone, generalized force."""

import mujoco
import numpy as np
import pytest

from uvms_mj import Plant

from conftest import random_q


@pytest.mark.parametrize("integrator, steps, rtol", [("rk4", 12, 1e-6), ("rk4", 2, 1e-3), ("euler", 120, 5e-3)])
def test_lag_reaches_63_percent_at_tau(integrator, steps, rtol):
    """After t = tau the thrust is (1 - 1/e) of a step. The lag ODE tau F' = u - F is integrated
    by the plant's integrator: RK4 (the default) with error ~ (dt/tau)^5 / 120 per step, 2.5e-7
    at dt = tau/12 and 4.6e-4 at the default dt = tau/2.4; explicit Euler is first order
    (2.4e-3 at tau/120)."""
    tau = Plant().params.thrusters[0].tau
    assert tau == 0.02  # docs/paper-reading.md default
    plant = Plant(gravity=False, integrator=integrator, timestep=tau / steps)
    plant.set_thrust([10.0, -5.0, 2.0])
    plant.step(steps)
    np.testing.assert_allclose(plant.thruster_forces, np.array([10.0, -5.0, 2.0]) * (1 - np.exp(-1)), rtol=rtol)


def test_saturation_at_both_asymmetric_limits():
    """Published characteristic at +-4 V: +15.978 N forward, -8.849 N reverse (docs/paper-reading.md)."""
    plant = Plant(gravity=False)
    for t in plant.params.thrusters:
        assert t.force_range == (-8.849, 15.978)
    plant.set_thrust([100.0, -100.0, 15.0])
    plant.step(round(1.0 / plant.model.opt.timestep))  # 50 tau
    np.testing.assert_allclose(plant.thruster_forces, [15.978, -8.849, 15.0], rtol=1e-9)
    assert plant.thruster_commands.tolist() == [100.0, -100.0, 15.0]  # MuJoCo clamps internally


def test_dead_zone_option():
    plant = Plant(gravity=False, dead_zone=True)
    lo, hi = plant.params.dead_zone
    assert (lo, hi) == (-0.07772, 0.26944)
    plant.set_thrust([0.2, -0.05, 0.3])
    plant.step(round(1.0 / plant.model.opt.timestep))  # 50 tau
    np.testing.assert_allclose(plant.thruster_forces[:2], 0.0, atol=0)
    assert plant.thruster_forces[2] == pytest.approx(0.3, rel=1e-9)


def test_generalized_force_is_jacobian_transpose_of_thrust_vectors(rng):
    """qfrc_actuator = sum_i J_site_i^T (F_i x_i), x_i the thruster axis in the world (1e-12)."""
    plant = Plant()
    m = plant.model
    for _ in range(10):
        q = random_q(rng)
        forces = rng.uniform(-8, 15, 3)
        plant.set_state(base_pose=q[:3], joint_angles=q[3:])
        plant.data.act[:] = forces  # the lag state is the thrust (gain 1)
        mujoco.mj_forward(m, plant.data)
        expected = np.zeros(5)
        for f, t in zip(forces, plant.params.thrusters):
            s = m.site(t.name).id
            jacp = np.zeros((3, 5))
            mujoco.mj_jacSite(m, plant.data, jacp, None, s)
            axis = plant.data.site_xmat[s].reshape(3, 3)[:, 0]
            expected += jacp.T @ (f * axis)
        np.testing.assert_allclose(plant.data.qfrc_actuator, expected, rtol=0, atol=1e-12)
        assert np.all(expected[3:] == 0)  # thrusters act on the base only


def test_thruster_layout():
    """Two thrusters along base x at +-R across it, one along base y through the origin (R = 0.3 m)."""
    t = Plant().params.thrusters
    np.testing.assert_allclose([x.position for x in t], [(0, 0.3), (0, -0.3), (0, 0)], atol=1e-15)
    np.testing.assert_allclose([x.direction for x in t], [(1, 0), (1, 0), (0, 1)], atol=1e-15)


def test_joint_torques():
    plant = Plant(gravity=False)
    plant.set_joint_torques([1.5, -0.5])
    mujoco.mj_forward(plant.model, plant.data)
    np.testing.assert_allclose(plant.data.qfrc_actuator[3:], [1.5, -0.5])
