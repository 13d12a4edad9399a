"""The device side of the hyst line protocol, serving a live twin over a pseudo-terminal.

Owns :class:`DeviceEmulator` (what a robot controller does with each received line: validate
the checksum, never act on a corrupt or malformed frame, move the twin's knobs, answer), the
fault injection that tests use (:class:`Fault`: stop replying, garble a reply, close the port,
answer ``ERR``, a current spike, a late reply) and :class:`PtyServer` / :func:`serve`, which
put that device behind a real pseudo-terminal (``os.openpty``) whose slave path any serial
client opens like a USB serial port.

The twin is anything with the interface of ``hystcli.sim.live.LiveTwin``: ``move(knob, q_target,
speed_deg_s=...) -> (knob_angle, motor_current, tip_angle)``, ``state(knob)`` (same triple),
``tip_available`` and the catheter it simulates; the optional features need ``move(..., dt=...)``,
``hold(duration, dt=...)`` and ``last_samples(knob)`` too. Besides the base protocol the emulator serves the optional
features ``dwell`` and ``mean`` (a MOVE that holds the target before answering and reports the
mean current over its last samples), so the live probe of Algorithm 1 reads a current averaged
like the replay probe's. POSIX only (pseudo-terminals).
"""
from __future__ import annotations

import errno
import math
import os
import re
import select
import threading
import time
from dataclasses import dataclass
from typing import Any, Iterable, Sequence

import numpy as np

from ..errors import DataError
from .protocol import (FEATURES, MAX_DWELL, MAX_FRAME, NO_SEQ, PROTOCOL_VERSION, DeviceInfo, Frame, FrameError,
                       decode_frame, encode_frame, parse_knob, parse_number)

FAULT_KINDS = ("silent", "garble", "close", "error", "spike", "delay")


@dataclass(frozen=True)
class Fault:
    """A fault the emulated device injects, triggered by the count of ``MOVE`` frames.

    Attributes
    ----------
    kind : str
        ``silent``: from the ``at``-th MOVE on, read frames but never answer (and do not move);
        ``garble``: answer ``count`` MOVEs from the ``at``-th with one byte of the reply
        corrupted (the knob did move: only the reply is damaged);
        ``close``: close the pseudo-terminal when the ``at``-th MOVE arrives (an unplugged cable);
        ``error``: answer ``count`` MOVEs with ``ERR value`` instead of moving (``value`` is the
        code, ``E_MOTOR`` by default);
        ``spike``: add ``value`` mA (default 5000) to the current of ``count`` replies (contact);
        ``delay``: answer ``count`` MOVEs ``value`` seconds late (default 1.0).
    at : int
        1-based index of the MOVE frame that triggers it.
    count : int
        How many MOVEs it affects (``silent`` and ``close`` are for good).
    value : str or None
    """

    kind: str
    at: int = 1
    count: int = 1
    value: str | None = None

    def __post_init__(self) -> None:
        if self.kind not in FAULT_KINDS:
            raise DataError(f"unknown fault {self.kind!r} (known: {', '.join(FAULT_KINDS)})")
        if self.at < 1 or self.count < 1:
            raise DataError(f"fault {self.kind}: at and count must be >= 1")
        if self.kind in ("spike", "delay") and self.value is not None:
            try:
                v = float(self.value)
            except ValueError:
                raise DataError(f"fault {self.kind}: value {self.value!r} is not a number") from None
            if not math.isfinite(v) or (self.kind == "delay" and v < 0):
                raise DataError(f"fault {self.kind}: value {self.value!r} out of range")
        if self.kind == "error" and self.value is not None and not re.fullmatch(r"E_[A-Z0-9_]+", self.value):
            raise DataError(f"fault error: code {self.value!r} must look like E_MOTOR")

    def hits(self, n: int) -> bool:
        """Whether the ``n``-th MOVE is affected."""
        if self.kind in ("silent", "close"):
            return n >= self.at
        return self.at <= n < self.at + self.count

    @classmethod
    def parse(cls, text: str) -> "Fault":
        """Parse ``KIND@N[xCOUNT][=VALUE]``, e.g. ``garble@5``, ``error@3=E_MOTOR``, ``spike@4x2=3000``."""
        m = re.fullmatch(r"\s*([a-z]+)@([0-9]+)(?:x([0-9]+))?(?:=(\S+))?\s*", text)
        if not m:
            raise DataError(f"bad fault {text!r}: expected KIND@N[xCOUNT][=VALUE], "
                            f"KIND one of {', '.join(FAULT_KINDS)}")
        return cls(m.group(1), int(m.group(2)), int(m.group(3) or 1), m.group(4))


def _scratch_copy(obj: Any) -> Any:
    """A deep copy of ``obj`` that shares its immutable parts (frozen dataclasses: a catheter, its
    effects, a shape), which may hold read-only mapping views that ``copy.deepcopy`` cannot copy.
    The copy's mutable state (clock, filter and noise states) is its own."""
    import copy
    import dataclasses

    memo: dict[int, Any] = {}

    def share(x: Any) -> None:
        if dataclasses.is_dataclass(x) and not isinstance(x, type) and x.__dataclass_params__.frozen:
            memo[id(x)] = x
        elif isinstance(x, dict):
            for v in x.values():
                share(v)
        elif isinstance(x, (list, tuple)):
            for v in x:
                share(v)

    for value in vars(obj).values():
        share(value)
    return copy.deepcopy(obj, memo)


class _Closed(Exception):
    """Raised inside the emulator when a ``close`` fault fires."""


class DeviceEmulator:
    """A robot controller in software: the device side of the protocol over a twin.

    Parameters
    ----------
    twin : LiveTwin-like
        The virtual catheter it drives.
    name : str
        Device name sent in the handshake.
    travel_limit : float
        Largest absolute knob angle (deg) it accepts; beyond, ``ERR E_RANGE``.
    default_speed : float
        Knob speed (deg/s) when a MOVE gives none.
    faults : iterable of Fault
        Faults to inject.
    features : sequence of str
        Optional protocol features to announce and serve (default: all of
        ``hystcli.device.FEATURES``: ``dwell`` and ``mean``); ``()`` makes a device of the base
        protocol, which refuses MOVE options with ``E_ARG``.
    max_speed : float
        Fastest knob speed (deg/s) its motors do; a faster MOVE is refused (``E_ARG``).
    max_move_time : float
        Longest single motion (s) it accepts: a MOVE whose distance / speed exceeds it is refused
        (``E_ARG``). The twin computes a move's samples at once (one per millisecond), so
        without this bound a slow speed over a long way (170 deg at 0.001 deg/s: 1.7e8 samples)
        would exhaust the memory of the process serving the port.

    The handshake announces ``travel=`` and ``max_speed=`` (docs/protocol.md, "Device limits"),
    so that a host checks a whole trajectory against them before its first MOVE.

    Attributes
    ----------
    moves, hellos, stops, bad_frames, errors_sent : int
        Counters a test can read: MOVE frames received, handshakes answered (one per host
        connection), STOPs executed, frames refused as corrupt or malformed, ERR replies sent.
    """

    def __init__(self, twin: Any, *, name: str = "hyst-sim", travel_limit: float = 170.0,
                 default_speed: float = 20.0, faults: Iterable[Fault] = (),
                 features: Sequence[str] = FEATURES, max_speed: float = 1000.0,
                 max_move_time: float = 120.0) -> None:
        for what, value in (("travel limit", travel_limit), ("default speed", default_speed),
                            ("max speed", max_speed), ("max move time", max_move_time)):
            if not (math.isfinite(value) and value > 0):
                raise DataError(f"emulator {what} must be a positive number, got {value!r}")
        if default_speed > max_speed:
            raise DataError(f"emulator default speed {default_speed:g} deg/s is beyond its max "
                            f"speed {max_speed:g} deg/s")
        self.twin = twin
        catheter = getattr(twin, "catheter", None)
        knobs = tuple(int(k) for k in getattr(twin, "knobs", (1, 2)))
        unknown = [f for f in features if f not in FEATURES]
        if unknown:
            raise DataError(f"unknown protocol feature {unknown[0]!r} (known: {', '.join(FEATURES)})")
        self.info = DeviceInfo(PROTOCOL_VERSION, name,
                               str(getattr(catheter, "name", catheter or "unknown")), knobs,
                               bool(getattr(twin, "tip_available", True)),
                               {"fw": "hystcli-emulator", "travel": f"{travel_limit:g}",
                                "max_speed": f"{max_speed:g}"},
                               tuple(f for f in FEATURES if f in features))
        self.travel_limit = float(travel_limit)
        self.default_speed = float(default_speed)
        self.max_speed = float(max_speed)
        self.max_move_time = float(max_move_time)
        self.faults: list[Fault] = list(faults)
        self.moves = 0
        self.hellos = 0
        self.stops = 0
        self.bad_frames = 0
        self.errors_sent = 0
        self.silent = False
        self._lock = threading.Lock()
        self._angles: dict[int, float] = {}
        self.warm_up()

    def warm_up(self) -> bool:
        """Make a few moves on a copy of the twin, so that the first MOVE a host sends is
        answered as fast as the others; learn where the knobs start. Returns False when the
        twin cannot be copied (it is then served cold).

        Why: the twin's sequential stages are numba-compiled functions, cached on disk but loaded
        (or, with no cache, compiled) on their first call, which took 0.2-0.9 s idle and several
        seconds on a busy machine: a fresh `hyst sim-robot` then missed a host's 1 s deadline on
        its first MOVE. A copy keeps the served twin's clock and noise streams untouched, so the
        device still answers exactly what a twin of the same seed computes.
        """
        try:
            scratch = _scratch_copy(self.twin)
        except Exception:  # noqa: BLE001 - a twin that cannot be copied: served cold
            return False
        with self._lock:
            try:
                angles = {k: float(scratch.state(k)[0]) for k in self.info.knobs}
                k = self.info.knobs[0]
                # both directions, a dwell and the averaging window: every path a MOVE takes
                self._run_move(k, angles[k] + 0.5, self.default_speed, 0.01, 0.01, twin=scratch)
                self._run_move(k, angles[k], self.default_speed, 0.0, None, twin=scratch)
            except Exception:  # noqa: BLE001 - a twin that fails here fails its MOVEs: E_MOTOR then
                return False
            self._angles.update(angles)
        return True

    SAMPLE_DT = 0.001
    """The twin's sample interval (s): ``LiveTwin.move``'s default, the controller's loop period.
    A dwell or an averaging window is counted in these samples."""

    def inject(self, fault: Fault) -> None:
        """Add a fault (thread-safe)."""
        with self._lock:
            self.faults.append(fault)

    # ---- one received line -> replies ------------------------------------------------------
    def handle_line(self, line: bytes) -> list[tuple[bytes, float]]:
        """Process one received line; return the replies as ``(bytes, delay_s)`` pairs.

        Raises ``_Closed`` when a ``close`` fault fires (the server closes the port).
        """
        with self._lock:
            try:
                return self._handle(line)
            except _Closed:
                raise
            except Exception as exc:  # noqa: BLE001 - a controller answers, it does not crash
                try:
                    seq = decode_frame(line).seq
                except FrameError:
                    seq = NO_SEQ
                return [(self._err(seq, "E_MOTOR", f"internal fault: {exc}"), 0.0)]

    def _handle(self, line: bytes) -> list[tuple[bytes, float]]:
        if not line.strip():
            return []  # empty lines end a partial frame of the host; not a command
        try:
            frame = decode_frame(line)
        except FrameError as exc:
            self.bad_frames += 1
            if self.silent:
                return []
            code = "E_CRC" if "checksum" in str(exc) else "E_FRAME"
            return [(self._err(NO_SEQ, code, "frame refused, nothing done"), 0.0)]
        if self.silent:
            return []
        if frame.verb == "MOVE":
            self.moves += 1
            return self._move(frame)
        try:
            if frame.verb == "HELLO":
                self.hellos += 1
                return [(encode_frame(frame.seq, "HELLO", *self.info.to_fields()), 0.0)]
            if frame.verb == "STOP":
                self.stops += 1
                stop = getattr(self.twin, "stop", None)
                if callable(stop):
                    stop()
                return [(encode_frame(frame.seq, "STOPPED"), 0.0)]
            if frame.verb == "STATE":
                if len(frame.args) != 1:
                    return [(self._err(frame.seq, "E_ARG", "STATE takes one knob"), 0.0)]
                knob = self._knob(frame.args[0])
                if knob is None:
                    return [(self._err(frame.seq, "E_KNOB", f"no knob {frame.args[0]}"), 0.0)]
                return [(self._pos(frame.seq, knob, self.twin.state(knob)), 0.0)]
        except FrameError as exc:
            return [(self._err(frame.seq, "E_ARG", str(exc)), 0.0)]
        return [(self._err(frame.seq, "E_CMD", f"unknown command {frame.verb}"), 0.0)]

    def _move(self, frame: Frame) -> list[tuple[bytes, float]]:
        n = self.moves
        active = [f for f in self.faults if f.hits(n)]
        kinds = {f.kind: f for f in active}
        if "close" in kinds:
            raise _Closed()
        if "silent" in kinds:
            self.silent = True
            return []
        if "error" in kinds:
            return [(self._err(frame.seq, kinds["error"].value or "E_MOTOR",
                               "injected fault: motor driver error"), 0.0)]
        positional = [a for a in frame.args if "=" not in a]
        if len(positional) not in (2, 3) or frame.args[:len(positional)] != tuple(positional):
            return [(self._err(frame.seq, "E_ARG", "MOVE takes knob angle [speed] [key=value ...]"), 0.0)]
        knob = self._knob(frame.args[0])
        if knob is None:
            return [(self._err(frame.seq, "E_KNOB", f"no knob {frame.args[0]}"), 0.0)]
        try:
            angle = parse_number(frame.args[1], "angle")
            speed = parse_number(frame.args[2], "speed") if len(positional) == 3 else self.default_speed
            options = self._move_options(frame.args[len(positional):])
        except FrameError as exc:
            return [(self._err(frame.seq, "E_ARG", str(exc)), 0.0)]
        if abs(angle) > self.travel_limit:
            return [(self._err(frame.seq, "E_RANGE",
                               f"{angle:g} deg outside +-{self.travel_limit:g}"), 0.0)]
        if not speed > 0:
            return [(self._err(frame.seq, "E_ARG", "speed must be positive"), 0.0)]
        if speed > self.max_speed:
            return [(self._err(frame.seq, "E_ARG", f"speed {speed:g} deg/s beyond the motor's "
                                                    f"{self.max_speed:g}"), 0.0)]
        # where the knob is, as this controller knows it (reading the twin would draw tracker
        # noise); unknown: anywhere within the travel
        here = self._angles.get(knob)
        distance = abs(angle - here) if here is not None else abs(angle) + self.travel_limit
        duration = distance / speed
        if duration > self.max_move_time:
            return [(self._err(frame.seq, "E_ARG", f"move of {duration:.4g} s beyond the "
                                                    f"{self.max_move_time:g} s limit"), 0.0)]
        q, c, y, mean = self._run_move(knob, angle, speed, options.get("dwell", 0.0),
                                       options.get("mean"))
        self._angles[knob] = float(q)
        if "spike" in kinds:
            bump = float(kinds["spike"].value or 5000.0)
            c = float(c) + bump
            if mean is not None:
                mean = (mean[0], mean[1] + bump, mean[2])
        reply = self._pos(frame.seq, knob, (q, c, y), mean)
        if "garble" in kinds:
            reply = garble(reply)
        delay = float(kinds["delay"].value or 1.0) if "delay" in kinds else 0.0
        return [(reply, delay)]

    def _move_options(self, fields: Sequence[str]) -> dict[str, float]:
        """The ``key=value`` options of a MOVE (raises :class:`FrameError` on a bad one)."""
        out: dict[str, float] = {}
        for f in fields:
            key, _, value = f.partition("=")
            if key not in self.info.features:
                raise FrameError(f"unknown MOVE option {key!r} (features: "
                                 f"{','.join(self.info.features) or 'none'})")
            if key in out:
                raise FrameError(f"MOVE option {key} given twice")
            v = parse_number(value, key)
            if not (0.0 <= v <= MAX_DWELL) or (key == "mean" and v == 0.0):
                raise FrameError(f"MOVE option {key}={value} outside "
                                 f"{'(0' if key == 'mean' else '[0'}, {MAX_DWELL:g}] s")
            out[key] = v
        return out

    def _run_move(self, knob: int, angle: float, speed: float, dwell: float, mean: float | None,
                  twin: Any = None) -> tuple[float, float, float, tuple[float, float, float] | None]:
        """Move the twin, hold it ``dwell`` s and, when asked, average the last ``mean`` s.

        Returns ``(q, c, tip, (q_mean, c_mean, t_mean) or None)``. The twin advances in whole
        samples of :attr:`SAMPLE_DT`; the window is the last ``mean`` s of the move's and the
        hold's samples (:meth:`LiveTwin.last_samples`), clipped to them.
        """
        twin, dt = self.twin if twin is None else twin, self.SAMPLE_DT
        n_dwell = int(round(dwell / dt)) if dwell > 0 else 0
        q, c, y = twin.move(knob, angle, speed_deg_s=speed, dt=dt)
        parts = [twin.last_samples(knob)]
        if n_dwell:
            twin.hold(n_dwell * dt, dt=dt)
            parts.append(twin.last_samples(knob))
            q, c, y = twin.state(knob)
        if mean is None:
            return q, c, y, None
        qs = np.concatenate([p[0] for p in parts])
        cs = np.concatenate([p[1] for p in parts])
        n_win = min(max(1, int(round(mean / dt))), qs.size)
        return q, c, y, (float(qs[-n_win:].mean()), float(cs[-n_win:].mean()), n_win * dt)

    def _knob(self, text: str) -> int | None:
        try:
            k = parse_knob(text)
        except FrameError:
            return None
        return k if k in self.info.knobs else None

    def _pos(self, seq: int | None, knob: int, st: Sequence[Any],
             mean: tuple[float, float, float] | None = None) -> bytes:
        q, c, y = st
        tip = "-" if (y is None or not self.info.tracker or not math.isfinite(y)) else float(y)
        extra = []
        if mean is not None:
            extra = [f"qmean={mean[0]:.4f}", f"cmean={mean[1]:.4f}", f"tmean={mean[2]:.4f}"]
        return encode_frame(seq, "POS", knob, float(q), float(c), tip, *extra)

    def _err(self, seq: int | None, code: str, message: str) -> bytes:
        self.errors_sent += 1
        words = [w for w in re.sub(r"[^\x21-\x7e ]|\*", "?", message).split(" ") if w]
        frame = encode_frame(seq, "ERR", code, *words[:12])
        return frame if len(frame) <= MAX_FRAME else encode_frame(seq, "ERR", code)


def garble(frame: bytes) -> bytes:
    """The frame with one byte of its body changed (its checksum no longer matches)."""
    body = bytearray(frame)
    i = max(0, min(len(body) - 5, len(body) // 2))
    body[i] = ord("#") if body[i] != ord("#") else ord("%")
    return bytes(body)


class PtyServer:
    """Serves a :class:`DeviceEmulator` on a pseudo-terminal, in a thread or in the foreground.

    Parameters
    ----------
    emulator : DeviceEmulator
    latency : float
        Seconds the device takes to answer each frame (a realistic controller: 1-5 ms).

    Attributes
    ----------
    path : str
        The slave device path (``/dev/pts/N``) a client opens as a serial port.
    closed : bool
        Whether the pseudo-terminal has been closed (:meth:`close_pty`, a ``close`` fault,
        :meth:`shutdown`).

    Notes
    -----
    Only one thread ever closes the file descriptors: the one serving (:meth:`serve_forever`)
    while it serves, else the caller. Another thread that wants the pty closed asks the serving
    loop (through the wake pipe) and waits. Closing a descriptor under a thread blocked on it in
    ``select`` or about to ``write`` to it is a race: the number can be reused at once by any
    ``open`` in the process (a test's temporary file, a client's port), and the serving thread
    would then read from or write replies into that file. A lock makes each close happen once.
    """

    def __init__(self, emulator: DeviceEmulator, latency: float = 0.0) -> None:
        import tty

        if not (latency >= 0 and math.isfinite(latency)):
            raise DataError("latency must be a finite number >= 0")
        self.emulator = emulator
        self.latency = float(latency)
        self._master, self._slave = os.openpty()
        # raw mode: no echo, no line editing, bytes pass untouched. The server keeps the slave
        # open so that clients may come and go without the master seeing a hang-up.
        tty.setraw(self._slave)
        os.set_blocking(self._master, False)
        self.path = os.ttyname(self._slave)
        self._wake_r, self._wake_w = os.pipe()
        os.set_blocking(self._wake_r, False)
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._serving: threading.Thread | None = None   # the thread inside serve_forever
        self._stopping = threading.Event()
        self._close_requested = False
        self._pty_closed = threading.Event()
        self.closed = False

    # ---- life cycle ------------------------------------------------------------------------
    def start(self) -> "PtyServer":
        """Serve in a daemon thread; returns self."""
        self._thread = threading.Thread(target=self.serve_forever, name="hyst-pty-device", daemon=True)
        self._thread.start()
        return self

    def __enter__(self) -> "PtyServer":
        return self.start() if self._thread is None else self

    def __exit__(self, *exc: object) -> None:
        self.shutdown()

    def shutdown(self) -> None:
        """Stop serving and close the pseudo-terminal (idempotent, from any thread)."""
        self._stopping.set()
        with self._lock:
            self._wake_locked()
        thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout=10)
        with self._lock:
            if self._serving is None or self._serving is threading.current_thread():
                self._close_pty_locked()
                self._close_wake_locked()
            # else the serving loop is still busy (a long reply delay): it sees _stopping and
            # closes everything itself on its way out

    def close_pty(self) -> None:
        """Close the pseudo-terminal now: the client sees a disconnected device."""
        with self._lock:
            if self.closed:
                return
            if self._serving is None or self._serving is threading.current_thread():
                self._close_pty_locked()
                return
            self._close_requested = True
            self._wake_locked()
        self._pty_closed.wait(timeout=10)

    def _wake_locked(self) -> None:
        if self._wake_w >= 0:
            try:
                os.write(self._wake_w, b"x")
            except OSError:
                pass  # the pipe is full: the loop is woken already

    def _close_pty_locked(self) -> None:
        if self.closed:
            return
        self.closed = True
        for fd in (self._master, self._slave):
            try:
                os.close(fd)
            except OSError:
                pass
        self._master = self._slave = -1
        self._pty_closed.set()

    def _close_wake_locked(self) -> None:
        for fd in (self._wake_r, self._wake_w):
            if fd >= 0:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self._wake_r = self._wake_w = -1

    # ---- the loop --------------------------------------------------------------------------
    def serve_forever(self) -> None:
        """Answer frames until :meth:`shutdown`, :meth:`close_pty` or a ``close`` fault."""
        with self._lock:
            if self.closed or self._stopping.is_set() or self._serving is not None:
                return
            self._serving = threading.current_thread()
        try:
            self._loop()
        finally:
            with self._lock:
                self._serving = None
                if self._close_requested or self._stopping.is_set():
                    self._close_pty_locked()
                if self._stopping.is_set():
                    self._close_wake_locked()

    def _loop(self) -> None:
        buf = bytearray()
        overflow = False
        master, wake = self._master, self._wake_r  # only this thread closes them while it serves
        while not (self._stopping.is_set() or self._close_requested or self.closed):
            try:
                ready, _, _ = select.select([master, wake], [], [], 0.5)
            except (OSError, ValueError):
                break
            if wake in ready:
                try:
                    os.read(wake, 512)
                except OSError:
                    pass
                continue  # the loop condition says why it was woken
            if not ready:
                continue
            try:
                data = os.read(master, 4096)
            except BlockingIOError:
                continue
            except OSError:
                break
            if not data:
                continue
            buf.extend(data)
            while True:
                nl = buf.find(b"\n")
                if nl < 0:
                    if len(buf) > MAX_FRAME:
                        # an endless line: drop it, answer once when its newline comes
                        buf.clear()
                        overflow = True
                    break
                line = bytes(buf[:nl + 1])
                del buf[:nl + 1]
                if overflow:
                    overflow = False
                    line = b"x" * (MAX_FRAME + 1)  # a line known too long: refused as E_FRAME
                try:
                    replies = self.emulator.handle_line(line)
                except _Closed:
                    self.close_pty()
                    return
                for reply, delay in replies:
                    if self.latency + delay > 0:
                        time.sleep(self.latency + delay)
                    self._send(master, reply)

    @staticmethod
    def _send(master: int, data: bytes) -> None:
        try:
            os.write(master, data)
        except BlockingIOError:
            pass  # the client does not read: a real device would drop the reply too
        except OSError as exc:
            if exc.errno not in (errno.EIO, errno.EBADF):
                raise


def serve(twin: Any, *, latency: float = 0.0, faults: Iterable[Fault] = (),
          name: str = "hyst-sim", travel_limit: float = 170.0, max_speed: float = 1000.0,
          background: bool = True) -> PtyServer:
    """Serve ``twin`` as a robot on a new pseudo-terminal.

    Parameters
    ----------
    twin : LiveTwin-like
    latency : float
        Per-frame answer latency (s).
    faults : iterable of Fault
        Faults to inject (tests).
    name : str
        Device name in the handshake.
    travel_limit : float
        Largest absolute knob angle accepted (deg).
    max_speed : float
        Fastest knob speed accepted (deg/s).
    background : bool
        Start a daemon thread (True) or return the server for :meth:`PtyServer.serve_forever`.

    Returns
    -------
    PtyServer
        ``server.path`` is the device to connect to; ``server.shutdown()`` ends it. The twin
        has been warmed up (:meth:`DeviceEmulator.warm_up`): the device answers its first MOVE
        as fast as the others as soon as the path exists.
    """
    emu = DeviceEmulator(twin, name=name, travel_limit=travel_limit, faults=faults,
                         max_speed=max_speed)
    server = PtyServer(emu, latency)
    return server.start() if background else server
