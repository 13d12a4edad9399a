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

from .. import kernel

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


SPEED_TAU = 0.05
"""Time constant (s) of the knob-speed estimate a speed-widened backlash reads (``rate`` form
``backlash``).

The speed is ``v = (x - lag(x, SPEED_TAU)) / SPEED_TAU``: the first-order filtered derivative of
the knob input, with :func:`lag_kernel`'s exact discretisation, so a ramp of speed v reads exactly
v once the filter has settled (about 3 * SPEED_TAU after a change of speed). Why not a backward
difference: a knob reading quantised to q deg at sample rate fs makes ``dx/dt`` jump by ``q * fs``
(0.01 deg at 2 kHz: 20 deg/s of noise), while this filter's noise is ``q / SPEED_TAU`` (0.2 deg/s)
whatever the rate, and it reads the same speed on a run decimated for the diagnosis' search. 0.05 s
trails a speed change by less than the backlash crossing takes at catheter speeds (a few deg at
10-40 deg/s: 0.1-0.5 s)."""


def new_speed_state() -> np.ndarray:
    """A knob-speed estimate's state at rest (a lag state ``[z, t, x]``; NaN: at rest, speed 0)."""
    return np.full(LAG_STATE, np.nan)


@njit(cache=True, fastmath=False)
def _speed_step(xi, ti, st, tau):
    # one sample of lag_kernel on the knob input (st = [z, t, x], NaN: at rest on xi) and the
    # speed it reads after it: (x - z) / tau, the same operations as knob_speed_kernel
    if math.isnan(st[0]):
        st[0], st[1], st[2] = xi, ti, xi
        return 0.0
    dt = ti - st[1]
    if dt > 0.0:
        e = math.exp(-dt / tau)
        lag = tau * (xi - st[2]) / dt
        st[0] = xi - lag + e * (st[0] - st[2] + lag)
    st[1] = ti
    st[2] = xi
    return (xi - st[0]) / tau


@njit(cache=True, fastmath=False)
def knob_speed_kernel(x, t, tau, st, out):
    """The knob-speed estimate (deg/s) of :data:`SPEED_TAU`'s notes at every sample, from state ``st``
    (``[z, t, x]`` of the last sample, NaN: at rest); leaves ``st`` at the last sample."""
    for i in range(x.shape[0]):
        out[i] = _speed_step(x[i], t[i], st, tau)


@njit(cache=True, fastmath=False)
def forward_edges_kernel(x, offset, d_pos, d_neg, dhat_pos, dhat_neg, omega, h_pos, h_neg, dp, dn, ep, en, y0, out):
    """The clamp recursion of docs/design.md section 3 with edges that move sample by sample.

    At sample i the edges are ``d_pos + dp[i]`` and ``d_neg + dn[i]``; the far edges (the backlash
    plateaus' ends) follow them by eq. D_hats (``dhat_pos`` moves with ``d_neg``, ``dhat_neg`` with
    ``d_pos``) and move apart from them by ``ep[i]``, ``en[i]``: ``dhat_pos + dn[i] + ep[i]`` and
    ``dhat_neg + dp[i] + en[i]`` (a backlash width b_neg grows by ``ep``, b_pos by ``-en``). An
    empty ``dp``/``dn`` or ``ep``/``en`` pair means no such move (the numbers are then those of the
    kernel without it, bit for bit). Where a move makes the envelopes cross, the descending one
    wins (the clamp's order), as in the static model.
    """
    moved = dp.shape[0] > 0
    apart = ep.shape[0] > 0
    y = y0
    a = 0.0
    b = 0.0
    for i in range(x.shape[0]):
        u = x[i] - offset
        if moved:
            a, b = dn[i], dp[i]
        far_pos = u - dhat_pos - a
        far_neg = u - dhat_neg - b
        if apart:
            far_pos = far_pos - ep[i]
            far_neg = far_neg - en[i]
        lo, hi = kernel.envelopes(far_pos, u - d_pos - b, u - d_neg - a, far_neg, omega, h_pos, h_neg)
        y = kernel.clamp(y, lo, hi)
        out[i] = y
    return y


@njit(cache=True, fastmath=False)
def inverse_edges_kernel(r, offset, d_pos, d_neg, dhat_pos, dhat_neg, omega, h_pos, h_neg, dp, dn, ep, en,
                         widen, lead, t, sst, y0, x0, out):
    """Exact inverse of :func:`forward_edges_kernel` (the moving-edge form of the model's inverse).

    ``dp``, ``dn``, ``ep``, ``en`` as there (empty: none). ``widen`` (s) adds a backlash that grows
    with the speed of the command this kernel writes: both plateau ends move apart by
    ``widen * |v|``, ``v`` the knob-speed estimate (:func:`knob_speed_kernel`, state ``sst``,
    times ``t``) *up to the previous sample*. Being one sample behind, the move is known before
    ``x_i`` is solved for, so the solve stays explicit and exact: :func:`forward_edges_kernel` with
    ``ep = widen * |v_{i-1}|``, ``en = -ep`` gives ``r`` back, for ``widen <= SPEED_TAU``.

    Beyond that the command's own speed feeds back: a step of the command reads as speed, which
    widens the backlash, which asks for a further step, ``widen / SPEED_TAU`` times the last: for a
    ratio above 1 an exact inverse is unstable (it rings into any limit). The inverse then reads its
    speed through a slower filter, :func:`inverse_speed_tau` (``2 * widen``: a loop gain of about 1/2), so
    it is stable but approximate where the speed changes (after a reversal, for about that time);
    at a steady speed both read the same speed and the command is exact again.

    A plateau end moved past its dead-zone edge (``dhat_pos + ... > d_pos``: the dead zone used
    up) leaves the envelope continuous and monotone with slope ``2 omega`` between the two (both
    tendons act at once, :func:`forward_edges_kernel`'s sum); its inverse there is the middle case
    below. Returns the hysteresis output at the end and the number of samples where a widened
    command's step was limited to ``lead`` deg (0: exact everywhere; module :mod:`.rate` notes).
    ``widen == 0``: ``t``, ``sst`` and ``lead`` are not read.
    """
    moved = dp.shape[0] > 0
    apart = ep.shape[0] > 0
    y = y0
    x = x0
    a = 0.0
    b = 0.0
    v = 0.0
    limited = 0
    tau = inverse_speed_tau(widen)
    if widen != 0.0 and not math.isnan(sst[0]):
        v = (sst[2] - sst[0]) / tau  # the speed after the last sample of an earlier call
    for i in range(r.shape[0]):
        ri = r[i]
        if moved:
            a, b = dn[i], dp[i]
        far_pos = dhat_pos + a
        far_neg = dhat_neg + b
        if apart:
            far_pos = far_pos + ep[i]
            far_neg = far_neg + en[i]
        if widen != 0.0:
            g = widen * abs(v)
            far_pos = far_pos + g
            far_neg = far_neg - g
        xp = x
        yp = y
        x = kernel.inverse_step(ri, y, x, d_pos + b, far_pos, d_neg + a, far_neg, omega, h_pos, h_neg, offset, True)
        if ri > y or ri < y:
            y = ri
        if widen != 0.0:
            if x > xp + lead or x < xp - lead:
                # a step beyond the lead limit: the command's own speed widens the backlash it
                # must cross (rate notes); take the limited step and the output it reaches
                x = xp + lead if x > xp else xp - lead
                limited += 1
                y = _forward_one(x - offset, yp, d_pos, d_neg, far_pos, far_neg, b, a, omega, h_pos, h_neg)
            v = _speed_step(x, t[i], sst, tau)
        out[i] = x
    return y, limited


@njit(cache=True, fastmath=False)
def inverse_speed_tau(widen):
    """Time constant (s) of the speed estimate :func:`inverse_edges_kernel` reads for a backlash
    widening ``widen`` (s): :data:`SPEED_TAU` (the forward's, exact) up to ``widen = SPEED_TAU``,
    ``2 * widen`` beyond (a stable loop; its notes)."""
    return SPEED_TAU if widen <= SPEED_TAU else 2.0 * widen


@njit(cache=True, fastmath=False)
def _forward_one(u, y, d_pos, d_neg, far_pos, far_neg, b, a, omega, h_pos, h_neg):
    # one sample of forward_edges_kernel with the far edges already moved
    lo, hi = kernel.envelopes(u - far_pos, u - d_pos - b, u - d_neg - a, u - far_neg, omega, h_pos, h_neg)
    return kernel.clamp(y, lo, hi)


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
# one sample at a time, in plain Python floats (the streaming compensator, hystcli/stream/)
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
