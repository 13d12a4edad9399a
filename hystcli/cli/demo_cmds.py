"""`hyst demo`: the paper's whole experiment on the virtual catheters, Tables I and II beside the paper's.

Parses the options, calls :func:`hystcli.experiment.run_protocol`, prints what
:func:`hystcli.experiment.render` returns and writes :func:`hystcli.experiment.write_outputs`.
"""
from __future__ import annotations

import time
from enum import Enum
from pathlib import Path
from typing import Annotated

import typer

from .. import experiment
from ..errors import DataError
from .app import QuietOpt, SeedOpt, command, info, stderr_is_tty


class DemoFormat(str, Enum):
    table = "table"
    json = "json"
    markdown = "markdown"


@command(
    "demo",
    help=(
        "Run the paper's whole experiment (Kim & Mansi, section III) on the calibrated virtual "
        "catheters and print Tables I and II beside the paper's values.\n\n"
        "Per catheter: identify the straight-shaft model on the sweep (current; omega = 1.45), "
        "detect the shift of each shape with Algorithm 1 on a replay, compensate the references "
        "(comp ignores the shift, comp+shift uses the detected one), run each controller (none, "
        "comp, comp+shift) on the twin for every trial, evaluate PTPE and RMSE. Beyond the paper: "
        "diagnose each catheter's Compensation+Shift runs (hyst diagnose), compensate with the "
        "augmented model and set the result beside the paper's (--no-diagnose leaves it out). Reads the "
        "recordings from --data (sample_data/, made by scripts/make_sample_data.py) and writes "
        "results.json, tables.md and figures like the paper's Figs. 6 and 7 into --out.\n\n"
        "Example:\n\n"
        "    hyst demo --out demo_out --format markdown"
    ),
)
def demo(
    data: Annotated[Path, typer.Option("--data", help="Data directory with the recordings "
                                       "(relative to the current directory).")] = Path("sample_data"),
    out: Annotated[Path, typer.Option("--out", help="Folder for results.json, tables.md and the "
                                      "figures.")] = Path("demo_out"),
    trials: Annotated[int, typer.Option("--trials", min=1, max=20, help="Trials per run (different "
                                        "sensor noise each).")] = 3,
    seed: SeedOpt = 0,
    fmt: Annotated[DemoFormat, typer.Option("--format", "-f", help="Output format on stdout.")] = DemoFormat.table,
    simulate: Annotated[bool, typer.Option("--simulate", help="Record the sweeps and replays from the "
                                           "twin instead of reading --data.")] = False,
    no_figures: Annotated[bool, typer.Option("--no-figures", help="Write no figures.")] = False,
    no_diagnose: Annotated[bool, typer.Option("--no-diagnose", help="Run only the paper's three "
                                              "controllers (no diagnosis, no comp+shift+diag).")] = False,
    quiet: QuietOpt = False,
) -> None:
    data_dir = None if simulate else data
    if data_dir is not None and not data_dir.is_dir():
        raise DataError(f"{data_dir}: no such data directory (run `hyst demo` from the repository root, "
                        f"where sample_data/ is, give --data DIR, or use --simulate)")
    if out.exists() and not out.is_dir():
        raise DataError(f"{out}: exists and is not a directory (--out needs a folder)")

    started = time.perf_counter()
    bar = None
    progress = None
    if not quiet and stderr_is_tty():
        from rich.console import Console
        from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

        bar = Progress(TextColumn("{task.description:<44}"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
                       TimeElapsedColumn(), console=Console(stderr=True), transient=True)
        task = bar.add_task("reading the recordings", total=None)

        def progress(what: str, done: int, total: int) -> None:
            bar.update(task, description=what[:44], completed=done, total=total)

        bar.start()
    try:
        result = experiment.run_protocol(trials=trials, seed=seed, data_dir=data_dir, progress=progress,
                                           diagnose=not no_diagnose)
    finally:
        if bar is not None:
            bar.stop()
    text = experiment.render(result, fmt.value)
    written = experiment.write_outputs(result, out, with_figures=not no_figures)
    elapsed = time.perf_counter() - started
    typer.echo(text, nl=False)
    info(f"wrote {', '.join(str(p) for p in written)}", quiet)
    info(f"demo took {elapsed:.1f} s ({len(result.runs)} runs)", quiet)
