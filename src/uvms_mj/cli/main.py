"""The ``uvms-mj`` command line.

Commands: ``run``, ``compare``, ``render``, ``plot``, ``validate``, ``info``, ``export``
(scenario files and logs), ``sweep`` (parameter sweeps, :mod:`uvms_mj.analysis.sweep`), ``paper`` (the
paper's experiment without a scenario file), ``drift`` (the plant left to itself) and ``view`` (a
model file in MuJoCo's interactive viewer, in water).

Output options: ``-o/--out PATH`` names an output file, ``--out-dir DIR`` an output folder
(the older spellings ``--output``, ``compare/sweep --out DIR`` and ``plot -o DIR`` still work,
hidden). SCENARIO arguments are a file, or the name of a scenario shipped with the package
(``paper``, ``current``...: see ``uvms-mj validate --list``) when no such file exists.

Exit codes: 0 success; 1 unexpected error (a run that raised: its log is closed with status
"error" and the reason); 2 bad input (usage, scenario, parameters, an
output path that cannot or must not be written, a log that another run is writing, an
unreadable log); 3 a run diverged (the log is still written, with the reason); 4 rendering
unavailable (missing GL libraries); 5 an output could not be written (I/O error such as a full
disk; the message names the file); 130 interrupted (Ctrl-C or SIGTERM; the log is closed cleanly).
"""

from __future__ import annotations

import os
import signal
import sys
from pathlib import Path


def _exit_130(*_) -> None:
    """SIGINT: exit 130 at once, quietly (no KeyboardInterrupt traceback, none swallowed by an
    import lock's callback)."""
    sys.stderr.write("interrupted\n")
    os._exit(130)


if __name__ == "__main__" or (sys.argv and os.path.basename(sys.argv[0]) == "uvms-mj"):
    # The command line's own process starting up (never a module that imports this one): a Ctrl-C
    # during its imports exits 130 quietly, and without a display MUJOCO_GL is set to a headless
    # backend before mujoco is imported (no GLFW probe; its children, e.g. sweep workers, inherit it).
    signal.signal(signal.SIGINT, _exit_130)
    from uvms_mj.analysis.render_gl import configure_gl

    configure_gl()

import click
import numpy as np

from uvms_mj import __version__
from uvms_mj.planar.hydro import HydroTerms
from uvms_mj.plant.params import ParameterError
from uvms_mj.plant.plant import DivergenceError, Plant

EXIT_DIVERGED = 3
EXIT_RENDER = 4
EXIT_IO = 5
EXIT_INTERRUPTED = 130

METRIC_LABELS = {
    "base_pos_rms_mm": "base position RMS [mm]",
    "base_pos_max_mm": "base position max [mm]",
    "base_att_rms_mrad": "base attitude RMS [mrad]",
    "base_att_max_mrad": "base attitude max [mrad]",
    "tip_rms_mm": "end tip RMS [mm]",
    "tip_max_mm": "end tip max [mm]",
    "thrust_rms_N": "thrust RMS [N]",
    "torque_rms_Nm": "joint torque RMS [N m]",
    "saturated_s": "thrusters saturated [s]",
    "joint_rms_mrad": "arm joints RMS [mrad]",
}
#: Rows shown only when some run has a value (floating-robot metrics).
_OPTIONAL_ROWS = ("joint_rms_mrad",)


def metrics_table(results: dict[str, dict[str, float]], status: dict[str, str] | None = None) -> str:
    """Side-by-side metrics; with two columns, the ratio second / first; with ``status``
    (controller -> "ok", "diverged"...), a status row first."""
    names = list(results)
    ratio = len(names) == 2
    lines = [f"{'metric':<28}" + "".join(f"{n:>12}" for n in names) + (f"{'ratio':>9}" if ratio else "")]
    if status is not None:
        lines.append(f"{'status':<28}" + "".join(f"{status.get(n, '?'):>12}" for n in names))
    for key, label in METRIC_LABELS.items():
        vals = [results[n].get(key, float("nan")) for n in names]
        if key in _OPTIONAL_ROWS and all(v != v for v in vals):
            continue
        line = f"{label:<28}" + "".join(f"{v:>12.4g}" for v in vals)
        if ratio:
            line += f"{(vals[1] / vals[0]) if vals[0] else float('nan'):>9.2f}"
        lines.append(line)
    return "\n".join(lines)


class _Group(click.Group):
    """Ctrl-C anywhere exits with 130, not click's "Aborted!" with 1: while the command runs a
    SIGINT handler exits 130 at once, quietly (:func:`_exit_130`, restored when it returns; the
    installed command's process has it from its start); runs and sweeps replace it with
    :func:`uvms_mj.io.recorder.handle_sigterm`, which closes the log first. A bad
    ``UVMS_MJ_COMPILED`` (or a former switch set) is one line and exit 2."""

    def main(self, *args, **kwargs):  # noqa: ANN002, ANN003
        try:
            old = signal.signal(signal.SIGINT, _exit_130)
        except ValueError:  # not the main thread: signals are not ours to handle
            return super().main(*args, **kwargs)
        try:
            return super().main(*args, **kwargs)
        finally:
            signal.signal(signal.SIGINT, old)

    def make_context(self, *args, **kwargs):  # noqa: ANN002, ANN003
        try:
            return super().make_context(*args, **kwargs)
        except KeyboardInterrupt:
            _interrupted()

    def invoke(self, ctx):  # noqa: ANN001
        from uvms_mj.physics.build import CompiledModeError, compiled_mode

        try:
            compiled_mode()
        except CompiledModeError as exc:
            click.echo(f"error: {exc}", err=True)
            sys.exit(2)
        try:
            return super().invoke(ctx)
        except KeyboardInterrupt:
            _interrupted()


def _interrupted() -> None:
    click.echo("interrupted", err=True)
    sys.exit(EXIT_INTERRUPTED)


def _io_error(path, exc: OSError) -> None:
    """An output that could not be written: one line, exit EXIT_IO."""
    click.echo(f"error: cannot write {path}: {exc.strerror or exc}", err=True)
    sys.exit(EXIT_IO)


def _check_out(path, protect: tuple = (), kind: str = "log", magic: bytes | None = b"\x89MCAP") -> Path:
    from uvms_mj.io.recorder import OutputPathError, check_output_path

    try:
        return check_output_path(path, protect=protect, kind=kind, magic=magic)
    except OutputPathError as exc:
        raise click.UsageError(str(exc)) from None


def _check_dir(path) -> Path:
    from uvms_mj.io.recorder import OutputPathError, check_output_dir

    try:
        return check_output_dir(path)
    except OutputPathError as exc:
        raise click.UsageError(str(exc)) from None


def _warn(scenario) -> None:
    from uvms_mj.scenario.schema import scenario_warnings

    for w in scenario_warnings(scenario):
        click.echo(f"warning: {w}", err=True)


def _json_metrics(runs: dict[str, dict], scenario: str) -> dict:
    """The machine-readable result of run/compare (see ``--json``)."""
    out: dict = {"scenario": scenario, "runs": runs}
    names = list(runs)
    if len(names) == 2:
        a, b = (runs[n]["metrics"] for n in names)
        out["ratio"] = {"of": names[1], "to": names[0],
                        "metrics": {k: (b[k] / a[k] if a.get(k) else None) for k in METRIC_LABELS if k in a and k in b}}
    return out


def _write_json(data: dict, dest: str) -> None:
    """JSON to stdout ("-") or to a file; NaN and infinities become null."""
    import json
    import math

    def clean(x):
        if isinstance(x, float) and not math.isfinite(x):
            return None
        if isinstance(x, dict):
            return {k: clean(v) for k, v in x.items()}
        if isinstance(x, (list, tuple)):
            return [clean(v) for v in x]
        if isinstance(x, np.generic):
            return clean(x.item())
        return x

    text = json.dumps(clean(data), indent=2, allow_nan=False)
    if dest == "-":
        click.echo(text)
    else:
        Path(dest).parent.mkdir(parents=True, exist_ok=True)
        Path(dest).write_text(text + "\n")


def scenarios_dir() -> Path:
    """The scenario files shipped with the package (the repository's ``scenarios/`` in a checkout)."""
    pkg = Path(__file__).resolve().parents[1]  # the uvms_mj package folder
    for cand in (pkg.parents[1] / "scenarios", pkg / "scenarios"):
        if cand.is_dir() and any(cand.glob("*.yaml")):
            return cand
    return pkg / "scenarios"


def packaged_scenarios() -> list[str]:
    """Names of the packaged scenarios (``uvms-mj run NAME``)."""
    return sorted(p.stem for p in scenarios_dir().glob("*.yaml"))


class ScenarioPath(click.ParamType):
    """A scenario file, or the name of a packaged scenario when no such file exists."""

    name = "SCENARIO"

    def convert(self, value, param, ctx):
        p = Path(value)
        if p.is_file():
            return str(p)
        if p.exists():
            self.fail(f"{value!r} is not a file", param, ctx)
        if p.name == str(value):  # a bare name: a packaged scenario
            cand = scenarios_dir() / (value if value.endswith((".yaml", ".yml")) else f"{value}.yaml")
            if cand.is_file():
                return str(cand)
        self.fail(f"{value!r}: no such file, nor a packaged scenario ({', '.join(packaged_scenarios())})",
                  param, ctx)


SCENARIO = ScenarioPath()


def _json_dest(human_to_stderr: bool):
    """click.echo for the human-readable lines: on stderr while --json - has stdout."""
    return (lambda *a, **k: click.echo(*a, err=True, **k)) if human_to_stderr else click.echo


_JSON_HELP = ("Also write the metrics (and status, reason, log of each run) as JSON: '-' for stdout (the "
              "human-readable lines then go to stderr), or a file path.")


@click.group(cls=_Group, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="uvms-mj")
def main() -> None:
    """uvms-mj: a MuJoCo testbed for underwater vehicle-manipulator systems.

    Run scenario files (scenarios/*.yaml) into Foxglove-ready MCAP logs, metrics tables, plots
    and videos; compare controllers; inspect logs.
    """


# ------------------------------------------------------------------ scenario runs


def _load(path: str, sets: tuple[str, ...]):
    from uvms_mj.scenario.schema import ScenarioError, load_scenario

    try:
        return load_scenario(path, sets)
    except ScenarioError as exc:
        raise click.UsageError(str(exc)) from None


def _run_one(scenario, out: Path, progress: bool = True, source: str | None = None):
    """Run one scenario into an MCAP log; returns (result, log path, metrics)."""
    from uvms_mj.sim.experiment import metrics
    from uvms_mj.io.recorder import LogInUseError, McapRecorder, handle_sigterm
    from uvms_mj.scenario.schema import ScenarioError, build, resolved, run_scenario

    _check_out(out, protect=(source,))
    try:
        plant, ctrl = build(scenario)
    except (ScenarioError, ParameterError, ValueError) as exc:
        raise click.UsageError(str(exc)) from None
    _warn(scenario)
    meta = {"scenario": resolved(scenario), "seed": scenario.seed}
    rec_kw = {}
    if getattr(plant, "layout", None) is not None:  # a floating robot: the recorder describes it from its model
        from uvms_mj.scenario.robot import robot_info

        meta["robot"] = robot_info(scenario, plant)
        rec_kw["model"] = plant.model
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        with _progress(f"{scenario.name} [{scenario.controller.name}]", "sample") as tick, handle_sigterm(), \
                McapRecorder(out, plant.params, meta, **rec_kw) as rec:
            try:
                res = run_scenario(scenario, sink=rec.write_sample, on_sample=tick if progress else None,
                                   built=(plant, ctrl))
            except KeyboardInterrupt as exc:
                rec.close(status="interrupted", reason=str(exc) or "interrupted (Ctrl-C)")
                click.echo(f"interrupted; partial log closed cleanly: {out}", err=True)
                sys.exit(EXIT_INTERRUPTED)
            except (ArithmeticError, ValueError, TypeError, LookupError, RuntimeError) as exc:
                # A controller or plant that raised mid-run: the log is closed with status "error".
                reason = " ".join(f"{type(exc).__name__}: {exc}".split())[:400]
                rec.close(status="error", reason=reason)
                click.echo(f"log: {out}")
                click.echo(f"error: the run failed: {reason}", err=True)
                sys.exit(1)
            rec.close(status=res.status, reason=res.reason, meta=res.meta)
    except LogInUseError as exc:
        raise click.UsageError(str(exc)) from None
    except OSError as exc:
        _io_error(out, exc)
    return res, out, metrics(res)


def _plots(log_path: Path, echo=click.echo) -> None:
    """The plots of a run's log; a run too short (or too broken) to plot gets a warning."""
    from uvms_mj.analysis.plots import plot_run

    try:
        paths = plot_run(_read(log_path), log_path.parent, stem=log_path.stem)
    except OSError as exc:
        _io_error(log_path.parent, exc)
    except (ValueError, KeyError, IndexError, TypeError) as exc:
        click.echo(f"warning: no plots for {log_path}: {exc}", err=True)
        return
    for p in paths:
        echo(f"plot: {p}")


def _read(path) -> object:
    """read_log with bad files turned into a usage error (exit 2), never a traceback."""
    from uvms_mj.io.recorder import read_log

    try:
        return read_log(path)
    except (MemoryError, RecursionError) as exc:
        raise click.UsageError(f"{path}: not a readable uvms-mj MCAP log ({type(exc).__name__})") from None
    except Exception as exc:  # noqa: BLE001 - McapError, struct, zstd, JSON... any malformed file
        raise click.UsageError(f"{path}: not a readable uvms-mj MCAP log ({type(exc).__name__}: "
                               f"{str(exc)[:200]})") from None


def _default_log(scenario, out: str | None, controller: str) -> Path:
    if out:
        return Path(out)
    if scenario.outputs.log:
        return Path(scenario.outputs.log)
    return Path("logs") / f"{scenario.name}-{controller}.mcap"


def _video(log_path: Path, video_path: Path, scenario=None, echo=click.echo) -> None:
    log = _read(log_path)
    kw = {}
    if scenario is not None:
        kw = {"fps": scenario.outputs.video_fps, "size": tuple(scenario.outputs.video_size)}
    _check_out(video_path, kind="video", magic=None)
    info = _render(log, video_path, log_path, **kw)
    echo(f"video: {video_path} ({info['frames']} frames)")


def _render(log, video_path: Path, log_path, **kw) -> dict:
    """render_video with GL trouble -> EXIT_RENDER, a log it cannot replay -> usage error,
    a write failure -> EXIT_IO."""
    from uvms_mj.analysis.render import RenderError, render_video

    try:
        with _progress(f"render {video_path.name}", "frame") as tick:
            return render_video(log, video_path, on_frame=tick, **kw)
    except RenderError as exc:
        click.echo(f"error: {exc}", err=True)
        sys.exit(EXIT_RENDER)
    except OSError as exc:
        _io_error(video_path, exc)
    except (ValueError, KeyError, IndexError, TypeError) as exc:
        raise click.UsageError(f"{log_path}: cannot be replayed: {type(exc).__name__}: {str(exc)[:200]}") from None


class _progress:
    """A tqdm bar (shown on terminals only) as a context manager yielding a (k, n) callback."""

    def __init__(self, desc: str, unit: str) -> None:
        from tqdm import tqdm

        self.bar = tqdm(desc=desc, unit=unit, leave=False, disable=None)

    def __enter__(self):
        def tick(k: int, n: int) -> None:
            self.bar.total = n
            self.bar.update(1)

        return tick

    def __exit__(self, *exc) -> None:
        self.bar.close()


@main.command()
@click.argument("scenario", type=SCENARIO)
@click.option("--set", "sets", multiple=True, metavar="KEY.PATH=VALUE",
              help="Override a scenario field, e.g. --set controller.name=rac --set plant.current=[0.1,0]")
@click.option("-o", "--out", type=click.Path(dir_okay=False), default=None,
              help="Log path (default: the scenario's outputs.log or logs/<name>-<controller>.mcap).")
@click.option("--video/--no-video", default=None, help="Render an MP4 next to the log (default: outputs.video).")
@click.option("--plots/--no-plots", default=None, help="Write PNG plots next to the log (default: outputs.plots).")
@click.option("--json", "json_out", metavar="PATH|-", default=None, help=_JSON_HELP)
def run(scenario: str, sets: tuple[str, ...], out: str | None, video: bool | None, plots: bool | None,
        json_out: str | None) -> None:
    """Run SCENARIO, write its MCAP log and print a metrics table.

    Exits with 3 if the run diverged (the log is kept, with the reason)."""
    echo = _json_dest(json_out == "-")
    sc = _load(scenario, sets)
    log = _default_log(sc, out, sc.controller.name)
    if video if video is not None else sc.outputs.video:
        _check_out(log.with_suffix(".mp4"), kind="video", magic=None)
    res, log, m = _run_one(sc, log, source=scenario)
    echo(f"log: {log}")
    echo(metrics_table({sc.controller.name: m}, {sc.controller.name: res.status}))
    if json_out:
        _write_json(_json_metrics({sc.controller.name: {"status": res.status, "reason": res.reason, "log": str(log),
                                                        "metrics": m}}, sc.name), json_out)
    if plots if plots is not None else sc.outputs.plots:
        _plots(log, echo)
    if video if video is not None else sc.outputs.video:
        _video(log, log.with_suffix(".mp4"), sc, echo=echo)
    if res.status != "ok":
        click.echo(f"error: {res.reason}", err=True)
        sys.exit(EXIT_DIVERGED)


@main.command()
@click.argument("scenario", type=SCENARIO)
@click.option("--controllers", default="rac,rac_dob", show_default=True, help="Comma-separated controller names.")
@click.option("--set", "sets", multiple=True, metavar="KEY.PATH=VALUE", help="Override a scenario field.")
@click.option("--out-dir", "out_dir", type=click.Path(file_okay=False), default=None,
              help="Folder for the logs and the comparison figure (default: logs).")
@click.option("--out", "out_dir_old", type=click.Path(file_okay=False), default=None, hidden=True)
@click.option("--video/--no-video", default=False, show_default=True, help="Render a video of each run.")
@click.option("--json", "json_out", metavar="PATH|-", default=None, help=_JSON_HELP)
def compare(scenario: str, controllers: str, sets: tuple[str, ...], out_dir: str | None, out_dir_old: str | None,
            video: bool, json_out: str | None) -> None:
    """Run SCENARIO with each controller; print a side-by-side table with ratios, write the logs
    and one comparison figure (PNG)."""
    out_dir = out_dir or out_dir_old or "logs"
    echo = _json_dest(json_out == "-")
    from uvms_mj.control import available
    from uvms_mj.analysis.plots import plot_comparison

    names = [c.strip() for c in controllers.split(",") if c.strip()]
    unknown = [c for c in names if c not in available()]
    if unknown or not names:
        raise click.BadParameter(f"unknown controller(s) {', '.join(unknown) or '(none given)'}; "
                                 f"registered: {', '.join(available())}", param_hint="--controllers")
    results, logs, failed, status, runs = {}, {}, [], {}, {}
    _check_dir(out_dir)
    base = _load(scenario, sets)
    # Every controller's scenario is checked before any runs (its own parameters: the
    # scenario's controllers.<name>, or controller.params for the file's controller, or defaults).
    scs = {name: _load(scenario, tuple(sets) + (f"controller.name={name}",)) for name in names}
    for name in names:
        sc = scs[name]
        path = Path(out_dir) / f"{sc.name}-{name}.mcap"
        res, path, m = _run_one(sc, path, source=scenario)
        results[name], logs[name], status[name] = m, path, res.status
        runs[name] = {"status": res.status, "reason": res.reason, "log": str(path), "metrics": m}
        echo(f"log: {path}")
        if res.status != "ok":
            failed.append(f"{name}: {res.reason}")
        if video:
            _video(path, path.with_suffix(".mp4"), sc, echo=echo)
    echo(metrics_table(results, status))
    if json_out:
        _write_json(_json_metrics(runs, base.name), json_out)
    try:
        fig = plot_comparison({n: _read(p) for n, p in logs.items()}, Path(out_dir) / f"{base.name}-compare.png")
        echo(f"figure: {fig}")
    except OSError as exc:
        _io_error(Path(out_dir) / f"{base.name}-compare.png", exc)
    except (ValueError, KeyError, IndexError, TypeError) as exc:
        click.echo(f"warning: no comparison figure: {exc}", err=True)
    if failed:
        click.echo("error: " + "; ".join(failed), err=True)
        sys.exit(EXIT_DIVERGED)


@main.command()
@click.argument("logs", nargs=-1, required=True, type=click.Path(exists=True, dir_okay=False), metavar="LOG [LOG_B]")
@click.option("-o", "--out", type=click.Path(dir_okay=False), default=None,
              help="MP4 path (default: LOG.mp4; with --compare LOG-vs-LOG_B.mp4 next to LOG).")
@click.option("--output", "out_old", type=click.Path(dir_okay=False), default=None, hidden=True)
@click.option("--compare", is_flag=True,
              help="Two logs side by side (same view), with an inset of both end-tip errors against time.")
@click.option("--fps", type=click.IntRange(1, 120), default=30, show_default=True)
@click.option("--size", type=(int, int), default=None,
              help="Width and height [px] (default 640 480; with --compare 1280 480, plus the inset).")
@click.option("--labels/--no-labels", default=True, show_default=True,
              help="Controller name, legend and scale bar on the frames.")
@click.option("--camera", default=None, metavar="NAME",
              help="A camera of the scene by name. Robot logs: follow_three_quarter (default) or follow_side; "
                   "paper logs: the fitted side view by default, or side / track.")
def render(logs: tuple[str, ...], out: str | None, out_old: str | None, compare: bool, fps: int,
           size: tuple[int, int] | None, labels: bool, camera: str | None) -> None:
    """Replay LOG's states in MuJoCo and render an MP4 off-screen (no re-simulation).

    With --compare, LOG and LOG_B side by side (e.g. rac and rac_dob)."""
    from uvms_mj.analysis.render import RenderError, render_compare_video, render_video

    out = out or out_old
    if compare != (len(logs) == 2) or len(logs) > 2:
        raise click.UsageError("give one LOG, or two with --compare")
    first = Path(logs[0])
    if compare:
        path = Path(out) if out else first.with_name(f"{first.stem}-vs-{Path(logs[1]).stem}.mp4")
    else:
        path = Path(out) if out else first.with_suffix(".mp4")
    _check_out(path, protect=logs, kind="video", magic=None)
    runs = [_read(p) for p in logs]
    try:
        with _progress(f"render {path.name}", "frame") as tick:
            if compare:
                info = render_compare_video(runs[0], runs[1], path, fps=fps, size=size or (1280, 480), on_frame=tick,
                                            camera=camera)
            else:
                info = render_video(runs[0], path, fps=fps, size=size or (640, 480), on_frame=tick, labels=labels,
                                    camera=camera)
    except RenderError as exc:
        click.echo(f"error: {exc}", err=True)
        sys.exit(EXIT_RENDER)
    except OSError as exc:
        _io_error(path, exc)
    except (ValueError, KeyError, IndexError, TypeError) as exc:
        raise click.UsageError(f"{', '.join(logs)}: cannot be rendered: {type(exc).__name__}: {str(exc)[:200]}") from None
    click.echo(f"video: {path} ({info['frames']} frames)")


@main.command(short_help="Paper-style time histories (Figs. 5 and 6) and control signals of LOG (PNG).")
@click.argument("log", type=click.Path(exists=True, dir_okay=False))
@click.option("--out-dir", type=click.Path(file_okay=False), default=None, help="Folder (default: LOG's).")
@click.option("-o", "out_dir_old", type=click.Path(file_okay=False), default=None, hidden=True)
def plot(log: str, out_dir: str | None, out_dir_old: str | None) -> None:
    """Paper-style time histories (Figs. 5 and 6) and control signals of LOG, as PNG."""
    from uvms_mj.analysis.plots import plot_run

    out_dir = out_dir or out_dir_old
    folder = _check_dir(Path(out_dir) if out_dir else Path(log).parent)
    run_log = _read(log)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        paths = plot_run(run_log, folder, stem=Path(log).stem)
    except OSError as exc:
        _io_error(folder, exc)
    except Exception as exc:  # noqa: BLE001 - a log that reads but holds nonsense
        raise click.UsageError(f"{log}: cannot be plotted: {type(exc).__name__}: {str(exc)[:200]}") from None
    for p in paths:
        click.echo(f"plot: {p}")


@main.command()
@click.argument("scenario", type=SCENARIO, required=False)
@click.option("--set", "sets", multiple=True, metavar="KEY.PATH=VALUE", help="Override a scenario field.")
@click.option("--list", "list_only", is_flag=True, help="List the packaged scenarios (runnable by name) and exit.")
def validate(scenario: str | None, sets: tuple[str, ...], list_only: bool) -> None:
    """Check SCENARIO (schema, values, controller, parameters) without running it."""
    from uvms_mj.scenario.schema import ScenarioError, build

    if list_only:
        for name in packaged_scenarios():
            click.echo(f"{name:<28} {scenarios_dir() / (name + '.yaml')}")
        return
    if scenario is None:
        raise click.UsageError("missing argument SCENARIO (or --list)")

    sc = _load(scenario, sets)
    try:
        build(sc)
    except (ScenarioError, ParameterError, ValueError) as exc:
        raise click.UsageError(str(exc)) from None
    _check_out(_default_log(sc, None, sc.controller.name), protect=(scenario,))
    _warn(sc)
    click.echo(f"{scenario}: ok ({sc.name}, controller {sc.controller.name}, {sc.duration:g} s)")


@main.command()
@click.argument("log", type=click.Path(exists=True, dir_okay=False))
def info(log: str) -> None:
    """Metadata, channels and message counts of LOG (and whether it is truncated)."""
    from mcap.exceptions import McapError

    from uvms_mj.io.recorder import format_info, log_info

    try:
        text = format_info(log_info(log))
    except (McapError, OSError, ValueError, KeyError) as exc:
        raise click.UsageError(f"{log}: not a readable uvms-mj MCAP log ({exc})") from None
    click.echo(text)


@main.command()
@click.argument("log", type=click.Path(exists=True, dir_okay=False))
@click.option("--format", "fmt", type=click.Choice(["csv", "parquet", "npz", "mat"]), default="csv",
              show_default=True, help="parquet needs pyarrow, mat needs scipy: pip install 'uvms-mj[export]'.")
@click.option("--layout", type=click.Choice(["wide", "channels"]), default="wide", show_default=True,
              help="wide: one table (t and every signal); channels: one table per log channel "
                   "(state_true, control).")
@click.option("-o", "--out", type=click.Path(), default=None,
              help="Output file (wide csv/parquet, npz, mat; default LOG.<format>) or folder (channels "
                   "csv/parquet; default LOG-export/).")
def export(log: str, fmt: str, layout: str, out: str | None) -> None:
    """Export LOG's per-sample signals as CSV, Parquet, NumPy .npz or MATLAB .mat.

    \b
    Columns: t [s], then each signal; a vector x gives x[0], x[1]...; a matrix x[i,j]
    (row-major); booleans 0/1; NaN empty in CSV. npz and mat keep the logged shapes and add
    meta_json (metadata and status). See uvms_mj.io.export."""
    from uvms_mj.io.export import ExportError, export_log

    run_log = _read(log)
    try:
        paths = export_log(run_log, fmt, out, layout=layout, log_path=log)
    except ExportError as exc:
        click.echo(f"error: {exc}", err=True)
        sys.exit(2)
    for p in paths:
        click.echo(f"{fmt}: {p}")


# ------------------------------------------------------------------ without scenario files


@main.command()
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


@main.command()
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


# ------------------------------------------------------------------ sweeps


@main.command()
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
@click.option("--seed", type=click.IntRange(min=0), default=0, show_default=True,
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


@main.command()
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


from uvms_mj.cli.sim2real import identify, sim2real  # noqa: E402

main.add_command(sim2real)
main.add_command(identify)

if __name__ == "__main__":
    main()
