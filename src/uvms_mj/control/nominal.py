"""The controller's own model of any floating robot: its own MjModel and MjData, never the plant's.

:class:`NominalRobot` compiles the robot FILE with the scenario's nominal overrides, with no
water current (a controller does not know it), and answers the questions a model-based
controller asks at a measured state, using MuJoCo's own functions on its own MjData:

* :meth:`NominalRobot.hold_force` -- the generalized force that holds the robot still at q
  (gravity and buoyancy: ``qfrc_bias - qfrc_passive`` at zero velocity, ``mj_forward``);
* :meth:`NominalRobot.mass_matrix` -- ``mj_fullM`` (added mass included);
* :meth:`NominalRobot.allocation` -- the thrusters' body-frame allocation matrix and limits.

Also :class:`JointTrajectory`: desired arm joint angles from timed waypoints with minimum-jerk
segments (rest at every waypoint).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import mujoco
import numpy as np

from uvms_mj.plant.params import ParameterError
from uvms_mj.physics import model as _pm
from uvms_mj.plant.files import robot_path
from uvms_mj.plant.layout import Layout
from uvms_mj.plant.robot import compile_robot_spec
from uvms_mj.physics.thrusters import allocation_matrix
from uvms_mj.control.trajectories import min_jerk
from uvms_mj.plant.layout import motor_torque_range


class NominalRobot:
    """A robot's nominal model for a controller (see the module docstring).

    Args:
        robot: built-in name or MJCF path (the same file as the plant's).
        overrides: nominal parameter errors, ``{"<element>.<field>": value}``
            (:func:`uvms_mj.plant.robot.apply_overrides`), never the plant's.
        gravity: model gravity and buoyancy (False: :meth:`hold_force` is zero).
        tip_site: end-effector site (default as :class:`uvms_mj.plant.robot.Layout`).
    """

    def __init__(self, robot: str | Path, overrides: Mapping[str, Any] | None = None, gravity: bool = True,
                 tip_site: str | None = None, edit: Callable[[mujoco.MjSpec], None] | None = None) -> None:
        self.path = robot_path(robot)

        def _edit(spec: mujoco.MjSpec) -> None:
            if edit is not None:
                edit(spec)
            # No knowledge of the water's motion: a constant zero current.
            _pm.set_water(spec, current="0 0 0", current_model="constant")
            if not gravity:
                spec.option.gravity = [0.0, 0.0, 0.0]

        self.model = compile_robot_spec(self.path, overrides, edit=_edit)
        self.data = mujoco.MjData(self.model)
        self.layout = Layout.of(self.model, tip_site, allow_planar=True)
        if not _pm.hydro_of(self.model).native:
            # Stripped plugins (no C compiler): serve the reference hydrodynamics on this MjData.
            from uvms_mj.physics import python_backend as _pyb

            self._served = _pyb.Served(self.model, self.data, _pm.hydro_of(self.model))
        m, lay = self.model, self.layout
        self.thruster_lo, self.thruster_hi = (m.actuator_forcerange[lay.thruster_ids].T.copy() if len(lay.thruster_ids)
                                              else (np.zeros(0), np.zeros(0)))
        #: The joint torque [N m] each motor can give (:func:`uvms_mj.plant.layout.motor_torque_range`:
        #: the control and force ranges where limited, times the gear; +-inf where not, the paper's).
        self.motor_lo, self.motor_hi = motor_torque_range(m, lay.motor_ids)
        self.motor_dofs = np.array([m.jnt_dofadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, j)]
                                    for j in lay.motor_joints], dtype=int)

    def tip_at(self, q: Sequence[float]) -> np.ndarray:
        """The end-effector site's position at ``q``, world [m], along the layout's plane axes
        (a planar robot's (x, y); a free vehicle's (x, y, z))."""
        self._set(np.asarray(q, dtype=float))
        return self.data.site_xpos[self.layout.tip_site, list(self.layout.plane_axes)].copy()

    def _set(self, q: np.ndarray, qd: np.ndarray | None = None) -> None:
        d = self.data
        d.qpos[:] = q
        d.qvel[:] = 0.0 if qd is None else qd
        d.time = 0.0
        mujoco.mj_forward(self.model, d)

    def dynamics(self, q: Sequence[float], qd: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
        """(M, h) at the measured state: the full mass matrix (``mj_fullM``, added mass
        included) and h = ``qfrc_bias - qfrc_passive`` (Coriolis and centrifugal, added-mass
        velocity terms, drag, damping, gravity minus buoyancy), so that the generalized force
        giving q_ddot is M q_ddot + h (Eq. 7 of the paper on its nominal model). One
        ``mj_forward`` of the controller's own MjData."""
        self._set(np.asarray(q, dtype=float), np.asarray(qd, dtype=float))
        M = np.zeros((self.model.nv, self.model.nv))
        mujoco.mj_fullM(self.model, self.data, M)
        return M, self.data.qfrc_bias - self.data.qfrc_passive

    def jacobians(self) -> dict[str, np.ndarray]:
        """Jacobians at the state of the last :meth:`dynamics` / :meth:`hold_force` call
        (``mj_jacBody`` at the vehicle's origin, ``mj_jacSite`` at the tip; rows world axes):
        ``base_p``, ``base_r``, ``tip_p``, ``tip_r`` (3 x nv each), and the vehicle's and tip's
        world rotation matrices ``R_base``, ``R_tip`` and tip position ``tip``."""
        m, d, lay = self.model, self.data, self.layout
        nv = m.nv
        out = {k: np.zeros((3, nv)) for k in ("base_p", "base_r", "tip_p", "tip_r")}
        mujoco.mj_jacBody(m, d, out["base_p"], out["base_r"], lay.base_body)
        if lay.tip_site >= 0:
            mujoco.mj_jacSite(m, d, out["tip_p"], out["tip_r"], lay.tip_site)
            out["R_tip"] = d.site_xmat[lay.tip_site].reshape(3, 3).copy()
            out["tip"] = d.site_xpos[lay.tip_site].copy()
        out["R_base"] = d.xmat[lay.base_body].reshape(3, 3).copy()
        out["base"] = d.xpos[lay.base_body].copy()
        return out

    def hold_force(self, q: Sequence[float]) -> np.ndarray:
        """Generalized force (nv) that holds the robot at rest at ``q``: gravity minus buoyancy
        (and joint springs), ``qfrc_bias - qfrc_passive`` at zero velocity. Free-joint rows:
        force in WORLD axes [N], then moment in BODY axes [N m] (MuJoCo's free-joint dofs)."""
        self._set(np.asarray(q, dtype=float))
        return self.data.qfrc_bias - self.data.qfrc_passive

    def mass_matrix(self, q: Sequence[float]) -> np.ndarray:
        """Full nv x nv mass matrix at ``q`` (rigid plus added mass), ``mj_fullM``."""
        self._set(np.asarray(q, dtype=float))
        out = np.zeros((self.model.nv, self.model.nv))
        mujoco.mj_fullM(self.model, self.data, out)
        return out

    def allocation(self) -> np.ndarray:
        """(6, n_thrusters) allocation matrix, vehicle BODY axes, moments about the vehicle origin
        (:func:`uvms_mj.physics.thrusters.allocation_matrix`; configuration-independent)."""
        if not self.layout.thruster_names:
            return np.zeros((6, 0))  # no thrusters: the vehicle cannot be actuated
        self._set(self.model.qpos0.copy())
        return allocation_matrix(self.model, self.data, list(self.layout.thruster_names), frame="body",
                                 body=self.layout.base_body)


@dataclass(frozen=True)
class JointTrajectory:
    """Desired arm joint angles through timed waypoints, minimum-jerk between them (at rest at
    each waypoint); before the first waypoint the start angles, after the last its angles.

    Attributes:
        names: the joints (their order in :meth:`__call__`'s arrays).
        start: the angles at t = 0 [rad] (the robot's initial angles).
        times: waypoint times [s], strictly increasing, > 0.
        angles: (n_waypoints, n_joints) [rad]; a joint a waypoint does not name keeps its
            previous angle.
    """

    names: tuple[str, ...]
    start: np.ndarray
    times: np.ndarray
    angles: np.ndarray

    @classmethod
    def from_waypoints(cls, names: Sequence[str], start: Sequence[float],
                       waypoints: Sequence[tuple[float, Mapping[str, float]]]) -> "JointTrajectory":
        """Build from ``[(t, {joint: angle [rad]}), ...]``.

        Raises:
            ParameterError: unknown joint, non-increasing or negative times.
        """
        names = tuple(names)
        cur = np.asarray(start, dtype=float).copy()
        times, rows = [], []
        last = 0.0
        for i, (t, joints) in enumerate(waypoints):
            t = float(t)
            if not (math.isfinite(t) and t > last):
                raise ParameterError(f"arm.waypoints[{i}].t = {t!r}: times must be finite, > 0 and strictly "
                                     f"increasing (previous {last:g} s)")
            for jn, a in joints.items():
                if jn not in names:
                    raise ParameterError(f"arm.waypoints[{i}].joints.{jn}: not an arm joint; joints: {', '.join(names)}")
                cur[names.index(jn)] = float(a)
            times.append(t)
            rows.append(cur.copy())
            last = t
        return cls(names, np.asarray(start, dtype=float).copy(), np.array(times),
                   np.array(rows).reshape(len(rows), len(names)))

    def __call__(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(angles [rad], rates [rad/s]) at time t."""
        t0, q0 = 0.0, self.start
        for ti, qi in zip(self.times, self.angles):
            if t < ti:
                s, ds, _ = min_jerk((t - t0) / (ti - t0))
                return q0 + float(s) * (qi - q0), float(ds) / (ti - t0) * (qi - q0)
            t0, q0 = ti, qi
        return q0.copy(), np.zeros_like(q0)
