"""Gains with a margin (issue 19 item 3): the sampled closed loop of one task coordinate
(:mod:`uvms_mj.control.margins`) against closed forms and against simulation of the controller,
the "auto" default gains, and the delay compensation (``delay_compensation``)."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from uvms_mj.control.base import ControllerError, Measurement
from uvms_mj.control.margins import (
    GAIN_MARGIN,
    GAIN_STEP,
    DelayPredictor,
    closed_loop_matrix,
    largest_stable_gain,
    spectral_radius,
    thruster_lag,
)

T_PAPER = 1.0 / 60.0


# ---------------------------------------------------------------- the model against closed forms


@pytest.mark.parametrize("T,tau", [(T_PAPER, 0.0), (T_PAPER, 0.05), (T_PAPER, 1e-4), (T_PAPER, 30.0),
                                   (0.05, 0.05), (0.01, 0.0105)])
def test_sampled_plant_is_the_matrix_exponential(T, tau):
    """The closed-form zero-order-hold plant (double integrator behind a first-order thruster lag)
    against scipy's matrix exponential of [[A, B], [0, 0]] T, the textbook discretisation (Franklin,
    Powell & Workman, Digital Control, section 4.3.3). Cases cover a = T/tau on both sides of the
    series/expm1 switch at 1 (0.0006 to 167) and no lag. Tolerance 1e-12 relative to each entry's
    scale: the closed form is exact; expm's Pade approximation is good to about 1e-15."""
    from scipy.linalg import expm

    from uvms_mj.control.margins import _plant

    if tau > 0:
        Ac = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0 / tau]])
        Bc = np.array([0.0, 0.0, 1.0 / tau])
    else:
        Ac, Bc = np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([0.0, 1.0])
    n = len(Bc)
    E = np.zeros((n + 1, n + 1))
    E[:n, :n], E[:n, n] = Ac, Bc
    F = expm(E * T)
    Phi, Gam = _plant(T, tau, "zoh")
    np.testing.assert_allclose(Phi, F[:n, :n], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(Gam, F[:n, n], rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("gamma,lam", [(0.3, 0.2), (0.1, 0.7), (0.5, 0.5)])
def test_ideal_plant_eigenvalues_are_one_minus_gains(gamma, lam):
    """The paper's reading (docs/paper-reading.md, Eqs. 10-11): with the velocity realising a_d
    over a sample, e_p(k+1) = (1 - gamma) e_p(k), e_v(k+1) = (1 - lambda) e_v(k); the state
    matrix adds one zero eigenvalue (the stored y(k-1)). Tolerance: eigenvalue round-off."""
    ev = np.sort(np.linalg.eigvals(closed_loop_matrix(gamma, lam, T_PAPER, plant="ideal")).real)
    want = np.sort([0.0, 1.0 - gamma, 1.0 - lam])
    np.testing.assert_allclose(ev, want, atol=1e-9)


@pytest.mark.parametrize("gamma,lam,T", [(0.3, 0.2, T_PAPER), (0.2, 0.2, 0.02), (0.6, 0.4, 0.05)])
def test_zoh_characteristic_polynomial(gamma, lam, T):
    """Zero-order hold, no delay, no lag: x(k+1) - 2x(k) + x(k-1) = T^2/2 (u(k) + u(k-1)) with
    T^2 u(k) = c0 x(k) + c1 x(k-1) (derived by hand from Eqs. 10-11: c0 = -(gamma + lambda),
    c1 = gamma + lambda - gamma lambda) gives the cubic of the module docstring. The state matrix
    (x, v, x(k-1)) has its roots."""
    c0, c1 = -(gamma + lam), gamma + lam - gamma * lam
    roots = np.roots([1.0, -(2.0 + c0 / 2.0), 1.0 - (c0 + c1) / 2.0, -c1 / 2.0])
    ev = np.linalg.eigvals(closed_loop_matrix(gamma, lam, T))
    np.testing.assert_allclose(np.sort_complex(ev), np.sort_complex(roots), atol=1e-9)


def test_delay_adds_a_sample_and_its_polynomial():
    """One sample of delay, no lag: y(k) = x(k-1), so the recursion is
    x(k+1) - 2x(k) + x(k-1) = 1/2 (c0 x(k-1) + c1 x(k-2) + c0 x(k-2) + c1 x(k-3)): a quartic."""
    gamma = lam = 0.3
    c0, c1 = -(gamma + lam), gamma + lam - gamma * lam
    roots = np.roots([1.0, -2.0, 1.0 - c0 / 2.0, -(c0 + c1) / 2.0, -c1 / 2.0])
    ev = np.linalg.eigvals(closed_loop_matrix(gamma, lam, T_PAPER, delay=1))
    ev = ev[np.abs(ev) > 1e-9]  # the extra stored sample x(k-2) adds a zero eigenvalue
    np.testing.assert_allclose(np.sort_complex(ev), np.sort_complex(roots), atol=1e-8)


def test_lag_limits_match_the_single_axis_numbers():
    """docs/paper-reading.md "Thruster lag vs the paper's gains": the lag at which a base gain
    loses stability is about 0.041 s for 0.3 (0.006 s with a one-sample delay), 0.089 s for 0.2,
    0.14 s for 0.15 and 0.25 s for 0.1 (an earlier analysis, confirmed there by simulation).
    Tolerance: the numbers' printed digits."""
    assert spectral_radius(closed_loop_matrix(0.3, 0.3, T_PAPER, tau=0.040)) < 1.0
    assert spectral_radius(closed_loop_matrix(0.3, 0.3, T_PAPER, tau=0.042)) > 1.0
    assert spectral_radius(closed_loop_matrix(0.3, 0.3, T_PAPER, delay=1, tau=0.005)) < 1.0
    assert spectral_radius(closed_loop_matrix(0.3, 0.3, T_PAPER, delay=1, tau=0.007)) > 1.0
    for g, tau in ((0.2, 0.089), (0.15, 0.14), (0.1, 0.25)):
        assert spectral_radius(closed_loop_matrix(g, g, T_PAPER, tau=tau * 0.98)) < 1.0
        assert spectral_radius(closed_loop_matrix(g, g, T_PAPER, tau=tau * 1.02)) > 1.0


def test_largest_stable_gain_bisection():
    """No delay, no lag, ZOH: the cubic's roots leave the unit circle where its value at z = -1
    crosses zero: p(-1) = -4 + 2 c0 + ... -> gamma_max with 2 (c0 + c1) ... solved numerically on
    the closed-form polynomial (independent of the state matrix); the bisection agrees to its
    tolerance. Also: the result is stable and tol above it is not."""
    def rho_poly(g):
        c0, c1 = -2 * g, 2 * g - g * g
        return max(abs(np.roots([1.0, -(2.0 + c0 / 2.0), 1.0 - (c0 + c1) / 2.0, -c1 / 2.0])))

    lo, hi = 0.01, 0.99
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if rho_poly(mid) < 1 else (lo, mid)
    g = largest_stable_gain(T_PAPER)
    assert abs(g - lo) < 2e-4
    g1 = largest_stable_gain(T_PAPER, delay=1, tau=0.02)
    assert spectral_radius(closed_loop_matrix(g1, g1, T_PAPER, 1, 0.02)) < 1.0
    assert spectral_radius(closed_loop_matrix(g1 + 2e-4, g1 + 2e-4, T_PAPER, 1, 0.02)) > 1.0


def test_compensation_restores_the_undelayed_loop_without_lag():
    """Prediction over the delay is exact for the ZOH double integrator without lag: the
    delayed, compensated loop has the undelayed loop's eigenvalues (plus zeros of the stored
    samples: a defective zero block, whose computed eigenvalues scatter to ~eps^(1/4), hence the
    1e-2 cut). Tolerance: round-off."""
    for g in (0.2, 0.5):
        ref = np.linalg.eigvals(closed_loop_matrix(g, g, T_PAPER))
        ev = np.linalg.eigvals(closed_loop_matrix(g, g, T_PAPER, delay=1, compensation=1))
        ev = ev[np.abs(ev) > 1e-2]
        ref = ref[np.abs(ref) > 1e-2]
        np.testing.assert_allclose(np.sort_complex(ev), np.sort_complex(ref), atol=1e-6)


def test_bad_inputs():
    with pytest.raises(ValueError, match="delay"):
        closed_loop_matrix(0.2, 0.2, T_PAPER, delay=-1)
    with pytest.raises(ValueError, match="plant"):
        closed_loop_matrix(0.2, 0.2, T_PAPER, plant="euler")


def test_thruster_lag_of_the_models():
    """models/uvms.xml: filter actuators, dynprm 0.02 s (docs/paper-reading.md); bluerov2_alpha:
    the uvms.thruster plugin's tau = 0.05 s (models/bluerov2_heavy/bluerov2_heavy_defs.xml)."""
    from uvms_mj.control.nominal import NominalRobot
    from uvms_mj.plant.files import models_dir, robot_path

    assert thruster_lag(NominalRobot(models_dir() / "uvms.xml").model) == pytest.approx(0.02)
    assert thruster_lag(NominalRobot(robot_path("bluerov2_alpha")).model) == pytest.approx(0.05)


# ---------------------------------------------------------------- against simulation


def _growth(gain: float, delay: int, seconds: float = 10.0, comp: int = 0) -> tuple[str, float]:
    """Paper robot with truth = nominal, holding station, 1e-5 m / rad measurement noise as
    the excitation: (status, RMS task error over the last quarter / over the second quarter)."""
    from uvms_mj.scenario.schema import load_scenario, run_scenario

    g = "[" + ",".join([repr(gain)] * 5) + "]"
    sc = load_scenario("scenarios/paper.yaml", sets=[
        "plant.model_mismatch=false", "trajectory.displacement=[0.0,0.0]", "sensors.position_noise=1e-5",
        "sensors.angle_noise=1e-5", f"sensors.delay={delay}", f"duration={seconds}", "controller.name=rac",
        f"controller.params.gamma={g}", f"controller.params.lam={g}",
        f"controller.params.delay_compensation={comp}"])
    r = run_scenario(sc)
    e = np.linalg.norm(r.signals["e_p"], axis=1)
    n = e.size
    rms = lambda x: float(np.sqrt(np.mean(x ** 2)))  # noqa: E731
    return r.status, rms(e[3 * n // 4:]) / max(rms(e[n // 4:n // 2]), 1e-300), rms(e[3 * n // 4:])


def test_simulated_limit_matches_the_computed_one_with_a_delay():
    """The computed largest gain with a one-sample delay and the paper's 0.02 s thruster lag
    (0.236) against the simulated controller: 0.025 below it the run stays at the noise level,
    0.025 above it the error grows by orders of magnitude (or the run diverges). Tolerance 0.025
    (about 10 %): the simulation's limit is 0.230 by bisection to 0.005 (docs/paper-reading.md
    "Gains and delay"); the model ignores the base-arm coupling through the lag."""
    g = largest_stable_gain(T_PAPER, delay=1, tau=0.02)
    assert 0.23 < g < 0.24
    status, _, low = _growth(g - 0.025, 1)
    assert status == "ok" and low < 1e-4  # noise level: 1e-5 noise gives errors of a few 1e-5 m
    status, ratio, high = _growth(g + 0.025, 1)
    assert status != "ok" or high > 30 * low


# ---------------------------------------------------------------- default gains


def test_auto_gains_floating_and_paper():
    """bluerov2_alpha (T = 0.02 s, thruster lag 0.05 s): the base blocks get the largest gain
    stable with a one-sample delay through the lag / GAIN_MARGIN, rounded down to GAIN_STEP
    (0.1908 / 1.5 -> 0.125); the tip blocks min(0.2, 0.352 / 1.5) = 0.2. The paper's robot keeps
    the paper's gains. Recorded in resolved_params."""
    from uvms_mj.control.nominal import NominalRobot
    from uvms_mj.control.rac import RAC, RACDOB
    from uvms_mj.plant.files import robot_path

    robot = NominalRobot(robot_path("bluerov2_alpha"))
    base = math.floor(largest_stable_gain(0.02, 1, 0.05) / GAIN_MARGIN / GAIN_STEP) * GAIN_STEP
    assert base == pytest.approx(0.125)
    for cls in (RAC, RACDOB):
        c = cls(robot=robot, T=0.02)
        np.testing.assert_allclose(c.gamma, [base] * 6 + [0.2] * 3, rtol=0, atol=1e-12)
        np.testing.assert_allclose(c.lam, c.gamma, rtol=0, atol=0)
        assert c.resolved_params["gamma"] == list(c.gamma)
        assert c.resolved_params["auto_gains"] == ["gamma", "lam"] and c.resolved_params["thruster_lag"] == 0.05
    c = RAC(robot=robot, T=0.02, gain_margin=1.0)  # the bare stability limit: 0.19 on the base
    assert c.gamma[0] == pytest.approx(0.19)
    np.testing.assert_allclose(RAC().gamma, [0.3, 0.3, 0.2, 0.2, 0.2], rtol=0, atol=0)
    given = RAC(robot=robot, T=0.02, gamma=0.3, lam=0.25)
    assert given.gamma[0] == 0.3 and given.lam[8] == 0.25 and "auto_gains" not in given.resolved_params
    with pytest.raises(ControllerError, match="gain_margin"):
        RAC(robot=robot, T=0.02, gain_margin=0.5)
    with pytest.raises(ControllerError, match="gamma"):
        RAC(robot=robot, T=0.02, gamma="fast")
    with pytest.raises(ControllerError, match="delay_compensation"):
        RAC(delay_compensation=-1)


# ---------------------------------------------------------------- delay compensation


def test_predictor_is_exact_for_the_double_integrator():
    """DelayPredictor on a free slide (x_ddot = a held over each sample): the exact sampled
    positions x(k) = x(k-1) + T v + T^2/2 a (closed form) delayed by d samples are predicted back
    to x(k) to round-off, for d = 1 and 2."""
    xml = '<mujoco><worldbody><body><joint type="slide"/><geom size="0.1" mass="1"/></body></worldbody></mujoco>'
    m = mujoco.MjModel.from_xml_string(xml)
    T = 0.02
    rng = np.random.default_rng(1)
    a = rng.normal(size=60)
    x, v = [0.3], 0.7
    for ak in a:
        x.append(x[-1] + T * v + 0.5 * T * T * ak)
        v += T * ak
    for d in (1, 2):
        p = DelayPredictor(m, T, d)
        p.reset([x[0]])
        for k in range(len(a)):
            y = x[max(k - d, 0)]
            qh, _ = p.predict([y])
            if k >= d + 1:
                assert qh[0] == pytest.approx(x[k], abs=1e-12)
            p.record([a[k]])


def _paper_run(comp: int, use_kernel: bool, seconds: float = 3.0, extra=()):
    from uvms_mj.scenario.schema import build, load_scenario, sensor_model
    from uvms_mj.sim.loop import run_closed_loop

    sc = load_scenario("scenarios/paper.yaml", sets=[
        "sensors.delay=1", f"duration={seconds}", f"controller.params.delay_compensation={comp}", *extra])
    plant, ctrl = build(sc)
    ctrl.use_kernel = use_kernel
    res = run_closed_loop(plant, ctrl, sc.duration, T=ctrl.T, sensor=sensor_model(sc), seed=sc.seed,
                          warm_start=sc.warm_start)
    assert (ctrl._ws is not None) == (use_kernel and ctrl._ws is not None)
    return res, ctrl


def test_compensation_keeps_the_paper_gains_with_a_delay():
    """The paper scenario's motion (paper gains, Eq. 12 carrying the arm) on a plant equal to the
    nominal model, one sample of delay: without compensation a saturated oscillation (about
    0.7 mm base RMS, thrusters saturated most of the time); with delay_compensation = 1 the
    prediction is exact up to the thrusters' lag and the errors stay at the undelayed run's
    level (below 0.02 mm). Thresholds: an order of magnitude either side of the measured values
    (docs/paper-reading.md "Gains and delay")."""
    extra = ("plant.model_mismatch=false",)
    r0, _ = _paper_run(0, True, 6.0, extra)
    r1, _ = _paper_run(1, True, 6.0, extra)
    assert r1.status == "ok"
    n = r1.signals["e_p"].shape[0]
    base = lambda r: float(np.sqrt(np.mean(r.signals["e_p"][n // 2:, :2] ** 2)))  # noqa: E731
    assert base(r1) < 2e-5
    assert r0.status != "ok" or base(r0) > 1e-4
    assert not np.any(r1.signals["thrust_saturated"])


def test_compensation_kernel_and_python_agree():
    """The prediction acts ahead of the per-sample algebra, so the compiled kernel and the Python
    code see the same measurement: their commands agree to the kernel's round-off tolerance of
    tests/test_rac_kernel.py (1e-9 of each signal's largest value over a short run)."""
    from uvms_mj.control import kernel

    if kernel.library() is None:
        pytest.skip("no compiled kernel")
    a, ca = _paper_run(1, True, 2.0)
    b, cb = _paper_run(1, False, 2.0)
    assert ca._ws is not None and cb._ws is None
    for k in ("thrust_command", "torques", "e_p", "q_true"):
        y = b.signals[k]
        np.testing.assert_allclose(a.signals[k], y, rtol=0, atol=1e-9 * float(np.max(np.abs(y))) + 1e-10, err_msg=k)


def test_resolved_scenario_shows_auto_or_the_papers_gains():
    """`validate --resolved` (schema.resolved): "auto" on bluerov2_alpha (the numbers are the
    controller's resolved_params, in a log's meta), the paper's gains on the paper's robot."""
    from uvms_mj.scenario.schema import load_scenario, resolved

    d = resolved(load_scenario("scenarios/bluerov2_alpha_circle_current.yaml"))["controller"]["params"]
    assert d["gamma"] == d["lam"] == "auto" and d["gain_margin"] == GAIN_MARGIN and d["delay_compensation"] == 0
    p = resolved(load_scenario("scenarios/paper.yaml"))["controller"]["params"]
    assert p["gamma"] == p["lam"] == [0.3, 0.3, 0.2, 0.2, 0.2]
