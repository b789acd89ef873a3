"""Joint and torque limits (issue 19, item 4): the controllers' velocity damper, the motors'
applied torques, the ``joint_limit`` status and the ``joint_limit_excursion_deg`` metric.

Truths used: the exact zero-order-hold double integrator (the damper's closed form), MuJoCo's
own ``data.actuator_force`` after a step and its ``jnt_range`` with the ``qpos`` of a separately
stepped MjData (the excursion), never the code's own numbers."""

from __future__ import annotations

import math
from pathlib import Path

import mujoco
import numpy as np
import pytest

from uvms_mj.control.base import Command, Controller, ControllerError
from uvms_mj.control.limits import JOINT_LIMIT_MARGIN, JointLimits, clamp_joint_acceleration
from uvms_mj.control.nominal import NominalRobot
from uvms_mj.plant.plant import Plant
from uvms_mj.scenario.schema import load_scenario, run_scenario
from uvms_mj.sim.experiment import metrics
from uvms_mj.sim.limits import JOINT_LIMIT_TOLERANCE_DEG, joint_limit_excursion, plant_joint_ranges
from uvms_mj.sim.loop import run_closed_loop

SCEN = Path(__file__).resolve().parents[1] / "scenarios"


# ------------------------------------------------------------------ the velocity damper


@pytest.mark.parametrize("beta", [0.1, 0.2, 1.0, 2.0])
def test_damper_keeps_a_double_integrator_inside_and_approaches_geometrically(beta):
    """A joint driven at 50 rad/s^2 toward hi under the zero-order hold (exact: q += T qd + T^2
    a / 2, qd += T a) never passes hi, and once the bound is active the distance shrinks by
    (1 - beta/2) / (1 + beta/2) per sample (module docstring's closed form; to 1e-12 relative:
    a few roundings per step)."""
    T, hi = 0.02, 1.0
    q, qd = 0.0, 0.0
    ratio = (1 - beta / 2) / (1 + beta / 2)
    active_prev = None
    for _ in range(400):
        a = float(clamp_joint_acceleration(np.array([q]), np.array([qd]), np.array([50.0]), np.array([-np.inf]),
                                           np.array([hi]), T, beta)[0])
        active = a < 50.0
        d = hi - q
        q, qd = q + T * qd + 0.5 * T * T * a, qd + T * a
        assert q <= hi + 1e-12
        if active and active_prev:
            assert (hi - q) == pytest.approx(ratio * d, rel=1e-9, abs=1e-15)
        active_prev = active
    assert hi - q < 1e-3  # it got close to the bound


def test_damper_pushes_a_joint_back_from_outside_and_is_inert_without_limits():
    T, beta = 0.02, 0.2
    a = clamp_joint_acceleration(np.array([1.1]), np.array([0.0]), np.array([0.0]), np.array([-1.0]),
                                 np.array([1.0]), T, beta)
    # a_hi = beta (hi - q) / T / (T (1 + beta/2)) at rest
    assert a[0] == pytest.approx(beta * (-0.1) / T / (T * (1 + beta / 2)), rel=1e-12)
    free = clamp_joint_acceleration(np.array([5.0]), np.array([3.0]), np.array([7.0]), np.array([-np.inf]),
                                    np.array([np.inf]), T, beta)
    assert free[0] == 7.0


def test_joint_limits_read_the_nominal_ranges_with_the_margin_and_check_settings():
    r = NominalRobot("bluerov2_alpha")
    m, lay = r.model, r.layout
    lim = JointLimits(m, lay.joint_qadr, 0.02)
    ranges = np.array([m.jnt_range[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, j)] for j in lay.joint_names])
    assert np.allclose(lim.lo, ranges[:, 0] + JOINT_LIMIT_MARGIN) and np.allclose(lim.hi, ranges[:, 1] - JOINT_LIMIT_MARGIN)
    assert JOINT_LIMIT_MARGIN == pytest.approx(math.radians(2.0))
    paper = NominalRobot(Path(__file__).resolve().parents[1] / "models" / "uvms.xml")
    assert not JointLimits(paper.model, paper.layout.joint_qadr, 1 / 60).active  # unlimited joints: inert
    assert np.all(np.isinf(paper.motor_lo)) and np.all(np.isinf(paper.motor_hi))  # unlimited motors
    with pytest.raises(ControllerError, match="joint_limit_time"):
        JointLimits(m, lay.joint_qadr, 0.02, tau=0.005)
    with pytest.raises(ControllerError, match="joint_limit_margin"):
        JointLimits(m, lay.joint_qadr, 0.02, margin=2.0)


# ------------------------------------------------------------------ applied torques


def test_applied_torque_is_mujocos_clip_of_the_command():
    """22 N m commanded to +-9 N m motors: the plant reports 9 (the clip), and MuJoCo's own
    actuator_force x gear after a step is the same."""
    p = Plant("bluerov2_alpha", max_speed=1e6)  # one step of a light arm at +-9 N m: fast, not a divergence
    lay = p.layout
    cmd = np.array([22.0, -30.0, 4.0, 7.0])[: len(lay.motor_ids)]
    p.set_joint_torques(cmd)
    applied = p.joint_torques_applied
    lo, hi = p.model.actuator_ctrlrange[lay.motor_ids].T
    assert np.array_equal(applied, np.clip(cmd, lo, hi))
    p.step(1)
    mj = p.data.actuator_force[lay.motor_ids] * p.model.actuator_gear[lay.motor_ids, 0]
    assert np.allclose(mj, applied, rtol=0, atol=1e-12)


# ------------------------------------------------------------------ detection


class _ConstantTorque(Controller):
    robots = "floating"
    T = 0.02

    def __init__(self, n_thr: int, torques) -> None:
        self.n_thr, self.tau = n_thr, np.asarray(torques, dtype=float)

    def reset(self, m) -> None:
        pass

    def compute(self, m) -> Command:
        return Command(thrust=np.zeros(self.n_thr), torques=self.tau.copy(), signals={})


def _soft_elbow_plant() -> tuple[Plant, int]:
    p = Plant("bluerov2_alpha", gravity=False)
    j = mujoco.mj_name2id(p.model, mujoco.mjtObj.mjOBJ_JOINT, "alpha_elbow")
    p.model.jnt_solref[j] = (0.5, 1.0)  # a very soft stop: 9 N m push the elbow degrees past it
    return p, j


def test_a_joint_forced_past_its_limit_is_reported_with_the_excursion_mujoco_gives():
    p, j = _soft_elbow_plant()
    lay = p.layout
    tau = np.zeros(len(lay.motor_ids))
    tau[list(lay.motor_joints).index("alpha_elbow")] = -9.0
    # independent truth: the same model and commands stepped here, qpos against jnt_range
    d = mujoco.MjData(p.model)
    d.qpos[:], d.qvel[:], d.act[:] = p.data.qpos, p.data.qvel, p.data.act
    d.ctrl[lay.motor_ids] = tau
    n_sub = int(round(0.02 / p.model.opt.timestep))
    lo = p.model.jnt_range[j, 0]
    adr = p.model.jnt_qposadr[j]
    truth = [lo - d.qpos[adr]]
    for _ in range(100):
        mujoco.mj_step(p.model, d, nstep=n_sub)
        truth.append(lo - d.qpos[adr])
    res = run_closed_loop(p, _ConstantTorque(len(lay.thruster_ids), tau), 2.0, T=0.02, warm_start=False)
    expect = math.degrees(max(truth))
    assert expect > 2 * JOINT_LIMIT_TOLERANCE_DEG  # the case does leave the range
    m = metrics(res)
    # same model, same steps: to round-off (the loop's ctrl path is the same arithmetic)
    assert m["joint_limit_excursion_deg"] == pytest.approx(expect, rel=1e-9)
    assert res.status == "joint_limit"
    assert "alpha_elbow" in res.reason and "lower limit" in res.reason and f"{expect:.2f} deg" in res.reason
    assert np.array_equal(res.signals["torques_applied"][-1], res.signals["torques"][-1])  # inside +-9


def test_within_the_tolerance_is_ok_and_the_excursion_function_names_the_joint():
    ranges = {"a": [0, -1.0, 1.0], "b": [1, 0.0, 2.0]}
    q = np.array([[0.0, 1.0], [1.0 + math.radians(0.5), 1.0], [0.0, -math.radians(3.0)]])
    e = joint_limit_excursion(q, ranges, np.array([0.0, 0.1, 0.2]))
    assert e["joint"] == "b" and e["side"] == "lower" and e["t"] == 0.2 and e["deg"] == pytest.approx(3.0)
    assert joint_limit_excursion(q[:2], ranges)["deg"] == pytest.approx(0.5)
    assert np.isnan(joint_limit_excursion(q, None)["deg"])
    paper = Plant()
    assert plant_joint_ranges(paper.model) == {}  # the paper's joints are unlimited


# ------------------------------------------------------------------ the controllers keep the ranges


def _payload(controller: str, *sets: str):
    return run_scenario(load_scenario(SCEN / "bluerov2_alpha_payload.yaml",
                                      ("duration=13", f"controller.name={controller}", *sets)))


@pytest.mark.parametrize("controller", ["rac", "rac_dob"])
def test_rac_keeps_the_base_yaw_inside_its_range_minus_the_margin(controller):
    """The payload study: the unknown 0.5 kg at t = 10 s throws the arm; without the damper the
    base yaw joint runs onto its 175 deg stop (today's behaviour), with it it stays below
    175 - 2 deg (0.1 deg of slack: the plant is not the nominal model)."""
    hi = math.degrees(NominalRobot("bluerov2_alpha").model.joint("alpha_base").range[1])
    off = _payload(controller, "controller.params.joint_limits=false")
    on = _payload(controller)
    yaw = lambda r: float(np.degrees(np.abs(r.signals["q_true"][:, 7])).max())  # noqa: E731
    assert yaw(off) > hi - 0.5
    assert yaw(on) < hi - 2.0 + 0.1
    tau = on.signals["torques"]
    assert np.all(np.abs(tau[:, :3]) <= 9.0) and np.all(np.abs(tau[:, 3]) <= 5.0)  # the motors' ranges


#: A tip line that needs the Alpha's shoulder 20 deg below its 0 deg limit (elbow 70 deg: the tip
#: at shoulder -20 deg is (0.398, 0, -1.264) m), in a 0.2 m/s side current.
SHOULDER_STUDY = """
name: limits_shoulder
robot: bluerov2_alpha
duration: 18.0
plant: {current: [0.0, 0.2, 0.0]}
initial: {position: [0.0, 0.0, -1.0], angle_unit: deg, joints: {alpha_shoulder: 110, alpha_elbow: 70}}
trajectory: {kind: line, origin: world, target: [0.398, 0.0, -1.264], cruise_speed: 0.03, accel: 0.03}
controller: {name: station_pid}
"""


@pytest.mark.parametrize("controller", ["station_pid", "task_priority"])
def test_baselines_keep_their_references_inside_the_ranges(controller, tmp_path):
    """Without the clamp the shoulder passes its 0 deg limit (measured: station_pid -0.11 deg,
    task_priority -0.61 deg); with it every arm joint stays above its lower limit, within 0.7 deg
    of the 2 deg margin (measured 1.50 and 1.92 deg: the joint loop's tracking lag)."""
    path = tmp_path / "shoulder.yaml"
    path.write_text(SHOULDER_STUDY)
    runs = {on: run_scenario(load_scenario(path, (f"controller.name={controller}",
                                                  f"controller.params.joint_limits={'true' if on else 'false'}")))
            for on in (True, False)}
    low = {on: float(np.degrees(r.signals["q_true"][:, 8]).min()) for on, r in runs.items()}  # the shoulder
    assert low[False] < 0.0
    assert low[True] > math.degrees(JOINT_LIMIT_MARGIN) - 0.7
    assert runs[True].status == "ok" and metrics(runs[True])["joint_limit_excursion_deg"] == 0.0
