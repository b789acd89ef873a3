"""One scenario schema for every robot (uvms_mj.scenario.document.Scenario): the same class, the
robot's own defaults, the tip trajectory in one form for every robot, the older spellings.

Independent truths: the geometry of the path the controller gets (its start is the initial tip
computed by MuJoCo's kinematics on the model file, its end that point plus the displacement),
the defaults the paper states (40 s, rac_dob, T = 1/60 s, 0.3 m along x), a resolved scenario
that validates back to the same scenario."""

from __future__ import annotations

import textwrap

import mujoco
import numpy as np
import pytest

from uvms_mj.plant.files import nominal_model_path
from uvms_mj.scenario.document import Scenario
from uvms_mj.scenario.schema import ScenarioError, build, load_scenario, resolved, validate_scenario


def _load(tmp_path, text: str):
    p = tmp_path / "s.yaml"
    p.write_text(textwrap.dedent(text))
    return load_scenario(p)


def _tip(robot: str) -> np.ndarray:
    """The initial tip position of a robot's model file (its initial keyframe), world [m]."""
    m = mujoco.MjModel.from_xml_path(str(nominal_model_path(robot)))
    d = mujoco.MjData(m)
    if m.nkey:
        mujoco.mj_resetDataKeyframe(m, d, 0)
    mujoco.mj_kinematics(m, d)
    sid = [i for i in range(m.nsite) if (mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_SITE, i) or "").endswith("tip")][0]
    return d.site_xpos[sid].copy()


def test_every_robot_is_one_class_with_its_own_defaults(tmp_path):
    paper = _load(tmp_path, "{}\n")
    rov = _load(tmp_path, "robot: bluerov2_alpha\n")
    assert type(paper) is type(rov) is Scenario
    # the paper's experiment (Section 4): 40 s, the observer, T = 1/60 s, 0.3 m along x
    assert (paper.duration, paper.controller.name) == (40.0, "rac_dob")
    assert resolved(paper)["control_period"] == pytest.approx(1 / 60, rel=1e-15)
    assert paper.trajectory.kind == "line" and paper.trajectory.displacement == [0.3, 0.0]
    # other robots: 20 s, the baseline at 50 Hz, hold the initial tip
    assert (rov.duration, rov.controller.name, rov.trajectory) == (20.0, "station_pid", None)
    assert resolved(rov)["control_period"] == 0.02
    # the model's step is what a resolved scenario shows (the paper's 1/120 s; the model file's)
    m = mujoco.MjModel.from_xml_path(str(nominal_model_path("bluerov2_alpha")))
    assert paper.physics.timestep == pytest.approx(1 / 120, rel=1e-15) and rov.physics.timestep == m.opt.timestep


@pytest.mark.parametrize("robot", ["paper", "bluerov2_alpha"])
def test_a_resolved_scenario_validates_back_to_itself(tmp_path, robot):
    sc = _load(tmp_path, f"robot: {robot}\ncurrent: {{velocity: [0.05, 0.0]}}\n" if robot == "paper" else
               f"robot: {robot}\ntrajectory: {{kind: line, displacement: [0.05, 0, 0]}}\ncontroller: {{name: rac}}\n")
    r = resolved(sc)
    again = validate_scenario(r, "resolved")
    assert resolved(again) == r


def test_a_line_without_start_runs_from_the_initial_tip_on_every_robot(tmp_path):
    """displacement: the path's end is the initial tip plus the displacement (3 numbers in 3-D,
    2 on the planar robot, whose plane is world x-y)."""
    sc = _load(tmp_path, "robot: bluerov2_alpha\ntrajectory: {displacement: [0.05, 0.0, -0.02], cruise_speed: 0.01}\n"
                         "controller: {name: rac}\nduration: 1\n")
    _, ctrl = build(sc)
    tip0 = _tip("bluerov2_alpha")
    tr = ctrl.trajectory
    np.testing.assert_allclose(tr.start, tip0, atol=1e-12)  # the same kinematics: round-off only
    np.testing.assert_allclose(tr.target, tip0 + [0.05, 0.0, -0.02], atol=1e-12)
    assert tr.cruise_speed == 0.01 and tr.accel == 0.02 and tr.t_start == 1.0  # Line3D's defaults

    paper = _load(tmp_path, "trajectory: {displacement: [0.1, -0.05]}\ncontroller: {name: rac}\n")
    _, ctrl = build(paper)
    tip0 = _tip("paper")
    np.testing.assert_allclose(ctrl.trajectory.start[:2], tip0[:2], atol=1e-12)
    np.testing.assert_allclose(ctrl.trajectory.target[:2], tip0[:2] + [0.1, -0.05], atol=1e-12)


def test_a_curve_is_written_the_same_way_on_every_robot(tmp_path):
    """The kind's keys in trajectory itself, translated to start at the initial tip; the older
    ``curve:`` spelling and ``trajectory_origin`` still load."""
    spec = "{kind: circle, centre: [0, 0, 0], radius: 0.02, normal: [0, 0, 1], period: 20}"
    for text in (f"trajectory: {spec}\n", f"trajectory: {{curve: {spec}}}\n"):
        sc = _load(tmp_path, text + "controller: {name: rac}\n")
        _, ctrl = build(sc)
        np.testing.assert_allclose(ctrl.trajectory.position(0.0)[:2], _tip("paper")[:2], atol=1e-12)
    sc = _load(tmp_path, f"robot: bluerov2_alpha\ntrajectory: {spec}\ntrajectory_origin: world\n"
                         "controller: {name: rac}\n")
    assert sc.trajectory.origin == "world"
    _, ctrl = build(sc)
    np.testing.assert_allclose(ctrl.trajectory.position(0.0), [0.02, 0.0, 0.0], atol=1e-12)  # as written


def test_trajectory_errors_are_one_line_each(tmp_path):
    with pytest.raises(ScenarioError, match=r"trajectory\.target: must be 3 numbers \(world x, y, z\) on robot "
                                            r"'bluerov2_alpha'"):
        _load(tmp_path, "robot: bluerov2_alpha\ntrajectory: {target: [0.1, 0.2]}\ncontroller: {name: rac}\n")
    with pytest.raises(ScenarioError, match=r"trajectory\.cruise_sped: unknown key 'cruise_sped' for kind 'line' "
                                            r"\(did you mean 'cruise_speed'\?\)"):
        _load(tmp_path, "trajectory: {cruise_sped: 0.1}\n")
    with pytest.raises(ScenarioError, match=r"trajectory\.kind: must be one of .* \(did you mean 'circle'\?\)"):
        _load(tmp_path, "trajectory: {kind: circel}\n")
    with pytest.raises(ScenarioError, match=r"trajectory\.displacement: applies to kind 'line' only"):
        _load(tmp_path, "trajectory: {kind: circle, displacement: [0.1, 0], centre: [0, 0, 0], radius: 0.1, "
                        "period: 10}\n")
    with pytest.raises(ScenarioError, match=r"trajectory\.curve: trajectory\.curve is the older spelling"):
        _load(tmp_path, "trajectory: {cruise_speed: 0.1, curve: {kind: circle, centre: [0, 0, 0], radius: 0.1, "
                        "period: 10}}\n")
    with pytest.raises(ScenarioError, match=r"trajectory: radius = -1 must be a finite number > 0"):
        _load(tmp_path, "trajectory: {kind: circle, centre: [0, 0, 0], radius: -1, period: 10}\n")


def test_null_trajectory_holds_the_tip_on_the_papers_robot_too(tmp_path):
    sc = _load(tmp_path, "trajectory: null\ncontroller: {name: rac}\n")
    assert sc.trajectory is None
    _, ctrl = build(sc)
    assert ctrl.trajectory is None


def test_the_control_period_of_the_paper_robot_is_a_field_too(tmp_path):
    sc = _load(tmp_path, "control_period: 0.025\ncontroller: {name: rac}\n")
    _, ctrl = build(sc)
    assert ctrl.T == 0.025
    with pytest.raises(ScenarioError, match=r"control_period: the controller period must be a whole multiple of "
                                            r"physics\.timestep"):
        _load(tmp_path, "control_period: 0.021\n")
