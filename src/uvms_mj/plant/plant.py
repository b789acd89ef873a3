"""The plant: the MuJoCo model of the robot, in water through the uvms plugins.

``Plant()`` loads ``models/scene.xml`` (robot + scene). The robot file carries its hydrodynamics
as attributes of the ``uvms.water`` / ``uvms.hydro`` MuJoCo plugins (``docs/hydrodynamics.md``),
so plain ``mujoco.mj_step`` / ``mujoco.mj_forward`` on ``plant.model`` and ``plant.data`` (or on
any other MjData of that model) include them with every integrator (Euler, implicit, RK4):

* the exact added-mass matrix is added to MuJoCo's mass matrix ``d.M`` and refactored
  (no lag, no filter), and
* the added-mass velocity terms, damping, strip drag and buoyancy are added to
  ``d.qfrc_passive``.

Two backends compute the same hydrodynamics (``Plant(backend=...)``, default from
``$UVMS_MJ_COMPILED``: "auto", "native" for ``on``, "python" for ``off``): "native", the C
plugins compiled into the model, and
"python", the numpy reference (:mod:`uvms_mj.physics.reference`) served through
``mjcb_passive`` (the model's plugins compiled with every term off, or stripped where they
cannot be built); "auto" takes native when the
plugin library can be built. Frames: world X horizontal, Y up; angles counter-clockwise positive.

The plant adds to MuJoCo only what a simulation run needs around it: parameter overrides,
named accessors, thruster commands with the optional dead zone, divergence detection and the
energy.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any, Mapping, Sequence

import mujoco
import numpy as np

from uvms_mj.planar.hydro import HydroTerms
from uvms_mj.planar.native import BACKENDS, default_backend
from uvms_mj.plant.params import (
    JOINT_MOTORS,
    THRUSTERS,
    TIP_SITE,
    ParameterError,
    RobotParams,
    apply_overrides,
    read_params,
)
from uvms_mj.physics import build as _build
from uvms_mj.physics import model as _pm
from uvms_mj.physics import python_backend as _pyb
from uvms_mj.physics import reference as _ref

def _finite(x: np.ndarray) -> bool:
    """Every entry of a small float array finite (cheaper than numpy's all(isfinite) here)."""
    return all(map(math.isfinite, x.ravel().tolist()))


#: What :meth:`Plant.step` saves before a batch of steps (restored for an exact replay).
_SNAPSHOT = mujoco.mjtState.mjSTATE_INTEGRATION

_PKG = Path(__file__).resolve().parents[1]  # the uvms_mj package folder

def models_dir() -> Path:
    """Folder holding uvms.xml and scene.xml (the repository's ``models/``, or the packaged copy)."""
    for cand in (_PKG.parents[1] / "models", _PKG / "models"):
        if (cand / "uvms.xml").is_file():
            return cand
    raise FileNotFoundError("cannot find the uvms_mj models folder (models/uvms.xml)")


def default_model_path() -> Path:
    """The default plant model: ``models/scene.xml`` (robot + floor, lights, cameras)."""
    return models_dir() / "scene.xml"


# MuJoCo's own warnings (mju_warning: e.g. "Nan, Inf or huge value in QACC") go by default to
# stdout and to a MUJOCO_LOG.TXT in the current folder. They are routed instead to stderr and to
# a per-process list that the closed loop puts in its run's metadata (RunResult.meta
# "mujoco_warnings"). Each process (sweep workers included) installs its own handler.
_MJ_WARNINGS: list[str] = []
_MJ_WARNINGS_MAX = 100
_mj_lock = threading.Lock()
_mj_handler_pid: int | None = None


def _on_mujoco_warning(msg: str) -> None:
    text = " ".join(str(msg).split())
    with _mj_lock:
        if len(_MJ_WARNINGS) < _MJ_WARNINGS_MAX:
            _MJ_WARNINGS.append(text)
    try:
        import sys

        sys.stderr.write(f"mujoco warning: {text}\n")
    except Exception:  # noqa: BLE001 - a closed stderr must not break the simulation
        pass


def install_mujoco_warning_handler() -> None:
    """Route MuJoCo's warnings to stderr and :func:`mujoco_warnings` instead of MUJOCO_LOG.TXT
    (once per process; done by every Plant)."""
    global _mj_handler_pid
    import os

    if _mj_handler_pid != os.getpid():
        mujoco.set_mju_user_warning(_on_mujoco_warning)
        _mj_handler_pid = os.getpid()


def mujoco_warnings(clear: bool = True) -> list[str]:
    """MuJoCo warnings seen in this process since the last call (with ``clear``)."""
    with _mj_lock:
        out = list(_MJ_WARNINGS)
        if clear:
            _MJ_WARNINGS.clear()
    return out


class DivergenceError(RuntimeError):
    """The simulated state became non-finite or ran away.

    Attributes:
        time: simulation time [s] at which it was detected.
        reason: what was detected.
    """

    def __init__(self, time: float, reason: str) -> None:
        super().__init__(f"simulation diverged at t = {time:.4f} s: {reason}")
        self.time = time
        self.reason = reason


@dataclass(frozen=True)
class Energy:
    """Mechanical energy of the plant [J] (velocities relative to the world for the rigid
    part and to the water for the added part)."""

    kinetic_rigid: float
    kinetic_added: float
    potential_gravity: float
    potential_buoyancy: float

    @property
    def kinetic(self) -> float:
        return self.kinetic_rigid + self.kinetic_added

    @property
    def total(self) -> float:
        return self.kinetic + self.potential_gravity + self.potential_buoyancy


def _resolve_backend(requested: str | None, terms: HydroTerms) -> bool:
    """Whether to use the native (C plugin) backend for the requested one."""
    if requested is None:
        requested = default_backend()  # UVMS_MJ_COMPILED; a bad value raises CompiledModeError
    if requested not in BACKENDS:
        raise ParameterError(f"backend = {requested!r}; allowed: {', '.join(BACKENDS)}")
    if requested == "python" or terms.added_mass == "lagged":  # lagged exists only in Python
        return False
    if requested == "native":
        if not _build.register_plugins():
            raise _build.PluginUnavailableError(f"backend 'native': {_build.unavailable_reason()}")
        return True
    return _build.register_plugins()


def water_terms(terms: HydroTerms) -> str:
    """The ``uvms.water`` ``terms`` word list for :class:`HydroTerms` (damping and
    Froude-Krylov always on)."""
    words = ["damping", "froude_krylov"]
    if terms.added_mass != "off":
        words.append("added_mass")
    if terms.drag == "strip":
        words.append("strips")
    if terms.buoyancy:
        words.append("buoyancy")
    return " ".join(sorted(words))


def set_integration(m: mujoco.MjModel, timestep: float | None, integrator: str | None) -> None:
    """Override a compiled model's timestep [s] and integrator (by name, e.g. "rk4"); None keeps
    the model's.

    Raises:
        ParameterError: a timestep that is not finite and > 0, an unknown integrator name."""
    if timestep is not None:
        if not (math.isfinite(timestep) and timestep > 0):
            raise ParameterError(f"timestep = {timestep!r} s must be finite and > 0")
        m.opt.timestep = timestep
    if integrator is not None:
        names = {k.removeprefix("mjINT_").lower(): v for k, v in mujoco.mjtIntegrator.__members__.items()}
        key = integrator.lower()
        if key not in names:
            raise ParameterError(f"integrator = {integrator!r}; allowed: {', '.join(names)}")
        m.opt.integrator = names[key]


# --------------------------------------------------------------------------- plant


class Plant:
    """The robot in MuJoCo with exact added mass, strip drag, buoyancy, thrusters and current.

    Args:
        model: path of an MJCF file (default: ``models/scene.xml``).
        overrides: parameter overrides applied to the model before it is compiled, keys as in
            :data:`uvms_mj.plant.params.OVERRIDE_KEYS` (e.g. ``{"base.volume": 0.03}``).
        terms: which hydrodynamic terms to apply (:class:`HydroTerms`, all on by default).
        gravity: apply gravity (and therefore buoyancy, which is -rho V g).
        current: uniform water current (world frame, m/s, 2 or 3 numbers); default: the model's.
        dead_zone: zero thrust commands inside the thrusters' dead zone.
        timestep, integrator: override the model's (e.g. ``integrator="RK4"``).
        max_speed: runaway threshold on sum |q_dot_i| (m/s and rad/s together).
        backend: "native" (the C plugins, built on first use), "python" (the numpy reference
            through ``mjcb_passive``) or "auto" (native if it can be built, else python);
            default: from ``$UVMS_MJ_COMPILED`` (auto, on: native, off: python).
            ``added_mass="lagged"`` always runs in Python. :attr:`backend` tells which one is in use.

    Raises:
        ParameterError: missing file, missing element, a non-physical parameter or an
            unknown backend.
        uvms_mj.physics.build.PluginUnavailableError: backend "native" requested but the
            plugins cannot be built (e.g. no C compiler); the message says why.
    """

    _snapshot: np.ndarray | None = None  # Plant.step's saved state (per instance once used)

    def __init__(
        self,
        model: str | Path | None = None,
        *,
        overrides: Mapping[str, Any] | None = None,
        terms: HydroTerms = HydroTerms(),
        gravity: bool = True,
        current: Sequence[float] | None = None,
        dead_zone: bool = False,
        timestep: float | None = None,
        integrator: str | None = None,
        max_speed: float = 100.0,
        backend: str | None = None,
    ) -> None:
        install_mujoco_warning_handler()
        path = Path(model) if model is not None else default_model_path()
        if not isinstance(terms, HydroTerms):
            raise ParameterError(f"terms = {terms!r} must be a HydroTerms")
        if not (max_speed > 0):
            raise ParameterError(f"max_speed = {max_speed!r} must be > 0")
        native = _resolve_backend(backend, terms)
        try:
            spec = _pm.load_spec(path)
            if overrides:
                apply_overrides(spec, overrides)
            if not gravity:
                spec.option.gravity = [0.0, 0.0, 0.0]
            if current is not None:
                cur = np.asarray(current, dtype=float).ravel()
                if cur.shape not in ((2,), (3,)) or not np.all(np.isfinite(cur)):
                    raise ParameterError(f"current = {current!r} must be 2 or 3 finite numbers (m/s, world frame)")
                cur3 = np.zeros(3)
                cur3[: cur.size] = cur
                _pm.set_water(spec, current=_pm.fmt(cur3))
                spec.option.wind = cur3  # MuJoCo's own fluid model (drag="mujoco") sees it too
            _pm.set_water(spec, terms=water_terms(terms))
            self.model = _pm.compile_spec(spec, native=native, source=path.name)
        except _pm.ModelError as exc:
            raise ParameterError(str(exc)) from None
        self.model_path = path
        m = self.model
        set_integration(m, timestep, integrator)
        #: The hydrodynamics backend in use: "native" or "python".
        self.backend = "native" if native else "python"
        self.hydro_info = _pm.hydro_of(m)

        self.params: RobotParams = read_params(m)
        self.terms = terms
        self.dead_zone = bool(dead_zone)
        self.max_speed = float(max_speed)
        self._configure_mujoco_drag(terms.drag == "mujoco")

        self.data = mujoco.MjData(m)
        self._scratch = mujoco.MjData(m)  # for rigid-only quantities (energy)
        ids = lambda obj, names: [mujoco.mj_name2id(m, obj, n) for n in names]  # noqa: E731
        self._thr = np.array(ids(mujoco.mjtObj.mjOBJ_ACTUATOR, THRUSTERS))
        self._mot = np.array(ids(mujoco.mjtObj.mjOBJ_ACTUATOR, JOINT_MOTORS))
        self._thr_act = m.actuator_actadr[self._thr]
        self._thr_lo, self._thr_hi = m.actuator_forcerange[self._thr].T.copy()
        self._tip = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, TIP_SITE)
        self._body_ids = ids(mujoco.mjtObj.mjOBJ_BODY, [b.name for b in self.params.bodies])
        if list(m.M_rownnz) != [1, 2, 3, 4, 5] or list(m.M_colind) != [c for r in range(5) for c in range(r + 1)]:
            raise ParameterError("the mass matrix must be dense 5x5 (a planar chain of 5 dofs)")

        self._diverged: tuple[float, str] | None = None
        self._serving: dict[int, _pyb.Served] = {}  # Python backend: mjData address -> its server
        if not native:
            self._serve(self.data)
        self.reset()

    # ---------------------------------------------------------------- hydrodynamics hook

    def _configure_mujoco_drag(self, on: bool) -> None:
        """MuJoCo's ellipsoid model as the drag: density on, its virtual mass/inertia zeroed
        (added mass is ours, exact; MuJoCo would add only its velocity terms)."""
        m = self.model
        robot_geoms = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, b.name) for b in self.params.bodies]
        if on:
            m.opt.density = self.params.rho
            for g in robot_geoms:
                if m.geom_fluid[g, 0] <= 0:
                    raise ParameterError(f"geom {m.geom(g).name!r} needs fluidshape='ellipsoid' for drag='mujoco'")
                m.geom_fluid[g, 6:12] = 0.0
        else:
            m.opt.density = 0.0
            m.opt.viscosity = 0.0

    def _serve(self, d: mujoco.MjData) -> None:
        """Python backend: serve MjData ``d`` with the reference hydrodynamics."""
        self._serving[d._address] = _pyb.Served(self.model, d, self.hydro_info,
                                                lagged=self.terms.added_mass == "lagged")

    def make_data(self) -> mujoco.MjData:
        """A new MjData for ``plant.model``, in water (e.g. for rollouts or a dm_control
        Physics). With the native backend every MjData of the model is (the plugins are part of
        the model); with the Python backend the plant registers this one."""
        d = mujoco.MjData(self.model)
        if self.backend == "python":
            self._serve(d)
        return d

    def attach_data(self, d: mujoco.MjData) -> mujoco.MjData:
        """Make sure an existing MjData of ``plant.model`` is served by the plant's
        hydrodynamics and return it (e.g. ``copy.copy(plant.data)``, or the data under a
        dm_control Physics copy). With the native backend this only checks ``d``.

        Only :meth:`step` on ``plant.data`` raises :class:`DivergenceError`.

        Raises:
            TypeError: ``d`` is not a ``mujoco.MjData``.
            ValueError: ``d`` belongs to another model (even a copy of ``plant.model``).
        """
        if not isinstance(d, mujoco.MjData):
            raise TypeError(f"attach_data expects a mujoco.MjData, got {type(d).__name__}")
        if d.model is not self.model:
            raise ValueError("attach_data: the MjData must belong to plant.model (create it with "
                             "mujoco.MjData(plant.model) or copy.copy(plant.data))")
        if self.backend == "python" and d._address not in self._serving:
            self._serve(d)
        return d

    # ---------------------------------------------------------------- state

    def reset(self, keyframe: str | None = "paper_initial") -> None:
        """Reset time, state and thruster activations; optionally to a model keyframe."""
        m, d = self.model, self.data
        if keyframe is None:
            mujoco.mj_resetData(m, d)
        else:
            k = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, keyframe)
            if k < 0:
                raise ParameterError(f"model has no keyframe named {keyframe!r}")
            mujoco.mj_resetDataKeyframe(m, d, k)
        self._diverged = None
        served = self._serving.get(d._address)
        if served is not None:
            served.reset(float(d.time))
        mujoco.mj_forward(m, d)

    def set_state(
        self,
        base_pose: Sequence[float] | None = None,
        joint_angles: Sequence[float] | None = None,
        base_velocity: Sequence[float] | None = None,
        joint_velocities: Sequence[float] | None = None,
    ) -> None:
        """Set (parts of) the state and recompute derived quantities (``mj_forward``).

        base_pose: (p0x, p0y, phi0) world [m, m, rad]; joint_angles: (phi1, phi2) [rad];
        base_velocity: (p0x_dot, p0y_dot, phi0_dot) world; joint_velocities: (phi1_dot, phi2_dot).
        """
        d = self.data
        for name, val, arr, sl in (
            ("base_pose", base_pose, d.qpos, slice(0, 3)),
            ("joint_angles", joint_angles, d.qpos, slice(3, 5)),
            ("base_velocity", base_velocity, d.qvel, slice(0, 3)),
            ("joint_velocities", joint_velocities, d.qvel, slice(3, 5)),
        ):
            if val is None:
                continue
            v = np.asarray(val, dtype=float).ravel()
            if v.shape != (sl.stop - sl.start,) or not np.all(np.isfinite(v)):
                raise ValueError(f"{name} = {val!r} must be {sl.stop - sl.start} finite numbers")
            arr[sl] = v
        mujoco.mj_forward(self.model, d)

    @property
    def time(self) -> float:
        """Simulation time [s]."""
        return float(self.data.time)

    @property
    def q(self) -> np.ndarray:
        """Generalized coordinates (p0x, p0y, phi0, phi1, phi2) [m, m, rad, rad, rad] (copy)."""
        return self.data.qpos.copy()

    @property
    def qd(self) -> np.ndarray:
        """Generalized velocities (world-frame base velocity, joint rates) (copy)."""
        return self.data.qvel.copy()

    @property
    def base_pose(self) -> np.ndarray:
        """(p0x, p0y, phi0): base position (world, m) and attitude (rad)."""
        return self.data.qpos[0:3].copy()

    @property
    def joint_angles(self) -> np.ndarray:
        """(phi1, phi2): relative joint angles [rad]."""
        return self.data.qpos[3:5].copy()

    @property
    def tip_position(self) -> np.ndarray:
        """End-tip position (x, y) in the world frame [m] at the current state.

        Computed from ``data.qpos`` (on a scratch MjData): after ``mj_step`` MuJoCo's own
        ``site_xpos`` still holds the start of the step (Euler) or an intermediate RK4 stage."""
        s = self._scratch
        s.qpos[:] = self.data.qpos
        mujoco.mj_kinematics(self.model, s)
        return s.site_xpos[self._tip, :2].copy()

    @property
    def thruster_forces(self) -> np.ndarray:
        """Actual thrust of each thruster along its axis [N] at the current time: the lag state,
        clamped to the force range (``data.actuator_force`` holds the value at the start of the
        last step)."""
        return np.minimum(np.maximum(self.data.act[self._thr_act], self._thr_lo), self._thr_hi)

    @property
    def thruster_commands(self) -> np.ndarray:
        """Commanded thrust of each thruster [N] (after the optional dead zone)."""
        return self.data.ctrl[self._thr].copy()

    # ---------------------------------------------------------------- inputs

    def set_thrust(self, commands: Sequence[float]) -> None:
        """Command the three thrusters [N along each thruster's axis], held until changed.

        MuJoCo clamps the command to the force range and lags it by tau (first order).
        With ``dead_zone`` on, commands inside the dead zone give no thrust.
        """
        self.data.ctrl[self._thr] = self._thrust_ctrl(commands)

    def _thrust_ctrl(self, commands: Sequence[float], finite: bool = False) -> np.ndarray:
        """The thrusters' actuator commands for thrusts [N] (checked; the dead zone applied)."""
        c = np.asarray(commands, dtype=float)
        if c.shape != (3,) or not (finite or _finite(c)):
            raise ValueError(f"thruster commands {commands!r} must be 3 finite numbers [N]")
        if self.dead_zone:
            lo, hi = self.params.dead_zone
            c = np.where((c > lo) & (c < hi), 0.0, c)
        return c

    def set_joint_torques(self, torques: Sequence[float]) -> None:
        """Command the two joint torques [N m], held until changed."""
        self.data.ctrl[self._mot] = self._torque_ctrl(torques)

    def _torque_ctrl(self, torques: Sequence[float], finite: bool = False) -> np.ndarray:
        t = np.asarray(torques, dtype=float)
        if t.shape != (2,) or not (finite or _finite(t)):
            raise ValueError(f"joint torques {torques!r} must be 2 finite numbers [N m]")
        return t

    def observe(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(q, qd, tip_position, thruster_forces) now (new arrays)."""
        return self.q, self.qd, self.tip_position, self.thruster_forces

    def command(self, thrust: Sequence[float], torques: Sequence[float], *, finite: bool = False) -> None:
        """:meth:`set_thrust` and :meth:`set_joint_torques` at once (each checked first; with
        ``finite`` the caller has checked that every value is finite, as the sampled loop does)."""
        if finite and not self.dead_zone and type(thrust) is type(torques) is np.ndarray \
                and thrust.shape == (3,) and torques.shape == (2,) and thrust.dtype == torques.dtype == np.float64:
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

    def step_observe(self, n: int = 1):
        """:meth:`step` (n) and the new state: (q, qd, tip_position, thruster forces or None --
        None where the forces follow the commands: read :attr:`thruster_forces` after the next
        :meth:`command`). Native backend: through the compiled sample
        (:mod:`uvms_mj.physics.plant_io`: the same steps, checks and numbers)."""
        io = self.__dict__.get("_io")
        if io is None or io.data is not self.data or io.model is not self.model:
            io = self._plant_io()
            if io is None:
                self.step(n)
                q, qd, tip, thr = self.observe()
                return q, qd, tip, thr if self._io_layout()[4] is not None else None
        if self._diverged is not None or _pyb._FAILURES:
            self._check()
        rc = io.run(n, self.max_speed) if self._diverged is None else 2
        if rc == 0:
            o = io.out.copy()
            s = io.slices
            return o[s[0]], o[s[1]], (o[s[2]] if s[2] is not None else self.tip_position), \
                (o[s[3]] if s[3] is not None else None)
        if rc == 1:
            mujoco.mj_setState(self.model, self.data, io.snapshot, _SNAPSHOT)  # replay step by step
        else:  # a state set from outside since the last step: recorded, then stepped as by step()
            self._check_state()
        self._step_each(n, None)
        self._check_state()
        self._check()
        q, qd, tip, thr = self.observe()
        return q, qd, tip, thr if io.nthr else None

    def _plant_io(self):
        """The compiled sample's arrays for this plant (None: the Python methods run)."""
        io = self.__dict__.get("_io")
        if io is not None and io.data is self.data and io.model is self.model:
            return io
        if self.__dict__.get("_io_tried") is self.data or self._serving.get(self.data._address) is not None:
            return None
        from uvms_mj.physics import plant_io

        self._io_tried = self.data
        fn = plant_io.library()
        if fn is None:
            return None
        m = self.model
        if self._snapshot is None:
            self._snapshot = np.empty(mujoco.mj_stateSize(m, _SNAPSHOT))
        tip_site, ntip, thr_act, lo, hi = self._io_layout()
        io = self._io = plant_io.PlantIO(fn, m, self.data, self._scratch, self._snapshot, int(_SNAPSHOT), tip_site,
                                         ntip, () if thr_act is None else thr_act, () if lo is None else lo,
                                         () if hi is None else hi)
        return io

    def _io_layout(self) -> tuple:
        """(tip_site, ntip, thr_act, lo, hi) of :class:`uvms_mj.physics.plant_io.PlantIO`: the tip's
        (x, y); the thrust = the lag state clamped to the force range (None: it follows the
        commands, the plant computes it)."""
        return self._tip, 2, self._thr_act, self._thr_lo, self._thr_hi

    # ---------------------------------------------------------------- stepping

    def step(self, n: int = 1) -> None:
        """Advance n physics steps.

        Native backend: the n steps run in one ``mj_step(m, d, nstep=n)`` from a saved state;
        if the batch shows a problem (a MuJoCo reset, a non-finite or runaway state), the state is
        restored and the steps are replayed one by one, so that the divergence is reported at the
        step where it happened (the time at the end of that step; a MuJoCo reset: at its start),
        whatever n.

        Raises:
            DivergenceError: the state became non-finite or exceeded ``max_speed``; the message
                says at what time. The plant must be reset before stepping again.
        """
        m, d = self.model, self.data
        self._check()
        self._check_state()
        served = self._serving.get(d._address)
        if served is None and n > 1 and self._diverged is None:
            snap = self._snapshot
            if snap is None:
                snap = self._snapshot = np.empty(mujoco.mj_stateSize(m, _SNAPSHOT))
            mujoco.mj_getState(m, d, snap, _SNAPSHOT)
            dt = m.opt.timestep
            t_end = d.time + n * dt
            mujoco.mj_step(m, d, nstep=n)
            # a MuJoCo reset (bad qpos/qvel/qacc) restarts time: the clock tells it
            if abs(d.time - t_end) < 0.5 * dt:
                self._check_state()
                if self._diverged is None:
                    return
                self._diverged = None
            mujoco.mj_setState(m, d, snap, _SNAPSHOT)  # replay step by step: the exact report
        self._step_each(n, served)
        self._check_state()
        self._check()

    def _step_each(self, n: int, served) -> None:
        m, d = self.model, self.data
        step = mujoco.mj_step
        t = d.time
        check = self._check_state
        if served is None:
            for _ in range(n):
                step(m, d)
                if d.time <= t:
                    break
                t = d.time
                check()  # a runaway is reported at the step where it happens
                if self._diverged is not None:
                    break
        else:
            advance = served.advance
            for _ in range(n):
                step(m, d)
                if d.time <= t or _pyb._FAILURES:
                    break
                t = d.time
                advance(t)
                check()
                if self._diverged is not None:
                    break
        # MuJoCo resets the state itself on a bad qpos/qvel/qacc (and restarts time): never let
        # that pass silently. t is the time at the start of the step that failed.
        for w in (mujoco.mjtWarning.mjWARN_BADQACC, mujoco.mjtWarning.mjWARN_BADQVEL, mujoco.mjtWarning.mjWARN_BADQPOS):
            if d.warning[w].number > 0 and self._diverged is None:
                self._diverged = (float(t), f"non-finite or huge state ({w.name}; MuJoCo reset the state)")

    def _check_state(self) -> None:
        """Record a divergence of the current state (non-finite, or sum |q_dot| > max_speed)."""
        if self._diverged is not None:
            return
        d = self.data
        speed = sum(map(abs, d.qvel.tolist()))  # plain floats: cheaper than numpy at these sizes
        if not (speed <= self.max_speed and math.isfinite(sum(d.qpos.tolist()))):
            finite = bool(np.all(np.isfinite(d.qpos)) and np.all(np.isfinite(d.qvel)))
            what = "non-finite state (NaN or inf)" if not finite else (
                f"runaway: sum |q_dot| = {speed:.3g} > max_speed = {self.max_speed:g}")
            self._diverged = (float(d.time), what)

    def _check(self) -> None:
        exc = _pyb.failure(self.data)
        if exc is not None:
            raise RuntimeError(f"the hydrodynamics callback failed at t = {self.time:.4f} s: {exc!r}") from exc
        if self._diverged is not None:
            raise DivergenceError(*self._diverged)

    # ---------------------------------------------------------------- diagnostics

    def energy(self) -> Energy:
        """Kinetic (rigid and added) and potential (gravity and buoyancy) energy [J]."""
        m, d, s = self.model, self.data, self._scratch
        s.qpos[:] = d.qpos
        s.qvel[:] = d.qvel
        s.time = d.time
        mujoco.mj_fwdPosition(m, s)  # the rigid mass matrix (the passive stage is not run)
        mujoco.mj_comVel(m, s)
        mq = np.zeros(m.nv)
        mujoco.mj_mulM(m, s, mq, s.qvel)
        rigid = 0.5 * float(s.qvel @ mq)
        info = self.hydro_info
        served = self._serving.get(d._address)
        state = served.current_state if served is not None else _pm.current_state_of(m, d)
        added = (_ref.added_kinetic_energy(m, s, info.water, info.bodies, current_state=state)
                 if self.terms.added_mass != "off" else 0.0)
        g = m.opt.gravity
        pot_g = -sum(m.body_mass[b] * float(g @ s.xipos[b]) for b in self._body_ids)
        pot_b = 0.0
        if self.terms.buoyancy:
            rho = float(info.water.density)
            for b, bh in info.bodies.items():
                cob = s.xpos[b] + s.xmat[b].reshape(3, 3) @ np.asarray(bh.cob, dtype=float)
                pot_b += rho * float(bh.volume) * float(g @ cob)
        return Energy(rigid, added, float(pot_g), float(pot_b))

    def mass_matrix(self) -> np.ndarray:
        """Full 5x5 generalized mass matrix at the current state, added mass included."""
        mujoco.mj_forward(self.model, self.data)
        out = np.zeros((self.model.nv, self.model.nv))
        mujoco.mj_fullM(self.model, self.data, out)
        return out
