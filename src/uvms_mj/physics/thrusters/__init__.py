"""Thruster allocation for any layout: allocation matrix, saturating allocator, thrust curves.

Three pieces, independent of the paper robot (for its three planar thrusters see also
the paper's planar allocator (the test oracle ``tests/oracles/planar/allocation.py``), whose "clip" / "scale" behaviour is unchanged):

* :func:`allocation_matrix` -- the 6 x n matrix B of a compiled MuJoCo model's thruster
  actuators (site transmission), wrench = B @ thrust.
* :class:`Allocator` -- weighted least squares with box limits on the thrusts, solved by the
  redistributed pseudo-inverse with a bounded-least-squares fallback; the result always
  minimises the stated weighted error inside the box.
* :class:`ThrustCurve` / :func:`invert_curve` -- the ``uvms.thruster`` curve forms
  (docs/hydrodynamics.md, "Thrusters") and their inverse, so that a controller can command
  forces in N.

SI units throughout: forces in N, moments in N m, positions in m. Wrenches are ordered linear
first, (Fx, Fy, Fz, Mx, My, Mz), as in Fossen's (X, Y, Z, K, M, N).

Modules: ``matrix`` (:func:`thruster_actuators`, :func:`allocation_matrix`), ``allocator``
(:class:`Allocator`, :class:`AllocationResult`, :data:`DOF_NAMES`), ``curves``
(:class:`ThrustCurve`, :func:`invert_curve`, :class:`CurveInverse`, :func:`thruster_curves`,
:func:`thrust_commands`); every public name is importable from this package.
"""

from uvms_mj.physics.thrusters.allocator import DOF_NAMES, AllocationResult, Allocator
from uvms_mj.physics.thrusters.curves import (
    CurveInverse,
    ThrustCurve,
    invert_curve,
    thrust_commands,
    thruster_curves,
)
from uvms_mj.physics.thrusters.matrix import allocation_matrix, thruster_actuators

__all__ = [
    "DOF_NAMES",
    "thruster_actuators",
    "allocation_matrix",
    "AllocationResult",
    "Allocator",
    "ThrustCurve",
    "invert_curve",
    "CurveInverse",
    "thruster_curves",
    "thrust_commands",
]
