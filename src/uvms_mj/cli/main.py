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

import contextlib
import os
import signal
import sys


def _exit_130(*_) -> None:
    """SIGINT or SIGTERM while the command line starts (its imports): exit 130 at once, quietly
    (no KeyboardInterrupt traceback, none swallowed by an import lock's callback; nothing is
    written yet)."""
    sys.stderr.write("interrupted\n")
    os._exit(130)


#: Commands that never render (nor start a process that does): the command line's own process imports
#: mujoco for them with rendering disabled (``MUJOCO_GL=disable`` unless the user set it).
_NEVER_RENDER = frozenset({"validate", "info", "export"})


def _command_name(argv: list[str]) -> str | None:
    """The subcommand of a command line (its first argument that is not an option), or None."""
    return next((a for a in argv if not a.startswith("-")), None)


#: This process is the command line's own (``python -m uvms_mj.cli.main`` or the installed
#: ``uvms-mj``), never a module that imports this one (a test runner): only then are signals
#: handled from the start and the watchdog of :func:`uvms_mj.io.interrupts.cli_signals` armed.
_CLI_PROCESS = ((__name__ == "__main__" or bool(sys.argv and os.path.basename(sys.argv[0]) == "uvms-mj"))
                and "--multiprocessing-fork" not in getattr(sys, "orig_argv", ()))  # not a sweep's spawned worker

if _CLI_PROCESS:
    # As early as possible (before click, numpy, mujoco are imported): Ctrl-C or SIGTERM during
    # the imports exits 130 quietly, and without a display MUJOCO_GL is set to a headless
    # backend before mujoco is imported (no GLFW probe; its children, e.g. sweep workers, inherit it).
    signal.signal(signal.SIGINT, _exit_130)
    signal.signal(signal.SIGTERM, _exit_130)
    if _command_name(sys.argv[1:]) in _NEVER_RENDER:
        # validate, info, export never render: mujoco is imported without an OpenGL backend (no PyOpenGL
        # import, no EGL/OSMesa library probe: ~0.05 s of validate's start-up); a user's MUJOCO_GL is kept.
        os.environ.setdefault("MUJOCO_GL", "disable")
    else:
        from uvms_mj.analysis.render_gl import configure_gl

        configure_gl()

import click  # noqa: E402

from uvms_mj import __version__  # noqa: E402
# The group and its options live here; each command in the module of its kind, imported when the command
# is looked up (a command line imports only its own command's module: ``validate`` no sweep, no sim2real);
# what they share in cli.common (re-exported here: the exit codes, metrics_table, the packaged scenarios).
from uvms_mj.cli.common import (EXIT_DIVERGED, EXIT_INTERRUPTED, EXIT_IO, EXIT_RENDER,  # noqa: F401,E402
                                _interrupted, metrics_table, packaged_scenarios, scenarios_dir,
                                short_usage_error)

#: Command name -> (module, attribute) of its click command.
_COMMANDS = {
    "run": ("uvms_mj.cli.run", "run_cmd"), "compare": ("uvms_mj.cli.run", "compare"),
    "validate": ("uvms_mj.cli.run", "validate"), "render": ("uvms_mj.cli.logs", "render"),
    "plot": ("uvms_mj.cli.logs", "plot"), "info": ("uvms_mj.cli.logs", "info"),
    "export": ("uvms_mj.cli.logs", "export"), "sweep": ("uvms_mj.cli.study", "sweep"),
    "paper": ("uvms_mj.cli.plant", "paper"), "drift": ("uvms_mj.cli.plant", "drift"),
    "view": ("uvms_mj.cli.plant", "view"), "sim2real": ("uvms_mj.cli.sim2real", "sim2real"),
    "identify": ("uvms_mj.cli.sim2real", "identify_cmd"),
}


class _Group(click.Group):
    """SIGINT or SIGTERM anywhere exits with 130, not click's "Aborted!" with 1 nor death by the
    signal: while the command runs :func:`uvms_mj.io.interrupts.cli_signals` turns them into
    KeyboardInterrupt (logs close with status "interrupted", a sweep stops its workers and writes
    the rows of its finished runs, files being written are removed) and, in the command line's
    own process, a watchdog ends the process GRACE_S (1.5 s) after the signal if that path has
    not; whatever the command was doing, a command that got the signal exits 130. A bad
    ``UVMS_MJ_COMPILED`` (or a former switch set) is one line and exit 2."""

    def main(self, *args, **kwargs):  # noqa: ANN002, ANN003
        if _CLI_PROCESS:
            # The command's module and mujoco (which every command's compiled_mode check imports) are
            # imported while Ctrl-C still exits 130 at once: an interrupt inside an extension's
            # initialisation would otherwise surface as an ImportError.
            self.get_command(None, _command_name(sys.argv[1:]) or "")
            import uvms_mj.physics.build  # noqa: F401
        from uvms_mj.io.interrupts import cli_signals, exit_now, signalled

        with contextlib.ExitStack() as stack:
            try:
                stack.enter_context(cli_signals(watchdog=_CLI_PROCESS))
            except KeyboardInterrupt:  # the signal came while the policy was being set up
                if _CLI_PROCESS:
                    exit_now(message=True)
                _interrupted()
            try:
                rv = super().main(*args, **kwargs)
            except SystemExit as exc:
                if signalled():
                    if exc.code != EXIT_INTERRUPTED:  # e.g. an exit code set while the signal unwound the command
                        click.echo("interrupted", err=True)
                    if _CLI_PROCESS:  # the command has closed its outputs: no teardown (it can take a second)
                        exit_now(message=False)
                    sys.exit(EXIT_INTERRUPTED)
                raise
            if signalled():
                _interrupted()  # standalone_mode=False: the command returned after the signal
            return rv

    def list_commands(self, ctx):  # noqa: ANN001
        return sorted({*_COMMANDS, *self.commands})

    def get_command(self, ctx, cmd_name: str):  # noqa: ANN001
        if cmd_name not in self.commands and cmd_name in _COMMANDS:
            module, attr = _COMMANDS[cmd_name]
            # (the import statement's machinery, not importlib.import_module: -X importtime reports it)
            self.add_command(getattr(__import__(module, fromlist=[attr]), attr), cmd_name)
        return self.commands.get(cmd_name)

    def make_context(self, *args, **kwargs):  # noqa: ANN002, ANN003
        try:
            return super().make_context(*args, **kwargs)
        except KeyboardInterrupt:
            _interrupted()
        except click.exceptions.NoArgsIsHelpError:
            raise  # the help text, as click shows it
        except click.UsageError as exc:  # the group's own options: one "Error:" line and the hint
            short_usage_error(exc)

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
        except click.exceptions.NoArgsIsHelpError:
            raise  # the help text, as click shows it
        except click.UsageError as exc:  # one "Error:" line and the help hint (not click's usage block)
            short_usage_error(exc)


@click.group(cls=_Group, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="uvms-mj")
def main() -> None:
    """uvms-mj: a MuJoCo testbed for underwater vehicle-manipulator systems.

    Run scenario files (scenarios/*.yaml) into Foxglove-ready MCAP logs, metrics tables, plots
    and videos; compare controllers; inspect logs.
    """


if __name__ == "__main__":
    main()
