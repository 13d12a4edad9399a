"""Commands over the model itself: ``identify``, ``compensate``, ``predict``, ``rotate-shift``."""
from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Optional

import typer

from ..safety import DEFAULT_MAX_SPEED, DEFAULT_TRAVEL
from .app import (ColumnsOpt, CurrentSign, FormatOpt, ModelOpt, OutOpt, OutputFormat, PlotOpt, QuietOpt, SeedOpt, about,
                  columns_mapping, command, distinct_outputs, echo_json, echo_table, info, load_run, one_of,
                  option_errors, prints, usage_error, warn)
from .robot_opts import (AllowFastOpt, InverseMaxSpeedOpt, MaxAccelOpt, StrictSpeedOpt, TravelLimitOpt, limit_hint,
                         limits, speed_mode)

InputArg = Annotated[Path, typer.Argument(metavar="RUN.csv", help="Input run CSV.", show_default=False)]


@command("identify", "Identify each knob's hysteresis model from a sweep",
         epilog="Example: hyst identify sample_data/ice-a/sweep_knob1.csv -o model.json --plot fit.png")
def identify_cmd(
    sweep: InputArg,
    output: Annotated[Optional[Path], typer.Option(
        "--output", "-o", help="Model JSON file to write (atomically); without it the parameters are printed only.")] = None,
    omega: Annotated[Optional[float], typer.Option(
        help="Slope omega when the run has no tip angle y (default: the paper's 1.45).")] = None,
    current_only: Annotated[bool, typer.Option(
        "--current-only", help="Ignore a measured tip angle: edges and backlash from the current alone.")] = False,
    current_sign: Annotated[CurrentSign, typer.Option(
        "--current-sign", help="How the drive reports its motor current: signed (below its no-load level "
        "while the negative tendon pulls), magnitude (|I|), or auto (read from the sweep).")] = CurrentSign.auto,
    level: Annotated[float, typer.Option(
        "--level", help="Confidence level of the intervals (profile likelihood).")] = 0.95,
    beta_catheter_mm: Annotated[Optional[float], typer.Option(
        help="Tendon offset from the backbone (mm), stored as the model's geometry.")] = None,
    beta_knob_mm: Annotated[Optional[float], typer.Option(help="Knob pulley radius (mm).")] = None,
    plot: PlotOpt = None,
    columns: ColumnsOpt = None,
    fmt: FormatOpt = OutputFormat.table,
    seed: SeedOpt = 0,
    quiet: QuietOpt = False,
) -> None:
    """Identify the straight-shaft hysteresis model of each knob from a sweep.

    Reads q<k> and c<k> (and y<k> when present) of every knob in RUN.csv. With y: the loop that
    best predicts the tip, each parameter with its interval (one the sweep cannot fix is reported
    open, not refused); without: dead-zone edges and backlash where the motor current shows them,
    omega given, heights by the documented assumption. Prints the parameters; -o writes the model
    that the other commands read.
    """
    from dataclasses import replace

    from .. import io
    from ..core.params import Geometry
    from ..settings import Settings

    del seed  # identification draws nothing at random
    if omega is not None and not (omega > 0 and omega < float("inf")):
        usage_error(f"must be a positive number, got {omega}", "--omega")
    if not 0.5 <= level < 1.0:
        usage_error(f"must be in [0.5, 1), got {level}", "--level")
    if (beta_catheter_mm is None) != (beta_knob_mm is None):
        usage_error("give both --beta-catheter-mm and --beta-knob-mm, or neither", "--beta-catheter-mm")
    distinct_outputs(**{"--output": output, "--plot": plot})
    geometry = None
    if beta_catheter_mm is not None:
        with option_errors("--beta-catheter-mm / --beta-knob-mm"):
            geometry = Geometry(beta_catheter_mm, beta_knob_mm)
    mapping = columns_mapping(columns)
    for target in (output, plot):
        if target is not None:
            io.check_not_input(target, [sweep])
    settings = Settings(level=level, current_sign=current_sign.value)
    with about(sweep):
        run = load_run(sweep, mapping, quiet=quiet)
        # the fit's libraries (scipy, numba) load only once the file is known to be good: a bad
        # file's error line comes in the time the command line itself takes to start
        from ..identification import identify, plot_identification

        result = identify(run, omega=omega, use_tip=not current_only, settings=settings)
    for fit in result.fits.values():
        for w in fit.warnings:
            warn(w)
    meta = dict(result.model.meta)
    meta.update(io.provenance(sweep, catheter=run.meta.get("catheter")))
    model = replace(result.model, meta=meta, geometry=geometry or result.model.geometry)
    if output is not None:
        # the figure and the model together or neither (an error drawing the one loses no old other)
        with io.all_or_none() as pending:
            if plot is not None:
                plot_identification(run, result, pending.path(plot, inputs=[sweep]))
            pending.write_text(output, io.dumps_model(model), inputs=[sweep])
    elif plot is not None:
        with io.all_or_none() as pending:
            plot_identification(run, result, pending.path(plot, inputs=[sweep]))
    if not prints(fmt, quiet):
        pass
    elif fmt == OutputFormat.json:
        echo_json({str(k): {"params": f.model.params(), "intervals": {n: e.to_dict() for n, e in f.estimates.items()},
                            "rmse": f.rmse, "method": f.method, "warnings": list(f.warnings),
                            "current_sign": None if f.current is None else f.current.sign,
                            "cogging": _cogging(result, k), "unfixed": list(f.unfixed)}
                   for k, f in result.fits.items()})
    elif fmt == OutputFormat.table:
        typer.echo(result.summary(warnings=False))  # warn() has printed them on stderr
    else:
        echo_table(_identify_table(result), fmt)
    written = [str(p) for p in (output, plot) if p is not None]
    info(f"wrote {' and '.join(written)}" if written else "no model written: -o model.json keeps it", quiet)


def _ident(result, knob: int):  # noqa: ANN001, ANN202 - identify.Identification -> KnobIdentification or None
    """What identify learnt of this knob's current, or None (a sweep without one)."""
    return result.model.identification.get(knob) if result.model.identification else None


def _cogging(result, knob: int) -> dict | None:  # noqa: ANN001 - identify.Identification
    """The cogging ripple identify read on this knob's current, for ``--format json``."""
    ident = _ident(result, knob)
    r = None if ident is None else ident.calibration.ripple
    return None if r is None else {"period": r.period, "sin": r.sin, "cos": r.cos, "amplitude": r.amplitude}


def _identify_table(result):  # noqa: ANN001, ANN202 - identify.Identification -> report.table.Table
    from ..report.table import Table

    rows = []
    for k, fit in result.fits.items():
        for name, e in fit.estimates.items():
            rows.append((k, name, e.value, e.lo if e.lo != float("-inf") else None,
                         e.hi if e.hi != float("inf") else None, "yes" if e.fixed else "no", fit.method, fit.rmse))
    return Table(("knob", "parameter", "value", "lo", "hi", "fixed", "method", "rmse"),
                 ("knob", "parameter", "value", "low", "high", "fixed", "method", "RMSE (deg)"), tuple(rows),
                 ("deg, omega in deg/deg; low/high: the 95 % profile-likelihood interval, empty where the sweep "
                  "says nothing that way; current-only: omega and the heights are assumed",))


@command("compensate", "Turn desired tip angles into knob commands",
         epilog="Example: hyst compensate sample_data/reference_periodic.csv --model "
                "shifted.json -o commands.csv")
def compensate_cmd(
    trajectory: Annotated[Path, typer.Argument(help="Desired trajectory CSV with t and r1/r2.",
                                               show_default=False)],
    model_path: ModelOpt,
    output: OutOpt,
    ignore_shift: Annotated[bool, typer.Option(
        "--ignore-shift", help="Use offset 0 on every knob: the paper's Compensation-Only.")] = False,
    travel_limit: TravelLimitOpt = DEFAULT_TRAVEL,
    max_speed: InverseMaxSpeedOpt = DEFAULT_MAX_SPEED,
    max_accel: MaxAccelOpt = None,
    allow_fast: AllowFastOpt = False,
    strict_speed: StrictSpeedOpt = False,
    columns: ColumnsOpt = None,
    fmt: FormatOpt = OutputFormat.table,
    quiet: QuietOpt = False,
) -> None:
    """Turn desired tip angles r1/r2 into knob commands q1/q2 through the inverse model.

    Keeps t, r and the metadata; sets `controller` (comp or comp+shift) and the offsets used.
    Where the tip must cross a flat part of the loop (the dead zone, the backlash at a reversal)
    the exact inverse jumps across it within one sample, faster than --max-speed: such a step is
    rate-limited (the knob crosses it at the limit and catches up with the exact inverse after
    it) and a warning says how long the knob lags and how far that moves the tip on the model.
    --allow-fast writes the exact inverse, jumps included; --strict-speed refuses (writes
    nothing, exit 1). Commands beyond --travel-limit are always refused. Reports each knob's
    range, peak speed and peak acceleration of what it writes.
    """
    from .. import compensation, io
    from ..safety import LimitExceeded

    mode = speed_mode(allow_fast, strict_speed)
    io.check_not_input(output, [trajectory, model_path])
    mapping = columns_mapping(columns)
    model = io.load_model(model_path)
    traj = load_run(trajectory, mapping, quiet=quiet)
    # checked before anything is written: a refused file never exists
    try:
        result = compensation.compensate(model, traj, ignore_shift=ignore_shift, speed=mode, name=str(output),
                                         limits=limits(travel_limit, max_speed, max_accel))
    except LimitExceeded as exc:
        raise type(exc)(f"{exc}{limit_hint(exc)}", exc.check) from None
    for w in result.warnings:
        warn(w)
    check = result.sent
    for v in check.violations:  # only what --allow-fast let through
        warn(f"{v.message}: written as asked (--allow-fast)")
    io.write_run(output, result.run, inputs=[trajectory, model_path])
    info(f"wrote {output} (controller {result.run.meta['controller']}, offsets "
         + ", ".join(f"knob {k}: {o:+.2f} deg" for k, o in result.offsets.items()) + ")", quiet)
    if fmt == OutputFormat.json:
        echo_json({"output": str(output), "controller": result.run.meta["controller"],
                   "offsets": {str(k): o for k, o in result.offsets.items()},
                   "warnings": list(result.warnings), "speed": mode,
                   "rate_limited": {str(k): c.to_dict() for k, c in result.catch_ups.items()},
                   **check.to_dict()})
    elif fmt != OutputFormat.table:
        echo_table(_motion_table(check, result.offsets), fmt)
    elif not quiet:
        typer.echo(f"{'knob':>4}  {'offset':>7}  {'q min':>7}  {'q max':>7}  {'peak speed':>10}  "
                   f"{'at t':>7}  {'peak accel':>11}  {'at t':>7}")
        for k, m in check.knobs.items():
            typer.echo(f"{k:>4}  {result.offsets[k]:>+7.2f}  {m.q_min:>+7.1f}  {m.q_max:>+7.1f}  "
                       f"{m.peak_speed:>10.1f}  {m.peak_speed_t:>7.2f}  {m.peak_accel:>11.4g}  "
                       f"{m.peak_accel_t:>7.2f}")
        lim = check.limits
        typer.echo(f"(deg, deg/s, deg/s^2, s; limits: travel +-{lim.travel:g} deg, speed "
                   f"{lim.max_speed:g} deg/s"
                   + (f", acceleration {lim.max_accel:g} deg/s^2" if lim.max_accel is not None else "")
                   + ("; beyond them, written with --allow-fast)" if not check.ok else
                      "; within them after rate-limiting)" if result.catch_ups else "; within them)"))


def _motion_table(check, offsets):  # noqa: ANN001, ANN202 - safety.MotionCheck, {knob: offset} -> report.table.Table
    """compensate's report for ``--format`` csv/markdown/latex."""
    from ..report.table import Table

    rows = tuple((k, offsets[k], m.q_min, m.q_max, m.peak_speed, m.peak_speed_t, m.peak_accel, m.peak_accel_t)
                 for k, m in check.knobs.items())
    return Table(("knob", "offset", "q_min", "q_max", "peak_speed", "peak_speed_t", "peak_accel", "peak_accel_t"),
                 ("knob", "offset", "q min", "q max", "peak speed", "at t", "peak accel", "at t"), rows,
                 ("deg, deg/s, deg/s^2, s",))


@command("predict", "Run the model on a run's knob commands: the tip",
         epilog="Example: hyst predict run_shift.csv --model shifted.json -o pred.csv")
def predict_cmd(
    run_path: Annotated[Path, typer.Argument(metavar="RUN.csv", help="Run CSV with t and q1/q2.",
                                             show_default=False)],
    model_path: ModelOpt,
    output: OutOpt,
    columns: ColumnsOpt = None,
    fmt: FormatOpt = OutputFormat.table,
    quiet: QuietOpt = False,
) -> None:
    """Run the model on the commands q1/q2 of a run and write the predicted tip angles y1/y2.

    A measured y<k> is kept as y<k>_measured beside the prediction; the summary on stdout gives
    per knob the predicted range and, with a measurement, the RMSE and PTPE of prediction minus
    measurement.
    """
    from .. import io

    io.check_not_input(output, [run_path, model_path])
    mapping = columns_mapping(columns)
    model = io.load_model(model_path)
    with about(run_path):
        run = load_run(run_path, mapping, quiet=quiet)
        predicted = model.predict(run)
    io.write_run(output, predicted, inputs=[run_path, model_path])
    if prints(fmt, quiet):
        echo_table(_prediction_table(predicted), fmt)
    info(f"wrote {output}", quiet)


def _prediction_table(predicted):  # noqa: ANN001, ANN202 - core.run.Run -> report.table.Table
    import numpy as np

    from ..report.metrics import ptpe, rmse
    from ..report.table import Table

    rows = []
    for k in predicted.knobs("y"):
        y = predicted[f"y{k}"]
        measured = predicted.columns.get(f"y{k}_measured")
        err = None if measured is None else y - measured
        rows.append((k, len(y), float(np.min(y)), float(np.max(y)),
                     None if err is None else rmse(err), None if err is None else ptpe(err)))
    return Table(("knob", "samples", "y_min", "y_max", "rmse_vs_measured", "ptpe_vs_measured"),
                 ("knob", "samples", "y min", "y max", "RMSE vs measured", "PTPE vs measured"), tuple(rows),
                 ("predicted tip angle y and its error against the measured y, deg; '-': no measurement",))


@command("rotate-shift", "Update the offsets after a bulk rotation of the body",
         epilog="Example: hyst rotate-shift shifted.json --degrees 30 -o rotated.json")
def rotate_shift_cmd(
    degrees: Annotated[float, typer.Option("--degrees", help="Bulk rotation of the catheter body (deg).")],
    output: OutOpt,
    model_arg: Annotated[Optional[Path], typer.Argument(
        metavar="MODEL.json", help="Model JSON file (from `hyst detect-shift`).", show_default=False)] = None,
    model_opt: Annotated[Optional[Path], typer.Option("--model", "-m", hidden=True)] = None,  # the old spelling
    fmt: FormatOpt = OutputFormat.table,
    quiet: QuietOpt = False,
) -> None:
    """Update both knobs' offsets after a bulk rotation of the catheter body, without moving a knob.

    The vector (offset1, offset2) rotates by -degrees (docs/design.md section 3; the paper leaves
    this case out).
    """
    from .. import io
    from ..report.table import Table

    model_path = one_of(model_arg, model_opt, "MODEL.json", "--model")
    if model_path is None:
        usage_error("give the model file, e.g. hyst rotate-shift shifted.json --degrees 30 -o rotated.json",
                    "MODEL.json")
    if not math.isfinite(degrees):
        usage_error(f"must be a finite number of degrees, got {degrees}", "--degrees")
    io.check_not_input(output, [model_path])
    model = io.load_model(model_path)
    rotated = model.rotated(degrees)
    io.save_model(output, rotated, inputs=[model_path])
    if not prints(fmt, quiet):
        return
    if fmt == OutputFormat.table:
        for k in rotated.knobs:
            typer.echo(f"knob {k}: offset {model.knob(k).offset:+.3f} -> {rotated.knob(k).offset:+.3f} deg")
    else:
        rows = tuple((k, model.knob(k).offset, rotated.knob(k).offset) for k in rotated.knobs)
        echo_table(Table(("knob", "offset_before", "offset_after"), ("knob", "offset before", "offset after"),
                         rows, (f"deg; catheter body rotated by {degrees:g} deg",)), fmt, digits=3)
    info(f"wrote {output}", quiet)
