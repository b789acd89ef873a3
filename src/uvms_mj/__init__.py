"""uvms-mj: a MuJoCo testbed for underwater vehicle-manipulator systems.

Reproduces Sagara et al., "Digital type disturbance compensation control of a floating
underwater robot with 2 link manipulator": a floating base with 3 thrusters carrying a planar
2-link arm, with exact added mass, strip-theory drag and buoyancy.

    >>> from uvms_mj import Plant
    >>> plant = Plant()          # default robot, all hydrodynamics on
    >>> plant.step(120)          # 1 s at the default 1/120 s step (RK4)
"""

import os as _os
import sys as _sys

if _sys.argv and _os.path.basename(_sys.argv[0]) == "uvms-mj":
    # The command line: Ctrl-C exits 130 at once, quietly (no KeyboardInterrupt traceback, and
    # none swallowed by an import lock's callback); runs and sweeps install their own handler
    # (recorder.handle_sigterm) that closes the log first.
    import signal as _signal

    _signal.signal(_signal.SIGINT, lambda *_: (_sys.stderr.write("interrupted\n"), _os._exit(130)))

# Without a display and without a user choice, pick a headless OpenGL backend (MUJOCO_GL)
# before anything imports mujoco; with a display, or MUJOCO_GL set, nothing changes (render.py).
from uvms_mj.analysis.render import configure_gl as _configure_gl

_configure_gl()

import warnings as _warnings

from uvms_mj.physics import build as _build

# Register the uvms MuJoCo plugins (hydrodynamics, thrusters) with MuJoCo: after this, plain
# MuJoCo loads and simulates any model file that uses them. Without a C compiler: one line, and
# uvms_mj's own loaders fall back to the numpy reference (uvms_mj.physics.python_backend).
if not _build.register_plugins() and _build._mode() != "off":
    _warnings.warn(f"uvms_mj: the C plugins are unavailable ({_build.unavailable_reason()}); "
                   "using the numpy reference hydrodynamics (slower)", RuntimeWarning, stacklevel=2)

from uvms_mj.planar.kinematics import ArmGeometry
from uvms_mj.planar.hydro import HydroModel, HydroTerms, strip_integrals
from uvms_mj.plant.params import ParameterError, RobotParams, read_params
from uvms_mj.plant.plant import DivergenceError, Energy, Plant, default_model_path, models_dir

__all__ = [
    "ArmGeometry",
    "DivergenceError",
    "Energy",
    "HydroModel",
    "HydroTerms",
    "ParameterError",
    "Plant",
    "RobotParams",
    "default_model_path",
    "models_dir",
    "read_params",
    "strip_integrals",
]
__version__ = "0.1.0"
