"""The typer application, the options every command shares, and the one place errors are rendered.

Command modules (``hystcli/cli/*_cmds.py``) register their commands with :func:`command`, which
wraps each one so that any :class:`~hystcli.errors.HystError` becomes one line ``Error: ...`` on
stderr and exit code 1, and Ctrl-C exit code 130, never a traceback. Usage errors are typer's and
exit with code 2.
"""
from __future__ import annotations

import functools
import json
import sys
from enum import Enum
from pathlib import Path
from typing import Annotated, Any, Callable, List, Optional

import typer

from .. import __version__
from ..errors import HystError

app = typer.Typer(
    name="hyst",
    help="Shape-adaptive hysteresis calibration and evaluation for tendon-driven catheter robots.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
)


def _version(value: bool) -> None:
    if value:
        typer.echo(f"hyst {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: Annotated[bool, typer.Option("--version", callback=_version, is_eager=True,
                                          help="Print the version and exit.")] = False,
) -> None:
    """hyst: identify, detect shift, compensate, evaluate and diagnose catheter hysteresis."""


def fail(message: str, code: int = 1) -> None:
    """Print ``Error: message`` on stderr and exit with ``code``."""
    typer.echo(f"Error: {message}", err=True)
    raise typer.Exit(code)


def command(name: str | None = None, **kwargs: Any) -> Callable:
    """Register a command on :data:`app`, turning hyst errors into ``Error: ...`` and exit 1."""

    def decorator(func: Callable) -> Callable:
        @functools.wraps(func)
        def wrapper(*args: Any, **kw: Any) -> Any:
            try:
                return func(*args, **kw)
            except HystError as exc:
                fail(str(exc).splitlines()[0] if str(exc) else type(exc).__name__)
            except KeyboardInterrupt:
                fail("interrupted", 130)
            except OSError as exc:
                fail(f"{exc.filename or ''}{': ' if exc.filename else ''}{exc.strerror or exc}")

        return app.command(name=name, **kwargs)(wrapper)

    return decorator


# --------------------------------------------------------------------------------------------
# shared options (house rule 7: declared once)
# --------------------------------------------------------------------------------------------
class OutputFormat(str, Enum):
    table = "table"
    json = "json"
    csv = "csv"
    markdown = "markdown"
    latex = "latex"


FormatOpt = Annotated[OutputFormat, typer.Option("--format", "-f", help="Output format on stdout.")]
SeedOpt = Annotated[int, typer.Option("--seed", help="Seed of every random draw (same seed, same bytes).")]
QuietOpt = Annotated[bool, typer.Option("--quiet", "-q", help="Print nothing but errors.")]
OutOpt = Annotated[Path, typer.Option("--output", "-o", help="Output file (written atomically).")]
ModelOpt = Annotated[Path, typer.Option("--model", "-m", help="Model JSON file (from `hyst identify`).")]
PlotOpt = Annotated[Optional[Path], typer.Option("--plot", help="Also draw a figure to this PNG file.")]
PortOpt = Annotated[Optional[str], typer.Option("--port", help="Serial port of the robot (name or pyserial URL).")]
BaudOpt = Annotated[int, typer.Option("--baud", help="Baud rate of the serial port.")]
EffectOpt = Annotated[Optional[List[str]], typer.Option(
    "--effect", help="Unmodelled effect NAME[:param=value,...] (repeatable; 'none' for none; "
                     "default: the catheter's own).")]


def effects_option(values: Optional[List[str]]) -> tuple | None:
    """What an ``--effect`` option asks for: None (not given: the catheter's default effects),
    ``()`` for ``--effect none``, else the parsed effects.

    One rule for ``simulate`` and ``sim-robot``, so both given the same options run the same
    catheter.
    """
    from ..effects import parse_effect

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


def warn(message: str) -> None:
    """A warning on stderr (never on stdout, which may carry machine-readable output)."""
    typer.echo(f"Warning: {message}", err=True)


def info(message: str, quiet: bool = False) -> None:
    """A progress/info line on stderr unless ``quiet``."""
    if not quiet:
        typer.echo(message, err=True)


def stderr_is_tty() -> bool:
    return sys.stderr.isatty()
