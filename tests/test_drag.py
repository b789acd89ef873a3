"""Strip-theory drag (paper Eqs. 2-3)."""

import numpy as np
import pytest
from scipy import integrate

from uvms_mj import HydroTerms, Plant, strip_integrals

from conftest import DECOUPLED_ARM, kinematics_only, point_jacobian, random_q, random_qd


def quad_pair(w0, om, a, b):
    """Adaptive quadrature of int |w| w ds and int s |w| w ds, told where w changes sign."""
    f0 = lambda s: abs(w0 + om * s) * (w0 + om * s)  # noqa: E731
    f1 = lambda s: s * f0(s)  # noqa: E731
    pts = [-w0 / om] if om != 0 and a < -w0 / om < b else None
    opts = dict(points=pts, epsabs=1e-16, epsrel=1e-12, limit=200)
    return integrate.quad(f0, a, b, **opts)[0], integrate.quad(f1, a, b, **opts)[0]


@pytest.mark.parametrize(
    "w0, om, a, b",
    [
        (0.3, 0.0, 0.0, 0.25),  # pure translation
        (0.0, 1.5, 0.0, 0.25),  # pure rotation about the joint
        (0.1, -2.0, 0.0, 0.25),  # sign change at s = 0.05 inside the link
        (-0.2, 1.0, -0.405, 0.405),  # base strip, sign change at 0.2
        (0.05, 3.0, -0.1, 0.1),  # sign change at -1/60
        (-0.4, -0.3, 0.0, 0.25),  # negative everywhere
    ],
)
def test_closed_form_equals_quadrature(w0, om, a, b):
    """Tolerance 1e-10 relative (quadrature is good to ~1e-13)."""
    got = strip_integrals(w0, om, a, b)
    ref = quad_pair(w0, om, a, b)
    scale = max(abs(ref[0]), abs(ref[1]), 1e-12)
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-10 * scale)


def test_closed_form_random(rng):
    for _ in range(200):
        w0, om = rng.normal(0, 0.5), rng.normal(0, 3)
        a = rng.uniform(-0.5, 0.2)
        b = a + rng.uniform(0.01, 0.8)
        got = strip_integrals(w0, om, a, b)
        ref = quad_pair(w0, om, a, b)
        scale = max(abs(ref[0]), abs(ref[1]), 1e-12)
        np.testing.assert_allclose(got, ref, rtol=0, atol=1e-10 * scale)


def drag_by_quadrature(plant: Plant, q, qd, current) -> np.ndarray:
    """Generalized drag force from Eqs. 2-3 integrated strip by strip with MuJoCo Jacobians:
    for each body, strips along its x extent feel the body-y component of the relative velocity
    (coefficient C_Dy), strips along its y extent the body-x component (C_Dx)."""
    d = kinematics_only(plant, q)
    rho = plant.params.rho
    Q = np.zeros(5)
    for bp in plant.params.bodies:
        b = plant.model.body(bp.name).id
        R = d.xmat[b].reshape(3, 3)
        o = d.xpos[b]
        cx, cy = bp.box_center
        hx, hy = bp.box_half

        def gen_force(point_body, axis, coef):
            p = o + R @ np.r_[point_body, 0.0]
            jp, _ = point_jacobian(plant, d, p, bp.name)
            v_rel = R[:2, :2].T @ (jp @ qd - current)
            w = v_rel[axis]
            f_body = np.zeros(2)
            f_body[axis] = -0.5 * rho * coef * bp.width * abs(w) * w
            return jp.T @ (R[:2, :2] @ f_body)

        opts = dict(epsabs=1e-13, epsrel=1e-11, limit=200)
        for i in range(5):
            if bp.drag_coef[1]:
                Q[i] += integrate.quad(lambda s: gen_force((s, 0.0), 1, bp.drag_coef[1])[i], cx - hx, cx + hx, **opts)[0]
            if bp.drag_coef[0]:
                Q[i] += integrate.quad(lambda s: gen_force((cx, s), 0, bp.drag_coef[0])[i], cy - hy, cy + hy, **opts)[0]
    return Q


@pytest.mark.parametrize("current", [(0.0, 0.0), (0.1, -0.05)])
def test_plant_drag_equals_strip_quadrature(rng, current):
    """The plant's drag generalized force (base in both axes, links across, rotation included)
    equals quadrature over the strips to 1e-8 relative."""
    current = np.asarray(current)
    plant = Plant(terms=HydroTerms(added_mass="off", buoyancy=False), gravity=False, current=current)
    for _ in range(4):
        q, qd = random_q(rng), random_qd(rng)
        plant.set_state(base_pose=q[:3], joint_angles=q[3:], base_velocity=qd[:3], joint_velocities=qd[3:])
        expected = drag_by_quadrature(plant, q, qd, current)
        np.testing.assert_allclose(plant.data.qfrc_passive, expected, rtol=0, atol=1e-8 * np.abs(expected).max())


@pytest.mark.parametrize("axis, thrust", [(1, [0.0, 0.0, 10.0]), (0, [5.0, 5.0, 0.0])])
def test_terminal_velocity_of_the_base(axis, thrust):
    """Constant 10 N through the base origin along body y (thruster 3), then body x (thrusters
    1 + 2): the base reaches v = sqrt(2 F / (rho C_D A)) within 1 %, A = l0x D = 0.2 x 0.42 m^2
    across body y and l0y D = 0.81 x 0.42 m^2 across body x (arm decoupled).

    Run for ~10 time constants m_eff / (rho C_D A v) (0.7 s and 1.1 s), not much longer: moving
    along body y, the Munk moment (m_Ax - m_Ay) v_x v_y makes the straight course unstable (a
    physical effect), and round-off grows into a turn after ~12 s."""
    plant = Plant(overrides=DECOUPLED_ARM, gravity=False)
    base = plant.params.body("base")
    plant.reset(keyframe=None)
    plant.set_thrust(thrust)
    plant.step(int(10 / plant.model.opt.timestep))
    v = plant.qd[axis]
    area = (base.length if axis == 1 else 2 * base.box_half[1]) * base.width
    expected = np.sqrt(2 * sum(thrust) / (plant.params.rho * base.drag_coef[axis] * area))
    assert v == pytest.approx(expected, rel=0.01)
    # still straight: side slip and turn rate under 0.1 % of the speed
    assert abs(plant.qd[1 - axis]) < 1e-3 * v and abs(plant.qd[2]) < 1e-3 * v


def test_mujoco_drag_option_is_dissipative_without_virtual_mass(rng):
    """MuJoCo's ellipsoid drag as an alternative: its virtual-mass terms are removed (added mass is
    ours), so it only dissipates: power q_dot . Q_drag <= 0 at random states."""
    plant = Plant(terms=HydroTerms(drag="mujoco", added_mass="off", buoyancy=False), gravity=False)
    robot_geoms = [plant.model.geom(b.name).id for b in plant.params.bodies]
    assert np.all(plant.model.geom_fluid[robot_geoms, 6:12] == 0)
    assert plant.model.opt.density == plant.params.rho
    for _ in range(20):
        q, qd = random_q(rng), random_qd(rng)
        plant.set_state(base_pose=q[:3], joint_angles=q[3:], base_velocity=qd[:3], joint_velocities=qd[3:])
        power = float(plant.data.qfrc_passive @ qd)
        assert power < 0
    # Pure spin in still water: drag opposes the spin and, with no virtual mass, makes no side force.
    plant.set_state(base_pose=(0, 0, 0), joint_angles=(0, 0), base_velocity=(0, 0, 1.0), joint_velocities=(0, 0))
    assert plant.data.qfrc_passive[2] < 0
