"""`hyst compensate` reports what its commands ask of the motors, rate-limits the inverse's jumps
by default, and refuses beyond the limits when asked (travel always).

The figures the command reports are checked against the written file, recomputed here with
numpy; the refusals write nothing and say one line. The limits' defaults and reasons are in
hystcli/safety.py.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from hystcli.io import read_run, save_model
from hystcli.core.model import Model
from hystcli.core.params import KnobModel

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


def test_strict_speed_refuses_beyond_the_speed_limit(files):
    fast = files / "fast.csv"
    assert invoke("compensate", files / "traj.csv", "--model", files / "model.json", "-o", fast,
                  "--allow-fast", "-q").exit_code == 0
    peak = max(v for v, *_ in _measured(fast).values())
    out = files / "cmd.csv"
    res = invoke("compensate", files / "traj.csv", "--model", files / "model.json", "-o", out,
                 "--strict-speed")
    assert res.exit_code == 1 and not out.exists()
    errors = [ln for ln in res.stderr.splitlines() if ln.startswith("Error:")]
    assert len(errors) == 1 and "Traceback" not in res.output
    assert f"refusing to write {out}" in errors[0] and "beyond the speed limit 360 deg/s" in errors[0]
    assert "--allow-fast" in errors[0] and "--strict-speed" in errors[0]
    # a limit just above the peak: written, within the limits, with or without --strict-speed
    for mode in ("--strict-speed", None):
        res = invoke("compensate", files / "traj.csv", "--model", files / "model.json", "-o", out,
                     "--max-speed", f"{peak * 1.001:.6f}", *([mode] if mode else []))
        assert res.exit_code == 0 and out.exists() and "within them)" in res.stdout
        assert "Warning" not in res.stderr
        assert out.read_bytes() == fast.read_bytes()  # the check never changes the commands


def test_allow_fast_and_strict_speed_together_are_a_usage_error(files):
    out = files / "cmd.csv"
    res = invoke("compensate", files / "traj.csv", "--model", files / "model.json", "-o", out,
                 "--allow-fast", "--strict-speed")
    assert res.exit_code == 2 and "--strict-speed" in res.output and not out.exists()


def test_by_default_the_jumps_are_rate_limited_and_the_knob_catches_up(files):
    """Without a flag the commands are the exact inverse's, but across each jump (the backlash
    at a reversal of r, the dead zone where r crosses its height) the knob moves at the speed
    limit until it is back on them; the warning names each knob's lag, and the file's commands
    keep to the limit."""
    exact_path, out = files / "exact.csv", files / "cmd.csv"
    assert invoke("compensate", files / "traj.csv", "--model", files / "model.json", "-o", exact_path,
                  "--allow-fast", "-q").exit_code == 0
    res = invoke("compensate", files / "traj.csv", "--model", files / "model.json", "-o", out,
                 "--format", "json")
    assert res.exit_code == 0, res.output
    report = json.loads(res.stdout)
    assert report["within_limits"] is True and report["speed"] == "limit"
    exact, cmd = read_run(exact_path), read_run(out)
    for k in (1, 2):
        v, *_ = _measured(out)[k]
        assert v <= 360.0
        lag = cmd[f"q{k}"] != exact[f"q{k}"]
        # each jump of the exact inverse (far apart) is one catch-up of a few samples
        jumps = int(np.sum(np.abs(np.diff(exact[f"q{k}"])) / 0.01 > 360.0))
        assert jumps >= 4 and jumps <= lag.sum() <= 6 * jumps
        assert not lag[-1]
        got = report["rate_limited"][str(k)]
        assert got["episodes"] == jumps and got["caught_up"] is True
        # the longest lag, measured here: the longest run of lagging samples (plus the sample it lands on)
        runs, n = [], 0
        for flag in lag:
            n = n + 1 if flag else 0
            runs.append(n)
        assert got["longest_s"] == pytest.approx(max(runs) * 0.01, abs=1e-9)
        assert f"knob {k}: steps beyond the motor's limits rate-limited ({jumps} times" in res.stderr
    assert "on the model this moves the tip by up to" in res.stderr


def test_strict_speed_refuses_the_acceleration_and_the_default_limits_it(files):
    out = files / "cmd.csv"
    res = invoke("compensate", files / "traj.csv", "--model", files / "model.json", "-o", out,
                 "--max-speed", "1e6", "--max-accel", "100", "--strict-speed")
    assert res.exit_code == 1 and "beyond the acceleration limit 100 deg/s^2" in res.stderr
    assert not out.exists()
    res = invoke("compensate", files / "traj.csv", "--model", files / "model.json", "-o", out,
                 "--max-speed", "1e6", "--max-accel", "100")
    assert res.exit_code == 0, res.output
    _, a, *_ = _measured(out)[1]
    assert a <= 100.0


def test_travel_is_never_waived(files):
    out = files / "cmd.csv"
    # knob 1 (offset 6) reaches 9.1 + 34/1.45 + 6 = 38.5 deg at r = 30
    res = invoke("compensate", files / "traj.csv", "--model", files / "model.json", "-o", out,
                 "--travel-limit", "30", "--allow-fast")
    assert res.exit_code == 1 and not out.exists()
    assert "knob 1 reaches 38.5 deg" in res.stderr and "travel limit +-30 deg" in res.stderr
    res = invoke("compensate", files / "traj.csv", "--model", files / "model.json", "-o", out,
                 "--travel-limit", "30")
    assert res.exit_code == 1 and "travel limit +-30 deg" in res.stderr and not out.exists()


@pytest.mark.parametrize("bad", [["--max-speed", "nan"], ["--max-speed", "0"], ["--travel-limit", "-1"],
                                 ["--max-accel", "inf"], ["--format", "xml"]])
def test_bad_limit_options_are_usage_errors(files, bad):
    out = files / "cmd.csv"
    res = invoke("compensate", files / "traj.csv", "--model", files / "model.json", "-o", out, *bad)
    assert res.exit_code == 2 and bad[0] in res.output and not out.exists()


# ------------------------------------------------------------------------------------------
# the paper's periodic reference, with no flag
# ------------------------------------------------------------------------------------------
# knob 1 of sample_data/ice-a as `hyst identify sample_data/ice-a/sweep_knob1.csv` reads it, rounded:
# written by hand so this test does not depend on the identification
ICE_A = dict(d_pos=20.27, d_neg=-20.52, b_pos=12.48, b_neg=12.64, omega=1.249, h_pos=-6.57, h_neg=7.17)
PERIODIC = Path(__file__).resolve().parents[1] / "sample_data" / "reference_periodic.csv"


@pytest.fixture
def ice_a(tmp_path):
    save_model(tmp_path / "model.json", Model({1: KnobModel(**ICE_A)}))
    return tmp_path / "model.json"


def test_the_papers_periodic_reference_compensates_without_a_flag(ice_a, tmp_path):
    out, exact_path = tmp_path / "cmd.csv", tmp_path / "exact.csv"
    res = invoke("compensate", PERIODIC, "--model", ice_a, "-o", out, "--format", "json")
    assert res.exit_code == 0, res.output
    report = json.loads(res.stdout)
    ref, cmd = read_run(PERIODIC), read_run(out)
    knob = KnobModel(**ICE_A)
    exact = knob.inverse(ref["r1"])
    q = cmd["q1"]
    # within the speed limit, measured on the file
    assert np.max(np.abs(np.diff(q) / np.diff(cmd.t))) <= 360.0
    # the tip on the model follows r wherever the knob is on the exact inverse ...
    y = knob.forward(q)
    on = q == exact
    assert np.max(np.abs(y[on] - ref["r1"][on])) < 1e-9
    # ... and the knob is off it only during the catch-ups the report and the warning state
    got = report["rate_limited"]["1"]
    dt = float(np.median(np.diff(ref.t)))
    assert (~on).sum() * dt == pytest.approx(got["total_s"], abs=1e-6)
    assert got["episodes"] == int(np.sum(np.abs(np.diff(exact)) / np.diff(ref.t) > 360.0))
    assert got["caught_up"] and not (~on)[-1]
    assert got["tip_error"] == pytest.approx(np.max(np.abs(y - knob.forward(exact))), abs=1e-9)
    assert got["tip_error"] > 0.1  # the knob's lag shows on the tip, and is said
    warning = next(ln for ln in res.stderr.splitlines() if "rate-limited" in ln)
    assert warning.startswith("Warning: knob 1: ")
    assert f"by up to {got['longest_s']:.3g} s" in warning and f"{got['total_s']:.3g} s in all" in warning
    assert f"moves the tip by up to {got['tip_error']:.3g} deg" in warning

    # --strict-speed: refused, nothing written
    strict = tmp_path / "strict.csv"
    res = invoke("compensate", PERIODIC, "--model", ice_a, "-o", strict, "--strict-speed")
    assert res.exit_code == 1 and not strict.exists()
    assert [ln for ln in res.stderr.splitlines() if ln.startswith("Error:")] == [res.stderr.strip()]
    # --allow-fast: the exact inverse, jumps included
    res = invoke("compensate", PERIODIC, "--model", ice_a, "-o", exact_path, "--allow-fast")
    assert res.exit_code == 0, res.output
    np.testing.assert_array_equal(read_run(exact_path)["q1"], exact)
    assert np.max(np.abs(np.diff(exact) / np.diff(ref.t))) > 3000.0
