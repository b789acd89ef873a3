"""SIGTERM and SIGINT: :func:`handle_sigterm` turns them into KeyboardInterrupt (:class:`Terminated`
for SIGTERM) and holds them back while a recorder is in a critical section (writing a sample,
closing), so that a log never ends in half a record; :func:`partial_output` marks a file being
written under its final name, removed if the write does not finish; :func:`cli_signals` is the
command line's policy (the orderly path above, and a watchdog that ends the process with exit
130 :data:`GRACE_S` after the signal whatever the main thread is doing).

The command line's contract (README, exit code 130): SIGINT or SIGTERM at any moment ends the
process with 130 within 2 s; every output finished before the signal is kept, and no file is
left half-written under its final name (a log is closed with status "interrupted", or, when its
close is cut short, stays readable and is called truncated). Before the interpreter runs any of
our code (the first ~0.05 s of a process) Python's default applies."""

from __future__ import annotations

import _thread
import os
import signal
import sys
import threading
import time
from collections.abc import Callable
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

#: The exit code of an interrupted command (= uvms_mj.cli.common.EXIT_INTERRUPTED).
_EXIT_INTERRUPTED = 130
_critical_depth = 0
_pending: BaseException | None = None
#: A SIGINT or SIGTERM has arrived since :func:`cli_signals` (or :func:`handle_sigterm`) started.
_signalled = False
#: True while the command line's watchdog is armed: signals after the first are left to it.
_watchdog_armed = False
#: Files being written under their final name: absolute path -> (nesting depth).
_partial: dict[str, int] = {}
#: Called (in the main thread, from the signal handler) when the first signal arrives, before its
#: exception is raised: e.g. a sweep's stop flag, so that its workers start no further run.
_on_interrupt: list[Callable[[], None]] = []

#: The interrupt :func:`_unraisable` caught where Python drops exceptions, for the handler's next
#: call (:func:`_on_signal`) to raise again.
_again: BaseException | None = None
#: The unraisable hook :func:`_unraisable` hands everything else to.
_previous_unraisable: Callable | None = None

#: Seconds the orderly path (the log's close, a sweep's table) gets after the first SIGINT/SIGTERM
#: before the command line's watchdog ends the process anyway (exit 130, files being written
#: removed, child processes killed). Ours: 1.5 s leaves 0.5 s of the 2 s promised for the forced
#: exit and the signal's delivery; a second signal ends the process at once.
GRACE_S = 1.5


class Terminated(KeyboardInterrupt):
    """Raised (inside :func:`handle_sigterm`) when the process gets SIGTERM."""


def _deliver_pending() -> None:
    global _pending
    if _critical_depth == 0 and _pending is not None:
        exc, _pending = _pending, None
        raise exc


class _CriticalSection:
    """A section that the handlers of :func:`handle_sigterm` do not interrupt (the signal's
    exception is raised when the section ends). Reentrant; one shared instance (a class rather
    than a generator: it is entered at every sample)."""

    __slots__ = ()

    def __enter__(self) -> None:
        global _critical_depth
        _critical_depth += 1

    def __exit__(self, exc_type, exc, tb) -> None:
        global _critical_depth
        _critical_depth -= 1
        _deliver_pending()


_CRITICAL = _CriticalSection()


def _critical() -> _CriticalSection:
    """The critical section (``with _critical(): ...``), see :class:`_CriticalSection`."""
    return _CRITICAL


def signalled() -> bool:
    """Whether a SIGINT or SIGTERM arrived since the handlers were installed."""
    return _signalled


def _unraisable(args) -> None:
    """``sys.unraisablehook`` once a signal has been handled: our interrupt, raised by the handler
    where Python cannot propagate an exception (a signal that lands inside a finalizer, a weakref
    callback or ``__del__``: Python would print "Exception ignored in ..." and drop it, and the
    command would go on), is raised again: ``_thread.interrupt_main`` runs the handler in the main
    thread 1 ms later (:func:`_interrupt_soon`), which raises it (:func:`_on_signal`; should that
    be inside another finalizer, the same happens again). Anything else goes to the hook that was
    there before."""
    global _again
    exc = args.exc_value
    signum = getattr(exc, "uvms_mj_signal", None)
    if signum is not None and threading.current_thread() is threading.main_thread():
        _again = exc
        _interrupt_soon(signum)
        return
    (_previous_unraisable or sys.__unraisablehook__)(args)


#: How long after :func:`_unraisable` the interrupt is raised again [s] (ours: 1 ms, time for the
#: hook to return; the handler checks that it has).
_AGAIN_S = 0.001


def _interrupt_soon(signum: int) -> None:
    """Run the handler of ``signum`` in the main thread :data:`_AGAIN_S` from now (a timer thread:
    a handler tripped from the main thread itself would run inside the hook, or inside itself)."""
    timer = threading.Timer(_AGAIN_S, _thread.interrupt_main, (signum,))
    timer.daemon = True
    timer.start()


def _in_hook(frame) -> bool:
    """Whether ``frame`` runs inside :func:`_unraisable` (where a raise would be dropped again)."""
    while frame is not None:
        if frame.f_code is _unraisable.__code__:
            return True
        frame = frame.f_back
    return False


def _hook_unraisable() -> None:
    global _previous_unraisable
    if sys.unraisablehook is not _unraisable:
        _previous_unraisable = sys.unraisablehook
        sys.unraisablehook = _unraisable


def _on_signal(signum, frame) -> None:  # noqa: ARG001
    """The orderly handler: KeyboardInterrupt (Terminated for SIGTERM), held back inside a
    critical section; with the watchdog armed, later signals are the watchdog's (the orderly
    path is not interrupted again). An interrupt Python dropped (:func:`_unraisable`) is raised
    again by the next call."""
    global _pending, _signalled, _again
    if _again is not None:
        if _in_hook(frame):  # still inside _unraisable: once it has returned
            _interrupt_soon(signum)
            return
        exc, _again = _again, None
        if _critical_depth:
            if _pending is None:
                _pending = exc
            return
        raise exc
    if _signalled and _watchdog_armed:
        return
    first = not _signalled
    _signalled = True
    if first:
        for hook in list(_on_interrupt):
            try:
                hook()
            except Exception:  # noqa: BLE001 - a hook never stops the interrupt
                pass
    if signum == signal.SIGTERM:
        exc: BaseException = Terminated("terminated by SIGTERM")
    else:
        exc = KeyboardInterrupt("interrupted by SIGINT")
    exc.uvms_mj_signal = signum  # type: ignore[attr-defined]  (for _unraisable)
    _hook_unraisable()
    if _critical_depth:
        if _pending is None:
            _pending = exc
        return
    raise exc


@contextmanager
def handle_sigterm(sigint: bool = True) -> Iterator[None]:
    """Turn SIGTERM into :class:`Terminated` (a KeyboardInterrupt) while the block runs, so that
    ``with`` blocks (an :class:`McapRecorder`) close cleanly; the old handlers come back after.

    With ``sigint`` (default) SIGINT is handled the same way (raising KeyboardInterrupt). Either
    signal arriving while a recorder is writing a sample or closing is held back until that
    write is over, so a log is never left with half a record. Outside the main thread (where
    Python cannot set handlers) this does nothing.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = {signal.SIGTERM: signal.signal(signal.SIGTERM, _on_signal)}
    if sigint:
        old[signal.SIGINT] = signal.signal(signal.SIGINT, _on_signal)
    try:
        yield
    finally:
        global _pending
        for sig, handler in old.items():
            # None: a handler not set from Python, which cannot be put back; use the default.
            signal.signal(sig, signal.SIG_DFL if handler is None else handler)
        held, _pending = _pending, None
        if held is not None and sys.exc_info()[0] is None:
            raise held  # a signal held back by the last write: deliver it now


def _stat(path: str):
    try:
        st = os.stat(path)
    except OSError:
        return None
    return (st.st_ino, st.st_size, st.st_mtime_ns)


@contextmanager
def partial_output(path: str | os.PathLike) -> Iterator[Path]:
    """Mark ``path`` as being written under its final name while the block runs: if the block
    does not finish (an interrupt, an error) the file is removed when the block wrote to it (a
    file the block never touched is left alone), and the command line's watchdog removes it if
    it ends the process first. Reentrant; yields ``Path(path)``."""
    key = os.path.abspath(path)
    before = _stat(key)
    _partial[key] = _partial.get(key, 0) + 1
    ok = False
    try:
        yield Path(path)
        ok = True
    finally:
        depth = _partial.pop(key, 1) - 1
        if depth > 0:
            _partial[key] = depth
        if not ok and _stat(key) != before:
            try:
                os.unlink(key)
            except OSError:
                pass


#: Children left alone by :func:`exit_now`: Ray's reaper, which ends the local Ray cluster's
#: process group (its workers included) when this process is gone.
_KEEP_CHILDREN = (b"ray_process_reaper",)


def _kids(pid: int | str) -> list[int]:
    kids: list[int] = []
    try:
        for task in os.listdir(f"/proc/{pid}/task"):
            with open(f"/proc/{pid}/task/{task}/children", encoding="ascii") as f:
                kids += [int(k) for k in f.read().split()]
    except OSError:
        pass
    return kids


def _children() -> list[int]:
    """This process's descendants to kill, parents first (Linux: /proc; elsewhere none known):
    a sweep's workers, ffmpeg, a local Ray cluster's processes and their workers and agents;
    not those of :data:`_KEEP_CHILDREN`."""
    out: list[int] = []
    todo = _kids("self")
    while todo:
        pid = todo.pop(0)
        try:
            with open(f"/proc/{pid}/cmdline", "rb") as f:
                cmd = f.read()
        except OSError:
            continue
        if pid in out or any(k in cmd for k in _KEEP_CHILDREN):
            continue
        out.append(pid)
        todo += _kids(pid)
    return out


def exit_now(message: bool = True) -> None:
    """End the process now with exit 130: files still being written removed (they are not
    finished), child processes killed, stdout and stderr flushed, no atexit handlers and no
    interpreter teardown (which can take a second after a sweep). The command line calls it
    once an interrupted command has unwound, and its watchdog when that takes too long."""
    for path in list(_partial):
        try:
            os.unlink(path)
        except OSError:
            pass
    for pid in _children():
        try:
            os.kill(pid, signal.SIGKILL)
        except OSError:
            pass
    try:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except Exception:  # noqa: BLE001 - a closed or broken stream
                pass
        if message:
            os.write(2, b"interrupted\n")
    finally:
        os._exit(_EXIT_INTERRUPTED)


def _force_exit() -> None:
    exit_now(message=True)


def _watch(fd: int) -> None:
    """The watchdog's thread: the signal numbers that Python's C-level handler writes to the
    wakeup fd (whatever the main thread is doing); GRACE_S after the first SIGINT/SIGTERM, or
    at the second, the process ends (:func:`_force_exit`)."""
    import select

    deadline = None
    wanted = {int(signal.SIGINT), int(signal.SIGTERM)}
    while True:
        timeout = None if deadline is None else max(0.0, deadline - time.monotonic())
        ready, _, _ = select.select([fd], [], [], timeout)
        if not ready:
            if _watchdog_armed:
                _force_exit()
            deadline = None
            continue
        try:
            data = os.read(fd, 512)
        except OSError:
            continue
        if not _watchdog_armed or not wanted & set(data):
            continue
        if deadline is None:
            deadline = time.monotonic() + GRACE_S
        else:
            _force_exit()


_watch_fd: int | None = None


def _arm_watchdog() -> int:
    """Start the watchdog thread once; return the write end of its pipe (non-blocking)."""
    global _watch_fd
    if _watch_fd is None:
        r, w = os.pipe()
        os.set_blocking(w, False)
        threading.Thread(target=_watch, args=(r,), name="uvms-mj-signal-watchdog", daemon=True).start()
        _watch_fd = w
    return _watch_fd


@contextmanager
def cli_signals(watchdog: bool = True) -> Iterator[None]:
    """The command line's signal policy while a command runs (main thread only): SIGINT and
    SIGTERM raise KeyboardInterrupt (:func:`_on_signal`, so logs close and commands exit 130),
    and with ``watchdog`` (the installed command's own process, never a test runner's) the
    process is ended GRACE_S after the first signal, or at the second, if it has not ended."""
    global _signalled, _watchdog_armed
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _signalled = False
    fd = None
    if watchdog:  # the thread started first, under the start-up policy (a signal while it starts: exit 130 there)
        try:
            fd = _arm_watchdog()
        except (ValueError, OSError):
            fd = None
    old = {sig: signal.signal(sig, _on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
    old_fd = None
    if fd is not None:
        try:
            old_fd = signal.set_wakeup_fd(fd, warn_on_full_buffer=False)
            _watchdog_armed = True
        except (ValueError, OSError):
            old_fd = None
    try:
        yield
    finally:
        # After a signal the process is ending (exit 130): the handlers and the watchdog stay,
        # so that a slow shutdown (thread joins, atexit) is still ended GRACE_S after the signal.
        if not (_signalled and _watchdog_armed):
            for sig, handler in old.items():
                signal.signal(sig, signal.SIG_DFL if handler is None else handler)
            if _watchdog_armed:
                _watchdog_armed = False
                signal.set_wakeup_fd(old_fd if old_fd is not None else -1)
