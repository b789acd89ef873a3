"""The Foxglove channels of any floating robot's log (a model given to the recorder), by the
model's own names: ``/tf``, ``/scene``, ``/joint_states``, ``/thrusters`` and the path strips."""

from __future__ import annotations

import json
import math
import warnings
from typing import Any, Mapping

import numpy as np

from uvms_mj.io.encoding import _PathSpec, _color, _dumps, _enc, _entity
from uvms_mj.io.schemas import SCHEMAS, TOPIC_JOINTS, TOPIC_SCENE, TOPIC_TF, TOPIC_THRUSTERS, _thrusters_schema

#: Geom types drawn on ``/scene`` for robot logs (the others -- plane, height field, SDF -- are
#: left out); meshes are drawn as their bounding box.
_GEOM_PRIMITIVE = {"box": "cubes", "sphere": "spheres", "ellipsoid": "spheres", "cylinder": "cylinders",
                   "capsule": "cylinders", "mesh": "cubes"}
_DEFAULT_RGBA = (0.5, 0.5, 0.5, 1.0)  # MuJoCo's default geom colour: the material's then wins


def _tip_site_of(metadata: Mapping[str, Any]) -> str | None:
    robot = metadata.get("robot")
    layout = robot.get("layout") if isinstance(robot, Mapping) else None
    tip = layout.get("tip_site") if isinstance(layout, Mapping) else None
    return str(tip) if tip else None


def _fox_quat(q_wxyz) -> dict:
    w, x, y, z = (float(v) for v in q_wxyz)
    return {"x": x, "y": y, "z": z, "w": w}


def _fox_pose(pos, q_wxyz) -> dict:
    return {"position": {"x": float(pos[0]), "y": float(pos[1]), "z": float(pos[2])},
            "orientation": _fox_quat(q_wxyz)}


def geom_primitive(model, g: int) -> tuple[str, dict] | None:
    """The Foxglove primitive (list name, primitive) of geom ``g`` in its body's frame, or None
    for geoms that are not drawn (plane, height field, SDF, group >= 3, fully transparent).

    Sizes [m]: box -> cube of the full edges; sphere / ellipsoid -> sphere of the diameters;
    cylinder -> cylinder (Foxglove's axis is z, as MuJoCo's); capsule -> cylinder of the total
    length (the caps approximated); mesh -> cube of its bounding box.
    """
    import mujoco

    kind = mujoco.mjtGeom(int(model.geom_type[g])).name.removeprefix("mjGEOM_").lower()
    if kind not in _GEOM_PRIMITIVE or int(model.geom_group[g]) >= 3:
        return None
    rgba = tuple(float(v) for v in model.geom_rgba[g])
    mat = int(model.geom_matid[g])
    if mat >= 0 and np.allclose(rgba, _DEFAULT_RGBA):
        rgba = tuple(float(v) for v in model.mat_rgba[mat])
    if rgba[3] <= 0:
        return None
    size = np.asarray(model.geom_size[g], dtype=float)
    pos, quat = np.asarray(model.geom_pos[g], dtype=float), np.asarray(model.geom_quat[g], dtype=float)
    if kind == "box":
        dims = 2 * size
    elif kind == "sphere":
        dims = np.full(3, 2 * size[0])
    elif kind == "ellipsoid":
        dims = 2 * size
    elif kind == "cylinder":
        dims = np.array([2 * size[0], 2 * size[0], 2 * size[1]])
    elif kind == "capsule":
        dims = np.array([2 * size[0], 2 * size[0], 2 * (size[1] + size[0])])
    else:  # mesh: its bounding box (centre and half sizes in the geom frame)
        aabb = np.asarray(model.geom_aabb[g], dtype=float)
        rot = np.empty(9)
        mujoco.mju_quat2Mat(rot, quat)
        pos = pos + rot.reshape(3, 3) @ aabb[:3]
        dims = 2 * aabb[3:]
    prim: dict = {"pose": _fox_pose(pos, quat), "size": {"x": float(dims[0]), "y": float(dims[1]),
                                                          "z": float(dims[2])},
                  "color": _color(*rgba)}
    if _GEOM_PRIMITIVE[kind] == "cylinders":
        prim["bottom_scale"] = 1.0
        prim["top_scale"] = 1.0
    return _GEOM_PRIMITIVE[kind], prim


class _RobotChannels:
    """The Foxglove channels of any robot's log, by the model's own names: ``/tf`` (the
    kinematic tree: ``view -> world`` fixed identity, then every body in its parent body's frame,
    from ``q_true`` through ``mj_kinematics``), ``/scene`` (geoms, thruster arrows,
    tip), ``/joint_states`` (the arm joints), ``/thrusters`` (command and force per thruster)
    and the specs of the ``/scene/paths`` line strips."""

    def __init__(self, model, tip_site: str | None) -> None:
        import mujoco

        from uvms_mj.plant.layout import Layout

        if not isinstance(model, mujoco.MjModel):
            raise TypeError(f"McapRecorder: model must be a mujoco.MjModel, not {type(model).__name__}")
        self.model = model
        self.layout = Layout.of(model, tip_site)
        self.data = mujoco.MjData(model)
        self.bodies = list(range(1, model.nbody))
        self.body_names = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, b) or f"body{b}" for b in self.bodies]
        self.body_name = {b: n for b, n in zip(self.bodies, self.body_names)}
        self.body_name[0] = "world"
        self._parent = np.asarray(model.body_parentid[1:], dtype=int)  # each body's parent body (0: the world)
        self.has_tf = self.has_joints = False
        self.thr_fields: tuple[str, ...] = ()

    # ---------------------------------------------------------------- setup

    def start(self, channel, writer, ns: int, stamp: dict, row: Mapping[str, Any]) -> None:
        m, lay = self.model, self.layout
        self.has_tf = np.shape(row.get("q_true", ())) == (m.nq,)
        if "q_true" in row and not self.has_tf:
            warnings.warn(f"recorder: q_true has shape {np.shape(row['q_true'])}, the model {m.nq} positions: "
                          "no /tf or /joint_states", stacklevel=4)
        if self.has_tf:
            self.tf_id = channel(TOPIC_TF, "foxglove.FrameTransforms", SCHEMAS["foxglove.FrameTransforms"])
            self._tf_heads = ['{"timestamp":%%s,"parent_frame_id":%s,"child_frame_id":%s,'
                              % (json.dumps(self.body_name[int(m.body_parentid[b])]).replace("%", "%%"),
                                 json.dumps(n).replace("%", "%%")) for b, n in zip(self.bodies, self.body_names)]
            # One template for the whole message: "\0" stands for the stamp, %s for the numbers; first
            # the fixed view -> world (identity: this world is already z up).
            view = ('{"timestamp":\0,"parent_frame_id":"view","child_frame_id":"world","translation":'
                    '{"x":0.0,"y":0.0,"z":0.0},"rotation":{"x":0.0,"y":0.0,"z":0.0,"w":1.0}}')
            self._tf_tmpl = '{"transforms":[' + ",".join([view.replace("%", "%%")] + [
                (h % "\0") + '"translation":{"x":%s,"y":%s,"z":%s},"rotation":{"x":%s,"y":%s,"z":%s,"w":%s}}'
                for h in self._tf_heads]) + "]}"
        self.has_joints = self.has_tf and len(lay.joint_names) > 0
        if self.has_joints:
            self.js_id = channel(TOPIC_JOINTS, "foxglove.JointStates", SCHEMAS["foxglove.JointStates"])
            self._js_names = [json.dumps(n) for n in lay.joint_names]
            self._js_vel = np.shape(row.get("qd_true", ())) == (m.nv,)
        n_thr = len(lay.thruster_names)
        self.thr_fields = tuple(f for f, sig in (("command", "thrust_command"), ("force", "thrust_force"))
                                if n_thr and np.shape(row.get(sig, ())) == (n_thr,))
        self._thr_sig = {"command": "thrust_command", "force": "thrust_force"}
        if self.thr_fields:
            self.thr_id = channel(TOPIC_THRUSTERS, "uvms_mj.Thrusters",
                                  _thrusters_schema(lay.thruster_names, self.thr_fields))
            self._thr_names = [json.dumps(n) for n in lay.thruster_names]
            one = "{" + ",".join('"%s":%%s' % f for f in self.thr_fields) + "}"
            self._thr_tmpl = ",".join(n.replace("%", "%%") + ":" + one for n in self._thr_names) + "}"
        scene_id = channel(TOPIC_SCENE, "foxglove.SceneUpdate", SCHEMAS["foxglove.SceneUpdate"])
        writer.add_message(scene_id, ns, _dumps(self.scene(stamp)), ns, 0)

    def path_specs(self, row: Mapping[str, Any]) -> tuple[_PathSpec, ...]:
        specs = []
        if np.shape(row.get("tip_desired", ())) == (3,):
            specs.append(_PathSpec("tip_desired", "tip_desired", 0, 3, (0.1, 0.8, 0.2), "desired_tip_path"))
        if np.shape(row.get("tip_true", ())) == (3,) and self.layout.tip_site >= 0:
            specs.append(_PathSpec("tip_true", "tip_true", 0, 3, (0.95, 0.2, 0.2), "true_tip_path"))
        if self.has_tf:
            specs.append(_PathSpec("base", "q_true", self.layout.base_qadr, 3, (0.2, 0.5, 1.0), "base_path"))
        return tuple(specs)

    def scene(self, stamp: dict) -> dict:
        """The robot's SceneUpdate: per body a frame-locked entity (id = frame = the body's name)
        with its drawn geoms; the thruster arrows (along each thruster site's x axis, the
        direction of positive thrust); a sphere at the tip site."""
        m, lay = self.model, self.layout
        per_body: dict[int, dict[str, list]] = {}
        for g in range(m.ngeom):
            prim = geom_primitive(m, g)
            if prim is not None:
                per_body.setdefault(int(m.geom_bodyid[g]), {}).setdefault(prim[0], []).append(prim[1])
        ents = [_entity(self.body_name[b], self.body_name[b], stamp, **prims) for b, prims in sorted(per_body.items())]
        arrows: dict[int, list] = {}
        for a in lay.thruster_ids:
            s = int(m.actuator_trnid[a][0])
            arrows.setdefault(int(m.site_bodyid[s]), []).append(
                {"pose": _fox_pose(m.site_pos[s], m.site_quat[s]), "shaft_length": 0.12, "shaft_diameter": 0.015,
                 "head_length": 0.04, "head_diameter": 0.035, "color": _color(0.2, 0.6, 1.0)})
        for b, arr in sorted(arrows.items()):
            eid = "thrusters" if len(arrows) == 1 else f"thrusters/{self.body_name[b]}"
            ents.append(_entity(self.body_name[b], eid, stamp, arrows=arr))
        if lay.tip_site >= 0:
            s = lay.tip_site
            tip = {"pose": _fox_pose(m.site_pos[s], (1.0, 0.0, 0.0, 0.0)), "size": {"x": 0.025, "y": 0.025, "z": 0.025},
                   "color": _color(1.0, 0.2, 0.2)}
            ents.append(_entity(self.body_name[int(m.site_bodyid[s])], "tip", stamp, spheres=[tip]))
        return {"deletions": [], "entities": ents}

    # ---------------------------------------------------------------- per sample

    def _tf_poses(self, rows: list) -> list:
        """Per row its bodies' frames in their parent body's frames, (nbody - 1, 7: x y z, qx qy qz
        qw), or None (no /tf: no finite ``q_true``): ``mj_kinematics`` row by row, then for the whole
        batch at once p = R_parent^T (x_child - x_parent), q = q_parent^-1 q_child (Hamilton product of
        MuJoCo's w-first quaternions); a child of the world keeps its world pose."""
        import mujoco

        out: list = [None] * len(rows)
        if not self.has_tf:
            return out
        m, d, keep, xs, qs, rs = self.model, self.data, [], [], [], []
        for i, row in enumerate(rows):
            q = row.get("q_true")
            if q is None:
                continue
            q = np.asarray(q, dtype=float)
            if not math.isfinite(float(q.sum())):
                continue
            d.qpos[:] = q
            mujoco.mj_kinematics(m, d)
            keep.append(i)
            xs.append(d.xpos.copy())
            qs.append(d.xquat.copy())
            rs.append(d.xmat.copy())
        if not keep:
            return out
        par = self._parent
        X, Q, R = np.array(xs), np.array(qs), np.array(rs).reshape(len(keep), -1, 3, 3)
        pose = np.empty((len(keep), len(par), 7))
        dx = (X[:, 1:] - X[:, par])[..., None]
        pose[..., :3] = (np.swapaxes(R[:, par], -1, -2) @ dx)[..., 0]
        qp, qc = Q[:, par], Q[:, 1:]
        w1, x1, y1, z1 = qp[..., 0], -qp[..., 1], -qp[..., 2], -qp[..., 3]  # the conjugate: a unit q's inverse
        w2, x2, y2, z2 = qc[..., 0], qc[..., 1], qc[..., 2], qc[..., 3]
        pose[..., 3] = w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2
        pose[..., 4] = w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2
        pose[..., 5] = w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2
        pose[..., 6] = w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2
        for j, i in enumerate(keep):
            out[i] = pose[j]
        return out

    def write_batch(self, outs: list, stamps: list, heads: list, rows: list) -> None:
        """:meth:`write` for a batch of rows (their /tf numbers computed at once)."""
        for out, stamp, head, row, pose in zip(outs, stamps, heads, rows, self._tf_poses(rows)):
            self.write(out, stamp, head, row, pose)

    def write(self, out: list, stamp: str, head: str, row: Mapping[str, Any], pose=False) -> None:
        """Append this sample's /tf, /joint_states and /thrusters messages (channel, data) to ``out``;
        ``pose``: its /tf numbers if already computed (:meth:`write_batch`)."""
        lay = self.layout
        if self.has_tf and "q_true" in row:
            q = np.asarray(row["q_true"], dtype=float)
            if math.isfinite(float(q.sum())):
                if pose is False:
                    pose = self._tf_poses([row])[0]
                nums = _enc(pose.ravel().tolist())[1:-1].split(",")
                msg = self._tf_tmpl.replace("\0", stamp) % tuple(nums)
                out.append((self.tf_id, msg.encode()))
            if self.has_joints:
                pos = _enc(q[lay.joint_qadr].tolist())[1:-1].split(",")
                vel = None
                if self._js_vel and "qd_true" in row:
                    vel = _enc(np.asarray(row["qd_true"], dtype=float)[lay.joint_dadr].tolist())[1:-1].split(",")
                joints = ",".join('{"name":%s,"position":%s%s}' % (n, pos[i], "" if vel is None else
                                                                  ',"velocity":' + vel[i])
                                  for i, n in enumerate(self._js_names))
                out.append((self.js_id, ('{"timestamp":%s,"joints":[%s]}' % (stamp, joints)).encode()))
        if self.thr_fields:
            if all(self._thr_sig[f] in row for f in self.thr_fields):
                cols = [_enc(np.asarray(row[self._thr_sig[f]], dtype=float).tolist())[1:-1].split(",")
                        for f in self.thr_fields]
                args = tuple(x for vals in zip(*cols) for x in vals)  # per thruster: its fields in order
                out.append((self.thr_id, (head + "," + self._thr_tmpl % args).encode()))
            else:
                cols = [_enc(np.asarray(row[self._thr_sig[f]], dtype=float).tolist())[1:-1].split(",")
                        if self._thr_sig[f] in row else None for f in self.thr_fields]
                items = []
                for i, n in enumerate(self._thr_names):
                    vals = ",".join('"%s":%s' % (f, c[i]) for f, c in zip(self.thr_fields, cols) if c is not None)
                    items.append('%s:{%s}' % (n, vals))
                out.append((self.thr_id, (head + "," + ",".join(items) + "}").encode()))
