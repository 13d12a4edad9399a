"""Sample-by-sample core of the zoo plants: the tip clamp recursion and the two tendon loads.

Written from docs/design.md section 3 and the paper alone; imports numpy and (optionally) numba.
Everything here works on the shifted knob coordinate ``u = q - offset``: the hysteresis loop of
the tip and of every tendon load lives in ``u``, which is what makes a bend of the shaft move the
whole loop (tip and current alike) along the knob axis by exactly ``offset``.

State vector (float64, length ``STATE_LEN``), carried from block to block so that a record
continues the history simulated before it:

====  ==========================================================================
0     u of the previous sample (the knob's last position, shifted coordinate)
1     tip angle y of the previous sample
2-8   positive tendon: mode, load, floor, x_r, P_r, u_pe, u_s
9-15  negative tendon: the same, in the mirrored coordinate v = -u
====  ==========================================================================

Tendon load coordinate: the load of a tendon is expressed in knob degrees of "stretch
equivalent": on the loading path it is exactly how far the knob is past the edge where the
tendon became taut (u - d_pos, or d_neg - u), so a law's loaded slope k (mA/deg) turns it into mA.
"""
from __future__ import annotations

import numpy as np

try:  # numba is optional: the pure-Python fallback gives the same numbers, only slower
    from numba import njit as _njit

    _jit = _njit(cache=True, nogil=True)
    HAVE_NUMBA = True
except Exception:  # pragma: no cover - exercised only without numba
    def _jit(f):
        return f

    HAVE_NUMBA = False

STATE_LEN = 16

# base tendon laws
BASE_STRETCH = 0
BASE_TIP_LOAD = 1
BASE_DROP = 2

# parameter vector layout
P_D_POS, P_D_NEG, P_B_POS, P_B_NEG, P_OMEGA, P_H_POS, P_H_NEG, P_DH_POS, P_DH_NEG = range(9)
P_BASE, P_RHO, P_PHI, P_DELTA, P_HOLD, P_WALL_SIDE, P_WALL_Y = range(9, 16)
PARAM_LEN = 16


@_jit
def tip_forward(u, d_pos, d_neg, omega, h_pos, h_neg, dhat_pos, dhat_neg, y0):
    """The clamp recursion y_t = min(max(y_{t-1}, f_up(u_t)), f_dn(u_t)) from y_{-1} = y0."""
    n = u.shape[0]
    out = np.empty(n)
    y = y0
    for i in range(n):
        x = u[i]
        if x < dhat_pos:
            fu = omega * (x - dhat_pos) + h_pos
        elif x <= d_pos:
            fu = h_pos
        else:
            fu = omega * (x - d_pos) + h_pos
        if x < d_neg:
            fd = omega * (x - d_neg) + h_neg
        elif x <= dhat_neg:
            fd = h_neg
        else:
            fd = omega * (x - dhat_neg) + h_neg
        if fu > y:
            y = fu
        if fd < y:
            y = fd
        out[i] = y
    return out


@_jit
def _unload_profile(v, xr, pr, upe, us, phi, delta):
    """Load of a tendon on its way back from a reversal at knob x_r with load P_r."""
    if v >= upe:
        if delta > 0.0:
            frac = (xr - v) / delta
            if frac > 1.0:
                frac = 1.0
            if frac < 0.0:
                frac = 0.0
        else:
            frac = 1.0
        return pr * (1.0 - phi * frac)
    if v > us:
        if delta > 0.0:
            frac = (xr - upe) / delta
            if frac > 1.0:
                frac = 1.0
            if frac < 0.0:
                frac = 0.0
        else:
            frac = 1.0
        top = pr * (1.0 - phi * frac)
        return top * (v - us) / (upe - us)
    return 0.0


@_jit
def _tendon_step(v, v_prev, st, o, e, shat, b, lo, base, rho, phi, delta, hold):
    """Advance one tendon by one sample in its own coordinate v (v grows as it is taken up).

    e: edge where it becomes taut; shat: where it is slack again on the way back (the tip
    settles on its dead-zone plateau); b: backlash width; lo: the other tendon's edge (this one
    is fully released by then).
    """
    if base == 0:
        val = v - e
        if val < 0.0:
            val = 0.0
        st[o + 1] = val
        return val
    mode = st[o]
    val = st[o + 1]
    if mode == 0.0:
        if v < v_prev and val > 0.0:
            xr = v_prev
            pr = val
            if hold > 0.5:
                upe = xr - b
            else:
                upe = xr - delta
            us = upe - rho * pr
            if shat < us:
                us = shat
            if us < lo:
                us = lo
            if us > xr - 1e-9:
                us = xr - 1e-9
            m = us + 0.25 * (xr - us)
            if upe < m:
                upe = m
            st[o] = 1.0
            st[o + 3] = xr
            st[o + 4] = pr
            st[o + 5] = upe
            st[o + 6] = us
            val = _unload_profile(v, xr, pr, upe, us, phi, delta)
        else:
            fl = st[o + 2]
            val = v - e
            if val < fl:
                val = fl
            if val < 0.0:
                val = 0.0
    else:
        if v > v_prev:
            st[o] = 0.0
            st[o + 2] = val
            if v - e > val:
                val = v - e
        else:
            val = _unload_profile(v, st[o + 3], st[o + 4], st[o + 5], st[o + 6], phi, delta)
    st[o + 1] = val
    return val


@_jit
def run_block(u, p, st, y_out, pos_out, neg_out):
    """Advance the plant over the shifted knob samples u; fill the tip and both tendon loads."""
    d_pos = p[0]
    d_neg = p[1]
    b_pos = p[2]
    b_neg = p[3]
    omega = p[4]
    h_pos = p[5]
    h_neg = p[6]
    dhat_pos = p[7]
    dhat_neg = p[8]
    base = int(p[9])
    rho = p[10]
    phi = p[11]
    delta = p[12]
    hold = p[13]
    wall_side = p[14]
    wall_y = p[15]
    y = st[1]
    for i in range(u.shape[0]):
        x = u[i]
        xp = st[0]
        if x < dhat_pos:
            fu = omega * (x - dhat_pos) + h_pos
        elif x <= d_pos:
            fu = h_pos
        else:
            fu = omega * (x - d_pos) + h_pos
        if x < d_neg:
            fd = omega * (x - d_neg) + h_neg
        elif x <= dhat_neg:
            fd = h_neg
        else:
            fd = omega * (x - dhat_neg) + h_neg
        if fu > y:
            y = fu
        if fd < y:
            y = fd
        if wall_side > 0.0 and y > wall_y:
            y = wall_y
        if wall_side < 0.0 and y < wall_y:
            y = wall_y
        y_out[i] = y
        pos_out[i] = _tendon_step(x, xp, st, 2, d_pos, dhat_neg, b_pos, d_neg,
                                  base, rho, phi, delta, hold)
        neg_out[i] = _tendon_step(-x, -xp, st, 9, -d_neg, -dhat_pos, b_neg, -d_pos,
                                  base, rho, phi, delta, hold)
        st[0] = x
    st[1] = y


def new_state(u0: float, y0: float = 0.0) -> np.ndarray:
    """A fresh plant resting at u0 with the tip at y0 (0: straight) and both tendons unloaded."""
    st = np.zeros(STATE_LEN)
    st[0] = u0
    st[1] = y0
    return st


def run(u: np.ndarray, p: np.ndarray, st: np.ndarray):
    """Convenience wrapper: returns (y, load_pos, load_neg); st is advanced in place."""
    u = np.ascontiguousarray(u, dtype=np.float64)
    n = u.shape[0]
    y = np.empty(n)
    a = np.empty(n)
    b = np.empty(n)
    run_block(u, p, st, y, a, b)
    return y, a, b
