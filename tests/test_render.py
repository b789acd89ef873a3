"""Off-screen video of a run (uvms_mj.analysis.render): frame count and size, non-blank frames, the
robot framed and moving, and a one-line RenderError when OpenGL cannot load.

Needs the headless GL packages (Debian: libegl1 libegl-mesa0 libgl1-mesa-dri libopengl0, or
libosmesa6); without them every rendering test fails with that install hint.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path
from types import SimpleNamespace

import imageio.v2 as iio2
import numpy as np
import pytest

from uvms_mj.sim.experiment import PaperExperiment
from uvms_mj.analysis.render import RenderError, render_frames, render_video

DURATION = 2.0  # s of simulated motion
FPS = 30
SIZE = (320, 240)


@pytest.fixture(scope="module")
def run():
    # A faster tip path than the paper's (0.3 m/s instead of 0.02 m/s, after 1 s at rest) so that
    # the arm visibly moves (0.15 m) within the clip.
    return PaperExperiment(duration=DURATION, cruise_speed=0.3).run()


def _orange(frame: np.ndarray) -> np.ndarray:
    """Pixels of the base's orange box (rgba 0.85 0.55 0.15, lit)."""
    r, g, b = (frame[..., i].astype(int) for i in range(3))
    return (r > 150) & (r - b > 90) & (g > 70) & (g < r - 30)


def _moving_region(frame: np.ndarray) -> np.ndarray:
    """The frame without the clock box in the top-left corner."""
    out = frame.astype(float).copy()
    out[:40, :160] = 0.0
    return out


def test_video_frames_size_and_content(run, tmp_path: Path) -> None:
    out = tmp_path / "sub" / "run.mp4"
    progress = []
    info = render_video(run, out, fps=FPS, size=SIZE, on_frame=lambda i, n: progress.append((i, n)))
    expected = round((run.t[-1] - run.t[0]) * FPS)
    assert info["frames"] == expected == 60
    assert info["seconds"] == pytest.approx(expected / FPS)
    assert progress[0] == (0, expected) and progress[-1] == (expected - 1, expected)
    assert out.is_file() and out.stat().st_size > 1000

    reader = iio2.get_reader(out, format="FFMPEG")
    try:
        meta = reader.get_meta_data()
        frames = [np.asarray(f) for f in reader]
    finally:
        reader.close()
    assert meta["codec"] == "h264" and meta["pix_fmt"].startswith("yuv420p")
    assert meta["fps"] == pytest.approx(FPS)
    assert len(frames) == expected
    assert all(f.shape == (SIZE[1], SIZE[0], 3) for f in frames)
    first, last = frames[0], frames[-1]
    for f in (first, last):
        assert f.std() > 10.0, "blank frame"
    # The robot moved: the picture changed outside the clock (H.264 noise is ~1 grey level).
    diff = np.abs(_moving_region(first) - _moving_region(last)).mean(axis=2)
    assert (diff > 30).sum() > 100, f"only {(diff > 30).sum()} pixels changed between first and last frame"


def test_camera_frames_the_robot(run) -> None:
    frames = [f.copy() for _, f in render_frames(run, fps=10, size=SIZE)]
    for f in (frames[0], frames[-1]):
        base = _orange(f)
        share = base.mean()
        assert 0.05 < share < 0.6, f"base covers {share:.1%} of the frame"
        rows, cols = np.flatnonzero(base.any(axis=1)), np.flatnonzero(base.any(axis=0))
        # whole base inside the frame, not touching the borders
        assert rows[0] > 2 and rows[-1] < SIZE[1] - 3 and cols[0] > 2 and cols[-1] < SIZE[0] - 3
        # side view, image up = +Y: the base (y ~ 0) sits above the arm's tip (y ~ -0.47),
        # so the orange box is in the upper part of the picture
        assert rows.mean() < 0.6 * SIZE[1]


def test_traces_drawn(run) -> None:
    """The desired path (green) and the tip trace (red) appear in the last frame."""
    *_, (_, last) = render_frames(run, fps=10, size=(640, 480))
    r, g, b = (last[..., i].astype(int) for i in range(3))
    green = (g > 180) & (r < 120) & (b < 150)
    red = (r > 180) & (g < 150) & (b < 150) & ~_orange(last)
    assert green.sum() > 50 and red.sum() > 20


def test_speed_max_seconds_and_minimal_log(tmp_path: Path) -> None:
    t = np.arange(0, 2.0 + 1e-9, 1 / 60)
    q = np.tile([0.0, 0.0, -np.pi / 2, np.pi / 3, -5 * np.pi / 18], (len(t), 1))
    q[:, 0] = 0.1 * t  # the base slides right
    log = SimpleNamespace(t=t, signals={"q_true": q}, meta={})  # no p_desired, no tip_true
    info = render_video(log, tmp_path / "fast.mp4", fps=FPS, size=(160, 120), speed=2.0)
    assert info["frames"] == round(2.0 / 2.0 * FPS)
    info = render_video(log, tmp_path / "capped.mp4", fps=FPS, size=(160, 120), max_seconds=0.5)
    assert info["frames"] == round(0.5 * FPS)
    with pytest.raises(ValueError, match="even"):
        render_video(log, tmp_path / "odd.mp4", size=(161, 120))
    with pytest.raises(ValueError, match="q_true"):
        render_video(SimpleNamespace(t=t, signals={}, meta={}), tmp_path / "none.mp4")


_CHILD = textwrap.dedent(
    """
    import ctypes, sys
    if sys.argv[1] == "hide":  # pretend the EGL and OSMesa libraries are not installed
        real = ctypes.CDLL.__init__
        def fake(self, name, *args, **kwargs):
            if name and ("EGL" in str(name) or "OSMesa" in str(name)):
                raise OSError(f"{name}: cannot open shared object file: No such file or directory")
            return real(self, name, *args, **kwargs)
        ctypes.CDLL.__init__ = fake
    from types import SimpleNamespace
    import numpy as np
    import uvms_mj
    from uvms_mj.analysis.render import RenderError, render_video
    plant = uvms_mj.Plant()  # simulation still works without GL
    plant.step(10)
    t = np.linspace(0, 0.2, 13)
    log = SimpleNamespace(t=t, signals={"q_true": np.tile(plant.q, (13, 1))}, meta={})
    try:
        render_video(log, sys.argv[2])
    except RenderError as exc:
        print(f"error: {exc}")
        sys.exit(3)
    print("rendered")
    """
)


def _child(mode: str, gl: str | None, tmp_path: Path) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM", "DISPLAY",
                                                           "WAYLAND_DISPLAY")}
    if gl is not None:
        env["MUJOCO_GL"] = gl
    return subprocess.run([sys.executable, "-c", _CHILD, mode, str(tmp_path / "x.mp4")], env=env,
                          capture_output=True, text=True, timeout=60)


@pytest.mark.parametrize(
    "mode, gl, expect",
    [
        ("plain", "no-such-backend", "MUJOCO_GL='no-such-backend' is not a valid"),
        ("hide", None, "libegl1 libegl-mesa0 libgl1-mesa-dri libopengl0"),
        ("hide", "egl", "MUJOCO_GL=egl but libEGL.so.1 cannot be loaded"),
        ("hide", "osmesa", "libosmesa6"),
    ],
)
def test_gl_failure_is_one_clear_line(tmp_path: Path, mode: str, gl: str | None, expect: str) -> None:
    proc = _child(mode, gl, tmp_path)
    assert proc.returncode == 3, proc.stdout + proc.stderr
    assert "Traceback" not in proc.stderr, proc.stderr
    lines = proc.stdout.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), proc.stdout
    assert expect in lines[0]
    assert "apt-get install" in lines[0] or "not a valid" in lines[0]
    assert not (tmp_path / "x.mp4").exists()


def test_default_backend_chosen_in_child(tmp_path: Path) -> None:
    """With MUJOCO_GL unset and no display, importing uvms_mj picks a headless backend."""
    proc = _child("plain", None, tmp_path)
    assert proc.returncode == 0 and proc.stdout.strip() == "rendered", proc.stdout + proc.stderr
    assert "Exception ignored" not in proc.stderr, proc.stderr


@pytest.mark.parametrize("extra, expect", [
    ({"DISPLAY": ":99"}, "None"),            # a display: MuJoCo's GLFW default, nothing set
    ({"WAYLAND_DISPLAY": "wayland-9"}, "None"),
    ({"MUJOCO_GL": "osmesa"}, "osmesa"),     # the user's choice is kept
    ({}, "egl"),                             # headless, unset: a headless backend
])
def test_configure_gl_only_chooses_for_headless(extra: dict, expect: str) -> None:
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM", "DISPLAY",
                                                           "WAYLAND_DISPLAY")}
    env.update(extra)
    code = ("import os, sys; from uvms_mj.analysis.render import configure_gl; configure_gl(); "
            "print(os.environ.get('MUJOCO_GL'))")
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60)
    got = proc.stdout.strip()
    if expect == "egl":
        assert got in ("egl", "osmesa"), proc.stdout + proc.stderr
    else:
        assert got == expect, proc.stdout + proc.stderr


def test_render_error_type() -> None:
    assert issubclass(RenderError, RuntimeError)


def test_labels_scale_bar_and_name(run) -> None:
    """Labels (controller name top right, legend bottom left, scale bar bottom right) change only
    their corners; the scale bar has the length of the plane of motion's metres."""
    from uvms_mj.analysis.render import _labels_overlay, _nice_length

    plain = next(iter(render_frames(run, fps=10, size=SIZE, labels=False)))[1].copy()
    labelled = next(iter(render_frames(run, fps=10, size=SIZE)))[1].copy()
    diff = np.abs(labelled.astype(int) - plain.astype(int)).max(axis=2) > 40
    h, w = diff.shape
    assert diff[: h // 4, 3 * w // 4:].any()        # name
    assert diff[3 * h // 4:, : w // 3].any()        # legend
    assert diff[3 * h // 4:, 2 * w // 3:].any()     # scale bar
    assert not diff[h // 3: 2 * h // 3, w // 3: 2 * w // 3].any()  # the robot is untouched
    assert _nice_length(0.37) == 0.2 and _nice_length(0.07) == 0.05 and _nice_length(1.0) == 1.0
    ov = _labels_overlay(400, 300, None, 1000.0, legend=False)  # 1000 px/m: a 0.1 m bar = 100 px
    img = np.zeros((300, 400, 3), np.uint8)
    ov.apply(img)
    white = img.min(axis=2) > 200
    assert 98 <= white.sum(axis=1).max() <= 102  # the bar's rows (the label's rows are shorter)


def test_compare_video_side_by_side(run, tmp_path: Path) -> None:
    from uvms_mj.analysis.render import render_compare_video

    other = PaperExperiment(duration=1.0, cruise_speed=0.3, controller="rac").run()  # shorter
    out = tmp_path / "ab.mp4"
    info = render_compare_video(other, run, out, fps=10, size=(320, 160))
    assert info["frames"] == 20 and info["size"] == (320, 160 + 40)
    reader = iio2.get_reader(out, format="FFMPEG")
    try:
        frames = [np.asarray(f) for f in reader]
    finally:
        reader.close()
    assert len(frames) == 20 and frames[0].shape == (200, 320, 3)
    last = frames[-1]
    assert _orange(last[:160, :160]).sum() > 50 and _orange(last[:160, 160:]).sum() > 50  # two robots
    # the inset's cursor moves with time
    assert np.abs(frames[2][160:].astype(int) - frames[-1][160:].astype(int)).max() > 100


def test_closing_one_replay_leaves_the_others_frames(run) -> None:
    """Two replays in one process (a comparison; the paper's first replay is rebuilt on the
    shared view): closing one must not free the other's offscreen buffer. mujoco.Renderer.close
    frees its render context in whatever GL context is current, so the second replay's frames came
    out upside down and partly garbage until the renderer's own context was made current first
    (render_gl._close_renderer). The survivor's frame is the same picture before and after (at
    most 1 level: the same renderer drawing the same scene)."""
    from uvms_mj.analysis.render_scene import _Replay

    res = run
    kw = dict(fps=5, size=(160, 120), camera=None, speed=1.0, max_seconds=None, model_path=None, clock=True)
    b = _Replay(res, **kw)
    try:
        before = next(iter(b))[1].copy()
        a = _Replay(res, **kw)
        next(iter(a))
        next(iter(b))  # b's GL context is the current one when a closes
        a.close()
        after = next(iter(b))[1]
        assert np.abs(before.astype(int) - after).max() <= 1
    finally:
        b.close()
