"""Commands over the virtual catheter: ``simulate``."""
from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Optional

import typer

from ..calibration import CALIBRATED_NAMES
from ..names import MOTIONS
from .app import (EffectOpt, FormatOpt, OutOpt, OutputFormat, QuietOpt, SeedOpt, about, command, echo_json,
                  echo_table, effects_option, info, option_errors, prints, usage_error)


def parse_knobs(text: str | None, option: str = "--knobs") -> tuple[int, ...] | None:
    """``1``, ``2``, ``1,2`` -> the knobs (each once, in order); anything else is a usage error."""
    if text is None:
        return None
    out: list[int] = []
    for part in text.split(","):
        part = part.strip()
        if part not in ("1", "2"):
            usage_error(f"{text!r}: expected 1, 2 or 1,2", option)
        if int(part) not in out:
            out.append(int(part))
    return tuple(out)


@command("simulate", epilog=(
    "Example: hyst simulate --catheter ice-a --shape \"alpha=90,theta=0\" --motion periodic "
    "--effect friction:mu=0.3 --seed 1 --trial 2 -o periodic_90.csv\n\n"
    "Replay compensated commands: hyst simulate --catheter ice-a --shape \"alpha=45\" "
    "--commands cmd_shift.csv -o run_shift.csv"))
def simulate_cmd(
    output: OutOpt,
    catheter: Annotated[str, typer.Option(help=f"Virtual catheter ({', '.join(CALIBRATED_NAMES)}).")] = "ice-a",
    shape: Annotated[str, typer.Option(
        help="Shaft shape: 'straight' or segments 'alpha=DEG,theta=DEG' separated by ';'.")] = "straight",
    motion: Annotated[str, typer.Option(
        help=f"Generated motion ({', '.join(MOTIONS)}); ignored with --commands.")] = "periodic",
    commands: Annotated[Optional[Path], typer.Option(
        metavar="RUN.csv", help="Run CSV whose q<k> (and r<k>) to play, e.g. the output of `hyst compensate`.")] = None,
    controller: Annotated[Optional[str], typer.Option(
        help="Controller name to record (default: none, or the --commands file's controller).")] = None,
    effect: EffectOpt = None,
    knobs: Annotated[Optional[str], typer.Option(
        help="Knobs to drive: 1, 2 or 1,2 (default 1; 1,2 for nonperiodic; the --commands file's).")] = None,
    rotation: Annotated[float, typer.Option(help="Bulk rotation of the catheter body (deg).")] = 0.0,
    trial: Annotated[int, typer.Option(min=0, help="Trial number (recorded; varies the noise).")] = 1,
    no_noise: Annotated[bool, typer.Option("--no-noise", help="Exact model output: no sensor noise, no filter.")] = False,
    fmt: FormatOpt = OutputFormat.table,
    seed: SeedOpt = 0,
    quiet: QuietOpt = False,
) -> None:
    """Run the virtual catheter and write the run CSV (t, q<k>, y<k>, c<k>, r<k>) with metadata.

    A generated periodic or non-periodic motion is played with controller none (q = r); with
    --commands the knob commands come from the file. Effects: friction, rate, coupling,
    deadzone, creep, latency, saturation, contact (docs/design.md section 8).
    """
    from .. import io
    from ..calibration import calibrated_catheter
    from ..model import Shape
    from ..twin import simulate_motion

    # every option is checked before the commands file is read or the twin runs
    if catheter not in CALIBRATED_NAMES:
        usage_error(f"unknown virtual catheter {catheter!r} (known: {', '.join(CALIBRATED_NAMES)})", "--catheter")
    if commands is None and motion not in MOTIONS:
        usage_error(f"unknown motion {motion!r} (known: {', '.join(MOTIONS)}, or give --commands)", "--motion")
    if commands is None and controller not in (None, "none"):
        usage_error(f"controller {controller!r} needs the commands it produced (--commands); a generated "
                    "motion runs with controller none", "--controller")
    if not math.isfinite(rotation):
        usage_error(f"must be a finite number of degrees, got {rotation}", "--rotation")
    with option_errors("--shape"):
        shp = Shape.parse(shape)
    with option_errors("--effect"):
        effs = effects_option(effect)
    knob_sel = parse_knobs(knobs)
    inputs = [commands] if commands is not None else []
    io.check_not_input(output, inputs)
    with about(commands):
        cmd_run = io.read_run(commands, require=("t",)) if commands is not None else None
        # the user-facing catheters are the calibrated ones, the same the sample data was recorded on
        run = simulate_motion(calibrated_catheter(catheter), shp, motion, knobs=knob_sel, commands=cmd_run,
                              controller=controller, effects=effs, seed=seed, trial=trial, rotation=rotation,
                              noise=not no_noise)
        io.write_run(output, run, inputs=inputs)
    summary = {"output": str(output), "samples": len(run), "knobs": run.knobs("q"), **dict(run.meta)}
    if not prints(fmt, quiet):
        return
    if fmt == OutputFormat.json:
        echo_json(summary)
    elif fmt != OutputFormat.table:
        from ..metrics import Table

        echo_table(Table(("key", "value"), ("key", "value"), tuple((k, str(v)) for k, v in summary.items())), fmt)
    info(f"wrote {output}: {len(run)} samples, knobs {','.join(map(str, run.knobs('q')))}, "
         f"{run.meta['motion']} / {run.meta['controller']} / {run.meta['shape']}, "
         f"effects {run.meta.get('effects', 'none')}", quiet)
