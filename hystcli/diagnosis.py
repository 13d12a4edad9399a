"""The sim-to-real gap: where the model departs from measurement, which effect causes it, how far
adding that effect closes it, checked on whole runs the fit never saw (docs/design.md section 8).

Three questions, one :func:`diagnose` call:

WHERE
    The residual ``e = y - predict(model, run)`` (deg), broken down by the phase of the
    hysteresis loop the model itself is in at each sample (backlash plateau, unloading slope,
    dead zone, loading slope: the paper's lines L1/L5, L2/L6, L3/L7, L4/L8), the knob direction,
    the shaft shape, the knob speed band, the amplitude band (knob angle from the offset),
    whether the other knob moves, and the time within the run. Each level gets its share of
    the samples, its share of the residual energy ``sum(e**2)`` and its RMSE; the level with the
    largest energy-to-sample ratio is the dominant finding.

WHICH, before any fit
    What physical quantity the residual follows, whatever the form of the effect behind it
    (:mod:`hystcli.attribution`): the other knob's angle and bend, knob velocity, time since a
    reversal, elapsed time, curvature, the stated condition, the tip angle, each scored by the
    share of the residual it explains on held-out runs. Reported in WHERE; it orders the
    candidates, and what it still finds after the chosen effects is named in the verdict
    ("Unexplained: the residual follows ...").

WHICH, fitted
    Every effect of :data:`hystcli.effects.EFFECTS` is a candidate family (one driven by a
    stated ``condition`` only when a run states one). Nothing here knows one effect from another:
    each family's forms bring their grids, bounds and the runs they act on
    (:mod:`hystcli.effects.base`), and :mod:`hystcli.search` makes the table of every run's SSE
    at every grid point of every form, so a fit on any set of training runs is a weighted column
    sum and a pick (no refit per fold): by BIC among forms, only where enough runs see a form,
    between the grid's neighbours along a one-parameter form's axis. Whole runs are held out:
    leave-one-run-out by default, or ``key=value`` (train on the runs whose metadata ``key``
    differs, test on the others). Families are ranked by the held-out RMSE they reach; a training
    information criterion (BIC, with AIC beside it) must improve too. Greedy forward selection
    adds the best family (in the form the all-run fit picks, refined by Gauss-Newton) while its
    held-out RMSE shrink is at least :data:`MIN_GAIN_PCT` % of the current held-out RMSE, at most
    ``max_effects`` effects. In the second and later rounds the effects already chosen keep
    their all-run fit (a small optimism in the *selection* only; the figures of HOW FAR refit
    everything per fold). ``bootstrap > 0`` resamples the runs with replacement: the whole
    selection is repeated for the inclusion frequency of each effect, the chosen set refitted for
    95 % intervals. When nothing passes the threshold the report says so and describes the
    residual that remains instead of naming a cause.

HOW FAR
    Per fold, the chosen effects are refitted jointly on the training runs (bounded Gauss-Newton
    from the better, on the training runs, of the fold's own picks and the all-run fit) and predict
    the held-out runs at full rate: held-out RMSE (pooled over samples) and PTPE (mean over run
    and knob) before and after, shrink in %.

Runs at 100 Hz or faster are decimated for the search (to at least 50 Hz); the figures of WHERE and
HOW FAR use every sample. The search is deterministic; only the bootstrap draws, from ``seed``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Callable, Mapping, Sequence

import numpy as np
from threadpoolctl import threadpool_limits

from . import attribution as A
from . import drive as D
from . import refit as R
from . import effects as E
from . import search as S
from .compensation import knobs_of
from .effects.base import EffectType
from .errors import DataError, ModelError
from .io import Run
from .metrics import ptpe as _ptpe
from .model import KnobModel, Model
from .search import DECIMATE_ABOVE_HZ, Prep

MIN_GAIN_PCT = 5.0
"""Smallest held-out RMSE shrink (%) for a candidate to join the model.

Sensor noise alone leaves every candidate within about 1 % of the base model on held-out runs
(the fit finds nothing that generalises); a real effect of the magnitudes a catheter shows gives
tens of %. 5 % sits between with room on both sides (bench/withheld.py measures both)."""

MOVING_DEG_S = 0.5
"""A knob moves when its speed exceeds this (deg/s)."""

SPEED_BANDS = (1.0, 5.0, 15.0, 40.0)
"""Edges of the knob-speed bands (deg/s)."""

AMPLITUDE_BANDS = (10.0, 20.0, 40.0)
"""Edges of the amplitude bands: knob angle from the offset (deg)."""

TIME_BINS = 5
"""Equal parts of each run's duration for the time breakdown."""

PHASES = ("backlash plateau", "unloading slope", "dead zone", "loading slope")


# --------------------------------------------------------------------------------------------
# results
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Breakdown:
    """One level of one factor of the residual (WHERE).

    Attributes
    ----------
    factor, level : str
    samples : int
    sample_share, energy_share : float
        Fractions (0..1) of all samples and of the residual energy ``sum(e**2)``.
    rmse : float
        RMSE of the residual within the level (deg).
    """

    factor: str
    level: str
    samples: int
    sample_share: float
    energy_share: float
    rmse: float

    @property
    def lift(self) -> float:
        """Energy share over sample share: > 1 where the residual concentrates."""
        return self.energy_share / self.sample_share if self.sample_share > 0 else 0.0


@dataclass(frozen=True)
class Where:
    """Where the residual lies: ``rmse`` overall and every factor's levels; ``finding`` in words."""

    rmse: float
    samples: int
    groups: tuple[Breakdown, ...]
    finding: str
    follows: tuple[A.Attribution, ...] = ()
    """What the residual follows: physical regressors ranked by the held-out share they explain."""

    def factor(self, name: str) -> tuple[Breakdown, ...]:
        """The levels of one factor."""
        return tuple(g for g in self.groups if g.factor == name)


@dataclass(frozen=True)
class Candidate:
    """One candidate effect in one round of the selection (WHICH).

    Attributes
    ----------
    name : str
    params : mapping
        Fitted on all runs (the selection's training fit).
    heldout_rmse : float
        Pooled RMSE on the held-out runs, each fold fitted without them (deg).
    gain_pct : float
        Held-out RMSE shrink against the round's base (%).
    delta_bic, delta_aic : float
        Change of the training information criteria against the round's base (< 0: better).
    rank : int
        1 = best held-out RMSE among the candidates whose BIC improves.
    form : str
        The family's form the all-run fit chose (the name is the physics, the form how it shows).
    """

    name: str
    params: Mapping[str, float]
    heldout_rmse: float
    gain_pct: float
    delta_bic: float
    delta_aic: float
    rank: int
    form: str = ""


@dataclass(frozen=True)
class Round:
    """One step of the greedy forward selection."""

    base: tuple[str, ...]
    base_heldout_rmse: float
    candidates: tuple[Candidate, ...]
    chosen: str | None


@dataclass(frozen=True)
class Selected:
    """An effect the diagnosis adds, with its bootstrap interval and inclusion frequency."""

    name: str
    params: Mapping[str, float]
    interval: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    inclusion: float | None = None
    form: str = ""

    def effect(self) -> E.Effect:
        return E.make_effect(self.name, self.form or None, **self.params)


@dataclass(frozen=True)
class RunFigures:
    """HOW FAR for one held-out run and knob."""

    run: str
    knob: int
    rmse_before: float
    rmse_after: float
    ptpe_before: float
    ptpe_after: float


@dataclass(frozen=True)
class HowFar:
    """Held-out RMSE (pooled) and PTPE (mean over runs and knobs) before and after, deg and %."""

    rmse_before: float
    rmse_after: float
    ptpe_before: float
    ptpe_after: float
    per_run: tuple[RunFigures, ...]

    @property
    def rmse_shrink_pct(self) -> float:
        return _shrink(self.rmse_before, self.rmse_after)

    @property
    def ptpe_shrink_pct(self) -> float:
        return _shrink(self.ptpe_before, self.ptpe_after)


@dataclass(frozen=True)
class Residual:
    """What remains after the chosen effects: its size and what it follows (correlations)."""

    rmse: float
    noise_rmse: float
    autocorr_1s: float
    corr_speed: float
    corr_abs_speed: float
    corr_other_knob: float | None
    corr_command: float
    description: str


@dataclass(frozen=True)
class Diagnosis:
    """Result of :func:`diagnose`: the augmented model and the three answers.

    Attributes
    ----------
    model : Model
        The input model with the chosen effects appended to ``effects``.
    where : Where
    rounds : tuple of Round
        Round 1 ranks every candidate against the base model.
    selected : tuple of Selected
    how_far : HowFar
    residual : Residual
        After the chosen effects (the base model's residual when none was chosen).
    holdout : str
        The hold-out scheme in words.
    verdict : str
        The answer in one or two sentences.
    """

    model: Model
    where: Where
    rounds: tuple[Round, ...]
    selected: tuple[Selected, ...]
    how_far: HowFar
    residual: Residual
    holdout: str
    verdict: str
    runs: tuple[str, ...] = ()
    bootstrap: int = 0
    left: tuple[A.Attribution, ...] = ()
    """What the residual still follows after the chosen effects (held out)."""
    drive: D.TipBehindCurrent | None = None
    """How long the sweep's tip trails its motor current at the edges (given a sweep with current):
    the evidence on which side of the tendons a delay sits (:mod:`hystcli.drive`)."""

    def summary(self) -> str:
        """The verdict, then each effect added with its parameters."""
        added = [f"added {s.name}{f' ({s.form})' if s.form else ''}: "
                 + ", ".join(f"{k} = {v:.4g}" for k, v in s.params.items()) for s in self.selected]
        return "\n".join([self.verdict] + (added or ["no effect added"]))

    @property
    def ranking(self) -> tuple[Candidate, ...]:
        """Round 1's candidates, best first."""
        return tuple(sorted(self.rounds[0].candidates, key=lambda c: c.rank)) if self.rounds else ()

    def report(self) -> dict:
        """A JSON-able dict of everything (the ``-o REPORT.json`` file)."""
        hf = self.how_far
        return {
            "format": "hyst-diagnosis", "version": 1,
            "runs": list(self.runs),
            "holdout": self.holdout,
            "verdict": self.verdict,
            "where": {
                "rmse": _r(self.where.rmse), "samples": self.where.samples,
                "finding": self.where.finding,
                "follows": [{"regressor": a.regressor, "explained_pct": _r(a.explained_pct, 2)}
                            for a in self.where.follows],
                "factors": _factors_dict(self.where.groups),
            },
            "which": {
                "min_gain_pct": MIN_GAIN_PCT,
                "rounds": [{
                    "base": list(rd.base), "base_heldout_rmse": _r(rd.base_heldout_rmse),
                    "chosen": rd.chosen,
                    "candidates": [{"rank": c.rank, "name": c.name, "form": c.form, "params": _rd(c.params),
                                    "heldout_rmse": _r(c.heldout_rmse), "gain_pct": _r(c.gain_pct),
                                    "delta_bic": _r(c.delta_bic), "delta_aic": _r(c.delta_aic)}
                                   for c in sorted(rd.candidates, key=lambda c: c.rank)],
                } for rd in self.rounds],
                "selected": [{"name": s.name, "form": s.form or s.effect().form, "params": _rd(s.params),
                              "interval95": {p: [_r(a), _r(b)] for p, (a, b) in s.interval.items()},
                              "inclusion": s.inclusion} for s in self.selected],
                "bootstrap": self.bootstrap,
                "delay_side": None if self.drive is None else {
                    "tip_behind_current_s": _r(self.drive.delay), "speed_deg_s": _r(self.drive.speed, 3),
                    "readings": [{"knob": k, "side": sd, "tip_minus_current_deg": _r(dd, 4), "speed_deg_s": _r(v, 3)}
                                 for k, sd, dd, v in self.drive.readings]},
            },
            "how_far": {
                "rmse_before": _r(hf.rmse_before), "rmse_after": _r(hf.rmse_after),
                "rmse_shrink_pct": _r(hf.rmse_shrink_pct),
                "ptpe_before": _r(hf.ptpe_before), "ptpe_after": _r(hf.ptpe_after),
                "ptpe_shrink_pct": _r(hf.ptpe_shrink_pct),
                "per_run": [{"run": f.run, "knob": f.knob, "rmse_before": _r(f.rmse_before),
                             "rmse_after": _r(f.rmse_after), "ptpe_before": _r(f.ptpe_before),
                             "ptpe_after": _r(f.ptpe_after)} for f in hf.per_run],
            },
            "residual": {
                "rmse": _r(self.residual.rmse), "noise_rmse": _r(self.residual.noise_rmse),
                "autocorr_1s": _r(self.residual.autocorr_1s),
                "corr_speed": _r(self.residual.corr_speed),
                "corr_abs_speed": _r(self.residual.corr_abs_speed),
                "corr_other_knob": _r(self.residual.corr_other_knob),
                "corr_command": _r(self.residual.corr_command),
                "description": self.residual.description,
                "follows": [{"regressor": a.regressor, "explained_pct": _r(a.explained_pct, 2)} for a in self.left],
            },
            "effects": [{"name": e.name, **({"form": e.form} if e.form else {}), "params": _rd(e.params)}
                        for e in self.model.effects],
        }


def _r(x: float | None, nd: int = 6) -> float | None:
    if x is None or not math.isfinite(x):
        return None
    return round(float(x), nd)


def _rd(params: Mapping[str, float]) -> dict:
    return {k: (_r(v) if math.isfinite(v) else ("inf" if v > 0 else "-inf")) for k, v in params.items()}


def _factors_dict(groups: Sequence[Breakdown]) -> dict:
    out: dict[str, list] = {}
    for g in groups:
        out.setdefault(g.factor, []).append({
            "level": g.level, "samples": g.samples, "sample_share": _r(g.sample_share),
            "energy_share": _r(g.energy_share), "rmse": _r(g.rmse)})
    return out


def _shrink(before: float, after: float) -> float:
    return 100.0 * (before - after) / before if before > 0 else 0.0


# --------------------------------------------------------------------------------------------
# hold-out
# --------------------------------------------------------------------------------------------
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
    picked on its training rows alone: :func:`hystcli.search.pick`) and, along a one-parameter
    form's axis, the vertex between the grid's neighbours (:func:`hystcli.search.subgrid`), where
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

# --------------------------------------------------------------------------------------------
# WHERE
# --------------------------------------------------------------------------------------------
def _phase(kn: KnobModel, x: np.ndarray, yh: np.ndarray) -> np.ndarray:
    u = x - kn.offset
    lo, hi = kn.f_up(u), kn.f_dn(u)
    tol = 1e-7 * (1.0 + np.abs(yh))
    on_up, on_dn = np.abs(yh - lo) <= tol, np.abs(yh - hi) <= tol
    flat_up = on_up & (u >= kn.dhat_pos) & (u <= kn.d_pos)
    flat_dn = on_dn & (u >= kn.d_neg) & (u <= kn.dhat_neg)
    out = np.full(u.shape, 0, dtype=np.int8)  # backlash plateau: held between the envelopes
    out[(on_up & (u < kn.dhat_pos)) | (on_dn & (u > kn.dhat_neg))] = 1    # unloading slope
    out[flat_up | flat_dn] = 2                                             # dead zone
    out[(on_up & (u > kn.d_pos)) | (on_dn & (u < kn.d_neg))] = 3           # loading slope
    return out


def _band(values: np.ndarray, edges: Sequence[float], unit: str) -> np.ndarray:
    labels = [f"<{edges[0]:g} {unit}"] + [f"{a:g}-{b:g} {unit}" for a, b in zip(edges[:-1], edges[1:])] \
        + [f">={edges[-1]:g} {unit}"]
    return np.array(labels, dtype=object)[np.searchsorted(np.asarray(edges), values, side="right")]


def _speed(q: np.ndarray, t: np.ndarray) -> np.ndarray:
    return np.gradient(q, t) if q.size > 1 else np.zeros_like(q)


@dataclass
class _Samples:
    e: list = field(default_factory=list)
    labels: dict = field(default_factory=dict)
    # for the residual description
    v: list = field(default_factory=list)
    q: list = field(default_factory=list)
    other: list = field(default_factory=list)


def _collect(preps: Sequence[Prep], effects: Sequence[E.Effect]) -> _Samples:
    s = _Samples()
    factors = ("phase", "direction", "shape", "speed", "amplitude", "other knob", "time", "knob")
    for f in factors:
        s.labels[f] = []
    for p in preps:
        pred = p.predict(effects)
        tt = p.t
        dur = float(tt[-1] - tt[0]) if tt.size > 1 else 1.0
        tbin = np.minimum(((tt - tt[0]) / max(dur, 1e-12) * TIME_BINS).astype(int), TIME_BINS - 1)
        for k, kn in p.knobs.items():
            e = p.y[k] - pred[k]
            if effects:
                tr = p.trace(effects, k)
                kc, x = tr.knob, tr.x
            else:
                kc, x = kn, p.q[k]
            yh = kc.forward(x, float(p.y[k][0]))
            v = _speed(p.q[k], tt)
            s.e.append(e)
            s.labels["phase"].append(np.array(PHASES, dtype=object)[_phase(kc, x, yh)])
            s.labels["direction"].append(np.where(v > MOVING_DEG_S, "increasing",
                                                  np.where(v < -MOVING_DEG_S, "decreasing", "holding")).astype(object))
            s.labels["shape"].append(np.full(e.size, str(p.shape), dtype=object))
            s.labels["speed"].append(_band(np.abs(v), SPEED_BANDS, "deg/s"))
            s.labels["amplitude"].append(_band(np.abs(p.q[k] - kn.offset), AMPLITUDE_BANDS, "deg"))
            o = 3 - k
            if o in p.q:
                vo = _speed(p.q[o], tt)
                s.labels["other knob"].append(np.where(np.abs(vo) > MOVING_DEG_S, "moving", "still").astype(object))
                s.other.append(p.q[o])
            else:
                s.labels["other knob"].append(np.full(e.size, "absent", dtype=object))
                s.other.append(np.full(e.size, np.nan))
            s.labels["time"].append(np.array([f"{100 * i // TIME_BINS}-{100 * (i + 1) // TIME_BINS} %"
                                              for i in range(TIME_BINS)], dtype=object)[tbin])
            s.labels["knob"].append(np.full(e.size, f"knob {k}", dtype=object))
            s.v.append(v)
            s.q.append(p.q[k] - kn.offset)
    return s


_FACTOR_WORDS = {
    "phase": "in the {level}",
    "direction": "while the knob is {level}",
    "shape": "with the shaft {level}",
    "speed": "at knob speeds {level}",
    "amplitude": "at knob angles {level} from the offset",
    "other knob": "while the other knob is {level}",
    "time": "in the {level} of the runs' duration",
    "knob": "on {level}",
}


def _where(samples: _Samples) -> Where:
    e = np.concatenate(samples.e)
    energy = float(e @ e)
    n = e.size
    groups = []
    for factor, parts in samples.labels.items():
        lab = np.concatenate(parts)
        levels = list(dict.fromkeys(lab.tolist()))
        if factor == "phase":
            levels = [p for p in PHASES if p in levels]
        elif factor in ("speed", "amplitude", "time"):
            levels = sorted(levels, key=lambda s: float(s.lstrip("<>=").split("-")[0].split()[0]))
            levels = [l for l in levels if l.startswith("<")] + [l for l in levels if not l.startswith("<")]
        for level in levels:
            m = lab == level
            c = int(m.sum())
            en = float(e[m] @ e[m])
            groups.append(Breakdown(factor, level, c, c / n, en / energy if energy > 0 else 0.0,
                                    math.sqrt(en / c) if c else 0.0))
    rmse = math.sqrt(energy / n) if n else 0.0
    # "knob" is reported but not a finding: a knob that only moves in 2-DoF runs would mask
    # the physical factor (the other knob moving) behind the bookkeeping one
    pool = [g for g in groups if g.factor != "knob" and g.sample_share >= 0.05
            and len({h.level for h in groups if h.factor == g.factor}) > 1]
    best = max(pool, key=lambda g: g.lift, default=None)
    if best is None or best.lift < 1.3:
        finding = (f"The residual (RMSE {rmse:.2f} deg) is spread evenly: no loop phase, direction, shape, "
                   f"speed, amplitude or time band holds markedly more than its share of the samples.")
    else:
        finding = (f"The residual (RMSE {rmse:.2f} deg) concentrates "
                   f"{_FACTOR_WORDS[best.factor].format(level=best.level)}: "
                   f"{100 * best.energy_share:.0f} % of its energy in {100 * best.sample_share:.0f} % of the "
                   f"samples (RMSE {best.rmse:.2f} deg there).")
    return Where(rmse, n, tuple(groups), finding)


def _corr(a: np.ndarray, b: np.ndarray) -> float | None:
    m = np.isfinite(a) & np.isfinite(b)
    if m.sum() < 3:
        return None
    a, b = a[m] - a[m].mean(), b[m] - b[m].mean()
    d = math.sqrt(float(a @ a) * float(b @ b))
    return float(a @ b) / d if d > 0 else 0.0


def _residual(preps: Sequence[Prep], samples: _Samples) -> Residual:
    e = np.concatenate(samples.e)
    rmse = math.sqrt(float(e @ e) / e.size) if e.size else 0.0
    ac_num = ac_den = 0.0
    hf = []
    i = 0
    for p in preps:
        dt = float(np.median(np.diff(p.t))) if p.t.size > 1 else 1.0
        lag = max(int(round(1.0 / dt)), 1)
        for _k in p.knobs:
            ek = samples.e[i] - samples.e[i].mean()
            i += 1
            if ek.size > lag:
                ac_num += float(ek[lag:] @ ek[:-lag])
                ac_den += float(ek @ ek)
            # sample-to-sample differences see the fast part only (noise), not slow model error
            hf.append(np.diff(samples.e[i - 1]))
    ac = ac_num / ac_den if ac_den > 0 else 0.0
    d = np.concatenate(hf) if hf else np.zeros(1)
    noise = float(np.std(d) / math.sqrt(2.0)) if d.size else 0.0
    v, q, other = np.concatenate(samples.v), np.concatenate(samples.q), np.concatenate(samples.other)
    cs, cas = _corr(e, v) or 0.0, _corr(e, np.abs(v)) or 0.0
    co = _corr(e, other)
    cq = _corr(e, q) or 0.0
    parts = [f"RMSE {rmse:.2f} deg", f"autocorrelation {ac:+.2f} at 1 s",
             f"correlation with knob speed {cs:+.2f}, with |speed| {cas:+.2f}",
             f"with the knob angle {cq:+.2f}"]
    if co is not None:
        parts.append(f"with the other knob {co:+.2f}")
    text = "What remains: " + ", ".join(parts) + "."
    follows = [(abs(c), what) for c, what in ((cs, "the knob speed"), (cas, "the knob speed's size"),
                                              (co or 0.0, "the other knob"), (cq, "the knob angle")) if abs(c) >= 0.3]
    if follows:
        text += f" It follows {max(follows)[1]}: an effect outside the catalogue, or one the data cannot pin down."
    elif abs(ac) < 0.2:
        text += " It is close to white: sensor noise, nothing a model term would explain."
    else:
        text += " It drifts slowly without following speed, angle or the other knob."
    return Residual(rmse, noise, ac, cs, cas, co, cq, text)


# --------------------------------------------------------------------------------------------
# validation
# --------------------------------------------------------------------------------------------
def _validate(model: Model, runs: Sequence[Run]) -> list[str]:
    names = []
    for i, r in enumerate(runs):
        names.append(r.source or f"run {i + 1}")
    if len(runs) < 2:
        raise DataError(f"diagnose needs at least 2 runs to hold whole runs out, got {len(runs)}: with a "
                        "single run nothing is left to test the fitted effects on")
    catheters = {}
    for name, r in zip(names, runs):
        c = str(r.meta.get("catheter", "")).strip()
        if c:
            catheters.setdefault(c, name)
    if len(catheters) > 1:
        pairs = ", ".join(f"{n} is {c}" for c, n in catheters.items())
        raise DataError(f"runs of different catheters are mixed ({pairs}): diagnose one catheter at a time")
    mc = str(model.meta.get("catheter", "") or "").strip()
    if mc and catheters and mc not in catheters:
        raise DataError(f"the model is of catheter {mc} but the runs are of {next(iter(catheters))}")
    model.require_loop(list(model.knobs), "diagnose")
    for name, r in zip(names, runs):
        r.require("t")
        for k in knobs_of(model, r, "q", "knob command", name=name):
            if f"y{k}" not in r:
                raise DataError(f"{name}: no measured tip angle y{k} (diagnose compares the model with "
                                f"measurement; q{k} is there but y{k} is not)")
            if not np.all(np.isfinite(r[f"y{k}"])) or not np.all(np.isfinite(r[f"q{k}"])):
                raise DataError(f"{name}: q{k} or y{k} holds NaN or infinite values")
        if len(r) < 3:
            raise DataError(f"{name}: needs at least 3 samples, has {len(r)}")
    return names


# --------------------------------------------------------------------------------------------
# the entry point
# --------------------------------------------------------------------------------------------
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
        Effect names to try (default: every effect of :data:`hystcli.effects.EFFECTS`; those
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
        re-identified from it with the effect acting (:mod:`hystcli.refit`), and a chosen one
        replaces the model's loop. With the sweep's motor current, the delay forms on the side of
        the tendons the current contradicts are left out (:mod:`hystcli.drive`).

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
    effect the straight sweep carries (:func:`hystcli.refit.applies`), and for a
    bend-driven coupling's input and output forms when the sweep moves both knobs
    (:func:`hystcli.refit.carries`), the knob models re-identified from the sweep with each grid
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


# --------------------------------------------------------------------------------------------
# the figure
# --------------------------------------------------------------------------------------------
def diagnosis_figure(diag: Diagnosis, runs: Sequence[Run]) -> bytes:
    """PNG bytes of :func:`diagnosis_axes`' figure."""
    import io as _io

    fig = diagnosis_axes(diag, runs)
    buf = _io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    return buf.getvalue()


def diagnosis_axes(diag: Diagnosis, runs: Sequence[Run]):  # noqa: ANN201 - matplotlib.figure.Figure
    """The diagnosis figure: WHERE (energy vs sample share per factor, %), what the residual follows
    (held-out %), and the held-out run the effects improve most, measured beside the model before
    and after (deg against s). matplotlib's Figure API: no global backend is switched.

    The shares and the explained energy are drawn on a 0-100 % axis (each explained-energy bar
    labelled with its value): a 0.2 % bar looks like 0.2 %, not like the panel's full height.
    """
    import textwrap

    from matplotlib.figure import Figure

    fig = Figure(figsize=(12, 8.5))
    axes = fig.subplots(2, 2)
    for ax, factor in zip(axes.flat[:2], ("phase", "speed")):
        gs = diag.where.factor(factor)
        x = np.arange(len(gs))
        ax.bar(x - 0.2, [100 * g.sample_share for g in gs], 0.4, label="samples")
        ax.bar(x + 0.2, [100 * g.energy_share for g in gs], 0.4, label="residual energy")
        ax.set_xticks(x, [g.level for g in gs], rotation=20, fontsize=8)
        ax.set_ylim(0, 100)
        ax.set_ylabel("share (%)")
        ax.set_title(f"residual by {factor}", fontsize=10)
        ax.legend(fontsize=8)
    ax = axes.flat[2]
    follows = list(diag.where.follows)
    if follows:
        y = np.arange(len(follows))
        bars = ax.barh(y, [max(a.explained_pct, 0.0) for a in follows], color="tab:green")
        ax.bar_label(bars, [f"{a.explained_pct:.1f} %" for a in follows], padding=3, fontsize=8)
        ax.set_yticks(y, [a.regressor for a in follows], fontsize=8)
        ax.invert_yaxis()
    ax.set_xlim(0, 100)
    ax.set_xlabel("residual energy explained, held out (%)")
    ax.set_title("what the base model's residual follows", fontsize=10)
    ax = axes.flat[3]
    if diag.how_far.per_run:
        best = max(diag.how_far.per_run, key=lambda f: f.rmse_before - f.rmse_after)
        i = list(diag.runs).index(best.run)
        run = runs[i]
        base_model = replace(diag.model, effects=diag.model.effects[:len(diag.model.effects) - len(diag.selected)])
        before = E.predict(base_model, run)[best.knob]
        after = E.predict(diag.model, run)[best.knob]
        t = run.t
        ax.plot(t, run[f"y{best.knob}"], "k", lw=1, label="measured")
        ax.plot(t, before, lw=1, label=f"model (RMSE {best.rmse_before:.2f} deg)")
        ax.plot(t, after, lw=1, label=f"+ effects (RMSE {best.rmse_after:.2f} deg)")
        ax.set_xlabel("time t (s)")
        ax.set_ylabel(f"tip angle y{best.knob} (deg)")
        name = best.run if len(best.run) < 50 else "..." + best.run[-47:]
        ax.set_title(f"held out: {name}", fontsize=9)
        ax.legend(fontsize=8)
    # the verdict, wrapped to the figure's width (a long one is cut after three lines)
    lines = textwrap.wrap(diag.verdict, 150)
    fig.suptitle("\n".join(lines[:3]) + (" ..." if len(lines) > 3 else ""), fontsize=9)
    fig.tight_layout(rect=(0, 0, 1, 0.93))
    return fig
