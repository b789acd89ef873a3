"""The sections every robot's scenario has (uvms_mj.scenario.sections): initial state, current,
thruster failures, vehicle setpoint, overrides by role and factor.

Independent truths: the model file's own numbers (a factor times the compiled value), MuJoCo's
actuator force after a step (a failed thruster), the stationary standard deviation of an
Ornstein-Uhlenbeck process (sigma, for the Gauss-Markov current), the setpoint itself (where the
station keeper must bring the vehicle)."""

from __future__ import annotations

import math
import textwrap

import mujoco
import numpy as np
import pytest

from uvms_mj.physics import model as pm
from uvms_mj.physics.current import Current
from uvms_mj.plant.plant import Plant, ThrusterFailure
from uvms_mj.scenario.schema import ScenarioError, build, load_scenario, run_scenario


def _load(tmp_path, text: str):
    p = tmp_path / "s.yaml"
    p.write_text(textwrap.dedent(text))
    return load_scenario(p)


def test_paper_scenario_initial_joints_and_pose(tmp_path):
    sc = _load(tmp_path, """
        duration: 0.5
        initial:
          joints: {joint1: 30, joint2: -40}
          position: [0.1, 0.2, 0.0]
          orientation: {rpy: [0, 0, -80]}
    """)
    plant, ctrl = build(sc)
    k = math.pi / 180
    # the section's numbers (degrees -> radians; the yaw through a quaternion: round-off)
    expected = [0.1, 0.2, -80 * k, 30 * k, -40 * k]
    np.testing.assert_allclose(plant.q, expected, rtol=0, atol=1e-14)
    res = run_scenario(sc, built=(plant, ctrl))
    assert res.status == "ok"
    np.testing.assert_allclose(res.signals["q_true"][0], expected, rtol=0, atol=1e-14)


def test_paper_initial_names_and_plane_checked(tmp_path):
    with pytest.raises(ScenarioError, match=r"initial: .*joint1x.*did you mean 'joint1'"):
        _load(tmp_path, "initial: {joints: {joint1x: 10}}")
    with pytest.raises(ScenarioError, match=r"initial: .*planar base of this robot cannot take that position"):
        _load(tmp_path, "initial: {position: [0, 0, 0.3]}")
    with pytest.raises(ScenarioError, match=r"initial: .*cannot take that rotation"):
        _load(tmp_path, "initial: {orientation: {rpy: [10, 0, 0]}}")


def test_overrides_by_role_and_factor():
    base = Plant("bluerov2_heavy")
    hull = base.layout.base_body
    p = Plant("bluerov2_heavy", overrides={"vehicle.mass": "x1.25", "vehicle.volume": "x0.5"})
    # the factor multiplies the model file's own value (compiled mass; the plugin's volume)
    assert p.model.body_mass[hull] == pytest.approx(1.25 * base.model.body_mass[hull], rel=1e-15)
    assert p.hydro_info.bodies[hull].volume == pytest.approx(0.5 * base.hydro_info.bodies[hull].volume, rel=1e-15)
    # the paper's robot: the vehicle is its base; its own keys take factors too
    paper0, paper = Plant(), Plant(overrides={"vehicle.volume": "x1.01", "link1.mass": "x2"})
    assert paper.params.body("base").volume == pytest.approx(1.01 * paper0.params.body("base").volume, rel=1e-15)
    assert paper.params.body("link1").mass == pytest.approx(2 * paper0.params.body("link1").mass, rel=1e-15)
    with pytest.raises(ValueError, match="factor"):
        Plant(overrides={"vehicle.volume": "xabc"})


def test_thrusters_role_sets_every_thruster():
    p = Plant("bluerov2_heavy", overrides={"thrusters.tau": 0.1, "thrusters.forcerange": [-20.0, 25.0]})
    lay = p.layout
    np.testing.assert_array_equal(p.model.actuator_forcerange[lay.thruster_ids], [[-20.0, 25.0]] * len(lay.thruster_ids))
    spec = pm.load_spec(p.model_path)
    from uvms_mj.plant.robot import apply_overrides

    apply_overrides(spec, {"thrusters.tau": 0.1, "thrusters.dead_zone": [-0.05, 0.05]})
    cfg = next(dict(x.config) for x in spec.plugins if x.plugin_name == "uvms.thruster")
    assert cfg["tau"] == "0.1" and cfg["dead_zone"] == "-0.05 0.05"


def test_thruster_failure_zeroes_its_force():
    """From the first sample at or after t the failed thruster gives no force: MuJoCo's own
    actuator force is zero whatever the command; the others are untouched."""
    p = Plant(failures=[ThrusterFailure("thruster2", 0.1)])
    a = p.layout.thruster_ids[1]
    dt = p.model.opt.timestep
    forces = []
    for k in range(40):
        p.on_sample(k * dt)
        p.set_thrust([5.0, 5.0, 5.0])
        p.step()
        forces.append(p.data.actuator_force[p.layout.thruster_ids].copy())
    forces = np.array(forces)
    t = np.arange(40) * dt
    assert np.all(forces[t < 0.1 - 1e-12, 1] > 0) and np.all(forces[t >= 0.1 - 1e-12, 1] == 0.0)
    assert np.all(forces[:, 0] > 0) and np.all(forces[:, 2] > 0)
    p.reset()  # a reset undoes the failure
    assert np.all(p.model.actuator_forcerange[a] != 0)
    with pytest.raises(ValueError, match=r"thruster 'thruster9'.*did you mean"):
        Plant(failures=[ThrusterFailure("thruster9", 1.0)])


def test_gauss_markov_current_from_the_scenario(tmp_path):
    """The current of the section is the plugin's: its stationary std is sigma (an
    Ornstein-Uhlenbeck process: 4 standard errors of a std estimate from ~T/(2 tau) independent
    samples), the same seed gives the same current, another seed another."""
    sigma, tau, T = 0.05, 0.5, 200.0

    def current_series(seed: int) -> np.ndarray:
        p = Plant(current=Current(model="gauss_markov", velocity=(0.1, 0, 0), mean=(0.1, 0, 0),
                                  sigma=(sigma, sigma, 0), tau=(tau, tau, tau), seed=seed), gravity=False)
        out = []
        n = int(T / p.model.opt.timestep)
        for _ in range(n // 12):
            mujoco.mj_step(p.model, p.data, nstep=12)
            out.append(pm.current_state_of(p.model, p.data)[2].copy())
        return np.array(out)

    v = current_series(7)
    n_eff = T / (2 * tau)
    assert abs(v[:, 0].std() - sigma) < 4 * sigma / math.sqrt(2 * n_eff)
    assert abs(v[:, 0].mean() - 0.1) < 4 * sigma / math.sqrt(n_eff)
    np.testing.assert_array_equal(v, current_series(7))
    assert not np.array_equal(v, current_series(8))
    sc = _load(tmp_path, """
        robot: bluerov2_alpha
        duration: 0.2
        current: {model: gauss_markov, velocity: [0.1, 0, 0], gauss_markov: {sigma: [0.05, 0.05, 0.0], tau: [5, 5, 5]}}
    """)
    plant, _ = build(sc)
    cfg = pm.hydro_of(plant.model).water
    assert cfg.current_model == "gauss_markov"
    with pytest.raises(ScenarioError, match=r"plant\.current: give the current in one place"):
        _load(tmp_path, "robot: bluerov2_alpha\nplant: {current: [0.1, 0, 0]}\ncurrent: {velocity: [0.1, 0, 0]}\n")
    with pytest.raises(ScenarioError, match=r"current\.profile: applies to model: profile"):
        _load(tmp_path, "current: {model: constant, profile: [{z: 0, velocity: [0, 0, 0]}]}\n")


def test_robot_scenario_failure_and_vehicle_setpoint(tmp_path):
    """A robot scenario sets a thruster failure and a vehicle setpoint from the schema alone:
    the failed thruster logs zero force from its time on; station_pid brings the vehicle to the
    setpoint (still water, 20 s: within 1 cm and 0.5 deg)."""
    sc = _load(tmp_path, """
        robot: bluerov2_heavy
        duration: 20
        initial: {position: [0, 0, -2]}
        thrusters:
          failures: [{thruster: bluerov2_t8, t: 1.0}]
        vehicle:
          setpoint: {position: [0.3, -0.2, -1.9], orientation: {rpy: [0, 0, 15]}}
        controller: {name: station_pid}
    """)
    res = run_scenario(sc)
    assert res.status == "ok"
    t, f, q = res.t, res.signals["thrust_force"], res.signals["q_true"]
    names = res.meta["robot"]["layout"]["thrusters"]
    j = names.index("bluerov2_t8")
    assert np.all(f[t >= 1.0 - 1e-12, j] == 0.0) and np.any(f[t < 1.0, j] != 0.0)
    np.testing.assert_allclose(q[-1, :3], [0.3, -0.2, -1.9], atol=0.01)
    yaw = 2 * math.atan2(q[-1, 6], q[-1, 3])
    assert abs(yaw - math.radians(15)) < math.radians(0.5)
    # every built-in floating controller takes a vehicle trajectory, task_priority too
    ctrl = build(_load(tmp_path, "robot: bluerov2_alpha\nvehicle: {trajectory: {kind: line, start: [0, 0, 0], "
                                 "target: [1, 0, 0]}}\ncontroller: {name: task_priority}\n"))[1]
    assert ctrl.base_trajectory is not None
    with pytest.raises(ScenarioError, match=r"vehicle\.trajectory: the paper's robot takes a vehicle setpoint only"):
        _load(tmp_path, "vehicle: {trajectory: {kind: line, start: [0, 0, 0], target: [1, 0, 0]}}\n")
    with pytest.raises(ScenarioError, match=r"thrusters\.failures\[0\]\.thruster: not a thruster"):
        _load(tmp_path, "robot: bluerov2_heavy\nthrusters: {failures: [{thruster: t99, t: 1}]}\n")


def test_validate_resolved_prints_a_valid_scenario(tmp_path):
    """``validate --resolved`` prints every default filled in; that output is itself a scenario
    that validates and resolves to the same thing."""
    import subprocess
    import sys

    import yaml

    src = tmp_path / "s.yaml"
    src.write_text("robot: bluerov2_alpha\nduration: 1\ncurrent: {model: gauss_markov, velocity: [0.1, 0, 0]}\n"
                   "vehicle: {setpoint: {position: [0, 0, -1]}}\n")
    run = lambda path: subprocess.run([sys.executable, "-m", "uvms_mj.cli.main", "validate", str(path), "--resolved"],  # noqa: E731
                                      capture_output=True, text=True, cwd=tmp_path)
    first = run(src)
    assert first.returncode == 0, first.stderr
    data = yaml.safe_load(first.stdout)
    assert data["current"]["model"] == "gauss_markov" and data["controller"]["params"]["T"] == 0.02
    again = tmp_path / "resolved.yaml"
    again.write_text(first.stdout)
    second = run(again)
    assert second.returncode == 0, second.stderr
    assert yaml.safe_load(second.stdout) == data


def test_a_section_of_the_other_robot_kind_says_so(tmp_path):
    """One schema for every robot: a value that applies to one robot kind only says so in one
    line; arm waypoints with a controller that follows the tip instead are a warning (rac) or
    that controller's own error (pd)."""
    from uvms_mj.scenario.schema import scenario_warnings

    sc = _load(tmp_path, "arm: {waypoints: [{t: 1.0, joints: {joint1: 10}}]}\n")
    assert any(w.startswith("arm.waypoints: controller 'rac_dob' moves the arm by the tip task")
               for w in scenario_warnings(sc))
    with pytest.raises(ScenarioError, match=r"arm: pd follows a tip trajectory, not arm joint waypoints"):
        _load(tmp_path, "arm: {waypoints: [{t: 1.0, joints: {joint1: 10}}]}\ncontroller: {name: pd}\n")
    sc = _load(tmp_path, "arm: {waypoints: [{t: 1.0, joints: {joint1: 10}}]}\ncontroller: {name: station_pid}\n"
                         "control_period: 0.025\n"
                         "trajectory: null\n")
    assert sc.robot == "paper" and sc.arm.waypoints[0].joints == {"joint1": 10}
    with pytest.raises(ScenarioError, match=r"plant\.model_mismatch: applies to the paper's robot only"):
        _load(tmp_path, "robot: bluerov2_heavy\nplant: {model_mismatch: true}\n")
    with pytest.raises(ScenarioError, match=r"plant\.hydro\.added_mass: 'lagged' applies to the paper's robot only"):
        _load(tmp_path, "robot: bluerov2_heavy\nplant: {hydro: {added_mass: lagged}}\n")
    with pytest.raises(ScenarioError, match=r"plant\.overrides_file: applies to MJCF robots"):
        _load(tmp_path, "plant: {overrides_file: identified.yaml}\n")
    with pytest.raises(ScenarioError, match=r"arms: unknown key 'arms' \(did you mean 'arm'\?\)"):
        _load(tmp_path, "robot: bluerov2_heavy\narms: {}\n")


def test_a_retired_controller_names_its_replacement(tmp_path):
    """A file valid before the planar closed form became a test oracle (controller rac_planar)
    fails with one line naming the controller to use instead (in a process of its own: the test
    suite registers the oracle)."""
    import subprocess
    import sys

    f = tmp_path / "old.yaml"
    f.write_text("controller: {name: rac_dob_planar}\n")
    out = subprocess.run([sys.executable, "-m", "uvms_mj.cli.main", "validate", str(f)], capture_output=True,
                         text=True)
    assert out.returncode == 2
    assert ("controller.name: controller 'rac_dob_planar' is no longer shipped (the planar closed form is a test "
            "oracle now): use 'rac_dob'") in out.stderr
    assert "Traceback" not in out.stderr


def test_paper_scenario_overrides_by_name_role_and_factor_and_a_payload(tmp_path):
    """The paper's robot takes the overrides every robot takes (element names, the vehicle role,
    factors) beside its own keys, and a payload: the compiled plant has the model file's values
    times the factors, and the payload's mass appears at its time (MuJoCo's body mass)."""
    sc = _load(tmp_path, """
        duration: 1.0
        plant:
          model_mismatch: false
          overrides: {vehicle.volume: x1.01, joint1.damping: 0.05, link1.mass: x1.1}
          payload: {mass: 0.4, t: 0.5}
        nominal:
          overrides: {link2.added_mass: x1.3}
    """)
    plant, ctrl = build(sc)
    ref = Plant()
    assert plant.params.body("base").volume == pytest.approx(1.01 * ref.params.body("base").volume, rel=1e-15)
    assert plant.params.body("link1").mass == pytest.approx(1.1 * ref.params.body("link1").mass, rel=1e-15)
    j = mujoco.mj_name2id(plant.model, mujoco.mjtObj.mjOBJ_JOINT, "joint1")
    assert plant.model.dof_damping[plant.model.jnt_dofadr[j]] == 0.05
    from uvms_mj.plant.params import read_params

    nom, file = read_params(ctrl.robot.model).body("link2"), ref.params.body("link2")
    np.testing.assert_allclose(nom.added_mass, 1.3 * np.array(file.added_mass), rtol=1e-15)
    res = run_scenario(sc, built=(plant, ctrl))
    assert res.status == "ok"
    b = mujoco.mj_name2id(plant.model, mujoco.mjtObj.mjOBJ_BODY, "payload")
    assert plant.model.body_mass[b] == 0.4


def test_rac_dob_carries_the_vehicle_along_its_trajectory(tmp_path):
    """vehicle.trajectory with rac_dob (the paper's method): the vehicle origin follows a 0.4 m
    line at 0.05 m/s (the tip holds its world position, as far as the arm reaches); after the
    move the vehicle sits at the line's end (within 5 mm; measured 0.85 mm) and its RMS error
    over the run stays below 1 cm (measured 0.9 mm; Eq. 11 takes the path's difference
    quotient as the desired velocity)."""
    sc = _load(tmp_path, """
        robot: bluerov2_alpha
        duration: 16
        initial: {position: [0, 0, -2], joints: {alpha_shoulder: 100, alpha_elbow: 60}}
        vehicle:
          trajectory: {kind: line, start: [0, 0, 0], target: [0.4, 0, 0], cruise_speed: 0.05, accel: 0.05}
        controller: {name: rac_dob}
    """)
    res = run_scenario(sc)
    assert res.status == "ok", res.reason
    q, bd = res.signals["q_true"], res.signals["base_desired"]
    np.testing.assert_allclose(bd[-1, :3], [0.4, 0.0, -2.0], atol=1e-12)
    np.testing.assert_allclose(q[-1, :3], [0.4, 0.0, -2.0], atol=0.005)
    assert np.sqrt(np.mean(np.sum((bd[:, :3] - q[:, :3]) ** 2, axis=1))) < 0.01


def test_robot_controller_base_reference_truth_and_nominal(tmp_path):
    """controller.base_reference applies to every robot: on the BlueROV2 + Alpha, ``truth`` is the
    plant's true initial pose and ``nominal`` the model file's (its qpos0: no initial keyframe)."""
    for ref, expected in (("truth", [0.1, 0.0, -1.5, 1.0, 0.0, 0.0, 0.0]), ("nominal", [0, 0, 0, 1, 0, 0, 0])):
        sc = _load(tmp_path, f"robot: bluerov2_alpha\ninitial: {{position: [0.1, 0, -1.5]}}\n"
                             f"controller: {{name: rac, base_reference: {ref}}}\n")
        _, ctrl = build(sc)
        np.testing.assert_allclose(ctrl.base_reference, expected, rtol=0, atol=1e-15)
    with pytest.raises(ScenarioError, match=r"controller\.base_reference: give one base reference"):
        _load(tmp_path, "robot: bluerov2_alpha\nvehicle: {setpoint: {position: [0, 0, -1]}}\n"
                        "controller: {name: rac, base_reference: truth}\n")


def test_one_thrusters_section(tmp_path):
    """The thrusters section is every robot's: on the paper's robot a dead-zone band in newtons
    (or true: the model's band) reaches the plant; on an MJCF robot the band and lag reach every
    thruster plugin (command units), true is refused in one line."""
    plant, _ = build(_load(tmp_path, "duration: 1\nthrusters: {dead_zone: [-0.1, 0.3]}\n"))
    assert plant.dead_zone and plant._dead_band == (-0.1, 0.3)
    plant, _ = build(_load(tmp_path, "duration: 1\nthrusters: {dead_zone: true}\n"))
    assert plant._dead_band == tuple(Plant().params.dead_zone)
    sc = _load(tmp_path, "robot: bluerov2_heavy\nthrusters: {dead_zone: [-0.05, 0.05], tau: 0.08}\n")
    plant, _ = build(sc)
    spec = pm.load_spec(plant.model_path)
    from uvms_mj.plant.robot import apply_overrides

    apply_overrides(spec, sc.thrusters.overrides())
    cfg = next(dict(x.config) for x in spec.plugins if x.plugin_name == "uvms.thruster")
    assert cfg["dead_zone"] == "-0.05 0.05" and cfg["tau"] == "0.08"
    with pytest.raises(ScenarioError, match=r"thrusters\.dead_zone: give the band \[low, high\]"):
        _load(tmp_path, "robot: bluerov2_heavy\nthrusters: {dead_zone: true}\n")


def test_vehicle_trajectory_refused_by_a_controller_without_base_trajectory(tmp_path, monkeypatch):
    """A (plug-in) floating controller without ``base_trajectory``: vehicle.trajectory is refused
    in one line naming the controllers that take it (every built-in floating one)."""
    from uvms_mj.control import base

    class Toy(base.Controller):
        robots = "floating"

        def __init__(self, robot=None, T=0.02, arm_trajectory=None, base_reference=None):
            self.T = T

        def reset(self, measurement):
            pass

        def compute(self, measurement):
            return base.Command(thrust=np.zeros(0), torques=np.zeros(0))

    monkeypatch.setitem(base._REGISTRY, "toy", Toy)
    with pytest.raises(ScenarioError, match=r"vehicle\.trajectory: controller 'toy' takes no vehicle trajectory "
                                            r"\(base_trajectory\); controllers that do: pd, rac, rac_dob, station_pid, "
                                            r"task_priority"):
        _load(tmp_path, "robot: bluerov2_alpha\nvehicle: {trajectory: {kind: line, start: [0, 0, 0], "
                        "target: [1, 0, 0]}}\ncontroller: {name: toy}\n")
