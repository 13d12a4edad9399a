"""Commands that read models: ``show`` (one model) and ``diff`` (two, side by side)."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from .app import FormatOpt, OutputFormat, PlotOpt, QuietOpt, command, echo_json, echo_table, info, prints, usage_error

ModelArg = Annotated[Path, typer.Argument(metavar="MODEL.json", help="Model JSON file.", show_default=False)]


@command("show", "Show a model: parameters, uncertainties, provenance",
         epilog="Example: hyst show shifted.json --plot envelopes.png")
def show_cmd(
    model_path: ModelArg,
    plot: PlotOpt = None,
    fmt: FormatOpt = OutputFormat.table,
    quiet: QuietOpt = False,
) -> None:
    """Show a model: each knob's parameters with their uncertainties, the edges they imply, what
    identification learnt from the current, the effects, the geometry and where it came from.

    --plot draws each knob's two envelopes against the knob angle (the loop every state lies in).
    csv gives the parameter table; json everything.
    """
    from .. import io
    from ..report import inspection

    if plot is not None and plot.suffix.lower().lstrip(".") not in ("png", "pdf", "svg"):
        usage_error(f"{plot} must end in .png, .pdf or .svg", "--plot")
    if plot is not None:
        io.check_not_input(plot, [model_path])
    model = io.load_model(model_path)
    if plot is not None:
        from ..report.figures import save_figure

        save_figure(inspection.envelope_figure(model), plot, inputs=[model_path])
    if not prints(fmt, quiet):
        return
    if fmt == OutputFormat.json:
        echo_json({"model": str(model_path), **inspection.model_summary(model)})
    elif fmt == OutputFormat.csv:
        echo_table(inspection.parameter_table(model), fmt, digits=4)
    else:
        if fmt == OutputFormat.table:
            typer.echo(_heading(model_path, model))
        tables = [inspection.parameter_table(model), inspection.identification_table(model),
                  inspection.effects_table(model)]
        for i, table in enumerate(t for t in tables if t is not None):
            if i:
                typer.echo("")
            echo_table(table, fmt, digits=3)
    if plot is not None:
        info(f"wrote {plot}", quiet)


def _heading(path: Path, model) -> str:  # noqa: ANN001 - model.Model
    meta = dict(model.meta)
    # the model's own record only: `created` when whatever wrote the model stated it, and the
    # source's modification time under its own name (never a file's time read here)
    labels = {"catheter": "catheter", "source": "source", "source_modified": "source modified",
              "created": "created", "shift_source": "shift source", "diagnosed_on": "diagnosed on"}
    bits = [f"{label} {meta[k]}" for k, label in labels.items() if k in meta]
    geometry = ("" if model.geometry is None else
                f"; geometry beta_catheter {model.geometry.beta_catheter_mm:g} mm, "
                f"beta_knob {model.geometry.beta_knob_mm:g} mm")
    return f"{path}: knobs {', '.join(map(str, model.knobs))}" + (f" ({', '.join(bits)})" if bits else "") \
        + geometry + "\n"


@command("diff", "Compare two models, parameter by parameter",
         epilog="Example: hyst diff model.json shifted.json   (straight shaft against bent)")
def diff_cmd(
    a: Annotated[Path, typer.Argument(metavar="A.json", help="First model.", show_default=False)],
    b: Annotated[Path, typer.Argument(metavar="B.json", help="Second model.", show_default=False)],
    all_rows: Annotated[bool, typer.Option("--all", help="Every parameter, not only those that differ.")] = False,
    fmt: FormatOpt = OutputFormat.table,
    quiet: QuietOpt = False,
) -> None:
    """Compare two models: per knob and parameter (derived edges included), then geometry and
    effects, the value in A, in B and B - A.

    By default only what differs is listed (e.g. the offset and the shifted edges between a
    straight-shaft model and the one detect-shift wrote).
    """
    from .. import io
    from ..report import inspection

    table = inspection.diff_table(io.load_model(a), io.load_model(b))
    if not all_rows:
        table = inspection.changed_rows(table)
    if not prints(fmt, quiet):
        return
    if fmt == OutputFormat.table and not table.rows:
        typer.echo(f"{a} and {b} hold the same parameters")
        return
    echo_table(table, fmt, digits=3)
