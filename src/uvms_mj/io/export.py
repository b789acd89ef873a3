"""Export a log's per-sample signals as tables: CSV, Parquet, NumPy ``.npz`` or MATLAB ``.mat``.

``uvms-mj export LOG.mcap --format csv|parquet|npz|mat [--layout wide|channels] [-o PATH]``.

Layouts:

* ``wide`` (default): one table, one row per control sample: ``t`` [s], then every signal of
  :func:`uvms_mj.io.recorder.read_log` in the log's order (``/state/true`` first: ``q_true``,
  ``qd_true``, ``tip_true``; then ``/control``: ``p_desired``, ``e_p``, ``u_B``...).
* ``channels``: one table per sample channel of the log, ``state_true`` (``/state/true``) and
  ``control`` (``/control``), each with its own ``t`` column.

Columns: a scalar signal is one column named like the signal; a vector ``x`` gives one column
per component, named from the robot's layout in the log's metadata (``--columns named``, the
default): ``q_true[base_x]``, ``q_true[base_qw]``, ``q_true[alpha_shoulder]``, ``tip_true[z]``,
``thrust_force[bluerov2_t7]``, ``torques[joint1]``, ``u_B[fx]``, ``e_p[tip_y]``... (the names of
each signal: :mod:`uvms_mj.io.columns`); where a name is unknown (a signal not in that table, a
size that does not match the layout), the component's index: ``x[0]`` .. ``x[n-1]``, as
``--columns index`` gives for every signal. A matrix gives ``x[i,j]`` (row-major). Booleans are
0/1, NaN stays NaN (empty in CSV). CSV and Parquet write one file per table: ``-o`` is the file (wide, default
``LOG.csv`` / ``LOG.parquet``) or the folder (channels, default ``LOG-export/``, files
``state_true.csv`` and ``control.csv``).

``npz`` and ``mat`` are one file (default ``LOG.npz`` / ``LOG.mat``) holding the arrays with
their logged shapes (no flattening): ``t`` and one array per signal (wide), or
``<channel>/<signal>`` keys (npz) and one struct per channel (mat), plus ``meta_json``, the
log's metadata and status as JSON text, and ``columns_json``, each signal's component names
(JSON: signal -> list of names, null where unknown; Parquet files carry it in their schema
metadata as ``uvms_mj_columns``). MATLAB names must be identifiers: ``e_p`` stays ``e_p``; any
other character becomes ``_``.

:func:`to_dataframe` (or ``read_log(path, as_dataframe=True)``) gives the wide table as a pandas
DataFrame indexed by ``t`` [s], with the same column names, booleans as bool, and the log's
metadata in ``df.attrs["meta"]`` (``status``, ``reason`` too); pandas is in the ``[export]`` extra.

Parquet needs pyarrow, mat scipy, DataFrames pandas: ``pip install 'uvms-mj[export]'``.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import numpy as np

from uvms_mj.io.atomic import atomic_open, atomic_path
from uvms_mj.io.interrupts import partial_output

__all__ = ["COLUMNS", "FORMATS", "LAYOUTS", "OUTPUT_KIND", "ExportError", "export_log", "export_paths", "tables",
           "to_dataframe"]

FORMATS = ("csv", "parquet", "npz", "mat")
LAYOUTS = ("wide", "channels")
#: Column naming: by the robot's layout (index where unknown), or by index everywhere.
COLUMNS = ("named", "index")
#: The kind of output file (:data:`uvms_mj.io.paths.OUTPUT_KINDS`) of each format.
OUTPUT_KIND = {"csv": "CSV table", "parquet": "Parquet file", "npz": "npz file", "mat": "mat file"}
#: Table names of the sample channels.
CHANNEL_TABLES = {"/state/true": "state_true", "/control": "control"}


class ExportError(RuntimeError):
    """A format whose optional dependency is missing (one-line message saying what to install)."""


def _columns(name: str, arr: np.ndarray, labels: list[str] | None = None,
             keep_bool: bool = False) -> list[tuple[str, np.ndarray]]:
    arr = np.asarray(arr)
    if arr.dtype == bool and not keep_bool:
        arr = arr.astype(np.int8)
    if arr.ndim == 1:
        return [(name, arr)]
    if labels is not None and arr.ndim == 2 and len(labels) == arr.shape[1]:
        return [(f"{name}[{label}]", arr[:, j]) for j, label in enumerate(labels)]
    flat = arr.reshape(len(arr), -1)
    shape = arr.shape[1:]
    out = []
    for j, idx in enumerate(np.ndindex(*shape)):
        out.append((f"{name}[{','.join(map(str, idx))}]", flat[:, j]))
    return out


def _labels(log, columns: str) -> dict[str, list[str] | None]:
    if columns not in COLUMNS:
        raise ValueError(f"columns = {columns!r}: use one of {', '.join(COLUMNS)}")
    if columns == "index":
        return {}
    from uvms_mj.io.columns import component_names

    return component_names(log)


def _groups(log) -> dict[str, list[str]]:
    """Signal names per table name, in the log's order."""
    from uvms_mj.io.schemas import STATE_SIGNALS

    names = list(log.signals)
    state = [n for n in names if n in STATE_SIGNALS]
    control = [n for n in names if n not in STATE_SIGNALS]
    return {"state_true": state, "control": control}


def tables(log, layout: str = "wide", columns: str = "named",
           keep_bool: bool = False) -> dict[str, dict[str, np.ndarray]]:
    """Table name -> ordered column name -> 1-D array (see the module docstring); ``columns``:
    "named" (by the robot's layout) or "index"; ``keep_bool``: booleans as bool (else 0/1)."""
    if layout not in LAYOUTS:
        raise ValueError(f"layout = {layout!r}: use one of {', '.join(LAYOUTS)}")
    labels = _labels(log, columns)
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
            cols.update(_columns(n, log.signals[n], labels.get(n), keep_bool))
        out[table] = cols
    return out


def to_dataframe(log, columns: str = "named"):
    """The wide table as a pandas DataFrame indexed by ``t`` [s] (module docstring).

    Raises:
        ExportError: pandas is not installed (one line saying what to install).
    """
    try:
        import pandas as pd
    except ImportError:
        raise ExportError("DataFrames need pandas: pip install 'uvms-mj[export]' (or pip install pandas)") from None
    cols = tables(log, "wide", columns, keep_bool=True)["wide"]
    t = cols.pop("t")
    df = pd.DataFrame(cols, index=pd.Index(t, name="t"))
    df.attrs["meta"] = dict(getattr(log, "meta", {}) or {})
    df.attrs["status"] = getattr(log, "status", None)
    df.attrs["reason"] = getattr(log, "reason", None)
    return df


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
    with atomic_open(path, "w", encoding="utf-8", newline="") as f:
        f.write(",".join(f'"{n}"' if "," in n else n for n in names) + "\n")
        for row in data:
            f.write(",".join("" if np.isnan(v) else repr(float(v)) for v in row) + "\n")


def _write_parquet(cols: dict[str, np.ndarray], path: Path, meta: str, names: str) -> None:
    pa = _require("pyarrow", "parquet")
    pq = _require("pyarrow.parquet", "parquet")
    table = pa.table({k: np.asarray(v) for k, v in cols.items()})
    table = table.replace_schema_metadata({"uvms_mj": meta, "uvms_mj_columns": names})
    with atomic_path(path) as tmp:
        pq.write_table(table, str(tmp))


def _mat_name(name: str) -> str:
    n = re.sub(r"[^A-Za-z0-9_]", "_", name)
    return n if re.match(r"[A-Za-z]", n) else "x_" + n


def export_paths(fmt: str, out: str | Path | None = None, layout: str = "wide",
                 log_path: str | Path | None = None) -> list[Path]:
    """The files :func:`export_log` may write (to check them before reading the log): one file,
    or for channels csv/parquet one per sample channel in the folder."""
    stem = Path(log_path) if log_path is not None else Path("log.mcap")
    if fmt in ("npz", "mat") or layout == "wide":
        return [Path(out) if out else stem.with_suffix(f".{fmt}")]
    folder = Path(out) if out else stem.with_name(stem.stem + "-export")
    return [folder / f"{name}.{fmt}" for name in CHANNEL_TABLES.values()]


def export_log(log, fmt: str, out: str | Path | None = None, layout: str = "wide",
               log_path: str | Path | None = None, columns: str = "named") -> list[Path]:
    """Write ``log`` (a :func:`~uvms_mj.io.recorder.read_log` result) in ``fmt``; returns the files.
    ``columns``: "named" (by the robot's layout, index where unknown) or "index".

    Raises:
        ExportError: parquet without pyarrow, mat without scipy.
        ValueError: unknown format, layout or columns.
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
    names = json.dumps({n: v for n, v in _labels(log, columns).items()})
    if fmt in ("npz", "mat"):
        path = Path(out) if out else stem.with_suffix(f".{fmt}")
        path.parent.mkdir(parents=True, exist_ok=True)
        groups = _groups(log)
        t = np.asarray(log.t, dtype=float)
        if fmt == "npz":
            arrays: dict[str, Any] = {"meta_json": np.array(meta), "columns_json": np.array(names)}
            if layout == "wide":
                arrays["t"] = t
                arrays.update({n: np.asarray(log.signals[n]) for n in groups["state_true"] + groups["control"]})
            else:
                for table, names in groups.items():
                    arrays[f"{table}/t"] = t
                    arrays.update({f"{table}/{n}": np.asarray(log.signals[n]) for n in names})
            with atomic_open(path, "wb") as f:
                np.savez_compressed(f, **arrays)
        else:
            sio = _require("scipy.io", fmt)
            mdict: dict[str, Any] = {"meta_json": meta, "columns_json": names}
            if layout == "wide":
                mdict["t"] = t
                mdict.update({_mat_name(n): np.asarray(log.signals[n]) for n in groups["state_true"] + groups["control"]})
            else:
                for table, names in groups.items():
                    mdict[table] = {"t": t, **{_mat_name(n): np.asarray(log.signals[n]) for n in names}}
            with atomic_path(path) as tmp:
                sio.savemat(str(tmp), mdict, appendmat=False, do_compression=True, oned_as="column")
        return [path]
    tabs = tables(log, layout, columns)
    if layout == "wide":
        path = Path(out) if out else stem.with_suffix(f".{fmt}")
        path.parent.mkdir(parents=True, exist_ok=True)
        targets = {path: tabs["wide"]}
    else:
        folder = Path(out) if out else stem.with_name(stem.stem + "-export")
        folder.mkdir(parents=True, exist_ok=True)
        targets = {folder / f"{name}.{fmt}": cols for name, cols in tabs.items()}
    for path, cols in targets.items():
        with partial_output(path):  # an interrupted or failed write leaves no half a file
            if fmt == "csv":
                _write_csv(cols, path)
            else:
                _write_parquet(cols, path, meta, names)
    return list(targets)
