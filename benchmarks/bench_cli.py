"""Benchmark: the command line's wall times, each a fresh ``python -m uvms_mj.cli.main`` process.

    python benchmarks/bench_cli.py [--repeats 3] [--scenario scenarios/paper.yaml] [--robots] [--no-plot-split]

Measures (issue 22 item 7):

* ``import uvms_mj.cli.main`` alone (``python -c``): the command line's own start-up (click, no numerics);
* the floor under ``validate``: ``import numpy, mujoco, pydantic, yaml, click`` (``MUJOCO_GL=disable``), what
  any scenario check needs before checking anything;
* ``validate SCENARIO`` (target: under 0.5 s) and, with ``--robots``, ``validate`` of every packaged
  ``bluerov2_alpha_*`` scenario (a robot scenario compiles its MJCF: the robot model and the nominal one);
* ``run paper --set duration=1 --no-plots --no-video`` (a short run: its time should be the run's);
* the same with ``--plots`` (the two PNG figures);
* in this process (unless ``--no-plot-split``): what the plots of that short run cost, split into
  ``import matplotlib`` (a fresh process) and each figure (built, laid out, drawn and encoded as PNG);

and which heavy packages (matplotlib, pandas, scipy, imageio, gymnasium, ...) ``validate`` and the short run
import (``-X importtime``). Prints the best of ``--repeats`` of the wall time and of the CPU time (user +
system; the machine is shared, so wall times vary +-30 % and more: compare CPU times, and each against the
floor measured in the same run). The processes run with bytecode caching on (``PYTHONDONTWRITEBYTECODE``
removed from their environment, one warm-up run first), as an installed package runs. A benchmark, not a
test: nothing here asserts a time.
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


def _env(**extra: str) -> dict:
    env = dict(os.environ, **extra)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    src = str(Path(__file__).resolve().parents[1] / "src")
    env["PYTHONPATH"] = src + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    return env


def _time(args: list[str], repeats: int, env: dict | None = None) -> tuple[float, float]:
    """Best (wall, CPU user + system) [s] of ``repeats`` runs: on a busy machine the CPU time is the steadier."""
    best, best_cpu = float("inf"), float("inf")
    for _ in range(repeats):
        r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        subprocess.run(args, env=env or _env(), check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
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


def _plot_split(repeats: int) -> None:
    """The plots of ``run paper --set duration=1`` in this process: matplotlib's import (fresh processes) and
    each figure, best of ``repeats`` (CPU time of the drawing thread)."""
    from uvms_mj.analysis.plots import paper
    from uvms_mj.scenario.schema import load_scenario, run_scenario

    root = Path(__file__).resolve().parents[1]
    res = run_scenario(load_scenario(root / "scenarios" / "paper.yaml", ("duration=1",)))
    _, mpl = _time([sys.executable, "-c", "import numpy, matplotlib.figure, matplotlib.backends.backend_agg"], repeats)
    _, floor = _time([sys.executable, "-c", "import numpy"], repeats)
    print(f"{'plots: import matplotlib':<36} cpu {mpl - floor:6.2f} s  (above an import of numpy)")
    import io

    for name, build in (("tracking", paper._tracking_figure), ("actuation", paper._actuation_figure)):
        best = float("inf")
        for _ in range(repeats):
            t0 = time.thread_time()  # this thread's: drawing is single-threaded (no BLAS or MuJoCo threads counted)
            build(res, "rac_dob: " + name).savefig(io.BytesIO(), format="png", dpi=110)
            best = min(best, time.thread_time() - t0)
        print(f"{'plots: figure ' + name:<36} cpu {best:6.2f} s  (built, drawn, PNG-encoded; best of {repeats})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--scenario", default="scenarios/paper.yaml")
    ap.add_argument("--robots", action="store_true", help="also validate every packaged bluerov2_alpha_* scenario")
    ap.add_argument("--no-plot-split", action="store_true", help="skip the in-process split of the plots' cost")
    a = ap.parse_args()
    cli = [sys.executable, "-m", "uvms_mj.cli.main"]
    root = Path(__file__).resolve().parents[1]
    with tempfile.TemporaryDirectory() as tmp:
        log = str(Path(tmp) / "run.mcap")
        short = [*cli, "run", "paper", "--set", "duration=1", "--no-video", "-o", log]
        floor = [sys.executable, "-c", "import numpy, mujoco, pydantic, yaml, click"]
        cases = [("import uvms_mj.cli.main", [sys.executable, "-c", "import uvms_mj.cli.main"], None),
                 ("floor: numpy mujoco pydantic yaml", floor, _env(MUJOCO_GL="disable")),
                 (f"validate {a.scenario}", [*cli, "validate", a.scenario], None)]
        if a.robots:
            cases += [(f"validate {p.stem}", [*cli, "validate", str(p)], None)
                      for p in sorted((root / "scenarios").glob("bluerov2_alpha_*.yaml"))]
        cases += [("run paper duration=1 --no-plots", [*short, "--no-plots"], None),
                  ("run paper duration=1 --plots", [*short, "--plots"], None)]
        _time(cases[2][1], 1)  # warm-up: bytecode written, files in the page cache
        for name, args, env in cases:
            wall, cpu = _time(args, a.repeats, env)
            print(f"{name:<36} wall {wall:6.2f} s  cpu {cpu:6.2f} s  (best of {a.repeats})", flush=True)
        for name, args, _ in (cases[2], cases[-2]):
            print(f"heavy imports, {name}: {', '.join(_heavy_imports(args)) or 'none'}")
    if not a.no_plot_split:
        _plot_split(a.repeats)


if __name__ == "__main__":
    main()
