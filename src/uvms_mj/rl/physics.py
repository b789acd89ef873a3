"""The dm_control Physics over a uvms_mj plant, and the controller's measurement, for
:mod:`uvms_mj.rl.env` (``pip install 'uvms-mj[rl]'``)."""

from __future__ import annotations

import copy

import mujoco
import numpy as np

try:  # dm-control is an extra: `pip install 'uvms-mj[rl]'` (the rest of uvms_mj does not need it)
    from dm_control import mujoco as dm_mujoco
    from dm_control.mujoco import wrapper
except ImportError as exc:  # pragma: no cover - exercised only without the extra
    raise ImportError(f"uvms_mj.rl.physics needs dm-control ({exc}): pip install 'uvms-mj[rl]'") from None

from uvms_mj.control.base import Measurement
from uvms_mj.plant.plant import DivergenceError, Plant
from uvms_mj.sim.loop import SensorModel, measure_robot
from uvms_mj.sim.sensors import SignalSensors

__all__ = ["Physics", "Sensor"]


# --------------------------------------------------------------------------- physics


class Physics(dm_mujoco.Physics):
    """A dm_control Physics over a :class:`~uvms_mj.plant.plant.Plant`'s own data.

    It wraps ``plant.data`` (served by the plant's hydrodynamics) and steps it with
    ``plant.step`` (``mj_step`` each physics step, for every integrator, exactly the plant's
    stepping; dm_control's ``legacy_step`` only adds an ``mj_step1`` afterwards to bring the
    position- and velocity-dependent fields up to date, which does not change the state).

    A divergence (:class:`~uvms_mj.plant.plant.DivergenceError`) does not raise: it is kept in
    :attr:`divergence`, further steps do nothing, and :meth:`reset` (or ``plant.reset()``
    followed by ``physics.divergence = None``) clears it. :meth:`copy` returns a physics over a
    copy of the data, registered with the plant (hydrodynamics included; its divergence is then
    only MuJoCo's own warnings, raised as ``PhysicsError``).
    """

    _plant: Plant
    divergence: DivergenceError | None

    def __init__(self, plant: Plant) -> None:
        if not isinstance(plant, Plant):
            raise TypeError(f"Physics expects a uvms_mj Plant, got {type(plant).__name__}")
        self._plant = plant
        self.divergence = None
        m = plant.model
        # a payload picked up during an episode (uvms_mj.plant.robot.Payload.apply changes these
        # fields of the model only): restored by drop_payload for the next episode
        self._payload0 = ((m.body_mass.copy(), m.body_inertia.copy(), m.body_subtreemass.copy())
                          if getattr(plant, "payload", None) is not None else None)
        super().__init__(wrapper.MjData(plant.data))

    def drop_payload(self) -> None:
        """Undo a payload's pick-up (the model as before it), so that the plant can be reset
        (:meth:`uvms_mj.plant.plant.Plant.reset` refuses to after a pick-up)."""
        if self._payload0 is not None and getattr(self._plant, "_picked", False):
            m = self._plant.model
            m.body_mass[:], m.body_inertia[:], m.body_subtreemass[:] = self._payload0
            self._plant._picked = False

    @property
    def plant(self) -> Plant:
        """The plant whose model (and hydrodynamics) this physics runs."""
        return self._plant

    @property
    def owns_plant_data(self) -> bool:
        """Whether this physics runs ``plant.data`` itself (False for copies)."""
        return self.data.ptr is self._plant.data

    def step(self, nstep: int = 1) -> None:
        if self.divergence is not None:
            return
        m, d = self.model.ptr, self.data.ptr
        if self.owns_plant_data:
            try:
                self._plant.step(nstep)  # checks MuJoCo's warnings itself
            except DivergenceError as exc:
                self.divergence = exc
                return
        else:
            with self.check_invalid_state():
                mujoco.mj_step(m, d, nstep)
        if self.legacy_step:
            mujoco.mj_step1(m, d)

    def reset(self, keyframe_id: int | None = None) -> None:
        self.divergence = None
        if self.owns_plant_data:
            self.drop_payload()
            self._plant.reset()  # its initial state (not qpos0: a wave scenario checks the depth); clears its divergence
        super().reset(keyframe_id)

    def copy(self, share_model: bool = True) -> "Physics":
        """A physics over a copy of the data (same model, registered with the plant).

        Raises:
            ValueError: ``share_model=False``: the hydrodynamics are installed on the plant's
                model, a copied model would run without them.
        """
        if not share_model:
            raise ValueError("uvms_mj Physics.copy needs share_model=True: the hydrodynamics are served "
                             "for the plant's own model only")
        new_data = self._plant.attach_data(copy.copy(self.data.ptr))
        new = Physics.__new__(Physics)
        new._plant = self._plant
        new._payload0 = self._payload0
        new.divergence = self.divergence
        new._warnings_cause_exception = True
        new._reload_from_data(wrapper.MjData(new_data))
        new.legacy_step = self.legacy_step
        return new

    def _make_rendering_contexts(self) -> None:
        """dm_control's contexts, with the OpenGL backend chosen now that rendering starts: on
        Linux without a display and ``MUJOCO_GL`` unset, EGL (else OSMesa) instead of the GLFW
        default dm_control took (:func:`uvms_mj.analysis.render_gl.dm_control_context_class`)."""
        from dm_control import _render

        from uvms_mj.analysis.render_gl import dm_control_context_class

        default, _render.Renderer = _render.Renderer, dm_control_context_class()
        try:
            super()._make_rendering_contexts()
        finally:
            _render.Renderer = default

    def __getstate__(self):  # noqa: D105
        raise TypeError("a uvms_mj Physics cannot be pickled (it lives on its plant, whose hydrodynamics it shares)")


# --------------------------------------------------------------------------- sensor


class Sensor:
    """The measurement of :func:`uvms_mj.sim.loop.run_closed_loop` (same draws in the same order):
    the per-signal sensors, a free vehicle's :func:`~uvms_mj.sim.loop.measure_robot`, or the planar
    base's model, each followed by the one-sample delay where configured."""

    def __init__(self, model: SensorModel, seed: int, T: float, plant: Plant) -> None:
        self.model, self.plant, self.T = model, plant, T
        self.layout = plant.layout
        self.rng = np.random.default_rng(seed)
        self.per_signal = SignalSensors(model.signals, T, seed, self.layout) if model.signals else None
        self.q_prev: np.ndarray | None = None
        att = model.angle_noise if model.attitude_noise is None else model.attitude_noise
        joint = model.angle_noise if model.joint_noise is None else model.joint_noise
        self.angle_std = np.array([att, joint, joint], dtype=float)
        self.noisy = bool(model.position_noise or att or joint)

    def measure(self, k: int, q: np.ndarray, qd: np.ndarray) -> Measurement:
        s, rng = self.model, self.rng
        if self.per_signal is not None:
            q, qd_meas = self.per_signal.measure(k, q, qd)
            return Measurement(k=k, t=k * self.T, q=q, qd=qd_meas)
        if self.layout.base_free:
            q, qd_meas = measure_robot(self.plant, self.layout, s, rng, q, qd)
        else:  # the planar base (the paper's): (p0x, p0y, phi0, phi1, phi2)
            if self.noisy:
                q = q + np.concatenate((rng.normal(0, s.position_noise, 2), rng.normal(0, self.angle_std)))
            if s.position_quantum or s.angle_quantum:
                q = np.concatenate((_quantize(q[:2], s.position_quantum), _quantize(q[2:], s.angle_quantum)))
            qd_meas = None
            if s.velocity_sensor:
                qd_meas = qd + (rng.normal(0, s.velocity_noise, qd.size) if s.velocity_noise else 0.0)
        if s.delay:
            q_out = q if self.q_prev is None else self.q_prev
            self.q_prev = q
            q = q_out
        return Measurement(k=k, t=k * self.T, q=q, qd=qd_meas)


def _quantize(x: np.ndarray, quantum: float) -> np.ndarray:
    return np.round(x / quantum) * quantum if quantum > 0 else x
