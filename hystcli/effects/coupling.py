"""``coupling``: 2-DoF cross-talk through the shared backbone: the other knob moves this one's loop.

The driver is the other knob: its command ``q_o`` (``angle`` forms, signed, deg, as the twin
has it) or its bend's size ``|q_o - offset_o|`` (``-magnitude`` forms: measured from its own
offset, where both its tendons are slack, since a bend either way lengthens the shared path the
same). Where the drive acts:

==================  ============================================================  ============
form                knob k, with drive D and gain g                                stage
==================  ============================================================  ============
input               x_k = x_k - g*D: the whole loop shifts along the knob axis     input
                    (the dead zone moves by g*D; default, D = q_o)
output              y_k = y_k + g*D: the tip is pushed, whatever the hysteresis    output
deadzone            d_pos += g*D/2, d_neg -= g*D/2 sample by sample: the dead      edges
                    zone widens (narrows for g*D < 0) with the other bend
==================  ============================================================  ============

each with ``-magnitude`` for D = |q_o - offset_o|. The gain is dimensionless (deg per deg).
Every form needs both knobs in the run; with one knob it is skipped. Its inverse needs the other
knob's command, which compensation is solving for at the same time: the chain iterates over both
knobs (a contraction for |g| < 1).
"""
from __future__ import annotations

import math

import numpy as np

from .base import EffectType, Form

_INF = math.inf


def _form(name: str, stage: str, rank: int, summary: str) -> Form:
    return Form(name, stage, rank, ("gain",), ("deg/deg",), "gain", 0.0, {"gain": 0.15}, {"gain": (-0.5, 0.5)},
                {"gain": (-_INF, _INF)}, {"gain": np.linspace(-0.5, 0.5, 21)}, summary)


class Coupling(EffectType):
    name = "coupling"
    summary = "the other knob's angle q_other shifts this knob's dead zone by gain * q_other"
    driver = "other knob"
    regressors = ("other knob angle", "other knob magnitude")
    forms = (
        _form("input", "input", 10, "the other knob's angle shifts this knob's input (its whole loop)"),
        _form("input-magnitude", "input", 10, "the other knob's bend size shifts this knob's input"),
        _form("output", "output", 30, "the other knob's angle pushes this knob's tip"),
        _form("output-magnitude", "output", 30, "the other knob's bend size pushes this knob's tip"),
        _form("deadzone", "edges", 0, "the other knob's angle widens this knob's dead zone"),
        _form("deadzone-magnitude", "edges", 0, "the other knob's bend size widens this knob's dead zone"),
    )

    @staticmethod
    def drive(eff, sig) -> np.ndarray:
        """The other knob's drive D (deg)."""
        if eff.form.endswith("-magnitude"):
            return np.abs(sig.other - sig.other_offset)
        return sig.other

    def forward(self, eff, z, sig, state):
        if sig.other is None:
            return z
        if eff.form.startswith("input"):
            return z - eff["gain"] * self.drive(eff, sig)
        return z + eff["gain"] * self.drive(eff, sig)

    def inverse(self, eff, z, sig, state, warnings, options):
        if sig.other is None:
            return z
        if eff.form.startswith("input"):
            return z + eff["gain"] * self.drive(eff, sig)
        return z - eff["gain"] * self.drive(eff, sig)

    def edges(self, eff, n, sig):
        if sig.other is None:
            return None
        half = 0.5 * eff["gain"] * self.drive(eff, sig)
        return half, -half

    def at_rest(self, eff, y, sig):
        if sig.other is None or not eff.form.startswith("output") or sig.other.size == 0:
            return y
        return y - eff["gain"] * float(self.drive(eff, sig)[0])

    def cross_knob(self, eff):
        return True

    def acts_on(self, form, curvature, condition, two_knobs):
        return two_knobs

    # -- one sample at a time (hystcli/stream.py) ------------------------------------------------
    @staticmethod
    def drive_at(eff, other: float, other_offset: float) -> float:
        """The other knob's drive D (deg) for one sample of its command."""
        return abs(other - other_offset) if eff.form.endswith("-magnitude") else other

    def edges_at(self, eff, other: float, other_offset: float) -> tuple[float, float]:
        """The moves ``(dp, dn)`` of :meth:`edges` for one sample of the other knob's command."""
        half = 0.5 * eff["gain"] * self.drive_at(eff, other, other_offset)
        return half, -half

    def stepper(self, eff, k, options, warnings):
        """:meth:`inverse` one sample at a time; the other knob's offset is the step's attribute
        ``other_offset`` (a streaming compensator updates it when the shift changes)."""
        return _CouplingStep(self, eff)


class _CouplingStep:
    __slots__ = ("etype", "eff", "gain", "sign", "other_offset")

    def __init__(self, etype, eff) -> None:
        self.etype, self.eff = etype, eff
        self.gain = float(eff["gain"])
        self.sign = 1.0 if eff.form.startswith("input") else -1.0
        self.other_offset = 0.0

    def reset(self) -> None:
        pass

    def step(self, z: float, t: float, other: float | None = None) -> float:
        if other is None:
            return z
        d = self.etype.drive_at(self.eff, other, self.other_offset)
        return z + self.gain * d if self.sign > 0 else z - self.gain * d

    def save(self) -> tuple:
        return ()

    def load(self, state: tuple) -> None:
        pass
