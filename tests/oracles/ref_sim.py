"""Run the numpy reference hydrodynamics in MuJoCo time simulations without the C plugin.

* :func:`strip_uvms` removes the uvms plugins from an MJCF text (XML level: without the plugin
  library MuJoCo cannot even parse the file, and in MuJoCo 3.17 deactivating a body's plugin in
  an MjSpec and compiling crashed) and returns their configuration strings;
* :func:`load` compiles the stripped model and parses the configuration with
  :mod:`uvms_mj.physics.config`;
* :class:`RefSim` installs :func:`uvms_mj.physics.reference.passive` as ``mjcb_passive``
  (a plain Python callable): M_add is added to ``d.M`` (CSR lower triangle), then
  ``mj_factorM``; the other terms to ``d.qfrc_passive``.

``mjcb_passive`` is process-global and the bindings abort on a model they do not know, so
compile every model *before* entering a :class:`RefSim` and never compile inside it; the
context manager restores the previous callback (normally None) on exit.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import mujoco
import numpy as np

from uvms_mj.physics import config, reference

MODELS = Path(__file__).resolve().parent.parent / "models"


def strip_uvms(xml: str) -> tuple[str, dict[str, str] | None, dict[str, dict[str, str]]]:
    """(stripped XML, water config or None, {body name: hydro config})."""
    root = ET.fromstring(xml)
    water = None
    for ext in root.findall("extension"):
        for pl in list(ext.findall("plugin")):
            if pl.get("plugin", "").startswith("uvms."):
                for inst in pl.findall("instance"):
                    if pl.get("plugin") == config.WATER_PLUGIN:
                        water = {c.get("key"): c.get("value", "") for c in inst.findall("config")}
                ext.remove(pl)
        if len(ext) == 0:
            root.remove(ext)
    bodies: dict[str, dict[str, str]] = {}
    for body in root.iter("body"):
        for pl in list(body.findall("plugin")):
            if pl.get("plugin") == config.HYDRO_PLUGIN:
                bodies[body.get("name")] = {c.get("key"): c.get("value", "") for c in pl.findall("config")}
                body.remove(pl)
    return ET.tostring(root, encoding="unicode"), water, bodies


@dataclass
class RefModel:
    m: mujoco.MjModel
    water: config.WaterParams
    bodies: dict[int, config.BodyHydro] = field(default_factory=dict)

    def body_id(self, name: str) -> int:
        return mujoco.mj_name2id(self.m, mujoco.mjtObj.mjOBJ_BODY, name)


def load(name_or_xml: str, *, water: dict[str, str] | None = None,
         bodies: dict[str, dict[str, str]] | None = None, edit=None) -> RefModel:
    """Compile a test model without the uvms plugins; parse its hydrodynamic configuration.

    Args:
        name_or_xml: a file in tests/models (e.g. "robot3d.xml") or an MJCF text.
        water, bodies: configuration overrides, merged into (water) or replacing (bodies, per
            body) what the file says.
        edit: optional callable(spec) applied before compiling (e.g. to change gravity).
    """
    xml = (MODELS / name_or_xml).read_text() if name_or_xml.endswith(".xml") else name_or_xml
    stripped, wcfg, bcfg = strip_uvms(xml)
    wcfg = dict(wcfg or {})
    wcfg.update(water or {})
    bcfg.update(bodies or {})
    spec = mujoco.MjSpec.from_string(stripped)
    if edit is not None:
        edit(spec)
    m = spec.compile()
    out = {}
    for bname, cfg in bcfg.items():
        b = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, bname)
        out[b] = config.resolve(m, b, config.parse_body(bname, cfg))
    return RefModel(m, config.parse_water(wcfg), out)


def csr_indices(m: mujoco.MjModel) -> tuple[np.ndarray, np.ndarray]:
    """Row and column of every entry of MuJoCo's sparse lower-triangular d.M."""
    rows, cols = [], []
    for i in range(m.nv):
        adr, n = m.M_rowadr[i], m.M_rownnz[i]
        rows += [i] * n
        cols += list(m.M_colind[adr:adr + n])
    return np.array(rows, dtype=int), np.array(cols, dtype=int)


def kinematics(m: mujoco.MjModel, d: mujoco.MjData) -> None:
    """Everything the reference needs from MuJoCo for the state in d (no passive stage)."""
    mujoco.mj_kinematics(m, d)
    mujoco.mj_comPos(m, d)
    mujoco.mj_comVel(m, d)


class RefSim:
    """Context manager: the reference hydrodynamics as MuJoCo's passive callback for one model.

    ``current_state`` follows the Gauss-Markov current; :meth:`step` advances it after each
    ``mj_step`` (what the C plugin's advance does).
    """

    def __init__(self, rm: RefModel) -> None:
        self.rm = rm
        self.m = rm.m
        self.rows, self.cols = csr_indices(rm.m)
        self.current_state = reference.initial_current_state(rm.water, 0.0, rm.m.opt.timestep)
        self._augmented: np.ndarray | None = None
        self.calls = 0

    def _passive(self, m: mujoco.MjModel, d: mujoco.MjData) -> None:
        if m._address != self.m._address:  # another model: not ours
            return
        self.calls += 1
        madd, qfrc = reference.passive(m, d, self.rm.water, self.rm.bodies, self.current_state)
        if "added_mass" in self.rm.water.terms and (
                self._augmented is None or not np.array_equal(d.M, self._augmented)):
            d.M[:] += madd[self.rows, self.cols]
            mujoco.mj_factorM(m, d)
            self._augmented = d.M.copy()
        d.qfrc_passive[:] += qfrc

    def __enter__(self) -> "RefSim":
        self._previous = mujoco.get_mjcb_passive()
        mujoco.set_mjcb_passive(self._passive)
        return self

    def __exit__(self, *exc) -> None:
        # restore what was there (None, or e.g. uvms_mj's own dispatcher for its Python backend)
        mujoco.set_mjcb_passive(self._previous)

    def step(self, d: mujoco.MjData, n: int = 1) -> None:
        for _ in range(n):
            mujoco.mj_step(self.m, d)
            self.current_state = reference.advance_current_state(
                self.rm.water, self.current_state, d.time, self.m.opt.timestep)
