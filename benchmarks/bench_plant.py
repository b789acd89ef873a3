"""Benchmark: microseconds per physics step, bare MuJoCo vs the same model in water.

    python benchmarks/bench_plant.py [--seconds 10] [--repeats 5] [--rollouts 64]

For each robot (the paper's planar robot ``models/paper/scene.xml``, the 3-D test robot
``tests/models/robot3d.xml``: a free-floating base with a 4-link arm, and the BlueROV2 Heavy
with an Alpha-class arm ``models/bluerov2_alpha/bluerov2_alpha.xml``) and each setting (the model's own integrator at
the model's step, Euler at 1/600 s), plain ``mujoco.mj_step`` loops on:

* bare: the same model file with the uvms plugins removed (no hydrodynamics);
* plugin: the model file as it is, the C plugins applying the hydrodynamics;
* python: the numpy reference through ``mjcb_passive`` (the fallback without a C compiler);
* (paper robot only) ``Plant.step``: the plant's loop with its divergence checks.

Then ``mujoco.rollout`` of N runs of the 3-D robot (1 s each) on 1 and 2 threads. Prints the
best of several repeats (the machine is shared: +-30 %), the ratio to bare MuJoCo and the
real-time factor (simulated seconds per wall-clock second).
"""

from __future__ import annotations

import argparse
import gc
import time
from pathlib import Path

import mujoco
import numpy as np
from mujoco import rollout

from uvms_mj import Plant, default_model_path
from uvms_mj.physics import build, model as pm
from uvms_mj.physics import python_backend

ROOT = Path(__file__).resolve().parents[1]
ROBOTS = {"paper (5 dof)": default_model_path(), "robot3d (10 dof)": ROOT / "tests" / "models" / "robot3d.xml",
          "bluerov2_heavy (6 dof)": ROOT / "models" / "bluerov2_heavy" / "bluerov2_heavy.xml",
          "bluerov2_alpha (10 dof)": ROOT / "models" / "bluerov2_alpha" / "bluerov2_alpha.xml"}


def best_time(fn, n: int, repeats: int) -> float:
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn(n)
        best = min(best, time.perf_counter() - t0)
    return best / n


def stepper(m: mujoco.MjModel, d: mujoco.MjData):
    qvel0 = np.random.default_rng(0).normal(0, 0.2, m.nv)

    def run(k: int) -> None:
        mujoco.mj_resetData(m, d)
        d.qvel[:] = qvel0
        for _ in range(k):
            mujoco.mj_step(m, d)

    return run


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=10.0, help="simulated seconds per repeat")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--rollouts", type=int, default=64)
    ap.add_argument("--robots", default=None, help="comma-separated name prefixes (e.g. bluerov2_heavy); default: all")
    ap.add_argument("--no-rollout", action="store_true", help="skip the mujoco.rollout part")
    args = ap.parse_args()
    if not build.register_plugins():
        raise SystemExit(f"the C plugins are unavailable: {build.unavailable_reason()}")

    rows = []
    wanted = [w.strip() for w in args.robots.split(",")] if args.robots else None
    for robot, path in ROBOTS.items():
        if wanted is not None and not any(robot.startswith(w) for w in wanted):
            continue
        spec = pm.load_spec(path)
        probe = pm.compile_spec(spec, native=False)
        default = (f"{mujoco.mjtIntegrator(probe.opt.integrator).name.removeprefix('mjINT_')}, "
                   f"{probe.opt.timestep * 1e3:.3g} ms (model)")
        settings = ((default, None, None), ("Euler, 1/600 s", mujoco.mjtIntegrator.mjINT_EULER, 1 / 600))
        for label, integrator, dt in settings:
            models = {"bare": pm.compile_spec(spec, native=False), "plugin": pm.compile_spec(spec, native=True),
                      "python": pm.compile_spec(spec, native=False)}
            for m in models.values():
                if integrator is not None:
                    m.opt.integrator, m.opt.timestep = integrator, dt
            h = models["bare"].opt.timestep
            n = int(round(args.seconds / h))
            t_bare = None
            for what, m in models.items():
                d = mujoco.MjData(m)
                if what == "python":
                    served = python_backend.Served(m, d, pm.hydro_of(m))  # noqa: F841 (keeps it served)
                k = n if what != "python" else max(1, n // 20)
                t = best_time(stepper(m, d), k, args.repeats if what != "python" else 1)
                t_bare = t if what == "bare" else t_bare
                rows.append((robot, label, what, t * 1e6, t / t_bare, h / t))
            if robot.startswith("paper"):
                plant = Plant(integrator=None if integrator is None else "euler", timestep=dt)

                def loop(k: int, plant: Plant = plant) -> None:
                    plant.reset()
                    plant.set_state(base_velocity=(0.05, 0.02, 0.1), joint_velocities=(0.3, -0.3))
                    plant.step(k)

                t = best_time(loop, n, args.repeats)
                rows.append((robot, label, "Plant.step", t * 1e6, t / t_bare, h / t))

    print(f"mujoco {mujoco.__version__}; {args.seconds:g} s simulated, best of {args.repeats} "
          "(python: 1/20 of the steps, once)")
    print(f"{'robot':<25}{'setting':<28}{'run':<12}{'us/step':>9}{'x bare':>8}{'RTF':>9}")
    for robot, label, what, us, ratio, rtf in rows:
        print(f"{robot:<25}{label:<28}{what:<12}{us:>9.2f}{ratio:>8.2f}{rtf:>8.0f}x")

    if args.no_rollout:
        return
    # rollout: N runs of 1 s of the 3-D robot from random velocities, 1 vs 2 threads (with no
    # Python mjcb_passive left installed by the python rows above)
    del served, d
    gc.collect()
    assert mujoco.get_mjcb_passive() is None
    m = pm.compile_spec(pm.load_spec(ROBOTS["robot3d (10 dof)"]), native=True)
    nstep = int(round(1.0 / m.opt.timestep))
    rng = np.random.default_rng(1)
    d = mujoco.MjData(m)
    size = mujoco.mj_stateSize(m, mujoco.mjtState.mjSTATE_FULLPHYSICS)
    state0 = np.empty((args.rollouts, size))
    for i in range(args.rollouts):
        mujoco.mj_resetData(m, d)
        d.qvel[:] = rng.normal(0, 0.2, m.nv)
        mujoco.mj_getState(m, d, state0[i], mujoco.mjtState.mjSTATE_FULLPHYSICS)
    times = {}
    results = {}
    for threads in (1, 2):
        datas = [mujoco.MjData(m) for _ in range(threads)]
        best = float("inf")
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            results[threads], _ = rollout.rollout(m, datas, state0, nstep=nstep)
            best = min(best, time.perf_counter() - t0)
        times[threads] = best
    same = np.array_equal(results[1], results[2])
    print(f"rollout of {args.rollouts} x {nstep} steps (robot3d): 1 thread {times[1]:.3f} s, 2 threads "
          f"{times[2]:.3f} s, speed-up {times[1] / times[2]:.2f}x; results identical: {same}")


if __name__ == "__main__":
    main()
