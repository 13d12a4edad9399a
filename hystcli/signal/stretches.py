"""The knob's monotone stretches: where a recorded command reverses, and a decimation that keeps
every reversal.

Every reading of a sweep works stretch by stretch: the tip's clamp recursion depends only on the
extremes of each monotone stretch of its input, and the motor current is read as a function of the
knob angle along each stretch.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["find_reversals", "decimation_index", "monotone_stretches"]


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


def monotone_stretches(q: np.ndarray, tol: float | None = None) -> list[tuple[int, int, int]]:
    """Every monotone stretch ``(start, stop, direction)`` of ``q``, the partial first and last
    included (``stop`` is the index of the reversal that ends it, or the last sample)."""
    q = np.asarray(q, float)
    rev, tops = find_reversals(q, tol)
    if rev.size == 0:
        if q.size < 2:
            return []
        return [(0, q.size - 1, 1 if q[-1] >= q[0] else -1)]
    bounds = [0] + [int(r) for r in rev] + [q.size - 1]
    dirs = [(+1 if top else -1) for top in tops]
    dirs = dirs + [-dirs[-1]]
    return [(a, b, d) for (a, b), d in zip(zip(bounds[:-1], bounds[1:]), dirs) if b > a]
