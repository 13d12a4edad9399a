"""``deadzone``: the shaft's shape changes the dead zone itself, not only its position.

Driven by the total curvature kappa (rad; or the run's stated ``condition``):

======  =============================================================  ==========================
form    knob parameters under curvature kappa                           null
======  =============================================================  ==========================
width   d_pos += width*kappa/2, d_neg -= width*kappa/2 (deg per rad)    width = 0 (default)
centre  d_pos += shift*kappa, d_neg += shift*kappa                      shift = 0
======  =============================================================  ==========================

``width`` widens the dead zone (narrows it for width < 0), split evenly between its edges; the
far edges follow by eq. D_hats, so the whole loop widens. ``centre`` moves both edges the same
way: the dead zone's centre drifts with the bend beyond what the geometry's shift (paper eqs.
1-4) predicts, e.g. when beta_catheter / beta_knob is off.
"""
from __future__ import annotations

import math

import numpy as np

from .base import EffectType, Form

_INF = math.inf


class Deadzone(EffectType):
    name = "deadzone"
    summary = "dead zone widens by width * total curvature (rad), split evenly between its edges"
    driver = "shape"
    regressors = ("curvature", "condition", "knob direction")
    forms = (
        Form("width", "condition", 20, ("width",), ("deg/rad",), "width", 0.0, {"width": 3.0},
             {"width": (-4.0, 10.0)}, {"width": (-_INF, _INF)}, {"width": np.linspace(-4.0, 10.0, 15)},
             "the dead zone widens by width per rad of curvature"),
        Form("centre", "condition", 20, ("shift",), ("deg/rad",), "shift", 0.0, {"shift": 2.0},
             {"shift": (-10.0, 10.0)}, {"shift": (-_INF, _INF)}, {"shift": np.linspace(-10.0, 10.0, 21)},
             "the dead zone's centre moves by shift per rad of curvature"),
    )

    def condition(self, eff, p, cond_deg):
        kappa = math.radians(cond_deg)
        if kappa == 0.0:
            return False
        if eff.form == "centre":
            move = eff["shift"] * kappa
            p["d_pos"] += move
            p["d_neg"] += move
        else:
            half = 0.5 * eff["width"] * kappa
            p["d_pos"] += half
            p["d_neg"] -= half
        return True

    def acts_on(self, form, curvature, condition, two_knobs):
        return (curvature if condition is None else condition) != 0.0
