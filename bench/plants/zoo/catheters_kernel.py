"""Sample-by-sample core of the zoo catheters: two clamp recursions that see each other.

Written from docs/design.md section 3 alone (imports numpy and, optionally, numba). Each knob's tip
follows y_t = min(max(y_{t-1}, f_up(u_t)), f_dn(u_t)) with the section 3 envelopes, but the
envelope parameters may move from sample to sample:

* ``eb`` (per sample, deg) is added to both backlash widths: a viscous tendon-sheath drag that
  widens the loop with knob speed;
* the shared backbone lets the other knob's bend (its tip angle at the previous sample) move this
  knob's dead zone: ``mode`` 1 shifts both edges by ``k * y_other`` (the loop slides along the
  knob axis with the other bend's sign), 2 by ``k * |y_other|``, 3 widens the dead zone by
  ``k * |y_other|`` on each side (narrowing when k < 0, never below 40 % of its width).

With ``eb == 0`` and ``mode == 0`` the recursion is exactly section 3's (same expressions for the
derived edges dhat_pos and dhat_neg), so a catheter without effects is the base model.

Parameter vector per knob (float64, length 7): d_pos, d_neg, b_pos, b_neg, omega, h_pos, h_neg.
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

COUPLE_NONE = 0
COUPLE_SHIFT_ANGLE = 1
COUPLE_SHIFT_MAGNITUDE = 2
COUPLE_WIDTH = 3


@_jit
def _clamp_step(x, y, d_pos, d_neg, b_pos, b_neg, omega, h_pos, h_neg):
    dhat_pos = (h_pos - h_neg) / omega + d_neg + b_neg
    dhat_neg = (h_neg - h_pos) / omega + d_pos - b_pos
    if dhat_pos > d_pos:          # a backlash wider than the loop allows: the plateau vanishes
        dhat_pos = d_pos
    if dhat_neg < d_neg:
        dhat_neg = d_neg
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
    return y


@_jit
def _edges(p, mode, k, drive):
    """Dead-zone edges of one knob given the other knob's bend ``drive``."""
    d_pos = p[0]
    d_neg = p[1]
    if mode == 1:
        s = k * drive
        d_pos += s
        d_neg += s
    elif mode == 2:
        s = k * abs(drive)
        d_pos += s
        d_neg += s
    elif mode == 3:
        w = k * abs(drive)
        wmin = -0.3 * (p[0] - p[1])
        if w < wmin:
            w = wmin
        d_pos += w
        d_neg -= w
    return d_pos, d_neg


@_jit
def two_knobs(u1, u2, p1, p2, eb1, eb2, mode, k12, k21, y01, y02, yh1, yh2, sh1, sh2):
    """Advance both knobs over the shifted knob samples u1, u2.

    k12: how knob 2's bend acts on knob 1; k21: the reverse. Fills the tips yh1, yh2 and the
    dead-zone centre shifts sh1, sh2 the coupling put in effect at each sample.
    """
    y1 = y01
    y2 = y02
    for i in range(u1.shape[0]):
        dp1, dn1 = _edges(p1, mode, k12, y2)
        dp2, dn2 = _edges(p2, mode, k21, y1)
        n1 = _clamp_step(u1[i], y1, dp1, dn1, p1[2] + eb1[i], p1[3] + eb1[i], p1[4], p1[5], p1[6])
        n2 = _clamp_step(u2[i], y2, dp2, dn2, p2[2] + eb2[i], p2[3] + eb2[i], p2[4], p2[5], p2[6])
        sh1[i] = 0.5 * (dp1 + dn1 - p1[0] - p1[1])
        sh2[i] = 0.5 * (dp2 + dn2 - p2[0] - p2[1])
        y1 = n1
        y2 = n2
        yh1[i] = y1
        yh2[i] = y2


def run_two(u1, u2, p1, p2, eb1=None, eb2=None, mode=0, k12=0.0, k21=0.0, y0=(0.0, 0.0)):
    """Convenience wrapper: returns (yh1, yh2, shift1, shift2)."""
    u1 = np.ascontiguousarray(u1, dtype=np.float64)
    u2 = np.ascontiguousarray(u2, dtype=np.float64)
    n = u1.shape[0]
    z = np.zeros(n)
    eb1 = z if eb1 is None else np.ascontiguousarray(eb1, dtype=np.float64)
    eb2 = z if eb2 is None else np.ascontiguousarray(eb2, dtype=np.float64)
    yh1, yh2, s1, s2 = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    two_knobs(u1, u2, np.asarray(p1, dtype=np.float64), np.asarray(p2, dtype=np.float64),
              eb1, eb2, int(mode), float(k12), float(k21), float(y0[0]), float(y0[1]),
              yh1, yh2, s1, s2)
    return yh1, yh2, s1, s2
