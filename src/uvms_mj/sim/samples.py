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

Streaming (``on_block`` given): nothing is kept. Each chunk of rows, as soon as it is complete
(and the rest at :meth:`SampleRecord.signals`), is handed to ``on_block(start, rows, signals)``
(the index of its first row, its number of rows, name -> array of the chunk) and dropped; the
arrays are reused for the next chunk, so the callback must copy what it keeps. A chunk whose rows
do not fit arrays is handed in as the list of rows would assemble it. Memory: one chunk.
"""

from __future__ import annotations

import operator
from typing import Callable

import numpy as np

#: Rows moved into the arrays at a time [rows] (ours: ~2.5 MB of rows for the paper's 23 signals).
CHUNK = 1024


class SampleRecord:
    """Rows (signal name -> float, int, bool or numeric array) of up to ``n`` samples.

    :meth:`append` one row per sample, :meth:`signals` the arrays (first-appearance order of the
    names; ``len`` = the rows appended).
    """

    def __init__(self, n: int, on_block: Callable[[int, int, dict], None] | None = None) -> None:
        if n < 0:
            raise ValueError(f"SampleRecord: n = {n!r} samples must be >= 0")
        self.n = int(n)
        self.on_block = on_block
        self._start = 0  # streaming: the index of the pending chunk's first row
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
                if self.on_block is not None:  # streaming: the rows before as one block, then these signals
                    self._flush()
                    self._keys, self._order, self._bufs = dict.fromkeys(row), list(row), {}
                    self._pending.append(row)
                    self.k += 1
                    return
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
        stream = self.on_block is not None
        for key in self._keys:
            try:
                v = np.asarray(list(map(operator.itemgetter(key), rows)))
            except (ValueError, TypeError):  # ragged values
                if stream:
                    return self._hand_on(m, _assemble(rows))
                self._to_rows()
                return
            buf = self._bufs.get(key)
            if v.dtype.kind not in "biuf" or (buf is not None and v.shape[1:] != buf.shape[1:]):
                if stream:
                    return self._hand_on(m, _assemble(rows))
                self._to_rows()
                return
            if buf is None:
                size = min(self.n, CHUNK) if stream else self.n
                buf = self._bufs[key] = np.empty((size,) + v.shape[1:], dtype=v.dtype)
            elif v.dtype != buf.dtype:
                wide = np.result_type(buf.dtype, v.dtype)
                if wide != buf.dtype:  # a wider chunk: the whole array widens, as np.asarray of the list
                    buf = self._bufs[key] = buf.astype(wide)
            buf[a:a + m] = v
        if stream:
            return self._hand_on(m, {key: buf[:m] for key, buf in self._bufs.items() if key in self._keys})
        self._done = a + m
        self._pending = []

    def _hand_on(self, m: int, block: dict) -> None:
        """Streaming: the pending chunk (``m`` rows, ``block``) to on_block, then dropped."""
        self._pending = []
        start, self._start = self._start, self._start + m
        self.on_block(start, m, block)

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
        if self.on_block is not None:  # streaming: every row was handed on
            return {}
        if self._rows is None:
            k = self.k
            return {key: (buf if k == self.n else buf[:k].copy()) for key, buf in self._bufs.items()}
        return _assemble(self._rows)


def _assemble(rows: list[dict]) -> dict[str, np.ndarray]:
    """name -> array of a list of rows (first-appearance order of the names; a signal present in
    some rows only: the rows that have it)."""
    keys = dict.fromkeys(key for row in rows[:1] for key in row)
    uniform = True  # every row has the first row's signals
    for row in rows[1:]:
        if len(row) != len(keys) or not keys.keys() >= row.keys():
            keys.update(dict.fromkeys(row))
            uniform = False
    if uniform:
        return {key: np.asarray(list(map(operator.itemgetter(key), rows))) for key in keys}
    return {key: np.asarray([row[key] for row in rows if key in row]) for key in keys}
