"""The typer application, the options every command shares, and the one place errors are rendered.

Command modules (``hystcli/cli/*_cmds.py``) register their commands with :func:`command`, which
wraps each one so that any :class:`~hystcli.errors.HystError` becomes one line ``Error: ...`` on
stderr and exit code 1, and Ctrl-C exit code 130, never a traceback. Usage errors exit with code 2:
typer's own, and those a command finds after parsing (:func:`usage_error`,
:func:`option_errors`, :func:`parameter_errors`). Long work reports through :func:`progress`.

This module is imported by ``hyst --help``: it imports typer and nothing heavy (rich only when a
progress bar is drawn on a terminal).
"""
from __future__ import annotations

import contextlib
import functools
import json
import sys
import time
from enum import Enum
from pathlib import Path
from typing import Annotated, Any, Callable, Iterator, List, NoReturn, Optional

import typer
from typer.core import TyperArgument, TyperCommand, TyperGroup

from .. import __version__
from ..errors import HystError, ParameterError

HELP_PANELS: dict[str, tuple[str, ...]] = {
    "Calibrate": ("identify", "check", "import"),
    "On the robot": ("detect-shift", "compensate", "track", "play", "sweep", "status", "home", "jog",
                     "sim-robot"),
    "Evaluate": ("evaluate", "diagnose", "predict", "batch", "report"),
    "Simulate": ("simulate", "demo"),
    "Data and models": ("show", "diff", "rotate-shift"),
}
"""The panels of ``hyst --help`` in workflow order, each with its commands in order."""

SUMMARY_WIDTH = 60
"""Longest one-line summary of a command: with the longest command name it fits 80 columns."""


class _Group(TyperGroup):
    """The ``hyst`` group: commands listed in :data:`HELP_PANELS`' panels and order, each with its
    one-line summary whole (never cut with "...").

    Plain text rather than typer's rich panels: ``hyst --help`` must not import rich (start-up
    time, ``tests/test_cli_startup.py``). Each command also carries its panel as typer's
    ``rich_help_panel``, so a rich help would group them the same way.
    """

    def format_commands(self, ctx: Any, formatter: Any) -> None:
        shown = {name: cmd for name, cmd in self.commands.items() if not cmd.hidden}
        panels = [(title, [n for n in names if n in shown]) for title, names in HELP_PANELS.items()]
        listed = {n for _, names in panels for n in names}
        panels.append(("Other commands", [n for n in shown if n not in listed]))
        width = max(map(len, shown), default=0)  # one column for the summaries across the panels
        for title, names in panels:
            if names:
                with formatter.section(title):
                    formatter.write_dl([(n.ljust(width), shown[n].get_short_help_str(limit=10 ** 6))
                                        for n in names])


app = typer.Typer(
    name="hyst",
    cls=_Group,
    help="Shape-adaptive hysteresis calibration and evaluation for tendon-driven catheter robots.",
    no_args_is_help=True,
    add_completion=True,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
    epilog="Threads: hyst runs BLAS, OpenMP and numba on 1 thread (its algebra is small; more threads "
           "only wait for each other on a busy machine). HYST_THREADS=N gives them N; an "
           "OMP_NUM_THREADS, OPENBLAS_NUM_THREADS or NUMBA_NUM_THREADS you set is kept.",
    context_settings={"help_option_names": ["--help", "-h"]},
)


def _version(value: bool) -> None:
    if value:
        typer.echo(f"hyst {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: Annotated[bool, typer.Option("--version", "-V", callback=_version, is_eager=True,
                                          help="Print the version and exit.")] = False,
) -> None:
    """hyst: identify, detect shift, compensate, evaluate and diagnose catheter hysteresis."""


def first_line(exc: BaseException) -> str:
    """The message of an error as one line (its first), or its type's name when it has none."""
    text = str(exc)
    return text.splitlines()[0] if text.strip() else type(exc).__name__


def fail(message: str, code: int = 1) -> NoReturn:
    """Print ``Error: message`` on stderr and exit with ``code``."""
    typer.echo(f"Error: {message}", err=True)
    raise typer.Exit(code)


def usage_error(message: str, param: str | None = None) -> NoReturn:
    """A usage error found after parsing (a bad option value, options that conflict): exit 2.

    Rendered by typer like its own usage errors (usage line, then one line ``Error: ...``).

    Parameters
    ----------
    message : str
        What is wrong, e.g. ``"must be a positive number, got -1"``.
    param : str, optional
        The option(s) at fault as the user typed them, e.g. ``"--shape"``.
    """
    raise typer.BadParameter(message, param_hint=param)


@contextlib.contextmanager
def option_errors(param: str) -> Iterator[None]:
    """Turn a :class:`HystError` raised while reading an option's value into a usage error.

    The core's parsers (shapes, effects, key=value pairs) raise data errors; on the command line
    a bad option value is the user's typing, not bad data, so it exits 2.
    """
    try:
        yield
    except HystError as exc:
        usage_error(first_line(exc), param)


@contextlib.contextmanager
def parameter_errors(options: dict[str, str]) -> Iterator[None]:
    """Turn a library's :class:`~hystcli.errors.ParameterError` into a usage error (exit 2) against
    the option the user typed for the parameter.

    Parameters
    ----------
    options : dict of str to str
        Library parameter -> its option, e.g. ``{"mean": "--mean-window"}``. A parameter not listed
        is no option's (the command passed it itself): its error stays a hyst error (exit 1).
    """
    try:
        yield
    except ParameterError as exc:
        if exc.parameter not in options:
            raise
        usage_error(exc.reason, options[exc.parameter])


@contextlib.contextmanager
def about(*paths: Optional[Path]) -> Iterator[None]:
    """Name the input file in a hyst error whose message names none of ``paths``.

    Errors found deep in the core (an identification that fails, a filter that refuses a sample
    rate) do not know which file the data came from; the command does.
    """
    try:
        yield
    except HystError as exc:
        names = [str(p) for p in paths if p is not None]
        message = first_line(exc)
        if names and not any(name in message for name in names):
            raise type(exc)(f"{names[0]}: {message}") from None
        raise


def distinct_outputs(**paths: Optional[Path]) -> None:
    """Usage error (exit 2) when two output options name the same file (one would overwrite the
    other, e.g. ``-o X --plot X`` would write the report into the figure)."""
    seen: dict[Path, str] = {}
    for option, path in paths.items():
        if path is None:
            continue
        key = Path(path).resolve()
        if key in seen:
            usage_error(f"{seen[key]} and {option} name the same file {path}", f"{seen[key]} / {option}")
        seen[key] = option


def distinct_inputs(paths: List[Path], what: str = "RUN.csv") -> None:
    """Usage error (exit 2) when one input file is given twice: its run would count twice in every
    mean and std (refused rather than dropped, since a repeated name is usually a typo for another)."""
    seen: dict[Path, Path] = {}
    for p in paths:
        key = Path(p).resolve()
        if key in seen:
            usage_error(f"{seen[key]} and {p} are the same file; give each run once", what)
        seen[key] = p


def prints(fmt: Any, quiet: bool) -> bool:
    """Whether a command prints its result on stdout: always for a machine format asked for with
    ``--format`` (json, csv, ...), the table unless ``--quiet``."""
    return not quiet or getattr(fmt, "value", fmt) != "table"


class _Argument(TyperArgument):
    def display_type_rich(self, ctx: Any) -> str | None:
        # an argument with a metavar (RUN.csv) needs no Python type beside it (<list[Path]>)
        return None if self.metavar is not None else super().display_type_rich(ctx)


class _Command(TyperCommand):
    """Typer's command with classic help: ``hyst evaluate [OPTIONS] RUN.csv...`` in the usage line
    (typer writes a required argument as ``{RUN.csv}``), arguments in capitals, and no Python
    type (``<list[Path]>``) beside an argument's metavar."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        for param in self.params:
            if type(param) is TyperArgument:
                param.__class__ = _Argument  # the same object, one method changed
                if param.metavar is None:  # click's convention: an argument in capitals
                    param.metavar = (param.name or "ARG").upper()

    def collect_usage_pieces(self, ctx: Any) -> list[str]:
        return [piece[1:].replace("}", "", 1) if piece.startswith("{") else piece
                for piece in super().collect_usage_pieces(ctx)]


def command(name: str, summary: str, **kwargs: Any) -> Callable:
    """Register a command on :data:`app`, turning hyst errors into ``Error: ...`` and exit 1.

    Parameters
    ----------
    name : str
        The command's name; its panel in ``hyst --help`` is the one :data:`HELP_PANELS` lists it in.
    summary : str
        Its one line in ``hyst --help`` (at most :data:`SUMMARY_WIDTH` characters, no final
        period).
    **kwargs
        Passed to typer (``help``, ``epilog``, ...).
    """
    if len(summary) > SUMMARY_WIDTH:
        raise ValueError(f"{name}: summary of {len(summary)} characters, at most {SUMMARY_WIDTH}")
    panel = next((title for title, names in HELP_PANELS.items() if name in names), None)

    def decorator(func: Callable) -> Callable:
        return app.command(name=name, cls=_Command, short_help=summary, rich_help_panel=panel,
                           **kwargs)(guarded(func))

    return decorator


def guarded(func: Callable) -> Callable:
    """``func`` with hyst errors turned into ``Error: ...`` and exit 1, Ctrl-C into exit 130 (what
    :func:`command` registers; a command group of its own, ``hyst batch``, wraps with it too)."""
    @functools.wraps(func)
    def wrapper(*args: Any, **kw: Any) -> Any:
        try:
            return func(*args, **kw)
        except HystError as exc:
            fail(first_line(exc))
        except KeyboardInterrupt:
            fail("interrupted", 130)
        except OSError as exc:
            fail(f"{exc.filename or ''}{': ' if exc.filename else ''}{exc.strerror or exc}")

    return wrapper


# --------------------------------------------------------------------------------------------
# shared options (house rule 7: declared once)
# --------------------------------------------------------------------------------------------
class CurrentSign(str, Enum):
    """How a drive reports its motor current (:data:`hystcli.settings.CURRENT_SIGNS`)."""

    auto = "auto"
    signed = "signed"
    magnitude = "magnitude"


class OutputFormat(str, Enum):
    table = "table"
    json = "json"
    csv = "csv"
    markdown = "markdown"
    latex = "latex"


FormatOpt = Annotated[OutputFormat, typer.Option("--format", "-f", help="Output format on stdout.")]
SeedOpt = Annotated[int, typer.Option("--seed", help="Seed of every random draw (same seed, same bytes).")]
QuietOpt = Annotated[bool, typer.Option(
    "--quiet", "-q", help="Print nothing but errors (output asked for with --format json/csv/... still "
                          "goes to stdout).")]
OutOpt = Annotated[Path, typer.Option("--output", "-o", help="Output file (written atomically).")]
ModelOpt = Annotated[Path, typer.Option("--model", "-m", help="Model JSON file (from `hyst identify`).")]
PlotOpt = Annotated[Optional[Path], typer.Option("--plot", help="Also draw a figure to this PNG file.")]
PortOpt = Annotated[Optional[str], typer.Option("--port", help="Serial port of the robot (name or pyserial URL).")]
BaudOpt = Annotated[int, typer.Option("--baud", help="Baud rate of the serial port.")]
EffectOpt = Annotated[Optional[List[str]], typer.Option(
    "--effect", help="Unmodelled effect NAME[:param=value,...] (repeatable; 'none' for none; "
                     "default: the catheter's own).")]


ColumnsOpt = Annotated[Optional[str], typer.Option(
    "--columns", metavar="t=NAME[:UNIT],q1=NAME[:UNIT],...",
    help="Read your own CSV: which of its columns (by header name, or number from 1) is t, q1, y1, "
         "c1, ..., each with an optional unit (ms, rad, A, ...) or scale. Any separator; # and % "
         "lines are comments. The syntax of `hyst import --map`.", show_default=False)]
KnobsAliasOpt = Annotated[Optional[List[str]], typer.Option("--knobs", hidden=True)]  # the old spelling


def one_of(value: Any, alias: Any, name: str, alias_name: str) -> Any:
    """The value given under an option's name or under its hidden old alias (usage error: both)."""
    given = [v for v in (value, alias) if v is not None and v != [] and v != ()]
    if len(given) == 2:
        usage_error(f"give {name} once (not also {alias_name}, its old spelling)", name)
    return given[0] if given else None


def parse_knobs(values: Optional[List[str]], option: str = "--knob", most: int = 2) -> tuple[int, ...] | None:
    """``--knob`` values (``1``, ``2``, ``1,2``, repeatable) -> the knobs in order; None when not given.
    Anything else, a knob given twice included (likely a typo for another), is a usage error."""
    if not values:
        return None
    out: list[int] = []
    for part in (p.strip() for v in values for p in str(v).split(",")):
        if not (part.isdigit() and 1 <= int(part) <= most):
            allowed = "1, 2 or 1,2" if most == 2 else f"knob numbers 1 to {most}, comma-separated"
            usage_error(f"{','.join(values)!r}: expected {allowed}", option)
        if int(part) in out:
            usage_error(f"{','.join(values)!r}: knob {part} is given twice", option)
        out.append(int(part))
    return tuple(out)


def only_formats(fmt: "OutputFormat", command_name: str, *allowed: "OutputFormat") -> None:
    """Usage error when a command's output is no table for ``--format`` csv/markdown/latex."""
    if fmt not in allowed:
        usage_error(f"{command_name} prints {', '.join(a.value for a in allowed)}, not {fmt.value}", "--format")


def columns_mapping(spec: Optional[str]) -> Any:
    """The ``--columns`` mapping (:func:`hystcli.io.importer.columns_mapping`), or None; a malformed
    spec is a usage error."""
    if spec is None:
        return None
    from ..io import importer

    with option_errors("--columns"):
        return importer.columns_mapping(spec)


def load_run(path: Path, columns: Any = None, require: tuple[str, ...] = ("t",), quiet: bool = False) -> Any:
    """Read one run CSV, or a user's own CSV through a ``--columns`` mapping (from
    :func:`columns_mapping`), warning on stderr about what the mapping's reading found; a big file
    shows its reading on a terminal (:func:`reading`)."""
    from .. import io

    with reading(path, quiet) as progress:
        if columns is None:
            return io.read_run(path, require=require, progress=progress)
        from ..io import importer

        imported = importer.read_mapped(path, columns, require=require, progress=progress)
    if not quiet:
        for w in imported.report.warnings:
            warn(f"{path}: {w}")
    return imported.run


def effects_option(values: Optional[List[str]]) -> tuple | None:
    """What an ``--effect`` option asks for: None (not given: the catheter's default effects),
    ``()`` for ``--effect none``, else the parsed effects.

    One rule for ``simulate`` and ``sim-robot``, so both given the same options run the same
    catheter.
    """
    from ..core.effects import parse_effect

    if not values:
        return None
    if [e.strip().lower() for e in values] == ["none"]:
        return ()
    return tuple(parse_effect(e) for e in values)


def echo_json(data: Any) -> None:
    """Plain JSON on stdout (machine-readable output)."""
    typer.echo(json.dumps(data, indent=2, allow_nan=False, default=_json_default))


def _json_default(obj: Any) -> Any:
    try:
        import numpy as np

        if isinstance(obj, np.generic):
            return obj.item()
        if isinstance(obj, np.ndarray):
            return obj.tolist()
    except ImportError:  # pragma: no cover
        pass
    return str(obj)


def echo_table(table: Any, fmt: "OutputFormat | str", digits: int = 2) -> None:
    """A :class:`hystcli.report.table.Table` on stdout in any ``--format``."""
    from ..report.table import format_table

    typer.echo(format_table(table, getattr(fmt, "value", fmt), digits), nl=False)


def warn(message: str) -> None:
    """A warning on stderr (never on stdout, which may carry machine-readable output)."""
    typer.echo(f"Warning: {message}", err=True)


def info(message: str, quiet: bool = False) -> None:
    """A progress/info line on stderr unless ``quiet``."""
    if not quiet:
        typer.echo(message, err=True)


def stderr_is_tty() -> bool:
    """Whether stderr is a terminal (rich progress bars) rather than a pipe or file (plain lines)."""
    return sys.stderr.isatty()


ProgressFn = Callable[..., None]
"""``update(message, done=None, total=None)``: what :func:`progress` yields."""


@contextlib.contextmanager
def progress(quiet: bool = False, interval: float = 1.0) -> Iterator[ProgressFn]:
    """Progress of long work on stderr: a rich bar on a terminal, plain lines otherwise.

    Yields ``update(message, done=None, total=None)``, to call after each step. On a terminal
    the bar appears at the first update (so it never shows an unknown total) and disappears at
    the end. Piped or redirected, each update is a line ``[done/total] message``, at most one
    per ``interval`` seconds besides the first and the last step, so a log shows the work moving
    without one line per step. With ``quiet`` nothing is shown.

    Examples
    --------
    >>> items = ["sweep.csv", "replay.csv"]
    >>> with progress(quiet=True) as update:
    ...     for i, item in enumerate(items, 1):
    ...         update(f"read {item}", i, len(items))
    """
    if quiet:
        yield lambda message, done=None, total=None: None
        return
    if stderr_is_tty():
        with _rich_progress() as update:
            yield update
        return
    last = [-float("inf")]

    def update(message: str, done: int | None = None, total: int | None = None) -> None:
        now = time.monotonic()
        edge = done is not None and (done <= 1 or (total is not None and done >= total))
        if done is None or edge or now - last[0] >= interval:
            last[0] = now
            count = "" if done is None else f"[{done}/{total}] " if total else f"[{done}] "
            typer.echo(f"{count}{message}", err=True)

    yield update


@contextlib.contextmanager
def reading(path: Path, quiet: bool = False) -> Iterator[Optional[Callable[[int, int], None]]]:
    """The ``progress`` of a big file's reading (:func:`hystcli.io.read_run`,
    :func:`hystcli.io.importer.convert`): a rich bar on stderr, in MiB, only when stderr is a
    terminal (a log gets no lines of it); None otherwise."""
    if quiet or not stderr_is_tty():
        yield None
        return
    with _rich_progress() as update:
        yield lambda done, total: update(f"reading {Path(path).name}", done >> 20, total >> 20)


@contextlib.contextmanager
def _rich_progress() -> Iterator[ProgressFn]:
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    bar = Progress(TextColumn("{task.description:<44}"), BarColumn(),
                   TextColumn("{task.fields[count]}"), TimeElapsedColumn(),
                   console=Console(stderr=True), transient=True)
    task = None

    def update(message: str, done: int | None = None, total: int | None = None) -> None:
        nonlocal task
        count = "" if done is None else f"{done}/{total}" if total else str(done)
        if task is None:
            bar.start()
            task = bar.add_task(message[:44], total=total, completed=done or 0, count=count)
        bar.update(task, description=message[:44], completed=done or 0, total=total, count=count)

    try:
        yield update
    finally:
        bar.stop()
