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

import contextlib
import json
import re
from pathlib import Path
from types import SimpleNamespace
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


class _CsvTable:
    """A CSV table written block by block (the header with the first block)."""

    def __init__(self, f) -> None:
        self._f, self._names = f, None

    def add(self, cols: dict[str, np.ndarray]) -> None:
        if self._names is None:
            self._names = list(cols)
            self._f.write(",".join(f'"{n}"' if "," in n else n for n in self._names) + "\n")
        if not len(cols["t"]):
            return
        data = np.column_stack([np.asarray(c, dtype=float) for c in cols.values()])
        self._f.write("".join(",".join("" if np.isnan(v) else repr(float(v)) for v in row) + "\n"
                              for row in data.tolist()))


class _ParquetTable:
    """A Parquet file written block by block: one row group per block, the first block's column
    types. Its key-value metadata (``uvms_mj``: the metadata and status, known once the log is read
    to its end; ``uvms_mj_columns``) is written at close, in the footer, where readers take the
    schema's metadata from (the Arrow schema is not stored: the columns are plain numbers and
    booleans, which Parquet's own types give back)."""

    def __init__(self, path: Path, names: str) -> None:
        self._pa = _require("pyarrow", "parquet")
        self._pq = _require("pyarrow.parquet", "parquet")
        self._path, self._names, self._writer, self._schema = path, names, None, None

    def add(self, cols: dict[str, np.ndarray]) -> None:
        table = self._pa.table({k: np.asarray(v) for k, v in cols.items()})
        if self._writer is None:
            self._schema = table.schema
            self._writer = self._pq.ParquetWriter(str(self._path), self._schema, store_schema=False)
        if table.num_rows:
            self._writer.write_table(table.cast(self._schema))

    def close(self, meta: str) -> None:
        if self._writer is not None:
            self._writer.add_key_value_metadata({"uvms_mj": meta, "uvms_mj_columns": self._names})
            self._writer.close()
            self._writer = None


class _Spool:
    """Arrays of a known row layout gathered block by block in raw files of a temporary folder
    (next to the output: the same disk), read back one array at a time: what bounds the memory of
    the npz and mat exports (one array, not the whole log)."""

    def __init__(self, folder: Path) -> None:
        self._dir = folder
        self._arrays: dict[str, list] = {}  # key -> [file, dtype, row shape, rows]

    def add(self, key: str, arr: np.ndarray) -> None:
        arr = np.ascontiguousarray(arr)
        ent = self._arrays.get(key)
        if ent is None:
            ent = self._arrays[key] = [open(self._dir / f"{len(self._arrays)}.raw", "wb"), arr.dtype, arr.shape[1:], 0]
        if arr.shape[1:] != ent[2]:
            raise ValueError(f"{key}: rows of shape {arr.shape[1:]} after rows of shape {ent[2]}")
        ent[0].write(arr.astype(ent[1], copy=False).tobytes())
        ent[3] += len(arr)

    def keys(self) -> list[str]:
        return list(self._arrays)

    def header(self, key: str) -> dict:
        _, dtype, shape, rows = self._arrays[key]
        return {"descr": np.lib.format.dtype_to_descr(dtype), "fortran_order": False, "shape": (rows,) + shape}

    def copy_to(self, key: str, dest, piece: int = 1 << 22) -> None:
        """The raw bytes of ``key`` into ``dest`` (a file), ``piece`` bytes at a time."""
        f = self._arrays[key][0]
        f.flush()
        with open(f.name, "rb") as src:
            while True:
                data = src.read(piece)
                if not data:
                    break
                dest.write(data)

    def load(self, key: str) -> np.ndarray:
        f, dtype, shape, rows = self._arrays[key]
        f.flush()
        return np.fromfile(f.name, dtype=dtype).reshape((rows,) + shape)

    def close(self) -> None:
        for ent in self._arrays.values():
            ent[0].close()


def _write_npz(spool: _Spool, extra: dict[str, str], path: Path) -> None:
    """As ``np.savez_compressed`` (members ``<key>.npy``, deflated, zip64): the text arrays of
    ``extra`` first, then each spooled array streamed into its member."""
    import zipfile

    with atomic_open(path, "wb") as f, zipfile.ZipFile(f, "w", compression=zipfile.ZIP_DEFLATED, allowZip64=True) as zf:
        for key, text in extra.items():
            with zf.open(key + ".npy", "w", force_zip64=True) as m:
                np.lib.format.write_array(m, np.array(text), allow_pickle=False)
        for key in spool.keys():
            with zf.open(key + ".npy", "w", force_zip64=True) as m:
                hdr = spool.header(key)
                big = len(repr(hdr)) > 60000  # a version 1.0 header holds at most 65535 bytes
                (np.lib.format.write_array_header_2_0 if big else np.lib.format.write_array_header_1_0)(m, hdr)
                spool.copy_to(key, m)


def _write_mat(spool: _Spool, extra: dict[str, str], path: Path, layout: str, groups: dict[str, list[str]]) -> None:
    """As ``scipy.io.savemat(..., do_compression=True, oned_as="column")``, one variable (wide:
    one array; channels: one channel's struct) in memory at a time."""
    sio = _require("scipy.io", "mat")
    try:
        from scipy.io.matlab._mio5 import MatFile5Writer
    except ImportError:  # another scipy layout: one savemat of every variable
        MatFile5Writer = None
    keys = spool.keys()
    variables: list[tuple[str, Any]] = list(extra.items())
    if layout == "wide":
        variables += [(_mat_name(k), lambda k=k: spool.load(k)) for k in keys]
    else:
        for table in groups:
            mine = [k for k in keys if k.split("/")[0] == table]
            variables.append((table, lambda mine=mine: {_mat_name(k.split("/", 1)[1]): spool.load(k) for k in mine}))

    def value(v):
        return v() if callable(v) else v

    with atomic_path(path) as tmp:
        if MatFile5Writer is None:
            sio.savemat(str(tmp), {k: value(v) for k, v in variables}, appendmat=False, do_compression=True,
                        oned_as="column")
            return
        with open(tmp, "wb") as f:
            writer = MatFile5Writer(f, do_compression=True, unicode_strings=True, oned_as="column")
            for n, (name, v) in enumerate(variables):
                writer.put_variables({name: value(v)}, write_header=n == 0)


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


def _blocks_of(log, chunk: int):
    """An in-memory log (a RunResult, a read_log result) as blocks of ``chunk`` samples."""
    from uvms_mj.io.reader import SampleBlock

    t = np.asarray(log.t, dtype=float)
    n = len(t)
    sig = {k: np.asarray(v) for k, v in log.signals.items()}
    for a in range(0, max(n, 1), chunk):
        yield SampleBlock(t=t[a:a + chunk], signals={k: v[a:a + chunk] for k, v in sig.items()})


#: Samples per block of an export (memory: a block's arrays and its messages, a few MB).
EXPORT_CHUNK = 4096


def export_log(log, fmt: str, out: str | Path | None = None, layout: str = "wide",
               log_path: str | Path | None = None, columns: str = "named", chunk: int = EXPORT_CHUNK) -> list[Path]:
    """Write ``log`` in ``fmt``; returns the files. ``log``: a path to an MCAP log (read by blocks
    of ``chunk`` samples, :func:`uvms_mj.io.reader.iter_samples`: the memory does not grow with
    the log's length) or an in-memory log (a :func:`~uvms_mj.io.recorder.read_log` result, a
    RunResult; written by the same blocks). ``columns``: "named" (by the robot's layout, index
    where unknown) or "index".

    Memory: csv and parquet are written block by block (parquet: a row group per block); npz and
    mat gather the blocks in raw files in a temporary folder next to the output (as much disk as
    the uncompressed arrays, removed at the end) and write one array at a time (mat with
    ``layout="channels"``: one channel's struct at a time).

    Raises:
        ExportError: parquet without pyarrow, mat without scipy.
        ValueError: unknown format, layout or columns.
    """
    if fmt not in FORMATS:
        raise ValueError(f"format = {fmt!r}: use one of {', '.join(FORMATS)}")
    if layout not in LAYOUTS:
        raise ValueError(f"layout = {layout!r}: use one of {', '.join(LAYOUTS)}")
    if columns not in COLUMNS:
        raise ValueError(f"columns = {columns!r}: use one of {', '.join(COLUMNS)}")
    if fmt == "parquet":
        _require("pyarrow", fmt)
    if fmt == "mat":
        _require("scipy.io", fmt)
    from uvms_mj.io.reader import LogStream, iter_samples

    if isinstance(log, (str, Path)):
        log_path = log_path if log_path is not None else log
        stream = LogStream()
        blocks = iter_samples(log, chunk=chunk, stream=stream)
        info = stream
    else:
        blocks = _blocks_of(log, chunk)
        info = log
    stem = Path(log_path) if log_path is not None else Path("log.mcap")
    targets = export_paths(fmt, out, layout, stem)
    targets[0].parent.mkdir(parents=True, exist_ok=True)
    first = True
    names = ""
    if fmt in ("npz", "mat"):
        import tempfile

        path = targets[0]
        with partial_output(path), tempfile.TemporaryDirectory(prefix=f".{path.stem}.", suffix=".spool",
                                                               dir=path.parent) as tmp:
            spool = _Spool(Path(tmp))
            try:
                groups = None
                for block in blocks:
                    view = SimpleNamespace(t=block.t, signals=block.signals, meta=_meta_of(info))
                    if first:
                        groups, first = _groups(view), False
                        names = json.dumps({n: v for n, v in _labels(view, columns).items()})
                    for key, arr in _arrays(view, layout, groups):
                        spool.add(key, arr)
                if groups is None:  # no sample: the layout's empty arrays
                    view = _empty_view(info)
                    groups = _groups(view)
                    names = json.dumps({n: v for n, v in _labels(view, columns).items()})
                    for key, arr in _arrays(view, layout, groups):
                        spool.add(key, arr)
                extra = {"meta_json": _meta_json(_final(info)), "columns_json": names}
                if fmt == "npz":
                    _write_npz(spool, extra, path)
                else:
                    _write_mat(spool, extra, path, layout, groups)
            finally:
                spool.close()
        return [path]
    with contextlib.ExitStack() as stack:
        writers: dict[str, Any] = {}
        for block in blocks:
            view = SimpleNamespace(t=block.t, signals=block.signals, meta=_meta_of(info), status=None, reason=None)
            tabs = tables(view, layout, columns)
            if first:
                first = False
                names = json.dumps({n: v for n, v in _labels(view, columns).items()})
                writers = _open_tables(stack, fmt, layout, tabs, targets, names)
            for table, cols in tabs.items():
                writers[table].add(cols)
        if first:  # no sample: the header (csv) or the schema (parquet) of the layout's empty columns
            view = _empty_view(info)
            tabs = tables(view, layout, columns)
            names = json.dumps({n: v for n, v in _labels(view, columns).items()})
            writers = _open_tables(stack, fmt, layout, tabs, targets, names)
            for table, cols in tabs.items():
                writers[table].add(cols)
        if fmt == "parquet":
            final = _meta_json(_final(info))
            for w in writers.values():
                w.close(final)
    return [Path(p) for p in writers_paths(targets, layout, writers)]


def writers_paths(targets: list[Path], layout: str, writers: dict) -> list[Path]:
    if layout == "wide":
        return targets[:1]
    return [p for p in targets if p.stem in writers]


def _open_tables(stack, fmt: str, layout: str, tabs: dict, targets: list[Path], names: str) -> dict:
    """A writer per table, each under :func:`partial_output` and written to a temporary file."""
    out = {}
    for table in tabs:
        path = targets[0] if layout == "wide" else next(p for p in targets if p.stem == table)
        stack.enter_context(partial_output(path))
        if fmt == "csv":
            out[table] = _CsvTable(stack.enter_context(atomic_open(path, "w", encoding="utf-8", newline="")))
        else:
            tmp = stack.enter_context(atomic_path(path))
            w = _ParquetTable(tmp, names)
            stack.callback(lambda w=w: w._writer is not None and w._writer.close())  # an error: let it go
            out[table] = w
    return out


def _meta_of(info) -> dict:
    return dict(getattr(info, "meta", None) or {})


def _final(info):
    """What the meta_json of a finished export says (metadata, status, reason)."""
    return SimpleNamespace(meta=_meta_of(info), status=getattr(info, "status", None),
                           reason=getattr(info, "reason", None))


def _empty_view(info):
    """A log with no sample: each signal of the layout as an empty array of its dtype and shape."""
    layout = getattr(info, "layout", None)
    if layout is None:
        sig = {k: np.asarray(v)[:0] for k, v in (getattr(info, "signals", None) or {}).items()}
    else:
        sig = {k: np.zeros((0,) + tuple(shape), dtype=np.dtype(dtype)) for k, (dtype, shape) in layout.items()}
    return SimpleNamespace(t=np.zeros(0), signals=sig, meta=_meta_of(info), status=None, reason=None)


def _arrays(view, layout: str, groups: dict[str, list[str]]):
    """(key, array) of the npz / mat arrays of one block (the logged shapes)."""
    t = np.asarray(view.t, dtype=float)
    if layout == "wide":
        yield "t", t
        for n in groups["state_true"] + groups["control"]:
            yield n, np.asarray(view.signals[n])
    else:
        for table, names in groups.items():
            yield f"{table}/t", t
            for n in names:
                yield f"{table}/{n}", np.asarray(view.signals[n])
