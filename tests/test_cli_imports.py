"""A quick CLI (issue 22 item 7), structurally: the command line's module imports none of the heavy optional
packages, and ``validate`` and a short ``run --no-plots`` of the paper scenario import no plotting, data-frame,
video or learning package (checked in ``sys.modules`` of a fresh subprocess; wall times are measured by
benchmarks/bench_cli.py, never asserted)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

PAPER = str(Path(__file__).resolve().parents[1] / "scenarios" / "paper.yaml")
HEAVY = ("matplotlib", "pandas", "scipy", "imageio", "dm_control", "gymnasium", "ray", "pinocchio", "PIL")

_PROBE = """
import json, sys
from click.testing import CliRunner
import uvms_mj.cli.main as cli_main
after_import = sorted(m for m in {heavy} if m in sys.modules)
args = {args}
code = CliRunner().invoke(cli_main.main, args).exit_code if args else 0
print(json.dumps([code, after_import, sorted(m for m in {heavy} if m in sys.modules)]))
"""


def _probe(args: list[str]) -> tuple[int, list[str], list[str]]:
    out = subprocess.run([sys.executable, "-c", _PROBE.format(heavy=HEAVY, args=args)], check=True,
                         capture_output=True, text=True).stdout
    code, at_import, after = json.loads(out.strip().splitlines()[-1])
    return code, at_import, after


def test_cli_module_imports_no_heavy_package() -> None:
    assert _probe([])[1] == []


@pytest.mark.slow  # two CLI processes: ~6 s on a busy 2-core machine
def test_validate_and_short_run_import_no_plotting_or_learning(tmp_path) -> None:
    # scipy may come in through the RAC's js = "auto" (the manipulability search: scipy's Nelder-Mead)
    not_wanted = set(HEAVY) - {"scipy"}
    code, _, after = _probe(["validate", PAPER])
    assert code == 0 and not_wanted.isdisjoint(after), after
    code, _, after = _probe(["run", PAPER, "--set", "duration=0.2", "--no-plots", "--no-video",
                             "-o", str(tmp_path / "r.mcap")])
    assert code == 0 and not_wanted.isdisjoint(after), after


def test_manipulability_disk_cache_gives_the_searchs_numbers(tmp_path, monkeypatch) -> None:
    """The disk cache that spares ``validate`` scipy's import: a hit returns the search's very numbers
    (floats written as round-trip reprs), without searching."""
    import numpy as np

    from uvms_mj.control import manipulability as mm
    from uvms_mj.plant.plant import Plant

    monkeypatch.setenv("UVMS_MJ_CACHE", str(tmp_path))
    monkeypatch.setenv(mm.ENV_DISK_CACHE, "on")
    monkeypatch.setattr(mm, "_CACHE", {})
    m = Plant().model
    tip = m.site("tip").id
    dofs = [int(m.jnt_dofadr[m.joint(n).id]) for n in ("joint1", "joint2")]
    first = mm.max_manipulability(m, tip, dofs, [0, 1])
    assert len(list((tmp_path / "manipulability").glob("*.json"))) == 1
    np.testing.assert_allclose(first.value, 0.25 * 0.25, rtol=1e-12)  # l1 l2 (module docstring), Table 1
    monkeypatch.setattr(mm, "_CACHE", {})
    monkeypatch.setattr(mm, "_search", lambda *a: (_ for _ in ()).throw(AssertionError("searched")))
    again = mm.max_manipulability(m, tip, dofs, [0, 1])
    assert again.value == first.value and np.array_equal(again.q_arm, first.q_arm)
