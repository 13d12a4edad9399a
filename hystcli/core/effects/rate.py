"""``rate`` (a lag): viscous friction makes the tip lag the knob, more the faster it turns.

A pure delay on the input equals one on the output for the rate-independent hysteresis, so a lag
is a low-pass, not a delay: it also rounds the tip's response to fast command changes (the jumps
a compensator makes), which ``latency`` does not. Forms, each with time constant tau (s):

=========  ==================================================================  =========
form       where                                                                stage
=========  ==================================================================  =========
input      the knob input x follows the command through a first-order lag       input
           (the tendon in its sheath; default)
input2     ... through two such lags in cascade (second order, critically
           damped: the motor-tendon pair)
output     the tip follows the hysteresis output through a first-order lag      output
           (a viscous bending section)
output2    ... second order
backlash   viscous backlash: both backlash widths grow with knob speed,         edges
           b_pos, b_neg -> b + c_visc*|v| (parameter ``c_visc``, s); the dead
           zone's edges d_pos, d_neg stay, the plateau ends move apart
=========  ==================================================================  =========

Each lag is the exact solution for an input held linearly between samples (a ramp of speed v is
trailed by tau*v). The inverse leads the target by the exact inverse lag, the lead limited to
``max_lead`` deg (a knob cannot move infinitely fast). That discrete inverse has a pole near -1
when tau >> dt: after a jump of its target (the hysteresis inverse jumps across the dead zone at
every reversal) it rings for some tau; one lag settles, two in cascade (``input2``) ring into the
lead limit, so its compensation is approximate (better than none by more than half, not exact).

``backlash``: the tendon drags in its sheath with a force growing with its speed, so after a
reversal the knob travels further before the tip follows, the faster the further. In the model's
terms (docs/design.md section 3) the plateau ends move apart from the dead zone: ``dhat_pos + c|v|``,
``dhat_neg - c|v|`` (:func:`hystcli.core.effects.kernels.forward_edges_kernel`'s ``ep``/``en``), while
``d_pos``/``d_neg`` stay (the engaging tendon's edge: its drag shows as the slope's lag, the
``input`` forms). A constant speed v makes the backlash plateau ``c*v`` longer; at rest it is the
base model. The speed v is the knob input's filtered derivative (time constant
:data:`~hystcli.core.effects.kernels.SPEED_TAU`, robust to a quantised knob at high rates), up to the
*previous* sample: one sample late, which changes nothing at catheter speeds and keeps the inverse
explicit (the move is known before the command is solved for): ``forward(inverse(r)) == r`` to
float rounding for ``c_visc <= SPEED_TAU`` (0.05 s: 2 deg of widening at 40 deg/s). The inverse
jumps across the widened plateau at a reversal and its own jump then reads as speed, which widens
the plateau again by ``c_visc / SPEED_TAU`` of the jump: above 1 an exact inverse is unstable. There
the inverse reads the speed through a slower filter (``2 * c_visc``,
:func:`~hystcli.core.effects.kernels.inverse_speed_tau`): stable, approximate after a speed change
(measured on a 1.3 s + 8 s sine reference: the miss on the model is 35-70 % of the uncompensated
viscous backlash's for c_visc 0.1-0.3 s, 70-90 % up to 3 s). A command step beyond ``max_lead`` deg is limited (a
guard: the commands then miss, and the inverse says so).
"""
from __future__ import annotations

import math

import numpy as np

from . import kernels
from .base import EffectType, Form

_INF = math.inf


def _form(name: str, stage: str, rank: int, summary: str) -> Form:
    return Form(name, stage, rank, ("tau",), ("s",), "tau", 0.0, {"tau": 0.3}, {"tau": (0.0, 2.0)},
                {"tau": (0.0, _INF)}, {"tau": np.concatenate([[0.0], np.geomspace(0.01, 2.0, 20)])}, summary)


class Rate(EffectType):
    name = "rate"
    summary = "viscous lag: the knob input follows the command with time constant tau"
    driver = "speed"
    regressors = ("knob velocity", "knob direction")
    forms = (
        _form("input", "input", 0, "the knob input lags the command (first order)"),
        _form("input2", "input", 0, "the knob input lags the command (second order)"),
        _form("output", "output", 20, "the tip lags the hysteresis output (first order)"),
        _form("output2", "output", 20, "the tip lags the hysteresis output (second order)"),
        Form("backlash", "edges", 10, ("c_visc",), ("s",), "c_visc", 0.0, {"c_visc": 0.05},
             {"c_visc": (0.0, 3.0)}, {"c_visc": (0.0, _INF)},
             {"c_visc": np.concatenate([[0.0], np.geomspace(0.002, 3.0, 20)])},
             "viscous backlash: both backlash widths grow by c_visc * |knob speed|"),
    )

    @staticmethod
    def order(eff) -> int:
        return 2 if eff.form.endswith("2") else 1

    def delay_side(self, form, params):
        # a ramp is trailed by tau per first-order stage; the input forms delay the tendons (the
        # motor current sees it), the output forms the tip after them; the viscous backlash moves
        # plateau ends, not the edges the current reading compares
        if form == "backlash":
            return None, 0.0
        order = 2 if form.endswith("2") else 1
        return (1.0 if form.startswith("input") else 0.0), order * float(params.get("tau", 0.0))

    def edges(self, eff, n, sig):
        # the dead-zone edges stay: only the plateau ends move (widening)
        return None

    def widening(self, eff) -> float:
        return float(eff["c_visc"]) if eff.form == "backlash" else 0.0

    def new_state(self, eff):
        return [kernels.new_lag_state() for _ in range(self.order(eff))]

    def forward(self, eff, z, sig, state):
        t = sig.need_t(self.name)
        if state is None:
            state = self.new_state(eff)
        for st in state:
            out = np.empty_like(z)
            kernels.lag_kernel(np.ascontiguousarray(z), t, float(eff["tau"]), st, out)
            z = out
        return z

    def inverse(self, eff, z, sig, state, warnings, options):
        t = sig.need_t(self.name)
        if z.size == 0:
            return z
        if state is None:
            state = [np.full(3, np.nan) for _ in range(self.order(eff))]
        for st in state:
            out = np.empty_like(z)
            kernels.partial_unlag_kernel(np.ascontiguousarray(z), t, 1.0, float(eff["tau"]), float(options["max_lead"]),
                                         st, out)
            z = out
        return z

    def new_inverse_state(self, eff):
        return [np.full(3, np.nan) for _ in range(self.order(eff))]

    # -- one sample at a time (hystcli/stream/) --------------------------------------------------
    def stepper(self, eff, k, options, warnings):
        """The exact inverse lag(s), one sample at a time (:meth:`inverse`'s numbers)."""
        lead = float(options["max_lead"])
        return kernels.Cascade(kernels.UnlagStep(1.0, float(eff["tau"]), lead) for _ in range(self.order(eff)))

    def forward_stepper(self, eff):
        """The forward lag(s), one sample at a time (:meth:`forward`'s numbers)."""
        return kernels.Cascade(kernels.LagStep(float(eff["tau"])) for _ in range(self.order(eff)))
