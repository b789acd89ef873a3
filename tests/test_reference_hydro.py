"""The numpy reference hydrodynamics (uvms_mj.physics.reference) against independent truths.

Truths: Pinocchio (rigid-body dynamics, frame Jacobians and accelerations, from its own MJCF
parser), an independent implementation of Fossen's 6-DOF equations (tests/oracles/fossen.py),
a finite-difference Lagrangian of the kinetic energy, scipy quadrature, closed-form solutions
and known SplitMix64 outputs. Nothing here compares the reference with itself. Every tolerance
has its justification next to it.

Time simulations run the reference as MuJoCo's passive callback on models with the uvms plugins
stripped (tests/oracles/ref_sim.py), so they need no C plugin.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest
from scipy import integrate

from uvms_mj.physics import config, reference
from uvms_mj.physics.config import HydroConfigError

from oracles import fossen, ref_sim
from oracles.pinocchio_model import PinRobot

G = 9.81


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20261201)


@pytest.fixture(autouse=True)
def _restore_callback():
    """mjcb_passive is process-global: leave it as the test found it (normally None)."""
    previous = mujoco.get_mjcb_passive()
    yield
    mujoco.set_mjcb_passive(previous)


def random_state(m: mujoco.MjModel, d: mujoco.MjData, rng, vscale: float = 1.0) -> None:
    """A random pose (free base anywhere within 1 m, any orientation, any joint angles) and
    velocity (up to vscale m/s, rad/s)."""
    d.qpos[:3] = rng.uniform(-1, 1, 3)
    q = rng.normal(size=4)
    d.qpos[3:7] = q / np.linalg.norm(q)
    d.qpos[7:] = rng.uniform(-np.pi, np.pi, m.nq - 7)
    d.qvel[:] = vscale * rng.uniform(-1, 1, m.nv)


def full_M(m, d) -> np.ndarray:
    M = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, M)
    return M


def forward_kinematics(m, d) -> None:
    """Position and velocity stages (kinematics, com, M, bias); no callback is installed."""
    mujoco.mj_fwdPosition(m, d)
    mujoco.mj_fwdVelocity(m, d)


# ------------------------------------------------------------------------------- Pinocchio


def test_rigid_dynamics_and_added_mass_matrix_match_pinocchio(rng):
    rm = ref_sim.load("robot3d.xml")
    m = rm.m
    xml = (ref_sim.MODELS / "robot3d.xml").read_text()
    frames = {m.body(b).name: (h.pos, h.quat) for b, h in rm.bodies.items()}
    pr = PinRobot(xml, frames)
    d = mujoco.MjData(m)
    worst = {"M": 0.0, "bias": 0.0, "M_add": 0.0, "acc": 0.0}
    for _ in range(6):
        random_state(m, d, rng)
        forward_kinematics(m, d)
        worst["M"] = max(worst["M"], np.abs(full_M(m, d) - pr.mass_matrix(d.qpos)).max())
        worst["bias"] = max(worst["bias"], np.abs(d.qfrc_bias - pr.bias(d.qpos, d.qvel, m.opt.gravity)).max())
        M_pin = np.zeros((m.nv, m.nv))
        for b, hb in rm.bodies.items():
            J = pr.frame_jacobian(d.qpos, m.body(b).name)
            M_pin += J.T @ hb.added_mass @ J
        worst["M_add"] = max(worst["M_add"],
                             np.abs(M_pin - reference.added_mass_matrix(m, d, rm.water, rm.bodies)).max())
        # The J_dot term: Pinocchio's classical acceleration of each hydro frame at qacc = 0
        # (LOCAL) is R^T J_p_dot q_dot and R^T J_r_dot q_dot, i.e. a + (w x v, 0) for v_c = 0.
        for b, hb in rm.bodies.items():
            a_pin = pr.frame_acceleration_at_rest(d.qpos, d.qvel, m.body(b).name)
            nu = reference.body_jacobian(m, d, b, hb.pos, hb.quat) @ d.qvel
            a = reference.bias_acceleration(m, d, b, hb.pos, hb.quat)
            worst["acc"] = max(worst["acc"], np.abs(a + np.r_[np.cross(nu[3:], nu[:3]), 0, 0, 0] - a_pin).max())
    # Entries are O(1-30) (kg, kg m, N): 1e-10 leaves 4 orders of magnitude above the
    # double-precision rounding of two different algorithms (measured <= 4e-14).
    assert worst["M"] < 1e-10 and worst["bias"] < 1e-10, worst
    assert worst["M_add"] < 1e-10, worst
    assert worst["acc"] < 1e-10, worst


# ---------------------------------------------------------------------------------- Fossen


def _vessel(rm: ref_sim.RefModel, b: int) -> fossen.Vessel:
    """The body (with its welded children) as Fossen's vessel in frame h, from the model's
    inertial parameters."""
    m = rm.m
    hb = rm.bodies[b]
    parts_m, parts_c, parts_I = [], [], []
    for bb in range(m.nbody):
        # b itself and its welded (jointless) descendants, expressed in b's frame
        chain, ok = [], False
        k = bb
        while k > 0:
            if k == b:
                ok = True
                break
            if m.body_jntnum[k]:
                break
            chain.append(k)
            k = m.body_parentid[k]
        if not ok:
            continue
        R, p = np.eye(3), np.zeros(3)
        for k in reversed(chain):  # compose b -> ... -> bb
            Rk = fossen.quat_to_mat(m.body_quat[k])
            p, R = p + R @ m.body_pos[k], R @ Rk
        Ri = R @ fossen.quat_to_mat(m.body_iquat[bb])
        parts_m.append(m.body_mass[bb])
        parts_c.append(p + R @ m.body_ipos[bb])
        parts_I.append(Ri @ np.diag(m.body_inertia[bb]) @ Ri.T)
    mass, com, I_g = fossen.composite_inertia(parts_m, parts_c, parts_I)
    Rh = fossen.quat_to_mat(hb.quat)
    return fossen.Vessel(
        mass=mass, r_g=Rh.T @ (com - hb.pos), I_g=Rh.T @ I_g @ Rh, M_A=hb.added_mass,
        D_L=hb.linear_damping, D_Q=hb.quadratic_damping, volume=hb.volume,
        r_b=Rh.T @ (hb.cob - hb.pos), rho=rm.water.density)


def _nu_and_nu_dot(m, d, qacc, pos, quat):
    """Frame-h velocity and Fossen's nu_dot from a free joint's qvel / qacc (MuJoCo: world linear
    velocity of the body origin, body-frame angular velocity), by rigid-body kinematics."""
    Rb = fossen.quat_to_mat(d.qpos[3:7])
    Rh = fossen.quat_to_mat(quat)
    u_o, w_b = Rb.T @ d.qvel[:3], d.qvel[3:6]          # body components
    a_o, dw_b = Rb.T @ qacc[:3], qacc[3:6]
    du_o = a_o - np.cross(w_b, u_o)                       # d/dt of body components of v_o
    nu = np.r_[Rh.T @ (u_o + np.cross(w_b, pos)), Rh.T @ w_b]
    nu_dot = np.r_[Rh.T @ (du_o + np.cross(dw_b, pos)), Rh.T @ dw_b]
    return nu, nu_dot, Rb @ Rh


@pytest.mark.parametrize("current", ["constant", "accelerating"])
def test_single_body_matches_fossen(rng, current):
    water = {}
    if current == "accelerating":
        water = {"current_model": "gauss_markov", "current": "0.3 -0.2 0.1", "gm_mean": "-0.1 0.2 0.05",
                 "gm_tau": "0.5 0.8 1.3", "gm_sigma": "0 0 0"}
    rm = ref_sim.load("single_body.xml", water=water)
    m = rm.m
    b = rm.body_id("box")
    hb = rm.bodies[b]
    vessel = _vessel(rm, b)
    d = mujoco.MjData(m)
    h = m.opt.timestep
    worst = 0.0
    for i in range(8):
        random_state(m, d, rng)
        d.time = 0.37 * h  # inside the first sample interval of the current
        # an external wrench (world force and torque at the hydro frame origin)
        f_ext, t_ext = rng.normal(size=3) * 5, rng.normal(size=3)
        forward_kinematics(m, d)
        p, R = reference.hydro_frame(m, d, b, hb.pos, hb.quat)
        qfrc_ext = np.zeros(m.nv)
        mujoco.mj_applyFT(m, d, f_ext, t_ext, p, b, qfrc_ext)
        M_add, qfrc = reference.passive(m, d, rm.water, rm.bodies)
        qacc = np.linalg.solve(full_M(m, d) + M_add, qfrc + qfrc_ext - d.qfrc_bias)
        if i == 0:  # the same through MuJoCo's pipeline (mjcb_passive, mj_forward)
            M_rigid = full_M(m, d)
            with ref_sim.RefSim(rm):
                mujoco.mj_forward(m, d)
            # same linear system solved by MuJoCo's sparse factorisation: rounding only
            assert np.abs(d.qacc - np.linalg.solve(M_rigid + M_add, qfrc - d.qfrc_bias)).max() < 1e-10
            assert np.abs(full_M(m, d) - (M_rigid + M_add)).max() < 1e-14  # d.M was augmented
        nu, nu_dot_mj, R_h = _nu_and_nu_dot(m, d, qacc, hb.pos, hb.quat)
        # current, written out independently: v_1 = mu + (v_0 - mu) exp(-h/tau) (sigma = 0)
        if current == "accelerating":
            v0, mu, tau = np.array([0.3, -0.2, 0.1]), np.array([-0.1, 0.2, 0.05]), np.array([0.5, 0.8, 1.3])
            a_c = (mu + (v0 - mu) * np.exp(-h / tau) - v0) / h
            v_c = v0 + d.time * a_c
        else:
            v_c, a_c = np.array([0.2, 0.1, -0.05]), np.zeros(3)
        tau_ext = np.r_[R_h.T @ f_ext, R_h.T @ t_ext]
        nu_dot_f = vessel.nu_dot(R_h, nu, v_c, a_c, m.opt.gravity, tau_ext)
        worst = max(worst, np.abs(nu_dot_f - nu_dot_mj).max())
    # accelerations O(1-100) m/s^2, rad/s^2 from 6x6 solves with condition number ~1e3:
    # 1e-10 is rounding with a 10x margin (measured below 1e-11).
    assert worst < 1e-10, worst


# ----------------------------------------------------------------- finite-difference Lagrangian


def _right_jacobian(phi: np.ndarray) -> np.ndarray:
    """Jr of SO(3): R = R0 Exp(phi) has body angular velocity Jr(phi) phi_dot."""
    th = float(np.linalg.norm(phi))
    K = fossen.S(phi)
    if th < 1e-8:
        return np.eye(3) - 0.5 * K
    return np.eye(3) - (1 - math.cos(th)) / th**2 * K + (th - math.sin(th)) / th**3 * K @ K


def _exp_quat(phi: np.ndarray) -> np.ndarray:
    th = float(np.linalg.norm(phi))
    return np.r_[math.cos(th / 2), math.sin(th / 2) * phi / th] if th > 0 else np.array([1.0, 0, 0, 0])


class _Chart:
    """Minimal coordinates of robot3d: base position x, a rotation vector phi about a reference
    orientation q0 (R = R0 Exp(phi)), the joint angles. qvel = G(qc) qc_dot."""

    def __init__(self, rm, q0):
        self.rm, self.m, self.q0 = rm, rm.m, q0
        self.d = mujoco.MjData(rm.m)

    def set(self, qc, qcd):
        d = self.d
        d.qpos[:3] = qc[:3]
        mujoco.mju_mulQuat(d.qpos[3:7], self.q0, _exp_quat(qc[3:6]))
        d.qpos[7:] = qc[6:]
        d.qvel[:] = self.G(qc) @ qcd
        forward_kinematics(self.m, d)
        return d

    def G(self, qc):
        G = np.eye(self.m.nv)
        G[3:6, 3:6] = _right_jacobian(qc[3:6])
        return G

    def T(self, qc, qcd) -> float:
        """Rigid plus added kinetic energy."""
        d = self.set(qc, qcd)
        rigid = 0.5 * d.qvel @ full_M(self.m, d) @ d.qvel
        return rigid + reference.added_kinetic_energy(self.m, d, self.rm.water, self.rm.bodies, 0.0)


def _d4(f, x, i, h):
    """4th-order central difference of f along coordinate i of x (error O(h^4))."""
    e = np.zeros_like(x)
    e[i] = h
    return (f(x - 2 * e) - 8 * f(x - e) + 8 * f(x + e) - f(x + 2 * e)) / (12 * h)


def test_added_mass_forces_match_finite_difference_lagrangian(rng):
    """Q = d/dt dT/dqc_dot - dT/dqc (T = rigid + added kinetic energy, a constant current, no
    gravity) equals G^T [(M + M_add) qacc + c(q, qvel) - Q_A] for random 3-D states."""

    def no_gravity(spec):
        spec.option.gravity = [0, 0, 0]

    rm = ref_sim.load("robot3d.xml", water={"terms": "added_mass", "current": "0.3 -0.2 0.15"}, edit=no_gravity)
    m = rm.m
    worst, scale = 0.0, 0.0
    for _ in range(3):
        q0 = rng.normal(size=4)
        chart = _Chart(rm, q0 / np.linalg.norm(q0))
        qc = np.r_[rng.uniform(-1, 1, 3), rng.uniform(-0.4, 0.4, 3), rng.uniform(-np.pi, np.pi, 4)]
        qcd = rng.uniform(-1, 1, m.nv)
        qcdd = rng.uniform(-1, 1, m.nv)

        def p_of(qc_, qcd_):  # dT/dqc_dot: T is quadratic in qc_dot, so this difference is exact
            return np.array([(chart.T(qc_, qcd_ + e) - chart.T(qc_, qcd_ - e)) / 2 for e in np.eye(m.nv)])

        def along(t):  # the trajectory qc(t) = qc + qcd t + qcdd t^2/2
            return qc + qcd * t + 0.5 * qcdd * t * t, qcd + qcdd * t

        ht = 1e-4
        dpdt = _d4(lambda t: p_of(*along(t[0])), np.zeros(1), 0, ht)
        dTdq = np.array([_d4(lambda x: chart.T(x, qcd), qc, i, 1e-4) for i in range(m.nv)])
        Q_lagrange = dpdt - dTdq
        # the same from the reference forces in MuJoCo's coordinates
        qvel_of = lambda t: chart.G(along(t[0])[0]) @ along(t[0])[1]  # noqa: E731
        qacc = _d4(qvel_of, np.zeros(1), 0, ht)
        d = chart.set(qc, qcd)
        M_add, Q_A = reference.passive(m, d, rm.water, rm.bodies)
        Q_ref = chart.G(qc).T @ ((full_M(m, d) + M_add) @ qacc + d.qfrc_bias - Q_A)
        worst = max(worst, np.abs(Q_lagrange - Q_ref).max())
        scale = max(scale, np.abs(Q_ref).max())
    # T ~ 30 J: the 4th-order stencils have truncation O(h^4 T^(5)) ~ 1e-14 and rounding
    # ~ eps T / h ~ 1e-10 (each of dT/dq and d/dt dT/dqdot); 1e-7 N gives a 100-1000x margin while
    # a missing term (e.g. the J_dot term, O(1) N here) would fail by 7 orders of magnitude.
    assert worst < 1e-7, (worst, scale)


# ---------------------------------------------------------------------------------- strips


# quad warns that it cannot certify epsrel = 1e-13 (rounding); the comparison below is 1e-9
@pytest.mark.filterwarnings("ignore::scipy.integrate.IntegrationWarning")
def test_strip_drag_matches_quadrature(rng):
    rho = 1025.0
    cases = 0
    for trial in range(40):
        axis = trial % 3
        s0 = rng.uniform(-0.5, 0.2)
        s1 = s0 + rng.uniform(0.05, 0.8)
        strip = (axis, s0, s1, rng.uniform(0.0, 0.2), rng.uniform(0.0, 0.2))
        v, w = rng.normal(size=3), rng.normal(size=3)
        e = np.eye(3)[axis]
        normals = reference.NORMALS[axis]
        if trial % 2 == 0:  # put the sign change of one normal velocity inside the strip
            n = normals[trial % 4 // 2]
            s_star = rng.uniform(s0, s1)
            v[n] = -s_star * np.cross(w, e)[n]
        if trial == 5:
            w[:] = 0.0  # uniform flow along the strip (om = 0)
        roots = [-v[n] / np.cross(w, e)[n] for n in normals if np.cross(w, e)[n] != 0]
        cases += any(s0 < r < s1 for r in roots)

        def density(s):  # force per length and its moment about the origin of h
            f = np.zeros(3)
            for n, c in zip(normals, strip[3:]):
                wn = v[n] + s * np.cross(w, e)[n]
                f[n] -= 0.5 * rho * c * abs(wn) * wn
            return np.r_[f, np.cross(s * e, f)]

        pts = [r for r in roots if s0 < r < s1]
        truth = np.array([integrate.quad(lambda s: density(s)[k], s0, s1, points=pts or None,
                                         epsabs=0.0, epsrel=1e-13, limit=200)[0] for k in range(6)])
        tau = reference.strip_drag(rho, [strip], np.r_[v, w])
        # quad on piecewise polynomials split at the kink is exact to ~1e-14 relative;
        # 1e-9 relative to the wrench's size (components can be 0) is a wide margin
        assert np.abs(tau - truth).max() <= 1e-9 * max(np.abs(truth).max(), 1e-300), (trial, tau, truth)
    assert cases >= 15  # sign changes inside the strip were exercised


# ------------------------------------------------------------------------------ closed forms

#: A box whose centre of mass is the body origin, with principal axes along the body axes and a
#: welded tiny child at the centre (keeps the free body non-simple without moving the centre of
#: mass): m = 10.001 kg, I = diag(0.2, 0.5, 0.6) + 1e-6.
BOX = """
<mujoco>
  <option timestep="{dt}" integrator="{integrator}" gravity="{gravity}"/>
  <worldbody>
    <body name="box">
      <freejoint/>
      <inertial pos="0 0 0" mass="10" diaginertia="0.2 0.5 0.6"/>
      <geom type="box" size="0.3 0.1 0.1" contype="0" conaffinity="0" mass="0"/>
      <body name="child"><inertial pos="0 0 0" mass="0.001" diaginertia="1e-6 1e-6 1e-6"/></body>
    </body>
  </worldbody>
</mujoco>
"""


def box(water=None, dt=0.002, integrator="RK4", gravity="0 0 0", **hydro) -> ref_sim.RefModel:
    xml = BOX.format(dt=dt, integrator=integrator, gravity=gravity)
    rm = ref_sim.load(xml, water=water or {}, bodies={"box": hydro})
    return rm


def test_from_rest_acceleration_is_force_over_mass_plus_added_mass(rng):
    M_A = np.array([2.0, 8.0, 9.0, 0.05, 0.3, 0.4])
    rm = box(water={"terms": "added_mass"}, added_mass=" ".join(map(str, M_A)))
    m = rm.m
    mass, inertia = 10.001, np.array([0.2, 0.5, 0.6]) + 1e-6
    d = mujoco.MjData(m)
    q = rng.normal(size=4)
    d.qpos[3:7] = q / np.linalg.norm(q)
    mujoco.mj_forward(m, d)
    R = d.xmat[1].reshape(3, 3)
    with ref_sim.RefSim(rm):
        for i in range(3):
            d.xfrc_applied[:] = 0
            d.xfrc_applied[1, :3] = 7.0 * R[:, i]  # force along body axis i
            mujoco.mj_forward(m, d)
            acc = R.T @ d.qacc[:3]
            # exact arithmetic up to rounding of a 6x6 factorisation: 1e-12 relative
            assert acc[i] == pytest.approx(7.0 / (mass + M_A[i]), rel=1e-12)
            assert np.abs(np.delete(acc, i)).max() < 1e-12 and np.abs(d.qacc[3:6]).max() < 1e-12
            d.xfrc_applied[:] = 0
            d.xfrc_applied[1, 3:] = 0.3 * R[:, i]  # torque about body axis i
            mujoco.mj_forward(m, d)
            alpha = d.qacc[3:6]  # body frame
            assert alpha[i] == pytest.approx(0.3 / (inertia[i] + M_A[3 + i]), rel=1e-12)
            assert np.abs(np.delete(alpha, i)).max() < 1e-12 and np.abs(d.qacc[:3]).max() < 1e-12


def test_terminal_velocity_with_linear_and_quadratic_damping(rng):
    D_L, D_Q, F = 5.0, 20.0, 40.0
    rm = box(water={"terms": "added_mass damping"}, dt=0.005, added_mass="2 8 8 0.05 0.3 0.4",
             linear_damping=f"{D_L} 1 1 1 1 1", quadratic_damping=f"{D_Q} 1 1 1 1 1")
    m = rm.m
    d = mujoco.MjData(m)
    q = rng.normal(size=4)
    d.qpos[3:7] = q / np.linalg.norm(q)
    mujoco.mj_forward(m, d)
    R = d.xmat[1].reshape(3, 3)
    d.xfrc_applied[1, :3] = F * R[:, 0]
    v_T = (-D_L + math.sqrt(D_L**2 + 4 * D_Q * F)) / (2 * D_Q)  # root of F = D_L v + D_Q v^2
    with ref_sim.RefSim(rm) as sim:
        sim.step(d, 1200)  # 6 s = 28 time constants m_eff/(D_L + 2 D_Q v_T) = 0.21 s
        u = R.T @ d.qvel[:3]
        # the transient has decayed to e^-28 ~ 1e-12 of v_T; RK4 keeps the exact fixed point
        assert u[0] == pytest.approx(v_T, rel=1e-9)
        assert np.abs(u[1:]).max() < 1e-12 and np.abs(d.qvel[3:]).max() < 1e-12
        # and exactly at v_T nothing accelerates (force balance, rounding only)
        d.qvel[:3] = v_T * R[:, 0]
        mujoco.mj_forward(m, d)
        assert np.abs(d.qacc).max() < 1e-12


def test_buoyancy_restoring_moment_of_a_tilted_body():
    rho, V, z_b, theta = 1000.0, 0.011, 0.04, 0.3
    rm = box(water={"terms": "buoyancy", "density": str(rho)}, gravity=f"0 0 {-G}",
             volume=str(V), cob=f"0 0 {z_b}")
    m = rm.m
    d = mujoco.MjData(m)
    d.qpos[3:7] = [math.cos(theta / 2), math.sin(theta / 2), 0, 0]  # roll theta about x
    forward_kinematics(m, d)
    _, qfrc = reference.passive(m, d, rm.water, rm.bodies)
    B = rho * V * G
    # free joint: world force; torque about the body origin (= centre of mass) in body axes
    np.testing.assert_allclose(qfrc[:3], [0, 0, B], rtol=0, atol=1e-12 * B)
    np.testing.assert_allclose(qfrc[3:], [-B * z_b * math.sin(theta), 0, 0], rtol=0, atol=1e-12 * B)


def test_buoyancy_roll_oscillation_period():
    """Neutrally buoyant, cob above com: small roll oscillations at
    omega^2 = rho V g z_b / (I_x + K_pdot) (linearised restoring moment)."""
    rho, z_b = 1000.0, 0.05
    mass, I_x, K_p = 10.001, 0.2 + 1e-6, 0.05
    V = mass / rho
    rm = box(water={"terms": "added_mass buoyancy", "density": str(rho)}, gravity=f"0 0 {-G}", dt=0.001,
             added_mass=f"2 8 9 {K_p} 0.3 0.4", volume=str(V), cob=f"0 0 {z_b}")
    m = rm.m
    d = mujoco.MjData(m)
    phi0 = 1e-4
    d.qpos[3:7] = [math.cos(phi0 / 2), math.sin(phi0 / 2), 0, 0]
    omega = math.sqrt(rho * V * G * z_b / (I_x + K_p))
    T = 2 * math.pi / omega
    n = int(round(T / 4 / m.opt.timestep))
    with ref_sim.RefSim(rm) as sim:
        sim.step(d, n)
    phi = 2 * math.atan2(d.qpos[4], d.qpos[3])
    t = d.time
    # phi(t) = phi0 cos(omega t); nonlinear correction O(phi0^2) = 1e-8 relative, RK4 error
    # (omega dt)^4 ~ 1e-10: compare with 1e-6 of the amplitude
    assert phi == pytest.approx(phi0 * math.cos(omega * t), abs=1e-6 * phi0)
    assert d.qvel[3] == pytest.approx(-phi0 * omega * math.sin(omega * t), rel=1e-6)


def test_co_moving_with_a_steady_current_gives_no_force(rng):
    rm = ref_sim.load("robot3d.xml", water={"terms": "added_mass damping strips froude_krylov"})
    m = rm.m
    d = mujoco.MjData(m)
    random_state(m, d, rng)
    d.qvel[:] = 0
    d.qvel[:3] = rm.water.current  # the whole robot translates with the water
    forward_kinematics(m, d)
    M_add, qfrc = reference.passive(m, d, rm.water, rm.bodies)
    assert np.abs(M_add).max() > 1  # the added mass is there ...
    assert np.abs(qfrc).max() < 1e-13  # ... but no force: rounding of O(1) products only


def test_neutrally_buoyant_body_moves_with_an_accelerating_current(rng):
    mu, v0, tau = np.array([0.5, -0.3, 0.2]), np.array([-0.2, 0.1, 0.0]), np.array([0.4, 0.7, 1.1])
    rho = 1000.0
    A = "3 0.5 0 0 0.2 0 0.5 6 0 -0.15 0 0 0 0 7 0 0 0.1 0 -0.15 0 0.05 0 0 0.2 0 0 0 0.09 0.01 0 0 0.1 0 0.01 0.08"
    water = {"density": str(rho), "current_model": "gauss_markov", "current": " ".join(map(str, v0)),
             "gm_mean": " ".join(map(str, mu)), "gm_tau": " ".join(map(str, tau)), "gm_sigma": "0 0 0"}
    rm = box(water=water, gravity=f"0 0 {-G}", dt=0.01, added_mass=A, volume=str(10.001 / rho),
             linear_damping="5 5 5 1 1 1", quadratic_damping="20 20 20 1 1 1",
             pos="0.05 0.02 -0.03", quat="0.9 0.1 0.2 0.3", cob="0 0 0")  # h off the com, cob at it
    m = rm.m
    d = mujoco.MjData(m)
    q = rng.normal(size=4)
    d.qpos[3:7] = q / np.linalg.norm(q)
    d.qvel[:3] = v0
    worst = 0.0
    with ref_sim.RefSim(rm) as sim:
        for k in range(1, 301):
            sim.step(d)
            v_c = mu + (v0 - mu) * np.exp(-k * m.opt.timestep / tau)  # exact samples, sigma = 0
            worst = max(worst, np.abs(d.qvel[:3] - v_c).max(), np.abs(d.qvel[3:]).max())
    # the current is linear between samples and the body's acceleration equals it exactly, so
    # every integrator reproduces the samples: only rounding accumulates over 300 steps
    assert worst < 1e-12, worst


def test_munk_moment_yaw_instability_growth_rate():
    """A slender body moving along its long axis x at speed U (no gravity, no damping, centre of
    mass at the origin of h, diagonal M_A = (X, Y, Z, K, M, N)). Linearised about
    (u, v, r) = (U, 0, 0), Fossen's equations in the horizontal plane are

        (m + Y) v_dot = -(m + X) U r                      (sway: -C_RB - C_A terms)
        (I_z + N) r_dot = (X - Y) U v + 0                 (yaw: the Munk moment (X - Y) u v)

    so v_ddot = lambda^2 v with lambda^2 = (m + X)(Y - X) U^2 / ((m + Y)(I_z + N)): for Y > X
    the yaw is unstable. From r(0) = r0, v(0) = 0: r(t) = r0 cosh(lambda t). (Without the sway
    coupling one would get (Y - X) U^2 / (I_z + N), 30 % too fast here.)"""
    X, Y, N = 1.0, 9.0, 0.5
    mass, I_z = 10.001, 0.6 + 1e-6
    U, r0 = 1.0, 1e-6
    rm = box(water={"terms": "added_mass"}, dt=0.002, added_mass=f"{X} {Y} {Y} 0.01 {N} {N}")
    m = rm.m
    d = mujoco.MjData(m)
    d.qvel[0] = U
    d.qvel[5] = r0
    lam = U * math.sqrt((mass + X) * (Y - X) / ((mass + Y) * (I_z + N)))
    with ref_sim.RefSim(rm) as sim:
        sim.step(d, 1000)  # 2 s: lambda t = 3.2, growth x12
    lam_sim = math.acosh(d.qvel[5] / r0) / d.time
    # amplitude stays ~1e-5 (nonlinear corrections ~1e-10 relative), RK4 error (lambda dt)^4 ~ 1e-10:
    # 1e-6 relative separates the coupled rate from the naive one (30 % off) by far
    assert lam_sim == pytest.approx(lam, rel=1e-6)
    lam_naive = U * math.sqrt((Y - X) / (I_z + N))
    assert abs(lam_naive / lam - 1) > 0.2


# ---------------------------------------------------------------------------- config errors


@pytest.mark.parametrize(
    "key, value, reason",
    [
        ("added_mass", "1 2 3", "expected 6, 21 or 36 numbers"),
        ("added_mass", "1 0.5 0 0 0 0 0.4 1 0 0 0 0" + " 0 0 1 0 0 0 0 0 0 1 0 0 0 0 0 0 1 0 0 0 0 0 0 1", "symmetric"),
        ("added_mass", "1 0 0 0 0 0 1 0 0 0 0 1 0 0 0 1 0 0 1 0 -1", "positive semi-definite"),
        ("added_mass", "1 2 nan 4 5 6", "finite"),
        ("added_mass", "1 2 x 4 5 6", "expected numbers"),
        ("linear_damping", "1 2 3 4 5 -6", ">= 0"),
        ("quadratic_damping", "1 2 3", "expected 6 numbers"),
        ("volume", "-0.1", ">= 0"),
        ("volume", "inf", "finite"),
        ("strips", "w 0 1 0.1 0.1", "allowed x, y, z"),
        ("strips", "x 1 0 0.1 0.1", "s0 < s1"),
        ("strips", "x 0 1 -0.1 0.1", ">= 0"),
        ("strips", "x 0 1 0.1", "5 words"),
        ("pos", "0 0", "expected 3 numbers"),
        ("quat", "0 0 0 0", "zero"),
        ("cob", "0 0 1 2", "expected 3 numbers"),
    ],
)
def test_bad_body_parameters_are_named(key, value, reason):
    with pytest.raises(HydroConfigError) as exc:
        config.parse_body("link1", {key: value})
    msg = str(exc.value)
    assert msg.startswith("uvms.hydro: body 'link1': ") and f'{key} = "{value}"' in msg and reason in msg, msg


@pytest.mark.parametrize(
    "key, value, reason",
    [
        ("density", "0", "> 0"),
        ("density", "1 2", "expected 1 number"),
        ("gm_tau", "1 0 1", "> 0"),
        ("gm_sigma", "0 -1 0", ">= 0"),
        ("gm_min", "0 0 5", "gm_min <= gm_max"),
        ("gm_seed", "-3", "integer"),
        ("gm_seed", "1.5", "integer"),
        ("profile", "0 1 0 0; 0 2 0 0", "strictly increasing"),
        ("profile", "0 1 0", "expected 4 numbers"),
        ("current_model", "tidal", "allowed: constant, gauss_markov, profile"),
        ("terms", "added_mass drag", "unknown term 'drag'"),
        ("current", "0 0 1e999", "finite"),
    ],
)
def test_bad_water_parameters_are_named(key, value, reason):
    cfg = {key: value}
    if key == "gm_min":
        cfg["gm_max"] = "1 1 1"
    with pytest.raises(HydroConfigError) as exc:
        config.parse_water(cfg)
    msg = str(exc.value)
    assert msg.startswith("uvms.water: ") and f'{key} = "{value}"' in msg and reason in msg, msg


def test_unknown_attributes_are_refused():
    with pytest.raises(HydroConfigError, match=r"uvms.hydro: body 'b': unknown attribute 'mass'; allowed: pos"):
        config.parse_body("b", {"mass": "1"})
    with pytest.raises(HydroConfigError, match=r"uvms.water: unknown attribute 'rho'"):
        config.parse_water({"rho": "1000"})


def test_config_values_and_defaults():
    A = [100, 1, 2, 3, 4, 5, 100, 6, 7, 8, 9, 100, 10, 11, 12, 100, 13, 14, 100, 15, 100]
    w = config.parse_water({"current": "0.1 0 0"})
    assert w.density == 1000 and w.current_model == "constant" and w.terms == set(config.TERMS)
    np.testing.assert_array_equal(w.gm_mean, [0.1, 0, 0])  # gm_mean defaults to current
    np.testing.assert_array_equal(w.gm_tau, [10, 10, 10])
    b = config.parse_body("b", {"added_mass": " ".join(map(str, A)), "strips": "x 0 1 0.1 0.2; z -1 1 0 0.3 ;"})
    M = b.added_mass
    # 21 numbers: the upper triangle row by row
    assert M[0, 5] == 5 and M[5, 0] == 5 and M[1, 2] == 6 and M[2, 1] == 6 and M[4, 5] == 15 and M[5, 5] == 100
    assert b.strips == ((0, 0.0, 1.0, 0.1, 0.2), (2, -1.0, 1.0, 0.0, 0.3))
    assert b.pos is None and b.cob is None
    np.testing.assert_array_equal(b.quat, [1, 0, 0, 0])
    np.testing.assert_array_equal(config.parse_body("b", {"added_mass": "1 2 3 4 5 6"}).added_mass,
                                  np.diag([1.0, 2, 3, 4, 5, 6]))
    assert config.parse_water({"terms": ""}).terms == set(config.TERMS)  # empty = unset = all on


# ---------------------------------------------------------------------------- Gauss-Markov


def test_splitmix64_matches_the_published_sequence():
    # SplitMix64 (Steele, Lea, Flood 2014) from state 0: the state advances by the golden gamma
    # and each output is the finaliser; the first three outputs are these well-known constants
    gamma = 0x9E3779B97F4A7C15
    outs = [reference.splitmix64((k * gamma) & (2**64 - 1)) for k in range(3)]
    assert outs == [0xE220A8397B1DCDAF, 0x6E789E6AA1B965F4, 0x06C45D188009454F]


def test_gm_normal_is_standard_normal():
    n = np.array([reference.gm_normal(12345, k, c) for k in range(33334) for c in range(3)])
    N = n.size
    # 5 sigma of the sampling error: mean 1/sqrt(N), standard deviation 1/sqrt(2N)
    assert abs(n.mean()) < 5 / math.sqrt(N)
    assert abs(n.std() - 1) < 5 / math.sqrt(2 * N)
    # lag-1 correlation between consecutive samples of a component: ~N(0, 1/N)
    x = n[0::3]
    assert abs(np.corrcoef(x[:-1], x[1:])[0, 1]) < 5 / math.sqrt(x.size)
    assert reference.gm_normal(1, 7, 2) == reference.gm_normal(1, 7, 2) != reference.gm_normal(2, 7, 2)


def test_gauss_markov_stationary_statistics():
    sigma = np.array([0.2, 0.05, 0.1])
    mu = np.array([0.3, -0.1, 0.0])
    water = config.parse_water({"current_model": "gauss_markov", "current": "0.3 -0.1 0",
                                "gm_sigma": " ".join(map(str, sigma)), "gm_tau": "1 1 1", "gm_seed": "99"})
    h, n = 1.0, 60000  # phi = e^-1: successive samples correlate 0.37
    v = np.empty((n, 3))
    vk = np.array(water.current)
    for k in range(n):
        vk = reference.gm_step(water, vk, k, h)
        v[k] = vk
    phi = math.exp(-1.0)
    N_eff = n * (1 - phi**2) / (1 + phi**2)  # effective count for the variance of an AR(1)
    # 5 sigma of the sampling error of the standard deviation (sigma / sqrt(2 N_eff))
    assert np.all(np.abs(v.std(axis=0) / sigma - 1) < 5 / math.sqrt(2 * N_eff))
    assert np.all(np.abs(v.mean(axis=0) - mu) < 5 * sigma * math.sqrt((1 + phi) / (1 - phi) / n))
    lag1 = [np.corrcoef(v[:-1, c], v[1:, c])[0, 1] for c in range(3)]
    assert np.all(np.abs(np.array(lag1) - phi) < 5 / math.sqrt(n))


def test_gauss_markov_current_is_linear_between_samples_and_bounded():
    water = config.parse_water({"current_model": "gauss_markov", "current": "0 0 0", "gm_sigma": "1 1 1",
                                "gm_tau": "0.1 0.1 0.1", "gm_min": "-0.5 -2 -2", "gm_max": "0.5 2 2"})
    h = 0.01
    state = reference.initial_current_state(water, 0.0, h)
    vmax = 0.0
    for k in range(400):
        t = k * h
        v_a, a_c = reference.current_at(water, state, t + 0.25 * h, 0.0, h)
        v_b, _ = reference.current_at(water, state, t + 0.75 * h, 0.0, h)
        assert np.allclose(v_b - v_a, 0.5 * h * a_c, rtol=0, atol=1e-13)  # O(1) values: rounding
        state = reference.advance_current_state(water, state, t + h, h)
        assert state[1] == k + 1
        vmax = max(vmax, abs(state[2][0]))
    assert vmax == 0.5  # sigma = 1 >> bound: the clip is hit


def test_profile_current():
    water = config.parse_water({"current_model": "profile", "profile": "-10 0 0 0; -2 0.4 0 0; 0 0.5 0.1 0"})
    v, a = reference.current_at(water, None, 0.0, -6.0)
    np.testing.assert_allclose(v, [0.2, 0, 0], atol=1e-15)
    assert not a.any()
    np.testing.assert_allclose(reference.current_at(water, None, 0.0, 3.0)[0], [0.5, 0.1, 0])
    np.testing.assert_allclose(reference.current_at(water, None, 0.0, -30.0)[0], [0, 0, 0])


# ------------------------------------------------------------------ reading compiled models


def _plugins_registered() -> bool:
    try:
        mujoco.MjSpec.from_string(
            '<mujoco><extension><plugin plugin="uvms.water"><instance name="w"/></plugin>'
            '<plugin plugin="uvms.hydro"/></extension></mujoco>')
    except Exception:  # noqa: BLE001
        return False
    return True


@pytest.mark.skipif(not _plugins_registered(), reason="the uvms plugins are not registered")
@pytest.mark.parametrize("name", ["robot3d.xml", "single_body.xml"])
def test_read_spec_and_read_model_agree_with_the_file(name):
    xml = (ref_sim.MODELS / name).read_text()
    _, wcfg, bcfg = ref_sim.strip_uvms(xml)
    spec = mujoco.MjSpec.from_string(xml)
    water, bodies = config.read_spec(spec)
    m = spec.compile()
    water_m, bodies_m = config.read_model(m)
    truth_w = config.parse_water(wcfg)
    for w in (water, water_m):
        np.testing.assert_array_equal(w.current, truth_w.current)
        assert w.density == truth_w.density and w.terms == truth_w.terms
    assert set(bodies) == set(bcfg)
    assert {m.body(b).name for b in bodies_m} == set(bcfg)
    for b, hb in bodies_m.items():
        truth = config.parse_body(m.body(b).name, bcfg[m.body(b).name])
        for hb2 in (hb, bodies[m.body(b).name]):
            np.testing.assert_array_equal(hb2.added_mass, truth.added_mass)
            assert hb2.strips == truth.strips and hb2.volume == truth.volume
