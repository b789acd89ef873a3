"""Kinematics (paper Eq. 1) against MuJoCo's model and finite differences."""

import mujoco
import numpy as np

from uvms_mj import Plant
from oracles.planar.kinematics import ArmGeometry, det_b, jacobians, task_jacobian, tip_position

from conftest import kinematics_only, random_q


def test_tip_site_matches_analytic_kinematics(rng):
    plant = Plant()
    geom = ArmGeometry.from_params(plant.params)
    for _ in range(50):
        q = random_q(rng)
        d = kinematics_only(plant, q)
        # MuJoCo composes the same rotations in a different order: agreement to ~1e-15 m;
        # 1e-12 m leaves room for summation order only.
        np.testing.assert_allclose(d.site("tip").xpos[:2], tip_position(geom, q), rtol=0, atol=1e-12)
        assert d.site("tip").xpos[2] == 0.0


def test_paper_initial_state():
    """Section 4: phi0 = -pi/2, phi1 = pi/3, phi2 = -5pi/18, and |det B| = 0.0625 sin 50 deg."""
    plant = Plant()
    geom = ArmGeometry.from_params(plant.params)
    np.testing.assert_allclose(plant.q[2:], [-np.pi / 2, np.pi / 3, -5 * np.pi / 18], atol=1e-15)
    np.testing.assert_allclose(abs(det_b(geom, plant.q)), 0.0625 * np.sin(np.deg2rad(50)), rtol=1e-14)
    assert 0.045 < abs(det_b(geom, plant.q)) < 0.048  # just above the paper's Js = 0.045


def test_det_b_is_l1_l2_sin_phi2(rng):
    geom = ArmGeometry.from_params(Plant().params)
    assert (geom.l1, geom.l2) == (0.25, 0.25)  # Table 1 link lengths
    for _ in range(50):
        q = random_q(rng)
        _, B = jacobians(geom, q)
        np.testing.assert_allclose(np.linalg.det(B), geom.l1 * geom.l2 * np.sin(q[4]), rtol=0, atol=1e-15)


def test_a_b_match_finite_differences(rng):
    """Central differences of the tip position; truncation error ~h^2 |pe'''| ~ 1e-12 at h = 1e-6."""
    geom = ArmGeometry.from_params(Plant().params)
    h = 1e-6
    for _ in range(20):
        q = random_q(rng)
        fd = np.column_stack(
            [(tip_position(geom, q + h * e) - tip_position(geom, q - h * e)) / (2 * h) for e in np.eye(5)]
        )
        A, B = jacobians(geom, q)
        np.testing.assert_allclose(np.hstack([A, B]), fd, rtol=0, atol=1e-8)
        J = task_jacobian(geom, q)
        np.testing.assert_array_equal(J[:3], np.hstack([np.eye(3), np.zeros((3, 2))]))


def test_a_b_match_mujoco_site_jacobian(rng):
    plant = Plant()
    geom = ArmGeometry.from_params(plant.params)
    for _ in range(20):
        q = random_q(rng)
        d = kinematics_only(plant, q)
        jacp = np.zeros((3, 5))
        mujoco.mj_jacSite(plant.model, d, jacp, None, plant.model.site("tip").id)
        A, B = jacobians(geom, q)
        np.testing.assert_allclose(np.hstack([A, B]), jacp[:2], rtol=0, atol=1e-12)
