"""ESKF parameters from the navigation sensors' own settings (:mod:`uvms_mj.sim.navsensors`), so the filter
models the noise the simulated sensors add. Conversions (ours, documented in docs/estimation.md):

* IMU: the densities and bias random walks as they are (same units, same continuous-time model).
* DVL: per-axis sigma of the least-squares velocity of 4 Janus beams at ``beam_angle`` with per-beam noise
  ``s``: ``s / (sqrt(2) sin(beam_angle))`` across the boresight, ``s / (2 cos(beam_angle))`` along it (DVL frame),
  with the output resolution's ``resolution / sqrt(12)`` added in quadrature.
* depth: ``hypot(noise, resolution / sqrt(12)) / (rho g)`` [m] (noise and resolution in Pa).
* fix: ``hypot(noise, range_noise * nominal_range)`` [m] per axis (the sensor's noise grows with the slant range;
  ``nominal_range`` is the caller's, default 1 m); ``yaw_noise`` for the yaw (0 -> 0.01 rad, the filter needs a
  positive variance).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Optional

import numpy as np

from uvms_mj.estimation.eskf import EskfParams
from uvms_mj.sim.navsensors import NavigationConfig, NavigationRecord

__all__ = ["params_from_navigation"]


def params_from_navigation(config: NavigationConfig, record: NavigationRecord, gravity, water_density: float = 1000.0,
                           nominal_range: float = 1.0, fix_gate: Optional[float] = None, **overrides) -> EskfParams:
    """:class:`EskfParams` for the sensors ``config`` mounted as in ``record.mounts``; ``gravity`` (3,) world
    [m/s^2] (the model's ``opt.gravity``); ``overrides``: any EskfParams field."""
    g = float(np.linalg.norm(gravity))
    kw: dict = {"gravity": np.asarray(gravity, dtype=float), "fix_gate": fix_gate}
    for kind in ("imu", "dvl", "depth", "fix"):
        if kind in record.mounts:
            kw[f"{kind}_mount"] = record.mounts[kind]
    if config.imu is not None:
        c = config.imu
        kw.update(accel_noise_density=c.accel_noise, gyro_noise_density=c.gyro_noise,
                  accel_bias_rw=max(c.accel_bias_walk, 1e-9), gyro_bias_rw=max(c.gyro_bias_walk, 1e-12))
    if config.dvl is not None:
        c = config.dvl
        q = c.resolution / math.sqrt(12.0)
        across = math.hypot(c.beam_noise / (math.sqrt(2.0) * math.sin(c.beam_angle)), q)
        along = math.hypot(c.beam_noise / (2.0 * math.cos(c.beam_angle)), q)
        kw["dvl_sigma"] = (max(across, 1e-6), max(across, 1e-6), max(along, 1e-6))
    if config.depth is not None:
        c = config.depth
        rho = c.density if c.density is not None else water_density
        kw["depth_sigma"] = max(math.hypot(c.noise, c.resolution / math.sqrt(12.0)) / (rho * g), 1e-6)
    if config.fix is not None:
        c = config.fix
        kw["fix_sigma"] = max(math.hypot(c.noise, c.range_noise * nominal_range), 1e-6)
        kw["yaw_sigma"] = c.yaw_noise if c.yaw_noise > 0 else 0.01
    names = {f.name for f in dataclasses.fields(EskfParams)}
    bad = sorted(set(overrides) - names)
    if bad:
        raise ValueError(f"params_from_navigation: unknown EskfParams field(s) {bad}; allowed: {sorted(names)}")
    kw.update(overrides)
    return EskfParams(**kw)
