"""The emulator and the driver over a REAL pseudo-terminal: round trips and faults.

The live twin on one end (``serve`` in a thread), :class:`Device` on the other; nothing is
mocked above the transport.
"""
from __future__ import annotations

import os
import time
from dataclasses import replace

import pytest
import serial

from hystcli.device import Device, DeviceProbe, crc8, decode_frame, encode_frame
from hystcli.emulator import DeviceEmulator, Fault, PtyServer, serve
from hystcli.errors import DataError, DeviceError, LinkError, SafetyStop
from hystcli.twin import LiveTwin, get_catheter

CAT = get_catheter("ice-a")


def _twin(**kw):
    return LiveTwin(CAT, **kw)


@pytest.fixture
def server():
    srv = serve(_twin(seed=3))
    yield srv
    srv.shutdown()


@pytest.fixture
def device(server):
    dev = Device(server.path, timeout=0.5)
    yield dev
    dev.close()


def _fault(server, kind, after=1, **kw):
    """Inject a fault that fires on the ``after``-th next MOVE."""
    server.emulator.inject(Fault(kind, at=server.emulator.moves + after, **kw))


# ------------------------------------------------------------------------------------------
# round trips
# ------------------------------------------------------------------------------------------
def test_path_is_a_terminal(server):
    assert server.path.startswith("/dev/")
    fd = os.open(server.path, os.O_RDWR | os.O_NOCTTY)
    try:
        assert os.isatty(fd)
    finally:
        os.close(fd)


def test_handshake_gives_identity(device):
    info = device.info
    assert (info.protocol, info.name, info.catheter, info.knobs, info.tracker) == \
        (1, "hyst-sim", "ice-a", (1, 2), True)
    assert device.info.as_meta()["device_catheter"] == "ice-a"


def test_move_state_stop_relay_the_twin(server, device):
    # the same moves on a second twin of the same seed: the device must relay exactly its readings
    ref = _twin(seed=3)
    for q in (5.0, 15.0, -3.0):
        s = device.move(1, q, 20.0)
        rq, rc, ry = ref.move(1, q, speed_deg_s=20.0)
        assert s.angle == pytest.approx(q, abs=1e-4)
        assert s.current == pytest.approx(rc, abs=1e-4)
        assert s.tip == pytest.approx(ry, abs=1e-4)
    st = device.state(1)
    assert st.angle == pytest.approx(-3.0, abs=1e-4)
    assert device.stop() is True
    assert server.emulator.stops == 1


def test_current_grows_once_the_tendon_is_taut(device):
    # DESIGN.md section 4 on the twin: ice-a knob 1 dead zone edge d_pos = 9.1 deg (straight
    # shaft); k_load = 4 mA/deg, so 10 deg past the edge adds ~40 mA (x(1 +- mu)) over no-load
    inside = device.move(1, 2.0, 20.0).current
    device.move(1, 19.0, 20.0)
    past = device.move(1, 20.0, 20.0).current
    assert past - inside > 25.0


def test_no_tracker_sends_dash_and_driver_gives_none():
    srv = serve(_twin(tip_available=False, knobs=(1,)))
    try:
        with Device(srv.path, timeout=0.5) as dev:
            assert dev.info.tracker is False and dev.info.knobs == (1,)
            assert dev.move(1, 1.0).tip is None
            with pytest.raises(DeviceError, match="E_KNOB"):
                dev.move(2, 1.0)
    finally:
        srv.shutdown()


def test_two_sessions_on_one_server(server):
    with Device(server.path, timeout=0.5) as a:
        a.move(1, 4.0)
    with Device(server.path, timeout=0.5) as b:
        assert b.state(1).angle == pytest.approx(4.0, abs=1e-4)


def test_device_errors_for_range_and_knob(device, server):
    with pytest.raises(DeviceError, match="E_RANGE"):
        device.move(1, 400.0)
    with pytest.raises(DeviceError, match="E_KNOB"):
        device.state(7)
    assert server.emulator.moves == 1  # the range error was a MOVE, refused; state is not a move
    assert device.state(1).angle == 0.0  # nothing moved


def test_version_mismatch_is_refused():
    emu = DeviceEmulator(_twin())
    emu.info = replace(emu.info, protocol=2)
    srv = PtyServer(emu).start()
    try:
        with pytest.raises(DeviceError, match="protocol version 2"):
            Device(srv.path, timeout=0.5)
    finally:
        srv.shutdown()


# ------------------------------------------------------------------------------------------
# a corrupt frame from the host is never acted on
# ------------------------------------------------------------------------------------------
def test_corrupt_request_gets_e_crc_and_no_move(server):
    port = serial.Serial(server.path, timeout=0.5)
    try:
        good = encode_frame(5, "MOVE", 1, 30.0)
        bad = good.replace(b"30.0000", b"80.0000")  # content changed, checksum kept
        port.write(bad)
        reply = decode_frame(port.readline())
        assert (reply.seq, reply.verb, reply.args[0]) == (None, "ERR", "E_CRC")
        port.write(encode_frame(6, "STATE", 1))
        st = decode_frame(port.readline())
        assert st.seq == 6 and float(st.args[1]) == 0.0  # the knob never moved
        assert server.emulator.bad_frames == 1 and server.emulator.moves == 0
        port.write(b"1 MOVE 1 " + b"9" * 200 + b"\n")  # an endless line
        assert decode_frame(port.readline()).args[0] == "E_FRAME"
        body = b"7 DANCE 1"
        port.write(body + b"*%02X\n" % crc8(body))
        assert decode_frame(port.readline()).args[0] == "E_CMD"
    finally:
        port.close()


# ------------------------------------------------------------------------------------------
# faults -> the right exception type
# ------------------------------------------------------------------------------------------
def test_no_reply_is_a_link_error_after_the_timeout(server, device):
    _fault(server, "silent")
    t0 = time.monotonic()
    with pytest.raises(LinkError, match="no reply to MOVE"):
        device.move(1, 1.0)
    assert 0.45 < time.monotonic() - t0 < 3.0  # the deadline, not much later (loaded CI slack)


def test_garbled_reply_is_a_link_error_and_the_next_request_works(server, device):
    _fault(server, "garble")
    with pytest.raises(LinkError, match="checksum mismatch"):
        device.move(1, 1.0)
    assert device.move(1, 2.0).angle == pytest.approx(2.0, abs=1e-4)


def test_device_err_reply_is_a_device_error_not_a_link_error(server, device):
    _fault(server, "error", value="E_MOTOR")
    with pytest.raises(DeviceError, match="E_MOTOR") as exc:
        device.move(1, 1.0)
    assert not isinstance(exc.value, LinkError)


def test_late_reply_is_dropped_as_stale(server, device):
    _fault(server, "delay", value="0.7")  # answer after the 0.5 s deadline
    with pytest.raises(LinkError, match="no reply"):
        device.move(1, 1.0)
    s = device.move(1, 2.0)  # the late answer for 1.0 arrives first: it must not be taken
    assert s.angle == pytest.approx(2.0, abs=1e-4)
    assert device.stale_replies == 1


def test_pty_closed_mid_run_is_a_link_error_and_stop_is_safe(server, device):
    device.move(1, 1.0)
    _fault(server, "close")
    with pytest.raises(LinkError, match="disconnected|no reply"):
        device.move(1, 2.0)
    assert server.closed
    assert device.stop() is False  # never raises on a dead link


def test_contact_spike_is_a_safety_stop_with_the_motor_stopped(server, device):
    probe = DeviceProbe(device, 1, current_ceiling=1000.0)
    assert probe.start == 0.0
    for q in (0.5, 1.0):
        probe.step_to(q)
    _fault(server, "spike", value="5000")
    with pytest.raises(SafetyStop, match="ceiling"):
        probe.step_to(1.5)
    assert server.emulator.stops == 1
    assert probe.steps == 3 and probe.travel == pytest.approx(1.5)
    assert probe.return_to_start() is True
    assert device.state(1).angle == pytest.approx(0.0, abs=1e-4)


def test_probe_refuses_a_knob_the_device_lacks(device):
    with pytest.raises(DeviceError, match="no knob 3"):
        DeviceProbe(device, 3)


@pytest.mark.parametrize("text, fault", [
    ("garble@5", Fault("garble", 5)),
    ("error@3=E_MOTOR", Fault("error", 3, 1, "E_MOTOR")),
    ("spike@4x2=3000", Fault("spike", 4, 2, "3000")),
])
def test_fault_specs_parse(text, fault):
    assert Fault.parse(text) == fault


@pytest.mark.parametrize("text", ["boom@1", "garble", "spike@2=abc", "error@1=motor", "close@0"])
def test_bad_fault_specs_are_data_errors(text):
    with pytest.raises(DataError):
        Fault.parse(text)
