"""The examples under examples/ run (with a tiny budget)."""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def _load(name: str):
    spec = importlib.util.spec_from_file_location(name, EXAMPLES / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.parametrize("scenario", ["paper", "bluerov2_alpha_circle_current"])
def test_residual_random_search_runs(scenario):
    """Two iterations of random search on 0.2 s episodes: the loop runs on both robots, the
    returns are finite, and the kept policy is never worse than the controller alone (the
    example's safeguard: a worse step is rejected; the episodes are seeded alike)."""
    pytest.importorskip("gymnasium")
    pytest.importorskip("shimmy")
    lines: list[str] = []
    out = _load("residual_random_search").train(scenario, iterations=2, directions=1, episode_s=0.2, step=0.01,
                                                nu=0.02, scale=0.05, seed=0, log=lines.append)
    assert math.isfinite(out["zero"]) and math.isfinite(out["final"])
    assert out["final"] >= out["zero"]
    assert len(lines) == 3 and lines[0].startswith(scenario)
