"""Build and register the uvms MuJoCo plugins (``plugin/*.c``: ``uvms.water``, ``uvms.hydro``,
``uvms.thruster``).

All ``plugin/*.c`` files are compiled into ONE shared library with the system C compiler
(``$CC``, else ``cc``, ``gcc`` or ``clang``; ``-O2 -shared -fPIC -ffp-contract=off``) against the
headers and the ``libmujoco`` of the installed mujoco wheel, into a cache folder:
``$UVMS_MJ_CACHE``, else ``$XDG_CACHE_HOME/uvms_mj``, else ``~/.cache/uvms_mj``. The file name
carries a hash of every source and header, the mujoco version and library, the platform and the
compiler command, so a change of any of them rebuilds; the build writes a temporary file that is
renamed into place, so parallel processes are safe (they may both compile; each rename is
atomic and the result is the same).

:func:`register_plugins` loads the library into MuJoCo (``mujoco.mj_loadPluginLibrary``) once
per process; every loader of a model that uses the plugins calls it (:mod:`uvms_mj.physics.model`,
the plant, the renderer's scene, the sim2real workers), never ``import uvms_mj``.

One switch chooses between the compiled paths (these plugins, the RAC kernel, the plant's
compiled sample, the planar nominal model's C code) and their Python/numpy references:
``UVMS_MJ_COMPILED`` (:func:`compiled_mode`, read when first needed):

* ``auto`` (default): compiled where a C compiler is available; otherwise the Python paths, with
  one ``RuntimeWarning`` per process saying why;
* ``on``: compiled, or a :class:`PluginUnavailableError` saying why not;
* ``off``: the Python paths everywhere, nothing compiled.

Explicit per-object choices (``Plant(backend=...)``, ``compile_spec(native=...)``) override it.
The former variables ``UVMS_MJ_PLUGIN``, ``UVMS_MJ_BACKEND`` and ``UVMS_MJ_KERNEL`` are refused
with a one-line :class:`CompiledModeError` naming ``UVMS_MJ_COMPILED``.
"""

from __future__ import annotations

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

import mujoco

__all__ = [
    "COMPILED_MODES",
    "CompiledModeError",
    "ENV_CACHE",
    "ENV_COMPILED",
    "LEGACY_ENV",
    "PluginUnavailableError",
    "cache_dir",
    "compile_library",
    "compiled_mode",
    "fallback",
    "library_path",
    "register_plugins",
    "sources",
    "unavailable_reason",
]

ENV_CACHE = "UVMS_MJ_CACHE"
#: The one switch between the compiled and the Python paths (module docstring).
ENV_COMPILED = "UVMS_MJ_COMPILED"
COMPILED_MODES = ("auto", "on", "off")
#: Former per-path switches, replaced by UVMS_MJ_COMPILED: refused when set.
LEGACY_ENV = ("UVMS_MJ_PLUGIN", "UVMS_MJ_BACKEND", "UVMS_MJ_KERNEL")
PLUGIN_DIR = Path(__file__).resolve().parent / "plugin"
CFLAGS = ("-O2", "-shared", "-fPIC", "-ffp-contract=off")  # no FMA contraction: reproducible maths


class PluginUnavailableError(RuntimeError):
    """The plugin library cannot be built or loaded (the message is a one-line reason)."""


class CompiledModeError(ValueError):
    """``UVMS_MJ_COMPILED`` has a bad value, or a former switch is set (a one-line message)."""


def compiled_mode() -> str:
    """``$UVMS_MJ_COMPILED`` lower-case: "auto" (unset or empty), "on" or "off".

    Raises:
        CompiledModeError: a value not in :data:`COMPILED_MODES`, or one of :data:`LEGACY_ENV` set.
    """
    legacy = [f"{k}={os.environ[k]}" for k in LEGACY_ENV if k in os.environ]
    if legacy:
        raise CompiledModeError(f"{', '.join(legacy)} is no longer read: unset it and use {ENV_COMPILED}="
                                f"{'|'.join(COMPILED_MODES)} (off: the Python paths everywhere)")
    raw = os.environ.get(ENV_COMPILED, "")
    mode = raw.strip().lower() or "auto"
    if mode not in COMPILED_MODES:
        raise CompiledModeError(f"{ENV_COMPILED}={raw!r} is not one of {', '.join(COMPILED_MODES)}")
    return mode


_warned = False


def fallback(what: str, reason: str) -> None:
    """A compiled path is unavailable: under ``auto`` warn (once per process, whichever path
    comes first) and let the caller take the Python path; under ``on`` raise.

    Raises:
        PluginUnavailableError: ``UVMS_MJ_COMPILED=on``.
    """
    global _warned
    if compiled_mode() == "on":
        raise PluginUnavailableError(f"{ENV_COMPILED}=on but {what} cannot be used: {reason}")
    if not _warned:
        _warned = True
        warnings.warn(f"uvms_mj: {what} unavailable ({reason}); using the Python paths (slower; "
                      f"{ENV_COMPILED}=off says so and silences this)", RuntimeWarning, stacklevel=3)


def sources() -> list[Path]:
    """The C sources compiled into the library (sorted)."""
    return sorted(PLUGIN_DIR.glob("*.c"))


def _headers() -> list[Path]:
    return sorted(PLUGIN_DIR.glob("*.h"))


def cache_dir() -> Path:
    """Where the library goes: $UVMS_MJ_CACHE, $XDG_CACHE_HOME/uvms_mj or ~/.cache/uvms_mj."""
    if os.environ.get(ENV_CACHE):
        return Path(os.environ[ENV_CACHE]).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base).expanduser() / "uvms_mj"


def _mujoco_paths() -> tuple[Path, Path]:
    """(include folder, libmujoco) of the installed mujoco wheel."""
    pkg = Path(mujoco.__file__).resolve().parent
    include = pkg / "include"
    if not (include / "mujoco" / "mjplugin.h").is_file():
        raise PluginUnavailableError(f"no MuJoCo headers at {include}/mujoco (is mujoco installed from a wheel?)")
    libs = sorted(pkg.glob("libmujoco.so*")) + sorted(pkg.glob("libmujoco*.dylib"))
    if not libs:
        raise PluginUnavailableError(f"no libmujoco in {pkg}")
    return include, max(libs, key=lambda p: len(p.name))  # the fully versioned name


def _compiler() -> list[str]:
    if os.environ.get("CC"):
        cc = shlex.split(os.environ["CC"])
        if cc and shutil.which(cc[0]):
            return cc
        raise PluginUnavailableError(f"the C compiler CC={os.environ['CC']!r} is not found")
    for name in ("cc", "gcc", "clang"):
        found = shutil.which(name)
        if found:
            return [found]
    raise PluginUnavailableError("no C compiler found (Debian: apt-get install gcc; or set CC)")


def library_path(force: bool = False) -> Path:
    """The compiled plugin library, built into the cache first if needed.

    Raises:
        PluginUnavailableError: unsupported platform, no compiler, no MuJoCo headers, an
            unwritable cache folder, or a failed compilation (one-line reason).
    """
    srcs = sources()
    if not srcs:
        raise PluginUnavailableError(f"no plugin sources in {PLUGIN_DIR}")
    return compile_library("uvms_plugins", srcs, headers=_headers(), force=force)


def compile_library(stem: str, srcs: list[Path], *, headers: list[Path] = (), force: bool = False) -> Path:
    """Compile C sources into one shared library in the cache (if not there yet) and return its
    path: ``STEM-HASH.so``, the hash over the sources, headers, mujoco version and library,
    platform and compiler command (built against the mujoco wheel's headers, linked to its
    libmujoco). Written to a temporary name and renamed: parallel builds are safe.

    Raises:
        PluginUnavailableError: unsupported platform, no compiler, no MuJoCo headers, an
            unwritable cache folder, or a failed compilation (one-line reason).
    """
    if sys.platform.startswith("win"):
        raise PluginUnavailableError("building the uvms C code is not supported on Windows")
    include, libmujoco = _mujoco_paths()
    cc = _compiler()
    dirs = sorted({str(p.parent) for p in [*srcs, *headers]})
    cmd_tail = [*CFLAGS, f"-I{include}", *(f"-I{d}" for d in dirs), *map(str, srcs), str(libmujoco),
                f"-Wl,-rpath,{libmujoco.parent}", "-lm"]
    h = hashlib.sha256()
    for path in [*srcs, *headers]:
        h.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    for part in (mujoco.__version__, str(libmujoco), sysconfig.get_platform(), " ".join(cc + cmd_tail)):
        h.update(part.encode() + b"\0")
    key = h.hexdigest()[:20]
    folder = cache_dir()
    suffix = ".dylib" if sys.platform == "darwin" else ".so"
    target = folder / f"{stem}-{key}{suffix}"
    if target.is_file() and not force:
        return target
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{stem}-", suffix=suffix + ".tmp", dir=folder)
        os.close(fd)
    except OSError as exc:
        raise PluginUnavailableError(f"cannot write to the cache folder {folder} ({exc}; set {ENV_CACHE})") from None
    try:
        try:
            res = subprocess.run([*cc, *cmd_tail, "-o", tmp], capture_output=True, text=True, timeout=300)
        except (OSError, subprocess.SubprocessError) as exc:
            raise PluginUnavailableError(f"cannot run the C compiler {cc[0]}: {exc}") from None
        if res.returncode != 0:
            detail = [ln for ln in (res.stderr or res.stdout).strip().splitlines() if ln.strip()][-4:]
            raise PluginUnavailableError(f"compiling {', '.join(p.name for p in srcs)} with {cc[0]} failed: "
                                         + " | ".join(detail))
        os.chmod(tmp, 0o755)
        os.replace(tmp, target)  # atomic: a parallel process sees no file or a complete one
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return target


_lock = threading.Lock()
_registered: bool | None = None  # None: not tried yet
_reason: str | None = None
_path: Path | None = None


def register_plugins() -> bool:
    """Build (if needed) and load the plugin library into MuJoCo, once per process: the one
    idempotent, thread-safe call every loader of a uvms model makes before parsing it.

    Returns True when ``uvms.water``, ``uvms.hydro`` and ``uvms.thruster`` are registered; False
    (and :func:`unavailable_reason` says why) with ``UVMS_MJ_COMPILED=off``, or under ``auto``
    when it cannot build or load (one RuntimeWarning per process). The outcome is cached.

    Raises:
        CompiledModeError: a bad ``UVMS_MJ_COMPILED``, or a former switch set.
        PluginUnavailableError: ``UVMS_MJ_COMPILED=on`` and the library cannot be built or loaded.
    """
    global _registered, _reason, _path
    mode = compiled_mode()
    with _lock:
        if _registered is None:
            _registered, _reason, _path = _register(mode)
        ok, reason = _registered, _reason
    if not ok and mode != "off":
        fallback("the uvms C plugins", reason or "")
    return ok


def _register(mode: str) -> tuple[bool, str | None, Path | None]:
    if mode == "off":
        return False, f"disabled by {ENV_COMPILED}=off", None
    try:
        path = library_path()
        try:
            mujoco.mj_loadPluginLibrary(str(path))
        except Exception:  # a damaged cache file: rebuild once
            path = library_path(force=True)
            mujoco.mj_loadPluginLibrary(str(path))
    except PluginUnavailableError as exc:
        return False, str(exc), None
    except Exception as exc:  # loading failed twice
        return False, f"cannot load the uvms plugin library: {exc}".replace("\n", " "), None
    return True, None, path


# --------------------------------------------------------------------------- compiled fast paths

def load_compiled(stem: str, srcs: list[Path], what: str):
    """Compile (into the cache, if needed) and load with ctypes one of the compiled fast paths:
    (the ``ctypes.CDLL``, None) or (None, the one-line reason: ``UVMS_MJ_COMPILED=off``, no
    compiler, a failed build; under ``auto`` also one warning per process, see :func:`fallback`).
    A damaged cache file is rebuilt once.

    Raises:
        CompiledModeError: a bad ``UVMS_MJ_COMPILED``, or a former switch set.
        PluginUnavailableError: ``UVMS_MJ_COMPILED=on`` and it cannot be built or loaded.
    """
    if compiled_mode() == "off":
        return None, f"disabled by {ENV_COMPILED}=off"
    lib, reason = _load_cdll(stem, srcs, what)
    if lib is None:
        fallback(what, reason)
    return lib, reason


def _load_cdll(stem: str, srcs: list[Path], what: str):
    import ctypes

    try:
        return ctypes.CDLL(str(compile_library(stem, srcs))), None
    except PluginUnavailableError as exc:
        return None, str(exc)
    except OSError as exc:
        try:
            return ctypes.CDLL(str(compile_library(stem, srcs, force=True))), None
        except (OSError, PluginUnavailableError) as exc2:
            return None, f"cannot load {what}: {exc2 or exc}"


class CompiledOnce:
    """One compiled fast path, loaded at most once per process (thread-safe): :meth:`get` gives
    ``configure(lib)`` of the library :func:`load_compiled` loads, or None (:attr:`reason` says
    why)."""

    def __init__(self, stem: str, srcs: list[Path], what: str, configure) -> None:
        self.stem, self.srcs, self.what, self.configure = stem, srcs, what, configure
        self._lock = threading.Lock()
        self._tried = False
        self.value = None
        self.reason: str | None = None

    def get(self):
        with self._lock:
            if not self._tried:
                lib, self.reason = load_compiled(self.stem, self.srcs, self.what)  # may raise ("on")
                self._tried = True
                self.value = self.configure(lib) if lib is not None else None
            return self.value

    def fresh(self) -> "CompiledOnce":
        """The same fast path, not loaded yet (e.g. to load it again under another setting)."""
        return CompiledOnce(self.stem, self.srcs, self.what, self.configure)


def unavailable_reason() -> str | None:
    """Why :func:`register_plugins` returned False (None if not tried or registered)."""
    return _reason


def loaded_path() -> Path | None:
    """The library registered in this process (None if none)."""
    return _path
