"""``saturation``: the bending section stiffens near its largest bend.

The tip y follows the hysteresis output y_h through a static map that flattens towards a limit:

==========  =========================================================  =========================
form        tip                                                         null
==========  =========================================================  =========================
smooth      limit * tanh(y_h / limit)                                   limit = inf (default)
hard        y_h clipped to [-limit, limit] (a mechanical stop)          limit = inf
asymmetric  limit * tanh(y_h / limit) for y_h >= 0, and                 limit = inf
            ratio*limit * tanh(y_h / (ratio*limit)) below
==========  =========================================================  =========================

Compensation inverts the map; targets beyond 99.9 % of a smooth limit (or beyond a hard one)
cannot be reached and are clipped there, with a warning.
"""
from __future__ import annotations

import math

import numpy as np

from .base import EffectType, Form

_INF = math.inf
_LIMITS = np.concatenate([np.geomspace(20.0, 400.0, 20), [math.inf]])


def _form(name: str, summary: str, **extra) -> Form:
    params, units = ("limit",), ("deg",)
    typical, bounds, domain, axes = {"limit": 80.0}, {"limit": (20.0, 400.0)}, {"limit": (1e-6, _INF)}, {"limit": _LIMITS}
    if extra:
        params, units = params + ("ratio",), units + ("1",)
        typical, bounds, domain = {**typical, "ratio": 1.0}, {**bounds, "ratio": (0.25, 4.0)}, {**domain, "ratio": (1e-3, 1e3)}
        axes = {"limit": np.concatenate([np.geomspace(20.0, 400.0, 10), [math.inf]]),
                "ratio": np.geomspace(0.4, 2.5, 5)}
    return Form(name, "output", 0, params, units, "limit", _INF, typical, bounds, domain, axes, summary)


class Saturation(EffectType):
    name = "saturation"
    summary = "the bending section stiffens: tip = limit * tanh(tip / limit)"
    driver = "tip"
    regressors = ("tip angle",)
    forms = (
        _form("smooth", "the tip flattens smoothly towards +-limit"),
        _form("hard", "the tip stops at +-limit"),
        _form("asymmetric", "the tip flattens towards +limit and -ratio*limit", ratio=True),
    )

    @staticmethod
    def _limits(eff) -> tuple[float, float]:
        lim = eff["limit"]
        return lim, (lim * eff["ratio"] if eff.form == "asymmetric" else lim)

    def forward(self, eff, z, sig, state):
        lim, neg = self._limits(eff)
        if eff.form == "hard":
            return np.clip(z, -lim, lim)
        if eff.form == "asymmetric":
            return np.where(z >= 0.0, lim * np.tanh(z / lim), neg * np.tanh(z / neg))
        return lim * np.tanh(z / lim)

    def at_rest(self, eff, y, sig):
        lim, neg = self._limits(eff)
        if eff.form == "hard":
            return min(max(y, -lim), lim)
        if eff.form == "asymmetric" and y < 0.0:
            lim = neg
        # the hysteresis state behind a saturated tip reading
        return lim * math.atanh(max(-1 + 1e-12, min(1 - 1e-12, y / lim)))

    def inverse(self, eff, z, sig, state, warnings, options):
        lim, neg = self._limits(eff)
        k = sig.k
        if eff.form == "hard":
            if np.any(np.abs(z) > lim):
                warnings.append(f"knob {k}: the reference passes the saturation limit {lim:g} deg: clipped there")
            return np.clip(z, -lim, lim)
        reach, reach_neg = 0.999 * lim, 0.999 * neg
        if np.any(z > reach) or np.any(z < -reach_neg):
            warnings.append(f"knob {k}: the reference passes 99.9 % of the saturation limit "
                            f"{lim:g} deg: clipped there")
        if eff.form == "asymmetric":
            zc = np.clip(z, -reach_neg, reach)
            return np.where(zc >= 0.0, lim * np.arctanh(zc / lim), neg * np.arctanh(zc / neg))
        return lim * np.arctanh(np.clip(z, -reach, reach) / lim)

    # -- one sample at a time (hystcli/stream.py) ------------------------------------------------
    def stepper(self, eff, k, options, warnings):
        """The inverse static map, one sample at a time (warns once, as :meth:`inverse`)."""
        from .kernels import StatelessStep

        lim, neg = self._limits(eff)
        said = []

        def say(text):
            if not said:
                said.append(True)
                warnings.append(text)

        if eff.form == "hard":
            def inv(z, other):
                if z > lim or z < -lim:
                    say(f"knob {k}: the reference passes the saturation limit {lim:g} deg: clipped there")
                    return lim if z > lim else -lim
                return z
            return StatelessStep(inv)
        reach, reach_neg = 0.999 * lim, 0.999 * neg
        text = f"knob {k}: the reference passes 99.9 % of the saturation limit {lim:g} deg: clipped there"
        asym = eff.form == "asymmetric"

        def inv(z, other):
            if z > reach or z < -reach_neg:
                say(text)
            if asym:
                zc = min(max(z, -reach_neg), reach)
                return lim * math.atanh(zc / lim) if zc >= 0.0 else neg * math.atanh(zc / neg)
            return lim * math.atanh(min(max(z, -reach), reach) / lim)

        return StatelessStep(inv)
