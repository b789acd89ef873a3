"""Where a sweep's runs execute: ``process`` (a spawn-started process pool; a worker dies with
its sweep), ``ray`` (Ray tasks) or ``serial`` (this process). Each calls ``done(task, result)``
as runs finish; a run never raises (its failure is its result)."""

from __future__ import annotations

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


#: The sweep's process, in a worker of the process engine (None elsewhere).
_PARENT_PID: int | None = None


def _parent_gone() -> bool:
    return _PARENT_PID is not None and os.getppid() != _PARENT_PID


def _watch_parent() -> None:
    while True:
        time.sleep(0.5)
        if _parent_gone():
            os._exit(1)


def _worker_init(parent: int) -> None:
    """Initializer of the process engine's workers: a worker ends with its sweep, even after
    ``kill -9`` of the sweep (Linux: PR_SET_PDEATHSIG; everywhere: a thread polling
    os.getppid() every 0.5 s, and a check before each run)."""
    global _PARENT_PID
    import signal
    import sys
    import threading

    _PARENT_PID = parent
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
    metrics, t_end, wall_s."""
    if _parent_gone():
        os._exit(1)
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
            Path(log).parent.mkdir(parents=True, exist_ok=True)
            meta = {"scenario": resolved(sc), "seed": sc.seed, "sweep": {"run_id": task["run_id"],
                                                                         "sample": task["sample"]}}
            with McapRecorder(log, plant.params, meta) as rec:
                res = _run_scenario(sc, sink=rec.write_sample)
                rec.close(status=res.status, reason=res.reason, meta=res.meta)
        else:
            res = _run_scenario(sc)
        out["status"], out["reason"] = str(res.status), _one_line(res.reason)
        out["t_end"] = float(res.t[-1]) if len(res.t) else 0.0
        try:
            out["metrics"] = {k: float(v) for k, v in metrics(res).items()}
        except Exception as exc:  # noqa: BLE001 - e.g. no sample at all
            out["reason"] = _one_line(f"{out['reason']}; metrics unavailable: {type(exc).__name__}: {exc}")
    except Exception as exc:  # noqa: BLE001 - recorded, never stops the sweep
        out["status"], out["reason"] = "error", _one_line(f"{type(exc).__name__}: {exc}")
    out["wall_s"] = time.perf_counter() - t0
    return out


def _run_scenario(scenario, sink=None):
    """uvms_mj.scenario.schema.run_scenario, imported when a run starts (a module attribute, so that
    tests can replace it)."""
    from uvms_mj.scenario.schema import run_scenario as rs

    return rs(scenario, sink=sink)


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

    ctx = mp.get_context("spawn")
    queue = list(tasks)
    attempts: dict[str, int] = {}
    while queue:
        pool = ProcessPoolExecutor(max_workers=max(1, min(workers, len(queue))), mp_context=ctx,
                                   initializer=_worker_init, initargs=(os.getpid(),))
        try:
            futs = {pool.submit(execute_run, t): t for t in queue}
            queue = []
            for fut in as_completed(futs):
                t = futs[fut]
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
                    res = {"status": "error", "reason": _one_line(f"{type(exc).__name__}: {exc}"), "metrics": {},
                           "t_end": float("nan"), "wall_s": float("nan")}
                done(t, res)
        except BaseException:
            pool.shutdown(wait=True, cancel_futures=True)
            raise
        pool.shutdown(wait=True)


def _engine_ray(tasks: list[dict], workers: int, done: Callable[[dict, dict], None]) -> None:
    try:
        import ray
    except ImportError:
        raise SweepError(RAY_MISSING) from None
    started = False
    if not ray.is_initialized():
        if os.environ.get("RAY_ADDRESS"):
            ray.init(log_to_driver=False)
        else:
            ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False)
        started = True
    try:
        remote = ray.remote(num_cpus=1, max_retries=MAX_ATTEMPTS - 1)(execute_run)
        pending = {remote.remote(t): t for t in tasks}
        try:
            while pending:
                ready, _ = ray.wait(list(pending), num_returns=1)
                for ref in ready:
                    t = pending.pop(ref)
                    try:
                        res = ray.get(ref)
                    except Exception as exc:  # noqa: BLE001 - worker crash, task error
                        res = _crashed(exc)
                    done(t, res)
        except BaseException:
            for ref in pending:
                ray.cancel(ref, force=True)
            raise
    finally:
        if started:
            ray.shutdown()


_ENGINES = {"process": _engine_process, "ray": _engine_ray, "serial": _engine_serial}
