"""The summary of a sweep's results: per controller the counts and metric distributions, per
controller pair the paired ratios; as a dict (``summary.json``) and as text."""

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


def summarize(rows: Sequence[dict], controllers: Sequence[str], columns: Sequence[str] = ()) -> dict:
    """Counts, per-controller metric distributions (ok runs) and paired ratios (each
    controller / the first, samples where both are ok)."""
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
    fails = summary.get("failures") or []
    if fails:
        lines.append(f"failed runs: {len(fails)}")
        for f in fails[:10]:
            lines.append(f"  {f['run_id']}: {f['status']}: {f['reason']}")
        if len(fails) > 10:
            lines.append(f"  ... and {len(fails) - 10} more (results.csv)")
    return "\n".join(lines)
