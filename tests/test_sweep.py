"""Parameter sweeps (uvms_mj.analysis.sweep, `uvms-mj sweep`): spec parsing, reproducible sampling,
parallel runs with a results table and figures, resume, failures, the Ray engine."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from uvms_mj.analysis import sweep as sw
from uvms_mj.cli.main import main
from uvms_mj.analysis.sweep import Grid, Random, Scale, SweepError, Vector, parse_spec, parse_vary, plan_sweep, run_sweep

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"
PAPER = str(SCENARIOS / "paper.yaml")


# ------------------------------------------------------------------ specs


def test_spec_forms():
    assert parse_spec("[0, 0.05, 0.1]") == Grid((0, 0.05, 0.1))
    g = parse_spec("linspace(0, 0.1, 5)")
    assert isinstance(g, Grid) and np.allclose(g.values, [0, 0.025, 0.05, 0.075, 0.1]) and len(g.values) == 5
    assert parse_spec("uniform(0, 0.1)") == Random("uniform", (0.0, 0.1))
    assert parse_spec("loguniform(1e-3, 1)") == Random("loguniform", (1e-3, 1.0))
    assert parse_spec("normal(0, 0.01)") == Random("normal", (0.0, 0.01))
    assert parse_spec("choice(strip, mujoco, 'a b')") == Random("choice", ("strip", "mujoco", "a b"))
    assert parse_spec("choice(0.02, 0.05)") == Random("choice", (0.02, 0.05))
    assert parse_spec("choice(strip, mujoco, off)") == Random("choice", ("strip", "mujoco", "off"))  # not False
    assert parse_spec("scale(uniform(0.7, 1.3))") == Scale(Random("uniform", (0.7, 1.3)))
    assert parse_spec("scale([0.7, 1, 1.3])") == Scale(Grid((0.7, 1, 1.3)))
    assert parse_spec("[uniform(0, 0.1), 0]") == Vector((Random("uniform", (0.0, 0.1)), 0))
    assert parse_spec("[[0, 0], [0.1, 0]]") == Grid(([0, 0], [0.1, 0]))
    assert parse_spec("0.1") == Grid((0.1,))
    assert parse_spec("[true, false]") == Grid((True, False))
    # the canonical text (stored in the sweep definition) parses back to the same spec
    for text in ("linspace(0, 0.1, 5)", "[uniform(0, 0.1), 0]", "scale(choice(0.5, 2))", "choice(a, b)"):
        assert parse_spec(str(parse_spec(text))) == parse_spec(text)


@pytest.mark.parametrize("text, message", [
    ("uniform(0.1, 0)", "empty range: low must be < high"),
    ("uniform(0, 0)", "empty range"),
    ("linspace(0, 0.1, 0)", "empty range: n must be >= 1"),
    ("linspace(0, 0, 3)", "empty range: start == stop"),
    ("linspace(0, 1, 2.5)", "n must be a whole number"),
    ("uniform(0, inf)", "high must be finite"),
    ("normal(nan, 1)", "mean must be finite"),
    ("[0, .inf]", "must be finite"),
    ("normal(0, 0)", "std must be > 0"),
    ("loguniform(0, 1)", "low must be > 0"),
    ("unifrom(0, 1)", "unknown function 'unifrom' (did you mean 'uniform'?)"),
    ("uniform(0, 1, 2)", "uniform(low, high) takes 2 argument(s), got 3"),
    ("uniform(0", "expected ')'"),
    ("uniform(0, 1) x", "unexpected 'x'"),
    ("uniform(a, 1)", "low must be a number (got 'a')"),
    ("[]", "empty grid"),
    ("choice()", "give at least one value"),
    ("", "empty spec"),
    ("scale(scale(uniform(1, 2)))", "SPEC must be a grid or a distribution of factors"),
    ("scale(choice(a, b))", "the factors must be numbers"),
    ("[1, [uniform(0, 1)]]", "a grid's values must be plain values"),
])
def test_bad_specs_name_the_problem(text, message):
    with pytest.raises(SweepError) as exc:
        parse_spec(text)
    assert message in str(exc.value) and repr(text) in str(exc.value)


@pytest.mark.parametrize("item, message", [
    ("plant.curent[0]=uniform(0, 0.1)", "unknown key 'curent' in plant (did you mean 'current'?)"),
    ("nominal.overrides.base.addedmass=scale(uniform(0.7, 1.3))", "did you mean 'base.added_mass'?"),
    ("controller.params.gama=[0.1]", "'gama' is not a parameter of controller 'rac' (did you mean 'gamma'?)"),
    ("plant.overrides.thrusters.tau=[0.1]", "in the thrusters section (thrusters.tau)"),
    ("seed=[1, 2]", "seed cannot be varied"),
    ("controller.name=choice(rac, pd)", "choose the controllers with --controllers"),
    ("outputs.log=[a]", "outputs cannot be varied"),
    ("plant=[1]", "plant is a section; vary one of its fields"),
    ("thrusters.tau.x=[1]", "thrusters.tau is a value, not a section"),
    ("thrusters.tau", "expected KEY.PATH=SPEC"),
    ("plant.current[x]=[1]", "the component index must be a whole number"),
    ("plant.current[0]=[uniform(0, 1), 0]", "sets the whole field"),
])
def test_bad_keys_name_the_problem(item, message):
    with pytest.raises(SweepError) as exc:
        parse_vary(item)
    assert message in str(exc.value), str(exc.value)
    assert item.partition("=")[0] in str(exc.value)


@pytest.mark.parametrize("vary, message", [
    (["plant.current[2]=[0.1]"], "index 2 out of range: plant.current has 2 components"),
    (["plant.current=uniform(0, 0.1)"], "plant.current is a vector of 2"),
    (["plant.current=[0, 0.1]"], "plant.current is a vector of 2"),
    (["plant.current=[uniform(0, 0.1), 0, 1]"], "plant.current has 2 components, the spec gives 3"),
    (["trajectory.target=scale([1, 2])"], "trajectory.target is null in the scenario"),
    (["plant.current[0]=[0, 0.1]", "plant.current=[[0, 0]]"], "plant.current is varied twice"),
    (["thrusters.tau=uniform(0.02, 0.05)"], "need --n N"),
    (["thrusters.tau=normal(0.02, 0.05)"], "thrusters.tau: Input should be greater than"),
    (["sensors.delay=[0, 2]"], "sensors.delay"),
])
def test_plan_rejects_bad_values_before_any_run(vary, message):
    n = 20 if any("normal" in v for v in vary) else None
    with pytest.raises(SweepError) as exc:
        plan_sweep(PAPER, vary, n=n, sets=["duration=1"])
    assert message in str(exc.value), str(exc.value)


def test_unknown_controller():
    with pytest.raises(SweepError, match=r"unknown controller\(s\) racdob \(did you mean 'rac_dob'\?\)"):
        plan_sweep(PAPER, ["thrusters.tau=[0.02]"], controllers="rac,racdob")


# ------------------------------------------------------------------ sampling


def test_sampling_is_reproducible_and_paired():
    vary = ["plant.current[0]=uniform(0, 0.1)", "thrusters.tau=[0.02, 0.03]",
            "nominal.overrides.{base,link1,link2}.added_mass=scale(uniform(0.7, 1.3))"]
    a = sw.sample_parameters(vary, n=3, seed=7)
    assert a == sw.sample_parameters(vary, n=3, seed=7)
    assert a != sw.sample_parameters(vary, n=3, seed=8)
    # grid x n: the grid point is constant over each block of n samples, the last grid varies fastest
    assert len(a) == 6 and [s["thrusters.tau"] for s in a] == [0.02] * 3 + [0.03] * 3
    cur = [s["plant.current[0]"] for s in a]
    assert len(set(cur)) == 6 and all(0 <= c < 0.1 for c in cur)
    # sample i's draws depend only on (seed, i): a longer sweep starts with the same samples
    longer = sw.sample_parameters(["plant.current[0]=uniform(0, 0.1)"], n=10, seed=7)
    shorter = sw.sample_parameters(["plant.current[0]=uniform(0, 0.1)"], n=4, seed=7)
    assert longer[:4] == shorter

    plan = plan_sweep(PAPER, vary, n=3, seed=7, sets=["duration=1"])
    again = plan_sweep(PAPER, vary, n=3, seed=7, sets=["duration=1"])
    assert [(r.run_id, r.seed, r.key, r.values) for r in plan.runs] == \
        [(r.run_id, r.seed, r.key, r.values) for r in again.runs]
    assert len(plan.runs) == 12 and len({r.key for r in plan.runs}) == 12
    for rac, dob in zip(plan.runs[0::2], plan.runs[1::2]):  # paired: same sample, parameters and seed
        assert (rac.controller, dob.controller) == ("rac", "rac_dob")
        assert rac.sample == dob.sample and rac.seed == dob.seed and rac.values == dob.values
        assert rac.scenario["seed"] == rac.seed
    assert len({r.seed for r in plan.runs}) == 6
    # scale: a factor on the model file's value (nominal added mass: base 72.7 6.28 1.05), shared
    s0 = plan.runs[0]
    f = s0.draws["scale(nominal.overrides.{base,link1,link2}.added_mass)"]
    assert 0.7 <= f < 1.3
    assert np.allclose(s0.values["nominal.overrides.base.added_mass"], np.multiply(f, [72.7, 6.28, 1.05]))
    assert np.allclose(s0.values["nominal.overrides.link1.added_mass"], np.multiply(f, [1.31, 3.57, 0.11]))
    # KEY[i]: the other component keeps the scenario's value
    assert s0.values["plant.current"] == [s0.draws["plant.current[0]"], 0.0]
    # the run's --set arguments reproduce it with `uvms-mj run`
    from uvms_mj.scenario.schema import load_scenario, resolved

    sc = load_scenario(PAPER, s0.sets)
    assert sw.plan._run_key(resolved(sc)) == s0.key


def test_scale_is_relative_to_the_scenario_value():
    # mismatch.yaml already sets the nominal added mass to x1.3: scale multiplies that
    plan = plan_sweep(str(SCENARIOS / "mismatch.yaml"), ["nominal.overrides.base.added_mass=scale([0.5])"],
                      controllers="rac_dob", sets=["duration=1"])
    assert np.allclose(plan.runs[0].values["nominal.overrides.base.added_mass"], [47.255, 4.082, 0.6825])
    # a vector given per component, a grid of one component
    plan = plan_sweep(PAPER, ["plant.current=[0.05, linspace(-0.02, 0.02, 3)]"], controllers="rac",
                      sets=["duration=1"])
    assert [r.values["plant.current"] for r in plan.runs] == [[0.05, -0.02], [0.05, 0.0], [0.05, 0.02]]
    assert [a.column for a in plan.axes] == ["plant.current[1]"]



def test_model_file_robot_overrides_are_swept_by_element_name():
    # A model-file robot's overrides are "<element>.<field>" (not the paper's parameter names);
    # scale of one the file does not give is a factor of the model's own value ("xF"), which the
    # run's nominal model applies: its hydro plugin's added mass = F x the model file's numbers
    # (models/bluerov2_heavy/bluerov2_heavy_hull.xml: 6.36 7.12 18.68 0.189 0.135 0.222).
    from uvms_mj.physics.model import body_config, load_spec
    from uvms_mj.plant.files import nominal_model_path
    from uvms_mj.plant.robot import apply_overrides

    key = "nominal.overrides.bluerov2_hull.added_mass"
    plan = plan_sweep(str(SCENARIOS / "bluerov2_alpha_sweep.yaml"), [f"{key}=scale([0.7, 1.3])"],
                      controllers="rac", sets=["duration=1"])
    assert [r.values[key] for r in plan.runs] == ["x0.7", "x1.3"]
    spec = load_spec(nominal_model_path("bluerov2_alpha"))
    apply_overrides(spec, {"bluerov2_hull.added_mass": plan.runs[1].values[key]})
    got = [float(v) for v in body_config(spec, "bluerov2_hull")["added_mass"].split()]
    assert np.allclose(got, 1.3 * np.array([6.36, 7.12, 18.68, 0.189, 0.135, 0.222]), rtol=1e-12)
    with pytest.raises(SweepError, match="<element>.<field>"):
        parse_vary("nominal.overrides.added_mass=[1]", ["rac"], robot="bluerov2_alpha")
    with pytest.raises(SweepError, match="no_such_body"):  # an unknown element: named before any run
        plan_sweep(str(SCENARIOS / "bluerov2_alpha_sweep.yaml"), ["nominal.overrides.no_such_body.mass=[1]"],
                   controllers="rac", sets=["duration=1"])


# ------------------------------------------------------------------ running


def _rows(path: Path) -> list[dict]:
    return sw.read_results(path)


@pytest.mark.slow
def test_local_sweep_table_figures_and_resume(tmp_path):
    """4 samples x 2 controllers on 2 worker processes; the rerun skips all 8 runs."""
    out = tmp_path / "sweep"
    args = ["sweep", PAPER, "--vary", "plant.current[0]=uniform(0, 0.1)",
            "--vary", "nominal.overrides.{base,link1,link2}.added_mass=scale(uniform(0.7, 1.3))",
            "--n", "4", "--workers", "2", "--set", "duration=3", "--seed", "3", "--out", str(out)]
    runner = CliRunner()
    first = runner.invoke(main, args)
    assert first.exit_code == 0, first.output
    assert "ran 8 runs" in first.output and "paired ratio rac_dob/rac (4 pairs" in first.output
    rows = _rows(out)
    assert len(rows) == 8
    assert [r["controller"] for r in rows] == ["rac", "rac_dob"] * 4
    assert [r["sample"] for r in rows] == [0, 0, 1, 1, 2, 2, 3, 3]
    assert all(r["status"] == "ok" and r["reason"] == "" and r["t_end"] == pytest.approx(3.0) for r in rows)
    for col in ("run_id", "seed", "plant.current[0]", "scale(nominal.overrides.{base,link1,link2}.added_mass)",
                "base_pos_rms_mm", "base_att_rms_mrad", "tip_rms_mm", "thrust_rms_N", "saturated_s", "wall_s", "log",
                "values", "sets", "key"):
        assert col in rows[0], col
    assert all(math.isfinite(r["base_pos_rms_mm"]) and r["base_pos_rms_mm"] > 0 for r in rows)
    assert all(r["wall_s"] > 0 and r["log"] == "" for r in rows)
    # the table's parameters are exactly the planned (reproducible) ones
    plan = plan_sweep(PAPER, [args[3], args[5]], n=4, seed=3, sets=["duration=3"])
    assert [r["key"] for r in rows] == [r.key for r in plan.runs]
    assert [r["plant.current[0]"] for r in rows] == [r.draws["plant.current[0]"] for r in plan.runs]
    for name in ("sweep_metrics.png", "sweep_ratio.png"):
        assert (out / name).stat().st_size > 20_000
    summary = json.loads((out / "summary.json").read_text())
    assert summary["ratios"]["rac_dob/rac"]["pairs"] == 4 and summary["controllers"]["rac"]["ok"] == 4

    second = runner.invoke(main, args)
    assert second.exit_code == 0, second.output
    assert "resumed: 8 of 8 runs already done, skipped" in second.output and "ran " not in second.output
    assert len((out / "runs.jsonl").read_text().splitlines()) == 8  # nothing ran again
    # the same table (compared as JSON text: a metric a run does not have is NaN, and NaN != NaN)
    assert json.dumps(_rows(out), sort_keys=True) == json.dumps(rows, sort_keys=True)

    changed = runner.invoke(main, args[:-2] + ["--seed", "4", "--out", str(out)])
    assert changed.exit_code == 2
    assert "holds a different sweep" in changed.output and "seed: 3 -> 4" in changed.output
    assert "Traceback" not in changed.output


def test_resume_runs_only_missing_runs_and_fresh(tmp_path):
    plan = plan_sweep(PAPER, ["thrusters.tau=[0.02, 0.03]"], sets=["duration=0.5"])
    out = tmp_path / "s"
    first = run_sweep(plan, out, engine="serial", figures=False)
    assert (first.planned, first.skipped, first.ran) == (4, 0, 4)
    lines = (out / "runs.jsonl").read_text().splitlines()
    (out / "runs.jsonl").write_text("\n".join(lines[:2]) + "\n" + lines[2][:40])  # cut, as by a kill
    second = run_sweep(plan, out, engine="serial", figures=False)
    assert (second.skipped, second.ran) == (2, 2)
    assert [r["run_id"] for r in second.rows] == [r.run_id for r in plan.runs]
    other = plan_sweep(PAPER, ["thrusters.tau=[0.02]"], sets=["duration=0.5"])
    with pytest.raises(SweepError, match="holds a different sweep; differs: vary"):
        run_sweep(other, out, engine="serial", figures=False)
    fresh = run_sweep(other, out, engine="serial", figures=False, fresh=True)
    assert (fresh.skipped, fresh.ran, len(fresh.rows)) == (0, 2, 2)


def test_failures_are_recorded_and_never_stop_the_sweep(tmp_path):
    """The paper's gains with slow thrusters (0.1 s) diverge; a run that raises is recorded."""
    plan = plan_sweep(PAPER, ["thrusters.tau=[0.1, 0.02]"], controllers="rac", sets=["duration=10"])
    out = run_sweep(plan, tmp_path / "p", workers=2)
    by = {r["thrusters.tau"]: r for r in out.rows}
    assert by[0.1]["status"] == "diverged" and "diverged at t =" in by[0.1]["reason"]
    assert 7.0 < by[0.1]["t_end"] < 10.0
    assert by[0.02]["status"] == "ok" and by[0.02]["t_end"] == pytest.approx(10.0)
    assert out.summary["controllers"]["rac"]["failed"] == 1
    assert out.summary["failures"][0]["run_id"] == by[0.1]["run_id"]
    assert (tmp_path / "p" / "sweep_metrics.png").exists()
    rows = _rows(tmp_path / "p")
    assert {r["status"] for r in rows} == {"ok", "diverged"}


def test_a_run_that_raises_is_recorded(tmp_path, monkeypatch):
    real = sw.engines._run_scenario

    def flaky(scenario, sink=None, **kw):
        if scenario.thrusters.tau > 0.025:
            raise RuntimeError("boom in the plant")
        return real(scenario, sink=sink, **kw)

    monkeypatch.setattr(sw.engines, "_run_scenario", flaky)
    plan = plan_sweep(PAPER, ["thrusters.tau=[0.02, 0.03, 0.021]"], controllers="rac", sets=["duration=0.5"])
    out = run_sweep(plan, tmp_path / "e", engine="serial")
    assert [r["status"] for r in out.rows] == ["ok", "error", "ok"]
    assert out.rows[1]["reason"] == "RuntimeError: boom in the plant"
    assert math.isnan(out.rows[1]["base_pos_rms_mm"])
    # an error is a finished run: not retried on resume
    assert run_sweep(plan, tmp_path / "e", engine="serial").ran == 0


def test_cli_bad_input_exits_2_before_any_run(tmp_path):
    runner = CliRunner()
    cases = [
        (["--vary", "plant.current[0]=unifrom(0, 0.1)", "--n", "2"], "unknown function 'unifrom'"),
        (["--vary", "plant.curent[0]=uniform(0, 0.1)", "--n", "2"], "did you mean 'current'?"),
        (["--vary", "plant.current[0]=uniform(0.1, 0.1)", "--n", "2"], "empty range"),
        (["--vary", "plant.current[0]=uniform(0, inf)", "--n", "2"], "must be finite"),
        (["--vary", "thrusters.tau=[0.02]", "--controllers", "rac,lqr"], "unknown controller(s) lqr"),
        (["--vary", "thrusters.tau=uniform(0.02, 0.03)"], "need --n N"),
    ]
    for extra, message in cases:
        out = tmp_path / "never"
        res = runner.invoke(main, ["sweep", PAPER, "--out", str(out)] + extra)
        assert res.exit_code == 2, (extra, res.output)
        assert message in res.output, (extra, res.output)
        assert "Traceback" not in res.output
        assert not out.exists()


def test_missing_ray_says_how_to_install(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` raises ImportError
    res = CliRunner().invoke(main, ["sweep", PAPER, "--vary", "thrusters.tau=[0.02]", "--engine", "ray",
                                    "--out", str(tmp_path / "r")])
    assert res.exit_code == 2, res.output
    assert "pip install 'uvms-mj[ray]'" in res.output and "Traceback" not in res.output
    assert not (tmp_path / "r").exists()
    with pytest.raises(SweepError, match=r"pip install 'uvms-mj\[ray\]'"):
        sw.check_engine("ray")


@pytest.mark.slow
def test_ray_engine_on_a_local_cluster(tmp_path):
    ray = pytest.importorskip("ray")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        plan = plan_sweep(PAPER, ["plant.current[0]=[0, 0.1]", "thrusters.tau=[0.02, 0.1]"], controllers="rac",
                          sets=["duration=10"])
        out = run_sweep(plan, tmp_path / "ray", engine="ray")
        assert ray.is_initialized()  # a cluster the caller started is left running
    finally:
        ray.shutdown()
    assert out.ran == 4 and len(out.rows) == 4
    assert out.rows[0]["status"] == "ok" and out.rows[1]["status"] == "diverged"  # no current: tau 0.1 diverges
    # same numbers as the local process pool
    local = run_sweep(plan_sweep(PAPER, ["plant.current[0]=[0, 0.1]", "thrusters.tau=[0.02, 0.1]"],
                                 controllers="rac", sets=["duration=10"]), tmp_path / "local", workers=2)
    for a, b in zip(out.rows, local.rows):
        assert a["key"] == b["key"] and a["status"] == b["status"] and a["base_pos_rms_mm"] == b["base_pos_rms_mm"]


@pytest.mark.slow
def test_sigterm_keeps_finished_runs_for_resume(tmp_path):
    """SIGTERM mid-sweep: exit 130, the finished runs are in runs.jsonl and results.csv, and a
    rerun would skip exactly them."""
    import signal
    import subprocess
    import time

    out = tmp_path / "t"
    vary = ["plant.current[0]=uniform(0, 0.1)"]
    cmd = [sys.executable, "-m", "uvms_mj.cli.main", "sweep", PAPER, "--vary", vary[0], "--n", "20", "--workers", "2",
           "--out", str(out)]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and proc.poll() is None:
            record = out / "runs.jsonl"
            if record.exists() and len(record.read_text().splitlines()) >= 2:
                break
            time.sleep(0.02)
        assert proc.poll() is None, "the sweep finished before it could be interrupted"
        proc.send_signal(signal.SIGTERM)
        output, _ = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, output
    assert "interrupted" in output and "Traceback" not in output
    done = [json.loads(line) for line in (out / "runs.jsonl").read_text().splitlines()]
    assert 2 <= len(done) < 40
    assert len(_rows(out)) == len(done)
    plan = plan_sweep(PAPER, vary, n=20)
    finished = sw.prepare_out(plan, out)
    assert set(finished) == {r["key"] for r in done}


def test_summary_counts_failures_where_another_held_and_per_value():
    # Hand-made rows, counted by hand: sample 1 has rac_dob diverged while station_pid held,
    # sample 2 both diverged (not counted as "where another held").
    from uvms_mj.analysis.sweep.summary import format_summary, summarize

    statuses = [(0, "ok", "ok"), (1, "ok", "diverged"), (1, "diverged", "diverged")]
    rows = [{"sample": i, "controller": c, "status": st, "delay": d, "run_id": f"s{i}-{c}", "reason": "",
             "base_pos_rms_mm": 1.0, "base_att_rms_mrad": 1.0, "tip_rms_mm": 1.0}
            for i, (d, *sts) in enumerate(statuses) for c, st in zip(("station_pid", "rac_dob"), sts)]
    s = summarize(rows, ["station_pid", "rac_dob"], ["delay"])
    assert s["failed_where_held"] == {"station_pid": {"rac_dob": 0}, "rac_dob": {"station_pid": 1}}
    assert s["by_column"]["delay"] == {"0": {"station_pid": [0, 1], "rac_dob": [0, 1]},
                                       "1": {"station_pid": [1, 2], "rac_dob": [2, 2]}}
    text = format_summary(s)
    assert "rac_dob where station_pid held 1" in text and "1: station_pid 1/2, rac_dob 2/2" in text
