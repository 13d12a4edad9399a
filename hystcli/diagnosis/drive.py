"""Where a delay sits: in the drive (before the tendons) or after them (the tip, the tracker).

The motor current is measured at the motor, on the drive side of the tendons; the tip angle at
the tip, by a tracker. A delay in the drive (the knob's tendon following the command late: a
viscous sheath, a motor servo; ``rate``'s input forms) delays the tendons' loading, so the
current's dead-zone edges trail the knob command exactly as the tip's do. A delay after the
tendons (the tip's own dynamics, ``rate``'s output forms; the tracker reporting late,
``latency``) leaves the current on time: the tip's edges trail by ``delay x speed`` more than the
current's. On the smooth runs diagnosis compares, a second-order lag and a pure delay of the same
low-frequency delay fit the tip alike (withheld suite, design seeds 90-96: second-order input
lags were named latency with held-out RMSEs within 1-2 % of each other, both at the noise floor),
but they sit on different sides of the tendons, and the identification sweep's current says which.

:func:`tip_behind_current` reads it: per knob and side, the loading edge the sweep's current
shows (:func:`hystcli.signal.reading.read_current`) against the edge of the loop identified
from the same sweep's tip, divided by the knob speed at the crossing: seconds the tip trails the
current there. On the design seeds' lag and latency cases (suite seeds 0, 91, 92): input lags
0.01-0.2 s against their 0.07-0.66 s (at most 0.3 of it); output lags and latencies 0.9-1.6 of
their delay.

:func:`contradicts` is the diagnosis' use: a candidate form that puts all of its delay on one
side (:meth:`hystcli.core.effects.base.EffectType.drive_share`) is contradicted when the current's
reading sits much closer to the other side's prediction, and the delay is large enough for the
edges to show it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.model import Model
from ..core.run import Run
from ..signal.reading import read_current

MIN_SPEED = 2.0
"""Knob speed (deg/s) at an edge crossing below which a reading is not used: the edges' reading
error (a degree or so) divided by a slow speed is no time at all."""

MIN_READINGS = 2
"""Edge pairs (knob and side) a reading needs."""

MIN_SHOW = 2.0
"""Trail (deg) a candidate's delay must make at the sweep's speed before the current can be said
to contradict it: below it the edges' own reading error decides."""

SHARE_MARGIN = 0.35
"""A form that puts its delay on one side is contradicted when the measured trail of the tip
behind the current lies within this share of the delay of the other side's prediction."""


@dataclass(frozen=True)
class TipBehindCurrent:
    """How long the sweep's tip trails its motor current at the dead-zone edges.

    Attributes
    ----------
    delay : float
        Median over the readings (s): ~0 for a delay in the drive, ~the delay for one after it.
    speed : float
        Median knob speed at the crossings (deg/s).
    readings : tuple of (int, str, float, float)
        (knob, side, tip edge minus current edge along the loading direction in deg, speed in
        deg/s) per edge both the tip's loop and the current show.
    """

    delay: float
    speed: float
    readings: tuple[tuple[int, str, float, float], ...]


def tip_behind_current(model: Model, sweep: Run) -> TipBehindCurrent | None:
    """Read how long the tip trails the motor current at the edges of the identification sweep.

    Parameters
    ----------
    model : Model
        The model identified from ``sweep``'s tip (its dead-zone edges are where the tip saw the
        tendons taken up).
    sweep : Run
        The straight-shaft sweep with ``t``, ``q<k>`` and motor current ``c<k>``.

    Returns
    -------
    TipBehindCurrent or None
        None when the sweep has no current, or fewer than :data:`MIN_READINGS` edges show in
        both the current and the tip at a brisk enough speed.
    """
    if "t" not in sweep:
        return None
    t = np.asarray(sweep["t"], float)
    readings = []
    for k, kn in model.knobs.items():
        if f"q{k}" not in sweep or f"c{k}" not in sweep or len(sweep) < 20:
            continue
        q = np.asarray(sweep[f"q{k}"], float)
        reading = read_current(q, np.asarray(sweep[f"c{k}"], float), t)
        v = np.gradient(q, t)
        for side, d, tip_edge in (("pos", 1, kn.d_pos), ("neg", -1, kn.d_neg)):
            e = reading.edges.get(side)
            if e is None or not e.fixed:
                continue
            at = e.value
            near = (np.abs(q - at) < 1.0) & (d * v > 0)
            if not near.any():
                continue
            speed = float(np.median(np.abs(v[near])))
            if speed < MIN_SPEED:
                continue
            readings.append((int(k), side, float(d * (tip_edge - at)), speed))
    if len(readings) < MIN_READINGS:
        return None
    delay = float(np.median([r[2] / r[3] for r in readings]))
    return TipBehindCurrent(delay, float(np.median([r[3] for r in readings])), tuple(readings))


def contradicts(reading: TipBehindCurrent | None, share: float | None, trail: float) -> bool:
    """Whether the current's reading contradicts a form that puts a delay of ``trail`` seconds
    on one side of the tendons (``share`` 1: all in the drive; 0: all after it; None: no claim)."""
    if reading is None or share is None or not trail > 0 or trail * reading.speed < MIN_SHOW:
        return False
    predicted = (1.0 - share) * trail
    other = share * trail
    return abs(reading.delay - other) < SHARE_MARGIN * trail and abs(reading.delay - predicted) > abs(
        reading.delay - other)
