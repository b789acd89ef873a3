"""Native (C) backend of the plant's hydrodynamics: build, load and bind ``_native/hydro.c``.

``hydro.c`` is a line-by-line C port of :meth:`uvms_mj.hydro.HydroModel.evaluate` (the pure-Python
reference, which stays the ground truth and the fallback) plus a MuJoCo ``mjcb_passive``
callback, ``uvms_passive``, that applies it to registered ``mjData`` without entering Python.

The library is compiled on first use with the system C compiler (``$CC``, else ``cc``, ``gcc`` or
``clang``) against the headers and the ``libmujoco`` shipped in the mujoco wheel, into a cache
folder: ``$UVMS_MJ_CACHE``, else ``$XDG_CACHE_HOME/uvms_mj``, else ``~/.cache/uvms_mj``. The file
name carries a hash of the C source, the mujoco version and library, the platform and the
compiler command, so a change of any of them rebuilds; the build goes to a temporary file that
is renamed into place, so parallel processes are safe.

Backend choice (``Plant(backend=...)``, default from the environment variable
``UVMS_MJ_BACKEND``): ``"auto"`` (default; native when it can be built, else Python with a
one-time warning), ``"native"`` (an error if it cannot be built) or ``"python"``.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import shlex
import shutil
import subprocess
import sys
import sysconfig
import tempfile
import threading
import warnings
from pathlib import Path
from typing import TYPE_CHECKING

import mujoco

if TYPE_CHECKING:
    from .hydro import HydroModel

BACKENDS = ("auto", "python", "native")
ENV_BACKEND = "UVMS_MJ_BACKEND"
ENV_CACHE = "UVMS_MJ_CACHE"
SOURCE = Path(__file__).resolve().parent / "_native" / "hydro.c"

# Must match hydro.c.
NV = 5
NM = 15
MAXBODY = 3
NB = 16
STATUS_OK, STATUS_RUNAWAY, STATUS_NONFINITE = 0, 1, 2

CFLAGS = ("-O2", "-shared", "-fPIC", "-ffp-contract=off")  # no FMA contraction: bit-compatible maths


class NativeUnavailableError(RuntimeError):
    """The native backend was requested but cannot be built or loaded."""


class Params(ctypes.Structure):
    """Mirror of ``uvms_params`` in hydro.c (parameters and callback state of one mjData)."""

    _fields_ = [
        ("bodies", ctypes.c_double * (MAXBODY * NB)),  # HydroModel._bodies, flattened
        ("nbody", ctypes.c_int),
        ("exact", ctypes.c_int),
        ("strip", ctypes.c_int),
        ("buoyancy", ctypes.c_int),
        ("max_speed", ctypes.c_double),
        ("augmented_valid", ctypes.c_int),
        ("augmented", ctypes.c_double),
        ("status", ctypes.c_int),
        ("status_time", ctypes.c_double),
        ("status_speed", ctypes.c_double),
    ]


def make_params(hydro: HydroModel, max_speed: float = float("inf")) -> Params:
    """The native parameters of a :class:`HydroModel` (its constants and terms) and a runaway
    threshold. ``added_mass="lagged"`` has no native form (it is a Python-only demonstration)."""
    terms = hydro.terms
    if terms.added_mass == "lagged":
        raise ValueError("added_mass='lagged' has no native implementation (use the Python backend)")
    bodies = hydro._bodies
    if not (1 <= len(bodies) <= MAXBODY) or any(len(b) != NB for b in bodies):
        raise ValueError(f"the native backend serves chains of up to {MAXBODY} bodies of {NB} constants")
    p = Params()
    for i, body in enumerate(bodies):
        p.bodies[i * NB : (i + 1) * NB] = [float(v) for v in body]
    p.nbody = len(bodies)
    p.exact = terms.added_mass == "exact"
    p.strip = terms.drag == "strip"
    p.buoyancy = bool(terms.buoyancy)
    p.max_speed = float(max_speed)
    return p


class NativeLib:
    """The loaded library with typed entry points."""

    def __init__(self, path: Path) -> None:
        self.path = path
        lib = ctypes.CDLL(str(path))
        self._lib = lib
        dp = ctypes.POINTER(ctypes.c_double)
        pp = ctypes.POINTER(Params)
        lib.uvms_params_layout.argtypes = [ctypes.POINTER(ctypes.c_size_t)]
        lib.uvms_params_layout.restype = None
        lib.uvms_register.argtypes = [ctypes.c_void_p, pp]
        lib.uvms_register.restype = ctypes.c_int
        lib.uvms_unregister.argtypes = [ctypes.c_void_p]
        lib.uvms_unregister.restype = ctypes.c_int
        lib.uvms_registered_count.argtypes = []
        lib.uvms_registered_count.restype = ctypes.c_int
        lib.uvms_set_fallback.argtypes = [ctypes.c_void_p]
        lib.uvms_set_fallback.restype = None
        lib.uvms_evaluate.argtypes = [pp, dp, dp, dp, dp, dp, dp]
        lib.uvms_evaluate.restype = None
        lib.uvms_strip_integrals.argtypes = [ctypes.c_double] * 4 + [dp, dp]
        lib.uvms_strip_integrals.restype = None
        lib.uvms_passive.argtypes = [ctypes.c_void_p, ctypes.c_void_p]
        lib.uvms_passive.restype = None
        #: The mjcb_passive function (a ctypes function pointer, as mujoco.set_mjcb_passive takes).
        self.passive = lib.uvms_passive
        self._check_layout()

    def _check_layout(self) -> None:
        out = (ctypes.c_size_t * 7)()
        self._lib.uvms_params_layout(out)
        mine = [ctypes.sizeof(Params)] + [
            getattr(Params, f).offset for f in ("nbody", "max_speed", "augmented", "status", "status_time", "status_speed")
        ]
        if list(out) != mine:
            raise NativeUnavailableError(f"uvms_params layout mismatch between hydro.c {list(out)} and ctypes {mine}")

    # ------------------------------------------------------------ registry (plant.py)

    def register(self, data_address: int, params: Params) -> int:
        """Serve ``mjData`` at ``data_address`` natively with ``params`` (which the caller keeps
        alive until :meth:`unregister`). Returns the slot, -1 if the registry is full."""
        return self._lib.uvms_register(data_address, ctypes.byref(params))

    def unregister(self, data_address: int) -> bool:
        """Stop serving ``mjData`` at ``data_address``. Lock-free: safe from finalizers."""
        return bool(self._lib.uvms_unregister(data_address))

    def registered_count(self) -> int:
        return self._lib.uvms_registered_count()

    def set_fallback(self, func: ctypes._CFuncPtr | None) -> None:
        """The mjcb_passive-compatible function called for data that is not registered."""
        self._lib.uvms_set_fallback(ctypes.cast(func, ctypes.c_void_p) if func is not None else None)

    # ------------------------------------------------------------ maths, without MuJoCo

    def evaluate(
        self,
        params: Params,
        q,
        qd,
        wind=(0.0, 0.0),
        gravity=(0.0, -9.81),
        want_mass: bool = True,
    ) -> tuple[list[float], list[float]]:
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
        """Same as :func:`uvms_mj.hydro.strip_integrals`, computed by the C code."""
        i0, i1 = ctypes.c_double(), ctypes.c_double()
        self._lib.uvms_strip_integrals(w0, om, a, b, ctypes.byref(i0), ctypes.byref(i1))
        return i0.value, i1.value


# --------------------------------------------------------------------------- building


def cache_dir() -> Path:
    """Where compiled libraries go: $UVMS_MJ_CACHE, $XDG_CACHE_HOME/uvms_mj or ~/.cache/uvms_mj."""
    if os.environ.get(ENV_CACHE):
        return Path(os.environ[ENV_CACHE]).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base).expanduser() / "uvms_mj"


def _mujoco_paths() -> tuple[Path, Path]:
    """(include folder, libmujoco) of the installed mujoco wheel."""
    pkg = Path(mujoco.__file__).resolve().parent
    include = pkg / "include"
    if not (include / "mujoco" / "mujoco.h").is_file():
        raise NativeUnavailableError(f"no MuJoCo headers at {include}/mujoco (is mujoco installed from a wheel?)")
    libs = sorted(pkg.glob("libmujoco.so*")) + sorted(pkg.glob("libmujoco*.dylib"))
    if not libs:
        raise NativeUnavailableError(f"no libmujoco in {pkg}")
    return include, max(libs, key=lambda p: len(p.name))  # the fully versioned name


def _compiler() -> list[str]:
    if os.environ.get("CC"):
        return shlex.split(os.environ["CC"])
    for name in ("cc", "gcc", "clang"):
        found = shutil.which(name)
        if found:
            return [found]
    raise NativeUnavailableError("no C compiler found (cc, gcc or clang; or set CC)")


def build(force: bool = False) -> Path:
    """Compile hydro.c into the cache (if not there yet) and return the library's path.

    Raises:
        NativeUnavailableError: no compiler, no MuJoCo headers, or the compilation failed.
    """
    if sys.platform.startswith("win"):
        raise NativeUnavailableError("the native backend is not supported on Windows")
    include, libmujoco = _mujoco_paths()
    cc = _compiler()
    src = SOURCE.read_bytes()
    cmd_tail = [*CFLAGS, f"-I{include}", str(SOURCE), str(libmujoco), f"-Wl,-rpath,{libmujoco.parent}", "-lm"]
    key = hashlib.sha256(
        b"\0".join(
            [src, mujoco.__version__.encode(), str(libmujoco).encode(), sysconfig.get_platform().encode(),
             " ".join(cc + cmd_tail).encode()]
        )
    ).hexdigest()[:20]
    folder = cache_dir()
    target = folder / f"hydro-{key}.so"
    if target.is_file() and not force:
        return target
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=".hydro-", suffix=".so.tmp", dir=folder)
        os.close(fd)
    except OSError as exc:
        raise NativeUnavailableError(f"cannot write to the cache folder {folder} ({exc}; set {ENV_CACHE})") from None
    try:
        try:
            res = subprocess.run([*cc, *cmd_tail, "-o", tmp], capture_output=True, text=True, timeout=300)
        except (OSError, subprocess.SubprocessError) as exc:
            raise NativeUnavailableError(f"cannot run the C compiler {cc[0]}: {exc}") from None
        if res.returncode != 0:
            detail = (res.stderr or res.stdout).strip().splitlines()[-5:]
            raise NativeUnavailableError(f"compiling {SOURCE.name} with {cc[0]} failed: " + " | ".join(detail))
        os.chmod(tmp, 0o755)
        os.replace(tmp, target)  # atomic: a parallel process sees no file or a complete one
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return target


_lock = threading.Lock()
_lib: NativeLib | None = None
_error: str | None = None
_tried = False
_warned = False


def load() -> NativeLib | None:
    """The native library (built on first use), or None if it cannot be built or loaded
    (:func:`unavailable_reason` says why). Cached for the process."""
    global _lib, _error, _tried
    with _lock:
        if _tried:
            return _lib
        _tried = True
        try:
            try:
                _lib = NativeLib(build())
            except OSError:  # a damaged cache file: rebuild once
                _lib = NativeLib(build(force=True))
        except (NativeUnavailableError, OSError) as exc:
            _lib, _error = None, str(exc)
        return _lib


def unavailable_reason() -> str | None:
    """Why :func:`load` returned None (None if it has not been tried or succeeded)."""
    return _error


def require() -> NativeLib:
    """The native library, or :class:`NativeUnavailableError` saying why it cannot be had."""
    lib = load()
    if lib is None:
        raise NativeUnavailableError(
            f"the native hydrodynamics backend is unavailable: {_error}. Install a C compiler "
            f"(e.g. apt-get install gcc libc6-dev) or use {ENV_BACKEND}=python / backend='python'"
        )
    return lib


def warn_unavailable_once() -> None:
    """One RuntimeWarning per process when 'auto' falls back to Python."""
    global _warned
    if not _warned:
        _warned = True
        warnings.warn(
            f"uvms_mj: native hydrodynamics unavailable ({_error}); using the much slower pure-Python "
            f"backend. Install a C compiler (e.g. apt-get install gcc libc6-dev) for the fast path, "
            f"or set {ENV_BACKEND}=python to silence this.",
            RuntimeWarning,
            stacklevel=3,
        )


def backend_from_env() -> str:
    """The backend requested by $UVMS_MJ_BACKEND (default "auto"), validated."""
    value = os.environ.get(ENV_BACKEND, "").strip().lower() or "auto"
    if value not in BACKENDS:
        raise ValueError(f"{ENV_BACKEND}={os.environ.get(ENV_BACKEND)!r}; allowed: {', '.join(BACKENDS)}")
    return value
