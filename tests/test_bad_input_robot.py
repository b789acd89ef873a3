"""Bad input on MJCF robots (issue 23, item 4: cases that ended in a traceback, a hang or a
meaningless run): each gives exit 2 from `uvms-mj validate` and one line naming the field and
the value -- no traceback."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from uvms_mj.scenario.base import ScenarioError
from uvms_mj.scenario.schema import load_scenario

ROOT = Path(__file__).resolve().parents[1]
HEAVY = ROOT / "models" / "bluerov2_heavy" / "bluerov2_heavy.xml"


def _model_with_timestep(tmp_path: Path, value: str) -> Path:
    """A copy of the BlueROV2 Heavy's robot file (and its fragments) with <option timestep=value>."""
    text = HEAVY.read_text()
    import re

    text = re.sub(r'timestep="[^"]*"', f'timestep="{value}"', text, count=1)
    for frag in HEAVY.parent.glob("bluerov2_heavy_*.xml"):
        (tmp_path / frag.name).write_text(frag.read_text())
    out = tmp_path / "heavy_t.xml"
    out.write_text(text)
    return out


def _edited_heavy(tmp_path: Path, file: str, old: str, new: str, regex: bool = False) -> Path:
    """A copy of the BlueROV2 Heavy's files with one edit in ``file``."""
    import re

    for f in HEAVY.parent.glob("bluerov2_heavy*.xml"):
        text = f.read_text()
        if f.name == file:
            edited = re.sub(old, new, text, flags=re.S) if regex else text.replace(old, new)
            assert edited != text, "the edit matched nothing"
            text = edited
        (tmp_path / f.name).write_text(text)
    return tmp_path / "bluerov2_heavy.xml"


CASES = {
    "empty thrust curve": (lambda t: "robot: " + str(_edited_heavy(
        t, "bluerov2_heavy_defs.xml", 'value="poly 0 8.9 0 176.0 0 -404.1 0 389.9 0 -140.3"', 'value=""')) + "\n",
        "attribute 'curve' = ''"),
    "short keyframe": (lambda t: "robot: " + str(_edited_heavy(
        t, "bluerov2_heavy.xml", "</worldbody>", '</worldbody>\n  <keyframe><key name="k" qpos="0 0 0"/></keyframe>'))
        + "\n", "keyframe 'k': qpos has 3 values; the model needs 7"),
    "hydro on the world body": (lambda t: "robot: " + str(_edited_heavy(
        t, "bluerov2_heavy.xml", "<worldbody>",
        '<worldbody>\n    <plugin plugin="uvms.hydro"><config key="volume" value="0.01"/></plugin>')) + "\n",
        "uvms.hydro on the world body"),
    "no thrusters": (lambda t: "robot: " + str(_edited_heavy(
        t, "bluerov2_heavy_defs.xml", r"<actuator>.*?</actuator>", "", regex=True)) + "\n",
        "drives no actuator"),
    "timestep 0": (lambda t: f"robot: {_model_with_timestep(t, '0')}\n", "<option timestep> = 0 s is outside"),
    "timestep 1e-9": (lambda t: f"robot: {_model_with_timestep(t, '1e-9')}\n", "<option timestep> = 1e-09 s is outside"),
    "no such user": (lambda t: "robot: '~nosuchuser_uvms/x.xml'\n", "robot: "),
    "mapping for a number": (lambda t: "robot: bluerov2_heavy\nplant: {overrides: {bluerov2.mass: {value: 13}}}\n",
                             "bluerov2.mass = {'value': 13}: expected body mass"),
    "overrides file /dev/zero": (lambda t: "robot: bluerov2_heavy\nplant: {overrides_file: /dev/zero}\n",
                                 "/dev/zero: not a regular file"),
    "overrides file a folder": (lambda t: f"robot: bluerov2_heavy\nplant: {{overrides_file: {t}}}\n", "is a folder"),
    "mass 1e308": (lambda t: "robot: bluerov2_heavy\nplant: {overrides: {bluerov2.mass: 1e308}}\n",
                   "|value| must be <= 1e+09"),
    "added mass 1e308": (lambda t: "robot: bluerov2_heavy\nplant: {overrides: {bluerov2_hull.added_mass: "
                         "[1e308, 1, 1, 1, 1, 1]}}\n", "|value| must be <= 1e+09"),
    "payload site ''": (lambda t: "robot: bluerov2_heavy\nplant: {payload: {mass: 0.5, site: ''}}\n",
                        "plant.payload.site"),
}


@pytest.mark.parametrize("case", list(CASES))
def test_the_scenario_is_refused_in_one_line(tmp_path, case):
    """In process: a ScenarioError (what the CLI prints as its one "Error:" line, exit 2) naming
    the problem, no other exception."""
    make, expected = CASES[case]
    f = tmp_path / "s.yaml"
    f.write_text(make(tmp_path) + "duration: 0.1\n")
    with pytest.raises(ScenarioError) as exc:
        load_scenario(f)
    msg = str(exc.value)
    assert expected in msg and "\n" not in msg.strip(), msg


def test_validate_exits_2_with_one_line(tmp_path):
    """The CLI's contract on one of the cases: exit 2, one "Error:" line, no traceback."""
    make, expected = CASES["overrides file /dev/zero"]
    f = tmp_path / "s.yaml"
    f.write_text(make(tmp_path) + "duration: 0.1\n")
    r = subprocess.run([sys.executable, "-m", "uvms_mj.cli.main", "validate", str(f)], capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 2, (r.stdout, r.stderr)
    assert "Traceback" not in r.stderr and expected in r.stderr, r.stderr
    assert len([ln for ln in r.stderr.splitlines() if ln.startswith("Error:")]) == 1
