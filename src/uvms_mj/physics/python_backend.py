"""The numpy reference hydrodynamics served through MuJoCo's ``mjcb_passive`` (no C compiler).

Where the uvms plugin library cannot be built, :func:`uvms_mj.physics.model.load_spec` strips
the plugins from the model (and where it can, but the Python backend is asked for,
:func:`~uvms_mj.physics.model.compile_spec` compiles them with every term off); this module
applies :func:`uvms_mj.physics.reference.passive` instead, at the same point of MuJoCo's pipeline (the passive stage, after ``mj_makeM`` /
``mj_factorM``, before the acceleration solve), so every integrator honours it:

* the added-mass matrix is added to ``d.M`` (MuJoCo's sparse lower triangle), then
  ``mj_factorM`` (and ``mj_projectConstraint`` when there are constraint rows);
* the generalized forces of every other term are added to ``d.qfrc_passive``.

``mjcb_passive`` is process-global. A plain Python callable would be wrapped by the bindings,
which abort with "Python exception raised" for every model they do not know (compilation runs
the passive stage on a temporary model); a ctypes function is installed instead, and it
dispatches on the mjData address to the handler that serves it; every other model and data is
left untouched. While any data is served, every model's passive stage calls into Python (which
also serialises multi-threaded rollouts on the GIL); the callback is removed when nothing is
served any more. The Gauss-Markov current is advanced by :meth:`Served.advance`, which the owner
(the :class:`uvms_mj.plant.plant.Plant`) calls after every ``mj_step``; plain ``mj_step`` on such data
keeps the current of the last sample.
"""

from __future__ import annotations

import ctypes
import threading
import warnings
import weakref
from typing import Callable

import mujoco
import numpy as np

from uvms_mj.physics import reference
from uvms_mj.physics.model import HydroInfo

_PASSIVE_CFUNC = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_void_p)
_HANDLERS: dict[int, Callable[[], None]] = {}  # mjData address -> handler
_FAILURES: dict[int, BaseException] = {}  # mjData address -> first exception of its handler
_LOCK = threading.RLock()


def _dispatch(m_ptr: int | None, d_ptr: int | None) -> None:
    handler = _HANDLERS.get(d_ptr)  # type: ignore[arg-type]
    if handler is not None:
        try:
            handler()
        except BaseException as exc:  # noqa: BLE001 - ctypes would print and swallow it
            _FAILURES.setdefault(d_ptr, exc)  # type: ignore[arg-type]


_C_DISPATCH = _PASSIVE_CFUNC(_dispatch)


def _install() -> None:
    current = mujoco.get_mjcb_passive()
    if current is _C_DISPATCH:
        return
    if current is not None:
        warnings.warn(f"replacing an existing mjcb_passive callback ({current!r}): the uvms_mj Python "
                      "hydrodynamics need it; other models are left untouched", RuntimeWarning, stacklevel=3)
    mujoco.set_mjcb_passive(_C_DISPATCH)


def failure(d: mujoco.MjData) -> BaseException | None:
    """The first exception raised while serving ``d`` (then forgotten), or None."""
    return _FAILURES.pop(d._address, None)


def _unregister(addr: int) -> None:
    # Runs from the garbage collector at any point: no lock (single dict operations are atomic).
    _HANDLERS.pop(addr, None)
    _FAILURES.pop(addr, None)
    if not _HANDLERS and mujoco.get_mjcb_passive() is _C_DISPATCH:
        # Nothing left to serve: stop calling into Python from every passive stage of every
        # model (which would also serialise multi-threaded rollouts on the GIL).
        mujoco.set_mjcb_passive(None)


def csr_indices(m: mujoco.MjModel) -> tuple[np.ndarray, np.ndarray]:
    """(rows, cols) of each entry of MuJoCo's sparse mass matrix ``d.M`` (lower triangle)."""
    rows = np.repeat(np.arange(m.nv), m.M_rownnz)
    return rows, np.asarray(m.M_colind).copy()


class Served:
    """The Python hydrodynamics of one MjData.

    Args:
        m, d: the (stripped) model and its data.
        info: the model's parameters (:func:`uvms_mj.physics.model.hydro_of`).
        lagged: apply the added-mass matrix as -M_A times the previous acceleration instead of
            putting it in ``d.M`` (the explicit scheme of several peer simulators; kept only to
            show that it diverges).
    """

    def __init__(self, m: mujoco.MjModel, d: mujoco.MjData, info: HydroInfo, *, lagged: bool = False) -> None:
        self.info = info
        self.lagged = lagged
        self._rows, self._cols = csr_indices(m)
        self._augmented: np.ndarray | None = None
        self._h = float(m.opt.timestep)
        self.current_state = reference.initial_current_state(info.water, float(d.time), self._h)
        mref, dref = weakref.ref(m), weakref.ref(d)
        water, bodies = info.water, info.bodies
        am_on = "added_mass" in water.terms
        rows, cols = self._rows, self._cols

        def passive() -> None:
            mm, dd = mref(), dref()
            if mm is None or dd is None:
                return
            madd, qfrc = reference.passive(mm, dd, water, bodies, self.current_state)
            if am_on:
                if self.lagged:
                    qfrc = qfrc - madd @ dd.qacc
                elif self._augmented is None or not np.array_equal(dd.M, self._augmented):
                    # mj_forwardSkip re-enters with d.M already augmented: add only to a fresh M.
                    dd.M[:] += madd[rows, cols]
                    mujoco.mj_factorM(mm, dd)
                    if dd.nefc:
                        mujoco.mj_projectConstraint(mm, dd)
                    self._augmented = dd.M.copy()
            dd.qfrc_passive[:] += qfrc

        with _LOCK:
            _install()
            _HANDLERS[d._address] = passive
        weakref.finalize(d, _unregister, d._address)

    def reset(self, time: float = 0.0) -> None:
        """Restart the current process at ``time`` (as MuJoCo's reset does for the C plugin)."""
        self.current_state = reference.initial_current_state(self.info.water, time, self._h)
        self._augmented = None

    def advance(self, time: float) -> None:
        """After a step to ``time``: move the Gauss-Markov current to its next sample if due."""
        self.current_state = reference.advance_current_state(self.info.water, self.current_state, time, self._h)
