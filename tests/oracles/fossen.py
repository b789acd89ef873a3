"""Fossen's 6-DOF equations of one rigid body in water, written independently of MuJoCo.

T. I. Fossen, Handbook of Marine Craft Hydrodynamics and Motion Control, 2nd ed. (2021),
Ch. 3 and 6, in a body frame h with origin o (any point; here the hydrodynamic frame):

    M_RB nu_dot + C_RB(nu) nu + M_A nu_r_dot + C_A(nu_r) nu_r + D(nu_r) nu_r + g(eta) = tau

with nu = (v, w) the velocity of o and the angular velocity in frame h (linear first),
nu_r = nu - nu_c, nu_c = (R^T v_c, 0) and nu_dot the time derivative of the *components* of nu
in frame h (so nu_c_dot = (R^T a_c - w x R^T v_c, 0) for a current v_c(t) uniform in space).

* M_RB = [[m I, -m S(r_g)], [m S(r_g), I_o]], I_o = I_g - m S(r_g)^2 (Eq. 3.44);
* C(M, nu) = [[0, -S(M11 v + M12 w)], [-S(M11 v + M12 w), -S(M21 v + M22 w)]] for any
  symmetric M (Theorem 3.2 / Eq. 6.43), for C_RB(nu) with M_RB and C_A(nu_r) with M_A;
* D(nu_r) nu_r = (D_L + D_Q |nu_r|) nu_r element-wise (diagonal linear + quadratic damping);
* g(eta) = -[f_W + f_B ; r_g x f_W + r_b x f_B], f_W = R^T m g, f_B = -R^T rho V g (Eq. 4.6
  generalised to a gravity vector g);
* the Froude-Krylov force of an accelerating current, rho V R^T a_c at the centre of buoyancy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def S(x: np.ndarray) -> np.ndarray:
    """Skew-symmetric matrix: S(x) y = x x y."""
    return np.array([[0.0, -x[2], x[1]], [x[2], 0.0, -x[0]], [-x[1], x[0], 0.0]])


def quat_to_mat(q) -> np.ndarray:
    """Rotation matrix of a quaternion (w x y z), normalised here."""
    w, x, y, z = np.asarray(q, float) / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def M_RB(mass: float, r_g: np.ndarray, I_g: np.ndarray) -> np.ndarray:
    """Rigid-body mass matrix about o (r_g: centre of gravity from o; I_g: inertia about it)."""
    I_o = I_g - mass * S(r_g) @ S(r_g)
    return np.block([[mass * np.eye(3), -mass * S(r_g)], [mass * S(r_g), I_o]])


def coriolis(M: np.ndarray, nu: np.ndarray) -> np.ndarray:
    """C(nu) of a symmetric 6x6 mass matrix M (Fossen's Eq. 6.43 form)."""
    a = M[:3, :3] @ nu[:3] + M[:3, 3:] @ nu[3:]
    b = M[3:, :3] @ nu[:3] + M[3:, 3:] @ nu[3:]
    return np.block([[np.zeros((3, 3)), -S(a)], [-S(a), -S(b)]])


@dataclass
class Vessel:
    """One body, everything in its frame h."""

    mass: float
    r_g: np.ndarray     # centre of gravity, frame h
    I_g: np.ndarray     # inertia about the centre of gravity, frame h axes
    M_A: np.ndarray
    D_L: np.ndarray
    D_Q: np.ndarray
    volume: float
    r_b: np.ndarray     # centre of buoyancy, frame h
    rho: float

    def nu_dot(self, R: np.ndarray, nu: np.ndarray, v_c: np.ndarray, a_c: np.ndarray,
               gravity: np.ndarray, tau: np.ndarray | None = None) -> np.ndarray:
        """Solve the equation of motion for nu_dot (R: world orientation of h)."""
        tau = np.zeros(6) if tau is None else tau
        nu_c = np.r_[R.T @ v_c, 0, 0, 0]
        nu_c_dot = np.r_[R.T @ a_c - np.cross(nu[3:], R.T @ v_c), 0, 0, 0]
        nu_r = nu - nu_c
        Mrb = M_RB(self.mass, self.r_g, self.I_g)
        f_W = R.T @ (self.mass * gravity)
        f_B = -R.T @ (self.rho * self.volume * gravity)
        g = -np.r_[f_W + f_B, np.cross(self.r_g, f_W) + np.cross(self.r_b, f_B)]
        f_FK = R.T @ (self.rho * self.volume * a_c)
        tau_FK = np.r_[f_FK, np.cross(self.r_b, f_FK)]
        D = (self.D_L + self.D_Q * np.abs(nu_r)) * nu_r
        rhs = (tau + tau_FK - coriolis(Mrb, nu) @ nu - coriolis(self.M_A, nu_r) @ nu_r - D - g
               + self.M_A @ nu_c_dot)
        return np.linalg.solve(Mrb + self.M_A, rhs)


def composite_inertia(masses, coms, inertias) -> tuple[float, np.ndarray, np.ndarray]:
    """Mass, centre of mass and inertia about it of rigidly joined parts (one common frame)."""
    mt = float(sum(masses))
    c = sum(mi * ci for mi, ci in zip(masses, coms)) / mt
    I = np.zeros((3, 3))
    for mi, ci, Ii in zip(masses, coms, inertias):
        r = ci - c
        I += Ii + mi * (r @ r * np.eye(3) - np.outer(r, r))
    return mt, c, I
