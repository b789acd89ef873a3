"""Gravity and buoyancy (paper Eqs. 4-5)."""

import mujoco
import numpy as np
import pytest

from uvms_mj import HydroTerms, Plant

from conftest import random_q

G = np.array([0.0, -9.81])


def static_generalized_force(plant: Plant) -> np.ndarray:
    """Gravity + buoyancy generalized force at rest: passive forces minus MuJoCo's bias (which
    holds -gravity at zero velocity)."""
    mujoco.mj_forward(plant.model, plant.data)
    return plant.data.qfrc_passive - plant.data.qfrc_bias


def test_net_force_is_rho_v_minus_m_times_g(rng):
    """Eq. 4 summed over the bodies: (rho V - m) g on the base slides, at any configuration
    (1e-12 relative). The default model is 1 % positively buoyant (our assumption)."""
    plant = Plant(terms=HydroTerms(added_mass="off", drag="off"))
    p = plant.params
    rho_v = sum(p.rho * b.volume for b in p.bodies)
    mass = sum(b.mass for b in p.bodies)
    assert rho_v == pytest.approx(1.01 * mass, rel=1e-12)
    for _ in range(10):
        q = random_q(rng)
        plant.set_state(base_pose=q[:3], joint_angles=q[3:])
        Q = static_generalized_force(plant)
        # Eq. 4, f_g = (rho V - m) g, sits on the left of Eq. 6: the applied force is -f_g.
        np.testing.assert_allclose(Q[:2], -(rho_v - mass) * G, rtol=1e-12, atol=1e-12)
        assert Q[1] > 0  # net upward


def cob_world(d, body: int, cob_xy) -> np.ndarray:
    """World (x, y) of a point given in a body's frame, from MuJoCo's body pose."""
    return d.xpos[body, :2] + d.xmat[body].reshape(3, 3)[:2, :2] @ np.asarray(cob_xy)


def test_moments_match_eq5(rng):
    """Eq. 5: hinge k feels the moment of sum_{i >= k} (rho V_i b_i - m_i a_i) x g, with a_i and b_i
    the vectors from hinge k to body i's centre of mass and centre of buoyancy, taken from
    MuJoCo's kinematics. Eq. 6 carries Eqs. 4-5 on its left-hand side, so the applied
    generalized force is their negative. Base centre of buoyancy 5 cm off its centre of mass.
    Tolerance 1e-12 N m."""
    plant = Plant(terms=HydroTerms(added_mass="off", drag="off"), overrides={"base.cob": [-0.05, 0.0]})
    p = plant.params
    bodies = [plant.model.body(b.name).id for b in p.bodies]
    cross = lambda a, b: a[0] * b[1] - a[1] * b[0]  # noqa: E731
    for _ in range(10):
        q = random_q(rng)
        plant.set_state(base_pose=q[:3], joint_angles=q[3:])
        Q = static_generalized_force(plant)
        d = plant.data
        for k in range(3):
            hinge = d.xpos[bodies[k], :2]
            eq5 = sum(
                cross(p.rho * p.bodies[i].volume * (cob_world(d, bodies[i], p.bodies[i].cob) - hinge)
                      - p.bodies[i].mass * (d.xipos[bodies[i], :2] - hinge), G)
                for i in range(k, 3)
            )
            expected = -eq5
            assert Q[2 + k] == pytest.approx(expected, abs=1e-12)


def test_tilted_base_is_restored():
    """Centre of buoyancy 5 cm above the centre of mass (base upright: phi0 = -pi/2, arm hanging):
    tilting the base by +-0.2 rad gives the restoring moment -rho V0 g h sin(tilt) from Eq. 5
    (arm decoupled: its weight would add its own moment)."""
    from conftest import DECOUPLED_ARM

    h = 0.05
    plant = Plant(terms=HydroTerms(added_mass="off", drag="off"), overrides={**DECOUPLED_ARM, "base.cob": [-h, 0.0]})
    base = plant.params.body("base")
    for tilt in (0.2, -0.2):
        plant.set_state(base_pose=(0, 0, -np.pi / 2 + tilt), joint_angles=(0, 0))
        Q = static_generalized_force(plant)
        expected = -plant.params.rho * base.volume * 9.81 * h * np.sin(tilt)
        assert Q[2] == pytest.approx(expected, rel=1e-6)
        assert np.sign(Q[2]) == -np.sign(tilt)
