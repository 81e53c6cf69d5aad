"""The ``kinecal`` command. Parsing only: every command loads files and calls the API.

Heavy modules (numpy, scipy, OpenCV) are imported inside the commands, and a command's
module only when that command runs (:class:`_LazyGroup`), so ``kinecal --help`` starts
fast. Every failure goes through :func:`main`: one line
``Error: ...`` on stderr and an exit code of :class:`~kinecal.cli._errors.ExitCode`
(0 success, 1 internal error, 2 bad input or usage, 3 calibration not converged, 4 some
targets unreachable, 5 the system refused a read or write, 130 Ctrl-C); docs/errors.md
lists them with what to do. Result folders are staged and moved into place only when the
command succeeds (:mod:`kinecal._outputs`).
"""

from __future__ import annotations

import functools
import importlib
import sys

import click

from kinecal._version import __version__
from kinecal.cli._errors import ExitCode
from kinecal.errors import OutputClosed

EXIT_INTERNAL = int(ExitCode.INTERNAL)
EXIT_BAD_INPUT = int(ExitCode.BAD_INPUT)
EXIT_NOT_CONVERGED = int(ExitCode.NOT_CONVERGED)
EXIT_UNREACHABLE = int(ExitCode.UNREACHABLE)
EXIT_IO = int(ExitCode.IO)
EXIT_INTERRUPTED = int(ExitCode.INTERRUPTED)


# Every command: (module, function, the first paragraph of its help). A command's module
# is imported when the command runs (or its --help is asked for); `kinecal --help` lists
# them from this table (tests/cli check it against the commands' own help).
# fmt: off
COMMANDS: dict[str, tuple[str, str, str]] = {
    "calibrate": ("_calibrate", "calibrate",
        "Identify a robot (and sensor) model from measurements DATA.csv."),
    "compare": ("_simulate", "compare",
        "Fit several models on TRAIN and score each on TEST (Tables 5 and 8)."),
    "compensate": ("_compensate", "compensate",
        "Corrected controller angles so the robot reaches TARGETS."),
    "demo": ("_simulate", "demo",
        "Run both of the paper's experiments on the built-in digital twin."),
    "evaluate": ("_calibrate", "evaluate",
        "Accuracy of a calibrated model on measurements DATA.csv (held-out poses)."),
    "export-urdf": ("_export", "export_urdf",
        "Write the calibrated kinematic part of MODEL.yaml as a URDF (or a DH table)."),
    "fk": ("_fk", "fk",
        "Flange pose from controller joint angles J1 ... JN [deg; mm if prismatic]."),
    "import-urdf": ("_fk", "import_urdf",
        "Write a robot YAML (standard DH, mm, deg) for the serial chain of a URDF."),
    "plan": ("_plan", "plan",
        "Choose the poses that determine a calibration model best."),
    "report": ("_report", "report",
        "Draw report.html from a folder written by `kinecal calibrate`."),
    "robots": ("_fk", "robots", "List the built-in robots."),
    "sensor": ("_sensor", "sensor",
        "The 3D rotary laser sensor: stripes, calibration, reconstruction, sphere fits."),
    "simulate": ("_simulate", "simulate",
        "Simulate a paper's experiment on the LR Mate 200iD twin, or any robot (--robot)."),
}
# fmt: on


# Options that name what a command writes; every other option or argument that names an
# existing file is an input, which no output may replace (kinecal._outputs.note_input).
_OUTS = ("out", "out_dir", "out_path", "errors_out", "report_path", "save_candidates")
OUTPUT_PARAMS = frozenset(_OUTS)


def _note_inputs(params: dict[str, object]) -> None:
    """Note the command's input files; refuse at once an output that is one of them
    (before any work, and before "exists; use --force" could suggest --force)."""
    from kinecal._outputs import note_input, refuse_input

    def values(value: object) -> list[str]:
        items = value if isinstance(value, (tuple, list)) else (value,)
        return [v for v in items if isinstance(v, str) and v]

    ctx = click.get_current_context(silent=True)  # the names a user typed or read
    shown = {
        p.name: p.opts[0] if isinstance(p, click.Option) else p.human_readable_name
        for p in (ctx.command.params if ctx is not None else [])
    }
    for name, value in params.items():
        if name not in OUTPUT_PARAMS:
            for v in values(value):
                note_input(v, f"{shown.get(name) or '--' + name.replace('_', '-')} {v}")
    for name in OUTPUT_PARAMS & set(params):
        for v in values(params[name]):
            refuse_input(v)


def _guarded(cmd: click.Command) -> click.Command:
    """``cmd`` (and a group's commands) noting its input files before it runs."""
    if isinstance(cmd, click.Group):
        for sub in cmd.commands.values():
            _guarded(sub)
        return cmd
    callback = cmd.callback
    if callback is None or getattr(callback, "_kinecal_guarded", False):
        return cmd

    def guarded(*args: object, **kwargs: object) -> object:
        _note_inputs(kwargs)
        try:
            return callback(*args, **kwargs)
        except BrokenPipeError as exc:  # not to click: it exits 1 on EPIPE, not 141
            raise OutputClosed() from exc

    guarded._kinecal_guarded = True  # type: ignore[attr-defined]
    cmd.callback = functools.update_wrapper(guarded, callback)
    return cmd


class _LazyGroup(click.Group):
    """A command group that imports a command's module only when that command runs."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted({*COMMANDS, *self.commands})

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        if cmd_name not in self.commands and cmd_name in COMMANDS:
            module, name, _ = COMMANDS[cmd_name]
            cmd = getattr(importlib.import_module(f"kinecal.cli.{module}"), name)
            self.add_command(_guarded(cmd), cmd_name)
        return self.commands.get(cmd_name)

    def format_commands(
        self, ctx: click.Context, formatter: click.HelpFormatter
    ) -> None:
        """The command list of ``--help``, from :data:`COMMANDS` (no module imported):
        the same text click writes from the commands themselves."""
        names = self.list_commands(ctx)
        if not names:
            return
        limit = formatter.width - 6 - max(len(n) for n in names)
        rows = [
            (n, click.Command(n, help=COMMANDS[n][2]).get_short_help_str(limit))
            if n in COMMANDS and n not in self.commands
            else (n, self.commands[n].get_short_help_str(limit))
            for n in names
        ]
        with formatter.section("Commands"):
            formatter.write_dl(rows)


def _print_version(ctx: click.Context, param: click.Parameter, value: bool) -> None:
    """``--version``: the version, and the model code in use (compiled kernel or numpy)
    with the reason."""
    if not value or ctx.resilient_parsing:
        return
    from kinecal.models import kernel_status

    code, why = kernel_status()
    click.echo(f"kinecal {__version__}\nmodel code: {code}: {why}")
    ctx.exit()


@click.group(cls=_LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.option(
    "--version",
    is_flag=True,
    expose_value=False,
    is_eager=True,
    callback=_print_version,
    help="Show the version and the model code in use (compiled kernel or numpy), then exit.",
)
def cli() -> None:
    """kinecal: calibrate robots and robotic vision systems.

    Unified kinematic model plus joint compliance (Ye et al., Sensors 2024). Files use mm
    and degrees; each command's --help gives the formats of its files (in the project:
    docs/files.md; exit codes and messages: docs/errors.md).
    """
    from kinecal import keep_freed_memory
    from kinecal._parallel import single_thread_blas

    keep_freed_memory()  # a command is one run: keep freed arrays for reuse
    single_thread_blas()  # small matrices; the cores go to worker processes instead


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``kinecal`` console script; returns the exit code.

    Runs the command inside an output transaction (result folders are moved into place
    only if it succeeds), turns every exception into one ``Error:`` line and an exit
    code, and shows Python warnings as one ``warning:`` line each. Called in a process
    that has already loaded numpy (too late for the command's one-BLAS-thread
    environment), it runs the command on one BLAS thread and restores the caller's.
    """
    import contextlib

    from kinecal._outputs import begin_transaction, end_transaction
    from kinecal.cli._errors import (
        RESULT_CODES,
        classify,
        debug,
        handled_signals,
        one_line_warnings,
        quiet_broken_pipe,
    )

    tx = begin_transaction()
    failure: BaseException | None = None
    code = 0
    try:
        if "numpy" in sys.modules:
            from kinecal._blas import one_blas_thread

            blas: contextlib.AbstractContextManager[object] = one_blas_thread()
        else:
            blas = contextlib.nullcontext()
        with one_line_warnings(), handled_signals(), blas:
            final = None  # the Error line of results with an error (exit 3), if any
            try:
                rv = cli.main(args=argv, prog_name="kinecal", standalone_mode=False)
                code = rv if isinstance(rv, int) else 0
            except SystemExit as exc:  # sys.exit(EXIT_...) in a command
                code = _exit_code(exc)
                final = getattr(exc, "message", None)
            if code in RESULT_CODES:
                tx.commit()
                if tx.late_signals:  # Ctrl-C while the results were moved into place
                    final = (
                        "interrupted after the results were written (they are complete)"
                    )
                    code = 128 + tx.late_signals[0]
            if final:  # last, after the results are in place
                click.echo(f"Error: {final}", err=True)
    except BaseException as exc:
        failure = exc
    finally:
        end_transaction(tx)  # removes whatever was not committed
    if failure is None:
        return code
    if isinstance(failure, click.exceptions.Abort) and failure.__cause__ is not None:
        failure = failure.__cause__  # Ctrl-C (KeyboardInterrupt) seen by click
    if isinstance(failure, click.exceptions.Exit):
        return int(failure.exit_code)
    no_args = getattr(click.exceptions, "NoArgsIsHelpError", ())
    if isinstance(failure, no_args) and failure.ctx is not None:
        click.echo(failure.ctx.get_help())  # `kinecal` alone: the help, no error
        return 0
    ec, message = classify(failure)
    if ec == ExitCode.BROKEN_PIPE:
        quiet_broken_pipe()
        return int(ec)
    if debug() and ec == ExitCode.INTERNAL:
        import traceback

        traceback.print_exception(failure)
    try:
        click.echo(f"Error: {message}", err=True)
    except OSError:  # stderr itself is gone
        pass
    return int(ec)


def _exit_code(exc: SystemExit) -> int:
    if exc.code is None:
        return 0
    if isinstance(exc.code, int):
        return exc.code
    click.echo(f"Error: {exc.code}", err=True)
    return EXIT_INTERNAL
