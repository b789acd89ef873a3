"""The fuzz test of tests/test_bad_input.py extended beyond the planar schema (issue 23, item 4): seeded
random mutations of the robot scenarios (scenarios/bluerov2_alpha_*.yaml), of the BlueROV2 + Alpha MJCF
(models/bluerov2_alpha and the fragments it includes) and of pool-trial folders (tests/data's Hinsdale
excerpt). Asserted for every case: no traceback, no hang (SIGALRM), an exit code of 0 or 2 (2 for input
that is certainly invalid: wrong types, NaN, 1e308, 2^64 + 1, unknown keys), a refusal in one "Error:"
line (at most 3 lines on stderr, see tests/test_error_lines.py); a scenario that validates runs (a short
run) to a status, never exit 1; a mutated trial is read or skipped with its problems named, never an
exception.

Each test draws a fixed number of cases from ``random.Random(seed)``: the same cases every run.
"""

from __future__ import annotations

import copy
import random
import re
import shutil
from pathlib import Path

import pytest
import yaml
from click.testing import CliRunner

from uvms_mj.cli.main import main

from test_error_lines import MAX_LINES, no_hang

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = sorted((ROOT / "scenarios").glob("bluerov2_alpha_*.yaml"))
EXCERPT = ROOT / "tests" / "data" / "hinsdale-2023-excerpt"

#: Values no numeric field of a scenario accepts.
ALWAYS_BAD = [float("nan"), 1e308, -1e308, 2**64 + 1, "abc", [1, [2]], {"value": 1}, True]
#: Values some fields accept (0 only for valid input: then a short run must end with a status).
MAYBE = [0, -1, 1e-300, -1e-300, 1e-9, 1e6, 0.5]


def _numeric_leaves(node, path=()):
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _numeric_leaves(v, path + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _numeric_leaves(v, path + (i,))
    elif isinstance(node, (int, float)) and not isinstance(node, bool):
        yield path


def _mappings(node, path=()):
    if isinstance(node, dict):
        yield path
        for k, v in node.items():
            yield from _mappings(v, path + (k,))


def _get(node, path):
    for p in path:
        node = node[p]
    return node


def _invoke(*args):
    with no_hang():
        return CliRunner().invoke(main, [str(a) for a in args])


def _check(r, expect: tuple, what: str) -> None:
    assert r.exception is None or isinstance(r.exception, SystemExit), f"{what}: {r.exception!r}\n{r.output}"
    assert "Traceback" not in r.output, f"{what}:\n{r.output}"
    assert r.exit_code in expect, f"{what}: exit {r.exit_code}\n{r.output}"
    if r.exit_code == 2:
        lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
        assert len(lines) <= MAX_LINES and sum(ln.startswith("Error:") for ln in lines) == 1, f"{what}:\n{r.stderr}"


def _station_pid(f: Path) -> bool:
    return "name: station_pid" in f.read_text()


#: The robot scenarios whose validation is fast (station_pid: ~0.06 s) and the others (rac, rac_dob: their
#: gains are checked against the nominal model, ~0.8 s a validation).
FAST = [f for f in SCENARIOS if _station_pid(f)]
SLOW = [f for f in SCENARIOS if not _station_pid(f)]


def test_fuzz_robot_scenarios(tmp_path):
    """40 mutations of the station_pid scenarios (about 4 s)."""
    _fuzz_scenarios(tmp_path, FAST, cases=40, seed=23)


@pytest.mark.slow  # about 12 s: each validation of a rac/rac_dob scenario checks its gains on the nominal model
def test_fuzz_robot_scenarios_rac(tmp_path):
    """12 mutations of the rac/rac_dob scenarios."""
    _fuzz_scenarios(tmp_path, SLOW, cases=12, seed=24)


def _fuzz_scenarios(tmp_path: Path, scenarios: list, cases: int, seed: int) -> None:
    rng = random.Random(seed)
    runs = 0
    for k in range(cases):
        src = rng.choice(scenarios)
        raw = yaml.safe_load(src.read_text())
        raw["duration"] = 0.2
        kind = rng.choice(["bad", "bad", "maybe", "unknown key"])
        if kind == "unknown key":
            where = rng.choice(list(_mappings(raw)))
            _get(raw, where)["nosuch_key_fuzz"] = rng.choice([1, "x", None])
            what = f"{src.name}: unknown key under {'.'.join(map(str, where)) or '(top)'}"
        else:
            path = rng.choice([p for p in _numeric_leaves(raw) if p != ("duration",)])
            value = rng.choice(ALWAYS_BAD if kind == "bad" else MAYBE)
            _get(raw, path[:-1])[path[-1]] = copy.deepcopy(value)
            what = f"{src.name}: {'.'.join(map(str, path))} = {value!r}"
        f = tmp_path / f"case{k}.yaml"
        f.write_text(yaml.safe_dump(raw))
        r = _invoke("validate", f)
        _check(r, (2,) if kind != "maybe" else (0, 2), what)
        if r.exit_code == 0 and runs < 3:  # valid: a short run ends with a status (ok, diverged, joint limit)
            runs += 1
            rr = _invoke("run", f, "--out", tmp_path / f"run{k}.mcap", "--no-plots", "--no-video")
            _check(rr, (0, 3, 6), f"run of {what}")


def _copy_models(dest: Path) -> Path:
    for name in ("bluerov2_alpha", "bluerov2_heavy", "alpha_arm"):
        shutil.copytree(ROOT / "models" / name, dest / name)
    return dest / "bluerov2_alpha" / "bluerov2_alpha.xml"


_ATTR = re.compile(r'(\s)([a-z_]+)="([^"]*)"')
_ELEMENT = re.compile(r"<(?!/|!|\?|mujoco\b)[a-z_]+\b[^<>]*/>")
GARBAGE = ["abc", "1e308", "-1e308", "nan", "", "1 2", "-1", "0", "1e-300", "1e999", "&amp;x", "1,2,3"]


def test_fuzz_mjcf_files(tmp_path):
    rng = random.Random(4)
    robot = _copy_models(tmp_path)
    files = [robot, *(tmp_path / "bluerov2_heavy").glob("bluerov2_heavy_*.xml"),
             *(tmp_path / "alpha_arm").glob("alpha_arm_*.xml")]
    originals = {f: f.read_text() for f in files}
    runs = 0
    for k in range(40):
        target = rng.choice(files)
        text = originals[target]
        op = rng.choice(["attribute", "attribute", "plugin", "remove"])
        if op == "remove":
            m = rng.choice(list(_ELEMENT.finditer(text)))
            edited, what = text[:m.start()] + text[m.end():], f"removed {m.group(0)[:60]}"
        else:
            if op == "plugin":
                cands = [m for m in re.finditer(r'(key="[a-z_]+" value=")([^"]*)"', text)]
            else:
                cands = [m for m in _ATTR.finditer(text) if m.group(2) not in ("name", "file", "class", "childclass")]
            if not cands:
                continue
            m = rng.choice(cands)
            value = rng.choice(GARBAGE)
            if op == "plugin":
                edited = text[:m.start(2)] + value + text[m.end(2):]
            else:
                edited = text[:m.start(3)] + value + text[m.end(3):]
            what = f"{target.name}: {m.group(0)[:50]!r} -> {value!r}"
        # a new file name each time: the compiled robot models are cached by path
        for f in files:
            f.write_text(originals[f])
        target.write_text(edited)
        case = robot.with_name(f"case{k}.xml")
        case.write_text(robot.read_text())
        sc = tmp_path / f"case{k}.yaml"
        sc.write_text(f"robot: {case}\nduration: 0.1\n")
        r = _invoke("validate", sc)
        _check(r, (0, 2), what)
        if r.exit_code == 0 and runs < 3:
            runs += 1
            rr = _invoke("run", sc, "--out", tmp_path / f"run{k}.mcap", "--no-plots", "--no-video")
            _check(rr, (0, 2, 3, 6), f"run of {what}")
    for f in files:
        f.write_text(originals[f])


def _mutate_trial(rng: random.Random, folder: Path) -> str:
    files = sorted(folder.glob("traj015-0_*.csv")) + [folder / "metadata_015-0.yml"]
    f = rng.choice([f for f in files if f.exists()] or files)
    if not f.exists():
        return f"{f.name}: already deleted"
    data = f.read_bytes()
    op = rng.choice(["truncate", "swap columns", "junk", "nan", "huge", "delete", "empty", "long line"])
    text = data.decode("utf-8", "replace")
    if op in ("swap columns", "nan", "huge") and (f.suffix != ".csv" or "," not in text.partition("\n")[0]):
        op = "truncate"  # needs a CSV header with two columns or more
    if op == "truncate" and not data:
        op = "delete"
    if op == "truncate":
        f.write_bytes(data[: rng.randrange(len(data))])
    elif op == "swap columns":
        lines = text.splitlines()
        head = lines[0].split(",")
        i, j = rng.sample(range(len(head)), 2)
        head[i], head[j] = head[j], head[i]
        f.write_text("\n".join([",".join(head), *lines[1:]]) + "\n")
    elif op == "junk":
        at = rng.randrange(len(data))
        f.write_bytes(data[:at] + bytes(rng.randrange(256) for _ in range(64)) + data[at:])
    elif op in ("nan", "huge"):
        lines = text.splitlines()
        n = rng.randrange(1, len(lines)) if len(lines) > 1 else 0
        parts = lines[n].split(",")
        parts[rng.randrange(len(parts))] = "nan" if op == "nan" else "1e308"
        lines[n] = ",".join(parts)
        f.write_text("\n".join(lines) + "\n")
    elif op == "delete":
        f.unlink()
    elif op == "empty":
        f.write_bytes(b"")
    else:
        f.write_bytes(data[:200] + b"1" * 50_000 + data[200:])
    return f"{f.name}: {op}"


@pytest.mark.skipif(not EXCERPT.is_dir(), reason="tests/data/hinsdale-2023-excerpt absent")
def test_fuzz_trial_folders(tmp_path):
    import numpy as np

    from uvms_mj.analysis.trials import load_trials

    rng = random.Random(5)
    offsets = np.array([3.07, 0.0, 0.0, 2.879])  # the hinsdale2023 model's numeric (tests/test_trial_input.py)
    for k in range(25):
        d = tmp_path / f"t{k}"
        d.mkdir()
        for f in EXCERPT.glob("*015-0*"):
            shutil.copy(f, d / f.name)
        whats = [_mutate_trial(rng, d) for _ in range(rng.choice([1, 1, 2]))]
        with no_hang():
            ts = load_trials(d, offsets=offsets, names=["015-0"])
        assert ("015-0" in ts.trials) != ("015-0" in ts.skipped), whats
        for issue in ts.issues:
            assert "\n" not in str(issue), (whats, str(issue))
        if "015-0" in ts.skipped:  # skipped: at least one error, naming its file
            errors = [i for i in ts.skipped["015-0"] if i.severity == "error"]
            assert errors and all(i.file is not None or "no" in i.message for i in errors), (whats, errors)
