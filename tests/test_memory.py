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


# --- the read side: subsets, blocks, streaming exports and info (issue 23 item 1) -------------------------------


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    """A short paper log and a short BlueROV2 + Alpha log (uvms-mj run), and a copy of each cut
    inside its data (as kill -9 leaves one)."""
    from conftest import run_logs

    folder = tmp_path_factory.mktemp("memlogs")
    out = run_logs(folder, (("paper", "paper", "3"), ("robot", "bluerov2_alpha_station", "1.5")))
    for name in ("paper", "robot"):
        out[name + "-cut"] = _cut_copy(out[name], folder / f"{name}-cut.mcap")
    return out


def _cut_copy(path, cut):
    """The samples of ``path`` rewritten one flush per sample (many chunks), cut at 60 % of the file."""
    from oracles.planar.nominal import params_from_file
    from uvms_mj.io.reader import read_log
    from uvms_mj.io.recorder import McapRecorder

    log = read_log(path)
    whole = cut.with_suffix(".whole")
    with McapRecorder(whole, params_from_file(), {}, flush_interval=0.0) as rec:
        for k, t in enumerate(log.t):
            rec.write_sample(t, {name: v[k] for name, v in log.signals.items()})
    data = whole.read_bytes()
    cut.write_bytes(data[: int(len(data) * 0.6)])
    return cut


def test_read_log_with_a_signal_subset_reads_only_those(logs):
    from uvms_mj.io.reader import read_log

    full = read_log(logs["robot"])
    sub = read_log(logs["robot"], signals=["tip_true", "q_true", "no_such_signal"])
    assert list(sub.signals) == ["q_true", "tip_true"]  # the log's order; an unknown name is absent
    np.testing.assert_array_equal(sub.t, full.t)
    for name in sub.signals:
        assert sub.signals[name].dtype == full.signals[name].dtype
        np.testing.assert_array_equal(sub.signals[name], full.signals[name])
    assert sub.status == full.status and sub.meta == full.meta
    assert list(read_log(logs["paper"], signals="q_true").signals) == ["q_true"]
    with pytest.raises(TypeError, match="signal name"):
        read_log(logs["paper"], signals=[3])


def test_a_subset_read_decodes_no_other_signal(logs, monkeypatch):
    from uvms_mj.io import reader

    seen = set()
    real = reader._Columns.__init__

    def spy(self, layout, wanted=None):
        real(self, layout, wanted)
        seen.update(self._names)

    monkeypatch.setattr(reader._Columns, "__init__", spy)
    reader.read_log(logs["paper"], signals=["q_true", "thrust_force"])
    assert seen == {"q_true", "thrust_force"}


@pytest.mark.parametrize("which", ["paper", "robot", "paper-cut", "robot-cut"])
def test_iter_samples_blocks_are_read_log_cut_into_pieces(logs, which):
    from uvms_mj.io.reader import LogStream, iter_samples, read_log

    full = read_log(logs[which])
    stream = LogStream()
    chunk = 7
    blocks = list(iter_samples(logs[which], chunk=chunk, stream=stream))
    assert len(full.t) > 3 * chunk
    assert all(0 < len(b.t) <= chunk for b in blocks) and sum(len(b.t) for b in blocks) == len(full.t)
    np.testing.assert_array_equal(np.concatenate([b.t for b in blocks]), full.t)
    for name, want in full.signals.items():
        got = np.concatenate([b.signals[name] for b in blocks])
        assert (got.dtype, got.shape) == (want.dtype, want.shape), name
        np.testing.assert_array_equal(got, want)
    assert list(stream.layout) == list(full.signals)
    assert (stream.status, stream.reason, stream.truncated) == (full.status, full.reason, full.truncated)
    assert stream.meta == full.meta and stream.samples == len(full.t)
    # memory: the samples held at once (assembled, or waiting for their other channel's message)
    assert stream.max_in_flight <= chunk + 2


def test_iter_samples_drops_a_sample_missing_from_one_channel_and_stays_bounded(tmp_path):
    """A sample whose /control message is missing (never completed) is dropped and not kept: the
    in-flight count stays bounded however many such samples there are."""
    from oracles.planar.nominal import params_from_file
    from uvms_mj.io import reader
    from uvms_mj.io.recorder import McapRecorder

    path = tmp_path / "gap.mcap"
    with McapRecorder(path, params_from_file(), {}) as rec:
        for k in range(60):
            rec.write_sample(k * 0.01, {"q_true": np.full(5, 0.1 * k), "u": np.array([float(k)])})
    # drop every 3rd sample's /control message by renumbering: read the messages and filter
    st = reader.LogStream()
    real_iter = reader._iter_records

    def without_some(p, state):
        control = None
        for r in real_iter(p, state):
            if isinstance(r, reader.Channel) and r.topic == "/control":
                control = r.id
            if isinstance(r, reader.Message) and r.channel_id == control and r.sequence % 3 == 0:
                continue
            yield r

    reader._iter_records = without_some
    try:
        got = list(reader.iter_samples(path, chunk=4, stream=st))
        full = reader.read_log(path)
    finally:
        reader._iter_records = real_iter
    kept = np.concatenate([b.t for b in got])
    np.testing.assert_array_equal(kept, full.t)
    assert len(kept) == 40 and not np.any(np.isclose(kept % 0.03, 0.0))
    assert st.max_in_flight <= 4 + 2


def test_log_info_decodes_no_message_and_counts_the_complete_samples(logs, monkeypatch):
    from uvms_mj.io import reader

    n = {k: len(reader.read_log(logs[k]).t) for k in logs}
    monkeypatch.setattr(reader, "_Columns", None)  # no sample decoded, no read_log
    monkeypatch.setattr(reader.json, "loads", _no_message_json(reader.json.loads))
    for k, path in logs.items():
        info = reader.log_info(path)
        assert info["samples"] == n[k]
        assert info["truncated"] == k.endswith("-cut")


def _no_message_json(loads):
    def guarded(s, *a, **kw):
        assert not str(s[:30]).lstrip("b'").startswith('{"timestamp"'), "a message was decoded"
        return loads(s, *a, **kw)
    return guarded


@pytest.mark.parametrize("fmt", ["csv", "npz", "parquet", "mat"])
def test_export_from_a_path_is_written_block_by_block(logs, tmp_path, monkeypatch, fmt):
    """The export reads the log by blocks (never read_log) and hands each writer at most one
    block at a time; what it writes is what the in-memory export of read_log writes."""
    if fmt == "parquet":
        pytest.importorskip("pyarrow")
    if fmt == "mat":
        pytest.importorskip("scipy")
    from uvms_mj.io import export, reader

    full = reader.read_log(logs["robot"])
    want = export.export_log(full, fmt, tmp_path / f"want.{fmt}")[0]
    rows = []
    for cls in (export._CsvTable, export._ParquetTable, export._Spool):
        real = cls.add

        def spy(self, *args, real=real):
            rows.append(len(args[-1] if isinstance(args[-1], np.ndarray) else args[-1]["t"]))
            return real(self, *args)

        monkeypatch.setattr(cls, "add", spy)
    monkeypatch.setattr(reader, "read_log", None)
    got = export.export_log(logs["robot"], fmt, tmp_path / f"got.{fmt}", chunk=5)[0]
    assert rows and max(rows) <= 5 and len(full.t) > 10
    _same_export(fmt, want, got)


def _same_export(fmt, a, b):
    if fmt == "csv":
        assert a.read_text() == b.read_text()
    elif fmt == "npz":
        x, y = np.load(a), np.load(b)
        assert x.files == y.files
        for k in x.files:
            assert x[k].dtype == y[k].dtype and x[k].shape == y[k].shape, k
            np.testing.assert_array_equal(x[k], y[k])
    elif fmt == "parquet":
        import pyarrow.parquet as pq

        x, y = pq.read_table(a), pq.read_table(b)
        assert x.equals(y) and x.schema.metadata == y.schema.metadata
    else:
        import scipy.io

        x, y = scipy.io.loadmat(a), scipy.io.loadmat(b)
        for k in (k for k in x if not k.startswith("__")):
            np.testing.assert_array_equal(x[k], y[k])


def test_export_spools_the_arrays_out_of_memory(logs, tmp_path):
    """npz: each array is gathered in a raw file (bytes on disk, not in a list of arrays) and
    streamed into its zip member: the file loads as np.load of np.savez_compressed would."""
    from uvms_mj.io import export

    spool = export._Spool(tmp_path)
    blocks = [np.arange(12.0).reshape(4, 3) + 12 * k for k in range(3)]
    for b in blocks:
        spool.add("x", b)
    spool.add("flag", np.array([True, False]))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["0.raw", "1.raw"]
    spool._arrays["x"][0].flush()
    assert (tmp_path / "0.raw").stat().st_size == 12 * 3 * 8  # on disk, as raw float64 rows
    np.testing.assert_array_equal(spool.load("x"), np.concatenate(blocks))
    with pytest.raises(ValueError, match="rows of shape"):
        spool.add("x", np.zeros((1, 2)))
    export._write_npz(spool, {"meta_json": "{}"}, tmp_path / "s.npz")
    spool.close()
    z = np.load(tmp_path / "s.npz")
    assert z.files == ["meta_json", "x", "flag"]
    np.testing.assert_array_equal(z["x"], np.concatenate(blocks))
    assert z["flag"].dtype == bool and str(z["meta_json"]) == "{}"


class _Spy(dict):
    """A signals dict that notes every name asked of it."""

    def __init__(self, *a):
        super().__init__(*a)
        self.asked = set()

    def __contains__(self, k):
        self.asked.add(k)
        return super().__contains__(k)

    def __getitem__(self, k):
        self.asked.add(k)
        return super().__getitem__(k)

    def get(self, k, default=None):
        self.asked.add(k)
        return super().get(k, default)


@pytest.mark.slow
@pytest.mark.parametrize("which", ["paper", "robot"])
def test_the_plot_signal_lists_cover_what_the_figures_read(logs, tmp_path, which):
    from uvms_mj.analysis.plots import COMPARE_SIGNALS, PLOT_SIGNALS, plot_comparison, plot_run
    from uvms_mj.io.reader import read_log

    log = read_log(logs[which])
    log.signals = _Spy(log.signals)
    plot_run(log, tmp_path, stem="spy")
    assert log.signals.asked and log.signals.asked <= set(PLOT_SIGNALS), log.signals.asked - set(PLOT_SIGNALS)
    log.signals = _Spy(log.signals)
    plot_comparison({"a": log}, tmp_path / "c.png")
    assert log.signals.asked and log.signals.asked <= set(COMPARE_SIGNALS)


def test_plot_and_render_commands_read_a_subset(logs, tmp_path, monkeypatch):
    from click.testing import CliRunner

    from uvms_mj.analysis import plots, render
    from uvms_mj.analysis.render_stream import RENDER_SIGNALS
    from uvms_mj.cli.main import main

    got = {}
    monkeypatch.setattr(plots, "plot_run", lambda log, folder, stem: got.setdefault("plot", set(log.signals)) and [])
    result = CliRunner().invoke(main, ["plot", str(logs["robot"]), "--out-dir", str(tmp_path)])
    assert result.exit_code == 0, result.output
    assert got["plot"] and got["plot"] <= set(plots.PLOT_SIGNALS)

    def fake_video(log, path, **kw):
        got["render"] = set(log.signals)
        return {"frames": 0}

    monkeypatch.setattr(render, "render_video", fake_video)
    result = CliRunner().invoke(main, ["render", str(logs["robot"]), "-o", str(tmp_path / "v.mp4")])
    assert result.exit_code == 0, result.output
    assert got["render"] and got["render"] <= set(RENDER_SIGNALS) and "q_true" in got["render"]


@pytest.mark.parametrize("which", ["paper", "robot"])
def test_compare_figure_from_paths_keeps_only_the_error_columns(logs, tmp_path, which):
    """plot_comparison given paths reads each log itself, keeping the few columns its errors need,
    and draws the figure the logs read in full give (the same PNG bytes: the same data drawn)."""
    from uvms_mj.analysis import plots
    from uvms_mj.io.reader import read_log

    slim = plots._slim(str(logs[which]))
    full = read_log(logs[which])
    assert slim.signals["q_true"].shape[1] == (7 if which == "robot" else 3)
    assert set(slim.signals) <= set(plots.COMPARE_SIGNALS) and len(slim.signals) <= 4
    a = plots.plot_comparison({"x": full, "y": full}, tmp_path / "a.png")
    b = plots.plot_comparison({"x": str(logs[which]), "y": logs[which]}, tmp_path / "b.png")
    assert a.read_bytes() == b.read_bytes()
