"""The plant: any robot's MuJoCo model, in water through the uvms plugins.

``Plant()`` loads the paper's robot in its scene (``robot: paper``, ``models/paper/scene.xml``);
``Plant("bluerov2_alpha")`` or ``Plant("my_robot.xml")`` any other robot. Every robot file
carries its hydrodynamics as attributes of the ``uvms.water`` / ``uvms.hydro`` MuJoCo plugins and
its thrusters as site actuators (``docs/hydrodynamics.md``), so plain ``mujoco.mj_step`` /
``mujoco.mj_forward`` on ``plant.model`` and ``plant.data`` (or on any other MjData of that
model) include them with every integrator (Euler, implicit, RK4):

* the exact added-mass matrix is added to MuJoCo's mass matrix ``d.M`` and refactored
  (no lag, no filter), and
* the added-mass velocity terms, damping, strip drag and buoyancy are added to
  ``d.qfrc_passive``.

Two backends compute the same hydrodynamics (``Plant(backend=...)``, default from
``$UVMS_MJ_COMPILED``: "auto", "native" for ``on``, "python" for ``off``): "native", the C plugins compiled into the model, and
"python", the numpy reference (:mod:`uvms_mj.physics.reference`) served through
``mjcb_passive`` (the model's plugins compiled with every term off, or stripped where they
cannot be built); "auto" takes native when the plugin library can be built.

One class for every robot; what differs is the robot's :class:`~uvms_mj.plant.layout.Layout`:

* a free vehicle (a body on a free joint): ``q`` = qpos (x, y, z world, qw, qx, qy, qz, joint
  angles), ``qd`` = qvel (linear velocity WORLD, angular velocity BODY, joint rates), the tip in
  3-D, world z up;
* a planar base (slides along world axes and a hinge, the paper's slide x, slide y, hinge z):
  ``q`` = (p0x, p0y, phi0, phi1, phi2), the tip in the plane (x, y), world X horizontal, Y up,
  angles counter-clockwise positive.

Thrusters are commanded in newtons (:meth:`Plant.set_thrust`). A thruster whose force is its
command (a ``general`` actuator of unit gain, the paper's) takes the thrust as its command; any
other (a ``uvms.thruster`` plugin with a thrust curve) gets the inverse of the model's own curve,
as a thruster driver with a calibrated lookup table would.

The plant adds to MuJoCo only what a simulation run needs around it: parameter overrides,
named accessors, thruster commands with the optional dead zone, scheduled events (a payload
picked up, a thruster failing), divergence detection and the energy (:mod:`.stepping`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import mujoco
import numpy as np

from uvms_mj.physics.terms import HydroTerms
from uvms_mj.plant.setup import resolve_backend, set_integration, water_terms
from uvms_mj.plant import params as _params
from uvms_mj.plant.files import default_model_path, models_dir, robot_path  # noqa: F401  (re-exported)
from uvms_mj.plant.actuation import Actuation
from uvms_mj.plant.layout import InitialState, Layout
from uvms_mj.plant.params import ParameterError, RobotParams, read_params
from uvms_mj.plant.robot import Payload, _is_planar_spec, apply_model_overrides
from uvms_mj.plant.tether import TETHER_PREFIX, Tether, add_tether, tether_dofs, tether_pull
from uvms_mj.plant.stepping import (  # noqa: F401  (DivergenceError, Energy, mujoco_warnings: re-exported)
    DivergenceError,
    Energy,
    Stepping,
    install_mujoco_warning_handler,
    mujoco_warnings,
)
from uvms_mj.physics import model as _pm
from uvms_mj.physics import python_backend as _pyb
from uvms_mj.physics.current import Current
from uvms_mj.physics.waves import Waves
from uvms_mj.plant.sea import SeaMonitor, SurfaceError
from uvms_mj.physics.thrusters import CurveInverse, thruster_curves

__all__ = ["DivergenceError", "Energy", "Plant", "ThrusterFailure"]

_RESET_TO_INITIAL = object()  # Plant.reset's default: the plant's initial state



@dataclass(frozen=True)
class ThrusterFailure:
    """A thruster that fails at time ``t`` [s]: from the first control sample at or after ``t``
    its force is zero (its actuator's force range becomes [0, 0], which MuJoCo applies to the
    actuator force whatever the command; the controller is not told).

    Attributes:
        thruster: the thruster actuator's name; t: the failure time [s] (>= 0).
    """

    thruster: str
    t: float = 0.0


class Plant(Stepping, Actuation):
    """A robot in MuJoCo with exact added mass, strip drag, buoyancy, thrusters and current
    (module docstring).

    Args:
        model: a built-in robot name (:data:`uvms_mj.plant.files.BUILTIN_ROBOTS`) or an MJCF
            path; default the paper's robot in its scene (``models/paper/scene.xml``).
        overrides: parameter overrides applied to the model before it is compiled
            (:func:`apply_model_overrides`: by element name, ``{"vehicle.mass": "x1.1"}``; the
            paper robot's own keys too, e.g. ``{"base.volume": 0.03}``).
        terms: which hydrodynamic terms to apply (:class:`HydroTerms`, all on by default;
            ``added_mass="lagged"`` and ``drag="mujoco"`` need a planar robot with the paper's
            parameters).
        gravity: apply gravity (and therefore buoyancy, which is -rho V g): True the model's
            (``<option gravity>``), False none, or 3 numbers: that gravity [m/s^2, world] (e.g. a
            robot's source's local value).
        current: the water current: 2 or 3 numbers (uniform, world frame, m/s) or a
            :class:`~uvms_mj.physics.current.Current` (Gauss-Markov, depth profile); default:
            the model's.
        waves: linear waves (:class:`~uvms_mj.physics.waves.Waves`: Airy, JONSWAP,
            Pierson-Moskowitz) set as the water plugin's attributes; default: the model's.
            With waves on, a centre of buoyancy above the mean surface is refused at reset
            and warned about during a run (:mod:`uvms_mj.plant.sea`).
        dead_zone: zero thrust commands inside the thrusters' dead zone: True (the band of the
            paper robot's parameters) or (low, high) [N].
        timestep, integrator: override the model's (e.g. ``integrator="RK4"``).
        initial: the initial state (:class:`~uvms_mj.plant.layout.InitialState`); default the
            model's initial keyframe (a keyframe named ``*initial``), else ``qpos0``.
        tip_site: end-effector site (default: the first site whose name ends in "tip").
        max_speed: runaway threshold on sum |q_dot_i| (m/s and rad/s together).
        backend: "native" (the C plugins, built on first use), "python" (the numpy reference
            through ``mjcb_passive``) or "auto" (native if it can be built, else python);
            default: from ``$UVMS_MJ_COMPILED`` (auto, on: native, off: python).
            ``added_mass="lagged"`` always runs in Python. :attr:`backend` tells which one is in use.
        payload: a payload picked up during the run (:class:`~uvms_mj.plant.robot.Payload`).
        failures: thrusters failing during the run (:class:`ThrusterFailure`).
        spec_edits: callables applied to the model's MjSpec before it is compiled, after the
            overrides (e.g. :func:`uvms_mj.sim.navsensors.add_to_spec`: MuJoCo sensors, a seabed).
        tether: a tether from a surface point to the vehicle (:class:`~uvms_mj.plant.tether.Tether`;
            a free vehicle only): a chain of its own appended to the model, placed at every
            :meth:`reset`; :attr:`q`, :attr:`qd` and everything the controllers see are the
            robot's coordinates only (a prefix of ``qpos`` / ``qvel``), the tether's pull is
            logged (:meth:`sea_signals`: ``tether_pull``). The divergence check (``max_speed``)
            sums the tether's joint rates too (a runaway chain is a divergence).

    Raises:
        ParameterError: missing file, missing element, a non-physical parameter or an
            unknown backend.
        uvms_mj.physics.build.PluginUnavailableError: backend "native" requested but the
            plugins cannot be built (e.g. no C compiler); the message says why.
    """

    def __init__(
        self,
        model: str | Path | None = None,
        *,
        overrides: Mapping[str, Any] | None = None,
        terms: HydroTerms = HydroTerms(),
        gravity: bool | Sequence[float] = True,
        current: Sequence[float] | Current | None = None,
        waves: Waves | None = None,
        dead_zone: bool | Sequence[float] = False,
        timestep: float | None = None,
        integrator: str | None = None,
        initial: InitialState | None = None,
        tip_site: str | None = None,
        max_speed: float = 100.0,
        backend: str | None = None,
        payload: Payload | None = None,
        failures: Sequence[ThrusterFailure] = (),
        spec_edits: Sequence[Any] = (),
        tether: Tether | None = None,
    ) -> None:
        install_mujoco_warning_handler()
        path = default_model_path() if model is None else robot_path(model)
        if not isinstance(terms, HydroTerms):
            raise ParameterError(f"terms = {terms!r} must be a HydroTerms")
        if not (max_speed > 0):
            raise ParameterError(f"max_speed = {max_speed!r} must be > 0")
        if payload is not None and not (payload.mass > 0 and payload.t >= 0):
            raise ParameterError(f"payload = {payload!r}: mass must be > 0 and t >= 0")
        if initial is not None and not isinstance(initial, InitialState):
            raise ParameterError(f"initial = {initial!r} must be an InitialState")
        native = resolve_backend(backend, terms)
        if isinstance(current, Current):
            water = current.attributes()
            wind = np.asarray(current.velocity, dtype=float)
        elif current is not None:
            cur = np.asarray(current, dtype=float).ravel()
            if cur.shape not in ((2,), (3,)) or not np.all(np.isfinite(cur)):
                raise ParameterError(f"current = {current!r} must be 2 or 3 finite numbers (m/s, world frame)")
            wind = np.zeros(3)
            wind[: cur.size] = cur
            water = {"current": _pm.fmt(wind)}
        try:
            spec = _pm.load_spec(path)
            planar = _is_planar_spec(spec)
            if planar is False and (terms.added_mass == "lagged" or terms.drag == "mujoco"):
                raise ParameterError(f"terms = {terms!r}: a free vehicle supports added_mass exact|off, "
                                     "drag strip|off (lagged and mujoco are the paper's planar robot's)")
            if overrides:
                apply_model_overrides(spec, overrides)
            if gravity is False:
                spec.option.gravity = [0.0, 0.0, 0.0]
            elif gravity is not True:
                g = np.asarray(gravity, dtype=float).ravel()
                if g.shape != (3,) or not np.all(np.isfinite(g)):
                    raise ParameterError(f"gravity = {gravity!r}: give true, false or 3 finite numbers [m/s^2, world]")
                spec.option.gravity = g
            if current is not None:
                _pm.set_water(spec, **water)
                spec.option.wind = wind  # MuJoCo's own fluid model (drag="mujoco") sees it too
            if waves is not None:
                if not isinstance(waves, Waves):
                    raise ParameterError(f"waves = {waves!r} must be a uvms_mj.physics.waves.Waves")
                _pm.set_water(spec, **waves.attributes())
            _pm.set_water(spec, terms=water_terms(terms))
            if payload is not None:
                site = payload.site or tip_site or next(
                    (x.name for x in spec.sites if x.name and x.name.endswith("tip")), None)
                if site is None:
                    raise ParameterError("payload: the robot has no tip site; give payload.site")
                payload.add_to(spec, site)
            for edit in spec_edits:
                edit(spec)
            robot_model = add_tether(spec, tether, native=native, source=path.name) if tether is not None else None
            # (a tether's joints pad the file's keyframes with qpos0; add_tether checked them as written)
            self.model = _pm.compile_spec(spec, native=native, source=path.name, check_keyframes=tether is None)
            #: The robot's own model, without a tether's chain (:attr:`q` fits it; the log's /tf
            #: and scene): :attr:`model` itself without a tether.
            self.robot_model = robot_model if tether is not None else self.model
        except _pm.ModelError as exc:
            raise ParameterError(str(exc)) from None
        self.model_path = path
        m = self.model
        set_integration(m, timestep, integrator)
        #: The hydrodynamics backend in use: "native" or "python".
        self.backend = "native" if native else "python"
        self.hydro_info = _pm.hydro_of(m)
        #: The named pieces of the model (:class:`~uvms_mj.plant.layout.Layout`).
        self.layout = lay = Layout.of(m, tip_site, allow_planar=True,
                                      exclude=f"{TETHER_PREFIX}_0" if tether is not None else None)
        #: The tether (None: none) and the robot's part of qpos / qvel (all of them without one).
        self.tether = tether
        self._nq, self._nv = tether_dofs(m)
        #: The paper robot's planar parameters (:class:`~uvms_mj.plant.params.RobotParams`) for a
        #: planar robot that has them, else None.
        self.params: RobotParams | None = None
        if not lay.base_free and all(mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, b) >= 0
                                     for b in _params.HYDRO_BODIES):
            self.params = read_params(m)  # the paper's robot: its parameters checked (raises)
        self.terms = terms
        self.max_speed = float(max_speed)
        self.initial = initial if initial is not None else InitialState()
        self.payload = payload
        self._configure_mujoco_drag(terms.drag == "mujoco")

        self.data = mujoco.MjData(m)
        self._scratch = mujoco.MjData(m)  # for rigid-only quantities (energy) and the tip
        self._thr = lay.thruster_ids
        self._mot = lay.motor_ids
        self._thr_act = np.array([m.actuator_actadr[a] for a in self._thr], dtype=int)
        self._thr_lagged = bool(len(self._thr)) and bool(np.all(self._thr_act >= 0))
        self._thr_lo, self._thr_hi = (m.actuator_forcerange[self._thr].T.copy() if len(self._thr)
                                      else (np.zeros(0), np.zeros(0)))
        self._curves = thruster_curves(m) if len(self._thr) else []
        #: Every thruster's force is its command (unit-gain actuators, the paper's): the command
        #: is the thrust in newtons, no curve to invert.
        self._direct = all(c.kind == "poly" and tuple(c.coeffs) == (0.0, 1.0) for c in self._curves)
        groups: dict = {}  # thrusters sharing a curve and command range are inverted together
        for k, (c, a) in enumerate(zip(self._curves, self._thr)):
            rng = tuple(m.actuator_ctrlrange[a]) if m.actuator_ctrllimited[a] else (None, None)
            groups.setdefault((c, rng), []).append(k)
        self._groups = [(np.array(ks), c, CurveInverse(c, *rng)) for (c, rng), ks in groups.items()]
        self.dead_zone = dead_zone is not False and dead_zone is not None
        if dead_zone is True:
            if self.params is None:
                raise ParameterError("dead_zone = True needs the paper robot's parameters; give the band "
                                     "(low, high) [N]")
            self._dead_band = tuple(float(v) for v in self.params.dead_zone)
        elif self.dead_zone:
            band = np.asarray(dead_zone, dtype=float).ravel()
            if band.shape != (2,) or not np.all(np.isfinite(band)) or not band[0] <= 0 <= band[1]:
                raise ParameterError(f"dead_zone = {dead_zone!r}: expected (low, high) [N] with low <= 0 <= high")
            self._dead_band = (float(band[0]), float(band[1]))
        self._tip = lay.tip_site
        self._tip_axes = list(lay.plane_axes)
        self._body_ids = ([mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, b.name) for b in self.params.bodies]
                          if self.params is not None else list(range(1, m.nbody)))
        if self.params is not None and (list(m.M_rownnz) != [1, 2, 3, 4, 5]
                                        or list(m.M_colind) != [c for r in range(5) for c in range(r + 1)]):
            raise ParameterError("the mass matrix must be dense 5x5 (a planar chain of 5 dofs)")
        names = list(lay.thruster_names)
        self.failures = tuple(failures)
        for f in self.failures:
            if f.thruster not in names:
                import difflib

                close = difflib.get_close_matches(str(f.thruster), names, n=1, cutoff=0.6)
                hint = f" (did you mean {close[0]!r}?)" if close else ""
                raise ParameterError(f"failure of thruster {f.thruster!r}: no thruster of that name{hint}; "
                                     f"thrusters: {', '.join(names) or 'none'}")
            if not (math.isfinite(f.t) and f.t >= 0):
                raise ParameterError(f"failure of thruster {f.thruster!r} at t = {f.t!r}: t must be finite and >= 0 s")
        self._forcerange0 = m.actuator_forcerange.copy()
        self._forcelimited0 = m.actuator_forcelimited.copy()

        self._diverged: tuple[float, str] | None = None
        self._serving: dict[int, _pyb.Served] = {}  # Python backend: mjData address -> its server
        if not native:
            self._serve(self.data)
        #: The waves at the vehicle (logged signals, the free-surface check).
        self.sea = SeaMonitor(m, lay.base_body)
        self.reset()

    # ---------------------------------------------------------------- hydrodynamics hook

    def _configure_mujoco_drag(self, on: bool) -> None:
        """MuJoCo's ellipsoid model as the drag (the paper robot's model mismatch): density on,
        its virtual mass/inertia zeroed (added mass is ours, exact; MuJoCo would add only its
        velocity terms). Off: MuJoCo's fluid model off (density and viscosity 0)."""
        m = self.model
        if on:
            robot_geoms = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, b.name) for b in self.params.bodies]
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

    def reset(self, keyframe: Any = _RESET_TO_INITIAL) -> None:
        """Reset time, state, thruster activations and scheduled events: to the plant's
        :attr:`initial` state (default), to ``qpos0`` (``keyframe=None``) or to a named model
        keyframe.

        Raises:
            ParameterError: no keyframe of that name; a reset after the payload was picked up."""
        m, d = self.model, self.data
        if getattr(self, "_picked", False):
            raise ParameterError("reset after the payload was picked up: create a new Plant")
        self._picked = False
        self._failed: set[str] = set()
        self.__dict__.pop("_motor_clamps", None)  # Actuation.joint_torques_applied reads the ranges again
        if not np.array_equal(m.actuator_forcerange, self._forcerange0):  # a failure happened: undo it
            m.actuator_forcerange[:] = self._forcerange0
            m.actuator_forcelimited[:] = self._forcelimited0
            self._thr_lo, self._thr_hi = (m.actuator_forcerange[self._thr].T.copy() if len(self._thr)
                                          else (np.zeros(0), np.zeros(0)))
            self.__dict__.pop("_io", None)
        if keyframe is _RESET_TO_INITIAL:
            self.initial.apply(m, d, self.layout)
        elif keyframe is None:
            mujoco.mj_resetData(m, d)
        else:
            k = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, keyframe)
            if k < 0:
                raise ParameterError(f"model has no keyframe named {keyframe!r}")
            mujoco.mj_resetDataKeyframe(m, d, k)
        if self.tether is not None:
            self.tether.place(m, d)
        d.time = 0.0
        self._diverged = None
        served = self._serving.get(d._address)
        if served is not None:
            served.reset(float(d.time))
        mujoco.mj_forward(m, d)
        try:
            self.sea.check_initial(d.qpos)
        except SurfaceError as exc:
            raise ParameterError(str(exc)) from None

    @property
    def has_sea_signals(self) -> bool:
        """Whether :meth:`sea_signals` gives any signal (waves or a tether; else it is always empty)."""
        return self.sea.on or self.tether is not None

    def sea_signals(self) -> dict:
        """The waves at the vehicle now (``wave_elevation``, ``wave_velocity``; empty without
        waves), for the sampled loop's log (:mod:`uvms_mj.plant.sea`); with a tether also
        ``tether_pull``: its force on the vehicle, world [N] (:func:`uvms_mj.plant.tether.tether_pull`,
        the constraint force of the last step's evaluation)."""
        out = self.sea.signals(float(self.data.time), self.data.qpos)
        if self.tether is not None:
            out["tether_pull"] = tether_pull(self.model, self.data)
        return out

    def on_sample(self, t: float) -> None:
        """Called by the sampled loop at every control sample (time t [s]): the scheduled events
        (the payload's pick-up, thruster failures)."""
        if self.payload is not None and not self._picked and t >= self.payload.t - 1e-12:
            self.payload.apply(self.model)
            self._picked = True
            mujoco.mj_forward(self.model, self.data)
        for f in self.failures:
            if f.thruster not in self._failed and t >= f.t - 1e-12:
                self._fail(f.thruster)

    def _fail(self, name: str) -> None:
        m = self.model
        a = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, name)
        m.actuator_forcerange[a] = (0.0, 0.0)
        m.actuator_forcelimited[a] = 1
        k = list(self._thr).index(a)
        self._thr_lo[k] = self._thr_hi[k] = 0.0
        self._failed.add(name)
        self.__dict__.pop("_io", None)  # the compiled sample copies the limits: rebuild it
        self.__dict__.pop("_motor_clamps", None)

    def set_state(
        self,
        base_pose: Sequence[float] | None = None,
        joint_angles: Sequence[float] | None = None,
        base_velocity: Sequence[float] | None = None,
        joint_velocities: Sequence[float] | None = None,
        *,
        qpos: Sequence[float] | None = None,
        qvel: Sequence[float] | None = None,
    ) -> None:
        """Set (parts of) the state and recompute derived quantities (``mj_forward``).

        ``qpos`` / ``qvel``: the whole of MuJoCo's (module docstring), applied first; then
        base_pose: the base's qpos (planar: (p0x, p0y, phi0) world [m, m, rad]; free: (x, y, z,
        qw, qx, qy, qz)); joint_angles: the arm joints' [rad]; base_velocity: the base's qvel
        (planar: world; free: linear world, angular body); joint_velocities: the arm's rates.

        Raises:
            ValueError: a part of the wrong size or not finite.
        """
        d, lay = self.data, self.layout
        nb = lay.base_nq
        for name, val, arr, idx in (
            ("qpos", qpos, d.qpos, slice(None)),
            ("qvel", qvel, d.qvel, slice(None)),
            ("base_pose", base_pose, d.qpos, slice(lay.base_qadr, lay.base_qadr + nb)),
            ("joint_angles", joint_angles, d.qpos, lay.joint_qadr),
            ("base_velocity", base_velocity, d.qvel, slice(lay.base_dadr, lay.base_dadr + lay.base_dofs.size)),
            ("joint_velocities", joint_velocities, d.qvel, lay.joint_dadr),
        ):
            if val is None:
                continue
            n = arr[idx].size
            v = np.asarray(val, dtype=float).ravel()
            if v.shape != (n,) or not np.all(np.isfinite(v)):
                raise ValueError(f"{name} = {val!r} must be {n} finite numbers")
            arr[idx] = v
        mujoco.mj_forward(self.model, d)

    @property
    def time(self) -> float:
        """Simulation time [s]."""
        return float(self.data.time)

    @property
    def q(self) -> np.ndarray:
        """Generalized coordinates ``qpos`` (copy; module docstring; the robot's only, without a
        tether's): the paper's (p0x, p0y, phi0, phi1, phi2) [m, m, rad, rad, rad]."""
        return self.data.qpos[:self._nq].copy()

    @property
    def qd(self) -> np.ndarray:
        """Generalized velocities ``qvel`` (copy): base velocity (planar: world; free: linear
        world, angular body), joint rates (the robot's only, without a tether's)."""
        return self.data.qvel[:self._nv].copy()

    @property
    def base_pose(self) -> np.ndarray:
        """The base's qpos (copy): planar (p0x, p0y, phi0) world [m, m, rad]; free (x, y, z [m]
        world, qw, qx, qy, qz)."""
        a = self.layout.base_qadr
        return self.data.qpos[a:a + self.layout.base_nq].copy()

    @property
    def joint_angles(self) -> np.ndarray:
        """Arm joint angles [rad] in :attr:`Layout.joint_names` order (copy): the paper's
        (phi1, phi2), relative angles."""
        return self.data.qpos[self.layout.joint_qadr].copy()

    @property
    def tip_position(self) -> np.ndarray:
        """End-effector site position, world [m], along :attr:`Layout.plane_axes` (the paper's:
        (x, y); a free vehicle's: (x, y, z)); NaN when the robot has no tip site.

        Computed from ``data.qpos`` (on a scratch MjData): after ``mj_step`` MuJoCo's own
        ``site_xpos`` still holds the start of the step (Euler) or an intermediate RK4 stage."""
        if self._tip < 0:
            return np.full(len(self._tip_axes), np.nan)
        s = self._scratch
        s.qpos[:] = self.data.qpos
        mujoco.mj_kinematics(self.model, s)
        return s.site_xpos[self._tip, self._tip_axes]
