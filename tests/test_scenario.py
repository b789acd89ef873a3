"""Scenario files: schema, defaults (= the paper experiment), --set overrides, error messages,
determinism and the shipped scenarios/."""

from __future__ import annotations

import json
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest
import yaml

from uvms_mj.control import available
from uvms_mj.sim.experiment import PAPER_TIP_DISPLACEMENT, PaperExperiment, truth_overrides
from uvms_mj.sim.loop import SensorModel
from oracles.planar.nominal import params_from_file
from uvms_mj.plant.params import read_params
from uvms_mj.plant.plant import Plant
from uvms_mj.scenario.schema import (
    Scenario,
    ScenarioError,
    build,
    dump_yaml,
    load_scenario,
    log_path,
    resolved,
    run_scenario,
    validate_scenario,
)

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"
FILES = sorted(SCENARIOS.glob("*.yaml"))
SHORT = 1.5  # s: enough for the loop, the thrusters and the trajectory to start (fast tests)


def write(tmp_path: Path, text: str, name: str = "case.yaml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def error_of(tmp_path: Path, text: str, sets=()) -> str:
    path = write(tmp_path, text)
    with pytest.raises(ScenarioError) as info:
        load_scenario(path, sets)
    msg = str(info.value)
    assert str(path) in msg.splitlines()[0]  # every message names the file
    return msg


def assert_same_run(a, b) -> None:
    assert a.status == b.status == "ok"
    np.testing.assert_array_equal(a.t, b.t)
    assert set(a.signals) == set(b.signals)
    for key in b.signals:
        np.testing.assert_array_equal(a.signals[key], b.signals[key], err_msg=key)


# ------------------------------------------------------------------ shipped scenarios


def test_the_required_scenarios_exist():
    names = {p.stem for p in FILES}
    assert {"paper", "current", "mismatch", "beyond_reach", "slow_thrusters", "slow_thrusters_low_gains",
            "noise_0.1mm", "noise_1mm"} <= names


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_every_scenario_file_validates_and_documents_itself(path):
    sc = load_scenario(path)
    assert sc.name == path.stem
    text = path.read_text()
    assert text.startswith("#")  # what it studies, expected outcome, measured numbers
    assert "Expected" in text and "Measured" in text


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_model_dump_round_trips(path, tmp_path):
    sc = load_scenario(path)
    dumped = write(tmp_path, yaml.safe_dump(sc.model_dump()))
    assert load_scenario(dumped) == sc
    assert load_scenario(write(tmp_path, dump_yaml(sc), "again.yaml")) == sc
    # resolved(): JSON-serialisable, itself a valid scenario, and a fixed point
    res = resolved(sc)
    assert json.loads(json.dumps(res)) == res
    assert resolved(validate_scenario(res)) == res


def test_paper_yaml_is_the_paper_experiment():
    sc = load_scenario(SCENARIOS / "paper.yaml", [f"duration={SHORT}"])
    assert_same_run(run_scenario(sc), PaperExperiment(duration=SHORT).run())


# ------------------------------------------------------------------ defaults


def test_defaults_are_the_paper_experiment():
    sc, pe = Scenario(), PaperExperiment()
    assert sc.duration == pe.duration and sc.seed == pe.seed and sc.warm_start == pe.warm_start
    assert sc.controller.name == pe.controller and sc.controller.params == pe.controller_params
    assert tuple(sc.trajectory.displacement) == PAPER_TIP_DISPLACEMENT and sc.trajectory.target is None
    assert sc.trajectory.cruise_speed == sc.trajectory.accel == pe.cruise_speed
    assert sc.plant.model_mismatch is pe.truth and sc.plant.overrides == pe.plant_overrides
    flat = {k: v for k, v in sc.sensors.model_dump().items() if k not in ("position", "attitude", "joints", "velocity")}
    assert {f.name: getattr(pe.sensor, f.name) for f in fields(SensorModel) if f.name != "signals"} == flat
    assert pe.sensor.signals is None and not sc.sensors.signal_sections()  # the per-signal sensors: off
    plant = Plant()
    assert sc.physics.timestep == plant.model.opt.timestep == 1 / 120
    assert sc.physics.integrator == "rk4"
    th = plant.params.thrusters[0]
    assert sc.thrusters.tau == th.tau and tuple(sc.thrusters.force_range) == th.force_range
    assert sc.thrusters.dead_zone is False and sc.plant.current == [0.0, 0.0]
    res = resolved(sc)
    assert res["plant"]["hydro"]["drag"] == "mujoco"
    assert res["controller"]["params"]["gamma"] == [0.3, 0.3, 0.2, 0.2, 0.2]
    assert res["outputs"]["log"] == "logs/scenario-rac_dob.mcap"
    assert resolved(Scenario(plant={"model_mismatch": False}))["plant"]["hydro"]["drag"] == "strip"


def test_default_scenario_runs_exactly_the_paper_experiment(tmp_path):
    a = run_scenario(Scenario(duration=SHORT))
    assert_same_run(a, PaperExperiment(duration=SHORT).run())
    # an empty file too (the name comes from the file)
    sc = load_scenario(write(tmp_path, "", "empty.yaml"), [f"duration={SHORT}"])
    assert sc.name == "empty" and log_path(sc) == Path("logs/empty-rac_dob.mcap")
    assert_same_run(run_scenario(sc), a)
    assert a.meta["scenario"]["duration"] == SHORT and a.meta["name"] == "scenario"


def test_ideal_and_rac_match_the_experiment_too():
    sc = Scenario(duration=SHORT, plant={"model_mismatch": False}, controller={"name": "rac"})
    assert_same_run(run_scenario(sc), PaperExperiment(duration=SHORT, truth=False, controller="rac").run())


# ------------------------------------------------------------------ building


def test_nominal_model_is_the_file_plus_nominal_overrides():
    sc = load_scenario(SCENARIOS / "mismatch.yaml")
    plant, ctrl = build(sc)
    nominal, file = read_params(ctrl.robot.model), params_from_file()  # the controller's own MuJoCo model
    for name in ("base", "link1", "link2"):
        b, f = nominal.body(name), file.body(name)
        np.testing.assert_allclose(b.added_mass + (b.added_inertia,), 1.3 * np.array(f.added_mass + (f.added_inertia,)),
                                   rtol=1e-9)
        np.testing.assert_allclose(b.drag_coef, 1.3 * np.array(f.drag_coef), rtol=1e-9)
        assert b.volume == f.volume
    # the plant is the truth: potential-flow added mass, +1 % base volume (never seen by the nominal)
    truth = truth_overrides()
    assert plant.params.body("base").added_mass == pytest.approx(truth["base.added_mass"][:2])
    assert plant.params.body("base").volume == pytest.approx(truth["base.volume"])
    # plant overrides never leak into the nominal model
    _, ctrl = build(Scenario(plant={"overrides": {"base.volume": 0.031}}))
    assert read_params(ctrl.robot.model).body("base").volume == file.body("base").volume


def test_sections_reach_the_plant_and_controller():
    sc = Scenario(
        physics={"timestep": 1 / 240, "integrator": "euler", "backend": "python"},
        plant={"current": [0.1, -0.05], "gravity": True, "hydro": {"drag": "strip", "buoyancy": True}},
        thrusters={"tau": 0.05, "force_range": [-5.0, 10.0], "dead_zone": True},
        controller={"name": "rac", "params": {"gamma": 0.25, "js_high": 0.05}},
        trajectory={"target": [0.5, -0.5], "cruise_speed": 0.03, "accel": 0.05, "t_start": 0.5},
    )
    plant, ctrl = build(sc)
    m = plant.model
    assert m.opt.timestep == 1 / 240 and plant.backend == "python" and plant.terms.drag == "strip"
    np.testing.assert_array_equal(m.opt.wind[:2], [0.1, -0.05])
    assert plant.params.thrusters[0].tau == 0.05 and plant.params.thrusters[2].force_range == (-5.0, 10.0)
    assert plant.dead_zone is True
    assert ctrl.name == "rac" and np.all(ctrl.gamma == 0.25) and ctrl.js_high == 0.05
    assert ctrl.trajectory.target == (0.5, -0.5, 0.0) and ctrl.trajectory.cruise_speed == 0.03  # the plane z = 0
    assert ctrl.trajectory.accel == 0.05 and ctrl.trajectory.t_start == 0.5


# ------------------------------------------------------------------ --set


def test_sets_override(tmp_path):
    path = write(tmp_path, "controller: {name: rac_dob}\ntrajectory: {displacement: [0.3, 0.0]}\n")
    sc = load_scenario(path, ["controller.name=rac", "trajectory.displacement=[0.2,0]", "plant.current=[0.1,0]",
                              "plant.overrides.base.volume=0.03", "controller.params.gamma=0.25",
                              "sensors.position_noise=1e-4", "duration=2"])
    assert sc.controller.name == "rac" and sc.controller.params == {"gamma": 0.25}
    assert sc.trajectory.displacement == [0.2, 0.0] and sc.plant.current == [0.1, 0.0]
    assert sc.plant.overrides == {"base.volume": 0.03}  # the rest of the path is one key
    assert sc.sensors.position_noise == 1e-4 and sc.duration == 2.0
    # target and displacement are alternatives: setting one removes the other
    sc = load_scenario(path, ["trajectory.target=[0.5,-0.4]"])
    assert sc.trajectory.target == [0.5, -0.4] and sc.trajectory.displacement is None
    # the file itself is not changed
    assert load_scenario(path).controller.name == "rac_dob"


@pytest.mark.parametrize("item, expected", [
    ("duration", "KEY.PATH=VALUE"),
    ("controller..name=rac", "KEY.PATH=VALUE"),
    ("duration=[1,", "not valid YAML"),
    ("duration.x=1", "duration: Input should be a valid number"),
    ("controller.name=rak", "did you mean 'rac'"),
])
def test_bad_sets(tmp_path, item, expected):
    path = write(tmp_path, "seed: 0\n")
    with pytest.raises(ScenarioError) as info:
        load_scenario(path, [item])
    assert expected in str(info.value) and item in str(info.value)


# ------------------------------------------------------------------ bad inputs


def test_unknown_key_with_did_you_mean(tmp_path):
    msg = error_of(tmp_path, "duraton: 10\nplant:\n  hydr: {drag: strip}\n")
    assert "duraton: unknown key 'duraton' (did you mean 'duration'?)" in msg
    assert "plant.hydr: unknown key 'hydr' (did you mean 'hydro'?); allowed: model_mismatch, overrides, hydro" in msg
    assert len(msg.splitlines()) == 2  # all errors, one line each
    msg = error_of(tmp_path, "controller:\n  params: {gama: 0.3}\n")
    assert "controller.params.gama" in msg and "did you mean 'gamma'" in msg
    msg = error_of(tmp_path, "plant:\n  overrides: {base.volum: 0.03}\n")
    assert "plant.overrides.base.volum" in msg and "unknown field 'volum' for body 'base' (did you mean 'volume'?)" in msg


def test_wrong_type(tmp_path):
    msg = error_of(tmp_path, "duration: forty\nwarm_start: 1\nplant:\n  current: 0.1\n")
    assert "duration: Input should be a valid number (got 'forty')" in msg
    assert "warm_start: Input should be a valid boolean (got 1)" in msg
    assert "plant.current: Input should be a valid list (got 0.1)" in msg
    msg = error_of(tmp_path, "trajectory: {displacement: [0.3]}\noutputs: {video_size: [640, 0]}\n")
    assert "trajectory.displacement" in msg and "at least 2 items" in msg
    assert "outputs.video_size[1]: must be an even number of pixels from 16 to 2160" in msg and "(got 0)" in msg


def test_out_of_range_gain_names_the_field_and_range(tmp_path):
    msg = error_of(tmp_path, "controller:\n  name: rac\n  params:\n    gamma: [0.3, 1.5, 0.2, 0.2, 0.2]\n")
    assert "controller.params.gamma" in msg and "(0, 1)" in msg and "1.5" in msg
    assert len(msg.splitlines()) == 1
    msg = error_of(tmp_path, "controller:\n  params: {lam: 0, js: -1}\n")
    assert "controller.params.lam" in msg and "controller.params.js" in msg
    msg = error_of(tmp_path, "controller:\n  params: {T: 0.01}\n")
    assert "controller.params.T" in msg and "whole multiple of physics.timestep" in msg


def test_both_target_and_displacement(tmp_path):
    msg = error_of(tmp_path, "trajectory:\n  target: [0.8, -0.4]\n  displacement: [0.3, 0.0]\n")
    assert "trajectory: give exactly one of target" in msg and "displacement" in msg


def test_non_finite_numbers(tmp_path):
    msg = error_of(tmp_path, "duration: .nan\nplant:\n  overrides: {base.volume: .nan}\n"
                             "controller:\n  params: {tf: .inf}\nsensors: {position_noise: -.inf}\n"
                             "current: {velocity: [.inf, 0]}\n")
    # (the robot's own checks of a section, e.g. its overrides, run once the section's fields are valid)
    for path in ("duration", "current.velocity[0]", "plant.overrides.base.volume", "controller.params.tf",
                 "sensors.position_noise"):
        assert any(line.split(": ")[1] == path and "finite" in line for line in msg.splitlines()), (path, msg)


def test_unknown_controller_lists_the_registered(tmp_path):
    msg = error_of(tmp_path, "controller:\n  name: lqr\n")
    assert "controller.name: unknown controller 'lqr'" in msg
    assert "registered: " + ", ".join(available()) in msg
    msg = error_of(tmp_path, "controller:\n  name: pd\n  params: {omgea: 3}\n")
    assert "'omgea' is not a parameter of controller 'pd' (did you mean 'omega'?)" in msg


def test_yaml_syntax_error_gives_line_and_column(tmp_path):
    msg = error_of(tmp_path, "name: x\nplant:\n  current: [0.1, 0\nseed: 1\n")
    assert "YAML syntax error" in msg and "line 4" in msg and ":4:" in msg
    msg = error_of(tmp_path, "seed: 1\nduration: 3\nseed: 2\n")
    assert "duplicate key 'seed'" in msg and "line 3" in msg
    msg = error_of(tmp_path, "name: x\n  bad: indent\n")
    assert "YAML syntax error" in msg and "line 2" in msg


def test_other_bad_inputs(tmp_path):
    with pytest.raises(ScenarioError, match="no such scenario file"):
        load_scenario(tmp_path / "missing.yaml")
    assert "must be a mapping" in error_of(tmp_path, "- a\n- b\n")
    msg = error_of(tmp_path, "plant:\n  overrides: {base.mass: -1, thrusters.tau: 0.1, link1.added_mass: [1, 2]}\n")
    assert "plant.overrides.base.mass: base.mass = -1.0 kg must be > 0" in msg
    assert "plant.overrides.thrusters.tau: set the plant's thrusters in the thrusters section (thrusters.tau)" in msg
    assert "plant.overrides.link1.added_mass" in msg and "3 value(s)" in msg
    msg = error_of(tmp_path, "thrusters: {force_range: [1, 16]}\nsensors: {delay: 2}\n"
                             "physics: {integrator: leapfrog}\n")
    assert "thrusters.force_range: must satisfy min < 0 < max" in msg
    assert "sensors.delay: Input should be less than or equal to 1 (got 2)" in msg
    assert "sensors.delay: Input should be a valid integer (got True)" in error_of(tmp_path, "sensors: {delay: true}\n")
    assert "physics.integrator: Input should be 'euler', 'rk4', 'implicit' or 'implicitfast'" in msg
    assert "name" in error_of(tmp_path, "name: 'two words'\n")
    assert isinstance(ScenarioError("x"), ValueError)


# ------------------------------------------------------------------ determinism, outputs


def test_determinism():
    sc = Scenario(duration=SHORT, seed=7, sensors={"position_noise": 1e-4, "angle_noise": 1e-4})
    a, b = run_scenario(sc), run_scenario(sc)
    assert_same_run(a, b)
    c = run_scenario(sc.model_copy(update={"seed": 8}))
    assert not np.array_equal(a.signals["q_measured"], c.signals["q_measured"])


def test_sink_and_progress_are_called():
    rows, progress = [], []
    res = run_scenario(Scenario(duration=0.5), sink=lambda t, row: rows.append((t, row)),
                       on_sample=lambda k, n: progress.append((k, n)))
    assert len(rows) == len(res.t) == len(progress) == 31
    assert rows[-1][0] == res.t[-1] and progress[-1] == (30, 31)
    assert res.meta["scenario"] == resolved(Scenario(duration=0.5)) and res.meta["T"] == 1 / 60


def test_plugin_controllers_are_validated_by_their_own_errors(monkeypatch):
    from uvms_mj.control import ControllerError, base

    class Toy(base.Controller):
        def __init__(self, trajectory, robot=None, T=1 / 60, gain=1.0, **extra):
            if not gain > 0:
                raise ControllerError(f"gain = {gain!r} must be > 0")
            self.T, self.extra = T, extra

        def reset(self, measurement):
            pass

        def compute(self, measurement):
            return base.Command(thrust=np.zeros(3), torques=np.zeros(2))

    monkeypatch.setitem(base._REGISTRY, "toy", Toy)
    sc = validate_scenario({"controller": {"name": "toy", "params": {"gain": 2.0, "anything": 1}}})
    assert build(sc)[1].extra == {"anything": 1}  # **kwargs: unknown keys are the controller's business
    with pytest.raises(ScenarioError, match=r"<scenario>: controller\.params\.gain: gain = -1 must be > 0"):
        validate_scenario({"controller": {"name": "toy", "params": {"gain": -1}}})
