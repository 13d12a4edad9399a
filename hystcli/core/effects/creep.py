"""``creep``: slow viscoelastic relaxation of the tip over seconds.

The tip is ``y = (1 - fraction) * y_h + fraction * lag(y_h, tau)``: after a move, the last
``fraction`` of it arrives with time constant ``tau`` (0.5-20 s on a catheter). A negative
fraction is the other sign of the same physics: the tip overshoots by ``|fraction|`` of the move
and relaxes back. The inverse is exact sample by sample (the map is minimum-phase for
fraction < 1).
"""
from __future__ import annotations

import math

import numpy as np

from . import kernels
from .base import EffectType, Form

_INF = math.inf


class Creep(EffectType):
    name = "creep"
    summary = "viscoelastic creep: a fraction of each tip move arrives with time constant tau"
    driver = "time"
    regressors = ("time since reversal", "knob velocity", "knob direction")
    forms = (
        Form("relax", "output", 10, ("fraction", "tau"), ("1", "s"), "fraction", 0.0,
             {"fraction": 0.2, "tau": 3.0}, {"fraction": (-0.6, 0.6), "tau": (0.2, 30.0)},
             {"fraction": (-0.95, 1.0), "tau": (1e-9, _INF)},
             {"fraction": np.linspace(-0.4, 0.6, 11), "tau": np.geomspace(0.3, 30.0, 9)},
             "a fraction of each tip move arrives (or, negative, is given back) with time constant tau"),
    )

    def new_state(self, eff):
        return kernels.new_lag_state()

    def forward(self, eff, z, sig, state):
        t = sig.need_t(self.name)
        a = eff["fraction"]
        out = np.empty_like(z)
        kernels.lag_kernel(np.ascontiguousarray(z), t, float(eff["tau"]),
                           kernels.new_lag_state() if state is None else state, out)
        return (1.0 - a) * z + a * out

    def new_inverse_state(self, eff):
        return np.full(3, np.nan)

    def inverse(self, eff, z, sig, state, warnings, options):
        t = sig.need_t(self.name)
        if z.size == 0:
            return z
        out = np.empty_like(z)
        kernels.partial_unlag_kernel(np.ascontiguousarray(z), t, float(eff["fraction"]), float(eff["tau"]), math.inf,
                                     np.full(3, np.nan) if state is None else state, out)
        return out

    # -- one sample at a time (hystcli/stream/) --------------------------------------------------
    def stepper(self, eff, k, options, warnings):
        """The exact inverse, one sample at a time (:meth:`inverse`'s numbers)."""
        return kernels.UnlagStep(float(eff["fraction"]), float(eff["tau"]), math.inf)
