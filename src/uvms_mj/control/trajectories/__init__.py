"""Desired end-effector trajectories in 3-D behind one interface.

Every trajectory is a :class:`Trajectory`: world frame, SI units, and

* ``position(t)``, ``velocity(t)``, ``acceleration(t)``: 3-vectors [m, m/s, m/s^2]. ``t`` may be
  a float (result shape ``(3,)``) or an array of any shape ``S`` (result shape ``S + (3,)``).
* ``duration``: the time [s] after which the trajectory is at rest (:class:`Line3D`,
  :class:`Waypoints`, :class:`CsvTrajectory`) or in its steady periodic motion (:class:`Circle`,
  :class:`Lemniscate`; :class:`Helix`: steady screw motion, periodic up to a translation).
* ``has_orientation`` and ``orientation(t)``: a unit quaternion ``(w, x, y, z)`` (shape ``(4,)``
  or ``S + (4,)``) for those that carry one (a :class:`CsvTrajectory` with quaternion columns);
  ``None`` otherwise.

Kinds:

* :class:`Line3D`: straight line with the trapezoidal speed profile of
  the paper's planar line (its 2-D scalar code: the test oracle ``tests/oracles/planar/trajectory.py``).
* :class:`Waypoints`: minimum-jerk (quintic) segments, at rest at every waypoint.
* :class:`Circle`, :class:`Lemniscate` (of Gerono), :class:`Helix`: periodic curves whose angular
  rate ramps up from 0 with a minimum-jerk profile over ``t_ramp`` (so they start at rest).
* :class:`CsvTrajectory`: samples from a CSV file, C2 cubic spline in position, slerp in attitude.

:func:`make_trajectory` builds any of them from a dict (a scenario section), e.g.
``{"kind": "circle", "centre": [0.5, 0, -1], "radius": 0.1, "period": 20}``.

The minimum-jerk profile used throughout (rest-to-rest in unit time, tau in [0, 1])::

    s(tau)   = 10 tau^3 - 15 tau^4 + 6 tau^5
    s'(tau)  = 30 tau^2 - 60 tau^3 + 30 tau^4         (peak s'(1/2) = 1.875)
    s''(tau) = 60 tau - 180 tau^2 + 120 tau^3
    s(0) = s'(0) = s''(0) = 0,  s(1) = 1,  s'(1) = s''(1) = 0.

Modules: ``base`` (the interface, :func:`min_jerk`, :class:`Shifted`, :func:`starting_at`),
``lines`` (:class:`Line3D`, :class:`Waypoints`), ``curves`` (:class:`Circle`, :class:`Lemniscate`,
:class:`Helix`), ``sampled`` (:class:`CsvTrajectory`, :func:`write_csv`), ``factory``
(:data:`KINDS`, :func:`make_trajectory`); every public name is importable from this package.
"""

from uvms_mj.control.trajectories.base import Shifted, Trajectory, min_jerk, starting_at
from uvms_mj.control.trajectories.curves import Circle, Helix, Lemniscate
from uvms_mj.control.trajectories.factory import KINDS, make_trajectory
from uvms_mj.control.trajectories.lines import Line3D, Waypoints, trapezoid_profile
from uvms_mj.control.trajectories.sampled import CsvTrajectory, write_csv

__all__ = [
    "Trajectory",
    "Line3D",
    "Waypoints",
    "Circle",
    "Lemniscate",
    "Helix",
    "CsvTrajectory",
    "Shifted",
    "KINDS",
    "make_trajectory",
    "min_jerk",
    "starting_at",
    "trapezoid_profile",
    "write_csv",
]
