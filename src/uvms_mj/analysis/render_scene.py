"""The paper robot's replay (:mod:`uvms_mj.analysis.render`): the scene model
(``models/paper/scene.xml`` through :func:`uvms_mj.physics.model.load_spec`, which registers the uvms
plugins on first use, plus a camera placed to fit the robot's extent), the desired path and
tip trace as user geoms, frame times and the frames of one log (:class:`_Replay`)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Iterator

import numpy as np

from uvms_mj.analysis.render_gl import _close_renderer, _make_renderer
from uvms_mj.analysis.render_overlay import (
    _RGBA_DESIRED,
    _RGBA_TRACE,
    _controller_name,
    _decimate,
    _interp,
    _labels_overlay,
    _signal,
    _simplify,
    _stamp_text,
    _thin,
)
from uvms_mj.analysis.render_stream import _STREAMED_PAPER, _streamed_span, frame_states, hold_single


# ------------------------------------------------------------------ scene


def _scene_model(model_path: str | Path | None, width: int, height: int):
    """Scene model compiled with one extra fixed camera ("uvms_render") that we place ourselves."""
    from uvms_mj.physics.model import load_spec

    if model_path is None:
        from uvms_mj.plant.plant import default_model_path

        model_path = default_model_path()
    spec = load_spec(model_path)  # registers the uvms plugins on first use (or strips them: Python paths)
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
        self._tip_logged = tip is not None and tip.ndim == 2 and tip.shape[1] >= 2 and len(tip) == len(ts)
        pd = _signal(log, "p_desired")
        self._has_desired = pd is not None and pd.ndim == 2 and pd.shape[1] >= 5 and len(pd) == len(ts)
        self._log = log
        model = self.model = _scene_model(model_path, width, height)
        data = self.data = mujoco.MjData(model)
        self.nq = min(model.nq, q_log.shape[1])
        # no logged tip: the model's "tip" site
        self._tip_site = (model.site("tip").id if not self._tip_logged
                          and mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, "tip") >= 0 else None)
        whole = self._series(ts, {k: _signal(log, k) for k in _STREAMED_PAPER})
        if not len(whole["q"][0]):
            raise ValueError("the log has no sample with a finite q_true: nothing to replay")
        whole = self._whole = hold_single(whole, 1.0 / fps)  # a single sample: a still picture of 1 / fps
        ts, q_log = whole["q"]
        tip = whole["tip"][1] if "tip" in whole else None
        desired = whole["desired"][1] if "desired" in whole else None
        self.ts, self.speed, self.clock, self.height = ts, speed, clock, height
        span = _streamed_span(log, [k for k in ("q_true", "tip_true", "p_desired") if k in log.signals])
        self.frame_t = _frame_times(np.asarray(span) if span is not None else ts, fps, speed, max_seconds)
        self._has_tip = tip is not None

        # Camera: the fitted side view, or a camera of the scene.
        stride = _decimate(len(self.frame_t), 60)
        lo, hi, z_robot = _robot_extent(model, data, _interp(np.r_[self.frame_t[::stride], self.frame_t[-1:]],
                                                             ts, q_log))
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
        self.trace_t, self.trace_pts = np.zeros(0), np.zeros((0, 2))
        if tip is not None:
            keep = _thin(_simplify(tip, _TRACE_TOL), 300)
            self.trace_t, self.trace_pts = ts[keep], tip[keep]
        self.overlay = None
        if labels:
            self.overlay = _labels_overlay(width, height, title if title is not None else _controller_name(log),
                                           px_per_m, legend=desired is not None or tip is not None)
        self.renderer = _make_renderer(model, height, width)

    def __len__(self) -> int:
        return len(self.frame_t)

    def _series(self, t: np.ndarray, signals) -> dict:
        """The replayed series of one block (or of the whole log): of the samples whose time,
        q_true, tip (x, y) and desired tip (``p_desired[3:5]``) are finite, ``q`` (its first
        ``nq`` values), ``tip`` (logged, else the model's "tip" site; absent without either) and
        ``desired``."""
        import mujoco

        t = np.asarray(t, dtype=float).ravel()
        q = np.asarray(signals["q_true"], dtype=float)
        tip = np.asarray(signals["tip_true"], dtype=float)[:, :2] if self._tip_logged else None
        desired = np.asarray(signals["p_desired"], dtype=float)[:, 3:5] if self._has_desired else None
        # Drop samples that are not finite (a run stopped by a divergence may end with some).
        ok = np.isfinite(t) & np.isfinite(q).all(axis=1)
        for arr in (tip, desired):
            if arr is not None:
                ok &= np.isfinite(arr).all(axis=1)
        q = q[ok, : self.nq]
        out = {"q": (t[ok], q)}
        if tip is None and self._tip_site is not None:
            tip = np.empty((len(q), 2))
            for k, qk in enumerate(q):
                self.data.qpos[: self.nq] = qk
                mujoco.mj_kinematics(self.model, self.data)
                tip[k] = self.data.site_xpos[self._tip_site, :2]
        elif tip is not None:
            tip = tip[ok]
        if tip is not None:
            out["tip"] = (t[ok], tip)
        if desired is not None:
            out["desired"] = (t[ok], desired[ok])
        return out

    def _states(self) -> Iterator[dict]:
        """Each frame's states (:func:`~.render_stream.frame_states`): from the whole log, or
        streamed again from a long log's file."""
        return frame_states(self.frame_t, self._log, self._whole, _STREAMED_PAPER, self._series)

    def qpos_frames(self) -> np.ndarray:
        """The replayed ``qpos[:nq]`` of every frame (M, nq) (tests: holds every frame)."""
        return np.array([s["q"][0] for s in self._states()])

    def __iter__(self) -> Iterator[tuple[float, np.ndarray]]:
        renderer = self.renderer
        scene = renderer.scene
        for tf, state in zip(self.frame_t, self._states()):
            self.data.qpos[: self.nq] = state["q"][0]
            _pose(self.model, self.data)
            renderer.update_scene(self.data, camera=self.cam)
            eye = 0.5 * (np.asarray(scene.camera[0].pos) + np.asarray(scene.camera[1].pos))
            if self.desired_pts is not None:
                # thin, in front of the (thicker) trace so that both stay visible when they overlap
                _add_polyline(scene, _to_front(self.desired_pts, eye, self.z_front + 0.01), _RGBA_DESIRED, 2.0)
                now = np.r_[state["desired"][0], 0.0]
                _add_sphere(scene, _to_front(now[None], eye, self.z_front + 0.02)[0], 0.008, _RGBA_DESIRED)
            if self._has_tip:
                now, last = state["tip"]
                kept = self.trace_pts[: int(np.searchsorted(self.trace_t, tf, side="right"))]
                pts = np.vstack([kept, *([last[None]] if np.isfinite(last).all() else []), now[None]])
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
        _close_renderer(self.renderer)


