"""CLI: export, --json, scenarios by name, output-option spellings, help, info, drift --set."""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest
from click.testing import CliRunner

from uvms_mj.cli.main import main, packaged_scenarios
from uvms_mj.io.recorder import read_log


@pytest.fixture(scope="module")
def short_log(tmp_path_factory):
    out = tmp_path_factory.mktemp("cli") / "p.mcap"
    # `paper` is not a file here: the packaged scenario
    result = CliRunner().invoke(main, ["run", "paper", "-o", str(out), "--no-plots", "--set", "duration=0.5"])
    assert result.exit_code == 0, result.output
    return out


def test_scenarios_run_by_name(short_log):
    assert {"paper", "current", "mismatch"} <= set(packaged_scenarios())
    assert read_log(short_log).meta["scenario"]["name"] == "paper"
    runner = CliRunner()
    result = runner.invoke(main, ["validate", "current"])
    assert result.exit_code == 0 and "ok (current" in result.output
    result = runner.invoke(main, ["validate", "no_such_scenario"])
    assert result.exit_code == 2 and "nor a packaged scenario" in result.output and "paper" in result.output
    result = runner.invoke(main, ["validate", "--list"])
    assert result.exit_code == 0 and "paper" in result.output


def test_json_metrics_on_stdout_and_to_a_file(tmp_path):
    runner = CliRunner()
    result = runner.invoke(main, ["compare", "paper", "--out-dir", str(tmp_path), "--set", "duration=0.5",
                                  "--json", "-"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)  # nothing but JSON on stdout
    assert data["scenario"] == "paper" and set(data["runs"]) == {"rac", "rac_dob"}
    assert data["runs"]["rac"]["status"] == "ok"
    m = data["runs"]["rac_dob"]["metrics"]
    assert m["tip_rms_mm"] > 0
    assert data["ratio"]["metrics"]["tip_rms_mm"] == pytest.approx(
        m["tip_rms_mm"] / data["runs"]["rac"]["metrics"]["tip_rms_mm"])
    assert "status" in result.stderr and "ratio" in result.stderr  # the table went to stderr
    js = tmp_path / "m.json"
    result = runner.invoke(main, ["run", "paper", "-o", str(tmp_path / "r.mcap"), "--no-plots",
                                  "--set", "duration=0.5", "--json", str(js)])
    assert result.exit_code == 0 and "end tip RMS" in result.stdout
    assert json.loads(js.read_text())["runs"]["rac_dob"]["log"] == str(tmp_path / "r.mcap")


def test_compare_diverged_has_a_status_row(tmp_path):
    result = CliRunner().invoke(main, ["compare", "slow_thrusters", "--controllers", "rac",
                                       "--out", str(tmp_path), "--set", "duration=12"])  # --out: old spelling
    assert result.exit_code == 3, result.output
    row = [line for line in result.output.splitlines() if line.startswith("status")]
    assert row and "diverged" in row[0]
    assert (tmp_path / "slow_thrusters-rac.mcap").exists()


@pytest.mark.parametrize("fmt", ["csv", "npz", "parquet", "mat"])
def test_export_wide(short_log, tmp_path, fmt):
    if fmt == "parquet":
        pytest.importorskip("pyarrow")
    if fmt == "mat":
        pytest.importorskip("scipy")
    out = tmp_path / f"x.{fmt}"
    result = CliRunner().invoke(main, ["export", str(short_log), "--format", fmt, "-o", str(out)])
    assert result.exit_code == 0, result.output
    log = read_log(short_log)
    q = log.signals["q_true"]
    if fmt == "csv":
        header = out.read_text().splitlines()[0].split(",")
        data = np.loadtxt(out, delimiter=",", skiprows=1)
        assert header[:3] == ["t", "q_true[base_x]", "q_true[base_y]"]  # named (tests/test_export_names.py)
        np.testing.assert_array_equal(data[:, 0], log.t)
        np.testing.assert_array_equal(data[:, header.index("q_true[joint2]")], q[:, 4])
        assert "e_p[tip_x]" in header and len(data) == len(log.t)
    elif fmt == "npz":
        z = np.load(out)
        np.testing.assert_array_equal(z["q_true"], q)
        assert json.loads(str(z["meta_json"]))["status"] == "ok"
    elif fmt == "parquet":
        import pyarrow.parquet as pq

        table = pq.read_table(out)
        np.testing.assert_array_equal(table.column("q_true[base_yaw]").to_numpy(), q[:, 2])
    else:
        import scipy.io

        mat = scipy.io.loadmat(out)
        np.testing.assert_array_equal(mat["q_true"], q)
        np.testing.assert_array_equal(mat["t"].ravel(), log.t)


def test_export_channels_layout(short_log, tmp_path):
    result = CliRunner().invoke(main, ["export", str(short_log), "--layout", "channels", "-o", str(tmp_path / "d")])
    assert result.exit_code == 0, result.output
    state = (tmp_path / "d" / "state_true.csv").read_text().splitlines()[0].split(",")
    control = (tmp_path / "d" / "control.csv").read_text().splitlines()[0].split(",")
    assert state[0] == control[0] == "t" and "q_true[base_x]" in state and "q_true[base_x]" not in control
    assert "e_p[base_x]" in control
    result = CliRunner().invoke(main, ["export", str(short_log), "--layout", "channels", "--columns", "index",
                                       "-o", str(tmp_path / "i")])
    assert result.exit_code == 0, result.output
    state = (tmp_path / "i" / "state_true.csv").read_text().splitlines()[0].split(",")
    assert state[:3] == ["t", "q_true[0]", "q_true[1]"]


@pytest.mark.parametrize("fmt, module", [("parquet", "pyarrow"), ("mat", "scipy.io")])
def test_export_missing_dependency_one_line_exit_2(short_log, tmp_path, monkeypatch, fmt, module):
    monkeypatch.setitem(sys.modules, module, None)  # import fails
    if module == "pyarrow":
        monkeypatch.setitem(sys.modules, "pyarrow.parquet", None)
    result = CliRunner().invoke(main, ["export", str(short_log), "--format", fmt, "-o", str(tmp_path / "x")])
    assert result.exit_code == 2
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and "pip install 'uvms-mj[export]'" in lines[0]


def test_help_and_info(short_log):
    runner = CliRunner()
    top = runner.invoke(main, ["-h"]).output
    assert "(Figs. 5 and 6)" in top and "(Figs.\n" not in top
    info = runner.invoke(main, ["info", str(short_log)])
    assert info.exit_code == 0
    lines = info.output.splitlines()
    assert "  scenario:" in lines  # the resolved scenario as indented YAML, not one line
    assert any(line.strip() == "name: paper" for line in lines)
    assert max(len(line) for line in lines) < 140
    assert "..." not in info.output


def test_output_option_spellings(short_log, tmp_path):
    runner = CliRunner()
    result = runner.invoke(main, ["plot", str(short_log), "-o", str(tmp_path / "b")])  # old spelling, hidden
    assert result.exit_code == 0, result.output
    assert list((tmp_path / "b").glob("*.png"))
    helps = {c: runner.invoke(main, [c, "-h"]).output for c in ("run", "compare", "render", "plot", "sweep")}
    assert "-o, --out" in helps["run"] and "-o, --out" in helps["render"]
    assert "--output" not in helps["render"]
    for c in ("compare", "plot", "sweep"):
        assert "--out-dir" in helps[c] and "--out " not in helps[c].replace("--out-dir", ""), c


def test_drift_set_parses_yaml_like_run():
    runner = CliRunner()
    a = runner.invoke(main, ["drift", "--seconds", "1", "--set", "link1.added_mass=[1.3, 3.6, 0.11]"])
    b = runner.invoke(main, ["drift", "--seconds", "1", "--set", "link1.added_mass=1.3,3.6,0.11"])  # old form
    c = runner.invoke(main, ["drift", "--seconds", "1"])
    assert a.exit_code == b.exit_code == c.exit_code == 0, a.output + b.output
    assert a.output == b.output != c.output
    bad = runner.invoke(main, ["drift", "--set", "base.volume=[1, x]"])
    assert bad.exit_code == 2 and "number or a list of numbers" in bad.output


def test_render_arguments(short_log, tmp_path):
    runner = CliRunner()
    two = runner.invoke(main, ["render", str(short_log), str(short_log)])  # two logs need --compare
    assert two.exit_code == 2 and "--compare" in two.output
    one = runner.invoke(main, ["render", "--compare", str(short_log)])
    assert one.exit_code == 2
    out = tmp_path / "ab.mp4"
    ok = runner.invoke(main, ["render", "--compare", str(short_log), str(short_log), "-o", str(out),
                              "--size", "160", "96", "--fps", "4"])
    assert ok.exit_code == 0, ok.output
    assert out.stat().st_size > 1000 and "video:" in ok.output
    old = runner.invoke(main, ["render", str(short_log), "--output", str(tmp_path / "a.mp4"),  # hidden alias
                               "--size", "160", "96", "--fps", "4"])
    assert old.exit_code == 0 and (tmp_path / "a.mp4").is_file(), old.output


def test_sweep_by_name(tmp_path):
    result = CliRunner().invoke(main, ["sweep", "paper", "--vary", "plant.current[0]=[0, 0.05]", "--engine", "serial",
                                       "--controllers", "rac", "--set", "duration=0.3",
                                       "--out-dir", str(tmp_path / "sw")])
    assert result.exit_code == 0, result.output
    assert (tmp_path / "sw" / "results.csv").is_file()
