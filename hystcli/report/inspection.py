"""Reading and comparing models: what ``hyst show`` and ``hyst diff`` print, and the envelope figure.

A model file holds numbers a user wants to see side by side: each knob's parameters with the
one-sigma uncertainty identification gave them, the edges they imply (the far edges
``dhat_pos``/``dhat_neg`` of docs/design.md section 3 and the shifted edges ``d~ = d + offset``),
what identification learnt from the current (the slopes and level ``detect-shift`` uses), the
effects ``diagnose`` added, the geometry. Two models of one catheter (straight against shifted,
before against after diagnosis) differ in a few of these: :func:`diff_table` lines them up.

Everything here returns plain data (:class:`hystcli.report.table.Table`, dicts) or a matplotlib
Figure; the command line renders and saves it.
"""
from __future__ import annotations

from typing import Any, Sequence

from ..core.model import Model
from ..core.params import KnobIdentification, KnobModel, PARAM_NAMES
from .table import Table

DERIVED = ("dhat_pos", "dhat_neg", "shifted_d_pos", "shifted_d_neg")
"""Edges a knob's parameters imply (deg): the far edges of the dead zone, the shifted edges."""

_IDENT_FIELDS = ("method", "q_min", "q_max", "rmse")
_CALIBRATION_FIELDS = ("current_sign", "slope_dead_zone", "slope_loaded", "current_dead_zone")


def _ident_values(ident: KnobIdentification) -> dict[str, Any]:
    return {**{name: getattr(ident, name) for name in _IDENT_FIELDS},
            **{name: getattr(ident.calibration, name) for name in _CALIBRATION_FIELDS}}


def _knob_values(knob: KnobModel) -> dict[str, float]:
    return {**knob.params(), **{name: float(getattr(knob, name)) for name in DERIVED}}


def parameter_table(model: Model) -> Table:
    """One row per knob and parameter: value and the interval identification gave it.

    The eight parameters of the model, then the derived edges; the interval is empty where the
    model has none (given by hand, derived) and open (``-inf``/``inf``) where the sweep did not fix
    the parameter on that side.
    """
    rows = []
    for k, knob in model.knobs.items():
        ident = model.identification.get(k)
        est = dict(ident.estimates) if ident is not None else {}
        for name, value in _knob_values(knob).items():
            e = est.get(name)
            note = ("derived" if name in DERIVED else
                    f"not fixed: {e.reason}" if e is not None and not e.fixed and e.reason else
                    "not fixed by the sweep" if e is not None and not e.fixed else
                    "assumed" if e is not None and e.lo == e.hi else "")
            rows.append((k, name, value, None if e is None else e.lo, None if e is None else e.hi, note))
    return Table(("knob", "parameter", "value", "lo", "hi", "note"),
                 ("knob", "parameter", "value", "low", "high", "note"), tuple(rows),
                 ("deg (omega: deg of tip per deg of knob); low/high: the interval identification gave "
                  "(95 % profile likelihood; inf: the sweep says nothing that way); dhat: far edges of the "
                  "dead zone; shifted_d = d + offset, the edges Algorithm 1 found",))


def identification_table(model: Model) -> Table | None:
    """What identification learnt per knob (range, RMSE, current slopes and level, Algorithm 1's
    default thresholds), or None when the model has no identification."""
    if not model.identification:
        return None
    rows = []
    for k, ident in model.identification.items():
        rows.append((k, *_ident_values(ident).values()))
    return Table(("knob",) + _IDENT_FIELDS + _CALIBRATION_FIELDS,
                 ("knob", "method", "q min", "q max", "RMSE", "current", "dC/dq dead zone", "dC/dq loaded",
                  "C dead zone"), tuple(rows),
                 ("identified range q (deg); RMSE of the tip fit (deg); the current's sign convention, its "
                  "slopes per deg (load coordinates) and no-load level in the current's unit (mA)",))


def effects_table(model: Model) -> Table | None:
    """One row per effect parameter (the effects ``hyst diagnose`` added), or None without effects."""
    if not model.effects:
        return None
    rows = tuple((e.name, p, float(v)) for e in model.effects for p, v in e.params.items())
    return Table(("effect", "parameter", "value"), ("effect", "parameter", "value"), rows,
                 ("unmodelled effects of docs/design.md section 8, run by predict and compensate",))


def model_summary(model: Model) -> dict[str, Any]:
    """Everything :func:`parameter_table` and the others show, as one JSON-ready dict."""
    out: dict[str, Any] = {"knobs": {}}
    for k, knob in model.knobs.items():
        ident = model.identification.get(k)
        out["knobs"][str(k)] = {
            "params": knob.params(),
            "derived": {name: float(getattr(knob, name)) for name in DERIVED},
            "intervals": {n: e.to_dict() for n, e in ident.estimates.items()} if ident is not None else {},
            "unfixed": list(ident.unfixed) if ident is not None else [],
            "identification": (None if ident is None else
                               _ident_values(ident)),
        }
    out["effects"] = [{"name": e.name, "params": dict(e.params)} for e in model.effects]
    out["geometry"] = (None if model.geometry is None else
                       {"beta_catheter_mm": model.geometry.beta_catheter_mm,
                        "beta_knob_mm": model.geometry.beta_knob_mm})
    out["meta"] = {str(k): v for k, v in model.meta.items()}
    return out


def diff_table(a: Model, b: Model) -> Table:
    """Two models line by line: per knob and parameter (derived edges included), then geometry and
    effect parameters: the value in ``a``, in ``b``, and ``b - a`` (``-`` where one lacks it)."""
    rows: list[tuple] = []
    for k in sorted(set(a.knobs) | set(b.knobs)):
        va = _knob_values(a.knobs[k]) if k in a.knobs else {}
        vb = _knob_values(b.knobs[k]) if k in b.knobs else {}
        for name in (*PARAM_NAMES, *DERIVED):
            rows.append(_diff_row(f"knob {k}", name, va.get(name), vb.get(name)))
    ga = {} if a.geometry is None else vars(a.geometry)
    gb = {} if b.geometry is None else vars(b.geometry)
    for name in ("beta_catheter_mm", "beta_knob_mm"):
        if name in ga or name in gb:
            rows.append(_diff_row("geometry", name, ga.get(name), gb.get(name)))
    ea = {(e.name, p): float(v) for e in a.effects for p, v in e.params.items()}
    eb = {(e.name, p): float(v) for e in b.effects for p, v in e.params.items()}
    for key in list(dict.fromkeys([*ea, *eb])):
        rows.append(_diff_row(f"effect {key[0]}", key[1], ea.get(key), eb.get(key)))
    return Table(("item", "parameter", "a", "b", "b_minus_a"), ("item", "parameter", "a", "b", "b - a"),
                 tuple(rows), ("deg (omega: deg/deg, geometry: mm); '-': not in that model",))


def _diff_row(item: str, name: str, va: float | None, vb: float | None) -> tuple:
    return item, name, va, vb, (vb - va) if va is not None and vb is not None else None


def changed_rows(table: Table, tol: float = 1e-12) -> Table:
    """The rows of a :func:`diff_table` whose values differ (or that one model lacks)."""
    keep = tuple(r for r in table.rows if r[4] is None or abs(r[4]) > tol)
    return Table(table.columns, table.headers, keep, table.notes)


def envelope_figure(model: Model, q_range: Sequence[float] | None = None):  # noqa: ANN201 - matplotlib Figure
    """Each knob's two envelopes against the knob angle, shifted by its offset (``hyst show --plot``).

    The ascending envelope ``f_up`` (loading: lines L2-L4) and the descending ``f_dn``
    (unloading: L8-L6) of docs/design.md section 3, with the shifted dead-zone edges and the far edges
    marked; between them lies every state the knob can hold.

    Parameters
    ----------
    model : Model
    q_range : (float, float), optional
        Knob angles to draw (deg); default the identified range widened to show both edges.

    Returns
    -------
    matplotlib.figure.Figure
        In the style of :mod:`hystcli.report.style`; :func:`hystcli.report.figures.save_figure`
        writes it.
    """
    import numpy as np

    from . import style

    ks = list(model.knobs)
    fig, axes = style.new_figure(1, len(ks))
    for ax, k in zip(axes[0], ks):
        knob = model.knobs[k]
        edges = [knob.shifted_d_neg, knob.shifted_d_pos, knob.dhat_pos + knob.offset, knob.dhat_neg + knob.offset]
        ident = model.identification.get(k)
        if q_range is not None:
            lo, hi = q_range
        else:
            lo = min(edges + ([ident.q_min] if ident else [])) - 15.0
            hi = max(edges + ([ident.q_max] if ident else [])) + 15.0
        q = np.linspace(lo, hi, 801)
        u = q - knob.offset
        ax.plot(q, knob.f_up(u), **style.line("loading"), label="f_up (loading)")
        ax.plot(q, knob.f_dn(u), **style.line("unloading"), label="f_dn (unloading)")
        ax.fill_between(q, knob.f_up(u), knob.f_dn(u), **style.band("region"), label="states the knob can hold")
        ax.axvline(knob.shifted_d_neg, **style.line("edge"), label="dead-zone edges d~_neg, d~_pos")
        ax.axvline(knob.shifted_d_pos, **style.line("edge"))
        ax.set_xlabel(f"knob angle q{k} (deg)")
        ax.set_ylabel(f"tip angle y{k} (deg)")
        unfixed_b = [n for n in ("b_neg", "b_pos") if ident is not None and n in ident.unfixed]
        style.title(ax, f"knob {k}: d {knob.d_neg:.2f} / {knob.d_pos:.2f}, b {knob.b_neg:.2f} / {knob.b_pos:.2f},\n"
                        f"omega {knob.omega:.3f}, offset {knob.offset:+.2f}"
                    + (f"\n{' and '.join(unfixed_b)} not fixed by the sweep: drawn as 0" if unfixed_b else ""))
        style.legend(ax, loc="upper left")
    style.finish(fig)
    return fig


__all__ = ["DERIVED", "changed_rows", "diff_table", "effects_table", "envelope_figure", "identification_table",
           "model_summary", "parameter_table"]
