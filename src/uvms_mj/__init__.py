"""uvms-mj: a MuJoCo testbed for underwater vehicle-manipulator systems.

Reproduces Sagara et al., "Digital type disturbance compensation control of a floating
underwater robot with 2 link manipulator": a floating base with 3 thrusters carrying a planar
2-link arm, with exact added mass, strip-theory drag and buoyancy.

    >>> from uvms_mj import Plant
    >>> plant = Plant()          # default robot, all hydrodynamics on
    >>> plant.step(120)          # 1 s at the default 1/120 s step (RK4)
"""

# Without a display and without a user choice, pick a headless OpenGL backend (MUJOCO_GL)
# before anything imports mujoco; with a display, or MUJOCO_GL set, nothing changes (render.py).
from .render import configure_gl as _configure_gl

_configure_gl()

from .kinematics import ArmGeometry
from .hydro import HydroModel, HydroTerms, strip_integrals
from .params import ParameterError, RobotParams, read_params
from .plant import DivergenceError, Energy, Plant, default_model_path, models_dir

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
