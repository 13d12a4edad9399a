"""The entry point of a diagnosis: :func:`diagnose` runs WHERE, WHICH and HOW FAR over the runs."""
from __future__ import annotations

import math
from dataclasses import replace
from typing import Callable, Sequence

import numpy as np
from threadpoolctl import threadpool_limits

from ..core import effects as E
from ..core.effects.base import EffectType
from ..core.model import Model
from ..core.run import Run
from ..errors import DataError, ModelError
from ..report.metrics import ptpe as _ptpe
from . import attribution as A
from . import drive as D
from . import refit as R
from . import search as S
from .result import MIN_GAIN_PCT, Diagnosis, HowFar, Residual, Round, RunFigures, Selected
from .select import _contradicted, _effects, _folds, _select
from .where import _collect, _residual, _validate, _where


def diagnose(model: Model, runs: Sequence[Run], holdout: str | None = None,
             candidates: Sequence[str] | None = None, max_effects: int = 3, bootstrap: int = 0,
             seed: int = 0, progress: Callable[[str], None] | None = None, sweep: Run | None = None) -> Diagnosis:
    """Where the model departs from measurement, which effect causes it, how far adding it helps.

    Parameters
    ----------
    model : Model
        The model to diagnose (e.g. from ``hyst identify``); effects it already has stay on and
        are no longer candidates.
    runs : sequence of Run
        At least two runs of one catheter with ``t``, ``q<k>`` and measured ``y<k>`` (metadata
        ``shape``, ``offset<k>``, ``condition`` drive offsets and conditions).
    holdout : str, optional
        ``key=value``: test on the runs whose metadata ``key`` equals ``value``, train on the
        others. Default: leave one run out.
    candidates : sequence of str, optional
        Effect names to try (default: every effect of :data:`hystcli.core.effects.EFFECTS`; those
        whose driver is ``condition``, e.g. stretch, only when a run has ``condition`` metadata).
    max_effects : int
        Most effects the greedy selection adds.
    bootstrap : int
        Resamples over runs for parameter intervals and inclusion frequencies (0: none).
    seed : int
        Seed of the bootstrap.
    progress : callable, optional
        Called with a short message at each step.
    sweep : Run, optional
        The model's identification sweep. A time-dependent effect (a lag, latency, creep) is in
        it too, and a fast sweep turns it into a wider, steeper identified loop; so is a coupling
        driven by the other bend when the sweep moves both knobs at once. With the sweep, those candidates bring the loop
        re-identified from it with the effect acting (:mod:`hystcli.diagnosis.refit`), and a chosen one
        replaces the model's loop. With the sweep's motor current, the delay forms on the side of
        the tendons the current contradicts are left out (:mod:`hystcli.diagnosis.drive`).

    Returns
    -------
    Diagnosis

    Raises
    ------
    DataError
        Fewer than two runs, a run without ``y<k>``, runs of different catheters, a bad hold-out.
    ModelError
        A run's knob the model lacks, an unknown candidate.
    """
    names = _validate(model, runs)
    base = E.as_effects(model.effects)
    have = {e.name for e in base}
    if candidates is None:
        # an effect driven by a stated condition (stretch under a load) is a default candidate
        # only when some run states one: on catheter runs the shape's pull on the cable path is
        # the shift of the dead zone (docs/design.md section 3), which an output offset would duplicate
        stated = any(E.run_condition(r.meta, n) is not None for r, n in zip(runs, names))
        cands = [n for n in E.EFFECTS if n not in have and (stated or E.EFFECTS[n].driver != "condition")]
    else:
        cands = []
        for c in candidates:
            etype = E.effect_type(c) if str(c).strip().lower() in {*E.EFFECTS, *E.ALIASES} else None
            if etype is None:
                raise ModelError(f"unknown candidate effect {str(c).strip().lower()!r} "
                                 f"(known: {', '.join(E.EFFECTS)})")
            if etype.name not in have and etype.name not in cands:
                cands.append(etype.name)
    if int(max_effects) < 0:
        raise DataError("max_effects must be >= 0")
    if int(bootstrap) < 0:
        raise DataError("bootstrap must be >= 0")
    folds, scheme = _folds(runs, names, holdout)
    with threadpool_limits(limits=1):
        # one BLAS thread: the work is many small products, and the machine is shared
        return _diagnose(model, runs, names, base, cands, folds, scheme, int(max_effects), int(bootstrap),
                         seed, progress, sweep)


def _loops(model: Model, sweep: Run):
    """The per-grid-point loops of :func:`_select` (``loops``): for the forms of a time-dependent
    effect the straight sweep carries (:func:`hystcli.diagnosis.refit.applies`), and for a
    bend-driven coupling's input and output forms when the sweep moves both knobs
    (:func:`hystcli.diagnosis.refit.carries`), the knob models re-identified from the sweep with each grid
    point's effect acting."""
    sw = R.prepare_sweep(sweep, model)
    if sw is None:
        return None
    done: dict[str, list] = {}
    cache: dict = {}

    def loops(etype: EffectType, grid) -> list | None:
        if etype.name in done:
            return done[etype.name]
        # a time-dependent family, or a coupling when the sweep moves both knobs: the forms the
        # sweep carries get their loops, the others keep the model's (rate's viscous backlash
        # moves the loop's plateau ends, which the refinement cannot take)
        if not any(R.carries(etype, f, sw) for f in etype.forms):
            done[etype.name] = None
            return None
        out, prev = [None] * len(grid), {}
        order = range(len(grid))
        if etype.driver not in R.DRIVERS:
            # a coupling's gain runs both ways from off: each side's continuation starts next to
            # the sweep's own loop, not at the far end of the other side
            order = sorted(order, key=lambda j: abs(grid[j].params[etype.get_form(grid[j].form).switch]))
        for j in order:
            g = grid[j]
            if g.effect is None or g.effect.is_null or not R.carries(etype, g.effect.spec_form, sw):
                continue
            # along a form's axis each refit starts where its neighbour ended (a continuation)
            key = g.form if etype.driver in R.DRIVERS else (g.form, g.params[g.effect.spec_form.switch] > 0)
            try:
                kn = R.refit(sw, model, g.effect, starts=prev.get(key), cache=cache)
            except ModelError:
                # the refinement ran off to a loop no knob has (withheld design seed 90: d_pos
                # 1.4e6 deg): no loop of its own at this grid point, which keeps the model's
                continue
            prev[key] = kn
            out[j] = kn
        done[etype.name] = out
        return out

    return loops


def _diagnose(model, runs, names, base, cands, folds, scheme, max_effects, bootstrap, seed, progress, sweep=None):
    fit = [S.prepare(model, r, n, decimate=True) for r, n in zip(runs, names)]
    full = [S.prepare(model, r, n, decimate=False) for r, n in zip(runs, names)]
    w = np.ones(len(runs))

    if progress:
        progress("where: residual of the model")
    where = _where(_collect(full, base))
    # WHICH, form-agnostic: what the residual follows, before any effect is fitted; it orders
    # the candidates (an effect whose regressors explain more is tried first)
    follows = A.attribute(fit, base, folds, w)
    where = replace(where, follows=follows)
    before_fit, before_model = fit, model
    families = sorted((E.EFFECTS[n] for n in cands), key=lambda et: -A.score(et, follows))
    tables: dict = {}
    loops = _loops(model, sweep) if sweep is not None else None
    drive = D.tip_behind_current(model, sweep) if sweep is not None else None
    excluded = _contradicted(families, drive)
    rounds, chosen, fold_starts, knobs, fold_knobs = _select(fit, w, folds, base, families, max_effects, progress,
                                                             tables, loops, excluded)
    before_full = full
    if knobs is not None:
        # the first effect chosen came with its loop, re-identified from the sweep under it
        model = replace(model, knobs={k: knobs.get(k, kn) for k, kn in model.knobs.items()},
                        meta={**model.meta, "loop": "re-identified from the sweep with the diagnosed effect"})
        fit_all, full_all = [S.with_knobs(p, knobs) for p in fit], [S.with_knobs(p, knobs) for p in full]
    else:
        fit_all, full_all = fit, full

    # HOW FAR: refit the chosen set per fold, predict the held-out runs at full rate
    if progress:
        progress("how far: held-out refits")
    per_run = []
    sse_b = sse_a = n_h = 0.0
    shared: dict = {}
    invalid: list[str] = []
    for f, (train, test) in enumerate(folds):
        wt = np.zeros(len(runs))
        wt[train] = 1.0
        fit, full = fit_all, full_all
        if knobs is not None:
            # the fold's own loop: re-identified under the fold's own pick (the model's when it
            # picked the effect off)
            kf = fold_knobs[f] or before_model.knobs
            fit, full = [S.with_knobs(p, kf) for p in before_fit], [S.with_knobs(p, kf) for p in before_full]
        if chosen:
            # two starts, each fitted on the fold's training runs alone, the better kept: the
            # fold's own grid picks, and the all-run fit (a start only: a coarse grid can put a
            # small gain on the wrong side of a local minimum the all-run fit has left). Folds that
            # start from the same point share its residuals and their Jacobian. Only the start
            # with the better training fit is refined (4 frozen Gauss-Newton steps rarely change
            # which of two starts ends better, and each costs a Jacobian over every training run).
            starts = []
            for start in (fold_starts[f], chosen):
                key = tuple((et.name, fm, tuple(sorted(p.items()))) for et, fm, p in start)
                _, sse0, shared[key] = S.fit(fit, wt, base, start, iterations=0, res=shared.get(key))
                starts.append((sse0, key, start))
            sse0, key, start = min(starts, key=lambda x: x[0])
            fitted, _, shared[key] = S.fit(fit, wt, base, start, iterations=4, res=shared[key], frozen=True)
            effs = _effects(base, fitted)
        else:
            effs = tuple(base)
        for i in test:
            before = before_full[i].predict(base)
            try:
                after = full[i].predict(effs)
            except ModelError:
                # the fold's fit takes the knob outside its valid range at this run's condition
                # (fitted without it: a dead zone narrowed past its backlash at a load or bend
                # beyond the training runs'): no prediction with the effects, so no gain counted
                after = before
                invalid.append(names[i])
            for k in full[i].knobs:
                eb, ea = full[i].y[k] - before[k], full[i].y[k] - after[k]
                sb, sa = float(np.dot(eb, eb)), float(np.dot(ea, ea))
                sse_b += sb
                sse_a += sa
                n_h += eb.size
                per_run.append(RunFigures(names[i], k, math.sqrt(sb / eb.size), math.sqrt(sa / ea.size),
                                          _ptpe(eb), _ptpe(ea)))
    how = HowFar(math.sqrt(sse_b / n_h), math.sqrt(sse_a / n_h),
                 float(np.mean([f.ptpe_before for f in per_run])),
                 float(np.mean([f.ptpe_after for f in per_run])), tuple(per_run))

    # bootstrap over runs
    inclusion: dict[str, float] = {}
    intervals: dict[str, dict[str, tuple[float, float]]] = {}
    if bootstrap > 0:
        rng = np.random.default_rng(seed)
        counts: dict[str, int] = {}
        draws: list = []
        for b in range(bootstrap):
            if progress:
                progress(f"bootstrap {b + 1}/{bootstrap}")
            # a resample needs a fold with runs on both sides (redrawn otherwise, deterministically)
            for _ in range(1000):
                wb = np.bincount(rng.integers(0, len(runs), len(runs)), minlength=len(runs)).astype(float)
                bfolds = [(tr, te) for tr, te in folds if wb[te].sum() > 0 and wb[tr].sum() > 0]
                if bfolds:
                    break
            _, bchosen, _, _, _ = _select(before_fit, wb, bfolds, base, families, max_effects, tables=tables,
                                          loops=loops, excluded=excluded)
            for et, _, _ in bchosen:
                counts[et.name] = counts.get(et.name, 0) + 1
            if chosen:
                fitted, _, _ = S.fit(fit_all, wb, base, chosen)
                draws.append(fitted)
        inclusion = {n: counts.get(n, 0) / bootstrap for n in set(counts) | {et.name for et, _, _ in chosen}}
        for j, (et, fm, _) in enumerate(chosen):
            intervals[et.name] = {}
            for p in et.get_form(fm).fit:
                vals = np.array([d[j][2][p] for d in draws], dtype=float)
                vals = vals[np.isfinite(vals)]
                if vals.size:
                    intervals[et.name][p] = (float(np.percentile(vals, 2.5)), float(np.percentile(vals, 97.5)))

    selected = tuple(Selected(et.name, dict(p), intervals.get(et.name, {}),
                              inclusion.get(et.name) if bootstrap else None, S.make(et, fm, p).spec().form)
                     for et, fm, p in chosen)
    effs_all = _effects(base, chosen)
    residual = _residual(full_all, _collect(full_all, effs_all))
    left = A.attribute(fit_all, effs_all, folds, w) if chosen else follows
    specs = tuple(model.effects) + tuple(S.make(et, fm, p).spec() for et, fm, p in chosen)
    meta = dict(model.meta)
    if chosen:
        meta["diagnosed_effects"] = ", ".join(S.make(et, fm, p).label() for et, fm, p in chosen)
    augmented = replace(model, effects=specs, meta=meta)
    verdict = _verdict(rounds, selected, how, residual, left)
    if invalid:
        verdict += (f" Held out, {len(invalid)} run(s) ({', '.join(dict.fromkeys(invalid))}) lie outside the valid "
                    "range of the effects fitted without them and count as unchanged.")
    return Diagnosis(augmented, where, tuple(rounds), selected, how, residual, scheme, verdict,
                     tuple(names), int(bootstrap), left, drive)


UNEXPLAINED_PCT = 10.0
"""A regressor that still explains this share (%) of the residual, held out, after the chosen
effects is named: "unexplained: the residual follows ..."."""


def _verdict(rounds: Sequence[Round], selected: Sequence[Selected], how: HowFar, residual: Residual,
             left: Sequence[A.Attribution] = ()) -> str:
    lead_left = next((a for a in left if a.explained_pct >= UNEXPLAINED_PCT), None)
    unexplained = ("" if lead_left is None else
                   f" Unexplained: the residual follows {lead_left.regressor} ({lead_left.explained_pct:.0f} % of "
                   f"what remains, held out); no candidate's form closes it by the {MIN_GAIN_PCT:g} % needed.")
    if not selected:
        if rounds and rounds[0].candidates:
            best = min(rounds[0].candidates, key=lambda c: c.rank)
            lead = (f"No candidate effect explains the gap: the best, {best.name}, shrinks the held-out RMSE "
                    f"by {best.gain_pct:.1f} %, below the {MIN_GAIN_PCT:g} % needed.")
        else:
            lead = "No candidate effect was tried."
        return f"{lead}{unexplained} {residual.description}"
    eff = " + ".join(f"{s.name}(" + (f"{s.form}: " if s.form else "")
                     + ", ".join(f"{p}={v:.3g}" for p, v in s.params.items()) + ")" for s in selected)
    return (f"The gap is explained by {eff}: held-out RMSE {how.rmse_before:.2f} -> {how.rmse_after:.2f} deg "
            f"({how.rmse_shrink_pct:.0f} % shrink), PTPE {how.ptpe_before:.2f} -> {how.ptpe_after:.2f} deg "
            f"({how.ptpe_shrink_pct:.0f} % shrink).{unexplained}")
