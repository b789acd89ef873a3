"""Benchmark: microseconds per physics step, bare MuJoCo vs the full plant.

    python benchmarks/bench_plant.py [--seconds 20] [--repeats 5]

Bare = the same model file stepped by MuJoCo with no hydrodynamics callback (same integrator
and timestep). Full = uvms_mj.Plant() with added mass, strip drag and buoyancy. Prints the best
of several repeats (the machine is shared and noisy: +-30 %), the ratio and the real-time
factor (simulated seconds per wall-clock second).
"""

from __future__ import annotations

import argparse
import time

import mujoco

from uvms_mj import Plant, default_model_path


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

    rows = []
    for label, integrator, dt in (("default (RK4, 1/120 s)", None, None), ("Euler, 1/600 s", "euler", 1 / 600)):
        plant = Plant(integrator=integrator, timestep=dt)
        m = plant.model
        n = int(round(args.seconds / m.opt.timestep))

        bare_m = mujoco.MjModel.from_xml_path(str(default_model_path()))
        bare_m.opt.integrator, bare_m.opt.timestep = m.opt.integrator, m.opt.timestep
        bare_d = mujoco.MjData(bare_m)
        mujoco.mj_resetDataKeyframe(bare_m, bare_d, 0)

        def bare(k: int) -> None:
            for _ in range(k):
                mujoco.mj_step(bare_m, bare_d)

        def full(k: int) -> None:
            plant.reset()
            plant.set_state(base_velocity=(0.05, 0.02, 0.1), joint_velocities=(0.3, -0.3))
            plant.step(k)

        t_bare = time_steps(bare, n, args.repeats)
        t_full = time_steps(full, n, args.repeats)
        rows.append((label, t_bare * 1e6, t_full * 1e6, t_full / t_bare, m.opt.timestep / t_full))

    print(f"mujoco {mujoco.__version__}; {args.seconds:g} s simulated, best of {args.repeats}")
    print(f"{'setting':<24}{'bare us/step':>14}{'plant us/step':>15}{'ratio':>8}{'plant RTF':>11}")
    for label, b, f, r, rtf in rows:
        print(f"{label:<24}{b:>14.2f}{f:>15.2f}{r:>8.2f}{rtf:>10.0f}x")


if __name__ == "__main__":
    main()
