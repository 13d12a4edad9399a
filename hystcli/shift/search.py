"""Algorithm 1 (the paper's gradient-based shift detection), its decisions made by statistics.

The stepping is the paper's: step the knob by ``direction * u``, read the motor current, reverse
at a contact (the current's slope past ``eps_upper``), never beyond the travel or step limit, and
on any fault or interruption stop and return the knob to where it began. What is statistical is
*when the edge is here*:

* the readings since the last turn are read as :mod:`hystcli.signal.reading` reads a sweep's
  stretch: a continuous broken line with a robust loss (pieces by BIC), its pieces named by the
  same rule (the dead zone is the last piece every later piece climbs faster than);
* the take-up knot is a change point declared at a stated false-alarm rate: its likelihood-ratio
  statistic (the deviance the knot saves, over the readings' correlation time) must pass the
  chi-square(1) quantile at ``false_alarm / (readings x step limit)`` (Bonferroni over where the
  knot could be and when the search looks);
* the current at the knot must be where the identification sweep's current took that tendon up
  (within the tendon's slope times :attr:`~hystcli.settings.Settings.max_edge_gap`, and the
  readings' noise): a flat stretch elsewhere is a held load or a taut tendon, not the dead zone;
* the offset is the knot's position minus where the sweep's current took the same tendon up
  (a bend moves the whole current along the knob), its interval the two profile intervals
  combined; the search takes more readings past the knot until that interval is narrow enough or
  it can go no further, and refuses when it stays wider than
  :attr:`~hystcli.settings.Settings.max_offset_halfwidth`;
* no offset is taken from a side whose reference the identification did not fix, or where the
  sweep's current took the tendon up farther from the tip's edge than
  :attr:`~hystcli.settings.Settings.max_edge_gap`: the search goes on to the other side.

A start with the tendon ahead already taut shows as readings that load from the first step, at a
level past the take-up's: the search turns and crosses the dead zone (the paper's "reverse"). Replay
and live run this same code over different probes (:mod:`.probe`, ``hystcli.device.DeviceProbe``).
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field, replace
from statistics import NormalDist
from typing import Any, Callable, Mapping

import numpy as np

from ..core.model import Model
from ..core.run import Run
from ..errors import HystError, ParameterError, ShiftDetectionError
from ..estimate import Estimate
from ..io import read_run
from ..settings import DEFAULT, Settings
from ..signal.pwl import fit_piecewise, knot_interval, profile
from ..signal.reading import _classify
from ..signal.result import orientation
from .probe import ProbeSample, ReplayExhausted, ReplayProbe, return_knob
from .request import ShiftRequest, select_knobs
from .result import Evidence, ShiftResult

__all__ = ["Reference", "reference_of", "detect_shift", "default_max_travel", "DEFAULT_MAX_TRAVEL"]

DEFAULT_MAX_TRAVEL = 25.0
"""Travel limit (deg) of a search whose model does not record the range it was identified on."""

MIN_READINGS = 5
"""Fewest readings since the last turn before the search reads them (a broken line needs them)."""

MAX_REFINE = 40
"""Most readings taken past a declared edge to narrow its interval (a budget of knob travel: the
contact slope and the travel limit stop it sooner)."""


@dataclass(frozen=True)
class Reference:
    """What the search knows of one knob: per direction of motion (+1 toward ``d_pos``)."""

    sign: str
    edges: Mapping[int, Estimate]
    kinds: Mapping[int, str]
    why_not: Mapping[int, str]
    edge_level: Mapping[int, float | None]
    slope_loaded: float
    eps_upper: float | None
    ripple: Any = None
    at_rest_spread: float = 0.0
    dead_slope: float = 0.0
    noise: float = 0.0
    current_range: tuple = (None, None)


def _side_reference(ident, km, d: int, settings: Settings):  # noqa: ANN001, ANN202
    """(Estimate or None, kind, why not) of the straight-shaft edge an offset on side ``d`` is
    measured from."""
    side, name = ("pos", "d_pos") if d > 0 else ("neg", "d_neg")
    tip_edge = float(getattr(km, name))
    if ident is None or ident.calibration.current_sign is None:
        est = None if ident is None else ident.estimates.get(name)
        if est is not None and not est.fixed:
            return None, "model", f"the identification did not fix {name} ({est.reason})"
        return Estimate(tip_edge, tip_edge, tip_edge), "model", ""
    ce = ident.calibration.current_edges.get(side)
    if ce is None or not ce.fixed:
        why = "did not show" if ce is None else f"did not fix ({ce.reason})"
        return None, "current", (f"the identification sweep's current {why} where the {side} tendon is taken up, "
                                 f"so an offset from that side has no reference")
    tip_est = ident.estimates.get(name)
    if ident.method == "tip" and tip_est is not None and tip_est.fixed and \
            abs(ce.value - tip_edge) > settings.max_edge_gap:
        return None, "current", (f"the sweep's current takes the {side} tendon up at {ce.value:.2f} deg, "
                                 f"{abs(ce.value - tip_edge):.2f} deg from the tip's {name} ({tip_edge:.2f}): "
                                 f"more than {settings.max_edge_gap:g} deg apart, the current and the tip model "
                                 "disagree about that edge")
    return ce, "current", ""


def reference_of(model: Model, knob: int, settings: Settings = DEFAULT, *,
                 eps_upper: float | None = None) -> Reference:
    """What a search of ``knob`` measures offsets from and how it reads the current."""
    k = int(knob)
    km = model.knob(k)
    ident = model.identification.get(k) if model.identification else None
    edges, kinds, why = {}, {}, {}
    for d in (1, -1):
        e, kind, w = _side_reference(ident, km, d, settings)
        if e is not None:
            edges[d] = e
        kinds[d], why[d] = kind, w
    cal = None if ident is None else ident.calibration
    sign = "signed" if cal is None or cal.current_sign is None else cal.current_sign
    levels = {1: None, -1: None}
    slope = 0.0
    spread = 0.0
    ripple = None
    if cal is not None:
        levels = {1: cal.edge_level_pos, -1: cal.edge_level_neg}
        slope = max(s for s in (cal.slope_loaded_pos, cal.slope_loaded_neg, 0.0) if s is not None)
        if cal.no_load_rising is not None and cal.no_load_falling is not None:
            spread = 0.5 * abs(cal.no_load_rising - cal.no_load_falling)
        ripple = cal.ripple
    if eps_upper is None and slope > 0:
        eps_upper = settings.contact_factor * slope
    dead = 0.0 if cal is None else float(cal.slope_dead_zone)
    noise = 0.0 if cal is None or cal.current_noise is None else float(cal.current_noise)
    crange = (None, None) if cal is None else (cal.current_min, cal.current_max)
    return Reference(sign=sign, edges=edges, kinds=kinds, why_not=why, edge_level=levels, slope_loaded=slope,
                     dead_slope=dead, noise=noise, eps_upper=eps_upper, ripple=ripple, at_rest_spread=spread,
                     current_range=crange)


def default_max_travel(model: Model, knob: int) -> float:
    """The travel limit of a search when none is given (deg of knob).

    Twice the largest ``|q|`` of the identification sweep plus half the dead zone's width: a bend
    moves the edges by up to the knob's own reach, and a search that starts with a tendon taut
    crosses the whole dead zone to the far edge (on a live robot the device's current ceiling and
    the contact slope stop a search that loads a tendon too far); :data:`DEFAULT_MAX_TRAVEL` when
    the model has no identification.
    """
    ident = model.identification.get(int(knob)) if model.identification else None
    if ident is None:
        return DEFAULT_MAX_TRAVEL
    reach = 2.0 * max(abs(float(ident.q_min)), abs(float(ident.q_max)))
    km = model.knob(int(knob))
    reach += 0.5 * max(km.d_pos - km.d_neg, 0.0)
    return reach if math.isfinite(reach) and reach > 0 else DEFAULT_MAX_TRAVEL


# --------------------------------------------------------------------------------------------
# the search
# --------------------------------------------------------------------------------------------
class _Limit(Exception):
    """The search can go no further this way (travel, record end)."""


@dataclass
class _Edge:
    """A declared take-up and what was read around it."""

    direction: int
    at: float
    lo: float
    hi: float
    statistic: float
    threshold: float
    level: float
    slope_before: float
    slope_after: float
    n_before: int
    n_after: int
    noise: float


@dataclass
class _Search:
    probe: Any
    ref: Reference
    settings: Settings
    step: float
    max_steps: int
    max_travel: float
    direction: int
    progress: Callable[[ProbeSample, float], None] | None = None
    start: float = 0.0
    steps: int = 0
    travel: float = 0.0
    contacts: list = field(default_factory=list)
    trace: list = field(default_factory=list)
    seg_q: list = field(default_factory=list)
    seg_c: list = field(default_factory=list)
    turned_taut: bool = False
    skipped: dict = field(default_factory=dict)
    turns: int = 0
    limits: int = 0
    seg_mark: int | None = None

    def __post_init__(self) -> None:
        self.start = float(self.probe.position())
        self.seg_mark = getattr(self.probe, "mark", None)
        self.z = NormalDist().inv_cdf(0.5 + 0.5 * self.settings.level)
        self.at_rest = not getattr(self.probe, "reads_moving", True)

    # -- readings ---------------------------------------------------------------------------
    def _reading(self, s: ProbeSample) -> float:
        c = float(s.current)
        return c - self.ref.ripple(float(s.q)) if self.ref.ripple is not None else c

    def _record(self, s: ProbeSample) -> None:
        c = self._reading(s)
        self.seg_q.append(float(s.q))
        self.seg_c.append(c)
        slope = math.nan
        if len(self.seg_q) >= 3:
            x = np.array(self.seg_q[-3:])
            if np.ptp(x) > 0:
                slope = float(np.polyfit(x, np.array(self.seg_c[-3:]), 1)[0])
        self.trace.append((float(s.q), float(s.current), slope))
        if self.progress is not None:
            self.progress(s, slope)

    def _advance(self) -> None:
        q = float(self.probe.position()) + self.direction * self.step
        if abs(q - self.start) > self.max_travel + 1e-9:
            raise _Limit(f"the travel limit ({self.max_travel:g} deg from {self.start:g})")
        if self.steps >= self.max_steps:
            raise ShiftDetectionError(f"the step limit ({self.max_steps}) was reached before an edge was found")
        try:
            s = self.probe.step_to(q)
        except ReplayExhausted as exc:
            raise _Limit(str(exc)) from None
        self.steps += 1
        self.travel += self.step
        if getattr(self.probe, "detoured", False):
            # the record took its own turn to get here: the readings before belong to another
            # pass of the knob, so the stretch starts afresh
            self.seg_q, self.seg_c = [], []
            self.seg_mark = max(getattr(self.probe, "mark", 1) - 1, 0)
        self._record(s)

    def _turn(self) -> None:
        self.direction = -self.direction
        self.turns += 1
        self.seg_q, self.seg_c = self.seg_q[-1:], self.seg_c[-1:]
        self.seg_mark = getattr(self.probe, "mark", None)

    # -- level tests ------------------------------------------------------------------------
    def _band(self, noise: float) -> float:
        """How far from the sweep's take-up level a take-up may read (mA).

        A bend moves the take-up along the knob, not the current it happens at: the readings'
        noise and the sweep's (at the settings' level), the dead zone's own tilt over the widest
        gap allowed between two readings of one edge, and, for readings taken at rest, the span of
        the motor's static friction between the two directions' levels."""
        spread = self.ref.at_rest_spread if self.at_rest else 0.0
        return (self.z * math.hypot(noise, self.ref.noise) + abs(self.ref.dead_slope) * self.settings.max_edge_gap
                + spread)

    def _load(self, c: float, d: int) -> float:
        return orientation(self.ref.sign, d) * c

    def _taut_ahead(self, c: float, d: int, noise: float) -> bool:
        """Whether a current reads past the take-up of the tendon ahead (that tendon taut)."""
        level = self.ref.edge_level.get(d)
        return level is not None and self._load(c, d) > self._load(level, d) + self._band(noise)

    # -- reading the segment ----------------------------------------------------------------
    def _read_segment(self):  # noqa: ANN202 - (_Edge or None, loading from the start)
        d = self.direction
        q = np.array(self.seg_q)
        c = np.array(self.seg_c)
        x = d * q
        order = np.argsort(x, kind="stable")
        x, c = x[order], c[order]
        if np.ptp(x) <= 0:
            return None, False
        noise = self._noise()
        fit = fit_piecewise(x, c, max_pieces=min(self.settings.max_pieces, 4), min_size=2, scale=noise, tau=1.0)
        dead, edge, _ = _classify(fit, self.ref.sign, d, self.z)
        if edge is None:
            o = orientation(self.ref.sign, d)
            rising = fit.n_knots == 0 and o * fit.slopes[0] > self.z * fit.slope_se()[0]
            return None, rising and self._taut_ahead(float(c[0]), d, noise)
        xe = fit.knots[edge]
        level = float(np.interp(xe, x, fit.fitted()))
        expected = self.ref.edge_level.get(d)
        if expected is not None and abs(self._load(level, d) - self._load(expected, d)) > self._band(noise):
            return None, False
        stat = float(profile(fit, edge, np.array([x[-1] + 1.0]))[0])
        threshold = _threshold(self.settings.false_alarm, x.size, self.max_steps, self._dof(fit))
        n_after = int(np.sum(x > xe))
        if stat <= threshold or n_after < 2:
            return None, False
        lo, hi = knot_interval(fit, edge, self.settings.chi2)
        o = orientation(self.ref.sign, d)
        slopes = o * fit.slopes
        a, b = d * lo, d * hi
        return _Edge(direction=d, at=d * xe, lo=min(a, b), hi=max(a, b), statistic=stat, threshold=threshold,
                     level=level, slope_before=float(slopes[dead]), slope_after=float(slopes[edge + 1]),
                     n_before=int(x.size - n_after), n_after=n_after, noise=noise), False

    def _noise(self) -> float:
        """Noise of one reading: from the second differences of every reading so far (a straight
        or broken line leaves them only noise, but at its few knots), never below a hundredth of
        the readings' spread."""
        c = np.array([r[1] for r in self.trace])
        if c.size < 5:
            return max(float(np.ptp(c)) if c.size else 1.0, 1e-6)
        d2 = np.diff(c, 2)
        s = float(1.4826 * np.median(np.abs(d2 - np.median(d2)))) / math.sqrt(6.0)
        return max(s, 1e-2 * float(np.ptp(c)), 1e-9)

    def _dof(self, fit) -> int:  # noqa: ANN001
        """Readings the noise estimate rests on, less what the fit spent (for the F test)."""
        return max(len(self.trace) - 2, 1)

    def _contact(self) -> bool:
        if self.ref.eps_upper is None or len(self.seg_q) < 3:
            return False
        x = np.array(self.seg_q[-3:])
        if np.ptp(x) <= 0:
            return False
        slope = float(np.polyfit(x, np.array(self.seg_c[-3:]), 1)[0])
        return orientation(self.ref.sign, self.direction) * slope * self.direction >= self.ref.eps_upper

    # -- the walk ---------------------------------------------------------------------------
    def run(self) -> _Edge:
        first = self.probe.read() if hasattr(self.probe, "read") else self.probe.step_to(self.start)
        self._record(first)
        c0 = self._reading(first)
        if self._taut_ahead(c0, self.direction, 0.0):
            self._turn()
            self.turned_taut = True
        while True:
            try:
                self._advance()
            except _Limit as why:
                self._at_limit(str(why))
                continue
            if self._contact():
                self.contacts.append(float(self.probe.position()))
                self._turn()
                continue
            if len(self.seg_q) < MIN_READINGS:
                continue
            edge, taut = self._read_segment()
            if taut and not self.turned_taut:
                self.turned_taut = True
                self._turn()
                continue
            if edge is None:
                continue
            if edge.direction not in self.ref.edges:
                self.skipped[edge.direction] = edge
                self._turn()
                continue
            return self._refine(edge)

    def _at_limit(self, why: str) -> None:
        """The first limit turns the search to the other side; the second ends it."""
        self.limits += 1
        if self.limits >= 2:
            skipped = "; ".join(f"an edge on the {'positive' if d > 0 else 'negative'} side at {e.at:.2f} deg gave no "
                                f"offset ({self.ref.why_not[d]})" for d, e in self.skipped.items())
            raise ShiftDetectionError(f"no edge that gives an offset was found within {why}"
                                      + (f" ({skipped})" if skipped else ""))
        self._turn()

    def _refine(self, edge: _Edge) -> _Edge:
        """More readings past the edge until its offset is known well enough or the search can go
        no further (a contact, a limit, the budget); each time the edge is placed again on every
        sample the probe keeps (:meth:`_read_record`), or on the readings."""
        best = self._read_record(edge)
        for _ in range(MAX_REFINE):
            if _offset_halfwidth(best, self.ref) <= self.settings.max_offset_halfwidth:
                break
            try:
                self._advance()
            except (_Limit, ShiftDetectionError):
                break
            if self._contact():
                self.contacts.append(float(self.probe.position()))
                break
            got, _ = self._read_segment()
            if got is not None and got.direction == edge.direction:
                best = self._read_record(got)
        return best

    def _read_record(self, edge: _Edge) -> _Edge:
        """The edge placed again on every sample the probe passed since the last turn, where the
        probe keeps them (a replay holds the whole record between the steps): the same broken
        line, read on all the samples instead of one median per step."""
        if self.seg_mark is None or not hasattr(self.probe, "samples_since"):
            return edge
        from ..signal.reading import bin_stretch

        q, c, t = self.probe.samples_since(self.seg_mark)
        d = edge.direction
        keep = d * np.diff(q, prepend=q[0]) >= 0
        if keep.sum() < 3 * MIN_READINGS:
            return edge
        if self.ref.ripple is not None:
            c = c - self.ref.ripple(q)
        x, y, w, _ = bin_stretch(d * q[keep], c[keep], t[keep], self.settings.filter_hz)
        order = np.argsort(x, kind="stable")
        x, y, w = x[order], y[order], w[order]
        fit = fit_piecewise(x, y, w, max_pieces=min(self.settings.max_pieces, 4))
        _, j, _ = _classify(fit, self.ref.sign, d, self.z)
        if j is None or abs(d * fit.knots[j] - edge.at) > max(edge.hi - edge.lo, 2.0 * self.step):
            return edge
        lo, hi = knot_interval(fit, j, self.settings.chi2)
        a, b = d * lo, d * hi
        if not (math.isfinite(a) and math.isfinite(b)):
            return edge
        return _Edge(direction=d, at=d * fit.knots[j], lo=min(a, b), hi=max(a, b), statistic=edge.statistic,
                     threshold=edge.threshold, level=edge.level, slope_before=edge.slope_before,
                     slope_after=edge.slope_after, n_before=edge.n_before, n_after=edge.n_after, noise=edge.noise)


def _threshold(false_alarm: float, n: int, max_steps: int, dof: int) -> float:
    """The change point's threshold at ``false_alarm`` spread (Bonferroni) over ``n`` positions of
    the knot and ``max_steps`` looks: the F(1, dof) quantile, the noise being estimated from the
    readings (``dof`` degrees of freedom; the chi-square(1) quantile as ``dof`` grows)."""
    from scipy.stats import f

    return float(f.isf(false_alarm / max(n * max_steps, 1), 1, max(dof, 1)))


def _offset_halfwidth(edge: _Edge, ref: Reference) -> float:
    lo, hi = _offset_interval(edge, ref)
    off = edge.at - ref.edges[edge.direction].value
    return max(off - lo, hi - off)


def _offset_interval(edge: _Edge, ref: Reference) -> tuple[float, float]:
    r = ref.edges[edge.direction]
    off = edge.at - r.value
    below = math.hypot(edge.at - edge.lo, r.hi - r.value)
    above = math.hypot(edge.hi - edge.at, r.value - r.lo)
    return off - below, off + above


def detect_shift(model: Model, probe: Any, knob: int | None = None, *, settings: Settings = DEFAULT,
                 eps_upper: float | None = None, step: float = 0.5, max_steps: int | None = None,
                 max_travel: float | None = None, direction: int | None = None, return_home: bool = True,
                 false_alarm: float | None = None,
                 progress: Callable[[ProbeSample, float], None] | None = None) -> ShiftResult:
    """Find the shift of one knob's dead zone from its motor current (Algorithm 1).

    Parameters
    ----------
    model : Model
        The straight-shaft model, with the identification sweep's reading of the current.
    probe : Probe, Run or path-like
        Steps the knob and reads the current (:class:`.probe.ReplayProbe`, a live device probe);
        a recorded replay (:class:`hystcli.core.run.Run`, or its CSV file) is read through a
        :class:`.probe.ReplayProbe`.
    knob : int, optional
        Default: the probe's own knob; for a replay, the one knob of the model it records; else
        the model's only knob.
    settings : Settings
        The level, the false-alarm rate, the widest offset interval returned.
    false_alarm : float, optional
        Replaces ``settings.false_alarm`` (a script need not build a :class:`Settings` for it).
    eps_upper : float, optional
        Contact slope (mA/deg); default the settings' contact factor times the sweep's loaded slope.
    step : float
        Unit step :math:`u` (deg).
    max_steps, max_travel : optional
        Step and travel limits (default: room to cross the dead zone and back; twice the sweep's
        reach, or a replay's own reach where that is more).
    direction : int, optional
        Initial direction (+1 as in the paper, or -1); default the way a replay's record goes first
        (a search the other way would walk the record through its own turn), else +1.
    return_home : bool
        Return the knob to where it began after a successful search too (a failed one always does).
    progress : callable, optional
        Called with each :class:`ProbeSample` and the slope of the last readings.

    Raises
    ------
    ShiftDetectionError
        No edge within the limits, an offset known less well than the settings allow, no side
        with a reference, a search option out of range. Every error raised during the search has
        stopped the probe and returned the knob first; its message says so.
    ParameterError
        No ``knob`` given and none to default to; ``false_alarm`` outside (0, 0.5).
    ModelError
        A knob the model does not have.
    """
    if isinstance(probe, (str, os.PathLike)):
        probe = read_run(probe)
    if false_alarm is not None:
        settings = ShiftRequest(false_alarm=false_alarm, settings=settings).options()["settings"]
    if knob is None:
        knob = _default_knob(model, probe)
    k = int(knob)
    if isinstance(probe, Run):
        probe = ReplayProbe(probe, k)
    ref = reference_of(model, k, settings, eps_upper=eps_upper)
    direction, max_travel, max_steps = _limits(model, k, probe, ref, step, max_travel, max_steps, direction)
    search = _Search(probe, ref, settings, float(step), max_steps, max_travel, direction, progress)
    start = search.start
    try:
        edge = search.run()
        _check_width(k, edge, ref, settings)
    except BaseException as exc:
        _, note = return_knob(probe, start)
        if isinstance(exc, HystError):
            raise type(exc)(f"knob {k}: {exc}; {note}" if not str(exc).startswith(f"knob {k}") else f"{exc}; {note}") \
                from exc
        if hasattr(exc, "add_note"):
            exc.add_note(note)
        raise
    returned = False
    if return_home:
        returned, note = return_knob(probe, start)
        if not returned:
            raise ShiftDetectionError(f"knob {k}: edge found at {edge.at:.2f} deg, but {note}")
    return _result(k, model.knob(k), edge, ref, search, returned, float(step))


def _default_knob(model: Model, probe: Any) -> int:
    """The knob a search without one means: the probe's, the replay's one knob, the model's only one."""
    if isinstance(probe, Run):
        knobs = select_knobs(model, None, probe)
    elif getattr(probe, "knob", None) is not None:
        return int(probe.knob)
    else:
        knobs = list(model.knobs)
    if len(knobs) != 1:
        where = "the replay records" if isinstance(probe, Run) else "the model has"
        raise ParameterError("knob", f"{where} knobs {', '.join(map(str, knobs))}: say which to search")
    return int(knobs[0])


def _limits(model: Model, k: int, probe: Any, ref: Reference, step: float, max_travel: float | None,
            max_steps: int | None, direction: int | None) -> tuple[int, float, int]:
    """The search's first direction, travel limit and step limit, checked."""
    user_direction = direction is not None
    if direction is None:
        direction = int(getattr(probe, "first_direction", 1))
    if max_travel is None:
        # a replay's record was driven already: its own reach is no risk
        max_travel = max(default_max_travel(model, k), float(getattr(probe, "reach", 0.0)))
    max_travel = float(max_travel)
    _check_options(step, max_travel, max_steps, direction)
    if not ref.edges:
        raise ShiftDetectionError(f"knob {k}: no offset can be taken from either side: "
                                  + "; ".join(ref.why_not[d] for d in (1, -1) if ref.why_not[d]))
    if max_steps is None:
        max_steps = 3 * int(math.ceil(max_travel / step - 1e-9)) + 2 * MIN_READINGS
    if direction not in ref.edges and not hasattr(probe, "first_direction") and not user_direction:
        direction = -direction
    return int(direction), max_travel, int(max_steps)


def _check_width(k: int, edge: _Edge, ref: Reference, settings: Settings) -> None:
    """Refuse an offset known less well than the settings allow (it would move the robot)."""
    off_lo, off_hi = _offset_interval(edge, ref)
    offset = edge.at - ref.edges[edge.direction].value
    if max(offset - off_lo, off_hi - offset) > settings.max_offset_halfwidth:
        raise ShiftDetectionError(
            f"knob {k}: the tendon is taken up at {edge.at:.2f} deg [{edge.lo:.2f}, {edge.hi:.2f}], giving an "
            f"offset of {offset:+.2f} deg known only to [{off_lo:+.2f}, {off_hi:+.2f}] at "
            f"{settings.level:.0%}, wider than +-{settings.max_offset_halfwidth:g} deg: the current does not "
            "place the edge well enough to move the robot by it")


def _result(k: int, km: Any, edge: _Edge, ref: Reference, search: _Search, returned: bool, step: float) -> ShiftResult:
    off_lo, off_hi = _offset_interval(edge, ref)
    offset = edge.at - ref.edges[edge.direction].value
    d = edge.direction
    ev = Evidence(statistic=edge.statistic, threshold=edge.threshold, edge_lo=edge.lo, edge_hi=edge.hi,
                  level=edge.level, expected_level=ref.edge_level.get(d), slope_before=edge.slope_before,
                  slope_after=edge.slope_after, n_before=edge.n_before, n_after=edge.n_after, noise=edge.noise)
    return ShiftResult(knob=k, offset=float(offset), offset_lo=float(off_lo),
                       offset_hi=float(off_hi), d_pos=float(km.d_pos + offset), d_neg=float(km.d_neg + offset),
                       edge="pos" if d > 0 else "neg", edge_found_at=float(edge.at), direction=d,
                       reference=ref.kinds[d], start=search.start, travel=float(search.travel), steps=search.steps,
                       contacts=tuple(search.contacts), start_outside=search.turned_taut, returned=returned,
                       step=step, evidence=ev, trace=tuple(search.trace))


def _check_options(step: float, max_travel: float, max_steps: int | None, direction: int) -> None:
    if not (math.isfinite(step) and step > 0):
        raise ShiftDetectionError(f"the unit step must be a positive number of degrees, got {step}")
    if not (math.isfinite(max_travel) and max_travel > 0):
        raise ShiftDetectionError(f"the travel limit must be a positive number of degrees, got {max_travel}")
    if max_steps is not None and int(max_steps) < 1:
        raise ShiftDetectionError(f"the step limit must be at least 1, got {max_steps}")
    if direction not in (1, -1):
        raise ShiftDetectionError(f"direction must be +1 or -1, got {direction}")


def detect_shifts(model: Model, probes: Mapping[int, Any], **options: Any) -> dict[int, ShiftResult]:
    """:func:`detect_shift` on several knobs, one after the other (knob order)."""
    return {k: detect_shift(model, probes[k], k, **options) for k in sorted(probes)}


def apply_shift(model: Model, results: Mapping[int, ShiftResult] | Any, *, source: str | None = None,
                sha256: str | None = None) -> Model:
    """The model with each detected knob's ``offset`` set (absolute), others unchanged.

    Parameters
    ----------
    model : Model
    results : mapping of knob to ShiftResult, or iterable of ShiftResult
    source : str, optional
        Where the shift was found (a replay's file name, ``live:PORT``): kept in the model's
        metadata as ``shift_source``, so a shifted model says what it was shifted by.
    sha256 : str, optional
        The replay file's SHA-256, kept as ``shift_sha256``.
    """
    items = results.values() if isinstance(results, Mapping) else results
    shifted = model.with_offsets({r.knob: r.offset for r in items})
    if source is None and sha256 is None:
        return shifted
    meta = dict(shifted.meta)
    if source is not None:
        meta["shift_source"] = source
    if sha256 is not None:
        meta["shift_sha256"] = sha256
    return replace(shifted, meta=meta)
