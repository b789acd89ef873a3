"""The summary of a sweep's results: per controller the counts and metric distributions, per
controller pair the paired ratios and the samples where one failed while the other held, per
varied column the failures at each of its values; as a dict (``summary.json``) and as text."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

#: The metrics of the summary figures and ratios.
SUMMARY_METRICS = {"base_pos_rms_mm": "base position RMS [mm]", "base_att_rms_mrad": "base attitude RMS [mrad]",
                   "tip_rms_mm": "end tip RMS [mm]"}


def _stats(x: Sequence[float]) -> dict:
    a = np.asarray([v for v in x if v is not None and math.isfinite(v)], dtype=float)
    if not a.size:
        return {"n": 0, "median": None, "p10": None, "p90": None}
    return {"n": int(a.size), "median": float(np.median(a)), "p10": float(np.percentile(a, 10)),
            "p90": float(np.percentile(a, 90)), "min": float(a.min()), "max": float(a.max())}


def _pairs(rows: Sequence[dict], ref: str, other: str) -> list[tuple[dict, dict]]:
    by = {(r["sample"], r["controller"]): r for r in rows}
    out = []
    for (s, c), r in sorted(by.items(), key=lambda kv: kv[0][0]):
        if c == ref and (s, other) in by:
            o = by[(s, other)]
            if r["status"] == "ok" and o["status"] == "ok":
                out.append((r, o))
    return out


#: Varied columns with at most this many distinct values get a failures-per-value breakdown.
MAX_LEVELS = 12


def _key(v: Any) -> str:
    return "-" if v is None else (f"{v:g}" if isinstance(v, float) else str(v))


def _order(v: str) -> tuple:
    """Numbers in numeric order, before other values (in text order)."""
    try:
        return (0, float(v), "")
    except ValueError:
        return (1, 0.0, v)


def _failed_where_held(rows: Sequence[dict], controllers: Sequence[str]) -> dict[str, dict[str, int]]:
    """{c: {other: samples where c did not end ok while other did}} (same sample, paired)."""
    by = {(r["sample"], r["controller"]): r["status"] for r in rows}
    samples = sorted({r["sample"] for r in rows})
    return {c: {o: sum(1 for s in samples if by.get((s, c)) not in (None, "ok") and by.get((s, o)) == "ok")
                for o in controllers if o != c} for c in controllers}


def _by_column(rows: Sequence[dict], controllers: Sequence[str], columns: Sequence[str]) -> dict:
    """{column: {value: {controller: [failed, runs]}}} for the grid-like columns (few values)."""
    out: dict[str, dict] = {}
    for col in columns:
        values = sorted({_key(r.get(col)) for r in rows}, key=_order)
        if len(values) > MAX_LEVELS:
            continue
        table: dict[str, dict] = {}
        for v in values:
            rs = [r for r in rows if _key(r.get(col)) == v]
            table[v] = {c: [sum(1 for r in rs if r["controller"] == c and r["status"] != "ok"),
                            sum(1 for r in rs if r["controller"] == c)] for c in controllers}
        out[col] = table
    return out


def summarize(rows: Sequence[dict], controllers: Sequence[str], columns: Sequence[str] = ()) -> dict:
    """Counts, per-controller metric distributions (ok runs), paired ratios (each controller /
    the first, samples where both are ok), ``failed_where_held`` (per controller and other: the
    samples it failed while the other ended ok) and ``by_column`` (failures and runs per value
    of each varied column with at most ``MAX_LEVELS`` values)."""
    out: dict[str, Any] = {"runs": len(rows), "controllers": {}, "ratios": {}, "failures": []}
    for c in controllers:
        rs = [r for r in rows if r["controller"] == c]
        ok = [r for r in rs if r["status"] == "ok"]
        statuses: dict[str, int] = {}
        for r in rs:
            statuses[r["status"]] = statuses.get(r["status"], 0) + 1
        out["controllers"][c] = {"runs": len(rs), "ok": len(ok), "failed": len(rs) - len(ok), "statuses": statuses,
                                 "metrics": {m: _stats([r[m] for r in ok]) for m in SUMMARY_METRICS}}
    for c in controllers[1:]:
        pairs = _pairs(rows, controllers[0], c)
        rat = {}
        for m in SUMMARY_METRICS:
            vals = [o[m] / r[m] for r, o in pairs if r[m] and math.isfinite(r[m]) and math.isfinite(o[m])]
            st = _stats(vals)
            st["below_1"] = float(np.mean(np.asarray(vals) < 1.0)) if vals else None
            rat[m] = st
        out["ratios"][f"{c}/{controllers[0]}"] = {"pairs": len(pairs), "metrics": rat}
    out["failed_where_held"] = _failed_where_held(rows, controllers)
    out["by_column"] = _by_column(rows, controllers, columns)
    out["failures"] = [{"run_id": r["run_id"], "status": r["status"], "reason": r["reason"],
                        **{k: r.get(k) for k in columns}} for r in rows if r["status"] != "ok"]
    return out


def _g(v: Any) -> str:
    return "-" if v is None else f"{v:.3g}"


def format_summary(summary: dict) -> str:
    """The summary as text: counts, metric distributions per controller, paired ratios, failures."""
    ctrl = summary["controllers"]
    lines = [f"{'controller':<12}{'runs':>6}{'ok':>6}{'failed':>8}"]
    for c, s in ctrl.items():
        extra = ", ".join(f"{k} {v}" for k, v in s["statuses"].items() if k != "ok")
        lines.append(f"{c:<12}{s['runs']:>6}{s['ok']:>6}{s['failed']:>8}" + (f"  ({extra})" if extra else ""))
    def cell(st: dict) -> str:
        return f"{_g(st['median'])} [{_g(st['p10'])}, {_g(st['p90'])}]"

    w = max([len(cell(st)) for s in ctrl.values() for st in s["metrics"].values()] + [len(c) for c in ctrl]) + 3
    lines.append(f"{'ok runs: median [10 %, 90 %]':<28}" + "".join(f"{c:>{w}}" for c in ctrl))
    for m, label in SUMMARY_METRICS.items():
        lines.append(f"{label:<28}" + "".join(f"{cell(s['metrics'][m]):>{w}}" for s in ctrl.values()))
    for name, r in summary["ratios"].items():
        lines.append(f"paired ratio {name} ({r['pairs']} pairs, both ok): median [10 %, 90 %], share < 1")
        for m, st in r["metrics"].items():
            b = st.get("below_1")
            share = "-" if b is None else f"{100 * b:.0f} %"
            lines.append(f"  {SUMMARY_METRICS[m].split(' [')[0]:<26}{cell(st):>{w}}   {share}")
    held = summary.get("failed_where_held") or {}
    if any(n for d in held.values() for n in d.values()):
        lines.append("failed where another held (samples): " + "; ".join(
            f"{c} where {o} held {n}" for c, d in held.items() for o, n in d.items() if n))
    for col, table in (summary.get("by_column") or {}).items():
        if len(table) < 2:
            continue
        lines.append(f"failed / runs by {col}: " + "; ".join(
            f"{v}: " + ", ".join(f"{c} {f}/{n}" for c, (f, n) in t.items()) for v, t in table.items()))
    fails = summary.get("failures") or []
    if fails:
        lines.append(f"failed runs: {len(fails)}")
        for f in fails[:10]:
            lines.append(f"  {f['run_id']}: {f['status']}: {f['reason']}")
        if len(fails) > 10:
            lines.append(f"  ... and {len(fails) - 10} more (results.csv)")
    return "\n".join(lines)
