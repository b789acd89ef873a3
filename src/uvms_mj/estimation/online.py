"""The ESKF run online in the sampled loop (``controller.feedback: estimate``, issue 21 item 2).

:class:`OnlineEstimator` reads the navigation suite's samples (:class:`uvms_mj.sim.navsensors.NavigationRecord`)
as the plant produces them and feeds them to the :class:`~uvms_mj.estimation.eskf.ESKF` in the order they
ARRIVE: at a control sample ``t_k`` every sample whose arrival time is ``<= t_k`` (the IMU's measurement time plus
its latency; the DVL's, depth's and fixes' ``t_arrival``), ties in the order IMU, DVL, depth, fix. A delayed sample
carries its measurement time; the ESKF applies it there (its buffer and re-propagation). The pose and velocity
the controller gets are ``ESKF.state(t_k)``: the estimate extrapolated from the last IMU sample to ``t_k``.

Our assumptions (documented in docs/estimation.md "In the loop"):

* initial state: the plant's true pose and velocity at t = 0, zero biases, with the covariance :data:`P0_SIGMA`
  (the same prior as tests/test_eskf.py's end-to-end test): 0.1 m, 0.05 m/s, 0.02 / 0.02 / 0.05 rad
  (roll, pitch, yaw), 0.02 m/s^2 accelerometer bias, 0.002 rad/s gyro bias, per axis;
* filter parameters: :func:`~uvms_mj.estimation.from_sensors.params_from_navigation` (the filter models the
  simulated sensors' own noise), a fix gate at the chi-square 99.9 % point for 3 dof (:data:`FIX_GATE`), the
  ESKF's default buffer (2 s), enough for any latency below it.
"""

from __future__ import annotations

from typing import Optional

import numpy as np

from uvms_mj.estimation.eskf import ESKF, NavEstimate, NavState
from uvms_mj.estimation.from_sensors import params_from_navigation

__all__ = ["FIX_GATE", "OnlineEstimator", "P0_SIGMA"]

#: The initial error-state standard deviations (dp [m] x3, dv [m/s] x3, dtheta [rad] roll, pitch, yaw,
#: accelerometer bias [m/s^2] x3, gyro bias [rad/s] x3): ours, those of tests/test_eskf.py's end-to-end test.
P0_SIGMA = np.array([0.1] * 3 + [0.05] * 3 + [0.02, 0.02, 0.05] + [0.02] * 3 + [0.002] * 3)

#: The position fixes' outlier gate on the NIS: scipy.stats.chi2.ppf(0.999, 3) = 16.266 (3 dof, 0.1 % of the
#: inliers rejected); the USBL's outliers (navsensors: 2 % by default) are rejected by it.
FIX_GATE = 16.266

_ORDER = ("imu", "dvl", "depth", "fix")


class OnlineEstimator:
    """The ESKF on a run's navigation samples as they arrive (module docstring).

    Args:
        config: the navigation sensors (:class:`uvms_mj.sim.navsensors.NavigationConfig`).
        record: the suite's record (filled as the plant steps; its ``mounts`` already set).
        gravity: (3,) world [m/s^2] (the plant model's ``opt.gravity``).
        water_density: [kg/m^3] (the depth sensor's conversion).
        position, velocity, quat: the initial state (world; quat w x y z, world <- body).
        trim: drop every sample from ``record`` once fed (a run that keeps no samples: memory that
            does not grow with its duration); False: the record keeps them.
    """

    def __init__(self, config, record, gravity, water_density: float, position, velocity, quat,
                 trim: bool = False) -> None:
        params = params_from_navigation(config, record, gravity, water_density=water_density, fix_gate=FIX_GATE)
        self.record = record
        self.trim = bool(trim)
        self.filter = ESKF(NavState(np.asarray(position, float), np.asarray(velocity, float),
                                    np.asarray(quat, float)), np.diag(P0_SIGMA ** 2), params)
        self._next = {k: 0 for k in _ORDER}  # the next unread sample per kind

    def _arrival(self, kind: str, i: int) -> float:
        if kind == "imu":
            return float(self.record.imu_arrival[i])
        return float(getattr(self.record, kind)[i].t_arrival)

    def feed(self, t: float) -> None:
        """Feed every sample that has arrived by ``t`` [s] and was not fed yet, in arrival order."""
        pending = []
        for rank, kind in enumerate(_ORDER):
            samples = getattr(self.record, kind)
            i = self._next[kind]
            while i < len(samples) and self._arrival(kind, i) <= t + 1e-9:
                pending.append((self._arrival(kind, i), rank, i, kind))
                i += 1
            self._next[kind] = i
        pending.sort()
        for _, _, i, kind in pending:
            getattr(self.filter, "on_" + kind)(getattr(self.record, kind)[i])
        if self.trim:  # the fed samples dropped: the indices start again at 0
            for kind, i in self._next.items():
                if i:
                    del getattr(self.record, kind)[:i]
                    if kind == "imu":
                        del self.record.imu_arrival[:i]
                    self._next[kind] = 0

    def state(self, t: Optional[float] = None) -> NavEstimate:
        """The estimate at ``t`` [s] (extrapolated from the last IMU sample fed; the filter unchanged)."""
        last = self.filter.state()
        return self.filter.state(None if t is None or t <= last.t else t)
