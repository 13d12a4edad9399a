"""`hyst evaluate`: PTPE and RMSE of runs, pooled over trials, with improvement rates.

Parses the options, reads the runs, calls :func:`hystcli.metrics.evaluate_runs`, and prints (or
writes) the text :func:`hystcli.metrics.render` returns; ``--plot`` draws the paper's Figs. 6/7.
"""
from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from .. import metrics
from ..errors import DataError
from ..io import atomic_write, atomic_write_text, check_not_input, read_run
from .app import FormatOpt, OutputFormat, PlotOpt, QuietOpt, command, info, warn


def _group_by(value: str) -> str:
    try:
        metrics.parse_group_by(value)
    except DataError as exc:
        raise typer.BadParameter(str(exc)) from None
    return value


@command(
    "evaluate",
    help=(
        "PTPE and RMSE of y - r per run and knob, pooled over trials as (mean, std), with "
        "improvement rates against the controllers `none` and `comp` (the paper's Tables I and II).\n\n"
        "Runs are grouped by their metadata (controller, shape, motion by default; trials, "
        "catheters and knobs are pooled); std is the sample std (ddof=1); improvement % = "
        "(base - new) / base * 100 on the group means. Missing metadata is grouped as 'unknown'.\n\n"
        "Example:\n\n"
        "    hyst evaluate runs/*.csv --format latex -o table1.tex --plot fig6.png"
    ),
)
def evaluate(
    runs: Annotated[list[Path], typer.Argument(
        metavar="RUN.csv", help="Run CSVs with y<k> and r<k> for at least one knob.")],
    fmt: FormatOpt = OutputFormat.table,
    group_by: Annotated[str, typer.Option(
        "--group-by", "-g", callback=_group_by,
        help=f"Comma-separated grouping fields among {', '.join(metrics.GROUP_FIELDS)} "
             "('' pools everything).")] = ",".join(metrics.DEFAULT_GROUP_BY),
    per_run: Annotated[bool, typer.Option("--per-run", help="One row per run and knob instead of per group "
                                                             "(JSON always holds both).")] = False,
    plot: PlotOpt = None,
    output: Annotated[Optional[Path], typer.Option(
        "--output", "-o", help="Write the result to this file (atomically) instead of stdout.")] = None,
    quiet: QuietOpt = False,
) -> None:
    if plot is not None:
        suffix = plot.suffix.lower().lstrip(".")
        if suffix not in metrics.PLOT_FORMATS:
            raise typer.BadParameter(f"{plot} must end in .png, .pdf or .svg", param_hint="--plot")
    if output is not None and plot is not None and output.resolve() == plot.resolve():
        raise typer.BadParameter("the output and the plot must be different files", param_hint="--plot")
    for target in (output, plot):
        if target is not None:
            check_not_input(target, runs)

    loaded = [read_run(p) for p in runs]
    evaluation = metrics.evaluate_runs(loaded, group_by=metrics.parse_group_by(group_by))
    text = metrics.render(evaluation, fmt.value, per_run=per_run)
    png = metrics.evaluation_figure(loaded, plot.suffix.lower().lstrip(".")) if plot is not None else None

    if not quiet:
        for w in evaluation.warnings:
            warn(w)
    # Everything is computed before the first write: a failure leaves no output file behind.
    if output is not None:
        atomic_write_text(output, text, inputs=runs)
        info(f"wrote {output}", quiet)
    else:
        typer.echo(text, nl=False)
    if png is not None:
        atomic_write(plot, lambda f: f.write(png), inputs=runs)
        info(f"wrote {plot}", quiet)
