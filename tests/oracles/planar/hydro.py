"""Test oracle: hydrodynamics of the paper's planar robot in closed form (independent of the plugins).

Everything here is plain Python on floats (no numpy in the hot path: for 3 bodies the scalar
closed form is ~10x faster than generic numpy Jacobian products).

Terms (each switchable through :class:`HydroTerms`):

* **Added mass and added inertia** (exact): for each body b with body-frame added mass
  D_b = diag(m_Ax, m_Ay, I_A) acting at the box centre p_b, the added kinetic energy is
  T_A = 1/2 nu_r^T D_b nu_r, nu_r = (v_b - R_b^T v_c, omega_b), the body-frame velocity relative
  to the water (uniform current v_c). Lagrange's equations give

      Q_A = -J_b^T D_b J_b q_ddot + J_b^T (K(nu_r) - D_b a_b)

  with J_b the body Jacobian at p_b, K the Kirchhoff/Munk terms and a_b the bias acceleration
  (the "J_dot term"; docs/mujoco-notes.md). The first part goes into MuJoCo's mass matrix, the rest
  into ``qfrc_passive``. In the plane (body frame, w = omega):

      F_x = (m_Ay - m_Ax) w v_y - m_Ax a_x,   F_y = (m_Ay - m_Ax) w v_x - m_Ay a_y,
      tau = (m_Ax - m_Ay) v_x v_y   (Munk moment)

  where (a_x, a_y) is the point's acceleration at q_ddot = 0, in the body frame.
* **Drag by strip theory** (paper Eqs. 2-3): normal velocity along a strip is linear,
  w(s) = w0 + omega s, so f = -(rho/2) C_D D int |w| w ds and tau = -(rho/2) C_D D int s |w| w ds
  have the closed forms of :func:`strip_integrals`. Each body has strips along its x extent
  (flow along body y, coefficient C_Dy) and along its y extent (flow along body x, C_Dx).
* **Buoyancy** (paper Eqs. 4-5): -rho V g at the centre of buoyancy. Gravity itself, m g at the
  centre of mass, is MuJoCo's own.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from uvms_mj.physics.terms import HydroTerms  # noqa: F401  (the terms this oracle switches)
from uvms_mj.plant.params import RobotParams


# The exact strip-theory integrals (paper Eqs. 2-3) are shared with the generic 3-D reference
# (the C plugins have their own port, so the plant-vs-planar comparison stays independent).
from uvms_mj.physics.reference import strip_integrals  # noqa: E402


class HydroModel:
    """Closed-form hydrodynamics of the planar chain base -> link1 -> link2.

    Built from :class:`RobotParams` (so from the model file) and evaluated on plain floats.
    The generalized coordinates are q = (p0x, p0y, phi0, phi1, phi2) (world frame for the base
    position; relative joint angles). ``wind`` is the uniform water current (world frame, m/s).
    """

    def __init__(self, params: RobotParams, terms: HydroTerms = HydroTerms()) -> None:
        self.params = params
        self.terms = terms
        self.nv = 5
        # Flat per-body constants for the hot loop (see evaluate()).
        self._bodies = []
        for b in params.bodies:
            cx, cy = b.box_center
            hx, hy = b.box_half
            self._bodies.append(
                (
                    b.joint_offset[0], b.joint_offset[1],
                    cx, cy,
                    b.added_mass[0], b.added_mass[1], b.added_inertia,
                    0.5 * params.rho * b.drag_coef[0] * b.width,  # kx: flow along body x
                    0.5 * params.rho * b.drag_coef[1] * b.width,  # ky: flow along body y
                    cx - hx, cx + hx,  # strips along body x (flow along body y)
                    cy - hy, cy + hy,  # strips along body y (flow along body x)
                    params.rho * b.volume,
                    b.cob[0], b.cob[1],
                )
            )

    # ---------------------------------------------------------------- evaluation

    def evaluate(
        self,
        q: list[float],
        qd: list[float],
        wind: tuple[float, float] = (0.0, 0.0),
        gravity: tuple[float, float] = (0.0, -9.81),
        want_mass: bool = True,
    ) -> tuple[list[float], list[float]]:
        """Added-mass matrix and hydrodynamic generalized force at (q, qd).

        Args:
            q, qd: generalized positions and velocities (5 each).
            wind: uniform current velocity (world frame, m/s).
            gravity: gravity vector (world frame, m/s^2) used for buoyancy.
            want_mass: also return the added-mass matrix.

        Returns:
            (m_add, qfrc): ``m_add`` is the lower triangle of the 5x5 added-mass matrix
            sum_b J_b^T D_b J_b in row-major order (15 numbers: (0,0), (1,0), (1,1), (2,0) ...),
            empty if added mass is not "exact" or ``want_mass`` is false. ``qfrc`` (5) is the
            sum of the added-mass velocity terms (Kirchhoff/Munk and J_dot), strip drag and
            buoyancy, according to :attr:`terms`.
        """
        terms = self.terms
        exact_am = terms.added_mass == "exact"
        strip = terms.drag == "strip"
        buoy = terms.buoyancy
        wx, wy = wind
        gx, gy = gravity
        cos, sin = math.cos, math.sin

        Q = [0.0, 0.0, 0.0, 0.0, 0.0]
        M = [0.0] * 15 if (exact_am and want_mass) else None
        # Running chain state: origin o of the current body, its velocity and its acceleration
        # at q_ddot = 0 (world frame); absolute angle th and angular velocity w.
        ox, oy = q[0], q[1]
        ovx, ovy = qd[0], qd[1]
        oax = oay = th = w = s = 0.0
        c = 1.0
        pvx: list[float] = []  # pivot (hinge) positions o_k, world
        pvy: list[float] = []
        i = 0
        for jx, jy, cx, cy, mx, my, ia, kx, ky, xa, xb, ya, yb, rhov, bx, by in self._bodies:
            if i:
                # Move to this body's origin along the parent (still the parent's angle).
                dx = c * jx - s * jy
                dy = s * jx + c * jy
                ox += dx
                oy += dy
                ovx -= w * dy
                ovy += w * dx
                oax -= w * w * dx
                oay -= w * w * dy
            th += q[2 + i]
            w += qd[2 + i]
            c = cos(th)
            s = sin(th)
            pvx.append(ox)
            pvy.append(oy)
            fx = fy = tq = 0.0  # world force and torque about o on this body
            # Body-frame velocity of the origin relative to the water.
            rvx = ovx - wx
            rvy = ovy - wy
            ubx = c * rvx + s * rvy
            uby = c * rvy - s * rvx

            if exact_am:
                # Added-mass reference point p = o + R (cx, cy); its velocity and q_ddot = 0
                # acceleration in the body frame (v_b = u + w x cen, a_b = R^T a_o - w^2 cen).
                vbx = ubx - w * cy
                vby = uby + w * cx
                abx = c * oax + s * oay - w * w * cx
                aby = c * oay - s * oax - w * w * cy
                dm = my - mx
                fbx = dm * w * vby - mx * abx
                fby = dm * w * vbx - my * aby
                fwx = c * fbx - s * fby
                fwy = s * fbx + c * fby
                rx = c * cx - s * cy
                ry = s * cx + c * cy
                fx += fwx
                fy += fwy
                tq += rx * fwy - ry * fwx - dm * vbx * vby  # + Munk moment (m_Ax - m_Ay) v_x v_y
                if M is not None:
                    # A = R diag(mx, my) R^T; column of hinge k at p: u_k = perp(p - o_k).
                    cc, ss, cs = c * c, s * s, c * s
                    axx = mx * cc + my * ss
                    ayy = mx * ss + my * cc
                    axy = -dm * cs
                    px = ox + rx
                    py = oy + ry
                    M[0] += axx
                    M[1] += axy
                    M[2] += ayy
                    r = 3
                    for k in range(i + 1):
                        ukx = pvy[k] - py
                        uky = px - pvx[k]
                        aux = axx * ukx + axy * uky
                        auy = axy * ukx + ayy * uky
                        M[r] += aux
                        M[r + 1] += auy
                        for j in range(k + 1):
                            M[r + 2 + j] += (pvy[j] - py) * aux + (px - pvx[j]) * auy + ia
                        r += k + 3

            if strip:
                if ky:  # flow along body y; strips over x in [xa, xb]: w(x) = uby + w x
                    i0, i1 = strip_integrals(uby, w, xa, xb)
                    fbx = 0.0
                    fby = -ky * i0
                    tq -= ky * i1
                else:
                    fbx = fby = 0.0
                if kx:  # flow along body x; strips over y in [ya, yb]: w(y) = ubx - w y
                    i0, i1 = strip_integrals(ubx, -w, ya, yb)
                    fbx = -kx * i0
                    tq += kx * i1
                fx += c * fbx - s * fby
                fy += s * fbx + c * fby

            if buoy and rhov:
                fbx = -rhov * gx
                fby = -rhov * gy
                fx += fbx
                fy += fby
                tq += (c * bx - s * by) * fby - (s * bx + c * by) * fbx

            # Generalized force of the wrench (fx, fy; tq about o) on the chain: J^T at o.
            Q[0] += fx
            Q[1] += fy
            for k in range(i + 1):
                Q[2 + k] += tq + (ox - pvx[k]) * fy - (oy - pvy[k]) * fx
            i += 1
        return (M if M is not None else []), Q

    def added_kinetic_energy(self, q: list[float], qd: list[float], wind=(0.0, 0.0)) -> float:
        """T_A = sum_b 1/2 nu_r^T D_b nu_r [J] (velocities relative to the water)."""
        wx, wy = wind
        ox, oy = q[0], q[1]
        ovx, ovy = qd[0], qd[1]
        th = w = 0.0
        c, s = 1.0, 0.0
        energy = 0.0
        for i, (jx, jy, cx, cy, mx, my, ia, *_rest) in enumerate(self._bodies):
            if i > 0:
                dx = c * jx - s * jy
                dy = s * jx + c * jy
                ox += dx
                oy += dy
                ovx -= w * dy
                ovy += w * dx
            th += q[2 + i]
            w += qd[2 + i]
            c, s = math.cos(th), math.sin(th)
            rvx, rvy = ovx - wx, ovy - wy
            vbx = c * rvx + s * rvy - w * cy  # body-frame velocity of the box centre
            vby = c * rvy - s * rvx + w * cx
            energy += 0.5 * (mx * vbx * vbx + my * vby * vby + ia * w * w)
        return energy
