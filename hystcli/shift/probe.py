"""What Algorithm 1 steps and reads: a probe (a recorded replay, or a live knob) and its samples.

:class:`Probe` is the protocol; :class:`ReplayProbe` walks a recorded run as if its knob were
stepped; ``hystcli.device.DeviceProbe`` drives a live robot. :func:`return_knob` brings a knob
back to where a search began, whatever happened.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from ..core.run import Run
from ..errors import DataError, ShiftDetectionError

__all__ = ["Probe", "ProbeSample", "ReplayExhausted", "ReplayProbe", "return_knob"]


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
        self._t = np.asarray(run["t"], dtype=float) if "t" in run else np.arange(self._q.size, dtype=float)
        self._y = np.asarray(run[yn], dtype=float) if yn in run else None
        dq = np.abs(np.diff(self._q))
        self._path = np.concatenate([[0.0], np.cumsum(dq)])
        self._i = 0          # segment [i, i+1] of the record that holds the present position
        self._frac = 0.0     # where in that segment
        self._pos = float(self._q[0])
        self._unit = None    # the last step length, the averaging span
        self.start = self._pos
        self.reads_moving = True
        self.detoured = False
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
        before = self.recorded_travel
        self._i, self._frac, self._pos = j, float(frac), target
        # the record went elsewhere and came back (its own turn) between the two positions: the
        # state the knob reached here is not the one the last reading left
        self.detoured = self.recorded_travel - before > 1.5 * unit + 1e-9
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

    @property
    def reach(self) -> float:
        """How far from where it starts the record takes the knob (deg): every angle it visits
        was already driven, so a search over it risks nothing the record did not."""
        return float(np.max(np.abs(self._q - self._q[0])))

    @property
    def mark(self) -> int:
        """Where in the record the walk stands (for :meth:`samples_since`)."""
        return self._i

    def samples_since(self, mark: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The recorded samples ``(q, current, t)`` the walk has passed since ``mark``: a replay
        holds every sample between the steps, which a search may read in full."""
        j = self._i + 1
        return self._q[mark:j].copy(), self._c[mark:j].copy(), self._t[mark:j].copy()

    def _sample_here(self) -> ProbeSample:
        i, f = self._i, self._frac
        c = self._c[i] + f * (self._c[i + 1] - self._c[i])
        tip = None if self._y is None else float(self._y[i] + f * (self._y[i + 1] - self._y[i]))
        return ProbeSample(self._pos, float(c), tip)


def return_knob(probe: Any, start: float) -> tuple[bool, str]:
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
