"""The thrusters of a compiled model and their 6 x n allocation matrix (wrench = B @ thrust).

Also the array check shared by the package (:func:`_finite_array`).
"""

from __future__ import annotations

from typing import Sequence

import mujoco
import numpy as np

__all__ = ["thruster_actuators", "allocation_matrix"]


# ---------------------------------------------------------------------------- allocation matrix


def _body_id(model: mujoco.MjModel, body) -> int:
    if isinstance(body, (int, np.integer)) and not isinstance(body, bool):
        if not 0 <= int(body) < model.nbody:
            raise ValueError(f"body = {body!r}: no such body id (model has {model.nbody} bodies)")
        return int(body)
    if isinstance(body, str):
        i = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, body)
        if i < 0:
            raise ValueError(f"body = {body!r}: no body of that name in the model")
        return i
    raise ValueError(f"body = {body!r}: give a body name or id")


def thruster_actuators(model: mujoco.MjModel, actuator_names: Sequence[str] | None = None) -> list[int]:
    """Ids of the thruster actuators: the named ones (in that order), or by default every
    actuator with a site transmission (``actuator_trntype == mjTRN_SITE``), in model order.

    Raises:
        ValueError: a name that is not an actuator, or an actuator without a site transmission
            or with a ``refsite`` (a Cartesian actuator, not a thruster).
    """
    site = int(mujoco.mjtTrn.mjTRN_SITE)
    if actuator_names is None:
        ids = [a for a in range(model.nu) if int(model.actuator_trntype[a]) == site]
        if not ids:
            raise ValueError("actuator_names = None: the model has no actuator with a site transmission")
    else:
        if isinstance(actuator_names, str):
            raise ValueError(f"actuator_names = {actuator_names!r}: give a sequence of names")
        ids = []
        for name in actuator_names:
            a = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, str(name))
            if a < 0:
                raise ValueError(f"actuator_names: {name!r} is not an actuator of the model")
            if int(model.actuator_trntype[a]) != site:
                raise ValueError(f"actuator_names: {name!r} has no site transmission (trntype "
                                 f"{int(model.actuator_trntype[a])}); a thruster acts on a site")
            ids.append(a)
        if not ids:
            raise ValueError("actuator_names = []: no actuators")
    for a in ids:
        if model.actuator_trnid[a][1] != -1:
            name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, a)
            raise ValueError(f"actuator {name!r} has a refsite: a Cartesian actuator, not a thruster")
    return ids


def allocation_matrix(
    model: mujoco.MjModel,
    data: mujoco.MjData | None = None,
    actuator_names: Sequence[str] | None = None,
    frame: str = "body",
    body: str | int | None = None,
    about: str = "origin",
) -> np.ndarray:
    r"""The 6 x n allocation matrix B of the thrusters: wrench = B @ f, f the actuator forces.

    MuJoCo's site transmission (no ``refsite``) applies, for actuator force f_i, the force
    f_i R_s g_f at the site and the torque f_i R_s g_t, with R_s the site's orientation and
    g = (g_f, g_t) = ``gear[0:3]``, ``gear[3:6]`` (a general gear: the usual thruster has
    g = (1, 0, 0, 0, 0, 0), thrust along the site's x axis). Column i of B is therefore

        d_i = R^T R_s g_f,        B[:, i] = ( d_i ,  r_i x d_i + R^T R_s g_t ),
        r_i = R^T (p_s - p_0),

    the wrench of a unit actuator force, expressed in the axes of ``frame`` (R = the vehicle
    body's orientation for ``"body"``, the identity for ``"world"``) with the moment about the
    point p_0: the vehicle body's origin (``about="origin"``, MuJoCo's ``xpos``: the point a
    free joint's rotational DOFs turn about) or its centre of mass (``about="com"``,
    ``xipos``, the body's own CoM, not the subtree's). Note that with gear norm |g_f| != 1 the
    physical thrust is |g_f| f_i; B accounts for it.

    Args:
        model: compiled model.
        data: its kinematics must be current (after ``mj_forward``, ``mj_kinematics`` or a
            step). With the default ``frame="body"`` and thruster sites fixed to the vehicle
            body the result does not depend on the configuration. None: a fresh MjData at
            ``qpos0`` is used.
        actuator_names: the thrusters, in column order; default every site-transmission
            actuator in model order.
        frame: ``"body"`` (vehicle body axes) or ``"world"`` (world axes).
        body: the vehicle body (name or id); default the root body (the child of the world
            that carries the free or planar joints) of the thruster sites, which must then be
            the same for all thrusters.
        about: ``"origin"`` or ``"com"``: the point the moments are taken about.

    Returns:
        (6, n) array; rows (Fx, Fy, Fz, Mx, My, Mz) [N per unit force, N m per unit force].

    Raises:
        ValueError: bad ``frame`` / ``about`` / ``body`` / ``actuator_names``, a data that does
            not belong to the model or whose kinematics were never computed.
    """
    if frame not in ("body", "world"):
        raise ValueError(f"frame = {frame!r}; allowed: 'body', 'world'")
    if about not in ("origin", "com"):
        raise ValueError(f"about = {about!r}; allowed: 'origin', 'com'")
    ids = thruster_actuators(model, actuator_names)
    sites = [int(model.actuator_trnid[a][0]) for a in ids]
    if body is None:
        roots = {int(model.body_rootid[model.site_bodyid[s]]) for s in sites}
        if len(roots) != 1:
            names = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, r) for r in sorted(roots)]
            raise ValueError(f"body = None: the thruster sites belong to several root bodies {names}; name one")
        b = roots.pop()
    else:
        b = _body_id(model, body)
    if data is None:
        data = mujoco.MjData(model)
        mujoco.mj_kinematics(model, data)
    else:
        if data.qpos.shape != (model.nq,) or data.site_xpos.shape != (model.nsite, 3):
            raise ValueError("data: does not belong to this model (qpos / site sizes differ)")
        if not np.any(data.site_xmat[sites]) or (b > 0 and not np.any(data.xmat[b])):
            raise ValueError("data: kinematics not computed (site_xmat all zero); call mujoco.mj_forward first")
    R = data.xmat[b].reshape(3, 3) if frame == "body" else np.eye(3)
    p0 = data.xpos[b] if about == "origin" else data.xipos[b]
    B = np.empty((6, len(ids)))
    for col, (a, s) in enumerate(zip(ids, sites)):
        Rs = data.site_xmat[s].reshape(3, 3)
        gear = model.actuator_gear[a]
        d = R.T @ (Rs @ gear[:3])
        r = R.T @ (data.site_xpos[s] - p0)
        B[:3, col] = d
        B[3:, col] = np.cross(r, d) + R.T @ (Rs @ gear[3:6])
    return B



# ---------------------------------------------------------------------------- shared checks


def _finite_array(name: str, value, ndim: int | None = None, allow_inf: bool = False) -> np.ndarray:
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} = {value!r}: not numeric") from None
    if ndim is not None and a.ndim != ndim:
        raise ValueError(f"{name} = {value!r}: expected a {ndim}-D array, got shape {a.shape}")
    bad = np.isnan(a) if allow_inf else ~np.isfinite(a)
    if bad.any():
        raise ValueError(f"{name} = {value!r}: contains NaN{'' if allow_inf else ' or inf'}")
    return a
