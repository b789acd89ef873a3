"""Navigation sensors on the plant: an IMU, a DVL, a depth (pressure) sensor and position fixes
(USBL or camera), each mounted on a named site of the model, with its own rate, latency, noise,
bias, failure modes and random stream (issue 21). The controllers do not use them (yet): a run
produces and logs them (:class:`NavigationRecord`, ``RunResult.navigation``, the MCAP channels
of :mod:`uvms_mj.io.nav_channels`).

What is measured (world z up, gravity (0, 0, -g); quaternions w x y z; each sensor's frame is
its site's frame):

* IMU -- MuJoCo's own ``accelerometer`` and ``gyro`` sensors at the IMU site (added to the
  model by :func:`add_to_spec`, so the lever arm is MuJoCo's: the accelerometer reads the
  specific force of the site, its acceleration minus gravity, +g up at rest; the gyro the
  site frame's angular velocity). Per axis: ``gyro = w + b_g + n_g``, ``acc = f + b_a + n_a``,
  white noise of std ``N sqrt(rate)`` (N the noise density, ARW [rad/s/sqrt(Hz)] or VRW
  [m/s^2/sqrt(Hz)]) and biases that random-walk, ``b <- b + K sqrt(1/rate) w`` after each
  sample (K [rad/s^2/sqrt(Hz)], [m/s^3/sqrt(Hz)]), starting at ``bias`` plus a turn-on draw of
  std ``bias_std``; outputs clipped to the ranges.
* DVL -- four beams (Janus: unit vectors at ``beam_angle`` from the site's +z axis, the DVL's
  boresight, at ``beam_azimuths`` about it). Each beam is a ray (``mujoco.mj_ray``, the
  vehicle's own body excluded) against the scene: a beam is valid when it hits a geom of the
  scene (not of the robot: a robot geom in the way blocks it) at an altitude along the boresight,
  ``range cos(beam_angle)``, within [min_altitude, max_altitude], and is not dropped at random
  (``beam_dropout``). Each valid beam measures the radial velocity ``r_i = b_i . v`` of the site
  over the ground (MuJoCo's ``velocimeter``: the site's velocity, site frame) plus noise; the
  velocity is their least-squares solution (4 beams; 3 solve it exactly), times ``1 + scale``,
  plus ``bias``, quantized to ``resolution``. Fewer than 3 valid beams: a dropout
  (``velocity`` None).
* depth -- the gauge pressure at the depth site, ``p = rho g (-z)`` (rho the plant's water
  density; the mean surface at world z = 0, no wave pressure), plus ``bias`` and noise [Pa],
  quantized to ``resolution`` [Pa], clipped to [0, rho_nominal g max_depth], converted back
  with the nominal ``density`` (null: the plant's).
* fix -- the world position of the fix site (a USBL transponder, or a camera's reference
  point) with per-axis noise of std ``hypot(noise, range_noise * slant range)`` (slant range
  from the ``transceiver``), none beyond ``max_range``, an outlier with probability
  ``outlier_probability`` (an added error of std ``outlier_std`` per axis); the site's yaw
  (world, from +x towards +y) with ``yaw_noise`` when ``yaw`` (a camera).

Timing: a sensor samples at steps ``s`` of the plant (time ``s dt``) with ``s`` a multiple of
its period in steps (``1 / (rate dt)``, a whole number). MuJoCo computes its sensors at the start
of each step (``mj_step`` runs ``mj_forward`` first; no integrator recomputes them after), so
the values of step ``s`` are read after the step ``s -> s + 1`` (:meth:`NavigationSuite.advance`
splits the control period's steps there): the state and the acceleration under the command in
force from ``s dt`` on. Each sample has its measurement time ``t = s dt`` and its arrival time
``t + latency``. ``outages``: [start, end) windows of measurement time without samples (the DVL:
dropout samples). A sample due at the run's last step is not taken (the run does not step past
it).

Random streams: each sensor draws from its own ``numpy.random.default_rng([seed, NAV_STREAM,
i])``, ``i`` its index in :data:`NAV_SENSORS`, in a fixed order per sample: deterministic per
scenario seed, and one sensor's settings do not change another's noise.

Defaults (datasheet figures, docs/platform-3d.md "Navigation sensors"; [A] our choices): IMU of
the TDK ICM-20602 class, DVL of the Water Linked A50 class, depth sensor of the Blue Robotics
Bar30 class (MS5837-30BA), USBL of the Water Linked Underwater GPS class.
"""

from __future__ import annotations

import difflib
import math
from dataclasses import dataclass, field
from typing import Callable, Sequence

import mujoco
import numpy as np

from uvms_mj.estimation.measurements import DepthSample, DvlSample, FixSample, ImuSample, Mount
from uvms_mj.rotations import quat_mul, quat_to_mat

__all__ = ["DepthConfig", "DvlConfig", "FixConfig", "ImuConfig", "NAV_SENSORS", "NavigationConfig",
           "NavigationRecord", "NavigationSuite", "SEABED_GEOM", "add_to_spec", "default_site"]

#: The sensors, in the order of their random streams.
NAV_SENSORS = ("imu", "dvl", "depth", "fix")
#: Second word of each sensor's random stream key ("NAV").
NAV_STREAM = 0x4E4156
#: The seabed plane :func:`add_to_spec` adds (``plant.seabed_depth``).
SEABED_GEOM = "uvms_seabed"
#: Name prefix of the MuJoCo sensors :func:`add_to_spec` adds.
SENSOR_PREFIX = "uvms_nav_"
#: Standard gravity [m/s^2] for the depth conversion when the model has gravity off.
G0 = 9.80665
DEG = math.pi / 180.0


def _vec3(name: str, v) -> tuple[float, float, float]:
    a = np.resize(np.asarray(v, dtype=float).ravel(), 3) if np.size(v) in (1, 3) else None
    if a is None or not np.all(np.isfinite(a)):
        raise ValueError(f"{name} = {v!r}: expected one number or 3 finite numbers")
    return tuple(float(x) for x in a)


def _check(cfg, nonneg: Sequence[str] = (), positive: Sequence[str] = ()) -> None:
    kind = type(cfg).__name__.removesuffix("Config").lower()
    for n in nonneg:
        v = getattr(cfg, n)
        if not (math.isfinite(v) and v >= 0):
            raise ValueError(f"navigation.{kind}.{n} = {v!r} must be finite and >= 0")
    for n in positive:
        v = getattr(cfg, n)
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f"navigation.{kind}.{n} = {v!r} must be finite and > 0")
    outs = tuple((float(a), float(b)) for a, b in cfg.outages)
    for a, b in outs:
        if not (math.isfinite(a) and math.isfinite(b) and 0 <= a < b):
            raise ValueError(f"navigation.{kind}.outages: [{a!r}, {b!r}] must satisfy 0 <= start < end [s]")
    object.__setattr__(cfg, "outages", outs)


@dataclass(frozen=True)
class ImuConfig:
    """The IMU (module docstring). Defaults: a TDK ICM-20602-class MEMS IMU (datasheet noise
    densities 0.004 deg/s/sqrt(Hz), 100 ug/sqrt(Hz); full scales 2000 deg/s, 16 g); bias random
    walks of the EuRoC dataset's ADIS16448 calibration [A: that datasheet gives none]; every plant
    step (``rate`` None: 250 Hz at 4 ms, 150 Hz at 1/150 s; such an IMU samples at up to 8 kHz) [A]."""

    site: str | None = None
    rate: float | None = None  # [Hz]; None: every plant step
    latency: float = 0.0  # [s]
    gyro_noise: float = 0.004 * DEG  # ARW [rad/s/sqrt(Hz)]
    gyro_bias_walk: float = 1.9393e-5  # [rad/s^2/sqrt(Hz)]
    gyro_bias: tuple = (0.0, 0.0, 0.0)  # initial [rad/s], site frame
    gyro_bias_std: float = 0.0  # turn-on bias std [rad/s]
    gyro_range: float = 2000.0 * DEG  # [rad/s]
    accel_noise: float = 100e-6 * 9.80665  # VRW [m/s^2/sqrt(Hz)]
    accel_bias_walk: float = 3.0e-3  # [m/s^3/sqrt(Hz)]
    accel_bias: tuple = (0.0, 0.0, 0.0)  # initial [m/s^2], site frame
    accel_bias_std: float = 0.0  # turn-on bias std [m/s^2]
    accel_range: float = 16.0 * 9.80665  # [m/s^2]
    outages: tuple = ()

    def __post_init__(self) -> None:
        _check(self, ("latency", "gyro_noise", "gyro_bias_walk", "gyro_bias_std", "accel_noise", "accel_bias_walk",
                      "accel_bias_std"), ("gyro_range", "accel_range") + (("rate",) if self.rate is not None else ()))
        object.__setattr__(self, "gyro_bias", _vec3("navigation.imu.gyro_bias", self.gyro_bias))
        object.__setattr__(self, "accel_bias", _vec3("navigation.imu.accel_bias", self.accel_bias))


@dataclass(frozen=True)
class DvlConfig:
    """The DVL (module docstring). Defaults: a Water Linked DVL A50-class DVL (Water Linked's
    specifications: 4 beams (Janus, 22.5 deg from the boresight), altitude 0.05-50 m, ping rate
    4-26 Hz with the altitude, 5-6 Hz at 1.5-14 m); 5 Hz, 0.05 s latency, 5 mm/s noise per beam
    (about 1 cm/s horizontally), 0.1 mm/s output resolution [A]."""

    site: str | None = None
    rate: float = 5.0
    latency: float = 0.05
    beam_angle: float = 22.5 * DEG  # from the boresight (+z of the site) [rad]
    beam_azimuths: tuple = (45 * DEG, 135 * DEG, 225 * DEG, 315 * DEG)  # about +z from +x [rad]
    beam_noise: float = 0.005  # std of each beam's radial velocity [m/s]
    beam_dropout: float = 0.0  # probability that a beam is lost at a ping
    bias: tuple = (0.0, 0.0, 0.0)  # [m/s], site frame
    scale: float = 0.0  # scale factor error (velocity x (1 + scale))
    resolution: float = 1e-4  # [m/s]
    min_altitude: float = 0.05  # [m]
    max_altitude: float = 50.0  # [m]
    outages: tuple = ()

    def __post_init__(self) -> None:
        _check(self, ("latency", "beam_noise", "resolution", "min_altitude"), ("rate", "max_altitude"))
        if not 0 < self.beam_angle < 0.5 * math.pi:
            raise ValueError(f"navigation.dvl.beam_angle = {self.beam_angle!r} rad must be in (0, pi/2)")
        az = tuple(float(a) for a in self.beam_azimuths)
        if len(az) < 3 or not all(map(math.isfinite, az)):
            raise ValueError(f"navigation.dvl.beam_azimuths = {self.beam_azimuths!r}: at least 3 finite angles")
        object.__setattr__(self, "beam_azimuths", az)
        if not 0 <= self.beam_dropout <= 1:
            raise ValueError(f"navigation.dvl.beam_dropout = {self.beam_dropout!r} must be in [0, 1]")
        if not (math.isfinite(self.scale) and abs(self.scale) < 1):
            raise ValueError(f"navigation.dvl.scale = {self.scale!r} must be in (-1, 1)")
        if not self.min_altitude < self.max_altitude:
            raise ValueError(f"navigation.dvl: min_altitude {self.min_altitude!r} must be below max_altitude "
                             f"{self.max_altitude!r} m")
        object.__setattr__(self, "bias", _vec3("navigation.dvl.bias", self.bias))

    def beams(self) -> np.ndarray:
        """The beams' unit vectors (n, 3), site frame."""
        s, c = math.sin(self.beam_angle), math.cos(self.beam_angle)
        return np.array([[s * math.cos(a), s * math.sin(a), c] for a in self.beam_azimuths])


@dataclass(frozen=True)
class DepthConfig:
    """The depth sensor (module docstring). Defaults: a Blue Robotics Bar30-class sensor
    (MS5837-30BA datasheet: 0.2 mbar = 20 Pa resolution, i.e. 2 mm of water, 0-30 bar); 25 Hz,
    0.02 s latency, 20 Pa noise [A]."""

    site: str | None = None
    rate: float = 25.0
    latency: float = 0.02
    noise: float = 20.0  # [Pa]
    bias: float = 0.0  # [Pa]
    resolution: float = 20.0  # [Pa]
    density: float | None = None  # nominal water density of the conversion [kg/m^3]; None: the plant's
    max_depth: float = 300.0  # [m] of nominal water (30 bar)
    outages: tuple = ()

    def __post_init__(self) -> None:
        _check(self, ("latency", "noise", "resolution"), ("rate", "max_depth"))
        if not math.isfinite(self.bias):
            raise ValueError(f"navigation.depth.bias = {self.bias!r} Pa must be finite")
        if self.density is not None and not (math.isfinite(self.density) and self.density > 0):
            raise ValueError(f"navigation.depth.density = {self.density!r} kg/m^3 must be finite and > 0")


@dataclass(frozen=True)
class FixConfig:
    """Position fixes (module docstring). Defaults: a USBL of the Water Linked Underwater GPS
    class: 1 Hz, 0.3 s latency, 1 % of the slant range (issue 21's figures for a USBL: 1-2 Hz,
    0.2-0.5 s, ~1 %, outliers); a 2 cm floor, 2 % outliers of 1 m std, 300 m range [A]."""

    site: str | None = None
    rate: float = 1.0
    latency: float = 0.3
    noise: float = 0.02  # [m] per axis
    range_noise: float = 0.01  # fraction of the slant range, per axis
    transceiver: tuple = (0.0, 0.0, 0.0)  # world [m]
    max_range: float = 300.0  # [m]
    outlier_probability: float = 0.02
    outlier_std: float = 1.0  # [m] per axis
    yaw: bool = False
    yaw_noise: float = 0.0  # [rad]
    outages: tuple = ()

    def __post_init__(self) -> None:
        _check(self, ("latency", "noise", "range_noise", "outlier_std", "yaw_noise"), ("rate", "max_range"))
        if not 0 <= self.outlier_probability <= 1:
            raise ValueError(f"navigation.fix.outlier_probability = {self.outlier_probability!r} must be in [0, 1]")
        object.__setattr__(self, "transceiver", _vec3("navigation.fix.transceiver", self.transceiver))


@dataclass(frozen=True)
class NavigationConfig:
    """The navigation sensors of a run (each None: absent); ``seabed_depth``: a flat seabed added
    at world z = -seabed_depth [m] (:func:`add_to_spec`), None: the scene's own."""

    imu: ImuConfig | None = None
    dvl: DvlConfig | None = None
    depth: DepthConfig | None = None
    fix: FixConfig | None = None
    seabed_depth: float | None = None

    def sensors(self) -> dict:
        return {n: getattr(self, n) for n in NAV_SENSORS if getattr(self, n) is not None}


#: Default site of each sensor: the first site whose name ends with one of these.
SITE_SUFFIXES = {"imu": ("imu",), "dvl": ("dvl",), "depth": ("depth", "pressure"), "fix": ("usbl", "fix")}


def default_site(kind: str, site_names: Sequence[str]) -> str:
    """The site of sensor ``kind`` when none is given: the first site named ``*imu``, ``*dvl``,
    ``*depth`` (or ``*pressure``), ``*usbl`` (or ``*fix``).

    Raises:
        ValueError: no such site (the message says what to give)."""
    for suffix in SITE_SUFFIXES[kind]:
        for n in site_names:
            if n and n.endswith(suffix):
                return n
    raise ValueError(f"navigation.{kind}.site: the model has no site named *{SITE_SUFFIXES[kind][0]}; give the "
                     f"site the {kind} is mounted on (sites: {', '.join(n for n in site_names if n) or 'none'})")


def _site_of(kind: str, cfg, site_names: Sequence[str]) -> str:
    if cfg.site is None:
        return default_site(kind, site_names)
    if cfg.site not in site_names:
        close = difflib.get_close_matches(cfg.site, [n for n in site_names if n], n=1, cutoff=0.6)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise ValueError(f"navigation.{kind}.site = {cfg.site!r}: no site of that name{hint}")
    return cfg.site


#: MuJoCo sensors per navigation sensor: (suffix, type).
_MJ_SENSORS = {
    "imu": (("acc", mujoco.mjtSensor.mjSENS_ACCELEROMETER), ("gyro", mujoco.mjtSensor.mjSENS_GYRO)),
    "dvl": (("pos", mujoco.mjtSensor.mjSENS_FRAMEPOS), ("quat", mujoco.mjtSensor.mjSENS_FRAMEQUAT),
            ("vel", mujoco.mjtSensor.mjSENS_VELOCIMETER)),
    "depth": (("pos", mujoco.mjtSensor.mjSENS_FRAMEPOS),),
    "fix": (("pos", mujoco.mjtSensor.mjSENS_FRAMEPOS), ("quat", mujoco.mjtSensor.mjSENS_FRAMEQUAT)),
}


def add_to_spec(config: NavigationConfig) -> Callable[[mujoco.MjSpec], None]:
    """A spec edit (``Plant(spec_edits=...)``) that adds the MuJoCo sensors of ``config`` at their
    sites (``uvms_nav_<sensor>_<what>``) and, with ``seabed_depth``, a plane geom
    :data:`SEABED_GEOM` at world z = -seabed_depth (no contacts, no mass, group 3: for the DVL's
    rays).

    Raises (when applied):
        ValueError: a missing site (with a suggestion), a robot without sites for a default."""

    def edit(spec: mujoco.MjSpec) -> None:
        names = [s.name for s in spec.sites]
        for kind, cfg in config.sensors().items():
            site = _site_of(kind, cfg, names)
            for suffix, typ in _MJ_SENSORS[kind]:
                spec.add_sensor(name=f"{SENSOR_PREFIX}{kind}_{suffix}", type=typ, objtype=mujoco.mjtObj.mjOBJ_SITE,
                                objname=site)
        if config.seabed_depth is not None:
            spec.worldbody.add_geom(name=SEABED_GEOM, type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0, 0, 1],
                                    pos=[0, 0, -float(config.seabed_depth)], contype=0, conaffinity=0, group=3,
                                    rgba=[0.45, 0.41, 0.32, 1])

    return edit


@dataclass
class NavigationRecord:
    """The navigation samples of a run, in measurement order per sensor (``RunResult.navigation``).

    Attributes:
        imu, dvl, depth, fix: the samples (:mod:`uvms_mj.estimation.measurements`).
        imu_arrival: each IMU sample's arrival time [s] (ImuSample has none).
        imu_gyro_bias, imu_accel_bias: the true biases of each IMU sample (n, 3), site frame.
        dvl_ranges: each ping's beam ranges [m] (NaN: no hit).
        fix_outlier: whether each fix is an outlier (truth).
        mounts: each sensor's :class:`Mount` (site pose in the vehicle body frame); sites: names.
    """

    imu: list = field(default_factory=list)
    imu_arrival: list = field(default_factory=list)
    imu_gyro_bias: list = field(default_factory=list)
    imu_accel_bias: list = field(default_factory=list)
    dvl: list = field(default_factory=list)
    dvl_ranges: list = field(default_factory=list)
    depth: list = field(default_factory=list)
    fix: list = field(default_factory=list)
    fix_outlier: list = field(default_factory=list)
    mounts: dict = field(default_factory=dict)
    sites: dict = field(default_factory=dict)

    def describe(self) -> dict:
        """Each sensor's site and mount (position [m], quat w x y z: site -> vehicle body), JSON-able."""
        return {k: {"site": self.sites[k], "position": [float(x) for x in m.position],
                    "quat": [float(x) for x in m.quat]} for k, m in self.mounts.items()}

    def arrivals(self) -> list:
        """Every sample as (arrival time, kind, sample), in arrival order (ties: IMU, DVL, depth, fix)."""
        out = [(float(ta), 0, "imu", s) for ta, s in zip(self.imu_arrival, self.imu)]
        for i, kind in enumerate(("dvl", "depth", "fix"), start=1):
            out += [(float(s.t_arrival), i, kind, s) for s in getattr(self, kind)]
        out.sort(key=lambda x: (x[0], x[1]))
        return [(t, kind, s) for t, _, kind, s in out]


class _Dropped(list):
    """A record field that keeps nothing (NavigationSuite ``keep`` other than "all"): appends are dropped."""

    def append(self, _item) -> None:
        pass


#: The record's fields the online estimator reads (NavigationSuite keep="samples").
_SAMPLE_FIELDS = ("imu", "imu_arrival", "dvl", "depth", "fix")
_TRUTH_FIELDS = ("imu_gyro_bias", "imu_accel_bias", "dvl_ranges", "fix_outlier")


class NavigationSuite:
    """The navigation sensors of one run on a model with :func:`add_to_spec`'s sensors (module
    docstring).

    Args:
        model, data: the plant's (``data`` stepped by the plant).
        config: the sensors.
        seed: the run's seed.
        base_body: the vehicle body's id (free joint); its body is excluded from the DVL's rays.
        water_density: the water's density [kg/m^3] (the plant's).
        sink: called with (kind, sample, extra) for every sample as it is taken (extra: a dict of
            what the sample's dataclass has no field for: the IMU's arrival time and true biases,
            the DVL's ranges and altitude, the depth's pressure, a fix's outlier flag).
        keep: what :attr:`record` keeps: "all" (every sample and its truth), "samples" (the
            samples the online estimator reads, which it drops once fed:
            :class:`uvms_mj.estimation.online.OnlineEstimator` ``trim``) or "none" (the mounts and
            sites only; the samples go to ``sink``): a run whose memory must not grow.
    """

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, config: NavigationConfig, seed: int,
                 base_body: int, water_density: float = 1000.0, sink: Callable | None = None,
                 keep: str = "all") -> None:
        if keep not in ("all", "samples", "none"):
            raise ValueError(f"NavigationSuite: keep = {keep!r}; allowed: all, samples, none")
        self.model, self.data, self.config = model, data, config
        self.dt = float(model.opt.timestep)
        self.base_body = int(base_body)
        self.root = int(model.body_rootid[self.base_body])
        self.rho = float(water_density)
        g = float(np.linalg.norm(model.opt.gravity))
        self.g = g if g > 0 else G0
        self.sink = sink
        self.sensors = config.sensors()
        self.every = {k: steps_of(k, c.rate, self.dt) for k, c in self.sensors.items()}
        self.adr: dict[str, dict[str, int]] = {}
        for kind in self.sensors:
            self.adr[kind] = {}
            for suffix, _ in _MJ_SENSORS[kind]:
                sid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SENSOR, f"{SENSOR_PREFIX}{kind}_{suffix}")
                if sid < 0:
                    raise ValueError(f"navigation.{kind}: the model lacks its sensors (build the plant with "
                                     "spec_edits=[add_to_spec(config)])")
                self.adr[kind][suffix] = int(model.sensor_adr[sid])
        self.rngs = {k: np.random.default_rng([int(seed), NAV_STREAM, i]) for i, k in enumerate(NAV_SENSORS)}
        self.record = NavigationRecord()
        self.keep = keep
        for name in (() if keep == "all" else _TRUTH_FIELDS if keep == "samples" else _TRUTH_FIELDS + _SAMPLE_FIELDS):
            setattr(self.record, name, _Dropped())
        self._mounts()
        imu = config.imu
        if imu is not None:
            r = self.rngs["imu"]
            self.b_g = np.asarray(imu.gyro_bias) + (r.normal(0.0, imu.gyro_bias_std, 3) if imu.gyro_bias_std
                                                    else 0.0)
            self.b_a = np.asarray(imu.accel_bias) + (r.normal(0.0, imu.accel_bias_std, 3) if imu.accel_bias_std
                                                     else 0.0)
        if config.dvl is not None:
            self.beams = config.dvl.beams()
        self.step_index = 0  # the plant's steps since the start

    def _mounts(self) -> None:
        m = self.model
        d = mujoco.MjData(m)
        mujoco.mj_kinematics(m, d)
        Rb = d.xmat[self.base_body].reshape(3, 3)
        qb = d.xquat[self.base_body] * np.array([1.0, -1.0, -1.0, -1.0])
        for kind in self.sensors:
            sid = int(m.sensor_objid[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SENSOR,
                                                        f"{SENSOR_PREFIX}{kind}_{_MJ_SENSORS[kind][0][0]}")])
            sq = np.empty(4)
            mujoco.mju_mat2Quat(sq, d.site_xmat[sid])
            q = quat_mul(qb, sq)
            self.record.mounts[kind] = Mount(position=Rb.T @ (d.site_xpos[sid] - d.xpos[self.base_body]),
                                             quat=q / np.linalg.norm(q))
            self.record.sites[kind] = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_SITE, sid)

    # ---------------------------------------------------------------- stepping

    def steps_to_next_read(self) -> int:
        """Plant steps from now to the next read (one step after the next sampling step)."""
        s = self.step_index
        nxt = min(-(-s // e) * e for e in self.every.values())
        return nxt + 1 - s

    def advance(self, step: Callable[[int], tuple], n: int) -> tuple:
        """Take ``n`` plant steps through ``step(k)`` (e.g. ``Plant.step_observe``), split where
        samples are read; returns the last ``step``'s result."""
        out = None
        while n > 0:
            k = min(n, self.steps_to_next_read())
            out = step(k)
            n -= k
            self.step_index += k
            self.read(self.step_index - 1)
        return out

    def read(self, s: int) -> None:
        """The samples of step ``s`` whose MuJoCo sensors ``data.sensordata`` holds (after the
        step ``s -> s + 1``, or after ``mj_forward`` at step ``s``)."""
        t = s * self.dt
        for kind in NAV_SENSORS:
            e = self.every.get(kind)
            if e is None or s % e:
                continue
            cfg = self.sensors[kind]
            out = any(a <= t < b for a, b in cfg.outages)
            if out and kind != "dvl":
                continue
            getattr(self, f"_{kind}")(t, cfg, out)

    def _emit(self, kind: str, sample, **extra) -> None:
        getattr(self.record, kind).append(sample)
        if self.sink is not None:
            extra["site"] = self.record.sites[kind]
            self.sink(kind, sample, extra)

    # ---------------------------------------------------------------- the sensors

    def _imu(self, t: float, c: ImuConfig, _out: bool) -> None:
        sd, a, rng = self.data.sensordata, self.adr["imu"], self.rngs["imu"]
        rate = c.rate or 1.0 / self.dt
        acc = sd[a["acc"]:a["acc"] + 3] + self.b_a
        gyro = sd[a["gyro"]:a["gyro"] + 3] + self.b_g
        if c.gyro_noise:
            gyro = gyro + rng.normal(0.0, c.gyro_noise * math.sqrt(rate), 3)
        if c.accel_noise:
            acc = acc + rng.normal(0.0, c.accel_noise * math.sqrt(rate), 3)
        bg, ba = self.b_g.copy(), self.b_a.copy()
        self.record.imu_gyro_bias.append(bg)
        self.record.imu_accel_bias.append(ba)
        self.record.imu_arrival.append(t + c.latency)
        self._emit("imu", ImuSample(t=t, acc=np.clip(acc, -c.accel_range, c.accel_range),
                                    gyro=np.clip(gyro, -c.gyro_range, c.gyro_range)),
                   t_arrival=t + c.latency, gyro_bias=bg, accel_bias=ba)
        h = 1.0 / rate
        if c.gyro_bias_walk:
            self.b_g = self.b_g + rng.normal(0.0, c.gyro_bias_walk * math.sqrt(h), 3)
        if c.accel_bias_walk:
            self.b_a = self.b_a + rng.normal(0.0, c.accel_bias_walk * math.sqrt(h), 3)

    def ranges(self, p: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(range [m] of each beam from the site at ``p`` with orientation ``R`` (NaN: no hit),
        whether it hit the scene rather than the robot)."""
        m, d = self.model, self.data
        geom = np.zeros(1, dtype=np.int32)
        rng = np.full(len(self.beams), np.nan)
        scene = np.zeros(len(self.beams), dtype=bool)
        for i, b in enumerate(self.beams):
            x = mujoco.mj_ray(m, d, p, R @ b, None, 1, self.base_body, geom)
            if x >= 0:
                rng[i] = x
                scene[i] = int(m.body_rootid[m.geom_bodyid[geom[0]]]) != self.root
        return rng, scene

    def _dvl(self, t: float, c: DvlConfig, out: bool) -> None:
        sd, a, rnd = self.data.sensordata, self.adr["dvl"], self.rngs["dvl"]
        n = len(self.beams)
        if out:
            self._emit("dvl", DvlSample(t=t, t_arrival=t + c.latency, velocity=None, beams_valid=(False,) * n),
                       ranges=[None] * n, altitude=None)
            self.record.dvl_ranges.append(np.full(n, np.nan))
            return
        p = sd[a["pos"]:a["pos"] + 3].copy()
        R = quat_to_mat(sd[a["quat"]:a["quat"] + 4])
        v = sd[a["vel"]:a["vel"] + 3].copy()
        rng, scene = self.ranges(p, R)
        alt = rng * math.cos(c.beam_angle)
        with np.errstate(invalid="ignore"):
            valid = scene & (alt >= c.min_altitude) & (alt <= c.max_altitude)
        drop = rnd.random(n) < c.beam_dropout if c.beam_dropout else np.zeros(n, dtype=bool)
        valid &= ~drop
        radial = self.beams @ v
        if c.beam_noise:
            radial = radial + rnd.normal(0.0, c.beam_noise, n)
        vel = None
        if int(valid.sum()) >= 3:
            vel = np.linalg.lstsq(self.beams[valid], radial[valid], rcond=None)[0] * (1.0 + c.scale) + c.bias
            if c.resolution:
                vel = np.round(vel / c.resolution) * c.resolution
        self.record.dvl_ranges.append(rng)
        altitude = float(np.mean(alt[valid])) if valid.any() else None
        self._emit("dvl", DvlSample(t=t, t_arrival=t + c.latency, velocity=vel,
                                    beams_valid=tuple(bool(x) for x in valid)),
                   ranges=[float(x) if math.isfinite(x) else None for x in rng], altitude=altitude)

    def _depth(self, t: float, c: DepthConfig, _out: bool) -> None:
        sd, a, rng = self.data.sensordata, self.adr["depth"], self.rngs["depth"]
        rho_nom = self.rho if c.density is None else c.density
        p = self.rho * self.g * -float(sd[a["pos"] + 2]) + c.bias
        if c.noise:
            p += float(rng.normal(0.0, c.noise))
        if c.resolution:
            p = round(p / c.resolution) * c.resolution
        p = min(max(p, 0.0), rho_nom * self.g * c.max_depth)
        self._emit("depth", DepthSample(t=t, t_arrival=t + c.latency, depth=p / (rho_nom * self.g)), pressure=p)

    def _fix(self, t: float, c: FixConfig, _out: bool) -> None:
        sd, a, rng = self.data.sensordata, self.adr["fix"], self.rngs["fix"]
        p = sd[a["pos"]:a["pos"] + 3].copy()
        slant = float(np.linalg.norm(p - np.asarray(c.transceiver)))
        noise = rng.normal(0.0, 1.0, 3)  # drawn at every ping, in range or not (a fixed stream)
        outlier = bool(rng.random() < c.outlier_probability) if c.outlier_probability else False
        jump = rng.normal(0.0, c.outlier_std, 3) if outlier else 0.0
        yaw_n = rng.normal(0.0, c.yaw_noise) if c.yaw and c.yaw_noise else 0.0
        if slant > c.max_range:
            return
        pos = p + math.hypot(c.noise, c.range_noise * slant) * noise + jump
        yaw = None
        if c.yaw:
            R = quat_to_mat(sd[a["quat"]:a["quat"] + 4])
            yaw = math.remainder(math.atan2(R[1, 0], R[0, 0]) + yaw_n, 2 * math.pi)
        self.record.fix_outlier.append(outlier)
        self._emit("fix", FixSample(t=t, t_arrival=t + c.latency, position=pos, yaw=yaw), outlier=outlier)


def steps_of(kind: str, rate: float | None, dt: float) -> int:
    """A sensor's period in plant steps of ``dt`` [s] (``rate`` None: every step).

    Raises:
        ValueError: a period that is not a whole number (>= 1) of steps; the message names the
            rates allowed."""
    if rate is None:
        return 1
    x = 1.0 / (rate * dt)
    n = round(x)
    if n < 1 or abs(x - n) > 1e-9 * max(1.0, x):
        raise ValueError(f"navigation.{kind}.rate = {rate:g} Hz: its period must be a whole number of plant steps "
                         f"(physics.timestep = {dt:g} s; rates allowed: {1 / dt:g} Hz / n, e.g. "
                         f"{', '.join(f'{1 / (dt * k):g}' for k in (1, 2, 5, 10))})")
    return int(n)
