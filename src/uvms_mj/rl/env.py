"""A dm_control environment over the plant: end-tip tracking, plain or residual on ``rac_dob``.

``load()`` builds a :class:`dm_control.rl.control.Environment` (a ``dm_env.Environment``) whose
physics is the SAME plant as everywhere else in uvms_mj (hydrodynamics included): the
:class:`Physics` wraps ``plant.data``, which is in water (the model's plugins), and advances
it with :meth:`uvms_mj.plant.plant.Plant.step` (``mj_step``, whatever the integrator), so an env step
is bit for bit the plant's own stepping.

.. code-block:: python

    import numpy as np
    from uvms_mj import env as uvms_env

    env = uvms_env.load(residual=True, time_limit=10.0, random=0)   # residual on rac_dob, 600 steps
    spec, rng = env.action_spec(), np.random.default_rng(0)
    ts, ret = env.reset(), 0.0
    while not ts.last():
        ts = env.step(0.05 * rng.uniform(spec.minimum, spec.maximum))   # small random residual
        ret += ts.reward
    print(f"return {ret:.3f}, tip {ts.observation['tip']}, target {ts.observation['target']}")

Rates: physics at the plant's step (1/120 s), control at the controller period T (1/60 s):
``n_sub_steps = T / dt = 2``, the action held over both physics steps (zero-order hold), as in
:func:`uvms_mj.sim.loop.run_closed_loop`.

Actions (``float64``, shape (5,), a ``BoundedArray``): (thrust1, thrust2, thrust3) [N along each
thruster's axis] and (tau1, tau2) [N m].

* plain mode: the command itself. Thrust bounds are the model's ``actuator_ctrlrange``
  (asymmetric, -8.849 / +15.978 N); the joint motors have no ``ctrlrange`` in the model (the
  paper gives no torque limit), so we bound them at +-``torque_limit`` (default
  :data:`DEFAULT_TORQUE_LIMIT` = 20 N m, six times the largest torque ``rac_dob`` uses in the
  paper's experiment, 3.4 N m). Actions outside the bounds are clipped.
* residual mode (``residual=True``): the action is ADDED to the command of the source's
  controller (``rac_dob`` by default: thrust and torques), for residual-learning studies.
  Residual bounds: thrust +-(max - min) of the ctrlrange (full authority: from any base command
  the total can reach any thrust; MuJoCo clamps the total to the ctrlrange, as for the plain
  controller), torques +-``torque_limit``; the total torque is not clipped (``rac_dob``'s own
  torque is not bounded either). The controller sees only its measurements, exactly as in
  ``run_closed_loop``: the measured positions q at each control sample (through the source's
  sensor model: noise, quantization, delay), its own velocity differencing (or the velocity
  sensor if configured), ``controller.reset(measurement)`` at k = 0. A zero residual reproduces
  ``run_closed_loop`` bit for bit (tested).

The first action of an episode warm-starts the thrusters' first-order lag state at the first
thrust command (clipped to the force range): the robot is holding station when the episode
starts, as ``run_closed_loop(warm_start=True)`` does (the source's ``warm_start`` setting).

Observations (``OrderedDict`` of ``float64`` arrays, world frame, SI units):

=================== ===== =====================================================================
key                 shape
=================== ===== =====================================================================
base_pose           (3,)  (p0x, p0y, phi0) [m, m, rad]
joint_angles        (2,)  (phi1, phi2) [rad]
base_velocity       (3,)  world-frame base velocity (p0x_dot, p0y_dot, phi0_dot)
joint_velocities    (2,)  (phi1_dot, phi2_dot) [rad/s]
tip                 (2,)  end-tip position [m]
target              (2,)  desired end-tip position p_ed(t) on the path at this sample [m]
goal                (2,)  end point of the path [m]
time_to_go          (1,)  time left in the episode [s]
thrust              (3,)  actual thrust of each thruster (the lag state, clamped) [N]
base_command        (5,)  residual mode only: the controller's command (thrust [N], torques
                          [N m]) for the coming step, to which the action is added
=================== ===== =====================================================================

Reward (each step, at the state the step reached, t = k T)::

    r = -(w_tip |p_tip - p_ed(t)| + w_base |p0 - p0_ref| + w_att |wrap(phi0 - phi0_ref)|)

with p_ed(t) the desired tip position (``target``), (p0_ref, phi0_ref) the base pose at the
start of the episode (hold station), |.| Euclidean norms, and the weights of
:class:`RewardWeights`: w_tip = 1 /m, w_base = 0.1 /m, w_att = 0.5 /rad. The base weight is
small because the paper's path ends 0.17 m beyond the arm's reach: the base has to carry the arm
(Eq. 12), and staying put would cost w_tip x 0.17 per step. A diverged plant (non-finite state,
runaway speed, or a non-finite controller output) ends the episode with discount 0 and reward
``-divergence_penalty`` (default 100); the last observation then has non-finite values zeroed.

Episodes start from the paper's initial state (keyframe ``paper_initial``, at rest), last
``time_limit`` seconds (default: the source's duration, 40 s): ``floor(time_limit / T)`` steps,
the last one a ``LAST`` step with discount 1 (a time limit, not a failure). Everything is
deterministic given ``random`` (a seed or a ``numpy.random.RandomState``): it seeds only the
sensor noise of the residual controller (``Task.sensor_seed`` is each episode's seed for
``np.random.default_rng``, the generator ``run_closed_loop(seed=...)`` uses).

Plant, trajectory and controller come from a source: a :class:`~uvms_mj.scenario.schema.Scenario`
(or the path of a scenario YAML file) or a :class:`~uvms_mj.sim.experiment.PaperExperiment`;
default ``Scenario()``, the paper's experiment (truth plant differing from the controller's
nominal model, straight 0.3 m tip path at 0.02 m/s, ``rac_dob``).
"""

from __future__ import annotations

import collections
import copy
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

try:  # dm-control is an extra: `pip install 'uvms-mj[rl]'` (the rest of uvms_mj does not need it)
    from dm_control import mujoco as dm_mujoco
    from dm_control.mujoco import wrapper
    from dm_control.rl import control
    from dm_env import specs
except ImportError as exc:  # pragma: no cover - exercised only without the extra
    raise ImportError(f"uvms_mj.rl.env needs dm-control ({exc}): pip install 'uvms-mj[rl]'") from None

from uvms_mj.control.base import Command, Controller, Measurement
from uvms_mj.sim.loop import SensorModel
from uvms_mj.plant.params import JOINT_MOTORS, THRUSTERS, TIP_SITE
from uvms_mj.plant.plant import DivergenceError, Plant
from uvms_mj.control.trajectories import Line3D

__all__ = [
    "DEFAULT_TORQUE_LIMIT",
    "Physics",
    "RewardWeights",
    "TrackingTask",
    "load",
    "from_plant",
]

#: Bound on the joint torques [N m] (the model's motors are unlimited; the paper gives none).
DEFAULT_TORQUE_LIMIT = 20.0


@dataclass(frozen=True)
class RewardWeights:
    """Weights of the tracking reward r = -(tip |e_tip| + base |e_base| + attitude |e_att|).

    Attributes:
        tip: per metre of end-tip error from the desired path position.
        base: per metre of base displacement from its initial position.
        attitude: per radian of base attitude error from its initial attitude.
    """

    tip: float = 1.0
    base: float = 0.1
    attitude: float = 0.5

    def __post_init__(self) -> None:
        for name in ("tip", "base", "attitude"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"reward weight {name} = {v!r} must be finite and >= 0")


# --------------------------------------------------------------------------- physics


class Physics(dm_mujoco.Physics):
    """A dm_control Physics over a :class:`~uvms_mj.plant.plant.Plant`'s own data.

    It wraps ``plant.data`` (served by the plant's hydrodynamics) and steps it with
    ``plant.step`` (``mj_step`` each physics step, for every integrator, exactly the plant's
    stepping; dm_control's ``legacy_step`` only adds an ``mj_step1`` afterwards to bring the
    position- and velocity-dependent fields up to date, which does not change the state).

    A divergence (:class:`~uvms_mj.plant.plant.DivergenceError`) does not raise: it is kept in
    :attr:`divergence`, further steps do nothing, and :meth:`reset` (or ``plant.reset()``
    followed by ``physics.divergence = None``) clears it. :meth:`copy` returns a physics over a
    copy of the data, registered with the plant (hydrodynamics included; its divergence is then
    only MuJoCo's own warnings, raised as ``PhysicsError``).
    """

    _plant: Plant
    divergence: DivergenceError | None

    def __init__(self, plant: Plant) -> None:
        if not isinstance(plant, Plant):
            raise TypeError(f"Physics expects a uvms_mj Plant, got {type(plant).__name__}")
        self._plant = plant
        self.divergence = None
        super().__init__(wrapper.MjData(plant.data))

    @property
    def plant(self) -> Plant:
        """The plant whose model (and hydrodynamics) this physics runs."""
        return self._plant

    @property
    def owns_plant_data(self) -> bool:
        """Whether this physics runs ``plant.data`` itself (False for copies)."""
        return self.data.ptr is self._plant.data

    def step(self, nstep: int = 1) -> None:
        if self.divergence is not None:
            return
        m, d = self.model.ptr, self.data.ptr
        if self.owns_plant_data:
            try:
                self._plant.step(nstep)  # checks MuJoCo's warnings itself
            except DivergenceError as exc:
                self.divergence = exc
                return
        else:
            with self.check_invalid_state():
                mujoco.mj_step(m, d, nstep)
        if self.legacy_step:
            mujoco.mj_step1(m, d)

    def reset(self, keyframe_id: int | None = None) -> None:
        self.divergence = None
        if self.owns_plant_data:
            self._plant.reset(None)  # clears the plant's divergence record too
        super().reset(keyframe_id)

    def copy(self, share_model: bool = True) -> "Physics":
        """A physics over a copy of the data (same model, registered with the plant).

        Raises:
            ValueError: ``share_model=False``: the hydrodynamics are installed on the plant's
                model, a copied model would run without them.
        """
        if not share_model:
            raise ValueError("uvms_mj Physics.copy needs share_model=True: the hydrodynamics are served "
                             "for the plant's own model only")
        new_data = self._plant.attach_data(copy.copy(self.data.ptr))
        new = Physics.__new__(Physics)
        new._plant = self._plant
        new.divergence = self.divergence
        new._warnings_cause_exception = True
        new._reload_from_data(wrapper.MjData(new_data))
        new.legacy_step = self.legacy_step
        return new

    def _make_rendering_contexts(self) -> None:
        """dm_control's contexts, with the OpenGL backend chosen now that rendering starts: on
        Linux without a display and ``MUJOCO_GL`` unset, EGL (else OSMesa) instead of the GLFW
        default dm_control took (:func:`uvms_mj.analysis.render_gl.dm_control_context_class`)."""
        from dm_control import _render

        from uvms_mj.analysis.render_gl import dm_control_context_class

        default, _render.Renderer = _render.Renderer, dm_control_context_class()
        try:
            super()._make_rendering_contexts()
        finally:
            _render.Renderer = default

    def __getstate__(self):  # noqa: D105
        raise TypeError("a uvms_mj Physics cannot be pickled (it lives on its plant, whose hydrodynamics it shares)")


# --------------------------------------------------------------------------- sensor


class _Sensor:
    """The measurement of :func:`uvms_mj.sim.loop.run_closed_loop` (same draws in the same order)."""

    def __init__(self, model: SensorModel, seed: int, T: float) -> None:
        self.model = model
        self.rng = np.random.default_rng(seed)
        self.T = T
        self.q_prev: np.ndarray | None = None

    def measure(self, k: int, q: np.ndarray, qd: np.ndarray) -> Measurement:
        s, rng = self.model, self.rng
        noise = np.r_[rng.normal(0, s.position_noise, 2), rng.normal(0, s.angle_noise, 3)] \
            if (s.position_noise or s.angle_noise) else 0.0
        q = q + noise
        q = np.r_[_quantize(q[:2], s.position_quantum), _quantize(q[2:], s.angle_quantum)]
        qd_meas = None
        if s.velocity_sensor:
            qd_meas = qd + (rng.normal(0, s.velocity_noise, 5) if s.velocity_noise else 0.0)
        if s.delay:
            q_out = q if self.q_prev is None else self.q_prev
            self.q_prev = q
            q = q_out
        return Measurement(k=k, t=k * self.T, q=q, qd=qd_meas)


def _quantize(x: np.ndarray, quantum: float) -> np.ndarray:
    return np.round(x / quantum) * quantum if quantum > 0 else x


# --------------------------------------------------------------------------- task


class TrackingTask(control.Task):
    """End-tip tracking of a straight path, plain or residual (see the module docstring).

    Args:
        plant: the plant (its model gives the thruster bounds and actuator names).
        trajectory: the desired end-tip path.
        T: control period [s] (a whole number of plant steps).
        time_limit: episode length [s] (for the ``time_to_go`` observation).
        controller: residual mode: the controller whose command the action adds to; None: plain.
        sensor: the controller's measurement model (residual mode).
        warm_start: start the thrusters' lag state at the first thrust command.
        weights: reward weights.
        torque_limit: joint torque bound [N m] (action and residual).
        divergence_penalty: reward of the step on which the plant diverged.
        random: a seed, a ``numpy.random.RandomState`` or None (seeds the sensor noise).
    """

    def __init__(
        self,
        plant: Plant,
        trajectory: Line3D,
        T: float,
        time_limit: float,
        controller: Controller | None = None,
        sensor: SensorModel = SensorModel(),
        warm_start: bool = True,
        weights: RewardWeights = RewardWeights(),
        torque_limit: float = DEFAULT_TORQUE_LIMIT,
        divergence_penalty: float = 100.0,
        random: int | np.random.RandomState | None = None,
    ) -> None:
        if not isinstance(random, np.random.RandomState):
            random = np.random.RandomState(random)
        self._random = random
        if not (math.isfinite(torque_limit) and torque_limit > 0):
            raise ValueError(f"torque_limit = {torque_limit!r} N m must be finite and > 0")
        if not (math.isfinite(divergence_penalty) and divergence_penalty >= 0):
            raise ValueError(f"divergence_penalty = {divergence_penalty!r} must be finite and >= 0")
        self.plant = plant
        self.trajectory = trajectory
        self.T = float(T)
        self.time_limit = float(time_limit)
        self.controller = controller
        self.sensor_model = sensor
        self.warm_start = bool(warm_start)
        self.weights = weights
        self.torque_limit = float(torque_limit)
        self.divergence_penalty = float(divergence_penalty)

        m = plant.model
        ids = lambda names: np.array([mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, n) for n in names])  # noqa: E731
        thr, mot = ids(THRUSTERS), ids(JOINT_MOTORS)
        if not np.all(m.actuator_ctrllimited[thr]):
            raise ValueError("the thruster actuators must have a ctrlrange")
        self._thr_lo, self._thr_hi = (np.array(v, dtype=float) for v in m.actuator_ctrlrange[thr].T)
        self._thr_act = m.actuator_actadr[thr]
        self._force_lo, self._force_hi = (np.array(v, dtype=float) for v in m.actuator_forcerange[thr].T)
        tq = np.full(2, self.torque_limit)
        mot_limited = m.actuator_ctrllimited[mot].astype(bool)
        tq_lo, tq_hi = -tq.copy(), tq.copy()
        tq_lo[mot_limited] = np.maximum(tq_lo[mot_limited], m.actuator_ctrlrange[mot][mot_limited, 0])
        tq_hi[mot_limited] = np.minimum(tq_hi[mot_limited], m.actuator_ctrlrange[mot][mot_limited, 1])
        name = "\t".join(THRUSTERS + JOINT_MOTORS)
        if controller is None:
            lo, hi = np.r_[self._thr_lo, tq_lo], np.r_[self._thr_hi, tq_hi]
        else:
            span = self._thr_hi - self._thr_lo
            lo, hi = np.r_[-span, -tq], np.r_[span, tq]
        self._action_spec = specs.BoundedArray((5,), np.float64, lo, hi, name=name)
        self._tip_scratch = mujoco.MjData(m)  # kinematics only: no passive stage, no callback
        self._tip_site = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, TIP_SITE)
        self._goal = np.asarray(trajectory.target, dtype=float)[:2]  # the paper's plane (x, y)

        #: set by :func:`from_plant`: the Environment flattens the observations.
        self.flat_observation = False
        self.k = 0  #: control samples since the start of the episode
        self.sensor_seed: int | None = None  #: the sensor generator's seed of this episode
        self.command: Command | None = None  #: residual mode: the controller's current command
        self._ref = np.zeros(3)
        self._sensor: _Sensor | None = None

    @property
    def random(self) -> np.random.RandomState:
        return self._random

    @property
    def residual(self) -> bool:
        return self.controller is not None

    # ---------------------------------------------------------------- episode

    def initialize_episode(self, physics: Physics) -> None:
        plant = physics.plant
        plant.reset()  # the paper's initial state (keyframe), the plant's divergence cleared
        physics.divergence = None
        self.k = 0
        self._ref = plant.data.qpos[:3].copy()
        self.sensor_seed = int(self._random.randint(2**31 - 1))
        self.command = None
        if self.controller is not None:
            self._sensor = _Sensor(self.sensor_model, self.sensor_seed, self.T)
            meas = self._measure(physics)
            self.controller.reset(meas)
            self._compute(physics, meas)

    def _measure(self, physics: Physics) -> Measurement:
        d = physics.data
        return self._sensor.measure(self.k, d.qpos.copy(), d.qvel.copy())

    def _compute(self, physics: Physics, meas: Measurement) -> None:
        cmd = self.controller.compute(meas)
        thrust = np.asarray(cmd.thrust, dtype=float)
        torques = np.asarray(cmd.torques, dtype=float)
        if not (np.all(np.isfinite(thrust)) and np.all(np.isfinite(torques))):
            physics.divergence = DivergenceError(self.k * self.T, "controller output not finite")
            thrust, torques = np.zeros(3), np.zeros(2)
        self.command = Command(thrust=thrust, torques=torques, signals=cmd.signals)

    def before_step(self, action: Any, physics: Physics) -> None:
        a = np.asarray(action, dtype=float)
        spec = self._action_spec
        if a.shape != spec.shape:
            raise ValueError(f"action shape {a.shape} != {spec.shape} ({spec.name.replace(chr(9), ', ')})")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"action {a!r} must be finite")
        a = np.clip(a, spec.minimum, spec.maximum)
        if self.command is not None:
            thrust, torques = self.command.thrust + a[:3], self.command.torques + a[3:]
        else:
            thrust, torques = a[:3], a[3:]
        plant = physics.plant
        plant.set_thrust(thrust)
        plant.set_joint_torques(torques)
        if self.k == 0 and self.warm_start:
            physics.data.act[self._thr_act] = np.clip(thrust, self._force_lo, self._force_hi)

    def after_step(self, physics: Physics) -> None:
        self.k += 1
        if self.controller is not None and physics.divergence is None:
            self._compute(physics, self._measure(physics))

    # ---------------------------------------------------------------- specs, observation, reward

    def action_spec(self, physics: Physics) -> specs.BoundedArray:
        return self._action_spec

    def observation_spec(self, physics: Physics) -> collections.OrderedDict:
        if self.flat_observation:
            raise NotImplementedError  # the Environment infers the flattened spec
        shapes = [("base_pose", 3), ("joint_angles", 2), ("base_velocity", 3), ("joint_velocities", 2),
                  ("tip", 2), ("target", 2), ("goal", 2), ("time_to_go", 1), ("thrust", 3)]
        if self.controller is not None:
            shapes.append(("base_command", 5))
        return collections.OrderedDict((k, specs.Array((n,), np.float64, name=k)) for k, n in shapes)

    def _tip(self, qpos: np.ndarray) -> np.ndarray:
        s = self._tip_scratch
        s.qpos[:] = qpos
        mujoco.mj_kinematics(s.model, s)
        return s.site_xpos[self._tip_site, :2].copy()

    def get_observation(self, physics: Physics) -> collections.OrderedDict:
        d = physics.data
        q, qd = d.qpos.copy(), d.qvel.copy()
        t = self.k * self.T
        obs = collections.OrderedDict(
            base_pose=q[:3],
            joint_angles=q[3:5],
            base_velocity=qd[:3],
            joint_velocities=qd[3:5],
            tip=self._tip(q),
            target=np.asarray(self.trajectory.position(t), dtype=float)[:2],
            goal=self._goal.copy(),
            time_to_go=np.array([max(self.time_limit - t, 0.0)]),
            thrust=np.clip(d.act[self._thr_act], self._force_lo, self._force_hi),
        )
        if self.controller is not None:
            cmd = self.command
            obs["base_command"] = np.r_[cmd.thrust, cmd.torques] if cmd is not None else np.zeros(5)
        if physics.divergence is not None:
            for key, val in obs.items():
                obs[key] = np.nan_to_num(val, nan=0.0, posinf=0.0, neginf=0.0)
        return obs

    def get_reward(self, physics: Physics) -> float:
        if physics.divergence is not None:
            return -self.divergence_penalty
        q = physics.data.qpos
        w = self.weights
        e_tip = float(np.linalg.norm(self._tip(q) - np.asarray(self.trajectory.position(self.k * self.T))[:2]))
        e_base = float(np.hypot(q[0] - self._ref[0], q[1] - self._ref[1]))
        e_att = abs(math.remainder(float(q[2] - self._ref[2]), 2 * math.pi))
        r = -(w.tip * e_tip + w.base * e_base + w.attitude * e_att)
        return r if math.isfinite(r) else -self.divergence_penalty

    def get_termination(self, physics: Physics) -> float | None:
        return 0.0 if physics.divergence is not None else None


# --------------------------------------------------------------------------- constructors


def from_plant(
    plant: Plant,
    trajectory: Line3D,
    *,
    controller: Controller | None = None,
    T: float = 1.0 / 60.0,
    time_limit: float = 40.0,
    sensor: SensorModel = SensorModel(),
    warm_start: bool = True,
    random: int | np.random.RandomState | None = None,
    reward_weights: RewardWeights = RewardWeights(),
    torque_limit: float = DEFAULT_TORQUE_LIMIT,
    divergence_penalty: float = 100.0,
    legacy_step: bool = True,
    flat_observation: bool = False,
) -> control.Environment:
    """The environment over an existing plant and path (``controller``: residual mode).

    Raises:
        ValueError: T is not a whole multiple of the plant's step, or time_limit < T.
    """
    dt = float(plant.model.opt.timestep)
    sub = T / dt
    if not (math.isfinite(sub) and abs(sub - round(sub)) <= 1e-9 and round(sub) >= 1):
        raise ValueError(f"T = {T!r} s must be a whole multiple of the plant timestep {dt!r} s")
    n_steps = int(math.floor(time_limit / T + 1e-9)) if math.isfinite(time_limit) and time_limit > 0 else 0
    if n_steps < 1:
        raise ValueError(f"time_limit = {time_limit!r} s must be finite and at least one control period T = {T!r} s")
    physics = Physics(plant)
    task = TrackingTask(plant, trajectory, T, time_limit, controller=controller, sensor=sensor,
                        warm_start=warm_start, weights=reward_weights, torque_limit=torque_limit,
                        divergence_penalty=divergence_penalty, random=random)
    task.flat_observation = bool(flat_observation)
    sub = int(round(sub))
    # dm_control counts steps against time_limit / (dt * n_sub_steps); half a step of margin
    # makes that exactly n_steps whatever the rounding of dt.
    return control.Environment(physics, task, time_limit=(n_steps - 0.5) * sub * dt, n_sub_steps=sub,
                               flat_observation=flat_observation, legacy_step=legacy_step)


def load(
    residual: bool = False,
    scenario: Any = None,
    time_limit: float | None = None,
    random: int | np.random.RandomState | None = None,
    **kwargs: Any,
) -> control.Environment:
    """The tracking environment of a scenario (see the module docstring).

    Args:
        residual: the action adds to the source controller's command (``rac_dob`` by default).
        scenario: a :class:`~uvms_mj.scenario.schema.Scenario`, the path of a scenario YAML file, a
            :class:`~uvms_mj.sim.experiment.PaperExperiment`, or None (``Scenario()``: the paper's
            experiment). Gives the plant, path, controller (period T, residual base), sensor
            model, warm start and default duration.
        time_limit: episode length [s]; default the source's duration (40 s for the paper).
        random: seed or ``numpy.random.RandomState`` (sensor noise of the residual controller).
        **kwargs: ``reward_weights``, ``torque_limit``, ``divergence_penalty``, ``legacy_step``,
            ``flat_observation`` (see :func:`from_plant`).

    Raises:
        uvms_mj.scenario.schema.ScenarioError: an invalid scenario file or combination.
        ValueError: bad time_limit or controller period.
    """
    from uvms_mj.sim.experiment import PaperExperiment
    from uvms_mj.scenario.schema import Scenario, build, load_scenario, sensor_model

    if scenario is None:
        scenario = Scenario()
    elif isinstance(scenario, (str, Path)):
        scenario = load_scenario(scenario)
    if isinstance(scenario, PaperExperiment):
        plant, ctrl = scenario.build()
        sensor, warm, duration = scenario.sensor, scenario.warm_start, scenario.duration
    elif isinstance(scenario, Scenario):
        plant, ctrl = build(scenario)
        sensor = sensor_model(scenario)
        warm, duration = scenario.warm_start, scenario.duration
    else:
        raise TypeError(f"scenario = {scenario!r} must be a Scenario, a scenario file path, a PaperExperiment or None")
    T = float(getattr(ctrl, "T", 1.0 / 60.0))
    trajectory = getattr(ctrl, "trajectory", None)
    if not isinstance(trajectory, Line3D):
        raise ValueError(f"controller {getattr(ctrl, 'name', ctrl)!r} exposes no straight-line (Line3D) trajectory")
    return from_plant(plant, trajectory, controller=ctrl if residual else None, T=T,
                      time_limit=duration if time_limit is None else float(time_limit), sensor=sensor,
                      warm_start=warm, random=random, **kwargs)
