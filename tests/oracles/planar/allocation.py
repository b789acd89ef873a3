"""Thrust allocation: base wrench -> the three thruster forces.

The allocation matrix comes from the thruster sites of the (nominal) model: thruster i at base-
frame position r_i, unit direction d_i, contributes d_i to the base-frame force and
r_i x d_i to the torque. u_B (world frame: fx, fy, tau0) is rotated into the base frame and
solved with the inverse of the 3x3 matrix (docs/paper-reading.md, "Assumptions").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from uvms_mj.plant.params import ThrusterParams


def allocation_matrix(thrusters: tuple[ThrusterParams, ...]) -> np.ndarray:
    """3x3 matrix A with (Fx, Fy, tau)_base = A @ thrusts."""
    cols = []
    for t in thrusters:
        (x, y), (dx, dy) = t.position, t.direction
        cols.append((dx, dy, x * dy - y * dx))
    A = np.array(cols).T
    if abs(np.linalg.det(A)) < 1e-9:
        raise ValueError("thruster layout cannot produce every planar wrench (singular allocation matrix)")
    return A


@dataclass(frozen=True)
class Allocation:
    """Result of allocating one wrench.

    Attributes:
        thrust: thruster commands within their limits [N].
        saturated: per thruster, whether its unconstrained command was outside its limits.
        wrench: the world-frame wrench (fx, fy, tau0) the commands really produce.
    """

    thrust: np.ndarray
    saturated: np.ndarray
    wrench: np.ndarray


class Allocator:
    """Allocate world-frame base wrenches to thrusters, with saturation.

    Args:
        thrusters: the thruster layout and limits (the nominal model's).
        mode: "clip" each thruster to its limits (default), or "scale" all commands by one
            factor so that the largest violation just fits (keeps the wrench's direction).
    """

    def __init__(self, thrusters: tuple[ThrusterParams, ...], mode: str = "clip") -> None:
        if mode not in ("clip", "scale"):
            raise ValueError(f"allocation mode = {mode!r}; allowed: clip, scale")
        self.A = allocation_matrix(thrusters)
        self.A_inv = np.linalg.inv(self.A)
        self.lo = np.array([t.force_range[0] for t in thrusters])
        self.hi = np.array([t.force_range[1] for t in thrusters])
        self.mode = mode

    def __call__(self, wrench_world, phi0: float) -> Allocation:
        fx, fy, tau = (float(v) for v in wrench_world)
        c, s = np.cos(phi0), np.sin(phi0)
        body = np.array([c * fx + s * fy, -s * fx + c * fy, tau])
        f = self.A_inv @ body
        sat = (f < self.lo) | (f > self.hi)
        if sat.any():
            if self.mode == "clip":
                f = np.clip(f, self.lo, self.hi)
            else:
                limits = np.where(f > 0, self.hi, self.lo)
                nz = f != 0
                f = f * min(1.0, float(np.min(limits[nz] / f[nz])))
        produced = self.A @ f
        world = np.array([c * produced[0] - s * produced[1], s * produced[0] + c * produced[1], produced[2]])
        return Allocation(thrust=f, saturated=sat, wrench=world)
