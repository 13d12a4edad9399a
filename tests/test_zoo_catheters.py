"""The zoo catheters: records that parse, a null catheter that is the base model, and effects
that show, each in the direction its physics says."""
from __future__ import annotations

import csv
import functools
import io
import math

import numpy as np
import pytest

from plants.zoo import catheters as cz
from plants.zoo.plants import KnobTruth

RUN_COLS = ["t", "q1", "q2", "y1", "y2"]
SWEEP_COLS = ["t", "q1", "q2", "y1", "y2", "c1", "c2"]
VISIBLE_FLOOR = 0.5


def _read(text: str):
    """Parse run CSV text with the plain csv module."""
    meta, lines = {}, text.splitlines()
    i = 0
    while lines[i].startswith("#"):
        key, sep, value = lines[i][1:].partition(":")
        assert sep, lines[i]
        meta[key.strip()] = value.strip()
        i += 1
    reader = csv.reader(io.StringIO("\n".join(lines[i:])))
    header = next(reader)
    rows = np.array([[float(x) for x in row] for row in reader])
    return meta, header, {h: rows[:, j] for j, h in enumerate(header)}


@functools.lru_cache(maxsize=None)
def _case(seed, effects=()):
    return cz.make_case(seed, effects)


def _fast(text: str):
    """Metadata and columns of run CSV text with numpy alone."""
    lines = text.split("\n")
    i = 0
    while lines[i].startswith("#"):
        i += 1
    header = lines[i].split(",")
    body = ",".join(x for x in lines[i + 1:] if x)
    arr = np.array(body.split(","), dtype=float).reshape(-1, len(header))
    return {h: arr[:, j] for j, h in enumerate(header)}


@functools.lru_cache(maxsize=None)
def _parsed(seed, effects=()):
    return [_fast(r) for r in _case(seed, effects).runs]


def _rms(d):
    d = np.asarray(d)
    return float(np.sqrt(np.mean(d * d)))


# every form once, strengths cycling so that every effect is seen at every strength
_COVER = []
for _name in cz.EFFECTS:
    _forms = list(cz.FORMS[_name])
    while len(_forms) < 3:
        _forms.append(_forms[len(_forms) % len(cz.FORMS[_name])])
    for _j, _form in enumerate(_forms):
        _COVER.append((_name, _form, cz.STRENGTHS[_j % 3]))
_SEEDS = (101, 102, 103)


def _seed_of(i):
    return _SEEDS[i % len(_SEEDS)]


# --------------------------------------------------------------------------------------------
def test_api_surface():
    assert set(cz.EFFECTS) >= {"coupling", "lag", "creep", "friction", "deadzone", "saturation",
                               "stretch"}
    assert set(cz.FORMS) == set(cz.EFFECTS)
    for name, forms in cz.FORMS.items():
        assert len(forms) >= 2 and len(set(forms)) == len(forms)
    with pytest.raises(ValueError):
        cz.make_case(1, [("gravity", None, "weak")])
    with pytest.raises(ValueError):
        cz.make_case(1, [("creep", "nonsense", "weak")])
    with pytest.raises(ValueError):
        cz.make_case(1, [("creep", None, "huge")])
    with pytest.raises(ValueError):
        cz.make_case(1, [("creep", None, "weak"), ("creep", None, "strong")])


@pytest.mark.slow
def test_determinism():
    spec = (("saturation", None, "mid"), ("lag", "output-second", "weak"))
    a = cz.make_case(7, spec)
    b = cz.make_case(7, spec)
    assert a.sweep == b.sweep and a.runs == b.runs
    assert [e.params for e in a.effects] == [e.params for e in b.effects]
    assert a.effects[0].form in cz.FORMS["saturation"] and a.effects[1].form == "output-second"
    c = cz.make_case(8, spec)
    assert c.runs != a.runs
    # the same seed gives the same catheter and noise whatever its effects
    n = _case(7)
    assert n.knobs == a.knobs and n.factors["runs"][0]["shape"] == a.factors["runs"][0]["shape"]


def test_suite_composition():
    specs = cz.suite_specs(0)
    assert specs == cz.suite_specs(0)
    assert len(specs) >= 60
    assert len({s for s, _ in specs}) == len(specs)
    singles = [e[0] for _, e in specs if len(e) == 1]
    pairs = [e for _, e in specs if len(e) == 2]
    nulls = [e for _, e in specs if len(e) == 0]
    assert len(nulls) >= 10 and len(pairs) >= 8
    assert all(p[0][0] != p[1][0] for p in pairs)
    for name in cz.EFFECTS:
        assert len({s for n, _, s in singles if n == name}) >= 2
        assert {f for n, f, _ in singles if n == name} == set(cz.FORMS[name])


@pytest.mark.parametrize("effects", [(), (("stretch", None, "mid"),), (("coupling", None, "weak"),)])
def test_records_parse(effects):
    case = _case(31, effects)
    assert case.name == "zoo-31" and tuple(e.name for e in case.effects) == tuple(
        e[0] for e in effects)
    has_load = any(e[0] == "stretch" for e in effects)
    meta, header, cols = _read(case.sweep)
    assert header == SWEEP_COLS
    assert meta["motion"] == "sweep" and meta["shape"] == "straight"
    assert ("condition" in meta) == has_load
    assert np.all(np.diff(cols["t"]) > 0)
    for k in (1, 2):
        assert cols[f"q{k}"].max() == pytest.approx(40.0, abs=0.5)
        assert cols[f"q{k}"].min() == pytest.approx(-40.0, abs=0.5)
        assert np.ptp(cols[f"c{k}"]) > 10.0
    assert 6 <= len(case.runs) <= 10
    shapes, loads, kappas, dofs = set(), set(), set(), set()
    for text in case.runs:
        meta, header, cols = _read(text)
        assert header == RUN_COLS
        for key in ("catheter", "motion", "trial", "shape", "offset1", "offset2"):
            assert key in meta
        assert meta["catheter"] == case.name
        assert meta["motion"] in ("periodic", "nonperiodic")
        int(meta["trial"])
        o1, o2 = float(meta["offset1"]), float(meta["offset2"])
        segs = cz._parse_shape(meta["shape"])
        k, p1, p2 = cz._geometry(segs)
        g = case.factors["offset_per_deg"]
        assert o1 == pytest.approx(g * math.degrees(p1), abs=2e-3)
        assert o2 == pytest.approx(g * math.degrees(p2), abs=2e-3)
        assert ("condition" in meta) == has_load
        if has_load:
            loads.add(float(meta["condition"]))
        t = cols["t"]
        assert np.all(np.diff(t) > 0) and 30.0 <= t[-1] - t[0] <= 100.0
        assert np.diff(t).mean() == pytest.approx(0.01, rel=1e-3)
        moving = tuple(kb for kb in (1, 2) if np.ptp(cols[f"q{kb}"]) > 1.0)
        assert moving
        dofs.add(len(moving))
        shapes.add(meta["shape"])
        kappas.add(round(k, 3))
    assert 2 in dofs and 1 in dofs
    assert "straight" in shapes and len(kappas) >= 3
    if has_load:
        ref = case.factors["load_reference"]
        assert ref in loads and len(loads) >= 3


def test_null_is_base_hysteresis_plus_noise():
    case = _case(41)
    assert case.effects == ()
    sigma = case.factors["noise_y"]
    assert 0.1 <= sigma <= 0.3
    for text, info in zip(case.runs, case.factors["runs"]):
        meta, _, cols = _read(text)
        for kb in (1, 2):
            truth = case.knobs[kb].shifted(float(meta[f"offset{kb}"]))
            y = truth.forward(cols[f"q{kb}"], info["y_start"][kb - 1])
            r = cols[f"y{kb}"] - y
            assert _rms(r) == pytest.approx(sigma, rel=0.08)
            assert abs(r.mean()) < 4 * sigma / math.sqrt(r.size) + 2e-3
    # noise-free, the simulator is exactly the section 3 recursion
    t = np.arange(0, 50, 0.01)
    q1 = 60 * np.sin(2 * np.pi * 0.04 * t)
    q2 = 30 * np.sin(2 * np.pi * 0.02 * t) + 30 * np.sin(2 * np.pi * 0.02 * math.sqrt(3) * t)
    y0 = tuple(0.5 * (case.knobs[k].h_pos + case.knobs[k].h_neg) for k in (1, 2))
    y1, y2 = cz.simulate_tip(case, t, q1, q2, "alpha=45,theta=30", y0=y0)
    g = case.factors["offset_per_deg"]
    o1 = round(g * 45 * math.cos(math.radians(30)), 3)
    o2 = round(g * 45 * math.sin(math.radians(30)), 3)
    # the bend happens while the knob rests at 0 before t[0]: the state at t[0] follows from it
    for kb, q, y, o in ((1, q1, y1, o1), (2, q2, y2, o2)):
        kt = case.knobs[kb]
        pre = np.concatenate([np.linspace(0.0, -o, 101), np.full(300, -o)])
        ys = KnobTruth(**{**kt.as_dict(), "offset": 0.0}).forward(pre, y0[kb - 1])[-1]
        np.testing.assert_allclose(y, kt.shifted(o).forward(q, ys), atol=1e-9)


def test_sweep_null_is_base():
    for seed in (43, 44, 45, 46):
        case = _case(seed)
        if not case.factors["sweep"]["filtered"]:
            break
    meta, _, cols = _read(case.sweep)
    for kb in (1, 2):
        y = case.knobs[kb].forward(cols[f"q{kb}"], cols[f"y{kb}"][0])
        assert _rms(cols[f"y{kb}"][200:] - y[200:]) < 2.0 * case.factors["noise_y"] + 0.05


# --------------------------------------------------------------------------------------------
# every effect: visible on its runs, absent where its driver is absent, in its physics' direction
# --------------------------------------------------------------------------------------------
def _run_deltas(seed, spec):
    out = []
    infos = _case(seed, spec).factors["runs"]
    for ca, cb, info in zip(_parsed(seed, spec), _parsed(seed), infos):
        np.testing.assert_array_equal(ca["q1"], cb["q1"])
        out.append((info, ca["y1"] - cb["y1"], ca["y2"] - cb["y2"]))
    return out


def _driven(name, info, ref):
    if name == "coupling":
        return info["dof"] == "both"
    if name in ("friction", "deadzone"):
        return info["shape"] != "straight"
    if name == "stretch":
        return info["load"] != ref
    return True


@pytest.mark.parametrize("i,spec", list(enumerate(_COVER)), ids=[f"{n}-{f}-{s}" for n, f, s in _COVER])
def test_effect_visible_on_its_runs(i, spec):
    name, form, strength = spec
    seed = _seed_of(i)
    case = _case(seed, (spec,))
    null = _case(seed)
    (eff,) = case.effects
    assert (eff.name, eff.form, eff.strength) == spec
    assert case.factors["visibility"][name]["reached"] >= VISIBLE_FLOOR
    ref = case.factors["load_reference"]
    ss, n = 0.0, 0
    for info, d1, d2 in _run_deltas(seed, (spec,)):
        moving = {"1": (1,), "2": (2,), "both": (1, 2)}[info["dof"]]
        ds = [d for kb, d in ((1, d1), (2, d2)) if kb in moving or name == "coupling"]
        if _driven(name, info, ref):
            for d in ds:
                ss += float(np.dot(d, d))
                n += d.size
        elif name in ("friction", "deadzone", "stretch"):
            # no curvature / reference load: exactly the base catheter (same noise)
            assert np.max(np.abs(d1)) < 2e-3 and np.max(np.abs(d2)) < 2e-3
    vis = math.sqrt(ss / n)
    assert vis >= VISIBLE_FLOOR
    lo, hi = cz.VISIBLE[strength]
    if strength == "strong":
        assert vis >= 3.0
    if strength == "weak":
        assert vis < cz.VISIBLE["strong"][0]


T = np.arange(0.0, 50.0, 0.01)
PERIODIC = 60.0 * np.sin(2 * np.pi * 0.04 * T)
ZERO = np.zeros_like(T)


def _pair(case, q1, q2, shape="straight", condition=None, t=T):
    with_ = cz.simulate_tip(case, t, q1, q2, shape, condition)
    without = cz.simulate_tip(case, t, q1, q2, shape, condition, effects=())
    return with_, without


def _best_delay(y, y_ref, t, max_delay=3.0):
    delays = np.arange(0.0, max_delay, 0.005)
    errs = [_rms(y - np.interp(t - s, t, y_ref)) for s in delays]
    return float(delays[int(np.argmin(errs))]), float(min(errs)), _rms(y - y_ref)


def _loop(q, y):
    """(area enclosed by the tip-vs-knob loop over the second cycle, tip range)."""
    sl = slice(y.size // 2, None)
    return abs(float(np.sum(0.5 * (y[sl][1:] + y[sl][:-1]) * np.diff(q[sl])))), float(np.ptp(y[sl]))


@pytest.mark.parametrize("i,spec", list(enumerate(_COVER)), ids=[f"{n}-{f}-{s}" for n, f, s in _COVER])
def test_effect_direction(i, spec):
    name, form, strength = spec
    case = _case(_seed_of(i), (spec,))
    (eff,) = case.effects
    pr = eff.params
    if name == "coupling":
        q1 = 40 * np.sin(2 * np.pi * 0.03 * T)
        q2 = 50 * np.sin(2 * np.pi * 0.05 * T + 1.0)
        (m1, _), (b1, _) = _pair(case, q1, q2)
        (i1, _), (bi1, _) = _pair(case, q1, ZERO)
        moved, idle = _rms(m1 - b1), _rms(i1 - bi1)
        # moving knob 2 changes knob 1's tip/loop; with knob 2 at rest hardly anything
        assert moved >= VISIBLE_FLOOR and moved > 3 * idle
        if form.startswith("output"):
            (a1, _), _ = _pair(case, ZERO, q2)
            assert np.ptp(a1) >= VISIBLE_FLOOR     # knob 2 alone moves knob 1's tip
    elif name in ("lag", "latency"):
        (y, _), (yb, _) = _pair(case, PERIODIC, ZERO)
        d, aligned, raw = _best_delay(y, yb, T)
        assert d > 0.02 and aligned < raw             # the tip comes late
        if name == "latency":
            assert d == pytest.approx(pr["delay"], abs=0.01 + 1.0 / pr.get("frame_rate", 1e3))
    elif name == "creep":
        t = np.arange(0.0, 40.0, 0.01)
        q = np.clip((t - 2.0) / 0.5, 0.0, 1.0) * 45.0
        (y, _), (yb, _) = _pair(case, q, np.zeros_like(t), t=t)
        after = t >= 3.0
        assert np.ptp(yb[after]) < 1e-9            # the base tip stops with the knob
        drift = y[-1] - y[after][0]
        step = yb[-1] - yb[0]
        sign = -1.0 if form == "relaxation" else 1.0
        assert sign * np.sign(step) * drift > 0.2   # creeps on (or relaxes back) after the step
    elif name == "saturation":
        # on every run the extremes of the tip shrink (the same noise is in both records)
        shrink = 0.0
        seed = _seed_of(i)
        for ca, cb, info in zip(_parsed(seed, (spec,)), _parsed(seed), case.factors["runs"]):
            for kb in {"1": (1,), "2": (2,), "both": (1, 2)}[info["dof"]]:
                y, yb = ca[f"y{kb}"], cb[f"y{kb}"]
                # toward the straight tip: a positive extreme comes down, a negative one up
                if yb.max() > 0:
                    assert y.max() <= yb.max() + 1e-3
                    shrink += yb.max() - y.max()
                if yb.min() < 0:
                    assert y.min() >= yb.min() - 1e-3
                    shrink += y.min() - yb.min()
        assert shrink >= VISIBLE_FLOOR
    elif name in ("friction", "deadzone"):
        (ys, _), (ybs, _) = _pair(case, PERIODIC, ZERO)
        np.testing.assert_array_equal(ys, ybs)      # straight shaft: nothing
        (y, _), (yb, _) = _pair(case, PERIODIC, ZERO, "alpha=90,theta=0")
        (y45, _), (yb45, _) = _pair(case, PERIODIC, ZERO, "alpha=45,theta=0")
        assert _rms(y - yb) >= VISIBLE_FLOOR
        assert _rms(y - yb) >= 0.97 * _rms(y45 - yb45)   # more curvature, no less effect
        area, rng = _loop(PERIODIC, y)
        area_b, rng_b = _loop(PERIODIC, yb)
        if name == "friction":
            # capstan friction: the loop widens and/or the slope falls (the range shrinks)
            assert area > area_b + 1.0 or rng < rng_b - 0.5
            if form == "width-only":
                assert area > area_b + 1.0
            if form == "slope-only":
                assert rng < rng_b - 0.5
        elif form in ("widen", "widen-saturating", "one-edge"):
            assert rng < rng_b - 0.3                # a wider dead zone: less tip for the knob
        elif form == "narrow":
            assert rng > rng_b + 0.3
        else:  # centre: the loop slides along the knob axis
            assert abs(np.mean(y - yb)) > 0.3
    elif name == "stretch":
        ref = case.factors["load_reference"]
        (y0, _), (yb, _) = _pair(case, PERIODIC, ZERO, condition=ref)
        np.testing.assert_array_equal(y0, yb)       # at the reference load: nothing
        (y50, _), _ = _pair(case, PERIODIC, ZERO, condition=min(100.0, ref + 40.0))
        (y100, _), _ = _pair(case, PERIODIC, ZERO, condition=100.0)
        d50, d100 = _rms(y50 - yb), _rms(y100 - yb)
        assert 0 < d50 < d100 and d100 >= VISIBLE_FLOOR   # more load, more stretch
        if form.startswith("outward"):
            assert _loop(PERIODIC, y100)[1] < _loop(PERIODIC, yb)[1]
        else:
            assert abs(np.mean(y100 - yb)) > 0.3
    else:  # pragma: no cover
        raise AssertionError(name)
