"""Every refusal of bad input is short (issue 23, item 4): exit 2, at most 3 lines on stderr (the
"Error: ..." line, the help hint, and at most one warning MuJoCo printed while loading), no traceback,
no hang -- over a corpus of bad inputs to every kind of command: logs that are not logs (foreign, empty,
the MCAP magic only, the magic and zeros, another tool's MCAP, a FIFO, /dev/zero, a folder), files given
as a FIFO or a device (scenario parts, sim2real --overrides, trajectory CSVs, robot files), very long
CSV lines (a 200 MB line without a line end, as a sparse file: never read whole), physically meaningless
numbers (2^64 + 1, 1e308, 1e-300 as masses, payloads, quaternions), MJCF problems, scenarios with
several errors (pydantic's list, one line per problem, joined), click's own usage errors (no usage
block) and trial folders with no usable trial.

Run in process through click's test runner (the parser the command line uses); SIGALRM ends a case
that blocks (a FIFO opened for reading), so a regression fails instead of hanging the suite.
"""

from __future__ import annotations

import io
import json
import os
import shutil
import signal
from contextlib import contextmanager
from pathlib import Path

import pytest
from click.testing import CliRunner

from uvms_mj.cli.main import main

ROOT = Path(__file__).resolve().parents[1]
EXCERPT = ROOT / "tests" / "data" / "hinsdale-2023-excerpt"
#: The most lines a refusal may print on stderr: "Error: ..." (one line), the help hint, and one line
#: that MuJoCo itself printed while loading the file (e.g. "XML contains a 'NaN'").
MAX_LINES = 3
#: Seconds a case may take before it counts as a hang (ours: each is refused before any simulation;
#: the slowest compiles the BlueROV2 + Alpha model, well under a second).
CASE_TIMEOUT_S = 30


class _Hang(Exception):
    pass


@contextmanager
def no_hang(seconds: float = CASE_TIMEOUT_S):
    """Raise _Hang if the body runs longer than ``seconds`` (SIGALRM: also ends a blocking open())."""
    def on_alarm(*_):
        raise _Hang(f"no answer within {seconds} s")

    old = signal.signal(signal.SIGALRM, on_alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


def _good_log(d: Path) -> Path:
    from uvms_mj.io.recorder import McapRecorder
    from uvms_mj.plant.plant import Plant

    p = d / "good.mcap"
    with McapRecorder(p, Plant().params, {"scenario": "corpus"}) as rec:
        for k in range(3):
            rec.write_sample(0.1 * k, {"a": float(k)})
    return p


def _foreign_mcap() -> bytes:
    from mcap.writer import Writer

    f = io.BytesIO()
    w = Writer(f)
    w.start()
    cid = w.register_channel("/camera", "json", w.register_schema("s", "jsonschema", b"{}"), {})
    for k in range(3):
        w.add_message(cid, k, json.dumps({"a": k}).encode(), k, k)
    w.finish()
    return f.getvalue()


def _robot_copy(d: Path, old: str, new: str) -> Path:
    """The BlueROV2 + Alpha files copied into ``d`` (relative includes kept), one edit in the robot file."""
    for name in ("bluerov2_alpha", "bluerov2_heavy", "alpha_arm"):
        if not (d / name).exists():
            shutil.copytree(ROOT / "models" / name, d / name)
    text = (ROOT / "models" / "bluerov2_alpha" / "bluerov2_alpha.xml").read_text()
    edited = text.replace(old, new)
    assert edited != text, old
    out = d / "bluerov2_alpha" / f"edit{abs(hash((old, new)))}.xml"
    out.write_text(edited)
    return out


@pytest.fixture(scope="module")
def corpus(tmp_path_factory) -> dict[str, tuple[list, str]]:
    """name -> (arguments, a text the one Error line must hold)."""
    d = tmp_path_factory.mktemp("corpus")
    fifo = d / "fifo"
    os.mkfifo(fifo)
    good = _good_log(d)
    (d / "empty.mcap").write_bytes(b"")
    (d / "magic.mcap").write_bytes(b"\x89MCAP0\r\n")
    with open(d / "zeros.mcap", "wb") as f:  # the magic and 50 MB of zeros (sparse: nothing written)
        f.write(b"\x89MCAP0\r\n")
        f.truncate(8 + 50_000_000)
    (d / "image.mcap").write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(200))
    (d / "scenario.mcap").write_text("robot: bluerov2_alpha\nduration: 1\n")
    (d / "foreign.mcap").write_bytes(_foreign_mcap())
    (d / "folder.mcap").mkdir()
    with open(d / "long.csv", "w") as f:  # a header, then a 200 MB line without a line end (sparse)
        f.write("t,x,y,z\n")
        f.truncate(8 + 200_000_000)
    (d / "bad.csv").write_bytes(b"t,x,y,z\n0,0,0,\xff\n")

    def sc(name: str, text: str) -> Path:
        p = d / f"{name}.yaml"
        p.write_text(text)
        return p

    rob = "robot: bluerov2_alpha\nduration: 0.2\n"
    cases: dict[str, tuple[list, str]] = {}
    for log in ("empty", "magic", "zeros", "image", "scenario", "foreign", "folder"):
        p = d / f"{log}.mcap"
        cases[f"info {log}"] = (["info", p], str(p))
        cases[f"export {log}"] = (["export", p, "-o", d / f"{log}.csv"], str(p))
    for what in (fifo, Path("/dev/zero")):
        cases[f"info {what.name}"] = (["info", what], "not a regular file")
        cases[f"export {what.name}"] = (["export", what, "-o", d / "x.csv"], "not a regular file")
        cases[f"plot {what.name}"] = (["plot", what, "--out-dir", d / "plots"], "not a regular file")
        cases[f"render {what.name}"] = (["render", what, "-o", d / "x.mp4"], "not a regular file")
        cases[f"render --compare B {what.name}"] = (["render", "--compare", good, what, "-o", d / "y.mp4"],
                                                    "not a regular file")
        cases[f"overrides_file {what.name}"] = (
            ["validate", sc(f"ov_{what.name}", rob + f"plant: {{overrides_file: {what}}}\n")], "not a regular file")
        cases[f"trajectory {what.name}"] = (
            ["validate", sc(f"tr_{what.name}", rob + f"trajectory: {{kind: csv, path: {what}}}\n")],
            "not a regular file")
        cases[f"robot {what.name}"] = (["validate", sc(f"rb_{what.name}", f"robot: {what}\n")], "not a regular file")
        cases[f"sim2real --overrides {what.name}"] = (["sim2real", EXCERPT, "--overrides", what], "not a regular file")
    cases["scenario fifo"] = (["validate", fifo], "is not a file")
    for name, csv, needle in (("long line", "long.csv", "line 2: longer than"), ("not utf-8", "bad.csv", "not UTF-8")):
        cases[f"trajectory {name}"] = (
            ["validate", sc(f"tr_{csv}", rob + f"trajectory: {{kind: csv, path: {d / csv}}}\n")], needle)
    big = 2**64 + 1
    for field, value, needle in (
        ("plant.overrides={bluerov2.mass: %s}" % big, None, "bluerov2.mass"),
        ("plant.overrides={bluerov2.mass: 1e308}", None, "|value| must be <="),
        ("plant.overrides={bluerov2.mass: 1e-300}", None, "0 or at least 1e-09"),
        ("plant.overrides={bluerov2.volume: -1e-300}", None, "0 or at least 1e-09"),
        ("plant.payload={mass: 1e308}", None, "plant.payload.mass"),
        ("plant.payload={mass: 1e-300}", None, "plant.payload.mass"),
        ("plant.payload={mass: %s}" % big, None, "plant.payload.mass"),
        ("plant.payload={mass: 0.5, radius: 1e-300}", None, "plant.payload.radius"),
        ("plant.payload={mass: 0.5, volume: 1e-300}", None, "plant.payload.volume"),
        ("plant.payload={mass: 0.5, offset: [1e308, 0, 0]}", None, "plant.payload.offset"),
        ("initial.orientation={quat: [1e308, 0, 0, 1]}", None, "initial.orientation.quat"),
        ("initial.orientation={quat: [%s, 0, 0, 1]}" % big, None, "initial.orientation.quat"),
        ("initial.position=[1e308, 0, 0]", None, "initial.position"),
        ("trajectory={kind: circle, radius: 1e308}", None, "trajectory"),
        ("duration=1e308", None, "duration"),
    ):
        cases[f"--set {field}"] = (["validate", "bluerov2_alpha_station", "--set", field], needle)
    for name, (old, new, needle) in {
        "mass 1e308": ('mass="13.5"', 'mass="1e308"', "mass = 1e+308 kg is outside"),
        "mass -1": ('mass="13.5"', 'mass="-1"', "mass = -1 kg is outside"),
        "inertia nan": ('diaginertia="0.26 0.23 0.37"', 'diaginertia="nan 0.23 0.37"', "diaginertia"),
        "gravity 1e308": ('gravity="0 0 -9.81"', 'gravity="0 0 -1e308"', "<option gravity>"),
        "timestep 0": ('timestep="0.004"', 'timestep="0"', "timestep"),
        "missing include": ("../alpha_arm/alpha_arm_defs.xml", "../alpha_arm/nosuch.xml", "nosuch.xml"),
        "include loop": ("../alpha_arm/alpha_arm_defs.xml", "bluerov2_alpha.xml", "already included"),
        "not xml": ('<mujoco model="bluerov2_alpha">', '<mujoco model="bluerov2_alpha"', "XML"),
        "plugin garbage": ('key="volume" value="0.0134"', 'key="volume" value="0.01 x \x01"', "volume"),
        "plugin unknown key": ('key="cob"', 'key="cobb"', "unknown attribute 'cobb'"),
        "unknown plugin": ('plugin="uvms.hydro"', 'plugin="uvms.nosuch"', "uvms.nosuch"),
        "bad attribute": ('pos="0.2 0 -0.14"', 'pos="0.2 zz"', "attribute 'pos'"),
    }.items():
        cases[f"mjcf {name}"] = (["validate", sc(f"mj_{abs(hash(name))}", f"robot: {_robot_copy(d, old, new)}\n"
                                                 "duration: 0.2\n")], needle)
    cases["several scenario errors"] = (["validate", sc("many", rob + "sensors: {position_noise: -1, delay: x}\n"
                                                       "physics: {timestep: 5}\nnosuch: 1\n")], "nosuch")
    cases["click: unknown option"] = (["validate", "--nosuch"], "No such option")
    cases["click: bad choice"] = (["export", good, "--format", "xls"], "'xls' is not one of")
    cases["click: no such command"] = (["nosuchcommand"], "No such command")
    cases["click: missing argument"] = (["info"], "Missing argument")
    cases["click: bad int"] = (["sim2real", "--jobs", "x"], "'x' is not a valid integer")
    trials = d / "trials"
    trials.mkdir()
    for f in EXCERPT.glob("*.csv"):
        text = f.read_text()
        (trials / f.name).write_text(text[:300] if f.name.endswith("_imu.csv") else text)
    cases["sim2real: no usable trial"] = (["sim2real", trials], "no usable trial")
    return cases


CASE_NAMES = [
    *(f"{c} {k}" for k in ("empty", "magic", "zeros", "image", "scenario", "foreign", "folder")
      for c in ("info", "export")),
    *(f"{c} {w}" for w in ("fifo", "zero") for c in ("info", "export", "plot", "render", "render --compare B",
                                                     "overrides_file", "trajectory", "robot", "sim2real --overrides")),
    "scenario fifo", "trajectory long line", "trajectory not utf-8",
]


@pytest.mark.slow  # about 10 s: some 100 cases, a third of them compile the BlueROV2 + Alpha model
def test_every_refusal_is_exit_2_in_at_most_3_lines(corpus):
    runner = CliRunner()
    failures = []
    for name, (args, needle) in corpus.items():
        with no_hang():
            r = runner.invoke(main, [str(a) for a in args])
        err = r.stderr
        lines = [ln for ln in err.splitlines() if ln.strip()]
        errors = [ln for ln in lines if ln.lower().startswith("error:")]
        ok = (r.exit_code == 2 and (r.exception is None or isinstance(r.exception, SystemExit))
              and "Traceback" not in r.output and len(lines) <= MAX_LINES and len(errors) == 1
              and (needle is None or needle in errors[0]))
        if not ok:
            failures.append(f"{name}: exit {r.exit_code} ({r.exception!r}), {len(lines)} lines:\n{err}")
    assert not failures, "\n".join(failures)
    assert set(CASE_NAMES) <= set(corpus)  # the listed classes are all in the corpus


def test_a_log_cut_by_kill_9_is_still_read_and_called_truncated(tmp_path):
    """Kept: the checks at the open of a log refuse what is not one, never a log of ours cut short."""
    from uvms_mj.io.recorder import log_info, read_log

    good = _good_log(tmp_path).read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(good[: int(len(good) * 0.6)])
    log = read_log(cut)
    assert log.truncated and len(log.t) >= 1  # cut inside its summary: the samples are kept
    assert log_info(cut)["truncated"]
    r = CliRunner().invoke(main, ["info", str(cut)])
    assert r.exit_code == 0 and "TRUNCATED" in r.output
