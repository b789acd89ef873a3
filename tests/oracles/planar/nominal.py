"""The controller's nominal model (paper Eqs. 6-7), independent of MuJoCo.

Analytic planar functions of the nominal parameters (:class:`~uvms_mj.plant.params.RobotParams`;
by default read from the model *file*, i.e. Table 1 and our documented assumptions, never from a
running plant). Constant added mass, added inertia and drag coefficients, still water.

Eq. 6:  M(q) q_ddot + N(q, q_dot) q_dot + f_D + g = u,  u = (fx, fy, tau0, tau1, tau2)

(the paper writes the gravity/buoyancy term of Eqs. 4-5 on the left like f_D). ``bias(q, qd)``
returns h = N q_dot + f_D + g, so u = M q_ddot + h. Block split (Eq. 7): base rows B = (0, 1, 2),
arm rows M = (3, 4).
"""

from __future__ import annotations

import ctypes
import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from uvms_mj.physics import build as _build
from oracles.planar import native as _native
from uvms_mj.physics.terms import default_backend
from oracles.planar.hydro import HydroModel
from uvms_mj.physics.terms import HydroTerms
from oracles.planar.kinematics import ArmGeometry
from uvms_mj.plant.params import RobotParams, read_params

_TRIL = np.tril_indices(5)

B = slice(0, 3)  # base rows/columns (fx, fy, tau0)
M_ = slice(3, 5)  # arm rows/columns (tau1, tau2)


def params_from_file(path: str | Path | None = None) -> RobotParams:
    """Read nominal parameters from a model file (default: the package's models/uvms.xml).

    Only the file is read: the nominal model never sees a running plant's parameters."""
    from uvms_mj.plant.params import compile_robot

    return read_params(compile_robot(path))


@dataclass(frozen=True)
class Dynamics:
    """Nominal dynamics at one state: u = M q_ddot + h (all generalized, world frame for the base)."""

    M: np.ndarray  # 5x5
    h: np.ndarray  # 5: N q_dot + f_D + g

    def blocks(self):
        """(M_BB, M_BM, M_MB, M_MM, h_B, h_M) of Eq. 7."""
        M, h = self.M, self.h
        return M[B, B], M[B, M_], M[M_, B], M[M_, M_], h[B], h[M_]


def rigid_as_hydro(params: RobotParams) -> RobotParams:
    """The rigid bodies written as "isotropic added mass" at their centres of mass, with their
    weight as a negative buoyancy there: a rigid body of mass m and inertia I has exactly the
    kinetic energy, Coriolis/centrifugal force and weight that :class:`HydroModel` gives an
    isotropic added mass (m, m, I) and a volume -m/rho at its centre of mass, so one closed form
    serves both parts of the nominal dynamics."""
    bodies = tuple(
        replace(b, added_mass=(b.mass, b.mass), added_inertia=b.inertia, box_center=b.com,
                drag_coef=(0.0, 0.0), volume=-b.mass / params.rho, cob=b.com)
        for b in params.bodies
    )
    return replace(params, bodies=bodies)


class _Evaluator:
    """HydroModel.evaluate on preallocated buffers: the native C code when it is available (and
    not disabled by UVMS_MJ_COMPILED=off), else the Python reference. Returns numpy arrays:
    the 5x5 matrix and the generalized force."""

    def __init__(self, hydro: HydroModel) -> None:
        self.hydro = hydro
        self.lib = None
        if default_backend() != "python":  # UVMS_MJ_COMPILED (physics.build.compiled_mode)
            self.lib = _native.load_native()
            if self.lib is None:
                _build.fallback("the planar nominal model's C code", _native.native_unavailable_reason() or "")
        if self.lib is not None:
            self.params = _native.make_params(hydro)
            self.buf = {k: np.zeros(n) for k, n in (("q", 5), ("qd", 5), ("w", 2), ("g", 2), ("m", 15), ("f", 5))}
            dp = ctypes.POINTER(ctypes.c_double)
            self.ptr = {k: v.ctypes.data_as(dp) for k, v in self.buf.items()}
            self.fn = self.lib._lib.uvms_evaluate
            self.pref = ctypes.byref(self.params)

    def __call__(self, q, qd, wind, gravity) -> tuple[np.ndarray, np.ndarray]:
        if self.lib is None:
            madd, qf = self.hydro.evaluate(list(map(float, q)), list(map(float, qd)), wind, gravity, True)
            m = np.asarray(madd) if madd else np.zeros(15)
            qf = np.asarray(qf)
        else:
            b, p = self.buf, self.ptr
            b["q"][:] = q
            b["qd"][:] = qd
            b["w"][:] = wind
            b["g"][:] = gravity
            b["m"][:] = 0.0  # the C function accumulates into its outputs
            b["f"][:] = 0.0
            self.fn(self.pref, p["q"], p["qd"], p["w"], p["g"], p["m"] if self.params.exact else None, p["f"])
            m, qf = (b["m"] if self.params.exact else np.zeros(15)), b["f"].copy()
        M = np.zeros((5, 5))
        M[_TRIL] = m
        M.T[_TRIL] = m
        return M, qf


class NominalModel:
    """M̄(q), N̄(q, q̇)q̇, f̄_D and ḡ of the paper's Eqs. 6-7 for given nominal parameters.

    Args:
        params: nominal robot parameters (default: :func:`params_from_file`).
        gravity: world gravity (x, y) [m/s^2]; default the model file's.
    """

    def __init__(self, params: RobotParams | None = None, gravity: tuple[float, float] | None = None) -> None:
        self.params = params or params_from_file()
        self.gravity = tuple(gravity) if gravity is not None else self.params.gravity
        self.geometry = ArmGeometry.from_params(self.params)
        # Hydrodynamic parts in closed form (the same closed form as the plant's ground truth,
        # evaluated with the nominal constants and still water).
        self._am = HydroModel(self.params, HydroTerms(added_mass="exact", drag="off", buoyancy=False))
        self._drag = HydroModel(self.params, HydroTerms(added_mass="off", drag="strip", buoyancy=False))
        self._buoy = HydroModel(self.params, HydroTerms(added_mass="off", drag="off", buoyancy=True))
        # Fast path for dynamics(): rigid part (see rigid_as_hydro) and hydrodynamic part.
        self._fast_rigid = _Evaluator(HydroModel(rigid_as_hydro(self.params), HydroTerms(drag="off")))
        self._fast_hydro = _Evaluator(HydroModel(self.params, HydroTerms()))

    # ---------------------------------------------------------------- rigid chain

    def _points(self, q, qd):
        """Per body: (CoM position, CoM velocity, CoM acceleration at q_ddot = 0, hinge pivots),
        world frame."""
        out = []
        ox, oy = float(q[0]), float(q[1])
        ovx, ovy = float(qd[0]), float(qd[1])
        oax = oay = th = w = 0.0
        c, s = 1.0, 0.0
        pivots = []
        for i, b in enumerate(self.params.bodies):
            if i:
                jx, jy = b.joint_offset
                dx, dy = c * jx - s * jy, s * jx + c * jy
                ox, oy = ox + dx, oy + dy
                ovx, ovy = ovx - w * dy, ovy + w * dx
                oax, oay = oax - w * w * dx, oay - w * w * dy
            th += float(q[2 + i])
            w += float(qd[2 + i])
            c, s = math.cos(th), math.sin(th)
            pivots.append((ox, oy))
            rx = c * b.com[0] - s * b.com[1]
            ry = s * b.com[0] + c * b.com[1]
            out.append(((ox + rx, oy + ry), (oax - w * w * rx, oay - w * w * ry), list(pivots)))
        return out

    @staticmethod
    def _jacobian(point, pivots) -> np.ndarray:
        """2x5 world Jacobian of a point on the body whose hinges are ``pivots``."""
        J = np.zeros((2, 5))
        J[0, 0] = J[1, 1] = 1.0
        for k, (px, py) in enumerate(pivots):
            J[0, 2 + k] = -(point[1] - py)
            J[1, 2 + k] = point[0] - px
        return J

    # ---------------------------------------------------------------- public

    def mass_matrix(self, q) -> np.ndarray:
        """M̄(q): rigid bodies plus constant added mass and inertia (5x5)."""
        M = np.zeros((5, 5))
        for b, (com, _, pivots) in zip(self.params.bodies, self._points(q, np.zeros(5))):
            J = self._jacobian(com, pivots)
            Jw = np.zeros(5)
            Jw[2 : 2 + len(pivots)] = 1.0
            M += b.mass * J.T @ J + b.inertia * np.outer(Jw, Jw)
        madd, _ = self._am.evaluate(list(map(float, q)), [0.0] * 5)
        A = np.zeros((5, 5))
        A[np.tril_indices(5)] = madd
        return M + A + np.tril(A, -1).T

    def coriolis(self, q, qd) -> np.ndarray:
        """N̄(q, q̇) q̇: rigid and added-mass Coriolis/centrifugal (incl. Munk) terms."""
        h = np.zeros(5)
        for b, (com, acc, pivots) in zip(self.params.bodies, self._points(q, qd)):
            h += b.mass * self._jacobian(com, pivots).T @ np.asarray(acc)
        _, qf = self._am.evaluate(list(map(float, q)), list(map(float, qd)), want_mass=False)
        return h - np.asarray(qf)  # the added-mass velocity force moves to the left-hand side

    def drag(self, q, qd) -> np.ndarray:
        """f̄_D: strip drag (Eqs. 2-3) as it appears on the left of Eq. 6 (still water)."""
        _, qf = self._drag.evaluate(list(map(float, q)), list(map(float, qd)), want_mass=False)
        return -np.asarray(qf)

    def gravity_buoyancy(self, q) -> np.ndarray:
        """ḡ: gravity and buoyancy (Eqs. 4-5) as they appear on the left of Eq. 6."""
        g = np.asarray(self.gravity)
        Q = np.zeros(5)
        for b, (com, _, pivots) in zip(self.params.bodies, self._points(q, np.zeros(5))):
            Q += self._jacobian(com, pivots).T @ (b.mass * g)
        _, qf = self._buoy.evaluate(list(map(float, q)), [0.0] * 5, gravity=self.gravity, want_mass=False)
        return -(Q + np.asarray(qf))

    def bias(self, q, qd) -> np.ndarray:
        """h = N̄ q̇ + f̄_D + ḡ."""
        return self.coriolis(q, qd) + self.drag(q, qd) + self.gravity_buoyancy(q)

    def dynamics(self, q, qd) -> Dynamics:
        """M̄(q) and h = N̄q̇ + f̄_D + ḡ in one pass (the controller's 60 Hz path; equals
        mass_matrix() and bias(), which spell the terms out separately)."""
        M1, Q1 = self._fast_rigid(q, qd, (0.0, 0.0), self.gravity)
        M2, Q2 = self._fast_hydro(q, qd, (0.0, 0.0), self.gravity)
        return Dynamics(M1 + M2, -(Q1 + Q2))
