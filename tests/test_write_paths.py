"""Every write path of the CLI (issue 23 item 3): a command never overwrites one of its inputs nor a
file that is not its own kind of output (exit 2, one line naming the option, the path and why, the
file unchanged byte for byte); a full disk or an I/O error is exit 5 with one line; nothing
half-written is left under the final name (outputs go through :mod:`uvms_mj.io.atomic`).

A full disk is simulated by making the write fail with OSError(ENOSPC) (no tmpfs needs root here):
``os.fsync`` for the files written through ``atomic_open`` (the data are flushed, then the disk
"fills up"), matplotlib's ``savefig`` for figures, a stand-in ffmpeg that writes part of a file and
exits with ffmpeg's ENOSPC message for videos.
"""

from __future__ import annotations

import errno
import os
import shutil
import stat
from pathlib import Path

import pytest
import yaml
from click.testing import CliRunner

from uvms_mj.cli.main import EXIT_IO, main

TRIALS = Path(__file__).resolve().parents[1] / "data" / "hinsdale-2023" / "trials"


@pytest.fixture
def cli(monkeypatch, tmp_path):
    monkeypatch.chdir(tmp_path)
    runner = CliRunner()
    return lambda *args: runner.invoke(main, [str(a) for a in args])


@pytest.fixture
def scenario(tmp_path) -> Path:
    p = tmp_path / "sc.yaml"
    p.write_text(yaml.safe_dump({"duration": 0.2, "outputs": {"plots": False}}), encoding="utf-8")
    return p


@pytest.fixture
def log(cli, scenario, tmp_path) -> Path:
    p = tmp_path / "run.mcap"
    res = cli("run", scenario, "--out", p)
    assert res.exit_code == 0, res.output
    return p


def _lines(res) -> list[str]:
    return [ln for ln in res.output.splitlines() if ln.strip()]


def _refused(res, option: str, path, *files: Path, before: dict | None = None) -> None:
    """Exit 2, no traceback, the last line names the option and the path; ``files`` unchanged."""
    assert res.exception is None or isinstance(res.exception, SystemExit), repr(res.exception)
    assert "Traceback" not in res.output
    assert res.exit_code == 2, res.output
    err = [ln for ln in _lines(res) if "Error:" in ln]
    assert len(err) == 1 and option in err[0] and str(path) in err[0], res.output
    for f in files:
        assert f.read_bytes() == before[f], f"{f} changed"


def _snapshot(*files: Path) -> dict:
    return {f: f.read_bytes() for f in files}


def _no_temporaries(folder: Path) -> None:
    left = [p.name for p in folder.iterdir() if ".part" in p.name]
    assert not left, left


# --------------------------------------------------------------------------- inputs are never overwritten


def test_run_and_compare_refuse_their_inputs(cli, scenario, tmp_path):
    before = _snapshot(scenario)
    _refused(cli("run", scenario, "--out", tmp_path / "a.mcap", "--json", scenario), "--json", scenario,
             scenario, before=before)
    # The JSON may not be the log it describes either (not there yet: compared by name).
    _refused(cli("run", scenario, "--out", tmp_path / "a.mcap", "--json", tmp_path / "a.mcap"), "--json",
             tmp_path / "a.mcap")
    _refused(cli("compare", scenario, "--out-dir", tmp_path, "--json", scenario), "--json", scenario,
             scenario, before=before)
    # A symbolic link to the scenario, given as --json: refused, the scenario kept.
    link = tmp_path / "link.json"
    link.symlink_to(scenario)
    res = cli("run", scenario, "--out", tmp_path / "b.mcap", "--json", link)
    assert res.exit_code == 2 and "symbolic link" in res.output
    assert scenario.read_bytes() == before[scenario]
    assert not (tmp_path / "a.mcap").exists() and not (tmp_path / "b.mcap").exists()


def test_export_refuses_its_log_and_foreign_files(cli, log, scenario, tmp_path):
    before = _snapshot(log, scenario)
    _refused(cli("export", log, "-o", scenario), "-o/--out", scenario, scenario, before=before)
    _refused(cli("export", log, "-o", log), "-o/--out", log, log, before=before)
    hard = tmp_path / "hard.csv"  # another name of the log: refused as the input
    os.link(log, hard)
    _refused(cli("export", log, "-o", hard), "-o/--out", hard, log, before=before)
    _refused(cli("export", log, "--format", "npz", "-o", scenario), "-o/--out", scenario, scenario, before=before)
    _refused(cli("export", log, "--layout", "channels", "-o", log), "-o/--out", log, log, before=before)
    # Its own kind of output is replaced as before.
    assert cli("export", log, "-o", tmp_path / "x.csv").exit_code == 0
    assert cli("export", log, "-o", tmp_path / "x.csv").exit_code == 0
    assert (tmp_path / "x.csv").read_text().startswith("t,")


def test_plot_and_render_refuse_foreign_files(cli, log, tmp_path):
    notes = tmp_path / "run_tracking.png"  # where plot would write, but not a PNG of ours
    notes.write_text("precious")
    before = _snapshot(notes, log)
    _refused(cli("plot", log), "--out-dir", notes, notes, before=before)
    _refused(cli("render", log, "-o", log), "--out", log, log, before=before)
    _refused(cli("render", log, "-o", notes), "--out", notes, notes, before=before)


def test_sweep_refuses_to_write_over_its_scenario(cli, tmp_path):
    out = tmp_path / "sw"
    out.mkdir()
    sc = out / "results.csv"  # a scenario that happens to sit where the table goes
    sc.write_text(yaml.safe_dump({"duration": 0.1, "outputs": {"plots": False}}), encoding="utf-8")
    before = _snapshot(sc)
    _refused(cli("sweep", sc, "--vary", "duration=[0.1]", "--out-dir", out, "--engine", "serial"), "--out-dir",
             sc, sc, before=before)


@pytest.fixture
def trials(tmp_path) -> Path:
    """One trial's files (not a valid trial needed: the outputs are refused before reading them)."""
    folder = tmp_path / "trials"
    folder.mkdir()
    for f in sorted(TRIALS.glob("baseline1_*.csv")):
        shutil.copy(f, folder / f.name)
    return folder


@pytest.mark.skipif(not TRIALS.is_dir(), reason="the pool trials are not in this checkout")
def test_sim2real_and_identify_refuse_trial_files(cli, trials, tmp_path):
    imu, joints = trials / "baseline1_imu.csv", trials / "baseline1_joint_states.csv"
    overrides = tmp_path / "over.yaml"
    overrides.write_text("# uvms-mj identify: by hand\nvehicle.mass: 10.0\n")
    before = _snapshot(imu, joints, overrides)
    _refused(cli("sim2real", trials, "--json", imu), "--json", imu, imu, before=before)
    _refused(cli("identify", trials, "--fit", "baseline1", "-o", joints), "-o/--out", joints, joints, before=before)
    _refused(cli("identify", trials, "--fit", "baseline1", "--overrides", overrides, "-o", overrides), "-o/--out",
             overrides, overrides, before=before)
    _refused(cli("identify", trials, "--fit", "baseline1", "--json", imu), "--json", imu, imu, before=before)


# --------------------------------------------------------------------------- full disk: exit 5, nothing left


def _full_disk(*_a, **_k):
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


def _io_failure(res, final: Path) -> None:
    assert res.exception is None or isinstance(res.exception, SystemExit), repr(res.exception)
    assert "Traceback" not in res.output
    assert res.exit_code == EXIT_IO, res.output
    err = [ln for ln in _lines(res) if ln.startswith("error:")]
    assert len(err) == 1 and "No space left on device" in err[0], res.output
    assert not final.exists(), f"{final} left behind"
    _no_temporaries(final.parent)


@pytest.mark.parametrize("fmt", ["csv", "npz"])
def test_export_on_a_full_disk(cli, log, tmp_path, monkeypatch, fmt):
    monkeypatch.setattr(os, "fsync", _full_disk)
    _io_failure(cli("export", log, "--format", fmt, "-o", tmp_path / f"x.{fmt}"), tmp_path / f"x.{fmt}")


def test_export_keeps_an_old_output_when_the_disk_fills(cli, log, tmp_path, monkeypatch):
    old = tmp_path / "x.csv"
    assert cli("export", log, "-o", old).exit_code == 0
    before = old.read_bytes()
    monkeypatch.setattr(os, "fsync", _full_disk)
    res = cli("export", log, "-o", old)
    assert res.exit_code == EXIT_IO and old.read_bytes() == before
    _no_temporaries(tmp_path)


def test_run_json_on_a_full_disk(cli, scenario, tmp_path, monkeypatch):
    monkeypatch.setattr(os, "fsync", _full_disk)
    _io_failure(cli("run", scenario, "--out", tmp_path / "a.mcap", "--json", tmp_path / "a.json"),
                tmp_path / "a.json")


def test_plots_on_a_full_disk(cli, log, tmp_path, monkeypatch):
    from matplotlib.figure import Figure

    def half_then_full(self, fname, *a, **k):
        Path(fname).write_bytes(b"\x89PNG\r\n\x1a\n half")
        _full_disk()

    monkeypatch.setattr(Figure, "savefig", half_then_full)
    _io_failure(cli("plot", log, "--out-dir", tmp_path / "p"), tmp_path / "p" / "run_tracking.png")


def test_log_cut_short_by_a_full_disk_is_removed(cli, scenario, tmp_path, monkeypatch):
    from uvms_mj.io import recorder

    monkeypatch.setattr(recorder.McapRecorder, "write_sample", lambda self, t, row: _full_disk())
    _io_failure(cli("run", scenario, "--out", tmp_path / "full.mcap"), tmp_path / "full.mcap")


def test_render_exits_5_when_ffmpeg_fails(cli, log, tmp_path, monkeypatch):
    """A stand-in ffmpeg: reads the frames, writes part of an MP4, prints ffmpeg's message for a
    full disk and exits 1 (what the real one does on ENOSPC)."""
    import imageio_ffmpeg

    fake = tmp_path / "ffmpeg"
    fake.write_text("#!/bin/sh\nfor a; do out=$a; done\ncat > /dev/null\n"
                    "printf '\\000\\000\\000\\040ftypisom' > \"$out\"\n"
                    "echo 'av_interleaved_write_frame(): No space left on device' >&2\n"
                    "echo 'Error writing trailer: No space left on device' >&2\nexit 1\n")
    fake.chmod(fake.stat().st_mode | stat.S_IXUSR)
    monkeypatch.setattr(imageio_ffmpeg, "get_ffmpeg_exe", lambda: str(fake))
    res = cli("render", log, "-o", tmp_path / "v.mp4", "--size", "64", "48", "--fps", "5")
    if res.exit_code == 4:
        pytest.skip("rendering unavailable")
    _io_failure(res, tmp_path / "v.mp4")


# --------------------------------------------------------------------------- the helper itself


def test_atomic_open_replaces_whole_or_not_at_all(tmp_path):
    from uvms_mj.io.atomic import atomic_open

    p = tmp_path / "a.txt"
    with atomic_open(p) as f:
        f.write("one")
    assert p.read_text() == "one"
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(p.stat().st_mode) == 0o666 & ~umask  # a new file's mode, not mkstemp's 0600
    with pytest.raises(RuntimeError):
        with atomic_open(p) as f:
            f.write("two, half")
            raise RuntimeError("stop")
    assert p.read_text() == "one"
    _no_temporaries(tmp_path)
