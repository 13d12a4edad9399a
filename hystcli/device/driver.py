"""The host-side driver of a robot speaking the hyst line protocol: :class:`Device`.

Opens a port name, a pyserial URL (``loop://``, ``socket://``, ``rfc2217://``) or takes any
already-open pyserial-like object; every read has a deadline; a reply is matched to its request by
sequence number so a stale reply is never taken for a fresh one. Faults are kept apart:
:class:`~hystcli.errors.DeviceError` when the device answered with ``ERR``,
:class:`~hystcli.errors.LinkError` when the link failed (no reply, corrupt or malformed frame,
disconnect). It never prints; the CLI (``hystcli/cli/device_cmds.py``) renders.
"""
from __future__ import annotations

import math
import time
from typing import Any

from ..errors import DeviceError, LinkError
from .protocol import (ERROR_CODES, MAX_DWELL, MAX_FRAME, NO_SEQ, PROTOCOL_VERSION, SEQ_MODULO, DeviceInfo, Frame,
                       FrameError, Sample, _show, decode_frame, encode_frame, parse_pos)


def _looks_like_port(obj: Any) -> bool:
    return callable(getattr(obj, "read", None)) and callable(getattr(obj, "write", None))


def open_port(port: Any, baud: int = 115200, timeout: float = 1.0) -> Any:
    """A pyserial port from a name, a URL or an already-open pyserial-like object.

    Raises
    ------
    LinkError
        When the port cannot be opened (names it and says why).
    """
    if _looks_like_port(port):
        return port
    import serial  # pyserial: imported here so that the codec works without it

    try:
        return serial.serial_for_url(str(port), baudrate=baud, timeout=timeout, write_timeout=timeout)
    except (serial.SerialException, OSError, ValueError) as exc:
        raise LinkError(f"cannot open port {port}: {exc}") from None


class Device:
    """Host-side driver of a robot speaking the hyst line protocol (docs/protocol.md).

    Parameters
    ----------
    port : str or pyserial-like object
        A port name (``/dev/ttyUSB0``, ``COM3``), a pyserial URL (``loop://``,
        ``socket://host:port``, ``rfc2217://host:port``) or an open object with ``read`` and
        ``write`` (its ``timeout`` is set to a short poll interval).
    baud : int
        Baud rate when the driver opens the port.
    timeout : float
        Deadline (s) for each reply, counted from the request. A ``MOVE`` is answered once the
        knob arrived (and held its dwell): its deadline grows by the dwell and, when the MOVE
        gives a speed and the knob's angle is known from an earlier reply (:attr:`angles`), by
        the motion's duration; otherwise the timeout must exceed the longest single step.
    handshake : bool
        Send ``HELLO`` on open and check the protocol version (recommended).

    Raises
    ------
    LinkError
        Cannot open the port, or no valid handshake reply.
    DeviceError
        The device answered with an error, or speaks another protocol version.

    Attributes
    ----------
    angles : dict of int to float
        The last angle each knob reported (every ``POS`` reply): where it is as far as the host
        knows, e.g. after a fault.

    Notes
    -----
    Not thread-safe: one request is in flight at a time. Use as a context manager; leaving the
    block stops every motor and closes the port when the driver opened it.
    """

    def __init__(self, port: Any, baud: int = 115200, timeout: float = 1.0, *,
                 handshake: bool = True) -> None:
        if not (timeout > 0 and math.isfinite(timeout)):
            raise ValueError("timeout must be a positive number of seconds")
        self.timeout = float(timeout)
        self._owns = not _looks_like_port(port)
        self.port_name = str(getattr(port, "port", None) or port) if self._owns else \
            str(getattr(port, "port", None) or getattr(port, "name", None) or type(port).__name__)
        self._port = open_port(port, baud, timeout)
        # a short poll interval: a read returns as soon as a byte is there, and the deadline of
        # the whole reply is checked between reads (pyserial's timeout is per read call)
        self._poll = min(0.05, self.timeout)
        try:
            self._port.timeout = self._poll
        except Exception:  # noqa: BLE001 - a port-like object without settable timeout
            pass
        self._buf = bytearray()
        self._seq = 0
        self._closed = False
        self.info: DeviceInfo | None = None
        self.stale_replies = 0    # replies dropped because their sequence number was old
        # the last angle each knob reported (POS replies): where it is as far as the host knows
        self.angles: dict[int, float] = {}
        self.requests = 0
        if handshake:
            try:
                self.info = self.hello()
            except BaseException:
                self.close()
                raise

    # ---- life cycle ------------------------------------------------------------------------
    def __enter__(self) -> "Device":
        return self

    def __exit__(self, *exc: object) -> None:
        if not self._stop_was_last:  # a stop just tried (say after a fault) is not repeated
            self.stop()
        self.close()

    def close(self) -> None:
        """Close the port if this driver opened it (an object passed in stays open)."""
        if self._closed:
            return
        self._closed = True
        if self._owns:
            try:
                self._port.close()
            except Exception:  # noqa: BLE001 - closing a dead port must not raise
                pass

    @property
    def closed(self) -> bool:
        return self._closed

    # ---- requests --------------------------------------------------------------------------
    def hello(self) -> DeviceInfo:
        """Handshake: ask the device who it is; check its protocol version.

        A bare newline is sent first so that a partial line left in the device's buffer by an
        earlier session ends there (the device ignores empty lines).
        """
        try:
            self._port.reset_input_buffer()
        except Exception:  # noqa: BLE001 - optional on port-like objects
            pass
        self._buf.clear()
        self._write(b"\n")
        frame = self._request("HELLO", expect="HELLO")
        info = DeviceInfo.from_fields(frame.args)
        if info.protocol != PROTOCOL_VERSION:
            raise DeviceError(f"device {info.name} speaks protocol version {info.protocol}; "
                              f"hyst speaks {PROTOCOL_VERSION}")
        self.info = info
        return info

    def move(self, knob: int, angle: float, speed: float | None = None, *,
             dwell: float | None = None, mean: float | None = None) -> Sample:
        """Move ``knob`` to ``angle`` (deg) and return where it got, its current and the tip.

        Parameters
        ----------
        knob : int
        angle : float
            Target knob angle (deg).
        speed : float, optional
            Knob speed (deg/s); the device's default when omitted.
        dwell : float, optional
            Hold the knob at the target this long (s) before the reply (feature ``dwell``), so
            that what lags the knob (the tendon's viscous lag, the current filter) settles.
        mean : float, optional
            Also report the mean knob angle and motor current over the last ``mean`` seconds
            before the reply, the dwell included, never before the move began (feature
            ``mean``): ``Sample.mean_angle``, ``Sample.mean_current``, ``Sample.mean_time``.

        Raises
        ------
        DeviceError
            A bad argument, or an option the device did not announce in its handshake.
        """
        angle = float(angle)
        if not math.isfinite(angle):
            raise DeviceError(f"refusing to send a non-finite target angle ({angle!r}) to knob {knob}")
        args: list[Any] = [int(knob), angle]
        if speed is not None:
            if not (speed > 0 and math.isfinite(speed)):
                raise DeviceError(f"knob speed must be positive and finite, got {speed!r}")
            args.append(float(speed))
        for option, value, lo_ok in (("dwell", dwell, True), ("mean", mean, False)):
            if value is None:
                continue
            if not (math.isfinite(value) and (value >= 0 if lo_ok else value > 0)
                    and value <= MAX_DWELL):
                raise DeviceError(f"MOVE option {option} must be {'>= 0' if lo_ok else '> 0'} and "
                                  f"<= {MAX_DWELL:g} s, got {value!r}")
            self._require(option)
            args.append(f"{option}={value:.4f}")
        # the reply comes on arrival, after the dwell: the deadline counts from the request, so it
        # grows by the dwell and, when the host knows where the knob was and how fast it goes, by
        # the motion's own duration (a long move at a slow speed is not a dead link)
        timeout = self.timeout + (dwell or 0.0)
        last = self.angles.get(int(knob))
        if speed is not None and last is not None:
            timeout += abs(angle - last) / float(speed)
        sample = self._pos(self._request("MOVE", *args, expect="POS", timeout=timeout), knob)
        if mean is not None and not sample.averaged:
            raise FrameError(f"MOVE asked device {self._name()} for a mean current (mean=) and its "
                             "reply carries none (no cmean=)")
        return sample

    def supports(self, feature: str) -> bool:
        """Whether the device announced the optional protocol feature ``feature`` (False
        before the handshake)."""
        return self.info is not None and self.info.has(feature)

    def _require(self, feature: str) -> None:
        if not self.supports(feature):
            have = ",".join(self.info.features) if self.info is not None and self.info.features else "none"
            raise DeviceError(f"device {self._name()} does not offer the protocol feature "
                              f"{feature!r} (its features: {have})")

    def _name(self) -> str:
        return self.info.name if self.info is not None else self.port_name

    def state(self, knob: int) -> Sample:
        """Read ``knob``'s angle, motor current and tip angle without moving it."""
        return self._pos(self._request("STATE", int(knob), expect="POS"), knob)

    def stop(self) -> bool:
        """Stop every motor. Never raises; True when the device confirmed.

        Tries up to three times (a garbled reply must not leave a motor running), with a short
        deadline each.
        """
        if self._closed:
            return False
        try:
            for _ in range(3):
                try:
                    self._request("STOP", expect="STOPPED", timeout=min(self.timeout, 0.5))
                    return True
                except (LinkError, DeviceError):
                    if self._closed or self._dead:
                        return False
                except Exception:  # noqa: BLE001 - stop() is the last line of defence
                    return False
            return False
        finally:
            self._stop_was_last = True

    # ---- internals -------------------------------------------------------------------------
    _dead = False            # the port failed (read/write error): no point in retrying
    _stop_was_last = False   # the last thing done was stop(): __exit__ need not repeat it

    def _pos(self, frame: Frame, knob: int) -> Sample:
        sample = parse_pos(frame.args)
        if sample.knob != int(knob):
            raise FrameError(f"reply is for knob {sample.knob}, request was for knob {knob}")
        self.angles[sample.knob] = sample.angle
        return sample

    def _next_seq(self) -> int:
        self._seq = (self._seq + 1) % SEQ_MODULO
        return self._seq

    def _request(self, verb: str, *args: Any, expect: str, timeout: float | None = None) -> Frame:
        if self._closed:
            raise LinkError(f"port {self.port_name} is closed")
        seq = self._next_seq()
        self.requests += 1
        self._stop_was_last = False
        self._write(encode_frame(seq, verb, *args))
        deadline = time.monotonic() + (self.timeout if timeout is None else timeout)
        while True:
            line = self._read_line(deadline, verb)
            if not line.strip():
                continue  # an empty line is a no-op on both sides
            try:
                frame = decode_frame(line)
            except FrameError as exc:  # never acted on
                raise FrameError(f"corrupt reply to {verb} from {self.port_name}: {exc}") from None
            if frame.seq is NO_SEQ:
                code = frame.args[0] if frame.args else "?"
                if frame.verb == "ERR" and code in ("E_CRC", "E_FRAME"):
                    raise LinkError(f"the device received our {verb} corrupted ({code}); "
                                    "it did nothing")
                raise FrameError(f"reply without a sequence number to {verb}: {_show(line)}")
            if frame.seq != seq:
                self.stale_replies += 1  # the late answer to an earlier request: not ours
                continue
            if frame.verb == "ERR":
                code = frame.args[0] if frame.args else "E_?"
                msg = " ".join(frame.args[1:]) or ERROR_CODES.get(code, "no message")
                raise DeviceError(f"device error {code} on {verb}: {msg}")
            if frame.verb != expect:
                raise FrameError(f"expected a {expect} reply to {verb}, got {frame.verb}")
            return frame

    def _write(self, data: bytes) -> None:
        try:
            n = self._port.write(data)
            if n is not None and n != len(data):
                raise LinkError(f"port {self.port_name}: wrote {n} of {len(data)} bytes")
            flush = getattr(self._port, "flush", None)
            if flush is not None and not hasattr(self._port, "fd"):
                flush()  # posix ports write synchronously; others may buffer
        except LinkError:
            raise
        except Exception as exc:  # noqa: BLE001 - SerialException, OSError, ...
            self._dead = True
            raise LinkError(f"device disconnected (write to {self.port_name} failed: {exc})") from None

    def _read_line(self, deadline: float, verb: str) -> bytes:
        buf = self._buf
        while True:
            nl = buf.find(b"\n")
            if nl >= 0:
                line = bytes(buf[:nl + 1])
                del buf[:nl + 1]
                if len(line) > MAX_FRAME:
                    raise FrameError(f"frame of {len(line)} bytes exceeds {MAX_FRAME}")
                return line
            if len(buf) > MAX_FRAME:
                buf.clear()
                raise FrameError(f"more than {MAX_FRAME} bytes without a newline from "
                                 f"{self.port_name}")
            if time.monotonic() >= deadline:
                raise LinkError(f"no reply to {verb} from {self.port_name} within "
                                f"{self.timeout:g} s")
            try:
                waiting = getattr(self._port, "in_waiting", 0) or 0
                chunk = self._port.read(max(1, min(int(waiting), 4096)))
            except Exception as exc:  # noqa: BLE001 - SerialException, OSError, ...
                self._dead = True
                raise LinkError(f"device disconnected (read from {self.port_name} failed: "
                                f"{exc})") from None
            if chunk:
                buf.extend(chunk)
