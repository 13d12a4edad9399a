"""`hyst sim-robot`, `play`, `status`, `home` and `jog` end to end over a real pseudo-terminal.

The robot is `hyst sim-robot` in a subprocess (the most honest setup: tests/simrobot.py) or the
same emulator in a thread when a test needs to look inside it (its MOVE and STOP counters); the
host side is the CLI through typer's CliRunner, or `hyst` in a subprocess when a test sends it
Ctrl-C. Nothing is mocked above the transport. Every host command that must succeed gets a
generous reply deadline (simrobot.TIMEOUT); tests that need a deadline to fire pass a short one
against a fault that cannot answer in time.
"""
from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from hystcli import compensation
from hystcli.sim.calibration import calibrated_catheter
from hystcli.cli import app
from hystcli.device import Device
from hystcli.device.emulator import Fault, serve
from hystcli.core.run import Run
from hystcli.io import read_run, write_run
from hystcli.core.params import Shape
from hystcli.device.robot import Interrupted, play_trajectory
from hystcli.safety import LimitExceeded, Limits
from hystcli.sim.live import LiveTwin
from hystcli.sim.twin import periodic, simulate
from simrobot import TIMEOUT, interrupt_after, sim_robot, start_sim_robot, stop

CAT = calibrated_catheter("ice-a")  # what `hyst sim-robot` and `hyst simulate` serve as ice-a
SHAPE = "alpha=45,theta=0"
runner = CliRunner()


def _status(path: str) -> dict:
    """`hyst status --format json` on the robot: what a user reads (nothing moves)."""
    res = runner.invoke(app, ["status", "--port", path, "--timeout", TIMEOUT, "--format", "json"])
    assert res.exit_code == 0, res.output
    return json.loads(res.stdout)


def _error_line(res) -> str:
    """The one `Error:` line of a failed command (and that there is exactly one, no traceback)."""
    lines = [ln for ln in res.output.splitlines() if ln.startswith("Error:")]
    assert len(lines) == 1 and "Traceback" not in res.output, res.output
    return lines[0]


@pytest.fixture(scope="module")
def commands(tmp_path_factory) -> Path:
    """Knob commands from `compensate` logic: the inverse of the true shifted model on a
    periodic reference (60 deg amplitude as in the paper, sped up to 0.5 Hz for a short run)."""
    folder = tmp_path_factory.mktemp("traj")
    t, r = periodic(amplitude=60.0, freq=0.5, cycles=1.0, fs=50.0)
    model = CAT.true_model(Shape.parse(SHAPE))
    traj = Run({"t": t, "r1": r}, {"catheter": "ice-a", "shape": SHAPE, "motion": "periodic",
                                    "trial": "1"})
    cmds = compensation.compensate(model, traj).run
    path = folder / "cmds.csv"
    write_run(path, cmds)
    return path


# ------------------------------------------------------------------------------------------
# sim-robot (subprocess) + play + evaluate
# ------------------------------------------------------------------------------------------
def _play_on_sim_robot(commands: Path, out: Path, *robot_args: str, shape: str = SHAPE) -> Path:
    """Play ``commands`` with `hyst play` on a fresh `hyst sim-robot --catheter ice-a --shape shape`."""
    proc, path = start_sim_robot("--catheter", "ice-a", "--shape", shape, *robot_args)
    try:
        # --allow-fast: the compensated commands jump across the dead zone and the backlash
        # (beyond the 360 deg/s default limit); they are played at the limit instead
        res = runner.invoke(app, ["play", str(commands), "--port", path, "-o", str(out), "--fast",
                                  "--quiet", "--allow-fast", "--timeout", TIMEOUT])
        assert res.exit_code == 0, res.output
    finally:
        assert stop(proc) == 0  # SIGTERM ends it cleanly
    return out


def test_play_against_sim_robot_matches_the_offline_twin(commands, tmp_path):
    out = _play_on_sim_robot(commands, tmp_path / "run.csv", "--seed", "4", "--latency-ms", "0.2",
                             "--effect", "none")
    run = read_run(out)
    cmds = read_run(commands)
    # metadata: the trajectory's kept, the device's added
    assert run.meta["controller"] == cmds.meta["controller"]
    assert run.meta["offset1"] == cmds.meta["offset1"]
    assert run.meta["device_catheter"] == "ice-a" and run.meta["device_tracker"] == "yes"
    np.testing.assert_allclose(run["q1"], cmds["q1"])
    np.testing.assert_allclose(run["r1"], cmds["r1"])
    # the tip measured through the link against the offline twin, noise-free, on the same
    # commands: only the tracker's noise (0.3 deg rms, ice-a's sensors) separates them
    offline = simulate(CAT, cmds.t, {1: cmds["q1"]}, shape=Shape.parse(SHAPE), effects=(), noise=False)
    err = run["y1"] - offline["y1"]
    assert np.sqrt(np.mean(err ** 2)) < 2 * CAT.em_noise_deg
    assert abs(np.mean(err)) < 0.15
    # compensation on the true model tracks the reference: the tip follows r within the noise
    assert np.sqrt(np.mean((run["y1"] - run["r1"]) ** 2)) < 2 * CAT.em_noise_deg

    # play -> evaluate gives the figures of the offline simulation of the same commands
    sim_path = tmp_path / "offline.csv"
    write_run(sim_path, simulate(CAT, cmds.t, {1: cmds["q1"]}, shape=Shape.parse(SHAPE), effects=(),
                                 r={1: cmds["r1"]}, meta=dict(cmds.meta), seed=4))
    rmse = []
    for p in (out, sim_path):
        res = runner.invoke(app, ["evaluate", str(p), "--format", "json", "--per-run"])
        assert res.exit_code == 0, res.output
        rmse.append(json.loads(res.stdout)["runs"][0]["rmse"])
    # both are the tracker noise (0.3 deg rms raw live, less after the offline 20 Hz filter)
    assert abs(rmse[0] - rmse[1]) < 0.25 and rmse[0] < 2 * CAT.em_noise_deg


def test_sim_robot_serves_the_catheter_hyst_simulate_runs(commands, tmp_path):
    """`sim-robot --catheter ice-a` and `simulate --catheter ice-a`, both with the catheter's
    default effects (no --effect), are one catheter: the tip played live on the robot is the
    offline simulation of the same commands up to the tracker's noise, while the bare model
    (`simulate --effect none`) is far off (ice-a's creep alone delays 26 % of every tip move
    by 3.35 s, degrees of tip on this 0.5 Hz input)."""
    live = read_run(_play_on_sim_robot(commands, tmp_path / "run.csv", "--seed", "5"))
    offline = {}
    for name, extra in (("default", []), ("none", ["--effect", "none"])):
        sim = tmp_path / f"sim_{name}.csv"
        res = runner.invoke(app, ["simulate", "--catheter", "ice-a", "--shape", SHAPE, "--commands",
                                  str(commands), "--no-noise", "-o", str(sim), "--quiet", *extra])
        assert res.exit_code == 0, res.output
        offline[name] = read_run(sim)
    rms = {name: float(np.sqrt(np.mean((live["y1"] - run["y1"]) ** 2))) for name, run in offline.items()}
    assert rms["default"] < 2 * CAT.em_noise_deg, rms
    assert rms["none"] > 10 * rms["default"], rms


# ------------------------------------------------------------------------------------------
# a fault or Ctrl-C while playing: motors stopped, knobs back (or held), the error says where
# ------------------------------------------------------------------------------------------
def test_play_fault_from_sim_robot_subprocess_writes_nothing(commands, tmp_path):
    """An unplugged cable (the robot closes its port at the 20th MOVE): exit 1, one error line
    that says the knob could NOT be returned and where it was last reported, nothing written."""
    proc, path = start_sim_robot("--fault", "close@20")
    try:
        out = tmp_path / "run.csv"
        res = runner.invoke(app, ["play", str(commands), "--port", path, "-o", str(out), "--fast",
                                  "--allow-fast", "--timeout", TIMEOUT])
    finally:
        try:
            code = proc.wait(timeout=20)  # its port closed, the robot process ends by itself
        finally:
            stop(proc)
    assert res.exit_code == 1
    line = _error_line(res)
    assert "disconnected" in line or "no reply" in line
    assert "knob 1 could NOT be returned to +0.00 deg" in line and "last reported at" in line
    assert not out.exists() and list(tmp_path.iterdir()) == []
    assert code == 0


@pytest.fixture
def robot():
    """The emulator in a thread behind a real pty (to see its counters)."""
    srv = serve(LiveTwin(CAT, seed=1))
    yield srv
    srv.shutdown()


@pytest.mark.slow
@pytest.mark.parametrize("fault, words, back", [
    (Fault("error", at=10, value="E_MOTOR"), "E_MOTOR", True),
    (Fault("garble", at=10), "checksum mismatch", True),
    (Fault("silent", at=10), "no reply", False),
])
def test_play_faults_stop_return_and_write_nothing(robot, commands, tmp_path, fault, words, back):
    robot.emulator.inject(fault)
    out = tmp_path / "run.csv"
    # a deadline that must fire on the silent robot (twice: the MOVE, the return): 2 s, far above
    # a warmed robot's answer (about 1 ms) on a loaded machine
    res = runner.invoke(app, ["play", str(commands), "--port", robot.path, "-o", str(out), "--fast",
                              "--allow-fast", "--timeout", "2"])
    assert res.exit_code == 1
    line = _error_line(res)
    assert words in line and "motors stopped" in line
    assert not out.exists()
    if back:
        assert robot.emulator.stops >= 1  # the host stopped the motors, then brought the knob back
        assert "knob 1 returned to +0.00 deg" in line
        assert _status(robot.path)["knobs"]["1"]["angle"] == 0.0
    else:
        assert "knob 1 could NOT be returned to +0.00 deg" in line and "last reported at" in line


def test_play_interrupted_returns_the_knob(robot, commands):
    """Ctrl-C (KeyboardInterrupt from the progress callback, where a real one lands) after 5
    samples: the motors are stopped, the knob goes back to where the play began (it was moved to
    3 deg first), and the interrupt says so."""
    def interrupt(i, n):
        if i == 5:
            raise KeyboardInterrupt

    with Device(robot.path, timeout=float(TIMEOUT)) as dev:
        dev.move(1, 3.0, 20.0)
        with pytest.raises(Interrupted, match=r"motors stopped, knob 1 returned to \+3.00 deg"):
            play_trajectory(dev, read_run(commands), paced=False, progress=interrupt,
                            speed="fast")
        assert robot.emulator.stops == 1
        assert dev.state(1).angle == pytest.approx(3.0, abs=1e-4)


def test_play_interrupted_without_return_holds_and_says_where(robot, commands):
    cmds = read_run(commands)

    def interrupt(i, n):
        if i == 8:
            raise KeyboardInterrupt

    with Device(robot.path, timeout=float(TIMEOUT)) as dev:
        with pytest.raises(Interrupted) as exc:
            play_trajectory(dev, cmds, paced=False, progress=interrupt, speed="fast",
                            return_on_abort=False)
        where = cmds["q1"][7]  # the 8th sample, the last one played
        assert f"knob 1 last reported at {where:+.2f} deg" in str(exc.value)
        assert "held" in str(exc.value)
        assert dev.state(1).angle == pytest.approx(where, abs=1e-3)


@pytest.mark.slow
def test_ctrl_c_on_hyst_play_returns_the_knob(tmp_path):
    """The user's Ctrl-C: `hyst play` in a subprocess, paced through a 12.6 s sweep on `hyst
    sim-robot`, gets SIGINT once it has checked the file and started: exit 130, one line that
    says the knob went back, no output file, and `hyst status` reads the knob at 0 deg."""
    sweep = tmp_path / "sweep.csv"
    assert runner.invoke(app, ["sweep", "-o", str(sweep), "--quiet"]).exit_code == 0
    out = tmp_path / "run.csv"
    with sim_robot() as path:
        code, err = interrupt_after(["play", str(sweep), "--port", path, "-o", str(out), "--timeout", TIMEOUT],
                                    "checked:", timeout=60)
        assert code == 130, err
        errors = [ln for ln in err.splitlines() if ln.startswith("Error:")]
        assert len(errors) == 1 and "Traceback" not in err, err
        assert errors[0].startswith("Error: interrupted; motors stopped, knob 1 returned to +0.00 deg")
        assert not out.exists()
        assert _status(path)["knobs"]["1"]["angle"] == 0.0


# ------------------------------------------------------------------------------------------
# play checks the whole file before its first MOVE
# ------------------------------------------------------------------------------------------
def _ramp(n: int = 50, fs: float = 50.0, top: float = 10.0) -> dict:
    t = np.arange(n) / fs
    return {"t": t, "q1": np.linspace(0.0, top, n)}


@pytest.mark.parametrize("case, words", [
    ("nan", "column 'q1', line 42: NaN"),   # row 40 is the file's line 42 (after the header)
    ("inf", "column 'q1', line 42: an infinite value"),
    ("t", "column 't' is not strictly increasing at line 32"),
    ("travel", "knob 1 reaches 175.0 deg at t=0.8 s, beyond the travel limit +-170 deg"),
    # a value no knob could reach is refused when the file is read, before any limit is checked
    ("huge", "column 'q1', line 42: 1e+308 is beyond +-1e+10"),
    ("speed", "knob 1 moves at 2010.2 deg/s at t=0.8 s, beyond the speed limit 360 deg/s"),
])
def test_play_checks_the_whole_file_before_the_first_move(robot, tmp_path, case, words):
    """A bad row late in the file (row 40 of 50) refuses the whole play: nothing moves (the
    robot counted no MOVE), nothing is written, one error line naming the row or the limit
    (it used to move until the bad row: the robot refused the MOVE there, E_RANGE).
    The travel limit is the robot's own (it announces +-170 deg, tighter than --travel-limit's
    180); the speed step is a 40 deg jump within one 20 ms sample."""
    cols = _ramp()
    q = cols["q1"].copy()
    t = cols["t"].copy()
    if case in ("nan", "inf", "huge"):
        q[40] = {"nan": math.nan, "inf": math.inf, "huge": 1e308}[case]
    elif case == "travel":
        q[40] = 175.0
    elif case == "speed":
        q[41:] += 40.0
    else:
        t[30] = t[29]
    path = tmp_path / "cmds.csv"
    # the file is written by hand: write_run would refuse some of these itself
    path.write_text("t,q1\n" + "".join(f"{float(a)!r},{float(b)!r}\n" for a, b in zip(t, q)))
    out = tmp_path / "run.csv"
    strict = ["--strict-speed"] if case == "speed" else []   # by default a fast step is rate-limited
    res = runner.invoke(app, ["play", str(path), "--port", robot.path, "-o", str(out), "--fast",
                              "--timeout", TIMEOUT, *strict])
    assert res.exit_code == 1
    assert words in _error_line(res)
    assert robot.emulator.moves == 0 and not out.exists()


def test_play_speed_modes_on_jumps(commands, tmp_path):
    """The robot's motors do 400 deg/s (it refuses faster MOVEs); the compensated commands
    jump at up to ~1500 deg/s. With --strict-speed play refuses the file before moving; with
    --allow-fast every step goes at most at the 360 deg/s limit, which the robot accepts, and the
    run says how many steps were capped; by default the commands are rate-limited before the play
    (the log's q: what was sent, within the limit, back on the file's commands after each jump)
    and a warning says how long the knob lags. A --max-speed above the robot's is tightened to it."""
    asked = read_run(commands)
    peak = np.max(np.abs(np.diff(asked["q1"]) / np.diff(asked.t)))
    assert peak > 400
    out, limited = tmp_path / "run.csv", tmp_path / "limited.csv"
    with sim_robot("--max-speed", "400") as path:
        res = runner.invoke(app, ["play", str(commands), "--port", path, "-o", str(out), "--fast",
                                  "--timeout", TIMEOUT, "--strict-speed"])
        assert res.exit_code == 1 and "beyond the speed limit 360 deg/s" in _error_line(res)
        assert "--allow-fast" in _error_line(res) and not out.exists()
        res = runner.invoke(app, ["play", str(commands), "--port", path, "-o", str(out), "--fast",
                                  "--timeout", TIMEOUT, "--max-speed", "1000", "--strict-speed"])
        assert "beyond the speed limit 400 deg/s" in _error_line(res)  # the robot's own
        res = runner.invoke(app, ["play", str(commands), "--port", path, "-o", str(out), "--fast",
                                  "--timeout", TIMEOUT, "--allow-fast"])
        assert res.exit_code == 0, res.output
        res = runner.invoke(app, ["play", str(commands), "--port", path, "-o", str(limited), "--fast",
                                  "--timeout", TIMEOUT, "--max-speed", "1000"])
        assert res.exit_code == 0, res.output
        assert "Warning: knob 1: steps beyond the motor's limits rate-limited" in res.stderr
    run = read_run(out)
    assert run.meta["play_speed_limit"] == "360" and int(run.meta["play_speed_capped"]) > 0
    assert float(run.meta["play_peak_speed"]) == pytest.approx(peak, rel=1e-3)
    np.testing.assert_allclose(run["q1"], asked["q1"])
    run = read_run(limited)
    assert run.meta["play_speed_limit"] == "400" and run.meta["play_speed_capped"] == "0"
    assert run.meta["play_speed_mode"] == "limit" and "catch-ups" in run.meta["play_catchup1"]
    sent = run["q1"]
    assert np.max(np.abs(np.diff(sent) / np.diff(run.t))) <= 400.0
    jumps = np.abs(np.diff(asked["q1"]) / np.diff(asked.t)) > 400.0
    off = sent != asked["q1"]
    # each jump lags, then lands (the file ends on a jump, not caught up by its last sample)
    assert off[1:][jumps].all() and (~off).mean() > 0.8


def test_play_refuses_a_knob_the_device_lacks(commands, tmp_path):
    srv = serve(LiveTwin(CAT, knobs=(2,)))
    try:
        out = tmp_path / "run.csv"
        res = runner.invoke(app, ["play", str(commands), "--port", srv.path, "-o", str(out),
                                  "--timeout", TIMEOUT])
        assert res.exit_code == 1 and "knob 1" in res.output and "drives knobs 2" in res.output
        assert srv.emulator.moves == 0 and not out.exists()
    finally:
        srv.shutdown()


def test_play_paced_follows_the_file_timing(robot):
    t = np.arange(11) * 0.03  # 0.3 s
    traj = Run({"t": t, "q1": np.linspace(0, 3, 11)})
    with Device(robot.path, timeout=float(TIMEOUT)) as dev:
        t0 = time.monotonic()
        run = play_trajectory(dev, traj, paced=True)
        elapsed = time.monotonic() - t0
    assert elapsed >= 0.3  # never ahead of the file (no upper bound: a loaded machine lags)
    assert run.meta["play_timing"] == "paced" and float(run.meta["play_max_lag_s"]) >= 0.0


def test_play_core_refuses_before_moving(robot):
    """The core function checks too (any caller, not only the CLI)."""
    traj = Run({"t": [0.0, 0.01, 0.02], "q1": [0.0, 0.0, 30.0]})
    with Device(robot.path, timeout=float(TIMEOUT)) as dev:
        with pytest.raises(LimitExceeded, match="3000.0 deg/s"):
            play_trajectory(dev, traj, paced=False)
        with pytest.raises(LimitExceeded, match="beyond the travel limit"):
            play_trajectory(dev, traj, paced=False, limits=Limits(travel=20.0), speed="fast")
    assert robot.emulator.moves == 0


def test_play_refuses_to_overwrite_its_input_before_connecting(commands):
    before = commands.read_bytes()
    res = runner.invoke(app, ["play", str(commands), "--port", "/nonexistent/tty", "-o", str(commands)])
    assert res.exit_code == 1 and "refusing to overwrite an input" in res.output
    assert commands.read_bytes() == before


def test_play_bad_port_is_one_error_line(commands, tmp_path):
    res = runner.invoke(app, ["play", str(commands), "--port", "/nonexistent/tty", "-o",
                              str(tmp_path / "x.csv")])
    assert res.exit_code == 1
    assert res.output.strip().splitlines() == [res.output.strip()]
    assert "cannot open port /nonexistent/tty" in res.output


# ------------------------------------------------------------------------------------------
# status, home, jog against `hyst sim-robot`
# ------------------------------------------------------------------------------------------
def test_status_home_jog_on_sim_robot():
    with sim_robot("--shape", SHAPE, "--seed", "3") as path:
        st = _status(path)
        assert st["device"]["name"] == "hyst-sim" and st["device"]["catheter"] == "ice-a"
        assert st["device"]["knobs"] == [1, 2] and st["device"]["features"] == ["dwell", "mean"]
        assert st["limits"] == {"travel": 170.0, "max_speed": 1000.0}
        # at rest at 0 deg inside the dead zone: the no-load current (ice-a: 120 mA) and noise
        for k in ("1", "2"):
            assert st["knobs"][k]["angle"] == 0.0
            assert abs(st["knobs"][k]["current"] - 120.0) < 5.0
        table = runner.invoke(app, ["status", "--port", path, "--timeout", TIMEOUT])
        assert table.exit_code == 0 and "limits: travel +-170 deg, max speed 1000 deg/s" in table.stdout

        res = runner.invoke(app, ["jog", "--port", path, "--knob", "1", "--by", "-2.5",
                                  "--timeout", TIMEOUT])
        assert res.exit_code == 0, res.output
        assert "knob 1: +0.000 -> -2.500 deg" in res.stdout
        res = runner.invoke(app, ["jog", "--port", path, "--knob", "1", "--by", "7", "--format",
                                  "json", "--timeout", TIMEOUT])
        assert json.loads(res.stdout)["knobs"]["1"]["to"] == pytest.approx(4.5)
        res = runner.invoke(app, ["home", "--port", path, "--knob", "2", "--angle", "-30",
                                  "--timeout", TIMEOUT])
        assert res.exit_code == 0 and "knob 2: +0.000 -> -30.000 deg" in res.stdout
        st = _status(path)
        assert (st["knobs"]["1"]["angle"], st["knobs"]["2"]["angle"]) == (4.5, -30.0)

        # refused before anything moves: beyond the robot's travel (+-170), jog past it
        res = runner.invoke(app, ["home", "--port", path, "--angle", "175", "--timeout", TIMEOUT])
        assert res.exit_code == 1
        assert "target +175.00 deg is beyond the travel limit +-170 deg; nothing moved" in _error_line(res)
        res = runner.invoke(app, ["home", "--port", path, "--knob", "2", "--angle", "-165",
                                  "--timeout", TIMEOUT])
        assert res.exit_code == 0
        res = runner.invoke(app, ["jog", "--port", path, "--knob", "2", "--by", "-8", "--timeout", TIMEOUT])
        assert res.exit_code == 1 and "target -173.00 deg is beyond the travel limit" in _error_line(res)
        res = runner.invoke(app, ["jog", "--port", path, "--knob", "3", "--by", "1", "--timeout", TIMEOUT])
        assert res.exit_code == 1 and "has no knob 3" in _error_line(res)
        st = _status(path)
        assert (st["knobs"]["1"]["angle"], st["knobs"]["2"]["angle"]) == (4.5, -165.0)

        # home: every knob back to 0, from 165 deg away (8 s of motion at 20 deg/s: the reply
        # deadline grows by the motion, so the 1 s default deadline is enough)
        res = runner.invoke(app, ["home", "--port", path])
        assert res.exit_code == 0, res.output
        assert "knob 2: -165.000 -> +0.000 deg" in res.stdout
        st = _status(path)
        assert (st["knobs"]["1"]["angle"], st["knobs"]["2"]["angle"]) == (0.0, 0.0)


def test_home_fault_says_where_the_knobs_are():
    with sim_robot("--fault", "error@2=E_MOTOR") as path:
        assert runner.invoke(app, ["jog", "--port", path, "--knob", "2", "--by", "5",
                                   "--timeout", TIMEOUT]).exit_code == 0
        res = runner.invoke(app, ["home", "--port", path, "--timeout", TIMEOUT])
        assert res.exit_code == 1
        line = _error_line(res)
        assert "E_MOTOR" in line and "motors stopped, knobs held where they are" in line
        assert "knob 1 last reported at +0.00 deg" in line and "knob 2 last reported at +5.00 deg" in line


# ------------------------------------------------------------------------------------------
# usage errors exit 2 (before connecting), bad data and faults exit 1
# ------------------------------------------------------------------------------------------
PORTLESS = "/nonexistent/tty"


@pytest.mark.parametrize("args, option", [
    (["play", "X", "--port", PORTLESS, "-o", "Y", "--timeout", "nan"], "--timeout"),
    (["play", "X", "--port", PORTLESS, "-o", "Y", "--timeout", "0"], "--timeout"),
    (["play", "X", "--port", PORTLESS, "-o", "Y", "--max-speed", "-5"], "--max-speed"),
    (["play", "X", "--port", PORTLESS, "-o", "Y", "--travel-limit", "inf"], "--travel-limit"),
    (["status", "--port", PORTLESS, "--timeout", "-1"], "--timeout"),
    (["status", "--port", PORTLESS, "--baud", "-9600"], "--baud"),
    (["status", "--port", PORTLESS, "--format", "xml"], "--format"),
    (["home", "--port", PORTLESS, "--speed", "nan"], "--speed"),
    (["home", "--port", PORTLESS, "--speed", "500"], "--speed"),
    (["home", "--port", PORTLESS, "--angle", "200"], "--angle"),
    (["home", "--port", PORTLESS, "--knob", "0"], "--knob"),
    (["jog", "--port", PORTLESS, "--knob", "1", "--by", "nan"], "--by"),
    (["jog", "--port", PORTLESS, "--knob", "1", "--by", "11"], "--by"),
    (["jog", "--port", PORTLESS, "--knob", "1"], "--by"),
    (["jog", "--port", PORTLESS, "--knob", "1", "--by", "1", "--max-step", "0"], "--max-step"),
    (["sim-robot", "--catheter", "ice-z"], "--catheter"),
    (["sim-robot", "--shape", "alpha=abc"], "--shape"),
    (["sim-robot", "--fault", "boom@1"], "--fault"),
    (["sim-robot", "--effect", "bogus"], "--effect"),
    (["sim-robot", "--knobs", "3"], "--knob"),
    (["sim-robot", "--knob", "1,1"], "--knob"),
    (["sim-robot", "--latency-ms", "nan"], "--latency-ms"),
    (["sim-robot", "--travel-limit", "nan"], "--travel-limit"),
    (["sim-robot", "--max-speed", "0"], "--max-speed"),
    (["sim-robot", "--seed", "-1"], "--seed"),
    (["sim-robot", "--rotation", "inf"], "--rotation"),
    (["sim-robot", "--name", "x" * 40], "--name"),
])
def test_bad_options_are_usage_errors(args, option):
    res = runner.invoke(app, args)
    assert res.exit_code == 2, (args, res.output)
    assert option in res.output and "Traceback" not in res.output


def test_sim_robot_names_what_it_refuses():
    res = runner.invoke(app, ["sim-robot", "--catheter", "ice-z"])
    assert "unknown virtual catheter 'ice-z'" in res.output
    res = runner.invoke(app, ["sim-robot", "--fault", "boom@1"])
    assert "unknown fault 'boom'" in res.output


def test_help_has_examples():
    for cmd in ("play", "sim-robot", "status", "home", "jog", "sweep"):
        res = runner.invoke(app, [cmd, "--help"])
        assert res.exit_code == 0 and "Example" in res.output


# ------------------------------------------------------------------------------------------
# sweep + play + identify: identification on the robot
# ------------------------------------------------------------------------------------------
def test_sweep_writes_the_papers_identification_sweep(tmp_path):
    out = tmp_path / "sweep.csv"
    res = runner.invoke(app, ["sweep", "--knob", "2", "-o", str(out), "--quiet"])
    assert res.exit_code == 0, res.output
    run = read_run(out)
    assert run.columns.keys() == {"t", "q2"} and run.meta["motion"] == "sweep"
    # paper section II-C-2: +-40 deg, 2 cycles, 40 deg/s peak: w = 40/40 = 1 rad/s, so the two
    # cycles last 4 pi s; sampled at 1 kHz
    assert np.max(np.abs(run["q2"])) == pytest.approx(40.0, abs=1e-3)
    assert run.t[-1] == pytest.approx(4 * np.pi, abs=1e-3)
    assert np.max(np.abs(np.diff(run["q2"]) / np.diff(run.t))) == pytest.approx(40.0, rel=1e-3)
    res = runner.invoke(app, ["sweep", "--amplitude", "0", "-o", str(tmp_path / "bad.csv")])
    assert res.exit_code == 2 and not (tmp_path / "bad.csv").exists()


@pytest.mark.slow
def test_identify_on_a_sweep_played_on_the_robot(tmp_path):
    """Job 1 on a live robot: `hyst sweep`, `hyst play` on `hyst sim-robot`, `hyst identify` on
    the recording. The bare model (no unmodelled effects) is identified to within a few tenths of
    a degree of the catheter's true knob 1: hystcli/sim/calibration.py gives ice-a d_pos = -d_neg =
    18.8 deg, b_pos = b_neg = 9.88 deg, omega = 1.45."""
    sweep = tmp_path / "sweep_cmd.csv"
    assert runner.invoke(app, ["sweep", "-o", str(sweep), "--quiet"]).exit_code == 0
    recorded = _play_on_sim_robot(sweep, tmp_path / "sweep_knob1.csv", "--seed", "2", "--effect", "none",
                                  shape="straight")
    run = read_run(recorded)
    assert {"t", "q1", "c1", "y1"} <= set(run.columns) and run.meta["motion"] == "sweep"
    out = tmp_path / "model.json"
    res = runner.invoke(app, ["identify", str(recorded), "-o", str(out), "--format", "json"])
    assert res.exit_code == 0, res.output
    knob = json.loads(out.read_text())["knobs"]["1"]
    for name, true in (("d_pos", 18.8), ("d_neg", -18.8), ("b_pos", 9.88), ("b_neg", 9.88)):
        assert abs(knob[name] - true) < 0.3, (name, knob[name])
    assert knob["omega"] == pytest.approx(1.45, rel=0.02)
