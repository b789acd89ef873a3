"""What a log file must be before it is read, and hold once read (issue 23, item 4).

:func:`check_log_file` runs at the open of a log (:func:`uvms_mj.io.reader.read_log`,
:func:`~uvms_mj.io.reader.log_info`): a regular file (a FIFO or a device such as /dev/zero would
block or never end), not empty, beginning with the MCAP magic and a well-formed header record.
:func:`check_log_content` runs once it is read: an MCAP file written by another tool, with
neither uvms-mj's sample channels nor its metadata, is not a uvms-mj log. A log cut by ``kill -9``
passes both (it keeps its magic, header and first metadata, flushed at the start of the run) and
is read as truncated. Each refusal is a :class:`LogFileError` whose message is one line naming the
file and what is wrong.
"""

from __future__ import annotations

import os
import stat
import struct
from dataclasses import dataclass
from pathlib import Path

__all__ = ["LogFileError", "LogHead", "check_log_content", "check_log_file"]

MCAP_MAGIC = b"\x89MCAP0\r\n"
_OP_HEADER = 0x01
#: A header record holds two short strings (profile, library): ours is about 40 bytes; 1 MiB is
#: beyond any writer's (ours: a bound so that a corrupt length is refused, not allocated).
_HEADER_MAX = 1 << 20

#: What a file that is not an MCAP log begins with (for the message), by its first bytes.
_FOREIGN = (
    (b"\x89PNG", "a PNG image"), (b"\xff\xd8\xff", "a JPEG image"), (b"GIF8", "a GIF image"),
    (b"%PDF", "a PDF document"), (b"PK\x03\x04", "a zip archive (npz?)"), (b"\x1f\x8b", "a gzip file"),
    (b"PAR1", "a Parquet file"), (b"MATLAB", "a MATLAB file"), (b"\x7fELF", "an executable"),
    (b"\x28\xb5\x2f\xfd", "a zstd file"), (b"SQLite format", "an SQLite database (a ROS 2 bag?)"),
    (b"#ROSBAG", "a ROS 1 bag"),
)


#: How every refusal begins (after the path): the words the command line has always used for a bad log.
_NOT = "not a readable uvms-mj MCAP log"


class LogFileError(ValueError):
    """A file given as a log that is not one (its message: the file and what is wrong, one line)."""


@dataclass(frozen=True)
class LogHead:
    """The start of a log: its size [bytes] and the MCAP header's profile and library strings."""

    size: int
    profile: str
    library: str


def _kind(head: bytes) -> str:
    for magic, what in _FOREIGN:
        if head.startswith(magic):
            return what
    if not head.strip(b"\0"):
        return "zero bytes"
    try:
        text = head.decode("utf-8")
    except UnicodeDecodeError:
        return "binary data"
    return "text (YAML, JSON or CSV?)" if text.isprintable() or text.strip() else "text"


def _file_type(mode: int) -> str:
    for test, what in ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
                       (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                       (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return what
    return "not a plain file"


def check_log_file(path: str | os.PathLike) -> LogHead:
    """Refuse what cannot be a log before reading it; return its :class:`LogHead`.

    Refused (:class:`LogFileError`): a missing path; a folder, FIFO, device or socket (``os.stat``
    only: a FIFO is never opened, so nothing blocks); an empty file; a file that does not begin
    with the MCAP magic (the message says what it looks like: a PNG image, text...); the magic
    alone (a log cut before its header); a first record that is not a header of a plausible
    length (e.g. the magic followed by zeros).
    """
    p = Path(path)
    try:
        st = os.stat(p)
    except FileNotFoundError:
        raise LogFileError(f"{p}: no such log file") from None
    except OSError as exc:
        raise LogFileError(f"{p}: cannot be read ({exc.strerror or exc})") from None
    if not stat.S_ISREG(st.st_mode):
        raise LogFileError(f"{p}: {_NOT}: not a regular file ({_file_type(st.st_mode)})")
    if st.st_size == 0:
        raise LogFileError(f"{p}: {_NOT}: empty file (0 bytes)")
    try:
        with open(p, "rb") as f:
            head = f.read(len(MCAP_MAGIC) + 9)
            if not head.startswith(MCAP_MAGIC):
                raise LogFileError(f"{p}: {_NOT}: no MCAP magic at its start (it looks like {_kind(head)})")
            if len(head) == len(MCAP_MAGIC):
                raise LogFileError(f"{p}: {_NOT}: only the MCAP magic ({st.st_size} bytes), cut before its "
                                   "header; nothing to read")
            if len(head) < len(MCAP_MAGIC) + 9:
                raise LogFileError(f"{p}: {_NOT}: {st.st_size} bytes, cut inside its header record")
            op, length = struct.unpack("<BQ", head[len(MCAP_MAGIC):])
            if op != _OP_HEADER or length > min(_HEADER_MAX, st.st_size - len(head)) or length < 8:
                raise LogFileError(f"{p}: {_NOT}: its first record (byte {len(MCAP_MAGIC)}) is not a "
                                   f"header (opcode 0x{op:02x}, length {length}; a header is opcode 0x01)")
            body = f.read(length)
    except OSError as exc:
        raise LogFileError(f"{p}: cannot be read ({exc.strerror or exc})") from None
    strings = []
    pos = 0
    for _ in range(2):  # profile, library: uint32 length + UTF-8
        if pos + 4 > len(body):
            raise LogFileError(f"{p}: {_NOT}: its header record is malformed")
        (n,) = struct.unpack_from("<I", body, pos)
        raw = body[pos + 4: pos + 4 + n]
        if len(raw) != n:
            raise LogFileError(f"{p}: {_NOT}: its header record is malformed")
        strings.append(raw.decode("utf-8", "replace"))
        pos += 4 + n
    return LogHead(size=st.st_size, profile=strings[0], library=strings[1])


def check_log_content(path: str | os.PathLike, head: LogHead, sample_channels: int, has_metadata: bool) -> None:
    """Refuse an MCAP file that is not a uvms-mj log: no uvms-mj sample channel
    (``/state/true``, ``/control`` with their signal layout), no ``uvms_mj`` metadata and a header
    written by another library. A log of ours cut before its first flush (header only) passes."""
    if sample_channels or has_metadata or head.library.startswith("uvms_mj"):
        return
    by = f" (written by {head.library!r})" if head.library else ""
    raise LogFileError(f"{path}: {_NOT}: an MCAP file without uvms-mj channels or metadata{by}")
