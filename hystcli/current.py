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

from .filters import lowpass

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
             resolution: float | None = None) -> Kink | None:
    """Best continuous two-line fit (with a quadratic term after the kink when ``curved``).

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
    ata = np.einsum("gni,gnj->gij", a, a)
    atc = np.einsum("gni,n->gi", a, c)
    p = a.shape[-1]
    det_ok = np.linalg.cond(ata) < 1e12
    if not det_ok.any():
        return None
    beta = np.zeros((grid.size, p))
    beta[det_ok] = np.linalg.solve(ata[det_ok], atc[det_ok][..., None])[..., 0]
    resid = c[None, :] - np.einsum("gni,gi->gn", a, beta)
    sse = np.where(det_ok, np.einsum("gn,gn->g", resid, resid), np.inf)
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
        se_s1 = math.inf
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
