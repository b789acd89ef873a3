"""What makes MuJoCo simulate water: the uvms plugins, loading robot files, the reference maths.

* :mod:`.build` compiles ``plugin/*.c`` (the ``uvms.water``, ``uvms.hydro`` and
  ``uvms.thruster`` MuJoCo plugins) into one library and registers it with MuJoCo when the first
  model that uses them is loaded (:func:`~.build.register_plugins`, idempotent; not at import),
  so plain MuJoCo then simulates any model file that uses them. ``UVMS_MJ_COMPILED=auto|on|off``
  (:func:`~.build.compiled_mode`) is the one switch between compiled and Python paths.
* :mod:`.model` loads, validates, edits and compiles such files (and strips the plugins for the
  Python backend where no C compiler exists).
* :mod:`.config` parses the plugin attributes (``docs/hydrodynamics.md``).
* :mod:`.reference` is the same physics in numpy, one function per term, for reading and for the
  tests; :mod:`.python_backend` serves it through ``mjcb_passive``.
"""

from __future__ import annotations

from typing import Any

_EXPORTS = {
    "HydroInfo": "model",
    "ModelError": "model",
    "PluginUnavailableError": "build",
    "compile_spec": "model",
    "hydro_of": "model",
    "load_model": "model",
    "load_spec": "model",
    "register_plugins": "build",
    "unavailable_reason": "build",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'uvms_mj.physics' has no attribute {name!r}")
    import importlib

    return getattr(importlib.import_module(f"uvms_mj.physics.{module}"), name)
