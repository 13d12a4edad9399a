"""The live robot link: the hyst line protocol (docs/protocol.md) and the host-side driver.

Owns three things:

* the frame codec shared by both ends (:func:`crc8`, :func:`encode_frame`, :func:`decode_frame`):
  ``SEQ VERB ARGS*XX\\n`` with a CRC-8 over everything before ``*``, so a corrupted line is
  detected and never acted on;
* :class:`Device`, the driver: opens a port name, a pyserial URL (``loop://``, ``socket://``,
  ``rfc2217://``) or takes any already-open pyserial-like object; every read has a deadline;
  a reply is matched to its request by sequence number so a stale reply is never taken for a
  fresh one. Faults are kept apart: :class:`~hystcli.errors.DeviceError` when the device
  answered with ``ERR``, :class:`~hystcli.errors.LinkError` when the link failed (no reply,
  corrupt or malformed frame, disconnect);
* :class:`DeviceProbe`, the live probe of Algorithm 1 (``hystcli.shift``): step one knob, read
  its motor current, with a current ceiling (contact) that stops every motor and raises
  :class:`~hystcli.errors.SafetyStop`. It steps and dwells, reading the mean current over the
  dwell, when the device offers the optional protocol features ``dwell`` and ``mean``
  (:data:`FEATURES`), as the replay probe averages the current over each step.

The core never prints; the CLI (``hystcli/cli/device_cmds.py``) renders.
"""
from __future__ import annotations

import math
import re
import time
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Mapping

from .errors import DeviceError, LinkError, SafetyStop
from .shift import ProbeSample

PROTOCOL_VERSION = 1
FEATURES = ("dwell", "mean")
"""Optional features of protocol 1 this host understands (docs/protocol.md, "Optional
features"): ``dwell`` (``MOVE ... dwell=S``: hold the target S seconds before answering) and
``mean`` (``MOVE ... mean=S``: the reply adds the mean knob angle and motor current over the
last S seconds before it). A device announces the ones it has in its handshake; they were added
without a version bump because neither side sends them unless both know them."""
MAX_DWELL = 10.0         # s: the longest dwell and averaging window a MOVE may ask for
MAX_FRAME = 160          # bytes, newline included; longer lines are a framing error
SEQ_MODULO = 65536       # sequence numbers run 0..65535 and wrap
NO_SEQ = None            # the ``?`` sequence of a device reply to a frame it could not decode

# error codes a device may send (docs/protocol.md, "Errors")
ERROR_CODES = {
    "E_CRC": "the device received a frame whose checksum failed (nothing was done)",
    "E_FRAME": "the device received a malformed frame (nothing was done)",
    "E_CMD": "unknown command",
    "E_ARG": "bad or missing argument",
    "E_KNOB": "no such knob",
    "E_RANGE": "target outside the device's travel limits",
    "E_MOTOR": "motor fault (stall, driver error)",
    "E_BUSY": "the device cannot take the command now",
}


# --------------------------------------------------------------------------------------------
# frame codec
# --------------------------------------------------------------------------------------------
def _crc8_table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = ((crc << 1) ^ 0x07) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
        table.append(crc)
    return tuple(table)


_CRC8 = _crc8_table()


def crc8(data: bytes) -> int:
    """CRC-8/SMBus (polynomial 0x07, init 0x00, no reflection, no final xor) of ``data``.

    Its check value is ``crc8(b"123456789") == 0xF4``. It detects every single-bit and every
    odd-bit error and every burst up to 8 bits, which a plain XOR checksum does not.
    """
    crc = 0
    for b in data:
        crc = _CRC8[crc ^ b]
    return crc


class FrameError(LinkError):
    """A line that is not a valid frame: bad checksum, bad characters, bad layout, too long."""


@dataclass(frozen=True)
class Frame:
    """One decoded frame.

    Attributes
    ----------
    seq : int or None
        Sequence number (0..65535); ``None`` for ``?`` (a device reply to a frame it could not
        decode, so whose number it cannot know).
    verb : str
        Command or reply word, upper case (``HELLO``, ``MOVE``, ``POS``, ``ERR``, ...).
    args : tuple of str
        The space-separated fields after the verb.
    """

    seq: int | None
    verb: str
    args: tuple[str, ...] = ()


_VERB = re.compile(r"[A-Z][A-Z0-9_]{0,15}\Z")
_SEQ = re.compile(r"[0-9]{1,5}\Z")
_NUMBER = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]{1,3})?\Z")
_FEATURE = re.compile(r"[a-z][a-z0-9_]{0,15}\Z")


def _check_field(text: str, what: str) -> None:
    if not text or any(not (0x21 <= ord(ch) <= 0x7E) or ch == "*" for ch in text):
        raise FrameError(f"cannot encode {what} {text!r}: fields are printable ASCII without "
                         "spaces or '*'")


def encode_frame(seq: int | None, verb: str, *args: Any) -> bytes:
    """Encode one frame: ``SEQ VERB ARG...*XX\\n``.

    Parameters
    ----------
    seq : int or None
        Sequence number, 0..65535 (``None`` writes ``?``).
    verb : str
        Upper-case word.
    *args
        Fields; floats are written with 4 decimals, other values with ``str``. A field may not
        contain spaces or ``*``, except the message of ``ERR`` (the fields after its code),
        whose words are sent as separate fields.

    Raises
    ------
    FrameError
        A field that cannot be sent, or a frame longer than :data:`MAX_FRAME`.
    """
    if seq is None:
        head = "?"
    else:
        if not (isinstance(seq, int) and 0 <= seq < SEQ_MODULO):
            raise FrameError(f"sequence number {seq!r} outside 0..{SEQ_MODULO - 1}")
        head = str(seq)
    if not _VERB.match(verb):
        raise FrameError(f"bad verb {verb!r}")
    parts = [head, verb]
    for a in args:
        if isinstance(a, float):
            if not math.isfinite(a):
                raise FrameError(f"cannot send a non-finite number ({a!r})")
            # fixed point keeps frames short and readable; huge values go to exponent form
            text = f"{a:.4f}" if abs(a) < 1e9 else f"{a:.6e}"
        else:
            text = str(a)
        _check_field(text, "field")
        parts.append(text)
    body = " ".join(parts).encode("ascii")
    frame = body + b"*%02X\n" % crc8(body)
    if len(frame) > MAX_FRAME:
        raise FrameError(f"frame of {len(frame)} bytes exceeds {MAX_FRAME}")
    return frame


def decode_frame(line: bytes) -> Frame:
    """Decode one line (with or without its ``\\n``, ``\\r\\n`` tolerated) into a :class:`Frame`.

    Raises
    ------
    FrameError
        On anything but a well-formed frame whose checksum matches: the only error it raises,
        whatever the bytes.
    """
    if not isinstance(line, (bytes, bytearray)):
        raise FrameError(f"a frame is bytes, got {type(line).__name__}")
    if len(line) > MAX_FRAME:
        raise FrameError(f"frame of {len(line)} bytes exceeds {MAX_FRAME}")
    raw = bytes(line)
    if raw.endswith(b"\n"):
        raw = raw[:-1]
    if raw.endswith(b"\r"):
        raw = raw[:-1]
    star = raw.rfind(b"*")
    if star < 0 or len(raw) - star != 3:
        raise FrameError(f"no checksum at the end of the frame {_show(line)}")
    body, hexsum = raw[:star], raw[star + 1:]
    if any(not (0x20 <= b <= 0x7E) or b == 0x2A for b in body):
        raise FrameError(f"non-printable byte or '*' in the frame {_show(line)}")
    # upper case only: then a flipped bit in the checksum itself is caught too
    if not all(c in b"0123456789ABCDEF" for c in hexsum):
        raise FrameError(f"checksum is not two upper-case hex digits in {_show(line)}")
    want = int(hexsum.decode("ascii"), 16)
    got = crc8(body)
    if got != want:
        raise FrameError(f"checksum mismatch (frame says {want:02X}, content gives {got:02X}) "
                         f"in {_show(line)}")
    fields = body.decode("ascii").split(" ")
    if len(fields) < 2 or any(f == "" for f in fields):
        raise FrameError(f"malformed frame {_show(line)}: expected 'SEQ VERB [ARGS]' "
                         "separated by single spaces")
    seq_text, verb = fields[0], fields[1]
    if seq_text == "?":
        seq = NO_SEQ
    elif _SEQ.match(seq_text) and int(seq_text) < SEQ_MODULO:
        seq = int(seq_text)
    else:
        raise FrameError(f"bad sequence number {seq_text!r} in {_show(line)}")
    if not _VERB.match(verb):
        raise FrameError(f"bad verb {verb!r} in {_show(line)}")
    return Frame(seq, verb, tuple(fields[2:]))


def parse_number(text: str, what: str) -> float:
    """A finite decimal number from a frame field (raises :class:`FrameError` naming ``what``)."""
    if not _NUMBER.match(text):
        raise FrameError(f"{what} {text!r} is not a number")
    value = float(text)
    if not math.isfinite(value):
        raise FrameError(f"{what} {text!r} is not finite")
    return value


def parse_knob(text: str) -> int:
    """A knob index (1..9) from a frame field."""
    if len(text) != 1 or not "1" <= text <= "9":
        raise FrameError(f"knob {text!r} is not a knob index 1..9")
    return int(text)


def _show(line: bytes | bytearray) -> str:
    text = bytes(line[:60]).decode("ascii", "backslashreplace")
    return repr(text + ("..." if len(line) > 60 else ""))


# --------------------------------------------------------------------------------------------
# replies
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class DeviceInfo:
    """What the device says about itself in the handshake.

    Attributes
    ----------
    protocol : int
        Protocol version (this driver speaks :data:`PROTOCOL_VERSION`).
    name : str
        Device name (controller model or serial number).
    catheter : str
        The catheter mounted on the handle.
    knobs : tuple of int
        Knob indices the device drives.
    tracker : bool
        Whether replies carry a measured tip angle (EM tracker).
    extra : mapping of str to str
        Any other ``key=value`` the device sent (kept, never an error).
    features : tuple of str
        Optional protocol features the device announced (``features=dwell,mean``): the ``MOVE``
        options it accepts (:data:`FEATURES`). Empty for a device of the base protocol.
    """

    protocol: int
    name: str
    catheter: str
    knobs: tuple[int, ...]
    tracker: bool
    extra: Mapping[str, str] = field(default_factory=dict)
    features: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "extra", MappingProxyType(dict(self.extra)))
        object.__setattr__(self, "features", tuple(self.features))

    def has(self, feature: str) -> bool:
        """Whether the device announced the optional protocol feature ``feature``."""
        return feature in self.features

    def as_meta(self) -> dict[str, str]:
        """Run metadata describing the device (``device``, ``device_protocol``, ...)."""
        meta = {"device": self.name, "device_protocol": str(self.protocol),
                "device_catheter": self.catheter,
                "device_knobs": ",".join(str(k) for k in self.knobs),
                "device_tracker": "yes" if self.tracker else "no"}
        if self.features:
            meta["device_features"] = ",".join(self.features)
        meta.update({f"device_{k}": v for k, v in self.extra.items()})
        return meta

    def to_fields(self) -> list[str]:
        """The handshake reply fields (used by the device side)."""
        out = [str(self.protocol), f"name={self.name}", f"catheter={self.catheter}",
               "knobs=" + ",".join(str(k) for k in self.knobs), f"tracker={int(self.tracker)}"]
        if self.features:
            out.append("features=" + ",".join(self.features))
        out += [f"{k}={v}" for k, v in self.extra.items()]
        return out

    @classmethod
    def from_fields(cls, args: tuple[str, ...]) -> "DeviceInfo":
        """Parse the handshake reply fields (raises :class:`FrameError` on a malformed one)."""
        if not args or not _SEQ.match(args[0]):
            raise FrameError(f"handshake reply lacks a protocol version (got {' '.join(args)!r})")
        kv: dict[str, str] = {}
        for a in args[1:]:
            key, sep, value = a.partition("=")
            if not sep or not key:
                raise FrameError(f"handshake field {a!r} is not key=value")
            kv[key] = value
        for key in ("name", "catheter", "knobs", "tracker"):
            if key not in kv:
                raise FrameError(f"handshake reply lacks {key}=")
        try:
            knobs = tuple(parse_knob(k) for k in kv.pop("knobs").split(","))
        except FrameError as exc:
            raise FrameError(f"handshake knobs: {exc}") from None
        tracker = kv.pop("tracker")
        if tracker not in ("0", "1"):
            raise FrameError(f"handshake tracker={tracker!r} is not 0 or 1")
        features: tuple[str, ...] = ()
        words = tuple(kv.get("features", "").split(","))
        if "features" in kv and all(_FEATURE.match(f) for f in words):
            features = words
            del kv["features"]
        # else: not a feature list of this protocol (a device's own key of that name, from
        # before the optional features): kept as an unknown key, as every other one, no error
        return cls(int(args[0]), kv.pop("name"), kv.pop("catheter"), knobs, tracker == "1", kv,
                   features)


@dataclass(frozen=True)
class Sample:
    """One ``POS`` reply: where a knob is and what its motor draws.

    Attributes
    ----------
    knob : int
    angle : float
        Knob angle reached (deg).
    current : float
        Motor current (mA).
    tip : float or None
        Tip bending angle from the tracker (deg); None when the device has none.
    mean_angle, mean_current, mean_time : float or None
        The mean knob angle (deg) and motor current (mA) over the averaging window a
        ``MOVE ... mean=S`` asked for, and the time averaged (s); None otherwise (feature
        ``mean``).
    """

    knob: int
    angle: float
    current: float
    tip: float | None
    mean_angle: float | None = None
    mean_current: float | None = None
    mean_time: float | None = None

    @property
    def averaged(self) -> bool:
        """Whether the reply carried the mean current of an averaging window (``cmean=``)."""
        return self.mean_current is not None


# the optional fields of a POS reply (feature "mean"): name -> (Sample attribute, what)
_POS_OPTIONS = {"qmean": ("mean_angle", "mean knob angle"),
                "cmean": ("mean_current", "mean motor current"),
                "tmean": ("mean_time", "averaging time")}


def parse_pos(args: tuple[str, ...]) -> Sample:
    """Parse the fields of a ``POS`` reply: ``KNOB ANGLE CURRENT TIP [key=value ...]``.

    ``TIP`` may be ``-`` (no tracker). The optional fields ``qmean=``, ``cmean=`` and
    ``tmean=`` (feature ``mean``, docs/protocol.md) fill the ``mean_*`` attributes; other
    ``key=value`` fields are ignored, so that a later optional field never breaks this host.
    """
    if len(args) < 4 or any("=" in a for a in args[:4]):
        raise FrameError(f"POS reply has {sum('=' not in a for a in args)} positional fields, "
                         "expected 4 (knob angle current tip)")
    tip = None if args[3] == "-" else parse_number(args[3], "tip angle")
    extra: dict[str, float] = {}
    for a in args[4:]:
        key, sep, value = a.partition("=")
        if not sep or not key:
            raise FrameError(f"POS reply field {a!r} after the 4 positional ones is not key=value")
        if key in _POS_OPTIONS:
            attr, what = _POS_OPTIONS[key]
            if attr in extra:
                raise FrameError(f"POS reply repeats {key}=")
            extra[attr] = parse_number(value, what)
    if ("mean_angle" in extra) != ("mean_current" in extra):
        raise FrameError("POS reply has only one of qmean= and cmean= (a mean comes as both)")
    if extra.get("mean_time", 0.0) < 0:
        raise FrameError(f"POS reply has a negative averaging time tmean={extra['mean_time']:g}")
    return Sample(parse_knob(args[0]), parse_number(args[1], "knob angle"),
                  parse_number(args[2], "motor current"), tip, **extra)


# --------------------------------------------------------------------------------------------
# the driver
# --------------------------------------------------------------------------------------------
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


# --------------------------------------------------------------------------------------------
# the live probe of Algorithm 1
# --------------------------------------------------------------------------------------------
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
