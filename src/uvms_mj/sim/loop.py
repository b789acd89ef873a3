"""The sampled loop: plant at its own dt, controller every T with a zero-order hold.

Measurements are sampled at kT: base pose and joint angles, with optional Gaussian noise,
quantization and a one-sample delay (:class:`SensorModel`); velocities come from a velocity
sensor if configured, else the controller differentiates positions. Every controller signal and
the true plant state are recorded per sample (:class:`uvms_mj.sim.samples.SampleRecord`: arrays
of the run's final size), or, with ``keep=False``, streamed to the sink and the metrics'
accumulator a chunk at a time (memory that does not grow with the duration). A diverging plant stops the run cleanly with the time and the reason
(the record up to then is kept).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping

import numpy as np

from uvms_mj.control.base import Command, Controller, Measurement
from uvms_mj.plant.plant import DivergenceError, Plant, mujoco_warnings
from uvms_mj.rotations import quat_from_rotvec, quat_mul, quat_to_mat, rotation_log
from uvms_mj.sim.limits import joint_limit_reason, joint_limit_status, plant_joint_ranges
from uvms_mj.sim.metrics import RunMetrics
from uvms_mj.sim.samples import SampleRecord
from uvms_mj.sim.sensors import Signal, SignalSensors


#: A thrust or joint-torque command beyond this [N, N m] is taken as divergence of the
#: controller (the robot's actuators give tens of N; the plant saturates them anyway).
COMMAND_ABS_MAX = 1e6


@dataclass(frozen=True)
class SensorModel:
    """Measurement model (all off by default).

    Attributes:
        position_noise: std of Gaussian noise on p0x, p0y [m].
        angle_noise: std of Gaussian noise on phi0, phi1, phi2 [rad] (shorthand for both below).
        attitude_noise: std on the base attitude phi0 [rad] (None: angle_noise).
        joint_noise: std on the joint encoders phi1, phi2 [rad] (None: angle_noise).
        position_quantum, angle_quantum: quantization steps [m], [rad] (0: none).
        delay: samples of measurement/computation delay (0 or 1).
        velocity_sensor: give the controller the true velocities (plus velocity_noise).
        velocity_noise: std of Gaussian noise on the measured velocities [m/s, rad/s].
        signals: per-signal sensors instead of the fields above (:mod:`uvms_mj.sim.sensors`:
            ``{"position": Signal(...), "attitude": ..., "joints": ..., "velocity": ...}``, each
            with its noise, bias, quantization, rate and delay); None: the fields above.
    """

    position_noise: float = 0.0
    angle_noise: float = 0.0
    position_quantum: float = 0.0
    angle_quantum: float = 0.0
    delay: int = 0
    velocity_sensor: bool = False
    velocity_noise: float = 0.0
    attitude_noise: float | None = None
    joint_noise: float | None = None
    signals: Mapping[str, Signal] | None = None

    def __post_init__(self) -> None:
        for name in ("position_noise", "angle_noise", "position_quantum", "angle_quantum", "velocity_noise",
                     "attitude_noise", "joint_noise"):
            v = getattr(self, name)
            if v is None and name in ("attitude_noise", "joint_noise"):
                continue
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"sensor.{name} = {v!r} must be finite and >= 0")
        if self.delay not in (0, 1):
            raise ValueError(f"sensor.delay = {self.delay!r}; allowed: 0, 1 (samples)")
        if self.signals:
            flat = [name for name in ("position_noise", "angle_noise", "position_quantum", "angle_quantum", "delay",
                                      "velocity_sensor", "velocity_noise", "attitude_noise", "joint_noise")
                    if getattr(self, name)]
            if flat:
                raise ValueError(f"sensor: give either the per-signal sensors (signals) or {', '.join(flat)}, not both")


@dataclass
class RunResult:
    """A closed-loop run.

    Attributes:
        t: sample times [s] (N).
        signals: name -> array (N, ...) of controller signals, thruster forces and the true state
            (``q_true``, ``qd_true``, ``tip_true``; ``thrust_command``: the controller's thrusts,
            ``thrust_force``: what the thrusters give at the sample, lagged and clipped;
            ``torques``: the controller's joint torques, ``torques_applied``: what the motors
            apply over the sample, after MuJoCo's control and force ranges).
        status: "ok", "diverged" or "joint_limit" (finished, but a joint left the plant's
            range by more than :data:`uvms_mj.sim.limits.JOINT_LIMIT_TOLERANCE_DEG`).
        reason: why it stopped early, or which joint left its range ("" if ok).
        meta: ``T``, ``dt``, ``seed``, ``controller``, ``samples`` (recorded), ``t_end`` (the
            last sample's time [s], NaN without one), ``joint_ranges`` (the plant's limited
            hinges, :func:`uvms_mj.sim.limits.plant_joint_ranges`) and, for a controller with a
            ``resolved_params`` dict (RAC: its thresholds as numbers), ``controller_params``.
        navigation: the navigation sensors' samples
            (:class:`uvms_mj.sim.navsensors.NavigationRecord`) of a run with ``navigation``; else None.
        metrics: the run's metrics accumulated as it ran (``run_closed_loop(keep=False)``:
            :class:`uvms_mj.sim.metrics.RunMetrics`), else None (:func:`uvms_mj.sim.metrics.metrics`
            computes them from ``signals``).
    """

    t: np.ndarray
    signals: dict[str, np.ndarray]
    status: str = "ok"
    reason: str = ""
    meta: dict = field(default_factory=dict)
    navigation: Any = None
    metrics: dict | None = None


def _quantize(x: np.ndarray, quantum: float) -> np.ndarray:
    return np.round(x / quantum) * quantum if quantum > 0 else x


def _observe(plant) -> tuple:
    """(q, qd, tip, thrust or None) now: Plant.observe, else the plant's properties."""
    if hasattr(plant, "observe"):
        return plant.observe()
    return plant.q, plant.qd, plant.tip_position, None


def _command(plant, thrust: np.ndarray, torques: np.ndarray) -> None:
    if hasattr(plant, "command"):
        plant.command(thrust, torques, finite=True)  # checked by the loop
    else:
        plant.set_thrust(thrust)
        plant.set_joint_torques(torques)


def _step_observe(plant, n: int) -> tuple:
    if hasattr(plant, "step_observe"):
        return plant.step_observe(n)
    plant.step(n)
    return plant.q, plant.qd, plant.tip_position, None


def controller_name(controller: Controller) -> str:
    """The controller's registry name, else its class name (a plug-in created directly)."""
    return str(getattr(controller, "name", "") or type(controller).__name__)


def measure_robot(plant, layout, sensor: SensorModel, rng: np.random.Generator, q_true: np.ndarray | None = None,
                  qd_true: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
    """(qpos, qvel or None) as measured on a floating robot (a :class:`uvms_mj.plant.plant.Plant` whose vehicle is on a free joint).

    Noise: ``position_noise`` on the vehicle's world position (3), ``attitude_noise`` as a
    body-frame rotation vector with that std per axis composed with the true orientation
    (q_meas = q_true * exp(n)), ``joint_noise`` on the joint angles; quantization of the position
    (``position_quantum``) and the joint angles (``angle_quantum``; the quaternion is not
    quantized); ``velocity_sensor``: the true qvel (v world, omega body, joint rates) plus
    ``velocity_noise``. Random numbers are drawn in that order, only for non-zero stds.
    ``q_true`` / ``qd_true``: the state to measure (default: the plant's now).
    """
    q = plant.q if q_true is None else np.array(q_true, dtype=float)
    a = layout.base_qadr
    att_noise = sensor.angle_noise if sensor.attitude_noise is None else sensor.attitude_noise
    joint_noise = sensor.angle_noise if sensor.joint_noise is None else sensor.joint_noise
    if sensor.position_noise:
        q[a:a + 3] += rng.normal(0.0, sensor.position_noise, 3)
    if att_noise:
        qq = quat_mul(q[a + 3:a + 7], quat_from_rotvec(rng.normal(0.0, att_noise, 3)))
        q[a + 3:a + 7] = qq / np.linalg.norm(qq)
    ja = layout.joint_qadr
    if joint_noise and len(ja):
        q[ja] += rng.normal(0.0, joint_noise, len(ja))
    if sensor.position_quantum:
        q[a:a + 3] = _quantize(q[a:a + 3], sensor.position_quantum)
    if sensor.angle_quantum and len(ja):
        q[ja] = _quantize(q[ja], sensor.angle_quantum)
    qd = None
    if sensor.velocity_sensor:
        qd = plant.qd if qd_true is None else np.array(qd_true, dtype=float)
        if sensor.velocity_noise:
            qd = qd + rng.normal(0.0, sensor.velocity_noise, qd.size)
    return q, qd


def _start_estimator(navigation, nav, plant, layout, q_true: np.ndarray, qd_true: np.ndarray):
    """The online ESKF (:class:`uvms_mj.estimation.online.OnlineEstimator`) started at the true pose and
    velocity of the first sample (our assumption; its prior covariance is ``online.P0_SIGMA``)."""
    from uvms_mj.estimation.online import OnlineEstimator

    a, d = layout.base_qadr, layout.base_dadr
    return OnlineEstimator(navigation, nav.record, plant.model.opt.gravity, nav.rho, q_true[a:a + 3].copy(),
                           qd_true[d:d + 3].copy(), q_true[a + 3:a + 7].copy(), trim=nav.keep != "all")


def _estimated(est, meas: Measurement, layout, q_true: np.ndarray, t: float) -> tuple[Measurement, dict]:
    """``meas`` with the vehicle's pose (and, when measured, velocity: world linear, body angular, the free
    joint's qvel convention) replaced by the online estimate at ``t`` after feeding what has arrived by then;
    and the row of the estimate's signals (run_closed_loop's ``feedback``)."""
    est.feed(t)
    e = est.state(t)
    a, d = layout.base_qadr, layout.base_dadr
    q = np.array(meas.q, dtype=float)
    q[a:a + 3] = e.position
    q[a + 3:a + 7] = e.quat / np.linalg.norm(e.quat)
    qd = None
    if meas.qd is not None:
        qd = np.array(meas.qd, dtype=float)
        qd[d:d + 3] = e.velocity
        qd[d + 3:d + 6] = e.angular_velocity
    R_err = quat_to_mat(q[a + 3:a + 7]).T @ quat_to_mat(q_true[a + 3:a + 7])
    row = {"nav_estimate": np.r_[e.position, q[a + 3:a + 7]], "nav_sigma_pos": e.sigma[0:3],
           "nav_sigma_att": e.sigma[6:9],
           "nav_error_pos": q_true[a:a + 3] - e.position, "nav_error_att": rotation_log(R_err)}
    return Measurement(k=meas.k, t=meas.t, q=q, qd=qd), row


def run_closed_loop(
    plant: Plant,
    controller: Controller,
    duration: float,
    T: float = 1.0 / 60.0,
    sensor: SensorModel = SensorModel(),
    seed: int = 0,
    warm_start: bool = True,
    on_sample: Callable[[int, int], None] | None = None,
    sink: Callable[[float, dict], None] | None = None,
    navigation: Any = None,
    nav_sink: Callable[[str, Any, dict], None] | None = None,
    feedback: str = "truth",
    keep: bool = True,
) -> RunResult:
    """Run ``controller`` on ``plant`` for ``duration`` seconds.

    Args:
        T: controller period [s]; must be a whole number of plant steps.
        warm_start: start the thrusters' lag state at the first command (the robot is holding
            station when the run starts) instead of at 0 N; see docs/paper-reading.md "Start-up".
        on_sample: progress callback (k, n_samples).
        sink: called with (t, row) for every sample as it happens (e.g. an MCAP recorder's
            ``write_sample``), row mapping signal names to floats, ints, bools or 1-D arrays;
            the same rows make up the returned :class:`RunResult`.
        navigation: the navigation sensors (:class:`uvms_mj.sim.navsensors.NavigationConfig`;
            the plant built with their :func:`~uvms_mj.sim.navsensors.add_to_spec`), sampled
            between the plant's steps into ``RunResult.navigation``; the controller does not see them.
        nav_sink: called with (kind, sample, extra) for every navigation sample as it is taken
            (e.g. an MCAP recorder's ``write_navigation``).
        feedback: ``"truth"`` (the measured truth of ``sensor``) or ``"estimate"``: the ESKF runs online on
            the navigation samples as they arrive (:class:`uvms_mj.estimation.online.OnlineEstimator`) and the
            controller's vehicle pose (and velocity, with a velocity sensor) is its estimate at the sample;
            the joints stay ``sensor``'s. Logs ``nav_estimate`` (position world, quat w x y z),
            ``nav_sigma_pos`` [m], ``nav_sigma_att`` [rad] (body), ``nav_error_pos`` (true - estimate,
            world [m]) and ``nav_error_att``
            (the rotation vector of R_est^T R_true, body [rad]).
        keep: keep every sample's signals in the result (``RunResult.t``, ``signals``, and the
            navigation samples). False: nothing grows with the run's duration: the rows go to
            ``sink`` only, the metrics are accumulated as the run goes
            (:class:`uvms_mj.sim.metrics.RunMetrics`, into ``RunResult.metrics``; the same numbers
            as :func:`uvms_mj.sim.metrics.metrics` of the kept run), ``t`` and ``signals`` are
            empty (``meta["samples"]`` and ``meta["t_end"]`` say how far the run got) and
            ``navigation`` holds the sensors' mounts only.
    """
    if feedback not in ("truth", "estimate"):
        raise ValueError(f"feedback = {feedback!r}; allowed: truth, estimate")
    dt = plant.model.opt.timestep
    sub = T / dt
    if abs(sub - round(sub)) > 1e-9 or round(sub) < 1:
        raise ValueError(f"T = {T!r} s must be a whole multiple of the plant timestep {dt!r} s")
    sub = int(round(sub))
    n = int(math.floor(duration / T + 1e-9)) + 1
    rng = np.random.default_rng(seed)
    ranges = plant_joint_ranges(plant.model)
    layout = getattr(plant, "layout", None)  # a free vehicle: measured by its layout (measure_robot)
    if layout is not None and not layout.base_free:
        layout = None  # a planar base (the paper's): the planar measurement below
    acc = None
    if keep:
        rows = SampleRecord(n)  # every signal in one array of the run's size (memory: the values only)
        times = np.empty(n)
    else:  # streamed: the metrics as the rows come, a chunk at a time (memory: one chunk)
        acc = RunMetrics({"T": T, "joint_ranges": ranges,
                          **({"robot": {"layout": layout.describe()}} if layout is not None else {})})

        def block(start: int, m: int, signals: dict) -> None:
            acc.add((start + np.arange(m)) * T, signals)

        rows = SampleRecord(n, on_block=block)
        times = None
    status, reason = "ok", ""
    q_prev_meas = None
    mujoco_warnings(clear=True)  # only this run's

    att_noise = sensor.angle_noise if sensor.attitude_noise is None else sensor.attitude_noise
    joint_noise = sensor.angle_noise if sensor.joint_noise is None else sensor.joint_noise
    angle_std = np.array([att_noise, joint_noise, joint_noise], dtype=float)
    noisy = bool(sensor.position_noise or att_noise or joint_noise)
    quantized = bool(sensor.position_quantum or sensor.angle_quantum)

    per_signal = SignalSensors(sensor.signals, T, seed, plant.layout) if sensor.signals else None
    nav = None
    if navigation is not None:
        from uvms_mj.sim.navsensors import NavigationSuite

        hydro = getattr(plant, "hydro_info", None)
        nav = NavigationSuite(plant.model, plant.data, navigation, seed, plant.layout.base_body,
                              float(hydro.water.density) if hydro is not None else 1000.0, sink=nav_sink,
                              keep="all" if keep else "samples" if feedback == "estimate" else "none")
    est = None  # feedback = "estimate": the online ESKF, started at the first sample
    if feedback == "estimate" and (nav is None or layout is None):
        raise ValueError("feedback = 'estimate' needs navigation sensors on a robot with a free vehicle")

    def measure(k: int, q_true: np.ndarray, qd_true: np.ndarray) -> Measurement:
        nonlocal q_prev_meas
        if per_signal is not None:
            q, qd = per_signal.measure(k, q_true, qd_true)
            return Measurement(k=k, t=k * T, q=q, qd=qd)
        if layout is not None:
            q, qd = measure_robot(plant, layout, sensor, rng, q_true, qd_true)
            if sensor.delay:
                q_out = q if q_prev_meas is None else q_prev_meas
                q_prev_meas = q
                q = q_out
            return Measurement(k=k, t=k * T, q=q, qd=qd)
        q = q_true.copy()
        if noisy:
            q = q + np.concatenate((rng.normal(0, sensor.position_noise, 2), rng.normal(0, angle_std)))
        if quantized:
            q = np.concatenate((_quantize(q[:2], sensor.position_quantum), _quantize(q[2:], sensor.angle_quantum)))
        qd = None
        if sensor.velocity_sensor:
            qd = qd_true + (rng.normal(0, sensor.velocity_noise, 5) if sensor.velocity_noise else 0.0)
        if sensor.delay:
            q_out = q if q_prev_meas is None else q_prev_meas
            q_prev_meas = q
            q = q_out
        return Measurement(k=k, t=k * T, q=q, qd=qd)

    on_event = getattr(plant, "on_sample", None)  # scheduled plant events (e.g. a payload pick-up)
    sea_signals = getattr(plant, "sea_signals", None)  # the waves at the vehicle (none without waves)
    if sea_signals is not None and not getattr(plant, "has_sea_signals", True):
        sea_signals = None  # a plant that says it has none (no waves, no tether): not called every sample
    # q = q_true: no sensor model (a free vehicle's measure_robot then copies q_true and gives no qd)
    exact = per_signal is None and not (noisy or quantized or sensor.velocity_sensor or sensor.delay)
    # the state at each sample: observed once, then read by each step (Plant.step_observe: the
    # compiled sample where it can); the thrust read after the commands where it follows them
    state = _observe(plant)
    has_applied = hasattr(plant, "joint_torques_applied")  # else (a plant without motor ranges): the command
    # what every sample calls, looked up once
    compute = controller.compute
    if hasattr(plant, "command"):
        command = plant.command
    else:
        def command(thrust, torques, finite=True):
            _command(plant, thrust, torques)
    if hasattr(plant, "step_observe"):
        step_observe = plant.step_observe
    else:
        def step_observe(m):
            return _step_observe(plant, m)
    estimate = feedback == "estimate"
    nav_row = None
    isfinite, ndarray, f64 = math.isfinite, np.ndarray, np.float64
    for k in range(n):
        t = k * T
        if on_event is not None:
            on_event(t)
        q_true, qd_true, tip_true, thr_lagged = state
        meas = Measurement(k, t, q_true.copy()) if exact else measure(k, q_true, qd_true)
        if estimate:
            if est is None:
                est = _start_estimator(navigation, nav, plant, layout, q_true, qd_true)
            meas, nav_row = _estimated(est, meas, layout, q_true, t)
        if k == 0:
            controller.reset(meas)
        cmd: Command = compute(meas)
        thrust, torques = cmd.thrust, cmd.torques
        if type(thrust) is not ndarray or thrust.dtype != f64:
            thrust = np.asarray(thrust, dtype=float)
        if type(torques) is not ndarray or torques.dtype != f64:
            torques = np.asarray(torques, dtype=float)
        out = thrust.ravel().tolist() + torques.ravel().tolist()
        if not isfinite(sum(out)):  # also true of a sum beyond the float range: look closer
            if not all(isfinite(v) for v in out):
                status, reason = "diverged", f"controller output not finite at t = {t:.4f} s"
                break
        big = max(map(abs, out)) if out else 0.0
        if big > COMMAND_ABS_MAX:
            status, reason = "diverged", (f"controller command {big:.3g} (N or N m) beyond {COMMAND_ABS_MAX:g} "
                                          f"at t = {t:.4f} s")
            break
        command(thrust, torques, finite=True)  # checked above
        applied = plant.joint_torques_applied if has_applied else torques
        if k == 0 and warm_start:
            plant.warm_start(thrust)
        if times is not None:
            times[k] = t
        row = {**cmd.signals, "q_true": q_true, "qd_true": qd_true, "tip_true": tip_true, "q_measured": meas.q,
               "thrust_command": thrust,
               "thrust_force": thr_lagged if thr_lagged is not None and k > 0 else plant.thruster_forces,
               "torques": torques, "torques_applied": applied}
        if sea_signals is not None:
            row.update(sea_signals())
        if nav_row is not None:
            row.update(nav_row)
        rows.append(row)
        if sink is not None:
            sink(t, row)
        if on_sample is not None:
            on_sample(k, n)
        if k == n - 1:
            break
        try:
            state = step_observe(sub) if nav is None else nav.advance(step_observe, sub)
        except DivergenceError as exc:
            status, reason = "diverged", str(exc)
            break
    signals = rows.signals()
    if times is not None:
        times = times[:len(rows)] if len(rows) == n else times[:len(rows)].copy()
    else:
        times = np.empty(0)
    meta = {"T": T, "dt": dt, "seed": seed, "controller": controller_name(controller), "joint_ranges": ranges,
            "samples": len(rows), "t_end": (len(rows) - 1) * T if len(rows) else math.nan}
    if status == "ok" and ranges:  # finished: did a joint leave the plant's range?
        if acc is not None:
            why = joint_limit_reason(acc.excursion)
        else:
            why = joint_limit_status(signals["q_true"], ranges, np.asarray(times)) if "q_true" in signals else ""
        if why:
            status, reason = "joint_limit", why
    resolved = getattr(controller, "resolved_params", None)  # parameters resolved at construction (RAC's thresholds)
    if isinstance(resolved, dict):
        meta["controller_params"] = dict(resolved)
    if nav is not None:
        meta["navigation"] = nav.record.describe()
    warned = mujoco_warnings(clear=True)
    if warned:
        meta["mujoco_warnings"] = warned
        if status != "ok":
            reason = f"{reason}; MuJoCo warning: {warned[0]}"
    return RunResult(t=times, signals=signals, status=status, reason=reason, meta=meta,
                     navigation=nav.record if nav is not None else None,
                     metrics=acc.result() if acc is not None else None)
