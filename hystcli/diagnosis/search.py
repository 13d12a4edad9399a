"""The diagnosis' search engine: runs prepared for thousands of predictions, SSE tables of an effect
family's grid, and least-squares fits of effect parameters over weighted runs.

Nothing here knows one effect from another: each effect's forms give their grids, bounds, scales
and which runs they can act on (:mod:`hystcli.core.effects.base`), and the chain says where in a
prediction a candidate sits, so everything before it is computed once per run and reused for
every grid point (a grid over a tracker latency reruns only the latency).

Sums of squares go through a compiled loop, not ``e @ e``: on vectors of 10 000 samples a
multithreaded BLAS spends more time waking threads than adding, and on a shared 2-core machine it
fights the other processes for them.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Mapping, Sequence

import numpy as np

from ..core import effects as E
from ..core.effects import kernels
from ..core.effects.base import EffectType, Form, Signals
from ..core.model import Model
from ..core.params import KnobModel, Shape
from ..core.run import Run
from ..errors import ModelError

UNPREDICTED = 1e300
"""The SSE a table cell holds where a grid point cannot predict a run (non-finite): finite, so
that weighted sums over runs stay defined, and large enough to rank last. A weighted sum at or
above :data:`UNPREDICTED_AT` contains one."""

UNPREDICTED_AT = 1e299


def finite_table(T: np.ndarray) -> np.ndarray:
    """An SSE table with its non-finite cells held at :data:`UNPREDICTED`."""
    return np.where(np.isfinite(T), T, UNPREDICTED)


DECIMATE_ABOVE_HZ = 100.0
"""Runs sampled at this rate or faster are decimated for the parameter search (to >= half of it:
50 Hz keeps a 0.02 s resolution of delays and lags, under the 20 Hz filter of the tracker)."""


# --------------------------------------------------------------------------------------------
# prepared runs
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Prep:
    """A run ready for fast repeated prediction: per-knob commands, targets and start states."""

    name: str
    meta: Mapping[str, str]
    t: np.ndarray
    q: Mapping[int, np.ndarray]
    y: Mapping[int, np.ndarray]
    knobs: Mapping[int, KnobModel]      # with the run's offset
    offsets: Mapping[int, float]
    shape: Shape
    condition: float | None
    shape_stated: bool = False
    """The run states its shape: effects of the shape read its curvature beside a stated condition."""

    @property
    def n(self) -> int:
        return sum(v.size for v in self.y.values())

    @property
    def two_knobs(self) -> bool:
        return len(self.q) > 1

    def bend(self, k: int) -> np.ndarray | None:
        """The bend of knob ``k``'s section as its base model predicts it (what the other knob's
        magnitude coupling reads), None when ``k`` is not a knob of both the model and the run."""
        kn = self.knobs.get(k)
        if kn is None or k not in self.q:
            return None
        return kn.forward(self.q[k], float(self.y[k][0]))

    def signals(self, k: int) -> Signals:
        return Signals(k, self.t, self.q.get(3 - k), float(self.offsets.get(3 - k, 0.0)), float(self.y[k][0]),
                       self.name, self.bend(3 - k))

    def acts(self, etype: EffectType, form: Form) -> bool:
        cond = None if (self.shape_stated and etype.driver == "shape") else self.condition
        return etype.acts_on(form, self.shape.total_curvature, cond, self.two_knobs)

    def trace(self, effects: Sequence[E.Effect], k: int) -> E.KnobTrace:
        o = 3 - k
        return E.tip_chain(self.knobs[k], k, self.q, self.t, effects, self.shape, float(self.y[k][0]),
                           condition=self.condition, other_offset=self.offsets.get(o, 0.0), source=self.name,
                           shape_stated=self.shape_stated, other_knob=self.knobs.get(o) if o in self.q else None,
                           other_y0=float(self.y[o][0]) if o in self.y else 0.0)

    def predict(self, effects: Sequence[E.Effect]) -> dict[int, np.ndarray]:
        out = {}
        for k, kn in self.knobs.items():
            if not effects:
                out[k] = kn.forward(self.q[k], float(self.y[k][0]))
            else:
                out[k] = self.trace(effects, k).y
        return out

    def residual(self, effects: Sequence[E.Effect]) -> np.ndarray:
        p = self.predict(effects)
        return np.concatenate([self.y[k] - p[k] for k in self.knobs])

    def sse(self, effects: Sequence[E.Effect]) -> float:
        try:
            p = self.predict(effects)
        except ModelError:
            return math.inf  # the effect makes the knob model invalid at this condition
        return float(sum(kernels.sse_kernel(self.y[k], p[k]) for k in self.knobs))


def prepare(model: Model, run: Run, name: str, decimate: bool) -> Prep:
    """A :class:`Prep` of ``run`` under ``model``'s offsets, decimated for the search when asked."""
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
    return Prep(name, run.meta, np.ascontiguousarray(t[sl]), q,
                {k: np.ascontiguousarray(run[f"y{k}"][sl], dtype=np.float64) for k in knobs},
                {k: model.knob(k).with_offset(offsets[k]) for k in knobs}, dict(offsets),
                Shape.parse(run.meta.get("shape")), E.run_condition(run.meta, name), "shape" in run.meta)


def wsse(preps: Sequence[Prep], w: np.ndarray, effs: Sequence[E.Effect]) -> float:
    """Weighted SSE over the runs with a positive weight."""
    return float(sum(w[i] * preps[i].sse(effs) for i in range(len(preps)) if w[i] > 0))


# --------------------------------------------------------------------------------------------
# a family's grid and its SSE table
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class GridPoint:
    """One point of a family's search grid: a form, its parameters and the effect they make
    (None where they are outside the form's domain)."""

    form: str
    params: Mapping[str, float]
    effect: E.Effect | None = None


_GRIDS: dict[str, list[GridPoint]] = {}


def family_grid(etype: EffectType) -> list[GridPoint]:
    """Every form's grid, one after the other: the family is one candidate with a larger grid, so
    a fold picks the form as it picks the parameters, on its training runs alone. Built once."""
    grid = _GRIDS.get(etype.name)
    if grid is None:
        grid = []
        for f in etype.forms:
            for g in f.grid():
                try:
                    eff = make(etype, f.name, g)
                except ModelError:
                    eff = None
                grid.append(GridPoint(f.name, g, eff))
        _GRIDS[etype.name] = grid
    return grid


def null_distance(etype: EffectType, grid: Sequence[GridPoint]) -> np.ndarray:
    """How far each grid point is from switching the effect off (0: off)."""
    return np.array([etype.get_form(g.form).null_distance(g.params) for g in grid])


def make(etype: EffectType, form: str, params: Mapping[str, float]) -> E.Effect:
    return E.make_effect(etype.name, form, **params)


def _is_null(etype: EffectType, g: GridPoint) -> bool:
    return etype.get_form(g.form).null_distance(g.params) == 0.0


def table(preps: Sequence[Prep], base: Sequence[E.Effect], base_sse: np.ndarray, etype: EffectType,
          grid: Sequence[GridPoint]) -> np.ndarray:
    """SSE of every run (rows) at every grid point (columns), with the ``base`` effects on.

    A run the form cannot act on (coupling on a one-knob run, friction on a straight shaft) and a
    grid point that switches the effect off keep the base SSE without a prediction. Within a run,
    everything the chain computes before the candidate's stage is computed once per form. A
    stage that is the identity inside a range (:meth:`EffectType.identity_range`: a stop, a
    knee) keeps the base SSE where the run's input to it stays inside, and points that do the
    same to a knob (:meth:`EffectType.knob_key`) compute it once: every entry is the point's
    own prediction, bit for bit.
    """
    T = np.empty((len(preps), len(grid)))
    base = tuple(base)
    # per grid point once, not per run: whether it is off, its chain plan and that plan's steps
    # (thousands of points times tens of runs: the bookkeeping cost more than the kernels)
    null = [_is_null(etype, g) for g in grid]
    plans = [None if o or g.effect is None else E.Plan.of(base + (g.effect,)) for o, g in zip(null, grid)]
    steps = [None if pl is None else pl.signal_steps() for pl in plans]
    acts = acting(preps, etype, grid)
    ident = [None if pl is None else {k: g.effect.type.identity_range(g.effect, k) for k in (1, 2)}
             for pl, g in zip(plans, grid)]
    ident = [None if r is None or all(v is None for v in r.values()) else r for r in ident]
    widest = _widest(grid, ident)
    # what a point does on each knob alone: points alike on a knob share its SSE there (the
    # two-limit forms of a stop on a one-knob run, or on the knob whose limit they share)
    keys = [None if pl is None else {k: g.effect.type.knob_key(g.effect, k) for k in (1, 2)}
            for pl, g in zip(plans, grid)]
    for i, p in enumerate(preps):
        cuts: dict[str, tuple] = {}
        sigs = {k: p.signals(k) for k in p.knobs}
        seen = {grid[j].form: _stage_input_range(p, plans[j], steps[j], grid[j].effect, ident[j], sigs)
                for j in widest}
        alike: dict = {}
        for j, g in enumerate(grid):
            if null[j] or not acts[i, j]:
                T[i, j] = base_sse[i]
                continue
            if g.effect is None:
                T[i, j] = math.inf  # outside the domain
                continue
            rest = False
            if ident[j] is not None and g.form in seen:
                if _inside(seen[g.form], ident[j], 0, 1):
                    T[i, j] = base_sse[i]  # the stage leaves this run alone: the base prediction
                    continue
                # at rest it hands the hysteresis the reading unchanged: what comes before it is
                # the switched-off effect's, shared by every such point of the form
                rest = _inside(seen[g.form], ident[j], 2, 2)
            try:
                T[i, j] = _sse_from_cut(p, plans[j], steps[j], g.effect, cuts, sigs, rest,
                                        None if keys[j] is None else (keys[j], alike))
            except ModelError:
                T[i, j] = math.inf
    return T


def _widest(grid: Sequence[GridPoint], ident: Sequence[Mapping[int, tuple] | None]) -> list[int]:
    """For each form whose stage is the identity inside a range (a stop, a knee), the grid point
    whose range is widest on its narrower knob: the plan that gives the stage's input on a run.
    (A point that switches the effect off would not do: its plan leaves the stage out.)"""
    best: dict[str, tuple[float, int]] = {}
    for j, (g, r) in enumerate(zip(grid, ident)):
        if r is None or any(v is None for v in r.values()) or g.effect.spec_form.stage != "output":
            continue
        width = min(v[1] - v[0] for v in r.values())
        if math.isfinite(width) and (g.form not in best or width > best[g.form][0]):
            best[g.form] = (width, j)
    return [j for _, j in best.values()]


def _stage_input_range(p: Prep, plan: E.Plan, steps: list, eff: E.Effect, ranges: Mapping[int, tuple],
                       sigs: Mapping) -> dict[int, tuple] | None:
    """Per knob, the least and largest input ``eff``'s stage sees on run ``p`` (the value its
    ``at_rest`` is handed included) and that value alone; None where ``eff`` at rest is not the
    identity (``ranges``, its identity ranges) or an input is not finite. The stages before it
    do not depend on its parameters but through that value, so a point of the form whose range
    holds the first two predicts the run as the base does, and one whose range holds the value
    at rest shares those stages' signals with ``eff``."""
    stop = E.step_index(plan, eff)
    if steps[stop][1] is not eff:
        return None
    out = {}
    for k, kn in p.knobs.items():
        v = E.rest_input(plan, eff, sigs[k].y0, sigs[k])
        lo, hi = ranges[k]
        if not (lo <= v <= hi):
            return None
        try:
            knc = E.condition_knob(kn, plan, p.shape, p.condition, p.shape_stated, k)
            z = E.run_signals(plan, knc, sigs[k], p.q[k], stop=stop, steps=steps)["z"]
        except ModelError:
            return None
        if z.size == 0:
            return None
        lo, hi = min(float(np.min(z)), v), max(float(np.max(z)), v)
        if not (math.isfinite(lo) and math.isfinite(hi)):
            return None
        out[k] = (lo, hi, v)
    return out


def _inside(seen: Mapping[int, tuple] | None, ranges: Mapping[int, tuple | None], lo: int, hi: int) -> bool:
    """Whether, on every knob, ``seen[k][lo] .. seen[k][hi]`` lies inside ``ranges[k]``."""
    if not seen:
        return False
    for k, s in seen.items():
        r = ranges.get(k)
        if r is None or not (r[0] <= s[lo] and s[hi] <= r[1]):
            return False
    return True


def with_knobs(p: Prep, knobs: Mapping[int, KnobModel]) -> Prep:
    """The run under other knob models (each moved to the run's offset)."""
    return replace(p, knobs={k: knobs[k].with_offset(p.offsets[k]) for k in p.knobs})


def table_loops(preps: Sequence[Prep], base: Sequence[E.Effect], base_sse: np.ndarray, etype: EffectType,
                grid: Sequence[GridPoint], loops: Sequence[Mapping[int, KnobModel] | None]) -> np.ndarray:
    """As :func:`table`, where grid point ``j`` brings its own knob models ``loops[j]`` (the loop
    re-identified with the effect acting, :mod:`hystcli.diagnosis.refit`); None keeps the runs' own."""
    T = table(preps, base, base_sse, etype, [g if lp is None else GridPoint(g.form, g.params, None)
                                             for g, lp in zip(grid, loops)])
    base = tuple(base)
    acts = acting(preps, etype, grid)
    for j, (g, lp) in enumerate(zip(grid, loops)):
        if lp is None or g.effect is None or _is_null(etype, g):
            continue
        for i, p in enumerate(preps):
            q = with_knobs(p, lp)
            T[i, j] = q.sse(base + (g.effect,)) if acts[i, j] else q.sse(base)
    return T


def _sse_from_cut(p: Prep, plan: E.Plan, steps: list, eff: E.Effect, cuts: dict, sigs: dict,
                  rest: bool = False, alike: tuple | None = None) -> float:
    """The run's SSE under ``plan``, reusing what the chain computes before ``eff``'s stage
    (``cuts``, per form and knob). ``rest``: ``eff``'s ``at_rest`` is the identity on this run
    (:func:`table`), so even a static map's cut may lie after the hysteresis. ``alike``: the
    point's knob keys and the run's SSE per knob and key so far (:meth:`EffectType.knob_key`)."""
    total = 0.0
    for k, kn in p.knobs.items():
        memo = None
        if alike is not None and alike[0][k] is not None:
            memo = (k, alike[0][k])
            got = alike[1].get(memo)
            if got is not None:
                total += got
                continue
        try:
            part = _knob_sse(p, plan, steps, eff, cuts, sigs, rest, k, kn)
        except ModelError:
            if memo is not None:
                alike[1][memo] = math.inf
            raise
        if memo is not None:
            alike[1][memo] = part
        total += part
    return total


def _knob_sse(p: Prep, plan: E.Plan, steps: list, eff: E.Effect, cuts: dict, sigs: dict, rest: bool,
              k: int, kn: KnobModel) -> float:
    """Knob ``k``'s share of :func:`_sse_from_cut`."""
    sig = sigs[k]
    if eff.spec_form.stage == "condition":
        knc = E.condition_knob(kn, plan, p.shape, p.condition, p.shape_stated, k)
        c = E.run_signals(plan, knc, sig, p.q[k], steps=steps)
    else:
        key = (eff.form, k, rest)
        if key not in cuts:
            j = E.step_index(plan, eff)
            if not rest and type(eff.type).at_rest is not EffectType.at_rest:
                # its static map sets the hysteresis' start: reuse only what comes before it
                j = min(j, [s for s, _ in steps].index("hyst"))
            knc = E.condition_knob(kn, plan, p.shape, p.condition, p.shape_stated, k)
            cuts[key] = (j, knc, E.run_signals(plan, knc, sig, p.q[k], stop=j, steps=steps))
        j, knc, carry = cuts[key]
        c = E.run_signals(plan, knc, sig, p.q[k], start=j, carry=carry, steps=steps)
    return kernels.sse_kernel(p.y[k], c["z"])


def fit_counts(etype: EffectType, grid: Sequence[GridPoint]) -> np.ndarray:
    """Fitted parameters at each grid point (0 where the point switches the effect off)."""
    return np.array([0 if _is_null(etype, g) else
                     len([q for q in etype.get_form(g.form).fit if math.isfinite(g.params[q])]) for g in grid])


def acting(preps: Sequence[Prep], etype: EffectType, grid: Sequence[GridPoint]) -> np.ndarray:
    """Whether each grid point's form can act on each run (runs x points)."""
    forms = {f.name: np.array([p.acts(etype, f) for p in preps]) for f in etype.forms}
    return np.column_stack([forms[g.form] for g in grid]) if grid else np.zeros((len(preps), 0), bool)


_AXES: dict[str, tuple[np.ndarray, np.ndarray, str | None]] = {}


def axis_neighbours(etype: EffectType) -> tuple[np.ndarray, np.ndarray, list]:
    """For each grid point of a family: its neighbours' indices along its form's axis (-1 where the
    form has more than one axis, at an end, or beside an infinite value) and the axis' value."""
    got = _AXES.get(etype.name)
    if got is None:
        grid = family_grid(etype)
        lo = np.full(len(grid), -1)
        hi = np.full(len(grid), -1)
        names: list = [None] * len(grid)
        for j, g in enumerate(grid):
            f = etype.get_form(g.form)
            if len(f.axes) != 1:
                continue
            p = next(iter(f.axes))
            names[j] = p
            for d, arr in ((-1, lo), (1, hi)):
                i = j + d
                if 0 <= i < len(grid) and grid[i].form == g.form and all(
                        math.isfinite(grid[x].params[p]) for x in (i, j)):
                    arr[j] = i
        got = _AXES[etype.name] = (lo, hi, names)
    return got


def subgrid(obj: np.ndarray, j: int, etype: EffectType) -> tuple[np.ndarray, np.ndarray, float | None]:
    """Where between its neighbours the minimum at grid point ``j`` lies: the vertex of the parabola
    through the three objective values along the form's axis. Returns the three indices, the
    interpolation weights that give any run's SSE there (Lagrange), and the parameter's value
    (None: no neighbours on both sides, or no interior minimum; then the weights pick ``j``)."""
    lo, hi, names = axis_neighbours(etype)
    a, b = int(lo[j]), int(hi[j])
    idx = np.array([j, j, j])
    # a neighbour no run can be predicted at (held at UNPREDICTED) bounds nothing: a parabola
    # through it would put the vertex anywhere, and its Lagrange weights, one of them negative,
    # would cancel it into any held-out SSE, zero included
    if a < 0 or b < 0 or not all(np.isfinite(obj[[a, j, b]])) or float(np.max(obj[[a, j, b]])) >= UNPREDICTED_AT:
        return idx, np.array([0.0, 1.0, 0.0]), None
    grid = family_grid(etype)
    p = names[j]
    x0, x1, x2 = (grid[i].params[p] for i in (a, j, b))
    f0, f1, f2 = obj[a], obj[j], obj[b]
    den = (x0 - x1) * (x0 - x2) * (x1 - x2)
    A = (x2 * (f1 - f0) + x1 * (f0 - f2) + x0 * (f2 - f1)) / den
    B = (x2 * x2 * (f0 - f1) + x1 * x1 * (f2 - f0) + x0 * x0 * (f1 - f2)) / den
    if not A > 0:
        return idx, np.array([0.0, 1.0, 0.0]), None
    x = min(max(-B / (2 * A), x0), x2)
    wts = np.array([(x - x1) * (x - x2) / ((x0 - x1) * (x0 - x2)), (x - x0) * (x - x2) / ((x1 - x0) * (x1 - x2)),
                    (x - x0) * (x - x1) / ((x2 - x0) * (x2 - x1))])
    return np.array([a, j, b]), wts, x


def pick(T: np.ndarray, w: np.ndarray, n: np.ndarray, ks: np.ndarray, acts: np.ndarray,
         null_dist: np.ndarray) -> tuple[int, float]:
    """The grid point a fit on the runs weighted ``w`` chooses, and its weighted SSE.

    Among the forms of a family the choice is by BIC (n log(SSE/n) + k log n): a form with more
    parameters must earn them. A form is eligible only where at least as many of the weighted runs
    see it as it has parameters, and a form with more parameters than the family's simplest needs
    one run more than that (three runs at three loads would pin down the three parameters of a
    stiffening cable exactly, noise and all). Ties (a parameter the runs cannot see) go to the point
    nearest to off.
    """
    on = w > 0
    obj = w[on] @ finite_table(T[on])
    n_w = max(float(w[on] @ n[on]), 1.0)
    seen = acts[on].sum(axis=0)
    k_min = int(ks[ks > 0].min()) if np.any(ks > 0) else 0
    need = np.where(ks > k_min, ks + 1, ks)
    ok = (need <= np.maximum(seen, 1)) | (ks == 0)
    crit = np.where(ok & (obj < UNPREDICTED_AT), n_w * np.log(np.maximum(obj, 1e-300) / n_w) + ks * math.log(n_w), np.inf)
    j = argmin(crit, null_dist, tol=1e-9 * n_w)
    return j, float(obj[j])


def argmin(obj: np.ndarray, null_dist: np.ndarray, tol: float | None = None) -> int:
    """The grid point of least SSE; among equal ones (a parameter the runs cannot see, e.g.
    coupling without a second knob, friction on a straight shaft) the one nearest to off."""
    obj = np.where(np.isfinite(obj), obj, np.inf)
    best = float(np.min(obj))
    if not math.isfinite(best):
        return int(np.argmin(null_dist))
    tie = np.flatnonzero(obj <= best + (1e-9 * abs(best) + 1e-12 if tol is None else tol))
    return int(tie[np.argmin(null_dist[tie])])


# --------------------------------------------------------------------------------------------
# least-squares fits of effect parameters
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Slot:
    i: int            # which free effect
    p: str            # parameter
    scale: float
    lo: float
    hi: float


def _slots(free: Sequence[tuple[EffectType, str, Mapping[str, float]]]) -> list[_Slot]:
    slots = []
    for i, (etype, form, params) in enumerate(free):
        f = etype.get_form(form)
        for p in f.fit:
            v = float(params[p])
            if not math.isfinite(v):
                continue  # a switch at an infinite null (saturation, contact off) stays where it is
            lo, hi = side_bounds(f, p, v)
            slots.append(_Slot(i, p, f.scale(p), lo, hi))
    return slots


def side_bounds(form: Form, p: str, v: float) -> tuple[float, float]:
    """The fitting bounds of ``p``, kept on ``v``'s side of zero when the grid has a gap there
    (a wall at +5 deg must not become one at -5 by passing 0, where it means nothing)."""
    lo, hi = form.bounds[p]
    axis = form.axes.get(p)
    if axis is not None and lo < 0.0 < hi:
        finite = axis[np.isfinite(axis)]
        if finite.size and not np.any(finite == 0.0) and np.any(finite < 0) and np.any(finite > 0):
            lo, hi = (lo, -1e-6) if v < 0 else (1e-6, hi)
    return lo, hi


def _params_at(free, slots, x) -> list[dict]:
    out = [dict(params) for _, _, params in free]
    for s, xv in zip(slots, x):
        out[s.i][s.p] = float(xv) * s.scale
    return out


def _effects_at(fixed, free, slots, x) -> tuple:
    return tuple(fixed) + tuple(make(et, form, p) for (et, form, _), p in zip(free, _params_at(free, slots, x)))


class Residuals:
    """Per-run residual vectors of a parameter vector, memoised (folds that start from the same
    point share them, and with them their Jacobian)."""

    def __init__(self, preps: Sequence[Prep], fixed, free, slots) -> None:
        self.preps, self.fixed, self.free, self.slots = preps, tuple(fixed), list(free), slots
        self._memo: dict[tuple, list] = {}

    def at(self, x: np.ndarray, runs: Sequence[int]) -> list:
        key = tuple(np.round(np.asarray(x, float), 12))
        got = self._memo.setdefault(key, [None] * len(self.preps))
        todo = [i for i in runs if got[i] is None]
        if todo:
            try:
                effs = _effects_at(self.fixed, self.free, self.slots, x)
            except ModelError:
                effs = None
            for i in todo:
                if effs is None:
                    got[i] = False
                    continue
                try:
                    got[i] = self.preps[i].residual(effs)
                except ModelError:
                    got[i] = False
        return got

    def sse(self, x: np.ndarray, w: np.ndarray) -> float:
        runs = [i for i in range(len(self.preps)) if w[i] > 0]
        got = self.at(x, runs)
        total = 0.0
        for i in runs:
            if got[i] is False:
                return math.inf
            r = got[i]
            total += w[i] * kernels.sumsq_kernel(r)
        return total


def _gauss_newton(res: Residuals, x0: np.ndarray, w: np.ndarray, bounds: np.ndarray, iterations: int,
                  frozen: bool) -> tuple[np.ndarray, float]:
    """Bounded, damped Gauss-Newton from ``x0`` on the weighted runs; Jacobian by forward
    differences (recomputed every iteration, or once when ``frozen``). Never returns a point
    worse than ``x0``."""
    runs = [i for i in range(len(res.preps)) if w[i] > 0]
    x = np.array(x0, float)
    f = res.sse(x, w)
    if not math.isfinite(f):
        return x, f
    J = None
    for _ in range(iterations):
        r0 = res.at(x, runs)
        if J is None or not frozen:
            h = np.maximum(1e-3 * np.maximum(np.abs(x), 0.1), 1e-6)
            cols = []
            for j in range(x.size):
                xj = x.copy()
                step = h[j] if xj[j] + h[j] <= bounds[j, 1] else -h[j]
                xj[j] += step
                rj = res.at(xj, runs)
                if any(rj[i] is False for i in runs):
                    return x, f
                cols.append([(rj[i] - r0[i]) / step for i in runs])
            J = cols
        A = np.zeros((x.size, x.size))
        b = np.zeros(x.size)
        for a, i in enumerate(runs):
            Ji = np.array([J[j][a] for j in range(x.size)])
            A += w[i] * (Ji @ Ji.T)
            b += w[i] * (Ji @ r0[i])
        lam = 1e-3
        improved = False
        for _ in range(6):
            try:
                delta = -np.linalg.solve(A + lam * np.diag(np.diag(A) + 1e-12), b)
            except np.linalg.LinAlgError:
                break
            xn = np.clip(x + delta, bounds[:, 0], bounds[:, 1])
            fn = res.sse(xn, w)
            if fn < f:
                improved = math.isfinite(fn)
                x, f = xn, fn
                break
            lam *= 10.0
        if not improved or abs(delta).max() < 1e-7:
            break
    return x, f


def fit(preps: Sequence[Prep], w: np.ndarray, fixed: Sequence[E.Effect],
        free: Sequence[tuple[EffectType, str, Mapping[str, float]]], iterations: int = 8,
        res: Residuals | None = None, frozen: bool = False):
    """Fit the tip parameters of the ``free`` effects (type, form, start) jointly on the weighted
    runs, ``fixed`` staying as they are: bounded Gauss-Newton on parameters scaled by their
    typical values.

    Returns the fitted ``[(type, form, params)]``, the weighted training SSE and the
    :class:`Residuals` (to share with later fits from the same start).
    """
    slots = _slots(free)
    x0 = np.array([min(max(float(free[s.i][2][s.p]), s.lo), s.hi) / s.scale for s in slots])
    if res is None:
        res = Residuals(preps, fixed, free, slots)
    if not slots:
        return [(et, fm, dict(p)) for et, fm, p in free], res.sse(x0, w), res
    bounds = np.array([(s.lo / s.scale, s.hi / s.scale) for s in slots])
    x, f = _gauss_newton(res, x0, w, bounds, iterations, frozen)
    return [(et, fm, p) for (et, fm, _), p in zip(free, _params_at(free, slots, x))], f, res
