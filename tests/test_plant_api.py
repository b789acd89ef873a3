"""The Plant API: named accessors, bad input, divergence, several plants in one process."""

from pathlib import Path

import mujoco
import numpy as np
import pytest

from uvms_mj import DivergenceError, HydroTerms, ParameterError, Plant, default_model_path, read_params

SPHERE = """<mujoco><worldbody><body><freejoint/><geom size="0.1" mass="1"/></body></worldbody></mujoco>"""


def test_model_holds_table1():
    """The model file carries the paper's Table 1 (second 'Added mass (x)' row read as y)."""
    p = Plant().params
    table = {
        "base": (26.04, 1.33, 0.2, 0.81, 0.42, (72.7, 6.28), 1.05, (1.2, 1.2)),
        "link1": (4.25, 0.19, 0.25, 0.04, 0.12, (1.31, 3.57), 0.11, (0.0, 1.2)),
        "link2": (1.23, 0.012, 0.25, 0.04, 0.12, (0.1, 2.83), 0.06, (0.0, 1.2)),
    }
    for name, (m, inertia, lx, ly, width, am, ia, cd) in table.items():
        b = p.body(name)
        assert (b.mass, b.inertia, b.added_mass, b.added_inertia, b.drag_coef) == (m, inertia, am, ia, cd)
        np.testing.assert_allclose([2 * b.box_half[0], 2 * b.box_half[1], b.width], [lx, ly, width], rtol=1e-15)
    assert p.joint1_offset == (0.1, 0.0)  # base frame (l0x / 2, 0), docs/paper-reading.md


def test_accessors_and_inputs():
    plant = Plant()
    np.testing.assert_allclose(plant.base_pose, [0, 0, -np.pi / 2])
    np.testing.assert_allclose(plant.joint_angles, [np.pi / 3, -5 * np.pi / 18])
    assert plant.tip_position.shape == (2,)
    plant.set_state(base_pose=(1.0, 2.0, 0.1), joint_angles=(0.2, 0.3), base_velocity=(0.1, 0, 0))
    np.testing.assert_allclose(plant.q, [1.0, 2.0, 0.1, 0.2, 0.3])
    plant.set_thrust([1.0, 2.0, 3.0])
    plant.set_joint_torques([0.1, 0.2])
    plant.step(10)
    assert plant.time == pytest.approx(10 * plant.model.opt.timestep)
    assert np.all(plant.thruster_forces > 0)
    plant.reset()
    assert plant.time == 0 and np.all(plant.thruster_forces == 0)


@pytest.mark.parametrize(
    "overrides, pattern",
    [
        ({"link1.mass": -1.0}, r"link1\.mass = -1\.0 kg must be > 0"),
        ({"base.volume": -0.01}, r"base\.volume = -0\.01 m\^3 must be >= 0"),
        ({"link2.added_mass": [0.1, -2, 0.06]}, r"link2\.added_mass = .* must be >= 0"),
        ({"base.drag_coef": [1.2]}, r"'base\.drag_coef' .* must have 2 value"),
        ({"link3.mass": 1.0}, r"override 'link3\.mass': the model has no body, joint or actuator named 'link3' "
                              r"\(did you mean 'link2'\?\)"),
        ({"joint1.dampin": 1.0}, r"unknown field 'dampin' for joint/actuator 'joint1' \(did you mean 'damping'\?\)"),
        ({"water_density": 0.0}, r"water_density = 0\.0 kg/m\^3 must be > 0"),
        ({"thrusters.tau": 0.0}, r"thruster1\.tau = 0\.0 s must be > 0"),
        ({"thrusters.force_range": [1.0, 5.0]}, r"force_range = \(1\.0, 5\.0\) N must satisfy min < 0 < max"),
    ],
)
def test_bad_parameters_are_named(overrides, pattern):
    with pytest.raises(ParameterError, match=pattern):
        Plant(overrides=overrides)


def test_bad_model_files(tmp_path: Path):
    with pytest.raises(ParameterError, match="nope.xml.*neither a built-in robot .* nor an existing MJCF file"):
        Plant(tmp_path / "nope.xml")
    xml = (default_model_path().parent / "uvms.xml").read_text()
    broken = tmp_path / "uvms.xml"
    broken.write_text(xml.replace('<config key="volume" value="0.0294352"/>', '<config key="volume" value="-1"/>'))
    with pytest.raises(ParameterError, match=r"body 'base'.*volume.*-1"):
        Plant(broken)
    broken.write_text(xml.replace('name="tip"', 'name="end"'))
    with pytest.raises(ParameterError, match=r"no site \(end tip\) named 'tip'"):
        Plant(broken)
    broken.write_text("<mujoco><worldbody><body><geom size='1'/></worldbody></mujoco>")
    with pytest.raises(ParameterError, match="cannot (load|read|compile)"):
        Plant(broken)


def test_bad_options():
    with pytest.raises(ParameterError, match=r"integrator = 'leapfrog'; allowed: euler, rk4"):
        Plant(integrator="leapfrog")
    with pytest.raises(ParameterError, match=r"timestep = -0\.001"):
        Plant(timestep=-0.001)
    with pytest.raises(ValueError, match=r"HydroTerms\.drag = 'stokes'; allowed: strip, mujoco, off"):
        HydroTerms(drag="stokes")
    plant = Plant()
    with pytest.raises(ValueError, match="thruster commands"):
        plant.set_thrust([1.0, np.nan, 0.0])
    with pytest.raises(ValueError, match="joint_angles"):
        plant.set_state(joint_angles=(1.0,))


@pytest.mark.parametrize("backend", ["python", "auto"])  # auto: native where it can be built
def test_divergence_is_reported_with_its_time(backend):
    plant = Plant(backend=backend)
    plant.step(12)  # 0.1 s
    plant.data.qvel[3] = 1e6  # a runaway joint rate
    with pytest.raises(DivergenceError, match=r"diverged at t = 0\.1000 s: runaway: sum \|q_dot\| = 1e\+06"):
        plant.step(10)
    with pytest.raises(DivergenceError):  # stays diverged until reset
        plant.step(1)
    plant.reset()
    plant.step(3)
    plant.data.qvel[0] = np.nan
    with pytest.raises(DivergenceError, match=r"t = 0\.0250 s: non-finite"):
        plant.step(5)
    plant.reset()
    plant.step(1)


def test_batched_steps_are_single_steps_and_report_a_divergence_where_it_happened():
    """Plant.step(n) runs n steps at once (mj_step nstep) from a saved state: the same state as n
    single steps, bit for bit; a runaway inside the batch (full thrust, max_speed 1) is
    replayed step by step and reported at the step where it happened, as with single steps."""
    a, b = Plant(), Plant()
    for p in (a, b):
        p.set_thrust([5.0, -3.0, 2.0])
    a.step(40)
    for _ in range(40):
        b.step(1)
    assert np.array_equal(a.data.qpos, b.data.qpos) and np.array_equal(a.data.qvel, b.data.qvel)
    assert a.time == b.time
    msgs = []
    for batch in (60, 1):
        p = Plant(max_speed=1.0)
        p.set_thrust([30.0, 30.0, 30.0])
        with pytest.raises(DivergenceError) as info:
            for _ in range(600 // batch):
                p.step(batch)
        msgs.append(str(info.value))
    assert msgs[0] == msgs[1] and "runaway" in msgs[0]
    t = float(msgs[0].split("t = ")[1].split(" s")[0])
    assert 0.0 < t < 600 * Plant().model.opt.timestep and round(t / Plant().model.opt.timestep) % 60 != 0


@pytest.mark.parametrize("kind", ["paper", "bluerov2_alpha"])
def test_step_observe_is_step_then_observe(kind):
    """The compiled sample (physics/plant_io.c) against the Python methods on a twin plant: the
    same states, tip and thrust readouts bit for bit over 200 samples of changing commands, and
    a state spoiled from outside reported as step() reports it."""
    from uvms_mj.physics import plant_io
    from uvms_mj.plant.layout import InitialState
    from uvms_mj.plant.plant import Plant

    if plant_io.plant_io_library() is None:
        pytest.skip(f"no compiled plant sample: {plant_io.plant_io_unavailable_reason()}")

    def make():
        if kind == "paper":
            return Plant()
        return Plant("bluerov2_alpha", initial=InitialState(position=(0, 0, -1),
                                                                joints={"alpha_shoulder": 1.9, "alpha_elbow": 1.2}))

    fast, slow = make(), make()
    slow._io_tried = slow.data  # the Python path
    assert fast._plant_io() is not None and slow._plant_io() is None
    nthr, nmot = len(fast._thr), len(fast._mot)
    rng = np.random.default_rng(1)
    for k in range(200):
        thrust, torques = rng.uniform(-5, 5, nthr), rng.uniform(-0.5, 0.5, nmot) * (1 if kind == "paper" else 0.01)
        fast.command(thrust, torques)
        slow.set_thrust(thrust)
        slow.set_joint_torques(torques)
        a = fast.step_observe(2)
        slow.step(2)
        b = slow.observe()
        # exact: plant_io.c runs the same mj_step and only copies and clamps its outputs (no
        # arithmetic of its own that a compiler or numpy's SIMD dispatch could order differently)
        for x, y in zip(a[:3], b[:3]):
            assert np.array_equal(x, y)
        thr = a[3] if a[3] is not None else fast.thruster_forces
        assert np.array_equal(thr, b[3])
    for p in (fast, slow):
        p.data.qvel[0] = np.nan
    msgs = []
    for p, go in ((fast, lambda: fast.step_observe(2)), (slow, lambda: slow.step(2))):
        with pytest.raises(DivergenceError) as info:
            go()
        msgs.append(str(info.value))
    assert msgs[0] == msgs[1] and "non-finite" in msgs[0]


def run_alone(**kw) -> np.ndarray:
    p = Plant(**kw)
    p.set_state(base_velocity=(0.1, 0.0, 0.3))
    p.step(300)
    return p.q


def test_several_plants_in_one_process():
    """Two plants with different physics stepped in alternation give exactly their solo runs, and a
    model compiled and stepped meanwhile is untouched by the hydrodynamics hook."""
    solo_a = run_alone()
    solo_b = run_alone(current=(0.2, 0.0), overrides={"base.added_mass": [50.0, 10.0, 1.0]})
    a = Plant()
    b = Plant(current=(0.2, 0.0), overrides={"base.added_mass": [50.0, 10.0, 1.0]})
    for p in (a, b):
        p.set_state(base_velocity=(0.1, 0.0, 0.3))
    sphere = mujoco.MjModel.from_xml_string(SPHERE)  # compiling while plants are alive works
    sd = mujoco.MjData(sphere)
    for _ in range(300):
        a.step(1)
        b.step(1)
        mujoco.mj_step(sphere, sd)
    np.testing.assert_array_equal(a.q, solo_a)
    np.testing.assert_array_equal(b.q, solo_b)
    assert sd.qacc[2] == pytest.approx(-9.81)  # plain free fall: no hydrodynamics leaked in


def test_plain_mujoco_calls_include_hydrodynamics():
    """mj_forward on plant.model / plant.data yields accelerations with added mass."""
    plant = Plant(gravity=False, terms=HydroTerms(drag="off", buoyancy=False))
    plant.set_state(base_pose=(0, 0, 0), joint_angles=(0, 0))
    plant.data.qfrc_applied[:] = 0
    plant.data.qfrc_applied[0] = 10.0
    mujoco.mj_forward(plant.model, plant.data)
    M = plant.mass_matrix()
    np.testing.assert_allclose(M @ plant.data.qacc, plant.data.qfrc_applied, atol=1e-12)
    assert M[0, 0] > read_params(plant.model).body("base").mass + 72.7  # rigid + added (body x)


@pytest.mark.parametrize("backend", ["native", "python"])
def test_extra_data(backend, native_available):
    """make_data() gives data in water with either backend. With the native backend the water is
    part of the model, so even a plain mujoco.MjData(plant.model) is; with the Python backend
    plain data of the (stripped) model is not served and drifts differently."""
    if backend == "native" and not native_available:
        pytest.skip("the C plugins are unavailable here")
    plant = Plant(backend=backend)
    d2 = plant.make_data()
    mujoco.mj_resetDataKeyframe(plant.model, d2, 0)
    for _ in range(100):
        mujoco.mj_step(plant.model, d2)
    plant.step(100)
    np.testing.assert_array_equal(d2.qpos, plant.data.qpos)
    stray = mujoco.MjData(plant.model)
    mujoco.mj_resetDataKeyframe(plant.model, stray, 0)
    for _ in range(100):
        mujoco.mj_step(plant.model, stray)
    assert np.array_equal(stray.qpos, plant.data.qpos) == (backend == "native")


def test_tip_position_is_current_after_steps():
    """After mj_step, MuJoCo's site_xpos lags the state (RK4: an intermediate stage); the
    accessor must give the tip of the current qpos (analytic Eq. 1, 1e-12)."""
    from oracles.planar.kinematics import ArmGeometry, tip_position

    plant = Plant()
    plant.set_state(joint_velocities=(1.0, -1.0))
    plant.step(5)
    geom = ArmGeometry.from_params(plant.params)
    np.testing.assert_allclose(plant.tip_position, tip_position(geom, plant.q), rtol=0, atol=1e-12)
