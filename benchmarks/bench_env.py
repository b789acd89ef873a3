"""Speed of the learning environments: dm_control steps per CPU second, plain and residual.

    python benchmarks/bench_env.py [--scenario NAME ...] [--seconds 10] [--repeats 3]

For each scenario (default: paper and bluerov2_alpha_circle_current), a ``time_limit`` episode
with the zero action, plain (the action is the command) and residual (on the scenario's
controller), the best of ``repeats`` by the process's CPU time (which a busy machine's preemptions
do not inflate).
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--scenario", nargs="+", default=["paper", "bluerov2_alpha_circle_current"])
    p.add_argument("--seconds", type=float, default=10.0)
    p.add_argument("--repeats", type=int, default=3)
    a = p.parse_args()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # dm_control's GLFW probe without a display
        from uvms_mj.rl import env as uvms_env
    for name in a.scenario:
        for residual in (False, True):
            env = uvms_env.load(residual=residual, scenario=name, time_limit=a.seconds, random=0)
            zero = np.zeros(env.action_spec().shape)
            best, n = 0.0, 0
            for _ in range(a.repeats):
                ts, n, t0 = env.reset(), 0, time.process_time()
                while not ts.last():
                    ts = env.step(zero)
                    n += 1
                best = max(best, n / max(time.process_time() - t0, 1e-9))
            print(f"{name:32s} {'residual' if residual else 'plain':8s} {n:6d} steps/episode  "
                  f"{best:8.0f} steps per CPU second")


if __name__ == "__main__":
    main()
