"""``coupling``: 2-DoF cross-talk through the shared backbone: the other knob moves this one's loop.

The driver is the other knob: its command ``q_o`` (``angle`` forms, signed, deg, as the twin
has it) or the size of its section's bend ``|yhat_o|`` (``-magnitude`` forms). Where the drive
acts:

==================  ============================================================  ============
form                knob k, with drive D and gain g                                stage
==================  ============================================================  ============
input               x_k = x_k - g*D: the whole loop shifts along the knob axis     input
                    (the dead zone moves by g*D; default, D = q_o)
output              y_k = y_k + g*D: the tip is pushed, whatever the hysteresis    output
deadzone            d_pos += g*D/2, d_neg -= g*D/2 sample by sample: the dead      edges
                    zone widens (narrows for g*D < 0) with the other bend
==================  ============================================================  ============

each with ``-magnitude`` for D = |yhat_o|. The gain is dimensionless (deg per deg).

Notes
-----
What drives the ``-magnitude`` forms is the other section's *bend*, not its knob's travel: a
bend either way lengthens the shared path the same, but a knob resting in its dead zone (both
tendons slack) bends nothing, and after a reversal the bend holds on its backlash plateau while
the knob travels back. The drive is therefore ``yhat_o``, the other knob's tip as our model
predicts it: its base hysteresis (:meth:`hystcli.core.params.KnobModel.forward`, with the run's
offset) on its command (:attr:`~hystcli.core.effects.base.Signals.other_tip`). A drive of
``|q_o - offset_o|`` made a bent one-knob run (the other knob at rest, its offset non-zero after
a shift) move this loop where physically nothing drives it. The stateless approximation (the
other tendon's stretch past its dead-zone edge) is zero in the dead zone too, but misses the
backlash plateaus, which is where a two-knob run's drive differs most.

The base model, not the other knob's whole chain: its own effects would make the drive depend on
the candidate being fitted (the diagnosis reuses one drive per run across thousands of grid
points) and a coupling on the other knob would make the two chains one forward problem. The
condition stage is left out for the same reason. Without the other knob's model (a one-knob
model on a two-knob run) the drive falls back to ``|q_o - offset_o|``.

Every form needs both knobs in the run; with one knob it is skipped. Its inverse needs the other
knob's command, which compensation is solving for at the same time: the chain iterates over both
knobs (a contraction for |g| < 1), the other bend computed from the other knob's last commands.
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
            if sig.other_tip is not None:
                return np.abs(sig.other_tip)
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

    def reads_bend(self, eff):
        return eff.form.endswith("-magnitude")

    def acts_on(self, form, curvature, condition, two_knobs):
        return two_knobs

    # -- one sample at a time (hystcli/stream/) --------------------------------------------------
    @staticmethod
    def drive_at(eff, other: float) -> float:
        """The other knob's drive D (deg) for one sample of what the coupling sees of it: its
        command (``angle`` forms) or its section's bend (``-magnitude`` forms; the streaming
        compensator runs the other knob's base model forward to get it)."""
        return abs(other) if eff.form.endswith("-magnitude") else other

    def edges_at(self, eff, other: float) -> tuple[float, float]:
        """The moves ``(dp, dn)`` of :meth:`edges` for one sample of what the coupling sees."""
        half = 0.5 * eff["gain"] * self.drive_at(eff, other)
        return half, -half

    def stepper(self, eff, k, options, warnings):
        """:meth:`inverse` one sample at a time (``other``: what :meth:`drive_at` reads)."""
        return _CouplingStep(self, eff)


class _CouplingStep:
    __slots__ = ("etype", "eff", "gain", "sign")

    def __init__(self, etype, eff) -> None:
        self.etype, self.eff = etype, eff
        self.gain = float(eff["gain"])
        self.sign = 1.0 if eff.form.startswith("input") else -1.0

    def reset(self) -> None:
        pass

    def step(self, z: float, t: float, other: float | None = None) -> float:
        if other is None:
            return z
        d = self.etype.drive_at(self.eff, other)
        return z + self.gain * d if self.sign > 0 else z - self.gain * d

    def save(self) -> tuple:
        return ()

    def load(self, state: tuple) -> None:
        pass
