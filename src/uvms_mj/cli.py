"""The ``uvms-mj`` command line.

For now one command, ``drift``: the default plant (paper's initial pose, all hydrodynamics on)
left to itself, its state printed every second. Scenario, run, compare, render and plot
commands come with the controller and testbed issues.
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
