"""WHICH, fitted: the hold-out folds and the greedy forward selection of effects on the search's
table."""
from __future__ import annotations

import math
from typing import Callable, Mapping, Sequence

import numpy as np

from ..core import effects as E
from ..core.effects.base import EffectType
from ..core.run import Run
from ..errors import DataError
from . import drive as D
from . import search as S
from .result import MIN_GAIN_PCT, Candidate, Round, _shrink


def _folds(runs: Sequence[Run], names: Sequence[str], holdout: str | None) -> tuple[list, str]:
    n = len(runs)
    if holdout is None or str(holdout).strip() == "":
        return [(np.array([j for j in range(n) if j != i]), np.array([i])) for i in range(n)], \
            f"leave-one-run-out ({n} folds)"
    key, eq, value = str(holdout).partition("=")
    key, value = key.strip(), value.strip()
    if not eq or not key or not value:
        raise DataError(f"bad hold-out {holdout!r}: expected key=value (e.g. motion=nonperiodic)")
    test = [i for i, r in enumerate(runs) if str(r.meta.get(key, "")).strip().lower() == value.lower()]
    if not test:
        raise DataError(f"hold-out {key}={value}: no run has metadata {key} = {value!r}")
    if len(test) == n:
        raise DataError(f"hold-out {key}={value}: every run matches, none is left to train on")
    train = [i for i in range(n) if i not in test]
    return [(np.array(train), np.array(test))], f"{key}={value} ({len(test)} test run(s), {len(train)} training)"


# --------------------------------------------------------------------------------------------
# the selection
# --------------------------------------------------------------------------------------------
def _ic(sse: float, n: float, p: int) -> tuple[float, float]:
    n = max(n, 1.0)
    s = max(sse / n, 1e-300)
    return n * math.log(s) + p * math.log(n), n * math.log(s) + 2 * p


def _fold_heldout(T: np.ndarray, w: np.ndarray, folds, n: np.ndarray, ks: np.ndarray, acts: np.ndarray,
                  null_dist: np.ndarray, etype: EffectType) -> tuple[float, list[tuple[int, float | None]]]:
    """Held-out weighted SSE of a table and what each fold chose: its grid point (form included,
    picked on its training rows alone: :func:`hystcli.diagnosis.search.pick`) and, along a one-parameter
    form's axis, the vertex between the grid's neighbours (:func:`hystcli.diagnosis.search.subgrid`), where
    the held-out runs' SSE is interpolated: the grid's spacing must not decide between two effects
    (a friction of 0.055 on a grid of 0.05 steps)."""
    total = 0.0
    picks = []
    Tf = S.finite_table(T)
    for train, test in folds:
        wt = np.zeros_like(w)
        wt[train] = w[train]
        j, _ = S.pick(T, wt, n, ks, acts, null_dist)
        idx, wts, x = S.subgrid(wt @ Tf, j, etype)
        if np.any(Tf[test][:, idx[wts != 0]] >= S.UNPREDICTED_AT):
            # a neighbour the held-out runs cannot be predicted at: the interpolation's weights
            # (one negative) would cancel it into any SSE; the grid point itself is scored
            idx, wts, x = np.array([j, j, j]), np.array([0.0, 1.0, 0.0]), None
        picks.append((j, x))
        total += float(max(w[test] @ (Tf[test][:, idx] @ wts), 0.0))
    return total, picks


def _at(etype: EffectType, grid, pick: tuple[int, float | None]) -> tuple[str, dict]:
    # the form and parameters of a (grid point, sub-grid value) pick
    j, x = pick
    params = dict(grid[j].params)
    if x is not None:
        params[S.axis_neighbours(etype)[2][j]] = float(x)
    return grid[j].form, params


def _n_fit(etype: EffectType, form: str, params: Mapping[str, float]) -> int:
    return len([p for p in etype.get_form(form).fit if math.isfinite(params[p])])


def _contradicted(families: Sequence[EffectType], drive: D.TipBehindCurrent | None) -> dict[str, np.ndarray]:
    # per family with any, its grid points whose delay sits on the side of the tendons the
    # sweep's current contradicts (fixed for the whole diagnosis: read once)
    out: dict[str, np.ndarray] = {}
    if drive is None:
        return out
    for etype in families:
        bad = np.array([D.contradicts(drive, *etype.delay_side(g.form, g.params)) for g in S.family_grid(etype)],
                       dtype=bool)
        if bad.any():
            out[etype.name] = bad
    return out


def _effects(fixed: Sequence[E.Effect], chosen) -> tuple[E.Effect, ...]:
    return tuple(fixed) + tuple(S.make(et, fm, p) for et, fm, p in chosen)


def _select(preps, w, folds, fixed: Sequence[E.Effect], families: Sequence[EffectType], max_effects: int,
            progress: Callable[[str], None] | None = None, tables: dict | None = None, loops=None,
            excluded: Mapping[str, np.ndarray] | None = None):
    """Greedy forward selection over effect families (each family's forms form one grid).

    ``tables`` caches the first round's SSE tables (they do not depend on the run weights, so the
    bootstrap's resamples reuse them). ``loops(etype, grid)``: per grid point the knob models
    re-identified from the sweep with that effect acting (None: the model's own), for the first
    effect chosen: when it is one of those, the rounds after it and the returned knobs use its
    loop. Returns the rounds, the chosen effects, each fold's starts, the knobs (None: the
    model's) and each fold's knobs. ``excluded``: per family, the grid points left out of every
    fit (:func:`_contradicted`: a delay on the side of the tendons the sweep's current
    contradicts)."""
    n_run = np.array([float(p.n) for p in preps])
    n_eff = float(w @ n_run)
    base_sse = np.array([p.sse(tuple(fixed)) for p in preps])
    chosen: list[tuple[EffectType, str, dict]] = []
    rounds: list[Round] = []
    # per fold, where its own training fit put each chosen effect (form and parameters): the start
    # of the HOW FAR refit, so that a fold never starts from parameters its held-out runs shaped
    fold_starts: list[list[tuple[EffectType, str, dict]]] = [[] for _ in folds]
    n_params = 0
    n_held = sum(float(w[test] @ np.array([preps[i].n for i in test])) for _, test in folds)
    knobs, fold_knobs = None, [None] * len(folds)
    for rnd in range(max(int(max_effects), 0)):
        base_effs = _effects(fixed, chosen)
        base_held = sum(float(w[test] @ base_sse[test]) for _, test in folds)
        base_train = float(w @ base_sse)
        bic0, aic0 = _ic(base_train, n_eff, n_params)
        rmse_b = math.sqrt(base_held / n_held) if n_held > 0 else math.nan
        rows = []
        for etype in families:
            if any(etype is c[0] for c in chosen):
                continue
            if progress:
                progress(f"round {rnd + 1}: candidate {etype.name}")
            grid = S.family_grid(etype)
            lp = loops(etype, grid) if (loops is not None and rnd == 0) else None
            T = tables.get(etype.name) if (tables is not None and rnd == 0) else None
            if T is None:
                T = S.table(preps, base_effs, base_sse, etype, grid) if lp is None else \
                    S.table_loops(preps, base_effs, base_sse, etype, grid, lp)
                if tables is not None and rnd == 0:
                    tables[etype.name] = T
            if excluded and etype.name in excluded:
                T = np.where(excluded[etype.name][None, :], np.inf, T)
            nd = S.null_distance(etype, grid)
            ks, acts = S.fit_counts(etype, grid), S.acting(preps, etype, grid)
            held, picks = _fold_heldout(T, w, folds, n_run, ks, acts, nd, etype)
            j, sse_j = S.pick(T, w, n_run, ks, acts, nd)
            Tf = S.finite_table(T)
            idx, wts, x = S.subgrid(w @ Tf, j, etype)
            if x is not None:
                sse_j = float(max(w @ (Tf[:, idx] @ wts), 0.0))
            form, params = _at(etype, grid, (j, x))
            k = _n_fit(etype, form, params)
            bic, aic = _ic(sse_j, n_eff, n_params + k)
            # a held-out run the candidate cannot predict (non-finite: held at S.UNPREDICTED so that
            # ranking puts it last) has no RMSE: inf, reported as "-", never as a number
            rmse_h = math.nan if n_held <= 0 else (math.inf if held >= S.UNPREDICTED_AT else math.sqrt(held / n_held))
            starts = [(etype, *_at(etype, grid, pk)) for pk in picks]
            rows.append([etype, form, params, rmse_h, _shrink(rmse_b, rmse_h), bic - bic0, aic - aic0, k,
                         starts, sse_j, None if lp is None else (lp[j], [lp[pk[0]] for pk in picks])])
        if not rows:
            break
        rows.sort(key=lambda r: (r[5] >= 0, r[3]))
        best = rows[0]
        # refine the leader's parameters on all runs (the others keep their grid fit: the ranking
        # is by held-out RMSE, which the grid already gives)
        # (not one that brings its own loop: the grid's loop belongs to the grid's point)
        fitted, sse, _ = S.fit(preps, w, base_effs, [(best[0], best[1], best[2])]) if best[10] is None \
            else (None, math.inf, None)
        if math.isfinite(sse) and sse < best[9]:
            best[2] = dict(fitted[0][2])
            bic, aic = _ic(sse, n_eff, n_params + best[7])
            best[5], best[6] = bic - bic0, aic - aic0
        cands = tuple(Candidate(r[0].name, r[2], r[3], r[4], r[5], r[6], i + 1, r[1]) for i, r in enumerate(rows))
        ok = best[4] >= MIN_GAIN_PCT and best[5] < 0
        rounds.append(Round(tuple(S.make(et, fm, p).label() for et, fm, p in chosen), rmse_b, cands,
                            best[0].name if ok else None))
        if not ok:
            break
        chosen.append((best[0], best[1], dict(best[2])))
        for f, start in enumerate(best[8]):
            fold_starts[f].append(start)
        if best[10] is not None:
            # the effect came with the loop re-identified under it: every later round builds on that
            knobs, fold_knobs = best[10]
            if knobs is not None:
                preps = [S.with_knobs(p, knobs) for p in preps]
        n_params += best[7]
        # the chosen effects are refitted jointly on all runs before the next round
        if len(chosen) > 1:
            chosen, _, _ = S.fit(preps, w, fixed, chosen)
            chosen = [(et, fm, dict(p)) for et, fm, p in chosen]
        effs = _effects(fixed, chosen)
        base_sse = np.array([p.sse(effs) for p in preps])
    return rounds, chosen, fold_starts, knobs, fold_knobs
