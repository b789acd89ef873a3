"""What every plant does around ``mj_step``: batched stepping with exact divergence reports,
MuJoCo's warnings routed to the run's metadata, the energy and the mass matrix.

:class:`Stepping` is the part of :class:`uvms_mj.plant.plant.Plant` that does not depend on the
robot's layout: it needs ``model``, ``data``, ``_scratch``, ``max_speed``, ``_diverged``,
``_serving`` (the Python backend's served MjData), ``hydro_info``, ``terms``, ``_body_ids``
and ``_io_layout()`` from the plant.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from uvms_mj.physics import model as _pm
from uvms_mj.physics import python_backend as _pyb
from uvms_mj.physics import reference as _ref
from uvms_mj.physics.mjwarnings import install_mujoco_warning_handler, mujoco_warnings  # noqa: F401  (re-exported)

__all__ = ["DivergenceError", "Energy", "Stepping", "install_mujoco_warning_handler", "mujoco_warnings"]


def _finite(x: np.ndarray) -> bool:
    """Every entry of a small float array finite (cheaper than numpy's all(isfinite) here)."""
    return all(map(math.isfinite, x.ravel().tolist()))


#: What :meth:`Plant.step` saves before a batch of steps (restored for an exact replay).
_SNAPSHOT = mujoco.mjtState.mjSTATE_INTEGRATION



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


class Stepping:
    """Stepping, divergence detection and diagnostics of a plant (module docstring)."""

    _snapshot: np.ndarray | None = None  # Plant.step's saved state (per instance once used)

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
        fn = plant_io.plant_io_library()
        if fn is None:
            return None
        m = self.model
        if self._snapshot is None:
            self._snapshot = np.empty(mujoco.mj_stateSize(m, _SNAPSHOT))
        tip_site, ntip, thr_act, lo, hi = self._io_layout()
        io = self._io = plant_io.PlantIO(fn, m, self.data, self._scratch, self._snapshot, int(_SNAPSHOT), tip_site,
                                         ntip, () if thr_act is None else thr_act, () if lo is None else lo,
                                         () if hi is None else hi,
                                         (getattr(self, "_nq", m.nq), getattr(self, "_nv", m.nv)))
        return io

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
        """Full nv x nv generalized mass matrix at the current state, added mass included."""
        mujoco.mj_forward(self.model, self.data)
        out = np.zeros((self.model.nv, self.model.nv))
        mujoco.mj_fullM(self.model, self.data, out)
        return out
