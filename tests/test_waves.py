"""Linear waves (physics/plugin/waves.c, physics/waves.py; docs/hydrodynamics.md "Waves") against closed forms.

Independent truths used here: the dispersion relation omega^2 = g k tanh(k h) solved with scipy's
brentq; the Airy kinematics written out below from the velocity potential (Faltinsen 1990 table 2.1);
the closed particle orbit of linear theory; the JONSWAP/PM spectra written out below from
DNV-RP-C205 3.5.5 and integrated with scipy's quad.
"""

from __future__ import annotations

import ctypes
import math
from pathlib import Path

import mujoco
import numpy as np
import pytest
from scipy.integrate import quad
from scipy.optimize import brentq

from uvms_mj.physics import model as pm
from uvms_mj.physics import reference
from uvms_mj.physics.waves import BAND, Waves, sea_of, wavenumber

from conftest import added_and_passive

MODELS = Path(__file__).parent / "models"
G = 9.81
CODES = {"none": 0, "airy": 1, "jonswap": 2, "pierson_moskowitz": 3}


@pytest.fixture(scope="module")
def lib():
    from uvms_mj.physics import build

    try:
        lib = ctypes.CDLL(str(build.library_path()))
    except Exception as exc:  # no compiler: the C checks skip, the numpy ones run
        pytest.skip(f"the C plugins are unavailable here ({exc})")
    lib.uvms_waves_wavenumber.restype = ctypes.c_double
    lib.uvms_waves_wavenumber.argtypes = [ctypes.c_double] * 3
    dp = ctypes.POINTER(ctypes.c_double)
    lib.uvms_waves_eval.restype = ctypes.c_int
    lib.uvms_waves_eval.argtypes = ([ctypes.c_int] + [ctypes.c_double] * 7 + [ctypes.c_uint64, ctypes.c_int,
                                    ctypes.c_double, ctypes.c_int, dp, dp, ctypes.c_char_p, ctypes.c_size_t])
    return lib


def c_eval(lib, w: Waves, pts: np.ndarray) -> np.ndarray:
    """The C code's (eta, v, dv/dt, grad v) at rows (t, x, y, z): (n, 16)."""
    pts = np.ascontiguousarray(pts, float)
    out = np.zeros((len(pts), 16))
    err = ctypes.create_string_buffer(200)
    dp = ctypes.POINTER(ctypes.c_double)
    rc = lib.uvms_waves_eval(CODES[w.model], w.height, w.period, w.gamma, w.direction, w.spreading, w.depth,
                             w.surface, w.seed, w.n_components, G, len(pts), pts.ctypes.data_as(dp),
                             out.ctypes.data_as(dp), err, 200)
    assert rc == 0, err.value
    return out


def k_brentq(omega: float, depth: float) -> float:
    """The dispersion relation solved independently: deep k = omega^2/g, else brentq on
    g k tanh(k h) - omega^2 over [omega^2/g, omega/sqrt(g h) + omega^2/g] (k >= its deep value, and
    the shallow-water k = omega/sqrt(g h) bounds it above)."""
    if depth <= 0:
        return omega * omega / G
    f = lambda k: G * k * math.tanh(k * depth) - omega * omega  # noqa: E731
    return brentq(f, omega * omega / G * (1 - 1e-12), omega / math.sqrt(G * depth) + omega * omega / G,
                  xtol=1e-15, rtol=4 * np.finfo(float).eps)


# ------------------------------------------------------------------ the dispersion relation


@pytest.mark.parametrize("depth", [0.0, 0.5, 3.0, 20.0, 500.0])
def test_dispersion_relation(lib, depth):
    """C and numpy wavenumbers against brentq, to 1e-12 relative, short to long waves."""
    for T in (0.5, 2.0, 4.0, 10.0, 20.0):
        om = 2 * math.pi / T
        k = k_brentq(om, depth)
        assert abs(lib.uvms_waves_wavenumber(om, depth, G) - k) <= 1e-12 * k
        assert abs(float(wavenumber(om, depth, G)) - k) <= 1e-12 * k


# ------------------------------------------------------------------ Airy kinematics


def airy_truth(H, T, depth, theta, t, x, y, z):
    """eta, v, a of a regular wave from the potential phi = (g a / omega) cosh(k(z+h))/cosh(kh) sin psi
    (deep: e^{kz}), psi = k (x cos theta + y sin theta) - omega t; u = grad phi, eta = -phi_t/g at z = 0."""
    a, om = H / 2, 2 * math.pi / T
    k = k_brentq(om, depth)
    psi = k * (x * math.cos(theta) + y * math.sin(theta)) - om * t
    if depth > 0:
        C = math.cosh(k * (z + depth)) / math.sinh(k * depth)
        S = math.sinh(k * (z + depth)) / math.sinh(k * depth)
    else:
        C = S = math.exp(k * z)
    uh, w = a * om * C * math.cos(psi), a * om * S * math.sin(psi)
    ah, aw = a * om**2 * C * math.sin(psi), -a * om**2 * S * math.cos(psi)
    c, s = math.cos(theta), math.sin(theta)
    return a * math.cos(psi), np.array([uh * c, uh * s, w]), np.array([ah * c, ah * s, aw])


@pytest.mark.parametrize("depth", [0.0, 8.0])
def test_airy_kinematics_and_decay(lib, depth):
    """Particle velocity and acceleration at several depths equal the closed forms (1e-10 relative
    to the surface values: the brentq k enters through exponentials of k z), which decay as e^{kz}
    (deep) or cosh(k(z+h))/sinh(kh) (finite depth)."""
    w = Waves(model="airy", height=0.4, period=3.0, direction=0.6, depth=depth)
    rng = np.random.default_rng(3)
    pts = np.column_stack([rng.uniform(0, 10, 40), rng.uniform(-20, 20, 40), rng.uniform(-20, 20, 40),
                           rng.uniform(-(depth or 30.0), 0, 40)])
    out_c = c_eval(lib, w, pts)
    sea = sea_of(w, G)
    scale_v = 0.2 * 2 * math.pi / 3.0 * (1 / math.tanh(k_brentq(2 * math.pi / 3.0, depth) * depth) if depth else 1)
    for row, oc in zip(pts, out_c):
        eta, v, a = airy_truth(0.4, 3.0, depth, 0.6, *row)
        vn, an = sea.kinematics(row[0], row[1:])
        assert abs(oc[0] - eta) <= 1e-10 * 0.2 and abs(sea.elevation(row[0], row[1], row[2]) - eta) <= 1e-10 * 0.2
        for got in (oc[1:4], vn):
            assert np.max(np.abs(got - v)) <= 1e-10 * scale_v
        for got in (oc[4:7], an):
            assert np.max(np.abs(got - a)) <= 1e-10 * scale_v * 2 * math.pi / 3.0
        # grad v against central differences of the closed form (step 1e-4 m: truncation ~ (k e)^2 ~ 2e-9
        # relative, rounding ~ 1e-16 / 1e-4)
        _, _, gn = sea.kinematics(row[0], row[1:], gradient=True)
        fd = np.column_stack([(airy_truth(0.4, 3.0, depth, 0.6, row[0], *(row[1:] + e))[1]
                               - airy_truth(0.4, 3.0, depth, 0.6, row[0], *(row[1:] - e))[1]) / 2e-4
                              for e in 1e-4 * np.eye(3)])
        kk = k_brentq(2 * math.pi / 3.0, depth)
        assert np.max(np.abs(gn - fd)) <= 1e-7 * scale_v * kk
        assert np.max(np.abs(oc[7:].reshape(3, 3) - gn)) <= 1e-12 * scale_v * kk
    # the decay with depth, explicitly: speed along a vertical under a crest and a node
    k = k_brentq(2 * math.pi / 3.0, depth)
    zs = np.linspace(-(depth or 10.0), 0, 9)
    for t in (0.0, 0.75):  # a crest (horizontal speed), a quarter period later (vertical)
        sp = np.array([np.linalg.norm(sea.kinematics(t, (0, 0, z))[0]) for z in zs])
        law = np.exp(k * zs) if not depth else (np.cosh(k * (zs + depth)) if t == 0 else np.sinh(k * (zs + depth)))
        np.testing.assert_allclose(sp / sp[-1], law / law[-1], rtol=1e-10, atol=1e-14)


# ------------------------------------------------------------------ a sphere in the waves


def sphere_model(depth: float, z0: float, H: float, T: float) -> mujoco.MjModel:
    """A neutrally buoyant sphere (radius 0.05 m: mass = rho V, added mass rho V / 2 on the linear axes, no
    damping) on a free joint, with a tiny welded child (so the body is not "simple"; its mass is taken off
    the sphere's), in a regular wave, RK4 at 2 ms."""
    r, rho = 0.05, 1000.0
    V = 4 / 3 * math.pi * r**3
    ma = 0.5 * rho * V
    child = 1e-3
    wave = (f'<config key="wave_model" value="airy"/><config key="wave_height" value="{H}"/>'
            f'<config key="wave_period" value="{T}"/><config key="wave_depth" value="{depth}"/>')
    xml = f"""<mujoco><option timestep="0.002" integrator="RK4"/>
      <extension><plugin plugin="uvms.water"><instance name="water"><config key="density" value="{rho}"/>{wave}
      </instance></plugin><plugin plugin="uvms.hydro"/></extension>
      <worldbody><body name="ball" pos="0 0 {z0}"><freejoint/>
        <inertial pos="0 0 0" mass="{rho * V - child}" diaginertia="1e-3 1e-3 1e-3"/>
        <plugin plugin="uvms.hydro"><config key="added_mass" value="{ma} {ma} {ma} 0 0 0"/>
          <config key="volume" value="{V}"/></plugin>
        <body name="ballast"><geom type="sphere" size="0.001" mass="{child}" contype="0" conaffinity="0"/></body>
      </body></worldbody></mujoco>"""
    return pm.compile_spec(mujoco.MjSpec.from_string(xml), native=True, source="sphere")


@pytest.mark.parametrize("depth", [0.0, 6.0])
def test_neutral_sphere_follows_the_particle_orbit(lib, depth):
    """With m = rho V the sphere's equation (m + m_a) dv/dt = (rho V + m_a) Du/Dt (Froude-Krylov and added
    mass of the water's material acceleration Du/Dt = du/dt + (u . grad) u; Auton et al. 1988) is the fluid
    particle's: started with the water's velocity it moves with the water, x_dot = u(x, t). Checked over two
    periods against that ODE integrated with scipy (rtol 1e-11) from the closed-form u of the test
    (1e-9 m: scipy's rtol on positions ~1 m and RK4's error at 2 ms, (omega h)^4 A ~ 1e-12 m; measured
    3.5e-13 m), and against the closed orbit of linear
    theory, x0 + int_0^t u(x0, t') dt', within its own error: the Stokes drift omega k A^2 t and the
    distortion of the orbit, 2 k A (omega t) A (A the orbit radius, k A ~ 7e-3 here)."""
    from scipy.integrate import solve_ivp

    H, T, z0 = 0.05, 3.0, -1.0
    m = sphere_model(depth, z0, H, T)
    d = mujoco.MjData(m)
    _, v0, _ = airy_truth(H, T, depth, 0.0, 0.0, 0.0, 0.0, z0)
    d.qvel[:3] = v0
    mujoco.mj_forward(m, d)
    times, xs = [], []
    while d.time < 2 * T - 1e-9:
        mujoco.mj_step(m, d)
        times.append(d.time)
        xs.append(d.qpos[:3].copy())
    times, xs = np.array(times), np.array(xs)
    path = solve_ivp(lambda t, x: airy_truth(H, T, depth, 0.0, t, *x)[1], (0, times[-1]), [0.0, 0.0, z0],
                     t_eval=times, rtol=1e-11, atol=1e-13, method="DOP853").y.T
    assert np.max(np.linalg.norm(xs - path, axis=1)) <= 1e-9
    om = 2 * math.pi / T
    k = k_brentq(om, depth)
    if depth:
        Ah = H / 2 * math.cosh(k * (z0 + depth)) / math.sinh(k * depth)
        Av = H / 2 * math.sinh(k * (z0 + depth)) / math.sinh(k * depth)
    else:
        Ah = Av = H / 2 * math.exp(k * z0)
    # int_0^t a om C cos(-om t') dt' = A_h sin(om t); int_0^t a om S sin(-om t') dt' = A_v (cos(om t) - 1)
    orbit = np.column_stack([Ah * np.sin(om * times), 0 * times, z0 + Av * (np.cos(om * times) - 1)])
    err = np.linalg.norm(xs - orbit, axis=1)
    assert np.all(err <= 2 * k * Ah * om * times * Ah + 1e-7)
    assert np.ptp(xs[:, 0]) > 1.9 * Ah and np.ptp(xs[:, 2]) > 1.9 * Av  # it went round


# ------------------------------------------------------------------ irregular seas


def dnv_spectrum(model: str, Hs: float, Tp: float, gamma: float, om: float) -> float:
    """DNV-RP-C205 3.5.5.1 / 3.5.5.2, written out again for the test."""
    wp = 2 * math.pi / Tp
    s = 5 / 16 * Hs**2 * wp**4 * om**-5 * math.exp(-5 / 4 * (om / wp) ** -4)
    if model == "jonswap":
        sigma = 0.07 if om <= wp else 0.09
        s *= (1 - 0.287 * math.log(gamma)) * gamma ** math.exp(-0.5 * ((om - wp) / (sigma * wp)) ** 2)
    return s


@pytest.mark.parametrize("model", ["jonswap", "pierson_moskowitz"])
def test_realised_sea_has_the_spectrum_hs_and_tp(lib, model):
    """The elevation time series of the C code over 4 h at 0.25 s: Hs = 4 std(eta) against 4 sqrt(m0) of
    the spectrum (quad over the discretised band [0.5, 4] omega_p: outside it the spectrum holds 0.5% of
    m0, documented), and the periodogram's peak against Tp.

    Tolerances: the sample variance of a sum of n = 100 sinusoids over a record T_r has cross terms of
    relative size ~ 1/(d_omega T_r) per pair, 2 pi / d_omega = 73 s << T_r = 4 h, so a fraction of a
    percent; the random frequency offsets make sum S(omega_i) d_omega a stratified-sampling quadrature of
    m0 with a relative error ~ max|S'| d_omega^2 / m0 / sqrt(n) (~1% for the sharp JONSWAP peak). 3% on Hs.
    The peak: the largest component lies within 2 d_omega of omega_p (one node per bin) = 7% of omega_p;
    the periodogram resolves 2 pi / T_r = 4e-4 rad/s. 8% on Tp."""
    Hs, Tp, gamma = 0.3, 4.0, 3.3
    w = Waves(model=model, height=Hs, period=Tp, gamma=gamma, seed=11)
    dt, n = 0.25, 57600
    t = np.arange(n) * dt
    eta = c_eval(lib, w, np.column_stack([t, np.full(n, 3.0), np.full(n, -2.0), np.zeros(n)]))[:, 0]
    wp = 2 * math.pi / Tp
    m0, _ = quad(lambda o: dnv_spectrum(model, Hs, Tp, gamma, o), BAND[0] * wp, BAND[1] * wp, limit=200,
                 points=[wp])
    hs_real = 4 * np.std(eta)
    assert abs(hs_real / (4 * math.sqrt(m0)) - 1) < 0.03, (hs_real, 4 * math.sqrt(m0))
    # the nominal Hs: m0 over all frequencies is Hs^2/16 only up to A_gamma's approximation (DNV)
    m0_all, _ = quad(lambda o: dnv_spectrum(model, Hs, Tp, gamma, o), 1e-3, 200 * wp, limit=400, points=[wp])
    assert abs(4 * math.sqrt(m0_all) / Hs - 1) < 0.02
    P = np.abs(np.fft.rfft(eta - eta.mean())) ** 2
    om = 2 * math.pi * np.fft.rfftfreq(n, dt)
    tp_real = 2 * math.pi / om[np.argmax(P)]
    assert abs(tp_real / Tp - 1) < 0.08, tp_real


def test_c_matches_numpy_and_seeds(lib):
    """C against numpy for a short-crested JONSWAP sea in finite depth (1e-12 relative to the largest
    value: libm and numpy round transcendental functions differently by an ulp); the same seed gives the
    same sea, another seed another."""
    w = Waves(model="jonswap", height=1.2, period=6.0, gamma=2.0, direction=0.4, spreading=4.0, depth=15.0,
              surface=0.5, seed=5, n_components=60)
    rng = np.random.default_rng(9)
    pts = np.column_stack([rng.uniform(0, 50, 30), rng.uniform(-20, 20, (30, 2)), rng.uniform(-15, 0.5, 30)])
    out_c = c_eval(lib, w, pts)
    sea = sea_of(w, G)
    out_n = np.array([[sea.elevation(p[0], p[1], p[2]),
                       *np.concatenate([x.ravel() for x in sea.kinematics(p[0], p[1:], gradient=True)])] for p in pts])
    assert np.max(np.abs(out_c - out_n)) <= 1e-12 * np.max(np.abs(out_n))
    assert np.ptp(sea.c[:, 3]) > 0.1  # spread directions
    again = c_eval(lib, w, pts)
    assert np.array_equal(again, out_c)  # the same code path, the same seed: the same sea
    other = c_eval(lib, Waves(**{**w.__dict__, "seed": 6}), pts)
    assert np.max(np.abs(other - out_c)) > 0.1 * np.max(np.abs(out_c))


# ------------------------------------------------------------------ in the plugin


def load(name: str, **water: str) -> mujoco.MjModel:
    spec = pm.load_spec(MODELS / name)
    if water:
        pm.set_water(spec, **water)
    return pm.compile_spec(spec, native=True, source=name)


@pytest.mark.parametrize("current", [{}, {"current": "0.1 -0.05 0.02"},
                                     {"current_model": "gauss_markov", "current": "0.2 0 0", "gm_sigma": "0.05 0.05 0",
                                      "gm_seed": "3"}])
def test_plugin_with_waves_matches_reference(lib, current, rng):
    """The plugin's added mass and generalized forces in waves (plus a current) equal the reference's to
    1e-12 (as tests/test_plugin_reference.py), strips included (each sees the waves at its midpoint)."""
    waves = Waves(model="jonswap", height=0.8, period=3.0, depth=12.0, surface=4.0, spreading=2.0, seed=2,
                  n_components=40).attributes()
    m = load("robot3d.xml", **current, **waves)
    info = pm.hydro_of(m)
    assert info.water.waves.model == "jonswap" and info.water.waves.n_components == 40
    d = mujoco.MjData(m)
    for k in range(6):
        mujoco.mj_resetData(m, d)
        d.qpos[:3] = rng.uniform(-1, 1, 3)
        q = rng.normal(size=4)
        d.qpos[3:7] = q / np.linalg.norm(q)
        d.qpos[7:] = rng.uniform(-1.5, 1.5, m.nq - 7)
        d.qvel[:] = rng.normal(0, 0.5, m.nv)
        for _ in range(k):
            mujoco.mj_step(m, d)
        # a later time (inside the Gauss-Markov sample interval, where the reference interpolates)
        d.time += 0.3 * m.opt.timestep if current.get("current_model") == "gauss_markov" else 0.37
        M, Q = added_and_passive(m, d)
        M0, Q0 = reference.passive(m, d, info.water, info.bodies, pm.current_state_of(m, d))
        assert np.max(np.abs(M - M0)) <= 1e-12 * max(1.0, np.max(np.abs(M0)))
        assert np.max(np.abs(Q - Q0)) <= 1e-12 * max(1.0, np.max(np.abs(Q0)))
    # the waves change the forces (they are not silently off)
    m1 = load("robot3d.xml", **current)
    d1 = mujoco.MjData(m1)
    d1.qpos[:], d1.qvel[:], d1.time = d.qpos, d.qvel, d.time
    d1.plugin_state[:] = d.plugin_state
    _, Q1 = added_and_passive(m1, d1)
    assert np.max(np.abs(Q1 - Q)) > 1e-3 * np.max(np.abs(Q))


def test_no_waves_leaves_the_forces_unchanged(lib, rng):
    """wave_model none (or absent) is the still water of before, in the same code: equal to 1e-15."""
    m0, m1 = load("robot3d.xml"), load("robot3d.xml", wave_model="none", wave_height="1", wave_period="5")
    d0, d1 = mujoco.MjData(m0), mujoco.MjData(m1)
    for d in (d0, d1):
        d.qpos[:3] = (0.3, -0.2, 0.1)
        d.qvel[:] = np.linspace(-0.5, 0.5, m0.nv)
    M0, Q0 = added_and_passive(m0, d0)
    M1, Q1 = added_and_passive(m1, d1)
    assert np.max(np.abs(Q1 - Q0)) <= 1e-15 * np.max(np.abs(Q0))
    assert np.max(np.abs(M1 - M0)) <= 1e-15 * np.max(np.abs(M0))


@pytest.mark.parametrize("water, message", [
    ({"wave_model": "stokes"}, "wave_model"),
    ({"wave_model": "jonswap", "wave_height": "0.3"}, "wave_period"),
    ({"wave_model": "jonswap", "wave_height": "0.3", "wave_period": "4", "wave_gamma": "9"}, "gamma"),
    ({"wave_model": "airy", "wave_height": "-1", "wave_period": "4"}, "wave_height"),
    ({"wave_model": "airy", "wave_height": "1", "wave_period": "4", "wave_components": "0"}, "components"),
])
def test_bad_wave_attributes_are_refused(lib, water, message):
    with pytest.raises(Exception, match=message):
        load("robot3d.xml", **water)


def test_waves_need_gravity_along_minus_z(lib):
    spec = pm.load_spec(MODELS / "robot3d.xml")
    pm.set_water(spec, wave_model="airy", wave_height="1", wave_period="4")
    spec.option.gravity = [0.0, -9.81, 0.0]
    with pytest.raises(Exception, match="gravity along -z"):
        mujoco.MjData(pm.compile_spec(spec, native=True, source="robot3d.xml"))


# ------------------------------------------------------------------ scenario, plant, log


def test_scenario_waves_are_logged_and_the_surface_is_checked():
    """A scenario's waves: section reaches the plugin; the log carries the elevation and the wave velocity
    at the vehicle (equal to the numpy sea there); a vehicle at the surface is refused; a run is
    deterministic per seed."""
    from uvms_mj.scenario.base import ScenarioError
    from uvms_mj.scenario.schema import Scenario, build, run_scenario as run

    doc = {"robot": "bluerov2_heavy", "duration": 1.0, "seed": 4,
           "waves": {"model": "jonswap", "hs": 0.3, "tp": 4.0, "direction": 30},
           "initial": {"position": [0.0, 0.0, -2.0]}}
    sc = Scenario.model_validate(doc)
    plant, _ = build(sc)
    w = pm.hydro_of(plant.model).water.waves
    assert (w.model, w.height, w.period, w.seed) == ("jonswap", 0.3, 4.0, 4)
    assert abs(w.direction - math.radians(30)) < 1e-15
    res = run(sc)
    eta, vel = res.signals["wave_elevation"], res.signals["wave_velocity"]
    assert eta.shape == res.t.shape and vel.shape == (len(res.t), 3)
    sea = sea_of(w, G)
    k = len(res.t) // 2
    x, y = res.signals["q_true"][k][:2]
    assert abs(eta[k] - sea.elevation(res.t[k], x, y)) < 1e-3  # the vehicle's hydro centre is near its origin
    assert np.std(vel[:, 0]) > 0
    again = run(Scenario.model_validate(doc))
    assert np.array_equal(again.signals["wave_elevation"], eta)
    with pytest.raises(ScenarioError, match="above the mean surface"):
        build(Scenario.model_validate({**doc, "initial": {"position": [0.0, 0.0, 0.0]}}))


def test_waves_section_validation():
    from uvms_mj.scenario.schema import Scenario

    for bad, word in (({"model": "jonswap", "hs": 0.3, "height": 0.3, "tp": 4}, "not both"),
                      ({"model": "jonswap", "hs": 0.3}, "period"),
                      ({"model": "airy", "hs": 0.3, "period": 4}, "height")):
        with pytest.raises(Exception, match=word):
            Scenario.model_validate({"robot": "bluerov2_heavy", "waves": bad})


def test_python_backend_matches_native_in_waves():
    """The Python backend (the reference through mjcb_passive) and the C plugin give the same motion in
    waves: 0.2 s of the BlueROV2 with its arm in a JONSWAP sea, to 1e-9 (rounding differences of 1e-12 in
    the forces, grown by 50 steps; measured 2e-16)."""
    from uvms_mj.plant.layout import InitialState
    from uvms_mj.plant.plant import Plant

    w = Waves(model="jonswap", height=0.3, period=4.0, seed=3)
    q = []
    for be in ("native", "python"):
        p = Plant("bluerov2_alpha", waves=w, backend=be, initial=InitialState(position=(0, 0, -2.0)))
        for _ in range(50):
            p.step()
        q.append(p.data.qpos.copy())
    assert np.max(np.abs(q[0] - q[1])) <= 1e-9
    assert np.max(np.abs(q[0][:3] - (0, 0, -2.0))) > 1e-5  # the waves moved it


def test_a_body_rising_above_the_surface_is_warned_about():
    """During a run (the plant's per-sample signals) a centre of buoyancy above the mean surface warns
    once, naming the body; below it nothing is said."""
    from uvms_mj.plant.layout import InitialState
    from uvms_mj.plant.plant import Plant

    p = Plant("bluerov2_heavy", waves=Waves(model="airy", height=0.2, period=3.0, surface=-1.0),
              initial=InitialState(position=(0, 0, -2.0)))
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert set(p.sea_signals()) == {"wave_elevation", "wave_velocity"}
    p.data.qpos[2] = -0.5  # 0.5 m above the mean surface at z = -1
    with pytest.warns(RuntimeWarning, match="above the mean surface"):
        p.sea_signals()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        p.sea_signals()  # once
