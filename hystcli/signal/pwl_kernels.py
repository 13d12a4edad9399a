"""Compiled inner loops of :mod:`hystcli.signal.pwl`: the knot scans and the robust refits.

A stretch's broken line is placed by coordinate descent over a grid of candidate knots, each scan
one projection of every candidate's hinge column off the other columns, each placement reweighted
for the robust loss. These loops run thousands of times per record on arrays of a few hundred
points, where Python's overhead, not the arithmetic, would set the pace; numba compiles them once
(cached on disk).
"""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def design(x, x0, knots, z):
    n = x.shape[0]
    k = knots.shape[0]
    m = z.shape[1]
    a = np.empty((n, 2 + k + m))
    for i in range(n):
        a[i, 0] = 1.0
        a[i, 1] = x[i] - x0
        for j in range(k):
            d = x[i] - knots[j]
            a[i, 2 + j] = d if d > 0.0 else 0.0
        for j in range(m):
            a[i, 2 + k + j] = z[i, j]
    return a


@njit(cache=True)
def wls(a, y, w):
    n, p = a.shape
    aw = np.empty((n, p))
    yw = np.empty(n)
    for i in range(n):
        s = np.sqrt(w[i])
        yw[i] = y[i] * s
        for j in range(p):
            aw[i, j] = a[i, j] * s
    coef = np.linalg.lstsq(aw, yw, -1.0)[0]
    return coef


@njit(cache=True)
def solve(x, y, sw, z, x0, knots, scale, u, rounds):
    """IRLS (soft_l1) at fixed knots: (coef, weights, deviance)."""
    a = design(x, x0, knots, z)
    n = x.shape[0]
    w = np.empty(n)
    coef = np.zeros(a.shape[1])
    for it in range(rounds + 1):
        for i in range(n):
            w[i] = sw[i] * sw[i] * u[i]
        coef = wls(a, y, w)
        r = (a @ coef - y) * sw
        for i in range(n):
            u[i] = 1.0 / np.sqrt(1.0 + (r[i] / scale) ** 2)
    dev = 0.0
    r = (a @ coef - y) * sw
    for i in range(n):
        dev += 2.0 * (np.sqrt(1.0 + (r[i] / scale) ** 2) - 1.0)
    return coef, u, dev


@njit(cache=True)
def scan(x, y, w, z, x0, knots, j, cand):
    """Weighted RSS with knot ``j`` moved to each of ``cand`` (other knots held)."""
    n = x.shape[0]
    k = knots.shape[0]
    others = np.empty(k - 1)
    c = 0
    for i in range(k):
        if i != j:
            others[c] = knots[i]
            c += 1
    base = design(x, x0, others, z)
    sw = np.sqrt(w)
    bw = np.empty(base.shape)
    for i in range(n):
        for p in range(base.shape[1]):
            bw[i, p] = base[i, p] * sw[i]
    q, rr = np.linalg.qr(bw)
    dmax = 0.0
    for p in range(rr.shape[0]):
        dmax = max(dmax, abs(rr[p, p]))
    keep = 0
    for p in range(rr.shape[0]):
        if abs(rr[p, p]) > 1e-10 * max(dmax, 1e-300):
            keep += 1
    qk = np.empty((n, keep))
    c = 0
    for p in range(rr.shape[0]):
        if abs(rr[p, p]) > 1e-10 * max(dmax, 1e-300):
            qk[:, c] = q[:, p]
            c += 1
    yw = y * sw
    r0 = yw - qk @ (qk.T @ yw)
    rss0 = 0.0
    for i in range(n):
        rss0 += r0[i] * r0[i]
    # suffix sums over the sorted x (index n: nothing left)
    m = keep
    sq_x = np.zeros((n + 1, m))
    sq_1 = np.zeros((n + 1, m))
    s_xx = np.zeros(n + 1)
    s_x = np.zeros(n + 1)
    s_1 = np.zeros(n + 1)
    s_rx = np.zeros(n + 1)
    s_r = np.zeros(n + 1)
    for i in range(n - 1, -1, -1):
        xc = x[i] - x0
        for p in range(m):
            sq_x[i, p] = sq_x[i + 1, p] + qk[i, p] * sw[i] * xc
            sq_1[i, p] = sq_1[i + 1, p] + qk[i, p] * sw[i]
        s_xx[i] = s_xx[i + 1] + w[i] * xc * xc
        s_x[i] = s_x[i + 1] + w[i] * xc
        s_1[i] = s_1[i + 1] + w[i]
        s_rx[i] = s_rx[i + 1] + sw[i] * xc * r0[i]
        s_r[i] = s_r[i + 1] + sw[i] * r0[i]
    tiny = 1e-12 * max(s_xx[0], 1e-300)
    out = np.empty(cand.shape[0])
    for t in range(cand.shape[0]):
        pc = cand[t] - x0
        kk = np.searchsorted(x, cand[t], side="right")
        hh = s_xx[kk] - 2.0 * pc * s_x[kk] + pc * pc * s_1[kk]
        for p in range(m):
            qh = sq_x[kk, p] - pc * sq_1[kk, p]
            hh -= qh * qh
        hr = s_rx[kk] - pc * s_r[kk]
        out[t] = rss0 - (hr * hr / hh if hh > tiny else 0.0)
    return out


@njit(cache=True)
def place(x, y, sw, z, x0, knots, scale, grid, rounds):
    """Coordinate descent of the knots over ``grid`` with robust reweighting, then each knot on a
    fine scan between its grid neighbours: (coef, knots, weights, deviance)."""
    knots = np.sort(knots.copy())
    u = np.ones(x.shape[0])
    coef, u, dev = solve(x, y, sw, z, x0, knots, scale, u, rounds)
    k = knots.shape[0]
    for _ in range(6):
        moved = False
        w = sw * sw * u
        for j in range(k):
            rss = scan(x, y, w, z, x0, knots, j, grid)
            best = grid[np.argmin(rss)]
            if best != knots[j]:
                knots[j] = best
                moved = True
        knots = np.sort(knots)
        coef, u, dev_new = solve(x, y, sw, z, x0, knots, scale, u, rounds)
        if not moved or dev_new >= dev - 1e-9 * max(dev, 1.0):
            dev = min(dev, dev_new)
            break
        dev = dev_new
    w = sw * sw * u
    g = grid.shape[0]
    for j in range(k):
        i = np.searchsorted(grid, knots[j])
        i = min(max(i, 1), g - 1)
        lo = grid[max(i - 1, 0)]
        hi = grid[min(i + 1, g - 1)]
        fine = np.linspace(lo, hi, 21)
        knots[j] = fine[np.argmin(scan(x, y, w, z, x0, knots, j, fine))]
    knots = np.sort(knots)
    coef, u, dev = solve(x, y, sw, z, x0, knots, scale, u, rounds)
    return coef, knots, u, dev
