"""Output paths: refuse one that would fail or destroy something before anything is written,
and open a log under an exclusive lock."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Callable, Union


class OutputPathError(ValueError):
    """An output path that cannot or must not be written (the message says why)."""


class LogInUseError(OSError):
    """Another process is writing the same log (it holds the file's lock)."""


_NO_WRITE_ROOTS = ("/proc", "/sys", "/dev")

Magic = Union[bytes, Callable[[bytes], bool], None]

#: How each kind of uvms-mj output begins (a prefix, or a test of the file's first 64 bytes): an
#: existing file that does not is not one of ours and is never overwritten. Kinds not listed
#: are not checked by content (only ``protect`` and the file type apply).
OUTPUT_KINDS: dict[str, Magic] = {
    "log": b"\x89MCAP",                                 # MCAP magic
    "video": lambda head: head[4:8] == b"ftyp",          # ISO base media (MP4): the ftyp box first
    "plot": b"\x89PNG\r\n\x1a\n",                     # PNG signature
    "JSON file": lambda head: head.lstrip()[:1] in (b"{", b"["),
    "CSV table": lambda head: head.startswith((b"t,", b"t\n", b"t\r\n")),  # export's tables: t [s] first
    "npz file": b"PK\x03\x04",                          # a zip archive
    "mat file": b"MATLAB",                               # MATLAB 5 header text
    "Parquet file": b"PAR1",
    "override file": b"# uvms-mj identify",              # identify's header comment
}

_BY_KIND = object()


def _matches(magic: Magic, head: bytes) -> bool:
    if callable(magic):
        return magic(head)
    return head[: len(magic)] == magic[: len(head)]  # a prefix of the magic: one of ours cut short (a killed run)


def check_output_path(path: str | os.PathLike, protect: tuple = (), kind: str = "log",
                      magic=_BY_KIND) -> Path:
    """Refuse an output path that would fail or destroy something, before anything is written.

    Refused: a path under /proc, /sys or /dev (except /dev/shm); a symbolic link; an existing directory, device
    or other non-regular file; a file in ``protect`` (the command's inputs: the scenario file,
    the log being exported, a trial's files, an overrides file; compared with
    :func:`os.path.samefile`, so another name or a hard link of an input is refused too); an
    existing non-empty file that does not look like ``kind`` (``magic``: a prefix or a test of the
    first 64 bytes, by default :data:`OUTPUT_KINDS` [kind]; None: no content check), i.e. not one
    of our outputs: never overwritten; a parent that is a file or is not writable; a name longer
    than the file system allows. Raises :class:`OutputPathError` (its message names the path and
    why); returns the path.
    """
    if magic is _BY_KIND:
        magic = OUTPUT_KINDS.get(kind)
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
    for other in protect:  # not there yet: the same path by name (symbolic links resolved)
        if other is not None and not p.exists() and os.path.realpath(p) == os.path.realpath(other):
            raise OutputPathError(f"{p}: is also {other}, another input or output of this command; "
                                  "choose another output path")
    if p.is_symlink():
        raise OutputPathError(f"{p}: is a symbolic link; give the path of a regular file (the link's target "
                              "is not overwritten)")
    if p.exists():
        if not p.is_file():
            raise OutputPathError(f"{p}: exists and is not a regular file")
        for other in protect:
            try:
                same = other is not None and os.path.samefile(p, other)
            except OSError:
                same = False
            if same:
                raise OutputPathError(f"{p}: is the input file {other}; choose another output path")
        if magic is not None:
            try:
                with open(p, "rb") as f:
                    head = f.read(64)
            except OSError as exc:
                raise OutputPathError(f"{p}: cannot be read back ({exc.strerror or exc})") from None
            if head and not _matches(magic, head):
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


class InputFileError(ValueError):
    """An input path that is not a readable regular file of a plausible size (the message: one line, the path
    and why)."""


def check_input_file(path: str | os.PathLike, what: str, max_bytes: int | None = None) -> Path:
    """Refuse an input that cannot be read as a file, before opening it: missing; a folder; a FIFO, a
    device (/dev/zero) or a socket (``os.stat`` only: opening a FIFO would block, reading /dev/zero would
    never end); larger than ``max_bytes``. ``what`` names the input in the message ("an overrides file",
    "a trajectory CSV"). Raises :class:`InputFileError`; returns the path."""
    import stat as _stat

    p = Path(path)
    try:
        st = os.stat(p)
    except FileNotFoundError:
        raise InputFileError(f"{p}: no such file ({what})") from None
    except OSError as exc:
        raise InputFileError(f"{p}: cannot be read ({exc.strerror or exc})") from None
    if _stat.S_ISDIR(st.st_mode):
        raise InputFileError(f"{p}: is a folder; expected {what}")
    if not _stat.S_ISREG(st.st_mode):
        kind = ("a FIFO" if _stat.S_ISFIFO(st.st_mode) else "a device" if _stat.S_ISCHR(st.st_mode)
                or _stat.S_ISBLK(st.st_mode) else "a socket" if _stat.S_ISSOCK(st.st_mode) else "special")
        raise InputFileError(f"{p}: not a regular file ({kind}); expected {what}")
    if max_bytes is not None and st.st_size > max_bytes:
        raise InputFileError(f"{p}: {st.st_size} bytes; {what} is at most {max_bytes} bytes")
    return p


class LineTooLong(ValueError):
    """A line of a text input longer than allowed (``line``: its number, from 1)."""

    def __init__(self, path, line: int, limit: int) -> None:
        super().__init__(f"{path}, line {line}: longer than {limit} characters")
        self.line = line


def read_lines(path: str | os.PathLike, max_line: int) -> tuple[list[str], bool]:
    """The lines of a UTF-8 text file without their line ends, and whether the last one had one. A line
    longer than ``max_line`` characters raises :class:`LineTooLong` as soon as it is met (a 200 MB line is
    never held whole); UnicodeDecodeError and OSError propagate."""
    lines: list[str] = []
    last = ""
    with open(path, newline="", encoding="utf-8") as fh:
        while True:
            s = fh.readline(max_line + 1)
            if not s:
                break
            if len(s) > max_line and not s.endswith(("\n", "\r")):
                raise LineTooLong(path, len(lines) + 1, max_line)
            last = s
            lines.append(s.rstrip("\r\n"))
    return lines, last.endswith(("\n", "\r"))
