"""What a recorded sweep offers an identification: its reversals, its branches, a decimation.

A record identifies a knob when the knob moves both ways and passes both dead-zone edges; how
many cycles it holds, where it starts and in which state the tip is then do not matter to the
output-error fit (:mod:`.tip`). :func:`check_sweep` refuses, before anything is fitted, only what
no fit could use (missing or non-finite columns, too few samples, a knob that never moves or
never reverses); whether the edges were passed is judged once the loop is fitted.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from ..errors import IdentificationError
from ..io import Run

MIN_SAMPLES = 100
"""Fewest samples of a sweep :func:`check_sweep` accepts."""


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
    n : int
        Samples in the record.
    """

    knob: int
    reversals: np.ndarray
    tops: np.ndarray
    q_min: float
    q_max: float
    n: int = 0

    @property
    def branches(self) -> list[tuple[int, int, int]]:
        """Complete branches ``(start, stop, direction)`` between two consecutive reversals."""
        out = []
        for a, b, top in zip(self.reversals[:-1], self.reversals[1:], self.tops[:-1]):
            out.append((int(a), int(b), -1 if top else +1))
        return out

    @property
    def segments(self) -> list[tuple[int, int, int]]:
        """Every monotone stretch ``(start, stop, direction)``, the partial first and last included."""
        if self.reversals.size == 0:
            return []
        bounds = [0] + [int(r) for r in self.reversals] + [max(self.n - 1, 0)]
        dirs = [(+1 if top else -1) for top in self.tops]   # direction before each reversal
        dirs = dirs + [-dirs[-1]]
        out = []
        for (a, b), d in zip(zip(bounds[:-1], bounds[1:]), dirs):
            if b > a:
                out.append((a, b, d))
        return out

    @property
    def n_cycles(self) -> int:
        """Full cycles: pairs of complete branches (one each way)."""
        return len(self.branches) // 2


# --------------------------------------------------------------------------------------------
# reversals
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


def decimation_index(q: np.ndarray, limit: int, keep: np.ndarray | None = None) -> np.ndarray:
    """Indices of at most about ``limit`` samples, evenly spread, every local extreme of ``q`` kept.

    The clamp recursion depends only on the extremes of each monotone stretch of its input, so
    dropping samples between kept extremes leaves the output at the kept samples unchanged.
    """
    q = np.asarray(q, float)
    n = q.size
    if n <= limit:
        return np.arange(n)
    stride = int(math.ceil(n / limit))
    extra = find_reversals(q, tol=1e-3 * float(np.ptp(q)))[0] if keep is None else np.asarray(keep, dtype=np.int64)
    return np.union1d(np.arange(0, n, stride), np.concatenate([extra, [n - 1]]))


# --------------------------------------------------------------------------------------------
# checks
# --------------------------------------------------------------------------------------------
def check_sweep(run: Run, knob: int, need_current: bool = True) -> SweepCheck:
    """Check that a run's sweep of one knob could identify anything, before anything is fitted.

    Needs the columns ``q<k>`` and ``c<k>`` (``y<k>`` instead when ``need_current`` is False:
    the tip fit), all finite; at least :data:`MIN_SAMPLES` samples; a knob that moves and
    reverses at least once (one cycle, started anywhere, is enough); a current (or tip) that
    is not constant. Whether the knob passes both dead-zone edges is judged by the fit.

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
    for name in [qn] + [nm for nm in (cn, yn) if nm in run]:
        if not np.all(np.isfinite(run[name])):
            row = int(np.flatnonzero(~np.isfinite(run[name]))[0])
            raise IdentificationError(f"{where}column {name!r} has a non-finite value at row {row + 1}")
    q = run[qn]
    if np.ptp(q) < 1.0:
        raise IdentificationError(f"{where}knob {knob} never moves: {qn} spans {np.ptp(q):.3g} deg")
    sig, what = (cn, "the motor current") if need_current else (yn, "the tip angle")
    s = run[sig]
    if np.ptp(s) <= 1e-9 * max(1.0, float(np.max(np.abs(s)))):
        raise IdentificationError(f"{where}knob {knob}: {what} {sig} is constant ({s[0]:g}); "
                                  "it carries no hysteresis to identify")
    rev, tops = find_reversals(q)
    if rev.size == 0:
        raise IdentificationError(
            f"{where}knob {knob}: the sweep never reverses ({qn} goes from {q[0]:.1f} to {q[-1]:.1f} deg "
            "once); identification needs the knob to go both ways past the dead zone")
    return SweepCheck(knob, rev, tops, float(np.min(q)), float(np.max(q)), n)
