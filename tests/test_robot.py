"""Any floating robot: layout by name, named overrides, initial states, thrust in newtons, the
nominal model's hold force, station_pid, and robot scenarios.

Independent truths: hand computation from the model files' parameters (von Benzon et al. 2022
numbers of models/bluerov2_heavy/*.xml), rotation matrices built by hand, MuJoCo's own
quaternion functions, the thrust curve's forward evaluation, and the damping law at the steady
current speed.
"""

from __future__ import annotations

import math
from pathlib import Path

import mujoco
import numpy as np
import pytest
import yaml

import uvms_mj  # noqa: F401  (the plugins: registered once by conftest.py)
from uvms_mj.control import create
from uvms_mj.sim.experiment import metrics
from uvms_mj.sim.loop import SensorModel, run_closed_loop
from uvms_mj.control.nominal import JointTrajectory, NominalRobot
from uvms_mj.plant.params import ParameterError
from uvms_mj.physics import model as pm
from uvms_mj.plant.files import robot_path
from uvms_mj.plant.layout import InitialState, Layout
from uvms_mj.plant.plant import Plant
from uvms_mj.plant.robot import compile_robot_spec
from uvms_mj.rotations import quat_from_rpy, rpy_from_quat
from uvms_mj.scenario.schema import ScenarioError, load_scenario, run_scenario, validate_scenario
from uvms_mj.physics.thrusters import CurveInverse, allocation_matrix, invert_curve, thruster_curves

REPO = Path(__file__).resolve().parents[1]
G = 9.81
RHO = 1000.0
# [vB] von Benzon et al. 2022 (models/bluerov2_heavy/bluerov2_heavy.xml, bluerov2_heavy_hull.xml)
MASS, VOLUME, COB_Z = 13.5, 0.0134, 0.01
LIN_DAMP = (13.7, 0.0, 33.0)
QUAD_DAMP = (141.0, 217.0, 190.0)


def test_layout_by_name():
    m = compile_robot_spec(robot_path("bluerov2_alpha"))
    lay = Layout.of(m)
    assert lay.base_name == "bluerov2" and lay.base_qadr == 0 and lay.base_dadr == 0
    assert lay.joint_names == ("alpha_base", "alpha_shoulder", "alpha_elbow", "alpha_wrist")
    assert lay.thruster_names == tuple(f"bluerov2_t{i}" for i in range(1, 9))
    assert lay.motor_joints == lay.joint_names
    assert lay.tip_name == "alpha_tip"
    assert Layout.of(compile_robot_spec(robot_path("bluerov2_heavy"))).tip_site == -1


def test_robot_path_errors():
    with pytest.raises(ParameterError, match="did you mean 'bluerov2_alpha'"):
        robot_path("bluerov2_alpa")
    assert robot_path("hinsdale2023") == REPO / "models" / "hinsdale2023" / "hinsdale2023.xml"


def test_named_overrides_reach_the_model():
    m = compile_robot_spec(robot_path("bluerov2_alpha"), {
        "bluerov2.mass": 14.0, "bluerov2.volume": 0.014, "alpha_elbow.damping": 0.7,
        "bluerov2_t3.forcerange": [-20, 25], "water.density": 1025.0, "alpha_shoulder.range": [0.1, 3.0]})
    b = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "bluerov2")
    assert m.body_mass[b] == 14.0
    info = pm.hydro_of(m)
    assert info.bodies[b].volume == 0.014 and info.water.density == 1025.0
    j = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "alpha_elbow")
    assert m.dof_damping[m.jnt_dofadr[j]] == 0.7
    a = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, "bluerov2_t3")
    assert list(m.actuator_forcerange[a]) == [-20, 25]
    j = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "alpha_shoulder")
    assert list(m.jnt_range[j]) == [0.1, 3.0]


@pytest.mark.parametrize("over, msg", [
    ({"bluerov.mass": 1}, r"no body, joint or actuator named 'bluerov' \(did you mean 'bluerov2'\?\)"),
    ({"bluerov2.mas": 1}, "unknown field 'mas'.*did you mean 'mass'"),
    ({"bluerov2.mass": -1}, "must be > 0"),
    ({"alpha_elbow.damping": [1, 2]}, "expected 1 number"),
    ({"bluerov2_t1.forcerange": [5, -5]}, "min < max"),
    ({"nodot": 1}, "expected '<element name>.<field>'"),
])
def test_named_override_errors(over, msg):
    with pytest.raises(ParameterError, match=msg):
        compile_robot_spec(robot_path("bluerov2_alpha"), over)


def _rz(a):
    return np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])


def _ry(a):
    return np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])


def _rx(a):
    return np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])


@pytest.mark.parametrize("rpy", [(0.3, -0.2, 1.1), (-1.0, 0.7, -2.5), (0.0, 0.0, 3.0)])
def test_rpy_quaternion_matches_hand_built_rotation(rpy):
    q = quat_from_rpy(*rpy)
    R = np.zeros(9)
    mujoco.mju_quat2Mat(R, q)
    np.testing.assert_allclose(R.reshape(3, 3), _rz(rpy[2]) @ _ry(rpy[1]) @ _rx(rpy[0]), atol=1e-14)
    np.testing.assert_allclose(rpy_from_quat(q), rpy, atol=1e-12)


def test_initial_state_by_name():
    st = InitialState(position=(1, 2, -3), quat=(2, 0, 0, 0), joints={"alpha_shoulder": 1.2},
                      linear_velocity=(0.1, 0, 0), angular_velocity=(0, 0, 0.2), joint_velocities={"alpha_base": 0.3})
    p = Plant("bluerov2_alpha", initial=st)
    np.testing.assert_array_equal(p.base_pose, [1, 2, -3, 1, 0, 0, 0])
    assert p.joint_angles[1] == 1.2
    np.testing.assert_array_equal(p.qd[:6], [0.1, 0, 0, 0, 0, 0.2])
    assert p.qd[6] == 0.3
    with pytest.raises(ParameterError, match="did you mean 'alpha_shoulder'"):
        Plant("bluerov2_alpha", initial=InitialState(joints={"alpha_shouldr": 1.0}))
    with pytest.raises(ParameterError, match="outside the joint's range"):
        Plant("bluerov2_alpha", initial=InitialState(joints={"alpha_shoulder": -1.0}))
    with pytest.raises(ParameterError, match="no such keyframe"):
        Plant("bluerov2_alpha", initial=InitialState(keyframe="nope"))


def test_curve_inverse_matches_invert_curve():
    m = compile_robot_spec(robot_path("bluerov2_heavy"))
    (c, *_) = thruster_curves(m)
    inv = CurveInverse(c, -1.0, 1.0)
    F = np.linspace(-35, 35, 701)
    np.testing.assert_allclose(inv(F), invert_curve(c, F, -1.0, 1.0), atol=1e-12)
    inside = np.abs(F) < 30.0
    np.testing.assert_allclose(c(inv(F[inside])), F[inside], atol=1e-10)  # the forward curve gives F back
    # a command vector (one per thruster, every control sample: the inverse's float path) against invert_curve
    F8 = np.array([-29.0, -7.5, -0.3, 0.0, 0.2, 3.3, 12.0, 29.9])
    np.testing.assert_allclose(inv(F8), invert_curve(c, F8, -1.0, 1.0), atol=1e-12)


def test_curve_inverse_of_a_table_is_its_piecewise_linear_inverse():
    """A table curve inverts exactly by interpolation (closed form: u = u_j + (F - F_j) (u_{j+1} - u_j) /
    (F_{j+1} - F_j) on the segment holding F, the table's ends beyond it), for a few thrusts (the float
    path) and for many (numpy's); 1e-12: round-off of one interpolation."""
    inv = CurveInverse("table -1 -10 -0.1 -1 0.1 1 1 20")
    F = np.array([-12.0, -10.0, -5.5, -1.0, 0.0, 0.5, 1.0, 10.5, 20.0, 25.0])
    u_true = np.array([-1.0, -1.0, -0.55, -0.1, 0.0, 0.05, 0.1, 0.55, 1.0, 1.0])
    np.testing.assert_allclose(inv(F), u_true, atol=1e-12)
    np.testing.assert_allclose(inv(np.tile(F, 10)), np.tile(u_true, 10), atol=1e-12)


def test_thrust_in_newtons_gives_the_allocated_wrench():
    """After the lag settles, each thruster gives the commanded force (forward curve) and the
    vehicle gets the wrench B f (MuJoCo's qfrc_actuator, free-joint rows, against B)."""
    p = Plant("bluerov2_heavy", gravity=False, initial=InitialState(quat=tuple(quat_from_rpy(0.2, -0.1, 0.5))))
    f = np.array([3.0, -2.0, 5.0, 1.0, -4.0, 2.5, 0.5, -1.5])
    p.set_thrust(f)
    p.data.act[p._thr_act] = p.thrust_to_ctrl(f)  # settled lag
    mujoco.mj_forward(p.model, p.data)
    np.testing.assert_allclose(p.thruster_forces, f, atol=1e-10)
    B = allocation_matrix(p.model, p.data, frame="body")
    R = p.data.xmat[p.layout.base_body].reshape(3, 3)
    gen = p.data.qfrc_actuator[:6]
    np.testing.assert_allclose(np.r_[R.T @ gen[:3], gen[3:]], B @ f, atol=1e-10)


def test_hold_force_is_the_hand_computed_net_buoyancy():
    """At a tilted attitude: force (m - rho V) g down in the world, moment of buoyancy about the
    CG: r_cob x F_b in body axes (vehicle only: its CG is the body origin)."""
    rpy = (0.3, -0.2, 0.7)
    q = np.zeros(7)
    q[3:] = quat_from_rpy(*rpy)
    h = NominalRobot("bluerov2_heavy").hold_force(q)
    np.testing.assert_allclose(h[:3], [0, 0, (MASS - RHO * VOLUME) * G], atol=1e-10)
    R = _rz(rpy[2]) @ _ry(rpy[1]) @ _rx(rpy[0])
    Fb_body = R.T @ np.array([0, 0, RHO * VOLUME * G])
    moment = np.cross([0, 0, COB_Z], Fb_body)
    np.testing.assert_allclose(h[3:], -moment, atol=1e-10)


def _station(robot, current=None, duration=10.0, init=None, **params):
    p = Plant(robot, current=current, initial=init or InitialState(position=(0, 0, -1)))
    c = create("station_pid", robot=NominalRobot(robot), **params)
    return p, run_closed_loop(p, c, duration, T=c.T)


def test_station_pid_holds_still_water_exactly():
    """Vehicle alone in still water, starting at rest on station: the feed-forward cancels the
    net weight exactly, so nothing moves (errors at round-off)."""
    _, res = _station("bluerov2_heavy", duration=5.0)
    assert res.status == "ok"
    assert np.abs(res.signals["e_position"]).max() < 1e-9
    assert np.abs(res.signals["e_attitude"]).max() < 1e-9


@pytest.mark.slow
def test_station_pid_integral_takes_the_damping_at_the_current_speed():
    """In a steady current the integral action ends up supplying the drag of the damping law at
    the current speed, per axis in body = world axes: d_l v + d_q |v| v (von Benzon)."""
    vc = np.array([-0.15, 0.1, 0.05])
    _, res = _station("bluerov2_heavy", current=vc, duration=60.0)
    assert res.status == "ok"
    w = res.signals["wrench_achieved"][-1]
    # station held: the water passes at vc, the velocity relative to the water is -vc, so the drag
    # on the vehicle is -D(-vc) = d_l vc + d_q |vc| vc; the thrusters cancel it and hold the net weight.
    drag = np.array(LIN_DAMP) * vc + np.array(QUAD_DAMP) * np.abs(vc) * vc
    expected = -drag + np.array([0, 0, (MASS - RHO * VOLUME) * G])
    # 1 % of the largest drag: the integrators' residual after 60 s (12 integral times)
    np.testing.assert_allclose(w[:3], expected, rtol=0, atol=0.01 * np.abs(drag).max())
    assert np.linalg.norm(res.signals["e_position"][-1]) < 2e-3


def test_station_pid_with_arm_motion_tracks_joints():
    names = ("alpha_base", "alpha_shoulder", "alpha_elbow", "alpha_wrist")
    p = Plant("bluerov2_alpha", initial=InitialState(position=(0, 0, -1), joints={"alpha_shoulder": 1.5,
                                                                                         "alpha_elbow": 1.5}))
    arm = JointTrajectory.from_waypoints(names, p.joint_angles, [(2.0, {"alpha_base": 0.8}), (4.0, {"alpha_base": 0.0})])
    c = create("station_pid", robot=NominalRobot("bluerov2_alpha"), arm_trajectory=arm)
    res = run_closed_loop(p, c, 6.0, T=c.T)
    assert res.status == "ok"
    s = res.signals
    err = s["joints_desired"] - s["q_true"][:, p.layout.joint_qadr]
    assert np.abs(err).max() < math.radians(2.0)  # the PD at 6 rad/s bandwidth
    assert np.abs(s["joints_desired"][-1] - p.joint_angles).max() < math.radians(0.5)
    assert np.linalg.norm(s["e_position"], axis=1).max() < 0.01  # pushed off station by < 1 cm


def test_joint_trajectory_min_jerk_endpoints():
    jt = JointTrajectory.from_waypoints(("a", "b"), [0.0, 1.0], [(2.0, {"a": 1.0}), (3.0, {"b": 0.0})])
    q, qd = jt(0.0)
    np.testing.assert_allclose(q, [0, 1]) and np.testing.assert_allclose(qd, 0)
    q, qd = jt(1.0)  # half way through the first segment: s = 1/2, ds/dtau = 15/8
    np.testing.assert_allclose(q, [0.5, 1.0], atol=1e-15)
    np.testing.assert_allclose(qd, [15 / 8 / 2, 0.0], atol=1e-15)
    np.testing.assert_allclose(jt(5.0)[0], [1.0, 0.0])
    with pytest.raises(ParameterError, match="strictly"):
        JointTrajectory.from_waypoints(("a",), [0.0], [(2.0, {}), (1.0, {})])
    with pytest.raises(ParameterError, match="not an arm joint"):
        JointTrajectory.from_waypoints(("a",), [0.0], [(2.0, {"c": 1})])


def test_robot_measurement_noise_is_seeded():
    sensor = SensorModel(position_noise=1e-3, attitude_noise=1e-3, joint_noise=1e-3)
    runs = []
    for _ in range(2):
        p = Plant("bluerov2_alpha", initial=InitialState(position=(0, 0, -1), joints={"alpha_shoulder": 1.5}))
        c = create("station_pid", robot=NominalRobot("bluerov2_alpha"))
        runs.append(run_closed_loop(p, c, 1.0, T=c.T, sensor=sensor, seed=3))
    np.testing.assert_array_equal(runs[0].signals["q_measured"], runs[1].signals["q_measured"])
    d = runs[0].signals["q_measured"][:, :3] - runs[0].signals["q_true"][:, :3]
    assert 0.5e-3 < d.std() < 2e-3
    qm = runs[0].signals["q_measured"][:, 3:7]
    np.testing.assert_allclose(np.linalg.norm(qm, axis=1), 1.0, atol=1e-12)


# ------------------------------------------------------------------ scenarios

SHIPPED = ("bluerov2_heavy_current", "bluerov2_alpha_station", "hinsdale2023_station")


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_robot_scenarios_validate(name):
    sc = load_scenario(REPO / "scenarios" / f"{name}.yaml")
    assert sc.robot != "paper" and sc.controller.name == "station_pid"


def test_robot_scenario_runs_deterministically():
    sc = load_scenario(REPO / "scenarios" / "bluerov2_alpha_station.yaml", ["duration=2.0"])
    a, b = run_scenario(sc), run_scenario(sc)
    assert a.status == "ok" and a.meta["robot"]["name"] == "bluerov2_alpha"
    for k in a.signals:
        np.testing.assert_array_equal(a.signals[k], b.signals[k])
    m = metrics(a)
    assert math.isfinite(m["base_pos_rms_mm"]) and math.isfinite(m["joint_rms_mrad"])
    assert math.isnan(m["tip_rms_mm"])  # no tip_desired from station_pid


@pytest.mark.parametrize("patch, msg", [
    ({"robot": "bluerov2_alpa"}, "robot: .*did you mean 'bluerov2_alpha'"),
    ({"initial": {"joints": {"alpha_shouldr": 10}}}, "did you mean 'alpha_shoulder'"),
    ({"initial": {"positon": [0, 0, 0]}}, "initial.positon: unknown key.*did you mean 'position'"),
    ({"initial": {"orientation": {"quat": [1, 0, 0, 0], "rpy": [0, 0, 0]}}}, "either quat or rpy"),
    ({"plant": {"overrides": {"bluerov2.mas": 3}}}, r"plant.overrides.bluerov2.mas: unknown field 'mas'"),
    ({"controller": {"name": "rac_planar"}}, "works on the paper robot only"),
    ({"controller": {"name": "station_pid", "params": {"kp": 1}}}, "'kp' is not a parameter"),
    ({"controller": {"name": "station_pid", "params": {"bandwidth_base": -1}}}, "bandwidth_base = -1"),
    ({"controller": {"name": "station_pid", "params": {"T": 0.015}}}, "whole multiple"),
    ({"arm": {"waypoints": [{"t": 3, "joints": {"alpha_bse": 1}}]}}, "did you mean 'alpha_base'"),
])
def test_robot_scenario_errors_name_the_field(patch, msg):
    raw = yaml.safe_load((REPO / "scenarios" / "bluerov2_alpha_station.yaml").read_text())
    raw.update(patch)
    with pytest.raises(ScenarioError, match=msg):
        validate_scenario(raw, "s.yaml")


def test_paper_scenarios_unchanged_by_robot_field():
    assert validate_scenario({}).robot == "paper"
    assert type(validate_scenario({"robot": "paper"})).__name__ == "Scenario"


def test_any_mjcf_robot_without_thrusters_or_motors_runs(tmp_path):
    """A robot file given by path (the 3-D test robot: no thrusters, no motors) runs from a
    scenario: the vehicle floats unactuated; rac asks for a tip site by name."""
    f = tmp_path / "r.yaml"
    f.write_text(f"robot: {REPO / 'tests' / 'models' / 'robot3d.xml'}\nduration: 0.5\n")
    res = run_scenario(load_scenario(f))
    assert res.status == "ok" and res.signals["thrust_force"].shape == (26, 0)
    with pytest.raises(ScenarioError, match="end-effector site"):
        load_scenario(f, ["controller.name=rac"])
