"""The plugin layer on the paper's planar robot against the planar closed form (an oracle).

``uvms_mj.planar.hydro.HydroModel`` is the planar closed form of the same physics (written for the
paper's chain on plain floats, independently of the plugins' generic 3-D formulation): at
random states and currents the plugins' added-mass matrix and generalized hydrodynamic force
must agree with it to 1e-10 (relative to the largest entry; both are exact formulas evaluated in
double precision, so only rounding separates them: measured about 1e-15).
"""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from uvms_mj import HydroTerms, Plant
from oracles.planar.hydro import HydroModel

from conftest import added_and_passive

TOL = 1e-10


def plugin_terms(plant: Plant, q, qd) -> tuple[np.ndarray, np.ndarray]:
    """The plant's own hydrodynamics at (q, qd) on fresh data of its model."""
    d = plant.make_data()
    d.qpos[:] = q
    d.qvel[:] = qd
    return added_and_passive(plant.model, d)


def oracle(plant: Plant, q, qd, current, terms: HydroTerms) -> tuple[np.ndarray, np.ndarray]:
    hm = HydroModel(plant.params, terms)
    madd, qfrc = hm.evaluate(list(q), list(qd), tuple(current), tuple(plant.model.opt.gravity[:2]), True)
    M = np.zeros((5, 5))
    if madd:
        M[np.tril_indices(5)] = madd
        M = M + np.tril(M, -1).T
    return M, np.asarray(qfrc)


def random_states(n: int, seed: int):
    rng = np.random.default_rng(seed)
    for _ in range(n):
        q = rng.uniform(-1, 1, 5) * [1, 1, np.pi, np.pi, np.pi]
        qd = rng.normal(0, 0.5, 5)
        yield q, qd


@pytest.mark.parametrize("backend", ["native", "python"])
@pytest.mark.parametrize("current", [(0.0, 0.0), (0.13, -0.07)])
@pytest.mark.parametrize("terms", [HydroTerms(), HydroTerms(added_mass="off"), HydroTerms(drag="off", buoyancy=False)],
                         ids=["all", "no-added-mass", "added-mass-only"])
def test_plugin_matches_planar_closed_form(backend, current, terms, native_available):
    if backend == "native" and not native_available:
        pytest.skip("the C plugins are unavailable here")
    plant = Plant(backend=backend, current=current, terms=terms)
    for q, qd in random_states(20, seed=7):
        M, Q = plugin_terms(plant, q, qd)
        M0, Q0 = oracle(plant, q, qd, current, terms)
        assert np.max(np.abs(M - M0)) <= TOL * max(1.0, np.max(np.abs(M0)))
        assert np.max(np.abs(Q - Q0)) <= TOL * max(1.0, np.max(np.abs(Q0)))


def test_overrides_reach_the_plugin():
    """Overridden added mass, drag, volume and centre of buoyancy change the plugin's physics
    exactly as the closed form with the same parameters says."""
    over = {"base.added_mass": [50.0, 9.0, 2.0], "link1.drag_coef": [0.8, 1.5], "base.volume": 0.03,
            "base.cob": [0.01, 0.02], "water_density": 1025.0}
    plant = Plant(overrides=over)
    assert plant.params.body("base").added_mass == (50.0, 9.0)
    assert plant.params.body("link1").drag_coef == pytest.approx((0.8, 1.5), rel=1e-15)
    for q, qd in random_states(5, seed=3):
        M, Q = plugin_terms(plant, q, qd)
        M0, Q0 = oracle(plant, q, qd, (0.0, 0.0), HydroTerms())
        assert np.max(np.abs(M - M0)) <= TOL * np.max(np.abs(M0))
        assert np.max(np.abs(Q - Q0)) <= TOL * np.max(np.abs(Q0))
    # and the closed form itself sees a different robot than the default one
    M1, _ = oracle(Plant(), q, qd, (0.0, 0.0), HydroTerms())
    assert not np.allclose(M1, M0)


@pytest.mark.parametrize("backend", ["native", "python"])
def test_zero_first_entry_keeps_the_whole_added_mass(backend, native_available):
    """Regression (issue "Any MJCF robot underwater"): a guard that compared only the (0, 0)
    entry of M dropped the whole added-mass matrix from the second mj_forward on when that
    added entry was exactly zero."""
    if backend == "native" and not native_available:
        pytest.skip("the C plugins are unavailable here")
    over = {"base.added_mass": [0, 0, 1.05], "link1.added_mass": [0, 0, 0.11], "link2.added_mass": [0, 0, 0.06]}
    if True:
        plant = Plant(overrides=over, backend=backend)
        q, qd = next(random_states(1, seed=11))
        M0, _ = oracle(plant, q, qd, (0.0, 0.0), HydroTerms())
        assert np.max(np.abs(M0)) > 0.05
        m, d = plant.model, plant.data
        d.qpos[:] = q
        d.qvel[:] = qd
        rigid = np.zeros((5, 5))
        mujoco.mj_fwdPosition(m, d)
        mujoco.mj_fullM(m, d, rigid)
        for _ in range(3):
            mujoco.mj_forward(m, d)
            full = np.zeros((5, 5))
            mujoco.mj_fullM(m, d, full)
            assert np.max(np.abs(full - rigid - M0)) < 1e-12
        # mj_forwardSkip re-enters the passive stage with d.M already augmented: not twice
        mujoco.mj_forwardSkip(m, d, mujoco.mjtStage.mjSTAGE_POS, 0)
        mujoco.mj_fullM(m, d, full)
        assert np.max(np.abs(full - rigid - M0)) < 1e-12
