"""The generic RAC's per-sample algebra compiled (``rac_kernel.c``), called through ctypes.

:class:`uvms_mj.control.rac.RAC` runs its samples here when it can (the numbers are those
of its Python code, the reference, to round-off: ``tests/test_rac_kernel.py``), about ten times
faster: a sample is hundreds of operations on 3- to 12-element arrays, where numpy's per-call
cost dominates. The C file is compiled with the plugins' machinery
(:func:`uvms_mj.physics.build.compile_library`: the system C compiler, the mujoco wheel's headers
and library, a cache keyed on every input) the first time it is needed.

``UVMS_MJ_COMPILED=off`` (default ``auto``, :func:`uvms_mj.physics.build.compiled_mode`) keeps
every RAC on its Python code; without a C compiler (under ``auto``), or on the Python
hydrodynamics backend (the nominal model's forces then come from a
Python callback), the Python code runs too. :func:`kernel_unavailable_reason` says why not.
"""

from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np

from uvms_mj.physics import build

#: The largest dof, task, arm and thruster-row count the C code's fixed buffers take.
MAXN = 32
#: The kernel's C source.
KERNEL_SOURCE = Path(__file__).resolve().parent / "rac_kernel.c"

_INT_FIELDS = ("nq", "nv", "nb", "na", "ntask", "nbt", "ntr", "nvec", "free_base", "tip_orient", "square",
               "observer", "observer_arm", "clip_alloc", "alloc_input", "nthr", "nwr", "nmot", "base_body",
               "tip_site", "base_qadr", "wls_fast", "nbv", "nlin", "joint_limits")
_INDEX_FIELDS = ("base_dofs", "arm_dofs", "tip_rows", "base_qpos", "arm_qadr", "wrench_rows", "motor_idx", "lin")
_PARAM_FIELDS = ("T", "dls_threshold", "dls_damping", "null_kp", "null_kd", "g", "h", "g_arm", "h_arm", "jl_beta")
_CONST_FIELDS = ("gamma", "lam", "q_rest", "Jb", "Jb_pinvT", "B", "B_pinv", "lo", "hi", "motor_lo", "motor_hi", "Q",
                 "jnt_lo", "jnt_hi")
_ARRAY_FIELDS = ("q", "qd_meas", "pd", "Rd", "pdn", "Rdn",
                 "q_prev", "p_prev", "R_prev", "J_prev", "e_p_prev", "pd_prev", "Rd_prev", "z", "z_arm",
                 "qd", "M", "hb", "J", "p", "R", "R_base", "pd_meas", "scalars",
                 "e_p", "e_v", "v_d", "a_d", "qdd", "u_B", "u_app", "f_e_hat", "f_m_hat", "f_t", "f_tM", "u_M",
                 "body", "thrust", "sat", "torques", "base_quat", "ref", "off", "v_base", "tipn", "pd_out")


#: The results :meth:`uvms_mj.control.rac.RAC.compute` returns as signals or commands
#: (:attr:`Workspace.block`).
OUTPUTS = ("p", "e_p", "e_v", "v_d", "a_d", "qdd", "u_B", "u_app", "f_e_hat", "f_m_hat", "thrust", "sat",
           "torques", "base_quat", "pd_out")


class _Struct(ctypes.Structure):
    """``uvms_rac`` of rac_kernel.c (same fields, same order)."""

    _fields_ = ([(f, ctypes.c_int) for f in _INT_FIELDS]
                + [(f, ctypes.POINTER(ctypes.c_int)) for f in _INDEX_FIELDS]
                + [(f, ctypes.c_double) for f in _PARAM_FIELDS]
                + [(f, ctypes.POINTER(ctypes.c_double)) for f in _CONST_FIELDS + _ARRAY_FIELDS]
                + [("m", ctypes.c_void_p), ("d", ctypes.c_void_p)])


def _configure(lib: ctypes.CDLL) -> ctypes.CDLL:
    p = ctypes.c_void_p
    for name, args in (("uvms_rac_measure", [p, ctypes.c_int, ctypes.c_int]),
                       ("uvms_rac_command", [p, ctypes.c_int, ctypes.c_int]), ("uvms_rac_finish", [p])):
        fn = getattr(lib, name)
        fn.argtypes, fn.restype = args, ctypes.c_int
    return lib


_LOADER = build.CompiledOnce("uvms_rac_kernel", [KERNEL_SOURCE], "the RAC kernel", _configure)


def library() -> ctypes.CDLL | None:
    """The compiled kernel (built into the cache if needed), or None (:func:`kernel_unavailable_reason`
    says why). Once per process; thread-safe."""
    return _LOADER.get()


def kernel_unavailable_reason() -> str | None:
    """Why :func:`library` returned None (None if it was not tried or is loaded)."""
    return _LOADER.reason


class Workspace:
    """The arrays of one RAC run that the C code reads and writes (numpy, owned here), and the
    struct holding their addresses. ``sizes``: the ints of ``uvms_rac``; ``params``: its doubles;
    ``index``: its index arrays; ``const``: its constant arrays (copied); ``model``, ``data``: the
    nominal MjModel and MjData the measurement stage evaluates."""

    def __init__(self, lib: ctypes.CDLL, sizes: dict, params: dict, index: dict, const: dict, model=None,
                 data=None) -> None:
        nq, nv, nt, nb, na = sizes["nq"], sizes["nv"], sizes["ntask"], sizes["nb"], sizes["na"]
        nthr, nmot = sizes["nthr"], sizes["nmot"]
        if max(nv, nt, na, nb, sizes["nwr"]) > MAXN:
            raise ValueError(f"the RAC kernel takes at most {MAXN} dofs and task rows")
        nvec = sizes["nvec"]
        shapes = {"q": nq, "qd_meas": nv, "pd": nvec, "Rd": 18, "pdn": nvec, "Rdn": 18,
                  "q_prev": nq, "p_prev": nvec, "R_prev": 18, "J_prev": (nt, nv), "e_p_prev": nt, "pd_prev": nvec,
                  "Rd_prev": 18, "z": nb, "z_arm": na,
                  "qd": nv, "M": (nv, nv), "hb": nv, "J": (nt, nv), "p": nvec, "R": 18, "R_base": (3, 3),
                  "pd_meas": nt, "scalars": 4, "e_p": nt, "e_v": nt, "v_d": nt, "a_d": nt, "qdd": nv, "u_B": nb,
                  "u_app": nb, "f_e_hat": nb, "f_m_hat": na, "f_t": nb, "f_tM": na, "u_M": na, "body": 6,
                  "thrust": nthr, "sat": nthr, "torques": nmot, "base_quat": 4,
                  "ref": sizes["nbv"], "off": sizes["nlin"], "v_base": sizes["nlin"], "tipn": nvec - sizes["nbv"],
                  "pd_out": nvec}
        self.lib = lib
        self.a: dict[str, np.ndarray] = {k: np.zeros(v) for k, v in shapes.items() if k not in OUTPUTS}
        # the per-sample results that become signals: views of one block, copied once per sample
        sizes_out = [int(np.prod(shapes[k])) for k in OUTPUTS]
        self.block = np.zeros(max(sum(sizes_out), 1))
        self.slices: dict[str, slice] = {}
        o = 0
        for k, n in zip(OUTPUTS, sizes_out):
            self.slices[k] = slice(o, o + n)
            self.a[k] = self.block[o:o + n]
            o += n
        self._keep = []
        s = _Struct()
        for k in _INT_FIELDS:
            setattr(s, k, int(sizes[k]))
        for k in _PARAM_FIELDS:
            setattr(s, k, float(params[k]))
        for k in _INDEX_FIELDS:
            arr = np.ascontiguousarray(index.get(k, ()), dtype=np.intc)
            arr = arr if arr.size else np.zeros(1, dtype=np.intc)
            self._keep.append(arr)
            setattr(s, k, arr.ctypes.data_as(ctypes.POINTER(ctypes.c_int)))
        for k in _CONST_FIELDS:
            arr = np.ascontiguousarray(const.get(k, ()), dtype=float).ravel()
            arr = arr.copy() if arr.size else np.zeros(1)
            self._keep.append(arr)
            setattr(s, k, arr.ctypes.data_as(ctypes.POINTER(ctypes.c_double)))
        for k in _ARRAY_FIELDS:
            arr = self.a[k]
            if arr.size == 0:
                self._keep.append(np.zeros(1))
                setattr(s, k, self._keep[-1].ctypes.data_as(ctypes.POINTER(ctypes.c_double)))
            else:
                setattr(s, k, arr.ctypes.data_as(ctypes.POINTER(ctypes.c_double)))
        s.m = model._address if model is not None else None
        s.d = data._address if data is not None else None
        self._model, self._data = model, data  # kept alive with the struct's pointers
        self.struct = s
        self.ptr = ctypes.addressof(s)
        self.measure = lib.uvms_rac_measure
        self.command = lib.uvms_rac_command
        self.finish = lib.uvms_rac_finish
