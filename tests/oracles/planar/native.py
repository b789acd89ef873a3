"""C port of the planar closed form :meth:`uvms_mj.planar.hydro.HydroModel.evaluate` (``_native/hydro.c``).

Used by the controller's planar nominal model (:mod:`uvms_mj.planar.nominal`) for speed; the plant's
hydrodynamics are the MuJoCo plugins of :mod:`uvms_mj.physics` (any robot). ``hydro.c`` has the
same order of floating-point operations as the Python closed form and matches it to rounding.

The library is compiled on first use by :func:`uvms_mj.physics.build.compile_library` (the
system C compiler, the same cache folder and atomic rename as the plugins). With
``UVMS_MJ_COMPILED=off`` (:func:`uvms_mj.physics.build.compiled_mode`), or where it cannot be
built (under ``auto``), the nominal model runs the Python closed form.
"""

from __future__ import annotations

import ctypes
import threading
from pathlib import Path
from typing import TYPE_CHECKING

from uvms_mj.physics import build as _build

if TYPE_CHECKING:
    from oracles.planar.hydro import HydroModel

from uvms_mj.physics.terms import BACKENDS  # noqa: F401
#: The native evaluator's C source.
NATIVE_SOURCE = Path(__file__).resolve().parent / "_native" / "hydro.c"

# Must match hydro.c.
NV = 5
NM = 15
MAXBODY = 3
NB = 16


class NativeUnavailableError(RuntimeError):
    """The native evaluator cannot be built or loaded."""


class Params(ctypes.Structure):
    """Mirror of ``uvms_params`` in hydro.c (the constants of one model)."""

    _fields_ = [
        ("bodies", ctypes.c_double * (MAXBODY * NB)),  # HydroModel._bodies, flattened
        ("nbody", ctypes.c_int),
        ("exact", ctypes.c_int),
        ("strip", ctypes.c_int),
        ("buoyancy", ctypes.c_int),
    ]


def make_params(hydro: HydroModel) -> Params:
    """The native parameters of a :class:`HydroModel` (its constants and terms).
    ``added_mass="lagged"`` has no native form."""
    terms = hydro.terms
    if terms.added_mass == "lagged":
        raise ValueError("added_mass='lagged' has no native implementation (use the Python closed form)")
    bodies = hydro._bodies
    if not (1 <= len(bodies) <= MAXBODY) or any(len(b) != NB for b in bodies):
        raise ValueError(f"the native evaluator serves chains of up to {MAXBODY} bodies of {NB} constants")
    p = Params()
    for i, body in enumerate(bodies):
        p.bodies[i * NB : (i + 1) * NB] = [float(v) for v in body]
    p.nbody = len(bodies)
    p.exact = terms.added_mass == "exact"
    p.strip = terms.drag == "strip"
    p.buoyancy = bool(terms.buoyancy)
    return p


class NativeLib:
    """The loaded library with typed entry points."""

    def __init__(self, path: Path) -> None:
        self.path = path
        lib = ctypes.CDLL(str(path))
        self._lib = lib
        dp = ctypes.POINTER(ctypes.c_double)
        lib.uvms_params_layout.argtypes = [ctypes.POINTER(ctypes.c_size_t)]
        lib.uvms_params_layout.restype = None
        lib.uvms_evaluate.argtypes = [ctypes.POINTER(Params), dp, dp, dp, dp, dp, dp]
        lib.uvms_evaluate.restype = None
        lib.uvms_strip_integrals.argtypes = [ctypes.c_double] * 4 + [dp, dp]
        lib.uvms_strip_integrals.restype = None
        out = (ctypes.c_size_t * 4)()
        lib.uvms_params_layout(out)
        mine = [ctypes.sizeof(Params)] + [getattr(Params, f).offset for f in ("nbody", "exact", "buoyancy")]
        if list(out) != mine:
            raise NativeUnavailableError(f"uvms_params layout mismatch between hydro.c {list(out)} and ctypes {mine}")

    def evaluate(self, params: Params, q, qd, wind=(0.0, 0.0), gravity=(0.0, -9.81),
                 want_mass: bool = True) -> tuple[list[float], list[float]]:
        """Same contract as :meth:`HydroModel.evaluate` (``m_add`` lower triangle, 15 or empty;
        ``qfrc``, 5), computed by the C code."""
        arr = ctypes.c_double * NV
        m_add = (ctypes.c_double * NM)()
        qfrc = arr()
        with_mass = bool(want_mass and params.exact)
        self._lib.uvms_evaluate(
            ctypes.byref(params),
            arr(*[float(v) for v in q[:NV]]),
            arr(*[float(v) for v in qd[:NV]]),
            (ctypes.c_double * 2)(*[float(v) for v in wind[:2]]),
            (ctypes.c_double * 2)(*[float(v) for v in gravity[:2]]),
            m_add if with_mass else None,
            qfrc,
        )
        return (list(m_add) if with_mass else []), list(qfrc)

    def strip_integrals(self, w0: float, om: float, a: float, b: float) -> tuple[float, float]:
        """Same as :func:`uvms_mj.planar.hydro.strip_integrals`, computed by the C code."""
        i0, i1 = ctypes.c_double(), ctypes.c_double()
        self._lib.uvms_strip_integrals(w0, om, a, b, ctypes.byref(i0), ctypes.byref(i1))
        return i0.value, i1.value


_lock = threading.Lock()
_lib: NativeLib | None = None
_error: str | None = None
_tried = False


def build_native(force: bool = False) -> Path:
    """Compile hydro.c into the cache (if not there yet) and return the library's path.

    Raises:
        NativeUnavailableError: no compiler, or the compilation failed."""
    try:
        return _build.compile_library("nominal", [NATIVE_SOURCE], force=force)
    except _build.PluginUnavailableError as exc:
        raise NativeUnavailableError(str(exc)) from None


def load_native() -> NativeLib | None:
    """The native library (built on first use), or None if it cannot be built or loaded
    (:func:`native_unavailable_reason` says why). Cached for the process."""
    global _lib, _error, _tried
    with _lock:
        if _tried:
            return _lib
        _tried = True
        try:
            try:
                _lib = NativeLib(build_native())
            except OSError:  # a damaged cache file: rebuild once
                _lib = NativeLib(build_native(force=True))
        except (NativeUnavailableError, OSError) as exc:
            _lib, _error = None, str(exc)
        return _lib


def native_unavailable_reason() -> str | None:
    """Why :func:`load_native` returned None (None if it has not been tried or succeeded)."""
    return _error
