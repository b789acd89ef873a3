"""``uvms-mj paper``, ``drift`` and ``view``: the paper's experiment and the plant without a
scenario file, and a model file in MuJoCo's viewer."""

from __future__ import annotations

import sys
from pathlib import Path

import click
import numpy as np

from uvms_mj.cli.common import EXIT_DIVERGED, EXIT_RENDER, metrics_table
from uvms_mj.physics.terms import HydroTerms
from uvms_mj.plant.params import ParameterError
from uvms_mj.plant.plant import DivergenceError, Plant


@click.command()
@click.option("--controllers", default="rac,rac_dob", show_default=True,
              help="Comma-separated controller names to run (registered: see --list).")
@click.option("--duration", type=click.FloatRange(min=0, min_open=True, max=3600), default=40.0, show_default=True,
              help="Simulated time [s].")
@click.option("--thruster-lag", type=click.FloatRange(min=0, min_open=True, max=10), default=None,
              help="Plant thruster time constant [s] (default: the model's 0.02 s).")
@click.option("--ideal", is_flag=True, help="Plant identical to the nominal model (no modelling error).")
@click.option("--list", "list_only", is_flag=True, help="List the registered controllers and exit.")
def paper(controllers: str, duration: float, thruster_lag: float | None, ideal: bool, list_only: bool) -> None:
    """Run the paper's experiment with each controller and print RMS / max errors side by side
    (no log; see `compare scenarios/paper.yaml` for logs, figures and videos)."""
    from uvms_mj.control import ControllerError, available
    from uvms_mj.sim.experiment import PaperExperiment, metrics

    if list_only:
        click.echo("\n".join(available()))
        return
    names = [c.strip() for c in controllers.split(",") if c.strip()]
    unknown = [c for c in names if c not in available()]
    if unknown:
        raise click.BadParameter(f"unknown controller(s) {', '.join(unknown)}; registered: {', '.join(available())}",
                                 param_hint="--controllers")
    twice = sorted({c for c in names if names.count(c) > 1})
    if twice:
        raise click.BadParameter(f"{', '.join(twice)} given twice: each controller once", param_hint="--controllers")
    if thruster_lag is not None:
        from uvms_mj.scenario.schema import LAG_STABILITY

        dt = 1.0 / 120.0  # the model's RK4 step, which `paper` uses
        if dt / thruster_lag >= LAG_STABILITY["rk4"]:
            raise click.BadParameter(f"{thruster_lag!r} s: the thruster lag integrates stably with rk4 at "
                                     f"{dt:.6g} s only for a lag > {dt / LAG_STABILITY['rk4']:.6g} s",
                                     param_hint="--thruster-lag")
    over = {} if thruster_lag is None else {"thrusters.tau": thruster_lag}
    results, states = {}, {}
    status = 0
    for name in names:
        try:
            res = PaperExperiment(controller=name, duration=duration, truth=not ideal, plant_overrides=over).run()
        except (ControllerError, ParameterError, ValueError) as exc:
            raise click.UsageError(str(exc)) from None
        if res.status != "ok":
            click.echo(f"{name}: {res.reason}", err=True)
            status = EXIT_DIVERGED
        results[name], states[name] = metrics(res), res.status
    click.echo(metrics_table(results, states))
    sys.exit(status)


def _yaml_value(item: str, text: str):
    """A --set value parsed as YAML, exactly as ``run --set`` parses it (numbers, [lists]...);
    the older comma form (``1.3,3.6,0.11``, a YAML string) is still read as a list of numbers."""
    from uvms_mj.scenario.schema import ScenarioError, apply_sets

    try:
        value = apply_sets({}, [f"v={text}"])["v"]
    except ScenarioError:
        raise click.BadParameter(f"{item!r}: the value is not valid YAML", param_hint="--set") from None
    if isinstance(value, str) and "," in value:
        try:
            value = [float(v) for v in value.split(",")]
        except ValueError:
            pass
    if isinstance(value, str) or (isinstance(value, list) and not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)):
        raise click.BadParameter(f"{item!r}: the value must be a number or a list of numbers, e.g. [1.3, 3.6, 0.11]",
                                 param_hint="--set")
    return value


@click.command()
@click.option("--seconds", type=click.FloatRange(min=0, min_open=True, max=3600), default=10.0, show_default=True,
              help="Simulated time [s].")
@click.option("--current", type=(float, float), default=(0.0, 0.0), show_default=True,
              help="Uniform water current, world X and Y [m/s].")
@click.option("--drag", type=click.Choice(["strip", "mujoco", "off"]), default="strip", show_default=True,
              help="Drag model.")
@click.option("--set", "overrides", multiple=True, metavar="KEY=VALUE",
              help="Parameter override, the value in YAML as for run --set, e.g. --set base.volume=0.03 "
                   "--set link1.added_mass=[1.3,3.6,0.11]")
def drift(seconds: float, current: tuple[float, float], drag: str, overrides: tuple[str, ...]) -> None:
    """Let the robot drift passively from the paper's initial pose and print its state."""
    try:
        parsed = {}
        for item in overrides:
            key, sep, value = item.partition("=")
            if not sep:
                raise click.BadParameter(f"{item!r} is not KEY=VALUE", param_hint="--set")
            parsed[key.strip()] = _yaml_value(item, value)
        plant = Plant(overrides=parsed, current=current, terms=HydroTerms(drag=drag))
    except ParameterError as exc:
        raise click.UsageError(str(exc)) from None
    per_second = round(1.0 / plant.model.opt.timestep)
    click.echo(f"{'t [s]':>6} {'p0x [m]':>9} {'p0y [m]':>9} {'phi0 [rad]':>11} {'phi1':>8} {'phi2':>8}"
               f" {'tip x':>8} {'tip y':>8} {'E [J]':>9}")
    try:
        for k in range(int(np.ceil(seconds)) + 1):
            if k:
                plant.step(per_second)
            q, tip = plant.q, plant.tip_position
            click.echo(f"{plant.time:6.1f} {q[0]:9.4f} {q[1]:9.4f} {q[2]:11.4f} {q[3]:8.4f} {q[4]:8.4f}"
                       f" {tip[0]:8.4f} {tip[1]:8.4f} {plant.energy().total:9.3f}")
    except DivergenceError as exc:
        click.echo(f"error: {exc}", err=True)
        sys.exit(EXIT_DIVERGED)


@click.command()
@click.argument("model", default="paper")
def view(model: str) -> None:
    """Open MODEL in MuJoCo's interactive viewer, in water (MODEL: an MJCF file or 'paper')."""
    import os

    from uvms_mj.physics import build
    from uvms_mj.physics import model as pm
    from uvms_mj.plant.plant import default_model_path

    path = default_model_path() if model == "paper" else Path(model)
    if not build.register_plugins():
        raise click.UsageError(f"the viewer needs the C plugins: {build.unavailable_reason()}")
    try:
        m = pm.load_model(path, native=True)
    except pm.ModelError as exc:
        raise click.UsageError(str(exc)) from None
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        click.echo("uvms-mj view needs a display (no DISPLAY or WAYLAND_DISPLAY is set); "
                   "for video without one use uvms-mj render", err=True)
        sys.exit(EXIT_RENDER)
    import mujoco.viewer

    mujoco.viewer.launch(m)
