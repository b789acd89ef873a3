"""A tether between the vehicle and a surface point: lumped segments in water (docs/hydrodynamics.md "Tether").

:class:`Tether` adds to a robot's MjSpec, before compiling (a run-time model edit like
:class:`uvms_mj.plant.robot.Payload`), a chain of ``segments`` rigid segments of length
``length / segments`` rooted at the world point ``anchor`` (a ball joint there: a pinned end), each
segment on a ball joint at its parent's far end, the last one's far end held on the vehicle's
attachment point by an equality ``connect`` between two sites. The physics of every segment is
in the model: its mass, and the attributes of its own ``uvms.hydro`` instance, applied by the
water plugin like those of any other body:

* normal drag: one strip along the segment (closed-form strip integral, docs/hydrodynamics.md
  item 4) with C_D D = ``cn * diameter`` for each normal axis;
* tangential drag: quadratic damping along the axis, (rho/2) ``ct`` pi D l (skin friction on the
  wetted area pi D l: Ablow and Schechter 1983; our reading of von Benzon et al. 2022's Ct);
* buoyancy: the displaced volume pi D^2/4 l at the segment's centre (gravity on its mass
  ``mass_per_length * l`` is MuJoCo's);
* added mass (``added_mass``, on by default): a circular cylinder's potential-flow value
  rho pi D^2/4 l across the axis (Ca = 1), rho pi D^2/4 l^3/12 about the normal axes, none along
  the axis.

Defaults: von Benzon et al. 2022's tether (J. Mar. Sci. Eng. 10(12) 1898): 7.5 mm diameter,
0.043 kg/m, Cn 1.2, Ct 0.01. The chain is appended after the robot's bodies, so the robot's
coordinates are a prefix of ``qpos`` / ``qvel`` (the plant hands the controllers only those:
the tether is a disturbance no nominal model knows). Its segments are a separate kinematic
tree rooted at the world, outside the robot's :class:`~uvms_mj.plant.layout.Layout`.

MuJoCo facts relied on (3.17): a body carries at most one plugin instance (``body_plugin``), so
MuJoCo's ``cable`` composite, whose bodies carry the ``mujoco.elasticity.cable`` plugin, cannot
also carry ``uvms.hydro``: hence our own chain; a site-to-site ``connect`` keeps the two sites
coincident whatever ``qpos0`` is; equality constraints are soft (``solref``/``solimp``): at rest
the constraint force equals the tether's pull (our tests check it), and the two points are
apart by a small violation (sub-millimetre in the tests). Segment inertia: isotropic,
m l^2/12 about the centre on all three axes (the axial value is ours: no force of the model has a
moment about a segment's own axis, so its spin stays zero whatever that value, and the mass
matrix stays well conditioned; the physical r^2 m/2 would make it nearly singular).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from uvms_mj.physics import model as _pm
from uvms_mj.plant.errors import ParameterError
from uvms_mj.plant.robot import add_hydro_instance

__all__ = ["TETHER_PREFIX", "Tether", "add_tether", "tether_dofs", "tether_pull"]

#: Names of the tether's elements: ``tether_0``... (bodies, joints), ``tether_end``,
#: ``tether_attach`` (sites), ``tether_connect`` (the equality).
TETHER_PREFIX = "tether"

#: von Benzon et al. 2022's tether (J. Mar. Sci. Eng. 10(12) 1898).
VB_DIAMETER = 0.0075  # [m]
VB_MASS_PER_LENGTH = 0.043  # [kg/m]
VB_CN = 1.2  # normal drag coefficient
VB_CT = 0.01  # tangential drag coefficient


@dataclass(frozen=True)
class Tether:
    """A tether from a surface point to the vehicle (module docstring).

    Attributes:
        length: [m] (> 0); segments: number of rigid segments (>= 2);
        anchor: world point [m] of the upper end; None: straight above the vehicle's initial
            attachment point at z = ``surface``;
        attach: the attachment point on the vehicle, vehicle body frame [m] (default its origin);
        diameter [m], mass_per_length [kg/m], cn, ct: von Benzon et al. 2022's by default;
        added_mass: the segments' potential-flow added mass (Ca = 1 across);
        damping: joint damping of every ball dof [N m s/rad] (0: none; a structural damping of
            ours, e.g. to settle a static test faster: it changes no equilibrium);
        surface: world z of the surface [m] for the default anchor.
    """

    length: float
    segments: int = 20
    anchor: tuple[float, float, float] | None = None
    attach: tuple[float, float, float] = (0.0, 0.0, 0.0)
    diameter: float = VB_DIAMETER
    mass_per_length: float = VB_MASS_PER_LENGTH
    cn: float = VB_CN
    ct: float = VB_CT
    added_mass: bool = True
    damping: float = 0.0
    surface: float = 0.0

    def __post_init__(self) -> None:
        for name, lo in (("length", 0.0), ("diameter", 0.0), ("mass_per_length", 0.0)):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > lo):
                raise ParameterError(f"tether.{name} = {v!r}: must be > {lo:g}")
        for name in ("cn", "ct", "damping"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ParameterError(f"tether.{name} = {v!r}: must be >= 0")
        if not (isinstance(self.segments, int) and self.segments >= 2):
            raise ParameterError(f"tether.segments = {self.segments!r}: must be an integer >= 2")

    @property
    def segment_length(self) -> float:
        return self.length / self.segments

    def segment_hydro(self, rho: float = 1000.0) -> dict[str, str]:
        """The ``uvms.hydro`` attributes of one segment (hydrodynamic frame at its centre, x along it)."""
        l, D = self.segment_length, self.diameter
        area = math.pi * D * D / 4.0
        cfg = {"pos": _pm.fmt([l / 2, 0.0, 0.0]),
               "strips": f"x {-l / 2!r} {l / 2!r} {self.cn * D!r} {self.cn * D!r}",
               "quadratic_damping": _pm.fmt([0.5 * rho * self.ct * math.pi * D * l, 0, 0, 0, 0, 0]),
               "volume": _pm.fmt([area * l])}
        if self.added_mass:
            ma = rho * area * l
            cfg["added_mass"] = _pm.fmt([0.0, ma, ma, 0.0, ma * l * l / 12.0, ma * l * l / 12.0])
        return cfg

    def add_to(self, spec: mujoco.MjSpec, vehicle: str) -> None:
        """Append the chain to ``spec`` and connect its end to body ``vehicle`` (module docstring)."""
        vb = spec.body(vehicle)
        if vb is None:
            raise ParameterError(f"tether: no vehicle body {vehicle!r}")
        if spec.body(f"{TETHER_PREFIX}_0") is not None:
            raise ParameterError("tether: the model already has a tether (body tether_0)")
        vb.add_site(name=f"{TETHER_PREFIX}_attach", pos=list(map(float, self.attach)), size=[0.01, 0, 0],
                    rgba=[1, 0.8, 0, 1], group=4)
        rho = float(_pm.water_config(spec).get("density", 1000.0))
        hydro = self.segment_hydro(rho)
        l = self.segment_length
        m = self.mass_per_length * l
        parent = spec.worldbody
        for i in range(self.segments):
            b = parent.add_body(name=f"{TETHER_PREFIX}_{i}", pos=[0.0, 0.0, 0.0] if i == 0 else [l, 0.0, 0.0])
            b.add_joint(name=f"{TETHER_PREFIX}_{i}", type=mujoco.mjtJoint.mjJNT_BALL, damping=self.damping)
            b.mass = m
            b.ipos = [l / 2, 0.0, 0.0]
            b.inertia = [m * l * l / 12.0] * 3
            b.explicitinertial = True
            b.add_geom(type=mujoco.mjtGeom.mjGEOM_CAPSULE, fromto=[0, 0, 0, l, 0, 0], size=[self.diameter / 2, 0, 0],
                       contype=0, conaffinity=0, mass=0.0, density=0.0, rgba=[0.95, 0.75, 0.1, 1], group=1)
            add_hydro_instance(spec, b, f"{TETHER_PREFIX}_{i}_hydro", hydro)
            parent = b
        parent.add_site(name=f"{TETHER_PREFIX}_end", pos=[l, 0.0, 0.0], size=[0.01, 0, 0], group=4)
        eq = spec.add_equality()  # (keyword arguments to add_equality crash MuJoCo 3.17's bindings)
        eq.name = f"{TETHER_PREFIX}_connect"
        eq.type = mujoco.mjtEq.mjEQ_CONNECT
        eq.objtype = mujoco.mjtObj.mjOBJ_SITE
        eq.name1, eq.name2 = f"{TETHER_PREFIX}_end", f"{TETHER_PREFIX}_attach"

    # ------------------------------------------------------------ state

    def anchor_point(self, attach_world: np.ndarray) -> np.ndarray:
        if self.anchor is not None:
            return np.asarray(self.anchor, dtype=float)
        return np.array([attach_world[0], attach_world[1], self.surface])

    def place(self, m: mujoco.MjModel, d: mujoco.MjData, side: np.ndarray | None = None) -> None:
        """Set the tether's initial shape (``d.qpos``, zero ``d.qvel``) from the vehicle's pose in
        ``d``: the anchor body at the anchor, the chain a V of two straight legs of whole segments
        from the anchor to the attachment point (straight when the length equals the distance),
        bent towards ``side`` (world; default: down, else +x). Then ``mj_kinematics``.

        Raises:
            ParameterError: the tether is shorter than the anchor-attachment distance."""
        mujoco.mj_kinematics(m, d)
        a_site = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, f"{TETHER_PREFIX}_attach")
        B = d.site_xpos[a_site].copy()
        A = self.anchor_point(B)
        b0 = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, f"{TETHER_PREFIX}_0")
        m.body_pos[b0] = A
        n, l = self.segments, self.segment_length
        AB = B - A
        dist = float(np.linalg.norm(AB))
        if dist > self.length * (1 + 1e-9):
            raise ParameterError(f"tether.length = {self.length:g} m is shorter than the distance from the anchor "
                                 f"{A.round(3).tolist()} to the vehicle's attachment point ({dist:.4g} m)")
        u = AB / dist if dist > 1e-12 else np.array([0.0, 0.0, -1.0])
        cand = [np.asarray(side, float)] if side is not None else []
        cand += [np.array([0.0, 0.0, -1.0]), np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])]
        for c in cand:
            w = c - (c @ u) * u
            if np.linalg.norm(w) > 1e-6:
                w /= np.linalg.norm(w)
                break
        # legs of k and n - k segments, as equal as the triangle allows: apex P with |P-A| = a, |P-B| = b
        best = None
        for k in range(1, n):
            a, b = k * l, (n - k) * l
            if abs(a - b) <= dist + 1e-12 and (best is None or abs(a - b) < abs(best[1] - best[2])):
                best = (k, a, b)
        k, a, b = best if best is not None else (n, self.length, 0.0)
        if dist < 1e-12 or b == 0.0:
            x = a / 2 if dist < 1e-12 else a
            dirs = [u] * n if b == 0.0 and dist > 1e-12 else [w] * (n // 2) + [-w] * (n - n // 2)
        else:
            x = (a * a - b * b + dist * dist) / (2 * dist)  # along u from A
            h = math.sqrt(max(a * a - x * x, 0.0))
            P = A + x * u + h * w
            d1, d2 = (P - A) / a, (B - P) / b
            dirs = [d1] * k + [d2] * (n - k)
        normal = np.cross(u, w)
        R_prev = np.eye(3)
        for i, t in enumerate(dirs):
            y = normal - (normal @ t) * t
            y /= np.linalg.norm(y)
            R = np.column_stack([t, y, np.cross(t, y)])
            q = np.zeros(4)
            mujoco.mju_mat2Quat(q, (R_prev.T @ R).ravel())
            j = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, f"{TETHER_PREFIX}_{i}")
            d.qpos[m.jnt_qposadr[j]:m.jnt_qposadr[j] + 4] = q
            d.qvel[m.jnt_dofadr[j]:m.jnt_dofadr[j] + 3] = 0.0
            R_prev = R
        mujoco.mj_kinematics(m, d)


def add_tether(spec: mujoco.MjSpec, tether: Tether, *, native: bool | None, source: str) -> mujoco.MjModel:
    """Add ``tether`` to a robot's spec, connected to its free vehicle; returns the robot's own model
    compiled before (without the chain: :attr:`uvms_mj.plant.plant.Plant.robot_model`).

    Raises:
        ParameterError: not a Tether, or a robot without a free vehicle (the paper's planar one)."""
    if not isinstance(tether, Tether):
        raise ParameterError(f"tether = {tether!r} must be a uvms_mj.plant.tether.Tether")
    free = [j.parent.name for j in spec.joints if j.type == mujoco.mjtJoint.mjJNT_FREE]
    if len(free) != 1:
        raise ParameterError("tether: a free vehicle only (the paper's planar robot has no tether)")
    robot_model = _pm.compile_spec(spec, native=native, source=source)  # (compiling leaves the spec as it is)
    tether.add_to(spec, free[0])
    return robot_model


def tether_pull(m: mujoco.MjModel, d: mujoco.MjData) -> np.ndarray:
    """The force the tether exerts on the vehicle now, world [N] (at its attachment point): the
    ``connect`` constraint's force (after ``mj_forward`` / a step)."""
    eq = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_EQUALITY, f"{TETHER_PREFIX}_connect")
    rows = np.flatnonzero((d.efc_type == mujoco.mjtConstraint.mjCNSTR_EQUALITY) & (d.efc_id == eq))
    if rows.size != 3:
        return np.zeros(3)
    # efc rows: site1 (tether end) minus site2 (vehicle), world axes; the force on site2 is -f
    return -np.asarray(d.efc_force[rows], dtype=float)


def tether_dofs(m: mujoco.MjModel) -> tuple[int, int]:
    """(first qpos address, first qvel address) of the tether's coordinates, or (nq, nv) without one."""
    j = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, f"{TETHER_PREFIX}_0")
    if j < 0:
        return m.nq, m.nv
    return int(m.jnt_qposadr[j]), int(m.jnt_dofadr[j])
