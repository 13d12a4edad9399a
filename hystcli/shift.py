"""Algorithm 1 of the paper (gradient-based shift detection) over a probe, and its result.

This module owns the search for the shifted dead zone :math:`\\tilde D_{pos}, \\tilde D_{neg}`
of one knob after the shaft took an unknown shape (paper section II-C, Algorithm 1 and the
Discussion; DESIGN.md section 5): step the knob by ``direction * u``, watch the slope of the
motor current :math:`\\nabla C = dC/dq`, reverse on a contact (:math:`\\nabla C \\ge
\\epsilon_{upper}`), stop at the first dead-zone edge (:math:`\\nabla C \\ge \\epsilon_{lower}`),
and report ``offset = q - D_pos`` (moving positive) or ``q - D_neg`` (moving negative).

One algorithm, several sources. The algorithm talks to a :class:`Probe` (step the knob, read the
current); :class:`ReplayProbe` walks a recorded run, ``hystcli.device.DeviceProbe`` drives a
live robot over a serial port. Both return :class:`ProbeSample`.

Beyond the paper's pseudo-code, the search:

* measures the slope over a small window of recent steps (least squares), reset at every
  direction change so that the Coulomb-friction jump of the motor at a reversal is never read
  as an edge;
* locates the edge it stopped at by fitting a hinge (flat then sloped, or sloped then flat) to
  the steps around it, so the reported edge is where the slope changes, not where the window's
  slope happened to cross the threshold (the window delays a threshold crossing by about half
  its width; the hinge fit removes that delay and the symmetric smoothing of the 20 Hz filter);
* handles a start outside the new dead zone (a tendon already taut at the first steps): it
  tells which tendon from the current level against the dead-zone level ``current_dead_zone``
  (the motor current is signed: above the level, the positive tendon pulls), moves toward the
  dead zone and takes the edge where the slope falls below :math:`\\epsilon_{lower}`;
* never exceeds its step and travel limits (raises :class:`ShiftDetectionError` rather than
  inventing an offset) and, on any failure or interruption, stops the probe and returns the
  knob to where it began.

The motor current is signed (see ``hystcli.twin``): past either edge ``dC/dq > 0`` whichever
way the knob moves, so the slope along the motion is ``dC/dq`` with ``dq`` signed.
"""
from __future__ import annotations

import io as _io
import math
import os
from dataclasses import dataclass, field
from typing import Any, Callable, Iterable, Mapping, Protocol, Sequence

import numpy as np

from .errors import DataError, HystError, ShiftDetectionError
from .io import Run, atomic_write
from .model import KnobModel, Model

LOCAL_SPAN = 4.0  # steps kept on the loaded side of a kink when refitting it (see _Search._fit)
RISE = "rise"
"""The slope rose through eps_lower: the knob left the dead zone (the paper's case)."""
FALL = "fall"
"""The slope fell below eps_lower: the knob entered the dead zone (a start outside it)."""


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

    The current of a step is what a stepping motor measures while it moves: the mean of the
    recorded current over the samples the knob passed during the last ``u`` of its approach to
    ``q`` (one unit step), and the sample's ``q`` is the mean knob angle of those samples. That
    mean is unbiased on the linear pieces of the current (its position is where it was measured)
    and smooths a kink symmetrically, so the edge fit stays unbiased. With ``average=False`` the
    current is read (linearly interpolated) at exactly ``q``.

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
            tip = float(np.mean(np.append(self._y[lo:j + 1][keep], tip_end)))
        return ProbeSample(float(np.mean(qs)), float(np.mean(cs)), tip)

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
    """The gradient bounds of Algorithm 1 for one knob, and the dead-zone current level.

    Attributes
    ----------
    eps_lower : float
        :math:`\\epsilon_{lower}` (mA/deg): a slope at or above it means a tendon is taut.
    eps_upper : float
        :math:`\\epsilon_{upper}` (mA/deg): a slope at or above it means contact with a wall.
    current_dead_zone : float or None
        Motor current with no tendon taut (mA), to tell which tendon is taut at a start
        outside the dead zone.
    """

    eps_lower: float
    eps_upper: float
    current_dead_zone: float | None = None


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
    if not eps_upper > eps_lower:
        raise ShiftDetectionError(f"eps_upper must be greater than eps_lower "
                                  f"(got eps_lower = {eps_lower:g}, eps_upper = {eps_upper:g})")
    if current_dead_zone is not None and not math.isfinite(current_dead_zone):
        raise ShiftDetectionError(f"current_dead_zone must be finite, got {current_dead_zone}")
    return Thresholds(float(eps_lower), float(eps_upper),
                      None if current_dead_zone is None else float(current_dead_zone))


# --------------------------------------------------------------------------------------------
# result
# --------------------------------------------------------------------------------------------
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
        Knob angle of that edge (deg), from the hinge fit.
    direction : int
        Direction of motion when it was found (+1 or -1).
    transition : str
        ``"rise"`` (left the dead zone, the paper's case) or ``"fall"`` (entered it from a start
        outside).
    start : float
        Knob angle where the search began and where the knob was returned (deg).
    travel : float
        Knob travel of the search (deg), the return excluded.
    steps : int
        Steps taken.
    contacts : tuple of float
        Knob angles where a contact made the search reverse.
    start_outside : bool
        The search began with a tendon already taut.
    returned : bool
        The knob was returned to ``start`` after the search.
    eps_lower, eps_upper, step : float
        The thresholds (mA/deg) and unit step (deg) used.
    trace : tuple of (q, current, slope)
        Every step: knob angle (deg), current (mA), window slope (mA/deg, NaN before the window
        is full), for plotting (the paper's Fig. 5b).
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
    eps_lower: float = math.nan
    eps_upper: float = math.nan
    step: float = math.nan
    trace: tuple[tuple[float, float, float], ...] = field(default=(), repr=False)

    def to_dict(self, trace: bool = False) -> dict:
        """Plain JSON-ready dict (the trace only when asked; NaN slopes as null)."""
        out = {
            "knob": self.knob, "offset": self.offset, "d_pos": self.d_pos, "d_neg": self.d_neg,
            "edge": self.edge, "edge_found_at": self.edge_found_at, "direction": self.direction,
            "transition": self.transition, "start": self.start, "travel": self.travel,
            "steps": self.steps, "contacts": list(self.contacts),
            "start_outside": self.start_outside, "returned": self.returned,
            "eps_lower": self.eps_lower, "eps_upper": self.eps_upper, "step": self.step,
        }
        if trace:
            out["trace"] = [[q, c, None if math.isnan(s) else s] for q, c, s in self.trace]
        return out


# --------------------------------------------------------------------------------------------
# helpers of the search
# --------------------------------------------------------------------------------------------
def _ls_slope(q: np.ndarray, c: np.ndarray) -> float:
    """Least-squares slope dC/dq."""
    qm = q - q.mean()
    den = float(qm @ qm)
    return float(qm @ (c - c.mean()) / den) if den > 0 else math.nan


_MIN_SIDE = 3  # samples on each side of a kink: two points always make a line, three may not
_MAX_EXTENSIONS = 3  # times a fit may ask for more steps past a kink it found at the last ones


@dataclass(frozen=True)
class _Hinge:
    edge: float      # knob angle of the kink (deg)
    before: float    # dC/dq before the kink along the motion
    after: float     # dC/dq after it
    at_end: bool = False  # the kink sits at the last place the fit allows: too few steps after it


def _hinge_fit(q: np.ndarray, c: np.ndarray, direction: int, resolution: float) -> _Hinge | None:
    """Best two-piece continuous line through ``(q, c)`` taken in the order of the motion.

    The kink is searched on a grid of ``resolution`` deg with at least ``_MIN_SIDE`` samples on either
    side; the two slopes and the level are linear least squares at each candidate.
    """
    x = direction * np.asarray(q, float)
    c = np.asarray(c, float)
    if x.size < 2 * _MIN_SIDE:
        return None
    lo, hi = x[_MIN_SIDE - 1], x[-_MIN_SIDE]
    if not hi > lo:
        return None
    grid = np.arange(lo, hi + 0.5 * resolution, resolution)
    # design matrices of every candidate at once: (G, n, 3)
    dx = x[None, :] - grid[:, None]
    a = np.stack([np.ones_like(dx), np.minimum(dx, 0.0), np.maximum(dx, 0.0)], axis=-1)
    ata = np.einsum("gni,gnj->gij", a, a)
    atc = np.einsum("gni,n->gi", a, c)
    ok = np.abs(np.linalg.det(ata)) > 1e-12
    if not ok.any():
        return None
    beta = np.zeros((grid.size, 3))
    beta[ok] = np.linalg.solve(ata[ok], atc[ok][..., None])[..., 0]
    resid = c[None, :] - np.einsum("gni,gi->gn", a, beta)
    sse = np.where(ok, np.einsum("gn,gn->g", resid, resid), np.inf)
    g = int(np.argmin(sse))
    # slopes along x are dC/dx; dC/dq = direction * dC/dx
    return _Hinge(edge=float(direction * grid[g]), before=float(direction * beta[g, 1]),
                  after=float(direction * beta[g, 2]), at_end=g == grid.size - 1)


class _LimitReached(Exception):
    def __init__(self, why: str) -> None:
        super().__init__(why)
        self.why = why


class _Found(Exception):
    def __init__(self, hinge: _Hinge, transition: str) -> None:
        super().__init__(transition)
        self.hinge = hinge
        self.transition = transition


# search phases
_SEEK_RISE = "seek-rise"          # in the dead zone, moving toward an edge
_SEEK_FALL = "seek-fall"          # a tendon taut since the start, moving toward the dead zone
_LEAVE_CONTACT = "leave-contact"  # backing away from a wall toward the dead zone


class _Search:
    """The state of one run of Algorithm 1 (see :func:`detect_shift`)."""

    def __init__(self, probe: Any, knob: int, th: Thresholds, step: float, max_steps: int,
                 max_travel: float, window: int, confirm_steps: int, direction: int,
                 level_margin: float, progress: Callable[[ProbeSample, float], None] | None) -> None:
        self.probe, self.knob, self.th = probe, knob, th
        self.u, self.max_steps, self.max_travel = step, max_steps, max_travel
        self.window, self.confirm = window, confirm_steps
        self.fit_len = 3 * window
        self.local_span = LOCAL_SPAN
        self.dir = direction
        self.margin = level_margin
        self.progress = progress
        self.start = float(probe.position())
        self.q = self.start
        self.steps = 0
        self.travel = 0.0
        self.seg_q: list[float] = []
        self.seg_c: list[float] = []
        self.seg_from_start = True   # the present segment began where the search began
        self.phase = _SEEK_RISE
        self.contacts: list[float] = []
        self.start_outside = False
        self.ambiguous = False       # the start's current level did not say which tendon is taut
        self.first_window_trigger = False
        self.trace: list[tuple[float, float, float]] = []

    # -- moving -------------------------------------------------------------------------------
    def _step(self) -> tuple[float, float]:
        """One unit step; returns (window slope, step slope) of the present segment."""
        if self.travel + self.u > self.max_travel + 1e-9:
            raise _LimitReached(f"the travel limit is {self.max_travel:g} deg")
        if self.steps >= self.max_steps:
            raise _LimitReached(f"the step limit is {self.max_steps}")
        target = self.q + self.dir * self.u
        try:
            s = self.probe.step_to(target)
        except ReplayExhausted as exc:
            raise _LimitReached(str(exc)) from None
        self.steps += 1
        self.travel += abs(target - self.q)
        self.q = target
        qs, cs = float(s.q), float(s.current)
        if not (math.isfinite(qs) and math.isfinite(cs)):
            raise ShiftDetectionError(f"knob {self.knob}: the probe reported a non-finite reading "
                                      f"(q = {s.q!r}, current = {s.current!r}) at {target:.2f} deg")
        self.seg_q.append(qs)
        self.seg_c.append(cs)
        n = len(self.seg_q)
        w = math.nan
        if n >= self.window:
            w = _ls_slope(np.array(self.seg_q[-self.window:]), np.array(self.seg_c[-self.window:]))
        step_slope = math.nan
        if n >= 2 and self.seg_q[-1] != self.seg_q[-2]:
            step_slope = (self.seg_c[-1] - self.seg_c[-2]) / (self.seg_q[-1] - self.seg_q[-2])
        self.trace.append((qs, cs, w))
        if self.progress is not None:
            self.progress(s, w)
        return w, step_slope

    def _reverse(self) -> None:
        # a new segment: the motor's Coulomb friction jumps at a reversal, and no slope may span it
        self.dir = -self.dir
        self.seg_q, self.seg_c = [], []
        self.seg_from_start = False

    def _contact(self) -> None:
        self.contacts.append(self.q)
        if len(self.contacts) > 1:
            raise ShiftDetectionError(
                f"knob {self.knob}: contact in both directions (at {self.contacts[0]:.2f} and "
                f"{self.contacts[1]:.2f} deg): no free side to find a dead-zone edge")
        self._reverse()
        self.phase = _LEAVE_CONTACT

    def _fit(self) -> _Hinge | None:
        q = np.array(self.seg_q[-self.fit_len:])
        c = np.array(self.seg_c[-self.fit_len:])
        h = _hinge_fit(q, c, self.dir, resolution=self.u / 25.0)
        if h is None or h.at_end or self.local_span is None:
            return h
        # Refit with the loaded side cut to the steps near the kink: the dead-zone side is flat
        # (no tendon taut) and every step of it helps, but the loaded side bends while the sheath
        # friction builds up after a start or a reversal, and a bent piece pulls the kink.
        for _ in range(3):  # recentre: each refit moves the kink, and with it the cut
            x = self.dir * (q - h.edge)
            loaded_side = x > 0 if h.after >= h.before else x < 0
            keep = ~loaded_side | (np.abs(x) <= self.local_span * self.u)
            if keep.sum() < 2 * _MIN_SIDE or keep.all():
                break
            h2 = _hinge_fit(q[keep], c[keep], self.dir, resolution=self.u / 25.0)
            if h2 is None:
                break
            moved = abs(h2.edge - h.edge)
            h = h2
            if moved < 1e-9:
                break
        return h

    # -- deciding -----------------------------------------------------------------------------
    def _start_outside(self) -> None:
        """A tendon is taut from the first steps: turn toward the dead zone."""
        cdz = self.th.current_dead_zone
        if cdz is None:
            raise ShiftDetectionError(
                f"knob {self.knob} is loaded from the first steps (a tendon is already taut at "
                f"{self.start:g} deg) and the model has no dead-zone current level to tell which "
                "one: give --current-dead-zone (or identify the model with `hyst identify`)")
        level = float(np.mean(self.seg_c[:self.window]))
        taut_side = 1 if level > cdz else -1          # signed current: above the level, + pulls
        self.ambiguous = abs(level - cdz) < self.margin
        self.start_outside = True
        self.phase = _SEEK_FALL
        if -taut_side != self.dir:
            self._reverse()

    def _level_says_taut(self) -> bool:
        cdz = self.th.current_dead_zone
        return cdz is not None and abs(float(np.mean(self.seg_c[:self.window])) - cdz) >= self.margin

    def _wrong_way(self) -> bool:
        """An ambiguous start turned the wrong way: the current left the dead-zone level."""
        cdz = self.th.current_dead_zone
        if not self.ambiguous or cdz is None or len(self.seg_c) < 2:
            return False
        level = 0.5 * (self.seg_c[-1] + self.seg_c[-2])
        return self.dir * (level - cdz) > self.margin

    def _evaluate(self) -> bool:
        """After a trigger and its confirming steps: classify the kink by a hinge fit.

        Returns True when the fit needs more steps (the kink is at the end of the steps).
        """
        eps = self.th.eps_lower
        h = self._fit()
        if h is None:
            return False
        n_after = int(np.sum(self.dir * (np.array(self.seg_q) - h.edge) > 0))
        if h.at_end or n_after < max(self.confirm, _MIN_SIDE):
            # too few steps past the kink to place it: take more before deciding
            return True
        rise = h.before < eps <= h.after
        fall = h.before >= eps > h.after
        loaded = h.before >= eps and h.after >= eps
        flat = h.before < eps and h.after < eps
        if self.phase == _SEEK_RISE:
            if h.after >= self.th.eps_upper:
                self._contact()
            elif rise:
                raise _Found(h, RISE)
            elif fall and self.first_window_trigger:
                # the first window was loaded and the slope has fallen since: the search began
                # with a tendon taut and has already entered the dead zone
                self.start_outside = True
                raise _Found(h, FALL)
            elif loaded and self.first_window_trigger:
                self._start_outside()
        elif self.phase == _SEEK_FALL:
            if fall:
                raise _Found(h, FALL)
            if flat:
                # already inside the dead zone (the fall came before the window filled):
                # go on to the far edge
                self._restart_segment_at(None)
                self.phase = _SEEK_RISE
        elif self.phase == _LEAVE_CONTACT:
            if fall or flat:
                # off the wall and back in the dead zone: search the other edge (paper, Discussion)
                self._restart_segment_at(h.edge if fall else None)
                self.phase = _SEEK_RISE

    def _restart_segment_at(self, edge: float | None) -> None:
        q, c = np.array(self.seg_q), np.array(self.seg_c)
        keep = (self.dir * (q - edge) > 0) if edge is not None else np.arange(q.size) >= q.size - self.window
        self.seg_q, self.seg_c = list(q[keep]), list(c[keep])
        self.seg_from_start = False

    def _triggered(self, w: float) -> bool:
        if math.isnan(w):
            return False
        if self.phase == _SEEK_RISE:
            return w >= self.th.eps_lower
        return w < self.th.eps_lower

    # -- the loop -----------------------------------------------------------------------------
    def run(self) -> tuple[_Hinge, str]:
        pending = 0
        extensions = 0
        while True:
            try:
                w, step_slope = self._step()
            except _LimitReached as lim:
                if pending:
                    try:
                        self._evaluate()
                    except _Found as f:
                        return f.hinge, f.transition
                raise ShiftDetectionError(
                    f"knob {self.knob}: no edge found within {self.steps} steps / "
                    f"{self.travel:.1f} deg of knob travel ({lim.why})") from None
            try:
                if self.phase != _LEAVE_CONTACT and step_slope >= self.th.eps_upper:
                    self._contact()
                    pending = 0
                    continue
                if self.phase == _SEEK_FALL and self._wrong_way():
                    self.ambiguous = False
                    self._reverse()
                    pending = 0
                    continue
                if pending:
                    pending -= 1
                    if pending == 0 and self._evaluate() and extensions < _MAX_EXTENSIONS:
                        extensions += 1
                        pending = _MIN_SIDE - 1
                    continue
                if (self.phase == _SEEK_RISE and self.seg_from_start and len(self.seg_q) == self.window
                        and w >= self.th.eps_lower and self._level_says_taut()):
                    # loaded from the first steps and the current level is clearly off the
                    # dead-zone level: a tendon is taut, no need to confirm before turning
                    self._start_outside()
                    continue
                if self._triggered(w):
                    # the first full window already loaded: a tendon may be taut since the start
                    self.first_window_trigger = self.seg_from_start and len(self.seg_q) == self.window
                    # entering the dead zone loads nothing: confirm a fall (possible after a
                    # first loaded window too) over more steps
                    pending = self.confirm
                    if self.phase != _SEEK_RISE or self.first_window_trigger:
                        pending += 2
                    extensions = 0
                    if pending == 0 and self._evaluate():
                        pending = _MIN_SIDE - 1
                        extensions = 1
            except _Found as f:
                return f.hinge, f.transition


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

    The largest ``|q|`` of the identification sweep (``KnobIdentification.q_min``/``q_max``):
    the knob has already been driven that far on this catheter, and a search from the middle
    reaches every edge inside it (a dead zone of +-19 deg shifted by 27 deg lies within the
    paper's +-40 deg sweep); :data:`DEFAULT_MAX_TRAVEL` when the model has no identification.
    """
    ident = model.identification.get(int(knob)) if model.identification else None
    if ident is None:
        return DEFAULT_MAX_TRAVEL
    reach = max(abs(float(ident.q_min)), abs(float(ident.q_max)))
    return reach if math.isfinite(reach) and reach > 0 else DEFAULT_MAX_TRAVEL


def detect_shift(model: Model, probe: Any, knob: int = 1, *, eps_lower: float | None = None,
                 eps_upper: float | None = None, current_dead_zone: float | None = None,
                 step: float = 0.5, max_steps: int | None = None, max_travel: float | None = None,
                 window: int = 6, confirm_steps: int = 4, direction: int = 1,
                 level_margin: float | None = None, return_home: bool = True,
                 progress: Callable[[ProbeSample, float], None] | None = None) -> ShiftResult:
    """Find the shift of one knob's dead zone by the slope of its motor current (Algorithm 1).

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
        Current with no tendon taut (mA); default: the model's identification. Needed only
        when the search starts with a tendon taut.
    step : float
        Unit step :math:`u` (deg).
    max_steps : int, optional
        Step limit; default ``ceil(max_travel / step)``.
    max_travel : float, optional
        Travel limit of the search (deg of knob, every step counted, the return excluded);
        default :func:`default_max_travel` (the identification sweep's reach).
    window : int
        Steps in the least-squares slope window (reset at every reversal).
    confirm_steps : int
        Extra steps taken after the window slope crosses a threshold, so the hinge fit that
        places the edge sees both sides of it.
    direction : int
        Initial direction (+1 as in the paper, or -1).
    level_margin : float, optional
        How far (mA) from ``current_dead_zone`` the current must be to tell which tendon is
        taut at a start outside the dead zone; default ``0.6 * eps_upper`` (3 deg of loaded
        slope with the default thresholds), above the motor's Coulomb friction. Closer starts
        go in ``direction`` and turn back if the current moves away from the level by more.
    return_home : bool
        Return the knob to where it began after a successful search too (a failed one always
        returns it).
    progress : callable, optional
        Called with each :class:`ProbeSample` and the window slope (NaN before it is full).

    Returns
    -------
    ShiftResult

    Raises
    ------
    ShiftDetectionError
        No edge within the limits ("no edge found within N steps / X deg of knob travel"),
        contact on both sides, a missing threshold, invalid options. Every error raised during
        the search (from the probe too) has stopped the probe and returned the knob first; its
        message says so.
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
        max_steps = int(math.ceil(max_travel / step - 1e-9))
    if int(max_steps) < 1:
        raise ShiftDetectionError(f"the step limit must be at least 1, got {max_steps}")
    if int(window) < 3:
        raise ShiftDetectionError(f"the slope window must hold at least 3 steps, got {window}")
    if int(confirm_steps) < 0:
        raise ShiftDetectionError(f"confirm_steps must be >= 0, got {confirm_steps}")
    if direction not in (1, -1):
        raise ShiftDetectionError(f"direction must be +1 or -1, got {direction}")
    margin = 0.6 * th.eps_upper if level_margin is None else float(level_margin)

    search = _Search(probe, k, th, float(step), int(max_steps), float(max_travel), int(window),
                     int(confirm_steps), int(direction), margin, progress)
    start = search.start
    try:
        hinge, transition = search.run()
    except BaseException as exc:
        returned, note = _return_knob(probe, start)
        if isinstance(exc, HystError):
            try:
                new = type(exc)(f"{exc}; {note}")
            except Exception:  # noqa: BLE001 - an error type with another signature
                new = ShiftDetectionError(f"{exc}; {note}")
            raise new from exc
        exc.add_note(note)
        raise
    returned = False
    if return_home:
        returned, note = _return_knob(probe, start)
        if not returned:
            raise ShiftDetectionError(f"knob {k}: edge found at {hinge.edge:.2f} deg, but {note}")
    d = search.dir
    if transition == RISE:
        edge = "pos" if d > 0 else "neg"
    else:
        # entering the dead zone moving + crosses its negative edge, moving - its positive one
        edge = "neg" if d > 0 else "pos"
    offset = hinge.edge - (km.d_pos if edge == "pos" else km.d_neg)
    return ShiftResult(
        knob=k, offset=float(offset), d_pos=float(km.d_pos + offset), d_neg=float(km.d_neg + offset),
        edge=edge, edge_found_at=float(hinge.edge), direction=int(d), transition=transition,
        start=start, travel=float(search.travel), steps=int(search.steps),
        contacts=tuple(float(c) for c in search.contacts), start_outside=search.start_outside,
        returned=returned, eps_lower=th.eps_lower, eps_upper=th.eps_upper, step=float(step),
        trace=tuple(search.trace))


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
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    results = list(results)
    if not results:
        raise ShiftDetectionError("nothing to plot: no knob was searched")
    fig, axes = plt.subplots(1, len(results), figsize=(5.5 * len(results), 4.0), squeeze=False)
    try:
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
        buf = _io.BytesIO()
        fig.savefig(buf, format="png", dpi=110)
    finally:
        plt.close(fig)
    data = buf.getvalue()
    atomic_write(path, lambda f: f.write(data), inputs=inputs)


def _sorted(q: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    order = np.argsort(q, kind="stable")
    return q[order], c[order]
