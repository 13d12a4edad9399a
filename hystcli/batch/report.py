"""``hyst report``: what a results table of ``hyst batch`` says across runs.

Three views of one table:

- **summary**: per group (a metadata or manifest column, e.g. ``meta_catheter`` or
  ``manifest_robot``): runs, failures, and the mean, sample std (ddof=1) and median of each value
  column;
- **drift**: each value against a time column (a date, a time stamp or a number; e.g.
  ``manifest_day`` or ``meta_trial``), per group: first and last value and the least-squares
  slope per day (per unit for a number), with a figure (:func:`drift_figure`);
- **outliers**: runs whose value is far from the others by the modified z-score of Iglewicz and
  Hoaglin, ``z = 0.6745 (x - median) / MAD`` with ``MAD = median |x - median|``, flagged beyond
  ``|z| > 3.5`` (the threshold they recommend), within each group. Median and MAD, not mean and std: a few bad runs
  cannot hide themselves by inflating the spread. A column whose MAD is 0 flags nothing.

The value columns default to the command's headline numbers (:data:`HEADLINE`): RMSE and PTPE
for evaluate, the parameters and fit RMSE for identify, the offsets for detect-shift, the gap
shrink for diagnose. Only runs with status ``ok`` enter any figure.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any, Sequence

from .. import DataError

HEADLINE = {
    "evaluate": (r"k\d+_rmse", r"k\d+_ptpe"),
    "identify": (r"k\d+_(d_pos|d_neg|b_pos|b_neg|omega|h_pos|h_neg)", r"k\d+_rmse"),
    "detect-shift": (r"k\d+_offset",),
    "diagnose": (r"gap_shrink_pct", r"k\d+_rmse_before", r"k\d+_rmse_after"),
}
"""Each command's default value columns, as patterns over the table's column names."""

Z_LIMIT = 3.5
"""Modified z-score beyond which a run is an outlier (Iglewicz and Hoaglin)."""

MAD_SCALE = 0.6745
"""The normal distribution's MAD is 0.6745 of its std: the factor that makes z comparable to a z-score."""


@dataclass(frozen=True)
class Report:
    """What :func:`report` finds.

    Attributes
    ----------
    command : str
        The batch command that wrote the table.
    runs, ok : int
        Rows of the table; those with status ``ok``.
    values : tuple of str
        The value columns reported.
    by : str or None
        The grouping column.
    summary : tuple of dict
        Per group: ``{"group", "runs", "failed", "<value>_mean", "<value>_std", "<value>_median"}``.
    time : str or None
        The time column of the drift.
    drift : tuple of dict
        Per group and value: ``{"group", "value", "n", "first", "last", "slope", "unit"}``.
    outliers : tuple of dict
        ``{"path", "group", "value", "x", "median", "mad", "z"}``, by ``|z|`` descending; each run
        judged within its group (all runs without ``by``).
    notes : tuple of str
        What could not be computed and why.
    """

    command: str
    runs: int
    ok: int
    values: tuple[str, ...]
    by: str | None
    summary: tuple[dict, ...]
    time: str | None
    drift: tuple[dict, ...]
    outliers: tuple[dict, ...]
    notes: tuple[str, ...] = ()

    def to_dict(self) -> dict:
        return {"format": "hyst-report", "command": self.command, "runs": self.runs, "ok": self.ok,
                "values": list(self.values), "by": self.by, "summary": list(self.summary), "time": self.time,
                "drift": list(self.drift), "outliers": list(self.outliers), "z_limit": Z_LIMIT,
                "outlier_rule": "|0.6745 (x - median) / MAD| > 3.5, MAD = median |x - median|",
                "notes": list(self.notes)}


def _num(x: Any) -> float | None:
    try:
        x = float(x)
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) else None


def value_columns(df: Any, command: str, asked: Sequence[str] = ()) -> list[str]:
    """The value columns: those asked for (each must be a numeric column), else the headline ones."""
    import pandas as pd

    if asked:
        for c in asked:
            if c not in df.columns:
                raise DataError(f"the table has no column {c!r} (its columns: {', '.join(df.columns)})")
            if not pd.api.types.is_numeric_dtype(df[c]):
                raise DataError(f"column {c!r} is not numeric")
        return list(asked)
    pats = [re.compile(p + "$") for p in HEADLINE.get(command, ())]
    return [c for c in df.columns if any(p.match(c) for p in pats) and pd.api.types.is_numeric_dtype(df[c])]


def _time_axis(series: Any) -> tuple[Any, str]:
    # a date or time stamp -> days since the first; a number -> itself; anything else refused
    import pandas as pd

    if pd.api.types.is_numeric_dtype(series):
        return series.astype(float), "per unit"
    parsed = pd.to_datetime(series, errors="coerce", utc=True)
    if parsed.notna().sum() == 0:
        num = pd.to_numeric(series, errors="coerce")
        if num.notna().sum() == 0:
            raise DataError(f"time column {series.name!r} holds neither dates nor numbers")
        return num.astype(float), "per unit"
    days = (parsed - parsed.min()).dt.total_seconds() / 86400.0
    return days, "per day"


def _groups(df: Any, by: str | None) -> list[tuple[str, Any]]:
    """``[(name, rows)]``: one group ``all`` without ``by``, else one per value (missing: ``unknown``), sorted."""
    if by is None:
        return [("all", df)]
    return [(str(g), d) for g, d in df.groupby(df[by].fillna("unknown").astype(str), sort=True)]


def robust_z(values: Sequence[float]) -> tuple[list[float | None], float, float]:
    """The modified z-score of each value (None where missing), with the median and MAD."""
    import numpy as np

    x = np.array([np.nan if v is None else float(v) for v in values])
    good = x[np.isfinite(x)]
    if good.size == 0:
        return [None] * len(x), math.nan, math.nan
    med = float(np.median(good))
    mad = float(np.median(np.abs(good - med)))
    if mad == 0:
        return [None if not np.isfinite(v) else 0.0 for v in x], med, mad
    return [None if not np.isfinite(v) else MAD_SCALE * (v - med) / mad for v in x], med, mad


def report(df: Any, by: str | None = None, time: str | None = None, values: Sequence[str] = (),
           z_limit: float = Z_LIMIT) -> Report:
    """Summaries, drift and outliers of a results table (see the module docstring).

    Parameters
    ----------
    df : pandas.DataFrame
        From :func:`hystcli.batch.table.read_table`.
    by : str, optional
        Grouping column (e.g. ``meta_catheter``); default: one group, ``all``.
    time : str, optional
        Time column for the drift; default: no drift.
    values : sequence of str
        Value columns; default: the command's headline columns.
    z_limit : float
        Outlier threshold on the modified z-score.

    Returns
    -------
    Report

    Raises
    ------
    DataError
        A grouping, time or value column the table lacks; a table of several commands.
    """
    commands = sorted(set(df["command"].dropna())) if "command" in df.columns else []
    if len(commands) > 1:
        raise DataError(f"the table mixes commands ({', '.join(commands)}); report one at a time")
    command = commands[0] if commands else "unknown"
    for name, col in (("--by", by), ("--time", time)):
        if col is not None and col not in df.columns:
            meta = [c for c in df.columns if c.startswith(("meta_", "manifest_"))]
            raise DataError(f"{name}: the table has no column {col!r} (metadata columns: {', '.join(meta) or 'none'})")
    vals = value_columns(df, command, values)
    ok = df[df["status"] == "ok"]
    notes: list[str] = []
    if not vals:
        notes.append("no numeric value column to report")
    summary = []
    for g, d in _groups(df, by):
        good = d[d["status"] == "ok"]
        row: dict[str, Any] = {"group": g, "runs": int(len(d)), "failed": int((d["status"] != "ok").sum())}
        for c in vals:
            x = good[c].dropna().astype(float)
            row[f"{c}_mean"] = _num(x.mean()) if len(x) else None
            row[f"{c}_std"] = _num(x.std(ddof=1)) if len(x) > 1 else None
            row[f"{c}_median"] = _num(x.median()) if len(x) else None
        summary.append(row)

    drift = []
    if time is not None and len(ok):
        axis, unit = _time_axis(ok[time])
        for g, d in _groups(ok, by):
            t_all = axis.loc[d.index]
            for c in vals:
                sel = d[c].notna() & t_all.notna()
                t, x = t_all[sel].to_numpy(float), d.loc[sel, c].to_numpy(float)
                if len(x) == 0:
                    continue
                order = sorted(range(len(t)), key=lambda i: (t[i], i))
                slope = None
                if len(set(t)) > 1:
                    tm, xm = t.mean(), x.mean()
                    slope = _num(((t - tm) * (x - xm)).sum() / ((t - tm) ** 2).sum())
                drift.append({"group": g, "value": c, "n": int(len(x)), "first": _num(x[order[0]]),
                              "last": _num(x[order[-1]]), "slope": slope, "unit": unit})

    outliers = []
    # within each group: a run is judged against its peers (its robot, its condition), so that
    # a group that differs as a whole is a finding of the summary, not a list of outliers
    for g, d in _groups(ok, by):
        for c in vals:
            z, med, mad = robust_z(d[c].tolist())
            if mad == 0:
                notes.append(f"{c}{'' if by is None else f' in {g}'}: MAD is 0 (half the runs or more share one "
                             "value); no outliers flagged")
                continue
            for path, x, zi in zip(d["path"], d[c], z):
                if zi is not None and abs(zi) > z_limit:
                    outliers.append({"path": str(path), "group": g, "value": c, "x": _num(x), "median": _num(med),
                                     "mad": _num(mad), "z": _num(zi)})
    outliers.sort(key=lambda o: (-abs(o["z"]), o["path"], o["value"]))
    return Report(command, int(len(df)), int(len(ok)), tuple(vals), by, tuple(summary), time, tuple(drift),
                  tuple(outliers), tuple(notes))


def drift_figure(df: Any, time: str, values: Sequence[str], by: str | None = None) -> Any:
    """Each value against the time column (one panel per value, one line per group): a
    matplotlib Figure in the style of :mod:`hystcli.report.style`, for the caller to save
    (:func:`hystcli.report.figures.save_figure`)."""
    from ..report import style

    ok = df[df["status"] == "ok"]
    axis, unit = _time_axis(ok[time])
    n = max(1, len(values))
    fig, axes = style.new_figure(n, 1, sharex=True)
    groups = _groups(ok, by)
    for ax, c in zip(axes[:, 0], values):
        for i, (g, d) in enumerate(groups):
            sel = d[c].notna()
            t = axis.loc[d.index][sel]
            order = t.sort_values(kind="mergesort").index
            ax.plot(axis.loc[order], d.loc[order, c], marker="o", ms=style.MARKER_SIZE,
                    **style.line("measured", color=style.series_colour(i)), label=str(g))
        ax.set_ylabel(c)
    axes[-1, 0].set_xlabel(f"{time} ({'days since the first' if unit == 'per day' else 'value'})")
    if by is not None and len(groups) <= 12:
        style.legend(axes[0, 0], title=by, title_fontsize=style.LEGEND_SIZE)
    style.finish(fig)
    return fig
