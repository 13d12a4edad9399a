"""Effects the base model leaves out (DESIGN.md section 8), shared by the twin and the diagnosis.

Every effect is a named physical term with one or two parameters, a *null* setting under which
it is skipped entirely (so the output is the base model's, bit for bit) and a documented direction
when switched on. The same :class:`Effect` objects drive the virtual catheter (``twin.py``, which
adds the motor current and the sensors) and the model's prediction :func:`predict` (which the
diagnosis fits, candidate by candidate, within each type's ``bounds``).

The tip chain of one knob runs in fixed stages, whatever order the effects are listed in::

    condition  friction, deadzone,  knob parameters from the shaft shape (total curvature kappa)
               stretch              or from the run's ``condition`` metadata (a load level)
    input      coupling, rate       the knob input x the hysteresis sees, from the commands
    hysteresis                      y_h = KnobModel.forward(x, y0)       (DESIGN.md section 3)
    output     saturation, creep    the physical tip, from y_h
    contact                         the tip stops at a wall (the twin adds the current's rise)
    sensor     latency              what the EM tracker reports

=============  ===============================================================  ============  =====================================
name           term                                                              null          direction when on
=============  ===============================================================  ============  =====================================
friction       b -> b*g, omega -> omega/g, g = exp(mu*kappa), kappa=sum|alpha|   mu = 0        loop widens, output range shrinks as
               in rad (capstan law: the sheath eats tension exponentially)                     the shaft bends more
deadzone       d_pos += width*kappa/2, d_neg -= width*kappa/2 (deg per rad)      width = 0     dead zone grows with curvature
                                                                                               (narrows for width < 0)
stretch        h_pos, h_neg += compliance*(kappa - reference), both in rad:      compliance   the output (both envelopes) moves
               the cable yields to the load the run states (its condition)      = 0           up by compliance per rad of condition
                                                                                               above reference (down below it)
coupling       x_k = q_k - gain*q_other (the other knob's command, deg/deg)      gain = 0      knob k's dead zone moves by gain*q_other
rate           x = first-order lag of q, time constant tau (viscous sheath)      tau = 0       tip lags by tau*speed: the loop widens
                                                                                               by 2*tau*speed
saturation     y = limit*tanh(y_h/limit)                                         limit = inf   tip stiffens towards +-limit
creep          y = (1-fraction)*y_h + fraction*lag(y_h, tau)                     fraction = 0  after a step, the last fraction of the
                                                                                               move arrives with time constant tau
contact        y = min(y, wall) (wall > 0) or max(y, wall) (wall < 0);           wall = inf    tip stops at the wall; current rises by
               current += stiffness * (blocked tip)/omega                                      stiffness mA per deg of knob
latency        y_reported(t) = y(t - delay)                                      delay = 0     reported tip late by exactly delay
=============  ===============================================================  ============  =====================================

``stretch`` is the effect of a steady load on a cable transmission: a torque ``T`` on the output
stretches the cable by ``T/k`` and the output sits that much further along, whatever the input
(real EndoWrist data, ``sample_data/real/STUDY.md``: about 0.1 deg per % of resistive torque).
Both envelopes move by the same amount, so the dead zones and backlash widths stay as they are.
Its driver is the run's ``condition`` metadata (the load), or the shape's total curvature for a
catheter run; ``reference`` is the condition the base model was identified under (the model
already holds the stretch there), so the shift is zero at the identification condition.

On the forward model a pure input delay equals a pure output delay (the hysteresis is
rate-independent), so ``rate`` is a first-order lag, not a delay: it also rounds the tip's
response to fast command changes (the jumps a compensator makes), which ``latency`` does not.
Every stage is monotone in its input, so :func:`inverse` (compensation with effects) undoes them
stage by stage in reverse order.

Sequential stages (hysteresis, the first-order lags) are numba-compiled; the others are numpy
expressions. Every stage can carry its state across calls (:class:`ChainState`), so the live
twin stepping sample chunks gives the same numbers as one batch call.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Mapping, Sequence

import numpy as np
from numba import njit

from .errors import DataError, ModelError
from .model import EffectSpec, KnobModel, Model, Shape

STAGES = ("condition", "input", "output", "contact", "sensor")


# --------------------------------------------------------------------------------------------
# the registry
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class EffectType:
    """One kind of effect: its parameters, their null values, domain, fitting bounds and scale.

    Attributes
    ----------
    name : str
    stage : str
        Where it acts in the tip chain (one of :data:`STAGES`).
    params : tuple of str
        Parameter names.
    units : tuple of str
        Unit of each parameter.
    null : mapping
        The value of the *switch* parameter that turns the effect off (``switch`` below); the
        other parameters then do not matter.
    switch : str
        The parameter whose null value turns the effect off.
    typical : mapping
        A typical switched-on value of each parameter: the default when one is not given, and
        the scale of the parameter for an optimiser.
    bounds : mapping
        Fitting bounds ``(lo, hi)`` per parameter: the range a diagnosis searches.
    domain : mapping
        Physically valid range ``(lo, hi)`` per parameter (inclusive); outside it is an error.
    driver : str
        What drives the effect: ``shape`` (run metadata), ``condition`` (the run's ``condition``
        metadata, else the shape's total curvature), ``other knob``, ``speed``, ``time``, ``tip``.
    summary : str
        The physics and the direction in one line.
    """

    name: str
    stage: str
    params: tuple[str, ...]
    units: tuple[str, ...]
    switch: str
    null: float
    typical: Mapping[str, float]
    bounds: Mapping[str, tuple[float, float]]
    domain: Mapping[str, tuple[float, float]]
    driver: str
    summary: str

    def __post_init__(self) -> None:
        for name in ("typical", "bounds", "domain"):
            object.__setattr__(self, name, MappingProxyType(dict(getattr(self, name))))

    @property
    def scale(self) -> dict[str, float]:
        """Typical magnitude of each parameter (for normalising an optimiser's steps)."""
        return {p: abs(v) for p, v in self.typical.items()}

    def null_params(self) -> dict[str, float]:
        """A full parameter set that switches the effect off."""
        p = dict(self.typical)
        p[self.switch] = self.null
        return p


_INF = math.inf

EFFECTS: Mapping[str, EffectType] = MappingProxyType({e.name: e for e in (
    EffectType("friction", "condition", ("mu",), ("1/rad",), "mu", 0.0,
               {"mu": 0.3}, {"mu": (0.0, 1.0)}, {"mu": (0.0, 5.0)}, "shape",
               "capstan friction: backlash x g and slope / g, g = exp(mu * total curvature in rad)"),
    EffectType("deadzone", "condition", ("width",), ("deg/rad",), "width", 0.0,
               {"width": 3.0}, {"width": (-4.0, 10.0)}, {"width": (-_INF, _INF)}, "shape",
               "dead zone widens by width * total curvature (rad), split evenly between its edges"),
    EffectType("stretch", "condition", ("compliance", "reference"), ("deg/rad", "deg"), "compliance", 0.0,
               {"compliance": 3.0, "reference": 0.0}, {"compliance": (-20.0, 20.0), "reference": (-90.0, 180.0)},
               {"compliance": (-_INF, _INF), "reference": (-_INF, _INF)}, "condition",
               "the cable yields to a load: the output moves by compliance * (condition - reference) (rad)"),
    EffectType("coupling", "input", ("gain",), ("deg/deg",), "gain", 0.0,
               {"gain": 0.15}, {"gain": (-0.5, 0.5)}, {"gain": (-_INF, _INF)}, "other knob",
               "the other knob's angle q_other shifts this knob's dead zone by gain * q_other"),
    EffectType("rate", "input", ("tau",), ("s",), "tau", 0.0,
               {"tau": 0.3}, {"tau": (0.0, 2.0)}, {"tau": (0.0, _INF)}, "speed",
               "viscous lag: the knob input follows the command with time constant tau"),
    EffectType("saturation", "output", ("limit",), ("deg",), "limit", _INF,
               {"limit": 80.0}, {"limit": (20.0, 400.0)}, {"limit": (1e-6, _INF)}, "tip",
               "the bending section stiffens: tip = limit * tanh(tip / limit)"),
    EffectType("creep", "output", ("fraction", "tau"), ("1", "s"), "fraction", 0.0,
               {"fraction": 0.2, "tau": 3.0}, {"fraction": (0.0, 0.6), "tau": (0.2, 30.0)},
               {"fraction": (0.0, 1.0), "tau": (1e-9, _INF)}, "time",
               "viscoelastic creep: a fraction of each tip move arrives with time constant tau"),
    EffectType("contact", "contact", ("wall", "stiffness"), ("deg", "mA/deg"), "wall", _INF,
               {"wall": 40.0, "stiffness": 60.0}, {"wall": (-120.0, 120.0), "stiffness": (0.0, 500.0)},
               {"wall": (-_INF, _INF), "stiffness": (0.0, _INF)}, "tip",
               "a wall at tip angle wall stops the tip; the current rises by stiffness per knob deg"),
    EffectType("latency", "sensor", ("delay",), ("s",), "delay", 0.0,
               {"delay": 0.1}, {"delay": (0.0, 1.0)}, {"delay": (0.0, _INF)}, "time",
               "the tracker reports the tip late by delay seconds"),
)})
"""Every effect of DESIGN.md section 8 by name."""


@dataclass(frozen=True)
class Effect:
    """An effect type with its parameter values (build with :func:`make_effect`)."""

    type: EffectType
    params: Mapping[str, float]

    def __post_init__(self) -> None:
        object.__setattr__(self, "params", MappingProxyType(dict(self.params)))

    @property
    def name(self) -> str:
        return self.type.name

    def __getitem__(self, param: str) -> float:
        return self.params[param]

    @property
    def is_null(self) -> bool:
        """True when the effect is switched off (its stage is skipped)."""
        v = self.params[self.type.switch]
        if math.isinf(self.type.null):
            return math.isinf(v)
        return v == self.type.null

    def spec(self) -> EffectSpec:
        """The :class:`EffectSpec` to store in a model file."""
        return EffectSpec(self.name, dict(self.params))

    def __str__(self) -> str:
        return f"{self.name}(" + ",".join(f"{p}={v:g}" for p, v in self.params.items()) + ")"


def make_effect(name: str, **params: float) -> Effect:
    """Build and validate an effect; omitted parameters take the type's typical value.

    Parameters
    ----------
    name : str
        One of :data:`EFFECTS`.
    **params : float
        Parameter values (see ``EFFECTS[name].params``).

    Raises
    ------
    ModelError
        Unknown effect or parameter, a value that is not a number, or outside its domain.
    """
    etype = EFFECTS.get(str(name).strip().lower())
    if etype is None:
        raise ModelError(f"unknown effect {name!r} (known: {', '.join(EFFECTS)})")
    values = dict(etype.typical)
    for p, v in params.items():
        if p not in etype.params:
            raise ModelError(f"effect {etype.name}: unknown parameter {p!r} "
                             f"(parameters: {', '.join(etype.params)})")
        try:
            fv = float(v)
        except (TypeError, ValueError):
            raise ModelError(f"effect {etype.name}: parameter {p} must be a number, got {v!r}") from None
        if math.isnan(fv) or (math.isinf(fv) and not (p == etype.switch and math.isinf(etype.null))):
            raise ModelError(f"effect {etype.name}: parameter {p} must be finite, got {v!r}")
        lo, hi = etype.domain[p]
        if not (lo <= fv <= hi) and not (p == etype.switch and math.isinf(fv) and math.isinf(etype.null)):
            raise ModelError(f"effect {etype.name}: parameter {p} = {fv:g} is outside its valid "
                             f"range [{lo:g}, {hi:g}]")
        values[p] = fv
    return Effect(etype, values)


def as_effect(e: "Effect | EffectSpec") -> Effect:
    """An :class:`Effect` from an :class:`Effect` or a stored :class:`EffectSpec` (validated)."""
    if isinstance(e, Effect):
        return e
    if isinstance(e, EffectSpec):
        return make_effect(e.name, **dict(e.params))
    raise ModelError(f"not an effect: {e!r}")


def as_effects(effects: Sequence["Effect | EffectSpec"] | None) -> tuple[Effect, ...]:
    """Validated effects; each name at most once (the same effect twice is ambiguous)."""
    out = tuple(as_effect(e) for e in (effects or ()))
    seen: set[str] = set()
    for e in out:
        if e.name in seen:
            raise ModelError(f"effect {e.name} is given twice")
        seen.add(e.name)
    return out


_EFFECT_RE = re.compile(r"^\s*([A-Za-z_]+)\s*(?:[:(]\s*(.*?)\s*\)?)?\s*$")


def parse_effect(text: str) -> Effect:
    """Parse ``name``, ``name:p=v,p=v`` (command line) or ``name(p=v,p=v)`` (run metadata).

    Raises
    ------
    ModelError
        Malformed text, unknown effect or parameter, bad value.
    """
    m = _EFFECT_RE.match(text or "")
    if not m:
        raise ModelError(f"bad effect {text!r}: expected NAME or NAME:param=value[,param=value]")
    name, body = m.group(1), m.group(2) or ""
    params: dict[str, str] = {}
    for item in filter(None, (s.strip() for s in body.split(","))):
        key, eq, val = item.partition("=")
        if not eq or not key.strip():
            raise ModelError(f"bad effect {text!r}: {item!r} is not param=value")
        params[key.strip()] = val.strip()
    return make_effect(name, **params)


def parse_effects(text: str) -> tuple[Effect, ...]:
    """Parse a ``;``-separated list of effects (the ``effects`` metadata of a simulated run)."""
    if text is None or text.strip().lower() in ("", "none"):
        return ()
    return as_effects([parse_effect(part) for part in text.split(";") if part.strip()])


def format_effects(effects: Sequence[Effect | EffectSpec]) -> str:
    """The ``effects`` metadata value, readable back by :func:`parse_effects`."""
    return ";".join(str(as_effect(e)) for e in effects) or "none"


# --------------------------------------------------------------------------------------------
# compiled kernels
# --------------------------------------------------------------------------------------------
@njit(cache=True, fastmath=False)
def _lag_kernel(u, t, tau, z0, t0, u0, out):
    # exact solution of dz/dt = (u - z)/tau for an input linear between samples (first-order
    # hold): a ramp of speed v is trailed by exactly tau*v, a hold decays as exp(-t/tau)
    z = z0
    tp = t0
    up = u0
    for i in range(u.shape[0]):
        dt = t[i] - tp
        if dt > 0.0:
            e = math.exp(-dt / tau)
            lag = tau * (u[i] - up) / dt
            z = u[i] - lag + e * (z - up + lag)
        tp = t[i]
        up = u[i]
        out[i] = z
    return z


def _lag(u: np.ndarray, t: np.ndarray, tau: float, state: list | None) -> np.ndarray:
    """First-order lag of ``u``; ``state`` is ``[z, t, u]`` carried between calls (None: at rest)."""
    out = np.empty_like(u)
    if u.size == 0:
        return out
    if state is None or state[0] is None:
        z0, t0, u0 = float(u[0]), float(t[0]), float(u[0])
    else:
        z0, t0, u0 = state
    z = _lag_kernel(u, t, float(tau), z0, t0, u0, out)
    if state is not None:
        state[0], state[1], state[2] = float(z), float(t[-1]), float(u[-1])
    return out


# --------------------------------------------------------------------------------------------
# the tip chain of one knob
# --------------------------------------------------------------------------------------------
@dataclass
class ChainState:
    """What one knob's tip chain carries between calls (mutable; one per knob).

    ``None`` fields mean "at rest before the first sample": the lags start on their input, the
    hysteresis on ``y0``, the tracker on the first tip angle.
    """

    y: float | None = None                       # hysteresis output y_{t-1}
    rate: list = field(default_factory=lambda: [None, None, None])    # lag state [z, t, u]
    creep: list = field(default_factory=lambda: [None, None, None])
    lat_t: np.ndarray | None = None              # tracker history (times, tips) within delay
    lat_y: np.ndarray | None = None
    lat_y0: float | None = None                  # the tip before the first sample


@dataclass(frozen=True)
class KnobTrace:
    """The signals of one knob's tip chain.

    Attributes
    ----------
    knob : KnobModel
        The knob model after the condition stage (friction, deadzone).
    x : numpy.ndarray
        The input the hysteresis saw (after coupling and rate), deg.
    free : numpy.ndarray
        The physical tip before a wall stops it, deg.
    tip : numpy.ndarray
        The physical tip, deg.
    y : numpy.ndarray
        What the tracker reports (tip after latency), deg.
    """

    knob: KnobModel
    x: np.ndarray
    free: np.ndarray
    tip: np.ndarray
    y: np.ndarray


def _by_name(effects: Sequence[Effect]) -> dict[str, Effect]:
    return {e.name: e for e in effects if not e.is_null}


def condition_knob(knob: KnobModel, effects: Sequence[Effect], shape: Shape,
                   condition: float | None = None) -> KnobModel:
    """The knob's parameters under the shaft ``shape`` (stage ``condition``).

    ``friction``: with g = exp(mu * kappa), kappa = total curvature in rad, the backlash widths
    are multiplied by g and omega divided by g. ``deadzone``: the edges move apart by
    ``width * kappa`` in all. ``stretch``: both heights move by
    ``compliance * (kappa - reference)`` (reference in deg, converted to rad like kappa), which
    moves both envelopes by that much. Returns ``knob`` itself (the same object) when none of
    them changes anything.
    ``condition`` (deg), when given, replaces the shape's total curvature as the driver: other
    cable-driven data state their own condition (a resistive load, a frequency) in the run's
    ``condition`` metadata, scaled to degrees of curvature-equivalent.

    Raises
    ------
    ModelError
        When the changed parameters are no longer a valid model (names the condition).
    """
    on = _by_name(effects)
    fr, dz, st = on.get("friction"), on.get("deadzone"), on.get("stretch")
    if fr is None and dz is None and st is None:
        return knob
    kdeg = shape.total_curvature if condition is None else condition
    kappa = math.radians(kdeg)
    # the output offset of a stretched cable (zero at the reference condition)
    lift = 0.0 if st is None else st["compliance"] * math.radians(kdeg - st["reference"])
    if lift != 0.0:
        # equal heights keep dhat_pos, dhat_neg (they depend on h_pos - h_neg): a pure output shift
        knob = KnobModel(**{**knob.params(), "h_pos": knob.h_pos + lift, "h_neg": knob.h_neg + lift})
    if kappa == 0.0 or (fr is None and dz is None):
        return knob
    p = knob.params()
    if fr is not None:
        g = math.exp(fr["mu"] * kappa)
        p["b_pos"] *= g
        p["b_neg"] *= g
        p["omega"] /= g
    if dz is not None:
        half = 0.5 * dz["width"] * kappa
        p["d_pos"] += half
        p["d_neg"] -= half
    try:
        return KnobModel(**p)
    except ModelError as exc:
        names = "+".join(e.name for e in (fr, dz) if e is not None)
        raise ModelError(f"effect {names} at total curvature {kdeg:g} deg: {exc}") from None


def knob_input(k: int, q: Mapping[int, np.ndarray], t: np.ndarray | None, effects: Sequence[Effect],
               state: ChainState | None = None) -> np.ndarray:
    """The input ``x`` knob ``k``'s hysteresis sees (stage ``input``: rate, then coupling).

    Returns the command array ``q[k]`` itself when neither effect is on.
    """
    on = _by_name(effects)
    x = q[k]
    rate = on.get("rate")
    if rate is not None:
        if t is None:
            raise DataError("effect rate needs the time column t")
        x = _lag(x, t, rate["tau"], None if state is None else state.rate)
    cp = on.get("coupling")
    other = 3 - k
    if cp is not None and other in q:
        x = x - cp["gain"] * q[other]
    return x


def tip_chain(knob: KnobModel, k: int, q: Mapping[int, np.ndarray], t: np.ndarray | None,
              effects: Sequence[Effect] = (), shape: Shape = Shape(), y0: float = 0.0,
              state: ChainState | None = None, condition: float | None = None) -> KnobTrace:
    """Run knob ``k`` through every stage: the tip angle the effects make of the commands.

    Parameters
    ----------
    knob : KnobModel
        The knob's base model, carrying the shift of the shape in its ``offset``.
    k : int
        Which knob (1 or 2); the other knob's command drives ``coupling``.
    q : mapping of int to numpy.ndarray
        Knob commands (deg) of every knob of the run, float64, same length.
    t : numpy.ndarray or None
        Sample times (s); needed by rate, creep and latency only.
    effects : sequence of Effect
        Validated effects (see :func:`as_effects`); null ones are skipped.
    shape : Shape
        Shaft shape: the condition of friction and deadzone.
    y0 : float
        The reported tip before the first sample.
    state : ChainState, optional
        Carried between calls (the live twin); updated in place.
    condition : float, optional
        Driver of the condition stage in place of the shape's total curvature (deg; see
        :func:`condition_knob`).

    Returns
    -------
    KnobTrace
        With no effect switched on, ``trace.y`` is exactly ``knob.forward(q[k], y0)``.
    """
    on = _by_name(effects)
    kn = condition_knob(knob, effects, shape, condition)
    x = knob_input(k, q, t, effects, state)
    sat = on.get("saturation")
    if state is not None and state.y is not None:
        yh0 = state.y
    elif sat is not None:
        # the hysteresis state behind a saturated tip reading
        lim = sat["limit"]
        yh0 = lim * math.atanh(max(-1 + 1e-12, min(1 - 1e-12, y0 / lim)))
    else:
        yh0 = y0
    y = kn.forward(x, yh0)
    if state is not None and y.size:
        state.y = float(y[-1])
    if sat is not None:
        lim = sat["limit"]
        y = lim * np.tanh(y / lim)
    creep = on.get("creep")
    if creep is not None:
        if t is None:
            raise DataError("effect creep needs the time column t")
        a = creep["fraction"]
        y = (1.0 - a) * y + a * _lag(y, t, creep["tau"], None if state is None else state.creep)
    free = y
    wall = on.get("contact")
    if wall is not None:
        w = wall["wall"]
        y = np.minimum(y, w) if w > 0 else np.maximum(y, w)
    tip = y
    lat = on.get("latency")
    if lat is not None:
        if t is None:
            raise DataError("effect latency needs the time column t")
        y = _delay(tip, t, lat["delay"], y0, state)
    return KnobTrace(kn, x, free, tip, y)


def _delay(y: np.ndarray, t: np.ndarray, delay: float, y0: float, state: ChainState | None) -> np.ndarray:
    # y(t - delay) by linear interpolation; before the first sample the tip sat at y0
    if state is None or state.lat_t is None:
        T, Y = t, y
        before = y0
    else:
        T, Y = np.concatenate([state.lat_t, t]), np.concatenate([state.lat_y, y])
        before = state.lat_y0
    out = np.interp(t - delay, T, Y, left=before)
    if state is not None and t.size:
        keep = T >= t[-1] - delay
        # one sample before the window is the left end of the first interpolation interval
        first = max(int(np.argmax(keep)) - 1, 0) if keep.any() else T.size - 1
        state.lat_t, state.lat_y = T[first:].copy(), Y[first:].copy()
        if state.lat_y0 is None:
            state.lat_y0 = before
    return out


def contact_current(trace: KnobTrace, effects: Sequence[Effect]) -> np.ndarray | float:
    """Extra motor current (mA) while a wall blocks the tip: stiffness per deg of knob past it.

    The blocked knob travel is the blocked tip angle over the loaded slope omega. 0.0 when the
    contact effect is off.
    """
    wall = _by_name(effects).get("contact")
    if wall is None:
        return 0.0
    blocked = np.abs(trace.free - trace.tip)
    return wall["stiffness"] * blocked / trace.knob.omega


# --------------------------------------------------------------------------------------------
# the model's prediction
# --------------------------------------------------------------------------------------------
def run_condition(meta: Mapping[str, str], source: str | None = None) -> float | None:
    """The ``condition`` metadata of a run (deg of curvature-equivalent), or None when absent.

    Catheter runs leave it out: their condition is the total curvature of ``shape``. Other
    cable-driven data give the driver of the condition effects here (see :func:`condition_knob`).

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

    Each knob uses the offset :meth:`Model.offsets_for` gives for the run's metadata; conditions
    (the shaft curvature of friction and deadzone) come from the run's ``shape`` metadata. The
    output starts from the run's first measured ``y<k>`` when present, else 0.

    Parameters
    ----------
    model : Model
    run : Run
        Needs ``q<k>`` for the knobs to predict (knobs of the model without one are left out),
        ``t`` when a time-driven effect is on.
    effects : sequence, optional
        Effects to use instead of ``model.effects`` (the diagnosis tries candidates this way).

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
    offsets = model.offsets_for(run.meta)
    shape = Shape.parse(run.meta.get("shape"))
    cond = run_condition(run.meta, run.source)
    q = {k: np.ascontiguousarray(run[f"q{k}"], dtype=np.float64) for k in (1, 2) if f"q{k}" in run}
    knobs = [k for k in model.knobs if k in q]
    if not knobs:
        raise DataError(f"{run.source or 'run'}: no command column for the model's knobs "
                        f"({', '.join(f'q{k}' for k in model.knobs)})")
    t = np.ascontiguousarray(run["t"], dtype=np.float64) if "t" in run else None
    out: dict[int, np.ndarray] = {}
    for k in knobs:
        yk = run.columns.get(f"y{k}")
        y0 = float(yk[0]) if yk is not None and len(yk) else 0.0
        knob = model.knob(k).with_offset(offsets[k])
        if not effs:
            out[k] = knob.forward(q[k], y0)
        else:
            out[k] = tip_chain(knob, k, q, t, effs, shape, y0, condition=cond).y
    return out


# --------------------------------------------------------------------------------------------
# the inverse (compensation with effects)
# --------------------------------------------------------------------------------------------
@njit(cache=True, fastmath=False)
def _lag_affine(dt, tau, u_prev, z_prev):
    # one step of _lag_kernel written as z_i = a u_i + b: a = 1 - c, b = c u_{i-1} + e (z_{i-1} - u_{i-1}),
    # c = (1 - e) tau / dt, e = exp(-dt/tau); both inverse kernels solve this for their own unknown
    e = math.exp(-dt / tau)
    c = (1.0 - e) * tau / dt
    return 1.0 - c, c * u_prev + e * (z_prev - u_prev)


@njit(cache=True, fastmath=False)
def _unlag_kernel(z_target, t, tau, lead, out):
    # the command u whose first-order lag (the exact solution of _lag_kernel, started at rest on
    # u[0]) lands on z_target: z_i = A u_i + B with A = 1 - c, B = c u_{i-1} + e (z_{i-1} - u_{i-1}),
    # c = (1 - e) tau / dt, e = exp(-dt/tau); 0 < A <= 1, so u_i is unique. A knob cannot move
    # infinitely fast: the lead |u - z_target| is limited to ``lead`` deg (then the lag catches
    # up over the next samples)
    n = z_target.shape[0]
    if n == 0:
        return
    u_prev = z_target[0]
    z = z_target[0]
    tp = t[0]
    out[0] = u_prev
    for i in range(1, n):
        dt = t[i] - tp
        if dt > 0.0:
            a, b = _lag_affine(dt, tau, u_prev, z)
            u = (z_target[i] - b) / a
            if u > z_target[i] + lead:
                u = z_target[i] + lead
            elif u < z_target[i] - lead:
                u = z_target[i] - lead
            z = a * u + b
        else:
            u = u_prev
        out[i] = u
        u_prev = u
        tp = t[i]


@njit(cache=True, fastmath=False)
def _uncreep_kernel(y_target, t, fraction, tau, out):
    # y = (1 - f) yh + f lag(yh, tau) with lag(yh)_i = A yh_i + B (see _unlag_kernel): solve for
    # yh_i sample by sample; 1 - f + f A > 0, and the inverse is stable (creep is minimum-phase)
    n = y_target.shape[0]
    if n == 0:
        return
    u_prev = y_target[0]
    z = y_target[0]
    tp = t[0]
    out[0] = u_prev
    for i in range(1, n):
        dt = t[i] - tp
        if dt > 0.0:
            a, b = _lag_affine(dt, tau, u_prev, z)
            u = (y_target[i] - fraction * b) / (1.0 - fraction + fraction * a)
            z = a * u + b
        else:
            u = u_prev
        out[i] = u
        u_prev = u
        tp = t[i]


@dataclass(frozen=True)
class Inverse:
    """Result of :func:`inverse`: the knob commands and what the user should know.

    Attributes
    ----------
    q : dict of int to numpy.ndarray
        Knob commands per knob (deg).
    warnings : tuple of str
        Targets no command can reach (a wall, the saturation limit), clipped.
    """

    q: dict
    warnings: tuple = ()


def inverse(model: Model, run, offsets: Mapping[int, float] | None = None,
            effects: Sequence[Effect | EffectSpec] | None = None, knobs: Sequence[int] | None = None,
            max_lead: float = 30.0, iterations: int = 50) -> Inverse:
    """Knob commands that make the model *with its effects* follow the desired tip angles.

    Every stage of :func:`tip_chain` is monotone in its input, so the chain is undone stage by
    stage in reverse order:

    ======== ===================================================================================
    sensor   latency: aim at the reference ``delay`` seconds ahead (the trajectory is known in
             advance; the last value is held at the end)
    contact  the tip cannot pass the wall: the target is clipped there (with a warning)
    output   creep: per-sample exact inverse of the partial lag; saturation: ``atanh``
             (targets beyond 99.9 % of the limit are clipped, with a warning)
    hyst.    the exact inverse of DESIGN.md section 3 on the conditioned knob (friction,
             deadzone under the run's shape)
    input    rate: per-sample exact inverse of the first-order lag, the lead over the target
             limited to ``max_lead`` deg; coupling: the other knob's command is added back,
             solved for both knobs together by fixed-point iteration (contraction |gain| < 1);
             with rate and coupling both on the exact inverse is unstable, so the coupling is
             cancelled on the other knob's lagged command (error ~ gain*tau*its speed)
    ======== ===================================================================================

    So ``predict`` of the commands equals the reference except during the first ``delay``
    seconds, where a rate lag needs more lead than ``max_lead``, and where a target was clipped.

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
        Largest lead (deg) of a command over the lagged input it aims at (rate effect).
    iterations : int
        Most fixed-point passes for coupling.

    Returns
    -------
    Inverse

    Raises
    ------
    DataError
        No ``r<k>`` column, or no ``t`` when a time-driven effect is on.
    """
    effs = as_effects(model.effects if effects is None else effects)
    on = _by_name(effs)
    use = [int(k) for k in (knobs if knobs is not None else run.knobs("r"))]
    if not use:
        raise DataError(f"{run.source or 'run'}: no desired tip angle column (r1 or r2)")
    offs = model.offsets_for(run.meta) if offsets is None else dict(offsets)
    shape = Shape.parse(run.meta.get("shape"))
    cond = run_condition(run.meta, run.source)
    needs_t = any(n in on for n in ("rate", "creep", "latency"))
    t = np.ascontiguousarray(run["t"], dtype=np.float64) if (needs_t or "t" in run) else None
    warnings: list[str] = []
    x: dict[int, np.ndarray] = {}
    for k in use:
        r = np.ascontiguousarray(run[f"r{k}"], dtype=np.float64)
        if not np.all(np.isfinite(r)):
            raise DataError(f"{run.source or 'run'}: r{k} holds NaN or infinite values")
        lat = on.get("latency")
        if lat is not None and r.size:
            r = np.interp(t + lat["delay"], t, r)
        wall = on.get("contact")
        if wall is not None:
            w = wall["wall"]
            clipped = np.minimum(r, w) if w > 0 else np.maximum(r, w)
            if np.any(clipped != r):
                warnings.append(f"knob {k}: the reference passes the wall at {w:g} deg: clipped there")
            r = clipped
        creep = on.get("creep")
        if creep is not None and r.size:
            out = np.empty_like(r)
            _uncreep_kernel(r, t, float(creep["fraction"]), float(creep["tau"]), out)
            r = out
        sat = on.get("saturation")
        if sat is not None:
            lim = sat["limit"]
            reach = 0.999 * lim
            if np.any(np.abs(r) > reach):
                warnings.append(f"knob {k}: the reference passes 99.9 % of the saturation limit "
                                f"{lim:g} deg: clipped there")
            r = lim * np.arctanh(np.clip(r, -reach, reach) / lim)
        kn = condition_knob(model.knob(k).with_offset(offs[k]), effs, shape, cond)
        x[k] = kn.inverse(r, y0=0.0)
    rate, cp = on.get("rate"), on.get("coupling")

    def unlag(z: np.ndarray) -> np.ndarray:
        if rate is None or z.size == 0:
            return z
        out = np.empty_like(z)
        _unlag_kernel(np.ascontiguousarray(z), t, float(rate["tau"]), float(max_lead), out)
        return out

    def relag(z: np.ndarray) -> np.ndarray:
        return z if rate is None or z.size == 0 else _lag(z, t, rate["tau"], None)

    q = {k: unlag(x[k]) for k in use}
    if cp is not None and len(use) == 2:
        g = cp["gain"]
        for _ in range(max(int(iterations), 1)):
            # with rate on, cancelling g*q_other exactly is unstable (the inverse of
            # L(q_k) - g q_other has a pole at (1/|g| - 1)/tau > 0): cancel g*L(q_other) instead,
            # a contraction by |g| that leaves about g*tau*(speed of the other knob)
            new = {k: unlag(x[k] + g * relag(q[3 - k])) for k in use}
            change = max(float(np.max(np.abs(new[k] - q[k]), initial=0.0)) for k in use)
            q = new
            if change < 1e-10:
                break
    return Inverse(q, tuple(warnings))
