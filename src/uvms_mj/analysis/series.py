"""A log's series as the figures, the videos and the tables read them, without matplotlib:
signal access, the tracking errors (desired minus true, SI units) of the paper's robot
(:func:`tracking_errors`) and of any floating robot (:func:`robot_errors`, :func:`attitude_error`),
the statistics the figures print (:class:`ErrorStats`, accumulated block by block by
:class:`ErrorSums`) and the bucket selection that keeps every bucket's extremes (:func:`_select`:
what :func:`uvms_mj.analysis.plots.common.decimate` keeps of a line and
:mod:`uvms_mj.analysis.envelope` of a log)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

__all__ = ["ErrorStats", "ErrorSums", "attitude_error", "error_stats", "robot_errors", "robot_of", "tracking_errors"]


def _sig(log, name: str) -> np.ndarray | None:
    signals = getattr(log, "signals", None) or {}
    try:
        if name not in signals:
            return None
        arr = np.asarray(signals[name], dtype=float)
    except (KeyError, TypeError, ValueError):
        return None
    if arr.size == 0 or len(arr) != len(np.asarray(log.t)):
        return None
    return arr


def robot_of(log) -> dict | None:
    """The log's robot description (``meta["robot"]``) when it is a robot log (name not
    "paper"), else None (the paper's planar robot)."""
    meta = getattr(log, "meta", None)
    robot = meta.get("robot") if isinstance(meta, Mapping) else None
    if not isinstance(robot, Mapping) or robot.get("name") in (None, "", "paper"):
        return None
    return dict(robot)


def _firsts(rows: np.ndarray, pos: np.ndarray) -> np.ndarray:
    """Of the rows (sorted indices into the bucket positions ``pos``), the first of each bucket."""
    if not len(rows):
        return rows
    p = pos[rows]
    return rows[np.r_[True, p[1:] != p[:-1]]]


def _select(index: np.ndarray, K: np.ndarray, size: int) -> np.ndarray:
    """Positions (sorted) of the samples to keep: per bucket ``index // size`` (``index``: the
    samples' increasing indices, consecutive or not) its first and last sample and, per column of
    K (n, C), its first smallest, first largest and first NaN value. What :func:`decimate` keeps of a
    line and :mod:`uvms_mj.analysis.envelope` of a log."""
    n = len(index)
    if not n:
        return np.zeros(0, dtype=np.int64)
    b = index // size
    new = np.r_[True, b[1:] != b[:-1]]
    starts = np.flatnonzero(new)
    pos = np.cumsum(new) - 1  # each sample's bucket (0 ...)
    picks = [starts, np.r_[starts[1:] - 1, n - 1]]
    for c in range(K.shape[1]):
        v = K[:, c]
        nan = np.isnan(v)
        lo = np.minimum.reduceat(np.where(nan, np.inf, v), starts)
        hi = np.maximum.reduceat(np.where(nan, -np.inf, v), starts)
        picks.append(_firsts(np.flatnonzero(v == lo[pos]), pos))
        picks.append(_firsts(np.flatnonzero(v == hi[pos]), pos))
        if nan.any():
            picks.append(_firsts(np.flatnonzero(nan), pos))
    return np.unique(np.concatenate(picks))


def _quat_rows(q: np.ndarray) -> np.ndarray:
    """Unit quaternions (N, 4) (w x y z); a zero row stays NaN."""
    n = np.linalg.norm(q, axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return q / n


def attitude_error(q_desired: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Rotation vector [rad] (N, 3), BODY frame, that turns the true attitude ``q`` into the
    desired ``q_desired`` (quaternions w x y z, (N, 4)): log(q^-1 q_desired), angle in [0, pi]."""
    a, b = _quat_rows(q), _quat_rows(q_desired)
    w1, v1 = a[:, 0], -a[:, 1:]  # conj(q)
    w2, v2 = b[:, 0], b[:, 1:]
    w = w1 * w2 - np.sum(v1 * v2, axis=1)
    v = w1[:, None] * v2 + w2[:, None] * v1 + np.cross(v1, v2)
    sign = np.where(w < 0, -1.0, 1.0)[:, None]  # the short way round
    w, v = np.abs(w), v * sign
    s = np.linalg.norm(v, axis=1)
    angle = 2 * np.arctan2(s, w)
    with np.errstate(invalid="ignore", divide="ignore"):
        scale = np.where(s > 1e-12, angle / np.where(s > 1e-12, s, 1.0), 2.0)
    return v * scale[:, None]


def robot_errors(log) -> dict[str, np.ndarray]:
    """Desired minus true of a robot log, SI units: 'base' (N, 3) [m] world, 'att' (N, 3)
    [rad] body-frame rotation vector, 'tip' (N, 3) [m] world. From ``base_desired`` and
    ``tip_desired`` against the true state, else the controller's ``e_position`` /
    ``e_attitude``; keys missing when not logged."""
    q, bd, td, tip = _sig(log, "q_true"), _sig(log, "base_desired"), _sig(log, "tip_desired"), _sig(log, "tip_true")
    out: dict[str, np.ndarray] = {}
    if q is not None and q.shape[1] >= 7 and bd is not None and bd.shape[1] >= 7:
        out["base"] = bd[:, :3] - q[:, :3]
        out["att"] = attitude_error(bd[:, 3:7], q[:, 3:7])
    else:
        for key, name in (("base", "e_position"), ("att", "e_attitude")):
            e = _sig(log, name)
            if e is not None and e.ndim == 2 and e.shape[1] == 3:
                out[key] = e
    if td is not None and tip is not None and td.shape[1:] == tip.shape[1:] == (3,) and np.isfinite(tip).any():
        out["tip"] = td - tip
    return out


def tracking_errors(log) -> dict[str, np.ndarray]:
    """Desired minus true, SI units: 'base' (N, 2) [m], 'att' (N,) [rad], 'tip' (N, 2) [m]
    (keys missing when a signal is absent)."""
    pd, q, tip = _sig(log, "p_desired"), _sig(log, "q_true"), _sig(log, "tip_true")
    out: dict[str, np.ndarray] = {}
    if pd is not None and q is not None:
        out["base"] = pd[:, :2] - q[:, :2]
        out["att"] = pd[:, 2] - q[:, 2]
    if pd is not None and tip is not None and pd.shape[1] >= 5:
        out["tip"] = pd[:, 3:5] - tip
    return out


@dataclass(frozen=True)
class ErrorStats:
    """The statistics a figure prints of one tracking error (N, m) (or (N,): m = 1), over its finite
    values [the error's units]: per column ``rms`` and ``absmax`` (max |e_j|), and of the row norm
    |e| its ``norm_rms`` and ``norm_max`` (NaN where nothing is finite)."""

    rms: tuple[float, ...]
    absmax: tuple[float, ...]
    norm_rms: float
    norm_max: float


class ErrorSums:
    """:class:`ErrorStats` of errors given block by block (``add`` a dict key -> array per block,
    then ``stats()``): sums of squares, counts and maxima, so the result is that of the whole
    arrays (to rounding: the sums are added in block order)."""

    def __init__(self) -> None:
        self._acc: dict[str, list] = {}

    def add(self, errors: Mapping[str, np.ndarray]) -> None:
        for key, e in errors.items():
            e = np.asarray(e, dtype=float)
            e = e.reshape(len(e), -1)
            ok = np.isfinite(e)
            z = np.where(ok, e, 0.0)
            norm = np.linalg.norm(e, axis=1)
            nok = np.isfinite(norm)
            part = [np.sum(z * z, axis=0), ok.sum(axis=0),
                    np.max(np.where(ok, np.abs(e), -np.inf), axis=0, initial=-np.inf),
                    float(np.sum(np.square(norm[nok]))), int(nok.sum()),
                    float(np.max(norm[nok], initial=-np.inf))]
            acc = self._acc.get(key)
            if acc is None or len(acc[0]) != e.shape[1]:
                self._acc[key] = part
                continue
            acc[0], acc[1], acc[2] = acc[0] + part[0], acc[1] + part[1], np.maximum(acc[2], part[2])
            acc[3], acc[4], acc[5] = acc[3] + part[3], acc[4] + part[4], max(acc[5], part[5])

    def stats(self) -> dict[str, ErrorStats]:
        nan = float("nan")
        out = {}
        for key, (ss, n, mx, nss, nn, nmx) in self._acc.items():
            rms = tuple(float(np.sqrt(s / c)) if c else nan for s, c in zip(ss, n))
            absmax = tuple(float(v) if c else nan for v, c in zip(mx, n))
            out[key] = ErrorStats(rms, absmax, float(np.sqrt(nss / nn)) if nn else nan, nmx if nn else nan)
        return out


def error_stats(log, errors: Mapping[str, np.ndarray]) -> dict[str, ErrorStats]:
    """The statistics of a log's errors the figures print: the log's own ``error_stats`` where it
    has them (:func:`uvms_mj.analysis.envelope.read_plot_log`: of the whole log, whose samples
    it has thinned), else those of ``errors`` (the arrays the figure draws)."""
    given = getattr(log, "error_stats", None)
    if isinstance(given, Mapping) and set(errors) <= set(given):
        return dict(given)
    sums = ErrorSums()
    sums.add(errors)
    return sums.stats()
