"""The sweep's figures: ``sweep_metrics.png`` (metrics against each varied parameter, per
controller, and their distributions) and ``sweep_ratio.png`` (the paired ratios)."""

from __future__ import annotations

import itertools
import json
import math
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np

from uvms_mj.io.atomic import atomic_path
from uvms_mj.analysis.sweep.plan import _jsonable
from uvms_mj.analysis.sweep.spec import _is_num
from uvms_mj.analysis.sweep.summary import SUMMARY_METRICS, _pairs


_COLORS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b")
_DPI = 110


def _xdata(rows: Sequence[dict], col: str) -> tuple[np.ndarray, list[str] | None]:
    """Numeric x of a column, or category positions and labels."""
    vals = [r.get(col) for r in rows]
    if all(_is_num(v) for v in vals):
        return np.asarray(vals, dtype=float), None
    labels = []
    for v in vals:
        s = v if isinstance(v, str) else json.dumps(_jsonable(v))
        if s not in labels:
            labels.append(s)
    pos = [labels.index(v if isinstance(v, str) else json.dumps(_jsonable(v))) for v in vals]
    return np.asarray(pos, dtype=float), labels


def _binned_median(ax, x: np.ndarray, y: np.ndarray, color: str) -> None:
    if len(x) < 6:
        return
    ux = np.unique(x)
    if len(ux) <= 12:
        centers = ux
        meds = [np.median(y[x == u]) for u in ux]
    else:
        edges = np.quantile(x, np.linspace(0, 1, 7))
        centers, meds = [], []
        for lo, hi in itertools.pairwise(edges):
            sel = (x >= lo) & (x <= hi)
            if sel.sum() >= 2:
                centers.append(float(np.median(x[sel])))
                meds.append(float(np.median(y[sel])))
    ax.plot(centers, meds, "-", color=color, lw=1.6, alpha=0.9)


def _logy(ax, ys: Sequence[np.ndarray]) -> None:
    a = np.concatenate([y[np.isfinite(y)] for y in ys if len(y)]) if ys else np.array([])
    if a.size and np.all(a > 0) and a.max() / a.min() > 30:
        ax.set_yscale("log")


def _fail_marks(ax, x: np.ndarray, color: str, label: str | None, k: int = 0) -> None:
    """Failed runs as crosses along the top of the panel (one row per controller)."""
    if not len(x):
        return
    import matplotlib.transforms as mtransforms

    trans = mtransforms.blended_transform_factory(ax.transData, ax.transAxes)
    ax.plot(x, np.full(len(x), 0.96 - 0.06 * k), "x", color=color, ms=7, mew=1.6, transform=trans, clip_on=False,
            label=label)


def _cat_ticks(ax, labels: list[str] | None) -> None:
    if labels is not None:
        ax.set_xticks(range(len(labels)))
        ax.set_xticklabels([lab if len(lab) <= 14 else lab[:13] + "…" for lab in labels], rotation=20, fontsize=7)


def _jitter(x: np.ndarray, labels, i: int, n: int, discrete: bool, span: float) -> np.ndarray:
    """Side by side per controller on discrete axes (grids, choices); continuous x as is."""
    if labels is not None:
        return x + (i - (n - 1) / 2) * 0.12
    if discrete:
        return x + (i - (n - 1) / 2) * 0.12 * span
    return x


def _spacing(rows: Sequence[dict], col: str) -> float:
    x, labels = _xdata(rows, col)
    if labels is not None:
        return 1.0
    u = np.unique(x[np.isfinite(x)])
    return float(np.min(np.diff(u))) if len(u) > 1 else 1.0


def plot_sweep(rows: Sequence[dict], columns: Sequence[str], controllers: Sequence[str], out_dir: str | Path,
               title: str = "sweep", discrete: Iterable[str] | None = None) -> list[Path]:
    """``sweep_metrics.png`` and (with two or more controllers) ``sweep_ratio.png``.

    ``discrete``: the columns drawn from a set of values (grids, choices), whose points are set
    side by side per controller (default: columns with at most 12 distinct values)."""
    from matplotlib.figure import Figure

    out = Path(out_dir)
    cols = list(columns)
    if discrete is None:
        discrete = [c for c in cols if len({json.dumps(_jsonable(r.get(c))) for r in rows}) <= 12]
    disc = {c: (c in set(discrete)) for c in cols}
    span = {c: _spacing(rows, c) for c in cols}
    mets = list(SUMMARY_METRICS)
    ncol = len(cols) + 1
    paths = []
    fig = Figure(figsize=(3.4 * ncol + 0.6, 2.5 * len(mets) + 0.9), dpi=_DPI, layout="constrained")
    axs = fig.subplots(len(mets), ncol, squeeze=False, sharey="row")
    n_ok = {c: sum(1 for r in rows if r["controller"] == c and r["status"] == "ok") for c in controllers}
    n_all = {c: sum(1 for r in rows if r["controller"] == c) for c in controllers}
    for i, m in enumerate(mets):
        for j, col in enumerate(cols):
            ax = axs[i, j]
            ys = []
            for k, c in enumerate(controllers):
                rc = [r for r in rows if r["controller"] == c]
                ok = [r for r in rc if r["status"] == "ok"]
                bad = [r for r in rc if r["status"] != "ok"]
                color = _COLORS[k % len(_COLORS)]
                if ok:
                    x, labels = _xdata(ok, col)
                    y = np.asarray([r[m] for r in ok], dtype=float)
                    ax.scatter(_jitter(x, labels, k, len(controllers), disc[col], span[col]), y, s=12, color=color,
                               alpha=0.6, lw=0, label=c if (i == 0 and j == 0) else None)
                    _binned_median(ax, x, y, color)
                    _cat_ticks(ax, labels)
                    ys.append(y)
                if bad:
                    xb, lb = _xdata(bad, col)
                    _fail_marks(ax, _jitter(xb, lb, k, len(controllers), disc[col], span[col]), color,
                                f"{c} failed" if (i == 0 and j == 0) else None, k)
                    _cat_ticks(ax, lb)
            if j == 0:
                _logy(ax, ys)
            ax.grid(True, alpha=0.3)
            if i == len(mets) - 1:
                ax.set_xlabel(col, fontsize=8)
            if j == 0:
                ax.set_ylabel(SUMMARY_METRICS[m], fontsize=8)
            ax.tick_params(labelsize=7)
        ax = axs[i, -1]
        data = [np.asarray([r[m] for r in rows if r["controller"] == c and r["status"] == "ok"], dtype=float)
                for c in controllers]
        present = [(c, d) for c, d in zip(controllers, data) if d.size]
        if present:
            bp = ax.boxplot([d for _, d in present], whis=(10, 90), showfliers=True, patch_artist=True,
                            flierprops={"markersize": 3})
            ax.set_xticks(range(1, len(present) + 1))
            ax.set_xticklabels([c for c, _ in present], fontsize=8)
            for patch, (c, _) in zip(bp["boxes"], present):
                patch.set_facecolor(_COLORS[list(controllers).index(c) % len(_COLORS)])
                patch.set_alpha(0.4)
        ax.grid(True, alpha=0.3)
        ax.tick_params(labelsize=7)
        if i == 0:
            ax.set_title("all samples (box: 25-75 %, whiskers 10-90 %)", fontsize=8)
    counts = ", ".join(f"{c}: {n_ok[c]}/{n_all[c]} ok" for c in controllers)
    fig.suptitle(f"{title}: metrics against the varied parameters ({counts}; lines: medians; x: failed runs)",
                 fontsize=10)
    fig.legend(loc="outside lower center", ncol=2 * len(controllers), fontsize=8)
    p = out / "sweep_metrics.png"
    with atomic_path(p) as tmp:
        fig.savefig(tmp, format="png")
    paths.append(p)

    if len(controllers) >= 2:
        ref = controllers[0]
        fig = Figure(figsize=(3.4 * ncol + 0.6, 2.5 * len(mets) + 0.9), dpi=_DPI, layout="constrained")
        axs = fig.subplots(len(mets), ncol, squeeze=False, sharey="row")
        notes = []
        for k, c in enumerate(controllers[1:], start=1):
            pairs = _pairs(rows, ref, c)
            notes.append(f"{c}/{ref}: {len(pairs)} pairs")
        for i, m in enumerate(mets):
            hist_data = []
            for k, c in enumerate(controllers[1:], start=1):
                color = _COLORS[k % len(_COLORS)]
                pairs = [(r, o) for r, o in _pairs(rows, ref, c)
                         if math.isfinite(r[m]) and r[m] > 0 and math.isfinite(o[m])]
                if not pairs:
                    continue
                ratio = np.asarray([o[m] / r[m] for r, o in pairs], dtype=float)
                hist_data.append((c, color, ratio))
                for j, col in enumerate(cols):
                    ax = axs[i, j]
                    x, labels = _xdata([r for r, _ in pairs], col)
                    ax.scatter(_jitter(x, labels, k - 1, len(controllers) - 1, disc[col], span[col]), ratio, s=12,
                               color=color, alpha=0.6, lw=0, label=f"{c}/{ref}" if (i == 0 and j == 0) else None)
                    _binned_median(ax, x, ratio, color)
                    _cat_ticks(ax, labels)
            for j, col in enumerate(cols):
                ax = axs[i, j]
                ax.axhline(1.0, color="k", lw=0.8, ls="--")
                if j == 0:
                    _logy(ax, [h[2] for h in hist_data] + [np.ones(1)])
                ax.grid(True, alpha=0.3)
                ax.tick_params(labelsize=7)
                if i == len(mets) - 1:
                    ax.set_xlabel(col, fontsize=8)
                if j == 0:
                    ax.set_ylabel(f"ratio of {SUMMARY_METRICS[m].split(' [')[0]}", fontsize=8)
            ax = axs[i, -1]
            if hist_data:
                bp = ax.boxplot([h[2] for h in hist_data], whis=(10, 90), showfliers=True, patch_artist=True,
                                flierprops={"markersize": 3}, widths=0.5)
                for patch, (c, color, _) in zip(bp["boxes"], hist_data):
                    patch.set_facecolor(color)
                    patch.set_alpha(0.4)
                ax.set_xticks(range(1, len(hist_data) + 1))
                ax.set_xticklabels([f"{c}/{ref}" for c, _, _ in hist_data], fontsize=8)
                for h, (c, color, ratio) in enumerate(hist_data):
                    med, p10, p90 = np.median(ratio), np.percentile(ratio, 10), np.percentile(ratio, 90)
                    ax.text(0.97, 0.95 - 0.16 * h, f"{c}/{ref}: median {med:.3g}\n10-90 % [{p10:.3g}, {p90:.3g}]",
                            transform=ax.transAxes, ha="right", va="top", fontsize=7, color=color)
            ax.axhline(1.0, color="k", lw=0.8, ls="--")
            ax.grid(True, alpha=0.3)
            ax.tick_params(labelsize=7)
            if i == 0:
                ax.set_title("all pairs (box: 25-75 %, whiskers 10-90 %)", fontsize=8)
        fig.suptitle(f"{title}: paired ratio to {ref} (same parameters and seed; < 1: better than {ref}; "
                     f"{'; '.join(notes)})", fontsize=10)
        if any(ax.get_legend_handles_labels()[0] for ax in axs.flat):
            fig.legend(loc="outside lower center", ncol=len(controllers), fontsize=8)
        p = out / "sweep_ratio.png"
        with atomic_path(p) as tmp:
            fig.savefig(tmp, format="png")
        paths.append(p)
    return paths
