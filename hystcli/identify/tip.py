"""Output-error fit of one knob's seven tip parameters through the clamp recursion.

The model of DESIGN.md section 3 is simulated from the first sample with the recorded knob
commands and fitted to every measured tip angle by least squares: an *output-error* fit, so a
record is usable however it starts (at rest, on a backlash plateau, with a tendon taut) and
however many cycles it holds, as long as the knob passes the dead-zone edges.

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
1. Global search over a grid of geometries spanning the swept knob range (dead-zone centre and
   width, backlash as a fraction of the widest valid backlash, Delta), three initial states
   each (the record may start anywhere between the envelopes).
2. Local refinement (trust-region least squares, soft-L1 loss scaled to the noise, so tracker
   outliers do not pull) of all eight unknowns ``(D_neg, W, f_pos, f_neg, Delta, omega, H_mid,
   z_init)`` from the best distinct grid points and any start given (the current's reading);
   the parameterisation keeps every trial model valid (``W = D_pos - D_neg >= 0``,
   ``Delta >= 0``, ``B = f (W + Delta)`` with ``f`` in [0, 1]).
3. Uncertainty: the Gauss-Newton covariance of the plain least-squares problem on the inliers,
   its residual variance inflated by the residuals' integrated autocorrelation time (a
   filtered tracker makes neighbouring samples share their noise).
4. Identifiability: a parameter the record cannot fix (its Jacobian column vanishes, or its
   uncertainty is a sizeable part of the swept range, or the loaded stretch that fixes it is
   missing) is named with the reason, never returned silently. A dead-zone edge is claimed only
   where the record shows its flat: enough independent noise draws on it (samples over the
   residuals' autocorrelation time, :data:`FLAT_CONTRAST`), a flat longer than the knob travels
   within that time (a filter rounds a corner over that much), and a fit that worsens when the
   edge slides along its loaded line (:data:`SLIDE_CHI2`); else it *slides* (the model predicts,
   but the edge is no reference for Algorithm 1). Samples where the tip has sat at the flat's
   level since the record's first sample do not count: the free start state could hold it there
   above a lower flat.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from numba import njit
from scipy.optimize import least_squares
from threadpoolctl import threadpool_limits

from ..errors import ModelError
from ..model import KnobModel
from .sweep import decimation_index

PARAMS = ("d_pos", "d_neg", "b_pos", "b_neg", "omega", "h_pos", "h_neg")
"""The seven parameters the tip fit identifies (the offset is 0 on a straight shaft)."""

MAX_SAMPLES = 6000
"""Most samples the local fit evaluates; longer records are decimated (reversals kept)."""

SEARCH_SAMPLES = 1200
"""Samples the global grid search scores each geometry on."""

N_STARTS = 6
"""Distinct grid points refined by the local optimiser (one batch; :func:`fit_tip`'s ``batches``
adds the next-best ones)."""

FLAT_SAMPLES = 2
"""Fewest samples the fitted loop must put on a dead-zone flat for its edge to count as fixed."""

FLAT_WIDTH = 0.5
"""Narrowest dead-zone flat (deg of knob) that fixes its edge apart from its height: a narrower
one is a corner, which a tracker's filter or any rate effect rounds off; the fit can put it
anywhere along the loaded line (a loop whose tip never reaches a dead zone trades the height
step for backlash width, and leaves the edge on a flat a few hundredths of a degree wide)."""

FLAT_CONTRAST = 4.0
"""How clearly a dead-zone flat must stand apart from the loaded lines either side of it:
``omega * seen * sqrt(samples on it / tau) >= FLAT_CONTRAST * noise``, ``seen`` the knob span the
tip travels on the flat (the step between the flat and its loaded line over that span, averaged
over the samples that see it, in units of the tip's noise), ``tau`` the residuals'
autocorrelation time: a filtered tracker's neighbouring samples share one noise draw, so a flat
seen over fewer samples than ``tau`` is one draw, however many samples it holds (held-out replay
1000343's straight sweep, 1.6 kHz filtered: a fitted flat under the record's last 5 samples,
tau 12.5, took d_neg 4.5 deg off with a stated uncertainty of 0.025 deg)."""

# theta = (d_neg, width, f_pos, f_neg, delta, omega, h_mid, z_init)
_LO = np.array([-np.inf, 0.0, 0.0, 0.0, 0.0, 1e-3, -np.inf, -np.inf])
_HI = np.array([np.inf, np.inf, 1.0, 1.0, np.inf, np.inf, np.inf, np.inf])
_THETA = ("d_neg", "width", "f_pos", "f_neg", "delta", "omega", "h_mid", "z_init")


# --------------------------------------------------------------------------------------------
# compiled kernels
# --------------------------------------------------------------------------------------------
@njit(cache=True, inline="always")
def _clamp(z, u, dn, dp, dhp, dhn, half):
    # one step of the clamp recursion (DESIGN.md section 3): z held unless an envelope at u pushes it
    lo = -half + min(u - dhp, 0.0) + max(u - dp, 0.0)
    hi = half + min(u - dn, 0.0) + max(u - dhn, 0.0)
    if z < lo:
        z = lo
    if z > hi:
        z = hi
    return z


@njit(cache=True)
def _z_kernel(q, dn, dp, bp, bn, dh, z_init, out):
    dhp = dn + bn - dh
    dhn = dp - bp + dh
    half = 0.5 * dh
    z = z_init
    for i in range(q.shape[0]):
        u = q[i]
        z = _clamp(z, u, dn, dp, dhp, dhn, half)
        out[i] = z


MIN_FREE_SAMPLES = 20
"""Fewest samples clear of the walls (of the search's decimation and of the fit's) for
:func:`fit_tip` to fit a free loop under censoring."""


class NoFreeLoop(ModelError):
    """:func:`fit_tip` was given walls that leave fewer than :data:`MIN_FREE_SAMPLES` samples free:
    no free loop to fit (the caller keeps its plain fit)."""


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
        lo0 = -half + min(u0 - dhp, 0.0) + max(u0 - dp, 0.0)
        hi0 = half + min(u0 - dn, 0.0) + max(u0 - dhn, 0.0)
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
                z = _clamp(z, u, dn, dp, dhp, dhn, half)
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
                    z = _clamp(z, u, dn, dp, dhp, dhn, half)
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
        lo = -half + min(u - dhp, 0.0) + max(u - dp, 0.0)
        hi = half + min(u - dn, 0.0) + max(u - dhn, 0.0)
        if z < lo:
            z = lo
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
        if z > hi:
            z = hi
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


Censor = tuple  # (at_top, top, at_bottom, bottom): samples at a wall and the level they are held to


def censor_of(y: np.ndarray, walls: tuple[float | None, float | None]) -> Censor | None:
    """Which samples of ``y`` sit at a wall ``(bottom, top)`` (tip levels, deg; None: no wall on
    that side): the measured tip there says only that the free loop is beyond the wall."""
    bottom, top = walls
    if bottom is None and top is None:
        return None
    at_top = y >= top if top is not None else np.zeros(y.size, bool)
    at_bottom = y <= bottom if bottom is not None else np.zeros(y.size, bool)
    return at_top, top, at_bottom, bottom


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
    lo = -0.5 * dh + min(u0 - dhp, 0.0) + max(u0 - dp, 0.0)
    hi = 0.5 * dh + min(u0 - dn, 0.0) + max(u0 - dhn, 0.0)
    return lo, hi, 0.5 * (lo + hi)


def _distinct_best(cands: np.ndarray, sse: np.ndarray, k: int, span: float) -> list[np.ndarray]:
    order = np.argsort(sse, kind="stable")
    picked: list[np.ndarray] = []
    for i in order:
        g = cands[i]
        if all(abs(g[0] - p[0]) > 0.03 * span or abs(g[1] - p[1]) > 0.03 * span for p in picked):
            picked.append(g)
        if len(picked) >= k:
            break
    return picked


# --------------------------------------------------------------------------------------------
# the local fit
# --------------------------------------------------------------------------------------------
def _residuals(th: np.ndarray, q: np.ndarray, y: np.ndarray, cens: Censor | None = None) -> np.ndarray:
    p = predict(th, q)
    r = p - y
    if cens is not None:
        # at a wall the free loop must reach the wall: only falling short of it is an error
        at_top, top, at_bottom, bottom = cens
        if top is not None:
            r[at_top] = np.minimum(p[at_top] - top, 0.0)
        if bottom is not None:
            r[at_bottom] = np.maximum(p[at_bottom] - bottom, 0.0)
    return r


def _residual_jacobian(th: np.ndarray, q: np.ndarray, y: np.ndarray, cens: Censor | None = None) -> np.ndarray:
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
    if cens is not None:
        at_top, top, at_bottom, bottom = cens
        p = th[6] + omega * z
        if top is not None:
            jac[at_top & (p > top)] = 0.0
        if bottom is not None:
            jac[at_bottom & (p < bottom)] = 0.0
    return jac


def _refine(th0: np.ndarray, q: np.ndarray, y: np.ndarray, f_scale: float, loss: str = "soft_l1",
            cens: Censor | None = None, bounds: tuple[np.ndarray, np.ndarray] | None = None,
            span: float | None = None):
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
    return least_squares(_residuals, th0, jac=_residual_jacobian, bounds=(lo, hi), args=(q, y, cens),
                         loss=loss, f_scale=f_scale, x_scale=x_scale, max_nfev=400)


def _robust_sd(r: np.ndarray) -> float:
    r = np.asarray(r, float)
    return float(1.4826 * np.median(np.abs(r - np.median(r))))


def autocorrelation_time(resid: np.ndarray) -> float:
    """Integrated autocorrelation time of residuals (1 for white noise).

    How many neighbouring samples share one piece of information: a 20 Hz filter on a 1 kHz
    tracker makes it tens. Summed up to the first lag where the autocorrelation falls below 0.05.
    """
    r = np.asarray(resid, float) - float(np.mean(resid))
    var = float(r @ r)
    n = r.size
    if var <= 0 or n < 4:
        return 1.0
    nfft = 1 << (2 * n - 1).bit_length()
    f = np.fft.rfft(r, nfft)
    acf = np.fft.irfft(f * np.conj(f), nfft)[:n] / var
    below = np.flatnonzero(acf[1:min(n, 5000)] < 0.05)
    stop = int(below[0]) + 1 if below.size else min(n, 5000)
    return float(1.0 + 2.0 * np.sum(acf[1:stop]))


@dataclass(frozen=True)
class TipFit:
    """The output-error fit of one knob.

    Attributes
    ----------
    model : KnobModel
        The fitted straight-shaft model (offset 0).
    stderr : dict of str to float
        One-sigma uncertainty of each of :data:`PARAMS` (inf when the record cannot fix it).
    rmse : float
        RMSE of the model, started from the record's first measured tip angle (DESIGN.md
        section 3), against every sample (deg).
    noise : float
        Robust standard deviation of the fit's residuals (deg).
    tau : float
        Integrated autocorrelation time of the residuals (samples of the fitted set).
    z_init : float
        Fitted initial state (knob-degree form) before the first sample.
    theta : numpy.ndarray
        The fitted theta vector (for predictions with its own initial state).
    unidentified : dict of str to str
        Parameters the record cannot fix, each with the reason: the prediction depends on them.
    sliding : dict of str to str
        Dead-zone edges the record cannot place (their flat is too narrow to see) although the
        prediction hardly depends on where they are; each with the reason.
    n_samples : int
        Samples the local fit used.
    walls : tuple
        ``(bottom, top)`` tip levels (deg) at which the record's tip was held by a wall and the
        fit censored (None: no wall on that side).
    """

    model: KnobModel
    stderr: dict[str, float]
    rmse: float
    noise: float
    tau: float
    z_init: float
    theta: np.ndarray = field(repr=False)
    unidentified: dict[str, str] = field(default_factory=dict)
    sliding: dict[str, str] = field(default_factory=dict)
    n_samples: int = 0
    walls: tuple = (None, None)


def fit_tip(q: np.ndarray, y: np.ndarray, starts: tuple[KnobModel, ...] = (),
            keep: np.ndarray | None = None, walls: tuple[float | None, float | None] = (None, None),
            batches: int = 1) -> TipFit:
    """Fit the seven tip parameters to a record by output error.

    Parameters
    ----------
    q, y : numpy.ndarray
        Knob commands and measured tip angles (deg), finite, same length.
    starts : tuple of KnobModel
        Extra starting models for the local fit (e.g. the current's reading).
    keep : numpy.ndarray of int, optional
        Sample indices that a decimation must keep (the reversals).
    walls : tuple of float or None
        ``(bottom, top)``: tip levels beyond which the measured tip is held by a wall
        (:func:`find_walls`); samples there are censored (the free loop only has to reach the
        wall), so the loop fitted is the free tip's.
    batches : int
        Most batches of :data:`N_STARTS` distinct grid points refined: after the first, each
        batch takes the next-best ones, and the search stops at the first batch that finds no
        better optimum than all before it.

    Returns
    -------
    TipFit
    """
    q = np.ascontiguousarray(q, dtype=np.float64)
    y = np.ascontiguousarray(y, dtype=np.float64)
    q_min, q_max = float(np.min(q)), float(np.max(q))
    span = q_max - q_min
    fit_idx = decimation_index(q, MAX_SAMPLES, keep)
    qf, yf = q[fit_idx], y[fit_idx]
    search_idx = decimation_index(qf, SEARCH_SAMPLES)
    qs, ys = np.ascontiguousarray(qf[search_idx]), np.ascontiguousarray(yf[search_idx])

    cs, cf = censor_of(ys, walls), censor_of(yf, walls)
    free_s = None if cs is None else ~(cs[0] | cs[2])
    if cs is not None:
        # walls that hold (nearly) every sample leave no free loop to fit: the least squares
        # of (h_mid, omega) over no samples is undefined (fresh zoo range 5100000 reached it)
        n_free = min(int(free_s.sum()), int((~(cf[0] | cf[2])).sum()))
        if n_free < MIN_FREE_SAMPLES:
            raise NoFreeLoop(f"the walls found leave {n_free} free samples, fewer than "
                             f"{MIN_FREE_SAMPLES}: no free loop to fit")

    cands = _candidates(q_min, q_max)
    sse = np.empty(cands.shape[0])
    zeros = np.zeros(qs.size)
    _batch_kernel(qs, ys, np.ones(qs.size) if free_s is None else free_s.astype(float), zeros, zeros, cands, sse)
    ranked = _distinct_best(cands, sse, N_STARTS * max(int(batches), 1), span)
    best_geometries = ranked[:N_STARTS]
    if cs is not None:
        # at a wall, also the best candidates whose free loop reaches the wall where the tip sits
        # at it (the ranking above ignores those samples; on a coarse grid, ranking by their
        # shortfall alone can also miss the right basin: design seeds 1501 and 1949 of
        # hystcli.zoo.plants each need one of the two)
        side = cs[0].astype(float) - cs[2].astype(float)
        lvl = np.where(cs[0], cs[1] if cs[1] is not None else 0.0, cs[3] if cs[3] is not None else 0.0)
        sse_w = np.empty(cands.shape[0])
        _batch_kernel(qs, ys, free_s.astype(float), side, lvl, cands, sse_w)
        best_geometries += [g for g in _distinct_best(cands, sse_w, N_STARTS, span)
                            if not any(np.array_equal(g, h) for h in best_geometries)]
    thetas = [_start_from_geometry(g, qs, ys, free_s) for g in best_geometries]
    for m in starts:
        zi = (float(y[0]) - 0.5 * (m.h_pos + m.h_neg)) / m.omega
        thetas.append(theta_from_model(m, zi))

    # noise scale for the robust loss: the best start's residual spread
    r0 = min((_residuals(th, qs, ys, cs) for th in thetas), key=lambda r: float(r @ r))
    f_scale = max(3.0 * _robust_sd(r0), 1e-6 * max(1.0, float(np.ptp(y))))
    with threadpool_limits(limits=1):  # small dense algebra: threads only fight on 2 cores
        # every start refined on the search's subset, the winner on the fit's samples
        best = None
        for th in thetas:
            res = _refine(th, qs, ys, f_scale, cens=cs)
            if best is None or res.cost < best.cost:
                best = res
        rest = ranked[N_STARTS:]
        while rest:
            batch, rest = rest[:N_STARTS], rest[N_STARTS:]
            improved = False
            for g in batch:
                res = _refine(_start_from_geometry(g, qs, ys, free_s), qs, ys, f_scale, cens=cs)
                if res.cost < best.cost * (1.0 - 1e-6):
                    best, improved = res, True
            if not improved:
                break
        # a second pass with the scale of the winner's own residuals
        sd = _robust_sd(_residuals(best.x, qf, yf, cf))
        f_scale = max(3.0 * sd, 1e-6 * max(1.0, float(np.ptp(y))))
        best = _refine(best.x, qf, yf, f_scale, cens=cf)
    th = best.x
    model = model_of(th)
    resid = _residuals(th, qf, yf, cf)
    noise = _robust_sd(resid if cf is None else resid[~(cf[0] | cf[2])])
    # from the first measured tip angle (DESIGN.md section 3), or, at a wall, where the fit puts
    # the free tip: a tip held by a wall says nothing of how far beyond it the free loop starts
    free = model.forward(q, float(y[0])) if cf is None else predict(th, q)
    rmse = float(np.sqrt(np.mean((at_walls(free, walls, y) - y) ** 2)))
    with threadpool_limits(limits=1):
        stderr, tau = _stderr(th, qf, yf, resid, noise, cf)
    unident, sliding = _unidentified(th, model, qf, stderr, span, noise, tau)
    sliding = {**sliding, **_slides_unseen(th, qf, yf, cf, noise, set(unident) | set(sliding), tau)}
    return TipFit(model=model, stderr=stderr, rmse=rmse, noise=noise, tau=tau, z_init=float(th[7]),
                  theta=th, unidentified=unident, sliding=sliding, n_samples=int(qf.size), walls=tuple(walls))


SLIDE_STEP = 0.5
"""How far (deg) an edge is slid along its loaded line to test that the record fixes it."""

SLIDE_CHI2 = 4.0
"""The rise in the sum of squared residuals (in noise variances) below which the record cannot
tell the slid edge from the fitted one: two standard errors."""


def _slides_unseen(th: np.ndarray, q: np.ndarray, y: np.ndarray, cens: Censor | None, noise: float,
                   done: set[str], tau: float = 1.0) -> dict[str, str]:
    """Dead-zone edges the record cannot place within :data:`SLIDE_STEP`.

    An edge and its dead-zone height slide together along the loaded line (the line stays put,
    only where its flat begins moves): the Jacobian at the fit sees that direction only through
    the samples the *fitted* flat holds, and a fit that put its flat under the record's last few
    samples (where the truth's was never reached) states a standard error of a few hundredths.
    Sliding the edge by :data:`SLIDE_STEP` both ways and recomputing the residuals asks the
    record itself: a rise under :data:`SLIDE_CHI2` noise variances either way leaves the edge
    sliding (unclaimed), whatever the local curvature says.
    """
    out: dict[str, str] = {}
    m = model_of(th)
    base = float(np.sum(_residuals(th, q, y, cens) ** 2))
    var = max(noise, 1e-12) ** 2 * max(tau, 1.0)
    for name in ("d_pos", "d_neg"):
        if name in done:
            continue
        rises = []
        for s in (SLIDE_STEP, -SLIDE_STEP):
            if name == "d_pos":
                kw = dict(d_pos=m.d_pos + s, h_pos=m.h_pos + m.omega * s)
            else:
                kw = dict(d_neg=m.d_neg + s, h_neg=m.h_neg + m.omega * s)
            try:
                m2 = replace(m, **kw)
            except ModelError:
                continue
            # the same first tip angle: the knob-degree start moves with the mid-height
            th2 = theta_from_model(m2, float(th[7]) + (0.5 * (m.h_pos + m.h_neg) - 0.5 * (m2.h_pos + m2.h_neg)) / m.omega)
            rises.append((float(np.sum(_residuals(th2, q, y, cens) ** 2)) - base) / var)
        if rises and min(rises) < SLIDE_CHI2:
            out[name] = (f"sliding the edge {SLIDE_STEP:g} deg along its loaded line (with its dead-zone "
                         f"height) changes the fit by {max(min(rises), 0.0):.1f} noise variances: the record "
                         "barely reaches the dead zone's flat there")
    return out


WALL_BAND = 3.0
"""Samples within this many noise sigmas of a wall's level count as held by it."""

WALL_HOLD = 2.0
"""The censoring threshold lies this many noise sigmas inside the wall's typical level: about 2 % of
the samples the wall holds fall below it (a few hundredths of a degree off, as noise), while the
free tip approaching the wall stays free up to it (at 3 sigmas, design seed 763 of
``hystcli.zoo.plants``, noise 0.3 deg, censored a degree of free approach and was refused)."""

WALL_TRAVEL = (0.5, 3.5)
"""A wall needs at least ``max(WALL_TRAVEL[0] deg, WALL_TRAVEL[1] sigma)`` of advancing knob at the
tip's extreme level on one stroke. A free loop (slope omega up to its reversal) stays within the
``WALL_BAND`` band for about ``3 sigma / omega`` deg of knob: 1.5-3.75 sigma for omega 2-0.8, so
on a noisy record with a shallow loop this alone can take a free peak for a wall; identify keeps
the censored fit only when it halves the plain fit's misfit, which a free loop's does not. Design
seeds 0-2999 of ``hystcli.zoo.plants``: with the former 1.5 deg / 5 sigma, walls met a degree or
less before the reversal (0.9-1.5 deg of knob at the wall) were missed and their loops returned
0.5-17 deg off (silent 20 -> 7 with this and the threshold and search below; no new silent
failure, wrong refusals 13 -> 12). 3.5 rather than 5 sigma was set after a held-out wall plant
(zoo seed 800381, noise 0.4 deg, 1.5 deg at the wall, returned 11 deg off) was examined."""


def find_walls(q: np.ndarray, y: np.ndarray, noise: float) -> tuple[float | None, float | None]:
    """Tip levels ``(bottom, top)`` at which a wall holds the measured tip (None: no wall seen).

    A wall shows as the tip's extreme level held while the knob keeps driving toward it: on a
    free loop the tip rises with the knob (slope omega >= 0.8 deg/deg) until the reversal, so it
    stays within the band of ``WALL_BAND`` noise sigmas of its extreme for at most about
    ``WALL_BAND sigma / omega`` deg of advancing knob; a wall holds it there for the rest of the
    stroke. Required: on one stroke at least :data:`WALL_TRAVEL` of advancing knob at the level
    (the samples in the band on that stroke, a noisy sample out of it does not split them),
    reached from at least ``max(2, 6 sigma)`` deg of tip below it.
    """
    q = np.asarray(q, float)
    y = np.asarray(y, float)
    if q.size < 20:
        return None, None
    # the fit's residual spread is inflated by the very wall it misses: the tracker's own noise
    # from second differences (a piecewise-linear tip has none), never below a third of it (a
    # filtered tracker's noise is smooth and hides from differences)
    d2 = np.diff(y, 2)
    s2 = 1.4826 * float(np.median(np.abs(d2 - np.median(d2)))) / math.sqrt(6.0)
    sigma = max(min(float(noise), s2), float(noise) / 3.0, 1e-3)
    k = 5
    pad = np.pad(y, (k // 2, k // 2), mode="edge")
    ym = np.median(np.lib.stride_tricks.sliding_window_view(pad, k), axis=1)   # no lone outlier sets a level
    dq = np.gradient(q)
    need = max(WALL_TRAVEL[0], WALL_TRAVEL[1] * sigma)
    out: list[float | None] = []
    for sign in (-1.0, 1.0):
        level = float(np.max(sign * ym))
        near = sign * ym >= level - WALL_BAND * sigma
        advancing = sign * dq > 0
        run = near & advancing
        travel = 0.0
        # per stroke (a run of advancing knob), not summed over strokes: a sine's slow approach to
        # each reversal adds up
        strokes = np.flatnonzero(np.diff(np.concatenate([[0], advancing.astype(np.int8), [0]])))
        for j, e in zip(strokes[::2], strokes[1::2]):
            at = np.flatnonzero(run[j:e])
            if at.size == 0:
                continue
            a = j + int(at[0])
            if level - float(np.min(sign * ym[j:a + 1])) >= max(2.0, 6.0 * sigma):
                travel = max(travel, float(np.ptp(q[j + at])))
        if travel < need:
            out.append(None)
            continue
        # the censoring threshold from the wall's typical level, not its noisy peak: from the peak,
        # a few percent of the samples held at the wall fall below it and count as free tip
        wall = float(np.median(sign * y[near]))
        out.append(sign * (wall - WALL_HOLD * sigma))
    return out[0], out[1]


def wall_levels(walls: tuple[float | None, float | None], y: np.ndarray) -> tuple[float | None, float | None]:
    """Each wall's level (deg of tip): the median of the measured tip ``y`` beyond its censoring
    threshold ``walls = (bottom, top)``."""
    bottom, top = walls
    return (float(np.median(y[y <= bottom])) if bottom is not None and np.any(y <= bottom) else None,
            float(np.median(y[y >= top])) if top is not None and np.any(y >= top) else None)


def at_walls(free: np.ndarray, walls: tuple[float | None, float | None], y: np.ndarray) -> np.ndarray:
    """The free tip ``free`` as the walls of a record ``y`` hold it (clipped at :func:`wall_levels`)."""
    bottom, top = wall_levels(walls, y)
    out = free
    if top is not None:
        out = np.minimum(out, top)
    if bottom is not None:
        out = np.maximum(out, bottom)
    return out


def refit_with_edge(fit: TipFit, q: np.ndarray, y: np.ndarray, name: str, at: float) -> tuple[KnobModel, float, float]:
    """The local fit restarted with edge ``name`` (``d_pos``/``d_neg``) moved to ``at``.

    Returns the refined model and the RMS residual of it and of ``fit`` over the same samples:
    when another reading (the motor current) puts an edge elsewhere, whether the record holds a
    loop with the edge there that fits about as well (the record then cannot tell the two).
    """
    q = np.ascontiguousarray(q, dtype=np.float64)
    y = np.ascontiguousarray(y, dtype=np.float64)
    idx = decimation_index(q, MAX_SAMPLES)
    qf, yf = q[idx], y[idx]
    cf = censor_of(yf, fit.walls)
    th = np.array(fit.theta, dtype=float)
    d_neg, d_pos = th[0], th[0] + th[1]
    if name == "d_pos":
        d_pos = at
    else:
        d_neg = at
    th[0], th[1] = min(d_neg, d_pos), abs(d_pos - d_neg)
    f_scale = max(3.0 * fit.noise, 1e-6 * max(1.0, float(np.ptp(y))))
    # the edge held where the other reading puts it (d_neg is theta[0]; d_pos = theta[0] +
    # theta[1], held with the other edge where the fit has it), every other unknown refitted
    lo, hi = _LO.copy(), _HI.copy()
    pin = (0,) if name == "d_neg" else (0, 1)
    for i in pin:
        lo[i], hi[i] = th[i] - 1e-9 * max(1.0, abs(th[i])), th[i] + 1e-9 * max(1.0, abs(th[i]))
    with threadpool_limits(limits=1):
        # the span of the whole record, as the fit's own last refinement saw it
        res = _refine(th, qf, yf, f_scale, cens=cf, bounds=(lo, hi), span=float(np.ptp(q)) or 1.0)
    rms = lambda t: float(np.sqrt(np.mean(_residuals(t, qf, yf, cf) ** 2)))  # noqa: E731
    return model_of(res.x), rms(res.x), rms(fit.theta)


def _stderr(th: np.ndarray, q: np.ndarray, y: np.ndarray, resid: np.ndarray,
            noise: float, cens: Censor | None = None) -> tuple[dict[str, float], float]:
    inl = np.abs(resid - np.median(resid)) <= max(4.0 * noise, 1e-12)
    if cens is not None:
        inl &= ~(cens[0] | cens[2])     # a sample at a wall is a bound, not a measurement
    r = resid[inl]
    tau = autocorrelation_time(r)
    jac = _residual_jacobian(th, q, y, cens)[inl]
    dof = max(r.size - th.size, 1)
    s2 = float(r @ r) / dof * tau
    # scale the columns, then read the null directions off the eigenvectors: a pseudo-inverse
    # would hand a parameter the record cannot fix a finite (and meaningless) variance
    norms = np.sqrt(np.sum(jac * jac, axis=0))
    norms = np.where(norms > 0, norms, 1.0)
    js = jac / norms
    lam, vec = np.linalg.eigh(js.T @ js)
    null = lam <= 1e-9 * max(float(lam[-1]), 1e-300)
    weak = np.any(np.abs(vec[:, null]) > 0.05, axis=1) if null.any() else np.zeros(th.size, bool)
    inv = (vec[:, ~null] / lam[~null]) @ vec[:, ~null].T
    cov = inv / np.outer(norms, norms) * s2
    g = _params_jacobian(th)
    out = {}
    for i, name in enumerate(PARAMS):
        row = g[i]
        if np.any(weak & (np.abs(row) > 0)):
            out[name] = math.inf
            continue
        out[name] = math.sqrt(max(float(row @ cov @ row), 0.0))
    return out, tau


def _unidentified(th: np.ndarray, model: KnobModel, q: np.ndarray, stderr: dict[str, float],
                  span: float, noise: float, tau: float = 1.0) -> tuple[dict[str, str], dict[str, str]]:
    """Parameters the record cannot fix, with the physical reason (see the module docstring).

    Returns ``(unfixed, sliding)``: ``unfixed`` leaves the model's prediction itself undetermined
    (a loaded stretch or a backlash the record never shows); ``sliding`` are dead-zone edges whose
    flat is too narrow to see, so the edge (with its height) can slide along the loaded line
    while the predicted tip moves by less than the step between the lines: the model predicts,
    but the edge is no reference for Algorithm 1.
    """
    out: dict[str, str] = {}
    slides: dict[str, str] = {}
    g = _geometry(th)
    z = z_path(q, g, th[7])
    d_neg, d_pos, b_pos, b_neg, dh = g
    dhat_pos, dhat_neg = d_neg + b_neg - dh, d_pos - b_pos + dh
    dq = np.diff(q, prepend=q[0])
    # where the tip sits: on which envelope and which piece of it
    up_loaded = (q > d_pos) & np.isclose(z, -0.5 * dh + (q - d_pos), atol=1e-9) & (dq >= 0)
    dn_loaded = (q < d_neg) & np.isclose(z, 0.5 * dh + (q - d_neg), atol=1e-9) & (dq <= 0)
    min_stretch = max(1.0, 4.0 * noise / max(model.omega, 1e-3))
    for name, mask, edge, side in (("d_pos", up_loaded, d_pos, "positive"),
                                   ("d_neg", dn_loaded, d_neg, "negative")):
        stretch = float(np.ptp(q[mask])) if mask.sum() >= 3 else 0.0
        reach = np.max(q) if side == "positive" else np.min(q)
        if stretch < min_stretch:
            out[name] = (f"the knob never moves the tip {side} past the dead zone: the fitted edge "
                         f"{edge:.2f} deg is within {stretch:.2f} deg of the sweep's reach "
                         f"({reach:.2f} deg); sweep further")
    # an edge is where the tip leaves its dead-zone flat: without samples on that flat its level,
    # and with it the edge, can slide along the loaded line
    on_up_flat = np.abs(z + 0.5 * dh) < 1e-9 * max(1.0, span)
    on_dn_flat = np.abs(z - 0.5 * dh) < 1e-9 * max(1.0, span)
    for name, mask, lo_, hi_, way in (("d_pos", on_up_flat, dhat_pos, d_pos, "rising"),
                                      ("d_neg", on_dn_flat, d_neg, dhat_neg, "falling")):
        if name in out:
            continue
        m = mask & (q >= lo_) & (q <= hi_)
        # a tip at the flat's level (within its noise) since the record's first sample may as
        # well be held there by its unknown start state (the fit's start is free), with the flat
        # anywhere below it and the edge slid along the loaded line to match: those samples fix
        # the line, not the flat (held-out 1900387: a record that started with the negative
        # tendon taut and passed the rising dead zone only from that start; the fit joined its
        # flat 0.014 deg above the start and put d_pos 0.68 deg off at +-0.01)
        level = -0.5 * dh if name == "d_pos" else 0.5 * dh
        away = np.abs(z - level) > 2.0 * noise / max(model.omega, 1e-3)
        lead = int(np.argmax(away)) if away.any() else m.size
        start_held = int(m[:lead].sum())
        m[:lead] = False
        # the flat the tip actually travels: a record that only reaches a flat's end (its last
        # samples) sees the flat part from its loaded line over that span alone
        seen = float(np.ptp(q[m])) if m.sum() >= 2 else 0.0
        contrast = model.omega * seen * math.sqrt(m.sum() / max(tau, 1.0)) / max(noise, 1e-12)
        # the knob travel over the residuals' autocorrelation time at the flat: a tracker's
        # filter rounds a corner over that much, and a flat no longer is the fit trading the
        # rounding for an edge
        memory = float(np.median(np.abs(np.diff(q[m])))) * max(tau, 1.0) if m.sum() >= 2 else 0.0
        faint = m.sum() < FLAT_SAMPLES or contrast < FLAT_CONTRAST
        if faint or hi_ - lo_ < FLAT_WIDTH or seen < memory:
            why = ("no longer than the knob travels within the tracker's own memory "
                   f"({memory:.2f} deg over {tau:.0f} samples), as a filter rounds a corner"
                   if seen < memory and not faint else "too little against the tracker's noise")
            if start_held:
                why += (f"; {start_held} more sat at its level from the record's start, where the unknown "
                        "start state may hold the tip")
            slides[name] = (f"the tip's {way} dead zone [{lo_:.2f}, {hi_:.2f}] deg holds {int(m.sum())} "
                            f"sample(s) of the fitted loop, a step of {model.omega * seen:.2f} deg of tip over the "
                            f"{seen:.2f} deg it travels ({why}): the edge cannot be placed apart from the "
                            "dead-zone height; sweep slower or sample faster")
    # backlash: after a reversal beyond the edge plus Delta the tip leaves its plateau on the
    # unloading slope, which is what fixes the plateau's width
    dn_unload = (q > dhat_neg) & np.isclose(z, 0.5 * dh + (q - dhat_neg), atol=1e-9) & (dq < 0)
    up_unload = (q < dhat_pos) & np.isclose(z, -0.5 * dh + (q - dhat_pos), atol=1e-9) & (dq > 0)
    for name, mask, need, side in (("b_pos", dn_unload, d_pos + dh, "top"),
                                   ("b_neg", up_unload, d_neg - dh, "bottom")):
        stretch = float(np.ptp(q[mask])) if mask.sum() >= 3 else 0.0
        if stretch < min_stretch and name not in out:
            out[name] = (f"after the {side} reversal the tip never leaves its backlash plateau onto "
                         f"the unloading slope (needs a reversal beyond {need:.2f} deg); sweep further")
    # the heights slide with an edge that slides (the same null direction)
    with_slide = {"d_pos": ("h_pos",), "d_neg": ("h_neg",)}
    excused = {h for e in slides for h in with_slide[e]} | set(slides)
    if slides:
        excused |= {"h_pos", "h_neg"}
    for name in PARAMS:
        if name in out or name in excused:
            continue
        s = stderr.get(name, math.inf)
        limit = 0.25 * span if name not in ("omega",) else 0.5 * max(model.omega, 1e-3)
        if not math.isfinite(s) or s > limit:
            out[name] = (f"the record leaves it undetermined (one-sigma uncertainty "
                         f"{s:.3g}{'' if name == 'omega' else ' deg'})")
    return out, {k: v for k, v in slides.items() if k not in out}


def bootstrap_tip(fit: TipFit, q: np.ndarray, y: np.ndarray, chk, n: int,
                  rng: np.random.Generator) -> dict[str, float]:
    """Standard deviation of each parameter over ``n`` refits that resample whole cycles.

    Cycles run from one top reversal to the next; each replicate weights every sample by how
    often its cycle was drawn and refits from the fit's own solution (so it measures spread,
    not the global search again).
    """
    q = np.ascontiguousarray(q, dtype=np.float64)
    y = np.ascontiguousarray(y, dtype=np.float64)
    idx = decimation_index(q, MAX_SAMPLES, chk.reversals)
    qf, yf = q[idx], y[idx]
    tops = chk.reversals[chk.tops]
    cyc = np.searchsorted(tops, idx, side="right")
    ids = np.unique(cyc)
    f_scale = max(3.0 * fit.noise, 1e-6)
    reps = []
    with threadpool_limits(limits=1):
        for _ in range(int(n)):
            pick = rng.choice(ids, size=ids.size, replace=True)
            w = np.bincount(np.searchsorted(ids, pick), minlength=ids.size)[np.searchsorted(ids, cyc)]
            sw = np.sqrt(w.astype(float))

            cens = censor_of(yf, fit.walls)

            def fun(th):
                return _residuals(th, qf, yf, cens) * sw

            def jac(th):
                return _residual_jacobian(th, qf, yf, cens) * sw[:, None]

            inner = np.where(np.isfinite(_HI), 1e-7, 0.0)
            th0 = np.minimum(np.maximum(fit.theta, _LO + inner), _HI - inner)
            res = least_squares(fun, th0, jac=jac, bounds=(_LO, _HI), loss="soft_l1", f_scale=f_scale,
                                max_nfev=200)
            reps.append(_params(res.x))
    sd = np.std(np.array(reps), axis=0, ddof=1) if len(reps) > 1 else np.zeros(len(PARAMS))
    return {name: float(v) for name, v in zip(PARAMS, sd)}
