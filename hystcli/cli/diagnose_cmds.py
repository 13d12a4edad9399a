"""``hyst diagnose``: where the model departs from measurement, which effect causes it, how far it shrinks."""
from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path
from typing import Annotated, List, Optional

import typer

from .app import (ColumnsOpt, FormatOpt, ModelOpt, OutputFormat, PlotOpt, QuietOpt, SeedOpt, columns_mapping, command,
                  distinct_inputs, distinct_outputs, echo_json, info, load_run, only_formats, progress, usage_error)


@command("diagnose", "Find the unmodelled effect behind the model's error",
         epilog="Example: hyst diagnose --model shifted.json run_none.csv run_only.csv run_shift.csv "
                "run_shift2.csv -o report.json --model-out augmented.json --plot diag.png")
def diagnose_cmd(
    runs: Annotated[List[Path], typer.Argument(metavar="RUN.csv", help="Run CSVs with t, q<k> and measured "
                                                    "y<k> (at least 2, one catheter).", show_default=False)],
    model_path: ModelOpt,
    output: Annotated[Optional[Path], typer.Option("--output", "-o", help="Write the report as JSON here.")] = None,
    model_out: Annotated[Optional[Path], typer.Option(
        "--model-out", help="Write the model with the chosen effects here (hyst predict/compensate use them).")] = None,
    plot: PlotOpt = None,
    holdout: Annotated[Optional[str], typer.Option(
        "--holdout", help="key=value: test on the runs whose metadata key equals value, train on the rest "
                          "(default: leave one run out).")] = None,
    candidates: Annotated[Optional[str], typer.Option(
        "--candidates", help="Comma-separated effects to try (default: all of docs/design.md section 8).")] = None,
    max_effects: Annotated[int, typer.Option("--max-effects", min=0, help="Most effects to add.")] = 3,
    bootstrap: Annotated[int, typer.Option(min=0, help="Bootstrap resamples over runs for intervals and "
                                                       "inclusion frequencies (0: none).")] = 0,
    sweep: Annotated[Optional[Path], typer.Option(
        "--sweep", help="The model's identification sweep (t, q<k>, y<k>): a lag, latency or creep is in it too "
                        "(and a coupling when it moves both knobs), so those candidates re-identify the loop "
                        "from it with the effect acting; with its motor current (c<k>) it also tells whether "
                        "a delay sits in the drive or after the tendons.")] = None,
    columns: ColumnsOpt = None,
    fmt: FormatOpt = OutputFormat.table,
    seed: SeedOpt = 0,
    quiet: QuietOpt = False,
) -> None:
    """Diagnose the sim-to-real gap of a model on measured runs.

    WHERE: the residual y - predicted by loop phase, direction, shape, speed, amplitude, other
    knob and time. WHICH: every unmodelled effect is fitted on training runs and judged on
    held-out runs; the best are added while the held-out gain is worth it. HOW FAR: held-out RMSE
    and PTPE before and after.
    """
    from .. import io
    from ..io.check import require_shape
    from ..diagnosis import diagnose
    from ..core.effects import EFFECTS

    only_formats(fmt, "diagnose", OutputFormat.table, OutputFormat.json)
    distinct_outputs(**{"--output": output, "--model-out": model_out, "--plot": plot})
    distinct_inputs(runs)
    if holdout is not None and holdout.strip():
        key, eq, value = holdout.partition("=")
        if not (eq and key.strip() and value.strip()):
            usage_error(f"{holdout!r}: expected key=value, e.g. motion=nonperiodic", "--holdout")
    inputs = [*runs, model_path] + ([sweep] if sweep is not None else [])
    for out in (output, model_out, plot):
        if out is not None:
            io.check_not_input(out, inputs)
    cands = None
    if candidates is not None:
        cands = [c.strip().lower() for c in candidates.split(",") if c.strip()]
        if not cands:
            usage_error("give at least one effect name", "--candidates")
        unknown = [c for c in cands if c not in EFFECTS]
        if unknown:
            usage_error(f"unknown effect {unknown[0]!r} (known: {', '.join(EFFECTS)})", "--candidates")
    mapping = columns_mapping(columns)
    model = io.load_model(model_path)
    loaded = [require_shape(load_run(p, mapping, quiet=quiet)) for p in runs]
    sweep_run = require_shape(load_run(sweep, mapping, quiet=quiet)) if sweep is not None else None
    with progress(quiet) as update:
        diag = diagnose(model, loaded, holdout=holdout, candidates=cands, max_effects=max_effects,
                        bootstrap=bootstrap, seed=seed, progress=update, sweep=sweep_run)
    report = diag.report()
    report["model"] = str(model_path)
    figure = diag.plot(loaded) if plot is not None else None
    with io.all_or_none() as pending:
        if output is not None:
            pending.write_text(output, json.dumps(report, indent=2, allow_nan=False) + "\n", inputs=inputs)
        if model_out is not None:
            meta = dict(diag.model.meta)
            meta["diagnosed_on"] = ", ".join(Path(p).name for p in runs)
            pending.write_text(model_out, io.dumps_model(replace(diag.model, meta=meta)), inputs=inputs)
        if figure is not None:
            from ..report.figures import save_figure

            save_figure(figure, pending.path(plot, inputs=inputs), fmt="png")
    if quiet:
        return
    if fmt == OutputFormat.json:
        echo_json(report)
        return
    typer.echo(render_table(report))
    for path in (output, model_out, plot):
        if path is not None:
            info(f"wrote {path}")


def _num(v, width: int, digits: int) -> str:
    # a figure the report holds as null (not finite: a candidate that breaks a held-out run) as "-"
    return f"{v:{width}.{digits}f}" if v is not None else f"{'-':>{width}s}"


def render_table(report: dict) -> str:
    """The report as text: the finding, the candidate ranking, the figures."""
    lines = ["WHERE", f"  {report['where']['finding']}"]
    follows = [a for a in report["where"].get("follows", []) if (a["explained_pct"] or 0) >= 1.0]
    if follows:
        lines.append("  the residual follows (share of its energy explained on held-out runs): "
                     + ", ".join(f"{a['regressor']} {a['explained_pct']:.0f} %" for a in follows))
    phase = report["where"]["factors"].get("phase", [])
    if phase:
        lines.append("  " + "  ".join(f"{g['level']}: {100 * g['energy_share']:.0f} % of energy in "
                                      f"{100 * g['sample_share']:.0f} % of samples" for g in phase))
    which = report["which"]
    lines += ["", f"WHICH (hold-out: {report['holdout']}; an effect joins at >= {which['min_gain_pct']:g} % "
                  "held-out RMSE shrink)"]
    side = which.get("delay_side")
    if side:
        lines.append(f"  the sweep's motor current: the tip trails it by {side['tip_behind_current_s']:.3f} s at the "
                     f"dead-zone edges ({side['speed_deg_s']:.1f} deg/s, {len(side['readings'])} edges); a delay "
                     "form on the side of the tendons this contradicts is left out")
    for i, rd in enumerate(which["rounds"], start=1):
        base = " + ".join(rd["base"]) or "base model"
        lines.append(f"  round {i}: over {base} (held-out RMSE {rd['base_heldout_rmse']:.3f} deg)"
                     + (f" -> add {rd['chosen']}" if rd["chosen"] else " -> nothing added"))
        lines.append(f"    {'rank':>4s}  {'effect':11s} {'form':18s} {'held-out RMSE':>13s} {'shrink %':>9s} "
                     f"{'dBIC':>12s}  params")
        for c in rd["candidates"]:
            params = ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in c["params"].items())
            bic = f"{c['delta_bic']:.1f}" if c["delta_bic"] is not None else "-"
            lines.append(f"    {c['rank']:4d}  {c['name']:11s} {c.get('form', ''):18s} {_num(c['heldout_rmse'], 13, 3)} "
                         f"{_num(c['gain_pct'], 9, 1)} {bic:>12s}  {params}")
    for s in which["selected"]:
        extra = ""
        if s["interval95"]:
            extra += " 95 % " + ", ".join(f"{p}=[{a:.4g}, {b:.4g}]" for p, (a, b) in s["interval95"].items())
        if s["inclusion"] is not None:
            extra += f" inclusion {100 * s['inclusion']:.0f} %"
        lines.append(f"  added {s['name']}[{s['form']}](" + ", ".join(
            f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in s["params"].items()) + ")" + extra)
    hf = report["how_far"]
    lines += ["", "HOW FAR (held-out runs)",
              f"  RMSE {hf['rmse_before']:.3f} -> {hf['rmse_after']:.3f} deg ({hf['rmse_shrink_pct']:.1f} % shrink)",
              f"  PTPE {hf['ptpe_before']:.3f} -> {hf['ptpe_after']:.3f} deg ({hf['ptpe_shrink_pct']:.1f} % shrink)",
              "", report["verdict"]]
    return "\n".join(lines)
