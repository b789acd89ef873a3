"""What the figures share: reading a log's signals and metadata, shading, panel finishing and
number formatting (matplotlib's Figure directly, never pyplot), and the decimation that keeps a
figure's memory independent of the run's length: every line added to one of our figures keeps at
most :data:`MAX_LINE_POINTS` points (:func:`decimate`: per bucket of consecutive samples its
first and last point and the points of its smallest and largest x and y, so that every peak
stays visible); the numbers a figure prints (RMS, max) come from the full data (:func:`error_stats`:
the log's own where :func:`uvms_mj.analysis.envelope.read_plot_log` has thinned it)."""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from uvms_mj.analysis.series import _select

_PHASES = {1: ("carry (base moves with the arm)", "#f4a582"), 2: ("release", "#92c5de")}
_XY = ("#1f77b4", "#d62728")  # x, y
_DPI = 110

#: The most points a line in one of our figures keeps [points] (ours: a panel is about 700 px
#: wide at :data:`_DPI`, so 1000 buckets of up to 8 points each are finer than a pixel column).
MAX_LINE_POINTS = 8000


def decimate(x: np.ndarray, y: np.ndarray, max_points: int = MAX_LINE_POINTS) -> np.ndarray:
    """Indices (sorted) of the points of the line (x, y) to draw: all of them if there are at
    most ``max_points``, else, for each of ``max_points // 8`` buckets of consecutive points, its
    first and last point, the points of its smallest and largest y and of its smallest and largest
    x (a parametric path keeps its extent too) and its first NaN (a gap stays a gap): :func:`_select`.
    The decimated line thus has the same minimum and maximum as the full one over every bucket."""
    x, y = np.asarray(x), np.asarray(y)
    n = len(y)
    if max_points < 8:
        raise ValueError(f"decimate: max_points = {max_points!r}; allowed: >= 8")
    if n <= max_points:
        return np.arange(n)
    size = -(-n // (max_points // 8))  # ceil
    return _select(np.arange(n), np.column_stack([np.asarray(y, dtype=float), np.asarray(x, dtype=float)]), size)


class _DecimatingAxes(Axes):
    """Axes whose lines are decimated as they are added (:func:`decimate`), before matplotlib
    makes its per-line copies for drawing."""

    def add_line(self, line: Line2D) -> Line2D:
        try:
            x = np.asarray(line.get_xdata(orig=True))
            y = np.asarray(line.get_ydata(orig=True))
            if x.ndim == 1 and y.ndim == 1 and len(x) == len(y) > MAX_LINE_POINTS \
                    and x.dtype.kind in "biuf" and y.dtype.kind in "biuf":
                idx = decimate(x, y)
                line.set_data(x[idx], y[idx])
        except (TypeError, ValueError):  # data matplotlib converts itself (units): drawn as given
            pass
        return super().add_line(line)


#: Fixed margins of our figures [inches] (instead of matplotlib's constrained layout, which measured
#: every text twice per save: half of a figure's time, ~0.7 s of the paper run's two). Sized for our
#: labels at the default 10 pt: y tick labels of up to 9 characters ("-0.000125") plus the axis label
#: left of each column (and right of a panel with a twin axis), a title above each panel, an x label
#: below each row, the figure's title above all. (Our twin axes are all in the last column.)
_MARGINS = {"left": 1.1, "right": 0.3, "right_twin": 1.1, "bottom": 0.6, "top": 0.65, "wspace": 1.2,
            "hspace": 0.72}


def _fixed_layout(fig: Figure) -> None:
    """Place the subplots with :data:`_MARGINS` (a panel with an axis on the right: more room right)."""
    w, h = fig.get_size_inches()
    specs = [a.get_subplotspec() for a in fig.axes if a.get_subplotspec() is not None]
    if not specs:
        return
    rows, cols = specs[0].get_topmost_subplotspec().get_gridspec().get_geometry()
    twin = any(a.yaxis.get_label_position() == "right" and a.get_visible() for a in fig.axes)
    m = _MARGINS
    left, right = m["left"], m["right_twin"] if twin else m["right"]
    bottom, top = m["bottom"], m["top"]
    wgap, hgap = m["wspace"], m["hspace"]
    aw = (w - left - right - (cols - 1) * wgap) / cols
    ah = (h - bottom - top - (rows - 1) * hgap) / rows
    fig.subplots_adjust(left=left / w, right=1 - right / w, bottom=bottom / h, top=1 - top / h,
                        wspace=wgap / aw if cols > 1 else 0.0, hspace=hgap / ah if rows > 1 else 0.0)


class _DecimatingFigure(Figure):
    """A Figure whose subplots (also twins and sub-grids) are :class:`_DecimatingAxes`, laid out
    with fixed margins (:func:`_fixed_layout`) when drawn."""

    def draw(self, renderer):  # noqa: ANN001
        if self.get_layout_engine() is None:
            _fixed_layout(self)
        return super().draw(renderer)

    def add_subplot(self, *args, **kwargs):
        if "projection" not in kwargs and "polar" not in kwargs:
            kwargs.setdefault("axes_class", _DecimatingAxes)
        return super().add_subplot(*args, **kwargs)


def _meta(log) -> Mapping[str, Any]:
    meta = getattr(log, "meta", None)
    return meta if isinstance(meta, Mapping) else {}


def _label(log, default: str = "") -> str:
    m = _meta(log)
    return str(m.get("controller") or m.get("name") or default)


def _dig(meta: Mapping[str, Any], *keys: str) -> Any:
    cur: Any = meta
    for k in keys:
        if not isinstance(cur, Mapping) or k not in cur:
            return None
        cur = cur[k]
    return cur


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) index ranges where mask is True."""
    m = np.r_[False, np.asarray(mask, dtype=bool), False]
    d = np.diff(m.astype(np.int8))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)))


def _shade(ax: Axes, t: np.ndarray, mask: np.ndarray, color: str, alpha: float = 0.25) -> bool:
    # the sample period: the smallest step (a log thinned by read_plot_log keeps consecutive samples
    # at its buckets' edges; its median step is a bucket's)
    dt = float(np.min(np.diff(t))) if len(t) > 1 else 0.0
    any_ = False
    for a, b in _runs(mask):
        ax.axvspan(t[a], t[b - 1] + dt, color=color, alpha=alpha, lw=0, zorder=0)
        any_ = True
    return any_


def _shade_phases(axes, t: np.ndarray, phase: np.ndarray | None) -> list[Patch]:
    if phase is None:
        return []
    handles = []
    for value, (name, color) in _PHASES.items():
        hit = False
        for ax in axes:
            hit |= _shade(ax, t, phase == value, color)
        if hit:
            handles.append(Patch(color=color, alpha=0.4, label=f"phase {value}: {name}"))
    return handles


def _missing(ax: Axes, text: str) -> None:
    ax.text(0.5, 0.5, text, ha="center", va="center", transform=ax.transAxes, color="0.4", fontsize=10, wrap=True)
    ax.set_yticks([])


def _finish(ax: Axes, ylabel: str, title: str, legend: bool = True, zero: bool = True) -> None:
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=11, loc="left")
    ax.grid(True, alpha=0.3)
    if zero:
        ax.axhline(0.0, color="0.6", lw=0.6, zorder=1)
    if legend and ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=8, loc="best", framealpha=0.85)


def _headroom(*axes: Axes, frac: float = 0.3) -> None:
    """Extend the y range upwards so that a legend at the top covers no data."""
    for a in axes:
        lo, hi = a.get_ylim()
        a.set_ylim(lo, hi + frac * (hi - lo))


def _new_figure(rows: int, cols: int, size: tuple[float, float]) -> tuple[Figure, np.ndarray]:
    fig = _DecimatingFigure(figsize=size, dpi=_DPI)
    axes = np.asarray(fig.subplots(rows, cols, squeeze=False))
    return fig, axes


def _g(x: float) -> str:
    """3 significant digits, no exponent for the usual range (0.0123, 1.23, 123)."""
    return f"{x:.3g}" if (x == 0 or 1e-3 <= abs(x) < 1e4) else f"{x:.2e}"
