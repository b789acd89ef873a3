"""Eq. 12's threshold (and the damped least squares') scaled to the arm:
src/uvms_mj/control/manipulability.py, used by rac / rac_dob.

Independent truths: the paper arm's closed form det B = l1 l2 sin(phi2)
(tests/oracles/planar/kinematics.py), whose largest value over its unlimited joints is l1 l2 at
phi2 = +-pi/2; central finite differences of the tip position for the Alpha arm's B; random
samples of the Alpha's joint box (none may beat the search); the geometry of a stretched arm
(the elbow angle that puts the tip farthest from the shoulder axis).
"""

from __future__ import annotations

import math
from pathlib import Path

import mujoco
import numpy as np
import pytest

from oracles.planar.kinematics import ArmGeometry, det_b
from uvms_mj.control import create
from uvms_mj.control.base import ControllerError
from uvms_mj.control.digital import PAPER_JS
from uvms_mj.control.manipulability import (DLS_RATIO, PAPER_DLS_THRESHOLD, PAPER_JS_RATIO, manipulability,
                                            max_manipulability)
from uvms_mj.control.nominal import NominalRobot
from uvms_mj.control.rac import paper_nominal_robot
from uvms_mj.plant.params import compile_robot, read_params
from uvms_mj.scenario.schema import load_scenario, run_scenario

SCEN = Path(__file__).resolve().parents[1] / "scenarios"
#: The search finds a flat maximum to round-off (w error ~ (joint error)^2, joint tolerance
#: 1e-8 rad); 1e-12 relative leaves four orders of margin above the measured 7e-16.
REL = 1e-12


@pytest.fixture(scope="module")
def alpha():
    robot = NominalRobot("bluerov2_alpha")
    ctrl = create("rac", robot=robot)
    found = max_manipulability(robot.model, robot.layout.tip_site, ctrl.arm_dofs, [0, 1, 2])
    return robot, ctrl, found


_DATA: dict = {}


def _w(robot, arm_dofs, q_arm) -> float:
    """The arm's manipulability at q_arm (other coordinates at qpos0), mj_jacSite."""
    m = robot.model
    d = _DATA.get(robot)
    if d is None:
        d = _DATA[robot] = mujoco.MjData(m)
    d.qpos[:] = m.qpos0
    d.qpos[[m.jnt_qposadr[m.dof_jntid[a]] for a in arm_dofs]] = q_arm
    mujoco.mj_kinematics(m, d)
    mujoco.mj_comPos(m, d)
    jp = np.zeros((3, m.nv))
    mujoco.mj_jacSite(m, d, jp, None, robot.layout.tip_site)
    return manipulability(jp[:, arm_dofs])[0]


def test_paper_arm_max_is_l1_l2_and_gives_the_papers_thresholds():
    """max |det B| = l1 l2 (closed form, Table 1's 0.25 m links: 0.0625 m^2) at |sin phi2| = 1;
    the resolved thresholds are the paper's Js = 0.045 and our 0.01."""
    robot = paper_nominal_robot()
    geom = ArmGeometry.from_params(read_params(compile_robot()))
    ctrl = create("rac", robot=robot)
    found = max_manipulability(robot.model, robot.layout.tip_site, ctrl.arm_dofs, ctrl.tip_rows)
    assert found.value == pytest.approx(geom.l1 * geom.l2, rel=REL)
    assert geom.l1 * geom.l2 == pytest.approx(0.0625, rel=1e-15)
    assert abs(math.sin(found.q_arm[1])) == pytest.approx(1.0, abs=REL)
    assert abs(det_b(geom, [0.0, 0.0, 0.0, *found.q_arm])) == pytest.approx(found.value, rel=REL)
    assert PAPER_JS_RATIO == pytest.approx(0.72, rel=1e-15) and DLS_RATIO == pytest.approx(0.16, rel=1e-15)
    assert ctrl.js == pytest.approx(PAPER_JS, rel=REL) and ctrl.js_high == ctrl.js
    assert ctrl.dls_threshold == pytest.approx(PAPER_DLS_THRESHOLD, rel=REL)
    rec = ctrl.resolved_params
    assert rec["auto"] == ["js", "dls_threshold"] and rec["max_manipulability"] == found.value
    explicit = create("rac", robot=robot, js=0.05, dls_threshold=0.02)  # a number stays as given
    assert (explicit.js, explicit.dls_threshold) == (0.05, 0.02) and "auto" not in explicit.resolved_params


def test_paper_run_with_auto_is_the_run_with_the_papers_numbers():
    """10 s of the paper's experiment (Eq. 12 engages at about 2 s): thresholds "auto" and the
    paper's numbers give the same run (states to 1e-12, the phase sample for sample) and the
    run records the resolved Js (what the plots read)."""
    base = ["duration=10", "controller.name=rac_dob"]
    auto = run_scenario(load_scenario(SCEN / "paper.yaml", base + ["controller.params.js=auto"]))
    given = run_scenario(load_scenario(SCEN / "paper.yaml", base + ["controller.params.dls_threshold=0.01"]))
    assert auto.status == given.status == "ok"
    assert np.any(auto.signals["singular_phase"] == 1)  # the threshold decides something in this window
    np.testing.assert_array_equal(auto.signals["singular_phase"], given.signals["singular_phase"])
    np.testing.assert_allclose(auto.signals["q_true"], given.signals["q_true"], rtol=0, atol=1e-12)
    assert auto.meta["controller_params"]["js"] == pytest.approx(PAPER_JS, rel=REL)
    assert given.meta["controller_params"]["dls_threshold"] == 0.01


def test_alpha_max_against_finite_differences_and_samples(alpha):
    """The Alpha arm (3 tip rows, 4 joints): w at the found maximum from central differences of
    the tip position (h = 1e-6 rad: truncation ~1e-12, round-off ~1e-10 relative; 1e-7 allowed);
    no configuration of 3000 uniform samples of the joint box beats it; the paper's absolute
    0.045 lies above every value the arm reaches (the measured bug: phase 1 at every sample)."""
    robot, ctrl, found = alpha
    m, d = robot.model, mujoco.MjData(robot.model)
    qadr = [m.jnt_qposadr[m.dof_jntid[a]] for a in ctrl.arm_dofs]

    def tip(q_arm):
        d.qpos[:] = m.qpos0
        d.qpos[qadr] = q_arm
        mujoco.mj_kinematics(m, d)
        return d.site_xpos[robot.layout.tip_site].copy()

    h = 1e-6
    B = np.column_stack([(tip(found.q_arm + h * e) - tip(found.q_arm - h * e)) / (2 * h) for e in np.eye(4)])
    assert manipulability(B)[0] == pytest.approx(found.value, rel=1e-7)
    lo, hi = np.array(found.ranges).T
    rng = np.random.default_rng(0)
    samples = [_w(robot, ctrl.arm_dofs, lo + rng.random(4) * (hi - lo)) for _ in range(3000)]
    assert max(samples) <= found.value * (1 + REL)
    assert found.value < PAPER_JS
    assert ctrl.js == pytest.approx(PAPER_JS_RATIO * found.value, rel=1e-15)
    assert ctrl.dls_threshold == pytest.approx(DLS_RATIO * found.value, rel=1e-15)


def test_alpha_phase_off_mid_workspace_on_when_stretched(alpha):
    """Around the Alpha's best posture (shoulder and elbow within 15 deg of it, any base yaw and
    wrist roll) w stays above js: Eq. 12 stays off; with the elbow at its straight angle (the
    tip farthest from the shoulder axis, found from positions alone) w is below js: it engages.
    Closed loop (the shipped circle in a current, 10 s, from the best posture): phase 0 at
    every sample with "auto", phase 1 at every sample with the paper's absolute numbers."""
    robot, ctrl, found = alpha
    _, s0, e0, _ = found.q_arm
    g = math.radians(15.0)
    mid = [_w(robot, ctrl.arm_dofs, [yaw, s0 + a, e0 + b, wr]) for yaw in (-2.0, 0.0, 2.0) for wr in (-2.0, 2.0)
           for a in np.linspace(-g, g, 5) for b in np.linspace(-g, g, 5)]
    assert min(mid) > ctrl.js_high
    m, d = robot.model, mujoco.MjData(robot.model)
    qadr = [m.jnt_qposadr[m.dof_jntid[a]] for a in ctrl.arm_dofs]
    shoulder = m.dof_jntid[ctrl.arm_dofs[1]]

    def reach(e):
        d.qpos[:] = m.qpos0
        d.qpos[qadr] = [0.0, s0, e, 0.0]
        mujoco.mj_kinematics(m, d)
        return np.linalg.norm(d.site_xpos[robot.layout.tip_site] - d.xanchor[shoulder])

    elbows = np.linspace(*found.ranges[2], 701)
    straight = elbows[int(np.argmax([reach(e) for e in elbows]))]
    assert _w(robot, ctrl.arm_dofs, [0.0, s0, straight, 0.0]) < 0.01 * ctrl.js
    assert _w(robot, ctrl.arm_dofs, [0.0, s0, straight - math.radians(20.0), 0.0]) < ctrl.js
    posture = f"initial.joints={{alpha_shoulder: {math.degrees(s0):.4f}, alpha_elbow: {math.degrees(e0):.4f}}}"
    phases = {}
    absolute = ["controllers.rac.js=0.045", "controllers.rac.dls_threshold=0.01"]  # the study pins controllers.rac
    for key, sets in (("auto", []), ("absolute", absolute)):
        sets = ["duration=10", "controller.name=rac", posture] + sets
        sc = load_scenario(SCEN / "bluerov2_alpha_circle_current.yaml", sets)
        res = run_scenario(sc)
        assert res.status == "ok"
        phases[key] = res.signals["singular_phase"]
    assert np.all(phases["auto"] == 0) and np.all(phases["absolute"] == 1)


def test_shipped_alpha_posture_is_near_the_shoulder_singularity(alpha):
    """Why the shipped Alpha scenarios stay in phase 1 with the scaled threshold too: their
    initial posture (shoulder 110 deg, elbow 70 deg) holds the tip 3.5 cm from the base yaw
    axis at 29 cm reach, so the yaw column of B nearly vanishes and w = 0.125 w_max < js."""
    robot, ctrl, found = alpha
    q = [0.0, math.radians(110.0), math.radians(70.0), 0.0]
    m, d = robot.model, mujoco.MjData(robot.model)
    d.qpos[[m.jnt_qposadr[m.dof_jntid[a]] for a in ctrl.arm_dofs]] = q
    mujoco.mj_kinematics(m, d)
    yaw = m.dof_jntid[ctrl.arm_dofs[0]]
    v = d.site_xpos[robot.layout.tip_site] - d.xanchor[yaw]
    off_axis = np.linalg.norm(v - d.xaxis[yaw] * (v @ d.xaxis[yaw]))
    assert off_axis / np.linalg.norm(v) < 0.15
    assert _w(robot, ctrl.arm_dofs, q) == pytest.approx(0.125 * found.value, rel=0.01)
    assert _w(robot, ctrl.arm_dofs, q) < ctrl.js


def test_more_rows_than_arm_joints_and_bad_values():
    """6 tip rows on the Alpha's 4 joints: w is identically 0, "auto" keeps the paper's numbers
    (the run is the same for any positive threshold); bad values name the parameter."""
    robot = NominalRobot("bluerov2_alpha")
    c = create("rac", robot=robot, tip_orientation=True)
    assert c.resolved_params["max_manipulability"] == 0.0
    assert (c.js, c.dls_threshold) == (pytest.approx(PAPER_JS, rel=1e-15), pytest.approx(0.01, rel=1e-15))
    for kw, name in (({"js": "abc"}, "js"), ({"js": True}, "js"), ({"dls_threshold": -1.0}, "dls_threshold"),
                     ({"js_ratio": 0.0}, "js_ratio"), ({"dls_ratio": 1.5}, "dls_ratio"),
                     ({"js_high": 0.001}, "js_high"), ({"js_high": "auto", "js_high_ratio": 0.5}, "js_high")):
        with pytest.raises(ControllerError, match=name):
            create("rac", robot=robot, **kw)
    hi = create("rac", robot=robot, js_high="auto", js_high_ratio=0.8)
    assert hi.js_high == pytest.approx(0.8 * hi.resolved_params["max_manipulability"], rel=1e-15)
    assert hi.js_high > hi.js
