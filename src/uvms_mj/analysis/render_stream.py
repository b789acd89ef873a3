"""A replay's log in memory that does not grow with the log's length (issue 23 item 1).

A video needs two things of a log: a summary of the whole run (the camera framed on the whole
motion, the drawn paths, the compare inset's errors) and, frame by frame, the state at the frame's
time (the interpolated ``qpos``, the tip now, the last tip sample before it). :func:`read_render_log`
reads the summary: the figures' min/max envelope of the :data:`RENDER_SIGNALS`
(:func:`uvms_mj.analysis.envelope.read_plot_log`: a log of at most
:data:`~uvms_mj.analysis.envelope.ENVELOPE_ROWS` samples whole, a longer one thinned to the
samples that hold each bucket's extremes) and the exact time span of each signal's finite samples
(:class:`FiniteSpans`). :class:`FrameStates` interpolates the frame states from the samples in
blocks, in time order: from the whole log at once when it was kept whole, else from a second
pass over the file (:func:`uvms_mj.io.reader.iter_samples`), one block in memory at a time.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field, fields
from typing import Callable, Iterable, Iterator

import numpy as np

from uvms_mj.analysis.envelope import PlotLog
from uvms_mj.analysis.render_overlay import _interp

__all__ = ["RENDER_BUCKETS", "RENDER_ROWS", "RENDER_SIGNALS", "FiniteSpans", "FrameStates", "RenderLog", "continuous_quaternions", "frame_states",
           "hold_single", "lerp_qpos", "read_render_log", "streamed_blocks"]

#: The signals a video reads of a log (the replayed q_true, the tip's trace and desired path, the
#: labels' and the compare inset's errors): ``render`` and ``run --video`` read only these.
RENDER_SIGNALS = ("q_true", "p_desired", "tip_true", "tip_desired", "base_desired", "e_p", "e_position")

#: The envelope's budget for a video (rows kept, buckets): the camera's framing samples ~40
#: configurations and 400 path points, the drawn paths keep ~300 points and the compare inset is
#: at most ~1300 px wide, so 500 buckets and 8000 rows (a 133 s log at 60 Hz kept whole) are
#: ample; ours, smaller than the figures' (:data:`uvms_mj.analysis.envelope.ENVELOPE_ROWS`).
RENDER_ROWS = 8000
RENDER_BUCKETS = 500

#: The signals each replay streams again from a long log's file (its frame states).
_STREAMED_ROBOT = ("q_true", "tip_true", "tip_desired")
_STREAMED_PAPER = ("q_true", "tip_true", "p_desired")

#: Series name -> (times (n,) [s], values (n, k)) of one block: the valid samples of each series.
Series = dict[str, tuple[np.ndarray, np.ndarray]]


class FiniteSpans:
    """The time span [s] of each signal's finite samples (a finite time and every value of the row
    finite), accumulated block by block: ``spans[name] = (first, last)``."""

    def __init__(self) -> None:
        self.spans: dict[str, tuple[float, float]] = {}

    def add(self, t: np.ndarray, signals: dict) -> None:
        t = np.asarray(t, dtype=float).ravel()
        if not len(t):
            return
        for name, v in signals.items():
            a = np.asarray(v)
            if a.dtype.kind not in "biuf" or len(a) != len(t):
                continue
            ok = np.isfinite(t) & np.isfinite(a.reshape(len(a), -1)).all(axis=1)
            if not ok.any():
                continue
            idx = np.flatnonzero(ok)
            first, last = float(t[idx[0]]), float(t[idx[-1]])
            old = self.spans.get(name)
            self.spans[name] = (first, last) if old is None else (old[0], last)

    def span(self, names: Iterable[str]) -> tuple[float, float] | None:
        """(latest first, earliest last) over the named signals that have finite samples, or None."""
        got = [self.spans[n] for n in names if n in self.spans]
        if not got:
            return None
        return max(s[0] for s in got), min(s[1] for s in got)


@dataclass
class RenderLog(PlotLog):
    """What :func:`read_render_log` gives: the figures' :class:`PlotLog` and ``finite_spans``
    (a :class:`FiniteSpans` over every sample of the log)."""

    finite_spans: FiniteSpans = field(default_factory=FiniteSpans)


def read_render_log(path: str | os.PathLike, signals: Iterable[str] = RENDER_SIGNALS, rows: int | None = None,
                    buckets: int | None = None) -> RenderLog:
    """The log at ``path`` as a video reads it, in bounded memory: the figures' envelope of
    ``signals`` (:func:`~uvms_mj.analysis.envelope.read_plot_log`) and the finite spans of
    every sample, in one pass; a log kept whole (``bucket == 1``) is replayed from these arrays,
    a thinned one streams its frames from ``path`` again (:func:`streamed_blocks`). ``rows``,
    ``buckets``: the envelope's budget (default :data:`RENDER_ROWS`, :data:`RENDER_BUCKETS`). Raises what
    :func:`uvms_mj.io.reader.iter_samples` raises for a file that is not a log."""
    from uvms_mj.analysis.envelope import read_plot_log

    spans = FiniteSpans()
    log = read_plot_log(path, signals=signals, rows=RENDER_ROWS if rows is None else rows,
                        buckets=RENDER_BUCKETS if buckets is None else buckets,
                        on_block=lambda block: spans.add(block.t, block.signals))
    return RenderLog(**{f.name: getattr(log, f.name) for f in fields(PlotLog)}, finite_spans=spans)


def streamed_blocks(log, signals: Iterable[str]) -> Iterator[tuple[np.ndarray, dict]] | None:
    """(t, signals) blocks of a thinned :func:`read_render_log` log read again from its file, or
    None for a log held whole (a run, :func:`~uvms_mj.io.recorder.read_log`'s log, a log kept whole)."""
    path = getattr(log, "path", "")
    if getattr(log, "bucket", 1) <= 1 or not path:
        return None
    from uvms_mj.io.reader import iter_samples

    return ((b.t, b.signals) for b in iter_samples(path, signals=list(signals)))


def _streamed_span(log, names: Iterable[str]) -> tuple[float, float] | None:
    """(first, last) time [s] of the named signals' finite samples over the whole file of a log
    whose frames are streamed (:func:`streamed_blocks`), else None (the arrays at hand are the
    whole log)."""
    spans = getattr(log, "finite_spans", None)
    if getattr(log, "bucket", 1) <= 1 or not isinstance(spans, FiniteSpans):
        return None
    return spans.span(names)


def continuous_quaternions(q: np.ndarray, quat_slots: list[int], previous: np.ndarray | None = None) -> np.ndarray:
    """A copy of ``qpos`` samples q (N, nq) with each quaternion's sign chosen nearest the
    previous sample's (``previous``: the sample before q[0], already continuous), so that no
    interpolation between samples goes the long way round."""
    q = np.array(q, dtype=float)
    for a in quat_slots:
        block = q[:, a:a + 4]
        before = None if previous is None else previous[a:a + 4]
        for k in range(len(block)):
            ref = before if k == 0 else block[k - 1]
            if ref is not None and block[k] @ ref < 0:
                block[k] = -block[k]
    return q


def lerp_qpos(t: np.ndarray, ts: np.ndarray, q: np.ndarray, quat_slots: list[int]) -> np.ndarray:
    """``qpos`` samples q (N, nq) at ts whose quaternions are already continuous
    (:func:`continuous_quaternions`), interpolated at times t (M,): every value linearly (clamped
    at the ends), then each quaternion normalised (normalised linear interpolation)."""
    out = _interp(t, ts, q)
    for a in quat_slots:
        n = np.linalg.norm(out[:, a:a + 4], axis=1, keepdims=True)
        out[:, a:a + 4] /= np.where(n > 0, n, 1.0)
    return out


def hold_single(series: Series, dt: float) -> Series:
    """A replay of a single sample (``series["q"]`` has one) held for ``dt`` [s], a still picture
    of one frame: every series' sample repeated at t + dt (a series without one unchanged); any
    other replay unchanged."""
    if len(series["q"][0]) != 1:
        return series
    return {k: (np.r_[t, t + dt], np.vstack([x, x])) if len(t) else (t, x) for k, (t, x) in series.items()}


class _Track:
    """One series' frames: the tail sample of the blocks so far and the frames computed."""

    def __init__(self, quat_slots: list[int]) -> None:
        self.quats = quat_slots
        self.t_tail: np.ndarray | None = None
        self.x_tail: np.ndarray | None = None
        self.done = 0
        self.now: list[np.ndarray] = []
        self.last: list[np.ndarray] = []

    def feed(self, frame_t: np.ndarray, ts: np.ndarray, x: np.ndarray, final: bool = False) -> None:
        """Add a block's valid samples; compute the frames up to its last sample (all on ``final``)."""
        if len(ts):
            x = continuous_quaternions(x, self.quats, None if self.x_tail is None else self.x_tail[-1])
            if self.t_tail is not None:
                ts, x = np.r_[self.t_tail, ts], np.vstack([self.x_tail, x])
        elif self.t_tail is not None:
            ts, x = self.t_tail, self.x_tail
        if not len(ts):
            if final:  # never a valid sample: every frame without a value
                n = len(frame_t) - self.done
                self.now.append(np.full((n, 0), np.nan))
                self.last.append(np.full((n, 0), np.nan))
                self.done = len(frame_t)
            return
        end = len(frame_t) if final else int(np.searchsorted(frame_t, ts[-1], side="right"))
        if end > self.done:
            tf = frame_t[self.done:end]
            now = lerp_qpos(tf, ts, x, self.quats)
            k = np.searchsorted(ts, tf, side="right") - 1  # the last sample at or before each frame
            last = x[np.maximum(k, 0)].copy()
            last[k < 0] = np.nan
            self.now.append(now)
            self.last.append(last)
            self.done = end
        self.t_tail, self.x_tail = ts[-1:].copy(), x[-1:].copy()

    def take(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        now, last = np.concatenate(self.now), np.concatenate(self.last)
        self.now, self.last = [now[n:]], [last[n:]]
        return now[:n], last[:n]


class FrameStates:
    """The states of a replay at its frame times from blocks of samples in time order.

    ``series_of(t, signals) -> {name: (times, values)}`` gives, for one block, the valid samples
    of each series the replay draws (its masks and derived series: the replay's own rule, applied
    alike to a whole log and to a block). Iterating :meth:`run` yields one dict per frame:
    ``name -> (now, last)``: the series linearly interpolated at the frame's time (clamped before
    the first and after the last valid sample; each quaternion of ``quat_slots[name]`` by
    normalised linear interpolation after :func:`continuous_quaternions`) and its last valid
    sample at or before the frame's time (NaN before the first). Memory: one block, the frames it
    completes and, for a series without valid samples over a stretch, the frames of that stretch.
    """

    def __init__(self, frame_t: np.ndarray, quat_slots: dict[str, list[int]] | None = None) -> None:
        self.frame_t = np.asarray(frame_t, dtype=float)
        self.quat_slots = dict(quat_slots or {})

    def run(self, blocks: Iterable[Series]) -> Iterator[dict[str, tuple[np.ndarray, np.ndarray]]]:
        frame_t, tracks, sent = self.frame_t, {}, 0
        for series in blocks:
            for name, (ts, x) in series.items():
                track = tracks.get(name)
                if track is None:
                    track = tracks[name] = _Track(self.quat_slots.get(name, []))
                track.feed(frame_t, np.asarray(ts, dtype=float), np.asarray(x, dtype=float))
            if tracks:
                ready = min(tr.done for tr in tracks.values())
                if ready > sent:
                    yield from self._emit(tracks, ready - sent)
                    sent = ready
        for track in tracks.values():
            track.feed(frame_t, np.zeros(0), np.zeros((0, 0)), final=True)
        if len(frame_t) > sent:
            yield from self._emit(tracks, len(frame_t) - sent)

    @staticmethod
    def _emit(tracks: dict[str, _Track], n: int) -> Iterator[dict[str, tuple[np.ndarray, np.ndarray]]]:
        got = {name: tr.take(n) for name, tr in tracks.items()}
        for i in range(n):
            yield {name: (now[i], last[i]) for name, (now, last) in got.items()}


def frame_states(frame_t: np.ndarray, log, whole: Series, signals: Iterable[str],
                 series_of: Callable[[np.ndarray, dict], Series],
                 quat_slots: dict[str, list[int]] | None = None) -> Iterator[dict]:
    """The frames' states (:class:`FrameStates`) of ``log``: from ``whole`` (its series at hand)
    when the log is held whole, else from its file's blocks of ``signals`` (those it has;
    :func:`streamed_blocks`) through ``series_of``."""
    stream = streamed_blocks(log, [k for k in signals if k in log.signals])
    blocks = [whole] if stream is None else (series_of(t, sig) for t, sig in stream)
    return FrameStates(frame_t, quat_slots).run(blocks)
