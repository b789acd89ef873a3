"""Benchmark: the command line's wall times, each a fresh ``python -m uvms_mj.cli.main`` process.

    python benchmarks/bench_cli.py [--repeats 3] [--scenario scenarios/paper.yaml]

Measures (issue 22 item 7):

* ``validate SCENARIO`` (target: under 0.5 s);
* ``run paper --set duration=1 --no-plots --no-video`` (a short run: its time should be the run's);
* the same with ``--plots`` (the two PNG figures);
* ``import uvms_mj.cli.main`` alone (``python -c``), the floor under every command;

and which heavy packages (matplotlib, pandas, scipy, imageio, gymnasium, ...) ``validate`` and the short run
import (``-X importtime``). Prints the best of ``--repeats`` of the wall time and of the CPU time (user +
system; the machine is shared, so wall times vary +-30 % and more). The processes run
with bytecode caching on (``PYTHONDONTWRITEBYTECODE`` removed from their environment, one warm-up run first), as
an installed package runs. A benchmark, not a test: nothing here asserts a time.
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HEAVY = ("matplotlib", "pandas", "scipy", "imageio", "dm_control", "gymnasium", "ray", "pinocchio", "PIL")


def _env() -> dict:
    env = dict(os.environ)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    src = str(Path(__file__).resolve().parents[1] / "src")
    env["PYTHONPATH"] = src + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    return env


def _time(args: list[str], repeats: int) -> tuple[float, float]:
    """Best (wall, CPU user + system) [s] of ``repeats`` runs: on a busy machine the CPU time is the steadier."""
    best, best_cpu = float("inf"), float("inf")
    for _ in range(repeats):
        r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        subprocess.run(args, env=_env(), check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        best = min(best, time.perf_counter() - t0)
        r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        best_cpu = min(best_cpu, r1.ru_utime - r0.ru_utime + r1.ru_stime - r0.ru_stime)
    return best, best_cpu


def _heavy_imports(args: list[str]) -> list[str]:
    err = subprocess.run([sys.executable, "-X", "importtime", *args[1:]], env=_env(), check=True,
                         stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True).stderr
    mods = {line.rsplit("|", 1)[-1].strip().split(".")[0] for line in err.splitlines()
            if line.startswith("import time:")}
    return sorted(m for m in HEAVY if m in mods)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--scenario", default="scenarios/paper.yaml")
    a = ap.parse_args()
    cli = [sys.executable, "-m", "uvms_mj.cli.main"]
    with tempfile.TemporaryDirectory() as tmp:
        log = str(Path(tmp) / "run.mcap")
        short = [*cli, "run", "paper", "--set", "duration=1", "--no-video", "-o", log]
        cases = [("import uvms_mj.cli.main", [sys.executable, "-c", "import uvms_mj.cli.main"]),
                 (f"validate {a.scenario}", [*cli, "validate", a.scenario]),
                 ("run paper duration=1 --no-plots", [*short, "--no-plots"]),
                 ("run paper duration=1 --plots", [*short, "--plots"])]
        _time(cases[1][1], 1)  # warm-up: bytecode written, files in the page cache
        for name, args in cases:
            wall, cpu = _time(args, a.repeats)
            print(f"{name:<36} wall {wall:6.2f} s  cpu {cpu:6.2f} s  (best of {a.repeats})", flush=True)
        for name, args in cases[1:3]:
            print(f"heavy imports, {name}: {', '.join(_heavy_imports(args)) or 'none'}")


if __name__ == "__main__":
    main()
