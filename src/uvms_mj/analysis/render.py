"""Off-screen video of a logged run (no simulation: the log's true state is replayed).

:func:`render_video` interpolates ``q_true`` to the video frame times, sets it as ``qpos`` of a
plain ``MjData`` of the scene model (``models/paper/scene.xml``), runs ``mj_kinematics`` (with
``mj_comPos`` and ``mj_camlight`` for the cameras) and renders
with ``mujoco.Renderer``; the desired end-tip path (``p_desired[:, 3:5]``) and the tip's trace so
far (``tip_true``) are drawn as user geoms, a small clock in the top-left corner, and the frames
are piped to the ffmpeg that ships with imageio-ffmpeg (H.264, yuv420p, MP4).

Robot logs (any floating robot, ``meta["robot"]``): the robot's MJCF file is compiled
(:func:`uvms_mj.plant.robot.compile_robot_spec`) with an underwater scene added to its MjSpec (a
sand-coloured sea floor 3 m below the vehicle's start, haze in the water's colour, daylight
dimmed with depth; :mod:`.render_robot`) and three cameras on the vehicle body in MuJoCo's
"track" mode (:data:`ROBOT_CAMERAS`: position follows the vehicle, orientation fixed in the
world; framed on the robot's geometry and its paths by :mod:`.render_camera`; the default
``follow_arm`` looks from the arm's side); ``q_true`` is interpolated to the frame times
(positions and angles linearly, quaternions by normalised lerp), and the tip trace and desired
tip path are drawn in world coordinates (m, z up). The scale bar holds at the vehicle's distance
from the camera.

A log read for a video (:func:`uvms_mj.analysis.render_stream.read_render_log`, what ``uvms-mj
render`` and ``run --video`` use) is held in memory that does not grow with its length: the
camera, the drawn paths and the compare inset come from the figures' min/max envelope of the log,
and a long log's frames are interpolated from a second pass over its file, block by block
(:class:`~uvms_mj.analysis.render_stream.FrameStates`); a short log (or a run) is replayed from its
arrays, as before.

The work is split by responsibility: :mod:`.render_gl` (the OpenGL backend, chosen when a
renderer starts; :class:`RenderError`), :mod:`.render_overlay` (clock, labels, error inset),
:mod:`.render_scene` (the paper robot's scene and replay), :mod:`.render_robot` (any floating
robot's scene and replay), :mod:`.render_stream` (the frames' states from blocks of samples);
this module writes the videos and lays out comparisons, and re-exports the public names of the
others, so ``uvms_mj.analysis.render`` stays the one import path.
"""

from __future__ import annotations

import errno
import os
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np

from uvms_mj.io.atomic import atomic_path
from uvms_mj.analysis.render_overlay import _ErrorInset, _controller_name, _tip_error_mm
from uvms_mj.analysis.render_scene import _Replay
from uvms_mj.analysis.render_robot import _RobotReplay, _replay, _robot_error_mm, robot_of

# The public names of the split modules, importable from here as before (and the private
# helpers that tests and benchmarks reach through this module).
from uvms_mj.analysis.render_gl import (  # noqa: F401
    DEBIAN_PACKAGES,
    RenderError,
    configure_gl,
    dm_control_context_class,
    gl_status,
    guard_mujoco_import,
)
from uvms_mj.analysis.render_overlay import _labels_overlay, _nice_length  # noqa: F401
from uvms_mj.analysis.render_robot import ROBOT_CAMERAS, _robot_file, interp_qpos  # noqa: F401

__all__ = ["RenderError", "DEBIAN_PACKAGES", "ROBOT_CAMERAS", "configure_gl", "gl_status", "interp_qpos",
           "render_compare_video", "render_frames", "render_video", "robot_of"]


def _cpu_now() -> float:
    """CPU seconds used so far by this process (all threads: llvmpipe's too) and its waited-for
    children (ffmpeg once it has exited)."""
    try:
        import resource
    except ImportError:  # not on Unix: this process only
        return time.process_time()
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + kids.ru_utime + kids.ru_stime


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


_ERRNO_TEXT = {os.strerror(e): e for e in (errno.ENOSPC, errno.EDQUOT, errno.EACCES, errno.EROFS, errno.EIO)}


class _VideoWriter:
    """The ffmpeg of imageio-ffmpeg encoding RGB frames from a pipe (H.264, yuv420p, MP4 with
    +faststart). :meth:`close` waits for ffmpeg and raises OSError (one line: ffmpeg's last
    message, errno ENOSPC etc. when it names one) when it failed, e.g. on a full disk, instead of
    leaving a broken MP4 behind a success; :meth:`abort` kills it. Write to a temporary path
    (:func:`uvms_mj.io.atomic.atomic_path`) so that a failed video never has the final name."""

    def __init__(self, out_path: Path, width: int, height: int, fps: float) -> None:
        import imageio_ffmpeg

        if width % 2 or height % 2:
            raise ValueError(f"size = ({width}, {height}): H.264 with yuv420p needs even width and height")
        cmd = [imageio_ffmpeg.get_ffmpeg_exe(), "-y", "-loglevel", "error", "-f", "rawvideo", "-vcodec", "rawvideo",
               "-s", f"{width}x{height}", "-pix_fmt", "rgb24", "-r", f"{fps:.12g}", "-i", "-", "-an",
               "-vcodec", "libx264", "-pix_fmt", "yuv420p", "-preset", "veryfast", "-crf", "23",
               "-movflags", "+faststart", "-f", "mp4", str(out_path)]
        self._err = tempfile.TemporaryFile()
        # Its own session: a Ctrl-C reaches us, not ffmpeg (we stop it; as imageio-ffmpeg does).
        self._p = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=self._err,
                                   start_new_session=True)

    def _failure(self, rc) -> OSError:
        self._err.seek(0)
        lines = [ln.strip() for ln in self._err.read().decode("utf-8", "replace").splitlines() if ln.strip()]
        self._err.close()
        last = lines[-1] if lines else f"exit status {rc}"
        code = next((e for text, e in _ERRNO_TEXT.items() if any(text in ln for ln in lines)), errno.EIO)
        return OSError(code, f"ffmpeg failed: {os.strerror(code)} ({last[:200]})")

    def send(self, frame: np.ndarray) -> None:
        try:
            self._p.stdin.write(memoryview(np.ascontiguousarray(frame)).cast("B"))
        except (BrokenPipeError, OSError):
            self._p.kill()
            raise self._failure(self._p.wait()) from None

    def close(self) -> None:
        try:
            self._p.stdin.close()
        except OSError:
            pass
        rc = self._p.wait()
        if rc != 0:
            raise self._failure(rc)
        self._err.close()

    def abort(self) -> None:
        self._p.kill()
        self._p.wait()
        self._err.close()


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
    in the robot's own model in a water scene (:func:`_robot_scene_model`: sea floor, lights,
    haze and background in the water's colour, three follow cameras on the vehicle); its tip trace
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
            Robot logs: "follow_arm" (default), "follow_three_quarter" or "follow_side" (:data:`ROBOT_CAMERAS`),
            another camera of the robot's model by name, or an id.
        speed: log seconds per video second.
        max_seconds: cap on the video length [s].
        on_frame: progress callback (frame index, number of frames).
        model_path: scene model (default: the package's models/paper/scene.xml); for a robot log, the
            robot's MJCF file (default: ``meta["robot"]["path"]``, else the built-in of that name).
        labels: draw the controller's name (top right, from the log's metadata), a legend of the
            desired path and the tip trace (bottom left) and a scale bar (bottom right): for the
            fitted side view in the plane of motion, for a robot's follow camera at the vehicle's
            distance (none for another camera of the model). Drawn once with matplotlib (Agg) and
            composited onto each frame.

    Returns:
        {"path", "frames", "seconds" (video length), "fps", "size", "render_fps" (frames per
        second of scene update + rendering alone), "setup_s" (scene and GL context), "wall_s" (total,
        encoding included), "cpu_s" (CPU seconds of this process, all its threads, and of ffmpeg)}.

    Raises:
        RenderError: no usable OpenGL (one-line message naming the packages to install).
        ValueError: bad arguments or a log without ``q_true``.
    """
    out_path = Path(out_path)
    width, height = int(size[0]), int(size[1])
    if width % 2 or height % 2:
        raise ValueError(f"size = {size!r}: H.264 with yuv420p needs even width and height")
    t_start, cpu_start = time.perf_counter(), _cpu_now()
    replay = _replay(log, fps, (width, height), camera, speed, max_seconds, model_path, clock=True, labels=labels)
    setup_s = time.perf_counter() - t_start
    render_s, n = 0.0, 0
    try:
        with atomic_path(out_path) as tmp:
            writer = _VideoWriter(tmp, width, height, fps)
            try:
                frames = iter(replay)
                while True:
                    t0 = time.perf_counter()
                    item = next(frames, None)
                    render_s += time.perf_counter() - t0
                    if item is None:
                        break
                    writer.send(item[1])
                    n += 1
                    if on_frame is not None:
                        on_frame(n - 1, len(replay))
            except BaseException:
                writer.abort()
                raise
            writer.close()
    finally:
        replay.close()
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
        "cpu_s": _cpu_now() - cpu_start,
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
    """Two robot replays (the same follow camera, framed on both runs) and the error inset (or None)."""
    if any(r is None for r in robots):
        which = "first" if robots[0] is None else "second"
        raise ValueError(f"render_compare_video: the {which} log is of the paper's planar robot and the other of "
                         f"robot {next(r for r in robots if r is not None)['name']!r}: comparing a planar and a "
                         "3-D robot side by side is not supported")
    kw = dict(fps=fps, size=size, camera=camera, speed=speed, max_seconds=max_seconds, clock=True,
              model_path=model_path)
    # each framed on both runs' motion: the same cameras, so the two scale bars agree
    a = _RobotReplay(log_a, robots[0], title=names[0], frame_also=log_b, **kw)
    try:
        b = _RobotReplay(log_b, robots[1], title=names[1], frame_also=log_a, **kw)
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
    camera (``camera``: one of :data:`ROBOT_CAMERAS`, default ``follow_arm``), and the
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
    t_start, cpu_start = time.perf_counter(), _cpu_now()
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
    render_s, n = 0.0, 0
    try:
        with atomic_path(out_path) as tmp:
            writer = _VideoWriter(tmp, frame.shape[1], frame.shape[0], fps)
            try:
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
                    writer.send(frame)
                    n += 1
                    if on_frame is not None:
                        on_frame(i, total)
            except BaseException:
                writer.abort()
                raise
            writer.close()
    finally:
        a.close()
        b.close()
    return {
        "path": str(out_path),
        "frames": n,
        "seconds": n / fps,
        "fps": fps,
        "size": (frame.shape[1], frame.shape[0]),
        "render_fps": n / render_s if render_s > 0 else float("inf"),
        "setup_s": setup_s,
        "wall_s": time.perf_counter() - t_start,
        "cpu_s": _cpu_now() - cpu_start,
    }
