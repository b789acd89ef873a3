"""Trial-folder input (issue 23, item 5): problems named with file and line, metadata checked
only where it is used, a file given for a folder said so. Each case is a copy of the real trial
``baseline1`` with one defect made by hand; the expected issue is the defect's file:line."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from uvms_mj.analysis.trials import load_trials

REPO = Path(__file__).resolve().parents[1]
SRC = REPO / "data" / "hinsdale-2023" / "trials"
OFFSETS = np.array([3.07, 0.0, 0.0, 2.879])  # the hinsdale2023 model's numeric

pytestmark = pytest.mark.skipif(not (SRC / "baseline1_imu.csv").is_file(), reason="data/hinsdale-2023 absent")


def _copy(tmp_path: Path) -> Path:
    for f in SRC.glob("baseline1_*.csv"):
        shutil.copy(f, tmp_path / f.name)
    return tmp_path


def _issues(folder: Path):
    ts = load_trials(folder, offsets=OFFSETS, names=["baseline1"])
    return ts, [(i.file.name if i.file else None, i.line, i.message, i.severity) for i in ts.issues]


def test_an_imu_file_cut_inside_its_last_field_is_reported_with_its_line(tmp_path):
    d = _copy(tmp_path)
    lines = (d / "baseline1_imu.csv").read_text().splitlines()
    half = lines[: len(lines) // 2]
    half[-1] = half[-1][:-3]  # cut inside the last field, no line end
    (d / "baseline1_imu.csv").write_text("\n".join(half))
    ts, issues = _issues(d)
    assert ("baseline1_imu.csv", len(half), "the last line has no line end: the file may be cut short there",
            "warning") in issues
    assert any("overlap only" in m for _, _, m, _ in issues)  # the IMU now ends 20 s before the joints
    assert "baseline1" in ts.trials


def test_a_negative_start_time_is_a_warning_not_a_skipped_trial(tmp_path):
    d = _copy(tmp_path)
    (d / "metadata_baseline1.yml").write_text("start_time: -5\n")
    ts, issues = _issues(d)
    assert "baseline1" in ts.trials and ts["baseline1"].start_time is None
    assert ("metadata_baseline1.yml", 1, "start_time -5 s < 0: ignored (start of the motion unknown)",
            "warning") in issues


def test_a_non_utf8_file_is_named(tmp_path):
    d = _copy(tmp_path)
    (d / "baseline1_joint_states.csv").write_bytes(b"time_secs,\xff\xfe\n")
    ts, issues = _issues(d)
    assert "baseline1" in ts.skipped
    assert any(f == "baseline1_joint_states.csv" and m.startswith("not UTF-8 text") for f, _, m, _ in issues)


def test_records_that_do_not_overlap_and_a_one_row_file_skip_the_trial_without_a_traceback(tmp_path):
    d = _copy(tmp_path)
    lines = (d / "baseline1_imu.csv").read_text().splitlines()
    shifted = [lines[0]] + [",".join([str(float(x.split(",")[0]) - 100.0)] + x.split(",")[1:]) for x in lines[1:]]
    (d / "baseline1_imu.csv").write_text("\n".join(shifted) + "\n")
    ts, issues = _issues(d)
    assert "baseline1" in ts.skipped and any("do not overlap" in m for _, _, m, _ in issues)
    d2 = _copy(tmp_path / "b" if (tmp_path / "b").mkdir() is None else tmp_path)
    rows = (d2 / "baseline1_joint_states.csv").read_text().splitlines()[:2]
    (d2 / "baseline1_joint_states.csv").write_text("\n".join(rows) + "\n")
    ts, issues = _issues(d2)
    assert "baseline1" in ts.skipped and any("one data row" in m for _, _, m, _ in issues)


def test_a_file_given_for_the_folder_is_said_so(tmp_path):
    d = _copy(tmp_path)
    with pytest.raises(FileNotFoundError, match="is a file"):
        load_trials(d / "baseline1_imu.csv", offsets=OFFSETS)
