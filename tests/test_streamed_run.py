"""A run streamed without keeping its samples (``keep=False``, what the CLI does): the same rows,
the same metrics and status as the kept run, and memory that does not grow with the duration.

Oracles: the metrics against their definitions written here on the whole arrays (numpy's RMS of
the errors; relative 1e-12: the accumulator sums blocks of 1024 samples where np.mean sums the
whole array pairwise, a difference of a few ulps); block invariance and kept-vs-streamed
equality are exact because both go through the same blocks of the same arithmetic (the same
arrays in the same order, one code path).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from uvms_mj.scenario.schema import load_scenario, run_scenario
from uvms_mj.sim.experiment import PaperExperiment
from uvms_mj.sim.metrics import BLOCK, METRIC_KEYS, RunMetrics, metrics
from uvms_mj.sim.samples import CHUNK, SampleRecord

REL = 1e-12  # block sums against numpy's pairwise sum of the whole array: a few ulps


def _same(a: dict, b: dict) -> bool:
    return set(a) == set(b) and all((math.isnan(a[k]) and math.isnan(b[k])) or a[k] == b[k] for k in a)


@pytest.fixture(scope="module")
def paper_run():
    return PaperExperiment(duration=40.0).run()  # 2401 samples: three blocks of BLOCK, the last partial


def test_paper_metrics_against_their_definitions(paper_run):
    s, T = paper_run.signals, paper_run.meta["T"]
    pd, q = s["p_desired"], s["q_true"]
    rms = lambda x: float(np.sqrt(np.mean(np.square(x))))  # noqa: E731
    base = np.hypot(pd[:, 0] - q[:, 0], pd[:, 1] - q[:, 1])
    tip = np.hypot(pd[:, 3] - s["tip_true"][:, 0], pd[:, 4] - s["tip_true"][:, 1])
    want = {"base_pos_rms_mm": 1e3 * rms(base), "base_pos_max_mm": 1e3 * base.max(),
            "base_att_rms_mrad": 1e3 * rms(pd[:, 2] - q[:, 2]),
            "base_att_max_mrad": 1e3 * np.abs(pd[:, 2] - q[:, 2]).max(),
            "tip_rms_mm": 1e3 * rms(tip), "tip_max_mm": 1e3 * tip.max(),
            "thrust_rms_N": rms(s["thrust_force"]), "torque_rms_Nm": rms(s["torques_applied"]),
            "singular_s": T * np.count_nonzero(s["singular_phase"])}
    m = metrics(paper_run)
    assert set(m) == set(METRIC_KEYS)
    for k, v in want.items():
        assert m[k] == pytest.approx(v, rel=REL, abs=1e-15), k
    assert m["saturated_s"] == 0.0 and m["joint_limit_excursion_deg"] == 0.0
    assert math.isnan(m["nav_pos_rms_mm"])


@pytest.mark.parametrize("block", [1, 7, BLOCK - 1, BLOCK, 5000])
def test_metrics_do_not_depend_on_how_the_samples_are_handed_in(paper_run, block):
    r = paper_run
    acc = RunMetrics(r.meta)
    for i in range(0, len(r.t), block):
        acc.add(r.t[i:i + block], {k: v[i:i + block] for k, v in r.signals.items()})
    assert _same(acc.result(), metrics(r))


def test_the_accumulator_copies_what_it_keeps(paper_run):
    """Blocks handed in through one reused buffer (as the streaming record does): the samples left
    pending must not change when the caller overwrites its arrays."""
    r, block = paper_run, 700  # not a divisor of BLOCK: samples stay pending between the calls
    acc = RunMetrics(r.meta)
    bufs = {k: np.empty((block,) + v.shape[1:], v.dtype) for k, v in r.signals.items()}
    tbuf = np.empty(block)
    for i in range(0, len(r.t), block):
        m = len(r.t[i:i + block])
        tbuf[:m] = r.t[i:i + block]
        for k, v in r.signals.items():
            bufs[k][:m] = v[i:i + block]
        acc.add(tbuf[:m], {k: b[:m] for k, b in bufs.items()})
    assert _same(acc.result(), metrics(r))


def test_no_samples_gives_nan_never_raises():
    m = RunMetrics({"T": 0.02}).result()
    assert set(m) == set(METRIC_KEYS) and all(math.isnan(v) for v in m.values())
    m = RunMetrics({"T": 0.02, "robot": {"layout": {"base_qpos": 0}}}).result()
    assert "joint_rms_mrad" in m and all(math.isnan(v) for v in m.values())


def _rows_and_run(sc, keep):
    rows = []
    res = run_scenario(sc, keep=keep, sink=lambda t, r: rows.append((t, {k: np.array(v, copy=True)
                                                                         for k, v in r.items()})))
    return rows, res


@pytest.mark.parametrize("name, sets", [
    ("paper", ["duration=20"]),
    ("bluerov2_alpha_payload", ["duration=12"]),  # a joint leaves its range at 10.4 s: status joint_limit
    ("bluerov2_alpha_navigation", ["duration=4", "controller.feedback=estimate"]),  # the ESKF in the loop
    ("slow_thrusters", ["duration=12"]),  # diverges at 8.2 s
])
def test_a_streamed_run_is_the_kept_run(name, sets):
    sc = load_scenario(f"scenarios/{name}.yaml", sets)
    rows_k, kept = _rows_and_run(sc, True)
    rows_s, streamed = _rows_and_run(sc, False)
    assert (streamed.status, streamed.reason) == (kept.status, kept.reason)
    assert len(rows_s) == len(rows_k) == len(kept.t) == streamed.meta["samples"]
    for (ta, a), (tb, b) in zip(rows_k, rows_s):
        assert ta == tb and a.keys() == b.keys()
        assert all(np.array_equal(a[k], b[k], equal_nan=a[k].dtype.kind == "f") for k in a)
    assert _same(metrics(streamed), metrics(kept))
    assert streamed.signals == {} and len(streamed.t) == 0 and streamed.meta["t_end"] == kept.t[-1]
    assert kept.metrics is None and streamed.metrics is not None
    if streamed.navigation is not None:  # the mounts only: no sample kept
        assert streamed.navigation.mounts and len(streamed.navigation.imu_gyro_bias) == 0
        assert len(streamed.navigation.imu) < 50 and len(kept.navigation.imu) >= 1000


def test_the_streaming_record_holds_one_chunk_at_most():
    blocks = []
    rec = SampleRecord(10 * CHUNK + 5, on_block=lambda start, m, s: blocks.append((start, m, s["x"][:, 0].copy())))
    for k in range(10 * CHUNK + 5):
        rec.append({"x": np.array([k, 2.0 * k]), "flag": k % 3 == 0})
        assert len(rec._pending) < CHUNK and all(len(b) <= CHUNK for b in rec._bufs.values())
    assert rec.signals() == {} and len(rec) == 10 * CHUNK + 5
    assert [b[:2] for b in blocks] == [(i * CHUNK, CHUNK) for i in range(10)] + [(10 * CHUNK, 5)]
    assert np.array_equal(np.concatenate([b[2] for b in blocks]), np.arange(10 * CHUNK + 5))


def test_the_streaming_record_hands_on_rows_whose_signals_change():
    got = []
    rec = SampleRecord(6, on_block=lambda start, m, s: got.append((start, m, sorted(s))))
    for k in range(6):
        rec.append({"a": 1.0 * k} if k < 3 else {"a": 1.0 * k, "b": np.zeros(2)})
    rec.signals()
    assert got == [(0, 3, ["a"]), (3, 3, ["a", "b"])]
