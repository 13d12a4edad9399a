"""The hyst line protocol (docs/protocol.md): the frame codec both ends share, and what a reply says.

``SEQ VERB ARGS*XX\n`` with a CRC-8 over everything before ``*`` (:func:`crc8`,
:func:`encode_frame`, :func:`decode_frame`), so a corrupted line is detected and never acted on;
the handshake's :class:`DeviceInfo` and a position reply's :class:`Sample`. The driver
(:mod:`.driver`) and the emulator (:mod:`.emulator`) speak it.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Mapping

from ..errors import LinkError

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
