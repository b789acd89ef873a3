"""The 3-D platform models (models/<name>/<name>.xml: bluerov2_heavy, alpha_arm, bluerov2_alpha,
hinsdale2023) against truths of their own.

Every expected number here is computed in this file from the published parameters (von Benzon
et al. 2022 Table A1 and thruster layout, the Alpha link table, the Hinsdale reference model),
not read back from the model files: hydrostatic sums, the hand-computed rest attitude, the
allocation matrix from the published layout (FSD, converted to FLU with T = diag(1, -1, -1)),
the T200 polynomial, the arm's added mass and strips from the cylinder formulas, and a 6-DOF
Fossen model integrated with scipy (written here, not the project's reference code).
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import fsolve

import uvms_mj  # noqa: F401  (the plugins: registered once by conftest.py)
from uvms_mj.physics import hydro_of, load_model

MODELS = Path(__file__).resolve().parents[1] / "models"
NAMES = ("bluerov2_heavy", "alpha_arm", "bluerov2_alpha", "hinsdale2023")
RHO, G = 1000.0, 9.81

# --- the published parameters (von Benzon et al. 2022, Table A1; FSD frame) -------------------
VB_M, VB_I, VB_V, VB_ZB_FSD = 13.5, np.array([0.26, 0.23, 0.37]), 0.0134, -0.01
VB_MA = np.array([6.36, 7.12, 18.68, 0.189, 0.135, 0.222])
VB_DL = np.array([13.7, 0.0, 33.0, 0.0, 0.8, 0.0])
VB_DQ = np.array([141.0, 217.0, 190.0, 1.19, 0.47, 1.5])
T200 = {9: -140.3, 7: 389.9, 5: -404.1, 3: 176.0, 1: 8.9}  # F(V) = sum c V^k [N]
TAU_THRUSTER = 0.05  # [A] in the model file
T_FSD_FLU = np.diag([1.0, -1.0, -1.0])

# Alpha link table (platform-3d.md): mass [kg], volume [L]; jaw from MagicNumAlpha.jl.
ARM = {"alpha_base": (0.341, 0.202), "alpha_shoulder": (0.194, 0.018), "alpha_upper_arm": (0.429, 0.203),
       "alpha_forearm": (0.115, 0.025), "alpha_wrist": (0.333, 0.155), "alpha_jaw": (0.05, 0.02)}
# Link tubes (reference URDF collision cylinders): length, axis of the hydrodynamic frame.
TUBES = {"alpha_base": (0.150, 0), "alpha_shoulder": (0.066, 2), "alpha_upper_arm": (0.145, 0),
         "alpha_forearm": (0.040, 2), "alpha_wrist": (0.140, 2)}
R_TUBE, CD = 0.020, 1.1

# Hinsdale reference model (MagicNumBlueROVHardware.jl, URDF comment): vehicle, extras (N).
H_MASS, H_BUOY_KG = 14.24, 13.082
H_WEIGHTS_N = (3.24, 1.62, 1.62, 0.69, 1.01)
H_FOAM_N = (8.46, 8.66 + 0.2)


def rz(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def t200(v):
    return sum(c * np.asarray(v, float) ** k for k, c in T200.items())


def layout_flu() -> tuple[np.ndarray, np.ndarray]:
    """Positions and thrust directions (8 x 3, FLU) of the published Heavy layout (FSD)."""
    r, d = [], []
    for a, b in zip((0, 5.05, 1.91, np.pi), (0, np.pi / 2, 3 * np.pi / 2, np.pi)):
        r.append(T_FSD_FLU @ rz(a) @ [0.156, 0.111, 0.085])
        d.append(T_FSD_FLU @ rz(b) @ (np.array([1.0, -1.0, 0.0]) / np.sqrt(2)))
    for c in (0, 4.15, 1.01, np.pi):
        r.append(T_FSD_FLU @ rz(c) @ [0.12, 0.218, 0.0])
        d.append(T_FSD_FLU @ [0.0, 0.0, -1.0])
    return np.array(r), np.array(d)


def allocation_hand() -> np.ndarray:
    r, d = layout_flu()
    return np.vstack([d.T, np.cross(r, d).T])


@pytest.fixture(scope="module")
def models():
    return {n: mujoco.MjModel.from_xml_path(str(MODELS / n / f"{n}.xml")) for n in NAMES}


def body(m, name):
    return mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, name)


# ------------------------------------------------------------------------------------- loading


@pytest.mark.parametrize("name", NAMES)
def test_loads_plain_and_checked(name, models):
    m = models[name]
    m2 = load_model(MODELS / name / f"{name}.xml")
    assert m2.nq == m.nq and m2.nu == m.nu and m2.nbody == m.nbody
    assert hydro_of(m2).native and hydro_of(m).water.density == RHO
    # Joint limits on every hinge, ranges on every actuator; no contacts anywhere.
    hinges = m.jnt_type == mujoco.mjtJoint.mjJNT_HINGE
    assert np.all(m.jnt_limited[hinges]) and np.all(m.jnt_range[hinges, 1] > m.jnt_range[hinges, 0])
    assert np.all(m.actuator_ctrllimited) and np.all(m.actuator_forcelimited)
    assert not np.any(m.geom_contype) and not np.any(m.geom_conaffinity)
    d = mujoco.MjData(m)
    for _ in range(20):
        mujoco.mj_step(m, d)
    assert np.all(np.isfinite(d.qpos))


def test_no_simple_free_body(models):
    for n in ("bluerov2_heavy", "bluerov2_alpha", "hinsdale2023"):
        m = models[n]
        assert m.body_simple[body(m, "bluerov2")] == 0


def test_composed_vehicle_root_equals_vehicle_file(models):
    a, b = models["bluerov2_heavy"], models["bluerov2_alpha"]
    ia, ib = body(a, "bluerov2"), body(b, "bluerov2")
    assert a.body_mass[ia] == b.body_mass[ib] == VB_M
    np.testing.assert_array_equal(a.body_inertia[ia], b.body_inertia[ib])
    ha, hb = hydro_of(a).bodies[ia], hydro_of(b).bodies[ib]
    assert ha.volume == hb.volume and np.array_equal(ha.cob, hb.cob)


# ---------------------------------------------------------------------------- vehicle numbers


def test_vehicle_parameters_converted_to_flu(models):
    m = models["bluerov2_heavy"]
    iv, ih = body(m, "bluerov2"), body(m, "bluerov2_hull")
    info = hydro_of(m).bodies
    assert m.body_mass[iv] == VB_M and np.allclose(m.body_inertia[iv], VB_I)
    assert np.allclose(m.body_ipos[iv], 0)
    assert info[iv].volume == VB_V
    np.testing.assert_allclose(info[iv].cob, T_FSD_FLU @ [0, 0, VB_ZB_FSD])  # 1 cm above the CG
    S = np.diag([1, -1, -1, 1, -1, -1.0])  # diagonal matrices are unchanged by FSD -> FLU
    np.testing.assert_allclose(info[ih].added_mass, S @ np.diag(VB_MA) @ S)
    np.testing.assert_allclose(info[ih].linear_damping, VB_DL)
    np.testing.assert_allclose(info[ih].quadratic_damping, VB_DQ)
    np.testing.assert_allclose(info[ih].pos, 0)


def test_t200_curve(models):
    m = models["bluerov2_heavy"]
    d = mujoco.MjData(m)
    vs = np.array([-1.0, -0.7, -0.2, 0.0, 0.05, 0.3, 0.6, 0.97166, 1.0])
    for v in vs:
        d.act[:] = v
        mujoco.mj_forward(m, d)
        np.testing.assert_allclose(d.actuator_force, t200(v), rtol=0, atol=1e-12)
    grid = np.linspace(-1, 1, 200001)
    fmax = np.abs(t200(grid)).max()
    # forcerange just outside the curve's extremes (never clamps), ctrlrange the input's.
    assert np.all(m.actuator_forcerange[:, 1] >= fmax) and np.all(m.actuator_forcerange[:, 1] - fmax < 1e-3)
    assert np.all(m.actuator_forcerange[:, 0] == -m.actuator_forcerange[:, 1])
    np.testing.assert_array_equal(m.actuator_ctrlrange, np.tile([-1.0, 1.0], (8, 1)))


def test_allocation_matrix(models):
    m = models["bluerov2_heavy"]
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)  # vehicle at the origin, level: world = body frame
    ids = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, f"bluerov2_t{i}") for i in range(1, 9)]
    r = d.site_xpos[ids]
    dirs = d.site_xmat[ids].reshape(-1, 3, 3)[:, :, 0]  # thrust along each site's x axis
    B_sites = np.vstack([dirs.T, np.cross(r, dirs).T])
    B_hand = allocation_hand()
    np.testing.assert_allclose(B_sites, B_hand, atol=1e-9)  # positions written to 1e-9 m
    assert np.linalg.matrix_rank(B_sites, tol=1e-9) == 6
    assert np.linalg.svd(B_sites, compute_uv=False).min() > 0.1
    # MuJoCo's generalized thruster force is B F: free-joint dofs (world linear, body angular).
    for i in range(8):
        d.act[:] = 0
        d.act[i] = 0.5
        mujoco.mj_forward(m, d)
        np.testing.assert_allclose(d.qfrc_actuator[:6], B_sites[:, i] * t200(0.5), atol=1e-12)


# ------------------------------------------------------------------------------------- the arm


def test_arm_added_mass_and_strips(models):
    for n in ("alpha_arm", "bluerov2_alpha", "hinsdale2023"):
        m = models[n]
        info = hydro_of(m).bodies
        for link, (mass, vol_l) in ARM.items():
            b = body(m, link)
            assert m.body_mass[b] == pytest.approx(mass, abs=1e-12)
            assert info[b].volume == pytest.approx(vol_l * 1e-3, abs=1e-15)
        for link, (L, axis) in TUBES.items():
            h = info[body(m, link)]
            mt = RHO * np.pi * R_TUBE**2 * L           # transverse added mass
            it = mt * L**2 / 12                        # added inertia about transverse axes
            lin, rot = np.full(3, mt), np.full(3, it)
            lin[axis] = rot[axis] = 0.0                # axial: neglected ("small")
            # the file writes 6 significant digits: rounding <= 5e-6 relative
            np.testing.assert_allclose(np.diag(h.added_mass), np.r_[lin, rot], rtol=5e-6)
            assert np.count_nonzero(h.added_mass - np.diag(np.diag(h.added_mass))) == 0
            assert len(h.strips) == 1
            ax, s0, s1, c1, c2 = h.strips[0]
            assert int(ax) == axis and s0 == pytest.approx(-L / 2) and s1 == pytest.approx(L / 2)
            assert c1 == pytest.approx(CD * 2 * R_TUBE) and c2 == pytest.approx(CD * 2 * R_TUBE)


def test_arm_reach_and_limits(models):
    m = models["alpha_arm"]
    deg = np.pi / 180
    lim = {"alpha_base": (-175, 175), "alpha_shoulder": (0, 200), "alpha_elbow": (0, 200), "alpha_wrist": (-165, 165)}
    for j, (lo, hi) in lim.items():
        np.testing.assert_allclose(m.joint(j).range, [lo * deg, hi * deg], atol=1e-12)
    # Reach: the farthest the jaw gets from the mount over the shoulder/elbow range, about 0.4 m
    # (Alpha 5 class), against the chain's own offsets: 0.046 up to the shoulder axis, then
    # 0.15 and hypot(0.02, 0.19) in line.
    d = mujoco.MjData(m)
    tip, mount = m.site("alpha_tip").id, body(m, "alpha_mount")
    reach = 0.0
    for qs in np.linspace(0, 200 * deg, 41):
        for qe in np.linspace(0, 200 * deg, 41):
            d.qpos[:] = [0, qs, qe, 0]
            mujoco.mj_kinematics(m, d)
            reach = max(reach, np.linalg.norm(d.site_xpos[tip] - d.xpos[mount]))
    assert reach <= np.hypot(0.02, 0.046) + 0.15 + np.hypot(0.02, 0.19) + 1e-12
    assert 0.35 < reach < 0.42
    np.testing.assert_allclose(m.actuator_ctrlrange, [[-9, 9], [-9, 9], [-9, 9], [-5, 5]])


# --------------------------------------------------------------------------------- hydrostatics


def hand_net_force(name: str) -> float:
    """sum (rho V - m) g from the published numbers (N, + = up)."""
    arm = sum(RHO * v * 1e-3 - mass for mass, v in ARM.values()) * G
    vehicle = (RHO * VB_V - VB_M) * G
    if name == "bluerov2_heavy":
        return vehicle
    if name == "alpha_arm":
        return arm
    if name == "bluerov2_alpha":
        return vehicle + arm
    return (H_BUOY_KG - H_MASS) * G - sum(H_WEIGHTS_N) + sum(H_FOAM_N) + arm


EXPECTED_NET = {"bluerov2_heavy": -0.981, "alpha_arm": -8.23059, "bluerov2_alpha": -9.21159,
                "hinsdale2023": -10.45057}


@pytest.mark.parametrize("name", NAMES)
def test_net_hydrostatic_force(name, models):
    m = models[name]
    info = hydro_of(m).bodies
    model_sum = (RHO * sum(h.volume for h in info.values()) - m.body_mass.sum()) * G
    hand = hand_net_force(name)
    assert hand == pytest.approx(EXPECTED_NET[name], abs=1e-5)
    assert model_sum == pytest.approx(hand, abs=1e-9)
    if m.jnt_type[0] == mujoco.mjtJoint.mjJNT_FREE:
        # What MuJoCo + the plugin apply at rest: the vertical generalized force of the free joint.
        d = mujoco.MjData(m)
        if m.nkey:
            mujoco.mj_resetDataKeyframe(m, d, 0)
        mujoco.mj_forward(m, d)
        f = d.qfrc_passive[:3] - d.qfrc_bias[:3]
        np.testing.assert_allclose(f, [0, 0, hand], atol=1e-9)


def quat_rp(roll: float, pitch: float) -> np.ndarray:
    """Quaternion (w x y z) of Z-Y-X Euler angles (yaw 0, pitch, roll)."""
    cr, sr, cp, sp = np.cos(roll / 2), np.sin(roll / 2), np.cos(pitch / 2), np.sin(pitch / 2)
    return np.array([cp * cr, cp * sr, sp * cr, -sp * sr])


def hand_rest_attitude(m, qarm) -> tuple[float, float]:
    """Roll, pitch at which the hydrostatic moment about the vehicle origin vanishes.

    Own sums over the bodies at the given (rigid) arm pose: with W r_G = sum m_i g r_Gi and
    B r_C = sum rho V_i g r_Ci in the vehicle frame, the moment (B r_C - W r_G) x z_world is zero
    when s = B r_C - W r_G points up (stable), i.e. R^T z = s / |s| = (-sin p, sin r cos p,
    cos r cos p). The positions come from MuJoCo's kinematics only (no forces)."""
    d = mujoco.MjData(m)
    d.qpos[7:] = qarm
    d.qpos[3] = 1.0
    mujoco.mj_kinematics(m, d)
    s = np.zeros(3)
    for b in range(1, m.nbody):
        s -= m.body_mass[b] * G * d.xipos[b]
    for b, h in hydro_of(m).bodies.items():
        s += RHO * h.volume * G * (d.xpos[b] + d.xmat[b].reshape(3, 3) @ h.cob)
    s /= np.linalg.norm(s)
    return float(np.arctan2(s[1], s[2])), float(np.arcsin(-s[0]))


def model_rest_attitude(m, qarm) -> tuple[float, float]:
    """Roll, pitch at which MuJoCo's gravity and the plugin's buoyancy give no moment on the
    free joint (its rotational generalized force = the moment about the vehicle origin)."""
    d = mujoco.MjData(m)

    def moment(x):
        d.qpos[:] = 0
        d.qpos[3:7] = quat_rp(*x)
        d.qpos[7:] = qarm
        d.qvel[:] = 0
        mujoco.mj_forward(m, d)
        tau_body = d.qfrc_passive[3:6] - d.qfrc_bias[3:6]
        return (d.xmat[body(m, "bluerov2")].reshape(3, 3) @ tau_body)[:2]

    x = fsolve(moment, [0.0, 0.0], xtol=1e-13)
    assert np.abs(moment(x)).max() < 1e-10
    return float(x[0]), float(x[1])


def arm_pose(m, name):
    if name == "hinsdale2023":
        return m.key("baseline1").qpos[7:].copy()
    return np.zeros(m.nq - 7)


@pytest.mark.parametrize("name", ["bluerov2_heavy", "bluerov2_alpha", "hinsdale2023"])
def test_rest_attitude(name, models):
    m = models[name]
    q = arm_pose(m, name)
    hand = hand_rest_attitude(m, q)
    sim = model_rest_attitude(m, q)
    # Both are exact zeros of smooth functions; fsolve converges to ~1e-12 rad.
    np.testing.assert_allclose(sim, hand, atol=1e-9)
    if name == "bluerov2_heavy":
        np.testing.assert_allclose(hand, 0.0, atol=1e-15)


def welded(name: str, qarm) -> mujoco.MjModel:
    """The model with its arm joints removed and the links welded at the angles qarm (each
    child body turned about its joint axis; the joints sit at the body origins), thrusters and
    arm motors kept out of the way (no commands)."""
    spec = mujoco.MjSpec.from_file(str(MODELS / name / f"{name}.xml"))
    for jname, q in zip(("alpha_base", "alpha_shoulder", "alpha_elbow", "alpha_wrist"), qarm):
        j = spec.joint(jname)
        assert np.allclose(j.pos, 0)
        turn, res = np.zeros(4), np.zeros(4)
        mujoco.mju_axisAngle2Quat(turn, np.array(j.axis, float), float(q))
        mujoco.mju_mulQuat(res, np.array(j.parent.quat, float), turn)
        j.parent.quat = res
        spec.delete(j)
    for a in list(spec.actuators):
        if a.name.startswith("alpha_"):
            spec.delete(a)
    for k in list(spec.keys):
        spec.delete(k)
    return spec.compile()


@pytest.mark.parametrize("name", ["bluerov2_heavy", "bluerov2_alpha", "hinsdale2023"])
def test_rest_attitude_by_simulation(name, models):
    """Released level with the arm held (welded) at its pose, with extra implicit damping on the
    free joint and the net hydrostatic force carried at the vehicle origin (as steady sinking
    drag at the origin would), the vehicle comes to rest at the hand-computed attitude."""
    q = arm_pose(models[name], name)
    m = welded(name, q) if name != "bluerov2_heavy" else load_model(MODELS / name / f"{name}.xml")
    m.opt.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    m.opt.timestep = 0.01
    m.dof_damping[:6] = [20, 20, 20, 2, 2, 2]  # changes the way there, not the rest state
    d = mujoco.MjData(m)
    d.qpos[3:7] = quat_rp(0.2, -0.15)
    d.xfrc_applied[body(m, "bluerov2"), 2] = -hand_net_force(name)
    for _ in range(4000):
        mujoco.mj_step(m, d)
    up = d.xmat[body(m, "bluerov2")].reshape(3, 3)[2]  # world z in the vehicle's axes
    roll, pitch = np.arctan2(up[1], up[2]), np.arcsin(-up[0])
    assert np.abs(d.qvel).max() < 1e-8
    # at rest to 1e-8 rad/s: the remaining angle error, (rate x decay time ~ 1 s), is < 1e-7 rad
    np.testing.assert_allclose([roll, pitch], hand_rest_attitude(models[name], q), atol=1e-7)


# ----------------------------------------------------------------------- Hinsdale configuration


def test_hinsdale_configuration(models):
    m = models["hinsdale2023"]
    info = hydro_of(m).bodies
    v = body(m, "bluerov2")
    assert m.body_mass[v] == H_MASS
    assert info[v].volume * RHO == pytest.approx(H_BUOY_KG, abs=1e-12)
    np.testing.assert_allclose(info[v].cob, [0.0074, 0, 0.02])
    np.testing.assert_allclose(m.body_pos[body(m, "alpha_mount")], [0.25, -0.10965, 0.005])
    np.testing.assert_allclose(m.body_quat[body(m, "alpha_mount")], [1, 0, 0, 0])
    extras = {"hinsdale_weight_ca": ((-0.2, 0.165, -0.075), 3.24), "hinsdale_weight_bl": ((-0.0975, 0.1275, -0.1325), 1.62),
              "hinsdale_weight_br": ((-0.0975, -0.1275, -0.1325), 1.62), "hinsdale_dvl": ((-0.1887, 0.0439, -0.1095 + 0.05), 0.69),
              "hinsdale_dvl_bracket": ((-0.1887 + 0.0345, 0.0439, -0.1295 + 0.05), 1.01)}
    for name, (pos, w) in extras.items():
        b = body(m, name)
        np.testing.assert_allclose(m.body_pos[b], pos, atol=1e-12)
        assert m.body_mass[b] * G == pytest.approx(w, abs=5e-6) and b not in info
    for name, (y, buoy) in {"hinsdale_foam_l": (0.11, 8.46), "hinsdale_foam_r": (-0.11, 8.86)}.items():
        b = body(m, name)
        np.testing.assert_allclose(m.body_pos[b], [0, y, 0.027])
        assert RHO * info[b].volume * G == pytest.approx(buoy, abs=5e-6) and m.body_mass[b] == 0
    # Joint mapping: angle = recorded axis - offset (base e, shoulder d, elbow c, wrist b).
    off = m.numeric("hinsdale:joint_offsets").data
    np.testing.assert_allclose(off, [3.07, 0, 0, 2.879])
    axes = np.array([3.1009, 0.0782, 0.0274, 1.6101])  # baseline1 medians (e, d, c, b)
    np.testing.assert_allclose(m.key("baseline1").qpos[7:], axes - off, atol=1e-12)
    for j, q in zip(("alpha_base", "alpha_shoulder", "alpha_elbow", "alpha_wrist"), axes - off):
        lo, hi = m.joint(j).range
        assert lo <= q <= hi


# ---------------------------------------------------------------- step responses against Fossen


def skew(a):
    return np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])


def quat_to_mat(q):
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def fossen_rhs(u_cmd):
    """Fossen's 6-DOF model of the von Benzon vehicle in FLU, origin at the CG, world z up:
    (M_RB + M_A) nu_dot + C_RB(nu) nu + C_A(nu) nu + D(nu) nu + g(eta) = B F(act),
    act_dot = (u - act) / tau; state (p_world, quat w x y z, nu, act)."""
    M_RB = np.diag(np.r_[np.full(3, VB_M), VB_I])
    M_A = np.diag(VB_MA)
    Minv = np.linalg.inv(M_RB + M_A)
    A11, A22 = M_A[:3, :3], M_A[3:, 3:]
    Ib = np.diag(VB_I)
    W, Bf = VB_M * G, RHO * VB_V * G
    r_b = T_FSD_FLU @ [0, 0, VB_ZB_FSD]
    Balloc = allocation_hand()
    u_cmd = np.asarray(u_cmd, float)

    def rhs(_t, x):
        p, q, nu, act = x[:3], x[3:7], x[7:13], x[13:]
        v, w = nu[:3], nu[3:]
        R = quat_to_mat(q)
        C_RB = np.block([[VB_M * skew(w), np.zeros((3, 3))], [np.zeros((3, 3)), -skew(Ib @ w)]])
        C_A = np.block([[np.zeros((3, 3)), -skew(A11 @ v)], [-skew(A11 @ v), -skew(A22 @ w)]])
        D = np.diag(VB_DL + VB_DQ * np.abs(nu))
        f_g, f_b = R.T @ [0, 0, -W], R.T @ [0, 0, Bf]
        g_eta = -np.r_[f_g + f_b, np.cross(r_b, f_b)]
        tau = Balloc @ t200(act)
        nu_dot = Minv @ (tau - C_RB @ nu - C_A @ nu - D @ nu - g_eta)
        qw, qv = q[0], q[1:]
        q_dot = 0.5 * np.r_[-qv @ w, qw * w + np.cross(qv, w)]
        return np.r_[R @ v, q_dot, nu_dot, (u_cmd - act) / TAU_THRUSTER]

    return rhs


# Surge at 0.15: the horizontal thrusters sit 8.5 cm below the CG, and at 0.3 (18 N) their pitch
# moment exceeds the 1.3 N m of hydrostatic restoring: the vehicle flips and tumbles (chaotic,
# no longer a meaningful 1e-6 comparison).
CASES = {"surge": [0.15, 0.15, -0.15, -0.15, 0, 0, 0, 0],
         "heave": [0, 0, 0, 0, 0.3, 0.3, 0.3, 0.3],
         "yaw": [0.3, -0.3, -0.3, 0.3, 0, 0, 0, 0]}


@pytest.fixture(scope="module")
def vehicle():
    m = load_model(MODELS / "bluerov2_heavy" / "bluerov2_heavy.xml")
    m.opt.timestep = 0.001
    m.opt.integrator = mujoco.mjtIntegrator.mjINT_RK4
    return m


@pytest.mark.parametrize("case", CASES)
def test_step_response_matches_fossen(case, vehicle):
    m, u = vehicle, np.array(CASES[case])
    # The commands give the intended wrench (hand allocation): the main axis dominates.
    wrench = allocation_hand() @ t200(u)
    main = {"surge": 0, "heave": 2, "yaw": 5}[case]
    assert abs(wrench[main]) > 10 * max(abs(wrench[i]) for i in (0, 1, 2, 5) if i != main)
    d = mujoco.MjData(m)
    d.ctrl[:] = u
    t_end, every = 10.0, 100
    steps = int(round(t_end / m.opt.timestep))
    ts, sim = [], []
    for k in range(1, steps + 1):
        mujoco.mj_step(m, d)
        if k % every == 0:
            R = d.xmat[body(m, "bluerov2")].reshape(3, 3)
            ts.append(d.time)
            sim.append(np.r_[d.qpos[:3], d.qpos[3:7], R.T @ d.qvel[:3], d.qvel[3:6]])
    sim = np.array(sim)
    x0 = np.r_[np.zeros(3), 1, 0, 0, 0, np.zeros(6), np.zeros(8)]
    # max_step: in the steady spin of the yaw case DOP853's error control lets steps grow until
    # r is off by 4e-6 while claiming 1e-10; 10 ms steps keep the reference at ~1e-10.
    sol = solve_ivp(fossen_rhs(u), (0, t_end), x0, method="DOP853", t_eval=np.minimum(ts, t_end),
                    rtol=1e-10, atol=1e-10, max_step=0.01)
    ref = sol.y[:13].T
    ref[:, 3:7] *= np.sign(ref[:, 3:4] * sim[:, 3:4] + 1e-300)
    err = np.abs(sim - ref).max()
    print(f"{case}: max |MuJoCo - Fossen| over 10 s = {err:.2e}")
    assert err < 1e-6, f"{case}: max |MuJoCo - Fossen| = {err:.2e}"
    # The response is non-trivial: it moved along/about its axis.
    moved = {"surge": sim[-1, 0], "heave": sim[-1, 2], "yaw": np.abs(sim[:, 12]).max()}[case]
    assert abs(moved) > 0.05
