"""Form-agnostic reference fits: what a sweep or replay record itself allows (the bench's yardstick).

The bench scores identify and detect-shift against what the data allow, not against the method's
own rules. This module owns that yardstick. It imports nothing from ``hystcli`` (numpy, scipy and
numba only) and was written without reading the method's code.

Three estimators, each a least-squares fit with a 95 % profile-likelihood interval per parameter:

``tip_reference(t, q, y)``
    The seven tip parameters (and the unknown initial tip state) through the clamp recursion
    ``y_t = min(max(y_{t-1}, f_up(u_t)), f_dn(u_t))`` (docs/design.md section 3; the envelopes are
    written here as medians of their three pieces), from a grid of starts over the swept range.
    A rigid wall that stops the tip on one side is an optional term, kept when BIC prefers it.
``current_reference(t, q, c)``
    One superset physical law of the motor current (:class:`_CurrentModel`) fitted by robust
    least squares (soft-L1 loss scaled to twice a robust noise estimate) over the whole sweep:
    a no-load level with drift, motor Coulomb and viscous friction (and friction growing with the
    load), a pretension slope, each tendon's load from its own state (stretch past its edge,
    optionally with a rounded onset; at a reversal a friction drop over a short travel, a hold
    over the backlash, a linear release to a slack point), stiffening, a wall on one side,
    cogging ripple in ``q``, a latency of the current behind the command, and a magnitude
    variant (``c0 + |c - c0|``). The base law (level, tendons, drop, friction) is fitted from
    generic starts (edges and slack points read per direction of travel by grids of linear
    fits, with a second knot for a wall; whole-record edge pairs), the best three run to
    convergence; the optional terms are then added greedily while BIC (over ``n / tau``
    effective samples) drops. It gives the knob angles where each tendon's current departs
    from no-load (``d_pos``, ``d_neg``) and, where the fitted law holds a tendon's load after a
    reversal past its drop (by more than :data:`MIN_HOLD`, behind an edge placed within
    :data:`EDGE_FOR_HOLD`), the length of that hold (``b_pos``, ``b_neg``).
``shift_reference(sweep_ref, t, q, c)``
    The same law with the sweep's fit held, the replay's own level, drift and friction free, and
    the shift ``offset`` of all tendon terms along the knob axis.

The profile interval of a parameter is the set of values whose best refit (every other parameter
free) stays within ``3.84 * s`` of the best objective, where ``s`` is the residual variance (the
robust M-estimator's ``E[psi^2]/E[psi']`` for the soft-L1 loss) times the residuals' integrated
autocorrelation time, so that filtered or coloured noise is not counted as independent samples.
A side that runs into the parameter's domain (a backlash of 0) keeps that limit and is flagged
open; a side that runs out of the record's range is infinite.

Records are reduced to bins before fitting (consecutive samples, at most a small knob travel and
never across a reversal; the tip is averaged, the current takes the bin median so that outliers and
stiction bursts do not leak into the bin), each bin weighted by the square root of its size.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
from numba import njit
from scipy.optimize import least_squares
from threadpoolctl import threadpool_limits

CHI2_95 = 3.841458820694124
"""The chi-square(1) 0.95 quantile: the profile's bound."""
TIP_PARAMS = ("d_pos", "d_neg", "b_pos", "b_neg", "omega", "h_pos", "h_neg")
CURRENT_PARAMS = ("d_pos", "d_neg", "b_pos", "b_neg")
MIN_HOLD = 0.25
"""deg: a current's hold after a reversal shorter than this is not read as a backlash (the bins,
a drop's own travel and the filter round a reversal over about that much knob travel)."""
EDGE_FOR_HOLD = 1.0
"""deg: a tendon's hold is read only where its edge is placed to this half-width."""
MAX_BINS = 2000
"""Bins a record is reduced to (about): enough for 0.1-deg edges on a full sweep, and fast."""


# --------------------------------------------------------------------------------------------
# Results
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ParamInterval:
    """One parameter's estimate and 95 % profile interval.

    ``lo``/``hi`` are infinite where the profile ran out of the record's range; where it ran into
    the parameter's domain limit they keep that limit and ``lo_open``/``hi_open`` say so.
    """

    estimate: float
    lo: float
    hi: float
    lo_open: bool = False
    hi_open: bool = False

    def resolved(self, tol: float) -> bool:
        """True when the interval is finite and its half-width is at most ``tol``."""
        return bool(math.isfinite(self.lo) and math.isfinite(self.hi)
                    and 0.5 * (self.hi - self.lo) <= tol)

    def contains(self, value: float) -> bool:
        return bool(self.lo <= value <= self.hi)


@dataclass(frozen=True)
class RefFit:
    """A reference fit: per parameter an interval, plus what the fit used.

    ``law`` carries what :func:`shift_reference` needs to hold the sweep's fit (current fits only).
    """

    params: dict[str, ParamInterval]
    terms: tuple[str, ...]
    sigma: float
    tau: float
    n_bins: int
    seconds: float
    law: dict = field(default_factory=dict, repr=False)

    def __getitem__(self, name: str) -> ParamInterval:
        return self.params[name]

    def resolved(self, name: str, tol: float) -> bool:
        return self.params[name].resolved(tol)


def _one_thread(f):
    """Run f with BLAS on one thread: the fits' matrices are small, and a threaded BLAS on a
    loaded machine spends a hundred times longer waiting than computing."""
    import functools

    @functools.wraps(f)
    def wrapped(*a, **kw):
        with threadpool_limits(limits=1, user_api="blas"):
            return f(*a, **kw)
    return wrapped


class RefFitError(ValueError):
    """A record the reference cannot fit at all (too short, no knob motion, not finite)."""


# --------------------------------------------------------------------------------------------
# Records to bins
# --------------------------------------------------------------------------------------------
@njit(cache=True)
def _bin_starts(q, max_travel, max_count):
    n = q.shape[0]
    starts = np.empty(n + 1, np.int64)
    starts[0] = 0
    k = 1
    s = 0
    d = 0.0
    for i in range(1, n):
        step = q[i] - q[i - 1]
        sd = 0.0
        if step > 0.0:
            sd = 1.0
        elif step < 0.0:
            sd = -1.0
        new = i - s >= max_count or abs(q[i] - q[s]) > max_travel or (sd != 0.0 and d != 0.0 and sd != d)
        if new:
            starts[k] = i
            k += 1
            s = i
            d = sd
        elif sd != 0.0:
            d = sd
    starts[k] = n
    return starts[:k + 1]


@njit(cache=True)
def _aggregate(starts, t, q, v, x, median):
    nb = starts.shape[0] - 1
    tb = np.empty(nb)
    qb = np.empty(nb)
    vb = np.empty(nb)
    xb = np.empty(nb)
    mb = np.empty(nb)
    for j in range(nb):
        a = starts[j]
        b = starts[j + 1]
        tb[j] = t[a:b].mean()
        qb[j] = q[a:b].mean()
        vb[j] = v[a:b].mean()
        xb[j] = np.median(x[a:b]) if median else x[a:b].mean()
        mb[j] = b - a
    return tb, qb, vb, xb, mb


@dataclass(frozen=True)
class _Bins:
    t: np.ndarray
    q: np.ndarray
    v: np.ndarray
    x: np.ndarray        # the measured column (tip or current), per bin
    w: np.ndarray        # sqrt(samples in the bin)
    tn: np.ndarray       # time scaled to [-1, 1]
    q_raw: np.ndarray    # the knob's samples (time order), and where each bin starts in them
    starts: np.ndarray
    travel: float        # the most knob travel a bin may span (deg)


def _binned(t, q, x, *, median: bool, max_bins: int = MAX_BINS) -> _Bins:
    t = np.ascontiguousarray(t, dtype=np.float64)
    q = np.ascontiguousarray(q, dtype=np.float64)
    x = np.ascontiguousarray(x, dtype=np.float64)
    if not (t.ndim == q.ndim == x.ndim == 1 and t.size == q.size == x.size):
        raise RefFitError("t, q and the measured column must be 1-D arrays of one length")
    if t.size < 30:
        raise RefFitError(f"a record of {t.size} samples is too short (at least 30)")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(q)) and np.all(np.isfinite(x))):
        raise RefFitError("the record has non-finite samples")
    if np.ptp(q) <= 0.0:
        raise RefFitError("the knob never moves")
    order = np.argsort(t, kind="stable")
    t, q, x = t[order], q[order], x[order]
    dt = np.diff(t)
    v = np.gradient(q, t) if np.all(dt > 0) else np.gradient(q) / max(float(np.median(dt)), 1e-9)
    travel = float(np.abs(np.diff(q)).sum())
    max_travel = max(0.05, travel / max_bins)
    max_count = max(1, int(math.ceil(t.size / max_bins)))
    st = _bin_starts(q, max_travel, max_count)
    tb, qb, vb, xb, mb = _aggregate(st, t, q, v, x, median)
    span = max(float(tb[-1] - tb[0]), 1e-9)
    return _Bins(t=tb, q=qb, v=vb, x=xb, w=np.sqrt(mb), tn=2.0 * (tb - tb[0]) / span - 1.0,
                 q_raw=q, starts=st[:-1].copy(), travel=max_travel)


# --------------------------------------------------------------------------------------------
# The fitting engine: held parameters, robust loss, profiles
# --------------------------------------------------------------------------------------------
def _tau_int(r: np.ndarray) -> float:
    """Integrated autocorrelation time of a series (Sokal's automatic window, c = 5)."""
    r = np.asarray(r, float) - float(np.mean(r))
    n = r.size
    var = float(r @ r)
    if n < 8 or var <= 0:
        return 1.0
    f = np.fft.rfft(r, 2 * n)
    acf = np.fft.irfft(f * np.conj(f))[:n] / var
    tau = 1.0
    for m in range(1, n // 4):
        tau += 2.0 * acf[m]
        if m >= 5.0 * tau:
            break
    return float(max(tau, 1.0))


class _Problem:
    """Least squares over a full parameter vector, some entries held (the profile's refits).

    ``resid(x)`` gives the weighted residuals (plus any penalty rows after ``n_data``);
    ``jac(x, idx)`` the Jacobian columns of the free entries ``idx``.
    """

    def __init__(self, resid, jac, lb, ub, n_data: int, loss: str = "linear", f_scale: float = 1.0):
        self.resid = resid
        self.jac = jac
        self.lb = np.asarray(lb, float)
        self.ub = np.asarray(ub, float)
        self.n_data = n_data
        self.loss = loss
        self.f_scale = float(f_scale)

    def objective(self, r: np.ndarray) -> float:
        """2 x scipy's cost: sum of r^2 for the plain loss, f^2 rho(r^2/f^2) for soft-L1."""
        if self.loss == "linear":
            return float(r @ r)
        z = (r / self.f_scale) ** 2
        return float(self.f_scale ** 2 * np.sum(2.0 * (np.sqrt(1.0 + z) - 1.0)))

    def fit(self, x0: np.ndarray, free: np.ndarray, max_nfev: int | None = None):
        idx = np.flatnonzero(free)
        lb, ub = self.lb[idx], self.ub[idx]
        base = np.array(x0, float)

        def full(z):
            x = base.copy()
            x[idx] = z
            return x

        z0 = np.clip(base[idx], lb, ub)
        if idx.size == 0:
            r = self.resid(base)
            return base, self.objective(r)
        res = least_squares(lambda z: self.resid(full(z)), z0, jac=lambda z: self.jac(full(z), idx),
                            bounds=(lb, ub), loss=self.loss, f_scale=self.f_scale, x_scale="jac",
                            method="trf", max_nfev=max_nfev, ftol=1e-7, xtol=1e-7)
        x = full(res.x)
        return x, 2.0 * float(res.cost)

    def violated(self, x: np.ndarray) -> bool:
        """True when x breaks a validity constraint (a penalty row after the data is active)."""
        r = self.resid(x)[self.n_data:]
        return bool(r.size and np.any(np.abs(r) > 0.0))

    def scores(self, x: np.ndarray) -> tuple[np.ndarray, float]:
        """(psi of each data residual, E[psi^2]/E[psi']): the M-estimator's score series and the
        scale of its deviance (sigma^2 for plain least squares)."""
        r = self.resid(x)[: self.n_data]
        if self.loss == "linear":
            return r, float(r @ r) / max(r.size, 1)
        z = (r / self.f_scale) ** 2
        d1 = 1.0 / np.sqrt(1.0 + z)
        d2 = -0.5 * (1.0 + z) ** -1.5
        psi = r * d1
        dpsi = d1 + 2.0 * z * d2
        return psi, float(np.mean(psi ** 2) / max(np.mean(dpsi), 1e-12))


def _fd_jac(resid, x, idx, steps, ub):
    """Forward differences of resid over the entries idx (backward at an upper bound)."""
    r0 = resid(x)
    J = np.empty((r0.size, idx.size))
    for j, i in enumerate(idx):
        h = steps[i]
        if x[i] + h > ub[i]:
            h = -h
        xp = x.copy()
        xp[i] += h
        J[:, j] = (resid(xp) - r0) / h
    return J


@dataclass
class _Limits:
    """Where a parameter's profile stops: its domain (kept, flagged open) and the record's range
    (beyond it the side is infinite)."""

    dom_lo: float = -math.inf
    dom_hi: float = math.inf
    rec_lo: float = -math.inf
    rec_hi: float = math.inf


class _Better(Exception):
    """A profile refit found a better optimum than the one profiled from."""

    def __init__(self, x, s):
        super().__init__("better optimum")
        self.x, self.s = x, s


def _profile_side(prob, x_best, s_best, k, free, thr, step0, lim: _Limits, sgn: int, tol_v: float,
                  restart: bool = True):
    """One end of parameter k's profile interval: (end, open_flag). A refit better than the
    optimum raises :class:`_Better` when ``restart`` (else it counts as inside)."""
    dom = lim.dom_lo if sgn < 0 else lim.dom_hi
    rec = lim.rec_lo if sgn < 0 else lim.rec_hi
    limit = max(dom, rec) if sgn < 0 else min(dom, rec)
    domain_binds = (dom >= rec) if sgn < 0 else (dom <= rec)
    fr = free.copy()
    fr[k] = False
    est = float(x_best[k])
    pv, px, pd = est, x_best, 0.0
    step = step0
    out = None
    better = -max(1e-9 * abs(s_best), 1e-6 * thr) if restart else -math.inf
    for _ in range(16):
        v = pv + sgn * step
        at_limit = v <= limit if sgn < 0 else v >= limit
        if at_limit:
            v = limit
        if (v - pv) * sgn <= 0:      # already at the limit
            break
        x0 = px.copy()
        x0[k] = v
        x, s = prob.fit(x0, fr)
        d = s - s_best
        if d < better:
            raise _Better(x, s)
        if d > thr:
            out = (v, d, x)
            break
        pv, px, pd = v, x, d
        if at_limit:
            break
        step *= 2.0
    if out is None:
        return (limit, True) if domain_binds else (-math.inf if sgn < 0 else math.inf, True)
    # a refit that can only break the model's validity constraints has run into the domain
    hit_domain = prob.violated(out[2])
    # the profile deviance is about quadratic: its square root is about linear in the value
    a, da, xa = pv, pd, px
    b, db, _ = out
    for it in range(8):
        if abs(b - a) <= max(tol_v, 0.05 * abs(a - est)):
            break
        ra, rb, rt = math.sqrt(max(da, 0.0)), math.sqrt(db), math.sqrt(thr)
        frac = (rt - ra) / max(rb - ra, 1e-12) if it % 2 == 0 else 0.5   # interpolate, bisect
        v = a + min(max(frac, 0.1), 0.9) * (b - a)
        x0 = xa.copy()
        x0[k] = v
        x, s = prob.fit(x0, fr)
        d = s - s_best
        if d < better:
            raise _Better(x, s)
        if d > thr:
            b, db = v, d
        else:
            a, da, xa = v, d, x
    ra, rb, rt = math.sqrt(max(da, 0.0)), math.sqrt(db), math.sqrt(thr)
    frac = (rt - ra) / max(rb - ra, 1e-12)
    return a + min(max(frac, 0.0), 1.0) * (b - a), hit_domain


def _wald_halfwidth(prob, x, free, k, thr) -> float:
    idx = np.flatnonzero(free)
    J = prob.jac(x, idx)[: prob.n_data]
    try:
        cov = np.linalg.pinv(J.T @ J)
    except np.linalg.LinAlgError:
        return math.nan
    j = int(np.flatnonzero(idx == k)[0])
    return float(math.sqrt(max(cov[j, j] * thr, 0.0)))


def _profiles(prob, x_best, s_best, free, names: dict[str, int], limits: dict[str, _Limits],
              min_step: dict[str, float], restarts: int = 3):
    """Profile every named parameter; a better optimum found on the way restarts all profiles.

    Returns (x_best, s_best, {name: (lo, hi, lo_open, hi_open)}, tau, scale).
    """
    for attempt in range(restarts + 1):
        last = attempt == restarts
        psi, scale = prob.scores(x_best)
        tau = _tau_int(psi)
        thr = CHI2_95 * scale * tau
        out = {}
        try:
            for name, k in names.items():
                lim = limits[name]
                hw = _wald_halfwidth(prob, x_best, free, k, thr)
                span = min(lim.rec_hi, lim.dom_hi) - max(lim.rec_lo, lim.dom_lo)
                step0 = hw if math.isfinite(hw) and hw > 0 else 0.1 * span
                step0 = float(min(max(step0, min_step[name]), 0.25 * span if math.isfinite(span) else step0))
                lo, lo_open = _profile_side(prob, x_best, s_best, k, free, thr, step0, lim, -1,
                                            0.1 * min_step[name], not last)
                hi, hi_open = _profile_side(prob, x_best, s_best, k, free, thr, step0, lim, +1,
                                            0.1 * min_step[name], not last)
                out[name] = (lo, hi, lo_open, hi_open)
            return x_best, s_best, out, tau, scale
        except _Better as b:
            x_best, s_best = prob.fit(b.x, free)
    raise AssertionError("unreachable: the last round never restarts")


def _interval(x, k, prof) -> ParamInterval:
    lo, hi, lo_open, hi_open = prof
    est = float(x[k])
    return ParamInterval(estimate=est, lo=float(min(lo, est)), hi=float(max(hi, est)),
                         lo_open=bool(lo_open), hi_open=bool(hi_open))


def _widen(iv: ParamInterval, by: float) -> ParamInterval:
    """The interval widened by ``by`` on each finite side not held at a domain limit."""
    lo = iv.lo if iv.lo_open else iv.lo - by
    hi = iv.hi if iv.hi_open else iv.hi + by
    return ParamInterval(iv.estimate, lo, hi, iv.lo_open, iv.hi_open)


def _bic(s: float, n: int, p: int, tau: float = 1.0) -> float:
    """BIC of an objective s over n residuals with p free parameters; residuals correlated over
    tau bins carry the information of n / tau independent ones."""
    ne = n / max(tau, 1.0)
    return ne * math.log(max(s, 1e-300) / n) + p * math.log(ne)


# --------------------------------------------------------------------------------------------
# Tip
# --------------------------------------------------------------------------------------------
@njit(cache=True)
def _clamp(u, d_pos, d_neg, b_pos, b_neg, omega, h_pos, h_neg, y0, wall_side, wall_y):
    """y_t = min(max(y_{t-1}, f_up(u_t)), f_dn(u_t)), a wall stopping y on one side."""
    dhp = (h_pos - h_neg) / omega + d_neg + b_neg
    dhn = (h_neg - h_pos) / omega + d_pos - b_pos
    out = np.empty(u.shape[0])
    y = y0
    for i in range(u.shape[0]):
        x = u[i]
        fu = max(omega * (x - d_pos) + h_pos, min(h_pos, omega * (x - dhp) + h_pos))
        fd = min(omega * (x - d_neg) + h_neg, max(h_neg, omega * (x - dhn) + h_neg))
        if fu > y:
            y = fu
        if fd < y:
            y = fd
        if wall_side > 0.0 and y > wall_y:
            y = wall_y
        elif wall_side < 0.0 and y < wall_y:
            y = wall_y
        out[i] = y
    return out


class _TipModel:
    """x = d_pos, d_neg, b_pos, b_neg, omega, h_pos, h_neg, y0, wall_y."""

    def __init__(self, bins: _Bins, wall_side: float):
        self.b = bins
        self.wall_side = float(wall_side)
        qs = float(np.ptp(bins.q))
        ys = max(float(np.ptp(bins.x)), 1.0)
        self.penalty = 1e3 * math.sqrt(float(np.sum(bins.w ** 2))) * ys / max(qs, 1.0)

    def predict(self, x):
        """The recursion on every sample, averaged per bin as the data are (exact bin means: a
        kink inside a bin costs no bias)."""
        b = self.b
        y = _clamp(b.q_raw, x[0], x[1], x[2], x[3], x[4], x[5], x[6], x[7], self.wall_side, x[8])
        return np.add.reduceat(y, b.starts) / (b.w * b.w)

    def resid(self, x):
        r = self.b.w * (self.predict(x) - self.b.x)
        dh = x[6] - x[5]
        gap = (x[0] - x[1]) + dh / x[4]
        pen = self.penalty * np.array([max(0.0, -dh), max(0.0, x[2] - gap), max(0.0, x[3] - gap)])
        return np.concatenate([r, pen])


def _tip_fit_variant(bins: _Bins, wall_side: float, starts: list[np.ndarray]):
    m = _TipModel(bins, wall_side)
    q0, q1 = float(bins.q.min()), float(bins.q.max())
    qs = q1 - q0
    y0, y1 = float(bins.x.min()), float(bins.x.max())
    ys = max(y1 - y0, 1.0)
    lb = np.array([q0 - qs, q0 - qs, 0.0, 0.0, 1e-3, y0 - 2 * ys, y0 - 2 * ys, y0 - 2 * ys, y0 - ys])
    ub = np.array([q1 + qs, q1 + qs, 2 * qs, 2 * qs, 1e3, y1 + 2 * ys, y1 + 2 * ys, y1 + 2 * ys, y1 + ys])
    steps = np.array([1e-3, 1e-3, 1e-3, 1e-3, 1e-5, 1e-3, 1e-3, 1e-3, 1e-3])
    prob = _Problem(m.resid, lambda x, idx: _fd_jac(m.resid, x, idx, steps, ub), lb, ub,
                    n_data=bins.q.size)
    free = np.ones(9, bool)
    free[8] = wall_side != 0.0
    best = None
    for s in starts:
        x0 = s.copy()
        x0[8] = y1 if wall_side > 0 else y0
        x, cost = prob.fit(np.clip(x0, lb, ub), free)
        if best is None or cost < best[1]:
            best = (x, cost)
    return prob, free, best[0], best[1]


def _tip_starts(bins: _Bins) -> list[np.ndarray]:
    """A grid over the swept range: for each pair of edges, the symmetric loop without hysteresis
    is linear in (level, slope); the best few pairs start the full fit with and without backlash."""
    q, y, w = bins.q, bins.x, bins.w
    q0, q1 = float(q.min()), float(q.max())
    grid = q0 + (q1 - q0) * np.linspace(0.04, 0.96, 24)
    cand = []
    for i, dn in enumerate(grid):
        for dp in grid[i + 1:]:
            g = np.maximum(q - dp, 0.0) - np.maximum(dn - q, 0.0)
            A = np.column_stack([np.ones_like(q), g]) * w[:, None]
            coef, *_ = np.linalg.lstsq(A, y * w, rcond=None)
            r = A @ coef - y * w
            if coef[1] > 0:
                cand.append((float(r @ r), dp, dn, float(coef[0]), float(coef[1])))
    cand.sort()
    starts = []
    picked: list[tuple[float, float]] = []
    for _, dp, dn, h, om in cand:
        if any(abs(dp - a) < 0.1 * (q1 - q0) and abs(dn - b) < 0.1 * (q1 - q0) for a, b in picked):
            continue
        picked.append((dp, dn))
        for bf in (0.0, 0.3, 0.6):
            b = bf * (dp - dn)
            starts.append(np.array([dp, dn, b, b, om, h, h, float(y[0]), 0.0]))
        if len(picked) == 6:
            break
    if not starts:
        mid = 0.5 * (q0 + q1)
        starts.append(np.array([mid + 0.1 * (q1 - q0), mid - 0.1 * (q1 - q0), 0.0, 0.0, 1.0,
                                float(np.median(y)), float(np.median(y)), float(y[0]), 0.0]))
    return starts


@_one_thread
def tip_reference(t, q, y, *, max_bins: int = MAX_BINS) -> RefFit:
    """Least-squares fit of the seven tip parameters with 95 % profile intervals.

    Parameters
    ----------
    t, q, y : array_like
        Time (s), knob angle (deg) and tip angle (deg) of one sweep.

    Returns
    -------
    RefFit
        ``params`` for :data:`TIP_PARAMS`; ``terms`` is ``("clamp",)`` or ``("clamp", "wall+")``
        / ``("clamp", "wall-")`` when BIC keeps a wall stopping the tip.
    """
    t0 = time.perf_counter()
    bins = _binned(t, q, y, median=False, max_bins=max_bins)
    starts = _tip_starts(bins)
    n = bins.q.size
    variants = []
    for side in (0.0, 1.0, -1.0):
        prob, free, x, s = _tip_fit_variant(bins, side, starts if side == 0.0 else [variants[0][2]])
        variants.append((prob, free, x, s, side))
    prob, free, x, s, side = min(variants, key=lambda v: _bic(v[3], n, int(v[1].sum())))
    q0, q1 = float(bins.q.min()), float(bins.q.max())
    qs = q1 - q0
    y0, y1 = float(bins.x.min()), float(bins.x.max())
    ys = max(y1 - y0, 1.0)
    limits = {"d_pos": _Limits(rec_lo=q0, rec_hi=q1), "d_neg": _Limits(rec_lo=q0, rec_hi=q1),
              "b_pos": _Limits(dom_lo=0.0, rec_hi=qs), "b_neg": _Limits(dom_lo=0.0, rec_hi=qs),
              "omega": _Limits(dom_lo=1e-3, rec_hi=1e3),
              "h_pos": _Limits(rec_lo=y0 - ys, rec_hi=y1 + ys),
              "h_neg": _Limits(rec_lo=y0 - ys, rec_hi=y1 + ys)}
    min_step = {p: 0.02 for p in TIP_PARAMS}
    min_step["omega"] = 0.002
    names = {p: i for i, p in enumerate(TIP_PARAMS)}
    x, s, prof, tau, scale = _profiles(prob, x, s, free, names, limits, min_step)
    params = {p: _interval(x, k, prof[p]) for p, k in names.items()}
    for p in ("omega",):
        iv = params[p]
        if iv.lo <= limits[p].dom_lo:
            params[p] = ParamInterval(iv.estimate, 0.0, iv.hi, True, iv.hi_open)
    terms = ("clamp",) + ((("wall+" if side > 0 else "wall-"),) if side else ())
    return RefFit(params=params, terms=terms, sigma=math.sqrt(scale), tau=tau, n_bins=n,
                  seconds=time.perf_counter() - t0,
                  law={"x": x.tolist(), "wall_side": side})


# --------------------------------------------------------------------------------------------
# Current
# --------------------------------------------------------------------------------------------
@njit(cache=True)
def _onset(s, w):
    if s <= 0.0:
        return 0.0
    if w > 0.0 and s < w:
        return s * s / (2.0 * w)
    return s - 0.5 * w if w > 0.0 else s


@njit(cache=True)
def _unload(x, xr, pr, phi, delta, upe, us):
    """Load at x after a reversal at xr with load pr: the friction drop (a fraction phi over a
    travel delta), held down to upe, then a linear release to zero at us."""
    at = x if x >= upe else upe
    frac = 1.0
    if delta > 0.0:
        frac = (xr - at) / delta
        if frac > 1.0:
            frac = 1.0
        elif frac < 0.0:
            frac = 0.0
    top = pr * (1.0 - phi * frac)
    if x >= upe:
        return top
    if x > us:
        return top * (x - us) / (upe - us)
    return 0.0


@njit(cache=True)
def _tendon(v, e, lo, beta, gamma, rho, phi, delta, w, v_hist, out):
    """One tendon's load (knob degrees of stretch) along its own coordinate v (growing as it is
    taken up); returns how often it is taken up from slack within the record.

    Loading: ``max(onset(v - e), floor)`` (the floor is the load it held when the knob last
    turned back toward it). At a reversal at ``x_r`` with load ``P_r`` the load drops by a
    fraction ``phi`` over a travel ``delta`` (the friction flipping), is held while the knob
    travels ``beta`` back, then falls linearly to zero at
    ``u_s = min(e + gamma, x_r - beta - rho P_r)`` (not below the other tendon's edge ``lo``).
    The history before the record: slack mid dead zone, then to ``v_hist``, then to ``v[0]``.
    """
    mode = 0
    p = 0.0
    floor = 0.0
    xr = 0.0
    pr = 0.0
    upe = 0.0
    us = 0.0
    vp = 0.5 * (e + lo)
    ups = 0
    n = v.shape[0]
    for i in range(-1, n):
        x = v_hist if i < 0 else v[i]
        if mode == 0:
            if x < vp and p > 0.0:
                xr = vp
                pr = p
                us = min(e + gamma, xr - beta - rho * p)
                if us < lo:
                    us = lo
                if us > xr - 1e-6:
                    us = xr - 1e-6
                upe = xr - beta
                if upe < us + 1e-6:
                    upe = us + 1e-6
                mode = 1
                p = _unload(x, xr, pr, phi, delta, upe, us)
            else:
                was = p
                f = _onset(x - e, w)
                p = f if f > floor else floor
                if i >= 0 and was <= 0.0 and p > 0.0 and floor <= 0.0:
                    ups += 1
        else:
            if x > vp:
                mode = 0
                floor = p
                f = _onset(x - e, w)
                p = f if f > floor else floor
            else:
                p = _unload(x, xr, pr, phi, delta, upe, us)
        if i >= 0:
            out[i] = p
        vp = x
    return ups


# nonlinear parameters (shared by every variant; held where their term is off)
_NL = ("e_pos", "e_neg", "beta_pos", "beta_neg", "gamma_pos", "gamma_neg", "rho", "x_h",
       "phi", "delta", "w_pos", "w_neg", "v_eps", "u_wall", "period", "lag", "offset")
# linear coefficients (columns of the design matrix)
_LIN = ("c0", "k_pos", "k_neg", "drift1", "drift2", "coulomb", "viscous", "pre", "s_pos", "s_neg",
        "k_wall", "rip_s", "rip_c", "lf_pos", "lf_neg")
_NI = {k: i for i, k in enumerate(_NL)}
_LI = {k: len(_NL) + i for i, k in enumerate(_LIN)}
_TERMS = {
    # term: (nonlinear entries, linear entries)
    "base": (("e_pos", "e_neg", "beta_pos", "beta_neg", "gamma_pos", "gamma_neg", "rho", "x_h"),
             ("c0", "k_pos", "k_neg")),
    "drift": ((), ("drift1",)),
    "drift2": ((), ("drift2",)),
    "friction": (("v_eps",), ("coulomb", "viscous")),
    "pretension": ((), ("pre",)),
    "stiffening": ((), ("s_pos", "s_neg")),
    "wall+": (("u_wall",), ("k_wall",)),
    "wall-": (("u_wall",), ("k_wall",)),
    "ripple": (("period",), ("rip_s", "rip_c")),
    "loadfriction": (("v_eps",), ("lf_pos", "lf_neg")),
    "drop": (("phi", "delta"), ()),
    "onset": (("w_pos", "w_neg"), ()),
    "latency": (("lag",), ()),
}
_BASE = ("base", "drop", "friction")
_NSTEP = {"e_pos": 1e-3, "e_neg": 1e-3, "beta_pos": 1e-3, "beta_neg": 1e-3, "gamma_pos": 1e-3,
          "gamma_neg": 1e-3, "rho": 1e-4, "x_h": 1e-3, "phi": 1e-4, "delta": 1e-3, "w_pos": 1e-3, "w_neg": 1e-3,
          "v_eps": 1e-3, "u_wall": 1e-3, "period": 1e-5, "lag": 1e-5, "offset": 1e-3}


class _CurrentModel:
    """The superset current law on a binned record.

    ``c = |.|? ( c0 + drift1 tn + drift2 tn^2                      (no-load level, drifting)
               + coulomb tanh(v/v_eps) + viscous v                 (motor and gearbox friction)
               + tanh(v/v_eps) (lf_pos P+ + lf_neg P-)             (friction growing with load)
               + pre (u - u_mid)                                   (pretensioned tendons)
               + k_pos P+ + s_pos P+^2 - k_neg P- - s_neg P-^2     (tendon loads, stiffening)
               + k_wall max(+-(u - u_wall), 0)                     (a wall on one side)
               + rip_s sin(2 pi q/period) + rip_c cos(...) )       (cogging, a function of q)``

    with ``u = q(t - lag) - offset`` and the tendon loads P+ (coordinate u, edge e_pos) and P-
    (coordinate -u, edge -e_neg) from :func:`_tendon`. The outer absolute value is the
    ``magnitude`` variant (a current logged without its sign: ``c0 + |c - c0|``).
    """

    def __init__(self, bins: _Bins, terms: frozenset, magnitude: bool, u_mid: float, vscale: float):
        self.b = bins
        self.terms = frozenset(terms)
        self.magnitude = bool(magnitude)
        self.u_mid = float(u_mid)
        self.vscale = float(vscale)
        self.lin_on = np.zeros(len(_LIN), bool)
        for term in self.terms:
            for name in _TERMS[term][1]:
                self.lin_on[_LI[name] - len(_NL)] = True
        self.wall_sign = 1.0 if "wall+" in self.terms else -1.0
        self.ups = (0, 0)

    def with_terms(self, terms, magnitude=None) -> "_CurrentModel":
        return _CurrentModel(self.b, terms, self.magnitude if magnitude is None else magnitude,
                             self.u_mid, self.vscale)

    def free_mask(self) -> np.ndarray:
        free = np.zeros(len(_NL) + len(_LIN), bool)
        for term in self.terms:
            nl, lin = _TERMS[term]
            for name in nl:
                free[_NI[name]] = True
            for name in lin:
                free[_LI[name]] = True
        return free

    def loads(self, x):
        b = self.b
        lag = x[_NI["lag"]]
        if lag != 0.0:
            qe = np.interp(b.t - lag, b.t, b.q)
            ve = np.interp(b.t - lag, b.t, b.v)
        else:
            qe, ve = b.q, b.v
        u = qe - x[_NI["offset"]]
        pp = np.empty(u.size)
        pn = np.empty(u.size)
        e_pos, e_neg = x[_NI["e_pos"]], x[_NI["e_neg"]]
        up = _tendon(u, e_pos, e_neg, x[_NI["beta_pos"]], x[_NI["gamma_pos"]], x[_NI["rho"]],
                     x[_NI["phi"]], x[_NI["delta"]], x[_NI["w_pos"]], x[_NI["x_h"]], pp)
        un = _tendon(-u, -e_neg, -e_pos, x[_NI["beta_neg"]], x[_NI["gamma_neg"]], x[_NI["rho"]],
                     x[_NI["phi"]], x[_NI["delta"]], x[_NI["w_neg"]], -x[_NI["x_h"]], pn)
        self.ups = (int(up), int(un))
        return qe, ve, u, pp, pn

    def design(self, x) -> np.ndarray:
        """The design matrix (bins x len(_LIN)); columns of terms that are off stay zero."""
        qe, ve, u, pp, pn = self.loads(x)
        n = u.size
        X = np.zeros((n, len(_LIN)))
        on = self.lin_on
        X[:, 0] = 1.0
        X[:, 1] = pp
        X[:, 2] = -pn
        if on[3]:
            X[:, 3] = self.b.tn
        if on[4]:
            X[:, 4] = self.b.tn ** 2
        if on[5] or on[13]:
            th = np.tanh(ve / max(x[_NI["v_eps"]], 1e-6))
            if on[5]:
                X[:, 5] = th
                X[:, 6] = ve / self.vscale
            if on[13]:
                X[:, 13] = th * pp
                X[:, 14] = th * pn
        if on[7]:
            X[:, 7] = u - self.u_mid
        if on[8]:
            X[:, 8] = pp * pp
            X[:, 9] = -pn * pn
        if on[10]:
            uw = x[_NI["u_wall"]]
            X[:, 10] = np.maximum(u - uw, 0.0) if self.wall_sign > 0 else -np.maximum(uw - u, 0.0)
        if on[11]:
            ph = 2.0 * np.pi * qe / x[_NI["period"]]
            X[:, 11] = np.sin(ph)
            X[:, 12] = np.cos(ph)
        return X

    def predict(self, x, X=None):
        X = self.design(x) if X is None else X
        m = X @ x[len(_NL):]
        return self._fold(m, x)

    def _fold(self, m, x):
        """The magnitude variant folds the current about its no-load level c0."""
        if not self.magnitude:
            return m
        c0 = x[_LI["c0"]]
        return c0 + np.abs(m - c0)

    def resid(self, x):
        r = self.b.w * (self.predict(x) - self.b.x)
        gap = x[_NI["e_pos"]] - x[_NI["e_neg"]]
        return np.append(r, self.penalty * max(0.0, -gap))

    def jac(self, x, idx):
        X = self.design(x)
        m = X @ x[len(_NL):]
        base = self.b.w * (self._fold(m, x) - self.b.x)
        sgn = np.sign(m - x[_LI["c0"]]) if self.magnitude else 1.0
        J = np.zeros((base.size + 1, idx.size))
        for j, i in enumerate(idx):
            if i == _LI["c0"]:
                J[:-1, j] = self.b.w
            elif i >= len(_NL):
                J[:-1, j] = self.b.w * sgn * X[:, i - len(_NL)]
            else:
                h = _NSTEP[_NL[i]]
                if x[i] + h > self.ub[i]:
                    h = -h
                xp = x.copy()
                xp[i] += h
                J[:-1, j] = (self.resid(xp)[:-1] - base) / h
                if i in (_NI["e_pos"], _NI["e_neg"]):
                    gap = x[_NI["e_pos"]] - x[_NI["e_neg"]]
                    if gap < 0:
                        J[-1, j] = self.penalty * (1.0 if i == _NI["e_neg"] else -1.0)
        return J

    # bounds are set per record by _current_bounds
    lb: np.ndarray
    ub: np.ndarray
    penalty: float = 0.0


def _current_bounds(bins: _Bins, qrange: tuple[float, float], vmax: float):
    q0, q1 = qrange
    qs = q1 - q0
    lb = np.full(len(_NL) + len(_LIN), -np.inf)
    ub = np.full(len(_NL) + len(_LIN), np.inf)
    for name, lo, hi in (("e_pos", q0 - qs, q1 + qs), ("e_neg", q0 - qs, q1 + qs),
                         ("beta_pos", 0.0, qs), ("beta_neg", 0.0, qs),
                         ("gamma_pos", -2 * qs, 2 * qs), ("gamma_neg", -2 * qs, 2 * qs),
                         ("rho", 0.0, 3.0), ("x_h", q0 - qs, q1 + qs), ("phi", 0.0, 0.95), ("delta", 0.0, 2.0),
                         ("w_pos", 0.0, 10.0), ("w_neg", 0.0, 10.0),
                         ("v_eps", 1e-3 * vmax, vmax), ("u_wall", q0, q1), ("period", 0.2, 20.0),
                         ("lag", 0.0, 0.5), ("offset", -np.inf, np.inf)):
        lb[_NI[name]], ub[_NI[name]] = lo, hi
    # a tendon taken up pulls the current its own way (up for the positive one, down for the
    # negative one; the magnitude variant folds the sign), and so does a wall
    for name in ("k_pos", "k_neg", "k_wall"):
        lb[_LI[name]] = 0.0
    return lb, ub


def _default_x(bins: _Bins, e_pos, e_neg, beta, vmax) -> np.ndarray:
    x = np.zeros(len(_NL) + len(_LIN))
    x[_NI["e_pos"]], x[_NI["e_neg"]] = e_pos, e_neg
    x[_NI["beta_pos"]] = x[_NI["beta_neg"]] = beta
    x[_NI["rho"]] = 0.3
    x[_NI["delta"]] = 0.2
    x[_NI["x_h"]] = float(bins.q[0])
    x[_NI["v_eps"]] = min(1.0, 0.5 * vmax)
    x[_NI["period"]] = 2.0
    x[_NI["u_wall"]] = float(np.median(bins.q))
    x[_LI["c0"]] = float(np.median(bins.x))
    return x


class _CurrentFit:
    """A model variant, its problem and its best point."""

    def __init__(self, model: _CurrentModel, lb, ub, f_scale: float, x: np.ndarray, tau: float = 1.0):
        self.tau = tau
        model.lb, model.ub = lb, ub
        model.penalty = 1e3 * f_scale * math.sqrt(model.b.q.size)
        self.model = model
        self.free = model.free_mask()
        self.prob = _Problem(model.resid, model.jac, lb, ub, n_data=model.b.q.size,
                             loss="soft_l1", f_scale=f_scale)
        self.x = np.clip(x, lb, ub)
        self.s = math.inf

    def run(self, x0=None, max_nfev=None):
        x0 = self.x if x0 is None else np.clip(x0, self.prob.lb, self.prob.ub)
        x, s = self.prob.fit(x0, self.free, max_nfev=max_nfev)
        if s < self.s or x0 is not None:
            self.x, self.s = x, s
        return self

    def init_linear(self):
        """The linear entries refitted with the nonlinear ones held (soft-L1 reweighted least
        squares, signed law): a start whose slopes match its edges."""
        m = self.model
        X = m.design(self.x)
        on = np.flatnonzero(m.lin_on)
        if m.magnitude:      # folded about no-load, the negative side rises too
            X[:, 2] = -X[:, 2]
        A = X[:, on] * m.b.w[:, None]
        y = m.b.x * m.b.w
        sw = np.ones_like(y)
        for _ in range(3):
            coef, *_ = np.linalg.lstsq(A * sw[:, None], y * sw, rcond=None)
            r = A @ coef - y
            sw = (1.0 + (r / self.prob.f_scale) ** 2) ** -0.25
        self.x[len(_NL) + on] = np.clip(coef, self.prob.lb[len(_NL) + on], self.prob.ub[len(_NL) + on])
        return self

    @property
    def bic(self) -> float:
        return _bic(self.s, self.model.b.q.size, int(self.free.sum()), self.tau)


def _robust_sigma(r: np.ndarray) -> float:
    r = np.asarray(r, float)
    mad = float(np.median(np.abs(r - np.median(r))))
    return max(1.4826 * mad, 1e-9)


def _ramp_grid(q, c, w, extra, grid, sgn):
    """Best (edge, slack) pair for one direction of travel: a tendon taken up past ``edge`` (a
    ramp of free slope) and the other one released until ``slack`` (another ramp), over a level
    and the extra columns, each pair a weighted linear least squares (L1 of the residuals)."""
    best = None
    for a in grid:
        up = np.maximum(sgn * (q - a), 0.0)
        for b in grid:
            if sgn * (b - a) >= 0:
                continue
            A = np.column_stack([extra, up, np.maximum(sgn * (b - q), 0.0)]) * w[:, None]
            coef, *_ = np.linalg.lstsq(A, c * w, rcond=None)
            r = A @ coef - c * w
            score = float(np.sum(np.abs(r)))
            if best is None or score < best[0]:
                best = (score, float(a), float(b), r)
    return best


def _knot_grid(q, c, w, extra, grid, sgn, slack):
    """With the released tendon's slack point held, the best (edge, knot) on the loaded side: the
    ramp past the edge bends again at the knot (a wall or a stiffening tendon)."""
    down = np.maximum(sgn * (slack - q), 0.0)
    best = None
    for a in grid:
        if sgn * (a - slack) <= 0:
            continue
        up = np.maximum(sgn * (q - a), 0.0)
        for k in grid:
            if sgn * (k - a) <= 0:
                continue
            A = np.column_stack([extra, up, np.maximum(sgn * (q - k), 0.0), down]) * w[:, None]
            coef, *_ = np.linalg.lstsq(A, c * w, rcond=None)
            score = float(np.sum(np.abs(A @ coef - c * w)))
            if best is None or score < best[0]:
                best = (score, float(a), float(k))
    return best


def _slack_line(q, c, w, extra, grid, sgn, a, k):
    """With the loaded side's edge and knot held, the best slack point of the released tendon."""
    up = np.column_stack([np.maximum(sgn * (q - a), 0.0), np.maximum(sgn * (q - k), 0.0)])
    best = None
    for b in grid:
        if sgn * (b - a) >= 0:
            continue
        A = np.column_stack([extra, up, np.maximum(sgn * (b - q), 0.0)]) * w[:, None]
        coef, *_ = np.linalg.lstsq(A, c * w, rcond=None)
        score = float(np.sum(np.abs(A @ coef - c * w)))
        if best is None or score < best[0]:
            best = (score, float(b))
    return best[1] if best is not None else float(grid[0] if sgn > 0 else grid[-1])


def _edge_grid(bins: _Bins, vmax: float):
    """Start values of the edges and slack points, read apart on each direction of travel: moving
    up, the positive tendon is taken up (its edge) while the negative one is released (its slack
    point); moving down, the reverse. Also, per side, an edge whose ramp bends again at a knot
    (a wall). Returns (e_pos, slack_pos, e_neg, slack_neg, sigma, {side: (edge, knot)})."""
    q, c, w = bins.q, bins.x, bins.w
    q0, q1 = float(q.min()), float(q.max())
    grid = q0 + (q1 - q0) * np.linspace(0.02, 0.98, 25)
    out = {}
    knots = {}
    res = []
    for sgn in (1, -1):
        m = bins.v * sgn > 0
        if m.sum() < 20:
            return None
        extra = np.column_stack([np.ones(int(m.sum())), bins.tn[m], bins.v[m] / vmax, q[m]])
        best = _ramp_grid(q[m], c[m], w[m], extra, grid, sgn)
        out[sgn] = best[1:3]
        res.append(best[3])
        # a wall's steep ramp can hide the edge before it: alternate the (edge, knot) grid with
        # the released tendon's slack point
        # (with and without a pretension slope: either can mimic the other's ramp)
        knots[sgn] = []
        for ex in (extra[:, :3], extra):
            slack = q0 if sgn > 0 else q1      # start with the released tendon out of the way
            for _ in range(2):
                kn = _knot_grid(q[m], c[m], w[m], ex, grid, sgn, slack)
                if kn is None:
                    break
                slack = _slack_line(q[m], c[m], w[m], ex, grid, sgn, kn[1], kn[2])
            if kn is not None:
                knots[sgn].append((kn[1], kn[2], slack))
    sigma = _robust_sigma(np.concatenate(res))
    (e_pos, slack_neg), (e_neg, slack_pos) = out[1], out[-1]
    return e_pos, slack_pos, e_neg, slack_neg, sigma, knots


def _pair_grid(bins: _Bins, vmax: float, k: int = 2) -> list[tuple[float, float]]:
    """Edge pairs that best explain the whole current with tendons that only stretch (a ramp and
    its square on each side, so a stiffening tendon or a wall past it bends the ramp instead of
    moving the edge), a level, drift and friction: weighted linear least squares per pair."""
    q, c, w = bins.q, bins.x, bins.w
    q0, q1 = float(q.min()), float(q.max())
    grid = q0 + (q1 - q0) * np.linspace(0.02, 0.98, 25)
    th = np.tanh(bins.v / max(0.05 * vmax, 1e-6))
    base = np.column_stack([np.ones_like(q), bins.tn, th, bins.v / vmax, q])
    cand = []
    for i, dn in enumerate(grid):
        neg = np.maximum(dn - q, 0.0)
        for dp in grid[i + 1:]:
            pos = np.maximum(q - dp, 0.0)
            A = np.column_stack([base, pos, pos * pos, neg, neg * neg]) * w[:, None]
            coef, *_ = np.linalg.lstsq(A, c * w, rcond=None)
            cand.append((float(np.sum(np.abs(A @ coef - c * w))), float(dp), float(dn)))
    cand.sort()
    out: list[tuple[float, float]] = []
    for _, dp, dn in cand:
        if any(abs(dp - a) < 0.08 * (q1 - q0) and abs(dn - b) < 0.08 * (q1 - q0) for a, b in out):
            continue
        out.append((dp, dn))
        if len(out) == k:
            break
    return out


def _screen_linear(fit: _CurrentFit, terms, x_nl_updates: dict[str, float]):
    """Objective of a variant whose extra entries are linear (and grid-held nonlinear): the
    nonlinear entries held, the linear ones refitted by two rounds of reweighted least squares
    (the soft-L1 weights of the current residuals). Returns (objective, x)."""
    model = fit.model.with_terms(terms)
    model.lb, model.ub, model.penalty = fit.prob.lb, fit.prob.ub, fit.model.penalty
    x = fit.x.copy()
    for k, v in x_nl_updates.items():
        x[_NI[k]] = v
    X = model.design(x)
    on = np.flatnonzero(model.lin_on)
    b = fit.model.b
    A = X[:, on] * b.w[:, None]
    y = b.x * b.w
    f = fit.prob.f_scale
    r = fit.prob.resid(fit.x)[: b.q.size]
    for _ in range(2):
        sw = (1.0 + (r / f) ** 2) ** -0.25
        coef, *_ = np.linalg.lstsq(A * sw[:, None], y * sw, rcond=None)
        r = A @ coef - y
    x[len(_NL) + on] = coef
    return fit.prob.objective(r), x


def _select_terms(fit: _CurrentFit, vmax: float, qrange) -> _CurrentFit:
    """Greedy forward selection of optional terms by BIC: each candidate is screened (its own
    entries fitted, the rest held), the best screen is refitted in full and kept if BIC drops."""
    q0, q1 = qrange
    rejected: set[str] = set()
    for _ in range(8):
        terms = set(fit.model.terms)
        screens = []
        for term in ("drift", "drift2", "friction", "pretension", "stiffening", "loadfriction",
                     "ripple", "wall+", "wall-", "onset", "latency"):
            if term in terms or term in rejected:
                continue
            if term == "drift2" and "drift" not in terms:
                continue
            if term in ("wall+", "wall-") and ({"wall+", "wall-"} & terms):
                continue
            new = terms | {term}
            if term == "friction" or (term == "loadfriction" and "friction" not in terms):
                opts = [{"v_eps": v} for v in (0.2, 0.5, 1.0, 2.0, 5.0) if v < 0.5 * vmax] or [{"v_eps": 0.25 * vmax}]
            elif term == "ripple":
                opts = [{"period": p} for p in np.geomspace(0.4, 8.0, 48)]
            elif term == "wall+":
                opts = [{"u_wall": u} for u in q0 + (q1 - q0) * np.linspace(0.55, 0.97, 12)]
            elif term == "wall-":
                opts = [{"u_wall": u} for u in q0 + (q1 - q0) * np.linspace(0.03, 0.45, 12)]
            elif term == "latency":
                opts = [{"lag": v} for v in (0.005, 0.01, 0.02, 0.04, 0.08, 0.15)]
            else:
                opts = [{}]
            if term == "onset":
                x0 = fit.x.copy()
                x0[_NI["w_pos"]] = x0[_NI["w_neg"]] = 1.0
                model = fit.model.with_terms(new)
                cf = _CurrentFit(model, fit.prob.lb, fit.prob.ub, fit.prob.f_scale, x0, fit.tau)
                cf.run(max_nfev=20)
                screens.append((cf.bic, term, cf.x))
                continue
            if fit.model.magnitude:
                continue
            obj, xb = min((_screen_linear(fit, new, o) for o in opts), key=lambda z: z[0])
            p = int(fit.model.with_terms(new).free_mask().sum())
            screens.append((_bic(obj, fit.model.b.q.size, p, fit.tau), term, xb))
        screens.sort(key=lambda z: z[0])
        if not screens or screens[0][0] >= fit.bic:
            break
        _, term, x0 = screens[0]
        cand = _CurrentFit(fit.model.with_terms(terms | {term}), fit.prob.lb, fit.prob.ub,
                           fit.prob.f_scale, x0, fit.tau).run()
        if cand.bic < fit.bic:
            fit = cand
        else:
            rejected.add(term)
    return fit


def _current_limits(qrange, name_map):
    q0, q1 = qrange
    qs = q1 - q0
    lim = {"d_pos": _Limits(rec_lo=q0, rec_hi=q1), "d_neg": _Limits(rec_lo=q0, rec_hi=q1),
           "b_pos": _Limits(dom_lo=0.0, rec_hi=qs), "b_neg": _Limits(dom_lo=0.0, rec_hi=qs)}
    return {k: lim[k] for k in name_map}


@_one_thread
def current_reference(t, q, c, *, max_bins: int = MAX_BINS) -> RefFit:
    """Robust fit of the superset current law, with 95 % profile intervals of the edges and holds.

    Parameters
    ----------
    t, q, c : array_like
        Time (s), knob angle (deg) and motor current (mA) of one sweep.

    Returns
    -------
    RefFit
        ``params`` for :data:`CURRENT_PARAMS`: ``d_pos``/``d_neg`` are where each tendon's load
        departs from zero; ``b_pos``/``b_neg`` the travel over which the law holds a tendon's
        load after a reversal, reported unresolved (``hi`` infinite) where the record allows no
        hold at all (the current does not carry the backlash). ``terms`` lists the law's terms.
    """
    t0 = time.perf_counter()
    bins = _binned(t, q, c, median=True, max_bins=max_bins)
    vmax = max(float(np.max(np.abs(bins.v))), 1e-6)
    qrange = (float(bins.q.min()), float(bins.q.max()))
    lb, ub = _current_bounds(bins, qrange, vmax)
    grid = _edge_grid(bins, vmax)
    if grid is None:
        raise RefFitError("the knob must move both ways")
    e_pos, s_pos, e_neg, s_neg, sigma0, knots = grid
    if e_neg >= e_pos:
        e_pos, e_neg = max(e_pos, e_neg), min(e_pos, e_neg)
    # starts: single ramps read apart per direction (with and without a friction drop), the
    # best whole-record pairs, and per side an edge with a wall at its knot; each with and
    # without a hold; compared by BIC after a short fit
    starts = [(e_pos, e_neg, s_pos - e_pos, e_neg - s_neg, phi, None) for phi in (0.0, 0.4)]
    starts += [(dp, dn, 0.0, 0.0, 0.0, None) for dp, dn in _pair_grid(bins, vmax)]
    for ep, kp, sn in knots.get(1, []):
        en = min(e_neg, ep - 1.0)
        starts.append((ep, en, s_pos - ep, en - sn, 0.0, ("wall+", kp)))
    for en, kn, sp in knots.get(-1, []):
        ep = max(e_pos, en + 1.0)
        starts.append((ep, en, sp - ep, en - s_neg, 0.0, ("wall-", kn)))
    def base_fits(magnitude: bool):
        model0 = _CurrentModel(bins, frozenset(_BASE), magnitude, 0.5 * sum(qrange), vmax)
        tried = []
        for ep, en, gp, gn, phi, wall in starts:
            for beta in ((0.0,) if wall else (0.0, 0.25 * (ep - en))):
                x0 = _default_x(bins, ep, en, beta, vmax)
                x0[_NI["gamma_pos"]] = gp + beta
                x0[_NI["gamma_neg"]] = gn + beta
                x0[_NI["rho"]] = 0.0
                x0[_NI["phi"]] = phi
                model = model0
                if wall is not None:
                    model = model0.with_terms(set(_BASE) | {wall[0]})
                    x0[_NI["u_wall"]] = wall[1]
                tried.append(_CurrentFit(model, lb, ub, 2.0 * sigma0, x0).init_linear().run(max_nfev=25))
        # the three best short fits (distinct edges) run to convergence
        tried.sort(key=lambda f: f.bic)
        finals: list[_CurrentFit] = []
        for f in tried:
            e = (f.x[_NI["e_pos"]], f.x[_NI["e_neg"]])
            if any(abs(e[0] - g.x[_NI["e_pos"]]) < 0.5 and abs(e[1] - g.x[_NI["e_neg"]]) < 0.5 for g in finals):
                continue
            finals.append(f.run())
            if len(finals) == 3:
                break
        best = min(finals, key=lambda f: f.bic)
        return best, finals

    best, finals = base_fits(False)
    k = (best.x[_LI["k_pos"]], best.x[_LI["k_neg"]])
    if min(k) < 0.1 * max(max(k), 1e-12):
        # one tendon pulls no current its own way: the current may be logged as a magnitude
        alt = base_fits(True)
        if alt[0].bic < best.bic:
            best, finals = alt
    # rescale the loss to the base fit's own residuals, then choose the optional terms
    r = best.prob.resid(best.x)[:-1]
    f_scale = 2.0 * _robust_sigma(r)
    fit = _CurrentFit(best.model, lb, ub, f_scale, best.x).run()
    fit.tau = _tau_int(fit.prob.scores(fit.x)[0])
    fit = _select_terms(fit, vmax, qrange)
    # the chosen law refitted from the other converged starts' tendon entries: keep the best
    tendon = [_NI[k] for k in ("e_pos", "e_neg", "beta_pos", "beta_neg", "gamma_pos", "gamma_neg",
                               "rho", "x_h", "phi", "delta")]
    for f in finals:
        if f is best:
            continue
        x0 = fit.x.copy()
        x0[tendon] = f.x[tendon]
        alt = _CurrentFit(fit.model, lb, ub, f_scale, x0, fit.tau).init_linear().run()
        if alt.s < fit.s:
            fit = alt
    names = {"d_pos": _NI["e_pos"], "d_neg": _NI["e_neg"], "b_pos": _NI["beta_pos"],
             "b_neg": _NI["beta_neg"]}
    limits = _current_limits(qrange, names)
    min_step = {k: 0.02 for k in names}
    x, s, prof, tau, scale = _profiles(fit.prob, fit.x, fit.run().s, fit.free, names, limits, min_step)
    params = {}
    for p, k in names.items():
        # the law is evaluated at each bin's mean knob angle: an edge inside a bin is placed to
        # about half the bin's travel, whatever the noise
        iv = _widen(_interval(x, k, prof[p]), 0.5 * bins.travel)
        # the load must be held past the end of its friction drop (when there is one) by more
        # than a reversal's own rounding, else the current does not carry this backlash
        drop_end = x[_NI["delta"]] if x[_NI["phi"]] > 0.05 else 0.0
        # nor does a tendon whose take-up the record does not place (its edge unresolved)
        edge = params.get("d_" + p[2:]) if p.startswith("b_") else None
        edge_open = edge is not None and not edge.resolved(EDGE_FOR_HOLD)
        if p.startswith("b_") and (iv.lo < drop_end + MIN_HOLD or edge_open):
            iv = ParamInterval(iv.estimate, 0.0, math.inf, True, True)
        params[p] = iv
    fit.model.loads(x)
    terms = tuple(sorted(fit.model.terms)) + (("magnitude",) if fit.model.magnitude else ())
    law = {"x": x.tolist(), "terms": sorted(fit.model.terms), "magnitude": fit.model.magnitude,
           "u_mid": fit.model.u_mid, "f_scale": f_scale, "vmax": vmax, "qrange": qrange,
           "ups": fit.model.ups}
    return RefFit(params=params, terms=terms, sigma=math.sqrt(scale), tau=tau, n_bins=bins.q.size,
                  seconds=time.perf_counter() - t0, law=law)


# --------------------------------------------------------------------------------------------
# Shift
# --------------------------------------------------------------------------------------------
_SHIFT_TERMS = ("drift", "friction")


@_one_thread
def shift_reference(sweep_ref: RefFit, t, q, c, *, max_bins: int = MAX_BINS) -> tuple[float, float, float]:
    """The shift of the replay's current edges relative to the sweep's, with a 95 % interval.

    The sweep's fitted law is held (edges, holds, slopes, stiffening, wall, cogging); the replay's
    own level, drift and friction amplitudes, its start state and ``offset`` are free. Where the
    fitted replay never takes a tendon up from slack, the interval is open (infinite both sides).

    Returns
    -------
    (offset, lo, hi)
    """
    law = sweep_ref.law
    if "terms" not in law:
        raise RefFitError("shift_reference needs a current_reference fit of the sweep")
    bins = _binned(t, q, c, median=True, max_bins=max_bins)
    xs = np.array(law["x"], float)
    # the sweep's own time trend is not the replay's: drop its curvature, free its slope
    terms = (frozenset(law["terms"]) - {"drift2"}) | frozenset(_SHIFT_TERMS)
    vmax_s = float(law["vmax"])
    model = _CurrentModel(bins, terms, bool(law["magnitude"]), float(law["u_mid"]), vmax_s)
    qr = (float(bins.q.min()), float(bins.q.max()))
    lb, ub = _current_bounds(bins, (min(qr[0], law["qrange"][0]), max(qr[1], law["qrange"][1])), vmax_s)
    e_pos, e_neg = xs[_NI["e_pos"]], xs[_NI["e_neg"]]
    off_lo = qr[0] - e_pos - 2.0
    off_hi = qr[1] - e_neg + 2.0
    lb[_NI["offset"]], ub[_NI["offset"]] = off_lo - 1.0, off_hi + 1.0
    lb[_NI["x_h"]], ub[_NI["x_h"]] = -np.inf, np.inf
    if "friction" not in law["terms"]:
        xs[_NI["v_eps"]] = min(1.0, 0.5 * max(float(np.max(np.abs(bins.v))), 1e-6))
    lb[_NI["v_eps"]], ub[_NI["v_eps"]] = -np.inf, np.inf
    free = np.zeros(xs.size, bool)
    for name in ("offset", "x_h"):
        free[_NI[name]] = True
    for name in ("c0", "drift1", "coulomb", "viscous"):
        free[_LI[name]] = True
    # a grid over the offset (and the start state), the free linear entries fitted at each point
    held = xs.copy()
    for name in ("c0", "drift1", "drift2", "coulomb", "viscous"):
        held[_LI[name]] = 0.0
    lin_idx = np.array([_LI[n] for n in ("c0", "drift1", "coulomb", "viscous")])
    cand = []
    span = off_hi - off_lo
    for off in np.linspace(off_lo, off_hi, max(41, int(span / 0.5) + 1)):
        for xh in (-off - 0.5 * span, -off, -off + 0.5 * span):
            x = held.copy()
            x[_NI["offset"]] = off
            x[_NI["x_h"]] = xh
            X = model.design(x)
            fixed = X @ x[len(_NL):]
            A = X[:, lin_idx - len(_NL)] * bins.w[:, None]
            rhs = (bins.x - fixed) * bins.w
            coef, *_ = np.linalg.lstsq(A, rhs, rcond=None)
            r = A @ coef - rhs
            x[lin_idx] = coef
            cand.append((float(np.sum(np.abs(r))), x, r))
    cand.sort(key=lambda z: z[0])
    f_scale = 2.0 * _robust_sigma(cand[0][2])
    model.lb, model.ub = lb, ub
    model.penalty = 0.0
    prob = _Problem(model.resid, model.jac, lb, ub, n_data=bins.q.size, loss="soft_l1", f_scale=f_scale)
    best = None
    seen: list[float] = []
    for _, x0, _ in cand:
        if any(abs(x0[_NI["offset"]] - o) < 1.0 for o in seen):
            continue
        seen.append(float(x0[_NI["offset"]]))
        x, s = prob.fit(x0, free)
        if best is None or s < best[1]:
            best = (x, s)
        if len(seen) == 4:
            break
    x, s = best
    k = _NI["offset"]
    lim = {"offset": _Limits(rec_lo=off_lo, rec_hi=off_hi)}
    x, s, prof, _, _ = _profiles(prob, x, s, free, {"offset": k}, lim, {"offset": 0.02})
    model.loads(x)
    if sum(model.ups) == 0:
        return float(x[k]), -math.inf, math.inf
    lo, hi, _, _ = prof["offset"]
    half = 0.5 * bins.travel      # the bins' own resolution (see current_reference)
    return float(x[k]), float(min(lo, x[k]) - half), float(max(hi, x[k]) + half)
