"""``uvms-mj run``, ``compare`` and ``validate``: scenario files run into MCAP logs, metrics
tables, plots and videos."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from uvms_mj.cli.common import (EXIT_JOINT_LIMIT, EXIT_INTERRUPTED, EXIT_RENDER, SCENARIO, _JSON_HELP, _check_dir,
                                _check_out, _io_error, _json_dest, _json_metrics, _load, _progress, _read, _warn,
                                _write_json, exit_code, metrics_table, packaged_scenarios, scenarios_dir)
from uvms_mj.io.interrupts import partial_output
from uvms_mj.plant.params import ParameterError


def _run_one(scenario, out: Path, progress: bool = True, source: str | None = None, live=None,
             option: str = "--out"):
    """Run one scenario into an MCAP log (and to ``live``, a LiveServer, when given); returns
    (result, log path, metrics). A log that could not be written whole (a full disk, an I/O
    error) is removed: exit EXIT_IO."""
    from uvms_mj.sim.experiment import metrics
    from uvms_mj.io.recorder import LogInUseError, McapRecorder, handle_sigterm
    from uvms_mj.scenario.schema import ScenarioError, build, resolved, run_scenario

    _check_out(out, protect=(source,), option=option)
    try:
        plant, ctrl = build(scenario)
    except (ScenarioError, ParameterError, ValueError) as exc:
        raise click.UsageError(str(exc)) from None
    _warn(scenario)
    meta = {"scenario": resolved(scenario), "seed": scenario.seed}
    rec_kw = {"live": live} if live is not None else {}
    if getattr(getattr(plant, "layout", None), "base_free", False):  # a floating robot: the recorder describes it from its model
        from uvms_mj.scenario.robot import robot_info

        meta["robot"] = robot_info(scenario, plant)
        rec_kw["model"] = getattr(plant, "robot_model", plant.model)  # without a tether's chain: q_true fits it
    opened = False
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        with _progress(f"{scenario.name} [{scenario.controller.name}]", "sample") as tick, handle_sigterm(), \
                McapRecorder(out, plant.params, meta, **rec_kw) as rec:
            opened = True
            try:
                # streamed (keep=False): the rows go to the log, the metrics accumulate as the run goes,
                # and nothing grows with the duration (plots and videos read the log)
                res = run_scenario(scenario, sink=rec.write_sample, on_sample=tick if progress else None,
                                   built=(plant, ctrl), nav_sink=rec.write_navigation, keep=False)
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
        if opened:  # ours, cut short: not left under the log's name
            out.unlink(missing_ok=True)
        _io_error(out, exc)
    return res, out, metrics(res)


def _live_server(port: int, pace: str, wait: float):
    """The --live server (uvms_mj.io.live.LiveServer); exit 2 in one line without foxglove-sdk or the port."""
    from uvms_mj.io.live import LiveServer, LiveUnavailable

    try:
        server = LiveServer(port=port, pace=pace, wait=wait)
    except LiveUnavailable as exc:
        click.echo(f"error: {exc}", err=True)
        sys.exit(2)
    except (OSError, RuntimeError) as exc:  # the port is taken (the SDK's error)
        click.echo(f"error: --live: cannot listen on 127.0.0.1:{port}: {exc}", err=True)
        sys.exit(2)
    click.echo(f"live: {server.url} (Foxglove: Open connection -> Foxglove WebSocket; pace {pace})", err=True)
    return server


def _plots(log_path: Path, echo=click.echo, protect: tuple = ()) -> None:
    """The plots of a run's log (its signals read from it); a run too short (or too broken) to
    plot gets a warning."""
    from uvms_mj.analysis.plots import PLOT_SIGNALS, plot_run, plot_run_paths, read_plot_log

    for p in plot_run_paths(log_path.parent, log_path.stem):
        _check_out(p, protect=protect, kind="plot", option="--plots")
    try:
        paths = plot_run(_read(log_path, PLOT_SIGNALS, reader=read_plot_log), log_path.parent, stem=log_path.stem)
    except OSError as exc:
        _io_error(log_path.parent, exc)
    except (ValueError, KeyError, IndexError, TypeError) as exc:
        click.echo(f"warning: no plots for {log_path}: {exc}", err=True)
        return
    for p in paths:
        echo(f"plot: {p}")


def _release_memory() -> None:
    """Between the runs of compare: collect the finished run's garbage and hand the freed heap
    back to the system (glibc's malloc_trim; elsewhere a no-op), so the next run starts low."""
    import ctypes
    import gc

    gc.collect()
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):
        pass


def _default_log(scenario, out: str | None, controller: str) -> Path:
    if out:
        return Path(out)
    if scenario.outputs.log:
        return Path(scenario.outputs.log)
    return Path("logs") / f"{scenario.name}-{controller}.mcap"


def _video(log_path: Path, video_path: Path, scenario=None, echo=click.echo, protect: tuple = ()) -> None:
    from uvms_mj.cli.logs import _read_video_log

    log = _read_video_log(log_path)
    kw = {}
    if scenario is not None:
        kw = {"fps": scenario.outputs.video_fps, "size": tuple(scenario.outputs.video_size)}
    _check_out(video_path, protect=(log_path, *protect), kind="video", option="--video")
    info = _render(log, video_path, log_path, **kw)
    echo(f"video: {video_path} ({info['frames']} frames)")


def _render(log, video_path: Path, log_path, **kw) -> dict:
    """render_video with GL trouble -> EXIT_RENDER, a log it cannot replay -> usage error,
    a write failure -> EXIT_IO."""
    from uvms_mj.analysis.render import RenderError, render_video

    try:
        with _progress(f"render {video_path.name}", "frame") as tick, partial_output(video_path):
            return render_video(log, video_path, on_frame=tick, **kw)
    except RenderError as exc:
        click.echo(f"error: {exc}", err=True)
        sys.exit(EXIT_RENDER)
    except OSError as exc:
        _io_error(video_path, exc)
    except (ValueError, KeyError, IndexError, TypeError) as exc:
        raise click.UsageError(f"{log_path}: cannot be replayed: {type(exc).__name__}: {str(exc)[:200]}") from None


@click.command("run")
@click.argument("scenario", type=SCENARIO)
@click.option("--set", "sets", multiple=True, metavar="KEY.PATH=VALUE",
              help="Override a scenario field, e.g. --set controller.name=rac --set plant.current=[0.1,0]")
@click.option("-o", "--out", type=click.Path(dir_okay=False), default=None,
              help="Log path (default: the scenario's outputs.log or logs/<name>-<controller>.mcap).")
@click.option("--video/--no-video", default=None, help="Render an MP4 next to the log (default: outputs.video).")
@click.option("--plots/--no-plots", default=None, help="Write PNG plots next to the log (default: outputs.plots).")
@click.option("--json", "json_out", metavar="PATH|-", default=None, help=_JSON_HELP)
@click.option("--live", is_flag=True, help="Also stream the run to the Foxglove app (WebSocket, ws://127.0.0.1:PORT; "
              "needs foxglove-sdk: pip install 'uvms-mj[live]').")
@click.option("--live-port", type=click.IntRange(0, 65535), default=8765, show_default=True,
              help="The --live server's port (0: any free port, printed).")
@click.option("--live-wait", type=click.FloatRange(0, 3600), default=0.0, show_default=True, metavar="SECONDS",
              help="With --live: wait up to SECONDS for the app to subscribe before the run starts.")
@click.option("--pace", type=click.Choice(["realtime", "fast"]), default=None,
              help="With --live: simulation time follows wall time (realtime, the default) or runs as fast as it can.")
def run_cmd(scenario: str, sets: tuple[str, ...], out: str | None, video: bool | None, plots: bool | None,
        json_out: str | None, live: bool, live_port: int, live_wait: float, pace: str | None) -> None:
    """Run SCENARIO, write its MCAP log and print a metrics table.

    Exits with 3 if the run diverged (the log is kept, with the reason)."""
    echo = _json_dest(json_out == "-")
    if pace is not None and not live:
        raise click.UsageError("--pace needs --live (a run without it goes as fast as it can)")
    sc = _load(scenario, sets)
    log = _default_log(sc, out, sc.controller.name)
    # Every output checked before the run: none may be an input or a file that is not its kind.
    _check_out(log, protect=(scenario,), option="--out")
    if video if video is not None else sc.outputs.video:
        _check_out(log.with_suffix(".mp4"), protect=(scenario, log), kind="video", option="--video")
    if json_out and json_out != "-":
        _check_out(json_out, protect=(scenario, log), kind="JSON file", option="--json")
    if plots if plots is not None else sc.outputs.plots:
        from uvms_mj.analysis.plots import plot_run_paths

        for p in plot_run_paths(log.parent, log.stem):
            _check_out(p, protect=(scenario, log, json_out), kind="plot", option="--plots")
    server = _live_server(live_port, pace or "realtime", live_wait) if live else None
    try:
        res, log, m = _run_one(sc, log, source=scenario, live=server)
    finally:
        if server is not None:
            server.close()
    status, reason = res.status, res.reason
    echo(f"log: {log}")
    echo(metrics_table({sc.controller.name: m}, {sc.controller.name: status}))
    if json_out:
        _write_json(_json_metrics({sc.controller.name: {"status": status, "reason": reason, "log": str(log),
                                                        "metrics": m}}, sc.name), json_out)
    if plots if plots is not None else sc.outputs.plots:
        _plots(log, echo, protect=(scenario, json_out))  # from the log (the run kept no samples)
    if video if video is not None else sc.outputs.video:
        _video(log, log.with_suffix(".mp4"), sc, echo=echo, protect=(scenario, json_out))
    if status != "ok":
        click.echo(f"{'error' if status != 'joint_limit' else 'warning'}: {reason}", err=True)
        sys.exit(exit_code([status]))


@click.command()
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
    twice = sorted({c for c in names if names.count(c) > 1})
    if twice:
        raise click.BadParameter(f"{', '.join(twice)} given twice: each controller once (one log each)",
                                 param_hint="--controllers")
    results, logs, failed, status, runs = {}, {}, [], {}, {}
    _check_dir(out_dir)
    base = _load(scenario, sets)
    # Every controller's scenario is checked before any runs (its own parameters: the
    # scenario's controllers.<name>, or controller.params for the file's controller, or defaults).
    scs = {name: _load(scenario, tuple(sets) + (f"controller.name={name}",)) for name in names}
    figure = Path(out_dir) / f"{base.name}-compare.png"
    paths = [Path(out_dir) / f"{scs[n].name}-{n}.mcap" for n in names]
    for p in paths:
        _check_out(p, protect=(scenario,), option="--out-dir")
        if video:
            _check_out(p.with_suffix(".mp4"), protect=(scenario,), kind="video", option="--video")
    if json_out and json_out != "-":
        _check_out(json_out, protect=(scenario, *paths), kind="JSON file", option="--json")
    _check_out(figure, protect=(scenario, json_out, *paths), kind="plot", option="--out-dir")
    for name in names:
        sc = scs[name]
        path = Path(out_dir) / f"{sc.name}-{name}.mcap"
        res, path, m = _run_one(sc, path, source=scenario, option="--out-dir")
        results[name], logs[name], status[name] = m, path, res.status
        runs[name] = {"status": res.status, "reason": res.reason, "log": str(path), "metrics": m}
        if res.status != "ok":
            failed.append(f"{name}: {res.reason}")
        del res
        _release_memory()
        echo(f"log: {path}")
        if video:
            _video(path, path.with_suffix(".mp4"), sc, echo=echo, protect=(scenario, json_out))
    echo(metrics_table(results, status))
    if json_out:
        _write_json(_json_metrics(runs, base.name), json_out)
    try:
        fig = plot_comparison({n: str(p) for n, p in logs.items()}, figure)  # read one at a time, subsets
        echo(f"figure: {fig}")
    except OSError as exc:
        _io_error(figure, exc)
    except Exception as exc:  # noqa: BLE001 - e.g. a log that no longer reads: no figure, the table stands
        click.echo(f"warning: no comparison figure: {exc}", err=True)
    if failed:
        code = exit_code(status.values())
        click.echo(("error: " if code != EXIT_JOINT_LIMIT else "warning: ") + "; ".join(failed), err=True)
        sys.exit(code)


@click.command()
@click.argument("scenario", type=SCENARIO, required=False)
@click.option("--set", "sets", multiple=True, metavar="KEY.PATH=VALUE", help="Override a scenario field.")
@click.option("--list", "list_only", is_flag=True, help="List the packaged scenarios (runnable by name) and exit.")
@click.option("--resolved", "show_resolved", is_flag=True,
              help="Print the fully resolved scenario (every default filled in) as YAML on stdout.")
def validate(scenario: str | None, sets: tuple[str, ...], list_only: bool, show_resolved: bool) -> None:
    """Check SCENARIO (schema, values, controller, parameters) without running it; --resolved
    prints the resolved scenario (itself a valid scenario describing the same run)."""
    from uvms_mj.scenario.schema import ScenarioError, build, resolved

    if list_only:
        for name in packaged_scenarios():
            click.echo(f"{name:<28} {scenarios_dir() / (name + '.yaml')}")
        return
    if scenario is None:
        raise click.UsageError("missing argument SCENARIO (or --list)")

    sc = _load(scenario, sets)
    try:
        _, ctrl = build(sc)
    except (ScenarioError, ParameterError, ValueError) as exc:
        raise click.UsageError(str(exc)) from None
    _check_out(_default_log(sc, None, sc.controller.name), protect=(scenario,))
    _warn(sc)
    if show_resolved:
        import yaml

        click.echo(yaml.safe_dump(resolved(sc), sort_keys=False, default_flow_style=None), nl=False)
        thresholds = getattr(ctrl, "resolved_params", None)  # RAC's "auto" thresholds as the numbers the run uses
        if isinstance(thresholds, dict) and "js" in thresholds:
            from uvms_mj.control.manipulability import describe_thresholds

            click.echo(f"{sc.controller.name}: {describe_thresholds(thresholds)}", err=True)
        click.echo(f"{scenario}: ok ({sc.name}, controller {sc.controller.name}, {sc.duration:g} s)", err=True)
        return
    click.echo(f"{scenario}: ok ({sc.name}, controller {sc.controller.name}, {sc.duration:g} s)")
