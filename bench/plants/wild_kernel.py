"""Sample-by-sample core of the wild plants: the stateful recursions, compiled with numba.

The tip's clamp recursion, the two tendons' play operators, the capstan direction state, the
servo's first-order lag and the stiction bursts at reversals all depend on the path, not just on
the current knob angle, so they run here in one loop. Everything algebraic (the current built from
these states, the instrument's noise) is vectorised numpy in `wild.py`.

The state vector `st` (float64[8], updated in place so that a plant can be advanced chunk by
chunk) holds: 0 actual knob angle, 1 tip, 2 positive tendon play output, 3 negative tendon play
output, 4 capstan direction (-1..1), 5 stiction burst, 6 sign of the last non-zero velocity,
7 time of the last point. The parameter vector `prm` holds the `P_*` indices below.
"""

from __future__ import annotations

import numpy as np
from numba import njit

P_OFFSET = 0
P_D_POS = 1
P_D_NEG = 2
P_DHAT_POS = 3
P_DHAT_NEG = 4
P_OMEGA = 5
P_H_POS = 6
P_H_NEG = 7
P_WALL_SIDE = 8
P_WALL_Y = 9
P_BETA_POS = 10
P_BETA_NEG = 11
P_EPS_DIR = 12
P_SERVO_TAU = 13
P_STICTION_AMP = 14
P_STICTION_TAU = 15
N_PRM = 16

S_Q = 0
S_Y = 1
S_ZP = 2
S_ZN = 3
S_DIR = 4
S_BURST = 5
S_SIGN = 6
S_T = 7
N_STATE = 8


@njit(cache=True)
def _f_up(u, d_pos, dhat_pos, omega, h_pos):
    if u < dhat_pos:
        return omega * (u - dhat_pos) + h_pos
    if u > d_pos:
        return omega * (u - d_pos) + h_pos
    return h_pos


@njit(cache=True)
def _f_dn(u, d_neg, dhat_neg, omega, h_neg):
    if u < d_neg:
        return omega * (u - d_neg) + h_neg
    if u > dhat_neg:
        return omega * (u - dhat_neg) + h_neg
    return h_neg


@njit(cache=True)
def clamp_path(u, y0, d_pos, d_neg, dhat_pos, dhat_neg, omega, h_pos, h_neg, pass_min):
    """Tip of the free knob along the loop coordinate `u`, and which edges the path passes.

    Parameters
    ----------
    u : ndarray
        Knob angle minus the loop's offset, one value per point.
    y0 : float
        Tip before the first point.
    d_pos, d_neg, dhat_pos, dhat_neg, omega, h_pos, h_neg : float
        The loop (see `KnobTruth`).
    pass_min : float
        Knob travel past an edge, on the loading branch, that counts as passing it.

    Returns
    -------
    y : ndarray
        Tip at every point: y_t = min(max(y_{t-1}, f_up(u_t)), f_dn(u_t)).
    passes_pos, passes_neg : bool
        Whether the tip, having rested on a dead-zone flat, climbed (fell) along the loading
        branch to at least `pass_min` beyond d_pos (d_neg).
    """
    n = u.shape[0]
    y = np.empty(n)
    yk = y0
    armed_pos = False
    armed_neg = False
    passes_pos = False
    passes_neg = False
    for i in range(n):
        ui = u[i]
        fu = _f_up(ui, d_pos, dhat_pos, omega, h_pos)
        fd = _f_dn(ui, d_neg, dhat_neg, omega, h_neg)
        yk = min(max(yk, fu), fd)
        y[i] = yk
        if yk == fu:
            if ui <= d_pos and ui >= dhat_pos:
                armed_pos = True
            elif ui >= d_pos + pass_min and armed_pos:
                passes_pos = True
        else:
            armed_pos = False
        if yk == fd:
            if ui >= d_neg and ui <= dhat_neg:
                armed_neg = True
            elif ui <= d_neg - pass_min and armed_neg:
                passes_neg = True
        else:
            armed_neg = False
    return y, passes_pos, passes_neg


@njit(cache=True)
def advance(t, q_cmd, v_cmd, st, prm):
    """Advance the plant's path-dependent state over commanded points.

    Parameters
    ----------
    t : ndarray
        Times (s), non-decreasing, after `st[S_T]`.
    q_cmd, v_cmd : ndarray
        Commanded knob angle (deg) and its rate (deg/s) at `t`; with a servo lag the actual
        knob follows q_cmd through a first-order lag and v_cmd is not used.
    st : ndarray
        State vector (see the module docstring), updated in place to the last point.
    prm : ndarray
        Parameter vector (`P_*` indices).

    Returns
    -------
    out : ndarray, shape (7, n)
        Rows: actual knob angle, its rate, tip (with the wall), positive and negative play
        outputs, capstan direction, stiction burst.
    """
    n = t.shape[0]
    out = np.empty((7, n))
    offset = prm[P_OFFSET]
    d_pos = prm[P_D_POS]
    d_neg = prm[P_D_NEG]
    dhat_pos = prm[P_DHAT_POS]
    dhat_neg = prm[P_DHAT_NEG]
    omega = prm[P_OMEGA]
    h_pos = prm[P_H_POS]
    h_neg = prm[P_H_NEG]
    wall_side = prm[P_WALL_SIDE]
    wall_y = prm[P_WALL_Y]
    beta_pos = prm[P_BETA_POS]
    beta_neg = prm[P_BETA_NEG]
    eps = prm[P_EPS_DIR]
    tau = prm[P_SERVO_TAU]
    amp = prm[P_STICTION_AMP]
    stau = prm[P_STICTION_TAU]
    q = st[S_Q]
    y = st[S_Y]
    zp = st[S_ZP]
    zn = st[S_ZN]
    s = st[S_DIR]
    burst = st[S_BURST]
    last_sign = st[S_SIGN]
    t_prev = st[S_T]
    for i in range(n):
        dt = t[i] - t_prev
        if dt < 0.0:
            dt = 0.0
        u_prev = q - offset
        if tau > 0.0:
            q = q + (1.0 - np.exp(-dt / tau)) * (q_cmd[i] - q)
            v = (q_cmd[i] - q) / tau
        else:
            q = q_cmd[i]
            v = v_cmd[i]
        u = q - offset
        fu = _f_up(u, d_pos, dhat_pos, omega, h_pos)
        fd = _f_dn(u, d_neg, dhat_neg, omega, h_neg)
        y = min(max(y, fu), fd)
        if wall_side > 0.0:
            y = min(y, wall_y)
        elif wall_side < 0.0:
            y = max(y, wall_y)
        zp = min(max(zp, u), u + beta_pos)
        zn = min(max(zn, u - beta_neg), u)
        s = min(max(s + 2.0 * (u - u_prev) / eps, -1.0), 1.0)
        if stau > 0.0:
            burst = burst * np.exp(-dt / stau)
        sign = 0.0
        if v > 1e-9:
            sign = 1.0
        elif v < -1e-9:
            sign = -1.0
        if sign != 0.0:
            if last_sign != 0.0 and sign != last_sign:
                burst = burst + amp * sign
            last_sign = sign
        t_prev = t[i]
        out[0, i] = q
        out[1, i] = v
        out[2, i] = y
        out[3, i] = zp
        out[4, i] = zn
        out[5, i] = s
        out[6, i] = burst
    st[S_Q] = q
    st[S_Y] = y
    st[S_ZP] = zp
    st[S_ZN] = zn
    st[S_DIR] = s
    st[S_BURST] = burst
    st[S_SIGN] = last_sign
    st[S_T] = t_prev
    return out
