"""The controller's nominal model against the MuJoCo plant with the same parameters."""

import mujoco
import numpy as np

from uvms_mj import Plant
from oracles.planar.nominal import NominalModel

from conftest import random_q, random_qd


def test_nominal_mass_matrix_equals_plant(rng):
    """Same parameters: M̄ (analytic rigid chain + constant added mass) equals MuJoCo's mass matrix
    with the added mass installed, to 1e-9 relative to its largest entry."""
    plant, nominal = Plant(), NominalModel()
    for _ in range(30):
        q = random_q(rng)
        plant.set_state(base_pose=q[:3], joint_angles=q[3:])
        M = plant.mass_matrix()
        np.testing.assert_allclose(nominal.mass_matrix(q), M, rtol=0, atol=1e-9 * np.abs(M).max())


def test_nominal_bias_equals_plant_forces(rng):
    """N̄q̇ + f̄_D + ḡ equals minus the plant's total non-actuator generalized force
    (qfrc_passive - qfrc_bias: hydrodynamics, gravity, Coriolis) at random states, to 1e-8."""
    plant, nominal = Plant(), NominalModel()
    for _ in range(30):
        q, qd = random_q(rng), random_qd(rng, 2.0)
        plant.set_state(base_pose=q[:3], joint_angles=q[3:], base_velocity=qd[:3], joint_velocities=qd[3:])
        mujoco.mj_forward(plant.model, plant.data)
        total = plant.data.qfrc_passive - plant.data.qfrc_bias
        np.testing.assert_allclose(nominal.bias(q, qd), -total, rtol=0, atol=1e-8 * max(1.0, np.abs(total).max()))


def test_block_split():
    nominal = NominalModel()
    q, qd = np.r_[0, 0, -np.pi / 2, np.pi / 3, -5 * np.pi / 18], np.r_[0.1, 0.0, 0.2, 0.3, -0.1]
    dyn = nominal.dynamics(q, qd)
    M_BB, M_BM, M_MB, M_MM, h_B, h_M = dyn.blocks()
    assert M_BB.shape == (3, 3) and M_BM.shape == (3, 2) and M_MM.shape == (2, 2)
    np.testing.assert_array_equal(M_BM, M_MB.T)
    np.testing.assert_array_equal(np.r_[h_B, h_M], dyn.h)


def test_fast_dynamics_equals_term_by_term(rng):
    """dynamics() (rigid bodies as isotropic added mass, one closed-form pass, native when
    available) equals the term-by-term mass_matrix() and bias() to 1e-12."""
    nominal = NominalModel()
    for _ in range(30):
        q, qd = random_q(rng), random_qd(rng, 2.0)
        dyn = nominal.dynamics(q, qd)
        np.testing.assert_allclose(dyn.M, nominal.mass_matrix(q), rtol=0, atol=1e-12 * 100)
        np.testing.assert_allclose(dyn.h, nominal.bias(q, qd), rtol=0, atol=1e-12 * 100)
