"""Paper-style figures of a run (matplotlib, Agg, no display needed).

* :func:`plot_run` writes ``{stem}_tracking.png`` (errors and desired vs actual, as the paper's
  Figs. 5 and 6: base position error x/y, base attitude error, end-tip position error, plus the
  tip and base positions and the path in the plane) and ``{stem}_actuation.png`` (thrust command
  and actual force with the limits, joint torques, the observer estimate f_E_hat, det B with the
  threshold Js and the singular-handling phase).
* :func:`plot_comparison` overlays the errors of the same scenario run with several controllers.
* Robot logs (any floating robot, ``meta["robot"]``) get their own figures with the model's
  names (:func:`plot_run`; errors by :func:`robot_errors`: world-frame position, body-frame
  attitude rotation vector).

Errors are in the metrics table's units (positions mm, attitudes mrad); absolute attitudes are drawn in
deg, joint angles in rad. Figures have fixed margins (:data:`uvms_mj.analysis.plots.common._MARGINS`),
not matplotlib's constrained layout: it measured every text twice per save, half of a figure's time.

Errors are desired minus true: ``p_desired`` against ``q_true`` (base) and ``tip_true`` (tip).
A log is anything with ``.t``, ``.signals`` (name -> array) and ``.meta``: a ``RunResult``, a
log read back from disk, or one read for its figures by :func:`read_plot_log` (in memory that does
not grow with the run: a long log thinned to the min/max envelope of its samples, with the
statistics the figures print computed over every sample; what ``uvms-mj plot``, ``run --plots`` and
the ``compare`` figure use). Signals a controller does not produce (the pd baseline has no f_E_hat
or singular_phase) are skipped with a note in their panel.

Figures are built on :class:`matplotlib.figure.Figure` directly (no pyplot), so importing this
module never changes the user's matplotlib backend.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping

import numpy as np

# common: log access and drawing helpers; paper: the planar paper robot's figures; robot: any
# floating robot's (logs with meta["robot"]). This module picks one for each log.
from uvms_mj.analysis.plots.paper import _plot_paper_comparison, _plot_paper_run
from uvms_mj.analysis.plots.robot import _plot_robot_comparison, _plot_robot_run
from uvms_mj.analysis.series import robot_of, attitude_error, robot_errors, tracking_errors
from uvms_mj.analysis.envelope import read_plot_log

__all__ = ["COMPARE_SIGNALS", "PLOT_SIGNALS", "attitude_error", "plot_run", "plot_run_paths", "plot_comparison",
           "read_plot_log", "robot_errors", "tracking_errors"]

#: The signals :func:`plot_comparison` reads (:func:`tracking_errors`, :func:`robot_errors`): a log
#: read for the comparison needs only these (``read_log(path, signals=COMPARE_SIGNALS)``).
COMPARE_SIGNALS = ("q_true", "p_desired", "tip_true", "base_desired", "tip_desired", "e_position", "e_attitude")
#: The signals :func:`plot_run` reads (paper and robot figures): ``read_log(path, signals=PLOT_SIGNALS)``
#: gives a log that plots the same figures with only these in memory (tests/test_memory.py checks the list).
PLOT_SIGNALS = COMPARE_SIGNALS + ("singular_phase", "thrust_command", "thrust_force", "thrust_saturated", "torques",
                                  "torques_applied", "f_E_hat", "det_B", "joints_desired", "wrench_body")


def plot_run_paths(out_dir: str | Path, stem: str = "run") -> list[Path]:
    """The files :func:`plot_run` writes (to check them before drawing anything)."""
    return [Path(out_dir) / f"{stem}_{suffix}.png" for suffix in ("tracking", "actuation")]


def plot_run(log, out_dir: str | Path, stem: str = "run") -> list[Path]:
    """Write ``{stem}_tracking.png`` and ``{stem}_actuation.png`` into ``out_dir``.

    Args:
        log: a run (``RunResult``) or a log read from disk (``.t``, ``.signals``, ``.meta``).
        out_dir: folder (created).
        stem: file name prefix.

    Returns:
        The paths written.

    A robot log (``meta["robot"]``, any floating robot) gets the same two files, labelled with
    the model's own names: ``_tracking``: base position x, y, z [m] and attitude roll, pitch,
    yaw [deg] (desired vs actual when ``base_desired`` is logged), base position error [mm] and
    attitude error [mrad], joint angles [rad] vs ``joints_desired``, the end-tip error [mm] (or
    position); ``_actuation``: thruster forces and commands [N], joint torques [N m], the
    controller's body-frame wrench. Panels whose signals are not logged say so.
    """
    t = np.asarray(log.t, dtype=float)
    if t.ndim != 1 or len(t) < 2:
        raise ValueError(f"the log has {len(t)} samples: at least 2 are needed to plot")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    robot = robot_of(log)
    if robot is not None:
        return _plot_robot_run(log, robot, out, stem)
    return _plot_paper_run(log, out, stem)


def _slim(log):
    """A log given by its path: read (:data:`COMPARE_SIGNALS`, by :func:`read_plot_log`: in bounded
    memory), with only what :func:`tracking_errors` / :func:`robot_errors` read of it (q_true's base columns; a robot's
    e_position / e_attitude only where base_desired is missing). Other logs: as given."""
    if not isinstance(log, (str, Path)):
        return log
    from types import SimpleNamespace

    full = read_plot_log(log, signals=COMPARE_SIGNALS)
    sig = dict(full.signals)
    robot = robot_of(full) is not None
    q = sig.get("q_true")
    if q is not None and q.ndim == 2:
        sig["q_true"] = np.ascontiguousarray(q[:, :7] if robot else q[:, :3])
    if robot:
        sig.pop("p_desired", None)
        bd = sig.get("base_desired")
        if bd is not None and bd.ndim == 2 and bd.shape[1] >= 7 and len(bd) == len(full.t):
            sig.pop("e_position", None)
            sig.pop("e_attitude", None)
    else:
        for name in ("base_desired", "tip_desired", "e_position", "e_attitude"):
            sig.pop(name, None)
    return SimpleNamespace(t=full.t, signals=sig, meta=full.meta, status=full.status, reason=full.reason,
                           error_stats=full.error_stats)


def plot_comparison(logs: Mapping[str, Any], out_path: str | Path) -> Path:
    """One figure overlaying, per controller, the base position error norm [mm], the base
    attitude error [mrad] and the end-tip error norm [mm] (desired - true); RMS and max in the
    legend. A panel whose curves differ by more than 30x in size switches to a log scale (and the
    attitude error to its magnitude) so that every controller stays readable.

    Args:
        logs: label (e.g. controller name) -> log of the same scenario, or the path of its MCAP
            log: read one at a time, only :data:`COMPARE_SIGNALS`, by :func:`read_plot_log` (a long
            log thinned to its min/max envelope, the statistics of the whole log) and each kept as
            the few columns the errors need (what bounds the memory of ``uvms-mj compare``).
        out_path: the PNG to write (folders are created).

    Robot logs (all of them; :func:`plot_run`): the base position error norm [mm], the attitude
    error angle [mrad] and, when ``tip_desired`` is logged, the end-tip error norm [mm]
    (:func:`robot_errors`).
    """
    if not logs:
        raise ValueError("plot_comparison needs at least one log")
    logs = {label: _slim(log) for label, log in logs.items()}  # a path: read, one at a time
    out_path = Path(out_path)
    robots = {label: robot_of(log) for label, log in logs.items()}
    if any(r is not None for r in robots.values()):
        paper = [label for label, r in robots.items() if r is None]
        if paper:
            raise ValueError(f"plot_comparison: {', '.join(map(repr, paper))} are paper (planar) logs and the "
                             "others robot logs: comparing the two kinds is not supported")
        out_path.parent.mkdir(parents=True, exist_ok=True)
        return _plot_robot_comparison(logs, out_path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    return _plot_paper_comparison(logs, out_path)
