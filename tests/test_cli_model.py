"""CLI tests of identify, compensate, predict and rotate-shift, and the bad-input contract.

docs/design.md section 10: bad data or a bad model -> exit 1 with one line ``Error: ...`` on stderr, no
traceback, no output file; usage errors exit 2.
"""
from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from hystcli.sim import twin
from hystcli.cli import app
from hystcli.core.run import Run
from hystcli.io import load_model, model_to_dict, read_run, save_model, write_run
from hystcli.core.model import Model
from hystcli.core.params import Geometry, KnobModel

runner = CliRunner()

EXAMPLE = dict(d_pos=9.1, d_neg=-8.7, b_pos=6.2, b_neg=5.9, omega=1.45, h_pos=-4.0, h_neg=4.2)


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


@pytest.fixture
def files(tmp_path):
    model = Model({1: KnobModel(**EXAMPLE, offset=6.0), 2: KnobModel(**EXAMPLE)}, Geometry(1.2, 8.0))
    save_model(tmp_path / "model.json", model)
    t = np.arange(0, 10, 0.01)
    r = 30 * np.sin(2 * np.pi * 0.2 * t)
    write_run(tmp_path / "traj.csv", Run({"t": t, "r1": r, "r2": 0.5 * r}, {"motion": "periodic"}))
    ts, q = twin.sweep(fs=200.0)
    sweep = twin.simulate(twin.get_catheter("example-a"), ts, {1: q}, seed=3)
    write_run(tmp_path / "sweep.csv", sweep)
    return tmp_path


def test_compensate_then_predict_reproduces_the_reference(files):
    res = invoke("compensate", files / "traj.csv", "--model", files / "model.json", "-o", files / "cmd.csv",
                 "--allow-fast")  # the inverse's jumps at reversals: beyond the default speed limit
    assert res.exit_code == 0, res.output
    cmd = read_run(files / "cmd.csv")
    assert cmd.meta["controller"] == "comp+shift"
    assert float(cmd.meta["offset1"]) == 6.0
    assert cmd.meta["motion"] == "periodic"
    assert {"t", "r1", "r2", "q1", "q2"} <= set(cmd.columns)
    res = invoke("predict", files / "cmd.csv", "--model", files / "model.json", "-o", files / "pred.csv")
    assert res.exit_code == 0, res.output
    pred = read_run(files / "pred.csv")
    # the model driven by its own inverse gives back the reference (docs/design.md section 3)
    np.testing.assert_allclose(pred["y1"], cmd["r1"], atol=1e-9)
    np.testing.assert_allclose(pred["y2"], cmd["r2"], atol=1e-9)


def test_ignore_shift_is_compensation_only(files):
    res = invoke("compensate", files / "traj.csv", "--model", files / "model.json", "-o", files / "c.csv",
                 "--ignore-shift", "--allow-fast")
    assert res.exit_code == 0, res.output
    cmd = read_run(files / "c.csv")
    assert cmd.meta["controller"] == "comp"
    # the commands ignore the shift, but the run still records the shift in effect (the model's
    # own offset 6.0 here: no shape, no offset in the trajectory), flagged as ignored, so a run
    # played from them is predicted with the shaft's real shift
    assert float(cmd.meta["offset1"]) == 6.0 and cmd.meta["shift_ignored"] == "true"
    shifted = read_run(files / "traj.csv")
    # the unshifted inverse differs from the shifted one by exactly the offset on knob 1
    k = KnobModel(**EXAMPLE)
    np.testing.assert_allclose(cmd["q1"], k.inverse(shifted["r1"]), atol=1e-12)


def test_predict_keeps_the_measurement_beside_the_prediction(files):
    res = invoke("predict", files / "sweep.csv", "--model", files / "model.json", "-o", files / "p.csv")
    assert res.exit_code == 0, res.output
    p = read_run(files / "p.csv")
    s = read_run(files / "sweep.csv")
    np.testing.assert_array_equal(p["y1_measured"], s["y1"])
    # straight shaft metadata + geometry: shape 'straight' gives offset 0, not the model's 6
    expected = KnobModel(**EXAMPLE).forward(s["q1"], y0=s["y1"][0])
    np.testing.assert_allclose(p["y1"], expected, atol=1e-12)


def test_predict_summary_in_every_format(files):
    args = ("predict", files / "sweep.csv", "--model", files / "model.json", "-o", files / "p.csv")
    s = read_run(files / "sweep.csv")
    res = invoke(*args, "--format", "json")
    assert res.exit_code == 0, res.output
    row = json.loads(res.stdout)["rows"][0]
    p = read_run(files / "p.csv")
    assert row["knob"] == 1 and row["samples"] == len(s)
    # the summary's RMSE is the one of the file it wrote, prediction against measurement
    assert row["rmse_vs_measured"] == pytest.approx(float(np.sqrt(np.mean((p["y1"] - s["y1"]) ** 2))))
    assert invoke(*args, "--format", "csv").stdout.startswith("knob,samples,y_min,y_max,rmse_vs_measured")
    assert "| knob |" in invoke(*args, "-f", "markdown").stdout
    assert "RMSE vs measured" in invoke(*args).stdout
    assert invoke(*args, "-q").stdout == ""


@pytest.mark.parametrize("fmt, expected", [
    ("table", "knob 1: offset +6.000 -> +0.000 deg"),
    ("csv", "knob,offset_before,offset_after\n1,6.0,"),
    ("markdown", "| knob | offset before | offset after |"),
    ("latex", "\\begin{tabular}"),
    ("json", '"offset_after": -6.0'),
])
def test_rotate_shift_formats(files, fmt, expected):
    res = invoke("rotate-shift", "--model", files / "model.json", "--degrees", "90", "-o", files / "r.json",
                 "--format", fmt)
    assert res.exit_code == 0, res.output
    assert expected in res.stdout


def test_compensate_warns_outside_the_identified_range(files):
    res = invoke("identify", files / "sweep.csv", "-o", files / "id.json", "-q")
    assert res.exit_code == 0, res.output
    t = np.arange(0, 5, 0.01)
    write_run(files / "big.csv", Run({"t": t, "r1": 90 * np.sin(t)}, {}))
    res = invoke("compensate", files / "big.csv", "--model", files / "id.json", "-o", files / "o.csv",
                 "--allow-fast")
    assert res.exit_code == 0
    assert "outside the identified range" in res.stderr


def test_rotate_shift(files):
    res = invoke("rotate-shift", "--model", files / "model.json", "--degrees", "90", "-o", files / "r.json")
    assert res.exit_code == 0, res.output
    m = load_model(files / "r.json")
    # (6, 0) rotated by -90 deg -> (0, -6)
    assert m.knob(1).offset == pytest.approx(0.0, abs=1e-12)
    assert m.knob(2).offset == pytest.approx(-6.0)


def test_version_and_help():
    res = invoke("--version")
    assert res.exit_code == 0 and res.stdout.startswith("hyst ")
    for cmd in ("identify", "compensate", "predict", "rotate-shift"):
        res = invoke(cmd, "--help")
        assert res.exit_code == 0
        assert "Example: hyst" in res.stdout


# ---------------------------------------------------------------------------------------------
# the bad-input contract, for every command in this module
# ---------------------------------------------------------------------------------------------
BAD_RUNS = {
    "missing file": None,
    "empty file": "",
    "NaN": "t,q1,c1,r1,y1\n0,0,1,0,0\n0.1,nan,1,1,1\n",
    "non-increasing t": "t,q1,c1,r1,y1\n0,0,1,0,0\n0,1,1,1,1\n",
    "text in a numeric column": "t,q1,c1,r1,y1\n0,0,1,0,0\n0.1,abc,1,1,1\n",
    "missing column": "t,z\n0,0\n0.1,1\n",
}
COMMANDS = {
    "identify": lambda d, run: ["identify", run, "-o", d / "out.json"],
    "compensate": lambda d, run: ["compensate", run, "--model", d / "model.json", "-o", d / "out.csv"],
    "predict": lambda d, run: ["predict", run, "--model", d / "model.json", "-o", d / "out.csv"],
}


def assert_clean_failure(res, d, needle=None):
    assert res.exit_code == 1, (res.exit_code, res.output)
    err = res.stderr.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("Error: "), res.stderr
    assert "Traceback" not in res.output
    if needle:
        assert needle in err[0], err[0]
    assert not (d / "out.csv").exists() and not (d / "out.json").exists()


@pytest.mark.parametrize("cmd", list(COMMANDS))
@pytest.mark.parametrize("case", list(BAD_RUNS))
def test_bad_runs_fail_cleanly(files, cmd, case):
    path = files / "bad.csv"
    if BAD_RUNS[case] is not None:
        path.write_text(BAD_RUNS[case])
    res = invoke(*COMMANDS[cmd](files, path))
    needle = {"missing file": "no such file", "empty file": "empty file", "NaN": "NaN",
              "non-increasing t": "not strictly increasing", "text in a numeric column": "'abc' is not a number",
              "missing column": "column"}[case]
    assert_clean_failure(res, files, needle)


@pytest.mark.parametrize("cmd", ["compensate", "predict", "rotate-shift"])
@pytest.mark.parametrize("case", ["invalid parameters", "unknown version", "missing model"])
def test_bad_models_fail_cleanly(files, cmd, case):
    d = model_to_dict(load_model(files / "model.json"))
    if case == "invalid parameters":
        d["knobs"]["1"]["omega"] = -1.0
    elif case == "unknown version":
        d["version"] = 99
    bad = files / "badmodel.json"
    if case != "missing model":
        bad.write_text(json.dumps(d))
    src = files / "traj.csv" if cmd == "compensate" else files / "sweep.csv"
    args = {"compensate": ["compensate", src, "--model", bad, "-o", files / "out.csv"],
            "predict": ["predict", src, "--model", bad, "-o", files / "out.csv"],
            "rotate-shift": ["rotate-shift", "--model", bad, "--degrees", "10", "-o", files / "out.json"]}[cmd]
    res = invoke(*args)
    needle = {"invalid parameters": "omega > 0 is violated", "unknown version": "unknown model version 99",
              "missing model": "no such model file"}[case]
    assert_clean_failure(res, files, needle)


def test_refuses_to_write_over_an_input(files):
    before = (files / "traj.csv").read_text()
    res = invoke("compensate", files / "traj.csv", "--model", files / "model.json", "-o", files / "traj.csv")
    assert res.exit_code == 1 and "overwrite an input" in res.stderr
    assert (files / "traj.csv").read_text() == before


def test_model_without_the_runs_knob(files):
    save_model(files / "one.json", Model({1: KnobModel(**EXAMPLE)}))
    res = invoke("compensate", files / "traj.csv", "--model", files / "one.json", "-o", files / "out.csv")
    assert_clean_failure(res, files, "no knob 2")


@pytest.mark.parametrize("args", [
    ["identify"],                                   # missing argument
    ["compensate", "x.csv"],                        # missing --model and -o
    ["identify", "x.csv", "-o", "m.json", "--omega", "abc"],
    ["identify", "x.csv", "-o", "m.json", "--level", "1.5"],
    ["no-such-command"],
])
def test_usage_errors_exit_2(args):
    assert invoke(*args).exit_code == 2
