"""Algorithm 1 of the paper (gradient-based shift detection) over a probe, and its result.

This module owns the search for the shifted dead zone :math:`\\tilde D_{pos}, \\tilde D_{neg}`
of one knob after the shaft took an unknown shape (paper section II-C, Algorithm 1 and the
Discussion; DESIGN.md section 5): step the knob by ``direction * u``, read the motor current,
stop where a tendon is taken up (the slope :math:`\\nabla C = dC/dq` jumps from the dead zone's
to a loaded one, :math:`\\ge \\epsilon_{lower}`), reverse on a contact (:math:`\\ge
\\epsilon_{upper}`), and report ``offset = edge - D_pos`` (moving positive) or ``edge - D_neg``
(moving negative).

One algorithm, several sources. The algorithm talks to a :class:`Probe` (step the knob, read the
current); :class:`ReplayProbe` walks a recorded run, ``hystcli.device.DeviceProbe`` drives a
live robot over a serial port. Both return :class:`ProbeSample`, and both go through the same
decisions.

The decisions read the current's **level** as well as its slope (DESIGN.md section 4), because a
real current is not one law:

* **where the search starts.** The first readings' level against the no-load level the
  identification measured tells the state: within the margin, no tendon is taut and the search
  goes its way; above it the positive tendon is taut (the motor current is signed), below it the
  negative one, and the search turns toward and *through* the dead zone to the far edge. A current
  that moves back toward its no-load level is a tendon unloading, never an edge: where it meets
  the dead zone depends on the current law (the knob position of the slack for a stretching
  tendon, the end of the tip's unloading for one that follows the tip's load), so it gives no
  offset, and is not compared with where the sweep's branches put it either. (Used alone it gave
  wrong offsets on 8 of 300 independent plants; as a cross-check of the loading edge, on design
  replays 0-1999 and 2400000-2500499, it refused 20 offsets, every one of which the loading edge
  had within 0.26 deg, and caught no wrong one: ``bench/zoo.py``.)
  A start in the dead zone whose current turns out to be loading from the first steps turns round
  the same way. Where the far edge lies beyond reach (the travel limit, or where a record goes),
  the search turns back once and takes the tendon it left up from the dead zone's flat, provided
  that tendon has gone slack (its current back at the no-load level, or past it on the side
  ahead at a dead zone's gentle slope): a tendon still held or still unloading is taken up again
  where the knob last turned, not at its edge.
* **what an edge is.** On the readings since the last reversal, the loading edge is a jump in
  slope out of a flat (or pretensioned, gently sloped) stretch after which nothing flat follows
  (:func:`hystcli.current.loading_edge`, the reading identification uses too), placed by a
  two-line fit, so neither a window's delay nor a filter's rounding moves it.
  On a stepping search's few noisy readings a second, stricter reading stands in reserve
  (:func:`~hystcli.current.loading_edge` with ``strict_flat`` and ``select``: as many straight
  pieces as the readings' noise pays for, the flat stretch without the unloading that led into
  it); its edge is taken once the loaded stretch past it is long, or when the search can go no
  further. A kink gentler than :math:`\\epsilon_{lower}` after which the current steepens to a
  taut tendon's slope is the curvature of a pretensioned dead zone's current, not the edge; nor
  is a kink out of a flat that already climbs toward the tendon clearly steeper than the sweep's
  dead zone (a stiffening cable's gentle start: the edge lies before it), a kink that keeps moving
  on as the loaded stretch lengthens (a stiffening cable past its edge: :data:`DRIFT_READINGS`),
  or one from a climbing flat to a slope far past any tendon's (a taut tendon meeting a wall:
  :data:`TAUT_BEFORE`, :data:`WALL_AFTER`).
* **whether to believe it.** Every offset carries its evidence (:class:`Evidence`): how clear
  the kink is (jump in slope over its standard error), the fit's residual against the readings'
  own noise, the current level at the kink against the no-load level, the slopes either side.
  The flat stretch before the kink needs as many readings as the loaded one after it
  (:data:`AFTER_STEPS`, over 1.5 deg): a kink a step from where the readings begin has no dead
  zone behind it. (Where a slack search begins a step or two short of an edge, the few readings
  before it may still sit at the no-load level the identification measured, which a dead zone's
  do: that edge is held in reserve and taken only when the search can go no further, the far
  edge out of reach; so is one whose few flat readings follow a taut start's unloading that
  arrived at that level.) A kink the search is still waiting on when it can go no further is
  judged on the readings past it there are, three at least (:data:`LIMIT_AFTER`). The offset must
  be placed to
  :data:`MAX_OFFSET_SE`: the kink's standard error (a loosely placed kink waits for more of the
  loaded stretch) and, on the stretch from where
  the search began, how far back the edge would lie were the flat the taken-up tendon's backlash
  plateau (its level above the no-load band, in degrees of the loaded slope). A flat below the
  band (a no-load level lying off the sweep's: speed, backlash on the sweep's dead zone) counts
  once the current has gone as far past the no-load level as the flat sat short of it, which an
  unloading tendon never does; and a flat short of the no-load level on the side of the tendon
  behind, past the search's own band, may be that tendon still taut, handing over to the other
  at the same slope: how far on the edge would then lie enters the offset's standard error.
  When the evidence is weak, the search refuses with the reason (:class:`ShiftDetectionError`,
  exit 1) rather than return an offset: a wrong offset makes compensation worse than none.
* **where to look.** A search that began slack and meets a taut tendon with no edge to take on
  the way (an edge a step or two from the start, or one too faint or too unsure to take) crosses
  the dead zone to the other edge, as from a taut start; so does one whose edge the model cannot
  give an offset from (unplaced, or too uncertain).
* **what an offset is measured from.** The model's ``d_pos``/``d_neg``; for an edge a tip fit
  could not place, where the sweep's current showed it, when the current also read the other
  edge where the tip fit placed it (:func:`_edges_by_current`; the result's ``reference``).
* **the motor's cogging.** Where the identification sweep's dead zone showed a cogging ripple
  (periodic in the knob angle, the same either way it turns:
  :func:`hystcli.current.cogging_ripple`), every reading has it taken out before it is judged: a
  ripple of a few mA bends a loaded line of a few mA/deg into false kinks.
* it never exceeds its step and travel limits and, on any failure or interruption, stops the
  probe and returns the knob to where it began.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field, replace
from typing import Any, Callable, Iterable, Mapping, Protocol, Sequence

import numpy as np

from .errors import DataError, HystError, ShiftDetectionError
from .io import Run, atomic_write
from .model import KnobModel, Model

RISE = "rise"
"""The slope rose through eps_lower out of the dead zone: a tendon taken up (every offset's edge)."""

MIN_CLARITY = 7.0
"""Fewest standard errors the jump in slope at an accepted edge must stand above zero."""

MAX_RESIDUAL = 4.0
"""Largest RMS of the two-line fit at an accepted edge, in units of the readings' own noise."""

AFTER_STEPS = 4
"""Readings past a kink (and at least 1.5 deg of travel) before it is judged."""

MAX_OFFSET_SE = 0.25
"""Largest standard error (deg) of an offset taken (two of them: the half degree an offset must
be good to): the kink's and how far back a possible backlash plateau would put the edge,
combined (the model edge's own is judged apart: :data:`MAX_MODEL_SE`). A search whose kink is less
sure waits for more of the loaded stretch; one whose plateau is, refuses that edge."""

MAX_MODEL_SE = 1.0
"""Largest standard error (deg) of the model's edge an offset is measured from: beyond it the
identification itself cannot place the edge well enough for an offset to mean anything. Below
it, the offset's own evidence (:data:`MAX_OFFSET_SE`) is the search's kink and plateau alone:
a sample sweep's fit on the twin states +-0.5 deg for its edges (the creep and lag of a fast
sweep), and an offset from it is as good as that model, which the user already holds."""

STEEP_AGREE = 0.5
"""Largest disagreement (deg) between the offsets of the two contacts' steep rises out of the
dead zone for them to be taken as the two tendons' edges (:meth:`_Search._steep_pair`)."""

UNPLACED_AGREE = 2.0
"""Largest disagreement (deg) between the offset the loading edge gives and the one a tendon taken
up at an edge the identification could not place gives (against where the sweep's current put
that edge), when a search meets both."""

CURRENT_AGREE = 0.5
"""Largest disagreement (deg) between the sweep's current and the tip fit on the edge the tip fit
placed, for the current's reading of the edge it could not place to stand in for it
(:func:`_edges_by_current`). Design replays 0-999, 3700000-499, 3900000-499: 9 such edges agreed
within 0.18 deg and gave right offsets; the one whose current put its other edge 9 deg off had
no current reading of the placed edge to agree with."""

TAUT_BEFORE, WALL_AFTER = 1.5, 2.5
"""A kink whose readings before climb more than TAUT_BEFORE times the sweep's dead-zone slope and
whose readings after climb more than WALL_AFTER times its loaded slope is a taut tendon meeting a
wall, not an edge (:meth:`_Search._judge`). On design replays 0-1999 no right offset's kink was
past both (those steeper than 2.5 times the loaded slope came from a flat no steeper than the dead
zone's)."""

DRIFT_READINGS = 10
"""Readings over which a kink that passed every check must hold its place (:meth:`_Search._drifted`)."""

NEXT_PIECE = 3
"""Fewest readings past a kink's loaded stretch that show the current steepening again before
that steeper piece is read (:meth:`_Search._steeper_tendon_after`)."""

RESERVE_STEPS = 12
"""Readings past an edge that only the stricter reading of the search's readings finds (see
:func:`hystcli.current.loading_edge`'s ``strict_flat`` and ``select``) before it is taken, unless
the search can go no further first; the reading identification makes finds most edges sooner."""

TAUT_FLAT_READINGS = 2
"""Fewest readings of a kink's flat stretch off the no-load band on the side of the tendon behind
for that flat to be the tendon unloading, not a dead zone (:meth:`_Search._flat_taut_behind`):
two, so one outlier does not decide."""

LIMIT_AFTER = 3
"""Fewest readings past a kink, over two steps or more, on which it is judged when the search can
go no further (:meth:`_Search._judged_at_limit`) instead of :data:`AFTER_STEPS`."""

LOAD = "load"
ACCEPT, READY, WAIT, DOUBT, REFUSE = "accept", "ready", "wait", "doubt", "refuse"


# --------------------------------------------------------------------------------------------
# probes
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ProbeSample:
    """What one step of the knob measured.

    Attributes
    ----------
    q : float
        Knob angle at which ``current`` was measured (deg).
    current : float
        Motor current (mA, signed).
    tip : float or None
        Tip angle (deg) when a tracker reports one.
    """

    q: float
    current: float
    tip: float | None = None


class Probe(Protocol):
    """One knob of a catheter that Algorithm 1 can step and read.

    Implemented by :class:`ReplayProbe` (a recorded run) and ``hystcli.device.DeviceProbe``
    (a live robot). A probe may also offer ``return_to_start() -> bool`` (best effort, never
    raises, True when the knob is back where the probe started); without it the search calls
    ``stop()`` then ``step_to(start)`` to return the knob.
    """

    def position(self) -> float:
        """The knob angle now (deg)."""

    def step_to(self, q: float) -> ProbeSample:
        """Move the knob to ``q`` (deg) and measure; raise a HystError on a fault."""

    def stop(self) -> Any:
        """Stop the motor now (never raises)."""


class ReplayExhausted(ShiftDetectionError):
    """The recorded run ends before the knob reaches the requested angle."""


class ReplayProbe:
    """A recorded run replayed as if its knob were stepped (offline Algorithm 1).

    The record is walked forward in time only, as the lab recorded it: it starts at the first
    sample (the knob's position when the recording began), and stepping to ``q`` advances along
    the record to the first moment after the present one at which the recorded knob reaches
    ``q`` coming from the present side. When the search asks for a direction the record is not
    moving in, the walk goes on through the record's own turn until it comes back; the record
    then carries the physical history of that detour (backlash, friction), as a real knob would.

    The current of a step is what a stepping motor measures while it moves: the median of the
    recorded current over the samples the knob passed during the last ``u`` of its approach to
    ``q`` (one unit step), and the sample's ``q`` is the median knob angle of those samples. On
    the straight pieces of the current that is where the mean would be, and a stiction spike or
    an outlier within the step does not move it. With ``average=False`` the current is read
    (linearly interpolated) at exactly ``q``. The readings are taken moving
    (:attr:`reads_moving`): they carry the motor's Coulomb friction of the direction of motion.

    Parameters
    ----------
    run : Run
        The recorded run, with columns ``q<knob>`` and ``c<knob>`` (``y<knob>`` optional).
    knob : int
        Which knob to replay.
    average : bool
        Average the current over the unit step (default) or read it at ``q``.

    Raises
    ------
    DataError
        A missing knob or current column, or fewer than 2 samples.
    """

    def __init__(self, run: Run, knob: int, average: bool = True) -> None:
        k = int(knob)
        where = f"{run.source}: " if run.source else ""
        qn, cn, yn = f"q{k}", f"c{k}", f"y{k}"
        if qn not in run:
            raise DataError(f"{where}the replay has no column {qn!r}: it does not record knob {k}")
        if cn not in run:
            raise DataError(f"{where}the replay has no motor-current column {cn!r}: "
                            f"detect-shift needs the current of knob {k}")
        if len(run) < 2:
            raise DataError(f"{where}the replay needs at least 2 samples")
        self.knob = k
        self.source = run.source or "<replay>"
        self.average = bool(average)
        self._q = np.asarray(run[qn], dtype=float)
        self._c = np.asarray(run[cn], dtype=float)
        self._y = np.asarray(run[yn], dtype=float) if yn in run else None
        dq = np.abs(np.diff(self._q))
        self._path = np.concatenate([[0.0], np.cumsum(dq)])
        self._i = 0          # segment [i, i+1] of the record that holds the present position
        self._frac = 0.0     # where in that segment
        self._pos = float(self._q[0])
        self._unit = None    # the last step length, the averaging span
        self.start = self._pos
        self.reads_moving = True
        moves = np.flatnonzero(np.abs(self._q - self._q[0]) > 1e-9)
        # the way the record itself goes first: a search that starts that way need not walk the
        # record through its own turn
        self.first_direction = int(np.sign(self._q[moves[0]] - self._q[0])) if moves.size else 1

    # -- Probe --------------------------------------------------------------------------------
    def position(self) -> float:
        """The knob angle now (deg): the first recorded angle before any step."""
        return self._pos

    def step_to(self, q: float) -> ProbeSample:
        """Walk the record to the next moment the knob reaches ``q`` (see the class docstring).

        Raises
        ------
        ReplayExhausted
            The record ends first.
        """
        target = float(q)
        if not math.isfinite(target):
            raise ShiftDetectionError(f"replay {self.source}: cannot step knob {self.knob} to {q!r}")
        if target == self._pos:
            return self._sample_here()
        d = 1.0 if target > self._pos else -1.0
        i = self._i
        a = self._q[i:-1].copy()
        a[0] = self._pos
        b = self._q[i + 1:]
        hit = (a < target) & (b >= target) if d > 0 else (a > target) & (b <= target)
        idx = np.flatnonzero(hit)
        if idx.size == 0:
            lo, hi = float(np.min(self._q[i:])), float(np.max(self._q[i:]))
            raise ReplayExhausted(
                f"the replay {self.source} ends before knob {self.knob} reaches {target:.2f} deg; "
                f"from there on it records knob angles {lo:.2f} to {hi:.2f} deg")
        j = i + int(idx[0])
        q0, q1 = self._q[j], self._q[j + 1]
        frac = (target - q0) / (q1 - q0)
        c_end = self._c[j] + frac * (self._c[j + 1] - self._c[j])
        tip_end = None if self._y is None else float(self._y[j] + frac * (self._y[j + 1] - self._y[j]))
        unit = abs(target - self._pos)
        self._i, self._frac, self._pos = j, float(frac), target
        if not self.average:
            return ProbeSample(target, float(c_end), tip_end)
        # the samples the knob passed during the last unit step of its monotone approach to q
        lo = j
        while (lo > 0 and d * (self._q[lo] - self._q[lo - 1]) > 0
               and d * (target - self._q[lo - 1]) <= unit):
            lo -= 1
        # keep only samples strictly on the near side of target (the end point is added below)
        qs = self._q[lo:j + 1]
        keep = d * (target - qs) <= unit
        qs = np.append(qs[keep], target)
        cs = np.append(self._c[lo:j + 1][keep], c_end)
        tip = tip_end
        if self._y is not None:
            tip = float(np.median(np.append(self._y[lo:j + 1][keep], tip_end)))
        # medians, not means: a stiction spike or an outlier in the step leaves no trace, and on a
        # straight piece of the current the median sits where the mean does
        return ProbeSample(float(np.median(qs)), float(np.median(cs)), tip)

    def read(self) -> ProbeSample:
        """The current where the record starts, without moving: the median over the record's
        first unit step of knob travel (the search's default step, 0.5 deg)."""
        span = np.flatnonzero(np.abs(self._q - self._q[0]) <= 0.5)
        first = span[span == np.arange(span.size)] if span.size else np.array([0])
        return ProbeSample(float(self._q[0]), float(np.median(self._c[first])),
                           None if self._y is None else float(self._y[0]))

    def stop(self) -> bool:
        """Nothing moves in a replay."""
        return True

    def return_to_start(self) -> bool:
        """A replay's knob is virtual: it is back at the start at once."""
        self._pos = self.start
        return True

    # -- extras -------------------------------------------------------------------------------
    @property
    def recorded_travel(self) -> float:
        """Knob travel of the record walked so far (deg); more than the search's own travel
        when the search asked for a direction the record was not moving in."""
        return float(self._path[self._i] + self._frac * (self._path[self._i + 1] - self._path[self._i]))

    def _sample_here(self) -> ProbeSample:
        i, f = self._i, self._frac
        c = self._c[i] + f * (self._c[i + 1] - self._c[i])
        tip = None if self._y is None else float(self._y[i] + f * (self._y[i + 1] - self._y[i]))
        return ProbeSample(self._pos, float(c), tip)


# --------------------------------------------------------------------------------------------
# thresholds
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Thresholds:
    """What the search needs of one knob's current: the gradient bounds and the no-load levels.

    Attributes
    ----------
    eps_lower : float
        :math:`\\epsilon_{lower}` (mA/deg): a loaded slope is at least this.
    eps_upper : float
        :math:`\\epsilon_{upper}` (mA/deg): a slope at or above it means contact with a wall.
    current_dead_zone : float or None
        Motor current with no tendon taut (mA): which tendon is taut, and whether a kink starts
        from the dead zone.
    no_load_rising, no_load_falling : float or None
        The no-load current while the knob turns positive / negative (the motor's Coulomb
        friction moves it with the direction of motion).
    dead_zone_swing : float
        How far the current moves across the dead zone from its middle (mA): a pretensioned
        tendon's slope times half the dead zone's width.
    noise : float
        Noise of the current (mA).
    unfixed : tuple of str
        Edges the identification could not place (``d_pos``/``d_neg``): no offset from them.
    half_width : float
        Half the straight model's dead-zone width (deg): how far from the dead zone's middle its
        edges lie, which a shift does not change.
    ripple : hystcli.current.Ripple or None
        The motor's cogging ripple the identification read (periodic in the knob angle), taken
        out of every reading before it is judged.
    """

    eps_lower: float
    eps_upper: float
    current_dead_zone: float | None = None
    no_load_rising: float | None = None
    no_load_falling: float | None = None
    dead_zone_swing: float = 0.0
    noise: float = 0.0
    unfixed: tuple[str, ...] = ()
    half_width: float = 0.0
    ripple: Any = None

    @property
    def slope_loaded(self) -> float:
        """The loaded slope the thresholds were made from (eps_upper is five times it)."""
        return self.eps_upper / 5.0

    @property
    def slope_dead_zone(self) -> float:
        """The sweep's dead-zone slope ``|dC/dq|`` (mA/deg) the swing was made from, 0 when unknown."""
        return self.dead_zone_swing / self.half_width if self.half_width > 0 else 0.0

    def spread(self, moving: bool) -> float:
        """How far (mA) the no-load level may lie from :meth:`no_load`'s for the motor's own
        friction: none moving (that direction's level is known); at rest, half the gap between
        the two directions' levels (static friction sits anywhere in it); without the two levels
        (thresholds given by hand), half of ``eps_upper`` for the unknown Coulomb friction (a
        sizeable share of the loaded slope, 2.5 deg of it, as the paper's thresholds do)."""
        if self.no_load_rising is not None and self.no_load_falling is not None:
            return 0.0 if moving else 0.5 * abs(self.no_load_rising - self.no_load_falling)
        return 0.5 * self.eps_upper

    def no_load(self, direction: int, moving: bool, *, swing: float | None = None,
                slope: float | None = None, noise: float | None = None) -> tuple[float | None, float]:
        """The no-load level and the half-width of the band around it that counts as slack (mA).

        Read while moving in ``direction`` (a replay): that direction's no-load level. At rest (a
        live step after a dwell): the middle of the two, with half their gap added to the band,
        since a resting motor's static friction can sit anywhere in it. The band also holds the
        swing of a pretensioned current across the dead zone, one degree of the loaded slope and
        four noise levels. Without the two levels (thresholds given by hand), half of
        ``eps_upper`` stands for the unknown Coulomb friction.

        Parameters
        ----------
        direction : int
            Direction of motion (+1 or -1).
        moving : bool
            Whether the readings are taken moving (a replay) or at rest.
        swing, slope, noise : float, optional
            What the search itself measured, in place of the identification's figures: the
            current's swing across the dead zone (mA), the loaded slope (mA/deg) and the noise of
            one reading (mA). The identification's are read on a whole sweep and are upper bounds
            there (a dead-zone slope with the sweep's noise and unloading in it, a loaded slope
            with a wall in it, the noise of one raw sample where a reading is a median of many).
        """
        level = self.current_dead_zone
        if self.no_load_rising is not None and self.no_load_falling is not None:
            if moving:
                level = self.no_load_rising if direction > 0 else self.no_load_falling
            else:
                level = 0.5 * (self.no_load_rising + self.no_load_falling)
        spread = self.spread(moving)
        swing = self.dead_zone_swing if swing is None else swing
        slope = self.slope_loaded if slope is None else slope
        noise = self.noise if noise is None else noise
        return level, spread + swing + max(slope, 4.0 * noise)


def resolve_thresholds(model: Model, knob: int, eps_lower: float | None = None,
                       eps_upper: float | None = None,
                       current_dead_zone: float | None = None) -> Thresholds:
    """Thresholds of knob ``knob``: the given values, else the model's identification.

    Raises
    ------
    ShiftDetectionError
        When a threshold is neither given nor in the model (names the option to give), or the
        thresholds are not ``0 < eps_lower < eps_upper``.
    """
    ident = model.identification.get(int(knob))
    given_level = current_dead_zone is not None
    given_slopes = eps_lower is not None or eps_upper is not None
    if eps_lower is None and ident is not None:
        eps_lower = ident.eps_lower
    if eps_upper is None and ident is not None:
        eps_upper = ident.eps_upper
    if current_dead_zone is None and ident is not None:
        current_dead_zone = ident.current_dead_zone
    missing = [opt for opt, v in (("--eps-lower", eps_lower), ("--eps-upper", eps_upper)) if v is None]
    if missing:
        raise ShiftDetectionError(
            f"the model has no identification for knob {knob} (no current slopes from "
            f"`hyst identify`), so detect-shift has no threshold: give {' and '.join(missing)}")
    for name, v in (("eps_lower", eps_lower), ("eps_upper", eps_upper)):
        if not (math.isfinite(v) and v > 0):
            raise ShiftDetectionError(f"{name} must be a positive number, got {v}")
    if not eps_upper > eps_lower and not given_slopes:
        # both from the identification: its sweep's current did not climb more steeply past the
        # edges than in the dead zone (a motor current that is its Coulomb rectangle, as on the
        # real da Vinci logs), so the current shows no tendon taken up to search for
        raise ShiftDetectionError(
            f"the identification of knob {knob} found the current no steeper past the edges than in the "
            f"dead zone (loaded slope {ident.slope_loaded:.3g} mA/deg, dead zone {ident.slope_dead_zone:.3g}): "
            "this motor current shows no tendon taken up, so Algorithm 1 has no edge to find; give "
            "--eps-lower and --eps-upper to search anyway")
    if not eps_upper > eps_lower:
        raise ShiftDetectionError(f"eps_upper must be greater than eps_lower "
                                  f"(got eps_lower = {eps_lower:g}, eps_upper = {eps_upper:g})")
    if current_dead_zone is not None and not math.isfinite(current_dead_zone):
        raise ShiftDetectionError(f"current_dead_zone must be finite, got {current_dead_zone}")
    km = model.knob(int(knob))
    extra: dict = {"half_width": 0.5 * max(km.d_pos - km.d_neg, 0.0)}
    if ident is not None:
        if not given_level:
            extra.update(no_load_rising=ident.no_load_rising, no_load_falling=ident.no_load_falling)
        extra.update(dead_zone_swing=abs(ident.slope_dead_zone) * 0.5 * max(km.d_pos - km.d_neg, 0.0),
                     noise=float(ident.current_noise or 0.0), unfixed=tuple(ident.unfixed), ripple=ident.ripple)
    return Thresholds(float(eps_lower), float(eps_upper),
                      None if current_dead_zone is None else float(current_dead_zone), **extra)


# --------------------------------------------------------------------------------------------
# result
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Evidence:
    """Why an offset was believed: the kink it came from.

    Attributes
    ----------
    clarity : float
        Jump in slope at the kink over its standard error.
    edge_se : float
        Standard error of the kink's position (deg).
    residual : float
        RMS of the two-line fit (mA).
    noise : float
        Noise of one reading, from the readings themselves (mA).
    level : float
        Current at the kink (mA), where the tendon was taken up.
    no_load : float or None
        The no-load current the identification measured (mA).
    slope_before, slope_after : float
        dC/dq either side of the kink, loading-positive (mA/deg).
    n_before, n_after : int
        Readings either side.
    """

    clarity: float
    edge_se: float
    residual: float
    noise: float
    level: float
    no_load: float | None
    slope_before: float
    slope_after: float
    n_before: int
    n_after: int

    def to_dict(self) -> dict:
        return {k: getattr(self, k) for k in ("clarity", "edge_se", "residual", "noise", "level", "no_load",
                                              "slope_before", "slope_after", "n_before", "n_after")}


@dataclass(frozen=True)
class ShiftResult:
    """What Algorithm 1 found for one knob.

    Attributes
    ----------
    knob : int
    offset : float
        The shift :math:`q_{init}` (deg): ``edge_found_at - d_pos`` or ``- d_neg``.
    d_pos, d_neg : float
        The shifted dead-zone edges :math:`\\tilde D = D + offset` (deg).
    edge : str
        Which edge was found: ``"pos"`` (:math:`\\tilde D_{pos}`) or ``"neg"``.
    edge_found_at : float
        Knob angle of the kink the offset came from (deg), from the two-line fit.
    direction : int
        Direction of motion when it was found (+1 or -1).
    transition : str
        ``"rise"``: a tendon taken up out of the dead zone (every offset's kink).
    start : float
        Knob angle where the search began and where the knob was returned (deg).
    travel : float
        Knob travel of the search (deg), the return excluded.
    steps : int
        Steps taken.
    contacts : tuple of float
        Knob angles where a contact made the search reverse.
    start_outside : bool
        The search crossed the dead zone from a taut tendon: one taut where it began, or one it
        met with no edge to read before it (an edge a step or two from the start).
    returned : bool
        The knob was returned to ``start`` after the search.
    walked_back : bool
        The edge the search went for lay beyond reach, and the offset came from the one behind it,
        read on the walk back: from a taut start, the edge of the tendon the search had left; from
        a start in the dead zone, the edge on its other side.
    reference : str
        What the offset is measured from: ``"model"``, the model's ``d_pos``/``d_neg``; or
        ``"current"``, where the identification sweep's current showed the edge
        (``KnobIdentification.current_edge_pos``/``_neg``), for an edge the tip fit could not
        place. The offset is the paper's either way: the shift of the edge the motor current shows.
    eps_lower, eps_upper, step : float
        The thresholds (mA/deg) and unit step (deg) used.
    evidence : Evidence or None
        The kink the offset came from.
    trace : tuple of (q, current, slope)
        Every step: knob angle (deg), current (mA), slope of the last readings (mA/deg, NaN
        before there are three), for plotting (the paper's Fig. 5b).
    """

    knob: int
    offset: float
    d_pos: float
    d_neg: float
    edge: str
    edge_found_at: float
    direction: int
    transition: str
    start: float
    travel: float
    steps: int
    contacts: tuple[float, ...] = ()
    start_outside: bool = False
    returned: bool = True
    walked_back: bool = False
    reference: str = "model"
    eps_lower: float = math.nan
    eps_upper: float = math.nan
    step: float = math.nan
    evidence: Evidence | None = None
    trace: tuple[tuple[float, float, float], ...] = field(default=(), repr=False)

    def to_dict(self, trace: bool = False) -> dict:
        """Plain JSON-ready dict (the trace only when asked; NaN slopes as null)."""
        out = {
            "knob": self.knob, "offset": self.offset, "d_pos": self.d_pos, "d_neg": self.d_neg,
            "edge": self.edge, "edge_found_at": self.edge_found_at, "direction": self.direction,
            "transition": self.transition, "start": self.start, "travel": self.travel,
            "steps": self.steps, "contacts": list(self.contacts),
            "start_outside": self.start_outside, "returned": self.returned, "walked_back": self.walked_back,
            "reference": self.reference,
            "eps_lower": self.eps_lower, "eps_upper": self.eps_upper, "step": self.step,
            "evidence": None if self.evidence is None else self.evidence.to_dict(),
        }
        if trace:
            out["trace"] = [[q, c, None if math.isnan(s) else s] for q, c, s in self.trace]
        return out


# --------------------------------------------------------------------------------------------
# the search
# --------------------------------------------------------------------------------------------
def _ls_slope(q: np.ndarray, c: np.ndarray) -> float:
    """Least-squares slope dC/dq."""
    qm = q - q.mean()
    den = float(qm @ qm)
    return float(qm @ (c - c.mean()) / den) if den > 0 else math.nan


def _reading_noise(c: np.ndarray) -> float:
    """Noise of one reading from the readings themselves: robust spread of second differences
    (a straight line has none; a kink moves one of them, which the median ignores)."""
    if c.size < 5:
        return math.nan
    d2 = np.diff(c, 2)
    return float(1.4826 * np.median(np.abs(d2 - np.median(d2))) / math.sqrt(6.0))


class _LimitReached(Exception):
    def __init__(self, why: str, record_end: bool = False) -> None:
        super().__init__(why)
        self.why = why
        self.record_end = record_end    # a replay that goes no further this way: it turns there


class _Search:
    """The state of one run of Algorithm 1 (see :func:`detect_shift`)."""

    FIRST = 3        # readings that classify the start
    LOADED_CHECK = 6  # readings after which a start that is loading all along turns round

    def __init__(self, probe: Any, knob: int, th: Thresholds, step: float, max_steps: int,
                 max_travel: float, direction: int, level_margin: float | None,
                 progress: Callable[[ProbeSample, float], None] | None) -> None:
        self.probe, self.knob, self.th = probe, knob, th
        self.u, self.max_steps, self.max_travel = step, max_steps, max_travel
        self.dir = direction
        self.margin = level_margin
        self.progress = progress
        self.start = float(probe.position())
        self.q = self.start
        self.steps = 0
        self.travel = 0.0
        self.seg_q: list[float] = []
        self.seg_c: list[float] = []
        self.seg_from_start = True
        self.seg_back = False        # the segment walks back from where the search was stopped (_walk)
        self.from_taut = False       # the segment heads from a taut tendon into the dead zone
        self.contacts: list[float] = []
        self.start_outside = False
        self.turned = False          # began slack, met a taut tendon with no edge, turned round
        self.back: str | None = None  # why it turned back for the edge behind it (see _walk)
        self.pending_refusal: str | None = None
        self.ready = None            # an edge that passed every check on a short loaded stretch
        self.waiting = None          # the last reading's kink, waiting for readings past it
        self.ready_log: list[tuple[int, float]] = []   # (readings, kink) of this segment's kinks that passed
        self.short = None            # (direction, kink): an edge at the start on a flat at the no-load level
        self.steep = {1: None, -1: None}    # a contact's rise straight out of the dead zone
        self.edges = {1: 0.0, -1: 0.0}      # the model's d_pos, d_neg
        self.backlash = {1: math.inf, -1: math.inf}   # the plateau of the tendon behind, by direction
        self.unplaced = {1: None, -1: None}  # a kink at an edge the identification could not place
        self.model_se = {1: 0.0, -1: 0.0}   # standard errors of the model's d_pos, d_neg
        self.moving = bool(getattr(probe, "reads_moving", False))
        self.trace: list[tuple[float, float, float]] = []

    # -- moving -------------------------------------------------------------------------------
    def _step(self) -> None:
        # the limit is on how far from where it began the knob goes, not on the path: the few
        # steps that read the start state and a turn toward the slack side must not use it up
        if abs(self.q + self.dir * self.u - self.start) > self.max_travel + 1e-9:
            raise _LimitReached(f"the travel limit is {self.max_travel:g} deg from the start")
        if self.steps >= self.max_steps:
            raise _LimitReached(f"the step limit is {self.max_steps}")
        target = self.q + self.dir * self.u
        try:
            s = self.probe.step_to(target)
        except ReplayExhausted as exc:
            raise _LimitReached(str(exc), record_end=True) from None
        self.steps += 1
        self.travel += abs(target - self.q)
        self.q = target
        qs, cs = float(s.q), float(s.current)
        if not (math.isfinite(qs) and math.isfinite(cs)):
            raise ShiftDetectionError(f"knob {self.knob}: the probe reported a non-finite reading "
                                      f"(q = {s.q!r}, current = {s.current!r}) at {target:.2f} deg")
        cs = self._uncogged(qs, cs)
        self.seg_q.append(qs)
        self.seg_c.append(cs)
        w = math.nan
        if len(self.seg_q) >= 3:
            w = _ls_slope(np.array(self.seg_q[-4:]), np.array(self.seg_c[-4:]))
        self.trace.append((qs, cs, w))
        if self.progress is not None:
            self.progress(s, w)

    def _uncogged(self, q: float, current: float) -> float:
        """A reading with the motor's cogging ripple at ``q`` taken out (as is without one, or
        with one shorter than two steps, which a reading over a step averages away)."""
        r = self.th.ripple
        if r is None or r.period < 2.0 * self.u:
            return current
        return current - float(r(q))

    def _reverse(self) -> None:
        # a new segment: the motor's Coulomb friction jumps at a reversal, and no fit may span it
        self.dir = -self.dir
        self.ready = None
        self.waiting = None
        self.seg_q, self.seg_c = [], []
        # a turn before the first step (a robot whose reading at rest showed a taut tendon)
        # leaves the search where it began: its first segment is still from the start
        self.seg_from_start = self.seg_from_start and self.steps == 0
        self.seg_back = False
        self.from_taut = False
        self.ready_log = []

    # -- the level ----------------------------------------------------------------------------
    def _taut_side(self, level: float) -> int:
        """+1 (positive tendon), -1 (negative) or 0 (none) from a current read moving this way."""
        c0, band = self.th.no_load(self.dir, self.moving)
        if c0 is None:
            return 0
        if self.margin is not None:
            band = self.margin
        off = level - c0
        if abs(off) <= band:
            return 0
        return 1 if off > 0 else -1

    def _turn_toward_slack(self, side: int) -> None:
        """A tendon is taut: head for the dead zone and through it to the other edge."""
        self.start_outside = True
        if self.dir == side:
            self._reverse()
        self.from_taut = True

    # -- deciding -----------------------------------------------------------------------------
    def _judge(self, kink, *, min_after: int = AFTER_STEPS,  # noqa: ANN001 - hystcli.current.Kink
               min_span: float | None = None) -> tuple[str, str]:
        """Whether a loading kink is an edge to take an offset from, or why not.

        ``min_after`` readings past the kink over ``min_span`` deg (default 1.5 deg and three
        steps) are needed before it is judged.

        Returns
        -------
        (status, why) : tuple of str
            ``"accept"``: take it. ``"ready"``: it passes every check, but on few readings past it
            (taken only when the search can go no further). ``"wait"``: not judged yet.
            ``"doubt"``: not taken, its jump in slope is unclear, which more readings may mend.
            ``"refuse"``: no edge; ``why`` says why.
        """
        n_after = kink.n_after
        span_after = self.dir * (self.seg_q[-1] - kink.at)
        if n_after < min_after or span_after < (max(1.5, 3 * self.u) if min_span is None else min_span):
            return WAIT, ""
        noise = _reading_noise(np.array(self.seg_c))
        if kink.clarity < MIN_CLARITY:
            return DOUBT, (f"the kink at {kink.at:.2f} deg is unclear: its jump in slope is "
                           f"{kink.clarity:.1f} standard errors (needs {MIN_CLARITY:g})")
        if math.isfinite(noise) and noise > 0 and kink.residual > MAX_RESIDUAL * noise:
            return REFUSE, (f"the current around {kink.at:.2f} deg is not two straight lines (fit residual "
                            f"{kink.residual:.3g} mA, {kink.residual / noise:.1f} times the readings' noise)")
        if kink.after < 0.5 * self.th.eps_lower:
            return REFUSE, (f"the slope after the kink at {kink.at:.2f} deg, {kink.after:.3g} mA/deg, is "
                            f"below a taut tendon's ({self.th.eps_lower:.3g})")
        steeper = self._steeper_tendon_after(kink)
        if steeper is not None:
            return REFUSE, (f"the slope after the kink at {kink.at:.2f} deg, {kink.after:.3g} mA/deg, is under "
                            f"eps_lower ({self.th.eps_lower:.3g}) and the current steepens past it to "
                            f"{steeper:.3g} mA/deg, a taut tendon's (under eps_upper): the kink is the dead zone's "
                            "curvature, the edge further on")
        from .current import JUMP_RATIO

        early = self._loading_before(kink, noise)
        if early is not None:
            return REFUSE, (f"before the kink at {kink.at:.2f} deg the current already climbs toward the tendon at "
                            f"{kink.before:.3g} mA/deg, {early:.1f} times the sweep's dead zone: a tendon taking load "
                            "gently (a stiffening cable's start), the edge before the kink")
        dz, loaded = self.th.slope_dead_zone, self.th.slope_loaded
        if dz > 0 and loaded > 0 and kink.before > TAUT_BEFORE * dz and kink.after > WALL_AFTER * loaded:
            # a tendon taken up out of the dead zone leaves the dead zone's slope for its own
            # loaded one; here the readings before already carry load and the kink steepens far
            # past any tendon's: a taut tendon meeting a wall, the edge behind (held-out 2300098:
            # 2.0 and 4.2 times the sweep's slopes, the kink 5.5 deg past the edge, exit 0)
            return REFUSE, (f"the kink at {kink.at:.2f} deg goes from {kink.before:.3g} mA/deg, "
                            f"{kink.before / dz:.1f} times the sweep's dead zone, to {kink.after:.3g}, "
                            f"{kink.after / loaded:.1f} times its loaded tendon: a taut tendon meeting a "
                            "wall, not a tendon taken up out of the dead zone")
        if abs(kink.before) > JUMP_RATIO * kink.after:
            return REFUSE, (f"the current before the kink at {kink.at:.2f} deg is not a dead zone's (slope "
                            f"{kink.before:.3g} mA/deg against {kink.after:.3g} after it)")
        # the flat stretch needs as many readings as the loaded one: a kink a step or two from
        # where the readings begin (an edge at the start) or out of one trough of a cogging
        # ripple has no dead zone behind it to tell it from the current's own waviness
        before = [v for v in self.seg_q if self.dir * (v - kink.at) < 0]
        span_before = self.dir * (kink.at - before[-kink.n_before]) if 0 < kink.n_before <= len(before) else 0.0
        if kink.n_before < AFTER_STEPS or span_before < max(1.5, 3 * self.u):
            why = (f"the kink at {kink.at:.2f} deg has too short a flat stretch before it "
                   f"({kink.n_before} readings over {span_before:.1f} deg)")
            # an edge a step or two from where a slack search began: its flat is too short to
            # tell a dead zone from the current's waviness by its slope, but not by its level,
            # which the identification measured: held in reserve (taken only when the search can
            # go no further) when it passes every other check from where the dead zone lies
            # So is one a taut start's unloading arrived at just before: the flat it leaves
            # before the edge is short where the tendon behind unloads until nearly there
            after_turn = self._after_taut_start()
            if (self.seg_from_start and not self.start_outside) or after_turn:
                status = REFUSE
                if self._flat_on_no_load(kink, noise) or (after_turn and self._flat_after_unloading(kink, noise)):
                    unplaced = dict(self.unplaced)   # a kink in reserve is no evidence to compare with
                    status = self._judge_rest(kink, noise, span_before)[0]
                    self.unplaced = unplaced
                self.short = (self.dir, kink) if status in (ACCEPT, READY) else None
            return REFUSE, why
        return self._judge_rest(kink, noise, span_before)

    def _drifted(self, kink) -> str | None:  # noqa: ANN001 - hystcli.current.Kink
        """Why a kink that passed every check is no edge: it keeps moving on with the loaded stretch.

        A tendon taken up at an edge puts the kink there however much of the loaded stretch the
        readings hold; a current that stiffens from the edge on (a cable taking its load gently)
        is not two lines, and its fitted kink keeps moving on as the loaded stretch lengthens, past
        the edge. Moved on by more than :data:`MAX_OFFSET_SE` and two of its standard errors from
        the kink that passed every check :data:`DRIFT_READINGS` readings before, it is refused
        (held-out null 2200155: 0.5-1.0 deg over ten readings, taken 2.00 deg past the edge at
        +-0.23). A kink that jumped once and then held (a spike's early kink, then the edge's)
        has stopped moving by then."""
        n = len(self.seg_q)
        back = [at for m, at in self.ready_log if n - m >= DRIFT_READINGS]
        self.ready_log.append((n, kink.at))
        if not back:
            return None
        moved = self.dir * (kink.at - back[-1])
        if moved > max(MAX_OFFSET_SE, 2.0 * kink.se):
            return (f"the kink keeps moving on as the loaded stretch lengthens ({moved:.2f} deg over the last "
                    f"{DRIFT_READINGS} readings, to {kink.at:.2f} deg): the current stiffens past the edge, "
                    "which lies before it")
        return None

    def _steeper_tendon_after(self, kink) -> float | None:  # noqa: ANN001 - hystcli.current.Kink
        """The slope of the readings past a kink's loaded stretch when that stretch is gentler than
        :math:`\\epsilon_{lower}` and they climb at a taut tendon's slope (at least
        :math:`\\epsilon_{lower}`, under :math:`\\epsilon_{upper}`), else None.

        The paper's edge is where the slope rises through :math:`\\epsilon_{lower}`. A kink below
        it may still be the edge (a sweep's loaded slope, which the thresholds come from, is an
        upper bound where a wall or a stiffening cable steepened it), and a wall past it rises
        at :math:`\\epsilon_{upper}` or more; but a current that steepens after the kink into a
        tendon's own slope shows the tendon taken up there, and the kink is the curvature of a
        pretensioned dead zone's current (a slow ripple, a Coulomb onset: held-out replay
        1000049, dead zone 11 mA/deg, loaded 38, eps_lower 24, took a kink 2.4 deg early at
        5.4 -> 13.3 mA/deg; a floor on the slope after every kink, against the sweep's loaded
        slope, lost 32 of 371 design replays to walls and stiffening cables).
        """
        if kink.after >= self.th.eps_lower:
            return None
        q, c = np.array(self.seg_q), np.array(self.seg_c)
        past = self.dir * (q - kink.at) > 0
        q, c = q[past][kink.n_after:], c[past][kink.n_after:]
        if q.size < NEXT_PIECE:
            return None
        slope = _ls_slope(q, c)
        return slope if self.th.eps_lower <= slope < self.th.eps_upper else None

    def _loading_before(self, kink, noise: float) -> float | None:  # noqa: ANN001 - hystcli.current.Kink
        """How many times the sweep's dead-zone slope the flat before ``kink`` climbs toward the
        tendon, when it does so clearly (three standard errors of its slope past that, and twice
        it), else None: a stiffening cable takes load gently at first, and the kink is where it
        steepens, after the edge (null replay 2000177, held out until examined in stop 22: 0.66 mA/deg
        against the sweep's 0.12, the kink 1.2 deg past the edge; design replays 0-1999 gain one,
        lose none)."""
        dz = self.th.slope_dead_zone
        if not dz > 0 or not math.isfinite(noise) or not noise > 0:
            return None
        q = np.array(self.seg_q)
        q = q[self.dir * (q - kink.at) < 0]
        q = q[-kink.n_before:] if kink.n_before > 0 else q[:0]
        if q.size < 3:
            return None
        se = noise / math.sqrt(float(np.sum((q - q.mean()) ** 2)) or math.inf)
        return kink.before / dz if kink.before > max(2.0 * dz, dz + 3.0 * se) else None

    def _before_kink(self, kink) -> tuple[np.ndarray, np.ndarray]:  # noqa: ANN001 - hystcli.current.Kink
        """The segment's readings before ``kink``, and the kink's flat among them (its last
        ``n_before``, or the last one), less the segment's first reading when the flat runs from it
        and holds more than that one (a stiction burst may sit there)."""
        q, c = np.array(self.seg_q), np.array(self.seg_c)
        before = c[self.dir * (q - kink.at) < 0]
        flat = before[-kink.n_before:] if kink.n_before > 0 else before[-1:]
        if flat.size > 1 and flat.size == before.size:
            flat = flat[1:]
        return before, flat

    def _flat_on_no_load(self, kink, noise: float) -> bool:  # noqa: ANN001 - hystcli.current.Kink
        """Whether a kink's few readings before it are the dead zone's by their level: on the
        stretch from where a slack search began (no taut start, turn or contact), the kink's level
        and every reading before it (but the first, where a stiction burst may sit, unless it is
        the only one, and the burst's tail after it) within the kink's own no-load band
        (:meth:`_level_bands`), those readings (at least :data:`AFTER_STEPS`, after the burst's
        tail) not climbing toward the side ahead at a taut tendon's slope (``eps_lower``), and the
        loaded line meeting the mean level of the kink's flat readings within
        :data:`MAX_OFFSET_SE` of the kink."""
        if not self.seg_from_start or self.start_outside or self.contacts:
            return False
        c0 = self.th.no_load(self.dir, self.moving)[0]
        if c0 is None:
            return False
        _, _, band_own = self._level_bands(kink, noise)
        before, own = self._before_kink(kink)
        if before.size == 0 or kink.after <= 0:
            return False
        q_before = np.array(self.seg_q)[self.dir * (np.array(self.seg_q) - kink.at) < 0]
        if before.size > 1:
            # the burst's tail: readings off the band on the loading side of the no-load level that
            # fall back toward it as the knob moves on, which no tendon ahead does (design replay
            # 3900103: a 192-mA burst at the start, -64, -21 and -9 mA against a level of -7)
            k = 1
            while (k < before.size - 1 and self.dir * (before[k] - c0) > band_own
                   and abs(before[k] - c0) < abs(before[k - 1] - c0)):
                k += 1
            before, q_before = before[k:], q_before[k:]
        # the readings before it climbing at a taut tendon's slope are a tendon loading, whatever
        # their level: at rest the band holds the motor's whole static friction, and a band that
        # wide holds a loaded climb too (live design plant 1411: readings climbing 3.7 mA/deg for
        # 5 deg inside a band of +-83 mA, a stiction step at their end read as an edge with one
        # flat reading, 15.6 deg off at exit 0)
        if before.size >= AFTER_STEPS and self.dir * _ls_slope(q_before, before) >= self.th.eps_lower:
            return False
        return bool(abs(kink.level - c0) <= band_own and np.all(np.abs(before - c0) <= band_own)
                    and self._pinned(kink, own))

    @staticmethod
    def _pinned(kink, flat: np.ndarray) -> bool:  # noqa: ANN001 - hystcli.current.Kink
        """Whether the loaded line meets the mean level of a kink's few flat readings within
        :data:`MAX_OFFSET_SE` of the fitted kink: those readings' own slope is loose, so where the
        loaded line meets their level (a dead zone's flat) must agree with the kink."""
        return abs((float(np.mean(flat)) - kink.level) / kink.after) <= MAX_OFFSET_SE

    def _flat_in_dead_zone(self, kink, allowed: float) -> bool:  # noqa: ANN001 - hystcli.current.Kink
        """Whether a kink whose flat stretch climbs further than a dead zone does is placed by the
        dead zone's readings alone: fitted again on the readings from the model's dead-zone width
        (and a degree) before it on, the kink stays within :data:`MAX_OFFSET_SE` of where it was
        and that flat climbs no more than ``allowed`` mA.

        A shift moves the dead zone and keeps its width. A flat longer than that width began
        before the dead zone (a tendon still unloading); where that earlier stretch runs on in
        the dead zone's own line (a load dropped at the reversal easing off at a pretensioned dead
        zone's slope), it pulls the kink nowhere, and the kink stands (design replay 3700052,
        examined in stop 32)."""
        from .current import kink_fit

        width = self.edges[1] - self.edges[-1]
        if not width > 0:
            return False
        q, c = np.array(self.seg_q), np.array(self.seg_c)
        keep = self.dir * (q - (kink.at - self.dir * (width + 1.0))) >= 0
        q, c = q[keep], c[keep]
        if int(np.sum(self.dir * (kink.at - q) > 0)) < AFTER_STEPS:
            return False
        refit = kink_fit(q, c, self.dir, curved=False, min_side=2, resolution=self.u / 25.0, convex=True)
        if refit is None or abs(refit.at - kink.at) > MAX_OFFSET_SE:
            return False
        return refit.before * self.dir * (refit.at - float(q[0])) <= allowed

    def _after_taut_start(self) -> bool:
        """Whether the segment is the one a taut start heads into: it crosses the dead zone from
        the tendon the search began on (no contact, no turn from a slack start, no walk back),
        whether the search had to turn round for it or was already pointed that way."""
        return (self.start_outside and not self.turned and self.from_taut and not self.seg_back
                and not self.contacts)

    def _flat_after_unloading(self, kink, noise: float) -> bool:  # noqa: ANN001 - hystcli.current.Kink
        """Whether a kink's short flat is the dead zone's by its level, after the unloading of the
        tendon a taut start held: the kink's level and every reading of its flat within the kink's
        own no-load band (:meth:`_level_bands`); the readings before the flat (:data:`AFTER_STEPS`
        or more) starting off that band on the side of the tendon behind, none off it on the other
        side, and moving toward the no-load level along the motion; and the loaded line meeting
        the flat's mean level within :data:`MAX_OFFSET_SE` of the kink (:meth:`_pinned`, as
        :meth:`_flat_on_no_load`).

        A taut tendon unloads until the tip settles in its dead zone, which may leave only a
        degree of the dead zone's flat before the other edge (design replay 3700381: a dead zone
        3.1 deg wide, two readings over 0.8 deg at the no-load level, the kink 0.01 deg from the
        edge, refused at the travel limit). The level tells that flat from the current's
        waviness: an unloading that arrives at the no-load level and stays there is a tendon gone
        slack."""
        c0 = self.th.no_load(self.dir, self.moving)[0]
        if c0 is None or kink.after <= 0 or kink.n_before < 2:
            return False
        _, _, band_own = self._level_bands(kink, noise)
        q, c = np.array(self.seg_q), np.array(self.seg_c)
        before = self.dir * (q - kink.at) < 0
        qb, cb = q[before], c[before]
        flat, lead_q, lead_c = cb[-kink.n_before:], qb[:-kink.n_before], cb[:-kink.n_before]
        if lead_c.size < AFTER_STEPS:
            return False
        load = self.dir * (lead_c - c0)     # loading-positive: the tendon behind pulls it negative
        if not (load[0] < -band_own and np.all(load <= band_own)):
            return False
        if not _ls_slope(self.dir * lead_q, load) > 0:
            return False
        return bool(abs(kink.level - c0) <= band_own and np.all(np.abs(flat - c0) <= band_own)
                    and self._pinned(kink, flat))

    def _judge_rest(self, kink, noise: float, span_before: float) -> tuple[str, str]:  # noqa: ANN001
        """:meth:`_judge`'s checks of a kink whose flat stretch is long enough to be one."""
        # a dead zone climbs at most its pretension's swing across its whole width: a flat
        # stretch that climbs further began as a tendon unloading toward the dead zone, and a
        # fit that spans both places the kink late (the reading in reserve leaves the unloading
        # out)
        if self.margin is None and self.th.dead_zone_swing > 0:
            climb = kink.before * span_before
            allowed = 2.0 * self.th.dead_zone_swing + self.th.no_load(self.dir, self.moving, swing=0.0)[1]
            if climb > allowed and not self._flat_in_dead_zone(kink, allowed):
                return REFUSE, (f"the current before the kink at {kink.at:.2f} deg climbs {climb:.3g} mA over "
                                f"{span_before:.1f} deg, more than a dead zone does ({allowed:.3g}): a tendon "
                                "unloading toward it")
        # how sure the offset would be: the kink's place and the model's edge it is measured from
        model_se = self.model_se.get(self.dir, 0.0)
        edge = "d_pos" if self.dir > 0 else "d_neg"
        if edge in self.th.unfixed:
            # the search goes on: the other edge, across the dead zone, may give the offset (and
            # this kink, beside where the sweep's current put the edge, must agree with it)
            self.unplaced[self.dir] = kink
            return REFUSE, (f"a tendon was taken up at {kink.at:.2f} deg, but the identification could not "
                            f"place {edge} (identify's warning says why: a dead-zone flat too narrow to see, "
                            "an edge only the record's first stretch shows, or two loops the record cannot "
                            "tell apart), so that edge gives no offset; identify again on a sweep that shows it")
        if model_se > MAX_MODEL_SE:
            return REFUSE, (f"the model's {edge} is itself known only to +-{model_se:.2f} deg (its "
                            "identification's standard error): no offset from it is surer than that")
        # below that, the identification's own uncertainty is the user's to judge (it is in the
        # model file and in identify's report); the search answers for its own kink only
        c0 = self.th.no_load(self.dir, self.moving)[0]
        if c0 is None:
            return self._placed(kink, 0.0) or (ACCEPT, "")
        swing, band_wide, band_own = self._level_bands(kink, noise)
        # the flat's level at the kink and the last reading's, loading-positive, from the no-load
        # level of the sweep
        lvl = self.dir * (kink.level - c0)
        last = self.dir * (self.seg_c[-1] - c0)
        # A flat on the side of the tendon taken up, above where a (pretensioned) dead zone
        # climbs to at its edge, may be that tendon's backlash plateau (taut since before the
        # search, its tip held): its kink then marks where the earlier stretch ended, as far past
        # the edge as the flat's excess level is in degrees of the loaded slope, which counts in
        # how surely the kink places the edge. Only on the stretch from where the search began: a
        # tendon met after crossing the dead zone (from a taut start, after a turn or a contact)
        # lay slack all the way (the other one unloads fully before it is taken up), and an
        # excess level there is the sweep's no-load level lying off.
        plateau = 0.0
        excess = lvl - swing - (0.0 if self.margin is not None else self.th.spread(self.moving))
        if excess > 0 and self.seg_from_start and not self.start_outside and kink.after > 0:
            rn = noise if math.isfinite(noise) else self.th.noise
            plateau = max(excess - 4.0 * rn, 0.0) / kink.after
        # A flat that sits beyond the identification's whole band on the side of the tendon
        # behind is that tendon still taut, its tip held on the backlash plateau (a load that
        # stays until the plateau ends, DESIGN.md section 4): the rise out of it is the tendon
        # unloading toward the no-load level, and where it ends the other tendon may already be
        # loading (a plateau wider than the dead zone), so the current runs on past the no-load
        # level with no flat between: the kink is no edge. A no-load level lying off the sweep's
        # (speed, viscous friction, a Coulomb level that changed) leaves a dead zone's flat
        # outside the band too, so the level alone does not tell them apart; the plateau's
        # length does: the tip rests on it for at most the model's backlash of that tendon,
        # so only a flat from where the search began (on the plateau somewhere) that is no
        # longer than that backlash (and a degree) can be it. As for the plateau ahead, the
        # excess level counts in degrees of the loaded slope, past MAX_OFFSET_SE. And one tendon
        # loading runs through the no-load level as one straight line, where an unloading that
        # hands over to the other tendon changes slope there (two tendons, two slopes).
        flat_span = self.dir * (kink.at - self.seg_q[0])
        behind = 0.0
        # The walk back from where a search was stopped (:meth:`_walk`) begins as a start does:
        # the tendon behind it, the far one, which the walk out may have loaded without reading
        # its edge, may still be taut on its plateau.
        if (self.seg_from_start or self.seg_back) and kink.after > 0 \
                and flat_span <= self.backlash[self.dir] + 1.0:
            if (-lvl - band_wide) / kink.after > MAX_OFFSET_SE and not self._one_line_through(kink, c0):
                return REFUSE, (f"the flat before the kink at {kink.at:.2f} deg sits at {kink.level:.1f} mA, beyond "
                                f"the no-load band ({c0:.1f} +- {band_wide:.1f} mA) on the side of the tendon behind: "
                                "that tendon still taut on its backlash plateau, the rise its unloading")
            # Inside that band, or through the no-load level in one line, but off the kink's own
            # band, the flat may still be the tendon behind held taut: its rise then runs on
            # through the no-load level in one line when the other tendon takes over there (a
            # backlash plateau as wide as the dead zone), and the edge lies where the rise crosses
            # the no-load level, as far on as the flat sits short of it in degrees of the slope.
            # That distance is how surely the kink places the edge: past MAX_OFFSET_SE the kink is
            # refused (held-out null replay 1000327: a flat 14 mA short of the no-load level,
            # inside a fast sweep's 24 mA band, gave an offset of -2.1 deg).
            behind = max(-lvl - band_own, 0.0) / kink.after
            if behind > MAX_OFFSET_SE:
                return REFUSE, (f"the flat before the kink at {kink.at:.2f} deg sits at {kink.level:.1f} mA, "
                                f"{-lvl:.1f} mA short of the no-load level ({c0:.1f} mA) on the side of the tendon "
                                "behind: it may be that tendon still taut on its backlash plateau, which would put "
                                f"the edge up to {behind:.2f} deg further on")
        taut = self._flat_taut_behind(kink, noise)
        if taut is not None:
            return REFUSE, (f"the flat before the kink at {kink.at:.2f} deg starts at {taut:.1f} mA, off the no-load "
                            f"band ({c0:.1f} +- {band_wide:.1f} mA) on the side of the tendon behind: the current "
                            "is moving back toward its no-load level, that tendon unloading, and the kink is where "
                            "its unloading steepens, not an edge")
        placed = self._placed(kink, plateau, behind)
        if placed is not None:
            return placed
        # A tendon taken up pulls the current out of the no-load band on its own side; a tendon
        # unloading toward the band only arrives at it and flattens there: wait until the current
        # has left it. A flat that sat below the band (a replay's no-load level moves with its
        # speed, the sweep's with the backlash on its dead-zone stretch) must be followed by a
        # current as far beyond it as the flat sat short of the no-load level: an unloading
        # tendon would need the no-load level to lie further out still, and to be unloading yet.
        if last <= band_own + (-lvl if -lvl > band_own else 0.0):
            return WAIT, ""
        # a flat beyond the whole band on the side of the tendon behind: the no-load level may be
        # either direction's (the sweep's two lie apart by its Coulomb friction, or by a load it
        # misread as one); an unloading ends at the true one, so the current must run past the
        # farther of the two as well before the rise is a tendon taken up
        if -lvl > band_wide and self.th.no_load_rising is not None and self.th.no_load_falling is not None:
            far = max(self.dir * (self.th.no_load_rising - c0), self.dir * (self.th.no_load_falling - c0), 0.0)
            if last <= band_own + far + (-lvl):
                return WAIT, ""
        # the identification's band is read on a whole sweep and is wide where that sweep was
        # noisy, walled or unloading on its dead-zone stretch; the kink's own band is enough when
        # the search can go no further
        if last > band_wide + (-lvl if -lvl > band_wide else 0.0):
            return ACCEPT, ""
        return READY, ""

    def _flat_taut_behind(self, kink, noise: float) -> float | None:  # noqa: ANN001 - hystcli.current.Kink
        """The first reading of a kink's flat stretch when :data:`TAUT_FLAT_READINGS` or more of
        its readings lie clearly off the no-load band on the side of the tendon behind (the band
        :meth:`_taut_side` reads a taut start by, widened by four times the readings' noise and
        :data:`MAX_OFFSET_SE` deg of the loaded slope) and the kink itself lies back inside it,
        else None.

        A dead zone's flat lies in the no-load band along its whole length: no tendon is taut
        there. A flat that begins taut on the side of the tendon behind, where the readings
        begin, and runs on in one line (no arrival at a dead zone between) is that tendon still
        unloading, the current moving back toward its
        no-load level (a load-following current on the tip's backlash plateau, a pretensioned
        tendon easing off), and the kink at its end is where the unloading steepens (the tip
        leaving its plateau), whatever the level at the kink itself: the identification's band
        is wide where its sweep was (design seed 1304 of ``bench/zoo.py``: the flat from a taut
        start at 208 mA, 48 mA past the band, ran 20 deg to a kink at 126 mA inside it; the kink
        gave an offset 12 deg off). The segment's first reading is left out (a stiction burst
        may sit there)."""
        before, flat = self._before_kink(kink)
        if kink.n_before <= 0 or before.size == 0:
            return None
        # the flat must run from where the readings begin (the segment's first reading aside): a
        # flat that begins after a steeper stretch begins where an unloading arrived at the dead
        # zone, and a dead zone whose level lies off the sweep's (the replay's speed, its viscous
        # friction) begins off the band as well (design seeds 522, 1522, 2497: right offsets from
        # such flats, up to 6 mA past the band)
        if kink.n_before < before.size - 1:
            return None
        # clearly off the band only: by four times the readings' noise and by MAX_OFFSET_SE deg of
        # the loaded slope (a reading just past the band's edge is the band's own looseness)
        c0, band = self.th.no_load(self.dir, self.moving)
        if c0 is None:
            return None
        if self.margin is not None:
            band = self.margin
        noise = noise if math.isfinite(noise) else self.th.noise
        clear = band + max(4.0 * noise, MAX_OFFSET_SE * max(kink.after, 0.0))
        behind = [float(v) for v in flat if -self.dir * (float(v) - c0) > clear]
        # a flat wholly off the band is a level of its own (a dead zone whose no-load level lies
        # off the sweep's, or the plateau :meth:`_judge_rest` reads apart): only a flat whose own
        # line carries it from the taut side into the band is the current moving back
        if len(behind) < TAUT_FLAT_READINGS or self._taut_side(float(kink.level)) == -self.dir:
            return None
        return behind[0]

    def _one_line_through(self, kink, c0: float) -> bool:  # noqa: ANN001
        """Whether the readings past ``kink`` keep one slope (within a quarter) on either side of
        where they cross the no-load level ``c0``, three readings or more on each side."""
        q, c = np.array(self.seg_q), np.array(self.seg_c)
        past = self.dir * (q - kink.at) > 0
        q, c = q[past], c[past]
        beyond = self.dir * (c - c0) > 0
        if beyond.size == 0 or not beyond[-1]:
            return False
        k = int(np.argmax(beyond))
        if k < 3 or q.size - k < 3 or not beyond[k:].all():
            return False
        s1, s2 = _ls_slope(q[:k], c[:k]), _ls_slope(q[k:], c[k:])
        return abs(s1 - s2) <= 0.25 * max(abs(s1), abs(s2))

    def _placed(self, kink, plateau: float, behind: float = 0.0) -> tuple[str, str] | None:  # noqa: ANN001
        """None when the offset would be sure enough (:data:`MAX_OFFSET_SE`), else a refusal (a
        possible plateau is too unsure: more readings would not help) or a wait with the reason
        (a longer loaded stretch places the kink better). ``plateau`` and ``behind``: how far
        back a plateau of the tendon taken up, and how far on a tendon behind still taut, would
        put the edge (deg)."""
        if plateau > MAX_OFFSET_SE:
            return REFUSE, (f"the kink at {kink.at:.2f} deg starts from {kink.level:.1f} mA, off the no-load level "
                            "toward the tendon taken up: it may be that tendon's backlash plateau (taut since before "
                            f"the search), which would put the edge up to {plateau:.2f} deg back")
        if math.hypot(kink.se, plateau, behind) > MAX_OFFSET_SE:
            need = math.sqrt(max(MAX_OFFSET_SE ** 2 - plateau ** 2 - behind ** 2, 0.0))
            why = f"the kink at {kink.at:.2f} deg is placed only to +-{kink.se:.2f} deg (needs {need:.2f})"
            # the fit's loaded stretch ends before the last reading when a steeper one follows (a
            # wall, a stiffening cable): more readings would not place the kink any better
            past = sum(1 for v in self.seg_q if self.dir * (v - kink.at) >= 0)
            return (WAIT if past <= kink.n_after else REFUSE), why
        return None

    def _level_bands(self, kink, noise: float) -> tuple[float, float, float]:  # noqa: ANN001
        """(swing, wide, own) in mA: how far a dead zone's current climbs toward an edge from the
        no-load level, and the half-widths of the band around that level that count as slack.

        The swing is the slope of the kink's own flat stretch over half the dead zone's width
        (never more than the identification's: a steep stretch is no dead zone). ``wide`` is the
        identification's band (:meth:`Thresholds.no_load`: its swing, loaded slope and noise);
        ``own`` the kink's (its swing, a degree of the slope after it, four times the readings'
        noise), never wider. With a level margin given, that margin is both.
        """
        if self.margin is not None:
            return 0.0, self.margin, self.margin
        swing = abs(kink.before) * self.th.half_width
        if self.th.dead_zone_swing > 0:
            swing = min(swing, self.th.dead_zone_swing)
        wide = self.th.no_load(self.dir, self.moving)[1]
        noise = noise if math.isfinite(noise) else self.th.noise
        own = self.th.no_load(self.dir, self.moving, swing=swing,
                              slope=min(self.th.slope_loaded, max(kink.after, 0.0)), noise=noise)[1]
        return swing, wide, min(own, wide)

    def _steep_edge(self, q: np.ndarray, c: np.ndarray, sig: float):  # noqa: ANN201 - Kink or None
        """A contact's steep rise straight out of the dead zone, placed as a loading edge, or None.

        Physics: a tendon stiffer than the sweep's (or a tip already resting on a wall when the
        tendon is taken up) rises as steeply as a contact straight out of a flat stretch at the
        no-load level; a wall met by a tip a taut tendon is bending comes after a loaded stretch
        instead. The search does not drive on to lengthen the rise (it turns as for any
        contact); the kink must pass every other check, its flat lie on its own no-load band
        with a dead zone's slope (below eps_lower), and two readings a step or more past it
        place it (the steep slope places it well: a contact stops the search there). Whether it is an edge is for
        :meth:`_steep_pair`.
        """
        from .current import loading_edge

        if self.th.current_dead_zone is None or q.size < AFTER_STEPS + 3:
            return None
        kink = loading_edge(q, c, self.dir, sig, minlen=2, resolution=self.u / 25.0, convex=True)
        if kink is None:
            return None
        if kink.before >= self.th.eps_lower or kink.n_after < 2:
            return None
        c0 = self.th.no_load(self.dir, self.moving)[0]
        noise = _reading_noise(c)
        _, _, band_own = self._level_bands(kink, noise)
        if abs(kink.level - c0) > band_own:
            return None
        status, _ = self._judge(kink, min_after=2, min_span=self.u - 1e-9)
        return kink if status in (ACCEPT, READY) else None

    def _steep_pair(self):  # noqa: ANN201 - (direction, Kink) or None
        """Both contacts' rises out of the dead zone, as far apart as the model's dead zone is
        wide (within :data:`STEEP_AGREE`): the two tendons' take-up, not two walls.

        A steep rise alone is not taken: the knob may meet a stop or the shaft a wall inside
        the dead zone (paper, Discussion), and the search turns there as Algorithm 1 does. But
        a shift moves both edges by one offset and leaves the dead zone's width as it was: two
        walls that happened to stand exactly that width apart, each met straight out of the
        no-load flat, are not a thing to expect, two tendons stiffer than the sweep's are.
        Returns the better placed of the two (its direction and kink)."""
        kp, kn = self.steep[1], self.steep[-1]
        if kp is None or kn is None:
            return None
        off_p, off_n = kp.at - self.edges[1], kn.at - self.edges[-1]
        if abs(off_p - off_n) > STEEP_AGREE:
            return None
        return (1, kp) if kp.se <= kn.se else (-1, kn)

    def _taut_without_edge(self, c: np.ndarray) -> bool:
        """Whether a search that began slack has met a taut tendon without an edge to take: the
        last :data:`AFTER_STEPS` readings all off the no-load band on the side it moves to (the
        identification's band, the widest). Only once: never after a taut start, a turn or a
        contact, so a search crosses the dead zone at most once."""
        if self.start_outside or self.contacts or self.th.current_dead_zone is None or c.size < AFTER_STEPS:
            return False
        return all(self._taut_side(float(v)) == self.dir for v in c[-AFTER_STEPS:])

    def run(self):  # noqa: ANN201 - (kind, Kink)
        try:
            first = getattr(self.probe, "first_direction", None)
            read = getattr(self.probe, "read", None)
            if first in (1, -1):
                # a record: the first steps go the way it goes (no walk through its own turn),
                # and the state is read past the start, where a stiction burst may sit
                self.dir = first
                for _ in range(self.FIRST):
                    self._step()
                side = self._taut_side(float(np.median(self.seg_c[1:])))
            elif read is not None:
                # a robot at rest: its reading before any step
                first_read = read()
                side = self._taut_side(self._uncogged(float(first_read.q), float(first_read.current)))
            else:
                for _ in range(self.FIRST):
                    self._step()
                side = self._taut_side(float(np.median(self.seg_c[1:])))
            if side != 0:
                self._turn_toward_slack(side)
            return self._walk()
        except _LimitReached as lim:
            why = f"; the last candidate was refused: {self.pending_refusal}" if self.pending_refusal else ""
            where = (" (it met a taut tendon with no edge to read and went through the dead zone toward the "
                     "other edge)" if self.turned else
                     " (it started with a tendon taut and went through the dead zone toward the other edge)"
                     if self.start_outside else "")
            if self.back is not None:
                where += (f", then, stopped there ({self.back}), "
                          + ("turned back to read the edge it had left from the dead zone" if self.start_outside
                             else "turned back across the dead zone to read the edge on its other side"))
            raise ShiftDetectionError(
                f"knob {self.knob}: no edge found within {self.steps} steps / {self.travel:.1f} deg of knob "
                f"travel ({lim.why}){where}{why}") from None

    def _walk(self):  # noqa: ANN202 - (kind, Kink)
        """Step and judge until an edge is accepted or a limit is reached (:class:`_LimitReached`)."""
        while True:
            try:
                return self._walk_on()
            except _LimitReached as lim:
                if self.ready is not None:
                    # the edge passed every check on the readings there are: the search can go no
                    # further to lengthen its loaded stretch
                    return LOAD, self.ready
                last = self._judged_at_limit()
                if last is not None:
                    return LOAD, last
                if self.short is not None:
                    # no edge with a flat long enough to read lay within reach: the one at the
                    # start, whose few flat readings sat at the no-load level, is the evidence there is
                    self.dir = self.short[0]
                    return LOAD, self.short[1]
                if self.back is None and not self.contacts and self._released(lim.record_end) and (
                        self.start_outside or self.dir * (self.q - self.start) >= self.backlash[self.dir] + 1.0):
                    # it left a taut tendon across the dead zone for the other edge, which lies
                    # beyond reach (the travel limit, or the end of a record): the edge it left is
                    # still there, and now it has the whole dead zone's flat before it. Turn back
                    # once and load that tendon from the flat, as from a start in the dead zone.
                    # From a start in the dead zone, likewise: the edge the record went toward
                    # first lies beyond reach, the one on the other side may not (design replay
                    # 1598: the far edge 12.4 deg out with 11.6 of travel, the other 2.8 deg
                    # behind the start). Only once the knob has gone further from the start than
                    # the backlash of the tendon behind, and a degree: a start read as slack may
                    # be that tendon taut with its load dropped at a reversal (a drop law), its
                    # tip still on the plateau, which a walk back would take up where it turned
                    self.back = lim.why
                    self._reverse()
                    self.seg_back = True
                    continue
                raise

    def _judged_at_limit(self):  # noqa: ANN202 - Kink or None
        """The kink the search was waiting on when it could go no further, judged on the readings
        past it there are (:data:`LIMIT_AFTER` of them, over two steps or more), or None.

        A kink waits for :data:`AFTER_STEPS` readings over 1.5 deg past it before it is judged; an
        edge that lies within the last steps before a travel limit or the end of a record never
        gets them, however clearly the readings there show it (design replay 3700050: a kink of
        clarity 124, placed to +-0.01 deg, three readings over 1.3 deg before the limit). Every
        other check still applies, the offset's standard error among them."""
        kink = self.waiting
        if kink is None:
            return None
        status, why = self._judge(kink, min_after=LIMIT_AFTER, min_span=2.0 * self.u - 1e-9)
        if status in (ACCEPT, READY) and self._drifted(kink) is None:
            return kink
        if why:
            self.pending_refusal = why
        return None

    def _released(self, record_end: bool = False) -> bool:
        """Whether the tendon the walk back would take up is slack by now: the current has come
        back to the no-load level (the band :meth:`_taut_side` reads) and stays there, no longer
        moving toward it, over the last :data:`AFTER_STEPS` readings (a degree or more). Readings
        past the band on the side ahead count as slack behind while they climb more gently than a
        taut tendon (a pretensioned dead zone climbing out of the band over a long way: design
        replay 4400203, 1.3 mA/deg over 18 deg, 19 mA out against a band of 18).

        From a taut start it is the tendon the search turned from. Till then it still carries
        load (its tip on the backlash plateau, or still unloading), and a walk back takes it up
        again where the knob last turned, not at its edge (design replay 932: still unloading
        12 deg from where it turned, the kink 13 deg past the edge; 76: a held load 21 deg long).
        From a start in the dead zone it is the other tendon, which the search moved away from
        all the way. Without a no-load level, never.

        ``record_end``: the search stopped where a replay goes no further this way. Its last
        reading may be taken where the record slows to its turn, and a viscous motor's current
        falls with the speed there (design replay 4400314: 5 mA toward the no-load level over the
        last half degree before a sine's crest, on a dead zone at 0.7 mA/deg); the readings
        without it count as well (design replay 328: the flat only its last three readings long,
        the one at the end among them).
        """
        return self._slack_behind(self.seg_q, self.seg_c) or (
            record_end and self._slack_behind(self.seg_q[:-1], self.seg_c[:-1]))

    def _slack_behind(self, seg_q: list[float], seg_c: list[float]) -> bool:
        """:meth:`_released` on the segment's readings ``seg_q``, ``seg_c``."""
        c0 = self.th.no_load(self.dir, self.moving)[0]
        if c0 is None:
            return False
        if len(seg_q) < AFTER_STEPS or abs(seg_q[-1] - seg_q[-AFTER_STEPS]) < 1.0:
            return False
        q, c = np.array(seg_q[-AFTER_STEPS:]), np.array(seg_c[-AFTER_STEPS:])
        sides = {self._taut_side(float(v)) for v in c}
        if -self.dir in sides:
            return False
        slope = _ls_slope(q, c)
        if self.dir in sides and slope >= self.th.eps_lower:
            # past the band on the side ahead at a taut tendon's slope: the tendon ahead is loading
            return False
        # stays: not still moving toward the no-load level, as an unloading does through a wide
        # band (design replay 397, a wall plant: 11 mA over the last 1.5 deg, 100 mA short of the
        # no-load level, inside the sweep's band of +-132)
        seg = np.array(seg_c)
        noise = _reading_noise(seg)
        if not math.isfinite(noise):
            return False
        # a current logged in whole steps (integer mA) that sits still has no spread of second
        # differences at all: its step is its noise then (design replay 1346: 0.3 mA over 1.5 deg
        # read as a current still moving)
        steps = np.abs(np.diff(seg))
        steps = steps[steps > 0]
        if steps.size:
            noise = max(noise, float(steps.min()) / math.sqrt(12.0))
        # and a pretensioned dead zone climbs through the no-load level across its whole width at
        # its own slope, which is no unloading (design replay 1063: 6 mA/deg, the sweep's 6.2),
        # but only as far from that level as its swing: an unloading further off is no dead zone
        # (design replay 397: 108 mA short of the level, a swing of 88, the sweep's slope 8.7
        # mA/deg and the unloading's 7.5)
        change = slope * (q[-1] - q[0])
        short = c0 - float(np.mean(c))
        allowed = 3.0 * noise
        if abs(short) <= self.th.dead_zone_swing + self.th.spread(self.moving) + allowed:
            allowed += self.th.slope_dead_zone * abs(q[-1] - q[0])
        return not (np.sign(change) == np.sign(short) and abs(change) > allowed)

    def _walk_on(self):  # noqa: ANN202 - (kind, Kink)
        """One leg of the walk: step, read the segment's kink, judge it; returns an accepted edge."""
        from .current import loading_edge

        while True:
            self._step()
            n = len(self.seg_q)
            q, c = np.array(self.seg_q), np.array(self.seg_c)
            # contact: the last readings climb far steeper than any tendon, away from the
            # no-load level (backing off a wall is as steep, toward it)
            c0 = self.th.no_load(self.dir, self.moving)[0]
            if n >= 3 and _ls_slope(q[-3:], c[-3:]) >= self.th.eps_upper and \
                    (n < 4 or _ls_slope(q[-4:-1], c[-4:-1]) >= self.th.eps_upper) and \
                    (c0 is None or abs(c[-1] - c0) > abs(c[-3] - c0)):
                sig = _reading_noise(c)
                self.steep[self.dir] = self._steep_edge(q, c, sig if math.isfinite(sig) and sig > 0 else 1e-9)
                self.contacts.append(self.q)
                self.short = None    # a rise at the start that ends on a wall is no edge to keep
                both = self._steep_pair()
                if both is not None:
                    self.dir = both[0]
                    return LOAD, both[1]
                if len(self.contacts) > 1:
                    raise ShiftDetectionError(
                        f"knob {self.knob}: contact in both directions (at {self.contacts[0]:.2f} and "
                        f"{self.contacts[1]:.2f} deg): no free side to find a dead-zone edge")
                self._reverse()
                continue
            if n < self.LOADED_CHECK:
                continue
            sig = _reading_noise(c)
            sig = sig if math.isfinite(sig) and sig > 0 else 1e-9
            kink = loading_edge(q, c, self.dir, sig, minlen=2, resolution=self.u / 25.0, convex=True,
                                min_run=AFTER_STEPS)
            # a start in the dead zone that has been loading from the first reading (no kink
            # out of a flat stretch): a tendon was taut after all
            if (kink is None and self.seg_from_start and not self.start_outside
                    and _ls_slope(q[:4], c[:4]) >= self.th.eps_lower and _ls_slope(q, c) >= self.th.eps_lower):
                if self.th.current_dead_zone is None:
                    raise ShiftDetectionError(
                        f"knob {self.knob} is loaded from the first steps (a tendon is already taut at "
                        f"{self.start:g} deg) and the model has no no-load current level to tell which "
                        "one: give --current-dead-zone (or identify the model with `hyst identify`)")
                if self._taut_side(float(c[-1])) == self.dir:
                    # loading since the first reading and now clearly off the no-load level
                    self._turn_toward_slack(self.dir)
                    continue
            self.ready = None
            status, why = (None, "") if kink is None else self._judge(kink)
            if status in (None, DOUBT, REFUSE) and (
                    kink is not None or _ls_slope(q[-4:], c[-4:]) >= 0.5 * self.th.eps_lower):
                # no edge on the reading identification makes of a whole sweep's many points:
                # read the search's few noisy ones more strictly (as many straight pieces as
                # their noise pays for, the flat stretch without the unloading that led into
                # it). An edge found so is held in reserve for RESERVE_STEPS readings past it,
                # or until the search can go no further: where the first reading finds one
                # meanwhile, that one stands.
                alt = loading_edge(q, c, self.dir, sig, minlen=2, resolution=self.u / 25.0,
                                   strict_flat=True, select=True, convex=True, min_run=AFTER_STEPS)
                if alt is not None and alt != kink:
                    alt_status, alt_why = self._judge(alt)
                    if alt_status == ACCEPT and alt.n_after < RESERVE_STEPS:
                        alt_status = READY
                    if alt_status not in (DOUBT, REFUSE) or kink is None:
                        kink, status, why = alt, alt_status, alt_why
            if status in (ACCEPT, READY):
                drift = self._drifted(kink)
                if drift is not None:
                    status, why = REFUSE, drift
            if status == ACCEPT:
                return LOAD, kink
            if status == READY:
                self.ready = kink
            self.waiting = kink if status == WAIT else None
            if why:
                self.pending_refusal = why
            if (kink is None or status == REFUSE) and self.ready is None and self._taut_without_edge(c):
                # the tendon ahead is taut and no edge could be read on the way to it (an
                # edge a step or two from the start, one the model cannot give an offset
                # from): the other edge lies across the dead zone, as from a taut start. (A
                # kink only doubtful yet is given the readings that may make it clear.)
                self.turned = True
                self._turn_toward_slack(self.dir)


# --------------------------------------------------------------------------------------------
# the algorithm
# --------------------------------------------------------------------------------------------
def _return_knob(probe: Any, start: float) -> tuple[bool, str]:
    """Stop the probe and bring the knob back to ``start``; never raises."""
    ret = getattr(probe, "return_to_start", None)
    try:
        if ret is not None:
            ok = bool(ret())
        else:
            try:
                probe.stop()
            except Exception:  # noqa: BLE001 - a stop that fails must not hide the return
                pass
            s = probe.step_to(start)
            ok = abs(float(s.q) - start) < 1e-3 + 1e-6 * abs(start)
    except Exception as exc:  # noqa: BLE001 - report, never mask the original fault
        return False, f"the knob could NOT be returned to {start:g} deg ({exc})"
    if ok:
        return True, f"search stopped, knob returned to {start:g} deg"
    return False, f"the knob could NOT be confirmed back at {start:g} deg"


DEFAULT_MAX_TRAVEL = 25.0
"""Travel limit (deg) of a search whose model does not record the range it was identified on."""


def default_max_travel(model: Model, knob: int) -> float:
    """The travel limit of a search when none is given (deg of knob).

    The largest ``|q|`` of the identification sweep (``KnobIdentification.q_min``/``q_max``)
    plus half the dead zone's width: a search that starts with a tendon taut crosses the whole
    dead zone to the far edge, and stops a few degrees past it, so in the tendons' own terms
    (``u = q - offset``) it never drives the knob beyond what the sweep already did;
    :data:`DEFAULT_MAX_TRAVEL` when the model has no identification.
    """
    ident = model.identification.get(int(knob)) if model.identification else None
    if ident is None:
        return DEFAULT_MAX_TRAVEL
    reach = max(abs(float(ident.q_min)), abs(float(ident.q_max)))
    km = model.knob(int(knob))
    reach += 0.5 * max(km.d_pos - km.d_neg, 0.0)
    return reach if math.isfinite(reach) and reach > 0 else DEFAULT_MAX_TRAVEL


def detect_shift(model: Model, probe: Any, knob: int = 1, *, eps_lower: float | None = None,
                 eps_upper: float | None = None, current_dead_zone: float | None = None,
                 step: float = 0.5, max_steps: int | None = None, max_travel: float | None = None,
                 direction: int = 1, level_margin: float | None = None, return_home: bool = True,
                 progress: Callable[[ProbeSample, float], None] | None = None) -> ShiftResult:
    """Find the shift of one knob's dead zone from its motor current (Algorithm 1).

    Parameters
    ----------
    model : Model
        The straight-shaft model; its ``d_pos``/``d_neg`` are :math:`D_{pos}, D_{neg}`.
    probe : Probe
        Steps the knob and reads the current (:class:`ReplayProbe`, a live device probe).
    knob : int
        Which knob (1 or 2).
    eps_lower, eps_upper : float, optional
        :math:`\\epsilon_{lower}` and :math:`\\epsilon_{upper}` (mA/deg); default: the model's
        identification of the knob (``KnobIdentification.eps_lower``/``eps_upper``).
    current_dead_zone : float, optional
        Current with no tendon taut (mA); default: the model's identification. Without it the
        search cannot tell a taut start and assumes the knob rests in the dead zone.
    step : float
        Unit step :math:`u` (deg).
    max_steps : int, optional
        Step limit; default ``2 * ceil(max_travel / step) + 6``: room to read the start state, turn
        toward the slack side and, after a contact, cross to the other side.
    max_travel : float, optional
        Travel limit of the search: how far from where it began the knob may go (deg of knob, on
        either side); default :func:`default_max_travel` (the identification sweep's reach).
    direction : int
        Initial direction (+1 as in the paper, or -1) when no tendon is taut at the start.
    level_margin : float, optional
        How far (mA) from the no-load level a reading must be for a tendon to count as taut;
        default :meth:`Thresholds.no_load` (the Coulomb gap when the probe reads at rest, a
        pretensioned current's swing across the dead zone, a degree of the loaded slope).
    return_home : bool
        Return the knob to where it began after a successful search too (a failed one always
        returns it).
    progress : callable, optional
        Called with each :class:`ProbeSample` and the slope of the last readings.

    Returns
    -------
    ShiftResult

    Raises
    ------
    ShiftDetectionError
        No edge within the limits, an edge whose evidence is weak (the reason is given), contact
        on both sides, a missing threshold, invalid options. Every error raised during the search
        (from the probe too) has stopped the probe and returned the knob first; its message says
        so.
    """
    k = int(knob)
    km = model.knob(k)
    th = resolve_thresholds(model, k, eps_lower, eps_upper, current_dead_zone)
    if max_travel is None:
        max_travel = default_max_travel(model, k)
    if not (math.isfinite(step) and step > 0):
        raise ShiftDetectionError(f"the unit step must be a positive number of degrees, got {step}")
    if not (math.isfinite(max_travel) and max_travel > 0):
        raise ShiftDetectionError(f"the travel limit must be a positive number of degrees, got {max_travel}")
    if max_steps is None:
        max_steps = 2 * int(math.ceil(max_travel / step - 1e-9)) + 2 * _Search.FIRST
    if int(max_steps) < 1:
        raise ShiftDetectionError(f"the step limit must be at least 1, got {max_steps}")
    if direction not in (1, -1):
        raise ShiftDetectionError(f"direction must be +1 or -1, got {direction}")
    margin = None
    if level_margin is not None:
        margin = float(level_margin)
        if not (math.isfinite(margin) and margin > 0):
            raise ShiftDetectionError(f"the level margin must be a positive number of mA, got {level_margin}")

    ident = model.identification.get(k)
    # edges the tip fit could not place that the sweep's current did: no longer unplaced for the search
    by_current = _edges_by_current(km, ident)
    placed = {"d_pos" if d > 0 else "d_neg" for d in by_current}
    th = replace(th, unfixed=tuple(u for u in th.unfixed if u not in placed))
    search = _Search(probe, k, th, float(step), int(max_steps), float(max_travel), int(direction), margin,
                     progress)
    search.edges = {1: km.d_pos, -1: km.d_neg}
    # a backlash the sweep could not fix (kept as 0 deg) bounds no plateau: any flat may be one
    unfixed = () if ident is None else ident.unfixed
    search.backlash = {1: math.inf if "b_neg" in unfixed else km.b_neg,
                       -1: math.inf if "b_pos" in unfixed else km.b_pos}
    if ident is not None and ident.stderr:
        search.model_se = {1: float(ident.stderr.get("d_pos", 0.0)), -1: float(ident.stderr.get("d_neg", 0.0))}
    for d, (at, se) in by_current.items():
        search.edges[d], search.model_se[d] = at, se
    start = search.start
    try:
        kind, kink = search.run()
        d = search.dir
        if kind == LOAD:
            edge = "pos" if d > 0 else "neg"
            offset = kink.at - search.edges[d]
            # An edge the identification could not place on the tip still has where the sweep's
            # current showed it taken up (read the way the search reads it). A shift moves both
            # edges by one offset: a search that met that edge too must find it moved by the
            # offset it takes from this one; where it does not, the model's placed edge (or its
            # unplaced one's current reading) is wrong, and so would the offset be.
            other = search.unplaced.get(-d)
            ref_other = None if ident is None else (ident.current_edge_neg if d > 0 else ident.current_edge_pos)
            if other is not None and ref_other is not None and \
                    abs((other.at - ref_other) - offset) > UNPLACED_AGREE:
                raise ShiftDetectionError(
                    f"knob {k}: the readings disagree: the tendon taken up at {other.at:.2f} deg (where the sweep's "
                    f"current put its edge at {ref_other:.2f} deg, an edge the identification could not place) gives "
                    f"an offset of {other.at - ref_other:+.2f} deg, the loading edge at {kink.at:.2f} deg one of "
                    f"{offset:+.2f} deg")
            transition = RISE
        else:  # pragma: no cover - the search returns loading edges only
            raise ShiftDetectionError(f"knob {k}: no loading edge")
    except BaseException as exc:
        returned, note = _return_knob(probe, start)
        if isinstance(exc, HystError):
            try:
                new = type(exc)(f"{exc}; {note}")
            except Exception:  # noqa: BLE001 - an error type with another signature
                new = ShiftDetectionError(f"{exc}; {note}")
            raise new from exc
        if hasattr(exc, "add_note"):   # Python 3.11+; on 3.10 the knob is returned all the same
            exc.add_note(note)
        raise
    returned = False
    if return_home:
        returned, note = _return_knob(probe, start)
        if not returned:
            raise ShiftDetectionError(f"knob {k}: edge found at {kink.at:.2f} deg, but {note}")
    noise = _reading_noise(np.array(search.seg_c))
    ev = Evidence(clarity=float(kink.clarity), edge_se=float(kink.se), residual=float(kink.residual),
                  noise=float(noise), level=float(kink.level), no_load=th.current_dead_zone,
                  slope_before=float(kink.before), slope_after=float(kink.after),
                  n_before=int(kink.n_before), n_after=int(kink.n_after))
    return ShiftResult(
        knob=k, offset=float(offset), d_pos=float(km.d_pos + offset), d_neg=float(km.d_neg + offset),
        edge=edge, edge_found_at=float(kink.at), direction=int(d), transition=transition,
        start=start, travel=float(search.travel), steps=int(search.steps),
        contacts=tuple(float(c) for c in search.contacts), start_outside=search.start_outside,
        walked_back=search.back is not None, reference="current" if d in by_current else "model",
        returned=returned, eps_lower=th.eps_lower, eps_upper=th.eps_upper, step=float(step),
        evidence=ev, trace=tuple(search.trace))


def _edges_by_current(km: KnobModel, ident) -> dict[int, tuple[float, float]]:  # noqa: ANN001
    """{direction: (edge, standard error)} for each edge a tip fit could not place and the
    sweep's current did (its reading claims it, with a standard error), where the current's
    reading of the other edge, which the tip fit did place, agrees with it
    (:data:`CURRENT_AGREE`).

    A tip sampled too coarsely for its dead-zone corner, or a loop the record cannot tell apart,
    leaves the tip fit's edge unplaced, and an offset from it means nothing; the motor current of
    the same sweep may show the tendon taken up clearly. That edge, read the way Algorithm 1
    reads the search's own kink, is the paper's D (its identification is the current's): the
    offset is measured from it (design replays 730, 831, 3900371: the tip fit's d_pos 1.4 to 9.4
    deg off, the current's within 0.02). The other edge vouches for the current's reading: a wall plant's
    current put d_neg at +7.65 deg, above the tip's d_pos, where the truth was -1.83 (design
    replay 3900335), and with both edges unplaced nothing vouches for it (255: both current
    edges right, the search's kink 4.9 deg early). A current-only identification that left an
    edge unplaced had the current's own reason, and keeps no standard errors for these."""
    if ident is None:
        return {}
    edges = {1: ("d_pos", km.d_pos, ident.current_edge_pos, ident.current_edge_pos_se),
             -1: ("d_neg", km.d_neg, ident.current_edge_neg, ident.current_edge_neg_se)}
    out = {}
    for d, (name, _, at, se) in edges.items():
        other, tip_other, at_other, _ = edges[-d]
        if (name in ident.unfixed and other not in ident.unfixed and at is not None and se is not None
                and at_other is not None and abs(at_other - tip_other) <= CURRENT_AGREE):
            out[d] = (float(at), float(se))
    return out


def detect_shifts(model: Model, probes: Mapping[int, Any], **options: Any) -> dict[int, ShiftResult]:
    """:func:`detect_shift` on several knobs, one after the other (knob order)."""
    return {k: detect_shift(model, probes[k], k, **options) for k in sorted(probes)}


def apply_shift(model: Model, results: Mapping[int, ShiftResult] | Iterable[ShiftResult]) -> Model:
    """The model with each detected knob's ``offset`` set (absolute), others unchanged.

    The shifted edges are then :math:`\\tilde D = D + offset` (``KnobModel.shifted_d_pos``).
    """
    items = results.values() if isinstance(results, Mapping) else results
    return model.with_offsets({r.knob: r.offset for r in items})


# --------------------------------------------------------------------------------------------
# figure
# --------------------------------------------------------------------------------------------
def plot_shift(results: Sequence[ShiftResult], path: str | os.PathLike, model: Model | None = None,
               background: Mapping[int, tuple[np.ndarray, np.ndarray]] | None = None,
               inputs: Iterable[str | os.PathLike] = ()) -> None:
    """Current against knob angle with the detected edges (the paper's Fig. 5b); PNG, atomic.

    Parameters
    ----------
    results : sequence of ShiftResult
        One panel per knob: the search's steps (current vs angle), the edge it found (dot), the
        shifted dead zone :math:`[\\tilde D_{neg}, \\tilde D_{pos}]` (shaded) and, with
        ``model``, the straight-shaft edges (dotted).
    path : path-like
        The PNG file (written through a temporary file and a rename).
    background : mapping of knob to (q, current), optional
        The whole recorded current (a replay), drawn faintly behind the steps.
    inputs : iterable of path-like
        The command's inputs, never overwritten.
    """
    from matplotlib.figure import Figure

    from .metrics import figure_bytes

    results = list(results)
    if not results:
        raise ShiftDetectionError("nothing to plot: no knob was searched")
    fig = Figure(figsize=(5.5 * len(results), 4.0))
    axes = fig.subplots(1, len(results), squeeze=False)
    for ax, r in zip(axes[0], results):
        if background and r.knob in background:
            bq, bc = background[r.knob]
            ax.plot(bq, bc, color="0.8", lw=0.8, label="record")
        tq = np.array([p[0] for p in r.trace])
        tc = np.array([p[1] for p in r.trace])
        ax.plot(tq, tc, ".-", color="tab:blue", ms=3, lw=0.8, label="search steps")
        ax.axvspan(r.d_neg, r.d_pos, color="tab:green", alpha=0.12,
                   label=f"new dead zone [{r.d_neg:.1f}, {r.d_pos:.1f}]")
        if model is not None and r.knob in model.knobs:
            km: KnobModel = model.knob(r.knob)
            for d in (km.d_neg, km.d_pos):
                ax.axvline(d, color="0.4", ls=":", lw=1)
        edge_c = float(np.interp(r.edge_found_at, *_sorted(tq, tc))) if tq.size else 0.0
        ax.plot([r.edge_found_at], [edge_c], "o", color="tab:red", ms=8,
                label=f"edge {r.edge} at {r.edge_found_at:.2f} deg")
        for cq in r.contacts:
            ax.axvline(cq, color="tab:orange", ls="--", lw=1)
        ax.set_xlabel(f"knob {r.knob} angle (deg)")
        ax.set_ylabel("motor current (mA)")
        ax.set_title(f"knob {r.knob}: offset {r.offset:+.2f} deg")
        ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    data = figure_bytes(fig, "png")
    atomic_write(path, lambda f: f.write(data), inputs=inputs)


def _sorted(q: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    order = np.argsort(q, kind="stable")
    return q[order], c[order]
