"""A quick CLI (issue 22 item 7), structurally (wall times are measured by benchmarks/bench_cli.py, never
asserted): the command line imports a command's module only when that command runs, ``validate`` imports
no OpenGL, no navigation sensors and no other command's module; the figures are laid out with fixed margins
that clip no label and let no panel overlap another; robot attitude errors are plotted in mrad, the metrics
table's unit; the metrics table's columns never run together."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

PAPER = str(Path(__file__).resolve().parents[1] / "scenarios" / "paper.yaml")


def _cli_imports(args: list[str]) -> set[str]:
    """The modules a real command-line process imports (``-X importtime``), MUJOCO_GL unset."""
    env = {k: v for k, v in os.environ.items() if k != "MUJOCO_GL"}
    p = subprocess.run([sys.executable, "-X", "importtime", "-m", "uvms_mj.cli.main", *args], env=env,
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr[-2000:]
    return {line.rsplit("|", 1)[-1].strip() for line in p.stderr.splitlines() if line.startswith("import time:")}


def test_validate_imports_only_what_it_checks_with() -> None:
    mods = _cli_imports(["validate", PAPER])
    assert {"mujoco", "pydantic", "uvms_mj.cli.run", "uvms_mj.scenario.schema"} <= mods  # it did validate
    # no GL backend (validate never renders), no other command's module, no navigation sensors or
    # estimator (the paper scenario has none), no plotting
    unwanted = {"OpenGL", "mujoco.egl", "mujoco.glfw", "uvms_mj.cli.plant", "uvms_mj.cli.logs",
                "uvms_mj.cli.study", "uvms_mj.cli.sim2real", "uvms_mj.sim.navsensors", "uvms_mj.estimation",
                "uvms_mj.analysis.plots", "matplotlib"}
    assert not unwanted & mods, sorted(unwanted & mods)


def test_importing_the_cli_imports_no_numerics() -> None:
    code = ("import sys, uvms_mj.cli.main; "
            "print(sorted(m for m in ('numpy', 'mujoco', 'pydantic', 'yaml', 'uvms_mj.cli.run', 'uvms_mj.cli.plant')"
            " if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_every_command_is_found_by_name() -> None:
    import click
    from click.testing import CliRunner

    from uvms_mj.cli.main import _COMMANDS, main

    assert main.list_commands(None) == sorted(_COMMANDS)
    for name in _COMMANDS:
        cmd = main.get_command(None, name)
        assert isinstance(cmd, click.Command) and cmd.name == name
    assert main.get_command(None, "no-such-command") is None
    res = CliRunner().invoke(main, ["--help"])
    assert res.exit_code == 0 and all(f"  {name} " in res.output for name in _COMMANDS)


def _robot_log(theta_rate: float = 0.01, n: int = 201, label: str = "c"):
    """A robot log whose desired attitude turns away from the true one (identity) about the body z
    axis at ``theta_rate`` [rad/s]: the attitude error is the rotation vector (0, 0, theta(t))."""
    t = np.linspace(0.0, 2.0, n)
    q = np.zeros((n, 7))
    q[:, 3] = 1.0
    bd = q.copy()
    theta = theta_rate * t
    bd[:, 3], bd[:, 6] = np.cos(theta / 2), np.sin(theta / 2)
    robot = {"name": "test", "layout": {"base": "vehicle"}}
    log = SimpleNamespace(t=t, signals={"q_true": q, "base_desired": bd}, meta={"robot": robot, "controller": label})
    return log, robot, theta


def _panel(fig, title_start: str):
    return next(a for a in fig.axes if a.get_title(loc="left").startswith(title_start))


def test_robot_attitude_error_plotted_in_mrad() -> None:
    from uvms_mj.analysis.plots.robot import _robot_tracking_figure

    log, robot, theta = _robot_log()
    fig = _robot_tracking_figure(log, robot, "t")
    a = _panel(fig, "(d) attitude error")
    assert a.get_ylabel() == "error [mrad]"
    norm = next(line for line in a.get_lines() if line.get_label().startswith("norm"))
    # the closed form: |rotation vector| = theta, in mrad (quaternion rounding ~1e-16 rad)
    np.testing.assert_allclose(norm.get_ydata(), 1e3 * theta, rtol=0, atol=1e-9)
    assert "mrad" in norm.get_label()


def test_robot_comparison_attitude_in_mrad(tmp_path, monkeypatch) -> None:
    from uvms_mj.analysis.plots import common, robot as plots_robot

    figs = []
    save = common._DecimatingFigure.savefig
    monkeypatch.setattr(common._DecimatingFigure, "savefig", lambda self, *a, **k: (figs.append(self),
                                                                                      save(self, *a, **k))[1])
    logs = {name: _robot_log(rate, label=name)[0] for name, rate in (("a", 0.01), ("b", 0.02))}
    plots_robot._plot_robot_comparison(logs, tmp_path / "c.png")
    a = _panel(figs[0], "(b) attitude error")
    assert a.get_ylabel() == "|error| [mrad]"
    peaks = sorted(float(np.max(line.get_ydata())) for line in a.get_lines() if line.get_label()[:1] in "ab")
    np.testing.assert_allclose(peaks, [1e3 * 0.01 * 2.0, 1e3 * 0.02 * 2.0], rtol=1e-9)  # theta_rate * t_end


def _check_layout(fig) -> None:
    """Every panel's labels inside the figure, no two panels' (with their twins and sub-panels) overlapping."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.transforms import Bbox

    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    r = canvas.get_renderer()
    W, H = fig.bbox.width, fig.bbox.height
    groups: dict = {}
    for a in fig.axes:
        if not a.get_visible() or a.get_subplotspec() is None:
            continue
        bb = a.get_tightbbox(r)
        assert bb.x0 >= -1 and bb.y0 >= -1 and bb.x1 <= W + 1 and bb.y1 <= H + 1, (a.get_title(loc="left"), bb)
        key = a.get_subplotspec().get_topmost_subplotspec()
        key = (key.rowspan.start, key.colspan.start)
        groups[key] = Bbox.union([groups[key], bb]) if key in groups else bb
    boxes = list(groups.items())
    for i, (ka, a) in enumerate(boxes):
        for kb, b in boxes[i + 1:]:
            overlap_x = min(a.x1, b.x1) - max(a.x0, b.x0)
            overlap_y = min(a.y1, b.y1) - max(a.y0, b.y0)
            assert overlap_x <= 1 or overlap_y <= 1, (ka, kb, a, b)  # 1 px: rounding of text extents


@pytest.fixture(scope="module")
def paper_run():
    from uvms_mj.sim.experiment import PaperExperiment

    return PaperExperiment(duration=1.0).run()


def test_paper_figures_fixed_layout_clips_and_overlaps_nothing(paper_run) -> None:
    from uvms_mj.analysis.plots import paper

    for build in (paper._tracking_figure, paper._actuation_figure):
        fig = build(paper_run, "rac_dob: a title")
        assert fig.get_layout_engine() is None  # fixed margins, no constrained layout
        _check_layout(fig)


def test_robot_figures_fixed_layout_clips_and_overlaps_nothing() -> None:
    from uvms_mj.analysis.plots import robot as plots_robot

    log, robot, _ = _robot_log()
    _check_layout(plots_robot._robot_tracking_figure(log, robot, "station_pid: test tracking"))
    _check_layout(plots_robot._robot_actuation_figure(log, robot, "station_pid: test actuation"))


def test_metrics_table_columns_never_run_together() -> None:
    from uvms_mj.cli.common import metrics_table

    names = ["station_pid", "task_priority", "a_controller_name_of_30_chars", "rac_dob"]
    status = dict(zip(names, ["ok", "joint_limit", "diverged", "ok"]))
    results = {n: {"base_pos_rms_mm": 1.0 + i, "tip_rms_mm": float("nan")} for i, n in enumerate(names)}
    lines = metrics_table(results, status).splitlines()
    assert lines[0].split() == ["metric", *names]
    assert lines[1].split() == ["status", *status.values()]
    assert len({len(line) for line in lines}) == 1  # every row as wide as the header: columns aligned
    row = next(line for line in lines if line.startswith("end tip RMS"))
    assert row.split()[-4:] == ["-"] * 4
