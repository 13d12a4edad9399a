"""The limits of a commanded knob trajectory, checked before anything moves.

A knob command file (``hyst compensate``'s output, ``hyst sweep``'s, a user's own) can ask a
motor for what it cannot or must not do: a non-finite angle, an angle past the knob's travel,
or a step too fast for one sample. The inverse model does the last by design: where the tip
must cross a flat part of the loop, the command jumps across it within one sample: across the
dead zone when the desired tip angle passes the dead-zone height (about 39 deg on the sample
data's shifted model: 3942 deg/s at 100 Hz), across the backlash plateau where it reverses
(about 10 deg on the calibrated catheters). This module
measures what a trajectory asks for (range, peak speed and acceleration per knob, with where
they occur) and compares it with :class:`Limits`, so that ``compensate`` can say it and refuse
it, and ``play`` (any command that moves a knob) can refuse a file *before its first MOVE*
rather than fail at the bad row with the catheter half-way.

What to do with a step beyond the speed (or acceleration) limit is the caller's choice among
:data:`SPEED_MODES`: refuse the trajectory (``strict``), send it as it is (``fast``: a player sends
the step at the speed limit and the knob arrives late), or rate-limit it (``limit``): the
:class:`RateLimiter` moves the knob toward the asked command at the limit, causally, and lands on
it again as soon as the limits allow; :class:`CatchUp` says for how long the knob lagged.
:func:`plan_motion` applies the choice to a whole trajectory.

It owns no device I/O; :mod:`hystcli.device.robot` applies it on a live device.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Mapping

from .errors import DataError, SafetyStop

DEFAULT_TRAVEL = 180.0
"""Default largest |knob angle| (deg): half a turn each way. Every command of the paper's
protocol stays inside it (the compensated 60 deg reference on the alpha=90 shape reaches about
+102 deg on the calibrated catheters), and the emulator's own limit (170 deg) is tighter still."""

DEFAULT_MAX_SPEED = 360.0
"""Default peak knob speed (deg/s): one knob turn per second. The paper's motions need at most
40 deg/s (the identification sweep; the compensated references about 12 deg/s away from their
reversals), and a geared knob motor of a catheter handle does a few hundred deg/s. What exceeds
it is the inverse model's jump across the dead zone or the backlash (up to ~40 deg in one
sample): a motor at this speed crosses such a jump in about 0.1 s instead of one sample, while
the tip rests on the flat part the jump crosses."""

DEFAULT_MOVE_SPEED = 20.0
"""Speed (deg/s) of the untimed moves: to a trajectory's first command, home, back to the start
after an abort. Slow enough to watch and to stop by hand, and the emulator's default speed."""


@dataclass(frozen=True)
class Limits:
    """What a commanded knob trajectory may ask of a motor.

    Attributes
    ----------
    travel : float
        Largest |knob angle| (deg), measured from the knob's zero (its straight-shaft rest).
    max_speed : float
        Largest knob speed between consecutive samples (deg/s).
    max_accel : float or None
        Largest knob acceleration (deg/s^2); None: measured and reported, not checked.

    Raises
    ------
    DataError
        A limit that is not a positive finite number.
    """

    travel: float = DEFAULT_TRAVEL
    max_speed: float = DEFAULT_MAX_SPEED
    max_accel: float | None = None

    def __post_init__(self) -> None:
        for name in ("travel", "max_speed", "max_accel"):
            value = getattr(self, name)
            if value is None and name == "max_accel":
                continue
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise DataError(f"the {name.replace('_', ' ')} limit must be a positive number, "
                                f"got {value!r}")
            object.__setattr__(self, name, float(value))

    def tightened(self, travel: float | None = None, max_speed: float | None = None) -> "Limits":
        """These limits, made no looser than a device's own (``None``: the device gives none)."""
        return Limits(self.travel if travel is None else min(self.travel, travel),
                      self.max_speed if max_speed is None else min(self.max_speed, max_speed),
                      self.max_accel)

    def to_dict(self) -> dict[str, float | None]:
        return {"travel": self.travel, "max_speed": self.max_speed, "max_accel": self.max_accel}


@dataclass(frozen=True)
class KnobMotion:
    """What one knob's command trajectory asks for.

    Attributes
    ----------
    knob : int
    samples : int
    q_min, q_max : float
        Range of the commands (deg).
    peak_speed : float
        Largest ``|q[i+1] - q[i]| / (t[i+1] - t[i])`` (deg/s): the speed a player sends to
        cover that step in its sample interval.
    peak_speed_t : float
        Time of the step's start (s).
    peak_speed_row : int
        Index of the step's start (0-based data row).
    peak_accel : float
        Largest |change of that speed| per the time between the two steps' midpoints (deg/s^2);
        0 with fewer than 3 samples.
    peak_accel_t : float
        Time of the sample between the two steps (s).
    """

    knob: int
    samples: int
    q_min: float
    q_max: float
    peak_speed: float
    peak_speed_t: float
    peak_speed_row: int
    peak_accel: float
    peak_accel_t: float

    @property
    def peak_angle(self) -> float:
        """The largest |command| (deg)."""
        return max(abs(self.q_min), abs(self.q_max))

    def to_dict(self) -> dict[str, float | int]:
        return {"knob": self.knob, "samples": self.samples, "q_min": self.q_min,
                "q_max": self.q_max, "peak_speed": self.peak_speed,
                "peak_speed_t": self.peak_speed_t, "peak_accel": self.peak_accel,
                "peak_accel_t": self.peak_accel_t}


@dataclass(frozen=True)
class Violation:
    """One limit a knob's trajectory exceeds (the worst instance of it).

    Attributes
    ----------
    knob : int
    limit : str
        ``travel``, ``speed`` or ``accel``.
    value, bound : float
        What the trajectory asks for and the limit.
    t : float
        Where (s).
    count : int
        How many samples (travel) or steps (speed, accel) exceed it.
    """

    knob: int
    limit: str
    value: float
    bound: float
    t: float
    count: int

    _UNITS = MappingProxyType({"travel": "deg", "speed": "deg/s", "accel": "deg/s^2"})

    @property
    def message(self) -> str:
        unit = self._UNITS[self.limit]
        what = {"travel": "reaches", "speed": "moves at", "accel": "accelerates at"}[self.limit]
        bound = f"+-{self.bound:g}" if self.limit == "travel" else f"{self.bound:g}"
        label = "acceleration" if self.limit == "accel" else self.limit
        value = f"{self.value:.1f}" if abs(self.value) < 1e6 else f"{self.value:.3g}"
        return (f"knob {self.knob} {what} {value} {unit} at t={self.t:g} s, beyond the "
                f"{label} limit {bound} {unit} ({self.count} "
                f"{'sample' if self.limit == 'travel' else 'step'}{'s' if self.count != 1 else ''})")

    def to_dict(self) -> dict[str, Any]:
        return {"knob": self.knob, "limit": self.limit, "value": self.value, "bound": self.bound,
                "t": self.t, "count": self.count, "message": self.message}


@dataclass(frozen=True)
class MotionCheck:
    """A trajectory's motion per knob against a set of limits.

    Attributes
    ----------
    knobs : mapping of int to KnobMotion
    limits : Limits
    violations : tuple of Violation
        Empty when the trajectory is within every limit.
    """

    knobs: Mapping[int, KnobMotion]
    limits: Limits
    violations: tuple[Violation, ...] = field(default=())

    def __post_init__(self) -> None:
        object.__setattr__(self, "knobs", MappingProxyType(dict(self.knobs)))
        object.__setattr__(self, "violations", tuple(self.violations))

    @property
    def ok(self) -> bool:
        """Whether every knob is within every limit."""
        return not self.violations

    def exceeds(self, *limits: str) -> tuple[Violation, ...]:
        """The violations of the named limits (``travel``, ``speed``, ``accel``)."""
        return tuple(v for v in self.violations if v.limit in limits)

    def to_dict(self) -> dict[str, Any]:
        return {"knobs": {str(k): m.to_dict() for k, m in self.knobs.items()},
                "limits": self.limits.to_dict(), "within_limits": self.ok,
                "violations": [v.to_dict() for v in self.violations]}


def knob_motion(t: Any, q: Any, knob: int, name: str = "trajectory") -> KnobMotion:
    """Range, peak speed and peak acceleration of one knob's commands ``q`` at times ``t``.

    Raises
    ------
    DataError
        ``t`` and ``q`` of different lengths, fewer than 2 samples, a non-finite value (the row
        named), or ``t`` not strictly increasing.
    """
    import numpy as np  # here: hyst --help imports this module and must not pay for numpy
    t = np.asarray(t, dtype=float)
    q = np.asarray(q, dtype=float)
    if t.ndim != 1 or t.shape != q.shape:
        raise DataError(f"{name}: t and q{knob} must be 1-D of one length, got {t.shape} and {q.shape}")
    if t.size < 2:
        raise DataError(f"{name}: a trajectory needs at least 2 samples, got {t.size}")
    for col, values in (("t", t), (f"q{knob}", q)):
        bad = ~np.isfinite(values)
        if bad.any():
            row = int(np.argmax(bad))
            raise DataError(f"{name}: column {col} has a non-finite value ({float(values[row])!r}) "
                            f"at row {row}")
    dt = np.diff(t)
    if np.any(dt <= 0):
        row = int(np.argmax(dt <= 0)) + 1
        raise DataError(f"{name}: t must be strictly increasing (row {row}: {float(t[row]):g} after "
                        f"{float(t[row - 1]):g})")
    with np.errstate(over="ignore"):
        # huge finite commands (1e308) overflow to inf here: still beyond any limit, never NaN
        v = np.diff(q) / dt
    speed = np.abs(v)
    i_v = int(np.argmax(speed))
    if v.size >= 2:
        with np.errstate(over="ignore", invalid="ignore"):
            a = np.abs(np.diff(v) / (0.5 * (dt[1:] + dt[:-1])))
        a = np.where(np.isnan(a), np.inf, a)  # inf - inf: a jump beyond float range
        i_a = int(np.argmax(a))
        peak_a, peak_a_t = float(a[i_a]), float(t[i_a + 1])
    else:
        peak_a, peak_a_t = 0.0, float(t[0])
    return KnobMotion(int(knob), int(t.size), float(q.min()), float(q.max()), float(speed[i_v]),
                      float(t[i_v]), i_v, peak_a, peak_a_t)


def check_motion(run: Any, limits: Limits = Limits(), *, knobs: Any = None,
                 name: str | None = None) -> MotionCheck:
    """Measure every knob command column ``q<k>`` of ``run`` and compare it with ``limits``.

    Parameters
    ----------
    run : hystcli.core.run.Run
        Columns ``t`` and ``q1`` and/or ``q2``.
    limits : Limits
    knobs : iterable of int, optional
        The knobs to check (default: every ``q<k>`` column).
    name : str, optional
        How messages name the run (default: its source).

    Returns
    -------
    MotionCheck
        The violations are collected, not raised: :func:`require_within` raises.

    Raises
    ------
    DataError
        No knob command column, or bad values (:func:`knob_motion`).
    """
    import numpy as np  # here: hyst --help imports this module and must not pay for numpy
    name = name or getattr(run, "source", None) or "trajectory"
    ks = list(run.knobs("q")) if knobs is None else [int(k) for k in knobs]
    if not ks:
        raise DataError(f"{name}: no knob command column (q1 or q2)")
    t = np.asarray(run.t, dtype=float)
    motions: dict[int, KnobMotion] = {}
    violations: list[Violation] = []
    for k in ks:
        q = np.asarray(run[f"q{k}"], dtype=float)
        m = knob_motion(t, q, k, name)
        motions[k] = m
        over = np.abs(q) > limits.travel
        if over.any():
            i = int(np.argmax(np.abs(q)))
            violations.append(Violation(k, "travel", float(abs(q[i])), limits.travel, float(t[i]),
                                        int(over.sum())))
        if m.peak_speed > limits.max_speed:
            with np.errstate(over="ignore"):
                n = int(np.sum(np.abs(np.diff(q) / np.diff(t)) > limits.max_speed))
            violations.append(Violation(k, "speed", m.peak_speed, limits.max_speed,
                                        m.peak_speed_t, n))
        if limits.max_accel is not None and m.peak_accel > limits.max_accel:
            violations.append(Violation(k, "accel", m.peak_accel, limits.max_accel,
                                        m.peak_accel_t, _count_accel(t, q, limits.max_accel)))
    return MotionCheck(motions, limits, tuple(violations))


def _count_accel(t: np.ndarray, q: np.ndarray, bound: float) -> int:
    import numpy as np  # here: hyst --help imports this module and must not pay for numpy
    dt = np.diff(t)
    with np.errstate(over="ignore", invalid="ignore"):
        a = np.abs(np.diff(np.diff(q) / dt) / (0.5 * (dt[1:] + dt[:-1])))
    return int(np.sum(np.where(np.isnan(a), np.inf, a) > bound))


class LimitExceeded(SafetyStop):
    """A commanded trajectory asks for more than the limits allow; nothing was moved.

    Attributes
    ----------
    check : MotionCheck
        The whole check (every knob, every violation).
    """

    def __init__(self, message: str, check: MotionCheck) -> None:
        super().__init__(message)
        self.check = check


def require_within(check: MotionCheck, *, allow: tuple[str, ...] = (), name: str = "trajectory",
                   action: str = "play") -> MotionCheck:
    """Raise :class:`LimitExceeded` when ``check`` has a violation not in ``allow``.

    Parameters
    ----------
    check : MotionCheck
    allow : tuple of str
        Limits whose violations are accepted (``("speed", "accel")``: the caller plays fast
        steps at the speed limit instead). Travel is never a caller's to allow: raise the limit.
    name : str
        The trajectory, for the message.
    action : str
        What is refused (``play``, ``write``), for the message.

    Returns
    -------
    MotionCheck
        ``check`` itself, when nothing is refused.
    """
    refused = [v for v in check.violations if v.limit not in allow]
    if refused:
        more = f" (and {len(refused) - 1} more)" if len(refused) > 1 else ""
        raise LimitExceeded(f"refusing to {action} {name}: {refused[0].message}{more}", check)
    return check


def check_target(knob: int, angle: float, limits: Limits) -> float:
    """A single target angle (home, jog) against the travel limit; returns it as a float.

    Raises
    ------
    DataError
        A non-finite angle.
    SafetyStop
        An angle beyond the travel limit (nothing was moved).
    """
    angle = float(angle)
    if not math.isfinite(angle):
        raise DataError(f"knob {knob}: target angle {angle!r} is not a finite number")
    if abs(angle) > limits.travel:
        raise SafetyStop(f"knob {knob}: target {angle:+.2f} deg is beyond the travel limit "
                         f"+-{limits.travel:g} deg; nothing moved")
    return angle


# --------------------------------------------------------------------------------------------
# what to do with a step beyond the speed limit
# --------------------------------------------------------------------------------------------
SPEED_MODES = ("limit", "strict", "fast")
"""``limit``: rate-limit the commands (:class:`RateLimiter`); ``strict``: refuse the trajectory;
``fast``: keep the commands as asked (a player sends a faster step at the speed limit)."""

_MARGIN = 1e-9
"""Relative margin under each limit the :class:`RateLimiter` keeps, so that the speed and
acceleration :func:`check_motion` measures on its output (after float rounding) are within it."""


def check_speed_mode(speed: str) -> str:
    """``speed`` when it is one of :data:`SPEED_MODES`, else :class:`DataError`."""
    if speed not in SPEED_MODES:
        raise DataError(f"the speed mode must be one of {', '.join(SPEED_MODES)}, got {speed!r}")
    return speed


@dataclass(frozen=True)
class CatchUp:
    """How long a rate-limited knob lagged the commands it was asked for.

    A *catch-up* runs from the first sample whose command the limiter could not reach to the
    first sample it reached again (or to the end of the trajectory, ``caught_up`` False).

    Attributes
    ----------
    knob : int
    episodes : int
        Separate catch-ups.
    longest : float
        Duration of the longest (s).
    longest_t : float
        When it began (s).
    total : float
        Duration of all of them (s).
    largest_gap : float
        Largest |command sent - command asked| (deg).
    samples : int
        Samples whose command was not the one asked.
    caught_up : bool
        Whether the knob was back on the asked command at the last sample.
    tip_error : float or None
        Largest change of the model's tip angle the lag causes (deg): the model run on the
        rate-limited commands against the model run on the exact ones
        (:func:`hystcli.compensation.compensate`); None when no model was run.
    """

    knob: int
    episodes: int
    longest: float
    longest_t: float
    total: float
    largest_gap: float
    samples: int
    caught_up: bool = True
    tip_error: float | None = None

    @property
    def message(self) -> str:
        """One sentence for the user."""
        many = f"{self.episodes} times, {self.total:.3g} s in all" if self.episodes > 1 else "once"
        text = (f"knob {self.knob}: steps beyond the motor's limits rate-limited ({many}): the knob "
                f"lags the exact commands by up to {self.longest:.3g} s (from t={self.longest_t:g} s) "
                f"and {self.largest_gap:.3g} deg")
        if self.tip_error is not None:
            text += f"; on the model this moves the tip by up to {self.tip_error:.3g} deg"
        if not self.caught_up:
            text += "; it had not caught up at the end of the trajectory"
        return text

    @property
    def note(self) -> str:
        """The figures in short, for a run's metadata."""
        return (f"{self.episodes} catch-ups, longest {self.longest:.4g} s from t={self.longest_t:g} s, "
                f"{self.total:.4g} s in all, largest gap {self.largest_gap:.4g} deg"
                + ("" if self.caught_up else ", not caught up at the end"))

    def to_dict(self) -> dict[str, Any]:
        return {"knob": self.knob, "episodes": self.episodes, "longest_s": self.longest,
                "longest_t": self.longest_t, "total_s": self.total, "largest_gap": self.largest_gap,
                "samples": self.samples, "caught_up": self.caught_up, "tip_error": self.tip_error,
                "message": self.message}


class RateLimiter:
    """One knob's commands, limited to a speed (and acceleration) sample by sample, causally.

    Each :meth:`step` takes the command asked for at time ``t`` and returns the one to send: the
    asked one when the limits allow reaching it from the last command sent, else a step toward it
    at the limit. So a jump of the inverse model (across the dead zone, across the backlash at a
    reversal) is crossed at the speed limit, and the knob lands on the asked commands again as
    soon as it has caught up. With an acceleration limit the knob also brakes in time to land
    without overshooting a command that stands still (a moving one it follows at its speed, and
    may overshoot by a fraction of a degree). The first sample is sent as asked: a player brings
    the knob there with an untimed move.

    The speed and acceleration are those :func:`check_motion` measures (``|q[i] - q[i-1]| /
    (t[i] - t[i-1])`` and the change of that per the time between two steps' midpoints), kept a
    relative 1e-9 under the limits so the output passes the check after float rounding.

    Parameters
    ----------
    knob : int
        For :meth:`catch_up`.
    max_speed : float
        deg/s.
    max_accel : float, optional
        deg/s^2 (default: none).
    """

    __slots__ = ("knob", "vmax", "amax", "q", "v", "t", "dt", "target", "vt", "_start", "_ep", "_longest",
                 "_longest_t", "_total", "_gap", "_samples")

    def __init__(self, knob: int, max_speed: float, max_accel: float | None = None) -> None:
        self.knob = int(knob)
        self.vmax = float(max_speed) * (1 - _MARGIN)
        self.amax = None if max_accel is None else float(max_accel) * (1 - _MARGIN)
        self.reset()

    def reset(self) -> None:
        """Forget every sample: the next one is sent as asked."""
        self.q = self.v = self.t = self.dt = self.target = math.nan
        self.vt = 0.0            # the asked commands' own speed, jumps left out
        self._start = None       # time the catch-up under way began (None: none under way)
        self._ep = self._samples = 0
        self._longest = self._longest_t = self._total = self._gap = 0.0

    def step(self, target: float, t: float) -> float:
        """The command to send at time ``t`` (s, after the previous sample's) for ``target`` (deg)."""
        target, t = float(target), float(t)
        if math.isnan(self.q):
            self.q, self.t, self.target = target, t, target
            return target
        dt = t - self.t
        q0 = self.q
        v_exact = (target - q0) / dt
        if self.amax is None:
            if abs(v_exact) <= self.vmax:
                q, v = target, v_exact
            else:
                v = math.copysign(self.vmax, v_exact)
                q = q0 + v * dt
        else:
            a = self.amax
            # the asked commands' speed as the limits could follow it: a jump is a gap to close,
            # not a speed to take up
            vt = min(max((target - self.target) / dt, self.vt - a * dt, -self.vmax), self.vt + a * dt, self.vmax)
            self.vt = vt
            dv = math.inf if math.isnan(self.v) else a * 0.5 * (self.dt + dt)
            lo, hi = max(-self.vmax, self.v - dv), min(self.vmax, self.v + dv)
            if lo <= v_exact <= hi and abs(v_exact - self.vt) <= a * dt:
                # lands on the asked command at a speed it can keep
                q, v = target, v_exact
            else:
                gap = target - self.vt * dt - q0   # relative to the command moving at its speed
                v = min(max(self.vt + math.copysign(_braking_speed(abs(gap) / dt, a * dt), gap), lo), hi)
                q = q0 + v * dt
        self._count(q, target, t)
        self.q, self.v, self.dt, self.t, self.target = q, v, dt, t, target
        return q

    def _count(self, q: float, target: float, t: float) -> None:
        if q == target:
            if self._start is not None:
                self._close(t)
            return
        if self._start is None:
            self._start = t
            self._ep += 1
        self._samples += 1
        self._gap = max(self._gap, abs(q - target))

    def _close(self, t: float) -> None:
        span = t - self._start
        if span > self._longest:
            self._longest, self._longest_t = span, self._start
        self._total += span
        self._start = None

    def catch_up(self) -> CatchUp | None:
        """What the knob lagged so far (a catch-up under way counts up to the last sample), or
        None when every command was sent as asked."""
        if not self._ep:
            return None
        longest, longest_t, total = self._longest, self._longest_t, self._total
        if self._start is not None:
            span = self.t - self._start
            total += span
            if span > longest:
                longest, longest_t = span, self._start
        return CatchUp(self.knob, self._ep, longest, longest_t, total, self._gap, self._samples,
                       self._start is None)


def _braking_speed(g: float, dv: float) -> float:
    """The largest speed w from which slowing down by ``dv`` a step stops within ``g`` (the gap
    over the step's duration, deg/s): w, w - dv, w - 2 dv, ... down to a last step of at most
    dv (on the target) sum to ``g``. With n whole decrements, w = (g + dv n (n + 1) / 2) / (n + 1)
    for the largest n with dv n (n + 1) / 2 < g; the continuous v^2 / 2a misses the steps'
    rounding and overshoots, and an overshoot past a reversal pushes the loop's state."""
    if g <= dv:
        return g
    n = int((math.sqrt(1.0 + 8.0 * g / dv) - 1.0) / 2.0)
    while n > 0 and dv * n * (n + 1) / 2 >= g:
        n -= 1
    return (g + dv * n * (n + 1) / 2) / (n + 1)


def rate_limit(t: Any, q: Any, knob: int, limits: Limits) -> tuple["np.ndarray", CatchUp | None]:
    """One knob's commands ``q`` at times ``t`` through a :class:`RateLimiter` of ``limits``.

    Returns
    -------
    q : numpy.ndarray
        The commands to send (equal to ``q`` where the limits allow).
    catch_up : CatchUp or None
        None when nothing was limited.
    """
    import numpy as np  # here: hyst --help imports this module and must not pay for numpy
    lim = RateLimiter(knob, limits.max_speed, limits.max_accel)
    step = lim.step
    out = [step(a, b) for a, b in zip(np.asarray(q, dtype=float).tolist(), np.asarray(t, dtype=float).tolist())]
    return np.asarray(out), lim.catch_up()


@dataclass(frozen=True)
class Planned:
    """A command trajectory as it will be played, from :func:`plan_motion`.

    Attributes
    ----------
    run : hystcli.core.run.Run
        The commands to send: those asked for, rate-limited where needed with ``speed="limit"``.
    check : MotionCheck
        The commands asked for against the limits (what ``strict`` refuses, ``fast`` sends).
    speed : str
        One of :data:`SPEED_MODES`.
    catch_ups : mapping of int to CatchUp
        Per knob rate-limited, how it lagged (empty unless ``speed="limit"`` limited something).
    sent : MotionCheck
        The commands to send against the limits: within the speed and acceleration limits unless
        ``speed="fast"``.
    """

    run: Any
    check: MotionCheck
    speed: str
    catch_ups: Mapping[int, CatchUp]
    sent: MotionCheck

    def __post_init__(self) -> None:
        object.__setattr__(self, "catch_ups", MappingProxyType(dict(self.catch_ups)))


def plan_motion(run: Any, limits: Limits = Limits(), speed: str = "strict", *, name: str | None = None,
                action: str = "play") -> Planned:
    """Check a command trajectory against ``limits`` and deal with its fast steps as ``speed`` says.

    Parameters
    ----------
    run : hystcli.core.run.Run
        Columns ``t`` and ``q1`` and/or ``q2``.
    limits : Limits
    speed : str
        ``strict``: a step beyond the speed or acceleration limit refuses the trajectory;
        ``fast``: the commands are kept as they are; ``limit``: each knob with such a step is
        rate-limited (:class:`RateLimiter`), the others are kept.
    name : str, optional
        How messages name the run (default: its source).
    action : str
        What is refused (``play``, ``write``), for the message.

    Raises
    ------
    DataError
        Bad values (:func:`check_motion`), an unknown ``speed``.
    LimitExceeded
        A command beyond the travel limit (whatever ``speed``; also a rate-limited command that
        overshoots to beyond it), or with ``strict`` a step beyond the speed or acceleration limit.
    """
    check_speed_mode(speed)
    name = name or getattr(run, "source", None) or "trajectory"
    check = check_motion(run, limits, name=name)
    require_within(check, allow=() if speed == "strict" else ("speed", "accel"), name=name, action=action)
    slow = {v.knob for v in check.exceeds("speed", "accel")}
    if speed != "limit" or not slow:
        return Planned(run, check, speed, {}, check)
    cols, catch_ups = {}, {}
    for k in sorted(slow):
        cols[f"q{k}"], c = rate_limit(run.t, run[f"q{k}"], k, limits)
        if c is not None:
            catch_ups[k] = c
    limited = run.with_columns(**cols)
    sent = check_motion(limited, limits, name=name)
    require_within(sent, name=name, action=action)
    return Planned(limited, check, speed, catch_ups, sent)
