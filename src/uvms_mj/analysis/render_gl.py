"""Headless OpenGL for the renderers: which backend, chosen when rendering starts.

MuJoCo binds its OpenGL backend (``mujoco.gl_context.GLContext``) from ``$MUJOCO_GL`` once, when
``mujoco`` is first imported, and dm_control binds its own (``dm_control._render.Renderer``)
when it is imported. Importing uvms_mj sets nothing; the choice is made when a renderer starts:

* :func:`_make_renderer` (every ``mujoco.Renderer`` of :mod:`uvms_mj.analysis.render`): with
  ``MUJOCO_GL`` unset on Linux without a display (neither ``DISPLAY`` nor ``WAYLAND_DISPLAY``),
  mujoco was imported with its GLFW default, which needs a display: the renderer's context is
  then constructed explicitly with ``mujoco.egl.GLContext`` if ``libEGL.so.1`` and
  ``libOpenGL.so.0`` (or ``libGL``) load, else ``mujoco.osmesa.GLContext`` if ``libOSMesa``
  loads; with a display, or ``MUJOCO_GL`` set, mujoco's own choice is used;
* :func:`dm_control_context_class` (the rl environment's ``render``): the same choice among
  dm_control's EGL and OSMesa contexts;
* :func:`configure_gl`, for a rendering-only entry path that runs before anything imports
  mujoco, sets ``MUJOCO_GL`` to that headless backend instead (never called by uvms_mj itself).

``MUJOCO_GL`` set to a value MuJoCo rejects, or to ``egl``/``osmesa`` whose library cannot be
loaded, makes ``import mujoco`` itself fail. :func:`guard_mujoco_import` (run by the lazy
attributes of ``uvms_mj``, e.g. ``uvms_mj.Plant``, before they import mujoco) then imports mujoco
with rendering disabled, so that simulation keeps working, puts the user's value back (os.environ
ends as it was) and remembers the problem for the renderer.

Every rendering problem (the remembered one, no backend library, a GL context that cannot be
created) surfaces as a :class:`RenderError` whose message is one line naming the Debian packages
to install: ``libegl1 libegl-mesa0 libgl1-mesa-dri libopengl0`` (EGL, Mesa's llvmpipe software
rasterizer when there is no GPU) or ``libosmesa6`` (``MUJOCO_GL=osmesa``).
"""

from __future__ import annotations

import ctypes
import os
import platform
import sys
from typing import Any

__all__ = ["DEBIAN_PACKAGES", "RenderError", "configure_gl", "dm_control_context_class", "gl_status",
           "guard_mujoco_import"]

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


def _gl_problem(raw: str | None) -> str | None:
    """Why ``import mujoco`` would fail or render nothing with ``MUJOCO_GL=raw`` (None: fine)."""
    value = (raw or "").strip().lower()
    if not value:
        return None
    if value in _MUJOCO_GL_OFF:
        return f"rendering is disabled by MUJOCO_GL={raw}: unset it (or set MUJOCO_GL=egl)"
    if value not in _MUJOCO_GL_VALID:
        return (f"MUJOCO_GL={raw!r} is not a valid OpenGL backend: use MUJOCO_GL=egl (or osmesa) to render "
                f"without a display, glfw with one")
    missing = _missing_libs(value)
    if missing:
        return f"MUJOCO_GL={raw} but {', '.join(missing)} cannot be loaded: {_install_hint()}"
    return None


def guard_mujoco_import() -> None:
    """Before the first ``import mujoco``: if ``MUJOCO_GL`` would make it fail (a value MuJoCo
    rejects, a backend whose library cannot load), import mujoco with rendering disabled, put
    the user's value back and remember the problem (raised by the renderer as a
    :class:`RenderError`). Nothing else; never raises. os.environ ends as it was."""
    if "mujoco" in sys.modules or platform.system() != "Linux":
        return
    raw = os.environ.get("MUJOCO_GL")
    problem = _gl_problem(raw)
    if problem is None:
        return
    _GL_STATE["problem"] = problem
    if (raw or "").strip().lower() in _MUJOCO_GL_OFF:
        return  # mujoco imports fine (without rendering)
    os.environ["MUJOCO_GL"] = "disable"
    try:
        import mujoco  # noqa: F401
    finally:
        os.environ["MUJOCO_GL"] = raw  # type: ignore[assignment]


def _headless_backend() -> str | None:
    """"egl" or "osmesa", whichever loads first, for Linux without a display; None otherwise."""
    if platform.system() != "Linux" or not _headless():
        return None
    return next((b for b in ("egl", "osmesa") if not _missing_libs(b)), None)


def configure_gl() -> None:
    """Set ``MUJOCO_GL`` for a rendering-only entry path, before anything imports mujoco: on Linux
    without a display and with ``MUJOCO_GL`` unset, the headless backend that loads (``egl``,
    else ``osmesa``); a user's value is checked (:func:`guard_mujoco_import`), never replaced.
    Not called by uvms_mj (its renderers choose when they start, see the module docstring).
    Never raises."""
    if "mujoco" in sys.modules or platform.system() != "Linux":
        return  # too late to choose, or not our business (macOS: CGL, Windows: WGL)
    if (os.environ.get("MUJOCO_GL") or "").strip():
        guard_mujoco_import()
        return
    backend = _headless_backend()
    if backend is not None:
        os.environ["MUJOCO_GL"] = backend
        _GL_STATE["auto"] = backend


def gl_status() -> dict[str, Any]:
    """The OpenGL backend of mujoco: {'backend' (of ``mujoco.gl_context``; the renderers may
    construct an EGL/OSMesa context instead, module docstring), 'auto' (chosen by
    :func:`configure_gl`), 'problem'}."""
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


def _first_headless(load):
    """``load(backend)`` for the first of EGL, then OSMesa, whose libraries are there and that
    loads; RenderError (one line: why each failed, what to install) if none does."""
    errors = []
    for backend in ("egl", "osmesa"):
        missing = _missing_libs(backend)
        if missing:
            errors.append(f"{backend}: no {missing[0]}")
            continue
        try:
            return load(backend)
        except Exception as exc:  # noqa: BLE001 (PyOpenGL raises anything from ImportError to RuntimeError)
            errors.append(f"{backend}: {_first_line(exc)}")
    raise RenderError(f"no OpenGL backend for rendering without a display ({'; '.join(errors)}): {_install_hint()}")


def _headless_context_class():
    """EGL or OSMesa GLContext class for a MuJoCo imported with the GLFW default, or RenderError."""
    def load(backend):
        if backend == "egl":
            from mujoco.egl import GLContext
        else:
            from mujoco.osmesa import GLContext
        return GLContext

    return _first_headless(load)


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
        use = _headless_context_class()  # MUJOCO_GL unset, no display: construct EGL/OSMesa ourselves
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


def _close_renderer(renderer) -> None:
    """Close a ``mujoco.Renderer`` with its own GL context current. ``Renderer.close`` frees its
    MuJoCo render context (framebuffers, textures) in whatever context is current, which is
    another renderer's after that one rendered: the other renderer's offscreen buffer was freed and
    its frames came out upside down and partly garbage (a comparison video whose first replay was
    rebuilt on the shared view; ``tests/test_render.py``)."""
    gl = getattr(renderer, "_gl_context", None)
    if gl is not None and getattr(renderer, "_mjr_context", None) is not None:
        try:
            gl.make_current()
        except Exception:  # noqa: BLE001 (a context already gone: close frees what is left)
            pass
    renderer.close()


def dm_control_context_class():
    """The OpenGL context class dm_control's ``Physics`` should create for rendering now: its own
    choice (``dm_control._render.Renderer``), except on Linux without a display where dm_control
    chose GLFW by itself (``MUJOCO_GL`` unset): then its EGL context, else its OSMesa one.

    Raises:
        RenderError: no headless backend loads (one line with the Debian packages to install).
    """
    from dm_control import _render

    if _GL_STATE["problem"]:
        raise RenderError(_GL_STATE["problem"])
    if (os.environ.get("MUJOCO_GL") or "").strip() or _render.BACKEND != "glfw" \
            or platform.system() != "Linux" or not _headless():
        return _render.Renderer
    def load(backend):
        if backend == "egl":
            from dm_control._render.pyopengl.egl_renderer import EGLContext as cls
        else:
            from dm_control._render.pyopengl.osmesa_renderer import OSMesaContext as cls
        return cls

    return _first_headless(load)
