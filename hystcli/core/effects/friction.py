"""``friction``: tendon-sheath (capstan) friction that grows with the shaft's total curvature.

The sheath eats tension exponentially along a curved path (capstan law): with
``g = exp(mu * kappa)``, kappa the total curvature ``sum |alpha_i|`` in rad (or the run's stated
``condition``), the knob must travel further before the tip follows and the tip follows less of
each degree. Forms: how the curvature shows on the loop (docs/design.md section 3's parameters)

=========  ==========================================  ===========================================
form       knob parameters under curvature kappa         direction when on (mu > 0)
=========  ==========================================  ===========================================
capstan    b -> b*g, omega -> omega/g                   loop widens, tip range shrinks (default)
backlash   b -> b*g                                     only the backlash widens
slope      omega -> omega/g                             only the slope falls
=========  ==========================================  ===========================================
"""
from __future__ import annotations

import math

import numpy as np

from .base import EffectType, Form

_MU = dict(params=("mu",), units=("1/rad",), switch="mu", null=0.0, typical={"mu": 0.3},
           bounds={"mu": (0.0, 1.0)}, domain={"mu": (0.0, 5.0)},
           axes={"mu": np.concatenate([[0.0], np.geomspace(0.005, 1.0, 21)])})
"""The search grid of mu is geometric from 0.005: a weak sheath friction is a few hundredths
(g = 1.05 over a 90-degree bend moves the tip a degree), where a linear grid of 0.05 steps had
only its first point, with no neighbour to interpolate towards off; the fit stuck there and lost
to a dead-zone width, which moves the edges without changing the loaded slope."""


class Friction(EffectType):
    name = "friction"
    summary = "capstan friction: backlash x g and slope / g, g = exp(mu * total curvature in rad)"
    driver = "shape"
    regressors = ("curvature", "condition", "knob direction")
    forms = (
        Form("capstan", "condition", 10, summary="backlash x g and slope / g (capstan law)", **_MU),
        Form("backlash", "condition", 10, summary="backlash x g: the knob travels further before the tip turns", **_MU),
        Form("slope", "condition", 10, summary="slope / g: the tip follows less of each knob degree", **_MU),
    )

    def condition(self, eff, p, cond_deg, bend_deg=0.0):
        kappa = math.radians(cond_deg)
        if kappa == 0.0:
            return False
        g = math.exp(eff["mu"] * kappa)
        if eff.form != "slope":
            p["b_pos"] *= g
            p["b_neg"] *= g
        if eff.form != "backlash":
            p["omega"] /= g
        return True

    def acts_on(self, form, curvature, condition, two_knobs):
        return (curvature if condition is None else condition) != 0.0
