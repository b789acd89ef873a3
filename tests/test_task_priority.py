"""``task_priority`` (uvms_mj.control.task_priority): the priority property of the reference
velocity against an independent constrained least-squares solution, the exact null-space
projectors, an exact hold in still water with plant = nominal, bounded tracking of a small
circle on bluerov2_alpha, parameter errors."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.linalg import null_space

from uvms_mj.control import ControllerError, Measurement, available, create
from uvms_mj.control.task_priority import null_space_projector, task_priority_velocity
from uvms_mj.sim.loop import SensorModel, run_closed_loop
from uvms_mj.control.nominal import NominalRobot
from uvms_mj.plant.layout import InitialState
from uvms_mj.plant.plant import Plant
from uvms_mj.control.trajectories import Shifted as _Shifted
from uvms_mj.control.trajectories import Circle

ROBOT = "bluerov2_alpha"
T = 0.02
#: a well-conditioned arm pose (the arm Jacobian's singular values 0.29, 0.11, 0.098 m/rad)
INIT = InitialState(position=(0.0, 0.0, -1.0), joints={"alpha_shoulder": 1.6, "alpha_elbow": 1.2})


@pytest.fixture(scope="module")
def nominal() -> NominalRobot:
    return NominalRobot(ROBOT)


def _random_state(nom: NominalRobot, rng: np.random.Generator) -> np.ndarray:
    """A random configuration: any position and orientation, joint angles inside their ranges."""
    m, lay = nom.model, nom.layout
    q = m.qpos0.copy()
    a = lay.base_qadr
    q[a:a + 3] = rng.uniform(-2, 2, 3)
    quat = rng.normal(size=4)
    q[a + 3:a + 7] = quat / np.linalg.norm(quat)
    for name, adr in zip(lay.joint_names, lay.joint_qadr):
        lo, hi = m.jnt_range[m.jnt_qposadr.tolist().index(adr)]
        q[adr] = rng.uniform(lo + 0.1 * (hi - lo), hi - 0.1 * (hi - lo))
    return q


def _task_jacobians(nom: NominalRobot, q: np.ndarray):
    nom.hold_force(q)
    jac = nom.jacobians()
    return jac, jac["tip_p"], jac["base_r"]


def _constrained_lsq(J1, v1, J2, v2):
    """Independent truth: argmin ||J2 z - v2|| subject to J1 z = v1 (null-space basis of scipy)."""
    z1 = np.linalg.lstsq(J1, v1, rcond=None)[0]
    Z = null_space(J1)
    y = np.linalg.lstsq(J2 @ Z, v2 - J2 @ z1, rcond=None)[0]
    return z1 + Z @ y


def test_registered():
    assert "task_priority" in available()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_priority_property_at_a_random_configuration(nominal, seed):
    """Task 1 (tip) exactly; task 2 (attitude) as well as the constrained least squares does and
    its correction invisible to task 1; task 3 likewise below tasks 1 and 2."""
    rng = np.random.default_rng(seed)
    q = _random_state(nominal, rng)
    jac, J1, J2 = _task_jacobians(nominal, q)
    nv = nominal.model.nv
    J3 = np.vstack((jac["base_p"], np.eye(nv)[nominal.layout.joint_dadr]))
    v1, v2, v3 = rng.normal(size=3), rng.normal(size=3), rng.normal(size=J3.shape[0])
    sol = task_priority_velocity([(J1, v1), (J2, v2), (J3, v3)])
    z = sol["zeta"]
    z1, z2, z3 = sol["levels"]
    assert sol["damping"][0] == 0.0 and sol["damping"][1] == 0.0  # tasks 1, 2 well-conditioned here
    np.testing.assert_allclose(J1 @ z, v1, atol=1e-9)              # task 1 exactly
    np.testing.assert_allclose(J1 @ (z2 - z1), 0.0, atol=1e-9)     # task 2's correction: no effect on 1
    np.testing.assert_allclose(J1 @ (z3 - z2), 0.0, atol=1e-9)     # nor task 3's
    np.testing.assert_allclose(J2 @ (z3 - z2), 0.0, atol=1e-9)     # ... on 2
    # task 2: the constrained least-squares optimum (here feasible: J2 z = v2)
    z_star = _constrained_lsq(J1, v1, J2, v2)
    np.testing.assert_allclose(J2 @ z, J2 @ z_star, atol=1e-9)
    np.testing.assert_allclose(J2 @ z, v2, atol=1e-9)


def test_conflicting_secondary_task_is_least_squares_in_the_null_space(nominal):
    """A secondary task with more rows than the null space of task 1 (infeasible): its residual
    is the constrained least-squares minimum, and task 1 is untouched. Damping is switched off
    (dls_threshold far below every singular value) to compare with the exact optimum."""
    rng = np.random.default_rng(7)
    q = _random_state(nominal, rng)
    _, J1, _ = _task_jacobians(nominal, q)
    nv = nominal.model.nv
    J2 = rng.normal(size=(nv - 1, nv))  # 9 rows > 7 = dim ker J1
    v1, v2 = rng.normal(size=3), rng.normal(size=nv - 1)
    sol = task_priority_velocity([(J1, v1), (J2, v2)], dls_threshold=1e-9, dls_damping=1e-9)
    z = sol["zeta"]
    z_star = _constrained_lsq(J1, v1, J2, v2)
    np.testing.assert_allclose(J1 @ z, v1, atol=1e-9)
    r, r_star = np.linalg.norm(J2 @ z - v2), np.linalg.norm(J2 @ z_star - v2)
    assert r > 0.1  # really infeasible
    assert abs(r - r_star) < 1e-9
    np.testing.assert_allclose(J2 @ z, J2 @ z_star, atol=1e-9)


def test_singularity_robust_form_keeps_task_one(nominal):
    rng = np.random.default_rng(3)
    q = _random_state(nominal, rng)
    _, J1, J2 = _task_jacobians(nominal, q)
    v1, v2 = rng.normal(size=3), rng.normal(size=3)
    sol = task_priority_velocity([(J1, v1), (J2, v2)], form="singularity_robust")
    z1, z2 = sol["levels"]
    np.testing.assert_allclose(J1 @ z2, v1, atol=1e-9)
    np.testing.assert_allclose(J1 @ (z2 - z1), 0.0, atol=1e-9)


@pytest.mark.parametrize("seed", [0, 5])
def test_null_space_projector_is_exact(nominal, seed):
    rng = np.random.default_rng(seed)
    q = _random_state(nominal, rng)
    _, J1, J2 = _task_jacobians(nominal, q)
    for J in (J1, np.vstack((J1, J2))):
        N = null_space_projector(J)
        np.testing.assert_allclose(N @ N, N, atol=1e-12)
        np.testing.assert_allclose(J @ N, 0.0, atol=1e-12)
        np.testing.assert_allclose(N, N.T, atol=1e-12)
        assert round(float(np.trace(N))) == J.shape[1] - np.linalg.matrix_rank(J)
    # the projectors the solver returns are these
    sol = task_priority_velocity([(J1, np.zeros(3)), (J2, np.zeros(3))])
    np.testing.assert_allclose(J1 @ sol["projectors"][0], 0.0, atol=1e-12)
    np.testing.assert_allclose(np.vstack((J1, J2)) @ sol["projectors"][1], 0.0, atol=1e-12)


def _run(duration: float, trajectory=None, **params):
    plant = Plant(ROBOT, initial=INIT)
    ctrl = create("task_priority", robot=NominalRobot(ROBOT), trajectory=trajectory, T=T, **params)
    return plant, run_closed_loop(plant, ctrl, duration, T=T)


def test_still_water_exact_model_holds_tip_and_vehicle():
    """plant = nominal, still water, at rest: every task error is zero, zeta_r = 0, the hold
    force cancels the net weight exactly, nothing moves (velocities by backward differences)."""
    plant, res = _run(3.0)
    assert res.status == "ok", res.reason
    s = res.signals
    assert np.abs(s["tip_desired"] - s["tip_true"]).max() < 1e-6
    assert np.abs(s["e_tip"]).max() < 1e-6
    assert np.abs(s["e_attitude"]).max() < 1e-6
    assert np.abs(s["e_position"]).max() < 1e-6
    assert np.abs(s["e_posture"]).max() < 1e-6
    assert np.abs(s["zeta_ref"]).max() < 1e-6
    assert np.abs(s["q_true"] - s["q_true"][0]).max() < 1e-6
    assert s["base_desired"].shape[1] == 7 and s["tip_desired"].shape[1] == 3
    assert s["zeta_ref"].shape[1] == plant.model.nv and s["wrench_body"].shape[1] == 6
    assert not s["thrust_saturated"].any()


def _circle(phase: float = 0.0):
    """Circle r = 0.05 m, period 20 s (|v| = 15.7 mm/s; the speed steps at t = 0) in the world
    horizontal plane, shifted to start at the initial tip (as robot_scenario does)."""
    plant0 = Plant(ROBOT, initial=INIT)
    circ = Circle(centre=(0.0, 0.0, 0.0), radius=0.05, period=20.0, phase=phase)
    return _Shifted(circ, plant0.tip_position - circ.position(0.0)), plant0.tip_position


def test_tracks_a_small_circle_with_a_bounded_tip_error():
    """Phase 0: the circle runs from the initial tip 10 cm back towards the vehicle, where the
    arm's tip Jacobian (arm dofs) comes close to singular (smallest singular value 0.098 -> 0.007
    m/rad at t = 10 s). Posture stacked with the vehicle position in task 3
    (posture_level="with_position", the better choice near this singularity; the default,
    "below_position", reaches 6 mm here). Measured:
    max tip error 2.10 mm (at the start: the velocity step that the low level must catch up
    with), 0.64 mm after 5 s; attitude error 1.4 mrad; the vehicle gives way by up to 40 mm (task
    3's least squares trades vehicle position against arm posture, posture_weight 0.1 m/rad).
    Bound 5 mm: the tip task has the top priority and its CLIK loop (gain_tip 1/s) closes on the
    measured tip, so its error is only the low-level lag behind zeta_r (Kp, Kd from the nominal
    mass matrix, 10 rad/s on the joints, 2 rad/s on the vehicle)."""
    tr, tip0 = _circle()
    _, res = _run(20.0, trajectory=tr, posture_level="with_position")
    assert res.status == "ok", res.reason
    s = res.signals
    err = np.linalg.norm(s["tip_desired"] - s["tip_true"], axis=1)
    assert err.max() < 5e-3
    assert err[res.t > 5.0].max() < 1.5e-3
    # the desired path really is the circle through the initial tip
    np.testing.assert_allclose(s["tip_desired"][0], tip0, atol=1e-12)
    assert np.ptp(s["tip_desired"][:, 0]) > 0.09
    # the lower priorities stay bounded while the tip is tracked
    assert np.abs(s["e_attitude"]).max() < 1e-2
    assert np.abs(s["e_position"]).max() < 0.1
    assert not s["thrust_saturated"].any()


def test_circle_away_from_singularities_holds_the_vehicle_with_posture_below():
    """Phase pi (the circle runs outwards, the arm stays well-conditioned: smallest singular
    value >= 0.073 m/rad), posture_level "below_position": the vehicle position is a priority of
    its own, held kinematically exactly. Measured: tip error max 0.98 mm, 0.065 mm after 5 s;
    vehicle position error max 0.21 mm; attitude 1.5 mrad. Bounds 2 mm, 0.5 mm, 1 mm."""
    tr, _ = _circle(phase=math.pi)
    _, res = _run(20.0, trajectory=tr, posture_level="below_position")
    assert res.status == "ok", res.reason
    s = res.signals
    err = np.linalg.norm(s["tip_desired"] - s["tip_true"], axis=1)
    assert err.max() < 2e-3
    assert err[res.t > 5.0].max() < 5e-4
    assert np.abs(s["e_position"]).max() < 1e-3
    assert np.abs(s["e_attitude"]).max() < 5e-3
    assert np.all(s["dls_lambda2"] == 0.0)  # no damping needed on this path


def test_closed_loop_with_a_velocity_sensor_is_deterministic():
    """The velocity-sensor path (measurement.qd) in closed loop on the circle: as bounded as with
    backward differences, and two runs give identical records."""
    tr, _ = _circle()

    def once():
        plant = Plant(ROBOT, initial=INIT)
        ctrl = create("task_priority", robot=NominalRobot(ROBOT), trajectory=tr, T=T)
        return run_closed_loop(plant, ctrl, 4.0, T=T, sensor=SensorModel(velocity_sensor=True))

    a, b = once(), once()
    assert a.status == "ok", a.reason
    err = np.linalg.norm(a.signals["tip_desired"] - a.signals["tip_true"], axis=1)
    assert err.max() < 5e-3
    for k in a.signals:
        np.testing.assert_array_equal(a.signals[k], b.signals[k])


def test_velocity_sensor_and_differences_both_work():
    nom = NominalRobot(ROBOT)
    ctrl = create("task_priority", robot=nom)
    q = Plant(ROBOT, initial=INIT).q
    ctrl.reset(Measurement(k=0, t=0.0, q=q))
    c0 = ctrl.compute(Measurement(k=0, t=0.0, q=q))
    c1 = ctrl.compute(Measurement(k=1, t=T, q=q, qd=np.zeros(nom.model.nv)))
    np.testing.assert_allclose(c0.thrust, c1.thrust, atol=1e-12)


@pytest.mark.parametrize("params, name", [
    ({"gain_tip": -1.0}, "gain_tip"),
    ({"gain_tip": 60.0}, "gain_tip"),          # >= 1/T
    ({"gain_attitude": math.nan}, "gain_attitude"),
    ({"gain_position": "x"}, "gain_position"),
    ({"gain_posture": -0.1}, "gain_posture"),
    ({"posture_weight": 0.0}, "posture_weight"),
    ({"posture_level": "top"}, "posture_level"),
    ({"priority_form": "nope"}, "priority_form"),
    ({"dls_threshold": 0.0}, "dls_threshold"),
    ({"dls_damping": -1.0}, "dls_damping"),
    ({"rank_tol": 2.0}, "rank_tol"),
    ({"bandwidth_base": 0.0}, "bandwidth_base"),
    ({"bandwidth_attitude": -1.0}, "bandwidth_attitude"),
    ({"bandwidth_joints": math.inf}, "bandwidth_joints"),
    ({"damping_ratio": 0.0}, "damping_ratio"),
    ({"kp": [1.0, 2.0]}, "kp"),
    ({"kd": -1.0}, "kd"),
    ({"kp": "stiff"}, "kp"),
    ({"reference_lead_limit": 0.0}, "reference_lead_limit"),
    ({"T": 0.0}, "T"),
    ({"trajectory": 3.0}, "trajectory"),
])
def test_bad_parameters_name_the_parameter(nominal, params, name):
    with pytest.raises(ControllerError, match=name):
        create("task_priority", robot=nominal, **params)


def test_needs_a_nominal_robot():
    with pytest.raises(ControllerError, match="NominalRobot"):
        create("task_priority", robot=None)
