"""The C port of the planar closed form (used by the nominal model) against the Python one.

The C code (src/uvms_mj/planar/_native/hydro.c) is a line-by-line port of HydroModel.evaluate with the
same order of operations, so it matches to rounding (measured: bit for bit); tolerance 1e-12
relative to each quantity's scale. Tests that need the library are skipped (with the reason)
where it cannot be built, e.g. without a C compiler. (The plant's hydrodynamics are the MuJoCo
plugins: tests/test_backends.py, tests/test_plugin_*.py.)
"""

import itertools
import os
import subprocess
import sys

import numpy as np
import pytest

import oracles.planar.native as native
from oracles.planar.hydro import HydroModel
from uvms_mj import HydroTerms, Plant, strip_integrals
from uvms_mj.physics import build

from conftest import random_q, random_qd

ALL_TERMS = [
    HydroTerms(added_mass=am, drag=dr, buoyancy=bu)
    for am, dr, bu in itertools.product(("exact", "off"), ("strip", "mujoco", "off"), (True, False))
]
#: Every body with drag along both of its axes, so that both strip branches run on every body.
BOTH_AXES_DRAG = {"link1.drag_coef": [0.9, 1.2], "link2.drag_coef": [0.7, 1.1]}


@pytest.fixture(scope="module")
def lib() -> native.NativeLib:
    found = native.load_native()
    if found is None:
        pytest.skip(f"native backend unavailable: {native.native_unavailable_reason()}")
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


# --------------------------------------------------------------------------- building


@pytest.mark.parametrize("cc, pattern", [("/nonexistent/cc", "not found"), ("false", "failed")])
def test_build_failures_are_reported(monkeypatch, tmp_path, cc, pattern):
    monkeypatch.setenv(build.ENV_CACHE, str(tmp_path))
    monkeypatch.setenv("CC", cc)
    with pytest.raises(native.NativeUnavailableError, match=pattern):
        native.build_native()
    assert not [f for f in tmp_path.iterdir() if f.name.startswith(".nominal")]  # no temporary file left


def test_parallel_builds_share_one_library(lib, tmp_path):
    """Four processes building into an empty cache at once: one library, no leftovers, all load."""
    code = "import oracles.planar.native as n; lib = n.NativeLib(n.build_native()); print(lib.path)"
    tests_dir = os.path.dirname(os.path.abspath(__file__))  # the oracles package lives there
    env = {**os.environ, build.ENV_CACHE: str(tmp_path),
           "PYTHONPATH": os.pathsep.join(filter(None, (tests_dir, os.environ.get("PYTHONPATH"))))}
    procs = [subprocess.Popen([sys.executable, "-c", code], env=env, stdout=subprocess.PIPE, text=True)
             for _ in range(4)]
    paths = {p.communicate(timeout=300)[0].strip() for p in procs}
    assert all(p.returncode == 0 for p in procs)
    assert len(paths) == 1
    # (importing uvms_mj also builds the plugin library into the same cache)
    assert [f.name for f in tmp_path.iterdir() if f.name.startswith(("nominal", ".nominal"))] == [os.path.basename(paths.pop())]
    assert not [f for f in tmp_path.iterdir() if f.name.endswith(".tmp")]
