"""Peak memory of ``uvms-mj run`` against the simulated duration: does it stay bounded?

    python benchmarks/bench_memory.py [--scenario NAME ...] [--durations 60 360 1200] [--no-plots] [--video]

For each scenario (default: paper and bluerov2_alpha_station) and duration, one ``uvms-mj run
SCENARIO --set duration=D`` (log written, plots on unless ``--no-plots``, video only with
``--video``) in its own process, measured by a small parent process of its own through
``resource.getrusage(RUSAGE_CHILDREN).ru_maxrss`` (the peak resident set size of the run and
whatever it waited for, e.g. ffmpeg), so that one duration's peak never hides another's. Prints
the peak [MB] per duration and, per scenario, the growth between the shortest and the longest
duration [MB per 1000 s simulated]. The logs go to a temporary folder, removed at the end.
"""

from __future__ import annotations

import argparse
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


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--scenario", nargs="+", default=["paper", "bluerov2_alpha_station"])
    p.add_argument("--durations", nargs="+", type=float, default=[60.0, 360.0, 1200.0])
    p.add_argument("--no-plots", dest="plots", action="store_false", help="Run with --no-plots.")
    p.add_argument("--video", action="store_true", help="Also render the video (--video).")
    a = p.parse_args()
    with tempfile.TemporaryDirectory(prefix="uvms-mj-bench-memory-") as tmp:
        print(f"{'scenario':28s} {'duration [s]':>12s} {'plots':>5s} {'video':>5s} {'peak RSS [MB]':>13s} "
              f"{'wall [s]':>8s}")
        for name in a.scenario:
            peaks = []
            for d in sorted(a.durations):
                log = Path(tmp) / f"{name}-{d:g}.mcap"
                cmd = [sys.executable, "-m", "uvms_mj.cli.main", "run", name, "--set", f"duration={d:g}",
                       "-o", str(log), "--plots" if a.plots else "--no-plots",
                       "--video" if a.video else "--no-video"]
                t0 = time.perf_counter()
                rc, mb = peak_rss_mb(cmd)
                wall = time.perf_counter() - t0
                peaks.append((d, mb))
                note = "" if rc in (0, 3, 4) else f"  (exit {rc})"
                print(f"{name:28s} {d:12g} {str(a.plots):>5s} {str(a.video):>5s} {mb:13.0f} {wall:8.1f}{note}",
                      flush=True)
                for f in Path(tmp).glob(f"{log.stem}*"):
                    f.unlink()
            if len(peaks) > 1 and peaks[-1][0] > peaks[0][0]:
                (d0, m0), (d1, m1) = peaks[0], peaks[-1]
                print(f"{name:28s} growth {1000.0 * (m1 - m0) / (d1 - d0):.1f} MB per 1000 s simulated "
                      f"({m0:.0f} MB at {d0:g} s -> {m1:.0f} MB at {d1:g} s)")


if __name__ == "__main__":
    main()
