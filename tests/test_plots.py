"""Figures of a run (uvms_mj.analysis.plots): files written, valid non-empty PNGs, logs without the
observer signals (pd baseline) and logs missing more than that."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import matplotlib
import numpy as np
import pytest

from uvms_mj.sim.experiment import PaperExperiment
from uvms_mj.analysis.plots import plot_comparison, plot_run, tracking_errors

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def runs():
    return {c: PaperExperiment(duration=3.0, controller=c).run() for c in ("rac_dob", "pd")}


def _check_png(path: Path, min_size=(800, 600)) -> None:
    import imageio.v3 as iio

    assert path.is_file() and path.stat().st_size > 20_000
    assert path.read_bytes()[:8] == PNG_MAGIC
    img = iio.imread(path)
    assert img.shape[1] >= min_size[0] and img.shape[0] >= min_size[1]
    assert img[..., :3].std() > 10  # not blank


def test_plot_run_rac_dob(runs, tmp_path: Path) -> None:
    backend = matplotlib.get_backend()
    paths = plot_run(runs["rac_dob"], tmp_path / "figs", stem="rac_dob")
    assert [p.name for p in paths] == ["rac_dob_tracking.png", "rac_dob_actuation.png"]
    for p in paths:
        _check_png(p)
    assert matplotlib.get_backend() == backend  # no global backend switch


def test_plot_run_pd_has_no_observer(runs, tmp_path: Path) -> None:
    log = runs["pd"]
    assert "f_E_hat" not in log.signals and "singular_phase" not in log.signals
    for p in plot_run(log, tmp_path, stem="pd"):
        _check_png(p)


def test_plot_run_sparse_log(tmp_path: Path) -> None:
    """A log with only the true state (e.g. another controller's) still plots."""
    t = np.linspace(0, 1, 61)
    q = np.tile([0.0, 0.0, -np.pi / 2, 1.0, -0.9], (61, 1))
    log = SimpleNamespace(t=t, signals={"q_true": q}, meta={})
    for p in plot_run(log, tmp_path, stem="sparse"):
        _check_png(p)
    with pytest.raises(ValueError):
        plot_run(SimpleNamespace(t=t[:1], signals={}, meta={}), tmp_path)


def test_plot_comparison(runs, tmp_path: Path) -> None:
    out = plot_comparison(runs, tmp_path / "cmp" / "comparison.png")
    assert out == tmp_path / "cmp" / "comparison.png"
    _check_png(out)


def test_errors_are_desired_minus_true(runs) -> None:
    log = runs["rac_dob"]
    e = tracking_errors(log)
    s = log.signals
    np.testing.assert_allclose(e["base"], s["p_desired"][:, :2] - s["q_true"][:, :2])
    np.testing.assert_allclose(e["att"], s["p_desired"][:, 2] - s["q_true"][:, 2])
    np.testing.assert_allclose(e["tip"], s["p_desired"][:, 3:5] - s["tip_true"])
