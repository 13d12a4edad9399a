"""Commands over the virtual catheter: ``simulate``."""
from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, List, Optional

import typer

from ..names import MOTIONS
from ..sim.calibration import CALIBRATED_NAMES
from .app import (ColumnsOpt, EffectOpt, FormatOpt, KnobsAliasOpt, OutOpt, OutputFormat, QuietOpt, SeedOpt, about,
                  columns_mapping, command, echo_json, echo_table, effects_option, info, load_run, one_of,
                  option_errors, parse_knobs, prints, usage_error)


@command("simulate", "Run the virtual catheter and write the run CSV", epilog=(
    "Example: hyst simulate --catheter ice-a --shape \"alpha=90,theta=0\" --motion periodic "
    "--effect friction:mu=0.3 --seed 1 --trial 2 -o periodic_90.csv\n\n"
    "Replay compensated commands: hyst simulate cmd_shift.csv --catheter ice-a --shape \"alpha=45\" "
    "-o run_shift.csv"))
def simulate_cmd(
    output: OutOpt,
    commands_arg: Annotated[Optional[Path], typer.Argument(
        metavar="COMMANDS.csv", help="Run CSV whose q<k> (and r<k>) to play, e.g. the output of "
                                       "`hyst compensate` (default: a generated --motion).",
        show_default=False)] = None,
    catheter: Annotated[str, typer.Option(help=f"Virtual catheter ({', '.join(CALIBRATED_NAMES)}).")] = "ice-a",
    shape: Annotated[str, typer.Option(
        help="Shaft shape: 'straight' or segments 'alpha=DEG,theta=DEG' separated by ';'.")] = "straight",
    motion: Annotated[str, typer.Option(
        help=f"Generated motion ({', '.join(MOTIONS)}); ignored with --commands.")] = "periodic",
    commands_opt: Annotated[Optional[Path], typer.Option("--commands", hidden=True)] = None,  # the old spelling
    controller: Annotated[Optional[str], typer.Option(
        help="Controller name to record (default: none, or the --commands file's controller).")] = None,
    effect: EffectOpt = None,
    knob: Annotated[Optional[List[str]], typer.Option(
        "--knob", metavar="K", help="Knobs to drive: 1, 2 or 1,2 (repeatable; default 1; 1,2 for "
                                    "nonperiodic; the commands file's).", show_default=False)] = None,
    knobs_alias: KnobsAliasOpt = None,
    rotation: Annotated[float, typer.Option(help="Bulk rotation of the catheter body (deg).")] = 0.0,
    trial: Annotated[int, typer.Option(min=0, help="Trial number (recorded; varies the noise).")] = 1,
    no_noise: Annotated[bool, typer.Option("--no-noise", help="Exact model output: no sensor noise, no filter.")] = False,
    columns: ColumnsOpt = None,
    fmt: FormatOpt = OutputFormat.table,
    seed: SeedOpt = 0,
    quiet: QuietOpt = False,
) -> None:
    """Run the virtual catheter and write the run CSV (t, q<k>, y<k>, c<k>, r<k>) with metadata.

    A generated periodic or non-periodic motion is played with controller none (q = r); with a
    COMMANDS.csv the knob commands come from the file. Effects: friction, rate, coupling,
    deadzone, creep, latency, saturation, contact (docs/design.md section 8).
    """
    from .. import io
    from ..sim.calibration import calibrated_catheter
    from ..core.params import Shape
    from ..sim.twin import simulate_motion

    # every option is checked before the commands file is read or the twin runs
    commands = one_of(commands_arg, commands_opt, "COMMANDS.csv", "--commands")
    if catheter not in CALIBRATED_NAMES:
        usage_error(f"unknown virtual catheter {catheter!r} (known: {', '.join(CALIBRATED_NAMES)})", "--catheter")
    if commands is None and motion not in MOTIONS:
        usage_error(f"unknown motion {motion!r} (known: {', '.join(MOTIONS)}, or give a COMMANDS.csv)", "--motion")
    if commands is None and controller not in (None, "none"):
        usage_error(f"controller {controller!r} needs the commands it produced (a COMMANDS.csv); a generated "
                    "motion runs with controller none", "--controller")
    if not math.isfinite(rotation):
        usage_error(f"must be a finite number of degrees, got {rotation}", "--rotation")
    with option_errors("--shape"):
        shp = Shape.parse(shape)
    with option_errors("--effect"):
        effs = effects_option(effect)
    knob_sel = parse_knobs(one_of(knob, knobs_alias, "--knob", "--knobs"))
    mapping = columns_mapping(columns)
    inputs = [commands] if commands is not None else []
    io.check_not_input(output, inputs)
    with about(commands):
        cmd_run = load_run(commands, mapping, quiet=quiet) if commands is not None else None
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
        from ..report.table import Table

        echo_table(Table(("key", "value"), ("key", "value"), tuple((k, str(v)) for k, v in summary.items())), fmt)
    info(f"wrote {output}: {len(run)} samples, knobs {','.join(map(str, run.knobs('q')))}, "
         f"{run.meta['motion']} / {run.meta['controller']} / {run.meta['shape']}, "
         f"effects {run.meta.get('effects', 'none')}", quiet)
