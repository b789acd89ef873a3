"""A run's per-sample rows kept in arrays of the run's final size (the sampled loop's record).

The loop knows its number of samples before it starts (duration / T + 1), so each signal gets
one preallocated array (N, ...) at the first row and every later row is written into it: memory
is 8 bytes per float64 value and nothing else (a list of per-sample numpy arrays costs about
100 bytes of object overhead per value and was the loop's memory growth). The arrays are the
ones ``np.asarray`` gives of the per-sample values (same dtype, shape and numbers): a value of a
wider dtype than its array's promotes the array (an int signal that later gives a float becomes
float64, as ``np.asarray`` of the list would); a row that does not fit (a signal missing, new or
of another shape, a value that is not a number or a numeric array) switches the record to a list
of rows, assembled at the end exactly as before (signals present in some rows only: the rows
that have them).
"""

from __future__ import annotations

import operator

import numpy as np

#: The dtype np.asarray gives a list of Python scalars of one type.
_PY_DTYPES = {float: np.dtype(np.float64), int: np.dtype(np.int64), bool: np.dtype(np.bool_)}


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
        self._slots: dict[str, list] | None = None  # name -> [array (n, ...), dtype, shape]
        self._rows: list[dict] | None = None  # the rows, once one did not fit the arrays

    def __len__(self) -> int:
        return self.k

    def append(self, row: dict) -> None:
        if self._rows is not None:
            self._rows.append(row)
        elif self.k >= self.n:
            raise IndexError(f"SampleRecord: more than its {self.n} rows")
        elif self._slots is None:
            if not self._start(row):
                self._rows = [row]
        elif not self._put(row):
            self._to_rows()
            self._rows.append(row)
        self.k += 1

    def _start(self, row: dict) -> bool:
        slots = {}
        for key, v in row.items():
            a = np.asarray(v)
            if a.dtype.kind not in "biuf":
                return False
            buf = np.empty((self.n,) + a.shape, dtype=a.dtype)
            buf[0] = a
            slots[key] = [buf, a.dtype, a.shape]
        self._slots = slots
        return True

    def _put(self, row: dict) -> bool:
        slots, k = self._slots, self.k
        if len(row) != len(slots):
            return False
        for key, v in row.items():
            slot = slots.get(key)
            if slot is None:
                return False
            tv = type(v)
            if tv is np.ndarray or isinstance(v, np.generic):
                if v.shape != slot[2]:
                    return False
                dt = v.dtype
            elif tv in _PY_DTYPES:
                if slot[2] != ():
                    return False
                dt = _PY_DTYPES[tv]
            else:
                return False
            if dt != slot[1]:
                if dt.kind not in "biuf":
                    return False
                wide = np.result_type(slot[1], dt)
                if wide != slot[1]:  # a wider value: the whole array widens, as np.asarray of the list
                    slot[0] = slot[0].astype(wide)
                    slot[1] = wide
            try:
                slot[0][k] = v
            except (OverflowError, ValueError, TypeError):
                return False
        return True

    def _to_rows(self) -> None:
        """From arrays to a list of rows (the rows so far, as numpy values of the arrays)."""
        k, slots = self.k, self._slots or {}
        self._rows = [{key: slot[0][i] for key, slot in slots.items()} for i in range(k)]
        self._slots = None

    def signals(self) -> dict[str, np.ndarray]:
        """name -> array (rows, ...)."""
        if self._rows is None:
            k = self.k
            return {key: (slot[0] if k == self.n else slot[0][:k].copy()) for key, slot in (self._slots or {}).items()}
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
