"""Importing does only what importing should (issue 18): `import uvms_mj` and every module under
it leave os.environ and the SIGINT/SIGTERM handlers as they were and compile or register nothing
(the build cache, pointed at an empty folder, stays empty; no uvms plugin is known to MuJoCo);
the plugins are registered by the first model load; one switch, UVMS_MJ_COMPILED, chooses the
compiled or the Python paths, and the former switches are refused in one line.

Each check runs in a fresh interpreter (the test process has long imported and registered all).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LEGACY = ("UVMS_MJ_PLUGIN", "UVMS_MJ_BACKEND", "UVMS_MJ_KERNEL")


def _env(tmp_path: Path, **extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in (*LEGACY, "UVMS_MJ_COMPILED")}
    env["UVMS_MJ_CACHE"] = str(tmp_path / "cache")  # empty: any compilation would land here
    env.update(extra)
    return env


def _python(code: str, env: dict[str, str], timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], env=env, capture_output=True, text=True,
                          timeout=timeout)


_IMPORT_ALL = """
    import os, signal, sys, json, pkgutil, importlib, warnings
    if WALK:  # third-party import effects are theirs (gymnasium sets PYGAME_HIDE_SUPPORT_PROMPT)
        for name in ("gymnasium", "shimmy.dm_control_compatibility", "dm_control.mujoco"):
            try:
                importlib.import_module(name)
            except ImportError:
                pass
    env0 = dict(os.environ)
    sig0 = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        import uvms_mj
        names = ["uvms_mj"]
        if WALK:
            for info in pkgutil.walk_packages(uvms_mj.__path__, "uvms_mj."):
                importlib.import_module(info.name)
                names.append(info.name)
    out = {
        "modules": names,
        "env_changed": sorted(k for k in set(env0) | set(os.environ) if env0.get(k) != os.environ.get(k)),
        "signals_changed": [int(s) for s, h in sig0.items() if signal.getsignal(s) is not h],
        "cache": sorted(os.listdir(os.environ["UVMS_MJ_CACHE"])) if os.path.isdir(os.environ["UVMS_MJ_CACHE"]) else [],
        "warnings": [str(w.message) for w in caught if "uvms_mj" in str(w.message)],
        "mujoco": "mujoco" in sys.modules,
    }
    if out["mujoco"]:
        import mujoco
        probe = ('<mujoco><extension><plugin plugin="uvms.water"><instance name="w"/></plugin></extension>'
                 '<worldbody/></mujoco>')
        try:
            mujoco.MjModel.from_xml_string(probe)
            out["registered"] = True
        except ValueError:
            out["registered"] = False
    print(json.dumps(out))
"""


@pytest.mark.parametrize("walk", [False, True], ids=["package", "every-module"])
def test_import_has_no_side_effects(tmp_path: Path, walk: bool) -> None:
    """`import uvms_mj` (and, walked with pkgutil, every module under it): os.environ unchanged
    (MUJOCO_GL included: unset here, no display), SIGINT/SIGTERM handlers unchanged, nothing
    compiled into the (empty) cache, no uvms plugin registered, no warning."""
    env = _env(tmp_path)
    for k in ("MUJOCO_GL", "PYOPENGL_PLATFORM", "DISPLAY", "WAYLAND_DISPLAY"):
        env.pop(k, None)
    proc = _python(_IMPORT_ALL.replace("WALK", str(walk)), env)
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    if walk:
        assert len(out["modules"]) > 40 and "uvms_mj.analysis.render_gl" in out["modules"]
    else:
        assert out["mujoco"] is False  # the package itself imports nothing heavy
    assert out["env_changed"] == [], out["env_changed"]
    assert out["signals_changed"] == []
    assert out["cache"] == []
    assert out["warnings"] == []
    assert out.get("registered", False) is False


def test_first_model_load_registers_the_plugins(tmp_path: Path, native_available: bool) -> None:
    """Loading a uvms model (a Plant) builds the plugins into the cache and registers them, so
    that plain MuJoCo then parses a file that uses them; the environment is still unchanged."""
    if not native_available:
        pytest.skip("no C compiler here: the plugins cannot be built")
    code = """
        import os, json, mujoco
        env0 = dict(os.environ)
        import uvms_mj
        from uvms_mj.physics import build
        plant = uvms_mj.Plant()
        plant.step(12)
        m = mujoco.MjModel.from_xml_path(str(uvms_mj.default_model_path()))
        print(json.dumps({"backend": plant.backend, "nplugin": m.nplugin, "env": dict(os.environ) == env0,
                          "cache": sorted(os.listdir(os.environ["UVMS_MJ_CACHE"]))}))
    """
    proc = _python(code, _env(tmp_path))
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["backend"] == "native" and out["nplugin"] > 0 and out["env"]
    assert any(name.startswith("uvms_plugins-") for name in out["cache"])


def test_compiled_off_runs_on_python_paths(tmp_path: Path) -> None:
    """UVMS_MJ_COMPILED=off: a short paper run (RAC with DOB) on the Python hydrodynamics, the
    RAC's Python code and the nominal model's Python closed form; nothing compiled, no warning."""
    code = """
        import os, json, warnings
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            from uvms_mj.sim.experiment import PaperExperiment
            from uvms_mj.physics import build
            exp = PaperExperiment(duration=0.5)
            plant, ctrl = exp.build()
            res = exp.run()
        print(json.dumps({"status": res.status, "backend": plant.backend, "registered": build.register_plugins(),
                          "reason": build.unavailable_reason(), "ws": getattr(ctrl, "_ws", None) is None,
                          "cache": os.listdir(os.environ["UVMS_MJ_CACHE"]) if os.path.isdir(os.environ["UVMS_MJ_CACHE"]) else [],
                          "warnings": [str(w.message) for w in caught if "uvms_mj" in str(w.message)]}))
    """
    proc = _python(code, _env(tmp_path, UVMS_MJ_COMPILED="off"))
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["status"] == "ok" and out["backend"] == "python"
    assert out["registered"] is False and "UVMS_MJ_COMPILED=off" in out["reason"]
    assert out["cache"] == [] and out["warnings"] == []


@pytest.mark.parametrize("var, value, expect", [
    ("UVMS_MJ_COMPILED", "bogus", "UVMS_MJ_COMPILED='bogus' is not one of auto, on, off"),
    *[(k, "off", f"{k}=off is no longer read: unset it and use UVMS_MJ_COMPILED=auto|on|off") for k in LEGACY],
])
def test_bad_switch_is_one_line(tmp_path: Path, var: str, value: str, expect: str) -> None:
    """A bad UVMS_MJ_COMPILED, or a former switch set: import still works; the first model load
    raises CompiledModeError with one line; the CLI says that line and exits 2, no traceback."""
    code = """
        import uvms_mj
        from uvms_mj.physics.build import CompiledModeError
        try:
            uvms_mj.Plant()
        except CompiledModeError as exc:
            print(f"error: {exc}")
    """
    env = _env(tmp_path, **{var: value})
    proc = _python(code, env)
    assert proc.returncode == 0, proc.stderr[-3000:]
    lines = proc.stdout.strip().splitlines()
    assert len(lines) == 1 and expect in lines[0], proc.stdout
    cli = subprocess.run([sys.executable, "-m", "uvms_mj.cli.main", "run", str(ROOT / "scenarios" / "paper.yaml"),
                          "--set", "duration=0.1", "--out", str(tmp_path / "x.mcap")],
                         env=env, capture_output=True, text=True, timeout=300)
    assert cli.returncode == 2, cli.stdout + cli.stderr
    assert "Traceback" not in cli.stderr
    err = cli.stderr.strip().splitlines()
    assert len(err) == 1 and err[0] == f"error: {lines[0].removeprefix('error: ')}", cli.stderr
    assert not (tmp_path / "x.mcap").exists()


def test_compiled_on_without_a_compiler_is_a_clear_error(tmp_path: Path) -> None:
    """UVMS_MJ_COMPILED=on with no C compiler (and an empty cache): the first model load raises
    PluginUnavailableError naming the switch and the reason, in one line."""
    code = """
        import uvms_mj
        from uvms_mj.physics.build import PluginUnavailableError
        try:
            uvms_mj.Plant()
        except PluginUnavailableError as exc:
            print(f"error: {exc}")
    """
    proc = _python(code, _env(tmp_path, UVMS_MJ_COMPILED="on", CC="/nonexistent/cc"))
    assert proc.returncode == 0, proc.stderr[-3000:]
    lines = proc.stdout.strip().splitlines()
    assert len(lines) == 1 and "UVMS_MJ_COMPILED=on" in lines[0] and "/nonexistent/cc" in lines[0], proc.stdout
