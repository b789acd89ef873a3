"""The uvms-mj CLI end to end, and the observer comparison that CI prints."""

from pathlib import Path

import numpy as np
from click.testing import CliRunner

from uvms_mj.cli.main import main
from uvms_mj.sim.experiment import metrics
from uvms_mj.io.recorder import read_log

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"


def test_observer_comparison_on_the_paper_scenario(tmp_path, capsys):
    """`uvms-mj compare scenarios/paper.yaml`: rac vs rac_dob on the paper's experiment.

    Measured (40 s): base position RMS 0.091 -> 0.035 mm (ratio 0.39), base attitude RMS
    4.11 -> 1.19 mrad (0.29), end tip RMS 0.063 -> 0.025 mm (0.39). Asserted with a margin for
    platform differences: position and attitude ratios below 0.5, the tip not worse."""
    result = CliRunner().invoke(main, ["compare", str(SCENARIOS / "paper.yaml"), "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    with capsys.disabled():
        print("\n" + result.output)
    m = {c: metrics(read_log(tmp_path / f"paper-{c}.mcap")) for c in ("rac", "rac_dob")}
    ratio = {k: m["rac_dob"][k] / m["rac"][k] for k in ("base_pos_rms_mm", "base_att_rms_mrad", "tip_rms_mm")}
    assert ratio["base_pos_rms_mm"] < 0.5, ratio
    assert ratio["base_att_rms_mrad"] < 0.5, ratio
    assert ratio["tip_rms_mm"] <= 1.0, ratio
    assert m["rac"]["saturated_s"] == 0 and m["rac_dob"]["saturated_s"] == 0
    assert (tmp_path / "paper-compare.png").stat().st_size > 10_000
    assert "ratio" in result.output and "base attitude RMS" in result.output


def test_run_writes_log_plots_and_reports_divergence(tmp_path):
    out = tmp_path / "slow.mcap"
    result = CliRunner().invoke(main, ["run", str(SCENARIOS / "slow_thrusters.yaml"), "--out", str(out),
                                       "--set", "duration=12"])
    assert result.exit_code == 3, result.output  # diverged: the paper's gains with a 0.1 s lag
    assert "diverged at t =" in result.output
    log = read_log(out)
    assert log.status == "diverged" and "diverged" in log.reason and not log.truncated
    assert 7.0 < log.t[-1] < 12.0
    assert list(tmp_path.glob("slow*.png"))  # plots of the partial run


def test_run_ok_and_info(tmp_path):
    out = tmp_path / "p.mcap"
    runner = CliRunner()
    result = runner.invoke(main, ["run", str(SCENARIOS / "paper.yaml"), "--out", str(out), "--no-plots",
                                  "--set", "duration=2", "--set", "controller.name=rac"])
    assert result.exit_code == 0, result.output
    log = read_log(out)
    assert log.status == "ok" and len(log.t) == 121 and np.all(np.isfinite(log.signals["q_true"]))
    info = runner.invoke(main, ["info", str(out)])
    assert info.exit_code == 0 and "/tf" in info.output and "foxglove.FrameTransforms" in info.output


def test_bad_input_exits_2_with_a_message(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("controller:\n  name: rac\n  params:\n    gamma: [1.5, 0.3, 0.2, 0.2, 0.2]\n")
    runner = CliRunner()
    result = runner.invoke(main, ["run", str(bad), "--out", str(tmp_path / "x.mcap")])
    assert result.exit_code == 2
    assert "controller.params.gamma" in result.output and "(0, 1)" in result.output
    assert not (tmp_path / "x.mcap").exists()  # no half-written output
    result = runner.invoke(main, ["compare", str(SCENARIOS / "paper.yaml"), "--controllers", "rac,nope"])
    assert result.exit_code == 2 and "registered:" in result.output
    result = runner.invoke(main, ["validate", str(SCENARIOS / "paper.yaml")])
    assert result.exit_code == 0 and "ok" in result.output


def test_sigterm_closes_the_log_cleanly(tmp_path):
    """SIGTERM during `uvms-mj run`: exit 130, and the log is complete (normal reader) with
    status 'interrupted' and the samples up to then."""
    import signal
    import subprocess
    import sys
    import time

    out = tmp_path / "long.mcap"
    proc = subprocess.Popen(
        [sys.executable, "-m", "uvms_mj.cli.main", "run", str(SCENARIOS / "paper.yaml"), "--out", str(out),
         "--no-plots", "--set", "duration=600"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    deadline = time.time() + 60
    while not (out.exists() and out.stat().st_size > 20_000) and time.time() < deadline:
        time.sleep(0.1)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "closed cleanly" in err and "Traceback" not in err
    log = read_log(out)
    assert not log.truncated and log.status == "interrupted"
    assert 1.0 < log.t[-1] < 600.0


def test_bad_log_files_exit_2(tmp_path):
    bad = tmp_path / "bad.mcap"
    bad.write_text("not a log")
    for cmd in ("info", "render", "plot"):
        result = CliRunner().invoke(main, [cmd, str(bad)])
        assert result.exit_code == 2, (cmd, result.output)
        assert "not a readable uvms-mj MCAP log" in result.output
