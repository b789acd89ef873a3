"""The recorder's writer process: encoding, compression and file writes off the simulation's core.

After the first sample (written as always: the channels, the scene and the first flush, in this
process) :class:`~uvms_mj.io.writer.McapRecorder` forks (Linux, ``writer="process"``, the default
where it pays, see :func:`process_wanted`). The child is a copy of the recorder at that moment;
it receives the samples and writes them exactly as the recorder would have (the same code, the
same bytes, see ``tests/test_recorder.py``). The simulation's side of a sample is a shallow
copy of its row; every :data:`BATCH` samples the rows are packed column by column (each
array signal stacked into one block: pickling a dict of small arrays costs as much as encoding
it) and sent down a pipe, the automatic flushes with them.

The child ends when its pipe closes: after ``close`` (status record and summary written), or
when this process is gone (``kill -9``: the log ends at the child's last flush and reads as
truncated, as before). It ignores SIGINT (a terminal's Ctrl-C reaches the whole process group;
the recorder's owner closes the log) and takes no signal from the command line's watchdog.
An exception in the child (a full disk, a sample that cannot be encoded) comes back pickled and
is raised here: by the next batch's hand-off or by :meth:`_WriterProcess.close`, with the
child's traceback as a note. :meth:`~uvms_mj.io.writer.McapRecorder.flush` waits for the child's
flush; close waits for the child and reaps it. Sends and waits block SIGINT and SIGTERM (the
handlers run right after), so that a message is never cut in half.
"""

from __future__ import annotations

import operator
import os
import pickle
import signal
import sys
import traceback
import warnings
import weakref
from typing import TYPE_CHECKING, Any, Mapping

import numpy as np

if TYPE_CHECKING:
    from uvms_mj.io.writer import McapRecorder

__all__ = ["BATCH", "WRITER_MODES", "process_wanted"]

#: Samples per hand-off to the writer process (about 4 s of a 60 Hz run; the child encodes a
#: batch while the simulation makes the next).
BATCH = 256
#: The recorder's ``writer`` argument (and the ``UVMS_MJ_LOG_WRITER`` environment variable, which
#: overrides "auto").
WRITER_MODES = ("auto", "process", "inline")
_BLOCKED = {signal.SIGINT, signal.SIGTERM}
_DTYPE = operator.attrgetter("dtype")
_NDARRAY = {np.ndarray}


#: Set by :func:`mark_pool_worker` in a pool's worker that multiprocessing does not mark (a Ray task's
#: process); "auto" then writes inline.
_POOL_WORKER = False


def mark_pool_worker() -> None:
    """Mark this process as a pool's worker (Ray): "auto" writes inline here (the pool has the cores)."""
    global _POOL_WORKER
    _POOL_WORKER = True


def process_wanted(mode: str, flush_interval: float, live: Any) -> bool:
    """Whether a recorder writes through a writer process. ``mode`` "auto": where that pays, on
    Linux with 2 or more usable cores, a flush interval > 0 (0: each sample is written by its
    ``write_sample``), no live sink, and not inside a pool's worker process (multiprocessing,
    Ray: the pool already has the cores); "process" / "inline": always / never."""
    if mode not in WRITER_MODES:
        raise ValueError(f"writer = {mode!r}; allowed: {list(WRITER_MODES)}")
    if mode == "auto":
        env = os.environ.get("UVMS_MJ_LOG_WRITER", "auto").strip().lower() or "auto"
        if env not in WRITER_MODES:
            raise ValueError(f"UVMS_MJ_LOG_WRITER = {env!r}; allowed: {list(WRITER_MODES)}")
        mode = env
    if mode == "inline":
        return False
    if not (hasattr(os, "fork") and sys.platform.startswith("linux")):
        if mode == "process":
            raise ValueError("writer = 'process' needs os.fork (Linux)")
        return False
    if mode == "process":
        if live is not None:
            raise ValueError("writer = 'process' cannot feed a live sink (it is written inline)")
        return True
    mp = sys.modules.get("multiprocessing")
    worker = (mp is not None and mp.parent_process() is not None) or _POOL_WORKER
    try:
        cores = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        cores = os.cpu_count() or 1
    return cores >= 2 and flush_interval > 0 and live is None and not worker


# --------------------------------------------------------------------------- packing the rows


def _specs(first: Mapping[str, Any]) -> tuple[tuple[str, ...], list]:
    """The first row's signal order and, per signal, (shape, {dtype}) of an array signal of
    1 or more dimensions (packed as one stacked block) or None (sent as the list of values)."""
    order = tuple(first)
    specs = []
    for name in order:
        v = first[name]
        ok = type(v) is np.ndarray and v.ndim >= 1 and v.dtype.kind in "biuf"
        specs.append((v.shape, {v.dtype}) if ok else None)
    return order, specs


def _pack(rows: list, order: tuple[str, ...], specs: list) -> tuple:
    """Rows ``(t, row, same)`` as (times, regular rows' columns, the others as (index, row,
    same)); a regular row has the first row's signals in its order. An array column whose
    values are all arrays of its dtype and shape is stacked; any other column is its list."""
    ts = [r[0] for r in rows]
    reg = [i for i, r in enumerate(rows) if r[2] and tuple(r[1]) == order]
    others = [(i, r[1], r[2]) for i, r in enumerate(rows) if not (r[2] and tuple(r[1]) == order)] \
        if len(reg) < len(rows) else []
    regrows = [rows[i][1] for i in reg] if others else [r[1] for r in rows]
    cols = []
    n = len(regrows)
    for name, spec in zip(order, specs):
        col = [r[name] for r in regrows]
        if spec is not None and n:
            try:  # (not an array: no dtype; one of another shape: not the block's shape)
                if set(map(_DTYPE, col)) == spec[1]:
                    block = np.array(col)
                    if block.shape == (n,) + spec[0] and set(map(type, col)) == _NDARRAY:
                        cols.append(block)
                        continue
            except (AttributeError, TypeError, ValueError):
                pass
        cols.append(col)
    return ts, (reg if others else None), cols, others


def _unpack(packed: tuple, order: tuple[str, ...]) -> list:
    """The rows ``(t, row, same)`` of :func:`_pack`'s result (each block's rows are views of it)."""
    ts, reg, cols, others = packed
    vals = [list(c) for c in cols]  # a block: its rows (views); a list: itself
    regrows = [dict(zip(order, v)) for v in zip(*vals)] if vals else [{} for _ in (reg if reg is not None else ts)]
    if reg is None:
        return [(t, row, True) for t, row in zip(ts, regrows)]
    out: list = [None] * len(ts)
    for i, row in zip(reg, regrows):
        out[i] = (ts[i], row, True)
    for i, row, same in others:
        out[i] = (ts[i], row, same)
    return out


# --------------------------------------------------------------------------- the parent's side


#: The pipe to the child holds this many bytes (Linux ``F_SETPIPE_SZ``, at most the system's
#: ``/proc/sys/fs/pipe-max-size``, 1 MiB by default): several batches (a 256-sample batch of the 3-D
#: circle study is 287 KB). With the default 64 KiB a hand-off blocked until the child had encoded
#: the previous batch and started reading, so the simulation waited for the encoding it hands off.
PIPE_BYTES = 1 << 20


def _widen(fd: int) -> None:
    """Make the pipe ``fd`` hold :data:`PIPE_BYTES` (or the most allowed; unchanged where it cannot)."""
    try:
        import fcntl

        setsz = getattr(fcntl, "F_SETPIPE_SZ", 1031)  # (the constant is in fcntl from Python 3.10, Linux)
        try:
            with open("/proc/sys/fs/pipe-max-size") as f:
                limit = int(f.read())
        except (OSError, ValueError):
            limit = PIPE_BYTES
        fcntl.fcntl(fd, setsz, min(PIPE_BYTES, limit))
    except (ImportError, OSError, ValueError):
        pass  # the default size: slower hand-offs, the same log


def _surfaced(exc: BaseException, tb: str) -> BaseException:
    """The child's exception as raised here (picklable as it is, else a RuntimeError naming it)."""
    try:
        exc.add_note("in the log writer process:\n" + tb)
    except AttributeError:  # pragma: no cover - Python < 3.11
        pass
    try:
        return pickle.loads(pickle.dumps(exc))
    except Exception:  # noqa: BLE001 - an exception that does not pickle
        return RuntimeError(f"log writer process: {exc!r}\n{tb}")


class _WriterProcess:
    """The parent's side: batches rows, hands them to the child, surfaces its exceptions."""

    def __init__(self, rec: "McapRecorder", first: Mapping[str, Any]) -> None:
        from multiprocessing.connection import Connection

        self.rec = rec
        self.order, self.specs = _specs(first)
        self.batch: list = []
        self.navs: list = []
        self.error: BaseException | None = None
        self.dead = ""  # why the child ended unexpectedly (then nothing more is written)
        down_r, down_w = os.pipe()
        up_r, up_w = os.pipe()
        _widen(down_w)
        rec._file.flush()  # nothing of the file left in this process's buffer: the child writes it
        old = signal.pthread_sigmask(signal.SIG_BLOCK, _BLOCKED)
        try:
            with warnings.catch_warnings():  # (Python >= 3.12 warns of fork() in a threaded process)
                warnings.simplefilter("ignore", DeprecationWarning)
                pid = os.fork()
            if pid == 0:  # the child
                try:
                    os.close(down_w)
                    os.close(up_r)
                    _child(rec, self.order, Connection(down_r, writable=False),
                           Connection(up_w, readable=False), old)
                finally:
                    os._exit(0)
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, old)
        os.close(down_r)
        os.close(up_w)
        self.pid = pid
        self.down = Connection(down_w, readable=False)
        self.up = Connection(up_r, writable=False)
        self._finalizer = weakref.finalize(self, _reap, pid, self.down, self.up)

    # -- hand-off

    def add(self, item: tuple) -> None:
        self.batch.append(item)
        if len(self.batch) >= BATCH:
            self.send(False)

    def send(self, flush: bool, sync: bool = False) -> None:
        """Hand the pending rows (and navigation samples) to the child; with ``flush`` the child
        flushes after writing them; with ``sync`` wait until it has."""
        if self.dead:
            raise RuntimeError(self.dead)
        self._check()
        rows, self.batch = self.batch, []
        navs, self.navs = self.navs, []
        data = pickle.dumps(("batch", navs, _pack(rows, self.order, self.specs), flush, sync),
                            protocol=pickle.HIGHEST_PROTOCOL)
        self._talk(data, sync)

    def _check(self) -> None:
        """Raise the child's exception if one has come back (once)."""
        try:
            while self.up.poll():
                self._reply(self.up.recv_bytes())
        except (EOFError, OSError):
            self._died()
        if self.error is not None:
            exc, self.error = self.error, None
            raise exc

    def _reply(self, data: bytes):
        kind, *rest = pickle.loads(data)
        if kind == "error":
            if self.error is None:
                self.error = rest[0]
            return None
        return rest

    def _talk(self, data: bytes, wait: bool):
        """Send ``data``; with ``wait`` the child's answer (signals held back meanwhile)."""
        old = signal.pthread_sigmask(signal.SIG_BLOCK, _BLOCKED)
        try:
            try:
                self.down.send_bytes(data)
                while wait:
                    got = self._reply(self.up.recv_bytes())
                    if got is not None:
                        return got
            except (EOFError, OSError):
                self._died()
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, old)
        return None

    def _died(self):
        status = _reap(self.pid, self.down, self.up, block=True)
        self._finalizer.detach()
        self.dead = (f"the log writer process of {self.rec.path} ended unexpectedly ({status}); "
                     "the log is cut short (it reads as truncated)")
        raise RuntimeError(self.dead)

    # -- flush, close

    def flush(self) -> None:
        self.send(True, sync=True)
        self._check()

    def close(self, status: str, reason: str, meta: Mapping[str, Any] | None) -> str:
        """Write the rows left, then the child closes the log; returns the log's status."""
        if self.dead:  # (already raised): the log stays as the child left it
            self.rec.status = "truncated"
            return "truncated"
        rows, self.batch = self.batch, []
        navs, self.navs = self.navs, []
        try:
            data = pickle.dumps(("close", navs, _pack(rows, self.order, self.specs), status, reason, meta),
                                protocol=pickle.HIGHEST_PROTOCOL)
        except Exception:  # noqa: BLE001 - meta that does not pickle: its JSON text as the log stores it
            from uvms_mj.io.encoding import _meta_value

            import json

            meta = {k: json.loads(_meta_value(v)) for k, v in dict(meta or {}).items()}
            data = pickle.dumps(("close", navs, _pack(rows, self.order, self.specs), status, reason, meta),
                                protocol=pickle.HIGHEST_PROTOCOL)
        try:
            final, failed = self._talk(data, True)
            self.rec.status = final
        finally:
            if not self.dead:
                _reap(self.pid, self.down, self.up, block=True)
                self._finalizer.detach()
            self.rec._proc = None
        if failed is not None:
            raise failed
        if self.error is not None:  # an earlier write failed and was not raised yet
            exc, self.error = self.error, None
            raise exc
        return final


def _reap(pid: int, down, up, block: bool = True) -> str:
    """Close the pipes (the child ends at the end of its input) and wait for the child."""
    for conn in (down, up):
        try:
            conn.close()
        except OSError:
            pass
    try:
        _, code = os.waitpid(pid, 0 if block else os.WNOHANG)
    except ChildProcessError:
        return "already reaped"
    if os.WIFSIGNALED(code):
        return f"killed by signal {os.WTERMSIG(code)}"
    return f"exit status {os.waitstatus_to_exitcode(code)}"


# --------------------------------------------------------------------------- the child


def _keep_only(fds: set[int]) -> None:
    """Close the inherited descriptors other than ``fds`` and stdio (another recorder's file and
    lock, another writer's pipe: they would outlive their owners here)."""
    try:
        open_fds = [int(x) for x in os.listdir("/proc/self/fd")]
    except OSError:
        return
    for fd in open_fds:
        if fd > 2 and fd not in fds:
            try:
                os.close(fd)
            except OSError:
                pass


def _child(rec: "McapRecorder", order: tuple[str, ...], down, up, mask) -> None:
    from uvms_mj.io import interrupts

    try:
        signal.set_wakeup_fd(-1)  # the command line's watchdog pipe is the parent's
    except (ValueError, OSError):
        pass
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_SETMASK, mask)
    interrupts._critical_depth = 0
    interrupts._pending = None
    _keep_only({rec._file.fileno(), down.fileno(), up.fileno()})
    rec._proc = None
    told = False
    while True:
        try:
            data = down.recv_bytes()
        except (EOFError, OSError):
            return  # the parent is gone: the log ends at the last flush (truncated)
        msg = pickle.loads(data)
        if msg[0] == "close":
            failed = None
            try:
                try:
                    _take(rec, msg, order)
                finally:  # (rows that could not be taken: the log is closed all the same)
                    rec.close(msg[3], msg[4], msg[5])
            except Exception as exc:  # noqa: BLE001 - surfaced in the parent
                failed = _surfaced(exc, traceback.format_exc())
            up.send_bytes(pickle.dumps(("closed", rec.status, failed)))
            return
        try:
            _take(rec, msg, order)
            if msg[3]:
                rec.flush()
            else:
                rec._write_pending()
        except Exception as exc:  # noqa: BLE001 - surfaced in the parent at its next hand-off
            if not told:  # one unasked message at most: the parent reads it before its next send
                up.send_bytes(pickle.dumps(("error", _surfaced(exc, traceback.format_exc()))))
                told = True
        if msg[4]:
            up.send_bytes(pickle.dumps(("flushed",)))


def _take(rec: "McapRecorder", msg: tuple, order: tuple[str, ...]) -> None:
    """A message's navigation samples and rows, into the recorder's pending lists."""
    rec.__dict__.setdefault("_nav_pending", []).extend(msg[1])
    for t, row, same in _unpack(msg[2], order):
        ns = int(round(t * 1e9))
        rec._pending.append((t, ns, rec.samples, row, same))
        rec.samples += 1
        rec._last_ns = ns
