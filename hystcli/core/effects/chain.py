"""The chain of one knob: the model's effects run stage by stage, forward (prediction) and inverse
(compensation), with a state that can be carried between calls.

Whatever order a model lists its effects in, the chain runs them in fixed stages (each effect's
form names its stage and its rank within it, :class:`~hystcli.core.effects.base.Form`)::

    condition   knob parameters from the run's shape (total curvature) or stated condition
    input       the input x the hysteresis sees, from the commands (lags, coupling)
    edges       dead-zone edges that move sample by sample (coupling that moves the dead zone)
    hysteresis  y_h = the model of docs/design.md section 3 on x, from y_h0
    output      the physical tip, from y_h (saturation, creep, output lags, output coupling)
    contact     the tip stops at a wall
    sensor      what the tracker reports (latency)

With no effect switched on the chain is :meth:`KnobModel.forward` itself, bit for bit. Every stage
is monotone in its input, so :func:`inverse` undoes them in reverse order; a stage that reads the
other knob (coupling) makes the inverse a joint problem of both knobs, solved by fixed-point
iteration.

State, for streaming: a :class:`ChainState` holds the hysteresis output and each stage's own state
(lags hold ``[z, t, u]``, the tracker its last ``delay`` seconds), so one call over a run and many
calls over its pieces give the same samples (the live twin relies on it). The inverse stages take
states the same way (:meth:`EffectType.new_inverse_state`); a streaming compensator keeps one per
stage and knob and steps them one sample at a time, solving the coupling's fixed point per sample.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping, Protocol, Sequence

import numpy as np

from ...errors import DataError, ModelError
from ..params import EffectSpec, KnobModel, Shape
from ..run import Run
from . import kernels
from .base import STAGES, Effect, Signals
from .registry import as_effects


class Model(Protocol):
    """What the chain reads of a catheter's model: :class:`hystcli.core.model.Model`, which sits
    above the chain (its prediction and compensation run it), is one."""

    knobs: Mapping[int, KnobModel]
    effects: Sequence[EffectSpec]

    def knob(self, k: int) -> KnobModel: ...

    def offsets_for(self, meta: Mapping[str, str]) -> dict[int, float]: ...

    def require_loop(self, knobs: Sequence[int], what: str) -> None: ...


@dataclass(frozen=True)
class Plan:
    """The switched-on effects of a chain, sorted into their stages (forward order)."""

    condition: tuple[Effect, ...] = ()
    input: tuple[Effect, ...] = ()
    edges: tuple[Effect, ...] = ()
    output: tuple[Effect, ...] = ()
    contact: tuple[Effect, ...] = ()
    sensor: tuple[Effect, ...] = ()

    @classmethod
    def of(cls, effects: Sequence[Effect]) -> "Plan":
        on = sorted((e for e in effects if not e.is_null), key=lambda e: e.order)
        by: list[list] = [[] for _ in STAGES]
        for e in on:
            by[e.order[0]].append(e)
        return cls(*map(tuple, by))

    @property
    def empty(self) -> bool:
        return not (self.condition or self.input or self.edges or self.output or self.contact or self.sensor)

    def signal_steps(self) -> list[tuple[str, Effect | None]]:
        """The forward steps after the condition stage: ``("sig", e)``, ``("edge", e)``,
        ``("hyst", None)`` and the markers ``("free", None)`` (before contact) and ``("tip", None)``
        (before the sensor)."""
        return ([("sig", e) for e in self.input] + [("edge", e) for e in self.edges] + [("hyst", None)]
                + [("sig", e) for e in self.output] + [("free", None)] + [("sig", e) for e in self.contact]
                + [("tip", None)] + [("sig", e) for e in self.sensor])


@dataclass
class ChainState:
    """What one knob's chain carries between calls (mutable; one per knob).

    ``y`` is the hysteresis output y_{t-1} (None: start from the reading ``y0``); ``stages``
    holds each effect's stage state by name, made on first use; ``other_y`` the other section's
    bend at the last sample, where a coupling reads it (None: start from ``other_y0``); ``speed``
    the knob-speed estimate's state (:func:`kernels.knob_speed_kernel`) where a backlash widens
    with speed (None: at rest).
    """

    y: float | None = None
    stages: dict = field(default_factory=dict)
    other_y: float | None = None
    speed: np.ndarray | None = None

    def of(self, eff: Effect) -> Any:
        s = self.stages.get(eff.name)
        if s is None:
            s = self.stages[eff.name] = eff.type.new_state(eff)
        return s


@dataclass(frozen=True)
class KnobTrace:
    """The signals of one knob's chain.

    Attributes
    ----------
    knob : KnobModel
        The knob model after the condition stage.
    x : numpy.ndarray
        The input the hysteresis saw (after the input stage), deg.
    free : numpy.ndarray
        The physical tip before a wall stops it, deg.
    tip : numpy.ndarray
        The physical tip, deg.
    y : numpy.ndarray
        What the tracker reports, deg.
    yh : numpy.ndarray
        The hysteresis output y_h, deg.
    """

    knob: KnobModel
    x: np.ndarray
    free: np.ndarray
    tip: np.ndarray
    y: np.ndarray
    yh: np.ndarray | None = None


def driver_value(e: Effect, shape: Shape, condition: float | None, shape_stated: bool = False) -> float:
    """What drives a condition-stage effect on a run (deg): the stated ``condition``, or the
    shape's total curvature.

    An effect of the shape (``driver == "shape"``: friction along the bent sheath, a dead zone the
    bend changes) reads the curvature whenever the run states its shape, even beside a stated load:
    a load does not bend the sheath. Without a stated shape (cable-driven tools whose runs state a
    resistive load instead) it reads the condition, as every other effect does when one is stated.
    """
    if condition is None or (shape_stated and e.type.driver == "shape"):
        return shape.total_curvature
    return condition


def condition_knob(knob: KnobModel, effects: Sequence[Effect], shape: Shape,
                   condition: float | None = None, shape_stated: bool = False, k: int | None = None) -> KnobModel:
    """The knob's parameters under the run's condition (stage ``condition``).

    The driver is the shape's total curvature (deg), or ``condition`` (deg) when the run states
    one: other cable-driven data state their own condition (a resistive load) in the run's
    ``condition`` metadata, scaled to degrees of curvature-equivalent (:func:`driver_value`: an
    effect of the shape reads the curvature when the run states its shape). ``k`` (the knob) gives
    the effects the bend projected on its plane (:meth:`Shape.projected`); without it that bend
    reads 0. Returns ``knob`` itself (the same object) when no effect changes anything.

    Raises
    ------
    ModelError
        When the changed parameters are no longer a valid model (names the effects).
    """
    plan = effects if isinstance(effects, Plan) else Plan.of(effects)
    conds = plan.condition
    if not conds:
        return knob
    p = knob.params()
    bend = shape.projected(k) if k is not None else 0.0
    changed = [e.name for e in conds if e.type.condition(e, p, driver_value(e, shape, condition, shape_stated), bend)]
    if not changed:
        return knob
    try:
        return KnobModel(**p)
    except ModelError as exc:
        kdeg = shape.total_curvature if condition is None else condition
        raise ModelError(f"effect {'+'.join(changed)} at total curvature {kdeg:g} deg: {exc}") from None


_NONE = np.empty(0)
"""An empty move array: the edges kernels' "no such move"."""


def _speed_moves(x: np.ndarray, t: np.ndarray, widen: float, st: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    # the plateau ends' moves of a speed-widened backlash: +-widen*|v| of the knob-speed estimate
    # up to the previous sample (kernels.inverse_edges_kernel's rule, so its inverse is exact)
    v0 = 0.0 if math.isnan(st[0]) else (st[2] - st[0]) / kernels.SPEED_TAU
    v = np.empty_like(x)
    kernels.knob_speed_kernel(x, t, kernels.SPEED_TAU, st, v)
    ep = np.empty_like(x)
    if x.size:
        ep[0] = widen * abs(v0)
        np.multiply(widen, np.abs(v[:-1]), out=ep[1:])
    return ep, -ep


def _hysteresis(kn: KnobModel, x: np.ndarray, yh0: float, dp, dn, widen: float = 0.0,
                sig: Signals | None = None, state: ChainState | None = None) -> np.ndarray:
    if dp is None and widen == 0.0:
        return kn.forward(x, yh0)
    x = np.ascontiguousarray(x, dtype=np.float64)
    ep = en = _NONE
    if widen != 0.0:
        t = np.ascontiguousarray(sig.t, dtype=np.float64)   # checked where the widening was read
        if state is not None:
            if state.speed is None:
                state.speed = kernels.new_speed_state()
            st = state.speed
        else:
            st = kernels.new_speed_state()
        ep, en = _speed_moves(x, t, widen, st)
    out = np.empty_like(x)
    kernels.forward_edges_kernel(x, *kn._kernel_args(),
                                 _NONE if dp is None else np.ascontiguousarray(dp, dtype=np.float64),
                                 _NONE if dn is None else np.ascontiguousarray(dn, dtype=np.float64),
                                 ep, en, float(yh0), out)
    return out


def _rest(plan: Plan, y0: float, sig: Signals) -> float:
    # the hysteresis state behind a reading y0 at rest: undo every output stage's static map
    return rest_input(plan, None, y0, sig)


def rest_input(plan: Plan, eff: Effect | None, y0: float, sig: Signals) -> float:
    """What :func:`_rest` hands output stage ``eff``'s ``at_rest``: the reading ``y0`` with the
    output stages after ``eff`` undone (``eff`` None: all of them, the hysteresis' start)."""
    for e in reversed(plan.output):
        if e is eff:
            break
        y0 = e.type.at_rest(e, y0, sig)
    return y0


def run_signals(plan: Plan, kn: KnobModel, sig: Signals, x: np.ndarray, state: ChainState | None = None,
                start: int = 0, carry: dict | None = None, stop: int | None = None,
                steps: list | None = None) -> dict:
    """Run the signal steps of ``plan`` (:meth:`Plan.signal_steps`) from step ``start`` (with the
    ``carry`` an earlier call stopped with) up to ``stop``; returns the carry: ``z`` (the signal),
    ``x``, ``yh``, ``free``, ``tip``, the edge moves ``dp``, ``dn`` and the backlash's speed
    widening ``w`` (s: both plateau ends move apart by ``w * |knob speed|``).

    Stopping before a step and starting there again is how the diagnosis reuses everything a
    candidate effect cannot change; ``steps`` is ``plan.signal_steps()`` when the caller has it.
    """
    if steps is None:
        steps = plan.signal_steps()
    c = ({"z": x, "x": x, "dp": None, "dn": None, "w": 0.0, "yh": None, "free": None, "tip": None}
         if carry is None else dict(carry))
    n = len(steps) if stop is None else stop
    for i in range(start, n):
        kind, e = steps[i]
        if kind == "sig":
            c["z"] = e.type.forward(e, c["z"], sig, None if state is None else state.of(e))
        elif kind == "edge":
            moves = e.type.edges(e, c["z"].size, sig)
            if moves is not None:
                c["dp"] = moves[0] if c["dp"] is None else c["dp"] + moves[0]
                c["dn"] = moves[1] if c["dn"] is None else c["dn"] + moves[1]
            w = e.type.widening(e)
            if w:
                sig.need_t(e.name)   # the speed it widens with needs the time column
                c["w"] += w
        elif kind == "hyst":
            c["x"] = c["z"]
            if state is not None and state.y is not None:
                yh0 = state.y
            else:
                yh0 = _rest(plan, sig.y0, sig)
            y = _hysteresis(kn, c["z"], yh0, c["dp"], c["dn"], c["w"], sig, state)
            if state is not None and y.size:
                state.y = float(y[-1])
            c["z"] = c["yh"] = y
        elif kind == "free":
            c["free"] = c["z"]
        else:
            c["tip"] = c["z"]
    return c


def step_index(plan: Plan, eff: Effect) -> int:
    """Where ``eff`` sits among :meth:`Plan.signal_steps` (0 for a condition effect: everything
    after the condition stage depends on it)."""
    for i, (kind, e) in enumerate(plan.signal_steps()):
        if e is eff:
            return i
    return 0


def reads_bend(plan: Plan) -> bool:
    """Whether a stage of ``plan`` reads the other section's bend (:attr:`Signals.other_tip`)."""
    return any(e.type.reads_bend(e) for e in plan.input + plan.edges + plan.output)


def other_bend(plan: Plan, other_knob: KnobModel | None, other: np.ndarray | None,
               y0: float = 0.0) -> np.ndarray | None:
    """The other section's bend as a coupling of ``plan`` reads it: the other knob's base model
    (with its offset) on its command ``other``, from the tip ``y0``; None when nothing reads it or
    the other knob's model or command is missing (see :mod:`hystcli.core.effects.coupling`)."""
    if other_knob is None or other is None or not reads_bend(plan):
        return None
    return other_knob.forward(other, y0)


def tip_chain(knob: KnobModel, k: int, q: Mapping[int, np.ndarray], t: np.ndarray | None,
              effects: Sequence[Effect] = (), shape: Shape = Shape(), y0: float = 0.0,
              state: ChainState | None = None, condition: float | None = None,
              other_offset: float = 0.0, source: str = "run", shape_stated: bool = False,
              other_knob: KnobModel | None = None, other_y0: float = 0.0) -> KnobTrace:
    """Run knob ``k`` through every stage: the tip angle the effects make of the commands.

    Parameters
    ----------
    knob : KnobModel
        The knob's base model, carrying the run's shift in its ``offset``.
    k : int
        Which knob (1 or 2); the other knob's command drives ``coupling``.
    q : mapping of int to numpy.ndarray
        Knob commands (deg) of every knob of the run, float64, same length.
    t : numpy.ndarray or None
        Sample times (s); needed by the time-driven effects only.
    effects : sequence of Effect
        Validated effects; null ones are skipped.
    shape : Shape
        Shaft shape: the condition of the condition stage.
    y0 : float
        The reported tip before the first sample.
    state : ChainState, optional
        Carried between calls (the live twin); updated in place.
    condition : float, optional
        Driver of the condition stage in place of the shape's total curvature (deg).
    other_offset : float
        The other knob's offset (deg): the zero of a coupling driven by its bend's size.
    shape_stated : bool
        The run states its shape (effects of the shape then read it beside a stated condition).
    other_knob : KnobModel, optional
        The other knob's base model with its offset: its prediction on ``q`` of the other knob
        is the bend a coupling of the ``-magnitude`` forms reads.
    other_y0 : float
        The other knob's reported tip before the first sample (where its bend starts).

    Returns
    -------
    KnobTrace
        With no effect switched on, ``trace.y`` is exactly ``knob.forward(q[k], y0)``.
    """
    plan = Plan.of(effects)
    kn = condition_knob(knob, plan, shape, condition, shape_stated, k)
    other = q.get(3 - k)
    start = other_y0 if state is None or state.other_y is None else state.other_y
    bend = other_bend(plan, other_knob, other, float(start))
    if state is not None and bend is not None and bend.size:
        state.other_y = float(bend[-1])
    sig = Signals(k, t, other, float(other_offset), float(y0), source, bend)
    c = run_signals(plan, kn, sig, q[k], state)
    return KnobTrace(kn, c["x"], c["free"], c["tip"], c["z"], c["yh"])


def contact_current(trace: KnobTrace, effects: Sequence[Effect]) -> np.ndarray | float:
    """Extra motor current (mA) while a wall blocks the tip (0.0 when no contact effect is on)."""
    for e in Plan.of(effects).contact:
        if hasattr(e.type, "current"):
            return e.type.current(e, trace.free, trace.tip, trace.knob.omega)
    return 0.0


# --------------------------------------------------------------------------------------------
# the model's prediction
# --------------------------------------------------------------------------------------------
def run_condition(meta: Mapping[str, str], source: str | None = None) -> float | None:
    """The ``condition`` metadata of a run (deg of curvature-equivalent), or None when absent.

    Raises
    ------
    DataError
        A value that is not a finite number.
    """
    text = meta.get("condition")
    if text is None or str(text).strip() == "":
        return None
    try:
        value = float(text)
    except ValueError:
        raise DataError(f"{source or 'run'}: metadata condition {text!r} is not a number") from None
    if not math.isfinite(value):
        raise DataError(f"{source or 'run'}: metadata condition must be finite")
    return value


def predict(model: Model, run, effects: Sequence[Effect | EffectSpec] | None = None) -> dict[int, np.ndarray]:
    """Tip angle of each knob that ``model`` plus its effects predicts for ``run``'s commands.

    Each knob uses the offset :meth:`Model.offsets_for` gives for the run's metadata; the
    condition stage reads the run's ``shape`` (or ``condition``). The output starts from the run's
    first measured ``y<k>`` when present, else 0.

    Parameters
    ----------
    model : Model
    run : Run
        Needs ``q<k>`` for the knobs to predict (knobs of the model without one are left out),
        ``t`` when a time-driven effect is on.
    effects : sequence, optional
        Effects to use instead of ``model.effects``.

    Returns
    -------
    dict of int to numpy.ndarray
        With no effects, exactly ``model.knob(k).with_offset(offset).forward(q<k>, y0)``.

    Raises
    ------
    DataError
        The run has no command column of any of the model's knobs.
    ModelError
        An unknown or invalid effect.
    """
    effs = as_effects(model.effects if effects is None else effects)
    return _predict(model, model.offsets_for(run.meta), run, effs)


def _predict(model: Model, offsets: Mapping[int, float], run: Run, effs: Sequence[Effect]) -> dict[int, np.ndarray]:
    # predict with the offsets given: the inverse checks its own commands at the offsets it used
    shape = Shape.parse(run.meta.get("shape"))
    cond = run_condition(run.meta, run.source)
    q = {k: np.ascontiguousarray(run[f"q{k}"], dtype=np.float64) for k in (1, 2) if f"q{k}" in run}
    knobs = [k for k in model.knobs if k in q]
    if not knobs:
        raise DataError(f"{run.source or 'run'}: no command column for the model's knobs "
                        f"({', '.join(f'q{k}' for k in model.knobs)})")
    # the other knob's bend feeds a coupling stage: its loop must be whole too
    model.require_loop(knobs if not effs else [k for k in model.knobs if k in q], "predict the tip")
    t = np.ascontiguousarray(run["t"], dtype=np.float64) if "t" in run else None
    out: dict[int, np.ndarray] = {}
    def first_y(k: int) -> float:
        yk = run.columns.get(f"y{k}")
        return float(yk[0]) if yk is not None and len(yk) else 0.0

    for k in knobs:
        knob = model.knob(k).with_offset(offsets[k])
        if not effs:
            out[k] = knob.forward(q[k], first_y(k))
        else:
            o = 3 - k
            other_knob = model.knob(o).with_offset(offsets[o]) if o in model.knobs and o in q else None
            out[k] = tip_chain(knob, k, q, t, effs, shape, first_y(k), condition=cond,
                               other_offset=offsets.get(o, 0.0), source=run.source or "run",
                               shape_stated="shape" in run.meta, other_knob=other_knob,
                               other_y0=first_y(o) if other_knob is not None else 0.0).y
    return out


# --------------------------------------------------------------------------------------------
# the inverse (compensation with effects)
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Inverse:
    """Result of :func:`inverse`: the knob commands and what the user should know.

    Attributes
    ----------
    q : dict of int to numpy.ndarray
        Knob commands per knob (deg).
    warnings : tuple of str
        Targets no command can reach (a wall, a saturation limit), clipped.
    """

    q: dict
    warnings: tuple = ()


def _reverse_steps(plan: Plan) -> list[tuple[str, Effect | None]]:
    # the inverse visits the signal stages from the sensor back to the input
    return ([("sig", e) for e in reversed(plan.sensor)] + [("sig", e) for e in reversed(plan.contact)]
            + [("sig", e) for e in reversed(plan.output)] + [("hyst", None)]
            + [("sig", e) for e in reversed(plan.input)])


def _needs_other(kind: str, e: Effect | None, plan: Plan) -> bool:
    if kind == "hyst":
        return any(x.type.cross_knob(x) for x in plan.edges)
    return e.type.cross_knob(e)


def inverse(model: Model, run, offsets: Mapping[int, float] | None = None,
            effects: Sequence[Effect | EffectSpec] | None = None, knobs: Sequence[int] | None = None,
            max_lead: float = 30.0, iterations: int = 50) -> Inverse:
    """Knob commands that make the model *with its effects* follow the desired tip angles.

    Every stage is monotone in its input, so the chain is undone stage by stage in reverse order
    (sensor, contact, output, hysteresis with its edges, input), each effect by its own
    :meth:`~hystcli.core.effects.base.EffectType.inverse`. A stage that reads the other knob
    (coupling) needs the other knob's command, which is being solved for too: the first pass
    leaves it out, then both knobs are solved again from the other's last commands until they
    change by less than 1e-10 deg (a contraction for |gain| < 1). The other knob's command is taken
    through its input lags first (what the cross-talk sees of it after the lag): cancelling the
    raw command through an inverse lag would amplify its lead every pass (an unstable loop), while
    this leaves an error of about gain * tau * its speed.

    So ``predict`` of the commands equals the reference except during the first ``delay`` seconds
    of a latency, where a lag needs more lead than ``max_lead``, and where a target was clipped.

    Parameters
    ----------
    model : Model
    run : Run
        Desired tip angles ``r<k>``, time ``t``, metadata ``shape`` (and ``condition``).
    offsets : mapping, optional
        Offset per knob (default: :meth:`Model.offsets_for` of the run's metadata).
    effects : sequence, optional
        Instead of ``model.effects``.
    knobs : sequence of int, optional
        Knobs to compensate (default: every knob with an ``r<k>`` column).
    max_lead : float
        Largest lead (deg) of a command over the lagged signal it aims at.
    iterations : int
        Most fixed-point passes for a stage that reads the other knob.

    Returns
    -------
    Inverse

    Raises
    ------
    DataError
        No ``r<k>`` column, or no ``t`` when a time-driven effect is on.
    """
    effs = as_effects(model.effects if effects is None else effects)
    plan = Plan.of(effs)
    use = [int(k) for k in (knobs if knobs is not None else run.knobs("r"))]
    if not use:
        raise DataError(f"{run.source or 'run'}: no desired tip angle column (r1 or r2)")
    model.require_loop(use, "compensate")
    offs = model.offsets_for(run.meta) if offsets is None else dict(offsets)
    shape = Shape.parse(run.meta.get("shape"))
    cond = run_condition(run.meta, run.source)
    t = np.ascontiguousarray(run["t"], dtype=np.float64) if "t" in run else None
    opts = {"max_lead": float(max_lead)}
    src = run.source or "run"
    steps = _reverse_steps(plan)
    two = len(use) == 2
    cut = next((i for i, (kind, e) in enumerate(steps) if two and _needs_other(kind, e, plan)), len(steps))
    kns = {k: condition_knob(model.knob(k).with_offset(offs[k]), plan, shape, cond, "shape" in run.meta, k)
           for k in use}

    # the other section's bend (coupling's -magnitude forms): the other knob's base model, not
    # conditioned, from a straight tip (where the forward chain of the commands starts it)
    bases = {k: model.knob(k).with_offset(offs[k]) for k in use}

    def sig_of(k: int, other: np.ndarray | None) -> Signals:
        bend = None if other is None else other_bend(plan, bases.get(3 - k), other, 0.0)
        return Signals(k, t, other, float(offs.get(3 - k, 0.0)), 0.0, src, bend)

    def run_steps(k: int, z: np.ndarray, lo: int, hi: int, other, warnings: list[str]) -> np.ndarray:
        sig = sig_of(k, other)
        for kind, e in steps[lo:hi]:
            if kind == "hyst":
                z = _hysteresis_inverse(kns[k], z, plan, sig, opts["max_lead"], warnings)
            else:
                z = e.type.inverse(e, z, sig, e.type.new_inverse_state(e), warnings, opts)
        return z

    warnings: list[str] = []
    head: dict[int, np.ndarray] = {}
    for k in use:
        r = np.ascontiguousarray(run[f"r{k}"], dtype=np.float64)
        if not np.all(np.isfinite(r)):
            raise DataError(f"{src}: r{k} holds NaN or infinite values")
        head[k] = run_steps(k, r, 0, cut, None, warnings)
    tail_warn: list[str] = []
    q = {k: run_steps(k, head[k], cut, len(steps), None, tail_warn) for k in use}
    if cut < len(steps):
        # the other knob as the cross-talk sees it: through the input stages before the first
        # one that reads the other knob (the lags; no arithmetic at all when there are none)
        pre = []
        for e in plan.input:
            if e.type.cross_knob(e):
                break
            pre.append(e)

        def seen(k: int, qk: np.ndarray) -> np.ndarray:
            sig = sig_of(k, None)
            for e in pre:
                qk = e.type.forward(e, qk, sig, None)
            return qk

        history = []
        for _ in range(max(int(iterations), 1)):
            tail_warn = []
            new = {k: run_steps(k, head[k], cut, len(steps), seen(3 - k, q[3 - k]), tail_warn) for k in use}
            change = max(float(np.max(np.abs(new[k] - q[k]), initial=0.0)) for k in use)
            q = new
            history.append(q)
            if change < 1e-10:
                break
        else:
            # no fixed point: a stage after the hysteresis reads the other knob, whose commands
            # jump where the hysteresis inverse jumps (a reversal), so the iteration can cycle
            # there. Keep the iterate whose forward prediction is closest to the reference.
            def miss(qs) -> float:
                ys = _predict(model, {k: offs[k] for k in use}, _commands_run(run, t, qs), effs)
                return max(float(np.sqrt(np.mean((ys[k] - run[f"r{k}"]) ** 2))) for k in use)

            errs = [miss(qs) for qs in history]
            q = history[int(np.argmin(errs))]
            tail_warn.append(f"the coupling's inverse did not converge (it reads the other knob after the "
                             f"hysteresis): the commands miss the reference by {min(errs):.3g} deg RMS on the model")
    return Inverse(q, tuple(dict.fromkeys(warnings + tail_warn)))


def _commands_run(run: Run, t, q: Mapping[int, np.ndarray]) -> Run:
    cols = {"t": t} if t is not None else {}
    cols.update({f"q{k}": v for k, v in q.items()})
    meta = {k: v for k, v in run.meta.items() if not k.startswith("offset")}
    return Run(cols, meta, run.source)


def _hysteresis_inverse(kn: KnobModel, r: np.ndarray, plan: Plan, sig: Signals, max_lead: float = 30.0,
                        warnings: list[str] | None = None) -> np.ndarray:
    dp = dn = None
    widen = 0.0
    for e in plan.edges:
        moves = e.type.edges(e, r.size, sig)
        if moves is not None:
            dp = moves[0] if dp is None else dp + moves[0]
            dn = moves[1] if dn is None else dn + moves[1]
        w = e.type.widening(e)
        if w:
            sig.need_t(e.name)
            widen += w
    # the hysteresis starts where the forward chain starts it: behind a straight tip reading
    # (0 unless an output stage bends the static map, e.g. a coupling that pushes the tip)
    yh0 = _rest(plan, 0.0, sig)
    if dp is None and widen == 0.0:
        return kn.inverse(r, y0=yh0)
    t = np.ascontiguousarray(sig.t, dtype=np.float64) if widen != 0.0 else _NONE
    out = np.empty_like(r)
    _, limited = kernels.inverse_edges_kernel(
        np.ascontiguousarray(r, dtype=np.float64), *kn._kernel_args(),
        _NONE if dp is None else np.ascontiguousarray(dp, dtype=np.float64),
        _NONE if dn is None else np.ascontiguousarray(dn, dtype=np.float64),
        _NONE, _NONE, float(widen), float(max_lead), t, kernels.new_speed_state(), yh0, kn.holding_knob_angle(yh0), out)
    if limited and warnings is not None:
        warnings.append(_lead_warning(sig.k, widen, max_lead))
    return out


def _lead_warning(k: int, widen: float, max_lead: float) -> str:
    """What the inverse says when a speed-widened backlash needed a command step beyond ``max_lead``."""
    return (f"knob {k}: the viscous backlash (c_visc {widen:g} s) needed command steps beyond max_lead "
            f"{max_lead:g} deg (the command's own speed widens the backlash it crosses): the commands "
            "miss the reference there")
