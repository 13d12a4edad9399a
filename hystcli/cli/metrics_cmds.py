"""`hyst evaluate`: PTPE and RMSE of runs, pooled over trials, with improvement rates.

Parses the options, reads the runs, calls :func:`hystcli.report.metrics.evaluate_runs`, and prints (or
writes) the text :func:`hystcli.report.metrics.render` returns; ``--plot`` draws the paper's Figs. 6/7.
"""
from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from ..report import metrics  # numpy only: the grouping fields and plot formats name the options
from ..report.figures import PLOT_FORMATS, save_figure
from .app import (ColumnsOpt, FormatOpt, OutputFormat, PlotOpt, QuietOpt, columns_mapping, command, distinct_inputs,
                  distinct_outputs, info, load_run, option_errors, prints, usage_error, warn)


def _group_by(value: str) -> str:
    with option_errors("--group-by"):
        metrics.parse_group_by(value)
    return value


@command(
    "evaluate", "PTPE and RMSE of runs, with improvement rates",
    help=(
        "PTPE and RMSE of y - r per run and knob, pooled over trials as (mean, std), with "
        "improvement rates against the controllers `none` and `comp` (the paper's Tables I and II).\n\n"
        "Runs are grouped by their metadata (controller, shape, motion by default; trials, "
        "catheters and knobs are pooled); std is the sample std (ddof=1); improvement % = "
        "(base - new) / base * 100 on the group means. Missing metadata is grouped as 'unknown'. "
        "The same file given twice is an error: it would count one run twice in the means.\n\n"
        "Example:\n\n"
        "    hyst evaluate run_none.csv run_only.csv run_shift.csv --format latex -o table1.tex --plot fig6.png"
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
    columns: ColumnsOpt = None,
    quiet: QuietOpt = False,
) -> None:
    from ..io.check import require_shape
    from ..io import all_or_none, check_not_input

    if plot is not None:
        suffix = plot.suffix.lower().lstrip(".")
        if suffix not in PLOT_FORMATS:
            usage_error(f"{plot} must end in .png, .pdf or .svg", "--plot")
    distinct_outputs(**{"--output": output, "--plot": plot})
    for target in (output, plot):
        if target is not None:
            check_not_input(target, runs)
    distinct_inputs(runs)
    mapping = columns_mapping(columns)

    loaded = [require_shape(load_run(p, mapping, quiet=quiet)) for p in runs]
    evaluation = metrics.evaluate_runs(loaded, group_by=metrics.parse_group_by(group_by))
    text = metrics.render(evaluation, fmt.value, per_run=per_run)
    figure = evaluation.plot(loaded) if plot is not None else None

    if not quiet:
        for w in evaluation.warnings:
            warn(w)
    # Everything is computed before the first write, and the files are renamed into place together:
    # a failure leaves no output file behind.
    with all_or_none() as pending:
        if output is not None:
            pending.write_text(output, text, inputs=runs)
        if figure is not None:
            save_figure(figure, pending.path(plot, inputs=runs))
    if output is None and prints(fmt, quiet):
        typer.echo(text, nl=False)
    for path in (output, plot):
        if path is not None:
            info(f"wrote {path}", quiet)

