"""What a sweep's motor current says: its sign convention, where each tendon is taken up (with an
interval), the no-load levels, the slopes, and the backlash where the current shows it.

The model
---------
Each monotone stretch of current against knob angle is a continuous broken line with a robust
noise model (:mod:`.pwl`: pieces chosen by BIC, each knot with a profile-likelihood interval),
plus, where BIC takes it, one cogging ripple common to the whole record (:func:`.condition.find_ripple`).
What the pieces mean follows from the mechanics, read in *load coordinates*: along the motion
(``x = direction * q``) and signed so that loading the tendon ahead raises the value
(``l = direction * c`` for a signed current, ``l = c`` for a magnitude). A stretch then reads,
left to right, as some of: a held load or a drop (the tendon behind, after a reversal), its
unloading, the dead zone (flat, or gently rising when the tendons are pretensioned), the take-up
of the tendon ahead, and a stiffening or a wall. The tendon ahead, once taken up, loads
monotonically until the knob turns: so the **loading edge** is the knot that starts the stretch's
last run of pieces whose slopes do not fall (within their standard errors), the piece before it
being the dead zone. A magnitude current unloads downward, so there the dead zone is the piece at
the stretch's lowest level and the edge the first knot after it from which the slopes do not fall.

Across stretches one edge per side is estimated by a random-effects combination of the stretches'
own profile intervals (DerSimonian-Laird): stretches that agree give the precision of all of
them; stretches that disagree (a first stretch from a state the record cannot tell, a latency
that depends on the direction) widen the interval by their spread instead of being dropped by a
rule.

The **backlash** shows in the current only where a tendon's load is held after a reversal while
the tip rests on its plateau: a flat piece before the dead zone that a rise (the unloading) ends.
Its length from the reversal is the backlash; a current that unloads at once (one that follows the
tendon's stretch) shows none, and the backlash is then not fixed by the current.

The **sign convention** is a model comparison: the current against the knob angle as a monotone
law (signed) or a V about a centre (magnitude), each with a level per direction of motion, by BIC
on the binned record.
"""
from __future__ import annotations

import math
from statistics import NormalDist

import numpy as np

from ..estimate import Estimate
from ..settings import DEFAULT, Settings
from .condition import Ripple, condition, find_ripple, robust_noise
from .pwl import Piecewise, fit_piecewise, knot_interval, robust_scale
from .result import CurrentReading, StretchReading, orientation
from .stretches import monotone_stretches

__all__ = ["CurrentReading", "StretchReading", "read_current", "detect_sign", "bin_stretch"]

MAX_BINS = 200
"""Most points a stretch is read on: longer stretches are binned along the knob (medians)."""


# --------------------------------------------------------------------------------------------
# binning
# --------------------------------------------------------------------------------------------
def bin_stretch(x: np.ndarray, c: np.ndarray, t: np.ndarray, band_hz: float | None,
                max_bins: int = MAX_BINS) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A stretch's samples as at most ``max_bins`` points along ``x``: ``(x, c, weight, speed)``,
    medians per bin, each weighted by the number of independent samples behind it (its count, or
    its duration times twice ``band_hz`` when a low-pass of that bandwidth made neighbours share
    their noise), with the knob's speed there (deg/s)."""
    x = np.asarray(x, float)
    c = np.asarray(c, float)
    t = np.asarray(t, float)
    speed = np.abs(np.gradient(x, t)) if x.size > 1 else np.zeros_like(x)
    dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    if x.size <= max_bins:
        w = np.ones_like(x) if band_hz is None else np.full(x.size, min(1.0, max(dt * 2.0 * band_hz, 1e-3)))
        return x, c, w, speed
    from scipy import ndimage

    edges = np.linspace(float(x.min()), float(x.max()), max_bins + 1)
    idx = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, max_bins - 1)
    labels = np.unique(idx)
    xb = np.asarray(ndimage.median(x, idx, labels), float)
    cb = np.asarray(ndimage.median(c, idx, labels), float)
    vb = np.asarray(ndimage.median(speed, idx, labels), float)
    n = np.bincount(idx, minlength=max_bins)[labels].astype(float)
    if band_hz is None:
        w = n
    else:
        dur = np.asarray(ndimage.maximum(t, idx, labels), float) - np.asarray(ndimage.minimum(t, idx, labels), float)
        w = np.minimum(n, np.maximum((dur + dt) * 2.0 * band_hz, 1.0))
    order = np.argsort(xb, kind="stable")
    return xb[order], cb[order], w[order], vb[order]


# --------------------------------------------------------------------------------------------
# sign convention
# --------------------------------------------------------------------------------------------
def detect_sign(q: np.ndarray, c: np.ndarray, moving: np.ndarray, level: float = 0.95) -> tuple[str, str]:
    """``("signed" | "magnitude", note)``: does the current dip between the record's ends?

    A signed current runs from one tendon's load (below the no-load level) through the dead zone
    to the other's (above it); a magnitude rises from the dead zone both ways, so its lowest level
    lies inside the swept range with both ends above it. Per direction of motion (the motor's
    friction moves the level with it), the current is binned along the knob and its lowest
    interior level compared with the levels at both ends: both ends above it by more than the
    one-sided normal quantile at ``level`` of the difference's noise, in every direction that
    shows it, read as a magnitude; otherwise signed.
    """
    q = np.asarray(q, float)
    c = np.asarray(c, float)
    d = np.asarray(moving, float)
    z = NormalDist().inv_cdf(level)
    votes = []
    for way in (-1.0, 1.0):
        m = d == way
        if m.sum() < 40:
            continue
        qq, cc = q[m], c[m]
        o = np.argsort(qq)
        groups = np.array_split(o, min(100, o.size // 4))
        lvl = np.array([float(np.median(cc[g])) for g in groups])
        if lvl.size < 12:
            continue
        s = robust_scale(np.diff(lvl)) / math.sqrt(2.0)
        s = max(s, 1e-12)
        end = max(2, lvl.size // 20)
        left, right = float(np.median(lvl[:end])), float(np.median(lvl[-end:]))
        inner = lvl[end:-end]
        low = float(np.min(inner)) if inner.size else min(left, right)
        noise = s * math.sqrt(1.0 + 1.0 / end)
        votes.append((left - low > z * noise) and (right - low > z * noise))
    if votes and all(votes):
        return "magnitude", ("the current dips between the record's ends and rises from there both ways (a "
                             "magnitude, never below its no-load level): read as a magnitude")
    return "signed", "the current does not dip inside the swept range with both ends above it: read as signed"


# --------------------------------------------------------------------------------------------
# one stretch
# --------------------------------------------------------------------------------------------
def _z(level: float) -> float:
    return NormalDist().inv_cdf(0.5 + 0.5 * level)


def _classify(fit: Piecewise, sign: str, direction: int, z: float) -> tuple[int | None, int | None, int | None]:
    """(dead piece, edge knot, hold knot) of one stretch, read in load coordinates.

    Returns ``(dead, edge, hold)`` (the edge is the knot ending the dead piece; None where absent).
    The dead zone is a piece that every later piece climbs faster than (by ``z`` standard errors of
    the difference, against the piece's own slope either way): past the take-up the tendon ahead
    only loads further, whatever the friction does as the knob slows for its reversal; a held
    load and its unloading, or a magnitude's fall, come before it. Of such pieces the last, or an
    earlier one where the slopes only rise between the two (a take-up, a stiffening, a wall: one
    ascent). The edge is the knot that
    ends the dead piece. A held plateau is a piece before the dead one, as flat as it, that a
    significant rise (the unloading) ends.
    """
    o = orientation(sign, direction)
    shown, se = fit.shown_slopes()
    slopes = o * shown
    k = fit.n_knots
    if k == 0:
        return None, None, None

    def steeper(j: int, i: int) -> bool:
        return bool(slopes[j] - slopes[i] > z * math.hypot(se[i], se[j]))

    # pieces every later piece climbs significantly faster than (the tendon ahead loading, against
    # the piece's own slope either way); of them the last, taken back to an earlier one where the
    # slopes only rise between the two (a take-up, then a stiffening or a wall: one ascent),
    # not where they fall (a held load's unloading into the dead zone lies between)
    def later_steeper(m: int) -> bool:
        return all(slopes[j] - abs(slopes[m]) > z * math.hypot(se[m], se[j]) for j in range(m + 1, k + 1))

    def ascending(a: int, b: int) -> bool:
        return all(slopes[i + 1] >= slopes[i] - z * math.hypot(se[i], se[i + 1]) for i in range(a, b))

    cands = [m for m in range(k) if later_steeper(m)]
    dead = cands[-1] if cands else None
    for m in reversed(cands[:-1]):
        if not ascending(m, dead):
            break
        dead = m
    # the held plateau: a piece before the dead zone that a significant rise (the unloading) ends,
    # and whose slope lies nearer the dead zone's (or level, in a stretch that ends before its
    # take-up) than the unloading's: a held load, not a bend in the unloading
    flat = 0.0 if dead is None else slopes[dead]
    hold = next((h for h in range(dead if dead is not None else k)
                 if steeper(h + 1, h) and abs(slopes[h] - flat) < slopes[h + 1] - slopes[h]), None)
    return dead, dead, hold


def _stretch_points(q, c, t, a, b, d, band_hz, ring_s):  # noqa: ANN001
    """A stretch's binned points along ``x = d q``, its ends trimmed by the low-pass's ring: a
    zero-phase filter spreads the step a reversal makes (the motor's friction flipping) over
    about one period of its cut-off either side, so those samples belong to neither stretch."""
    tt = t[a:b + 1]
    keep = (tt >= tt[0] + ring_s) & (tt <= tt[-1] - ring_s)
    if keep.sum() < 8:
        keep = np.ones(tt.size, bool)
    return bin_stretch(d * q[a:b + 1][keep], c[a:b + 1][keep], tt[keep], band_hz)


def _knot_q(fit: Piecewise, j: int, d: int, chi2: float, blur: float = 0.0) -> tuple[float, float, float]:
    """A knot in knob degrees with its interval, each side widened (in quadrature) by ``blur``."""
    lo, hi = knot_interval(fit, j, chi2)
    at = d * fit.knots[j]
    a, b = sorted((d * lo, d * hi))
    return at, at - math.hypot(at - a, blur), at + math.hypot(b - at, blur)


def _blur(q: np.ndarray, t: np.ndarray, a: int, b: int, d: int, x_knot: float, band: float | None) -> float:
    """How far (deg of knob) the low-pass the current was read through spreads a kink: the knob's
    speed there times the filter's time constant ``1 / (2 pi band)``. No reading places a kink
    more finely than the filter lets it show, however many samples lie around it."""
    if not band or b - a < 2:
        return 0.0
    x = d * q[a:b + 1]
    v = np.abs(np.gradient(q[a:b + 1], t[a:b + 1]))
    order = np.argsort(x, kind="stable")
    return float(np.interp(x_knot, x[order], v[order])) / (2.0 * math.pi * band)


# --------------------------------------------------------------------------------------------
# combining stretches
# --------------------------------------------------------------------------------------------
def combine(values: list[float], los: list[float], his: list[float], z: float,
            level: float) -> tuple[float, float, float, float]:
    """Random-effects combination of per-stretch estimates with (possibly asymmetric, possibly
    open) intervals: ``(value, lo, hi, heterogeneity p-value)``.

    Each interval's half-widths over ``z`` are the stretch's standard errors on either side; an
    open side carries no information there. DerSimonian-Laird adds the between-stretch variance
    when the estimates disagree more than their errors allow.
    """
    from scipy.stats import chi2 as chi2_dist

    v = np.asarray(values, float)
    lo_se = np.where(np.isfinite(los), (v - np.asarray(los, float)) / z, np.inf)
    hi_se = np.where(np.isfinite(his), (np.asarray(his, float) - v) / z, np.inf)
    se = np.maximum(np.minimum(lo_se, hi_se), 1e-9)   # the better-determined side's precision
    closed = np.isfinite(lo_se) & np.isfinite(hi_se)
    if not closed.any():
        lo = float(np.max(np.asarray(los, float)))
        hi = float(np.min(np.asarray(his, float)))
        return float(np.median(v)), min(lo, float(np.median(v))), max(hi, float(np.median(v))), 1.0
    vv, ss = v[closed], se[closed]
    w = 1.0 / ss ** 2
    mu = float(np.sum(w * vv) / np.sum(w))
    q_stat = float(np.sum(w * (vv - mu) ** 2))
    k = vv.size
    p = float(chi2_dist.sf(q_stat, k - 1)) if k > 1 else 1.0
    tau2 = 0.0
    if k > 1:
        c = float(np.sum(w) - np.sum(w ** 2) / np.sum(w))
        tau2 = max(0.0, (q_stat - (k - 1)) / max(c, 1e-300))
    w_re = 1.0 / (ss ** 2 + tau2)
    mu = float(np.sum(w_re * vv) / np.sum(w_re))
    se_mu = math.sqrt(1.0 / float(np.sum(w_re)))
    lo, hi = mu - z * se_mu, mu + z * se_mu
    # an open stretch still bounds the edge on its closed side
    for i in np.flatnonzero(~closed):
        if np.isfinite(los[i]):
            lo = max(lo, float(los[i])) if los[i] < mu else lo
        if np.isfinite(his[i]):
            hi = min(hi, float(his[i])) if his[i] > mu else hi
    return mu, lo, hi, p


# --------------------------------------------------------------------------------------------
# the reading
# --------------------------------------------------------------------------------------------
def read_current(q: np.ndarray, c: np.ndarray, t: np.ndarray, settings: Settings = DEFAULT, *,
                 conditioned: bool = False) -> CurrentReading:
    """Read a sweep's motor current (see the module docstring).

    Parameters
    ----------
    q, c, t : numpy.ndarray
        Knob command (deg), motor current, time (s).
    settings : Settings
        Level, robust loss, pieces, low-pass and the current's sign convention.
    conditioned : bool
        ``c`` is already despiked and low-passed.

    Returns
    -------
    CurrentReading
    """
    q = np.ascontiguousarray(q, dtype=float)
    t = np.asarray(t, float)
    fs = 1.0 / float(np.median(np.diff(t))) if t.size > 1 else None
    band = settings.filter_hz
    if not conditioned:
        c = condition(np.asarray(c, float), fs, band)
    c = np.asarray(c, float)
    if band is not None and fs is not None and band >= 0.5 * fs:
        band = None
    z = _z(settings.level)
    chi2 = settings.chi2
    dq = np.gradient(q, t) if q.size > 1 else np.zeros_like(q)
    moving = np.sign(dq)
    if settings.current_sign == "auto":
        sign, sign_note = detect_sign(q, c, moving, settings.level)
    else:
        sign, sign_note = settings.current_sign, f"read as {settings.current_sign}, as asked"
    spans = monotone_stretches(q)
    ring_s = 1.0 / settings.filter_hz if settings.filter_hz else 0.0
    fits = _fit_stretches(q, c, t, spans, settings, band, ring_s)
    # one cogging ripple for the whole record, where BIC takes it; the stretches read again without it
    ripple = _ripple(q, spans, fits, sign, z)
    if ripple is not None:
        c = c - ripple(q)
        fits = _fit_stretches(q, c, t, spans, settings, band, ring_s)
    stretches = []
    for i, ((a, b, d), fit) in enumerate(zip(spans, fits)):
        dead, edge, hold = _classify(fit, sign, d, z)
        kw: dict = dict(start=a, stop=b, direction=d, fit=fit, dead=dead, edge=None, from_reversal=i > 0)
        if edge is not None:
            at, lo, hi = _knot_q(fit, edge, d, chi2, _blur(q, t, a, b, d, fit.knots[edge], settings.filter_hz))
            kw.update(edge=edge, edge_at=at, edge_lo=lo, edge_hi=hi)
        if hold is not None:
            x_start = d * q[a]
            h_at, h_lo, h_hi = _knot_q(fit, hold, d, chi2)
            # travel from the reversal (load coordinates): distance along the motion
            kw.update(hold=d * h_at - x_start, hold_lo=min(d * h_lo, d * h_hi) - x_start,
                      hold_hi=max(d * h_lo, d * h_hi) - x_start)
        stretches.append(StretchReading(**kw))
    # a stretch begins after a loaded reversal when the one before it passed its loading edge
    marked = []
    for i, s in enumerate(stretches):
        prev = stretches[i - 1] if i > 0 else None
        loaded = prev is not None and math.isfinite(prev.edge_at) and \
            prev.direction * (q[prev.stop] - prev.edge_at) > 0
        marked.append(StretchReading(**{**s.__dict__, "after_loaded_reversal": bool(loaded)}))
    stretches = marked
    return _summarise(q, c, t, sign, sign_note, stretches, ripple, z, settings)


FRICTION_SPEEDS = (0.03, 0.1, 0.3)
"""Speeds (as fractions of the record's peak knob speed) searched for the motor friction's
transition: ``C tanh(speed / v) + mu speed`` is the friction nuisance of every stretch."""


def _friction(speed: np.ndarray, v: float | None) -> np.ndarray | None:
    """The friction nuisance columns at transition speed ``v`` (None: no nuisance), or None
    where the knob's speed hardly varies (the columns would repeat the intercept)."""
    if v is None or speed.size < 8 or float(np.ptp(speed)) < 0.05 * max(float(np.median(speed)), 1e-12):
        return None
    return np.column_stack([np.tanh(speed / v), speed])


def _fit_stretches(q, c, t, spans, settings, band, ring_s) -> list[Piecewise]:  # noqa: ANN001
    """Every stretch's broken line, with the motor friction's nuisance term where BIC takes it.

    One noise scale and correlation time for the whole record (read per stretch first, then
    pooled: a short stretch's own residuals would understate them and let it cut noise into
    pieces), and one friction transition speed for the whole record (one motor): the speed
    among :data:`FRICTION_SPEEDS` (or none) whose fits have the lowest total BIC.
    """
    pts = [_stretch_points(q, c, t, a, b, d, band, ring_s) for a, b, d in spans]
    first = [fit_piecewise(x, y, w, max_pieces=settings.max_pieces, min_pieces=settings.max_pieces)
             for x, y, w, _ in pts]
    size = np.array([f.n_eff * f.tau for f in first])
    scale = float(np.average([f.scale for f in first], weights=size))
    tau = float(np.average([f.tau for f in first], weights=size))
    peak = max(float(np.max(v)) if v.size else 0.0 for _, _, _, v in pts)
    # the transition speed is chosen on the longest stretch (one motor: one speed), then every
    # stretch is read with and without the nuisance at it, by the total BIC
    longest = max(range(len(pts)), key=lambda i: pts[i][0].size)
    x, y, w, sp = pts[longest]
    v_best, b_best = None, math.inf
    for v in (None,) + tuple(f * peak for f in FRICTION_SPEEDS):
        b = fit_piecewise(x, y, w, z=_friction(sp, v), max_pieces=settings.max_pieces, scale=scale, tau=tau).bic
        if b < b_best:
            v_best, b_best = v, b
    best = None
    for v in {None, v_best}:
        fits = [fit_piecewise(x, y, w, z=_friction(sp, v), max_pieces=settings.max_pieces, scale=scale, tau=tau)
                for x, y, w, sp in pts]
        total = sum(f.bic for f in fits) + (0.0 if v is None else math.log(max(sum(f.n_eff for f in fits), 2.0)))
        if best is None or total < best[0]:
            best = (total, fits)
    return best[1]


def _ripple(q, spans, fits, sign, z) -> Ripple | None:  # noqa: ANN001
    """The cogging ripple, read on the dead-zone pieces' residuals (where no tendon's load bends the
    current) pooled over the record, where BIC takes it (:func:`.condition.find_ripple`)."""
    qs, rs, ws, taus, ds = [], [], [], [], []
    for (a, b, d), fit in zip(spans, fits):
        dead, _, _ = _classify(fit, sign, d, z)
        if dead is None:
            continue
        x, y, sw, _, _ = fit.data
        xs = np.concatenate([[x[0]], np.asarray(fit.knots), [x[-1]]])
        m = (x >= xs[dead]) & (x <= xs[dead + 1])
        if m.sum() < 10:
            continue
        r = (y - fit.fitted())[m]
        s = max(fit.scale, 1e-12)
        lim = 3.0 * s / np.maximum(sw[m], 1e-12)
        qs.append(d * x[m])
        rs.append(np.clip(r, -lim, lim))
        ws.append(sw[m] ** 2)
        taus.append(fit.tau)
        ds.append(np.full(int(m.sum()), d))
    if not qs:
        return None
    step = float(np.median(np.abs(np.diff(q)))) if q.size > 1 else 0.01
    spacing = float(np.median(np.concatenate([np.abs(np.diff(x)) for x in qs if x.size > 1]) if qs else [0.0]))
    # a wave shorter than four points' spacing is aliasing, not cogging
    qa, ra, wa, da = np.concatenate(qs), np.concatenate(rs), np.concatenate(ws), np.concatenate(ds)
    scale, tau = float(np.median([f.scale for f in fits])), float(np.median(taus))
    ripple = find_ripple(qa, ra, wa, scale=scale, tau=tau, shortest=max(8.0 * step, 4.0 * spacing, 0.3))
    if ripple is None or not _same_both_ways(ripple, qa, ra, wa, da, scale, tau, z):
        return None
    return ripple


def _same_both_ways(ripple: Ripple, q, r, w, d, scale, tau, z) -> bool:  # noqa: ANN001
    """Whether each direction of motion shows the ripple on its own, with amplitudes that agree: a
    motor's cogging is set by its shaft's angle, not by the way it turns, where a wave fitted to a
    misfit of the broken lines is not (a 2-dof chi-square test of the difference, and each
    direction's amplitude beyond ``z`` standard errors)."""
    k = 2.0 * math.pi / ripple.period
    fits = []
    for way in (1, -1):
        m = d == way
        if m.sum() < 10:
            return False
        a = np.column_stack([np.sin(k * q[m]), np.cos(k * q[m])]) * np.sqrt(w[m])[:, None]
        coef, *_ = np.linalg.lstsq(a, r[m] * np.sqrt(w[m]), rcond=None)
        cov = np.linalg.pinv(a.T @ a) * scale ** 2 * max(tau, 1.0)
        fits.append((coef, cov))
    (c1, v1), (c2, v2) = fits
    for c, v in fits:
        if float(c @ np.linalg.pinv(v) @ c) < z * z:
            return False
    diff = c1 - c2
    level = math.erf(z / math.sqrt(2.0))             # the two-sided level z stands for
    return float(diff @ np.linalg.pinv(v1 + v2) @ diff) <= -2.0 * math.log(1.0 - level)  # chi-square(2)


def _summarise(q, c, t, sign, sign_note, stretches, ripple, z, settings) -> CurrentReading:  # noqa: ANN001
    edges: dict[str, Estimate] = {}
    backlash: dict[str, Estimate] = {}
    notes: dict[str, str] = {}
    no_load: dict[int, float] = {}
    loaded_slope: dict[str, float] = {}
    edge_level: dict[str, float] = {}
    dead_slopes: list[float] = []
    for side, d in (("pos", 1), ("neg", -1)):
        mine = _take_up_stretches(stretches, d, sign, z, settings)
        got = _side_edge(mine, side, d, sign, z, settings)
        if got is None:
            notes[f"d_{side}"] = (f"no stretch of the record takes the {'positive' if d > 0 else 'negative'} "
                                  "tendon up from the dead zone (the current never steepens past a flat "
                                  "stretch that way): sweep further that way")
        else:
            edges[side], loaded_slope[side], edge_level[side], note = got
            if note:
                notes[f"d_{side}"] = note
        levels, slopes = _dead_levels([s for s in stretches if s.direction == d and s.dead is not None], sign)
        dead_slopes += slopes
        if levels:
            no_load[d] = float(np.median(levels))
        est, note = _side_backlash([s for s in stretches if s.direction == -d and s.after_loaded_reversal],
                                   z, settings)
        if est is not None and est.fixed and not (side in edges and edges[side].fixed):
            # the held load is measured from a reversal after a take-up the record does not fix:
            # that reversal may not have loaded the tendon at all
            est = Estimate(est.value, est.lo, est.hi, est.level, False,
                           f"the take-up before it is not fixed ({'d_' + side}), so the reversal may not "
                           "have loaded the tendon")
        if est is not None:
            backlash[side] = est
        else:
            notes[f"b_{side}"] = note
    noise = _noise(q, c, stretches)
    return CurrentReading(sign=sign, sign_note=sign_note, edges=edges, backlash=backlash, notes=notes,
                          no_load=no_load, dead_slope=float(np.median(dead_slopes)) if dead_slopes else 0.0,
                          loaded_slope=loaded_slope, edge_level=edge_level, noise=noise, ripple=ripple,
                          stretches=tuple(stretches), current_range=(float(np.min(c)), float(np.max(c))))


def _take_up_stretches(stretches, d, sign, z, settings) -> list[StretchReading]:  # noqa: ANN001
    """The stretches of direction ``d`` whose take-up the edge is read from: at the no-load level,
    over a dead piece the other direction finds slack too, and begun at a reversal (the record's
    first stretch starts from a state the record cannot tell: a tip held above its plateau is
    taken up early; it stands in only where no other shows the edge, and then fixes nothing)."""
    # the first stretch is set aside before the no-load level is read: its unknown start state
    # would otherwise set the level the others are judged by
    cands = [s for s in stretches if s.direction == d and math.isfinite(s.edge_at)]
    return _confirmed(_at_no_load([s for s in cands if s.from_reversal] or cands, sign, z, settings.max_edge_gap),
                      [s for s in stretches if s.direction == -d and math.isfinite(s.edge_at)])


def _side_edge(mine, side, d, sign, z, settings):  # noqa: ANN001, ANN202
    """(edge Estimate, loaded slope, current at the take-up, note or None), or None without one."""
    if not mine:
        return None
    v, lo, hi, p = combine([s.edge_at for s in mine], [s.edge_lo for s in mine], [s.edge_hi for s in mine], z,
                           settings.level)
    closed = math.isfinite(lo) and math.isfinite(hi)
    reason = None if closed else "the current's take-up is seen too close to where the stretches end"
    disagree = p < 1.0 - settings.level and len(mine) > 1
    if not mine[0].from_reversal:
        closed, reason = False, ("only the record's first stretch shows the take-up, from a start state "
                                 "the record cannot tell: sweep a whole cycle past that edge")
    elif closed and max(v - lo, hi - v) > settings.max_fixed_halfwidth:
        closed, reason = False, (f"the current places the take-up only to [{lo:.2f}, {hi:.2f}] deg "
                                 + ("(its stretches disagree)" if disagree else ""))
    note = (f"the stretches place the take-up differently ({', '.join(f'{s.edge_at:.2f}' for s in mine)} deg; "
            f"heterogeneity p = {p:.2g}): the interval carries their spread") if disagree else None
    slope = float(np.median([orientation(sign, d) * s.fit.shown_slopes()[0][s.edge + 1] for s in mine]))
    level = float(np.median([np.interp(s.fit.knots[s.edge], s.fit.data[0], s.fit.fitted()) for s in mine]))
    return Estimate(v, lo, hi, settings.level, closed, reason), slope, level, note


def _dead_levels(deads, sign) -> tuple[list[float], list[float]]:  # noqa: ANN001
    """The current at the middle of each dead piece, and each dead piece's slope (load coordinates)."""
    levels, slopes = [], []
    for s in deads:
        x = s.fit.data[0]
        x_lo = s.fit.knots[s.dead - 1] if s.dead > 0 else x[0]
        x_hi = s.fit.knots[s.dead] if s.dead < s.fit.n_knots else x[-1]
        levels.append(float(np.interp(0.5 * (x_lo + x_hi), x, s.fit.fitted())))
        slopes.append(float(orientation(sign, s.direction) * s.fit.shown_slopes()[0][s.dead]))
    return levels, slopes


def _side_backlash(after, z, settings):  # noqa: ANN001, ANN202
    """(Estimate, None) of the backlash the stretches after a loaded reversal show held, or
    (None, why not)."""
    held = [s for s in after if math.isfinite(s.hold)]
    if not held:
        if after:
            return None, ("after a reversal the current unloads at once (it follows the tendon's stretch, not "
                          "the tip's load): it does not show the backlash")
        return None, "no reversal of the record comes back from a loaded tendon: the backlash is not shown"
    if len(held) < len(after):
        return None, (f"{len(held)} of the {len(after)} stretches after a loaded reversal show the load held, "
                      "the others none: the current does not fix the backlash")
    v, lo, hi, _ = combine([s.hold for s in held], [s.hold_lo for s in held], [s.hold_hi for s in held], z,
                           settings.level)
    lo, v = max(lo, 0.0), max(v, 0.0)
    sharp = math.isfinite(hi) and max(v - lo, hi - v) <= settings.max_fixed_halfwidth
    return Estimate(v, lo, hi, settings.level, sharp,
                    None if sharp else f"the current places the held load's end only to [{lo:.2f}, {hi:.2f}] deg"), None


def _dead_span(s: StretchReading) -> tuple[float, float]:
    """The knob range (deg) of a stretch's dead piece."""
    x = s.fit.data[0]
    xs = np.concatenate([[x[0]], np.asarray(s.fit.knots), [x[-1]]])
    a, b = s.direction * xs[s.dead], s.direction * xs[s.dead + 1]
    return min(a, b), max(a, b)


def _confirmed(mine: list[StretchReading], other: list[StretchReading]) -> list[StretchReading]:
    """The stretches whose dead piece shares knob angles with a dead piece read the other way.

    The dead zone is where neither tendon is taut, whichever way the knob turns: a flat piece
    that no stretch of the other direction finds slack too is a held load or a tendon still
    loaded (a record's first stretch, a stretch ending in its unloading), not the dead zone.
    Where the other direction shows no dead piece at all, nothing is confirmed and every
    stretch stands.
    """
    spans = [_dead_span(s) for s in other]
    if not spans or not mine:
        return mine
    ok = [s for s in mine if any(min(_dead_span(s)[1], b) >= max(_dead_span(s)[0], a) for a, b in spans)]
    return ok or mine


def _edge_load(s: StretchReading, sign: str) -> float:
    """The current at a stretch's take-up knot, in load coordinates."""
    x = s.fit.data[0]
    return orientation(sign, s.direction) * float(np.interp(s.fit.knots[s.edge], x, s.fit.fitted()))


def _at_no_load(mine: list[StretchReading], sign: str, z: float, gap: float) -> list[StretchReading]:
    """The stretches whose take-up happens at the no-load level.

    In load coordinates a tendon still held behind (a load held after a reversal) reads below the
    dead zone's level for a signed current and above it for a magnitude; a take-up starts from the
    dead zone. Of one direction's candidates the highest (signed) or lowest (magnitude) level is
    the dead zone's, and a candidate farther from it than the readings' noise (at the level ``z``)
    and the dead zone's tilt over ``gap`` deg is a held load's end, not a take-up."""
    if len(mine) < 2:
        return mine
    levels = np.array([_edge_load(s, sign) for s in mine])
    ref = float(levels.max() if sign == "signed" else levels.min())
    noise = max(s.fit.scale / math.sqrt(max(float(np.median(s.fit.data[2] ** 2)), 1e-12)) for s in mine)
    tilt = max(abs(float(s.fit.shown_slopes()[0][s.dead])) for s in mine) * gap
    band = z * math.sqrt(2.0) * noise + tilt
    return [s for s, lv in zip(mine, levels) if abs(lv - ref) <= band]


def _noise(q, c, stretches) -> float:  # noqa: ANN001
    rs = []
    for s in stretches:
        x = s.direction * q[s.start:s.stop + 1]
        rs.append(c[s.start:s.stop + 1] - np.interp(x, s.fit.data[0], s.fit.fitted()))
    if not rs:
        return robust_noise(c)
    return robust_scale(np.concatenate(rs))
