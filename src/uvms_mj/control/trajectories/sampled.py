"""Sampled trajectories: :class:`CsvTrajectory` (spline + slerp through CSV samples) and :func:`write_csv`."""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any

import numpy as np

from uvms_mj.control.trajectories.base import Trajectory, _suggest

__all__ = ["CsvTrajectory", "write_csv"]


# --------------------------------------------------------------------------- CSV


_CSV_POS = ("t", "x", "y", "z")
_CSV_QUAT = ("qw", "qx", "qy", "qz")
_BC_TYPES = ("not-a-knot", "natural", "clamped")


#: The longest line of a trajectory CSV [characters] (ours: a row of 8 numbers is below 200; a longer line,
#: e.g. 200 MB without a line end, is not a trajectory row and is refused without being read whole).
CSV_LINE_MAX = 10_000


def _read_csv(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    from uvms_mj.io.paths import InputFileError, LineTooLong, check_input_file, read_lines

    try:
        check_input_file(path, "a trajectory CSV file")  # a FIFO or /dev/zero: refused, not read
        lines, _ = read_lines(path, CSV_LINE_MAX)
    except InputFileError as exc:
        raise ValueError(f"trajectory.path = {str(path)!r}: {str(exc).split(': ', 1)[1]}") from None
    except LineTooLong as exc:
        raise ValueError(f"{exc}; not a trajectory row (t,x,y,z[,qw,qx,qy,qz])") from None
    except UnicodeDecodeError as exc:
        raise ValueError(f"{path}: not UTF-8 text (byte {exc.start}: {exc.reason})") from None
    except OSError as exc:
        raise ValueError(f"{path}: cannot be read ({exc.strerror or exc})") from None
    rows: list[tuple[int, list[str]]] = []
    for line_num, text in enumerate(lines, start=1):
        try:
            row = next(csv.reader([text]), [])
        except csv.Error as exc:
            raise ValueError(f"{path}, line {line_num}: {exc}") from None
        if not row or all(not c.strip() for c in row) or row[0].lstrip().startswith("#"):
            continue
        rows.append((line_num, row))
    if not rows:
        raise ValueError(f"{path}: empty file; expected a header row {','.join(_CSV_POS)}[,{','.join(_CSV_QUAT)}]")
    hline, header = rows[0]
    names = tuple(c.strip().lower() for c in header)
    if names not in (_CSV_POS, _CSV_POS + _CSV_QUAT):
        raise ValueError(
            f"{path}, line {hline}: header {','.join(c.strip() for c in header)!r} must be "
            f"{','.join(_CSV_POS)!r} or {','.join(_CSV_POS + _CSV_QUAT)!r}"
        )
    ncol = len(names)
    data = []
    prev_t, prev_line = None, None
    for line, row in rows[1:]:
        if len(row) != ncol:
            raise ValueError(f"{path}, line {line}: {len(row)} columns, expected {ncol} ({','.join(names)})")
        vals = []
        for j, (cell, name) in enumerate(zip(row, names)):
            try:
                x = float(cell)
            except ValueError:
                x = math.nan
            if not math.isfinite(x):
                raise ValueError(f"{path}, line {line}, column {j + 1} ({name}): {cell.strip()!r} is not a finite number")
            vals.append(x)
        if prev_t is not None and not vals[0] > prev_t:
            raise ValueError(
                f"{path}, line {line}, column 1 (t): {vals[0]!r} is not greater than the previous "
                f"t = {prev_t!r} (line {prev_line}); t must be strictly increasing"
            )
        if ncol == 8 and not any(vals[4:]):
            raise ValueError(f"{path}, line {line}, columns 5-8 (qw,qx,qy,qz): the zero quaternion has no attitude")
        prev_t, prev_line = vals[0], line
        data.append(vals)
    if len(data) < 2:
        raise ValueError(f"{path}: {len(data)} data row(s); a spline needs at least 2")
    arr = np.asarray(data, dtype=float)
    return arr[:, 0], arr[:, 1:4], (arr[:, 4:8] if ncol == 8 else None)


class CsvTrajectory(Trajectory):
    """Samples (t_k, p_k[, q_k]) from a CSV file, interpolated.

    File: a header row ``t,x,y,z`` or ``t,x,y,z,qw,qx,qy,qz`` (case and spaces ignored), then one
    row per sample, t strictly increasing [s], positions [m], quaternions (w, x, y, z) of any
    non-zero norm. Blank lines and lines starting with ``#`` are skipped. Bad rows raise
    ValueError naming the file, line and column.

    Position: a C2 cubic spline through the samples (``scipy.interpolate.CubicSpline``, end
    condition ``bc_type``, default not-a-knot); velocity and acceleration are its first and second
    derivatives. Outside [t_0, t_N] the trajectory holds the end sample, at rest (so velocity and
    acceleration jump there unless the data start and end at rest).

    Orientation: the quaternions are normalised and made sign-continuous (q_k -> -q_k when
    q_k . q_{k-1} < 0), then interpolated by slerp with the linear fraction u = (t - t_k)/(t_{k+1} - t_k)::

        q(t) = [sin((1-u) W) q_k + sin(u W) q_{k+1}] / sin W,   cos W = q_k . q_{k+1}

    (normalised linear interpolation when W < 1e-9), held at the ends.

    ``duration`` is t_N. Needs scipy (``pip install uvms-mj[export]`` or scipy itself).
    """

    def __init__(self, path: str | Path, *, bc_type: str = "not-a-knot") -> None:
        p = Path(path)
        t, pos, quat = _read_csv(p)
        self._init(t, pos, quat, bc_type, str(p))

    @classmethod
    def from_samples(
        cls,
        t: Any,
        positions: Any,
        quaternions: Any = None,
        *,
        bc_type: str = "not-a-knot",
    ) -> CsvTrajectory:
        """The same interpolation from arrays: t (N,), positions (N, 3), quaternions (N, 4) or None."""
        t = np.asarray(t, dtype=float)
        pos = np.asarray(positions, dtype=float)
        if t.ndim != 1 or len(t) < 2 or not np.all(np.isfinite(t)) or not np.all(np.diff(t) > 0):
            raise ValueError("samples: t must be at least 2 finite, strictly increasing times [s]")
        if pos.shape != (len(t), 3) or not np.all(np.isfinite(pos)):
            raise ValueError(f"samples: positions must be finite with shape ({len(t)}, 3), got {pos.shape}")
        q = None
        if quaternions is not None:
            q = np.asarray(quaternions, dtype=float)
            if q.shape != (len(t), 4) or not np.all(np.isfinite(q)) or np.any(np.linalg.norm(q, axis=1) == 0):
                raise ValueError(f"samples: quaternions must be finite, non-zero, shape ({len(t)}, 4)")
        obj = cls.__new__(cls)
        obj._init(t, pos, q, bc_type, "<samples>")
        return obj

    def _init(self, t: np.ndarray, pos: np.ndarray, quat: np.ndarray | None, bc_type: str, source: str) -> None:
        if bc_type not in _BC_TYPES:
            raise ValueError(f"trajectory.bc_type = {bc_type!r} must be one of {list(_BC_TYPES)}{_suggest(bc_type, _BC_TYPES)}")
        try:
            from scipy.interpolate import CubicSpline
        except ImportError as e:  # pragma: no cover - scipy is in the test and export extras
            raise ImportError("CsvTrajectory needs scipy: pip install scipy (or uvms-mj[export])") from e
        self.source = source
        self.bc_type = bc_type
        self.times = t.copy()
        self.samples = pos.copy()
        self._spline = CubicSpline(t, pos, axis=0, bc_type=bc_type)
        self._d1 = self._spline.derivative(1)
        self._d2 = self._spline.derivative(2)
        if quat is not None:
            q = quat / np.linalg.norm(quat, axis=1, keepdims=True)
            for k in range(1, len(q)):
                if np.dot(q[k], q[k - 1]) < 0:
                    q[k] = -q[k]
            self.quaternions: np.ndarray | None = q
        else:
            self.quaternions = None

    def __repr__(self) -> str:
        return f"CsvTrajectory({self.source!r}, {len(self.times)} samples, t in [{self.times[0]}, {self.times[-1]}])"

    @property
    def duration(self) -> float:
        return float(self.times[-1])

    @property
    def has_orientation(self) -> bool:
        return self.quaternions is not None

    def _clamped(self, t: Any) -> tuple[np.ndarray, np.ndarray]:
        t = np.asarray(t, dtype=float)
        inside = (t >= self.times[0]) & (t <= self.times[-1])
        return np.clip(t, self.times[0], self.times[-1]), inside

    def position(self, t: Any) -> np.ndarray:
        tc, _ = self._clamped(t)
        return self._spline(tc)

    def velocity(self, t: Any) -> np.ndarray:
        tc, inside = self._clamped(t)
        return self._d1(tc) * inside[..., None]

    def acceleration(self, t: Any) -> np.ndarray:
        tc, inside = self._clamped(t)
        return self._d2(tc) * inside[..., None]

    def orientation(self, t: Any) -> np.ndarray | None:
        if self.quaternions is None:
            return None
        tc, _ = self._clamped(t)
        ts, Q = self.times, self.quaternions
        k = np.clip(np.searchsorted(ts, tc, side="right") - 1, 0, len(ts) - 2)
        u = ((tc - ts[k]) / (ts[k + 1] - ts[k]))[..., None]
        q0, q1 = Q[k], Q[k + 1]
        cosw = np.clip(np.sum(q0 * q1, axis=-1, keepdims=True), -1.0, 1.0)
        w = np.arccos(cosw)
        sinw = np.sin(w)
        small = w < 1e-9
        safe = np.where(small, 1.0, sinw)
        a = np.where(small, 1.0 - u, np.sin((1.0 - u) * w) / safe)
        b = np.where(small, u, np.sin(u * w) / safe)
        q = a * q0 + b * q1
        return q / np.linalg.norm(q, axis=-1, keepdims=True)


def write_csv(path: str | Path, times: Any, positions: Any, quaternions: Any = None) -> None:
    """Write samples in the :class:`CsvTrajectory` format (full float precision, ``%.17g``)."""
    t = np.asarray(times, dtype=float)
    cols = [t[:, None], np.asarray(positions, dtype=float)]
    header = list(_CSV_POS)
    if quaternions is not None:
        cols.append(np.asarray(quaternions, dtype=float))
        header += list(_CSV_QUAT)
    np.savetxt(path, np.hstack(cols), delimiter=",", header=",".join(header), comments="", fmt="%.17g")
