"""MuJoCo's warnings never land in ./MUJOCO_LOG.TXT (issue 23: a model load that warned left one
in the working directory, although the README says it does not). Independent check: in a fresh
process whose working directory is empty, load a robot with uvms_mj only (no Plant), make MuJoCo
warn (a NaN velocity: "Nan, Inf or huge value in QACC"), and look at the folder and stderr."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_a_warning_after_a_plain_model_load_goes_to_stderr_not_to_a_file(tmp_path):
    code = textwrap.dedent(f"""\
        import mujoco
        from uvms_mj.physics.model import load_model
        m = load_model({str(ROOT / "models" / "bluerov2_heavy" / "bluerov2_heavy.xml")!r})
        d = mujoco.MjData(m)
        d.qvel[0] = float("nan")
        mujoco.mj_step(m, d)
        from uvms_mj.physics.mjwarnings import mujoco_warnings
        print(len(mujoco_warnings()))
        """)
    r = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()
    assert "mujoco warning:" in r.stderr and int(r.stdout.split()[-1]) >= 1
