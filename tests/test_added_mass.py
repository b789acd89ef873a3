"""Added mass and added inertia: exact, anisotropic, in the mass matrix, every step."""

import mujoco
import numpy as np
import pytest

from uvms_mj import HydroTerms, Plant

from conftest import DECOUPLED_ARM, kinematics_only, point_jacobian, random_q, random_qd

INTEGRATORS = ["euler", "implicitfast", "implicit", "rk4"]


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_force_along_base_axes_gives_f_over_m_plus_ma(integrator):
    """From rest, a force through the base origin along body x (then body y) accelerates the base
    at F / (m + m_A) along that axis and not across it (Table 1: 26.04 + 72.7 and 26.04 + 6.28 kg).
    The arm is made negligible (DECOUPLED_ARM, ~1e-8 relative); tolerance 1e-6 relative."""
    plant = Plant(overrides=DECOUPLED_ARM, gravity=False, integrator=integrator, terms=HydroTerms(drag="off"))
    base = plant.params.body("base")
    force = 10.0
    for phi0 in (0.0, 0.7, -1.9, np.pi / 2):
        for axis, m_a in ((0, base.added_mass[0]), (1, base.added_mass[1])):
            plant.reset(keyframe=None)
            plant.set_state(base_pose=(0.2, -0.1, phi0))
            c, s = np.cos(phi0), np.sin(phi0)
            e_body = np.eye(2)[axis]
            e_world = np.array([[c, -s], [s, c]]) @ e_body
            plant.data.qfrc_applied[:2] = force * e_world
            mujoco.mj_forward(plant.model, plant.data)
            acc_world = plant.data.qacc[:2]
            acc_body = np.array([[c, s], [-s, c]]) @ acc_world
            expected = force / (base.mass + m_a)
            assert acc_body[axis] == pytest.approx(expected, rel=1e-6)
            assert abs(acc_body[1 - axis]) < 1e-6 * expected
            assert abs(plant.data.qacc[2]) < 1e-6 * expected  # no rotation: force through the CoM
            # One step with the integrator realises the same acceleration: v = a dt.
            plant.step(1)
            vel_body = np.array([[c, s], [-s, c]]) @ plant.data.qvel[:2]
            assert vel_body[axis] == pytest.approx(expected * plant.model.opt.timestep, rel=1e-6)


def independent_mass_matrix(plant: Plant, q: np.ndarray) -> np.ndarray:
    """sum over bodies of J^T (m + R M_A R^T) J + (I + I_A) Jw^T Jw, from MuJoCo's own Jacobians.

    Rigid part at each centre of mass, added part at each geom (box) centre; numpy algebra, no
    code shared with the plant's closed form."""
    d = kinematics_only(plant, q)
    M = np.zeros((5, 5))
    for bp in plant.params.bodies:
        b = plant.model.body(bp.name).id
        jp, jr = point_jacobian(plant, d, d.xipos[b], bp.name)
        M += bp.mass * jp.T @ jp + bp.inertia * jr.T @ jr
        g = plant.model.geom(bp.name).id
        jp, jr = point_jacobian(plant, d, d.geom_xpos[g], bp.name)
        R = d.xmat[b].reshape(3, 3)[:2, :2]
        MA = R @ np.diag(bp.added_mass) @ R.T
        M += jp.T @ MA @ jp + bp.added_inertia * jr.T @ jr
    return M


def test_mass_matrix_equals_independent_sum(rng):
    """Tolerance 1e-9 relative to the largest entry (~100 kg): floating-point summation only."""
    plant = Plant()
    for _ in range(30):
        q = random_q(rng)
        plant.set_state(base_pose=q[:3], joint_angles=q[3:])
        M = plant.mass_matrix()
        expected = independent_mass_matrix(plant, q)
        np.testing.assert_allclose(M, expected, rtol=0, atol=1e-9 * np.abs(expected).max())
        np.testing.assert_allclose(M, M.T, rtol=0, atol=1e-12)


def added_kinetic_energy(plant: Plant, q: np.ndarray, qd: np.ndarray, current: np.ndarray) -> float:
    """T_A = sum_b 1/2 (nu_r^T D_b nu_r), nu_r the body-frame velocity relative to the water at
    the geom centre, from MuJoCo Jacobians (independent of the plant's closed form)."""
    d = kinematics_only(plant, q)
    T = 0.0
    for bp in plant.params.bodies:
        b = plant.model.body(bp.name).id
        g = plant.model.geom(bp.name).id
        jp, jr = point_jacobian(plant, d, d.geom_xpos[g], bp.name)
        R = d.xmat[b].reshape(3, 3)[:2, :2]
        v = R.T @ (jp @ qd - current)
        w = (jr @ qd)[0]
        T += 0.5 * (bp.added_mass[0] * v[0] ** 2 + bp.added_mass[1] * v[1] ** 2 + bp.added_inertia * w**2)
    return T


@pytest.mark.parametrize("current", [(0.0, 0.0), (0.15, -0.08)])
def test_velocity_terms_match_finite_difference_lagrangian(rng, current):
    """The added-mass generalized force at q_ddot = 0 equals -(d/dt dT/dq_dot - dT/dq) of the
    added kinetic energy, by finite differences (Kirchhoff/Munk terms and the J_dot term).

    dT/dq_dot by central differences is exact for a quadratic up to round-off; the q-derivatives
    use eps = 1e-5 (truncation ~eps^2 ~ 1e-10, round-off ~1e-16/eps * |p| ~ 1e-10). Tolerance
    1e-7 absolute on forces of order 1 N."""
    current = np.asarray(current)
    plant = Plant(terms=HydroTerms(drag="off", buoyancy=False), gravity=False, current=current)
    T = lambda q, qd: added_kinetic_energy(plant, q, qd, current)  # noqa: E731
    h, eps = 1e-3, 1e-5
    E = np.eye(5)

    def momentum(q, qd):
        return np.array([(T(q, qd + h * e) - T(q, qd - h * e)) / (2 * h) for e in E])

    for _ in range(8):
        q, qd = random_q(rng), random_qd(rng)
        p_dot = (momentum(q + eps * qd, qd) - momentum(q - eps * qd, qd)) / (2 * eps)
        dT_dq = np.array([(T(q + eps * e, qd) - T(q - eps * e, qd)) / (2 * eps) for e in E])
        expected = -(p_dot - dT_dq)

        plant.set_state(base_pose=q[:3], joint_angles=q[3:], base_velocity=qd[:3], joint_velocities=qd[3:])
        # qfrc_passive holds exactly the added-mass velocity terms here (no drag, no buoyancy).
        np.testing.assert_allclose(plant.data.qfrc_passive, expected, rtol=0, atol=1e-7)
        # and the added kinetic energy the plant reports is the same T_A
        assert plant.energy().kinetic_added == pytest.approx(T(q, qd), rel=1e-12)


def test_isotropic_added_mass_equals_rigid_mass():
    """With isotropic added mass m_a on the base, the base behaves exactly as a rigid body of mass
    m + m_a: compare accelerations with a rigid model whose base mass is m + m_a (arm decoupled,
    added inertia moved into the rigid inertia too). Tolerance 1e-10 relative."""
    ma, ia = 40.0, 0.5
    over = dict(DECOUPLED_ARM)
    hydro = Plant(overrides={**over, "base.added_mass": [ma, ma, ia]}, gravity=False,
                  terms=HydroTerms(drag="off", buoyancy=False))
    base = hydro.params.body("base")
    rigid = Plant(overrides={**over, "base.added_mass": [0, 0, 0], "base.mass": base.mass + ma,
                             "base.inertia": base.inertia + ia}, gravity=False,
                  terms=HydroTerms(drag="off", buoyancy=False))
    for plant in (hydro, rigid):
        plant.set_state(base_pose=(0.1, 0.2, 0.4), base_velocity=(0.3, -0.2, 0.7))
        plant.data.qfrc_applied[:3] = (3.0, -2.0, 0.5)
        mujoco.mj_forward(plant.model, plant.data)
    np.testing.assert_allclose(hydro.data.qacc[:3], rigid.data.qacc[:3], rtol=1e-10, atol=1e-12)
