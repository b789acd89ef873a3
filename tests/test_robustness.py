"""Robustness of the exact added mass, and the choice of the default time step."""

import mujoco
import numpy as np
import pytest

from uvms_mj import DivergenceError, HydroTerms, Plant

SCALE = 5.0


def heavy_added_mass() -> dict:
    """All added masses and added inertias scaled by 5: the base's m_Ax / m becomes 14."""
    params = Plant().params
    return {f"{b.name}.added_mass": [SCALE * b.added_mass[0], SCALE * b.added_mass[1], SCALE * b.added_inertia]
            for b in params.bodies}


def drifting(plant: Plant) -> Plant:
    plant.set_state(base_velocity=(0.1, -0.05, 0.2), joint_velocities=(0.5, -0.8))
    return plant


def test_exact_added_mass_stays_bounded_at_5x():
    """30 s of passive drift with 5x added mass: finite, bounded, and its mechanical energy
    (kinetic + gravity/buoyancy potential) never rises (sampled every second; 1e-6 J slack for
    the integrator): the arm swings, drag damps it, the 1 % net buoyancy lifts the robot."""
    plant = drifting(Plant(overrides=heavy_added_mass()))
    energy = plant.energy().total
    for _ in range(30):
        plant.step(round(1 / plant.model.opt.timestep))
        assert np.all(np.isfinite(plant.q)) and np.all(np.isfinite(plant.qd))
        assert np.abs(plant.qd).max() < 5.0
        now = plant.energy().total
        assert now <= energy + 1e-6
        energy = now
    assert abs(plant.time - 30.0) < 1e-9
    assert np.abs(plant.q[:2]).max() < 3.0


def test_lagged_added_mass_diverges_on_the_same_case():
    """Applying -M_A times the previous acceleration (as peer simulators do) amplifies the
    acceleration by about -m_A/m each step: the same case blows up, and the plant says when."""
    plant = drifting(Plant(overrides=heavy_added_mass(), terms=HydroTerms(added_mass="lagged")))
    with pytest.raises(DivergenceError) as err:
        plant.step(round(30 / plant.model.opt.timestep))
    assert err.value.time < 30.0
    assert "diverged at t =" in str(err.value)


def tip_and_base_after(dt: float, seconds: float = 10.0) -> np.ndarray:
    plant = drifting(Plant(timestep=dt))
    plant.step(int(round(seconds / dt)))
    return np.r_[plant.q[:2], plant.tip_position]


@pytest.mark.slow
def test_default_timestep_converged():
    """Default: RK4 at dt = T/2 = 1/120 s. Halving dt moves the base and the end tip after a
    10 s drift by under 1 mm (measured: 7e-8 m, fourth order; semi-implicit Euler at 1/600 s,
    which costs about as much, moves them by 1.0 mm)."""
    plant = Plant()
    dt = plant.model.opt.timestep
    assert dt == pytest.approx(1 / 120, rel=1e-15)
    assert plant.model.opt.integrator == mujoco.mjtIntegrator.mjINT_RK4
    diff = np.abs(tip_and_base_after(dt) - tip_and_base_after(dt / 2)).max()
    assert diff < 1e-3, diff
    assert diff > 1e-10  # the check is sensitive: the trajectories do differ
