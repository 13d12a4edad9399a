"""``saturation``: the bending section stiffens near its largest bend.

The tip y follows the hysteresis output y_h through a static map that flattens towards a limit:

==========  =========================================================  =========================
form        tip                                                         null
==========  =========================================================  =========================
smooth      limit * tanh(y_h / limit)                                   limit = inf (default)
hard        y_h clipped to [-limit, limit] (a mechanical stop)          limit = inf
asymmetric  limit * tanh(y_h / limit) for y_h >= 0, and                 limit = inf
            ratio*limit * tanh(y_h / (ratio*limit)) below
smooth-     smooth, with knob 2's section flattening towards            limit = inf
knobs       +-knob2*limit (each knob bends its own section or plane)
hard-knobs  hard, knob 2's section stopping at +-knob2*limit             limit = inf
knee        y_h up to +-limit, beyond it limit + slope*(|y_h| - limit)  limit = inf
            (a second, stiffer spring engages: the section keeps
            bending, slower)
==========  =========================================================  =========================

The ``-knobs`` forms exist because the two knobs of a 2-DoF catheter bend different sections (or
the same section in two planes, with different tendon moment arms and wall stiffness): nothing
makes their largest bends equal, and one limit shared by both knobs must compromise between them,
where a one-sided ``contact`` wall fits one of them exactly and wins.

A ``knee`` is not a stop: past it every sample shows the slope, and a run driven farther than the
training runs is predicted to keep bending at it, where ``hard`` would hold it at the knee.

Compensation inverts the map; targets beyond 99.9 % of a smooth limit (or beyond a hard one)
cannot be reached and are clipped there, with a warning; a knee's map is inverted exactly.
"""
from __future__ import annotations

import math

import numpy as np

from .base import EffectType, Form

_INF = math.inf
_STEP = (400.0 / 20.0) ** (1.0 / 19.0)
"""The limit grid's ratio (17 %): a smooth flattening's SSE is a smooth function of its limit,
which the sub-grid vertex reads between these points."""
_LIMITS = np.concatenate([np.geomspace(20.0, 400.0, 20), [math.inf]])
_HARD_LIMITS = np.concatenate([np.geomspace(20.0, 400.0, 58), [math.inf]])
"""A hard stop's grid (5.4 %, a third of the smooth forms' step, their points included): a stop's
SSE has a kink where the stop meets the largest free tip, no vertex to read between coarse
points, and every clipped sample shows the stop's level to the grid's step (a contact wall's
grid is 5 deg: a stop must be placed as finely to be told from it)."""


def _ratios(step: float, n: int) -> np.ndarray:
    """Knob 2's ratio axis of ``hard-knobs``: integer powers of its limit grid's ``step``
    (0.5-2), so that every knob-2 limit it makes (limit x knob2) is a point of ``hard``'s grid.
    A stop is invisible below it: where the runs take only knob 2 to its stop, knob 1's limit
    is free above knob 1's largest tip. On a ratio axis of its own step the product would set
    knob 2's stop more finely than ``hard`` can, and that finer placement, not the data, would
    earn the extra parameter and leave knob 1's stop wherever the lattice put it (off, for a run
    that drives knob 1 past it). Commensurate, ``hard`` fits those runs as well with one
    parameter less and BIC keeps it: a catheter's two sections are alike unless the data show
    them different."""
    return step ** np.arange(-n, n + 1, dtype=float)


def _form(name: str, summary: str, second: str | None = None) -> Form:
    """A saturation form; ``second`` names a ratio parameter (the negative side's limit for
    ``asymmetric``, knob 2's for the ``-knobs`` forms)."""
    params, units = ("limit",), ("deg",)
    limits = _HARD_LIMITS if name.startswith("hard") else _LIMITS
    typical, bounds, domain, axes = {"limit": 80.0}, {"limit": (20.0, 400.0)}, {"limit": (1e-6, _INF)}, {"limit": limits}
    if second == "slope":
        # the smooth forms' limit grid (17 %: a knee's misplacement costs only 1 - slope of a
        # stop's; on the stops' finer grid it would beat the two-parameter asymmetric form by its
        # spacing), the slope (0: a stop, 1: no knee) in quarter steps
        return Form(name, "output", 0, ("limit", "slope"), ("deg", "1"), "limit", _INF,
                    {**typical, "slope": 0.5}, {**bounds, "slope": (0.05, 0.95)},
                    {**domain, "slope": (1e-3, 1.0)}, {"limit": limits, "slope": np.array([0.25, 0.5, 0.75])},
                    summary)
    if second:
        params, units = params + (second,), units + ("1",)
        typical, bounds, domain = ({**typical, second: 1.0}, {**bounds, second: (0.25, 4.0)},
                                   {**domain, second: (1e-3, 1e3)})
        if second == "ratio":
            axes = {"limit": np.concatenate([np.geomspace(20.0, 400.0, 10), [math.inf]]),
                    second: np.geomspace(0.4, 2.5, 5)}
        elif name.startswith("hard"):
            # knob 2's limit on the hard grid, in steps of two of its points (11 %)
            axes = {"limit": limits, second: _ratios(_STEP ** (2.0 / 3.0), 6)}
        else:
            # a smooth flattening bends every sample, far below its limit too: each knob's limit
            # is seen wherever that knob moves, and its ratio keeps a step of its own (12 %)
            axes = {"limit": limits, second: np.geomspace(0.5, 2.0, 13)}
    return Form(name, "output", 0, params, units, "limit", _INF, typical, bounds, domain, axes, summary)


class Saturation(EffectType):
    name = "saturation"
    summary = "the bending section stiffens: tip = limit * tanh(tip / limit)"
    driver = "tip"
    regressors = ("tip angle",)
    forms = (
        _form("smooth", "the tip flattens smoothly towards +-limit"),
        _form("hard", "the tip stops at +-limit"),
        _form("asymmetric", "the tip flattens towards +limit and -ratio*limit", "ratio"),
        _form("smooth-knobs", "each knob's section flattens towards its own limit (knob 2: knob2*limit)", "knob2"),
        _form("hard-knobs", "each knob's section stops at its own limit (knob 2: knob2*limit)", "knob2"),
        _form("knee", "past +-limit the tip bends at slope times the rate (a stiffer second stage)", "slope"),
    )

    @staticmethod
    def _limits(eff, k: int) -> tuple[float, float]:
        """The positive and negative limits on knob ``k``."""
        lim = eff["limit"]
        if eff.form == "asymmetric":
            return lim, lim * eff["ratio"]
        if eff.form.endswith("-knobs") and k == 2:
            lim = lim * eff["knob2"]
        return lim, lim

    @staticmethod
    def _hard(eff) -> bool:
        return eff.form.startswith("hard")

    @staticmethod
    def _knee(z, lim: float, slope: float):
        """The knee's map (``slope``) or its inverse (``1/slope``), arrays or floats."""
        a = np.abs(z)
        return np.where(a > lim, np.sign(z) * (lim + slope * (a - lim)), z)

    def forward(self, eff, z, sig, state):
        lim, neg = self._limits(eff, sig.k)
        if eff.form == "knee":
            return self._knee(z, lim, eff["slope"])
        if self._hard(eff):
            return np.clip(z, -lim, lim)
        if eff.form == "asymmetric":
            return np.where(z >= 0.0, lim * np.tanh(z / lim), neg * np.tanh(z / neg))
        return lim * np.tanh(z / lim)

    def knob_key(self, eff, k):
        # the map on one knob: its kind and that knob's limits (a -knobs form is the one-limit
        # form on each knob, with knob 2's limit its own; a knob-1 run does not see knob2)
        lim, neg = self._limits(eff, k)
        if eff.form == "knee":
            return "knee", lim, eff["slope"]
        if self._hard(eff):
            return "hard", lim
        return ("asymmetric", lim, neg) if eff.form == "asymmetric" else ("smooth", lim)

    def identity_range(self, eff, k):
        # a stop and a knee leave the tip alone up to their limits; tanh bends every sample
        if eff.form == "knee" or self._hard(eff):
            lim, neg = self._limits(eff, k)
            return -neg, lim
        return None

    def at_rest(self, eff, y, sig):
        lim, neg = self._limits(eff, sig.k)
        if eff.form == "knee":
            return float(self._knee(y, lim, 1.0 / eff["slope"]))
        if self._hard(eff):
            return min(max(y, -lim), lim)
        if eff.form == "asymmetric" and y < 0.0:
            lim = neg
        # the hysteresis state behind a saturated tip reading
        return lim * math.atanh(max(-1 + 1e-12, min(1 - 1e-12, y / lim)))

    def inverse(self, eff, z, sig, state, warnings, options):
        k = sig.k
        lim, neg = self._limits(eff, k)
        if eff.form == "knee":
            return self._knee(z, lim, 1.0 / eff["slope"])
        if self._hard(eff):
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

    # -- one sample at a time (hystcli/stream/) --------------------------------------------------
    def stepper(self, eff, k, options, warnings):
        """The inverse static map, one sample at a time (warns once, as :meth:`inverse`)."""
        from .kernels import StatelessStep

        lim, neg = self._limits(eff, k)
        said = []

        def say(text):
            if not said:
                said.append(True)
                warnings.append(text)

        if eff.form == "knee":
            inv_slope = 1.0 / eff["slope"]

            def knee(z, other):
                # _knee's inverse in plain floats: called once per sample, where numpy's scalar
                # overhead would dominate
                return z if abs(z) <= lim else math.copysign(lim + inv_slope * (abs(z) - lim), z)
            return StatelessStep(knee)
        if self._hard(eff):
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
