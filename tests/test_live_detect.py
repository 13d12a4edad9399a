"""`hyst detect-shift --port` end to end over a real pseudo-terminal (issue 4, Must-show 1 and 2).

The robot is `hyst sim-robot` in a subprocess (a real pty, another process: nothing mocked above
the transport), serving the calibrated catheter `hyst simulate` and the demo use, with its
default effects unless a test says otherwise; the host is the CLI through typer's CliRunner. The
model is the catheter's true straight-shaft model with what `hyst identify` stores for the search
(the current's take-ups at the true edges, its levels and slopes from the twin's current model),
so the only thing under test is the live search. The reference shift is computed here from the
catheter's tendon geometry by the paper's eqs. 1-4, never from an output of detect-shift.
"""
from __future__ import annotations

import math
from pathlib import Path

import pytest
from typer.testing import CliRunner

from hystcli.sim.calibration import calibrated_catheter
from hystcli.cli import app
from hystcli.device import Device
from hystcli.estimate import Estimate
from hystcli.io import load_model, save_model
from hystcli.core.model import Model
from hystcli.core.params import Calibration, KnobIdentification
from simrobot import TIMEOUT, sim_robot, start_sim_robot, stop  # noqa: F401 - test_rotate_shift imports them from here

CAT = calibrated_catheter("ice-a")  # what `hyst sim-robot --catheter ice-a` serves
runner = CliRunner()

# The calibrated ice-a's tendon geometry (hystcli/sim/calibration.py: tendons 1.83 mm off the shaft
# axis, a 6 mm knob pulley). Written out here so that the reference below does not come from the
# code under test; test_geometry_is_the_one_the_reference_uses notices a recalibration.
BETA_CATHETER_MM, BETA_KNOB_MM = 1.83, 6.0


def shift_by_eqs_1_4(segments: list[tuple[float, float]]) -> dict[int, float]:
    """Paper eqs. 1-4: offset_1 = (180/pi) beta_c sum alpha_i cos(theta_i) / beta_k, offset_2
    with sin; segments as (alpha, theta) in degrees."""
    s1 = sum(math.radians(a) * math.cos(math.radians(t)) for a, t in segments)
    s2 = sum(math.radians(a) * math.sin(math.radians(t)) for a, t in segments)
    k = math.degrees(1.0) * BETA_CATHETER_MM / BETA_KNOB_MM
    return {1: k * s1, 2: k * s2}


def ice_a_model() -> Model:
    """The straight-shaft model of the calibrated ice-a with what identification stores for
    detect-shift, written from the twin's current model (twin.CurrentParams, kept by the
    calibration) rather than read from a sweep: each tendon is taken up at the knob's true edge;
    moving, the motor's Coulomb friction puts the dead zone's current at no-load +- coulomb
    (126 mA rising, 114 falling), which is where the current stands as each tendon is taken up;
    loaded, the current rises k_load (1 + mu) = 5 mA per deg."""
    cur = CAT.current
    moving_up, moving_down = cur.no_load + cur.coulomb, cur.no_load - cur.coulomb
    ident = {}
    for k, km in CAT.knobs.items():
        ident[k] = KnobIdentification(
            q_min=-40.0, q_max=40.0, method="given", calibration=Calibration(
                current_sign="signed",
                current_edges={"pos": Estimate(km.d_pos, km.d_pos - 0.05, km.d_pos + 0.05),
                               "neg": Estimate(km.d_neg, km.d_neg - 0.05, km.d_neg + 0.05)},
                no_load_rising=moving_up, no_load_falling=moving_down,
                slope_loaded_pos=cur.k_load * (1 + cur.mu), slope_loaded_neg=cur.k_load * (1 + cur.mu),
                edge_level_pos=moving_up, edge_level_neg=moving_down))
    return Model(dict(CAT.knobs), CAT.geometry, meta={"catheter": CAT.name}, identification=ident)


@pytest.fixture(scope="module")
def model_path(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("live") / "model.json"
    save_model(path, ice_a_model())
    return path


def detect(model_path: Path, port: str, out: Path, *extra: str, timeout: str = TIMEOUT):
    """`hyst detect-shift --port` with a generous reply deadline unless told (a loaded machine
    must not turn a slow answer into a failed search)."""
    return runner.invoke(app, ["detect-shift", "--model", str(model_path), "--port", port,
                               "-o", str(out), "--quiet", "--timeout", timeout, *extra])


# ---------------------------------------------------------------------------------------------
# Must-show 1: the offset found live is the twin's true shift
# ---------------------------------------------------------------------------------------------
# (shape option, its segments (alpha, theta) in deg, noise seed of the robot)
SHAPES = [
    ("straight", [], 3),
    ("alpha=45,theta=0", [(45, 0)], 4),
    ("alpha=90,theta=180", [(90, 180)], 5),
    ("alpha=45,theta=0;alpha=45,theta=90", [(45, 0), (45, 90)], 6),
]


def test_geometry_is_the_one_the_reference_uses():
    assert (CAT.geometry.beta_catheter_mm, CAT.geometry.beta_knob_mm) == (BETA_CATHETER_MM, BETA_KNOB_MM)
    # by hand: 1.83/6 * 45 = 13.725 deg of knob 1 at alpha=45, theta=0; -27.45 at alpha=90, theta=180
    assert shift_by_eqs_1_4([(45, 0)])[1] == pytest.approx(13.725)
    assert shift_by_eqs_1_4([(90, 180)])[1] == pytest.approx(-27.45)


# The live search reads, at each 0.5 deg step, the mean current over the last 0.3 s of a 0.35 s
# dwell at the target (protocol features dwell and mean): with single instantaneous samples the
# twin's current noise (3 mA rms raw, 0.6 mA filtered, against 1.5 to 2.5 mA of change per step
# once a tendon is taut) put the edge up to ~1 deg off, and a reading taken while moving reads it
# late by speed x (tendon lag + filter delay). Offline, 10 seeds x these shapes x both knobs on
# the calibrated ice-a and ice-b, with and without the default effects: |error| <= 0.24 deg
# (bench/bench_live.py, section 4).
# Every shape on the catheter users get (its default effects: creep, friction, rate, coupling),
# and the hardest one (a start with a tendon taut) on the bare model too, so that a failure tells
# the probe from the effects apart.
CASES = [(*s, "default") for s in SHAPES] + [(*SHAPES[2], "none")]


@pytest.mark.slow
@pytest.mark.parametrize("shape,segments,seed,effects", CASES, ids=[f"{c[0]}-{c[3]}" for c in CASES])
def test_detect_shift_live_matches_true_shift(model_path, tmp_path, shape, segments, seed, effects):
    true = shift_by_eqs_1_4(segments)
    out = tmp_path / "shifted.json"
    extra = ("--effect", "none") if effects == "none" else ()
    proc, path = start_sim_robot("--shape", shape, "--seed", str(seed), *extra)
    try:
        # no --max-travel: the default is the identification sweep's reach (40 deg here), which
        # covers the 32.5 deg edge of alpha=45 (13.725 + ice-a's d_pos)
        res = detect(model_path, path, out)
    finally:
        stop(proc)
    assert res.exit_code == 0, res.output
    shifted = load_model(out)
    for k in (1, 2):
        assert abs(shifted.knob(k).offset - true[k]) <= 0.5, (shape, k, shifted.knob(k).offset, true[k])
    assert shifted.meta["shift_source"] == f"live:{path}"


@pytest.mark.slow
def test_shorter_hold_and_window_are_options_and_are_checked(model_path, tmp_path):
    # a 0.2 s hold averaged over its last 0.15 s still settles the 25 ms tendon lag and the
    # 16 ms filter delay; straight shaft: the true shift is 0 on both knobs
    out = tmp_path / "short.json"
    proc, path = start_sim_robot("--seed", "7")
    try:
        res = detect(model_path, path, out, "--dwell", "0.2", "--mean-window", "0.15")
    finally:
        stop(proc)
    assert res.exit_code == 0, res.output
    for k in (1, 2):
        assert abs(load_model(out).knob(k).offset) <= 0.5
    for bad in (("--dwell", "-1"), ("--mean-window", "11"), ("--dwell", "nan")):
        res = detect(model_path, "/dev/null-no-port", tmp_path / "x.json", *bad)
        assert res.exit_code == 2 and bad[0] in res.output, res.output
    assert not (tmp_path / "x.json").exists()


@pytest.mark.slow
def test_detect_shift_live_returns_knobs_home(model_path, tmp_path):
    """After a successful search both knobs are back where they began (0 deg), read by a fresh
    connection to the same device."""
    proc, path = start_sim_robot("--shape", "alpha=45,theta=0")
    try:
        res = detect(model_path, path, tmp_path / "m.json", "--max-travel", "40")
        assert res.exit_code == 0, res.output
        with Device(path, timeout=float(TIMEOUT)) as dev:
            for k in (1, 2):
                assert abs(dev.state(k).angle) < 1e-3
    finally:
        stop(proc)


# ---------------------------------------------------------------------------------------------
# Must-show 2: faults during the search
# ---------------------------------------------------------------------------------------------
# (fault, words the one-line error must contain, whether the link survives to check the knob)
# The 5th MOVE is inside knob 1's search: from 0 deg the first edge of the calibrated ice-a is
# 18.8 deg away, i.e. ~38 steps of 0.5 deg.
FAULTS = [
    ("close@5", ("disconnected",), False),
    ("silent@5", ("no reply",), False),
    ("garble@5", ("corrupt",), True),
    ("error@5=E_MOTOR", ("E_MOTOR",), True),
]


@pytest.mark.slow
@pytest.mark.parametrize("fault,words,alive", FAULTS, ids=[f[0] for f in FAULTS])
def test_fault_mid_search_stops_safely(model_path, tmp_path, fault, words, alive):
    out = tmp_path / "shifted.json"
    proc, path = start_sim_robot("--fault", fault)
    try:
        # a deadline that must fire on the silent robot, twice (the step, the return): 2 s, far
        # above a warmed robot's answer (about 1 ms) even on a loaded machine
        res = detect(model_path, path, out, timeout="2")
        assert res.exit_code == 1, res.output
        errors = [line for line in res.output.splitlines() if line.startswith("Error:")]
        assert len(errors) == 1, res.output
        assert "Traceback" not in res.output
        for w in words:
            assert w in errors[0], errors[0]
        assert not out.exists()
        if alive:
            # the message says the knob went back, and a fresh connection confirms it
            assert "returned to 0 deg" in errors[0], errors[0]
            with Device(path, timeout=float(TIMEOUT)) as dev:
                assert abs(dev.state(1).angle) < 1e-3
                assert abs(dev.state(2).angle) < 1e-3
        else:
            # a dead link cannot return the knob: the message must not claim it did
            assert "could NOT" in errors[0], errors[0]
    finally:
        stop(proc)


@pytest.mark.slow
def test_contact_spike_cli_stops_and_writes_nothing(model_path, tmp_path):
    """A 5000 mA current spike (contact) mid-search: the CLI must stop, return the knob, exit 1
    and write nothing (issue 4: 'current ceiling as contact')."""
    out = tmp_path / "shifted.json"
    proc, path = start_sim_robot("--fault", "spike@5=5000")
    try:
        res = detect(model_path, path, out)
        assert res.exit_code == 1, res.output
        assert not out.exists()
        errors = [line for line in res.output.splitlines() if line.startswith("Error:")]
        assert len(errors) == 1 and "current" in errors[0], res.output
        with Device(path, timeout=float(TIMEOUT)) as dev:
            assert abs(dev.state(1).angle) < 1e-3
    finally:
        stop(proc)


def test_contact_spike_live_probe_safety_stop():
    """The live probe's current ceiling over a real pty (emulator in a thread, so its STOP
    counter is visible): a 5000 mA spike at the 5th MOVE is far above ice-a's largest honest
    current (no-load 120 mA + k_load(1+mu) 5 mA/deg x 25 deg past an edge ~ 250 mA) and under
    the 2000 mA ceiling's check -> SafetyStop, motors stopped, knob back at 0 deg."""
    from hystcli.device import open_probe
    from hystcli.device.emulator import Fault, serve
    from hystcli.errors import SafetyStop
    from hystcli.shift import detect_shift
    from hystcli.sim.live import LiveTwin

    server = serve(LiveTwin(CAT, seed=1), faults=[Fault("spike", 5, 1, "5000")])
    try:
        probe = open_probe(server.path, knob=1, timeout=float(TIMEOUT), current_ceiling=2000.0)
        try:
            with pytest.raises(SafetyStop, match=r"ceiling 2000 mA.*returned to 0 deg"):
                detect_shift(ice_a_model(), probe, 1)
            assert server.emulator.stops >= 1
            assert server.emulator.moves == 6  # 5 steps + the move home, nothing after the spike
            assert abs(probe.device.state(1).angle) < 1e-3
        finally:
            probe.device.close()
    finally:
        server.shutdown()


# ---------------------------------------------------------------------------------------------
# the reply deadline and the connection (issue 12)
# ---------------------------------------------------------------------------------------------
@pytest.mark.slow
def test_timeout_is_the_reply_deadline(model_path, tmp_path):
    """The 3rd MOVE is answered 1.5 s late: with --timeout 0.5 its deadline (0.5 s + the
    0.35 s dwell + 0.1 s of motion) passes first and the search stops, saying the deadline;
    with --timeout 10 the search waits for it and succeeds."""
    with sim_robot("--fault", "delay@3=1.5") as path:
        res = detect(model_path, path, tmp_path / "a.json", timeout="0.5")
    assert res.exit_code == 1 and "no reply to MOVE" in res.output and "within 0.5 s" in res.output
    assert not (tmp_path / "a.json").exists()
    with sim_robot("--fault", "delay@3=1.5") as path:
        res = detect(model_path, path, tmp_path / "b.json", "--max-travel", "40")
    assert res.exit_code == 0, res.output
    for k in (1, 2):
        assert abs(load_model(tmp_path / "b.json").knob(k).offset) <= 0.5  # straight shaft


@pytest.mark.parametrize("bad", ["0", "-1", "nan", "inf", "abc"])
def test_bad_timeout_is_a_usage_error(model_path, tmp_path, bad):
    res = detect(model_path, "/dev/null-no-port", tmp_path / "x.json", timeout=bad)
    assert res.exit_code == 2 and "--timeout" in res.output, res.output
    assert not (tmp_path / "x.json").exists()


def test_bad_baud_is_a_usage_error(model_path, tmp_path):
    res = detect(model_path, "/dev/null-no-port", tmp_path / "x.json", "--baud", "-9600")
    assert res.exit_code == 2 and "--baud" in res.output, res.output


def test_one_connection_for_every_knob(model_path, tmp_path):
    """Both knobs are searched over one connection: one handshake (the port used to be opened,
    and the device greeted, once per knob)."""
    from hystcli.device.emulator import serve
    from hystcli.sim.live import LiveTwin

    server = serve(LiveTwin(CAT, seed=2))
    try:
        res = detect(model_path, server.path, tmp_path / "m.json", "--max-travel", "40")
        assert res.exit_code == 0, res.output
        assert server.emulator.hellos == 1
        assert server.emulator.stops >= 1  # the connection's end stopped the motors
    finally:
        server.shutdown()
