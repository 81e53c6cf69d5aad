"""The ``kinecal`` command. Parsing only: every command loads files and calls the API.

Heavy modules (numpy, scipy, OpenCV) are imported inside the commands, and a command's
module only when that command runs (:class:`_LazyGroup`), so ``kinecal --help`` starts
fast. Exit codes: 0 success, 1 internal error, 2 bad input or
usage, 3 calibration failed (no convergence), 4 some targets unreachable.
"""

from __future__ import annotations

import importlib
import sys

import click

from kinecal._version import __version__

EXIT_BAD_INPUT = 2
EXIT_NOT_CONVERGED = 3
EXIT_UNREACHABLE = 4


# Every command: (module, function, the first paragraph of its help). A command's module
# is imported when the command runs (or its --help is asked for); `kinecal --help` lists
# them from this table (tests/cli check it against the commands' own help).
COMMANDS: dict[str, tuple[str, str, str]] = {
    "calibrate": (
        "_calibrate",
        "calibrate",
        "Identify a robot (and sensor) model from measurements DATA.csv.",
    ),
    "compare": (
        "_simulate",
        "compare",
        "Fit several models on TRAIN and score each on TEST (Tables 5 and 8).",
    ),
    "compensate": (
        "_compensate",
        "compensate",
        "Corrected controller angles so the robot reaches TARGETS.",
    ),
    "demo": (
        "_simulate",
        "demo",
        "Run both of the paper's experiments on the built-in digital twin.",
    ),
    "evaluate": (
        "_calibrate",
        "evaluate",
        "Accuracy of a calibrated model on measurements DATA.csv (held-out poses).",
    ),
    "export-urdf": (
        "_export",
        "export_urdf",
        "Write the calibrated kinematic part of MODEL.yaml as a URDF (or a DH table).",
    ),
    "fk": (
        "_fk",
        "fk",
        "Flange pose from controller joint angles J1 ... JN [deg; mm if prismatic].",
    ),
    "import-urdf": (
        "_fk",
        "import_urdf",
        "Write a robot YAML (standard DH, mm, deg) for the serial chain of a URDF.",
    ),
    "plan": (
        "_plan",
        "plan",
        "Choose the poses that determine a calibration model best.",
    ),
    "report": (
        "_report",
        "report",
        "Draw report.html from a folder written by `kinecal calibrate`.",
    ),
    "robots": ("_fk", "robots", "List the built-in robots."),
    "sensor": (
        "_sensor",
        "sensor",
        "The 3D rotary laser sensor: stripes, calibration, reconstruction, sphere fits.",
    ),
    "simulate": (
        "_simulate",
        "simulate",
        "Simulate one of the paper's experiments on the digital twin (LR Mate 200iD).",
    ),
}


class _LazyGroup(click.Group):
    """A command group that imports a command's module only when that command runs."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted({*COMMANDS, *self.commands})

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        if cmd_name not in self.commands and cmd_name in COMMANDS:
            module, name, _ = COMMANDS[cmd_name]
            cmd = getattr(importlib.import_module(f"kinecal.cli.{module}"), name)
            self.add_command(cmd, cmd_name)
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


@click.group(cls=_LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="kinecal")
def cli() -> None:
    """kinecal: calibrate robots and robotic vision systems.

    Unified kinematic model plus joint compliance (Ye et al., Sensors 2024). Files use mm
    and degrees; see DESIGN §11 or each command's --help for the formats.
    """
    from kinecal import keep_freed_memory
    from kinecal._parallel import single_thread_blas

    keep_freed_memory()  # a command is one run: keep freed arrays for reuse
    single_thread_blas()  # small matrices; the cores go to worker processes instead


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``kinecal`` console script; returns the exit code."""
    from kinecal.errors import CalibError

    try:
        rv = cli.main(args=argv, prog_name="kinecal", standalone_mode=False)
    except click.exceptions.Exit as exc:
        return int(exc.exit_code)
    except click.ClickException as exc:
        exc.show()
        return int(exc.exit_code)
    except click.exceptions.Abort:
        click.echo("Aborted.", err=True)
        return 1
    except CalibError as exc:
        click.echo(f"kinecal: error: {exc}", err=True)
        return EXIT_BAD_INPUT
    except (
        FileExistsError,
        FileNotFoundError,
        IsADirectoryError,
        PermissionError,
    ) as exc:
        click.echo(f"kinecal: error: {exc}", err=True)
        return EXIT_BAD_INPUT
    return rv if isinstance(rv, int) else 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
