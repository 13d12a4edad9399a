"""The line protocol codec and the host driver below the pseudo-terminal (codec, loop://, fuzz)."""
from __future__ import annotations

import math

import pytest
import serial
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hystcli.device import (MAX_FRAME, Device, DeviceInfo, Frame, FrameError, Sample, crc8,
                            decode_frame, encode_frame, parse_pos)
from hystcli.device.emulator import DeviceEmulator
from hystcli.errors import DeviceError, HystError, LinkError


# ------------------------------------------------------------------------------------------
# checksum and frames
# ------------------------------------------------------------------------------------------
def test_crc8_check_value_of_the_catalogue():
    # CRC-8/SMBus (poly 0x07, init 0): the CRC catalogue's check value for "123456789" is 0xF4
    assert crc8(b"123456789") == 0xF4
    assert crc8(b"") == 0x00
    # one byte 0x01 -> the polynomial itself (0x07), by the definition of a CRC with init 0
    assert crc8(b"\x01") == 0x07


def test_encode_layout_and_checksum():
    frame = encode_frame(12, "MOVE", 1, 2.5, 20.0)
    body = b"12 MOVE 1 2.5000 20.0000"
    assert frame == body + b"*%02X\n" % crc8(body)


def test_decode_reads_fields_and_tolerates_crlf():
    body = b"7 POS 2 -1.2500 130.0000 -"
    line = body + b"*%02X\r\n" % crc8(body)
    assert decode_frame(line) == Frame(7, "POS", ("2", "-1.2500", "130.0000", "-"))
    s = parse_pos(decode_frame(line).args)
    assert (s.knob, s.angle, s.current, s.tip) == (2, -1.25, 130.0, None)


def test_lower_case_checksum_refused():
    body = b"1 HELLO"  # its checksum, A3, has a letter digit
    assert decode_frame(body + b"*%02X\n" % crc8(body)).verb == "HELLO"
    with pytest.raises(FrameError, match="upper-case"):
        decode_frame(body + b"*%02x\n" % crc8(body))


@pytest.mark.parametrize("line, words", [
    (b"1 HELLO\n", "no checksum"),
    (b"1 HELLO*00\n", "checksum mismatch"),
    (b"1 HELLO*ZZ\n", "hex"),
    (b"1 HE\x01LLO*00\n", "non-printable"),
    (b"x" * (MAX_FRAME + 1), "exceeds"),
])
def test_decode_refuses_bad_lines(line, words):
    with pytest.raises(FrameError, match=words):
        decode_frame(line)


def test_decode_refuses_bad_seq_and_verb_even_with_a_good_checksum():
    for body in (b"70000 STOP", b"-1 STOP", b"1 stop", b"1  STOP", b"STOP"):
        with pytest.raises(FrameError):
            decode_frame(body + b"*%02X\n" % crc8(body))


def test_frame_error_is_a_link_error():
    # a corrupt frame is a link fault, never a device-reported error
    assert issubclass(FrameError, LinkError) and not issubclass(FrameError, DeviceError)


def test_encode_refuses_what_cannot_be_sent():
    for args in ((math.nan,), ("a b",), ("a*b",), ("",)):
        with pytest.raises(FrameError):
            encode_frame(1, "MOVE", *args)
    with pytest.raises(FrameError):
        encode_frame(65536, "STOP")


def test_handshake_fields_round_trip():
    info = DeviceInfo(1, "rig7", "ice-b", (1,), False, {"fw": "2.1"})
    assert DeviceInfo.from_fields(tuple(info.to_fields())) == info
    with pytest.raises(FrameError, match="tracker"):
        DeviceInfo.from_fields(("1", "name=a", "catheter=b", "knobs=1"))


def test_handshake_features_are_optional():
    # a base-protocol device sends no features=; one with the optional features lists them
    base = DeviceInfo.from_fields(("1", "name=a", "catheter=b", "knobs=1,2", "tracker=1"))
    assert base.features == () and not base.has("mean")
    info = DeviceInfo(1, "rig7", "ice-b", (1, 2), True, {"fw": "2.1"}, ("dwell", "mean"))
    fields = info.to_fields()
    assert "features=dwell,mean" in fields
    back = DeviceInfo.from_fields(tuple(fields))
    assert back == info and back.has("dwell") and dict(back.extra) == {"fw": "2.1"}
    # a feature this host does not know yet is kept, not an error
    assert DeviceInfo.from_fields(tuple(fields[:-2]) + ("features=mean,warp9",)).features == ("mean", "warp9")
    # a device's own key of that name that is not a feature list stays an unknown key
    odd = DeviceInfo.from_fields(("1", "name=a", "catheter=b", "knobs=1", "tracker=0", "features=LED_Blue"))
    assert odd.features == () and dict(odd.extra) == {"features": "LED_Blue"}


def test_pos_with_the_mean_fields():
    s = parse_pos(("1", "18.5000", "121.8000", "-", "qmean=18.4000", "cmean=121.2500", "tmean=0.3000"))
    assert (s.angle, s.current, s.tip) == (18.5, 121.8, None)
    assert (s.mean_angle, s.mean_current, s.mean_time, s.averaged) == (18.4, 121.25, 0.3, True)
    plain = parse_pos(("2", "1.0000", "120.0000", "0.5000"))
    assert not plain.averaged and plain.mean_angle is None
    # a field this host does not know is ignored (a later optional feature)
    assert parse_pos(("1", "1.0", "2.0", "3.0", "torque=9")) == Sample(1, 1.0, 2.0, 3.0)


@pytest.mark.parametrize("args, words", [
    (("1", "1.0", "2.0", "-", "cmean=3.0"), "only one of qmean"),
    (("1", "1.0", "2.0", "-", "qmean=1.0", "cmean=3.0", "cmean=3.0"), "repeats"),
    (("1", "1.0", "2.0", "-", "5.0"), "not key=value"),
    (("1", "1.0", "2.0", "qmean=1.0", "cmean=3.0"), "positional"),
    (("1", "1.0", "2.0", "-", "qmean=1.0", "cmean=nan"), "mean motor current"),
    (("1", "1.0", "2.0", "-", "qmean=1.0", "cmean=3.0", "tmean=-1"), "negative"),
])
def test_pos_refuses_bad_mean_fields(args, words):
    with pytest.raises(FrameError, match=words):
        parse_pos(args)


# ------------------------------------------------------------------------------------------
# fuzz: the codec raises nothing but FrameError, round trips, and catches every bit flip
# ------------------------------------------------------------------------------------------
FIELD = st.text(st.characters(min_codepoint=0x21, max_codepoint=0x7E, blacklist_characters="*"),
                min_size=1, max_size=12)
VERB = st.from_regex(r"\A[A-Z][A-Z0-9_]{0,8}\Z")


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=200))
def test_decode_random_bytes_only_frame_error(data):
    try:
        frame = decode_frame(data)
    except FrameError:
        return
    assert isinstance(frame, Frame)


@settings(max_examples=300, deadline=None)
@given(st.one_of(st.none(), st.integers(0, 65535)), VERB, st.lists(FIELD, max_size=6))
def test_encode_decode_round_trip(seq, verb, args):
    assert decode_frame(encode_frame(seq, verb, *args)) == Frame(seq, verb, tuple(args))


@settings(max_examples=300, deadline=None)
@given(st.integers(0, 65535), st.sampled_from(["MOVE", "POS", "STATE"]),
       st.lists(st.floats(-1e6, 1e6, allow_nan=False), min_size=1, max_size=4), st.data())
def test_any_single_bit_flip_is_detected(seq, verb, values, data):
    # CRC-8 with polynomial 0x07 detects every single-bit error (its generator has >1 term)
    frame = bytearray(encode_frame(seq, verb, *values))
    i = data.draw(st.integers(0, len(frame) - 2))  # any byte but the final newline
    bit = data.draw(st.integers(0, 7))
    frame[i] ^= 1 << bit
    with pytest.raises(FrameError):
        decode_frame(bytes(frame))


class _CountingTwin:
    """A stand-in below the transport: counts the moves the device side makes."""

    knobs = (1, 2)
    tip_available = True
    catheter = "fake"

    def __init__(self):
        self.moved = 0

    def move(self, knob, q, speed_deg_s=20.0):
        self.moved += 1
        return q, 100.0, q / 2

    def state(self, knob):
        return 0.0, 100.0, 0.0


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.binary(max_size=180))
def test_device_side_never_crashes_and_never_moves_on_garbage(data):
    twin = _CountingTwin()
    emu = DeviceEmulator(twin)
    replies = emu.handle_line(data)
    try:
        frame = decode_frame(data)
        valid_move = frame.verb == "MOVE"
    except FrameError:
        valid_move = False
    if not valid_move:
        assert twin.moved == 0
    for reply, _delay in replies:
        decode_frame(reply)  # every reply the device sends is itself a valid frame


class _ScriptedPort:
    """A pyserial-like object that answers any request with fixed bytes (below the transport)."""

    def __init__(self, answer: bytes):
        self.answer = answer
        self.pending = b""
        self.timeout = None

    def write(self, data):
        if data.strip():
            self.pending += self.answer
        return len(data)

    def read(self, n=1):
        out, self.pending = self.pending[:n], self.pending[n:]
        return out


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=120))
def test_host_raises_only_hyst_errors_on_random_replies(answer):
    dev = Device(_ScriptedPort(answer), timeout=0.01, handshake=False)
    try:
        dev.move(1, 1.0)
    except (LinkError, DeviceError):
        pass


def test_host_reads_a_good_reply_from_a_scripted_port():
    body = b"1 POS 1 2.0000 150.0000 1.5000"
    dev = Device(_ScriptedPort(body + b"*%02X\n" % crc8(body)), timeout=0.1, handshake=False)
    s = dev.move(1, 2.0)
    assert (s.angle, s.current, s.tip) == (2.0, 150.0, 1.5)


class _RecordingPort(_ScriptedPort):
    def __init__(self, answer: bytes):
        super().__init__(answer)
        self.sent: list[bytes] = []

    def write(self, data):
        self.sent.append(data)
        return super().write(data)


def _featured(port) -> Device:
    """A driver whose handshake (not sent) announced the features dwell and mean."""
    dev = Device(port, timeout=0.1, handshake=False)
    dev.info = DeviceInfo(1, "rig", "c", (1, 2), True, {}, ("dwell", "mean"))
    return dev


def test_host_sends_the_options_and_reads_the_mean():
    body = b"1 POS 1 2.0000 150.0000 1.5000 qmean=2.0000 cmean=149.2500 tmean=0.3000"
    port = _RecordingPort(body + b"*%02X\n" % crc8(body))
    s = _featured(port).move(1, 2.0, 5.0, dwell=0.35, mean=0.3)
    assert port.sent[-1] == encode_frame(1, "MOVE", 1, 2.0, 5.0, "dwell=0.3500", "mean=0.3000")
    assert (s.mean_angle, s.mean_current, s.mean_time) == (2.0, 149.25, 0.3)


def test_host_refuses_a_reply_without_the_mean_it_asked_for():
    body = b"1 POS 1 2.0000 150.0000 1.5000"
    dev = _featured(_ScriptedPort(body + b"*%02X\n" % crc8(body)))
    with pytest.raises(LinkError, match="carries none"):
        dev.move(1, 2.0, mean=0.3)


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 65535), st.floats(-170, 170), st.floats(-5e3, 5e3), st.floats(-170, 170),
       st.floats(0.001, 10.0))
def test_pos_mean_round_trip(seq, q, c, qm, t):
    # what the emulator sends (4 decimals) is what the host reads, to the 4th decimal
    frame = encode_frame(seq, "POS", 1, q, c, "-", f"qmean={qm:.4f}", f"cmean={c:.4f}", f"tmean={t:.4f}")
    s = parse_pos(decode_frame(frame).args)
    assert abs(s.mean_angle - qm) <= 5e-5 and abs(s.mean_current - c) <= 5e-5
    assert abs(s.mean_time - t) <= 5e-5 and abs(s.angle - q) <= 5e-5


# ------------------------------------------------------------------------------------------
# the driver over a pyserial URL (loop://: what is written is read back)
# ------------------------------------------------------------------------------------------
def test_driver_over_loop_url_matches_replies_by_sequence_number():
    port = serial.serial_for_url("loop://", timeout=0.05)
    # a stale reply (seq 0) and the fresh one (seq 1) queued before the request
    port.write(encode_frame(0, "POS", 1, 9.0, 999.0, 9.0))
    port.write(encode_frame(1, "POS", 1, 2.0, 140.0, 1.0))
    dev = Device(port, timeout=0.5, handshake=False)
    s = dev.move(1, 2.0)
    assert (s.angle, s.current, s.tip) == (2.0, 140.0, 1.0)
    assert dev.stale_replies == 1
    dev.close()
    assert port.is_open  # a port passed in is the caller's to close


def test_driver_over_loop_url_refuses_a_reply_of_the_wrong_kind():
    # over loop:// the request itself comes back: right seq, wrong verb -> link fault
    dev = Device("loop://", timeout=0.2, handshake=False)
    with pytest.raises(LinkError, match="expected a POS reply"):
        dev.move(1, 2.0)
    dev.close()


def test_driver_reports_device_errors_apart():
    port = serial.serial_for_url("loop://", timeout=0.05)
    port.write(encode_frame(1, "ERR", "E_RANGE", "too", "far"))
    dev = Device(port, timeout=0.5, handshake=False)
    with pytest.raises(DeviceError, match="E_RANGE.*too far"):
        dev.move(1, 500.0)


def test_driver_turns_a_corrupt_frame_notice_into_a_link_error():
    port = serial.serial_for_url("loop://", timeout=0.05)
    port.write(encode_frame(None, "ERR", "E_CRC", "frame", "refused"))
    dev = Device(port, timeout=0.5, handshake=False)
    with pytest.raises(LinkError, match="corrupted"):
        dev.state(1)


def test_unopenable_port_is_a_link_error():
    with pytest.raises(LinkError, match="cannot open port /nonexistent/tty"):
        Device("/nonexistent/tty", timeout=0.1)


def test_stop_on_a_closed_device_does_not_raise():
    dev = Device("loop://", timeout=0.05, handshake=False)
    dev.close()
    assert dev.stop() is False
    with pytest.raises(LinkError, match="closed"):
        dev.state(1)


def test_all_driver_errors_are_hyst_errors():
    assert issubclass(LinkError, HystError) and issubclass(DeviceError, HystError)
