"""`hyst detect-shift` through the CLI: success (table and JSON), the shifted model on disk, and
every bad input (one line `Error: ...`, exit 1, nothing written; usage errors exit 2)."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from hystcli import twin
from hystcli.cli import app
from hystcli.io import Run, load_model, model_to_dict, save_model, write_run
from hystcli.model import Model, Shape

from test_shift import CATHETER, MODEL, slow_ramp

runner = CliRunner()
SHAPE = "alpha=90,theta=45"   # both knobs shifted by 13.5 cos 45 = 9.546 deg (paper eqs. 3-4)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("detect")
    t, q = slow_ramp(speed=2.0, fs=250.0)
    run = twin.simulate(CATHETER, t, {1: q, 2: q}, shape=Shape.parse(SHAPE), effects=(), seed=4)
    write_run(d / "bent.csv", run)
    save_model(d / "model.json", MODEL)
    return d


def invoke(*args):
    return runner.invoke(app, ["detect-shift", *map(str, args)])


def assert_error(res, pattern, out=None):
    assert res.exit_code == 1, res.output
    lines = [ln for ln in res.stderr.splitlines() if ln.startswith("Error:")]
    assert len(lines) == 1 and "Traceback" not in res.output
    assert pattern in lines[0], lines[0]
    if out is not None:
        assert not out.exists()


def test_detect_shift_writes_the_shifted_model(files):
    out = files / "shifted.json"
    res = invoke("--model", files / "model.json", "--replay", files / "bent.csv", "-o", out,
                 "--plot", files / "fig.png")
    assert res.exit_code == 0, res.output
    true = math.degrees(1.2 / 8.0 * math.radians(90)) * math.cos(math.radians(45))
    shifted = load_model(out)
    for k in (1, 2):
        assert shifted.knob(k).offset == pytest.approx(true, abs=0.5)
        assert shifted.knob(k).d_pos == MODEL.knob(k).d_pos          # d stays; offset shifts it
        assert f"{shifted.knob(k).offset:+.2f}" in res.stdout
    assert shifted.meta["shift_source"] == "bent.csv"
    assert shifted.identification == MODEL.identification
    assert (files / "fig.png").read_bytes()[:4] == b"\x89PNG"


def test_json_output_and_one_knob(files):
    out = files / "k2.json"
    res = invoke("-m", files / "model.json", "--replay", files / "bent.csv", "-o", out,
                 "--knob", "2", "--format", "json", "--max-travel", "24", "--step", "0.5")
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    assert list(data["knobs"]) == ["2"]
    r = data["knobs"]["2"]
    assert r["d_pos"] == pytest.approx(MODEL.knob(2).d_pos + r["offset"])
    assert r["travel"] <= 24 and r["steps"] == r["travel"] / 0.5
    assert load_model(out).knob(1).offset == 0.0                     # knob 1 untouched


def test_thresholds_can_be_given_when_the_model_has_none(files, tmp_path):
    bare = tmp_path / "bare.json"
    save_model(bare, Model(dict(MODEL.knobs), MODEL.geometry))
    out = tmp_path / "o.json"
    res = invoke("-m", bare, "--replay", files / "bent.csv", "-o", out, "--knob", "1")
    assert_error(res, "--eps-lower", out)
    res = invoke("-m", bare, "--replay", files / "bent.csv", "-o", out, "--knob", "1",
                 "--eps-lower", "1.4", "--eps-upper", "20", "--current-dead-zone", "120")
    assert res.exit_code == 0, res.output
    assert load_model(out).knob(1).offset == pytest.approx(9.546, abs=0.5)


def test_replay_without_a_current_column(files, tmp_path):
    t = np.arange(100) / 100.0
    write_run(tmp_path / "noc.csv", Run({"t": t, "q1": t}, {}))
    out = tmp_path / "o.json"
    assert_error(invoke("-m", files / "model.json", "--replay", tmp_path / "noc.csv", "-o", out),
                 "'c1'", out)


def test_replay_that_never_leaves_the_dead_zone(files, tmp_path):
    t, q = slow_ramp(amplitude=5.0, speed=2.0, fs=250.0)
    write_run(tmp_path / "flat.csv", twin.simulate(CATHETER, t, {1: q}, effects=(), seed=1))
    out = tmp_path / "o.json"
    assert_error(invoke("-m", files / "model.json", "--replay", tmp_path / "flat.csv", "-o", out),
                 "no edge found within", out)


def test_bad_files(files, tmp_path):
    out = tmp_path / "o.json"
    model = files / "model.json"
    assert_error(invoke("-m", model, "--replay", tmp_path / "missing.csv", "-o", out), "no such file", out)
    nan = tmp_path / "nan.csv"
    nan.write_text("t,q1,c1\n0,0,120\n0.01,0.1,nan\n")
    assert_error(invoke("-m", model, "--replay", nan, "-o", out), "NaN", out)
    bad = model_to_dict(MODEL)
    bad["knobs"]["1"]["omega"] = -1.0
    (tmp_path / "bad.json").write_text(json.dumps(bad))
    assert_error(invoke("-m", tmp_path / "bad.json", "--replay", files / "bent.csv", "-o", out),
                 "omega > 0 is violated", out)
    bad = model_to_dict(MODEL)
    bad["version"] = 99
    (tmp_path / "v99.json").write_text(json.dumps(bad))
    assert_error(invoke("-m", tmp_path / "v99.json", "--replay", files / "bent.csv", "-o", out),
                 "unknown model version", out)
    assert_error(invoke("-m", tmp_path / "nomodel.json", "--replay", files / "bent.csv", "-o", out),
                 "no such model file", out)


def test_never_writes_over_an_input(files):
    before = (files / "model.json").read_bytes()
    res = invoke("-m", files / "model.json", "--replay", files / "bent.csv", "-o", files / "model.json")
    assert_error(res, "refusing to overwrite")
    assert (files / "model.json").read_bytes() == before


def test_usage_errors_exit_2(files, tmp_path):
    out = tmp_path / "o.json"
    assert invoke("-m", files / "model.json", "-o", out).exit_code == 2            # no source
    assert invoke("-m", files / "model.json", "--replay", files / "bent.csv", "--port", "x",
                  "-o", out).exit_code == 2                                       # two sources
    assert invoke("-m", files / "model.json", "--replay", files / "bent.csv", "-o", out,
                  "--knob", "3").exit_code == 2
    assert invoke("-m", files / "model.json", "--replay", files / "bent.csv", "-o", out,
                  "--step", "-1").exit_code == 2
    assert not out.exists()


def test_help_has_an_example():
    res = runner.invoke(app, ["detect-shift", "--help"])
    assert res.exit_code == 0 and "hyst detect-shift sample_data/ice-a/replay_alpha90_knob1.csv --model" in res.stdout


def test_the_readme_walk_through_steps_1_and_2(tmp_path):
    # README "A walk through the method": identify the sample sweep (its fast-sweep fit states
    # +-0.5 deg for its edges), then detect the shift on the alpha=90 replay. An offset must come
    # back (a stricter rule once refused it for the model edge's own uncertainty), and the edge
    # found must be the twin's: ice-a knob 1 has d_pos 18.8, and alpha=90 shifts it by 27.45
    # (the twin's calibrated shift, README step 2), so the positive edge lies at 46.25 deg
    from pathlib import Path

    root = Path(__file__).resolve().parents[1] / "sample_data" / "ice-a"
    mp, out = tmp_path / "model.json", tmp_path / "shifted.json"
    res = runner.invoke(app, ["identify", str(root / "sweep_knob1.csv"), "-o", str(mp), "-q"])
    assert res.exit_code == 0, res.output
    res = runner.invoke(app, ["detect-shift", "--model", str(mp), "--replay", str(root / "replay_alpha90_knob1.csv"),
                              "-o", str(out), "-q"])
    assert res.exit_code == 0, res.output
    k0, k1 = load_model(mp).knob(1), load_model(out).knob(1)
    assert abs(k1.offset + k0.d_pos - 46.25) <= 0.6


def test_an_offset_from_the_sweeps_current_says_so(tmp_path):
    # zoo design plant 831 (examined in stop 34): its straight sweep's tip fit cannot place
    # d_pos, its current does; through the CLI as a user runs it, identify then detect-shift
    # (730 until stop 41: which of its fit's near-equal optima wins depends on numpy's SIMD
    # kernels, tests/test_shift_zoo.py)
    from hystcli.zoo import plants

    case = plants.replay_case(831)
    (tmp_path / "sweep.csv").write_text(case.straight_sweep.csv_text())
    (tmp_path / "replay.csv").write_text(case.replay.csv_text())
    mp = tmp_path / "model.json"
    res = runner.invoke(app, ["identify", str(tmp_path / "sweep.csv"), "-o", str(mp), "-q"])
    assert res.exit_code == 0, res.output
    ident = load_model(mp).identification[1]
    assert "d_pos" in ident.unfixed and ident.current_edge_pos_se is not None
    res = invoke("-m", mp, "--replay", tmp_path / "replay.csv", "-o", tmp_path / "shifted.json")
    assert res.exit_code == 0, res.output
    assert "offset from d_pos as the sweep's current showed it" in res.stdout
    res = invoke("-m", mp, "--replay", tmp_path / "replay.csv", "-o", tmp_path / "shifted2.json",
                 "--format", "json")
    r = json.loads(res.stdout)["knobs"]["1"]
    assert r["reference"] == "current" and r["edge"] == "pos"
    assert r["offset"] == pytest.approx(case.offset, abs=0.5)
