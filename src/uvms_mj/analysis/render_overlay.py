"""What the renderer draws over the 3-D scene: log access helpers, the clock (a 5x7 bitmap font),
the static labels (controller name, legend, scale bar; Pillow, once per video) and the
tip-error inset of a comparison video (matplotlib Agg) (:mod:`uvms_mj.analysis.render`)."""

from __future__ import annotations

import math
from pathlib import Path

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


def _font(size_px: int, bold: bool = False):
    """DejaVu Sans (matplotlib's own font files, found without importing matplotlib) at
    ``size_px`` pixels, through Pillow; Pillow's default font if the file is missing."""
    import importlib.util

    from PIL import ImageFont

    spec = importlib.util.find_spec("matplotlib")
    if spec is not None and spec.submodule_search_locations:
        name = "DejaVuSans-Bold.ttf" if bold else "DejaVuSans.ttf"
        path = Path(list(spec.submodule_search_locations)[0]) / "mpl-data" / "fonts" / "ttf" / name
        if path.is_file():
            return ImageFont.truetype(str(path), size_px)
    return ImageFont.load_default(size_px)


_BOX = (0, 0, 0, 140)  # the labels' backgrounds: black, alpha 0.55


def _labels_overlay(width: int, height: int, title: str | None, px_per_m: float | None,
                    legend: bool, trace_label: str = "tip trace",
                    desired_label: str | None = "desired tip path", scale_note: str | None = None) -> _Overlay:
    """Controller name (top right), legend of the paths (bottom left; ``desired_label`` None:
    the trace alone) and a scale bar of ``px_per_m`` [px/m] (bottom right; ``scale_note``: a
    smaller line under it, e.g. where the scale holds). Drawn once with Pillow (a TrueType
    font; importing matplotlib would cost about a second per video)."""
    from PIL import Image, ImageDraw

    img = Image.new("RGBA", (width, height), (0, 0, 0, 0))
    draw = ImageDraw.Draw(img)
    fs = max(9, int(round(height / 29)))
    font, small = _font(fs), _font(max(8, int(round(0.75 * fs))))
    pad = max(2, fs // 4)

    def boxed(x: float, y: float, text: str, fnt, fill, anchor: str) -> tuple[int, int, int, int]:
        l, t, r, b = draw.textbbox((x, y), text, font=fnt, anchor=anchor)
        draw.rounded_rectangle((l - pad, t - pad, r + pad, b + pad), radius=pad, fill=_BOX)
        draw.text((x, y), text, font=fnt, fill=fill, anchor=anchor)
        return l, t, r, b

    if title:
        boxed(width - 8 - pad, 6 + pad, title, _font(int(round(1.3 * fs)), bold=True), (255, 255, 255, 255), "ra")
    if legend:
        rows = [(trace_label, _RGBA_TRACE if trace_label == "tip trace" else _RGBA_BASE)]
        if desired_label:
            rows.insert(0, (desired_label, _RGBA_DESIRED))
        y = height - 8 - pad
        sample = int(1.6 * fs)
        for label, rgba in reversed(rows):  # from the bottom up
            x = 8 + pad + sample + pad
            l, t, r, b = draw.textbbox((x, y), label, font=font, anchor="ld")
            draw.rounded_rectangle((8, t - pad, r + pad, b + pad), radius=pad, fill=_BOX)
            colour = tuple(int(round(255 * c)) for c in rgba[:3]) + (255,)
            mid = (t + b) // 2
            draw.line((8 + pad, mid, 8 + pad + sample, mid), fill=colour, width=max(2, fs // 5))
            draw.text((x, y), label, font=font, fill=(255, 255, 255, 255), anchor="ld")
            y = t - 2 * pad - 3
    if px_per_m and math.isfinite(px_per_m) and px_per_m > 0:
        length = _nice_length(0.25 * width / px_per_m)
        bar = int(round(length * px_per_m))
        x1, y_bar = width - 14, height - 14  # the bar's right end and bottom row
        text = _fmt_length(length)
        lt, tt, rt, bt = draw.textbbox((x1 - bar / 2, y_bar - 8), text, font=font, anchor="md")
        top, left = tt, min(x1 - bar, lt)
        note_box = None
        if scale_note:
            note_box = draw.textbbox((x1 - bar / 2, tt - 2), scale_note, font=small, anchor="md")
            top, left = note_box[1], min(left, note_box[0])
        draw.rounded_rectangle((left - 6, top - 6, max(x1, rt) + 6, y_bar + 6), radius=pad, fill=_BOX)
        draw.rectangle((x1 - bar, y_bar - 2, x1 - 1, y_bar), fill=(255, 255, 255, 255))  # 3 rows, bar px wide
        draw.text((x1 - bar / 2, y_bar - 8), text, font=font, fill=(255, 255, 255, 255), anchor="md")
        if note_box is not None:
            draw.text((x1 - bar / 2, tt - 2), scale_note, font=small, fill=(220, 220, 220, 255), anchor="md")
    return _Overlay(np.asarray(img))


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
    """A strip under the panels: the tip error of each run against time, and a moving cursor.

    Laid out in pixels from the font size so that nothing is clipped at any strip size: the
    title and the legend inside the axes (top left, top right), the y tick labels left of
    the axes, the x tick labels under them and the unit "t [s]" at the x axis' right end.
    :attr:`text_boxes` keeps every drawn text's (x0, y0, x1, y1) in pixels (from the bottom left)."""

    COLORS = ("#4da6ff", "#ffb347")

    def __init__(self, width: int, height: int, series: list[tuple[str, tuple[np.ndarray, np.ndarray]]],
                 title: str = "end-tip error [mm]") -> None:
        from matplotlib.ticker import MaxNLocator

        fig, canvas = _rgba_canvas(width, height)
        fig.patch.set_facecolor((0.08, 0.08, 0.1, 1.0))
        fig.patch.set_alpha(1.0)
        fs = float(np.clip(height / 10.0, 5.0, 12.0))  # points; 1 pt = 100/72 px at dpi 100
        px = fs * 100 / 72
        left, bottom, top = 3.3 * px + 8, 1.35 * px + 5, 4.0
        right = 2.6 * px + 12  # room for "t [s]"
        ax = fig.add_axes((left / width, bottom / height, 1 - (left + right) / width, 1 - (bottom + top) / height))
        ax.set_facecolor((0.12, 0.12, 0.15))
        t_max = 0.0
        for (name, (t, e)), color in zip(series, self.COLORS):
            ok = np.isfinite(e)
            ax.plot(t[ok], e[ok], color=color, linewidth=1.2, label=name)
            t_max = max(t_max, float(t[ok].max()) if ok.any() else 0.0)
        ax.set_xlim(0.0, t_max or 1.0)
        ax.set_ylim(bottom=0.0)
        _, y_top = ax.get_ylim()
        y_top = y_top if y_top > 0 else 1.0
        ticks = [v for v in MaxNLocator(nbins=3, min_n_ticks=2).tick_values(0.0, y_top) if 0 <= v <= y_top]
        ax.set_yticks(ticks)
        ax.set_ylim(0.0, 1.35 * y_top)  # headroom for the title and the legend (no tick up there)
        ax.xaxis.set_major_locator(MaxNLocator(nbins=max(2, int(width / (6 * px))), min_n_ticks=2))
        texts = [ax.text(0.006, 0.96, title, transform=ax.transAxes, color="white", fontsize=fs, ha="left",
                         va="top")]
        ax.tick_params(colors="white", labelsize=fs * 0.85, length=2, pad=1.5)
        for sp in ax.spines.values():
            sp.set_color((0.6, 0.6, 0.6))
        texts.append(fig.text(1 - (right - 6) / width, bottom / height, "t [s]", color="white", fontsize=fs * 0.85,
                              ha="left", va="center"))
        leg = ax.legend(fontsize=fs * 0.85, loc="upper right", frameon=False, labelcolor="white", ncol=2,
                        borderaxespad=0.2, handlelength=1.2, columnspacing=1.0)
        self.image = _canvas_rgba(canvas)[..., :3]
        renderer = canvas.get_renderer()
        texts += list(leg.get_texts()) + [lb for lb in ax.get_xticklabels() + ax.get_yticklabels() if lb.get_text()]
        self.text_boxes = [tuple(tx.get_window_extent(renderer).extents) for tx in texts if tx.get_visible()]
        # pixel columns of t = 0 and t = t_max, rows of the axes (image rows from the top)
        (x0, y0), (x1, y1) = ax.transData.transform([(0.0, 0.0), (t_max or 1.0, ax.get_ylim()[1])])
        self.x0, self.x1, self.t_max = x0, x1, t_max or 1.0
        self.r0, self.r1 = int(height - y1), int(height - y0)

    def frame(self, t: float) -> np.ndarray:
        img = self.image.copy()
        x = int(round(self.x0 + (self.x1 - self.x0) * min(max(t, 0.0), self.t_max) / self.t_max))
        img[self.r0:self.r1, max(0, x - 1):x + 1] = 255
        return img


