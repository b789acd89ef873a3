"""The plant's two backends: the C plugins (native) and the numpy reference (python).

Both implement the equations of docs/hydrodynamics.md independently (C in
src/uvms_mj/physics/plugin/water.c, numpy in src/uvms_mj/physics/reference.py). Single
evaluations agree to 1e-12 relative to each quantity's scale (only the order of floating-point
operations differs: measured about 1e-15); 10 s driven trajectories to 1e-9 (rounding amplified
by the dynamics over 1200 RK4 steps: measured about 1e-13).
"""

from __future__ import annotations

import itertools
import os
import subprocess
import sys
import textwrap

import mujoco
import numpy as np
import pytest

from uvms_mj import HydroTerms, ParameterError, Plant
from uvms_mj.physics import build

from conftest import random_q, random_qd

ALL_TERMS = [HydroTerms(added_mass=am, drag=dr, buoyancy=bu)
             for am, dr, bu in itertools.product(("exact", "off"), ("strip", "mujoco", "off"), (True, False))]


@pytest.fixture(autouse=True)
def _need_native(native_available):
    if not native_available:
        pytest.skip(f"the C plugins are unavailable: {build.unavailable_reason()}")


def close(actual, expected, rel):
    actual, expected = np.asarray(actual, float), np.asarray(expected, float)
    scale = max(1.0, float(np.abs(expected).max(initial=0.0)))
    np.testing.assert_allclose(actual, expected, rtol=0, atol=rel * scale)


def forward(plant: Plant, q, qd, ctrl) -> dict:
    d = plant.data
    d.qpos[:], d.qvel[:], d.ctrl[:] = q, qd, ctrl
    mujoco.mj_forward(plant.model, d)
    full = np.zeros((5, 5))
    mujoco.mj_fullM(plant.model, d, full)
    return {"M": full, "qfrc_passive": d.qfrc_passive.copy(), "qacc": d.qacc.copy()}


@pytest.mark.parametrize("terms", ALL_TERMS, ids=str)
def test_forward_agrees(rng, terms):
    """M (rigid + added), passive forces and accelerations at 30 random states with a current."""
    plants = [Plant(terms=terms, backend=b, current=(0.07, -0.03)) for b in ("native", "python")]
    assert [p.backend for p in plants] == ["native", "python"]
    for _ in range(30):
        q, qd, ctrl = random_q(rng), random_qd(rng), rng.uniform(-3, 3, 5)
        a, b = (forward(p, q, qd, ctrl) for p in plants)
        for key in a:
            close(a[key], b[key], 1e-12)


def drive(plant: Plant, seconds: float = 10.0) -> np.ndarray:
    plant.reset()
    plant.set_state(base_velocity=(0.1, -0.05, 0.2), joint_velocities=(0.5, -0.4))
    out = []
    for k in range(int(round(seconds / plant.model.opt.timestep))):
        plant.set_thrust([2.0 * np.sin(0.01 * k), 1.0, -0.5])
        plant.set_joint_torques([0.3 * np.cos(0.02 * k), -0.1])
        plant.step(1)
        out.append(np.r_[plant.q, plant.qd])
    return np.array(out)


@pytest.mark.parametrize("integrator", [None, "euler", "implicitfast"])
def test_trajectories_agree(integrator):
    a = drive(Plant(backend="native", integrator=integrator))
    b = drive(Plant(backend="python", integrator=integrator), 10.0)
    close(a, b, 1e-9)


def test_finite_difference_derivatives_agree():
    """mjd_transitionFD (mj_forwardSkip re-enters the passive stage with d.M augmented: the
    guard) gives the same linearization with both backends (1e-6: finite differences of
    forces that agree to 1e-12, divided by eps = 1e-6)."""
    mats = []
    for backend in ("native", "python"):
        p = Plant(backend=backend, integrator="euler")  # mjd_transitionFD does not take RK4
        p.set_state(base_velocity=(0.1, 0.0, 0.2), joint_velocities=(0.3, -0.2))
        n = 2 * p.model.nv + p.model.na
        A = np.zeros((n, n))
        B = np.zeros((n, p.model.nu))
        mujoco.mjd_transitionFD(p.model, p.data, 1e-6, True, A, B, None, None)
        mats.append((A, B))
    close(mats[0][0], mats[1][0], 1e-6)
    close(mats[0][1], mats[1][1], 1e-6)


def test_mixed_backends_in_one_process():
    """Native and Python plants side by side (and models compiled meanwhile) each behave as alone."""
    alone = {b: drive(Plant(backend=b), 1.0) for b in ("native", "python")}
    plants = [Plant(backend=b) for b in ("native", "python", "native")]
    mujoco.MjModel.from_xml_string("<mujoco><worldbody><body><freejoint/><geom size='0.1'/></body></worldbody></mujoco>")
    for p in plants:
        np.testing.assert_array_equal(drive(p, 1.0), alone[p.backend])


def test_backend_choice(monkeypatch):
    """The default backend follows UVMS_MJ_COMPILED (off: python, on: native); an explicit
    backend= wins; a bad value or a former switch is a one-line CompiledModeError."""
    monkeypatch.setenv("UVMS_MJ_COMPILED", "off")
    assert Plant().backend == "python"
    assert Plant(backend="python").backend == "python"
    monkeypatch.setenv("UVMS_MJ_COMPILED", "on")
    assert Plant().backend == "native"
    monkeypatch.delenv("UVMS_MJ_COMPILED")
    assert Plant().backend == "native"
    assert Plant(terms=HydroTerms(added_mass="lagged"), backend="native").backend == "python"
    with pytest.raises(ParameterError, match=r"backend = 'fortran'; allowed: auto, python, native"):
        Plant(backend="fortran")
    monkeypatch.setenv("UVMS_MJ_COMPILED", "fast")
    with pytest.raises(build.CompiledModeError, match=r"UVMS_MJ_COMPILED='fast' is not one of auto, on, off"):
        Plant()
    monkeypatch.delenv("UVMS_MJ_COMPILED")
    monkeypatch.setenv("UVMS_MJ_BACKEND", "python")
    with pytest.raises(build.CompiledModeError, match=r"UVMS_MJ_BACKEND=python is no longer read.*UVMS_MJ_COMPILED"):
        Plant()


def test_unavailable_plugins_native_is_an_error(monkeypatch):
    monkeypatch.setattr(build, "_registered", False)
    monkeypatch.setattr(build, "_reason", "no C compiler found (Debian: apt-get install gcc; or set CC)")
    monkeypatch.setattr(build, "_warned", False)  # UVMS_MJ_COMPILED=auto: the process's one warning, then the error
    with pytest.warns(RuntimeWarning, match="uvms C plugins unavailable"), \
            pytest.raises(build.PluginUnavailableError, match=r"no C compiler found.*apt-get install gcc"):
        Plant(backend="native")


@pytest.mark.slow
def test_without_a_compiler_everything_falls_back(tmp_path):
    """A fresh process with no compiler and an empty cache: `import uvms_mj` is silent, the
    first plant says so in one warning (one for every compiled path), runs on the Python backend
    (with the model file's plugins stripped) and gives the native trajectory (1e-9)."""
    code = textwrap.dedent("""
        import warnings, numpy as np
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            import uvms_mj
            assert not caught, [str(w.message) for w in caught]
            from uvms_mj import Plant
            p = Plant()
            p.set_state(base_velocity=(0.1, -0.05, 0.2))
            p.step(240)
            p.step_observe(2)
            from uvms_mj.sim.experiment import PaperExperiment
            assert PaperExperiment(duration=0.2, controller="rac").run().status == "ok"
        msgs = [str(w.message) for w in caught if "uvms_mj" in str(w.message)]
        assert len(msgs) == 1 and "\\n" not in msgs[0] and "C plugins unavailable" in msgs[0], msgs
        assert p.backend == "python"
        p.reset()
        p.set_state(base_velocity=(0.1, -0.05, 0.2))
        p.step(240)
        np.save(OUT, np.r_[p.q, p.qd])
    """).replace("OUT", repr(str(tmp_path / "q.npy")))
    env = {**os.environ, "CC": "/nonexistent/cc", "UVMS_MJ_CACHE": str(tmp_path / "cache")}
    env.pop("UVMS_MJ_COMPILED", None)
    res = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    p = Plant()
    p.set_state(base_velocity=(0.1, -0.05, 0.2))
    p.step(240)
    close(np.load(tmp_path / "q.npy"), np.r_[p.q, p.qd], 1e-9)
