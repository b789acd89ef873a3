"""The scenario's ``navigation`` section: the navigation sensors of :mod:`uvms_mj.sim.navsensors`
(an IMU, a DVL, a depth sensor, position fixes), each on a named site of the model, for robots
with a free vehicle (the paper's planar robot refuses it in one line). A field left out (null)
takes the sensor's datasheet-based default (:class:`uvms_mj.sim.navsensors.ImuConfig` ...,
docs/platform-3d.md "Navigation sensors"); ``{}`` is the default sensor. Units SI (angles rad),
except the DVL's beam geometry (deg). The DVL's beams need a scene to hit: the model's own static
geoms, or a flat seabed ``plant.seabed_depth`` [m] below the surface (world z = 0).

.. code-block:: yaml

    plant: {seabed_depth: 20}          # a seabed plane at world z = -20 m
    navigation:
      imu: {}                          # ICM-20602-class MEMS IMU at the site *imu, every plant step
      dvl: {rate: 5, max_altitude: 50} # A50-class DVL at *dvl: 4 beams, Janus, 22.5 deg
      depth: {}                        # Bar30-class pressure sensor at *depth
      fix: {rate: 1, latency: 0.3}     # USBL at *usbl: 1 % of the slant range, outliers
"""

from __future__ import annotations

import re
from typing import Annotated

import mujoco
from pydantic import Field

from uvms_mj.scenario.base import _NO_VALUE, DURATION_MAX, _Section

__all__ = ["NavigationSection", "nav_config", "navigation_issues", "resolved_navigation"]

Rate = Annotated[float, Field(gt=0, le=10_000.0, description="sample rate [Hz]: its period a whole number of "
                                                               "physics.timestep; null: the sensor's default "
                                                               "(the IMU's: every plant step)")]
Latency = Annotated[float, Field(ge=0, le=100.0, description="arrival time - measurement time [s]")]
Outage = Annotated[list[Annotated[float, Field(ge=0, le=DURATION_MAX)]], Field(min_length=2, max_length=2)]
Vec = Annotated[list[Annotated[float, Field(ge=-1e3, le=1e3)]], Field(min_length=3, max_length=3)]


class _Sensor(_Section):
    site: str | None = Field(None, min_length=1, description="the mount site; null: the first site named *<sensor>")
    rate: Rate | None = None
    latency: Latency | None = None
    outages: list[Outage] | None = Field(None, description="[start, end) windows of measurement time [s] without "
                                         "samples (the DVL: dropouts)")


class ImuSection(_Sensor):
    """The IMU (:class:`uvms_mj.sim.navsensors.ImuConfig`)."""

    gyro_noise: float | None = Field(None, ge=0, le=1.0, description="ARW [rad/s/sqrt(Hz)]")
    gyro_bias_walk: float | None = Field(None, ge=0, le=1.0, description="[rad/s^2/sqrt(Hz)]")
    gyro_bias: float | Vec | None = Field(None, description="initial bias [rad/s], site frame")
    gyro_bias_std: float | None = Field(None, ge=0, le=1.0, description="turn-on bias std [rad/s]")
    gyro_range: float | None = Field(None, gt=0, le=1e3, description="full scale [rad/s]")
    accel_noise: float | None = Field(None, ge=0, le=10.0, description="VRW [m/s^2/sqrt(Hz)]")
    accel_bias_walk: float | None = Field(None, ge=0, le=10.0, description="[m/s^3/sqrt(Hz)]")
    accel_bias: float | Vec | None = Field(None, description="initial bias [m/s^2], site frame")
    accel_bias_std: float | None = Field(None, ge=0, le=10.0, description="turn-on bias std [m/s^2]")
    accel_range: float | None = Field(None, gt=0, le=1e4, description="full scale [m/s^2]")


class DvlSection(_Sensor):
    """The DVL (:class:`uvms_mj.sim.navsensors.DvlConfig`)."""

    beam_angle_deg: float | None = Field(None, gt=0, lt=90, description="beams from the boresight (+z) [deg]")
    beam_azimuths_deg: list[Annotated[float, Field(ge=-360, le=360)]] | None = Field(
        None, min_length=3, max_length=16, description="beams about +z from +x [deg]")
    beam_noise: float | None = Field(None, ge=0, le=1.0, description="std of each beam's radial velocity [m/s]")
    beam_dropout: float | None = Field(None, ge=0, le=1, description="probability of losing a beam at a ping")
    bias: float | Vec | None = Field(None, description="velocity bias [m/s], site frame")
    scale: float | None = Field(None, gt=-1, lt=1, description="scale factor error")
    resolution: float | None = Field(None, ge=0, le=1.0, description="[m/s]")
    min_altitude: float | None = Field(None, ge=0, le=1e3, description="[m]")
    max_altitude: float | None = Field(None, gt=0, le=1e4, description="[m]")


class DepthSection(_Sensor):
    """The depth sensor (:class:`uvms_mj.sim.navsensors.DepthConfig`)."""

    noise: float | None = Field(None, ge=0, le=1e5, description="[Pa]")
    bias: float | None = Field(None, ge=-1e6, le=1e6, description="[Pa]")
    resolution: float | None = Field(None, ge=0, le=1e5, description="[Pa]")
    density: float | None = Field(None, gt=0, le=2e4, description="nominal density of the conversion [kg/m^3]; "
                                  "null: the plant's")
    max_depth: float | None = Field(None, gt=0, le=11000.0, description="[m]")


class FixSection(_Sensor):
    """Position fixes (:class:`uvms_mj.sim.navsensors.FixConfig`): a USBL, or a camera with yaw."""

    noise: float | None = Field(None, ge=0, le=100.0, description="std per axis [m]")
    range_noise: float | None = Field(None, ge=0, le=1.0, description="std per axis / slant range")
    transceiver: Vec | None = Field(None, description="world [m]")
    max_range: float | None = Field(None, gt=0, le=1e5, description="[m]")
    outlier_probability: float | None = Field(None, ge=0, le=1)
    outlier_std: float | None = Field(None, ge=0, le=1e3, description="[m] per axis")
    yaw: bool | None = Field(None, description="the fix gives the site's yaw (a camera)")
    yaw_noise: float | None = Field(None, ge=0, le=3.15, description="[rad]")


class NavigationSection(_Section):
    """The navigation sensors (module docstring); each null: absent."""

    imu: ImuSection | None = None
    dvl: DvlSection | None = None
    depth: DepthSection | None = None
    fix: FixSection | None = None


def _config(kind: str, sec):
    import math

    from uvms_mj.sim import navsensors as ns

    kw = {k: v for k, v in sec.model_dump().items() if v is not None}
    for k in ("outages", "beam_azimuths_deg"):
        if k in kw:
            kw[k] = tuple(tuple(x) if isinstance(x, list) else x for x in kw[k])
    if "beam_angle_deg" in kw:
        kw["beam_angle"] = math.radians(kw.pop("beam_angle_deg"))
    if "beam_azimuths_deg" in kw:
        kw["beam_azimuths"] = tuple(math.radians(a) for a in kw.pop("beam_azimuths_deg"))
    cls = {"imu": ns.ImuConfig, "dvl": ns.DvlConfig, "depth": ns.DepthConfig, "fix": ns.FixConfig}[kind]
    return cls(**kw)


def nav_config(sc):
    """The scenario's :class:`uvms_mj.sim.navsensors.NavigationConfig`, or None (no navigation
    section and no seabed)."""
    nav, seabed = sc.navigation, sc.plant.seabed_depth
    if nav is None and seabed is None:
        return None
    from uvms_mj.sim.navsensors import NAV_SENSORS, NavigationConfig

    parts = {k: _config(k, getattr(nav, k)) for k in NAV_SENSORS if nav is not None and getattr(nav, k) is not None}
    return NavigationConfig(**parts, seabed_depth=seabed)


def resolved_navigation(sc) -> dict:
    """The navigation section with every null of a given sensor filled in: the sensor's default
    (the DVL's beam angles in deg) and its default site on the robot's model."""
    import dataclasses
    import math

    from uvms_mj.scenario.document import robot_model
    from uvms_mj.sim.navsensors import NAV_SENSORS, _site_of

    _, m, _ = robot_model(sc.robot, sc.base_dir)
    sites = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_SITE, i) or "" for i in range(m.nsite)]
    out: dict = {}
    for kind in NAV_SENSORS:
        sec = getattr(sc.navigation, kind)
        if sec is None:
            out[kind] = None
            continue
        cfg = _config(kind, sec)
        full = {f.name: getattr(cfg, f.name) for f in dataclasses.fields(cfg)}
        full["site"] = _site_of(kind, cfg, sites)
        if kind == "dvl":
            full["beam_angle_deg"] = math.degrees(full.pop("beam_angle"))
            full["beam_azimuths_deg"] = [math.degrees(a) for a in full.pop("beam_azimuths")]
        given = sec.model_dump(mode="json")
        out[kind] = {k: (v if v is not None else _plain(full[k])) for k, v in given.items()}
    return out


def _plain(v):
    if isinstance(v, (tuple, list)):
        return [_plain(x) for x in v]
    return v


def navigation_issues(sc, m: mujoco.MjModel, dt: float) -> list:
    """Problems of the navigation section and ``plant.seabed_depth`` on the robot's model ``m``
    at the plant step ``dt`` [s]: a planar robot, missing sites, rates that are not whole numbers
    of steps, a DVL without a scene to hit."""
    nav = sc.navigation
    issues: list = []
    free = any(int(t) == mujoco.mjtJoint.mjJNT_FREE for t in m.jnt_type)
    if not free:
        if sc.controller.feedback == "estimate":
            issues.append((("controller", "feedback"), "estimate applies to robots with a free vehicle (MJCF robots "
                           "with a navigation section); the paper's planar robot has none", "estimate"))
        if nav is not None:
            issues.append((("navigation",), "applies to robots with a free vehicle (MJCF robots such as "
                           "bluerov2_alpha); the paper's planar robot has no navigation sensors", _NO_VALUE))
        if sc.plant.seabed_depth is not None:
            issues.append((("plant", "seabed_depth"), "applies to robots with a free vehicle (for the navigation "
                           "sensors' DVL)", sc.plant.seabed_depth))
        return issues
    fb = sc.controller.feedback
    if fb == "estimate" and (nav is None or nav.imu is None or (nav.fix is None and nav.depth is None)):
        issues.append((("controller", "feedback"), "estimate needs a navigation section with an imu and a position "
                       "source (fix or depth) for the ESKF; give them or use feedback: truth", fb))
    if nav is None:
        return issues
    from uvms_mj.sim.navsensors import NAV_SENSORS, _site_of, steps_of  # (here: only a navigation section needs it)

    sites = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_SITE, i) or "" for i in range(m.nsite)]
    for kind in NAV_SENSORS:
        sec = getattr(nav, kind)
        if sec is None:
            continue
        try:
            cfg = _config(kind, sec)
        except ValueError as exc:
            rest = str(exc).removeprefix(f"navigation.{kind}")
            key = re.match(r"\.(\w+)", rest)
            if key:
                rest = rest[key.end():]
            issues.append((("navigation", kind) + ((key.group(1),) if key else ()), rest.lstrip(":= "), _NO_VALUE))
            continue
        try:
            _site_of(kind, cfg, sites)
        except ValueError as exc:
            issues.append((("navigation", kind, "site"), str(exc).split(": ", 1)[-1], sec.site or _NO_VALUE))
        try:
            steps_of(kind, cfg.rate, dt)
        except ValueError as exc:
            issues.append((("navigation", kind, "rate"), str(exc).split(": ", 1)[-1], cfg.rate))
    if nav.dvl is not None and sc.plant.seabed_depth is None:
        static = [g for g in range(m.ngeom) if int(m.body_rootid[m.geom_bodyid[g]]) == 0]
        if not static:
            issues.append((("navigation", "dvl"), f"robot {sc.robot!r} has no scene for the DVL's beams to hit: set "
                           "plant.seabed_depth [m] (a flat seabed at world z = -seabed_depth)", _NO_VALUE))
    return issues
