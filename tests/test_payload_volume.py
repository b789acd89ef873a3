"""A payload that displaces water (``plant.payload.volume``): its own ``uvms.hydro`` instance,
added at run time (uvms_mj.plant.robot.add_hydro_instance; a MuJoCo 3.17 crash avoided: see its
docstring). Independent truth: Archimedes -- the payload's buoyancy rho |g| V, at its centre,
reaches the vehicle's free joint as a vertical generalized force (the whole robot is one tree on
that joint), so the difference between volume V and volume 0 at the same state is rho |g| V.
"""

from __future__ import annotations

import textwrap

import mujoco
import numpy as np
import pytest

from uvms_mj.physics.config import read_model
from uvms_mj.scenario.schema import build, load_scenario, run_scenario


def _scenario(tmp_path, volume: float, t: float = 0.0, duration: float = 1.0):
    f = tmp_path / f"s{volume}.yaml"
    f.write_text(textwrap.dedent(f"""\
        robot: bluerov2_alpha
        duration: {duration}
        plant:
          payload: {{mass: 0.5, volume: {volume}, t: {t}}}
        controller: {{name: station_pid}}
        """))
    return load_scenario(f)


def test_the_payload_volume_adds_its_buoyancy_on_the_vehicle(tmp_path):
    """qfrc_passive on the free joint's z (world) with V = 2e-4 m^3 minus with V = 0, same state:
    rho |g| V (1.962 N for fresh water); float64 sums of a few terms: 1e-9 N."""
    V = 2e-4
    fz = {}
    for vol in (0.0, V):
        plant, _ = build(_scenario(tmp_path, vol))
        m, d = plant.model, plant.data
        mujoco.mj_forward(m, d)
        fz[vol] = float(d.qfrc_passive[plant.layout.base_dadr + 2])  # the free joint's world z
        water, _ = read_model(m)
        rho, g = water.density, float(np.linalg.norm(m.opt.gravity))
    assert fz[V] - fz[0.0] == pytest.approx(rho * g * V, abs=1e-9)


def test_a_run_with_a_displacing_payload_finishes(tmp_path):
    """The payload picked up at 0.5 s with its volume: the run ends "ok" (it crashed the
    Python process before add_hydro_instance)."""
    res = run_scenario(_scenario(tmp_path, 2e-4, t=0.5))
    assert res.status == "ok", res.reason
