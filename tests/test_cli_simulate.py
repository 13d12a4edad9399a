"""`hyst simulate` through the command line."""
from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from hystcli.cli import app
from hystcli.core.run import Run
from hystcli.io import read_run, write_run

runner = CliRunner()


def _invoke(*args):
    return runner.invoke(app, ["simulate", *args])


def test_help_shows_an_example():
    res = _invoke("--help")
    assert res.exit_code == 0
    assert "Example: hyst simulate" in res.output and "--effect" in res.output


def test_periodic_run_with_effects_and_full_metadata(tmp_path):
    out = tmp_path / "run.csv"
    res = _invoke("--catheter", "ice-b", "--shape", "alpha=90,theta=0", "--motion", "periodic",
                  "--effect", "friction:mu=0.3", "--effect", "latency:delay=0.05", "--seed", "3",
                  "--trial", "2", "-o", str(out))
    assert res.exit_code == 0, res.output
    run = read_run(out)
    assert list(run.columns) == ["t", "r1", "q1", "y1", "c1"]
    for key, value in {"catheter": "ice-b", "controller": "none", "shape": "alpha=90,theta=0",
                       "motion": "periodic", "trial": "2", "seed": "3",
                       "effects": "friction(mu=0.3);latency(delay=0.05)"}.items():
        assert run.meta[key] == value
    # calibrated ice-b (hystcli/sim/calibration.py): (180/pi) * 1.92 mm * (pi/2) / 6.5 mm
    # = 90 * 1.92 / 6.5 = 26.5846 deg (paper eq. 3)
    assert float(run.meta["true_offset1"]) == pytest.approx(90 * 1.92 / 6.5, abs=1e-6)
    assert np.array_equal(run["q1"], run["r1"])


def test_same_seed_same_bytes(tmp_path):
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    for path in (a, b):
        assert _invoke("--motion", "sweep", "--knobs", "1,2", "--seed", "9", "-o", str(path)).exit_code == 0
    assert a.read_bytes() == b.read_bytes()
    assert read_run(a).knobs("c") == [1, 2]


def test_commands_take_q_r_and_controller_from_the_file(tmp_path):
    t = np.arange(300) / 100.0
    cmds = tmp_path / "commands.csv"
    write_run(cmds, Run({"t": t, "r1": 20 * np.sin(t), "q1": 25 * np.sin(t)},
                        {"controller": "comp", "motion": "periodic", "offset1": "0.0"}))
    out = tmp_path / "out.csv"
    res = _invoke("--commands", str(cmds), "--shape", "alpha=45", "--effect", "none", "--no-noise",
                  "-o", str(out))
    assert res.exit_code == 0, res.output
    run = read_run(out)
    assert run.meta["controller"] == "comp" and run.meta["motion"] == "periodic"
    assert run.meta["effects"] == "none" and run.meta["offset1"] == "0.0"
    assert np.array_equal(run["q1"], 25 * np.sin(t))
    res = _invoke("--commands", str(cmds), "--controller", "comp+shift", "-o", str(out))
    assert read_run(out).meta["controller"] == "comp+shift"
    # the commands file is an input: never written over
    res = _invoke("--commands", str(cmds), "-o", str(cmds))
    assert res.exit_code == 1 and "refusing to overwrite" in res.output


@pytest.mark.parametrize("args, message", [
    (["--effect", "stiction"], "unknown effect 'stiction'"),
    (["--effect", "creep:fraction=2"], "parameter fraction = 2 is outside its valid range"),
    (["--effect", "rate:speed=1"], "unknown parameter 'speed'"),
    (["--shape", "alpha=ninety"], "'ninety' is not a number"),
    (["--shape", "alpha=abc"], "'abc' is not a number"),
    (["--shape", "alpha=1e9"], "|alpha| <= 360 deg"),
    (["--shape", "alpha=90,alpha=45"], "alpha is given twice"),
    (["--catheter", "ice-z"], "unknown virtual catheter"),
    (["--motion", "zigzag"], "unknown motion"),
    (["--knobs", "3"], "expected 1, 2 or 1,2"),
    (["--rotation", "1e309"], "must be a finite number"),
    (["--controller", "comp"], "needs the commands"),
])
def test_bad_option_is_a_usage_error_with_one_error_line_and_no_file(tmp_path, args, message):
    # a bad option value is the user's typing: exit 2 like typer's own usage errors (issue 12)
    out = tmp_path / "out.csv"
    res = _invoke(*args, "-o", str(out))
    assert res.exit_code == 2, res.output
    errors = [ln for ln in res.output.splitlines() if ln.startswith("Error")]
    assert len(errors) == 1 and message in errors[0], res.output
    assert "Traceback" not in res.output
    assert not out.exists()


def test_commands_missing_a_column(tmp_path):
    cmds = tmp_path / "commands.csv"
    cmds.write_text("t,r1\n0,0\n0.01,1\n")
    out = tmp_path / "out.csv"
    res = _invoke("--commands", str(cmds), "-o", str(out))
    assert res.exit_code == 1 and "no knob command column" in res.output and not out.exists()
    cmds.write_text("t,q1\n0,0\n0.01,1\n")
    res = _invoke("--commands", str(cmds), "--knobs", "1,2", "-o", str(out))
    assert res.exit_code == 1 and "missing column 'q2'" in res.output and not out.exists()


def test_format_prints_what_was_simulated(tmp_path):
    out = tmp_path / "run.csv"
    res = _invoke("--shape", "alpha=45", "--format", "json", "-o", str(out))
    assert res.exit_code == 0, res.output
    summary = json.loads(res.stdout)
    assert summary["output"] == str(out) and summary["samples"] == len(read_run(out))
    assert summary["shape"] == "alpha=45,theta=0" and summary["knobs"] == [1]
    res = _invoke("--format", "csv", "-o", str(out))
    assert res.stdout.startswith("key,value\n") and "catheter,ice-a" in res.stdout
    assert _invoke("-o", str(out)).stdout == ""  # the table format says it on stderr
