"""Benchmark: microseconds per physics step, bare MuJoCo vs the full plant on each backend.

    python benchmarks/bench_plant.py [--seconds 20] [--repeats 5]

Bare = the same model file stepped by MuJoCo with no hydrodynamics callback (same integrator
and timestep). Plant = uvms_mj.Plant() with added mass, strip drag and buoyancy, once with the
pure-Python hydrodynamics (backend="python") and once with their C port (backend="native";
skipped, with the reason, if it cannot be built). Prints the best of several repeats (the
machine is shared and noisy: +-30 %), the ratio to bare MuJoCo and the real-time factor
(simulated seconds per wall-clock second).
"""

from __future__ import annotations

import argparse
import time

import mujoco

from uvms_mj import Plant, default_model_path, native


def time_steps(step, n: int, repeats: int) -> float:
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        step(n)
        best = min(best, time.perf_counter() - t0)
    return best / n


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=20.0, help="simulated seconds per repeat")
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()

    backends = ["python", "native"]
    if native.load() is None:
        print(f"native backend unavailable: {native.unavailable_reason()}")
        backends.remove("native")

    rows = []
    for label, integrator, dt in (("default (RK4, 1/120 s)", None, None), ("Euler, 1/600 s", "euler", 1 / 600)):
        bare_m = mujoco.MjModel.from_xml_path(str(default_model_path()))
        bare_d = mujoco.MjData(bare_m)
        n = 0

        def bare(k: int) -> None:
            for _ in range(k):
                mujoco.mj_step(bare_m, bare_d)

        t_bare = None
        for backend in backends:
            plant = Plant(integrator=integrator, timestep=dt, backend=backend)
            m = plant.model
            if t_bare is None:
                n = int(round(args.seconds / m.opt.timestep))
                bare_m.opt.integrator, bare_m.opt.timestep = m.opt.integrator, m.opt.timestep
                mujoco.mj_resetDataKeyframe(bare_m, bare_d, 0)
                t_bare = time_steps(bare, n, args.repeats)
                rows.append((label, "bare mujoco", t_bare * 1e6, 1.0, m.opt.timestep / t_bare))

            def full(k: int, plant: Plant = plant) -> None:
                plant.reset()
                plant.set_state(base_velocity=(0.05, 0.02, 0.1), joint_velocities=(0.3, -0.3))
                plant.step(k)

            t_full = time_steps(full, n, args.repeats)
            rows.append((label, f"plant, {plant.backend}", t_full * 1e6, t_full / t_bare, m.opt.timestep / t_full))

    print(f"mujoco {mujoco.__version__}; {args.seconds:g} s simulated, best of {args.repeats}")
    print(f"{'setting':<24}{'run':<16}{'us/step':>10}{'x bare':>9}{'RTF':>10}")
    for label, what, us, ratio, rtf in rows:
        print(f"{label:<24}{what:<16}{us:>10.2f}{ratio:>9.2f}{rtf:>9.0f}x")


if __name__ == "__main__":
    main()
