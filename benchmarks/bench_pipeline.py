"""End-to-end speed of a scenario: plant + controller + logging.

    python benchmarks/bench_pipeline.py [--repeats 3] [--sweep-runs 8] [--scenario NAME ...]

Prints, for scenarios/paper.yaml (40 s, rac_dob) and the 3-D circle study
scenarios/bluerov2_alpha_circle_current.yaml (40 s, rac_dob; BlueROV2 Heavy + Alpha arm, 50 Hz):
  * the real-time factor of the whole pipeline (plant with hydrodynamics + 60 Hz controller +
    MCAP logging, the log closed) with the recorder's writer process (the default: encoding,
    compression and writes in a forked process, uvms_mj.io.writer_process) and with the inline
    writer, and of the pipeline without logging, by wall-clock time and by the process's CPU
    time (which a busy machine's preemptions do not inflate; the writer process's own CPU time
    is printed apart: it runs on the other core);
  * its ratio to bare MuJoCo stepping of the same model (no hydrodynamics, same integrator and
    timestep) over the same number of steps, by wall-clock time and by CPU time;
  * the split of the time between MuJoCo, hydrodynamics, controller, logging (write_sample and
    close in the simulation's process: with the writer process, the hand-off of the samples and
    the wait for the last batch at close; inline, the encoding and writing) and the loop;
  * sweep throughput (runs per second) with 1 and 2 worker processes.
Best of --repeats (the machine is shared and noisy).
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import multiprocessing as mp
import resource
import tempfile
import time
from pathlib import Path

import mujoco

from uvms_mj import default_model_path
from uvms_mj.sim.loop import run_closed_loop
from uvms_mj.io.recorder import McapRecorder
from uvms_mj.scenario.schema import build, load_scenario, sensor_model

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"
SCENARIO = SCENARIOS / "paper.yaml"
DEFAULT_SCENARIOS = ("paper", "bluerov2_alpha_circle_current")


class Timer:
    """Wraps a callable and accumulates its wall time."""

    def __init__(self, fn):
        self.fn, self.total = fn, 0.0

    def __call__(self, *a, **kw):
        t0 = time.perf_counter()
        try:
            return self.fn(*a, **kw)
        finally:
            self.total += time.perf_counter() - t0


def _child_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)  # (reaped children: the writer process after close)
    return r.ru_utime + r.ru_stime


def one_run(log: bool, split: bool = False, scenario: Path = SCENARIO, writer: str = "auto") -> dict:
    sc = load_scenario(scenario)
    plant, ctrl = build(sc)
    T = ctrl.T
    timers = {}
    if split:  # the loop steps through step_observe (the plant's compiled sample) where there is one
        if hasattr(plant, "step_observe"):
            timers["plant"] = plant.step_observe = Timer(plant.step_observe)
        else:
            timers["plant"] = plant.step = Timer(plant.step)
        timers["controller"] = ctrl.compute = Timer(ctrl.compute)
    with tempfile.TemporaryDirectory() as tmp:
        meta, kw = {"bench": True}, {}
        if getattr(getattr(plant, "layout", None), "base_free", False):  # as `uvms-mj run` records a floating robot
            from uvms_mj.scenario.robot import robot_info

            meta["robot"] = robot_info(sc, plant)
            kw["model"] = getattr(plant, "robot_model", plant.model)
        rec = McapRecorder(Path(tmp) / "bench.mcap", plant.params, meta, writer=writer, **kw) if log else None
        sink = None
        if rec is not None:
            sink = rec.write_sample
            if split:
                sink = timers["logging"] = Timer(rec.write_sample)
        t0, c0, k0 = time.perf_counter(), time.process_time(), _child_cpu()
        res = run_closed_loop(plant, ctrl, sc.duration, T=T, sensor=sensor_model(sc), seed=sc.seed,
                              warm_start=sc.warm_start, sink=sink)
        if rec is not None:  # close encodes and writes the samples since the last flush: logging too
            close = Timer(rec.close)
            close(res.status, res.reason)
            if split:
                timers["logging"].total += close.total
        wall = time.perf_counter() - t0
        cpu = time.process_time() - c0
        child = _child_cpu() - k0
    steps = round(sc.duration / plant.model.opt.timestep)
    return {"wall": wall, "cpu": cpu, "child_cpu": child, "steps": steps, "sim": sc.duration,
            "timers": {k: v.total for k, v in timers.items()},
            "integrator": plant.model.opt.integrator, "timestep": plant.model.opt.timestep, "backend": plant.backend,
            "path": plant.model_path, "T": T, "controller": ctrl.name}


def bare(steps: int, integrator, timestep: float, path=None) -> float:
    """Bare MuJoCo stepping of the same model file without its plugins (no hydrodynamics)."""
    from uvms_mj.physics import model as pm

    m = pm.compile_spec(pm.load_spec(path or default_model_path()), native=False)
    m.opt.integrator, m.opt.timestep = integrator, timestep
    d = mujoco.MjData(m)
    if m.nkey:
        mujoco.mj_resetDataKeyframe(m, d, 0)
    t0, c0 = time.perf_counter(), time.process_time()
    for _ in range(steps):
        mujoco.mj_step(m, d)
    return time.perf_counter() - t0, time.process_time() - c0


def sweep_job(duration: float) -> float:
    from uvms_mj.scenario.schema import run_scenario

    sc = load_scenario(SCENARIO, [f"duration={duration}"])
    return run_scenario(sc).t[-1]


def sweep_throughput(workers: int, runs: int, duration: float) -> float:
    ctx = mp.get_context("spawn")
    with cf.ProcessPoolExecutor(workers, mp_context=ctx) as ex:
        list(ex.map(sweep_job, [1.0] * workers))  # start the workers (imports, native build)
        t0 = time.perf_counter()
        list(ex.map(sweep_job, [duration] * runs))
        return runs / (time.perf_counter() - t0)


def report(scenario: Path, repeats: int) -> None:
    fulls = [one_run(log=True, scenario=scenario) for _ in range(repeats)]
    inlines = [one_run(log=True, scenario=scenario, writer="inline") for _ in range(repeats)]
    nologs = [one_run(log=False, scenario=scenario) for _ in range(repeats)]
    full, nolog = min(fulls, key=lambda r: r["wall"]), min(nologs, key=lambda r: r["wall"])
    inline = min(inlines, key=lambda r: r["wall"])
    split = min((one_run(log=True, split=True, scenario=scenario) for _ in range(repeats)), key=lambda r: r["wall"])
    bares = [bare(full["steps"], full["integrator"], full["timestep"], full["path"]) for _ in range(repeats)]
    t_bare, c_bare = min(b[0] for b in bares), min(b[1] for b in bares)

    sim = full["sim"]
    print(f"{scenario.stem}: {sim:g} s simulated, {full['steps']} physics steps ({full['timestep'] * 1e3:.3g} ms), "
          f"controller {full['controller']} at {1 / full['T']:.0f} Hz, backend {full['backend']}, best of {repeats}")
    rows = [("with logging (writer process)", full, fulls), ("with logging (inline writer)", inline, inlines),
            ("without logging", nolog, nologs)]
    print(f"  {'pipeline':<38}{'wall':>8}   {'real time':>9}  {'/ bare':>6}   {'CPU':>7}  {'/ bare':>6}   writer CPU")
    for label, best, runs in rows:
        cpu = min(r["cpu"] for r in runs)
        kid = min(r["child_cpu"] for r in runs)
        print(f"  {label:<38}{best['wall']:7.3f}s  {sim / best['wall']:8.1f}x  {best['wall'] / t_bare:5.2f}x   "
              f"{cpu:6.3f}s  {cpu / c_bare:5.2f}x   " + (f"{kid:.3f} s" if kid > 0 else "-"))
    print(f"  {'bare MuJoCo stepping':<38}{t_bare:7.3f}s  {sim / t_bare:8.1f}x  {1:5.2f}x   {c_bare:6.3f}s  {1:5.2f}x")
    tm = split["timers"]
    parts = {
        "MuJoCo (bare stepping)": t_bare,
        "hydrodynamics and plant (- bare)": max(tm["plant"] - t_bare, 0.0),
        "controller (compute)": tm["controller"],
        "logging (MCAP write)": tm["logging"],
    }
    parts["loop, sensors, recording"] = max(split["wall"] - sum(parts.values()), 0.0)
    print("  split of the pipeline (instrumented run, %.3f s):" % split["wall"])
    for k, v in parts.items():
        print(f"    {k:<32}{v:7.3f} s  {100 * v / split['wall']:5.1f} %")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--sweep-runs", type=int, default=8)
    ap.add_argument("--sweep-duration", type=float, default=10.0)
    ap.add_argument("--scenario", nargs="+", default=list(DEFAULT_SCENARIOS), help="scenario names (scenarios/)")
    args = ap.parse_args()

    for name in args.scenario:
        report(SCENARIOS / f"{name}.yaml", args.repeats)
    if args.sweep_runs:
        r1 = sweep_throughput(1, args.sweep_runs, args.sweep_duration)
        r2 = sweep_throughput(2, args.sweep_runs, args.sweep_duration)
        print(f"  sweep ({args.sweep_runs} runs of {args.sweep_duration:g} s, no logs): "
              f"1 worker {r1:.2f} runs/s, 2 workers {r2:.2f} runs/s, speed-up {r2 / r1:.2f}x")


if __name__ == "__main__":
    main()
