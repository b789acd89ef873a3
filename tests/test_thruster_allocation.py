"""Thruster allocation for any layout (uvms_mj.physics.thrusters) against independent truths.

Truths: MuJoCo's own generalized actuator forces (qfrc_actuator of a free body), the columns
d_i, r_i x d_i computed by hand from docs (platform-3d.md), the paper robot's 3x3 matrix and
allocator (uvms_mj.planar.allocation), an exhaustive enumeration of active sets of the box-constrained
least squares (exact, finite: every thruster free, at its lower or at its upper limit), the KKT
conditions, and the thrust curves evaluated forwards.
"""

from __future__ import annotations

import itertools

import mujoco
import numpy as np
import pytest

from oracles.planar.allocation import Allocator as PlanarAllocator
from oracles.planar.allocation import allocation_matrix as planar_matrix
from oracles.planar.nominal import NominalModel
from uvms_mj.plant.plant import default_model_path
from uvms_mj.physics.thrusters import (Allocator, ThrustCurve, allocation_matrix, invert_curve, thrust_commands,
                               thruster_curves)

T200 = "poly 0 8.9 0 176.0 0 -404.1 0 389.9 0 -140.3"  # platform-3d.md, von Benzon et al. 2022


def rz(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def heavy_layout() -> tuple[np.ndarray, np.ndarray]:
    """BlueROV2 Heavy thruster positions r_i and directions d_i by hand from platform-3d.md
    (vehicle frame x forward, y left, z up)."""
    r, d = [], []
    for a, b in zip((0.0, 5.05, 1.91, np.pi), (0.0, np.pi / 2, 3 * np.pi / 2, np.pi)):
        r.append(rz(a) @ [0.156, 0.111, 0.085])
        d.append(rz(b) @ np.array([1.0, -1.0, 0.0]) / np.sqrt(2))
    for c in (0.0, 4.15, 1.01, np.pi):
        r.append(rz(c) @ [0.12, 0.218, 0.0])
        d.append(np.array([0.0, 0.0, -1.0]))
    return np.array(r), np.array(d)


def _v(x) -> str:
    return " ".join(f"{float(v):.17g}" for v in x)


def heavy_mjcf(com=(0.0, 0.0, 0.0)) -> str:
    """The 8 thrusters of the Heavy on a free body, written in three different ways so that
    every path of the transmission is exercised: horizontal thrusters on sites rotated about z
    (thrust along the site x axis), two vertical ones on unrotated sites with gear (0 0 -1)
    (general gear), two on sites pitched by +90 deg (x axis -> -z), one of the latter on a
    child body welded to the vehicle at an offset and a rotation."""
    r, _ = heavy_layout()
    sites, acts = [], []
    for i, b in enumerate((0.0, np.pi / 2, 3 * np.pi / 2, np.pi)):
        sites.append(f'<site name="t{i}" pos="{_v(r[i])}" euler="0 0 {np.degrees(b - np.pi / 4):.17g}"/>')
    sites.append(f'<site name="t4" pos="{_v(r[4])}"/>')
    sites.append(f'<site name="t5" pos="{_v(r[5])}"/>')
    sites.append(f'<site name="t6" pos="{_v(r[6])}" euler="0 90 0"/>')
    off = np.array([0.05, -0.02, 0.03])
    child_rot = rz(0.7)
    local = child_rot.T @ (r[7] - off)
    child_quat = np.empty(4)
    mujoco.mju_mat2Quat(child_quat, child_rot.ravel())
    for i in range(8):
        gear = "0 0 -1 0 0 0" if i in (4, 5) else "1 0 0 0 0 0"
        acts.append(f'<motor name="t{i}" site="t{i}" gear="{gear}"/>')
    # site t7 in the child body: x axis must point along world -z after the child's rotation
    return f"""
<mujoco>
  <compiler angle="degree"/>
  <option gravity="0 0 0"/>
  <worldbody>
    <body name="rov" pos="0.3 -0.2 1.0" euler="10 -20 30">
      <freejoint/>
      <inertial pos="{_v(com)}" mass="13.5" diaginertia="0.26 0.23 0.37"/>
      {"".join(sites)}
      <body name="bracket" pos="{_v(off)}" quat="{_v(child_quat)}">
        <geom type="sphere" size="0.01" mass="0.01"/>
        <site name="t7" pos="{_v(local)}" euler="0 90 0"/>
      </body>
    </body>
  </worldbody>
  <actuator>{"".join(acts)}</actuator>
</mujoco>"""


def mujoco_columns(m: mujoco.MjModel, d: mujoco.MjData) -> np.ndarray:
    """Independent truth from MuJoCo: unit force on each motor, qfrc_actuator of the free
    joint = (world force, body-frame torque about the body origin)."""
    R = d.xmat[1].reshape(3, 3)
    cols = []
    for i in range(m.nu):
        d.ctrl[:] = 0.0
        d.ctrl[i] = 1.0
        mujoco.mj_forward(m, d)
        q = d.qfrc_actuator[:6].copy()
        cols.append(np.r_[R.T @ q[:3], q[3:]])
    return np.array(cols).T


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20261201)


@pytest.fixture(scope="module")
def heavy():
    m = mujoco.MjModel.from_xml_string(heavy_mjcf(com=(0.01, -0.005, 0.02)))
    d = mujoco.MjData(m)
    d.qpos[3:7] = np.array([0.9, 0.2, -0.3, 0.25]) / np.linalg.norm([0.9, 0.2, -0.3, 0.25])
    mujoco.mj_forward(m, d)
    return m, d


# ---------------------------------------------------------------------------- allocation matrix


def test_paper_robot_planar_rows_reproduce_the_3x3_matrix():
    m = mujoco.MjModel.from_xml_path(str(default_model_path()))
    B = allocation_matrix(m)
    A = planar_matrix(NominalModel().params.thrusters)
    assert B.shape == (6, 3)
    # MuJoCo's site frames vs the planar closed form: the same numbers by different operations
    # (measured: bit for bit), so to a few ulps of the O(1) entries
    np.testing.assert_allclose(B[[0, 1, 5]], A, rtol=0, atol=1e-15 * max(1.0, np.abs(A).max()))
    np.testing.assert_allclose(B[[2, 3, 4]], 0.0, atol=1e-15)  # planar thrusters: no z, roll, pitch
    d = mujoco.MjData(m)  # any configuration: the body-frame matrix does not move
    d.qpos[:] = [0.4, -0.7, 1.1, 0.3, -0.5]
    mujoco.mj_forward(m, d)
    np.testing.assert_allclose(allocation_matrix(m, d), B, rtol=0, atol=1e-15)


def test_heavy_columns_by_hand_and_rank_6(heavy):
    m, d = heavy
    B = allocation_matrix(m, d)
    r, dirs = heavy_layout()
    for i in range(8):
        np.testing.assert_allclose(B[:3, i], dirs[i], rtol=0, atol=1e-12)
        np.testing.assert_allclose(B[3:, i], np.cross(r[i], dirs[i]), rtol=0, atol=1e-12)
    assert np.linalg.matrix_rank(B) == 6
    s = np.linalg.svd(B, compute_uv=False)
    assert s[-1] > 0.1  # well conditioned: smallest singular value about 0.3
    # horizontal thrusters: no z force, no roll/pitch from them beyond the 0.085 m height
    np.testing.assert_allclose(B[2, :4], 0.0, atol=1e-15)


def test_heavy_matrix_matches_mujoco_generalized_forces(heavy):
    m, d0 = heavy
    d = mujoco.MjData(m)
    d.qpos[:] = d0.qpos
    np.testing.assert_allclose(allocation_matrix(m, d0), mujoco_columns(m, d), rtol=0, atol=1e-12)


def test_world_frame_and_com_options(heavy):
    m, d = heavy
    R = d.xmat[1].reshape(3, 3)
    Bb = allocation_matrix(m, d)
    Bw = allocation_matrix(m, d, frame="world")
    np.testing.assert_allclose(Bw[:3], R @ Bb[:3], atol=1e-14)
    np.testing.assert_allclose(Bw[3:], R @ Bb[3:], atol=1e-14)
    c = m.body_ipos[1]  # CoM in the body frame: M_com = M_origin - c x F
    Bc = allocation_matrix(m, d, about="com")
    np.testing.assert_allclose(Bc[:3], Bb[:3], atol=1e-15)
    np.testing.assert_allclose(Bc[3:], Bb[3:] - np.cross(c, Bb[:3].T).T, atol=1e-14)
    sub = allocation_matrix(m, d, actuator_names=["t5", "t1"])
    np.testing.assert_array_equal(sub, Bb[:, [5, 1]])


def test_general_gear_with_torque_part_matches_mujoco(rng):
    xml = """<mujoco><option gravity="0 0 0"/><worldbody>
      <body name="b" pos="0.1 0.2 0.3" euler="0.3 -0.2 0.5"><freejoint name="fj"/>
        <geom type="box" size="0.2 0.1 0.1"/>
        <site name="s1" pos="0.2 -0.1 0.05" euler="0.4 0.1 -0.9"/>
        <site name="s2" pos="-0.15 0.1 0"/></body></worldbody>
      <actuator><motor name="a1" site="s1" gear="2 0.5 -0.3 0.1 -0.2 0.7"/>
        <motor name="a2" site="s2" gear="0 1 0 0 0 -1"/>
        <motor name="j" joint="fj" gear="0 0 1 0 0 0"/></actuator></mujoco>"""
    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    B = allocation_matrix(m, d)  # the joint motor is not a thruster
    assert B.shape == (6, 2)
    np.testing.assert_allclose(B, mujoco_columns(m, mujoco.MjData(m))[:, :2], rtol=0, atol=1e-12)


def test_allocation_matrix_bad_input(heavy):
    m, d = heavy
    with pytest.raises(ValueError, match="frame"):
        allocation_matrix(m, d, frame="ned")
    with pytest.raises(ValueError, match="about"):
        allocation_matrix(m, d, about="cob")
    with pytest.raises(ValueError, match="'nope'"):
        allocation_matrix(m, d, actuator_names=["t0", "nope"])
    with pytest.raises(ValueError, match="body"):
        allocation_matrix(m, d, body="nope")
    with pytest.raises(ValueError, match="mj_forward"):
        allocation_matrix(m, mujoco.MjData(m))
    pm = mujoco.MjModel.from_xml_path(str(default_model_path()))
    with pytest.raises(ValueError, match="site transmission"):
        allocation_matrix(pm, actuator_names=["thruster1", pm.actuator(3).name])
    with pytest.raises(ValueError, match="data"):
        allocation_matrix(pm, d)


# ---------------------------------------------------------------------------- allocator


def brute_force(Bs: np.ndarray, t: np.ndarray, lo, hi, eps: float = 0.0) -> np.ndarray:
    """Exact optimum by enumerating every active set (each thruster free, at lo, or at hi):
    on each, the free thrusters take the minimum-norm least squares; keep the feasible ones;
    the best weighted error, ties (within 1e-12 relative) broken by the smallest norm."""
    n = Bs.shape[1]
    best, best_key = None, None
    for state in itertools.product((0, 1, 2), repeat=n):
        state = np.array(state)
        u = np.where(state == 1, lo, np.where(state == 2, hi, 0.0)).astype(float)
        free = state == 0
        if free.any():
            A = Bs[:, free]
            r = t - Bs[:, ~free] @ u[~free]
            if eps > 0:
                A, r = np.vstack([A, np.sqrt(eps) * np.eye(free.sum())]), np.r_[r, np.zeros(free.sum())]
            u[free] = np.linalg.lstsq(A, r, rcond=None)[0]
        if np.any(u < lo - 1e-12) or np.any(u > hi + 1e-12):
            continue
        e = Bs @ u - t
        key = (float(e @ e + eps * u @ u), float(u @ u))
        if best is None or key[0] < best_key[0] * (1 - 1e-12) - 1e-24 or (
                key[0] <= best_key[0] * (1 + 1e-12) + 1e-24 and key[1] < best_key[1]):
            best, best_key = np.clip(u, lo, hi), key
    return best


def kkt(alloc: Allocator, tau: np.ndarray, u: np.ndarray, tol: float = 1e-9) -> None:
    """g = B_c^T W (B_c u - tau) + eps u: zero where free, <= 0 at hi, >= 0 at lo."""
    g = alloc.Bc.T @ alloc.W @ (alloc.Bc @ u - tau) + alloc.eps * u
    at_hi, at_lo = u >= alloc.hi, u <= alloc.lo
    scale = tol * (1 + np.abs(tau).max()) * (1 + np.abs(alloc.Bc).max()) ** 2
    assert np.all(np.abs(g[~(at_hi | at_lo)]) <= scale)
    assert np.all(g[at_hi & ~at_lo] <= scale)
    assert np.all(g[at_lo & ~at_hi] >= -scale)


def paper_allocator():
    m = mujoco.MjModel.from_xml_path(str(default_model_path()))
    params = NominalModel().params
    lo = [t.force_range[0] for t in params.thrusters]
    hi = [t.force_range[1] for t in params.thrusters]
    return Allocator(allocation_matrix(m), lo, hi, dofs=("x", "y", "yaw")), PlanarAllocator(params.thrusters)


def test_paper_unsaturated_equals_todays_allocator(rng):
    new, old = paper_allocator()
    count = 0
    for _ in range(500):
        tau = rng.normal(0, 8, 3) * [1, 1, 0.3]
        phi0 = rng.uniform(-np.pi, np.pi)
        c, s = np.cos(phi0), np.sin(phi0)
        world = np.r_[c * tau[0] - s * tau[1], s * tau[0] + c * tau[1], tau[2]]
        ref = old(world, phi0)
        if ref.saturated.any():
            continue
        count += 1
        out = new(tau)
        np.testing.assert_allclose(out.thrust, ref.thrust, rtol=0, atol=1e-12)
        np.testing.assert_allclose(out.thrust, old.A_inv @ tau, rtol=0, atol=1e-12)
        np.testing.assert_allclose(out.residual, 0.0, atol=1e-12)
        assert out.method == "redistribution" and out.iterations == 1 and not out.saturated.any()
    assert count > 100


def test_paper_saturated_is_the_exact_box_optimum(rng):
    new, old = paper_allocator()
    out = new([0.0, 0.0, 10.0])  # 10 N m needs -16.7 / +16.7 N: today's clip gives -8.849, 15.978
    # u1 = -8.849 (at its limit), u3 = 0, u2 minimises (u1 + u2)^2 + (0.3 (u2 - u1) - 10)^2
    # (the unweighted error trades surge force [N] against yaw moment [N m]):
    u2 = (2 * 8.849 + 0.6 * (10 - 0.3 * 8.849)) / (2 + 2 * 0.09)
    np.testing.assert_allclose(out.thrust, [-8.849, u2, 0.0], rtol=0, atol=1e-12)
    assert out.saturated.tolist() == [True, False, False]
    # weighting yaw 1e4 times more: both thrusters at their limits, yaw 0.3 (15.978 + 8.849) N m
    # would need u1 = -u2; the surge error is then the price of yaw
    heavy_yaw = Allocator(new.B, new.lo, new.hi, dofs=("x", "y", "yaw"), weights=[1, 1, 1e4])
    out = heavy_yaw([0.0, 0.0, 10.0])
    np.testing.assert_allclose(out.thrust, brute_force(heavy_yaw.Bs, heavy_yaw.S @ [0, 0, 10.0], new.lo, new.hi),
                               rtol=0, atol=1e-10)
    for _ in range(200):
        tau = rng.normal(0, 25, 3) * [1, 1, 0.3]
        out = new(tau)
        np.testing.assert_allclose(out.thrust, brute_force(new.Bs, tau, new.lo, new.hi), rtol=0, atol=1e-8)
        kkt(new, tau, out.thrust)
        assert np.all(out.thrust >= new.lo) and np.all(out.thrust <= new.hi)


def heavy_allocator(m, d, **kw):
    B = allocation_matrix(m, d)
    lo, hi = -30.0 * np.ones(8), 40.0 * np.ones(8)  # asymmetric, like the T200 at 16 V
    return Allocator(B, lo, hi, **kw)


@pytest.mark.parametrize("weights", [None, [1, 1, 1, 10, 10, 10], "matrix"])
def test_heavy_attainable_wrenches_are_reproduced(heavy, rng, weights):
    m, d = heavy
    if weights == "matrix":
        L = rng.normal(size=(6, 6))
        weights = L @ L.T + 6 * np.eye(6)
    alloc = heavy_allocator(m, d, weights=weights)
    methods = set()
    for _ in range(300):
        u_star = rng.uniform(-30, 40, 8) * 0.999  # strictly inside the box
        tau = alloc.B @ u_star
        out = alloc(tau)
        np.testing.assert_allclose(out.wrench, tau, rtol=0, atol=1e-10)
        np.testing.assert_allclose(out.residual, 0.0, atol=1e-10)
        assert np.all(out.thrust >= alloc.lo) and np.all(out.thrust <= alloc.hi)
        # minimum norm among the exact solutions in the box: never larger than u*'s
        assert out.thrust @ out.thrust <= u_star @ u_star + 1e-9
        methods.add(out.method)
    assert "redistribution" in methods


@pytest.mark.slow
def test_heavy_saturated_matches_exhaustive_optimum(heavy, rng):
    m, d = heavy
    alloc = heavy_allocator(m, d, weights=[1, 1, 1, 4, 4, 4])
    methods = set()
    for _ in range(15):
        tau = rng.normal(0, 1, 6) * [150, 150, 200, 20, 20, 20]
        out = alloc(tau)
        ref = brute_force(alloc.Bs, alloc.S @ tau, alloc.lo, alloc.hi)
        e_ref = alloc.Bs @ ref - alloc.S @ tau
        assert out.cost == pytest.approx(e_ref @ e_ref, rel=1e-8, abs=1e-8)
        np.testing.assert_allclose(out.wrench, alloc.Bc @ ref, rtol=0, atol=1e-8)  # unique
        np.testing.assert_allclose(out.thrust, ref, rtol=0, atol=1e-7)
        kkt(alloc, tau, out.thrust)
        methods.add(out.method)
    assert any(out.saturated.any() for out in [out])


def test_heavy_saturated_tie_takes_the_smallest_norm(heavy):
    """A saturating wrench whose weighted-error minimisers form a segment (2-D null space of
    B, two thrusters at limits): the redistribution alone lands on another minimiser, with
    ||u||^2 larger by 1389 N^2; the second stage returns the smallest-norm one (exhaustive
    truth)."""
    m, _ = heavy
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)  # the upright vehicle of heavy_mjcf
    alloc = heavy_allocator(m, d)
    tau = np.array([173.002962, -150.435756, 37.149186, -6.466287, 9.525826, -8.40983])
    out = alloc(tau)
    ref = brute_force(alloc.Bs, tau, alloc.lo, alloc.hi)
    np.testing.assert_allclose(out.thrust, ref, rtol=0, atol=1e-9)
    first, _ = alloc._redistribute(alloc.Bs, tau)  # stage one alone: same cost, larger norm
    assert (first - ref) @ (first - ref) > 1.0 and np.allclose(alloc.Bc @ first, alloc.Bc @ ref, atol=1e-9)
    kkt(alloc, tau, out.thrust)


def test_redundant_attainable_outside_pinv_box_is_minimum_norm(heavy, rng):
    """Attainable wrenches whose minimum-norm solution leaves the box: still exact, and the
    smallest-norm exact solution inside the box (exhaustive truth)."""
    m, d = heavy
    alloc = heavy_allocator(m, d)
    done, methods = 0, set()
    while done < 12:
        u_star = rng.uniform(-30, 40, 8) * 0.999
        tau = alloc.B @ u_star
        pinv = np.linalg.pinv(alloc.B) @ tau
        if np.all((pinv >= -30) & (pinv <= 40)):
            continue
        done += 1
        out = alloc(tau)
        np.testing.assert_allclose(out.wrench, tau, rtol=0, atol=1e-10)
        ref = brute_force(alloc.Bs, tau, alloc.lo, alloc.hi)
        assert out.thrust @ out.thrust == pytest.approx(ref @ ref, rel=1e-8)
        np.testing.assert_allclose(out.thrust, ref, rtol=0, atol=1e-7)
        methods.add(out.method)
    assert methods == {"redistribution"}  # here redistribution finds an exact solution


def test_random_problems_with_eps_and_dofs_vs_exhaustive(rng):
    for trial in range(60):
        k, n = rng.integers(2, 5), rng.integers(2, 6)
        B = rng.normal(size=(k + 1, n))
        lo = -rng.uniform(0.2, 2, n)
        hi = rng.uniform(0.2, 2, n)
        if trial % 5 == 0:
            hi[0] = lo[0] = 0.3  # a thruster with equal limits (fixed)
        eps = 0.0 if trial % 2 else 1e-3
        w = rng.uniform(0.5, 3, k)
        dofs = list(range(1, k + 1))
        alloc = Allocator(B, lo, hi, weights=w, dofs=dofs, eps=eps)
        tau = rng.normal(0, 3, k)
        out = alloc(tau)
        ref = brute_force(alloc.Bs, alloc.S @ tau, lo, hi, eps)
        e = alloc.Bs @ ref - alloc.S @ tau
        assert out.cost == pytest.approx(e @ e + eps * ref @ ref, rel=1e-8, abs=1e-10)
        np.testing.assert_allclose(out.wrench, B[dofs] @ ref, rtol=0, atol=1e-8)
        kkt(alloc, tau, out.thrust)
        np.testing.assert_allclose(out.full_wrench, B @ out.thrust, atol=1e-14)
        # a full-length tau is read on the controlled rows
        full = np.r_[99.0, tau]
        np.testing.assert_array_equal(alloc(full).thrust, out.thrust)


def test_allocator_bad_input():
    B = np.eye(3)
    with pytest.raises(ValueError, match="lo"):
        Allocator(B, [1, 1, 1], [0, 2, 2])  # lo > hi
    with pytest.raises(ValueError, match="hi"):
        Allocator(B, -1, [1, 1])
    with pytest.raises(ValueError, match="B"):
        Allocator([1, 2, 3], -1, 1)
    with pytest.raises(ValueError, match="B"):
        Allocator([[1, np.nan], [0, 1]], -1, 1)
    with pytest.raises(ValueError, match="lo"):
        Allocator(B, [np.nan, 0, 0], 1)
    with pytest.raises(ValueError, match="weights"):
        Allocator(B, -1, 1, weights=[1, -1, 1])
    with pytest.raises(ValueError, match="weights"):
        Allocator(B, -1, 1, weights=[1, 1])
    with pytest.raises(ValueError, match="weights"):
        Allocator(B, -1, 1, weights=[[1, 2, 0], [2, 1, 0], [0, 0, 1]])  # not positive definite
    with pytest.raises(ValueError, match="dofs"):
        Allocator(B, -1, 1, dofs=["yaw"])  # names need 6 rows
    with pytest.raises(ValueError, match="dofs"):
        Allocator(np.eye(6), -1, 1, dofs=["x", "x"])
    with pytest.raises(ValueError, match="eps"):
        Allocator(B, -1, 1, eps=-1)
    alloc = Allocator(B, -1, 1)
    with pytest.raises(ValueError, match="tau"):
        alloc([1, 2])
    with pytest.raises(ValueError, match="tau"):
        alloc([1, np.nan, 2])
    inf = Allocator(B, -np.inf, [np.inf, 1, np.inf])  # infinite limits are allowed
    np.testing.assert_allclose(inf([5, 5, 5]).thrust, [5, 1, 5])


# ---------------------------------------------------------------------------- thrust curves


def test_t200_monotone_branch_and_inverse():
    """The T200 polynomial is not monotone on [-1, 1]: F' = 0 at |V| = 0.97166, where F peaks
    at 30.62 N, above F(1) = 30.40 N. The inverse lives on [-0.97166, 0.97166]."""
    c = ThrustCurve.parse(T200)
    a, b, sign = c.monotone_range()
    assert sign == 1 and a == pytest.approx(-0.9716561711867696, abs=1e-12) and b == pytest.approx(-a, abs=1e-12)
    assert abs(c.derivative(b)) < 1e-10 and c.derivative(1.0) == pytest.approx(-17.0, abs=1e-9)
    assert c(b) == pytest.approx(30.6217533706272, abs=1e-9) and c(1.0) == pytest.approx(30.4, abs=1e-12)
    u = np.linspace(-0.9716, 0.9716, 4001)  # F' >= 0.0005 * F'' scale here: well conditioned
    np.testing.assert_allclose(invert_curve(T200, c(u)), u, rtol=0, atol=1e-10)
    np.testing.assert_allclose(invert_curve(c, c(u).reshape(1, -1, 1)), u.reshape(1, -1, 1), rtol=0, atol=1e-10)
    # forwards: any reachable thrust is produced (random thrusts, 1e-12 N)
    F = np.random.default_rng(7).uniform(c(a), c(b), 50000)
    np.testing.assert_allclose(c(invert_curve(c, F)), F, rtol=0, atol=1e-12)
    # unreachable thrusts clamp to the branch ends
    np.testing.assert_array_equal(invert_curve(c, [100.0, -100.0, 0.0]), [b, a, 0.0])
    # a narrower command range is honoured
    assert invert_curve(T200, 100.0, -0.5, 0.5) == 0.5


def test_polys_tables_and_decreasing_curves(rng):
    lin = ThrustCurve.parse("poly 0.5 2")
    np.testing.assert_allclose(invert_curve(lin, [0.5, 2.5, 10.0]), [0.0, 1.0, 1.0], atol=1e-15)
    cubic = "poly 0 0 0 1"  # F' = 0 at 0 without a sign change: monotone on all of [-1, 1]
    assert ThrustCurve.parse(cubic).monotone_range() == (-1.0, 1.0, 1)
    u = rng.uniform(-1, 1, 10000)
    u = u[np.abs(u) > 1e-2]  # F' = 3 u^2: u known to ~4e-16 / (3 u^2)
    np.testing.assert_allclose(invert_curve(cubic, u ** 3), u, rtol=0, atol=1e-10)
    table = "table -1 -8.849 -0.2 -1 0 0 0.3 2.5 1 15.978"
    tc = ThrustCurve.parse(table)
    u = rng.uniform(-1, 1, 500)
    np.testing.assert_allclose(invert_curve(table, tc(u)), u, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(invert_curve(table, [-20.0, 20.0]), [-1.0, 1.0])
    dec = "table 0 10 1 5 2 -3"
    np.testing.assert_allclose(invert_curve(dec, [10, 7.5, 1, -3, 50]), [0, 0.5, 1.5, 2, 0], atol=1e-15)
    decp = "poly 0 -3 0 -1"
    u = rng.uniform(-1, 1, 10000)
    np.testing.assert_allclose(invert_curve(decp, ThrustCurve.parse(decp)(u)), u, rtol=0, atol=1e-12)
    # one curve per thruster
    np.testing.assert_allclose(invert_curve([T200, table, lin], [0.0, 2.5, 1.5]), [0.0, 0.3, 0.5], atol=1e-14)


def test_curve_bad_input():
    for bad in ("", "spline 1 2", "poly", "poly a b", "table 0 0 1", "table 1 0 0 1", "poly 0 nan"):
        with pytest.raises(ValueError, match="curve"):
            ThrustCurve.parse(bad)
    with pytest.raises(ValueError, match="monotone"):
        invert_curve("table 0 0 1 1 2 0", 0.5)
    with pytest.raises(ValueError, match="constant"):
        invert_curve("poly 3", 0.5)
    with pytest.raises(ValueError, match="F"):
        invert_curve(T200, [1.0, np.nan])
    with pytest.raises(ValueError, match="F"):
        invert_curve([T200, T200], [1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="range"):
        invert_curve(T200, 1.0, 0.5, -0.5)


# ---------------------------------------------------------------------------- the model's curves


def heavy_with_plugins(tau: float = 0.0) -> mujoco.MjModel:
    """The Heavy layout with `uvms.thruster` actuators: six T200 sharing an instance (no lag,
    so that the force follows the command at once), one table curve, one plain motor."""
    xml = heavy_mjcf()
    acts = xml[xml.index("<actuator>") + len("<actuator>"):xml.index("</actuator>")]
    new = []
    for i, line in enumerate(acts.split("/>")[:-1]):
        site, gear = line.split('site="')[1].split('"')[0], line.split('gear="')[1].split('"')[0]
        if i < 6:
            new.append(f'<plugin instance="T200" site="{site}" gear="{gear}" ctrlrange="-1 1"/>')
        elif i == 6:
            new.append(f'<plugin plugin="uvms.thruster" site="{site}" gear="{gear}" ctrlrange="-2 2">'
                       '<config key="curve" value="table -2 -20 0 0 1 15 2 40"/></plugin>')
        else:
            new.append(f'<motor site="{site}" gear="{gear}"/>')
    ext = ('<extension><plugin plugin="uvms.thruster"><instance name="T200">'
           f'<config key="curve" value="{T200}"/><config key="tau" value="{tau!r}"/></instance>'
           '</plugin></extension>')
    xml = xml.replace(acts, "".join(new)).replace("<worldbody>", ext + "<worldbody>", 1)
    try:
        return mujoco.MjModel.from_xml_string(xml)
    except ValueError as err:
        if "uvms.thruster" in str(err):
            pytest.skip(f"uvms.thruster plugin not registered here ({err})")
        raise


def test_model_curves_and_commands_through_the_plugin(rng):
    """Truth: the C plugin itself. Commands from thrust_commands, mj_forward, the actuator
    forces are the requested thrusts (1e-10), and the generalized force is J^T B f."""
    m = heavy_with_plugins()  # (importing uvms_mj registered the plugins)
    curves = thruster_curves(m)
    assert curves[0] == ThrustCurve.parse(T200) and curves[5] == curves[0]
    assert curves[6] == ThrustCurve.parse("table -2 -20 0 0 1 15 2 40")
    assert curves[7] == ThrustCurve("poly", coeffs=(0.0, 1.0))
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    B = allocation_matrix(m, d)
    peak = float(ThrustCurve.parse(T200)(ThrustCurve.parse(T200).monotone_range()[1]))
    lo = np.r_[[-peak] * 6, -20.0, -50.0]
    hi = np.r_[[peak] * 6, 40.0, 50.0]
    alloc = Allocator(B, lo, hi)
    for _ in range(20):
        tau = B @ rng.uniform(lo, hi) * 0.9
        out = alloc(tau)
        d.ctrl[:] = thrust_commands(m, out.thrust)
        mujoco.mj_forward(m, d)
        np.testing.assert_allclose(d.actuator_force, out.thrust, rtol=0, atol=1e-10)
        np.testing.assert_allclose(mujoco_columns_from_force(m, d), tau, rtol=0, atol=1e-9)
    # unreachable thrusts clamp to the command range
    cmd = thrust_commands(m, [100.0, -100.0, 0, 0, 0, 0, 100.0, 7.5])
    np.testing.assert_allclose(cmd[[0, 1, 6, 7]], [ThrustCurve.parse(T200).monotone_range()[1],
                                                   ThrustCurve.parse(T200).monotone_range()[0], 2.0, 7.5])
    with pytest.raises(ValueError, match="thrust"):
        thrust_commands(m, [1.0, 2.0])


def mujoco_columns_from_force(m: mujoco.MjModel, d: mujoco.MjData) -> np.ndarray:
    """Body wrench of the free body from MuJoCo's qfrc_actuator (world force, body torque)."""
    R = d.xmat[1].reshape(3, 3)
    return np.r_[R.T @ d.qfrc_actuator[:3], d.qfrc_actuator[3:6]]
