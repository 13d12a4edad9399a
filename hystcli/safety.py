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

It owns no device I/O; :mod:`hystcli.robot` applies it on a live device.
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
    run : hystcli.io.Run
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
