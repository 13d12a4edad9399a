"""One knob of a live robot as Algorithm 1's probe (:mod:`hystcli.shift`): :class:`DeviceProbe`.

Steps one knob and reads its motor current, with a current ceiling (contact) that stops every motor
and raises :class:`~hystcli.errors.SafetyStop`. It steps and dwells, reading the mean current over
the dwell, when the device offers the optional protocol features ``dwell`` and ``mean``
(:data:`hystcli.device.protocol.FEATURES`), as the replay probe averages the current over each step.
"""
from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass
from typing import Any, Iterator, Sequence

from ..errors import DeviceError, ParameterError, SafetyStop
from ..shift import ProbeSample
from .driver import Device
from .protocol import MAX_DWELL, Sample


DEFAULT_DWELL = 0.35
"""Default hold at each search step (s), feature ``dwell``. The averaging starts 50 ms after
arrival, when what lags the knob has settled: the tendon's viscous lag (the calibrated
catheters' ``rate`` effect, tau = 25 ms: e^-2 of it is left) and the device's causal 20 Hz
current filter (16 ms of group delay, settled in about 50 ms)."""
DEFAULT_MEAN = 0.3
"""Default averaging window of each search step (s), feature ``mean``: the last 0.3 s of the
dwell. The twin's current noise (3 mA rms at 1 kHz before the filter) averages down to about
0.17 mA, against 1.5 to 2.5 mA of change per 0.5 deg step once a tendon is taut; with 0.1 s the
worst edge error over 10 seeds x 4 shapes x 2 knobs of the calibrated catheters was 0.61 deg
(a 'fall' edge, where the slope changes least), with 0.3 s 0.24 deg (bench/bench_live.py)."""


class DeviceProbe:
    """One knob of a live device as Algorithm 1's probe: ``position``, ``step_to``, ``stop``.

    Each step is a step-and-dwell when the device offers it (protocol features ``dwell`` and
    ``mean``): the knob moves to the target, holds there ``dwell`` seconds, and the reading is
    the mean knob angle and motor current over the last ``mean`` seconds of the hold. One
    instantaneous current sample carries the device's whole noise (a few mA, against a change
    of about 2 mA per 0.5 deg step once a tendon is taut), and a reading taken while moving
    carries the lags of the tendon and of the filter (the edge reads late in the direction of
    motion); the settled mean has neither. A device without these features gives the single
    sample of its ``POS`` reply (:attr:`averaged` is then False).

    Parameters
    ----------
    device : Device
    knob : int
    current_ceiling : float, optional
        Absolute motor current (mA) treated as contact with a wall: the motors are stopped and
        :class:`~hystcli.errors.SafetyStop` raised. None disables the check (not advised).
    speed : float, optional
        Knob speed for each step (deg/s); the device's default when None.
    dwell : float or None
        Hold at each target before the reply (s); None or 0: no hold.
    mean : float or None
        Averaging window (s) ending at the reply; None: the instantaneous sample.

    Attributes
    ----------
    start : float
        The knob angle when the probe was made (where :meth:`return_to_start` goes).
    steps : int
        Steps taken.
    travel : float
        Total knob travel commanded (deg).
    averaged : bool
        Whether the steps read a mean current (the device offers the features asked for).
    """

    def __init__(self, device: Device, knob: int, *, current_ceiling: float | None = None,
                 speed: float | None = None, dwell: float | None = DEFAULT_DWELL,
                 mean: float | None = DEFAULT_MEAN) -> None:
        if device.info is not None and int(knob) not in device.info.knobs:
            raise DeviceError(f"device {device.info.name} has no knob {knob} "
                              f"(knobs: {','.join(map(str, device.info.knobs))})")
        self.device = device
        self.knob = int(knob)
        self.current_ceiling = current_ceiling
        self.speed = speed
        # ask only for what the device announced: a base-protocol device still works, with
        # single-sample readings
        self.dwell = dwell if dwell and device.supports("dwell") else None
        self.mean = mean if mean and device.supports("mean") else None
        self.averaged = self.mean is not None
        # readings taken while the knob still moves carry the motor's Coulomb friction of that
        # direction; after a dwell the knob rests (Algorithm 1 reads the level accordingly)
        self.reads_moving = self.dwell is None
        first = device.state(self.knob)
        self._check(first)
        self._q = first.angle
        self.start = first.angle
        self.steps = 0
        self.travel = 0.0
        self.last: Sample = first

    def position(self) -> float:
        """The knob angle (deg) after the last step."""
        return self._q

    def read(self) -> Any:
        """The knob at rest where it is: a sample ``(q, current, tip)`` without moving (the
        state the device reported when the probe opened, before any step)."""
        s = self.last
        return ProbeSample(s.angle, s.current, s.tip)

    def step_to(self, q: float) -> Any:
        """Move the knob to ``q`` and return a sample ``(q, current, tip)``.

        With averaging, ``q`` and ``current`` are the means over the averaging window (the
        current is attributed to where it was measured).

        Raises
        ------
        SafetyStop
            The current passed the ceiling (contact): every motor has been stopped.
        LinkError, DeviceError
            From the device; the caller stops and returns the knob.
        """
        q = float(q)
        self.travel += abs(q - self._q)
        self.steps += 1
        s = self.device.move(self.knob, q, self.speed, dwell=self.dwell, mean=self.mean)
        self._q = s.angle
        self.last = s
        self._check(s)
        if s.averaged:
            return ProbeSample(s.mean_angle, s.mean_current, s.tip)
        return ProbeSample(s.angle, s.current, s.tip)

    def stop(self) -> bool:
        """Stop every motor (never raises)."""
        return self.device.stop()

    def return_to_start(self) -> bool:
        """Best effort: stop, then move the knob back to :attr:`start`. Never raises.

        Returns True when the device confirmed the knob is back.
        """
        self.device.stop()
        try:
            s = self.device.move(self.knob, self.start, self.speed)
            self._q = s.angle
            return abs(s.angle - self.start) < 1e-3 + 1e-6 * abs(self.start)
        except Exception:  # noqa: BLE001 - a dead link cannot return the knob; say so via False
            self.device.stop()
            return False

    def _check(self, s: Sample) -> None:
        if self.current_ceiling is None:
            return
        worst = max(abs(s.current), abs(s.mean_current) if s.averaged else 0.0)
        if worst >= self.current_ceiling:
            self.device.stop()
            raise SafetyStop(f"knob {self.knob}: motor current {worst:.1f} mA reached the "
                             f"ceiling {self.current_ceiling:g} mA at {s.angle:.2f} deg "
                             "(contact?); motors stopped")


def open_probe(port: Any, baud: int = 115200, knob: int = 1, *, timeout: float = 1.0,
               current_ceiling: float | None = None, speed: float | None = None,
               dwell: float | None = DEFAULT_DWELL, mean: float | None = DEFAULT_MEAN) -> DeviceProbe:
    """Open a device and make a probe of one knob (close it with ``probe.device.close()``).

    ``dwell`` and ``mean`` as in :class:`DeviceProbe` (used when the device offers them).
    """
    device = Device(port, baud, timeout)
    try:
        return DeviceProbe(device, knob, current_ceiling=current_ceiling, speed=speed,
                           dwell=dwell, mean=mean)
    except BaseException:
        device.stop()
        device.close()
        raise


@dataclass(frozen=True)
class LiveProbes:
    """A live robot as the source of a shift detection (:func:`hystcli.shift.run_detect_shift`):
    one connection, a :class:`DeviceProbe` per knob. Its settings are checked when made.

    Parameters
    ----------
    port : str or pyserial-like object
    baud : int
    timeout : float
        Deadline of each reply, s, beyond the motion's own duration and any dwell.
    current_ceiling, speed, dwell, mean
        As in :class:`DeviceProbe`.

    Raises
    ------
    ParameterError
        A setting outside its domain: a baud rate, timeout, ceiling or speed that is not a positive
        number, a dwell or window outside [0, :data:`~hystcli.device.protocol.MAX_DWELL`] s.
    """

    port: Any
    baud: int = 115200
    timeout: float = 1.0
    current_ceiling: float | None = 2000.0
    speed: float | None = None
    dwell: float | None = DEFAULT_DWELL
    mean: float | None = DEFAULT_MEAN

    def __post_init__(self) -> None:
        # checked here, before any port is opened: pyserial's own refusal of a bad baud rate
        # would come out as a link error
        for name in ("timeout", "current_ceiling", "speed"):
            v = getattr(self, name)
            if v is not None and not (math.isfinite(v) and v > 0):
                raise ParameterError(name, f"must be a positive number, got {v}")
        for name in ("dwell", "mean"):
            v = getattr(self, name)
            if v is not None and not (math.isfinite(v) and 0 <= v <= MAX_DWELL):
                raise ParameterError(name, f"must be between 0 and {MAX_DWELL:g} s, got {v}")
        if self.baud <= 0:
            raise ParameterError("baud", f"must be a positive number, got {self.baud}")

    @contextlib.contextmanager
    def open(self, knobs: Sequence[int]) -> Iterator[dict[int, DeviceProbe]]:
        """Yield ``{knob: probe}`` on one connection; closed (motors stopped) on the way out.

        One connection for every knob: one handshake, and no second open of a port that a device
        (or an OS) may hold exclusively.
        """
        with Device(self.port, self.baud, self.timeout) as dev:
            yield {k: DeviceProbe(dev, k, current_ceiling=self.current_ceiling, speed=self.speed,
                                  dwell=self.dwell, mean=self.mean) for k in knobs}
