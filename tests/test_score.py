"""bench/score.py: the outcome rules, coverage helpers and the pooled summary on hand-made inputs."""
from __future__ import annotations

import math

import pytest

import score as S

REF_SHARP = {"estimate": 1.0, "lo": 0.8, "hi": 1.2}       # resolved at 0.5
REF_WIDE = {"estimate": 1.0, "lo": -3.0, "hi": 5.0}       # not resolved at 0.5
REF_OPEN = {"estimate": 1.0, "lo": 0.0, "hi": math.inf}   # not resolved


def fixed(v, lo=None, hi=None, se=None):
    return {"value": v, "lo": lo, "hi": hi, "fixed": True, "se": se}


@pytest.mark.parametrize("truth, entry, ref, expected", [
    (1.0, fixed(1.3), REF_SHARP, "right"),
    (1.0, fixed(1.5), REF_SHARP, "right"),                  # at the tolerance
    (1.0, fixed(1.6), REF_SHARP, "wrong"),
    (1.0, fixed(1.6), REF_WIDE, "wrong"),                   # fixed and off: wrong whatever the reference
    (1.0, None, REF_WIDE, "refused-right"),
    (1.0, None, REF_OPEN, "refused-right"),
    (1.0, None, None, "refused-right"),
    (1.0, None, REF_SHARP, "refused-wrong"),
    (1.0, {"value": 2.0, "lo": None, "hi": None, "fixed": False}, REF_SHARP, "refused-wrong"),
    (1.0, {"value": 2.0, "lo": -math.inf, "hi": math.inf, "fixed": False}, REF_WIDE, "refused-right"),
    (1.0, {"value": 2.0, "lo": 0.5, "hi": 3.0, "fixed": False}, REF_SHARP, "interval-right"),
    (1.0, {"value": 2.0, "lo": 1.5, "hi": 3.0, "fixed": False}, REF_SHARP, "interval-wrong"),
    (1.0, {"value": 2.0, "lo": 0.5, "hi": None, "fixed": False}, REF_WIDE, "interval-right"),
])
def test_outcome_rules(truth, entry, ref, expected):
    assert S.outcome(truth, entry, ref, 0.5) == expected


def test_reference_resolution_and_coverage_helpers():
    assert S.ref_resolves(REF_SHARP, 0.5) and not S.ref_resolves(REF_WIDE, 0.5)
    assert not S.ref_resolves(REF_OPEN, 100.0) and not S.ref_resolves(None, 1.0)
    assert S.in_interval(1.0, None, 2.0) and not S.in_interval(3.0, None, 2.0)
    assert S.within_2se(1.0, 1.9, 0.5) and not S.within_2se(1.0, 2.1, 0.5)
    assert not S.within_2se(1.0, 1.0, None)


def test_score_case_refusal_and_silent_failure():
    truth = {"d_pos": 5.0, "d_neg": -5.0}
    ref = {"d_pos": REF_SHARP, "d_neg": REF_WIDE}
    rows = S.score_case(truth, {"refused": "no edge", "names": ["d_pos"]}, ref, 0.5, ("d_pos", "d_neg"))
    assert [r["outcome"] for r in rows] == ["refused-wrong", "refused-right"]
    rows = S.score_case(truth, {"d_pos": fixed(8.0), "d_neg": fixed(-5.1, -5.3, -4.9, se=0.1)}, ref, 0.5,
                        ("d_pos", "d_neg"), family="wall")
    assert rows[0]["outcome"] == "wrong" and rows[0]["silent"] and rows[0]["error"] == pytest.approx(3.0)
    assert rows[1]["outcome"] == "right" and not rows[1]["silent"]
    assert rows[1]["covered"] and rows[1]["covered_2se"]
    rows = S.score_case(truth, {"d_pos": fixed(8.0)}, ref, 0.5, ("d_pos",), exit_code=1)
    assert not rows[0]["silent"]


def test_summary_counts_and_rates():
    truth = {"d_pos": 1.0}
    ref = {"d_pos": {"estimate": 1.1, "lo": 0.9, "hi": 1.3}}
    rows = []
    rows += S.score_case(truth, {"d_pos": fixed(1.2)}, ref, 0.5, ("d_pos",), family="a")
    rows += S.score_case(truth, {"d_pos": fixed(4.0)}, ref, 0.5, ("d_pos",), family="a")
    rows += S.score_case(truth, {"refused": "x"}, ref, 0.5, ("d_pos",), family="b")
    rows += S.score_case(truth, {"refused": "x"}, {"d_pos": REF_WIDE}, 0.5, ("d_pos",), family="b")
    summ = S.summarize(rows)
    assert summ["total"]["right"] == 1 and summ["total"]["wrong"] == 1
    assert summ["total"]["refused-wrong"] == 1 and summ["total"]["refused-right"] == 1
    assert summ["per_family"]["a"]["right"] == 1 and summ["per_family"]["b"]["refused-right"] == 1
    assert summ["resolved"] == 3
    assert summ["right_of_resolved"] == pytest.approx(1 / 3)
    assert summ["rms_method"] == pytest.approx(math.sqrt((0.2 ** 2 + 3.0 ** 2) / 2))
    assert summ["rms_reference"] == pytest.approx(0.1)
    assert summ["silent"] == 1
    text = S.format_summary(summ)
    assert "refused-wrong" in text and "right of what the reference resolves: 0.333" in text
