"""The base loop given back: re-identify the hysteresis from the identification sweep under a
hypothesised time-dependent effect (a lag, a latency, creep).

Why: a lag or a latency of the tracker is in the identification sweep too. The sweep runs fast
(15-40 deg/s), so the tip trails the knob by ``tau * speed`` there, and ``identify``, which knows
no lag, fits a loop that is wider (larger backlash) and steeper than the catheter's. On slower runs
that loop is wrong by more than the lag itself: adding a lag on top of it makes things worse, and
a loop-shape effect (saturation, a dead zone) explains the error better than the true cause.
The physics says what to do instead: a time-dependent effect acts on every record, the sweep
included, so hypothesising it means re-identifying the loop from the sweep with it in place.

For the re-identification the effect is applied to the knob input (``x = effect(q)``): exact for a
lag on the input and for a latency (the hysteresis is rate-independent, so a delay of the output
is a delay of the input), and the same on the loop's slopes for an output lag or creep (a linear
filter commutes with the slope's linear map); it needs no inversion of the noisy tip. The fit is
the local output-error refinement of :mod:`hystcli.identification.tip`, started from the sweep's own
identified loop, on the sweep decimated to :data:`SWEEP_HZ`.

A coupling driven by the other section's bend (the ``-magnitude`` forms) is in the sweep too when
the sweep moves both knobs at once (a two-knob sweep): its drive never changes sign, so
``identify`` bakes the other knob's pull into the loop (an offset and an asymmetry), which is
wrong on every run where the other knob moves differently (a one-knob run most of all), and a
coupling on top of that loop only makes things worse (withheld case 45 of seed 0: every gain
raised the RMSE, 1.57 deg at best; with the loop re-identified under gain 0.05, 0.28 deg). The
input form is re-identified as the lags are (``x = effect(q)``, exact), the output form by taking
the push off the measured tip (``y - g D``, exact too: the push adds to the hysteresis output);
the dead-zone form moves the loop's edges, which the refinement cannot take, and keeps the
sweep's loop. The drive is the other knob's bend as its loop (where the refit's continuation
stands) predicts it over the sweep. The signed (``angle``) forms are left out: a drive of either
sign over a symmetric sweep largely averages out of the identified loop, and re-identifying under
them changed no seed-0 case by more than 0.01 deg while doubling the refits.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np
from scipy.optimize import least_squares
from threadpoolctl import threadpool_limits

from ..core.effects.base import Effect, Signals
from ..core.model import Model
from ..core.params import KnobModel
from ..core.run import Run
from ..identification import tip as T

SWEEP_HZ = 50.0
"""The sweep is block-averaged to this rate for the refits (a lag of 0.02 s resolution)."""

STAGES = ("input", "output", "sensor")
"""Stages of a time-dependent effect whose re-identification this module does."""


@dataclass(frozen=True)
class Sweep:
    """The identification sweep, decimated, per knob that moves in it."""

    t: np.ndarray
    q: Mapping[int, np.ndarray]
    y: Mapping[int, np.ndarray]


def prepare_sweep(run: Run, model: Model) -> Sweep | None:
    """The sweep's moving knobs (command and tip), block-averaged to :data:`SWEEP_HZ`; None when no
    knob of the model moves in it with a measured tip."""
    t = np.asarray(run["t"], float)
    if t.size < 10:
        return None
    fs = 1.0 / float(np.median(np.diff(t)))
    step = max(int(round(fs / SWEEP_HZ)), 1)
    n = (t.size // step) * step

    def avg(a: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(np.asarray(a, float)[:n].reshape(-1, step).mean(axis=1))

    q, y = {}, {}
    for k in model.knobs:
        if f"q{k}" in run and f"y{k}" in run and np.ptp(np.asarray(run[f"q{k}"], float)) > 5.0:
            q[k], y[k] = avg(run[f"q{k}"]), avg(run[f"y{k}"])
    if not q:
        return None
    return Sweep(avg(t), q, y)


DRIVERS = ("speed", "time")
"""Drivers of the effects the sweep carries whatever the shape or load: knob speed and time."""


def applies(eff: Effect) -> bool:
    """Whether the effect is time-dependent in a way the straight sweep carries."""
    return eff.type.driver in DRIVERS and eff.spec_form.stage in STAGES


COUPLED_STAGES = ("input", "output")
"""Stages of a bend-driven coupling whose re-identification this module does (module notes)."""


def carries(etype, form, sweep: Sweep) -> bool:
    """Whether the sweep carries this form of an effect in a way :func:`refit` can take off it:
    a time-dependent effect always (a speed-widened backlash too: :func:`unwiden`), a bend-driven
    coupling of the input or output when both knobs move (module notes)."""
    if etype.driver in DRIVERS:
        return form.stage in STAGES or (form.stage == "edges" and etype.driver == "speed")
    return (etype.driver == "other knob" and len(sweep.q) == 2 and form.stage in COUPLED_STAGES
            and form.name.endswith("-magnitude"))


WIDENING_SPEED = 0.5
"""The sweep's knob speed that widened the backlash it identified: the median of the speed
estimate over the samples moving at least this fraction of the sweep's fastest (the plateaus are
crossed just after a reversal, once the estimate has come back up to the sweep's speed)."""


def unwiden(sweep: Sweep, model: Model, widen: float) -> dict[int, KnobModel]:
    """The loops under a backlash that widens by ``widen * |knob speed|`` (s): each knob's
    identified backlash widths less ``widen`` times the speed the sweep crossed its plateaus at.

    A sweep identifies the plateaus as long as the speed made them (``b + widen * v``), so the
    hypothesis is tried on the loop it implies; a widening the sweep cannot have held (a width
    below zero) leaves a zero width. Closed form, not a refinement: the widening moves only the
    plateau ends, which the identification read directly.
    """
    from ..core.effects import kernels

    out = {k: model.knob(k) for k in model.knobs}
    for k, q in sweep.q.items():
        v = np.empty_like(q)
        kernels.knob_speed_kernel(q, sweep.t, kernels.SPEED_TAU, kernels.new_speed_state(), v)
        v = np.abs(v)
        fast = v >= WIDENING_SPEED * float(np.max(v)) if v.size else v > 0
        speed = float(np.median(v[fast])) if np.any(fast) else 0.0
        m = out[k]
        cut = widen * speed
        p = m.params()
        p["b_pos"], p["b_neg"] = max(m.b_pos - cut, 0.0), max(m.b_neg - cut, 0.0)
        out[k] = KnobModel(**p)
    return out


MAX_NFEV = 30
"""Evaluations of each local refinement (it starts from a neighbouring loop: a few suffice)."""


def _refine(th0: np.ndarray, q: np.ndarray, y: np.ndarray, f_scale: float):
    # the identification's own local refinement (:func:`hystcli.identification.tip._refine`), shorter
    inner = np.where(np.isfinite(T._HI), 1e-7, 0.0)
    th0 = np.minimum(np.maximum(np.asarray(th0, float), T._LO + inner), T._HI - inner)
    span = float(np.ptp(q)) or 1.0
    x_scale = np.array([0.05 * span, 0.05 * span, 0.05, 0.05, 0.05 * span, 0.1, max(1.0, f_scale), 0.05 * span])
    with threadpool_limits(limits=1):
        return least_squares(T._residuals, th0, jac=T._residual_jacobian, bounds=(T._LO, T._HI), args=(q, y),
                             loss="soft_l1", f_scale=f_scale, x_scale=x_scale, max_nfev=MAX_NFEV)


def refit(sweep: Sweep, model: Model, eff: Effect, starts: Mapping[int, KnobModel] | None = None,
          cache: dict | None = None) -> dict[int, KnobModel]:
    """Knob models re-identified from the sweep with ``eff`` acting (knobs not in the sweep keep the
    model's). ``starts``: where each knob's refinement starts (default: the model's own loop);
    ``cache``: refits by the input they saw (an output lag and an input lag of one time constant
    give the sweep the same input, and are refitted once)."""
    if eff.spec_form.stage == "edges":
        return unwiden(sweep, model, eff.type.widening(eff))
    out = {k: model.knob(k) for k in model.knobs}
    cross = eff.type.cross_knob(eff) and len(sweep.q) == 2
    for k, q in sweep.q.items():
        y = sweep.y[k]
        if cross:
            # the other knob over the sweep, and its bend as its loop (where this refit's
            # continuation stands) predicts it
            o = 3 - k
            other = (starts or {}).get(o, model.knob(o))
            bend = other.forward(sweep.q[o], float(sweep.y[o][0])) if eff.type.reads_bend(eff) else None
            sig = Signals(k, sweep.t, sweep.q[o], float(other.offset), float(y[0]), "sweep", bend)
        else:
            sig = Signals(k, sweep.t, None, 0.0, float(y[0]), "sweep")
        if cross and eff.spec_form.stage == "output":
            x = q
            y = np.ascontiguousarray(eff.type.inverse(eff, y, sig, None, [], {}), dtype=np.float64)
            key = (k, x.tobytes(), y.tobytes())
        else:
            x = np.ascontiguousarray(eff.type.forward(eff, q, sig, None), dtype=np.float64)
            key = (k, x.tobytes())
        if cache is not None and key in cache:
            out[k] = cache[key]
            continue
        m = (starts or {}).get(k, model.knob(k))
        zi = (float(y[0]) - 0.5 * (m.h_pos + m.h_neg)) / m.omega
        th0 = T.theta_from_model(m, zi)
        f_scale = max(3.0 * T._robust_sd(T._residuals(th0, x, y)), 1e-3)
        res = _refine(th0, x, y, f_scale)
        out[k] = T.model_of(res.x).with_offset(model.knob(k).offset)
        if cache is not None:
            cache[key] = out[k]
    return out
