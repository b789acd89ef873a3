"""Any floating robot's replay (logs with ``meta["robot"]``, :mod:`uvms_mj.analysis.render`):
the robot's MJCF file compiled (:func:`uvms_mj.plant.robot.compile_robot_spec`) with a water scene
added to its MjSpec (a checkered sea floor 3 m below the vehicle's start, a directional light, a
water-coloured gradient skybox and haze) and two cameras on the vehicle body in MuJoCo's "track"
mode (:data:`ROBOT_CAMERAS`); ``q_true`` interpolated to the frame times (:func:`interp_qpos`)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Iterator, Mapping

import numpy as np

from uvms_mj.analysis.render_gl import _make_renderer
from uvms_mj.analysis.render_overlay import (
    _RGBA_BASE,
    _RGBA_DESIRED,
    _RGBA_TRACE,
    _controller_name,
    _interp,
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


# ------------------------------------------------------------------ any robot (logs with meta["robot"])

#: The cameras added to a robot's scene, both on the vehicle body in MuJoCo's "track" mode
#: (position follows the vehicle, orientation fixed in the world): a side view from the
#: vehicle's starboard side (its -y axis at the first sample) and a three-quarter view from the
#: front-left, above. The first is the default.
ROBOT_CAMERAS = ("follow_three_quarter", "follow_side")
_FLOOR_DEPTH = 3.0  # m below the vehicle's start (and at least 0.5 m below its lowest point)
_SKY = ((0.16, 0.42, 0.62), (0.01, 0.06, 0.14))  # water: lighter above, darker below
_FLOOR_RGB = ((0.50, 0.46, 0.36), (0.42, 0.38, 0.29))


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


