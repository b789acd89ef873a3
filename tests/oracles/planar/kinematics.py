"""Analytic planar kinematics of the robot (paper Eq. 1), independent of MuJoCo.

q = (p0x, p0y, phi0, phi1, phi2): base position (world, m), base attitude and relative joint
angles (rad, counter-clockwise positive). Absolute link angles theta1 = phi0 + phi1,
theta2 = theta1 + phi2. Joint 1 sits at ``joint1`` in the base frame.

Eq. 1: pe_dot = A x0_dot + B phi_dot, with A in R^{2x3} and B (the arm Jacobian) in R^{2x2};
det B = l1 l2 sin(phi2). The task-space Jacobian is J = [[I3, 0], [A, B]] (p_dot = J q_dot with
p = (x0, pe)).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from uvms_mj.plant.params import RobotParams


@dataclass(frozen=True)
class ArmGeometry:
    """Lengths that fix the kinematics [m].

    Attributes:
        joint1: joint-1 position (x, y) in the base frame.
        l1: joint 1 to joint 2.
        l2: joint 2 to the end tip.
    """

    joint1: tuple[float, float]
    l1: float
    l2: float

    @classmethod
    def from_params(cls, params: RobotParams) -> "ArmGeometry":
        l1, l2 = params.link_lengths
        return cls(joint1=params.joint1_offset, l1=l1, l2=l2)


def tip_position(geom: ArmGeometry, q) -> np.ndarray:
    """End-tip position pe (world frame, m)."""
    x, y, p0, p1, p2 = (float(v) for v in q)
    t1, t2 = p0 + p1, p0 + p1 + p2
    c0, s0 = math.cos(p0), math.sin(p0)
    jx, jy = geom.joint1
    return np.array(
        [
            x + c0 * jx - s0 * jy + geom.l1 * math.cos(t1) + geom.l2 * math.cos(t2),
            y + s0 * jx + c0 * jy + geom.l1 * math.sin(t1) + geom.l2 * math.sin(t2),
        ]
    )


def jacobians(geom: ArmGeometry, q) -> tuple[np.ndarray, np.ndarray]:
    """A (2x3) and B (2x2) of Eq. 1 at q."""
    _, _, p0, p1, p2 = (float(v) for v in q)
    t1, t2 = p0 + p1, p0 + p1 + p2
    c0, s0 = math.cos(p0), math.sin(p0)
    jx, jy = geom.joint1
    c1, s1, c2, s2 = math.cos(t1), math.sin(t1), math.cos(t2), math.sin(t2)
    bx = -geom.l1 * s1 - geom.l2 * s2  # d pe / d theta1 (x)
    by = geom.l1 * c1 + geom.l2 * c2
    A = np.array([[1.0, 0.0, -(s0 * jx + c0 * jy) + bx], [0.0, 1.0, (c0 * jx - s0 * jy) + by]])
    B = np.array([[bx, -geom.l2 * s2], [by, geom.l2 * c2]])
    return A, B


def det_b(geom: ArmGeometry, q) -> float:
    """det B = l1 l2 sin(phi2) (the paper's J(k), Eq. 12)."""
    return geom.l1 * geom.l2 * math.sin(float(q[4]))


def task_jacobian(geom: ArmGeometry, q) -> np.ndarray:
    """J(q) = [[I3, 0], [A, B]] (5x5): p_dot = J q_dot with p = (x0, pe)."""
    A, B = jacobians(geom, q)
    J = np.zeros((5, 5))
    J[:3, :3] = np.eye(3)
    J[3:, :3] = A
    J[3:, 3:] = B
    return J
