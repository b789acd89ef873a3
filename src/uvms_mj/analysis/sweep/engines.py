"""Where a sweep's runs execute: ``process`` (a spawn-started process pool; a worker dies with
its sweep), ``ray`` (Ray tasks) or ``serial`` (this process). Each calls ``done(task, result)``
as runs finish; a run never raises (its failure is its result).

Interrupted (KeyboardInterrupt: SIGINT, or SIGTERM inside :func:`uvms_mj.io.interrupts.handle_sigterm`),
an engine starts no further run, records the runs whose results are already back, ends its
workers (process: SIGTERM, which closes a worker's log with status "interrupted" and ends it;
SIGKILL for one still alive :data:`WORKER_GRACE_S` later; ray: the tasks cancelled with force)
and re-raises. A process worker ignores SIGINT (a terminal's Ctrl-C reaches the whole process
group: the sweep's process ends its workers)."""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from uvms_mj.analysis.sweep.spec import SweepError

ENGINES = ("process", "ray", "serial")
RAY_MISSING = ("--engine ray needs Ray, which is not installed: pip install 'uvms-mj[ray]' "
               "(or pip install ray); the default --engine process needs nothing more")
#: Tries of a run whose worker process died before it is recorded as ``crashed``.
MAX_ATTEMPTS = 3


def check_engine(engine: str) -> None:
    """Unknown engine, or Ray asked for and missing: SweepError (before any run)."""
    if engine not in ENGINES:
        raise SweepError(f"--engine {engine!r}: unknown; choose one of {', '.join(ENGINES)}")
    if engine == "ray":
        try:
            import ray  # noqa: F401
        except ImportError:
            raise SweepError(RAY_MISSING) from None


def _one_line(text: str, limit: int = 400) -> str:
    s = " ".join(str(text).split())
    return s if len(s) <= limit else s[:limit - 3] + "..."


#: Seconds an interrupted process engine waits for its workers to end after SIGTERM (they close
#: their log and exit in milliseconds) before it kills them. Ours: within the command line's 1.5 s
#: grace (uvms_mj.io.interrupts.GRACE_S), leaving time for the table.
WORKER_GRACE_S = 0.5

#: The sweep's process, in a worker of the process engine (None elsewhere).
_PARENT_PID: int | None = None
#: The sweep's stop flag (a multiprocessing Event set when it is interrupted), in a worker.
_STOP = None
#: True while a worker executes a run (SIGTERM then closes the run's log before the worker ends).
_IN_RUN = False


def _parent_gone() -> bool:
    return _PARENT_PID is not None and os.getppid() != _PARENT_PID


def _watch_parent() -> None:
    while True:
        time.sleep(0.5)
        if _parent_gone():
            os._exit(1)


def _worker_sigterm(signum, frame) -> None:  # noqa: ARG001
    """A worker's SIGTERM: inside a run, the interrupt of handle_sigterm (the run's log closes with
    status "interrupted", then :func:`execute_run` ends the worker); between runs, exit at once."""
    if not _IN_RUN:
        os._exit(130)
    from uvms_mj.io.interrupts import _on_signal

    _on_signal(signum, frame)


def _worker_init(parent: int, stop=None) -> None:
    """Initializer of the process engine's workers: a worker ends with its sweep, even after
    ``kill -9`` of the sweep (Linux: PR_SET_PDEATHSIG; everywhere: a thread polling
    os.getppid() every 0.5 s, and a check before each run); it ignores SIGINT and ends on
    SIGTERM (:func:`_worker_sigterm`); with ``stop`` set it starts no run."""
    global _PARENT_PID, _STOP
    import signal
    import sys
    import threading

    _PARENT_PID, _STOP = parent, stop
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _worker_sigterm)
    if sys.platform.startswith("linux"):
        try:
            import ctypes

            ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL), 0, 0, 0)  # PR_SET_PDEATHSIG
        except (OSError, AttributeError):
            pass
    if _parent_gone():
        os._exit(1)
    threading.Thread(target=_watch_parent, name="uvms-mj-parent-watch", daemon=True).start()


def execute_run(task: dict) -> dict:
    """Run one task (in a worker): never raises for a failing run; returns status, reason,
    metrics, t_end, wall_s. In a process worker, an interrupt (SIGTERM) ends the worker once the
    run's log is closed."""
    global _IN_RUN
    if _parent_gone() or (_STOP is not None and _STOP.is_set()):
        os._exit(1)
    if _PARENT_PID is None:
        return _execute_run(task)
    _IN_RUN = True
    try:
        return _execute_run(task)
    except KeyboardInterrupt:
        os._exit(130)
    finally:
        _IN_RUN = False


def _execute_run(task: dict) -> dict:
    t0 = time.perf_counter()
    out: dict[str, Any] = {"status": "error", "reason": "", "metrics": {}, "t_end": float("nan")}
    try:
        from uvms_mj.sim.experiment import metrics
        from uvms_mj.scenario.schema import validate_scenario

        sc = validate_scenario(task["scenario"], f"run {task['run_id']}")
        log = task.get("log")
        if log:
            from uvms_mj.io.writer import McapRecorder
            from uvms_mj.scenario.schema import build, resolved

            plant, _ = build(sc)
            if _STOP is not None and _STOP.is_set():  # the sweep was interrupted while this run was set up
                os._exit(1)
            Path(log).parent.mkdir(parents=True, exist_ok=True)
            meta = {"scenario": resolved(sc), "seed": sc.seed, "sweep": {"run_id": task["run_id"],
                                                                         "sample": task["sample"]}}
            with McapRecorder(log, plant.params, meta) as rec:
                res = _run_scenario(sc, sink=rec.write_sample)
                rec.close(status=res.status, reason=res.reason, meta=res.meta)
        else:
            res = _run_scenario(sc)
        out["status"], out["reason"] = str(res.status), _one_line(res.reason)
        out["t_end"] = _t_end(res)
        try:
            out["metrics"] = {k: float(v) for k, v in metrics(res).items()}
        except Exception as exc:  # noqa: BLE001 - e.g. no sample at all
            out["reason"] = _one_line(f"{out['reason']}; metrics unavailable: {type(exc).__name__}: {exc}")
    except Exception as exc:  # noqa: BLE001 - recorded, never stops the sweep
        out["status"], out["reason"] = "error", _one_line(f"{type(exc).__name__}: {exc}")
    out["wall_s"] = time.perf_counter() - t0
    return out


def _run_scenario(scenario, sink=None, keep=False):
    """uvms_mj.scenario.schema.run_scenario, imported when a run starts (a module attribute, so that
    tests can replace it); streamed by default (``keep=False``: a worker's memory does not grow
    with the run's duration)."""
    from uvms_mj.scenario.schema import run_scenario as rs

    return rs(scenario, sink=sink, keep=keep)


def _t_end(res) -> float:
    """The last sample's time [s] of a run (0 without one): its meta's ``t_end``, else its times."""
    t = (res.meta or {}).get("t_end")
    if t is None:
        return float(res.t[-1]) if len(res.t) else 0.0
    return 0.0 if math.isnan(t) else float(t)


def _crashed(exc: BaseException) -> dict:
    return {"status": "crashed", "reason": _one_line(f"worker died: {type(exc).__name__}: {exc}"), "metrics": {},
            "t_end": float("nan"), "wall_s": float("nan")}


def _engine_serial(tasks: list[dict], workers: int, done: Callable[[dict, dict], None]) -> None:
    for t in tasks:
        done(t, execute_run(t))


def _engine_process(tasks: list[dict], workers: int, done: Callable[[dict, dict], None]) -> None:
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor, as_completed
    from concurrent.futures.process import BrokenProcessPool

    from uvms_mj.io.interrupts import _on_interrupt

    ctx = mp.get_context("spawn")
    stop = ctx.Event()
    queue = list(tasks)
    attempts: dict[str, int] = {}
    _on_interrupt.append(stop.set)  # set in the signal handler itself: no worker starts a run after it
    try:
        while queue:
            pool = ProcessPoolExecutor(max_workers=max(1, min(workers, len(queue))), mp_context=ctx,
                                       initializer=_worker_init, initargs=(os.getpid(), stop))
            futs: dict = {}
            recorded: set = set()
            try:
                futs = {pool.submit(execute_run, t): t for t in queue}
                queue = []
                for fut in as_completed(futs):
                    t = futs[fut]
                    recorded.add(fut)
                    try:
                        res = fut.result()
                    except BrokenProcessPool as exc:
                        attempts[t["run_id"]] = attempts.get(t["run_id"], 0) + 1
                        if attempts[t["run_id"]] >= MAX_ATTEMPTS:
                            done(t, _crashed(exc))
                        else:
                            queue.append(t)
                        continue
                    except Exception as exc:  # noqa: BLE001 - e.g. a result that does not unpickle
                        res = _failed(exc)
                    done(t, res)
            except BaseException:
                stop.set()
                _end_pool(pool)
                _record_finished(futs, recorded, done)
                _drop_unopened_logs(t for f, t in futs.items() if f not in recorded)
                raise
            pool.shutdown(wait=True)
    finally:
        _on_interrupt.remove(stop.set)


def _failed(exc: BaseException) -> dict:
    return {"status": "error", "reason": _one_line(f"{type(exc).__name__}: {exc}"), "metrics": {},
            "t_end": float("nan"), "wall_s": float("nan")}


def _end_pool(pool) -> None:
    """An interrupted pool: queued runs cancelled, its workers sent SIGTERM (they close the log of
    the run they are in and exit), killed if still alive WORKER_GRACE_S later."""
    procs = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for p in procs:
        try:
            p.terminate()
        except (OSError, ValueError):
            pass
    deadline = time.monotonic() + WORKER_GRACE_S
    for p in procs:
        p.join(max(0.0, deadline - time.monotonic()))
    for p in procs:
        if p.is_alive():
            try:
                p.kill()
                p.join(0.1)
            except (OSError, ValueError):
                pass


def _record_finished(futs: dict, recorded: set, done: Callable[[dict, dict], None]) -> None:
    """The runs whose results came back but were not recorded yet (the interrupt came first); and
    those whose worker finished the run (its log closed with a final status) but whose result was
    still in the pipe when the pool was ended: their row from the log (:func:`_result_from_log`)."""
    for fut, t in futs.items():
        if fut in recorded or fut.cancelled():
            continue
        if fut.done() and fut.exception() is None:
            done(t, fut.result())
            continue
        res = _result_from_log(t)
        if res is not None:
            done(t, res)


#: The statuses of a finished run: not retried on resume (``crashed`` is); a log closed with one
#: of them (not "interrupted") is a finished run.
FINISHED = ("ok", "diverged", "error", "joint_limit")


def _result_from_log(task: dict) -> dict | None:
    """A task's result read back from its complete log (status, reason, metrics, t_end; wall_s
    unknown: NaN), or None (no log, a log cut short or interrupted, unreadable)."""
    log = task.get("log")
    if not log or not Path(log).is_file():
        return None
    try:
        from uvms_mj.io.recorder import read_log
        from uvms_mj.sim.experiment import metrics

        data = read_log(log)
        if data.truncated or data.status not in FINISHED:
            return None
        return {"status": str(data.status), "reason": _one_line(data.reason or ""),
                "metrics": {k: float(v) for k, v in metrics(data).items()},
                "t_end": float(data.t[-1]) if len(data.t) else 0.0, "wall_s": float("nan")}
    except Exception:  # noqa: BLE001 - a log that cannot be read gives no row
        return None


def _drop_unopened_logs(tasks) -> None:
    """Remove the logs of interrupted runs whose worker was ended between creating the file and
    writing its header (not an MCAP file, so not a log any command can read); a log with its
    header stays (readable, called truncated or interrupted)."""
    from uvms_mj.io.reader import _MAGIC

    for t in tasks:
        log = t.get("log")
        if not log:
            continue
        try:
            with open(log, "rb") as f:
                head = f.read(len(_MAGIC))
        except OSError:
            continue
        if head != _MAGIC:
            Path(log).unlink(missing_ok=True)


def _execute_ray(task: dict) -> dict:
    """:func:`execute_run` in a Ray task's process, marked as a pool worker (logs written inline)."""
    from uvms_mj.io.writer_process import mark_pool_worker

    mark_pool_worker()
    return execute_run(task)


def _engine_ray(tasks: list[dict], workers: int, done: Callable[[dict, dict], None]) -> None:
    try:
        import ray
    except ImportError:
        raise SweepError(RAY_MISSING) from None
    started = False
    handlers = _signal_handlers()
    if not ray.is_initialized():
        if os.environ.get("RAY_ADDRESS"):
            ray.init(log_to_driver=False)
        else:
            ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False)
        started = True
    _reclaim_signals(handlers)
    interrupted = False
    try:
        remote = ray.remote(num_cpus=1, max_retries=MAX_ATTEMPTS - 1)(_execute_ray)
        pending = {remote.remote(t): t for t in tasks}
        try:
            while pending:
                # a short timeout: the main thread returns to Python (and a signal's handler) at least every 0.2 s
                ready, _ = ray.wait(list(pending), num_returns=1, timeout=0.2)
                for ref in ready:
                    t = pending.pop(ref)
                    try:
                        res = ray.get(ref)
                    except Exception as exc:  # noqa: BLE001 - worker crash, task error
                        res = _crashed(exc)
                    done(t, res)
        except BaseException:
            interrupted = True
            ready, _ = ray.wait(list(pending), num_returns=len(pending), timeout=0) if pending else ([], [])
            for ref in ready:  # finished before the interrupt was seen: recorded, not lost
                t = pending.pop(ref)
                try:
                    done(t, ray.get(ref, timeout=0.1))
                except Exception:  # noqa: BLE001 - a failed task: re-run on resume
                    pass
            for ref in pending:
                try:
                    ray.cancel(ref, force=True)
                except Exception:  # noqa: BLE001 - a task that ended meanwhile
                    pass
            if pending:  # the cancels are asynchronous: let the killed workers go before the clean-up
                ray.wait(list(pending), num_returns=len(pending), timeout=WORKER_GRACE_S)
            for t in pending.values():  # its log closed with a final status, its result not back: the row from the log
                res = _result_from_log(t)
                if res is not None:
                    done(t, res)
            _drop_unopened_logs(pending.values())
            raise
    finally:
        if started and not interrupted:
            # Interrupted, the sweep writes its table first: Ray's own exit handler (or the command
            # line's watchdog, which kills the child processes) ends the local cluster after.
            ray.shutdown()


def _signal_handlers() -> dict:
    import signal

    return {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}


def _reclaim_signals(handlers: dict) -> None:
    """Put back this process's handlers of SIGINT and SIGTERM (``handlers``, from before
    ray.init): Ray installs its own in the driver (SIGTERM: exit 1, or abort with rc -6 from its
    C++ handler), which would bypass the sweep's interrupt (rows written, exit 130)."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        return
    for sig, handler in handlers.items():
        if handler is not None:
            signal.signal(sig, handler)


_ENGINES = {"process": _engine_process, "ray": _engine_ray, "serial": _engine_serial}
