"""`hyst compensate` reports what its commands ask of the motors and refuses beyond the limits.

The figures the command reports are checked against the written file, recomputed here with
numpy; the refusals write nothing and say one line. The limits' defaults and reasons are in
hystcli/safety.py.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from hystcli.io import read_run

from test_cli_model import files, invoke  # noqa: F401 - the fixture: a shifted 2-knob model, a 0.2 Hz sine


def _measured(path):
    """Peak speed and acceleration per knob of a written command file, by numpy."""
    run = read_run(path)
    out = {}
    for k in (1, 2):
        q, t = run[f"q{k}"], run.t
        v = np.diff(q) / np.diff(t)
        a = np.diff(v) / (0.5 * (np.diff(t)[1:] + np.diff(t)[:-1]))
        out[k] = (float(np.max(np.abs(v))), float(np.max(np.abs(a))), float(q.min()), float(q.max()),
                  float(t[np.argmax(np.abs(v))]))
    return out


def test_reports_the_peaks_of_what_it_writes(files):
    out = files / "cmd.csv"
    res = invoke("compensate", files / "traj.csv", "--model", files / "model.json", "-o", out,
                 "--allow-fast", "--format", "json")
    assert res.exit_code == 0, res.output
    report = json.loads(res.stdout)
    measured = _measured(out)
    for k in (1, 2):
        got = report["knobs"][str(k)]
        v, a, lo, hi, tv = measured[k]
        assert got["peak_speed"] == pytest.approx(v, rel=1e-9)
        assert got["peak_accel"] == pytest.approx(a, rel=1e-9)
        assert (got["q_min"], got["q_max"]) == (pytest.approx(lo), pytest.approx(hi))
        assert got["peak_speed_t"] == pytest.approx(tv)
    # the inverse model jumps across the backlash at each reversal of r: at least b (6.2 / 5.9
    # deg) within one 10 ms sample, far beyond 360 deg/s
    assert measured[1][0] >= 5.9 / 0.01
    assert report["within_limits"] is False and report["limits"]["max_speed"] == 360.0
    assert {(v["knob"], v["limit"]) for v in report["violations"]} == {(1, "speed"), (2, "speed")}
    assert report["controller"] == "comp+shift" and report["offsets"] == {"1": 6.0, "2": 0.0}
    assert "written as asked (--allow-fast)" in res.stderr

    # the table: one row per knob with the same figures
    res = invoke("compensate", files / "traj.csv", "--model", files / "model.json", "-o", out,
                 "--allow-fast")
    rows = {line.split()[0]: line.split() for line in res.stdout.splitlines() if line.split()[0] in "12"}
    assert float(rows["1"][4]) == pytest.approx(measured[1][0], abs=0.05)
    assert "beyond them, written with --allow-fast" in res.stdout


def test_refuses_beyond_the_speed_limit_unless_asked(files):
    fast = files / "fast.csv"
    assert invoke("compensate", files / "traj.csv", "--model", files / "model.json", "-o", fast,
                  "--allow-fast", "-q").exit_code == 0
    peak = max(v for v, *_ in _measured(fast).values())
    out = files / "cmd.csv"
    res = invoke("compensate", files / "traj.csv", "--model", files / "model.json", "-o", out)
    assert res.exit_code == 1 and not out.exists()
    errors = [ln for ln in res.stderr.splitlines() if ln.startswith("Error:")]
    assert len(errors) == 1 and "Traceback" not in res.output
    assert "refusing to write" in errors[0] and "beyond the speed limit 360 deg/s" in errors[0]
    assert "--allow-fast" in errors[0]
    # a limit just above the peak: written, within the limits
    res = invoke("compensate", files / "traj.csv", "--model", files / "model.json", "-o", out,
                 "--max-speed", f"{peak * 1.001:.6f}")
    assert res.exit_code == 0 and out.exists() and "within them" in res.stdout
    assert out.read_bytes() == fast.read_bytes()  # the check never changes the commands


def test_travel_is_never_waived_and_acceleration_is_checked_when_asked(files):
    out = files / "cmd.csv"
    # knob 1 (offset 6) reaches 9.1 + 34/1.45 + 6 = 38.5 deg at r = 30
    res = invoke("compensate", files / "traj.csv", "--model", files / "model.json", "-o", out,
                 "--travel-limit", "30", "--allow-fast")
    assert res.exit_code == 1 and not out.exists()
    assert "knob 1 reaches 38.5 deg" in res.stderr and "travel limit +-30 deg" in res.stderr
    res = invoke("compensate", files / "traj.csv", "--model", files / "model.json", "-o", out,
                 "--max-speed", "1e6", "--max-accel", "100")
    assert res.exit_code == 1 and "beyond the acceleration limit 100 deg/s^2" in res.stderr
    assert not out.exists()


@pytest.mark.parametrize("bad", [["--max-speed", "nan"], ["--max-speed", "0"], ["--travel-limit", "-1"],
                                 ["--max-accel", "inf"], ["--format", "xml"]])
def test_bad_limit_options_are_usage_errors(files, bad):
    out = files / "cmd.csv"
    res = invoke("compensate", files / "traj.csv", "--model", files / "model.json", "-o", out, *bad)
    assert res.exit_code == 2 and bad[0] in res.output and not out.exists()
