"""Recorded trials (uvms_mj.analysis.trials) and the hydrostatic static check (uvms_mj.analysis.hydrostatics).

Truths: the raw CSV text (a known row of a real file), hand-made synthetic folders (the expected
de-duplication and the file:line of each defect), and for the equilibrium a hand computation on
a small synthetic model (sums of point forces, closed-form angles), independent of the solver.
The real data are shipped in the repository (data/hinsdale-2023, the 18 trials with their MIT
licence; UVMS_MJ_HINSDALE points elsewhere): those tests skip only when the folder is absent
(an sdist or wheel, which leave data/ out).
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest

import uvms_mj  # noqa: F401  (the plugins: registered once by conftest.py)
from uvms_mj.physics import load_model
from uvms_mj.analysis.trials import JOINT_NAMES, load_trials, lowpass, roll_pitch_yaw

pytest.importorskip("scipy")
from uvms_mj.analysis.hydrostatics import equilibrium_attitude, hydrostatic_moment, static_check  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
MODEL = REPO / "models" / "hinsdale2023" / "hinsdale2023.xml"
OFFSETS = np.array([3.07, 0.0, 0.0, 2.879])  # the model's numeric, stated independently


def hinsdale_dir() -> Path | None:
    env = os.environ.get("UVMS_MJ_HINSDALE")
    for cand in ([Path(env)] if env else []) + [REPO / "data" / "hinsdale-2023"]:
        for d in (cand / "trials", cand):
            if d.is_dir() and any(d.glob("*_imu.csv")):
                return d
    return None


REAL = hinsdale_dir()
needs_real = pytest.mark.skipif(REAL is None, reason="Hinsdale 2023 trials not found (set UVMS_MJ_HINSDALE)")


# ------------------------------------------------------------------------- synthetic folders

IMU_H = "time_secs,x_ori,y_ori,z_ori,w_ori,x_angvel,y_angvel,z_angvel,x_linacc,y_linacc,z_linacc"
JS_H = ("time_secs," + ",".join(f"axis_{a}_pos" for a in "abcde") + "," + ",".join(f"axis_{a}_vel" for a in "abcde"))
MC_H = "time_secs,x_pose,y_pose,z_pose,x_ori,y_ori,z_ori,w_ori,roll,pitch,yaw"


def imu_rows(n=40, dt=0.05, roll=0.05):
    # quaternion of a pure roll, scalar last
    s, c = math.sin(roll / 2), math.cos(roll / 2)
    return [f"{k * dt:.4f},{s},0,0,{c},0,0,0,0,0,9.81" for k in range(n)]


def js_rows(n=100, dt=0.02):
    # the value changes every 2nd row (a 25 Hz update in a 50 Hz stream)
    rows = []
    for k in range(n):
        u = k // 2
        pos = [0.0013, 1.6 + 0.001 * u, 0.03 + 0.001 * u, 0.08, 3.1]
        vel = [0, 0.05, 0.05, 0, 0]
        rows.append(f"{k * dt:.4f}," + ",".join(map(str, pos + vel)))
    return rows


def mc_rows(n=20, dt=0.1):
    return [f"{k * dt:.4f},1,2,0.3,0,0,0,1,0,0,0" for k in range(n)]


def write_trial(folder: Path, key: str, imu=None, js=None, mc=None, meta="start_time: 0.5\n",
                drop=()):
    folder.mkdir(exist_ok=True)
    files = {
        f"traj{key}_imu.csv": [IMU_H] + (imu_rows() if imu is None else imu),
        f"traj{key}_joint_states.csv": [JS_H] + (js_rows() if js is None else js),
        f"traj{key}_mocap.csv": [MC_H] + (mc_rows() if mc is None else mc),
    }
    for name, lines in files.items():
        if name[len(f"traj{key}_"):-len(".csv")] not in drop:
            (folder / name).write_text("\n".join(lines) + "\n")
    if meta is not None and "metadata" not in drop:
        (folder / f"metadata_{key}.yml").write_text(meta)


def only_issue(ts, trial, severity="error"):
    got = [i for i in ts.issues if i.trial == trial and i.severity == severity]
    assert len(got) == 1, ts.report()
    return got[0]


def test_synthetic_good_trial(tmp_path):
    write_trial(tmp_path, "001-0")
    ts = load_trials(tmp_path, offsets=OFFSETS)
    assert list(ts.trials) == ["001-0"] and not ts.skipped and not ts.issues, ts.report()
    tr = ts["001-0"]
    assert tr.start_time == 0.5
    np.testing.assert_allclose(tr.imu.roll, 0.05, atol=1e-12)
    np.testing.assert_allclose(tr.imu.pitch, 0.0, atol=1e-12)
    # de-duplication: the first row of each pair kept, at its own time and line
    np.testing.assert_allclose(tr.joints.t, np.arange(50) * 0.04, atol=1e-12)
    np.testing.assert_array_equal(tr.joints.lines, 2 + 2 * np.arange(50))
    assert tr.joints.n_rows == 100
    # mapping q = axis - offset (base e, shoulder d, elbow c, wrist b)
    np.testing.assert_allclose(tr.joints.q[3], [3.1 - 3.07, 0.08, 0.033, 1.603 - 2.879], atol=1e-12)
    assert tr.mocap is not None and len(tr.mocap.t) == 20


def test_dedup_keeps_velocity_only_updates(tmp_path):
    vel0, vel1 = "0,0,0,0,0", "0,0.1,0,0,0"
    pos0, pos1 = "0,1.6,0,0,3.07", "0,1.7,0,0,3.07"
    js = [f"0.00,{pos0},{vel0}", f"0.02,{pos0},{vel0}", f"0.04,{pos0},{vel0}",  # repeats
          f"0.05,{pos1},{vel0}", f"0.07,{pos1},{vel0}",                      # new position
          f"0.09,{pos1},{vel1}",                                             # new velocity only
          f"0.11,{pos0},{vel0}"]                                             # back: a change
    write_trial(tmp_path, "001-0", js=js)
    tr = load_trials(tmp_path, offsets=OFFSETS)["001-0"]
    np.testing.assert_allclose(tr.joints.t, [0.0, 0.05, 0.09, 0.11])
    np.testing.assert_array_equal(tr.joints.lines, [2, 5, 7, 8])


@pytest.mark.parametrize("case", ["missing_file", "missing_column", "nan_row", "empty_field", "unsorted",
                                  "repeated_time", "gap", "bad_metadata"])
def test_bad_data_reported_and_skipped(tmp_path, case):
    write_trial(tmp_path, "001-0")  # a good one next to it keeps loading
    imu, js = imu_rows(), js_rows()
    kw, file, line = {}, None, None
    if case == "missing_file":
        kw, file = {"drop": ("imu",)}, "traj002-0_imu.csv"
    elif case == "missing_column":
        kw, file, line = {"imu": imu}, "traj002-0_imu.csv", 1
    elif case == "nan_row":
        js[6] = js[6].replace("1.6", "nan", 1)
        kw, file, line = {"js": js}, "traj002-0_joint_states.csv", 8
    elif case == "empty_field":
        imu[9] = imu[9].replace(",0,0,0,", ",,0,0,", 1)
        kw, file, line = {"imu": imu}, "traj002-0_imu.csv", 11
    elif case == "unsorted":
        imu[4], imu[5] = imu[5], imu[4]
        kw, file, line = {"imu": imu}, "traj002-0_imu.csv", 7
    elif case == "repeated_time":
        js[10] = js[9].split(",", 1)[0] + "," + js[10].split(",", 1)[1]
        kw, file, line = {"js": js}, "traj002-0_joint_states.csv", 12
    elif case == "gap":
        js = js[:30] + [f"{float(r.split(',', 1)[0]) + 1.0:.4f},{r.split(',', 1)[1]}" for r in js[30:]]
        kw, file, line = {"js": js}, "traj002-0_joint_states.csv", 32
    elif case == "bad_metadata":
        kw, file = {"meta": "start: 1.0\n"}, "metadata_002-0.yml"
    write_trial(tmp_path, "002-0", **kw)
    if case == "missing_column":
        p = tmp_path / "traj002-0_imu.csv"
        p.write_text(p.read_text().replace(",z_ori,", ",zz_ori,", 1))
    ts = load_trials(tmp_path, offsets=OFFSETS)
    assert list(ts.trials) == ["001-0"], ts.report()
    assert list(ts.skipped) == ["002-0"]
    issue = only_issue(ts, "002-0")
    assert issue.file is not None and issue.file.name == file, ts.report()
    assert issue.line == line, ts.report()
    assert "002-0" in ts.report() and file in str(issue)
    if case == "missing_column":
        assert "z_ori" in issue.message


def test_bad_mocap_is_a_warning(tmp_path):
    mc = mc_rows()
    mc[3] = mc[3].replace(",1,2,", ",nan,2,", 1)
    write_trial(tmp_path, "002-0", mc=mc)
    gap = mc_rows()
    gap = gap[:10] + [f"{float(r.split(',', 1)[0]) + 2:.4f},{r.split(',', 1)[1]}" for r in gap[10:]]
    write_trial(tmp_path, "003-0", mc=gap)
    ts = load_trials(tmp_path, offsets=OFFSETS)
    assert set(ts.trials) == {"002-0", "003-0"} and not ts.skipped
    assert ts["002-0"].mocap is None
    w = [i for i in ts.issues if i.trial == "002-0"]
    assert w[0].severity == "warning" and w[0].file.name == "traj002-0_mocap.csv" and w[0].line == 5
    assert ts["003-0"].mocap is not None  # gaps are known in mocap: kept, reported
    g = only_issue(ts, "003-0", "warning")
    assert g.line == 12 and "gap" in g.message


def test_resample_and_lowpass():
    t = np.arange(0, 20, 0.01)
    slow = np.sin(2 * np.pi * 0.2 * t)
    fast = 0.1 * np.sin(2 * np.pi * 10 * t)
    y = lowpass(np.column_stack([slow + fast, slow]), 0.01, cutoff_hz=2.0)
    inner = slice(200, -200)  # away from the ends
    # 0.2 Hz: |H|^2 = 1 / (1 + (0.1)^4) -> 1e-4 relative; 10 Hz: (1 / (1 + 5^4)) -> 1.6e-3
    np.testing.assert_allclose(y[inner, 0], slow[inner], atol=2e-3)
    np.testing.assert_allclose(y[inner, 1], slow[inner], atol=2e-4)
    with pytest.raises(ValueError):
        lowpass(slow, 0.01, cutoff_hz=60.0)


def test_roll_pitch_of_quaternion():
    # vehicle -> world rotation Ry(pitch) Rx(roll) (Z-Y-X, yaw 0), as a quaternion x y z w
    r, p = 0.3, -0.2
    qx = np.array([math.sin(r / 2), 0, 0, math.cos(r / 2)])
    qy = np.array([0, math.sin(p / 2), 0, math.cos(p / 2)])

    def mul(a, b):  # Hamilton product, scalar last
        av, aw, bv, bw = a[:3], a[3], b[:3], b[3]
        return np.r_[aw * bv + bw * av + np.cross(av, bv), aw * bw - av @ bv]

    roll, pitch, yaw = roll_pitch_yaw(-mul(qy, qx))  # sign of q irrelevant
    np.testing.assert_allclose([roll, pitch, yaw], [r, p, 0.0], atol=1e-12)


# ------------------------------------------------------------------------------ real trials


@needs_real
def test_real_trials_load():
    ts = load_trials(REAL)
    assert not ts.skipped, ts.report()
    assert {"003-0", "baseline1"} <= set(ts.trials)
    for tr in ts:
        assert 19 < tr.joints.update_rate < 25  # positions update at about 21 Hz
        assert np.all(np.diff(tr.imu.t) > 0) and np.all(np.diff(tr.joints.t) > 0)
        assert (tr.start_time is None) == tr.name.startswith("baseline")
    # a known row: the first data row (line 2) of traj003-0_joint_states.csv
    line2 = (REAL / "traj003-0_joint_states.csv").read_text().splitlines()[1].split(",")
    axis = dict(zip(JS_H.split(","), map(float, line2)))
    js = ts["003-0"].joints
    assert js.lines[0] == 2 and js.t[0] == axis["time_secs"]
    np.testing.assert_array_equal(
        js.q[0], [axis["axis_e_pos"] - 3.07, axis["axis_d_pos"], axis["axis_c_pos"], axis["axis_b_pos"] - 2.879])
    assert js.names == JOINT_NAMES
    # baseline1 at rest: the IMU's median roll / pitch (docs: 3.97 and 1.41 deg)
    b = ts["baseline1"].imu
    assert math.degrees(np.median(b.roll)) == pytest.approx(3.97, abs=0.01)
    assert math.degrees(np.median(b.pitch)) == pytest.approx(1.41, abs=0.01)


@needs_real
def test_static_check_real():
    m = load_model(MODEL)
    ts = load_trials(REAL, model=m, names=["003-0", "012-0"])
    sc = static_check(m, ts)
    print("\n" + sc.table())
    assert len(sc.rows) == 2 and not sc.skipped
    for r in sc.rows:
        vals = np.r_[r.pred_pre, r.pred_post, r.meas_pre, r.meas_post]
        assert np.all(np.isfinite(vals)) and np.all(np.abs(vals) < 30)
    assert np.isfinite(sc.summary.rms_change["both"]) and np.isfinite(sc.summary.slope["both"])


# ------------------------------------------------------------------------ hydrostatic check

BOX = """
<mujoco model="hs_box">
  <option gravity="0 0 -9.81"/>
  <extension>
    <plugin plugin="uvms.water"><instance name="water"><config key="density" value="{rho}"/></instance></plugin>
    <plugin plugin="uvms.hydro"/>
  </extension>
  <worldbody>
    <body name="box">
      <freejoint/>
      <geom type="box" size="0.2 0.1 0.08" mass="{M}" contype="0" conaffinity="0"/>
      <plugin plugin="uvms.hydro">
        <config key="volume" value="{V}"/>
        <config key="cob" value="{cob}"/>
      </plugin>
      <body name="arm" pos="{p}">
        <joint name="turn" type="hinge" axis="0 0 1"/>
        <inertial pos="{l}" mass="{mp}" diaginertia="1e-6 1e-6 1e-6"/>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


def box_model(tmp_path, **kw):
    v = dict(rho=1000.0, M=10.0, V=0.0112, cob=(0.01, -0.02, 0.05), p=(0.1, 0.05, -0.02),
             l=(0.15, 0.0, 0.0), mp=1.5)
    v.update(kw)
    fmt = {k: " ".join(map(repr, x)) if isinstance(x, tuple) else repr(x) for k, x in v.items()}
    path = tmp_path / "box.xml"
    path.write_text(BOX.format(**fmt))
    return load_model(path), v


def hand_equilibrium(v, theta, about="root"):
    """Forces f_j (N, + up) at points r_j (vehicle frame): the box weight at its origin, the
    buoyancy at cob, the point mass at p + Rz(theta) l. Moment-free when the vehicle's up axis
    is along s = sum f_j (r_j - P): roll = atan2(s_y, s_z), pitch = atan2(-s_x, hypot(s_y, s_z))."""
    g = 9.81
    c, s_ = math.cos(theta), math.sin(theta)
    l = np.array(v["l"])
    r_mass = np.array(v["p"]) + np.array([c * l[0] - s_ * l[1], s_ * l[0] + c * l[1], l[2]])
    pts = np.array([[0, 0, 0], v["cob"], r_mass], float)
    f = np.array([-v["M"] * g, v["rho"] * v["V"] * g, -v["mp"] * g])
    if about == "root":
        P = np.zeros(3)
    else:  # total centre of mass
        P = (v["M"] * pts[0] + v["mp"] * pts[2]) / (v["M"] + v["mp"])
    s = (f[:, None] * (pts - P)).sum(0)
    return math.atan2(s[1], s[2]), math.atan2(-s[0], math.hypot(s[1], s[2]))


@pytest.mark.parametrize("theta", [0.0, 0.7, -2.0])
@pytest.mark.parametrize("about", ["root", "com"])
def test_equilibrium_against_hand(tmp_path, theta, about):
    m, v = box_model(tmp_path)
    e = equilibrium_attitude(m, {"turn": theta}, about=about)
    hand = hand_equilibrium(v, theta, about)
    assert abs(e.roll - hand[0]) < 1e-9 and abs(e.pitch - hand[1]) < 1e-9, (e, hand)
    assert e.residual < 1e-10
    assert e.net_force == pytest.approx(9.81 * (1000 * 0.0112 - 11.5), rel=1e-12)
    # and the moment there vanishes about that point, also in MuJoCo's own evaluation
    assert np.abs(hydrostatic_moment(m, {"turn": theta}, e.roll, e.pitch, about)[:2]).max() < 1e-10
    # com and cob give the same attitude (the pure couple); root differs as F_net != 0
    if about == "com":
        e2 = equilibrium_attitude(m, {"turn": theta}, about="cob")
        assert abs(e2.roll - e.roll) < 1e-9 and abs(e2.pitch - e.pitch) < 1e-9


def test_equilibrium_unstable_rejected(tmp_path):
    # buoyancy below the weight: the upright state is unstable
    m, _ = box_model(tmp_path, cob=(0.0, 0.0, -0.2), mp=1e-3)
    with pytest.raises(RuntimeError):
        equilibrium_attitude(m, {"turn": 0.0})


def test_equilibrium_hinsdale_rest():
    """The model file states its rest attitude at the keyframe baseline1: 3.90, 1.78 deg."""
    m = load_model(MODEL)
    q = m.key("baseline1").qpos[7:]
    e = equilibrium_attitude(m, dict(zip(JOINT_NAMES, q)))
    assert math.degrees(e.roll) == pytest.approx(3.90, abs=0.005)
    assert math.degrees(e.pitch) == pytest.approx(1.78, abs=0.005)
