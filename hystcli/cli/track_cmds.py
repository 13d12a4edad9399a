"""`hyst track`: compensate a reference live and play it on the robot, logging a run CSV.

Parses, reads the reference (a file, or ``-``: stdin line by line), opens the robot, calls
:func:`hystcli.device.tracking.track`, writes the log atomically and renders a summary. Nothing heavy is
imported at the top (``hyst --help`` must stay light).
"""
from __future__ import annotations

import math
import sys
from enum import Enum
from pathlib import Path
from typing import Annotated

import typer

from ..errors import DataError
from ..safety import DEFAULT_MAX_SPEED, DEFAULT_TRAVEL
from .app import (BaudOpt, ColumnsOpt, ModelOpt, OutOpt, QuietOpt, columns_mapping, command, fail, info, load_run,
                  stderr_is_tty, warn)
from .robot_opts import (AllowFastOpt, InverseMaxSpeedOpt, NoReturnOpt, StrictSpeedOpt, TimeoutOpt, TravelLimitOpt,
                         limit_hint, limits, speed_mode)


class LatencyMode(str, Enum):
    delay = "delay"
    ignore = "ignore"


@command("track", "Compensate a reference live and play it on the robot",
         epilog="Example: hyst track sample_data/reference_periodic.csv --port /dev/ttyUSB0 "
                         "--model shifted.json -o run.csv\n\n"
                         "         my_planner | hyst track - --port /dev/ttyUSB0 --model shifted.json "
                         "-o run.csv --detect-shift-first")
def track_cmd(
    reference: Annotated[str, typer.Argument(
        metavar="REFERENCE.csv", help="Desired trajectory CSV with t and r1/r2; '-' reads it from stdin "
                                      "line by line as it comes.", show_default=False)],
    port: Annotated[str, typer.Option("--port", help="Serial port of the robot (name or pyserial URL).",
                                      show_default=False)],
    model_path: ModelOpt,
    output: OutOpt,
    baud: BaudOpt = 115200,
    timeout: TimeoutOpt = 1.0,
    detect_shift_first: Annotated[bool, typer.Option(
        "--detect-shift-first", help="Detect each knob's shift with Algorithm 1 first (as `hyst "
                                     "detect-shift --port`) and compensate with it.")] = False,
    latency: Annotated[LatencyMode, typer.Option(
        "--latency", help="With a latency effect in the model: 'delay' sends exact commands (each "
                          "needs the reference that far ahead: free from a file, late from stdin); "
                          "'ignore' leaves the tracker's delay in.")] = LatencyMode.delay,
    fast: Annotated[bool, typer.Option("--fast", help="Send each command as soon as the previous one "
                                       "is answered instead of at the reference's timing.")] = False,
    travel_limit: TravelLimitOpt = DEFAULT_TRAVEL,
    max_speed: InverseMaxSpeedOpt = DEFAULT_MAX_SPEED,
    allow_fast: AllowFastOpt = False,
    strict_speed: StrictSpeedOpt = False,
    no_return: NoReturnOpt = False,
    columns: ColumnsOpt = None,
    quiet: QuietOpt = False,
) -> None:
    """Compensate REFERENCE live through the model and play each command on the robot as it comes.

    Each sample goes through the streaming compensator (hystcli.Compensator: the model and its
    effects, one sample at a time) and out as a MOVE at the reference's timing; the log
    (t, r, q, c, and y when the robot has a tracker) is written to --output for `hyst evaluate`.
    A reference file is compensated and checked against --travel-limit and --max-speed before the
    first MOVE; one from stdin is checked sample by sample. A step beyond --max-speed (the
    inverse's jump across the dead zone or the backlash) is rate-limited as it comes (the knob
    catches up after it; a warning says how long it lagged), sent at the limit with
    --allow-fast, or refused with --strict-speed. On any fault or Ctrl-C every motor
    stops, the knobs return to where they began (--no-return: they hold), the error says where
    each knob is, and nothing is written.
    """
    from .. import io
    from ..device import Device
    from ..device.robot import Interrupted
    from ..safety import LimitExceeded
    from ..device.tracking import reference_from_lines, reference_from_run, track

    mode = speed_mode(allow_fast, strict_speed)
    inputs = [model_path] + ([] if reference == "-" else [Path(reference)])
    io.check_not_input(output, inputs)
    folder = output.parent if str(output.parent) else Path(".")
    if not folder.is_dir():
        raise DataError(f"{output}: the folder {folder} does not exist")
    if baud <= 0:
        raise typer.BadParameter(f"must be a positive number, got {baud}", param_hint="--baud")
    if columns is not None and reference == "-":
        raise typer.BadParameter("--columns reads a REFERENCE.csv file, not stdin", param_hint="--columns")
    mapping = columns_mapping(columns)
    model = io.load_model(model_path)
    if reference == "-":
        ref = reference_from_lines(sys.stdin, "<stdin>")
    else:
        ref = reference_from_run(load_run(Path(reference), mapping, quiet=quiet))
    lim = limits(travel_limit, max_speed)
    tty = not quiet and stderr_is_tty()

    def progress(i: int) -> None:
        if i == 1:  # the first command reached: the run is under way (what a Ctrl-C now undoes)
            info(f"tracking {reference}: started at the first command; Ctrl-C stops and returns the knobs",
                 quiet)
        elif tty and i % 100 == 0:
            typer.echo(f"\rtracking: {i} samples", err=True, nl=False)
    with Device(port, baud, timeout) as device:
        info(f"connected to {device.info.name} ({device.info.catheter}, knobs "
             f"{','.join(map(str, device.info.knobs))}, tracker {'yes' if device.info.tracker else 'no'})",
             quiet)
        try:
            result = track(device, model, ref, limits=lim, speed=mode, paced=not fast,
                           latency=latency.value, detect_shift_first=detect_shift_first,
                           return_on_abort=not no_return, progress=progress)
        except LimitExceeded as exc:
            raise type(exc)(f"{exc}{limit_hint(exc)}", exc.check) from None
        except Interrupted as exc:
            fail(f"interrupted; {exc}" if str(exc) else "interrupted", 130)
    run = result.run.with_meta(reference=("<stdin>" if reference == "-" else Path(reference).name), port=port)
    io.write_run(output, run, inputs=inputs)
    if tty and len(run) >= 100:
        typer.echo("", err=True)
    for c in result.catch_ups.values():
        warn(c.message)
    parts = [f"{len(run)} samples", f"max lag {run.meta['track_max_lag_s']} s",
             f"compensator {result.step_us:.1f} us/step"]
    for k, o in result.offsets.items():
        parts.append(f"offset{k} {o:+.2f} deg" + (" (detected)" if k in result.shift else ""))
        if f"y{k}" in run:
            err = run[f"y{k}"] - run[f"r{k}"]
            parts.append(f"RMSE{k} {math.sqrt(float((err ** 2).mean())):.2f} deg")
    capped = int(run.meta["track_speed_capped"])
    if capped:
        parts.append(f"{capped} steps sent at the {run.meta['track_speed_limit']} deg/s limit")
    info(f"wrote {output} (" + ", ".join(parts) + ")", quiet)
