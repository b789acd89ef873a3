"""SIGTERM and SIGINT while a log is written: :func:`handle_sigterm` turns them into
KeyboardInterrupt (:class:`Terminated` for SIGTERM) and holds them back while a recorder is in a
critical section (writing a sample, closing), so that a log never ends in half a record."""

from __future__ import annotations

import signal
import sys
import threading
from contextlib import contextmanager
from typing import Iterator

_critical_depth = 0
_pending: BaseException | None = None


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

    def on_signal(signum, frame):  # noqa: ARG001
        global _pending
        if signum == signal.SIGTERM:
            exc: BaseException = Terminated("terminated by SIGTERM")
        else:
            exc = KeyboardInterrupt("interrupted by SIGINT")
        if _critical_depth:
            if _pending is None:
                _pending = exc
            return
        raise exc

    old = {signal.SIGTERM: signal.signal(signal.SIGTERM, on_signal)}
    if sigint:
        old[signal.SIGINT] = signal.signal(signal.SIGINT, on_signal)
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


