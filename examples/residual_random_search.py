"""Learn a residual on top of a controller by random search: a tiny linear policy, numpy only.

The environment is ``uvms_mj/TrackingResidual-v0`` (gymnasium): the action, normalised to
[-1, 1], is added to the command of the scenario's controller (``rac_dob`` in the packaged
studies), so the zero policy is the controller itself. The policy is linear in a few named
features of the observation (tip error to the path, base and joint velocities, a bias),

    a = clip(scale * W phi(obs), -1, 1),

and W is improved by basic random search (Mania et al. 2018, "Simple random search provides a
competitive approach to reinforcement learning", method V1-t without the top-b selection): each
iteration draws ``directions`` perturbations dW, runs one episode with W + nu dW and one with
W - nu dW, and moves W along the return differences divided by their spread; the step is kept
only if the return does not drop (a safeguard for the tiny budgets here: a light arm diverges
under a large residual torque). Every episode has the same seed, so the comparison is paired.

    python examples/residual_random_search.py                          # the paper's robot, 20 iterations
    python examples/residual_random_search.py --scenario bluerov2_alpha_circle_current --iterations 5

It prints the zero policy's return (the controller alone) and the learned policy's, per iteration.
A few iterations are not enough to beat ``rac_dob`` by much: this shows the loop, not a result.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np


def features(obs: dict, names: dict) -> np.ndarray:
    """phi(obs): tip error to the path [m] (where the robot has a tip), base and joint velocities, 1."""
    parts = []
    if "tip" in obs:
        parts.append(np.asarray(obs["target"]) - np.asarray(obs["tip"]))
    parts.append(np.asarray(obs["base_velocity"]))
    if "joint_velocities" in obs:
        parts.append(np.asarray(obs["joint_velocities"]))
    parts.append(np.ones(1))
    return np.concatenate(parts)


def episode(env, W: np.ndarray, scale: float, seed: int) -> float:
    """The return of one episode with the linear policy W."""
    obs, _ = env.reset(seed=seed)
    names = env.unwrapped.observation_names
    total, done = 0.0, False
    while not done:
        a = np.clip(scale * (W @ features(obs, names)), -1.0, 1.0)
        obs, r, terminated, truncated, _ = env.step(a)
        total += float(r)
        done = terminated or truncated
    return total


def train(scenario: str, iterations: int, directions: int, episode_s: float, step: float, nu: float,
          scale: float, seed: int, log=print) -> dict:
    """Random search (module docstring); returns the zero policy's and the final policy's returns."""
    import gymnasium

    import uvms_mj  # noqa: F401  (registers the uvms_mj/ ids)

    env = gymnasium.make("uvms_mj/TrackingResidual-v0", scenario=scenario, time_limit=episode_s)
    try:
        obs, _ = env.reset(seed=seed)
        n_act = env.action_space.shape[0]
        W = np.zeros((n_act, features(obs, env.unwrapped.observation_names).size))
        rng = np.random.default_rng(seed)
        base = episode(env, W, scale, seed)
        log(f"{scenario}: {n_act} actions ({', '.join(env.unwrapped.action_names)}), "
            f"{W.shape[1]} features; zero residual (the controller alone): return {base:.4f}")
        best = base
        for it in range(iterations):
            deltas = rng.standard_normal((directions, *W.shape))
            plus = np.array([episode(env, W + nu * d, scale, seed) for d in deltas])
            minus = np.array([episode(env, W - nu * d, scale, seed) for d in deltas])
            sigma = float(np.std(np.r_[plus, minus])) or 1.0  # V1-t: steps in units of the returns' spread
            W_new = W + step / (directions * sigma) * np.tensordot(plus - minus, deltas, axes=1)
            ret = episode(env, W_new, scale, seed)
            kept = ret >= best  # a safeguard for tiny budgets: never keep a worse policy
            if kept:
                W, best = W_new, ret
            log(f"iteration {it + 1}: return {ret:.4f} ({'kept' if kept else 'rejected'}; best {best:.4f})")
        return {"zero": base, "final": best, "W": W}
    finally:
        env.close()


def main(argv: list[str] | None = None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--scenario", default="paper", help="a scenario file or packaged name (default: paper)")
    p.add_argument("--iterations", type=int, default=20)
    p.add_argument("--directions", type=int, default=4, help="perturbations per iteration")
    p.add_argument("--episode-s", type=float, default=4.0, help="episode length [s]")
    p.add_argument("--step", type=float, default=0.01, help="step size of the update")
    p.add_argument("--nu", type=float, default=0.02, help="size of the perturbations")
    p.add_argument("--scale", type=float, default=0.05, help="residual scale (of the normalised action)")
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args(argv)
    return train(a.scenario, a.iterations, a.directions, a.episode_s, a.step, a.nu, a.scale, a.seed)


if __name__ == "__main__":
    main(sys.argv[1:])
