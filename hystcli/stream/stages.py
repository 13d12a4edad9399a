"""The stages of the streaming compensator, one sample at a time: the hysteresis inverse, a knob's
bend as the other knob's coupling reads it, one knob's chain, and the coupled chains' compiled
fixed point (:mod:`hystcli.stream.kernels`). :class:`hystcli.stream.Compensator` drives them."""
from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from ..core.effects import chain, kernels
from ..core.effects.base import Effect, Signals
from ..core.kernel import clamp_py as _clamp, envelopes_py as _envelopes, inverse_step_py as _inverse_step
from ..core.params import KnobModel


class _Hysteresis:
    """The hysteresis inverse of docs/design.md section 3, one sample at a time (:func:`hystcli.core.kernel.inverse_step`
    on plain floats, as ``inverse_edges_kernel`` of the batch path runs it)."""

    __slots__ = ("kn", "offset", "d_pos", "d_neg", "dhat_pos", "dhat_neg", "omega", "h_pos", "h_neg",
                 "y", "x", "fresh", "y0", "edges", "outputs", "k", "widen", "speed", "lead", "warnings", "tau")

    def __init__(self, kn: KnobModel, k: int, edges: Sequence[Effect], outputs: Sequence[Effect],
                 widen: float = 0.0, lead: float = 30.0, warnings: list[str] | None = None) -> None:
        self.k = k
        self.edges = tuple(edges)          # coupling that moves the dead zone (reads the other knob)
        self.outputs = tuple(outputs)      # output stages: where the hysteresis starts behind a reading
        # a backlash that widens with the knob's speed (rate form backlash): the plateau ends move
        # apart by widen*|v|, v the speed estimate of the commands up to the previous sample
        # (kernels.inverse_edges_kernel: the speed is (x - lag(x, tau)) / tau, its lag one LagStep)
        self.widen = float(widen)
        self.tau = float(kernels.inverse_speed_tau(self.widen))
        self.speed = kernels.LagStep(self.tau)
        self.lead = float(lead)
        self.warnings = warnings
        self.y0 = 0.0
        self.set_knob(kn)
        self.reset(0.0)

    def set_knob(self, kn: KnobModel) -> None:
        self.kn = kn
        (self.offset, self.d_pos, self.d_neg, self.dhat_pos, self.dhat_neg, self.omega, self.h_pos,
         self.h_neg) = kn._kernel_args()

    def reset(self, y0: float) -> None:
        self.fresh = True
        self.y0 = float(y0)
        self.y = self.x = 0.0
        self.speed.reset()   # the speed estimate at rest

    def _start(self, other: float | None) -> None:
        # the hysteresis state behind the tip reading y0 at rest, as the batch inverse starts it
        # (what the coupling sees of the other knob: its command, or its bend for the magnitude forms)
        other_arr = None if other is None else np.array([other])
        sig = Signals(self.k, None, other_arr, 0.0, 0.0, "stream", other_arr)
        yh0 = self.y0
        for e in reversed(self.outputs):
            yh0 = e.type.at_rest(e, yh0, sig)
        self.y = yh0
        self.x = self.kn.holding_knob_angle(yh0)
        self.fresh = False

    def step(self, r: float, t: float, other: float | None = None) -> float:
        if self.fresh:
            self._start(other)
        y = self.y
        if r == y:
            if self.widen != 0.0:
                self.speed.step(self.x, t)
            return self.x
        # the dead-zone edges as the other knob moves them this sample (coupling)
        b = a = 0.0
        if other is not None:
            for e in self.edges:
                dp, dn = e.type.edges_at(e, other)
                b += dp
                a += dn
        far_pos = self.dhat_pos + a
        far_neg = self.dhat_neg + b
        if self.widen != 0.0:
            s = self.speed
            v = 0.0 if s.fresh else (s.up - s.z) / self.tau
            g = self.widen * abs(v)
            far_pos = far_pos + g
            far_neg = far_neg - g
        xp = self.x
        self.x = _inverse_step(r, y, xp, self.d_pos + b, far_pos, self.d_neg + a, far_neg, self.omega,
                               self.h_pos, self.h_neg, self.offset, True)
        if r > y or r < y:  # not NaN: the batch kernel holds y on it
            self.y = r
        if self.widen != 0.0:
            x = self.x
            if x > xp + self.lead or x < xp - self.lead:
                # kernels.inverse_edges_kernel's lead limit, the same operations
                x = self.x = xp + self.lead if x > xp else xp - self.lead
                u = x - self.offset
                lo, hi = _envelopes(u - far_pos, u - self.d_pos - b, u - self.d_neg - a, u - far_neg,
                                    self.omega, self.h_pos, self.h_neg)
                self.y = _clamp(y, lo, hi)
                if self.warnings is not None:
                    self.warnings.append(chain._lead_warning(self.k, self.widen, self.lead))
            self.speed.step(self.x, t)
        return self.x

    def save(self) -> tuple:
        return (self.fresh, self.y, self.x, self.speed.save())

    def load(self, s: tuple) -> None:
        self.fresh, self.y, self.x, speed = s
        self.speed.load(speed)

    @property
    def plain(self) -> bool:
        """True when the compiled :func:`hystcli.core.kernel.inverse` gives this stage's numbers."""
        return not self.edges and self.widen == 0.0


class _Bend:
    """The forward hysteresis of docs/design.md section 3 one sample at a time (:mod:`hystcli.core.kernel`'s
    envelopes and clamp on plain floats): a knob's bend as its base model predicts it, what the other knob's
    magnitude coupling reads (:mod:`hystcli.core.effects.coupling`)."""

    __slots__ = ("kn", "y")

    def __init__(self, kn: KnobModel) -> None:
        self.kn = kn
        self.y = 0.0

    def reset(self, y0: float = 0.0) -> None:
        self.y = float(y0)

    def step(self, q: float, t: float = 0.0) -> float:
        offset, d_pos, d_neg, dhat_pos, dhat_neg, omega, h_pos, h_neg = self.kn._kernel_args()
        u = q - offset
        lo, hi = _envelopes(u - dhat_pos, u - d_pos, u - d_neg, u - dhat_neg, omega, h_pos, h_neg)
        self.y = y = _clamp(self.y, lo, hi)
        return y

    def save(self) -> float:
        return self.y

    def load(self, y: float) -> None:
        self.y = y


class _Knob:
    """One knob's inverse chain: the steps before the first one that reads the other knob
    (``head``), then the rest (``tail``), and what the other knob looks like to it (``seen``)."""

    __slots__ = ("k", "head", "tail", "hyst", "seen")

    def __init__(self, k: int, head: list, tail: list, hyst: _Hysteresis, seen: list) -> None:
        self.k = k
        self.head = head
        self.tail = tail
        self.hyst = hyst
        self.seen = seen          # forward steps of this knob's command as the other knob's coupling sees it

    def run(self, z: float, t: float, other: float | None) -> float:
        for s in self.head:
            z = s.step(z, t, None)
        for s in self.tail:
            z = s.step(z, t, other)
        return z

    def save_tail(self) -> tuple:
        return tuple(s.save() for s in self.tail)

    def load_tail(self, state: tuple) -> None:
        for s, v in zip(self.tail, state):
            s.load(v)

    def reset(self, y0: float) -> None:
        # (this knob's bend, as the other knob's coupling sees it, starts from its own tip y0)
        for s in self.head + self.tail + self.seen:
            if s is self.hyst or isinstance(s, _Bend):
                s.reset(y0)
            else:
                s.reset()


class _CompiledCoupling:
    """The coupled tails of two knobs and what each knob's coupling sees of the other's command,
    as the op table of :mod:`hystcli.stream.kernels`: the per-sample fixed point in one compiled
    call. The table owns the state of those stages (the Python stage objects of the tails and of
    ``seen`` then sit idle); the head stays in Python. Built only when every stage has an op."""

    __slots__ = ("ops", "rng", "par", "st", "work", "kernel", "pending", "_params", "_fresh", "_hysts", "_bends")

    @classmethod
    def build(cls, c1: _Knob, c2: _Knob, plan: chain.Plan) -> "_CompiledCoupling | None":
        # a hysteresis in a tail starts behind the tip reading through the output stages: done in
        # Python on the first sample, exact only when no output stage reads the other knob there
        if any(e.type.cross_knob(e) for e in plan.output) and any(
                s is c.hyst for c in (c1, c2) for s in c.tail):
            return None
        # a backlash widened by the knob's speed has no op (its speed state): the Python passes
        if any(c.hyst.widen != 0.0 and c.hyst in c.tail for c in (c1, c2)):
            return None
        table: list = []
        rng = []
        for stages in (c1.tail, c2.tail, c1.seen, c2.seen):
            lo = len(table)
            for s in stages:
                if not cls._flatten(s, table):
                    return None
            rng += [lo, len(table)]
        return cls(table, rng)

    @staticmethod
    def _flatten(s: Any, table: list) -> bool:
        from . import kernels as K
        from ..core.effects import kernels
        from ..core.effects.coupling import _CouplingStep

        if isinstance(s, kernels.Cascade):
            return all(_CompiledCoupling._flatten(x, table) for x in s.steps)
        if isinstance(s, kernels.UnlagStep):
            table.append((K.UNLAG, s))
        elif isinstance(s, kernels.LagStep):
            table.append((K.LAG, s))
        elif isinstance(s, _CouplingStep):
            table.append((K.COUPLE, s))
        elif isinstance(s, _Hysteresis):
            table.append((K.HYST, s))
        elif isinstance(s, _Bend):
            table.append((K.BEND, s))
        else:
            return False
        return True

    def __init__(self, table: list, rng: list) -> None:
        from . import kernels as K

        self.kernel = K.coupled_step
        n_par = n_st = 0
        rows = []
        for code, s in table:
            rows.append((code, n_par, n_st))
            n_par += {K.COUPLE: 3, K.UNLAG: 3, K.HYST: 9 + 2 * len(getattr(s, "edges", ())), K.LAG: 1,
                      K.BEND: 8}[code]
            n_st += K.STATE_SIZE[code]
        self.ops, self.par, self.st, self.work = K.new_arrays(len(rows), n_par, n_st)
        for i, row in enumerate(rows):
            self.ops[i] = row
        self.rng = np.asarray(rng, dtype=np.int64)
        self._params = [(code, s, p) for (code, s), (_, p, _) in zip(table, rows)]
        self._fresh = [(code, st) for (code, _), (_, _, st) in zip(table, rows) if code in (K.UNLAG, K.LAG)]
        self._hysts = [(s, st) for (code, s), (_, _, st) in zip(table, rows) if code == K.HYST]
        self._bends = [(s, st) for (code, s), (_, _, st) in zip(table, rows) if code == K.BEND]
        self.load_params()
        self.reset()

    def load_params(self) -> None:
        """The stages' parameters now (a new offset moves the hysteresis and a coupling's zero)."""
        from . import kernels as K

        par = self.par
        for code, s, p in self._params:
            if code == K.COUPLE:
                par[p:p + 3] = (s.gain, s.sign, 1.0 if s.eff.form.endswith("-magnitude") else 0.0)
            elif code == K.BEND:
                par[p:p + 8] = s.kn._kernel_args()
            elif code == K.UNLAG:
                par[p:p + 3] = (s.fraction, s.tau, s.lead)
            elif code == K.LAG:
                par[p] = s.tau
            else:
                par[p:p + 8] = s.kn._kernel_args()
                par[p + 8] = len(s.edges)
                for j, e in enumerate(s.edges):
                    q = p + 9 + 2 * j
                    par[q:q + 2] = (float(e["gain"]), 1.0 if e.form.endswith("-magnitude") else 0.0)

    def reset(self) -> None:
        """Every stage at rest (the lags start on their first input); the hysteresis starts on
        the first sample (:meth:`start`)."""
        self.st[:] = 0.0
        for code, s in self._fresh:
            self.st[s] = 1.0          # fresh
            self.st[s + 4] = -1.0     # no sample interval seen yet
        for b, s in self._bends:
            self.st[s] = b.y          # a knob's bend starts from its tip reading (its _Bend's reset)
        self.work[:] = self.st
        self.pending = bool(self._hysts)

    def start(self) -> None:
        """The hysteresis state behind the tip reading at rest, as ``_Hysteresis`` starts it."""
        for h, s in self._hysts:
            h._start(None)
            self.st[s] = h.y
            self.st[s + 1] = h.x
        self.pending = False
