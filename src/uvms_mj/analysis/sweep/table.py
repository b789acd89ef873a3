"""The results table: one row per run (``results.csv``, and ``results.parquet`` with pyarrow),
and reading it back."""

from __future__ import annotations

import csv
import json
import re
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from uvms_mj.io.atomic import atomic_open, atomic_path
from uvms_mj.analysis.sweep.plan import Run, SweepPlan, _jsonable
from uvms_mj.analysis.sweep.spec import _is_num

#: The metrics of :func:`uvms_mj.sim.metrics.metrics`, in table order (others found are appended).
METRICS = ("base_pos_rms_mm", "base_pos_max_mm", "base_att_rms_mrad", "base_att_max_mrad", "tip_rms_mm",
           "tip_max_mm", "thrust_rms_N", "torque_rms_Nm", "saturated_s", "singular_s")


def _columns(plan: SweepPlan, rows: Iterable[dict]) -> list[str]:
    extra = sorted({k for r in rows for k in r.get("metrics_extra", ())})
    return (["run_id", "sample", "controller", "seed"] + [a.column for a in plan.axes] + list(METRICS) + extra
            + ["status", "reason", "t_end", "wall_s", "log", "values", "sets", "key"])


def _row(run: Run, res: dict, log: str | None) -> dict:
    row: dict[str, Any] = {"run_id": run.run_id, "sample": run.sample, "controller": run.controller, "seed": run.seed}
    row.update(run.draws)
    m = res.get("metrics") or {}
    for k in METRICS:
        row[k] = m.get(k, float("nan"))
    extra = [k for k in m if k not in METRICS]
    for k in extra:
        row[k] = m[k]
    row["metrics_extra"] = extra
    row.update(status=res["status"], reason=res.get("reason", ""), t_end=res.get("t_end", float("nan")),
               wall_s=res.get("wall_s", float("nan")), log=log or "", values=run.values, sets=run.sets, key=run.key)
    return row


def _cell(v: Any) -> Any:
    if isinstance(v, (dict, list, tuple)):
        return json.dumps(_jsonable(v))
    if isinstance(v, float):
        return repr(v)
    if v is None:
        return ""
    return v


def _write_table(plan: SweepPlan, rows: list[dict], out: Path, parquet: bool = True) -> list[Path]:
    """results.csv (through a temporary file) and, with ``parquet`` and pyarrow, results.parquet.
    An interrupted sweep passes ``parquet=False``: pyarrow's first write takes 0.5-1.5 s on a busy
    machine, past the command line's grace (uvms_mj.io.interrupts.GRACE_S); its stale
    results.parquet is removed (results.csv has every finished run; the resumed sweep writes both)."""
    cols = _columns(plan, rows)
    paths = []
    with atomic_open(out / "results.csv", "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(cols)
        for r in rows:
            w.writerow([_cell(r.get(c, "")) for c in cols])
    paths.append(out / "results.csv")
    if not parquet:
        (out / "results.parquet").unlink(missing_ok=True)
        return paths
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        return paths
    data = {c: [(json.dumps(_jsonable(r.get(c))) if isinstance(r.get(c), (dict, list)) else r.get(c)) for r in rows]
            for c in cols}
    for c in [a.column for a in plan.axes]:
        if any(not _is_num(v) for v in data[c]):
            data[c] = [json.dumps(_jsonable(v)) for v in data[c]]
    with atomic_path(out / "results.parquet") as tmp:
        pq.write_table(pa.table(data), str(tmp))
    paths.append(out / "results.parquet")
    return paths


def read_results(path: str | Path) -> list[dict]:
    """results.csv back as dicts (numbers parsed, JSON columns decoded)."""
    p = Path(path)
    if p.is_dir():
        p = p / "results.csv"
    rows = []
    with open(p, newline="", encoding="utf-8") as f:
        for r in csv.DictReader(f):
            out = {}
            for k, v in r.items():
                if k in ("values", "sets"):
                    out[k] = json.loads(v) if v else None
                elif k in ("run_id", "controller", "status", "reason", "log", "key"):
                    out[k] = v
                else:
                    try:
                        out[k] = int(v) if re.fullmatch(r"-?\d+", v) else float(v)
                    except ValueError:
                        try:
                            out[k] = json.loads(v)
                        except ValueError:
                            out[k] = v
            rows.append(out)
    return rows
