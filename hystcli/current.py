"""Reading a motor current: conditioning, noise, and where its slope changes.

Shared by identification (:mod:`hystcli.identify`) and shift detection (:mod:`hystcli.shift`).
Real motor currents differ from plant to plant (DESIGN.md section 4): pretensioned tendons keep
the slope from ever being flat, stiction leaves spikes, the motor's own Coulomb friction moves
the level with the direction of motion, a cable may stiffen. What they share is what this module
reads: a taut tendon is a *kink* where the slope of current against knob angle jumps, and the
level of the current tells which tendon pulls (signed current: above the no-load level the
positive tendon, below it the negative one).

* :func:`condition` removes one-sample outliers (a running median over 5 samples) before the
  paper's 20 Hz low-pass, so a spike does not become a bump the width of the filter;
* :func:`robust_noise` is the current's noise from its sample-to-sample differences;
* :func:`kink_fit` places a kink between two straight lines (a curved loaded side allowed), with
  its standard error and how clear the jump in slope is.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from .filters import lowpass

N_PIECES = 5
"""Straight pieces a stretch is split into (plateau, unloading, dead zone, loading, a wall or a
stiffening cable)."""

N_PIECES_SELECT = 8
"""Most straight pieces a stretch may be split into when the readings' noise decides how many pay
for themselves (:func:`pieces` with ``sig``): a search that crossed the dead zone from a taut start
holds a backlash plateau, a steep unloading, the unloading's softer tail, the dead zone, the
loading and a wall or a stiffening cable in one stretch, and with :data:`N_PIECES` the tail of the
unloading is merged into the dead zone's piece (design seed 1140 of ``bench/zoo.py``: a fit residual
five times the noise, the edge refused). The information criterion, not this cap, keeps noise from
being cut into little pieces."""

JUMP_RATIO = 0.6
"""A piece counts as flatter than the next one when its slope is below this share of the next."""

FLAT_AFTER = 0.35
"""A later piece flatter than this share of the loaded slope (or than the piece before the jump,
whichever is steeper, with a 20 % margin) is a dead zone still to come: the jump was a tendon
unloading, or the end of a backlash plateau."""

MERGE_RESIDUAL = 2.0
"""A kink fitted with the pieces merged into the flat one (as noise-split dead zone) whose residual
is more than this many times the residual of the same take-up fitted on the flat piece alone (or
the points' noise, if larger) had no straight dead zone before it: the merged pieces were a tendon
unloading, and the flat piece alone places the kink (:func:`loading_edge`). Chosen on design
sweeps; 2 was the one value tried."""

END_PIECE = 1.5
"""A last piece shorter than this (deg) is the rounding of the reversal, not a feature."""

MIN_CLARITY = 6.0
"""A kink counts when its jump in slope exceeds this many standard errors."""

DESPIKE_SAMPLES = 5
"""Width of the running median that takes out one-sample outliers before the low-pass."""


def condition(c: np.ndarray, fs: float | None, cutoff: float | None = 20.0) -> np.ndarray:
    """The current with one-sample outliers removed and the paper's low-pass applied (zero phase).

    Parameters
    ----------
    c : numpy.ndarray
        Recorded current.
    fs : float or None
        Sample rate (Hz); None or ``cutoff`` None skips the low-pass.
    cutoff : float or None
        Cut-off of the 3rd-order Butterworth (Hz).
    """
    from scipy.signal import medfilt

    c = np.asarray(c, dtype=float)
    if c.size >= DESPIKE_SAMPLES:
        med = medfilt(c, DESPIKE_SAMPLES)
        # keep the ends as recorded: medfilt pads with zeros
        h = DESPIKE_SAMPLES // 2
        med[:h], med[-h:] = c[:h], c[-h:]
        c = med
    if fs is not None and cutoff is not None and c.size > 12:
        c = lowpass(c, fs, cutoff)
    return c


def robust_noise(c: np.ndarray) -> float:
    """Standard deviation of the current's sample-to-sample noise (MAD of differences / sqrt 2)."""
    d = np.diff(np.asarray(c, float))
    if d.size == 0:
        return 0.0
    return float(1.4826 * np.median(np.abs(d - np.median(d))) / math.sqrt(2.0))


RIPPLE_EXPLAINED = 0.5
"""Share of the dead-zone current's variance (about its levels and slope) a cogging ripple must
explain before it is taken for one: less, and the wave is more likely the flat's other structure
(a pretensioned curve, a backlash load) than the motor's cogging."""

RIPPLE_PERIODS = 1.5
"""Fewest periods of a ripple the dead-zone samples must span at :data:`RIPPLE_EXPLAINED`."""

RIPPLE_STRONG = 0.9
"""Share of the variance a ripple must explain when the evidence is thin in another way: the
samples span fewer than :data:`RIPPLE_PERIODS` periods (but at least one), or they were all read
moving one way, so that the two directions cannot be compared. On design sweeps 0-1999 of
bench/zoo.py such ripples explained 0.92-0.995 of the flat (a cogging period of 4.9 deg over a
6.8-deg dead zone, 1871; flats read only rising or only falling, 258, 351, 893), where the waves
taken for a ripple on plants that had none explained 0.5-0.8."""

RIPPLE_ONE_WAY_PERIODS = 2.0
"""Fewest periods of a ripple the samples must span when they were all read moving one way."""

RIPPLE_SHORTEST = 1.0
"""Shortest ripple period searched (deg of knob): twice a search's default step. A shorter wave
is averaged within one step of a replay's reading, and on a dense sweep the shortest periods of
the grid fit the samples' own jitter (design sweeps of bench/zoo.py: 0.03 deg "periods" on
stretch and spiky plants)."""


@dataclass(frozen=True)
class Ripple:
    """A cogging ripple: the motor's torque ripple, periodic in its shaft angle and so in the knob's.

    ``ripple(q) = sin * sin(2 pi q / period) + cos * cos(2 pi q / period)`` (mA): the same
    whichever way the knob turns and whatever the tendons carry, so it can be taken out of any
    reading of the knob at ``q``.

    Attributes
    ----------
    period : float
        Period in knob angle (deg).
    sin, cos : float
        Amplitudes of the two phases (mA).
    """

    period: float
    sin: float
    cos: float

    @property
    def amplitude(self) -> float:
        """Half the peak-to-peak ripple (mA)."""
        return math.hypot(self.sin, self.cos)

    def __call__(self, q):  # noqa: ANN001, ANN204 - float or array in, the same out
        w = 2.0 * math.pi * np.asarray(q, float) / self.period
        out = self.sin * np.sin(w) + self.cos * np.cos(w)
        return float(out) if np.ndim(out) == 0 else out


def _ripple_rss(q: np.ndarray, c: np.ndarray, base: np.ndarray, period: float | None):
    """Least squares of ``c`` on ``base`` (and the two phases of ``period``): (rss, coefficients)."""
    a = base
    if period is not None:
        w = 2.0 * math.pi * q / period
        a = np.column_stack([base, np.sin(w), np.cos(w)])
    coef, *_ = np.linalg.lstsq(a, c, rcond=None)
    r = c - a @ coef
    return float(r @ r), coef


def _ripple_rss_grid(q: np.ndarray, c: np.ndarray, base: np.ndarray, periods: np.ndarray,
                     chunk: int = 64) -> np.ndarray:
    """:func:`_ripple_rss`'s rss for each of ``periods`` at once: the two phases are projected off
    ``base`` (its QR, taken once) and fitted to what ``base`` leaves of ``c``, a 2x2 solve per
    period instead of a whole least squares."""
    qb, _ = np.linalg.qr(base)
    r0 = c - qb @ (qb.T @ c)
    rss0 = float(r0 @ r0)
    out = np.empty(periods.size)
    for a in range(0, periods.size, chunk):
        w = (2.0 * math.pi) * q[:, None] / periods[None, a:a + chunk]
        s, co = np.sin(w), np.cos(w)
        s -= qb @ (qb.T @ s)
        co -= qb @ (qb.T @ co)
        ss, cc, sc = np.einsum("ij,ij->j", s, s), np.einsum("ij,ij->j", co, co), np.einsum("ij,ij->j", s, co)
        sr, cr = s.T @ r0, co.T @ r0
        det = ss * cc - sc * sc
        with np.errstate(divide="ignore", invalid="ignore"):
            gain = (cc * sr * sr - 2.0 * sc * sr * cr + ss * cr * cr) / det
        out[a:a + chunk] = rss0 - np.where(det > 1e-12 * ss * cc, gain, 0.0)
    return out


def cogging_ripple(q: np.ndarray, c: np.ndarray, group: np.ndarray, *, max_points: int = 4000,
                   n_periods: int = 400) -> Ripple | None:
    """The cogging ripple of a motor current read where no tendon is taut, or None.

    ``q, c`` are samples on the dead zone's flat; ``group`` labels each with the direction of
    motion (0/1), which sets the motor's Coulomb level. The fit is a level per group, one slope
    (a pretensioned dead zone) and a sinusoid in ``q``, its period searched on a log grid from
    :data:`RIPPLE_SHORTEST` (or four samples' spacing) to the span. The ripple is taken only
    when it explains :data:`RIPPLE_EXPLAINED` of the variance about the levels and slope,
    and when each direction, fitted alone at that period, shows it with the same phase (within
    45 deg) and amplitude (within a factor of 2): cogging is set by where the motor shaft is, not
    by which way it turns, where a wave from the tendons' loads would not hold still like that.
    Thinner evidence needs a clearer wave (:data:`RIPPLE_STRONG`): a period between one and
    :data:`RIPPLE_PERIODS` times the span, or samples read moving one way only (then over at
    least :data:`RIPPLE_ONE_WAY_PERIODS` periods, with no second direction to compare).
    """
    q = np.asarray(q, float)
    c = np.asarray(c, float)
    g = np.asarray(group, int)
    if q.size > max_points:
        keep = np.linspace(0, q.size - 1, max_points).round().astype(int)
        q, c, g = q[keep], c[keep], g[keep]
    labels = [v for v in (0, 1) if np.sum(g == v) >= 20]
    keep = np.isin(g, labels)
    q, c, g = q[keep], c[keep], g[keep]
    if not labels or q.size < 60:
        return None
    one_way = len(labels) < 2
    span = float(np.ptp(q))
    dx = np.diff(np.sort(q))
    dx = dx[dx > 0]
    if dx.size == 0 or span <= 0:
        return None
    lo, hi = max(4.0 * float(np.median(dx)), RIPPLE_SHORTEST), span / (RIPPLE_ONE_WAY_PERIODS if one_way
                                                                        else RIPPLE_PERIODS)
    if not hi > lo:
        return None
    base = np.column_stack([(g == v).astype(float) for v in labels] + [q - float(q.mean())])
    rss0, _ = _ripple_rss(q, c, base, None)
    if not rss0 > 0:
        return None
    grid = np.geomspace(lo, hi, n_periods)
    if not one_way:
        # on to one period over the span, at the grid's own spacing (the grid below is kept as it
        # is, so that a ripple read on it is read the same)
        ratio = float(grid[1] / grid[0]) if grid.size > 1 else 2.0
        grid = np.concatenate([grid, hi * ratio ** np.arange(1, math.floor(math.log(span / hi) / math.log(ratio)) + 1)])
    rss = _ripple_rss_grid(q, c, base, grid)
    i = int(np.argmin(rss))
    if i in (0, grid.size - 1):
        return None          # the best period at the grid's end: no ripple inside it
    # a finer look between the neighbours
    fine = np.geomspace(grid[i - 1], grid[i + 1], 41)
    fr = _ripple_rss_grid(q, c, base, fine)
    period = float(fine[int(np.argmin(fr))])
    rss1, coef = _ripple_rss(q, c, base, period)
    thin = one_way or span / period < RIPPLE_PERIODS
    if (rss0 - rss1) / rss0 < (RIPPLE_STRONG if thin else RIPPLE_EXPLAINED):
        return None
    a_sin, a_cos = float(coef[-2]), float(coef[-1])
    amp = math.hypot(a_sin, a_cos)
    for v in labels if not one_way else ():
        m = g == v
        _, cv = _ripple_rss(q[m], c[m], np.column_stack([np.ones(int(m.sum())), q[m] - float(q[m].mean())]), period)
        s_v, c_v = float(cv[-2]), float(cv[-1])
        amp_v = math.hypot(s_v, c_v)
        if not (0.5 * amp <= amp_v <= 2.0 * amp):
            return None
        cosang = (s_v * a_sin + c_v * a_cos) / max(amp_v * amp, 1e-300)
        if cosang < math.cos(math.radians(45.0)):
            return None
    return Ripple(period, a_sin, a_cos)


@dataclass(frozen=True)
class Kink:
    """A kink in current against knob angle, read along the motion.

    Attributes
    ----------
    at : float
        Knob angle of the kink (deg).
    se : float
        Its standard error (deg).
    before, after : float
        Slopes dC/dq just before and just after the kink along the motion (current unit per
        deg of knob; dq signed, so a taut tendon's loading slope is positive either way).
    clarity : float
        The jump in slope over its standard error.
    residual : float
        RMS of the fit's residuals (current unit).
    n_before, n_after : int
        Points on either side.
    level : float
        Fitted current at the kink.
    """

    at: float
    se: float
    before: float
    after: float
    clarity: float
    residual: float
    n_before: int
    n_after: int
    level: float


def kink_fit(q: np.ndarray, c: np.ndarray, direction: int, *, lo: float | None = None,
             hi: float | None = None, curved: bool = True, min_side: int = 3,
             resolution: float | None = None, convex: bool = False) -> Kink | None:
    """Best continuous two-line fit (with a quadratic term after the kink when ``curved``).

    With ``convex``, a quadratic term that bends a loaded side of ten points or more down by more
    than twice its standard error is dropped (the fit made again straight): a taut tendon
    stiffens, never softens, and a current that sags (a replay slowing into its own turn, its
    friction fading) would otherwise pull the kink late.

    ``c = a + s0 (x - e) + s1 (x - e)+ [+ k (x - e)+^2]`` with ``x = direction * q``; the kink
    ``e`` is searched on a grid within ``[lo, hi]`` (knob angles; default the data's range less
    ``min_side`` points at each end), the rest is linear least squares at each grid point, then
    the minimum is refined on a parabola through the grid's best three. The standard error of
    the kink comes from the profile of the residual sum of squares (where it rises by the noise
    variance), the clarity is ``s1 / se(s1)``.

    Returns
    -------
    Kink or None
        None when there are too few points.
    """
    q = np.asarray(q, float)
    c = np.asarray(c, float)
    x = direction * q
    order = np.argsort(x, kind="stable")
    x, c = x[order], c[order]
    n = x.size
    if n < 2 * min_side + (1 if curved else 0):
        return None
    xl, xh = x[min_side - 1], x[-min_side]
    if lo is not None and hi is not None:
        blo, bhi = sorted((direction * float(lo), direction * float(hi)))
        xl, xh = max(xl, blo), min(xh, bhi)
    if not xh > xl:
        return None
    step = resolution if resolution else max((x[-1] - x[0]) / 400.0, 1e-3)
    grid = np.arange(xl, xh + 0.5 * step, step)
    dx = x[None, :] - grid[:, None]
    a = np.stack(_columns(dx, curved), axis=-1)                              # (G, n, p)
    # the normal equations of every grid point at once; c centred (the constant column takes
    # the mean) so that sse = c.c - beta.(A'c) loses nothing to cancellation
    cc = c - float(np.mean(c))
    at = a.transpose(0, 2, 1)
    ata = at @ a
    atc = at @ cc
    p = a.shape[-1]
    # every grid point keeps min_side points on each side, so A'A is well conditioned there: solve
    # at once, and only when that fails look for the ill-conditioned points (A'A is symmetric
    # positive semi-definite: its condition number is the ratio of its extreme eigenvalues)
    try:
        beta = np.linalg.solve(ata, atc[..., None])[..., 0]
        det_ok = np.all(np.isfinite(beta), axis=1)
    except np.linalg.LinAlgError:
        ev = np.linalg.eigvalsh(ata)
        det_ok = ev[:, 0] > ev[:, -1] * 1e-12
        beta = np.zeros((grid.size, p))
        if det_ok.any():
            beta[det_ok] = np.linalg.solve(ata[det_ok], atc[det_ok][..., None])[..., 0]
    if not det_ok.any():
        return None
    sse = np.where(det_ok, np.maximum(float(cc @ cc) - np.sum(beta * atc, axis=1), 0.0), np.inf)
    g = int(np.argmin(sse))
    e = grid[g]
    if 0 < g < grid.size - 1 and np.all(np.isfinite(sse[g - 1:g + 2])):
        y0, y1, y2 = sse[g - 1:g + 2]
        den = y0 - 2 * y1 + y2
        if den > 0:
            e = grid[g] + 0.5 * step * (y0 - y2) / den
    dx1 = x - e
    a1 = np.column_stack(_columns(dx1, curved))
    b1, *_ = np.linalg.lstsq(a1, c, rcond=None)
    r1 = c - a1 @ b1
    dof = max(n - p - 1, 1)
    s2 = float(r1 @ r1) / dof
    try:
        cov = np.linalg.inv(a1.T @ a1) * s2
        se_s1 = math.sqrt(max(cov[2, 2], 0.0))
    except np.linalg.LinAlgError:
        cov, se_s1 = None, math.inf
    # a sag clear of the noise (two standard errors) on a loaded stretch long enough to show one
    # (ten points): no tendon's; on fewer the quadratic term is loose either way, and is kept.
    # c is fitted against x unsigned: moving down, the negative tendon's current falls (its
    # loaded slope along x is negative), and it stiffens by falling faster still, so its sag is
    # the quadratic term's sign turned by the direction (taken unturned, every stiffening
    # negative tendon was fitted straight and its edge put late: design replays 1228, 0.92 deg
    # off at exit 0, and 3400497, 1.5 deg)
    if (convex and curved and cov is not None and int(np.sum(dx1 >= 0)) >= 10
            and direction * b1[3] + 2.0 * math.sqrt(max(cov[3, 3], 0.0)) < 0):
        return kink_fit(q, c, direction, lo=lo, hi=hi, curved=False, min_side=min_side, resolution=resolution)
    # standard error of the kink from the SSE profile: where it rises by s2 above its minimum
    prof = sse - float(np.min(sse))
    inside = grid[prof <= s2]
    se_e = max(0.5 * (float(inside.max()) - float(inside.min())), step / math.sqrt(12.0)) if inside.size else step
    # back to dC/dq (dq signed): a loading tendon's slope is positive whichever way the knob goes
    s0, s1 = direction * float(b1[1]), direction * float(b1[2])
    clarity = s1 / se_s1 if se_s1 > 0 else math.inf
    return Kink(at=float(direction * e), se=float(se_e), before=s0, after=s0 + s1, clarity=float(clarity),
                residual=math.sqrt(float(r1 @ r1) / n), n_before=int(np.sum(dx1 < 0)),
                n_after=int(np.sum(dx1 >= 0)), level=float(b1[0]))


def _columns(dx: np.ndarray, curved: bool) -> list[np.ndarray]:
    cols = [np.ones_like(dx), dx, np.maximum(dx, 0.0)]
    if curved:
        cols.append(np.maximum(dx, 0.0) ** 2)
    return cols


# --------------------------------------------------------------------------------------------
# straight pieces and the loading edge
# --------------------------------------------------------------------------------------------
@njit(cache=True)
def _segment_tables(x, v, nseg, minlen):
    # Optimal splits of (x, v) into 1..nseg independent straight lines (least squares), by
    # dynamic programming over prefix sums: exact, and cheap for the ~100-200 bins of one branch.
    # best[k, j]: least SSE of the first j points in k lines; arg[k, j]: where the last one starts.
    n = x.shape[0]
    s0 = np.zeros(n + 1)
    sx = np.zeros(n + 1)
    sy = np.zeros(n + 1)
    sxx = np.zeros(n + 1)
    sxy = np.zeros(n + 1)
    syy = np.zeros(n + 1)
    for i in range(n):
        s0[i + 1] = s0[i] + 1.0
        sx[i + 1] = sx[i] + x[i]
        sy[i + 1] = sy[i] + v[i]
        sxx[i + 1] = sxx[i] + x[i] * x[i]
        sxy[i + 1] = sxy[i] + x[i] * v[i]
        syy[i + 1] = syy[i] + v[i] * v[i]
    inf = 1e300
    best = np.full((nseg + 1, n + 1), inf)
    arg = np.zeros((nseg + 1, n + 1), dtype=np.int64)
    best[0, 0] = 0.0
    for k in range(1, nseg + 1):
        for j in range(k * minlen, n + 1):
            for i in range((k - 1) * minlen, j - minlen + 1):
                if best[k - 1, i] >= inf:
                    continue
                m = s0[j] - s0[i]
                ax = sx[j] - sx[i]
                ay = sy[j] - sy[i]
                cxx = sxx[j] - sxx[i] - ax * ax / m
                cxy = sxy[j] - sxy[i] - ax * ay / m
                cyy = syy[j] - syy[i] - ay * ay / m
                sse = cyy - (cxy * cxy / cxx if cxx > 1e-12 else 0.0)
                if sse < 0.0:
                    sse = 0.0
                total = best[k - 1, i] + sse
                if total < best[k, j]:
                    best[k, j] = total
                    arg[k, j] = i
    return best, arg


@njit(cache=True)
def _backtrack(arg, nseg, n):
    bounds = np.zeros(nseg + 1, dtype=np.int64)
    bounds[nseg] = n
    j = n
    for k in range(nseg, 0, -1):
        j = arg[k, j]
        bounds[k - 1] = j
    return bounds


@njit(cache=True)
def _segment_dp(x, v, nseg, minlen):
    # the optimal split into exactly nseg lines
    best, arg = _segment_tables(x, v, nseg, minlen)
    return _backtrack(arg, nseg, x.shape[0])



def pieces(x: np.ndarray, v: np.ndarray, minlen: int,
           sig: float | None = None) -> list[tuple[int, int, float, float]]:
    """Split binned points into straight pieces: ``(first, stop, slope, level at first)``.

    Into :data:`N_PIECES` pieces (fewer when there are too few points); with ``sig`` (the noise
    of one point), into as many as pay for themselves by the Bayesian information criterion (up
    to :data:`N_PIECES_SELECT`):
    each piece costs its three parameters (level, slope, where it starts) ``log(n)`` noise
    variances of residual, so the noise of a few readings is not cut into steep little pieces
    (a kink clear enough to take, seven standard errors, earns far more than that).
    """
    n = x.size
    selecting = sig is not None and sig > 0
    kmax = max(1, min(N_PIECES_SELECT if selecting else N_PIECES, n // max(minlen, 1)))
    xs, vs = np.ascontiguousarray(x), np.ascontiguousarray(v)
    if selecting and kmax > 1:
        best, arg = _segment_tables(xs, vs, kmax, minlen)
        crit = best[1:, n] / sig ** 2 + 3.0 * math.log(n) * np.arange(1, kmax + 1)
        k = 1 + int(np.argmin(crit))
        bounds = _backtrack(arg, k, n)
    else:
        bounds = _segment_dp(xs, vs, kmax, minlen)
    out = []
    for a, b in zip(bounds[:-1], bounds[1:]):
        xs, vs = x[a:b], v[a:b]
        if b - a >= 2 and np.ptp(xs) > 0:
            m, c0 = np.polyfit(xs, vs, 1)
        else:
            m, c0 = 0.0, float(vs.mean())
        out.append((int(a), int(b), float(m), float(c0 + m * xs[0])))
    return out


HELD_LEAD = 2.0
"""Knob travel (deg) after a reversal within which a held plateau must begin
(:func:`hystcli.identify.current._held_plateau`, :func:`unloads_after_level`):
an immediate drop (the sheath friction flipping over a fraction of a degree) or the motor's own
Coulomb flip may come first; anything longer is not the backlash phase."""


def unloads_after_level(pieces, slopes, x, k: int, flat: float, sig: float) -> bool:
    """Whether piece ``k`` is a tendon unloading out of a held plateau rather than part of the dead
    zone: a level piece (a degree or more, at most 0.15 of its slope, beginning within
    :data:`HELD_LEAD` of the stretch's start, the reversal) right before it, and its own fall more
    than twice the dead zone's slope ``flat`` and clear of the noise ``sig`` over its length.

    A capstan's friction can make the unloading much gentler than the loading (design seed
    2098: 4.0 against 20.5 mA/deg), so flatness against the loaded slope alone merges
    it into the dead zone; a pretensioned dead zone whose curve softens piece by piece has no
    level piece before it, and a dead zone met degrees after the reversal, before a loading piece
    that levels off short of a wall (design seed 245), is not a held plateau.
    """
    if k < 1 or x[pieces[k - 1][0]] - x[pieces[0][0]] > HELD_LEAD:
        return False
    span = x[pieces[k][1] - 1] - x[pieces[k][0]]
    span_before = x[pieces[k - 1][1] - 1] - x[pieces[k - 1][0]]
    unloads = abs(slopes[k]) > 2.0 * abs(flat) and abs(slopes[k] - flat) * span > 6.0 * sig
    return bool(unloads and abs(slopes[k - 1]) <= 0.15 * abs(slopes[k]) and span_before >= 1.0)


def edge_piece(pieces, slopes, xb, sig, *, corner: bool = False) -> int | None:
    """Index of the flat piece that the loading edge ends (see the module docstring)."""
    ranked = edge_pieces(pieces, slopes, xb, sig, corner=corner)
    return ranked[0] if ranked else None


def edge_pieces(pieces, slopes, xb, sig, *, corner: bool = False) -> list[int]:
    """Every flat piece a loading edge may end, the likeliest first (:func:`edge_piece`'s choice:
    the flattest start, of equals the later one).

    With ``corner`` (a sweep's binned reading), a piece shorter than :data:`END_PIECE` between
    the flat one and a steeper one is read as the edge's corner, its climb judged over both.
    A stepping search's few readings keep the plain test: its pieces are a handful of probes,
    where a short piece is a probe or two, not a corner."""
    n = len(pieces)
    if n < 2:
        return []
    # the stretch must end loaded: its last piece rises clearly (or the one before a short last
    # piece, the reversal's rounding)
    def rises(k: int) -> bool:
        p = pieces[k]
        return slopes[k] > 0 and slopes[k] * (xb[p[1] - 1] - xb[p[0]] + 1e-9) > 6 * sig

    short_last = xb[pieces[-1][1] - 1] - xb[pieces[-1][0]] < END_PIECE
    if not (rises(n - 1) or (short_last and n > 1 and rises(n - 2))):
        return []
    found = []
    for j in range(n - 1):
        pre, post = slopes[j], slopes[j + 1]
        if post <= 0 or abs(pre) > JUMP_RATIO * post:
            continue
        length = xb[pieces[j + 1][1] - 1] - xb[pieces[j + 1][0]] + 1e-9
        climb = post * length
        if corner and length < END_PIECE and j + 2 < n and slopes[j + 2] > post:
            # a short piece between the flat and a steeper one is the corner (a bin or two
            # straddling the edge, the law's rounding): the climb is read over both (zoo sweep
            # 5000211: a 0.5-deg piece at 7 mA/deg before the loaded 18, the flat's edge dropped)
            end = xb[pieces[j + 2][1] - 1]
            climb += slopes[j + 2] * (end - xb[pieces[j + 2][0]]) + post * (xb[pieces[j + 2][0]] - xb[pieces[j + 1][1] - 1])
            length = end - xb[pieces[j + 1][0]] + 1e-9
        # the piece after the jump must itself climb clearly: a loaded tendon, not a flat
        if climb - pre * length < 6 * sig or climb < 6 * sig:
            continue
        # nothing flat after it (a dead zone still to come means this was a tendon unloading);
        # a short last piece is the reversal's rounding, not a dead zone
        later = [k for k in range(j + 2, n)
                 if not (k == n - 1 and xb[pieces[k][1] - 1] - xb[pieces[k][0]] < END_PIECE)]
        floor = 1.2 * max(pre, FLAT_AFTER * post)
        if any(slopes[k] <= floor for k in later):
            continue
        # nor a marked fall after it (a piece below FLAT_AFTER of the steepest between): a loaded
        # tendon stiffens or meets a wall, it never softens back; a fall is a held load's end, or
        # a dead zone climbing at a pretensioned tendon's slope (design seed 28: the reversal's
        # first half-degree read as the dead zone, the held plateau as the loading, 6 against the
        # unloading's 29 and the dead zone's 6 mA/deg)
        if any(slopes[k] <= FLAT_AFTER * max(slopes[j + 1:k]) for k in later):
            continue
        found.append(j)
    # the flattest start; of equals the later one (the far side)
    return sorted(found, key=lambda j: (slopes[j], -j))


def loading_edge(q: np.ndarray, c: np.ndarray, direction: int, sig: float, *, minlen: int = 2,
                 resolution: float | None = None, strict_flat: bool = False,
                 select: bool = False, convex: bool = False, min_run: int = 0,
                 fallback: bool = False, corner: bool = False) -> Kink | None:
    """Where a tendon is taken up on one monotone stretch, or None when it shows no such kink.

    ``q, c`` are points along the motion (binned samples, or a stepping search's readings);
    ``sig`` the noise of one point. The stretch is split into straight pieces; the loading edge
    is the jump in slope (dC/dq, loading-positive) out of the flattest piece after which nothing
    flat follows (:func:`edge_piece`), placed by :func:`kink_fit` on the flat piece and the
    loaded run up to a wall. Kinks clearer than :data:`MIN_CLARITY` standard errors only.

    With ``strict_flat`` (a stepping search's readings), the kink fit takes in a piece before the
    flat one only when its slope is the flat one's within three standard errors of the two:
    pieces that noise split off the dead zone, never a tendon's unloading that led into it, whose
    slope may be any share of the loaded one (or twice a pretensioned dead zone's). With
    ``select``, the stretch is split into only as many pieces as the noise ``sig`` lets pay for
    themselves (:func:`pieces`). With ``convex``, the loaded side may stiffen but not sag
    (:func:`kink_fit`). With ``min_run``, a steeper piece ends the loaded run (a wall) only after
    that many points of it: the fewest a caller needs past a kink to judge it. With ``fallback``,
    when the likeliest flat piece gives no clear kink, the next ones are tried in turn (a wall's
    kink among them: the caller judges the loaded slope it finds). ``corner`` is
    :func:`edge_pieces`'.
    """
    q = np.asarray(q, float)
    c = np.asarray(c, float)
    d = direction
    x = d * (q - q[0])
    if x.size < 2 * minlen + 1:
        return None
    pcs = pieces(x, c, minlen, sig if select else None)
    slopes = [d * m for (_, _, m, _) in pcs]
    ranked = edge_pieces(pcs, slopes, x, sig, corner=corner)
    for j in ranked[:None if fallback else 1]:
        kink = _edge_at(q, c, d, x, pcs, slopes, j, sig, minlen=minlen, resolution=resolution,
                        strict_flat=strict_flat, convex=convex, min_run=min_run)
        if kink is not None:
            return kink
    return None


def _edge_at(q, c, d, x, pcs, slopes, j, sig, *, minlen, resolution, strict_flat, convex,  # noqa: ANN001
             min_run) -> Kink | None:
    """:func:`loading_edge`'s kink out of flat piece ``j``, or None when it is not clear."""
    # the kink fit sees the whole flat stretch before the jump (noise may have split it into
    # pieces) and the loaded run up to a wall (the next qualifying jump)
    first = j
    if strict_flat:
        sxx_j = _sxx(x[pcs[j][0]:pcs[j][1]])
        while first > 0:
            k = first - 1
            sxx_k = _sxx(x[pcs[k][0]:pcs[k][1]])
            agree = (sxx_k > 0 and sxx_j > 0
                     and abs(slopes[k] - slopes[j]) <= 3.0 * sig * math.sqrt(1.0 / sxx_k + 1.0 / sxx_j))
            if not agree:
                break
            first = k
    else:
        while first > 0 and abs(slopes[first - 1]) <= max(FLAT_AFTER * slopes[j + 1], 2.0 * abs(slopes[j])):
            # noise splits the flat into pieces; a piece clearly steeper than the flat one (beyond
            # three standard errors and a fifth of the jump) is a tendon unloading into the dead
            # zone, at twice a pretensioned dead zone's slope (design seed 1: 5.0 against 2.5 and a
            # loaded 10.1 mA/deg; in the fit it put d_pos 1.9 deg late)
            k = first - 1
            sxx_k, sxx_j = _sxx(x[pcs[k][0]:pcs[k][1]]), _sxx(x[pcs[j][0]:pcs[j][1]])
            same = (sxx_k > 0 and sxx_j > 0
                    and abs(slopes[k] - slopes[j]) <= 3.0 * sig * math.sqrt(1.0 / sxx_k + 1.0 / sxx_j))
            if not same and (abs(slopes[k] - slopes[j]) > 0.2 * (slopes[j + 1] - slopes[j])
                             or unloads_after_level(pcs, slopes, x, k, slopes[j], sig)):
                break
            first -= 1
    a0 = pcs[first][0]
    stop = x.size
    for jj in range(j + 2, len(pcs)):
        if pcs[jj][0] - pcs[j + 1][0] < min_run:
            # a run that short between the flat and a steeper piece is the corner, its readings
            # straddling the edge (one just past it, barely loaded): the steeper piece is the
            # tendon's own loaded one, not a wall, and a fit stopped before it would wait for
            # points past the kink that can never come (design replays 1531, a stretch law read
            # 0.1 deg past its edge, and 1898: refused at the travel limit with the edge 20 and
            # 5 deg behind)
            continue
        if slopes[jj - 1] <= JUMP_RATIO * slopes[jj] and (slopes[jj] - slopes[jj - 1]) * (
                x[pcs[jj][1] - 1] - x[pcs[jj][0]]) > 6 * sig:
            stop = pcs[jj][0]
            break
    # the kink is searched over the whole flat stretch and the loaded piece: noise can split off
    # a short flat piece just past the true edge (a one-step drop, then a level pair of
    # readings), and a search near the segmentation's break would then sit degrees late
    hi = q[min(pcs[j + 1][1] - 1, stop - 1)]
    # a stiffening loaded side needs its quadratic term, and enough points to carry it
    curved = stop - pcs[j + 1][0] >= 10

    def fit(a: int) -> Kink | None:
        # the kink of the points from ``a`` (the flat's first) to the loaded run's end
        return kink_fit(q[a:stop], c[a:stop], d, lo=q[a], hi=hi, curved=curved, min_side=max(2, minlen // 2),
                        resolution=resolution, convex=convex)

    def clear(k: Kink | None) -> bool:
        return k is not None and k.clarity >= MIN_CLARITY and k.after > 0

    kink = fit(a0)
    # the merge above tells a noise-split dead zone from an unloading by slope alone; one that
    # starts at the reversal, with no held level before it (a drop law's tendon unloading at a
    # share of its loaded slope), passes for a tilted dead zone, and the two-line fit through it
    # leans the kink late (design sweep 3800430: d_pos 1.1 deg late at +-0.25, a residual of 60
    # noise sigmas). The pieces merged must leave the fit straight: where the flat piece alone
    # fits the same take-up (its loaded slope within half) far better and flatter, it places
    # the kink. (The same loaded slope: a wall's kink after a soft take-up is another kink.)
    if first < j and kink is not None and not strict_flat:
        alone = fit(pcs[j][0])
        if (clear(alone) and abs(alone.before) < abs(kink.before)
                and abs(alone.after - kink.after) <= 0.5 * kink.after
                and kink.residual > MERGE_RESIDUAL * max(alone.residual, sig)):
            kink = alone
    return kink if clear(kink) else None


def _sxx(x: np.ndarray) -> float:
    """Sum of squared deviations of ``x`` from its mean (what a fitted slope's variance divides)."""
    return float(np.sum((x - x.mean()) ** 2)) if x.size else 0.0


def arrival_edge(q: np.ndarray, c: np.ndarray, direction: int, sig: float, *, minlen: int = 2,
                 resolution: float | None = None) -> Kink | None:
    """Where an unloading tendon's current arrives at the dead zone's flat, or None.

    The mirror of :func:`loading_edge` on a stretch that starts with a tendon taut and moves
    toward the dead zone: the first flat piece (at least a degree long) after a clearly rising
    one (loading-positive slope: the current moving back toward its no-load level) ends the
    unloading. Where that happens depends on the current law (the knob position of the slack for
    a stretching tendon, the end of the tip's unloading for a load-following one), so it is no
    dead-zone edge by itself: Algorithm 1 compares it with where the same reading found it on the
    identification sweep. The kink's clarity is returned positive (the slope falls here).
    """
    q = np.asarray(q, float)
    c = np.asarray(c, float)
    d = direction
    x = d * (q - q[0])
    if x.size < 2 * minlen + 1:
        return None
    pcs = pieces(x, c, minlen)
    slopes = [d * m for (_, _, m, _) in pcs]
    for j in range(1, len(pcs)):
        length = x[pcs[j][1] - 1] - x[pcs[j][0]]
        # flat against the piece it follows (the unloading slope), not only against a steep
        # backlash piece before that
        if length < 1.0 or slopes[j - 1] <= 0 or abs(slopes[j]) > 0.2 * slopes[j - 1]:
            continue
        ju = j - 1      # the unloading piece the flat follows
        rise = slopes[ju] * (x[pcs[ju][1] - 1] - x[pcs[ju][0]] + 1e-9)
        if slopes[ju] <= 0 or rise < 6 * sig:
            return None
        kink = kink_fit(q[pcs[ju][0]:pcs[j][1]], c[pcs[ju][0]:pcs[j][1]], d,
                        lo=q[pcs[ju][0]], hi=q[pcs[j][1] - 1], curved=False,
                        min_side=max(2, minlen // 2), resolution=resolution)
        if kink is None or -kink.clarity < MIN_CLARITY:
            return None
        return Kink(kink.at, kink.se, kink.before, kink.after, -kink.clarity, kink.residual,
                    kink.n_before, kink.n_after, kink.level)
    return None
