"""A dm_control environment over the plant, for any robot: end-tip tracking, plain or residual on
the scenario's controller.

``load()`` builds a :class:`dm_control.rl.control.Environment` (a ``dm_env.Environment``) from a
scenario, through the same :func:`uvms_mj.scenario.schema.build` as ``uvms-mj run``: the paper's
planar robot and every MJCF robot (the BlueROV2 Heavy + Alpha studies included) alike. Its
:class:`~uvms_mj.rl.physics.Physics` wraps ``plant.data``, which is in water (the model's
plugins), and advances it with :meth:`uvms_mj.plant.plant.Plant.step` (``mj_step``, whatever the
integrator), so an env step is bit for bit the plant's own stepping.

.. code-block:: python

    import numpy as np
    from uvms_mj.rl import env as uvms_env

    env = uvms_env.load(residual=True, scenario="bluerov2_alpha_circle_current", time_limit=10.0, random=0)
    spec, rng = env.action_spec(), np.random.default_rng(0)
    ts, ret = env.reset(), 0.0
    while not ts.last():
        ts = env.step(0.02 * rng.uniform(spec.minimum, spec.maximum))   # small random residual
        ret += ts.reward
    print(f"return {ret:.3f}, tip {ts.observation['tip']}, target {ts.observation['target']}")
    print(env.task.action_names, env.task.observation_names)            # every component named

Scenario: a :class:`~uvms_mj.scenario.schema.Scenario`, a scenario file or the name of a packaged
scenario (``"paper"``, ``"bluerov2_alpha_station"``: resolved as the command line does, with
``sets=["duration=5", ...]`` as ``--set``), a :class:`~uvms_mj.sim.experiment.PaperExperiment`, or
None (the paper's experiment). A bad one raises :class:`~uvms_mj.scenario.schema.ScenarioError`
(a ValueError) in one line per problem, naming the file and the field.

Rates: physics at the plant's step, control at the controller's period T (the paper's: 1/120 s
and 1/60 s, ``n_sub_steps = 2``; the BlueROV2 studies': 0.004 s and 0.02 s), the action held over
the physics steps (zero-order hold), as in :func:`uvms_mj.sim.loop.run_closed_loop`.

Actions (``float64``, a ``BoundedArray`` named ``"\t".join(task.action_names)``): one thrust per
thruster [N along its axis], then one torque per joint motor [N m], in the model's order
(:mod:`uvms_mj.rl.layout`; the paper's: (thrust1, thrust2, thrust3, tau1, tau2); the BlueROV2 +
Alpha's: 8 thrusters, 4 joint motors).

* plain mode: the command itself. Thrust bounds: the model's force range (the paper's
  asymmetric -8.849 / +15.978 N, the T200's +-30.622 N). Torque bounds: the motor's ctrlrange
  where the model gives one (the Alpha's +-9 N m, +-5 N m for the wrist), inside +-``torque_limit``
  (default :data:`DEFAULT_TORQUE_LIMIT` = 20 N m: the paper's motors have no ``ctrlrange`` and the
  paper gives no limit: six times the largest torque ``rac_dob`` uses in the paper's experiment,
  3.4 N m). Actions outside the bounds are clipped.
* residual mode (``residual=True``): the action is ADDED to the command of the scenario's
  controller (``rac_dob`` in the paper's and the packaged 3-D studies), for residual-learning
  studies. Residual bounds: thrust +-(max - min) of the force range (full authority: from any
  base command the total can reach any thrust; the plant clamps the total to the range, as for
  the plain controller), torques +- the larger magnitude of the plain bounds (the paper's +-20,
  the Alpha's +-9 / +-5 N m); the total torque is clipped only by the model's ctrlrange where it
  has one (``rac_dob``'s own torque is not bounded either). The controller sees only its
  measurements, exactly as in ``run_closed_loop``: the measured positions at each control sample
  (through the scenario's sensor model: noise, quantization, delay, per-signal sensors), its own
  velocity differencing (or the velocity sensor if configured), ``controller.reset(measurement)``
  at k = 0, the plant's scheduled events (payload pick-up, thruster failures) at each sample. A
  zero residual reproduces ``run_closed_loop`` bit for bit (tested on the paper's robot and the
  BlueROV2 + Alpha).

The first action of an episode warm-starts the thrusters' first-order lag state at the first
thrust command (:meth:`uvms_mj.plant.plant.Plant.warm_start`): the robot is holding station when
the episode starts, as ``run_closed_loop(warm_start=True)`` does (the source's ``warm_start``).

Observations (``OrderedDict`` of ``float64`` arrays, SI units; each component named in
``task.observation_names``, :func:`uvms_mj.rl.layout.observation_names`; ``flat_observation=True``
concatenates them in this order, named by ``task.flat_observation_names``):

=================== ======================================================================
key                 contents (the paper's robot / a free vehicle such as the BlueROV2)
=================== ======================================================================
base_pose           the base's qpos: (x, y, yaw) [m, m, rad] (p0x, p0y, phi0) / (x, y, z, qw,
                    qx, qy, qz) world position [m] and attitude quaternion
joint_angles        arm joint angles [rad], by joint name (omitted for a vehicle without arm)
base_velocity       the base's qvel: world (vx, vy, wz) / (vx, vy, vz) world and (wx, wy, wz)
                    body frame
joint_velocities    arm joint rates [rad/s] (omitted without arm)
tip                 end-tip position, world [m]: (x, y) in the paper's plane / (x, y, z)
target              desired end-tip position on the path at this sample [m] (no path: the tip
                    where the episode started)
goal                a straight path's end point; another path's position at the time limit [m]
time_to_go          time left in the episode [s]
thrust              actual thrust of each thruster (the lag state, clamped) [N]
base_command        residual mode only: the controller's command (thrusts [N], torques [N m])
                    for the coming step, to which the action is added
=================== ======================================================================

(``tip``, ``target`` and ``goal``: robots with a tip site only.)

Reward (each step, at the state the step reached, t = k T)::

    r = -(w_tip |p_tip - p_ed(t)| + w_base |p0 - p0_ref| + w_att angle(R0_ref^T R0))

with p_ed(t) the desired tip position (``target``), (p0_ref, R0_ref) the base pose at the start
of the episode (hold station; a planar base's angle error wrapped to [-pi, pi], a free vehicle's
the rotation angle 2 acos |<q, q_ref>|), |.| Euclidean norms, and the weights of
:class:`RewardWeights`: w_tip = 1 /m, w_base = 0.1 /m, w_att = 0.5 /rad. The base weight is
small because the paper's path ends 0.17 m beyond the arm's reach: the base has to carry the arm
(Eq. 12), and staying put would cost w_tip x 0.17 per step. A diverged plant (non-finite state,
runaway speed, a non-finite controller output or one beyond 1e6 N / N m) ends the episode with
discount 0 and reward ``-divergence_penalty`` (default 100); the last observation then has
non-finite values zeroed.

Episodes start from the scenario's initial state (the paper's: keyframe ``paper_initial``, at
rest; a payload picked up in the last episode is dropped first), last ``time_limit`` seconds
(default: the scenario's duration): ``floor(time_limit / T)`` steps, the last one a ``LAST`` step
with discount 1 (a time limit, not a failure). Everything is deterministic given ``random`` (a
seed or a ``numpy.random.RandomState``): it seeds only the sensor noise of the residual controller
(``Task.sensor_seed`` is each episode's seed, the ``seed`` of ``run_closed_loop``).
"""

from __future__ import annotations

import collections
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import mujoco
import numpy as np

try:  # dm-control is an extra: `pip install 'uvms-mj[rl]'` (the rest of uvms_mj does not need it)
    from dm_control.rl import control
    from dm_env import specs
except ImportError as exc:  # pragma: no cover - exercised only without the extra
    raise ImportError(f"uvms_mj.rl.env needs dm-control ({exc}): pip install 'uvms-mj[rl]'") from None

from uvms_mj.control.base import Command, Controller, Measurement
from uvms_mj.control.trajectories.base import Trajectory
from uvms_mj.plant.plant import DivergenceError, Plant
from uvms_mj.rl.layout import action_bounds, action_names, observation_names
from uvms_mj.rl.physics import Physics, Sensor
from uvms_mj.sim.loop import COMMAND_ABS_MAX, SensorModel

__all__ = [
    "DEFAULT_TORQUE_LIMIT",
    "Physics",
    "RewardWeights",
    "TrackingTask",
    "load",
    "from_plant",
]

#: Bound on the joint torques [N m] where the model gives none (the paper's motors are unlimited; the
#: paper gives no limit): six times the largest torque rac_dob uses in the paper's experiment (3.4 N m).
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


# --------------------------------------------------------------------------- task


class TrackingTask(control.Task):
    """End-tip tracking, plain or residual, on any robot (see the module docstring).

    Args:
        plant: the plant (its model gives the actuators, their bounds and the observation layout).
        trajectory: the desired end-tip path (None: hold the tip where the episode starts).
        T: control period [s] (a whole number of plant steps).
        time_limit: episode length [s] (for the ``time_to_go`` observation).
        controller: residual mode: the controller whose command the action adds to; None: plain.
        sensor: the controller's measurement model (residual mode).
        warm_start: start the thrusters' lag state at the first thrust command.
        weights: reward weights.
        torque_limit: joint torque bound [N m] where the model gives none (action and residual).
        divergence_penalty: reward of the step on which the plant diverged.
        random: a seed, a ``numpy.random.RandomState`` or None (seeds the sensor noise).
    """

    def __init__(
        self,
        plant: Plant,
        trajectory: Trajectory | None,
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

        m, lay = plant.model, plant.layout
        self.layout = lay
        lo, hi = action_bounds(m, lay, self.torque_limit, bool(getattr(plant, "_direct", True)))
        self.n_thrusters = n_thr = len(lay.thruster_names)
        if controller is not None:  # residual: full authority on thrust, the torque bound's magnitude
            lo, hi = np.r_[-(hi[:n_thr] - lo[:n_thr]), -np.maximum(-lo[n_thr:], hi[n_thr:])], \
                np.r_[hi[:n_thr] - lo[:n_thr], np.maximum(-lo[n_thr:], hi[n_thr:])]
        #: the action's component names (thrusters, then motors)
        self.action_names = action_names(lay)
        self._action_spec = specs.BoundedArray((lo.size,), np.float64, lo, hi, name="\t".join(self.action_names))
        #: observation key -> the names of its components (:func:`uvms_mj.rl.layout.observation_names`)
        self.observation_names = observation_names(m, lay, controller is not None)
        self._tip_scratch = mujoco.MjData(m)  # kinematics only: no passive stage, no callback
        self._tip_site = lay.tip_site
        self._axes = list(lay.plane_axes)
        a = lay.base_qadr
        self._base_q = slice(a, a + lay.base_nq)
        nd = int(lay.base_dofs.size)
        self._base_v = slice(lay.base_dadr, lay.base_dadr + nd)
        if lay.base_free:
            self._pos_idx, self._att_idx = np.arange(a, a + 3), None
        else:
            hinge = int(m.jnt_qposadr[lay.base_hinge]) if lay.base_hinge >= 0 else None
            self._pos_idx = np.array([i for i in range(a, a + lay.base_nq) if i != hinge], dtype=int)
            self._att_idx = hinge

        #: set by :func:`from_plant`: the Environment flattens the observations.
        self.flat_observation = False
        self.k = 0  #: control samples since the start of the episode
        self.sensor_seed: int | None = None  #: the sensor generator's seed of this episode
        self.command: Command | None = None  #: residual mode: the controller's current command
        self._ref = plant.data.qpos.copy()
        self._hold = np.zeros(len(self._axes))
        self._goal = np.zeros(len(self._axes))
        self._sensor: Sensor | None = None

    @property
    def random(self) -> np.random.RandomState:
        return self._random

    @property
    def residual(self) -> bool:
        return self.controller is not None

    @property
    def flat_observation_names(self) -> list[str]:
        """``key.component`` for every entry of the flattened observation (``flat_observation=True``:
        the keys in spec order, each key's components in order)."""
        return [f"{key}.{name}" for key, names in self.observation_names.items() for name in names]

    # ---------------------------------------------------------------- episode

    def initialize_episode(self, physics: Physics) -> None:
        plant = physics.plant
        physics.drop_payload()
        plant.reset()  # the initial state (keyframe or the scenario's), the plant's divergence cleared
        physics.divergence = None
        self.k = 0
        self._ref = plant.data.qpos.copy()
        if self._tip_site >= 0:
            self._hold = self._tip(self._ref)
            self._goal = self._target_at(max(self.time_limit, 0.0), goal=True)
        self.sensor_seed = int(self._random.randint(2**31 - 1))
        self.command = None
        plant.on_sample(0.0)  # the scheduled events at t = 0 (as run_closed_loop)
        if self.controller is not None:
            self._sensor = Sensor(self.sensor_model, self.sensor_seed, self.T, plant)
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
        out = np.r_[thrust.ravel(), torques.ravel()]
        if not np.all(np.isfinite(out)):
            physics.divergence = DivergenceError(self.k * self.T, "controller output not finite")
        elif out.size and np.max(np.abs(out)) > COMMAND_ABS_MAX:
            physics.divergence = DivergenceError(self.k * self.T, f"controller command beyond {COMMAND_ABS_MAX:g}")
        if physics.divergence is not None:
            thrust, torques = np.zeros(thrust.size), np.zeros(torques.size)
        self.command = Command(thrust=thrust, torques=torques, signals=cmd.signals)

    def before_step(self, action: Any, physics: Physics) -> None:
        a = np.asarray(action, dtype=float)
        spec = self._action_spec
        if a.shape != spec.shape:
            raise ValueError(f"action shape {a.shape} != {spec.shape} ({spec.name.replace(chr(9), ', ')})")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"action {a!r} must be finite")
        a = np.clip(a, spec.minimum, spec.maximum)
        n = self.n_thrusters
        if self.command is not None:
            thrust, torques = self.command.thrust + a[:n], self.command.torques + a[n:]
        else:
            thrust, torques = a[:n], a[n:]
        plant = physics.plant
        plant.set_thrust(thrust)
        plant.set_joint_torques(torques)
        if self.k == 0 and self.warm_start:
            plant.warm_start(thrust)

    def after_step(self, physics: Physics) -> None:
        self.k += 1
        if physics.divergence is None:
            physics.plant.on_sample(self.k * self.T)
        if self.controller is not None and physics.divergence is None:
            self._compute(physics, self._measure(physics))

    # ---------------------------------------------------------------- specs, observation, reward

    def action_spec(self, physics: Physics) -> specs.BoundedArray:
        return self._action_spec

    def observation_spec(self, physics: Physics) -> collections.OrderedDict:
        if self.flat_observation:
            raise NotImplementedError  # the Environment infers the flattened spec
        return collections.OrderedDict((k, specs.Array((len(v),), np.float64, name=k))
                                       for k, v in self.observation_names.items())

    def _tip(self, qpos: np.ndarray) -> np.ndarray:
        s = self._tip_scratch
        s.qpos[:] = qpos
        mujoco.mj_kinematics(s.model, s)
        return s.site_xpos[self._tip_site, self._axes].copy()

    def _target_at(self, t: float, goal: bool = False) -> np.ndarray:
        """The desired tip position at t (the path's, else the tip where the episode started);
        ``goal``: a straight line's end point, another path's position at t."""
        traj = self.trajectory
        if traj is None:
            return self._hold.copy()
        end = getattr(traj, "target", None) if goal else None
        p = np.asarray(traj.position(t) if end is None else end, dtype=float)
        return p[self._axes].copy()

    def get_observation(self, physics: Physics) -> collections.OrderedDict:
        d = physics.data
        q, qd = d.qpos.copy(), d.qvel.copy()
        lay = self.layout
        t = self.k * self.T
        obs = collections.OrderedDict(
            base_pose=q[self._base_q],
            joint_angles=q[lay.joint_qadr],
            base_velocity=qd[self._base_v],
            joint_velocities=qd[lay.joint_dadr],
        )
        if self._tip_site >= 0:
            obs.update(tip=self._tip(q), target=self._target_at(t), goal=self._goal.copy())
        obs["time_to_go"] = np.array([max(self.time_limit - t, 0.0)])
        obs["thrust"] = physics.plant.thruster_forces if physics.owns_plant_data else np.zeros(self.n_thrusters)
        if self.controller is not None:
            cmd = self.command
            obs["base_command"] = (np.r_[cmd.thrust, cmd.torques] if cmd is not None
                                   else np.zeros(self._action_spec.shape[0]))
        if len(obs) != len(self.observation_names):  # a robot without arm joints: no joint entries
            obs = collections.OrderedDict((k, obs[k]) for k in self.observation_names)
        if physics.divergence is not None:
            for key, val in obs.items():
                obs[key] = np.nan_to_num(val, nan=0.0, posinf=0.0, neginf=0.0)
        return obs

    def errors(self, qpos: np.ndarray) -> tuple[float, float, float]:
        """(tip, base position, base attitude) errors of the reward at ``qpos`` (sample k): |p_tip -
        p_ed(kT)| [m] (0 without a tip site), |p0 - p0_ref| [m], the attitude error's angle [rad]."""
        e_tip = (float(np.linalg.norm(self._tip(qpos) - self._target_at(self.k * self.T)))
                 if self._tip_site >= 0 else 0.0)
        e_base = float(np.linalg.norm(qpos[self._pos_idx] - self._ref[self._pos_idx]))
        if self.layout.base_free:
            qa, qr = qpos[self._base_q][3:7], self._ref[self._base_q][3:7]
            c = abs(float(np.dot(qa, qr))) / max(float(np.linalg.norm(qa) * np.linalg.norm(qr)), 1e-300)
            e_att = 2.0 * math.acos(min(1.0, c))
        elif self._att_idx is not None:
            e_att = abs(math.remainder(float(qpos[self._att_idx] - self._ref[self._att_idx]), 2 * math.pi))
        else:
            e_att = 0.0
        return e_tip, e_base, e_att

    def get_reward(self, physics: Physics) -> float:
        if physics.divergence is not None:
            return -self.divergence_penalty
        w = self.weights
        e_tip, e_base, e_att = self.errors(physics.data.qpos)
        r = -(w.tip * e_tip + w.base * e_base + w.attitude * e_att)
        return r if math.isfinite(r) else -self.divergence_penalty

    def get_termination(self, physics: Physics) -> float | None:
        return 0.0 if physics.divergence is not None else None


# --------------------------------------------------------------------------- constructors


def from_plant(
    plant: Plant,
    trajectory: Trajectory | None,
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
    sets: Sequence[str] = (),
    **kwargs: Any,
) -> control.Environment:
    """The tracking environment of a scenario, for any robot (see the module docstring).

    Args:
        residual: the action adds to the source controller's command (``rac_dob`` by default).
        scenario: a :class:`~uvms_mj.scenario.schema.Scenario`; a scenario file path or the name of
            a packaged scenario (``"bluerov2_alpha_circle_current"``), resolved as the command line
            does (:func:`uvms_mj.scenario.packaged.resolve_scenario`); a
            :class:`~uvms_mj.sim.experiment.PaperExperiment`; or None (``Scenario()``: the paper's
            experiment). Gives the plant, path, controller (period T, residual base), sensor model,
            warm start and default duration, built as ``uvms-mj run`` builds them
            (:func:`uvms_mj.scenario.schema.build`).
        time_limit: episode length [s]; default the source's duration (40 s for the paper).
        random: seed or ``numpy.random.RandomState`` (sensor noise of the residual controller).
        sets: ``key.path=value`` overrides of a scenario file or name (``uvms-mj run --set``).
        **kwargs: ``reward_weights``, ``torque_limit``, ``divergence_penalty``, ``legacy_step``,
            ``flat_observation`` (see :func:`from_plant`).

    Raises:
        uvms_mj.scenario.schema.ScenarioError: an unknown scenario name, an invalid scenario file or
            combination (one line per problem, naming the file and the field).
        TypeError: ``scenario`` of another type (the message names the type).
        ValueError: bad time_limit, controller period or action bounds.
    """
    from uvms_mj.scenario.packaged import resolve_scenario
    from uvms_mj.scenario.schema import Scenario, ScenarioError, build, load_scenario, sensor_model
    from uvms_mj.sim.experiment import PaperExperiment

    if scenario is None:
        scenario = Scenario()
    elif isinstance(scenario, (str, Path)):
        scenario = load_scenario(resolve_scenario(scenario), sets)
    elif sets:
        raise TypeError("sets= applies to a scenario file or name only")
    if isinstance(scenario, PaperExperiment):
        plant, ctrl = scenario.build()
        sensor, warm, duration = scenario.sensor, scenario.warm_start, scenario.duration
    elif isinstance(scenario, Scenario):
        plant, ctrl = build(scenario)
        sensor = sensor_model(scenario)
        warm, duration = scenario.warm_start, scenario.duration
    else:
        raise TypeError(f"scenario: expected a Scenario, a scenario file path or name, a PaperExperiment or None, "
                        f"got {type(scenario).__name__}")
    T = float(getattr(ctrl, "T", 1.0 / 60.0))
    trajectory = getattr(ctrl, "trajectory", None)
    if trajectory is not None and not isinstance(trajectory, Trajectory):
        trajectory = None
    try:
        return from_plant(plant, trajectory, controller=ctrl if residual else None, T=T,
                          time_limit=duration if time_limit is None else float(time_limit), sensor=sensor,
                          warm_start=warm, random=random, **kwargs)
    except ValueError as exc:
        if isinstance(scenario, Scenario):
            raise ScenarioError(f"scenario {scenario.name!r}: {exc}") from None
        raise
