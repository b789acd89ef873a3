"""The plant: the MuJoCo model of the robot with the hydrodynamics installed.

``Plant()`` loads ``models/scene.xml`` (robot + scene), validates its parameters and installs
the closed-form hydrodynamics of :mod:`uvms_mj.hydro` through MuJoCo's ``mjcb_passive``
callback, so that plain ``mujoco.mj_step`` / ``mujoco.mj_forward`` on ``plant.model`` and
``plant.data`` include them with every integrator (Euler, implicit, RK4):

* the exact added-mass matrix is added to MuJoCo's mass matrix ``d.M`` and refactored
  (no lag, no filter), and
* the added-mass velocity terms, strip drag and buoyancy are added to ``d.qfrc_passive``.

``mjcb_passive`` is process-global: one dispatcher serves every live plant and leaves
other models untouched, so several plants (and unrelated MuJoCo models) can live in one
process. Frames: world X horizontal, Y up; angles counter-clockwise positive.

Two backends compute the same hydrodynamics (``Plant(backend=...)``, default from
``$UVMS_MJ_BACKEND``, else "auto"): "python", the closed form of :mod:`uvms_mj.hydro` called
through a ctypes dispatcher, and "native", its C port (:mod:`uvms_mj.native`) installed as the
callback itself, several times faster; "auto" takes native when a C compiler can build it.
"""

from __future__ import annotations

import ctypes
import math
import threading
import warnings
import weakref
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import mujoco
import numpy as np

from . import native as _native
from .hydro import HydroModel, HydroTerms
from .params import (
    JOINT_MOTORS,
    THRUSTERS,
    TIP_SITE,
    ParameterError,
    RobotParams,
    apply_overrides,
    read_params,
)

_PKG = Path(__file__).resolve().parent


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


# --------------------------------------------------------------------------- callback dispatch
#
# MuJoCo has ONE process-global mjcb_passive. A plain Python callable would be wrapped by the
# bindings, which look up the Python MjModel/MjData of every raw pointer and abort with
# "Python exception raised" for structs they do not know: that breaks every model compiled
# while a plant is alive (compilation runs the passive stage on a temporary model). We install
# a ctypes function instead: MuJoCo calls it with raw pointers, and we dispatch on the mjData
# address to the plant that owns it; every other model and data is left untouched.

_PASSIVE_CFUNC = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_void_p)
_HANDLERS: dict[int, Callable[[], None]] = {}  # mjData address -> handler
_PLANT_MODELS: set[int] = set()  # mjModel addresses of live plants
_FAILURES: dict[int, BaseException] = {}  # mjData address -> first exception in its handler
_LOCK = threading.RLock()
_warned_unregistered = False


def _dispatch(m_ptr: int | None, d_ptr: int | None) -> None:
    handler = _HANDLERS.get(d_ptr)  # type: ignore[arg-type]
    if handler is not None:
        try:
            handler()
        except BaseException as exc:  # noqa: BLE001 - ctypes would print and swallow it
            # Never let a failed hydrodynamics evaluation pass silently: Plant.step raises it.
            _FAILURES.setdefault(d_ptr, exc)  # type: ignore[arg-type]
    elif m_ptr in _PLANT_MODELS:
        global _warned_unregistered
        if not _warned_unregistered:
            _warned_unregistered = True
            warnings.warn(
                "an MjData of a uvms_mj plant's model is stepped without hydrodynamics: create "
                "extra data with Plant.make_data() so that the plant can serve it",
                RuntimeWarning,
                stacklevel=1,
            )


_C_DISPATCH = _PASSIVE_CFUNC(_dispatch)


# The native backend installs its C function uvms_passive as mjcb_passive instead: it serves its
# registered mjData itself and calls _C_DISPATCH (set as its fallback) for every other mjData,
# so Python-backed plants and the unregistered-data warning keep working alongside it.
_NATIVE_LIB: _native.NativeLib | None = None  # set once a native plant exists


def _install_dispatcher(lib: _native.NativeLib | None = None) -> None:
    """Make mjcb_passive ours: the native callback if ``lib`` is given or already installed,
    else the Python dispatcher."""
    global _NATIVE_LIB
    current = mujoco.get_mjcb_passive()
    if lib is not None:
        lib.set_fallback(_C_DISPATCH)
        _NATIVE_LIB = lib
    ours = _NATIVE_LIB.passive if _NATIVE_LIB is not None else _C_DISPATCH
    if current is ours:
        return
    if current is not None and current is not _C_DISPATCH:
        warnings.warn(
            f"replacing an existing mjcb_passive callback ({current!r}): uvms_mj needs it for "
            "its hydrodynamics; other models are left untouched",
            RuntimeWarning,
            stacklevel=3,
        )
    mujoco.set_mjcb_passive(ours)


def _register(model: mujoco.MjModel, data: mujoco.MjData, handler: Callable[[], None]) -> None:
    with _LOCK:
        _install_dispatcher()
        _HANDLERS[data._address] = handler
        _PLANT_MODELS.add(model._address)
    weakref.finalize(data, _unregister_data, data._address)
    weakref.finalize(model, _unregister_model, model._address)


def _register_native(
    lib: _native.NativeLib, model: mujoco.MjModel, data: mujoco.MjData, params: _native.Params
) -> None:
    with _LOCK:
        _install_dispatcher(lib)
        if lib.register(data._address, params) < 0:
            raise RuntimeError("too many live MjData served by the native hydrodynamics (registry full)")
        _PLANT_MODELS.add(model._address)  # its unregistered data still get the Python warning
    # The finalizer holds params alive until the C registry has let go of it.
    weakref.finalize(data, _unregister_native_data, lib, data._address, params)
    weakref.finalize(model, _unregister_model, model._address)


# Finalizers may run from the garbage collector at any point, even while _LOCK is held by this
# thread: they take no lock (single dict/set operations are atomic under the GIL).
def _unregister_data(addr: int) -> None:
    _HANDLERS.pop(addr, None)
    _FAILURES.pop(addr, None)


def _unregister_native_data(lib: _native.NativeLib, addr: int, params: _native.Params) -> None:
    lib.unregister(addr)  # lock-free in C
    _FAILURES.pop(addr, None)


def _unregister_model(addr: int) -> None:
    _PLANT_MODELS.discard(addr)


def _resolve_backend(requested: str | None, terms: HydroTerms) -> _native.NativeLib | None:
    """The native library for the requested backend, or None for the Python backend."""
    if requested is None:
        try:
            requested = _native.backend_from_env()
        except ValueError as exc:
            raise ParameterError(str(exc)) from None
    if requested not in _native.BACKENDS:
        raise ParameterError(f"backend = {requested!r}; allowed: {', '.join(_native.BACKENDS)}")
    if requested == "python" or terms.added_mass == "lagged":  # lagged exists only in Python
        return None
    if requested == "native":
        return _native.require()
    lib = _native.load()
    if lib is None:
        _native.warn_unavailable_once()
    return lib


# --------------------------------------------------------------------------- plant


class Plant:
    """The robot in MuJoCo with exact added mass, strip drag, buoyancy, thrusters and current.

    Args:
        model: path of an MJCF file (default: ``models/scene.xml``).
        overrides: parameter overrides applied to the compiled model, keys as in
            :data:`uvms_mj.params.OVERRIDE_KEYS` (e.g. ``{"base.volume": 0.03}``).
        terms: which hydrodynamic terms to apply (:class:`HydroTerms`, all on by default).
        gravity: apply gravity (and therefore buoyancy, which is -rho V g).
        current: uniform water current (world frame, m/s); default: the model's ``opt.wind``.
        dead_zone: zero thrust commands inside the thrusters' dead zone.
        timestep, integrator: override the model's (e.g. ``integrator="RK4"``).
        max_speed: runaway threshold on sum |q_dot_i| (m/s and rad/s together).
        backend: "native" (the C hydrodynamics, built on first use), "python" (the reference
            implementation) or "auto" (native if it can be built, else python with a one-time
            warning); default: ``$UVMS_MJ_BACKEND``, else "auto". ``added_mass="lagged"``
            always runs in Python. :attr:`backend` tells which one is in use.

    Raises:
        ParameterError: missing file, missing element, a non-physical parameter or an
            unknown backend.
        uvms_mj.native.NativeUnavailableError: backend "native" requested but it cannot be
            built (e.g. no C compiler); the message says why.
    """

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
        if not path.is_file():
            raise ParameterError(f"model file {str(path)!r} does not exist")
        try:
            self.model = mujoco.MjModel.from_xml_path(str(path))
        except ValueError as exc:
            raise ParameterError(f"cannot load model file {str(path)!r}: {exc}") from None
        self.model_path = path
        m = self.model
        if overrides:
            apply_overrides(m, overrides)
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
        if not gravity:
            m.opt.gravity[:] = 0.0
        if current is not None:
            cur = np.asarray(current, dtype=float).ravel()
            if cur.shape not in ((2,), (3,)) or not np.all(np.isfinite(cur)):
                raise ParameterError(f"current = {current!r} must be 2 finite numbers (m/s, world X and Y)")
            m.opt.wind[: cur.size] = cur
        if not (max_speed > 0):
            raise ParameterError(f"max_speed = {max_speed!r} must be > 0")
        if not isinstance(terms, HydroTerms):
            raise ParameterError(f"terms = {terms!r} must be a HydroTerms")
        self._native_lib = _resolve_backend(backend, terms)
        #: The hydrodynamics backend in use: "native" or "python".
        self.backend = "native" if self._native_lib is not None else "python"

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
        self._cob_ids = ids(mujoco.mjtObj.mjOBJ_SITE, [f"{b.name}:cob" for b in self.params.bodies])
        if list(m.M_rownnz) != [1, 2, 3, 4, 5] or list(m.M_colind) != [c for r in range(5) for c in range(r + 1)]:
            raise ParameterError("the mass matrix must be dense 5x5 (a planar chain of 5 dofs)")

        self._diverged: tuple[float, str] | None = None
        self._native_state: _native.Params | None = None  # native callback state of self.data
        self._served: weakref.WeakSet[mujoco.MjData] = weakref.WeakSet()  # data served by this plant
        self._install()
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

    def _install(self) -> None:
        terms = self.terms
        lagged = terms.added_mass == "lagged"
        # "lagged" evaluates the same exact terms but applies the matrix part explicitly.
        self.hydro = HydroModel(self.params, replace(terms, added_mass="exact") if lagged else terms)
        self._attach(self.data)

    def make_data(self) -> mujoco.MjData:
        """A new MjData for ``plant.model`` that the plant's hydrodynamics also serve
        (e.g. for rollouts or a dm_control Physics). Plain ``mujoco.MjData(plant.model)`` is
        stepped without hydrodynamics (with a one-time RuntimeWarning)."""
        d = mujoco.MjData(self.model)
        self._attach(d)
        return d

    def attach_data(self, d: mujoco.MjData) -> mujoco.MjData:
        """Register an existing MjData of ``plant.model`` with the plant's hydrodynamics and
        return it (e.g. ``copy.copy(plant.data)``, or the data under a dm_control Physics copy).

        ``plant.data`` and data from :meth:`make_data` are served already: attaching them again
        is a no-op. Only :meth:`step` on ``plant.data`` raises :class:`DivergenceError`; other
        data are served the same hydrodynamics but their divergence is not tracked.

        Raises:
            TypeError: ``d`` is not a ``mujoco.MjData``.
            ValueError: ``d`` belongs to another model (even a copy of ``plant.model``).
        """
        if not isinstance(d, mujoco.MjData):
            raise TypeError(f"attach_data expects a mujoco.MjData, got {type(d).__name__}")
        if d.model is not self.model:
            raise ValueError("attach_data: the MjData must belong to plant.model (create it with "
                             "mujoco.MjData(plant.model) or copy.copy(plant.data))")
        if d not in self._served:
            self._attach(d)
        return d

    def _attach(self, d: mujoco.MjData) -> None:
        """Register the passive-force handler of data ``d``: it adds the exact added-mass
        matrix to d.M (then refactors it) and the hydrodynamic forces to d.qfrc_passive."""
        self._served.add(d)
        if self._native_lib is not None:
            # The C callback does all of passive() below natively, with its own copy of the
            # constants and per-data state (added-mass guard, divergence status).
            params = _native.make_params(self.hydro, self.max_speed)
            _register_native(self._native_lib, self.model, d, params)
            if d is self.data:
                self._native_state = params
            return
        m = self.model
        evaluate = self.hydro.evaluate
        exact = self.terms.added_mass == "exact"
        lagged = self.terms.added_mass == "lagged"
        max_speed = self.max_speed
        opt = m.opt
        qpos, qvel, mass, qfrc_passive, qacc = d.qpos, d.qvel, d.M, d.qfrc_passive, d.qacc
        factor = mujoco.mj_factorM
        plant_ref = weakref.ref(self)
        data_ref = weakref.ref(d)
        state = {"augmented": None}  # d.M[0] right after our last augmentation
        isfinite = math.isfinite

        def flag(q: list[float], qd: list[float]) -> None:
            """Record the first divergence of the plant's own data (a callback cannot raise)."""
            p, dd = plant_ref(), data_ref()
            if p is not None and dd is p.data and p._diverged is None:
                finite = all(map(isfinite, q + qd))
                what = "non-finite state (NaN or inf)" if not finite else (
                    f"runaway: sum |q_dot| = {sum(map(abs, qd)):.3g} > max_speed = {max_speed:g}")
                p._diverged = (float(dd.time), what)

        def passive() -> None:
            q = qpos.tolist()
            qd = qvel.tolist()
            # One sum catches NaN, inf and runaway speeds (a NaN makes the comparison false).
            if not (sum(map(abs, qd)) <= max_speed and isfinite(sum(q))):
                flag(q, qd)
                return
            # mj_forwardSkip (finite differencing) re-enters here with d.M already augmented.
            want_mass = exact and state["augmented"] != mass[0]
            madd, qfrc = evaluate(q, qd, opt.wind.tolist()[:2], opt.gravity.tolist()[:2], want_mass or lagged)
            if want_mass:
                mass[:] += madd
                factor(m, data_ref())
                state["augmented"] = mass[0]
            elif lagged:
                # -M_A(q) times the previous step's acceleration as a force, d.M untouched:
                # the explicit scheme of several peer simulators, kept to show that it diverges.
                am = np.zeros((5, 5))
                am[np.tril_indices(5)] = madd
                qfrc = np.asarray(qfrc) - (am + np.tril(am, -1).T) @ qacc
            qfrc_passive[:] += qfrc

        _register(m, d, passive)

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
        if self._native_state is not None:
            self._native_state.status = _native.STATUS_OK
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
        return np.clip(self.data.act[self._thr_act], self._thr_lo, self._thr_hi)

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
        c = np.asarray(commands, dtype=float)
        if c.shape != (3,) or not np.all(np.isfinite(c)):
            raise ValueError(f"thruster commands {commands!r} must be 3 finite numbers [N]")
        if self.dead_zone:
            lo, hi = self.params.dead_zone
            c = np.where((c > lo) & (c < hi), 0.0, c)
        self.data.ctrl[self._thr] = c

    def set_joint_torques(self, torques: Sequence[float]) -> None:
        """Command the two joint torques [N m], held until changed."""
        t = np.asarray(torques, dtype=float)
        if t.shape != (2,) or not np.all(np.isfinite(t)):
            raise ValueError(f"joint torques {torques!r} must be 2 finite numbers [N m]")
        self.data.ctrl[self._mot] = t

    # ---------------------------------------------------------------- stepping

    def step(self, n: int = 1) -> None:
        """Advance n physics steps.

        Raises:
            DivergenceError: the state became non-finite or exceeded ``max_speed``; the message
                says at what time. The plant must be reset before stepping again.
        """
        m, d = self.model, self.data
        self._check()
        step = mujoco.mj_step
        t = d.time
        native = self._native_state
        if native is not None:
            for _ in range(n):
                step(m, d)
                if native.status or _FAILURES or d.time <= t:
                    break
                t = d.time
            self._sync_native()
        else:
            for _ in range(n):
                step(m, d)
                if self._diverged is not None or _FAILURES or d.time <= t:
                    break
                t = d.time
        # MuJoCo resets the state itself on a bad qpos/qvel/qacc (and restarts time): never let
        # that pass silently. t is the time at the start of the step that failed.
        for w in (mujoco.mjtWarning.mjWARN_BADQACC, mujoco.mjtWarning.mjWARN_BADQVEL, mujoco.mjtWarning.mjWARN_BADQPOS):
            if d.warning[w].number > 0 and self._diverged is None:
                self._diverged = (float(t), f"non-finite or huge state ({w.name}; MuJoCo reset the state)")
        self._check()

    def _sync_native(self) -> None:
        """Turn the native callback's divergence status of self.data into ``_diverged``
        (the same record as the Python handler's ``flag``)."""
        st = self._native_state
        if st is None or not st.status or self._diverged is not None:
            return
        if st.status == _native.STATUS_NONFINITE:
            what = "non-finite state (NaN or inf)"
        else:
            what = f"runaway: sum |q_dot| = {st.status_speed:.3g} > max_speed = {self.max_speed:g}"
        self._diverged = (float(st.status_time), what)

    def _check(self) -> None:
        self._sync_native()
        exc = _FAILURES.pop(self.data._address, None)
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
        mujoco.mj_fwdPosition(m, s)  # builds the rigid mass matrix only (no passive callback)
        mq = np.zeros(m.nv)
        mujoco.mj_mulM(m, s, mq, s.qvel)
        rigid = 0.5 * float(s.qvel @ mq)
        added = (
            self.hydro.added_kinetic_energy(d.qpos.tolist(), d.qvel.tolist(), tuple(m.opt.wind[:2]))
            if self.terms.added_mass != "off"
            else 0.0
        )
        g = m.opt.gravity
        pot_g = -sum(m.body_mass[b] * float(g @ s.xipos[b]) for b in self._body_ids)
        pot_b = (
            sum(self.params.rho * bp.volume * float(g @ s.site_xpos[c]) for bp, c in zip(self.params.bodies, self._cob_ids))
            if self.terms.buoyancy
            else 0.0
        )
        return Energy(rigid, added, float(pot_g), float(pot_b))

    def mass_matrix(self) -> np.ndarray:
        """Full 5x5 generalized mass matrix at the current state, added mass included."""
        mujoco.mj_forward(self.model, self.data)
        out = np.zeros((self.model.nv, self.model.nv))
        mujoco.mj_fullM(self.model, self.data, out)
        return out
