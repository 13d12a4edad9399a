"""CLI of `hyst diagnose` (issue 5): report, augmented model that `hyst predict` and
`hyst compensate` then use, and the bad-input contract (exit 1, one line, no output file)."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from hystcli import compensation
from hystcli.core import effects as E
from hystcli.sim import twin
from hystcli.cli import app
from hystcli.core.run import Run
from hystcli.io import load_model, read_run, save_model, write_run
from hystcli.core.model import Model
from hystcli.core.params import Shape

runner = CliRunner()
CAT = twin.get_catheter("example-a")
BASE = Model(CAT.knobs, CAT.geometry, meta={"catheter": "example-a"})
T = np.arange(0, 30.0 + 1e-9, 0.02)
LATENCY = E.make_effect("latency", delay=0.3)


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("diag")
    save_model(d / "model.json", BASE)
    paths = []
    for i, shape in enumerate(["straight", "alpha=90,theta=0", "alpha=45,theta=0"]):
        q = {1: 50 * np.sin(2 * np.pi * (0.05 + 0.01 * i) * T)}
        run = twin.simulate(CAT, T, q, shape=Shape.parse(shape), effects=(LATENCY,), seed=i,
                            meta={"motion": "periodic" if i < 2 else "nonperiodic", "trial": i + 1})
        paths.append(d / f"run{i}.csv")
        write_run(paths[-1], run)
    other = twin.simulate(twin.get_catheter("example-b"), T, {1: 40 * np.sin(0.3 * T)}, seed=9)
    write_run(d / "other.csv", other)
    write_run(d / "no_y.csv", Run({"t": T, "q1": T}, {"catheter": "example-a"}))
    write_run(d / "two_knobs.csv", twin.simulate(CAT, T, {1: 30 * np.sin(0.3 * T), 2: 20 * np.sin(0.5 * T)}, seed=4))
    return d, paths


def test_diagnose_writes_report_model_and_plot(files):
    d, paths = files
    res = invoke("diagnose", "--model", d / "model.json", *paths, "-o", d / "report.json",
                 "--model-out", d / "aug.json", "--plot", d / "diag.png")
    assert res.exit_code == 0, res.output
    assert "WHERE" in res.stdout and "HOW FAR" in res.stdout and "latency" in res.stdout
    report = json.loads((d / "report.json").read_text())
    assert report["format"] == "hyst-diagnosis"
    assert report["which"]["selected"][0]["name"] == "latency"
    assert abs(report["which"]["selected"][0]["params"]["delay"] - 0.3) < 0.03
    assert report["how_far"]["rmse_shrink_pct"] > 50
    assert (d / "diag.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    aug = load_model(d / "aug.json")
    assert [e.name for e in aug.effects] == ["latency"]
    assert aug.knobs == BASE.knobs  # the base parameters are untouched

    # hyst predict uses the effects: the prediction now tracks the measured (delayed) tip
    for model, name in ((d / "model.json", "base"), (d / "aug.json", "aug")):
        assert invoke("predict", paths[1], "--model", model, "-o", d / f"pred_{name}.csv").exit_code == 0
    errs = {}
    for name in ("base", "aug"):
        p = read_run(d / f"pred_{name}.csv")
        errs[name] = float(np.sqrt(np.mean((p["y1"] - p["y1_measured"]) ** 2)))
    assert errs["aug"] < 0.3 * errs["base"]


def test_json_format_and_holdout(files):
    d, paths = files
    res = invoke("diagnose", "--model", d / "model.json", *paths, "--holdout", "motion=nonperiodic",
                 "--candidates", "latency,rate", "--format", "json")
    assert res.exit_code == 0, res.output
    report = json.loads(res.stdout)
    assert report["holdout"].startswith("motion=nonperiodic")
    assert {c["name"] for c in report["which"]["rounds"][0]["candidates"]} == {"latency", "rate"}


def test_compensate_with_the_augmented_model_uses_its_effects(files, tmp_path):
    d, paths = files
    assert invoke("diagnose", "--model", d / "model.json", *paths, "--model-out", tmp_path / "aug.json",
                  "-q").exit_code == 0
    t, r = twin.periodic(fs=50.0)
    write_run(tmp_path / "traj.csv", Run({"t": t, "r1": r}, {"shape": "alpha=90,theta=0"}))
    errs = []
    for m in (d / "model.json", tmp_path / "aug.json"):
        res = invoke("compensate", tmp_path / "traj.csv", "--model", m, "-o", tmp_path / "cmd.csv",
                     "--allow-fast")
        assert res.exit_code == 0, res.output
        cmd = read_run(tmp_path / "cmd.csv")
        run = twin.simulate_motion(CAT, Shape.parse("alpha=90,theta=0"), commands=cmd, effects=[LATENCY], seed=1)
        errs.append(float(np.sqrt(np.mean((run["y1"] - r) ** 2))))
    # the twin's tracker is 0.3 s late: the base model's compensation trails by 0.3 s * tip speed
    assert errs[1] < 0.5 * errs[0]


@pytest.mark.parametrize("case, message", [
    ("single", "at least 2 runs"),
    ("no_y", "no measured tip angle y1"),
    ("mixed", "different catheters"),
    ("knobs", "no knob 2"),
    ("holdout", "no run has metadata motion"),
])
def test_bad_input_fails_cleanly(files, tmp_path, case, message):
    d, paths = files
    model = d / "model.json"
    args = {"single": [paths[0]], "no_y": [paths[0], d / "no_y.csv"], "mixed": [paths[0], d / "other.csv"],
            "knobs": [paths[0], d / "two_knobs.csv"], "holdout": [*paths, "--holdout", "motion=spiral"],
            }[case]
    if case == "knobs":
        one = tmp_path / "one.json"
        save_model(one, Model({1: CAT.knobs[1]}, CAT.geometry))
        model = one
    out = tmp_path / "report.json"
    res = invoke("diagnose", "--model", model, *args, "-o", out, "--model-out", tmp_path / "aug.json")
    assert res.exit_code == 1
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error: ") and message in lines[0]
    assert "Traceback" not in res.output
    assert not out.exists() and not (tmp_path / "aug.json").exists()


@pytest.mark.parametrize("case, message", [
    ("candidate", "unknown effect 'wobble'"),
    ("holdout", "expected key=value"),
    ("same_output", "--output and --model-out name the same file"),
    ("same_plot", "--output and --plot name the same file"),
    ("same_run", "are the same file"),
])
def test_usage_errors_found_after_parsing_exit_2(files, tmp_path, case, message):
    # issue 12: option values found wrong after parsing are usage errors (exit 2), with one
    # Error: line, and nothing is written (the report is not lost under the model, nor the reverse)
    d, paths = files
    out, aug = tmp_path / "report.json", tmp_path / "aug.json"
    args = {"candidate": [*paths, "--candidates", "wobble", "-o", out],
            "holdout": [*paths, "--holdout", "foo", "-o", out],
            "same_output": [*paths, "-o", out, "--model-out", out],
            "same_plot": [*paths, "-o", out, "--plot", out],
            "same_run": [paths[0], paths[0], "-o", out]}[case]
    res = invoke("diagnose", "--model", d / "model.json", *args)
    assert res.exit_code == 2, res.output
    errors = [ln for ln in res.output.splitlines() if ln.startswith("Error")]
    assert len(errors) == 1 and message in errors[0], res.output
    assert "Traceback" not in res.output
    assert not out.exists() and not aug.exists()


def test_usage_errors_and_inputs_are_protected(files):
    d, paths = files
    assert invoke("diagnose", "--model", d / "model.json", *paths, "--format", "csv").exit_code == 2
    res = invoke("diagnose", "--model", d / "model.json", *paths, "-o", paths[0])
    assert res.exit_code == 1 and "Error:" in res.stderr
    assert read_run(paths[0])["y1"].size == T.size  # the input is intact
    assert invoke("diagnose", "--help").exit_code == 0
