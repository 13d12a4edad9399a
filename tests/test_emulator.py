"""The emulator and the driver over a REAL pseudo-terminal: round trips and faults.

The live twin on one end (``serve`` in a thread), :class:`Device` on the other; nothing is
mocked above the transport.
"""
from __future__ import annotations

import math
import os
import time
from dataclasses import replace

import numpy as np
import pytest
import serial

from hystcli.device import Device, DeviceProbe, crc8, decode_frame, encode_frame
from hystcli.device.emulator import DeviceEmulator, Fault, PtyServer, serve
from hystcli.errors import DataError, DeviceError, LinkError, SafetyStop
from hystcli.sim.live import LiveTwin
from hystcli.sim.twin import get_catheter

CAT = get_catheter("example-a")


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
        (1, "hyst-sim", "example-a", (1, 2), True)
    assert device.info.as_meta()["device_catheter"] == "example-a"
    # the optional features of protocol 1 (docs/protocol.md, "Optional features")
    assert info.features == ("dwell", "mean") and device.supports("mean")
    assert info.as_meta()["device_features"] == "dwell,mean"


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
    # docs/design.md section 4 on the twin: example-a knob 1 dead zone edge d_pos = 9.1 deg (straight
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


def test_late_reply_is_dropped_as_stale(server):
    # margins of 0.6 s and 0.4 s either way, for a busy machine: the first answer comes 1.6 s
    # after its request, past the 1 s deadline; the second request goes out then, and its answer
    # follows the late one (about 0.6 s later), well within its own deadline
    with Device(server.path, timeout=1.0) as device:
        _fault(server, "delay", value="1.6")
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


# ------------------------------------------------------------------------------------------
# optional features: step-and-dwell with the mean current
# ------------------------------------------------------------------------------------------
@pytest.fixture
def quiet_device():
    """A noise-free twin (current filter on) behind a real pty."""
    srv = serve(_twin(noise=False))
    dev = Device(srv.path, timeout=0.5)
    yield dev
    dev.close()
    srv.shutdown()


def test_dwell_mean_is_the_settled_current_computed_by_hand(quiet_device):
    # example-a knob 1 (twin.CATHETERS): d_pos 9.1 deg, b_pos 6.2 deg; current model no_load 120 mA,
    # coulomb 6 mA, k_load 4 mA/deg, mu 0.25 (twin.CurrentParams). At rest at 15 deg after a rise
    # from 0 (the friction play saturated at +1 after b/2 = 3.1 deg): tension 4 * (15 - 9.1) =
    # 23.6 mA, current 120 + 23.6 + 0.25 * 23.6 = 149.5 mA.
    s = quiet_device.move(1, 15.0, 20.0, dwell=0.35, mean=0.3)
    assert s.averaged and s.mean_time == pytest.approx(0.3)
    assert s.mean_angle == pytest.approx(15.0, abs=1e-4)
    assert s.mean_current == pytest.approx(149.5, abs=0.05)
    # the plain reply to a move on to 16 deg is read while moving at 20 deg/s: the static
    # current there (149.5 + 5 mA/deg x 1 deg = 154.5 mA), plus the 6 mA Coulomb term of a
    # moving motor, minus the causal filter's lag on the 100 mA/s ramp (~16 ms: ~1.6 mA)
    moving = quiet_device.move(1, 16.0, 20.0).current
    assert 154.5 + 2.0 < moving < 154.5 + 6.0


def test_mean_window_reaching_into_the_motion_says_where_it_was_measured(quiet_device):
    # 0 -> 1 deg at 5 deg/s: 200 samples of 1 ms at q_i = i/200 (i = 1..200), no dwell.
    # The whole move (window clipped to it): mean of i/200 = 201/400 = 0.5025 deg over 0.2 s;
    # its last 0.1 s: mean of i/200 for i = 101..200 = 301/400 = 0.7525 deg.
    s = quiet_device.move(1, 1.0, 5.0, mean=10.0)
    assert (s.mean_angle, s.mean_time) == (pytest.approx(0.5025, abs=1e-4), pytest.approx(0.2))
    assert s.angle == pytest.approx(1.0, abs=1e-4)
    s = quiet_device.move(1, 2.0, 5.0, mean=0.1)
    assert (s.mean_angle, s.mean_time) == (pytest.approx(1.7525, abs=1e-4), pytest.approx(0.1))
    # 2 -> 3 deg then a 0.1 s dwell, a 0.2 s window: the last 100 samples of the motion
    # (q_i = 2 + i/200, i = 101..200: mean 2.7525) and the 100 of the hold (3.0), weighted by
    # time: (2.7525 + 3.0) / 2 = 2.87625 deg
    s = quiet_device.move(1, 3.0, 5.0, dwell=0.1, mean=0.2)
    assert (s.mean_angle, s.mean_time) == (pytest.approx(2.87625, abs=1e-4), pytest.approx(0.2))


def test_mean_averages_the_current_noise_down(device):
    # at rest inside the dead zone (2 deg; example-a's edges are -8.7 and 9.1) the current is the
    # no-load 120 mA plus noise: 3 mA rms raw at 1 kHz, ~0.6 mA after the 20 Hz filter; a mean
    # over 0.3 s averages ~300 raw samples: ~3/sqrt(300) = 0.17 mA. Readings 0.35 s apart.
    device.move(1, 2.0, 20.0, dwell=0.5)
    single = [device.move(1, 2.0, dwell=0.35).current for _ in range(30)]
    means = [device.move(1, 2.0, dwell=0.35, mean=0.3).mean_current for _ in range(30)]
    assert abs(sum(means) / len(means) - 120.0) < 0.15
    sd_single, sd_mean = (float(np.std(x)) for x in (single, means))
    assert sd_single > 0.35 and sd_mean < 0.5 * sd_single, (sd_single, sd_mean)


def test_probe_reads_the_mean_when_the_device_offers_it(device):
    probe = DeviceProbe(device, 1, dwell=0.35, mean=0.3)
    assert probe.averaged
    s = probe.step_to(0.5)
    assert s.q == pytest.approx(0.5, abs=1e-4)  # the window lies in the dwell: at the target
    assert s.current == pytest.approx(probe.last.mean_current)


def test_base_protocol_device_gets_no_options_and_the_probe_falls_back():
    srv = PtyServer(DeviceEmulator(_twin(seed=2), features=())).start()
    try:
        with Device(srv.path, timeout=0.5) as dev:
            assert dev.info.features == () and not dev.supports("mean")
            with pytest.raises(DeviceError, match="does not offer the protocol feature 'mean'"):
                dev.move(1, 1.0, mean=0.3)
            assert srv.emulator.moves == 0  # refused on the host: nothing was sent
            probe = DeviceProbe(dev, 1)
            assert not probe.averaged
            s = probe.step_to(0.5)
            assert (s.q, s.current) == (probe.last.angle, probe.last.current)
        # a host that sends an option anyway gets E_ARG, and nothing moves
        port = serial.Serial(srv.path, timeout=0.5)
        try:
            port.write(encode_frame(9, "MOVE", 1, 3.0, "dwell=0.1000"))
            assert decode_frame(port.readline()).args[0] == "E_ARG"
            port.write(encode_frame(10, "STATE", 1))
            assert float(decode_frame(port.readline()).args[1]) == pytest.approx(0.5)
        finally:
            port.close()
    finally:
        srv.shutdown()


@pytest.mark.parametrize("fields", [
    ("1", "3.0", "dwell=11"),            # over the 10 s limit
    ("1", "3.0", "mean=0"),              # an empty window
    ("1", "3.0", "dwell=-0.1"),
    ("1", "3.0", "blink=1"),             # no such option
    ("1", "3.0", "dwell=0.1", "dwell=0.2"),
    ("1", "dwell=0.1", "3.0"),           # an option before a positional field
    ("1", "3.0", "mean=abc"),
])
def test_bad_move_options_are_refused_and_nothing_moves(server, fields):
    port = serial.Serial(server.path, timeout=0.5)
    try:
        port.write(encode_frame(3, "MOVE", *fields))
        reply = decode_frame(port.readline())
        assert (reply.seq, reply.verb, reply.args[0]) == (3, "ERR", "E_ARG")
        port.write(encode_frame(4, "STATE", 1))
        assert float(decode_frame(port.readline()).args[1]) == 0.0
    finally:
        port.close()


def test_host_refuses_bad_option_values_before_sending(device, server):
    for kw in ({"dwell": -1.0}, {"mean": 0.0}, {"mean": float("nan")}, {"dwell": 11.0}):
        with pytest.raises(DeviceError, match="MOVE option"):
            device.move(1, 1.0, **kw)
    assert server.emulator.moves == 0


def test_the_reply_deadline_grows_by_the_dwell(server):
    # a real device answers a dwelling MOVE dwell seconds after arrival; the emulator answers at
    # once, so a 0.5 s answer delay stands in for a 0.4 s dwell (+ 0.1 s of motion)
    with Device(server.path, timeout=0.3) as dev:
        _fault(server, "delay", value="0.5")
        s = dev.move(1, 1.0, 5.0, dwell=0.4)  # deadline 0.3 + 0.4 s (+ the motion): in time
        assert s.angle == pytest.approx(1.0, abs=1e-4) and dev.stale_replies == 0
        # no dwell: the plain 0.3 s deadline and the 1-deg move's 0.2 s at 5 deg/s. The answer
        # comes 0.5 s past that, well clear of it on a busy machine (a 0.5 s delay, the deadline
        # itself, was answered in time once under two CPU hogs)
        _fault(server, "delay", value="1.0")
        with pytest.raises(LinkError, match="no reply"):
            dev.move(1, 2.0, 5.0)


# ------------------------------------------------------------------------------------------
# device hygiene (issue 12): limits, readiness, closing the pty
# ------------------------------------------------------------------------------------------
def test_handshake_announces_the_devices_limits(device):
    assert device.info.extra["travel"] == "170" and device.info.extra["max_speed"] == "1000"
    from hystcli.device.robot import device_limits

    assert device_limits(device.info) == {"travel": 170.0, "max_speed": 1000.0}


@pytest.mark.parametrize("fields, words", [
    (("1", "10.0", "5000.0"), "speed 5000 deg/s beyond the motor's 1000"),
    # 170 deg at 0.001 deg/s: 1.7e5 s of motion, 1.7e8 samples of 1 ms the twin would allocate
    (("1", "170.0", "0.001"), "move of 1.7e+05 s beyond the 120 s limit"),
    (("2", "-100.0", "0.5"), "move of 200 s beyond the 120 s limit"),
])
def test_absurd_speeds_and_moves_are_device_errors_and_nothing_moves(server, fields, words):
    port = serial.Serial(server.path, timeout=float(5))
    try:
        port.write(encode_frame(3, "MOVE", *fields))
        reply = decode_frame(port.readline())
        assert (reply.seq, reply.verb, reply.args[0]) == (3, "ERR", "E_ARG")
        assert words in " ".join(reply.args[1:])
        port.write(encode_frame(4, "STATE", int(fields[0])))
        assert float(decode_frame(port.readline()).args[1]) == 0.0
    finally:
        port.close()


def test_the_longest_move_within_the_limit_is_served(device):
    # 120 s of motion exactly (12 deg at 0.1 deg/s): served, and the reply deadline grows by
    # the motion (here it is simulated time, answered at once)
    s = device.move(1, 12.0, 0.1)
    assert s.angle == pytest.approx(12.0, abs=1e-4)


def test_emulator_refuses_bad_limits():
    for kw in ({"max_speed": 0.0}, {"travel_limit": math.nan}, {"max_move_time": -1.0},
               {"default_speed": 50.0, "max_speed": 20.0}):
        with pytest.raises(DataError):
            DeviceEmulator(_twin(), **kw)


def test_reply_deadline_grows_by_the_motion_the_host_asked_for(server):
    # a robot that takes 1.5 s to answer (a delay fault stands in for a 2 s move of 10 deg at
    # 5 deg/s): with the knob's angle known (a STATE first) the 0.5 s deadline grows by 2 s of
    # motion and the reply is in time; without it (a fresh driver, the knob's angle unknown) the
    # 0.5 s deadline holds and the slow reply is a link error.
    with Device(server.path, timeout=0.5) as dev:
        dev.state(1)
        _fault(server, "delay", value="1.5")
        assert dev.move(1, 10.0, 5.0).angle == pytest.approx(10.0, abs=1e-4)
    with Device(server.path, timeout=0.5) as dev:
        _fault(server, "delay", value="1.5")
        with pytest.raises(LinkError, match="no reply to MOVE"):
            dev.move(2, 10.0, 5.0)


WARM_SCRIPT = r"""
import sys
import numba.core.dispatcher as dispatcher
from hystcli.sim.calibration import calibrated_catheter
from hystcli.device import Device
from hystcli.device.emulator import serve
from hystcli.sim.live import LiveTwin

server = serve(LiveTwin(calibrated_catheter("ice-a"), effects=None, seed=0))
# from here on, any numba compilation or cache load (what made a fresh robot's first MOVE take
# 0.2-0.9 s idle, seconds under load) is a fault of the device: it answers E_MOTOR
def refuse(self, *args, **kw):
    raise RuntimeError("numba work while serving a MOVE")
dispatcher.Dispatcher._compile_for_args = refuse
with Device(server.path, timeout=30) as dev:
    dev.move(1, 2.0, 20.0, dwell=0.05, mean=0.02)
    dev.move(2, -3.0, 20.0)
    dev.move(1, 0.0, 40.0)
server.shutdown()
print("ok")
"""


@pytest.mark.parametrize("warm", [True, False])
def test_a_served_twin_is_warm_before_its_first_move(warm):
    """The root cause of the device tests failing under load: the first MOVE of a fresh robot
    loaded (or compiled) the twin's numba functions. A fresh process serves the calibrated
    catheter (default effects), then forbids numba any further compilation: the MOVEs must still
    be answered. The control (warm-up disabled) shows the check has teeth."""
    import subprocess
    import sys

    script = WARM_SCRIPT if warm else WARM_SCRIPT.replace(
        "from hystcli.device.emulator import serve",
        "from hystcli.device.emulator import DeviceEmulator, serve\nDeviceEmulator.warm_up = lambda self: False")
    res = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300)
    if warm:
        assert res.returncode == 0 and res.stdout.strip() == "ok", res.stderr
    else:
        assert res.returncode != 0 and "numba work while serving a MOVE" in res.stderr


def test_warm_up_leaves_the_served_twin_untouched():
    # the same moves on a twin that was never served: identical readings, noise included
    emu = DeviceEmulator(_twin(seed=9))
    assert emu.warm_up() is True
    ref = _twin(seed=9)
    for q in (3.0, -2.0):
        reply = decode_frame(emu.handle_line(encode_frame(1, "MOVE", 1, q, 20.0))[0][0])
        rq, rc, ry = ref.move(1, q, speed_deg_s=20.0)
        assert float(reply.args[2]) == pytest.approx(rc, abs=1e-4)
        assert float(reply.args[3]) == pytest.approx(ry, abs=1e-4)


def test_close_pty_from_another_thread_never_touches_a_reused_descriptor(tmp_path):
    """The race of the old _close_fds: closing the pty from another thread while the serving
    thread still held its descriptor (here: sleeping before a delayed reply). The freed number
    goes to the next open in the process; the serving thread then wrote its reply into that
    file. Now the serving thread closes its own descriptors (close_pty asks it and waits), so a
    file opened after close_pty returns is never written by the server."""
    server = serve(_twin(seed=1))
    port = serial.Serial(server.path, timeout=5)
    try:
        server.emulator.inject(Fault("delay", at=1, value="0.6"))
        port.write(encode_frame(1, "MOVE", 1, 1.0))
        deadline = time.monotonic() + 30
        while server.emulator.moves < 1 and time.monotonic() < deadline:
            time.sleep(0.01)  # readiness: the server has the MOVE and sleeps before replying
        master = server._master
        server.close_pty()
        assert server.closed
        # take the lowest free descriptors until the master's old number is ours
        files, target = [], None
        for _ in range(64):
            fd = os.open(tmp_path / f"f{len(files)}", os.O_RDWR | os.O_CREAT)
            files.append(fd)
            if fd == master:
                target = fd
                break
        time.sleep(1.0)  # past the delayed reply
        if target is not None:
            assert os.fstat(target).st_size == 0, "the server wrote into a file it did not own"
        for fd in files:
            os.close(fd)
    finally:
        port.close()
        server.shutdown()
