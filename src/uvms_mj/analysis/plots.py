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

Errors are desired minus true: ``p_desired`` against ``q_true`` (base) and ``tip_true`` (tip).
A log is anything with ``.t``, ``.signals`` (name -> array) and ``.meta``: a ``RunResult`` or a
log read back from disk. Signals a controller does not produce (the pd baseline has no f_E_hat
or singular_phase) are skipped with a note in their panel.

Figures are built on :class:`matplotlib.figure.Figure` directly (no pyplot), so importing this
module never changes the user's matplotlib backend.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.patches import Patch

__all__ = ["attitude_error", "plot_run", "plot_comparison", "robot_errors", "tracking_errors"]

_PHASES = {1: ("carry (base moves with the arm)", "#f4a582"), 2: ("release", "#92c5de")}
_XY = ("#1f77b4", "#d62728")  # x, y
_THR = ("#1f77b4", "#ff7f0e", "#2ca02c")
_DPI = 110


# ------------------------------------------------------------------ log access


def _sig(log, name: str) -> np.ndarray | None:
    signals = getattr(log, "signals", None) or {}
    try:
        if name not in signals:
            return None
        arr = np.asarray(signals[name], dtype=float)
    except (KeyError, TypeError, ValueError):
        return None
    if arr.size == 0 or len(arr) != len(np.asarray(log.t)):
        return None
    return arr


def _meta(log) -> Mapping[str, Any]:
    meta = getattr(log, "meta", None)
    return meta if isinstance(meta, Mapping) else {}


def _label(log, default: str = "") -> str:
    m = _meta(log)
    return str(m.get("controller") or m.get("name") or default)


def tracking_errors(log) -> dict[str, np.ndarray]:
    """Desired minus true, SI units: 'base' (N, 2) [m], 'att' (N,) [rad], 'tip' (N, 2) [m]
    (keys missing when a signal is absent)."""
    pd, q, tip = _sig(log, "p_desired"), _sig(log, "q_true"), _sig(log, "tip_true")
    out: dict[str, np.ndarray] = {}
    if pd is not None and q is not None:
        out["base"] = pd[:, :2] - q[:, :2]
        out["att"] = pd[:, 2] - q[:, 2]
    if pd is not None and tip is not None and pd.shape[1] >= 5:
        out["tip"] = pd[:, 3:5] - tip
    return out


def _dig(meta: Mapping[str, Any], *keys: str) -> Any:
    cur: Any = meta
    for k in keys:
        if not isinstance(cur, Mapping) or k not in cur:
            return None
        cur = cur[k]
    return cur


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
        from uvms_mj.planar.nominal import params_from_file

        return [tuple(map(float, th.force_range)) for th in params_from_file().thrusters]
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
        from uvms_mj.control.builtin import PAPER_JS

        return float(PAPER_JS), " (paper)"
    except Exception:  # noqa: BLE001
        return None


def _geometry():
    """(base box half extents, joint-1 offset, l1, l2) from the model file, or None."""
    try:
        from uvms_mj.planar.nominal import params_from_file

        p = params_from_file()
        return p.body("base").box_half, p.joint1_offset, *p.link_lengths
    except Exception:  # noqa: BLE001
        return None


# ------------------------------------------------------------------ drawing helpers


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) index ranges where mask is True."""
    m = np.r_[False, np.asarray(mask, dtype=bool), False]
    d = np.diff(m.astype(np.int8))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)))


def _shade(ax: Axes, t: np.ndarray, mask: np.ndarray, color: str, alpha: float = 0.25) -> bool:
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    any_ = False
    for a, b in _runs(mask):
        ax.axvspan(t[a], t[b - 1] + dt, color=color, alpha=alpha, lw=0, zorder=0)
        any_ = True
    return any_


def _shade_phases(axes, t: np.ndarray, phase: np.ndarray | None) -> list[Patch]:
    if phase is None:
        return []
    handles = []
    for value, (name, color) in _PHASES.items():
        hit = False
        for ax in axes:
            hit |= _shade(ax, t, phase == value, color)
        if hit:
            handles.append(Patch(color=color, alpha=0.4, label=f"phase {value}: {name}"))
    return handles


def _missing(ax: Axes, text: str) -> None:
    ax.text(0.5, 0.5, text, ha="center", va="center", transform=ax.transAxes, color="0.4", fontsize=10, wrap=True)
    ax.set_yticks([])


def _finish(ax: Axes, ylabel: str, title: str, legend: bool = True, zero: bool = True) -> None:
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=11, loc="left")
    ax.grid(True, alpha=0.3)
    if zero:
        ax.axhline(0.0, color="0.6", lw=0.6, zorder=1)
    if legend and ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=8, loc="best", framealpha=0.85)


def _headroom(*axes: Axes, frac: float = 0.3) -> None:
    """Extend the y range upwards so that a legend at the top covers no data."""
    for a in axes:
        lo, hi = a.get_ylim()
        a.set_ylim(lo, hi + frac * (hi - lo))


def _new_figure(rows: int, cols: int, size: tuple[float, float]) -> tuple[Figure, np.ndarray]:
    fig = Figure(figsize=size, dpi=_DPI, layout="constrained")
    axes = np.asarray(fig.subplots(rows, cols, squeeze=False))
    return fig, axes


def _g(x: float) -> str:
    """3 significant digits, no exponent for the usual range (0.0123, 1.23, 123)."""
    return f"{x:.3g}" if (x == 0 or 1e-3 <= abs(x) < 1e4) else f"{x:.2e}"


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x)))) if x.size else float("nan")


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


# ------------------------------------------------------------------ figures


def _tracking_figure(log, title: str) -> Figure:
    t = np.asarray(log.t, dtype=float)
    e = tracking_errors(log)
    pd, q, tip = _sig(log, "p_desired"), _sig(log, "q_true"), _sig(log, "tip_true")
    phase = _sig(log, "singular_phase")
    fig, ax = _new_figure(3, 2, (13, 10))
    fig.suptitle(title, fontsize=13)
    time_axes = [ax[0, 0], ax[0, 1], ax[1, 0], ax[1, 1], ax[2, 0]]

    a = ax[0, 0]
    if "base" in e:
        for j, name in enumerate("xy"):
            a.plot(t, 1e3 * e["base"][:, j], color=_XY[j], lw=1.2,
                   label=f"$e_{{{name}}}$ (rms {_g(1e3 * _rms(e['base'][:, j]))} mm)")
    else:
        _missing(a, "no p_desired / q_true in this log")
    _finish(a, "error [mm]", "(a) base position error (desired - true)")

    a = ax[0, 1]
    if "att" in e:
        a.plot(t, 1e3 * e["att"], color="#2ca02c", lw=1.2,
               label=rf"$e_{{\phi_0}}$ (rms {_g(1e3 * _rms(e['att']))} mrad)")
    else:
        _missing(a, "no p_desired / q_true in this log")
    _finish(a, "error [mrad]", r"(b) base attitude error $\phi_{0,d} - \phi_0$")

    a = ax[1, 0]
    if "tip" in e:
        for j, name in enumerate("xy"):
            a.plot(t, 1e3 * e["tip"][:, j], color=_XY[j], lw=1.2,
                   label=f"$e_{{{name}}}$ (rms {_g(1e3 * _rms(e['tip'][:, j]))} mm)")
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
    tau = _sig(log, "torques")
    if tau is not None:
        for j in range(min(2, tau.shape[1])):
            a.plot(t, tau[:, j], color=_XY[j], lw=1.1, label=rf"$\tau_{{{j + 1}}}$ (joint {j + 1})")
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


# ------------------------------------------------------------------ any robot (logs with meta["robot"])
# The vehicle's free joint comes first in qpos (x, y, z [m] world, qw, qx, qy, qz) and the arm
# joints follow (one angle each), as in every built-in robot (uvms_mj.plant.robot); velocities:
# (v [m/s] world, omega [rad/s] body, joint rates).

_COLORS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf",
           "#bcbd22", "#7f7f7f")
_XYZ = ("#1f77b4", "#d62728", "#2ca02c")


def _robot(log) -> dict | None:
    from uvms_mj.analysis.render import robot_of

    return robot_of(log)


def _names(robot: Mapping[str, Any], key: str, n: int, generic: str) -> list[str]:
    """The model's names of ``key`` ("joints", "thrusters", "motors") from the log's layout, or
    generic ones when they are missing or do not match the signal's width ``n``."""
    layout = robot.get("layout") if isinstance(robot.get("layout"), Mapping) else {}
    names = layout.get(key) if isinstance(layout, Mapping) else None
    if isinstance(names, (list, tuple)) and len(names) == n:
        return [str(x) for x in names]
    return [f"{generic} {i + 1}" for i in range(n)]


def _quat_rows(q: np.ndarray) -> np.ndarray:
    """Unit quaternions (N, 4) (w x y z); a zero row stays NaN."""
    n = np.linalg.norm(q, axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return q / n


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


def attitude_error(q_desired: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Rotation vector [rad] (N, 3), BODY frame, that turns the true attitude ``q`` into the
    desired ``q_desired`` (quaternions w x y z, (N, 4)): log(q^-1 q_desired), angle in [0, pi]."""
    a, b = _quat_rows(q), _quat_rows(q_desired)
    w1, v1 = a[:, 0], -a[:, 1:]  # conj(q)
    w2, v2 = b[:, 0], b[:, 1:]
    w = w1 * w2 - np.sum(v1 * v2, axis=1)
    v = w1[:, None] * v2 + w2[:, None] * v1 + np.cross(v1, v2)
    sign = np.where(w < 0, -1.0, 1.0)[:, None]  # the short way round
    w, v = np.abs(w), v * sign
    s = np.linalg.norm(v, axis=1)
    angle = 2 * np.arctan2(s, w)
    with np.errstate(invalid="ignore", divide="ignore"):
        scale = np.where(s > 1e-12, angle / np.where(s > 1e-12, s, 1.0), 2.0)
    return v * scale[:, None]


def robot_errors(log) -> dict[str, np.ndarray]:
    """Desired minus true of a robot log, SI units: 'base' (N, 3) [m] world, 'att' (N, 3)
    [rad] body-frame rotation vector, 'tip' (N, 3) [m] world. From ``base_desired`` and
    ``tip_desired`` against the true state, else the controller's ``e_position`` /
    ``e_attitude``; keys missing when not logged."""
    q, bd, td, tip = _sig(log, "q_true"), _sig(log, "base_desired"), _sig(log, "tip_desired"), _sig(log, "tip_true")
    out: dict[str, np.ndarray] = {}
    if q is not None and q.shape[1] >= 7 and bd is not None and bd.shape[1] >= 7:
        out["base"] = bd[:, :3] - q[:, :3]
        out["att"] = attitude_error(bd[:, 3:7], q[:, 3:7])
    else:
        for key, name in (("base", "e_position"), ("att", "e_attitude")):
            e = _sig(log, name)
            if e is not None and e.ndim == 2 and e.shape[1] == 3:
                out[key] = e
    if td is not None and tip is not None and td.shape[1:] == tip.shape[1:] == (3,) and np.isfinite(tip).any():
        out["tip"] = td - tip
    return out


def _desired_true(a: Axes, t: np.ndarray, true: np.ndarray, desired: np.ndarray | None, labels: list[str],
                  colors=_XYZ) -> None:
    for j, name in enumerate(labels):
        c = colors[j % len(colors)]
        if desired is not None:
            a.plot(t, desired[:, j], "-", color=c, lw=3.5, alpha=0.35, label=f"{name} desired")
        a.plot(t, true[:, j], "-", color=c, lw=1.1, label=name if desired is None else f"{name} actual")


def _error_lines(a: Axes, t: np.ndarray, e: np.ndarray, scale: float, unit: str, labels: list[str]) -> None:
    for j, name in enumerate(labels):
        a.plot(t, scale * e[:, j], color=_XYZ[j], lw=1.1, label=f"{name} (rms {_g(scale * _rms(e[:, j]))} {unit})")
    norm = scale * np.linalg.norm(e, axis=1)
    a.plot(t, norm, color="k", lw=1.3, label=f"norm (max {_g(float(np.nanmax(norm)))} {unit})")


def _robot_tracking_figure(log, robot: Mapping[str, Any], title: str) -> Figure:
    t = np.asarray(log.t, dtype=float)
    q, bd = _sig(log, "q_true"), _sig(log, "base_desired")
    if bd is not None and bd.shape[1] < 7:
        bd = None
    e = robot_errors(log)
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
        _error_lines(a, t, e["base"], 1e3, "mm", ["$e_x$", "$e_y$", "$e_z$"])
    else:
        _missing(a, "not logged (no base_desired / e_position)")
    _finish(a, "error [mm]", "(c) base position error (desired - true), world frame")

    a = ax[1, 1]
    if "att" in e:
        _error_lines(a, t, e["att"], 180 / np.pi, "deg", [r"$e_{\theta x}$", r"$e_{\theta y}$", r"$e_{\theta z}$"])
    else:
        _missing(a, "not logged (no base_desired / e_attitude)")
    _finish(a, "error [deg]", "(d) attitude error (rotation vector, body frame)")

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
        _error_lines(a, t, e["tip"], 1e3, "mm", ["$e_x$", "$e_y$", "$e_z$"])
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
    tau = _sig(log, "torques")
    if tau is not None and tau.ndim == 2 and tau.shape[1]:
        for i, name in enumerate(_names(robot, "motors", tau.shape[1], "motor")):
            a.plot(t, tau[:, i], color=_COLORS[i % len(_COLORS)], lw=1.1, label=name)
        _finish(a, "torque [N m]", "(b) joint torques", legend=False)
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
        fig.savefig(path, dpi=_DPI)
        paths.append(path)
    return paths


def _norm_panel(a: Axes, series: list[tuple[str, str, np.ndarray, np.ndarray]], title: str, unit: str,
                missing: list[str]) -> None:
    """Error norms (>= 0) of several runs; log scale when their peaks differ by more than 30x;
    ``missing``: the runs that did not log this error (noted in the panel)."""
    peaks = [float(np.nanmax(y)) for *_, y in series if len(y) and np.isfinite(y).any()]
    log_scale = len(peaks) > 1 and min(peaks) > 0 and max(peaks) / min(peaks) > 30
    for label, c, t, y in series:
        ok = np.isfinite(y)
        stats = f"rms {_g(_rms(y[ok]))}, max {_g(float(np.max(y[ok])) if ok.any() else float('nan'))} {unit}"
        a.plot(t, y, color=c, lw=1.2, label=f"{label} ({stats})")
    _finish(a, f"|error| [{unit}]", title + (" (log scale)" if log_scale else ""), legend=False, zero=not log_scale)
    if log_scale:
        a.set_yscale("log")
    if a.lines:
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
    panels: list[list[tuple[str, str, np.ndarray, np.ndarray]]] = [[], [], []]
    scale = (1e3, 180 / np.pi, 1e3)
    t_lo, t_hi = np.inf, -np.inf
    for k, (label, log) in enumerate(logs.items()):
        t = np.asarray(log.t, dtype=float)
        if len(t):
            t_lo, t_hi = min(t_lo, float(t[0])), max(t_hi, float(t[-1]))
        e = robot_errors(log)
        for i, key in enumerate(("base", "att", "tip")):
            if key in e:
                panels[i].append((label, _COLORS[k % len(_COLORS)], t, scale[i] * np.linalg.norm(e[key], axis=1)))
    for a, series, title, unit in zip(ax, panels, ("(a) base position error norm, world frame",
                                                   "(b) attitude error angle (rotation vector norm)",
                                                   "(c) end-tip position error norm, world frame"),
                                      ("mm", "deg", "mm")):
        have = {s[0] for s in series}
        _norm_panel(a, series, title, unit, [label for label in logs if label not in have])
        if t_hi > t_lo:
            a.set_xlim(t_lo, t_hi)
    ax[2].set_xlabel("time t [s]")
    fig.savefig(out_path, dpi=_DPI)
    return out_path


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
    attitude error [deg], joint angles [rad] vs ``joints_desired``, the end-tip error [mm] (or
    position); ``_actuation``: thruster forces and commands [N], joint torques [N m], the
    controller's body-frame wrench. Panels whose signals are not logged say so.
    """
    t = np.asarray(log.t, dtype=float)
    if t.ndim != 1 or len(t) < 2:
        raise ValueError(f"the log has {len(t)} samples: at least 2 are needed to plot")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    robot = _robot(log)
    if robot is not None:
        return _plot_robot_run(log, robot, out, stem)
    name = _label(log, stem)
    paths = []
    for suffix, build, what in (("tracking", _tracking_figure, "tracking"),
                                ("actuation", _actuation_figure, "actuation and singularity handling")):
        fig = build(log, f"{name}: {what}")
        path = out / f"{stem}_{suffix}.png"
        fig.savefig(path, dpi=_DPI)
        paths.append(path)
    return paths


def plot_comparison(logs: Mapping[str, Any], out_path: str | Path) -> Path:
    """One figure overlaying, per controller, the base position error norm [mm], the base
    attitude error [mrad] and the end-tip error norm [mm] (desired - true); RMS and max in the
    legend. A panel whose curves differ by more than 30x in size switches to a log scale (and the
    attitude error to its magnitude) so that every controller stays readable.

    Args:
        logs: label (e.g. controller name) -> log of the same scenario.
        out_path: the PNG to write (folders are created).

    Robot logs (all of them; :func:`plot_run`): the base position error norm [mm], the attitude
    error angle [deg] and, when ``tip_desired`` is logged, the end-tip error norm [mm]
    (:func:`robot_errors`).
    """
    if not logs:
        raise ValueError("plot_comparison needs at least one log")
    out_path = Path(out_path)
    robots = {label: _robot(log) for label, log in logs.items()}
    if any(r is not None for r in robots.values()):
        paper = [label for label, r in robots.items() if r is None]
        if paper:
            raise ValueError(f"plot_comparison: {', '.join(map(repr, paper))} are paper (planar) logs and the "
                             "others robot logs: comparing the two kinds is not supported")
        out_path.parent.mkdir(parents=True, exist_ok=True)
        return _plot_robot_comparison(logs, out_path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    fig, ax = _new_figure(3, 1, (11, 9.5))
    ax = ax[:, 0]
    fig.suptitle("controller comparison: tracking errors (desired - true)", fontsize=13)
    colors = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf"]
    panels: list[list[tuple[str, str, np.ndarray, np.ndarray]]] = [[], [], []]
    for k, (label, log) in enumerate(logs.items()):
        t = np.asarray(log.t, dtype=float)
        e = tracking_errors(log)
        c = colors[k % len(colors)]
        if "base" in e:
            panels[0].append((label, c, t, 1e3 * np.hypot(e["base"][:, 0], e["base"][:, 1])))
        if "att" in e:
            panels[1].append((label, c, t, 1e3 * e["att"]))
        if "tip" in e:
            panels[2].append((label, c, t, 1e3 * np.hypot(e["tip"][:, 0], e["tip"][:, 1])))
    titles = ("(a) base position error norm", r"(b) base attitude error $\phi_{0,d} - \phi_0$",
              "(c) end-tip position error norm")
    units = ("mm", "mrad", "mm")
    t_lo, t_hi = np.inf, -np.inf
    for i, (a, series) in enumerate(zip(ax, panels)):
        peaks = [float(np.max(np.abs(y))) for *_, y in series if len(y)]
        log_scale = len(peaks) > 1 and min(peaks) > 0 and max(peaks) / min(peaks) > 30
        positive = []
        for label, c, t, y in series:
            if len(t):
                t_lo, t_hi = min(t_lo, float(t[0])), max(t_hi, float(t[-1]))
            stats = f"rms {_g(_rms(y))}, max {_g(float(np.max(np.abs(y))))} {units[i]}"
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
    fig.savefig(out_path, dpi=_DPI)
    return out_path
