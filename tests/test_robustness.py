"""The robustness sweep's hardest corner (scenarios/bluerov2_alpha_robustness.yaml; issue 19,
item 6; the README's "Robustness" tables): a 0.3 m/s side current, a one-sample measurement
delay, 1 mm / 0.5 deg camera noise and the nominal hull hydrodynamics (added mass, linear and
quadratic damping) at 0.7 of the model file's -- the sample of the sweep with the largest errors
of every controller.

Independent truths: the vehicle's station is its initial position (the scenario sets no
setpoint), so the base error is computed here from the true trajectory alone; "no divergence" is
the run's status.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from uvms_mj.scenario.schema import load_scenario, run_scenario
from uvms_mj.sim.experiment import metrics
from uvms_mj.sim.loop import RunResult

STUDY = Path(__file__).resolve().parents[1] / "scenarios" / "bluerov2_alpha_robustness.yaml"
#: The sweep's draw for this sample (logs/robustness/results.csv, sample 33): the noise streams.
SEED = 571002945
CORNER = [f"seed={SEED}", "current.velocity=[0.0, 0.3, 0.0]", "sensors.delay=1",
          "sensors.position_noise=0.001", "sensors.attitude_noise=0.0087266",
          'nominal.overrides.bluerov2_hull.added_mass="x0.7"',
          'nominal.overrides.bluerov2_hull.linear_damping="x0.7"',
          'nominal.overrides.bluerov2_hull.quadratic_damping="x0.7"']


def _base_rms(name: str) -> float:
    res = run_scenario(load_scenario(STUDY, [f"controller.name={name}", *CORNER]))
    assert res.status == "ok", f"{name}: {res.reason}"
    p = np.asarray(res.signals["q_true"])[:, :3]
    return float(np.sqrt(np.mean(np.sum((p - p[0]) ** 2, axis=1))))


@pytest.mark.slow
def test_the_hardest_corner_diverges_nowhere_and_the_observer_halves_the_base_error():
    """All four controllers end "ok" (before issue 19's gains and limits, task_priority, rac and
    rac_dob diverged here); rac_dob's base displacement RMS from its start below 0.75 x rac's
    (measured: 16.3 / 31.8 mm = 0.513; the sweep's metric against each controller's own base
    reference, 16.9 / 34.2 mm; 0.75 leaves room for the noise draw's effect, which moves the
    ratio by a few per cent across seeds) and below station_pid's (measured 369 mm)."""
    rms = {name: _base_rms(name) for name in ("station_pid", "task_priority", "rac", "rac_dob")}
    assert rms["rac_dob"] < 0.75 * rms["rac"], rms
    assert rms["rac_dob"] < rms["station_pid"], rms


def test_singular_s_counts_the_samples_of_the_singular_phase():
    """``singular_s`` = (samples with singular_phase 1 or 2) x T: 3 of 10 samples at T = 0.02 s
    give 0.06 s; a controller without Eq. 12 (no signal) gives NaN."""
    t = np.arange(10) * 0.02
    ph = np.array([0, 0, 1, 1, 2, 0, 0, 0, 0, 0])
    res = RunResult(t=t, signals={"singular_phase": ph}, status="ok", reason="", meta={"T": 0.02})
    assert metrics(res)["singular_s"] == pytest.approx(0.06, rel=1e-12)
    res = RunResult(t=t, signals={}, status="ok", reason="", meta={"T": 0.02})
    assert np.isnan(metrics(res)["singular_s"])
