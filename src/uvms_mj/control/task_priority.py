"""``task_priority``: task-priority kinematic control with a velocity-tracking low-level loop.

The kinematic control of an underwater vehicle-manipulator system of Antonelli, *Underwater
Robots*, 4th ed., Springer 2018, ch. 9 ("Kinematic control": task-priority inverse kinematics,
after Nakamura, Hanafusa & Yoshikawa 1987, Siciliano & Slotine 1991 and Chiaverini 1997), for
any floating robot with an arm (``robots = "floating"``), on the controller's own nominal MuJoCo model
(:class:`uvms_mj.control.nominal.NominalRobot`).

Frames and units. Generalized velocities zeta are MuJoCo's qvel (Antonelli's zeta = [nu; q_dot]
with the vehicle's linear part in WORLD axes here): vehicle origin velocity v [m/s, world],
vehicle angular velocity omega [rad/s, BODY], joint rates [rad/s]. Every task Jacobian row is in
world axes (``mj_jacBody`` / ``mj_jacSite``). Positions [m], angles [rad], forces [N], moments
[N m].

Tasks, highest priority first (Antonelli ch. 9, "task-priority inverse kinematics"):

1. end-effector position sigma_1 = p_tip (world, 3), J_1 = d p_tip / d zeta;
2. vehicle attitude, error sigma~_2 = log(R_d R^T) (rotation vector, WORLD axes, as ``rac``),
   J_2 = the vehicle's world angular-velocity rows (= [0 R 0]);
3. vehicle position p_v (world, 3) and arm posture q (n joints), stacked, J_3 = [J_pv; 0 S],
   the posture rows scaled by ``posture_weight`` (a row weight in the task-3 least squares);
   by default (``posture_level = "below_position"``) the posture is a 4th level of its own,
   below the vehicle position.

Each task's reference velocity is the closed-loop inverse kinematics (CLIK) one (Antonelli ch. 9,
"kinematic control", sigma_dot_r = sigma_dot_d + Lambda sigma~), on the MEASURED task values:

    v_1 = p_dot_d(t) + gain_tip (p_d(t) - p_tip)
    v_2 = gain_attitude log(R_d R^T)                       (R_d: the station's attitude)
    v_3 = [p_dot_v,d(t) + gain_position (p_v,d(t) - p_v);  posture_weight (q_dot_d + gain_posture (q_d - q))]

with the station (p_v,d, R_d) = ``base_reference``, else the first measurement's position with a
level attitude at its yaw (``station_attitude``, :mod:`uvms_mj.control.station`), and, with a
``base_trajectory``, p_v,d(t), p_dot_v,d(t) its position and velocity (else constant, 0).

and the reference zeta_r by the recursive task-priority solution (``priority_form``):

* "siciliano_slotine" (default; Antonelli ch. 9, the task-priority solution of Siciliano &
  Slotine 1991, extended recursively with the augmented Jacobians):

      zeta_1 = J_1^# v_1
      zeta_i = zeta_{i-1} + (J_i N_{1..i-1})^# (v_i - J_i zeta_{i-1}),  N_{1..i} = I - J_{1..i}^+ J_{1..i}

  each lower task is solved in least squares inside the null space of the higher ones (it is
  achieved exactly when feasible, as well as possible otherwise, and never disturbs them);
* "singularity_robust" (Chiaverini 1997, Antonelli ch. 9 "singularity-robust task priority"):

      zeta_r = J_1^# v_1 + N_1 J_2^# v_2 + N_{12} J_3^# v_3

  (each task inverted alone, then projected: no algorithmic singularities, lower tasks are not
  least-squares optimal when they conflict).

J_{1..i} is the stacked (augmented) Jacobian of tasks 1..i. Null-space projectors use the exact
Moore-Penrose pseudo-inverse (SVD, singular values below ``rank_tol`` times the largest treated
as zero), so N J = 0 and N N = N to round-off. The task solutions use a DAMPED pseudo-inverse
(damped least squares, Antonelli ch. 9 on kinematic singularities; Nakamura & Hanafusa 1986),
per singular value: A^# = V diag(s_i / (s_i^2 + lambda_i^2)) U^T with

    lambda_i^2 = dls_damping^2 (1 - (s_i / dls_threshold)^2)   if s_i < dls_threshold, else 0

(s_i in the Jacobian's own units: 1 for the vehicle's translation, m for the tip per joint rad;
s_i <= ``rank_tol`` s_max are exact zeros, inverted as 0), so well-conditioned directions are inverted exactly and the solution stays bounded (<= 1 /
(2 dls_damping) per unit task velocity) through a singularity.

Low-level loop (Antonelli ch. 9, "kinematic control" with a dynamic low-level velocity
controller; the vehicle's and joints' PI velocity loops of its dynamic-control chapters): the
reference is integrated, q_r(k+1) = q_r(k) (+) T zeta_r(k) (``mj_integratePos``, q_r(0) =
q(0)), and every dof tracks it with a PD on the reference (= a PI on the velocity error
zeta_r - zeta):

    u = Kp (q_r (-) q) + Kd (zeta_r - zeta) + h(q)

(q_r (-) q: ``mj_differentiatePos``, in qvel coordinates; h(q): the nominal hold force, gravity
minus buoyancy, the restoring-force compensation of Antonelli's dynamic control). The lead
q_r (-) q is clamped to ``reference_lead_limit`` per dof (anti-windup: q_r is pulled back
along). Vehicle rows of u: world force and body moment (MuJoCo's free-joint dofs), sent as the
body wrench [R^T F; M] to the saturating allocator :class:`uvms_mj.physics.thrusters.Allocator`; joint
rows clipped to the motors' ranges. Gains, unless given, from the nominal mass matrix M at the
initial state: Kp_i = M_ii w_i^2, Kd_i = 2 damping_ratio w_i M_ii (a critically damped
second-order loop per dof, as ``station_pid``), w_i = ``bandwidth_base`` /
``bandwidth_attitude`` / ``bandwidth_joints``. The joint rows, by default (``joint_gains =
"inertia"``, ours), use the whole nominal joint-block inertia at the measured q instead of its
diagonal: u_j = M_jj(q) (w_j^2 lead_j + 2 damping_ratio w_j (zeta_r - zeta)_j) + h_j, so every
joint-space mode has the bandwidth w_j. Why: with diagonal gains a mode's bandwidth is w_j
sqrt(lambda), lambda an eigenvalue of M_jj^-1 diag(M_jj), and on the Alpha arm lambda_max grows
from 3.6 (shoulder 40, elbow 90 deg) to 8.6 stretched (80, 160 deg): 29 rad/s at T = 0.02 s,
where the sampled loop oscillated at 5 Hz and diverged in the reach study
(scenarios/bluerov2_alpha_beyond_reach.yaml). ``joint_gains = "diagonal"``: the diagonal gains
above on the joints too (as before).

Defaults. A cascade: the kinematic (outer) gains, 1/s on the tip and the attitude and 0.5/s on
task 3, sit below the low-level (inner) bandwidths, 2 rad/s on the vehicle's translation,
3 rad/s on its rotation, 10 rad/s on the joints (station_pid's 1, 2, 6 raised: here the loops
track a moving reference instead of holding a fixed one); every kinematic gain must satisfy
gain T < 1 (the sampled CLIK error e(k+1) = (1 - gain T) e(k) then decays monotonically).
dls_threshold 0.01 and dls_damping 0.05 (Jacobian units): the damping starts where the arm's
tip Jacobian loses two orders of magnitude against its usual 0.1 - 0.3 m/rad; rank_tol 1e-10.

Reach. With the vehicle position held below the tip task (``carry = "hold"``, the default: the
textbook controller), a tip path that leaves the arm's reach pulls the vehicle off its station by
priority; what made that run diverge (``sum |q_dot| > 100`` at 4.8 s in
scenarios/bluerov2_alpha_beyond_reach.yaml, 5.7 s with dls_threshold 0.1: the damping does not
help) was the joint loop (``joint_gains``, "Low-level loop" above), not the priorities. Ours,
``carry = "path"``: the paper's Eq. 12 transposed to this controller, as
``rac`` does, while the arm's manipulability w = sqrt(det(B B^T)) (B: the tip Jacobian on the arm
joints, nominal model at the measured q) is below ``js`` (by default "auto": 0.72 w_max, the
paper's fraction, :mod:`uvms_mj.control.manipulability`) the vehicle's desired position moves
with the tip path, p_v,d += T (p_d(t + T) - p_d(t)) / T per sample, its velocity fed forward in
v_3 (:class:`uvms_mj.control.digital.SingularHandler`, carry "path", ramps of ``n_ramp``
samples; release above ``js_high``): the vehicle carries the arm, which keeps the posture it had
at js, away from the singularity (measured in the reach study: vehicle error against its
desired position 3.6 mm max with "path", against the fixed station 145 mm with "hold").

References are to chapter and topic; the book's equation numbers were not checked against a
copy (the forms are the standard ones of the cited papers: Nakamura, Hanafusa & Yoshikawa 1987;
Siciliano & Slotine 1991; Chiaverini 1997).

Velocities: ``measurement.qd`` when there is a velocity sensor, else backward differences of the
measured poses (``mj_differentiatePos`` on the nominal model; zero at the first sample).
"""

from __future__ import annotations

import math
from typing import Any, Sequence

import mujoco
import numpy as np

from uvms_mj.control.digital import SingularHandler
from uvms_mj.control.manipulability import PAPER_JS_RATIO, manipulability, resolve_thresholds
from uvms_mj.control.limits import JOINT_LIMIT_MARGIN, JointLimits
from uvms_mj.control.nominal import JointTrajectory, NominalRobot
from uvms_mj.physics.thrusters import Allocator
from uvms_mj.control.base import Command, Controller, ControllerError, Measurement, check_positive, register
from uvms_mj.rotations import rotation_log
from uvms_mj.control.station import check_base_reference, check_base_trajectory, check_station_attitude, station_reference
from uvms_mj.control.station_pid import DEFAULT_T

#: The priority forms (module docstring).
PRIORITY_FORMS = ("siciliano_slotine", "singularity_robust")
#: The vehicle's carry of the arm (``carry``; module docstring "Reach").
TP_CARRY_MODES = ("path", "hold")
#: How the joint rows of the low-level loop are scaled (``joint_gains``; module docstring).
JOINT_GAINS = ("inertia", "diagonal")
#: Where the arm posture sits in the hierarchy (``posture_level``).
POSTURE_LEVELS = ("with_position", "below_position")


# ------------------------------------------------------------------ linear algebra


def pinv_exact(A: np.ndarray, rank_tol: float) -> np.ndarray:
    """Moore-Penrose pseudo-inverse by SVD; singular values <= rank_tol * s_max count as zero."""
    A = np.atleast_2d(np.asarray(A, dtype=float))
    if A.size == 0:
        return np.zeros((A.shape[1], A.shape[0]))
    U, s, Vt = np.linalg.svd(A, full_matrices=False)
    keep = s > rank_tol * max(float(s[0]) if s.size else 0.0, 1e-300)
    inv = np.where(keep, 1.0 / np.where(keep, s, 1.0), 0.0)
    return (Vt.T * inv) @ U.T


def null_space_projector(J: np.ndarray, rank_tol: float = 1e-10) -> np.ndarray:
    """N = I - J^+ J (exact pseudo-inverse): the orthogonal projector onto ker J (Antonelli ch. 9,
    task-priority: the null-space projector of a task). N is symmetric, N N = N and J N = 0 to
    round-off, computed as I - V_r V_r^T from the SVD (V_r: the rank-r right singular vectors)."""
    J = np.atleast_2d(np.asarray(J, dtype=float))
    n = J.shape[1]
    if J.shape[0] == 0:
        return np.eye(n)
    _, s, Vt = np.linalg.svd(J, full_matrices=False)
    r = int(np.sum(s > rank_tol * max(float(s[0]), 1e-300))) if s.size else 0
    V = Vt[:r].T
    return np.eye(n) - V @ V.T


def damped_pinv(A: np.ndarray, threshold: float, damping: float, rank_tol: float = 1e-10) -> tuple[np.ndarray, float]:
    """Damped pseudo-inverse with per-singular-value variable damping (damped least squares,
    Antonelli ch. 9 on kinematic singularities): s_i / (s_i^2 + lambda_i^2), lambda_i^2 =
    damping^2 (1 - (s_i / threshold)^2) below ``threshold``, 0 above; singular values <=
    rank_tol s_max count as exact zeros (inverted as 0). Returns (A^#, the largest
    lambda^2 used on a non-zero singular value, > rank_tol s_max: a structurally zero one is
    inverted as 0 whatever its lambda)."""
    A = np.atleast_2d(np.asarray(A, dtype=float))
    if A.size == 0:
        return np.zeros((A.shape[1], A.shape[0])), 0.0
    U, s, Vt = np.linalg.svd(A, full_matrices=False)
    lam2 = np.where(s < threshold, damping ** 2 * (1.0 - (s / threshold) ** 2), 0.0)
    # structurally zero singular values (<= rank_tol s_max: round-off of a rank deficiency, whose
    # singular vectors are noise) are inverted as 0, never amplified
    nonzero = s > rank_tol * max(float(s[0]), 1e-300)
    den = s * s + lam2
    inv = np.where(nonzero, s / np.where(nonzero, den, 1.0), 0.0)
    return (Vt.T * inv) @ U.T, float(np.max(lam2[nonzero], initial=0.0))


def task_priority_velocity(tasks: Sequence[tuple[np.ndarray, np.ndarray]], form: str = "siciliano_slotine",
                           dls_threshold: float = 1e-2, dls_damping: float = 5e-2,
                           rank_tol: float = 1e-10) -> dict[str, Any]:
    """Reference velocity of prioritised tasks [(J_1, v_1), (J_2, v_2), ...] (highest first).

    Returns ``zeta`` (the reference), ``levels`` (zeta after each level: levels[i] - levels[i-1]
    is task i's correction), ``projectors`` (N_{1..i} after each level, exact) and
    ``damping`` (the largest lambda^2 per level). Module docstring for the two forms."""
    if form not in PRIORITY_FORMS:
        raise ControllerError(f"priority_form = {form!r}; allowed: {', '.join(PRIORITY_FORMS)}")
    n = np.atleast_2d(tasks[0][0]).shape[1]
    zeta = np.zeros(n)
    N = np.eye(n)
    stacked = np.zeros((0, n))
    levels, projectors, damping = [], [], []
    for J, v in tasks:
        J = np.atleast_2d(np.asarray(J, dtype=float))
        v = np.asarray(v, dtype=float).ravel()
        if form == "siciliano_slotine":
            # zeta_i = zeta_{i-1} + (J_i N_{1..i-1})^# (v_i - J_i zeta_{i-1}) (Antonelli ch. 9)
            A = J @ N
            Ad, lam2 = damped_pinv(A, dls_threshold, dls_damping, rank_tol)
            # Ad = N J^T (...) lies in range(N) (N symmetric): no effect on the higher tasks.
            zeta = zeta + Ad @ (v - J @ zeta)
        else:
            # zeta_r += N_{1..i-1} J_i^# v_i (Chiaverini's singularity-robust form, Antonelli ch. 9)
            Jd, lam2 = damped_pinv(J, dls_threshold, dls_damping, rank_tol)
            zeta = zeta + N @ (Jd @ v)
        stacked = np.vstack((stacked, J))
        N = null_space_projector(stacked, rank_tol)  # N_{1..i} = I - J_{1..i}^+ J_{1..i}
        levels.append(zeta.copy())
        projectors.append(N.copy())
        damping.append(lam2)
    return {"zeta": zeta, "levels": levels, "projectors": projectors, "damping": damping}


def _vector(name: str, value: Any, size: int) -> np.ndarray | None:
    if value is None:
        return None
    try:
        arr = np.atleast_1d(np.asarray(value, dtype=float))
    except (TypeError, ValueError):
        raise ControllerError(f"{name} = {value!r} must be 1 or {size} finite numbers >= 0") from None
    if arr.size == 1:
        arr = np.full(size, float(arr[0]))
    if arr.shape != (size,) or not np.all(np.isfinite(arr)) or np.any(arr < 0):
        raise ControllerError(f"{name} = {value!r} must be 1 or {size} finite numbers >= 0")
    return arr


def _nonneg(name: str, value: Any) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ControllerError(f"{name} = {value!r} must be a finite number >= 0") from None
    if not (math.isfinite(v) and v >= 0):
        raise ControllerError(f"{name} = {value!r} must be finite and >= 0")
    return v


def _positive(name: str, value: Any) -> float:
    try:
        return check_positive(name, value)
    except (TypeError, ValueError) as exc:
        if isinstance(exc, ControllerError):
            raise
        raise ControllerError(f"{name} = {value!r} must be finite and > 0") from None


@register("task_priority")
class TaskPriority(Controller):
    """Task-priority kinematic control + PD-on-reference low-level loop (module docstring).

    Args:
        robot: the controller's :class:`NominalRobot` (given by the scenario; never the plant).
        trajectory: desired tip path, any object with ``position(t)`` and ``velocity(t)``
            (world [m], [m/s]; :mod:`uvms_mj.control.trajectories`); None: hold the initial tip.
        arm_trajectory: desired arm posture of task 3 (None: the initial angles).
        T: controller period [s].
        gain_tip: Lambda_1 of the tip task [1/s].
        gain_attitude: Lambda_2 of the vehicle attitude task [1/s].
        gain_position: Lambda_3 of the vehicle position hold [1/s].
        gain_posture: Lambda_3 of the arm posture [1/s].
        posture_weight: weight of the posture rows against the vehicle-position rows in task 3's
            least squares [m/rad] (> 0): where the two conflict (the arm's position joints are
            fixed by the tip once the vehicle is), task 3 settles where gain-weighted position
            and posture errors balance, |e_pos| ~ posture_weight |e_posture|.
        posture_level: "below_position" (default: a 4th, lowest level: the vehicle position is
            held exactly, kinematically, the posture only uses what is left) | "with_position"
            (the posture rows stacked with the vehicle position in task 3: the vehicle then gives
            way by about posture_weight times the posture error, 4-5 cm in the 3-D studies).
        priority_form: "siciliano_slotine" | "singularity_robust".
        dls_threshold: singular value below which the task inverses are damped (Jacobian units).
        dls_damping: lambda_max of the damped least squares (same units).
        rank_tol: relative rank tolerance of the exact projectors.
        bandwidth_base, bandwidth_attitude, bandwidth_joints: low-level loop bandwidths [rad/s].
        damping_ratio: of every low-level loop.
        kp, kd: explicit low-level gains (1 or nv numbers, per qvel dof: N/m, N m/rad, N m/rad;
            N s/m, N m s/rad), overriding the bandwidth ones.
        reference_lead_limit: largest |q_r (-) q| per dof [m or rad] (anti-windup; default 1:
            0.1 bounded the loop's integral action below the moment of a 1 % buoyancy error,
            leaving a 4 deg attitude offset in the sweep study).
        feedforward: add the nominal hold force.
        base_reference: the vehicle pose to hold (x, y, z [m] world, qw, qx, qy, qz; the
            scenario's ``vehicle.setpoint``); default the first measurement's position, its
            attitude by ``station_attitude``.
        base_trajectory: the vehicle origin's path (``position(t)``, ``velocity(t)``, world [m],
            [m/s]; the scenario's ``vehicle.trajectory``): task 3's p_v,d(t) with the
            feed-forward p_dot_v,d(t); the attitude stays the station's.
        station_attitude: the default station's attitude: "level" (default: roll = pitch = 0 at
            the measured yaw) | "measured" (:mod:`uvms_mj.control.station`).
        joint_gains: "inertia" (default, ours: the joint rows' PD through the nominal joint-block
            inertia at the measured q) | "diagonal" (module docstring, "Low-level loop"); explicit
            kp / kd always act per dof.
        carry: "hold" (default: the station, the tip task above it) | "path" (ours: the vehicle
            carries the arm along the tip path while the arm's manipulability is below js;
            module docstring "Reach").
        js, js_high, js_ratio, n_ramp: the carry's thresholds and ramp, as ``rac``'s Eq. 12 ones
            ("auto" = js_ratio x the arm's largest manipulability; js_high default js; 30 samples).
        joint_limits, joint_limit_margin: (ours; default true, 2 deg) keep the integrated
            reference q_r of the arm joints inside the nominal ranges minus the margin
            (:mod:`uvms_mj.control.limits`): the arm rows of zeta_r are clipped so that
            q_r + T zeta_r stays inside, and q_r itself is clamped (after the anti-windup pull-back).
            The posture reference (arm waypoints) is clamped too.
    """

    robots = "floating"

    def __init__(self, robot: NominalRobot, trajectory=None, arm_trajectory: JointTrajectory | None = None,
                 T: float = DEFAULT_T, gain_tip: float = 1.0, gain_attitude: float = 1.0, gain_position: float = 0.5,
                 gain_posture: float = 0.5, posture_weight: float = 0.1, posture_level: str = "below_position",
                 priority_form: str = "siciliano_slotine",
                 dls_threshold: float = 1e-2, dls_damping: float = 5e-2, rank_tol: float = 1e-10,
                 bandwidth_base: float = 2.0, bandwidth_attitude: float = 3.0, bandwidth_joints: float = 10.0,
                 damping_ratio: float = 1.0, kp=None, kd=None, reference_lead_limit: float = 1.0,
                 feedforward: bool = True, base_reference=None, base_trajectory=None,
                 station_attitude: str | None = None, carry: str = "hold", js: float | str = "auto",
                 js_high: float | str | None = None, js_ratio: float = PAPER_JS_RATIO, n_ramp: int = 30,
                 joint_gains: str = "inertia", joint_limits: bool = True,
                 joint_limit_margin: float = JOINT_LIMIT_MARGIN) -> None:
        if not isinstance(robot, NominalRobot):
            raise ControllerError("task_priority needs robot= a NominalRobot (a floating robot scenario)")
        self.base_reference = check_base_reference(base_reference)
        self.base_trajectory = check_base_trajectory(base_trajectory, velocity=True)
        lay = robot.layout
        if not lay.base_free:
            raise ControllerError("task_priority needs a floating robot (a free-joint vehicle)")
        self.station_attitude = check_station_attitude(station_attitude, True, self.base_reference)
        if lay.tip_site < 0:
            raise ControllerError("task_priority needs an end-effector site (tip_site)")
        self.robot = robot
        self.trajectory = trajectory
        if trajectory is not None and not (hasattr(trajectory, "position") and hasattr(trajectory, "velocity")):
            raise ControllerError(f"trajectory = {trajectory!r} must have position(t) and velocity(t)")
        self.T = _positive("T", T)
        for nm, v in (("gain_tip", gain_tip), ("gain_attitude", gain_attitude), ("gain_position", gain_position),
                      ("gain_posture", gain_posture)):
            g = _nonneg(nm, v)
            if g * self.T >= 1.0:  # the sampled CLIK error e(k+1) = (1 - g T) e(k) must converge monotonically
                raise ControllerError(f"{nm} = {v!r} must be < 1/T = {1.0 / self.T:g} 1/s")
            setattr(self, nm, g)
        self.posture_weight = _positive("posture_weight", posture_weight)
        if posture_level not in POSTURE_LEVELS:
            raise ControllerError(f"posture_level = {posture_level!r}; allowed: {', '.join(POSTURE_LEVELS)}")
        self.posture_level = posture_level
        if priority_form not in PRIORITY_FORMS:
            raise ControllerError(f"priority_form = {priority_form!r}; allowed: {', '.join(PRIORITY_FORMS)}")
        self.priority_form = priority_form
        self.dls_threshold = _positive("dls_threshold", dls_threshold)
        self.dls_damping = _positive("dls_damping", dls_damping)
        self.rank_tol = _positive("rank_tol", rank_tol)
        if self.rank_tol >= 1.0:
            raise ControllerError(f"rank_tol = {rank_tol!r} must be < 1")
        self.bandwidth_base = _positive("bandwidth_base", bandwidth_base)
        self.bandwidth_attitude = _positive("bandwidth_attitude", bandwidth_attitude)
        self.bandwidth_joints = _positive("bandwidth_joints", bandwidth_joints)
        self.zeta_ratio = _positive("damping_ratio", damping_ratio)
        nv = robot.model.nv
        self.kp_given = _vector("kp", kp, nv)
        self.kd_given = _vector("kd", kd, nv)
        self.reference_lead_limit = _positive("reference_lead_limit", reference_lead_limit)
        self.feedforward = bool(feedforward)
        if arm_trajectory is not None and tuple(arm_trajectory.names) != tuple(lay.joint_names):
            raise ControllerError("arm_trajectory joints differ from the robot's")
        self.arm = arm_trajectory
        self.nj = len(lay.joint_names)
        B = robot.allocation()
        self.allocator = Allocator(B, robot.thruster_lo, robot.thruster_hi) if B.shape[1] else None
        self.d = int(lay.base_dadr)
        self.joint_dofs = np.asarray(lay.joint_dadr, dtype=int)
        if joint_gains not in JOINT_GAINS:
            raise ControllerError(f"joint_gains = {joint_gains!r}; allowed: {', '.join(JOINT_GAINS)}")
        self.joint_gains = joint_gains
        if carry not in TP_CARRY_MODES:
            raise ControllerError(f"carry = {carry!r}; allowed: {', '.join(TP_CARRY_MODES)}")
        self.carry = carry
        if int(n_ramp) != n_ramp or n_ramp < 1:
            raise ControllerError(f"n_ramp = {n_ramp!r} must be an integer >= 1")
        self.n_ramp = int(n_ramp)
        self.resolved_params: dict[str, Any] = {"carry": carry}
        if carry != "hold":  # the carry's thresholds as numbers (what a run records)
            res = resolve_thresholds(robot, self.joint_dofs, [0, 1, 2], js, js_high, self.dls_threshold,
                                     js_ratio=js_ratio)
            self.js, self.js_high = res["js"], res["js_high"]
            self.resolved_params.update({k: v for k, v in res.items() if k != "dls_threshold"})
        #: The arm joints' bounds on the nominal model (:mod:`uvms_mj.control.limits`).
        self.limits = JointLimits(robot.model, lay.joint_qadr, self.T, joint_limits, joint_limit_margin)

    # ------------------------------------------------------------------ pieces

    def tasks(self, t: float, q: np.ndarray, jac: dict) -> tuple[list[tuple[np.ndarray, np.ndarray]], dict]:
        """The prioritised tasks [(J_i, v_i)] (3, or 4 with posture_level "below_position") at
        time t for the measured q (with the nominal model's ``jacobians()`` at q), and their
        errors (module docstring)."""
        lay, nv = self.robot.layout, self.robot.model.nv
        a = lay.base_qadr
        p_d, v_d = self._tip_desired(t)
        e_tip = p_d - jac["tip"]                                    # world [m]
        e_att = rotation_log(self.R_ref @ jac["R_base"].T)          # world rotation vector [rad]
        pv_d, vv_d = self._base_desired(t)
        e_pos = pv_d - q[a:a + 3]                                   # world [m]
        qj_d, qdj_d = self._posture(t)
        e_post = qj_d - q[lay.joint_qadr]                           # [rad]
        J1 = jac["tip_p"]
        J2 = jac["base_r"]
        S = np.zeros((self.nj, nv))
        S[np.arange(self.nj), self.joint_dofs] = 1.0
        w = self.posture_weight
        # CLIK reference velocities sigma_dot_d + Lambda sigma~ (Antonelli ch. 9, kinematic control)
        v1 = v_d + self.gain_tip * e_tip
        v2 = self.gain_attitude * e_att
        v_pos = vv_d + self.gain_position * e_pos
        v_post = w * (qdj_d + self.gain_posture * e_post)
        errors = {"e_tip": e_tip, "e_attitude": e_att, "e_position": e_pos, "e_posture": e_post,
                  "tip_desired": p_d, "base_desired": pv_d}
        if self.posture_level == "below_position":  # a 4th level: posture strictly below position
            return [(J1, v1), (J2, v2), (jac["base_p"], v_pos), (w * S, v_post)], errors
        J3 = np.vstack((jac["base_p"], w * S))
        return [(J1, v1), (J2, v2), (J3, np.concatenate((v_pos, v_post)))], errors

    def _base_desired(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """The vehicle origin's desired position and velocity at t (world [m], [m/s]), plus the
        carry's offset and velocity (module docstring "Reach"; zero before ``compute``)."""
        off, v_off = getattr(self, "_carry", (np.zeros(3), np.zeros(3)))
        if self.base_trajectory is None:
            return self.p_ref + off, v_off
        return (np.asarray(self.base_trajectory.position(t), dtype=float).reshape(3) + off,
                np.asarray(self.base_trajectory.velocity(t), dtype=float).reshape(3) + v_off)

    def _v_path(self, k: int) -> np.ndarray:
        """The tip path's velocity over [k, k+1) [m/s, world]: the carry's velocity."""
        t = (k - self.k0) * self.T + self.t0
        return (self._tip_desired(t + self.T)[0] - self._tip_desired(t)[0]) / self.T

    def _tip_desired(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        if self.trajectory is None:
            return self.tip0.copy(), np.zeros(3)
        p = np.asarray(self.trajectory.position(t), dtype=float).reshape(3)
        v = np.asarray(self.trajectory.velocity(t), dtype=float).reshape(3)
        return p, v

    def _posture(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        if self.arm is None:
            return self.q_joint0.copy(), np.zeros(self.nj)
        qd, qdd = self.arm(t)
        return self.limits.clamp_position(np.asarray(qd, dtype=float)), np.asarray(qdd, dtype=float)

    # ------------------------------------------------------------------ interface

    def reset(self, measurement: Measurement) -> None:
        r, lay, d = self.robot, self.robot.layout, self.d
        q = np.asarray(measurement.q, dtype=float).copy()
        self.p_ref, self.quat_ref, self.R_ref, self.q_joint0 = station_reference(q, lay, self.base_reference, self.station_attitude)
        M = r.mass_matrix(q)
        self.tip0 = r.jacobians()["tip"].copy()
        m = np.diag(M)
        wb = np.zeros(r.model.nv)
        wb[:] = self.bandwidth_joints
        wb[d:d + 3] = self.bandwidth_base
        wb[d + 3:d + 6] = self.bandwidth_attitude
        self.kp = self.kp_given if self.kp_given is not None else m * wb ** 2
        self.kd = self.kd_given if self.kd_given is not None else 2.0 * self.zeta_ratio * wb * m
        self.q_ref = q.copy()           # integrated reference configuration q_r
        self.q_prev = q.copy()
        self.k0, self.t0 = measurement.k, measurement.t
        self._carry = (np.zeros(3), np.zeros(3))  # (offset of p_v,d [m], its velocity [m/s]) at this sample
        self.singular = (SingularHandler(self.js, self.js_high, self.n_ramp, self._v_path, size=3, carry="path")
                         if self.carry != "hold" else None)

    def _measured_velocity(self, m: Measurement, q: np.ndarray) -> np.ndarray:
        nv = self.robot.model.nv
        if m.qd is not None:
            return np.asarray(m.qd, dtype=float).copy()
        out = np.zeros(nv)
        if m.k > self.k0:  # backward difference of the measured poses (qvel coordinates)
            mujoco.mj_differentiatePos(self.robot.model, out, self.T, self.q_prev, q)
        return out

    def compute(self, measurement: Measurement) -> Command:
        r, d, T = self.robot, self.d, self.T
        model = r.model
        q = np.asarray(measurement.q, dtype=float).copy()
        zeta = self._measured_velocity(measurement, q)
        self.q_prev = q.copy()
        h = r.hold_force(q)  # also sets the nominal state for the Jacobians below
        if not self.feedforward:
            h = np.zeros(model.nv)
        jac = r.jacobians()
        manip = None
        if self.singular is not None:  # the carry (module docstring "Reach"): v over [k, k+1)
            manip = manipulability(jac["tip_p"][:, self.joint_dofs])[0]
            v_c = self.singular.update(measurement.k, manip)
            self._carry = (self._carry[0], v_c)
        tasks, err = self.tasks(measurement.t, q, jac)
        if self.singular is not None:
            self._carry = (self._carry[0] + T * self._carry[1], self._carry[1])  # offset at k + 1
        sol = task_priority_velocity(tasks, self.priority_form, self.dls_threshold, self.dls_damping, self.rank_tol)
        zeta_r = sol["zeta"]

        # low level: PD on the integrated reference = PI on the velocity error (module docstring)
        lead = np.zeros(model.nv)
        mujoco.mj_differentiatePos(model, lead, 1.0, q, self.q_ref)  # q_r (-) q, qvel coordinates
        lim = self.reference_lead_limit
        if np.any(np.abs(lead) > lim):  # anti-windup: pull the reference back along
            lead = np.clip(lead, -lim, lim)
            qr = q.copy()
            mujoco.mj_integratePos(model, qr, lead, 1.0)
            self.q_ref = qr
        ja, jd = self.robot.layout.joint_qadr, self.joint_dofs
        if self.limits.active:  # ours: q_r of the arm joints inside the nominal ranges (minus the margin)
            qr_arm = self.limits.clamp_position(self.q_ref[ja])
            if np.any(qr_arm != self.q_ref[ja]):
                self.q_ref[ja] = qr_arm
                lead = np.zeros(model.nv)
                mujoco.mj_differentiatePos(model, lead, 1.0, q, self.q_ref)
                lead = np.clip(lead, -lim, lim)
            zeta_r = zeta_r.copy()
            zeta_r[jd] = self.limits.clamp_rate(self.q_ref[ja], zeta_r[jd])
        u = self.kp * lead + self.kd * (zeta_r - zeta) + h
        if self.joint_gains == "inertia" and self.kp_given is None and self.kd_given is None:
            jd, w = self.joint_dofs, self.bandwidth_joints
            M = np.zeros((model.nv, model.nv))
            mujoco.mj_fullM(model, r.data, M)  # nominal, at q (hold_force set the state)
            u[jd] = M[np.ix_(jd, jd)] @ (w * w * lead[jd] + 2.0 * self.zeta_ratio * w * (zeta_r - zeta)[jd]) + h[jd]
        # q_r(k+1) = q_r(k) (+) T zeta_r(k)
        mujoco.mj_integratePos(model, self.q_ref, zeta_r, T)

        R = jac["R_base"]
        wrench = np.concatenate((R.T @ u[d:d + 3], u[d + 3:d + 6]))  # body wrench [N, N m]
        if self.allocator is not None:
            res = self.allocator(wrench)
            thrust, saturated, achieved = res.thrust, res.saturated, res.wrench
        else:
            thrust, saturated, achieved = np.zeros(0), np.zeros(0, dtype=bool), np.zeros(6)
        tau = np.clip(u[r.motor_dofs], r.motor_lo, r.motor_hi)
        signals = {
            "base_desired": np.concatenate((err["base_desired"], self.quat_ref)),
            "tip_desired": err["tip_desired"],
            "tip_measured": jac["tip"].copy(),
            "zeta_ref": zeta_r.copy(),
            "e_tip": err["e_tip"], "e_attitude": err["e_attitude"],
            "e_position": err["e_position"], "e_posture": err["e_posture"],
            "reference_lead": lead,
            "dls_lambda2": np.asarray(sol["damping"], dtype=float),
            "wrench_body": wrench, "wrench_achieved": np.asarray(achieved, dtype=float),
            "thrust_saturated": np.asarray(saturated, dtype=bool),
        }
        if manip is not None:
            signals.update(manipulability=manip, singular_phase=self.singular.phase)
        return Command(thrust=np.asarray(thrust, dtype=float), torques=tau, signals=signals)
