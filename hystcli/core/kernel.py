"""The one hysteresis kernel: envelopes, the clamp update, the one-sample inverse, whole runs.

The dead-zone + backlash model of docs/design.md section 3 (paper eqs. D_hats and model_eqs) is a
recursion: the output is held until an envelope at the present knob angle pushes it,

    y_t = min(max(y_{t-1}, f_up(u_t)), f_dn(u_t)),

and its exact inverse puts the knob on the ascending envelope when the desired output rises and on
the descending one when it falls. This module is the only place that writes either: prediction
(:class:`hystcli.core.params.KnobModel`), the effect chain's moving-edge kernels
(:mod:`hystcli.core.effects.kernels`), the streaming compensator (:mod:`hystcli.stream`), the tip fit
(:mod:`hystcli.identification.tip`) and the twin all call the functions below.

Every function is compiled with numba (``fastmath=False``: IEEE operations in source order), and
each one-sample function is plain Python underneath (``.py_func``): the streaming compensator runs
those on Python floats, where a numba call would cost as much as the arithmetic. Both give the same
numbers bit for bit, because they do the same operations in the same order. Callers pass the
envelope arguments as *gaps* (``u - edge``) computed in their own order: moving an edge by ``a``
as ``u - dhat_pos - a`` and as ``u - (dhat_pos + a)`` round differently, and each caller keeps the
numbers it has always had.

Importing this module imports numba but compiles nothing; :mod:`hystcli.core.params` imports it on the
first prediction, so ``import hystcli`` stays light.
"""
from __future__ import annotations

from numba import njit

_JIT = {"cache": True, "fastmath": False}


# --------------------------------------------------------------------------------------------
# one sample
# --------------------------------------------------------------------------------------------
@njit(**_JIT)
def clamp(y, lo, hi):
    """The clamp update: ``y`` held unless the ascending envelope ``lo`` or the descending one
    ``hi`` pushes it (where they cross, the descending one wins)."""
    if y < lo:
        y = lo
    if y > hi:
        y = hi
    return y


@njit(**_JIT)
def envelopes(g_far_pos, g_near_pos, g_near_neg, g_far_neg, omega, h_pos, h_neg):
    """The ascending and descending envelopes (lines L2-L4 and L8-L6) from the gaps of the knob
    angle to the four edges: ``u - dhat_pos``, ``u - d_pos``, ``u - d_neg``, ``u - dhat_neg``
    (branch-free: ``h + omega (min(u - a, 0) + max(u - b, 0))``)."""
    lo = h_pos + omega * (min(g_far_pos, 0.0) + max(g_near_pos, 0.0))
    hi = h_neg + omega * (min(g_near_neg, 0.0) + max(g_far_neg, 0.0))
    return lo, hi


@njit(**_JIT)
def forward_step(y, u, d_pos, d_neg, dhat_pos, dhat_neg, omega, h_pos, h_neg):
    """One sample of the forward recursion at the unshifted knob angle ``u``."""
    lo, hi = envelopes(u - dhat_pos, u - d_pos, u - d_neg, u - dhat_neg, omega, h_pos, h_neg)
    return clamp(y, lo, hi)


@njit(**_JIT)
def unit_envelopes(u, dn, dp, dhp, dhn, half):
    """The envelopes in the tip fit's normalised coordinates (omega 1, heights -+``half``): the
    fit's own association of the sums, ``-half + min(u - dhp, 0) + max(u - dp, 0)``."""
    lo = -half + min(u - dhp, 0.0) + max(u - dp, 0.0)
    hi = half + min(u - dn, 0.0) + max(u - dhn, 0.0)
    return lo, hi


@njit(**_JIT)
def unit_step(z, u, dn, dp, dhp, dhn, half):
    """One sample of the forward recursion in the tip fit's normalised coordinates."""
    lo, hi = unit_envelopes(u, dn, dp, dhp, dhn, half)
    return clamp(z, lo, hi)


@njit(**_JIT)
def inverse_step(r, y, x, near_pos, far_pos, near_neg, far_neg, omega, h_pos, h_neg, offset, overlap):
    """The knob command (shifted by ``offset``) that takes the output from ``y`` to ``r``.

    Rising: the smallest knob angle on the ascending envelope reaching ``r`` (past the dead zone
    above ``h_pos``, on the far edge's line below it); falling: the largest on the descending one;
    ``r == y``: the command ``x`` is held. ``near_*``/``far_*`` are the dead-zone edges and the
    backlash plateaus' ends as the caller moved them. ``overlap``: a plateau end moved past its
    edge (the dead zone used up) leaves a line of slope ``2 omega`` between the two, solved there.
    """
    if r > y:
        if (overlap and far_pos > near_pos
                and h_pos + omega * (near_pos - far_pos) < r <= h_pos + omega * (far_pos - near_pos)):
            x = 0.5 * (far_pos + near_pos + (r - h_pos) / omega) + offset
        elif r > h_pos:
            x = near_pos + (r - h_pos) / omega + offset
        else:
            x = far_pos + (r - h_pos) / omega + offset
    elif r < y:
        if (overlap and far_neg < near_neg
                and h_neg + omega * (far_neg - near_neg) <= r < h_neg + omega * (near_neg - far_neg)):
            x = 0.5 * (far_neg + near_neg + (r - h_neg) / omega) + offset
        elif r < h_neg:
            x = near_neg + (r - h_neg) / omega + offset
        else:
            x = far_neg + (r - h_neg) / omega + offset
    return x


# the one-sample functions as plain Python, for a caller that runs on Python floats
clamp_py = clamp.py_func
envelopes_py = envelopes.py_func
inverse_step_py = inverse_step.py_func


# --------------------------------------------------------------------------------------------
# whole runs
# --------------------------------------------------------------------------------------------
@njit(**_JIT)
def forward(x, offset, d_pos, d_neg, dhat_pos, dhat_neg, omega, h_pos, h_neg, y0, out):
    """The forward recursion over knob angles ``x`` from output ``y0``; writes ``out``, returns
    the last output."""
    y = y0
    for i in range(x.shape[0]):
        y = forward_step(y, x[i] - offset, d_pos, d_neg, dhat_pos, dhat_neg, omega, h_pos, h_neg)
        out[i] = y
    return y


@njit(**_JIT)
def inverse(r, offset, d_pos, d_neg, dhat_pos, dhat_neg, omega, h_pos, h_neg, y0, x0, out):
    """The exact inverse over desired outputs ``r`` from output ``y0`` and knob angle ``x0``;
    writes the commands to ``out``, returns the last output."""
    y = y0
    x = x0
    for i in range(r.shape[0]):
        ri = r[i]
        x = inverse_step(ri, y, x, d_pos, dhat_pos, d_neg, dhat_neg, omega, h_pos, h_neg, offset, False)
        if ri > y or ri < y:  # not NaN: a comparison with it is false and y is held
            y = ri
        out[i] = x
    return y


__all__ = ["clamp", "clamp_py", "envelopes", "envelopes_py", "forward", "forward_step", "inverse",
           "inverse_step", "inverse_step_py", "unit_envelopes", "unit_step"]
