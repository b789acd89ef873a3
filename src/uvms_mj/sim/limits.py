"""A run's joint-limit excursions, from the TRUE joint angles and the PLANT model's ranges.

:func:`plant_joint_ranges` lists the plant's limited hinge joints (name -> qpos address and
``jnt_range`` [rad]); the sampled loop writes them into the run's meta (``joint_ranges``), so
that the excursion can be computed again from any saved log (:func:`joint_limit_excursion`). A run
whose joint leaves its range by more than :data:`JOINT_LIMIT_TOLERANCE_DEG` ends with status
``joint_limit`` (:func:`joint_limit_status`) unless it diverged or failed first.
"""

from __future__ import annotations

import math
from typing import Mapping

import mujoco
import numpy as np

__all__ = ["JOINT_LIMIT_TOLERANCE_DEG", "joint_limit_excursion", "joint_limit_reason", "joint_limit_status", "plant_joint_ranges"]

#: A joint further than this past its range [deg] makes the run's status ``joint_limit``
#: (ours: the issue's 1 deg; MuJoCo's soft limit constraint lets a joint pushed into its limit
#: by the motors' torque sink a fraction of a degree, which is not a violation).
JOINT_LIMIT_TOLERANCE_DEG = 1.0


def plant_joint_ranges(model: mujoco.MjModel) -> dict[str, list[float]]:
    """{joint name: [qpos address, lo, hi]} of the model's limited hinge joints (``jnt_range``,
    [rad]); slides and free joints are not listed."""
    out = {}
    for j in range(model.njnt):
        if model.jnt_limited[j] and int(model.jnt_type[j]) == int(mujoco.mjtJoint.mjJNT_HINGE):
            name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j) or f"joint{j}"
            lo, hi = (float(v) for v in model.jnt_range[j])
            out[name] = [int(model.jnt_qposadr[j]), lo, hi]
    return out


def joint_limit_excursion(q: np.ndarray, ranges: Mapping[str, list[float]] | None,
                          t: np.ndarray | None = None) -> dict:
    """The largest excursion past a range over joints and samples of ``q`` (N, nq) [rad]:
    ``{"deg": max(lo - q, q - hi, 0) in degrees, "joint", "side" ("lower"/"upper"), "t", "limit_deg"}``
    (deg 0 and joint "" when every joint stays inside; deg NaN when ``ranges`` is None or q is
    empty)."""
    out = {"deg": float("nan"), "joint": "", "side": "", "t": float("nan"), "limit_deg": float("nan")}
    q = np.asarray(q, dtype=float)
    if ranges is None or q.ndim != 2 or len(q) == 0:
        return out
    out["deg"] = 0.0
    best = 0.0
    for name, (adr, lo, hi) in ranges.items():
        x = q[:, int(adr)]
        below, above = lo - x, x - hi
        for side, e, lim in (("lower", below, lo), ("upper", above, hi)):
            k = int(np.argmax(e))
            if e[k] > best:
                best = float(e[k])
                out.update(deg=math.degrees(best), joint=name, side=side, limit_deg=math.degrees(lim),
                           t=float(t[k]) if t is not None and len(t) > k else float("nan"))
    return out


def joint_limit_status(q: np.ndarray, ranges: Mapping[str, list[float]] | None, t: np.ndarray | None = None,
                       tolerance_deg: float = JOINT_LIMIT_TOLERANCE_DEG) -> str:
    """The reason of a ``joint_limit`` status ("" when no joint leaves its range by more than
    ``tolerance_deg``), naming the joint, the excursion, the limit and the time."""
    return joint_limit_reason(joint_limit_excursion(q, ranges, t), tolerance_deg)


def joint_limit_reason(e: Mapping, tolerance_deg: float = JOINT_LIMIT_TOLERANCE_DEG) -> str:
    """The reason of a ``joint_limit`` status from an excursion (:func:`joint_limit_excursion`'s
    dict): "" unless it exceeds ``tolerance_deg``."""
    if not (e["deg"] > tolerance_deg):
        return ""
    return (f"joint {e['joint']} went {e['deg']:.2f} deg past its {e['side']} limit ({e['limit_deg']:.1f} deg) "
            f"at t = {e['t']:.3f} s (more than the {tolerance_deg:g} deg tolerated)")
