"""Conditioning a motor current before it is read, and the motor's cogging ripple.

* :func:`condition`: one-sample outliers out (a running median over 5 samples) before the
  paper's 20 Hz low-pass, so a logging spike does not become a bump the width of the filter;
* :func:`robust_noise`: the sample-to-sample noise of a current;
* :class:`Ripple` and :func:`find_ripple`: the cogging ripple, periodic in the knob angle and the
  same whichever way the knob turns, a nuisance term taken into a reading only where BIC says the
  record shows it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..filters import lowpass

__all__ = ["DESPIKE_SAMPLES", "Ripple", "condition", "find_ripple", "robust_noise"]

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
class Ripple:
    """A cogging ripple: the motor's torque ripple, periodic in its shaft angle and so in the knob's.

    ``ripple(q) = sin * sin(2 pi q / period) + cos * cos(2 pi q / period)`` (current unit).

    Attributes
    ----------
    period : float
        Period in knob angle (deg).
    sin, cos : float
        Amplitudes of the two phases.
    """

    period: float
    sin: float
    cos: float

    @property
    def amplitude(self) -> float:
        """Half the peak-to-peak ripple."""
        return math.hypot(self.sin, self.cos)

    def __call__(self, q):  # noqa: ANN001, ANN204 - float or array in, the same out
        w = 2.0 * math.pi * np.asarray(q, float) / self.period
        out = self.sin * np.sin(w) + self.cos * np.cos(w)
        return float(out) if np.ndim(out) == 0 else out


def _rss_grid(q: np.ndarray, r: np.ndarray, wt: np.ndarray, periods: np.ndarray,
              chunk: int = 64) -> tuple[np.ndarray, np.ndarray]:
    """Weighted residual sum of squares of ``r`` after a sinusoid of each period (and the two
    amplitudes of the best), one 2x2 solve per period."""
    out = np.empty(periods.size)
    amps = np.empty((periods.size, 2))
    r0 = float(np.sum(wt * r * r))
    for a in range(0, periods.size, chunk):
        w = (2.0 * math.pi) * q[:, None] / periods[None, a:a + chunk]
        s, co = np.sin(w), np.cos(w)
        ss = np.einsum("i,ij,ij->j", wt, s, s)
        cc = np.einsum("i,ij,ij->j", wt, co, co)
        sc = np.einsum("i,ij,ij->j", wt, s, co)
        sr = (wt * r) @ s
        cr = (wt * r) @ co
        det = ss * cc - sc * sc
        ok = det > 1e-12 * ss * cc
        with np.errstate(divide="ignore", invalid="ignore"):
            a_s = np.where(ok, (cc * sr - sc * cr) / det, 0.0)
            a_c = np.where(ok, (ss * cr - sc * sr) / det, 0.0)
        out[a:a + chunk] = r0 - (a_s * sr + a_c * cr)
        amps[a:a + chunk, 0], amps[a:a + chunk, 1] = a_s, a_c
    return out, amps


def find_ripple(q: np.ndarray, resid: np.ndarray, weight: np.ndarray, *, scale: float, tau: float,
                shortest: float, n_periods: int = 400) -> Ripple | None:
    """The cogging ripple in the residuals of a reading, or None where BIC does not take it.

    The residuals of every stretch's broken-line fit, pooled against the knob angle, are searched
    for one sinusoid over a log grid of periods from ``shortest`` to half their span. The ripple
    costs three parameters (period and two amplitudes); it is taken when it lowers the BIC of the
    pooled residuals, the deviance and the sample count both at the effective sample size
    (``tau``), as the broken lines' own pieces are chosen.

    Parameters
    ----------
    q : numpy.ndarray
        Knob angle of each residual (deg).
    resid, weight : numpy.ndarray
        Residuals (current unit) and their weights (effective independent samples behind each).
    scale : float
        Noise scale of a point of weight 1.
    tau : float
        Autocorrelation time of the residuals (points).
    shortest : float
        Shortest period searched (deg): a shorter wave is averaged away within one reading.
    """
    q = np.asarray(q, float)
    r = np.asarray(resid, float)
    wt = np.asarray(weight, float)
    span = float(np.ptp(q)) if q.size else 0.0
    lo, hi = max(shortest, 1e-6), 0.5 * span
    if q.size < 30 or not hi > lo or not scale > 0:
        return None
    grid = np.geomspace(lo, hi, n_periods)
    rss, amps = _rss_grid(q, r, wt, grid)
    i = int(np.argmin(rss))
    fine = np.geomspace(grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)], 41)
    rss_f, amps_f = _rss_grid(q, r, wt, fine)
    j = int(np.argmin(rss_f))
    gain = (float(np.sum(wt * r * r)) - float(rss_f[j])) / scale ** 2 / max(tau, 1.0)
    n_eff = float(np.sum(wt)) / max(tau, 1.0)
    if gain <= 3.0 * math.log(max(n_eff, 2.0)):
        return None
    return Ripple(float(fine[j]), float(amps_f[j, 0]), float(amps_f[j, 1]))
