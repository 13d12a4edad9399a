"""Commands over the model itself: ``identify``, ``compensate``, ``predict``, ``rotate-shift``."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Annotated, Optional

import typer

from .. import compensation, io
from ..model import PARAM_NAMES, Geometry
from ..safety import DEFAULT_MAX_SPEED, DEFAULT_TRAVEL
from .app import (FormatOpt, ModelOpt, OutOpt, OutputFormat, PlotOpt, QuietOpt, SeedOpt, command,
                  echo_json, info, warn)
from .robot_opts import (AllowFastOpt, FormatTJOpt, MaxAccelOpt, MaxSpeedOpt, TableOrJson,
                         TravelLimitOpt, limit_hint, limits)

InputArg = Annotated[Path, typer.Argument(help="Input run CSV.", show_default=False)]


@command("identify", epilog="Example: hyst identify sample_data/sweep_ice-a.csv -o model.json --plot fit.png")
def identify_cmd(
    sweep: InputArg,
    output: OutOpt,
    omega: Annotated[Optional[float], typer.Option(
        help="Slope omega when the run has no tip angle y (default: the paper's 1.45).")] = None,
    current_only: Annotated[bool, typer.Option(
        "--current-only", help="Ignore a measured tip angle: edges and backlash from the current alone.")] = False,
    bootstrap: Annotated[int, typer.Option(min=0, help="Bootstrap resamples over cycles for uncertainties "
                                           "(0: from the fit's covariance).")] = 0,
    beta_catheter_mm: Annotated[Optional[float], typer.Option(
        help="Tendon offset from the backbone (mm), stored as the model's geometry.")] = None,
    beta_knob_mm: Annotated[Optional[float], typer.Option(help="Knob pulley radius (mm).")] = None,
    plot: PlotOpt = None,
    fmt: FormatOpt = OutputFormat.table,
    seed: SeedOpt = 0,
    quiet: QuietOpt = False,
) -> None:
    """Identify the straight-shaft hysteresis model of each knob from a sweep.

    Reads q<k> and c<k> (and y<k> when present) of every knob in SWEEP. With y: least-squares fit
    of all seven parameters through the model; without: dead-zone edges and backlash from the
    motor current, omega given, heights by the documented assumption.
    """
    from ..identify import identify, plot_identification

    if omega is not None and not omega > 0:
        raise typer.BadParameter("omega must be > 0", param_hint="--omega")
    if (beta_catheter_mm is None) != (beta_knob_mm is None):
        raise typer.BadParameter("give both --beta-catheter-mm and --beta-knob-mm, or neither")
    geometry = Geometry(beta_catheter_mm, beta_knob_mm) if beta_catheter_mm is not None else None
    io.check_not_input(output, [sweep])
    run = io.read_run(sweep, require=("t",))
    result = identify(run, omega=omega, use_tip=not current_only, bootstrap=bootstrap, seed=seed)
    meta = dict(result.model.meta)
    meta.update(io.provenance(sweep, catheter=run.meta.get("catheter")))
    model = replace(result.model, meta=meta, geometry=geometry or result.model.geometry)
    if plot is not None:
        io.check_not_input(plot, [sweep])
        plot_identification(run, result, plot)
    io.save_model(output, model, inputs=[sweep])
    if quiet:
        return
    if fmt == OutputFormat.json:
        echo_json({str(k): {"params": f.model.params(), "stderr": dict(f.stderr), "rmse": f.rmse,
                            "method": f.method} for k, f in result.fits.items()})
        return
    for k, fit in result.fits.items():
        typer.echo(f"knob {k} ({fit.method}{', RMSE %.2f deg' % fit.rmse if fit.rmse is not None else ''})")
        for name in PARAM_NAMES:
            if name == "offset":
                continue
            value = getattr(fit.model, name)
            err = fit.stderr.get(name)
            typer.echo(f"  {name:7s} {value:9.3f}" + (f"  +- {err:.3f}" if err is not None else "  (assumed)"))
    info(f"wrote {output}", quiet)


@command("compensate", epilog="Example: hyst compensate sample_data/reference_periodic.csv --model "
                              "shifted.json -o commands.csv --allow-fast")
def compensate_cmd(
    trajectory: Annotated[Path, typer.Argument(help="Desired trajectory CSV with t and r1/r2.",
                                               show_default=False)],
    model_path: ModelOpt,
    output: OutOpt,
    ignore_shift: Annotated[bool, typer.Option(
        "--ignore-shift", help="Use offset 0 on every knob: the paper's Compensation-Only.")] = False,
    travel_limit: TravelLimitOpt = DEFAULT_TRAVEL,
    max_speed: MaxSpeedOpt = DEFAULT_MAX_SPEED,
    max_accel: MaxAccelOpt = None,
    allow_fast: AllowFastOpt = False,
    fmt: FormatTJOpt = TableOrJson.table,
    quiet: QuietOpt = False,
) -> None:
    """Turn desired tip angles r1/r2 into knob commands q1/q2 through the inverse model.

    Keeps t, r and the metadata; sets `controller` (comp or comp+shift) and the offsets used.
    Reports each knob's range, peak speed and peak acceleration, and refuses (writes nothing,
    exit 1) commands beyond --travel-limit, or beyond --max-speed (--max-accel) unless
    --allow-fast: where the tip must cross a flat part of the loop (the dead zone, the
    backlash at a reversal) the inverse model jumps across it within one sample, which a motor
    cannot follow at the file's timing.
    """
    from ..safety import LimitExceeded, check_motion, require_within

    io.check_not_input(output, [trajectory, model_path])
    model = io.load_model(model_path)
    traj = io.read_run(trajectory)
    result = compensation.compensate(model, traj, ignore_shift=ignore_shift)
    # checked before anything is written: a refused file never exists
    check = check_motion(result.run, limits(travel_limit, max_speed, max_accel), name=str(output))
    try:
        require_within(check, allow=("speed", "accel") if allow_fast else (), name=str(output),
                       action="write")
    except LimitExceeded as exc:
        raise type(exc)(f"{exc}{limit_hint(exc)}", exc.check) from None
    for w in result.warnings:
        warn(w)
    for v in check.violations:  # only what --allow-fast let through
        warn(f"{v.message}: written as asked (--allow-fast)")
    io.write_run(output, result.run, inputs=[trajectory, model_path])
    info(f"wrote {output} (controller {result.run.meta['controller']}, offsets "
         + ", ".join(f"knob {k}: {o:+.2f} deg" for k, o in result.offsets.items()) + ")", quiet)
    if fmt == TableOrJson.json:
        echo_json({"output": str(output), "controller": result.run.meta["controller"],
                   "offsets": {str(k): o for k, o in result.offsets.items()},
                   "warnings": list(result.warnings), **check.to_dict()})
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
                   + ("; within them)" if check.ok else "; beyond them, written with --allow-fast)"))


@command("predict", epilog="Example: hyst predict run.csv --model model.json -o predicted.csv")
def predict_cmd(
    run_path: Annotated[Path, typer.Argument(help="Run CSV with t and q1/q2.", show_default=False)],
    model_path: ModelOpt,
    output: OutOpt,
    quiet: QuietOpt = False,
) -> None:
    """Run the model on the commands q1/q2 of a run and write the predicted tip angles y1/y2.

    A measured y<k> is kept as y<k>_measured beside the prediction.
    """
    io.check_not_input(output, [run_path, model_path])
    model = io.load_model(model_path)
    run = io.read_run(run_path)
    io.write_run(output, compensation.predict(model, run), inputs=[run_path, model_path])
    info(f"wrote {output}", quiet)


@command("rotate-shift", epilog="Example: hyst rotate-shift --model shifted.json --degrees 30 -o rotated.json")
def rotate_shift_cmd(
    model_path: ModelOpt,
    degrees: Annotated[float, typer.Option("--degrees", help="Bulk rotation of the catheter body (deg).")],
    output: OutOpt,
    quiet: QuietOpt = False,
) -> None:
    """Update both knobs' offsets after a bulk rotation of the catheter body, without moving a knob.

    The vector (offset1, offset2) rotates by -degrees (DESIGN.md section 3; the paper leaves
    this case out).
    """
    io.check_not_input(output, [model_path])
    model = io.load_model(model_path)
    rotated = model.rotated(degrees)
    io.save_model(output, rotated, inputs=[model_path])
    if not quiet:
        for k in rotated.knobs:
            typer.echo(f"knob {k}: offset {model.knob(k).offset:+.3f} -> {rotated.knob(k).offset:+.3f} deg")
