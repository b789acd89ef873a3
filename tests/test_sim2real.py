"""Sim-to-real (uvms_mj.analysis.sim2real, uvms_mj.analysis.identify, ``uvms-mj sim2real`` / ``identify``).

Truths: synthetic signals with a known shift, known RMS and known settled changes (the metrics);
a closed loop for the identification (attitudes simulated by the model itself with known
parameters must give those parameters back); hand-made defects in copies of real files (each
bad trial skipped and named with its file and line, the others still run). The CI short version
runs on tests/data/hinsdale-2023-excerpt (two real trials); the tests of the whole Hinsdale folder
run on the copy shipped in data/hinsdale-2023 (see tests/test_trials.py: UVMS_MJ_HINSDALE), and
pin the README's headline figures.
"""

from __future__ import annotations

import json
import math
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import uvms_mj  # noqa: F401  (the plugins: registered once by conftest.py)
from uvms_mj.analysis import sim2real as s2r
from uvms_mj.cli.main import main
from uvms_mj.analysis.identify import identify, nominal_values, overrides_for, write_overrides
from uvms_mj.analysis.trials import ImuData, load_trials

from test_trials import REAL, needs_real

EXCERPT = Path(__file__).resolve().parent / "data" / "hinsdale-2023-excerpt"
FAST = s2r.SimConfig(dt=0.01)


@pytest.fixture(scope="module")
def excerpt():
    ts = load_trials(EXCERPT)
    assert sorted(ts.trials) == ["015-0", "026-0"] and not ts.skipped
    return ts


@pytest.fixture(scope="module")
def model():
    return s2r.build_model()


# ----------------------------------------------------------------------------- metrics


def test_best_lag_recovers_a_known_shift():
    t = np.arange(0, 30, 0.05)
    sig = lambda tt: np.tanh((tt - 12) / 2) + 0.3 * np.sin(2 * np.pi * tt / 2.6)  # noqa: E731
    ts = np.arange(0, 30, 0.01)
    for shift in (0.37, -0.81, 0.0):
        meas = [sig(t - shift), 0.5 * sig(t - shift)]  # the measurement follows the simulation by `shift`
        lag, rr = s2r.best_lag(t, meas, ts, [sig(ts), 0.5 * sig(ts)], window=2.0, step=0.01)
        assert lag == pytest.approx(shift, abs=1.5e-3)
        assert max(rr) < 2e-3


def test_rms_and_settled_changes_on_a_known_step():
    t = np.arange(0, 20, 0.01)
    q = np.zeros((len(t), 4))
    ramp = (t >= 5) & (t <= 10)
    q[:, 1] = np.clip((t - 5) / 5, 0, 1) * 0.5  # 0.1 rad/s from 5 to 10 s
    moves = s2r.arm_moves(t, q, speed=0.02, gap=1.0)
    assert len(moves) == 1 and moves[0][0] == pytest.approx(5, abs=0.02) and moves[0][1] == pytest.approx(10, abs=0.02)
    assert ramp.any()
    meas = [np.where(t < 7, 0.1, 0.3)]
    sim = [np.where(t < 7, 0.1, 0.35)]
    ch = s2r.settled_changes(t, meas, t, sim, moves, (0.0, 20.0), window=2.0)
    assert len(ch) == 1
    assert ch[0]["meas"][0] == pytest.approx(0.2) and ch[0]["sim"][0] == pytest.approx(0.25)
    assert ch[0]["err"][0] == pytest.approx(0.05)
    assert ch[0]["pre"] == [pytest.approx(3.0, abs=0.02), pytest.approx(5.0, abs=0.02)]
    assert s2r.rms(np.array([3.0, -4.0])) == pytest.approx(math.sqrt(12.5))


# ----------------------------------------------------------------------------- overrides


def test_override_file_round_trip_and_errors(tmp_path):
    p = write_overrides(tmp_path / "o.yaml", {"bluerov2.cob": [0.01, 0.0, 0.03], "alpha_wrist.volume": 1.6e-4,
                                              "bluerov2.mass": 13.2}, header="test")
    over = s2r.load_overrides(p)
    assert over["bluerov2.cob"] == [0.01, 0.0, 0.03]
    from uvms_mj.physics import hydro_of

    m = s2r.build_model(overrides=over, neutral=False)
    info = hydro_of(m)
    assert np.allclose(info.bodies[m.body("bluerov2").id].cob, [0.01, 0.0, 0.03])
    assert info.bodies[m.body("alpha_wrist").id].volume == pytest.approx(1.6e-4)
    assert m.body_mass[m.body("bluerov2").id] == pytest.approx(13.2)
    bad = {"nodot: 1": "BODY.ATTRIBUTE", "bluerov2.colour: 1": "unknown attribute",
           "bluerov2.cob: [1, 2]": "needs 3", "bluerov2.volume: abc": "number", "[1, 2]": "mapping",
           "bluerov2.volume: -1": ">= 0"}
    for text, what in bad.items():
        (tmp_path / "b.yaml").write_text(text + "\n")
        with pytest.raises(s2r.OverrideError, match=what):
            s2r.load_overrides(tmp_path / "b.yaml")
    with pytest.raises(s2r.OverrideError, match="no body named 'nope'"):
        s2r.build_model(overrides={"nope.mass": 1.0})


def test_neutral_model_has_no_net_force(model):
    assert abs(s2r._net_force(model)) < 1e-9
    assert s2r._net_force(s2r.build_model(neutral=False)) == pytest.approx(-10.45, abs=0.01)


# ----------------------------------------------------------------------------- simulation


def test_replay_tracks_the_arm_and_is_step_independent(excerpt, model):
    tr = excerpt["015-0"]
    sim = s2r.simulate_trial(model, tr)  # the sim2real settings (dt 0.002 s)
    sc = s2r.score_trial(tr, sim)
    assert sc.tracking_deg < s2r.MAX_TRACKING_ERROR_DEG
    assert sc.n > 250 and 0 < sc.rms_roll < 2 and 0 < sc.rms_pitch < 2
    assert len(sc.moves) == 1 and len(sc.changes) == 1 and abs(sc.lag) <= 2
    # starts from the measured attitude
    assert sim.roll[0] == pytest.approx(tr.imu.roll[np.searchsorted(tr.imu.t, sim.t[0])], abs=1e-9)
    # the identification's step (0.01 s) changes the scores by far less than they resolve
    sc2 = s2r.score_trial(tr, s2r.simulate_trial(model, tr, FAST), FAST)
    assert abs(sc2.rms_roll - sc.rms_roll) < 0.01 and abs(sc2.rms_pitch - sc.rms_pitch) < 0.01
    assert sc2.tracking_deg < s2r.MAX_TRACKING_ERROR_DEG


@pytest.mark.slow
def test_identification_recovers_known_parameters(excerpt):
    """Closed loop: the IMU of a trial replaced by the model's own attitude with known parameters."""
    names = ("cob_z", "roll_damping")
    truth = np.array([0.027, 1.5])
    cfg = s2r.SimConfig(dt=0.02)
    tr = excerpt["026-0"]
    m_true = s2r.build_model(overrides=overrides_for("hinsdale2023", names, truth))
    sim = s2r.simulate_trial(m_true, tr, cfg)
    roll, pitch = np.interp(tr.imu.t, sim.t, sim.roll), np.interp(tr.imu.t, sim.t, sim.pitch)
    cr, sr, cp, sp = np.cos(roll / 2), np.sin(roll / 2), np.cos(pitch / 2), np.sin(pitch / 2)
    quat = np.column_stack([cp * sr, sp * cr, -sp * sr, cp * cr])  # x y z w of Ry(pitch) Rx(roll)
    imu = ImuData(tr.imu.t, quat, roll, pitch, np.zeros_like(roll), tr.imu.ang_vel, tr.imu.lin_acc, tr.imu.lines)
    synth = replace(tr, imu=imu, name="synthetic")
    res = identify({"synthetic": synth}, fit=["synthetic"], names=names, cfg=cfg, fit_dt=0.02, max_nfev=12, jobs=1)
    assert np.allclose(res.value, truth, rtol=0, atol=[1e-4, 0.05]), res.value
    assert res.cost < 1e-3 < res.cost0
    assert nominal_values("hinsdale2023", names) == pytest.approx([0.02, 0.0])


def test_folds_are_disjoint_deterministic_and_cover_every_trial():
    from uvms_mj.analysis.identify import folds

    names = ["b", "a", "d", "c", "e"]
    parts = folds(names, 2)
    assert parts == [["a", "c", "e"], ["b", "d"]] == folds(list(reversed(names)), 2)
    with pytest.raises(ValueError, match="at least 2 folds"):
        folds(names, 1)
    with pytest.raises(ValueError, match="at least 6 trials"):
        folds(names, 6)


def test_identify_refuses_scoring_a_fit_trial(excerpt):
    with pytest.raises(ValueError, match="both fitted and scored"):
        identify(excerpt.trials, fit=["015-0"], score=["015-0"], jobs=1)
    with pytest.raises(ValueError, match="unknown parameter"):
        identify(excerpt.trials, fit=["015-0"], names=["nope"], jobs=1)


# ----------------------------------------------------------------------------- CLI (CI short version)


def test_cli_sim2real_on_the_excerpt(tmp_path):
    out = tmp_path / "s.json"
    r = CliRunner().invoke(main, ["sim2real", str(EXCERPT), "--json", str(out), "--plots", str(tmp_path / "p"),
                                  "--jobs", "1"])
    assert r.exit_code == 0, r.output
    text = r.output
    assert text.index("Static check") < text.index("Dynamic replay")
    d = json.loads(out.read_text())
    assert sorted(d["trials"]) == ["015-0", "026-0"]
    assert d["static_check"]["summary"]["n"] == 2
    for v in d["trials"].values():
        assert v["tracking_ok"] and v["rms_roll"] < 2 and v["rms_pitch"] < 2 and len(v["changes"]) == 1
    assert d["mean"]["n"] == 2
    assert sorted(p.name for p in (tmp_path / "p").iterdir()) == ["sim2real_015-0.png", "sim2real_026-0.png"]


@pytest.mark.slow
def test_cli_identify_fit_one_score_the_other(tmp_path):
    over = tmp_path / "id.yaml"
    js = tmp_path / "id.json"
    r = CliRunner().invoke(main, ["identify", str(EXCERPT), "--fit", "026-0", "--params", "cob_z,arm_volume_scale",
                                  "--max-nfev", "3", "--fit-dt", "0.02", "--jobs", "1", "--quiet", "-o", str(over),
                                  "--json", str(js)])
    assert r.exit_code == 0, r.output
    d = json.loads(js.read_text())
    fold = d["folds"][0]
    assert fold["fit"] == ["026-0"] and fold["score"] == ["015-0"]
    assert fold["cost"] <= fold["cost0"]
    assert set(d["score_after"]) == {"015-0"}
    assert all(math.isfinite(x) for x in fold["std"])
    o = s2r.load_overrides(over)
    assert "bluerov2.cob" in o and "alpha_wrist.volume" in o
    r2 = CliRunner().invoke(main, ["sim2real", str(EXCERPT), "--trials", "015-0", "--overrides", str(over),
                                   "--dt", "0.01", "--jobs", "1"])
    assert r2.exit_code == 0, r2.output
    # the fit and the score trials must differ
    r3 = CliRunner().invoke(main, ["identify", str(EXCERPT), "--fit", "026-0", "--score", "026-0,015-0"])
    assert r3.exit_code == 2 and "also in --fit" in r3.output


def _copy_trial(src: Path, dst: Path, name: str, new: str) -> dict:
    prefix = f"traj{name}"
    files = {}
    for role in ("imu", "joint_states", "mocap"):
        p = dst / f"traj{new}_{role}.csv"
        shutil.copy(src / f"{prefix}_{role}.csv", p)
        files[role] = p
    shutil.copy(src / f"metadata_{name}.yml", dst / f"metadata_{new}.yml")
    return files


def test_cli_bad_trials_are_skipped_and_named(tmp_path):
    f_ok = _copy_trial(EXCERPT, tmp_path, "015-0", "ok")
    assert f_ok
    f = _copy_trial(EXCERPT, tmp_path, "015-0", "nofile")
    f["imu"].unlink()
    f = _copy_trial(EXCERPT, tmp_path, "015-0", "nocol")
    lines = f["joint_states"].read_text().splitlines()
    lines[0] = lines[0].replace("axis_c_pos", "axis_c_position")
    f["joint_states"].write_text("\n".join(lines) + "\n")
    f = _copy_trial(EXCERPT, tmp_path, "015-0", "nanrow")
    lines = f["imu"].read_text().splitlines()
    parts = lines[9].split(",")
    parts[2] = "nan"
    lines[9] = ",".join(parts)
    f["imu"].write_text("\n".join(lines) + "\n")
    f = _copy_trial(EXCERPT, tmp_path, "015-0", "unsorted")
    lines = f["joint_states"].read_text().splitlines()
    lines[20], lines[21] = lines[21], lines[20]
    f["joint_states"].write_text("\n".join(lines) + "\n")
    r = CliRunner().invoke(main, ["sim2real", str(tmp_path), "--dt", "0.02", "--jobs", "1", "--json", str(tmp_path / "o.json")])
    assert r.exit_code == 0, r.output
    out = r.output
    assert "skipped trial nofile: trajnofile_imu.csv: file missing" in out
    assert "skipped trial nocol: trajnocol_joint_states.csv:1: missing column(s) axis_c_pos" in out
    assert "skipped trial nanrow: trajnanrow_imu.csv:10: NaN/inf in y_ori" in out
    assert "skipped trial unsorted: trajunsorted_joint_states.csv:22: time goes backwards" in out
    d = json.loads((tmp_path / "o.json").read_text())
    assert list(d["trials"]) == ["ok"]
    assert sorted(d["skipped"]) == ["nanrow", "nocol", "nofile", "unsorted"]


def test_cli_bad_input_is_one_line(tmp_path):
    r = CliRunner().invoke(main, ["sim2real", str(tmp_path / "nope")])
    assert r.exit_code == 2 and "does not exist" in r.output and "Traceback" not in r.output
    (tmp_path / "bad.yaml").write_text("bluerov2.cob: [1, 2]\n")
    r = CliRunner().invoke(main, ["sim2real", str(EXCERPT), "--overrides", str(tmp_path / "bad.yaml")])
    assert r.exit_code == 2 and "bluerov2.cob: needs 3 number(s)" in r.output
    r = CliRunner().invoke(main, ["sim2real", str(tmp_path)])
    assert r.exit_code == 2 and "no usable trial" in r.output
    r = CliRunner().invoke(main, ["identify", str(EXCERPT), "--fit", "015-0", "--params", "cob_q"])
    assert r.exit_code == 2 and "unknown parameter(s) cob_q" in r.output
    r = CliRunner().invoke(main, ["identify", str(EXCERPT)])
    assert r.exit_code == 2 and "--fit" in r.output
    r = CliRunner().invoke(main, ["identify", str(EXCERPT), "--fit", "015-0", "-o", str(tmp_path / "no" / "o.yaml")])
    assert r.exit_code == 2 and "cannot write" in r.output
    r = CliRunner().invoke(main, ["sim2real", str(EXCERPT), "--trials", "nope"])
    assert r.exit_code == 2 and "nope" in r.output


def test_cli_data_dir_defaults_to_the_shipped_trials(tmp_path, monkeypatch):
    """Without DATA_DIR: data/hinsdale-2023 of the package's checkout (else of the current
    folder); neither: a one-line error asking for DATA_DIR, exit 2."""
    from uvms_mj.cli import sim2real as cli_s2r

    repo = Path(__file__).resolve().parents[1]
    monkeypatch.chdir(tmp_path)
    assert cli_s2r.default_data_dir() == repo / "data" / "hinsdale-2023"
    js = tmp_path / "s.json"
    r = CliRunner().invoke(main, ["sim2real", "--trials", "015-0", "--dt", "0.02", "--jobs", "1", "--json", str(js)])
    assert r.exit_code == 0, r.output
    assert list(json.loads(js.read_text())["trials"]) == ["015-0"]
    monkeypatch.setattr(cli_s2r, "default_data_dir", lambda: None)
    for cmd in (["sim2real"], ["identify", "--cv", "2"]):
        r = CliRunner().invoke(main, cmd)
        assert r.exit_code == 2, r.output
        assert r.output.count("\n") == 1 and "pass DATA_DIR" in r.output and "Traceback" not in r.output


# ----------------------------------------------------------------------------- the whole folder


@needs_real
def test_excerpt_is_a_byte_copy_of_the_real_files():
    for p in EXCERPT.iterdir():
        if p.suffix in (".csv", ".yml"):
            assert p.read_bytes() == (REAL / p.name).read_bytes(), p.name


# The README's headline figures (section "Sim-to-real"), pinned: RMS roll and pitch errors [deg]
# of every trial, with the model as is and with the parameters identified on the *other* fold of
# `identify --cv 2` (tests/data/sim2real/identified.fold{1,2}.yaml). Source: docs/sim2real/
# sim2real-nominal.json and sim2real-fold{1,2}.json (the README's table, rounded there to 0.01).
# trial: (nominal roll, nominal pitch, identified roll, identified pitch)
HEADLINE = {
    "003-0": (0.5663, 0.9044, 0.3216, 0.3937),
    "005-0": (1.3944, 0.9841, 0.5799, 0.3885),
    "007-0": (1.4784, 1.5997, 0.4007, 0.6035),
    "009-0": (0.2580, 0.6521, 0.4551, 0.3054),
    "012-0": (1.4090, 0.4348, 0.3303, 0.6339),
    "015-0": (0.9362, 0.5165, 0.1577, 0.1092),
    "016-0": (0.3500, 0.5783, 0.1496, 0.1469),
    "024-0": (0.8239, 0.9329, 0.1820, 0.2739),
    "025-0": (0.3686, 0.5861, 0.0916, 0.3269),
    "026-0": (1.2078, 0.4299, 0.1286, 0.2967),
    "030-0": (0.7636, 0.4736, 0.2158, 0.2085),
    "alt_001-0": (1.3911, 1.2798, 1.0086, 0.6045),
    "alt_002-0": (0.5618, 1.2763, 0.4157, 0.3860),
    "alt_008-0": (0.6668, 0.9448, 0.3765, 0.2792),
    "alt_011-0": (0.4384, 1.0604, 0.2114, 0.3649),
    "baseline1": (0.3041, 0.4141, 0.3009, 0.3373),
    "baseline2": (0.2577, 0.4946, 0.2757, 0.3152),
    "baseline3": (0.2737, 0.5887, 0.2739, 0.2407),
}
HEADLINE_MEAN = (0.7472, 0.7862, 0.3264, 0.3453)  # the means over the 18 trials (README: 0.75 0.79 0.33 0.35)
# Tolerances, set by what the README states rather than by round-off: each trial within 0.005 deg
# (half the README's last digit, plus the 5e-5 of the 4-decimal pins above), each mean within
# 0.0005 deg (a systematic shift of a thousandth of a degree fails). Round-off is far below:
# the whole replay measured against the stored JSON (another commit, another run) and with numpy's
# SIMD dispatch reduced to SSE (NPY_DISABLE_CPU_FEATURES=AVX512F,...,AVX2,FMA3): max difference
# 1e-15 deg per trial. The replay is a damped, stable pendulum (no chaos amplifying it).
PER_TRIAL_TOL, MEAN_TOL = 0.005 + 5e-5, 5e-4
IDENTIFIED = Path(__file__).resolve().parent / "data" / "sim2real"


@pytest.fixture(scope="module")
def real_trials():
    ts = load_trials(REAL)
    assert sorted(ts.trials) == sorted(HEADLINE) and not ts.skipped
    return ts


def _check_headline(scores: dict, col: int) -> None:
    for name, sc in scores.items():
        want = HEADLINE[name][col:col + 2]
        assert [sc.rms_roll, sc.rms_pitch] == pytest.approx(want, abs=PER_TRIAL_TOL), name
        assert sc.tracking_deg < s2r.MAX_TRACKING_ERROR_DEG, name
    got = [sum(getattr(sc, f) for sc in scores.values()) / len(scores) for f in ("rms_roll", "rms_pitch")]
    assert got == pytest.approx(HEADLINE_MEAN[col:col + 2], abs=MEAN_TOL)


@needs_real
@pytest.mark.slow
def test_headline_figures_nominal_model(real_trials):
    """`uvms-mj sim2real` on the 18 shipped trials, the model as is (dt 0.002 s): the README's
    nominal columns and means (0.75 / 0.79 deg), arm tracking below the limit on every trial."""
    from uvms_mj.analysis.identify import run_trials

    res = run_trials(list(real_trials), cfg=s2r.SimConfig())
    assert sorted(res) == sorted(HEADLINE)
    _check_headline({n: v[1] for n, v in res.items()}, 0)
    assert max(v[1].tracking_deg for v in res.values()) < 0.003  # README: at most 0.0021 deg


@needs_real
@pytest.mark.slow
def test_headline_figures_identified_cross_validated(real_trials):
    """sim2real of each fold's trials with the parameters identified on the other fold (the
    README's identified columns and means, 0.33 / 0.35 deg)."""
    from uvms_mj.analysis.identify import folds, run_trials

    scores = {}
    for k, part in enumerate(folds(list(real_trials.trials), 2), 1):
        over = s2r.load_overrides(IDENTIFIED / f"identified.fold{k}.yaml")
        res = run_trials([real_trials[n] for n in part], overrides=over, cfg=s2r.SimConfig())
        scores.update({n: v[1] for n, v in res.items()})
    assert sorted(scores) == sorted(HEADLINE)
    _check_headline(scores, 2)


@needs_real
@pytest.mark.slow
def test_identify_objective_at_the_stored_fold(real_trials):
    """The fit itself takes minutes (30 evaluations of 9 trials and their Jacobians, twice), so
    only its end is checked, along its best-determined parameter: from fold 1's stored
    parameters, identify's objective on fold 1's fit trials (the other fold; 0.01 s step) is the
    fit RMS it reported (0.3859 deg, docs/sim2real/identify-cv2.json; to 0.001 deg, set like the
    pins above), and a step in cob_z (the metacentric height) finds no better point: the cost
    falls by < 0.001 deg and cob_z moves by < 0.1 of its standard deviation (1.0 mm)."""
    from uvms_mj.analysis.identify import folds

    fit = folds(list(real_trials.trials), 2)[1]  # fold 1's parameters were fitted on fold 2's trials
    stored = s2r.load_overrides(IDENTIFIED / "identified.fold1.yaml")
    cob_z = stored["bluerov2.cob"][2]
    r = identify(real_trials.trials, fit=fit, names=["cob_z"], base=stored, cfg=s2r.SimConfig(dt=0.01), fit_dt=None,
                 max_nfev=2)
    assert r.nominal == [cob_z]
    assert r.cost0 == pytest.approx(0.3859, abs=1e-3)
    assert r.cost > r.cost0 - 1e-3
    assert abs(r.value[0] - cob_z) < 0.1 * 0.001, (r.value, cob_z)
