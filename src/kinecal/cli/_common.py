"""Helpers shared by the commands: progress display, option parsing, manifests."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

import click

from kinecal.io._manifest import manifest

__all__ = ["manifest"]  # the run manifest, for the commands that import it from here

MODEL_CHOICES = ("kinematic", "ntm", "rfcm", "full", "auto")

# Options several commands share, declared once.
model_file_option = click.option(
    "--model",
    "model_path",
    required=True,
    type=click.Path(dir_okay=False),
    help="A model.yaml written by `kinecal calibrate`.",
)
targets_option = click.option(
    "--targets",
    type=click.Path(dir_okay=False),
    help="Targets file (target, x_mm, y_mm, z_mm) for sensor data.",
)
allow_out_of_limits_option = click.option(
    "--allow-out-of-limits",
    is_flag=True,
    help="Accept joint values more than 1 deg (1 mm) beyond the robot's limits, with a "
    "warning, instead of refusing the file.",
)


def echo_err(line: str) -> None:
    """One line on stderr."""
    click.echo(line, err=True)


def read_data_checked(
    data: str,
    robot: Any,
    targets: str | None,
    allow_out_of_limits: bool,
    skip: tuple[str, ...] = (),
) -> Any:
    """Read a measurement file and print the warnings among the findings of its checks
    (but those of the codes ``skip``): (meas, findings)."""
    from kinecal.io import read_data

    meas, found = read_data(
        data, robot, targets, allow_out_of_limits=allow_out_of_limits
    )
    for d in found:
        if d.severity == "warning" and d.code not in skip:
            click.echo(f"warning   {d.message}", err=True)
    return meas, found


def jobs_option(what: str) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """``--jobs N``: how many workers (``what``: "Worker processes for ...") share the
    command's work; 0 means one per CPU. Results never depend on it."""
    return click.option(
        "--jobs",
        type=click.IntRange(min=0),
        default=0,
        show_default=True,
        help=f"{what} (0: one per CPU; 1: serial). The result does not depend on it.",
    )


class FiniteFloat(click.ParamType):
    """A finite float (no nan, no inf) within optional bounds."""

    name = "float"

    def __init__(
        self,
        low: float | None = None,
        high: float | None = None,
        *,
        low_open: bool = False,
        high_open: bool = False,
    ) -> None:
        self.low, self.high = low, high
        self.low_open, self.high_open = low_open, high_open

    def convert(self, value: Any, param: Any, ctx: Any) -> float:
        import math

        try:
            x = float(value)
        except (TypeError, ValueError):
            self.fail(f"expected a number; got {value!r}", param, ctx)
        if not math.isfinite(x):
            self.fail(f"expected a finite number; got {value!r}", param, ctx)
        lo, hi = self.low, self.high
        if lo is not None and (x < lo or (self.low_open and x == lo)):
            self.fail(
                f"expected {'>' if self.low_open else '>='} {lo:g}; got {x:g}",
                param,
                ctx,
            )
        if hi is not None and (x > hi or (self.high_open and x == hi)):
            self.fail(
                f"expected {'<' if self.high_open else '<='} {hi:g}; got {x:g}",
                param,
                ctx,
            )
        return x


SEED = click.IntRange(min=0)


class Progress:
    """Stage-by-stage progress on stderr, silenced by ``--quiet``.

    Every call prints ``[  12.34s] stage: detail``. A stage that runs long without a new
    line (a large file read, a fold of the cross-validation, the report's figures) gets a
    ``still working`` line every ``heartbeat`` seconds from a background thread, so a
    long run is never silent for longer. The thread stops with the command (or
    :meth:`close`).
    """

    HEARTBEAT_S = 5.0

    def __init__(self, quiet: bool, heartbeat: float = HEARTBEAT_S) -> None:
        self.quiet = quiet
        self.t0 = time.perf_counter()
        self.heartbeat = heartbeat
        self._stage = ""
        self._stage_t0 = self._last = self.t0
        self._lock = threading.Lock()
        self._stop = threading.Event()
        if quiet or heartbeat <= 0:
            return
        threading.Thread(
            target=self._beat, name="kinecal-progress", daemon=True
        ).start()
        ctx = click.get_current_context(silent=True)
        if ctx is not None:
            ctx.call_on_close(self.close)

    def __call__(self, stage: str, detail: str = "") -> None:
        if self.quiet:
            return
        with self._lock:
            now = time.perf_counter()
            if stage != self._stage:
                self._stage, self._stage_t0 = stage, now
            self._last = now
            self._echo(now, f"{stage}" + (f": {detail}" if detail else ""))

    def begin(self, stage: str, detail: str = "") -> None:
        """Enter ``stage`` without a line: one appears only if it lasts longer than the
        heartbeat (a large file being read, say)."""
        with self._lock:
            now = time.perf_counter()
            self._stage = stage + (f": {detail}" if detail else "")
            self._stage_t0 = self._last = now

    def _echo(self, now: float, text: str) -> None:
        try:
            click.echo(f"[{now - self.t0:6.2f}s] {text}", err=True)
        except (OSError, ValueError):  # stderr closed: stay silent
            self._stop.set()

    def _beat(self) -> None:
        tick = min(0.5, self.heartbeat / 4)
        while not self._stop.wait(tick):
            with self._lock:
                now = time.perf_counter()
                if self._stage and now - self._last >= self.heartbeat:
                    self._last = now
                    self._echo(
                        now,
                        f"{self._stage}: still working "
                        f"({now - self._stage_t0:.0f} s in this stage)",
                    )

    def close(self) -> None:
        """Stop the ``still working`` lines."""
        self._stop.set()


def parse_floats(text: str, n: int, name: str) -> list[float]:
    """``"1,2,3"`` -> [1.0, 2.0, 3.0]: ``n`` finite numbers, else a usage error naming
    the option ``name``."""
    import math

    try:
        vals = [float(t) for t in text.split(",")]
    except ValueError:
        vals = []
    if len(vals) != n or not all(math.isfinite(v) for v in vals):
        raise click.BadParameter(
            f"expected {n} comma-separated numbers (finite); got {text!r}",
            param_hint=name,
        )
    return vals


def parse_pose(text: str | None, name: str, sizes: tuple[int, ...] = (6,)) -> Any:
    """``X,Y,Z,R,W,P`` (or, with ``sizes`` (3, 6), also ``X,Y,Z``) [mm, deg; Trans
    Rz(R) Ry(W) Rx(P)] as a (4, 4) transform [m]; None stays None. Else a usage error
    naming the option ``name``."""
    if text is None:
        return None
    import numpy as np

    from kinecal.geometry import euler_transform
    from kinecal.workflows._frames import FAR_FRAME, FAR_TOOL, far_from_origin

    n = len(text.split(",")) if len(sizes) > 1 else sizes[0]
    vals = parse_floats(text, n, name)
    if n not in sizes:
        raise click.BadParameter("expected X,Y,Z or X,Y,Z,R,W,P", param_hint=name)
    vals += [0.0] * (6 - n)
    T = euler_transform([*np.array(vals[:3]) * 1e-3, *np.radians(vals[3:])])
    far = FAR_TOOL if "tool" in name else FAR_FRAME
    if far_from_origin(T, far):  # wrong units (a tool within 5 m, a frame 100 m)
        raise click.BadParameter(
            f"{text!r} puts it {np.linalg.norm(vals[:3]):.4g} mm away; expected mm "
            f"and at most {far:g} m", param_hint=name,
        )  # fmt: skip
    return T


def parse_int_list(
    text: str | None, name: str, n_max: int | None = None
) -> tuple[int, ...] | None:
    """``"1,2,3"`` -> (1, 2, 3); None stays None. Empty text, a number twice or one
    outside 1..``n_max`` is a usage error naming the option ``name``."""
    if text is None:
        return None
    try:
        out = tuple(int(t) for t in text.split(",") if t.strip())
    except ValueError:
        out = ()
    if not out:
        raise click.BadParameter(
            f"expected comma-separated joint numbers; got {text!r}", param_hint=name
        )
    twice = sorted({j for j in out if out.count(j) > 1})
    if twice:
        raise click.BadParameter(
            f"joint {twice[0]} is given twice in {text!r}; expected each joint once",
            param_hint=name,
        )
    if n_max is not None:
        bad = [j for j in out if not 1 <= j <= n_max]
        if bad:
            raise click.BadParameter(
                f"joint {bad[0]} does not exist; expected joint numbers 1 to {n_max}",
                param_hint=name,
            )
    return out


def option_table(
    table: list[Any],
) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """The options of a command from a table, in the order ``--help`` lists them: each
    entry ``(declarations, settings)`` of :func:`click.option`, or an option decorator."""

    def apply(f: Callable[..., Any]) -> Callable[..., Any]:
        for entry in reversed(table):
            f = entry(f) if callable(entry) else click.option(*entry[0], **entry[1])(f)
        return f

    return apply


def refuse_unused(why: dict[str, str]) -> None:
    """Refuse an option given on the command line that this run would not use (issue
    35: it was ignored): ``why`` maps a parameter's name to why ("is for --like")."""
    from click.core import ParameterSource

    ctx = click.get_current_context()
    for p in ctx.command.params:
        if (
            p.name in why
            and ctx.get_parameter_source(p.name) == ParameterSource.COMMANDLINE
        ):
            raise click.UsageError(f"{p.opts[0]} {why[p.name]}; remove it.")


def common_options(f: Callable[..., Any]) -> Callable[..., Any]:
    f = click.option("--quiet", "-q", is_flag=True, help="No progress display.")(f)
    return f
