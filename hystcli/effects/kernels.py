"""Compiled kernels the effects share: first-order lags and their exact inverses, the hysteresis
with edges that move sample by sample, and a sum of squares that never touches BLAS.

Every kernel that carries a state takes it as a small float64 array and leaves it updated, so one
call over a whole run and many calls over its pieces (one sample at a time, for a streaming
compensator) give the same numbers. A state whose first entry is NaN is "at rest before the first
sample".
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

LAG_STATE = 3
"""Size of a first-order lag's state ``[z, t, u]``: output, time and input of the last sample."""


def new_lag_state() -> np.ndarray:
    """A lag state at rest: it starts on its first input."""
    return np.full(LAG_STATE, np.nan)


@njit(cache=True, fastmath=False)
def lag_kernel(u, t, tau, st, out):
    """Exact first-order lag ``dz/dt = (u - z)/tau`` of ``u`` held linearly between samples.

    A ramp of speed v is trailed by exactly tau*v, a hold decays as exp(-t/tau). ``st`` is
    ``[z, t, u]`` of the last sample (NaN: start at rest on ``u[0]``). ``exp`` is evaluated only
    when the sample interval changes (uniform sampling: once), with the same argument, so the
    numbers are those of evaluating it every sample.
    """
    n = u.shape[0]
    if n == 0:
        return
    if math.isnan(st[0]):
        z, tp, up = u[0], t[0], u[0]
    else:
        z, tp, up = st[0], st[1], st[2]
    dt_e = -1.0
    e = 0.0
    for i in range(n):
        dt = t[i] - tp
        if dt > 0.0:
            if dt != dt_e:
                e = math.exp(-dt / tau)
                dt_e = dt
            lag = tau * (u[i] - up) / dt
            z = u[i] - lag + e * (z - up + lag)
        tp = t[i]
        up = u[i]
        out[i] = z
    st[0], st[1], st[2] = z, tp, up


@njit(cache=True, fastmath=False)
def _lag_affine(dt, tau, u_prev, z_prev):
    # one step of lag_kernel written as z_i = a u_i + b: a = 1 - c, b = c u_{i-1} + e (z_{i-1} - u_{i-1}),
    # c = (1 - e) tau / dt, e = exp(-dt/tau); both inverse kernels solve this for their own unknown
    e = math.exp(-dt / tau)
    c = (1.0 - e) * tau / dt
    return 1.0 - c, c * u_prev + e * (z_prev - u_prev)


@njit(cache=True, fastmath=False)
def partial_unlag_kernel(target, t, fraction, tau, lead, st, out):
    """Inverse of the partial lag ``y = (1 - f) u + f lag(u, tau)``, sample by sample.

    lag(u)_i = A u_i + B with A = 1 - c, B = c u_{i-1} + e (z_{i-1} - u_{i-1}), c = (1 - e) tau / dt,
    e = exp(-dt/tau), so u_i = (y_i - f B) / (1 - f + f A): unique, since 1 - f + f A > 0 for
    f < 1 and A > 0 for f = 1 (a whole lag). The inverse is stable: the map is minimum-phase. A
    knob cannot move infinitely fast: ``|u - target|`` is limited to ``lead`` deg (inf: no limit;
    the lag then catches up over the next samples). ``st`` is ``[u, z, t]`` of the last sample
    (NaN: at rest on ``target[0]``).
    """
    n = target.shape[0]
    if n == 0:
        return
    start = 0
    if math.isnan(st[0]):
        u_prev = target[0]
        z = target[0]
        tp = t[0]
        out[0] = u_prev
        start = 1
    else:
        u_prev, z, tp = st[0], st[1], st[2]
    for i in range(start, n):
        dt = t[i] - tp
        if dt > 0.0:
            a, b = _lag_affine(dt, tau, u_prev, z)
            u = (target[i] - fraction * b) / (1.0 - fraction + fraction * a)
            if u > target[i] + lead:
                u = target[i] + lead
            elif u < target[i] - lead:
                u = target[i] - lead
            z = a * u + b
        else:
            u = u_prev
        out[i] = u
        u_prev = u
        tp = t[i]
    st[0], st[1], st[2] = u_prev, z, tp


@njit(cache=True, fastmath=False)
def forward_edges_kernel(x, offset, d_pos, d_neg, dhat_pos, dhat_neg, omega, h_pos, h_neg, dp, dn, y0, out):
    """The clamp recursion of DESIGN.md section 3 with edges that move sample by sample.

    At sample i the edges are ``d_pos + dp[i]`` and ``d_neg + dn[i]``; the far edges follow by
    eq. D_hats (``dhat_pos`` moves with ``d_neg``, ``dhat_neg`` with ``d_pos``). Where a narrowing
    makes the envelopes cross, the descending one wins (the clamp's order), as in the static model.
    """
    y = y0
    for i in range(x.shape[0]):
        u = x[i] - offset
        a, b = dn[i], dp[i]
        lo = h_pos + omega * (min(u - dhat_pos - a, 0.0) + max(u - d_pos - b, 0.0))
        hi = h_neg + omega * (min(u - d_neg - a, 0.0) + max(u - dhat_neg - b, 0.0))
        if y < lo:
            y = lo
        if y > hi:
            y = hi
        out[i] = y
    return y


@njit(cache=True, fastmath=False)
def inverse_edges_kernel(r, offset, d_pos, d_neg, dhat_pos, dhat_neg, omega, h_pos, h_neg, dp, dn, y0, x0, out):
    """Exact inverse of :func:`forward_edges_kernel` (the moving-edge form of the model's inverse)."""
    y = y0
    x = x0
    for i in range(r.shape[0]):
        ri = r[i]
        a, b = dn[i], dp[i]
        if ri > y:
            if ri > h_pos:
                x = d_pos + b + (ri - h_pos) / omega + offset
            else:
                x = dhat_pos + a + (ri - h_pos) / omega + offset
            y = ri
        elif ri < y:
            if ri < h_neg:
                x = d_neg + a + (ri - h_neg) / omega + offset
            else:
                x = dhat_neg + b + (ri - h_neg) / omega + offset
            y = ri
        out[i] = x
    return y


@njit(cache=True, fastmath=False)
def sse_kernel(y, p):
    """sum((y - p)**2) in one pass: no temporary, and no BLAS threads fighting over 2 cores."""
    s = 0.0
    for i in range(y.shape[0]):
        d = y[i] - p[i]
        s += d * d
    return s


@njit(cache=True, fastmath=False)
def sumsq_kernel(r):
    """sum(r**2) in one pass (see :func:`sse_kernel`)."""
    s = 0.0
    for i in range(r.shape[0]):
        s += r[i] * r[i]
    return s


# --------------------------------------------------------------------------------------------
# one sample at a time, in plain Python floats (the streaming compensator, hystcli/stream.py)
# --------------------------------------------------------------------------------------------
# A numba call costs about as much as the whole one-sample arithmetic (its dispatcher boxes the
# arguments), so a streaming step runs these plain-float mirrors of the kernels above instead.
# They do the same IEEE operations in the same order, so they give the kernels' numbers; exp()
# may differ from numba's by an ulp.
class LagStep:
    """:func:`lag_kernel` one sample at a time (the forward lag of the other knob's command that
    the coupling's inverse reads)."""

    __slots__ = ("tau", "z", "tp", "up", "fresh", "_dt", "_e")

    def __init__(self, tau: float) -> None:
        self.tau = float(tau)
        self.reset()

    def reset(self) -> None:
        self.fresh = True
        self.z = self.tp = self.up = 0.0
        self._dt = -1.0
        self._e = 0.0

    def step(self, u: float, t: float, other: float | None = None) -> float:
        if self.fresh:
            self.fresh = False
            self.z, self.tp, self.up = u, t, u
            return u
        dt = t - self.tp
        if dt > 0.0:
            if dt != self._dt:
                self._e = math.exp(-dt / self.tau)
                self._dt = dt
            lag = self.tau * (u - self.up) / dt
            self.z = u - lag + self._e * (self.z - self.up + lag)
        self.tp = t
        self.up = u
        return self.z

    def save(self) -> tuple:
        return (self.fresh, self.z, self.tp, self.up)

    def load(self, s: tuple) -> None:
        self.fresh, self.z, self.tp, self.up = s


class UnlagStep:
    """:func:`partial_unlag_kernel` one sample at a time: the inverse of
    ``y = (1 - fraction) u + fraction lag(u, tau)``, the knob's lead limited to ``lead`` deg."""

    __slots__ = ("fraction", "tau", "lead", "u", "z", "tp", "fresh", "_dt", "_e", "_c")

    def __init__(self, fraction: float, tau: float, lead: float) -> None:
        self.fraction = float(fraction)
        self.tau = float(tau)
        self.lead = float(lead)
        self.reset()

    def reset(self) -> None:
        self.fresh = True
        self.u = self.z = self.tp = 0.0
        self._dt = -1.0
        self._e = self._c = 0.0

    def step(self, target: float, t: float, other: float | None = None) -> float:
        if self.fresh:
            # at rest on the first target (the kernel's NaN state)
            self.fresh = False
            self.u = self.z = target
            self.tp = t
            return target
        dt = t - self.tp
        u = self.u
        if dt > 0.0:
            if dt != self._dt:
                # _lag_affine's e and c depend on dt only: uniform sampling computes them once
                e = math.exp(-dt / self.tau)
                self._e, self._c, self._dt = e, (1.0 - e) * self.tau / dt, dt
            e, c = self._e, self._c
            f = self.fraction
            a = 1.0 - c
            b = c * u + e * (self.z - u)
            u = (target - f * b) / (1.0 - f + f * a)
            if u > target + self.lead:
                u = target + self.lead
            elif u < target - self.lead:
                u = target - self.lead
            self.z = a * u + b
        self.u = u
        self.tp = t
        return u

    def save(self) -> tuple:
        return (self.fresh, self.u, self.z, self.tp)

    def load(self, s: tuple) -> None:
        self.fresh, self.u, self.z, self.tp = s


class Cascade:
    """One-sample stages in series (a second-order lag is two first-order ones)."""

    __slots__ = ("steps",)

    def __init__(self, steps) -> None:
        self.steps = tuple(steps)

    def reset(self) -> None:
        for s in self.steps:
            s.reset()

    def step(self, z: float, t: float, other: float | None = None) -> float:
        for s in self.steps:
            z = s.step(z, t)
        return z

    def save(self) -> tuple:
        return tuple(s.save() for s in self.steps)

    def load(self, state: tuple) -> None:
        for s, v in zip(self.steps, state):
            s.load(v)


class StatelessStep:
    """A one-sample stage without state: ``fn(z, other)``."""

    __slots__ = ("fn",)

    def __init__(self, fn) -> None:
        self.fn = fn

    def reset(self) -> None:
        pass

    def step(self, z: float, t: float, other: float | None = None) -> float:
        return self.fn(z, other)

    def save(self) -> tuple:
        return ()

    def load(self, state: tuple) -> None:
        pass
