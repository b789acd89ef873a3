"""Figures of any floating robot's log (``meta["robot"]``), with the model's own names: tracking
(position, attitude, errors, joints, tip), actuation (thrusters, joint torques, the body-frame
wrench) and the comparison of several controllers' error norms."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping

import numpy as np

from uvms_mj.io.atomic import atomic_path
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from uvms_mj.analysis.plots.common import _DPI, _finish, _g, _headroom, _label, _missing, _new_figure
from uvms_mj.analysis.series import ErrorStats, _sig, error_stats, robot_errors

# The vehicle's free joint comes first in qpos (x, y, z [m] world, qw, qx, qy, qz) and the arm
# joints follow (one angle each), as in every built-in robot (uvms_mj.plant.robot); velocities:
# (v [m/s] world, omega [rad/s] body, joint rates).

_COLORS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf",
           "#bcbd22", "#7f7f7f")
_XYZ = ("#1f77b4", "#d62728", "#2ca02c")


def _names(robot: Mapping[str, Any], key: str, n: int, generic: str) -> list[str]:
    """The model's names of ``key`` ("joints", "thrusters", "motors") from the log's layout, or
    generic ones when they are missing or do not match the signal's width ``n``."""
    layout = robot.get("layout") if isinstance(robot.get("layout"), Mapping) else {}
    names = layout.get(key) if isinstance(layout, Mapping) else None
    if isinstance(names, (list, tuple)) and len(names) == n:
        return [str(x) for x in names]
    return [f"{generic} {i + 1}" for i in range(n)]


def _rpy_deg(quat: np.ndarray) -> np.ndarray:
    """(roll, pitch, yaw) [deg] (N, 3) of quaternions (N, 4) (z-y-x, :func:`uvms_mj.plant.robot.rpy_from_quat`),
    roll and yaw unwrapped (continuous through +-180 deg)."""
    from uvms_mj.rotations import rpy_from_quat

    out = np.full((len(quat), 3), np.nan)
    for k, qk in enumerate(quat):
        if np.all(np.isfinite(qk)) and np.linalg.norm(qk) > 0:
            out[k] = rpy_from_quat(qk)
    ok = np.isfinite(out).all(axis=1)
    for j in (0, 2):
        out[ok, j] = np.unwrap(out[ok, j])
    return np.degrees(out)


def _desired_true(a: Axes, t: np.ndarray, true: np.ndarray, desired: np.ndarray | None, labels: list[str],
                  colors=_XYZ) -> None:
    for j, name in enumerate(labels):
        c = colors[j % len(colors)]
        if desired is not None:
            a.plot(t, desired[:, j], "-", color=c, lw=3.5, alpha=0.35, label=f"{name} desired")
        a.plot(t, true[:, j], "-", color=c, lw=1.1, label=name if desired is None else f"{name} actual")


def _error_lines(a: Axes, t: np.ndarray, e: np.ndarray, scale: float, unit: str, labels: list[str],
                 stats: ErrorStats) -> None:
    """The error's columns and norm; ``stats``: the whole log's (:func:`error_stats`)."""
    for j, name in enumerate(labels):
        a.plot(t, scale * e[:, j], color=_XYZ[j], lw=1.1, label=f"{name} (rms {_g(scale * stats.rms[j])} {unit})")
    norm = scale * np.linalg.norm(e, axis=1)
    a.plot(t, norm, color="k", lw=1.3, label=f"norm (max {_g(scale * stats.norm_max)} {unit})")


def _robot_tracking_figure(log, robot: Mapping[str, Any], title: str) -> Figure:
    t = np.asarray(log.t, dtype=float)
    q, bd = _sig(log, "q_true"), _sig(log, "base_desired")
    if bd is not None and bd.shape[1] < 7:
        bd = None
    e = robot_errors(log)
    stats = error_stats(log, e)  # of the whole log (a thinned log carries its own)
    base = robot.get("layout", {}).get("base", "vehicle") if isinstance(robot.get("layout"), Mapping) else "vehicle"
    fig, ax = _new_figure(3, 2, (13, 10.5))
    fig.suptitle(title, fontsize=13)
    xyz = ["x", "y", "z"]

    a = ax[0, 0]
    if q is not None and q.shape[1] >= 7:
        _desired_true(a, t, q[:, :3], bd[:, :3] if bd is not None else None, xyz)
    else:
        _missing(a, "no q_true in this log")
    _finish(a, "position [m]", f"(a) {base} position, world frame" + (": desired vs actual" if bd is not None else ""),
            zero=False)

    a = ax[0, 1]
    if q is not None and q.shape[1] >= 7:
        _desired_true(a, t, _rpy_deg(q[:, 3:7]), _rpy_deg(bd[:, 3:7]) if bd is not None else None,
                      ["roll", "pitch", "yaw"])
    else:
        _missing(a, "no q_true in this log")
    _finish(a, "angle [deg]", f"(b) {base} attitude (z-y-x roll, pitch, yaw)", zero=False)

    a = ax[1, 0]
    if "base" in e:
        _error_lines(a, t, e["base"], 1e3, "mm", ["$e_x$", "$e_y$", "$e_z$"], stats["base"])
    else:
        _missing(a, "not logged (no base_desired / e_position)")
    _finish(a, "error [mm]", "(c) base position error (desired - true), world frame")

    a = ax[1, 1]
    if "att" in e:
        # mrad, the metrics table's unit for attitude errors (base_att_rms_mrad)
        _error_lines(a, t, e["att"], 1e3, "mrad", [r"$e_{\theta x}$", r"$e_{\theta y}$", r"$e_{\theta z}$"],
                     stats["att"])
    else:
        _missing(a, "not logged (no base_desired / e_attitude)")
    _finish(a, "error [mrad]", "(d) attitude error (rotation vector, body frame)")

    a = ax[2, 0]
    jd = _sig(log, "joints_desired")
    nj = q.shape[1] - 7 if q is not None and q.shape[1] > 7 else 0
    if nj:
        names = _names(robot, "joints", nj, "joint")
        if jd is not None and jd.shape[1:] != (nj,):
            jd = None
        _desired_true(a, t, q[:, 7:7 + nj], jd, names, colors=_COLORS)
    else:
        _missing(a, "the robot has no arm joints")
    _finish(a, "angle [rad]", "(e) joint angles" + (": desired vs actual" if nj and jd is not None else ""),
            zero=False)

    a = ax[2, 1]
    tip = _sig(log, "tip_true")
    if "tip" in e:
        _error_lines(a, t, e["tip"], 1e3, "mm", ["$e_x$", "$e_y$", "$e_z$"], stats["tip"])
        _finish(a, "error [mm]", "(f) end-tip position error (desired - true), world frame")
    elif tip is not None and tip.ndim == 2 and tip.shape[1] == 3 and np.isfinite(tip).any():
        _desired_true(a, t, tip, None, xyz)
        _finish(a, "position [m]", "(f) end-tip position, world frame (no tip_desired logged)", zero=False)
    else:
        _missing(a, "no tip (the robot has no tip site, or tip_true is not logged)")
        _finish(a, "", "(f) end-tip position", legend=False)

    for a in ax.ravel():
        a.set_xlim(t[0], t[-1])
    for a in ax[2]:
        a.set_xlabel("time t [s]")
    for a in ax.ravel():
        if len(a.get_legend_handles_labels()[0]) > 4:
            a.legend(fontsize=7, loc="best", ncol=2, framealpha=0.85)
    return fig


def _robot_actuation_figure(log, robot: Mapping[str, Any], title: str) -> Figure:
    t = np.asarray(log.t, dtype=float)
    fig, ax = _new_figure(3, 1, (12, 10.5))
    ax = ax[:, 0]
    fig.suptitle(title, fontsize=13)

    a = ax[0]
    cmd, force = _sig(log, "thrust_command"), _sig(log, "thrust_force")
    width = next((s.shape[1] for s in (force, cmd) if s is not None and s.ndim == 2), 0)
    if width:
        names = _names(robot, "thrusters", width, "thruster")
        for i, name in enumerate(names):
            c = _COLORS[i % len(_COLORS)]
            if force is not None and force.shape[1] == width:
                a.plot(t, force[:, i], "-", color=c, lw=1.1, label=name)
            if cmd is not None and cmd.shape[1] == width:
                a.plot(t, cmd[:, i], "--", color=c, lw=1.0, alpha=0.8,
                       label=f"{name} command" if force is None else None)
        what = "actual (solid) and command (dashed)" if force is not None and cmd is not None else \
            ("actual" if force is not None else "command")
        _finish(a, "thrust [N]", f"(a) thruster forces: {what}", legend=False)
        a.legend(fontsize=7, loc="best", ncol=4, framealpha=0.85)
    else:
        _missing(a, "no thrusters (or thrust_command / thrust_force not logged)")
        _finish(a, "thrust [N]", "(a) thruster forces", legend=False)

    a = ax[1]
    tau, app = _sig(log, "torques"), _sig(log, "torques_applied")
    if tau is not None and tau.ndim == 2 and tau.shape[1]:
        both = app is not None and app.shape == tau.shape
        for i, name in enumerate(_names(robot, "motors", tau.shape[1], "motor")):
            c = _COLORS[i % len(_COLORS)]
            if both:
                a.plot(t, app[:, i], "-", color=c, lw=1.1, label=name)
            a.plot(t, tau[:, i], "--" if both else "-", color=c, lw=1.0 if both else 1.1, alpha=0.8 if both else 1.0,
                   label=None if both else name)
        what = ": applied (solid) and command (dashed)" if both else " (command)"
        _finish(a, "torque [N m]", f"(b) joint torques{what}", legend=False)
        a.legend(fontsize=7, loc="best", ncol=4, framealpha=0.85)
    else:
        _missing(a, "no joint torques (no arm, or not logged)")
        _finish(a, "torque [N m]", "(b) joint torques", legend=False)

    a = ax[2]
    wr = _sig(log, "wrench_body")
    if wr is not None and wr.ndim == 2 and wr.shape[1] == 6:
        for j, name in enumerate(("$F_x$", "$F_y$", "$F_z$")):
            a.plot(t, wr[:, j], color=_XYZ[j], lw=1.1, label=f"{name} [N]")
        a2 = a.twinx()
        for j, name in enumerate(("$M_x$", "$M_y$", "$M_z$")):
            a2.plot(t, wr[:, 3 + j], "--", color=_XYZ[j], lw=1.0, label=f"{name} [N m] (right)")
        a2.set_ylabel("moment [N m]")
        _finish(a, "force [N]", "(c) controller wrench on the vehicle, body frame", legend=False)
        _headroom(a, a2)
        h1, l1 = a.get_legend_handles_labels()
        h2, l2 = a2.get_legend_handles_labels()
        a.legend(h1 + h2, l1 + l2, fontsize=7, loc="upper center", ncol=6, framealpha=0.85)
    else:
        _missing(a, "not logged (no wrench_body)")
        _finish(a, "", "(c) controller wrench on the vehicle, body frame", legend=False)
    for a in ax:
        a.set_xlim(t[0], t[-1])
    ax[-1].set_xlabel("time t [s]")
    return fig


def _plot_robot_run(log, robot: Mapping[str, Any], out: Path, stem: str) -> list[Path]:
    name = _label(log, stem)
    paths = []
    for suffix, build, what in (("tracking", _robot_tracking_figure, f"{robot.get('name')} tracking"),
                                ("actuation", _robot_actuation_figure, f"{robot.get('name')} actuation")):
        fig = build(log, robot, f"{name}: {what}")
        path = out / f"{stem}_{suffix}.png"
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=_DPI, format="png")
        paths.append(path)
    return paths


def _norm_panel(a: Axes, series: list[tuple], title: str, unit: str, missing: list[str]) -> None:
    """Error norms (>= 0) of several runs, ``(label, colour, t, y, rms, max)`` (the statistics of the
    whole log); log scale when their peaks differ by more than 30x; ``missing``: the runs that did
    not log this error (noted in the panel)."""
    peaks = [peak for *_, y, _, peak in series if len(y) and np.isfinite(peak)]
    log_scale = len(peaks) > 1 and min(peaks) > 0 and max(peaks) / min(peaks) > 30
    for label, c, t, y, rms, peak in series:
        stats = f"rms {_g(rms)}, max {_g(peak)} {unit}"
        a.plot(t, y, color=c, lw=1.2, label=f"{label} ({stats})")
    _finish(a, f"|error| [{unit}]", title + (" (log scale)" if log_scale else ""), legend=False, zero=not log_scale)
    if log_scale:
        a.set_yscale("log")
    if series:
        a.legend(fontsize=8, loc="best", framealpha=0.85)
        if missing:
            a.text(0.99, 0.02, "not logged: " + ", ".join(missing), ha="right", va="bottom", transform=a.transAxes,
                   color="0.4", fontsize=8)
    else:
        _missing(a, "not logged in any run")


def _plot_robot_comparison(logs: Mapping[str, Any], out_path: Path) -> Path:
    fig, ax = _new_figure(3, 1, (11, 9.5))
    ax = ax[:, 0]
    fig.suptitle("controller comparison: tracking errors (desired - true)", fontsize=13)
    panels: list[list[tuple]] = [[], [], []]
    scale = (1e3, 1e3, 1e3)  # mm, mrad, mm: the metrics table's units
    t_lo, t_hi = np.inf, -np.inf
    for k, (label, log) in enumerate(logs.items()):
        t = np.asarray(log.t, dtype=float)
        if len(t):
            t_lo, t_hi = min(t_lo, float(t[0])), max(t_hi, float(t[-1]))
        e = robot_errors(log)
        st = error_stats(log, e)
        for i, key in enumerate(("base", "att", "tip")):
            if key in e:
                panels[i].append((label, _COLORS[k % len(_COLORS)], t, scale[i] * np.linalg.norm(e[key], axis=1),
                                  scale[i] * st[key].norm_rms, scale[i] * st[key].norm_max))
    for a, series, title, unit in zip(ax, panels, ("(a) base position error norm, world frame",
                                                   "(b) attitude error angle (rotation vector norm)",
                                                   "(c) end-tip position error norm, world frame"),
                                      ("mm", "mrad", "mm")):
        have = {s[0] for s in series}
        _norm_panel(a, series, title, unit, [label for label in logs if label not in have])
        if t_hi > t_lo:
            a.set_xlim(t_lo, t_hi)
    ax[2].set_xlabel("time t [s]")
    with atomic_path(out_path) as tmp:
        fig.savefig(tmp, dpi=_DPI, format="png")
    return out_path
