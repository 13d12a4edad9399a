"""Continuous piecewise-linear regression: a robust fit, its number of pieces by BIC, and a
profile-likelihood interval for each knot.

A monotone stretch of motor current against knob angle is, to the precision the method needs, a
continuous broken line: a held load, an unloading, the dead zone (flat, or sloped when the tendons
are pretensioned), the take-up, a stiffening or a wall; plus nuisance terms that are linear in
known columns (the motor's friction as a function of the knob's speed). This module fits such
lines and nothing else; what the pieces mean is :mod:`hystcli.signal.reading`'s business.

The model with knots :math:`t_1..t_K` and nuisance columns :math:`Z` is

.. math::  f(x) = a + b\\,(x - x_0) + \\sum_k g_k\\,(x - t_k)_+ + Z\\,\\beta

For given knots it is linear, so the fit is iteratively reweighted least squares with the
``soft_l1`` loss (a logging spike or a stiction burst is down-weighted, not fitted). Knots are
placed by coordinate descent over a grid of candidate positions, each scan one projection for all
candidates at once, from the knots ``ruptures``' bottom-up continuous-linear segmentation proposes
(and from the fit with one knot fewer plus one where its residuals run longest on one side). The
number of knots is the one with the lowest BIC, deviance and sample count both taken at the
residuals' effective sample size (neighbouring points of a filtered current share their noise),
at one noise scale read from the richest fit. A knot's interval is its profile likelihood: the
positions whose refit (the other knots held, every linear coefficient refitted) keeps the deviance
rise under the chi-square(1) quantile of the chosen level; where the rise is never reached before
the data end, the interval is open on that side.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from . import pwl_kernels as _k

__all__ = ["Piecewise", "fit_piecewise", "knot_interval", "autocorrelation_time", "robust_scale"]

IRLS_ROUNDS = 4
"""Reweighting rounds of the robust loss per knot placement (a computation budget)."""


def robust_scale(r: np.ndarray) -> float:
    """Normal-consistent MAD of ``r`` about its median."""
    r = np.asarray(r, float)
    if r.size == 0:
        return 0.0
    return float(1.4826 * np.median(np.abs(r - np.median(r))))


def autocorrelation_time(resid: np.ndarray, max_lag: int = 5000) -> float:
    """Integrated autocorrelation time of a residual series (1 for white noise).

    How many neighbouring points share one draw of noise: summed up to the first lag where the
    autocorrelation falls below 0.05 (past it the estimate is its own noise).
    """
    r = np.asarray(resid, float)
    r = r - float(np.mean(r)) if r.size else r
    var = float(r @ r)
    n = r.size
    if var <= 0 or n < 4:
        return 1.0
    nfft = 1 << (2 * n - 1).bit_length()
    f = np.fft.rfft(r, nfft)
    acf = np.fft.irfft(f * np.conj(f), nfft)[:n] / var
    below = np.flatnonzero(acf[1:min(n, max_lag)] < 0.05)
    stop = int(below[0]) + 1 if below.size else min(n, max_lag)
    return float(max(1.0, 1.0 + 2.0 * np.sum(acf[1:stop])))


@dataclass(frozen=True)
class Piecewise:
    """A continuous piecewise-linear fit of ``y`` against ``x`` (plus nuisance columns).

    Attributes
    ----------
    knots : tuple of float
        Knot positions, increasing (x units).
    coef : numpy.ndarray
        ``(a, b, g_1, ..., g_K, beta...)``: value at ``x0``, first slope, slope changes at the
        knots, nuisance coefficients.
    x0 : float
        Where the intercept ``a`` is taken (the data's first x).
    scale : float
        Robust noise scale of a point of weight 1 (y units).
    tau : float
        Autocorrelation time of the residuals (points).
    deviance : float
        Robust deviance ``sum rho(r^2 / scale^2)`` (soft_l1).
    bic : float
        ``deviance / tau + (2 + 2K + m) log(n_eff)``, m nuisance columns.
    n_eff : float
        Effective number of independent points (the weights' sum over ``tau``).
    """

    knots: tuple[float, ...]
    coef: np.ndarray = field(repr=False)
    x0: float
    scale: float
    tau: float
    deviance: float
    bic: float
    n_eff: float
    data: tuple = field(default=(), repr=False, compare=False)   # (x, y, sw, Z, irls weights)

    @property
    def n_knots(self) -> int:
        return len(self.knots)

    @property
    def slopes(self) -> np.ndarray:
        """Slope of each piece, left to right."""
        k = self.n_knots
        return float(self.coef[1]) + np.concatenate([[0.0], np.cumsum(self.coef[2:2 + k])])

    @property
    def nuisance(self) -> np.ndarray:
        """Coefficients of the nuisance columns."""
        return np.asarray(self.coef[2 + self.n_knots:], float)

    def __call__(self, x, z=None) -> np.ndarray:  # noqa: ANN001
        """The broken line at ``x`` (with the nuisance columns ``z`` when given)."""
        x = np.asarray(x, float)
        out = self.coef[0] + self.coef[1] * (x - self.x0)
        for t, g in zip(self.knots, self.coef[2:2 + self.n_knots]):
            out = out + g * np.maximum(x - t, 0.0)
        if z is not None and self.nuisance.size:
            out = out + np.asarray(z, float) @ self.nuisance
        return out

    def fitted(self) -> np.ndarray:
        """The fit at its own points, nuisance included."""
        x, _, _, z, _ = self.data
        return self(x, z if z.shape[1] else None)

    def slope_se(self) -> np.ndarray:
        """Standard error of each piece's slope with the knots held (tau-inflated)."""
        x, _, sw, z, u = self.data
        a = _design(x, self.x0, np.asarray(self.knots), z) * (sw * np.sqrt(u))[:, None]
        cov = np.linalg.pinv(a.T @ a) * self.scale ** 2 * self.tau
        k = self.n_knots
        t = np.zeros((k + 1, a.shape[1]))
        t[:, 1] = 1.0
        for i in range(1, k + 1):
            t[i, 2:2 + i] = 1.0
        return np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", t, cov, t), 0.0))


    def shown_slopes(self) -> tuple[np.ndarray, np.ndarray]:
        """Slope of the whole fitted curve (broken line and nuisance) over each piece, and its
        standard error (knots held, tau-inflated).

        Where the nuisance columns vary along ``x`` (a friction term of the knob's speed, which a
        sine sweep makes a function of position), the split between the broken line and the
        nuisance is poorly determined, but their sum, the curve the data show, is not: this is
        the slope a physical reading of the pieces should use. Without nuisance columns it is
        :attr:`slopes` and :meth:`slope_se`.
        """
        x, _, sw, z, u = self.data
        if not z.shape[1]:
            return self.slopes, self.slope_se()
        kn = np.asarray(self.knots)
        ends = np.concatenate([[x[0]], kn, [x[-1]]])
        zs = np.column_stack([np.interp(ends, x, z[:, i]) for i in range(z.shape[1])])
        rows = _design(ends, self.x0, kn, zs)
        width = np.maximum(np.diff(ends), 1e-12)[:, None]
        lin = (rows[1:] - rows[:-1]) / width
        a = _design(x, self.x0, kn, z) * (sw * np.sqrt(u))[:, None]
        cov = np.linalg.pinv(a.T @ a) * self.scale ** 2 * self.tau
        return lin @ self.coef, np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", lin, cov, lin), 0.0))


def _design(x: np.ndarray, x0: float, knots: np.ndarray, z: np.ndarray) -> np.ndarray:
    cols = [np.ones_like(x), x - x0] + [np.maximum(x - t, 0.0) for t in knots]
    a = np.column_stack(cols)
    return np.hstack([a, z]) if z.shape[1] else a


def _z(z: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(z, dtype=np.float64).reshape(z.shape[0], -1)


def _solve(x, y, sw, z, x0, knots, scale, u=None):  # noqa: ANN001
    """IRLS at fixed knots: (coef, irls weights, deviance)."""
    u = np.ones_like(x) if u is None else np.array(u, dtype=np.float64)
    return _k.solve(x, y, sw, _z(z), float(x0), np.asarray(knots, np.float64), float(scale), u, IRLS_ROUNDS)


def _scan(x, y, w, z, x0, knots, j, cand):  # noqa: ANN001
    """Weighted RSS with knot ``j`` moved to each of ``cand`` (other knots held), all at once.

    The hinge column ``(x - p)_+`` of a candidate ``p`` is projected off the other columns through
    suffix sums over the sorted ``x``: every candidate costs a few sums, not a pass over the data.
    """
    return _k.scan(x, y, np.asarray(w, np.float64), _z(z), float(x0), np.asarray(knots, np.float64), int(j),
                   np.ascontiguousarray(cand, dtype=np.float64))


def _place(x, y, sw, z, x0, knots, scale, grid):  # noqa: ANN001
    """Coordinate descent of the knots over ``grid`` with robust reweighting: (coef, knots, u, dev)."""
    return _k.place(x, y, sw, _z(z), float(x0), np.asarray(knots, np.float64), float(scale),
                    np.ascontiguousarray(grid, dtype=np.float64), IRLS_ROUNDS)


def _candidates(y: np.ndarray, k: int, min_size: int) -> list[np.ndarray]:
    """Knot index candidates for ``k`` knots from ruptures' bottom-up continuous-linear segmentation."""
    import ruptures as rpt

    n = y.size
    if k == 0 or n < (k + 1) * min_size:
        return []
    try:
        bk = rpt.BottomUp(model="clinear", min_size=min_size, jump=1).fit(y).predict(n_bkps=k)
    except Exception:  # noqa: BLE001 - ruptures refuses too short or degenerate signals: no candidate
        return []
    return [np.asarray(bk[:-1], dtype=int)]


def _worst_place(x, y, sw, z, x0, knots, coef) -> float:  # noqa: ANN001
    """Where a knot would help most: the middle of the longest run of same-signed residuals."""
    r = np.sign(_design(x, x0, knots, z) @ coef - y)
    best_len, best_mid, start = 0, float(np.median(x)), 0
    for i in range(1, r.size + 1):
        if i == r.size or r[i] != r[start]:
            if i - start > best_len:
                best_len, best_mid = i - start, float(x[(start + i - 1) // 2])
            start = i
    return best_mid


def fit_piecewise(x: np.ndarray, y: np.ndarray, w: np.ndarray | None = None, *, z: np.ndarray | None = None,
                  max_pieces: int = 5, min_pieces: int = 1, min_size: int = 3, scale: float | None = None,
                  tau: float | None = None) -> Piecewise:
    """The continuous broken line through ``(x, y)`` with the number of pieces chosen by BIC.

    Parameters
    ----------
    x, y : numpy.ndarray
        The points, ``x`` increasing.
    w : numpy.ndarray, optional
        Weights (effective numbers of independent samples behind each point).
    z : numpy.ndarray, optional
        Nuisance columns (n x m), fitted linearly alongside.
    max_pieces, min_pieces : int
        Most and fewest pieces tried.
    min_size : int
        Fewest points between candidate knots.
    scale, tau : float, optional
        Noise scale of a point of weight 1 and the residuals' autocorrelation time; default:
        read from the richest fit's residuals.

    Returns
    -------
    Piecewise
    """
    x = np.ascontiguousarray(x, dtype=np.float64)
    y = np.ascontiguousarray(y, dtype=np.float64)
    sw = np.sqrt(np.ones_like(x) if w is None else np.maximum(np.asarray(w, np.float64), 0.0))
    z = np.zeros((x.size, 0)) if z is None else _z(np.asarray(z, np.float64).reshape(x.size, -1))
    x0 = float(x[0])
    n = x.size
    inner = x[min_size:-min_size] if n > 2 * min_size + 1 else x
    grid = inner[::max(1, inner.size // 100)]
    kmax = max(0, min(max_pieces - 1, n // max(min_size, 1) - 1))
    s0 = scale if scale is not None else max(robust_scale(np.diff(y) * sw[1:]) / math.sqrt(2.0), 1e-12)
    k_first = min(max(min_pieces, 1), kmax + 1) - 1
    fits = _nested_fits(x, y, sw, z, x0, k_first, kmax, min_size, s0, grid)
    coef, kn, u, _ = fits[max(fits)]
    r = (_design(x, x0, kn, z) @ coef - y) * sw
    s = scale if scale is not None else max(robust_scale(r), 1e-12)
    tau = autocorrelation_time(r) if tau is None else float(tau)
    best_fit = None
    for coef, kn, u, dev in (fits[k] for k in sorted(fits)):
        if s != s0:
            coef, u, dev = _solve(x, y, sw, z, x0, kn, s, u)
        pw = _make(x, y, sw, z, x0, coef, kn, u, dev, s, tau)
        if best_fit is None or pw.bic < best_fit.bic:
            best_fit = pw
    return best_fit


def _nested_fits(x, y, sw, z, x0, k_first, kmax, min_size, s0, grid) -> dict[int, tuple]:  # noqa: ANN001
    """The best fit with each number of knobs from ``k_first`` to ``kmax``: the first from the
    segmentation's candidates, each next one from the last plus a knot where it misses most (and,
    for the richest, from the candidates too)."""
    fits: dict[int, tuple] = {}
    proposed = _candidates(y, kmax, min_size) if k_first < kmax else []
    prev = None
    for k in range(k_first, kmax + 1):
        if k == 0:
            starts = [np.zeros(0)]
        elif prev is None:
            starts = [x[idx] for idx in _candidates(y, k, min_size)] or \
                     [np.quantile(x, np.arange(1, k + 1) / (k + 1))]
        else:
            starts = [np.sort(np.append(prev[1], _worst_place(x, y, sw, z, x0, prev[1], prev[0])))]
            if k == kmax:
                starts += [x[idx] for idx in proposed]
        prev = min((_place(x, y, sw, z, x0, st, s0, grid) for st in starts), key=lambda got: got[3])
        fits[k] = prev
    return fits


def _make(x, y, sw, z, x0, coef, knots, u, dev, scale, tau) -> Piecewise:  # noqa: ANN001
    n_eff = float(np.sum(sw ** 2)) / max(tau, 1.0)
    k = knots.size
    m = z.shape[1]
    bic = dev / max(tau, 1.0) + (2 + 2 * k + m) * math.log(max(n_eff, 2.0))
    return Piecewise(knots=tuple(float(t) for t in knots), coef=np.asarray(coef, float), x0=x0,
                     scale=float(scale), tau=float(tau), deviance=float(dev), bic=float(bic), n_eff=n_eff,
                     data=(x, y, sw, z, u))


def profile(fit: Piecewise, j: int, at: np.ndarray) -> np.ndarray:
    """Deviance rise (over ``tau``) with knot ``j`` held at each of ``at``, the others held where
    they are and every linear coefficient refitted (the robust weights of the fit held)."""
    x, y, sw, z, u = fit.data
    kn = np.asarray(fit.knots, float)
    w = sw ** 2 * u
    rss = _scan(x, y, w, z, fit.x0, kn, j, np.asarray(at, float))
    here = _scan(x, y, w, z, fit.x0, kn, j, np.array([kn[j]]))[0]
    return (rss - here) / fit.scale ** 2 / max(fit.tau, 1.0)


def knot_interval(fit: Piecewise, j: int, chi2: float, *, resolution: float | None = None) -> tuple[float, float]:
    """Profile-likelihood interval of knot ``j`` (see :func:`profile`): where the rise stays under
    ``chi2``, read on a grid of ``resolution`` (default a tenth of the points' spacing, capped at
    2000 positions); ``-inf``/``inf`` where the data end first."""
    x = fit.data[0]
    lo_x, hi_x = float(x[0]), float(x[-1])
    span = hi_x - lo_x
    step = resolution or max(0.1 * span / max(x.size - 1, 1), span / 2000.0, 1e-9)
    grid = np.arange(lo_x, hi_x + 0.5 * step, step)
    rise = profile(fit, j, grid)
    t = fit.knots[j]
    i0 = int(np.clip(np.searchsorted(grid, t), 0, grid.size - 1))
    out = []
    for sign in (-1, 1):
        i = i0
        while 0 <= i + sign < grid.size and rise[i + sign] <= chi2:
            i += sign
        if not 0 <= i + sign < grid.size:
            out.append(-math.inf if sign < 0 else math.inf)
            continue
        a, b = rise[i], rise[i + sign]
        f = (chi2 - a) / (b - a) if b != a else 0.0
        out.append(float(grid[i] + sign * f * step))
    lo, hi = out
    return min(lo, t), max(hi, t)
