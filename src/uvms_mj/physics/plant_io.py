"""One control sample of a plant's input and output, compiled (``plant_io.c``).

:meth:`uvms_mj.plant.plant.Plant.step_observe` (n steps, the divergence checks, the new state) runs
through :func:`plant_io_library` when it can: the same steps and numbers as its Python code (the
reference, used with ``UVMS_MJ_COMPILED=off``, without a C compiler or on the Python hydrodynamics
backend), in one call instead of a dozen numpy and MuJoCo calls. Built and loaded like the RAC
kernel (:mod:`uvms_mj.control.kernel`), by :class:`uvms_mj.physics.build.CompiledOnce`.
"""

from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np

from uvms_mj.physics import build

#: The compiled sample's C source.
PLANT_IO_SOURCE = Path(__file__).resolve().parent / "plant_io.c"


def _configure(lib: ctypes.CDLL):
    fn = lib.uvms_plant_step_observe
    fn.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.c_double]
    fn.restype = ctypes.c_int
    return fn


_LOADER = build.CompiledOnce("uvms_plant_io", [PLANT_IO_SOURCE], "the compiled plant sample", _configure)


def plant_io_library():
    """The compiled ``uvms_plant_step_observe`` (ctypes function), or None
    (:func:`plant_io_unavailable_reason`)."""
    return _LOADER.get()


def plant_io_unavailable_reason() -> str | None:
    """Why :func:`plant_io_library` returned None (None if it was not tried or is loaded)."""
    return _LOADER.reason


class _Struct(ctypes.Structure):
    """``uvms_plant_io`` of plant_io.c (same fields, same order)."""

    _fields_ = [("m", ctypes.c_void_p), ("d", ctypes.c_void_p), ("scratch", ctypes.c_void_p),
                ("snap", ctypes.c_void_p), ("snap_spec", ctypes.c_int), ("tip_site", ctypes.c_int),
                ("ntip", ctypes.c_int), ("nthr", ctypes.c_int), ("thr_act", ctypes.c_void_p), ("lo", ctypes.c_void_p),
                ("hi", ctypes.c_void_p), ("out", ctypes.c_void_p)]


class PlantIO:
    """The arrays of one plant that the compiled sample reads and writes: ``tip_site`` and
    ``ntip`` (0: no tip readout); ``thr_act``, ``lo``, ``hi``: the thrusters' lag states and
    force ranges (empty: no thrust readout); ``robot``: (nq, nv) of the robot's part of the state
    that q and qd are read from (a prefix: without a tether's coordinates; None: all)."""

    def __init__(self, fn, model, data, scratch, snapshot: np.ndarray, snap_spec: int, tip_site: int, ntip: int,
                 thr_act=(), lo=(), hi=(), robot: tuple[int, int] | None = None) -> None:
        self.fn, self.model, self.data, self.scratch = fn, model, data, scratch
        self.thr_act = np.ascontiguousarray(thr_act if len(thr_act) else [0], dtype=np.intc)
        self.lo = np.ascontiguousarray(lo if len(lo) else [0.0], dtype=float)
        self.hi = np.ascontiguousarray(hi if len(hi) else [0.0], dtype=float)
        self.nthr = len(thr_act)
        self.nq, self.nv, self.ntip = model.nq, model.nv, ntip
        self.out = np.zeros(self.nq + self.nv + ntip + self.nthr)
        nq, nv = self.nq, self.nv
        #: where q, qd, the tip and the thrusts are in :attr:`out` (None: not read here)
        rq, rv = robot if robot is not None else (nq, nv)
        self.slices = (slice(0, rq), slice(nq, nq + rv), slice(nq + nv, nq + nv + ntip) if ntip else None,
                       slice(nq + nv + ntip, nq + nv + ntip + self.nthr) if self.nthr else None)
        self.snapshot = snapshot
        self._struct = _Struct(model._address, data._address, scratch._address, snapshot.ctypes.data, int(snap_spec),
                               int(tip_site), int(ntip), self.nthr, self.thr_act.ctypes.data, self.lo.ctypes.data,
                               self.hi.ctypes.data, self.out.ctypes.data)
        self._ptr = ctypes.addressof(self._struct)

    def run(self, n: int, max_speed: float) -> int:
        """n steps and the readout: 0 (the new state in :attr:`out`), 1 (replay from
        :attr:`snapshot`) or 2 (the state was bad before: nothing done)."""
        return self.fn(self._ptr, n, max_speed)
