"""What a reading of the motor current returns: each monotone stretch's reading and the whole
sweep's (the edges, take-ups and levels with their intervals)."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from ..estimate import Estimate
from .condition import Ripple
from .pwl import Piecewise


@dataclass(frozen=True)
class StretchReading:
    """One monotone stretch's broken line and what its pieces are.

    Attributes
    ----------
    start, stop : int
        Sample indices (``stop`` is the reversal that ends it, or the last sample).
    direction : int
        +1 (knob rising) or -1.
    fit : Piecewise
        The broken line of the current against ``x = direction * q``.
    dead : int or None
        Index of the dead-zone piece (the one before the loading edge).
    edge : int or None
        Index (into ``fit.knots``) of the loading edge.
    edge_at, edge_lo, edge_hi : float
        The loading edge and its profile interval, in knob degrees (NaN when none).
    hold : float
        Knob travel from the stretch's start over which the load behind was held (deg), NaN when
        the stretch shows no held plateau.
    hold_lo, hold_hi : float
        Its interval.
    after_loaded_reversal : bool
        The stretch begins at a reversal where the tendon behind was loaded (past its edge).
    from_reversal : bool
        The stretch begins at a reversal (not the record's first, whose start state the record
        cannot tell).
    """

    start: int
    stop: int
    direction: int
    fit: Piecewise = field(repr=False)
    dead: int | None = None
    edge: int | None = None
    edge_at: float = math.nan
    edge_lo: float = math.nan
    edge_hi: float = math.nan
    hold: float = math.nan
    hold_lo: float = math.nan
    hold_hi: float = math.nan
    after_loaded_reversal: bool = False
    from_reversal: bool = False


@dataclass(frozen=True)
class CurrentReading:
    """What a sweep's current says about one knob.

    Attributes
    ----------
    sign : str
        ``"signed"`` or ``"magnitude"``.
    sign_note : str
        How the sign convention was decided.
    edges : dict of str to Estimate
        ``"pos"``/``"neg"``: knob angle where each tendon is taken up from slack (deg).
    backlash : dict of str to Estimate
        ``"pos"``/``"neg"``: backlash width the current shows after the top / bottom reversal.
    notes : dict of str to str
        Why an edge or a backlash is missing or not fixed (keys ``d_pos``, ``b_neg``, ...).
    no_load : dict of int to float
        The dead zone's current per direction of motion (+1 rising, -1 falling), at the dead
        zone's middle.
    dead_slope : float
        Slope of the current in the dead zone, load coordinates (current unit per deg).
    loaded_slope : dict of str to float
        Slope just past each loading edge, load coordinates (current unit per deg).
    edge_level : dict of str to float
        The current where each tendon is taken up (current unit), moving toward it: a bend moves
        the take-up along the knob, not this level.
    noise : float
        Per-sample noise of the conditioned current about the broken lines.
    current_range : tuple of float
        The lowest and highest conditioned current of the record: the most the sweep loaded each
        tendon.
    ripple : Ripple or None
        The cogging ripple taken out before the stretches were read.
    stretches : tuple of StretchReading
    """

    sign: str
    sign_note: str
    edges: dict[str, Estimate]
    backlash: dict[str, Estimate]
    notes: dict[str, str]
    no_load: dict[int, float]
    dead_slope: float
    loaded_slope: dict[str, float]
    edge_level: dict[str, float]
    noise: float
    ripple: Ripple | None = None
    stretches: tuple[StretchReading, ...] = field(default=(), repr=False)
    current_range: tuple[float, float] = (math.nan, math.nan)


def orientation(sign: str, direction: int) -> int:
    """``l = orientation * c`` is the load coordinate of a stretch moving ``direction``."""
    return int(direction) if sign == "signed" else 1
