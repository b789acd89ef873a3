"""``uvms-mj sweep``: parameter sweeps (:mod:`uvms_mj.analysis.sweep`)."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from uvms_mj.cli.common import EXIT_INTERRUPTED, SCENARIO, _check_dir, _check_out, _io_error


@click.command()
@click.argument("scenario", type=SCENARIO)
@click.option("--vary", "varies", multiple=True, required=True, metavar="KEY.PATH=SPEC",
              help="A field and its values (repeat for more axes), e.g. --vary 'plant.current[0]=uniform(0, 0.1)'.")
@click.option("--n", "n", type=click.IntRange(min=1), default=None,
              help="Samples (at each grid point): required with random specs; with grids only, repeats "
                   "(default 1).")
@click.option("--workers", type=click.IntRange(min=1), default=None, help="Parallel runs (default: the CPUs).")
@click.option("--engine", type=click.Choice(["process", "ray", "serial"]), default="process", show_default=True,
              help="process: local process pool; ray: Ray tasks (pip install 'uvms-mj[ray]'); serial: here.")
@click.option("--controllers", default="rac,rac_dob", show_default=True,
              help="Comma-separated controllers; every sample runs with each (same parameters and seed).")
@click.option("--seed", type=click.IntRange(min=0, max=2**63 - 1), default=0, show_default=True,
              help="Sweep seed: sampled parameters and per-run seeds derive from it.")
@click.option("--set", "sets", multiple=True, metavar="KEY.PATH=VALUE",
              help="Override a scenario field for every run, e.g. --set duration=10.")
@click.option("--out-dir", "out_dir", type=click.Path(file_okay=False), default=None,
              help="Output folder (default: logs/<name>-sweep).")
@click.option("--out", "out_dir_old", type=click.Path(file_okay=False), default=None, hidden=True)
@click.option("--logs/--no-logs", default=False, show_default=True,
              help="Write an MCAP log per run (about 1.8 MB and +50 % time per 40 s run).")
@click.option("--fresh", is_flag=True, help="Delete the results of a different sweep in --out-dir instead of refusing.")
def sweep(scenario: str, varies: tuple[str, ...], n: int | None, workers: int | None, engine: str,
          controllers: str, seed: int, sets: tuple[str, ...], out_dir: str | None, out_dir_old: str | None,
          logs: bool, fresh: bool) -> None:
    """Run SCENARIO over sampled parameters, in parallel; write a results table (CSV, one row per
    run), summary figures and the paired ratio of each controller to the first.

    \b
    SPEC (KEY.PATH: any scenario field, checked against the schema):
      [0, 0.05, 0.1]             grid values (a vector field: a list per value)
      linspace(0, 0.1, 5)        grid, ends included
      uniform(0, 0.1)            random (also loguniform(lo, hi), normal(mean, std),
                                 choice(a, b, ...))
      scale(uniform(0.7, 1.3))   a factor on the field's value in the scenario (for an
                                 override not in the file: the model's value)
      KEY[i]=SPEC                one component of a vector: plant.current[0]=uniform(0, 0.1)
      [uniform(0, 0.1), 0]       a vector given per component
      'a.{b,c}.d=SPEC'           several fields, one shared value (quote it in the shell)

    \b
    Samples: the Cartesian product of the grid specs, times N (--n) at each grid point, with
    fresh random draws and seeds (random specs need --n). Sample i draws from
    SeedSequence(--seed).spawn()[i]: the same arguments give the same parameters and seeds.

    \b
    Example (the observer's benefit under current and added-mass error):
      uvms-mj sweep scenarios/paper.yaml --n 50 \\
        --vary 'plant.current[0]=uniform(0, 0.1)' \\
        --vary 'nominal.overrides.{base,link1,link2}.added_mass=scale(uniform(0.7, 1.3))'

    \b
    Outputs in --out-dir: results.csv (run_id, sample, controller, seed, the drawn values, metrics,
    status, reason, t_end, wall_s, log, values, sets, key), summary.json, sweep_metrics.png,
    sweep_ratio.png, runs.jsonl and sweep.json (resume record and definition), logs/ (--logs).
    Rerunning the same command skips finished runs; a different sweep in the same --out-dir is
    refused (or deleted with --fresh). A run that diverges or raises is recorded with its
    status and reason and never stops the sweep. Exit codes: 0 done (failed runs included),
    2 bad input (before any run), 130 interrupted (finished runs kept: rerun to resume).
    """
    from uvms_mj.io.recorder import handle_sigterm
    from uvms_mj.analysis.sweep import SweepError, check_engine, format_summary, plan_sweep, run_sweep

    try:
        check_engine(engine)
        plan = plan_sweep(scenario, list(varies), n=n, seed=seed, controllers=controllers.split(","), sets=sets)
    except SweepError as exc:
        raise click.UsageError(str(exc)) from None
    out_dir = out_dir or out_dir_old
    out = _check_dir(Path(out_dir) if out_dir else Path("logs") / f"{plan.name}-sweep")
    from uvms_mj.analysis.sweep.runner import _OUR_FILES

    for name in _OUR_FILES:  # the scenario file is never one of the sweep's outputs
        _check_out(out / name, protect=(scenario,), kind="sweep output", option="--out-dir")
    n_samples = len(plan.samples)
    click.echo(f"sweep: {len(plan.runs)} runs ({n_samples} samples x {len(plan.controllers)} controllers: "
               f"{', '.join(plan.controllers)}) -> {out}")
    bar = None

    def on_run(row: dict, k: int, total: int) -> None:
        nonlocal bar
        if bar is None:
            from tqdm import tqdm

            bar = tqdm(total=total, desc="sweep", unit="run", leave=False, disable=None)
        bar.update(1)
        if row["status"] != "ok":
            bar.write(f"{row['run_id']}: {row['status']}: {row['reason']}")

    try:
        with handle_sigterm():
            outcome = run_sweep(plan, out, workers=workers, engine=engine, logs=logs, fresh=fresh, on_run=on_run)
    except SweepError as exc:
        raise click.UsageError(str(exc)) from None
    except OSError as exc:
        _io_error(getattr(exc, "filename", None) or out, exc)
    except KeyboardInterrupt:
        if bar is not None:
            bar.close()
        click.echo(f"interrupted; finished runs are kept in {out / 'results.csv'}: rerun the same command to resume",
                   err=True)
        sys.exit(EXIT_INTERRUPTED)
    if bar is not None:
        bar.close()
    if outcome.skipped:
        click.echo(f"resumed: {outcome.skipped} of {outcome.planned} runs already done, skipped")
    if outcome.ran:
        click.echo(f"ran {outcome.ran} runs in {outcome.elapsed_s:.1f} s ({outcome.runs_per_s:.2f} runs/s, "
                   f"{outcome.summary['workers']} workers, engine {engine})")
    click.echo(format_summary(outcome.summary))
    for p in outcome.tables:
        click.echo(f"table: {p}")
    for p in outcome.figures:
        click.echo(f"figure: {p}")
