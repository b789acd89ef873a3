"""The gymnasium ids of uvms_mj, registered without importing gymnasium before it is needed.

``import uvms_mj`` calls :func:`register_when_imported`: if gymnasium is imported already, the ids
are registered at once; otherwise one finder is put on ``sys.meta_path`` that does nothing until
gymnasium itself is imported, then registers the ids right after gymnasium's own import and takes
itself off again. So ``gymnasium.make("uvms_mj/Tracking-v0")`` works after ``import uvms_mj``,
whichever of the two is imported first, and importing uvms_mj neither imports gymnasium nor fails
where it is not installed. (gymnasium 1.x reads no plugin entry points: its 0.x
``gymnasium.envs`` entry-point group was removed in 1.0, so there is no installed-metadata way.)

The ids' entry points are strings (``"uvms_mj.rl.gym:tracking"``): nothing of the environments
(dm_control, the plant) is imported until ``gymnasium.make``.
"""

from __future__ import annotations

import sys

#: Registered ids and whether each is residual.
ENV_IDS = {"uvms_mj/Tracking-v0": False, "uvms_mj/TrackingResidual-v0": True}
_ENTRY_POINTS = {False: "uvms_mj.rl.gym:tracking", True: "uvms_mj.rl.gym:tracking_residual"}

__all__ = ["ENV_IDS", "register_envs", "register_when_imported"]


def register_envs() -> None:
    """Register :data:`ENV_IDS` with gymnasium (idempotent; imports gymnasium)."""
    from gymnasium.envs.registration import register, registry

    for env_id, residual in ENV_IDS.items():
        if env_id not in registry:
            # disable_env_checker: the observations are unbounded (-inf, inf) boxes, on which the
            # passive checker warns at every make (check_env passes: tests/test_gym.py)
            register(id=env_id, entry_point=_ENTRY_POINTS[residual], disable_env_checker=True)


class _Loader:
    """gymnasium's own loader, registering the ids once gymnasium's module has run."""

    def __init__(self, inner) -> None:
        self._inner = inner

    def create_module(self, spec):
        return self._inner.create_module(spec)

    def exec_module(self, module) -> None:
        self._inner.exec_module(module)
        register_envs()

    def __getattr__(self, name: str):
        return getattr(self._inner, name)


class _WhenGymnasiumImported:
    """A ``sys.meta_path`` finder that answers only for ``gymnasium``, once (module docstring)."""

    def find_spec(self, name: str, path=None, target=None):
        if name != "gymnasium":
            return None
        _unhook()
        import importlib.util

        spec = importlib.util.find_spec(name)  # the other finders' answer
        if spec is not None and spec.loader is not None and hasattr(spec.loader, "exec_module"):
            spec.loader = _Loader(spec.loader)
        return spec


def _unhook() -> None:
    sys.meta_path[:] = [f for f in sys.meta_path if not isinstance(f, _WhenGymnasiumImported)]


def register_when_imported() -> None:
    """Register the ids now if gymnasium is imported, else as soon as it is (module docstring)."""
    if "gymnasium" in sys.modules:
        try:
            register_envs()
        except Exception:  # noqa: BLE001 - a broken gymnasium must not break `import uvms_mj`
            pass
    elif not any(isinstance(f, _WhenGymnasiumImported) for f in sys.meta_path):
        sys.meta_path.insert(0, _WhenGymnasiumImported())
