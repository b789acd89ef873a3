"""Running a sweep: the output folder's definition checked (resume: finished runs are skipped,
a different sweep refused), the unfinished runs executed by an engine, each appended to
``runs.jsonl`` as it finishes, then the table, the summary and the figures written."""

from __future__ import annotations

import json
import os
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from uvms_mj.io.atomic import atomic_open
from uvms_mj.analysis.sweep.engines import _ENGINES, FINISHED, check_engine
from uvms_mj.analysis.sweep.figures import plot_sweep
from uvms_mj.analysis.sweep.plan import SweepPlan, _jsonable
from uvms_mj.analysis.sweep.spec import SweepError
from uvms_mj.analysis.sweep.summary import summarize
from uvms_mj.analysis.sweep.table import _row, _write_table

def _read_jsonl(path: Path) -> list[dict]:
    rows = []
    if not path.exists():
        return rows
    with open(path, encoding="utf-8") as f:
        for line in f:
            line = line.strip()
            if not line:
                continue
            try:
                rows.append(json.loads(line))
            except ValueError:
                continue  # a line cut by a kill
    return rows


def _diff(old: dict, new: dict) -> list[str]:
    out = []
    for k in sorted(set(old) | set(new)):
        if old.get(k) != new.get(k):
            if k == "scenario":
                sub = sorted(s for s in set(old.get(k) or {}) | set(new.get(k) or {})
                             if (old.get(k) or {}).get(s) != (new.get(k) or {}).get(s))
                out.append(f"scenario ({', '.join(sub)})")
            else:
                out.append(f"{k}: {json.dumps(old.get(k))} -> {json.dumps(new.get(k))}")
    return out


_OUR_FILES = ("sweep.json", "runs.jsonl", "results.csv", "results.parquet", "summary.json", "sweep_metrics.png",
              "sweep_ratio.png")


@dataclass
class SweepOutcome:
    out_dir: Path
    rows: list[dict]
    planned: int
    skipped: int
    ran: int
    elapsed_s: float
    summary: dict
    figures: list[Path] = field(default_factory=list)
    tables: list[Path] = field(default_factory=list)
    interrupted: bool = False

    @property
    def runs_per_s(self) -> float:
        return self.ran / self.elapsed_s if self.ran and self.elapsed_s > 0 else float("nan")


def prepare_out(plan: SweepPlan, out_dir: str | Path, fresh: bool = False) -> dict[str, dict]:
    """Check or create DIR's sweep definition; return the finished runs by key."""
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise SweepError(f"--out-dir {out}: exists and is not a folder")
    spec = out / "sweep.json"
    if fresh and out.exists():
        for name in _OUR_FILES:
            (out / name).unlink(missing_ok=True)
        if (out / "logs").is_dir():
            shutil.rmtree(out / "logs")
    if spec.exists():
        try:
            old = json.loads(spec.read_text(encoding="utf-8"))
        except ValueError:
            raise SweepError(f"--out-dir {out}: {spec} is not readable JSON; use another --out-dir or --fresh") from None
        old_def = old.get("definition", {})
        new_def = json.loads(json.dumps(plan.definition))
        if old_def != new_def:
            raise SweepError(f"--out-dir {out} holds a different sweep; differs: " + "; ".join(_diff(old_def, new_def))
                             + ". Rerun with the same arguments to resume, choose another --out-dir, or add --fresh to "
                             "delete the old results.")
    elif out.exists() and (out / "runs.jsonl").exists():
        raise SweepError(f"--out-dir {out}: runs.jsonl without sweep.json; use another --out-dir or --fresh")
    out.mkdir(parents=True, exist_ok=True)
    if not spec.exists():
        from uvms_mj import __version__

        with atomic_open(spec, "w", encoding="utf-8") as f:
            f.write(json.dumps({"definition": plan.definition, "source": plan.scenario_path,
                                "sets": list(plan.sets), "uvms_mj": __version__,
                                "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}, indent=1))
    wanted = {r.key for r in plan.runs}
    finished = {}
    for row in _read_jsonl(out / "runs.jsonl"):
        if row.get("key") in wanted and row.get("status") in FINISHED:
            finished[row["key"]] = row
    return finished


def run_sweep(
    plan: SweepPlan,
    out_dir: str | Path,
    workers: int | None = None,
    engine: str = "process",
    logs: bool = False,
    fresh: bool = False,
    on_run: Callable[[dict, int, int], None] | None = None,
    figures: bool = True,
) -> SweepOutcome:
    """Run the plan's unfinished runs and write the table, summary and figures into out_dir.

    ``on_run(row, k, total)`` is called as each run finishes. KeyboardInterrupt (Ctrl-C, or
    SIGTERM inside recorder.handle_sigterm) stops the sweep; finished runs are kept (table
    written) and the exception propagates.
    """
    from uvms_mj.io.interrupts import _critical

    check_engine(engine)
    workers = int(workers or _cpu_count())
    if workers < 1:
        raise SweepError(f"--workers must be >= 1 (got {workers})")
    out = Path(out_dir)
    finished = prepare_out(plan, out, fresh)
    todo = [r for r in plan.runs if r.key not in finished]
    by_id = {r.run_id: r for r in todo}
    tasks = [{"run_id": r.run_id, "sample": r.sample, "scenario": r.scenario,
              "log": str(out / "logs" / f"{r.run_id}.mcap") if logs else None} for r in todo]
    rows_by_key = dict(finished)
    k = 0
    record = out / "runs.jsonl"
    if record.exists() and record.stat().st_size and not record.read_bytes().endswith(b"\n"):
        with open(record, "a", encoding="utf-8") as f:
            f.write("\n")  # end a line cut by a kill (it is skipped when read)
    jsonl = open(record, "a", encoding="utf-8")  # noqa: SIM115 - closed in the finally below

    def done(task: dict, res: dict) -> None:
        nonlocal k
        run = by_id[task["run_id"]]
        log = task["log"] if task["log"] and Path(task["log"]).exists() else None
        row = _row(run, res, log)
        rows_by_key[run.key] = row
        with _critical():  # SIGTERM / Ctrl-C (inside recorder.handle_sigterm) wait for the whole line
            jsonl.write(json.dumps(_jsonable(row), allow_nan=True) + "\n")
            jsonl.flush()
        k += 1
        if on_run is not None:
            on_run(row, k, len(tasks))

    t0 = time.perf_counter()
    interrupted = True  # until the engine returns
    try:
        if tasks:
            _ENGINES[engine](tasks, workers, done)
        interrupted = False
    finally:
        jsonl.close()
        elapsed = time.perf_counter() - t0
        order = {r.key: i for i, r in enumerate(plan.runs)}
        rows = sorted((r for key, r in rows_by_key.items() if key in order), key=lambda r: order[r["key"]])
        tables = _write_table(plan, rows, out, parquet=not interrupted)
        summary = summarize(rows, plan.controllers, [a.column for a in plan.axes])
        summary.update(planned=len(plan.runs), skipped=len(finished), ran=k, elapsed_s=elapsed,
                       runs_per_s=(k / elapsed if k and elapsed > 0 else None), workers=workers, engine=engine)
        with atomic_open(out / "summary.json", "w", encoding="utf-8") as f:
            f.write(json.dumps(_jsonable(summary), indent=1, allow_nan=True))
        figs = []
        if figures and not interrupted and rows:
            discrete = [a.column for a in plan.axes if a.kind == "grid" or a.spec.dist == "choice"]
            figs = plot_sweep(rows, [a.column for a in plan.axes], plan.controllers, out, title=plan.name,
                              discrete=discrete)
    return SweepOutcome(out, rows, len(plan.runs), len(finished), k, elapsed, summary, figs, tables, interrupted)


def _cpu_count() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1
