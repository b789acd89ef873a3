"""``uvms-mj sim2real`` and ``uvms-mj identify``: the model against recorded pool trials
(:mod:`uvms_mj.analysis.sim2real`, :mod:`uvms_mj.analysis.identify`).

Exit codes as the rest of ``uvms-mj``: 0 success (bad trials are skipped and named, the others
still run), 2 bad input (no such folder, no usable trial, a bad override file, unknown trial or
parameter names), 5 an output could not be written.
"""

from __future__ import annotations

import math
import sys
from dataclasses import asdict
from pathlib import Path

import click

from uvms_mj.cli.common import _check_dir, _check_out, _io_error, _json_dest, _write_json

_JSON_HELP = "Also write the results as JSON: '-' for stdout (the table then goes to stderr), or a file path."


def _names(value: str | None) -> list[str] | None:
    if value is None:
        return None
    out = [v.strip() for v in value.split(",") if v.strip()]
    return out or None


def default_data_dir() -> Path | None:
    """The pool trials shipped in the repository (``data/hinsdale-2023``): next to the package's
    checkout (an editable install: ``src/uvms_mj`` -> the repository root), else under the current
    folder; None when neither holds them (a wheel install: the data are not in the wheel)."""
    pkg = Path(__file__).resolve().parents[1]  # the uvms_mj package folder
    for root in (pkg.parents[1], Path.cwd()):
        cand = root / "data" / "hinsdale-2023"
        if (cand / "trials").is_dir():
            return cand
    return None


def _trial_dir(path: str | None) -> Path:
    if path is None:
        found = default_data_dir()
        if found is None:
            click.echo("error: no DATA_DIR given and data/hinsdale-2023 not found (in the package's checkout or "
                       "the current folder): pass DATA_DIR, a folder of trials", err=True)
            sys.exit(2)
        path = str(found)
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise click.UsageError(f"data folder {path!r} is a file: give the folder that holds the trials' CSV files "
                               f"(here: {str(p.parent)!r})")
    if not p.is_dir():
        raise click.UsageError(f"data folder {path!r} does not exist")
    sub = p / "trials"
    if sub.is_dir() and not any(p.glob("*_imu.csv")):
        return sub
    return p


def _load(data_dir: str, model: str, overrides: str | None, names, neutral: bool = True, echo=click.echo):
    """(compiled model, override dict, TrialSet); issues reported (errors on stderr)."""
    from uvms_mj.physics import ModelError
    from uvms_mj.analysis.sim2real import OverrideError, build_model, load_overrides, model_path
    from uvms_mj.analysis.trials import load_trials
    from uvms_mj.io.paths import InputFileError, check_input_file

    folder = _trial_dir(data_dir)
    mp = model_path(model)
    if mp.exists() and not mp.is_file():
        raise click.UsageError(f"--model: {mp}: not a regular file; give an MJCF file or a name in models/")
    if not mp.is_file():
        raise click.UsageError(f"--model: no model {model!r} (a file, or a name in models/: {model_path(model)})")
    try:
        if overrides:  # a FIFO or /dev/zero would block or never end
            check_input_file(overrides, "an overrides file (YAML)", max_bytes=1_000_000)
        over = load_overrides(overrides) if overrides else {}
    except InputFileError as exc:
        raise click.UsageError(f"--overrides: {exc}") from None
    except OverrideError as exc:
        raise click.UsageError(str(exc)) from None
    try:
        m = build_model(model, over, neutral=neutral)
    except (OverrideError, ModelError) as exc:
        raise click.UsageError(str(exc)) from None
    try:
        ts = load_trials(folder, model=m, names=names)
    except (FileNotFoundError, KeyError, ValueError) as exc:
        raise click.UsageError(str(exc).strip("'\"")) from None
    def why(name):
        return "; ".join((f"{i.file.name}{'' if i.line is None else f':{i.line}'}: " if i.file else "") + i.message
                         for i in ts.skipped[name])

    if not len(ts):  # exit 2 with one line: every trial and why it was skipped
        raise click.UsageError(f"no usable trial in {folder}" + (": " + "; ".join(
            f"{n} skipped ({why(n)})" for n in ts.skipped) if ts.skipped else ""))
    for issue in ts.issues:
        if issue.severity == "error":
            click.echo(str(issue), err=True)
    warns = [i for i in ts.issues if i.severity != "error"]
    if warns:
        # the ones that change what is used (a file cut short, a dropped mocap, an unknown start,
        # records of different lengths) by name; the routine ones (mocap gaps) counted
        named = [i for i in warns if not i.message.startswith("gap of") and "no metadata file" not in i.message]
        for i in named[:10]:
            echo(str(i))
        rest = len(warns) - min(len(named), 10)
        if rest:
            echo(f"{rest} other warning(s) while reading (mocap gaps, missing metadata...; listed in the JSON)")
    for name in ts.skipped:
        click.echo(f"skipped trial {name}: {why(name)}", err=True)
    return m, over, ts


def _inputs(data_dir: str | None, overrides: str | None) -> tuple:
    """The files a command reads (never overwritten): the trial folder's files and the overrides file."""
    folder = _trial_dir(data_dir)
    files = [p for p in sorted(folder.iterdir()) if p.is_file()] if folder.is_dir() else []
    return (*files, overrides)


def _issues_json(ts) -> dict:
    return {
        "skipped": {n: [str(i) for i in v] for n, v in ts.skipped.items()},
        "issues": [{"trial": i.trial, "file": None if i.file is None else str(i.file), "line": i.line,
                    "message": i.message, "severity": i.severity} for i in ts.issues],
    }


def _fmt(x, spec=".2f") -> str:
    return "-" if x is None or (isinstance(x, float) and not math.isfinite(x)) else format(x, spec)


def scores_table(scores: dict, title: str = "") -> tuple[str, dict]:
    """Plain-text per-trial table (degrees, seconds) and the means."""
    h = (f"{'trial':<11} {'RMS roll':>8} {'RMS pitch':>9} {'lag [s]':>7} {'roll@lag':>8} {'pitch@lag':>9}"
         f" {'d_roll err':>10} {'d_pitch err':>11} {'track':>6}")
    out = ([title] if title else []) + [h, "-" * len(h)]
    for n in sorted(scores):
        s = scores[n]
        ch = s.changes
        dr = max((c["err"][0] for c in ch), key=abs) if ch else None
        dp = max((c["err"][1] for c in ch), key=abs) if ch else None
        out.append(f"{n:<11} {s.rms_roll:8.2f} {s.rms_pitch:9.2f} {_fmt(s.lag, '7.2f'):>7} {s.rms_roll_lag:8.2f}"
                   f" {s.rms_pitch_lag:9.2f} {_fmt(dr, '10.2f'):>10} {_fmt(dp, '11.2f'):>11} {s.tracking_deg:6.3f}")
    rows = list(scores.values())
    lags = [abs(s.lag) for s in rows if s.lag is not None]
    chs = [c["err"] for s in rows for c in s.changes]
    mean = {
        "n": len(rows),
        "rms_roll": sum(s.rms_roll for s in rows) / len(rows),
        "rms_pitch": sum(s.rms_pitch for s in rows) / len(rows),
        "rms_roll_lag": sum(s.rms_roll_lag for s in rows) / len(rows),
        "rms_pitch_lag": sum(s.rms_pitch_lag for s in rows) / len(rows),
        "max_rms": max(max(s.rms_roll, s.rms_pitch) for s in rows),
        "mean_abs_lag": sum(lags) / len(lags) if lags else None,
        "max_abs_lag": max(lags) if lags else None,
        "rms_change_err_roll": math.sqrt(sum(c[0] ** 2 for c in chs) / len(chs)) if chs else None,
        "rms_change_err_pitch": math.sqrt(sum(c[1] ** 2 for c in chs) / len(chs)) if chs else None,
        "max_tracking_deg": max(s.tracking_deg for s in rows),
    }
    out.append("-" * len(h))
    out.append(f"{'mean':<11} {mean['rms_roll']:8.2f} {mean['rms_pitch']:9.2f} {_fmt(mean['mean_abs_lag'], '7.2f'):>7}"
               f" {mean['rms_roll_lag']:8.2f} {mean['rms_pitch_lag']:9.2f} {_fmt(mean['rms_change_err_roll'], '10.2f'):>10}"
               f" {_fmt(mean['rms_change_err_pitch'], '11.2f'):>11} {mean['max_tracking_deg']:6.3f}")
    out.append("(degrees; lag: the best constant lag of the IMU behind the simulation within +-2 s, '-' for a still "
               "arm; roll/pitch@lag: RMS after removing it;\n d_* err: simulated - measured settled attitude change "
               "over an arm move (the largest); track: max arm tracking error;\n mean row: means over the trials, "
               "lag: mean |lag|, d_* err: RMS over all moves, track: the max)")
    return "\n".join(out), mean


def _static(m, ts, echo) -> dict | None:
    from uvms_mj.analysis.hydrostatics import static_check

    try:
        sc = static_check(m, ts)
    except (RuntimeError, ValueError) as exc:
        echo(f"static check failed: {exc}")
        return None
    echo("Static check (hydrostatic equilibrium at the first and last arm pose vs the mean IMU attitude "
         "before the motion and over the last 2 s):")
    echo(sc.table())
    echo("")
    return {"rows": [asdict(r) for r in sc.rows], "summary": asdict(sc.summary), "skipped": sc.skipped}


def _write(json_out, data) -> None:
    try:
        _write_json(data, json_out)
    except OSError as exc:
        _io_error(json_out, exc)


def _cfg(dt: float | None, neutral: bool):
    from uvms_mj.analysis.sim2real import SimConfig

    if dt is not None and not (1e-5 <= dt <= 0.05):  # 1e-5 s: the scenarios' smallest physics.timestep
        raise click.UsageError(f"--dt must lie in [1e-05, 0.05] s, got {dt}")
    return SimConfig(dt=dt, neutral=neutral)


@click.command()
@click.argument("data_dir", type=click.Path(), required=False)
@click.option("--trials", "trial_names", default=None, metavar="A,B,...", help="Comma-separated trial names (default: all).")
@click.option("--model", default="hinsdale2023", show_default=True, help="Model name in models/ or an MJCF file.")
@click.option("--overrides", default=None, type=click.Path(), metavar="FILE",
              help="Parameter override file (YAML 'BODY.ATTRIBUTE: value', e.g. from uvms-mj identify).")
@click.option("--json", "json_out", metavar="PATH|-", default=None, help=_JSON_HELP)
@click.option("--plots", "plots_dir", type=click.Path(file_okay=False), default=None,
              help="Folder for one PNG per trial (measured vs simulated roll and pitch).")
@click.option("--dt", type=float, default=None, help="Physics step [s] (default: the model's, 0.002 s).")
@click.option("--as-is", "as_is", is_flag=True, default=False,
              help="Keep the model's mass as written (default: made neutrally buoyant through the vehicle mass).")
@click.option("--jobs", type=click.IntRange(min=1), default=None, help="Worker processes (default: min(2, CPUs)).")
@click.option("--plot-nominal", is_flag=True, default=False,
              help="With --overrides and --plots: also draw the model without the overrides (dashed).")
def sim2real(data_dir, trial_names, model, overrides, json_out, plots_dir, dt, as_is, jobs, plot_nominal) -> None:
    """Replay the pool trials of DATA_DIR in the model (arm motion imposed, thrusters off, measured
    initial attitude and velocity) and compare simulated roll and pitch with the IMU.

    DATA_DIR defaults to the trials shipped in a checkout, data/hinsdale-2023."""
    from uvms_mj.analysis.identify import run_trials
    from uvms_mj.analysis.sim2real import MAX_TRACKING_ERROR_DEG, plot_trial

    echo = _json_dest(json_out == "-")
    cfg = _cfg(dt, not as_is)
    inputs = _inputs(data_dir, overrides)
    if json_out and json_out != "-":
        _check_out(json_out, protect=inputs, kind="JSON file", option="--json")
    plots = None
    if plots_dir is not None:
        plots = _check_dir(plots_dir, option="--plots")
    m, over, ts = _load(data_dir, model, overrides, _names(trial_names), cfg.neutral, echo)
    if plots is not None:
        for n in ts.trials:
            _check_out(plots / f"sim2real_{n}.png", protect=(*inputs, json_out), kind="plot", option="--plots")
    static = _static(m, ts, echo)
    try:
        res = run_trials(list(ts), model, over, cfg, jobs)
    except RuntimeError as exc:
        click.echo(f"error: {exc}", err=True)
        sys.exit(1)
    scores = {n: v[1] for n, v in res.items()}
    table, mean = scores_table(scores, "Dynamic replay (simulated - IMU roll and pitch at the IMU time stamps):")
    echo(table)
    if ts.skipped:
        echo(f"skipped (bad data): {', '.join(sorted(ts.skipped))}")
    bad = [n for n, s in scores.items() if not s.tracking_deg < MAX_TRACKING_ERROR_DEG]
    if bad:
        click.echo(f"warning: arm tracking error >= {MAX_TRACKING_ERROR_DEG} deg in {', '.join(bad)}", err=True)
    if plots is not None:
        try:
            plots.mkdir(parents=True, exist_ok=True)
            nominal = run_trials(list(ts), model, {}, cfg, jobs) if (plot_nominal and over) else {}
            for n, (sim, sc) in sorted(res.items()):
                others = [(f"nominal model (RMS {nominal[n][1].rms_roll:.2f} / {nominal[n][1].rms_pitch:.2f} deg)",
                           nominal[n][0])] if n in nominal else []
                plot_trial(ts[n], sim, sc, plots / f"sim2real_{n}.png", label="with overrides" if over else "simulated",
                           others=others)
        except OSError as exc:
            _io_error(plots, exc)
        echo(f"plots: {plots}")
    if json_out:
        _write(json_out, {"model": str(model), "overrides": over, "config": asdict(cfg), "static_check": static,
                          "trials": {n: s.to_json() for n, s in sorted(scores.items())}, "mean": mean,
                          **_issues_json(ts)})


@click.command("identify")
@click.argument("data_dir", type=click.Path(), required=False)
@click.option("--fit", "fit_names", default=None, metavar="A,B,...", help="Trials to fit on.")
@click.option("--score", "score_names", default=None, metavar="C,D,...",
              help="Trials to score (default: every other trial that loads; never a fit trial).")
@click.option("--cv", "cv", type=int, default=None, metavar="K",
              help="K-fold cross-validation instead of --fit/--score: each fold scored by a fit on the others.")
@click.option("--trials", "trial_names", default=None, metavar="A,B,...", help="Restrict to these trials (with --cv).")
@click.option("--params", "param_names", default=None, metavar="P,Q,...",
              help="Parameters to fit (default: cob_x,cob_y,cob_z,roll_damping,pitch_damping).")
@click.option("--model", default="hinsdale2023", show_default=True, help="Model name in models/ or an MJCF file.")
@click.option("--overrides", default=None, type=click.Path(), metavar="FILE", help="Start from these overrides.")
@click.option("-o", "--out", "out", type=click.Path(dir_okay=False), default="identified.yaml", show_default=True,
              help="Override file to write (with --cv: one per fold, OUT with .foldK before the suffix).")
@click.option("--json", "json_out", metavar="PATH|-", default=None, help=_JSON_HELP)
@click.option("--fit-dt", type=float, default=None, help="Physics step of the fit [s] (default 0.01).")
@click.option("--max-nfev", type=int, default=30, show_default=True, help="Most optimiser evaluations per fit.")
@click.option("--jobs", type=click.IntRange(min=1), default=None, help="Worker processes (default: min(2, CPUs)).")
@click.option("--quiet", is_flag=True, default=False, help="No progress lines.")
def identify_cmd(data_dir, fit_names, score_names, cv, trial_names, param_names, model, overrides, out, json_out, fit_dt,
             max_nfev, jobs, quiet) -> None:
    """Fit uncertain model parameters to the roll and pitch of chosen trials (bounded least squares)
    and report the error on other trials; write the identified values as an override file.

    DATA_DIR defaults to the trials shipped in a checkout, data/hinsdale-2023."""
    from uvms_mj.analysis.identify import (
        DEFAULT_FIT_DT,
        DEFAULT_PARAMS,
        PARAMETERS,
        folds,
        identify as run_identify,
        write_overrides,
    )
    from uvms_mj.analysis.sim2real import SimConfig

    echo = _json_dest(json_out == "-")
    names = _names(param_names) or list(DEFAULT_PARAMS)
    unknown = [p for p in names if p not in PARAMETERS]
    if unknown:
        raise click.UsageError(f"--params: unknown parameter(s) {', '.join(unknown)} (known: {', '.join(PARAMETERS)})")
    if fit_dt is not None and not (1e-5 <= fit_dt <= 0.05):
        raise click.UsageError(f"--fit-dt must lie in [1e-05, 0.05] s, got {fit_dt}")
    if max_nfev < 1:
        raise click.UsageError(f"--max-nfev must be >= 1, got {max_nfev}")
    if cv is None and not fit_names:
        raise click.UsageError("give --fit TRIALS (and optionally --score), or --cv K")
    if cv is not None and (fit_names or score_names):
        raise click.UsageError("--cv replaces --fit/--score: give one or the other")
    import os

    parent = Path(out).resolve().parent
    if not parent.is_dir() or not os.access(parent, os.W_OK) or Path(out).is_dir():
        raise click.UsageError(f"-o/--out: cannot write {out} (its folder does not exist or is not writable)")
    inputs = _inputs(data_dir, overrides)
    outp = Path(out)
    dests = [outp] if cv is None else [outp.with_name(f"{outp.stem}.fold{k}{outp.suffix or '.yaml'}")
                                       for k in range(1, min(max(cv, 1), 1000) + 1)]
    for dest in dests:
        _check_out(dest, protect=inputs, kind="override file", option="-o/--out")
    if json_out and json_out != "-":
        _check_out(json_out, protect=(*inputs, *dests), kind="JSON file", option="--json")
    fit = _names(fit_names) or []
    score = _names(score_names)
    wanted = _names(trial_names) if cv is not None else (fit + score if score else None)
    m, base, ts = _load(data_dir, model, overrides, wanted, True, echo)
    missing = [n for n in fit if n not in ts.trials]
    if missing:
        raise click.UsageError(f"--fit: trial(s) {', '.join(missing)} not usable (skipped or absent)")
    missing = [n for n in (score or []) if n not in ts.trials]
    if missing:
        raise click.UsageError(f"--score: trial(s) {', '.join(missing)} not usable (skipped or absent)")
    if cv is None:
        score = [n for n in (score or sorted(ts.trials)) if n in ts.trials and n not in fit]
        overlap = sorted(set(fit) & set(_names(score_names) or []))
        if overlap:
            raise click.UsageError(f"--score: trial(s) {', '.join(overlap)} also in --fit: the score would not be a prediction")
        plan = [(fit, score)]
    else:
        try:
            parts = folds(list(ts.trials), cv)
        except ValueError as exc:
            raise click.UsageError(f"--cv: {exc}") from None
        plan = [([n for j, p in enumerate(parts) if j != i for n in p], part) for i, part in enumerate(parts)]
    say = None if quiet else (lambda s: click.echo(s, err=True))
    results, written = [], []
    for k, (f, s) in enumerate(plan, 1):
        echo(f"fit on {', '.join(f)}; score on {', '.join(s) or '(none)'}")
        try:
            r = run_identify(ts.trials, fit=f, score=s, names=names, model=model, base=base, cfg=SimConfig(),
                             fit_dt=fit_dt or DEFAULT_FIT_DT, max_nfev=max_nfev, jobs=jobs, progress=say)
        except (ValueError, RuntimeError) as exc:
            click.echo(f"error: {exc}", err=True)
            sys.exit(1)
        results.append(r)
        echo(param_table(r))
        dest = outp if cv is None else outp.with_name(f"{outp.stem}.fold{k}{outp.suffix or '.yaml'}")
        header = (f"uvms-mj identify: parameters {', '.join(names)} fitted on {', '.join(f)}\n"
                  f"(model {model}; score trials {', '.join(s) or 'none'}). Format: BODY.ATTRIBUTE: value (SI).\n"
                  + "\n".join(f"{n} = {v:.6g} +- {sd:.2g} {u} (nominal {nom:.6g})"
                              for n, v, sd, u, nom in zip(r.names, r.value, r.std, r.units, r.nominal)))
        try:
            write_overrides(dest, r.overrides, header)
        except OSError as exc:
            _io_error(dest, exc)
        written.append(str(dest))
        echo(f"overrides: {dest}")
    fit_sc = {n: r.after[n] for r in results for n in r.fit}
    held = {n: r.after[n] for r in results for n in r.score}
    held0 = {n: r.before[n] for r in results for n in r.score}
    mean = mean0 = None
    if held:
        t0, mean0 = scores_table(held0, "Score trials, nominal model:")
        echo(t0)
        t1, mean = scores_table(held, "Score trials, identified parameters (fitted on other trials):")
        echo(t1)
    if json_out:
        _write(json_out, {"model": str(model), "params": names, "folds": [r.to_json() for r in results],
                          "overrides_files": written,
                          "score_before": {n: s.to_json() for n, s in sorted(held0.items())},
                          "score_after": {n: s.to_json() for n, s in sorted(held.items())},
                          "mean_before": mean0, "mean_after": mean,
                          "fit_after": {n: s.to_json() for n, s in sorted(fit_sc.items())} if cv is None else None,
                          **_issues_json(ts)})


def param_table(r) -> str:
    """The identified values, their standard deviations and the fit error before / after."""
    h = f"  {'parameter':<18} {'nominal':>10} {'identified':>11} {'std':>9}  unit"
    out = [h]
    for n, nom, v, sd, u in zip(r.names, r.nominal, r.value, r.std, r.units):
        out.append(f"  {n:<18} {nom:10.5g} {v:11.5g} {sd:9.2g}  {u}")
    out.append(f"  fit RMS (roll and pitch pooled): {r.cost0:.3f} -> {r.cost:.3f} deg  ({r.nfev} evaluations; "
               f"uncertainty inflated x{math.sqrt(r.n_eff_factor):.1f} for correlated residuals)")
    return "\n".join(out)
