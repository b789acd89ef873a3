"""A run's per-sample rows kept in arrays of the run's final size (the sampled loop's record).

The loop knows its number of samples before it starts (duration / T + 1), so each signal gets
one preallocated array (N, ...) and the rows are moved into it :data:`CHUNK` at a time (one
``np.asarray`` per signal and chunk, as fast as stacking the whole list at the end): memory is 8
bytes per float64 value plus one chunk of rows (a list of every sample's numpy arrays costs about
100 bytes of object overhead per value and was the loop's memory growth). The arrays are the ones
``np.asarray`` gives of the per-sample values (same dtype, shape and numbers): a chunk of a wider
dtype than its array's promotes the array (an int signal that later gives a float becomes
float64, as ``np.asarray`` of the list would); a row or chunk that does not fit (a signal
missing, new or of another shape, values that are not numbers) switches the record to a list of
rows, assembled at the end exactly as before (signals present in some rows only: the rows that
have them).
"""

from __future__ import annotations

import operator

import numpy as np

#: Rows moved into the arrays at a time [rows] (ours: ~2.5 MB of rows for the paper's 23 signals).
CHUNK = 1024


class SampleRecord:
    """Rows (signal name -> float, int, bool or numeric array) of up to ``n`` samples.

    :meth:`append` one row per sample, :meth:`signals` the arrays (first-appearance order of the
    names; ``len`` = the rows appended).
    """

    def __init__(self, n: int) -> None:
        if n < 0:
            raise ValueError(f"SampleRecord: n = {n!r} samples must be >= 0")
        self.n = int(n)
        self.k = 0  # rows appended
        self._keys: dict | None = None  # the first row's names, in order
        self._bufs: dict[str, np.ndarray] = {}  # name -> array (n, ...), rows [0, self._done) filled
        self._done = 0
        self._pending: list[dict] = []  # rows not yet in the arrays
        self._rows: list[dict] | None = None  # every row, once one did not fit the arrays

    def __len__(self) -> int:
        return self.k

    def append(self, row: dict) -> None:
        if self._rows is not None:
            self._rows.append(row)
        elif self.k >= self.n:
            raise IndexError(f"SampleRecord: more than its {self.n} rows")
        else:
            keys = self._keys
            if keys is None:
                self._keys = dict.fromkeys(row)
                self._order = list(row)
            elif list(row) != self._order and (len(row) != len(keys) or not keys.keys() >= row.keys()):
                self._to_rows()
                self._rows.append(row)
                self.k += 1
                return
            self._pending.append(row)
            if len(self._pending) >= CHUNK:
                self._flush()
        self.k += 1

    def _flush(self) -> None:
        """Move the pending rows into the arrays (or, if they do not fit, switch to rows)."""
        rows, a = self._pending, self._done
        if not rows:
            return
        m = len(rows)
        for key in self._keys:
            try:
                v = np.asarray(list(map(operator.itemgetter(key), rows)))
            except (ValueError, TypeError):  # ragged values
                self._to_rows()
                return
            buf = self._bufs.get(key)
            if v.dtype.kind not in "biuf" or (buf is not None and v.shape[1:] != buf.shape[1:]):
                self._to_rows()
                return
            if buf is None:
                buf = self._bufs[key] = np.empty((self.n,) + v.shape[1:], dtype=v.dtype)
            elif v.dtype != buf.dtype:
                wide = np.result_type(buf.dtype, v.dtype)
                if wide != buf.dtype:  # a wider chunk: the whole array widens, as np.asarray of the list
                    buf = self._bufs[key] = buf.astype(wide)
            buf[a:a + m] = v
        self._done = a + m
        self._pending = []

    def _to_rows(self) -> None:
        """From arrays to a list of rows: the rows in the arrays (as their numpy values), then the
        pending ones as given."""
        done, bufs = self._done, self._bufs
        self._rows = [{key: buf[i] for key, buf in bufs.items()} for i in range(done)] + self._pending
        self._bufs, self._pending, self._done = {}, [], 0

    def signals(self) -> dict[str, np.ndarray]:
        """name -> array (rows, ...)."""
        if self._rows is None:
            self._flush()
        if self._rows is None:
            k = self.k
            return {key: (buf if k == self.n else buf[:k].copy()) for key, buf in self._bufs.items()}
        rows = self._rows
        keys = dict.fromkeys(key for row in rows[:1] for key in row)  # first-appearance order
        uniform = True  # every row has the first row's signals
        for row in rows[1:]:
            if len(row) != len(keys) or not keys.keys() >= row.keys():
                keys.update(dict.fromkeys(row))
                uniform = False
        if uniform:
            return {key: np.asarray(list(map(operator.itemgetter(key), rows))) for key in keys}
        return {key: np.asarray([row[key] for row in rows if key in row]) for key in keys}
