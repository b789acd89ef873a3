"""The native (C) hydrodynamics backend against the pure-Python reference.

The C code (src/uvms_mj/_native/hydro.c) is a line-by-line port of HydroModel.evaluate with the
same order of operations, so it matches to rounding (measured: bit for bit); tolerances below
are 1e-12 relative to each quantity's scale for single evaluations and 1e-9 for a 10 s
trajectory. Tests that need the native library are skipped (with the reason) where it cannot
be built, e.g. without a C compiler.
"""

import gc
import itertools
import os
import re
import subprocess
import sys
import warnings

import mujoco
import numpy as np
import pytest

import uvms_mj.native as native
import uvms_mj.plant as plant_module
from uvms_mj import HydroModel, HydroTerms, ParameterError, Plant, strip_integrals

from conftest import random_q, random_qd

ALL_TERMS = [
    HydroTerms(added_mass=am, drag=dr, buoyancy=bu)
    for am, dr, bu in itertools.product(("exact", "off"), ("strip", "mujoco", "off"), (True, False))
]
#: Every body with drag along both of its axes, so that both strip branches run on every body.
BOTH_AXES_DRAG = {"link1.drag_coef": [0.9, 1.2], "link2.drag_coef": [0.7, 1.1]}


@pytest.fixture(scope="module")
def lib() -> native.NativeLib:
    found = native.load()
    if found is None:
        pytest.skip(f"native backend unavailable: {native.unavailable_reason()}")
    return found


def close(actual, expected, rel=1e-12):
    """|actual - expected| <= rel * scale, scale = max(1, max |expected|)."""
    actual, expected = np.asarray(actual, float), np.asarray(expected, float)
    scale = max(1.0, float(np.abs(expected).max(initial=0.0)))
    np.testing.assert_allclose(actual, expected, rtol=0, atol=rel * scale)


def random_state(rng, k):
    """Random q, qd, current and gravity; every 5th state has special velocities (rest, no
    rotation, pure rotation) that hit the strip integrals' om = 0 and w = 0 branches."""
    q = random_q(rng)
    qd = random_qd(rng, scale=rng.choice([0.1, 1.0, 5.0]))
    if k % 5 == 1:
        qd[:] = 0.0
    elif k % 5 == 2:
        qd[2:] = 0.0
    elif k % 5 == 3:
        qd[:2] = 0.0
    wind = rng.uniform(-0.3, 0.3, 2) if k % 2 else np.zeros(2)
    gravity = np.array([rng.uniform(-1, 1), -9.81 * rng.uniform(0.5, 1.5)])
    return q, qd, wind, gravity


# --------------------------------------------------------------------------- the maths alone


def test_strip_integrals_match(lib, rng):
    cases = [(0.0, 0.0, -0.1, 0.2), (0.3, 0.0, -0.1, 0.2), (-0.3, 0.0, 0.0, 0.25), (0.0, 1.0, -0.1, 0.1),
             (0.1, 1.0, -0.1, 0.1), (-0.05, 2.0, 0.0, 0.25), (0.2, -2.0, 0.1, 0.1), (0.1, -1.0, 0.0, 0.1)]
    cases += [(rng.normal(), rng.normal() * 3, lo, lo + rng.uniform(0, 0.5))
              for lo in rng.uniform(-0.3, 0.3, 300)]
    for w0, om, a, b in cases:
        close(lib.strip_integrals(w0, om, a, b), strip_integrals(w0, om, a, b))


@pytest.mark.parametrize("terms", ALL_TERMS, ids=str)
def test_evaluate_matches_python(lib, rng, terms):
    """Added-mass matrix and generalized force equal HydroModel.evaluate at 200 random states
    (with current, tilted gravity) for every combination of terms, with and without the mass."""
    for overrides in (None, BOTH_AXES_DRAG):
        hydro = HydroModel(Plant(overrides=overrides, backend="python").params, terms)
        params = native.make_params(hydro)
        for k in range(200):
            q, qd, wind, gravity = random_state(rng, k)
            for want_mass in (True, False):
                m_py, f_py = hydro.evaluate(q.tolist(), qd.tolist(), tuple(wind), tuple(gravity), want_mass)
                m_c, f_c = lib.evaluate(params, q, qd, wind, gravity, want_mass)
                assert len(m_c) == len(m_py)
                close(f_c, f_py)
                if m_py:
                    close(m_c, m_py)


# --------------------------------------------------------------------------- inside MuJoCo


def forward_quantities(plant: Plant, q, qd, ctrl) -> dict:
    d = plant.data
    d.qpos[:], d.qvel[:], d.ctrl[:] = q, qd, ctrl
    mujoco.mj_forward(plant.model, d)
    return {"qfrc_passive": d.qfrc_passive.copy(), "M": d.M.copy(), "qacc": d.qacc.copy(), "qLD": d.qLD.copy()}


@pytest.mark.parametrize("terms", ALL_TERMS, ids=str)
def test_forward_matches_python_plant(lib, rng, terms):
    """mj_forward of a native plant and of a Python plant at the same random states (current and
    gravity changed at run time) give the same passive force, mass matrix (augmented and
    factorized) and acceleration."""
    plants = [Plant(terms=terms, backend=b) for b in ("native", "python")]
    assert [p.backend for p in plants] == ["native", "python"]
    for k in range(40):
        q, qd, wind, gravity = random_state(rng, k)
        ctrl = rng.uniform(-3, 3, plants[0].model.nu)
        for p in plants:
            p.model.opt.wind[:2] = wind
            p.model.opt.gravity[:2] = gravity
        nat, py = (forward_quantities(p, q, qd, ctrl) for p in plants)
        for key in py:
            close(nat[key], py[key])


def drive(plant: Plant, seconds: float = 10.0) -> np.ndarray:
    """A 10 s run with thrust, joint torques and a current; the state sampled every 0.5 s."""
    plant.model.opt.wind[:2] = (0.05, -0.02)
    plant.set_state(base_velocity=(0.1, -0.05, 0.2), joint_velocities=(0.5, -0.8))
    rows = []
    per = round(0.5 / plant.model.opt.timestep)
    for i in range(round(seconds / 0.5)):
        plant.set_thrust([2.0 * np.sin(i), 1.0, -0.5 * np.cos(i)])
        plant.set_joint_torques([0.3 * np.cos(0.7 * i), -0.2])
        plant.step(per)
        rows.append(np.r_[plant.time, plant.q, plant.qd])
    return np.array(rows)


@pytest.mark.parametrize("integrator", [None, "euler", "implicitfast"])
def test_trajectory_matches_python_plant(lib, integrator):
    """10 s driven trajectories of the two backends agree to 1e-9."""
    nat = drive(Plant(backend="native", integrator=integrator))
    py = drive(Plant(backend="python", integrator=integrator))
    np.testing.assert_allclose(nat, py, rtol=0, atol=1e-9)


def test_finite_difference_derivatives_match(lib):
    """mjd_transitionFD (mj_forwardSkip re-enters the callback with d.M already augmented: the
    guard) gives the same linearization with both backends."""
    out = []
    for backend in ("native", "python"):
        p = Plant(backend=backend, integrator="euler")  # mjd_transitionFD does not take RK4
        p.set_state(base_velocity=(0.1, 0.0, 0.2), joint_velocities=(0.3, -0.2))
        m, nv, nu = p.model, p.model.nv, p.model.nu
        A = np.zeros((2 * nv + m.na, 2 * nv + m.na))
        B = np.zeros((2 * nv + m.na, nu))
        mujoco.mjd_transitionFD(m, p.data, 1e-6, True, A, B, None, None)
        out.append((A, B))
    for a, b in zip(*out):
        close(a, b, rel=1e-9)


# --------------------------------------------------------------------------- plant behaviour


def test_mixed_backends_in_one_process(lib):
    """Native and Python plants with different physics, extra data of each and a model compiled
    meanwhile: each equals its solo run, and the sphere falls freely."""
    def make(backend, **kw):
        p = Plant(backend=backend, **kw)
        p.set_state(base_velocity=(0.1, 0.0, 0.3))
        return p

    kinds = [("native", {}), ("python", {"current": (0.2, 0.0)}),
             ("native", {"terms": HydroTerms(drag="mujoco"), "overrides": {"base.added_mass": [50.0, 10.0, 1.0]}})]
    solo = []
    for backend, kw in kinds:
        p = make(backend, **kw)
        p.step(200)
        solo.append(p.q)
    plants = [make(backend, **kw) for backend, kw in kinds]
    assert [p.backend for p in plants] == ["native", "python", "native"]
    extra = []
    for p in plants:
        d = p.make_data()
        d.qpos[:], d.qvel[:] = p.data.qpos, p.data.qvel
        extra.append(d)
    sphere = mujoco.MjModel.from_xml_string(
        "<mujoco><worldbody><body><freejoint/><geom size='0.1' mass='1'/></body></worldbody></mujoco>")
    sd = mujoco.MjData(sphere)
    for _ in range(200):
        for p, d in zip(plants, extra):
            p.step(1)
            mujoco.mj_step(p.model, d)
        mujoco.mj_step(sphere, sd)
    for p, d, q in zip(plants, extra, solo):
        np.testing.assert_array_equal(p.q, q)
        np.testing.assert_array_equal(d.qpos, q)
    assert sd.qacc[2] == pytest.approx(-9.81)


def test_unregistered_data_of_native_plant_warns(lib):
    plant = Plant(backend="native")
    stray = mujoco.MjData(plant.model)
    plant_module._warned_unregistered = False
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        mujoco.mj_step(plant.model, stray)
    assert any(re.search("without hydrodynamics", str(w.message)) for w in caught)


def test_finalizers_unregister(lib):
    gc.collect()
    before = lib.registered_count()
    plant = Plant(backend="native")
    extra = plant.make_data()
    assert lib.registered_count() == before + 2
    del extra
    gc.collect()
    assert lib.registered_count() == before + 1
    del plant
    gc.collect()
    assert lib.registered_count() == before


# --------------------------------------------------------------------------- backend choice


def test_backend_choice(monkeypatch):
    monkeypatch.setenv(native.ENV_BACKEND, "python")
    assert Plant().backend == "python"
    assert Plant(terms=HydroTerms(added_mass="lagged"), backend="native").backend == "python"
    with pytest.raises(ParameterError, match=r"backend = 'fortran'; allowed: auto, python, native"):
        Plant(backend="fortran")
    monkeypatch.setenv(native.ENV_BACKEND, "fast")
    with pytest.raises(ParameterError, match=r"UVMS_MJ_BACKEND='fast'; allowed: auto, python, native"):
        Plant()


def test_unavailable_native_backend(monkeypatch):
    """Without a library: 'native' is a clear error, 'auto' falls back to Python and warns once."""
    monkeypatch.setattr(native, "_tried", True)
    monkeypatch.setattr(native, "_lib", None)
    monkeypatch.setattr(native, "_error", "no C compiler found (cc, gcc or clang; or set CC)")
    monkeypatch.setattr(native, "_warned", False)
    with pytest.raises(native.NativeUnavailableError, match=r"no C compiler found.*apt-get install gcc"):
        Plant(backend="native")
    with pytest.warns(RuntimeWarning, match=r"native hydrodynamics unavailable.*Install a C compiler"):
        assert Plant(backend="auto").backend == "python"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert Plant(backend="auto").backend == "python"  # only once


@pytest.mark.parametrize("cc, pattern", [("/nonexistent/cc", "cannot run the C compiler"), ("false", "failed")])
def test_build_failures_are_reported(monkeypatch, tmp_path, cc, pattern):
    monkeypatch.setenv(native.ENV_CACHE, str(tmp_path))
    monkeypatch.setenv("CC", cc)
    with pytest.raises(native.NativeUnavailableError, match=pattern):
        native.build()
    assert list(tmp_path.iterdir()) == []  # no temporary file left behind


def test_parallel_builds_share_one_library(lib, tmp_path):
    """Four processes building into an empty cache at once: one library, no leftovers, all load."""
    code = "import uvms_mj.native as n; lib = n.NativeLib(n.build()); print(lib.path)"
    env = {**os.environ, native.ENV_CACHE: str(tmp_path)}
    procs = [subprocess.Popen([sys.executable, "-c", code], env=env, stdout=subprocess.PIPE, text=True)
             for _ in range(4)]
    paths = {p.communicate(timeout=300)[0].strip() for p in procs}
    assert all(p.returncode == 0 for p in procs)
    assert len(paths) == 1
    assert [f.name for f in tmp_path.iterdir()] == [os.path.basename(paths.pop())]
