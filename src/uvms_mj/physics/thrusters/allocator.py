"""Saturating weighted least-squares thrust allocation: :class:`Allocator`, :class:`AllocationResult`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from uvms_mj.physics.thrusters.matrix import _finite_array

__all__ = ["DOF_NAMES", "AllocationResult", "Allocator"]

#: Names of the six wrench rows, usable in ``Allocator(dofs=...)``.
DOF_NAMES = ("x", "y", "z", "roll", "pitch", "yaw")


# ---------------------------------------------------------------------------- allocator


@dataclass(frozen=True)
class AllocationResult:
    """Result of one allocation.

    Attributes:
        thrust: (n,) thrusts within ``lo <= thrust <= hi`` [N].
        saturated: (n,) bool, thruster at one of its limits (a thruster whose limits are
            equal counts as saturated).
        wrench: the achieved wrench B_c @ thrust on the controlled rows.
        residual: tau - wrench on the controlled rows (0 when tau is attainable).
        full_wrench: B @ thrust on all rows of B (differs from ``wrench`` when ``dofs``
            selects rows).
        cost: the weighted error ||W^(1/2) (B_c u - tau)||^2 + eps ||u||^2 at the solution.
        method: ``"redistribution"`` or ``"bvls"`` (the fallback), which produced the result.
        iterations: redistribution passes (each fixes the thrusters it found out of the box).
    """

    thrust: np.ndarray
    saturated: np.ndarray
    wrench: np.ndarray
    residual: np.ndarray
    full_wrench: np.ndarray
    cost: float
    method: str
    iterations: int


def _dof_rows(dofs, m: int) -> np.ndarray:
    if dofs is None:
        return np.arange(m)
    if isinstance(dofs, (str, int, np.integer)):
        dofs = [dofs]
    rows = []
    for d in dofs:
        if isinstance(d, str):
            if d not in DOF_NAMES or m != 6:
                raise ValueError(f"dofs: {d!r}; names {DOF_NAMES} need a 6-row B (B has {m} rows)")
            rows.append(DOF_NAMES.index(d))
        elif isinstance(d, (int, np.integer)) and not isinstance(d, bool) and 0 <= int(d) < m:
            rows.append(int(d))
        else:
            raise ValueError(f"dofs: {d!r} is not a row index of B (0..{m - 1}) or a name in {DOF_NAMES}")
    if not rows or len(set(rows)) != len(rows):
        raise ValueError(f"dofs = {list(dofs)!r}: give distinct rows, at least one")
    return np.array(rows)


class Allocator:
    r"""Saturating weighted least-squares thrust allocation.

    For a desired wrench tau on the controlled rows (B_c = B[dofs]) it returns

        u = argmin_{lo <= u <= hi}  ||W^(1/2) (B_c u - tau)||^2 + eps ||u||^2.

    With the default eps = 0 this is read as the limit eps -> 0+: the smallest weighted error,
    and among several minimisers the one of smallest norm. When tau is attainable without
    limits, the unconstrained answer is the minimum-norm exact solution u = B_c^+ tau (for a
    square invertible B_c exactly B_c^-1 tau, whatever W); if it lies in the box, that is the
    result (nothing is redistributed).

    Algorithm: the classic "redistributed pseudo-inverse" (see the survey T. A. Johansen,
    T. I. Fossen, "Control allocation - a survey", Automatica 49(5), 2013), certified and, where
    it falls short, replaced by an exact bounded least squares:

    1. F = all thrusters free, S = none fixed.
    2. Solve the free thrusters against what the fixed ones leave:
       u_F = argmin ||W^(1/2) (B_F u_F - (tau - B_S u_S))||^2 + eps ||u_F||^2
       (minimum norm; numpy's SVD least squares with singular values below 1e-12 of the
       largest treated as zero, for eps > 0 on the stacked system
       [W^(1/2) B_F; sqrt(eps) I]).
    3. If every u_F is in its box: stop. Otherwise clip each out-of-box thruster to the limit
       it crossed, move it to S, and go to 2 (at most n passes; with F empty, stop).
    4. Certify: the result is feasible by construction; it is optimal iff the KKT conditions
       of the box-constrained problem hold, with g = B_c^T W (B_c u - tau) + eps u:
       g_i = 0 for free thrusters (true by step 2), g_i <= 0 at the upper limit, g_i >= 0 at
       the lower limit (relative tolerance ``tol``).
    5. If the certificate fails (the redistribution is a heuristic: it fixes thrusters that a
       true optimum would keep free, typically with redundant layouts or strong coupling),
       solve the same problem by bounded-variable least squares (scipy.optimize.lsq_linear,
       method "bvls") on [W^(1/2) B_c; sqrt(eps) I] u ~ [W^(1/2) tau; 0], then polish: fix
       the thrusters BVLS left at a limit and re-solve the free ones as in step 2 (kept if
       still feasible and no worse).
    6. With eps = 0, a redundant layout (rank B_c < n) and a thruster at a limit, the
       weighted-error minimisers may form a set; a second stage then picks its smallest-norm
       point: min ||u||^2 subject to W^(1/2) B_c u = W^(1/2) B_c u* in the box, solved by
       semismooth Newton on its dual (u = clip(B_c^T W^(1/2) l, lo, hi)), then polished
       exactly.

    The result thus always minimises the stated weighted error inside the box.

    Args:
        B: (m, n) allocation matrix (e.g. :func:`allocation_matrix`).
        lo, hi: (n,) or scalar thrust limits [N], lo <= hi (infinite allowed, NaN not).
        weights: W: None (identity), (k,) positive row weights, or (k, k) symmetric positive
            definite matrix, k = the number of controlled rows.
        dofs: the controlled rows of B: indices or names from :data:`DOF_NAMES` (e.g.
            ``("x", "y", "yaw")`` for the paper's planar robot); default all rows.
        eps: Tikhonov weight >= 0 on ||u||^2 [1/N^2 in units of the weighted error].
        tol: relative tolerance of the optimality certificate.

    Call with tau, (k,) on the controlled rows (or (m,) on all rows of B, of which the
    controlled ones are used); returns an :class:`AllocationResult`.
    """

    def __init__(self, B, lo, hi, weights=None, dofs=None, eps: float = 0.0, tol: float = 1e-9) -> None:
        B = _finite_array("B", B, ndim=2)
        m, n = B.shape
        if m == 0 or n == 0:
            raise ValueError(f"B: shape {B.shape}; needs at least one row and one thruster")
        lo = _finite_array("lo", lo, allow_inf=True)
        hi = _finite_array("hi", hi, allow_inf=True)
        for name, v in (("lo", lo), ("hi", hi)):
            if v.ndim > 1 or (v.ndim == 1 and v.shape != (n,)):
                raise ValueError(f"{name} = {v.tolist()!r}: expected a scalar or {n} values (one per thruster)")
        lo, hi = np.broadcast_to(lo, (n,)).copy(), np.broadcast_to(hi, (n,)).copy()
        if np.any(lo > hi):
            raise ValueError(f"lo = {lo.tolist()}, hi = {hi.tolist()}: need lo <= hi for every thruster")
        if np.any(lo == np.inf) or np.any(hi == -np.inf):
            raise ValueError(f"lo = {lo.tolist()}, hi = {hi.tolist()}: a limit of +inf below / -inf above is empty")
        if not (np.isfinite(eps) and eps >= 0):
            raise ValueError(f"eps = {eps!r}: must be finite and >= 0")
        if not (np.isfinite(tol) and tol > 0):
            raise ValueError(f"tol = {tol!r}: must be finite and > 0")
        rows = _dof_rows(dofs, m)
        k = rows.size
        if weights is None:
            S = np.eye(k)
        else:
            w = _finite_array("weights", weights)
            if w.shape == (k,):
                if np.any(w <= 0):
                    raise ValueError(f"weights = {w.tolist()}: must be > 0")
                S = np.diag(np.sqrt(w))
            elif w.shape == (k, k):
                if not np.allclose(w, w.T, rtol=1e-12, atol=0):
                    raise ValueError(f"weights = {w.tolist()}: matrix not symmetric")
                try:
                    S = np.linalg.cholesky(w).T  # S^T S = W
                except np.linalg.LinAlgError:
                    raise ValueError(f"weights = {w.tolist()}: matrix not positive definite") from None
            else:
                raise ValueError(f"weights: shape {w.shape}; expected ({k},) or ({k}, {k}) for {k} controlled rows")
        self.B = B
        self.rows = rows
        self.Bc = B[rows]
        self.S = S
        self.W = S.T @ S
        self.Bs = S @ self.Bc
        self.lo, self.hi = lo, hi
        self.eps = float(eps)
        self.tol = float(tol)
        self._redundant = np.linalg.matrix_rank(self.Bs) < n
        self._norm = float(np.linalg.norm(self.Bs, 2))
        # Fast path (every thruster free, the usual case): the first pass of step 2 with all
        # thrusters free is u = P t, P the minimum-norm least-squares operator (the same SVD
        # cut-off as _solve_free); when u is inside the box it is the answer (g = 0).
        A = self.Bs if self.eps == 0 else np.vstack([self.Bs, np.sqrt(self.eps) * np.eye(n)])
        P = np.linalg.pinv(A, rcond=1e-12)
        self._P_free = P[:, :k] if self.eps > 0 else P
        self._any_equal = bool(np.any(lo == hi))

    # -------------------------------------------------------------- pieces

    def _solve_free(self, A: np.ndarray, r: np.ndarray, free: np.ndarray) -> np.ndarray:
        """Minimum-norm argmin ||A[:, free] x - r||^2 + eps ||x||^2."""
        Af = A[:, free]
        if self.eps > 0:
            Af = np.vstack([Af, np.sqrt(self.eps) * np.eye(Af.shape[1])])
            r = np.r_[r, np.zeros(Af.shape[1])]
        # SVD least squares, singular values below 1e-12 of the largest treated as zero: a subset
        # of a redundant layout's columns can be singular in exact arithmetic
        return np.linalg.lstsq(Af, r, rcond=1e-12)[0]

    def _redistribute(self, A: np.ndarray, t: np.ndarray, fixed_init: np.ndarray | None = None):
        n = A.shape[1]
        u = np.zeros(n)
        free = np.ones(n, bool)
        if fixed_init is not None:
            free &= ~fixed_init[0]
            u[fixed_init[0]] = fixed_init[1][fixed_init[0]]
        equal = self.lo == self.hi
        u[equal] = self.lo[equal]
        free &= ~equal
        passes = 0
        while free.any():
            passes += 1
            u[free] = self._solve_free(A, t - A[:, ~free] @ u[~free], free)
            over, under = free & (u > self.hi), free & (u < self.lo)
            if not (over.any() or under.any()):
                break
            u[over], u[under] = self.hi[over], self.lo[under]
            free &= ~(over | under)
        return u, passes

    def _gradient(self, u: np.ndarray, t: np.ndarray) -> np.ndarray:
        return self.Bs.T @ (self.Bs @ u - t) + self.eps * u

    def _kkt_ok(self, u: np.ndarray, t: np.ndarray) -> bool:
        g = self._gradient(u, t)
        scale = self._norm * (np.linalg.norm(t) + self._norm * np.linalg.norm(u)) + self.eps * np.linalg.norm(u) + 1e-300
        gt = self.tol * scale
        at_hi, at_lo = u >= self.hi, u <= self.lo
        free = ~(at_hi | at_lo)
        return bool(np.all(np.abs(g[free]) <= gt) and np.all(g[at_hi & ~at_lo] <= gt)
                    and np.all(g[at_lo & ~at_hi] >= -gt))

    def _cost(self, u: np.ndarray, t: np.ndarray) -> float:
        e = self.Bs @ u - t
        return float(e @ e + self.eps * (u @ u))

    def _bvls(self, A: np.ndarray, b: np.ndarray) -> np.ndarray:
        fixed = self.lo == self.hi
        u = self.lo.copy()
        if (~fixed).any():
            Af = A[:, ~fixed]
            bf = b - A[:, fixed] @ self.lo[fixed]
            from scipy.optimize import lsq_linear  # here: scipy costs ~0.5 s to import, rarely needed

            res = lsq_linear(Af, bf, bounds=(self.lo[~fixed], self.hi[~fixed]), method="bvls", tol=1e-14,
                             lsq_solver="exact")
            u[~fixed] = np.clip(res.x, self.lo[~fixed], self.hi[~fixed])
        return u

    def _polish(self, A: np.ndarray, t: np.ndarray, u: np.ndarray, rel: float = 1e-9) -> np.ndarray:
        """Fix the thrusters at (or within rel of the box size of) a limit, re-solve the rest."""
        span = np.where(np.isfinite(self.hi - self.lo), self.hi - self.lo, 1.0)
        at_lo, at_hi = u - self.lo <= rel * span, self.hi - u <= rel * span
        fixed = at_lo | at_hi
        target = np.where(at_hi, self.hi, self.lo)
        v, _ = self._redistribute(A, t, (fixed, target))
        return v

    # -------------------------------------------------------------- call

    def __call__(self, tau) -> AllocationResult:
        tau = _finite_array("tau", tau, ndim=1)
        k = self.rows.size
        if tau.shape == (self.B.shape[0],) and tau.shape != (k,):
            tau = tau[self.rows]
        if tau.shape != (k,):
            raise ValueError(f"tau = {tau.tolist()}: expected {k} values (the controlled rows)")
        t = self.S @ tau
        if not self._any_equal:
            u = self._P_free @ t
            if np.all(u <= self.hi) and np.all(u >= self.lo):
                wrench = self.Bc @ u
                return AllocationResult(thrust=u, saturated=np.zeros(u.size, bool), wrench=wrench,
                                        residual=tau - wrench, full_wrench=self.B @ u, cost=self._cost(u, t),
                                        method="redistribution", iterations=1)
        u, passes = self._redistribute(self.Bs, t)
        method = "redistribution"
        if not self._kkt_ok(u, t):
            method = "bvls"
            A, b = self.Bs, t
            if self.eps > 0:
                n = self.Bs.shape[1]
                A, b = np.vstack([A, np.sqrt(self.eps) * np.eye(n)]), np.r_[b, np.zeros(n)]
            v = self._bvls(A, b)
            p = self._polish(self.Bs, t, v)
            if np.all(p >= self.lo) and np.all(p <= self.hi) and self._cost(p, t) <= self._cost(v, t):
                v = p
            u = v
        if self.eps == 0 and self._redundant and np.any((u <= self.lo) | (u >= self.hi)):
            u = self._min_norm(u)  # several error minimisers possible: take the smallest norm
        wrench = self.Bc @ u
        sat = (u <= self.lo) | (u >= self.hi)
        return AllocationResult(thrust=u, saturated=sat, wrench=wrench, residual=tau - wrench,
                                full_wrench=self.B @ u, cost=self._cost(u, t), method=method, iterations=passes)

    def _min_norm(self, u: np.ndarray) -> np.ndarray:
        """Second stage (eps = 0, redundant layout): the smallest-norm v in the box with the same
        weighted wrench y = W^(1/2) B_c u as the error minimiser u.

        Solved through its dual: min 1/2 ||v||^2 s.t. A v = y, lo <= v <= hi (A = W^(1/2) B_c)
        has v(l) = clip(A^T l, lo, hi) and the concave, piecewise-quadratic dual
        q(l) = 1/2 ||v(l)||^2 - l.(A v(l) - y) with gradient y - A v(l); maximised by
        semismooth Newton steps (generalised Hessian -A_F A_F^T over the unclipped F) with
        Armijo backtracking, then polished exactly (clipped thrusters fixed, the others the
        minimum-norm exact solution). Kept only if feasible, as exact and not larger."""
        A = self.Bs
        y = A @ u
        lo, hi = self.lo, self.hi
        inside = (u > lo) & (u < hi)
        lam = np.linalg.lstsq(A[:, inside].T, u[inside], rcond=None)[0] if inside.any() else np.zeros(A.shape[0])
        ytol = 1e-13 * (1.0 + np.linalg.norm(y))

        def q(l):
            v = np.clip(A.T @ l, lo, hi)
            return 0.5 * (v @ v) - l @ (A @ v - y), v

        qv, v = q(lam)
        for _ in range(100):
            grad = y - A @ v
            if np.linalg.norm(grad) <= ytol:
                break
            z = A.T @ lam
            F = (z > lo) & (z < hi)
            H = A[:, F] @ A[:, F].T + 1e-12 * self._norm ** 2 * np.eye(A.shape[0])
            step = np.linalg.lstsq(H, grad, rcond=None)[0]
            alpha, slope = 1.0, grad @ step
            while alpha > 1e-12:
                qn, vn = q(lam + alpha * step)
                if qn >= qv + 1e-4 * alpha * slope:
                    break
                alpha *= 0.5
            else:
                break
            lam, qv, v = lam + alpha * step, qn, vn
        p = self._polish(A, y, v)
        e = A @ p - y
        if np.all(p >= lo) and np.all(p <= hi) and np.linalg.norm(e) <= max(ytol, np.linalg.norm(A @ u - y)) * 10 \
                and p @ p <= u @ u:
            return p
        return u
