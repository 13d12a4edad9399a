"""`hyst demo`: the paper's whole experiment on the virtual catheters, Tables I and II beside the paper's.

Parses the options, calls :func:`hystcli.sim.experiment.run_protocol`, prints what
:func:`hystcli.sim.render.render` returns and writes :func:`hystcli.sim.render.write_outputs`.
"""
from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated, Optional

import typer

from ..errors import DataError
from .app import (FormatOpt, OutputFormat, QuietOpt, SeedOpt, command, info, only_formats, progress, prints,
                  usage_error)


@command(
    "demo", "The paper's whole experiment on the virtual catheters",
    help=(
        "Run the paper's whole experiment (Kim & Mansi, section III) on the calibrated virtual "
        "catheters and print Tables I and II beside the paper's values.\n\n"
        "Per catheter: identify the straight-shaft model on the sweep (current; omega = 1.45), "
        "detect the shift of each shape with Algorithm 1 on a replay, compensate the references "
        "(comp ignores the shift, comp+shift uses the detected one), run each controller (none, "
        "comp, comp+shift) on the twin for every trial, evaluate PTPE and RMSE. Beyond the paper: "
        "diagnose each catheter's Compensation+Shift runs (hyst diagnose), compensate with the "
        "augmented model and set the result beside the paper's (--no-diagnose leaves it out).\n\n"
        "Reads the recordings from --data, by default sample_data/ when the current folder has "
        "one (the repository root); elsewhere (an installed hyst) it records the same data from "
        "the twin first, byte for byte what scripts/make_sample_data.py wrote into sample_data/. "
        "Writes results.json, tables.md and figures like the paper's Figs. 6 and 7 into --out.\n\n"
        "Example:\n\n"
        "    hyst demo --out demo_out --format markdown"
    ),
)
def demo(
    data: Annotated[Optional[Path], typer.Option(
        "--data", show_default=False, help="Data directory with the recordings (default: sample_data/ "
                                           "when the current folder has one, else recorded from the twin).")] = None,
    out: Annotated[Path, typer.Option("--out", help="Folder for results.json, tables.md and the "
                                      "figures.")] = Path("demo_out"),
    trials: Annotated[int, typer.Option("--trials", min=1, max=20, help="Trials per run (different "
                                        "sensor noise each).")] = 3,
    seed: SeedOpt = 0,
    fmt: FormatOpt = OutputFormat.table,
    simulate: Annotated[bool, typer.Option("--simulate", help="Record the sweeps and replays from the "
                                           "twin instead of reading --data.")] = False,
    no_figures: Annotated[bool, typer.Option("--no-figures", help="Write no figures.")] = False,
    no_diagnose: Annotated[bool, typer.Option("--no-diagnose", help="Run only the paper's three "
                                              "controllers (no diagnosis, no comp+shift+diag).")] = False,
    quiet: QuietOpt = False,
) -> None:
    from ..sim import experiment, render, scenarios

    only_formats(fmt, "demo", OutputFormat.table, OutputFormat.json, OutputFormat.markdown)
    if simulate and data is not None:
        usage_error("give --data DIR or --simulate, not both", "--data / --simulate")
    if data is not None and not data.is_dir():
        raise DataError(f"{data}: no such data directory (give a folder made by scripts/make_sample_data.py, "
                        "or leave --data out to use sample_data/ here or the twin)")
    if out.exists() and not out.is_dir():
        raise DataError(f"{out}: exists and is not a directory (--out needs a folder)")
    data_dir = None if simulate else (data if data is not None else scenarios.default_data_dir())
    # without --simulate the recordings are the sample data's, wherever they come from
    recording_seed = None if simulate else scenarios.SAMPLE_DATA_SEED
    if data_dir is None and not simulate:
        info("no sample_data/ in this folder: recording the same data from the twin (seeded, "
             "as scripts/make_sample_data.py made it)", quiet)

    started = time.perf_counter()
    with progress(quiet) as update:
        result = experiment.run_protocol(trials=trials, seed=seed, data_dir=data_dir, progress=update,
                                         diagnose=not no_diagnose, recording_seed=recording_seed)
    text = render.render(result, fmt.value)
    written = render.write_outputs(result, out, with_figures=not no_figures)
    elapsed = time.perf_counter() - started
    if prints(fmt, quiet):
        typer.echo(text, nl=False)
    info(f"wrote {', '.join(str(p) for p in written)}", quiet)
    # the same count as the progress's last [done/total]: every step, each kind named
    steps = {"identifications": len(result.models), "shift detections": len(result.shifts),
             "runs": len(result.runs), "diagnoses": len(result.diagnoses)}
    info(f"demo took {elapsed:.1f} s ({sum(steps.values())} steps: "
         + ", ".join(f"{n} {what}" for what, n in steps.items() if n) + ")", quiet)
