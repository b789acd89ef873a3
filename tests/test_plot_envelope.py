"""The figures' reader in bounded memory (issue 23 item 1): uvms_mj.analysis.envelope.

Oracles: the log read whole (read_log) and numpy on its whole arrays: each bucket's minimum and
maximum of every plotted column (signals, tracking errors, their norms), the errors' RMS and
maxima. No timing and no absolute memory figures (benchmarks/bench_memory.py measures those).
"""

from __future__ import annotations

import numpy as np
import pytest

from uvms_mj.analysis.plots import PLOT_SIGNALS, plot_run, read_plot_log, robot_errors, tracking_errors
from uvms_mj.analysis.plots import common as plot_common
from uvms_mj.analysis.series import ErrorSums
from uvms_mj.analysis.envelope import _Envelope


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    """A 20 s paper log (1201 samples) and a 6 s BlueROV2 + Alpha log (301 samples)."""
    from conftest import run_logs

    return run_logs(tmp_path_factory.mktemp("envlogs"),
                    (("paper", "paper", "20"), ("robot", "bluerov2_alpha_station", "6")))


def _errors(which, log):
    return (robot_errors if which == "robot" else tracking_errors)(log)


def _plotted_columns(which, log) -> list[np.ndarray]:
    """Every column the envelope promises to keep the extremes of: the signals', the errors', the norms."""
    n = len(log.t)
    errs = _errors(which, log)
    cols = [np.asarray(v).reshape(n, -1).astype(float) for v in list(log.signals.values()) + list(errs.values())]
    cols += [np.linalg.norm(np.asarray(e, dtype=float).reshape(n, -1), axis=1)[:, None] for e in errs.values()]
    return [c[:, j] for c in cols for j in range(c.shape[1])]


def _stats_oracle(e: np.ndarray) -> tuple[list, list, float, float]:
    e = np.asarray(e, dtype=float).reshape(len(e), -1)
    rms = [float(np.sqrt(np.mean(c[np.isfinite(c)] ** 2))) for c in e.T]
    absmax = [float(np.max(np.abs(c[np.isfinite(c)]))) for c in e.T]
    norm = np.linalg.norm(e, axis=1)
    norm = norm[np.isfinite(norm)]
    return rms, absmax, float(np.sqrt(np.mean(norm ** 2))), float(np.max(norm))


@pytest.mark.parametrize("which", ["paper", "robot"])
def test_a_short_log_is_read_whole(logs, which):
    from uvms_mj.io.reader import read_log

    full = read_log(logs[which], signals=PLOT_SIGNALS)
    got = read_plot_log(logs[which])
    assert got.bucket == 1 and got.samples == len(full.t) > 300
    assert np.array_equal(got.t, full.t)
    assert list(got.signals) == list(full.signals)
    for name, a in full.signals.items():  # the same decoded values: no arithmetic on them
        assert got.signals[name].dtype == a.dtype and np.array_equal(got.signals[name], a, equal_nan=True), name
    assert got.meta == full.meta and (got.status, got.reason) == (full.status, full.reason)


@pytest.mark.parametrize("which", ["paper", "robot"])
@pytest.mark.parametrize("rows, buckets", [(200, 40), (64, 8), (300, 16), (10 ** 6, 1000)])
def test_a_thinned_log_keeps_every_buckets_extremes(logs, which, rows, buckets):
    """Against the whole log: the kept samples are samples of the log (the first and the last among
    them); over every bucket of the reported size each plotted column has the log's minimum and
    maximum; at most ``buckets`` buckets and at most max(rows, 2 + 3 C) samples."""
    from uvms_mj.io.reader import read_log

    full = read_log(logs[which], signals=PLOT_SIGNALS)
    got = read_plot_log(logs[which], rows=rows, buckets=buckets)
    n = len(full.t)
    assert got.samples == n
    idx = np.searchsorted(full.t, got.t)
    assert np.array_equal(full.t[idx], got.t) and idx[0] == 0 and idx[-1] == n - 1
    for name, a in full.signals.items():
        assert np.array_equal(got.signals[name], a[idx], equal_nan=True), name
    size = got.bucket
    cols_full, cols_kept = _plotted_columns(which, full), _plotted_columns(which, got)
    assert len(cols_full) == len(cols_kept) > 20
    if n <= rows:  # a short log: kept whole
        assert size == 1 and len(got.t) == n
    else:
        assert size > 1 and len(got.t) < n and -(-n // size) <= buckets
    assert len(got.t) <= max(rows, 2 + 3 * len(cols_full))
    starts = np.arange(0, n, size)
    kept_bucket = idx // size
    for k, (cf, ck) in enumerate(zip(cols_full, cols_kept)):
        for b, a in enumerate(starts):
            part, mine = cf[a:a + size], ck[kept_bucket == b]
            assert len(mine) >= 2 or len(part) == 1
            if np.isnan(part).all():
                assert np.isnan(mine).all(), (k, b)
                continue
            assert np.nanmin(mine) == np.nanmin(part) and np.nanmax(mine) == np.nanmax(part), (k, b)
            assert np.isnan(mine).any() == np.isnan(part).any(), (k, b)  # a gap stays a gap


@pytest.mark.parametrize("which", ["paper", "robot"])
def test_the_statistics_are_the_whole_logs(logs, which, tmp_path, monkeypatch):
    """The RMS and maxima a thinned log carries are numpy's on the whole arrays (1e-12: the sums are
    added block by block), and the figures drawn from it print the labels the whole log gives."""
    from uvms_mj.io.reader import read_log

    full = read_log(logs[which], signals=PLOT_SIGNALS)
    got = read_plot_log(logs[which], rows=200, buckets=20)
    assert got.bucket > 1
    errs = _errors(which, full)
    assert set(got.error_stats) == set(errs) and errs
    for key, e in errs.items():
        rms, absmax, norm_rms, norm_max = _stats_oracle(e)
        s = got.error_stats[key]
        assert s.rms == pytest.approx(rms, rel=1e-12) and s.norm_rms == pytest.approx(norm_rms, rel=1e-12)
        assert list(s.absmax) == absmax and s.norm_max == norm_max  # maxima: exact
    figures = []
    monkeypatch.setattr(plot_common._DecimatingFigure, "savefig", lambda self, path, **kw: figures.append(self),
                        raising=False)

    def labels(log):
        figures.clear()
        plot_run(log, tmp_path)
        return sorted(str(ln.get_label()) for fig in figures for ax in fig.axes for ln in ax.get_lines()
                      if "rms" in str(ln.get_label()) or "max" in str(ln.get_label()))

    want = labels(full)
    assert want and labels(got) == want


def test_error_sums_are_the_arrays_statistics():
    """ErrorSums over blocks against numpy on the whole arrays, NaN rows skipped, 1-D errors as one column."""
    rng = np.random.default_rng(3)
    e = rng.normal(size=(1000, 3))
    e[[5, 600], 1] = np.nan
    att = rng.normal(size=1000)
    sums = ErrorSums()
    for a in range(0, 1000, 77):
        sums.add({"base": e[a:a + 77], "att": att[a:a + 77]})
    got = sums.stats()
    for key, arr in (("base", e), ("att", att)):
        rms, absmax, norm_rms, norm_max = _stats_oracle(arr)
        assert got[key].rms == pytest.approx(rms, rel=1e-12) and list(got[key].absmax) == absmax
        assert got[key].norm_rms == pytest.approx(norm_rms, rel=1e-12) and got[key].norm_max == norm_max
    none = ErrorSums()
    none.add({"tip": np.full((4, 3), np.nan)})  # nothing finite: NaN, not 0
    assert all(np.isnan(v) for v in (*none.stats()["tip"].rms, none.stats()["tip"].norm_max))


def _feed(K: np.ndarray, block: int, rows: int, buckets: int) -> _Envelope:
    env = _Envelope(rows, buckets)
    t = np.arange(len(K)) / 60.0
    for a in range(0, len(K), block):
        env.add(t[a:a + block], {"k": K[a:a + block]}, K[a:a + block])
    return env


def test_the_envelope_does_not_depend_on_the_blocks():
    """A log just over the rows budget (thinned) where only the bucket count binds: the samples kept are the
    same whatever the blocks' sizes."""
    rng = np.random.default_rng(7)
    K = np.cumsum(rng.normal(size=(20_000, 4)), axis=0)
    K[1234:1300, 2] = np.nan
    K[::97, 3] = 1e3  # spikes on many samples
    envs = [_feed(K, block, 19_999, 100) for block in (1, 7, 4096, 20_000)]
    kept = [env.result({})[0] for env in envs]
    assert all(np.array_equal(k, kept[0]) for k in kept[1:])
    assert envs[0].size == 256  # 20 000 / 256 = 79 buckets <= 100 < 20 000 / 128


def test_a_long_noisy_stream_stays_within_the_budget():
    """200 000 samples of 12 independent noisy columns (extremes on different samples): at most
    ``rows`` kept, the bucket widened past what the bucket count alone asks, every extreme kept."""
    rng = np.random.default_rng(11)
    K = rng.normal(size=(200_000, 12))
    env = _feed(K, 4096, 3000, 1000)
    size = env.size
    index, _, signals = env.result({})
    assert len(index) <= 3000 and size > 256  # 1000 buckets alone: 256
    b = index // size
    for c in range(12):
        full = K[: (len(K) // size) * size, c].reshape(-1, size)
        kept_max = np.full(len(full), -np.inf)
        np.maximum.at(kept_max, b[b < len(full)], signals["k"][b < len(full), c])
        assert np.array_equal(kept_max, full.max(axis=1)), c


def test_bad_budgets_are_refused(logs):
    with pytest.raises(ValueError, match="rows = 10"):
        read_plot_log(logs["paper"], rows=10)
    with pytest.raises(ValueError, match="buckets = 2"):
        read_plot_log(logs["paper"], buckets=2)
