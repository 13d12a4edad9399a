"""Identification of a catheter's straight-shaft hysteresis model from a sweep (``hyst identify``).

This module owns DESIGN.md sections 3-4 seen from the data side: it checks that a recorded sweep
can identify anything (:func:`check_sweep`), reads the dead-zone edges :math:`D_{pos}, D_{neg}` and
the backlash widths :math:`B_{pos}, B_{neg}` from where the motor-current slope changes, and, when
the tip angle ``y`` was measured, fits all seven parameters (:math:`D_{pos}, D_{neg}, B_{pos},
B_{neg}, \\omega, H_{pos}, H_{neg}`) through the forward model by least squares. It also measures
what Algorithm 1 needs to run with no thresholds given (the current-slope levels inside and
outside the dead zone, :class:`~hystcli.model.KnobIdentification`), and draws the measured loop
against the fitted model like Fig. 4 of the paper (:func:`plot_identification`).

The current signature read here (see :mod:`hystcli.twin`) : along each monotone branch of the
sweep, measured as travel ``s`` from the reversal that starts it, the current is a continuous
piecewise-linear function of four pieces::

    [0, s1]    backlash: steep change of 2 mu |T| while the sheath friction changes sign (s1 = B)
    [s1, s2]   the taut tendon unloads, slope k_load (1 - mu)
    [s2, s3]   dead zone: no tendon taut, flat
    [s3, end]  the other tendon loads, slope k_load (1 + mu)

so an ascending branch (from the bottom reversal) gives B_neg = s1, D_neg = q0 + s2,
D_pos = q0 + s3, and a descending one B_pos = s1, D_pos = q0 - s2, D_neg = q0 - s3.
"""
from __future__ import annotations

import io as _io
import math
from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np
from numba import njit
from scipy.optimize import OptimizeResult, least_squares

from ..errors import IdentificationError, ModelError
from ..filters import lowpass
from ..io import Run, atomic_write
from ..model import PAPER_OMEGA, KnobIdentification, KnobModel, Model

MIN_SAMPLES = 100
"""Fewest samples of a sweep :func:`check_sweep` accepts."""

BIN_DEG = 0.5
"""Knob-angle bin (deg) the current of one branch is averaged on before its pieces are fitted."""

MAX_BRANCHES = 24
"""Most branches per direction whose current is fitted; a longer sweep uses an evenly spread subset."""

MAX_TIP_SAMPLES = 6_000
"""Most samples the tip fit evaluates; longer runs are decimated (reversal points always kept)."""

TIP_F_SCALE = 1.0
"""Soft-L1 scale of the tip fit (deg): residuals below it count as squares, above it linearly."""

# Travel right after a reversal that is dropped from the current fits (deg): there the motor's
# Coulomb friction flips sign, a step the piecewise-linear signature does not contain.
_SKIP_AFTER_REVERSAL = 0.2
# Shortest piece of a branch that counts as "reached" (deg of knob).
_MIN_PIECE = 1.0
# Travel before the far reversal over which the current must still climb (deg).
_END_WINDOW = 5.0


# --------------------------------------------------------------------------------------------
# results
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class BranchFit:
    """The four-piece current fit of one monotone branch between two reversals.

    Attributes
    ----------
    start, stop : int
        Sample indices of the reversals that bound the branch.
    direction : int
        +1 ascending (starts at a bottom reversal), -1 descending.
    q_start, q_stop : float
        Knob angle at the two reversals (deg).
    breaks : tuple of float
        ``(s1, s2, s3)``: travel from ``q_start`` (deg) where the backlash, unloading and dead-zone
        pieces end.
    slopes : tuple of float
        ``dC/dq`` of the four pieces (current unit per deg of knob, sign of the knob axis).
    noise : float
        Robust standard deviation of the binned current about the fit.
    near_ok, far_ok : bool
        Whether the piece after the backlash (near end) and the loading piece past the dead zone
        (far end) were really reached (long enough, sloped like a taut tendon).
    end_slope : float
        ``dC/dq`` over the last degrees of travel before the far reversal.
    break_se : tuple of float
        Standard errors of ``breaks`` from the fit's Jacobian.
    curve : tuple of float
        Parameters of the fitted curve (for :meth:`current`).
    """

    start: int
    stop: int
    direction: int
    q_start: float
    q_stop: float
    breaks: tuple[float, float, float]
    slopes: tuple[float, float, float, float]
    noise: float
    near_ok: bool
    far_ok: bool
    end_slope: float = float("nan")
    break_se: tuple[float, float, float] = (float("nan"),) * 3
    curve: tuple[float, ...] = ()

    def current(self, q: np.ndarray) -> np.ndarray:
        """The fitted four-piece current at knob angles ``q`` on this branch."""
        return _pwl(self.direction * (np.asarray(q, float) - self.q_start), np.asarray(self.curve))

    @property
    def backlash(self) -> float:
        """Backlash width read on this branch: B_neg when ascending, B_pos when descending."""
        return self.breaks[0]

    @property
    def edges_se(self) -> tuple[float, float]:
        """Standard errors of :attr:`edges` from this branch's fit."""
        if self.direction > 0:
            return self.break_se[1], self.break_se[2]
        return self.break_se[2], self.break_se[1]

    @property
    def edges(self) -> tuple[float, float]:
        """``(d_neg, d_pos)`` read on this branch (deg)."""
        s2, s3 = self.breaks[1], self.breaks[2]
        if self.direction > 0:
            return self.q_start + s2, self.q_start + s3
        return self.q_start - s3, self.q_start - s2


@dataclass(frozen=True)
class KnobFit:
    """Identification of one knob.

    Attributes
    ----------
    knob : int
    model : KnobModel
        The identified straight-shaft model (offset 0).
    stderr : dict of str to float
        One-sigma uncertainty of each identified parameter (deg, or deg/deg for omega); parameters
        fixed by assumption (omega and the heights on the current-only path) are absent.
    rmse : float or None
        RMSE of the model against the measured tip angle on all samples (deg), when ``y`` exists.
    method : str
        ``"tip"`` (seven-parameter fit through the forward model) or ``"current"`` (current only).
    ident : KnobIdentification
        What ``detect-shift`` needs (current-slope levels, identified range, RMSE, stderr).
    n_reversals : int
        Reversals found in the knob command.
    n_cycles : int
        Full cycles (top-to-top) in the sweep.
    current_estimate : dict of str to float
        ``d_pos, d_neg, b_pos, b_neg`` read from the current alone (the tip fit's start).
    current_stderr : dict of str to float
        Their uncertainty (spread over branches, or bootstrap over cycles).
    branches : tuple of BranchFit
        The per-branch current fits that were used.
    bootstrap : int
        Bootstrap replicates behind ``stderr`` (0: the fit's Jacobian covariance).
    start : str
        Where the tip fit started: ``"current"`` (edges and backlash read from the current's
        four-piece signature) or ``"loop"`` (a coarse start read from the q-y loop itself, when
        the current is absent or does not show that signature); ``""`` on the current path.
    start_note : str
        Why the loop start was used (empty otherwise).
    """

    knob: int
    model: KnobModel
    stderr: dict[str, float]
    rmse: float | None
    method: str
    ident: KnobIdentification | None
    n_reversals: int
    n_cycles: int = 0
    current_estimate: dict[str, float] = field(default_factory=dict)
    current_stderr: dict[str, float] = field(default_factory=dict)
    branches: tuple[BranchFit, ...] = ()
    bootstrap: int = 0
    start: str = ""
    start_note: str = ""


@dataclass(frozen=True)
class Identification:
    """Result of :func:`identify`: one :class:`KnobFit` per knob and the assembled model."""

    fits: dict[int, KnobFit]
    model: Model


@dataclass(frozen=True)
class SweepCheck:
    """What :func:`check_sweep` learnt of one knob's command: its reversals and branches.

    Attributes
    ----------
    knob : int
    reversals : numpy.ndarray of int
        Sample indices of the reversals, in time order.
    tops : numpy.ndarray of bool
        True where the reversal is a top (the knob turns from ascending to descending).
    q_min, q_max : float
        Range of the knob command (deg).
    """

    knob: int
    reversals: np.ndarray
    tops: np.ndarray
    q_min: float
    q_max: float

    @property
    def branches(self) -> list[tuple[int, int, int]]:
        """Complete branches ``(start, stop, direction)`` between two consecutive reversals."""
        out = []
        for a, b, top in zip(self.reversals[:-1], self.reversals[1:], self.tops[:-1]):
            out.append((int(a), int(b), -1 if top else +1))
        return out

    @property
    def n_cycles(self) -> int:
        """Full cycles: pairs of complete branches (one each way)."""
        return len(self.branches) // 2


# --------------------------------------------------------------------------------------------
# reversals and sweep checks
# --------------------------------------------------------------------------------------------
@njit(cache=True)
def _reversal_kernel(q, tol, idx, top):
    # A reversal is a running extreme that the knob then leaves by more than tol in the other
    # direction; the tolerance keeps encoder jitter from counting as reversals.
    n = q.shape[0]
    count = 0
    direction = 0
    hi = 0
    lo = 0
    ext = 0
    for i in range(1, n):
        if direction == 0:
            if q[i] > q[hi]:
                hi = i
            if q[i] < q[lo]:
                lo = i
            if q[hi] - q[lo] > tol:
                if hi > lo:
                    direction = 1
                    ext = hi
                else:
                    direction = -1
                    ext = lo
        elif direction > 0:
            if q[i] > q[ext]:
                ext = i
            elif q[ext] - q[i] > tol:
                idx[count] = ext
                top[count] = True
                count += 1
                direction = -1
                ext = i
        else:
            if q[i] < q[ext]:
                ext = i
            elif q[i] - q[ext] > tol:
                idx[count] = ext
                top[count] = False
                count += 1
                direction = 1
                ext = i
    return count


def find_reversals(q: np.ndarray, tol: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Sample indices where the knob command reverses, and whether each is a top.

    Parameters
    ----------
    q : numpy.ndarray
        Knob command (deg).
    tol : float, optional
        How far (deg) the knob must come back from an extreme for it to count as a reversal.
        Default: 1 % of the range of ``q``, at least 0.25 deg.

    Returns
    -------
    (numpy.ndarray of int, numpy.ndarray of bool)
    """
    q = np.ascontiguousarray(q, dtype=np.float64)
    if tol is None:
        tol = max(0.25, 0.01 * float(np.ptp(q))) if q.size else 0.25
    idx = np.empty(max(q.size, 1), dtype=np.int64)
    top = np.empty(max(q.size, 1), dtype=np.bool_)
    n = _reversal_kernel(q, float(tol), idx, top) if q.size > 1 else 0
    return idx[:n].copy(), top[:n].copy()


def check_sweep(run: Run, knob: int, need_current: bool = True) -> SweepCheck:
    """Check that a run's sweep of one knob can identify its model before anything is fitted.

    Needs: columns ``q<k>`` and ``c<k>`` (finite), at least :data:`MIN_SAMPLES` samples, a
    current that is not constant, a knob that moves, and at least one full cycle: a reversal at
    the top and at the bottom and a complete branch (reversal to reversal) each way. Whether the
    sweep reaches past the dead zone plus the backlash on both sides is only known once the
    current is read (:func:`identify` says so then).

    With ``need_current`` False (the tip fit, which reads the loop from the measured tip angle)
    the current may be absent or flat; the tip angle ``y<k>`` is required instead and must move.

    Raises
    ------
    IdentificationError
        Naming what is missing.
    """
    where = f"{run.source}: " if run.source else ""
    qn, cn, yn = f"q{knob}", f"c{knob}", f"y{knob}"
    required = (qn, cn) if need_current else (qn, yn)
    for name in required:
        if name not in run:
            why = "" if need_current else " (the tip fit reads the loop from the tip angle)"
            raise IdentificationError(f"{where}knob {knob}: column {name!r} is missing{why} "
                                      f"(columns: {', '.join(run.columns) or 'none'})")
    n = len(run)
    if n < MIN_SAMPLES:
        raise IdentificationError(f"{where}knob {knob}: too few samples ({n}); a sweep needs at "
                                  f"least {MIN_SAMPLES}")
    names = [qn] + [nm for nm in (cn, yn) if nm in run]
    for name in names:
        if not np.all(np.isfinite(run[name])):
            row = int(np.flatnonzero(~np.isfinite(run[name]))[0])
            raise IdentificationError(f"{where}column {name!r} has a non-finite value at row {row + 1}")
    q = run[qn]
    if np.ptp(q) < 1.0:
        raise IdentificationError(f"{where}knob {knob} never moves: {qn} spans {np.ptp(q):.3g} deg")
    if need_current:
        c = run[cn]
        if np.ptp(c) <= 1e-9 * max(1.0, float(np.max(np.abs(c)))):
            raise IdentificationError(f"{where}knob {knob}: the motor current {cn} is constant ({c[0]:g}); "
                                      "it carries no dead-zone signature")
    else:
        y = run[yn]
        if np.ptp(y) <= 1e-9 * max(1.0, float(np.max(np.abs(y)))):
            raise IdentificationError(f"{where}knob {knob}: the tip angle {yn} is constant ({y[0]:g}); "
                                      "it carries no hysteresis loop to fit")
    rev, tops = find_reversals(q)
    q_min, q_max = float(np.min(q)), float(np.max(q))
    if rev.size == 0:
        raise IdentificationError(
            f"{where}knob {knob}: the sweep never reverses ({qn} goes from {q[0]:.1f} to {q[-1]:.1f} deg "
            "once); identification needs a full cycle with a reversal at each end")
    if not tops.any() or tops.all():
        end, other = ("top", "bottom") if tops.all() else ("bottom", "top")
        at = q[rev[0]]
        raise IdentificationError(
            f"{where}knob {knob}: the sweep reverses only at its {end} ({qn} = {at:.1f} deg), never at "
            f"its {other}; identification needs a full cycle with a reversal at each end")
    chk = SweepCheck(knob, rev, tops, q_min, q_max)
    dirs = {d for _, _, d in chk.branches}
    if dirs != {-1, 1}:
        missing = "ascending" if 1 not in dirs else "descending"
        raise IdentificationError(
            f"{where}knob {knob}: no complete {missing} branch (from one reversal to the next); "
            "identification needs a full cycle")
    return chk


# --------------------------------------------------------------------------------------------
# the current signature of one branch
# --------------------------------------------------------------------------------------------
@njit(cache=True)
def _segment_dp(x, v, nseg, minlen):
    # Optimal split of (x, v) into nseg independent straight lines (least squares), by dynamic
    # programming over prefix sums: exact, and cheap for the ~100-200 bins of one branch.
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
    bounds = np.zeros(nseg + 1, dtype=np.int64)
    bounds[nseg] = n
    j = n
    for k in range(nseg, 0, -1):
        j = arg[k, j]
        bounds[k - 1] = j
    return bounds


def _hinge_basis(s: np.ndarray, breaks: Sequence[float]) -> np.ndarray:
    cols = [np.ones_like(s), s] + [np.maximum(s - b, 0.0) for b in breaks]
    return np.stack(cols, axis=1)


def _pwl(s: np.ndarray, p: np.ndarray) -> np.ndarray:
    # Continuous four-piece curve: a quadratic backlash piece (the sheath friction term
    # mu |T| phi is a product of two linear ramps), then three straight pieces.
    a, m0, m1, m2, m3, g1, g2, g3, kappa = p
    b1 = g1
    b2 = b1 + g2
    b3 = b2 + g3
    s0 = np.minimum(s, b1)
    return (a + m0 * s0 + kappa * s0 * s0 + m1 * np.clip(s - b1, 0.0, g2)
            + m2 * np.clip(s - b2, 0.0, g3) + m3 * np.maximum(s - b3, 0.0))


def _bin_branch(s: np.ndarray, c: np.ndarray, width: float) -> tuple[np.ndarray, np.ndarray]:
    k = np.floor(s / width).astype(np.int64)
    cnt = np.bincount(k)
    tot = np.bincount(k, weights=c)
    keep = cnt > 0
    centres = (np.arange(cnt.size) + 0.5) * width
    return centres[keep], tot[keep] / cnt[keep]


def _fit_branch(q: np.ndarray, c: np.ndarray, start: int, stop: int, direction: int) -> BranchFit | None:
    """Fit the four-piece current signature to one branch; None when it is too short to try."""
    q0 = float(q[start])
    s = direction * (q[start:stop + 1] - q0)
    cc = c[start:stop + 1]
    keep = s >= _SKIP_AFTER_REVERSAL
    s, cc = s[keep], cc[keep]
    if s.size < 8:
        return None
    travel = float(s.max())
    width = min(BIN_DEG, travel / 40.0)
    x, v = _bin_branch(s, cc, width)
    if x.size < 12:
        return None
    minlen = max(2, int(round(0.5 / width)))
    bounds = _segment_dp(x, v, 4, minlen)
    br = [0.5 * (x[b - 1] + x[b]) for b in bounds[1:4]]
    basis = _hinge_basis(x, br)
    coef, *_ = np.linalg.lstsq(basis, v, rcond=None)
    a, m0 = coef[0], coef[1]
    m1 = m0 + coef[2]
    m2 = m1 + coef[3]
    m3 = m2 + coef[4]
    resid0 = v - basis @ coef
    scale = 1.4826 * float(np.median(np.abs(resid0 - np.median(resid0))))
    scale = max(scale, 1e-6 * max(1.0, float(np.ptp(v))))
    p0 = np.array([a, m0, m1, m2, m3, br[0], br[1] - br[0], br[2] - br[1], 0.0])
    lo = np.array([-np.inf] * 5 + [0.0, 0.0, 0.0, -np.inf])
    hi = np.array([np.inf] * 5 + [travel] * 3 + [np.inf])
    p0[5:8] = np.clip(p0[5:8], lo[5:8] + 1e-9, hi[5:8] - 1e-9)
    res = least_squares(lambda p: _pwl(x, p) - v, p0, bounds=(lo, hi), loss="soft_l1",
                        f_scale=3.0 * scale, x_scale="jac", max_nfev=200)
    p = res.x
    s1 = float(p[5])
    s2 = s1 + float(p[6])
    s3 = s2 + float(p[7])
    resid = _pwl(x, p) - v
    noise = max(1.4826 * float(np.median(np.abs(resid - np.median(resid)))), scale * 0.1)
    slopes = tuple(float(direction * m) for m in p[1:5])  # dC/dq
    # standard errors of the three breaks from the fit's Jacobian (s2, s3 are sums of widths)
    try:
        cov = np.linalg.pinv(res.jac.T @ res.jac) * noise ** 2
        acc = np.tril(np.ones((3, 3)))
        cb = acc @ cov[5:8, 5:8] @ acc.T
        break_se = tuple(float(math.sqrt(max(v, 0.0))) for v in np.diag(cb))
    except np.linalg.LinAlgError:  # pragma: no cover
        break_se = (math.nan,) * 3
    # The far end is loaded when the current still climbs over the last few degrees of travel:
    # a slope well above what the noise allows on that window. This needs no fitted piece, so it
    # holds when the sweep never leaves the dead zone and the four pieces mean nothing.
    win = x >= travel - _END_WINDOW
    xw = x[win] - x[win].mean()
    den = float(xw @ xw)
    if win.sum() >= 4 and den > 0:
        vw = v[win] - v[win].mean()
        m_end = float(xw @ vw) / den
        # the window's own scatter: bins near a reversal average many more samples than the rest
        local = math.sqrt(float(np.sum((vw - m_end * xw) ** 2)) / (win.sum() - 2))
        end_slope = direction * m_end
        end_se = max(local, 0.25 * noise) / math.sqrt(den)
    else:
        end_slope, end_se = 0.0, math.inf
    far_ok = end_slope >= 6.0 * end_se
    # The near end is past the dead zone plus the backlash when a taut piece follows the backlash:
    # long enough, sloped like a taut tendon, far steeper than the dead zone, above the noise.
    m_back, m_unload, m_dead, m_load = slopes
    near_ok = (s2 - s1 >= _MIN_PIECE and m_unload > 0 and m_unload >= 4.0 * abs(m_dead)
               and m_unload * (s2 - s1) >= 8.0 * noise)
    return BranchFit(int(start), int(stop), int(direction), q0, float(q[stop]), (s1, s2, s3),
                     slopes, noise, bool(near_ok), bool(far_ok), end_slope, break_se,
                     tuple(float(v) for v in p))


def _spread(values: np.ndarray) -> float:
    # standard error of a median over branches (normal approximation, 1.25 * sd / sqrt(n))
    values = np.asarray(values, float)
    if values.size < 2:
        return float("nan")
    return float(1.2533 * np.std(values, ddof=1) / math.sqrt(values.size))


# --------------------------------------------------------------------------------------------
# the tip fit
# --------------------------------------------------------------------------------------------
# Parameterisation of the seven tip-fit parameters so that every trial point is a valid model:
#   theta = (d_neg, W, f_pos, f_neg, omega, dh, h_mid) with W = d_pos - d_neg >= 0,
#   dh = (h_neg - h_pos)/omega >= 0, b = f * (W + dh) with f in [0, 1], omega > 0.
# Then dhat_pos <= d_pos and d_neg <= dhat_neg hold (b <= W + dh), and f_up <= f_dn everywhere
# (outside the dead zone the gap is omega*b >= 0, inside it f_up <= h_pos <= h_neg <= f_dn).
_THETA_LO = np.array([-np.inf, 0.0, 0.0, 0.0, 1e-3, 0.0, -np.inf])
_THETA_HI = np.array([np.inf, np.inf, 1.0, 1.0, np.inf, np.inf, np.inf])
_TIP_PARAMS = ("d_pos", "d_neg", "b_pos", "b_neg", "omega", "h_pos", "h_neg")


def _theta_to_params(th: np.ndarray) -> np.ndarray:
    d_neg, w, f_pos, f_neg, omega, dh, h_mid = th
    span = w + dh
    return np.array([d_neg + w, d_neg, f_pos * span, f_neg * span, omega,
                     h_mid - 0.5 * omega * dh, h_mid + 0.5 * omega * dh])


def _params_to_theta(p: Mapping[str, float]) -> np.ndarray:
    w = max(p["d_pos"] - p["d_neg"], 0.0)
    dh = max((p["h_neg"] - p["h_pos"]) / p["omega"], 0.0)
    span = max(w + dh, 1e-9)
    return np.array([p["d_neg"], w, min(p["b_pos"] / span, 1.0), min(p["b_neg"] / span, 1.0),
                     p["omega"], dh, 0.5 * (p["h_pos"] + p["h_neg"])])


def _model_from_theta(th: np.ndarray) -> KnobModel:
    return KnobModel(**dict(zip(_TIP_PARAMS, _theta_to_params(th))))


def _heights_assumed(d_pos: float, d_neg: float, b_pos: float, b_neg: float,
                     omega: float) -> tuple[float, float]:
    """Dead-zone heights when no tip angle was measured (see :func:`identify`)."""
    dh = max(0.5 * (b_pos + b_neg), max(b_pos, b_neg) - (d_pos - d_neg), 0.0)
    return -0.5 * omega * dh, 0.5 * omega * dh


def _tau(resid: np.ndarray) -> float:
    # integrated autocorrelation time of the residuals: how many neighbouring samples share one
    # piece of information (the 20 Hz filter and model misfit correlate them)
    r = resid - resid.mean()
    var = float(r @ r)
    if var <= 0 or r.size < 4:
        return 1.0
    n = r.size
    nfft = 1 << (2 * n - 1).bit_length()
    f = np.fft.rfft(r, nfft)
    acf = np.fft.irfft(f * np.conj(f), nfft)[:n] / var
    tau = 1.0
    for k in range(1, min(n, 5000)):
        if acf[k] < 0.05:
            break
        tau += 2.0 * acf[k]
    return tau


def _fit_tip(q: np.ndarray, y: np.ndarray, y0: float, th0: np.ndarray,
             weights: np.ndarray | None = None) -> OptimizeResult:
    sw = None if weights is None else np.sqrt(weights)

    def resid(th):
        r = _model_from_theta(th).forward(q, y0) - y
        return r if sw is None else r * sw

    th0 = np.clip(th0, _THETA_LO, _THETA_HI)
    # keep the start strictly inside the box: trf needs an interior point
    inner = np.where(np.isfinite(_THETA_HI), 1e-6, 0.0)
    th0 = np.minimum(np.maximum(th0, _THETA_LO + inner), _THETA_HI - inner)
    return least_squares(resid, th0, bounds=(_THETA_LO, _THETA_HI), loss="soft_l1",
                         f_scale=TIP_F_SCALE, x_scale="jac", max_nfev=400)


def _theta_jacobian(th: np.ndarray) -> np.ndarray:
    # d(params)/d(theta), for carrying the covariance from theta to the model's parameters
    g = np.zeros((7, 7))
    base = _theta_to_params(th)
    for j in range(7):
        h = 1e-6 * max(1.0, abs(th[j]))
        t2 = th.copy()
        t2[j] += h
        g[:, j] = (_theta_to_params(t2) - base) / h
    return g


def _decimate_index(n: int, keep: np.ndarray, limit: int) -> np.ndarray:
    if n <= limit:
        return np.arange(n)
    stride = int(math.ceil(n / limit))
    # the clamp recursion only depends on the extremes of a monotone stretch, so dropping samples
    # between kept reversal points changes nothing but the number of residuals
    return np.union1d(np.arange(0, n, stride), np.concatenate([keep, [n - 1]]))


def _initial_omega(q: np.ndarray, y: np.ndarray, est: Mapping[str, float], chk: SweepCheck,
                   default: float) -> float:
    # slope of y over the loaded stretches (past an edge and past the backlash after a reversal),
    # with one intercept per side and direction
    rows, ys, groups = [], [], []
    for a, b, d in chk.branches:
        qq, yy = q[a:b + 1], y[a:b + 1]
        if d > 0:
            m_hi = qq > est["d_pos"] + 1.0
            m_lo = (qq < est["d_neg"] - 1.0) & (qq > q[a] + est["b_neg"] + 1.0)
        else:
            m_lo = qq < est["d_neg"] - 1.0
            m_hi = (qq > est["d_pos"] + 1.0) & (qq < q[a] - est["b_pos"] - 1.0)
        for m, gid in ((m_hi, 0), (m_lo, 1)):
            if m.sum() >= 10:
                rows.append(qq[m])
                ys.append(yy[m])
                groups.append(np.full(m.sum(), 2 * gid + (d > 0)))
    if not rows:
        return default
    qq, yy, gg = np.concatenate(rows), np.concatenate(ys), np.concatenate(groups)
    # demean per group, then one common slope
    qd, yd = qq.copy(), yy.copy()
    for g in np.unique(gg):
        m = gg == g
        qd[m] -= qd[m].mean()
        yd[m] -= yd[m].mean()
    den = float(qd @ qd)
    if den <= 0:
        return default
    om = float(qd @ yd) / den
    return om if om > 0.05 else default


# --------------------------------------------------------------------------------------------
# identification
# --------------------------------------------------------------------------------------------
def _pick(items: list, limit: int) -> list:
    if len(items) <= limit:
        return items
    idx = np.unique(np.round(np.linspace(0, len(items) - 1, limit)).astype(int))
    return [items[i] for i in idx]


def _identify_current(q: np.ndarray, c: np.ndarray, chk: SweepCheck, where: str,
                      ) -> tuple[list[BranchFit], dict[str, np.ndarray]]:
    ups = [br for br in chk.branches if br[2] > 0]
    dns = [br for br in chk.branches if br[2] < 0]
    chosen = sorted(_pick(ups, MAX_BRANCHES) + _pick(dns, MAX_BRANCHES))
    fits = [f for f in (_fit_branch(q, c, *br) for br in chosen) if f is not None]
    where_k = f"{where}knob {chk.knob}"
    reach = {"pos": chk.q_max, "neg": chk.q_min}
    sign = {"pos": "positive", "neg": "negative"}

    def majority(flags: list[bool]) -> bool:
        return bool(flags) and 2 * sum(flags) >= len(flags)

    # branches heading to an end test whether it passes the dead zone (their far end) ...
    for side in ("pos", "neg"):
        heading = [f.far_ok for f in fits if (f.direction > 0) == (side == "pos")]
        if not majority(heading):
            raise IdentificationError(
                f"{where_k} never moves {sign[side]} past the dead zone: reaches {reach[side]:.1f} deg "
                "and the motor current stays flat there (no tendon taut); sweep further")
    # ... and branches leaving it whether it passes the dead zone plus the backlash (near end);
    # there the taut tendon unloads, so the current changes more slowly than while it loads
    for side in ("pos", "neg"):
        loading = np.median([f.slopes[3] for f in fits if (f.direction > 0) == (side == "pos")])
        leaving = [f.near_ok and f.slopes[1] < loading for f in fits if (f.direction < 0) == (side == "pos")]
        if not majority(leaving):
            edge = np.median([f.edges[1 if side == "pos" else 0] for f in fits
                              if (f.direction > 0) == (side == "pos")])
            raise IdentificationError(
                f"{where_k} does not move {sign[side]} past the dead zone plus the backlash: reaches "
                f"{reach[side]:.1f} deg, the dead-zone edge is near {edge:.1f} deg, and after the "
                "reversal the backlash takes all the travel back to the dead zone (no loaded stretch "
                "to read it from); sweep further")
    good = [f for f in fits if f.far_ok and f.near_ok]
    per = {
        "d_neg": np.array([f.edges[0] for f in good]),
        "d_pos": np.array([f.edges[1] for f in good]),
        "b": np.array([f.backlash for f in good]),
        "se_d_neg": np.array([f.edges_se[0] for f in good]),
        "se_d_pos": np.array([f.edges_se[1] for f in good]),
        "se_b": np.array([f.break_se[0] for f in good]),
        "up": np.array([f.direction > 0 for f in good]),
        "cycle": np.array([_cycle_of(chk, f.start) for f in good]),
    }
    return good, per


def _cycle_of(chk: SweepCheck, index: int) -> int:
    # cycles run from one top reversal to the next
    return int(np.searchsorted(chk.reversals[chk.tops], index, side="right"))


def _median_estimate(per: Mapping[str, np.ndarray], use: np.ndarray | None = None,
                     fallback: Mapping[str, float] | None = None) -> dict[str, float]:
    """Medians over branches (``use``: indices of the branches, repeats allowed)."""
    if use is None:
        use = np.arange(per["up"].size)
    up = per["up"][use]
    b = per["b"][use]
    est = {"d_pos": float(np.median(per["d_pos"][use])), "d_neg": float(np.median(per["d_neg"][use]))}
    for name, mask in (("b_pos", ~up), ("b_neg", up)):
        if mask.any():
            est[name] = float(np.median(b[mask]))
        else:
            # a bootstrap replicate with no branch this way keeps the full-sample estimate
            est[name] = fallback[name] if fallback else float("nan")
    return est


def _current_levels_loose(q: np.ndarray, c: np.ndarray, chk: SweepCheck, d_neg: float,
                          d_pos: float) -> tuple[float, float, float]:
    """The current levels when the current has no four-piece signature (the tip fit's edges).

    The loaded slope is the median over branches of the straight-line ``dC/dq`` past the far
    edge (ascending: above ``d_pos``, descending: below ``d_neg``); the dead-zone levels as in
    :func:`_current_levels`.
    """
    slopes, spans = [], []
    for a, b, d in chk.branches:
        qq, cc = q[a:b + 1], c[a:b + 1]
        m = qq > d_pos + 1.0 if d > 0 else qq < d_neg - 1.0
        if m.sum() < 8 or np.ptp(qq[m]) < 1.0:
            m = np.ones(qq.size, bool)  # the edge lies beyond the travel: the whole branch
        slopes.append(float(np.polyfit(qq[m], cc[m], 1)[0]))
        spans.append((a, b))
    # magnitude: a current without the signature may even fall while the tendon loads
    return _current_levels(q, c, spans, d_neg, d_pos, slope_loaded=abs(float(np.median(slopes))))


def _current_levels(q: np.ndarray, c: np.ndarray, fits: Sequence, d_neg: float,
                    d_pos: float, slope_loaded: float | None = None) -> tuple[float, float, float]:
    """(slope_dead_zone, slope_loaded, current_dead_zone) from the filtered current.

    ``fits``: :class:`BranchFit` objects, or ``(start, stop)`` pairs when ``slope_loaded`` is given.
    """
    if slope_loaded is None:
        slope_loaded = float(np.median([f.slopes[3] for f in fits]))
    lo, hi = d_neg + 1.0, d_pos - 1.0
    if hi <= lo:
        lo, hi = d_neg, d_pos
    inside = (q >= lo) & (q <= hi)
    current_dz = float(np.median(c[inside])) if inside.any() else float(np.median(c))
    # typical |dC/dq| the way a stepping search sees it: slope of the current over 2 deg of knob
    # travel inside the dead zone, noise included
    slopes = []
    for f in fits:
        a, b = (f.start, f.stop) if isinstance(f, BranchFit) else f
        qq, cc = q[a:b + 1], c[a:b + 1]
        m = (qq >= lo) & (qq <= hi)
        if m.sum() < 8:
            continue
        x, v = _bin_branch(qq[m] - lo, cc[m], BIN_DEG)
        w = 4
        for i in range(0, x.size - w + 1, 2):
            xs, vs = x[i:i + w], v[i:i + w]
            xs = xs - xs.mean()
            den = float(xs @ xs)
            if den > 0:
                slopes.append(abs(float(xs @ (vs - vs.mean())) / den))
    if slopes:
        slope_dz = float(np.median(slopes))
    elif fits and isinstance(fits[0], BranchFit):
        slope_dz = abs(float(np.median([f.slopes[2] for f in fits])))
    else:  # no dead zone wide enough to look inside: the current's scatter per 2 deg instead
        slope_dz = float(np.median(np.abs(np.diff(c)))) / max(float(np.median(np.abs(np.diff(q)))), 1e-9)
    return slope_dz, slope_loaded, current_dz


def _knob_list(run: Run, knobs, use_tip: bool = False) -> list[int]:
    where = f"{run.source}: " if run.source else ""
    if knobs is None:
        ks = [k for k in (1, 2) if f"q{k}" in run
              and (f"c{k}" in run or (use_tip and f"y{k}" in run))]
        if not ks:
            need = "q1,c1 or q2,c2 (or q1,y1 / q2,y2 for the tip fit)" if use_tip else "q1,c1 or q2,c2"
            raise IdentificationError(
                f"{where}no knob to identify: needs a pair of columns {need} "
                f"(columns: {', '.join(run.columns) or 'none'})")
        return ks
    ks = []
    for k in knobs:
        try:
            k = int(k)
        except (TypeError, ValueError):
            raise IdentificationError(f"knob {k!r} is not 1 or 2") from None
        if k not in (1, 2):
            raise IdentificationError(f"knob {k} is not a knob of a two-knob catheter (1 or 2)")
        if k not in ks:
            ks.append(k)
    if not ks:
        raise IdentificationError("no knob to identify")
    return ks


def identify(run: Run, knobs: Sequence[int] | None = None, omega: float | None = None,
             use_tip: bool = True, bootstrap: int = 0, seed: int = 0,
             filter_hz: float | None = 20.0) -> Identification:
    """Identify the straight-shaft hysteresis model of each knob from a sweep.

    Current (always): the motor current is low-passed (3rd-order Butterworth, zero phase, the
    paper's 20 Hz; filtering an already filtered recording again changes little, the sweep's
    content being far below 20 Hz); every complete branch (reversal to reversal) gets the four-
    piece fit of the module docstring (exact 4-segment least-squares split by dynamic programming
    as the start, then a continuous piecewise-linear fit, soft-L1 loss); each branch gives both
    dead-zone edges :math:`D_{pos}, D_{neg}` and the backlash :math:`B` of the end it starts
    from; the estimates are the medians over branches.

    Tip (``y<k>`` present and ``use_tip``): least-squares fit of :math:`D_{pos}, D_{neg},
    B_{pos}, B_{neg}, \\omega, H_{pos}, H_{neg}` through :meth:`KnobModel.forward` started from
    the current's edges and backlash, with the run's first measured ``y`` as :math:`y_{-1}`
    (DESIGN.md section 3), soft-L1 loss of scale :data:`TIP_F_SCALE`. The fit is parameterised
    so every trial point is a valid model, which restricts it to :math:`H_{neg} \\ge H_{pos}`
    (the descending dead zone above the ascending one, as on every measured loop).

    Current only (no ``y<k>``, or ``use_tip`` False): :math:`\\omega` is ``omega`` or the
    paper's 1.45, and the heights, which the current cannot see, follow a stated assumption.
    The tip moves only while a tendon is taut, and the current shows where the tension
    vanishes; so on the way up the tip's dead zone should begin where the posterior tendon goes
    slack, :math:`\\hat D_{pos} = D_{neg}`, i.e. :math:`H_{neg} - H_{pos} = \\omega B_{neg}`, and
    on the way down where the anterior one does, :math:`\\hat D_{neg} = D_{pos}`, i.e.
    :math:`H_{neg} - H_{pos} = \\omega B_{pos}`. Both hold only when :math:`B_{pos} = B_{neg}`, so
    we take the mean, :math:`H_{neg} - H_{pos} = \\omega (B_{pos}+B_{neg})/2` (raised if needed
    to keep the model valid), and centre the loop on the straight tip, :math:`H_{pos} = -H_{neg}`.
    With a measured tip the fit finds the heights instead, and this assumption is its start.

    Every branch fit must show a taut tendon at both ends of the sweep, past the dead zone and
    past the dead zone plus the backlash; otherwise :class:`IdentificationError` says which end
    falls short and how far the knob went.

    Uncertainties (``KnobFit.stderr``, one sigma): on the tip path the fit's Jacobian
    covariance, its residual variance inflated by the residuals' autocorrelation time (the
    filter makes neighbouring samples share their noise); on the current path the spread of the
    per-branch values (standard error of a median), never below the branches' own fit errors.
    With ``bootstrap > 0``, the standard deviation over that many replicates resampling whole
    cycles (seeded by ``seed``), never below the estimate without it (a two-cycle sweep gives a
    bootstrap little to resample).

    Parameters
    ----------
    run : Run
        The sweep: ``t``, ``q<k>``, ``c<k>`` and optionally ``y<k>`` per knob.
    knobs : sequence of int, optional
        Knobs to identify; default every ``k`` with ``q<k>`` and ``c<k>``.
    omega : float, optional
        Slope used on the current-only path (default 1.45); ignored by the tip fit.
    use_tip : bool
        Fit through the tip angle when the run has it.
    bootstrap : int
        Replicates of a bootstrap over cycles for the uncertainties (0: the fit's Jacobian
        covariance on the tip path, the spread over branches on the current path).
    seed : int
        Seed of the bootstrap.
    filter_hz : float or None
        Cut-off of the current's low-pass (None: use the current as recorded).

    Returns
    -------
    Identification

    Raises
    ------
    IdentificationError
        When the sweep cannot identify a knob (says what is missing, see :func:`check_sweep`).
    """
    where = f"{run.source}: " if run.source else ""
    if omega is not None and not (math.isfinite(float(omega)) and float(omega) > 0):
        raise IdentificationError(f"omega must be a positive number, got {omega}")
    if bootstrap < 0:
        raise IdentificationError(f"bootstrap must be >= 0, got {bootstrap}")
    ks = _knob_list(run, knobs, use_tip)
    fits: dict[int, KnobFit] = {}
    for k in ks:
        fits[k] = _identify_knob(run, k, omega, use_tip, int(bootstrap), int(seed), filter_hz, where)
    methods = sorted({f.method for f in fits.values()})
    meta = {"method": methods[0] if len(methods) == 1 else
            ",".join(f"{k}:{f.method}" for k, f in fits.items())}
    starts = {k: f.start for k, f in fits.items() if f.start}
    if starts:
        meta["tip_start"] = ",".join(f"{k}:{v}" for k, v in starts.items())
    model = Model({k: f.model for k, f in fits.items()}, meta=meta,
                  identification={k: f.ident for k, f in fits.items() if f.ident is not None})
    return Identification(fits, model)


def _identify_knob(run: Run, k: int, omega: float | None, use_tip: bool, bootstrap: int, seed: int,
                   filter_hz: float | None, where: str) -> KnobFit:
    yname, cname = f"y{k}", f"c{k}"
    tip = use_tip and yname in run
    chk = check_sweep(run, k, need_current=not tip)
    q = np.ascontiguousarray(run[f"q{k}"], dtype=float)
    c = None
    if cname in run:
        c = np.asarray(run[cname], dtype=float)
        if np.ptp(c) <= 1e-9 * max(1.0, float(np.max(np.abs(c)))):
            c = None  # only reachable on the tip path: check_sweep refuses it otherwise
        elif filter_hz is not None and "t" in run:
            c = lowpass(c, run.sample_rate, filter_hz)
    rng = np.random.default_rng(seed)
    cur = None
    start_note = ""
    if c is None:
        start_note = f"no usable motor current {cname} (absent or constant)"
    elif tip:
        # the current's four-piece signature is only the tip fit's start: a transmission whose
        # current does not show it (issue 6: a real instrument) still has a loop to fit
        try:
            cur = _current_estimate(q, c, chk, bootstrap, rng, where)
        except IdentificationError as exc:
            start_note = f"current signature not usable ({exc})"
    else:
        cur = _current_estimate(q, c, chk, bootstrap, rng, where)

    if tip:
        y = np.asarray(run[yname], float)
        if cur is None:
            end_slopes = _check_tip_reach(q, y, chk, where)
        model, stderr, rmse = _identify_tip(q, y, chk, cur.est if cur is not None else None, omega,
                                            bootstrap, rng)
        if cur is None:
            _check_tip_backlash(model, chk, where, end_slopes)
        method, start = "tip", ("current" if cur is not None else "loop")
    else:
        est = cur.est
        om = PAPER_OMEGA if omega is None else float(omega)
        d_pos, d_neg = est["d_pos"], est["d_neg"]
        # the backlash cannot exceed what a valid model allows at this dead-zone width
        b_pos, b_neg = max(est["b_pos"], 0.0), max(est["b_neg"], 0.0)
        h_pos, h_neg = _heights_assumed(d_pos, d_neg, b_pos, b_neg, om)
        try:
            model = KnobModel(d_pos=d_pos, d_neg=d_neg, b_pos=b_pos, b_neg=b_neg, omega=om,
                              h_pos=h_pos, h_neg=h_neg)
        except ModelError as exc:  # pragma: no cover - the heights are chosen to keep it valid
            raise IdentificationError(f"{where}knob {k}: the current gives no valid model ({exc})") from None
        stderr = {n: v for n, v in cur.err.items() if math.isfinite(v)}
        rmse = None
        if yname in run:
            rmse = float(np.sqrt(np.mean((model.forward(q, float(run[yname][0])) - run[yname]) ** 2)))
        method, start = "current", ""
    if cur is not None:
        levels = _current_levels(q, c, cur.good, cur.est["d_neg"], cur.est["d_pos"])
    elif c is not None:
        levels = _current_levels_loose(q, c, chk, model.d_neg, model.d_pos)
    else:
        levels = None
    ident = None
    if levels is not None:
        slope_dz, slope_loaded, current_dz = levels
        ident = KnobIdentification(slope_dead_zone=slope_dz, slope_loaded=slope_loaded,
                                   q_min=chk.q_min, q_max=chk.q_max, rmse=rmse, stderr=stderr,
                                   current_dead_zone=current_dz)
    return KnobFit(knob=k, model=model, stderr=stderr, rmse=rmse, method=method, ident=ident,
                   n_reversals=int(chk.reversals.size), n_cycles=chk.n_cycles,
                   current_estimate=dict(cur.est) if cur is not None else {},
                   current_stderr=({n: v for n, v in cur.err.items() if math.isfinite(v)}
                                   if cur is not None else {}),
                   branches=tuple(cur.good) if cur is not None else (), bootstrap=bootstrap,
                   start=start, start_note=start_note)


_SIDE = {"pos": "positive", "neg": "negative"}


def _check_tip_reach(q: np.ndarray, y: np.ndarray, chk: SweepCheck, where: str) -> dict[str, float]:
    """Without the current's signature: the tip must still move at the far end of each branch.

    Over the last :data:`_END_WINDOW` deg of travel before a reversal ``dy/dq`` must be positive
    well beyond what the tip angle's scatter there allows (a taut tendon moves the tip; in the
    dead zone it stays put), on most branches heading to each end.
    """
    heading = {"pos": [], "neg": []}
    slopes = {"pos": [], "neg": []}
    for a, b, d in chk.branches:
        qq, yy = q[a:b + 1], y[a:b + 1]
        travel = d * (qq - qq[0])
        m = travel >= float(travel.max()) - _END_WINDOW
        ok = False
        if m.sum() >= 4:
            x = qq[m] - qq[m].mean()
            den = float(x @ x)
            if den > 0:
                v = yy[m] - yy[m].mean()
                slope = float(x @ v) / den
                scatter = math.sqrt(float(np.sum((v - slope * x) ** 2)) / max(m.sum() - 2, 1))
                # quantised encoders: never trust a scatter below a tenth of the window's span
                scatter = max(scatter, 1e-3 * max(float(np.ptp(y)), 1e-9))
                ok = slope >= 6.0 * scatter / math.sqrt(den) and slope > 0.0
                slopes["pos" if d > 0 else "neg"].append(slope)
        heading["pos" if d > 0 else "neg"].append(ok)
    reach = {"pos": chk.q_max, "neg": chk.q_min}
    for side, flags in heading.items():
        if not flags or 2 * sum(flags) < len(flags):
            raise IdentificationError(
                f"{where}knob {chk.knob} never moves {_SIDE[side]} past the dead zone: reaches "
                f"{reach[side]:.1f} deg and the tip angle stays flat there (no tendon taut; the motor "
                "current shows no usable signature either); sweep further")
    return {side: float(np.median(v)) if v else 0.0 for side, v in slopes.items()}


def _check_tip_backlash(model: KnobModel, chk: SweepCheck, where: str,
                        end_slopes: Mapping[str, float]) -> None:
    r"""Without the current's signature: the fitted loop must show a loaded stretch after each reversal.

    After the top reversal the tip leaves its backlash plateau at ``q_max - B_pos``; it moves on
    a loaded slope (which is what fixes :math:`B_{pos}`) only if that is above
    :math:`\hat D_{neg}`, i.e. ``q_max > D_pos + (H_neg - H_pos)/omega``; likewise at the bottom.
    """
    dh = (model.h_neg - model.h_pos) / model.omega
    # the fitted dead zone must lie inside the sweep when the tip is nearly flat at that end (a
    # flat tip fits any edge beyond it); a tip that moves at the loaded slope there is loaded,
    # wherever the fit put the edge
    for side, past in (("pos", chk.q_max - model.d_pos), ("neg", model.d_neg - chk.q_min)):
        if past < _MIN_PIECE and end_slopes.get(side, 0.0) < 0.5 * model.omega:
            reach = chk.q_max if side == "pos" else chk.q_min
            raise IdentificationError(
                f"{where}knob {chk.knob} never moves {_SIDE[side]} past the dead zone: reaches "
                f"{reach:.1f} deg and the fitted dead zone reaches that far (no loaded stretch of the "
                "tip beyond it; the motor current shows no usable signature either); sweep further")
    for side, reach, edge in (("pos", chk.q_max, model.d_pos + dh), ("neg", chk.q_min, model.d_neg - dh)):
        dz = model.d_pos if side == "pos" else model.d_neg
        # a dead zone fitted beyond the other end of the sweep: no dead zone inside it, the
        # sloped loop (checked above) is all there is to read
        beyond = dz < chk.q_min if side == "neg" else dz > chk.q_max
        if not beyond and (reach - edge if side == "pos" else edge - reach) < _MIN_PIECE:
            raise IdentificationError(
                f"{where}knob {chk.knob} does not move {_SIDE[side]} past the dead zone plus the "
                f"backlash: reaches {reach:.1f} deg, the dead-zone edge is near {dz:.1f} deg, and after "
                "the reversal the tip stays on its backlash plateau all the way back to the dead zone "
                "(no loaded stretch to read the backlash from); sweep further")


@dataclass(frozen=True)
class _CurrentEstimate:
    good: list
    est: dict
    err: dict


def _current_estimate(q: np.ndarray, c: np.ndarray, chk: SweepCheck, bootstrap: int,
                      rng: np.random.Generator, where: str) -> _CurrentEstimate:
    """Edges and backlash from the current's four-piece signature, with their uncertainties."""
    k = chk.knob
    good, per = _identify_current(q, c, chk, where)
    est = _median_estimate(per)
    for name in ("b_pos", "b_neg"):
        if not math.isfinite(est[name]):  # pragma: no cover - check_sweep guarantees both ways
            raise IdentificationError(f"{where}knob {k}: no branch to read {name} from")
    cycles = np.unique(per["cycle"])
    names = ("d_pos", "d_neg", "b_pos", "b_neg")
    up = per["up"]
    values = {"d_pos": per["d_pos"], "d_neg": per["d_neg"], "b_pos": per["b"][~up], "b_neg": per["b"][up]}
    fit_se = {"d_pos": per["se_d_pos"], "d_neg": per["se_d_neg"], "b_pos": per["se_b"][~up],
              "b_neg": per["se_b"][up]}
    # floor of every uncertainty: the branches' own fit errors, pooled as for a median of n
    floor = {n: float(1.2533 * np.median(fit_se[n]) / math.sqrt(fit_se[n].size)) for n in names}
    if bootstrap > 0 and cycles.size >= 2:
        reps = []
        for _ in range(bootstrap):
            pick = rng.choice(cycles, size=cycles.size, replace=True)
            use = np.concatenate([np.flatnonzero(per["cycle"] == cy) for cy in pick])
            rep = _median_estimate(per, use, fallback=est)
            reps.append([rep[n] for n in names])
        spread = dict(zip(names, map(float, np.std(np.array(reps), axis=0, ddof=1))))
    else:
        spread = {n: _spread(values[n]) for n in names}
    err = {n: float(np.nanmax([spread[n], floor[n]])) for n in names}
    return _CurrentEstimate(good, est, err)


def _centred(th: np.ndarray, q: np.ndarray, y: np.ndarray, y0: float) -> np.ndarray:
    # the loop's vertical position (and with it an output's arbitrary zero): the median residual
    # of the start, removed
    th = np.clip(th, _THETA_LO, _THETA_HI)
    th[6] += float(np.median(y - _model_from_theta(th).forward(q, y0)))
    return th


LOOP_GRID = 9
"""Dead-zone centres (and, separately, widths) tried by the loop start of the tip fit."""


def _loop_start(q: np.ndarray, y: np.ndarray, y0: float, chk: SweepCheck) -> np.ndarray:
    """A coarse tip-fit start read from the q-y loop alone (no current), as a theta vector.

    omega: slope of a straight line through the loop. Backlash (both ends): the loop's vertical
    width over the middle half of the knob range (descending minus ascending residual of that
    line) divided by omega, since outside the dead zone f_dn - f_up = omega B. Edges: the best,
    by soft-L1 residual, of a grid of dead-zone centres and widths over the swept range (width
    0: no dead zone, the loop a parallelogram); heights from the stated assumption of the
    current path, then shifted to the loop's median level.
    """
    g = np.polyfit(q, y, 1)
    omega = float(g[0]) if g[0] > 0.05 else PAPER_OMEGA
    r = y - np.polyval(g, q)
    lo, hi = chk.q_min, chk.q_max
    span = hi - lo
    mid = (q > lo + 0.25 * span) & (q < hi - 0.25 * span)
    dq = np.gradient(q)
    up, dn = mid & (dq > 0), mid & (dq < 0)
    gap = float(np.median(r[dn]) - np.median(r[up])) if up.any() and dn.any() else 0.0
    b = max(gap, 0.0) / omega
    best, best_cost = None, math.inf
    centres = np.linspace(lo + 0.1 * span, hi - 0.1 * span, LOOP_GRID)
    widths = np.linspace(0.0, 0.6 * span, LOOP_GRID)
    for cen in centres:
        for w in widths:
            d_neg, d_pos = cen - 0.5 * w, cen + 0.5 * w
            h_pos, h_neg = _heights_assumed(d_pos, d_neg, b, b, omega)
            th = _centred(_params_to_theta(dict(d_pos=d_pos, d_neg=d_neg, b_pos=b, b_neg=b,
                                                omega=omega, h_pos=h_pos, h_neg=h_neg)), q, y, y0)
            e = np.abs(_model_from_theta(th).forward(q, y0) - y) / TIP_F_SCALE
            cost = float(np.sum(np.sqrt(1.0 + e * e) - 1.0))  # the fit's own soft-L1 loss
            if cost < best_cost:
                best, best_cost = th, cost
    return best


def _identify_tip(q: np.ndarray, y: np.ndarray, chk: SweepCheck, est: Mapping[str, float] | None,
                  omega: float | None, bootstrap: int, rng: np.random.Generator,
                  ) -> tuple[KnobModel, dict[str, float], float]:
    n = q.size
    idx = _decimate_index(n, chk.reversals, MAX_TIP_SAMPLES)
    qd, yd = np.ascontiguousarray(q[idx]), np.ascontiguousarray(y[idx])
    y0 = float(y[0])
    if est is None:
        th0 = _loop_start(qd, yd, y0, chk)
    else:
        om0 = _initial_omega(q, y, est, chk, PAPER_OMEGA if omega is None else float(omega))
        h_pos, h_neg = _heights_assumed(est["d_pos"], est["d_neg"], est["b_pos"], est["b_neg"], om0)
        start = dict(est, omega=om0, h_pos=h_pos, h_neg=h_neg)
        th0 = _centred(_params_to_theta(start), qd, yd, y0)
    res = _fit_tip(qd, yd, y0, th0)
    th = res.x
    model = _model_from_theta(th)
    resid_full = model.forward(q, y0) - y
    rmse = float(np.sqrt(np.mean(resid_full ** 2)))
    resid = res.fun
    dof = max(resid.size - th.size, 1)
    s2 = float(resid @ resid) / dof * _tau(resid)
    cov_th = np.linalg.pinv(res.jac.T @ res.jac) * s2
    g = _theta_jacobian(th)
    sd = np.sqrt(np.clip(np.diag(g @ cov_th @ g.T), 0.0, None))
    if bootstrap > 0:
        cyc = np.searchsorted(chk.reversals[chk.tops], idx, side="right")
        ids = np.unique(cyc)
        reps = []
        for _ in range(bootstrap):
            pick = rng.choice(ids, size=ids.size, replace=True)
            w = np.bincount(np.searchsorted(ids, pick), minlength=ids.size)[np.searchsorted(ids, cyc)]
            r = _fit_tip(qd, yd, y0, th, weights=w.astype(float))
            reps.append(_theta_to_params(r.x))
        # a bootstrap over the few cycles of a short sweep sees little spread: never report less
        # than the Jacobian's estimate
        sd = np.maximum(sd, np.std(np.array(reps), axis=0, ddof=1))
    stderr = {name: float(v) for name, v in zip(_TIP_PARAMS, sd)}
    return model, stderr, rmse


# --------------------------------------------------------------------------------------------
# figure
# --------------------------------------------------------------------------------------------
def plot_identification(run: Run, result: Identification, path) -> None:
    """Draw each knob's measured loop against the identified model (like Fig. 4 of the paper).

    Left: tip angle against knob angle, measured and predicted by the model; right: motor current
    against knob angle. The identified dead-zone edges (solid) and the backlash ends after each
    reversal (dashed) are marked. Written atomically as PNG.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ks = sorted(result.fits)
    fig, axes = plt.subplots(len(ks), 2, figsize=(11, 4.2 * len(ks)), squeeze=False)
    for row, k in zip(axes, ks):
        fit = result.fits[k]
        m = fit.model
        q = np.asarray(run[f"q{k}"], float)
        has_y = f"y{k}" in run
        y0 = float(run[f"y{k}"][0]) if has_y else 0.0
        ax = row[0]
        if has_y:
            ax.plot(q, run[f"y{k}"], color="0.6", lw=1.0, label="measured")
        ax.plot(q, m.forward(q, y0), color="C3", lw=1.2, label=f"model ({fit.method})")
        ax.set_xlabel(f"knob angle q{k} (deg)")
        ax.set_ylabel(f"tip angle y{k} (deg)")
        title = f"knob {k}: d_pos={m.d_pos:.2f} d_neg={m.d_neg:.2f} b_pos={m.b_pos:.2f} " \
                f"b_neg={m.b_neg:.2f} omega={m.omega:.3f}"
        if fit.rmse is not None:
            title += f"  RMSE={fit.rmse:.2f} deg"
        ax.set_title(title, fontsize=9)
        ax2 = row[1]
        ax2.plot(q, run[f"c{k}"], color="0.6", lw=1.0, label="measured")
        for i, br in enumerate(fit.branches):
            qb = np.linspace(br.q_start, br.q_stop, 200)
            ax2.plot(qb, br.current(qb), color="C3", lw=1.2,
                     label="four-piece fit per branch" if i == 0 else None)
        ax2.set_xlabel(f"knob angle q{k} (deg)")
        ax2.set_ylabel(f"motor current c{k}")
        ax2.set_title(f"knob {k}: current slope in dead zone {fit.ident.slope_dead_zone:.3g}, "
                      f"loaded {fit.ident.slope_loaded:.3g} per deg", fontsize=9)
        for a in (ax, ax2):
            a.axvline(m.d_pos, color="C0", lw=1.0, label="dead-zone edges d_neg, d_pos")
            a.axvline(m.d_neg, color="C0", lw=1.0)
            a.axvline(fit.ident.q_max - m.b_pos, color="C2", ls="--", lw=1.0,
                      label="end of backlash after each reversal")
            a.axvline(fit.ident.q_min + m.b_neg, color="C2", ls="--", lw=1.0)
            a.grid(alpha=0.3)
        ax2.legend(loc="upper left", fontsize=8)
        ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    buf = _io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    data = buf.getvalue()
    atomic_write(path, lambda f: f.write(data))
