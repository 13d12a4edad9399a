"""Tests of hystcli.report.metrics: PTPE, RMSE, pooling, improvement rates and the formatters.

Every expected number is worked out by hand in the comments (or taken from the paper's Table I),
never produced by the code under test.
"""
from __future__ import annotations

import csv
import io
import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hystcli.errors import DataError
from hystcli.core.run import Run
from hystcli.report.metrics import (Evaluation, evaluate_runs, evaluation_figure, format_json, format_latex, group_table,
                             improvement, mean_std, parse_group_by, ptpe, render, rmse, run_table)
from hystcli.report.table import format_csv, format_markdown, format_text

T = [0.0, 1.0, 2.0, 3.0]
R = [0.0, 10.0, 20.0, 10.0]


def make_run(error, controller="none", shape="straight", motion="periodic", trial="1",
             catheter="ice-a", source=None, knob=1, **extra_meta):
    """A 4-sample 1-DoF run whose tracking error y - r is ``error``."""
    meta = {"catheter": catheter, "controller": controller, "shape": shape, "motion": motion,
            "trial": trial, **extra_meta}
    meta = {k: v for k, v in meta.items() if v is not None}
    r = np.array(R)
    cols = {"t": T, f"r{knob}": r, f"y{knob}": r + np.array(error, dtype=float)}
    return Run(cols, meta, source or f"{controller}-{shape}-{trial}.csv")


# The hand-worked experiment (one shape, one motion, two trials per controller):
#   none       trial 1: e = [3, 4, 0, 0]      PTPE 4 - 0 = 4   RMSE sqrt((9+16)/4) = 2.5
#              trial 2: e = [0, 8, 0, 0]      PTPE 8           RMSE sqrt(64/4)     = 4
#              -> PTPE mean 6, sample std sqrt((2^2 + 2^2)/1) = sqrt(8) = 2.8284271
#                 RMSE mean 3.25, sample std sqrt((0.75^2 + 0.75^2)/1) = 1.0606602
#   comp       trial 1: e = [1, -1, 1, -1]    PTPE 2           RMSE 1
#              trial 2: e = [2, 0, 0, 0]      PTPE 2           RMSE sqrt(4/4) = 1
#              -> PTPE (2, 0), RMSE (1, 0)
#              vs none: PTPE (6 - 2)/6*100 = 66.666667 %, RMSE (3.25 - 1)/3.25*100 = 69.230769 %
#   comp+shift trial 1: e = [1, 0, 0, 0]      PTPE 1           RMSE sqrt(1/4) = 0.5
#              trial 2: e = [2, 0, 0, 0]      PTPE 2           RMSE 1
#              -> PTPE mean 1.5, std sqrt(0.25 + 0.25) = 0.70710678
#                 RMSE mean 0.75, std sqrt(0.0625 + 0.0625) = 0.35355339
#              vs none: PTPE (6 - 1.5)/6*100 = 75 %,  RMSE (3.25 - 0.75)/3.25*100 = 76.923077 %
#              vs comp: PTPE (2 - 1.5)/2*100 = 25 %,  RMSE (1 - 0.75)/1*100 = 25 %
ERRORS = {
    ("none", "1"): [3, 4, 0, 0], ("none", "2"): [0, 8, 0, 0],
    ("comp", "1"): [1, -1, 1, -1], ("comp", "2"): [2, 0, 0, 0],
    ("comp+shift", "1"): [1, 0, 0, 0], ("comp+shift", "2"): [2, 0, 0, 0],
}


def experiment_runs():
    # listed in a scrambled order: the groups must come out in the paper's order anyway
    order = [("comp+shift", "2"), ("none", "1"), ("comp", "2"), ("comp+shift", "1"), ("comp", "1"),
             ("none", "2")]
    return [make_run(ERRORS[k], controller=k[0], trial=k[1]) for k in order]


@pytest.fixture(scope="module")
def ev() -> Evaluation:
    return evaluate_runs(experiment_runs())


# --------------------------------------------------------------------------------------------
# the metrics
# --------------------------------------------------------------------------------------------
def test_ptpe_and_rmse_by_hand():
    # e = [3, 4, 0, 0]: max 4 - min 0 = 4; sqrt((9 + 16 + 0 + 0)/4) = sqrt(6.25) = 2.5
    assert ptpe([3, 4, 0, 0]) == 4.0
    assert rmse([3, 4, 0, 0]) == 2.5
    # e = [-2, 1, 5]: 5 - (-2) = 7; sqrt((4 + 1 + 25)/3) = sqrt(10)
    assert ptpe([-2, 1, 5]) == 7.0
    assert rmse([-2, 1, 5]) == pytest.approx(math.sqrt(10), rel=1e-15)
    # a constant offset has no peak-to-peak error but all of its RMSE
    assert ptpe([3, 3, 3]) == 0.0
    assert rmse([-3, -3, -3]) == 3.0


def test_metrics_refuse_empty_and_nan():
    with pytest.raises(DataError):
        ptpe([])
    with pytest.raises(DataError):
        rmse([1.0, float("nan")])


def test_improvement_definition():
    # (base - new) / base * 100
    assert improvement(10.0, 4.0) == 60.0
    assert improvement(8.0, 8.0) == 0.0
    assert improvement(4.0, 6.0) == -50.0  # a worse controller has a negative rate
    assert improvement(5.0, 0.0) == 100.0
    with pytest.raises(ValueError):
        improvement(0.0, 1.0)


@pytest.mark.parametrize("base,new,paper", [
    # the paper's Table I "Improvement rate" row, from the table's own means
    (61.9, 24.3, 60.74), (30.12, 24.3, 19.3),   # PTPE at 45 deg vs none and vs comp
    (25.4, 7.9, 68.9), (24.2, 7.9, 67.3),       # RMSE at 45 deg
    (75.0, 26.0, 65.3), (45.0, 26.0, 42.2),     # PTPE at 90 deg
    (38.2, 8.0, 79.0), (31.3, 8.0, 74.4),       # RMSE at 90 deg
])
def test_improvement_reproduces_paper_table_1(base, new, paper):
    # the paper prints one or two decimals (and truncates 67.36 to 67.3)
    assert improvement(base, new) == pytest.approx(paper, abs=0.1)


def test_mean_std_is_sample_std():
    # [4, 8]: mean 6, sample std sqrt(((4-6)^2 + (8-6)^2) / (2-1)) = sqrt(8)
    m, s = mean_std([4.0, 8.0])
    assert m == 6.0 and s == pytest.approx(math.sqrt(8), rel=1e-12)
    # [1, 2, 3, 4]: mean 2.5, squares of deviations 2.25+0.25+0.25+2.25 = 5, /3 -> sqrt(5/3)
    assert mean_std([1, 2, 3, 4])[1] == pytest.approx(math.sqrt(5 / 3), rel=1e-12)
    assert mean_std([7.0]) == (7.0, None)  # one trial: no repeatability to report


finite = st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False)


@settings(max_examples=60, deadline=None)
@given(st.lists(finite, min_size=1, max_size=40), finite)
def test_metric_properties(e, c):
    e = np.array(e)
    # PTPE ignores a constant offset; RMSE lies between |mean| and max|e|; order does not matter
    assert ptpe(e + c) == pytest.approx(ptpe(e), abs=1e-9)
    assert abs(e.mean()) - 1e-9 <= rmse(e) <= np.abs(e).max() + 1e-9
    assert rmse(e[::-1]) == pytest.approx(rmse(e), rel=1e-12)
    assert ptpe(e) >= 0


# --------------------------------------------------------------------------------------------
# evaluate_runs
# --------------------------------------------------------------------------------------------
def test_per_run_results(ev):
    by = {(r.controller, r.trial): r for r in ev.results}
    assert len(ev.results) == 6
    assert (by["none", "1"].ptpe, by["none", "1"].rmse, by["none", "1"].n) == (4.0, 2.5, 4)
    assert (by["none", "2"].ptpe, by["none", "2"].rmse) == (8.0, 4.0)
    assert (by["comp+shift", "1"].ptpe, by["comp+shift", "1"].rmse) == (1.0, 0.5)
    assert by["comp", "1"].shape == "straight" and by["comp", "1"].motion == "periodic"
    assert by["comp", "1"].knob == 1 and by["comp", "1"].catheter == "ice-a"


def test_groups_pool_trials_by_hand(ev):
    assert [g.value("controller") for g in ev.groups] == ["none", "comp", "comp+shift"]
    none = ev.group(controller="none")
    assert none.n == 2
    assert none.ptpe_mean == pytest.approx(6.0) and none.ptpe_std == pytest.approx(2.8284271, abs=1e-7)
    assert none.rmse_mean == pytest.approx(3.25) and none.rmse_std == pytest.approx(1.0606602, abs=1e-7)
    assert none.improvements == ()
    cs = ev.group(controller="comp+shift")
    assert cs.ptpe_mean == pytest.approx(1.5) and cs.ptpe_std == pytest.approx(0.70710678, abs=1e-8)
    assert cs.rmse_mean == pytest.approx(0.75) and cs.rmse_std == pytest.approx(0.35355339, abs=1e-8)


def test_improvement_rates_by_hand(ev):
    comp = ev.group(controller="comp")
    assert comp.improvement("none").ptpe == pytest.approx(66.666667, abs=1e-6)
    assert comp.improvement("none").rmse == pytest.approx(69.230769, abs=1e-6)
    assert comp.improvement("comp") is None  # a baseline is not rated against itself
    cs = ev.group(controller="comp+shift")
    assert cs.improvement("none").ptpe == pytest.approx(75.0)
    assert cs.improvement("none").rmse == pytest.approx(76.923077, abs=1e-6)
    assert cs.improvement("comp").ptpe == pytest.approx(25.0)
    assert cs.improvement("comp").rmse == pytest.approx(25.0)


def test_improvement_only_within_the_same_shape():
    # 45 deg has comp only (no `none` there): no rate, even though `none` exists at straight
    runs = [make_run([0, 8, 0, 0], controller="none"),           # straight none: PTPE 8
            make_run([2, 0, 0, 0], controller="comp"),           # straight comp: PTPE 2 -> 75 %
            make_run([4, 0, 0, 0], controller="comp", shape="alpha=45,theta=0")]
    ev = evaluate_runs(runs)
    assert ev.group(controller="comp", shape="straight").improvement("none").ptpe == pytest.approx(75.0)
    assert ev.group(controller="comp", shape="alpha=45,theta=0").improvements == ()


def test_two_knobs_and_catheters_pool_and_split():
    # one 2-DoF run: knob 1 e = [3, 4, 0, 0] (PTPE 4, RMSE 2.5), knob 2 e = [0, 0, 0, 2]
    # (PTPE 2, RMSE sqrt(4/4) = 1); a second catheter's 1-DoF run e = [0, 8, 0, 0] (PTPE 8)
    r = np.array(R)
    two = Run({"t": T, "r1": r, "y1": r + [3, 4, 0, 0], "r2": r, "y2": r + [0, 0, 0, 2]},
              {"controller": "none", "shape": "straight", "motion": "nonperiodic", "trial": "1",
               "catheter": "ice-a"}, "two.csv")
    other = make_run([0, 8, 0, 0], motion="nonperiodic", catheter="ice-b")
    ev = evaluate_runs([two, other])
    assert sorted((x.knob, x.ptpe, x.rmse) for x in ev.results if x.source == "two.csv") == [(1, 4.0, 2.5), (2, 2.0, 1.0)]
    pooled = ev.group(controller="none")
    # PTPE [4, 2, 8]: mean 14/3, deviations -2/3, -8/3, 10/3 -> (4 + 64 + 100)/9 / 2 = 168/18
    assert pooled.n == 3
    assert pooled.ptpe_mean == pytest.approx(14 / 3)
    assert pooled.ptpe_std == pytest.approx(math.sqrt(168 / 18))
    split = evaluate_runs([two, other], group_by=["controller", "catheter"])
    assert split.group(catheter="ice-a").n == 2 and split.group(catheter="ice-b").n == 1
    assert split.group(catheter="ice-a").ptpe_mean == pytest.approx(3.0)   # (4 + 2)/2
    assert split.group(catheter="ice-b").ptpe_std is None                  # one result
    by_knob = evaluate_runs([two, other], group_by="knob")
    assert by_knob.group(knob="2").ptpe_mean == 2.0


def test_shapes_group_by_canonical_form():
    runs = [make_run([4, 0, 0, 0], controller="none", shape="alpha=45"),          # PTPE 4
            make_run([0, 0, 0, 2], controller="none", shape="alpha=45.0,theta=0")]  # PTPE 2
    ev = evaluate_runs(runs)
    assert len(ev.groups) == 1 and ev.groups[0].n == 2 and ev.groups[0].ptpe_mean == 3.0


def test_missing_metadata_is_unknown_with_a_warning():
    bare = Run({"t": T, "r1": R, "y1": np.array(R) + [3, 4, 0, 0]}, {}, "bare.csv")
    ev = evaluate_runs([bare, make_run([0, 8, 0, 0])])
    unknown = ev.group(controller="unknown")
    assert unknown.value("shape") == "unknown" and unknown.ptpe_mean == 4.0
    assert unknown.improvements == ()
    assert any("bare.csv" in w and "controller" in w for w in ev.warnings)
    assert [g.value("controller") for g in ev.groups] == ["none", "unknown"]  # unknown last


def test_group_order_follows_the_paper():
    runs = [make_run([1, 0, 0, 0], controller=c, shape=s)
            for s in ("alpha=90,theta=0", "straight", "alpha=45,theta=0") for c in ("comp+shift", "none", "comp")]
    ev = evaluate_runs(runs)
    assert [(g.value("controller"), g.value("shape")) for g in ev.groups][:4] == [
        ("none", "straight"), ("none", "alpha=45,theta=0"), ("none", "alpha=90,theta=0"),
        ("comp", "straight")]


def test_run_without_y_and_r_names_file_and_column():
    half = Run({"t": T, "y1": R}, {"controller": "none"}, "half.csv")
    with pytest.raises(DataError, match=r"half\.csv.*'r1'"):
        evaluate_runs([half])
    nothing = Run({"t": T, "q1": R}, {}, "q.csv")
    with pytest.raises(DataError, match=r"q\.csv.*'y1'"):
        evaluate_runs([nothing])
    with pytest.raises(DataError, match="no runs"):
        evaluate_runs([])


def test_knob_without_reference_is_skipped_with_a_warning():
    r = np.array(R)
    run = Run({"t": T, "r1": r, "y1": r + [3, 4, 0, 0], "y2": r}, {"controller": "none"}, "k.csv")
    ev = evaluate_runs([run])
    assert [x.knob for x in ev.results] == [1]
    assert any("knob 2" in w and "'r2'" in w for w in ev.warnings)


def test_bad_group_field():
    with pytest.raises(DataError, match="colour"):
        parse_group_by("controller,colour")
    assert parse_group_by(" Shape, controller,shape ") == ("shape", "controller")


# --------------------------------------------------------------------------------------------
# tables and formatters
# --------------------------------------------------------------------------------------------
def test_group_table_is_plain_data(ev):
    t = group_table(ev)
    assert t.columns[:9] == ("controller", "shape", "motion", "n", "ptpe_mean", "ptpe_std",
                             "rmse_mean", "rmse_std", "ptpe_improvement_vs_none")
    row = dict(zip(t.columns, t.rows[2]))
    assert row["controller"] == "comp+shift" and row["n"] == 2
    assert row["ptpe_improvement_vs_comp"] == pytest.approx(25.0)
    assert dict(zip(t.columns, t.rows[0]))["ptpe_improvement_vs_none"] is None
    assert len(run_table(ev).rows) == 6


def test_csv_format(ev):
    rows = list(csv.DictReader(io.StringIO(format_csv(group_table(ev)))))
    assert [r["controller"] for r in rows] == ["none", "comp", "comp+shift"]
    assert float(rows[0]["ptpe_mean"]) == pytest.approx(6.0)
    assert float(rows[0]["ptpe_std"]) == pytest.approx(2.8284271, abs=1e-7)
    assert float(rows[1]["rmse_improvement_vs_none"]) == pytest.approx(69.230769, abs=1e-6)
    assert float(rows[2]["rmse_improvement_vs_none"]) == pytest.approx(76.923077, abs=1e-6)
    assert rows[0]["ptpe_improvement_vs_none"] == ""  # not applicable: empty, not 0


def test_json_format(ev):
    data = json.loads(format_json(ev))
    assert data["group_by"] == ["controller", "shape", "motion"]
    g = {x["key"]["controller"]: x for x in data["groups"]}
    assert g["none"]["ptpe"] == {"mean": pytest.approx(6.0), "std": pytest.approx(2.8284271, abs=1e-7)}
    assert g["comp+shift"]["improvement"]["comp"]["ptpe"] == pytest.approx(25.0)
    assert g["comp+shift"]["improvement"]["none"]["rmse"] == pytest.approx(76.923077, abs=1e-6)
    assert len(data["runs"]) == 6 and "ddof=1" in data["definitions"]["std"]


def test_json_single_trial_std_is_null():
    data = json.loads(format_json(evaluate_runs([make_run([3, 4, 0, 0])])))
    assert data["groups"][0]["ptpe"] == {"mean": 4.0, "std": None}


def test_text_format(ev):
    lines = format_text(group_table(ev), width=200).splitlines()
    assert lines[0].split()[:4] == ["controller", "shape", "motion", "n"]
    comp = next(line.split() for line in lines if line.startswith("comp "))
    # comp: n 2, PTPE (2, 0), RMSE (1, 0), 66.67 / 69.23 % vs none, nothing vs comp
    assert comp == ["comp", "straight", "periodic", "2", "2.00", "0.00", "1.00", "0.00",
                    "66.67", "69.23", "-", "-"]
    assert any("ddof=1" in line for line in lines)


def test_a_wide_text_table_comes_in_slices_with_its_keys(ev):
    wide = format_text(group_table(ev), width=200).splitlines()
    assert max(map(len, wide)) > 100  # the evaluation table is wider than the default
    lines = format_text(group_table(ev)).splitlines()
    assert max(map(len, lines)) <= 100
    # each slice starts with the three grouping columns; together they hold every cell once
    comp = [line.split() for line in lines if line.startswith("comp ")]
    assert len(comp) >= 2 and all(part[:3] == ["comp", "straight", "periodic"] for part in comp)
    assert comp[0] + [cell for part in comp[1:] for cell in part[3:]] == \
        next(line.split() for line in wide if line.startswith("comp "))


def test_markdown_format(ev):
    md = format_markdown(group_table(ev))
    assert md.splitlines()[1].startswith("|---|---|---|---:|")
    assert "| comp+shift | straight | periodic | 2 | 1.50 | 0.71 | 0.75 | 0.35 | 75.00 | 76.92 | 25.00 | 25.00 |" in md


def test_latex_format_is_like_the_paper(ev):
    tex = format_latex(ev)
    assert tex.startswith(r"\begin{tabular}{|c||c|c|}") and tex.rstrip().endswith(r"\end{tabular}")
    assert r"Straight ($\alpha = 0^\circ$)" in tex and "Periodic inputs" in tex
    # (mean, std) with one decimal like the paper: none PTPE (6, 2.83), comp RMSE (1, 0)
    assert r"No Compensation (deg) & (6.0, 2.8) &" in tex
    assert r"Compensation-Only (deg) & (2.0, 0.0) & (1.0, 0.0) \\" in tex
    # improvement row: "vs none and vs comp", PTPE 75 and 25, RMSE 76.9 and 25
    assert r"Improvement rate ($\%$) & 75.0 and 25.0 & 76.9 and 25.0 \\" in tex


def test_latex_missing_cells_and_escaping():
    runs = [make_run([0, 8, 0, 0], controller="none"),
            make_run([2, 0, 0, 0], controller="comp+shift", shape="alpha=45,theta=0"),
            make_run([2, 0, 0, 0], controller="my_ctrl")]
    tex = format_latex(evaluate_runs(runs))
    assert r"\multicolumn{2}{|c||}{Straight ($\alpha = 0^\circ$)}" in tex
    assert r"Compensation+Shift (deg) & - & - & (2.0, -) & (1.0, -)" in tex  # n = 1: no std
    assert r"my\_ctrl (deg)" in tex


def test_render_dispatch(ev):
    assert render(ev, "csv") == format_csv(group_table(ev))
    assert render(ev, "csv", per_run=True).splitlines()[0].startswith("source,knob,")
    with pytest.raises(ValueError):
        render(ev, "xml")


def test_figure_is_a_png():
    runs = [make_run(ERRORS[k], controller=k[0], trial=k[1]) for k in ERRORS] + \
           [make_run([1, 0, 0, 0], controller="other", shape="alpha=90,theta=0")]
    png = evaluation_figure(runs)
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    # one panel pair per shape: two shapes (straight, 90 deg) -> 2 columns of 4.2 in at 100 dpi,
    # 7 in high (the PNG header holds width and height, big-endian, at bytes 16..24)
    assert int.from_bytes(png[16:20], "big") == 840 and int.from_bytes(png[20:24], "big") == 700
    assert evaluation_figure(runs) == png  # same runs, same bytes
    with pytest.raises(DataError):
        evaluation_figure(runs, "gif")


def test_figure_legend_names_every_controller_of_every_column():
    # Fig. 6's first column is the straight shaft, where Compensation+Shift and the diagnosed
    # controller do not run: the legend must still name them (issue 12)
    runs = [make_run([1, 0, 0, 0], controller=c, shape="straight") for c in ("none", "comp")]
    runs += [make_run([1, 0, 0, 0], controller=c, shape="alpha=90,theta=0")
             for c in ("none", "comp", "comp+shift", "comp+shift+diag")]
    svg = evaluation_figure(runs, "svg").decode()
    legend = svg[svg.index('<g id="legend_1">'):]
    for label in ("No Compensation", "Compensation-Only", "Compensation+Shift", "Compensation+Shift+Diagnosis",
                  "ground truth (r)"):
        assert f"<!-- {label} -->" in legend, label
    # and the axes carry their units
    for label in ("time (s)", "output angle y1 (deg)", "input angle r1 (deg)"):
        assert f"<!-- {label} -->" in svg
