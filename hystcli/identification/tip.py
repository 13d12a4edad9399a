"""Output-error fit of one knob's seven tip parameters through the clamp recursion.

The model of the method (the dead-zone + backlash loop) is simulated from the first sample with
the recorded knob commands and fitted to every measured tip angle by least squares: an
*output-error* fit, so a record is usable however it starts (at rest, on a backlash plateau, with
a tendon taut) and however many cycles it holds.

Knob-degree form
----------------
With :math:`\\Delta = (H_{neg} - H_{pos})/\\omega` and :math:`H_{mid} = (H_{pos}+H_{neg})/2`,
both envelopes are :math:`H_{mid} + \\omega\\, z(u)` where the *geometry*
``g = (D_neg, D_pos, B_pos, B_neg, Delta)`` (all in degrees of knob) fixes ``z``::

    z_up(u) = -Delta/2 + min(u - Dhat_pos, 0) + max(u - D_pos, 0),   Dhat_pos = D_neg + B_neg - Delta
    z_dn(u) = +Delta/2 + min(u - D_neg, 0) + max(u - Dhat_neg, 0),   Dhat_neg = D_pos - B_pos + Delta

and because :math:`\\omega > 0` the clamp recursion commutes with that affine map:
:math:`y_t = H_{mid} + \\omega z_t`, :math:`z_t = \\min(\\max(z_{t-1}, z_{up}), z_{dn})`. So for a
given geometry the tip is *linear* in :math:`(H_{mid}, \\omega)`: the global search scores tens
of thousands of geometries with a two-parameter linear least squares each (variable
projection), in one compiled loop, before any local optimiser runs.

Fit
---
1. Global search over a grid of geometries spanning the swept knob range, three initial states
   each (the record may start anywhere between the envelopes).
2. Local refinement (trust-region least squares, soft-L1 loss scaled to the noise, so tracker
   outliers do not pull) of all eight unknowns ``(D_neg, W, f_pos, f_neg, Delta, omega, H_mid,
   z_init)`` from the best distinct grid points and any start given; the parameterisation keeps
   every trial model valid (``W = D_pos - D_neg >= 0``, ``Delta >= 0``, ``B = f (W + Delta)``
   with ``f`` in [0, 1]).
3. Walls: a tip held by a wall while the knob drives on is the loop clipped at a level
   (``min(loop, top)``, ``max(loop, bottom)``), each level one more parameter; the loop with a
   wall on neither, either or both sides is chosen by BIC at the residuals' effective sample
   size (:func:`fit_tip`).

What the record fixes of each parameter is :mod:`.intervals`' business (profile likelihood).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit
from scipy.optimize import least_squares
from threadpoolctl import threadpool_limits

from ..core import kernel
from ..core.params import KnobModel
from ..signal.pwl import autocorrelation_time
from ..signal.stretches import decimation_index

PARAMS = ("d_pos", "d_neg", "b_pos", "b_neg", "omega", "h_pos", "h_neg")
"""The seven parameters the tip fit identifies (the offset is 0 on a straight shaft)."""

MAX_SAMPLES = 2500
"""Most samples the local fit evaluates; longer records are decimated (reversals kept)."""

SEARCH_SAMPLES = 1200
"""Samples the global grid search scores each geometry on."""

N_STARTS = 10
"""Distinct grid points refined by the local optimiser (a computation budget)."""

# theta = (d_neg, width, f_pos, f_neg, delta, omega, h_mid, z_init)
_LO = np.array([-np.inf, 0.0, 0.0, 0.0, 0.0, 1e-3, -np.inf, -np.inf])
_HI = np.array([np.inf, np.inf, 1.0, 1.0, np.inf, np.inf, np.inf, np.inf])


# --------------------------------------------------------------------------------------------
# compiled kernels
# --------------------------------------------------------------------------------------------
@njit(cache=True)
def _z_kernel(q, dn, dp, bp, bn, dh, z_init, out):
    dhp = dn + bn - dh
    dhn = dp - bp + dh
    half = 0.5 * dh
    z = z_init
    for i in range(q.shape[0]):
        u = q[i]
        z = kernel.unit_step(z, u, dn, dp, dhp, dhn, half)
        out[i] = z



#BATCH
@njit(cache=True)
def _batch_kernel(q, y, wt, side, lvl, cands, out):
    # SSE after the best (h_mid, omega >= 1e-3) of every candidate geometry, best of three
    # initial states (at the ascending envelope, the descending one, midway); sample weights
    # wt are 1, or 0 for a sample at a wall (censored: the recursion runs through it, the fit
    # does not see it). With side[i] +1 (held at a top wall) or -1 (a bottom one), the squared
    # shortfall of the candidate's free tip from the wall's censoring level lvl[i] is added
    # (the wall says the free loop reaches it; (h_mid, omega) stay the free samples' least
    # squares); side all zero: the plain SSE.
    n = 0.0
    syy = 0.0
    sy = 0.0
    walls = False
    for i in range(q.shape[0]):
        n += wt[i]
        sy += wt[i] * y[i]
        syy += wt[i] * y[i] * y[i]
        if side[i] != 0.0:
            walls = True
    for m in range(cands.shape[0]):
        dn = cands[m, 0]
        dp = cands[m, 1]
        bp = cands[m, 2]
        bn = cands[m, 3]
        dh = cands[m, 4]
        dhp = dn + bn - dh
        dhn = dp - bp + dh
        half = 0.5 * dh
        u0 = q[0]
        lo0, hi0 = kernel.unit_envelopes(u0, dn, dp, dhp, dhn, half)
        best = 1e300
        for s in range(3):
            if s == 0:
                z0 = lo0
            elif s == 1:
                z0 = hi0
            else:
                z0 = 0.5 * (lo0 + hi0)
            z = z0
            sz = 0.0
            szz = 0.0
            szy = 0.0
            for i in range(q.shape[0]):
                u = q[i]
                z = kernel.unit_step(z, u, dn, dp, dhp, dhn, half)
                sz += wt[i] * z
                szz += wt[i] * z * z
                szy += wt[i] * z * y[i]
            den = n * szz - sz * sz
            if den > 1e-12 * n * n:
                w = (n * szy - sz * sy) / den
            else:
                w = 1e-3
            if w < 1e-3:
                w = 1e-3
            a = (sy - w * sz) / n
            sse = syy - 2.0 * a * sy - 2.0 * w * szy + n * a * a + 2.0 * a * w * sz + w * w * szz
            if walls and sse < best:
                z = z0
                for i in range(q.shape[0]):
                    u = q[i]
                    z = kernel.unit_step(z, u, dn, dp, dhp, dhn, half)
                    if side[i] != 0.0:
                        short = side[i] * (lvl[i] - (a + w * z))
                        if short > 0.0:
                            sse += short * short
            if sse < best:
                best = sse
        out[m] = best


@njit(cache=True)
def _z_jac_kernel(q, dn, w, fp, fn, dh, z_init, z_out, jac):
    # z and its exact derivatives with respect to (d_neg, width, f_pos, f_neg, delta, z_init):
    # a clamped sample takes the derivative of the envelope that clamps it, a held one keeps the
    # previous sample's (forward-mode sensitivities through the recursion)
    s = w + dh
    bn = fn * s
    bp = fp * s
    dp = dn + w
    dhp = dn + bn - dh
    dhn = dp - bp + dh
    half = 0.5 * dh
    z = z_init
    g0 = 0.0
    g1 = 0.0
    g2 = 0.0
    g3 = 0.0
    g4 = 0.0
    g5 = 1.0
    for i in range(q.shape[0]):
        u = q[i]
        lo, hi = kernel.unit_envelopes(u, dn, dp, dhp, dhn, half)
        # the derivative of kernel.clamp: the envelope that binds (the descending one where
        # both do, as the clamp's order has it) gives its derivative, a held sample keeps its own
        zl = lo if z < lo else z
        if z < lo:
            # d lo = -d(dh)/2 - [u < dhp] d(dhp) - [u > dp] d(dp)
            g0 = 0.0
            g1 = 0.0
            g2 = 0.0
            g3 = 0.0
            g4 = -0.5
            if u < dhp:      # d(dhp) = (1, fn, 0, s, fn - 1)
                g0 -= 1.0
                g1 -= fn
                g3 -= s
                g4 -= fn - 1.0
            if u > dp:       # d(dp) = (1, 1, 0, 0, 0)
                g0 -= 1.0
                g1 -= 1.0
            g5 = 0.0
        if zl > hi:
            # d hi = d(dh)/2 - [u < dn] d(dn) - [u > dhn] d(dhn)
            g0 = 0.0
            g1 = 0.0
            g2 = 0.0
            g3 = 0.0
            g4 = 0.5
            if u < dn:       # d(dn) = (1, 0, 0, 0, 0)
                g0 -= 1.0
            if u > dhn:      # d(dhn) = (1, 1 - fp, -s, 0, 1 - fp)
                g0 -= 1.0
                g1 -= 1.0 - fp
                g2 += s
                g4 -= 1.0 - fp
            g5 = 0.0
        z = kernel.clamp(z, lo, hi)
        z_out[i] = z
        jac[i, 0] = g0
        jac[i, 1] = g1
        jac[i, 2] = g2
        jac[i, 3] = g3
        jac[i, 4] = g4
        jac[i, 5] = g5


def z_path(q: np.ndarray, geometry, z_init: float) -> np.ndarray:
    """``z`` of the knob-degree form for geometry ``(d_neg, d_pos, b_pos, b_neg, delta)``."""
    out = np.empty(q.size)
    _z_kernel(np.ascontiguousarray(q, dtype=np.float64), *map(float, geometry), float(z_init), out)
    return out


# --------------------------------------------------------------------------------------------
# parameterisation
# --------------------------------------------------------------------------------------------
def _geometry(th: np.ndarray) -> tuple[float, float, float, float, float]:
    d_neg, w, f_pos, f_neg, dh = th[:5]
    span = w + dh
    return d_neg, d_neg + w, f_pos * span, f_neg * span, dh


def _params(th: np.ndarray) -> np.ndarray:
    """The seven model parameters (:data:`PARAMS` order) of a theta vector."""
    d_neg, d_pos, b_pos, b_neg, dh = _geometry(th)
    omega, h_mid = th[5], th[6]
    return np.array([d_pos, d_neg, b_pos, b_neg, omega, h_mid - 0.5 * omega * dh, h_mid + 0.5 * omega * dh])


def _params_jacobian(th: np.ndarray) -> np.ndarray:
    """d(params)/d(theta), (7, 8): carries the covariance from theta to the model's parameters."""
    d_neg, w, f_pos, f_neg, dh, omega, h_mid, _ = th
    span = w + dh
    g = np.zeros((7, 8))
    g[0, 0] = 1.0
    g[0, 1] = 1.0                      # d_pos = d_neg + w
    g[1, 0] = 1.0                      # d_neg
    g[2, 1] = f_pos
    g[2, 2] = span
    g[2, 4] = f_pos                    # b_pos = f_pos (w + dh)
    g[3, 1] = f_neg
    g[3, 3] = span
    g[3, 4] = f_neg                    # b_neg
    g[4, 5] = 1.0                      # omega
    g[5, 4] = -0.5 * omega
    g[5, 5] = -0.5 * dh
    g[5, 6] = 1.0                      # h_pos = h_mid - omega dh / 2
    g[6, 4] = 0.5 * omega
    g[6, 5] = 0.5 * dh
    g[6, 6] = 1.0                      # h_neg
    return g


def theta_from_model(m: KnobModel, z_init: float) -> np.ndarray:
    """A theta vector (clipped into the valid box) for a start given as a model."""
    w = max(m.d_pos - m.d_neg, 0.0)
    dh = max((m.h_neg - m.h_pos) / m.omega, 0.0)
    span = max(w + dh, 1e-9)
    return np.array([m.d_neg, w, min(m.b_pos / span, 1.0), min(m.b_neg / span, 1.0), dh,
                     m.omega, 0.5 * (m.h_pos + m.h_neg), z_init])


def model_of(th: np.ndarray) -> KnobModel:
    return KnobModel(**dict(zip(PARAMS, map(float, _params(th)))))


def predict(th: np.ndarray, q: np.ndarray) -> np.ndarray:
    """The tip the theta vector predicts on ``q`` (its own initial state)."""
    return th[6] + th[5] * z_path(q, _geometry(th), th[7])


# --------------------------------------------------------------------------------------------
# the global search
# --------------------------------------------------------------------------------------------
def _candidates(q_min: float, q_max: float) -> np.ndarray:
    span = q_max - q_min
    centres = np.linspace(q_min + 0.04 * span, q_max - 0.04 * span, 17)
    widths = np.concatenate([[0.0], np.geomspace(0.015 * span, 0.9 * span, 12)])
    fracs = np.array([0.0, 0.15, 0.35, 0.6, 1.0])
    deltas = np.array([0.0, 0.04, 0.12, 0.3]) * span
    c, w, dh, fp, fn = (a.ravel() for a in np.meshgrid(centres, widths, deltas, fracs, fracs, indexing="ij"))
    dn, dp = c - 0.5 * w, c + 0.5 * w
    ok = (dn >= q_min) & (dp <= q_max)
    s = w + dh
    return np.column_stack([dn, dp, fp * s, fn * s, dh])[ok]


def _linear_part(z: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    a = np.column_stack([np.ones_like(z), z])
    (h_mid, omega), *_ = np.linalg.lstsq(a, y, rcond=None)
    return float(h_mid), float(max(omega, 1e-3))


def _start_from_geometry(g, q: np.ndarray, y: np.ndarray, free: np.ndarray | None = None) -> np.ndarray:
    dn, dp, bp, bn, dh = map(float, g)
    span = max(dp - dn + dh, 1e-9)
    best = None
    for zi in _initial_states(q[0], g):
        z = z_path(q, g, zi)
        zf, yf = (z, y) if free is None else (z[free], y[free])
        h_mid, omega = _linear_part(zf, yf)
        sse = float(np.sum((yf - h_mid - omega * zf) ** 2))
        if best is None or sse < best[0]:
            best = (sse, np.array([dn, dp - dn, min(bp / span, 1.0), min(bn / span, 1.0), dh,
                                   omega, h_mid, zi]))
    return best[1]


def _initial_states(u0: float, g) -> tuple[float, float, float]:
    dn, dp, bp, bn, dh = map(float, g)
    dhp, dhn = dn + bn - dh, dp - bp + dh
    lo, hi = kernel.unit_envelopes.py_func(u0, dn, dp, dhp, dhn, 0.5 * dh)  # -(0.5 dh) is -0.5 dh exactly
    return lo, hi, 0.5 * (lo + hi)


def _distinct_best(cands: np.ndarray, sse: np.ndarray, k: int, span: float) -> list[np.ndarray]:
    """The ``k`` best geometries that differ from each other in an edge or a backlash by more than
    3 % of the span: distinct starts, so that loops that fit about as well are each refined."""
    order = np.argsort(sse, kind="stable")
    picked: list[np.ndarray] = []
    for i in order:
        g = cands[i]
        if all(np.max(np.abs(g[:4] - p[:4])) > 0.03 * span for p in picked):
            picked.append(g)
        if len(picked) >= k:
            break
    return picked


# --------------------------------------------------------------------------------------------
# the local fit
# --------------------------------------------------------------------------------------------
def _residuals(th: np.ndarray, q: np.ndarray, y: np.ndarray) -> np.ndarray:
    return predict(th, q) - y


def _residual_jacobian(th: np.ndarray, q: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Exact d(residual)/d(theta), (n, 8), from the recursion's sensitivities."""
    z = np.empty(q.size)
    jz = np.empty((q.size, 6))
    _z_jac_kernel(q, *map(float, th[:5]), float(th[7]), z, jz)
    omega = th[5]
    jac = np.empty((q.size, 8))
    jac[:, :5] = omega * jz[:, :5]
    jac[:, 5] = z
    jac[:, 6] = 1.0
    jac[:, 7] = omega * jz[:, 5]
    return jac


def _refine(th0: np.ndarray, q: np.ndarray, y: np.ndarray, f_scale: float, loss: str = "soft_l1",
            bounds: tuple[np.ndarray, np.ndarray] | None = None, span: float | None = None):
    """Trust-region least squares from ``th0``: within the valid box (started just inside it), or
    within ``bounds`` (some unknowns pinned); ``span`` (deg) scales the knob-angle unknowns
    (default the ``q`` given)."""
    if bounds is None:
        inner = np.where(np.isfinite(_HI), 1e-7, 0.0)
        lo, hi = _LO, _HI
        th0 = np.minimum(np.maximum(np.asarray(th0, float), _LO + inner), _HI - inner)
    else:
        lo, hi = bounds
        th0 = np.minimum(np.maximum(np.asarray(th0, float), lo), hi)
    span = (float(np.ptp(q)) or 1.0) if span is None else span
    x_scale = np.array([0.05 * span, 0.05 * span, 0.05, 0.05, 0.05 * span, 0.1,
                        max(1.0, f_scale), 0.05 * span])
    return least_squares(_residuals, th0, jac=_residual_jacobian, bounds=(lo, hi), args=(q, y),
                         loss=loss, f_scale=f_scale, x_scale=x_scale, max_nfev=400)


def _robust_sd(r: np.ndarray) -> float:
    r = np.asarray(r, float)
    return float(1.4826 * np.median(np.abs(r - np.median(r))))


# --------------------------------------------------------------------------------------------
# walls: the loop clipped at a level
# --------------------------------------------------------------------------------------------
def _clip(p: np.ndarray, q: np.ndarray, sides: tuple[bool, bool]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The loop of ``p[:8]`` clipped at the wall levels that follow (bottom, then top, where
    ``sides`` has them): (prediction, held at the bottom, held at the top)."""
    pred = predict(p[:8], q)
    i = 8
    low = np.zeros(q.size, bool)
    high = np.zeros(q.size, bool)
    if sides[0]:
        low = pred < p[i]
        pred = np.maximum(pred, p[i])
        i += 1
    if sides[1]:
        high = pred > p[i]
        pred = np.minimum(pred, p[i])
    return pred, low, high


def _clip_residuals(p: np.ndarray, q: np.ndarray, y: np.ndarray, sides: tuple[bool, bool]) -> np.ndarray:
    return _clip(p, q, sides)[0] - y


def _clip_jacobian(p: np.ndarray, q: np.ndarray, y: np.ndarray, sides: tuple[bool, bool]) -> np.ndarray:
    _, low, high = _clip(p, q, sides)
    jac = np.zeros((q.size, p.size))
    jac[:, :8] = _residual_jacobian(p[:8], q, y)
    held = low | high
    jac[held, :8] = 0.0
    i = 8
    if sides[0]:
        jac[low, i] = 1.0
        i += 1
    if sides[1]:
        jac[high, i] = 1.0
    return jac


@dataclass(frozen=True)
class LoopFit:
    """One least-squares optimum of the (possibly clipped) loop on a record.

    Attributes
    ----------
    p : numpy.ndarray
        ``theta`` (8) and the wall levels of ``sides`` (bottom, top).
    sides : tuple of bool
        Which walls the fit has (bottom, top).
    deviance : float
        Robust deviance ``2 cost / noise^2`` on the fitted samples.
    """

    p: np.ndarray = field(repr=False)
    sides: tuple[bool, bool]
    deviance: float

    @property
    def theta(self) -> np.ndarray:
        return self.p[:8]

    @property
    def walls(self) -> tuple[float | None, float | None]:
        """Tip levels (bottom, top) of the walls, None where there is none."""
        i = 8
        out: list[float | None] = []
        for s in self.sides:
            if s:
                out.append(float(self.p[i]))
                i += 1
            else:
                out.append(None)
        return out[0], out[1]

    def predict(self, q: np.ndarray) -> np.ndarray:
        return _clip(self.p, np.ascontiguousarray(q, dtype=np.float64), self.sides)[0]


def refine_clipped(p0: np.ndarray, q: np.ndarray, y: np.ndarray, sides: tuple[bool, bool], f_scale: float,
                   noise: float, bounds: tuple[np.ndarray, np.ndarray] | None = None,
                   penalty=None, max_nfev: int = 400) -> LoopFit:  # noqa: ANN001
    """Least squares of the clipped loop from ``p0``; ``penalty`` (a pair of functions: extra
    residuals and their Jacobian rows) holds a derived parameter where the profile puts it."""
    nw = int(sides[0]) + int(sides[1])
    lo = np.concatenate([_LO, np.full(nw, -np.inf)]) if bounds is None else bounds[0]
    hi = np.concatenate([_HI, np.full(nw, np.inf)]) if bounds is None else bounds[1]
    inner = np.where(np.isfinite(hi) & np.isfinite(lo), 1e-7, 0.0)
    p0 = np.minimum(np.maximum(np.asarray(p0, float), lo + inner), hi - inner)
    span = float(np.ptp(q)) or 1.0
    x_scale = np.concatenate([[0.05 * span, 0.05 * span, 0.05, 0.05, 0.05 * span, 0.1, max(1.0, f_scale),
                               0.05 * span], np.full(nw, max(1.0, f_scale))])
    if penalty is None:
        fun, jac = _clip_residuals, _clip_jacobian
    else:
        extra, extra_jac = penalty

        def fun(p, q, y, sides):  # noqa: ANN001, ANN202
            return np.concatenate([_clip_residuals(p, q, y, sides), extra(p)])

        def jac(p, q, y, sides):  # noqa: ANN001, ANN202
            return np.vstack([_clip_jacobian(p, q, y, sides), extra_jac(p)])
    with threadpool_limits(limits=1):   # small dense algebra: threads only fight on 2 cores
        res = least_squares(fun, p0, jac=jac, bounds=(lo, hi), args=(q, y, sides), loss="soft_l1",
                            f_scale=f_scale, x_scale=x_scale, max_nfev=max_nfev)
    r = _clip_residuals(res.x, q, y, sides)
    dev = float(np.sum(2.0 * (np.sqrt(1.0 + (r / f_scale) ** 2) - 1.0))) * f_scale ** 2 / max(noise, 1e-12) ** 2
    return LoopFit(p=res.x, sides=sides, deviance=dev)


# --------------------------------------------------------------------------------------------
# the fit
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class TipFit:
    """The output-error fit of one knob.

    Attributes
    ----------
    model : KnobModel
        The fitted straight-shaft model (offset 0).
    loop : LoopFit
        The optimum (theta, wall levels).
    rmse : float
        RMSE of the fit (its own initial state, walls as fitted) against every sample (deg).
    noise : float
        Robust standard deviation of the fit's residuals (deg).
    tau : float
        Integrated autocorrelation time of the residuals (samples of the fitted set).
    f_scale : float
        Scale of the soft-L1 loss (deg).
    q, y : numpy.ndarray
        The samples fitted (decimated, reversals kept).
    bic : float
        BIC of the chosen loop (walls included) at the effective sample size.
    walls : tuple
        ``(bottom, top)`` tip levels (deg) of the walls the fit clips the loop at (None: none).
    grid : tuple
        ``(geometries, sse, qs, ys)``: every geometry the global search scored and its sum of squares
        on the search's samples ``qs, ys`` (:mod:`.intervals` reads distant optima off it).
    alternatives : tuple of numpy.ndarray
        The theta of every local optimum the starts reached (the chosen one among them).
    """

    model: KnobModel
    loop: LoopFit = field(repr=False)
    rmse: float
    noise: float
    tau: float
    f_scale: float
    q: np.ndarray = field(repr=False)
    y: np.ndarray = field(repr=False)
    bic: float = math.nan
    walls: tuple = (None, None)
    grid: tuple = field(default=(), repr=False)
    alternatives: tuple = field(default=(), repr=False)

    @property
    def theta(self) -> np.ndarray:
        return self.loop.theta

    @property
    def z_init(self) -> float:
        return float(self.loop.theta[7])


def _bic(dev: float, tau: float, n: int, k: int) -> float:
    return dev / max(tau, 1.0) + k * math.log(max(n / max(tau, 1.0), 2.0))


def _scored(qs: np.ndarray, ys: np.ndarray, wt: np.ndarray | None = None, side: np.ndarray | None = None,
            lvl: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Every geometry of the grid and its best sum of squares on ``qs, ys``."""
    cands = _candidates(float(np.min(qs)), float(np.max(qs)))
    sse = np.empty(cands.shape[0])
    zeros = np.zeros(qs.size)
    _batch_kernel(qs, ys, np.ones(qs.size) if wt is None else wt, zeros if side is None else side,
                  zeros if lvl is None else lvl, cands, sse)
    return cands, sse


def _search(qs: np.ndarray, ys: np.ndarray, k: int, span: float, wt: np.ndarray | None = None,
            side: np.ndarray | None = None, lvl: np.ndarray | None = None) -> list[np.ndarray]:
    cands, sse = _scored(qs, ys, wt, side, lvl)
    return _distinct_best(cands, sse, k, span)


def _wall_starts(qs: np.ndarray, ys: np.ndarray, sides: tuple[bool, bool], noise: float,
                 span: float) -> list[np.ndarray]:
    """Starting loops for a fit with walls: the grid search with the samples beyond each wall's
    starting level censored (their shortfall from the level scored instead)."""
    lo0 = float(np.quantile(ys, 0.02)) + 2.0 * noise
    hi0 = float(np.quantile(ys, 0.98)) - 2.0 * noise
    at_lo = (ys <= lo0) if sides[0] else np.zeros(ys.size, bool)
    at_hi = (ys >= hi0) if sides[1] else np.zeros(ys.size, bool)
    free = ~(at_lo | at_hi)
    if free.sum() < 20:
        return []
    side = at_hi.astype(float) - at_lo.astype(float)
    lvl = np.where(at_hi, hi0, np.where(at_lo, lo0, 0.0))
    levels = ([lo0] if sides[0] else []) + ([hi0] if sides[1] else [])
    out = []
    for g in _search(qs, ys, 2, span, free.astype(float), side, lvl):
        th = _start_from_geometry(g, qs, ys, free)
        out.append(np.concatenate([th, levels]))
    return out


def _fit_walls(best: LoopFit, qs, ys, qf, yf, sides, f_scale, noise, span) -> LoopFit:  # noqa: ANN001
    """The loop clipped by walls on ``sides``, from the plain fit and from a censored search."""
    levels = ([float(np.min(yf))] if sides[0] else []) + ([float(np.max(yf))] if sides[1] else [])
    cands = [np.concatenate([best.p[:8], levels])] + _wall_starts(qs, ys, sides, noise, span)
    fits = [refine_clipped(p, qs, ys, sides, f_scale, noise) for p in cands]
    return refine_clipped(min(fits, key=lambda f: f.deviance).p, qf, yf, sides, f_scale, noise)


def fit_tip(q: np.ndarray, y: np.ndarray, starts: tuple[KnobModel, ...] = (),
            keep: np.ndarray | None = None, walls: bool = True) -> TipFit:
    """Fit the seven tip parameters to a record by output error.

    Parameters
    ----------
    q, y : numpy.ndarray
        Knob commands and measured tip angles (deg), finite, same length.
    starts : tuple of KnobModel
        Extra starting models for the local fit.
    keep : numpy.ndarray of int, optional
        Sample indices that a decimation must keep (the reversals).
    walls : bool
        Also fit the loop clipped by a wall on either or both sides, and keep the one BIC
        prefers.

    Returns
    -------
    TipFit
    """
    q = np.ascontiguousarray(q, dtype=np.float64)
    y = np.ascontiguousarray(y, dtype=np.float64)
    span = float(np.ptp(q))
    fit_idx = decimation_index(q, MAX_SAMPLES, keep)
    qf, yf = q[fit_idx], y[fit_idx]
    search_idx = decimation_index(qf, SEARCH_SAMPLES)
    qs, ys = np.ascontiguousarray(qf[search_idx]), np.ascontiguousarray(yf[search_idx])

    grid_cands, grid_sse = _scored(qs, ys)
    thetas = [_start_from_geometry(g, qs, ys) for g in _distinct_best(grid_cands, grid_sse, N_STARTS, span)]
    for m in starts:
        zi = (float(y[0]) - 0.5 * (m.h_pos + m.h_neg)) / m.omega
        thetas.append(theta_from_model(m, zi))
    r0 = min((_residuals(th, qs, ys) for th in thetas), key=lambda r: float(r @ r))
    f_scale = max(3.0 * _robust_sd(r0), 1e-6 * max(1.0, float(np.ptp(y))))
    noise = f_scale / 3.0
    plain = (False, False)
    refined = [refine_clipped(th, qs, ys, plain, f_scale, noise) for th in thetas]
    best = min(refined, key=lambda f: f.deviance)
    # the winner on the fit's samples, at the scale of its own residuals
    sd = _robust_sd(_clip_residuals(best.p, qf, yf, plain))
    f_scale = max(3.0 * sd, 1e-6 * max(1.0, float(np.ptp(y))))
    noise = max(sd, 1e-9)
    best = refine_clipped(best.p, qf, yf, plain, f_scale, noise)
    tau = autocorrelation_time(_clip_residuals(best.p, qf, yf, plain))
    chosen = best
    chosen_bic = _bic(best.deviance, tau, qf.size, 8)
    if walls:
        # a wall on one side, then (when both single walls beat the plain loop) on both
        improved = []
        for sides in ((False, True), (True, False), (True, True)):
            if sides == (True, True) and len(improved) < 2:
                break
            got = _fit_walls(best, qs, ys, qf, yf, sides, f_scale, noise, span)
            b = _bic(got.deviance, tau, qf.size, 8 + int(sides[0]) + int(sides[1]))
            if b < _bic(best.deviance, tau, qf.size, 8):
                improved.append(sides)
            if b < chosen_bic:
                chosen, chosen_bic = got, b
    model = model_of(chosen.theta)
    resid = _clip_residuals(chosen.p, qf, yf, chosen.sides)
    rmse = float(np.sqrt(np.mean((chosen.predict(q) - y) ** 2)))
    return TipFit(model=model, loop=chosen, rmse=rmse, noise=float(_robust_sd(resid)), tau=float(tau),
                  f_scale=float(f_scale), q=qf, y=yf, bic=float(chosen_bic), walls=chosen.walls,
                  grid=(grid_cands, grid_sse, qs, ys), alternatives=tuple(f.theta for f in refined))


def systematic_misfit(resid: np.ndarray, fs: float, tau: float, noise: float, level: float) -> tuple[float, bool]:
    """The residuals averaged over quarter seconds (RMS, deg) and whether they depart from zero
    by more than the tracker's noise explains: a chi-square test at ``level`` of the window means
    against their variance ``noise^2 tau / m`` (``m`` samples a window, ``tau`` the residuals'
    autocorrelation time)."""
    from scipy.stats import chi2

    w = max(3, int(round(0.25 * fs)))
    r = np.asarray(resid, float)
    if r.size <= w:
        return float(np.sqrt(np.mean(r ** 2))), False
    k = r.size // w
    means = r[:k * w].reshape(k, w).mean(axis=1)
    rms = float(np.sqrt(np.mean(means ** 2)))
    var = noise ** 2 * min(max(tau, 1.0), w) / w
    return rms, bool(float(np.sum(means ** 2)) / max(var, 1e-300) > chi2.ppf(level, k))
