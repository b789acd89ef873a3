"""The `uvms.thruster` actuator plugin (src/uvms_mj/physics/plugin/thruster.c) against closed forms.

Specification: docs/hydrodynamics.md, "Thrusters". Pipeline: ctrl clamped to ctrlrange -> dead
zone -> first-order lag (the actuator's act, tau > 0) -> curve F(act) -> forcerange.

The library comes from ``uvms_mj.physics.build.library_path()`` when that module exists; before
it does, the fixture compiles thruster.c alone with the system C compiler.
"""

from __future__ import annotations

import copy
import json
import os
import shutil
import subprocess
import sys
import textwrap
import warnings
from pathlib import Path

import mujoco
import numpy as np
import pytest

SOURCE = Path(__file__).resolve().parents[1] / "src" / "uvms_mj" / "physics" / "plugin" / "thruster.c"

#: Blue Robotics T200 thrust (N) against the normalised command V in [-1, 1].
T200 = [0.0, 8.9, 0.0, 176.0, 0.0, -404.1, 0.0, 389.9, 0.0, -140.3]  # c0 ... c9


def _registered() -> bool:
    """Is `uvms.thruster` registered in this process (by an earlier load or by uvms_mj)?"""
    try:
        mujoco.MjModel.from_xml_string(model_xml('<plugin plugin="uvms.thruster" site="s"/>'))
    except ValueError as err:
        msg = str(err).lower()
        if "uvms.thruster" in msg and ("not found" in msg or "unknown" in msg):
            return False
        raise
    return True


def _compile_alone(out: Path) -> Path:
    """Compile thruster.c alone against the mujoco wheel's headers and library."""
    cc = os.environ.get("CC") or next((c for c in ("cc", "gcc", "clang") if shutil.which(c)), None)
    if cc is None:
        pytest.skip("no C compiler to build the thruster plugin")
    wheel = Path(mujoco.__file__).resolve().parent
    lib = next(wheel.glob("libmujoco.so*"))
    target = out / "libuvms_thruster.so"
    cmd = [cc, "-O2", "-shared", "-fPIC", "-ffp-contract=off", "-Wall", "-Wextra", "-Werror",
           "-Wno-unused-parameter", f"-I{wheel / 'include'}", str(SOURCE), "-o", str(target),
           f"-L{wheel}", f"-l:{lib.name}", f"-Wl,-rpath,{wheel}"]
    subprocess.run(cmd, check=True, capture_output=True, text=True)
    return target


@pytest.fixture(scope="session")
def plugin_library(tmp_path_factory) -> Path:
    """Path of a library that registers `uvms.thruster`, loaded into this process."""
    try:
        from uvms_mj.physics.build import library_path
    except ImportError:
        library_path = None
    path = None
    if library_path is not None:
        try:
            path = Path(library_path())
        except Exception as err:  # e.g. another plugin source does not compile: test this one
            warnings.warn(f"uvms_mj.physics.build.library_path() failed ({err}); "
                          "compiling thruster.c alone")
    if path is None:
        path = _compile_alone(tmp_path_factory.mktemp("thruster"))
    # a second dlopen of the same file runs no constructor; a different file registering the
    # same plugin name again would be an error, hence the check
    if not _registered():
        mujoco.mj_loadPluginLibrary(str(path))
    assert _registered()
    return path


def model_xml(actuators: str, *, integrator: str = "RK4", timestep: float = 1e-3,
              extension: str = '<plugin plugin="uvms.thruster"/>') -> str:
    """A floating box with a swinging link; sites "s" (on the box, rotated) and "s2" (on the
    link), so that J_site has full rank and couples the dofs."""
    return textwrap.dedent(f"""\
        <mujoco>
          <option timestep="{timestep}" integrator="{integrator}" gravity="0 0 0"/>
          <extension>{extension}</extension>
          <worldbody>
            <body name="box" pos="0.1 -0.2 0.3" euler="5 -10 20">
              <freejoint/>
              <geom type="box" size="0.2 0.1 0.05" mass="3"/>
              <site name="s" pos="0.15 0.05 -0.03" euler="10 20 30"/>
              <body name="link" pos="0.2 0 0">
                <joint name="hinge" type="hinge" axis="0 1 0"/>
                <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.02" mass="0.4"/>
                <site name="s2" pos="0.3 0 0" euler="0 60 15"/>
              </body>
            </body>
          </worldbody>
          <actuator>{actuators}</actuator>
        </mujoco>""")


def thruster(site: str = "s", *, curve: str | None = None, dead_zone: str | None = None,
             tau: float | None = None, attrs: str = "") -> str:
    cfg = ""
    if curve is not None:
        cfg += f'<config key="curve" value="{curve}"/>'
    if dead_zone is not None:
        cfg += f'<config key="dead_zone" value="{dead_zone}"/>'
    if tau is not None:
        cfg += f'<config key="tau" value="{tau!r}"/>'
    actdim = 'actdim="1"' if tau else ""
    return f'<plugin plugin="uvms.thruster" site="{site}" {actdim} {attrs}>{cfg}</plugin>'


def build(actuators: str, **kw) -> tuple[mujoco.MjModel, mujoco.MjData]:
    m = mujoco.MjModel.from_xml_string(model_xml(actuators, **kw))
    return m, mujoco.MjData(m)


def static_forces(m: mujoco.MjModel, d: mujoco.MjData, commands) -> np.ndarray:
    """actuator_force of actuator 0 for each command (stateless thrusters, mj_forward)."""
    out = []
    for u in commands:
        d.ctrl[0] = u
        mujoco.mj_forward(m, d)
        out.append(d.actuator_force[0])
    return np.array(out)


# ------------------------------------------------------------------------------------------------
# first-order lag


@pytest.mark.parametrize("integrator", ["Euler", "RK4"])
def test_step_response_reaches_63_percent_at_tau(plugin_library, integrator):
    """act(t) = u (1 - e^{-t/tau}) for a step u. The integrators solve the linear ODE with known
    per-step amplification R(z), z = h/tau: Euler 1 - z, RK4 the 4th-order Taylor polynomial of
    e^{-z}; so act_N = u (1 - R^N) exactly (to rounding, 1e-13), and the continuous value at
    t = tau (63.2 % of u) is met to the integrator's global error: Euler u e^{-1} z / 2 (+O(z^2)),
    RK4 u e^{-1} z^4 / 120 (+O(z^5))."""
    tau, h, u = 0.05, 1e-4, 7.5
    n = round(tau / h)
    m, d = build(thruster(curve="poly 0 1", tau=tau, attrs='ctrlrange="-10 10"'),
                 integrator=integrator, timestep=h)
    assert m.na == 1 and m.actuator_actnum[0] == 1
    d.ctrl[0] = u
    for _ in range(n):
        mujoco.mj_step(m, d)
    z = h / tau
    r = 1 - z if integrator == "Euler" else 1 - z + z**2 / 2 - z**3 / 6 + z**4 / 24
    np.testing.assert_allclose(d.act[0], u * (1 - r**n), rtol=1e-13)
    exact = u * (1 - np.exp(-1.0))
    assert d.act[0] / u == pytest.approx(0.632, abs=5e-4)
    err = abs(d.act[0] - exact)
    bound = u * np.exp(-1) * (z / 2 if integrator == "Euler" else z**4 / 120)
    assert err <= 1.01 * bound
    if integrator == "Euler":
        assert err >= 0.99 * bound  # first order, as predicted
    # the force is the curve of the state, evaluated before the step's integration
    mujoco.mj_forward(m, d)
    assert d.actuator_force[0] == d.act[0]


def test_lag_follows_clamped_and_dead_zoned_command(plugin_library):
    """The lag is driven by the command after ctrlrange and dead zone: with Euler,
    act_{k+1} = act_k + h (u_eff - act_k) / tau exactly (bit for bit)."""
    tau, h = 0.02, 1e-3
    m, d = build(thruster(curve="poly 0 1", dead_zone="-0.1 0.2", tau=tau, attrs='ctrlrange="-1 2"'),
                 integrator="Euler", timestep=h)
    act = 0.0
    for u in [5.0, 5.0, 0.15, -0.05, -3.0, -0.1, 0.2, 1.0]:
        d.ctrl[0] = u
        mujoco.mj_step(m, d)
        ueff = min(max(u, -1.0), 2.0)
        ueff = 0.0 if -0.1 < ueff < 0.2 else ueff
        act = act + h * ((ueff - act) / tau)
        assert d.act[0] == act
        assert d.ctrl[0] == u  # MuJoCo leaves ctrl itself unclamped


# ------------------------------------------------------------------------------------------------
# curve, dead zone, limits (tau = 0: stateless, force from the command at once)


def test_polynomial_curve_t200(plugin_library):
    """F = -140.3 V^9 + 389.9 V^7 - 404.1 V^5 + 176.0 V^3 + 8.9 V against numpy.polyval."""
    m, d = build(thruster(curve="poly " + " ".join(map(str, T200)), attrs='ctrlrange="-1 1"'))
    assert m.na == 0
    v = np.linspace(-1, 1, 201)
    expected = np.polyval(T200[::-1], v)
    np.testing.assert_allclose(static_forces(m, d, v), expected, rtol=1e-12, atol=1e-12)
    assert static_forces(m, d, [1.0])[0] == pytest.approx(30.4, abs=1e-12)


def test_constant_and_default_curve(plugin_library):
    m, d = build(thruster(curve="poly 2.5"))
    np.testing.assert_array_equal(static_forces(m, d, [-3.0, 0.0, 4.0]), 2.5)
    m, d = build(thruster())  # default curve "poly 0 1", no dead zone, no lag
    u = np.array([-3.0, -1e-9, 0.0, 0.7, 12.0])
    np.testing.assert_array_equal(static_forces(m, d, u), u)


def test_table_curve_interpolates_and_is_constant_beyond_the_ends(plugin_library):
    pts = np.array([[-1.0, -8.0], [-0.3, -1.5], [0.0, 0.0], [0.1, 0.2], [0.6, 9.0], [1.0, 15.0]])
    curve = "table " + " ".join(repr(float(x)) for x in pts.ravel())
    m, d = build(thruster(curve=curve))
    u = np.r_[np.linspace(-1.5, 1.5, 301), pts[:, 0]]  # beyond both ends and every knot
    np.testing.assert_allclose(static_forces(m, d, u), np.interp(u, pts[:, 0], pts[:, 1]),
                               rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(static_forces(m, d, pts[:, 0]), pts[:, 1])  # knots exactly
    m, d = build(thruster(curve="table 0.5 3"))  # a single point: constant
    np.testing.assert_array_equal(static_forces(m, d, [-2.0, 0.5, 7.0]), 3.0)


def test_dead_zone_is_open_and_acts_on_the_command(plugin_library):
    """Commands strictly between dz_lo and dz_hi become 0 before the curve: with c0 = 5 the
    force in the dead zone is F(0) = 5, not 0."""
    m, d = build(thruster(curve="poly 5 1", dead_zone="-0.1 0.2"))
    u = np.array([-0.5, -0.1, -0.09999, 0.0, 0.1, 0.19999, 0.2, 0.5])
    ueff = np.where((u > -0.1) & (u < 0.2), 0.0, u)
    np.testing.assert_array_equal(static_forces(m, d, u), 5 + ueff)


def test_ctrlrange_clamp_and_both_force_limits(plugin_library):
    """F = clip(10 clip(u, -1, 1), -3, 4): MuJoCo clamps plugin forces to forcerange (after the
    plugin's compute); the plugin clamps the command itself (MuJoCo clamps only a private copy)."""
    m, d = build(thruster(curve="poly 0 10", attrs='ctrlrange="-1 1" forcerange="-3 4"'))
    assert m.actuator_forcelimited[0] and m.actuator_ctrllimited[0]
    u = np.array([-5.0, -1.0, -0.31, -0.3, -0.1, 0.0, 0.2, 0.4, 0.41, 1.0, 5.0])
    np.testing.assert_array_equal(static_forces(m, d, u), np.clip(10 * np.clip(u, -1, 1), -3, 4))
    # no forcerange: the curve's value, still with the command clamped
    m, d = build(thruster(curve="poly 0 10", attrs='ctrlrange="-1 1"'))
    np.testing.assert_array_equal(static_forces(m, d, u), 10 * np.clip(u, -1, 1))
    # clamping of ctrl disabled by the model: the plugin obeys
    m, d = build(thruster(curve="poly 0 10", attrs='ctrlrange="-1 1"'))
    m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CLAMPCTRL
    np.testing.assert_array_equal(static_forces(m, d, u), 10 * u)


def test_limits_with_lag(plugin_library):
    """The saturated force of a lagged thruster: F = clip(c1 act, lo, hi)."""
    m, d = build(thruster(curve="poly 0 20", tau=0.01, attrs='ctrlrange="-1 1" forcerange="-5 8"'),
                 integrator="Euler")
    for u in [1.0, -1.0]:
        d.ctrl[0] = u
        for _ in range(300):
            mujoco.mj_step(m, d)
            assert -5 <= d.actuator_force[0] <= 8
        mujoco.mj_forward(m, d)
        assert d.actuator_force[0] == np.clip(20 * d.act[0], -5, 8)
        assert d.actuator_force[0] == (8 if u > 0 else -5)


# ------------------------------------------------------------------------------------------------
# generalized force


@pytest.mark.parametrize("gear", ["1 0 0 0 0 0", "0.5 0 0 0 0.02 -0.01"])
def test_generalized_force_is_site_jacobian_transpose(plugin_library, gear):
    """qfrc_actuator = J_site^T (F R_site g_lin) + J_rot^T (F R_site g_rot) (mj_jacSite), 1e-12;
    gear "1 0 0 0 0 0": the thrust F along the site's x axis."""
    m, d = build(thruster("s", curve="poly 0.3 2 -1", attrs=f'gear="{gear}"')
                 + thruster("s2", curve="table -1 -4 1 6", attrs=f'gear="{gear}"'))
    g = np.array(gear.split(), dtype=float)
    rng = np.random.default_rng(20261201)
    for _ in range(5):
        d.qpos[:3] = rng.uniform(-1, 1, 3)
        d.qpos[3:7] = rng.normal(size=4)
        d.qpos[3:7] /= np.linalg.norm(d.qpos[3:7])
        d.qpos[7] = rng.uniform(-np.pi, np.pi)
        d.qvel[:] = rng.normal(size=m.nv)
        d.ctrl[:] = rng.uniform(-1.5, 1.5, 2)
        mujoco.mj_forward(m, d)
        expected = np.zeros(m.nv)
        for i, site in enumerate(["s", "s2"]):
            sid = m.site(site).id
            jacp, jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
            mujoco.mj_jacSite(m, d, jacp, jacr, sid)
            r = d.site_xmat[sid].reshape(3, 3)
            f = d.actuator_force[i]
            expected += jacp.T @ (f * r @ g[:3]) + jacr.T @ (f * r @ g[3:])
        np.testing.assert_allclose(d.qfrc_actuator, expected, rtol=1e-12, atol=1e-12)
        assert np.abs(d.actuator_force).min() > 0.1  # non-trivial forces


# ------------------------------------------------------------------------------------------------
# equivalence with MuJoCo's own filter actuator


def _trajectory(m, d, controls):
    out = []
    for u in controls:
        d.ctrl[:] = u
        mujoco.mj_step(m, d)
        out.append(np.concatenate([d.qpos, d.qvel, d.act, d.actuator_force, d.qfrc_actuator]))
    return np.array(out)


@pytest.mark.parametrize("integrator", ["RK4", "Euler", "implicitfast"])
@pytest.mark.parametrize("extra", ["", 'actearly="true"', 'delay="0.004" nsample="8"'])
def test_bit_identical_to_general_filter_actuator(plugin_library, integrator, extra):
    """<general dyntype="filter" dynprm="tau"> (gain 1) and the plugin with curve "poly 0 1" and
    the same tau, ctrlrange and forcerange: the same trajectories (measured: bit for bit, the
    same operations; compared to 1e-12 of the values' scale, O(1), since two implementations --
    MuJoCo's and the plugin's C -- need not order the same formula the same way)."""
    specs = [("s", 0.05, 'ctrlrange="-1 1" forcerange="-0.6 0.8"'), ("s2", 0.3, 'ctrlrange="-2 1"')]
    plug = "".join(thruster(s, curve="poly 0 1", tau=tau, attrs=f"{a} {extra}") for s, tau, a in specs)
    gen = "".join(f'<general site="{s}" dyntype="filter" dynprm="{tau!r}" {a} {extra}/>'
                  for s, tau, a in specs)
    controls = np.random.default_rng(7).uniform(-3, 3, (600, 2))
    mp, dp = build(plug, integrator=integrator, timestep=2e-3)
    mg, dg = build(gen, integrator=integrator, timestep=2e-3)
    tp, tg = _trajectory(mp, dp, controls), _trajectory(mg, dg, controls)
    assert np.abs(tp[:, mp.nq + mp.nv:]).max() > 0.3  # the actuators did act
    np.testing.assert_allclose(tp, tg, rtol=0, atol=1e-12 * max(1.0, np.abs(tg).max()))


def test_disabled_actuator_group_gives_no_force(plugin_library):
    m, d = build(thruster(curve="poly 1 1", attrs='group="3"') + thruster("s2", curve="poly 1 1"))
    d.ctrl[:] = [0.5, 0.5]
    mujoco.mj_forward(m, d)
    np.testing.assert_array_equal(d.actuator_force, [1.5, 1.5])
    m.opt.disableactuator = 1 << 3
    mujoco.mj_forward(m, d)
    np.testing.assert_array_equal(d.actuator_force, [0.0, 1.5])


# ------------------------------------------------------------------------------------------------
# instances, data copies, threads


def test_shared_instance_drives_several_actuators(plugin_library):
    ext = textwrap.dedent("""\
        <plugin plugin="uvms.thruster">
          <instance name="T200">
            <config key="curve" value="poly 0 2"/><config key="tau" value="0.1"/>
          </instance>
        </plugin>""")
    acts = ('<plugin name="a" instance="T200" site="s" actdim="1"/>'
            '<plugin name="b" instance="T200" site="s2" actdim="1"/>')
    m = mujoco.MjModel.from_xml_string(model_xml(acts, extension=ext, integrator="Euler"))
    d = mujoco.MjData(m)
    assert m.nplugin == 1 and list(m.actuator_plugin) == [0, 0] and m.na == 2
    d.ctrl[:] = [1.0, -0.5]
    mujoco.mj_step(m, d)
    np.testing.assert_array_equal(d.act, [1e-3 * 1.0 / 0.1, 1e-3 * -0.5 / 0.1])
    mujoco.mj_forward(m, d)
    np.testing.assert_array_equal(d.actuator_force, 2 * d.act)


def test_copy_reset_and_threaded_rollout(plugin_library):
    from mujoco import rollout

    acts = thruster(curve="table -1 -3 0 0 1 5", dead_zone="-0.05 0.05", tau=0.03,
                    attrs='ctrlrange="-1 1" forcerange="-2 4"') + thruster("s2", curve="poly 0 1 0 -0.2")
    m, d = build(acts)
    controls = np.random.default_rng(3).uniform(-1.2, 1.2, (8, 200, 2))
    state0 = np.zeros(mujoco.mj_stateSize(m, mujoco.mjtState.mjSTATE_FULLPHYSICS))
    mujoco.mj_getState(m, d, state0, mujoco.mjtState.mjSTATE_FULLPHYSICS)

    # serial reference
    ref = []
    for b in range(len(controls)):
        mujoco.mj_resetData(m, d)
        ref.append(_trajectory(m, d, controls[b]))
    # a copied mjData continues identically (the same mj_step on the same state: determinism, exact)
    mujoco.mj_resetData(m, d)
    _trajectory(m, d, controls[0][:50])
    d2 = copy.copy(d)
    np.testing.assert_array_equal(_trajectory(m, d, controls[0][50:]), _trajectory(m, d2, controls[0][50:]))
    # rollout on 4 threads
    datas = [mujoco.MjData(m) for _ in range(4)]
    state, _ = rollout.rollout(m, datas, np.tile(state0, (len(controls), 1)), controls)
    ref_qpos = np.array([r[:, : m.nq] for r in ref])
    ref_act = np.array([r[:, m.nq + m.nv : m.nq + m.nv + m.na] for r in ref])
    # full-physics state: time, qpos, qvel, act, ... Exact: rollout runs the same compiled mj_step
    # (no CPU-dependent dispatch in MuJoCo or the plugins, built with -ffp-contract=off) per trajectory
    np.testing.assert_array_equal(state[:, :, 1 : 1 + m.nq], ref_qpos)
    np.testing.assert_array_equal(state[:, :, 1 + m.nq + m.nv : 1 + m.nq + m.nv + m.na], ref_act)


# ------------------------------------------------------------------------------------------------
# bad configurations: clear exceptions (checked in a subprocess, so a crash would show as such)

BAD = [
    # (label, actuator xml, words the message must contain)
    ("keyword", thruster(curve="spline 0 1"), ["'curve'", "spline", "poly", "table"]),
    ("nan", thruster(curve="poly 0 nan"), ["'curve'", "nan", "finite"]),
    ("inf", thruster(curve="table 0 0 1 inf"), ["'curve'", "inf", "finite"]),
    ("word", thruster(curve="poly 0 one"), ["'curve'", "one", "finite"]),
    ("empty poly", thruster(curve="poly"), ["'curve'", "at least one coefficient"]),
    ("odd table", thruster(curve="table 0 1 2"), ["'curve'", "pairs", "3 numbers"]),
    ("non-increasing", thruster(curve="table 0 0 1 2 1 3"), ["'curve'", "strictly increasing", "u2 = 1"]),
    ("decreasing", thruster(curve="table 1 0 0 2"), ["'curve'", "strictly increasing"]),
    ("dz order", thruster(dead_zone="0.2 -0.1"), ["'dead_zone'", "0.2 -0.1", "dz_lo <= dz_hi"]),
    ("dz count", thruster(dead_zone="0.2"), ["'dead_zone'", "two numbers"]),
    ("dz nan", thruster(dead_zone="nan 1"), ["'dead_zone'", "nan", "finite"]),
    ("tau negative", thruster(tau=-0.1), ["'tau'", "-0.1", "tau >= 0"]),
    ("tau nan", '<plugin plugin="uvms.thruster" site="s" actdim="1"><config key="tau" value="nan"/></plugin>',
     ["'tau'", "nan", "finite"]),
    ("tau without state", '<plugin plugin="uvms.thruster" site="s"><config key="tau" value="0.1"/></plugin>',
     ["'tau'", 'actdim="1"']),
    ("state without tau", '<plugin plugin="uvms.thruster" site="s" actdim="1"/>',
     ["'tau' = 0", 'actdim="0"']),
    ("dyntype", thruster(tau=0.1, attrs='dyntype="filter" dynprm="0.1"'), ["dyntype", "none"]),
]


def _run(script: str, library: Path) -> list:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    res = subprocess.run([sys.executable, "-c", script, str(library)], capture_output=True, text=True,
                         env=env, timeout=120)
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout.strip().splitlines()[-1])


def test_bad_configurations_raise_clear_errors(plugin_library):
    """Each bad configuration fails to compile with a ValueError naming the plugin, the actuator,
    the attribute and its value, and what is allowed; the process survives."""
    cases = [(label, model_xml(xml.replace('plugin="uvms.thruster"', 'name="thr" plugin="uvms.thruster"', 1)))
             for label, xml, _ in BAD]
    script = textwrap.dedent(f"""\
        import json, sys, mujoco
        mujoco.mj_loadPluginLibrary(sys.argv[1])
        out = []
        for label, xml in {cases!r}:
            try:
                mujoco.MjModel.from_xml_string(xml)
                out.append([label, None, ""])
            except Exception as err:
                out.append([label, type(err).__name__, str(err)])
        # the process is still healthy: a good model steps
        m = mujoco.MjModel.from_xml_string({model_xml(thruster(tau=0.1))!r})
        d = mujoco.MjData(m); d.ctrl[0] = 1; mujoco.mj_step(m, d)
        out.append(["ok", None, repr(float(d.act[0]))])
        print(json.dumps(out))
        """)
    results = _run(script, plugin_library)
    assert results[-1][0] == "ok" and float(results[-1][2]) > 0
    for (label, _, words), (label2, kind, msg) in zip(BAD, results[:-1]):
        assert label == label2
        assert kind == "ValueError", (label, kind, msg)
        for w in ["uvms.thruster", "actuator 'thr'"] + words:
            assert w in msg, (label, w, msg)


def test_unknown_attribute_is_refused_by_mujoco(plugin_library):
    xml = model_xml('<plugin plugin="uvms.thruster" site="s"><config key="tua" value="0.1"/></plugin>')
    with pytest.raises(ValueError, match="tua"):
        mujoco.MjModel.from_xml_string(xml)


def test_bad_configuration_at_mjdata_creation_raises_fatal_error(plugin_library):
    """A model that skips the compiler's check (configuration edited in a compiled model, as
    from a binary file): MjData creation raises mujoco.FatalError with the plugin's message."""
    script = textwrap.dedent(f"""\
        import json, sys, mujoco
        mujoco.mj_loadPluginLibrary(sys.argv[1])
        m = mujoco.MjModel.from_xml_string({model_xml(thruster(tau=0.5))!r})
        i = m.plugin_attr.tobytes().find(b"0.5")
        m.plugin_attr[i] = ord("-")          # tau = "-.5"
        out = []
        try:
            mujoco.MjData(m)
            out.append([None, ""])
        except Exception as err:
            out.append([type(err).__name__, str(err)])
        m.plugin_attr[i] = ord("0")          # repaired: works again
        d = mujoco.MjData(m); mujoco.mj_step(m, d)
        out.append(["ok", ""])
        print(json.dumps(out))
        """)
    (kind, msg), ok = _run(script, plugin_library)
    assert kind == "FatalError"
    assert "uvms.thruster" in msg and "'tau'" in msg and "-.5" in msg and "tau >= 0" in msg
    assert ok[0] == "ok"
