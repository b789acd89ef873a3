"""CLI options that were accepted although meaningless (issue 23, item 4): each now exits 2 with
one "Error:" line naming the option -- a controller listed twice, --jobs 0 or below, a sweep seed
beyond 2^63 - 1, identify --score naming a trial that does not exist, a physics step of 1e-9 s
(it tried to allocate 171 GiB), a binary overrides file (a UnicodeDecodeError traceback). Checked through click's
test runner (in process, the same parser the command line uses)."""

from __future__ import annotations

import pytest
from click.testing import CliRunner

from uvms_mj.cli.main import main as cli

CASES = {
    "compare rac twice": (["compare", "paper", "--controllers", "rac,rac", "--no-video"], "given twice"),
    "paper rac twice": (["paper", "--controllers", "rac,rac"], "given twice"),
    "sweep seed 2^64": (["sweep", "paper", "--vary", "plant.current[0]=[0, 0.01]", "--seed", str(2**64)], "--seed"),
    "sim2real jobs 0": (["sim2real", "--jobs", "0"], "--jobs"),
    "identify jobs -3": (["identify", "--jobs", "-3"], "--jobs"),
    "sim2real dt 1e-9": (["sim2real", "--dt", "1e-9"], "--dt must lie in [1e-05, 0.05] s"),
    "identify fit-dt 1e-9": (["identify", "--fit-dt", "1e-9", "-o", "{tmp}/o.yaml"], "--fit-dt must lie in"),
    "sim2real binary overrides": (["sim2real", "--overrides", "{tmp}/bin.yaml"], "not a UTF-8 text file"),
    "identify score nosuch": (["identify", "--fit", "baseline1", "--score", "nosuch", "-o", "{tmp}/o.yaml"],
                              "--score: trial(s) nosuch not usable"),
}


@pytest.mark.parametrize("case", list(CASES))
def test_refused_with_exit_2(tmp_path, case):
    args, expected = CASES[case]
    args = [a.replace("{tmp}", str(tmp_path)) for a in args]
    (tmp_path / "bin.yaml").write_bytes(bytes(range(128, 256)) * 8)  # not UTF-8
    r = CliRunner().invoke(cli, args)
    assert r.exit_code == 2, r.output
    assert expected in r.output, r.output
    assert not (tmp_path / "o.yaml").exists()
