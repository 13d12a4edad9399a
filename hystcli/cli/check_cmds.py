"""`hyst check`: every problem of run CSVs at once (:mod:`hystcli.io.check` finds them; here they are
rendered, one line each, and the exit code says whether any is an error)."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated, List

import typer

from .app import (ColumnsOpt, CurrentSign, FormatOpt, OutputFormat, columns_mapping, command, distinct_inputs,
                  echo_json, echo_table)


@command(
    "check", "List every problem of run CSVs before you use them",
    help=(
        "List every problem of each RUN.csv at once, one line each: what would make a command refuse "
        "it (missing columns, text or NaN cells, values like 1e308, time that does not increase, "
        "another separator), and what would make the data unfit for its job (time stamps with "
        "sample-rate jitter, a tip that never moves, a knob that never reverses, a current that "
        "never goes below its no-load level, a sweep that never passes a dead-zone edge).\n\n"
        "Exit 1 when any file has an error, 0 with warnings only. With --columns your own CSV is "
        "checked as the other commands would read it with the same --columns.\n\n"
        "Examples:\n\n"
        "    hyst check sample_data/ice-a/sweep_knob1.csv\n\n"
        "    hyst check my_sweep.tsv --columns t=time_s,q1=knob_deg,y1=tip_deg,c1=current_mA"
    ),
)
def check_cmd(
    runs: Annotated[List[Path], typer.Argument(metavar="RUN.csv", help="Run CSVs to check.", show_default=False)],
    columns: ColumnsOpt = None,
    current_sign: Annotated[CurrentSign, typer.Option(
        "--current-sign", help="How the drive reports its motor current, as you would tell identify: auto (a "
                               "magnitude found is a warning), signed (it is an error) or magnitude (not looked "
                               "for).")
    ] = CurrentSign.auto,
    fmt: FormatOpt = OutputFormat.table,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="Print the errors only (not the warnings, "
                                                              "not the files without a problem).")] = False,
) -> None:
    from ..io.check import check_file

    distinct_inputs(runs)
    mapping = columns_mapping(columns)
    reports = [check_file(p, mapping, current_sign.value) for p in runs]
    if fmt == OutputFormat.json:
        echo_json({"ok": all(r.ok for r in reports), "files": [r.to_dict() for r in reports]})
    elif fmt == OutputFormat.table:
        for line in render_lines(reports, errors_only=quiet):
            typer.echo(line)
    else:
        echo_table(problem_table(reports), fmt)
    if not all(r.ok for r in reports):
        raise typer.Exit(1)


def _summary(report) -> str:  # noqa: ANN001 - check.CheckReport
    bits = [f"{report.rows} rows"]
    if report.rate is not None:
        bits.append(f"{report.rate:.4g} Hz" + (f" (jitter {100 * report.jitter:.1f} %)" if report.jitter is not None else ""))
    if report.columns:
        bits.append("columns " + ", ".join(report.columns))
    return "; ".join(bits)


def render_lines(reports, errors_only: bool = False) -> list[str]:  # noqa: ANN001 - sequence of check.CheckReport
    """``FILE: LEVEL: WHERE: message`` per problem (the form compilers use, so editors can jump to
    it), a summary line per file without problems, and a last line counting them; with
    ``errors_only`` (``--quiet``) the error lines alone."""
    if errors_only:
        return [f"{r.source}: {p.level}: {p.where}: {p.message}" for r in reports for p in r.errors]
    lines = []
    for r in reports:
        if not r.problems:
            lines.append(f"{r.source}: ok: {_summary(r)}")
        for p in r.problems:
            lines.append(f"{r.source}: {p.level}: {p.where}: {p.message}")
    errors = sum(len(r.errors) for r in reports)
    warnings = sum(len(r.problems) for r in reports) - errors
    lines.append(f"{errors} error(s), {warnings} warning(s) in {len(reports)} file(s)")
    return lines


def problem_table(reports):  # noqa: ANN001, ANN202 - sequence of check.CheckReport -> report.table.Table
    """Every problem as a row, for ``--format`` csv/markdown/latex."""
    from ..report.table import Table

    rows = tuple((r.source, p.level, p.where, p.message) for r in reports for p in r.problems)
    return Table(("file", "level", "where", "message"), ("file", "level", "where", "message"), rows)
