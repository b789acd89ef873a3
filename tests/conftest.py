"""Shared helpers for the validation suite.

Every physics test compares the plant with an independent truth (analytic solution, quadrature,
finite-difference Lagrangian, MuJoCo's own Jacobians, energy balance); tolerances are stated
next to each assertion.
"""

from __future__ import annotations

import os

import mujoco
import numpy as np
import pytest

from oracles.planar.rac import register_oracles
from uvms_mj import Plant
from uvms_mj.physics import build as _build

# The arm's largest manipulability searched in every test (no disk cache shared with the user's runs).
os.environ["UVMS_MJ_MANIPULABILITY_CACHE"] = "off"

register_oracles()  # the planar closed-form RAC as controllers rac_planar, rac_dob_planar (tests only)

# The uvms plugins registered once for the suite: uvms_mj's loaders do it on first use (not
# `import uvms_mj`), and some tests hand model files to plain MuJoCo first.
_build.register_plugins()

#: Overrides that make the arm dynamically negligible (1e-6 kg, no hydrodynamics): the base then
#: behaves as a base-only model to ~1e-8 relative (arm/base mass ratio), well inside the
#: tolerances of the tests that use it.
DECOUPLED_ARM = {
    f"{link}.{key}": value
    for link in ("link1", "link2")
    for key, value in (
        ("mass", 1e-6),
        ("inertia", 1e-9),
        ("added_mass", [0.0, 0.0, 0.0]),
        ("drag_coef", [0.0, 0.0]),
        ("volume", 0.0),
    )
}


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20261122)


def random_q(rng: np.random.Generator) -> np.ndarray:
    """A random configuration: base within 1 m of the origin, any angles."""
    return np.r_[rng.uniform(-1, 1, 2), rng.uniform(-np.pi, np.pi, 3)]


def random_qd(rng: np.random.Generator, scale: float = 1.0) -> np.ndarray:
    """A random velocity: base up to 0.3 m/s and 0.5 rad/s, joints up to 1 rad/s (x scale)."""
    return scale * np.r_[rng.uniform(-0.3, 0.3, 2), rng.uniform(-0.5, 0.5), rng.uniform(-1, 1, 2)]


def kinematics_only(plant: Plant, q: np.ndarray) -> mujoco.MjData:
    """A fresh MjData at configuration q with kinematics and CoM quantities computed by MuJoCo
    (no passive stage, so no hydrodynamics and no callback involved)."""
    d = mujoco.MjData(plant.model)
    d.qpos[:] = q
    mujoco.mj_kinematics(plant.model, d)
    mujoco.mj_comPos(plant.model, d)
    return d


def point_jacobian(plant: Plant, d: mujoco.MjData, point: np.ndarray, body: str) -> tuple[np.ndarray, np.ndarray]:
    """MuJoCo's translational (2x5, world x/y) and rotational (1x5, about z) Jacobians of a point."""
    jacp = np.zeros((3, plant.model.nv))
    jacr = np.zeros((3, plant.model.nv))
    mujoco.mj_jac(plant.model, d, jacp, jacr, point, plant.model.body(body).id)
    return jacp[:2], jacr[2:3]


@pytest.fixture(scope="session")
def native_available() -> bool:
    """Whether the C plugins could be built and registered here (else tests of them skip)."""
    from uvms_mj.physics import build

    return build.register_plugins()


def added_and_passive(m: mujoco.MjModel, d: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
    """(added-mass matrix, generalized force) that the water adds at d's state: the full M after
    mj_forward minus the rigid M of mj_fwdPosition (no passive stage), and qfrc_passive (for
    models with no springs, joint damping or MuJoCo fluid forces, all of it is the water's)."""
    mujoco.mj_fwdPosition(m, d)
    rigid = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, rigid)
    mujoco.mj_forward(m, d)
    full = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, full)
    return full - rigid, d.qfrc_passive.copy()


def run_logs(folder, specs) -> dict:
    """``uvms-mj run SCENARIO -o FOLDER/NAME.mcap --set duration=D`` (no plots, no video) for each
    (name, scenario, duration) of ``specs``: name -> the log's path."""
    from click.testing import CliRunner

    from uvms_mj.cli.main import main

    out = {}
    for name, scenario, duration in specs:
        path = folder / f"{name}.mcap"
        result = CliRunner().invoke(main, ["run", scenario, "-o", str(path), "--no-plots", "--no-video",
                                           "--set", f"duration={duration}"])
        assert result.exit_code == 0, result.output
        out[name] = path
    return out
