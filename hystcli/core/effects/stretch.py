"""``stretch``: a steady load stretches the cable, moving the whole output.

A torque T on the output stretches the cable by T/k and the output sits that much further along,
whatever the input (real EndoWrist data, ``sample_data/real/STUDY.md``: about 0.1 deg per % of
resistive torque). Both envelopes move by the same amount, so the dead zones and backlash widths
stay as they are. The driver c is the run's ``condition`` metadata (the load), or the shape's
total curvature for a catheter run, in rad (the metadata in deg); ``reference`` is the condition
the base model was identified under, so the move is zero there.

==========  ===========================================================================
form        move of both heights h_pos, h_neg
==========  ===========================================================================
linear      compliance * (c - reference)                                    (default)
stiffening  compliance * (g(c) - g(reference)), g(c) = sign(c) ln(1 + s|c|)/s: a cable
            whose stiffness grows with the load (s = stiffening, 1/rad; s -> 0 is linear)
slack       no height moves: the dead zone widens by compliance * (c - reference), split
            evenly between its edges: each tendon, stretched by the load it carries,
            must be wound that much further before it pulls (the slack the knob takes up)
==========  ===========================================================================
"""
from __future__ import annotations

import math

import numpy as np

from .base import EffectType, Form

_INF = math.inf


def _soft(c: float, s: float) -> float:
    # the strain of a cable whose stiffness grows linearly with the load: ln(1 + s c)/s, odd in c
    return math.copysign(math.log1p(s * abs(c)) / s, c)


class Stretch(EffectType):
    name = "stretch"
    summary = "the cable yields to a load: the output moves by compliance * (condition - reference) (rad)"
    driver = "condition"
    regressors = ("condition", "curvature")
    forms = (
        Form("linear", "condition", 0, ("compliance", "reference"), ("deg/rad", "deg"), "compliance", 0.0,
             {"compliance": 3.0, "reference": 0.0}, {"compliance": (-20.0, 20.0), "reference": (-90.0, 180.0)},
             {"compliance": (-_INF, _INF), "reference": (-_INF, _INF)},
             # the offset compliance*(condition - reference) is what the runs see: a coarse reference
             # grid (15 deg of condition) is enough, the joint simplex refines both
             {"compliance": np.linspace(-20.0, 20.0, 41), "reference": np.linspace(-90.0, 180.0, 19)},
             "the output moves by compliance per rad of condition above the reference"),
        Form("stiffening", "condition", 0, ("compliance", "reference", "stiffening"), ("deg/rad", "deg", "1/rad"),
             "compliance", 0.0, {"compliance": 3.0, "reference": 0.0, "stiffening": 1.0},
             {"compliance": (-40.0, 40.0), "reference": (-90.0, 180.0), "stiffening": (0.05, 10.0)},
             {"compliance": (-_INF, _INF), "reference": (-_INF, _INF), "stiffening": (1e-6, _INF)},
             {"compliance": np.linspace(-30.0, 30.0, 21), "reference": np.linspace(-90.0, 180.0, 10),
              "stiffening": np.geomspace(0.5, 5.0, 3)},
             "the output moves less per unit of load as the load grows (a stiffening cable)"),
        Form("slack", "condition", 0, ("compliance", "reference"), ("deg/rad", "deg"), "compliance", 0.0,
             {"compliance": 3.0, "reference": 0.0}, {"compliance": (-20.0, 20.0), "reference": (-90.0, 180.0)},
             {"compliance": (-_INF, _INF), "reference": (-_INF, _INF)},
             {"compliance": np.linspace(-20.0, 20.0, 41), "reference": np.linspace(-90.0, 180.0, 19)},
             "the dead zone widens by compliance per rad of condition above the reference (stretched tendons)"),
    )

    def condition(self, eff, p, cond_deg, bend_deg=0.0):
        if eff.form == "slack":
            half = 0.5 * eff["compliance"] * math.radians(cond_deg - eff["reference"])
            if half == 0.0:
                return False
            p["d_pos"] += half
            p["d_neg"] -= half
            return True
        if eff.form == "stiffening":
            s = eff["stiffening"]
            lift = eff["compliance"] * (_soft(math.radians(cond_deg), s) - _soft(math.radians(eff["reference"]), s))
        else:
            lift = eff["compliance"] * math.radians(cond_deg - eff["reference"])
        if lift == 0.0:
            return False
        # equal heights keep dhat_pos, dhat_neg (they depend on h_pos - h_neg): a pure output shift
        p["h_pos"] += lift
        p["h_neg"] += lift
        return True
