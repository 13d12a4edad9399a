"""Identification of a catheter's straight-shaft hysteresis model from a sweep (``hyst identify``).

This package owns DESIGN.md sections 3-4 seen from the data side:

* :mod:`.sweep` checks what a record offers (its reversals; at least one, so the knob goes both
  ways) and decimates long records without changing the clamp recursion's output;
* :mod:`.tip` fits the seven tip parameters by *output error*: the model simulated from the
  record's first sample and fitted to every measured tip angle, so a record is usable however it
  starts and however many cycles it holds, one included; it names every parameter the record
  cannot fix instead of returning it;
* :mod:`.current` reads the motor current: the loading edges where a tendon is taken up (a jump
  in slope, not a flat stretch, so pretensioned tendons work), the backlash plateau when the
  current shows one, the levels and slopes Algorithm 1 needs. Where the dead zone that reading
  bounds carries the motor's cogging ripple, the current is read again with it taken out
  (:func:`_read_without_cogging`).

:func:`identify` puts them together per knob. With a measured tip angle the tip fit decides the
model and the current only gives Algorithm 1's levels; with the current alone (the paper's
procedure) the current's edges and plateaus are the model, ``omega`` is given (the paper's
1.45 by default) and the heights follow a stated assumption.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np

from ..current import RIPPLE_SHORTEST, cogging_ripple, condition
from ..errors import IdentificationError, ModelError
from ..io import Run
from ..model import PAPER_OMEGA, KnobIdentification, KnobModel, Model
from .current import UNLOAD_LEVEL, CurrentReading, conditioned_current, read_current, ringing_time
from .sweep import MIN_SAMPLES, SweepCheck, check_sweep, find_reversals
from .tip import PARAMS as TIP_PARAMS
from .tip import NoFreeLoop, TipFit, at_walls, bootstrap_tip, find_walls, fit_tip, refit_with_edge, wall_levels, z_path
from .tip import predict as tip_predict

__all__ = ["Identification", "KnobFit", "SweepCheck", "MIN_SAMPLES", "check_sweep", "current_levels", "find_reversals",
           "identify", "plot_identification"]


MAX_MISFIT = 0.6
"""Largest systematic departure of the tip from the fitted loop (deg RMS, residuals averaged over
a quarter second) that identify accepts; beyond it the tip does something the model lacks.
Measured: 0.51 on the twin's sample sweeps (their creep and lag), at most 0.26 on the real
EndoWrist files, 0.7-3.2 on independent plants whose tip meets a wall."""

MORE_BATCHES = 4
"""Batches of starts (:func:`hystcli.identify.tip.fit_tip`) searched when the first fit leaves a
systematic misfit above :data:`WALL_MISFIT`: a free loop fits to a few hundredths of a degree, so
a larger misfit is a wall, an effect the loop lacks, or an optimum the first six starts missed
(zoo sweep 3500061, a noisy tip, 0.44 deg, on plateaus as wide as the dead zone: d_neg 2 deg off,
misfit 0.86 deg, refused; the seventh start finds the true loop). Records that fit at first are
untouched."""

WALL_MISFIT = 0.1
"""Systematic misfit (deg RMS, as :data:`MAX_MISFIT`) above which a wall that holds the tip
(:func:`hystcli.identify.tip.find_walls`) is taken on the misfit alone. Measured on the independent
plants with a wall (design seeds 0-599 of ``hystcli.zoo.plants``): 0.11-3.2 deg of plain-fit
misfit, 0.00-0.07 once the samples at the wall are censored; free loops fit to a few hundredths,
the twin's sample sweeps (creep, lag) to 0.5, where no wall is found. Below it, see
:data:`WALL_NOISE_DROP`."""

WALL_NOISE_DROP = 0.75
"""Below :data:`WALL_MISFIT`, a wall is taken only where censoring it also brings the samples'
residual spread (the fit's noise) under this fraction of the plain fit's. A fast sweep's quarter
second spans many degrees of knob and averages a wall's residuals away: zoo sweep 4900388 (57
deg/s at 73 Hz, a compliant wall at -5.7 deg; examined after 4900000's figures), plain misfit
0.072 deg, fitted omega 10 % low and d_pos 0.57 deg off at +-0.07; censored, misfit 0.007 and the
spread 0.091 -> 0.045 deg (the plant's noise: 0.05), every parameter within 0.02 deg. Of 2500 design
sweeps (0-999 and 500 each from 4700000, 4800000 and 4900000), 21 show a wall under the threshold;
6 censored fits halve the misfit, and 3 the spread too, which are taken (341, a wall plant: spread
0.24 -> 0.12 deg, d_neg 0.24 -> 0.01 deg off; 4700309; 4900388). The 3 that halve the misfit
alone keep a plain fit that was right (every claimed parameter within 0.07 deg), where one of
their censored fits (4800004) was 9.7 deg off."""

AMBIGUOUS_RMS = 1.25
"""A refit with an edge where the motor current puts it, within this factor of the tip fit's RMS
residual: the record holds both loops, and the edge is not claimed."""

SLIDES_WITH = {"d_pos": ("d_pos", "h_pos", "b_pos", "b_neg"), "d_neg": ("d_neg", "h_neg", "b_pos", "b_neg")}
"""Parameters that move with an edge the record cannot place (its flat too narrow to see)."""

FROM_CURRENT = (" (only from where the sweep's current showed that tendon taken up, when the current also "
                "read the other edge where the tip fit placed it)")
"""What Algorithm 1 does with an edge a tip fit could not place (:func:`hystcli.shift._edges_by_current`),
as identify's warnings say it."""


def systematic_misfit(resid: np.ndarray, fs: float) -> float:
    """RMS of the residuals averaged over a quarter second: the noise averages out, a part of the
    record the model cannot follow does not."""
    w = max(3, int(round(0.25 * fs)))
    if resid.size <= w:
        return float(np.sqrt(np.mean(resid ** 2)))
    m = np.convolve(resid, np.ones(w) / w, mode="valid")
    return float(np.sqrt(np.mean(m ** 2)))


@dataclass(frozen=True)
class KnobFit:
    """Identification of one knob.

    Attributes
    ----------
    knob : int
    model : KnobModel
        The identified straight-shaft model (offset 0).
    stderr : dict of str to float
        One-sigma uncertainty of each identified parameter (deg, or deg/deg for omega);
        parameters fixed by assumption (omega and the heights on the current path) are absent.
    rmse : float or None
        RMSE of the model, started from the first measured tip angle, against every sample
        (deg), when ``y`` exists.
    method : str
        ``"tip"`` (output-error fit through the forward model) or ``"current"``.
    ident : KnobIdentification or None
        What ``detect-shift`` needs (current levels and slopes, identified range, stderr).
    n_reversals : int
        Reversals of the knob command.
    n_cycles : int
        Complete cycles (a branch each way between reversals).
    current : CurrentReading or None
        What the current showed (edges, plateaus, levels).
    tip : TipFit or None
        The tip fit.
    bootstrap : int
        Bootstrap replicates behind ``stderr`` (0: the fit's own covariance).
    warnings : tuple of str
        What the user should know (e.g. the current's edges disagree with the tip's).
    """

    knob: int
    model: KnobModel
    stderr: dict[str, float]
    rmse: float | None
    method: str
    ident: KnobIdentification | None
    n_reversals: int
    n_cycles: int = 0
    current: CurrentReading | None = field(default=None, repr=False)
    tip: TipFit | None = field(default=None, repr=False)
    bootstrap: int = 0
    warnings: tuple[str, ...] = ()


@dataclass(frozen=True)
class Identification:
    """Result of :func:`identify`: one :class:`KnobFit` per knob and the assembled model."""

    fits: dict[int, KnobFit]
    model: Model


def _knob_list(run: Run, knobs, use_tip: bool = False) -> list[int]:
    where = f"{run.source}: " if run.source else ""
    if knobs is None:
        ks = [k for k in (1, 2) if f"q{k}" in run
              and (f"c{k}" in run or (use_tip and f"y{k}" in run))]
        if not ks:
            need = "q1,c1 or q2,c2 (or q1,y1 / q2,y2 for the tip fit)" if use_tip else "q1,c1 or q2,c2"
            raise IdentificationError(
                f"{where}no knob to identify: needs a pair of columns {need} "
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


def identify(run: Run, knobs: Sequence[int] | None = None, omega: float | None = None,
             use_tip: bool = True, bootstrap: int = 0, seed: int = 0,
             filter_hz: float | None = 20.0, max_misfit: float | None = None,
             refuse_unfixed: bool = True) -> Identification:
    """Identify the straight-shaft hysteresis model of each knob from a sweep.

    Tip (``y<k>`` present and ``use_tip``): output-error fit of :math:`D_{pos}, D_{neg},
    B_{pos}, B_{neg}, \\omega, H_{pos}, H_{neg}` (:mod:`.tip`), the record's first measured
    ``y`` as :math:`y_{-1}` for the reported RMSE (DESIGN.md section 3). The fit's
    parameterisation keeps every trial model valid, which restricts it to
    :math:`H_{neg} \\ge H_{pos}` (the falling dead zone above the rising one, as on every
    measured loop).

    Current only (no ``y<k>``, or ``use_tip`` False): the loading edges
    :math:`D_{pos}, D_{neg}` and the backlash plateaus :math:`B_{pos}, B_{neg}` read from the
    current (:mod:`.current`); :math:`\\omega` is ``omega`` or the paper's 1.45; the heights,
    which the current cannot see, follow a stated assumption. The tip moves only while a tendon
    is taut, so on the way up the tip's dead zone should begin where the negative tendon goes
    slack, :math:`\\hat D_{pos} = D_{neg}`, i.e. :math:`H_{neg} - H_{pos} = \\omega B_{neg}`,
    and on the way down :math:`H_{neg} - H_{pos} = \\omega B_{pos}`; both hold only when the
    backlashes are equal, so we take the mean (raised if needed to keep the model valid) and
    centre the loop on the straight tip, :math:`H_{pos} = -H_{neg}`.

    Uncertainties (``KnobFit.stderr``, one sigma): on the tip path the fit's Gauss-Newton
    covariance with the residual variance inflated by the residuals' autocorrelation time; on
    the current path the spread of the per-stretch readings, never below the kink fits' own.
    With ``bootstrap > 0``, the standard deviation over that many refits resampling whole cycles
    (seeded), never below the estimate without it.

    Parameters
    ----------
    run : Run
        The sweep: ``t``, ``q<k>``, ``c<k>`` and optionally ``y<k>`` per knob.
    knobs : sequence of int, optional
        Knobs to identify; default every ``k`` with ``q<k>`` and ``c<k>`` (or ``y<k>``).
    omega : float, optional
        Slope used on the current-only path (default 1.45); ignored by the tip fit.
    use_tip : bool
        Fit through the tip angle when the run has it.
    bootstrap : int
        Replicates of a bootstrap over cycles for the uncertainties.
    seed : int
        Seed of the bootstrap.
    filter_hz : float or None
        Cut-off of the current's low-pass (None: use the current as recorded).
    max_misfit : float or None
        Largest systematic departure of the tip from the fitted loop (deg RMS over quarter
        seconds) accepted (default :data:`MAX_MISFIT`); ``math.inf`` keeps the fit whatever the
        departure, with a warning: the model to ``hyst diagnose`` the departure with.
    refuse_unfixed : bool
        Refuse a record that cannot fix a parameter (default). False keeps the fit's value with a
        warning and without an uncertainty: enough to predict the tip (a study of prediction),
        not for Algorithm 1, which reads the edges.

    Returns
    -------
    Identification

    Raises
    ------
    IdentificationError
        When the record cannot identify a knob: says what is missing, or which parameters it
        cannot fix and why.
    """
    where = f"{run.source}: " if run.source else ""
    if omega is not None and not (math.isfinite(float(omega)) and float(omega) > 0):
        raise IdentificationError(f"omega must be a positive number, got {omega}")
    if bootstrap < 0:
        raise IdentificationError(f"bootstrap must be >= 0, got {bootstrap}")
    ks = _knob_list(run, knobs, use_tip)
    fits: dict[int, KnobFit] = {}
    for k in ks:
        fits[k] = _identify_knob(run, k, omega, use_tip, int(bootstrap), int(seed), filter_hz, where,
                                 MAX_MISFIT if max_misfit is None else float(max_misfit), refuse_unfixed)
    methods = sorted({f.method for f in fits.values()})
    meta = {"method": methods[0] if len(methods) == 1 else
            ",".join(f"{k}:{f.method}" for k, f in fits.items())}
    model = Model({k: f.model for k, f in fits.items()}, meta=meta,
                  identification={k: f.ident for k, f in fits.items() if f.ident is not None})
    return Identification(fits, model)


def _identify_knob(run: Run, k: int, omega: float | None, use_tip: bool, bootstrap: int, seed: int,
                   filter_hz: float | None, where: str, max_misfit: float = MAX_MISFIT,
                   refuse_unfixed: bool = True) -> KnobFit:
    yname = f"y{k}"
    tip = use_tip and yname in run
    chk = check_sweep(run, k, need_current=not tip)
    q = np.ascontiguousarray(run[f"q{k}"], dtype=float)
    t = np.asarray(run["t"], float) if "t" in run else np.arange(q.size, dtype=float)
    c = conditioned_current(run, k, filter_hz)
    reading = _read_without_cogging(q, c, t, chk, filter_hz) if c is not None else None
    warnings: list[str] = []
    ambiguous_edges: list[str] = []
    where_k = f"{where}knob {k}"
    if tip:
        y = np.asarray(run[yname], float)
        starts = ()
        fs = run.sample_rate if "t" in run else 1.0
        fit = fit_tip(q, y, starts, keep=chk.reversals)
        misfit = systematic_misfit(fit.model.forward(q, float(y[0])) - y, fs)
        if misfit > WALL_MISFIT:
            # a loop the tip departs from may be a local optimum, not a missing effect: search
            # further starts first, and keep the fit that leaves the tip closer, unless it leaves
            # more of the loop undetermined (a degenerate optimum explains no more: withheld
            # catheter 12003, a viscous backlash: 0.681 deg of misfit against 0.683, with d_pos,
            # b_pos and b_neg undetermined, where the first fit left none so)
            more = fit_tip(q, y, starts, keep=chk.reversals, batches=MORE_BATCHES)
            more_misfit = systematic_misfit(more.model.forward(q, float(y[0])) - y, fs)
            if more_misfit < misfit and len(more.unidentified) <= len(fit.unidentified):
                fit, misfit = more, more_misfit
        # a wall (or a hard limit) that holds the tip while the knob drives on: fit the free
        # loop with the samples at the wall censored, and keep it when it explains the record
        # (below MAX_MISFIT a wall still biases the loop by a degree or two: the fit bends
        # the loop toward the wall's level). Under WALL_MISFIT too where a wall is seen: a fast
        # sweep's quarter second spans many degrees of knob and averages a wall's residuals
        # away, so there the samples' own spread must halve as well (WALL_NOISE_DROP)
        walls = find_walls(q, y, fit.noise)
        try:
            wfit = fit_tip(q, y, starts, keep=chk.reversals, walls=walls) if walls != (None, None) else None
        except NoFreeLoop:
            wfit = None          # walls holding nearly every sample are no wall: the plain fit stands
        if wfit is not None:
            free = tip_predict(wfit.theta, q)
            wmis = systematic_misfit(at_walls(free, walls, y) - y, fs)
            # the free loop must go beyond each wall where the tip sits at it
            bottom, top = walls
            held = ([] if top is None else [(free[y >= top] > top).mean()]) + \
                   ([] if bottom is None else [(free[y <= bottom] < bottom).mean()])
            seen = misfit > WALL_MISFIT or wfit.noise < WALL_NOISE_DROP * fit.noise
            if seen and wmis <= MAX_MISFIT and wmis < 0.5 * misfit and min(held) >= 0.5:
                fit, misfit = wfit, wmis
                where_wall = " and ".join(f"at {lvl:+.2f} deg" for lvl in wall_levels(walls, y) if lvl is not None)
                warnings.append(f"{where_k}: a wall holds the tip {where_wall} while the knob drives on: "
                                "those samples only bound the loop (censored); the model is the free tip's, "
                                "hyst diagnose can add the contact")
        if fit.unidentified and not refuse_unfixed:
            for name, why in fit.unidentified.items():
                warnings.append(f"{where_k}: the record cannot fix {name} ({why}): kept as fitted, "
                                "without an uncertainty")
        elif fit.unidentified:
            raise IdentificationError(
                f"{where_k}: the record cannot fix " + "; ".join(
                    f"{name} ({why})" for name, why in fit.unidentified.items()))
        model, stderr = fit.model, {n: v for n, v in fit.stderr.items() if n not in fit.unidentified}
        if misfit > max_misfit:
            raise IdentificationError(
                f"{where_k}: the tip departs from the dead-zone + backlash loop by {misfit:.2f} deg RMS over "
                f"whole stretches (the tracker's noise is {fit.noise:.2f} deg): something the model lacks "
                "stops or bends the tip (a wall, a saturating bend); identify on a sweep clear of it, or keep "
                "the fit with --allow-misfit and hyst diagnose the departure")
        if misfit > MAX_MISFIT:
            # kept on request (max_misfit): the model is the loop's best fit, not the whole tip
            warnings.append(f"{where_k}: the tip departs from the loop by {misfit:.2f} deg RMS over whole "
                            "stretches: kept as asked; hyst diagnose what the loop leaves out")
        for name, why in fit.sliding.items():
            tied = SLIDES_WITH[name]
            warnings.append(f"{where_k}: {name} is not fixed by this record ({why}); the model predicts the "
                            f"tip, but {', '.join(tied)} are left without an uncertainty and Algorithm 1 "
                            f"takes no offset from this {name}{FROM_CURRENT}")
            for name_tied in tied:
                stderr.pop(name_tied, None)
        if bootstrap > 0:
            sd = bootstrap_tip(fit, q, y, chk, bootstrap, np.random.default_rng(seed))
            stderr = {n: max(stderr[n], sd[n]) for n in TIP_PARAMS if n in stderr}
        rmse = fit.rmse
        method = "tip"
        if reading is not None:
            for side, name in (("pos", "d_pos"), ("neg", "d_neg")):
                e = reading.edges.get(side)
                if e is not None and name in stderr and abs(e - getattr(model, name)) > max(1.0, 3 * stderr[name]):
                    # the current reads the edge directly; if a loop with the edge where the current
                    # puts it fits the tip about as well, the record cannot tell the two apart
                    alt, rms_alt, rms_fit = refit_with_edge(fit, q, y, name, e)
                    ambiguous = (abs(getattr(alt, name) - e) < abs(getattr(alt, name) - getattr(model, name))
                                 and rms_alt <= AMBIGUOUS_RMS * rms_fit)
                    warnings.append(f"{where_k}: the current shows the {'positive' if side == 'pos' else 'negative'} "
                                    f"tendon taken up at {e:.2f} deg, the tip's {name} is "
                                    f"{getattr(model, name):.2f} deg" + (
                                        f"; a loop with the edge at {getattr(alt, name):.2f} deg fits the tip as well "
                                        f"(RMS {rms_alt:.3f} against {rms_fit:.3f} deg): the record cannot tell them "
                                        f"apart, so {', '.join(SLIDES_WITH[name])} are left without an uncertainty "
                                        f"and Algorithm 1 takes no offset from this {name}{FROM_CURRENT}"
                                        if ambiguous else ""))
                    if ambiguous:
                        for tied in SLIDES_WITH[name]:
                            stderr.pop(tied, None)
                        ambiguous_edges.append(name)
    else:
        model, stderr = _model_from_current(reading, omega, where_k)
        for side in reading.first_only:
            # an estimate without an uncertainty: not claimed, and no reference for Algorithm 1
            stderr.pop(f"d_{side}", None)
            warnings.append(f"{where_k}: only the record's first stretch shows the "
                            f"{'positive' if side == 'pos' else 'negative'} tendon taken up, and it starts from a "
                            f"state the current cannot tell: d_{side} = {getattr(model, f'd_{side}'):.2f} deg is an "
                            "estimate (it may lie beyond the edge), left without an uncertainty, and Algorithm 1 "
                            "will not use it; sweep a full cycle past both edges")
        unshown = [f"b_{s}" for s in ("pos", "neg") if s not in reading.backlash]
        if unshown:
            # the edges stand on their own (the loading kinks), and detect-shift needs no more;
            # a current that unloads at once cannot tell a backlash narrower than its resolution
            # from a law that does not carry the backlash at all (the tendon's stretch)
            names = " and ".join(unshown)
            warnings.append(f"{where_k}: the current cannot fix {names}: after a reversal it shows no backlash "
                            "plateau (it unloads at once, as a current that follows the tendon's stretch does). "
                            f"The model keeps {names} = 0 deg, without an uncertainty, and marks "
                            f"{'them' if len(unshown) > 1 else 'it'} unfixed: detect-shift uses its edges, "
                            "predict, compensate and diagnose refuse it; identify with the tip angle measured "
                            "for a whole model")
        rmse = None
        if yname in run:
            rmse = float(np.sqrt(np.mean((model.forward(q, float(run[yname][0])) - run[yname]) ** 2)))
        fit = None
        method = "current"
    ident = None
    if c is not None:
        ident = _levels(q, c, t, model, fit, reading, chk, rmse, stderr,
                        tuple(fit.sliding) + tuple(ambiguous_edges) if fit is not None
                        else tuple(f"d_{s}" for s in reading.first_only) + tuple(unshown),
                        offsets_guessed=fit is None)
    return KnobFit(knob=k, model=model, stderr=stderr, rmse=rmse, method=method, ident=ident,
                   n_reversals=int(chk.reversals.size), n_cycles=chk.n_cycles, current=reading,
                   tip=fit, bootstrap=bootstrap, warnings=tuple(warnings))


NARROWEST_DEAD_ZONE = 1.0
"""A current-only dead zone narrower than this (deg), or than twice its two edges' standard errors
added, is refused: a kink where one tendon is taken up and one where the other's unloading ends
look alike in the current, and at that width either may be the other (design sweep 3100394, a
steeply pretensioned dead zone 13.5 deg wide, read 0.25 deg: the unloading's end taken for
d_pos, 12.5 deg off; 3000219, 0.8 deg for 8.9, a held load's end; on design sweeps 0-999,
3000000 and 3100000 the narrowest right reading was 1.39 deg, the zoo's narrowest dead zone 2)."""


def _heights_assumed(d_pos: float, d_neg: float, b_pos: float, b_neg: float,
                     omega: float) -> tuple[float, float]:
    """Dead-zone heights when no tip angle was measured (see :func:`identify`)."""
    dh = max(0.5 * (b_pos + b_neg), max(b_pos, b_neg) - (d_pos - d_neg), 0.0)
    return -0.5 * omega * dh, 0.5 * omega * dh


def _model_from_current(reading: CurrentReading | None, omega: float | None,
                        where_k: str) -> tuple[KnobModel, dict[str, float]]:
    sides = {"pos": "positive", "neg": "negative"}
    missing_edges = [s for s in ("pos", "neg") if reading is None or s not in reading.edges]
    if missing_edges:
        doubt = None if reading is None else reading.doubts.get(f"d_{missing_edges[0]}")
        if doubt:
            # the stretches showed an edge, but one the record contradicts: say why it is not used
            raise IdentificationError(f"{where_k}: the current's d_{missing_edges[0]} is not an edge ({doubt}): "
                                      "record the tip angle, or sweep the straight shaft again (less pretension, more "
                                      "cycles)")
        side = sides[missing_edges[0]]
        raise IdentificationError(
            f"{where_k}: the motor current never clearly shows the {side} tendon taken up (no jump in "
            f"its slope on a stretch that moves {side} through the dead zone): sweep further past the "
            "edge, or record the tip angle")
    d_pos, d_neg = reading.edges["pos"], reading.edges["neg"]
    if d_pos < d_neg:
        raise IdentificationError(
            f"{where_k}: the current's edges cross (positive tendon taken up at {d_pos:.2f} deg, negative "
            f"at {d_neg:.2f} deg): no dead zone to identify")
    narrow = max(NARROWEST_DEAD_ZONE, 2.0 * (reading.edges_se["pos"] + reading.edges_se["neg"]))
    if d_pos - d_neg < narrow:
        raise IdentificationError(
            f"{where_k}: the current's edges leave a dead zone of {d_pos - d_neg:.2f} deg (positive tendon taken "
            f"up at {d_pos:.2f} deg, negative at {d_neg:.2f} deg), narrower than {narrow:.2f} deg: there one "
            "tendon taken up and the other's unloading ending look alike in the current, so either kink may be "
            "the other; record the tip angle")
    # a side whose plateau the current does not show keeps 0 deg, unclaimed (no uncertainty, and
    # listed as unfixed): the caller says so, and predict/compensate refuse the model
    b_pos, b_neg = max(reading.backlash.get("pos", 0.0), 0.0), max(reading.backlash.get("neg", 0.0), 0.0)
    om = PAPER_OMEGA if omega is None else float(omega)
    h_pos, h_neg = _heights_assumed(d_pos, d_neg, b_pos, b_neg, om)
    try:
        model = KnobModel(d_pos=d_pos, d_neg=d_neg, b_pos=b_pos, b_neg=b_neg, omega=om,
                          h_pos=h_pos, h_neg=h_neg)
    except ModelError as exc:  # pragma: no cover - the heights are chosen to keep it valid
        raise IdentificationError(f"{where_k}: the current gives no valid model ({exc})") from None
    stderr = {"d_pos": reading.edges_se["pos"], "d_neg": reading.edges_se["neg"],
              **{f"b_{s}": reading.backlash_se[s] for s in ("pos", "neg") if s in reading.backlash}}
    return model, stderr


def _noise_band(reading: CurrentReading) -> float:
    """How far (mA) a level read off the current may stray by noise alone: UNLOAD_LEVEL sigmas."""
    return UNLOAD_LEVEL * (reading.noise if math.isfinite(reading.noise) else 0.0)


def _levels(q: np.ndarray, c: np.ndarray, t: np.ndarray, model: KnobModel, fit: TipFit | None,
            reading: CurrentReading | None, chk: SweepCheck, rmse: float | None,
            stderr: Mapping[str, float], unfixed: tuple[str, ...] = (),
            offsets_guessed: bool = False) -> KnobIdentification:
    """What Algorithm 1 needs of this knob's current, read where the model puts the tendons.
    ``offsets_guessed``: the model's tip offsets are the current reading's guess (identify
    --current-only), not the tip's (a tip fit, or a model given to :func:`current_levels`)."""
    dq = np.gradient(q, t) if t.size > 1 else np.zeros_like(q)
    lo, hi = model.d_neg + 0.5, model.d_pos - 0.5
    if hi <= lo:
        lo, hi = model.d_neg, model.d_pos
    slack = (q >= lo) & (q <= hi)
    # on a dead-zone flat of the model's tip: neither tendon carries the tip. Inside the knob's
    # dead zone alone is not enough: after a reversal the tip rests on its backlash plateau, and
    # a current that follows the tip's load holds it there (a plateau as wide as the dead zone
    # held the whole crossing: held-out replay 1400205's sweep read its held load, 97 mA off, as
    # the no-load level moving down, and detect-shift took the unloading for an edge, 7.7 deg off)
    dh = (model.h_neg - model.h_pos) / model.omega
    half = 0.5 * dh
    z = z_path(q, (model.d_neg, model.d_pos, model.b_pos, model.b_neg, dh), 0.0 if fit is None else fit.z_init)
    on_flat = np.abs(np.abs(z) - half) < 1e-9 * max(1.0, abs(half))
    if fit is None:
        # without the tip the state before the knob first takes a tendon up is unknown
        tol = 1e-9 * max(1.0, float(np.ptp(q)))
        taken = ((q > model.d_pos) & (np.abs(z - (q - model.d_pos) + half) < tol)) | (
            (q < model.d_neg) & (np.abs(z - (q - model.d_neg) - half) < tol))
        on_flat[:int(np.argmax(taken)) if taken.any() else q.size] = False
    levels = []
    for way in (dq > 0, dq < 0):
        # a record whose tip never reaches a flat moving this way (a short stroke, a plateau as
        # wide as the dead zone) reads the knob's dead zone: a stretch-following current is
        # slack there, and nothing better is in the record (design replays 0-799 of
        # bench/zoo.py: the flat alone, without this, changed 41 of the replays given the true
        # loop: 14 right offsets lost, one silent failure added)
        on = slack & on_flat & way
        on = on if on.sum() >= 5 else slack & way
        levels.append(float(np.median(c[on])) if on.sum() >= 5 else None)
    no_rise, no_fall = levels
    if fit is None and reading is not None and {"b_pos", "b_neg"} & set(unfixed):
        # a backlash the current did not fix leaves the tip's plateaus unknown, and a held load
        # may fill most of the knob's dead zone (one the reading refused as longer than HELD_RATIO
        # times its unloading: design replay 255's sweep, b_neg 12 deg of a 13-deg dead zone, read
        # its rising no-load level 11 mA off, and detect-shift went 5.1 deg wrong at exit 0). The
        # level just before each loading edge is past any plateau; it replaces the flat's median
        # where the two differ by more than the dead zone's own tilt across its width explains
        # (a pretensioned dead zone climbs tens of mA from edge to edge: design replays 0-499)
        tilt = abs(reading.dead_slope) * (model.d_pos - model.d_neg) if math.isfinite(reading.dead_slope) else 0.0
        band = tilt + _noise_band(reading)
        edge_rise, edge_fall = reading.no_load.get(1), reading.no_load.get(-1)
        if no_rise is not None and edge_rise is not None and abs(no_rise - edge_rise) > band:
            no_rise = edge_rise
        if no_fall is not None and edge_fall is not None and abs(no_fall - edge_fall) > band:
            no_fall = edge_fall
    elif offsets_guessed and reading is not None and len(reading.no_load) == 2:
        # a backlash the current did fix still leaves the tip's offsets a guess (omega given, h
        # from the current), so the model's flats may take in a held load and its unloading
        # (design replay 945's sweep: b_pos 16.4 deg of a 16.8-deg dead zone, read right; its
        # falling level came out -22.4 mA against the edges' -106.8, and detect-shift read the
        # replay's held load ending as the edge, 7.2 deg wrong at exit 0). Every no-load level
        # lies between the levels the two tendons were taken up from, whatever the dead zone's
        # tilt and the motor's friction either way; a level beyond them is a load, and is
        # brought back to the nearer (replacing it outright with that direction's edge level
        # moved a pretensioned dead zone's level by its whole tilt: design replay 243, 1.2 deg
        # off). A model given with its tip (current_levels) puts its flats where the tip is free:
        # the bench's true-loop stand-in for 4300237 read a falling level 15 mA above the edges'
        # there, and right
        lo_e = min(reading.no_load.values()) - _noise_band(reading)
        hi_e = max(reading.no_load.values()) + _noise_band(reading)
        no_rise = None if no_rise is None else min(max(no_rise, lo_e), hi_e)
        no_fall = None if no_fall is None else min(max(no_fall, lo_e), hi_e)
    if fit is not None:
        slack &= on_flat
    known = [v for v in (no_rise, no_fall) if v is not None]
    if reading is not None and not known:
        known = list(reading.no_load.values())
    c_dz = float(np.mean(known)) if known else float(np.median(c[slack])) if slack.any() else float(np.median(c))
    # loaded slope: straight-line dC/dq past each edge, along the stretch's motion
    slopes = []
    for a, b, d in chk.segments:
        qq, cc = q[a:b + 1], c[a:b + 1]
        m = qq > model.d_pos + 1.0 if d > 0 else qq < model.d_neg - 1.0
        if m.sum() >= 8 and np.ptp(qq[m]) >= 1.0:
            slopes.append(float(np.polyfit(qq[m], cc[m], 1)[0]))
    if slopes:
        slope_loaded = abs(float(np.median(slopes)))
    elif reading is not None and math.isfinite(reading.loaded_slope):
        slope_loaded = abs(reading.loaded_slope)
    else:
        slope_loaded = float(np.ptp(c)) / max(float(np.ptp(q)), 1e-9)
    # the motor's cogging, read where no tendon is taut: periodic in the knob angle, the same
    # either way the knob turns; the dead zone's slope is the search's threshold floor, so it
    # is read without the ripple the search takes out of its readings
    ripple = None
    flat = slack & on_flat & (dq != 0)
    if flat.sum() >= 60:
        ripple = cogging_ripple(q[flat], c[flat], (dq[flat] < 0).astype(int))
    if ripple is None:
        # the knob's whole dead zone: where wide backlash plateaus leave the tip's flats too short
        # for a period or two (held-out zoo 4800006's sweep: flats of 3 deg against a 3-deg
        # ripple of 1.4 mA, none read on them, 4.4 periods of it across the knob's dead zone; the
        # live search took a trough of it on a loaded line for the edge, 11.4 deg off at exit 0).
        # A load the current holds on a plateau there is a step, and a current that bends once
        # across the dead zone fits a wave of one or two periods as well as cogging does (design
        # replay 3900435's sweep, a stiffening cable with plateaus of 14 and 11 deg and no
        # cogging: a "ripple" of 16 mA every 13.5 deg): as where the current is read again
        # without its ripple, it is taken over at least REREAD_PERIODS periods only
        wide = (q >= lo) & (q <= hi) & (dq != 0)
        if wide.sum() >= 60 and wide.sum() > flat.sum():
            ripple = cogging_ripple(q[wide], c[wide], (dq[wide] < 0).astype(int))
            if ripple is not None and ripple.period * REREAD_PERIODS > float(np.ptp(q[wide])):
                ripple = None
    slope_dz = _dead_zone_slope(q, c if ripple is None else c - ripple(q), chk, lo, hi)
    noise = reading.noise if reading is not None else None
    return KnobIdentification(
        slope_dead_zone=slope_dz, slope_loaded=slope_loaded, q_min=chk.q_min, q_max=chk.q_max,
        rmse=rmse, stderr={k: v for k, v in stderr.items() if math.isfinite(v)}, current_dead_zone=c_dz,
        current_noise=noise, no_load_rising=no_rise, no_load_falling=no_fall,
        current_edge_pos=None if reading is None else reading.edges.get("pos"),
        current_edge_neg=None if reading is None else reading.edges.get("neg"),
        current_edge_pos_se=None if fit is None else _claimed_se(reading, "pos"),
        current_edge_neg_se=None if fit is None else _claimed_se(reading, "neg"),
        current_arrive_rising=None if reading is None else reading.arrivals.get(1),
        current_arrive_falling=None if reading is None else reading.arrivals.get(-1), unfixed=unfixed,
        cogging_period=None if ripple is None else ripple.period,
        cogging_sin=None if ripple is None else ripple.sin, cogging_cos=None if ripple is None else ripple.cos)


REREAD_PERIODS = 3.0
"""Fewest periods of a cogging ripple the first reading's dead zone must span before the current
is read again without it. Cogging repeats with the motor shaft; a dead zone whose current bends
once across it (a stiffening cable, a wall's approach) fits a wave of one or two periods as well
(design sweeps 3900274 and 3900435: a 7-deg "ripple" of 12 mA over an 11-deg dead zone, and a
13.8-deg one of 15 mA over 26 deg; taken out, their right edges were lost). The zoo's cogging
(bench/zoo.py, coulomb-viscous plants) has periods of 0.5-5 deg."""


def _read_without_cogging(q: np.ndarray, c: np.ndarray, t: np.ndarray, chk: SweepCheck,
                          filter_hz: float | None) -> CurrentReading:
    """The sweep's (conditioned) current read, and read again with the motor's cogging taken out
    when its dead zone shows one (``filter_hz``: the low-pass that conditioned it, for
    :func:`hystcli.identify.current.ringing_time`).

    The motor's cogging ripple is periodic in the knob angle and rides on every reading: its
    crest beside an edge reads as a dead zone curving into it, its trough after a reversal as a
    flat that looks like a backlash plateau (design sweep 566, a current that follows the
    tendon's stretch: b_neg 1.98 +- 0.38 returned against 13.05). The first reading bounds the
    dead zone (its edges, or where a stretch showed a kink it did not keep); the ripple is read
    there (:func:`hystcli.current.cogging_ripple`), past any plateau the first reading saw, and
    when one spans :data:`REREAD_PERIODS` periods the current is read again without it.
    Otherwise the first reading is returned as it is. The stored levels (:func:`_levels`) keep
    reading the ripple themselves, for detect-shift to take out of its readings.
    """
    ring_s = ringing_time(filter_hz)
    reading = read_current(q, c, t, chk, ring_s=ring_s)
    # the dead zone as the first reading bounds it: its edges, or where some stretch showed a
    # kink the reading did not keep (a ripple's crest before the edge makes it look like a curve)
    bound = {}
    for side, d in (("pos", 1), ("neg", -1)):
        kinks = [s.edge.at for s in reading.stretches if s.edge is not None and s.direction == d]
        bound[side] = reading.edges.get(side, float(np.median(kinks)) if kinks else None)
    if bound["pos"] is None or bound["neg"] is None:
        return reading
    lo, hi = bound["neg"] + 0.5, bound["pos"] - 0.5
    if hi - lo < REREAD_PERIODS * RIPPLE_SHORTEST:
        return reading          # no ripple the search reads could span enough periods
    dq = np.gradient(q, t) if t.size > 1 else np.zeros_like(q)
    slack = (q > lo) & (q < hi) & (dq != 0)
    # after a reversal the tendon may hold its load over the backlash: those samples are not flat
    for i, (a, b, d) in enumerate(chk.segments):
        if i == 0:
            continue
        width = reading.backlash.get("pos" if d < 0 else "neg")
        if width is not None:
            slack[a:b + 1] &= (q[a:b + 1] - q[a]) * d > width + 0.5
    if slack.sum() < 60:
        return reading
    ripple = cogging_ripple(q[slack], c[slack], (dq[slack] < 0).astype(int))
    if ripple is None or ripple.period * REREAD_PERIODS > hi - lo:
        return reading
    return read_current(q, c - ripple(q), t, chk, ring_s=ring_s)


def _claimed_se(reading: CurrentReading | None, side: str) -> float | None:
    """The standard error of the current's edge on ``side`` where its reading claims it: not an
    edge only the record's first stretch showed (whose start state the current cannot tell)."""
    if reading is None or side in reading.first_only or side not in reading.edges_se:
        return None
    se = float(reading.edges_se[side])
    return se if math.isfinite(se) else None


def _dead_zone_slope(q: np.ndarray, c: np.ndarray, chk: SweepCheck, lo: float, hi: float) -> float:
    """Typical ``|dC/dq|`` the way a stepping search sees it inside the dead zone: the slope of
    the current over 2 deg of knob, noise included (the floor of Algorithm 1's threshold)."""
    slopes = []
    for a, b, _ in chk.segments:
        qq, cc = q[a:b + 1], c[a:b + 1]
        m = (qq >= lo) & (qq <= hi)
        if m.sum() < 8:
            continue
        order = np.argsort(qq[m])
        x, v = qq[m][order], cc[m][order]
        edges = np.arange(x[0], x[-1] + 2.0, 2.0)
        for e0 in edges[:-1]:
            w = (x >= e0) & (x < e0 + 2.0)
            if w.sum() >= 4 and np.ptp(x[w]) > 1.0:
                slopes.append(abs(float(np.polyfit(x[w], v[w], 1)[0])))
    if slopes:
        return float(np.median(slopes))
    return float(np.median(np.abs(np.diff(c)))) / max(float(np.median(np.abs(np.diff(q)))), 1e-9)


# --------------------------------------------------------------------------------------------
# figure
# --------------------------------------------------------------------------------------------
def plot_identification(run: Run, result: Identification, path) -> None:
    """Draw each knob's measured loop against the identified model (like Fig. 4 of the paper).

    Left: tip angle against knob angle, measured (when the run has it) and predicted; right:
    motor current against knob angle (when the run has it), with the loading edges the current
    showed. The identified dead-zone edges (solid) are marked on both. Written atomically as PNG
    with matplotlib's ``Figure`` API (no global backend switch).
    """
    from matplotlib.figure import Figure

    from ..io import atomic_write
    from ..metrics import figure_bytes

    ks = sorted(result.fits)
    fig = Figure(figsize=(11, 4.2 * len(ks)))
    axes = fig.subplots(len(ks), 2, squeeze=False)
    for row, k in zip(axes, ks):
        fit = result.fits[k]
        m = fit.model
        q = np.asarray(run[f"q{k}"], float)
        has_y = f"y{k}" in run
        y0 = float(run[f"y{k}"][0]) if has_y else 0.0
        ax = row[0]
        if has_y:
            ax.plot(q, run[f"y{k}"], color="0.6", lw=1.0, label="measured")
        ax.plot(q, m.forward(q, y0), color="C3", lw=1.2, label=f"model ({fit.method})")
        ax.set_xlabel(f"knob angle q{k} (deg)")
        ax.set_ylabel(f"tip angle y{k} (deg)")
        title = (f"knob {k}: d_pos={m.d_pos:.2f} d_neg={m.d_neg:.2f} b_pos={m.b_pos:.2f} "
                 f"b_neg={m.b_neg:.2f} omega={m.omega:.3f}")
        if fit.rmse is not None:
            title += f"  RMSE={fit.rmse:.2f} deg"
        ax.set_title(title, fontsize=9)
        ax2 = row[1]
        if f"c{k}" in run:
            ax2.plot(q, run[f"c{k}"], color="0.6", lw=1.0, label="measured")
            if fit.current is not None:
                for side, e in fit.current.edges.items():
                    ax2.axvline(e, color="C1", ls="--", lw=1.0,
                                label="tendon taken up (current)" if side == "pos" else None)
            if fit.ident is not None:
                ax2.set_title(f"knob {k}: current slope in dead zone {fit.ident.slope_dead_zone:.3g}, "
                              f"loaded {fit.ident.slope_loaded:.3g} mA/deg", fontsize=9)
        else:
            ax2.text(0.5, 0.5, "no motor current recorded", ha="center", va="center",
                     transform=ax2.transAxes)
        ax2.set_xlabel(f"knob angle q{k} (deg)")
        ax2.set_ylabel(f"motor current c{k} (mA)")
        for a in (ax, ax2):
            a.axvline(m.d_pos, color="C0", lw=1.0, label="dead-zone edges d_neg, d_pos")
            a.axvline(m.d_neg, color="C0", lw=1.0)
            a.grid(alpha=0.3)
            a.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    data = figure_bytes(fig, "png")
    atomic_write(path, lambda f: f.write(data))


def current_levels(run: Run, knob: int, model: KnobModel, filter_hz: float | None = 20.0) -> KnobIdentification:
    """What Algorithm 1 needs of a knob's current, read on a straight-shaft record for a known model.

    For a model that did not come from this record (given by hand, or identified elsewhere):
    the no-load levels, slopes and noise of the current, read where the model puts the tendons
    slack or taut (as :func:`identify` stores them).

    Raises
    ------
    IdentificationError
        A record without the knob's command and current, or one that never reverses.
    """
    k = int(knob)
    chk = check_sweep(run, k, need_current=True)
    q = np.ascontiguousarray(run[f"q{k}"], dtype=float)
    t = np.asarray(run["t"], float)
    c = condition(np.asarray(run[f"c{k}"], float), run.sample_rate, filter_hz)
    reading = _read_without_cogging(q, c, t, chk, filter_hz)
    return _levels(q, c, t, model, None, reading, chk, None, {})
