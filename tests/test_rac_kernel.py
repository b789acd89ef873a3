"""The compiled RAC kernel (uvms_mj/control/kernel) against the RAC's Python code.

The Python code of :class:`uvms_mj.control.rac.RAC` is the reference (itself checked against
the planar closed form and exact-nominal truths in test_rac3d.py); the kernel computes the same
equations in C with other operation orders and its own small inverses. Every closed-loop run
below is made twice, kernel and Python, and every signal must agree to 1e-9 relative to its
largest value (measured: at most 1e-11 after 40 s; chaos would show as orders of magnitude
more). The cases cover each branch of the kernel: planar base (square arm, Eq. 12 carry and
release, damped least squares), floating base with the redundant arm (weighted pseudo-inverse,
null-space posture), tip orientation (6 task rows on 4 joints: always damped), the "wls"
allocation's fast path and its fall-back to the Allocator, measured velocities, the arm
observer, and the payload event.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from uvms_mj.control import kernel
from uvms_mj.control.digital import SingularHandler
from uvms_mj.sim.experiment import metrics
from uvms_mj.sim.loop import run_closed_loop
from uvms_mj.scenario.schema import build, load_scenario, sensor_model

SCEN = Path(__file__).resolve().parents[1] / "scenarios"

needs_kernel = pytest.mark.skipif(kernel.library() is None, reason=f"no RAC kernel: {kernel.kernel_unavailable_reason()}")


def _run(name: str, sets: list[str], use_kernel: bool):
    sc = load_scenario(SCEN / f"{name}.yaml", sets)
    plant, ctrl = build(sc)
    ctrl.use_kernel = use_kernel
    res = run_closed_loop(plant, ctrl, sc.duration, T=ctrl.T, sensor=sensor_model(sc), seed=sc.seed,
                          warm_start=sc.warm_start)
    assert (ctrl._ws is not None) == use_kernel
    return res


def _assert_same_runs(a, b, rel=1e-9, rel_metrics=1e-8, flag_mismatch=0.0):
    # "joint_limit": finished, a joint more than 1 deg past the plant's range (the payload study's
    # elbow, driven onto its stop by the weight no nominal model knows): a whole run all the same
    assert a.status == b.status and a.status in ("ok", "joint_limit"), (a.reason, b.reason)
    assert list(a.signals) == list(b.signals)
    for k, y in b.signals.items():
        x = a.signals[k]
        assert x.dtype == y.dtype and x.shape == y.shape, k
        if y.dtype.kind in "iub":
            assert np.mean(x != y) <= flag_mismatch if y.size else True, k
            continue
        scale = float(np.nanmax(np.abs(y))) if y.size else 0.0
        # 1e-10 absolute: round-off of O(1) quantities amplified by 1/T^2 (2500 at 50 Hz) in a_desired
        np.testing.assert_allclose(x, y, rtol=0, atol=rel * scale + 1e-10, err_msg=k)
    ma, mb = metrics(a), metrics(b)
    for k in mb:
        assert ma[k] == pytest.approx(mb[k], rel=rel_metrics, abs=1e-12, nan_ok=True), k


CASES = {
    "paper rac_dob (Eq. 12 carry and release)": ("paper", []),
    "paper rac": ("paper", ["controller.name=rac"]),
    "paper with DLS below 0.2": ("paper", ["duration=20", "controller.params.dls_threshold=0.2"]),
    "paper, velocity sensor and noise": ("paper", ["duration=10", "sensors.velocity_sensor=true",
                                                   "sensors.velocity_noise=0.001", "sensors.angle_noise=0.0005"]),
    "3-D circle in a current (wls fast path)": ("bluerov2_alpha_circle_current", ["duration=10"]),
    "3-D sweep": ("bluerov2_alpha_sweep", ["duration=6"]),
    "3-D payload, arm observer": ("bluerov2_alpha_payload", ["duration=12", "controllers.rac_dob.observer_arm=true"]),
    "3-D tip orientation (6 rows, 4 joints)": ("bluerov2_alpha_station", ["duration=4", "controller.name=rac_dob",
                                                                          "controllers.rac_dob.tip_orientation=true"]),
}


@needs_kernel
@pytest.mark.parametrize("case", list(CASES))
def test_kernel_gives_the_python_run(case):
    name, sets = CASES[case]
    _assert_same_runs(_run(name, sets, True), _run(name, sets, False))


@pytest.mark.slow
@needs_kernel
def test_wls_saturation_falls_back_to_the_allocator():
    """Thrust limits of 3 N in the nominal model: the fast path (all thrusters free) does not
    apply at some samples and the Allocator redistributes (rc 1 of uvms_rac_command); same run
    as the Python code, to 1e-3 relative: a saturated allocation switches its active set where
    two choices tie to round-off (kinks of a continuous map), so the C and numpy paths, whose
    floating-point order differs with the CPU's vector instructions, part there: measured 1e-5
    relative on one CPU and 1.1e-4 (6 of 2408 thrusts, 3.3e-4 N of 3 N) on an AVX-512 one;
    1e-3 keeps a ~10x margin over the worst seen and still catches any real difference."""
    limits = ", ".join(f"bluerov2_t{i}.forcerange: [-3, 3]" for i in range(1, 9))
    old = "[0.3, 0.3, 0.3, 0.2, 0.2, 0.2, 0.2, 0.2, 0.2]"  # the gains this case was built with (not "auto")
    sets = ["duration=6", f"nominal.overrides={{{limits}}}", f"controller.params={{gamma: {old}, lam: {old}}}"]
    a = _run("bluerov2_alpha_circle_current", sets, True)
    assert a.signals["thrust_saturated"].any()
    _assert_same_runs(a, _run("bluerov2_alpha_circle_current", sets, False), rel=1e-3, rel_metrics=1e-3,
                      flag_mismatch=0.02)  # a thruster exactly at its limit in one run, a hair inside in the other
    # (measured 1.3 % of the flags since the arm's wrist runs into its joint-limit damper here: the
    # clamp is another kink; the thrusts themselves agree to 1e-5 relative)


@pytest.fixture
def kernel_mode(monkeypatch):
    """Set UVMS_MJ_COMPILED and load afresh (the process's loaded kernel is restored after)."""
    def load(mode: str):
        monkeypatch.setenv("UVMS_MJ_COMPILED", mode)
        monkeypatch.setattr(kernel, "_LOADER", kernel._LOADER.fresh())
        return kernel.library()

    return load


def test_kernel_off_runs_the_python_code(kernel_mode):
    """UVMS_MJ_COMPILED=off: every RAC on its Python code, and the reason is said."""
    assert kernel_mode("off") is None
    assert "UVMS_MJ_COMPILED=off" in kernel.kernel_unavailable_reason()
    sc = load_scenario(SCEN / "paper.yaml", ["duration=1"])
    plant, ctrl = build(sc)
    res = run_closed_loop(plant, ctrl, sc.duration, T=ctrl.T)
    assert res.status == "ok" and ctrl._ws is None


def test_bad_compiled_mode_is_named(kernel_mode):
    from uvms_mj.physics.build import CompiledModeError

    with pytest.raises(CompiledModeError, match="UVMS_MJ_COMPILED='fast' is not one of auto, on, off"):
        kernel_mode("fast")


# ----------------------------------------------------------------------------- Eq. 12 handler


def _ramps(js_low, js_high, n, v_cruise, manip):
    """Eq. 12 as read (docs/paper-reading.md), written out directly: the linear ramps of the
    base velocity between 0 and v_cruise, restarted at each event."""
    phase, k_ev, v_from, v_to, v = 0, 0, np.zeros(len(v_cruise)), np.zeros(len(v_cruise)), np.zeros(len(v_cruise))
    out = []
    for k, a in enumerate(manip):
        if phase != 1 and a < js_low:
            phase, k_ev, v_from, v_to = 1, k, v.copy(), np.asarray(v_cruise, float)
        elif phase == 1 and a > js_high:
            phase, k_ev, v_from, v_to = 2, k, v.copy(), np.zeros(len(v_cruise))
        frac = min(1.0, (k - k_ev + 1) / n)
        v = v_from + frac * (v_to - v_from)
        if phase == 2 and frac >= 1.0:
            phase = 0
        out.append((phase, v.copy()))
    return out


@pytest.mark.parametrize("size", [2, 3])
def test_eq12_handler_carries_and_releases_in_2d_and_3d(size):
    """Near-singular stretches (manipulability below js, then above js_high) with a 2-D (paper)
    and 3-D (floating base) cruise velocity: the handler gives the written-out ramps exactly
    (its shortcut for a finished ramp returns the same numbers), back to exactly 0 after each
    release (the release of a 3-D base used a 2-vector before)."""
    rng = np.random.default_rng(3)
    manip = np.concatenate([np.full(20, 0.2), np.full(40, 0.01), np.full(15, 0.06), rng.uniform(0.0, 0.1, 200),
                            np.full(50, 0.3)])
    v_cruise = [0.02, -0.01, 0.005][:size]
    h = SingularHandler(0.045, 0.05, 10, v_cruise, size=size)
    want = _ramps(0.045, 0.05, 10, v_cruise, manip)
    for k, a in enumerate(manip):
        v = h.update(k, a)
        assert v.shape == (size,)
        assert h.phase == want[k][0]
        assert np.array_equal(v, want[k][1]), k
    assert h.phase == 0 and not np.any(h.v)


def test_desired_tip_blocks_are_the_per_sample_path():
    """RAC reads the paper line's desired tips in blocks (StraightLine.positions, over several
    blocks of TIP_BLOCK samples in 40 s): the run is the same, bit for bit, as with a trajectory
    offering only position(t) (evaluated sample by sample)."""
    from uvms_mj.control.rac_task import TIP_BLOCK

    class PerSample:  # the same line without positions()
        def __init__(self, line):
            self.line = line

        def position(self, t):
            return self.line.position(t)

        def cruise_velocity(self):
            return self.line.cruise_velocity()

    sc = load_scenario(SCEN / "paper.yaml", [])
    runs = []
    for wrap in (False, True):
        plant, ctrl = build(sc)
        assert hasattr(ctrl.trajectory, "positions")
        if wrap:
            ctrl.trajectory = PerSample(ctrl.trajectory)
        runs.append(run_closed_loop(plant, ctrl, sc.duration, T=ctrl.T, sensor=sensor_model(sc), seed=sc.seed,
                                    warm_start=sc.warm_start))
        if wrap:
            assert ctrl._tip_blk is None
        else:
            assert ctrl._tip_blk[0] >= 3 * TIP_BLOCK  # the last block read: several before it
    a, b = runs
    assert list(a.signals) == list(b.signals)
    # exact: the blocks are StraightLine.positions, element-wise +, -, * in position()'s order
    # (IEEE-rounded alike in SIMD lanes; tests/test_trajectories.py), the rest the same code
    for k in a.signals:
        np.testing.assert_array_equal(a.signals[k], b.signals[k], err_msg=k)
