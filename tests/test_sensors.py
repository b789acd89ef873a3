"""Per-signal sensors (uvms_mj.sim.sensors; the scenario's sensors.position / attitude / joints /
velocity sections): delay, rate (zero-order hold), bias, quantization and noise.

Independent truths: the signal definitions themselves on synthetic states (the measured value
at sample k is the true value of sample r - delay, r the last refresh, plus the bias,
quantized), the rotation angle between the true and a biased quaternion (|b|), and the sample
standard deviation of the noise (sigma within 4 standard errors)."""

from __future__ import annotations

import math
import textwrap

import numpy as np
import pytest

from uvms_mj.plant.plant import Plant
from uvms_mj.scenario.schema import ScenarioError, load_scenario, run_scenario
from uvms_mj.sim.sensors import Signal, SignalSensors


def _feed(sensors: SignalSensors, states: list) -> list:
    return [sensors.measure(k, q, qd) for k, (q, qd) in enumerate(states)]


def test_delay_rate_bias_quantum_on_the_paper_robot():
    lay = Plant().layout
    states = [(np.array([0.01 * k, -0.02 * k, 0.001 * k, 0.1 + 0.003 * k, -0.2]), np.full(5, 0.5 * k))
              for k in range(30)]
    s = SignalSensors({"position": Signal(bias=[0.1, -0.2], delay=2, rate=20.0),
                       "joints": Signal(quantum=0.01), "velocity": Signal(delay_s=1 / 60)}, T=1 / 60, seed=0,
                      layout=lay)
    out = _feed(s, states)
    for k, (q, qd) in enumerate(out):
        r = (k // 3) * 3  # 20 Hz at 60 Hz: every 3 samples
        j = max(0, r - 2)
        np.testing.assert_allclose(q[:2], states[j][0][:2] + [0.1, -0.2], rtol=0, atol=1e-15)
        assert q[2] == states[k][0][2]  # attitude not configured: exact, at once
        np.testing.assert_allclose(q[3:], np.round(states[k][0][3:] / 0.01) * 0.01, rtol=0, atol=1e-15)
        np.testing.assert_array_equal(qd, states[max(0, k - 1)][1])


def test_free_vehicle_attitude_bias_and_noise_statistics():
    lay = Plant("bluerov2_heavy").layout
    q0 = Plant("bluerov2_heavy").q
    b = np.array([0.02, -0.01, 0.03])
    s = SignalSensors({"attitude": Signal(bias=b), "position": Signal(noise=0.002)}, T=0.02, seed=3, layout=lay)
    n = 4000
    out = _feed(s, [(q0, np.zeros(6))] * n)
    qa = np.array([q[3:7] for q, _ in out])
    # the angle between the true (identity) and the measured orientation is |b|
    ang = 2 * np.arccos(np.clip(np.abs(qa[:, 0]), 0, 1))
    np.testing.assert_allclose(ang, np.linalg.norm(b), rtol=1e-12)
    e = np.array([q[:3] for q, _ in out]) - q0[:3]
    assert np.all(np.abs(e.std(axis=0) - 0.002) < 4 * 0.002 / math.sqrt(2 * n))
    assert np.all(np.abs(e.mean(axis=0)) < 4 * 0.002 / math.sqrt(n))


def test_scenario_sections_reach_the_measurement(tmp_path):
    """From the schema alone, on the paper's robot: the logged measurement is the true state
    delayed (2 samples) and biased, at the configured rate."""
    f = tmp_path / "s.yaml"
    f.write_text(textwrap.dedent("""
        duration: 2
        controller: {name: rac_dob, params: {gamma: 0.15, lam: 0.15}}
        sensors:
          position: {bias: [0.001, 0.0], delay: 2}
          attitude: {rate: 30}
    """))
    res = run_scenario(load_scenario(f))
    assert res.status == "ok"
    qt, qm = res.signals["q_true"], res.signals["q_measured"]
    np.testing.assert_allclose(qm[2:, :2], qt[:-2, :2] + [0.001, 0.0], rtol=0, atol=1e-15)
    np.testing.assert_array_equal(qm[1::2, 2], qt[0:-1:2, 2])  # 30 Hz at 60 Hz: held for 2 samples


def test_sensor_sections_errors(tmp_path):
    f = tmp_path / "s.yaml"
    f.write_text("sensors: {position: {rate: 25}}\n")
    with pytest.raises(ScenarioError, match=r"sensors\.position\.rate: its period must be a whole number of control "
                                            r"periods"):
        load_scenario(f)
    f.write_text("sensors: {position_noise: 0.001, joints: {noise: 0.001}}\n")
    with pytest.raises(ScenarioError, match=r"sensors\.position_noise: give either the per-signal sections"):
        load_scenario(f)
    f.write_text("robot: bluerov2_heavy\nsensors: {velocity: {delay: 1, delay_s: 0.02}}\n")
    with pytest.raises(ScenarioError, match=r"sensors\.velocity: give the delay in samples \(delay\) or in seconds"):
        load_scenario(f)
