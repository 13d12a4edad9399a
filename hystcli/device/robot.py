"""What the host does with a robot's knobs: play a command trajectory, home, jog, read status.

Every function here takes an open :class:`hystcli.device.Device` (handshake done) and keeps one
rule: nothing moves before the whole request has been checked against the :class:`Limits`
(:mod:`hystcli.safety`), tightened by the limits the device announces in its handshake
(``travel=`` and ``max_speed=``, docs/protocol.md). On any fault or Ctrl-C while moving, every
motor is stopped first; then :func:`play_trajectory` returns the knobs to where they began (or,
asked not to, holds them), and the error says where each knob is. Ctrl-C comes out as
:class:`Interrupted` (a ``KeyboardInterrupt`` that carries that statement).

The core never prints; ``hystcli/cli/device_cmds.py`` renders.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Mapping

import numpy as np

from ..errors import DataError, HystError, LinkError, SafetyStop
from ..safety import DEFAULT_MOVE_SPEED, Limits, Planned, check_target, plan_motion
from .driver import Device
from .protocol import DeviceInfo, Sample

DEVICE_LIMIT_KEYS = {"travel": "travel", "max_speed": "max_speed"}
"""Optional handshake fields (docs/protocol.md, "Device limits") -> :class:`Limits` fields."""


class Interrupted(KeyboardInterrupt):
    """Ctrl-C while the knobs moved: the motors were stopped; ``str()`` says where the knobs are."""


# --------------------------------------------------------------------------------------------
# limits
# --------------------------------------------------------------------------------------------
def device_limits(info: DeviceInfo | None) -> dict[str, float]:
    """The limits a device announced in its handshake (``travel=``, ``max_speed=``), if any.

    A value that is not a positive finite number is left out: the protocol keeps unknown or
    malformed ``key=value`` fields without error, and the host's own limits still apply.
    """
    out: dict[str, float] = {}
    if info is None:
        return out
    for key, name in DEVICE_LIMIT_KEYS.items():
        try:
            value = float(info.extra.get(key, "nan"))
        except ValueError:
            continue
        if math.isfinite(value) and value > 0:
            out[name] = value
    return out


def effective_limits(limits: Limits, device: Device) -> Limits:
    """``limits`` tightened by what ``device`` announced (never loosened)."""
    return limits.tightened(**device_limits(device.info))


def _move_speed(speed: float | None, limits: Limits) -> float:
    speed = DEFAULT_MOVE_SPEED if speed is None else float(speed)
    if not (math.isfinite(speed) and speed > 0):
        raise DataError(f"knob speed must be a positive number of deg/s, got {speed!r}")
    if speed > limits.max_speed:
        raise SafetyStop(f"knob speed {speed:g} deg/s is beyond the speed limit {limits.max_speed:g} "
                         "deg/s; nothing moved")
    return speed


def _knobs_of(device: Device, knobs: Iterable[int] | None) -> list[int]:
    info = device.info or device.hello()
    ks = list(info.knobs) if knobs is None else [int(k) for k in knobs]
    missing = [k for k in ks if k not in info.knobs]
    if missing:
        raise DataError(f"device {info.name} has no knob {missing[0]} "
                        f"(knobs: {','.join(map(str, info.knobs))})")
    return ks


# --------------------------------------------------------------------------------------------
# status
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Status:
    """What a device says about itself and its knobs, read without moving anything.

    Attributes
    ----------
    info : DeviceInfo
        The handshake.
    knobs : tuple of Sample
        One ``STATE`` reading per knob: angle (deg), motor current (mA), tip (deg or None).
    limits : mapping of str to float
        The limits the device announced (``travel``, ``max_speed``), if any.
    """

    info: DeviceInfo
    knobs: tuple[Sample, ...]
    limits: Mapping[str, float]

    def to_dict(self) -> dict[str, Any]:
        i = self.info
        return {"device": {"name": i.name, "protocol": i.protocol, "catheter": i.catheter,
                           "knobs": list(i.knobs), "tracker": i.tracker,
                           "features": list(i.features), "extra": dict(i.extra)},
                "limits": dict(self.limits),
                "knobs": {str(s.knob): {"angle": s.angle, "current": s.current, "tip": s.tip}
                          for s in self.knobs}}


def status(device: Device) -> Status:
    """The handshake and one ``STATE`` of every knob (nothing moves)."""
    info = device.info or device.hello()
    return Status(info, tuple(device.state(k) for k in info.knobs), device_limits(info))


# --------------------------------------------------------------------------------------------
# where the knobs are after an abort
# --------------------------------------------------------------------------------------------
def _where(device: Device, knobs: Iterable[int]) -> str:
    parts = []
    for k in knobs:
        q = device.angles.get(k)
        parts.append(f"knob {k} last reported at {q:+.2f} deg" if q is not None
                     else f"knob {k} position unknown")
    return ", ".join(parts)


def _return_knobs(device: Device, starts: Mapping[int, float], speed: float) -> str:
    """Best effort after a fault: move each knob back to ``starts``. Never raises (a second
    Ctrl-C stops the return); says where every knob is."""
    back: list[int] = []
    for k, q0 in starts.items():
        try:
            s = device.move(k, q0, speed)
            why = None if abs(s.angle - q0) <= 1e-3 + 1e-6 * abs(q0) else f"it stopped at {s.angle:+.2f} deg"
        except (Exception, KeyboardInterrupt) as exc:  # noqa: BLE001 - report, never raise here
            device.stop()
            why = "interrupted" if isinstance(exc, KeyboardInterrupt) else str(exc)
        if why is not None:
            done = "".join(f"knob {j} returned to {starts[j]:+.2f} deg, " for j in back)
            return (f"motors stopped; {done}knob {k} could NOT be returned to {q0:+.2f} deg "
                    f"({why}); " + _where(device, [j for j in starts if j not in back]))
        back.append(k)
    return "motors stopped, " + ", ".join(f"knob {j} returned to {starts[j]:+.2f} deg" for j in back)


def _hold_statement(device: Device, knobs: Iterable[int]) -> str:
    return "motors stopped, knobs held where they are: " + _where(device, knobs)


def _reraise_with(exc: BaseException, statement: str) -> None:
    """Raise ``exc`` again with ``statement`` (where the knobs are) added to its message."""
    if isinstance(exc, KeyboardInterrupt):
        raise Interrupted(statement) from None
    if isinstance(exc, HystError):
        try:
            new = type(exc)(f"{exc}; {statement}")
        except Exception:  # noqa: BLE001 - an error type with another signature
            new = HystError(f"{exc}; {statement}")
        raise new from None
    raise exc


# --------------------------------------------------------------------------------------------
# home and jog
# --------------------------------------------------------------------------------------------
def move_knobs(device: Device, targets: Mapping[int, float], *, speed: float | None = None,
               limits: Limits = Limits()) -> dict[int, tuple[Sample, Sample]]:
    """Move each knob to its target, one after the other, after checking every target.

    Parameters
    ----------
    device : Device
    targets : mapping of int to float
        Knob -> target angle (deg).
    speed : float, optional
        Knob speed (deg/s); default :data:`~hystcli.safety.DEFAULT_MOVE_SPEED`.
    limits : Limits
        Tightened by the device's announced limits.

    Returns
    -------
    dict of int to (Sample, Sample)
        Per knob, where it was (a ``STATE`` before anything moved) and where it arrived.

    Raises
    ------
    SafetyStop
        A target beyond the travel limit, a speed beyond the speed limit: nothing moved.
    DataError
        A knob the device lacks, a non-finite target.
    LinkError, DeviceError
        From the device: the motors were stopped and the message says where the knobs are.
    Interrupted
        Ctrl-C: the motors were stopped; the message says where the knobs are.
    """
    _knobs_of(device, targets)
    lim = effective_limits(limits, device)
    checked = {int(k): check_target(int(k), q, lim) for k, q in targets.items()}
    v = _move_speed(speed, lim)
    # where every knob starts (the reply deadlines then cover each motion), before any moves
    before = {k: device.state(k) for k in checked}
    out: dict[int, tuple[Sample, Sample]] = {}
    try:
        for k, q in checked.items():
            out[k] = (before[k], device.move(k, q, v))
    except BaseException as exc:
        device.stop()
        _reraise_with(exc, _hold_statement(device, checked))
    return out


def home(device: Device, knobs: Iterable[int] | None = None, angle: float = 0.0, *,
         speed: float | None = None, limits: Limits = Limits()) -> dict[int, tuple[Sample, Sample]]:
    """Return ``knobs`` (default: every knob of the device) to ``angle`` (deg; 0: the knobs'
    zero, the straight-shaft rest). See :func:`move_knobs`."""
    return move_knobs(device, {k: angle for k in _knobs_of(device, knobs)}, speed=speed,
                      limits=limits)


def jog(device: Device, knob: int, delta: float, *, max_step: float, speed: float | None = None,
        limits: Limits = Limits()) -> tuple[Sample, Sample]:
    """Move one knob by ``delta`` deg from where it is now.

    Parameters
    ----------
    max_step : float
        Largest |delta| (deg): a jog is a small nudge, not a move to anywhere.

    Returns
    -------
    (Sample, Sample)
        The knob before (a ``STATE``) and after the move.

    Raises
    ------
    SafetyStop
        |delta| beyond ``max_step``, a target beyond the travel limit, a speed beyond the
        speed limit: nothing moved. Otherwise as :func:`move_knobs`.
    """
    k = _knobs_of(device, [knob])[0]
    delta = float(delta)
    if not math.isfinite(delta):
        raise DataError(f"knob {k}: jog angle {delta!r} is not a finite number")
    if abs(delta) > max_step:
        raise SafetyStop(f"knob {k}: a jog of {delta:+g} deg is beyond the jog limit "
                         f"+-{max_step:g} deg; nothing moved")
    here = device.state(k).angle
    return move_knobs(device, {k: here + delta}, speed=speed, limits=limits)[k]


# --------------------------------------------------------------------------------------------
# playing a command trajectory
# --------------------------------------------------------------------------------------------
def check_trajectory(device: Device, trajectory: Any, limits: Limits = Limits(), *,
                     speed: str = "strict") -> Planned:
    """Everything :func:`play_trajectory` checks before its first MOVE, without moving, and the
    commands it will send (rate-limited with ``speed="limit"``: :func:`hystcli.safety.plan_motion`).

    Raises
    ------
    DataError
        No knob command, a knob the device lacks, non-finite values, ``t`` not increasing.
    LimitExceeded
        A command beyond the travel limit, or with ``speed="strict"`` a step beyond the speed
        (or acceleration) limit.
    """
    run = trajectory
    name = run.source or "trajectory"
    knobs = run.knobs("q")
    if not knobs:
        raise DataError(f"{name}: no knob command column (q1 or q2)")
    info = device.info or device.hello()
    missing = [k for k in knobs if k not in info.knobs]
    if missing:
        raise DataError(f"{name} commands knob {missing[0]} but device {info.name} drives knobs "
                        f"{','.join(map(str, info.knobs))}")
    return plan_motion(run, effective_limits(limits, device), speed, name=name)


class _Pacer:
    """Sends sample ``i`` at ``t[i] - t[0]`` after :meth:`start` (``paced``), keeping the worst lag."""

    def __init__(self, paced: bool, clock: Callable[[], float], sleep: Callable[[float], None]) -> None:
        self.paced, self.clock, self.sleep = paced, clock, sleep
        self.t0 = self.origin = 0.0
        self.max_lag = 0.0

    def start(self, t0: float) -> None:
        self.t0, self.origin = t0, self.clock()

    def wait(self, t: float) -> None:
        if not self.paced:
            return
        lag = self.clock() - (self.origin + (t - self.t0))
        if lag < 0:
            self.sleep(-lag)
        else:
            self.max_lag = max(self.max_lag, lag)


def _send_row(device: Device, info: DeviceInfo, knobs: Iterable[int], q: Any, prev: Any, dt: float,
              lim: Limits, *, fast: bool, min_speed: float, i: int, t: float) -> tuple[list, list, int]:
    """One sample's MOVE per knob, each at the speed that covers its step in ``dt`` (``prev``: the
    previous commands, or None for the first sample): (currents, tip angles, steps capped at the
    speed limit). A step beyond the limit is sent at the limit with ``fast``, else refused."""
    c_row, y_row, capped = [], [], 0
    for j, k in enumerate(knobs):
        speed = abs(q[j] - prev[j]) / dt if prev is not None else 0.0
        if speed > lim.max_speed:
            if not fast:
                raise SafetyStop(f"knob {k} would move at {speed:.1f} deg/s at t={t:g} s, beyond "
                                 f"the speed limit {lim.max_speed:g} deg/s (--allow-fast sends such "
                                 "steps at the limit; without --strict-speed they are rate-limited)")
            speed = lim.max_speed
            capped += 1
        s = device.move(k, q[j], max(speed, min_speed))
        c_row.append(s.current)
        if info.tracker:
            if s.tip is None:
                raise LinkError(f"device {info.name} announced a tracker but sent no tip angle at sample {i}")
            y_row.append(s.tip)
    return c_row, y_row, capped


def play_trajectory(device: Device, trajectory: Any, *, paced: bool = True,
                    limits: Limits = Limits(), speed: str = "strict",
                    return_on_abort: bool = True, move_speed: float | None = None,
                    min_speed: float = 1e-3,
                    progress: Callable[[int, int], None] | None = None,
                    clock: Callable[[], float] = time.monotonic,
                    sleep: Callable[[float], None] = time.sleep) -> Any:
    """Play the knob commands ``q<k>`` of a run on the device and record what it reports.

    The whole trajectory is checked first (:func:`check_trajectory`): nothing moves when any
    row is bad or beyond a limit. The knobs' starting angles are read, they are brought to the
    first command (untimed, at ``move_speed``), then every sample ``i`` is sent at
    ``t[i] - t[0]`` after the start (``paced``) or as soon as the previous one is answered. Each
    MOVE carries the speed that covers the step in the sample interval, so the motor moves as the
    trajectory says. A step beyond the speed (acceleration) limit refuses the trajectory
    (``speed="strict"``), is sent at the speed limit (``"fast"``: the knob then arrives late;
    ``play_speed_capped`` counts those steps), or is rate-limited before the play (``"limit"``:
    the knob crosses it at the limit and catches up with the commands after it; the log's
    ``q<k>`` are the commands sent and ``play_catchup<k>`` says how long the knob lagged).

    Parameters
    ----------
    device : Device
        An open device (handshake done).
    trajectory : hystcli.core.run.Run
        Columns ``t`` and ``q1`` and/or ``q2`` (e.g. the output of ``hyst compensate``); its
        ``r<k>`` columns and metadata are carried over.
    paced : bool
        Follow the file's timing (True) or go as fast as the device answers.
    limits : Limits
        Travel, speed (and acceleration) limits, tightened by the device's announced ones.
    speed : {"strict", "fast", "limit"}
        What to do with a step beyond the speed (or acceleration) limit (above; the modes of
        :func:`hystcli.safety.plan_motion`). Travel is never allowed past its limit.
    return_on_abort : bool
        On a fault or Ctrl-C, after stopping the motors, move every knob back to where it was
        before the play (True) or hold it where it stopped (False).
    move_speed : float, optional
        Speed of the untimed moves (to the first command, back after an abort); default
        :data:`~hystcli.safety.DEFAULT_MOVE_SPEED`, never above the speed limit.
    min_speed : float
        Lowest knob speed sent (deg/s), for steps that hardly move.
    progress : callable, optional
        Called as ``progress(i, n)`` after each sample.

    Returns
    -------
    hystcli.core.run.Run
        Columns ``t`` (the file's), ``q<k>`` (commands), ``c<k>`` (mA), ``y<k>`` (deg, when the
        device has a tracker), ``r<k>`` when the trajectory has them; the trajectory's metadata
        plus the device identity and ``play_timing``, ``play_max_lag_s``, ``play_peak_speed``,
        ``play_speed_limit``, ``play_speed_capped``, ``play_speed_mode`` and, per rate-limited
        knob, ``play_catchup<k>``.

    Raises
    ------
    DataError, LimitExceeded
        From the check: nothing moved.
    LinkError, DeviceError, SafetyStop
        From the device while playing: the motors were stopped, the knobs returned (or held);
        the message says where they are.
    Interrupted
        Ctrl-C while playing (likewise).
    """
    from ..core.run import Run

    info = device.info or device.hello()
    plan = check_trajectory(device, trajectory, limits, speed=speed)
    check, run = plan.check, plan.run
    lim = check.limits
    v_move = min(DEFAULT_MOVE_SPEED if move_speed is None else float(move_speed), lim.max_speed)
    knobs = list(check.knobs)
    t = np.asarray(run.t, float)
    qs = {k: np.asarray(run[f"q{k}"], float) for k in knobs}
    n = len(t)
    c = {k: np.empty(n) for k in knobs}
    y = {k: np.empty(n) for k in knobs} if info.tracker else {}
    pacer = _Pacer(paced, clock, sleep)
    capped = 0
    starts = {k: device.state(k).angle for k in knobs}
    try:
        for k in knobs:
            device.move(k, qs[k][0], v_move)
        pacer.start(t[0])
        for i in range(n):
            dt = t[i] - t[i - 1] if i else t[1] - t[0]
            pacer.wait(t[i])
            # the plan refused or rate-limited any step beyond the speed limit unless fast
            c_row, y_row, n_capped = _send_row(
                device, info, knobs, [qs[k][i] for k in knobs], [qs[k][i - 1] for k in knobs] if i else None,
                dt, lim, fast=speed == "fast", min_speed=min_speed, i=i, t=t[i])
            capped += n_capped
            for j, k in enumerate(knobs):
                c[k][i] = c_row[j]
                if info.tracker:
                    y[k][i] = y_row[j]
            if progress is not None:
                progress(i + 1, n)
    except BaseException as exc:
        device.stop()
        statement = (_return_knobs(device, starts, v_move) if return_on_abort
                     else _hold_statement(device, knobs))
        _reraise_with(exc, statement)
    cols: dict[str, np.ndarray] = {"t": t}
    for k in knobs:
        if f"r{k}" in run:
            cols[f"r{k}"] = np.asarray(run[f"r{k}"], float)
        cols[f"q{k}"] = qs[k]
        if info.tracker:
            cols[f"y{k}"] = y[k]
        cols[f"c{k}"] = c[k]
    meta = dict(run.meta)
    meta.update(info.as_meta())
    meta["play_timing"] = "paced" if paced else "fast"
    meta["play_max_lag_s"] = f"{pacer.max_lag:.4f}"
    meta["play_peak_speed"] = f"{max(m.peak_speed for m in check.knobs.values()):.4g}"
    meta["play_speed_limit"] = f"{lim.max_speed:g}"
    meta["play_speed_capped"] = str(capped)
    meta["play_speed_mode"] = speed
    for k, c in plan.catch_ups.items():
        meta[f"play_catchup{k}"] = c.note
    return Run(cols, meta)
