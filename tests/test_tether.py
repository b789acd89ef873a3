"""The tether (uvms_mj.plant.tether, docs/hydrodynamics.md "Tether") against independent truths.

The tether's lower end is held on a fixed point (a body welded to the world carrying the attachment site), so the
static problem is that of a cable between two fixed points; the truths are computed here, not by the code:

* the hanging cable in still water: the classical catenary (hand computation with a root finder);
* the steady shape in a uniform current with normal drag only (Ct = 0): the inclined-cable ODE of a cable with weight
  and normal drag q_n = 1/2 rho Cn D |U_n| U_n, integrated with scipy's solve_ivp (rtol 1e-11) and shot to the end
  point with fsolve;
* convergence in the segment count: the vehicle-end pull's error against that ODE shrinks from 10 to 20 to 40
  segments.

The statics are reached by simulating with a joint damping (Tether.damping: it changes no equilibrium) and with the
segments' added mass off (it changes no equilibrium either, and costs most of the step time).
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq, fsolve

from uvms_mj.physics import model as _pm
from uvms_mj.plant.errors import ParameterError
from uvms_mj.plant.tether import Tether, tether_pull

RHO, G = 1000.0, 9.81
XML = """<mujoco><option timestep="{dt}" integrator="implicitfast" gravity="0 0 -9.81">
<flag contact="disable"/></option>
<extension><plugin plugin="uvms.water"><instance name="water"><config key="density" value="1000"/></instance></plugin>
<plugin plugin="uvms.hydro"/></extension>
<worldbody><body name="vehicle" pos="{x} 0 {z}"><geom type="sphere" size="0.05" contype="0" conaffinity="0"/></body>
</worldbody></mujoco>"""


def _settle(tmp_path, tether: Tether, end, *, current=None, side=(1.0, 0.0, 0.0), t_end=6.0, dt=0.01):
    """Simulate the tether from ``anchor`` to the fixed point ``end`` (x, z) for ``t_end`` s; (model, data)."""
    f = tmp_path / "fixed_end.xml"
    f.write_text(XML.format(dt=dt, x=end[0], z=end[1]))
    spec = _pm.load_spec(f)
    if current is not None:
        _pm.set_water(spec, current=_pm.fmt(current))
    tether.add_to(spec, "vehicle")
    m = _pm.compile_spec(spec, native=True)
    d = mujoco.MjData(m)
    tether.place(m, d, side=np.asarray(side, dtype=float))
    mujoco.mj_step(m, d, nstep=int(round(t_end / dt)))
    mujoco.mj_forward(m, d)
    return m, d


def _weight(mass_per_length: float, diameter: float) -> float:
    """Submerged weight per length [N/m] (down positive)."""
    return (mass_per_length - RHO * math.pi * diameter ** 2 / 4) * G


def _cable(L, end, w, U=0.0, cn=1.2, D=0.0075, guess=(0.5, -1.2)):
    """Static cable from (0, 0) to ``end`` (x, z) of arc length L with submerged weight w [N/m] and normal drag in a
    current U along +x: d(T t)/ds + f = 0 with t = (cos phi, sin phi). Returns (force on the body at ``end``, world
    (x, z) [N]; the dense solution (x, z, T, phi) of s)."""
    def force(phi):
        t = np.array([math.cos(phi), math.sin(phi)])
        un = U * (np.array([1.0, 0.0]) - math.cos(phi) * t)  # the flow's normal component
        return 0.5 * RHO * cn * D * np.linalg.norm(un) * un + np.array([0.0, -w])

    def rhs(s, y):
        _, _, T, phi = y
        f = force(phi)
        return [math.cos(phi), math.sin(phi), -(f[0] * math.cos(phi) + f[1] * math.sin(phi)),
                (f[0] * math.sin(phi) - f[1] * math.cos(phi)) / T]

    def solve(p):
        return solve_ivp(rhs, (0.0, L), [0.0, 0.0, p[0], p[1]], rtol=1e-11, atol=1e-12, dense_output=True)

    p = fsolve(lambda p: solve(p).y[:2, -1] - np.asarray(end), guess, xtol=1e-13)
    sol = solve(p)
    T, phi = sol.y[2, -1], sol.y[3, -1]
    return -T * np.array([math.cos(phi), math.sin(phi)]), sol


# ----------------------------------------------------------------------------- statics


def test_hanging_tether_pull_is_the_catenary_hand_computation(tmp_path):
    """A heavy tether (0.2 kg/m: 1.53 N/m submerged) between two points at the same height, 1.5 m apart, 2 m long.
    By symmetry each end carries half the submerged weight: F_z = -w L / 2 on the vehicle (exact for the discrete
    chain too); horizontally the catenary's tension H = w a with L / 2 = a sinh(s / (2 a)) (hand computation).
    Tolerances: vertical 0.3 % (settling and the soft constraint's violation, measured 0.05 %); horizontal 1 %
    (20 rigid segments against the continuous catenary, measured 0.16 %)."""
    L, s, mpl = 2.0, 1.5, 0.2
    t = Tether(length=L, segments=20, anchor=(0.0, 0.0, 0.0), mass_per_length=mpl, added_mass=False, damping=0.02)
    m, d = _settle(tmp_path, t, (s, 0.0), side=(0.0, 0.0, -1.0), t_end=8.0, dt=0.005)
    F = tether_pull(m, d)
    w = _weight(mpl, t.diameter)
    a = brentq(lambda a: a * math.sinh(s / (2 * a)) - L / 2, 0.05, 100.0)
    assert F[2] == pytest.approx(-w * L / 2, rel=3e-3)
    assert F[0] == pytest.approx(-w * a, rel=1e-2)  # towards the anchor
    assert abs(F[1]) < 1e-6


def test_default_tether_is_slightly_buoyant():
    """von Benzon et al. 2022's tether: 0.043 kg/m against rho pi D^2 / 4 = 0.0442 kg/m of water displaced: it floats
    (hand computation); the segment's hydro attributes carry that volume and the strips C_D D = Cn D."""
    t = Tether(length=10.0, segments=10)
    assert (t.diameter, t.mass_per_length, t.cn, t.ct) == (0.0075, 0.043, 1.2, 0.01)
    assert _weight(t.mass_per_length, t.diameter) == pytest.approx(-0.0116, abs=1e-4)
    cfg = t.segment_hydro()
    assert float(cfg["volume"]) == pytest.approx(math.pi * 0.0075 ** 2 / 4 * 1.0, rel=1e-9)
    assert cfg["strips"].split()[-2:] == [repr(1.2 * 0.0075)] * 2


# ----------------------------------------------------------------------------- current


def test_steady_shape_in_a_uniform_current_against_the_cable_ode(tmp_path):
    """The default tether (Ct = 0 for the comparison), 3 m, from (0, 0, 0) to a fixed point at (0.5, 0, -2.5), in a
    0.2 m/s current along +x: the vehicle-end pull within 1 % of the ODE's (measured 0.17 %: 20 segments) and the
    segments' joints within 1 cm of the ODE's curve at the same arc length (measured 2 mm)."""
    L, end, U = 3.0, (0.5, -2.5), 0.2
    t = Tether(length=L, segments=20, anchor=(0.0, 0.0, 0.0), ct=0.0, added_mass=False, damping=0.005)
    m, d = _settle(tmp_path, t, end, current=(U, 0.0, 0.0))
    F_ode, sol = _cable(L, end, _weight(t.mass_per_length, t.diameter), U=U, cn=t.cn, D=t.diameter)
    F = tether_pull(m, d)
    assert np.linalg.norm(F[[0, 2]] - F_ode) < 1e-2 * np.linalg.norm(F_ode)
    assert F[0] > 0.1  # dragged downstream
    l = t.segment_length
    for i in range(1, t.segments):
        b = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, f"tether_{i}")
        xz = sol.sol(i * l)[:2]
        assert np.linalg.norm(d.xpos[b][[0, 2]] - xz) < 1e-2, i


@pytest.mark.slow
def test_vehicle_end_pull_converges_in_the_segment_count(tmp_path):
    """A heavy tether (0.2 kg/m) in the current case above: its low point is a tight bend near the vehicle, which
    coarse chains cannot resolve. The vehicle-end pull's error against the ODE shrinks from 10 to 20 to 40 segments
    (measured 37 %, 4.5 %, 0.2 %) and the differences between successive counts shrink."""
    L, end, U, mpl = 3.0, (0.5, -2.5), 0.2, 0.2
    F_ode, _ = _cable(L, end, _weight(mpl, 0.0075), U=U)
    F = {}
    for n in (10, 20, 40):
        t = Tether(length=L, segments=n, anchor=(0.0, 0.0, 0.0), mass_per_length=mpl, ct=0.0, added_mass=False,
                   damping=0.02)
        m, d = _settle(tmp_path, t, end, current=(U, 0.0, 0.0), side=(0.0, 0.0, -1.0), t_end=10.0, dt=0.005)
        F[n] = tether_pull(m, d)[[0, 2]]
    err = {n: np.linalg.norm(F[n] - F_ode) / np.linalg.norm(F_ode) for n in F}
    assert err[40] < err[20] < err[10]
    assert err[40] < 0.02
    assert np.linalg.norm(F[40] - F[20]) < 0.5 * np.linalg.norm(F[20] - F[10])


# ----------------------------------------------------------------------------- the plant


def test_plant_hands_the_controllers_the_robots_coordinates_only():
    """A tethered BlueROV2: q / qd are the robot's (a prefix of qpos / qvel), the layout knows no tether joint, and
    the pull is logged (tether_pull, world [N]); the vehicle sinks onto the taut tether (it is ~9 N heavy with the
    arm: the tether holds it, its pull is upward)."""
    from uvms_mj.plant.layout import InitialState
    from uvms_mj.plant.plant import Plant

    free = Plant("bluerov2_alpha")
    p = Plant("bluerov2_alpha", tether=Tether(length=2.5, segments=8), initial=InitialState(position=(0.0, 0.0, -2.0)))
    assert p.q.shape == free.q.shape and p.qd.shape == free.qd.shape
    assert p.model.nq == free.model.nq + 4 * 8 and p.model.nv == free.model.nv + 3 * 8
    assert p.layout.joint_names == free.layout.joint_names
    assert not any(b.startswith("tether") for b in p.layout.body_names)
    for _ in range(100):
        q, qd, _, _ = p.step_observe(25)
    assert q.shape == free.q.shape and qd.shape == free.qd.shape
    pull = p.sea_signals()["tether_pull"]
    assert pull.shape == (3,) and pull[2] > 1.0


def test_native_and_python_backends_agree_on_a_tethered_plant():
    """The tether's segments are hydro bodies like any other: the C plugin and the numpy reference give the same
    motion (1 s in a 0.2 m/s current; the two sum the same terms in different orders: 1e-9 m / rad / N)."""
    from uvms_mj.plant.layout import InitialState
    from uvms_mj.plant.plant import Plant

    out = []
    for backend in ("native", "python"):
        p = Plant("bluerov2_alpha", tether=Tether(length=3.0, segments=6), current=(0.2, 0.0, 0.0),
                  initial=InitialState(position=(0.0, 0.0, -2.0)), backend=backend)
        p.step(250)
        out.append((p.q, p.sea_signals()["tether_pull"]))
    np.testing.assert_allclose(out[0][0], out[1][0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(out[0][1], out[1][1], rtol=0, atol=1e-9)


def test_bad_tether_input_is_refused():
    from uvms_mj.plant.plant import Plant

    with pytest.raises(ParameterError, match="tether.length"):
        Tether(length=-1.0)
    with pytest.raises(ParameterError, match="tether.segments"):
        Tether(length=1.0, segments=1)
    with pytest.raises(ParameterError, match="free vehicle only"):
        Plant(tether=Tether(length=1.0))
    with pytest.raises(ParameterError, match="shorter than the distance"):
        from uvms_mj.plant.layout import InitialState

        Plant("bluerov2_alpha", tether=Tether(length=1.0), initial=InitialState(position=(0.0, 0.0, -2.0)))


# ----------------------------------------------------------------------------- the scenario section


def _scenario(tmp_path, text: str):
    from uvms_mj.scenario.schema import load_scenario

    p = tmp_path / "s.yaml"
    p.write_text(text)
    return load_scenario(p)


def test_scenario_tether_section_builds_the_plants_tether(tmp_path):
    from uvms_mj.scenario.schema import build

    sc = _scenario(tmp_path, "robot: bluerov2_alpha\nduration: 1.0\ninitial: {position: [0, 0, -2]}\n"
                             "plant:\n  tether: {length: 3.0, segments: 6, ct: 0.02}\n")
    plant, _ = build(sc)
    t = plant.tether
    assert (t.length, t.segments, t.ct, t.diameter, t.mass_per_length, t.cn) == (3.0, 6, 0.02, 0.0075, 0.043, 1.2)
    assert plant.q.shape == (plant.robot_model.nq,)


@pytest.mark.parametrize("body, match", [
    ("robot: paper\nplant:\n  tether: {length: 3.0}\n", r"plant\.tether: applies to MJCF robots"),
    ("robot: bluerov2_alpha\nplant:\n  tether: {length: -3.0}\n", r"plant\.tether\.length"),
    ("robot: bluerov2_alpha\nplant:\n  tether: {length: 3.0, segments: 1}\n", r"plant\.tether\.segments"),
    ("robot: bluerov2_alpha\nplant:\n  tether: {length: 3.0, lenght: 2}\n", r"plant\.tether.*lenght"),
])
def test_scenario_tether_section_refuses_bad_input(tmp_path, body, match):
    from uvms_mj.scenario.schema import ScenarioError

    with pytest.raises(ScenarioError, match=match) as info:
        _scenario(tmp_path, body)
    assert len(str(info.value).splitlines()) <= 3
