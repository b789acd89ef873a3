"""Any floating robot's replay (logs with ``meta["robot"]``, :mod:`uvms_mj.analysis.render`):
the robot's MJCF file compiled (:func:`uvms_mj.plant.robot.compile_robot_spec`) with a water scene
added to its MjSpec and three cameras on the vehicle body in MuJoCo's "track" mode
(:data:`ROBOT_CAMERAS`, framed by :mod:`.render_camera`); ``q_true`` interpolated to the frame
times (:func:`interp_qpos`).

The underwater look (constants below, display choices [A]): a sand-coloured, untextured sea floor
3 m below the vehicle's start; MuJoCo's (linear) fog in the water's colour from 0.8 m to 12 m
from the eye, and a plane just beyond its end as the background; daylight from above and the
water's colour dimmed with the vehicle's depth by exp(-K_d depth) (K_d = 0.12 / m, the surface
at z = 0); a point light 1 m above the surface whose linear attenuation darkens what lies
deeper; a dim headlight. Speed on a software rasterizer (Mesa llvmpipe): no multisampling, no
shadow map, no skybox."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Iterator, Mapping

import numpy as np

from uvms_mj.analysis.render_gl import _close_renderer, _make_renderer
from uvms_mj.analysis.series import robot_of
from uvms_mj.analysis.render_overlay import (
    _RGBA_BASE,
    _RGBA_DESIRED,
    _RGBA_TRACE,
    _controller_name,
    _labels_overlay,
    _signal,
    _simplify,
    _stamp_text,
    _thin,
)
from uvms_mj.analysis.render_scene import (
    _Replay,
    _TRACE_TOL,
    _add_polyline,
    _add_sphere,
    _check_size,
    _frame_times,
    _pose,
)
from uvms_mj.analysis.render_stream import (_STREAMED_ROBOT as _STREAMED, _streamed_span, continuous_quaternions,
                                           frame_states, hold_single, lerp_qpos)
from uvms_mj.analysis.render_camera import DIRECTIONS, FOVY, FollowCamera, fit_camera, heading_frame, px_per_metre


# ------------------------------------------------------------------ any robot (logs with meta["robot"])

#: The cameras added to a robot's scene, all on the vehicle body in MuJoCo's "track" mode
#: (position follows the vehicle, orientation fixed in the world), framed on the robot and its
#: paths (:mod:`.render_camera`): "follow_arm" in front of the arm and to its side, a little
#: above (the default); "follow_three_quarter" from the front-left above; "follow_side" from the
#: vehicle's starboard side (directions in the heading frame at the first sample).
ROBOT_CAMERAS = ("follow_arm", "follow_three_quarter", "follow_side")
_FLOOR_DEPTH = 3.0  # m below the vehicle's start (and at least 0.5 m below its lowest point)
# The underwater look; display choices [A], not measurements:
_SURFACE_Z = 0.0  # m: the water surface is the world's z = 0 (depth = -z)
_KD = 0.12  # 1/m: diffuse attenuation of daylight with depth (clear coastal water: 0.05-0.3)
_WATER = (0.10, 0.34, 0.46)  # the water's colour near the surface (fog and background)
_FOG = (0.8, 12.0)  # m from the eye: haze starts, and only water is seen beyond
_SUN = np.array([0.55, 0.62, 0.62])  # daylight from above (greenish-blue), before the depth's dimming
_SURFACE_LIGHT = (0.45, 0.55, 0.6)  # the point light 1 m above the surface
_SURFACE_ATTENUATION = 0.25  # 1/m: its linear attenuation (the deeper, the darker)
_HEADLIGHT = ((0.18, 0.2, 0.22), (0.34, 0.36, 0.38))  # ambient, diffuse of the camera's lamp
_RGBA_BACKDROP = np.array([0.0, 0.0, 0.0, 1.0], dtype=np.float32)  # fully fogged: shows the water's colour
_FACETS = (16, 8)  # numslices, numstacks of the replay's primitives (a 16-gon: smooth enough at 640 x 480)
_SAND = (0.62, 0.57, 0.44)  # sea floor: sand


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
    each sample nearest the previous one, :func:`~.render_stream.continuous_quaternions`, so that
    no interpolation goes the long way round)."""
    return lerp_qpos(t, ts, continuous_quaternions(q, quat_slots), quat_slots)


def _visible_geoms(model) -> list[int]:
    """The robot's visible geoms: on a body other than the world, group < 3, not planes."""
    import mujoco

    return [g for g in range(model.ngeom) if model.geom_bodyid[g] != 0 and model.geom_group[g] < 3
            and model.geom_type[g] not in (mujoco.mjtGeom.mjGEOM_PLANE, mujoco.mjtGeom.mjGEOM_HFIELD)]


def _arm_geoms(model, geoms: list[int], base_body: int) -> list[int]:
    """Those of ``geoms`` moved by a joint other than the vehicle's own (the arm's)."""
    moved = np.zeros(model.nbody, dtype=bool)
    for b in range(1, model.nbody):  # parents come before children in MuJoCo's body order
        p = int(model.body_parentid[b])
        moved[b] = moved[p] or (b != base_body and int(model.body_jntnum[b]) > 0 and p != 0)
    return [g for g in geoms if moved[int(model.geom_bodyid[g])]]


def _framing(model, data, layout, segments: list[tuple[np.ndarray, list[np.ndarray]]]):
    """(points (N, 3): the corners of the robot's visible geoms' boxes (MuJoCo's ``geom_aabb``,
    in each geom's frame) and the paths' samples, as offsets from the vehicle origin at the same
    sample [m, world], over at most ~40 configurations of each segment; the world direction
    from the vehicle origin to the arm's geoms, summed over the segments' first samples, or the
    vehicle's x axis without an arm). ``segments``: (q samples (N, nq), paths (N, 3) each) of
    one log, or of two (a comparison: the result does not depend on their order)."""
    import mujoco

    geoms = _visible_geoms(model)
    arm = _arm_geoms(model, geoms, layout.base_body)
    base, a = layout.base_body, layout.base_qadr
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float)
    aabb = model.geom_aabb[geoms].reshape(-1, 6) if geoms else np.zeros((0, 6))
    local = aabb[:, None, :3] + signs[None] * aabb[:, None, 3:]  # (G, 8, 3) geom frame
    out, arm_dir = [np.zeros((1, 3))], np.zeros(3)
    for q_log, paths in segments:
        step = max(1, len(q_log) // 40)
        for k, q in enumerate(np.vstack([q_log[::step], q_log[-1:]])):
            data.qpos[:] = q
            mujoco.mj_kinematics(model, data)
            origin = data.xpos[base].copy()
            if k == 0:
                arm_dir = arm_dir + ((data.geom_xpos[arm].mean(axis=0) - origin) if arm
                                     else data.xmat[base].reshape(3, 3)[:, 0])
            if geoms:
                rot = data.geom_xmat[geoms].reshape(-1, 3, 3)
                world = np.einsum("gij,gkj->gki", rot, local) + (data.geom_xpos[geoms] - origin)[:, None]
                out.append(world.reshape(-1, 3))
        step_p = max(1, len(q_log) // 400)
        for path in paths:  # a path's samples go with q_log's
            rel = path[::step_p] - q_log[::step_p, a:a + 3]
            out.append(rel[np.isfinite(rel).all(axis=1)])
    return np.vstack(out), arm_dir


def _robot_cameras(model, data, layout, segments: list, aspect: float) -> dict[str, FollowCamera]:
    """The :data:`ROBOT_CAMERAS`, framed on the robot and its paths (:mod:`.render_camera`)."""
    points, arm_dir = _framing(model, data, layout, segments)
    frame = heading_frame(arm_dir)
    return {name: fit_camera(points, frame @ np.asarray(DIRECTIONS[name]), FOVY, aspect) for name in ROBOT_CAMERAS}


def _water_rgb(depth: float) -> np.ndarray:
    """Colour of the water (fog and background) at ``depth`` [m]: :data:`_WATER` dimmed by
    exp(-:data:`_KD` depth) (Beer-Lambert), at least a quarter of it."""
    return np.asarray(_WATER) * max(math.exp(-_KD * max(depth, 0.0)), 0.25)


def _robot_scene_model(robot: dict, q_log: np.ndarray, width: int, height: int,
                       model_path: str | Path | None = None, paths: tuple = (), also: tuple | None = None):
    """The robot's model plus the replay scene (sandy sea floor, lights, water haze, the
    :data:`ROBOT_CAMERAS` on the vehicle body), the robot's Layout and the cameras
    (:class:`~.render_camera.FollowCamera` by name).

    ``q_log``: the logged qpos samples (N, nq); ``paths``: (N, 3) world paths to keep in view
    (tip trace, desired tip path). ``also``: (q samples, paths) of another log framed too (a
    comparison: both halves get the same cameras, so their scale bars agree); ignored when its
    qpos size differs. The floor is :data:`_FLOOR_DEPTH` below the vehicle's start and at least
    0.5 m below its lowest point.
    """
    import mujoco

    from uvms_mj.plant.params import ParameterError
    from uvms_mj.plant.layout import Layout
    from uvms_mj.plant.robot import compile_robot_spec

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
    segments = [(q_log, list(paths))]
    if also is not None and also[0].ndim == 2 and also[0].shape[1] == plain.nq:
        segments.append((also[0], list(also[1])))
    cams = _robot_cameras(plain, data, layout, segments, width / height)
    a = layout.base_qadr
    # Track cameras keep their qpos0 offset from the body (world frame): express the wanted
    # world offset and axes in the body frame at qpos0.
    r0 = np.empty(9)
    mujoco.mju_quat2Mat(r0, plain.qpos0[a + 3:a + 7] / np.linalg.norm(plain.qpos0[a + 3:a + 7]))
    r0 = r0.reshape(3, 3)
    floor_z = min(float(q0[a + 2]) - _FLOOR_DEPTH, float(np.min(q_log[:, a + 2])) - 0.5)
    depth = -float(q0[a + 2]) - _SURFACE_Z
    dim = max(math.exp(-_KD * max(depth, 0.0)), 0.25)

    def edit(spec) -> None:
        # sand: one flat, low-contrast colour, no texture (a texture costs about 6 ms per 640x480
        # frame in llvmpipe: a quarter of the frame); the lights and the haze shade it. size[2]:
        # the spacing of the plane's grid [m], at whose vertices the lights are evaluated.
        spec.add_material(name="uvms_sand", rgba=[*_SAND, 1.0], specular=0.0, shininess=0.0,
                                reflectance=0.0)
        spec.worldbody.add_geom(name="uvms_floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[40.0, 40.0, 2.0],
                                pos=[float(q0[a]), float(q0[a + 1]), floor_z], material="uvms_sand",
                                contype=0, conaffinity=0, group=0)
        # daylight from above, dimmed by the depth; and a point light at the surface above the
        # start whose attenuation darkens what lies deeper (the floor more than the vehicle)
        spec.worldbody.add_light(name="uvms_sun", type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL,
                                 pos=[0.0, 0.0, 10.0], dir=[0.25, 0.15, -1.0], diffuse=list(dim * _SUN),
                                 ambient=[0.0, 0.0, 0.0], specular=[0.0, 0.0, 0.0], castshadow=False)
        spec.worldbody.add_light(name="uvms_surface", type=mujoco.mjtLightType.mjLIGHT_POINT,
                                 pos=[float(q0[a]), float(q0[a + 1]), _SURFACE_Z + 1.0],
                                 diffuse=list(_SURFACE_LIGHT), ambient=[0.0, 0.0, 0.0], specular=[0.1, 0.1, 0.1],
                                 attenuation=[1.0, _SURFACE_ATTENUATION, 0.0], castshadow=False)
        body = spec.body(layout.base_name)
        for name, cam in cams.items():
            local = np.r_[r0.T @ cam.xyaxes[:3], r0.T @ cam.xyaxes[3:]]
            body.add_camera(name=name, mode=mujoco.mjtCamLight.mjCAMLIGHT_TRACK, pos=list(r0.T @ cam.offset),
                            xyaxes=list(local), fovy=cam.fovy)

    try:
        model = compile_robot_spec(path, edit=edit)
    except ParameterError as exc:
        raise ValueError(f"the log's robot model {path}: {exc}") from None
    vis = model.vis
    vis.global_.offwidth = max(int(vis.global_.offwidth), width)
    vis.global_.offheight = max(int(vis.global_.offheight), height)
    # Software rasterizer (llvmpipe): no multisampling (4 samples cost 3x the frame) and no
    # shadow map (no light casts shadows); headlight dim (a camera-side lamp).
    vis.quality.offsamples = 0
    vis.quality.shadowsize = 0
    # Fewer facets per cylinder, capsule, sphere and ellipsoid (MuJoCo's defaults 28 x 16): the
    # frame is vertex-bound in software (75 primitive geoms: 32 ms at 28 x 16, 20 ms at 16 x 8).
    vis.quality.numslices = min(int(vis.quality.numslices), _FACETS[0])
    vis.quality.numstacks = min(int(vis.quality.numstacks), _FACETS[1])
    vis.headlight.ambient = list(_HEADLIGHT[0])
    vis.headlight.diffuse = list(_HEADLIGHT[1])
    vis.headlight.specular = [0.0, 0.0, 0.0]
    # water haze [MuJoCo's unit: the model's extent]
    extent = max(float(model.stat.extent), 1e-6)
    vis.map.fogstart = _FOG[0] / extent
    vis.map.fogend = _FOG[1] / extent
    vis.rgba.fog = (*_water_rgb(depth), 1.0)
    return model, layout, cams

def _finite_rows(x: np.ndarray | None, n: int, width: int) -> np.ndarray | None:
    """A (n, width) signal, or None when it is missing, misshapen or never finite."""
    if x is None or x.ndim != 2 or x.shape != (n, width) or not np.isfinite(x).all(axis=1).any():
        return None
    return x


def _framed_motion(log, max_seconds: float | None, speed: float):
    """(q_true rows, [tip_true, tip_desired] rows) of ``log`` that a video of it would show
    (finite samples up to ``max_seconds`` of video), or None without q_true."""
    ts = np.asarray(log.t, dtype=float).ravel()
    q = _signal(log, "q_true")
    if q is None or q.ndim != 2 or len(q) != len(ts):
        return None
    ok = np.isfinite(ts) & np.isfinite(q).all(axis=1)
    if max_seconds is not None and ok.any():
        ok &= ts <= ts[ok][0] + float(max_seconds) * speed + 1e-9
    if not ok.any():
        return None
    paths = [p[ok] for p in (_finite_rows(_signal(log, n), len(ts), 3) for n in ("tip_true", "tip_desired"))
             if p is not None]
    return q[ok], paths


class _RobotReplay:
    """Replay of a robot log (:func:`robot_of`): the robot's own model in a water scene,
    followed by a tracking camera; same interface as :class:`_Replay`."""

    def __init__(self, log, robot: dict, fps: float, size: tuple[int, int], camera: str | int | None,
                 speed: float, max_seconds: float | None, clock: bool, labels: bool = True,
                 title: str | None = None, model_path: str | Path | None = None, frame_also=None) -> None:
        import mujoco

        width, height = _check_size(size, fps, speed)
        ts = np.asarray(log.t, dtype=float).ravel()
        q_log = _signal(log, "q_true")
        if q_log is None or q_log.ndim != 2 or len(q_log) != len(ts) or len(ts) < 1:
            raise ValueError("the log has no q_true signal matching its time base: nothing to replay")
        if not (np.isfinite(ts) & np.isfinite(q_log).all(axis=1)).any():
            raise ValueError("the log has no sample with a finite q_true: nothing to replay")
        n = len(ts)
        # which series are drawn, decided on the whole log (or its envelope): the tip's trace
        # (else the vehicle origin's) and the desired tip path
        self._has_tip = _finite_rows(_signal(log, "tip_true"), n, 3) is not None
        self._has_desired = _finite_rows(_signal(log, "tip_desired"), n, 3) is not None
        self._log = log

        # framed: the part of the log (and of frame_also's) in the video, found the same way for both
        own = _framed_motion(log, max_seconds, speed)
        also = _framed_motion(frame_also, max_seconds, speed) if frame_also is not None else None
        model, layout, cams = _robot_scene_model(robot, own[0], width, height, model_path, paths=tuple(own[1]),
                                                 also=also)
        self.model, self.layout = model, layout
        self._base_qadr = layout.base_qadr
        self.data = mujoco.MjData(model)
        # a single sample: a still picture of 1 / fps
        whole = self._whole = hold_single(self._series(ts, {k: _signal(log, k) for k in _STREAMED}), 1.0 / fps)
        ts = whole["q"][0]
        self.ts, self.speed, self.clock, self.height = ts, speed, clock, height
        span = _streamed_span(log, ["q_true"])
        self.frame_t = _frame_times(np.asarray(span) if span is not None else ts, fps, speed, max_seconds)
        self._quats = {"q": _quat_slots(model)}
        self.cam = self._camera(model, camera)
        follow = cams.get(model.camera(self.cam).name)
        trace_label = "tip trace" if self._has_tip else "vehicle trace"  # no tip: the vehicle origin
        self.trace_rgba = _RGBA_TRACE if self._has_tip else _RGBA_BASE
        # the drawn paths, simplified to within _TRACE_TOL and at most ~300 points
        good_t, good = whole["tip"]
        keep = _thin(_simplify(good, _TRACE_TOL), 300) if len(good) else np.zeros(0, dtype=int)
        self.trace_t, self.trace_pts = good_t[keep], good[keep]
        self.desired_pts = None
        if self._has_desired:
            d = whole["desired"][1]
            d_ok = d[np.isfinite(d).all(axis=1)]
            self.desired_pts = d_ok[_thin(_simplify(d_ok, _TRACE_TOL), 300)]
        #: image scale at the vehicle's distance [px/m] (None for a camera of the model)
        self.px_per_m = px_per_metre(follow, height) if follow is not None else None
        self.overlay = None
        if labels:
            self.overlay = _labels_overlay(width, height, title if title is not None else _controller_name(log),
                                           self.px_per_m, legend=True, trace_label=trace_label,
                                           desired_label="desired tip path" if self._has_desired else None,
                                           scale_note="at the vehicle")
        self.renderer = _make_renderer(model, height, width)
        self.renderer.scene.flags[mujoco.mjtRndFlag.mjRND_FOG] = True
        self.renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SKYBOX] = False
        extent = max(float(model.stat.extent), 1e-6)
        self.backdrop_dist = 1.02 * float(model.vis.map.fogend) * extent
        self.backdrop_half = 1.5 * self.backdrop_dist * math.tan(math.radians(float(model.cam_fovy[self.cam])) / 2) \
            * max(width / height, 1.0)

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

    def _add_backdrop(self, scene) -> None:
        """The water behind everything: a plane facing the eye just beyond the fog's end (so it
        shows the fog colour), instead of a skybox (a full-screen textured sphere costs about
        11 ms per 640x480 frame in llvmpipe, the plane about 1.5 ms)."""
        import mujoco

        if scene.ngeom >= scene.maxgeom:
            return
        cam = scene.camera[0]
        fwd, up = np.asarray(cam.forward, dtype=float), np.asarray(cam.up, dtype=float)
        eye = 0.5 * (np.asarray(scene.camera[0].pos) + np.asarray(scene.camera[1].pos))
        rot = np.column_stack([np.cross(fwd, up), up, -fwd])
        g = scene.geoms[scene.ngeom]
        half = self.backdrop_half
        mujoco.mjv_initGeom(g, mujoco.mjtGeom.mjGEOM_PLANE, np.array([half, half, half]),
                            eye + self.backdrop_dist * fwd, rot.ravel(), _RGBA_BACKDROP)
        g.category = mujoco.mjtCatBit.mjCAT_DECOR
        scene.ngeom += 1

    def _series(self, t: np.ndarray, signals: Mapping) -> dict:
        """The replayed series of one block (or of the whole log): ``q`` (the finite q_true
        samples), ``tip`` (of those, the ones with a finite tip; the vehicle origin without a
        tip) and ``desired`` (tip_desired at the q samples, NaN rows kept)."""
        t = np.asarray(t, dtype=float).ravel()
        q = np.asarray(signals["q_true"], dtype=float)
        ok = np.isfinite(t) & np.isfinite(q).all(axis=1)
        out = {"q": (t[ok], q[ok])}
        if self._has_tip:
            tip = np.asarray(signals["tip_true"], dtype=float)
            tok = ok & np.isfinite(tip).all(axis=1)
            out["tip"] = (t[tok], tip[tok])
        else:
            a = self._base_qadr
            out["tip"] = (t[ok], q[ok, a:a + 3])
        if self._has_desired:
            out["desired"] = (t[ok], np.asarray(signals["tip_desired"], dtype=float)[ok])
        return out

    def _states(self) -> Iterator[dict]:
        """Each frame's states (:func:`~.render_stream.frame_states`): from the whole log, or
        streamed again from a long log's file."""
        return frame_states(self.frame_t, self._log, self._whole, _STREAMED, self._series, self._quats)

    def qpos_frames(self) -> np.ndarray:
        """The replayed ``qpos`` of every frame (M, nq) (tests: holds every frame)."""
        return np.array([s["q"][0] for s in self._states()])

    def __iter__(self) -> Iterator[tuple[float, np.ndarray]]:
        renderer = self.renderer
        scene = renderer.scene
        for tf, state in zip(self.frame_t, self._states()):
            self.data.qpos[:] = state["q"][0]
            _pose(self.model, self.data)
            renderer.update_scene(self.data, camera=self.cam)
            self._add_backdrop(scene)
            if self.desired_pts is not None:
                # thin, 1 cm nearer the eye than the trace: both stay visible where they overlap
                near = -0.01 * np.asarray(scene.camera[0].forward, dtype=float)
                _add_polyline(scene, self.desired_pts + near, _RGBA_DESIRED, 2.0)
                now = state["desired"][0]
                if now.size and np.isfinite(now).all():
                    _add_sphere(scene, now + near, 0.012, _RGBA_DESIRED)
            now, last = state["tip"]
            if now.size:
                kept = self.trace_pts[: int(np.searchsorted(self.trace_t, tf, side="right"))]
                pts = np.vstack([kept, *([last[None]] if np.isfinite(last).all() else []), now[None]])
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
        _close_renderer(self.renderer)


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


