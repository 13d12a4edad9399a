"""``hyst batch identify|evaluate|detect-shift|diagnose`` and ``hyst report``: many runs, one table.

Parses the options, calls :func:`hystcli.batch.core.plan` and :func:`hystcli.batch.core.run_batch`
(or :func:`hystcli.batch.report.report`), and renders what they return. Nothing heavy is
imported until a command runs (``hyst --help`` stays fast).
"""
from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any, Callable, List, Optional

import typer

from .app import (CurrentSign, FormatOpt, OutputFormat, QuietOpt, SeedOpt, _Command, app, command, echo_json, fail,
                  guarded, info, only_formats, progress, usage_error, warn)

batch_app = typer.Typer(
    name="batch", no_args_is_help=True, rich_markup_mode=None, pretty_exceptions_enable=False,
    help="Run identify, evaluate, detect-shift or diagnose over many runs: one results table (Parquet or "
         "CSV), one row per run, on local processes or a dask cluster (--scheduler). A bad run is a row, "
         "never the end of the batch; a rerun skips what is done. Needs pip install 'hystcli[batch]'.",
    context_settings={"help_option_names": ["--help", "-h"]})
app.add_typer(batch_app, name="batch", short_help="Run a command over many runs into one table",
              rich_help_panel="Evaluate")


def _sub(name: str, summary: str, **kwargs: Any) -> Callable:
    """Register a batch subcommand; hyst errors become ``Error: ...`` and exit 1 (as :func:`command`)."""

    def decorator(func: Callable) -> Callable:
        return batch_app.command(name=name, cls=_Command, short_help=summary, **kwargs)(guarded(func))

    return decorator


RunsArg = Annotated[Optional[List[str]], typer.Argument(
    metavar="RUN.csv|GLOB", help="Run files or globs ('runs/**/*.csv', quoted so hyst expands it).",
    show_default=False)]
ManifestOpt = Annotated[Optional[Path], typer.Option(
    "--manifest", help="CSV with a 'run' column (and optional 'model', 'session', and any column to keep); "
                       "paths relative to it.")]
TableOpt = Annotated[Path, typer.Option(
    "--output", "-o", help="Results table: .parquet (default) or .csv; parts are kept in OUTPUT.parts/ "
                           "and the seconds per task in OUTPUT-stem.timing.*")]
SchedulerOpt = Annotated[Optional[str], typer.Option(
    "--scheduler", help="A dask.distributed scheduler (tcp://host:8786 or dask://host:8786); default: "
                        "local processes.")]
JobsOpt = Annotated[int, typer.Option("--jobs", "-j", min=1, help="Local worker processes.")]
RetriesOpt = Annotated[int, typer.Option("--retries", min=0, help="Times a task is sent again after its "
                                                                  "worker died.")]
StrictOpt = Annotated[bool, typer.Option("--strict", help="Exit 1 when any run failed (default: exit 0 "
                                                          "and count them).")]
ModelReqOpt = Annotated[Optional[Path], typer.Option(
    "--model", "-m", help="Model JSON of every run (or a 'model' column in the manifest).")]


def _run(command_name: str, runs: Optional[List[str]], manifest: Optional[Path], output: Path,
         settings: dict, model: Optional[Path], scheduler: Optional[str], jobs: int, retries: int,
         strict: bool, fmt: OutputFormat, quiet: bool, session_by: Optional[str] = None) -> None:
    from ..batch import require

    only_formats(fmt, f"batch {command_name}", OutputFormat.table, OutputFormat.json)
    if not runs and manifest is None:
        usage_error("give RUN.csv files, globs or --manifest", "RUN.csv|GLOB")
    require("pyarrow", *(("distributed",) if scheduler else ()))
    from ..batch import core

    pl = core.plan(command_name, runs or [], manifest, model, settings, session_by=session_by)
    with progress(quiet) as update:
        res = core.run_batch(pl, output, scheduler=scheduler, jobs=jobs, retries=retries,
                             progress=lambda message, done, total: update(message, done, total))
    if res.interrupted:
        rerun = f" ({res.retried} rerun after a worker died)" if res.retried else ""
        fail(f"interrupted: {res.computed + res.skipped} of {res.tasks} task(s) are kept in {res.parts}{rerun}; "
             "the same command resumes", 130)
    counts: dict[str, int] = {}
    for _, status, _ in res.failures:
        counts[status] = counts.get(status, 0) + 1
    if fmt == OutputFormat.json:
        echo_json({"table": str(res.table), "timing": str(res.timing), "parts": str(res.parts), "runs": res.runs,
                   "tasks": res.tasks, "computed": res.computed, "skipped": res.skipped, "failed": res.failed,
                   "failed_by_status": counts, "retried": res.retried, "seconds": res.seconds,
                   "engine": res.engine,
                   "failures": [{"path": p, "status": s, "reason": r} for p, s, r in res.failures]})
    elif not quiet:
        for path, status, reason in res.failures[:10]:
            warn(f"{status}: {reason if path in reason else f'{path}: {reason}'}")
        if len(res.failures) > 10:
            warn(f"... and {len(res.failures) - 10} more failed run(s): the table's status and reason columns")
        by = ", ".join(f"{k} {v}" for k, v in sorted(counts.items()))
        typer.echo(f"wrote {res.table}: {res.runs} run(s), {res.failed} failed{f' ({by})' if by else ''}; "
                   f"{res.tasks} task(s): {res.computed} computed, {res.skipped} already done"
                   + (f", {res.retried} rerun after a worker died" if res.retried else "")
                   + f"; {res.seconds:.1f} s on {res.engine}")
    if strict and res.failed:
        fail(f"{res.failed} of {res.runs} run(s) failed (--strict)")


@_sub("identify", "Identify every sweep's model into one table",
      epilog="Example: hyst batch identify 'sweeps/**/*.csv' -o models.parquet --jobs 2")
def batch_identify(
    runs: RunsArg = None, manifest: ManifestOpt = None, output: TableOpt = Path("identify.parquet"),
    omega: Annotated[Optional[float], typer.Option(help="Slope omega when a run has no tip angle y.")] = None,
    current_only: Annotated[bool, typer.Option("--current-only", help="Ignore the tip angle.")] = False,
    current_sign: Annotated[CurrentSign, typer.Option("--current-sign", help="signed, magnitude or auto.")
                            ] = CurrentSign.auto,
    level: Annotated[float, typer.Option("--level", help="Confidence level of the intervals.")] = 0.95,
    scheduler: SchedulerOpt = None, jobs: JobsOpt = 2, retries: RetriesOpt = 2, strict: StrictOpt = False,
    fmt: FormatOpt = OutputFormat.table, quiet: QuietOpt = False,
) -> None:
    """Identify each run's knob models (hyst identify): per knob every parameter with its interval,
    whether the sweep fixes it, the method and the RMSE."""
    if not 0.5 <= level < 1.0:
        usage_error(f"must be in [0.5, 1), got {level}", "--level")
    _run("identify", runs, manifest, output, {"omega": omega, "current_only": current_only, "level": level,
                                              "current_sign": current_sign.value},
         None, scheduler, jobs, retries, strict, fmt, quiet)


@_sub("evaluate", "PTPE and RMSE of every run into one table",
      epilog="Example: hyst batch evaluate 'runs/*.csv' -o scores.parquet --scheduler tcp://head:8786")
def batch_evaluate(
    runs: RunsArg = None, manifest: ManifestOpt = None, output: TableOpt = Path("evaluate.parquet"),
    scheduler: SchedulerOpt = None, jobs: JobsOpt = 2, retries: RetriesOpt = 2, strict: StrictOpt = False,
    fmt: FormatOpt = OutputFormat.table, quiet: QuietOpt = False,
) -> None:
    """PTPE and RMSE of y - r per run and knob (hyst evaluate --per-run)."""
    _run("evaluate", runs, manifest, output, {}, None, scheduler, jobs, retries, strict, fmt, quiet)


@_sub("detect-shift", "Each replay's shift under one model into one table",
      epilog="Example: hyst batch detect-shift 'replays/*.csv' -m model.json -o shifts.parquet")
def batch_detect_shift(
    runs: RunsArg = None, manifest: ManifestOpt = None, output: TableOpt = Path("detect-shift.parquet"),
    model: ModelReqOpt = None,
    false_alarm: Annotated[float, typer.Option("--false-alarm", help="False-alarm probability of a search.")] = 1e-3,
    step: Annotated[float, typer.Option("--step", help="Unit step u, deg.")] = 0.5,
    max_steps: Annotated[Optional[int], typer.Option("--max-steps", min=1, help="Step limit.")] = None,
    max_travel: Annotated[Optional[float], typer.Option("--max-travel", help="Knob travel limit, deg.")] = None,
    eps_upper: Annotated[Optional[float], typer.Option("--eps-upper", help="Contact slope, mA/deg.")] = None,
    scheduler: SchedulerOpt = None, jobs: JobsOpt = 2, retries: RetriesOpt = 2, strict: StrictOpt = False,
    fmt: FormatOpt = OutputFormat.table, quiet: QuietOpt = False,
) -> None:
    """Algorithm 1 on each replay (hyst detect-shift REPLAY.csv): per knob the offset and its interval."""
    if model is None and manifest is None:
        usage_error("give --model (or a manifest with a model column)", "--model")
    if not 0.0 < false_alarm < 0.5:
        usage_error(f"must be in (0, 0.5), got {false_alarm}", "--false-alarm")
    _run("detect-shift", runs, manifest, output, {"false_alarm": false_alarm, "step": step, "max_steps": max_steps,
                                                  "max_travel": max_travel, "eps_upper": eps_upper},
         model, scheduler, jobs, retries, strict, fmt, quiet)


@_sub("diagnose", "Diagnose every session of runs into one table",
      epilog="Example: hyst batch diagnose 'sessions/*/*.csv' -m model.json -o diagnoses.parquet")
def batch_diagnose(
    runs: RunsArg = None, manifest: ManifestOpt = None, output: TableOpt = Path("diagnose.parquet"),
    model: ModelReqOpt = None,
    holdout: Annotated[Optional[str], typer.Option("--holdout", help="key=value hold-out (default: leave one "
                                                                     "run out).")] = None,
    candidates: Annotated[Optional[str], typer.Option("--candidates", help="Comma-separated effects.")] = None,
    max_effects: Annotated[int, typer.Option("--max-effects", min=0, help="Most effects to add.")] = 3,
    bootstrap: Annotated[int, typer.Option(min=0, help="Bootstrap resamples (0: none).")] = 0,
    seed: SeedOpt = 0,
    session_by: Annotated[Optional[str], typer.Option("--session-by", metavar="KEY",
                                                      help="One session per value of the runs' '# KEY:' "
                                                           "metadata (default: per folder).")] = None,
    scheduler: SchedulerOpt = None, jobs: JobsOpt = 2, retries: RetriesOpt = 2, strict: StrictOpt = False,
    fmt: FormatOpt = OutputFormat.table, quiet: QuietOpt = False,
) -> None:
    """Diagnose each session (hyst diagnose): the runs of one folder, of one 'session' in the
    manifest, or with one value of a metadata key (--session-by robot) are one diagnosis; each
    run's row holds the session's top effect and gap shrink and its own RMSE before and after."""
    if model is None and manifest is None:
        usage_error("give --model (or a manifest with a model column)", "--model")
    _run("diagnose", runs, manifest, output, {"holdout": holdout, "candidates": candidates,
                                              "max_effects": max_effects, "bootstrap": bootstrap, "seed": seed},
         model, scheduler, jobs, retries, strict, fmt, quiet, session_by=session_by)


def _tables(rep: Any, z_limit: float) -> list[Any]:
    """The report's three views as tables (summary, drift, outliers)."""
    from ..batch.tasks import text_table

    stats = [f"{v}_{s}" for v in rep.values for s in ("mean", "std", "median")]
    out = [text_table(["group", "runs", "failed", *stats], [rep.by or "group", "runs", "failed", *stats],
                      [tuple(r.get(c) for c in ["group", "runs", "failed", *stats]) for r in rep.summary],
                      [f"{rep.command}: {rep.runs} run(s), {rep.ok} ok; mean, sample std (ddof=1) and median over "
                       "the runs with status ok"])]
    if rep.time is not None:
        cols = ["group", "value", "n", "first", "last", "slope", "unit"]
        out.append(text_table(cols, cols, [tuple(d[c] for c in cols) for d in rep.drift],
                              [f"drift against {rep.time}: first and last value in time order, least-squares slope"]))
    cols = ["path", "group", "value", "x", "median", "mad", "z"]
    out.append(text_table(cols, cols, [tuple(o[c] for c in cols) for o in rep.outliers],
                          [f"outliers: |modified z| = |0.6745 (x - median) / MAD| > {z_limit:g} within each group "
                           "(Iglewicz and Hoaglin)"
                           + ("" if rep.outliers else "; none"), *rep.notes]))
    return out


@command("report", "Summaries, drift and outliers of a batch's table",
         epilog="Example: hyst report scores.parquet --by meta_catheter --time manifest_day -o drift.png")
def report_cmd(
    table: Annotated[Path, typer.Argument(metavar="TABLE", help="A results table of hyst batch (.parquet or .csv).",
                                          show_default=False)],
    by: Annotated[Optional[str], typer.Option("--by", help="Group by this column (e.g. meta_catheter, "
                                                           "manifest_robot).")] = None,
    time: Annotated[Optional[str], typer.Option("--time", help="Drift against this column (dates, time stamps "
                                                               "or numbers).")] = None,
    value: Annotated[Optional[List[str]], typer.Option(
        "--value", help="Value column (repeatable; default: the command's RMSE/PTPE, parameters or offsets).")] = None,
    z: Annotated[float, typer.Option("--z", help="Outlier threshold on the modified z-score.")] = 3.5,
    output: Annotated[Optional[Path], typer.Option(
        "--output", "-o", help="Draw the drift (needs --time) to this PNG/PDF/SVG file.")] = None,
    fmt: FormatOpt = OutputFormat.table,
    quiet: QuietOpt = False,
) -> None:
    """Per-group summaries, drift of the values over time, and the runs whose values are outliers
    by a robust z-score (median and MAD), over a results table of hyst batch."""
    from ..batch import require

    require("pyarrow")
    from ..batch.report import drift_figure, report
    from ..batch.table import read_table

    if not (z > 0 and z < float("inf")):
        usage_error(f"must be a positive number, got {z}", "--z")
    if output is not None:
        if time is None:
            usage_error("a figure draws the drift: give --time", "--output")
        if output.suffix.lower() not in (".png", ".pdf", ".svg"):
            usage_error(f"{output} must end in .png, .pdf or .svg", "--output")
    df = read_table(table)
    rep = report(df, by=by, time=time, values=value or (), z_limit=z)
    if output is not None:
        from ..report.figures import save_figure

        save_figure(drift_figure(df, time, rep.values, by), output, inputs=[table])
        info(f"wrote {output}", quiet)
    if fmt == OutputFormat.json:
        echo_json(rep.to_dict())
    elif not quiet or fmt != OutputFormat.table:
        from .app import echo_table

        for t in _tables(rep, z):
            echo_table(t, fmt, digits=3)
            if fmt == OutputFormat.table:
                typer.echo("")
