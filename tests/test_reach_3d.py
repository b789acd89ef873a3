"""Reach beyond the arm in 3-D: scenarios/bluerov2_alpha_beyond_reach.yaml (issue 19, item 2).

The BlueROV2 Heavy + Alpha arm starts in the middle of its workspace (shoulder 40 deg, elbow
90 deg: w = 0.995 w_max) and its tip follows the paper's straight line (0.02 m/s, 0.02 m/s^2)
0.2 m outwards, to a target 0.142 m beyond the arm's reach from the initial vehicle pose.

Independent truths: the arm's geometry from the plant model (the reach = the largest
shoulder-axis-to-tip distance over the elbow's range, found by a dense scan; the target's
distance from the shoulder), the joint ranges of the plant model (``jnt_range``) against the true
joint angles (``q_true``), the closed form of Eq. 12's carry ramps (SingularHandler), and the
eigenvalues of the nominal joint-block inertia (why task_priority's joint loop is scaled by it).
"""

from __future__ import annotations

import math
from pathlib import Path

import mujoco
import numpy as np
import pytest

from uvms_mj.control.base import ControllerError
from uvms_mj.control.digital import SingularHandler
from uvms_mj.control.nominal import NominalRobot
from uvms_mj.scenario.schema import build, load_scenario, run_scenario

STUDY = Path(__file__).resolve().parents[1] / "scenarios" / "bluerov2_alpha_beyond_reach.yaml"
#: The study's line ends at t = 12 s (1 s rest, 1 s ramps, 9 s cruise over 0.2 m); 15 s leaves
#: 3 s to settle (the RACs' errors are ~0.1 mm at the end of the line already).
DURATION = 15.0
#: The issue's bar: "final tip error below 1 mm".
TIP_FINAL_MAX = 1e-3
#: The issue's bar: "no joint past its limit by more than 1 deg".
JOINT_SLACK = math.radians(1.0)


def _geometry(robot: NominalRobot, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(shoulder axis anchor, tip position), world, at the full configuration q."""
    m, d = robot.model, mujoco.MjData(robot.model)
    d.qpos[:] = q
    mujoco.mj_kinematics(m, d)
    return d.xanchor[m.joint("alpha_shoulder").id].copy(), d.site_xpos[robot.layout.tip_site].copy()


def _reach(robot: NominalRobot) -> float:
    """The arm's reach: the largest shoulder-anchor-to-tip distance over the elbow's range
    (1/10 deg scan; the distance does not depend on the shoulder, base yaw or wrist roll)."""
    m = robot.model
    q = m.qpos0.copy()
    adr = m.jnt_qposadr[m.joint("alpha_elbow").id]
    best = 0.0
    for e in np.linspace(*m.jnt_range[m.joint("alpha_elbow").id], 2001):
        q[adr] = e
        s, tip = _geometry(robot, q)
        best = max(best, float(np.linalg.norm(tip - s)))
    return best


def _excursion(plant, q_true: np.ndarray) -> float:
    """Largest excursion [rad] of a limited hinge past its range (plant model), over the run."""
    m = plant.model
    worst = -math.inf
    for j in range(m.njnt):
        if m.jnt_limited[j] and m.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE:
            a = m.jnt_qposadr[j]
            lo, hi = m.jnt_range[j]
            worst = max(worst, float(np.max(np.maximum(lo - q_true[:, a], q_true[:, a] - hi))))
    return worst


def _run(name: str, sets=()):
    sc = load_scenario(STUDY, [f"controller.name={name}", f"duration={DURATION}", *sets])
    plant, ctrl = build(sc)
    return plant, ctrl, run_scenario(sc, built=(plant, ctrl))


def test_the_target_lies_beyond_the_reach_and_the_start_is_mid_workspace():
    """The study's premise from the geometry alone: the line's target is more than 0.1 m
    beyond the reach of the arm from the initial vehicle pose, the start is well inside it."""
    sc = load_scenario(STUDY, [f"duration={DURATION}"])
    plant, ctrl = build(sc)
    robot = ctrl.robot
    q0 = plant.q.copy()
    s, tip0 = _geometry(robot, q0)
    reach = _reach(robot)
    assert reach == pytest.approx(0.341, abs=1e-3)  # 0.15 m upper arm + the forearm to the jaw tip
    target = np.asarray(ctrl.trajectory.position(1e3), dtype=float)
    assert np.linalg.norm(target - s) - reach > 0.1
    assert np.linalg.norm(tip0 - s) / reach == pytest.approx(0.83, abs=0.01)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["rac", "rac_dob", "task_priority"])
def test_the_vehicle_carries_the_arm_and_the_tip_arrives(name):
    """rac, rac_dob and task_priority (its default carry "hold": the tip task moves the vehicle):
    no divergence, the tip within 1 mm of the target at the end, no joint past its range by more
    than 1 deg (plant model's jnt_range, true angles), the vehicle moved at least the distance
    the target lies beyond the reach."""
    plant, ctrl, res = _run(name)
    assert res.status == "ok", res.reason
    target = np.asarray(ctrl.trajectory.position(1e3), dtype=float)
    tip = res.signals["tip_true"]
    assert np.linalg.norm(tip[-1] - target) < TIP_FINAL_MAX
    assert _excursion(plant, res.signals["q_true"]) < JOINT_SLACK
    q = res.signals["q_true"]
    s, _ = _geometry(ctrl.robot, q[0])
    beyond = np.linalg.norm(target - s) - _reach(ctrl.robot)
    # the tip is within the reach of the (moved) shoulder: the vehicle moved at least `beyond`,
    # less 2 mm for the final tip error and the vehicle's attitude error (mrad) on the 0.3 m arm
    assert np.linalg.norm(q[-1, :3] - q[0, :3]) > beyond - 2e-3


@pytest.mark.slow
def test_station_pid_stretches_the_arm_and_holds():
    """station_pid (its arm IK relative to a fixed station): no divergence, no joint past its
    range, the vehicle within 1 mm of its station, and the tip short of the target by the
    distance the target lies beyond the reach (the arm stretched towards it; 2 mm: the IK's
    damping and the vehicle's attitude error on the 0.3 m arm)."""
    plant, ctrl, res = _run("station_pid")
    assert res.status == "ok", res.reason
    q = res.signals["q_true"]
    assert _excursion(plant, q) < JOINT_SLACK
    assert np.linalg.norm(q[-1, :3] - q[0, :3]) < 1e-3
    target = np.asarray(ctrl.trajectory.position(1e3), dtype=float)
    s, _ = _geometry(ctrl.robot, q[0])
    beyond = np.linalg.norm(target - s) - _reach(ctrl.robot)
    assert np.linalg.norm(res.signals["tip_true"][-1] - target) == pytest.approx(beyond, abs=2e-3)


@pytest.mark.slow
def test_the_singular_phase_engages_only_near_the_stretch():
    """rac: phase 0 while the tip is below 90 % of the reach from the (moving) shoulder axis,
    phase 1 reached (the carry happens), and every phase-1 sample with the arm at >= 90 % of
    its reach (geometry of the true configuration)."""
    plant, ctrl, res = _run("rac")
    assert res.status == "ok", res.reason
    robot, reach = ctrl.robot, _reach(ctrl.robot)
    phase = res.signals["singular_phase"]
    q = res.signals["q_true"]
    ratio = np.array([np.linalg.norm(np.subtract(*_geometry(robot, qk)[::-1])) for qk in q]) / reach
    assert np.any(phase == 1)
    assert np.all(phase[ratio < 0.9] == 0)
    assert np.all(ratio[phase == 1] >= 0.9)
    assert phase[0] == 0 and ratio[0] < 0.85


@pytest.mark.slow
def test_from_the_shipped_near_singular_posture_the_path_carry_arrives():
    """The shipped Alpha posture (shoulder 110, elbow 70 deg: w = 0.125 w_max < js, the singular
    phase on from the first sample): the paper's "cruise" carry keeps the cruise velocity until
    a release that never comes: at 35 s (the line ended at 17 s) the tip misses the 0.3 m
    line's end by > 0.1 m (measured 0.39 m) with the vehicle still cruising and the arm folded
    against its joint ranges, and the run may diverge after that (measured: at 37.04 s, when the
    folded arm flips round its base joint); "path" (the default on a floating robot) moves the
    base with the path, the tip arrives and the run ends "ok"."""
    sets = ["initial.joints={alpha_shoulder: 110, alpha_elbow: 70}",
            "trajectory={kind: line, displacement: [0.3, 0, 0]}", "duration=40"]
    out = {}
    for carry in ("cruise", "path"):
        plant, ctrl, res = _run("rac", [*sets, f"controller.params.carry={carry}"])
        target = np.asarray(ctrl.trajectory.position(1e3), dtype=float)
        k = int(np.searchsorted(res.t, 35.0))
        assert k < len(res.t), res.reason
        out[carry] = float(np.linalg.norm(res.signals["tip_true"][k] - target))
        assert _excursion(plant, res.signals["q_true"][: k + 1]) < JOINT_SLACK
        if carry == "path":
            assert res.status == "ok", res.reason
            assert float(np.linalg.norm(res.signals["tip_true"][-1] - target)) < TIP_FINAL_MAX
    assert out["path"] < TIP_FINAL_MAX and out["cruise"] > 0.1


def test_path_carry_ramps_to_the_path_velocity_and_stops_with_it():
    """SingularHandler carry "path" against its closed form: from k1 = 0, v(k) = min(1, (k+1)/n)
    v_path(k) while the path moves; v = 0 from n samples after the path stops (a ramp from the
    last v to 0 of the target); "cruise" holds the velocity of k1 instead."""
    n, c, k_stop = 5, np.array([0.02, 0.0, 0.01]), 12

    def v_path(k):
        return c if k < k_stop else np.zeros(3)

    path = SingularHandler(1.0, 1.0, n, v_path, size=3, carry="path")
    cruise = SingularHandler(1.0, 1.0, n, v_path, size=3)
    for k in range(30):
        vp, vc = path.update(k, 0.5), cruise.update(k, 0.5)  # w = 0.5 < js = 1: phase 1 throughout
        if k < k_stop:
            np.testing.assert_allclose(vp, min(1.0, (k + 1) / n) * c, rtol=1e-15, atol=1e-18)
        elif k >= k_stop + n - 1:
            assert not np.any(vp)
        np.testing.assert_allclose(vc, min(1.0, (k + 1) / n) * c, rtol=1e-15, atol=1e-18)
    assert path.phase == 1 and cruise.phase == 1


def test_carry_bad_input_names_the_field():
    with pytest.raises(ControllerError, match="carry = 'sideways'"):
        SingularHandler(1.0, 1.0, 5, lambda k: np.zeros(3), size=3, carry="sideways")
    with pytest.raises(ControllerError, match="carry = 'path' needs"):
        SingularHandler(1.0, 1.0, 5, np.zeros(3), size=3, carry="path")
    from uvms_mj.control import create

    robot = NominalRobot("bluerov2_alpha")
    with pytest.raises(ControllerError, match="carry = 'x'"):
        create("rac", robot=robot, carry="x")
    with pytest.raises(ControllerError, match="carry = 'x'"):
        create("task_priority", robot=robot, carry="x")
    with pytest.raises(ControllerError, match="joint_gains = 'x'"):
        create("task_priority", robot=robot, joint_gains="x")


def test_diagonal_joint_gains_stiffen_the_stretched_arm():
    """Why task_priority's joint rows go through M_jj(q) (joint_gains "inertia"): with diagonal
    gains Kp = diag(M_jj) w^2 the fastest joint-space mode has bandwidth w sqrt(lambda_max),
    lambda = eig(M_jj^-1 diag(M_jj)); on the nominal Alpha arm lambda_max more than doubles from
    the study's start (40, 90 deg) to the stretched arm (80, 160 deg), and the 10 rad/s loop then
    sits at w T sqrt(lambda) > 0.5 rad per sample at T = 0.02 s."""
    robot = NominalRobot("bluerov2_alpha")
    m, lay = robot.model, robot.layout
    jd, jq = np.asarray(lay.joint_dadr), np.asarray(lay.joint_qadr)
    lam = []
    for s_deg, e_deg in ((40.0, 90.0), (80.0, 160.0)):
        q = m.qpos0.copy()
        q[jq[1]], q[jq[2]] = math.radians(s_deg), math.radians(e_deg)
        Mj = robot.mass_matrix(q)[np.ix_(jd, jd)]
        lam.append(float(np.max(np.linalg.eigvals(np.linalg.solve(Mj, np.diag(np.diag(Mj)))).real)))
    assert lam[1] > 2.0 * lam[0]
    assert 10.0 * 0.02 * math.sqrt(lam[1]) > 0.5
