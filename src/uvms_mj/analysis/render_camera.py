"""Follow cameras of a robot's replay (:mod:`uvms_mj.analysis.render_robot`), framed from the model.

The framed points are the robot's visible geometry (vehicle and arm: the corners of every visible
geom's bounding box) over the logged configurations, plus the tip's trace and desired path, all expressed
relative to the vehicle origin at the same sample (the cameras follow the vehicle in MuJoCo's
"track" mode: the position keeps a fixed world offset from the vehicle, the orientation is fixed
in the world). Each camera looks at the box's centre from a direction given in the vehicle's
heading frame at the first sample (h = the horizontal direction from the vehicle origin towards
the arm, s = z x h, z up), at the distance at which every point projects within :data:`FILL` of
the frame's half-width and half-height (so the robot spans about that fraction of the frame;
pinhole projection with the camera's ``fovy``).

:func:`px_per_metre` is the image scale at the vehicle's distance along the view axis, which the
scale bar uses (a track camera keeps that distance over the whole video).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Fraction of the frame's limiting dimension the framed box spans [A: "the robot fills about
#: half the frame", leaving room for the labels in the corners and for motion of the arm].
FILL = 0.64
#: Vertical field of view of the follow cameras [deg] [A: MuJoCo's default].
FOVY = 45.0

#: Directions to the cameras as (along h, along s, along z) in the heading frame (h: towards the
#: arm, s = z x h, z up), normalised. "follow_arm": in front of the arm, 38 deg to its side and
#: 16 deg above (the arm hangs below the hull's front: seen from the front and a little above it
#: stands in front of the hull, not under it) [A]. The other two are the earlier views.
DIRECTIONS = {
    "follow_arm": (math.cos(math.radians(16)) * math.cos(math.radians(38)),
                   math.cos(math.radians(16)) * math.sin(math.radians(38)), math.sin(math.radians(16))),
    "follow_three_quarter": (1.0, 1.0, 0.75),
    "follow_side": (0.0, -1.0, 0.12),
}


@dataclass(frozen=True)
class FollowCamera:
    """A follow camera: ``offset`` (3,) world offset of the eye from the vehicle origin [m],
    ``xyaxes`` (6,) its image x (right) and y (up) axes in the world, ``fovy`` [deg] and
    ``depth``: the vehicle origin's distance from the eye along the view axis [m]."""

    offset: np.ndarray
    xyaxes: np.ndarray
    fovy: float
    depth: float


def xyaxes_looking(forward: np.ndarray) -> np.ndarray:
    """Camera x and y axes (6) looking along ``forward`` with the world's z up in the image."""
    f = np.asarray(forward, dtype=float) / np.linalg.norm(forward)
    x = np.cross(f, [0.0, 0.0, 1.0])
    x = x / np.linalg.norm(x) if np.linalg.norm(x) > 1e-9 else np.array([1.0, 0.0, 0.0])
    return np.r_[x, np.cross(x, f)]


def heading_frame(arm_dir_world: np.ndarray) -> np.ndarray:
    """(3, 3) columns h, s, z: h the horizontal unit towards the arm (world), s = z x h, z up."""
    h = np.array([arm_dir_world[0], arm_dir_world[1], 0.0])
    h = h / np.linalg.norm(h) if np.linalg.norm(h) > 1e-9 else np.array([1.0, 0.0, 0.0])
    z = np.array([0.0, 0.0, 1.0])
    return np.column_stack([h, np.cross(z, h), z])


def fit_camera(points: np.ndarray, direction: np.ndarray, fovy: float, aspect: float,
               fill: float = FILL) -> FollowCamera:
    """The camera looking at the centre of the box of ``points`` (N, 3; offsets from the vehicle
    origin, world) from unit ``direction`` (world, target to eye), at the least distance at
    which every point projects within ``fill`` of the frame's half-width and half-height."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    center = 0.5 * (lo + hi)
    d = np.asarray(direction, dtype=float) / np.linalg.norm(direction)
    axes = xyaxes_looking(-d)
    right, up = axes[:3], axes[3:]
    rel = points - center
    tan_y = math.tan(math.radians(fovy) / 2)
    tan_x = tan_y * aspect
    # a point at rel projects to x = (rel . right) / (dist - rel . d) in units of the focal length
    dist = float(np.max(np.r_[rel @ d + np.abs(rel @ right) / (fill * tan_x),
                              rel @ d + np.abs(rel @ up) / (fill * tan_y)]))
    dist = max(dist, 0.3)
    eye = center + dist * d
    return FollowCamera(offset=eye, xyaxes=axes, fovy=fovy, depth=float(dist - (-center) @ d))


def px_per_metre(cam: FollowCamera, height: int) -> float:
    """Image scale [px/m] of a length perpendicular to the view axis at the vehicle's distance."""
    return height / (2.0 * cam.depth * math.tan(math.radians(cam.fovy) / 2))


def project(points: np.ndarray, eye: np.ndarray, xmat: np.ndarray, fovy: float, width: int,
            height: int) -> tuple[np.ndarray, np.ndarray]:
    """Pixel coordinates (N, 2: column from the left, row from the top) and depths (N,) of world
    ``points`` seen by a MuJoCo camera at ``eye`` with orientation ``xmat`` (3, 3: columns the
    camera's x right, y up, z backwards) and vertical field of view ``fovy`` [deg]."""
    rel = (np.asarray(points, dtype=float) - eye) @ np.asarray(xmat).reshape(3, 3)
    depth = -rel[:, 2]
    f = height / (2.0 * math.tan(math.radians(fovy) / 2))
    col = width / 2.0 + f * rel[:, 0] / depth
    row = height / 2.0 - f * rel[:, 1] / depth
    return np.column_stack([col, row]), depth
