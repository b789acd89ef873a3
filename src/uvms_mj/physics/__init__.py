"""What makes MuJoCo simulate water: the uvms plugins, loading robot files, the reference maths.

* :mod:`.build` compiles ``plugin/*.c`` (the ``uvms.water``, ``uvms.hydro`` and
  ``uvms.thruster`` MuJoCo plugins) into one library and registers it with MuJoCo;
  ``import uvms_mj`` does this, so plain MuJoCo then simulates any model file that uses them.
* :mod:`.model` loads, validates, edits and compiles such files (and strips the plugins for the
  Python backend where no C compiler exists).
* :mod:`.config` parses the plugin attributes (``docs/hydrodynamics.md``).
* :mod:`.reference` is the same physics in numpy, one function per term, for reading and for the
  tests; :mod:`.python_backend` serves it through ``mjcb_passive``.
"""

from uvms_mj.physics.build import PluginUnavailableError, register_plugins, unavailable_reason
from uvms_mj.physics.model import HydroInfo, ModelError, compile_spec, hydro_of, load_model, load_spec

__all__ = [
    "HydroInfo",
    "ModelError",
    "PluginUnavailableError",
    "compile_spec",
    "hydro_of",
    "load_model",
    "load_spec",
    "register_plugins",
    "unavailable_reason",
]
