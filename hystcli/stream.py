"""Streaming compensation: the model's inverse chain one reference sample at a time, for a
robot's own control loop (docs/design.md section 9, ``hystcli.Compensator``).

:class:`Compensator` runs the same chain as ``hyst compensate`` (:func:`hystcli.effects.inverse`):
the inverse stages of the model's effects from the sensor back to the input, with the hysteresis
inverse of docs/design.md section 3 in the middle, each stage keeping its own state between samples
(:meth:`hystcli.effects.EffectType.stepper`). Fed the samples of a reference file one by one it
returns the commands ``hyst compensate`` writes for that file (to float rounding: ``exp`` and
``atanh`` may differ from the compiled kernels' by an ulp).

What is causal, and what is not:

* the hysteresis inverse, ``rate`` (inverse lags, the knob's lead limited to ``max_lead``),
  ``creep``, ``saturation``, ``contact`` and the condition effects (``friction``, ``deadzone``,
  ``stretch``: fixed for a shape/condition) are causal: sample ``i``'s command needs samples
  ``<= i`` only;
* ``coupling`` reads the other knob's command of the same sample: solved per sample by the same
  fixed-point iteration the batch inverse runs over the whole run (so a two-knob step costs up to
  ``iterations`` passes over the coupled stages: one compiled call of
  :mod:`hystcli.stream_kernels` where every coupled stage has an op there, else Python passes);
* ``latency`` (the tracker reports the tip ``delay`` s late) has no causal exact inverse: to make
  the *reported* tip follow ``r`` the command at ``t`` must aim at ``r(t + delay)``. The default
  (``latency="delay"``) buffers ``lookahead = ceil(delay / dt)`` samples: :meth:`Compensator.step`
  then returns the command of the sample ``lookahead`` steps back (the first ``lookahead`` calls
  return the knob's rest command) and :meth:`Compensator.flush` returns the last ones; these are
  exactly the commands ``hyst compensate`` writes. A caller that knows its reference ahead (a
  planned trajectory) feeds it ``lookahead`` samples early and loses nothing; a caller that does
  not gets its commands that much late. ``latency="ignore"`` leaves the delay in (no lookahead):
  the physical tip follows ``r`` and only the tracker's report lags, by ``delay``.

Time: the time-driven stages (``rate``, ``creep``, ``latency``) need each sample's time: pass
``t`` to :meth:`Compensator.step`, or give the sample period ``dt`` once (sample ``i`` is then at
``i * dt``).

A motor's limits: given ``limits``, every command goes out through a
:class:`hystcli.safety.RateLimiter` per knob, causally: the inverse's jumps (across the dead zone,
across the backlash at a reversal) are crossed at the speed (acceleration) limit and the knob
catches up with the exact commands after them (:attr:`Compensator.catch_ups` says how long it
lagged). The chain itself keeps following the exact commands: the limiter is the last stage, so
the knob lands on exactly what ``hyst compensate --allow-fast`` writes once it has caught up (a
coupling reads the other knob's exact command, not the lagging one).

Cost: a step is plain Python floats (no numpy, no numba dispatch, no allocation but the returned
float or pair), but for a coupling's fixed point, which is one numba call over preallocated arrays
(the kernel compiles, or loads from numba's cache, on the first coupled step, never at import);
:meth:`Compensator.steps` runs a knob without effects through the compiled kernel of
:mod:`hystcli.model`. ``bench/bench_stream.py`` measures both (docs/streaming.md).
"""
from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

import numpy as np

from .core import kernel as core_kernel
from .core.kernel import clamp_py as _clamp, envelopes_py as _envelopes, inverse_step_py as _inverse_step
from .effects import chain, kernels
from .effects.base import Effect, Signals
from .effects.registry import as_effects
from .errors import DataError, ModelError
from .model import KnobModel, Model, Shape
from .safety import CatchUp, Limits, RateLimiter

LATENCY_MODES = ("delay", "ignore")
"""What a :class:`Compensator` does with a ``latency`` effect (see the module's notes)."""


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
    magnitude coupling reads (:mod:`hystcli.effects.coupling`)."""

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
    as the op table of :mod:`hystcli.stream_kernels`: the per-sample fixed point in one compiled
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
        from . import stream_kernels as K
        from .effects import kernels
        from .effects.coupling import _CouplingStep

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
        from . import stream_kernels as K

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
        from . import stream_kernels as K

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


class Compensator:
    """Streaming compensation: one desired tip angle in, one knob command out, causal.

    Parameters
    ----------
    model : Model
        The catheter's model with its effects; each knob's ``offset`` is the shift in effect
        (``Model.with_offsets``, or a model ``hyst detect-shift`` wrote).
    knobs : sequence of int, optional
        Knobs to compensate (default: every knob of the model). With one knob :meth:`step`
        takes and returns floats, with two it takes and returns pairs ``(knob 1, knob 2)``.
    dt : float, optional
        Sample period (s): sample ``i`` is at ``i * dt`` when :meth:`step` gets no ``t``.
        Needed with ``latency="delay"`` (the lookahead in samples).
    shape : Shape or str, optional
        The shaft's shape, the condition of ``friction``/``deadzone`` (default: straight).
    condition : float, optional
        A stated load in place of the shape's curvature (``stretch``; docs/design.md section 6).
    latency : {"delay", "ignore"}
        With a ``latency`` effect: return exact commands ``lookahead`` samples late, or leave the
        tracker's delay uncompensated (module notes).
    max_lead : float
        Largest lead (deg) of a command over the lagged signal it aims at (``rate``), as
        ``hyst compensate``.
    iterations : int
        Most fixed-point passes per sample for ``coupling`` (two knobs).
    limits : hystcli.safety.Limits, optional
        Rate-limit every command to these speed and acceleration limits (module notes); the
        travel limit is the caller's to check. Needs each sample's time (``t`` or ``dt``).

    Raises
    ------
    ModelError
        An unknown knob, an invalid effect, an effect without a one-sample inverse, a latency
        mode that is not one of :data:`LATENCY_MODES`, or ``latency="delay"`` without ``dt``.

    Examples
    --------
    >>> import hystcli
    >>> m = hystcli.Model({1: hystcli.KnobModel(d_pos=5.0, d_neg=-5.0, b_pos=6.0, b_neg=6.0)})
    >>> c = hystcli.Compensator(m, dt=0.01)
    >>> q = [c.step(r) for r in (0.0, 2.0, 3.0, 2.5)]  # in a robot's loop: robot.move(1, c.step(r))
    >>> [round(x, 3) for x in q]
    [0.0, 6.379, 7.069, 0.724]
    >>> [round(float(y), 9) for y in m.knob(1).forward(q)]  # the model follows the reference
    [0.0, 2.0, 3.0, 2.5]
    """

    def __init__(self, model: Model, knobs: Sequence[int] | None = None, *, dt: float | None = None,
                 shape: Shape | str | None = None, condition: float | None = None,
                 latency: str = "delay", max_lead: float = 30.0, iterations: int = 50,
                 limits: Limits | None = None) -> None:
        self._model = model
        self._knobs = tuple(int(k) for k in (model.knobs if knobs is None else knobs))
        if not self._knobs or len(set(self._knobs)) != len(self._knobs):
            raise ModelError(f"a compensator needs distinct knobs, got {self._knobs}")
        for k in self._knobs:
            model.knob(k)
        model.require_loop(self._knobs, "compensate")
        if latency not in LATENCY_MODES:
            raise ModelError(f"latency must be one of {', '.join(LATENCY_MODES)}, got {latency!r}")
        if dt is not None and not (math.isfinite(dt) and dt > 0):
            raise ModelError(f"the sample period dt must be a positive number of seconds, got {dt!r}")
        self.dt = None if dt is None else float(dt)
        self.shape = shape if isinstance(shape, Shape) else Shape.parse(shape)
        self.condition = None if condition is None else float(condition)
        self.latency = latency
        self.iterations = max(int(iterations), 1)
        self._effects = as_effects(model.effects)
        self._plan = chain.Plan.of(self._effects)
        self._warnings: list[str] = []
        opts = {"max_lead": float(max_lead)}
        two = len(self._knobs) == 2
        names = {(e.name, e.form) for e in self._effects}
        if two and any(n == "coupling" for n, _ in names) and ("rate", "input2") in names:
            # measured: on the two-knob sample reference the commands of both the stream and the
            # batch inverse miss the reference by 2-5 deg RMS on the model itself (the batch says
            # its iteration did not converge); a causal step cannot check that, so it says so here
            self._warnings.append("a coupling together with a second-order input lag: the commands "
                                  "can miss the reference by degrees (the batch inverse does not "
                                  "converge either); check them with `hyst predict`")

        # the reverse steps of the batch inverse (chain._reverse_steps), minus the tracker delay,
        # which is a buffer of the reference here (it needs future samples)
        steps = chain._reverse_steps(self._plan)
        self.delay_s = 0.0
        kept = []
        for kind, e in steps:
            if kind == "sig" and e.type.preview(e) > 0.0:
                self.delay_s = max(self.delay_s, e.type.preview(e))
                continue
            kept.append((kind, e))
        cut = next((i for i, (kind, e) in enumerate(kept) if two and chain._needs_other(kind, e, self._plan)),
                   len(kept))
        # the other knob as the cross-talk sees it: through the input lags before the first stage
        # that reads the other knob (chain.inverse's `seen`), then, for a coupling driven by the
        # bend's size, through the knob's base model forward (chain.other_bend)
        bend = two and chain.reads_bend(self._plan)
        pre = []
        for e in self._plan.input:
            if e.type.cross_knob(e):
                break
            pre.append(e)
        self._chains: dict[int, _Knob] = {}
        for k in self._knobs:
            hyst = _Hysteresis(model.knob(k), k, [e for e in self._plan.edges if e.type.cross_knob(e)],
                               self._plan.output, sum(e.type.widening(e) for e in self._plan.edges),
                               opts["max_lead"], self._warnings)
            made = []
            for kind, e in kept:
                if kind == "hyst":
                    made.append(hyst)
                    continue
                s = e.type.stepper(e, k, opts, self._warnings)
                if s is None:
                    raise ModelError(f"effect {e.label()} has no one-sample inverse: the streaming "
                                     "compensator cannot run it (use `hyst compensate` on a whole file)")
                made.append(s)
            seen = []
            if two and cut < len(kept):
                for e in pre:
                    fs = getattr(e.type, "forward_stepper", None)
                    if fs is None:
                        raise ModelError(f"effect {e.label()} has no one-sample forward stage: the "
                                         "streaming compensator cannot run it with a coupling")
                    seen.append(fs(e))
                if bend:
                    seen.append(_Bend(model.knob(k)))
            self._chains[k] = _Knob(k, made[:cut], made[cut:], hyst, seen)
        self._coupled = two and cut < len(kept)
        # the coupled tails' per-sample fixed point as one compiled call, where every stage has an
        # op (hystcli/stream_kernels.py); else the Python passes of _command
        self._fast = _CompiledCoupling.build(self._chains[self._knobs[0]], self._chains[self._knobs[1]],
                                             self._plan) if self._coupled else None
        # the time-driven stages (lags, creep, the tracker delay) need each sample's time
        self._needs_t = any(e.type.driver in ("speed", "time") for e in self._effects if not e.is_null)
        self._limiters = None if limits is None else tuple(
            RateLimiter(k, limits.max_speed, limits.max_accel) for k in self._knobs)
        self._needs_t = self._needs_t or self._limiters is not None
        if self.delay_s > 0.0 and latency == "delay":
            if self.dt is None:
                raise ModelError(f"the model's latency ({self.delay_s:g} s) needs the sample period dt "
                                 "to buffer the reference (or latency='ignore')")
            ratio = self.delay_s / self.dt
            # ceil, but a ratio within rounding of an integer is that integer
            self.lookahead = int(round(ratio)) if abs(ratio - round(ratio)) < 1e-9 else int(math.ceil(ratio))
        else:
            self.lookahead = 0
        n = self.lookahead + 1
        self._buf_t = [0.0] * n
        self._buf_r = [[0.0] * n for _ in self._knobs]
        self._refresh()
        self.reset()

    # -- construction helpers --------------------------------------------------------------------
    @classmethod
    def for_run(cls, model: Model, meta: Mapping[str, str], knobs: Sequence[int] | None = None,
                offsets: Mapping[int, float] | None = None, **kwargs: Any) -> "Compensator":
        """The compensator ``hyst compensate`` would use for a reference with metadata ``meta``:
        each knob's offset by docs/design.md section 6's rule (:meth:`Model.offsets_for`) unless
        ``offsets`` are given, the shape and the stated condition from ``meta``."""
        offs = model.offsets_for(meta) if offsets is None else dict(offsets)
        return cls(model.with_offsets(offs), knobs, shape=Shape.parse(meta.get("shape")),
                   condition=chain.run_condition(meta, "reference"), **kwargs)

    # -- state -------------------------------------------------------------------------------------
    @property
    def knobs(self) -> tuple[int, ...]:
        """The knobs compensated, in the order :meth:`step` takes and returns them."""
        return self._knobs

    @property
    def model(self) -> Model:
        """The model with the offsets in effect now."""
        return self._model

    @property
    def offsets(self) -> dict[int, float]:
        """The offset (shift) of every knob of the model now (deg)."""
        return {k: kn.offset for k, kn in self._model.knobs.items()}

    @property
    def warnings(self) -> tuple[str, ...]:
        """What the inverse warned about so far (a target beyond a wall or a saturation), once each."""
        return tuple(dict.fromkeys(self._warnings))

    @property
    def catch_ups(self) -> dict[int, CatchUp]:
        """Per knob whose commands the ``limits`` held back so far, how long it lagged the exact
        commands (:class:`hystcli.safety.CatchUp`); empty without ``limits`` or when none was."""
        out = {}
        for lim in self._limiters or ():
            c = lim.catch_up()
            if c is not None:
                out[lim.knob] = c
        return out

    @property
    def rest_command(self) -> tuple[float, ...]:
        """Per knob, the command while the reference rests at the tip reading it started from (the
        middle of the knob range that holds it): what :meth:`step` returns while the latency
        buffer fills."""
        return tuple(self._chains[k].hyst.kn.holding_knob_angle(self._rest_y[i])
                     for i, k in enumerate(self._knobs))

    def reset(self, y0: float | Sequence[float] = 0.0) -> None:
        """Start again: the tip reads ``y0`` (deg; a pair for two knobs) at rest, every lag at rest,
        the latency buffer empty, the clock at 0. ``hyst compensate`` starts from 0."""
        ys = self._per_knob(y0, "y0", broadcast=True)
        self._rest_y = ys
        for i, k in enumerate(self._knobs):
            self._chains[k].reset(ys[i])
        if self._fast is not None:
            self._fast.reset()
        for lim in self._limiters or ():
            lim.reset()
        self._n = 0          # samples taken
        self._last_t = -math.inf
        self._filled = 0     # samples in the latency buffer
        self._rest = self.rest_command

    def set_offset(self, k: int, offset: float) -> None:
        """Set knob ``k``'s offset (absolute, deg) between two steps, e.g. after a new Algorithm 1
        result (``Model.with_offsets``). The chain's state (where the tip is, the lags) is kept:
        the next command follows the shifted loop from the present tip."""
        offset = float(offset)
        if not math.isfinite(offset):
            raise ModelError(f"offset of knob {k} must be finite, got {offset!r}")
        self._model.knob(k)
        self._model = self._model.with_offsets({int(k): offset})
        self._refresh()

    def rotate(self, delta_deg: float) -> None:
        """A bulk rotation of the catheter body by ``delta_deg`` (deg) between two steps: rotates
        the offsets' vector by ``-delta_deg`` (``Model.rotated``, docs/design.md section 3)."""
        delta = float(delta_deg)
        if not math.isfinite(delta):
            raise ModelError(f"rotation must be finite, got {delta_deg!r}")
        self._model = self._model.rotated(delta)
        self._refresh()

    def _refresh(self) -> None:
        # the knob parameters under the shape/condition with the offsets now
        for k, ch in self._chains.items():
            kn = chain.condition_knob(self._model.knob(k), self._plan, self.shape, self.condition, k=k)
            ch.hyst.set_knob(kn)
            # this knob's bend (what the other knob's magnitude coupling reads): its base model,
            # not conditioned, with its offset now (chain.inverse's `bases`)
            for s in ch.seen:
                if isinstance(s, _Bend):
                    s.kn = self._model.knob(k)
        if self._fast is not None:
            self._fast.load_params()

    def _per_knob(self, value: Any, what: str, broadcast: bool = False) -> list[float]:
        n = len(self._knobs)
        if (n == 1 or broadcast) and not isinstance(value, (tuple, list, np.ndarray)):
            return [float(value)] * n
        vals = [float(v) for v in (value if isinstance(value, (tuple, list, np.ndarray)) else (value,))]
        if len(vals) != n:
            raise DataError(f"{what}: expected {n} value{'s' if n > 1 else ''} (knobs "
                            f"{', '.join(map(str, self._knobs))}), got {len(vals)}")
        return vals

    # -- the stream ---------------------------------------------------------------------------------
    def _time(self, t: float | None) -> float:
        if t is None:
            if self.dt is None:
                if self._needs_t:
                    raise DataError(f"sample {self._n}: the model's time-driven effects and the rate "
                                    "limit need the sample's time t (or a sample period dt)")
                return float(self._n)  # read by no stage
            return self._n * self.dt
        t = float(t)
        if not t > self._last_t:  # also refuses NaN
            raise DataError(f"sample {self._n}: time {t!r} must be after the previous sample's "
                            f"({self._last_t!r})")
        return t

    def _command(self, rs: list[float], t: float) -> tuple[float, ...]:
        # one sample (after the latency buffer) through every knob's chain, then the rate limit
        q = self._exact(rs, t)
        if self._limiters is None:
            return q
        return tuple(lim.step(v, t) for lim, v in zip(self._limiters, q))

    def _exact(self, rs: list[float], t: float) -> tuple[float, ...]:
        if not self._coupled:
            return tuple(self._chains[k].run(rs[i], t, None) for i, k in enumerate(self._knobs))
        c1, c2 = self._chains[self._knobs[0]], self._chains[self._knobs[1]]
        fast = self._fast
        if fast is not None:
            h1 = rs[0]
            for s in c1.head:
                h1 = s.step(h1, t, None)
            h2 = rs[1]
            for s in c2.head:
                h2 = s.step(h2, t, None)
            if fast.pending:
                fast.start()
            q1, q2, ok = fast.kernel(h1, h2, t, self.iterations, fast.ops, fast.rng, fast.par, fast.st, fast.work)
            if not ok:
                self._warnings.append("the coupling's per-sample fixed point did not converge: the last "
                                      "iterate is used")
            return (q1, q2)
        # the head (stages that read no other knob) once; then the tail solved for both knobs by
        # the batch inverse's fixed-point iteration, restarted from this sample's state each pass
        h1 = h2 = 0.0
        for i, ch in enumerate((c1, c2)):
            z = rs[i]
            for s in ch.head:
                z = s.step(z, t, None)
            if i == 0:
                h1 = z
            else:
                h2 = z
        s1, s2 = c1.save_tail(), c2.save_tail()
        seen1 = tuple(s.save() for s in c1.seen)
        seen2 = tuple(s.save() for s in c2.seen)

        def tail(ch, state, h, other):
            ch.load_tail(state)
            for s in ch.tail:
                h = s.step(h, t, other)
            return h

        def see(ch, state, q):
            for s, v in zip(ch.seen, state):
                s.load(v)
            for s in ch.seen:
                q = s.step(q, t)
            return q

        q1 = tail(c1, s1, h1, None)
        q2 = tail(c2, s2, h2, None)
        for _ in range(self.iterations):
            n1 = tail(c1, s1, h1, see(c2, seen2, q2))
            n2 = tail(c2, s2, h2, see(c1, seen1, q1))
            change = max(abs(n1 - q1), abs(n2 - q2))
            q1, q2 = n1, n2
            if change < 1e-10:
                break
        else:
            self._warnings.append("the coupling's per-sample fixed point did not converge: the last "
                                  "iterate is used")
        # commit what the other knob's coupling saw of each command this sample
        see(c1, seen1, q1)
        see(c2, seen2, q2)
        return (q1, q2)

    def step(self, r: float | Sequence[float], t: float | None = None) -> float | tuple[float, float]:
        """One reference sample in, one command out.

        Parameters
        ----------
        r : float or pair of float
            Desired tip angle(s) (deg), one per knob of :attr:`knobs`.
        t : float, optional
            The sample's time (s), increasing; default ``i * dt``.

        Returns
        -------
        float or tuple of float
            The knob command(s) (deg). With a ``lookahead`` (latency), the command of the sample
            ``lookahead`` steps back (the rest command until the buffer holds that many).

        Raises
        ------
        DataError
            A non-finite reference, a time not after the previous one, the wrong number of values.
        """
        if len(self._knobs) == 1 and not self.lookahead and not isinstance(r, (tuple, list, np.ndarray)):
            # the hot path of one knob: no list, no tuple
            r = float(r)
            if not math.isfinite(r):
                raise DataError(f"sample {self._n}: reference {r!r} is not a finite number")
            tt = self._time(t)
            self._last_t = tt
            self._n += 1
            q = self._chains[self._knobs[0]].run(r, tt, None)
            return q if self._limiters is None else self._limiters[0].step(q, tt)
        rs = self._per_knob(r, f"sample {self._n}")
        for v in rs:
            if not math.isfinite(v):
                raise DataError(f"sample {self._n}: reference {v!r} is not a finite number")
        tt = self._time(t)
        self._last_t = tt
        self._n += 1
        if self.lookahead:
            out = self._push(tt, rs)
            if out is None:
                q = self._rest
            else:
                q = self._command(*out)
        else:
            q = self._command(rs, tt)
        return q[0] if len(q) == 1 else q

    # the latency buffer: the last lookahead + 1 samples, a ring
    def _push(self, t: float, rs: list[float]) -> tuple[list[float], float] | None:
        n = self.lookahead + 1
        j = (self._n - 1) % n
        self._buf_t[j] = t
        for i, v in enumerate(rs):
            self._buf_r[i][j] = v
        self._filled += 1
        if self._filled <= self.lookahead:
            return None
        return self._aim(self._n - 1 - self.lookahead, self._n - 1)

    def _aim(self, i: int, last: int) -> tuple[list[float], float]:
        # the reference at t_i + delay by linear interpolation over the buffered samples i..last
        # (np.interp's formula), held at the last one beyond it
        n = self.lookahead + 1
        ti = self._buf_t[i % n]
        x = ti + self.delay_s
        out = []
        for buf in self._buf_r:
            value = buf[last % n]
            for j in range(i, last):
                a, b = self._buf_t[j % n], self._buf_t[(j + 1) % n]
                if a <= x < b:
                    fa, fb = buf[j % n], buf[(j + 1) % n]
                    value = (fb - fa) / (b - a) * (x - a) + fa if x != a else fa
                    break
            out.append(value)
        return out, ti

    def flush(self) -> list:
        """The commands still in the latency buffer (the reference held at its last sample, as
        ``hyst compensate`` holds it at the end of a file): call once after the last :meth:`step`.
        Empty without a lookahead. Each item as :meth:`step` returns it."""
        if not self.lookahead or self._filled == 0:
            return []
        last = self._n - 1
        first = max(self._n - self.lookahead, 0)
        out = []
        for i in range(first, self._n):
            rs, ti = self._aim(i, last)
            q = self._command(rs, ti)
            out.append(q[0] if len(q) == 1 else q)
        self._filled = 0
        return out

    def steps(self, r: Any, t: Any = None) -> np.ndarray:
        """A block of samples: the same as :meth:`step` in a loop, as one array.

        Parameters
        ----------
        r : array_like, shape (n,) or (n, 2)
            Desired tip angles, one column per knob of :attr:`knobs`.
        t : array_like, shape (n,), optional
            Sample times (default ``i * dt``).

        Returns
        -------
        numpy.ndarray
            Commands of the same shape (with a lookahead, shifted as :meth:`step` shifts them).
        """
        rr = np.asarray(r, dtype=np.float64)
        nk = len(self._knobs)
        if (nk == 1 and rr.ndim != 1) or (nk == 2 and (rr.ndim != 2 or rr.shape[1] != 2)):
            raise DataError(f"steps expects shape (n,) for one knob or (n, 2) for two, got {rr.shape}")
        tt = None if t is None else np.asarray(t, dtype=np.float64)
        if tt is not None and tt.shape != (rr.shape[0],):
            raise DataError(f"steps: t has shape {tt.shape}, r has {rr.shape[0]} samples")
        if nk == 1 and not self.lookahead and rr.size:
            ch = self._chains[self._knobs[0]]
            timed = tt is not None or self.dt is not None or self._limiters is None
            if not ch.tail and ch.head == [ch.hyst] and ch.hyst.plain and timed and np.all(np.isfinite(rr)):
                # the compiled kernel of hystcli.core.kernel: the same operations, so the same numbers
                if tt is not None:
                    self._check_times(tt)
                h = ch.hyst
                if h.fresh:
                    h._start(None)
                out = np.empty_like(rr)
                h.y = float(core_kernel.inverse(np.ascontiguousarray(rr), *h.kn._kernel_args(), h.y, h.x, out))
                h.x = float(out[-1])
                first = self._n
                self._n += rr.size
                self._last_t = float(tt[-1]) if tt is not None else (
                    (self._n - 1) * self.dt if self.dt is not None else float(self._n - 1))
                if self._limiters is not None:
                    times = tt if tt is not None else (first + np.arange(rr.size)) * self.dt
                    step = self._limiters[0].step
                    out = np.array([step(q, ti) for q, ti in zip(out.tolist(), times.tolist())])
                return out
        out = np.empty_like(rr)
        step = self.step
        if nk == 1:
            for i in range(rr.shape[0]):
                out[i] = step(rr[i], None if tt is None else tt[i])
        else:
            for i in range(rr.shape[0]):
                out[i] = step((rr[i, 0], rr[i, 1]), None if tt is None else tt[i])
        return out

    def _check_times(self, tt: np.ndarray) -> None:
        if not np.all(np.isfinite(tt)) or (tt.size > 1 and np.any(np.diff(tt) <= 0)) or not tt[0] > self._last_t:
            raise DataError("steps: t must be finite and strictly increasing, after the previous sample")


__all__ = ["Compensator", "LATENCY_MODES"]
