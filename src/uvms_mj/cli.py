"""The ``uvms-mj`` command line.

* ``paper``: the paper's experiment (Section 4) with and without the disturbance observer, and a
  metrics table;
* ``drift``: the plant left to itself from the paper's initial pose, its state every second.

Scenario files, logs, video and plots come with the testbed issue.
"""

from __future__ import annotations

import sys

import click
import numpy as np

from . import __version__
from .hydro import HydroTerms
from .params import ParameterError
from .plant import DivergenceError, Plant


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="uvms-mj")
def main() -> None:
    """uvms-mj: a MuJoCo testbed for underwater vehicle-manipulator systems."""


@main.command()
@click.option("--seconds", type=click.FloatRange(min=0, min_open=True), default=10.0, show_default=True,
              help="Simulated time [s].")
@click.option("--current", type=(float, float), default=(0.0, 0.0), show_default=True,
              help="Uniform water current, world X and Y [m/s].")
@click.option("--drag", type=click.Choice(["strip", "mujoco", "off"]), default="strip", show_default=True,
              help="Drag model.")
@click.option("--set", "overrides", multiple=True, metavar="KEY=VALUE",
              help="Parameter override, e.g. --set base.volume=0.03 --set link1.added_mass=1.3,3.6,0.11")
def drift(seconds: float, current: tuple[float, float], drag: str, overrides: tuple[str, ...]) -> None:
    """Let the robot drift passively from the paper's initial pose and print its state."""
    try:
        parsed = {}
        for item in overrides:
            key, sep, value = item.partition("=")
            if not sep:
                raise click.BadParameter(f"{item!r} is not KEY=VALUE", param_hint="--set")
            try:
                nums = [float(v) for v in value.split(",")]
            except ValueError:
                raise click.BadParameter(f"{item!r}: value must be numbers separated by commas",
                                         param_hint="--set") from None
            parsed[key] = nums[0] if len(nums) == 1 else nums
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
        sys.exit(3)


if __name__ == "__main__":
    main()


@main.command()
@click.option("--controllers", default="rac,rac_dob", show_default=True,
              help="Comma-separated controller names to run (registered: see --list).")
@click.option("--duration", type=click.FloatRange(min=0, min_open=True), default=40.0, show_default=True,
              help="Simulated time [s].")
@click.option("--thruster-lag", type=click.FloatRange(min=0, min_open=True), default=None,
              help="Plant thruster time constant [s] (default: the model's 0.02 s).")
@click.option("--ideal", is_flag=True, help="Plant identical to the nominal model (no modelling error).")
@click.option("--list", "list_only", is_flag=True, help="List the registered controllers and exit.")
def paper(controllers: str, duration: float, thruster_lag: float | None, ideal: bool, list_only: bool) -> None:
    """Run the paper's experiment with each controller and print RMS / max errors side by side."""
    from .controllers import ControllerError, available
    from .experiment import PaperExperiment, metrics

    if list_only:
        click.echo("\n".join(available()))
        return
    names = [c.strip() for c in controllers.split(",") if c.strip()]
    unknown = [c for c in names if c not in available()]
    if unknown:
        raise click.BadParameter(f"unknown controller(s) {', '.join(unknown)}; registered: {', '.join(available())}",
                                 param_hint="--controllers")
    over = {} if thruster_lag is None else {"thrusters.tau": thruster_lag}
    results = {}
    status = 0
    for name in names:
        try:
            res = PaperExperiment(controller=name, duration=duration, truth=not ideal, plant_overrides=over).run()
        except (ControllerError, ParameterError, ValueError) as exc:
            raise click.UsageError(str(exc)) from None
        if res.status != "ok":
            click.echo(f"{name}: {res.reason}", err=True)
            status = 3
        results[name] = metrics(res)
    labels = {
        "base_pos_rms_mm": "base position RMS [mm]", "base_pos_max_mm": "base position max [mm]",
        "base_att_rms_mrad": "base attitude RMS [mrad]", "base_att_max_mrad": "base attitude max [mrad]",
        "tip_rms_mm": "end tip RMS [mm]", "tip_max_mm": "end tip max [mm]", "thrust_rms_N": "thrust RMS [N]",
        "torque_rms_Nm": "joint torque RMS [N m]", "saturated_s": "thrusters saturated [s]",
    }
    ratio = len(names) == 2
    click.echo(f"{'metric':<28}" + "".join(f"{n:>12}" for n in names) + (f"{'ratio':>9}" if ratio else ""))
    for key, label in labels.items():
        vals = [results[n][key] for n in names]
        line = f"{label:<28}" + "".join(f"{v:>12.4g}" for v in vals)
        if ratio:
            line += f"{(vals[1] / vals[0] if vals[0] else float('nan')):>9.2f}"
        click.echo(line)
    sys.exit(status)
