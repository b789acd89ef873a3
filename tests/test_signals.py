"""SIGINT and SIGTERM at start-up and mid-command (issue 23 item 2): exit 130, the process and its
children gone, no half-written file under a final output name, finished outputs kept; a sweep
starts no run after the signal and every finished run has its row.

Bound: the contract is exit within 2 s of the signal (uvms_mj.io.interrupts.GRACE_S = 1.5 s and a
forced exit after it). The tests allow :data:`BOUND_S` = 10 s for the process and its children to
be gone: a behaviour check (the reported faults were 8-39 s and queued runs started after the
signal) with room for a loaded 2-core test machine, not a speed claim. Moments are events where
possible (the log exists, runs.jsonl has a row); "start-up" is 0.2 s after the start (imports), and
not before the command line's first lines have installed its SIGTERM handler (:func:`_start_up`): a
signal during the interpreter's own start (Python's start-up and site, tens of ms, longer on a loaded
machine) meets no handler of ours, the one moment the contract cannot cover."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from uvms_mj.io.recorder import read_log

BOUND_S = 10.0
SIGNALS = [signal.SIGTERM, signal.SIGINT]
FINISHED = ("ok", "diverged", "error", "joint_limit")
linux_only = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="uses /proc for the process tree")


def _start(tmp: Path, *args: str) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1] / "src"))
    return subprocess.Popen([sys.executable, "-m", "uvms_mj.cli.main", *args], cwd=tmp, env=env,
                            stdout=open(tmp / "stdout.txt", "w"), stderr=open(tmp / "stderr.txt", "w"))


def _catches(pid: int, sig) -> bool:
    """Whether process ``pid`` has a handler for ``sig`` (/proc/PID/status SigCgt)."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("SigCgt:"):
                return bool(int(line.split()[1], 16) >> (int(sig) - 1) & 1)
    except OSError:
        pass
    return False


def _start_up(p: subprocess.Popen, after: float = 0.2) -> None:
    """The start-up moment: ``after`` s after the start, and the SIGTERM handler installed
    (the first lines of uvms_mj.cli.main), whichever is later."""
    t0 = time.monotonic()
    _wait_for(lambda: _catches(p.pid, signal.SIGTERM), p, limit=60.0)
    time.sleep(max(0.0, after - (time.monotonic() - t0)))


def _descendants(pid: int) -> set[int]:
    out, todo = set(), [pid]
    while todo:
        p = todo.pop()
        try:
            for task in os.listdir(f"/proc/{p}/task"):
                kids = {int(k) for k in Path(f"/proc/{p}/task/{task}/children").read_text().split()}
                todo += list(kids - out)
                out |= kids
        except OSError:
            continue
    return out


def _alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return False


def _wait_for(cond, p: subprocess.Popen, limit: float = 120.0) -> None:
    """Until ``cond()`` or the process ended (a hang guard of ``limit`` seconds)."""
    t0 = time.monotonic()
    while not cond() and p.poll() is None:
        assert time.monotonic() - t0 < limit, "the awaited moment never came"
        time.sleep(0.01)


def _signal(p: subprocess.Popen, sig, tmp: Path) -> tuple[bool, str]:
    """Send ``sig``; the process and every descendant it had must be gone within BOUND_S.
    Returns (whether it was running when signalled, its stderr)."""
    kids = _descendants(p.pid)
    running = p.poll() is None
    p.send_signal(sig)
    try:
        p.wait(timeout=BOUND_S)
    except subprocess.TimeoutExpired:
        p.kill()
        raise AssertionError(f"still running {BOUND_S} s after {sig.name}") from None
    t0 = time.monotonic()
    while any(_alive(k) for k in kids) and time.monotonic() - t0 < BOUND_S:
        time.sleep(0.05)
    assert not [k for k in kids if _alive(k)], "children outlived the command"
    return running, (tmp / "stderr.txt").read_text()


def _check_rc(p: subprocess.Popen, running: bool, err: str) -> None:
    assert "Traceback" not in err and "Aborted" not in err, err
    if not running:  # it finished before the signal (a fast machine): a success, its outputs checked as complete
        assert p.returncode == 0, (p.returncode, err)
        return
    if p.returncode == 0:
        return  # it finished between the check and the signal: its outputs are checked as complete
    assert p.returncode == 130, (p.returncode, err)


def _complete(folder: Path) -> list[Path]:
    """Every file under ``folder`` is complete in its format (logs: readable, maybe truncated);
    no temporary file is left. Returns the files."""
    files = [f for f in folder.rglob("*") if f.is_file() and f.name not in ("stdout.txt", "stderr.txt")]
    for f in files:
        assert not f.name.endswith(".tmp"), f
        data = f.read_bytes()
        if f.suffix == ".png":
            assert data[:8] == b"\x89PNG\r\n\x1a\n" and data[-8:-4] == b"IEND", f"half a PNG: {f}"
        elif f.suffix == ".json":
            json.loads(data)
        elif f.suffix == ".jsonl":
            assert not data or data.endswith(b"\n"), f
        elif f.suffix == ".csv":
            lines = data.decode().splitlines()
            assert data.endswith(b"\n") and len({len(next(csv.reader([ln]))) for ln in lines}) == 1, f
        elif f.suffix == ".mcap":
            read_log(f)  # readable (truncated allowed: a log flushed incrementally)
        elif f.suffix == ".parquet":
            assert data[-4:] == b"PAR1", f
    return files


# --------------------------------------------------------------------------- run, compare


@linux_only
@pytest.mark.parametrize("sig", SIGNALS, ids=lambda s: s.name)
@pytest.mark.parametrize("moment", ["start-up", "mid-run", "plots"])
def test_run(sig, moment, tmp_path):
    duration = "40" if moment == "plots" else "600"
    p = _start(tmp_path, "run", "paper", "--set", f"duration={duration}", "-o", "r.mcap", "--json", "r.json",
               "--plots")
    if moment == "start-up":
        _start_up(p)
    elif moment == "mid-run":
        _wait_for(lambda: (tmp_path / "r.mcap").exists() and (tmp_path / "r.mcap").stat().st_size > 20_000, p)
    else:  # the run is over (its JSON written): the plots are being drawn
        _wait_for(lambda: (tmp_path / "r.json").exists(), p)
    running, err = _signal(p, sig, tmp_path)
    _check_rc(p, running, err)
    files = _complete(tmp_path)
    if moment == "mid-run":
        log = read_log(tmp_path / "r.mcap")
        assert log.status == "interrupted" and not log.truncated and 0 < log.t[-1] < 600
        assert not (tmp_path / "r.json").exists()  # written after the run only
    if moment == "plots":
        assert {f.name for f in files} >= {"r.mcap", "r.json"}  # finished before the signal: kept
        assert read_log(tmp_path / "r.mcap").status == "ok"


@linux_only
@pytest.mark.parametrize("sig", SIGNALS, ids=lambda s: s.name)
@pytest.mark.parametrize("moment", ["start-up", "first-run"])
def test_compare(sig, moment, tmp_path):
    p = _start(tmp_path, "compare", "paper", "--set", "duration=300", "--out-dir", "c", "--json", "c.json")
    if moment == "start-up":
        _start_up(p)
    else:
        first = tmp_path / "c" / "paper-rac.mcap"
        _wait_for(lambda: first.exists() and first.stat().st_size > 20_000, p)
    running, err = _signal(p, sig, tmp_path)
    _check_rc(p, running, err)
    _complete(tmp_path)
    assert not (tmp_path / "c.json").exists() and not (tmp_path / "c" / "paper-compare.png").exists()


# --------------------------------------------------------------------------- export


@pytest.fixture(scope="module")
def long_log(tmp_path_factory) -> Path:
    from click.testing import CliRunner

    from uvms_mj.cli.main import main

    out = tmp_path_factory.mktemp("log") / "long.mcap"
    res = CliRunner().invoke(main, ["run", "paper", "--set", "duration=60", "-o", str(out), "--no-plots"])
    assert res.exit_code == 0, res.output
    return out


@linux_only
@pytest.mark.parametrize("sig", SIGNALS, ids=lambda s: s.name)
@pytest.mark.parametrize("moment", ["start-up", "writing"])
def test_export(sig, moment, long_log, tmp_path):
    """export at start-up (0.2 s) and while it writes the CSV (its temporary file exists):
    130 and no CSV, or (finished first) a complete CSV."""
    p = _start(tmp_path, "export", str(long_log), "-o", "x.csv")
    if moment == "start-up":
        _start_up(p)
    else:
        _wait_for(lambda: any(tmp_path.glob(".x.*.part.csv")), p)
    running, err = _signal(p, sig, tmp_path)
    _check_rc(p, running, err)
    files = _complete(tmp_path)
    if p.returncode == 130:
        assert not files, files


# --------------------------------------------------------------------------- sweep


def _rows(out: Path) -> list[dict]:
    f = out / "results.csv"
    return list(csv.DictReader(open(f, encoding="utf-8"))) if f.exists() else []


def _sweep(tmp: Path, sig, moment: str, engine: str = "process") -> None:
    out = tmp / "sw"
    p = _start(tmp, "sweep", "paper", "--vary", "plant.current[0]=[0, 0.01, 0.02, 0.03, 0.04, 0.05, 0.06, 0.07]",
               "--workers", "2", "--engine", engine, "--controllers", "rac", "--set", "duration=10", "--logs",
               "--out-dir", str(out))
    record, logs = out / "runs.jsonl", out / "logs"
    if moment == "start-up":
        _start_up(p)
    else:
        _wait_for(lambda: record.exists() and record.read_text().count("\n") >= 1, p)
    before = set(os.listdir(logs)) if logs.exists() else set()
    running, err = _signal(p, sig, tmp)
    _check_rc(p, running, err)
    _complete(tmp)
    after = set(os.listdir(logs)) if logs.exists() else set()
    done = [json.loads(line) for line in record.read_text().splitlines()] if record.exists() else []
    rows = _rows(out)
    # every finished run has its row, in runs.jsonl and results.csv
    assert {r["run_id"] for r in rows} == {d["run_id"] for d in done}
    for name in after:
        log = read_log(logs / name)
        if log.status in FINISHED and not log.truncated:
            assert name[:-len(".mcap")] in {r["run_id"] for r in rows}, f"{name} finished without a row"
    # no run started after the signal: a log that appeared since is one of the runs in flight
    # then (at most one per worker; its log may be created just after the listing above), closed
    # as interrupted or cut short, or finished in the grace time (a 10 s run takes ~50 ms) and then
    # in the table like any finished run
    new = after - before
    assert len(new) <= 2, new
    ids = {r["run_id"] for r in rows}
    for name in new:
        log = read_log(logs / name)
        assert log.status not in FINISHED or log.truncated or name[:-len(".mcap")] in ids, (name, log.status)
    if moment != "start-up" and p.returncode == 130:
        assert "rerun the same command to resume" in err


@linux_only
@pytest.mark.parametrize("sig", SIGNALS, ids=lambda s: s.name)
def test_sweep_start_up(sig, tmp_path):
    _sweep(tmp_path, sig, "start-up")


@pytest.mark.slow
@linux_only
@pytest.mark.parametrize("sig", SIGNALS, ids=lambda s: s.name)
def test_sweep_mid(sig, tmp_path):
    _sweep(tmp_path, sig, "mid")


@pytest.mark.slow
@linux_only
def test_sweep_ray_mid(tmp_path):
    pytest.importorskip("ray")
    _sweep(tmp_path, signal.SIGTERM, "mid", engine="ray")


@linux_only
@pytest.mark.parametrize("sig", SIGNALS, ids=lambda s: s.name)
def test_render_mid_video(sig, long_log, tmp_path):
    """render, signalled while ffmpeg writes the MP4: 130, ffmpeg gone, no MP4 left (a video cut
    short is not the requested output)."""
    mp4 = tmp_path / "v.mp4"
    p = _start(tmp_path, "render", str(long_log), "-o", str(mp4))
    # ffmpeg writes a temporary next to it (uvms_mj.io.atomic), renamed to v.mp4 only when complete
    _wait_for(lambda: any(tmp_path.glob(".v.*.part.mp4")) or mp4.exists(), p)
    if p.poll() is not None and p.returncode == 4:
        pytest.skip("rendering unavailable here")
    running, err = _signal(p, sig, tmp_path)
    _check_rc(p, running, err)
    if p.returncode == 130:
        assert not mp4.exists()
