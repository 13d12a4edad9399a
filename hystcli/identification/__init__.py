"""Identification of a catheter's straight-shaft hysteresis model from a sweep (``hyst identify``).

Identification serves prediction. With the tip angle recorded, the model is the loop that best
predicts the record (:mod:`.tip`, output error) and every parameter carries its profile-likelihood
interval (:mod:`.intervals`): a parameter the record cannot fix is an interval, open where the
record says nothing (``b_pos >= 5.4``), not a refusal. The record is refused only when the knob
never moves the tip, or when no loop predicts it better than a static line through it (both by
BIC). A misfit the tracker's noise does not explain is a warning that names ``hyst diagnose``.

With the motor current alone (the paper's procedure) the dead-zone edges are where the current
shows each tendon taken up, and the backlash where it shows a load held after a reversal
(:mod:`hystcli.signal.reading`), each with its interval; ``omega`` is given (the paper's 1.45 by
default) and the heights follow a stated assumption.

Either way the current's reading (when the sweep has a current) is stored for Algorithm 1: where
each tendon is taken up, the no-load levels, the slopes, the noise, the sign convention.

:mod:`.sweep` checks what a record offers before anything is fitted.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from ..core.model import Model
from ..core.params import Calibration, KnobIdentification, KnobModel, PAPER_OMEGA
from ..core.run import Run
from ..errors import IdentificationError
from ..estimate import Estimate
from ..settings import DEFAULT, Settings
from ..signal.condition import condition
from ..signal.reading import read_current
from ..signal.result import CurrentReading
from .sweep import MIN_SAMPLES, SweepCheck, check_sweep, find_reversals
from .tip import PARAMS as TIP_PARAMS
from .tip import TipFit, fit_tip, systematic_misfit

__all__ = ["Identification", "KnobFit", "SweepCheck", "MIN_SAMPLES", "check_sweep", "current_levels",
           "find_reversals", "identification_figure", "identify", "plot_identification"]


@dataclass(frozen=True)
class KnobFit:
    """Identification of one knob.

    Attributes
    ----------
    knob : int
    model : KnobModel
        The identified straight-shaft model (offset 0).
    estimates : dict of str to Estimate
        Each of the seven parameters with its interval; ``fixed`` False where the record does not
        fix it (the value is then one inside the interval that predicts the record as well).
    rmse : float or None
        RMSE of the model against the measured tip (deg), when the run has one.
    method : str
        ``"tip"`` (output-error fit) or ``"current"``.
    ident : KnobIdentification or None
        What detect-shift needs of the sweep (stored in the model file).
    n_reversals, n_cycles : int
    current : CurrentReading or None
    tip : TipFit or None
    warnings : tuple of str
    """

    knob: int
    model: KnobModel
    estimates: dict[str, Estimate]
    rmse: float | None
    method: str
    ident: KnobIdentification | None
    n_reversals: int
    n_cycles: int = 0
    current: CurrentReading | None = field(default=None, repr=False)
    tip: TipFit | None = field(default=None, repr=False)
    warnings: tuple[str, ...] = ()

    @property
    def stderr(self) -> dict[str, float]:
        """One-sigma uncertainties of the fixed parameters (from their intervals)."""
        return {n: e.stderr for n, e in self.estimates.items() if e.fixed}

    @property
    def unfixed(self) -> tuple[str, ...]:
        """Parameters the record does not fix."""
        return tuple(n for n, e in self.estimates.items() if not e.fixed)

    def summary(self, warnings: bool = True) -> str:
        """A few lines: method, RMSE, each parameter with its interval, the warnings (unless
        ``warnings`` is False: the CLI prints them once, on stderr)."""
        head = f"knob {self.knob} ({self.method}" + (f", RMSE {self.rmse:.3f} deg" if self.rmse is not None else "") + ")"
        lines = [head]
        for name, e in self.estimates.items():
            lines.append("  " + e.describe(name, unit="" if name == "omega" else "deg", digits=3 if name == "omega" else 2))
        lines += [f"  warning: {w}" for w in self.warnings] if warnings else []
        return "\n".join(lines)


@dataclass(frozen=True)
class Identification:
    """Result of :func:`identify`: one :class:`KnobFit` per knob and the assembled model."""

    fits: dict[int, KnobFit]
    model: Model

    def summary(self, warnings: bool = True) -> str:
        """Each knob's :meth:`KnobFit.summary`."""
        return "\n".join(f.summary(warnings) for f in self.fits.values())

    @property
    def intervals(self) -> dict[int, dict[str, Estimate]]:
        return {k: f.estimates for k, f in self.fits.items()}

    def plot(self, run: Run):  # noqa: ANN201 - matplotlib.figure.Figure, imported only when drawn
        """The sweep's measured loop and current against the identified model, per knob.

        Parameters
        ----------
        run : Run
            The sweep this was identified from (the result keeps the fit, not the record).

        Returns
        -------
        matplotlib.figure.Figure
            What ``hyst identify --plot`` saves (:func:`identification_figure`); save it with
            :func:`hystcli.report.figures.save_figure`.
        """
        return identification_figure(run, self)


def _knob_list(run: Run, knobs, use_tip: bool = False) -> list[int]:  # noqa: ANN001
    where = f"{run.source}: " if run.source else ""
    if knobs is None:
        ks = [k for k in (1, 2) if f"q{k}" in run and (f"c{k}" in run or (use_tip and f"y{k}" in run))]
        if not ks:
            need = "q1,c1 or q2,c2 (or q1,y1 / q2,y2 for the tip fit)" if use_tip else "q1,c1 or q2,c2"
            raise IdentificationError(f"{where}no knob to identify: needs a pair of columns {need} "
                                      f"(columns: {', '.join(run.columns) or 'none'})")
        return ks
    ks = []
    for k in knobs:
        try:
            k = int(k)
        except (TypeError, ValueError):
            raise IdentificationError(f"knob {k!r} is not 1 or 2") from None
        if k not in (1, 2):
            raise IdentificationError(f"knob {k} is not a knob of a two-knob catheter (1 or 2)")
        if k not in ks:
            ks.append(k)
    if not ks:
        raise IdentificationError("no knob to identify")
    return ks


def identify(run: Run, knobs: Sequence[int] | None = None, *, settings: Settings = DEFAULT,
             omega: float | None = None, use_tip: bool = True) -> Identification:
    """Identify the straight-shaft hysteresis model of each knob from a sweep.

    Parameters
    ----------
    run : Run
        The sweep: ``t``, ``q<k>``, and ``y<k>`` and/or ``c<k>`` per knob.
    knobs : sequence of int, optional
        Knobs to identify; default every ``k`` with ``q<k>`` and ``c<k>`` (or ``y<k>``).
    settings : Settings
        Interval level, robust loss, current reading (:class:`hystcli.settings.Settings`).
    omega : float, optional
        Slope used on the current-only path (default the paper's 1.45); ignored by the tip fit.
    use_tip : bool
        Fit through the tip angle when the run has it.

    Returns
    -------
    Identification

    Raises
    ------
    IdentificationError
        A record that cannot identify a knob: columns missing, the knob never moves the tip, no
        loop beats a static line, or (current only) the current shows no tendon taken up.
    """
    if omega is not None and not (math.isfinite(float(omega)) and float(omega) > 0):
        raise IdentificationError(f"omega must be a positive number, got {omega}")
    ks = _knob_list(run, knobs, use_tip)
    fits = {k: _identify_knob(run, k, settings, omega, use_tip) for k in ks}
    methods = sorted({f.method for f in fits.values()})
    meta = {"method": methods[0] if len(methods) == 1 else ",".join(f"{k}:{f.method}" for k, f in fits.items())}
    model = Model({k: f.model for k, f in fits.items()}, meta=meta,
                  identification={k: f.ident for k, f in fits.items() if f.ident is not None})
    return Identification(fits, model)


def conditioned_current(run: Run, k: int, filter_hz: float | None) -> np.ndarray | None:
    """Knob ``k``'s motor current despiked and low-passed, or None when the run has none."""
    name = f"c{k}"
    if name not in run:
        return None
    fs = run.sample_rate if "t" in run and len(run) > 1 else None
    return condition(np.asarray(run[name], float), fs, filter_hz)


def _identify_knob(run: Run, k: int, settings: Settings, omega: float | None, use_tip: bool) -> KnobFit:
    where = f"{run.source}: knob {k}" if run.source else f"knob {k}"
    tip_path = use_tip and f"y{k}" in run
    chk = check_sweep(run, k, need_current=not tip_path)
    q = np.ascontiguousarray(run[f"q{k}"], dtype=float)
    t = np.asarray(run["t"], float) if "t" in run else np.arange(q.size, dtype=float)
    c = conditioned_current(run, k, settings.filter_hz)
    reading = read_current(q, c, t, settings, conditioned=True) if c is not None else None
    if tip_path:
        y = np.asarray(run[f"y{k}"], float)
        tip, estimates, warnings = _tip_path(q, y, t, chk, settings, where)
        model, method = tip.model, "tip"
        rmse = float(np.sqrt(np.mean((model.forward(q, float(y[0])) - y) ** 2)))
        if reading is not None:
            warnings += _edge_gaps(reading, model, settings, where)
    else:
        tip = None
        model, estimates, warnings = _current_path(reading, omega, chk, where)
        method = "current"
        rmse = None
        if f"y{k}" in run:
            rmse = float(np.sqrt(np.mean((model.forward(q, float(run[f"y{k}"][0])) - run[f"y{k}"]) ** 2)))
    ident = _identification(reading, chk, estimates, rmse, method)
    return KnobFit(knob=k, model=model, estimates=estimates, rmse=rmse, method=method, ident=ident,
                   n_reversals=int(chk.reversals.size), n_cycles=chk.n_cycles, current=reading, tip=tip,
                   warnings=tuple(warnings))


# --------------------------------------------------------------------------------------------
# the tip path
# --------------------------------------------------------------------------------------------
def _tip_path(q: np.ndarray, y: np.ndarray, t: np.ndarray, chk: SweepCheck, settings: Settings,
              where: str) -> tuple[TipFit, dict[str, Estimate], list[str]]:
    from .intervals import tip_intervals

    fit = fit_tip(q, y, keep=chk.reversals)
    _refuse_static(q, y, fit, where)
    estimates, fit = tip_intervals(fit, settings)
    warnings = []
    fs = 1.0 / float(np.median(np.diff(t))) if t.size > 1 else 1.0
    resid = fit.loop.predict(q) - y
    rms, departs = systematic_misfit(resid, fs, fit.tau, fit.noise, settings.level)
    if departs:
        warnings.append(f"{where}: the tip departs from the dead-zone + backlash loop by {rms:.2f} deg RMS over "
                        f"quarter seconds, more than the tracker's noise ({fit.noise:.2f} deg) explains; no dead-zone + backlash "
                        "loop fits the record better, so this one is kept: run hyst diagnose to find what it leaves out")
    bottom, top = fit.walls
    if bottom is not None or top is not None:
        at = " and ".join(f"{lvl:+.2f} deg" for lvl in (bottom, top) if lvl is not None)
        warnings.append(f"{where}: a wall holds the tip at {at} while the knob drives on (a clipped loop fits the "
                        "record better by BIC): the model is the free tip's; hyst diagnose can add the contact")
    for name, e in estimates.items():
        if not e.fixed:
            warnings.append(f"{where}: the record does not fix {e.describe(name, '' if name == 'omega' else 'deg')}")
    return fit, estimates, warnings


def _refuse_static(q: np.ndarray, y: np.ndarray, fit: TipFit, where: str) -> None:
    """Refuse a record whose tip a constant or a static line predicts as well as the loop (BIC).

    The three models are scored alike: on the fit's samples, with the loop's soft-L1 loss, noise
    scale and correlation time, each fitted under that loss: a constant (1 parameter), a line
    through the record (2), the loop (8, its walls more).
    """
    from scipy.optimize import least_squares

    qf, yf = fit.q, fit.y
    fs, noise = fit.f_scale, max(fit.noise, 1e-12)
    tau = max(fit.tau, 1.0)
    n_eff = max(qf.size / tau, 2.0)

    def deviance(r: np.ndarray) -> float:
        return float(np.sum(2.0 * (np.sqrt(1.0 + (r / fs) ** 2) - 1.0))) * fs ** 2 / noise ** 2 / tau

    def robust(design: np.ndarray) -> tuple[float, np.ndarray]:
        coef0, *_ = np.linalg.lstsq(design, yf, rcond=None)
        got = least_squares(lambda c: design @ c - yf, coef0, loss="soft_l1", f_scale=fs)
        return deviance(design @ got.x - yf), got.x

    dev_const, _ = robust(np.ones((qf.size, 1)))
    dev_line, coef = robust(np.column_stack([np.ones_like(qf), qf]))
    bic_const = dev_const + math.log(n_eff)
    bic_line = dev_line + 2 * math.log(n_eff)
    bic_loop = deviance(fit.loop.predict(qf) - yf) + (8 + sum(map(bool, fit.loop.sides))) * math.log(n_eff)
    if bic_const <= min(bic_line, bic_loop):
        raise IdentificationError(f"{where}: the knob never moves the tip: over {np.ptp(qf):.1f} deg of knob the tip "
                                  f"stays within its noise ({np.std(yf):.3f} deg about its mean); nothing to identify")
    if bic_line <= bic_loop:
        raise IdentificationError(f"{where}: no dead-zone + backlash loop predicts the tip better than a static line "
                                  f"through it (slope {coef[1]:.3f}): the record shows no hysteresis to identify")


def _edge_gaps(reading: CurrentReading, model: KnobModel, settings: Settings, where: str) -> list[str]:
    """Warnings where the current's take-up lies farther from the tip's edge than one tendon event
    allows (:attr:`Settings.max_edge_gap`): Algorithm 1 will refuse an offset from that side."""
    out = []
    for side, name in (("pos", "d_pos"), ("neg", "d_neg")):
        e = reading.edges.get(side)
        if e is None or not e.fixed:
            continue
        gap = e.value - getattr(model, name)
        if abs(gap) > settings.max_edge_gap:
            out.append(f"{where}: the motor current takes the {'positive' if side == 'pos' else 'negative'} tendon "
                       f"up at {e.value:.2f} deg where the tip's {name} is {getattr(model, name):.2f} deg "
                       f"({gap:+.2f} deg apart, more than {settings.max_edge_gap:g}): that current edge is not the "
                       f"tip's, and detect-shift will take no offset from it")
    return out


# --------------------------------------------------------------------------------------------
# the current path
# --------------------------------------------------------------------------------------------
def _heights_assumed(d_pos: float, d_neg: float, b_pos: float, b_neg: float, omega: float) -> tuple[float, float]:
    """Dead-zone heights when no tip angle was measured.

    The tip moves only while a tendon is taut, so on the way up the tip's dead zone should begin
    where the negative tendon goes slack, ``dhat_pos = d_neg``, i.e. ``h_neg - h_pos = omega b_neg``,
    and on the way down ``h_neg - h_pos = omega b_pos``; both hold only when the backlashes are
    equal, so the mean is taken (raised if needed to keep the model valid) and the loop is
    centred on the straight tip, ``h_pos = -h_neg``.
    """
    dh = max(0.5 * (b_pos + b_neg), max(b_pos, b_neg) - (d_pos - d_neg), 0.0)
    return -0.5 * omega * dh, 0.5 * omega * dh


def _current_path(reading: CurrentReading | None, omega: float | None, chk: SweepCheck,
                  where: str) -> tuple[KnobModel, dict[str, Estimate], list[str]]:
    if reading is None or not reading.edges:
        why = "" if reading is None else "; ".join(v for k, v in reading.notes.items() if k.startswith("d_"))
        raise IdentificationError(f"{where}: the motor current shows no tendon taken up ({why}); "
                                  + ("the current was read as a magnitude; " if reading is not None
                                     and reading.sign == "magnitude" else "")
                                  + "identify with the tip angle measured, or sweep past the dead-zone edges")
    level = next(iter(reading.edges.values())).level
    warnings: list[str] = []
    est: dict[str, Estimate] = {}
    for side, name, reach in (("pos", "d_pos", chk.q_max), ("neg", "d_neg", chk.q_min)):
        e = reading.edges.get(side)
        if e is None:
            # the edge lies beyond where the sweep took that tendon up: bounded by the reach
            e = Estimate(reach, reach if side == "pos" else -math.inf, math.inf if side == "pos" else reach,
                         level, False, reading.notes.get(name, "not shown by the current"))
        est[name] = e
    for side, name in (("pos", "b_pos"), ("neg", "b_neg")):
        b = reading.backlash.get(side)
        est[name] = b if b is not None else Estimate(0.0, 0.0, math.inf, level, False,
                                                     reading.notes.get(name, "not shown by the current"))
    w = PAPER_OMEGA if omega is None else float(omega)
    est["omega"] = Estimate(w, w, w, level, True, None)
    d_pos, d_neg = est["d_pos"].value, est["d_neg"].value
    if d_pos <= d_neg:
        raise IdentificationError(f"{where}: the current's take-ups put d_pos {d_pos:.2f} at or below d_neg "
                                  f"{d_neg:.2f} deg: it shows no dead zone between the tendons")
    h_pos, h_neg = _heights_assumed(d_pos, d_neg, est["b_pos"].value, est["b_neg"].value, w)
    est["h_pos"] = Estimate(h_pos, h_pos, h_pos, level, True, None)
    est["h_neg"] = Estimate(h_neg, h_neg, h_neg, level, True, None)
    model = KnobModel(d_pos=d_pos, d_neg=d_neg, b_pos=est["b_pos"].value, b_neg=est["b_neg"].value, omega=w,
                      h_pos=h_pos, h_neg=h_neg)
    for name in ("d_pos", "d_neg", "b_pos", "b_neg"):
        if not est[name].fixed:
            warnings.append(f"{where}: the current does not fix {name} ({est[name].reason})")
    warnings.append(f"{where}: omega {w:g} is assumed and the heights follow the current-only assumption "
                    "(h_pos = -h_neg, the mean backlash); identify with the tip angle measured to fit them")
    return model, {n: est[n] for n in TIP_PARAMS}, warnings


# --------------------------------------------------------------------------------------------
# what detect-shift keeps
# --------------------------------------------------------------------------------------------
def _identification(reading: CurrentReading | None, chk: SweepCheck, estimates: dict[str, Estimate],
                    rmse: float | None, method: str) -> KnobIdentification:
    calibration = Calibration()
    if reading is not None:
        kw = dict(current_sign=reading.sign, current_edges=dict(reading.edges),
                  no_load_rising=reading.no_load.get(1), no_load_falling=reading.no_load.get(-1),
                  slope_dead_zone=float(reading.dead_slope), slope_loaded_pos=reading.loaded_slope.get("pos"),
                  slope_loaded_neg=reading.loaded_slope.get("neg"), edge_level_pos=reading.edge_level.get("pos"),
                  edge_level_neg=reading.edge_level.get("neg"), current_noise=float(reading.noise),
                  current_min=reading.current_range[0], current_max=reading.current_range[1])
        if reading.ripple is not None:
            kw.update(cogging_period=reading.ripple.period, cogging_sin=reading.ripple.sin,
                      cogging_cos=reading.ripple.cos)
        calibration = Calibration(**kw)
    return KnobIdentification(q_min=chk.q_min, q_max=chk.q_max, method=method, rmse=rmse,
                              estimates=dict(estimates), calibration=calibration)


def current_levels(run: Run, knob: int, model: KnobModel, settings: Settings = DEFAULT) -> KnobIdentification:
    """What Algorithm 1 needs of a knob's current, read on a straight-shaft record, for a model that
    did not come from this record (given by hand, or identified elsewhere).

    Raises
    ------
    IdentificationError
        A record without the knob's command and current, or one that never reverses.
    """
    k = int(knob)
    chk = check_sweep(run, k, need_current=True)
    q = np.ascontiguousarray(run[f"q{k}"], dtype=float)
    t = np.asarray(run["t"], float)
    reading = read_current(q, np.asarray(run[f"c{k}"], float), t, settings)
    est = {n: Estimate(float(getattr(model, n)), float(getattr(model, n)), float(getattr(model, n)))
           for n in TIP_PARAMS}
    return _identification(reading, chk, est, None, "given")


# --------------------------------------------------------------------------------------------
# figure
# --------------------------------------------------------------------------------------------
def plot_identification(run: Run, result: Identification, path) -> None:  # noqa: ANN001
    """:func:`identification_figure` written atomically to ``path`` as PNG (``hyst identify --plot``)."""
    from ..report.figures import save_figure

    save_figure(identification_figure(run, result), path, fmt="png")


def identification_figure(run: Run, result: Identification):  # noqa: ANN201 - matplotlib.figure.Figure
    """Each knob's measured loop against the identified model (like Fig. 4 of the paper).

    Left: tip angle against knob angle, measured (when the run has it) and predicted; right:
    motor current against knob angle (when the run has it), with where the current shows each
    tendon taken up. The identified dead-zone edges are marked on both. matplotlib's ``Figure``
    API: no global backend is switched, nothing is shown.

    Parameters
    ----------
    run : Run
        The sweep ``result`` was identified from.
    result : Identification

    Returns
    -------
    matplotlib.figure.Figure
    """
    from ..report import style

    ks = sorted(result.fits)
    fig, axes = style.new_figure(len(ks), 2)
    for row, k in zip(axes, ks):
        fit = result.fits[k]
        m = fit.model
        q = np.asarray(run[f"q{k}"], float)
        has_y = f"y{k}" in run
        y0 = float(run[f"y{k}"][0]) if has_y else 0.0
        ax = row[0]
        if has_y:
            ax.plot(q, run[f"y{k}"], **style.line("measured"), label="measured")
        ax.plot(q, m.forward(q, y0), **style.line("model"), label=f"model ({fit.method})")
        ax.set_xlabel(f"knob angle q{k} (deg)")
        ax.set_ylabel(f"tip angle y{k} (deg)")
        title = (f"knob {k}: d_pos={m.d_pos:.2f} d_neg={m.d_neg:.2f} b_pos={m.b_pos:.2f}\n"
                 f"b_neg={m.b_neg:.2f} omega={m.omega:.3f}")
        if fit.rmse is not None:
            title += f"  RMSE={fit.rmse:.2f} deg"
        style.title(ax, title)
        ax2 = row[1]
        if f"c{k}" in run:
            ax2.plot(q, run[f"c{k}"], **style.line("measured"), label="measured")
            if fit.current is not None:
                for side, e in fit.current.edges.items():
                    ax2.axvspan(e.lo if math.isfinite(e.lo) else e.value, e.hi if math.isfinite(e.hi) else e.value,
                                **style.band("interval"),
                                label="tendon taken up (current)" if side == "pos" else None)
        else:
            ax2.text(0.5, 0.5, "no motor current recorded", ha="center", va="center", transform=ax2.transAxes,
                     fontsize=style.NOTE_SIZE)
        ax2.set_xlabel(f"knob angle q{k} (deg)")
        ax2.set_ylabel(f"motor current c{k} (mA)")
        for a in (ax, ax2):
            a.axvline(m.d_pos, **style.line("edge"), label="dead-zone edges d_neg, d_pos")
            a.axvline(m.d_neg, **style.line("edge"))
            style.legend(a, loc="upper left")
    style.finish(fig)
    return fig
