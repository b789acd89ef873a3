"""The scenario files shipped with the package, and scenario names resolved as the command line does.

A SCENARIO argument (``uvms-mj run SCENARIO``, ``uvms_mj.rl.env.load(scenario=...)``,
``gymnasium.make("uvms_mj/Tracking-v0", scenario=...)``) is a file, or, when no such file exists and
the value is a bare name, the packaged scenario of that name (``paper`` -> ``scenarios/paper.yaml``).
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["packaged_scenarios", "resolve_scenario", "scenarios_dir"]


def scenarios_dir() -> Path:
    """The scenario files shipped with the package (the repository's ``scenarios/`` in a checkout)."""
    pkg = Path(__file__).resolve().parents[1]  # the uvms_mj package folder
    for cand in (pkg.parents[1] / "scenarios", pkg / "scenarios"):
        if cand.is_dir() and any(cand.glob("*.yaml")):
            return cand
    return pkg / "scenarios"


def packaged_scenarios() -> list[str]:
    """Names of the packaged scenarios (``uvms-mj run NAME``)."""
    return sorted(p.stem for p in scenarios_dir().glob("*.yaml"))


def resolve_scenario(value: str | Path) -> Path:
    """The scenario file ``value`` names: the file itself, else the packaged scenario of that name.

    Raises:
        ScenarioError: not a file (a folder), or neither a file nor a packaged scenario's name (the
            message lists the packaged ones).
    """
    from uvms_mj.scenario.base import ScenarioError

    p = Path(value)
    if p.is_file():
        return p
    if p.exists():
        raise ScenarioError(f"{str(value)!r} is not a file")
    name = str(value)
    if p.name == name:  # a bare name: a packaged scenario
        cand = scenarios_dir() / (name if name.endswith((".yaml", ".yml")) else f"{name}.yaml")
        if cand.is_file():
            return cand
    raise ScenarioError(f"{name!r}: no such file, nor a packaged scenario ({', '.join(packaged_scenarios())})")
