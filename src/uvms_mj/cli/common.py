"""What the ``uvms-mj`` commands share: exit codes, output-path checks and I/O errors, JSON and
metrics tables, the SCENARIO argument (a file or a packaged scenario), reading logs, progress bars."""

from __future__ import annotations

import sys
from pathlib import Path

import click

# scenarios_dir, packaged_scenarios: importable from here as before
from uvms_mj.scenario.packaged import packaged_scenarios, resolve_scenario, scenarios_dir  # noqa: F401

EXIT_DIVERGED = 3
EXIT_RENDER = 4
EXIT_IO = 5
EXIT_INTERRUPTED = 130
#: A run that finished but took a joint past its range by more than 1 deg (status "joint_limit").
EXIT_JOINT_LIMIT = 6

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
    "joint_limit_excursion_deg": "joint limit excursion [deg]",
    "singular_s": "Eq. 12 singular phase [s]",
    "nav_pos_rms_mm": "estimate position RMS [mm]",
    "nav_att_rms_mrad": "estimate attitude RMS [mrad]",
}
#: Rows shown only when some run has a value (floating-robot metrics; controllers with Eq. 12).
_OPTIONAL_ROWS = ("joint_rms_mrad", "singular_s", "nav_pos_rms_mm", "nav_att_rms_mrad")


def metrics_table(results: dict[str, dict[str, float]], status: dict[str, str] | None = None) -> str:
    """Side-by-side metrics; with two columns, the ratio second / first; with ``status``
    (controller -> "ok", "diverged"...), a status row first."""
    names = list(results)
    ratio = len(names) == 2
    # each column at least 2 characters wider than its controller's name (and its status): columns
    # never run together, and the table splits on whitespace
    width = [max(12, len(str(n)) + 2, len(str((status or {}).get(n, ""))) + 2) for n in names]
    lines = [f"{'metric':<28}" + "".join(f"{n:>{w}}" for n, w in zip(names, width))
             + (f"{'ratio':>9}" if ratio else "")]
    if status is not None:
        lines.append(f"{'status':<28}" + "".join(f"{status.get(n, '?'):>{w}}" for n, w in zip(names, width)))
    for key, label in METRIC_LABELS.items():
        vals = [results[n].get(key, float("nan")) for n in names]
        if key in _OPTIONAL_ROWS and all(v != v for v in vals):
            continue
        # "-": a metric a run does not have (NaN), a ratio that is not defined (0 / 0, NaN)
        line = f"{label:<28}" + "".join(f"{v:>{w}.4g}" if v == v else f"{'-':>{w}}" for v, w in zip(vals, width))
        if ratio:
            r = (vals[1] / vals[0]) if vals[0] else float("nan")
            line += f"{r:>9.2f}" if r == r else f"{'-':>9}"
        lines.append(line)
    return "\n".join(lines)


def exit_code(statuses) -> int:
    """The exit code of finished runs: EXIT_DIVERGED if one diverged, else EXIT_JOINT_LIMIT if a
    joint left its range (status "joint_limit"), else 0."""
    statuses = list(statuses)
    if any(s not in ("ok", "joint_limit") for s in statuses):
        return EXIT_DIVERGED
    return EXIT_JOINT_LIMIT if "joint_limit" in statuses else 0


def _interrupted() -> None:
    click.echo("interrupted", err=True)
    sys.exit(EXIT_INTERRUPTED)


def _io_error(path, exc: OSError) -> None:
    """An output that could not be written: one line, exit EXIT_IO."""
    why = exc.strerror or str(exc) or type(exc).__name__
    why = " ".join(why.split())[:300]  # one line, whatever the OSError carried (ffmpeg's text...)
    click.echo(f"error: cannot write {path}: {why}", err=True)
    sys.exit(EXIT_IO)


#: The longest "Error:" line of a usage error [characters] (ours: a message listing many problems
#: is cut there, with the count of what was left out).
ERROR_LINE_MAX = 2000


def _short_word(word: str, limit: int = 200) -> str:
    """A word (no spaces) longer than ``limit``, e.g. a --set value of 3000 digits, as its start and end."""
    if len(word) <= limit:
        return word
    return f"{word[:100]}...({len(word) - 140} characters)...{word[-40:]}"


def short_usage_error(exc: click.UsageError) -> None:
    """Print a usage error (exit 2) as at most two lines, then exit: ``Error: ...`` (its message on one line,
    the lines of a multi-line message joined by "; ") and the help hint -- not click's usage block."""
    lines = [" ".join(_short_word(w) for w in ln.split()) for ln in exc.format_message().splitlines()]
    msg = "; ".join(ln for ln in lines if ln)
    if len(msg) > ERROR_LINE_MAX:  # the start and the end (where a file name often is)
        cut = len(msg) - ERROR_LINE_MAX
        msg = f"{msg[:ERROR_LINE_MAX - 400]}... ({cut} characters left out) ...{msg[-400:]}"
    click.echo(f"Error: {msg}", err=True)
    ctx = exc.ctx
    if ctx is not None and ctx.command.get_help_option(ctx) is not None:
        click.echo(f"Try '{ctx.command_path} {ctx.help_option_names[0]}' for help.", err=True)
    sys.exit(exc.exit_code)


def _check_out(path, protect: tuple = (), kind: str = "log", option: str | None = None, **magic) -> Path:
    """:func:`uvms_mj.io.paths.check_output_path` with a refusal as a usage error (exit 2):
    one line naming ``option`` (when given), the path and why. ``protect``: the command's inputs;
    ``kind``: a key of :data:`uvms_mj.io.paths.OUTPUT_KINDS` (or ``magic=`` to override)."""
    from uvms_mj.io.paths import OutputPathError, check_output_path

    try:
        return check_output_path(path, protect=tuple(protect), kind=kind, **magic)
    except OutputPathError as exc:
        raise click.UsageError(f"{option}: {exc}" if option else str(exc)) from None


def _check_dir(path, option: str | None = None) -> Path:
    from uvms_mj.io.paths import OutputPathError, check_output_dir

    try:
        return check_output_dir(path)
    except OutputPathError as exc:
        raise click.UsageError(f"{option}: {exc}" if option else str(exc)) from None


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

    import numpy as np

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

    from uvms_mj.io.atomic import atomic_open

    text = json.dumps(clean(data), indent=2, allow_nan=False)
    if dest == "-":
        click.echo(text)
        return
    try:
        with atomic_open(dest, "w", encoding="utf-8") as f:
            f.write(text + "\n")
    except OSError as exc:
        _io_error(dest, exc)


class ScenarioPath(click.ParamType):
    """A scenario file, or the name of a packaged scenario when no such file exists
    (:func:`uvms_mj.scenario.packaged.resolve_scenario`)."""

    name = "SCENARIO"

    def convert(self, value, param, ctx):
        from uvms_mj.scenario.base import ScenarioError

        try:
            return str(resolve_scenario(value))
        except ScenarioError as exc:
            self.fail(str(exc), param, ctx)


SCENARIO = ScenarioPath()


def _json_dest(human_to_stderr: bool):
    """click.echo for the human-readable lines: on stderr while --json - has stdout."""
    return (lambda *a, **k: click.echo(*a, err=True, **k)) if human_to_stderr else click.echo


_JSON_HELP = ("Also write the metrics (and status, reason, log of each run) as JSON: '-' for stdout (the "
              "human-readable lines then go to stderr), or a file path.")


def _load(path: str, sets: tuple[str, ...]):
    from uvms_mj.scenario.schema import ScenarioError, load_scenario

    try:
        return load_scenario(path, sets)
    except ScenarioError as exc:
        raise click.UsageError(str(exc)) from None


def _read(path, signals=None, reader=None) -> object:
    """read_log with bad files turned into a usage error (exit 2), never a traceback; ``signals``:
    read only those (read_log's subset: what a plot or a video needs of a long log); ``reader``:
    another reader with read_log's arguments (the figures': ``read_plot_log``)."""
    from uvms_mj.io.logfile import LogFileError
    from uvms_mj.io.recorder import read_log

    try:
        return (reader or read_log)(path, signals=signals)
    except LogFileError as exc:
        raise click.UsageError(str(exc)) from None
    except (MemoryError, RecursionError) as exc:
        raise click.UsageError(f"{path}: not a readable uvms-mj MCAP log ({type(exc).__name__})") from None
    except Exception as exc:  # noqa: BLE001 - McapError, struct, zstd, JSON... any malformed file
        raise click.UsageError(f"{path}: not a readable uvms-mj MCAP log ({type(exc).__name__}: "
                               f"{str(exc)[:200]})") from None


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
