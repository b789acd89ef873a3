"""The plant's actuation: thrusters and joint motors, as :class:`uvms_mj.plant.plant.Plant`
exposes them (a mixin, kept apart to keep the plant's module short; its methods read the
attributes ``Plant.__init__`` sets: ``data``, ``model``, ``_thr`` / ``_mot`` (the thrusters' and
motors' actuator ids), ``_thr_act`` (their lag states), ``_thr_lo`` / ``_thr_hi`` (force ranges
[N]), ``_groups`` (thrust curves and their inverses), ``_direct`` (unit-gain thrusters),
``_thr_lagged``, ``dead_zone`` / ``_dead_band``, ``_tip`` / ``_tip_axes``)).

Units: thrusts [N] along each thruster's axis; joint torques [N m]; actuator commands in the
actuator's own units (newtons for unit-gain thrusters, else e.g. a normalised voltage).
"""

from __future__ import annotations

from functools import cached_property
from typing import Sequence

import numpy as np

from uvms_mj.physics.thrusters.curves import _poly
from uvms_mj.plant.layout import motor_clamps, motor_torques
from uvms_mj.plant.stepping import _finite

__all__ = ["Actuation"]


def _clipped_poly(curve, u: list, lo: list, hi: list) -> list:
    """np.clip(curve(u), lo, hi) of a polynomial thrust curve on floats: the same Horner steps
    (:class:`uvms_mj.physics.thrusters.curves._Poly`) and np.clip's own comparisons (NaN kept,
    max(x, lo) = x if x > lo else lo, then min(x, hi) = x if x < hi else hi)."""
    p = _poly(curve.coeffs)
    kind, top, rev = p.kind, p.top, p.rev
    out = []
    for v, a, b in zip(u, lo, hi):
        x = v * v if kind != "plain" else v
        y = top
        for c in rev:
            y = y * x + c
        if kind == "odd":
            y = v * y
        if y == y:
            y = y if y > a else a
            y = y if y < b else b
        out.append(y)
    return out


class Actuation:
    """Thrusters and joint motors of :class:`uvms_mj.plant.plant.Plant` (module docstring)."""

    @property
    def thruster_forces(self) -> np.ndarray:
        """Actual thrust of each thruster along its axis [N] now: the thrust curve at the lag
        state (the command without a lag), clamped to the force range (``data.actuator_force``
        holds the value at the start of the last step)."""
        if not len(self._thr):
            return np.zeros(0)
        if self._direct and self._thr_lagged:
            return np.minimum(np.maximum(self.data.act[self._thr_act], self._thr_lo), self._thr_hi)
        u = self.data.act[self._thr_act] if self._thr_lagged else self.data.ctrl[self._thr]
        groups = self._groups
        if len(groups) == 1:  # one curve for every thruster (in order)
            c = groups[0][1]
            if c.kind == "poly" and u.size <= 32:
                return np.array(_clipped_poly(c, u.tolist(), self._thr_lo.tolist(), self._thr_hi.tolist()))
            return np.clip(c(u), self._thr_lo, self._thr_hi)
        f = np.empty(u.size)
        for ks, c, _ in groups:
            f[ks] = c(u[ks])
        return np.clip(f, self._thr_lo, self._thr_hi)

    @property
    def thruster_commands(self) -> np.ndarray:
        """The thrusters' actuator commands (``ctrl``: newtons for unit-gain thrusters, after the
        optional dead zone; else the actuator's units, e.g. a normalised voltage)."""
        return self.data.ctrl[self._thr].copy()

    @property
    def joint_torques_applied(self) -> np.ndarray:
        """The joint torques the motors apply for the held commands [N m] (:attr:`Layout.motor_names`
        order): MuJoCo's motor force after its ``ctrlrange`` / ``forcerange`` clamps, times the gear
        (:func:`uvms_mj.plant.layout.motor_torques`; what the next step applies). The ranges are
        read once after each :meth:`reset` (:func:`uvms_mj.plant.layout.motor_clamps`)."""
        clamps = self.__dict__.get("_motor_clamps")
        if clamps is None:
            arrays = motor_clamps(self.model, self._mot)
            clamps = self._motor_clamps = (arrays, list(zip(*(v.tolist() for v in arrays))))
        arrays, per_motor = clamps
        ctrl = self.data.ctrl[self._ctrl_slices[1]]
        if len(per_motor) > 16:
            return motor_torques(self.model, self._mot, ctrl, arrays)
        out = []  # motor_torques' steps on floats: x if lo <= x, as np.maximum(x, lo) (and min)
        for x, (clo, chi, gain, flo, fhi, gear) in zip(ctrl.tolist(), per_motor):
            x = clo if clo > x else x
            x = gain * (chi if chi < x else x)
            x = flo if flo > x else x
            out.append(gear * (fhi if fhi < x else x))
        return np.array(out)

    def thrust_to_ctrl(self, thrust: Sequence[float]) -> np.ndarray:
        """Actuator commands for thrusts [N] (the thrust itself for unit-gain thrusters; else
        the inverse of the model's curve, clamped)."""
        f = np.asarray(thrust, dtype=float).ravel()
        if self._direct:
            return f.copy()
        groups = self._groups
        if len(groups) == 1:  # one curve and range for every thruster (in order)
            return groups[0][2](f)
        u = np.empty(f.size)
        for ks, _, inv in groups:
            u[ks] = inv(f[ks])
        return u

    def warm_start(self, thrust: Sequence[float]) -> None:
        """Start the thrusters' lag states at ``thrust`` [N] (holding station when the run
        starts): the lag state of a unit-gain thruster is its force (clamped to the range), a
        curve thruster's its command."""
        if not self._thr_lagged:
            return
        if self._direct:
            self.data.act[self._thr_act] = np.clip(np.asarray(thrust, dtype=float), self._thr_lo, self._thr_hi)
        else:
            self.data.act[self._thr_act] = self.thrust_to_ctrl(thrust)

    # ---------------------------------------------------------------- inputs

    def set_thrust(self, commands: Sequence[float]) -> None:
        """Command each thruster's thrust [N along its axis] (:attr:`Layout.thruster_names`
        order), held until changed. MuJoCo clamps the force to the force range and lags it
        (first order) where the model says so; with ``dead_zone`` on, commands inside the dead
        zone give no thrust."""
        u = self._thrust_ctrl(commands)
        if u.size:
            self.data.ctrl[self._thr] = u

    def _thrust_ctrl(self, commands: Sequence[float], finite: bool = False) -> np.ndarray:
        """The thrusters' actuator commands for thrusts [N] (checked; the dead zone applied)."""
        c = np.asarray(commands, dtype=float)
        n = len(self._thr)
        if c.shape != (n,) or not (finite or _finite(c)):
            raise ValueError(f"thruster commands {commands!r} must be {n} finite numbers [N]")
        if self.dead_zone:
            lo, hi = self._dead_band
            c = np.where((c > lo) & (c < hi), 0.0, c)
        return c if self._direct else self.thrust_to_ctrl(c)

    def set_joint_torques(self, torques: Sequence[float]) -> None:
        """Command the joint actuators (:attr:`Layout.motor_names` order) [N m], held until
        changed."""
        t = self._torque_ctrl(torques)
        if t.size:
            self.data.ctrl[self._mot] = t

    def _torque_ctrl(self, torques: Sequence[float], finite: bool = False) -> np.ndarray:
        t = np.asarray(torques, dtype=float)
        n = len(self._mot)
        if t.shape != (n,) or not (finite or _finite(t)):
            raise ValueError(f"joint torques {torques!r} must be {n} finite numbers [N m]")
        return t

    def observe(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(q, qd, tip_position, thruster_forces) now (new arrays)."""
        return self.q, self.qd, self.tip_position, self.thruster_forces

    def command(self, thrust: Sequence[float], torques: Sequence[float], *, finite: bool = False) -> None:
        """:meth:`set_thrust` and :meth:`set_joint_torques` at once (each checked first; with
        ``finite`` the caller has checked that every value is finite, as the sampled loop does)."""
        if finite and self._direct and not self.dead_zone and type(thrust) is type(torques) is np.ndarray \
                and thrust.shape == (len(self._thr),) and torques.shape == (len(self._mot),) \
                and thrust.dtype == torques.dtype == np.float64:
            c, t = thrust, torques  # what _thrust_ctrl and _torque_ctrl give them
        else:
            c, t = self._thrust_ctrl(thrust, finite), self._torque_ctrl(torques, finite)
        ctrl = self.data.ctrl
        thr, mot = self._ctrl_slices
        if c.size:
            ctrl[thr] = c
        if t.size:
            ctrl[mot] = t

    @cached_property
    def _ctrl_slices(self) -> tuple:
        """The thrusters' and motors' actuator indices, as slices where they are consecutive
        (a slice assignment costs less than a fancy one)."""
        def as_slice(idx):
            idx = [int(i) for i in np.ravel(idx)]
            if idx and idx == list(range(idx[0], idx[0] + len(idx))):
                return slice(idx[0], idx[0] + len(idx))
            return np.asarray(idx, dtype=int)
        return as_slice(self._thr), as_slice(self._mot)

    def _io_layout(self) -> tuple:
        """(tip_site, ntip, thr_act, lo, hi) of :class:`uvms_mj.physics.plant_io.PlantIO`: the
        tip's coordinates along the plane axes (the first ``ntip`` of its world position); the
        thrust = the lag state clamped to the force range for unit-gain lagged thrusters (else
        None: the plant computes it through the curves)."""
        ntip = len(self._tip_axes) if self._tip >= 0 and self._tip_axes in ([0, 1], [0, 1, 2]) else 0
        if self._direct and self._thr_lagged:
            return max(self._tip, 0), ntip, self._thr_act, self._thr_lo, self._thr_hi
        return max(self._tip, 0), ntip, None, None, None
