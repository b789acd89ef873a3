"""Peak memory of ``uvms-mj run`` (and of the commands that read its log) against the simulated
duration: does it stay bounded?

    python benchmarks/bench_memory.py [--scenario NAME ...] [--durations 60 360 1200] [--no-plots] [--video]
        [--commands run info plot csv npz parquet mat render compare sweep]

For each scenario (default: paper and bluerov2_alpha_station) and duration, one ``uvms-mj run
SCENARIO --set duration=D`` (log written, plots on unless ``--no-plots``, video only with
``--video``) in its own process, measured by a small parent process of its own through
``resource.getrusage(RUSAGE_CHILDREN).ru_maxrss`` (the peak resident set size of the run and
whatever it waited for, e.g. ffmpeg), so that one duration's peak never hides another's. Prints
the peak [MB] per duration and, per scenario, the growth between the shortest and the longest
duration [MB per 1000 s simulated]. The logs go to a temporary folder, removed at the end.

``--commands`` (default: run only): also, on each run's log, ``info``, ``plot``, ``export`` as
csv / npz / parquet / mat (named by format), ``render`` (at 1 frame/s and 320 x 240: the log's
reading and the streaming to ffmpeg are what is measured, not the frames' number), and, running
their own simulations of the same duration, ``compare`` (rac,rac_dob on the paper's robot, the
scenario's controller and rac on a floating robot; figure and table) and ``sweep`` (two runs on two
workers; the peak is the largest single process: ru_maxrss of the children is a maximum, not a sum).
Measured on 2026-12-03 (issue 23; 3600 s logs: paper 119 MB, bluerov2_alpha_station 230 MB), peak
RSS [MB] before -> after: paper info 5748 -> 89, plot 401 -> 241, csv 492 -> 115, npz 374 -> 104,
parquet 597 -> 200, render 478 -> 272, compare -> 385; station: see the report of branch mem-read.
Measured on 2026-12-04 after the runs were streamed (``keep=False``: metrics accumulated, no
sample kept): ``run --no-plots`` paper 98 MB at 60 s and 99 MB at 3600 s, station 96 and 97 MB;
``sweep`` station 207 MB at both durations (README "Memory"). After the figures read the log through
``read_plot_log`` (a bounded min/max envelope), 60 / 1200 / 3600 s: ``plot`` paper 129 / 145 / 160 MB,
station 125 / 161 / 184 MB; ``run --plots`` paper 151 / 175 / 175, station 148 / 189 / 199; ``compare``
paper 143 / 163 / 191, station 145 / 170 / 188. After ``render`` read the log through
``read_render_log`` (the envelope, frames streamed from a second pass): paper 191 / 224 / 235 MB,
station 176 / 206 / 213 MB (was 294 MB at 3600 s).
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

# The measuring parent: runs the command given, prints its children's peak RSS [KiB on Linux].
_MEASURE = ("import resource, subprocess, sys; rc = subprocess.run(sys.argv[1:], stdout=subprocess.DEVNULL, "
            "stderr=subprocess.PIPE).returncode; "
            "print(rc, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)")


def peak_rss_mb(cmd: list[str]) -> tuple[int, float]:
    """(exit status, peak RSS [MB]) of ``cmd`` run in a fresh measuring process."""
    out = subprocess.run([sys.executable, "-c", _MEASURE, *cmd], capture_output=True, text=True, check=True)
    rc, kib = out.stdout.split()
    scale = 1.0 if sys.platform != "darwin" else 1.0 / 1024.0  # ru_maxrss: KiB on Linux, bytes on macOS
    return int(rc), int(kib) * scale / 1024.0


#: Commands measured on a run's log: (name, arguments after "uvms_mj.cli.main", with LOG and OUT).
_ON_LOG = {
    "info": ["info", "LOG"],
    "plot": ["plot", "LOG", "--out-dir", "OUT"],
    "csv": ["export", "LOG", "--format", "csv", "-o", "OUT/x.csv"],
    "npz": ["export", "LOG", "--format", "npz", "-o", "OUT/x.npz"],
    "parquet": ["export", "LOG", "--format", "parquet", "-o", "OUT/x.parquet"],
    "mat": ["export", "LOG", "--format", "mat", "-o", "OUT/x.mat"],
    "render": ["render", "LOG", "--fps", "1", "--size", "320", "240", "-o", "OUT/x.mp4"],
}
COMMANDS = ("run", *_ON_LOG, "compare", "sweep")


def _own_runs(command: str, name: str, d: float, out: str) -> list[str]:
    """compare / sweep of ``name`` with runs of ``d`` s into ``out``."""
    paper = name in ("paper",) or name.endswith("paper.yaml")
    if command == "compare":
        ctrls = "rac,rac_dob" if paper else "station_pid,rac" if "station" in name else "rac,rac_dob"
        return ["compare", name, "--set", f"duration={d:g}", "--controllers", ctrls, "--out-dir", out]
    vary = "plant.current[0]=[0, 0.01]" if paper else "current.velocity=[[0, 0, 0], [0.01, 0, 0]]"
    ctrl = "rac" if paper else "station_pid" if "station" in name else "rac"
    return ["sweep", name, "--vary", vary, "--controllers", ctrl, "--workers", "2", "--set", f"duration={d:g}",
            "--out-dir", out]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--scenario", nargs="+", default=["paper", "bluerov2_alpha_station"])
    p.add_argument("--durations", nargs="+", type=float, default=[60.0, 360.0, 1200.0])
    p.add_argument("--no-plots", dest="plots", action="store_false", help="Run with --no-plots.")
    p.add_argument("--video", action="store_true", help="Also render the video (--video).")
    p.add_argument("--commands", nargs="+", choices=COMMANDS, default=["run"],
                   help="What to measure (default: run): the commands on each run's log, compare and sweep.")
    a = p.parse_args()
    with tempfile.TemporaryDirectory(prefix="uvms-mj-bench-memory-") as tmp:
        print(f"{'scenario':28s} {'command':8s} {'duration [s]':>12s} {'peak RSS [MB]':>13s} {'wall [s]':>8s}")
        py = [sys.executable, "-m", "uvms_mj.cli.main"]
        for name in a.scenario:
            peaks: dict[str, list[tuple[float, float]]] = {}

            def measure(command: str, d: float, cmd: list[str]) -> None:
                t0 = time.perf_counter()
                rc, mb = peak_rss_mb(cmd)
                wall = time.perf_counter() - t0
                peaks.setdefault(command, []).append((d, mb))
                note = "" if rc in (0, 3, 4) else f"  (exit {rc})"
                print(f"{name:28s} {command:8s} {d:12g} {mb:13.0f} {wall:8.1f}{note}", flush=True)

            for d in sorted(a.durations):
                log = Path(tmp) / f"{name}-{d:g}.mcap"
                out = Path(tmp) / f"{name}-{d:g}-out"
                out.mkdir()
                on_log = [c for c in a.commands if c in _ON_LOG]
                if "run" in a.commands or on_log:
                    cmd = py + ["run", name, "--set", f"duration={d:g}", "-o", str(log),
                                "--plots" if a.plots and "run" in a.commands else "--no-plots",
                                "--video" if a.video else "--no-video"]
                    if "run" in a.commands:
                        measure("run", d, cmd)
                    else:
                        subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=False)
                for c in on_log:
                    measure(c, d, py + [str(log) if x == "LOG" else x.replace("OUT", str(out)) for x in _ON_LOG[c]])
                for c in ("compare", "sweep"):
                    if c in a.commands:
                        measure(c, d, py + _own_runs(c, name, d, str(out / c)))
                shutil.rmtree(out, ignore_errors=True)
                for f in Path(tmp).glob(f"{log.stem}*"):
                    f.unlink()
            for command, pk in peaks.items():
                if len(pk) > 1 and pk[-1][0] > pk[0][0]:
                    (d0, m0), (d1, m1) = pk[0], pk[-1]
                    print(f"{name:28s} {command:8s} growth {1000.0 * (m1 - m0) / (d1 - d0):.1f} MB per 1000 s "
                          f"simulated ({m0:.0f} MB at {d0:g} s -> {m1:.0f} MB at {d1:g} s)")


if __name__ == "__main__":
    main()
