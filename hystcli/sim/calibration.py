"""The calibrated virtual catheters: the twin's two ICE catheters tuned to the paper's Tables I and II.

This module owns the *values* of the virtual catheters the demo and the sample data use: their
true hysteresis per knob, their tendon geometry (which sets the shift per shape, paper eqs. 1-4)
and the unmodelled effects they have by default (docs/design.md section 8). The twin
(:mod:`hystcli.sim.twin`) owns the physics; this module only chooses numbers, each with the reason
it has its value. They were chosen so that the paper's whole protocol run through our own core
(:func:`hystcli.sim.experiment.run_protocol`, ``hyst demo``) lands within 30 % of every cell of the
paper's Tables I and II (Kim & Mansi); ``hyst demo`` prints the side-by-side table.

What drives each cell of the tables (this is how the values were chosen):

* **No Compensation** (q = r): the hysteresis itself. The error swings with the dead zone
  (the tip does not move for ``d_pos - d_neg`` of knob), the backlash and the slope omega != 1,
  plus the shift (the whole loop slides along the knob axis by ``omega * offset`` of tip).
  The paper's straight No-Compensation error (PTPE 57.2, RMSE 18.5 deg on a 60 deg periodic
  input) needs a wide dead zone: about +-19 deg of knob, just inside the paper's bound ("the
  dead zone value is less than 20 deg", section IV).
* **Compensation-Only** at the straight shaft: the inverse model is right, so what is left is
  what the base model does not contain: here mainly viscoelastic creep (a fraction of every tip
  move arrives seconds late), which on a 0.04 Hz sine gives an error of the shape of a phase lag
  (PTPE 18.6, RMSE 7.7 deg in the paper).
* **Compensation-Only** at 45 and 90 deg: the unmodelled effects plus the shift the model
  ignores. The shift is what makes these cells large (RMSE 24.2 and 31.3 deg): it sets
  ``beta_catheter / beta_knob`` (offset = beta_catheter/beta_knob * alpha, with alpha in deg).
* **Compensation+Shift**: Algorithm 1 removed the shift; what is left is again the unmodelled
  effects, a little larger on a bent shaft because capstan friction grows with the curvature
  (PTPE 24.3 and 26.0 deg against 18.6 straight).
* **Table II** (2-DoF, knob 2 twice as fast): the same, plus the coupling of the two knobs
  through the shared backbone (the paper's Discussion blames coupling for the 2-DoF residual,
  RMSE 10.1 against 8 deg in 1-DoF), and a larger rate lag on the faster knob.

All effects are real physics terms of :mod:`hystcli.core.effects` (the ones a later diagnosis can
find and add to the model), none is noise.
"""
from __future__ import annotations

from dataclasses import replace
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, Mapping

from ..core.params import Geometry, KnobModel
from ..errors import ModelError

if TYPE_CHECKING:  # the twin and the effects load numba and scipy: imported when a catheter is built
    from ..core.effects import Effect
    from .twin import VirtualCatheter


def taut_heights(b_pos: float, b_neg: float, omega: float) -> tuple[float, float]:
    """Dead-zone heights of a loop whose tip moves only while a tendon is taut.

    After a reversal the tip stays on the backlash plateau while the sheath friction turns over
    (width ``B``), then follows the unloading tendon down to where it goes slack; it must reach
    the dead-zone height exactly where the current says that tendon is slack, i.e.
    :math:`\\hat D_{pos} = D_{neg}` and :math:`\\hat D_{neg} = D_{pos}` (paper eq. D_hats), which
    gives :math:`H_{neg} - H_{pos} = \\omega B`. With two backlash widths we use their mean, and
    centre the loop on the straight tip (:math:`H_{pos} = -H_{neg}`): the same rule
    ``hyst identify`` assumes when it has only the current, so a catheter built with it is one
    the paper's current-based identification can describe exactly (its error is then the
    unmodelled effects and omega != 1.45, as on a real catheter).

    Returns
    -------
    (h_pos, h_neg) : tuple of float
    """
    h = 0.25 * omega * (b_pos + b_neg)
    return -h, h


def _knob(d_pos: float, d_neg: float, b_pos: float, b_neg: float, omega: float) -> KnobModel:
    h_pos, h_neg = taut_heights(b_pos, b_neg, omega)
    return KnobModel(d_pos=d_pos, d_neg=d_neg, b_pos=b_pos, b_neg=b_neg, omega=omega,
                     h_pos=h_pos, h_neg=h_neg)


# --------------------------------------------------------------------------------------------
# the unmodelled effects every calibrated catheter has (docs/design.md section 8)
# --------------------------------------------------------------------------------------------
_DEFAULT_EFFECTS: tuple[tuple[str, dict[str, float]], ...] = (
    # Viscoelastic creep of the polymer shaft and bending section: 26 % of every tip move arrives
    # with a 3.35 s time constant. This is the bulk of the paper's straight Compensation-Only
    # residual (PTPE 18.6, RMSE 7.7 deg): on the 25 s period of the 0.04 Hz input it acts as a
    # phase lag of the tip, an error of about 0.26 * 60 deg * x / sqrt(1 + x^2) = 10 deg
    # amplitude with x = 2 pi * 0.04 Hz * 3.35 s = 0.84 (PTPE ~20, RMSE ~7 deg).
    # Time constants of seconds and fractions of a few tens of percent are what polymer (Pebax)
    # catheter shafts show in step tests.
    ("creep", dict(fraction=0.26, tau=3.35)),
    # Tendon-sheath (capstan) friction: the tension lost in the sheath grows as exp(mu * total
    # curvature). mu = 0.055 per rad of bend makes the backlash 9 % wider and the slope 9 %
    # lower at 90 deg of shaft bend (g = exp(0.055 * pi/2) = 1.09): the small growth of the
    # Compensation+Shift error with curvature in Table I (PTPE 24.3 at 45, 26.0 at 90 against
    # 18.6 deg straight). A small mu because the paper found the backlash change "negligible in
    # dynamic motions" (section IV).
    ("friction", dict(mu=0.055)),
    # Viscous friction of the tendon in its sheath: the knob input reaches the bending section
    # through a first-order lag of 25 ms. Small on the 1-DoF input (about 10 deg/s of knob at
    # most: 0.25 deg), it doubles on the 2-DoF knob that runs twice as fast, and it biases the
    # edges the current shows on the fast identification sweep (40 deg/s: up to 1 deg), so the
    # identified model and Algorithm 1's offsets are each off by about a degree, as on a real
    # catheter.
    ("rate", dict(tau=0.025)),
    # Coupling of the two knobs through the shared backbone: turning one knob by q moves the
    # other knob's dead zone by 0.10 * q. Only the 2-DoF runs (Table II) see it; it is why the
    # paper's 2-DoF Compensation+Shift residual (RMSE 10.1 deg) is larger than the 1-DoF one
    # (about 8 deg), as the paper's Discussion says ("there exist coupling effects in
    # mechanical structures, which is not detected ... from motor current").
    ("coupling", dict(gain=0.10)),
)
"""The unmodelled effects of the calibrated catheters as (name, parameters); why each value: see
the comments. :data:`DEFAULT_EFFECTS` holds them as validated effects."""


# --------------------------------------------------------------------------------------------
# the calibrated catheters
# --------------------------------------------------------------------------------------------
# Knob parameters (d_pos, d_neg, b_pos, b_neg, omega):
# - dead zone about +-19 deg of knob: the width the paper's No-Compensation errors need
#   (PTPE 57.2, RMSE 18.5 deg straight), just inside the paper's "less than 20 deg"; the knobs
#   of one catheter and the two catheters differ by a few percent, as two units of one product
#   do;
# - backlash about 10 deg: with the dead zone it sets the loop width the No-Compensation error
#   swings through;
# - omega around the paper's 1.45 ("we used omega as 1.45 as the average value"), each knob a
#   little off it, so the paper's identification with omega = 1.45 has a small slope error.
# Geometry: offset = (beta_catheter / beta_knob) * alpha (alpha in deg, eqs. 3-4). A ratio of
# about 0.3 (tendons 1.83 mm off the axis of a 10 Fr shaft, a 6 mm knob pulley) makes the
# shift 13.7 deg of knob at 45 deg and 27.5 deg at 90 deg of shaft bend (ice-a): the shift the
# paper's Compensation-Only RMSE (24.2 and 31.3 deg) needs at omega ~ 1.45. At 90 deg this moves
# the new dead zone's negative edge past the knob's rest position (the posterior tendon is
# already taut at q = 0), which Algorithm 1 handles as "a start outside the dead zone".
_CALIBRATED: Mapping[str, dict] = MappingProxyType({
    "ice-a": dict(
        knobs={1: _knob(18.8, -18.8, 9.88, 9.88, 1.45),
               2: _knob(17.8, -19.8, 9.39, 10.37, 1.42)},
        geometry=Geometry(beta_catheter_mm=1.83, beta_knob_mm=6.0),
    ),
    "ice-b": dict(
        knobs={1: _knob(19.9, -19.5, 10.37, 10.08, 1.49),
               2: _knob(19.4, -19.9, 10.67, 9.58, 1.47)},
        geometry=Geometry(beta_catheter_mm=1.92, beta_knob_mm=6.5),
    ),
})

CALIBRATED_NAMES: tuple[str, ...] = tuple(_CALIBRATED)
"""Names of the calibrated catheters (``hyst simulate --catheter``, ``hyst sim-robot``, the demo)."""


def calibrated_catheter(name: str) -> "VirtualCatheter":
    """The virtual catheter ``name`` with the calibrated parameters and default effects.

    Built on the twin's plain catheter of the same letter (:func:`hystcli.sim.twin.get_catheter`,
    ``example-a`` for ``ice-a``: its sensors and motor-current model are kept);
    the knobs, the geometry and the default effects are replaced by this module's values.

    Raises
    ------
    ModelError
        For an unknown name (names the known ones).
    """
    from .twin import get_catheter  # the twin loads numba and scipy: only when a catheter is built

    try:
        values = _CALIBRATED[name]
    except KeyError:
        raise ModelError(f"unknown virtual catheter {name!r} (known: {', '.join(_CALIBRATED)})") from None
    base = get_catheter(name.replace("ice-", "example-"))   # the sensors and the current model
    return replace(base, name=name, knobs=values["knobs"], geometry=values["geometry"],
                   default_effects=tuple(e.spec() for e in default_effects()))


def default_effects() -> "tuple[Effect, ...]":
    """The calibrated catheters' unmodelled effects, validated (see :data:`_DEFAULT_EFFECTS`)."""
    from ..core.effects import make_effect

    return tuple(make_effect(name, **params) for name, params in _DEFAULT_EFFECTS)


def __getattr__(name: str) -> Any:
    # DEFAULT_EFFECTS is built on first use: building it imports the effects (numba)
    if name == "DEFAULT_EFFECTS":
        return default_effects()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["CALIBRATED_NAMES", "DEFAULT_EFFECTS", "calibrated_catheter", "default_effects", "taut_heights"]
