"""``uvms-mj render``, ``plot``, ``info`` and ``export``: what is done with a log once written."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from uvms_mj.cli.common import EXIT_RENDER, _check_dir, _check_out, _io_error, _progress, _read
from uvms_mj.io.interrupts import partial_output


def _read_video_log(path: str):
    """A log as a video reads it (:func:`uvms_mj.analysis.render_stream.read_render_log`: in memory that
    does not grow with the log), bad files a usage error."""
    from uvms_mj.analysis.render_stream import RENDER_SIGNALS, read_render_log

    return _read(path, RENDER_SIGNALS, reader=read_render_log)


@click.command()
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
              help="A camera of the scene by name. Robot logs: follow_arm (default: vehicle and arm, from the arm's "
                   "side), follow_three_quarter or follow_side; "
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
    _check_out(path, protect=logs, kind="video", option="--out")
    runs = [_read_video_log(p) for p in logs]
    try:
        with _progress(f"render {path.name}", "frame") as tick, partial_output(path):
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


@click.command(short_help="Paper-style time histories (Figs. 5 and 6) and control signals of LOG (PNG).")
@click.argument("log", type=click.Path(exists=True, dir_okay=False))
@click.option("--out-dir", type=click.Path(file_okay=False), default=None, help="Folder (default: LOG's).")
@click.option("-o", "out_dir_old", type=click.Path(file_okay=False), default=None, hidden=True)
def plot(log: str, out_dir: str | None, out_dir_old: str | None) -> None:
    """Paper-style time histories (Figs. 5 and 6) and control signals of LOG, as PNG."""
    from uvms_mj.analysis.plots import PLOT_SIGNALS, plot_run, plot_run_paths, read_plot_log

    out_dir = out_dir or out_dir_old
    folder = _check_dir(Path(out_dir) if out_dir else Path(log).parent)
    for p in plot_run_paths(folder, Path(log).stem):
        _check_out(p, protect=(log,), kind="plot", option="--out-dir")
    run_log = _read(log, PLOT_SIGNALS, reader=read_plot_log)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        paths = plot_run(run_log, folder, stem=Path(log).stem)
    except OSError as exc:
        _io_error(folder, exc)
    except Exception as exc:  # noqa: BLE001 - a log that reads but holds nonsense
        raise click.UsageError(f"{log}: cannot be plotted: {type(exc).__name__}: {str(exc)[:200]}") from None
    for p in paths:
        click.echo(f"plot: {p}")


@click.command()
@click.argument("log", type=click.Path(exists=True, dir_okay=False))
def info(log: str) -> None:
    """Metadata, channels and message counts of LOG (and whether it is truncated)."""
    from mcap.exceptions import McapError

    from uvms_mj.io.logfile import LogFileError
    from uvms_mj.io.recorder import format_info, log_info

    try:
        text = format_info(log_info(log))
    except LogFileError as exc:
        raise click.UsageError(str(exc)) from None
    except (McapError, OSError, ValueError, KeyError) as exc:
        raise click.UsageError(f"{log}: not a readable uvms-mj MCAP log ({exc})") from None
    click.echo(text)


@click.command()
@click.argument("log", type=click.Path(exists=True, dir_okay=False))
@click.option("--format", "fmt", type=click.Choice(["csv", "parquet", "npz", "mat"]), default="csv",
              show_default=True, help="parquet needs pyarrow, mat needs scipy: pip install 'uvms-mj[export]'.")
@click.option("--layout", type=click.Choice(["wide", "channels"]), default="wide", show_default=True,
              help="wide: one table (t and every signal); channels: one table per log channel "
                   "(state_true, control).")
@click.option("-o", "--out", type=click.Path(), default=None,
              help="Output file (wide csv/parquet, npz, mat; default LOG.<format>) or folder (channels "
                   "csv/parquet; default LOG-export/).")
@click.option("--columns", type=click.Choice(["named", "index"]), default="named", show_default=True,
              help="named: vector components by joint, axis and thruster from the log's robot layout "
                   "(q_true[alpha_shoulder], thrust_force[bluerov2_t1], tip_true[z]; the index where a name "
                   "is unknown); index: x[0], x[1]... everywhere.")
def export(log: str, fmt: str, layout: str, out: str | None, columns: str) -> None:
    """Export LOG's per-sample signals as CSV, Parquet, NumPy .npz or MATLAB .mat.

    \b
    Columns: t [s], then each signal; a vector gives one column per component, named by
    joint, axis and thruster (q_true[base_x], torques[joint1]; x[0], x[1]... where a name is
    unknown, or with --columns index); a matrix x[i,j] (row-major); booleans 0/1; NaN empty
    in CSV. npz and mat keep the logged shapes and add meta_json (metadata and status) and
    columns_json (the component names). See uvms_mj.io.export."""
    from uvms_mj.io.export import OUTPUT_KIND, ExportError, export_log, export_paths
    from uvms_mj.io.logfile import LogFileError

    targets = export_paths(fmt, out, layout, log)
    if layout == "channels" and fmt in ("csv", "parquet"):
        _check_dir(targets[0].parent, option="-o/--out")
    for p in targets:
        _check_out(p, protect=(log,), kind=OUTPUT_KIND[fmt], option="-o/--out")
    try:  # the log is read by blocks as the output is written (its memory does not grow with the log)
        paths = export_log(log, fmt, out, layout=layout, log_path=log, columns=columns)
    except ExportError as exc:
        click.echo(f"error: {exc}", err=True)
        sys.exit(2)
    except LogFileError as exc:  # a FIFO, a foreign, empty or magic-only file (io/logfile.py)
        raise click.UsageError(str(exc)) from None
    except OSError as exc:
        _io_error(getattr(exc, "filename", None) or out or log, exc)
    except (MemoryError, RecursionError) as exc:
        raise click.UsageError(f"{log}: not a readable uvms-mj MCAP log ({type(exc).__name__})") from None
    except Exception as exc:  # noqa: BLE001 - McapError, struct, zstd, JSON... any malformed file (as _read)
        raise click.UsageError(f"{log}: not a readable uvms-mj MCAP log ({type(exc).__name__}: "
                               f"{str(exc)[:200]})") from None
    for p in paths:
        click.echo(f"{fmt}: {p}")
