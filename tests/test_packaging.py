"""Packaging: one version, py.typed, licence, packaged scenarios, optional dm-control."""

from __future__ import annotations

import subprocess
import sys
import tomllib
from importlib import metadata
from pathlib import Path

import uvms_mj
from uvms_mj.cli.main import packaged_scenarios, scenarios_dir

ROOT = Path(__file__).resolve().parents[1]


def test_version_in_one_place():
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert "version" in pyproject["project"]["dynamic"] and "version" not in pyproject["project"]
    assert pyproject["tool"]["hatch"]["version"]["path"] == "src/uvms_mj/__init__.py"
    assert metadata.version("uvms-mj") == uvms_mj.__version__


def test_licence_typed_and_scenarios_in_the_wheel():
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert pyproject["project"]["license"] == "Apache-2.0" and pyproject["project"]["license-files"] == ["LICENSE"]
    assert "Apache License" in (ROOT / "LICENSE").read_text() and "Version 2.0" in (ROOT / "LICENSE").read_text()
    assert (ROOT / "src" / "uvms_mj" / "py.typed").is_file()
    wheel = pyproject["tool"]["hatch"]["build"]["targets"]["wheel"]
    assert wheel["force-include"]["scenarios"] == "uvms_mj/scenarios"
    assert wheel["hooks"]["custom"]["path"] == "hatch_build.py"
    assert set(packaged_scenarios()) == {p.stem for p in (ROOT / "scenarios").glob("*.yaml")}
    assert scenarios_dir() == ROOT / "scenarios"  # in a checkout


def test_dm_control_is_optional():
    """Without dm-control, uvms_mj works and uvms_mj.rl.env says what to install."""
    code = ("import sys; sys.modules['dm_control'] = None\n"
            "import uvms_mj; from uvms_mj.scenario.schema import load_scenario\n"
            "try:\n    import uvms_mj.rl.env\nexcept ImportError as exc:\n    print(exc)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert "pip install 'uvms-mj[rl]'" in out.stdout
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert not any(d.startswith("dm-control") for d in pyproject["project"]["dependencies"])
    extras = pyproject["project"]["optional-dependencies"]
    assert "dm-control==1.0.50" in extras["rl"] and "dm-control==1.0.50" in extras["test"]
    assert "mujoco==3.17.0" in pyproject["project"]["dependencies"]
    for pkg in ("gymnasium", "shimmy", "pyarrow", "scipy"):
        assert any(d.startswith(pkg) for d in extras["test"]), pkg


def test_pool_trials_in_the_repository_not_in_the_distributions():
    """data/hinsdale-2023 (17 MB, MIT) is in the git repository for sim2real / identify and the
    tests, and excluded from the sdist and the wheel (anchored, so tests/data stays in the sdist;
    checked with hatchling's builders: 74 files of data/ otherwise in the sdist, none with it)."""
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    targets = pyproject["tool"]["hatch"]["build"]["targets"]
    assert targets["sdist"]["exclude"] == ["/data/"] and targets["wheel"]["exclude"] == ["/data/"]
    data = ROOT / "data" / "hinsdale-2023"
    assert "MIT License" in (data / "LICENSE").read_text()
    assert len(list((data / "trials").glob("*_imu.csv"))) == 18
