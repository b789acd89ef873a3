"""The navigation sensors (uvms_mj.sim.navsensors) against independent truths: closed forms of the
specific force and angular rate at a lever arm, the velocity of a point of a rigid body, a ray's
intersection with a plane, hydrostatic pressure; their timing and random streams; the scenario
section and the MCAP channels.

Tolerances: with the noise off every sensor is a few floating-point operations on MuJoCo's own
state (sensors, rays), so its error is rounding, ~1e-15 relative; 1e-9 leaves a wide margin
without hiding any modelling error (a wrong lever arm, frame or time is >= 1e-3 here). The
depth sensor quantizes the pressure: it is within half a resolution step (1.02 mm) of the truth.
"""

from __future__ import annotations

import math
from pathlib import Path

import mujoco
import numpy as np
import pytest

from uvms_mj.plant.layout import InitialState
from uvms_mj.plant.plant import Plant
from uvms_mj.rotations import quat_from_rpy, quat_to_mat
from uvms_mj.sim.navsensors import (DepthConfig, DvlConfig, FixConfig, ImuConfig, NavigationConfig, NavigationSuite,
                                    add_to_spec)

TOL = 1e-9

#: A neutrally buoyant box (10 kg, 0.01 m^3 of water, centre of buoyancy at the CG: no net force or
#: moment at rest), principal inertia diag(0.2, 0.3, 0.4), with a sensor site at a lever arm each.
BOX = """<mujoco model="nav_box">
  <option timestep="0.004" integrator="implicitfast" gravity="0 0 -9.81" density="0" viscosity="0">
    <flag contact="disable"/>
  </option>
  <extension>
    <plugin plugin="uvms.hydro"/>
    <plugin plugin="uvms.water"><instance name="water"><config key="density" value="1000"/></instance></plugin>
  </extension>
  <worldbody>
    <body name="box" pos="0 0 -2">
      <freejoint name="box"/>
      <inertial pos="0 0 0" mass="10" diaginertia="0.2 0.3 0.4"/>
      <plugin plugin="uvms.hydro"><config key="volume" value="0.01"/><config key="cob" value="0 0 0"/></plugin>
      <geom type="box" size="0.1 0.1 0.1" mass="0" contype="0" conaffinity="0"/>
      <site name="box_imu" pos="0.3 -0.2 0.1" euler="30 20 10"/>
      <site name="box_dvl" pos="-0.1 0.05 -0.12" euler="180 0 15"/>
      <site name="box_depth" pos="0.05 0.02 0.07"/>
      <site name="box_usbl" pos="-0.1 0 0.12"/>
    </body>
  </worldbody>
</mujoco>
"""

QUIET_IMU = ImuConfig(gyro_noise=0, gyro_bias_walk=0, accel_noise=0, accel_bias_walk=0, rate=125.0)
QUIET_DVL = DvlConfig(beam_noise=0, resolution=0, latency=0.05)
QUIET_FIX = FixConfig(noise=0, range_noise=0, outlier_probability=0, yaw=True)


@pytest.fixture(scope="module")
def box(tmp_path_factory) -> Path:
    p = tmp_path_factory.mktemp("nav") / "box.xml"
    p.write_text(BOX)
    return p


def _plant(path, cfg, seed=0, **kw) -> tuple[Plant, NavigationSuite]:
    p = Plant(path, spec_edits=[add_to_spec(cfg)], **kw)
    return p, NavigationSuite(p.model, p.data, cfg, seed, p.layout.base_body, float(p.hydro_info.water.density))


def _site(plant, name) -> tuple[np.ndarray, np.ndarray]:
    """(position in the body frame, rotation body <- site) of a site, from the model file's numbers."""
    sid = plant.model.site(name).id
    return plant.model.site_pos[sid].copy(), quat_to_mat(plant.model.site_quat[sid])


def test_imu_at_rest_reads_plus_g_up_and_zero_rate(box):
    q = quat_from_rpy(0.3, -0.2, 1.1)
    plant, nav = _plant(box, NavigationConfig(imu=QUIET_IMU), initial=InitialState(quat=tuple(q)))
    nav.advance(plant.step_observe, 40)
    assert len(nav.record.imu) == 20  # 125 Hz: every 2nd step of 4 ms, steps 0, 2, ..., 38
    R_site = quat_to_mat(q) @ _site(plant, "box_imu")[1]  # world <- site
    f = R_site.T @ np.array([0.0, 0.0, 9.81])  # specific force at rest: -gravity, in the site frame
    for s in nav.record.imu:
        np.testing.assert_allclose(s.acc, f, atol=TOL * 10)
        np.testing.assert_allclose(s.gyro, 0.0, atol=TOL)


def test_imu_on_spinning_vehicle_reads_centripetal_at_lever_arm(box):
    w = 2.0  # [rad/s] about the box's principal z axis: torque-free, constant (Euler's equations)
    plant, nav = _plant(box, NavigationConfig(imu=QUIET_IMU), gravity=False,
                        initial=InitialState(angular_velocity=(0.0, 0.0, w)))
    nav.advance(plant.step_observe, 100)
    r, R = _site(plant, "box_imu")
    omega = np.array([0.0, 0.0, w])
    a = np.cross(omega, np.cross(omega, r))  # body frame, = -w^2 (r_x, r_y, 0)
    for s in nav.record.imu:
        np.testing.assert_allclose(s.acc, R.T @ a, atol=TOL)
        np.testing.assert_allclose(s.gyro, R.T @ omega, atol=TOL)
    assert np.linalg.norm(a) == pytest.approx(w * w * math.hypot(0.3, 0.2))


def test_imu_noise_and_bias_walk_have_their_allan_parameters(box):
    """At rest the truth is constant, so reading the same state many times gives the noise alone:
    std N sqrt(rate) per sample, bias increments of std K sqrt(1/rate) (4 x 3 x 4000 draws: the
    std estimates are within 3 % at about 4 sigma)."""
    cfg = ImuConfig(gyro_noise=1e-3, gyro_bias_walk=2e-4, accel_noise=2e-3, accel_bias_walk=1e-3, rate=125)
    plant, nav = _plant(box, NavigationConfig(imu=cfg))
    mujoco.mj_forward(plant.model, plant.data)
    g0 = plant.data.sensordata[nav.adr["imu"]["gyro"]:nav.adr["imu"]["gyro"] + 3].copy()
    for s in range(0, 2 * 4000, 2):
        nav.read(s)
    rec = nav.record
    gyro = np.array([x.gyro for x in rec.imu]) - g0 - np.array(rec.imu_gyro_bias)
    assert np.std(gyro) == pytest.approx(1e-3 * math.sqrt(125), rel=0.03)
    db = np.diff(np.array(rec.imu_accel_bias), axis=0)
    assert np.std(db) == pytest.approx(1e-3 * math.sqrt(1 / 125), rel=0.03)


def _rigid_site_truth(q, qd, r, R_mount):
    """(position world, velocity in the site frame) of a site at body point r on a free body with
    qpos q (x, y, z, quat) and qvel qd (linear world, angular body): v = v_o + R (w x r)."""
    Rb = quat_to_mat(q[3:7])
    v = qd[:3] + Rb @ np.cross(qd[3:6], r)
    return q[:3] + Rb @ r, (Rb @ R_mount).T @ v, Rb @ R_mount


def _dvl_at(plant, nav, q, qd):
    plant.set_state(qpos=q, qvel=qd)  # mj_forward: the sensors of this state
    nav.read(0)
    return nav.record.dvl[-1], nav.record.dvl_ranges[-1]


def test_dvl_over_flat_seabed_recovers_the_site_velocity_and_ranges(box):
    cfg = NavigationConfig(dvl=QUIET_DVL, seabed_depth=12.0)
    plant, nav = _plant(box, cfg)
    r, Rm = _site(plant, "box_dvl")
    q = np.concatenate(([1.0, -2.0, -3.0], quat_from_rpy(0.15, -0.1, 0.7)))
    qd = np.array([0.3, -0.2, 0.1, 0.2, -0.3, 0.4])
    sample, ranges = _dvl_at(plant, nav, q, qd)
    p, v_site, Rws = _rigid_site_truth(q, qd, r, Rm)
    assert sample.beams_valid == (True,) * 4 and sample.t_arrival == pytest.approx(0.05)
    np.testing.assert_allclose(sample.velocity, v_site, atol=TOL)
    for rng, b in zip(ranges, nav.beams):  # the ray p + x d meets the plane z = -12 at x = (p_z + 12) / -d_z
        d = Rws @ b
        assert rng == pytest.approx((p[2] + 12.0) / -d[2], rel=TOL)


def test_dvl_degrades_to_three_beams_and_drops_out(box):
    cfg = NavigationConfig(dvl=QUIET_DVL, seabed_depth=12.0)
    plant, nav = _plant(box, cfg)
    r, Rm = _site(plant, "box_dvl")
    q = np.concatenate(([0.0, 0.0, -3.0], quat_from_rpy(0.2, 0.25, 0.0)))
    qd = np.array([0.1, 0.2, -0.05, 0.1, 0.0, -0.2])
    _, ranges = _dvl_at(plant, nav, q, qd)
    alt = ranges * math.cos(QUIET_DVL.beam_angle)
    # a max altitude between the longest beam's and the others': that beam is lost, 3 remain
    lim = 0.5 * (np.sort(alt)[-1] + np.sort(alt)[-2])
    nav.sensors["dvl"] = nav.config.dvl.__class__(beam_noise=0, resolution=0, max_altitude=float(lim))
    sample, _ = _dvl_at(plant, nav, q, qd)
    assert sum(sample.beams_valid) == 3 and not sample.beams_valid[int(np.argmax(alt))]
    np.testing.assert_allclose(sample.velocity, _rigid_site_truth(q, qd, r, Rm)[1], atol=TOL)
    # above the maximum altitude: every beam lost, a dropout
    nav.sensors["dvl"] = nav.config.dvl.__class__(beam_noise=0, max_altitude=float(np.min(alt) - 0.1))
    sample, _ = _dvl_at(plant, nav, q, qd)
    assert sample.velocity is None and not any(sample.beams_valid)
    # pitched 80 deg: two beams point above the horizon and miss the seabed; 2 beams cannot solve it
    nav.sensors["dvl"] = QUIET_DVL
    q2 = np.concatenate(([0.0, 0.0, -3.0], quat_from_rpy(0.0, math.radians(80), 0.0)))
    sample, ranges = _dvl_at(plant, nav, q2, qd)
    assert sample.velocity is None and sum(sample.beams_valid) == 2 and np.isnan(ranges).sum() == 2
    # an outage: a dropout whatever the geometry
    nav.sensors["dvl"] = DvlConfig(beam_noise=0, outages=((0.0, 1.0),))
    sample, _ = _dvl_at(plant, nav, q, qd)
    assert sample.velocity is None


def test_depth_is_minus_z_of_the_site_within_the_resolution(box):
    plant, nav = _plant(box, NavigationConfig(depth=DepthConfig(noise=0)))
    r, _ = _site(plant, "box_depth")
    half = 0.5 * 20.0 / (1000.0 * 9.81)  # half a 20 Pa step, in metres of water
    for z, rpy in ((-2.0, (0, 0, 0)), (-7.3, (0.4, -0.3, 2.0)), (-0.2, (0.1, 0.2, 0.3))):
        q = np.concatenate(([0.5, 0.2, z], quat_from_rpy(*rpy)))
        plant.set_state(qpos=q, qvel=np.zeros(6))
        nav.read(0)
        truth = -(q[:3] + quat_to_mat(q[3:7]) @ r)[2]
        assert abs(nav.record.depth[-1].depth - truth) <= half + 1e-12
    nav.sensors["depth"] = DepthConfig(noise=0, resolution=0, density=1025.0)  # a seawater conversion in fresh water
    nav.read(0)
    assert nav.record.depth[-1].depth == pytest.approx(truth * 1000.0 / 1025.0, rel=TOL)


@pytest.mark.parametrize("integrator", ["implicitfast", "rk4", "euler"])
def test_fix_rate_latency_position_and_yaw(box, integrator):
    """Also the time of a sample: MuJoCo's sensors hold the state at the start of the last step
    with every integrator, so a sample of step s, read after step s + 1, is the state at s dt."""
    cfg = NavigationConfig(fix=FixConfig(noise=0, range_noise=0, outlier_probability=0, yaw=True, rate=2.0,
                                         latency=0.25))
    v = np.array([0.2, -0.1, 0.05])  # no gravity, no forces: constant velocity, so p(t) = p0 + v t
    plant, nav = _plant(box, cfg, gravity=False, integrator=integrator,
                        initial=InitialState(position=(0, 0, -2), linear_velocity=tuple(v),
                                             quat=tuple(quat_from_rpy(0, 0, 0.6))))
    nav.advance(plant.step_observe, 800)  # 3.2 s
    fixes = nav.record.fix
    assert [f.t for f in fixes] == pytest.approx([0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0])
    r, _ = _site(plant, "box_usbl")
    for f in fixes:
        assert f.t_arrival - f.t == pytest.approx(0.25)
        truth = np.array([0, 0, -2.0]) + v * f.t + quat_to_mat(quat_from_rpy(0, 0, 0.6)) @ r
        np.testing.assert_allclose(f.position, truth, atol=TOL)
        assert f.yaw == pytest.approx(0.6, abs=TOL)


def _noisy_fixes(box, seed, n=400):
    cfg = NavigationConfig(fix=FixConfig(rate=250.0, outlier_probability=0.1), imu=ImuConfig())
    plant, nav = _plant(box, cfg, seed=seed)
    mujoco.mj_forward(plant.model, plant.data)
    for s in range(n):
        nav.read(2 * s)
    return nav.record


def test_fixes_and_imu_are_deterministic_per_seed_with_outliers(box):
    a, b, c = _noisy_fixes(box, 7), _noisy_fixes(box, 7), _noisy_fixes(box, 8)
    pa = np.array([f.position for f in a.fix])
    assert np.array_equal(pa, np.array([f.position for f in b.fix]))  # the same draws, the same arithmetic
    assert np.array_equal(np.array([s.gyro for s in a.imu]), np.array([s.gyro for s in b.imu]))
    assert not np.allclose(pa, np.array([f.position for f in c.fix]))
    # outliers: about 10 % (binomial, 400 draws: 40 +- 6), each with an error of 1 m std per axis
    n_out = sum(a.fix_outlier)
    assert 20 <= n_out <= 60
    err = np.linalg.norm(pa - pa[~np.array(a.fix_outlier)].mean(axis=0), axis=1)
    assert np.median(err[np.array(a.fix_outlier)]) > 10 * np.median(err[~np.array(a.fix_outlier)])


# --------------------------------------------------------------------------- scenario and log


def _scenario(**nav):
    from uvms_mj.scenario.document import Scenario

    base = {"name": "nav", "robot": "bluerov2_alpha", "duration": 1.0, "controller": {"name": "station_pid"},
            "initial": {"position": [0, 0, -1], "joints": {"alpha_shoulder": 90, "alpha_elbow": 90}},
            "plant": {"seabed_depth": 10.0}, "outputs": {"plots": False}}
    base.update(nav)
    return Scenario.model_validate(base)


@pytest.mark.parametrize("nav, plant, words", [
    ({"imu": {"site": "bluerov2_imux"}}, None, ["navigation.imu.site", "did you mean 'bluerov2_imu'"]),
    ({"depth": {"rate": 20}}, None, ["navigation.depth.rate", "whole number of plant steps"]),
    ({"dvl": {}}, {}, ["navigation.dvl", "plant.seabed_depth"]),
    ({"fix": {"outlier_probability": 2}}, None, ["navigation.fix.outlier_probability"]),
    ({"imu": {"gyro_nois": 1}}, None, ["navigation.imu.gyro_nois"]),
])
def test_scenario_errors_name_the_field(nav, plant, words):
    from uvms_mj.scenario.base import ScenarioError
    from uvms_mj.scenario.schema import validate_scenario

    d = _scenario().model_dump(mode="json", exclude_none=True)
    d["navigation"] = nav
    if plant is not None:
        d["plant"] = plant
    with pytest.raises(ScenarioError) as e:
        validate_scenario(d, "nav.yaml")
    for w in words:
        assert w in str(e.value)


def test_paper_robot_refuses_navigation_in_one_line():
    from uvms_mj.scenario.base import ScenarioError
    from uvms_mj.scenario.schema import validate_scenario

    with pytest.raises(ScenarioError) as e:
        validate_scenario({"name": "p", "navigation": {"imu": {}}}, "p.yaml")
    lines = [x for x in str(e.value).splitlines() if "navigation" in x]
    assert len(lines) == 1 and "free vehicle" in lines[0]


def test_scenario_run_logs_the_channels_and_leaves_the_physics_alone(tmp_path):
    from uvms_mj.io.nav_channels import NAV_TOPICS, read_navigation
    from uvms_mj.io.reader import iter_messages
    from uvms_mj.io.writer import McapRecorder
    from uvms_mj.scenario.schema import build, run_scenario

    sc = _scenario(navigation={"imu": {}, "dvl": {}, "depth": {}, "fix": {"yaw": True}})  # the IMU at every step
    plant, ctrl = build(sc)
    log = tmp_path / "nav.mcap"
    with McapRecorder(log, None, {}, model=plant.model) as rec:
        res = run_scenario(sc, sink=rec.write_sample, nav_sink=rec.write_navigation, built=(plant, ctrl))
        rec.close(res.status, res.reason, meta=res.meta)
    nav = res.navigation
    assert len(nav.imu) == 250 and len(nav.dvl) == 5 and len(nav.depth) == 25 and len(nav.fix) == 1
    assert nav.sites == {"imu": "bluerov2_imu", "dvl": "bluerov2_dvl", "depth": "bluerov2_depth",
                         "fix": "bluerov2_usbl"}
    back = read_navigation(log)
    assert np.array_equal(np.array([s.acc for s in back.imu]), np.array([s.acc for s in nav.imu]))
    assert [s.t_arrival for s in back.dvl] == [s.t_arrival for s in nav.dvl]
    assert back.mounts["dvl"].quat == pytest.approx(np.array([0.0, 1.0, 0.0, 0.0]))
    times = {}
    for ch, _, msg in iter_messages(log):
        if ch.topic in NAV_TOPICS:
            times.setdefault(ch.topic, []).append(msg.log_time)
    assert times["/navigation/fix"] == [300_000_000]  # logged at its arrival: t = 0 + 0.3 s latency
    # the same run without the sensors: the same trajectory (the sensors only read the state; the
    # same mj_step sequence, split where they are read: equal to rounding, 1e-12 m or rad)
    bare = run_scenario(_scenario(plant={}))
    np.testing.assert_allclose(bare.signals["q_true"], res.signals["q_true"], rtol=0, atol=1e-12)
