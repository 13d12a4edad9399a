"""Evaluation of runs as in the paper's Tables I and II: PTPE, RMSE, grouping, improvement rates.

This module owns the metrics (section III of the paper), their grouping over run metadata, the
tables they make (plain data: columns and rows) and the pure-text formatters of those tables
(JSON and a LaTeX tabular laid out like the paper's; the generic ones are
:mod:`hystcli.report.table`'s; the figure like the paper's Figs. 6 and 7 is drawn by
:mod:`hystcli.report.evaluation`, from the runs this module picks for it). It never prints and
never imports typer or rich: ``hystcli.cli.metrics_cmds`` prints what it returns.

Definitions (the paper's words, section III-A):

- tracking error ``e = y - r`` per knob: measured tip angle minus desired tip angle (deg);
- PTPE, the peak-to-peak error ``max(e) - min(e)`` (deg);
- RMSE, ``sqrt(mean(e**2))`` (deg);
- each result is first computed per run and knob; a group pools every (run, knob) result that
  shares the grouping metadata (by default controller, shape, motion, so trials, catheters and
  knobs are pooled as the paper pools its two catheters and three trials) and reports
  ``(mean, std)``. The std is the *sample* standard deviation (``ddof=1``), the usual estimate
  of repeatability from a few trials; a group of one result has no std (``None``), never a
  made-up 0;
- the improvement rate of a controller against a baseline controller (``none`` and ``comp``) in
  the same group otherwise, ``(base - new) / base * 100`` (%), on the group means. That is how
  the paper's "Improvement rate" row is computed: at 45 deg, PTPE (61.9 - 24.3) / 61.9 = 60.74 %
  against No Compensation and (30.12 - 24.3) / 30.12 = 19.3 % against Compensation-Only.

Missing metadata never stops an evaluation: the value is ``"unknown"`` and a warning says so.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Iterable, Sequence

import numpy as np

from ..core.params import Shape
from ..core.run import Run
from ..errors import DataError, HystError
from .table import (FORMATS, Cell, Table, format_csv, format_latex_long, format_markdown,
                           format_text, latex_escape)

UNKNOWN = "unknown"
#: Metadata (and ``knob``) a group can be keyed on.
GROUP_FIELDS = ("controller", "shape", "motion", "catheter", "knob", "trial")
#: The paper's grouping: one cell of Table I per controller, shape and motion.
DEFAULT_GROUP_BY = ("controller", "shape", "motion")
#: Baseline controllers of the paper's improvement rates: No Compensation, Compensation-Only.
BASELINES = ("none", "comp")
_META_FIELDS = ("controller", "shape", "motion", "trial", "catheter")
_CONTROLLER_ORDER = ("none", "comp", "comp+shift")
_MOTION_ORDER = ("sweep", "periodic", "nonperiodic")
CONTROLLER_LABELS = {"none": "No Compensation", "comp": "Compensation-Only",
                     "comp+shift": "Compensation+Shift", "comp+shift+diag": "Compensation+Shift+Diagnosis"}


# --------------------------------------------------------------------------------------------
# metrics
# --------------------------------------------------------------------------------------------
def _as_error(error: Sequence[float] | np.ndarray) -> np.ndarray:
    e = np.asarray(error, dtype=np.float64).ravel()
    if e.size == 0:
        raise DataError("no samples: the error signal is empty")
    if not np.all(np.isfinite(e)):
        raise DataError("the error signal holds NaN or infinite values")
    return e


def ptpe(error: Sequence[float] | np.ndarray) -> float:
    """Peak-to-peak error, the paper's PTPE: ``max(e) - min(e)`` (deg).

    Parameters
    ----------
    error : array_like
        Tracking error ``e = y - r`` (deg).

    Returns
    -------
    float

    Raises
    ------
    DataError
        Empty or non-finite error.
    """
    e = _as_error(error)
    return float(e.max() - e.min())


def rmse(error: Sequence[float] | np.ndarray) -> float:
    """Root mean squared error ``sqrt(mean(e**2))`` (deg).

    Parameters
    ----------
    error : array_like
        Tracking error ``e = y - r`` (deg).

    Returns
    -------
    float

    Raises
    ------
    DataError
        Empty or non-finite error.
    """
    e = _as_error(error)
    return float(np.sqrt(np.mean(e * e)))


def improvement(base: float, new: float) -> float:
    """Improvement rate of ``new`` over ``base`` in %: ``(base - new) / base * 100``.

    Positive when ``new`` is the smaller error; 100 % when ``new`` is 0.

    Raises
    ------
    ValueError
        When ``base`` is 0 (no rate can be defined against a zero error).
    """
    if base == 0:
        raise ValueError("an improvement rate needs a non-zero baseline error")
    return (base - new) / base * 100.0


def mean_std(values: Sequence[float]) -> tuple[float, float | None]:
    """Mean and sample standard deviation (``ddof=1``) of pooled results.

    Returns ``(mean, None)`` for a single value: one trial says nothing about repeatability.
    """
    v = np.asarray(values, dtype=np.float64)
    if v.size == 0:
        raise DataError("no results to pool")
    mean = float(v.mean())
    return mean, (float(v.std(ddof=1)) if v.size > 1 else None)


# --------------------------------------------------------------------------------------------
# results
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class RunResult:
    """PTPE and RMSE of one knob of one run, with the run's metadata.

    Attributes
    ----------
    source : str
        The run's file (or ``<run N>``).
    knob : int
    controller, shape, motion, trial, catheter : str
        Run metadata (``"unknown"`` when absent); ``shape`` in the canonical form of
        :class:`~hystcli.core.params.Shape` when it parses.
    ptpe : float
        ``max(e) - min(e)``, deg.
    rmse : float
        ``sqrt(mean(e**2))``, deg.
    n : int
        Number of samples.
    """

    source: str
    knob: int
    controller: str
    shape: str
    motion: str
    trial: str
    catheter: str
    ptpe: float
    rmse: float
    n: int

    def value(self, name: str) -> str:
        """The grouping value of this result for ``name`` (one of :data:`GROUP_FIELDS`)."""
        return str(self.knob) if name == "knob" else getattr(self, name)

    def to_dict(self) -> dict:
        return {"source": self.source, "knob": self.knob, "catheter": self.catheter,
                "controller": self.controller, "shape": self.shape, "motion": self.motion,
                "trial": self.trial, "n": self.n, "ptpe": self.ptpe, "rmse": self.rmse}


@dataclass(frozen=True)
class Improvement:
    """Improvement rate (%) of a group against a baseline controller in the same group.

    ``None`` where the baseline's mean error is 0.
    """

    baseline: str
    ptpe: float | None
    rmse: float | None


@dataclass(frozen=True)
class GroupResult:
    """Pooled results of the (run, knob) results sharing one set of grouping values.

    Attributes
    ----------
    key : tuple of (str, str)
        ``(field, value)`` for each grouping field, in the order of ``group_by``.
    n : int
        Number of pooled (run, knob) results.
    ptpe_mean, rmse_mean : float
        Means (deg).
    ptpe_std, rmse_std : float or None
        Sample standard deviations (``ddof=1``, deg); ``None`` when ``n == 1``.
    improvements : tuple of Improvement
        Against ``none`` and/or ``comp`` (see the module docstring); empty for a baseline
        without a lower baseline, or when ``controller`` is not a grouping field.
    """

    key: tuple[tuple[str, str], ...]
    n: int
    ptpe_mean: float
    ptpe_std: float | None
    rmse_mean: float
    rmse_std: float | None
    improvements: tuple[Improvement, ...] = ()

    def value(self, name: str) -> str:
        """This group's value for grouping field ``name``."""
        for k, v in self.key:
            if k == name:
                return v
        raise KeyError(name)

    def improvement(self, baseline: str) -> Improvement | None:
        """The improvement against ``baseline``, or ``None`` when there is none."""
        return next((i for i in self.improvements if i.baseline == baseline), None)

    def to_dict(self) -> dict:
        return {"key": dict(self.key), "n": self.n,
                "ptpe": {"mean": self.ptpe_mean, "std": self.ptpe_std},
                "rmse": {"mean": self.rmse_mean, "std": self.rmse_std},
                "improvement": {i.baseline: {"ptpe": i.ptpe, "rmse": i.rmse} for i in self.improvements}}


@dataclass(frozen=True)
class Evaluation:
    """What :func:`evaluate_runs` returns: per (run, knob) results and their groups.

    Attributes
    ----------
    results : tuple of RunResult
    groups : tuple of GroupResult
        Sorted: controllers none, comp, comp+shift, then others; straight shaft first, then by
        total curvature; motions sweep, periodic, nonperiodic, then others; ``unknown`` last.
    group_by : tuple of str
    warnings : tuple of str
        Things the user should know (missing metadata, skipped knobs); never fatal.
    """

    results: tuple[RunResult, ...]
    groups: tuple[GroupResult, ...]
    group_by: tuple[str, ...]
    warnings: tuple[str, ...] = ()

    def group(self, **values: str) -> GroupResult:
        """The group whose grouping values include ``values`` (e.g. ``controller="comp"``).

        Raises
        ------
        KeyError
            When no group, or more than one, matches.
        """
        found = [g for g in self.groups
                 if all(dict(g.key).get(k) == str(v) for k, v in values.items())]
        if len(found) != 1:
            raise KeyError(f"{len(found)} groups match {values}")
        return found[0]

    def summary(self) -> str:
        """The groups' table as text (what ``hyst evaluate`` prints), then the warnings."""
        return "\n".join([format_text(group_table(self))] + [f"warning: {w}" for w in self.warnings])

    def plot(self, runs: Sequence[Run]):  # noqa: ANN201 - matplotlib.figure.Figure, imported only when drawn
        """The paper's Figs. 6 and 7 for the runs evaluated: time and input against output.

        Parameters
        ----------
        runs : sequence of Run
            The runs given to :func:`evaluate_runs` (the result keeps their errors, not their
            samples); one run per controller stands for each (motion, shape, knob) column.

        Returns
        -------
        matplotlib.figure.Figure
            What ``hyst evaluate --plot`` saves (:func:`evaluation_figure`).
        """
        from .evaluation import evaluation_axes

        return evaluation_axes(figure_columns(runs))

    def to_dict(self) -> dict:
        return {
            "format": "hyst-evaluation",
            "group_by": list(self.group_by),
            "definitions": {
                "error": "y - r (deg), per run and knob",
                "ptpe": "max(error) - min(error) (deg)",
                "rmse": "sqrt(mean(error^2)) (deg)",
                "std": "sample standard deviation (ddof=1) over the pooled run-knob results; "
                       "null for a group of one",
                "improvement": "(base - new) / base * 100 (%), on group means, against controller "
                               "none and comp in the same group",
            },
            "runs": [r.to_dict() for r in self.results],
            "groups": [g.to_dict() for g in self.groups],
            "warnings": list(self.warnings),
        }


# --------------------------------------------------------------------------------------------
# evaluation
# --------------------------------------------------------------------------------------------
def parse_group_by(text: str | Iterable[str]) -> tuple[str, ...]:
    """Validate grouping fields (``"controller,shape"`` or a list); duplicates dropped.

    Raises
    ------
    DataError
        On a field that is not one of :data:`GROUP_FIELDS`.
    """
    items = text.split(",") if isinstance(text, str) else list(text)
    out: list[str] = []
    for item in items:
        name = item.strip().lower()
        if not name:
            continue
        if name not in GROUP_FIELDS:
            raise DataError(f"cannot group by {item.strip()!r}: choose among {', '.join(GROUP_FIELDS)}")
        if name not in out:
            out.append(name)
    return tuple(out)


def canonical_shape(text: str) -> str:
    """The canonical form of a ``shape`` value, so ``alpha=45`` and ``alpha=45.0,theta=0`` group
    together; a value that does not parse is kept as written."""
    try:
        return str(Shape.parse(text))
    except HystError:
        return text


def _meta_value(run: Run, name: str) -> str | None:
    v = run.meta.get(name)
    if v is None or not str(v).strip():
        return None
    v = str(v).strip()
    if name == "shape":
        return canonical_shape(v)
    if name == "trial":
        try:  # "1.0" and "1" are the same trial
            f = float(v)
            if f.is_integer():
                return str(int(f))
        except ValueError:
            pass
    return v


def _evaluable_knobs(run: Run, source: str, warnings: list[str]) -> list[int]:
    knobs = [k for k in (1, 2) if f"y{k}" in run and f"r{k}" in run]
    half = [(k, f"r{k}" if f"y{k}" in run else f"y{k}") for k in (1, 2)
            if (f"y{k}" in run) != (f"r{k}" in run)]
    if not knobs:
        if half:
            k, missing = half[0]
            raise DataError(f"{source}: missing column {missing!r} (evaluate needs the measured tip "
                            f"angle y{k} and the reference r{k} of a knob)")
        raise DataError(f"{source}: missing columns 'y1' and 'r1' (or 'y2' and 'r2'): evaluate needs "
                        f"a measured tip angle y<k> and a reference r<k> for at least one knob")
    for k, missing in half:
        warnings.append(f"{source}: knob {k} not evaluated: no column {missing!r}")
    return knobs


def _rank(name: str, value: str) -> tuple:
    """Sort key of a grouping value: the paper's order where it has one, ``unknown`` last."""
    if value == UNKNOWN:
        return (2, 0.0, value)
    if name == "controller":
        order = _CONTROLLER_ORDER
    elif name == "motion":
        order = _MOTION_ORDER
    else:
        order = ()
    if value in order:
        return (0, float(order.index(value)), "")
    if name == "shape":
        try:
            return (0, Shape.parse(value).total_curvature, value)
        except HystError:
            return (1, 0.0, value)
    try:
        return (0, float(value), value)
    except ValueError:
        return (1, 0.0, value)


def evaluate_runs(runs: Sequence[Run], group_by: Iterable[str] = DEFAULT_GROUP_BY) -> Evaluation:
    """PTPE and RMSE per run and knob, pooled by metadata, with improvement rates.

    Parameters
    ----------
    runs : sequence of Run
        Each needs ``y<k>`` and ``r<k>`` for at least one knob ``k``; runs of different
        catheters, shapes and controllers may be mixed (they are grouping keys).
    group_by : iterable of str
        Grouping fields among :data:`GROUP_FIELDS`; the default is the paper's table cells
        (controller, shape, motion), pooling trials, catheters and knobs. Empty pools all.

    Returns
    -------
    Evaluation

    Raises
    ------
    DataError
        No runs; a run without any knob's ``y<k>`` and ``r<k>`` (names the file and the missing
        column); a non-finite value; a bad grouping field.
    """
    group_by = parse_group_by(group_by)
    if not runs:
        raise DataError("no runs to evaluate")
    warnings: list[str] = []
    missing_meta: dict[str, list[str]] = {}
    results: list[RunResult] = []
    for i, run in enumerate(runs):
        source = run.source or f"<run {i + 1}>"
        meta = {}
        for name in _META_FIELDS:
            v = _meta_value(run, name)
            if v is None:
                v = UNKNOWN
                if name in group_by:
                    missing_meta.setdefault(name, []).append(source)
            meta[name] = v
        for k in _evaluable_knobs(run, source, warnings):
            y, r = run[f"y{k}"], run[f"r{k}"]
            e = y - r
            if not np.all(np.isfinite(e)):
                col = f"y{k}" if not np.all(np.isfinite(y)) else f"r{k}"
                raise DataError(f"{source}: column {col!r} holds NaN or infinite values")
            results.append(RunResult(source=source, knob=k, ptpe=ptpe(e), rmse=rmse(e), n=int(e.size),
                                     **meta))
    for name, sources in missing_meta.items():
        shown = ", ".join(sources[:3]) + (f" and {len(sources) - 3} more" if len(sources) > 3 else "")
        warnings.append(f"{len(sources)} run(s) have no {name!r} metadata (grouped as 'unknown'): {shown}")

    pooled: dict[tuple[str, ...], list[RunResult]] = {}
    for res in results:
        pooled.setdefault(tuple(res.value(f) for f in group_by), []).append(res)
    stats: dict[tuple[str, ...], tuple] = {}
    for key, members in pooled.items():
        p_mean, p_std = mean_std([m.ptpe for m in members])
        r_mean, r_std = mean_std([m.rmse for m in members])
        stats[key] = (len(members), p_mean, p_std, r_mean, r_std)

    groups = []
    ci = group_by.index("controller") if "controller" in group_by else None
    for key in sorted(stats, key=lambda kk: tuple(_rank(f, v) for f, v in zip(group_by, kk))):
        n, p_mean, p_std, r_mean, r_std = stats[key]
        imps = []
        if ci is not None and key[ci] not in (UNKNOWN, "none"):
            bases = ("none",) if key[ci] == "comp" else BASELINES
            for base in bases:
                bkey = key[:ci] + (base,) + key[ci + 1:]
                if bkey in stats:
                    b = stats[bkey]
                    imps.append(Improvement(base, None if b[1] == 0 else improvement(b[1], p_mean),
                                            None if b[3] == 0 else improvement(b[3], r_mean)))
        groups.append(GroupResult(tuple(zip(group_by, key)), n, p_mean, p_std, r_mean, r_std, tuple(imps)))
    return Evaluation(tuple(results), tuple(groups), group_by, tuple(warnings))


evaluate = evaluate_runs
"""The library's name of :func:`evaluate_runs` (``hystcli.evaluate(runs)``)."""


# --------------------------------------------------------------------------------------------
# the figure: which run stands for which panel (the drawing is hystcli.report.evaluation's)
# --------------------------------------------------------------------------------------------
def figure_columns(runs: Sequence[Run]) -> list[tuple[tuple[str, str, int], list[tuple[str, str, Run]]]]:
    """The figure's columns: one per (motion, shape, knob) present, each with one run per
    controller (the first catheter and trial, as the paper shows "one catheter"), in the order of
    the tables, each controller with its label."""
    entries = []
    for i, run in enumerate(runs):
        source = run.source or f"<run {i + 1}>"
        meta = {n: (_meta_value(run, n) or UNKNOWN) for n in _META_FIELDS}
        for k in _evaluable_knobs(run, source, []):
            entries.append((meta, k, run))
    entries.sort(key=lambda e: (_rank("catheter", e[0]["catheter"]), _rank("trial", e[0]["trial"])))
    columns: dict[tuple[str, str, int], dict[str, Run]] = {}
    for meta, k, run in entries:
        col = columns.setdefault((meta["motion"], meta["shape"], k), {})
        col.setdefault(meta["controller"], run)
    order = sorted(columns, key=lambda c: (_rank("motion", c[0]), _rank("shape", c[1]), c[2]))
    if not order:
        raise DataError("nothing to draw: no run with a tip column y1 or y2 and its reference")
    return [(c, [(ctrl, CONTROLLER_LABELS.get(ctrl, ctrl), columns[c][ctrl])
                 for ctrl in sorted(columns[c], key=lambda x: _rank("controller", x))]) for c in order]


def evaluation_figure(runs: Sequence[Run], fmt: str = "png") -> bytes:
    """:meth:`Evaluation.plot`'s figure as file bytes in ``fmt`` (``png``, ``pdf`` or ``svg``),
    the same bytes for the same runs (``hyst evaluate --plot``, the demo's figures).

    Raises
    ------
    DataError
        Another format; no run with a tip column and its reference.
    """
    from .evaluation import evaluation_axes
    from .figures import PLOT_FORMATS, figure_bytes

    if fmt not in PLOT_FORMATS:
        raise DataError(f"cannot draw a {fmt!r} figure: choose among {', '.join(PLOT_FORMATS)}")
    return figure_bytes(evaluation_axes(figure_columns(runs)), fmt)


# --------------------------------------------------------------------------------------------
# tables: plain data, then pure-text formatters
# --------------------------------------------------------------------------------------------


def group_table(evaluation: Evaluation) -> Table:
    """One row per group: grouping values, n, PTPE and RMSE (mean, std), improvement rates."""
    cols = list(evaluation.group_by) + ["n", "ptpe_mean", "ptpe_std", "rmse_mean", "rmse_std"]
    heads = list(evaluation.group_by) + ["n", "PTPE mean", "PTPE std", "RMSE mean", "RMSE std"]
    with_imp = "controller" in evaluation.group_by
    if with_imp:
        for base in BASELINES:
            cols += [f"ptpe_improvement_vs_{base}", f"rmse_improvement_vs_{base}"]
            heads += [f"PTPE vs {base} %", f"RMSE vs {base} %"]
    rows = []
    for g in evaluation.groups:
        row: list[Cell] = [v for _, v in g.key] + [g.n, g.ptpe_mean, g.ptpe_std, g.rmse_mean, g.rmse_std]
        if with_imp:
            for base in BASELINES:
                imp = g.improvement(base)
                row += [imp.ptpe, imp.rmse] if imp else [None, None]
        rows.append(tuple(row))
    notes = ("PTPE and RMSE of y - r in deg: mean and sample std (ddof=1) over the pooled run-knob "
             "results (n); '-' where not defined",)
    if with_imp:
        notes += ("improvement % = (base - new) / base * 100 on the means, against controller none "
                  "and comp in the same group",)
    return Table(tuple(cols), tuple(heads), tuple(rows), notes, keys=max(1, len(evaluation.group_by)))


def run_table(evaluation: Evaluation) -> Table:
    """One row per run and knob."""
    cols = ("source", "knob", "catheter", "controller", "shape", "motion", "trial", "n", "ptpe", "rmse")
    heads = cols[:8] + ("PTPE", "RMSE")
    rows = tuple((r.source, r.knob, r.catheter, r.controller, r.shape, r.motion, r.trial, r.n,
                  r.ptpe, r.rmse) for r in evaluation.results)
    return Table(cols, heads, rows, ("PTPE and RMSE of y - r per run and knob, deg",), keys=2)


def format_json(evaluation: Evaluation) -> str:
    """The whole evaluation (runs, groups, definitions, warnings) as JSON."""
    return json.dumps(evaluation.to_dict(), indent=2, allow_nan=False) + "\n"


def _latex_shape(value: str) -> str:
    try:
        shape = Shape.parse(value)
    except HystError:
        return latex_escape(value)
    if not shape.segments:
        return r"Straight ($\alpha = 0^\circ$)"
    if len(shape.segments) == 1 and shape.segments[0].theta == 0:
        return rf"$\alpha = {shape.segments[0].alpha:g}^\circ$"
    parts = []
    for i, s in enumerate(shape.segments, 1):
        parts.append(rf"$\alpha_{i} = {s.alpha:g}^\circ$, $\theta_{i} = {s.theta:g}^\circ$")
    return ", ".join(parts)


def _latex_label(name: str, value: str) -> str:
    if name == "motion":
        return {"periodic": "Periodic inputs", "nonperiodic": "Non-periodic inputs",
                "sweep": "Sweep"}.get(value, f"motion {latex_escape(value)}")
    if name == "shape":
        return _latex_shape(value)
    return f"{name} {latex_escape(value)}"


def _pair(mean: float, std: float | None, digits: int) -> str:
    return f"({mean:.{digits}f}, {'-' if std is None else f'{std:.{digits}f}'})"


def format_latex(evaluation: Evaluation, digits: int = 1) -> str:
    """LaTeX tabular(s) laid out like the paper's Tables I and II.

    Needs ``controller`` and ``shape`` among the grouping fields: rows are controllers, column
    pairs are shapes with cells ``(mean, std)`` for PTPE and RMSE, and a last "Improvement rate"
    row gives ``a and b``: the rate against No Compensation and against Compensation-Only. That
    row is given for each controller other than the baselines (the paper's proposed method);
    when only ``none`` and ``comp`` were run, for ``comp`` against ``none``. Each combination of
    the other grouping fields (motion, catheter, ...) gets its own tabular. Without
    ``controller`` and ``shape`` it falls back to one long tabular of :func:`group_table`.
    """
    gb = evaluation.group_by
    if "controller" not in gb or "shape" not in gb:
        return format_latex_long(group_table(evaluation), digits)
    others = [f for f in gb if f not in ("controller", "shape")]
    blocks: dict[tuple[str, ...], list[GroupResult]] = {}
    for g in evaluation.groups:
        blocks.setdefault(tuple(g.value(f) for f in others), []).append(g)
    out = []
    for okey, groups in blocks.items():
        shapes = list(dict.fromkeys(g.value("shape") for g in groups))
        controllers = list(dict.fromkeys(g.value("controller") for g in groups))
        cell = {(g.value("controller"), g.value("shape")): g for g in groups}
        ncol = 2 * len(shapes)
        spec = "|c||" + "||".join("c|c" for _ in shapes) + "|"
        title = ", ".join(_latex_label(f, v) for f, v in zip(others, okey)) or "All runs"
        lines = [r"\begin{tabular}{" + spec + "}",
                 r"\hline {\bf Test inputs} & \multicolumn{" + str(ncol) + r"}{|c|}{\bf " + title + r"} \\",
                 r"\hline {\bf Shaft shape} & " + " & ".join(
                     r"\multicolumn{2}{|c" + ("||" if i < len(shapes) - 1 else "|") + "}{" + _latex_shape(s) + "}"
                     for i, s in enumerate(shapes)) + r" \\",
                 r"\hline {\bf Metrics} & " + " & ".join(r"{\bf PTPE} & {\bf RMSE}" for _ in shapes)
                 + r" \\ \hline"]
        for c in controllers:
            cells = []
            for s in shapes:
                g = cell.get((c, s))
                cells += ([_pair(g.ptpe_mean, g.ptpe_std, digits), _pair(g.rmse_mean, g.rmse_std, digits)]
                          if g else ["-", "-"])
            label = latex_escape(CONTROLLER_LABELS.get(c, c)) + " (deg)"
            lines.append(f"{label} & " + " & ".join(cells) + r" \\ \hline")
        rated = [c for c in controllers if c not in BASELINES + (UNKNOWN,)] or \
                [c for c in controllers if c == "comp"]
        for c in rated:
            cells = []
            for s in shapes:
                g = cell.get((c, s))
                imps = [i for i in (g.improvements if g else ()) if i.baseline in BASELINES]
                for metric in ("ptpe", "rmse"):
                    vals = [getattr(i, metric) for i in imps]
                    cells.append(" and ".join("-" if v is None else f"{v:.{digits}f}" for v in vals) or "-")
            name = "" if len(rated) == 1 else f" of {latex_escape(CONTROLLER_LABELS.get(c, c))}"
            lines.append(rf"Improvement rate{name} ($\%$) & " + " & ".join(cells) + r" \\ \hline")
        lines.append(r"\end{tabular}")
        out.append("\n".join(lines))
    return "\n\n".join(out) + "\n"


def render(evaluation: Evaluation, fmt: str = "table", per_run: bool = False) -> str:
    """The evaluation as text in ``fmt`` (one of :data:`FORMATS`).

    ``per_run`` shows one row per run and knob instead of the groups (table, csv, markdown,
    latex); JSON always holds both.
    """
    if fmt == "json":
        return format_json(evaluation)
    if fmt == "latex" and not per_run:
        return format_latex(evaluation)
    table = run_table(evaluation) if per_run else group_table(evaluation)
    if fmt == "table":
        return format_text(table)
    if fmt == "csv":
        return format_csv(table)
    if fmt == "markdown":
        return format_markdown(table)
    if fmt == "latex":
        return format_latex_long(table, 2)
    raise ValueError(f"unknown format {fmt!r}: choose among {', '.join(FORMATS)}")


__all__ = [
    "BASELINES", "DEFAULT_GROUP_BY", "Evaluation", "GROUP_FIELDS", "GroupResult",
    "Improvement", "RunResult", "UNKNOWN", "evaluate", "evaluate_runs", "evaluation_figure", "figure_columns",
    "format_json", "format_latex", "group_table",
    "improvement", "mean_std", "parse_group_by", "ptpe", "render", "rmse", "run_table",
]
