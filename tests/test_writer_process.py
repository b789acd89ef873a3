"""The recorder's writer process (uvms_mj.io.writer_process): the same log as the inline writer,
its exceptions raised in the parent, no child left behind (closed, failed, killed, parent killed)."""

from __future__ import annotations

import errno
import math
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from oracles.planar.nominal import params_from_file
from uvms_mj.io import writer_process
from uvms_mj.io.mcap_writer import LeanWriter
from uvms_mj.io.reader import iter_messages, read_log
from uvms_mj.io.recorder import McapRecorder
from uvms_mj.io.writer_process import BATCH, _pack, _specs, _unpack, process_wanted

linux_only = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="os.fork, /proc")


def row_of(k: int) -> dict:
    """A paper-like row: arrays, Python and numpy scalars, booleans, a 2-D array."""
    t = k / 60
    q = np.array([0.1 * t, -0.05 * t, 0.3 * math.sin(t), 1.0 + 0.2 * t, -0.8 + 0.1 * math.cos(t)])
    return {"p_desired": np.r_[q[:3], 0.5 + 0.01 * t, 0.2], "det_B": 0.05 * math.sin(q[4]),
            "singular_phase": k % 3, "dls_active": bool(k % 2), "count": np.int64(k),
            "thrust_saturated": np.array([k % 2 == 0, False, True]), "mat": np.arange(6.0).reshape(2, 3) * t,
            "q_true": q, "qd_true": np.full(5, 0.01 * k), "tip_true": np.array([0.5 + 0.01 * t, 0.2])}


def odd_rows(n: int) -> list[dict]:
    """Regular rows and, among them, every kind the packing must send as it is: a signal missing,
    one added late, another order, another dtype (float32, int), another shape, a list, NaN and
    +-inf, a 0-d array."""
    rows = [row_of(k) for k in range(n)]
    rows[5].pop("det_B")
    rows[7]["late"] = 1.0
    rows[9] = dict(reversed(list(rows[9].items())))
    rows[11]["qd_true"] = rows[11]["qd_true"].astype(np.float32)
    rows[13]["tip_true"] = np.array([1, 2])
    rows[15]["p_desired"] = np.zeros(4)
    rows[17]["tip_true"] = [0.25, 0.5]
    rows[19]["q_true"] = np.array([np.nan, np.inf, -np.inf, 0.0, 1.0])
    rows[21]["det_B"] = np.array(0.5)
    rows[23]["qd_true"] = np.asfortranarray(np.ones((5, 2)))[:, 0]  # not contiguous
    return rows


def messages(path: Path) -> list:
    return [(c.topic, c.metadata, m.log_time, m.publish_time, m.sequence, m.data) for c, _, m in iter_messages(path)]


def write(path: Path, rows: list[dict], writer: str, **kw) -> McapRecorder:
    with pytest.warns(UserWarning, match="late"):
        with McapRecorder(path, params_from_file(), {"case": "wp"}, writer=writer, **kw) as rec:
            for k, row in enumerate(rows):
                rec.write_sample(k / 60, row)
                if k == BATCH + 3:
                    rec.flush()
    return rec


def test_pack_round_trip_keeps_every_value_and_type():
    rows = odd_rows(40)
    order, specs = _specs(rows[0])
    items = [(k / 60, r, set(r) == set(rows[0]) | {"late"}) for k, r in enumerate(rows)]
    back = _unpack(_pack(items, order, specs), order)
    assert len(back) == len(items)
    for (t, r, same), (t2, r2, same2) in zip(items, back):
        assert t2 == t and same2 == same and list(r2) == list(r)
        for name, v in r.items():
            assert type(r2[name]) is type(v), name
            if isinstance(v, np.ndarray):
                assert r2[name].dtype == v.dtype and r2[name].shape == v.shape
            np.testing.assert_array_equal(r2[name], v)


@linux_only
@pytest.mark.parametrize("n", [3, BATCH * 2 + 17])
def test_process_writes_the_inline_log(tmp_path, n):
    """Every message (topic, times, sequence, bytes) of the writer process's log is the inline
    writer's: regular rows and odd ones, across batches and an explicit flush."""
    rows = odd_rows(n) if n > 30 else [row_of(k) for k in range(n)] + [{**row_of(n), "late": 1.0}]
    logs = {}
    for writer in ("inline", "process"):
        path = tmp_path / f"{writer}.mcap"
        rec = write(path, rows, writer)
        assert rec.status == "ok" and rec.samples == len(rows)
        logs[writer] = messages(path)
        if n < 30:  # (read_log takes no signal whose shape changes, as the odd rows' do)
            log = read_log(path)
            assert log.status == "ok" and not log.truncated and len(log.t) == len(rows)
    assert len(logs["process"]) == len(logs["inline"]) > len(rows)
    assert logs["process"] == logs["inline"]


@linux_only
def test_auto_is_the_process_here_and_inline_where_it_cannot_pay(monkeypatch):
    monkeypatch.delenv("UVMS_MJ_LOG_WRITER", raising=False)
    cores = len(os.sched_getaffinity(0))
    assert process_wanted("auto", 1.0, None) == (cores >= 2)
    assert not process_wanted("auto", 0.0, None)  # each sample written by its write_sample
    assert not process_wanted("auto", 1.0, object())  # a live sink
    assert process_wanted("process", 0.0, None) and not process_wanted("inline", 1.0, None)
    monkeypatch.setattr(writer_process, "_POOL_WORKER", True)  # a Ray task's process (mark_pool_worker)
    assert not process_wanted("auto", 1.0, None) and process_wanted("process", 1.0, None)
    monkeypatch.setattr(writer_process, "_POOL_WORKER", False)
    monkeypatch.setenv("UVMS_MJ_LOG_WRITER", "inline")
    assert not process_wanted("auto", 1.0, None)
    with pytest.raises(ValueError, match="writer = 'threads'.*allowed"):
        process_wanted("threads", 1.0, None)
    with pytest.raises(ValueError, match="live sink"):
        process_wanted("process", 1.0, object())


def _gone(pid: int, limit: float = 10.0) -> bool:
    """The process has ended and been reaped (no zombie left)."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < limit:
        if not os.path.exists(f"/proc/{pid}"):
            return True
        time.sleep(0.02)  # running, or a zombie not reaped yet
    return False


@linux_only
def test_a_full_disk_in_the_child_is_raised_here_and_the_child_reaped(tmp_path, monkeypatch):
    """A full disk while the child writes: OSError(ENOSPC) raised in the parent (by a later
    write_sample or by close), the child gone, and the log closed."""
    parent = os.getpid()
    add = LeanWriter.add_samples

    def full_in_child(self, *a, **k):
        if os.getpid() != parent:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return add(self, *a, **k)

    monkeypatch.setattr(LeanWriter, "add_samples", full_in_child)
    path = tmp_path / "full.mcap"
    rec = McapRecorder(path, params_from_file(), {}, writer="process")
    rec.write_sample(0.0, row_of(0))  # written here (inline), then the fork
    pid = rec._proc.pid
    by_close = False  # the error raised by close: the child had not answered before (the pipe holds the batches)
    with pytest.raises(OSError) as err:
        for k in range(1, 5 * BATCH):
            rec.write_sample(k / 60, row_of(k))
        by_close = True
        rec.close()
    assert err.value.errno == errno.ENOSPC and "log writer process" in "".join(getattr(err.value, "__notes__", []))
    if not by_close:
        with pytest.raises(OSError):  # the child's close cannot write the samples either: raised too
            rec.close("error", "disk full")
    assert rec.closed and rec._proc is None and _gone(pid)
    log = read_log(path)
    assert log.status == "error" and "No space left" in log.reason and not log.truncated


@linux_only
def test_an_error_in_the_childs_close_is_raised_by_close(tmp_path, monkeypatch):
    """A sample the child cannot encode: close finishes the log (status "error", the reason
    naming the exception) and raises the exception here, with the child's traceback as a note."""
    import uvms_mj.io.writer as writer

    encode = writer.McapRecorder._encode_rows

    def bad_after_first(self, rows):
        if any(r[0] > 0 for r in rows):
            raise ZeroDivisionError("no encoding")
        return encode(self, rows)

    monkeypatch.setattr(writer.McapRecorder, "_encode_rows", bad_after_first)
    path = tmp_path / "bad.mcap"
    rec = McapRecorder(path, params_from_file(), {}, writer="process")
    for k in range(10):
        rec.write_sample(k / 60, row_of(k))
    pid = rec._proc.pid
    with pytest.raises(ZeroDivisionError) as err:
        rec.close()
    assert "log writer process" in "".join(getattr(err.value, "__notes__", []))
    assert rec.status == "error" and _gone(pid)
    log = read_log(path)
    assert log.status == "error" and "ZeroDivisionError" in log.reason and len(log.t) == 1


@linux_only
def test_a_child_killed_is_an_error_not_a_hang(tmp_path):
    path = tmp_path / "k.mcap"
    rec = McapRecorder(path, params_from_file(), {}, writer="process")
    rec.write_sample(0.0, row_of(0))
    pid = rec._proc.pid
    os.kill(pid, signal.SIGKILL)
    with pytest.raises(RuntimeError, match="ended unexpectedly .*killed by signal 9.*truncated"):
        for k in range(1, 4 * BATCH):
            rec.write_sample(k / 60, row_of(k))
        rec.close()
    rec.close()
    assert _gone(pid) and read_log(path).truncated


@linux_only
def test_parent_killed_leaves_a_truncated_log_and_no_child(tmp_path):
    """kill -9 of the writing process: the child sees its pipe close and ends; the log reads
    as truncated up to the last flush."""
    path = tmp_path / "killed.mcap"
    code = textwrap.dedent(f"""
        import sys, time
        sys.path.insert(0, {str(Path(__file__).parent)!r})
        from test_writer_process import row_of, params_from_file
        from uvms_mj.io.recorder import McapRecorder
        rec = McapRecorder({str(path)!r}, params_from_file(), {{}}, writer="process", flush_interval=1e9)
        for k in range(600):
            rec.write_sample(k / 60, row_of(k))
            if k == 399:
                rec.flush()
        print(rec._proc.pid, flush=True)
        time.sleep(120)
    """)
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1] / "src"))
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=env)
    try:
        line = proc.stdout.readline()
        assert line.strip().isdigit(), (line, proc.stderr.read() if proc.poll() is not None else "")
        child = int(line)
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert _gone(child)
    log = read_log(path)
    assert log.truncated and len(log.t) == 400


@linux_only
def test_hand_offs_do_not_wait_for_the_child_to_encode(tmp_path):
    """The pipe to the child holds several batches (writer_process.PIPE_BYTES): with the child
    stopped (SIGSTOP, as if busy encoding) the simulation still hands off three batches (~250 KB,
    four times Linux's default 64 KiB pipe, which made each hand-off wait for the child's previous
    encoding). The hand-offs run in a thread; the 60 s join only guards against a hang."""
    import pickle
    import threading

    try:
        limit = int(Path("/proc/sys/fs/pipe-max-size").read_text())
    except (OSError, ValueError):
        limit = 0
    rows = [row_of(k) for k in range(3 * BATCH + 1)]
    batch = len(pickle.dumps(writer_process._pack([(0.0, r, True) for r in rows[1:BATCH + 1]],
                                                  *_specs(rows[0]))))
    if limit < 4 * batch:
        pytest.skip(f"pipe-max-size {limit} B holds fewer than 4 batches of {batch} B")
    path = tmp_path / "p.mcap"
    rec = McapRecorder(path, params_from_file(), {}, writer="process", flush_interval=1e9)
    rec.write_sample(0.0, rows[0])
    pid = rec._proc.pid
    os.kill(pid, signal.SIGSTOP)
    try:
        worker = threading.Thread(target=lambda: [rec.write_sample(k / 60, rows[k]) for k in range(1, len(rows))])
        worker.start()
        worker.join(60)
        handed_off = not worker.is_alive()
    finally:
        os.kill(pid, signal.SIGCONT)
    worker.join()
    rec.close()
    assert 3 * batch > 65536, "the case must exceed the default pipe"
    assert handed_off, "a hand-off waited for the stopped child"
    assert len(read_log(path).t) == len(rows)
