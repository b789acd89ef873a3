"""Energy balance: exact added mass conserves energy; drag only removes it."""

import numpy as np

from uvms_mj import HydroTerms, Plant

from conftest import random_qd


def kinetic_energy(plant: Plant) -> float:
    """1/2 q_dot^T M q_dot with the plant's full mass matrix (rigid + added)."""
    qd = plant.qd
    return 0.5 * float(qd @ plant.mass_matrix() @ qd)


def test_energy_conserved_without_drag_and_gravity(rng):
    """10 s of coasting from a random state with RK4 at 1/600 s: total kinetic energy (rigid +
    added) is conserved to 1e-8 relative. Without the J_dot term it drifts by ~10 % (docs/mujoco-notes.md),
    so this fails if any velocity term is missing or wrong."""
    plant = Plant(terms=HydroTerms(drag="off", buoyancy=False), gravity=False, integrator="rk4", timestep=1 / 600)
    plant.set_state(base_velocity=random_qd(rng)[:3] * 2, joint_velocities=random_qd(rng)[3:] * 2)
    e0 = kinetic_energy(plant)
    assert e0 > 0.5
    parts = plant.energy()
    assert abs(parts.kinetic - e0) < 1e-12 * e0  # energy() agrees with the mass matrix
    energies = []
    for _ in range(100):
        plant.step(60)  # 0.1 s
        energies.append(kinetic_energy(plant))
    assert plant.time > 9.99
    drift = np.max(np.abs(np.array(energies) - e0)) / e0
    assert drift < 1e-8, drift
    assert np.abs(plant.qd).max() > 0.05  # it really moved


def test_energy_never_increases_with_drag(rng):
    """Drag, gravity and buoyancy on (default RK4): the total mechanical energy (kinetic + gravity
    and buoyancy potentials) is non-increasing at every step, up to 1e-10 J of integration error."""
    plant = Plant()
    plant.set_state(base_velocity=random_qd(rng)[:3] * 3, joint_velocities=random_qd(rng)[3:] * 3)
    prev = plant.energy().total
    start = prev
    for _ in range(round(5 / plant.model.opt.timestep)):  # 5 s
        plant.step(1)
        e = plant.energy().total
        assert e <= prev + 1e-10, (plant.time, e - prev)
        prev = e
    assert prev < start - 0.1  # drag dissipated a visible amount
