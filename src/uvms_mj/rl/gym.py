"""Gymnasium environments over :mod:`uvms_mj.rl.env` (``pip install 'uvms-mj[gym]'``).

Importing this module registers two environments with gymnasium::

    import gymnasium as gym
    import uvms_mj.rl.gym  # noqa: F401  (registers the ids below)

    env = gym.make("uvms_mj/Tracking-v0")              # plain: the action is the command
    env = gym.make("uvms_mj/TrackingResidual-v0")      # residual on rac_dob
    env = gym.make("uvms_mj.rl.gym:uvms_mj/Tracking-v0")  # the same, without the import

Both are the dm_control environment of :func:`uvms_mj.rl.env.load` (same plant, observations,
reward and episode length: 40 s by default, ``time_limit=`` to change it), converted by shimmy's
``DmControlCompatibilityV0`` and with the action normalised to [-1, 1] in every component
(affinely, as ``gymnasium.wrappers.RescaleAction`` would; out-of-range values are clipped): -1 and +1 are the bounds of the dm_control action spec
(thrust -8.849 / +15.978 N, torques +-20 N m; the residual bounds in residual mode), so 0 is not
zero thrust in plain mode. Observations are a ``Dict`` of float64 boxes (the dm_control keys).
The end of an episode at the time limit is ``truncated``; a divergence is ``terminated``.
``reset(seed=s)`` also seeds the sensor noise of the residual controller.

Keyword arguments of ``gym.make`` go to :func:`uvms_mj.rl.env.load` (``scenario``, ``time_limit``,
``random``, ``reward_weights``, ``torque_limit``...), except ``render_mode`` ("rgb_array":
dm_control's off-screen render of the scene's first camera; on Linux without a display and with
``MUJOCO_GL`` unset, the first render creates an EGL, else OSMesa, context instead of dm_control's
GLFW default: :meth:`uvms_mj.rl.env.Physics._make_rendering_contexts`).
"""

from __future__ import annotations

from typing import Any

try:
    import gymnasium
    from shimmy.dm_control_compatibility import DmControlCompatibilityV0
except ImportError as exc:  # pragma: no cover - exercised only without the extra
    raise ImportError(f"uvms_mj.rl.gym needs gymnasium and shimmy ({exc}): pip install 'uvms-mj[gym]'") from None

import numpy as np

__all__ = ["ENV_IDS", "make_env", "register_envs"]

#: Registered ids and whether each is residual.
ENV_IDS = {"uvms_mj/Tracking-v0": False, "uvms_mj/TrackingResidual-v0": True}


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


def _plain(**kwargs: Any) -> gymnasium.Env:
    return make_env(residual=False, **kwargs)


def _residual(**kwargs: Any) -> gymnasium.Env:
    return make_env(residual=True, **kwargs)


def register_envs() -> None:
    """Register :data:`ENV_IDS` with gymnasium (idempotent)."""
    for env_id, residual in ENV_IDS.items():
        if env_id not in gymnasium.registry:
            gymnasium.register(id=env_id, entry_point=_residual if residual else _plain,
                               disable_env_checker=True)


register_envs()
