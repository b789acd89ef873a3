"""The paper robot's figures (planar: base x, y, attitude; the 2-link arm's tip): tracking errors
and positions as the paper's Figs. 5 and 6, actuation and singularity handling, the comparison
of several controllers."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping

import numpy as np

from uvms_mj.io.atomic import atomic_path
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from uvms_mj.analysis.plots.common import (_DPI, _XY, _dig, _finish, _g, _headroom, _label, _meta, _missing,
                                           _new_figure, _shade, _shade_phases)
from uvms_mj.analysis.series import _sig, error_stats, tracking_errors

_THR = ("#1f77b4", "#ff7f0e", "#2ca02c")


def _thrust_limits(log) -> list[tuple[float, float]] | None:
    """Per-thruster (min, max) [N]: the log's metadata (a scenario's plant thrusters), else the
    model file's."""
    meta = _meta(log)
    lim = meta.get("thrust_limits")
    if lim is not None:
        try:
            return [(float(lo), float(hi)) for lo, hi in lim]
        except (TypeError, ValueError):
            pass
    rng = _dig(meta, "scenario", "plant", "thrusters", "force_range")
    if rng is not None:
        try:
            lo, hi = (float(v) for v in rng)
            return [(lo, hi)] * 3
        except (TypeError, ValueError):
            pass
    try:
        from uvms_mj.plant.params import compile_robot, read_params

        return [tuple(map(float, th.force_range)) for th in read_params(compile_robot()).thrusters]
    except Exception:  # noqa: BLE001 (the limits are decoration: never fail a plot on them)
        return None


def _js(log) -> tuple[float, str] | None:
    """(Js, where from): the run's controller parameter if recorded, else the paper's value."""
    meta = _meta(log)
    for keys in (("js",), ("controller_params", "js"), ("scenario", "controller", "params", "js")):
        v = _dig(meta, *keys)
        if v is not None:
            try:
                return float(v), ""
            except (TypeError, ValueError):
                pass
    try:
        from uvms_mj.control.digital import PAPER_JS

        return float(PAPER_JS), " (paper)"
    except Exception:  # noqa: BLE001
        return None


def _geometry():
    """(base box half extents, joint-1 offset, l1, l2) from the model file, or None."""
    try:
        from uvms_mj.plant.params import compile_robot, read_params

        p = read_params(compile_robot())
        return p.body("base").box_half, p.joint1_offset, *p.link_lengths
    except Exception:  # noqa: BLE001
        return None


def _stick(q: np.ndarray, geom) -> tuple[np.ndarray, np.ndarray]:
    """World outline of the base box (5, 2) and the arm polyline (3, 2) at q."""
    (hx, hy), (jx, jy), l1, l2 = geom
    x, y, p0, p1, p2 = q[:5]
    rot = np.array([[np.cos(p0), -np.sin(p0)], [np.sin(p0), np.cos(p0)]])
    box = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy], [-hx, -hy]]) @ rot.T + (x, y)
    j1 = np.array([x, y]) + rot @ (jx, jy)
    j2 = j1 + l1 * np.array([np.cos(p0 + p1), np.sin(p0 + p1)])
    tip = j2 + l2 * np.array([np.cos(p0 + p1 + p2), np.sin(p0 + p1 + p2)])
    return box, np.array([j1, j2, tip])


def _tracking_figure(log, title: str) -> Figure:
    t = np.asarray(log.t, dtype=float)
    e = tracking_errors(log)
    stats = error_stats(log, e)  # of the whole log (a thinned log carries its own)
    pd, q, tip = _sig(log, "p_desired"), _sig(log, "q_true"), _sig(log, "tip_true")
    phase = _sig(log, "singular_phase")
    fig, ax = _new_figure(3, 2, (13, 10))
    fig.suptitle(title, fontsize=13)
    time_axes = [ax[0, 0], ax[0, 1], ax[1, 0], ax[1, 1], ax[2, 0]]

    a = ax[0, 0]
    if "base" in e:
        for j, name in enumerate("xy"):
            a.plot(t, 1e3 * e["base"][:, j], color=_XY[j], lw=1.2,
                   label=f"$e_{{{name}}}$ (rms {_g(1e3 * stats['base'].rms[j])} mm)")
    else:
        _missing(a, "no p_desired / q_true in this log")
    _finish(a, "error [mm]", "(a) base position error (desired - true)")

    a = ax[0, 1]
    if "att" in e:
        a.plot(t, 1e3 * e["att"], color="#2ca02c", lw=1.2,
               label=rf"$e_{{\phi_0}}$ (rms {_g(1e3 * stats['att'].rms[0])} mrad)")
    else:
        _missing(a, "no p_desired / q_true in this log")
    _finish(a, "error [mrad]", r"(b) base attitude error $\phi_{0,d} - \phi_0$")

    a = ax[1, 0]
    if "tip" in e:
        for j, name in enumerate("xy"):
            a.plot(t, 1e3 * e["tip"][:, j], color=_XY[j], lw=1.2,
                   label=f"$e_{{{name}}}$ (rms {_g(1e3 * stats['tip'].rms[j])} mm)")
    else:
        _missing(a, "no p_desired / tip_true in this log")
    _finish(a, "error [mm]", "(c) end-tip position error (desired - true)")

    a = ax[1, 1]
    if pd is not None and tip is not None and pd.shape[1] >= 5:
        # x on the left axis, y on the right: they sit tens of centimetres apart
        a2 = a.twinx()
        for j, (axis, name) in enumerate(((a, "x"), (a2, "y"))):
            axis.plot(t, pd[:, 3 + j], "-", color=_XY[j], lw=3.5, alpha=0.35, label=f"$p_{{e{name}}}$ desired")
            axis.plot(t, tip[:, j], "-", color=_XY[j], lw=1.1, label=f"$p_{{e{name}}}$ actual" +
                      (" (right axis)" if j else ""))
        a2.set_ylabel("y [m]", color=_XY[1])
        a2.tick_params(axis="y", colors=_XY[1])
        _finish(a, "x [m]", "(d) end-tip position, world frame: desired vs actual", legend=False, zero=False)
        a.tick_params(axis="y", colors=_XY[0])
        a.yaxis.label.set_color(_XY[0])
        _headroom(a, a2)
        h1, l1 = a.get_legend_handles_labels()
        h2, l2 = a2.get_legend_handles_labels()
        a.legend(h1 + h2, l1 + l2, fontsize=8, loc="upper center", ncol=2, framealpha=0.85)
    else:
        _missing(a, "no p_desired / tip_true in this log")
        _finish(a, "position [m]", "(d) end-tip position, world frame", legend=False)

    a = ax[2, 0]
    if pd is not None and q is not None:
        for j, name in enumerate(("$x_0$", "$y_0$")):
            a.plot(t, pd[:, j], "-", color=_XY[j], lw=3.5, alpha=0.35, label=f"{name} desired")
            a.plot(t, q[:, j], "-", color=_XY[j], lw=1.1, label=f"{name} actual")
    else:
        _missing(a, "no p_desired / q_true in this log")
    _finish(a, "position [m]", "(e) base position, world frame: desired vs actual", legend=False)
    if a.get_legend_handles_labels()[0]:
        a.legend(fontsize=8, loc="best", ncol=2, framealpha=0.85)

    for a in time_axes:
        a.set_xlim(t[0], t[-1])
    for a in (ax[2, 0], ax[1, 1]):
        a.set_xlabel("time t [s]")
    handles = _shade_phases(time_axes, t, phase)
    if handles:
        ax[0, 1].legend(handles=ax[0, 1].get_legend_handles_labels()[0] + handles, fontsize=8, loc="best",
                        framealpha=0.85)

    _path_panel(ax[2, 1], log, pd, q, tip)
    return fig


def _path_panel(a: Axes, log, pd, q, tip) -> None:
    geom = _geometry()
    if q is not None and geom is not None:
        for k, (style, name) in enumerate(((":", "start"), ("-", "end"))):
            box, arm = _stick(q[0 if k == 0 else -1], geom)
            a.plot(box[:, 0], box[:, 1], style, color="#ff7f0e", lw=1.2)
            a.plot(arm[:, 0], arm[:, 1], style, color="0.35", lw=1.8, marker="o", ms=3, label=f"robot at {name}")
    if pd is not None and pd.shape[1] >= 5:
        a.plot(pd[:, 3], pd[:, 4], "-", color="#2ca02c", lw=5, alpha=0.4, label="tip desired")
    if tip is not None:
        a.plot(tip[:, 0], tip[:, 1], "-", color="#d62728", lw=1.2, label="tip actual")
    if q is not None:
        if pd is not None:
            a.plot(pd[:, 0], pd[:, 1], "-", color="#17becf", lw=5, alpha=0.4, label="base desired")
        a.plot(q[:, 0], q[:, 1], "-", color="#1f77b4", lw=1.2, label="base actual")
    if not a.lines:
        _missing(a, "no positions in this log")
    a.set_aspect("equal", adjustable="datalim")
    a.set_xlabel("world x [m]")
    a.set_ylabel("world y [m] (up)")
    a.set_title("(f) motion in the vertical plane", fontsize=11, loc="left")
    a.grid(True, alpha=0.3)
    if a.lines:
        a.legend(fontsize=8, loc="best", framealpha=0.85)


def _actuation_figure(log, title: str) -> Figure:
    t = np.asarray(log.t, dtype=float)
    cmd, force = _sig(log, "thrust_command"), _sig(log, "thrust_force")
    sat = _sig(log, "thrust_saturated")
    limits = _thrust_limits(log)
    fig, ax = _new_figure(3, 2, (13, 10))
    fig.suptitle(title, fontsize=13)

    for i in range(3):
        a = ax[i, 0]
        if cmd is None and force is None:
            _missing(a, "no thruster signals in this log")
        if cmd is not None and cmd.shape[1] > i:
            a.plot(t, cmd[:, i], "--", color=_THR[i], lw=1.4, label="command")
        if force is not None and force.shape[1] > i:
            a.plot(t, force[:, i], "-", color="k", lw=0.9, alpha=0.8, label="actual (lagged, saturated)")
        if limits is not None and len(limits) > i and (cmd is not None or force is not None):
            lo, hi = limits[i]
            a.axhline(hi, color="#d62728", ls=":", lw=1.2, label=f"limits {lo:+.2f} / {hi:+.2f} N")
            a.axhline(lo, color="#d62728", ls=":", lw=1.2)
        if sat is not None and sat.ndim == 2 and sat.shape[1] > i and _shade(a, t, sat[:, i] > 0.5, "#d62728", 0.15):
            a.plot([], [], color="#d62728", alpha=0.3, lw=6, label="saturated")
        _finish(a, "thrust [N]", f"({'abc'[i]}) thruster {i + 1}")
        a.set_xlim(t[0], t[-1])
    ax[2, 0].set_xlabel("time t [s]")

    a = ax[0, 1]
    tau, app = _sig(log, "torques"), _sig(log, "torques_applied")
    if tau is not None:
        for j in range(min(2, tau.shape[1])):
            a.plot(t, tau[:, j], color=_XY[j], lw=1.1, label=rf"$\tau_{{{j + 1}}}$ (joint {j + 1})")
            if app is not None and app.shape == tau.shape and not np.array_equal(app[:, j], tau[:, j]):
                a.plot(t, app[:, j], ":", color=_XY[j], lw=1.3, label=rf"$\tau_{{{j + 1}}}$ applied")
    else:
        _missing(a, "no joint torques in this log")
    _finish(a, "torque [N m]", "(d) joint torques")

    a = ax[1, 1]
    fe = _sig(log, "f_E_hat")
    if fe is not None and fe.ndim == 2 and fe.shape[1] >= 3:
        a.plot(t, fe[:, 0], color=_XY[0], lw=1.1, label=r"$\hat f_{E,x}$ [N]")
        a.plot(t, fe[:, 1], color=_XY[1], lw=1.1, label=r"$\hat f_{E,y}$ [N]")
        a2 = a.twinx()
        a2.plot(t, fe[:, 2], color="#2ca02c", lw=1.1, label=r"$\hat n_{E}$ [N m] (right)")
        a2.set_ylabel("moment [N m]", color="#2ca02c")
        a2.tick_params(axis="y", colors="#2ca02c")
        h1, l1 = a.get_legend_handles_labels()
        h2, l2 = a2.get_legend_handles_labels()
        _finish(a, "force [N]", r"(e) disturbance observer estimate $\hat f_E$ (base, world frame)", legend=False)
        _headroom(a, a2)
        a.legend(h1 + h2, l1 + l2, fontsize=8, loc="upper center", ncol=3, framealpha=0.85)
    else:
        name = _label(log)
        _missing(a, f"no disturbance observer in this run (controller {name}): no f_E_hat" if name
                 else "no f_E_hat in this log")
        _finish(a, "", r"(e) disturbance observer estimate $\hat f_E$", legend=False)

    detb, phase = _sig(log, "det_B"), _sig(log, "singular_phase")
    right = [ax[0, 1], ax[1, 1]]
    if detb is not None and phase is not None:
        # |det B| against Js above, the phase as a step below (shared time axis)
        spec = ax[2, 1].get_subplotspec().subgridspec(2, 1, height_ratios=(3, 1), hspace=0.0)
        ax[2, 1].remove()
        a, ap = fig.add_subplot(spec[0]), fig.add_subplot(spec[1])
        a.sharex(ap)
        a.tick_params(labelbottom=False)
        right += [a, ap]
    else:
        a, ap = ax[2, 1], None
        right.append(a)
    if detb is not None:
        a.plot(t, np.abs(detb), color="k", lw=1.2, label=r"$|\det B| = l_1 l_2 |\sin\phi_2|$")
        js = _js(log)
        if js is not None:
            a.axhline(js[0], color="#d62728", ls="--", lw=1.1, label=f"threshold $J_s$ = {js[0]:g}{js[1]}")
        handles = _shade_phases([a] + ([ap] if ap is not None else []), t, phase)
        _finish(a, r"$|\det B|$ [m$^2$]", "(f) arm singularity measure and singular-handling phase", legend=False,
                zero=False)
        a.legend(handles=a.get_legend_handles_labels()[0] + handles, fontsize=8, loc="best", framealpha=0.85)
        if ap is not None:
            ap.step(t, phase, where="post", color="#9467bd", lw=1.3)
            ap.set_ylim(-0.4, 2.4)
            ap.set_yticks([0, 1, 2], ["0 normal", "1 carry", "2 release"], fontsize=8)
            ap.set_ylabel("phase")
            ap.grid(True, alpha=0.3)
        else:
            a.text(0.99, 0.02, f"no singular_phase in this log ({_label(log) or 'no singular handling'})", ha="right",
                   va="bottom", transform=a.transAxes, color="0.4", fontsize=8)
    else:
        _missing(a, "no det_B in this log")
        _finish(a, "", "(f) det B", legend=False)
    for a in right:
        a.set_xlim(t[0], t[-1])
    (ap if ap is not None else a).set_xlabel("time t [s]")
    return fig


def _plot_paper_run(log, out: Path, stem: str) -> list[Path]:
    name = _label(log, stem)
    paths = []
    for suffix, build, what in (("tracking", _tracking_figure, "tracking"),
                                ("actuation", _actuation_figure, "actuation and singularity handling")):
        fig = build(log, f"{name}: {what}")
        path = out / f"{stem}_{suffix}.png"
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=_DPI, format="png")
        paths.append(path)
    return paths


def _plot_paper_comparison(logs: Mapping[str, Any], out_path: Path) -> Path:
    fig, ax = _new_figure(3, 1, (11, 9.5))
    ax = ax[:, 0]
    fig.suptitle("controller comparison: tracking errors (desired - true)", fontsize=13)
    colors = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf"]
    # per run and panel: (label, colour, t, y, rms, max |y|); the statistics of the whole log
    panels: list[list[tuple]] = [[], [], []]
    for k, (label, log) in enumerate(logs.items()):
        t = np.asarray(log.t, dtype=float)
        e = tracking_errors(log)
        st = error_stats(log, e)
        c = colors[k % len(colors)]
        if "base" in e:
            panels[0].append((label, c, t, 1e3 * np.hypot(e["base"][:, 0], e["base"][:, 1]),
                              1e3 * st["base"].norm_rms, 1e3 * st["base"].norm_max))
        if "att" in e:
            panels[1].append((label, c, t, 1e3 * e["att"], 1e3 * st["att"].rms[0], 1e3 * st["att"].absmax[0]))
        if "tip" in e:
            panels[2].append((label, c, t, 1e3 * np.hypot(e["tip"][:, 0], e["tip"][:, 1]),
                              1e3 * st["tip"].norm_rms, 1e3 * st["tip"].norm_max))
    titles = ("(a) base position error norm", r"(b) base attitude error $\phi_{0,d} - \phi_0$",
              "(c) end-tip position error norm")
    units = ("mm", "mrad", "mm")
    t_lo, t_hi = np.inf, -np.inf
    for i, (a, series) in enumerate(zip(ax, panels)):
        peaks = [peak for *_, y, _, peak in series if len(y)]
        log_scale = len(peaks) > 1 and min(peaks) > 0 and max(peaks) / min(peaks) > 30
        positive = []
        for label, c, t, y, rms, peak in series:
            if len(t):
                t_lo, t_hi = min(t_lo, float(t[0])), max(t_hi, float(t[-1]))
            stats = f"rms {_g(rms)}, max {_g(peak)} {units[i]}"
            a.plot(t, np.abs(y) if log_scale else y, color=c, lw=1.2, label=f"{label} ({stats})")
            positive.append(np.abs(y)[np.abs(y) > 0])
        ylabel = f"|error| [{units[i]}]" if (i != 1 or log_scale) else f"error [{units[i]}]"
        _finish(a, ylabel, titles[i] + (" (magnitude, log scale)" if log_scale else ""), legend=False,
                zero=not log_scale)
        if log_scale:
            a.set_yscale("log")
            vals = np.concatenate(positive)
            lo = max(float(np.percentile(vals, 1)) / 2, float(vals.max()) * 1e-6)
            a.set_ylim(lo, float(vals.max()) * 3)
        if a.lines:
            a.legend(fontsize=8, loc="best", framealpha=0.85)
        else:
            _missing(a, "no signal in any log")
    for a in ax:
        if t_hi > t_lo:
            a.set_xlim(t_lo, t_hi)
    ax[2].set_xlabel("time t [s]")
    with atomic_path(out_path) as tmp:
        fig.savefig(tmp, dpi=_DPI, format="png")
    return out_path
