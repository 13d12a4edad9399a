"""The experiment's tables beside the paper's (text, Markdown) and its figures, and the files `hyst
demo` writes."""
from __future__ import annotations

import textwrap
from pathlib import Path
from typing import Mapping, Sequence

from ..report import metrics
from ..errors import DataError
from ..io import all_or_none
from ..report.metrics import evaluation_figure
from ..report.table import TEXT_WIDTH, Table, format_markdown, format_text
from .experiment import Cell, ExperimentResult
from .scenarios import CONTROLLERS, PAPER_CELLS, PAPER_IMPROVEMENT, SCENARIOS, TOLERANCE


_LABELS = metrics.CONTROLLER_LABELS


def _pair(v: tuple[float, float | None] | None) -> str:
    if v is None:
        return "-"
    return f"({v[0]:.1f}, {v[1]:.1f})" if v[1] is not None else f"({v[0]:.1f}, -)"


def _ratio_text(c: Cell, metric: str) -> str:
    r = c.ratio(metric)
    if r is None:
        return "-"
    return f"{r:.2f} " + ("ok" if c.within(metric) else "MISS")


def comparison_table(result: ExperimentResult, table: str) -> Table:
    """Table I or II as rows: controller, shape, ours and the paper's (mean, std), ratio, mark."""
    cols = ("controller", "shape", "ptpe_ours", "ptpe_paper", "ptpe_ratio", "rmse_ours", "rmse_paper",
            "rmse_ratio")
    heads = ("controller", "shaft shape", "PTPE ours", "PTPE paper", "ours/paper",
             "RMSE ours", "RMSE paper", "ours/paper")
    rows = []
    # the paper's layout: one block of rows per controller, the shapes in order within it
    order = {c: i for i, c in enumerate(CONTROLLERS)}
    scen = {s.name: i for i, s in enumerate(SCENARIOS)}
    cells = sorted((c for c in result.table(table) if c.controller in order),
                   key=lambda c: (order[c.controller], scen.get(c.scenario, len(scen))))
    for c in cells:
        rows.append((_LABELS.get(c.controller, c.controller), c.scenario, _pair(c.ptpe), _pair(c.paper_ptpe),
                     _ratio_text(c, "ptpe"), _pair(c.rmse), _pair(c.paper_rmse), _ratio_text(c, "rmse")))
    for c in result.table(table):
        if c.controller != "comp+shift":
            continue
        ours = c.improvement
        paper = PAPER_IMPROVEMENT.get(c.scenario)

        def imp(metric: str) -> str:
            vals = [ours.get(b, {}).get(metric) for b in ("none", "comp")]
            return " and ".join("-" if v is None else f"{v:.1f}" for v in vals)

        def pimp(metric: str) -> str:
            return "-" if paper is None else " and ".join(f"{v:g}" for v in paper[metric])

        rows.append(("Improvement rate (%)", c.scenario, imp("ptpe"), pimp("ptpe"), "", imp("rmse"),
                     pimp("rmse"), ""))
    title = ("Table I: PTPE and RMSE for 1-DoF, periodic inputs" if table == "I"
             else "Table II: PTPE and RMSE for 2-DoF, non-periodic inputs")
    notes = (title,
             "(mean, std) in deg over catheters x knobs x trials; paper: Kim & Mansi, Table " + table
             + f"; ok = ours within {TOLERANCE:.0%} of the paper's mean; improvement rate of "
               "Compensation+Shift against No Compensation and Compensation-Only")
    return Table(cols, heads, tuple(rows), notes, keys=2)


def _effects_text(effects: Sequence[tuple[str, Mapping[str, float]]], forms: Sequence[str] = ()) -> str:
    # a form other than the family's first is named: deadzone(shift=...) is centre or centre-bend
    if not effects:
        return "none"
    forms = tuple(forms) or ("",) * len(effects)
    return ", ".join(f"{n}{f'[{f}]' if f else ''}(" + ", ".join(f"{k}={v:.3g}" for k, v in p.items()) + ")"
                     for (n, p), f in zip(effects, forms))


def beyond_table(result: ExperimentResult) -> Table:
    """Beyond the paper: Compensation+Shift with the diagnosed model beside the paper's.

    One row per bent scenario: the paper's Compensation+Shift RMSE and PTPE, ours, ours after
    the diagnosis (``comp+shift+diag``), and the target (half the paper's RMSE). The notes name
    the effects the diagnosis found per catheter beside the ones the catheter really has.
    """
    cols = ("scenario", "rmse_paper", "rmse_ours", "rmse_diag", "rmse_target", "met", "ptpe_paper",
            "ptpe_ours", "ptpe_diag")
    heads = ("shaft shape", "RMSE paper C+S", "RMSE ours C+S", "RMSE ours C+S+diagnosis", "target",
             "met", "PTPE paper C+S", "PTPE ours C+S", "PTPE ours C+S+diagnosis")
    rows = []
    for scenario, c, target in result.beyond():
        paper = PAPER_CELLS[("comp+shift", scenario)]
        ours = result.cell("comp+shift", scenario)  # ran wherever the diagnosed controller did
        rows.append((scenario, _pair(paper["rmse"]), _pair(ours.rmse), _pair(c.rmse), f"<= {target:.2f}",
                     "yes" if c.rmse[0] <= target else "NO", _pair(paper["ptpe"]), _pair(ours.ptpe),
                     _pair(c.ptpe)))
    notes = ["Beyond the paper: Compensation+Shift (C+S) with the model `hyst diagnose` augmented",
             "(mean, std) in deg; target: half the paper's C+S RMSE; the diagnosis is fitted on the "
             "C+S runs, the diagnosed controller runs on fresh trials"]
    for d in result.diagnoses:
        notes.append(f"{d.catheter}: diagnosis of {d.runs} C+S runs added {_effects_text(d.effects, d.forms)}; "
                     f"held-out tip RMSE {d.rmse_before:.2f} -> {d.rmse_after:.2f} deg ({d.holdout}); "
                     f"the catheter has {_effects_text(d.true_effects)}")
    return Table(cols, heads, tuple(rows), tuple(notes))


def shift_table(result: ExperimentResult) -> Table:
    """Algorithm 1 per catheter, scenario and knob: detected and true offsets."""
    cols = ("catheter", "scenario", "knob", "offset", "offset_lo", "offset_hi", "true_offset", "error", "edge",
            "edge_found_at", "true_edge", "edge_error", "travel")
    heads = ("catheter", "scenario", "knob", "offset", "low", "high", "true offset", "error", "edge", "found at",
             "true edge", "edge error", "travel")
    rows = tuple((s.catheter, s.scenario, s.knob, s.result.offset, s.result.offset_lo, s.result.offset_hi,
                  s.true_offset, s.error, s.result.edge, s.result.edge_found_at, s.true_edge,
                  s.edge_error, s.result.travel) if s.result is not None else
                 (s.catheter, s.scenario, s.knob, None, None, None, s.true_offset, None, "refused", None, None, None,
                  None) for s in result.shifts)
    return Table(cols, heads, rows, (
        "Algorithm 1 on the replays",
        "deg; low/high: the offset's 95 % interval; error = detected - true offset; edge error = found - true "
        "edge (the search's own error; the offset is measured from where the sweep's current took the same "
        "tendon up)"), keys=3)


def _section(table: Table, fmt: str) -> str:
    """One titled table: ``notes[0]`` is the title, ``notes[1]`` the note under it, any further
    notes a list below that."""
    title, note, *items = table.notes
    body = Table(table.columns, table.headers, table.rows, keys=table.keys)
    if fmt == "markdown":
        listed = "".join(f"- {line}\n" for line in items)
        return f"**{title}**\n\n" + format_markdown(body) + f"\n{note}\n" + (f"\n{listed}" if items else "")
    width = TEXT_WIDTH
    listed = "".join(textwrap.fill(line, width, initial_indent="  ", subsequent_indent="    ",
                                   break_on_hyphens=False) + "\n" for line in items)
    return (f"{title}\n\n" + format_text(body) + "\n"
            + textwrap.fill(note, width, break_on_hyphens=False) + f"\n{listed}")


def render(result: ExperimentResult, fmt: str = "table") -> str:
    """Tables I and II beside the paper's values, the diagnosed controller beside the paper's
    Compensation+Shift, and Algorithm 1's detections, as text (``table``, ``markdown``) or ``json``."""
    if fmt == "json":
        return result.to_json()
    if fmt not in ("table", "markdown"):
        raise DataError(f"unknown format {fmt!r}: choose among table, markdown, json")
    tables = [comparison_table(result, "I"), comparison_table(result, "II"), beyond_table(result),
              shift_table(result)]
    parts = [_section(t, fmt) for t in tables if t.rows]
    compared = result.compared()
    summary = f"{compared - len(result.misses())}/{compared} paper values matched within {TOLERANCE:.0%}"
    if result.beyond():
        met = len(result.beyond()) - len(result.beyond_misses())
        summary += f"; beyond the paper: {met}/{len(result.beyond())} diagnosed RMSE at most half the paper's"
    parts.append(summary + "\n")
    return "\n".join(parts)


FIGURES = {"fig6_periodic_1dof": ("I", 1), "fig7_nonperiodic_2dof": ("II", None)}
"""Figure files: the paper's Fig. 6 (1-DoF, one catheter, knob 1, each shape) and Fig. 7 (2-DoF)."""


def figures(result: ExperimentResult, fmt: str = "png") -> dict[str, bytes]:
    """Figures like the paper's Figs. 6 and 7 of the first catheter's first trial, as file bytes.

    Keys are file names (``fig6_periodic_1dof.png``, ``fig7_nonperiodic_2dof.png``); a figure
    whose scenarios were not run is left out.
    """
    if not result.runs:
        return {}
    first = result.runs[0].meta.get("catheter")
    out = {}
    for name, (table, knob) in FIGURES.items():
        scen = {s.name for s in SCENARIOS if s.table == table}
        sel = [r for r in result.runs
               if r.meta.get("scenario") in scen and r.meta.get("catheter") == first
               and r.meta.get("trial") == "1" and (knob is None or f"q{knob}" in r)]
        if sel:
            out[f"{name}.{fmt}"] = evaluation_figure(sel, fmt)
    return out


def write_outputs(result: ExperimentResult, out_dir: str | Path, with_figures: bool = True,
                  fmt: str = "png") -> list[Path]:
    """Write ``results.json``, ``tables.md`` and the figures into ``out_dir`` (atomically).

    Returns the paths written.
    """
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise DataError(f"{out}: exists and is not a directory")
    files: dict[str, bytes] = {"results.json": result.to_json().encode("utf-8"),
                               "tables.md": render(result, "markdown").encode("utf-8")}
    if with_figures:
        files.update(figures(result, fmt))
    out.mkdir(parents=True, exist_ok=True)
    # every file or none: an error leaves the folder's old results whole, not half replaced
    with all_or_none() as pending:
        for name, data in files.items():
            pending.write_bytes(out / name, data)
    return [out / name for name in files]


__all__ = [
    "BEYOND_FACTOR", "CONTROLLERS", "Cell", "DIAGNOSED", "DiagnosisRow", "PAPER_CELLS", "beyond_table", "DETECT_MAX_TRAVEL", "ExperimentResult", "PAPER_IMPROVEMENT", "PAPER_TABLE_I",
    "PAPER_TABLE_II", "SCENARIOS", "SCENARIOS_1DOF", "SCENARIO_2DOF", "Scenario", "ShiftRow", "TOLERANCE",
    "comparison_table", "figures", "identify_catheter", "record_replay", "record_sweep",
    "reference_nonperiodic", "reference_path", "reference_periodic", "render", "replay_motion",
    "replay_path", "run_protocol", "SAMPLE_DATA", "SAMPLE_DATA_SEED", "default_data_dir", "sample_data_runs", "shift_table",
    "sweep_path", "write_outputs",
]
