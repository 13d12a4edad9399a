"""The loop re-identified from the sweep under a hypothesised lag (hystcli/refit.py)."""
from __future__ import annotations

import math

import numpy as np

from hystcli import effects as E
from hystcli import refit as R
from hystcli.identify import identify
from hystcli.io import Run
from hystcli.model import KnobModel, Model

TRUE = KnobModel(d_pos=8.0, d_neg=-7.0, b_pos=5.0, b_neg=4.5, omega=1.45, h_pos=-3.0, h_neg=3.5, offset=0.0)


def _sweep(delay: float) -> Run:
    # a fast sweep (40 deg/s triangle) seen by a tracker that reports the tip late
    t = np.arange(0.0, 16.0, 0.002)
    q = 40.0 * (2.0 / math.pi) * np.arcsin(np.sin(2 * math.pi * t / 8.0))
    y = TRUE.forward(q, 0.0)
    y = np.interp(t - delay, t, y, left=y[0])
    y = y + np.random.default_rng(0).normal(0.0, 0.05, t.size)
    return Run({"t": t, "q1": q, "y1": y})


def test_a_latency_widens_the_identified_loop_and_the_refit_gives_it_back():
    sweep = _sweep(0.2)
    model = identify(sweep, max_misfit=math.inf, refuse_unfixed=False).model
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
