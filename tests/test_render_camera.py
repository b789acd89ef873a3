"""The robot video's follow cameras, scale bar and comparison strip (uvms_mj.analysis.render_camera,
render_robot, render_overlay): the vehicle and the tip project inside the frame, the robot fills
about half of it, the arm is seen (not hidden behind the hull), the scale bar's length is the
projection of a known length at the vehicle, and no text of the --compare strip is clipped.

Projections use MuJoCo's own camera pose (``cam_xpos``, ``cam_xmat`` after ``mj_camlight``) and
the pinhole model of its ``fovy`` (MuJoCo's renderer: vertical field of view, square pixels).
Needs the headless GL packages, as tests/test_render.py.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import mujoco
import numpy as np
import pytest

from uvms_mj.analysis.render import RenderError, render_frames
from uvms_mj.analysis.render_camera import FILL, fit_camera, project
from uvms_mj.analysis.render_robot import ROBOT_CAMERAS, _RobotReplay, _pose, robot_of
from uvms_mj.plant.files import robot_path
from uvms_mj.plant.robot import compile_robot_spec

W, H = 320, 240


def _synthetic_log(n: int = 61, seconds: float = 6.0) -> SimpleNamespace:
    """A bluerov2_alpha log without a simulation: the vehicle drifts 0.3 m forward and yaws
    20 deg while every arm joint swings +-0.3 rad about its qpos0 angle (kept in its range); the
    tip from MuJoCo's kinematics."""
    model = compile_robot_spec(robot_path("bluerov2_alpha"))
    data = mujoco.MjData(model)
    t = np.linspace(0.0, seconds, n)
    q = np.tile(model.qpos0, (n, 1))
    q[:, 0] = 0.3 * t / seconds
    q[:, 2] = -1.0
    yaw = math.radians(20) * t / seconds
    q[:, 3], q[:, 6] = np.cos(yaw / 2), np.sin(yaw / 2)
    for j in range(model.njnt):
        if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE:
            a = model.jnt_qposadr[j]
            swing = model.qpos0[a] + 0.3 * np.sin(2 * np.pi * t / seconds + j)
            q[:, a] = np.clip(swing, *model.jnt_range[j]) if model.jnt_limited[j] else swing
    sid = model.site("alpha_tip").id
    tip = np.empty((n, 3))
    for k in range(n):
        data.qpos[:] = q[k]
        mujoco.mj_kinematics(model, data)
        tip[k] = data.site_xpos[sid]
    desired = tip + np.array([0.0, 0.01, 0.0])
    meta = {"robot": {"name": "bluerov2_alpha", "layout": {"tip_site": "alpha_tip"}}, "controller": "rac_dob"}
    return SimpleNamespace(t=t, signals={"q_true": q, "tip_true": tip, "tip_desired": desired}, meta=meta)


@pytest.fixture(scope="module")
def log():
    return _synthetic_log()


def _replay(log, camera=None, labels=False) -> _RobotReplay:
    try:
        return _RobotReplay(log, robot_of(log), fps=5, size=(W, H), camera=camera, speed=1.0, max_seconds=None,
                            clock=False, labels=labels)
    except RenderError as exc:  # no GL: every rendering test says what to install
        pytest.fail(str(exc))


def _camera_pose(rp: _RobotReplay, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    rp.data.qpos[:] = q
    _pose(rp.model, rp.data)
    return rp.data.cam_xpos[rp.cam].copy(), rp.data.cam_xmat[rp.cam].reshape(3, 3).copy(), \
        float(rp.model.cam_fovy[rp.cam])


def test_fit_camera_fills_the_frame() -> None:
    """Every framed point projects within FILL of the half-frame, and one of them on it (to 1e-9:
    the distance is solved in closed form)."""
    rng = np.random.default_rng(3)
    pts = rng.normal(size=(200, 3)) * [0.4, 0.3, 0.2]
    for direction in ([1, 1, 0.5], [0, -1, 0.1], [0.2, 0.1, 1]):
        cam = fit_camera(pts, np.array(direction, float), 45.0, W / H)
        xmat = np.column_stack([cam.xyaxes[:3], cam.xyaxes[3:], np.cross(cam.xyaxes[:3], cam.xyaxes[3:])])
        pix, depth = project(pts, cam.offset, xmat, 45.0, W, H)
        u = np.abs(pix[:, 0] - W / 2) / (W / 2)
        v = np.abs(pix[:, 1] - H / 2) / (H / 2)
        assert (depth > 0).all()
        assert max(u.max(), v.max()) == pytest.approx(FILL, abs=1e-9)


@pytest.mark.parametrize("camera", ROBOT_CAMERAS)
def test_vehicle_and_tip_stay_in_the_frame(log, camera) -> None:
    """At every frame the vehicle origin and the tip project inside the image with a 10 % margin,
    and the robot's geoms span 35-80 % of the frame's limiting dimension (FILL = 64 % of the
    box over the whole motion; a single pose is smaller)."""
    rp = _replay(log, camera)
    try:
        geoms = [g for g in range(rp.model.ngeom) if rp.model.geom_bodyid[g] != 0 and rp.model.geom_group[g] < 3]
        sid = rp.model.site("alpha_tip").id
        spans = []
        for q in rp.qpos_frames():
            eye, xmat, fovy = _camera_pose(rp, q)
            pts = np.vstack([rp.data.xpos[rp.layout.base_body], rp.data.site_xpos[sid]])
            pix, depth = project(pts, eye, xmat, fovy, W, H)
            assert (depth > 0).all()
            assert (pix[:, 0] > 0.1 * W).all() and (pix[:, 0] < 0.9 * W).all(), (camera, pix)
            assert (pix[:, 1] > 0.1 * H).all() and (pix[:, 1] < 0.9 * H).all(), (camera, pix)
            gp, _ = project(rp.data.geom_xpos[geoms], eye, xmat, fovy, W, H)
            spans.append(max(np.ptp(gp[:, 0]) / W, np.ptp(gp[:, 1]) / H))
        assert 0.35 < max(spans) < 0.8, (camera, max(spans))
    finally:
        rp.close()


def test_follow_arm_sees_the_arm(log) -> None:
    """From the default camera the line of sight to the tip and to the wrist meets no geom of
    the vehicle's hull first (mj_ray from the eye): the arm is in front of the hull, not under
    it. The camera is on the arm's side: the eye is ahead of the vehicle (body x) at the start."""
    rp = _replay(log)
    try:
        model, data = rp.model, rp.data
        assert model.camera(rp.cam).name == "follow_arm" == ROBOT_CAMERAS[0]
        hull = {g for g in range(model.ngeom) if model.geom_bodyid[g] in
                (rp.layout.base_body, model.body("bluerov2_hull").id)}
        qs = rp.qpos_frames()
        for q in qs[:: max(1, len(qs) // 8)]:
            eye, xmat, _ = _camera_pose(rp, q)
            for target in (data.site_xpos[model.site("alpha_tip").id], data.xpos[model.body("alpha_wrist").id]):
                vec = target - eye
                geomid = np.array([-1], dtype=np.int32)
                dist = mujoco.mj_ray(model, data, eye, vec / np.linalg.norm(vec), None, 1, -1, geomid)
                assert dist < 0 or int(geomid[0]) not in hull or dist > np.linalg.norm(vec) - 1e-3, \
                    model.geom(int(geomid[0])).name
        eye, _, _ = _camera_pose(rp, rp.qpos_frames()[0])
        ahead = (eye - data.xpos[rp.layout.base_body]) @ data.xmat[rp.layout.base_body].reshape(3, 3)[:, 0]
        assert ahead > 0.2
    finally:
        rp.close()


def test_scale_bar_is_the_projection_of_a_length_at_the_vehicle(log) -> None:
    """px_per_m: a 0.2 m segment through the vehicle origin along the image's x or y axis (both
    ends at the vehicle's depth) projects to 0.2 * px_per_m pixels (to 1e-6: the track camera's
    offset is the fitted one at every frame, so only rounding remains); and the drawn bar is
    that long (+-1 px: it is a whole number of pixels)."""
    rp = _replay(log, labels=True)
    try:
        eye, xmat, fovy = _camera_pose(rp, rp.qpos_frames()[0])
        base = rp.data.xpos[rp.layout.base_body]
        for axis in (0, 1):  # along the image's x and y axes
            ends = base + np.outer([-0.1, 0.1], xmat[:, axis])
            pix, _ = project(ends, eye, xmat, fovy, W, H)
            assert np.linalg.norm(pix[1] - pix[0]) == pytest.approx(0.2 * rp.px_per_m, rel=1e-6)
        from uvms_mj.analysis.render_overlay import _nice_length

        length = _nice_length(0.25 * W / rp.px_per_m)
        img = np.zeros((H, W, 3), np.uint8)
        rp.overlay.apply(img)
        white = img.min(axis=2) > 200
        rows = white[H // 2:, W // 2:]  # the bar is at the bottom right
        assert abs(rows.sum(axis=1).max() - length * rp.px_per_m) <= 1.0
    finally:
        rp.close()


def test_robot_frame_has_water_and_labels(log) -> None:
    """A labelled frame: the background is the fog's water colour (not black: no skybox), the
    labels touch only the corners, and the clock and labels are drawn."""
    frames = [f.copy() for _, f in render_frames(log, fps=1, size=(W, H), labels=False)]
    plain = frames[len(frames) // 2]
    corner = plain[H // 3, 2].astype(int)  # left edge, upper third: water
    assert corner.sum() > 60 and corner[2] > corner[0], corner  # bluish, not black
    labelled = [f.copy() for _, f in render_frames(log, fps=1, size=(W, H))][len(frames) // 2]
    diff = np.abs(labelled.astype(int) - plain.astype(int)).max(axis=2) > 40
    assert diff[: H // 5, 2 * W // 3:].any()  # controller name
    assert diff[4 * H // 5:, : W // 3].any()  # legend
    assert diff[4 * H // 5:, 2 * W // 3:].any()  # scale bar
    assert not diff[H // 3: 2 * H // 3, W // 3: 2 * W // 3].any()


@pytest.mark.parametrize("size", [(1280, 120), (640, 120), (320, 40), (1920, 270)])
def test_compare_strip_text_is_not_clipped(size) -> None:
    """Every text of the error strip (title, legend, tick labels, unit) lies inside it."""
    from uvms_mj.analysis.render_overlay import _ErrorInset

    t = np.linspace(0.0, 12.0, 600)
    ins = _ErrorInset(*size, [("station_pidtask_priority", (t, 3 + np.sin(t))), ("rac_dob", (t, 1 + np.cos(t)))])
    w, h = size
    assert ins.text_boxes
    for x0, y0, x1, y1 in ins.text_boxes:
        assert x0 >= 0 and y0 >= 0 and x1 <= w and y1 <= h, (size, (x0, y0, x1, y1))
    assert ins.frame(6.0).shape == (h, w, 3)


def test_compare_halves_share_the_camera(log) -> None:
    """Two runs of different motion, each framed on both: the same camera pose and scale bar in
    both halves (to 1e-9: the same points in another order), unlike each framed alone."""
    small = _synthetic_log()
    n = len(small.t)  # held still at the first sample: a smaller motion to frame
    small.signals = {k: np.repeat(v[:1], n, axis=0) for k, v in small.signals.items()}
    robot = robot_of(log)
    kw = dict(fps=5, size=(W, H), camera=None, speed=1.0, max_seconds=None, clock=False, labels=False)
    a, b = _RobotReplay(log, robot, frame_also=small, **kw), _RobotReplay(small, robot, frame_also=log, **kw)
    alone = _RobotReplay(small, robot, **kw)
    try:
        assert a.px_per_m == pytest.approx(b.px_per_m, rel=1e-9)
        np.testing.assert_allclose(a.model.cam_pos0[a.cam], b.model.cam_pos0[b.cam], atol=1e-9)
        assert abs(alone.px_per_m - b.px_per_m) > 1e-3 * b.px_per_m
    finally:
        for rp in (a, b, alone):
            rp.close()
