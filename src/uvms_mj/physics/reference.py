"""Reference implementation of the `uvms.water` / `uvms.hydro` equations, written for reading.

Every function implements one term of docs/hydrodynamics.md, with the equation in its
docstring; :func:`passive` sums the terms that are on. The C plugin is compared with this module
(1e-12), and this module with independent truths (Pinocchio, Fossen's equations, closed forms)
in tests/test_reference_hydro.py.

Conventions (docs/hydrodynamics.md):

* h is a body's hydrodynamic frame: origin ``pos`` and orientation ``quat`` in the body frame;
  p is the world position of its origin, R its world orientation.
* 6-vectors are in Fossen's order, linear first: nu = (v, w) in frame h; forces (f, m).
* nu_r = nu - (R^T v_c, 0) is the velocity relative to the water; v_c is the current plus the
  waves' particle velocity at p (:func:`water_at`), each strip seeing the waves at its midpoint.

Every function expects ``d`` to hold the kinematics of the current state:
``mj_kinematics`` + ``mj_comPos`` (+ ``mj_comVel`` for :func:`bias_acceleration` and
:func:`passive`), e.g. after ``mj_fwdPosition`` and ``mj_fwdVelocity``.

The current's state (model ``gauss_markov``) is ``current_state = (t_k, k, v_k, v_next)``:
the time of the last sample, its index, the sample v_k and the next one v_{k+1} (3 each);
:func:`as_current_state` reads it from the C plugin's ``d.plugin_state`` slice
(t_k, k, v_k, v_next, h). The sampling step h is the physics step ``m.opt.timestep``.
"""

from __future__ import annotations

import math
from typing import Mapping

import mujoco
import numpy as np

from uvms_mj.physics.config import BodyHydro, WaterParams, resolve
from uvms_mj.physics.rng import MASK, splitmix64
from uvms_mj.physics.waves import Sea, sea_of

CurrentState = tuple  # (t_k: float, k: int, v_k: (3,), v_next: (3,))


# ----------------------------------------------------------------------------- kinematics


def skew(x: np.ndarray) -> np.ndarray:
    """S(x), the matrix of the cross product: S(x) y = x x y."""
    return np.array([[0.0, -x[2], x[1]], [x[2], 0.0, -x[0]], [-x[1], x[0], 0.0]])


def _quat_to_mat(quat: np.ndarray) -> np.ndarray:
    """Rotation matrix of a unit quaternion (w x y z), by MuJoCo's ``mju_quat2Mat``.

    Kept apart from :func:`uvms_mj.rotations.quat_to_mat` (a closed form): this reference
    composes frames with MuJoCo's own routine, as the C plugin does."""
    R = np.zeros(9)
    mujoco.mju_quat2Mat(R, np.asarray(quat, float) / np.linalg.norm(quat))
    return R.reshape(3, 3)


def hydro_frame(m: mujoco.MjModel, d: mujoco.MjData, b: int, pos, quat) -> tuple[np.ndarray, np.ndarray]:
    """World position p and orientation R of frame h of body b:

        p = x_b + R_b pos,   R = R_b R(quat).
    """
    Rb = d.xmat[b].reshape(3, 3)
    return d.xpos[b] + Rb @ np.asarray(pos, float), Rb @ _quat_to_mat(quat)


def body_jacobian(m: mujoco.MjModel, d: mujoco.MjData, b: int, pos, quat) -> np.ndarray:
    """Body Jacobian of frame h (6 x nv, Fossen order), nu = J q_dot:

        J = [R^T J_p(p) ; R^T J_r]

    J_p(p) is the world translational Jacobian of the point p fixed to body b, J_r the world
    rotational Jacobian of body b (`mj_jac`).
    """
    p, R = hydro_frame(m, d, b, pos, quat)
    jacp = np.zeros((3, m.nv))
    jacr = np.zeros((3, m.nv))
    mujoco.mj_jac(m, d, jacp, jacr, p, b)
    return np.vstack([R.T @ jacp, R.T @ jacr])


def point_jacobian(m: mujoco.MjModel, d: mujoco.MjData, b: int, point_world: np.ndarray) -> np.ndarray:
    """World translational Jacobian (3 x nv) of a world point fixed to body b (`mj_jac`)."""
    jacp = np.zeros((3, m.nv))
    mujoco.mj_jac(m, d, jacp, None, np.asarray(point_world, float), b)
    return jacp


def bias_acceleration(m: mujoco.MjModel, d: mujoco.MjData, b: int, pos, quat, v_c=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Frame-h rate of nu_r at q_ddot = 0 (the "J_dot term"), for a current v_c (world):

        a = [R^T (J_p_dot q_dot) - w x v_r ; R^T (J_r_dot q_dot)]

    with v_r = R^T (J_p q_dot - v_c) and w = R^T J_r q_dot (`mj_jacDot`; needs `mj_comVel`).
    The rate of the current itself, -R^T a_c, is not included (it enters tau_A separately).
    """
    p, R = hydro_frame(m, d, b, pos, quat)
    jacp = np.zeros((3, m.nv))
    jacr = np.zeros((3, m.nv))
    mujoco.mj_jac(m, d, jacp, jacr, p, b)
    djacp = np.zeros((3, m.nv))
    djacr = np.zeros((3, m.nv))
    mujoco.mj_jacDot(m, d, djacp, djacr, p, b)
    qd = d.qvel
    v_r = R.T @ (jacp @ qd - np.asarray(v_c, float))
    w = R.T @ (jacr @ qd)
    return np.r_[R.T @ (djacp @ qd) - np.cross(w, v_r), R.T @ (djacr @ qd)]


# -------------------------------------------------------------------------------- current


def gm_normal(seed: int, k: int, c: int) -> float:
    """Standard normal n_k of component c at sample k (counter-based, Box-Muller):

        a = splitmix64(seed ^ splitmix64(6k + 2c)),  b = splitmix64(seed ^ splitmix64(6k + 2c + 1))
        u1 = ((a >> 11) + 1) 2^-53 in (0, 1],  u2 = (b >> 11) 2^-53 in [0, 1)
        n = sqrt(-2 log u1) cos(2 pi u2)
    """
    seed &= MASK
    i = (6 * k + 2 * c) & MASK
    a = splitmix64(seed ^ splitmix64(i))
    b = splitmix64(seed ^ splitmix64((i + 1) & MASK))
    u1 = ((a >> 11) + 1) * 2.0**-53
    u2 = (b >> 11) * 2.0**-53
    return math.sqrt(-2.0 * math.log(u1)) * math.cos(2.0 * math.pi * u2)


def gm_step(water: WaterParams, v_k: np.ndarray, k: int, h: float) -> np.ndarray:
    """One exact step of the bounded Gauss-Markov current (each component c):

        v_{k+1} = clip(mu + (v_k - mu) e^{-h/tau} + sigma sqrt(1 - e^{-2h/tau}) n_k, min, max)

    with n_k = gm_normal(gm_seed, k, c).
    """
    mu, sigma, tau = water.gm_mean, water.gm_sigma, water.gm_tau
    out = np.empty(3)
    for c in range(3):
        phi = math.exp(-h / tau[c])
        n = gm_normal(water.gm_seed, k, c)
        v = mu[c] + (v_k[c] - mu[c]) * phi + sigma[c] * math.sqrt(1.0 - phi * phi) * n
        out[c] = min(max(v, water.gm_min[c]), water.gm_max[c])
    return out


def initial_current_state(water: WaterParams, t0: float = 0.0, h: float | None = None) -> CurrentState:
    """The current's state at reset: (t_0, 0, v_0 = current, v_1 = gm_step(v_0, 0, h)).

    Without ``h`` the next sample is left undrawn (None); :func:`current_at` and
    :func:`advance_current_state` draw it when they know h.
    """
    v0 = np.array(water.current, float)
    return (float(t0), 0, v0, None if h is None else gm_step(water, v0, 0, h))


def as_current_state(x) -> CurrentState:
    """A current state from a flat array laid out like the C plugin's ``d.plugin_state`` slice,
    (t_k, k, v_k[3], v_next[3][, h]) (8 or 9 numbers), or a state tuple (returned as is)."""
    if isinstance(x, tuple):
        return x
    x = np.asarray(x, float)
    return (float(x[0]), int(round(x[1])), x[2:5].copy(), x[5:8].copy())


def _complete(water: WaterParams, state: CurrentState | None, h: float) -> CurrentState:
    if state is None:
        state = initial_current_state(water, 0.0, h)
    t_k, k, v_k, v_next = as_current_state(state)
    if v_next is None:
        v_next = gm_step(water, np.asarray(v_k, float), k, h)
    return (t_k, k, np.asarray(v_k, float), np.asarray(v_next, float))


def advance_current_state(water: WaterParams, state: CurrentState | None, t: float, h: float) -> CurrentState:
    """Advance the sampled current to time t: while t >= t_k + h, take the next sample
    (t_k += h, k += 1, v_k = v_next, v_next = gm_step(v_next, k, h)). A relative slack of
    1e-9 h absorbs the rounding of d.time."""
    t_k, k, v_k, v_next = _complete(water, state, h)
    while t >= t_k + h * (1.0 - 1e-9):
        t_k, k, v_k = t_k + h, k + 1, v_next
        v_next = gm_step(water, v_k, k, h)
    return (t_k, k, v_k, v_next)


def current_at(water: WaterParams, state: CurrentState | None, t: float, z: float,
               h: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Current velocity v_c and acceleration a_c (world) at time t and height z:

    * constant:     v_c = current, a_c = 0;
    * gauss_markov: linear between samples, v_c = v_k + (t - t_k) a_c, a_c = (v_{k+1} - v_k)/h
      (``state`` = (t_k, k, v_k, v_{k+1}), see :func:`initial_current_state`; None = the
      initial state at t = 0; ``h`` the sampling step = the physics step);
    * profile:      v_c(z) piecewise linear in the knots, constant beyond; a_c = 0.
    """
    if water.current_model == "constant":
        return np.array(water.current, float), np.zeros(3)
    if water.current_model == "profile":
        P = water.profile
        return np.array([np.interp(z, P[:, 0], P[:, 1 + c]) for c in range(3)]), np.zeros(3)
    if h is None:
        raise ValueError("current_at: the gauss_markov model needs the sampling step h")
    t_k, _k, v_k, v_next = _complete(water, state, h)
    a_c = (v_next - v_k) / h
    return v_k + (t - t_k) * a_c, a_c


def sea(m: mujoco.MjModel, water: WaterParams) -> Sea | None:
    """The waves of ``water`` under the model's gravity (None without waves).

    Raises:
        ValueError: waves with gravity not along -z."""
    if not water.waves.on:
        return None
    g = np.asarray(m.opt.gravity, float)
    if not (g[0] == 0.0 and g[1] == 0.0 and g[2] < 0.0):
        raise ValueError(f"uvms.water: waves need gravity along -z (opt.gravity = 0 0 -g, g > 0; got {g.tolist()})")
    return sea_of(water.waves, float(-g[2]))


def water_at(m: mujoco.MjModel, water: WaterParams, current_state: CurrentState | None, t: float,
             p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Water velocity and acceleration (world) at the point p, time t: the current
    (:func:`current_at` at z = p_z) plus the waves (:meth:`uvms_mj.physics.waves.Sea.kinematics`),

        v = v_c + v_w,   a = a_c + dv_w/dt + (grad v_w) v   (the water's material acceleration).
    """
    v_c, a_c = current_at(water, current_state, t, float(p[2]), m.opt.timestep)
    s = sea(m, water)
    if s is not None:
        v_w, a_w, grad = s.kinematics(t, p, gradient=True)
        v_c = v_c + v_w
        a_c = a_c + a_w + grad @ v_c
    return v_c, a_c


# ---------------------------------------------------------------------------------- terms


def added_mass_matrix(m: mujoco.MjModel, d: mujoco.MjData, water: WaterParams,
                      bodies: Mapping[int, BodyHydro]) -> np.ndarray:
    """Added mass in generalized coordinates (nv x nv, dense, symmetric) (Eq. 1):

        M_add = sum_b J_b^T M_A,b J_b
    """
    M = np.zeros((m.nv, m.nv))
    for b, hb in bodies.items():
        hb = resolve(m, b, hb)
        J = body_jacobian(m, d, b, hb.pos, hb.quat)
        M += J.T @ hb.added_mass @ J
    return 0.5 * (M + M.T)


def added_mass_forces(M_A: np.ndarray, nu_r: np.ndarray, a: np.ndarray, a_c_h: np.ndarray) -> np.ndarray:
    """Added-mass velocity terms in frame h (Eq. 2; Kirchhoff with a current, Fossen's
    -C_A(nu_r) nu_r, the J_dot term and the current's acceleration):

        h = (h_v, h_w) = M_A nu_r,
        tau_A = [h_v x w ; h_v x v_r + h_w x w] - M_A a + M_A [R^T a_c ; 0]

    Args:
        nu_r: (v_r, w) relative velocity in frame h; a: :func:`bias_acceleration`;
        a_c_h: R^T a_c, the current's acceleration in frame h.
    """
    v_r, w = nu_r[:3], nu_r[3:]
    hv, hw = M_A[:3] @ nu_r, M_A[3:] @ nu_r
    kirchhoff = np.r_[np.cross(hv, w), np.cross(hv, v_r) + np.cross(hw, w)]
    return kirchhoff - M_A @ a + M_A @ np.r_[a_c_h, 0.0, 0.0, 0.0]


def damping(D_L: np.ndarray, D_Q: np.ndarray, nu_r: np.ndarray) -> np.ndarray:
    """Linear and quadratic damping in frame h, element-wise (Eq. 3):

        tau_D = -(D_L + D_Q |nu_r|) nu_r
    """
    return -(D_L + D_Q * np.abs(nu_r)) * nu_r


def _poly_piece(w0: float, om: float, a: float, b: float) -> tuple[float, float]:
    """int_a^b w^2 ds and int_a^b s w^2 ds for w = w0 + om s (no sign)."""
    a2, b2 = a * a, b * b
    a3, b3 = a2 * a, b2 * b
    d1, d2, d3, d4 = b - a, b2 - a2, b3 - a3, b2 * b2 - a2 * a2
    w02, wom, om2 = w0 * w0, w0 * om, om * om
    return (w02 * d1 + wom * d2 + om2 * d3 / 3.0,
            0.5 * w02 * d2 + (2.0 / 3.0) * wom * d3 + 0.25 * om2 * d4)


def strip_integrals(w0: float, om: float, a: float, b: float) -> tuple[float, float]:
    """(int_a^b |w| w ds, int_a^b s |w| w ds) for w(s) = w0 + om s, a <= b, in closed form.

    Never divides by om except to locate the sign change s* = -w0/om, where the interval is
    split when s* lies strictly inside; each piece, of constant sign, is an exact polynomial.
    """
    if om != 0.0:
        s0 = -w0 / om
        if a < s0 < b:
            i0, i1 = _poly_piece(w0, om, a, s0)
            j0, j1 = _poly_piece(w0, om, s0, b)
            sa = 1.0 if w0 + om * a > 0 else -1.0
            return sa * (i0 - j0), sa * (i1 - j1)
    wm = w0 + om * 0.5 * (a + b)
    if wm == 0.0:
        return 0.0, 0.0
    i0, i1 = _poly_piece(w0, om, a, b)
    return (i0, i1) if wm > 0 else (-i0, -i1)


#: The two normal axes of a strip along axis 0 (x), 1 (y), 2 (z), in increasing order.
NORMALS = ((1, 2), (0, 2), (0, 1))


def strip_drag(rho: float, strips, nu_r: np.ndarray) -> np.ndarray:
    """Strip drag in frame h about its origin (Eq. 4): for a strip along the unit axis e from
    s0 to s1 and each normal axis n with coefficient c_n,

        w_n(s) = n . (v_r + s (w x e)) = w0 + om s,
        f = -(rho/2) c_n int |w_n| w_n ds  n,   m = -(rho/2) c_n int s |w_n| w_n ds  (e x n).
    """
    v_r, w = nu_r[:3], nu_r[3:]
    E = np.eye(3)
    tau = np.zeros(6)
    for axis, s0, s1, cd1, cd2 in strips:
        e = E[axis]
        we = np.cross(w, e)
        for n_idx, c in zip(NORMALS[axis], (cd1, cd2)):
            if c == 0.0:
                continue
            n = E[n_idx]
            i0, i1 = strip_integrals(float(v_r[n_idx]), float(we[n_idx]), s0, s1)
            k = 0.5 * rho * c
            tau[:3] -= k * i0 * n
            tau[3:] -= k * i1 * np.cross(e, n)
    return tau


def buoyancy(rho: float, volume: float, gravity: np.ndarray) -> np.ndarray:
    """Buoyancy force (world), applied at the centre of buoyancy (Eq. 5): f_B = -rho V g."""
    return -rho * volume * np.asarray(gravity, float)


def froude_krylov(rho: float, volume: float, a_c: np.ndarray) -> np.ndarray:
    """Froude-Krylov force of an accelerating current (world), at the centre of buoyancy
    (Eq. 6): f_FK = rho V a_c."""
    return rho * volume * np.asarray(a_c, float)


# --------------------------------------------------------------------------------- totals


def body_wrench(m: mujoco.MjModel, d: mujoco.MjData, water: WaterParams, b: int, hb: BodyHydro,
                current_state: CurrentState | None = None) -> dict[str, np.ndarray]:
    """Each term of body b (resolved BodyHydro): frame-h wrenches 'added_mass', 'damping',
    'strips' (Fossen order, about the origin of h) and world forces 'buoyancy',
    'froude_krylov' (at the centre of buoyancy); terms that are off are zero."""
    terms = water.terms
    p, R = hydro_frame(m, d, b, hb.pos, hb.quat)
    J = body_jacobian(m, d, b, hb.pos, hb.quat)
    v_c, a_c = water_at(m, water, current_state, d.time, p)
    nu_r = J @ d.qvel - np.r_[R.T @ v_c, 0.0, 0.0, 0.0]
    out = {k: np.zeros(6) for k in ("added_mass", "damping", "strips")}
    out.update({k: np.zeros(3) for k in ("buoyancy", "froude_krylov")})
    if "added_mass" in terms and np.any(hb.added_mass):
        a = bias_acceleration(m, d, b, hb.pos, hb.quat, v_c)
        out["added_mass"] = added_mass_forces(hb.added_mass, nu_r, a, R.T @ a_c)
    if "damping" in terms:
        out["damping"] = damping(hb.linear_damping, hb.quadratic_damping, nu_r)
    if "strips" in terms and hb.strips:
        s = sea(m, water)
        if s is None:
            out["strips"] = strip_drag(water.density, hb.strips, nu_r)
        else:  # each strip sees the waves at its midpoint (uniform along it), plus the current at p
            v_wp, _ = s.kinematics(d.time, p)
            for st in hb.strips:
                mid = p + R[:, st[0]] * 0.5 * (st[1] + st[2])
                v_wm, _ = s.kinematics(d.time, mid)
                nu_s = nu_r - np.r_[R.T @ (v_wm - v_wp), 0.0, 0.0, 0.0]
                out["strips"] = out["strips"] + strip_drag(water.density, (st,), nu_s)
    if "buoyancy" in terms:
        out["buoyancy"] = buoyancy(water.density, hb.volume, m.opt.gravity)
    if "froude_krylov" in terms:
        out["froude_krylov"] = froude_krylov(water.density, hb.volume, a_c)
    return out


def passive(m: mujoco.MjModel, d: mujoco.MjData, water: WaterParams, bodies: Mapping[int, BodyHydro],
            current_state: CurrentState | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Everything the water adds, for the terms in ``water.terms``:

        M_add = sum_b J_b^T M_A,b J_b                                  (if added_mass is on)
        qfrc  = sum_b J_b^T (tau_A + tau_D + tau_strip) + J_p(cob)^T (f_B + f_FK)

    Returns (M_add (nv x nv, dense symmetric), qfrc (nv,)). ``d`` must hold the kinematics,
    com positions and com velocities of the current state; ``bodies`` maps body ids to their
    BodyHydro (defaults are resolved here).
    """
    M = np.zeros((m.nv, m.nv))
    qfrc = np.zeros(m.nv)
    for b, hb in bodies.items():
        hb = resolve(m, b, hb)
        J = body_jacobian(m, d, b, hb.pos, hb.quat)
        terms = body_wrench(m, d, water, b, hb, current_state)
        if "added_mass" in water.terms:
            M += J.T @ hb.added_mass @ J
        qfrc += J.T @ (terms["added_mass"] + terms["damping"] + terms["strips"])
        cob = d.xpos[b] + d.xmat[b].reshape(3, 3) @ hb.cob
        qfrc += point_jacobian(m, d, b, cob).T @ (terms["buoyancy"] + terms["froude_krylov"])
    return 0.5 * (M + M.T), qfrc


def added_kinetic_energy(m: mujoco.MjModel, d: mujoco.MjData, water: WaterParams,
                         bodies: Mapping[int, BodyHydro], t: float | None = None,
                         current_state: CurrentState | None = None) -> float:
    """T_A = sum_b 1/2 nu_r^T M_A,b nu_r [J] with nu_r relative to the water at time t
    (default d.time)."""
    t = d.time if t is None else t
    T = 0.0
    for b, hb in bodies.items():
        hb = resolve(m, b, hb)
        p, R = hydro_frame(m, d, b, hb.pos, hb.quat)
        v_c, _ = water_at(m, water, current_state, t, p)
        nu_r = body_jacobian(m, d, b, hb.pos, hb.quat) @ d.qvel - np.r_[R.T @ v_c, 0.0, 0.0, 0.0]
        T += 0.5 * nu_r @ hb.added_mass @ nu_r
    return float(T)
