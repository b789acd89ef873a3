"""Sim-to-real: replay recorded pool trials (the Hinsdale 2023 format, :mod:`uvms_mj.analysis.trials`) in
the model and compare its roll and pitch with the IMU.

Per trial (:func:`simulate_trial`):

1. **Arm reference.** The recorded joint states are de-duplicated by :mod:`uvms_mj.analysis.trials` (one
   sample per position update, ~21 Hz), mapped to model joint angles with the model's
   ``hinsdale:joint_offsets``, resampled on a uniform grid of ``SimConfig.joint_dt`` (linear
   interpolation between updates) and smoothed by a zero-phase Butterworth low-pass
   (``SimConfig.cutoff_hz``, order ``SimConfig.filter_order``, ``scipy.signal.filtfilt``). A cubic
   spline through the smoothed grid gives the reference angle, rate and acceleration at any time.
2. **Imposed motion (prescribed joint accelerations).** At every physics step the arm's joint
   torques are those that give the arm joints exactly the acceleration
   ``a = qdd_ref + 2 zeta wn (qd_ref - qd) + wn^2 (q_ref - q)`` (computed torque on the full
   floating-base dynamics, added mass included: ``tau = ((M^-1)_aa)^-1 (a - qacc0_a)`` with
   ``qacc0`` the accelerations without arm torque, from ``mj_forward`` and ``mj_solveM``). The
   vehicle stays free: it feels the arm only through the physics. The torques enter through
   ``qfrc_applied`` (the model's arm motors and their limits are not used); joint limits are
   switched off (the recorded angles touch the shoulder's lower limit). The tracking error (max
   over the trial and joints of ``|q - q_ref|``) is reported; it must stay below
   :data:`MAX_TRACKING_ERROR_DEG`.
3. **Initial state.** Attitude = the IMU quaternion at the first IMU sample at or after the start
   of both records (yaw removed: it does not enter roll, pitch or the physics of a vehicle in
   still water), angular velocity = the IMU's (body frame, as MuJoCo's free joint); linear
   velocity = the mocap's (least-squares slope over the first ``SimConfig.vel_window`` s) when
   a mocap is present, else 0. Thrusters off (ctrl 0).
4. **Buoyancy.** ``SimConfig.neutral`` (default True): the vehicle's mass is set so that the
   whole configuration is neutrally buoyant, as the trials (free floating for tens of seconds)
   show; the change sits at the vehicle's origin (its centre of gravity), so it moves no
   equilibrium taken about that point (:mod:`uvms_mj.analysis.hydrostatics`). The model as written
   sinks at 10.45 N (see ``models/hinsdale2023/hinsdale2023.xml``). An override of ``bluerov2.mass`` wins.
5. **Comparison.** Simulated roll and pitch (Z-Y-X Euler angles, as :func:`trials.roll_pitch_yaw`)
   are interpolated to the IMU's own time stamps; per trial: RMS error of roll and pitch, the
   best constant lag within +-``SimConfig.lag_window`` s (:func:`best_lag`) and the RMS after
   removing it, and the error of the settled attitude change over each arm move
   (:func:`settled_changes`).

Parameter overrides (:func:`load_overrides`, :func:`apply_trial_overrides`) change the model before it
is compiled: a YAML mapping ``"BODY.ATTRIBUTE": value`` (a ``uvms.hydro`` attribute of that body,
``docs/hydrodynamics.md``: ``volume``, ``cob``, ``pos``, ``added_mass``, ``linear_damping``,
``quadratic_damping``, ...), ``"BODY.mass": kg`` (the body's own mass), or
``"water.ATTRIBUTE": value`` (``uvms.water``). :mod:`uvms_mj.analysis.identify` writes such files.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

import mujoco
import numpy as np

from uvms_mj.analysis.trials import (
    DEFAULT_CUTOFF_HZ,
    DEFAULT_FILTER_ORDER,
    JOINT_NAMES,
    Trial,
    lowpass,
    roll_pitch_yaw,
)

__all__ = [
    "DEFAULT_MODEL",
    "MAX_TRACKING_ERROR_DEG",
    "OverrideError",
    "SimConfig",
    "SimResult",
    "TrialScore",
    "apply_trial_overrides",
    "arm_moves",
    "best_lag",
    "build_model",
    "load_overrides",
    "plot_trial",
    "rms",
    "score_trial",
    "settled_changes",
    "simulate_trial",
]

#: The model of the Hinsdale 2023 configuration (``models/<name>/<name>.xml``).
DEFAULT_MODEL = "hinsdale2023"
#: Largest allowed tracking error of the imposed arm motion [deg].
MAX_TRACKING_ERROR_DEG = 0.1
#: Hydro attributes an override may set (``docs/hydrodynamics.md``).
HYDRO_ATTRS = ("pos", "quat", "added_mass", "linear_damping", "quadratic_damping", "strips", "volume", "cob")
#: Attribute sizes (None: several sizes allowed / free form).
_SIZES = {"pos": 3, "quat": 4, "linear_damping": 6, "quadratic_damping": 6, "volume": 1, "cob": 3, "mass": 1,
          "added_mass": None, "strips": None}


@dataclass(frozen=True)
class SimConfig:
    """Settings of a trial replay (every one a documented default; SI units).

    Attributes:
        dt: physics step [s] (the model's own, 0.002 s, when None).
        joint_dt: grid of the resampled joint reference [s] (100 Hz).
        cutoff_hz: low-pass cutoff of the joint reference [Hz] (:data:`trials.DEFAULT_CUTOFF_HZ`).
        filter_order: Butterworth order (filtfilt doubles it).
        servo_wn: natural frequency of the tracking correction of the imposed motion [rad/s].
        servo_zeta: its damping ratio.
        neutral: make the configuration neutrally buoyant through the vehicle mass (see module).
        vel_window: span of the mocap fit of the initial linear velocity [s].
        lag_window: the best lag is searched within +-lag_window [s].
        lag_step: grid of the lag search [s] (refined to 1 ms around the best grid point).
        move_speed: an arm "moves" while any reference joint rate exceeds this [rad/s].
        move_gap: still intervals shorter than this do not end a move [s].
        settle_window: settled attitude = mean over the last ``settle_window`` s of the still
            interval before / after a move [s].
        record_dt: how often the simulated attitude is recorded [s].
    """

    dt: float | None = None
    joint_dt: float = 0.01
    cutoff_hz: float = DEFAULT_CUTOFF_HZ
    filter_order: int = DEFAULT_FILTER_ORDER
    servo_wn: float = 40.0
    servo_zeta: float = 1.0
    neutral: bool = True
    vel_window: float = 1.0
    lag_window: float = 2.0
    lag_step: float = 0.01
    move_speed: float = 0.02
    move_gap: float = 1.0
    settle_window: float = 2.0
    record_dt: float = 0.01


class OverrideError(ValueError):
    """A bad override file or value (the message names the file, key and value)."""


# ------------------------------------------------------------------------------ overrides


def load_overrides(path: str | Path) -> dict[str, Any]:
    """Read an override file (YAML mapping ``"BODY.ATTRIBUTE": value``; see the module docstring).

    Raises:
        OverrideError: missing / unreadable file, not a mapping, bad key or value.
    """
    import yaml

    p = Path(path)
    if not p.is_file():
        raise OverrideError(f"override file {str(p)!r} does not exist")
    if p.stat().st_size > 1_000_000:  # ours: an override file is a few hundred bytes (identify writes one)
        raise OverrideError(f"{p}: {p.stat().st_size} bytes; an override file is at most 1000000 bytes")
    try:
        doc = yaml.safe_load(p.read_text())
    except UnicodeDecodeError as e:
        raise OverrideError(f"{p}: not a UTF-8 text file (byte {e.start}: {e.reason})") from None
    except (OSError, yaml.YAMLError) as e:
        raise OverrideError(f"{p}: unreadable YAML: {' '.join(str(e).split())}") from None
    if doc is None:
        return {}
    if not isinstance(doc, dict):
        raise OverrideError(f"{p}: must be a mapping 'BODY.ATTRIBUTE: value', got {type(doc).__name__}")
    out = {}
    for k, v in doc.items():
        out[str(k)] = _check_value(str(k), v, str(p))
    return out


def _check_value(key: str, v: Any, source: str) -> list[float]:
    body, dot, attr = key.rpartition(".")
    if not dot or not body:
        raise OverrideError(f"{source}: key {key!r} must be 'BODY.ATTRIBUTE' (e.g. bluerov2.cob)")
    if body != "water" and attr not in HYDRO_ATTRS + ("mass",):
        raise OverrideError(f"{source}: {key}: unknown attribute {attr!r} (one of {', '.join(HYDRO_ATTRS + ('mass',))})")
    vals = v if isinstance(v, (list, tuple)) else [v]
    try:
        f = [float(x) for x in vals]
        if any(isinstance(x, bool) for x in vals):
            raise TypeError
    except (TypeError, ValueError):
        raise OverrideError(f"{source}: {key}: value {v!r} must be a number or a list of numbers") from None
    if not all(math.isfinite(x) for x in f):
        raise OverrideError(f"{source}: {key}: value {v!r} must be finite")
    from uvms_mj.plant.robot import OVERRIDE_MAX, OVERRIDE_MIN, SCALE_FIELDS  # the scenario overrides' bounds

    tiny = attr in SCALE_FIELDS and any(0 < abs(x) < OVERRIDE_MIN for x in f)
    if tiny or any(abs(x) > OVERRIDE_MAX for x in f):
        raise OverrideError(f"{source}: {key}: value {v!r}: each number must be at most {OVERRIDE_MAX:g} in "
                            f"magnitude (a scale such as a mass or a volume: 0 or at least {OVERRIDE_MIN:g})")
    n = _SIZES.get(attr)
    if body != "water" and n is not None and len(f) != n:
        raise OverrideError(f"{source}: {key}: needs {n} number(s), got {len(f)}")
    if attr in ("mass", "volume") and f[0] < 0:
        raise OverrideError(f"{source}: {key}: must be >= 0, got {f[0]}")
    return f


def apply_trial_overrides(spec: mujoco.MjSpec, overrides: Mapping[str, Any], source: str = "overrides") -> None:
    """Apply ``{"BODY.ATTRIBUTE": value}`` to a spec (before compiling).

    Raises:
        OverrideError: an unknown body or a body without uvms.hydro parameters.
    """
    from uvms_mj.physics.model import ModelError, fmt, set_body, set_water

    for key, v in overrides.items():
        vals = _check_value(key, v, source)
        body, _, attr = key.rpartition(".")
        try:
            if body == "water":
                set_water(spec, **{attr: fmt(vals)})
            elif attr == "mass":
                b = spec.body(body)
                if b is None:
                    raise ModelError(f"the model has no body named {body!r}")
                b.mass = vals[0]
            else:
                set_body(spec, body, **{attr: fmt(vals)})
        except ModelError as e:
            raise OverrideError(f"{source}: {key}: {e}") from None


def model_path(model: str | Path) -> Path:
    """``models/<name>/<name>.xml`` for a bare name, else the path itself."""
    p = Path(model)
    if p.suffix == ".xml" or p.exists():
        return p
    from uvms_mj.plant.plant import models_dir

    return models_dir() / str(model) / f"{model}.xml"


def build_model(model: str | Path = DEFAULT_MODEL, overrides: Mapping[str, Any] | None = None,
                neutral: bool = True, dt: float | None = None) -> mujoco.MjModel:
    """Compile the trial model with overrides; optionally neutral (vehicle mass adjusted).

    Raises:
        OverrideError, uvms_mj.physics.ModelError.
    """
    from uvms_mj.physics import compile_spec, load_spec

    path = model_path(model)
    spec = load_spec(path)
    overrides = dict(overrides or {})
    apply_trial_overrides(spec, overrides)
    m = compile_spec(spec, source=path.name)
    root = _root_body(m)
    if neutral and f"{m.body(root).name}.mass" not in overrides:
        net = _net_force(m)
        spec.body(m.body(root).name).mass = float(m.body_mass[root] + net / np.linalg.norm(m.opt.gravity))
        m = compile_spec(spec, source=path.name)
    if dt is not None:
        m.opt.timestep = float(dt)
    return m


def _root_body(m: mujoco.MjModel) -> int:
    free = [j for j in range(m.njnt) if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE]
    if not free:
        raise ValueError("the model has no free joint")
    return int(m.jnt_bodyid[free[0]])


def _net_force(m: mujoco.MjModel) -> float:
    """Buoyancy minus weight of the whole model [N] (> 0: floats up)."""
    from uvms_mj.physics import hydro_of

    info = hydro_of(m)
    g = float(np.linalg.norm(m.opt.gravity))
    rho = float(info.water.density)
    return rho * g * sum(h.volume for h in info.bodies.values()) - g * float(m.body_mass.sum())


# ------------------------------------------------------------------------------ simulation


@dataclass
class SimResult:
    """A simulated trial.

    Attributes:
        trial: name; t: (K,) record times [s]; roll, pitch: (K,) simulated [rad];
        q_err_max: max |q - q_ref| [rad] over the run and the arm joints;
        tau_max: (4,) max |arm joint torque| [N m];
        t_ref, q_ref: (M,), (M, 4) the smoothed joint reference on its grid;
        t0, t1: simulated span [s]; wall_s: time taken [s]; steps: physics steps.
    """

    trial: str
    t: np.ndarray
    roll: np.ndarray
    pitch: np.ndarray
    q_err_max: float
    tau_max: np.ndarray
    t_ref: np.ndarray
    q_ref: np.ndarray
    t0: float
    t1: float
    wall_s: float = 0.0
    steps: int = 0


def joint_reference(trial: Trial, cfg: SimConfig = SimConfig()):
    """``(t, q, spline)``: the smoothed joint reference on its grid and a CubicSpline of it
    (``spline(t, 1)``: rates, ``spline(t, 2)``: accelerations)."""
    from scipy.interpolate import CubicSpline

    t, q = trial.joints.resampled(cfg.joint_dt)
    if len(t) > 9 * (cfg.filter_order + 1):  # filtfilt needs more than its padding (3 (order + 1))
        q = lowpass(q, cfg.joint_dt, cfg.cutoff_hz, cfg.filter_order)
    return t, q, CubicSpline(t, q, axis=0, bc_type="natural")


def _initial_state(trial: Trial, t0: float, cfg: SimConfig):
    imu = trial.imu
    k = int(np.searchsorted(imu.t, t0))
    qx, qy, qz, qw = imu.quat[k]
    r, p, _ = roll_pitch_yaw(imu.quat[k])
    r, p = float(r), float(p)
    # yaw removed: R = Ry(p) Rx(r)  (w x y z)
    cr, sr, cp, sp = math.cos(r / 2), math.sin(r / 2), math.cos(p / 2), math.sin(p / 2)
    quat = np.array([cp * cr, cp * sr, sp * cr, -sp * sr])
    w = np.zeros(3) if imu.ang_vel is None else imu.ang_vel[k].astype(float)
    v = np.zeros(3)
    mc = trial.mocap
    if mc is not None:
        sel = (mc.t >= imu.t[k]) & (mc.t < imu.t[k] + cfg.vel_window)
        if sel.sum() >= 5:
            tt = mc.t[sel] - mc.t[sel].mean()
            v = np.array([float(np.polyfit(tt, mc.pos[sel, i], 1)[0]) for i in range(3)])
            # world velocity, rotated by -yaw of the mocap (our yaw is 0)
            yaw = float(np.median(mc.yaw[sel]))
            c, s = math.cos(-yaw), math.sin(-yaw)
            v = np.array([c * v[0] - s * v[1], s * v[0] + c * v[1], v[2]])
    return float(imu.t[k]), quat, w, v


def simulate_trial(m: mujoco.MjModel, trial: Trial, cfg: SimConfig = SimConfig(),
                   joint_names: Sequence[str] = JOINT_NAMES) -> SimResult:
    """Replay one trial in the model (see the module docstring)."""
    import time

    wall0 = time.perf_counter()
    m = _copy(m)
    if cfg.dt is not None:
        m.opt.timestep = float(cfg.dt)
    m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_LIMIT)
    d = mujoco.MjData(m)
    t_ref, q_ref, spl = joint_reference(trial, cfg)
    t_start = max(trial.imu.t[0], t_ref[0])
    t1 = min(trial.t_end, t_ref[-1])
    t0, quat, w, v = _initial_state(trial, t_start, cfg)
    root = _root_body(m)
    fj = [j for j in range(m.njnt) if m.jnt_bodyid[j] == root and m.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE][0]
    qa, va = int(m.jnt_qposadr[fj]), int(m.jnt_dofadr[fj])
    jq = np.array([int(m.joint(n).qposadr[0]) for n in joint_names])
    jv = np.array([int(m.joint(n).dofadr[0]) for n in joint_names])
    mujoco.mj_resetData(m, d)
    d.qpos[qa:qa + 3] = 0.0
    d.qpos[qa + 3:qa + 7] = quat
    d.qvel[va:va + 3] = v
    d.qvel[va + 3:va + 6] = w
    d.qpos[jq] = spl(t0)
    d.qvel[jv] = spl(t0, 1)
    d.time = t0
    d.ctrl[:] = 0.0
    h = m.opt.timestep
    n = int(math.floor((t1 - t0) / h + 1e-9))
    every = max(1, int(round(cfg.record_dt / h)))
    kp, kd = cfg.servo_wn ** 2, 2 * cfg.servo_zeta * cfg.servo_wn
    E = np.zeros((len(jv), m.nv))
    E[np.arange(len(jv)), jv] = 1.0
    X = np.zeros_like(E)
    ts, rs, ps = [], [], []
    err_max, tau_max = 0.0, np.zeros(len(jv))
    tq = t0 + h * np.arange(n + 1)
    Q, QD, QDD = spl(tq), spl(tq, 1), spl(tq, 2)

    def record():
        qw, qx, qy, qz = d.qpos[qa + 3:qa + 7]
        r, p, _ = roll_pitch_yaw(np.array([qx, qy, qz, qw]))
        ts.append(d.time)
        rs.append(float(r))
        ps.append(float(p))

    record()
    for k in range(n):
        e = Q[k] - d.qpos[jq]
        err_max = max(err_max, float(np.abs(e).max()))
        d.qfrc_applied[:] = 0.0
        mujoco.mj_forward(m, d)
        if not np.all(np.isfinite(d.qacc)):
            raise RuntimeError(f"trial {trial.name}: the simulation diverged at t = {d.time:.3f} s")
        mujoco.mj_solveM(m, d, X, E)
        A = X[:, jv]
        a = QDD[k] + kd * (QD[k] - d.qvel[jv]) + kp * e
        tau = np.linalg.solve(A, a - d.qacc[jv])
        tau_max = np.maximum(tau_max, np.abs(tau))
        d.qfrc_applied[jv] = tau
        mujoco.mj_step(m, d)
        if (k + 1) % every == 0:
            record()
    err_max = max(err_max, float(np.abs(Q[n] - d.qpos[jq]).max()))
    return SimResult(trial.name, np.array(ts), np.array(rs), np.array(ps), err_max, tau_max, t_ref, q_ref,
                     t0, float(d.time), time.perf_counter() - wall0, n)


def _copy(m: mujoco.MjModel) -> mujoco.MjModel:
    from uvms_mj.physics.model import copy_model

    return copy_model(m)


# ------------------------------------------------------------------------------ metrics


def rms(x: np.ndarray) -> float:
    """Root mean square (NaN for no samples)."""
    x = np.asarray(x, float)
    return float(np.sqrt(np.mean(x ** 2))) if x.size else math.nan


def _shifted_err(t_meas, meas, t_sim, sim, lag):
    """Errors sim(t - lag) - meas(t) at the measurement times where t - lag is simulated."""
    tt = t_meas - lag
    sel = (tt >= t_sim[0]) & (tt <= t_sim[-1])
    out = [np.interp(tt[sel], t_sim, s) - mm[sel] for s, mm in zip(sim, meas)]
    return out, sel


def best_lag(t_meas: np.ndarray, meas: Sequence[np.ndarray], t_sim: np.ndarray, sim: Sequence[np.ndarray],
             window: float = 2.0, step: float = 0.01) -> tuple[float, list[float]]:
    """The constant lag within +-window that minimises the pooled RMS of ``sim(t - lag) - meas(t)``
    over all channels (lag > 0: the measurement follows the simulation), searched on a grid of
    ``step`` and refined to 1 ms around the best grid point. Returns (lag [s], RMS per channel).
    Only times where the shifted simulation exists count (their mean is taken, so a shift does not
    gain by dropping samples)."""
    def cost(lag):
        e, sel = _shifted_err(t_meas, meas, t_sim, sim, lag)
        if sel.sum() < 2:
            return math.inf
        return float(np.mean(np.concatenate(e) ** 2))

    grid = np.arange(-window, window + 0.5 * step, step)
    c = np.array([cost(x) for x in grid])
    b = float(grid[int(np.argmin(c))])
    fine = np.arange(max(-window, b - step), min(window, b + step) + 1e-4, 0.001)
    cf = np.array([cost(x) for x in fine])
    lag = round(float(fine[int(np.argmin(cf))]), 3)
    e, _ = _shifted_err(t_meas, meas, t_sim, sim, lag)
    return lag, [rms(x) for x in e]


def arm_moves(t: np.ndarray, q: np.ndarray, speed: float = 0.02, gap: float = 1.0) -> list[tuple[float, float]]:
    """Spans (t_start, t_end) [s] where the arm moves: any joint rate (finite differences of the
    smoothed reference) above ``speed`` [rad/s]; spans separated by less than ``gap`` s merge."""
    if len(t) < 2:
        return []
    qd = np.gradient(q, t, axis=0)
    moving = np.any(np.abs(qd) > speed, axis=1)
    spans = []
    k = 0
    while k < len(t):
        if moving[k]:
            j = k
            while j + 1 < len(t) and moving[j + 1]:
                j += 1
            spans.append([float(t[k]), float(t[j])])
            k = j + 1
        else:
            k += 1
    merged = []
    for s in spans:
        if merged and s[0] - merged[-1][1] < gap:
            merged[-1][1] = s[1]
        else:
            merged.append(s)
    return [tuple(s) for s in merged]


def settled_changes(t_meas, meas, t_sim, sim, moves, t_span, window: float = 2.0) -> list[dict]:
    """Per arm move: the settled attitude change (mean over the last ``window`` s of the still
    interval after the move minus that before it), measured and simulated, per channel [rad].

    Args:
        t_meas, meas: measurement times and channels (e.g. roll, pitch); t_sim, sim: the same of
            the simulation; moves: :func:`arm_moves` spans; t_span: (t0, t1) of the comparison.

    Returns:
        One dict per move with ``move`` (t_start, t_end), ``pre`` and ``post`` windows,
        ``meas``, ``sim`` (lists per channel) and ``err`` (sim - meas). Moves without a still
        interval of at least 0.2 s on both sides are left out.
    """
    out = []
    bounds = [t_span[0]] + [x for mv in moves for x in mv] + [t_span[1]]
    for i, mv in enumerate(moves):
        still_before = (bounds[2 * i], mv[0])
        still_after = (mv[1], bounds[2 * i + 3])
        if still_before[1] - still_before[0] < 0.2 or still_after[1] - still_after[0] < 0.2:
            continue
        pre = (max(still_before[0], still_before[1] - window), still_before[1])
        post = (max(still_after[0], still_after[1] - window), still_after[1])

        def mean(tt, x, w):
            sel = (tt >= w[0]) & (tt <= w[1])
            return float(np.mean(x[sel])) if sel.any() else math.nan

        dm = [mean(t_meas, x, post) - mean(t_meas, x, pre) for x in meas]
        ds = [mean(t_sim, x, post) - mean(t_sim, x, pre) for x in sim]
        out.append({"move": list(mv), "pre": list(pre), "post": list(post), "meas": dm, "sim": ds,
                    "err": [a - b for a, b in zip(ds, dm)]})
    return out


@dataclass
class TrialScore:
    """Scores of one trial (degrees, seconds).

    Attributes:
        trial; n: IMU samples compared; rms_roll, rms_pitch; lag: best lag [s] (None when the
        arm does not move: a still trial has nothing to align);
        rms_roll_lag, rms_pitch_lag: after removing it; changes: settled changes per move
        (degrees, see :func:`settled_changes`); tracking_deg: max arm tracking error;
        tau_max: max |arm torque| per joint [N m]; span: (t0, t1); wall_s: simulation time.
    """

    trial: str
    n: int
    rms_roll: float
    rms_pitch: float
    lag: float | None
    rms_roll_lag: float
    rms_pitch_lag: float
    changes: list
    tracking_deg: float
    tau_max: list
    span: tuple
    wall_s: float
    moves: list = field(default_factory=list)

    @property
    def rms_both(self) -> float:
        return math.sqrt(0.5 * (self.rms_roll ** 2 + self.rms_pitch ** 2))

    def to_json(self) -> dict:
        d = asdict(self)
        d["rms_both"] = self.rms_both
        d["tracking_ok"] = self.tracking_deg < MAX_TRACKING_ERROR_DEG
        return d


def score_trial(trial: Trial, sim: SimResult, cfg: SimConfig = SimConfig()) -> TrialScore:
    """Compare a simulated trial with its IMU (at the IMU's own time stamps)."""
    imu = trial.imu
    sel = (imu.t >= sim.t[0]) & (imu.t <= sim.t[-1])
    tm = imu.t[sel]
    meas = [imu.roll[sel], imu.pitch[sel]]
    simv = [np.interp(tm, sim.t, sim.roll), np.interp(tm, sim.t, sim.pitch)]
    er, ep = simv[0] - meas[0], simv[1] - meas[1]
    moves = arm_moves(sim.t_ref, sim.q_ref, cfg.move_speed, cfg.move_gap)
    if moves:
        lag, (rr, rp) = best_lag(tm, meas, sim.t, [sim.roll, sim.pitch], cfg.lag_window, cfg.lag_step)
    else:  # arm still: nothing to align, the lag is undefined
        lag, rr, rp = None, rms(er), rms(ep)
    ch = settled_changes(tm, meas, sim.t, [sim.roll, sim.pitch], moves, (sim.t[0], sim.t[-1]), cfg.settle_window)
    for c in ch:
        for k in ("meas", "sim", "err"):
            c[k] = [math.degrees(x) for x in c[k]]
    deg = math.degrees
    return TrialScore(trial.name, int(sel.sum()), deg(rms(er)), deg(rms(ep)), lag, deg(rr), deg(rp), ch,
                      deg(sim.q_err_max), [float(x) for x in sim.tau_max], (sim.t0, sim.t1), sim.wall_s,
                      [list(mv) for mv in moves])


# ------------------------------------------------------------------------------ figure


def plot_trial(trial: Trial, sim: SimResult, score: TrialScore | None, path: str | Path, title: str | None = None,
               dpi: int = 90, label: str = "simulated", others: Sequence[tuple[str, SimResult]] = ()) -> Path:
    """Measured vs simulated roll and pitch of one trial (PNG, matplotlib Agg); ``others``:
    further simulations (label, result) drawn dashed (e.g. the nominal model)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(2, 1, figsize=(7.5, 4.6), sharex=True)
    imu = trial.imu
    sel = (imu.t >= sim.t[0] - 0.5) & (imu.t <= sim.t[-1] + 0.5)
    for ax, meas, simv, name, key in ((axs[0], imu.roll, sim.roll, "roll", "rms_roll"),
                                      (axs[1], imu.pitch, sim.pitch, "pitch", "rms_pitch")):
        ax.plot(imu.t[sel], np.degrees(meas[sel]), "k-", lw=1.2, label="IMU")
        for i, (lab, o) in enumerate(others):
            ax.plot(o.t, np.degrees(o.roll if name == "roll" else o.pitch), "--", color=f"C{i + 1}", lw=1.0, label=lab)
        ax.plot(sim.t, np.degrees(simv), "C0-", lw=1.2, label=label)
        if score is not None:
            for mv in score.moves:
                ax.axvspan(mv[0], mv[1], color="0.9", zorder=0)
            ax.set_title(f"{name}: RMS {getattr(score, key):.2f} deg", fontsize=9, loc="left")
        ax.set_ylabel(f"{name} [deg]")
        ax.grid(alpha=0.3)
    axs[0].legend(fontsize=8, loc="best")
    axs[1].set_xlabel("trial time [s] (grey: arm moving)")
    fig.suptitle(title or f"trial {trial.name}", fontsize=10)
    fig.tight_layout()
    p = Path(path)
    from uvms_mj.io.atomic import atomic_path

    with atomic_path(p) as tmp:
        fig.savefig(tmp, dpi=dpi, format="png")
    plt.close(fig)
    return p
