"""The hydrostatic (static) attitude of a free-floating vehicle with an arm, and its check
against recorded trials.

Equilibrium. Gravity (``m_i g`` at each body's centre of mass, MuJoCo's ``xipos``) and buoyancy
(``rho V_i g`` at each body's centre of buoyancy, ``uvms_mj.physics.hydro_of(m).bodies[i].cob``
in the body frame; ``rho`` = the ``uvms.water`` density) are all vertical, so their resultant
is a vertical force F_net and the horizontal (world x, y) components of their moment about a
reference point P decide the attitude: the vehicle is at rest in roll and pitch where they
vanish. Yaw does not enter (a turn about the vertical turns the moment with it). If F_net = 0
the moment is the same about every point; otherwise it changes by ``(P' - P) x F_net``, and the
point where whatever balances F_net acts (drag while sinking, the floor, a tether) matters.
:func:`equilibrium_attitude` takes the moment about the root body's origin by default (for the
Hinsdale model the vehicle's centre of gravity, where its surplus weight sits; as the model
file and tests/test_platform_models.py do), or about the total centre of mass / of buoyancy.
The last two give the same attitude (the pure couple B (r_B - r_G): as if F_net acted at the
centre of mass); "root" equals the attitude of the same model made neutral by changing the root
body's own mass (its weight acts at its origin and has no moment there). For the Hinsdale model
(F_net = -10.45 N, see the model file) the two choices differ by ~0.9 deg roll, ~2.6 deg pitch.

Solving. The moment is evaluated with MuJoCo's kinematics at the trial attitude (free joint at
the origin, yaw 0, the arm at the given angles) and its two horizontal components are driven to
zero with ``scipy.optimize.root`` (hybrid Powell) from level (or a given start), which finds the
upright (stable) equilibrium for a vehicle whose buoyancy acts above its weight. The result is
checked (residual, and stability: the moment must turn the vehicle back).

For a rigid configuration this has a closed form (the tests use it as the independent check):
with ``s = sum_j f_j r_j`` over all forces in the vehicle frame (f_j = +rho V g for buoyancy,
-m g for weight, r_j relative to P), the moment is ``R (s x u)`` with ``u = R^T e_z``, zero when
``u = s / |s|``: roll = atan2(s_y, s_z), pitch = asin(-s_x / |s|).

Static check. :func:`static_check` compares, per trial, the equilibrium at the arm pose before
the planned motion and at the end with the IMU's mean roll and pitch over the same windows:
before the motion (``t < start_time``; the first ``pre_window`` seconds if the trial has no
start time) and over the last ``post_window`` seconds. The arm pose of a window is the mean of
the joint angles there (the arm is still in both; :class:`StaticRow` records how far it moved).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Iterable, Mapping

import mujoco
import numpy as np

from uvms_mj.physics import hydro_of

__all__ = [
    "Equilibrium",
    "StaticCheck",
    "StaticRow",
    "StaticSummary",
    "equilibrium_attitude",
    "hydrostatic_moment",
    "static_check",
]


@dataclass(frozen=True)
class Equilibrium:
    """A hydrostatic equilibrium attitude.

    Attributes:
        roll, pitch: [rad] (Z-Y-X Euler angles with yaw 0; roll > 0 turns about the vehicle's
            x axis, pitch > 0 about its y axis).
        residual: max |horizontal moment| [N m] left at the solution.
        net_force: world z component of gravity + buoyancy [N] (> 0: floats up).
        about: the reference point of the moment (``"root"``, ``"com"``, ``"cob"``).
    """

    roll: float
    pitch: float
    residual: float
    net_force: float
    about: str


class _Hydrostatics:
    """Gravity and buoyancy points of a model's free-floating root body (and its subtree)."""

    def __init__(self, m: mujoco.MjModel, root: str | int | None = None):
        self.m = m
        if root is None:
            free = [j for j in range(m.njnt) if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE]
            if not free:
                raise ValueError("the model has no free joint")
            self.root = int(m.jnt_bodyid[free[0]])
        else:
            self.root = int(m.body(root).id)
        jnts = [j for j in range(m.njnt) if m.jnt_bodyid[j] == self.root and m.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE]
        if not jnts:
            raise ValueError(f"body {m.body(self.root).name!r} has no free joint")
        self.qadr = int(m.jnt_qposadr[jnts[0]])
        self.bodies = [b for b in range(1, m.nbody) if self._in_subtree(b)]
        info = hydro_of(m)
        if info.water is None:
            raise ValueError("the model declares no uvms.water instance (no water density)")
        self.rho = float(info.water.density)
        self.g = float(np.linalg.norm(m.opt.gravity))
        self.hydro = {b: h for b, h in info.bodies.items() if b in set(self.bodies)}
        self.d = mujoco.MjData(m)

    def _in_subtree(self, b: int) -> bool:
        while b > 0:
            if b == self.root:
                return True
            b = int(self.m.body_parentid[b])
        return False

    def set_pose(self, joints: Mapping[str, float]) -> None:
        """qpos = qpos0, then the named joints (hinge / slide) set."""
        self.d.qpos[:] = self.m.qpos0
        for name, v in joints.items():
            j = self.m.joint(name)  # KeyError for an unknown name
            if int(np.ravel(j.type)[0]) not in (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE)):
                raise ValueError(f"joint {name!r} is not a hinge or slide joint")
            self.d.qpos[int(np.ravel(j.qposadr)[0])] = float(v)

    def forces(self, roll: float, pitch: float):
        """World application points (K, 3) and vertical forces (K,) at attitude roll, pitch."""
        # R = Ry(pitch) Rx(roll): Z-Y-X Euler angles with yaw 0 (quaternion w x y z)
        cr, sr, cp, sp = math.cos(roll / 2), math.sin(roll / 2), math.cos(pitch / 2), math.sin(pitch / 2)
        q = np.array([cp * cr, cp * sr, sp * cr, -sp * sr])
        a = self.qadr
        self.d.qpos[a:a + 3] = 0.0
        self.d.qpos[a + 3:a + 7] = q
        mujoco.mj_kinematics(self.m, self.d)
        pts, f = [], []
        for b in self.bodies:
            if self.m.body_mass[b] > 0:
                pts.append(self.d.xipos[b].copy())
                f.append(-self.m.body_mass[b] * self.g)
        for b, h in self.hydro.items():
            if h.volume > 0:
                pts.append(self.d.xpos[b] + self.d.xmat[b].reshape(3, 3) @ np.asarray(h.cob, float))
                f.append(self.rho * h.volume * self.g)
        return np.array(pts), np.array(f)

    def moment(self, roll: float, pitch: float, about: str = "root") -> np.ndarray:
        """World moment (3,) of gravity + buoyancy about the reference point [N m]."""
        pts, f = self.forces(roll, pitch)
        if about == "root":
            p = self.d.xpos[self.root]
        elif about in ("com", "cob"):
            sel = f < 0 if about == "com" else f > 0
            if not sel.any():
                raise ValueError(f"no {'mass' if about == 'com' else 'volume'} to take the centre of")
            p = (np.abs(f[sel])[:, None] * pts[sel]).sum(0) / np.abs(f[sel]).sum()
        else:
            raise ValueError(f"about must be 'root', 'com' or 'cob', got {about!r}")
        r = pts - p
        # r x (0, 0, f) = (r_y f, -r_x f, 0)
        return np.array([(r[:, 1] * f).sum(), -(r[:, 0] * f).sum(), 0.0])


def hydrostatic_moment(m: mujoco.MjModel, joints: Mapping[str, float], roll: float, pitch: float,
                       about: str = "root", root: str | int | None = None) -> np.ndarray:
    """World moment [N m] of gravity and buoyancy at attitude (roll, pitch, yaw 0) and the arm
    at ``joints`` (name -> angle; unnamed joints at ``qpos0``), about the reference point."""
    hs = _Hydrostatics(m, root)
    hs.set_pose(joints)
    return hs.moment(roll, pitch, about)


def equilibrium_attitude(m: mujoco.MjModel, joints: Mapping[str, float] | None = None,
                         about: str = "root", root: str | int | None = None,
                         x0: tuple[float, float] = (0.0, 0.0), tol: float = 1e-13,
                         _hs: _Hydrostatics | None = None) -> Equilibrium:
    """The hydrostatic equilibrium roll and pitch (see the module docstring).

    Args:
        m: compiled model with a free-floating root body and a ``uvms.water`` density.
        joints: joint name -> angle [rad] (others at ``qpos0``).
        about: reference point of the moment: ``"root"`` (the free body's origin; default),
            ``"com"`` (total centre of mass), ``"cob"`` (total centre of buoyancy).
        root: the free body (default: the body of the first free joint).
        x0: start (roll, pitch) [rad].
        tol: solver tolerance (relative step).

    Returns:
        :class:`Equilibrium`.

    Raises:
        RuntimeError: no equilibrium found, or the one found is unstable (a top-heavy model).
    """
    from scipy.optimize import root as solve

    hs = _hs if _hs is not None else _Hydrostatics(m, root)
    hs.set_pose(joints or {})

    def res(x):
        return hs.moment(x[0], x[1], about)[:2]

    sol = solve(res, np.asarray(x0, float), method="hybr", tol=tol)
    r = np.abs(res(sol.x)).max()
    scale = max(1.0, float(np.abs(hs.forces(0.0, 0.0)[1]).sum()))  # N; moments ~ N x 0.1 m
    if not sol.success and r > 1e-9 * scale:
        raise RuntimeError(f"no hydrostatic equilibrium found: {sol.message} (residual {r:.3g} N m)")
    # stable if a small tilt makes a restoring moment: d M_x / d roll < 0, d M_y / d pitch < 0
    h = 1e-4
    k_r = (res(sol.x + [h, 0])[0] - res(sol.x - [h, 0])[0]) / (2 * h)
    k_p = (res(sol.x + [0, h])[1] - res(sol.x - [0, h])[1]) / (2 * h)
    if not (k_r < 0 and k_p < 0):
        raise RuntimeError(f"the equilibrium at roll {sol.x[0]:.4f}, pitch {sol.x[1]:.4f} rad is unstable")
    wrap = lambda a: float((a + math.pi) % (2 * math.pi) - math.pi)  # noqa: E731
    return Equilibrium(wrap(sol.x[0]), wrap(sol.x[1]), float(r), float(hs.forces(*sol.x)[1].sum()), about)


# ------------------------------------------------------------------------------- static check


@dataclass
class StaticRow:
    """One trial of :func:`static_check` (angles in degrees).

    Attributes:
        trial: name.
        pre, post: the time windows (t0, t1) [s] of "before the motion" and "at the end".
        n_pre, n_post: IMU samples in them.
        pred_pre, pred_post: predicted (roll, pitch) [deg] at the arm poses of the windows.
        meas_pre, meas_post: measured mean IMU (roll, pitch) [deg].
        arm_motion_pre, arm_motion_post: largest range of any joint angle within the window
            [deg] (the arm should be still there).
    """

    trial: str
    pre: tuple
    post: tuple
    n_pre: int
    n_post: int
    pred_pre: tuple
    pred_post: tuple
    meas_pre: tuple
    meas_post: tuple
    arm_motion_pre: float
    arm_motion_post: float

    @property
    def pred_change(self) -> np.ndarray:
        """Predicted (roll, pitch) change post - pre [deg]."""
        return np.subtract(self.pred_post, self.pred_pre)

    @property
    def meas_change(self) -> np.ndarray:
        """Measured (roll, pitch) change post - pre [deg]."""
        return np.subtract(self.meas_post, self.meas_pre)


@dataclass
class StaticSummary:
    """Statistics over trials of measured vs predicted (degrees).

    Attributes (each a dict with keys ``roll``, ``pitch``, ``both``: the two pooled):
        n: number of trials.
        corr: Pearson correlation of measured change vs predicted change.
        slope: least-squares slope through the origin, measured change = slope x predicted.
        rms_change: RMS of (measured - predicted) change [deg].
        rms_abs: RMS of (measured - predicted) absolute attitude, both windows [deg].
    """

    n: int
    corr: dict
    slope: dict
    rms_change: dict
    rms_abs: dict


@dataclass
class StaticCheck:
    """Result of :func:`static_check`: per trial rows, the summary, the trials left out."""

    rows: list
    summary: StaticSummary
    skipped: dict = field(default_factory=dict)

    def table(self) -> str:
        """A plain-text table (degrees)."""
        h = (f"{'trial':<11} {'pred d_roll':>11} {'meas d_roll':>11} {'pred d_pitch':>12} {'meas d_pitch':>12}"
             f" {'pred r0':>8} {'meas r0':>8} {'pred p0':>8} {'meas p0':>8} {'arm mv':>7}")
        out = [h, "-" * len(h)]
        for r in self.rows:
            pc, mc = r.pred_change, r.meas_change
            out.append(f"{r.trial:<11} {pc[0]:11.2f} {mc[0]:11.2f} {pc[1]:12.2f} {mc[1]:12.2f}"
                       f" {r.pred_pre[0]:8.2f} {r.meas_pre[0]:8.2f} {r.pred_pre[1]:8.2f} {r.meas_pre[1]:8.2f}"
                       f" {max(r.arm_motion_pre, r.arm_motion_post):7.2f}")
        s = self.summary
        out.append("-" * len(h))
        for k in ("roll", "pitch", "both"):
            out.append(f"{k:<6} n={s.n:<3} corr {s.corr[k]:6.3f}  slope {s.slope[k]:6.3f}  "
                       f"RMS change {s.rms_change[k]:5.2f} deg  RMS abs {s.rms_abs[k]:5.2f} deg")
        for name, why in self.skipped.items():
            out.append(f"skipped {name}: {why}")
        return "\n".join(out)


def _stats(pred: np.ndarray, meas: np.ndarray) -> tuple[float, float, float]:
    pred, meas = np.ravel(pred), np.ravel(meas)
    corr = float(np.corrcoef(pred, meas)[0, 1]) if len(pred) > 1 and pred.std() > 0 and meas.std() > 0 else math.nan
    pp = float(pred @ pred)
    slope = float(pred @ meas / pp) if pp > 0 else math.nan
    rms = float(np.sqrt(np.mean((meas - pred) ** 2))) if len(pred) else math.nan
    return corr, slope, rms


def static_check(m: mujoco.MjModel, trials: Iterable, post_window: float = 2.0,
                 pre_window: float = 2.0, about: str = "root",
                 joint_names: tuple[str, ...] | None = None) -> StaticCheck:
    """Predicted hydrostatic attitude changes against the measured ones, per trial and overall.

    Args:
        m: the compiled model of the configuration (e.g. ``models/hinsdale2023/hinsdale2023.xml``).
        trials: :class:`uvms_mj.analysis.trials.Trial` objects (or a ``TrialSet``).
        post_window: the end window, the last ``post_window`` seconds of the trial [s].
        pre_window: the start window of a trial with no start time (from its first sample) [s];
            with a start time the window is ``[first sample, start_time)``.
        about: the reference point of the moment (:func:`equilibrium_attitude`).
        joint_names: model joints of the columns of ``trial.joints.q`` (default: its ``names``).

    Returns:
        :class:`StaticCheck` (degrees). Trials with an empty window are left out and named.
    """
    hs = _Hydrostatics(m)
    rows, skipped = [], {}
    for tr in trials:
        imu, js = tr.imu, tr.joints
        t0 = max(imu.t[0], js.t[0])
        pre = (t0, tr.start_time if tr.start_time is not None else t0 + pre_window)
        post = (tr.t_end - post_window, tr.t_end + 1e-9)
        r0, p0, n0 = imu.window_mean(*pre)
        r1, p1, n1 = imu.window_mean(*post)
        sel0 = (js.t >= pre[0]) & (js.t < pre[1])
        sel1 = (js.t >= post[0]) & (js.t < post[1])
        if n0 == 0 or n1 == 0 or not sel0.any() or not sel1.any():
            skipped[tr.name] = f"empty window (pre {pre}, post {post})"
            continue
        names = joint_names or js.names
        preds = []
        for sel in (sel0, sel1):
            q = js.q[sel].mean(0)
            e = equilibrium_attitude(m, dict(zip(names, q)), about=about, _hs=hs)
            preds.append((math.degrees(e.roll), math.degrees(e.pitch)))
        rows.append(StaticRow(
            trial=tr.name, pre=pre, post=post, n_pre=n0, n_post=n1,
            pred_pre=preds[0], pred_post=preds[1],
            meas_pre=(math.degrees(r0), math.degrees(p0)), meas_post=(math.degrees(r1), math.degrees(p1)),
            arm_motion_pre=float(np.degrees(np.ptp(js.q[sel0], axis=0).max())),
            arm_motion_post=float(np.degrees(np.ptp(js.q[sel1], axis=0).max())),
        ))
    pc = np.array([r.pred_change for r in rows]).reshape(-1, 2)
    mc = np.array([r.meas_change for r in rows]).reshape(-1, 2)
    pa = np.array([[*r.pred_pre, *r.pred_post] for r in rows]).reshape(-1, 2, 2)
    ma = np.array([[*r.meas_pre, *r.meas_post] for r in rows]).reshape(-1, 2, 2)
    corr, slope, rms, rms_abs = {}, {}, {}, {}
    for k, sl in (("roll", [0]), ("pitch", [1]), ("both", [0, 1])):
        corr[k], slope[k], rms[k] = _stats(pc[:, sl], mc[:, sl])
        d = (ma - pa)[:, :, sl] if len(rows) else np.zeros(0)
        rms_abs[k] = float(np.sqrt(np.mean(d ** 2))) if np.size(d) else math.nan
    return StaticCheck(rows, StaticSummary(len(rows), corr, slope, rms, rms_abs), skipped)
