"""Desired 3-D end-effector trajectories (uvms_mj.control.trajectories) against independent truths.

Truths: central finite differences of the position, closed forms (circle speed and centripetal
acceleration, helix pitch, minimum-jerk peak speed, the lemniscate of Gerono's implicit equation
and its points at known phases), exact boundary conditions, a CSV round trip of a sampled circle,
and the planar StraightLine. Tolerances are stated next to each assertion.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from uvms_mj.control.trajectories import (
    Circle,
    CsvTrajectory,
    Helix,
    Lemniscate,
    Line3D,
    Trajectory,
    Waypoints,
    make_trajectory,
    min_jerk,
    write_csv,
)
from oracles.planar.trajectory import StraightLine

EPS = np.finfo(float).eps

#: Finite-difference step [s]. A central difference of x errs by at most h^2/6 max|x'''| (truncation)
#: plus ~eps max|x|/h (rounding); x is p for the velocity and v for the acceleration, so jerk and
#: snap enter. The largest snap below is in the min-jerk segments, 360 L/T^4 <= 200 m/s^4
#: (L = 1.12 m, T = 1.2 s); |p|, |v| <= 3. With h = 5e-6 the error is
#: <= 2.5e-11/6 * 200 + 2.2e-16 * 3/5e-6 ~ 1e-9 (observed <= 9.5e-10); we assert 1e-8 (10x margin).
H = 5e-6
FD_TOL = 1e-8


def _cases() -> dict[str, tuple[Trajectory, list[float]]]:
    """name -> (trajectory, times at which the derivatives may jump: kept > 10 H away)."""
    line = Line3D(start=(0.1, -0.2, 0.3), target=(1.1, 0.5, -0.4), cruise_speed=0.3, accel=0.5, t_start=0.5)
    v, tr, tc = line.profile
    wp = Waypoints(points=[(0, 0, 0), (1, 0, 0), (1, 1, 0.5), (0, 1, 1)], durations=[1.5, 2.0, 1.2], t_start=0.3)
    circ = Circle(centre=(0.2, -0.1, 1.0), radius=0.5, normal=(1, 1, 1), period=4.0, phase=0.3, t_ramp=1.5, t_start=0.2)
    lem = Lemniscate(centre=(0, 0, -1), size=0.8, normal=(0, 1, 0), omega=-1.2, phase=0.1, t_ramp=2.0, t_start=0.4)
    hel = Helix(centre=(0, 0, 0), radius=0.3, normal=(0, 0, 1), omega=2.0, axial_speed=0.05, t_ramp=1.0)
    return {
        "line": (line, [0.5, 0.5 + tr, 0.5 + tr + tc, line.duration]),
        "waypoints": (wp, list(wp.knots)),
        "circle": (circ, [0.2, 1.7]),
        "lemniscate": (lem, [0.4, 2.4]),
        "helix": (hel, [0.0, 1.0]),
    }


@pytest.mark.parametrize("name", list(_cases()))
def test_derivatives_match_central_differences(name: str) -> None:
    traj, kinks = _cases()[name]
    t = np.linspace(-0.5, traj.duration + 3.0, 801)
    t = t[np.min(np.abs(t[:, None] - np.asarray(kinks)[None, :]), axis=1) > 10 * H]
    v_fd = (traj.position(t + H) - traj.position(t - H)) / (2 * H)
    a_fd = (traj.velocity(t + H) - traj.velocity(t - H)) / (2 * H)
    np.testing.assert_allclose(traj.velocity(t), v_fd, rtol=0, atol=FD_TOL)
    np.testing.assert_allclose(traj.acceleration(t), a_fd, rtol=0, atol=FD_TOL)


@pytest.mark.parametrize("name", list(_cases()))
def test_scalar_and_vectorised_agree(name: str) -> None:
    traj, _ = _cases()[name]
    t = np.linspace(-1.0, traj.duration + 2.0, 12).reshape(3, 4)
    for f in (traj.position, traj.velocity, traj.acceleration):
        batch = f(t)
        assert batch.shape == (3, 4, 3)
        single = np.array([[f(float(x)) for x in row] for row in t])
        assert f(0.7).shape == (3,)
        # same formulas; only the BLAS summation order of the plane-to-world product may differ (1 ulp)
        np.testing.assert_allclose(batch, single, rtol=0, atol=4 * EPS)


# --------------------------------------------------------------------------- Line3D


@pytest.mark.parametrize(
    "kw",
    [
        dict(start=(0.1, -0.3), target=(0.4, -0.3)),  # the paper line, defaults
        dict(start=(0.0, 0.0), target=(-0.7, 1.3), cruise_speed=0.2, accel=0.05, t_start=0.0),
        dict(start=(1.0, 2.0), target=(1.01, 2.02), cruise_speed=0.5, accel=0.1, t_start=2.0),  # triangular
        dict(start=(0.5, 0.5), target=(0.5, 0.5)),  # zero length
    ],
)
def test_line3d_in_the_plane_equals_straight_line(kw: dict) -> None:
    ref = StraightLine(**kw)
    line = Line3D(**{**kw, "start": (*kw["start"], 0.0), "target": (*kw["target"], 0.0)})
    assert line.duration == pytest.approx(ref.duration, abs=1e-12)
    t = np.r_[np.linspace(-1.0, ref.duration + 2.0, 997), ref.t_start, ref.duration]
    p = line.position(t)
    p_ref = np.array([ref.position(x) for x in t])
    np.testing.assert_allclose(p[:, :2], p_ref, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(p[:, 2], 0.0)
    # the cruise velocity StraightLine hands the base
    np.testing.assert_allclose(line.profile[0] * line.direction[:2], ref.cruise_velocity(), rtol=0, atol=1e-12)


@pytest.mark.parametrize(
    "kw",
    [
        dict(start=(0.1, -0.3), target=(0.4, -0.3)),
        dict(start=(0.0, 0.0), target=(-0.7, 1.3), cruise_speed=0.2, accel=0.05, t_start=0.0),
        dict(start=(1.0, 2.0), target=(1.01, 2.02), cruise_speed=0.5, accel=0.1, t_start=2.0),  # triangular
        dict(start=(0.5, 0.5), target=(0.5, 0.5)),  # zero length
    ],
)
def test_straight_line_positions_are_position_bit_for_bit(kw: dict) -> None:
    """The block evaluation a sampled controller reads (StraightLine.positions) gives position(t)
    at each time exactly (compared as bit patterns, so -0.0 and 0.0 differ): at the samples of
    60 Hz, before the start, on every phase boundary and after the end."""
    ref = StraightLine(**kw)
    _, tr, tc = ref._profile()
    t = np.r_[np.arange(-30, 1200) / 60.0, ref.t_start, ref.t_start + tr, ref.t_start + tr + tc, ref.duration, 1e9]
    got = ref.positions(t)
    want = np.array([ref.position(float(x)) for x in t])
    assert got.shape == want.shape == (t.size, 2)
    # Exact is sound here, unlike the sin/cos paths: positions() does only +, - and * on each
    # element, each correctly rounded by IEEE 754 whether numpy runs it in SIMD lanes or not
    # (no transcendental function, no reduction), in the order position() does.
    np.testing.assert_array_equal(got.view(np.int64), want.view(np.int64))


def test_line3d_trapezoid_closed_form() -> None:
    line = Line3D(start=(0, 0, 0), target=(0, 0, 2.0), cruise_speed=0.5, accel=0.25, t_start=1.0)
    v, tr, tc = line.profile
    assert (v, tr) == (0.5, 2.0) and tc == pytest.approx(2.0, abs=1e-15)  # (2 - 0.5*2)/0.5
    np.testing.assert_allclose(line.velocity(1.0 + tr + 0.5 * tc), [0, 0, 0.5], atol=1e-15)
    np.testing.assert_allclose(line.acceleration(1.5), [0, 0, 0.25], atol=1e-15)
    np.testing.assert_allclose(line.acceleration(line.duration - 0.5), [0, 0, -0.25], atol=1e-15)
    np.testing.assert_array_equal(line.position(line.duration + 1), [0, 0, 2.0])
    np.testing.assert_array_equal(line.velocity(line.duration + 1), 0.0)


# --------------------------------------------------------------------------- Waypoints


def test_min_jerk_profile_boundaries_and_peak() -> None:
    s, ds, dds = min_jerk(np.array([0.0, 0.5, 1.0]))
    np.testing.assert_array_equal(s, [0.0, 0.5, 1.0])
    np.testing.assert_array_equal(ds[[0, 2]], 0.0)
    np.testing.assert_array_equal(dds[[0, 2]], 0.0)
    assert ds[1] == 1.875 and dds[1] == 0.0  # exact in binary


def test_waypoints_boundary_conditions_exact() -> None:
    pts = [(0.1, 0.2, 0.3), (1.0, -0.5, 0.7), (1.3, 0.4, -0.2), (-0.2, 0.0, 0.0)]
    wp = Waypoints(points=pts, durations=[1.0, 0.7, 2.3], t_start=0.5)
    np.testing.assert_array_equal(wp.knots, 0.5 + np.cumsum([0.0, 1.0, 0.7, 2.3]))
    # exactly at each waypoint, exactly at rest, before, at and after
    np.testing.assert_array_equal(wp.position(wp.knots), np.asarray(pts))
    np.testing.assert_array_equal(wp.velocity(wp.knots), 0.0)
    np.testing.assert_array_equal(wp.acceleration(wp.knots), 0.0)
    np.testing.assert_array_equal(wp.position([0.0, 100.0]), np.asarray([pts[0], pts[-1]]))
    np.testing.assert_array_equal(wp.velocity([0.0, 100.0]), 0.0)
    assert wp.duration == wp.knots[-1]


def test_waypoints_peak_speed_is_1_875_L_over_T_at_the_middle() -> None:
    pts = np.array([(0, 0, 0), (0.6, 0.8, 0.0), (0.6, 0.8, 2.0)])
    T = np.array([2.0, 4.0])
    wp = Waypoints(points=pts, durations=T)
    L = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    for i in range(2):
        mid = wp.knots[i] + T[i] / 2
        speed_mid = np.linalg.norm(wp.velocity(mid))
        assert speed_mid == pytest.approx(1.875 * L[i] / T[i], rel=1e-14)
        grid = np.linspace(wp.knots[i], wp.knots[i + 1], 2001)
        assert np.max(np.linalg.norm(wp.velocity(grid), axis=1)) <= speed_mid * (1 + 1e-14)
        # the tip is halfway along the segment at the middle (s(1/2) = 1/2)
        np.testing.assert_allclose(wp.position(mid), 0.5 * (pts[i] + pts[i + 1]), atol=1e-15)


def test_waypoints_cruise_speed_sets_durations() -> None:
    pts = [(0, 0, 0), (0.3, 0, 0), (0.3, 0.4, 0)]
    wp = Waypoints(points=pts, cruise_speed=0.1)
    np.testing.assert_allclose(wp.segment_durations, 1.875 * np.array([0.3, 0.4]) / 0.1, rtol=1e-15)
    t = np.linspace(0, wp.duration, 4001)
    assert np.max(np.linalg.norm(wp.velocity(t), axis=1)) == pytest.approx(0.1, rel=1e-6)


# --------------------------------------------------------------------------- Circle, Helix


def test_circle_closed_forms_once_steady() -> None:
    r, T = 0.4, 5.0
    omega = 2 * math.pi / T
    c = Circle(centre=(1.0, 2.0, 3.0), radius=r, normal=(0, -2, 1), period=T, phase=0.7, t_ramp=2.0, t_start=1.0)
    u, v, n = c.basis
    np.testing.assert_allclose([u @ v, u @ n, v @ n, np.linalg.norm(np.cross(u, v) - n)], 0, atol=1e-15)
    np.testing.assert_allclose(n, np.array([0, -2, 1]) / math.sqrt(5), atol=1e-15)
    t = np.linspace(c.duration, c.duration + 2 * T, 301)
    p, vel, acc = c.position(t) - c.centre, c.velocity(t), c.acceleration(t)
    np.testing.assert_allclose(np.linalg.norm(p, axis=1), r, rtol=1e-14)  # on the circle
    np.testing.assert_allclose(p @ n, 0, atol=1e-15)  # in the plane
    np.testing.assert_allclose(np.linalg.norm(vel, axis=1), omega * r, rtol=1e-14)  # |v| = omega r
    np.testing.assert_allclose(acc, -(omega**2) * p, rtol=0, atol=1e-14)  # a = -omega^2 (p - c)
    # periodic; phase after the ramp = phase + omega (t - t_start - t_ramp/2)
    np.testing.assert_allclose(c.position(t + T), c.position(t), atol=1e-14)
    th = 0.7 + omega * (t - 1.0 - 1.0)
    np.testing.assert_allclose(p, r * (np.cos(th)[:, None] * u + np.sin(th)[:, None] * v), atol=1e-14)
    assert c.cycle_period == T and c.angular_rate == omega


def test_circle_smooth_start_from_rest() -> None:
    c = Circle(centre=(0, 0, 0), radius=1.0, omega=-3.0, phase=1.0, t_ramp=2.0, t_start=0.5)
    u, v, _ = c.basis
    rest = np.array([0.0, 0.5])
    np.testing.assert_allclose(c.position(rest), np.tile(math.cos(1) * u + math.sin(1) * v, (2, 1)), atol=1e-15)
    np.testing.assert_array_equal(c.velocity(rest), 0.0)
    np.testing.assert_array_equal(c.acceleration(rest), 0.0)
    # the speed rises monotonically to |omega| r over the ramp (min-jerk rate profile)
    speed = np.linalg.norm(c.velocity(np.linspace(0.5, 2.5, 401)), axis=1)
    assert np.all(np.diff(speed) >= -1e-15) and speed[-1] == pytest.approx(3.0, rel=1e-14)
    # half-way through the ramp the rate is omega/2 (s(1/2) = 1/2), and clockwise for omega < 0
    vel = c.velocity(1.5)
    assert np.linalg.norm(vel) == pytest.approx(1.5, rel=1e-14)
    p = c.position(1.5)
    assert np.cross(p, vel) @ np.array([0, 0, 1.0]) < 0


def test_circle_without_ramp_and_default_axis() -> None:
    c = Circle(centre=(0, 0, 0), radius=2.0, omega=1.0)  # normal z: u = X, v = Y
    np.testing.assert_allclose(c.position(math.pi / 2), [0, 2, 0], atol=1e-15)
    c2 = Circle(centre=(0, 0, 0), radius=1.0, normal=(1, 0, 0), period=1.0)  # X is the normal: u = Y
    np.testing.assert_allclose(c2.basis[0], [0, 1, 0], atol=1e-15)
    np.testing.assert_allclose(c2.position(0.25), [0, 0, 1], atol=1e-15)  # v = n x u = Z


def test_helix_pitch_and_speed() -> None:
    r, omega, w = 0.25, 1.5, 0.04
    hx = Helix(centre=(0, 0, -2), radius=r, normal=(0, 1, 0), omega=omega, axial_speed=w, t_ramp=3.0, t_start=1.0)
    T = 2 * math.pi / omega
    assert hx.pitch_per_turn == pytest.approx(w * T, rel=1e-15)
    t = np.linspace(hx.duration, hx.duration + 3 * T, 97)
    n = hx.basis[2]
    # one turn later: same point on the circle, advanced by one pitch along the axis
    np.testing.assert_allclose(hx.position(t + T) - hx.position(t), np.tile(w * T * n, (97, 1)), atol=1e-14)
    np.testing.assert_allclose(np.linalg.norm(hx.velocity(t), axis=1), math.hypot(omega * r, w), rtol=1e-14)
    np.testing.assert_allclose(hx.velocity(t) @ n, w, rtol=1e-14)
    # radial distance from the axis stays r, starts at rest
    rel = hx.position(t) - hx.centre
    np.testing.assert_allclose(np.linalg.norm(rel - (rel @ n)[:, None] * n, axis=1), r, rtol=1e-14)
    np.testing.assert_array_equal(hx.velocity(1.0), 0.0)
    # pitch given instead of axial speed
    hp = Helix(centre=(0, 0, 0), radius=r, period=T, pitch=w * T)
    assert hp.axial_rate == pytest.approx(w, rel=1e-15)


# --------------------------------------------------------------------------- Lemniscate


def test_lemniscate_of_gerono_closed_form() -> None:
    a, T = 0.6, 8.0
    omega = 2 * math.pi / T
    lem = Lemniscate(centre=(1.0, 0.0, -1.0), size=a, normal=(0, 0, 1), period=T)  # u = X, v = Y
    c = np.array(lem.centre)
    # known phases (no ramp: theta = omega t)
    np.testing.assert_allclose(lem.position(0.0), c, atol=1e-15)  # crossing
    np.testing.assert_allclose(lem.position(T / 8), c + [a / math.sqrt(2), a / 2, 0], atol=1e-15)  # lobe top
    np.testing.assert_allclose(lem.position(T / 4), c + [a, 0, 0], atol=1e-15)  # tip
    np.testing.assert_allclose(lem.position(T / 2), c, atol=1e-15)  # crossing again
    np.testing.assert_allclose(lem.position(3 * T / 4), c + [-a, 0, 0], atol=1e-15)  # other tip
    np.testing.assert_allclose(lem.velocity(T / 2), a * omega * np.array([-1, 1, 0]), atol=1e-15)
    np.testing.assert_allclose(lem.velocity(T / 4), a * omega * np.array([0, -1, 0]), atol=1e-15)
    # tip: a = (x'' u + y'' v) omega^2 = (-a, 0) omega^2
    np.testing.assert_allclose(lem.acceleration(T / 4), [-a * omega**2, 0, 0], atol=1e-15)
    # the implicit equation x^4 = a^2 (x^2 - y^2) along a whole period, and periodicity
    t = np.linspace(0, T, 1001)
    x, y, z = (lem.position(t) - c).T
    np.testing.assert_allclose(x**4, a**2 * (x**2 - y**2), atol=1e-15)
    np.testing.assert_array_equal(z, 0.0)
    np.testing.assert_allclose(lem.position(t + T), lem.position(t), atol=1e-14)


def test_lemniscate_smooth_start() -> None:
    lem = Lemniscate(centre=(0, 0, 0), size=1.0, period=10.0, t_ramp=4.0, t_start=1.0)
    np.testing.assert_array_equal(lem.velocity([0.0, 1.0]), 0.0)
    np.testing.assert_array_equal(lem.acceleration([0.0, 1.0]), 0.0)
    t = np.linspace(lem.duration, lem.duration + 10.0, 51)
    np.testing.assert_allclose(lem.position(t + 10.0), lem.position(t), atol=1e-14)


# --------------------------------------------------------------------------- CSV


def _axis_quat(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    axis = axis / np.linalg.norm(axis)
    return np.c_[np.cos(angle / 2), np.sin(angle / 2)[:, None] * axis]


def test_csv_round_trip_of_a_sampled_circle(tmp_path) -> None:
    c = Circle(centre=(0.3, -0.2, 1.0), radius=0.2, normal=(0, 1, 1), period=4.0, t_ramp=2.0, t_start=0.5)
    ts = np.arange(0.0, 12.0 + 1e-9, 0.01)
    q = _axis_quat(np.array([0, 1.0, 1.0]), c.theta(ts)[0])
    f = tmp_path / "circle.csv"
    write_csv(f, ts, c.position(ts), q)
    csv_traj = CsvTrajectory(f)
    assert csv_traj.has_orientation and csv_traj.duration == pytest.approx(12.0, abs=1e-12)
    # between samples; spline error ~ (5/384) h^4 max|p''''| (h = 0.01 s; r omega^4 ~ 1.2 m/s^4 steady,
    # larger in the ramp) ~ 1e-10 (observed 2.3e-10); the brief's bound is 1e-6
    mid = 0.5 * (ts[1:] + ts[:-1])
    np.testing.assert_allclose(csv_traj.position(mid), c.position(mid), rtol=0, atol=1e-6)
    np.testing.assert_allclose(csv_traj.position(ts), c.position(ts), rtol=0, atol=1e-12)  # interpolates
    # derivatives of the spline: errors O(h^3 |p''''|), O(h^2 |p''''|) away from the ends
    inner = mid[(mid > 0.1) & (mid < 11.9)]
    np.testing.assert_allclose(csv_traj.velocity(inner), c.velocity(inner), rtol=0, atol=1e-6)
    np.testing.assert_allclose(csv_traj.acceleration(inner), c.acceleration(inner), rtol=0, atol=1e-4)
    # slerp of a rotation about a fixed axis: exact where the angle is linear in t (steady),
    # and within the half-angle's chord error h^2/16 max|theta''| (theta'' <= 1.5 rad/s^2) ~ 1e-5 during
    # the ramp (observed 6.5e-6)
    qm = csv_traj.orientation(mid)
    qt = _axis_quat(np.array([0, 1.0, 1.0]), c.theta(mid)[0])
    np.testing.assert_allclose(np.linalg.norm(qm, axis=1), 1.0, atol=1e-15)
    steady = mid > c.duration + 0.01
    np.testing.assert_allclose(qm[steady], qt[steady], atol=1e-12)
    np.testing.assert_allclose(qm, qt, atol=5e-5)
    assert csv_traj.position(3.0).shape == (3,) and csv_traj.orientation(3.0).shape == (4,)
    assert csv_traj.velocity(ts.reshape(-1, 1)).shape == (len(ts), 1, 3)
    # at rest outside the samples
    np.testing.assert_allclose(csv_traj.position(20.0), c.position(12.0), atol=1e-12)
    np.testing.assert_array_equal(csv_traj.velocity([-1.0, 20.0]), 0.0)


def test_csv_quaternions_normalised_and_sign_continuous(tmp_path) -> None:
    ts = np.arange(6.0)
    q = _axis_quat(np.array([1.0, 0.0, 0.0]), 0.4 * ts)
    stored = q * np.array([1, -1, 3, 1, -2, 0.5])[:, None]  # flipped signs and arbitrary norms
    f = tmp_path / "q.csv"
    write_csv(f, ts, np.zeros((6, 3)), stored)
    tr = CsvTrajectory(f)
    t = np.linspace(0, 5, 101)
    np.testing.assert_allclose(tr.orientation(t), _axis_quat(np.array([1.0, 0, 0]), 0.4 * t), atol=1e-14)
    no_q = tmp_path / "p.csv"
    write_csv(no_q, ts, np.zeros((6, 3)))
    assert not CsvTrajectory(no_q).has_orientation and CsvTrajectory(no_q).orientation(1.0) is None


@pytest.mark.parametrize(
    "text, where",
    [
        ("t,x,y,z\n0,0,0,0\n1,0,abc,0\n", ("line 3", "column 3 (y)", "'abc'")),
        ("t,x,y,z\n0,0,0,0\n1,0,0\n", ("line 3", "3 columns, expected 4")),
        ("t,x,y,z\n0,0,0,0\n1,0,0,0\n1,1,0,0\n", ("line 4", "column 1 (t)", "strictly increasing")),
        ("t,x,y,z\n0,0,0,0\n1,0,nan,0\n", ("line 3", "column 3 (y)", "not a finite number")),
        ("time,x,y,z\n0,0,0,0\n1,0,0,0\n", ("line 1", "header")),
        ("t,x,y,z,qw,qx,qy,qz\n0,0,0,0,1,0,0,0\n1,0,0,0,0,0,0,0\n", ("line 3", "zero quaternion")),
        ("t,x,y,z\n0,0,0,0\n", ("at least 2",)),
    ],
)
def test_csv_bad_rows_name_file_line_column(tmp_path, text: str, where: tuple[str, ...]) -> None:
    f = tmp_path / "bad.csv"
    f.write_text(text)
    with pytest.raises(ValueError) as e:
        CsvTrajectory(f)
    msg = str(e.value)
    assert "bad.csv" in msg
    for w in where:
        assert w in msg


# --------------------------------------------------------------------------- make_trajectory


def test_make_trajectory_builds_every_kind(tmp_path) -> None:
    f = tmp_path / "traj.csv"
    write_csv(f, [0.0, 1.0, 2.0], [[0, 0, 0], [1, 0, 0], [1, 1, 0]])
    specs = {
        Line3D: {"kind": "line", "start": [0, 0, 0], "target": [0.3, 0, 0]},
        Waypoints: {"kind": "waypoints", "points": [[0, 0, 0], [1, 0, 0]], "cruise_speed": 0.1},
        Circle: {"kind": "circle", "centre": [0, 0, 0], "radius": 0.1, "period": 10, "t_ramp": 2},
        Lemniscate: {"kind": "lemniscate", "centre": [0, 0, 0], "size": 0.2, "omega": 0.5},
        Helix: {"kind": "helix", "centre": [0, 0, 0], "radius": 0.1, "period": 10, "pitch": 0.02},
        CsvTrajectory: {"kind": "csv", "path": "traj.csv"},
    }
    for cls, spec in specs.items():
        tr = make_trajectory(spec, base_dir=tmp_path)
        assert type(tr) is cls
        assert tr.position(np.linspace(0, 3, 5)).shape == (5, 3)
    c = make_trajectory(specs[Circle])
    assert c == Circle(centre=(0, 0, 0), radius=0.1, period=10, t_ramp=2)


@pytest.mark.parametrize(
    "spec, words",
    [
        ({"kind": "circel"}, ["trajectory.kind", "'circel'", "did you mean 'circle'", "lemniscate"]),
        ({"radius": 1}, ["trajectory.kind", "required"]),
        ({"kind": "circle", "centre": [0, 0, 0], "radius": 0.1, "perod": 3}, ["trajectory.perod", "did you mean 'period'", "allowed"]),
        ({"kind": "circle", "radius": 0.1, "period": 3}, ["trajectory.centre", "required"]),
        ({"kind": "circle", "centre": [0, 0, 0], "radius": -0.1, "period": 3}, ["trajectory.radius", "-0.1", "> 0"]),
        ({"kind": "circle", "centre": [0, 0], "radius": 0.1, "period": 3}, ["trajectory.centre", "[0, 0]", "3 finite numbers"]),
        ({"kind": "circle", "centre": [0, 0, 0], "radius": 0.1}, ["omega", "period", "exactly one"]),
        ({"kind": "circle", "centre": [0, 0, 0], "radius": 0.1, "omega": 1, "period": 3}, ["omega", "period", "exactly one"]),
        ({"kind": "circle", "centre": [0, 0, 0], "radius": 0.1, "omega": 0}, ["trajectory.omega", "!= 0"]),
        ({"kind": "circle", "centre": [0, 0, 0], "radius": 0.1, "period": 3, "normal": [0, 0, 0]}, ["trajectory.normal", "non-zero"]),
        ({"kind": "circle", "centre": [0, 0, 0], "radius": 0.1, "period": 3, "phase_axis": [0, 0, 2]}, ["trajectory.phase_axis", "parallel"]),
        ({"kind": "circle", "centre": [0, 0, 0], "radius": "big", "period": 3}, ["trajectory.radius", "'big'"]),
        ({"kind": "circle", "centre": [0, 0, 0], "radius": 0.1, "period": 3, "t_ramp": -1}, ["trajectory.t_ramp", "-1", ">= 0"]),
        ({"kind": "lemniscate", "centre": [0, 0, 0], "size": 0, "period": 3}, ["trajectory.size", "> 0"]),
        ({"kind": "helix", "centre": [0, 0, 0], "radius": 0.1, "period": 3}, ["axial_speed", "pitch", "exactly one"]),
        ({"kind": "line", "start": [0, 0, 0], "target": [1, 0, math.inf]}, ["trajectory.target", "finite"]),
        ({"kind": "line", "start": [0, 0, 0], "target": [1, 0, 0], "accel": 0}, ["trajectory.accel", "> 0"]),
        ({"kind": "waypoints", "points": [[0, 0, 0]], "durations": [1]}, ["trajectory.points", "at least 2"]),
        ({"kind": "waypoints", "points": [[0, 0, 0], [1, 0, 0]], "durations": [1, 2]}, ["trajectory.durations", "1 segment"]),
        ({"kind": "waypoints", "points": [[0, 0, 0], [1, 0, 0]], "durations": [-1]}, ["trajectory.durations[0]", "> 0"]),
        ({"kind": "waypoints", "points": [[0, 0, 0], [0, 0, 0]], "cruise_speed": 1}, ["trajectory.points[1]", "zero-length"]),
        ({"kind": "waypoints", "points": [[0, 0, 0], [1, 0, 0], [1, 0]], "cruise_speed": 1}, ["trajectory.points[2]"]),
        ({"kind": "csv", "path": "/nonexistent/x.csv"}, ["trajectory.path", "no such file"]),
        ({"kind": "csv", "path": "x.csv", "bctype": "natural"}, ["trajectory.bctype", "did you mean 'bc_type'"]),
    ],
)
def test_bad_specs_raise_value_error_naming_the_field(spec: dict, words: list[str]) -> None:
    with pytest.raises(ValueError) as e:
        make_trajectory(spec)
    for w in words:
        assert w in str(e.value), (w, str(e.value))


def test_bad_bc_type(tmp_path) -> None:
    f = tmp_path / "t.csv"
    write_csv(f, [0.0, 1.0], [[0, 0, 0], [1, 0, 0]])
    with pytest.raises(ValueError, match=r"trajectory.bc_type = 'natrual'.*did you mean 'natural'"):
        make_trajectory({"kind": "csv", "path": str(f), "bc_type": "natrual"})


def test_scalar_time_paths_equal_the_vectorised_ones():
    """The per-sample (float t) fast paths of Waypoints and the phase curves give the vectorised
    formulas' values (before, during and after the ramps and segments), to round-off: numpy's
    vectorised sin/cos take SIMD kernels chosen at run time (AVX-512 differs by one ulp from the
    scalar path on 5 of 1863 values), so 1e-14 relative of the largest value (about 50 ulp) and
    1e-16 absolute, far below any formula error (a wrong phase or ramp moves values by > 1e-6)."""
    from uvms_mj.control.trajectories import Circle, Lemniscate, Waypoints

    trs = [Circle(centre=(0, 0, 0), radius=0.05, normal=(1, 0, 0), period=20, t_ramp=5, t_start=2),
           Circle(centre=(0, 0, 0), radius=0.05, normal=(0, 0, 1), period=7),
           Lemniscate(centre=(0, 0, 0), size=0.1, normal=(0, 0, 1), period=10, t_ramp=3),
           Waypoints(points=((0, 0, 0), (0.1, 0.2, 0), (0, 0, 0.1)), durations=(2, 3), t_start=1)]
    ts = np.linspace(-1, 30, 621)
    for tr in trs:
        for f in ("position", "velocity", "acceleration"):
            vec = getattr(tr, f)(ts)
            one = np.array([getattr(tr, f)(float(t)) for t in ts])
            scale = float(np.max(np.abs(one))) if one.size else 0.0
            np.testing.assert_allclose(vec, one, rtol=0, atol=1e-14 * scale + 1e-16, err_msg=f)
