"""Output paths: refuse one that would fail or destroy something before anything is written,
and open a log under an exclusive lock."""

from __future__ import annotations

import os
from pathlib import Path


class OutputPathError(ValueError):
    """An output path that cannot or must not be written (the message says why)."""


class LogInUseError(OSError):
    """Another process is writing the same log (it holds the file's lock)."""


_NO_WRITE_ROOTS = ("/proc", "/sys", "/dev")


def check_output_path(path: str | os.PathLike, protect: tuple = (), kind: str = "log",
                      magic: bytes | None = b"\x89MCAP") -> Path:
    """Refuse an output path that would fail or destroy something, before anything is written.

    Refused: a path under /proc, /sys or /dev (except /dev/shm); a symbolic link; an existing directory, device
    or other non-regular file; an existing non-empty file that does not start with ``magic``
    (not one of our outputs: never overwritten); a file in ``protect`` (e.g. the scenario
    file); a parent that is a file or is not writable; a name longer than the file system
    allows. Raises :class:`OutputPathError`; returns the path.
    """
    p = Path(path)
    absolute = Path(os.path.abspath(p))
    for root in _NO_WRITE_ROOTS:
        if Path("/dev/shm") in absolute.parents:  # a tmpfs: fine
            break
        if absolute == Path(root) or Path(root) in absolute.parents:
            raise OutputPathError(f"{p}: {root} is not a place to write a {kind} to")
    for part in absolute.parts:
        if len(os.fsencode(part)) > 255:
            raise OutputPathError(f"{p}: a file name is {len(os.fsencode(part))} bytes long; "
                                  "the file system allows 255")
    if p.is_symlink():
        raise OutputPathError(f"{p}: is a symbolic link; give the path of a regular file (the link's target "
                              "is not overwritten)")
    if p.exists():
        if not p.is_file():
            raise OutputPathError(f"{p}: exists and is not a regular file")
        for other in protect:
            try:
                if other is not None and os.path.samefile(p, other):
                    raise OutputPathError(f"{p}: is the input file {other}; choose another output path")
            except OSError:
                pass
        if magic is not None:
            try:
                with open(p, "rb") as f:
                    head = f.read(len(magic))
            except OSError as exc:
                raise OutputPathError(f"{p}: cannot be read back ({exc.strerror or exc})") from None
            if head and head != magic[: len(head)]:
                raise OutputPathError(f"{p}: exists and is not a {kind} written by uvms-mj; not overwriting it "
                                      "(delete it or choose another path)")
        if not os.access(p, os.W_OK):
            raise OutputPathError(f"{p}: is not writable")
        return p
    _check_creatable(p, absolute.parent)
    return p


def _check_creatable(p: Path, start: Path) -> None:
    """``start`` (a folder to write into) exists, or can be created: its nearest existing
    ancestor is a writable folder (no dangling symbolic link on the way)."""
    parent = start
    while not parent.exists():
        if parent.is_symlink():
            raise OutputPathError(f"{p}: {parent} is a dangling symbolic link")
        parent = parent.parent
    if not parent.is_dir():
        raise OutputPathError(f"{p}: {parent} is a file, not a folder")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputPathError(f"{p}: the folder {parent} is not writable")


def check_output_dir(path: str | os.PathLike) -> Path:
    """Refuse an output folder under /proc, /sys or /dev (except /dev/shm), one that exists
    as something else, or one whose nearest existing parent is a file or not writable.
    Raises :class:`OutputPathError`; returns the path."""
    p = Path(path)
    absolute = Path(os.path.abspath(p))
    if Path("/dev/shm") not in absolute.parents:
        for root in _NO_WRITE_ROOTS:
            if absolute == Path(root) or Path(root) in absolute.parents:
                raise OutputPathError(f"{p}: {root} is not a place to write results to")
    if p.exists() and not p.is_dir():
        raise OutputPathError(f"{p}: exists and is not a folder")
    _check_creatable(p, absolute)
    return p


def _open_locked(path: Path):
    """Open ``path`` for writing under an exclusive lock (never following a symbolic link),
    then truncate it: a second writer of the same log fails with :class:`LogInUseError`
    instead of interleaving its records with the first one's."""
    flags = os.O_WRONLY | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
    fd = os.open(path, flags, 0o666)
    try:
        try:
            import fcntl
        except ImportError:  # not POSIX: no lock
            fcntl = None
        if fcntl is not None:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                raise LogInUseError(f"{path}: another process is writing this log now") from None
            except OSError:  # a file system without locks (some network mounts): write unlocked
                pass
        os.ftruncate(fd, 0)
        return os.fdopen(fd, "wb")
    except BaseException:
        os.close(fd)
        raise
