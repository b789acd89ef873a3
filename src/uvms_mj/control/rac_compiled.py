"""``rac`` / ``rac_dob`` through the compiled kernel: the samples of
:class:`uvms_mj.control.rac.RAC` run in C (:mod:`uvms_mj.control.kernel`) where it is available,
with the Python code's numbers to round-off (tests/test_rac_kernel.py).

:class:`CompiledSamples` is the part of RAC that loads the kernel's workspace from the state
:meth:`RAC.reset` set, runs a sample through it and unpacks its results; it uses RAC's
attributes (``robot``, ``free``, the task sizes, gains, filters, the Eq. 12 handler).
"""

from __future__ import annotations

import numpy as np

from uvms_mj.control.base import Command, Measurement

__all__ = ["CompiledSamples", "RESULTS_CHUNK"]

#: Samples of the compiled kernel's results held in one array (:meth:`CompiledSamples._result_row`).
RESULTS_CHUNK = 600


class CompiledSamples:
    """The compiled path of :class:`uvms_mj.control.rac.RAC` (module docstring)."""

    def _kernel_workspace(self):
        """The compiled kernel's workspace for this run, loaded with the state that
        :meth:`reset` set, or None where the Python code runs (no kernel, the Python hydrodynamics
        backend, a planar base whose Jacobian is not constant, a robot beyond the kernel's sizes, a
        moving base reference)."""
        from uvms_mj.control import kernel as _k

        r = self.robot
        lib = _k.library()
        if (lib is None or getattr(r, "_served", None) is not None or (not self.free and self._Jb_const is None)
                or getattr(self, "base_trajectory", None) is not None):  # a moving base reference: Python
            return None
        m, lay = r.model, r.layout
        nb, na = self.base_dofs.size, self.arm_dofs.size
        ntr = self.ntask - self.nbt
        nvec = 6 if self.free else self.ntask
        sizes = {"nq": m.nq, "nv": m.nv, "nb": nb, "na": na, "ntask": self.ntask, "nbt": self.nbt, "ntr": ntr,
                 "nvec": nvec, "free_base": int(self.free), "tip_orient": int(self.tip_orientation),
                 "square": int(ntr == na), "observer": int(self.observer), "observer_arm": int(self.observer_arm),
                 "clip_alloc": int(self.allocator is None), "alloc_input": int(self.observer_input == "allocated"),
                 "nthr": self.B.shape[1], "nwr": self.wrench_rows.size, "nmot": self._motor_idx.size,
                 "base_body": lay.base_body, "tip_site": lay.tip_site, "base_qadr": lay.base_qadr if self.free else 0,
                 "wls_fast": 0, "nbv": self._ref_pos.size, "nlin": self.lin.size,
                 "joint_limits": int(self.limits.active)}
        if max(m.nv, self.ntask, na, nb) > _k.MAXN:
            return None
        params = {"T": self.T, "dls_threshold": self.dls_threshold, "dls_damping": self.dls_damping,
                  "null_kp": self.null_kp, "null_kd": self.null_kd, "g": self.g, "h": self.filter.h,
                  "g_arm": self.g_arm, "h_arm": self.filter_arm.h, "jl_beta": self.limits.beta}
        index = {"base_dofs": self.base_dofs, "arm_dofs": self.arm_dofs, "tip_rows": self.tip_rows,
                 "base_qpos": getattr(self, "base_qpos", ()), "arm_qadr": self.arm_qadr,
                 "wrench_rows": self.wrench_rows, "motor_idx": self._motor_idx, "lin": self.lin}
        const = {"gamma": self.gamma, "lam": self.lam, "q_rest": self.q_rest, "B": self.B, "B_pinv": self.B_pinv,
                 "lo": self.lo, "hi": self.hi, "motor_lo": r.motor_lo, "motor_hi": r.motor_hi,
                 "jnt_lo": self.limits.lo, "jnt_hi": self.limits.hi}
        if not self.free:
            const.update(Jb=self._Jb_const, Jb_pinvT=self._Jb_pinvT)
        al = self.allocator
        if al is not None and not al._any_equal:  # the Allocator's fast path: u = P_free S tau
            sizes["wls_fast"] = 1
            const["Q"] = al._P_free @ al.S
        ws = _k.Workspace(lib, sizes, params, index, const, model=r.model, data=r.data)
        sig = {} if self.free else {"p_desired": "pd_out", "p_measured": "p"}  # signal: kernel output, in order
        sig.update(e_p="e_p", e_v="e_v", v_desired="v_d", a_desired="a_d", qdd_desired="qdd", u_B="u_B",
                   u_B_applied="u_app", f_E_hat="f_e_hat")
        # the results a sample returns, in this order: the signals above, the commands, then what
        # _compute_kernel reads of the kernel's outputs for this robot
        self._signal_names = tuple(sig)
        extra = (("f_m_hat",) if self.observer_arm else ()) + (("pd_out", "base_quat", "p") if self.free else ())
        self._result_slices = tuple(ws.slices[v] for v in (*sig.values(), "thrust", "torques", *extra))
        self._results = None  # [next row, rows, flags, views per result] of the results chunk
        a = ws.a
        self._ws_views = (a["q"], a["qd_meas"], a["scalars"], a["v_base"], a["tipn"], a["sat"])
        a["ref"][:] = self._ref_pos  # the desired points' base part: reference + Eq. 12 offset (0 now)
        a["pd"][:] = self._pd_prev[0]  # p_d(k0) (the kernel's own from then on)
        a["Rd"][:] = a["Rdn"][:] = self._rots(self._pd_prev[1])
        a["q_prev"][:] = self._q_prev
        a["p_prev"][:] = self._p_prev[0]
        a["R_prev"][:] = self._rots(self._p_prev[1])
        a["J_prev"][:] = self._J_prev
        a["pd_prev"][:] = self._pd_prev[0]
        a["Rd_prev"][:] = self._rots(self._pd_prev[1])
        a["z"][:] = self.filter.z
        a["z_arm"][:] = self.filter_arm.z
        self.filter.z, self.filter_arm.z = a["z"], a["z_arm"]  # the filters' states now live in the kernel
        return ws

    @staticmethod
    def _rots(rots: list) -> np.ndarray:
        """Up to two rotation matrices as the kernel's 18 numbers (zeros for the missing)."""
        out = np.zeros(18)
        for i, R in enumerate(rots):
            out[9 * i:9 * i + 9] = R.ravel()
        return out

    def _compute_kernel(self, m: Measurement) -> Command:
        """One sample through the compiled kernel: the steps of :meth:`compute`'s Python code
        (see rac_kernel.c); Eq. 12's handler, the desired tip and a "wls" allocation staying here."""
        ws, k = self._ws, m.k
        a_q, a_qd, sc, a_v, a_tipn, a_sat = self._ws_views
        first = k <= self._k0
        a_q[:] = m.q
        has_qd = m.qd is not None
        if has_qd:
            a_qd[:] = m.qd
        ws.measure(ws.ptr, first, has_qd)
        manip = sc.item(0)
        sh = self.singular
        v_base = sh.update(k, manip)  # Eq. 12
        moving = not sh.at_rest and any(v_base.tolist())  # the offset moves: off(k+1) = off(k) + T v
        if moving:
            a_v[:] = v_base
        a_tipn[:] = self._tip_k(k + 1)  # p_d(k + 1): the kernel adds the base part (_desired)
        if self.tip_orientation:
            ws.a["Rdn"][9:] = self._tip_R_d((k + 1) * self.T).ravel()
        rc = ws.command(ws.ptr, first, moving)
        if rc < 0:
            raise np.linalg.LinAlgError("Singular matrix")
        saturated = None
        if rc == 1:  # "wls": the Allocator
            a = ws.a
            res = self.allocator(a["body"][self.wrench_rows])
            a["thrust"][:] = res.thrust
            saturated = res.saturated
        ws.finish(ws.ptr)
        out = self._result_row(ws.block, a_sat if saturated is None else saturated)
        names = self._signal_names
        n = len(names)
        signals = dict(zip(names, out))  # [p_desired, p_measured,] e_p ... f_E_hat
        signals.update(manipulability=manip, singular_phase=sh.phase, dls_active=sc.item(2) != 0.0,
                       thrust_saturated=out[-1])
        rest = out[n + 2:-1]  # [f_m_hat,] [pd_out, base_quat, p]
        if self.observer_arm:
            signals["f_M_hat"] = rest.pop(0)
        if self.free:
            p_d, base_quat, p = rest
            signals["base_desired"] = np.concatenate((p_d[:3], base_quat))
            signals["tip_desired"] = p_d[3:6]
            signals["tip_measured"] = p[3:6]
        else:
            signals["det_B"] = sc.item(1)
        return Command(out[n], out[n + 1], signals)

    def _result_row(self, block: np.ndarray, saturated) -> list[np.ndarray]:
        """This sample's results as arrays of their own (the kernel's buffers are reused): the
        kernel's output block and the thrusters' saturation flags copied into the next row of a
        chunk of ``RESULTS_CHUNK`` samples, whose views of each result are made for the whole
        chunk at once (a new chunk when it is full: rows are never written twice)."""
        ch = self._results
        if ch is None or ch[0] == RESULTS_CHUNK:
            rows = np.empty((RESULTS_CHUNK, block.size))
            flags = np.empty((RESULTS_CHUNK, np.size(saturated)), dtype=bool)
            ch = self._results = [0, rows, flags, [list(rows[:, s]) for s in self._result_slices] + [list(flags)]]
        i = ch[0]
        ch[0] = i + 1
        ch[1][i] = block
        ch[2][i] = saturated  # (!= 0: True)
        return [views[i] for views in ch[3]]

