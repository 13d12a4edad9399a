"""Regression records: every plant record that once went wrong, with what its truth says should
happen, kept as rows of tests/data/regressions.csv and run by the one test below.

To add a record, append a row to tests/data/regressions.csv:

* ``plants``: ``zoo`` (plants.zoo.plants) or ``wild`` (bench/plants/wild.py);
* ``seed``: the case's seed (``sweep_case(seed)`` for identify, ``replay_case(seed)`` for shift);
* ``family``: the family that seed draws (checked first: a plant module that changed its draws
  is named, not mistaken for a regression);
* ``command``: ``identify-tip`` or ``identify-current`` (identify with the tip angle, or from the
  motor current alone), ``shift-tip`` or ``shift-current`` (the straight sweep identified so,
  then detect-shift on the replay with that model, as a user runs them);
* ``parameter``: ``d_pos``, ``d_neg``, ``b_pos`` or ``b_neg`` for identify, ``offset`` for shift;
* ``expect``: what the truth says should happen:
  ``right`` (returned as fixed, within ``tol`` deg of the truth),
  ``covers`` (returned as fixed, its interval holds the truth),
  ``not-fixed`` (returned, marked not fixed: only where the record cannot show the parameter,
  e.g. a backlash in a current that follows the tendon's stretch),
  ``refused`` (exit 1: only where nothing in the record could give it);
* ``tol``: deg, for ``right``;
* ``why``: one line saying what the truth says, not which code once failed it.

Run the command on the code first (``python -m pytest tests/test_regressions.py -m ''``): a row
goes in only when it states the truth; a record the code gets wrong is an estimator bug to fix,
not a row to weaken. Rows whose command fits the tip run only with the slow tests.
"""
from __future__ import annotations

import csv
import functools
import importlib
import math
from pathlib import Path

import pytest

from hystcli.errors import HystError
from hystcli.identification import identify
from hystcli.core.run import Run
from hystcli.io import parse_run
from hystcli.shift import ReplayProbe, detect_shift

ROWS_FILE = Path(__file__).resolve().parent / "data" / "regressions.csv"
COMMANDS = ("identify-tip", "identify-current", "shift-tip", "shift-current")
EXPECTATIONS = ("right", "covers", "not-fixed", "refused")


def _rows() -> list:
    with ROWS_FILE.open(newline="") as f:
        rows = list(csv.DictReader(f))
    out = []
    for r in rows:
        assert r["plants"] in ("zoo", "wild") and r["command"] in COMMANDS and r["expect"] in EXPECTATIONS, r
        slow = r["command"].endswith("-tip")   # a tip fit takes seconds; the current alone a fraction
        rid = f"{r['plants']}-{r['seed']}-{r['command']}-{r['parameter']}"
        out.append(pytest.param(r, id=rid, marks=(pytest.mark.slow,) if slow else ()))
    return out


def _plants(name: str):  # noqa: ANN202 - a plant module
    return importlib.import_module("plants.zoo.plants" if name == "zoo" else "plants.wild")


def _run(record, source: str, tip: bool) -> Run:
    """A plant's record as a user's file reads, without its tip column when ``tip`` is False."""
    run = parse_run(record.csv_text(), source=source)
    if tip:
        return run
    return Run({k: v for k, v in run.columns.items() if not k.startswith("y")}, run.meta, run.source)


@functools.lru_cache(maxsize=None)
def _outcome(plants: str, seed: int, command: str):  # noqa: ANN202 - (family, truth, result or refusal)
    """What the command returns on the record: ``(family, truth, estimates or None, refusal)``,
    the estimates a mapping of parameter to ``(value, lo, hi, fixed)``."""
    mod = _plants(plants)
    use_tip = command.endswith("-tip")
    if command.startswith("identify"):
        case = mod.sweep_case(seed)
        truth = {n: getattr(case.truth, n) for n in ("d_pos", "d_neg", "b_pos", "b_neg")}
        try:
            fit = identify(_run(case.record, f"{plants}-{seed}", use_tip), use_tip=use_tip).fits[1]
        except HystError as exc:
            return case.family, truth, None, str(exc)
        return case.family, truth, {n: (e.value, e.lo, e.hi, e.fixed) for n, e in fit.estimates.items()}, None
    case = mod.replay_case(seed)
    truth = {"offset": case.offset}
    try:
        model = identify(_run(case.straight_sweep, f"{plants}-{seed}-sweep", use_tip), use_tip=use_tip).model
        r = detect_shift(model, ReplayProbe(_run(case.replay, f"{plants}-{seed}-replay", True), 1), 1)
    except HystError as exc:
        return case.family, truth, None, str(exc)
    return case.family, truth, {"offset": (r.offset, r.offset_lo, r.offset_hi, True)}, None


@pytest.mark.parametrize("row", _rows())
def test_regression_record(row):
    family, truth, got, refusal = _outcome(row["plants"], int(row["seed"]), row["command"])
    assert family == row["family"], f"the plant module now draws {family} for this seed"
    name, expect = row["parameter"], row["expect"]
    true = truth[name]
    if expect == "refused":
        assert got is None, f"{name} returned {got[name]} where the record cannot give it ({row['why']})"
        return
    assert got is not None, f"refused ({refusal}); the truth says: {row['why']}"
    value, lo, hi, fixed = got[name]
    if expect == "not-fixed":
        assert not fixed, f"{name} = {value:.2f} [{lo:.2f}, {hi:.2f}] claimed fixed; true {true:.2f}: {row['why']}"
    elif expect == "right":
        assert fixed and abs(value - true) <= float(row["tol"]), (
            f"{name} = {value:.2f} [{lo:.2f}, {hi:.2f}] ({'fixed' if fixed else 'not fixed'}); true {true:.2f}, "
            f"tolerance {row['tol']}: {row['why']}")
    else:
        assert fixed and lo <= true <= hi and math.isfinite(lo) and math.isfinite(hi), (
            f"{name} = {value:.2f} [{lo:.2f}, {hi:.2f}] ({'fixed' if fixed else 'not fixed'}); true {true:.2f}: "
            f"{row['why']}")
