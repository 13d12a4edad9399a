"""Tests of the independent plant zoo (plants.zoo.plants): physics, format, determinism."""
from __future__ import annotations

import csv
import io
import math

import numpy as np
import pytest

from plants.zoo import plants as P

PAPER = dict(d_pos=9.1, d_neg=-8.7, b_pos=6.2, b_neg=5.9, omega=1.45, h_pos=-4.0, h_neg=4.2)
PARAM_SETS = [
    PAPER,
    # strongly asymmetric, dead zone off-centre, small backlash
    dict(d_pos=18.0, d_neg=-6.0, b_pos=1.0, b_neg=3.0, omega=0.8, h_pos=-2.0, h_neg=1.0),
    # backlash wider than the dead zone: heights at the validity bound dh/omega = max(b) - width
    dict(d_pos=3.0, d_neg=-2.0, b_pos=9.0, b_neg=4.0, omega=2.0, h_pos=-4.0, h_neg=4.0),
    # the knob's zero outside the dead zone, no backlash on one side
    dict(d_pos=14.0, d_neg=4.0, b_pos=0.0, b_neg=7.5, omega=1.3, h_pos=1.5, h_neg=6.0),
]


def _lines_by_hand(p: dict, offset: float, X: float, n: int = 4001):
    """The paper's eight lines L1..L8 on a full sweep -X -> +X -> -X (in u = x - offset)."""
    w, dp, dn, bp, bn, hp, hn = (p[k] for k in ("omega", "d_pos", "d_neg", "b_pos", "b_neg", "h_pos", "h_neg"))
    Dp = (hp - hn) / w + dn + bn      # paper eq. D_hats
    Dn = (hn - hp) / w + dp - bp
    up = np.linspace(-X, X, n)
    dn_ = np.linspace(X, -X, n)
    y_up = np.empty(n)
    y_dn = np.empty(n)
    L1 = w * (-X - dn) + hn
    L5 = w * (X - dp) + hp
    x12 = -X + bn                      # L1 ends where L2 reaches it
    x56 = X - bp
    for i, x in enumerate(up):
        if x < x12:
            y_up[i] = L1
        elif x < Dp:
            y_up[i] = w * (x - Dp) + hp      # L2
        elif x <= dp:
            y_up[i] = hp                      # L3
        else:
            y_up[i] = w * (x - dp) + hp       # L4
    for i, x in enumerate(dn_):
        if x > x56:
            y_dn[i] = L5
        elif x > Dn:
            y_dn[i] = w * (x - Dn) + hn       # L6
        elif x >= dn:
            y_dn[i] = hn                      # L7
        else:
            y_dn[i] = w * (x - dn) + hn       # L8
    u = np.concatenate([up, dn_])
    return u + offset, np.concatenate([y_up, y_dn]), (x12, Dp, dp, x56, Dn, dn)


@pytest.mark.parametrize("p", PARAM_SETS)
@pytest.mark.parametrize("offset", [0.0, 7.25, -12.5])
def test_forward_walks_the_eight_lines(p, offset):
    t = P.KnobTruth(**p, offset=offset)
    X = max(abs(v) for v in (t.d_pos, t.d_neg, t.dhat_pos, t.dhat_neg)) + max(t.b_pos, t.b_neg) + 5
    q, y_hand, (x12, Dp, dp, x56, Dn, dn) = _lines_by_hand(p, offset, X)
    # the switch points are in the order the paper draws them
    assert -X <= x12 <= Dp <= dp < X and X >= x56 >= Dn >= dn > -X
    y0 = p["omega"] * (-X - p["d_neg"]) + p["h_neg"]      # on L8 at -X, as the previous sweep left it
    y = t.forward(q, y0)
    np.testing.assert_allclose(y, y_hand, rtol=0, atol=1e-9)
    # a second full cycle retraces the same loop
    y2 = t.forward(np.concatenate([q, q]), y0)
    np.testing.assert_allclose(y2[q.size:], y_hand, rtol=0, atol=1e-9)


def test_shift_moves_the_tip_loop_by_exactly_offset():
    rng = np.random.default_rng(1)
    q = np.cumsum(rng.normal(0, 0.7, 3000))
    t0 = P.KnobTruth(**PAPER)
    for off in (-30.0, -4.5, 0.0, 11.0, 30.0):
        np.testing.assert_allclose(t0.shifted(off).forward(q + off, 1.0), t0.forward(q, 1.0), atol=1e-12)


def test_invalid_parameters_name_the_condition():
    with pytest.raises(ValueError, match="omega > 0"):
        P.KnobTruth(**{**PAPER, "omega": 0.0})
    with pytest.raises(ValueError, match="b_pos >= 0"):
        P.KnobTruth(**{**PAPER, "b_pos": -1.0})
    with pytest.raises(ValueError, match="dhat_pos <= d_pos"):
        P.KnobTruth(d_pos=1, d_neg=-1, b_pos=0, b_neg=5, omega=1, h_pos=0, h_neg=0)
    with pytest.raises(ValueError, match="d_neg <= dhat_neg"):
        P.KnobTruth(d_pos=1, d_neg=-1, b_pos=5, b_neg=0, omega=1, h_pos=0, h_neg=0)
    with pytest.raises(ValueError, match="f_up <= f_dn"):
        P.KnobTruth(d_pos=5, d_neg=-5, b_pos=0, b_neg=0, omega=1, h_pos=1, h_neg=0)


def test_drawn_truths_are_valid_and_in_range():
    cases = P.sweep_cases(80, seed=1000, tip=False)
    for c in cases:
        t = c.truth
        P.KnobTruth(**t.as_dict())                     # re-validates
        assert set(t.as_dict()) == {"d_pos", "d_neg", "b_pos", "b_neg", "omega", "h_pos", "h_neg", "offset"}
        assert 2 - 1e-9 <= t.d_pos - t.d_neg <= 25 + 1e-9
        assert 0.8 <= t.omega <= 2.0
        if t.b_pos > 0 and t.b_neg > 0:
            assert 1 / 3 - 1e-9 <= t.b_pos / t.b_neg <= 3 + 1e-9
        if t.d_neg < 0 < t.d_pos:
            assert 1 / 3 - 1e-9 <= t.d_pos / -t.d_neg <= 3 + 1e-9
    bw = [max(c.truth.b_pos, c.truth.b_neg) / (c.truth.d_pos - c.truth.d_neg) for c in cases]
    assert max(bw) > 0.5                              # backlash wider than half the dead zone occurs


def test_determinism():
    for fam in P.FAMILIES:
        a, b = P.sweep_case(7, fam), P.sweep_case(7, fam)
        assert a.record.csv_text() == b.record.csv_text() and a.truth == b.truth
    r1, r2 = P.replay_case(8), P.replay_case(8)
    assert r1.replay.csv_text() == r2.replay.csv_text() and r1.offset == r2.offset
    assert [c.family for c in P.sweep_cases(9, seed=3)] == list(P.FAMILIES) + [P.FAMILIES[0]]
    assert P.sweep_cases(3, seed=5)[2].record.csv_text() == P.sweep_case(7, P.FAMILIES[2]).record.csv_text()
    # the replay's straight sweep is the sweep case of the same seed: the same plant
    rc, sc = P.replay_case(11, "tip-load"), P.sweep_case(11, "tip-load")
    assert rc.truth == sc.truth and rc.straight_sweep.csv_text() == sc.record.csv_text()
    outs = []
    for _ in range(2):
        lp, _t = P.live_plant(4, "spiky", offset=5.0)
        outs.append([lp.move(1, x) for x in (10.0, -20.0, 3.0)])
    assert outs[0] == outs[1]


def _parse(text: str):
    meta, rows = {}, []
    lines = text.splitlines()
    i = 0
    while lines[i].startswith("#"):
        k, v = lines[i][1:].split(":", 1)
        meta[k.strip()] = v.strip()
        i += 1
    reader = csv.reader(io.StringIO("\n".join(lines[i:])))
    header = next(reader)
    rows = [[float(x) for x in r] for r in reader]
    return meta, header, np.array(rows)


@pytest.mark.parametrize("family", P.FAMILIES)
def test_every_family_gives_valid_records(family):
    for seed in (21, 22):
        c = P.sweep_case(seed, family)
        assert c.family == family
        for rec, tip in ((c.record, True),):
            cols = rec.columns
            assert list(cols) == ["t", "q1", "y1", "c1"]
            n = cols["t"].size
            assert n >= 300 and all(v.shape == (n,) and np.all(np.isfinite(v)) for v in cols.values())
            assert np.all(np.diff(cols["t"]) > 0)
            assert 50 - 1e-9 <= c.factors["fs"] <= 2000 + 1e-9 and n <= P.MAX_SAMPLES
            assert rec.meta["shape"] == "straight" and rec.meta["motion"] == "sweep"
            meta, header, arr = _parse(rec.csv_text())
            assert meta == rec.meta and header == list(cols)
            for j, k in enumerate(header):
                np.testing.assert_array_equal(arr[:, j], cols[k])
            arr2 = np.loadtxt(io.StringIO(rec.csv_text()), delimiter=",", skiprows=len(meta) + 1)
            np.testing.assert_array_equal(arr2, arr)
        r = P.replay_case(seed, family)
        assert list(r.replay.columns) == ["t", "q1", "y1", "c1"]
        assert r.replay.columns["q1"][0] == 0.0 and -30 <= r.offset <= 30
        assert all(np.all(np.isfinite(v)) for v in r.replay.columns.values())
        assert np.all(np.diff(r.replay.columns["t"]) > 0)
        assert r.truth.offset == 0.0
    c2 = P.sweep_case(5, family, knob=2, tip=False)
    assert list(c2.record.columns) == ["t", "q2", "c2"]


def test_offsets_and_null_cases():
    offs = [P.replay_case(s).offset for s in range(60)]
    assert any(o == 0.0 for o in offs) and max(offs) > 15 and min(offs) < -15
    assert all(-30 <= o <= 30 for o in offs)


def _clean(seed, family, **over):
    base = {"filtered": False, "ripple_amp": 0.0}
    base.update(over)
    return P.sweep_case(seed, family, noiseless=True, overrides=base)


def test_start_state_is_what_the_history_leaves():
    for seed in range(30):
        c = _clean(seed, P.FAMILIES[seed % 7])        # all but the wall: the free-tip recursion
        hist = P._dense_path(c.factors["history"])
        y_start = c.truth.forward(hist, 0.0)[-1]
        assert y_start == pytest.approx(c.factors["y_start"], abs=1e-12)
        col = c.record.columns
        np.testing.assert_allclose(col["y1"], c.truth.forward(col["q1"], y_start), atol=1e-12)
    kinds = {P.sweep_case(s).factors["start_taut"] for s in range(40)}
    assert kinds == {"pos", "neg", "none"}


def test_replay_follows_the_shifted_loop():
    for seed in range(12):
        r = P.replay_case(seed, "stretch", noiseless=True, overrides={"filtered": False})
        t, o = r.truth, r.offset
        col = r.replay.columns
        q = col["q1"]
        bent = t.shifted(o)
        np.testing.assert_allclose(col["y1"], bent.forward(q, r.factors["y_start"]), atol=1e-12)
        law = r.factors["sweep"]
        u = q - o
        expect = law["c0"] + law["k_pos"] * np.maximum(u - t.d_pos, 0) - law["k_neg"] * np.maximum(t.d_neg - u, 0)
        np.testing.assert_allclose(col["c1"], expect, atol=1e-9)


@pytest.mark.parametrize("family", P.FAMILIES)
def test_shift_moves_the_current_loop_by_exactly_offset(family):
    """Two plants, straight and bent, different histories: after one full cycle the loops agree."""
    off = 13.0 if family != "wall" else -9.0
    res = []
    for o in (0.0, off):
        lp, t = P.live_plant(31, family, offset=o, noiseless=True)
        lp.law["ripple_amp"] = 0.0                      # the motor's cogging lives in q, not u
        A = max(abs(t.d_pos), abs(t.d_neg), abs(t.dhat_pos), abs(t.dhat_neg)) + max(t.b_pos, t.b_neg) + 8
        lp.move(1, o + A, 40, 0.002)
        lp.move(1, o - A, 40, 0.002)
        qs, cs = [], []
        for target in (o + A, o - A, o + 0.3 * A):
            lp.move(1, target, 40, 0.002)
            q, c = lp.last_samples(1)
            qs.append(q - o)
            cs.append(c)
        res.append((np.concatenate(qs), np.concatenate(cs)))
    np.testing.assert_allclose(res[0][0], res[1][0], atol=1e-9)
    np.testing.assert_allclose(res[0][1], res[1][1], atol=1e-6)


def _loop(c):
    col = c.record.columns
    return col["q1"], col["c1"], c.truth, c.factors


def test_stretch_is_the_same_both_ways():
    for seed in range(10):
        q, cur, t, f = _loop(_clean(seed, "stretch"))
        expect = f["c0"] + f["k_pos"] * np.maximum(q - t.d_pos, 0) - f["k_neg"] * np.maximum(t.d_neg - q, 0)
        np.testing.assert_allclose(cur, expect, atol=1e-9)
        assert not P.sweep_case(seed, "stretch").current_shows_backlash


def _first_top_reversal(q):
    dq = np.diff(q)
    for i in range(1, dq.size):
        if dq[i - 1] > 0 and dq[i] < 0:
            return i
    return None


def test_tip_load_holds_through_the_backlash_then_unloads():
    checked = 0
    for seed in range(200):
        c = _clean(seed, "tip-load", waveform="triangle")
        q, cur, t, f = _loop(c)
        i = _first_top_reversal(q)
        if i is None or t.b_pos < 1.0 or q[i] - t.d_pos < 2.0:
            continue
        assert c.current_shows_backlash
        xr, peak = q[i], cur[i]
        assert peak > f["c0"] + 1e-6
        j = i + 1
        while j < q.size and q[j] < q[j - 1]:
            j += 1
        seg_q, seg_c = q[i:j], cur[i:j]
        hold = seg_q >= xr - t.b_pos + 1e-9
        np.testing.assert_allclose(seg_c[hold], peak, atol=1e-9)          # load stays on the plateau
        after = ~hold
        assert np.all(np.diff(seg_c[after]) <= 1e-9)                       # then unloads
        assert seg_c[after][-1] <= f["c0"] + 1e-9 or seg_q[-1] > t.dhat_neg
        checked += 1
        if checked >= 5:
            break
    assert checked >= 3


def test_drop_at_reversal_jumps():
    checked = 0
    for seed in range(200):
        c = _clean(seed, "drop-at-reversal", waveform="triangle")
        q, cur, t, f = _loop(c)
        i = _first_top_reversal(q)
        if i is None or q[i] - t.d_pos < 3.0:
            continue
        load = cur[i] - f["c0"]
        k = i + 1
        while k < q.size and q[i] - q[k] < f["drop_travel"]:
            k += 1
        assert q[i] - q[k] < f["drop_travel"] + 2.0                       # within a small knob travel
        assert cur[i] - cur[k] >= 0.9 * f["drop_frac"] * load             # the force fell by drop_frac
        assert (cur[i] - cur[k]) / (q[i] - q[k]) > 3 * f["k_pos"]         # far steeper than loading
        checked += 1
        if checked >= 5:
            break
    assert checked >= 3


def test_pretension_is_never_flat():
    """Where the same plant without pretension is flat (no tendon taut), this one still slopes."""
    for seed in range(15):
        c = _clean(seed, "pretension")
        f = c.factors
        assert f["pre_slope"] > 0
        bare = _clean(seed, "pretension", pre_slope=0.0)
        q = c.record.columns["q1"]
        dq = np.diff(q)
        ok = np.abs(dq) > 1e-6
        s_pre = np.diff(c.record.columns["c1"])[ok] / dq[ok]
        s_bare = np.diff(bare.record.columns["c1"])[ok] / dq[ok]
        flat = np.abs(s_bare) < 1e-9
        assert flat.sum() > 20
        np.testing.assert_allclose(s_pre[flat], f["pre_slope"], rtol=1e-5)
        loaded = np.abs(s_bare) > 1e-6
        assert np.all(np.abs(s_pre[loaded & (s_bare > 0)]) > f["pre_slope"])


def test_pretension_slope_in_dead_zone_with_any_base():
    for seed in range(15):
        c = _clean(seed, "pretension")
        f = c.factors
        off = _clean(seed, "pretension", pre_slope=0.0)
        diff = c.record.columns["c1"] - off.record.columns["c1"]
        q = c.record.columns["q1"]
        np.testing.assert_allclose(diff, f["pre_slope"] * (q - 0.5 * (c.truth.d_pos + c.truth.d_neg)), atol=1e-9)


def test_coulomb_viscous_adds_a_velocity_sign_jump():
    for seed in range(8):
        c = _clean(seed, "coulomb-viscous", base="stretch", waveform="triangle", pre_slope=0.0)
        f = c.factors
        q, cur, t = c.record.columns["q1"], c.record.columns["c1"], c.truth
        ref = f["c0"] + f["k_pos"] * np.maximum(q - t.d_pos, 0) - f["k_neg"] * np.maximum(t.d_neg - q, 0)
        extra = cur - ref
        v = np.gradient(q, c.record.columns["t"] - c.record.columns["t"][0])
        np.testing.assert_allclose(extra, f["coulomb"] * np.tanh(v / f["v_eps"]) + f["viscous"] * v, atol=1e-9)
        moving = np.abs(v) > 0.5 * f["speed"]
        assert np.all(np.sign(extra[moving]) == np.sign(v[moving]))
        assert np.abs(extra[moving]).min() > 0.7 * f["coulomb"]


def test_spiky_has_stiction_bursts_and_outliers():
    for seed in range(6):
        c = _clean(seed, "spiky")
        calm = _clean(seed, "spiky", spike_amp=0.0)
        d = c.record.columns["c1"] - calm.record.columns["c1"]
        q = c.record.columns["q1"]
        f = c.factors
        assert abs(d[1]) == pytest.approx(f["spike_amp"], rel=1e-9)   # the start from rest
        i = _first_top_reversal(q)
        assert abs(d[i + 1]) > 0.8 * f["spike_amp"]                   # a burst at the reversal
        tt = c.record.columns["t"]
        quiet = np.ones(q.size, bool)
        dq = np.diff(q)
        for k in np.flatnonzero(np.sign(dq[1:]) != np.sign(dq[:-1])) + 1:
            quiet &= ~((tt >= tt[k] - 1e-9) & (tt < tt[k] + 12 * f["spike_tau"]))
        quiet[: np.searchsorted(tt, tt[0] + 12 * f["spike_tau"])] = False
        assert np.abs(d[quiet]).max() < 1e-3 * f["spike_amp"]         # and nothing in between
        noisy = P.sweep_case(seed, "spiky", overrides={"filtered": False, "outlier_rate": 0.01})
        jumps = np.abs(noisy.record.columns["c1"] - c.record.columns["c1"]) > 0.5 * f["outlier_amp"]
        assert 0.002 * q.size < jumps.sum() < 0.03 * q.size


def test_stiffening_slope_grows():
    for seed in range(6):
        c = _clean(seed, "stiffening", base="stretch")
        q, cur, t, f = _loop(c)
        s = q - t.d_pos
        m = s > 0
        expect = f["c0"] + f["k_pos"] * (s[m] + s[m] ** 2 / (2 * f["stiff_scale"]))
        np.testing.assert_allclose(cur[m], expect, atol=1e-9)


def test_wall_stops_the_tip_and_the_current_rises_steeply():
    seen = 0
    for seed in range(40):
        c = _clean(seed, "wall")
        q, cur, t, f = _loop(c)
        y = c.record.columns["y1"]
        side = f["wall_side"]
        assert side in (-1.0, 1.0)
        assert f["wall_y"] > max(t.h_pos, t.h_neg) if side > 0 else f["wall_y"] < min(t.h_pos, t.h_neg)
        assert np.all(y <= f["wall_y"] + 1e-12) if side > 0 else np.all(y >= f["wall_y"] - 1e-12)
        beyond = (q - f["wall_u"]) * side > 0.5
        if beyond.sum() > 3 and f["base"] == "stretch":
            k = f["k_pos"] if side > 0 else f["k_neg"]
            sl = np.diff(cur) / np.diff(q)
            bb = beyond[1:] & beyond[:-1]
            assert np.all(np.abs(sl[bb]) >= 5 * k)
            np.testing.assert_allclose(y[beyond], f["wall_y"], atol=1e-12)
            seen += 1
    assert seen >= 2


def test_live_plant_moves_and_holds():
    lp, t = P.live_plant(2, "stretch", offset=-6.0, noiseless=True)
    lp.law["filtered"] = False
    assert lp.knobs == (1,) and t.offset == -6.0
    q, c, y = lp.move(1, 25.0, speed_deg_s=20.0, dt=0.001)
    qs, cs = lp.last_samples(1)
    assert q == 25.0 and qs[-1] == 25.0 and qs.size == 1250 and cs[-1] == c
    f = lp.law
    u = 25.0 - t.offset
    assert c == pytest.approx(f["c0"] + f["k_pos"] * max(u - t.d_pos, 0) - f["k_neg"] * max(t.d_neg - u, 0))
    assert y == pytest.approx(lp.true_tip(1)) and lp.true_tip(1) == pytest.approx(float(t.f_up(25.0)))
    lp.hold(0.2)
    qs, cs = lp.last_samples(1)
    assert np.all(qs == 25.0) and qs.size == 200 and lp.state(1)[0] == 25.0
    with pytest.raises(ValueError):
        lp.move(2, 0.0)
    noisy, _ = P.live_plant(2, "spiky", offset=3.0)
    for target in np.arange(0.5, 10.0, 0.5):
        out = noisy.move(1, target, 10.0)
        assert all(math.isfinite(v) for v in out)
