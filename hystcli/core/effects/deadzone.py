"""``deadzone``: the shaft's shape changes the dead zone itself, not only its position.

Driven by the total curvature kappa (rad; or the run's stated ``condition``), or by the bend
projected on the knob's plane p (rad, signed: paper eqs. 3-4's sum, :meth:`Shape.projected`):

===========  ========================================================  ==========================
form         knob parameters under the bend                             null
===========  ========================================================  ==========================
width        d_pos += width*kappa/2, d_neg -= width*kappa/2 (deg/rad)   width = 0 (default)
centre       d_pos += shift*kappa, d_neg += shift*kappa                 shift = 0
one-edge     the edge on p's side moves out by side*|p|: d_pos +=       side = 0
             side*p for p > 0, d_neg += side*p for p < 0
centre-bend  d_pos += shift*p, d_neg += shift*p                         shift = 0
===========  ========================================================  ==========================

``width`` widens the dead zone (narrows it for width < 0), split evenly between its edges; the
far edges follow by eq. D_hats, so the whole loop widens. ``centre`` moves both edges the same
way: the dead zone's centre drifts with the bend, by the same amount whichever side it bends to.
The two forms driven by p follow the side the shaft bends to, which kappa cannot: ``one-edge``
is the tendon on the outside of the bend pulled tauter (or given slack, side < 0) by the bend
while the other keeps its length, so only that tendon's edge moves; ``centre-bend`` is a shift
the geometry's (paper eqs. 1-4) misses in proportion to the bend, as a wrong beta_catheter /
beta_knob gives. Without a stated shape p is 0 and they do nothing.
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
        Form("one-edge", "condition", 20, ("side",), ("deg/rad",), "side", 0.0, {"side": 3.0},
             {"side": (-4.0, 10.0)}, {"side": (-_INF, _INF)}, {"side": np.linspace(-4.0, 10.0, 15)},
             "the edge on the side the shaft bends to moves out by side per rad of that bend"),
        Form("centre-bend", "condition", 20, ("shift",), ("deg/rad",), "shift", 0.0, {"shift": 2.0},
             {"shift": (-10.0, 10.0)}, {"shift": (-_INF, _INF)}, {"shift": np.linspace(-10.0, 10.0, 21)},
             "the dead zone's centre moves by shift per rad of the bend on the knob's plane"),
    )

    def condition(self, eff, p, cond_deg, bend_deg=0.0):
        if eff.form in ("one-edge", "centre-bend"):
            bend = math.radians(bend_deg)
            if bend == 0.0:
                return False
            if eff.form == "centre-bend":
                p["d_pos"] += eff["shift"] * bend
                p["d_neg"] += eff["shift"] * bend
            elif bend > 0.0:
                p["d_pos"] += eff["side"] * bend
            else:
                p["d_neg"] += eff["side"] * bend
            return True
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
        if form.name in ("one-edge", "centre-bend"):
            return curvature != 0.0  # the shape's bend only (a stated load has no side)
        return (curvature if condition is None else condition) != 0.0
