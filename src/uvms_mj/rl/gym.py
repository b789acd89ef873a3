"""Gymnasium environments over :mod:`uvms_mj.rl.env`, for any robot (``pip install 'uvms-mj[gym]'``).

Two ids, registered when ``uvms_mj`` is imported (:mod:`uvms_mj.rl.registration`; importing this
module registers them too)::

    import gymnasium as gym
    import uvms_mj  # noqa: F401  (registers the ids below)

    env = gym.make("uvms_mj/Tracking-v0")                       # the paper's experiment, plain
    env = gym.make("uvms_mj/TrackingResidual-v0",               # residual on the scenario's controller
                   scenario="bluerov2_alpha_circle_current")    # a packaged name or a file path
    envs = gym.make_vec("uvms_mj/Tracking-v0", num_envs=4, vectorization_mode="async",
                        scenario="bluerov2_alpha_station")      # one process per environment
    envs = uvms_mj.rl.gym.make_vec(4, scenario="paper")         # the same, any multiprocessing context

Each is the dm_control environment of :func:`uvms_mj.rl.env.load` (same plant as ``uvms-mj run``
builds, observations, reward and episode length: the scenario's duration by default,
``time_limit=`` to change it), converted by shimmy's ``DmControlCompatibilityV0``, with the action
normalised to [-1, 1] in every component (affinely, as ``gymnasium.wrappers.RescaleAction``
would; out-of-range values are clipped): -1 and +1 are the bounds of the dm_control action spec,
the model's thruster force ranges and motor torque ranges (:mod:`uvms_mj.rl.layout`; the paper's:
thrust -8.849 / +15.978 N, torques +-20 N m, so 0 is not zero thrust in plain mode; the
BlueROV2's: +-30.622 N, the Alpha's +-9 N m and +-5 N m), or the residual bounds in residual mode
(where 0 is the controller's own command). The action's components are named by
``env.unwrapped.action_names`` (thrusters, then motors). Observations are a ``Dict`` of float64
boxes (the dm_control keys), each component named by ``env.unwrapped.observation_names``. The
end of an episode at the time limit is ``truncated``; a divergence is ``terminated``.
``reset(seed=s)`` also seeds the sensor noise of the residual controller.

Keyword arguments of ``gym.make`` go to :func:`uvms_mj.rl.env.load` (``scenario``, ``sets``,
``time_limit``, ``random``, ``reward_weights``, ``torque_limit``...), except ``render_mode``
("rgb_array": dm_control's off-screen render of the scene's first camera; on Linux without a display
and with ``MUJOCO_GL`` unset, the first render creates an EGL, else OSMesa, context instead of
dm_control's GLFW default: :meth:`uvms_mj.rl.physics.Physics._make_rendering_contexts`). A bad
scenario raises :class:`~uvms_mj.scenario.schema.ScenarioError` (a ValueError) in one line naming
the file and the field.
"""

from __future__ import annotations

import functools
from typing import Any

try:
    import gymnasium
    from shimmy.dm_control_compatibility import DmControlCompatibilityV0
except ImportError as exc:  # pragma: no cover - exercised only without the extra
    raise ImportError(f"uvms_mj.rl.gym needs gymnasium and shimmy ({exc}): pip install 'uvms-mj[gym]'") from None

import numpy as np

from uvms_mj.rl.registration import ENV_IDS, register_envs

__all__ = ["ENV_IDS", "make_env", "make_vec", "register_envs", "tracking", "tracking_residual"]


class _Compat(DmControlCompatibilityV0):
    """shimmy's wrapper with the action normalised to [-1, 1] (affinely onto the dm_control
    bounds, as ``gymnasium.wrappers.RescaleAction`` does) and ``reset(seed=...)`` also seeding
    the task (sensor noise)."""

    def __init__(self, env: Any, render_mode: str | None = None) -> None:
        super().__init__(env, render_mode=render_mode)
        spec = self.action_space
        #: the dm_control action bounds that -1 and +1 map to
        self.action_low, self.action_high = spec.low.astype(np.float64), spec.high.astype(np.float64)
        self.action_space = gymnasium.spaces.Box(-1.0, 1.0, shape=spec.shape, dtype=np.float64)
        task = env.task
        #: the action's components: thruster names, then motor names
        self.action_names: list[str] = list(task.action_names)
        #: observation key -> the names of its components (:func:`uvms_mj.rl.layout.observation_names`)
        self.observation_names: dict[str, list[str]] = {k: list(v) for k, v in task.observation_names.items()}

    def step(self, action):
        a = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
        return super().step(self.action_low + 0.5 * (a + 1.0) * (self.action_high - self.action_low))

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        if seed is not None:
            self._env.task._random = np.random.RandomState(seed)
        return super().reset(seed=seed, options=options)


def make_env(residual: bool = False, render_mode: str | None = None, **kwargs: Any) -> gymnasium.Env:
    """The gymnasium environment (see the module docstring); ``kwargs`` go to ``uvms_mj.rl.env.load``."""
    from uvms_mj.rl import env as uvms_env

    return _Compat(uvms_env.load(residual=residual, **kwargs), render_mode=render_mode)


def tracking(**kwargs: Any) -> gymnasium.Env:
    """``uvms_mj/Tracking-v0``: the action is the command (thrusts and joint torques, normalised)."""
    return make_env(residual=False, **kwargs)


def tracking_residual(**kwargs: Any) -> gymnasium.Env:
    """``uvms_mj/TrackingResidual-v0``: the action adds to the scenario's controller command."""
    return make_env(residual=True, **kwargs)


def make_vec(num_envs: int, residual: bool = False, context: str | None = None,
             **kwargs: Any) -> gymnasium.vector.AsyncVectorEnv:
    """``num_envs`` environments, each in its own process (``gymnasium.vector.AsyncVectorEnv``;
    ``context``: the multiprocessing start method, e.g. "spawn"; the environment functions are
    picklable, so every method works). ``kwargs`` go to :func:`make_env`; ``reset(seed=s)`` seeds
    environment i with s + i.

    Raises:
        ValueError: num_envs < 1.
    """
    if int(num_envs) < 1:
        raise ValueError(f"num_envs = {num_envs!r} must be >= 1")
    fn = functools.partial(make_env, residual, **kwargs)
    return gymnasium.vector.AsyncVectorEnv([fn] * int(num_envs), context=context)


register_envs()
