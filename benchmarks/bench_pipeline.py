"""End-to-end speed of a scenario: plant + controller + logging.

    python benchmarks/bench_pipeline.py [--repeats 3] [--sweep-runs 8] [--scenario NAME ...]

Prints, for scenarios/paper.yaml (40 s, rac_dob) and the 3-D circle study
scenarios/bluerov2_alpha_circle_current.yaml (40 s, rac_dob; BlueROV2 Heavy + Alpha arm, 50 Hz):
  * the real-time factor of the whole pipeline (plant with hydrodynamics + 60 Hz controller +
    MCAP logging, the log closed) and of the pipeline without logging, by wall-clock time and by
    the process's CPU time (which a busy machine's preemptions do not inflate);
  * its ratio to bare MuJoCo stepping of the same model (no hydrodynamics, same integrator and
    timestep) over the same number of steps;
  * the split of the time between MuJoCo, hydrodynamics, controller, logging (write_sample and
    close: the recorder encodes its samples in batches at each flush) and the loop;
  * sweep throughput (runs per second) with 1 and 2 worker processes.
Best of --repeats (the machine is shared and noisy).
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import multiprocessing as mp
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


def one_run(log: bool, split: bool = False, scenario: Path = SCENARIO) -> dict:
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
        rec = McapRecorder(Path(tmp) / "bench.mcap", plant.params, meta, **kw) if log else None
        sink = None
        if rec is not None:
            sink = rec.write_sample
            if split:
                sink = timers["logging"] = Timer(rec.write_sample)
        t0, c0 = time.perf_counter(), time.process_time()
        res = run_closed_loop(plant, ctrl, sc.duration, T=T, sensor=sensor_model(sc), seed=sc.seed,
                              warm_start=sc.warm_start, sink=sink)
        if rec is not None:  # close encodes and writes the samples since the last flush: logging too
            close = Timer(rec.close)
            close(res.status, res.reason)
            if split:
                timers["logging"].total += close.total
        wall = time.perf_counter() - t0
        cpu = time.process_time() - c0
    steps = round(sc.duration / plant.model.opt.timestep)
    return {"wall": wall, "cpu": cpu, "steps": steps, "sim": sc.duration, "timers": {k: v.total for k, v in timers.items()},
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
    t0 = time.perf_counter()
    for _ in range(steps):
        mujoco.mj_step(m, d)
    return time.perf_counter() - t0


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
    nologs = [one_run(log=False, scenario=scenario) for _ in range(repeats)]
    full, nolog = min(fulls, key=lambda r: r["wall"]), min(nologs, key=lambda r: r["wall"])
    split = min((one_run(log=True, split=True, scenario=scenario) for _ in range(repeats)), key=lambda r: r["wall"])
    t_bare = min(bare(full["steps"], full["integrator"], full["timestep"], full["path"]) for _ in range(repeats))

    sim = full["sim"]
    print(f"{scenario.stem}: {sim:g} s simulated, {full['steps']} physics steps ({full['timestep'] * 1e3:.3g} ms), "
          f"controller {full['controller']} at {1 / full['T']:.0f} Hz, backend {full['backend']}, best of {repeats}")
    cpu_full = min(r["cpu"] for r in fulls)
    cpu_nolog = min(r["cpu"] for r in nologs)
    print(f"  pipeline with logging     {full['wall']:7.3f} s   {sim / full['wall']:6.1f}x real time   "
          f"{full['wall'] / t_bare:5.1f}x bare MuJoCo   (CPU time {cpu_full:.3f} s: {sim / cpu_full:.1f}x)")
    print(f"  pipeline without logging  {nolog['wall']:7.3f} s   {sim / nolog['wall']:6.1f}x real time   "
          f"{nolog['wall'] / t_bare:5.1f}x bare MuJoCo   (CPU time {cpu_nolog:.3f} s: {sim / cpu_nolog:.1f}x)")
    print(f"  bare MuJoCo stepping      {t_bare:7.3f} s   {sim / t_bare:6.1f}x real time")
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
