"""The task space of ``rac`` / ``rac_dob`` (:class:`uvms_mj.control.rac.RAC`): the task vector
p = (base, tip) and its Jacobian, differences on the rotation manifold, and the desired task
p_d(k) -- the base reference plus Eq. 12's offset, the tip path read in blocks -- with Eq. 12's
carry velocities (``cruise``: the path's velocity at the event; ``path``: its step per sample).

A mixin of :class:`~uvms_mj.control.rac.RAC`, kept apart to keep the controller's module short;
its methods read the controller's attributes (``free``, ``robot``, ``trajectory``, ``T``, ...)
set in ``RAC.__init__`` / ``RAC.reset``.
"""

from __future__ import annotations

import numpy as np

from uvms_mj.rotations import quat_to_mat, rotation_log

__all__ = ["TIP_BLOCK", "RACTaskSpace"]

#: Samples of desired tip positions evaluated at once (:meth:`RACTaskSpace._tip_k`).
TIP_BLOCK = 600


class RACTaskSpace:
    """The task-space methods of :class:`uvms_mj.control.rac.RAC` (module docstring)."""

    def _base_jac(self, jac: dict) -> np.ndarray:
        """(6, nb): world linear and angular velocity of the vehicle origin per base dof."""
        return np.vstack((jac["base_p"], jac["base_r"]))[:, self.base_dofs]

    def _task(self, q: np.ndarray, jac: dict) -> tuple[np.ndarray, list[np.ndarray]]:
        """p as (vector part, rotation matrices): planar (base coords, tip rows); floating
        (base position, tip position; rotations R_base [, R_tip])."""
        if self.free:
            a = self.robot.layout.base_qadr
            vec = np.concatenate((q[a:a + 3], jac["tip"]))
            rots = [quat_to_mat(q[a + 3:a + 7])] + ([jac["R_tip"]] if self.tip_orientation else [])
            return vec, rots
        return np.concatenate((q[self.base_qpos], jac["tip"][self.tip_rows])), []

    def _diff(self, a: tuple, b: tuple) -> np.ndarray:
        """a - b in the task space (rotation parts: log(R_a R_b^T), world axes)."""
        (va, ra), (vb, rb) = a, b
        if not self.free:
            return va - vb
        out = np.empty(self.ntask)
        out[0:3] = va[0:3] - vb[0:3]
        out[3:6] = 0.0 if ra[0] is rb[0] else rotation_log(ra[0] @ rb[0].T)  # same desired attitude: 0
        out[6:9] = va[3:6] - vb[3:6]
        if self.tip_orientation:
            out[9:12] = 0.0 if ra[1] is rb[1] else rotation_log(ra[1] @ rb[1].T)
        return out

    def _jacobian(self, jac: dict) -> np.ndarray:
        if self.free:
            rows = [jac["base_p"], jac["base_r"], jac["tip_p"]] + ([jac["tip_r"]] if self.tip_orientation else [])
            return np.vstack(rows)
        J = self._J_template.copy()  # base rows: the identity on the base dofs
        J[self.base_dofs.size:] = jac["tip_p"][self.tip_rows]
        return J

    def _desired(self, k: int) -> tuple[np.ndarray, list[np.ndarray]]:
        """p_d(k): base reference plus the Eq. 12 offset, and the tip path."""
        t = k * self.T
        off = self._base_offset[k]
        tip = self._tip_k(k)
        cache = self._base_d
        if self.base_trajectory is not None:  # a moving base reference: the path's position at t
            path = np.asarray(self.base_trajectory.position(t), dtype=float).ravel()
            base = self._ref_pos.copy()
            if self.free:
                base[:3] = path[:3] + off
            else:
                base[self.lin] = (path[self.tip_rows] if path.size == 3 else path[: self.lin.size]) + off
            cache = (off, base)
        elif cache is None or cache[0] is not off:  # the base's desired part: new only when the offset is
            if self.free:
                base = self._ref_pos + off
            else:
                base = self._ref_pos.copy()
                base[self.lin] += off
            cache = self._base_d = (off, base)
        vec = np.concatenate((cache[1], tip))
        if self.free:
            return vec, [self._ref_R] + ([self._tip_R_d(t)] if self.tip_orientation else [])
        return vec, []

    def _tip_k(self, k: int) -> np.ndarray:
        """The desired tip at sample k (:meth:`_tip_d` at t = k T): read from blocks of
        ``TIP_BLOCK`` samples where the trajectory has ``positions(ts)`` (position at each time,
        the same numbers bit for bit, where a trajectory offers it)."""
        blk = self._tip_blk
        if blk is not None and 0 <= k - blk[0] < len(blk[1]):
            return blk[1][k - blk[0]]
        positions = getattr(self.trajectory, "positions", None)
        if positions is None:
            return self._tip_d(k * self.T)
        P = np.asarray(positions(np.arange(k, k + TIP_BLOCK) * self.T), dtype=float)  # (float(k) T, as k * T)
        P = P[:, :3] if self.free else (P[:, self.tip_rows] if P.shape[1] == 3 else P[:, :self.tip_rows.size])
        self._tip_blk = (k, P)
        return P[0]

    def _tip_d(self, t: float) -> np.ndarray:
        if self.trajectory is None:
            return self._tip0.copy()
        p = self.trajectory.position(t)
        if not (type(p) is np.ndarray and p.ndim == 1 and p.dtype == np.float64):
            p = np.asarray(p, dtype=float).ravel()
        if self.free:
            return p[:3]
        return p[self.tip_rows] if p.size == 3 else p[: self.tip_rows.size]

    def _tip_R_d(self, t: float) -> np.ndarray:
        tr = self.trajectory
        if tr is not None and getattr(tr, "has_orientation", False):
            return quat_to_mat(tr.orientation(t))
        return self._tip_R0

    def _v_event(self, k: int) -> np.ndarray:
        tr = self.trajectory
        if tr is None:
            v = np.zeros(3)
        elif hasattr(tr, "cruise_velocity"):
            v = np.asarray(tr.cruise_velocity(), dtype=float).ravel()
        else:
            v = np.asarray(tr.velocity(k * self.T), dtype=float).ravel()
        if self.free:
            return np.resize(v, 3) if v.size != 3 else v
        n = self.lin.size
        return v[self.tip_rows] if v.size == 3 else v[:n]

    def _v_path(self, k: int) -> np.ndarray:
        """The tip path's velocity over [k, k+1): (p_d(k+1) - p_d(k)) / T (world [m/s]; planar:
        the tip rows), Eq. 12's carry velocity with ``carry = "path"``: the base offset then
        moves by exactly the path's step, so the arm keeps the posture it had."""
        return (self._tip_k(k + 1) - self._tip_k(k)) / self.T
