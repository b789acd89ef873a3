"""What the renderer draws over the 3-D scene: log access helpers, the clock (a 5x7 bitmap font),
the static labels (controller name, legend, scale bar; matplotlib Agg, once per video) and the
tip-error inset of a comparison video (:mod:`uvms_mj.analysis.render`)."""

from __future__ import annotations

import math

import numpy as np


# ------------------------------------------------------------------ log access


def _signal(log, name: str) -> np.ndarray | None:
    sig = log.signals
    try:
        if name not in sig:
            return None
        return np.asarray(sig[name], dtype=float)
    except (KeyError, TypeError):
        return None


def _interp(t: np.ndarray, ts: np.ndarray, x: np.ndarray) -> np.ndarray:
    """x (N, k) sampled at ts, linearly interpolated at times t (M,) -> (M, k)."""
    return np.stack([np.interp(t, ts, x[:, j]) for j in range(x.shape[1])], axis=1)


def _decimate(n: int, max_points: int) -> int:
    return max(1, math.ceil(n / max_points))


def _thin(idx: np.ndarray, max_points: int) -> np.ndarray:
    """Every k-th index so that at most ~max_points remain, the last one kept."""
    if len(idx) <= max_points:
        return idx
    out = idx[:: _decimate(len(idx), max_points)]
    return out if out[-1] == idx[-1] else np.r_[out, idx[-1]]


def _simplify(points: np.ndarray, tol: float) -> np.ndarray:
    """Indices of a Ramer-Douglas-Peucker simplification of a polyline (N, 2 or 3) to within ``tol``
    (sorted, first and last included): a straight path needs 2 points, not thousands of line
    geoms, each of which costs a draw call in the software rasterizer."""
    n = len(points)
    if n <= 2:
        return np.arange(n)
    keep = np.zeros(n, dtype=bool)
    keep[[0, n - 1]] = True
    stack = [(0, n - 1)]
    while stack:
        i, j = stack.pop()
        if j - i < 2:
            continue
        a, b = points[i], points[j]
        rel = points[i + 1:j] - a
        ab = b - a
        # distance to the segment (not the line: a path may double back along itself)
        s = np.clip(rel @ ab / max(float(ab @ ab), 1e-300), 0.0, 1.0)
        if points.shape[1] == 2:
            dist = np.hypot(rel[:, 0] - s * ab[0], rel[:, 1] - s * ab[1])
        else:  # 3-D paths (robot logs)
            dist = np.linalg.norm(rel - s[:, None] * ab, axis=1)
        k = int(np.argmax(dist))
        if dist[k] > tol:
            m = i + 1 + k
            keep[m] = True
            stack += [(i, m), (m, j)]
    return np.flatnonzero(keep)


#: Colours of the desired path, the tip trace and the vehicle's trace (the scene's lines and the legend).
_RGBA_DESIRED = np.array([0.2, 1.0, 0.35, 0.9], dtype=np.float32)
_RGBA_TRACE = np.array([1.0, 0.25, 0.2, 1.0], dtype=np.float32)
_RGBA_BASE = np.array([0.3, 0.6, 1.0, 1.0], dtype=np.float32)


# ------------------------------------------------------------------ clock overlay (5x7 bitmap font)

_FONT = {
    "0": "01110 10001 10011 10101 11001 10001 01110", "1": "00100 01100 00100 00100 00100 00100 01110",
    "2": "01110 10001 00001 00010 00100 01000 11111", "3": "11110 00001 00001 01110 00001 00001 11110",
    "4": "00010 00110 01010 10010 11111 00010 00010", "5": "11111 10000 11110 00001 00001 10001 01110",
    "6": "00110 01000 10000 11110 10001 10001 01110", "7": "11111 00001 00010 00100 01000 01000 01000",
    "8": "01110 10001 10001 01110 10001 10001 01110", "9": "01110 10001 10001 01111 00001 00010 01100",
    ".": "00000 00000 00000 00000 00000 01100 01100", "-": "00000 00000 00000 11111 00000 00000 00000",
    "=": "00000 00000 11111 00000 11111 00000 00000", " ": "00000 00000 00000 00000 00000 00000 00000",
    "t": "01000 01000 11100 01000 01000 01001 00110", "s": "00000 00000 01111 10000 01110 00001 11110",
    "x": "00000 00000 10001 01010 00100 01010 10001",
}
_GLYPHS = {c: np.array([[ch == "1" for ch in row] for row in rows.split()], dtype=bool) for c, rows in _FONT.items()}


def _stamp_text(img: np.ndarray, text: str, x: int = 8, y: int = 8, scale: int = 2) -> None:
    """Draw ``text`` (digits, '.', '-', '=', ' ', 't', 's', 'x') in white on a dark box, in place."""
    glyphs = [_GLYPHS[c] for c in text if c in _GLYPHS]
    if not glyphs:
        return
    mask = np.concatenate([np.pad(g, ((0, 0), (0, 1))) for g in glyphs], axis=1)
    mask = np.kron(mask, np.ones((scale, scale), dtype=bool))
    h, w = mask.shape
    pad = scale * 2
    y0, x0, y1, x1 = y, x, min(img.shape[0], y + h + 2 * pad), min(img.shape[1], x + w + 2 * pad)
    img[y0:y1, x0:x1] = (img[y0:y1, x0:x1] * 0.35).astype(img.dtype)
    region = img[y0 + pad:y0 + pad + h, x0 + pad:x0 + pad + w]
    region[mask[: region.shape[0], : region.shape[1]]] = 255


# ------------------------------------------------------------------ static overlays (matplotlib Agg, once per video)


def _nice_length(max_len: float) -> float:
    """The largest 1, 2 or 5 x 10^k not above max_len (> 0)."""
    k = math.floor(math.log10(max_len))
    for m in (5, 2, 1):
        if m * 10 ** k <= max_len:
            return m * 10 ** k
    return 10 ** k


def _fmt_length(m: float) -> str:
    if m >= 1:
        return f"{m:g} m"
    if m >= 0.01:
        return f"{m * 100:g} cm"
    return f"{m * 1000:g} mm"


def _rgba_canvas(width: int, height: int):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width / 100, height / 100), dpi=100)
    fig.patch.set_alpha(0.0)
    canvas = FigureCanvasAgg(fig)
    return fig, canvas


def _canvas_rgba(canvas) -> np.ndarray:
    canvas.draw()
    return np.asarray(canvas.buffer_rgba()).copy()


class _Overlay:
    """A premultiplied RGBA layer composited onto each frame, only where it is not transparent
    (tight boxes in a 4 x 4 grid of tiles, so a label in each corner costs four small blends)."""

    def __init__(self, rgba: np.ndarray) -> None:
        h, w = rgba.shape[:2]
        self.parts = []
        for ty in range(4):
            for tx in range(4):
                ya, yb, xa, xb = ty * h // 4, (ty + 1) * h // 4, tx * w // 4, (tx + 1) * w // 4
                alpha = rgba[ya:yb, xa:xb, 3]
                ys, xs = np.nonzero(alpha)
                if not len(ys):
                    continue
                y0, y1, x0, x1 = ya + ys.min(), ya + ys.max() + 1, xa + xs.min(), xa + xs.max() + 1
                a = rgba[y0:y1, x0:x1, 3:4].astype(np.float32) / 255.0
                self.parts.append(((y0, y1, x0, x1), 1.0 - a, rgba[y0:y1, x0:x1, :3].astype(np.float32) * a))

    def apply(self, frame: np.ndarray) -> None:
        for (y0, y1, x0, x1), keep, rgb in self.parts:
            region = frame[y0:y1, x0:x1]
            region[...] = (region * keep + rgb).astype(frame.dtype)


def _labels_overlay(width: int, height: int, title: str | None, px_per_m: float | None,
                    legend: bool, trace_label: str = "tip trace",
                    desired_label: str | None = "desired tip path") -> _Overlay:
    """Controller name (top right), legend of the paths (bottom left; ``desired_label`` None:
    the trace alone) and a scale bar (bottom right)."""
    fig, canvas = _rgba_canvas(width, height)
    fs = max(7.0, height / 40)
    box = {"boxstyle": "round,pad=0.3", "facecolor": (0, 0, 0, 0.55), "edgecolor": "none"}
    if title:
        fig.text(1 - 10 / width, 1 - 8 / height, title, ha="right", va="top", color="white", fontsize=fs * 1.3,
                 fontweight="bold", bbox=box)
    if legend:
        y = 10 / height
        if desired_label:
            fig.text(10 / width, y + 1.9 * fs / height * 1.4, "\u2014 " + desired_label,
                     color=tuple(_RGBA_DESIRED[:3]), fontsize=fs, va="bottom", ha="left", bbox=box)
        color = _RGBA_TRACE if trace_label == "tip trace" else _RGBA_BASE
        fig.text(10 / width, y, "\u2014 " + trace_label, color=tuple(color[:3]), fontsize=fs, va="bottom",
                 ha="left", bbox=box)
    if px_per_m and math.isfinite(px_per_m) and px_per_m > 0:
        length = _nice_length(0.25 * width / px_per_m)
        bar = length * px_per_m
        x1, y0 = width - 14, 14
        fig.patches.append(__import__("matplotlib.patches", fromlist=["Rectangle"]).Rectangle(
            ((x1 - bar - 6) / width, (y0 - 6) / height), (bar + 12) / width, (fs * 2.2 + 12) / height,
            transform=fig.transFigure, facecolor=(0, 0, 0, 0.55), edgecolor="none"))
        fig.add_artist(__import__("matplotlib.lines", fromlist=["Line2D"]).Line2D(
            [(x1 - bar) / width, x1 / width], [y0 / height, y0 / height], transform=fig.transFigure,
            color="white", linewidth=3, solid_capstyle="butt"))
        fig.text((x1 - bar / 2) / width, (y0 + 5) / height, _fmt_length(length), color="white", fontsize=fs,
                 ha="center", va="bottom")
    return _Overlay(_canvas_rgba(canvas))


def _controller_name(log) -> str | None:
    meta = getattr(log, "meta", None) or {}
    name = meta.get("controller")
    if not name and isinstance(meta.get("scenario"), dict):
        name = (meta["scenario"].get("controller") or {}).get("name")
    return str(name) if name else None


def _tip_error_mm(log) -> tuple[np.ndarray, np.ndarray] | None:
    """(t, |p_tip,desired - p_tip| [mm]) of a log, or None."""
    t = np.asarray(log.t, dtype=float).ravel()
    pd, tip = _signal(log, "p_desired"), _signal(log, "tip_true")
    if pd is not None and tip is not None and pd.ndim == 2 and pd.shape[1] >= 5 and len(pd) == len(t) == len(tip):
        return t, 1e3 * np.hypot(pd[:, 3] - tip[:, 0], pd[:, 4] - tip[:, 1])
    ep = _signal(log, "e_p")
    if ep is not None and ep.ndim == 2 and ep.shape[1] >= 5 and len(ep) == len(t):
        return t, 1e3 * np.hypot(ep[:, 3], ep[:, 4])
    return None


class _ErrorInset:
    """A strip under the panels: the tip error of each run against time, and a moving cursor."""

    COLORS = ("#4da6ff", "#ffb347")

    def __init__(self, width: int, height: int, series: list[tuple[str, tuple[np.ndarray, np.ndarray]]],
                 title: str = "end-tip error [mm]") -> None:
        fig, canvas = _rgba_canvas(width, height)
        fig.patch.set_facecolor((0.08, 0.08, 0.1, 1.0))
        fig.patch.set_alpha(1.0)
        fs = max(6.0, height / 12)
        ax = fig.add_axes((0.07, 0.22, 0.9, 0.68))
        ax.set_facecolor((0.12, 0.12, 0.15))
        t_max = 0.0
        for (name, (t, e)), color in zip(series, self.COLORS):
            ok = np.isfinite(e)
            ax.plot(t[ok], e[ok], color=color, linewidth=1.2, label=name)
            t_max = max(t_max, float(t[ok].max()) if ok.any() else 0.0)
        ax.set_xlim(0.0, t_max or 1.0)
        ax.set_ylim(bottom=0.0)
        ax.set_title(title, color="white", fontsize=fs, loc="left", pad=2)
        ax.tick_params(colors="white", labelsize=fs * 0.85, length=2)
        for sp in ax.spines.values():
            sp.set_color((0.6, 0.6, 0.6))
        ax.set_xlabel("t [s]", color="white", fontsize=fs * 0.85, labelpad=0)
        leg = ax.legend(fontsize=fs * 0.85, loc="upper right", frameon=False, labelcolor="white", ncol=2)
        self.image = _canvas_rgba(canvas)[..., :3]
        # pixel columns of t = 0 and t = t_max, rows of the axes (image rows from the top)
        (x0, y0), (x1, y1) = ax.transData.transform([(0.0, 0.0), (t_max or 1.0, ax.get_ylim()[1])])
        self.x0, self.x1, self.t_max = x0, x1, t_max or 1.0
        self.r0, self.r1 = int(height - y1), int(height - y0)
        del leg

    def frame(self, t: float) -> np.ndarray:
        img = self.image.copy()
        x = int(round(self.x0 + (self.x1 - self.x0) * min(max(t, 0.0), self.t_max) / self.t_max))
        img[self.r0:self.r1, max(0, x - 1):x + 1] = 255
        return img


