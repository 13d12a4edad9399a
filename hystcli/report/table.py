"""Tables as plain data and their pure-text formatters: aligned text, Markdown, CSV, JSON, LaTeX.

Every command that prints a table builds a :class:`Table` and renders it with
:func:`format_table` in the ``--format`` asked for; the evaluation's own layouts (the paper's
Tables I and II) are :mod:`hystcli.report.metrics`'. Nothing here prints or imports typer or rich.
"""
from __future__ import annotations

import csv
import io as _io
import json
import re
import textwrap
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

Cell = str | int | float | None


@dataclass(frozen=True)
class Table:
    """A table as plain data.

    Attributes
    ----------
    columns : tuple of str
        Machine names of the columns (CSV header).
    headers : tuple of str
        Human headers (text and Markdown).
    rows : tuple of tuple
        Cells: str, int, float or None (not applicable).
    notes : tuple of str
        Lines below the table.
    keys : int
        Leading columns that name a row: a text table too wide for its width repeats them beside
        each slice of the other columns (:func:`format_text`).
    """

    columns: tuple[str, ...]
    headers: tuple[str, ...]
    rows: tuple[tuple[Cell, ...], ...]
    notes: tuple[str, ...] = field(default=())
    keys: int = 1


def _cell_text(value: Cell, digits: int) -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:.{digits}f}"
    return str(value)


def _numeric(value: Cell) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


TEXT_WIDTH = 100
"""Widest line of a text table: wider tables are cut into slices of columns, the row's key columns
repeated beside each, and notes are wrapped."""


def _slices(widths: Sequence[int], keys: int, width: int) -> list[list[int]]:
    """Column indices of each slice of a text table: the key columns, then as many of the others as
    fit ``width`` (at least one each)."""
    keys = min(keys, len(widths))
    base = sum(widths[:keys]) + 2 * keys
    out: list[list[int]] = []
    used = base
    for j in range(keys, len(widths)):
        if out and out[-1][keys:] and used + widths[j] > width:
            used = base
            out.append(list(range(keys)))
        if not out:
            out.append(list(range(keys)))
        out[-1].append(j)
        used += widths[j] + 2
    return out or [list(range(len(widths)))]


def format_text(table: Table, digits: int = 2, width: int = TEXT_WIDTH) -> str:
    """Aligned plain text: strings left-aligned, numbers right-aligned, notes below.

    A table wider than ``width`` comes in slices of columns one under the other, each with the
    table's key columns (:attr:`Table.keys`); notes are wrapped to ``width``.
    """
    cells = [[_cell_text(v, digits) for v in row] for row in table.rows]
    numeric = [any(_numeric(row[j]) for row in table.rows) for j in range(len(table.headers))]
    widths = [max([len(h)] + [len(r[j]) for r in cells]) for j, h in enumerate(table.headers)]

    def line(items: Sequence[str], cols: Sequence[int]) -> str:
        return "  ".join(items[j].rjust(widths[j]) if numeric[j] else items[j].ljust(widths[j])
                         for j in cols).rstrip()

    out: list[str] = []
    for cols in _slices(widths, table.keys, width):
        if out:
            out.append("")
        out += [line(table.headers, cols), line(["-" * w for w in widths], cols)]
        out += [line(r, cols) for r in cells]
    if table.notes:
        out += [""] + [wrapped for note in table.notes
                       for wrapped in textwrap.wrap(note, width, break_on_hyphens=False) or [""]]
    return "\n".join(out) + "\n"


def format_markdown(table: Table, digits: int = 2) -> str:
    """A GitHub Markdown table (numbers right-aligned)."""
    numeric = [any(_numeric(row[j]) for row in table.rows) for j in range(len(table.headers))]

    def esc(s: str) -> str:
        return s.replace("|", "\\|")

    out = ["| " + " | ".join(esc(h) for h in table.headers) + " |",
           "|" + "|".join("---:" if n else "---" for n in numeric) + "|"]
    out += ["| " + " | ".join(esc(_cell_text(v, digits)) for v in row) + " |" for row in table.rows]
    return "\n".join(out) + "\n"


def format_csv(table: Table) -> str:
    """CSV with the machine column names; floats at full precision, empty where not defined."""
    buf = _io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(table.columns)
    for row in table.rows:
        w.writerow(["" if v is None else (repr(v) if isinstance(v, float) else v) for v in row])
    return buf.getvalue()


_LATEX_SPECIAL = {"\\": r"\textbackslash{}", "&": r"\&", "%": r"\%", "$": r"\$", "#": r"\#",
                  "_": r"\_", "{": r"\{", "}": r"\}", "~": r"\textasciitilde{}", "^": r"\textasciicircum{}"}


def latex_escape(text: str) -> str:
    """Escape LaTeX's special characters in plain text."""
    return re.sub(r"[\\&%$#_{}~^]", lambda m: _LATEX_SPECIAL[m.group()], text)


def format_latex_long(table: Table, digits: int) -> str:
    spec = "|" + "|".join("r" if any(_numeric(r[j]) for r in table.rows) else "l"
                          for j in range(len(table.headers))) + "|"
    lines = [r"\begin{tabular}{" + spec + "}", r"\hline",
             " & ".join(latex_escape(h) for h in table.headers) + r" \\ \hline"]
    for row in table.rows:
        lines.append(" & ".join(latex_escape(_cell_text(v, digits)) for v in row) + r" \\")
    lines += [r"\hline", r"\end{tabular}"]
    return "\n".join(lines) + "\n"


FORMATS = ("table", "json", "csv", "markdown", "latex")


def format_table(table: Table, fmt: str = "table", digits: int = 2) -> str:
    """Any :class:`Table` as text in ``fmt`` (one of :data:`FORMATS`).

    JSON is ``{"columns": [...], "rows": [{column: value}], "notes": [...]}`` at full precision;
    the other formats are those of the evaluation tables (``latex`` as one long tabular).
    """
    if fmt == "table":
        return format_text(table, digits)
    if fmt == "csv":
        return format_csv(table)
    if fmt == "markdown":
        return format_markdown(table, digits)
    if fmt == "latex":
        return format_latex_long(table, digits)
    if fmt == "json":
        rows = [dict(zip(table.columns, row)) for row in table.rows]
        return json.dumps({"columns": list(table.columns), "rows": rows, "notes": list(table.notes)},
                          indent=2, allow_nan=False, default=_json_scalar) + "\n"
    raise ValueError(f"unknown format {fmt!r}: choose among {', '.join(FORMATS)}")


def _json_scalar(obj: object) -> object:
    if isinstance(obj, np.generic):
        return obj.item()
    raise TypeError(f"{type(obj).__name__} is not JSON serialisable")


__all__ = ["Cell", "FORMATS", "TEXT_WIDTH", "Table", "format_csv", "format_latex_long", "format_markdown",
           "format_table", "format_text", "latex_escape"]
