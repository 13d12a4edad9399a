"""`hyst sim-robot` and `hyst play` end to end over a real pseudo-terminal.

The robot is `hyst sim-robot` in a subprocess (the most honest setup) or the same emulator in a
thread when a test needs to look inside it (its stop counter); the host side is the CLI through
typer's CliRunner. Nothing is mocked above the transport.
"""
from __future__ import annotations

import json
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from hystcli import compensation
from hystcli.cli import app
from hystcli.device import Device, play_trajectory
from hystcli.emulator import Fault, serve
from hystcli.io import Run, read_run, write_run
from hystcli.model import Shape
from hystcli.calibration import calibrated_catheter
from hystcli.twin import LiveTwin, periodic, simulate

CAT = calibrated_catheter("ice-a")  # what `hyst sim-robot` and `hyst simulate` serve as ice-a
SHAPE = "alpha=45,theta=0"
runner = CliRunner()


def _start_sim_robot(*args: str) -> tuple[subprocess.Popen, str]:
    proc = subprocess.Popen([sys.executable, "-m", "hystcli", "sim-robot", "--quiet", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    ready, _, _ = select.select([proc.stdout], [], [], 60)
    if not ready:
        proc.kill()
        raise AssertionError("sim-robot printed no device path within 60 s")
    path = proc.stdout.readline().strip()
    assert path.startswith("/dev/"), (path, proc.stderr.read() if proc.poll() is not None else "")
    return proc, path


def _stop(proc: subprocess.Popen) -> int:
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
    try:
        return proc.wait(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()


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
    proc, path = _start_sim_robot("--catheter", "ice-a", "--shape", shape, *robot_args)
    try:
        res = runner.invoke(app, ["play", str(commands), "--port", path, "-o", str(out), "--fast",
                                  "--quiet"])
        assert res.exit_code == 0, res.output
    finally:
        assert _stop(proc) == 0  # SIGTERM ends it cleanly
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


def test_sim_robot_refuses_an_unknown_catheter():
    res = runner.invoke(app, ["sim-robot", "--catheter", "ice-z"])
    assert res.exit_code == 1 and "unknown virtual catheter 'ice-z'" in res.output


def test_play_fault_from_sim_robot_subprocess_writes_nothing(commands, tmp_path):
    proc, path = _start_sim_robot("--fault", "close@20")
    try:
        out = tmp_path / "run.csv"
        res = runner.invoke(app, ["play", str(commands), "--port", path, "-o", str(out), "--fast",
                                  "--timeout", "0.5"])
    finally:
        try:
            code = proc.wait(timeout=20)  # its port closed, the robot process ends by itself
        finally:
            _stop(proc)
    assert res.exit_code == 1
    assert "Error:" in res.output and ("disconnected" in res.output or "no reply" in res.output)
    assert "Traceback" not in res.output
    assert not out.exists() and list(tmp_path.iterdir()) == []
    assert code == 0


def test_sim_robot_refuses_a_bad_fault_spec():
    res = runner.invoke(app, ["sim-robot", "--fault", "boom@1"])
    assert res.exit_code == 1 and "unknown fault 'boom'" in res.output


# ------------------------------------------------------------------------------------------
# play faults against an emulator in a thread (to see its stop counter)
# ------------------------------------------------------------------------------------------
@pytest.fixture
def robot():
    srv = serve(LiveTwin(CAT, seed=1))
    yield srv
    srv.shutdown()


@pytest.mark.parametrize("fault, words", [
    (Fault("error", at=10, value="E_MOTOR"), "E_MOTOR"),
    (Fault("garble", at=10), "checksum mismatch"),
    (Fault("silent", at=10), "no reply"),
])
def test_play_faults_stop_the_motors_and_write_nothing(robot, commands, tmp_path, fault, words):
    robot.emulator.inject(fault)
    out = tmp_path / "run.csv"
    res = runner.invoke(app, ["play", str(commands), "--port", robot.path, "-o", str(out), "--fast",
                              "--timeout", "0.3"])
    assert res.exit_code == 1
    last = res.output.strip().splitlines()[-1]
    assert last.startswith("Error:") and words in last
    assert not out.exists()
    if fault.kind != "silent":
        assert robot.emulator.stops >= 1  # the host stopped the motors


def test_play_interrupted_stops_the_motors(robot, commands):
    def interrupt(i, n):
        if i == 5:
            raise KeyboardInterrupt

    with Device(robot.path, timeout=0.5) as dev:
        with pytest.raises(KeyboardInterrupt):
            play_trajectory(dev, read_run(commands), paced=False, progress=interrupt)
        assert robot.emulator.stops == 1


def test_play_paced_follows_the_file_timing(robot):
    t = np.arange(11) * 0.03  # 0.3 s
    traj = Run({"t": t, "q1": np.linspace(0, 3, 11)})
    with Device(robot.path, timeout=0.5) as dev:
        t0 = time.monotonic()
        run = play_trajectory(dev, traj, paced=True)
        elapsed = time.monotonic() - t0
    assert 0.3 <= elapsed < 2.0  # never ahead of the file; slack for a loaded machine
    assert run.meta["play_timing"] == "paced" and float(run.meta["play_max_lag_s"]) < 0.5


def test_play_refuses_a_knob_the_device_lacks(commands, tmp_path):
    srv = serve(LiveTwin(CAT, knobs=(2,)))
    try:
        out = tmp_path / "run.csv"
        res = runner.invoke(app, ["play", str(commands), "--port", srv.path, "-o", str(out)])
        assert res.exit_code == 1 and "knob 1" in res.output and "drives knobs 2" in res.output
        assert srv.emulator.moves == 0 and not out.exists()
    finally:
        srv.shutdown()


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


def test_help_has_examples():
    for cmd in ("play", "sim-robot"):
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


def test_identify_on_a_sweep_played_on_the_robot(tmp_path):
    """Job 1 on a live robot: `hyst sweep`, `hyst play` on `hyst sim-robot`, `hyst identify` on
    the recording. The bare model (no unmodelled effects) is identified to within a few tenths of
    a degree of the catheter's true knob 1: hystcli/calibration.py gives ice-a d_pos = -d_neg =
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
