"""The C engine plugins uvms.water / uvms.hydro (src/uvms_mj/physics/plugin/water.c) in plain MuJoCo.

Built and registered by uvms_mj.physics.build; every check here uses only MuJoCo's own API
(MjModel.from_xml_string, mj_step, mj_forward, mj_inverse, mj_forwardSkip, rollout) and
independent truths (closed forms, mj_jac/mj_applyFT, quadrature, energy conservation).
Skipped where the library cannot be built (no C compiler).
"""

from __future__ import annotations

import ctypes
import json
import math
import os
import subprocess
import sys
import textwrap

import mujoco
import numpy as np
import pytest

from uvms_mj.physics import build

pytestmark = pytest.mark.skipif(
    os.environ.get("UVMS_MJ_COMPILED", "").strip().lower() == "off" or not build.register_plugins(),
    reason=f"uvms plugins unavailable: {build.unavailable_reason()}",
)

INTEGRATORS = ("Euler", "RK4", "implicitfast", "implicit")
RHO = 1000.0


def water(**cfg: str) -> str:
    items = "".join(f'<config key="{k}" value="{v}"/>' for k, v in cfg.items())
    return (f'<extension><plugin plugin="uvms.water"><instance name="water">{items}</instance></plugin>'
            f'<plugin plugin="uvms.hydro"/></extension>')


def hydro(**cfg: str) -> str:
    items = "".join(f'<config key="{k}" value="{v}"/>' for k, v in cfg.items())
    return f'<plugin plugin="uvms.hydro">{items}</plugin>'


def free_body_xml(integrator="Euler", wcfg=None, hcfg=None, euler="0.3 0.7 -0.4", gravity="0 0 -9.81",
                  ballast=True) -> str:
    """A box on a free joint, rotated; a welded ballast child keeps its mass matrix dense."""
    child = '<body name="ballast"><geom type="sphere" size="0.01" mass="0.001"/></body>' if ballast else ""
    return f"""<mujoco><option integrator="{integrator}" timestep="0.002" gravity="{gravity}"/>
    {water(**(wcfg or {}))}
    <worldbody><body name="hull" pos="0.1 -0.2 0.3" euler="{euler}"><freejoint/>
      <geom type="box" size="0.2 0.1 0.1" mass="8"/>
      {hydro(**(hcfg or {}))}{child}
    </body></worldbody></mujoco>"""


ARM_XML = """<mujoco><option integrator="{integrator}" timestep="0.002" gravity="0 0 -9.81"/>
{water}
<worldbody><body name="base" pos="0 0 1"><freejoint/><geom type="box" size="0.3 0.2 0.1" mass="20"/>{h0}
  <body name="l1" pos="0.3 0 0"><joint type="hinge" axis="0 0 1"/>
    <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.04" mass="2"/>{h1}
    <body name="l2" pos="0.3 0 0"><joint type="hinge" axis="0 1 0"/>
      <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.04" mass="2"/>{h2}
      <body name="l3" pos="0.3 0 0"><joint type="hinge" axis="1 0 0" limited="true" range="-0.5 0.5"/>
        <geom type="capsule" fromto="0 0 0 0.2 0 0" size="0.03" mass="1"/>{h3}
      </body></body></body></body></worldbody></mujoco>"""


def arm_xml(integrator="Euler", wcfg=None, am=("5 10 10 0.1 0.2 0.2", "0.5 2 2 0.01 0.02 0.02",
                                               "0.5 2 2 0.01 0.02 0.02", "0.3 1 1 0.003 0.003 0.003"),
            extra=None) -> str:
    extra = extra or {}
    hs = []
    for i, a in enumerate(am):
        cfg = {"added_mass": a, **extra} if a is not None else dict(extra)
        hs.append(hydro(**cfg) if cfg else "")
    return ARM_XML.format(integrator=integrator, water=water(**(wcfg or {})), h0=hs[0], h1=hs[1], h2=hs[2],
                          h3=hs[3])


def full_terms_arm(integrator="Euler", wcfg=None) -> str:
    extra = {"linear_damping": "1 1 1 0.01 0.01 0.01", "quadratic_damping": "5 5 5 0.01 0.01 0.01",
             "strips": "x 0 0.3 0.08 0.08; y -0.05 0.05 0.1 0", "volume": "0.003", "cob": "0.1 0 0.01"}
    return arm_xml(integrator, wcfg, extra=extra)


def M_full(m: mujoco.MjModel, d: mujoco.MjData) -> np.ndarray:
    out = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, out, d.qM) if hasattr(d, "qM") else mujoco.mj_fullM(m, d, out)
    return out


def bare_M(xml: str, qpos: np.ndarray) -> np.ndarray:
    """The mass matrix of the same model with water terms off (M without added mass)."""
    m = mujoco.MjModel.from_xml_string(xml.replace("<instance name=\"water\">",
                                                   '<instance name="water"><config key="terms" value="damping"/>'))
    d = mujoco.MjData(m)
    d.qpos[:] = qpos
    mujoco.mj_forward(m, d)
    return M_full(m, d)


# --------------------------------------------------------------------------- build and load


def test_library_builds_and_registers_idempotently():
    path = build.library_path()
    assert path.is_file() and path.name.startswith("uvms_plugins-")
    assert build.register_plugins() is True
    assert build.register_plugins() is True  # once per process, cached
    assert build.unavailable_reason() is None
    m = mujoco.MjModel.from_xml_string(free_body_xml())
    assert m.nplugin == 2  # uvms.water + the hull's uvms.hydro
    assert m.npluginstate == 9


def test_plugin_off_and_no_compiler_fallback_in_subprocess(tmp_path):
    code = textwrap.dedent("""
        import json, os
        from uvms_mj.physics import build
        ok = build.register_plugins()
        out = {"ok": ok, "reason": build.unavailable_reason()}
        os.environ.pop("UVMS_MJ_COMPILED")
        os.environ["CC"] = "/nonexistent/cc"
        os.environ["UVMS_MJ_CACHE"] = os.environ["EMPTY_CACHE"]
        try:
            build.library_path()
        except build.PluginUnavailableError as exc:
            out["cc_error"] = str(exc)
        print(json.dumps(out))
    """)
    env = dict(os.environ, UVMS_MJ_COMPILED="off", EMPTY_CACHE=str(tmp_path))
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout.strip().splitlines()[-1])
    assert out["ok"] is False and "UVMS_MJ_COMPILED=off" in out["reason"]
    assert "/nonexistent/cc" in out["cc_error"] and "\n" not in out["cc_error"]


def test_parallel_builds_into_a_fresh_cache_are_safe(tmp_path):
    """Several processes building at once into an empty cache all get the same complete file."""
    code = "from uvms_mj.physics import build; print(build.library_path())"
    env = dict(os.environ, UVMS_MJ_CACHE=str(tmp_path))
    procs = [subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True, env=env) for _ in range(3)]
    outs = [p.communicate(timeout=300) for p in procs]
    assert all(p.returncode == 0 for p in procs), [o[1] for o in outs]
    paths = {o[0].strip() for o in outs}
    assert len(paths) == 1
    assert [f.name for f in tmp_path.iterdir()] == [os.path.basename(paths.pop())]  # no temporaries left
    check = ("import mujoco, sys; mujoco.mj_loadPluginLibrary(sys.argv[1]); "
             "mujoco.MjModel.from_xml_string(sys.argv[2])")
    lib = next(tmp_path.iterdir())
    res = subprocess.run([sys.executable, "-c", check, str(lib), free_body_xml()], capture_output=True, text=True,
                         timeout=120)
    assert res.returncode == 0, res.stderr


# --------------------------------------------------------------------------- physics sanity


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_force_along_body_axis_gives_F_over_m_plus_mA(integrator):
    """From rest, a force along each axis of a rotated free body (through its centre of mass,
    the default origin of h) accelerates it at exactly F/(m + m_A) along that axis."""
    am = (2.0, 8.0, 6.0)
    xml = free_body_xml(integrator, wcfg={"terms": "added_mass"},
                        hcfg={"added_mass": f"{am[0]} {am[1]} {am[2]} 0.02 0.05 0.07"}, gravity="0 0 0")
    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    R = d.xmat[1].reshape(3, 3).copy()
    mass = m.body_subtreemass[1]
    for axis in range(3):
        mujoco.mj_resetData(m, d)
        F = 3.0 * R[:, axis]
        d.xfrc_applied[1, :3] = F
        mujoco.mj_step(m, d)
        acc = d.qvel[:3] / m.opt.timestep
        np.testing.assert_allclose(acc, F / (mass + am[axis]), rtol=0, atol=1e-9)
        np.testing.assert_allclose(d.qvel[3:], 0.0, atol=1e-12)


def test_torque_about_body_axis_gives_T_over_I_plus_IA():
    I_A = (0.02, 0.05, 0.07)
    xml = free_body_xml("RK4", wcfg={"terms": "added_mass"},
                        hcfg={"added_mass": f"2 8 6 {I_A[0]} {I_A[1]} {I_A[2]}"}, gravity="0 0 0")
    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    R = d.xmat[1].reshape(3, 3).copy()
    # the box's principal inertia plus that of the ballast sphere at the same centre
    inertia = m.body_inertia[1] + 0.4 * 0.001 * 0.01 ** 2
    for axis in range(3):
        mujoco.mj_resetData(m, d)
        d.xfrc_applied[1, 3:] = 0.5 * R[:, axis]
        mujoco.mj_step(m, d)
        alpha = d.qvel[3:] / m.opt.timestep  # body-frame angular acceleration of the free joint
        expect = np.zeros(3)
        expect[axis] = 0.5 / (inertia[axis] + I_A[axis])
        np.testing.assert_allclose(alpha, expect, atol=1e-9 * abs(expect[axis]) + 1e-12)


def test_buoyancy_is_rho_V_g_at_the_centre_of_buoyancy():
    V, cob = 0.006, np.array([0.02, -0.01, 0.05])
    xml = free_body_xml(wcfg={"density": "1025"}, hcfg={"volume": str(V), "cob": " ".join(map(str, cob))})
    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    F = -1025.0 * V * m.opt.gravity
    point = d.xpos[1] + d.xmat[1].reshape(3, 3) @ cob
    expect = np.zeros(m.nv)
    mujoco.mj_applyFT(m, d, F, np.zeros(3), point, 1, expect)
    np.testing.assert_allclose(d.qfrc_passive, expect, rtol=0, atol=1e-12)
    # net: a neutrally buoyant body (rho V = m) at rest does not accelerate linearly
    mass = m.body_subtreemass[1]
    xml = free_body_xml(wcfg={"density": "1000"}, hcfg={"volume": repr(float(mass) / 1000.0)})
    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    np.testing.assert_allclose(d.qacc, 0.0, atol=1e-12)


def test_damping_and_strips_match_independent_formulas():
    """Linear/quadratic damping in frame h and strip drag against numerical quadrature."""
    quat = np.array([0.9, 0.1, -0.3, 0.2])
    quat /= np.linalg.norm(quat)
    pos = np.array([0.05, 0.01, -0.02])
    DL, DQ = np.array([1, 2, 3, 0.1, 0.2, 0.3]), np.array([4, 5, 6, 0.4, 0.5, 0.6])
    strips = [("x", -0.2, 0.25, 0.3, 0.1), ("z", -0.05, 0.1, 0.2, 0.05)]
    cur = np.array([0.2, -0.1, 0.05])
    xml = free_body_xml(
        wcfg={"current": " ".join(map(str, cur)), "terms": "damping strips"},
        hcfg={"pos": " ".join(map(str, pos)), "quat": " ".join(map(str, quat)),
              "linear_damping": " ".join(map(str, DL)), "quadratic_damping": " ".join(map(str, DQ)),
              "strips": "; ".join(" ".join(map(str, s)) for s in strips)})
    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    d.qvel[:] = [0.3, -0.2, 0.4, 1.1, -0.7, 0.5]
    mujoco.mj_forward(m, d)
    # independent evaluation
    Rh = np.zeros(9)
    mujoco.mju_quat2Mat(Rh, quat)
    R = d.xmat[1].reshape(3, 3) @ Rh.reshape(3, 3)
    p = d.xpos[1] + d.xmat[1].reshape(3, 3) @ pos
    jacp, jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
    mujoco.mj_jac(m, d, jacp, jacr, p, 1)
    v = R.T @ (jacp @ d.qvel - cur)
    w = R.T @ (jacr @ d.qvel)
    nu = np.r_[v, w]
    tau = -(DL + DQ * np.abs(nu)) * nu
    s_nodes, s_weights = np.polynomial.legendre.leggauss(400)
    for ax_name, s0, s1, c1, c2 in strips:
        ax = "xyz".index(ax_name)
        e = np.eye(3)[ax]
        others = [n for n in range(3) if n != ax]
        # split the quadrature at the sign changes for accuracy
        for n, cd in zip(others, (c1, c2)):
            wn0, om = v[n], np.cross(w, e)[n]
            cuts = [s0, s1]
            if om != 0 and s0 < -wn0 / om < s1:
                cuts = [s0, -wn0 / om, s1]
            for a, b in zip(cuts[:-1], cuts[1:]):
                s = 0.5 * (b - a) * s_nodes + 0.5 * (a + b)
                wt = 0.5 * (b - a) * s_weights
                wn = wn0 + om * s
                f = -0.5 * RHO * cd * np.abs(wn) * wn
                tau[n] += np.sum(wt * f)
                tau[3:] += np.cross(e, np.eye(3)[n]) * np.sum(wt * s * f)
    expect = np.zeros(m.nv)
    mujoco.mj_applyFT(m, d, R @ tau[:3], R @ tau[3:], p, 1, expect)
    np.testing.assert_allclose(d.qfrc_passive, expect, rtol=1e-10, atol=1e-12)


def _strip_lib():
    lib = ctypes.CDLL(str(build.library_path()))
    f = lib.uvms_water_strip_integrals
    f.argtypes = [ctypes.c_double] * 4 + [ctypes.POINTER(ctypes.c_double)] * 2
    f.restype = None
    return f


def test_strip_integrals_closed_form_against_quadrature():
    f = _strip_lib()
    rng = np.random.default_rng(3)
    for _ in range(200):
        w0, om = rng.normal(size=2)
        a, b = np.sort(rng.uniform(-1, 1, 2))
        if rng.random() < 0.2:
            om = 0.0
        i0, i1 = ctypes.c_double(), ctypes.c_double()
        f(w0, om, a, b, ctypes.byref(i0), ctypes.byref(i1))
        s = np.linspace(a, b, 200001)
        wv = w0 + om * s
        np.testing.assert_allclose(i0.value, np.trapezoid(np.abs(wv) * wv, s), atol=1e-8)
        np.testing.assert_allclose(i1.value, np.trapezoid(s * np.abs(wv) * wv, s), atol=1e-8)


def test_added_mass_matrix_is_J_T_MA_J_full_matrix():
    """d.M after mj_forward = bare M + sum_b J_b^T M_A J_b (Fossen's order, frame h), full M_A."""
    rng = np.random.default_rng(7)
    B = rng.normal(size=(6, 6))
    A = B @ B.T * 0.3
    quat = np.array([0.8, -0.2, 0.4, 0.1])
    quat /= np.linalg.norm(quat)
    pos = np.array([0.1, -0.02, 0.03])
    hc = {"added_mass": " ".join(repr(float(x)) for x in A.ravel()), "pos": " ".join(map(str, pos)),
          "quat": " ".join(map(str, quat))}
    xml = ARM_XML.format(integrator="Euler", water=water(), h0=hydro(**hc), h1="", h2=hydro(**hc), h3="")
    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    d.qpos[:] = m.qpos0
    d.qpos[3:7] = [0.9, 0.2, -0.3, 0.1]
    d.qpos[3:7] /= np.linalg.norm(d.qpos[3:7])
    d.qpos[7:] = [0.4, -0.6, 0.3]
    mujoco.mj_forward(m, d)
    expect = bare_M(xml, d.qpos.copy())
    Rh = np.zeros(9)
    mujoco.mju_quat2Mat(Rh, quat)
    for b in (1, 3):
        R = d.xmat[b].reshape(3, 3) @ Rh.reshape(3, 3)
        p = d.xpos[b] + d.xmat[b].reshape(3, 3) @ pos
        jacp, jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
        mujoco.mj_jac(m, d, jacp, jacr, p, b)
        J = np.r_[R.T @ jacp, R.T @ jacr]
        expect += J.T @ A @ J
    np.testing.assert_allclose(M_full(m, d), expect, rtol=0, atol=1e-12 * np.abs(expect).max())


def test_added_mass_velocity_terms_match_the_formula_with_mj_jacDot():
    """tau_A = [h_v x w; h_v x v_r + h_w x w] - M_A a (+ M_A [R^T a_c; 0]), h = M_A nu_r,
    a = [R^T Jp_dot qd - w x v_r; R^T Jr_dot qd], evaluated here with mj_jac/mj_jacDot and
    mj_applyFT, for a moving arm with a current (full M_A, rotated and offset frame h)."""
    rng = np.random.default_rng(2)
    B = rng.normal(size=(6, 6))
    A = B @ B.T * 0.2
    quat = np.array([0.7, 0.3, -0.2, 0.4])
    quat /= np.linalg.norm(quat)
    pos = np.array([0.12, 0.03, -0.02])
    cur = np.array([0.3, -0.2, 0.1])
    hc = {"added_mass": " ".join(repr(float(x)) for x in A.ravel()), "pos": " ".join(map(str, pos)),
          "quat": " ".join(map(str, quat))}
    xml = ARM_XML.format(integrator="Euler", water=water(current=" ".join(map(str, cur))),
                         h0=hydro(**hc), h1=hydro(**hc), h2="", h3=hydro(**hc))
    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    d.qpos[3:7] = [0.9, -0.2, 0.3, 0.1]
    d.qpos[3:7] /= np.linalg.norm(d.qpos[3:7])
    d.qpos[7:] = [0.5, -0.4, 0.3]
    d.qvel[:] = rng.normal(size=m.nv)
    mujoco.mj_forward(m, d)
    Rh = np.zeros(9)
    mujoco.mju_quat2Mat(Rh, quat)
    expect = np.zeros(m.nv)
    for b in (1, 2, 4):
        R = d.xmat[b].reshape(3, 3) @ Rh.reshape(3, 3)
        p = d.xpos[b] + d.xmat[b].reshape(3, 3) @ pos
        jp, jr, jdp, jdr = (np.zeros((3, m.nv)) for _ in range(4))
        mujoco.mj_jac(m, d, jp, jr, p, b)
        mujoco.mj_jacDot(m, d, jdp, jdr, p, b)
        vr = R.T @ (jp @ d.qvel - cur)
        w = R.T @ (jr @ d.qvel)
        h = A @ np.r_[vr, w]
        a = np.r_[R.T @ (jdp @ d.qvel) - np.cross(w, vr), R.T @ (jdr @ d.qvel)]
        tau = np.r_[np.cross(h[:3], w), np.cross(h[:3], vr) + np.cross(h[3:], w)] - A @ a
        mujoco.mj_applyFT(m, d, R @ tau[:3], R @ tau[3:], p, b, expect)
    np.testing.assert_allclose(d.qfrc_passive, expect, rtol=0, atol=1e-11 * np.abs(expect).max())


def test_inverse_dynamics_matches_forward():
    """mj_inverse with the qacc of mj_forward returns the applied forces (all terms on)."""
    for integrator in ("Euler", "RK4"):
        m = mujoco.MjModel.from_xml_string(full_terms_arm(integrator, {"current": "0.2 -0.1 0.05"}))
        d = mujoco.MjData(m)
        rng = np.random.default_rng(1)
        d.qvel[:] = rng.normal(size=m.nv) * 0.5
        d.qfrc_applied[:] = rng.normal(size=m.nv)
        for _ in range(20):
            mujoco.mj_step(m, d)
        mujoco.mj_forward(m, d)
        qacc = d.qacc.copy()
        mujoco.mj_inverse(m, d)
        np.testing.assert_allclose(d.qacc, qacc)
        np.testing.assert_allclose(d.qfrc_inverse, d.qfrc_applied, rtol=0, atol=1e-9)


def test_added_mass_energy_is_conserved_in_drag_free_coasting():
    """Kirchhoff velocity terms + J_dot term + M augmentation: with only added mass (no drag,
    no gravity) the kinetic energy 1/2 qvel^T M_aug qvel is conserved up to the integrator's own
    error, which converges (a wrong or missing J_dot term drifts by percents, not converging).
    MuJoCo's RK4 on this free-floating arm is second order in energy even without water."""
    drift = []
    for h in (0.002, 0.001):
        xml = arm_xml("RK4", {"terms": "added_mass"}).replace('gravity="0 0 -9.81"', 'gravity="0 0 0"')
        xml = xml.replace(' limited="true" range="-0.5 0.5"', "").replace('timestep="0.002"', f'timestep="{h}"')
        m = mujoco.MjModel.from_xml_string(xml)
        d = mujoco.MjData(m)
        d.qvel[:] = [0.3, -0.2, 0.1, 0.5, -0.4, 0.3, 1.0, -0.8, 1.2]

        def energy():
            mujoco.mj_forward(m, d)
            out = np.zeros(m.nv)
            mujoco.mj_mulM(m, d, out, d.qvel)
            return 0.5 * d.qvel @ out

        e0 = energy()
        for _ in range(round(1.0 / h)):  # 1 s
            mujoco.mj_step(m, d)
        drift.append(abs(energy() - e0) / e0)
    assert drift[0] < 5e-7
    assert drift[1] < drift[0] / 3.5  # converges (order 2)


LIMIT_XML = """<mujoco><option integrator="{integrator}" solver="{solver}" timestep="0.002" gravity="0 0 0"/>
{water}
<worldbody><body name="base"><joint name="slide" type="slide" axis="1 0 0" limited="true" range="-0.05 0.05"/>
  <joint type="hinge" axis="0 0 1"/>
  <inertial pos="0.05 0.02 0" mass="{m0}" diaginertia="{i0} {i0} {i0}"/>{h0}
  <body name="link" pos="0.3 0 0"><joint name="elbow" type="hinge" axis="0 1 0" limited="true" range="-0.3 0.3"/>
    <inertial pos="0.15 0 0.01" mass="{m1}" diaginertia="{i1} {i1} {i1}"/>{h1}
    <geom type="sphere" size="0.05" pos="0.3 0 0" contype="0" conaffinity="0"/>
  </body></body></worldbody>
<actuator><motor joint="slide" gear="1"/><motor joint="elbow" gear="1"/></actuator></mujoco>"""


@pytest.mark.parametrize("solver", ["Newton", "PGS", "CG"])
@pytest.mark.parametrize("integrator", ["Euler", "RK4", "implicitfast"])
def test_isotropic_added_mass_equals_extra_rigid_mass_with_joint_limits(integrator, solver):
    """Isotropic added mass (m_A, I_A at the centre of mass) is exactly extra rigid mass: the
    trajectory, pushed hard into joint limits (constraint rows: mj_projectConstraint after the
    refactorisation), matches the rigid model with mass m + m_A and inertia I + I_A."""
    (ma0, ia0), (ma1, ia1) = (3.0, 0.02), (1.5, 0.01)  # base, link: added mass and inertia
    w = water(terms="added_mass")
    h0 = hydro(added_mass=f"{ma0} {ma0} {ma0} {ia0} {ia0} {ia0}")
    h1 = hydro(added_mass=f"{ma1} {ma1} {ma1} {ia1} {ia1} {ia1}")
    water_xml = LIMIT_XML.format(integrator=integrator, solver=solver, water=w, h0=h0, h1=h1,
                                 m0=5, i0=0.1, m1=1, i1=0.02)
    rigid_xml = LIMIT_XML.format(integrator=integrator, solver=solver, water="", h0="", h1="",
                                 m0=5 + ma0, i0=0.1 + ia0, m1=1 + ma1, i1=0.02 + ia1)
    runs, limits = [], 0
    rigid = mujoco.MjModel.from_xml_string(rigid_xml)
    for xml in (water_xml, rigid_xml):
        m = mujoco.MjModel.from_xml_string(xml)
        # constraint softness scales with the compile-time inverse weights, which know nothing
        # of the added mass: use the rigid model's so that both solve the same constraint
        m.dof_invweight0[:] = rigid.dof_invweight0
        m.body_invweight0[:] = rigid.body_invweight0
        d = mujoco.MjData(m)
        d.qvel[:] = [0.2, 1.0, -0.5]
        traj = []
        for i in range(400):
            d.ctrl[:] = [20.0 * math.sin(0.02 * i), 5.0 * math.cos(0.03 * i)]
            mujoco.mj_step(m, d)
            traj.append(np.r_[d.qpos, d.qvel])
            limits += d.nefc
        runs.append(np.array(traj))
    assert limits > 100  # the limits were active during many steps
    np.testing.assert_allclose(runs[0], runs[1], rtol=0, atol=1e-9)


# --------------------------------------------------------------------------- guard


GUARD_CASES = {
    "zero": None,
    "diagonal": "5 10 10 0.1 0.2 0.2",
    "one_entry": "0 0 0 0 0 0.3",
    "upper21": "3 0 0 0 0.2 0  4 0 0 0 0  5 0 0 0  0.1 0 0  0.2 0  0.3",
    "full36": None,  # filled below
}


def _full36():
    rng = np.random.default_rng(11)
    B = rng.normal(size=(6, 3))
    return " ".join(repr(float(x)) for x in (B @ B.T).ravel())  # PSD of rank 3 (singular)


@pytest.mark.parametrize("case", list(GUARD_CASES))
def test_guard_forward_skip_leaves_M_identical(case):
    am = _full36() if case == "full36" else GUARD_CASES[case]
    xml = arm_xml("Euler", am=(am, None, am, am))
    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    d.qpos[7:] = [0.3, -0.5, 0.2]
    d.qvel[:] = np.linspace(-0.5, 0.6, m.nv)
    mujoco.mj_forward(m, d)
    M1, L1, qacc1 = d.M.copy(), d.qLD.copy(), d.qacc.copy()
    for stage in (mujoco.mjtStage.mjSTAGE_POS, mujoco.mjtStage.mjSTAGE_VEL, mujoco.mjtStage.mjSTAGE_POS):
        mujoco.mj_forwardSkip(m, d, stage, 0)
        np.testing.assert_array_equal(d.M, M1)
        np.testing.assert_array_equal(d.qLD, L1)
        np.testing.assert_array_equal(d.qacc, qacc1)
    mujoco.mj_forward(m, d)  # recomputed from scratch: the same, not added twice
    np.testing.assert_array_equal(d.M, M1)
    np.testing.assert_array_equal(d.qacc, qacc1)
    if am is not None:  # and the added mass is in it
        assert np.abs(M_full(m, d) - bare_M(xml, d.qpos.copy())).max() > 1e-3


def test_finite_difference_derivatives_leave_the_mass_matrix_intact():
    """mjd_transitionFD (mj_forwardSkip inside) with added mass: finite results, d.M restored,
    and the velocity block matches a direct central difference of mj_step."""
    m = mujoco.MjModel.from_xml_string(arm_xml("Euler"))
    d = mujoco.MjData(m)
    d.qvel[:] = 0.2
    mujoco.mj_forward(m, d)
    M_before = d.M.copy()
    nx = 2 * m.nv + m.na
    A = np.zeros((nx, nx))
    mujoco.mjd_transitionFD(m, d, 1e-6, 1, A, None, None, None)
    assert np.all(np.isfinite(A))
    mujoco.mj_forward(m, d)
    np.testing.assert_array_equal(d.M, M_before)
    # column of d(qvel_next)/d(qvel_0) by a direct central difference
    eps, j = 1e-6, 7
    outs = []
    for sgn in (1, -1):
        d2 = mujoco.MjData(m)
        d2.qpos[:], d2.qvel[:] = d.qpos, d.qvel
        d2.qvel[j] += sgn * eps
        mujoco.mj_step(m, d2)
        outs.append(d2.qvel.copy())
    col = (outs[0] - outs[1]) / (2 * eps)
    np.testing.assert_allclose(A[m.nv:2 * m.nv, m.nv + j], col, atol=1e-6)


def test_copy_data_keeps_the_guard_and_the_trajectory():
    import copy

    m = mujoco.MjModel.from_xml_string(full_terms_arm("RK4", {"current_model": "gauss_markov",
                                                             "gm_sigma": "0.1 0.1 0.1", "gm_tau": "1 1 1"}))
    d = mujoco.MjData(m)
    d.qvel[:] = 0.3
    for _ in range(10):
        mujoco.mj_step(m, d)
    d2 = copy.copy(d)
    for _ in range(50):
        mujoco.mj_step(m, d)
        mujoco.mj_step(m, d2)
    np.testing.assert_array_equal(d.qpos, d2.qpos)
    np.testing.assert_array_equal(d.plugin_state, d2.plugin_state)


# --------------------------------------------------------------------------- current, state, threads


def _splitmix64(z: int) -> int:
    mask = (1 << 64) - 1
    z = (z + 0x9E3779B97F4A7C15) & mask
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & mask
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & mask
    return z ^ (z >> 31)


def _normal(seed: int, k: int, c: int) -> float:
    a = _splitmix64(seed ^ _splitmix64(6 * k + 2 * c))
    b = _splitmix64(seed ^ _splitmix64(6 * k + 2 * c + 1))
    u1 = ((a >> 11) + 1) * 2.0 ** -53
    u2 = (b >> 11) * 2.0 ** -53
    return math.sqrt(-2.0 * math.log(u1)) * math.cos(2.0 * math.pi * u2)


GM = {"current_model": "gauss_markov", "current": "0.2 0 -0.05", "gm_mean": "0.3 0.1 0",
      "gm_sigma": "0.05 0.1 0.02", "gm_tau": "0.5 2 5", "gm_min": "-1 -0.15 -1", "gm_max": "1 1 1",
      "gm_seed": "42"}


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_gauss_markov_state_is_advanced_once_per_step_bit_for_bit(integrator):
    """plugin advance runs once per mj_step with every integrator (RK4 included), and the
    samples follow the documented counter-based recurrence exactly."""
    m = mujoco.MjModel.from_xml_string(free_body_xml(integrator, wcfg=GM, hcfg={"volume": "0.008"}))
    d = mujoco.MjData(m)
    h = m.opt.timestep
    mu, sig, tau = np.array([0.3, 0.1, 0]), np.array([0.05, 0.1, 0.02]), np.array([0.5, 2, 5])
    lo, hi = np.array([-1, -0.15, -1]), np.array([1, 1, 1])

    def draw(v, k):
        out = []
        for c in range(3):
            e1 = math.exp((-h) / tau[c])
            e2 = math.exp((-2.0 * h) / tau[c])
            x = mu[c] + (v[c] - mu[c]) * e1 + sig[c] * math.sqrt(1.0 - e2) * _normal(42, k, c)
            out.append(min(max(x, lo[c]), hi[c]))
        return out

    v = [0.2, 0.0, -0.05]
    vn = draw(v, 0)
    s = d.plugin_state
    assert list(s[2:5]) == v and list(s[5:8]) == vn and s[1] == 0 and s[8] == h
    for k in range(1, 301):
        mujoco.mj_step(m, d)
        v, vn = vn, draw(vn, k)
        assert s[1] == k and s[0] == d.time
        assert list(s[2:5]) == v and list(s[5:8]) == vn
    lib = ctypes.CDLL(str(build.library_path()))
    lib.uvms_water_gm_normal.argtypes = [ctypes.c_uint64, ctypes.c_uint64, ctypes.c_int]
    lib.uvms_water_gm_normal.restype = ctypes.c_double
    for k, c in [(0, 0), (5, 2), (2 ** 40, 1)]:
        assert lib.uvms_water_gm_normal(42, k, c) == _normal(42, k, c)


def test_gauss_markov_deterministic_per_seed():
    def run(seed):
        m = mujoco.MjModel.from_xml_string(full_terms_arm("Euler", {**GM, "gm_seed": str(seed)}))
        d = mujoco.MjData(m)
        for _ in range(200):
            mujoco.mj_step(m, d)
        return d.qpos.copy(), d.plugin_state.copy()

    a, b, c = run(1), run(1), run(2)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])
    assert not np.array_equal(a[1], c[1]) and not np.array_equal(a[0], c[0])


def test_froude_krylov_and_current_acceleration():
    """sigma = 0: the current relaxes to its mean deterministically; a neutral body (rho V = m,
    no added mass) then feels rho V a_c: it accelerates with the water, a = a_c."""
    m0 = mujoco.MjModel.from_xml_string(free_body_xml())
    mass = m0.body_subtreemass[1]
    cfg = {"current_model": "gauss_markov", "current": "0 0 0", "gm_mean": "1 0 0", "gm_tau": "0.5 1 1",
           "terms": "buoyancy froude_krylov"}
    m = mujoco.MjModel.from_xml_string(free_body_xml("RK4", wcfg=cfg, hcfg={"volume": repr(float(mass) / RHO)}))
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    s = d.plugin_state
    a_c = (s[5:8] - s[2:5]) / s[8]
    np.testing.assert_allclose(d.qacc[:3], a_c, rtol=1e-9, atol=1e-12)


def test_profile_current_depends_on_depth():
    cfg = {"current_model": "profile", "profile": "-10 0 0 0; 0 1 0 0", "terms": "damping"}
    out = []
    for z in (-20.0, -5.0, 3.0):
        xml = free_body_xml(wcfg=cfg, hcfg={"linear_damping": "2 2 2 0 0 0"}, euler="0 0 0", gravity="0 0 0")
        xml = xml.replace('pos="0.1 -0.2 0.3"', f'pos="0 0 {z}"')
        m = mujoco.MjModel.from_xml_string(xml)
        d = mujoco.MjData(m)
        mujoco.mj_forward(m, d)
        out.append(d.qfrc_passive[0])
    np.testing.assert_allclose(out, [0.0, 2 * 0.5, 2 * 1.0], atol=1e-12)


def test_rollout_one_and_two_threads_bit_identical():
    from mujoco import rollout

    m = mujoco.MjModel.from_xml_string(full_terms_arm("RK4", GM))
    d = mujoco.MjData(m)
    nstate = mujoco.mj_stateSize(m, mujoco.mjtState.mjSTATE_FULLPHYSICS)
    rng = np.random.default_rng(5)
    init = np.zeros((6, nstate))
    for i in range(6):
        mujoco.mj_resetData(m, d)
        d.qvel[:] = rng.normal(size=m.nv) * 0.3
        mujoco.mj_getState(m, d, init[i], mujoco.mjtState.mjSTATE_FULLPHYSICS)
    s1, _ = rollout.rollout(m, [mujoco.MjData(m)], init, nstep=200)
    s2, _ = rollout.rollout(m, [mujoco.MjData(m), mujoco.MjData(m)], init, nstep=200)
    # exact: threads split the trajectories, not the arithmetic of one (the same compiled mj_step,
    # no CPU-dependent dispatch in MuJoCo or the plugins, built with -ffp-contract=off)
    np.testing.assert_array_equal(s1, s2)
    # and a plain serial loop gives the same
    mujoco.mj_setState(m, d, init[3], mujoco.mjtState.mjSTATE_FULLPHYSICS)
    for _ in range(200):
        mujoco.mj_step(m, d)
    last = np.zeros(nstate)
    mujoco.mj_getState(m, d, last, mujoco.mjtState.mjSTATE_FULLPHYSICS)
    np.testing.assert_array_equal(s1[3, -1], last)


# --------------------------------------------------------------------------- bad parameters

BAD = [
    # (name, water config, hull config, ballast, substrings expected in the message)
    ("count", {}, {"added_mass": "1 2 3"}, True,
     ["uvms.hydro: body 'hull'", "added_mass", '"1 2 3"', "expected 6, 21 or 36"]),
    ("nonsymmetric", {}, {"added_mass": " ".join(["1" if i == 1 else ("2" if i % 7 == 0 else "0")
                                                   for i in range(36)])}, True,
     ["body 'hull'", "added_mass", "not symmetric", "symmetric positive semi-definite"]),
    ("non_psd", {}, {"added_mass": "-1 1 1 1 1 1"}, True,
     ["body 'hull'", "added_mass", '"-1 1 1 1 1 1"', "not positive semi-definite"]),
    ("non_psd21", {}, {"added_mass": "1 5 0 0 0 0 1 0 0 0 0 1 0 0 0 1 0 0 1 0 1"}, True,
     ["added_mass", "not positive semi-definite"]),
    ("nan", {}, {"linear_damping": "nan 0 0 0 0 0"}, True,
     ["body 'hull'", "linear_damping", '"nan 0 0 0 0 0"', "not finite"]),
    ("negative_damping", {}, {"quadratic_damping": "1 1 -1 1 1 1"}, True,
     ["quadratic_damping", "(-1)", ">= 0"]),
    ("damping_count", {}, {"quadratic_damping": "1 2"}, True,
     ["quadratic_damping", '"1 2"', "got 2 numbers; expected 6"]),
    ("negative_volume", {}, {"volume": "-0.1"}, True, ["body 'hull'", "volume", '"-0.1"', ">= 0"]),
    ("not_a_number", {}, {"cob": "0 0 up"}, True, ["cob", '"0 0 up"', "not a number", "3 numbers"]),
    ("unknown_attribute", {}, {"colour": "red"}, True, ["colour", "uvms.hydro"]),
    ("strip_order", {}, {"strips": "x 0 0.3 1 1; y 0.5 0.1 1 1"}, True,
     ["body 'hull'", "strips", "strip 2", "s0 (0.5) must be < s1 (0.1)"]),
    ("strip_axis", {}, {"strips": "w 0 1 1 1"}, True, ["strips", "axis 'w' unknown", "x, y or z"]),
    ("strip_count", {}, {"strips": "x 0 1 1"}, True, ["strips", "strip 1 has 3 numbers", "expected 4"]),
    ("strip_cd", {}, {"strips": "z 0 1 -1 1"}, True, ["strips", "must be >= 0"]),
    ("current_model", {"current_model": "tidal"}, {}, True,
     ["uvms.water", "current_model", '"tidal"', "constant, gauss_markov, profile"]),
    ("density", {"density": "0"}, {}, True, ["uvms.water", "density", '"0"', "> 0"]),
    ("gm_tau", {"gm_tau": "1 0 1"}, {}, True, ["gm_tau", "> 0"]),
    ("gm_sigma", {"gm_sigma": "1 -1 1"}, {}, True, ["gm_sigma", ">= 0"]),
    ("gm_bounds", {"gm_min": "0 0 2", "gm_max": "1 1 1"}, {}, True, ["gm_min", "gm_max"]),
    ("gm_seed", {"gm_seed": "-3"}, {}, True, ["gm_seed", '"-3"', "integer >= 0"]),
    ("profile_order", {"current_model": "profile", "profile": "0 1 0 0; -5 0 0 0"}, {}, True,
     ["profile", "knot 2", "strictly increasing"]),
    ("profile_missing", {"current_model": "profile"}, {}, True, ["profile", "knots"]),
    ("terms", {"terms": "added_mass drag"}, {}, True, ["terms", "'drag'", "froude_krylov"]),
    ("terms_none_mixed", {"terms": "none damping"}, {}, True, ["terms", "'none'", "none alone"]),
    ("simple_body", {}, {"added_mass": "1 1 1 0.1 0.1 0.1"}, False,
     ["body 'hull'", "simple", "weld a child body"]),
]


def test_bad_parameters_raise_clear_python_errors_in_subprocess():
    cases = [(name, free_body_xml(wcfg=w, hcfg=h, ballast=ballast)) for name, w, h, ballast, _ in BAD]
    no_water = free_body_xml(hcfg={"volume": "0.01"}).replace(
        '<plugin plugin="uvms.water"><instance name="water"></instance></plugin>', "")
    two_water = free_body_xml().replace(
        '<instance name="water"></instance>', '<instance name="water"></instance><instance name="w2"/>')
    cases += [("no_water", no_water), ("two_water", two_water)]
    code = textwrap.dedent("""
        import json, sys, mujoco
        from uvms_mj.physics import build
        assert build.register_plugins()
        out = {}
        for name, xml in json.loads(sys.stdin.read()):
            try:
                m = mujoco.MjModel.from_xml_string(xml)
                mujoco.MjData(m)
                out[name] = ["no error", ""]
            except Exception as exc:
                out[name] = [type(exc).__name__, str(exc)]
        print(json.dumps(out))
    """)
    res = subprocess.run([sys.executable, "-c", code], input=json.dumps(cases), capture_output=True,
                         text=True, timeout=300)
    assert res.returncode == 0, f"the process crashed (rc {res.returncode}): {res.stderr[-2000:]}"
    out = json.loads(res.stdout.strip().splitlines()[-1])
    expected = {name: subs for name, _, _, _, subs in BAD}
    expected["no_water"] = ["body 'hull'", "no uvms.water instance"]
    expected["two_water"] = ["more than one uvms.water instance"]
    for name, subs in expected.items():
        kind, msg = out[name]
        assert kind in ("ValueError", "FatalError"), (name, kind, msg)
        for sub in subs:
            assert sub in msg, f"{name}: {sub!r} not in {msg!r}"
        assert len(msg.splitlines()) <= 2, msg


def test_terms_none_switches_everything_off():
    cfg = {"added_mass": "2 8 6 0.02 0.05 0.07", "linear_damping": "1 1 1 1 1 1", "volume": "0.01",
           "strips": "x 0 0.2 1 1"}
    m = mujoco.MjModel.from_xml_string(free_body_xml(wcfg={"terms": "none", "current": "0.3 0 0"}, hcfg=cfg))
    d = mujoco.MjData(m)
    d.qvel[:] = 0.4
    mujoco.mj_forward(m, d)
    np.testing.assert_array_equal(d.qfrc_passive, 0.0)
    np.testing.assert_array_equal(M_full(m, d), bare_M(free_body_xml(hcfg=cfg), d.qpos.copy()))


def test_valid_forms_of_added_mass_are_equivalent():
    """6 (diagonal), 21 (upper triangle) and 36 (full) forms of the same M_A give the same M."""
    diag = [2.0, 8.0, 6.0, 0.02, 0.05, 0.07]
    up = []
    for i in range(6):
        for j in range(i, 6):
            up.append(diag[i] if i == j else 0.0)
    full = np.diag(diag).ravel()
    Ms = []
    for value in (" ".join(map(str, diag)), " ".join(map(str, up)), " ".join(map(str, full))):
        m = mujoco.MjModel.from_xml_string(free_body_xml(hcfg={"added_mass": value}))
        d = mujoco.MjData(m)
        mujoco.mj_forward(m, d)
        Ms.append(d.M.copy())
    # the forms may reach M_A through different operations in the plugin (measured: bit for bit);
    # a few ulps of M's scale
    tol = 1e-14 * np.abs(Ms[0]).max()
    np.testing.assert_allclose(Ms[1], Ms[0], rtol=0, atol=tol)
    np.testing.assert_allclose(Ms[2], Ms[0], rtol=0, atol=tol)
