"""The bench's reference fits (bench/reference.py): independence from the method, recovery of a
noiseless plant, and intervals left open where the record cannot fix a parameter."""
from __future__ import annotations

import ast
import math
from pathlib import Path

import numpy as np
import pytest

import reference as R
from plants.zoo import plants

BENCH = Path(__file__).resolve().parents[1] / "bench"
FORBIDDEN = ("hystcli.identification", "hystcli.shift", "hystcli.current", "hystcli.signal")


def _imports(path: Path) -> set[str]:
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            mod = node.module or ""
            out.add(mod)
            out |= {f"{mod}.{a.name}" for a in node.names}
    return out


@pytest.mark.parametrize("name", ["reference.py", "score.py"])
def test_reference_and_score_import_nothing_of_the_method(name):
    found = _imports(BENCH / name)
    bad = {m for m in found if any(m == f or m.startswith(f + ".") for f in FORBIDDEN)}
    assert not bad, f"{name} imports {bad}"
    if name == "score.py":
        assert not {m for m in found if m.startswith("hystcli")}


def _sweep(qs, n_per_deg=20):
    """Knob waypoints joined by straight moves at 10 deg/s."""
    parts = [np.array([qs[0]], float)]
    for a, b in zip(qs[:-1], qs[1:]):
        m = max(2, int(abs(b - a) * n_per_deg))
        parts.append(np.linspace(a, b, m + 1)[1:])
    q = np.concatenate(parts)
    t = np.arange(q.size) / (10.0 * n_per_deg)
    return t, q


@pytest.mark.slow
def test_noiseless_tip_load_plant_recovered():
    case = plants.sweep_case(1, "tip-load", noiseless=True)
    col, tr = case.record.columns, case.truth
    tip = R.tip_reference(col["t"], col["q1"], col["y1"])
    for p in R.TIP_PARAMS:
        assert abs(tip[p].estimate - getattr(tr, p)) < 0.02, (p, tip[p], getattr(tr, p))
        assert tip[p].resolved(0.5 if p != "omega" else 0.05)
    cur = R.current_reference(col["t"], col["q1"], col["c1"])
    for p in R.CURRENT_PARAMS:
        assert abs(cur[p].estimate - getattr(tr, p)) < 0.2, (p, cur[p], getattr(tr, p))
        assert cur[p].resolved(1.0)


def test_tip_backlash_open_when_the_sweep_never_leaves_its_plateau():
    tr = plants.KnobTruth(d_pos=5.0, d_neg=-5.0, b_pos=4.0, b_neg=3.0, omega=1.0, h_pos=-2.0, h_neg=2.0)
    # from rest on the dead-zone plateau, down past d_neg, up past d_pos to 20, back only 2 deg
    # (the tip stays on its backlash plateau), up again: b_pos >= 2 is all the record shows
    t, q = _sweep([4.0, -20.0, 20.0, 18.0, 20.0])
    y = tr.forward(q, 2.0) + 0.05 * np.random.default_rng(0).standard_normal(q.size)
    fit = R.tip_reference(t, q, y)
    b = fit["b_pos"]
    assert not b.resolved(0.5) and b.contains(4.0) and b.lo < 2.5
    assert b.hi == math.inf or b.hi_open
    # the ascent shows the h_pos plateau and the loaded line past d_pos
    for p in ("d_pos", "h_pos", "omega"):
        assert fit[p].contains(getattr(tr, p)) and fit[p].resolved(0.5), (p, fit[p])


def _stretch_current(q, d_pos, d_neg, seed=0, noise=0.5):
    rng = np.random.default_rng(seed)
    return 20.0 + 6.0 * np.maximum(q - d_pos, 0.0) - 4.0 * np.maximum(d_neg - q, 0.0) \
        + noise * rng.standard_normal(q.size)


@pytest.mark.slow
def test_current_edge_open_when_never_reached():
    t, q = _sweep([0.0, -3.0, 20.0, -3.0, 20.0])
    c = _stretch_current(q, 4.0, -5.0)
    fit = R.current_reference(t, q, c)
    assert abs(fit["d_pos"].estimate - 4.0) < 0.2 and fit["d_pos"].resolved(1.0)
    assert not fit["d_neg"].resolved(1.0)
    # a current that only stretches carries no backlash
    assert not fit["b_pos"].resolved(1.0) and not fit["b_neg"].resolved(1.0)


@pytest.mark.slow
def test_shift_found_and_open_without_an_edge_crossed_from_slack():
    t, q = _sweep([0.0, -20.0, 20.0, -20.0, 20.0, 0.0])
    sweep = R.current_reference(t, q, _stretch_current(q, 4.0, -5.0))
    assert abs(sweep["d_pos"].estimate - 4.0) < 0.1 and abs(sweep["d_neg"].estimate + 5.0) < 0.1
    tr, qr = _sweep([0.0, 25.0, -15.0, 0.0])
    off, lo, hi = R.shift_reference(sweep, tr, qr, _stretch_current(qr, 4.0 + 6.0, -5.0 + 6.0, seed=1))
    assert abs(off - 6.0) < 0.3 and lo <= 6.0 <= hi and hi - lo < 1.0
    # a replay that stays inside the shifted dead zone never takes a tendon up
    tr, qr = _sweep([0.0, 3.0, 0.0, 2.0])
    off, lo, hi = R.shift_reference(sweep, tr, qr, _stretch_current(qr, 4.5, -4.5, seed=2))
    assert lo == -math.inf and hi == math.inf


def test_bad_records_refused():
    with pytest.raises(R.RefFitError):
        R.tip_reference(np.arange(10.0), np.arange(10.0), np.zeros(10))
    with pytest.raises(R.RefFitError):
        R.current_reference(np.arange(100.0), np.zeros(100), np.zeros(100))


@pytest.mark.slow
def test_magnitude_current_folded_about_no_load():
    t, q = _sweep([0.0, -20.0, 20.0, -20.0, 20.0])
    rng = np.random.default_rng(3)
    signed = 6.0 * np.maximum(q - 4.0, 0.0) - 4.0 * np.maximum(-5.0 - q, 0.0)
    c = 20.0 + np.abs(signed) + 0.5 * rng.standard_normal(q.size)
    fit = R.current_reference(t, q, c)
    assert "magnitude" in fit.terms
    assert abs(fit["d_pos"].estimate - 4.0) < 0.2 and abs(fit["d_neg"].estimate + 5.0) < 0.2
