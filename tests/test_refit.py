"""The loop re-identified from the sweep under a hypothesised lag (hystcli/diagnosis/refit.py)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from hystcli.core import effects as E
from hystcli.diagnosis import refit as R
from hystcli.identification import identify
from hystcli.core.run import Run
from hystcli.core.model import Model
from hystcli.core.params import KnobModel

TRUE = KnobModel(d_pos=8.0, d_neg=-7.0, b_pos=5.0, b_neg=4.5, omega=1.45, h_pos=-3.0, h_neg=3.5, offset=0.0)


def _sweep(delay: float) -> Run:
    # a fast sweep (40 deg/s triangle) seen by a tracker that reports the tip late
    t = np.arange(0.0, 16.0, 0.002)
    q = 40.0 * (2.0 / math.pi) * np.arcsin(np.sin(2 * math.pi * t / 8.0))
    y = TRUE.forward(q, 0.0)
    y = np.interp(t - delay, t, y, left=y[0])
    y = y + np.random.default_rng(0).normal(0.0, 0.05, t.size)
    return Run({"t": t, "q1": q, "y1": y})


@pytest.mark.slow
def test_a_latency_widens_the_identified_loop_and_the_refit_gives_it_back():
    sweep = _sweep(0.2)
    model = identify(sweep).model
    # the sweep's 0.2 s at 40 deg/s is 8 deg of knob: identify sees a much wider loop
    assert model.knob(1).b_pos > TRUE.b_pos + 4.0
    sw = R.prepare_sweep(sweep, model)
    kn = R.refit(sw, model, E.make_effect("latency", "tracker", delay=0.2))[1]
    assert abs(kn.b_pos - TRUE.b_pos) < 1.0 and abs(kn.b_neg - TRUE.b_neg) < 1.0
    assert abs(kn.omega - TRUE.omega) < 0.1


def test_refit_cache_and_applies():
    sweep = _sweep(0.1)
    model = Model({1: TRUE})
    sw = R.prepare_sweep(sweep, model)
    cache: dict = {}
    a = R.refit(sw, model, E.make_effect("rate", "input", tau=0.1), cache=cache)
    b = R.refit(sw, model, E.make_effect("rate", "output", tau=0.1), cache=cache)
    assert a[1] is b[1]   # an output lag gives the sweep the input an input lag does: refitted once
    assert R.applies(E.make_effect("latency", "tracker", delay=0.1))
    assert not R.applies(E.make_effect("saturation", "smooth", limit=80.0))


TRUE2 = KnobModel(d_pos=7.5, d_neg=-8.0, b_pos=4.8, b_neg=5.2, omega=1.4, h_pos=-3.2, h_neg=3.3, offset=0.0)


def _two_knob_sweep(eff: E.Effect) -> Run:
    # both knobs at once (phase-shifted triangles), each loop moved by the other section's bend
    t = np.arange(0.0, 32.0, 0.01)
    q1 = 40.0 * (2.0 / math.pi) * np.arcsin(np.sin(2 * math.pi * t / 8.0))
    q2 = 40.0 * (2.0 / math.pi) * np.arcsin(np.sin(2 * math.pi * t / 11.0 + 1.0))
    model = Model({1: TRUE, 2: TRUE2}, effects=(eff.spec(),))
    ys = E.predict(model, Run({"t": t, "q1": q1, "q2": q2}))
    rng = np.random.default_rng(1)
    return Run({"t": t, "q1": q1, "q2": q2, "y1": ys[1] + rng.normal(0.0, 0.05, t.size),
                "y2": ys[2] + rng.normal(0.0, 0.05, t.size)})


@pytest.mark.slow
def test_a_two_knob_sweep_carries_a_bend_coupling_and_the_refit_takes_it_off():
    for form in ("input-magnitude", "output-magnitude"):
        eff = E.make_effect("coupling", form, gain=0.1)
        sweep = _two_knob_sweep(eff)
        model = identify(sweep).model
        sw = R.prepare_sweep(sweep, model)
        assert R.carries(eff.type, eff.spec_form, sw)
        kn = R.refit(sw, model, eff)
        for k, true in ((1, TRUE), (2, TRUE2)):
            # the loop under the coupling predicts a one-knob run (the other knob at rest: no
            # drive) far better than the loop the coupling was baked into
            q = 40.0 * np.sin(np.linspace(0.0, 4 * math.pi, 2000))
            want = true.forward(q)
            err_refit = float(np.sqrt(np.mean((kn[k].forward(q) - want) ** 2)))
            err_ident = float(np.sqrt(np.mean((model.knob(k).forward(q) - want) ** 2)))
            assert err_refit < 0.25 * err_ident and err_refit < 0.5, (form, k, err_refit, err_ident)
    # the signed and the dead-zone forms keep the sweep's loop; a one-knob sweep carries none
    assert not R.carries(eff.type, eff.type.get_form("input"), sw)
    assert not R.carries(eff.type, eff.type.get_form("deadzone-magnitude"), sw)
    one = R.prepare_sweep(_sweep(0.0), Model({1: TRUE, 2: TRUE2}))
    assert not R.carries(eff.type, eff.spec_form, one)


def test_a_viscous_backlash_sweep_gives_its_widening_back():
    # _sweep's triangle (40 deg amplitude, 8 s period) turns the knob at 4 * 40 / 8 = 20 deg/s, so
    # it identifies both plateaus c_visc * 20 deg/s too wide (c_visc = 0.05 s: 1 deg); the loop the
    # hypothesis implies is the identified one with that taken off (hand-computed: b - 0.05 * 20).
    # The sweep's own tip does not enter: the wide model stands in for what identify read.
    sweep = _sweep(0.0)
    wide = KnobModel(**{**TRUE.params(), "b_pos": TRUE.b_pos + 1.0, "b_neg": TRUE.b_neg + 1.0})
    model = Model({1: wide})
    sw = R.prepare_sweep(sweep, model)
    eff = E.make_effect("rate", "backlash", c_visc=0.05)
    assert R.carries(eff.type, eff.spec_form, sw)
    kn = R.refit(sw, model, eff)[1]
    assert abs(kn.b_pos - TRUE.b_pos) < 0.02 and abs(kn.b_neg - TRUE.b_neg) < 0.02
    # the edges and the slope stay: the widening moves only the plateau ends
    assert (kn.d_pos, kn.d_neg, kn.omega) == (wide.d_pos, wide.d_neg, wide.omega)
    # a widening larger than the sweep can have held leaves a zero width, never a negative one
    assert R.refit(sw, model, E.make_effect("rate", "backlash", c_visc=1.0))[1].b_pos == 0.0
