"""The sim-to-real gap: where the model departs from measurement, which effect causes it, how far
adding that effect closes it, checked on whole runs the fit never saw (DESIGN.md section 8, issue 5).

Three questions, one :func:`diagnose` call:

WHERE
    The residual ``e = y - predict(model, run)`` (deg), broken down by the phase of the
    hysteresis loop the model itself is in at each sample (backlash plateau, unloading slope,
    dead zone, loading slope: the paper's lines L1/L5, L2/L6, L3/L7, L4/L8), the knob direction,
    the shaft shape, the knob speed band, the amplitude band (knob angle from the offset),
    whether the other knob moves, and the time within the run. Each level gets its share of
    the samples, its share of the residual energy ``sum(e**2)`` and its RMSE; the level with the
    largest energy-to-sample ratio is the dominant finding.

WHICH
    Every effect of :data:`hystcli.effects.EFFECTS` is a candidate (one driven by a stated
    ``condition``, stretch, only when a run states one). Each candidate's parameters
    that move the tip (``contact``'s stiffness only moves the current) are searched on a grid over
    the type's ``bounds``: the SSE of every run at every grid point is one table, so a fit on any
    set of training runs is a weighted column sum and an argmin (no refit per fold). Whole runs
    are held out: leave-one-run-out by default, or ``key=value`` (train on the runs whose
    metadata ``key`` differs, test on the others). Candidates are ranked by the held-out RMSE
    they reach; a training information criterion (BIC, with AIC beside it) must improve too.
    Greedy forward selection adds the best candidate while its held-out RMSE shrink is at least
    :data:`MIN_GAIN_PCT` % of the current held-out RMSE, at most ``max_effects`` effects. In the
    second and later rounds the effects already chosen keep their all-run fit (a small optimism
    in the *selection* only; the figures of HOW FAR refit everything per fold).
    ``bootstrap > 0`` resamples the runs with replacement: the whole selection is repeated for
    the inclusion frequency of each effect, the chosen set refitted for 95 % intervals.
    When nothing passes the threshold the report says so and describes the residual that
    remains (autocorrelation, correlation with knob speed, with the other knob) instead of
    naming a cause.

HOW FAR
    Per fold, the chosen effects are refitted jointly (a bounded Nelder-Mead simplex from the
    fold's own grid fit) on the training runs and predict the held-out runs at full rate: held-out RMSE
    (pooled over samples) and PTPE (mean over run and knob) before and after, shrink in %.

Runs at 100 Hz or faster are decimated for the search (to at least 50 Hz); the figures of WHERE and
HOW FAR use every sample. The search is deterministic; only the bootstrap draws, from ``seed``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Callable, Mapping, Sequence

import numpy as np

from . import effects as E
from .compensation import knobs_of
from .errors import DataError, ModelError
from .io import Run
from .metrics import ptpe as _ptpe
from .model import EffectSpec, KnobModel, Model, Shape

MIN_GAIN_PCT = 5.0
"""Smallest held-out RMSE shrink (%) for a candidate to join the model.

Sensor noise alone leaves every candidate within about 1 % of the base model on held-out runs
(the fit finds nothing that generalises); a real effect of the magnitudes a catheter shows gives
tens of %. 5 % sits between with room on both sides (bench/withheld.py measures both)."""

DECIMATE_ABOVE_HZ = 100.0
"""Runs sampled at this rate or faster are decimated for the parameter search (to >= half of it:
50 Hz keeps a 0.02 s resolution of delays and lags, under the 20 Hz filter of the tracker)."""

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
    """

    name: str
    params: Mapping[str, float]
    heldout_rmse: float
    gain_pct: float
    delta_bic: float
    delta_aic: float
    rank: int


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
                "factors": _factors_dict(self.where.groups),
            },
            "which": {
                "min_gain_pct": MIN_GAIN_PCT,
                "rounds": [{
                    "base": list(rd.base), "base_heldout_rmse": _r(rd.base_heldout_rmse),
                    "chosen": rd.chosen,
                    "candidates": [{"rank": c.rank, "name": c.name, "params": _rd(c.params),
                                    "heldout_rmse": _r(c.heldout_rmse), "gain_pct": _r(c.gain_pct),
                                    "delta_bic": _r(c.delta_bic), "delta_aic": _r(c.delta_aic)}
                                   for c in sorted(rd.candidates, key=lambda c: c.rank)],
                } for rd in self.rounds],
                "selected": [{"name": s.name, "params": _rd(s.params),
                              "interval95": {p: [_r(a), _r(b)] for p, (a, b) in s.interval.items()},
                              "inclusion": s.inclusion} for s in self.selected],
                "bootstrap": self.bootstrap,
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
            },
            "effects": [{"name": e.name, "params": _rd(e.params)} for e in self.model.effects],
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
# prepared runs
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Prep:
    """A run ready for fast repeated prediction: per-knob commands, targets and start states."""

    name: str
    meta: Mapping[str, str]
    t: np.ndarray
    q: Mapping[int, np.ndarray]
    y: Mapping[int, np.ndarray]
    knobs: Mapping[int, KnobModel]      # with the run's offset
    shape: Shape
    condition: float | None

    @property
    def n(self) -> int:
        return sum(v.size for v in self.y.values())

    def predict(self, effects: Sequence[E.Effect]) -> dict[int, np.ndarray]:
        out = {}
        for k, kn in self.knobs.items():
            y0 = float(self.y[k][0])
            if not effects:
                out[k] = kn.forward(self.q[k], y0)
            else:
                out[k] = E.tip_chain(kn, k, self.q, self.t, effects, self.shape, y0,
                                     condition=self.condition).y
        return out

    def residual(self, effects: Sequence[E.Effect]) -> np.ndarray:
        p = self.predict(effects)
        return np.concatenate([self.y[k] - p[k] for k in self.knobs])

    def sse(self, effects: Sequence[E.Effect]) -> float:
        try:
            e = self.residual(effects)
        except ModelError:
            return math.inf  # the effect makes the knob model invalid at this condition
        return float(e @ e)


def _prepare(model: Model, run: Run, name: str, decimate: bool) -> _Prep:
    t = np.ascontiguousarray(run["t"], dtype=np.float64)
    step = 1
    if decimate and t.size > 2:
        fs = 1.0 / float(np.median(np.diff(t)))
        if fs >= DECIMATE_ABOVE_HZ * 0.999:
            step = max(int(fs * 1.001 // (DECIMATE_ABOVE_HZ / 2.0)), 1)
    sl = slice(None, None, step)
    offsets = model.offsets_for(run.meta)
    knobs = [k for k in model.knobs if f"q{k}" in run]
    q = {k: np.ascontiguousarray(run[f"q{k}"][sl], dtype=np.float64) for k in (1, 2) if f"q{k}" in run}
    return _Prep(name, run.meta, np.ascontiguousarray(t[sl]), q,
                 {k: np.ascontiguousarray(run[f"y{k}"][sl], dtype=np.float64) for k in knobs},
                 {k: model.knob(k).with_offset(offsets[k]) for k in knobs},
                 Shape.parse(run.meta.get("shape")), E.run_condition(run.meta, name))


# --------------------------------------------------------------------------------------------
# candidates: grids and fits
# --------------------------------------------------------------------------------------------
def _fit_params(name: str) -> tuple[str, ...]:
    # the parameters that move the tip (contact's stiffness only moves the current)
    return ("wall",) if name == "contact" else E.EFFECTS[name].params


def _grid_axes(name: str) -> dict[str, np.ndarray]:
    et = E.EFFECTS[name]
    if name == "friction":
        return {"mu": np.linspace(0.0, 1.0, 41)}
    if name == "deadzone":
        return {"width": np.linspace(-4.0, 10.0, 29)}
    if name == "coupling":
        return {"gain": np.linspace(-0.5, 0.5, 41)}
    if name == "rate":
        return {"tau": np.concatenate([[0.0], np.geomspace(0.01, 2.0, 40)])}
    if name == "saturation":
        return {"limit": np.concatenate([np.geomspace(20.0, 400.0, 40), [math.inf]])}
    if name == "creep":
        return {"fraction": np.linspace(0.0, 0.6, 9), "tau": np.geomspace(0.2, 30.0, 11)}
    if name == "contact":
        return {"wall": np.concatenate([np.arange(-120.0, -1.0, 5.0), np.arange(5.0, 121.0, 5.0), [math.inf]])}
    if name == "latency":
        return {"delay": np.linspace(0.0, 1.0, 51)}
    if name == "stretch":
        # the offset compliance*(condition - reference) is what the runs see: a coarse reference
        # grid (15 deg of condition) is enough, the joint simplex refines both
        return {"compliance": np.linspace(-20.0, 20.0, 41), "reference": np.linspace(-90.0, 180.0, 19)}
    lo, hi = et.bounds[et.switch]  # pragma: no cover - a new effect type without a tuned grid
    return {et.switch: np.linspace(lo, hi, 41)}


def _param_scale(name: str, p: str) -> float:
    """Step scale of a parameter for the simplex: its typical value, or a tenth of its fitting
    range when the typical value is 0 (stretch's reference: 0 for a catheter)."""
    et = E.EFFECTS[name]
    if et.typical[p] != 0.0:
        return max(abs(et.typical[p]), 1e-3)
    lo, hi = et.bounds[p]
    return (hi - lo) / 10.0


def _grid(name: str) -> list[dict[str, float]]:
    axes = _grid_axes(name)
    names = list(axes)
    mesh = np.meshgrid(*[axes[n] for n in names], indexing="ij")
    return [{n: float(m.flat[i]) for n, m in zip(names, mesh)} for i in range(mesh[0].size)]


def _make(name: str, params: Mapping[str, float]) -> E.Effect:
    return E.make_effect(name, **params)


def _table(preps: Sequence[_Prep], base: Sequence[E.Effect], name: str,
           grid: Sequence[Mapping[str, float]]) -> np.ndarray:
    """SSE of every run (rows) at every grid point (columns), with ``base`` effects on."""
    T = np.empty((len(preps), len(grid)))
    for j, params in enumerate(grid):
        effs = tuple(base) + (_make(name, params),)
        for i, p in enumerate(preps):
            T[i, j] = p.sse(effs)
    return T


def _ic(sse: float, n: float, p: int) -> tuple[float, float]:
    n = max(n, 1.0)
    s = max(sse / n, 1e-300)
    return n * math.log(s) + p * math.log(n), n * math.log(s) + 2 * p


def _refine(preps: Sequence[_Prep], w: np.ndarray, base: Sequence[E.Effect], name: str,
            grid: Sequence[Mapping[str, float]], j: int) -> tuple[dict[str, float], float]:
    """Refine one effect's parameters around grid point ``j`` (the grid's neighbours bracket a
    one-parameter search; two parameters start a bounded simplex there)."""
    start = {**E.EFFECTS[name].typical, **grid[j]}
    fitp = [p for p in _fit_params(name) if math.isfinite(start[p])]
    if len(fitp) != 1:
        fitted, sse = _fit(preps, w, base, [(name, start)])
        return fitted[0][1], sse
    from scipy.optimize import minimize_scalar

    p = fitp[0]
    axis = _grid_axes(name)[p]
    axis = axis[np.isfinite(axis)]
    i = int(np.argmin(np.abs(axis - start[p])))
    lo_b, hi_b = E.EFFECTS[name].bounds[p]
    lo = max(axis[max(i - 1, 0)], lo_b)
    hi = min(axis[min(i + 1, axis.size - 1)], hi_b)
    if name == "contact" and lo < 0.0 < hi:  # the wall's side is the grid point's side
        lo, hi = (lo, -1e-6) if start[p] < 0 else (1e-6, hi)
    obj = lambda v: _wsse(preps, w, tuple(base) + (_make(name, {**start, p: float(v)}),))
    f0 = obj(start[p])
    if not hi > lo:
        return start, f0
    res = minimize_scalar(obj, bounds=(lo, hi), method="bounded",
                          options={"xatol": 1e-4 * max(abs(E.EFFECTS[name].typical[p]), 1e-3), "maxiter": 30})
    if res.fun < f0:
        return {**start, p: float(res.x)}, float(res.fun)
    return start, f0


def _wsse(preps: Sequence[_Prep], w: np.ndarray, effs: Sequence[E.Effect]) -> float:
    return float(sum(w[i] * preps[i].sse(effs) for i in range(len(preps)) if w[i] > 0))


def _fit(preps: Sequence[_Prep], w: np.ndarray, fixed: Sequence[E.Effect],
         free: Sequence[tuple[str, Mapping[str, float]]], maxfev: int = 120):
    """Fit the tip parameters of ``free`` effects jointly (weighted runs), ``fixed`` staying as
    they are: a bounded Nelder-Mead simplex on parameters scaled by their typical values.

    Returns the fitted ``[(name, params)]`` and the weighted training SSE. A switch parameter at
    an infinite null (saturation, contact off) is left where it is. Only SSE evaluations, no
    Jacobian: each costs one prediction per training run.
    """
    from scipy.optimize import minimize

    slots = []  # (effect index, param, scale, lo, hi)
    x0 = []
    for i, (name, params) in enumerate(free):
        et = E.EFFECTS[name]
        for p in _fit_params(name):
            v = float(params[p])
            if not math.isfinite(v):
                continue
            lo, hi = et.bounds[p]
            if name == "contact":  # keep the wall on its side (a wall at 0 flips sides)
                lo, hi = (lo, -1e-6) if v < 0 else (1e-6, hi)
            scale = _param_scale(name, p)
            slots.append((i, p, scale, lo, hi))
            x0.append(min(max(v, lo), hi) / scale)

    def params_at(x):
        out = [dict(params) for _, params in free]
        for (i, p, scale, _, _), xv in zip(slots, x):
            out[i][p] = float(xv) * scale
        return out

    def obj(x):
        try:
            effs = tuple(fixed) + tuple(_make(n, p) for (n, _), p in zip(free, params_at(x)))
        except ModelError:
            return math.inf
        return _wsse(preps, w, effs)

    x0 = np.array(x0)
    f0 = obj(x0)
    if not slots:
        return [(n, dict(p)) for n, p in free], f0
    bounds = [(s[3] / s[2], s[4] / s[2]) for s in slots]
    x0 = np.array([min(max(v, lo), hi) for v, (lo, hi) in zip(x0, bounds)])
    # the simplex starts a few % of each scale away: the grid already put x0 near the minimum
    simplex = [x0] + [x0 + np.where(np.arange(len(x0)) == k, 0.05 if x0[k] + 0.05 <= bounds[k][1] else -0.05, 0.0)
                      for k in range(len(x0))]
    res = minimize(obj, x0, method="Nelder-Mead", bounds=bounds,
                   options={"initial_simplex": np.array(simplex), "xatol": 1e-4, "fatol": 1e-9 * max(f0, 1e-12),
                            "maxfev": maxfev})
    x, f = (res.x, float(res.fun)) if res.fun < f0 else (x0, f0)
    return [(n, p) for (n, _), p in zip(free, params_at(x))], f


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
def _null_distance(name: str, grid: Sequence[Mapping[str, float]]) -> np.ndarray:
    """How far each grid point is from switching the effect off (0: off)."""
    et = E.EFFECTS[name]
    out = np.zeros(len(grid))
    for j, g in enumerate(grid):
        for p, v in g.items():
            if p != et.switch:
                continue
            scale = max(abs(et.typical[p]), 1e-9)
            if math.isinf(et.null):
                out[j] += 0.0 if math.isinf(v) else scale / max(abs(v), 1e-12)
            else:
                out[j] += abs(v - et.null) / scale
    return out


def _argmin(obj: np.ndarray, null_dist: np.ndarray) -> int:
    """The grid point of least SSE; among equal ones (a parameter the runs cannot see, e.g.
    coupling without a second knob, friction on a straight shaft) the one nearest to off."""
    obj = np.where(np.isfinite(obj), obj, np.inf)
    best = float(np.min(obj))
    if not math.isfinite(best):
        return int(np.argmin(null_dist))
    tie = np.flatnonzero(obj <= best + 1e-9 * abs(best) + 1e-12)
    return int(tie[np.argmin(null_dist[tie])])


def _fold_heldout(T: np.ndarray, w: np.ndarray, folds, null_dist: np.ndarray) -> tuple[float, list[int]]:
    """Held-out weighted SSE of a table (each fold fits, by argmin, on its training rows) and the
    grid point each fold chose."""
    total = 0.0
    picks = []
    for train, test in folds:
        obj = w[train] @ T[train]
        j = _argmin(obj, null_dist)
        picks.append(j)
        total += float(w[test] @ T[test, j])
    return total, picks


def _select(preps, w, folds, fixed: Sequence[E.Effect], candidates: Sequence[str], max_effects: int,
            progress: Callable[[str], None] | None = None):
    n_eff = float(sum(w[i] * preps[i].n for i in range(len(preps))))
    base_sse = np.array([p.sse(tuple(fixed)) for p in preps])
    chosen: list[tuple[str, dict]] = []
    rounds: list[Round] = []
    # per fold, where its own training fit put each chosen effect: the start of the HOW FAR
    # refit, so that a fold never starts from parameters its held-out runs shaped
    fold_starts: list[list[tuple[str, dict]]] = [[] for _ in folds]
    n_params = 0
    for _ in range(max(int(max_effects), 0)):
        base_effs = tuple(fixed) + tuple(_make(n, p) for n, p in chosen)
        base_held = sum(float(w[test] @ base_sse[test]) for _, test in folds)
        n_held = sum(float(w[test] @ np.array([preps[i].n for i in test])) for _, test in folds)
        base_train = float(w @ base_sse)
        bic0, aic0 = _ic(base_train, n_eff, n_params)
        rows = []
        for name in candidates:
            if name in (c for c, _ in chosen):
                continue
            if progress:
                progress(f"round {len(rounds) + 1}: candidate {name}")
            grid = _grid(name)
            T = _table(preps, base_effs, name, grid)
            nd = _null_distance(name, grid)
            held, picks = _fold_heldout(T, w, folds, nd)
            obj = w @ T
            j = _argmin(obj, nd)
            params, sse = _refine(preps, w, base_effs, name, grid, j)
            if not math.isfinite(sse) or sse > obj[j]:
                params, sse = {**E.EFFECTS[name].typical, **grid[j]}, float(obj[j])
            k = len([p for p in _fit_params(name) if math.isfinite(params[p])])
            bic, aic = _ic(sse, n_eff, n_params + k)
            rmse_h = math.sqrt(held / n_held) if n_held > 0 else math.nan
            rmse_b = math.sqrt(base_held / n_held) if n_held > 0 else math.nan
            starts = [{**E.EFFECTS[name].typical, **grid[jf]} for jf in picks]
            rows.append((name, params, rmse_h, _shrink(rmse_b, rmse_h), bic - bic0, aic - aic0, k, starts))
        if not rows:
            break
        rows.sort(key=lambda r: (r[4] >= 0, r[2]))
        cands = tuple(Candidate(r[0], r[1], r[2], r[3], r[4], r[5], i + 1) for i, r in enumerate(rows))
        best = rows[0]
        ok = best[3] >= MIN_GAIN_PCT and best[4] < 0
        rmse_b = math.sqrt(base_held / n_held) if n_held > 0 else math.nan
        rounds.append(Round(tuple(c for c, _ in chosen), rmse_b, cands, best[0] if ok else None))
        if not ok:
            break
        chosen.append((best[0], dict(best[1])))
        for f, start in enumerate(best[7]):
            fold_starts[f].append((best[0], start))
        n_params += best[6]
        # the chosen effects are refitted jointly on all runs before the next round
        if len(chosen) > 1:
            chosen, _ = _fit(preps, w, fixed, chosen)
            chosen = [(n, dict(p)) for n, p in chosen]
        effs = tuple(fixed) + tuple(_make(n, p) for n, p in chosen)
        base_sse = np.array([p.sse(effs) for p in preps])
    return rounds, chosen, fold_starts


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


def _collect(preps: Sequence[_Prep], effects: Sequence[E.Effect]) -> _Samples:
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
                tr = E.tip_chain(kn, k, p.q, p.t, effects, p.shape, float(p.y[k][0]), condition=p.condition)
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


def _residual(preps: Sequence[_Prep], samples: _Samples) -> Residual:
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
             seed: int = 0, progress: Callable[[str], None] | None = None) -> Diagnosis:
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
        # the shift of the dead zone (DESIGN.md section 3), which an output offset would duplicate
        stated = any(E.run_condition(r.meta, n) is not None for r, n in zip(runs, names))
        cands = [n for n in E.EFFECTS if n not in have and (stated or E.EFFECTS[n].driver != "condition")]
    else:
        cands = []
        for c in candidates:
            c = str(c).strip().lower()
            if c not in E.EFFECTS:
                raise ModelError(f"unknown candidate effect {c!r} (known: {', '.join(E.EFFECTS)})")
            if c not in have and c not in cands:
                cands.append(c)
    if int(max_effects) < 0:
        raise DataError("max_effects must be >= 0")
    if int(bootstrap) < 0:
        raise DataError("bootstrap must be >= 0")
    folds, scheme = _folds(runs, names, holdout)
    fit = [_prepare(model, r, n, decimate=True) for r, n in zip(runs, names)]
    full = [_prepare(model, r, n, decimate=False) for r, n in zip(runs, names)]
    w = np.ones(len(runs))

    if progress:
        progress("where: residual of the model")
    where = _where(_collect(full, base))
    rounds, chosen, fold_starts = _select(fit, w, folds, base, cands, max_effects, progress)

    # HOW FAR: refit the chosen set per fold, predict the held-out runs at full rate
    if progress:
        progress("how far: held-out refits")
    per_run = []
    sse_b = sse_a = n_h = 0.0
    for f, (train, test) in enumerate(folds):
        wt = np.zeros(len(runs))
        wt[train] = 1.0
        if chosen:
            fitted, _ = _fit(fit, wt, base, fold_starts[f], maxfev=200)
            effs = tuple(base) + tuple(_make(n, p) for n, p in fitted)
        else:
            effs = tuple(base)
        for i in test:
            before, after = full[i].predict(base), full[i].predict(effs)
            for k in full[i].knobs:
                eb, ea = full[i].y[k] - before[k], full[i].y[k] - after[k]
                sse_b += float(eb @ eb)
                sse_a += float(ea @ ea)
                n_h += eb.size
                per_run.append(RunFigures(names[i], k, math.sqrt(float(eb @ eb) / eb.size),
                                          math.sqrt(float(ea @ ea) / ea.size), _ptpe(eb), _ptpe(ea)))
    how = HowFar(math.sqrt(sse_b / n_h), math.sqrt(sse_a / n_h),
                 float(np.mean([f.ptpe_before for f in per_run])),
                 float(np.mean([f.ptpe_after for f in per_run])), tuple(per_run))

    # bootstrap over runs
    inclusion: dict[str, float] = {}
    intervals: dict[str, dict[str, tuple[float, float]]] = {}
    if bootstrap > 0:
        rng = np.random.default_rng(seed)
        counts: dict[str, int] = {}
        draws: list[list[tuple[str, dict]]] = []
        for b in range(int(bootstrap)):
            if progress:
                progress(f"bootstrap {b + 1}/{bootstrap}")
            # a resample needs a fold with runs on both sides (redrawn otherwise, deterministically)
            for _ in range(1000):
                wb = np.bincount(rng.integers(0, len(runs), len(runs)), minlength=len(runs)).astype(float)
                bfolds = [(tr, te) for tr, te in folds if wb[te].sum() > 0 and wb[tr].sum() > 0]
                if bfolds:
                    break
            _, bchosen, _ = _select(fit, wb, bfolds, base, cands, max_effects)
            for n, _ in bchosen:
                counts[n] = counts.get(n, 0) + 1
            if chosen:
                fitted, _ = _fit(fit, wb, base, chosen)
                draws.append(fitted)
        inclusion = {n: counts.get(n, 0) / bootstrap for n in set(counts) | {c for c, _ in chosen}}
        for j, (n, _) in enumerate(chosen):
            intervals[n] = {}
            for p in _fit_params(n):
                vals = np.array([d[j][1][p] for d in draws], dtype=float)
                vals = vals[np.isfinite(vals)]
                if vals.size:
                    intervals[n][p] = (float(np.percentile(vals, 2.5)), float(np.percentile(vals, 97.5)))

    selected = tuple(Selected(n, dict(p), intervals.get(n, {}), inclusion.get(n) if bootstrap else None)
                     for n, p in chosen)
    effs_all = tuple(base) + tuple(_make(n, p) for n, p in chosen)
    residual = _residual(full, _collect(full, effs_all))
    specs = tuple(model.effects) + tuple(_make(n, p).spec() for n, p in chosen)
    meta = dict(model.meta)
    if chosen:
        meta["diagnosed_effects"] = ", ".join(n for n, _ in chosen)
    augmented = replace(model, effects=specs, meta=meta)
    verdict = _verdict(rounds, selected, how, residual)
    return Diagnosis(augmented, where, tuple(rounds), selected, how, residual, scheme, verdict,
                     tuple(names), int(bootstrap))


def _verdict(rounds: Sequence[Round], selected: Sequence[Selected], how: HowFar, residual: Residual) -> str:
    if not selected:
        if rounds and rounds[0].candidates:
            best = min(rounds[0].candidates, key=lambda c: c.rank)
            lead = (f"No candidate effect explains the gap: the best, {best.name}, shrinks the held-out RMSE "
                    f"by {best.gain_pct:.1f} %, below the {MIN_GAIN_PCT:g} % needed.")
        else:
            lead = "No candidate effect was tried."
        return f"{lead} {residual.description}"
    eff = " + ".join(f"{s.name}(" + ", ".join(f"{p}={v:.3g}" for p, v in s.params.items()) + ")"
                     for s in selected)
    return (f"The gap is explained by {eff}: held-out RMSE {how.rmse_before:.2f} -> {how.rmse_after:.2f} deg "
            f"({how.rmse_shrink_pct:.0f} % shrink), PTPE {how.ptpe_before:.2f} -> {how.ptpe_after:.2f} deg "
            f"({how.ptpe_shrink_pct:.0f} % shrink).")


# --------------------------------------------------------------------------------------------
# the figure
# --------------------------------------------------------------------------------------------
def diagnosis_figure(diag: Diagnosis, runs: Sequence[Run]) -> bytes:
    """PNG bytes: WHERE (energy vs sample share per factor) and the held-out run the effects
    improve most, measured beside the model before and after."""
    import io as _io

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(12, 8))
    for ax, factor in zip(axes.flat[:3], ("phase", "speed", "time")):
        gs = diag.where.factor(factor)
        x = np.arange(len(gs))
        ax.bar(x - 0.2, [100 * g.sample_share for g in gs], 0.4, label="samples %")
        ax.bar(x + 0.2, [100 * g.energy_share for g in gs], 0.4, label="residual energy %")
        ax.set_xticks(x, [g.level for g in gs], rotation=20, fontsize=8)
        ax.set_title(f"residual by {factor}")
        ax.legend(fontsize=8)
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
        ax.plot(t, before, lw=1, label=f"model (RMSE {best.rmse_before:.2f})")
        ax.plot(t, after, lw=1, label=f"+ effects (RMSE {best.rmse_after:.2f})")
        ax.set_xlabel("t (s)")
        ax.set_ylabel(f"tip angle y{best.knob} (deg)")
        ax.set_title(f"{best.run}" if len(best.run) < 50 else "..." + best.run[-47:], fontsize=9)
        ax.legend(fontsize=8)
    fig.suptitle(diag.verdict[:140] + ("..." if len(diag.verdict) > 140 else ""), fontsize=9)
    fig.tight_layout()
    buf = _io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    plt.close(fig)
    return buf.getvalue()
