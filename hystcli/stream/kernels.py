"""The coupling's per-sample fixed point of :class:`hystcli.Compensator`, compiled.

A two-knob model whose inverse chain reads the other knob (``coupling``) solves, per sample, the
same fixed-point iteration the batch inverse runs over a whole run: each pass restarts both
knobs' coupled stages (the chain's *tail*) from the sample's state, and the other knob's command
is taken through its input lags first (what the cross-talk sees of it). In plain Python floats
that is a dozen passes over a handful of stage objects, ~50 us a sample; here the passes run in
one numba call over preallocated arrays (a few us with the call's own cost).

The stages are an op table: each row ``[code, par, st]`` names an op and where its parameters
(``par``) and its state (``st``) start. Ops:

=========  ===================================================  ===============================
code       one sample                                           par / state
=========  ===================================================  ===============================
COUPLE     ``z + g D`` (input forms) / ``z - g D`` (output        gain, sign, magnitude / none
           forms), ``D = other`` or ``|other|`` (``other``: the
           other knob's command, or its bend for the magnitude
           forms); the identity when the other knob is not given
UNLAG      :class:`hystcli.core.effects.kernels.UnlagStep`             fraction, tau, lead / fresh,
                                                                  u, z, tp, dt, e, c
HYST       ``_Hysteresis.step`` of hystcli/stream/stages.py       the knob's 8 kernel args, n,
           (edges moved by the deadzone couplings)                (gain, magnitude) x n / y, x
LAG        :class:`hystcli.core.effects.kernels.LagStep` (what the     tau / fresh, z, tp, up, dt, e
           other knob's coupling sees of a command)
BEND       ``_Bend.step`` of hystcli/stream/stages.py: the        the knob's 8 kernel args / y
           knob's base model forward, its bend as the other
           knob's magnitude coupling sees it
=========  ===================================================  ===============================

Every op does the same IEEE operations in the same order as its Python stage, so a step gives
the Python path's numbers (``exp`` may differ by an ulp). Importing this module compiles nothing:
the kernel compiles (or loads from numba's cache) on its first call; ``hystcli.stream.stages``
imports it only when a compensator has a coupled chain, so ``import hystcli`` stays light.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..core import kernel

COUPLE, UNLAG, HYST, LAG, BEND = 0, 1, 2, 3, 4
"""Op codes of the table (module notes)."""

STATE_SIZE = {COUPLE: 0, UNLAG: 7, HYST: 2, LAG: 6, BEND: 1}
"""Floats of state per op."""


@njit(cache=True, fastmath=False)
def _run(lo, hi, z, t, other, has_other, ops, par, st, work):
    # ops lo..hi-1 on one sample: read each op's state from st (the sample's start), write it to
    # work. A lag's cache of exp() for the last sample interval is read from and kept in work
    # (every pass of a sample has the same interval: one exp per sample, as the Python stages)
    for i in range(lo, hi):
        code = ops[i, 0]
        p = ops[i, 1]
        s = ops[i, 2]
        if code == 0:  # COUPLE
            if has_other:
                if par[p + 2] != 0.0:
                    d = abs(other)
                else:
                    d = other
                if par[p + 1] > 0.0:
                    z = z + par[p] * d
                else:
                    z = z - par[p] * d
        elif code == 1:  # UNLAG
            if st[s] != 0.0:
                # at rest on the first target
                work[s] = 0.0
                work[s + 1] = z
                work[s + 2] = z
                work[s + 3] = t
            else:
                f = par[p]
                tau = par[p + 1]
                lead = par[p + 2]
                u = st[s + 1]
                zz = st[s + 2]
                dt = t - st[s + 3]
                dt_c = work[s + 4]
                e = work[s + 5]
                c = work[s + 6]
                if dt > 0.0:
                    if dt != dt_c:
                        e = math.exp(-dt / tau)
                        c = (1.0 - e) * tau / dt
                        dt_c = dt
                    a = 1.0 - c
                    b = c * u + e * (zz - u)
                    u = (z - f * b) / (1.0 - f + f * a)
                    if u > z + lead:
                        u = z + lead
                    elif u < z - lead:
                        u = z - lead
                    zz = a * u + b
                work[s] = 0.0
                work[s + 1] = u
                work[s + 2] = zz
                work[s + 3] = t
                work[s + 4] = dt_c
                work[s + 5] = e
                work[s + 6] = c
                z = u
        elif code == 2:  # HYST
            y = st[s]
            x = st[s + 1]
            offset = par[p]
            omega = par[p + 5]
            h_pos = par[p + 6]
            h_neg = par[p + 7]
            if z > y or z < y:
                b = 0.0
                a = 0.0
                if has_other:
                    n = int(par[p + 8])
                    for j in range(n):
                        q = p + 9 + 2 * j
                        if par[q + 1] != 0.0:
                            d = abs(other)
                        else:
                            d = other
                        half = 0.5 * par[q] * d
                        b += half
                        a += -half
                x = kernel.inverse_step(z, y, x, par[p + 1] + b, par[p + 3] + a, par[p + 2] + a, par[p + 4] + b,
                                        omega, h_pos, h_neg, offset, False)
                y = z
            work[s] = y
            work[s + 1] = x
            z = x
        elif code == 4:  # BEND
            y = kernel.forward_step(st[s], z - par[p], par[p + 1], par[p + 2], par[p + 3], par[p + 4], par[p + 5],
                                    par[p + 6], par[p + 7])
            work[s] = y
            z = y
        else:  # LAG
            if st[s] != 0.0:
                work[s] = 0.0
                work[s + 1] = z
                work[s + 2] = t
                work[s + 3] = z
            else:
                tau = par[p]
                zz = st[s + 1]
                up = st[s + 3]
                dt = t - st[s + 2]
                dt_c = work[s + 4]
                e = work[s + 5]
                if dt > 0.0:
                    if dt != dt_c:
                        e = math.exp(-dt / tau)
                        dt_c = dt
                    lag = tau * (z - up) / dt
                    zz = z - lag + e * (zz - up + lag)
                work[s] = 0.0
                work[s + 1] = zz
                work[s + 2] = t
                work[s + 3] = z
                work[s + 4] = dt_c
                work[s + 5] = e
                z = zz
    return z


@njit(cache=True, fastmath=False)
def coupled_step(h1, h2, t, iterations, ops, rng, par, st, work):
    """One sample of the two knobs' coupled tails, solved by the batch inverse's fixed point.

    ``h1``, ``h2``: each knob's signal after its head (the stages that read no other knob).
    ``rng``: op ranges ``[tail1, tail2, seen1, seen2]`` as (lo, hi) pairs, ``seen_j`` being knob
    j's input lags as the other knob's coupling sees its command. ``st`` is the state at the
    sample's start and is left at its end (``work``: scratch of the same size). Returns
    ``(q1, q2, converged)``; not converged: the last iterate (the Python path's rule).
    """
    t1a, t1b, t2a, t2b = rng[0], rng[1], rng[2], rng[3]
    s1a, s1b, s2a, s2b = rng[4], rng[5], rng[6], rng[7]
    q1 = _run(t1a, t1b, h1, t, 0.0, False, ops, par, st, work)
    q2 = _run(t2a, t2b, h2, t, 0.0, False, ops, par, st, work)
    converged = False
    for _ in range(iterations):
        n1 = _run(t1a, t1b, h1, t, _run(s2a, s2b, q2, t, 0.0, False, ops, par, st, work), True,
                  ops, par, st, work)
        n2 = _run(t2a, t2b, h2, t, _run(s1a, s1b, q1, t, 0.0, False, ops, par, st, work), True,
                  ops, par, st, work)
        d1 = abs(n1 - q1)
        d2 = abs(n2 - q2)
        change = d2 if d2 > d1 else d1  # noqa: FURB136 (Python's max(d1, d2), NaN and all)
        q1 = n1
        q2 = n2
        if change < 1e-10:
            converged = True
            break
    # commit what the other knob's coupling saw of each command this sample
    _run(s1a, s1b, q1, t, 0.0, False, ops, par, st, work)
    _run(s2a, s2b, q2, t, 0.0, False, ops, par, st, work)
    for i in range(st.shape[0]):
        st[i] = work[i]
    return q1, q2, converged


def new_arrays(n_ops: int, n_par: int, n_st: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Zeroed ``ops``, ``par``, ``st`` and ``work`` arrays of those sizes."""
    return (np.zeros((n_ops, 3), dtype=np.int64), np.zeros(max(n_par, 1)), np.zeros(max(n_st, 1)),
            np.zeros(max(n_st, 1)))


__all__ = ["BEND", "COUPLE", "HYST", "LAG", "STATE_SIZE", "UNLAG", "coupled_step", "new_arrays"]
