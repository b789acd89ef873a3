"""uvms-mj: a MuJoCo testbed for underwater vehicle-manipulator systems.

Reproduces Sagara et al., "Digital type disturbance compensation control of a floating
underwater robot with 2 link manipulator": a floating base with 3 thrusters carrying a planar
2-link arm, with exact added mass, strip-theory drag and buoyancy.

    >>> from uvms_mj import Plant
    >>> plant = Plant()          # default robot, all hydrodynamics on
    >>> plant.step(120)          # 1 s at the default 1/120 s step (RK4)

Importing the package only defines names: the public ones below are imported on first access.
Nothing is compiled, no environment variable is set and no signal handler is installed at import.
The one registration: the gymnasium ids ``uvms_mj/Tracking-v0`` and ``uvms_mj/TrackingResidual-v0``
(:mod:`uvms_mj.rl.registration`): at once if gymnasium is imported already, else by a finder on
``sys.meta_path`` that waits for gymnasium's import (gymnasium itself is never imported here, and
nothing happens if it is not installed). The uvms MuJoCo plugins are built (C compiler, cached) and registered with
MuJoCo when the first model that uses them is loaded (:func:`uvms_mj.physics.build.register_plugins`,
which every loader calls); the OpenGL backend is chosen when rendering starts
(:mod:`uvms_mj.analysis.render_gl`); the command line installs its Ctrl-C / SIGTERM handling when
it runs.

One switch, ``UVMS_MJ_COMPILED=auto|on|off`` (read when first needed,
:func:`uvms_mj.physics.build.compiled_mode`), chooses between the compiled paths (the plugins, the
RAC kernel, the plant's compiled sample, the planar nominal model's C code) and their Python/numpy
references: ``auto`` (default) compiled where a C compiler is available, else Python with one
warning; ``on`` compiled or a clear error; ``off`` Python everywhere.
"""

from __future__ import annotations  # (no typing import: the command line's start-up passes here first)

#: Public name -> the module that defines it (imported on first access, see __getattr__).
_EXPORTS = {
    "DivergenceError": "uvms_mj.plant.plant",
    "Energy": "uvms_mj.plant.plant",
    "HydroTerms": "uvms_mj.physics.terms",
    "ParameterError": "uvms_mj.plant.params",
    "Plant": "uvms_mj.plant.plant",
    "RobotParams": "uvms_mj.plant.params",
    "default_model_path": "uvms_mj.plant.plant",
    "models_dir": "uvms_mj.plant.plant",
    "read_params": "uvms_mj.plant.params",
    "strip_integrals": "uvms_mj.physics.reference",
}

__all__ = sorted(_EXPORTS)
__version__ = "0.1.0"


from uvms_mj.rl.registration import register_when_imported as _register_gym

_register_gym()


def __getattr__(name: str) -> object:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'uvms_mj' has no attribute {name!r}")
    import importlib

    from uvms_mj.analysis.render_gl import guard_mujoco_import

    guard_mujoco_import()  # a MUJOCO_GL that would break `import mujoco`: simulate without rendering
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *_EXPORTS])
