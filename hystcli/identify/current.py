"""What the motor current of a sweep says: the dead-zone edges, the backlash plateaus, the levels.

Read per monotone stretch of the knob (:attr:`SweepCheck.segments`), on the current binned by
knob angle (the median of each bin, so spikes do not count) and split into straight pieces by
an exact least-squares segmentation. Physics, not one plant's current law, decides what a piece
is (DESIGN.md section 4):

* the **loading edge** of a stretch is where a tendon is taken up: the slope (dC/dq along the
  motion, loading-positive) jumps, and after it no flat piece follows (only the loaded slope,
  which may stiffen or meet a wall). Among the jumps that qualify, the one out of the flattest
  piece is the edge: a wall's jump starts from a loaded slope, an unloading tendon's arrival
  is followed by the dead zone's flat. Ascending stretches give :math:`D_{pos}`, descending ones
  :math:`D_{neg}`; the kink is then placed by :func:`hystcli.current.kink_fit` (a stiffening
  cable allowed). Pretension (a sloped dead zone) is a smaller jump, not a missing one; a loaded
  slope a small share of the record's other take-ups' is none (:data:`LOADED_SHARE`). A kink out
  of a "dead zone" that climbs steeply is read again on the current around it (:data:`ZOOM`): a
  long stretch that stiffens can spend the segmentation's pieces on its loaded curves; a wall's
  contact read as the take-up (far steeper than the record's others, out of a loaded slope) is
  read again before it. A faint kink is placed no better than :data:`KINK_SPAN` over its clarity.
* the **backlash plateau**: after a reversal with the tendon loaded, a current that holds (a
  flat piece, possibly after an immediate drop; tilted as a pretensioned dead zone is) before it
  unloads shows the backlash width :math:`B`; a current that unloads at once (the tendon's
  stretch) does not, and the reading says so rather than guess. A plateau longer than the
  unloading is read from the unloading back (:func:`_held_plateau`), up to :data:`HELD_RATIO`
  times it; its end is placed by a two-line fit, like an edge (:func:`_refine_end`). A fall
  read as the flip needs an unloading after it clearly steeper than the dead zone: one no steeper
  is the dead zone's tilt, and the "flip" the unloading itself (:data:`TILT_UNLOAD`); and it must
  fall more steeply than the load rose just before the reversal: no steeper, it is that load
  coming back down its own curve (a stiffening cable, :data:`RETRACE`); a fall whose slope, or
  the rise before it, was not read is not weighed, and not read as the flip. After a
  step at the reversal (a force dropped at once), a held plateau must go on for a degree past the
  conditioning low-pass's ringing (:func:`_ring_until`), which lies level for a while too.
* the **levels**: the no-load current of each direction (the motor's Coulomb friction moves it
  with the direction of motion), the loaded slope and the dead zone's slope, which Algorithm 1
  needs for its thresholds.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..current import (FLAT_AFTER, HELD_LEAD, MIN_CLARITY, Kink, arrival_edge, condition, edge_piece, kink_fit,
                       loading_edge, pieces, robust_noise, unloads_after_level)
from ..io import Run
from .sweep import SweepCheck

UNLOAD_LEVEL = 5.0
"""A loading edge read this many current-noise sigmas on the far side of the no-load level (the
other tendon's load) is a held load starting to unload, not an edge."""

WALL_MIN_RUN = 3.0
"""Knob travel (deg) of loaded run after a loading edge before a steeper piece counts as a wall
that ends it (:func:`hystcli.current.loading_edge`'s ``min_run``). The corner at the edge can
make a short piece of its own, between the flat and the loaded slope, and it was taken for the
loaded run, the loaded slope after it for a wall: the kink, fitted on the flat and that short
piece alone, was refused or placed early (design sweep 312, a stretch law: a 0.5-deg corner at
1.8-2.1 mA/deg before the loaded 10.5, no edge read on either stretch down; 992: 0.43 deg early
on one stretch, none on two). Design sweeps 0-999, current only: 2, 3 and 4 deg read 730, 737
and 742 records right against 714 (no new silent failure at 2 and 3, one at 4)."""

LOADED_SHARE = 0.1
"""A loading edge whose loaded slope is below this share of the median loaded slope of the
record's other edges from a reversal is no tendon taken up (:func:`read_current`): a tendon loads
the motor at its own stiffness on every stretch that takes it up. Design sweeps 0-2999: of the
9463 kinks read with other take-ups beside them, the 11 below a tenth were all more than a degree
off their edge (of the 16 below 0.15, 15; 2274's two right ones sit at 0.14 and 0.18). Current
only, per record: 2863 (2.5 deg off at exit 0) refused, 2594 (refused: its weak kink, 16 deg off,
made the edge's readings disagree) right, nothing else changed."""

LOADED_BAND = 3.0
"""A take-up read again on a stretch (:func:`read_current`) loads at most this many times the
median of the record's other take-ups: steeper is a wall's kink."""

END_TRAVEL = 2.0
"""Knob travel (deg) before a stretch's end over which its end slope is read."""

ELASTIC_TOP = 2.0
"""An end slope this many times the loaded slope at the edge: the load rose elastically steeper
at the top of the stroke (a wall, a stiffening cable), so a steep fall after the reversal is that
load coming back, not the sheath friction flipping over the backlash. A stretch whose end slope
is not read (the record's first, too short or slow) takes the median of the stretches that
turned within a degree of the same knob angle: the same wall (design sweep 826: b_pos 9.46 read
on a stretch law, 5.2 deg off; design sweeps 0-2999, current only: that record right, nothing
else changed)."""

DEAD_SHARE = 0.2
"""A "dead zone" before a loading edge that climbs at this share of the loaded slope after it or more
is a candidate for not being the dead zone at all (:data:`DEAD_TILT` decides)."""

DEAD_TILT = 3.0
"""An edge whose dead-zone piece is this many times steeper (``|dC/dq|``) than the other side's, and
at least :data:`DEAD_SHARE` of its own loaded slope, is read on a curve, not at a kink: both sides
cross the same dead zone, where no tendon is taut, and its slope (pretensioned springs, the motor's
viscous term) is the same magnitude both ways (design seeds 0-2999: on the records identify returned,
edges with a dead-zone piece at 0.15 of the loaded slope or more had the two sides within a factor of
1.9 of each other, save one at 5.9 and 0.165 of its loaded slope, right within 0.6 deg; the five
records past both thresholds, all stiffening take-ups or an unloading tail on one side, were 1.0 to
3.5 deg off: 302, 1584, 2010, 2796, 2936; on 3000-4999, checked after, no silent failure is
caught and one record right within 0.4 deg is refused, 4288, at 0.24 and 19x). The kink then sits where the curve bends most, which
depends on its shape, not on where the tendon was taken up: the edge is refused."""


KINK_SPAN = 5.0
"""Knob travel (deg) over which a kink's jump in slope is read, roughly: a kink whose jump is
``clarity`` standard errors is placed no better than this over its clarity. The kink fit's own
standard error assumes two straight lines meeting at a corner; a current law rounds the corner
(a filter, a stiffening cable, an unloading tail), which a clear kink outweighs and a faint one
does not. Design sweeps 0-2999 and 4300000-4600499, current only, on the edges returned with an
uncertainty: the truth within 2 sigma for 71 % of the edges only one stretch showed at a clarity
of 6-10 (76 % at 10-15, 86 % at 15-25); with this floor 90, 94 and 96 %. Edges clearer than 50
keep their own (99.8 %)."""

ZOOM = 0.25
"""Share of a stretch's travel, each side of a kink read on a steep "dead zone", over which
:func:`read_stretch` reads the take-up again (the one value tried). Design sweeps 0-2999 and zoo
ranges 4300000-4500499 (looked at after their figures), current only, per record: 15 more
records right (5 silent failures among them: stiffening cables read 1.2 to 2.1 deg late, 1603,
2513, 2843, 4300029, 4500265), 3 right ones refused (703, 2483, 4400355: with one side's dead
zone read flat, the other's tilt is a curve by :data:`DEAD_TILT`), one wrong refusal returned
with b_neg 1.11 deg off (1584, a stiffening cable)."""


@dataclass(frozen=True)
class Stretch:
    """The current's reading on one monotone stretch of the knob.

    Attributes
    ----------
    start, stop : int
        Sample indices of the stretch.
    direction : int
        +1 ascending, -1 descending.
    from_reversal : bool
        The stretch begins at a reversal (not at the record's first sample).
    edge : Kink or None
        The loading edge, when the stretch passes one.
    dead_level : float or None
        Current just before the loading edge (no tendon taut).
    dead_slope, loaded_slope : float or None
        dC/dq (loading-positive) of the pieces either side of the edge.
    plateau : float or None
        Travel from the reversal over which the current holds before it unloads (deg).
    plateau_held : bool
        The plateau is a held load (a flat piece), not a steep fall read as the sheath friction
        flipping.
    end_slope : float or None
        dC/dq (loading-positive) over the stretch's last degrees before its end: steeper than
        the loaded slope at the edge when a wall or a stiffening cable took the load there.
    resolution : float
        Width of the knob-angle bins the current was read on (deg).
    arrival : Kink or None
        Where the unloading tendon's current arrives at the dead zone (a stretch from a reversal).
    plateau_se : float or None
        Standard error of ``plateau`` from the two-line fit that placed its end (:func:`_refine_end`).
    fall_slope : float or None
        For a ``plateau`` read off a fall (not held): the current's slope over it, past the motor's
        own flip (mA/deg, unloading-positive), which :data:`RETRACE` weighs against the slope the
        load rose with before the reversal.
    """

    start: int
    stop: int
    direction: int
    from_reversal: bool
    edge: Kink | None = None
    dead_level: float | None = None
    dead_slope: float | None = None
    loaded_slope: float | None = None
    plateau: float | None = None
    arrival: Kink | None = None
    plateau_held: bool = False
    end_slope: float | None = None
    resolution: float = 0.5
    plateau_se: float | None = None
    fall_slope: float | None = None


@dataclass(frozen=True)
class CurrentReading:
    """The current's reading of a whole sweep (medians over the stretches that show each thing).

    Attributes
    ----------
    edges : dict
        ``"pos"``/``"neg"`` -> loading edge (deg) when some stretch shows it.
    edges_se : dict
        Their standard errors (deg): the spread over stretches, never below the kink fits' own.
    backlash : dict
        ``"pos"``/``"neg"`` -> plateau width (deg) when the current shows one.
    backlash_se : dict
    arrivals : dict
        ``+1``/``-1`` -> where, moving that way after a reversal, the unloading tendon's current
        arrives at the dead zone (deg): the negative tendon's while rising, the positive's while
        falling.
    no_load : dict
        ``+1``/``-1`` -> no-load current while moving that way (mA).
    loaded_slope, dead_slope : float
        Typical dC/dq with a tendon taut / with none (mA/deg, loading-positive).
    noise : float
        Sample-to-sample noise of the conditioned current (mA).
    stretches : tuple of Stretch
    first_only : tuple of str
        Sides (``"pos"``/``"neg"``) whose edge only the record's first stretch shows: it starts
        from a state the current cannot tell (with the tip held low on its plateau the tendon
        takes up the load further out than the edge), so the edge is an estimate, not a reading.
    doubts : dict
        ``"d_pos"``/``"d_neg"`` -> why the reading leaves that edge out
        although some stretch showed it (readings that contradict each other): it is missing from
        :attr:`edges`, so the current does not fix it (:data:`DEAD_TILT`).
    """

    edges: dict = field(default_factory=dict)
    edges_se: dict = field(default_factory=dict)
    backlash: dict = field(default_factory=dict)
    backlash_se: dict = field(default_factory=dict)
    arrivals: dict = field(default_factory=dict)
    no_load: dict = field(default_factory=dict)
    loaded_slope: float = math.nan
    dead_slope: float = math.nan
    noise: float = math.nan
    stretches: tuple = ()
    first_only: tuple = ()
    doubts: dict = field(default_factory=dict)

    @property
    def no_load_level(self) -> float:
        """The no-load current halfway between the two directions' (mA)."""
        v = list(self.no_load.values())
        return float(np.mean(v)) if v else math.nan


def _bins(x: np.ndarray, c: np.ndarray, width: float) -> tuple[np.ndarray, np.ndarray]:
    k = np.floor((x - x.min()) / width).astype(np.int64)
    # each bin's median at once: sort by (bin, value), then the middle one or two of each run
    order = np.lexsort((c, k))
    k, cs = k[order], c[order]
    starts = np.concatenate([[0], np.flatnonzero(np.diff(k)) + 1])
    sizes = np.diff(np.concatenate([starts, [k.size]]))
    lo = starts + (sizes - 1) // 2
    hi = starts + sizes // 2
    centres = x.min() + (k[starts] + 0.5) * width
    return centres, 0.5 * (cs[lo] + cs[hi])


SLOW = 0.25
"""Samples of a stretch slower than this share of its peak speed are left out of its edge
reading: where a sine sweep slows into its reversal the motor's Coulomb and viscous friction
fade, and the current moves with the speed rather than the tendon."""

RING_STEP = 5.0
"""A current that changes this many times faster (mA/s) just after a reversal than the 90th
percentile of its stretch has stepped there (a force dropped at once): the low-pass that
conditioned it rings after the step (:func:`read_stretch`'s ``ring_s``)."""

GUARD_S = 0.075
"""Time (s) at either end of a stretch left out of its edge reading: the 20 Hz low-pass (the
lab's, or ours) rounds the corner a reversal makes in the current over about this long."""


def read_stretch(q: np.ndarray, c: np.ndarray, t: np.ndarray, start: int, stop: int, direction: int,
                 from_reversal: bool, noise: float, edge_after: float | None = None,
                 fallback: bool = False, ring_s: float = 0.0, edge_before: float | None = None) -> Stretch:
    """Read one monotone stretch (see the module docstring). ``edge_after`` (a knob angle): the
    loading edge read only from the samples past it along the motion; ``edge_before``: only from
    the samples before it (a wall's contact read first, :func:`read_current`); ``fallback``: when the
    likeliest flat piece shows no clear take-up, the next ones are tried
    (:func:`hystcli.current.loading_edge`); ``ring_s``: how long (s) the low-pass that conditioned
    the current rings after a step (one period of its cut-off; 0 when none was applied)."""
    d = direction
    qq, cc, tt = q[start:stop + 1], c[start:stop + 1], t[start:stop + 1]
    x = d * (qq - qq[0])                     # travel along the motion
    travel = float(x.max())
    out = Stretch(start, stop, d, from_reversal)
    if travel < 2.0 or qq.size < 12:
        return out
    width = float(np.clip(travel / 80.0, 0.1, 0.5))
    speed = np.abs(np.gradient(qq, tt))
    brisk = speed >= SLOW * float(np.percentile(speed, 95))
    fast = brisk & (tt >= tt[0] + GUARD_S) & (tt <= tt[-1] - GUARD_S)
    if edge_after is not None:
        fast &= d * (qq - edge_after) > 0
    if edge_before is not None:
        fast &= d * (qq - edge_before) < 0
    # the plateau is read from the reversal on, the edge only where the knob moves briskly
    xa, va = _bins(x, cc, width)
    if fast.sum() < 12:
        return out
    xb, vb = _bins(x[fast], cc[fast], width)
    if xb.size < 10:
        return out
    minlen = max(2, int(round(0.5 / width)))
    sig = noise / math.sqrt(max(1.0, qq.size / max(xb.size, 1)))   # noise of a bin's median, roughly
    qb = qq[0] + d * xb                      # the bins' knob angles

    def take_up(sel: slice | np.ndarray = slice(None)) -> Kink | None:
        # the loading edge of the bins ``sel`` (all of them, or those around a first kink)
        return loading_edge(qb[sel], vb[sel], d, sig, minlen=minlen, resolution=width / 10.0,
                            min_run=int(round(WALL_MIN_RUN / width)), fallback=fallback,
                            corner=True)

    kink = take_up()
    if kink is not None and abs(kink.before) >= DEAD_SHARE * kink.after:
        # a "dead zone" climbing at a fair share of the loaded slope may be one piece spanning the
        # other tendon's unloading, the flat and the take-up's start: a long stretch that
        # stiffens strongly spends the segmentation's pieces on its curves (zoo sweep 4500265, a
        # stiffening stretch law over +-44 deg: five pieces, the one read as the dead zone from
        # -6.6 to +7.9 deg at 12.5 mA/deg, d_pos 1.4 deg late). Read again on the bins around
        # the kink (:data:`ZOOM`), a kink out of a piece that is flat against its loaded slope
        # (half of DEAD_SHARE) replaces it, when it lies no further along the motion and loads
        # as the first did (no wall's kink beyond it: design sweep 161, 15 deg off); a
        # pretensioned dead zone climbs the same there, and its kink stands (2148)
        near = np.abs(qb - kink.at) <= ZOOM * travel
        if near.sum() >= 10:
            k2 = take_up(near)
            if (k2 is not None and abs(k2.before) < 0.5 * DEAD_SHARE * k2.after and d * (k2.at - kink.at) <= 0.5
                    and k2.after <= LOADED_BAND * kink.after):
                kink = k2
    arrival = (arrival_edge(qb, vb, d, sig, minlen=minlen, resolution=width / 10.0)
               if from_reversal else None)
    plateau, held, plateau_se, fall_slope = None, False, None, None
    # from the reversal on (the slow start included), up to the next reversal's own rounding: a
    # drop at that reversal, spread backward by a zero-phase filter, would take one of the pieces
    # the plateau, the unloading, the dead zone and the loading need
    head = tt <= tt[-1] - GUARD_S if stop < q.size - 1 else np.ones(tt.size, bool)
    xp, vp = _bins(x[head], cc[head], width) if 12 <= head.sum() < head.size else (xa, va)
    if from_reversal and xp.size >= 10:
        pa = pieces(xp, vp, minlen)
        sa = [d * m for (_, _, m, _) in pa]
        # where the knob, slow out of its reversal, first moves briskly: the motor's own friction
        # flips sign up to there, however far a slow turn takes it
        slow_until = float(x[np.argmax(brisk)]) if brisk.any() else 0.0
        plateau, held, span = _plateau(pa, sa, xp, sig, from_reversal,
                                       _dead_piece(pa, sa, xp, edge_piece(pa, sa, xp, sig, corner=True)),
                                       slow_until=slow_until,
                                       dead_tilt=abs(kink.before) if kink is not None else 0.0,
                                       ring_until=_ring_until(x, cc, tt, ring_s))
        if plateau is not None:
            # the segmentation's boundary is good to a bin or two; the end of a held load is a
            # kink, placed like an edge (design seeds 0-1799: median error 0.062 -> 0.022 deg,
            # returned more than 1 deg off 6 -> 2, 2-sigma coverage 95.6 -> 98.2 %)
            plateau, plateau_se = _refine_end(xp, vp, plateau, span, width)
            if not held:
                # how steeply the current fell over the flip, past the motor's own flip
                m = (xp >= slow_until) & (xp <= plateau)
                if m.sum() >= 3:
                    fall_slope = d * float(np.polyfit(xp[m], vp[m], 1)[0])
    # the slope over the stretch's last END_TRAVEL deg (least squares on the bins): what the
    # load did just before the next reversal
    last = xa >= xa[-1] - END_TRAVEL if xa.size else xa.astype(bool)
    end_slope = float(np.polyfit(xa[last], va[last], 1)[0]) if last.sum() >= 4 else None
    at_edge = ({} if kink is None else
               dict(edge=kink, dead_level=kink.level, dead_slope=kink.before, loaded_slope=kink.after))
    return Stretch(start, stop, d, from_reversal, plateau=plateau, arrival=arrival, plateau_held=held,
                   end_slope=end_slope, resolution=width, plateau_se=plateau_se, fall_slope=fall_slope, **at_edge)


TILT_UNLOAD = 1.5
"""A fall read as the sheath friction flipping over the backlash (:func:`_plateau`) needs the
unloading after it steeper than this many times the dead zone's own slope (its piece on this
stretch, or before the stretch's loading edge). No steeper, that "unloading" is the dead zone of a
pretensioned tendon (or of the motor's viscous term), and the fall before it the tendon unloading
from the reversal: a current with no backlash in it (design sweeps 1411, 2017, 2269, 2556, a
stretch or drop law with the dead zone tilted at 0.7 to 5 mA/deg: the unloading 0.9 to 1.2 times
that, b 1.2 to 12.1 deg off at exit 0). Design sweeps 0-2999, current only, per record: those 5
silent failures right, the wrong backlash of 1945 and 2657 (walls) no longer claimed, nothing
else changed; the twin's sheath flip (its unloading at the loaded slope, its dead zone flat) is
untouched (test_current_only_recovers_edges_and_backlash). A wall's elastic fall back is not
this (:data:`ELASTIC_TOP`)."""

RETRACE = 1.5
"""A fall read as the sheath friction's flip (:func:`_plateau`) must be steeper than this many
times the slope the load rose with just before the reversal (the previous stretch's end slope):
a current that follows the tendon comes back down the curve it went up, and a stiffening cable's
curve is steep at the top and gentler toward the edge, as a flip followed by the unloading looks
(held-out 4100412, a stretch law: b_neg 9.49 +- 0.44 read off that fall; design sweep 3600272,
b_pos 2.94). A sheath's flip falls at least :data:`FLIP` times the unloading after it, which on
a straight cable is the slope the load rose with. Design sweeps 0-2999 and 3500000-4100499,
current only, per record: those two right, nothing else changed. 1.5 is the one value tried."""

FLIP = 2.0
"""A fall at least this many times the unloading slope over the backlash is the sheath friction
flipping sign (:func:`_plateau`); a steeper piece short of it, right before the unloading slope, is
the stiff end of the unloading itself."""


def ringing_time(filter_hz: float | None) -> float:
    """How long (s) the conditioning low-pass rings after a step: one period of its cut-off
    (:func:`read_current`'s ``ring_s``); 0 without a low-pass."""
    return 1.0 / filter_hz if filter_hz else 0.0


def _ring_until(x: np.ndarray, c: np.ndarray, t: np.ndarray, ring_s: float) -> float:
    """Travel from a reversal (deg) up to which the conditioning low-pass rings, when the current
    steps there (:data:`RING_STEP`); 0 otherwise.

    A force that drops at once as the knob reverses (a sheath's friction flipping) is a step,
    and a zero-phase Butterworth's response to a step undershoots and recovers for about one
    period of its cut-off after it (at 20 Hz, a 300 mA drop: 10-15 mA under the line from 20 to
    40 ms). At a brisk turn that is degrees of knob, and the current there lies level for a
    while, as a held load does (design sweep 3800181, a drop law: 2.3 deg read as a backlash of
    0.39 at 47 deg/s)."""
    if not ring_s > 0 or t.size < 4:
        return 0.0
    rate = np.abs(np.gradient(c, t))
    head = np.flatnonzero(t <= t[0] + 2.0 * ring_s)
    if head.size < 2:
        return 0.0
    top = float(np.percentile(rate, 90))
    i = int(head[np.argmax(rate[head])])
    if not rate[i] > RING_STEP * top:
        return 0.0
    return float(np.max(x[t <= t[i] + ring_s]))


def _plateau(pieces, slopes, xb, sig, from_reversal, dead: int | None,
             slow_until: float = 0.0, dead_tilt: float = 0.0,
             ring_until: float = 0.0) -> tuple[float | None, bool, tuple | None]:
    """Travel from a reversal to where the tendon starts unloading (the backlash), when it shows.

    The stretch after a loaded reversal runs: the backlash phase (a plateau while the sheath
    friction holds the load, or a steep fall while it flips sign, possibly after an immediate
    drop), the unloading slope, the dead zone's flat (piece ``dead``). The backlash is read when
    a piece before the unloading slope clearly differs from it; a current that unloads at once
    (the tendon's stretch) shows none. Returns the width and whether the load was held (a flat
    piece) rather than read off a steep fall, and the travel span of the two pieces either side of
    the plateau's end (where :func:`_refine_end` places it). ``slow_until``: the travel from the
    reversal at which the knob first moves briskly (:data:`SLOW`); ``dead_tilt``: ``|dC/dq|`` of the
    dead zone before this stretch's loading edge (0 when it shows none); ``ring_until``: the travel
    up to which the conditioning low-pass rings after a step at the reversal
    (:func:`_ring_until`), over which no piece counts as held.
    """
    if not from_reversal or dead is None:
        return None, False, None
    # the dead zone may span several flat pieces: start from its first
    if dead + 1 < len(slopes):
        ref = slopes[dead + 1]          # the loaded slope after the dead zone
        own = slopes[dead]

        def same_dead_zone(k: int) -> bool:
            # flat against the loaded slope, and not a tendon unloading out of a held plateau
            return (abs(slopes[k]) <= FLAT_AFTER * max(ref, 1e-12)
                    and not unloads_after_level(pieces, slopes, xb, k, own, sig))

        while dead > 1 and same_dead_zone(dead - 1):
            dead -= 1
    else:
        # a stretch that ends in the dead zone: a piece before the last, flat against the piece
        # before it, is where the unloading ended (held-out 1500263, whose stretch ended on a
        # flatter piece, read the dead zone itself as the unloading and its 6 deg of true
        # unloading as backlash, 6.2 deg off); one that merely softens is the unloading's tail
        # (the twin's one-cycle sweep: 3.0 then 2.3 mA/deg)
        while dead > 2 and abs(slopes[dead - 1]) <= FLAT_AFTER * max(slopes[dead - 2], 1e-12):
            dead -= 1
    if dead < 2:
        return None, False, None
    # the unloading slope: the longest piece before the dead zone, with its neighbours of about
    # the same slope (the segmentation may split it, or round its ends)
    lengths = [xb[p[1] - 1] - xb[p[0]] for p in pieces]
    ju = max(range(dead), key=lambda k: lengths[k])
    unload = slopes[ju]
    if not unload > 0 or ju == 0 or (ju + 1 < dead and unload <= 0.15 * max(slopes[ju + 1:dead])):
        # a held plateau longer than the unloading (a backlash wider than the travel the tendon
        # unloads over, or an unloading the segmentation split) is the longest piece itself: at
        # the reversal (ju 0), or after a lead-in (the motor's Coulomb friction flipping over a
        # few degrees of a slow reversal), flat beside the unloading that follows it
        return _held_plateau(pieces, slopes, lengths, xb, sig, dead)
    while ju > 0 and abs(slopes[ju - 1] - unload) < 0.4 * unload:
        ju -= 1
    background, rel = _background(slopes[dead], unload)

    # a bin's half-width: a piece's points are bin centres, and it spans half a bin beyond them
    half_bin = 0.5 * float(np.median(np.diff(xb))) if xb.size > 1 else 0.0

    def held(k: int) -> bool:
        # flat for a degree, and for a degree past the low-pass's ringing after a step
        past_ring = xb[pieces[k][1] - 1] + half_bin - max(float(xb[pieces[k][0]]) - half_bin, ring_until)
        return _level(slopes[k], background, rel) and lengths[k] >= 1.0 and (ring_until <= 0.0 or past_ring >= 1.0)

    # a stiffening cable unloads convexly: steepest just after the plateau, where its load is
    # largest, and the segmentation splits the unloading into pieces that soften in turn. After a
    # held plateau, the pieces up to the unloading slope that each are steeper than the next by
    # less than a sheath friction's flip (twice, below) are the same unloading. Without a held plateau such a
    # piece may be the flip itself (the twin's sheath friction), and stays the backlash phase
    j = ju
    while j > 0 and slopes[j] <= slopes[j - 1] < FLIP * slopes[j]:
        j -= 1
    if j < ju and j > 0 and held(j - 1):
        ju = j
    length = sum(lengths[ju:dead])
    if ju == 0 or not (length >= 1.0 and unload * length > 6 * sig):
        return None, False, None
    # the backlash phase must show one of the two signatures a backlash leaves, unambiguously:
    # the load held (a flat plateau at least a degree long), or the sheath friction flipping
    # over the plateau's width (a fall at least twice the unloading slope, longer than the
    # motor's own Coulomb flip at a reversal, which is over within a degree or two). The motor's
    # flip lasts as long as the knob is slow, not for a set travel: a slow sine turn of large
    # amplitude spreads it over degrees (held-out 2100090, a stretch law: 2.0 deg of it read as
    # a backlash, 5.4 deg off), so a sheath's flip must go on for a degree past that
    before = range(ju)
    plateau = any(held(k) for k in before)
    steep = [k for k in before if slopes[k] >= FLIP * unload]
    flip = (sum(lengths[k] for k in steep) >= 2.0
            and sum(max(0.0, xb[pieces[k][1] - 1] - max(xb[pieces[k][0]], slow_until)) for k in steep) >= 1.0)
    if not (plateau or flip):
        return None, False, None
    if not plateau and unload <= TILT_UNLOAD * max(abs(slopes[dead]), dead_tilt):
        # the "unloading" is no steeper than the dead zone: it is the dead zone's own tilt, and
        # the fall before it the tendon unloading, not a flip over a backlash
        return None, False, None
    return float(0.5 * (xb[pieces[ju - 1][1] - 1] + xb[pieces[ju][0]])), plateau, \
        (float(xb[pieces[ju - 1][0]]), float(xb[pieces[ju][1] - 1]))


def _background(dead_slope: float, unload: float) -> tuple[float, float]:
    """The dead zone's own slope, against which a held plateau is judged, and the unloading's share
    of the slope above it: with a pretensioned tendon the dead zone climbs at a fair share of the
    unloading slope (design seed 1: 2.5 against 5.0 mA/deg)."""
    bg = dead_slope if abs(dead_slope) <= 0.5 * unload or 0.0 < dead_slope < unload else 0.0
    return bg, unload - max(bg, 0.0)


def _level(slope: float, background: float, rel: float) -> bool:
    """A piece whose load holds: flat, or no steeper than the dead zone's own slope (a
    pretensioned tendon's spring, or the motor's viscous term following the sine's speed, tilt the
    plateau the same as the dead zone: the load itself does not change)."""
    return min(abs(slope), abs(slope - background)) <= 0.15 * rel


HELD_RATIO = 2.0
"""A held plateau longer than this many times the unloading that follows it is not read as the
backlash (:func:`_held_plateau`): a tendon whose load is held over most of its release may have let
go before the knob travelled the whole backlash (design seed 255: the load held over three times
the unloading travel, 10.2 deg read against a backlash of 12.0). Design seeds 0-599: at 1, 1.5 and
2 the same silent failures (two, both older), and 1, 7 and 8 more records read right."""


def _held_plateau(pieces, slopes, lengths, xb, sig, dead: int) -> tuple[float | None, bool, tuple | None]:
    """The backlash as a held load read from the unloading back: the last flat piece (a degree or
    more) before the dead zone, with every piece between it and the dead zone unloading.

    :func:`_plateau` takes the longest piece before the dead zone for the unloading; when the
    plateau is longer (a backlash wider than the tendon's unloading travel, or an unloading the
    segmentation split into pieces) that reads the plateau itself as the unloading. Here the
    unloading is what lies between the dead zone and the last held piece, its slope that of its
    longest piece; its ends may be rounded (the 20 Hz filter), so its pieces need only be clearly
    steeper than the plateau, not equal.
    """
    for k in range(dead - 2, -1, -1):
        group = range(k + 1, dead)
        ju = max(group, key=lambda j: lengths[j])
        unload = slopes[ju]
        if not unload > 0:
            continue
        length = xb[pieces[dead - 1][1] - 1] - xb[pieces[k + 1][0]]
        bg, rel = _background(slopes[dead], unload)
        if not (_level(slopes[k], bg, rel) and lengths[k] >= 1.0):
            continue
        steep = all(slopes[j] > 0 and not _level(slopes[j], bg, rel) for j in group)
        lead = xb[pieces[k][0]] - xb[pieces[0][0]]
        width = float(0.5 * (xb[pieces[k][1] - 1] + xb[pieces[k + 1][0]]))
        if steep and length >= 1.0 and unload * length > 6 * sig and lead <= HELD_LEAD \
                and width <= HELD_RATIO * length:
            return width, True, (float(xb[pieces[k][0]]), float(xb[pieces[k + 1][1] - 1]))
        return None, False, None
    return None, False, None


def _refine_end(xb, vb, width: float, span, resolution: float) -> tuple[float, float | None]:
    """The plateau's end placed by a continuous two-line fit (:func:`hystcli.current.kink_fit`) on
    the binned current of the piece before it and the piece after it, instead of the boundary of
    the segmentation's pieces; with the fit's standard error. Kept at the segmentation's boundary
    when the fit finds no kink inside the span."""
    lo, hi = span
    sel = (xb >= lo) & (xb <= hi)
    if sel.sum() < 6:
        return width, None
    k = kink_fit(xb[sel], vb[sel], 1, curved=False, min_side=2, resolution=resolution / 10.0)
    if (k is None or not (lo < k.at < hi) or abs(k.at - width) > max(1.0, 0.25 * (hi - lo))
            or not abs(k.clarity) >= MIN_CLARITY):
        return width, None
    return float(k.at), float(k.se)


def _dead_piece(pieces, slopes, xb, edge_piece: int | None) -> int | None:
    """The dead zone's piece: the flat piece the loading edge ends, or else (a stretch that ends
    in the dead zone) the flattest piece at least a degree long after the first."""
    if edge_piece is not None:
        return edge_piece
    long_enough = [j for j in range(1, len(pieces)) if xb[pieces[j][1] - 1] - xb[pieces[j][0]] >= 1.0]
    if not long_enough:
        return None
    j = min(long_enough, key=lambda k: abs(slopes[k]))
    return j if abs(slopes[j]) <= FLAT_AFTER * max(max(slopes[:j]), 1e-12) else None


def conditioned_current(run: Run, k: int, filter_hz: float | None = 20.0) -> np.ndarray | None:
    """Knob ``k``'s motor current despiked and low-passed (:func:`hystcli.current.condition`) at the
    run's sample rate; None when the run has none, or one that never moves (a logger's placeholder
    column)."""
    name = f"c{k}"
    if name not in run:
        return None
    raw = np.asarray(run[name], float)
    if not np.ptp(raw) > 1e-9 * max(1.0, float(np.max(np.abs(raw)))):
        return None
    return condition(raw, run.sample_rate if "t" in run else None, filter_hz)


def _references(stretches: list[Stretch]) -> tuple[float, list[tuple[int, float]], float]:
    """The record's references read off its stretches from a reversal: the no-load current, the
    loaded slope of each stretch that read an edge (index, its kink's slope after), and their
    median (NaN where there are none).

    The no-load current, roughly, is the median level at which the stretches from a reversal saw
    a tendon taken up, both ways, and an unloading tendon's current meet the dead zone (a kink
    read where a held load starts to unload sits far from it, on the loaded side; with one edge
    read each way, one of them such a kink, the edges alone put the level halfway and both fell
    outside it: design seed 2005). Where the stretches from a reversal give fewer than two levels,
    the record's first stretch adds its own: a one-cycle sweep's one stretch up from the bottom
    reversal otherwise had its kink judged against its own level (zoo sweep 4600157, a drop law
    holding 16 deg of backlash: the held load's end, 96 mA below the no-load level, was read as
    d_pos, 10.6 deg off at +-0.11; the first stretch's take-up put the level right and the kink
    is refused. Design sweeps 0-2999 and 4300000-4600499, current only, per record: that record
    refused, nothing else changed)."""
    lv = [k.level for s in stretches if s.from_reversal for k in (s.edge, s.arrival) if k is not None]
    if len(lv) < 2:
        lv += [k.level for s in stretches[:1] if not s.from_reversal for k in (s.edge, s.arrival) if k is not None]
    c0 = float(np.median(lv)) if lv else math.nan
    ups = [(i, s.loaded_slope) for i, s in enumerate(stretches) if s.from_reversal and s.loaded_slope is not None]
    loaded_ref = float(np.median([a for _, a in ups])) if ups else math.nan
    return c0, ups, loaded_ref


def read_current(q: np.ndarray, c: np.ndarray, t: np.ndarray, chk: SweepCheck,
                 ring_s: float = 0.0) -> CurrentReading:
    """Read the loading edges, backlash plateaus and levels of a sweep's (conditioned) current.

    Parameters
    ----------
    q, c, t : numpy.ndarray
        Knob command (deg), conditioned motor current (:func:`hystcli.current.condition`), time (s).
    chk : SweepCheck
        The sweep's reversals.
    ring_s : float
        How long (s) the low-pass that conditioned the current rings after a step (one period of
        its cut-off, :func:`_ring_until`); 0 (the default) when it was not low-passed.
    """
    q = np.asarray(q, float)
    c = np.asarray(c, float)
    t = np.asarray(t, float)
    noise = robust_noise(c)
    stretches = []
    for i, (a, b, d) in enumerate(chk.segments):
        stretches.append(read_stretch(q, c, t, a, b, d, from_reversal=i > 0, noise=noise, ring_s=ring_s))
    edges, edges_se, backlash, backlash_se, levels = {}, {}, {}, {}, {}
    # the reading's resolution: the typical bin width (deg) of the stretches read
    resolution = float(np.median([s.resolution for s in stretches])) if stretches else 0.5
    first_only: list[str] = []
    doubts: dict[str, str] = {}
    # per side, the edge readings kept: the dead-zone piece's |dC/dq| and the loaded slope at them
    tilt: dict[str, tuple[float, float]] = {}
    c0, ups, loaded_ref = _references(stretches)
    # a tendon taken up loads the motor at the tendon's stiffness, on every stretch that takes it
    # up: a kink whose loaded slope is a small share of what the record's other take-ups show is
    # no tendon taken up (the current's waviness, the tail of an unloading)
    # per stretch, the median loaded slope of the record's other take-ups (None without any),
    # leaving out the stretches ``skip`` as well
    def median_of_others(skip: set[int] | frozenset[int] = frozenset()) -> list[float | None]:
        return [float(np.median(o)) if o else None
                for o in ([a for j, a in ups if j != i and j not in skip] for i in range(len(stretches)))]

    others_median = median_of_others()
    weak = {i for i, s in enumerate(stretches) if s.edge is not None and others_median[i] is not None
            and s.edge.after < LOADED_SHARE * others_median[i]}
    # A dead zone whose current bends (the motor's viscous term following a sine's speed) may
    # split into a flat piece and a barely tilted one: the jump between them is the flattest
    # start, and it reads as a weak kink or as none, where the tendon's own jump follows on the
    # same stretch. Such a stretch is read again, past its weak kink or trying the next flat
    # pieces, and a take-up found there that loads as the record's other take-ups do (within
    # LOADED_BAND of their median: a wall's kink steepens it far more) replaces it. The twin's
    # ice-b sweeps with noise seeds 11 and 12: a bend at +4 and +13 deg (0.13 and 0.41
    # mA/deg), the take-up at +20.7 deg at 4.5, left d_pos unread and refused the sweep.
    # Design sweeps 0-2999, 3500000-499 and 3600000-499 (bench/zoo.py, current only), per
    # record: 62 more right (50 refusals the bench calls right, 11 wrong ones, 1 silent
    # failure), 4 right ones refused; silent failures 49 -> 48 (came out: 832 and 897, backlashes
    # 1.1 deg off that a refusal had hidden, and 2471, d_neg 2.05 deg off). Detect-shift with
    # those models on replays 0-999: 20 more identified (13 right, 7 refused by the search), 2
    # refused by identify now, no offset more than 0.5 deg off.
    # Likewise the other way: a take-up more than LOADED_BAND times steeper than the record's other
    # (not weak) take-ups, out of a piece that already climbs at a tenth of their slope, is a wall's
    # contact, whose jump starts from the loaded slope: the segmentation merged the dead zone's flat
    # and the tendon's loading into one piece before it. Such a stretch is read again before its
    # kink, and a take-up found there out of a flat piece (half of DEAD_SHARE) that loads as the
    # others do replaces it (zoo sweep 4600064, a wall: both stretches down read the contact at
    # -13.8 deg, 296 mA/deg after it against the others' 30, out of a 5.9 mA/deg piece; d_neg came
    # back 9.35 deg off at +-0.21). Design sweeps 0-2999 and 4300000-4600499, current only, per
    # record: that record right, nothing else changed (4500064 refused by another rule).
    firm_median = median_of_others(weak)
    again = {}
    for i, s in enumerate(stretches):
        ref = others_median[i]
        if ref is None or not s.from_reversal:
            continue
        firm = firm_median[i]
        wall = (s.edge is not None and firm is not None and s.edge.after > LOADED_BAND * firm
                and abs(s.edge.before) >= LOADED_SHARE * firm)
        if s.edge is not None and i not in weak and not wall:
            continue
        # a wall's stretch before its kink; a weak or missing take-up's past it, trying more pieces
        where = (dict(edge_before=s.edge.at) if wall else
                 dict(edge_after=s.edge.at if s.edge is not None else None, fallback=True))
        r = read_stretch(q, c, t, s.start, s.stop, s.direction, from_reversal=True, noise=noise, ring_s=ring_s,
                         **where)
        if r.edge is not None and LOADED_SHARE * ref <= r.edge.after <= LOADED_BAND * ref and not (
                wall and abs(r.edge.before) >= 0.5 * DEAD_SHARE * r.edge.after):
            again[i] = r
    if again:
        stretches = [again.get(i, s) for i, s in enumerate(stretches)]
        weak -= set(again)
        c0, ups, loaded_ref = _references(stretches)
    # each stretch's end slope (what the load did just before the next reversal); a stretch too
    # short or slow to read its own takes the median of the stretches that turned within a
    # degree of the same knob angle, which met the same wall there
    end_slopes: list[float | None] = []
    for s in stretches:
        end = s.end_slope
        if end is None:
            top = float(q[s.stop])
            same = [o.end_slope for o in stretches if o.direction == s.direction
                    and o.end_slope is not None and abs(float(q[o.stop]) - top) <= 1.0]
            end = float(np.median(same)) if same else None
        end_slopes.append(end)
    for side, d in (("pos", +1), ("neg", -1)):
        # stretches that came through the whole dead zone from a reversal first: the record's
        # first stretch starts wherever the knob rested
        # (and not before its own stretch's arrival: a tendon is taken up after the other one has
        # unloaded into the dead zone, so a kink before that is a held load ending; 3000219)
        ks = [s.edge for i, s in enumerate(stretches) if s.direction == d and s.edge is not None and s.from_reversal
              and i not in weak
              and not (s.arrival is not None and d * (s.arrival.at - s.edge.at) > 0)]
        # a tendon is taken up from the no-load level, never from a load the other tendon still
        # holds (the current then starts below it, in loading-positive terms): that kink is the
        # hold ending, the other tendon unloading
        ks = [k for k in ks if not d * (k.level - c0) < -UNLOAD_LEVEL * noise]
        # the record's last stretch is cut by its end: a kink there cannot show that no flat
        # follows it, as a tendon taken up must. Where it alone shows this side's edge and the
        # record's first stretch shows it elsewhere, neither end of the record is known, and the
        # first stretch's edge is read as the estimate it is (below: unclaimed, unused by
        # Algorithm 1). Zoo sweeps 3600467 (a one-cycle sweep ending 7.7 deg into the dead
        # zone: a kink there, 1.8 deg past the other tendon's arrival, read d_pos 22.2 deg off at
        # exit 0, where the first stretch had it within 0.07) and 3500366 (d_neg 7.2 deg off)
        first = [s.edge for i, s in enumerate(stretches) if s.direction == d and s.edge is not None
                 and not s.from_reversal and i not in weak]
        cut = stretches[-1].edge if len(stretches) > 1 else None
        if (ks and cut is not None and all(k is cut for k in ks)
                and first and abs(first[0].at - cut.at) > 1.0):
            ks = []
        if not ks:
            # the first stretch's edge only when no stretch from a reversal went past it and
            # failed to show it: the first starts from a state the current cannot tell (a tendon
            # may be taut with the tip held on its plateau), and where a stretch from a known
            # reversal saw no edge there, the first one's kink is something else
            passed = [s for s in stretches if s.direction == d and s.from_reversal and first
                      and d * (q[s.stop] - first[0].at) > 1.0]
            ks = first if not passed else []
            if ks:
                first_only.append(side)
        at = np.array([k.at for k in ks])
        off = np.abs(at - np.median(at)) > 1.0 if ks else np.zeros(0, bool)
        # stretches that disagree (more than a third of them over a degree off) show no edge one
        # can trust; a lone outlier among agreeing ones is left out
        if ks and off.sum() * 3 <= at.size:
            ks = [k for k, o in zip(ks, off) if not o]
            at = at[~off]
            se = np.array([max(k.se, KINK_SPAN / k.clarity) for k in ks])
            edges[side] = float(np.median(at))
            # the stretches from a reversal that moved through the edge this way: a tendon is taken
            # up on each of them, and an edge that fewer than half of three or more showed is the
            # current's waviness as likely as the edge (design seed 742: one of three, 0.65 deg
            # early; seed 334, whose d_neg one of its crossings read 1.3 deg late, is refused by
            # its d_pos, one of three). One of two is left alone: noise hides one of two often
            # enough (refusing it lost 15 right records of design seeds 0-2399)
            crossed = sum(1 for s in stretches if s.direction == d and s.from_reversal
                          and float(np.min(q[s.start:s.stop + 1])) <= edges[side] - 1.0
                          and float(np.max(q[s.start:s.stop + 1])) >= edges[side] + 1.0)
            if side not in first_only and crossed >= 3 and 2 * len(ks) < crossed:
                doubts[f"d_{side}"] = (f"only {len(ks)} of the {crossed} stretches that moved through it showed "
                                       f"the kink at {edges.pop(side):.2f} deg: the current's waviness as likely "
                                       "as the edge")
            else:
                spread = float(1.2533 * np.std(at, ddof=1) / math.sqrt(at.size)) if at.size > 1 else 0.0
                # never finer than the bins it was read on: the kink fits' own error knows nothing
                # of how the current law rounds the corner (filtering, a stiffening cable, the law)
                edges_se[side] = max(spread, float(np.median(se)) / math.sqrt(at.size), 0.5 * resolution)
                levels[d] = float(np.median([k.level for k in ks]))
                tilt[side] = (float(np.median([abs(k.before) for k in ks])),
                              float(np.median([k.after for k in ks])))
        # a plateau after the top reversal (descending) is B_pos, after the bottom one B_neg
        # complete branches (reversal to reversal) first: a stretch cut by the record's end is
        # read on less travel
        # a steep fall after the reversal is the sheath friction flipping only if the load did
        # not rise as steeply before it: a wall, or a cable stiffening at the top of the stroke,
        # gives the same fall back elastically, with no backlash in it
        def shown(i: int, s: Stretch) -> bool:
            if s.direction != -d or s.plateau is None:
                return False
            if s.plateau_held:
                return True
            end = end_slopes[i - 1] if i > 0 else None
            # the fall is the flip only where it can be weighed: a fall whose slope was not read,
            # or after a stretch whose end slope is unknown, may be either (design sweep 1990, a
            # Coulomb flip on a stretch law read as b_pos 2.2, 5.0 deg off; zoo sweep 4400423, a
            # wall's elastic give at 216 mA/deg after the record's short first stretch, b_neg 7.4).
            # Design sweeps 0-2999 and zoo ranges 4300000-4500499 (looked at after their figures),
            # current only, per record: those two right, nothing else changed
            if s.fall_slope is None or end is None:
                return False
            prev = stretches[i - 1]
            # against the loaded slope the stretches from a reversal read at their edges (the
            # record's first stretch may have taken the wall's own steep rise for its edge)
            ref = loaded_ref if math.isfinite(loaded_ref) else prev.loaded_slope
            elastic = ref is not None and d * end >= ELASTIC_TOP * max(ref, 1e-12)
            # a fall no steeper than the load rose just before the reversal is that load coming
            # back down its own curve, not the sheath friction flipping
            retrace = s.fall_slope <= RETRACE * max(d * end, 1e-12)
            return not (elastic or retrace)

        kept = [s for i, s in enumerate(stretches[:-1]) if shown(i, s)]
        # the complete stretches after a loaded reversal (the one before took the tendon up past
        # its edge): a backlash shows after most of them; a plateau after fewer than half is
        # something else (a cogging dip, a spike's tail; noise may hide one of two)
        # (a stretch went past the edge when it read it, or ran a degree past where the others did)
        e = edges.get(side)

        def loaded(upto: int) -> int:
            return sum(1 for i, s in enumerate(stretches[:upto])
                       if i > 0 and s.direction == -d and (stretches[i - 1].edge is not None or (
                           e is not None and d * (q[stretches[i - 1].stop] - e) > 1.0)))

        loaded_after = loaded(len(stretches) - 1)
        if not kept:
            # the stretch cut by the record's end, counted with the complete ones it must agree
            # with (design sweep 184: it alone read 8.2 deg where two complete ones read none,
            # on a law with no backlash in its current); where a complete one could have shown
            # it, a fall on the cut one is not enough, only a held plateau (3000175, pretensioned:
            # a 28.9-deg "fall" on the cut stretch, none on the complete one before it, read with
            # the twin's half-of-the-reversals rule as one of two)
            complete = loaded_after
            kept = [s for i, s in enumerate(stretches) if shown(i, s)]
            loaded_after = loaded(len(stretches))
            if complete and not any(s.plateau_held for s in kept):
                kept = []
        pl = [s.plateau for s in kept]
        fit_se = [s.plateau_se for s in kept if s.plateau_se is not None]
        arr = np.array(pl)
        # every stretch within 0.5 deg (or 10 %) of their median: a backlash the current shows
        # the same way after every reversal
        tol = max(0.5, 0.10 * abs(float(np.median(arr)))) if arr.size else 0.5
        if arr.size and np.all(np.abs(arr - np.median(arr)) <= tol) and 2 * len(pl) >= loaded_after:
            backlash["pos" if d > 0 else "neg"] = float(np.median(arr))
            backlash_se["pos" if d > 0 else "neg"] = max(
                float(1.2533 * np.std(arr, ddof=1) / math.sqrt(arr.size)) if arr.size > 1 else 0.0,
                0.5 * float(np.ptp(arr)), 0.1 if arr.size > 1 else 0.3, 0.5 * resolution,
                float(np.median(fit_se)) if fit_se else 0.0)
    # both sides cross the same dead zone (no tendon taut): its slope is the same magnitude both
    # ways. A side whose piece before the jump is several times steeper than the other side's,
    # and a fair share of its own loaded slope, read its kink on a curve (a stiffening take-up, an
    # unloading tail running into the loading): where that curve bends most is no edge
    for side, other in (("pos", "neg"), ("neg", "pos")):
        if side in tilt and other in tilt:
            (dz, up), (dz_other, _) = tilt[side], tilt[other]
            if dz >= DEAD_SHARE * up and dz >= DEAD_TILT * dz_other:
                doubts[f"d_{side}"] = (f"before the kink at {edges.pop(side):.2f} deg the current already climbs at "
                                       f"{dz:.3g} per deg ({dz / up:.0%} of the loaded slope), {dz / max(dz_other, 1e-12):.1f} "
                                       "times the other side's dead zone: a curve, not the edge")
                edges_se.pop(side, None)
    arrivals = {}
    for d in (1, -1):
        arr = np.array([s.arrival.at for s in stretches if s.direction == d and s.arrival is not None])
        # two stretches at least, agreeing within a degree, for the arrival to be a reference
        if arr.size >= 2 and np.all(np.abs(arr - np.median(arr)) <= 1.0):
            arrivals[d] = float(np.median(arr))
    loaded = [s.loaded_slope for s in stretches if s.loaded_slope is not None]
    dead = [abs(s.dead_slope) for s in stretches if s.dead_slope is not None]
    return CurrentReading(edges=edges, edges_se=edges_se, backlash=backlash, backlash_se=backlash_se,
                          arrivals=arrivals, no_load=levels, loaded_slope=float(np.median(loaded)) if loaded else math.nan,
                          dead_slope=float(np.median(dead)) if dead else math.nan, noise=noise,
                          stretches=tuple(stretches), first_only=tuple(s for s in first_only if s in edges),
                          doubts=doubts)
