"""``latency``: the tracker reports the tip late by a fixed delay.

``y_reported(t) = y(t - delay)`` by linear interpolation; before the first sample the tip sat
where it started. Compensation aims at the reference ``delay`` seconds ahead (a trajectory file
is known in advance; the last value is held at the end). A streaming compensator has no future
samples: it needs ``delay`` seconds of preview of the reference, or it leaves the delay in.

The search grid of the delay is geometric from 0.01 s, as ``rate``'s time constant is: at the slow
runs' speeds a lag of tau and a delay of tau trail the knob alike, so the two are told apart by
what is left at the best of each, and a grid of 0.04 s steps left a 0.075 s delay worse fitted
than a lag of the same time.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .base import EffectType, Form

_INF = math.inf


@dataclass
class DelayState:
    """The tracker's history within ``delay`` (times, tips) and the tip before the first sample."""

    t: np.ndarray | None = None
    y: np.ndarray | None = None
    y0: float | None = None


class Latency(EffectType):
    name = "latency"
    summary = "the tracker reports the tip late by delay seconds"
    driver = "time"
    regressors = ("knob velocity",)
    forms = (
        Form("tracker", "sensor", 0, ("delay",), ("s",), "delay", 0.0, {"delay": 0.1}, {"delay": (0.0, 1.0)},
             {"delay": (0.0, _INF)}, {"delay": np.concatenate([[0.0], np.geomspace(0.01, 1.0, 25)])}, "the tracker reports the tip late"),
    )

    def delay_side(self, form, params):
        # the tracker reports late: the motor current, measured at the motor, is on time
        return 0.0, float(params.get("delay", 0.0))

    def new_state(self, eff):
        return DelayState()

    def forward(self, eff, z, sig, state):
        t = sig.need_t(self.name)
        delay = eff["delay"]
        # y(t - delay) by linear interpolation; before the first sample the tip sat at y0
        if state is None or state.t is None:
            T, Y = t, z
            before = sig.y0
        else:
            T, Y = np.concatenate([state.t, t]), np.concatenate([state.y, z])
            before = state.y0
        out = np.interp(t - delay, T, Y, left=before)
        if state is not None and t.size:
            keep = T >= t[-1] - delay
            # one sample before the window is the left end of the first interpolation interval
            first = max(int(np.argmax(keep)) - 1, 0) if keep.any() else T.size - 1
            state.t, state.y = T[first:].copy(), Y[first:].copy()
            if state.y0 is None:
                state.y0 = before
        return out

    def inverse(self, eff, z, sig, state, warnings, options):
        t = sig.need_t(self.name)
        if z.size == 0:
            return z
        return np.interp(t + eff["delay"], t, z)

    # -- one sample at a time (hystcli/stream/) --------------------------------------------------
    def preview(self, eff):
        """The inverse reads the target ``delay`` seconds ahead: not causal (a streaming
        compensator buffers the reference that long, or leaves the delay in)."""
        return float(eff["delay"])
