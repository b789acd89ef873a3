"""The BlueROV2 Heavy as its source simulates it (issue 20, item 3): von Benzon et al. 2022's
gravity (9.82 m/s^2 in their simulator) and their thrusters (a static map from input to thrust:
no dynamics) are available beside our defaults (9.81 m/s^2, a first-order lag of 0.05 s):
``physics.gravity: [0, 0, -9.82]`` and ``thrusters.tau: 0``
(models/bluerov2_heavy/README.md "As the source simulates it").

Independent truths: Archimedes with the published m = 13.5 kg, V = 0.0134 m^3, rho = 1000 kg/m^3
(net vertical force (rho V - m) g), and [vB]'s T200 curve F(V) = -140.3 V^9 + 389.9 V^7 -
404.1 V^5 + 176.0 V^3 + 8.9 V [N] evaluated here.
"""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from uvms_mj.scenario.base import ScenarioError
from uvms_mj.scenario.schema import build, load_scenario

STUDY = "scenarios/bluerov2_heavy_current.yaml"
VB_M, VB_V, RHO = 13.5, 0.0134, 1000.0


def _t200(v: float) -> float:
    return -140.3 * v**9 + 389.9 * v**7 - 404.1 * v**5 + 176.0 * v**3 + 8.9 * v


def _plant(sets):
    plant, _ = build(load_scenario(STUDY, ["plant.current=[0, 0, 0]", *sets]))
    return plant


def test_the_source_gravity_gives_the_source_net_force():
    """At rest, the vertical generalized force on the free joint: (rho V - m) g with g = 9.82
    (-0.982 N) against 9.81 by default (-0.981 N); float64 sums: 1e-9 N."""
    for sets, g in (([], 9.81), (["physics.gravity=[0, 0, -9.82]"], 9.82)):
        plant = _plant(sets)
        m, d = plant.model, mujoco.MjData(plant.model)
        mujoco.mj_forward(m, d)
        a = plant.layout.base_dadr
        f = d.qfrc_passive[a:a + 3] - d.qfrc_bias[a:a + 3]
        np.testing.assert_allclose(f, [0.0, 0.0, (RHO * VB_V - VB_M) * g], rtol=0, atol=1e-9)


def test_the_source_thrusters_are_static():
    """thrusters.tau = 0: no actuator state, and the force of every thruster equals [vB]'s curve
    at its input from the first step (with the default lag it is 1 - exp(-dt/tau) of it)."""
    plant = _plant(["thrusters.tau=0"])
    m, d = plant.model, mujoco.MjData(plant.model)
    assert m.na == 0
    u = np.array([0.9, -0.6, 0.3, -0.1, 0.5, -0.8, 0.2, 0.7])
    d.ctrl[: u.size] = u
    mujoco.mj_step(m, d)
    np.testing.assert_allclose(d.actuator_force[: u.size], [_t200(v) for v in u], rtol=1e-12, atol=1e-12)
    lagged = _plant([])
    assert lagged.model.na == 8  # the default: one lag state per thruster


def test_bad_gravity_names_the_field():
    with pytest.raises(ScenarioError, match=r"physics\.gravity"):
        load_scenario(STUDY, ["physics.gravity=[0, 0]"])
    with pytest.raises(ScenarioError, match=r"physics\.gravity\[2\]"):
        load_scenario(STUDY, ["physics.gravity=[0, 0, 1000]"])
