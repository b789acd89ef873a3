"""Off-screen video of a logged run (no simulation: the log's true state is replayed).

:func:`render_video` interpolates ``q_true`` to the video frame times, sets it as ``qpos`` of a
plain ``MjData`` of the scene model (``models/scene.xml``), runs ``mj_kinematics`` (with
``mj_comPos`` and ``mj_camlight`` for the cameras) and renders
with ``mujoco.Renderer``; the desired end-tip path (``p_desired[:, 3:5]``) and the tip's trace so
far (``tip_true``) are drawn as user geoms, a small clock in the top-left corner, and the frames
are piped to the ffmpeg that ships with imageio-ffmpeg (H.264, yuv420p, MP4).

Robot logs (any floating robot, ``meta["robot"]``): the robot's MJCF file is compiled
(:func:`uvms_mj.plant.robot.compile_robot_spec`) with a scene added to its MjSpec (a checkered sea
floor 3 m below the vehicle's start, a directional light, a water-coloured gradient skybox and
haze) and two cameras on the vehicle body in MuJoCo's "track" mode (:data:`ROBOT_CAMERAS`:
position follows the vehicle, orientation fixed in the world); ``q_true`` is interpolated to the
frame times (positions and angles linearly, quaternions by normalised lerp), and the tip trace
and desired tip path are drawn in world coordinates (m, z up).

Headless OpenGL
---------------
MuJoCo picks its OpenGL backend from ``$MUJOCO_GL`` once, when ``mujoco`` is first imported, and
``import mujoco`` itself fails when that backend's library is missing. ``uvms_mj/__init__.py``
therefore calls :func:`configure_gl` before anything imports mujoco:

* ``MUJOCO_GL`` unset (Linux) and no display (neither ``DISPLAY`` nor ``WAYLAND_DISPLAY``):
  ``egl`` if ``libEGL.so.1`` and ``libOpenGL.so.0`` (or ``libGL``) load, else ``osmesa`` if
  ``libOSMesa`` loads, else left unset (MuJoCo's GLFW default);
* ``MUJOCO_GL`` unset with a display: left unset, so the process (and its children, viewers
  included) keeps MuJoCo's GLFW default; the user's choice, when set, is never replaced;
* ``MUJOCO_GL`` set to a value MuJoCo rejects, or to ``egl``/``osmesa`` whose library cannot be
  loaded: mujoco is imported with rendering disabled (so simulation keeps working), the user's
  value is put back, and the problem is remembered.

Every rendering problem (the remembered one, no backend library, a GL context that cannot be
created) surfaces as a :class:`RenderError` whose message is one line naming the Debian packages
to install. On Linux without a display, a MuJoCo that was imported before ``uvms_mj`` with the
GLFW default is switched to EGL/OSMesa for the renderer's context.

Debian packages: ``libegl1 libegl-mesa0 libgl1-mesa-dri libopengl0`` (EGL, Mesa's llvmpipe
software rasterizer when there is no GPU) or ``libosmesa6`` (``MUJOCO_GL=osmesa``).
"""

from __future__ import annotations

import ctypes
import math
import os
import platform
import sys
import time
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping

import numpy as np

__all__ = ["RenderError", "DEBIAN_PACKAGES", "ROBOT_CAMERAS", "configure_gl", "gl_status", "interp_qpos",
           "render_compare_video", "render_frames", "render_video", "robot_of"]

#: Debian/Ubuntu packages that provide each headless backend.
DEBIAN_PACKAGES: dict[str, tuple[str, ...]] = {
    "egl": ("libegl1", "libegl-mesa0", "libgl1-mesa-dri", "libopengl0"),
    "osmesa": ("libosmesa6",),
}
#: Shared libraries each backend needs: every group must have one loadable member.
_BACKEND_LIBS: dict[str, tuple[tuple[str, ...], ...]] = {
    "egl": (("libEGL.so.1",), ("libOpenGL.so.0", "libGL.so.1")),
    "osmesa": (("libOSMesa.so.8", "libOSMesa.so.6"),),
}
_MUJOCO_GL_VALID = ("", "enable", "enabled", "on", "true", "1", "glfw", "glx", "egl", "osmesa")
_MUJOCO_GL_OFF = ("disable", "disabled", "off", "false", "0")

# What configure_gl decided: backend chosen automatically (or None) and a deferred problem.
_GL_STATE: dict[str, Any] = {"auto": None, "problem": None}


class RenderError(RuntimeError):
    """Rendering is impossible here (no OpenGL backend, or no GL context); a one-line message."""


def _install_hint() -> str:
    egl, osm = " ".join(DEBIAN_PACKAGES["egl"]), " ".join(DEBIAN_PACKAGES["osmesa"])
    return f"install the Debian packages: apt-get install {egl} (MUJOCO_GL=egl), or {osm} (MUJOCO_GL=osmesa)"


_LOADABLE: dict[str, bool] = {}


def _loadable(soname: str) -> bool:
    if soname not in _LOADABLE:
        try:
            ctypes.CDLL(soname)
            _LOADABLE[soname] = True
        except OSError:
            _LOADABLE[soname] = False
    return _LOADABLE[soname]


def _missing_libs(backend: str) -> list[str]:
    """Library groups of ``backend`` with no loadable member (as 'a or b' strings)."""
    return [" or ".join(group) for group in _BACKEND_LIBS.get(backend, ()) if not any(map(_loadable, group))]


def _headless() -> bool:
    return not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def configure_gl() -> None:
    """Choose ``MUJOCO_GL`` before mujoco is imported (called by ``uvms_mj/__init__``).

    Never raises: a backend that cannot work is remembered and reported by the renderer as a
    :class:`RenderError`, so that ``import uvms_mj`` and simulation work without any GL library.
    """
    if "mujoco" in sys.modules or platform.system() != "Linux":
        return  # too late to choose, or not our business (macOS: CGL, Windows: WGL)
    raw = os.environ.get("MUJOCO_GL")
    value = (raw or "").strip().lower()
    if not value:
        if not _headless():
            return  # a display: MuJoCo's GLFW default works, and the process keeps its own choice
        for backend in ("egl", "osmesa"):
            if not _missing_libs(backend):
                os.environ["MUJOCO_GL"] = backend
                _GL_STATE["auto"] = backend
                return
        return  # nothing headless: leave MuJoCo's GLFW default (fine with a display)
    if value in _MUJOCO_GL_OFF:
        _GL_STATE["problem"] = f"rendering is disabled by MUJOCO_GL={raw}: unset it (or set MUJOCO_GL=egl)"
        return
    if value not in _MUJOCO_GL_VALID:
        problem = (f"MUJOCO_GL={raw!r} is not a valid OpenGL backend: use MUJOCO_GL=egl (or osmesa) to render "
                   f"without a display, glfw with one")
    else:
        missing = _missing_libs(value)
        if not missing:
            return
        problem = f"MUJOCO_GL={raw} but {', '.join(missing)} cannot be loaded: {_install_hint()}"
    # `import mujoco` would fail outright with this value: import it without rendering, then
    # put the user's value back (for child processes) and remember the problem.
    _GL_STATE["problem"] = problem
    os.environ["MUJOCO_GL"] = "disable"
    try:
        import mujoco  # noqa: F401
    finally:
        os.environ["MUJOCO_GL"] = raw  # type: ignore[assignment]


def gl_status() -> dict[str, Any]:
    """The OpenGL backend in use: {'backend', 'auto' (chosen by configure_gl), 'problem'}."""
    try:
        from mujoco.rendering.classic import gl_context

        cls = getattr(gl_context, "GLContext", None)
        backend = None if cls is None else cls.__module__.rsplit(".", 1)[-1]
    except ImportError:
        backend = None
    return {"backend": backend, "auto": _GL_STATE["auto"], "problem": _GL_STATE["problem"]}


def _first_line(exc: BaseException) -> str:
    try:
        text = str(exc).strip()
    except Exception:  # noqa: BLE001 (PyOpenGL's EGLError can fail to format itself)
        text = ""
    line = text.splitlines()[0] if text else ""
    return f"{type(exc).__name__}: {line[:200]}" if line else type(exc).__name__


def _headless_context_class():
    """EGL or OSMesa GLContext class for a MuJoCo imported with the GLFW default, or RenderError."""
    errors = []
    for backend in ("egl", "osmesa"):
        missing = _missing_libs(backend)
        if missing:
            errors.append(f"{backend}: no {missing[0]}")
            continue
        try:
            if backend == "egl":
                from mujoco.egl import GLContext
            else:
                from mujoco.osmesa import GLContext
            return GLContext
        except Exception as exc:  # noqa: BLE001
            errors.append(f"{backend}: {_first_line(exc)}")
    raise RenderError(f"no OpenGL backend for rendering without a display ({'; '.join(errors)}): {_install_hint()}")


def _make_renderer(model, height: int, width: int):
    """mujoco.Renderer, with every GL failure turned into a one-line RenderError."""
    if _GL_STATE["problem"]:
        raise RenderError(_GL_STATE["problem"])
    import mujoco

    try:
        from mujoco.rendering.classic import gl_context
    except ImportError as exc:
        raise RenderError(f"this MuJoCo has no off-screen renderer ({_first_line(exc)})") from None
    current = getattr(gl_context, "GLContext", None)
    if current is None or not hasattr(mujoco, "Renderer"):
        gl = os.environ.get("MUJOCO_GL", "")
        raise RenderError(f"MuJoCo was imported with rendering disabled (MUJOCO_GL={gl!r}): "
                          f"set MUJOCO_GL=egl before importing mujoco; {_install_hint()}")
    use = current
    if platform.system() == "Linux" and current.__module__ == "mujoco.glfw" and _headless():
        use = _headless_context_class()  # mujoco was imported before uvms_mj, MUJOCO_GL unset
    backend = use.__module__.rsplit(".", 1)[-1]
    try:
        gl_context.GLContext = use
        try:
            return mujoco.Renderer(model, height=height, width=width)
        finally:
            gl_context.GLContext = current
    except Exception as exc:  # noqa: BLE001 (EGL/OSMesa/GLFW raise anything from ImportError to GLError)
        raise RenderError(f"cannot create an OpenGL context with MUJOCO_GL={backend} ({_first_line(exc)}): "
                          f"{_install_hint()}") from None


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


# ------------------------------------------------------------------ scene


def _scene_model(model_path: str | Path | None, width: int, height: int):
    """Scene model compiled with one extra fixed camera ("uvms_render") that we place ourselves."""
    import mujoco

    if model_path is None:
        from uvms_mj.plant.plant import default_model_path

        model_path = default_model_path()
    spec = mujoco.MjSpec.from_file(str(model_path))
    spec.worldbody.add_camera(name="uvms_render", pos=[0, 0, 3], quat=[1, 0, 0, 0], fovy=45.0)
    model = spec.compile()
    model.vis.global_.offwidth = max(int(model.vis.global_.offwidth), width)
    model.vis.global_.offheight = max(int(model.vis.global_.offheight), height)
    return model


def _pose(model, data) -> None:
    """Kinematics, centres of mass (for tracking cameras), cameras and lights of data.qpos."""
    import mujoco

    mujoco.mj_kinematics(model, data)
    mujoco.mj_comPos(model, data)
    mujoco.mj_camlight(model, data)


def _robot_extent(model, data, qs: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """World x-y bounds of the robot's visible geoms over configurations ``qs``, and their max z."""
    import mujoco

    geoms = [g for g in range(model.ngeom) if model.geom_bodyid[g] != 0 and model.geom_group[g] < 3]
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float)
    pts = []
    for q in qs:
        data.qpos[: len(q)] = q
        mujoco.mj_kinematics(model, data)
        for g in geoms:
            if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX:
                local = signs * model.geom_size[g]
            else:
                local = signs * model.geom_rbound[g]
            pts.append(data.geom_xpos[g] + local @ data.geom_xmat[g].reshape(3, 3).T)
    pts = np.concatenate(pts) if pts else np.zeros((1, 3))
    return pts[:, :2].min(axis=0), pts[:, :2].max(axis=0), float(pts[:, 2].max())


def _place_camera(model, cam_id: int, lo: np.ndarray, hi: np.ndarray, z_near: float, aspect: float,
                  margin: float = 0.12) -> None:
    """Side view along -Z (image right +X, up +Y) framing the box [lo, hi] on the plane z = z_near."""
    center = 0.5 * (lo + hi)
    half = 0.5 * (hi - lo) * (1 + 2 * margin) + 0.05
    tan_half = math.tan(math.radians(model.cam_fovy[cam_id]) / 2)
    dist = max(half[1], half[0] / aspect) / tan_half
    model.cam_pos[cam_id] = (center[0], center[1], z_near + dist)
    model.cam_quat[cam_id] = (1.0, 0.0, 0.0, 0.0)


def _to_front(points: np.ndarray, eye: np.ndarray, z_front: float) -> np.ndarray:
    """Move points (N, 3) along the ray towards ``eye`` to z = z_front: same image position, but
    drawn in front of the robot (whose geoms reach z_front)."""
    if eye[2] <= z_front + 1e-6:
        return points
    s = ((z_front - points[:, 2]) / (eye[2] - points[:, 2]))[:, None]
    return points + s * (eye - points)


_TRACE_TOL = 0.5e-3  # m
_RGBA_DESIRED = np.array([0.2, 1.0, 0.35, 0.9], dtype=np.float32)
_RGBA_TRACE = np.array([1.0, 0.25, 0.2, 1.0], dtype=np.float32)


def _add_polyline(scene, pts: np.ndarray, rgba: np.ndarray, width: float) -> None:
    import mujoco

    line = mujoco.mjtGeom.mjGEOM_LINE
    zero3, eye9 = np.zeros(3), np.eye(3).ravel()
    for a, b in zip(pts[:-1], pts[1:]):
        if scene.ngeom >= scene.maxgeom:
            return
        g = scene.geoms[scene.ngeom]
        mujoco.mjv_initGeom(g, line, zero3, zero3, eye9, rgba)
        mujoco.mjv_connector(g, line, width, a, b)
        g.category = mujoco.mjtCatBit.mjCAT_DECOR
        scene.ngeom += 1


def _add_sphere(scene, pos: np.ndarray, radius: float, rgba: np.ndarray) -> None:
    import mujoco

    if scene.ngeom >= scene.maxgeom:
        return
    g = scene.geoms[scene.ngeom]
    mujoco.mjv_initGeom(g, mujoco.mjtGeom.mjGEOM_SPHERE, np.array([radius, 0, 0]), pos, np.eye(3).ravel(), rgba)
    g.category = mujoco.mjtCatBit.mjCAT_DECOR
    scene.ngeom += 1


# ------------------------------------------------------------------ frames and video


def _check_size(size: tuple[int, int], fps: float, speed: float) -> tuple[int, int]:
    """(width, height) of a frame size, checked (16 .. 3840 x 2160 px; fps, speed > 0)."""
    width, height = int(size[0]), int(size[1])
    if width < 16 or height < 16:
        raise ValueError(f"size = {size!r}: width and height must be at least 16 pixels")
    if width > 3840 or height > 2160:
        raise ValueError(f"size = {size!r}: at most 3840 x 2160 pixels")
    if not (fps > 0 and speed > 0):
        raise ValueError(f"fps = {fps!r} and speed = {speed!r} must be > 0")
    return width, height


def _frame_times(t: np.ndarray, fps: float, speed: float, max_seconds: float | None) -> np.ndarray:
    seconds = (float(t[-1]) - float(t[0])) / speed
    if max_seconds is not None:
        seconds = min(seconds, float(max_seconds))
    n = max(1, int(round(seconds * fps)))
    return float(t[0]) + np.arange(n) * (speed / fps)


class _Replay:
    """Scene, camera, overlays and GL context for replaying a log; iterate for the frames."""

    def __init__(self, log, fps: float, size: tuple[int, int], camera: str | int | None, speed: float,
                 max_seconds: float | None, model_path: str | Path | None, clock: bool,
                 labels: bool = True, extent: tuple[np.ndarray, np.ndarray] | None = None,
                 title: str | None = None) -> None:
        import mujoco

        width, height = int(size[0]), int(size[1])
        if width < 16 or height < 16:
            raise ValueError(f"size = {size!r}: width and height must be at least 16 pixels")
        if width > 3840 or height > 2160:
            raise ValueError(f"size = {size!r}: at most 3840 x 2160 pixels")
        if not (fps > 0 and speed > 0):
            raise ValueError(f"fps = {fps!r} and speed = {speed!r} must be > 0")
        ts = np.asarray(log.t, dtype=float).ravel()
        q_log = _signal(log, "q_true")
        if q_log is None or q_log.ndim != 2 or len(q_log) != len(ts) or len(ts) < 1:
            raise ValueError("the log has no q_true signal matching its time base: nothing to replay")
        tip = _signal(log, "tip_true")
        if tip is not None and (tip.ndim != 2 or tip.shape[1] < 2 or len(tip) != len(ts)):
            tip = None
        pd = _signal(log, "p_desired")
        desired = pd[:, 3:5] if pd is not None and pd.ndim == 2 and pd.shape[1] >= 5 and len(pd) == len(ts) \
            else None
        # Drop samples that are not finite (a run stopped by a divergence may end with some).
        ok = np.isfinite(ts) & np.isfinite(q_log).all(axis=1)
        for arr in (tip, desired):
            if arr is not None:
                ok &= np.isfinite(arr[:, :2]).all(axis=1)
        if not ok.any():
            raise ValueError("the log has no sample with a finite q_true: nothing to replay")
        ts, q_log = ts[ok], q_log[ok]
        tip = tip[ok, :2] if tip is not None else None
        desired = desired[ok] if desired is not None else None
        if len(ts) == 1:  # a single sample: a still picture of 1 / fps
            dup = lambda a: None if a is None else np.vstack([a, a])  # noqa: E731
            ts, q_log, tip, desired = np.r_[ts, ts + 1.0 / fps], dup(q_log), dup(tip), dup(desired)
        self.ts, self.speed, self.clock, self.height = ts, speed, clock, height
        self.frame_t = _frame_times(ts, fps, speed, max_seconds)

        model = self.model = _scene_model(model_path, width, height)
        data = self.data = mujoco.MjData(model)
        self.nq = nq = min(model.nq, q_log.shape[1])
        self.qs = _interp(self.frame_t, ts, q_log[:, :nq])

        if tip is None and mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, "tip") >= 0:
            # no logged tip: the model's "tip" site
            sid = model.site("tip").id
            tip = np.empty((len(q_log), 2))
            for k, q in enumerate(q_log):
                data.qpos[:nq] = q[:nq]
                mujoco.mj_kinematics(model, data)
                tip[k] = data.site_xpos[sid, :2]
        self.tip, self.desired = tip, desired

        # Camera: the fitted side view, or a camera of the scene.
        stride = _decimate(len(self.qs), 60)
        lo, hi, z_robot = _robot_extent(model, data, np.vstack([self.qs[::stride], self.qs[-1:]]))
        shown = ts <= self.frame_t[-1] + 1e-9  # the part of the log in the video
        for path in (desired, tip):
            if path is not None:
                lo, hi = np.minimum(lo, path[shown].min(axis=0)), np.maximum(hi, path[shown].max(axis=0))
        if extent is not None:  # a view shared with another replay (render_compare_video)
            lo, hi = np.minimum(lo, extent[0]), np.maximum(hi, extent[1])
        self.extent = (lo, hi)
        self.z_front = z_robot + 0.01
        px_per_m = None
        if camera is None:
            self.cam = model.camera("uvms_render").id
            _place_camera(model, self.cam, lo, hi, z_robot, width / height)
            # the plane of motion (z = 0) seen from the camera on +Z
            px_per_m = height / (2.0 * float(model.cam_pos[self.cam][2])
                                 * math.tan(math.radians(model.cam_fovy[self.cam]) / 2))
        elif isinstance(camera, str):
            if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, camera) < 0:
                names = [model.camera(i).name for i in range(model.ncam) if model.camera(i).name != "uvms_render"]
                raise ValueError(f"camera {camera!r} is not in the scene; cameras: {names}")
            self.cam = model.camera(camera).id
        else:
            self.cam = int(camera)
            if not 0 <= self.cam < model.ncam:
                raise ValueError(f"camera id {camera!r} out of range 0..{model.ncam - 1}")

        # Polylines in the plane of motion (z = 0), simplified to within 0.5 mm (well under a
        # pixel of the fitted view), and at most ~300 segments.
        self.desired_pts = None
        if desired is not None:
            keep = _thin(_simplify(desired, _TRACE_TOL), 300)
            self.desired_pts = np.c_[desired[keep], np.zeros(len(keep))]
        self.tip_keep = _thin(_simplify(tip, _TRACE_TOL), 300) if tip is not None else None
        self.overlay = None
        if labels:
            self.overlay = _labels_overlay(width, height, title if title is not None else _controller_name(log),
                                           px_per_m, legend=desired is not None or tip is not None)
        self.renderer = _make_renderer(model, height, width)

    def __len__(self) -> int:
        return len(self.frame_t)

    def __iter__(self) -> Iterator[tuple[float, np.ndarray]]:
        import mujoco

        ts, tip, desired, renderer = self.ts, self.tip, self.desired, self.renderer
        scene = renderer.scene
        for tf, q in zip(self.frame_t, self.qs):
            self.data.qpos[: self.nq] = q
            _pose(self.model, self.data)
            renderer.update_scene(self.data, camera=self.cam)
            eye = 0.5 * (np.asarray(scene.camera[0].pos) + np.asarray(scene.camera[1].pos))
            if self.desired_pts is not None:
                # thin, in front of the (thicker) trace so that both stay visible when they overlap
                _add_polyline(scene, _to_front(self.desired_pts, eye, self.z_front + 0.01), _RGBA_DESIRED, 2.0)
                now = np.r_[np.interp(tf, ts, desired[:, 0]), np.interp(tf, ts, desired[:, 1]), 0.0]
                _add_sphere(scene, _to_front(now[None], eye, self.z_front + 0.02)[0], 0.008, _RGBA_DESIRED)
            if tip is not None:
                k = int(np.searchsorted(ts, tf, side="right"))  # samples at or before tf
                now = [np.interp(tf, ts, tip[:, 0]), np.interp(tf, ts, tip[:, 1])]
                kept = self.tip_keep[: int(np.searchsorted(self.tip_keep, k))]
                pts = np.vstack([tip[kept], tip[k - 1:k], now])
                if len(pts) >= 2:
                    pts = np.c_[pts, np.zeros(len(pts))]
                    _add_polyline(scene, _to_front(pts, eye, self.z_front), _RGBA_TRACE, 5.0)
            frame = renderer.render()
            if self.overlay is not None:
                self.overlay.apply(frame)
            if self.clock:
                text = f"t = {tf:5.2f} s" if self.speed == 1 else f"t = {tf:5.2f} s  x{self.speed:g}"
                _stamp_text(frame, text, scale=max(1, self.height // 240))
            yield float(tf), frame

    def close(self) -> None:
        self.renderer.close()


# ------------------------------------------------------------------ any robot (logs with meta["robot"])

#: The cameras added to a robot's scene, both on the vehicle body in MuJoCo's "track" mode
#: (position follows the vehicle, orientation fixed in the world): a side view from the
#: vehicle's starboard side (its -y axis at the first sample) and a three-quarter view from the
#: front-left, above. The first is the default.
ROBOT_CAMERAS = ("follow_three_quarter", "follow_side")
_FLOOR_DEPTH = 3.0  # m below the vehicle's start (and at least 0.5 m below its lowest point)
_SKY = ((0.16, 0.42, 0.62), (0.01, 0.06, 0.14))  # water: lighter above, darker below
_FLOOR_RGB = ((0.50, 0.46, 0.36), (0.42, 0.38, 0.29))
_RGBA_BASE = np.array([0.3, 0.6, 1.0, 1.0], dtype=np.float32)


def robot_of(log) -> dict | None:
    """The log's robot description (``meta["robot"]``) when it is a robot log (name not
    "paper"), else None (the paper's planar robot)."""
    meta = getattr(log, "meta", None)
    robot = meta.get("robot") if isinstance(meta, Mapping) else None
    if not isinstance(robot, Mapping) or robot.get("name") in (None, "", "paper"):
        return None
    return dict(robot)


def _robot_file(robot: dict, model_path: str | Path | None) -> Path:
    """The robot's MJCF file: ``model_path``, else the recorded path, else the built-in name."""
    from uvms_mj.plant.files import robot_path

    if model_path is not None:
        return Path(model_path)
    path = robot.get("path")
    if path and Path(str(path)).is_file():
        return Path(str(path))
    try:
        return robot_path(str(robot["name"]))
    except Exception as exc:  # noqa: BLE001 (ParameterError: no such robot here)
        raise ValueError(f"the log's robot {robot.get('name')!r}: its model file {path!r} is not here and "
                         f"{exc}; give model_path") from None


def _quat_slots(model) -> list[int]:
    """qpos addresses of the quaternions (free and ball joints)."""
    import mujoco

    out = []
    for j in range(model.njnt):
        t, a = int(model.jnt_type[j]), int(model.jnt_qposadr[j])
        if t == mujoco.mjtJoint.mjJNT_FREE:
            out.append(a + 3)
        elif t == mujoco.mjtJoint.mjJNT_BALL:
            out.append(a)
    return out


def interp_qpos(t: np.ndarray, ts: np.ndarray, q: np.ndarray, quat_slots: list[int]) -> np.ndarray:
    """``qpos`` samples q (N, nq) at ts, interpolated at times t (M,): positions and angles
    linearly, each quaternion by normalised linear interpolation (after choosing the sign of
    each sample nearest the previous one, so that no interpolation goes the long way round)."""
    q = np.array(q, dtype=float)
    for a in quat_slots:
        block = q[:, a:a + 4]
        for k in range(1, len(block)):
            if block[k] @ block[k - 1] < 0:
                block[k] = -block[k]
    out = _interp(t, ts, q)
    for a in quat_slots:
        n = np.linalg.norm(out[:, a:a + 4], axis=1, keepdims=True)
        out[:, a:a + 4] /= np.where(n > 0, n, 1.0)
    return out


def _geom_box(model, data, qpos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World bounds (lo, hi) of the visible geoms (group < 3, not planes) at ``qpos``."""
    import mujoco

    data.qpos[:] = qpos
    mujoco.mj_kinematics(model, data)
    geoms = [g for g in range(model.ngeom) if model.geom_group[g] < 3
             and model.geom_type[g] not in (mujoco.mjtGeom.mjGEOM_PLANE, mujoco.mjtGeom.mjGEOM_HFIELD)]
    if not geoms:
        p = data.xpos[1:] if model.nbody > 1 else np.zeros((1, 3))
        return p.min(axis=0) - 0.1, p.max(axis=0) + 0.1
    r = model.geom_rbound[geoms][:, None]
    pos = data.geom_xpos[geoms]
    return (pos - r).min(axis=0), (pos + r).max(axis=0)


def _xyaxes(forward: np.ndarray) -> np.ndarray:
    """Camera x and y axes (6) looking along ``forward`` with the world's z up in the image."""
    f = forward / np.linalg.norm(forward)
    x = np.cross(f, [0.0, 0.0, 1.0])
    x = x / np.linalg.norm(x) if np.linalg.norm(x) > 1e-9 else np.array([1.0, 0.0, 0.0])
    return np.r_[x, np.cross(x, f)]


def _robot_cameras(lo: np.ndarray, hi: np.ndarray, base_pos: np.ndarray, yaw: float,
                   fovy: float) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """World offsets from the vehicle origin and xyaxes (world) of the two follow cameras,
    framing the robot's bounding box [lo, hi] (world, at the first sample)."""
    center = 0.5 * (lo + hi)
    radius = max(0.5 * float(np.linalg.norm(hi - lo)), 0.2)
    dist = 1.25 * radius / math.tan(math.radians(fovy) / 2)
    c, s = math.cos(yaw), math.sin(yaw)
    rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    out = {}
    for name, d in (("follow_side", (0.0, -1.0, 0.12)), ("follow_three_quarter", (1.0, 1.0, 0.75))):
        eye = center + dist * (rz @ (np.asarray(d) / np.linalg.norm(d)))
        out[name] = (eye - base_pos, _xyaxes(center - eye))
    return out


def _robot_scene_model(robot: dict, q_log: np.ndarray, width: int, height: int,
                       model_path: str | Path | None = None):
    """The robot's model plus the replay scene (sea floor, light, water background, the
    :data:`ROBOT_CAMERAS` on the vehicle body), and the robot's Layout.

    ``q_log``: the logged qpos samples (N, nq): the cameras are framed on the first; the floor
    is :data:`_FLOOR_DEPTH` below the vehicle's start and at least 0.5 m below its lowest point.
    """
    import mujoco

    from uvms_mj.plant.params import ParameterError
    from uvms_mj.plant.layout import Layout
    from uvms_mj.plant.robot import compile_robot_spec
    from uvms_mj.rotations import rpy_from_quat

    path = _robot_file(robot, model_path)
    layout_meta = robot.get("layout")
    tip = (layout_meta.get("tip_site") or None) if isinstance(layout_meta, Mapping) else None
    try:
        plain = compile_robot_spec(path)
        layout = Layout.of(plain, tip)
    except ParameterError as exc:
        raise ValueError(f"the log's robot model {path}: {exc}") from None
    q0 = q_log[0]
    if len(q0) != plain.nq:
        raise ValueError(f"the log's q_true has {len(q0)} values per sample, the robot model {path.name} "
                         f"has nq = {plain.nq}: not this robot's log")
    data = mujoco.MjData(plain)
    lo, hi = _geom_box(plain, data, q0)
    a = layout.base_qadr
    yaw = float(rpy_from_quat(q0[a + 3:a + 7])[2]) if np.linalg.norm(q0[a + 3:a + 7]) > 0 else 0.0
    fovy = 45.0
    cams = _robot_cameras(lo, hi, q0[a:a + 3], yaw, fovy)
    # Track cameras keep their qpos0 offset from the body (world frame): express the wanted
    # world offset and axes in the body frame at qpos0.
    r0 = np.empty(9)
    mujoco.mju_quat2Mat(r0, plain.qpos0[a + 3:a + 7] / np.linalg.norm(plain.qpos0[a + 3:a + 7]))
    r0 = r0.reshape(3, 3)
    floor_z = min(float(q0[a + 2]) - _FLOOR_DEPTH, float(np.min(q_log[:, a + 2])) - 0.5)

    def edit(spec) -> None:
        spec.add_texture(name="uvms_water", type=mujoco.mjtTexture.mjTEXTURE_SKYBOX,
                         builtin=mujoco.mjtBuiltin.mjBUILTIN_GRADIENT, rgb1=list(_SKY[0]), rgb2=list(_SKY[1]),
                         width=128, height=768)
        spec.add_texture(name="uvms_floor", type=mujoco.mjtTexture.mjTEXTURE_2D,
                         builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER, rgb1=list(_FLOOR_RGB[0]),
                         rgb2=list(_FLOOR_RGB[1]), width=256, height=256)
        mat = spec.add_material(name="uvms_floor", texrepeat=[25, 25])
        mat.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = "uvms_floor"
        spec.worldbody.add_geom(name="uvms_floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[50.0, 50.0, 0.1],
                                pos=[float(q0[a]), float(q0[a + 1]), floor_z], material="uvms_floor",
                                contype=0, conaffinity=0, group=0)
        spec.worldbody.add_light(name="uvms_sun", type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL,
                                 pos=[0.0, 0.0, 10.0], dir=[0.3, 0.2, -1.0], diffuse=[0.6, 0.6, 0.6],
                                 castshadow=False)
        body = spec.body(layout.base_name)
        for name, (offset, axes) in cams.items():
            local = np.r_[r0.T @ axes[:3], r0.T @ axes[3:]]
            body.add_camera(name=name, mode=mujoco.mjtCamLight.mjCAMLIGHT_TRACK, pos=list(r0.T @ offset),
                            xyaxes=list(local), fovy=fovy)

    try:
        model = compile_robot_spec(path, edit=edit)
    except ParameterError as exc:
        raise ValueError(f"the log's robot model {path}: {exc}") from None
    model.vis.global_.offwidth = max(int(model.vis.global_.offwidth), width)
    model.vis.global_.offheight = max(int(model.vis.global_.offheight), height)
    # water haze: fog from 4 m to 25 m [MuJoCo's unit: the model's extent]
    model.vis.map.fogstart = 4.0 / max(float(model.stat.extent), 1e-6)
    model.vis.map.fogend = 25.0 / max(float(model.stat.extent), 1e-6)
    model.vis.rgba.fog = (*_SKY[0], 1.0)
    return model, layout


def _finite_rows(x: np.ndarray | None, n: int, width: int) -> np.ndarray | None:
    """A (n, width) signal, or None when it is missing, misshapen or never finite."""
    if x is None or x.ndim != 2 or x.shape != (n, width) or not np.isfinite(x).all(axis=1).any():
        return None
    return x


class _RobotReplay:
    """Replay of a robot log (:func:`robot_of`): the robot's own model in a water scene,
    followed by a tracking camera; same interface as :class:`_Replay`."""

    def __init__(self, log, robot: dict, fps: float, size: tuple[int, int], camera: str | int | None,
                 speed: float, max_seconds: float | None, clock: bool, labels: bool = True,
                 title: str | None = None, model_path: str | Path | None = None) -> None:
        import mujoco

        width, height = _check_size(size, fps, speed)
        ts = np.asarray(log.t, dtype=float).ravel()
        q_log = _signal(log, "q_true")
        if q_log is None or q_log.ndim != 2 or len(q_log) != len(ts) or len(ts) < 1:
            raise ValueError("the log has no q_true signal matching its time base: nothing to replay")
        ok = np.isfinite(ts) & np.isfinite(q_log).all(axis=1)
        if not ok.any():
            raise ValueError("the log has no sample with a finite q_true: nothing to replay")
        n = len(ts)
        tip = _finite_rows(_signal(log, "tip_true"), n, 3)
        desired = _finite_rows(_signal(log, "tip_desired"), n, 3)
        ts, q_log = ts[ok], q_log[ok]
        tip = tip[ok] if tip is not None else None
        desired = desired[ok] if desired is not None else None
        if len(ts) == 1:  # a single sample: a still picture of 1 / fps
            dup = lambda a: None if a is None else np.vstack([a, a])  # noqa: E731
            ts, q_log, tip, desired = np.r_[ts, ts + 1.0 / fps], dup(q_log), dup(tip), dup(desired)
        self.ts, self.speed, self.clock, self.height = ts, speed, clock, height
        self.frame_t = _frame_times(ts, fps, speed, max_seconds)

        model, layout = self.model, self.layout = _robot_scene_model(robot, q_log, width, height, model_path)
        self.data = mujoco.MjData(model)
        self.qs = interp_qpos(self.frame_t, ts, q_log, _quat_slots(model))
        self.cam = self._camera(model, camera)
        a = layout.base_qadr
        trace_label = "tip trace"
        if tip is None:  # no tip site (or none logged): trace the vehicle origin
            tip, trace_label = q_log[:, a:a + 3], "vehicle trace"
        self.tip, self.desired = tip, desired
        self.trace_rgba = _RGBA_TRACE if trace_label == "tip trace" else _RGBA_BASE
        self.tip_ok = np.isfinite(tip).all(axis=1)
        self.tip_keep = _thin(_simplify(tip[self.tip_ok], _TRACE_TOL), 300)
        self.desired_pts = None
        if desired is not None:
            d_ok = desired[np.isfinite(desired).all(axis=1)]
            self.desired_pts = d_ok[_thin(_simplify(d_ok, _TRACE_TOL), 300)]
        self.overlay = None
        if labels:
            self.overlay = _labels_overlay(width, height, title if title is not None else _controller_name(log),
                                           None, legend=True, trace_label=trace_label,
                                           desired_label="desired tip path" if desired is not None else None)
        self.renderer = _make_renderer(model, height, width)
        self.renderer.scene.flags[mujoco.mjtRndFlag.mjRND_FOG] = True

    @staticmethod
    def _camera(model, camera: str | int | None) -> int:
        import mujoco

        if camera is None:
            camera = ROBOT_CAMERAS[0]
        if isinstance(camera, str):
            cid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, camera)
            if cid < 0:
                names = [model.camera(i).name for i in range(model.ncam)]
                raise ValueError(f"camera {camera!r} is not in the robot's scene; cameras: {names}")
            return cid
        cid = int(camera)
        if not 0 <= cid < model.ncam:
            raise ValueError(f"camera id {camera!r} out of range 0..{model.ncam - 1}")
        return cid

    def __len__(self) -> int:
        return len(self.frame_t)

    def __iter__(self) -> Iterator[tuple[float, np.ndarray]]:
        ts, tip, renderer = self.ts, self.tip, self.renderer
        scene = renderer.scene
        good_t = ts[self.tip_ok]
        good = tip[self.tip_ok]
        for tf, q in zip(self.frame_t, self.qs):
            self.data.qpos[:] = q
            _pose(self.model, self.data)
            renderer.update_scene(self.data, camera=self.cam)
            if self.desired_pts is not None:
                _add_polyline(scene, self.desired_pts, _RGBA_DESIRED, 2.0)
                now = np.array([np.interp(tf, ts, self.desired[:, j]) for j in range(3)])
                if np.isfinite(now).all():
                    _add_sphere(scene, now, 0.012, _RGBA_DESIRED)
            if len(good):
                k = int(np.searchsorted(good_t, tf, side="right"))
                now = np.array([np.interp(tf, good_t, good[:, j]) for j in range(3)])
                kept = self.tip_keep[: int(np.searchsorted(self.tip_keep, k))]
                pts = np.vstack([good[kept], good[max(k - 1, 0):k], now[None]])
                if len(pts) >= 2:
                    _add_polyline(scene, pts, self.trace_rgba, 4.0)
            frame = renderer.render()
            if self.overlay is not None:
                self.overlay.apply(frame)
            if self.clock:
                text = f"t = {tf:5.2f} s" if self.speed == 1 else f"t = {tf:5.2f} s  x{self.speed:g}"
                _stamp_text(frame, text, scale=max(1, self.height // 240))
            yield float(tf), frame

    def close(self) -> None:
        self.renderer.close()


def _replay(log, fps: float, size: tuple[int, int], camera, speed: float, max_seconds: float | None,
            model_path, clock: bool, labels: bool = True, title: str | None = None):
    """The replay of ``log``: :class:`_RobotReplay` for a robot log, else the paper's :class:`_Replay`."""
    robot = robot_of(log)
    if robot is not None:
        return _RobotReplay(log, robot, fps, size, camera, speed, max_seconds, clock, labels=labels,
                            title=title, model_path=model_path)
    return _Replay(log, fps, size, camera, speed, max_seconds, model_path, clock, labels=labels, title=title)


def _robot_error_mm(log) -> tuple[str, tuple[np.ndarray, np.ndarray]] | None:
    """(what, (t, error norm [mm])) of a robot log: the tip error |tip_desired - tip_true| if
    logged, else the base position error |base_desired[0:3] - q_true[0:3]|, else
    |e_position|; None without any."""
    t = np.asarray(log.t, dtype=float).ravel()
    n = len(t)
    td, tip = _finite_rows(_signal(log, "tip_desired"), n, 3), _finite_rows(_signal(log, "tip_true"), n, 3)
    if td is not None and tip is not None:
        return "end-tip error [mm]", (t, 1e3 * np.linalg.norm(td - tip, axis=1))
    bd, q = _signal(log, "base_desired"), _signal(log, "q_true")
    if bd is not None and q is not None and bd.ndim == 2 and bd.shape[1] >= 3 and len(bd) == n == len(q):
        return "base position error [mm]", (t, 1e3 * np.linalg.norm(bd[:, :3] - q[:, :3], axis=1))
    ep = _finite_rows(_signal(log, "e_position"), n, 3)
    if ep is not None:
        return "base position error [mm]", (t, 1e3 * np.linalg.norm(ep, axis=1))
    return None


def render_frames(
    log,
    fps: float = 30.0,
    size: tuple[int, int] = (640, 480),
    camera: str | int | None = None,
    speed: float = 1.0,
    max_seconds: float | None = None,
    model_path: str | Path | None = None,
    clock: bool = True,
    labels: bool = True,
) -> Iterator[tuple[float, np.ndarray]]:
    """Yield (log time [s], RGB frame (height, width, 3) uint8) for each video frame.

    The frame buffer is reused: copy a frame to keep it past the next iteration.
    See :func:`render_video` for the arguments.
    """
    replay = _replay(log, fps, size, camera, speed, max_seconds, model_path, clock, labels=labels)
    try:
        yield from replay
    finally:
        replay.close()


def _open_writer(out_path: Path, width: int, height: int, fps: float):
    import imageio_ffmpeg

    if width % 2 or height % 2:
        raise ValueError(f"size = ({width}, {height}): H.264 with yuv420p needs even width and height")
    writer = imageio_ffmpeg.write_frames(
        str(out_path), (width, height), fps=fps, codec="libx264", pix_fmt_in="rgb24", pix_fmt_out="yuv420p",
        quality=None, macro_block_size=2, ffmpeg_log_level="error",
        output_params=["-preset", "veryfast", "-crf", "23", "-movflags", "+faststart"],
    )
    writer.send(None)
    return writer


def render_video(
    log,
    out_path: str | Path,
    fps: float = 30,
    size: tuple[int, int] = (640, 480),
    camera: str | int | None = None,
    speed: float = 1.0,
    max_seconds: float | None = None,
    on_frame: Callable[[int, int], None] | None = None,
    model_path: str | Path | None = None,
    labels: bool = True,
) -> dict[str, Any]:
    """Replay a run's true motion into the MuJoCo scene and write an MP4 video.

    A robot log (``meta["robot"]`` with a name other than "paper", :func:`robot_of`) is replayed
    in the robot's own model in a water scene (:func:`_robot_scene_model`: sea floor, light,
    water-coloured background and haze, two follow cameras on the vehicle); its tip trace
    (``tip_true``, or the vehicle origin when the robot has no tip) and the desired tip path
    (``tip_desired``, when logged) are drawn in 3-D.

    Args:
        log: a run (``RunResult`` or a log read back from disk): ``.t`` (N,) and ``.signals``
            with ``q_true`` (N, 5); ``p_desired`` and ``tip_true`` are drawn when present.
        out_path: the MP4 file to write (folders are created).
        fps: video frame rate; frame i shows log time t[0] + i * speed / fps.
        size: (width, height) in pixels (even numbers).
        camera: None for a fixed side view along -Z (image up = +Y) fitted to the whole logged
            motion and the desired path; else a camera of the scene by name ("side", "track") or id.
            Robot logs: "follow_three_quarter" (default) or "follow_side" (:data:`ROBOT_CAMERAS`),
            another camera of the robot's model by name, or an id.
        speed: log seconds per video second.
        max_seconds: cap on the video length [s].
        on_frame: progress callback (frame index, number of frames).
        model_path: scene model (default: the package's models/scene.xml); for a robot log, the
            robot's MJCF file (default: ``meta["robot"]["path"]``, else the built-in of that name).
        labels: draw the controller's name (top right, from the log's metadata), a legend of the
            desired path and the tip trace (bottom left) and, for the fitted side view, a scale
            bar in the plane of motion (bottom right). Drawn once with matplotlib (Agg) and
            composited onto each frame.

    Returns:
        {"path", "frames", "seconds" (video length), "fps", "size", "render_fps" (frames per
        second of scene update + rendering alone), "setup_s" (scene and GL context), "wall_s" (total,
        encoding included)}.

    Raises:
        RenderError: no usable OpenGL (one-line message naming the packages to install).
        ValueError: bad arguments or a log without ``q_true``.
    """
    out_path = Path(out_path)
    width, height = int(size[0]), int(size[1])
    if width % 2 or height % 2:
        raise ValueError(f"size = {size!r}: H.264 with yuv420p needs even width and height")
    t_start = time.perf_counter()
    replay = _replay(log, fps, (width, height), camera, speed, max_seconds, model_path, clock=True, labels=labels)
    setup_s = time.perf_counter() - t_start
    render_s, n, writer = 0.0, 0, None
    try:
        out_path.parent.mkdir(parents=True, exist_ok=True)
        writer = _open_writer(out_path, width, height, fps)
        frames = iter(replay)
        while True:
            t0 = time.perf_counter()
            item = next(frames, None)
            render_s += time.perf_counter() - t0
            if item is None:
                break
            writer.send(np.ascontiguousarray(item[1]))
            n += 1
            if on_frame is not None:
                on_frame(n - 1, len(replay))
    finally:
        replay.close()
        if writer is not None:
            writer.close()
    wall = time.perf_counter() - t_start
    return {
        "path": str(out_path),
        "frames": n,
        "seconds": n / fps,
        "fps": fps,
        "size": (width, height),
        "render_fps": n / render_s if render_s > 0 else float("inf"),
        "setup_s": setup_s,
        "wall_s": wall,
    }


def _paper_compare_replays(log_a, log_b, names, fps, size, strip, speed, max_seconds, model_path):
    """The paper's two replays (the same fitted side view) and the tip-error inset (or None)."""
    half, height = size
    kw = dict(fps=fps, size=(half, height), camera=None, speed=speed, max_seconds=max_seconds,
              model_path=model_path, clock=True)
    a = _Replay(log_a, title=names[0], **kw)
    b = _Replay(log_b, title=names[1], extent=a.extent, **kw)
    if not all(np.array_equal(x, y) for x, y in zip(a.extent, b.extent)):
        a.close()
        a = _Replay(log_a, title=names[0], extent=b.extent, **kw)
    err = None
    if strip:
        series = [(n, e) for n, e in zip(names, (_tip_error_mm(log_a), _tip_error_mm(log_b))) if e is not None]
        err = _ErrorInset(2 * half, strip, series) if series else None
    return a, b, err


def _robot_compare_replays(log_a, log_b, robots, names, fps, size, strip, speed, max_seconds, model_path, camera):
    """Two robot replays (each its own follow camera) and the error inset (or None)."""
    if any(r is None for r in robots):
        which = "first" if robots[0] is None else "second"
        raise ValueError(f"render_compare_video: the {which} log is of the paper's planar robot and the other of "
                         f"robot {next(r for r in robots if r is not None)['name']!r}: comparing a planar and a "
                         "3-D robot side by side is not supported")
    kw = dict(fps=fps, size=size, camera=camera, speed=speed, max_seconds=max_seconds, clock=True,
              model_path=model_path)
    a = _RobotReplay(log_a, robots[0], title=names[0], **kw)
    try:
        b = _RobotReplay(log_b, robots[1], title=names[1], **kw)
    except BaseException:
        a.close()
        raise
    err = None
    if strip:
        found = [_robot_error_mm(log_a), _robot_error_mm(log_b)]
        kinds = {f[0] for f in found if f is not None}
        if len(kinds) == 2:  # one run has a tip error, the other only a base error: show the base error
            found = [f if f is None or f[0].startswith("base") else _robot_error_mm(_without_tip(lg))
                     for f, lg in zip(found, (log_a, log_b))]
            kinds = {f[0] for f in found if f is not None}
        series = [(n, f[1]) for n, f in zip(names, found) if f is not None]
        if series and len(kinds) == 1:
            err = _ErrorInset(2 * size[0], strip, series, title=kinds.pop())
    return a, b, err


def _without_tip(log):
    """A view of a log without its tip_desired signal."""
    from types import SimpleNamespace

    return SimpleNamespace(t=log.t, meta=getattr(log, "meta", {}),
                           signals={k: v for k, v in log.signals.items() if k != "tip_desired"})


def render_compare_video(
    log_a,
    log_b,
    out_path: str | Path,
    fps: float = 30,
    size: tuple[int, int] = (1280, 480),
    speed: float = 1.0,
    max_seconds: float | None = None,
    on_frame: Callable[[int, int], None] | None = None,
    model_path: str | Path | None = None,
    names: tuple[str, str] | None = None,
    inset: bool = True,
    camera: str | int | None = None,
) -> dict[str, Any]:
    """Side-by-side MP4 of two runs (e.g. ``rac`` and ``rac_dob``), with an error inset.

    Each half (``size[0] / 2`` x ``size[1]``) is :func:`render_video`'s fitted side view, both
    with the same view (fitted to both runs, so the scale bars agree), each labelled with its
    controller (or ``names``). Below them (``inset=True``) a strip of height ``size[1] / 4``
    plots the end-tip error |p_ed - p_tip| [mm] of both runs against time with a moving cursor:
    sub-millimetre differences that no side view can show. A run that ends earlier (a
    divergence) holds its last frame. Returns the same dictionary as :func:`render_video`.

    Two robot logs (:func:`robot_of`): each half is that run's robot seen by the same follow
    camera (``camera``: one of :data:`ROBOT_CAMERAS`, default the three-quarter view), and the
    inset plots the end-tip error norm when both runs logged ``tip_desired`` (else the base
    position error norm). A robot log and a paper log cannot be compared (ValueError).
    ``camera`` is for robot logs only (the paper's halves always use the fitted side view).
    """
    out_path = Path(out_path)
    width, height = int(size[0]), int(size[1])
    half = (width // 2) // 2 * 2
    strip = (height // 4) // 2 * 2 if inset else 0
    if half < 16 or height < 16:
        raise ValueError(f"size = {size!r}: too small for two panels")
    if height % 2:
        raise ValueError(f"size = {size!r}: H.264 with yuv420p needs an even height")
    names = tuple(names) if names else (_controller_name(log_a) or "A", _controller_name(log_b) or "B")
    t_start = time.perf_counter()
    robots = (robot_of(log_a), robot_of(log_b))
    if any(r is not None for r in robots):
        a, b, err = _robot_compare_replays(log_a, log_b, robots, names, fps, (half, height), strip, speed,
                                           max_seconds, model_path, camera)
    else:
        a, b, err = _paper_compare_replays(log_a, log_b, names, fps, (half, height), strip, speed, max_seconds,
                                           model_path)
    setup_s = time.perf_counter() - t_start
    total = max(len(a), len(b))
    frame = np.zeros((height + (strip if err is not None else 0), 2 * half, 3), dtype=np.uint8)
    render_s, n, writer = 0.0, 0, None
    try:
        out_path.parent.mkdir(parents=True, exist_ok=True)
        writer = _open_writer(out_path, frame.shape[1], frame.shape[0], fps)
        ia, ib = iter(a), iter(b)
        for i in range(total):
            t0 = time.perf_counter()
            tf = None
            for it, x0 in ((ia, 0), (ib, half)):
                item = next(it, None)
                if item is not None:
                    frame[:height, x0:x0 + half] = item[1]
                    tf = item[0] if tf is None else max(tf, item[0])
            if err is not None and tf is not None:
                frame[height:] = err.frame(tf)
            render_s += time.perf_counter() - t0
            writer.send(np.ascontiguousarray(frame))
            n += 1
            if on_frame is not None:
                on_frame(i, total)
    finally:
        a.close()
        b.close()
        if writer is not None:
            writer.close()
    return {
        "path": str(out_path),
        "frames": n,
        "seconds": n / fps,
        "fps": fps,
        "size": (frame.shape[1], frame.shape[0]),
        "render_fps": n / render_s if render_s > 0 else float("inf"),
        "setup_s": setup_s,
        "wall_s": time.perf_counter() - t_start,
    }
