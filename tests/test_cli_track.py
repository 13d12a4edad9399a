"""`hyst track` end to end over a real pseudo-terminal: the robot is `hyst sim-robot` in a
subprocess (tests/simrobot.py: readiness is its printed path, never a fixed sleep) or the same
emulator in a thread when a test injects a fault or reads its counters. Nothing is mocked above
the transport; every host command that must succeed gets a generous reply deadline."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from hystcli.sim.calibration import calibrated_catheter
from hystcli.cli import app
from hystcli.device.emulator import Fault, serve
from hystcli.core.run import Run
from hystcli.io import read_run, save_model, write_run
from hystcli.core.model import Model
from hystcli.core.params import Shape
from hystcli.sim.live import LiveTwin
from hystcli.sim.twin import periodic, simulate
from simrobot import TIMEOUT, interrupt_after, start_sim_robot, stop

CAT = calibrated_catheter("ice-a")   # what `hyst sim-robot --catheter ice-a` serves
SHAPE = "alpha=45,theta=0"
runner = CliRunner()


def _error_line(res) -> str:
    lines = [ln for ln in res.output.splitlines() if ln.startswith("Error:")]
    assert len(lines) == 1 and "Traceback" not in res.output, res.output
    return lines[0]


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> Path:
    """The catheter's true model (no effects: the robot below serves it with --effect none), and
    the paper's 60 deg periodic reference sped up to 0.5 Hz, one cycle at 50 Hz, on SHAPE."""
    d = tmp_path_factory.mktemp("track")
    true = CAT.true_model(Shape.parse(SHAPE))
    save_model(d / "model.json", Model(true.knobs, true.geometry))
    t, r = periodic(amplitude=60.0, freq=0.5, cycles=1.0, fs=50.0)
    write_run(d / "ref.csv", Run({"t": t, "r1": r}, {"shape": SHAPE, "motion": "periodic", "trial": "1"}))
    return d


def _track(files: Path, port: str, out: Path, *extra: str, ref: str | None = None, **kw):
    return runner.invoke(app, ["track", ref or str(files / "ref.csv"), "--port", port, "--model",
                               str(files / "model.json"), "-o", str(out), "--quiet", "--timeout", TIMEOUT,
                               *extra], **kw)


def _evaluate_rmse(path: Path) -> float:
    res = runner.invoke(app, ["evaluate", str(path), "--format", "json", "--per-run"])
    assert res.exit_code == 0, res.output
    return json.loads(res.stdout)["runs"][0]["rmse"]


@pytest.mark.slow
def test_track_on_sim_robot_logs_what_compensate_and_simulate_say(files, tmp_path):
    # the commands hyst compensate writes for the reference (batch inverse, another code path)
    cmds = tmp_path / "cmds.csv"
    res = runner.invoke(app, ["compensate", str(files / "ref.csv"), "-m", str(files / "model.json"), "-o",
                              str(cmds), "--quiet", "--allow-fast"])
    assert res.exit_code == 0, res.output
    cmds = read_run(cmds)
    out = tmp_path / "run.csv"
    proc, path = start_sim_robot("--catheter", "ice-a", "--shape", SHAPE, "--seed", "4", "--effect", "none")
    try:
        # --allow-fast: the inverse jumps across the dead zone and the backlash (beyond 360 deg/s)
        res = _track(files, path, out, "--fast", "--allow-fast")
        assert res.exit_code == 0, res.output
        # the reference again, from stdin line by line (a subprocess: a real pipe)
        out2 = tmp_path / "run_stdin.csv"
        text = (files / "ref.csv").read_text()
        sub = subprocess.run([sys.executable, "-m", "hystcli", "track", "-", "--port", path, "--model",
                              str(files / "model.json"), "-o", str(out2), "--quiet", "--timeout", TIMEOUT,
                              "--fast", "--allow-fast"], input=text, capture_output=True, text=True, timeout=300)
        assert sub.returncode == 0, sub.stderr
    finally:
        assert stop(proc) == 0
    run = read_run(out)
    assert set(run.columns) == {"t", "r1", "q1", "y1", "c1"}
    assert run.meta["controller"] == "comp+shift" and float(run.meta["offset1"]) == pytest.approx(13.725)
    assert run.meta["device_catheter"] == "ice-a" and run.meta["track_lookahead"] == "0"
    np.testing.assert_array_equal(run.t, cmds.t)
    np.testing.assert_array_equal(run["r1"], cmds["r1"])
    assert np.max(np.abs(run["q1"] - cmds["q1"])) <= 1e-6   # what the log says was sent
    assert np.max(np.abs(read_run(out2)["q1"] - cmds["q1"])) <= 1e-6
    # the tip measured live against the offline twin on the same commands: only the tracker's
    # noise (0.3 deg rms on ice-a) separates them
    offline = simulate(CAT, run.t, {1: run["q1"]}, shape=Shape.parse(SHAPE), effects=(), noise=False)
    err = run["y1"] - offline["y1"]
    assert np.sqrt(np.mean(err ** 2)) < 2 * CAT.em_noise_deg
    # hyst evaluate on the log and on `hyst simulate` of the logged commands (with its own noise)
    sim = tmp_path / "offline.csv"
    res = runner.invoke(app, ["simulate", "--catheter", "ice-a", "--shape", SHAPE, "--commands", str(out),
                              "--effect", "none", "--seed", "4", "-o", str(sim), "--quiet"])
    assert res.exit_code == 0, res.output
    live, off = _evaluate_rmse(out), _evaluate_rmse(sim)
    assert abs(live - off) < 0.25 and live < 2 * CAT.em_noise_deg, (live, off)


# ------------------------------------------------------------------------------------------
# faults: motors stopped, knob back, one error line, no file
# ------------------------------------------------------------------------------------------
@pytest.fixture
def robot():
    srv = serve(LiveTwin(CAT, shape=Shape.parse(SHAPE), effects=(), seed=1))
    yield srv
    srv.shutdown()


def _angle(port: str) -> float:
    res = runner.invoke(app, ["status", "--port", port, "--timeout", TIMEOUT, "--format", "json"])
    assert res.exit_code == 0, res.output
    return json.loads(res.stdout)["knobs"]["1"]["angle"]


@pytest.mark.slow
@pytest.mark.parametrize("fault, words, back", [
    (Fault("garble", at=10), "checksum mismatch", True),
    (Fault("error", at=10, value="E_MOTOR"), "E_MOTOR", True),
    (Fault("silent", at=10), "no reply", False),
])
def test_track_faults_stop_return_and_write_nothing(robot, files, tmp_path, fault, words, back):
    robot.emulator.inject(fault)
    out = tmp_path / "run.csv"
    # a deadline that must fire on the silent robot: 2 s, far above a warmed robot's answer
    res = runner.invoke(app, ["track", str(files / "ref.csv"), "--port", robot.path, "--model",
                              str(files / "model.json"), "-o", str(out), "--fast", "--allow-fast",
                              "--timeout", "2"])
    assert res.exit_code == 1
    line = _error_line(res)
    assert words in line and "motors stopped" in line, line
    assert not out.exists() and list(tmp_path.iterdir()) == []
    if back:
        assert robot.emulator.stops >= 1  # the host stopped the motors, then brought the knob back
        assert "knob 1 returned to +0.00 deg" in line
        assert _angle(robot.path) == 0.0
    else:
        assert "knob 1 could NOT be returned to +0.00 deg" in line and "last reported at" in line


def test_track_port_closed_mid_run(files, tmp_path):
    """An unplugged cable: the robot closes its port at the 20th MOVE."""
    proc, path = start_sim_robot("--shape", SHAPE, "--effect", "none", "--fault", "close@20")
    try:
        out = tmp_path / "run.csv"
        res = _track(files, path, out, "--fast", "--allow-fast")
    finally:
        stop(proc)
    assert res.exit_code == 1
    line = _error_line(res)
    assert ("disconnected" in line or "no reply" in line) and "motors stopped" in line, line
    assert "knob 1 could NOT be returned" in line
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_bad_stdin_line_mid_run_stops_and_returns(robot, files, tmp_path):
    lines = (files / "ref.csv").read_text().splitlines()
    head = [i for i, ln in enumerate(lines) if ln.startswith("t,")][0]
    lines[head + 30] = "0.58,abc"                      # the 30th sample: the knob has moved
    out = tmp_path / "run.csv"
    res = _track(files, robot.path, out, "--fast", "--allow-fast", ref="-", input="\n".join(lines) + "\n")
    assert res.exit_code == 1
    line = _error_line(res)
    assert "not a number" in line and "knob 1 returned to +0.00 deg" in line, line
    assert robot.emulator.moves > 30 and _angle(robot.path) == 0.0
    assert not out.exists()


def test_strict_speed_refuses_a_file_beyond_the_speed_limit_before_anything_moves(robot, files, tmp_path):
    out = tmp_path / "run.csv"
    res = _track(files, robot.path, out, "--fast", "--strict-speed")   # the dead-zone jumps are too fast
    assert res.exit_code == 1
    line = _error_line(res)
    assert "refusing" in line and "speed limit" in line and "--allow-fast" in line, line
    assert robot.emulator.moves == 0 and not out.exists()


def test_strict_speed_on_stdin_stops_at_the_sample_beyond_the_speed_limit(robot, files, tmp_path):
    out = tmp_path / "run.csv"
    res = _track(files, robot.path, out, "--fast", "--strict-speed", ref="-",
                 input=(files / "ref.csv").read_text())
    assert res.exit_code == 1
    line = _error_line(res)
    assert "beyond the speed limit" in line and "knob 1 returned to +0.00 deg" in line, line
    assert not out.exists()


def test_by_default_track_rate_limits_as_compensate_does(robot, files, tmp_path):
    """No speed flag: the compensator rate-limits its commands as they come, from a file and from
    stdin alike, and they are the commands `hyst compensate` writes by default (the batch inverse
    and its rate limit over the whole file: another code path); the warning says the lag."""
    cmds = tmp_path / "cmds.csv"
    res = runner.invoke(app, ["compensate", str(files / "ref.csv"), "-m", str(files / "model.json"), "-o",
                              str(cmds), "--quiet"])
    assert res.exit_code == 0, res.output
    cmds = read_run(cmds)
    assert np.max(np.abs(np.diff(cmds["q1"]) / np.diff(cmds.t))) <= 360.0
    for ref, text in ((None, None), ("-", (files / "ref.csv").read_text())):
        out = tmp_path / f"run{ref or ''}.csv"
        res = runner.invoke(app, ["track", ref or str(files / "ref.csv"), "--port", robot.path, "--model",
                                  str(files / "model.json"), "-o", str(out), "--timeout", TIMEOUT, "--fast"],
                            input=text)
        assert res.exit_code == 0, res.output
        run = read_run(out)
        assert np.max(np.abs(run["q1"] - cmds["q1"])) <= 1e-9
        assert run.meta["track_speed_mode"] == "limit" and run.meta["track_speed_capped"] == "0"
        assert run.meta["track_catchup1"].startswith(f"{_episodes(files, tmp_path)} catch-ups")
        assert "Warning: knob 1: steps beyond the motor's limits rate-limited" in res.stderr


def _episodes(files: Path, tmp_path: Path) -> int:
    """The steps of the exact inverse beyond 360 deg/s (each one catch-up), counted on `hyst
    compensate --allow-fast`'s file."""
    exact = tmp_path / "exact.csv"
    res = runner.invoke(app, ["compensate", str(files / "ref.csv"), "-m", str(files / "model.json"), "-o",
                              str(exact), "--quiet", "--allow-fast"])
    assert res.exit_code == 0, res.output
    q = read_run(exact)
    return int(np.sum(np.abs(np.diff(q["q1"]) / np.diff(q.t)) > 360.0))


def test_usage_and_input_errors(files, tmp_path):
    res = runner.invoke(app, ["track", str(files / "ref.csv"), "--model", str(files / "model.json"), "-o",
                              str(tmp_path / "x.csv")])
    assert res.exit_code == 2  # --port is required
    res = _track(files, "/dev/nonexistent-hyst-port", tmp_path / "x.csv")
    assert res.exit_code == 1 and "cannot open port" in _error_line(res)
    res = _track(files, "/dev/null", files / "ref.csv")  # never overwrite the input
    assert res.exit_code == 1 and not (tmp_path / "x.csv").exists()
    assert "Example:" in runner.invoke(app, ["track", "--help"]).output


# ------------------------------------------------------------------------------------------
# --detect-shift-first: Algorithm 1, then tracking with its offset
# ------------------------------------------------------------------------------------------
def test_detect_shift_first_tracks_with_the_detected_offset(tmp_path):
    """The straight-shaft model with what identification stores (tests/test_live_detect.py's),
    without its geometry: the reference names no shape, so the offset can only come from the
    search. By hand (paper eqs. 1-4, ice-a: tendons 1.83 mm off axis, 6 mm pulley): 1.83 / 6 * 45
    = 13.725 deg."""
    from test_live_detect import ice_a_model

    live = ice_a_model()
    save_model(tmp_path / "model.json", Model(live.knobs, None, identification=live.identification))
    t, r = periodic(amplitude=60.0, freq=0.5, cycles=1.0, fs=50.0)
    write_run(tmp_path / "ref.csv", Run({"t": t, "r1": r}, {"motion": "periodic"}))
    out = tmp_path / "run.csv"
    proc, path = start_sim_robot("--shape", SHAPE, "--seed", "4", "--effect", "none")
    try:
        res = _track(tmp_path, path, out, "--fast", "--allow-fast", "--detect-shift-first")
    finally:
        stop(proc)
    assert res.exit_code == 0, res.output
    run = read_run(out)
    assert float(run.meta["offset1"]) == pytest.approx(13.725, abs=0.5)
    assert run.meta["controller"] == "comp+shift"
    assert np.sqrt(np.mean((run["y1"] - run["r1"]) ** 2)) < 1.0


@pytest.mark.slow
def test_ctrl_c_on_hyst_track_returns_the_knob(files, tmp_path):
    """The user's Ctrl-C: `hyst track` in a subprocess, paced through a 10 s reference on `hyst
    sim-robot`, gets SIGINT a second after it started: exit 130 (as `hyst play`), one line that
    says the knob went back, no log, and the robot reads the knob at 0 deg."""

    t, r = periodic(amplitude=30.0, freq=0.1, cycles=1.0, fs=50.0)
    ref = tmp_path / "slow.csv"
    write_run(ref, Run({"t": t, "r1": r}, {"shape": SHAPE}))
    out = tmp_path / "run.csv"
    proc_robot, path = start_sim_robot("--shape", SHAPE, "--effect", "none")
    try:
        code, err = interrupt_after(["track", str(ref), "--port", path, "--model", str(files / "model.json"),
                                     "-o", str(out), "--timeout", TIMEOUT, "--allow-fast"], "tracking ")
        assert code == 130, err
        errors = [ln for ln in err.splitlines() if ln.startswith("Error:")]
        assert len(errors) == 1 and "Traceback" not in err, err
        assert errors[0].startswith("Error: interrupted; motors stopped, knob 1 returned to +0.00 deg"), errors
        assert not out.exists()
        assert _angle(path) == 0.0
    finally:
        stop(proc_robot)
