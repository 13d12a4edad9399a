"""`hyst detect-shift`: Algorithm 1 on a recorded replay (``REPLAY.csv``) or a live robot (``--port``).

Parses the options, calls :func:`hystcli.shift.run_detect_shift` on the replay or on a
:class:`hystcli.device.LiveProbes` (which checks the knobs and every setting before anything
moves), renders the offsets, and writes the shifted model (:func:`hystcli.shift.apply_shift`)
atomically. Nothing is written unless every knob succeeded.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Any, Optional

import typer

from .. import device
from .. import shift as shift_mod
from ..errors import DataError
from ..io import all_or_none, check_not_input, dumps_model, file_sha256, load_model
from .app import (BaudOpt, ColumnsOpt, FormatOpt, OutputFormat, OutOpt, ModelOpt, PlotOpt, PortOpt, QuietOpt,
                  columns_mapping, command, echo_json, echo_table, info, load_run, one_of, parameter_errors,
                  parse_knobs, usage_error)
from .robot_opts import TimeoutOpt

# the library's parameter -> the option that sets it (a bad value is a usage error against it)
_OPTIONS = {"step": "--step", "max_travel": "--max-travel", "max_steps": "--max-steps", "eps_upper": "--eps-upper",
            "false_alarm": "--false-alarm", "current_ceiling": "--current-ceiling", "speed": "--speed",
            "dwell": "--dwell", "mean": "--mean-window", "baud": "--baud", "timeout": "--timeout"}


def _notes(r: shift_mod.ShiftResult) -> list[str]:
    """What the search did beyond the plain walk to an edge, in words."""
    notes = []
    if r.start_outside:
        notes.append("started with the tendon ahead taut: turned and crossed the dead zone")
    if r.contacts:
        notes.append("contact at " + ", ".join(f"{c:.1f}" for c in r.contacts) + " deg, reversed")
    if r.reference == "model":
        notes.append("offset from the model's edge (the model keeps no reading of the current)")
    return notes


_NOTE = ("deg; offset = where the current takes the tendon up now minus where the straight-shaft sweep's "
         "current did; its 95 % interval beside it; shifted model written to {output}")


def _text(results: dict[int, shift_mod.ShiftResult], output: Path) -> str:
    """The offsets found as aligned text, each knob's notes below the table."""
    import textwrap

    from ..report.table import TEXT_WIDTH

    head = (f"{'knob':>4}  {'offset':>8}  {'interval':>17}  {'d~_neg':>8}  {'d~_pos':>8}  {'edge':>11}  "
            f"{'travel':>7}  {'steps':>5}")
    lines = [head, "-" * len(head)]
    notes = []
    for k, r in results.items():
        edge = f"{r.edge} {r.edge_found_at:+.2f}"
        interval = f"[{r.offset_lo:+.2f}, {r.offset_hi:+.2f}]"
        lines.append(f"{k:>4}  {r.offset:>+8.2f}  {interval:>17}  {r.d_neg:>+8.2f}  {r.d_pos:>+8.2f}  {edge:>11}  "
                     f"{r.travel:>7.1f}  {r.steps:>5}")
        notes += [f"knob {k}: {n}" for n in _notes(r)]
    return "\n".join(lines + [""] + [w for n in notes + [_NOTE.format(output=output)]
                                    for w in textwrap.wrap(n, TEXT_WIDTH, break_on_hyphens=False)])


def _table(results: dict[int, shift_mod.ShiftResult], output: Path) -> Any:
    """The offsets found as a :class:`hystcli.report.table.Table` (``--format`` csv/markdown/latex)."""
    from ..report.table import Table

    rows = tuple((k, r.offset, r.offset_lo, r.offset_hi, r.d_neg, r.d_pos, r.edge, r.edge_found_at, r.travel,
                  r.steps, "; ".join(_notes(r))) for k, r in results.items())
    return Table(("knob", "offset", "offset_lo", "offset_hi", "d_neg", "d_pos", "edge", "edge_at", "travel", "steps",
                  "notes"),
                 ("knob", "offset", "low", "high", "d~_neg", "d~_pos", "edge", "at", "travel", "steps", "notes"),
                 rows, (_NOTE.format(output=output),))


@command(
    "detect-shift", "Detect each knob's shift after the shaft bends",
    help=(
        "Detect the hysteresis shift of each knob after the shaft took a new shape, by the "
        "motor current (Algorithm 1 of the paper), and write the shifted model.\n\n"
        "The knob is stepped by --step degrees and the current read at each step. The readings "
        "since the last turn are read as a broken line; the edge is where the tendon ahead is "
        "taken up: a change point declared at a stated false-alarm rate (--false-alarm), at the "
        "current where the identification sweep's current took that tendon up. The offset is "
        "that edge minus the sweep's, with its interval; wider than +-0.5 deg, the command "
        "refuses (exit 1) rather than move the robot by it. A start with the tendon ahead "
        "taut turns and crosses the dead zone; a slope beyond eps_upper is a contact: "
        "reverse. The search never exceeds --max-steps / --max-travel and returns the knob "
        "to where it began.\n\n"
        "A REPLAY.csv (a run recorded under the new shape: a slow sweep from the rest position) is "
        "walked as if the knob were stepped; --port runs it live on the robot.\n\n"
        "Example:\n\n"
        "    hyst detect-shift sample_data/ice-a/replay_alpha90_knob1.csv --model model.json "
        "-o shifted.json --plot fig5b.png"
    ),
)
def detect_shift_cmd(
    model_path: ModelOpt,
    output: OutOpt,
    replay_arg: Annotated[Optional[Path], typer.Argument(
        metavar="REPLAY.csv", help="Run CSV recorded under the new shape (columns t, q<k>, c<k>); or --port.",
        show_default=False)] = None,
    replay_opt: Annotated[Optional[Path], typer.Option("--replay", hidden=True)] = None,  # the old spelling
    port: PortOpt = None,
    baud: BaudOpt = 115200,
    timeout: TimeoutOpt = 1.0,
    knob: Annotated[Optional[list[str]], typer.Option(
        "--knob", metavar="K", help="Search these knobs only: 1, 2 or 1,2 (default: every knob of the model "
                                    "the source has).", show_default=False)] = None,
    eps_upper: Annotated[Optional[float], typer.Option(
        "--eps-upper", help="Contact slope, mA/deg (default: four times the sweep's loaded slope).")] = None,
    false_alarm: Annotated[float, typer.Option(
        "--false-alarm", help="Probability that a search along a stretch with no edge declares one.")] = 1e-3,
    step: Annotated[float, typer.Option("--step", help="Unit step u, deg.")] = 0.5,
    max_steps: Annotated[Optional[int], typer.Option(
        "--max-steps", help="Step limit (default: max-travel / step).")] = None,
    max_travel: Annotated[Optional[float], typer.Option(
        "--max-travel", help="Knob travel limit of the search, deg (default: the reach of the model's "
                             "identification sweep, max |q|; 25 without one).")] = None,
    current_ceiling: Annotated[float, typer.Option(
        "--current-ceiling", help="Live: a motor current beyond +-this (mA) is a contact: stop, return "
                                  "the knob, exit 1.")] = 2000.0,
    speed: Annotated[float, typer.Option(
        "--speed", help="Live: knob speed between steps, deg/s. A device with the dwell/mean features "
                        "holds at each step and reports the mean current after the lag has settled "
                        "(docs/protocol.md); without them, slow steps keep that lag small.")] = 5.0,
    dwell: Annotated[float, typer.Option(
        "--dwell", help="Live: hold at each step before reading, s (0: no hold). Used when the "
                        "device offers the dwell feature.")] = device.DEFAULT_DWELL,
    mean_window: Annotated[float, typer.Option(
        "--mean-window", help="Live: average the current over the last S seconds of the hold "
                              "(0: one sample; a window longer than the hold also averages the "
                              "move). Used when the device offers the mean feature.")] = device.DEFAULT_MEAN,
    plot: PlotOpt = None,
    columns: ColumnsOpt = None,
    fmt: FormatOpt = OutputFormat.table,
    quiet: QuietOpt = False,
) -> None:
    replay = one_of(replay_arg, replay_opt, "REPLAY.csv", "--replay")
    if (replay is None) == (port is None):
        usage_error("give exactly one of REPLAY.csv or --port PORT", "REPLAY.csv / --port")
    if columns is not None and replay is None:
        usage_error("--columns reads a REPLAY.csv; a live search (--port) reads no file", "--columns")
    with parameter_errors(_OPTIONS):
        request = shift_mod.ShiftRequest(step=step, max_steps=max_steps, max_travel=max_travel, eps_upper=eps_upper,
                                         false_alarm=false_alarm)
        # the live settings are checked with a replay too (a typo is refused either way); the baud
        # rate only where a port is opened
        live = device.LiveProbes(port, baud if port is not None else 115200, timeout, current_ceiling, speed,
                                 dwell, mean_window)
    inputs = [model_path] + ([replay] if replay is not None else [])
    _check_outputs(output, plot, inputs)  # refuse a bad output before anything moves
    mapping = columns_mapping(columns)
    knobs = parse_knobs(knob)
    model = load_model(model_path)
    run = None if replay is None else load_run(replay, mapping, quiet=quiet)

    def progress(k: int, s: Any, w: float) -> None:  # live progress on stderr
        slope = "" if math.isnan(w) else f", slope {w:.2f} mA/deg"
        info(f"knob {k}: q {s.q:+.2f} deg, current {s.current:.1f} mA{slope}")

    results = shift_mod.run_detect_shift(
        model, run, live=None if port is None else live, knobs=knobs, request=request, name=replay,
        started=lambda k: info(f"knob {k}: searching the dead-zone edge ...", quiet),
        progress=progress if port is not None and not quiet else None)

    shifted = shift_mod.apply_shift(model, results, source=f"live:{port}" if replay is None else replay.name,
                                    sha256=None if replay is None else file_sha256(replay))
    # the model and the figure together or neither
    with all_or_none() as pending:
        if plot is not None:
            background = None if run is None else {k: (run[f"q{k}"], run[f"c{k}"]) for k in results}
            shift_mod.plot_shift(list(results.values()), pending.path(plot, inputs=inputs), model=model,
                                 background=background)
        pending.write_text(output, dumps_model(shifted), inputs=inputs)
    if fmt == OutputFormat.json:
        echo_json({"knobs": {str(k): r.to_dict() for k, r in results.items()},
                   "output": str(output), "plot": None if plot is None else str(plot)})
    elif fmt != OutputFormat.table:
        echo_table(_table(results, output), fmt)
    elif not quiet:
        typer.echo(_text(results, output))


def _check_outputs(output: Path, plot: Path | None, inputs: list[Path]) -> None:
    """Refuse an output that would overwrite an input or the other output, or whose folder is missing."""
    check_not_input(output, inputs)
    if plot is not None:
        check_not_input(plot, inputs)
        if plot.resolve() == output.resolve():
            usage_error("the plot and the output must be different files", "--plot")
    for target in [output] + ([plot] if plot is not None else []):
        folder = target.parent if str(target.parent) else Path(".")
        if not folder.is_dir():
            raise DataError(f"{target}: the folder {folder} does not exist")
