"""What the figures share: reading a log's signals and metadata, shading, panel finishing and
number formatting (matplotlib's Figure directly, never pyplot)."""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.patches import Patch

_PHASES = {1: ("carry (base moves with the arm)", "#f4a582"), 2: ("release", "#92c5de")}
_XY = ("#1f77b4", "#d62728")  # x, y
_DPI = 110


def _sig(log, name: str) -> np.ndarray | None:
    signals = getattr(log, "signals", None) or {}
    try:
        if name not in signals:
            return None
        arr = np.asarray(signals[name], dtype=float)
    except (KeyError, TypeError, ValueError):
        return None
    if arr.size == 0 or len(arr) != len(np.asarray(log.t)):
        return None
    return arr


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
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
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
    fig = Figure(figsize=size, dpi=_DPI, layout="constrained")
    axes = np.asarray(fig.subplots(rows, cols, squeeze=False))
    return fig, axes


def _g(x: float) -> str:
    """3 significant digits, no exponent for the usual range (0.0123, 1.23, 123)."""
    return f"{x:.3g}" if (x == 0 or 1e-3 <= abs(x) < 1e4) else f"{x:.2e}"


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x)))) if x.size else float("nan")
