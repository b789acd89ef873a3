"""Memory bounded by design (issue 23): structural properties, no timing or absolute-RSS checks.

* figures: every line keeps at most MAX_LINE_POINTS points, and the decimation keeps each
  bucket's extremes (a one-sample peak stays visible);
* the loop's record (SampleRecord): arrays of the run's final size that hold what np.asarray of
  the per-sample values gives (the definition of RunResult.signals), list semantics for rows that
  do not fit;
* read_log decodes a batch of messages at a time: with tiny batches it gives what np.asarray of
  the rows gives.

The peak RSS against duration is measured by benchmarks/bench_memory.py.
"""

from __future__ import annotations

import numpy as np
import pytest

from uvms_mj.analysis.plots import common as plot_common
from uvms_mj.analysis.plots import plot_run
from uvms_mj.analysis.plots.common import MAX_LINE_POINTS, decimate
from uvms_mj.sim.loop import RunResult
from uvms_mj.sim.samples import SampleRecord


def _buckets(n: int, max_points: int) -> list[tuple[int, int]]:
    """The buckets decimate documents: max_points // 8 runs of ceil(n / that) samples."""
    nb = max_points // 8
    size = -(-n // nb)
    return [(a, min(a + size, n)) for a in range(0, n, size)]


def test_decimation_is_bounded_and_keeps_every_bucket_extreme():
    rng = np.random.default_rng(3)
    n = 250_001
    t = np.linspace(0.0, 3600.0, n)
    y = np.cumsum(rng.normal(size=n)) * 1e-3
    spikes = rng.choice(n, 20, replace=False)
    y[spikes] += rng.choice([-50.0, 50.0], 20)  # one-sample peaks
    idx = decimate(t, y)
    assert len(idx) <= MAX_LINE_POINTS
    assert np.all(np.diff(idx) > 0) and idx[0] == 0 and idx[-1] == n - 1
    assert set(spikes) <= set(idx.tolist())
    kept = np.zeros(n, dtype=bool)
    kept[idx] = True
    for a, b in _buckets(n, MAX_LINE_POINTS):
        seg, k = y[a:b], kept[a:b]
        assert seg[k].min() == seg.min() and seg[k].max() == seg.max()
    # a short line is kept whole
    assert np.array_equal(decimate(t[:100], y[:100]), np.arange(100))


def test_decimation_keeps_a_paths_extent_and_its_gaps():
    n = 100_000
    s = np.linspace(0.0, 6.0 * np.pi, n)
    x, y = np.cos(s) * (1 + s), np.sin(s) * (1 + s)  # a spiral: x is not monotone
    y[40_000:40_010] = np.nan
    idx = decimate(x, y, max_points=800)
    assert len(idx) <= 800
    assert x[idx].max() == x.max() and x[idx].min() == x.min()
    assert np.nanmax(y[idx]) == np.nanmax(y) and np.nanmin(y[idx]) == np.nanmin(y)
    assert np.isnan(y[idx]).any()  # the gap is still drawn as a gap
    with pytest.raises(ValueError, match="max_points"):
        decimate(x, y, max_points=3)


def _long_paper_log(n: int) -> RunResult:
    T = 1.0 / 60.0
    t = np.arange(n) * T
    q = np.zeros((n, 5))
    q[:, 0] = 1e-3 * np.sin(0.01 * t)
    q[n // 2, 1] = 0.05  # a one-sample peak in the base y error
    pd = np.zeros((n, 5))
    pd[:, 3:5] = 0.5
    signals = {"p_desired": pd, "q_true": q, "tip_true": np.full((n, 2), 0.5),
               "thrust_command": np.ones((n, 3)), "thrust_force": np.ones((n, 3)), "torques": np.zeros((n, 2)),
               "det_B": np.full(n, 0.05), "singular_phase": np.zeros(n, dtype=int)}
    return RunResult(t=t, signals=signals, meta={"T": T, "controller": "rac_dob"})


def test_plot_lines_are_bounded_for_a_long_run(tmp_path, monkeypatch):
    figures = []
    monkeypatch.setattr(plot_common._DecimatingFigure, "savefig",
                        lambda self, path, **kw: figures.append(self), raising=False)
    log = _long_paper_log(100_001)  # 1667 s at 60 Hz: 12 times MAX_LINE_POINTS
    plot_run(log, tmp_path, stem="long")
    assert len(figures) == 2
    lines = [ln for fig in figures for ax in fig.axes for ln in ax.get_lines()]
    assert any(len(ln.get_xdata()) > 1000 for ln in lines)  # the time histories are there
    assert all(len(ln.get_xdata()) <= MAX_LINE_POINTS for ln in lines)
    peak = max(float(np.nanmax(np.abs(np.asarray(ln.get_ydata(), dtype=float)))) for ln in lines
               if len(ln.get_ydata()) > 1000 and "y" in str(ln.get_label()).lower())
    assert peak == pytest.approx(50.0)  # the one-sample 0.05 m = 50 mm peak in y, drawn


def _rows() -> list[dict]:
    rows = []
    for k in range(23):
        rows.append({"x": np.array([k, 0.5 * k]), "count": k if k < 10 else k + 0.5, "flag": k % 3 == 0,
                     "mask": np.array([k % 2 == 0, True]), "f32": np.array([k], dtype=np.float32),
                     "mat": np.arange(6.0).reshape(2, 3) * k, "s": np.float64(k) / 3})
    return rows


def _stacked(rows: list[dict]) -> dict:
    return {key: np.asarray([row[key] for row in rows]) for key in rows[0]}


def _same(got: dict, want: dict) -> None:
    assert list(got) == list(want)
    for key, a in want.items():
        b = got[key]
        assert (b.dtype, b.shape) == (a.dtype, a.shape), key
        assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), key


@pytest.fixture(params=[1024, 4], ids=["one-chunk", "chunks-of-4"])
def chunk(request, monkeypatch):
    """SampleRecord's chunk: the run's default, and 4 rows (promotion across chunks: "count" is
    int in the first chunks and float later; a ragged value in a later chunk)."""
    from uvms_mj.sim import samples

    monkeypatch.setattr(samples, "CHUNK", request.param)
    return request.param


def test_sample_record_gives_what_asarray_of_the_rows_gives(chunk):
    rows = _rows()
    rec = SampleRecord(len(rows))
    for row in rows:
        rec.append(row)
    got = rec.signals()
    _same(got, _stacked(rows))  # "count": ints, then floats -> float64 with the ints exact
    assert all(v.base is None or v.base.shape[0] == len(rows) for v in got.values())
    # a run stopped early: arrays of the rows appended, not of the planned size
    rec = SampleRecord(100)
    for row in rows[:5]:
        rec.append(row)
    short = rec.signals()
    _same(short, _stacked(rows[:5]))
    assert all(v.base is None for v in short.values())  # copies, not views of the 100-row arrays
    with pytest.raises(IndexError):
        full = SampleRecord(1)
        full.append(rows[0])
        full.append(rows[1])


def test_sample_record_rows_that_do_not_fit_keep_the_list_semantics(chunk):
    ragged = _rows()
    ragged[13] = {**ragged[13], "x": np.array([1.0, 2.0, 3.0])}  # another shape: stacked as before (an error)
    rec = SampleRecord(len(ragged))
    for row in ragged:
        rec.append(row)
    with pytest.raises(ValueError):
        np.asarray([row["x"] for row in ragged])
    with pytest.raises(ValueError):
        rec.signals()
    rows = _rows()
    rows[7] = {k: v for k, v in rows[7].items() if k != "flag"}  # a signal missing in one row
    rows[9] = {**rows[9], "late": 1.0}  # one that appears later
    rec = SampleRecord(len(rows))
    for row in rows:
        rec.append(row)
    got = rec.signals()
    keys = dict.fromkeys(k for row in rows for k in row)
    want = {k: np.asarray([row[k] for row in rows if k in row]) for k in keys}
    _same(got, want)
    assert len(got["flag"]) == len(rows) - 1 and len(got["late"]) == 1


def test_read_log_in_small_batches_gives_the_rows(tmp_path, monkeypatch):
    from oracles.planar.nominal import params_from_file
    from uvms_mj.io import reader
    from uvms_mj.io.recorder import McapRecorder

    rows = []
    for k in range(40):
        rows.append({"a": np.array([k, np.nan if k % 11 == 0 else 1.5 * k, np.inf]), "n": k % 4, "b": k % 2 == 0,
                     "m": np.arange(4.0).reshape(2, 2) + k, "q_true": np.full(5, 0.1 * k)})
    path = tmp_path / "b.mcap"
    with McapRecorder(path, params_from_file(), {}) as rec:
        for k, row in enumerate(rows):
            rec.write_sample(k * 0.01, row)
    monkeypatch.setattr(reader, "_BATCH", 3)  # 14 batches, one with a NaN and others without
    log = reader.read_log(path)
    _same(log.signals, _stacked(rows))
    assert np.array_equal(log.t, np.arange(40) * 0.01)
