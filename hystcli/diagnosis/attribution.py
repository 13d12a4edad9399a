"""The diagnosis' form-agnostic "which" stage: what physical quantity the residual follows.

Before any effect is fitted, the residual ``e = y - predicted`` of every run is regressed, group
by group, on physical regressors that name a cause without assuming its form:

=====================  ======================================================================
regressor              columns (each beside the generic loop terms 1, dir, dir*m, y)
=====================  ======================================================================
other knob angle       q_o * (1, m, dir, dir*m, side)  (q_o: the other knob's command)
other knob magnitude   a * (1, m, dir, dir*m, side)    (a = |yhat_o|: its section's bend as its
                                                     base model predicts it, 0 in its dead zone)
knob velocity          v, v*m                       (v = dq/dt)
time since reversal    dir*exp(-s/tau), tau = 0.5, 2, 8 s  (s: time since the knob reversed)
elapsed time           t - t0, (t - t0)*dir
curvature              kappa * (1, dir, dir*m, y, side)  (total curvature, rad)
condition              c * (1, dir, dir*m, y, side)      (the run's stated condition, rad)
tip angle              y^3, y*|y|                   (y: the predicted tip)
knob direction         dir, dir*m, y, side beside a constant alone (a loop-shape error)
=====================  ======================================================================

with ``dir`` the sign of the knob's last motion, ``m`` 1 where the model's hysteresis output
moves (the tip follows the knob), 0 on its plateaus, and ``side = sign(y)*m`` (which loaded slope:
where a wider or narrower dead zone shows). Each group is fitted on the training runs of
every fold of the diagnosis and scored on the held-out runs: the share of the residual's energy it
explains beyond the generic loop terms (what any error of the loop's width, slope or offset leaves). The ranking is reported in WHERE, orders the candidate effects
(each effect names the regressors its residual follows), and says what is left unexplained.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ..core import effects as E
from .search import Prep

REGRESSORS = ("other knob angle", "other knob magnitude", "knob velocity", "time since reversal",
              "elapsed time", "curvature", "condition", "tip angle", "knob direction")
"""The physical regressors, in report order."""


@dataclass(frozen=True)
class Attribution:
    """How much of the residual one regressor explains on held-out runs.

    Attributes
    ----------
    regressor : str
        One of :data:`REGRESSORS`.
    explained_pct : float
        Held-out share of the residual energy it explains beyond a constant offset (%; < 0 when it
        does worse than the constant on runs it was not fitted on).
    """

    regressor: str
    explained_pct: float


def _direction(v: np.ndarray) -> np.ndarray:
    # the sign of the last motion, held through pauses (0 before the first move)
    s = np.sign(v)
    idx = np.where(s != 0, np.arange(s.size), 0)
    np.maximum.accumulate(idx, out=idx)
    d = s[idx]
    d[: np.argmax(s != 0) if np.any(s != 0) else s.size] = 0.0
    return d


def _since_reversal(d: np.ndarray, t: np.ndarray) -> np.ndarray:
    change = np.r_[True, d[1:] != d[:-1]]
    start = np.where(change, np.arange(d.size), 0)
    np.maximum.accumulate(start, out=start)
    return t - t[start]


def columns(p: Prep, k: int, effects: Sequence[E.Effect]) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """The residual of knob ``k`` of a prepared run, the generic loop terms every group is
    measured beyond, and every regressor group's columns."""
    tr = p.trace(effects, k) if effects else None
    yp = tr.y if tr is not None else p.knobs[k].forward(p.q[k], float(p.y[k][0]))
    yh = tr.yh if tr is not None and tr.yh is not None else yp
    e = p.y[k] - yp
    t = p.t
    v = np.gradient(p.q[k], t) if t.size > 1 else np.zeros_like(t)
    d = _direction(np.where(np.abs(v) > 1e-6, v, 0.0))
    m = (np.abs(np.gradient(yh, t)) > 1e-6).astype(float) if t.size > 1 else np.zeros_like(t)
    s = _since_reversal(d, t)
    te = t - t[0]
    one = np.ones_like(t)
    # what any loop-shape error leaves (an offset, a wider loop, a slope, a dead zone): a group
    # earns credit only for what it explains beyond these
    side = np.sign(yp) * m   # which loaded slope the tip is on: a dead-zone width error
    loop = np.column_stack([one, d, d * m, yp / 50.0, side])
    groups: dict[str, np.ndarray] = {}
    o = p.q.get(3 - k)
    if o is not None:
        # the bend the magnitude coupling reads (hystcli/core/effects/coupling.py): the other knob's
        # travel from its offset where its model is missing
        bend = p.bend(3 - k)
        a = np.abs(o - p.offsets.get(3 - k, 0.0)) if bend is None else np.abs(bend)
        groups["other knob angle"] = np.column_stack([o, o * m, o * d, o * d * m, o * side])
        groups["other knob magnitude"] = np.column_stack([a, a * m, a * d, a * d * m, a * side])
    groups["knob velocity"] = np.column_stack([v, v * m])
    groups["time since reversal"] = np.column_stack([d * np.exp(-s / tau) for tau in (0.5, 2.0, 8.0)])
    groups["elapsed time"] = np.column_stack([te, te * d])
    kappa = math.radians(p.shape.total_curvature)
    groups["curvature"] = kappa * loop
    if p.condition is not None:
        groups["condition"] = math.radians(p.condition) * loop
    groups["tip angle"] = np.column_stack([(yp / 50.0) ** 3, yp * np.abs(yp) / 2500.0])
    return e, loop, groups


def attribute(preps: Sequence[Prep], effects: Sequence[E.Effect], folds, w: np.ndarray) -> tuple[Attribution, ...]:
    """Rank the regressors by the held-out share of the residual they explain (best first).

    Each group is fitted, with the generic loop terms (a constant, the knob direction, the
    direction where the tip moves, the tip angle), on a fold's training runs and scored on its
    held-out runs against the loop terms alone: its share of the residual energy explained beyond
    them. A group that does not vary across the runs is left out (one curvature for every run
    cannot tell a curvature effect from a loop-shape error).

    Parameters
    ----------
    preps : sequence of Prep
        The runs (decimated is enough: the regressors are slow).
    effects : sequence of Effect
        The model's effects (the residual is the one they leave).
    folds : sequence of (train, test) index arrays
        The diagnosis' hold-out folds.
    w : numpy.ndarray
        Run weights.
    """
    energy = np.zeros(len(preps))
    stats: dict[str, list] = {}
    curv = {p.shape.total_curvature for p in preps}
    conds = {p.condition for p in preps}
    for i, p in enumerate(preps):
        for k in p.knobs:
            e, loop, groups = columns(p, k, effects)
            energy[i] += float(np.dot(e, e))
            if len(curv) < 2:
                groups.pop("curvature", None)
            if len(conds) < 2:
                groups.pop("condition", None)
            groups["knob direction"] = loop[:, 1:]
            for name, X in groups.items():
                if not np.any(X):
                    continue
                base = loop[:, :1] if name == "knob direction" else loop
                Xc = np.column_stack([base, X])
                G, c = Xc.T @ Xc, Xc.T @ e
                per = stats.setdefault(name, [None] * len(preps))
                per[i] = (G, c, base.shape[1]) if per[i] is None else (per[i][0] + G, per[i][1] + c, base.shape[1])
    out = []
    for name in REGRESSORS:
        per = stats.get(name)
        if per is None:
            continue
        size = next(x[0].shape[0] for x in per if x is not None)
        nb = next(x[2] for x in per if x is not None)
        G = np.zeros((len(preps), size, size))
        c = np.zeros((len(preps), size))
        for i, x in enumerate(per):
            if x is not None:
                G[i], c[i] = x[0], x[1]
        gain = total = 0.0
        for train, test in folds:
            wt = w[train]
            if wt.sum() <= 0 or w[test].sum() <= 0:
                continue
            A = np.tensordot(wt, G[train], axes=1)
            b = wt @ c[train]
            beta = _solve(A, b)
            beta0 = _solve(A[:nb, :nb], b[:nb])
            for i in test:
                held = energy[i] - 2 * beta @ c[i] + beta @ G[i] @ beta
                held0 = energy[i] - 2 * beta0 @ c[i, :nb] + beta0 @ G[i, :nb, :nb] @ beta0
                gain += w[i] * (held0 - held)
                total += w[i] * energy[i]
        if total > 0:
            out.append(Attribution(name, float(100.0 * gain / total)))
    return tuple(sorted(out, key=lambda a: -a.explained_pct))


def _solve(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    # a touch of ridge: a group whose columns are collinear on these runs (one shape) still solves
    ridge = 1e-9 * max(float(np.trace(A)) / max(A.shape[0], 1), 1e-12)
    return np.linalg.solve(A + ridge * np.eye(A.shape[0]), b)


def score(etype, ranking: Sequence[Attribution]) -> float:
    """The best held-out share any of the effect's regressors explains (0 when none is present)."""
    got = {a.regressor: a.explained_pct for a in ranking}
    return max((got[r] for r in etype.regressors if r in got), default=0.0)


def describe(ranking: Sequence[Attribution], top: int = 3) -> str:
    """``other knob magnitude 41 %, knob velocity 9 %``: the leading regressors in words."""
    shown = [a for a in ranking[:top] if a.explained_pct >= 1.0]
    return ", ".join(f"{a.regressor} {a.explained_pct:.0f} %" for a in shown) or "nothing above 1 %"
