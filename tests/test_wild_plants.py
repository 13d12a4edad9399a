"""Tests of the wild test plants (bench/plants/wild.py) against the physics they claim.

The tip's clamp recursion is recomputed here in plain Python from the truth's parameters, so the
plants' compiled kernel is checked against an independent implementation.
"""

from __future__ import annotations

import ast
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from plants import wild

PLANTS_DIR = Path(__file__).resolve().parents[1] / "bench" / "plants"
SEEDS_PER_FAMILY = 5
NON_WALL = tuple(f for f in wild.FAMILIES if f != "wall")


def envelopes(p: dict):
    """f_up and f_dn of the loop with parameters `p` (KnobTruth.as_dict), in u = q - offset."""
    dhat_pos = (p["h_pos"] - p["h_neg"]) / p["omega"] + p["d_neg"] + p["b_neg"]
    dhat_neg = (p["h_neg"] - p["h_pos"]) / p["omega"] + p["d_pos"] - p["b_pos"]

    def f_up(u):
        if u < dhat_pos:
            return p["omega"] * (u - dhat_pos) + p["h_pos"]
        if u > p["d_pos"]:
            return p["omega"] * (u - p["d_pos"]) + p["h_pos"]
        return p["h_pos"]

    def f_dn(u):
        if u < p["d_neg"]:
            return p["omega"] * (u - p["d_neg"]) + p["h_neg"]
        if u > dhat_neg:
            return p["omega"] * (u - dhat_neg) + p["h_neg"]
        return p["h_neg"]

    return f_up, f_dn, dhat_pos, dhat_neg


def clamp_tip(q, y0: float, p: dict, offset: float, factors: dict | None = None) -> np.ndarray:
    """y_t = min(max(y_{t-1}, f_up(u_t)), f_dn(u_t)), then the wall (if the factors have one)."""
    f_up, f_dn, _, _ = envelopes(p)
    side = (factors or {}).get("wall_side", "none")
    wall = (factors or {}).get("wall_tip")
    y, out = float(y0), []
    for qi in np.asarray(q, dtype=float).tolist():
        u = qi - offset
        y = min(max(y, f_up(u)), f_dn(u))
        if side == "pos":
            y = min(y, wall)
        elif side == "neg":
            y = max(y, wall)
        out.append(y)
    return np.array(out)


@pytest.fixture(scope="module")
def noiseless_sweeps() -> list[wild.SweepCase]:
    return [wild.sweep_case(s, fam, noiseless=True)
            for fam in wild.FAMILIES for s in range(100, 100 + SEEDS_PER_FAMILY)]


def test_same_seed_same_bytes():
    for seed, fam in ((3, None), (4, "latency"), (5, "coloured")):
        a, b = wild.sweep_case(seed, fam), wild.sweep_case(seed, fam)
        assert a.record.csv_text() == b.record.csv_text()
        assert a.factors == b.factors
    ra, rb = wild.replay_case(7, "drift"), wild.replay_case(7, "drift")
    assert ra.replay.csv_text() == rb.replay.csv_text()
    assert ra.factors == rb.factors
    assert wild.sweep_case(3).record.csv_text() != wild.sweep_case(4).record.csv_text()


def test_drawn_family_is_the_seeds_and_replay_shares_the_sweep():
    drawn = wild.sweep_case(11)
    named = wild.sweep_case(11, drawn.family)
    assert drawn.record.csv_text() == named.record.csv_text()
    replay = wild.replay_case(11)
    assert replay.straight_sweep.csv_text() == drawn.record.csv_text()
    assert replay.truth == drawn.truth


def test_noiseless_is_the_same_plant_and_path():
    noisy, clean = wild.sweep_case(21, "latency"), wild.sweep_case(21, "latency", noiseless=True)
    assert noisy.truth == clean.truth
    np.testing.assert_array_equal(noisy.record.columns["q1"], clean.record.columns["q1"])
    np.testing.assert_array_equal(noisy.record.columns["t"], clean.record.columns["t"])
    assert {k: v for k, v in noisy.factors.items() if k != "noiseless"} == \
        {k: v for k, v in clean.factors.items() if k != "noiseless"}
    assert not np.array_equal(noisy.record.columns["c1"], clean.record.columns["c1"])


def test_cases_cycle_families_and_knob_names_columns():
    cases = wild.sweep_cases(4, seed=30, families=("wall", "drift"), knob=2, tip=False)
    assert [c.family for c in cases] == ["wall", "drift", "wall", "drift"]
    assert [c.seed for c in cases] == [30, 31, 32, 33]
    assert list(cases[0].record.columns) == ["t", "q2", "c2"]
    with pytest.raises(ValueError, match="family"):
        wild.sweep_case(1, "no-such-family")


def test_csv_text_round_trips_exactly():
    rec = wild.sweep_case(8, "magnitude").record
    lines = rec.csv_text().splitlines()
    meta = [ln for ln in lines if ln.startswith("# ")]
    assert meta == [f"# {k}: {v}" for k, v in rec.meta.items()]
    header = lines[len(meta)].split(",")
    assert header == list(rec.columns)
    data = np.array([[float(x) for x in ln.split(",")] for ln in lines[len(meta) + 1:]])
    for j, name in enumerate(header):
        np.testing.assert_array_equal(data[:, j], rec.columns[name])


@pytest.mark.parametrize("family", wild.FAMILIES)
def test_every_family_draws_valid_truths(family):
    for seed in range(25):
        case = wild.sweep_case(seed, family)
        p = case.truth.as_dict()
        width = p["d_pos"] - p["d_neg"]
        assert 1.0 <= width <= 40.0
        assert 0.3 <= p["omega"] <= 3.0
        assert 0.0 <= p["b_pos"] <= 1.2 * width and 0.0 <= p["b_neg"] <= 1.2 * width
        assert p["offset"] == 0.0
        f_up, f_dn, dhat_pos, dhat_neg = envelopes(p)
        assert dhat_pos <= p["d_pos"] + 1e-9 and p["d_neg"] <= dhat_neg + 1e-9
        grid = np.concatenate([np.linspace(p["d_neg"] - 60, p["d_pos"] + 60, 2001),
                               [dhat_pos, dhat_neg, p["d_pos"], p["d_neg"]]])
        assert all(f_up(u) <= f_dn(u) + 1e-9 for u in grid.tolist())
        assert case.factors["n"] == case.record.columns["t"].size <= 50_000
        assert 30.0 <= case.factors["fs"] <= 5000.0


def test_invalid_truths_are_refused_by_name():
    good = dict(d_pos=2.0, d_neg=-2.0, b_pos=1.0, b_neg=1.0, omega=1.0, h_pos=0.0, h_neg=0.5)
    wild.KnobTruth(**good)
    for bad in (dict(omega=0.0), dict(b_pos=-0.1), dict(b_neg=6.0),
                dict(h_pos=1.0, h_neg=0.0, b_pos=0.0, b_neg=0.0), dict(d_pos=math.nan)):
        with pytest.raises(ValueError, match="KnobTruth"):
            wild.KnobTruth(**{**good, **bad})


def test_truth_forward_is_the_clamp_recursion():
    truth = wild.sweep_case(2, "asymmetric").truth.shifted(3.5)
    q = 40 * np.sin(np.linspace(0, 9, 700)) + 5 * np.sin(np.linspace(0, 40, 700))
    y0 = float(truth.f_up(q[0]))
    np.testing.assert_allclose(truth.forward(q, y0), clamp_tip(q, y0, truth.as_dict(), 3.5),
                               rtol=0, atol=1e-9)


def test_noiseless_tip_follows_the_clamp_recursion(noiseless_sweeps):
    for case in noiseless_sweeps:
        cols = case.record.columns
        expected = clamp_tip(cols["q1"], case.factors["tip_before"], case.truth.as_dict(), 0.0,
                             case.factors)
        np.testing.assert_allclose(cols["y1"], expected, rtol=0, atol=1e-9,
                                   err_msg=f"seed {case.seed} {case.family}")


def moving(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Samples strictly inside a rising (falling) run of the knob angle."""
    up = np.zeros(q.size, bool)
    dn = np.zeros(q.size, bool)
    d = np.diff(q)
    up[1:-1] = (d[:-1] > 0) & (d[1:] > 0)
    dn[1:-1] = (d[:-1] < 0) & (d[1:] < 0)
    return up, dn


def test_signed_current_leaves_no_load_past_the_current_edges(noiseless_sweeps):
    counted = 0
    for case in noiseless_sweeps:
        f = case.factors
        if f["current_sign"] != "signed":
            continue
        q, c = case.record.columns["q1"], case.record.columns["c1"]
        up, dn = moving(q)
        above = up & (q > f["current_edge_pos"] + 1e-6)
        below = dn & (q < f["current_edge_neg"] - 1e-6)
        assert np.all(c[above] > f["no_load"]), f"seed {case.seed} {case.family}"
        assert np.all(c[below] < f["no_load"]), f"seed {case.seed} {case.family}"
        counted += int(above.sum() > 0) + int(below.sum() > 0)
    assert counted >= 40


def test_magnitude_current_never_below_no_load():
    seen_load = 0
    for seed in range(40, 52):
        case = wild.sweep_case(seed, "magnitude", noiseless=True)
        c = case.record.columns["c1"]
        assert case.factors["current_sign"] == "magnitude"
        assert np.all(c >= case.factors["no_load"])
        seen_load += bool(np.max(c) > case.factors["no_load"] + 1.0)
    assert seen_load >= 10


def test_replay_noiseless_tip_follows_the_shifted_truth():
    offsets = []
    for seed in range(60, 60 + 2 * len(wild.FAMILIES)):
        case = wild.replay_case(seed, wild.FAMILIES[seed % len(wild.FAMILIES)], noiseless=True)
        f = case.factors
        assert case.truth.offset == 0.0 and f["offset"] == case.offset
        cols = case.replay.columns
        assert cols["q1"][0] == 0.0
        expected = clamp_tip(cols["q1"], f["replay_tip_before"], case.truth.as_dict(),
                             case.offset, f)
        np.testing.assert_allclose(cols["y1"], expected, rtol=0, atol=1e-9,
                                   err_msg=f"seed {seed}")
        assert -30.0 <= case.offset <= 30.0
        offsets.append(case.offset)
    assert len(set(offsets)) > len(offsets) // 2


def test_pass_flags_need_the_knob_past_the_edge_and_most_sweeps_pass_both():
    both = one = none = 0
    for seed in range(200, 350):
        case = wild.sweep_case(seed)
        f, q, t = case.factors, case.record.columns["q1"], case.truth
        if f["passes_pos_edge"]:
            assert q.max() >= t.d_pos + wild.PASS_MIN - 1e-6
        if f["passes_neg_edge"]:
            assert q.min() <= t.d_neg - wild.PASS_MIN + 1e-6
        k = f["passes_pos_edge"] + f["passes_neg_edge"]
        both, one, none = both + (k == 2), one + (k == 1), none + (k == 0)
    assert 0.8 <= both / 150 <= 0.97
    assert one >= 1 and none >= 1


def test_factors_hold_the_required_keys():
    case = wild.sweep_case(9)
    f = case.factors
    assert f["current_sign"] in ("signed", "magnitude")
    assert f["start_state"] in ("slack", "pos-taut", "neg-taut")
    for key in ("current_edge_pos", "current_edge_neg", "fs"):
        assert isinstance(f[key], float)
    for key in ("current_shows_backlash", "passes_pos_edge", "passes_neg_edge"):
        assert isinstance(f[key], bool)
    assert isinstance(f["n"], int) and f["family"] == case.family
    states = {wild.sweep_case(s).factors["start_state"] for s in range(60)}
    assert states == {"slack", "pos-taut", "neg-taut"}


def test_kink_offset_family_moves_the_current_edges_off_the_tip_edges():
    moved = 0
    for seed in range(20):
        case = wild.sweep_case(seed, "kink-offset")
        gap = max(abs(case.factors["current_edge_pos"] - case.truth.d_pos),
                  abs(case.factors["current_edge_neg"] - case.truth.d_neg))
        assert gap <= 2.0 + 1e-9
        moved += gap > 0.1
    assert moved >= 16


def test_weak_current_rises_only_a_few_noise_sigmas():
    checked = 0
    for seed in range(300, 400):
        noisy = wild.sweep_case(seed, "weak-current")
        f = noisy.factors
        if (f["current_sign"] != "signed" or f["coloured_taus"] or f["lowpass_current"]
                or f["take_up_width_pos"] or f["take_up_width_neg"] or f["stiffening"]
                or f["latency_current"] or f["servo"] != "none"):
            continue
        clean = wild.sweep_case(seed, "weak-current", noiseless=True)
        resid = noisy.record.columns["c1"] - clean.record.columns["c1"]
        resid = resid - np.polyval(np.polyfit(noisy.record.columns["t"], resid, 2),
                                   noisy.record.columns["t"])  # drift is not noise
        sigma = float(np.std(resid))
        rise_pos = f["gain_pos"] * max(f["sweep_max_deg"] - f["current_edge_pos"], 0.0)
        rise_neg = f["gain_neg"] * max(f["current_edge_neg"] - f["sweep_min_deg"], 0.0)
        rises = [r for r in (rise_pos, rise_neg) if r > 0]
        assert min(rises) / sigma < 4.0, f"seed {seed}"
        checked += 1
        if checked == 10:
            break
    assert checked == 10


def test_noiseless_live_plant_moves_along_the_shifted_loop():
    seed = next(s for s in range(100) if wild.sweep_case(s, "rounded").factors["wall_side"]
                == "none")
    live, truth = wild.live_plant(seed, "rounded", offset=6.0, noiseless=True)
    assert truth.offset == 6.0 and live.knobs == (1,)
    for target in (35.0, -40.0, 10.0):
        y_before = live.true_tip(1)
        q_end, _, tip = live.move(1, target, speed_deg_s=30.0)
        q, c = live.last_samples(1)
        assert q_end == target == q[-1] and q.size == c.size
        expected = clamp_tip(q, y_before, truth.as_dict(), 6.0)
        assert tip == pytest.approx(expected[-1], abs=1e-9)
        assert live.true_tip(1) == pytest.approx(expected[-1], abs=1e-9)
    with pytest.raises(ValueError):
        live.move(2, 0.0)


def test_live_plant_is_deterministic_and_noisy():
    readings = []
    for _ in range(2):
        live, _ = wild.live_plant(12, "coloured", offset=-4.0)
        live.move(1, 20.0)
        live.hold(0.2)
        readings.append((live.state(1), live.last_samples(1)[1]))
    assert readings[0][0] == readings[1][0]
    np.testing.assert_array_equal(readings[0][1], readings[1][1])
    assert np.std(readings[0][1]) > 0


def test_plants_import_nothing_from_hystcli():
    allowed = {"numpy", "scipy", "numba", "plants"} | set(sys.stdlib_module_names)
    files = sorted(PLANTS_DIR.glob("*.py"))
    assert {p.name for p in files} >= {"__init__.py", "wild.py"}
    for path in files:
        roots = set()
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if isinstance(node, ast.Import):
                roots |= {a.name.split(".")[0] for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0:
                roots.add(node.module.split(".")[0])
        assert "hystcli" not in roots, path.name
        assert roots <= allowed, (path.name, roots - allowed)
