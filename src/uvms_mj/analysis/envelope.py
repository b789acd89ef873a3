"""A log read for its figures in memory that does not grow with the run's length (issue 23 item 1).

:func:`read_plot_log` reads a log block by block (:func:`uvms_mj.io.reader.iter_samples`) and keeps
a min/max envelope of its samples: the samples are cut into buckets of ``size`` consecutive ones
and, of each bucket, the first and the last sample are kept and, for every column of every signal
read and of every tracking error the figures draw (:func:`tracking_errors` / :func:`robot_errors`
of the block, and their norms), the sample of its smallest value, of its largest value and its
first NaN. A log of at most :data:`ENVELOPE_ROWS` samples is kept whole (``size`` 1); beyond,
``size`` is the smallest power of two that gives at most :data:`ENVELOPE_BUCKETS` buckets, doubled
again while more than ``ENVELOPE_ROWS`` samples would be kept (noisy signals, whose extremes fall on
different samples). Merging two buckets is exact: the extremes of the merged bucket are among the
samples kept of its halves. So every line of a signal's column, an error's column or an error's
norm drawn from the result has, over each bucket, the minimum and maximum of the full line (a peak
or a saturation is never lost; what is lost is the order of the values inside one bucket, about a
pixel column of a panel) and the memory is bounded by ``ENVELOPE_ROWS`` rows, whatever the duration.
Lines computed otherwise (the attitude in degrees from quaternions) are drawn through the same
samples.

The numbers the figures print (RMS, max of each error) come from the whole log: sums of squares,
counts and maxima accumulated block by block (:class:`uvms_mj.analysis.plots.common.ErrorStats`,
``log.error_stats``).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Iterable

import numpy as np

from uvms_mj.analysis.series import ErrorStats, ErrorSums, robot_of, _select, robot_errors, tracking_errors

__all__ = ["ENVELOPE_BUCKETS", "ENVELOPE_ROWS", "PlotLog", "read_plot_log"]

#: The most samples :func:`read_plot_log` keeps [samples] (ours: 32 000, at most about 50 MB for the
#: BlueROV2 + Alpha's ~90 plotted columns and ~100 selection columns; a paper run of up to 533 s is
#: kept whole).
ENVELOPE_ROWS = 32_000
#: The most buckets of the envelope (ours: as many as :func:`uvms_mj.analysis.plots.common.decimate`
#: draws per line, finer than a pixel column of a panel ~700 px wide).
ENVELOPE_BUCKETS = 1000


@dataclass
class PlotLog:
    """What :func:`read_plot_log` gives: a log as the figures read it (``t``, ``signals``, ``meta``,
    ``status``, ``reason``) with the samples of the envelope, ``samples`` (how many the log has),
    ``bucket`` (the envelope's bucket size [samples]; 1: every sample kept) and ``error_stats`` (the
    whole log's error statistics, key -> :class:`ErrorStats`)."""

    t: np.ndarray
    signals: dict
    meta: dict
    status: str = "unknown"
    reason: str = ""
    truncated: bool = False
    path: str = ""
    samples: int = 0
    bucket: int = 1
    error_stats: dict[str, ErrorStats] = field(default_factory=dict)


def _columns(n: int, signals: dict, errors: dict) -> np.ndarray:
    """(n, C) float matrix of every numeric column of the block's signals, its errors and their norms."""
    cols = []
    for v in list(signals.values()) + list(errors.values()):
        a = np.asarray(v)
        if a.dtype.kind not in "biuf" or a.ndim == 0:
            continue
        cols.append(a.reshape(len(a), -1).astype(float, copy=False))
    for e in errors.values():
        e = np.asarray(e, dtype=float)
        cols.append(np.linalg.norm(e.reshape(len(e), -1), axis=1)[:, None])
    return np.concatenate(cols, axis=1) if cols else np.zeros((n, 0))


@dataclass
class _Part:
    """Consecutive kept samples: their indices in the log, times, signals and selection columns."""

    index: np.ndarray
    t: np.ndarray
    signals: dict
    K: np.ndarray

    def take(self, keep) -> "_Part":
        return _Part(self.index[keep], self.t[keep], {k: v[keep] for k, v in self.signals.items()}, self.K[keep])

    def then(self, other: "_Part") -> "_Part":
        return _Part(np.concatenate([self.index, other.index]), np.concatenate([self.t, other.t]),
                     {k: np.concatenate([v, other.signals[k]]) for k, v in self.signals.items()},
                     np.concatenate([self.K, other.K]))


class _Envelope:
    """The streaming envelope (module docstring): ``add`` each block in order, then :meth:`result`.
    What is kept is a list of parts whose buckets are complete and the last bucket's samples (the
    tail, which the next block may extend); a block is selected together with the tail only, and
    a coarser bucket selects the parts again one at a time, so no step copies everything kept."""

    def __init__(self, rows: int, buckets: int) -> None:
        self.rows, self.buckets = rows, buckets
        self.size = 1
        self.n = 0
        self.parts: list[_Part] = []
        self.tail: _Part | None = None
        self.done = 0  # samples kept in the parts

    @property
    def kept(self) -> int:
        return self.done + (len(self.tail.index) if self.tail is not None else 0)

    def add(self, t: np.ndarray, signals: dict, K: np.ndarray) -> None:
        m = len(t)
        part = _Part(np.arange(self.n, self.n + m, dtype=np.int64), np.asarray(t),
                     {k: np.asarray(v) for k, v in signals.items()}, K)
        self.n += m
        if self.size == 1 and self.n <= self.rows:  # a short log: every sample kept (buckets of one)
            self.parts.append(part)
            self.done += m
            return
        size = self.size
        while -(-self.n // size) > self.buckets:
            size *= 2
        if size != self.size:
            self._rebuild(size)
        self._push(part)
        while self.kept > self.rows and self.size < self.n:  # noisy signals: fewer, wider buckets
            self._rebuild(2 * self.size)

    def _push(self, part: _Part) -> None:
        """Select ``part`` (after the tail) at the current size; all but its last bucket is done."""
        if self.tail is not None:
            part = self.tail.then(part)
        part = part.take(_select(part.index, part.K, self.size))
        b = part.index // self.size
        split = int(np.searchsorted(b, b[-1]))  # the first sample of the last bucket
        if split:
            self.parts.append(part.take(slice(0, split)))
            self.done += split
        self.tail = part.take(slice(split, None))

    def _rebuild(self, size: int) -> None:
        """Coarser buckets: the kept samples selected again, part by part."""
        parts = self.parts + ([self.tail] if self.tail is not None else [])
        self.parts, self.tail, self.done, self.size = [], None, 0, size
        parts.reverse()
        while parts:
            self._push(parts.pop())  # each part freed once selected

    def result(self, layout: dict) -> tuple[np.ndarray, np.ndarray, dict]:
        """(index, t, signals) of the kept samples; no sample: empty arrays of ``layout``
        (name -> (dtype, shape))."""
        parts = self.parts + ([self.tail] if self.tail is not None else [])
        if not parts:
            return (np.zeros(0, dtype=np.int64), np.zeros(0),
                    {name: np.zeros((0,) + tuple(shape), dtype=dtype) for name, (dtype, shape) in layout.items()})
        names = list(parts[0].signals)
        index = np.concatenate([p.index for p in parts])
        t = np.concatenate([p.t for p in parts])
        for p in parts:
            p.K = None  # type: ignore[assignment]
        signals = {}
        for name in names:
            signals[name] = np.concatenate([p.signals[name] for p in parts])
            for p in parts:
                del p.signals[name]
        self.parts, self.tail = [], None
        return index, t, signals


def read_plot_log(path: str | os.PathLike, signals: Iterable[str] | None = None, rows: int = ENVELOPE_ROWS,
                  buckets: int = ENVELOPE_BUCKETS, on_block=None) -> PlotLog:
    """The log at ``path`` as its figures need it, in bounded memory (module docstring).

    Args:
        path: an MCAP log of :class:`uvms_mj.io.recorder.McapRecorder`.
        signals: the signals to read (default: :data:`uvms_mj.analysis.plots.PLOT_SIGNALS`).
        rows: the most samples kept (>= 64).
        buckets: the most buckets of the envelope (>= 8).
        on_block: called with every block of samples read (:class:`uvms_mj.io.reader.SampleBlock`),
            for what another reader accumulates in the same pass (a video's finite spans).

    Raises what :func:`uvms_mj.io.reader.iter_samples` raises for a file that is not a log. A log
    whose robot is recorded after its first samples (none of ours) gets the paper's error kinds.
    """
    from uvms_mj.io.reader import LogStream, iter_samples

    if rows < 64 or buckets < 8:
        raise ValueError(f"read_plot_log: rows = {rows!r}, buckets = {buckets!r}; allowed: rows >= 64, buckets >= 8")
    if signals is None:
        from uvms_mj.analysis.plots import PLOT_SIGNALS

        signals = PLOT_SIGNALS
    st = LogStream()
    env = _Envelope(rows, buckets)
    sums = ErrorSums()
    errors_of = None
    for block in iter_samples(path, signals=list(signals), stream=st):
        if errors_of is None:
            errors_of = robot_errors if robot_of(st) is not None else tracking_errors
        if on_block is not None:
            on_block(block)
        errs = errors_of(_Block(block.t, block.signals, st.meta))
        sums.add(errs)
        env.add(block.t, block.signals, _columns(len(block.t), block.signals, errs))
    _, t, sig = env.result(st.layout or {})
    return PlotLog(t=t, signals=sig, meta=st.meta, status=st.status, reason=st.reason, truncated=st.truncated,
                   path=str(path), samples=env.n, bucket=env.size, error_stats=sums.stats())


@dataclass
class _Block:
    """A block as the error functions read a log."""

    t: np.ndarray
    signals: dict
    meta: dict
