"""Export a log's per-sample signals as tables: CSV, Parquet, NumPy ``.npz`` or MATLAB ``.mat``.

``uvms-mj export LOG.mcap --format csv|parquet|npz|mat [--layout wide|channels] [-o PATH]``.

Layouts:

* ``wide`` (default): one table, one row per control sample: ``t`` [s], then every signal of
  :func:`uvms_mj.io.recorder.read_log` in the log's order (``/state/true`` first: ``q_true``,
  ``qd_true``, ``tip_true``; then ``/control``: ``p_desired``, ``e_p``, ``u_B``...).
* ``channels``: one table per sample channel of the log, ``state_true`` (``/state/true``) and
  ``control`` (``/control``), each with its own ``t`` column.

Columns: a scalar signal is one column named like the signal; a vector ``x`` of n values gives
``x[0]`` .. ``x[n-1]``; a matrix gives ``x[i,j]`` (row-major). Booleans are 0/1, NaN stays NaN
(empty in CSV). CSV and Parquet write one file per table: ``-o`` is the file (wide, default
``LOG.csv`` / ``LOG.parquet``) or the folder (channels, default ``LOG-export/``, files
``state_true.csv`` and ``control.csv``).

``npz`` and ``mat`` are one file (default ``LOG.npz`` / ``LOG.mat``) holding the arrays with
their logged shapes (no flattening): ``t`` and one array per signal (wide), or
``<channel>/<signal>`` keys (npz) and one struct per channel (mat), plus ``meta_json``, the
log's metadata and status as JSON text. MATLAB names must be identifiers: ``e_p`` stays
``e_p``; any other character becomes ``_``.

Parquet needs pyarrow and mat needs scipy: ``pip install 'uvms-mj[export]'``.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["FORMATS", "LAYOUTS", "ExportError", "export_log", "tables"]

FORMATS = ("csv", "parquet", "npz", "mat")
LAYOUTS = ("wide", "channels")
#: Table names of the sample channels.
CHANNEL_TABLES = {"/state/true": "state_true", "/control": "control"}


class ExportError(RuntimeError):
    """A format whose optional dependency is missing (one-line message saying what to install)."""


def _columns(name: str, arr: np.ndarray) -> list[tuple[str, np.ndarray]]:
    arr = np.asarray(arr)
    if arr.dtype == bool:
        arr = arr.astype(np.int8)
    if arr.ndim == 1:
        return [(name, arr)]
    flat = arr.reshape(len(arr), -1)
    shape = arr.shape[1:]
    out = []
    for j, idx in enumerate(np.ndindex(*shape)):
        out.append((f"{name}[{','.join(map(str, idx))}]", flat[:, j]))
    return out


def _groups(log) -> dict[str, list[str]]:
    """Signal names per table name, in the log's order."""
    from uvms_mj.io.schemas import STATE_SIGNALS

    names = list(log.signals)
    state = [n for n in names if n in STATE_SIGNALS]
    control = [n for n in names if n not in STATE_SIGNALS]
    return {"state_true": state, "control": control}


def tables(log, layout: str = "wide") -> dict[str, dict[str, np.ndarray]]:
    """Table name -> ordered column name -> 1-D array (see the module docstring)."""
    if layout not in LAYOUTS:
        raise ValueError(f"layout = {layout!r}: use one of {', '.join(LAYOUTS)}")
    t = np.asarray(log.t, dtype=float)
    groups = _groups(log)
    if layout == "wide":
        groups = {"wide": groups["state_true"] + groups["control"]}
    out = {}
    for table, names in groups.items():
        if not names and table != "wide":
            continue
        cols: dict[str, np.ndarray] = {"t": t}
        for n in names:
            cols.update(_columns(n, log.signals[n]))
        out[table] = cols
    return out


def _meta_json(log) -> str:
    meta = dict(getattr(log, "meta", {}) or {})
    meta["status"] = getattr(log, "status", None)
    meta["reason"] = getattr(log, "reason", None)
    return json.dumps(meta, default=str)


def _require(module: str, fmt: str):
    try:
        return __import__(module, fromlist=["_"])
    except ImportError:
        pkg = {"pyarrow": "pyarrow", "scipy.io": "scipy"}[module]
        raise ExportError(f"--format {fmt} needs {pkg}: pip install 'uvms-mj[export]' (or pip install {pkg})") \
            from None


def _write_csv(cols: dict[str, np.ndarray], path: Path) -> None:
    names = list(cols)
    data = np.column_stack([np.asarray(c, dtype=float) for c in cols.values()])
    with open(path, "w", encoding="utf-8", newline="") as f:
        f.write(",".join(f'"{n}"' if "," in n else n for n in names) + "\n")
        for row in data:
            f.write(",".join("" if np.isnan(v) else repr(float(v)) for v in row) + "\n")


def _write_parquet(cols: dict[str, np.ndarray], path: Path, meta: str) -> None:
    pa = _require("pyarrow", "parquet")
    pq = _require("pyarrow.parquet", "parquet")
    table = pa.table({k: np.asarray(v) for k, v in cols.items()})
    table = table.replace_schema_metadata({"uvms_mj": meta})
    pq.write_table(table, str(path))


def _mat_name(name: str) -> str:
    n = re.sub(r"[^A-Za-z0-9_]", "_", name)
    return n if re.match(r"[A-Za-z]", n) else "x_" + n


def export_log(log, fmt: str, out: str | Path | None = None, layout: str = "wide",
               log_path: str | Path | None = None) -> list[Path]:
    """Write ``log`` (a :func:`~uvms_mj.io.recorder.read_log` result) in ``fmt``; returns the files.

    Raises:
        ExportError: parquet without pyarrow, mat without scipy.
        ValueError: unknown format or layout.
    """
    if fmt not in FORMATS:
        raise ValueError(f"format = {fmt!r}: use one of {', '.join(FORMATS)}")
    if layout not in LAYOUTS:
        raise ValueError(f"layout = {layout!r}: use one of {', '.join(LAYOUTS)}")
    if fmt == "parquet":
        _require("pyarrow", fmt)
    if fmt == "mat":
        _require("scipy.io", fmt)
    stem = Path(log_path) if log_path is not None else Path("log.mcap")
    meta = _meta_json(log)
    if fmt in ("npz", "mat"):
        path = Path(out) if out else stem.with_suffix(f".{fmt}")
        path.parent.mkdir(parents=True, exist_ok=True)
        groups = _groups(log)
        t = np.asarray(log.t, dtype=float)
        if fmt == "npz":
            arrays: dict[str, Any] = {"meta_json": np.array(meta)}
            if layout == "wide":
                arrays["t"] = t
                arrays.update({n: np.asarray(log.signals[n]) for n in groups["state_true"] + groups["control"]})
            else:
                for table, names in groups.items():
                    arrays[f"{table}/t"] = t
                    arrays.update({f"{table}/{n}": np.asarray(log.signals[n]) for n in names})
            with open(path, "wb") as f:
                np.savez_compressed(f, **arrays)
        else:
            sio = _require("scipy.io", fmt)
            mdict: dict[str, Any] = {"meta_json": meta}
            if layout == "wide":
                mdict["t"] = t
                mdict.update({_mat_name(n): np.asarray(log.signals[n]) for n in groups["state_true"] + groups["control"]})
            else:
                for table, names in groups.items():
                    mdict[table] = {"t": t, **{_mat_name(n): np.asarray(log.signals[n]) for n in names}}
            sio.savemat(str(path), mdict, do_compression=True, oned_as="column")
        return [path]
    tabs = tables(log, layout)
    if layout == "wide":
        path = Path(out) if out else stem.with_suffix(f".{fmt}")
        path.parent.mkdir(parents=True, exist_ok=True)
        targets = {path: tabs["wide"]}
    else:
        folder = Path(out) if out else stem.with_name(stem.stem + "-export")
        folder.mkdir(parents=True, exist_ok=True)
        targets = {folder / f"{name}.{fmt}": cols for name, cols in tabs.items()}
    for path, cols in targets.items():
        if fmt == "csv":
            _write_csv(cols, path)
        else:
            _write_parquet(cols, path, meta)
    return list(targets)
