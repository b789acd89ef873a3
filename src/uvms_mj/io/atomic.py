"""Write a file whole or not at all: a temporary file next to it, renamed over it at the end.

Every uvms-mj output other than the MCAP log (which is written in place under an exclusive lock,
so that a second writer is refused and a killed run leaves a log that reads as truncated) goes
through :func:`atomic_path` or :func:`atomic_open`: the data go to a hidden temporary file in the
destination's own folder (same file system, so :func:`os.replace` is an atomic rename), and only a
complete file is renamed to the final name. On any failure (a full disk, an I/O error, Ctrl-C) the
temporary file is removed and the exception propagates; a file already under the final name is
left as it was.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path
from typing import IO, Iterator

__all__ = ["atomic_open", "atomic_path"]


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, mkdir: bool = True) -> Iterator[Path]:
    """Yield a temporary path to write in place of ``path``; on a clean exit it replaces ``path``.

    The temporary name is ``.<name>.<random>.part<suffix>`` in ``path``'s folder: it keeps the
    suffix, so writers that choose a format by it (matplotlib's ``savefig``, ffmpeg, ``savemat``)
    write the right one. ``mkdir``: create the folder first. The file gets the permissions a new
    file would get (0666 less the umask), not the 0600 of :func:`tempfile.mkstemp`.
    """
    final = Path(path)
    if mkdir:
        final.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(prefix=f".{final.stem}.", suffix=f".part{final.suffix}", dir=final.parent or ".")
    tmp = Path(name)
    from uvms_mj.io.interrupts import partial_output

    try:
        os.close(fd)
        os.chmod(tmp, 0o666 & ~_umask())
        with partial_output(tmp):  # the command line's watchdog removes it if it ends the process first
            yield tmp
        os.replace(tmp, final)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


@contextlib.contextmanager
def atomic_open(path: str | os.PathLike, mode: str = "w", mkdir: bool = True, **kw) -> Iterator[IO]:
    """``open(path, mode, **kw)`` on a temporary file that replaces ``path`` once closed cleanly
    (flushed and fsync'ed first, so a full disk shows up here rather than after the rename)."""
    if not mode.startswith("w"):
        raise ValueError(f"mode = {mode!r}: atomic_open writes a new file ('w' or 'wb')")
    with atomic_path(path, mkdir=mkdir) as tmp:
        with open(tmp, mode, **kw) as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
