"""The channels of a log: topics, metadata record names and the JSON schemas of their messages
(the layout is described in :mod:`uvms_mj.io.recorder`)."""

from __future__ import annotations

import numpy as np

from uvms_mj.plant.params import ARM_JOINTS, BASE_JOINTS

#: Version of the layout described in :mod:`uvms_mj.io.recorder` (stored in the metadata).
LOG_FORMAT = 1
METADATA_NAME = "uvms_mj"
STATUS_NAME = "uvms_mj.status"
#: Signals that go to ``/state/true``; every other signal goes to ``/control``.
STATE_SIGNALS = ("q_true", "qd_true", "tip_true")
TOPIC_CONTROL = "/control"
TOPIC_STATE = "/state/true"
TOPIC_TF = "/tf"
TOPIC_SCENE = "/scene"
TOPIC_PATHS = "/scene/paths"
TOPIC_JOINTS = "/joint_states"
TOPIC_THRUSTERS = "/thrusters"  # robot logs
#: Per-sample channels whose messages make up the signals (a sample is complete when all the
#: log's sample channels hold its message).
SAMPLE_TOPICS = (TOPIC_CONTROL, TOPIC_STATE)
#: Metadata keys the recorder adds itself (a caller's metadata must not use them).
RESERVED_KEYS = ("versions", "git_commit", "git_dirty", "robot_params", "created_utc", "log_format")
#: The paper robot's joints on ``/joint_states`` (base x, y, attitude, then the arm's two).
PAPER_JOINT_NAMES = BASE_JOINTS + ARM_JOINTS


# --------------------------------------------------------------------------- JSON schemas
# The foxglove.* schemas follow the published JSON schemas (github.com/foxglove/foxglove-sdk,
# schemas/jsonschema), without descriptions and without the optional message_id/lineage fields.


def _num() -> dict:
    return {"type": "number"}


def _obj(title: str | None, props: dict, required: bool = True, description: str | None = None) -> dict:
    out: dict = {}
    if title:
        out["title"] = title
    if description:
        out["description"] = description
    out["type"] = "object"
    out["properties"] = props
    if required:
        out["required"] = list(props)
    return out


def _arr(items: dict, description: str | None = None) -> dict:
    out = {"type": "array", "items": items}
    if description:
        out["description"] = description
    return out


def _time_schema() -> dict:
    return {"type": "object", "title": "time", "properties": {
        "sec": {"type": "integer", "minimum": 0},
        "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999}}}


def _duration_schema() -> dict:
    return {"type": "object", "title": "duration", "properties": {
        "sec": {"type": "integer"},
        "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999}}}


def _vec3() -> dict:
    return _obj("foxglove.Vector3", {"x": _num(), "y": _num(), "z": _num()})


def _point3() -> dict:
    return _obj("foxglove.Point3", {"x": _num(), "y": _num(), "z": _num()})


def _quat() -> dict:
    return _obj("foxglove.Quaternion", {"x": _num(), "y": _num(), "z": _num(), "w": _num()})


def _color_schema() -> dict:
    return _obj("foxglove.Color", {"r": _num(), "g": _num(), "b": _num(), "a": _num()})


def _pose() -> dict:
    return _obj("foxglove.Pose", {"position": _vec3(), "orientation": _quat()})


def _enum(title: str, names: tuple[str, ...]) -> dict:
    return {"title": title, "oneOf": [{"title": n, "const": i} for i, n in enumerate(names)]}


def _frame_transforms_schema() -> dict:
    tf = _obj("foxglove.FrameTransform", {
        "timestamp": _time_schema(), "parent_frame_id": {"type": "string"},
        "child_frame_id": {"type": "string"}, "translation": _vec3(), "rotation": _quat()})
    return _obj("foxglove.FrameTransforms", {"transforms": _arr(tf)},
                description="An array of FrameTransform messages")


def _scene_update_schema() -> dict:
    idx = _arr({"type": "integer", "minimum": 0})
    prims = {
        "arrows": _obj("foxglove.ArrowPrimitive", {
            "pose": _pose(), "shaft_length": _num(), "shaft_diameter": _num(), "head_length": _num(),
            "head_diameter": _num(), "color": _color_schema()}),
        "cubes": _obj("foxglove.CubePrimitive", {"pose": _pose(), "size": _vec3(), "color": _color_schema()}),
        "spheres": _obj("foxglove.SpherePrimitive", {"pose": _pose(), "size": _vec3(), "color": _color_schema()}),
        "cylinders": _obj("foxglove.CylinderPrimitive", {
            "pose": _pose(), "size": _vec3(), "bottom_scale": _num(), "top_scale": _num(), "color": _color_schema()}),
        "lines": _obj("foxglove.LinePrimitive", {
            "type": _enum("foxglove.LineType", ("LINE_STRIP", "LINE_LOOP", "LINE_LIST")),
            "pose": _pose(), "thickness": _num(), "scale_invariant": {"type": "boolean"},
            "points": _arr(_point3()), "color": _color_schema(), "colors": _arr(_color_schema()), "indices": idx}),
        "triangles": _obj("foxglove.TriangleListPrimitive", {
            "pose": _pose(), "points": _arr(_point3()), "color": _color_schema(), "colors": _arr(_color_schema()),
            "indices": idx}),
        "texts": _obj("foxglove.TextPrimitive", {
            "pose": _pose(), "billboard": {"type": "boolean"}, "font_size": _num(),
            "scale_invariant": {"type": "boolean"}, "color": _color_schema(), "text": {"type": "string"}}),
        "models": _obj("foxglove.ModelPrimitive", {
            "pose": _pose(), "scale": _vec3(), "color": _color_schema(), "override_color": {"type": "boolean"},
            "url": {"type": "string"}, "media_type": {"type": "string"},
            "data": {"type": "string", "contentEncoding": "base64"}}),
    }
    entity = _obj("foxglove.SceneEntity", {
        "timestamp": _time_schema(), "frame_id": {"type": "string"}, "id": {"type": "string"},
        "lifetime": _duration_schema(), "frame_locked": {"type": "boolean"},
        "metadata": _arr(_obj("foxglove.KeyValuePair", {"key": {"type": "string"}, "value": {"type": "string"}})),
        **{k: _arr(v) for k, v in prims.items()}})
    deletion = _obj("foxglove.SceneEntityDeletion", {
        "timestamp": _time_schema(), "type": _enum("foxglove.SceneEntityDeletionType", ("MATCHING_ID", "ALL")),
        "id": {"type": "string"}})
    return _obj("foxglove.SceneUpdate", {"deletions": _arr(deletion), "entities": _arr(entity)},
                description="An update to the entities displayed in a 3D scene")


def _joint_states_schema() -> dict:
    joint = _obj("foxglove.JointState", {
        "name": {"type": "string"}, "position": _num(), "velocity": _num(), "acceleration": _num(),
        "effort": _num()})
    joint["required"] = ["name"]
    return _obj("foxglove.JointStates", {"timestamp": _time_schema(), "joints": _arr(joint)},
                description="The state of a set of joints at a given time.")


#: Logs written before foxglove.JointStates existed used this schema name on /joint_states
#: ({"timestamp", "name": [...], "position": [...], "velocity": [...]}); they read back the same.
LEGACY_JOINT_STATES = "uvms_mj.JointStates"


_JSON_TYPE = {"b": "integer", "i": "integer", "u": "integer", "f": "number"}


def _sample_schema(title: str, description: str, layout: list[dict]) -> dict:
    props: dict = {"timestamp": _time_schema(),
                   "t": {"type": "number", "description": "sample time [s] (exact float)"}}
    for sig in layout:
        item: dict = {"type": _JSON_TYPE[np.dtype(sig["dtype"]).kind]}
        notes = ["boolean as 0/1"] if sig["dtype"] == "bool" else []
        shape = sig["shape"]
        if len(shape) > 1:
            notes.append(f"shape {tuple(shape)} flattened row-major")
        if notes:
            item["description"] = "; ".join(notes)
        if shape:
            n = int(np.prod(shape))
            item = {"type": "array", "items": item, "minItems": n, "maxItems": n}
        props[sig["name"]] = item
    return _obj(title, props, description=description + " (null = NaN, +-1e999 = +-inf)")


#: Published-schema equivalents, by schema name (exposed for tests and tools).
SCHEMAS: dict[str, dict] = {
    "foxglove.FrameTransforms": _frame_transforms_schema(),
    "foxglove.SceneUpdate": _scene_update_schema(),
    "foxglove.JointStates": _joint_states_schema(),
}


def _thrusters_schema(names: tuple[str, ...], fields: tuple[str, ...]) -> dict:
    what = {"command": "commanded thrust [N]", "force": "actual thrust [N] (lagged, saturated)"}
    props: dict = {"timestamp": _time_schema(), "t": {"type": "number", "description": "sample time [s]"}}
    for n in names:
        props[n] = _obj(None, {f: {"type": "number", "description": what[f]} for f in fields})
    return _obj("uvms_mj.Thrusters", props, description="Thrust of each thruster [N], by actuator name "
                "(null = NaN)")
