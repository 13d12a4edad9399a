"""`hyst show` and `hyst diff` (issue 12): a model's numbers to read, two models to compare."""
from __future__ import annotations

import json
import math

import pytest
from typer.testing import CliRunner

from hystcli.cli import app
from hystcli.estimate import Estimate
from hystcli.io import save_model
from hystcli.core.model import Model
from hystcli.core.params import Calibration, EffectSpec, Geometry, KnobIdentification, KnobModel

runner = CliRunner()
EXAMPLE = dict(d_pos=9.1, d_neg=-8.7, b_pos=6.2, b_neg=5.9, omega=1.45, h_pos=-4.0, h_neg=4.2)
# by hand (docs/design.md section 3): dhat_pos = (h_pos - h_neg)/omega + d_neg + b_neg
#   = -8.2/1.45 - 8.7 + 5.9 = -8.455172..., dhat_neg = (h_neg - h_pos)/omega + d_pos - b_pos
#   = 8.2/1.45 + 9.1 - 6.2 = 8.555172...
DHAT_POS, DHAT_NEG = -8.2 / 1.45 - 2.8, 8.2 / 1.45 + 2.9


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


@pytest.fixture
def models(tmp_path):
    # d_pos fixed to [9.06, 9.14], b_pos bounded below only (the record said nothing above 5)
    estimates = {"d_pos": Estimate(9.1, 9.06, 9.14), "omega": Estimate(1.45, 1.442, 1.458),
                 "b_pos": Estimate(6.2, 5.0, math.inf, fixed=False, reason="the record ends on the plateau")}
    ident = KnobIdentification(-40.0, 40.0, method="tip", rmse=0.31, estimates=estimates,
                               calibration=Calibration(current_sign="signed", slope_dead_zone=0.05,
                                                       slope_loaded_pos=4.8, slope_loaded_neg=5.2,
                                                       no_load_rising=126.0, no_load_falling=114.0))
    straight = Model({1: KnobModel(**EXAMPLE), 2: KnobModel(**EXAMPLE)}, Geometry(1.2, 8.0),
                     meta={"catheter": "ice-a", "source": "sweep.csv"}, identification={1: ident})
    shifted = straight.with_offsets({1: 13.5})
    save_model(tmp_path / "model.json", straight)
    save_model(tmp_path / "shifted.json", shifted)
    save_model(tmp_path / "augmented.json", Model(shifted.knobs, Geometry(1.2, 8.0),
                                                  (EffectSpec("creep", {"fraction": 0.27, "tau": 2.4}),)))
    return tmp_path


def test_show_lists_parameters_with_intervals_and_derived_edges(models):
    res = invoke("show", models / "shifted.json")
    assert res.exit_code == 0, res.output
    rows = {tuple(ln.split()[:2]): ln.split()[2:] for ln in res.stdout.splitlines() if ln.strip()[:1] in "12"}
    assert rows[("1", "d_pos")][:3] == ["9.100", "9.060", "9.140"]  # value and its interval
    assert rows[("1", "b_pos")][:3] == ["6.200", "5.000", "inf"]    # open above
    assert "not fixed: the record ends on the plateau" in " ".join(rows[("1", "b_pos")])
    assert rows[("1", "b_neg")][:3] == ["5.900", "-", "-"]          # no interval known
    assert rows[("1", "offset")][0] == "13.500"
    assert float(rows[("1", "dhat_pos")][0]) == pytest.approx(DHAT_POS, abs=1e-3)
    assert float(rows[("1", "shifted_d_neg")][0]) == pytest.approx(-8.7 + 13.5, abs=1e-3)
    # identification: what detect-shift will use: the smaller loaded slope (4.8 of 4.8 and 5.2) and
    # the no-load level midway between the two directions' (126 and 114 mA)
    ident = next(ln for ln in res.stdout.splitlines() if ln.split()[:4] == ["1", "tip", "-40.000", "40.000"])
    assert ident.split()[-4:] == ["signed", "0.050", "4.800", "120.000"]
    assert "catheter ice-a" in res.stdout and "beta_catheter 1.2 mm" in res.stdout


def test_show_json_csv_and_effects(models):
    data = json.loads(invoke("show", models / "augmented.json", "-f", "json").stdout)
    assert data["knobs"]["1"]["derived"]["dhat_neg"] == pytest.approx(DHAT_NEG)
    assert data["knobs"]["1"]["params"]["offset"] == 13.5
    assert data["effects"] == [{"name": "creep", "params": {"fraction": 0.27, "tau": 2.4}}]
    csv = invoke("show", models / "augmented.json", "-f", "csv").stdout.splitlines()
    assert csv[0] == "knob,parameter,value,lo,hi,note" and len(csv) == 1 + 2 * 12
    text = invoke("show", models / "augmented.json").stdout
    assert "creep   fraction" in text and "0.270" in text


def test_show_plot_draws_the_envelopes(models, tmp_path):
    res = invoke("show", models / "shifted.json", "--plot", tmp_path / "env.svg", "-q")
    assert res.exit_code == 0, res.output
    svg = (tmp_path / "env.svg").read_text()
    for label in ("f_up (loading)", "f_dn (unloading)", "knob angle q1 (deg)", "tip angle y2 (deg)"):
        assert f"<!-- {label} -->" in svg
    res = invoke("show", models / "shifted.json", "--plot", tmp_path / "env.txt")
    assert res.exit_code == 2 and not (tmp_path / "env.txt").exists()


def test_diff_straight_against_shifted_lists_what_moved(models):
    res = invoke("diff", models / "model.json", models / "shifted.json", "-f", "csv")
    assert res.exit_code == 0, res.output
    rows = [ln.split(",") for ln in res.stdout.splitlines()[1:]]
    # the shift moves the offset and the shifted edges of knob 1, nothing else
    assert [r[:2] for r in rows] == [["knob 1", "offset"], ["knob 1", "shifted_d_pos"], ["knob 1", "shifted_d_neg"]]
    assert [float(r[4]) for r in rows] == pytest.approx([13.5] * 3)
    full = invoke("diff", models / "model.json", models / "shifted.json", "--all", "-f", "json")
    table = json.loads(full.stdout)
    assert len(table["rows"]) == 2 * 12 + 2  # two knobs' parameters and edges, the geometry
    d_pos = next(r for r in table["rows"] if r["item"] == "knob 2" and r["parameter"] == "d_pos")
    assert d_pos == {"item": "knob 2", "parameter": "d_pos", "a": 9.1, "b": 9.1, "b_minus_a": 0.0}


def test_diff_shows_effects_one_model_lacks_and_says_when_nothing_differs(models):
    res = invoke("diff", models / "shifted.json", models / "augmented.json", "-f", "markdown")
    assert "| effect creep | tau | - | 2.400 | - |" in res.stdout
    res = invoke("diff", models / "model.json", models / "model.json")
    assert res.exit_code == 0 and "hold the same parameters" in res.stdout


def test_missing_or_bad_model_is_one_error_line(models):
    res = invoke("diff", models / "model.json", models / "nope.json")
    assert res.exit_code == 1 and res.stderr.strip().startswith("Error: ") and "nope.json" in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1
    (models / "bad.json").write_text('{"format": "hyst-model", "version": 1, "knobs": {"1": {"d_pos": 1e308}}}')
    res = invoke("show", models / "bad.json")
    assert res.exit_code == 1 and "bad.json" in res.stderr and "Traceback" not in res.output
