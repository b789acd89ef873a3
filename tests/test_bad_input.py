"""Bad input and bad output paths end in a clear error (exit 2, or 5 for I/O failures), never a
traceback or a hang, and never destroy a user's file.

A generated fuzz corpus over every numeric scenario field and the classes found by the
issue's corpus (extreme numbers, booleans, explicit YAML tags, long integers, alias bombs,
deep nesting, endless input), run in-process through the CLI; a few subprocess cases (Ctrl-C,
kill -9 of a sweep, /dev/zero).
"""

from __future__ import annotations

import copy
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from uvms_mj.cli.main import EXIT_INTERRUPTED, EXIT_IO, main
from uvms_mj.control.base import Command, Controller
from uvms_mj.sim.loop import COMMAND_ABS_MAX, SensorModel, run_closed_loop
from uvms_mj.plant.plant import Plant
from uvms_mj.scenario.schema import load_scenario, scenario_warnings

#: Every numeric field of a scenario (dotted path, list index as an int).
NUMERIC_FIELDS = [
    ("duration",), ("seed",), ("physics", "timestep"), ("thrusters", "tau"),
    ("thrusters", "force_range", 0), ("thrusters", "force_range", 1),
    ("thrusters", "dead_zone_band", 0), ("thrusters", "dead_zone_band", 1),
    ("plant", "current", 0), ("plant", "current", 1),
    ("sensors", "position_noise"), ("sensors", "angle_noise"), ("sensors", "attitude_noise"),
    ("sensors", "joint_noise"), ("sensors", "position_quantum"), ("sensors", "angle_quantum"),
    ("sensors", "delay"), ("sensors", "velocity_noise"),
    ("controller", "params", "T"), ("controller", "params", "gamma"), ("controller", "params", "lam"),
    ("controller", "params", "js"), ("controller", "params", "js_high"), ("controller", "params", "tf"),
    ("controller", "params", "n_ramp"), ("controller", "params", "dls_threshold"),
    ("controller", "params", "dls_damping"),
    ("trajectory", "cruise_speed"), ("trajectory", "accel"), ("trajectory", "t_start"),
    ("trajectory", "displacement", 0), ("trajectory", "displacement", 1),
    ("outputs", "video_fps"), ("outputs", "video_size", 0), ("outputs", "video_size", 1),
    ("plant", "overrides", "base.volume"), ("plant", "overrides", "link1.mass"),
    ("nominal", "overrides", "base.mass"), ("nominal", "overrides", "thrusters.tau"),
]
#: Values no numeric field accepts (the schema's bounds, booleans, strings, containers).
ALWAYS_BAD = [1e308, -1e308, 2**64 + 1, -(2**64 + 1), True, "abc", [], {}]
#: Values some fields accept: never a traceback either way.
EDGE = [5e-324, -5e-324, 0, -1, 1e-12, 7]

BASE = {"duration": 0.3, "physics": {}, "thrusters": {"force_range": [-8.849, 15.978],
                                                        "dead_zone_band": [-0.07772, 0.26944]},
        "plant": {"current": [0.0, 0.0], "overrides": {}}, "nominal": {"overrides": {}}, "sensors": {},
        "controller": {"params": {}}, "trajectory": {"displacement": [0.3, 0.0]},
        "outputs": {"video_size": [640, 480], "plots": False}}


def _with(path: tuple, value) -> dict:
    raw = copy.deepcopy(BASE)
    node = raw
    for part in path[:-1]:
        node = node[part]
    node[path[-1]] = value
    return raw


def _write(tmp_path: Path, raw, name: str = "case") -> Path:
    p = tmp_path / f"{name}.yaml"
    p.write_text(raw if isinstance(raw, str) else yaml.safe_dump(raw), encoding="utf-8")
    return p


def _no_traceback(result) -> None:
    """The command ended by itself (SystemExit or normally), not by an exception."""
    assert result.exception is None or isinstance(result.exception, SystemExit), (
        f"traceback: {result.exception!r}\n{result.output}")
    assert "Traceback" not in result.output


def _usage_error(result, *needles: str) -> None:
    _no_traceback(result)
    assert result.exit_code == 2, result.output
    for n in needles:
        assert n in result.output, result.output


@pytest.fixture
def cli(monkeypatch, tmp_path):
    monkeypatch.chdir(tmp_path)
    runner = CliRunner()
    return lambda *args: runner.invoke(main, [str(a) for a in args])


# --------------------------------------------------------------------------- scenario fuzz


@pytest.mark.parametrize("path", NUMERIC_FIELDS, ids=lambda p: ".".join(map(str, p)))
def test_fuzz_every_numeric_field(path, cli, tmp_path):
    for value in ALWAYS_BAD:
        f = _write(tmp_path, _with(path, value))
        res = cli("validate", f)
        where = ".".join(str(p) for p in path[:-1] if not isinstance(p, int))
        _usage_error(res, str(f), where)
        assert not any(tmp_path.glob("**/*.mcap"))
    for value in EDGE:
        res = cli("validate", _write(tmp_path, _with(path, value)))
        _no_traceback(res)
        assert res.exit_code in (0, 2), res.output
    # run refuses the same before writing anything (cwd is tmp_path: the default log would be there)
    value = ALWAYS_BAD[NUMERIC_FIELDS.index(path) % len(ALWAYS_BAD)]
    f = _write(tmp_path, _with(path, value))
    _usage_error(cli("run", f, "--set", "description=fuzz", "--plots"), str(f))
    assert not any(tmp_path.glob("**/*.mcap")) and not any(tmp_path.glob("**/*.png"))


def test_fuzz_runs_of_valid_edge_values(cli, tmp_path):
    """Valid but extreme values run to a status (ok or diverged) with a readable log."""
    import random

    rng = random.Random(8)
    cases = [(p, v) for p in NUMERIC_FIELDS for v in EDGE + [1e-9, 0.99]]
    rng.shuffle(cases)
    ran = 0
    for path, value in cases:
        f = _write(tmp_path, _with(path, value))
        if cli("validate", f).exit_code != 0:
            continue
        out = tmp_path / f"run{ran}.mcap"
        res = cli("run", f, "--set", "duration=0.3", "--out", out, "--no-plots")
        _no_traceback(res)
        assert res.exit_code in (0, 3), (path, value, res.output)
        assert cli("info", out).exit_code == 0
        ran += 1
        if ran == 6:
            break
    assert ran == 6


def test_bounds_are_named_in_the_error(cli, tmp_path):
    res = cli("validate", _write(tmp_path, {"duration": 18446744073709551617}))
    _usage_error(res, "duration", "less than or equal to 3600", "18446744073709551617")
    res = cli("validate", _write(tmp_path, {"controller": {"params": {"T": True}}}))
    _usage_error(res, "controller.params.T", "not a boolean")
    res = cli("validate", _write(tmp_path, {"outputs": {"video_size": [641, 480]}}))
    _usage_error(res, "outputs.video_size[0]", "even", "641")
    res = cli("validate", _write(tmp_path, {"outputs": {"video_size": [100000, 100000]}}))
    _usage_error(res, "outputs.video_size[1]", "2160")
    res = cli("validate", _write(tmp_path, {"outputs": {"video_fps": 1000}}))
    _usage_error(res, "outputs.video_fps", "120")
    res = cli("validate", _write(tmp_path, {"name": "a" * 300}))
    _usage_error(res, "name", "at most 100 characters")


def test_thruster_lag_checked_against_the_timestep(cli, tmp_path):
    res = cli("validate", _write(tmp_path, {"thrusters": {"tau": 0.001}}))
    _usage_error(res, "thrusters.tau", "rk4", "0.00299")
    res = cli("validate", _write(tmp_path, {"thrusters": {"tau": 0.004}, "physics": {"integrator": "euler"}}))
    _usage_error(res, "thrusters.tau", "euler", "0.00416")
    # Just inside the bound it is accepted (and stable).
    assert cli("validate", _write(tmp_path, {"thrusters": {"tau": 0.0031}})).exit_code == 0


@pytest.mark.parametrize("text, needle", [
    ("duration: !!float 'abc'\n", "line 1"),
    ("seed: !!int 'x'\n", "bad int value"),
    ("seed: " + "9" * 5000 + "\n", "4300 digits"),
    ("seed: !!binary 'AAAA'\n", "seed"),
    ("a: &a [lol, lol, lol]\nb: &b [*a, *a, *a]\nc: [*b, *b, *b]\n", "aliases"),
    ("description: &x lol\nname: *x\n", "aliases"),
    ("&a [*a]\n", "aliases"),
    ("description: " + "[" * 100_000 + "]" * 100_000 + "\n", "nesting deeper than 32"),
    ("x: " + "{a: " * 2000 + "1" + "}" * 2000 + "\n", "nesting deeper than 32"),
    ("- " * 500 + "x\n", "nesting deeper than 32"),
    ("duration: 1\n" + "#" * (1 << 20) + "\n", "larger than 1024 KiB"),
    ("duration: \0\n", "NUL"),
    ("\xff\xfe", "cannot read"),
])
def test_yaml_classes(text, needle, cli, tmp_path):
    f = tmp_path / "case.yaml"
    f.write_bytes(text.encode("utf-8", "surrogateescape") if text != "\xff\xfe" else b"\xff\xfe\x00")
    # (no wall-clock bound: the message names the refusal -- aliases, nesting, size -- so the
    # input was refused before it was expanded or recursed into, which is what a bound would guard)
    for cmd in (("validate", f), ("run", f, "--set", "duration=0.3", "--no-plots")):
        res = cli(*cmd)
        _usage_error(res, str(f), needle)
    assert not any(tmp_path.glob("**/*.mcap"))


def test_billion_laughs_is_refused_unexpanded(cli, tmp_path):
    """10^9 "lol"s through 9 levels of aliases: refused for its aliases (by the reader, before any
    expansion; an expansion would not finish, so no wall-clock bound is needed to see it)."""
    lines = ['a0: &a0 "lol"'] + [f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 10) + "]" for i in range(1, 10)]
    f = _write(tmp_path, "\n".join(lines) + "\ndescription: *a9\n")
    _usage_error(cli("validate", f), "aliases")


def test_endless_input_is_refused():
    """/dev/zero is refused after the first 1 MiB (it does not hang: the timeout is only a hang
    guard, not a speed claim; a direct call answers in milliseconds)."""
    r = subprocess.run([sys.executable, "-m", "uvms_mj.cli.main", "validate", "/dev/zero"], capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert "'/dev/zero' is not a file" in r.stderr or "larger than 1024 KiB" in r.stderr


def test_sets_with_bad_yaml_values(cli, tmp_path):
    f = _write(tmp_path, {"duration": 0.3})
    for s in ("duration=!!float abc", "seed=" + "9" * 5000, "description=&a [*a]", "duration=true",
              "controller.params.T=true", "duration=1e308"):
        res = cli("run", f, "--set", s, "--no-plots")
        _usage_error(res, s.partition("=")[0])
        # the value named (a 5000-digit one by its start: the Error line is kept to one readable line)
        assert str(f) in res.output or f"--set {s[:50]!r}"[:-1] in res.output
    assert not any(tmp_path.glob("**/*.mcap"))


# --------------------------------------------------------------------------- short or broken runs


def test_one_sample_run_ends_with_status_and_log(cli, tmp_path):
    f = _write(tmp_path, {"duration": 0.001})
    res = cli("run", f, "--out", tmp_path / "one.mcap", "--plots")
    _no_traceback(res)
    assert res.exit_code == 0
    assert "at least 2 are needed" in res.output  # a warning, not a traceback
    assert (tmp_path / "one.mcap").exists()
    info = cli("info", tmp_path / "one.mcap")
    assert info.exit_code == 0 and "status:    ok" in info.output


def test_a_run_that_raises_ends_with_status_error(cli, tmp_path, monkeypatch):
    from uvms_mj.control import rac

    def boom(self, m):
        raise np.linalg.LinAlgError("Singular matrix")

    monkeypatch.setattr(rac.RAC, "compute", boom)
    f = _write(tmp_path, {"duration": 0.3, "controller": {"name": "rac"}})
    res = cli("run", f, "--out", tmp_path / "e.mcap")
    _no_traceback(res)
    assert res.exit_code == 1 and "error: the run failed: LinAlgError: Singular matrix" in res.output
    info = cli("info", tmp_path / "e.mcap")
    assert info.exit_code == 0 and "status:    error" in info.output


class _Wild(Controller):
    name = "wild"
    T = 1 / 60

    def __init__(self, at: int = 0, value: float = 1e43) -> None:
        self.at, self.value = at, value

    def reset(self, m) -> None:
        pass

    def compute(self, m) -> Command:
        u = self.value if m.k >= self.at else 0.0
        return Command(thrust=np.full(3, u), torques=np.zeros(2), signals={"p_desired": np.zeros(5)})


def test_absurd_commands_are_divergence():
    res = run_closed_loop(Plant(), _Wild(at=3), 1.0, T=1 / 60)
    assert res.status == "diverged"
    assert "1e+43" in res.reason and f"{COMMAND_ABS_MAX:g}" in res.reason and "t = 0.0500" in res.reason
    # Large but plausible commands are not (the plant saturates them).
    assert run_closed_loop(Plant(), _Wild(at=3, value=100.0), 0.2, T=1 / 60).status == "ok"


def test_metrics_of_a_run_without_samples():
    from uvms_mj.sim.experiment import METRIC_KEYS, metrics

    res = run_closed_loop(Plant(), _Wild(at=0, value=float("nan")), 1.0, T=1 / 60)
    assert res.status == "diverged" and len(res.t) == 0
    m = metrics(res)
    assert set(m) == set(METRIC_KEYS) and all(np.isnan(v) for v in m.values())


def test_mujoco_warnings_go_to_the_run_not_a_file(monkeypatch, tmp_path, capfd):
    monkeypatch.chdir(tmp_path)

    class Kick(_Wild):
        def compute(self, m):
            if m.k == 2:
                plant.data.qvel[:] = np.nan
            return super().compute(m)

    plant = Plant()
    res = run_closed_loop(plant, Kick(at=99, value=0.0), 1.0, T=1 / 60)
    assert res.status == "diverged"
    assert any("QVEL" in w for w in res.meta["mujoco_warnings"])
    assert "MuJoCo warning" in res.reason
    assert "mujoco warning: Nan, Inf or huge value in QVEL" in capfd.readouterr().err
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()


# --------------------------------------------------------------------------- output paths


@pytest.fixture
def scenario(tmp_path) -> Path:
    return _write(tmp_path, {"duration": 0.1, "outputs": {"plots": False}}, "sc")


@pytest.mark.parametrize("out, needle", [
    ("/proc/uvms.mcap", "/proc is not a place"),
    ("/sys/uvms.mcap", "/sys is not a place"),
    ("/dev/full", "/dev is not a place"),
    ("/proc/self/fd/1", "/proc is not a place"),
])
def test_out_in_system_folders(out, needle, cli, scenario):
    _usage_error(cli("run", scenario, "--out", out), needle)


def test_out_whose_parent_is_a_file(cli, scenario, tmp_path):
    _usage_error(cli("run", scenario, "--out", scenario / "x.mcap"), "is a file, not a folder")
    _usage_error(cli("run", scenario, "--out", tmp_path / "sc.yaml" / "a" / "b.mcap"), "is a file, not a folder")


def test_out_equal_to_the_scenario_keeps_it(cli, scenario):
    before = scenario.read_bytes()
    _usage_error(cli("run", scenario, "--out", scenario), "is the input file")
    assert scenario.read_bytes() == before


def test_out_on_a_symlink_or_a_foreign_file_keeps_it(cli, scenario, tmp_path):
    target = tmp_path / "notes.txt"
    target.write_text("precious")
    link = tmp_path / "link.mcap"
    link.symlink_to(target)
    _usage_error(cli("run", scenario, "--out", link), "symbolic link")
    _usage_error(cli("run", scenario, "--out", target), "not a log written by uvms-mj")
    assert target.read_text() == "precious"
    # An old log is replaced as before.
    assert cli("run", scenario, "--out", tmp_path / "a.mcap").exit_code == 0
    assert cli("run", scenario, "--out", tmp_path / "a.mcap").exit_code == 0


def test_outputs_log_pointing_into_an_unwritable_place(cli, tmp_path):
    f = _write(tmp_path, {"duration": 0.1, "outputs": {"log": "/proc/self/uvms.mcap"}})
    _usage_error(cli("run", f), "outputs" if False else "/proc is not a place")
    _usage_error(cli("validate", f), "/proc is not a place")


def test_output_folders_of_compare_sweep_plot(cli, scenario, tmp_path):
    for cmd in (("compare", scenario, "--out", "/sys/x"),
                ("sweep", scenario, "--vary", "duration=[0.1]", "--out", "/proc/x"),
                ("sweep", scenario, "--vary", "duration=[0.1]", "--out", scenario / "x"),
                ("plot", scenario, "-o", "/proc/x")):
        res = cli(*cmd)
        _usage_error(res, "not a place" if str(cmd[-1]).startswith(("/proc", "/sys")) else "not a folder")
    _usage_error(cli("sweep", scenario, "--vary", "duration=linspace(0.01, 0.1, 100000000)"), "at most 10000")


def test_full_disk_is_an_io_error(cli, scenario, tmp_path, monkeypatch):
    from uvms_mj.io import recorder

    def full(self, t, row):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(recorder.McapRecorder, "write_sample", full)
    res = cli("run", scenario, "--out", tmp_path / "full.mcap")
    _no_traceback(res)
    assert res.exit_code == EXIT_IO
    assert "cannot write" in res.output and "No space left on device" in res.output


def test_two_writers_of_one_log(tmp_path, cli, scenario):
    from uvms_mj.io.recorder import LogInUseError, McapRecorder, read_log

    path = tmp_path / "same.mcap"
    params = Plant().params
    with McapRecorder(path, params, {"x": 1}) as rec:
        rec.write_sample(0.0, {"a": 1.0})
        with pytest.raises(LogInUseError, match="another process is writing"):
            McapRecorder(path, params, {"x": 2})
        _usage_error(cli("run", scenario, "--out", path), "another process is writing")
        rec.write_sample(0.1, {"a": 2.0})
    log = read_log(path)  # the first writer's log is intact
    assert log.status == "ok" and len(log.t) == 2 and log.meta["x"] == 1


# --------------------------------------------------------------------------- malformed logs


def _malformed(tmp_path: Path, good: bytes) -> dict[str, Path]:
    from mcap.writer import Writer

    cases = {"empty": b"", "magic": b"\x89MCAP0\r\n", "head": good[:200], "tail": good[-300:],
             "garbage": bytes(range(256)) * 20}
    b = bytearray(good)
    b[len(b) // 2] ^= 0xFF  # a flipped byte in the data (the log reads up to it, and plots)
    cases["flip"] = bytes(b)
    b = bytearray(good)
    b[40] ^= 0xFF  # in the header
    cases["flip_header"] = bytes(b)
    for name, topic, chmeta, meta in (
        ("other", "/x", {}, None),
        ("bogus_meta", "/x", {}, {"robot_params": "[1,2", "T": '"x"'}),
        ("bogus_signals", "/uvms/state", {"uvms_mj.signals": "not json"}, None),
    ):
        import io

        f = io.BytesIO()
        w = Writer(f)
        w.start()
        cid = w.register_channel(topic, "json", w.register_schema("s", "jsonschema", b"{}"), chmeta)
        if meta:
            w.add_metadata("uvms_mj", meta)
        for k in range(3):
            w.add_message(cid, k, json.dumps({"a": k}).encode(), k, k)
        w.finish()
        cases[name] = f.getvalue()
    out = {}
    for name, data in cases.items():
        p = tmp_path / f"bad_{name}.mcap"
        p.write_bytes(data)
        out[name] = p
    return out


def test_plot_and_render_on_malformed_logs(cli, scenario, tmp_path, monkeypatch):
    from uvms_mj.analysis import render

    assert cli("run", scenario, "--out", tmp_path / "good.mcap").exit_code == 0
    # No GL needed: the renderer is only reached for logs that read and replay.
    monkeypatch.setattr(render, "render_video", lambda log, out, **kw: {"frames": len(log.t)})
    for name, p in _malformed(tmp_path, (tmp_path / "good.mcap").read_bytes()).items():
        for cmd in (("plot", p, "-o", tmp_path / "plots"), ("render", p, "-o", tmp_path / f"{name}.mp4"),
                    ("info", p)):
            res = cli(*cmd)
            _no_traceback(res)
            assert res.exit_code in (0, 2), (name, cmd[0], res.output)


# --------------------------------------------------------------------------- scenario extras


def test_attitude_and_joint_noise_are_separate_sensors():
    q = np.zeros(5)

    def noise(sensor):
        plant = Plant()
        res = run_closed_loop(plant, _Wild(at=99, value=0.0), 0.5, T=1 / 60, sensor=sensor, seed=3)
        return res.signals["q_measured"] - res.signals["q_true"] + q

    both = noise(SensorModel(angle_noise=1e-3))
    split = noise(SensorModel(attitude_noise=1e-3, joint_noise=1e-3))
    assert np.array_equal(both, split)  # the shorthand is the same draw
    cam = noise(SensorModel(attitude_noise=1e-3, joint_noise=0.0))
    assert np.all(cam[:, 3:] == 0) and np.std(cam[:, 2]) > 5e-4
    enc = noise(SensorModel(angle_noise=1e-3, joint_noise=1e-5))
    assert 0 < np.std(enc[:, 3:]) < 2e-5 and np.std(enc[:, 2]) > 5e-4


def test_base_reference_options(tmp_path):
    from uvms_mj.scenario.schema import build

    f = _write(tmp_path, {"sensors": {"position_noise": 0.01}})
    refs = {}
    for ref in ("measured", "truth", "nominal"):
        sc = load_scenario(f, [f"controller.base_reference={ref}"])
        plant, ctrl = build(sc)
        q0 = plant.q.copy()
        from uvms_mj.control.base import Measurement

        ctrl.reset(Measurement(k=0, t=0.0, q=q0 + np.r_[0.01, 0.01, 0, 0, 0], qd=None))
        refs[ref] = ctrl._ref_pos.copy()
    assert np.allclose(refs["measured"][:2], q0[:2] + 0.01)
    assert np.allclose(refs["truth"], q0[:3]) and np.allclose(refs["nominal"], q0[:3])
    from uvms_mj.scenario.schema import resolved, validate_scenario

    sc = load_scenario(f, ["controller.base_reference=truth"])
    assert validate_scenario(resolved(sc)).controller.base_reference == "truth"  # logs re-validate
    with pytest.raises(ValueError, match="not both"):
        load_scenario(f, ["controller.base_reference=truth", "controller.params.base_reference=[0,0,0]"])
    _, pd_ctrl = build(load_scenario(f, ["controller.name=pd", "controller.base_reference=truth"]))
    assert np.allclose(pd_ctrl.base_reference, q0[:3])  # pd takes it too (on the generic nominal model)


def test_delay_with_the_paper_gains_warns(cli, tmp_path):
    f = _write(tmp_path, {"sensors": {"delay": 1}})
    res = cli("validate", f)
    assert res.exit_code == 0 and "warning: sensors.delay = 1" in res.output and "0.15" in res.output
    assert not scenario_warnings(load_scenario(f, ["controller.params.gamma=0.1", "controller.params.lam=0.1"]))
    assert not scenario_warnings(load_scenario(_write(tmp_path, {}, "plain")))


# --------------------------------------------------------------------------- signals and processes


#: The installed command (its start-up is what Ctrl-C must not turn into a traceback).
UVMS = Path(sys.executable).parent / "uvms-mj"


def _uvms(*args: str, pipes: bool = True) -> subprocess.Popen:
    if not UVMS.exists():
        pytest.skip("the uvms-mj command is not installed next to this Python")
    out = subprocess.PIPE if pipes else subprocess.DEVNULL
    return subprocess.Popen([str(UVMS), *args], stdout=out, stderr=out, text=True)


def _wait_for_mujoco(pid: int, limit: float = 30.0) -> None:
    """Until the process has loaded libmujoco (its imports are under way: the CLI's own handler
    is set before it imports mujoco), or it ended, or ``limit`` seconds passed."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < limit:
        try:
            if "libmujoco" in Path(f"/proc/{pid}/maps").read_text(errors="replace"):
                return
        except OSError:
            return
        time.sleep(0.005)


@pytest.mark.parametrize("after", ["imports", 0.4])
def test_early_ctrl_c_exits_130(after, scenario, tmp_path):
    """Ctrl-C while the command is still importing (as soon as mujoco is loaded: an event, not a
    time, so the test does not depend on the machine's speed) or a little later exits 130
    quietly. (Before the interpreter runs any of our code, Python's own default applies.)"""
    p = _uvms("run", str(scenario), "--set", "duration=40", "--out", str(tmp_path / "c.mcap"))
    if after == "imports" and sys.platform.startswith("linux"):
        _wait_for_mujoco(p.pid)
    else:
        time.sleep(0.4)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=30)
    assert p.returncode == EXIT_INTERRUPTED, err
    assert "Traceback" not in err and "Aborted" not in err


def _children(pid: int) -> set[int]:
    out = set()
    for task in Path(f"/proc/{pid}/task").iterdir():
        text = (task / "children").read_text().split()
        out |= {int(c) for c in text}
    return out


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="uses /proc")
def test_sweep_workers_end_with_a_killed_sweep(tmp_path):
    f = _write(tmp_path, {"duration": 40, "outputs": {"plots": False}})
    p = _uvms("sweep", str(f), "--vary", "plant.current[0]=[0, 0.01, 0.02, 0.03]", "--workers", "2",
              "--controllers", "rac", "--out", str(tmp_path / "sw"), pipes=False)
    deadline = time.time() + 30
    kids: set[int] = set()
    while time.time() < deadline and len(kids) < 2:
        time.sleep(0.2)
        kids = {k for k in _children(p.pid)
                if "resource_tracker" not in Path(f"/proc/{k}/cmdline").read_text(errors="replace")}
    assert len(kids) >= 2, "no workers started"
    os.kill(p.pid, signal.SIGKILL)
    p.wait(timeout=10)
    deadline = time.time() + 30  # a hang guard, not a speed claim
    while time.time() < deadline and any(Path(f"/proc/{k}").exists() for k in kids):
        time.sleep(0.1)
    alive = [k for k in kids if Path(f"/proc/{k}").exists()
             and "Z" not in Path(f"/proc/{k}/stat").read_text().split()[2]]
    assert not alive, f"workers {alive} outlived the sweep"
