"""`hyst detect-shift` through the command line on recorded replays: the table and JSON, the
shifted model on disk, the figure, and every refusal and bad input (one line `Error: ...`, exit 1,
nothing written; usage errors exit 2).

The model is `hyst identify --current-only` on the sample sweep, as a user makes it; the reference
shift is each replay's true offset (the twin's, paper eqs. 3-4, in its metadata).
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from hystcli.cli import app
from hystcli.core.run import Run
from hystcli.io import load_model, model_to_dict, read_run, write_run

SAMPLES = Path(__file__).resolve().parents[1] / "sample_data" / "ice-a"
runner = CliRunner()


@pytest.fixture(scope="module")
def model(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("detect") / "model.json"
    res = runner.invoke(app, ["identify", str(SAMPLES / "sweep_knob1.csv"), "--current-only", "-o", str(path), "-q"])
    assert res.exit_code == 0, res.output
    return path


def invoke(*args):
    return runner.invoke(app, ["detect-shift", *map(str, args)])


def assert_error(res, pattern, out=None):
    assert res.exit_code == 1, res.output
    lines = [ln for ln in res.stderr.splitlines() if ln.startswith("Error:")]
    assert len(lines) == 1 and "Traceback" not in res.output, res.output
    assert pattern in lines[0], lines[0]
    if out is not None:
        assert not out.exists()


def test_detect_shift_writes_the_shifted_model_and_the_figure(model, tmp_path):
    replay = SAMPLES / "replay_alpha90_knob1.csv"
    true = float(read_run(replay).meta["true_offset1"])           # 27.45 deg
    out, fig = tmp_path / "shifted.json", tmp_path / "fig.png"
    res = invoke("--model", model, "--replay", replay, "-o", out, "--plot", fig)
    assert res.exit_code == 0, res.output
    shifted, straight = load_model(out), load_model(model)
    k = shifted.knob(1)
    assert abs(k.offset - true) <= 1.0
    assert k.d_pos == straight.knob(1).d_pos                        # d stays; the offset shifts it
    assert f"{k.offset:+.2f}" in res.stdout
    assert shifted.meta["shift_source"] == replay.name
    assert shifted.identification == straight.identification
    assert fig.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_json_output_carries_the_interval_and_the_evidence(model, tmp_path):
    replay = SAMPLES / "replay_alpha45_knob1.csv"
    true = float(read_run(replay).meta["true_offset1"])           # 13.725 deg
    res = invoke("-m", model, "--replay", replay, "-o", tmp_path / "s.json", "--format", "json", "--knob", "1",
                 "--step", "0.5")
    assert res.exit_code == 0, res.output
    r = json.loads(res.stdout)["knobs"]["1"]
    assert abs(r["offset"] - true) <= 1.0
    assert r["offset_lo"] <= r["offset"] <= r["offset_hi"] and r["offset_hi"] - r["offset_lo"] <= 1.0
    assert r["reference"] == "current" and r["returned"] is True
    assert r["evidence"]["statistic"] > r["evidence"]["threshold"]
    assert r["d_pos"] == pytest.approx(load_model(model).knob(1).d_pos + r["offset"])


def test_a_noisy_replay_is_refused_with_the_interval_and_nothing_is_written(model, tmp_path):
    # 8 mA of extra noise on the straight replay's current: the take-up is found but placed only
    # to about 0.6 deg either way, wider than the +-0.5 deg an offset must be known to
    run = read_run(SAMPLES / "replay_straight_knob1.csv")
    noisy = run.with_columns(c1=run["c1"] + np.random.default_rng(0).normal(0.0, 8.0, len(run)))
    write_run(tmp_path / "noisy.csv", noisy)
    out = tmp_path / "o.json"
    res = invoke("-m", model, "--replay", tmp_path / "noisy.csv", "-o", out)
    assert_error(res, "known only to [", out)
    assert "wider than +-0.5 deg" in res.stderr and "returned to 0 deg" in res.stderr


def test_a_replay_that_never_leaves_the_dead_zone_is_refused(model, tmp_path):
    # the sample model's dead zone is about +-19.7 deg wide; a straight replay within +-10 deg
    # reaches neither edge
    t = np.arange(0.0, 20.0, 0.01)
    q = 10.0 * np.sin(2 * np.pi * t / 20.0)
    c = 120.0 + np.random.default_rng(1).normal(0.0, 0.3, t.size)
    write_run(tmp_path / "inside.csv", Run({"t": t, "q1": q, "c1": c}))
    out = tmp_path / "o.json"
    assert_error(invoke("-m", model, "--replay", tmp_path / "inside.csv", "-o", out),
                 "no edge that gives an offset was found", out)


def test_bad_files(model, tmp_path):
    out = tmp_path / "o.json"
    replay = SAMPLES / "replay_straight_knob1.csv"
    assert_error(invoke("-m", model, "--replay", tmp_path / "missing.csv", "-o", out), "no such file", out)
    nan = tmp_path / "nan.csv"
    nan.write_text("t,q1,c1\n0,0,120\n0.01,0.1,nan\n")
    assert_error(invoke("-m", model, "--replay", nan, "-o", out), "NaN", out)
    t = np.arange(100) / 100.0
    write_run(tmp_path / "noc.csv", Run({"t": t, "q1": t}, {}))
    assert_error(invoke("-m", model, "--replay", tmp_path / "noc.csv", "-o", out), "'c1'", out)
    good = model_to_dict(load_model(model))
    bad = json.loads(json.dumps(good))
    bad["knobs"]["1"]["omega"] = -1.0
    (tmp_path / "bad.json").write_text(json.dumps(bad))
    assert_error(invoke("-m", tmp_path / "bad.json", "--replay", replay, "-o", out), "omega > 0 is violated", out)
    bad = json.loads(json.dumps(good))
    bad["identification"]["1"]["current_sign"] = "sideways"
    (tmp_path / "sign.json").write_text(json.dumps(bad))
    assert_error(invoke("-m", tmp_path / "sign.json", "--replay", replay, "-o", out), "current_sign", out)
    assert_error(invoke("-m", tmp_path / "nomodel.json", "--replay", replay, "-o", out), "no such model file", out)


def test_never_writes_over_an_input(model):
    before = model.read_bytes()
    res = invoke("-m", model, "--replay", SAMPLES / "replay_straight_knob1.csv", "-o", model)
    assert_error(res, "refusing to overwrite")
    assert model.read_bytes() == before


def test_usage_errors_exit_2(model, tmp_path):
    out = tmp_path / "o.json"
    replay = SAMPLES / "replay_straight_knob1.csv"
    assert invoke("-m", model, "-o", out).exit_code == 2                                       # no source
    assert invoke("-m", model, "--replay", replay, "--port", "x", "-o", out).exit_code == 2    # two sources
    assert invoke("-m", model, "--replay", replay, "-o", out, "--knob", "3").exit_code == 2
    assert invoke("-m", model, "--replay", replay, "-o", out, "--step", "-1").exit_code == 2
    assert invoke("-m", model, "--replay", replay, "-o", out, "--false-alarm", "0.7").exit_code == 2
    assert not out.exists()


def test_help_has_an_example():
    res = runner.invoke(app, ["detect-shift", "--help"])
    assert res.exit_code == 0 and "Example:" in res.stdout and "hyst detect-shift" in res.stdout
