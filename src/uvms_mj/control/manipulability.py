"""The arm's manipulability (the measure of Eq. 12) and the Eq. 12 and damped-least-squares
thresholds scaled to the arm, for :class:`uvms_mj.control.rac.RAC`.

The measure. B is the arm Jacobian (tip rows, arm dofs) of the task (rac.py); its
manipulability is w = sqrt(det(B B^T)), the product of B's singular values (Yoshikawa), equal to
|det B| for the paper's square B (:func:`manipulability`). It depends on the arm joints only:
a base rotation R turns B into R B (floating base: world rows; planar base: the tip rows along
the slides, turned about the plane's normal), and det(R B B^T R^T) = det(B B^T).

Why scale the thresholds. The paper's Js = 0.045 [m^2] and our damped-least-squares threshold
0.01 are absolute values of w, chosen for the paper's arm. w has units m^r (r tip rows) and
scales with the arm's size: on the BlueROV2's Alpha arm (3 rows, max w = 0.0081 m^3) both lie
above every value the arm can reach, so Eq. 12 and the damping were on at every sample.

The paper's arm in closed form. Planar 2R arm, link lengths l1, l2 (Table 1: 0.25, 0.25 m),
absolute link angles t1 = phi0 + phi1, t2 = t1 + phi2, tip pe = ... + l1 (cos t1, sin t1) +
l2 (cos t2, sin t2): B = d pe / d(phi1, phi2) = [[-l1 s1 - l2 s2, -l2 s2], [l1 c1 + l2 c2, l2 c2]],
det B = l1 l2 (c1 s2 - s1 c2) = l1 l2 sin(phi2) (tests/oracles/planar/kinematics.py). Its joints
have no limits, so max |det B| = l1 l2 = 0.0625 m^2 at phi2 = +-pi/2 (the arm bent at a right
angle), 0 stretched (phi2 = 0) or folded (phi2 = pi). The paper's Js is the fraction
Js / (l1 l2) = 0.72 of it: Eq. 12 engages where |sin phi2| < 0.72, within 46 deg of stretched
or folded.

Any arm (``js = "auto"``, the default): js = js_ratio w_max, js_ratio = 0.72 (the paper's
fraction, :data:`PAPER_JS_RATIO`), w_max = the largest manipulability over the arm's joint
ranges (:func:`max_manipulability`); ``dls_threshold = "auto"``: dls_ratio w_max, dls_ratio =
0.16 (our 0.01 on the paper's arm, :data:`DLS_RATIO`: within 9.2 deg of stretched there). On the
paper's robot this gives Js = 0.045 and 0.01 again (to round-off: w_max = l1 l2 to ~1e-16
relative), on any arm the same fractions of what the arm can reach, invariant to its size. A
number still sets an absolute threshold. Limit of the rule: on a 3-D positioning arm w / w_max is
the product of two sin-like factors (the elbow's and the tip's distance from the base joint's
axis), so the same fraction marks more of the joint space as near-singular (measured: 86 % of
the Alpha arm's joint box below 0.72 w_max, against 51 % of the paper arm's phi2 circle).

More task rows than arm joints (a 4-joint arm with ``tip_orientation``): w is 0 at every
configuration, every positive threshold gives the same run (Eq. 12 and the damping at every
sample, as before); "auto" then takes the paper arm's l1 l2 for w_max (the paper's numbers).

The search (:func:`max_manipulability`): a coarse grid over the arm joints (about
:data:`GRID_POINTS` points; a Halton sequence when the grid would have fewer than 4 points per
joint), then bounded Nelder-Mead from the :data:`N_STARTS` best points. Why: w is smooth,
cheap (one ``mj_kinematics`` + ``mj_jacSite``) and multi-modal (symmetric maxima, e.g. phi2 =
+-pi/2; several on 3-D arms), so a global coarse look then a local polish; gradient-free because
w's gradient needs second-order kinematics, and a maximum is flat (w error ~ (joint error)^2), so
Nelder-Mead's 1e-8 rad tolerance gives w to round-off. Deterministic (a fixed grid and starts).
About 0.1 s, once per nominal model: cached on the model's kinematic arrays, in memory and on disk
(:func:`_disk_cached`: scipy alone takes ~0.5 s to import, most of a ``uvms-mj validate``).
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import os
from typing import Any, Sequence

import mujoco
import numpy as np

from uvms_mj.control.base import ControllerError, check_positive
from uvms_mj.control.digital import PAPER_JS

__all__ = ["DLS_RATIO", "GRID_POINTS", "N_STARTS", "PAPER_ARM_MAX_MANIPULABILITY", "PAPER_DLS_THRESHOLD",
           "PAPER_JS_RATIO", "MaxManipulability", "describe_thresholds", "max_manipulability", "manipulability",
           "resolve_thresholds",
           "small_det", "small_inv"]

#: The paper arm's largest |det B| = l1 l2 [m^2] (Table 1: l1 = l2 = 0.25 m; module docstring).
PAPER_ARM_MAX_MANIPULABILITY = 0.25 * 0.25
#: Js as a fraction of the arm's largest manipulability: the paper's 0.045 / 0.0625 = 0.72.
PAPER_JS_RATIO = PAPER_JS / PAPER_ARM_MAX_MANIPULABILITY
#: Ours: damped least squares below 0.01 m^2 on the paper's arm (|sin phi2| < 0.16) ...
PAPER_DLS_THRESHOLD = 0.01
#: ... as a fraction of the arm's largest manipulability: 0.16.
DLS_RATIO = PAPER_DLS_THRESHOLD / PAPER_ARM_MAX_MANIPULABILITY
#: Points of the coarse search over the arm joints (module docstring).
GRID_POINTS = 4096
#: Best grid points refined by Nelder-Mead.
N_STARTS = 4


def small_inv(A: np.ndarray) -> np.ndarray:
    """Inverse of a 1x1, 2x2 or 3x3 matrix in closed form (adjugate / determinant; numpy's
    LAPACK call costs more than the arithmetic at these sizes), else ``numpy.linalg.inv``.

    Raises:
        numpy.linalg.LinAlgError: singular matrix (determinant exactly 0)."""
    n = A.shape[0]
    if n > 3:
        return np.linalg.inv(A)
    if n == 1:
        if A[0, 0] == 0:
            raise np.linalg.LinAlgError("Singular matrix")
        return np.array([[1.0 / A[0, 0]]])
    if n == 2:
        (a, b), (c, d) = A.tolist()
        det = a * d - b * c
        if det == 0:
            raise np.linalg.LinAlgError("Singular matrix")
        return np.array([[d / det, -b / det], [-c / det, a / det]])
    (a, b, c), (d, e, f), (g, h, i) = A.tolist()
    co = [e * i - f * h, f * g - d * i, d * h - e * g]
    det = a * co[0] + b * co[1] + c * co[2]
    if det == 0:
        raise np.linalg.LinAlgError("Singular matrix")
    return np.array([[co[0], c * h - b * i, b * f - c * e],
                     [co[1], a * i - c * g, c * d - a * f],
                     [co[2], b * g - a * h, a * e - b * d]]) / det


def small_det(A: np.ndarray) -> float:
    """Determinant of a 1x1, 2x2 or 3x3 matrix in closed form, else ``numpy.linalg.det``."""
    n = A.shape[0]
    if n == 1:
        return float(A[0, 0])
    if n == 2:
        return float(A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0])
    if n == 3:
        (a, b, c), (d, e, f), (g, h, i) = A.tolist()
        return a * (e * i - f * h) + b * (f * g - d * i) + c * (d * h - e * g)
    return float(np.linalg.det(A))


def manipulability(B: np.ndarray) -> tuple[float, float]:
    """(w, det B) of the arm Jacobian B (tip rows, arm dofs): w = |det B| for a square B, else
    sqrt(det(B B^T)) with det B NaN (the measure of Eq. 12; the compiled kernel computes the same)."""
    if B.shape[0] == B.shape[1]:
        detb = small_det(B)
        return abs(detb), detb
    return math.sqrt(max(small_det(B @ B.T), 0.0)), float("nan")


class MaxManipulability:
    """The largest manipulability of an arm over its joint ranges (:func:`max_manipulability`).

    Attributes:
        value: w_max [m^r, r tip rows]; 0 when it is identically 0 (more tip rows than arm dofs).
        q_arm: the arm joint angles [rad] (or slide positions [m]) where it is reached (None when
            identically 0).
        ranges: the (low, high) searched per arm dof.
    """

    def __init__(self, value: float, q_arm: np.ndarray | None, ranges: list[tuple[float, float]]) -> None:
        self.value, self.q_arm, self.ranges = float(value), q_arm, ranges

    def __repr__(self) -> str:
        return f"MaxManipulability(value={self.value!r}, q_arm={self.q_arm!r})"


_CACHE: dict[bytes, MaxManipulability] = {}
_CACHE_SIZE = 32


def _arm_ranges(model: mujoco.MjModel, arm_dofs: Sequence[int]) -> tuple[list[tuple[float, float]], list[bool]]:
    """(low, high) and periodic per arm dof: a limited joint's range; a hinge without one the
    full circle [-pi, pi) (periodic)."""
    ranges, periodic = [], []
    for d in arm_dofs:
        j = int(model.dof_jntid[d])
        typ = int(model.jnt_type[j])
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j) or f"#{j}"
        if typ not in (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE)):
            raise ControllerError(f"js = 'auto': arm joint {name!r} is a ball or free joint; the search over the arm's "
                                  "joint ranges takes hinges and slides: give js and dls_threshold as numbers")
        if model.jnt_limited[j]:
            lo, hi = (float(v) for v in model.jnt_range[j])
            ranges.append((lo, hi))
            periodic.append(False)
        elif typ == int(mujoco.mjtJoint.mjJNT_HINGE):
            ranges.append((-math.pi, math.pi))
            periodic.append(True)
        else:
            raise ControllerError(f"js = 'auto': arm joint {name!r} is a slide without a range; give it a range "
                                  "in the model or give js and dls_threshold as numbers")
    return ranges, periodic


def _key(model: mujoco.MjModel, tip_site: int, arm_dofs, rows) -> bytes:
    """What the arm Jacobian depends on: the kinematic tree, the joints, the sites, qpos0."""
    parts = [np.asarray(v) for v in (model.body_parentid, model.body_pos, model.body_quat, model.jnt_type,
                                      model.jnt_bodyid, model.jnt_qposadr, model.jnt_pos, model.jnt_axis,
                                      model.jnt_limited, model.jnt_range, model.site_bodyid, model.site_pos,
                                      model.site_quat, model.qpos0, model.dof_jntid)]
    parts += [np.asarray([tip_site]), np.asarray(arm_dofs, dtype=np.int64), np.asarray(rows, dtype=np.int64)]
    return b"|".join(np.ascontiguousarray(p).tobytes() for p in parts)


def _start_points(ranges, periodic) -> np.ndarray:
    """The coarse search's points: a grid of about GRID_POINTS (endpoints included, a periodic
    joint's once), or a Halton sequence where that grid would have fewer than 4 points a joint."""
    n = len(ranges)
    per = int(math.floor(GRID_POINTS ** (1.0 / n) + 1e-9))
    if per >= 4:
        axes = [np.linspace(lo, hi, per, endpoint=not p) for (lo, hi), p in zip(ranges, periodic)]
        return np.array(list(itertools.product(*axes)), dtype=float)
    from scipy.stats import qmc

    u = qmc.Halton(d=n, scramble=False).random(GRID_POINTS)
    lo, hi = np.array(ranges).T
    return lo + u * (hi - lo)


def max_manipulability(model: mujoco.MjModel, tip_site: int, arm_dofs: Sequence[int],
                       rows: Sequence[int]) -> MaxManipulability:
    """The largest manipulability (:func:`manipulability`) of the arm Jacobian B = rows of
    [jacp; jacr] of ``tip_site`` (``mj_jacSite``, world axes; rows 0-2 position, 3-5 rotation)
    on the columns ``arm_dofs``, over the arm joints' ranges (hinges without a range: the full
    circle), the other coordinates at ``qpos0`` (w does not depend on them: module docstring).
    Coarse grid + bounded Nelder-Mead (module docstring); cached per model kinematics.

    Raises:
        ControllerError: an arm joint the search cannot take (ball, free, slide without range)."""
    arm_dofs, rows = [int(d) for d in arm_dofs], [int(r) for r in rows]
    key = _key(model, tip_site, arm_dofs, rows)
    hit = _CACHE.get(key)
    if hit is not None:
        return hit
    ranges, periodic = _arm_ranges(model, arm_dofs)
    if len(rows) > len(arm_dofs) or not arm_dofs:  # rank B < rows: w is identically 0
        res = MaxManipulability(0.0, None, ranges)
    else:
        res = _disk_cached(key, lambda: _search(model, tip_site, arm_dofs, rows, ranges, periodic), ranges)
    if len(_CACHE) >= _CACHE_SIZE:
        _CACHE.pop(next(iter(_CACHE)))
    _CACHE[key] = res
    return res


#: Set to "off" to search every time (no disk cache); the suite sets it (tests/conftest.py).
ENV_DISK_CACHE = "UVMS_MJ_MANIPULABILITY_CACHE"


def _disk_cached(key: bytes, search, ranges) -> MaxManipulability:
    """``search()``'s result, kept as JSON in ``<cache_dir>/manipulability/<sha256>.json``
    (:func:`uvms_mj.physics.build.cache_dir`). The name hashes the kinematics ``key``, this module's
    source and the mujoco and scipy versions (all the result depends on); floats are written as
    their shortest round-trip repr, so a hit gives back the very numbers of a search. An unreadable
    or unwritable cache is a miss (the search runs); ``$UVMS_MJ_MANIPULABILITY_CACHE=off`` turns it off."""
    if os.environ.get(ENV_DISK_CACHE, "").lower() in ("off", "0", "false", "no"):
        return search()
    from importlib.metadata import PackageNotFoundError, version

    from uvms_mj.physics.build import cache_dir

    try:
        scipy_version = version("scipy")
    except PackageNotFoundError:
        scipy_version = "none"
    h = hashlib.sha256(key)
    for part in (open(__file__, "rb").read(), mujoco.__version__.encode(), scipy_version.encode()):
        h.update(b"|" + part)
    path = cache_dir() / "manipulability" / f"{h.hexdigest()}.json"
    try:
        d = json.loads(path.read_text())
        return MaxManipulability(d["value"], None if d["q_arm"] is None else np.array(d["q_arm"], dtype=float),
                                 ranges)
    except (OSError, ValueError, KeyError, TypeError):
        pass
    res = search()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")
        q = None if res.q_arm is None else [float(v) for v in res.q_arm]
        tmp.write_text(json.dumps({"value": res.value, "q_arm": q}))
        os.replace(tmp, path)  # atomic: a reader sees the whole file or none
    except OSError:
        pass
    return res


def _search(model, tip_site, arm_dofs, rows, ranges, periodic) -> MaxManipulability:
    from scipy.optimize import minimize

    data = mujoco.MjData(model)
    qadr = np.array([model.jnt_qposadr[model.dof_jntid[d]] for d in arm_dofs], dtype=int)
    jac = np.zeros((6, model.nv))

    def w(qa: np.ndarray) -> float:
        data.qpos[:] = model.qpos0
        data.qpos[qadr] = qa
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        mujoco.mj_jacSite(model, data, jac[:3], jac[3:], tip_site)
        return manipulability(jac[rows][:, arm_dofs])[0]

    pts = _start_points(ranges, periodic)
    vals = np.array([w(p) for p in pts])
    best = np.argsort(-vals, kind="stable")[:N_STARTS]
    scale = float(vals[best[0]])
    if not scale > 0.0:  # singular everywhere on the grid (a degenerate arm)
        return MaxManipulability(0.0, None, ranges)
    lo, hi = np.array(ranges).T
    step = (hi - lo) / max(2.0, round(len(pts) ** (1.0 / len(ranges))))
    q_best, w_best = pts[best[0]].copy(), scale
    for i in best:
        x0 = pts[i]
        simplex = [x0]
        for j in range(x0.size):  # one grid step along each joint, inward at a bound
            x = x0.copy()
            x[j] = x0[j] + step[j] if x0[j] + step[j] <= hi[j] else x0[j] - step[j]
            simplex.append(x)
        res = minimize(lambda x: -w(x) / scale, x0, method="Nelder-Mead", bounds=list(zip(lo, hi)),
                       options={"initial_simplex": np.array(simplex), "xatol": 1e-8, "fatol": 1e-14,
                                "maxiter": 2000 * x0.size, "maxfev": 4000 * x0.size})
        val = w(np.clip(res.x, lo, hi))
        if val > w_best:
            q_best, w_best = np.clip(res.x, lo, hi), val
    return MaxManipulability(w_best, q_best, ranges)


def _ratio(name: str, value: Any) -> float:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ControllerError(f"{name} = {value!r} must be a number in (0, 1]")
    v = float(value)
    if not (math.isfinite(v) and 0.0 < v <= 1.0):
        raise ControllerError(f"{name} = {value!r} must be a number in (0, 1] (a fraction of the arm's "
                              "largest manipulability)")
    return v


def _threshold(name: str, value: Any, allow_none: bool = False) -> float | str | None:
    """'auto', a number (checked > 0 by check_rac_settings) or, for js_high, None."""
    if value is None and allow_none:
        return None
    if isinstance(value, str):
        if value == "auto":
            return value
    elif not isinstance(value, (bool, np.bool_)) and isinstance(value, (int, float, np.integer, np.floating)):
        return check_positive(name, value)
    allowed = "'auto', a number > 0" + (" or null (= js)" if allow_none else "")
    raise ControllerError(f"{name} = {value!r}; allowed: {allowed}")


def resolve_thresholds(robot, arm_dofs: Sequence[int], rows: Sequence[int], js: Any = "auto",
                       js_high: Any = None, dls_threshold: Any = "auto", js_ratio: Any = PAPER_JS_RATIO,
                       js_high_ratio: Any = None, dls_ratio: Any = DLS_RATIO) -> dict[str, Any]:
    """The Eq. 12 thresholds and the damped-least-squares threshold of a RAC on ``robot`` (a
    :class:`uvms_mj.control.nominal.NominalRobot`) as numbers: "auto" = ratio x w_max
    (:func:`max_manipulability` of the arm Jacobian ``rows`` x ``arm_dofs``; js_high "auto" with
    js_high_ratio, default js_ratio), a number as given, js_high None = js (the paper's single
    threshold). Returns {"js", "js_high", "dls_threshold"} plus, when any is "auto",
    "max_manipulability", the ratios used and "auto" (the names resolved): what a run records.

    Raises:
        ControllerError: a value that is neither "auto" nor a number, a ratio outside (0, 1],
            js_high below js."""
    js, dls_threshold = _threshold("js", js), _threshold("dls_threshold", dls_threshold)
    js_high = _threshold("js_high", js_high, allow_none=True)
    js_ratio, dls_ratio = _ratio("js_ratio", js_ratio), _ratio("dls_ratio", dls_ratio)
    js_high_ratio = js_ratio if js_high_ratio is None else _ratio("js_high_ratio", js_high_ratio)
    auto = [n for n, v in (("js", js), ("js_high", js_high), ("dls_threshold", dls_threshold)) if v == "auto"]
    out: dict[str, Any] = {}
    if auto:
        lay = robot.layout
        found = max_manipulability(robot.model, lay.tip_site, arm_dofs, rows)
        w_max = found.value if found.value > 0.0 else PAPER_ARM_MAX_MANIPULABILITY  # identically 0: any > 0 is alike
        out.update(max_manipulability=found.value, auto=auto, js_ratio=js_ratio, dls_ratio=dls_ratio)
        if js == "auto":
            js = js_ratio * w_max
        if js_high == "auto":
            js_high = js_high_ratio * w_max
            out["js_high_ratio"] = js_high_ratio
        if dls_threshold == "auto":
            dls_threshold = dls_ratio * w_max
    js_high = js if js_high is None else js_high
    if js_high < js:
        raise ControllerError(f"js_high = {js_high:.6g} must be >= js = {js:.6g} (resolved from "
                              f"js = {'auto' if 'js' in auto else js!r}, js_high = "
                              f"{'auto' if 'js_high' in auto else js_high!r})")
    return {"js": js, "js_high": js_high, "dls_threshold": dls_threshold, **out}


def describe_thresholds(resolved: dict[str, Any]) -> str:
    """One line for :func:`resolve_thresholds`' result, e.g. ``js = 0.045 (auto: 0.72 x max
    manipulability 0.0625), js_high = js, dls_threshold = 0.01 (auto: 0.16 x ...)``."""
    auto, w = resolved.get("auto", ()), resolved.get("max_manipulability")
    ratio = {"js": resolved.get("js_ratio"), "js_high": resolved.get("js_high_ratio"),
             "dls_threshold": resolved.get("dls_ratio")}
    parts = []
    for k in ("js", "js_high", "dls_threshold"):
        v = resolved[k]
        if k == "js_high" and k not in auto and v == resolved["js"]:
            parts.append("js_high = js")
        elif k in auto:
            note = " (identically 0: the paper arm's l1 l2 used)" if not w else ""
            parts.append(f"{k} = {v:.6g} (auto: {ratio[k]:g} x max manipulability {w:.6g}{note})")
        else:
            parts.append(f"{k} = {v:.6g}")
    return ", ".join(parts)
