"""The effects of docs/design.md section 8: null settings reproduce the base model bit for bit, and each
effect moves the output the documented way (issue 3, must-show 4)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hystcli.core import effects as E
from hystcli.sim import twin
from hystcli.errors import DataError, ModelError
from hystcli.core.run import Run
from hystcli.core.model import Model
from hystcli.core.params import EffectSpec, KnobModel, Shape

CAT = twin.get_catheter("example-a")
K1 = CAT.knobs[1]  # d_pos=9.1, d_neg=-8.7, b_pos=6.2, b_neg=5.9, omega=1.45, h_pos=-4.0, h_neg=4.2


def _triangle(amp: float, speed: float, cycles: int = 2, fs: float = 1000.0):
    """Constant-speed triangle 0 -> +amp -> -amp -> ... (deg), so lags settle to tau*speed."""
    period = 4 * amp / speed
    t = np.arange(int(round(cycles * period * fs)) + 1) / fs
    ph = (t / period) % 1.0
    q = amp * np.where(ph < 0.25, 4 * ph, np.where(ph < 0.75, 2 - 4 * ph, 4 * ph - 4))
    return t, q


def _crossing(q, y, level, rising, last_cycle_from):
    """Knob angle where y crosses ``level`` going up (rising) or down, on the last cycle."""
    dq = np.gradient(q)
    idx = np.arange(len(q))
    sel = (idx >= last_cycle_from) & ((dq > 0) if rising else (dq < 0))
    s = np.flatnonzero(sel[1:] & sel[:-1] & ((y[1:] - level) * (y[:-1] - level) <= 0) & (y[1:] != y[:-1]))
    assert s.size, "no crossing"
    i = s[0]
    return q[i] + (level - y[i]) * (q[i + 1] - q[i]) / (y[i + 1] - y[i])


def _loop_width(t, q, y, level=0.0):
    half = len(q) // 2
    return _crossing(q, y, level, True, half) - _crossing(q, y, level, False, half)


def _sim(effects, q, t, shape=Shape(), **kw):
    return twin.simulate(CAT, t, q, shape=shape, effects=effects, noise=False, **kw)


# --------------------------------------------------------------------------------------------
# registry and parsing
# --------------------------------------------------------------------------------------------
def test_registry_covers_design_section_8():
    # the eight of docs/design.md section 8, and stretch: the cable yielding to a stated load (issue 6)
    assert set(E.EFFECTS) == {"friction", "rate", "coupling", "deadzone", "creep", "latency",
                              "saturation", "contact", "stretch"}
    for et in E.EFFECTS.values():
        assert 1 <= len(et.params) <= 2
        assert et.switch in et.params and et.stage in E.STAGES
        for p in et.params:
            lo, hi = et.bounds[p]
            assert lo < hi and lo <= et.typical[p] <= hi
            assert et.domain[p][0] <= lo and hi <= et.domain[p][1]
        assert E.make_effect(et.name, **et.null_params()).is_null
        assert not E.make_effect(et.name).is_null


@pytest.mark.parametrize("text, message", [
    ("stiction", "unknown effect"),
    ("friction:nu=0.3", "unknown parameter 'nu'"),
    ("friction:mu=abc", "must be a number"),
    ("friction:mu=nan", "must be finite"),
    ("friction:mu=-0.1", "outside its valid range"),
    ("creep:fraction=1.5", "outside its valid range"),
    ("latency:delay", "not param=value"),
    ("latency:delay=inf", "must be finite"),
])
def test_bad_effects_raise_model_error_naming_the_problem(text, message):
    with pytest.raises(ModelError, match=message):
        E.parse_effect(text)


def test_same_effect_twice_is_refused():
    with pytest.raises(ModelError, match="given twice"):
        E.as_effects([E.make_effect("rate"), EffectSpec("rate", {"tau": 0.1})])


@settings(max_examples=40, deadline=None)
@given(st.sampled_from(sorted(E.EFFECTS)), st.data())
def test_format_and_parse_round_trip(name, data):
    et = E.EFFECTS[name]
    params = {p: data.draw(st.floats(*et.bounds[p], allow_nan=False)) for p in et.params}
    eff = E.make_effect(name, **params)
    back = E.parse_effects(E.format_effects([eff, E.make_effect("latency" if name != "latency" else "rate")]))
    assert back[0].name == name
    for p in et.params:
        assert back[0][p] == pytest.approx(params[p], rel=1e-5, abs=1e-9)  # %g keeps 6 digits
    assert E.parse_effect(f"{name}:" + ",".join(f"{p}={v!r}" for p, v in params.items())).params == eff.params


# --------------------------------------------------------------------------------------------
# null settings: bit for bit the base model
# --------------------------------------------------------------------------------------------
T_SW, Q_SW = twin.sweep(fs=200.0)
Q2_SW = 25.0 * np.sin(0.7 * T_SW + 0.3)
BENT = Shape.parse("alpha=90,theta=30;alpha=40,theta=200")


@settings(max_examples=40, deadline=None)
@given(st.sampled_from(sorted(E.EFFECTS)), st.data())
def test_null_setting_reproduces_the_base_twin_bit_for_bit(name, data):
    et = E.EFFECTS[name]
    params = {p: data.draw(st.floats(*et.bounds[p], allow_nan=False)) for p in et.params}
    params[et.switch] = et.null
    eff = E.make_effect(name, **params)
    base = _sim((), {1: Q_SW, 2: Q2_SW}, T_SW, BENT)
    null = _sim((eff,), {1: Q_SW, 2: Q2_SW}, T_SW, BENT)
    offs = CAT.true_offsets(BENT)
    for k in (1, 2):
        assert np.array_equal(null[f"y{k}"], base[f"y{k}"])
        assert np.array_equal(null[f"c{k}"], base[f"c{k}"])
        # ... and the base twin is the model of docs/design.md section 3 itself
        assert np.array_equal(base[f"y{k}"], CAT.knobs[k].with_offset(offs[k]).forward(null[f"q{k}"]))


@settings(max_examples=30, deadline=None)
@given(st.lists(st.sampled_from(sorted(E.EFFECTS)), unique=True, max_size=4),
       st.floats(-10, 10), st.sampled_from(["straight", "alpha=90,theta=0", "alpha=45,theta=90"]))
def test_null_effects_in_predict_equal_knob_forward_bit_for_bit(names, y0, shape):
    # no geometry: the knobs' own offsets apply whatever the shape (docs/design.md section 6)
    model = Model({1: K1.with_offset(3.0), 2: CAT.knobs[2].with_offset(-2.0)})
    run = Run({"t": T_SW, "q1": Q_SW, "q2": Q2_SW, "y1": np.full_like(T_SW, y0)}, {"shape": shape})
    null = [E.make_effect(n, **E.EFFECTS[n].null_params()) for n in names]
    for effs in (None, null):
        m = model if effs is None else Model(model.knobs, effects=tuple(e.spec() for e in null))
        ys = E.predict(m, run)
        assert np.array_equal(ys[1], model.knob(1).forward(Q_SW, y0))
        assert np.array_equal(ys[2], model.knob(2).forward(Q2_SW, 0.0))


def test_predict_uses_run_offsets_and_needs_commands():
    model = CAT.true_model()
    run = Run({"t": T_SW, "q1": Q_SW}, {"offset1": "7.5"})
    assert np.array_equal(E.predict(model, run)[1], model.knob(1).with_offset(7.5).forward(Q_SW))
    with pytest.raises(DataError, match="no command column"):
        E.predict(model, Run({"t": T_SW, "y1": Q_SW}))


@pytest.mark.parametrize("name", sorted(E.EFFECTS))
def test_predict_with_the_true_effect_reproduces_the_noise_free_twin(name):
    # the diagnosis and the twin share one effect code: the true model + effect predicts the twin
    eff = E.make_effect(name, **({"wall": 10.0} if name == "contact" else {}))
    run = _sim((eff,), {1: Q_SW, 2: Q2_SW}, T_SW, BENT)
    model = Model(CAT.knobs, CAT.geometry, effects=(eff.spec(),))
    ys = E.predict(model, run)
    for k in (1, 2):
        assert np.array_equal(ys[k], run[f"y{k}"])


# --------------------------------------------------------------------------------------------
# switched on: the documented direction
# --------------------------------------------------------------------------------------------
def test_friction_widens_the_loop_as_curvature_grows():
    t, q = _triangle(60.0, 40.0)
    widths = []
    for alpha in (0.0, 45.0, 90.0):
        shape = Shape.parse(f"alpha={alpha},theta=90")  # theta=90: no shift of knob 1
        run = _sim((E.make_effect("friction", mu=0.3),), {1: q}, t, shape)
        widths.append(_loop_width(t, q, run["y1"]))
        # by hand (docs/design.md section 3, y = 0 between h_pos and h_neg): ascending at
        # d_pos + (0 - h_pos)/omega', descending at d_neg + (0 - h_neg)/omega', omega' = omega/g
        g = math.exp(0.3 * math.radians(alpha))
        assert widths[-1] == pytest.approx(9.1 + 8.7 + (4.2 + 4.0) * g / 1.45, abs=0.05)
    assert widths[0] < widths[1] < widths[2]
    # the slope falls by g: the tip's range shrinks
    straight = _sim((), {1: q}, t)["y1"]
    bent = _sim((E.make_effect("friction", mu=0.3),), {1: q}, t, Shape.parse("alpha=90,theta=90"))["y1"]
    assert np.ptp(bent) < np.ptp(straight)


def test_deadzone_widens_the_dead_zone_with_curvature():
    t, q = _triangle(60.0, 40.0)
    half = len(q) // 2
    up = (np.gradient(q) > 0) & (np.arange(len(q)) >= half)

    def dead_zone_length(y):
        # the ascending flat part L3 at height h_pos = -4
        flat = up & (np.abs(y - K1.h_pos) < 1e-12)
        return q[flat].max() - q[flat].min()

    base = dead_zone_length(_sim((), {1: q}, t)["y1"])
    # by hand: d_pos - dhat_pos = 9.1 - ((-4 - 4.2)/1.45 - 8.7 + 5.9)
    assert base == pytest.approx(9.1 - (-8.2 / 1.45 - 8.7 + 5.9), abs=0.05)
    wide = dead_zone_length(_sim((E.make_effect("deadzone", width=3.0),), {1: q}, t,
                                 Shape.parse("alpha=90,theta=90"))["y1"])
    assert wide - base == pytest.approx(3.0 * math.pi / 2, abs=0.08)
    narrow = dead_zone_length(_sim((E.make_effect("deadzone", width=-2.0),), {1: q}, t,
                                   Shape.parse("alpha=90,theta=90"))["y1"])
    assert narrow - base == pytest.approx(-2.0 * math.pi / 2, abs=0.08)


def test_deadzone_bend_forms_follow_the_side_the_shaft_bends_to():
    # Shape.projected by hand: 60 cos 0 + 30 cos 180 = 30 on knob 1; 60 sin 0 + 30 sin 180 = 0 on knob 2
    shape = Shape.parse("alpha=60,theta=0;alpha=30,theta=180")
    assert shape.projected(1) == pytest.approx(30.0) and shape.projected(2) == pytest.approx(0.0, abs=1e-12)
    one = (E.make_effect("deadzone", "one-edge", side=4.0),)
    rad60 = math.radians(60.0)
    out = E.condition_knob(K1, one, Shape.parse("alpha=60,theta=0"), k=1)
    assert out.d_pos == pytest.approx(K1.d_pos + 4.0 * rad60) and out.d_neg == K1.d_neg
    out = E.condition_knob(K1, one, Shape.parse("alpha=60,theta=180"), k=1)
    assert out.d_neg == pytest.approx(K1.d_neg - 4.0 * rad60) and out.d_pos == K1.d_pos
    # the same bend on knob 2's plane: knob 2 sees it, knob 1 barely (cos 90 deg)
    out = E.condition_knob(K1, one, Shape.parse("alpha=60,theta=90"), k=2)
    assert out.d_pos == pytest.approx(K1.d_pos + 4.0 * rad60)
    assert E.condition_knob(K1, one, Shape.parse("alpha=60,theta=90"), k=1).d_pos == pytest.approx(K1.d_pos)
    # centre-bend: both edges move with the signed bend
    cb = (E.make_effect("deadzone", "centre-bend", shift=2.0),)
    for theta, sign in ((0, 1.0), (180, -1.0)):
        out = E.condition_knob(K1, cb, Shape.parse(f"alpha=60,theta={theta}"), k=1)
        assert out.d_pos - K1.d_pos == pytest.approx(sign * 2.0 * rad60)
        assert out.d_neg - K1.d_neg == pytest.approx(sign * 2.0 * rad60)
    # a stated load without a shape has no side: the base knob itself
    assert E.condition_knob(K1, one, Shape(), 40.0, k=1) is K1
    assert E.condition_knob(K1, cb, Shape(), 40.0, k=1) is K1


def _rising_edge(q, y, h):
    # knob angle where the ascending tip leaves the dead-zone height h (the shifted d_pos)
    i = np.flatnonzero((np.gradient(q) > 0) & (y > h + 1e-9) & (np.abs(q) < 30))
    return q[i[0]]


@pytest.mark.parametrize("q2_held", [-30.0, 20.0])
def test_coupling_shifts_knob_1_dead_zone_when_knob_2_moves(q2_held):
    t = np.arange(4001) / 200.0
    q1 = -30.0 + 3.0 * t  # one slow ascending pass through the dead zone
    eff = (E.make_effect("coupling", gain=0.15),)
    still = _sim(eff, {1: q1, 2: np.zeros_like(t)}, t)
    moved = _sim(eff, {1: q1, 2: np.full_like(t, q2_held)}, t)
    base = _sim((), {1: q1, 2: np.full_like(t, q2_held)}, t)
    e0, e1 = _rising_edge(q1, still["y1"], K1.h_pos), _rising_edge(q1, moved["y1"], K1.h_pos)
    assert e0 == pytest.approx(9.1, abs=0.02)  # d_pos, straight shaft
    assert e1 - e0 == pytest.approx(0.15 * q2_held, abs=0.03)
    assert np.array_equal(base["y1"], still["y1"])  # without coupling knob 2 does not matter
    # the current sees the same shifted edge (its slope jumps there)
    c = moved["c1"]
    taut = np.flatnonzero(c > c[np.abs(q1 - (e1 - 3)).argmin()] + 1.0)
    # 1 mA above the flat level is 1 / (k_load (1 + mu)) = 1/5 deg past the edge
    assert q1[taut[0]] == pytest.approx(e1 + 0.2, abs=0.03)


def test_rate_widens_the_loop_by_twice_tau_times_speed():
    tau = 0.1
    for speed in (10.0, 40.0):
        t, q = _triangle(60.0, speed)
        base = _loop_width(t, q, _sim((), {1: q}, t)["y1"])
        slow = _loop_width(t, q, _sim((E.make_effect("rate", tau=tau),), {1: q}, t)["y1"])
        # a first-order lag trails a ramp of speed v by tau*v once settled (e^-7 of the
        # transient left 0.7 s after a reversal), on both branches
        assert slow - base == pytest.approx(2 * tau * speed, abs=0.01)


def test_creep_decays_with_its_time_constant():
    fs, tau, frac = 100.0, 2.0, 0.25
    t = np.arange(2001) / fs
    q = np.where(t >= 1.0, 35.0, 0.0)  # a step of the knob at t = 1 s, then hold
    base = _sim((), {1: q}, t)["y1"]
    y = _sim((E.make_effect("creep", fraction=frac, tau=tau),), {1: q}, t)["y1"]
    jump = base[-1] - base[0]
    assert jump > 10  # the step bends the tip
    i = np.flatnonzero(t >= 1.0)
    # right after the step the tip has moved (1 - fraction) of the way (the sampled step is a
    # ramp over one sample of 0.01 s: the slow part has moved by dt/(2 tau) of itself) ...
    assert y[i[0]] - y[0] == pytest.approx((1 - frac) * jump, rel=1e-3)
    # ... and the rest arrives as exp(-(t - 1)/tau)
    gap = base[i] - y[i]
    assert gap[0] == pytest.approx(frac * jump, rel=0.01 / (2 * tau) + 1e-4)
    assert gap == pytest.approx(gap[0] * np.exp(-(t[i] - 1.0) / tau), rel=1e-9)
    assert y[-1] < base[-1]


@pytest.mark.parametrize("delay, samples", [(0.05, 5), (0.2, 20)])
def test_latency_shifts_the_reported_tip_by_exactly_the_delay(delay, samples):
    t, r = twin.periodic(fs=100.0)
    base = _sim((), {1: r}, t)
    late = _sim((E.make_effect("latency", delay=delay),), {1: r}, t)
    assert np.allclose(late["y1"][samples:], base["y1"][:-samples], rtol=0, atol=1e-9)
    assert np.all(late["y1"][:samples] == 0.0)  # before the run the tip sat straight
    assert np.array_equal(late["c1"], base["c1"])  # the tracker is late, not the motor


def test_latency_interpolates_between_samples():
    t = np.arange(101) / 100.0
    q = 40.0 * t  # ramp through the dead zone onto the loaded slope
    base = _sim((), {1: q}, t)["y1"]
    late = _sim((E.make_effect("latency", delay=0.015),), {1: q}, t)["y1"]
    assert late[50] == pytest.approx(0.5 * (base[48] + base[49]), abs=1e-12)


def test_saturation_stiffens_near_the_largest_bend():
    t, r = twin.periodic(fs=100.0)
    base = _sim((), {1: r}, t)["y1"]
    sat = _sim((E.make_effect("saturation", limit=50.0),), {1: r}, t)["y1"]
    assert np.max(np.abs(sat)) < 50.0
    assert np.max(sat) == pytest.approx(50.0 * math.tanh(np.max(base) / 50.0), rel=1e-12)
    small = np.abs(base) < 2
    assert np.allclose(sat[small], base[small], atol=2e-3)  # near straight, barely changed


def test_saturation_hard_knobs_grid_sets_knob2_stops_on_the_hard_grid():
    # every knob-2 limit hard-knobs' grid makes (limit x knob2) is a limit of hard's: the extra
    # parameter cannot place knob 2's stop more finely
    etype = E.EFFECTS["saturation"]
    for two, one in (("hard-knobs", "hard"),):
        f, g = etype.get_form(two), etype.get_form(one)
        lims = np.log(g.axes["limit"][np.isfinite(g.axes["limit"])])
        assert np.any(f.axes["knob2"] == 1.0)
        assert f.axes["knob2"].min() <= 0.6 and f.axes["knob2"].max() >= 1.6
        for L in f.axes["limit"][np.isfinite(f.axes["limit"])]:
            for r in f.axes["knob2"]:
                v = math.log(L * r)
                if lims[0] <= v <= lims[-1]:
                    assert np.min(np.abs(lims - v)) < 1e-9, (two, L, r)
    # a hard stop's limit is placed as finely as a contact wall (5 deg at 80 deg)
    hard = etype.get_form("hard").axes["limit"]
    assert np.max(np.diff(np.log(hard[np.isfinite(hard)]))) < math.log(1.06)


def test_saturation_knobs_forms_give_each_knob_its_own_limit():
    t, r = twin.periodic(fs=100.0)
    q = {1: r, 2: 0.9 * r}
    base = _sim((), q, t)
    hard = _sim((E.make_effect("saturation", "hard-knobs", limit=50.0, knob2=0.6),), q, t)
    # knob 1 stops at +-50, knob 2 at +-0.6 * 50 = +-30 (hand-computed limits)
    assert np.max(np.abs(hard["y1"])) == pytest.approx(min(50.0, np.max(np.abs(base["y1"]))))
    assert np.max(np.abs(hard["y2"])) == pytest.approx(30.0)
    assert np.max(np.abs(base["y2"])) > 30.0
    # knob2 = 1 is the one-limit form, sample for sample
    one = _sim((E.make_effect("saturation", "smooth", limit=50.0),), q, t)
    both = _sim((E.make_effect("saturation", "smooth-knobs", limit=50.0, knob2=1.0),), q, t)
    for k in (1, 2):
        assert np.array_equal(one[f"y{k}"], both[f"y{k}"])
    # the inverse undoes it on each knob
    eff = E.make_effect("saturation", "smooth-knobs", limit=60.0, knob2=0.7)
    m = Model(CAT.knobs, CAT.geometry, effects=(eff.spec(),))
    comp = m.compensate(Run({"t": t, "r1": 0.5 * r, "r2": 0.3 * r}))
    sim = _sim((eff,), {1: comp.run["q1"], 2: comp.run["q2"]}, t)
    for k, scale in ((1, 0.5), (2, 0.3)):
        assert np.max(np.abs(sim[f"y{k}"] - scale * r)) < 0.05


def test_contact_stops_the_tip_and_the_current_climbs_far_above_the_loaded_slope():
    t = np.arange(3001) / 100.0
    q = 2.0 * t  # 0 -> 60 deg, slowly
    free = _sim((), {1: q}, t)
    wall = _sim((E.make_effect("contact", wall=20.0, stiffness=60.0),), {1: q}, t)
    y, c = wall["y1"], wall["c1"]
    assert np.max(y) == 20.0 and np.max(free["y1"]) > 40.0
    assert np.array_equal(y[free["y1"] <= 20.0], free["y1"][free["y1"] <= 20.0])

    def slope(mask):
        return np.polyfit(q[mask], c[mask], 1)[0]

    loaded = slope((q > 15) & (q < 25))  # tendon taut, no wall: k_load (1 + mu) = 4 * 1.25
    contact = slope(free["y1"] > 25)
    assert loaded == pytest.approx(5.0, rel=0.02)
    # stiffness = 60 mA per knob deg past the wall, on top of the loaded slope
    assert contact == pytest.approx(5.0 + 60.0, rel=0.02)
    assert contact > 5 * loaded


def test_negative_wall_stops_negative_bending():
    t = np.arange(3001) / 100.0
    y = _sim((E.make_effect("contact", wall=-15.0),), {1: -2.0 * t}, t)["y1"]
    assert np.min(y) == -15.0


def test_friction_that_breaks_the_model_is_an_error_naming_it():
    knob = KnobModel(d_pos=2.0, d_neg=-2.0, b_pos=1.5, b_neg=1.5, omega=1.0, h_pos=0.0, h_neg=0.0)
    # g = exp(1 * pi) = 23.1: b_neg -> 34.7, dhat_pos = 0 - 2 + 34.7 > d_pos = 2
    with pytest.raises(ModelError, match="friction.*dhat_pos <= d_pos"):
        E.condition_knob(knob, (E.make_effect("friction", mu=1.0),), Shape.parse("alpha=180"))


# --------------------------------------------------------------------------------------------
# stretch: an output offset driven by the run's condition (a load), zero at the reference
# --------------------------------------------------------------------------------------------
def _stretch_run(condition: str | None, shape: str = "straight") -> Run:
    t, q = _triangle(60.0, 40.0)
    meta = {"shape": shape}
    if condition is not None:
        meta["condition"] = condition
    return Run({"t": t, "q1": q}, meta)


def test_stretch_moves_the_whole_output_by_compliance_times_condition_over_reference():
    model = Model({1: K1})
    run = _stretch_run("40")
    base = E.predict(model, run)[1]
    st = Model({1: K1}, effects=(E.make_effect("stretch", compliance=6.0, reference=10.0).spec(),))
    y = E.predict(st, run)[1]
    # by hand: 6 deg/rad * (40 - 10) deg = 6 * pi/6 rad = pi deg, the same on every line of the loop
    # once the output has met an envelope (before that both hold the start y0 = 0)
    met = np.arange(y.size) >= np.argmax(np.abs(run["q1"]) >= 30.0)
    assert np.allclose(y[met] - base[met], math.pi, rtol=0, atol=1e-9)
    assert np.max(np.abs(y - base)) <= math.pi + 1e-9
    # the direction: more load (condition) moves the output further up; below reference, down
    lower = E.predict(st, _stretch_run("0"))[1]
    assert np.allclose(lower[met] - base[met], -6.0 * math.radians(10.0), rtol=0, atol=1e-9)


def test_stretch_at_its_reference_or_off_is_the_base_model_bit_for_bit():
    model = Model({1: K1.with_offset(2.0)})
    for cond, eff in (("25", E.make_effect("stretch", compliance=6.0, reference=25.0)),
                      ("80", E.make_effect("stretch", compliance=0.0, reference=-40.0))):
        run = _stretch_run(cond)
        y = E.predict(Model(model.knobs, effects=(eff.spec(),)), run)[1]
        assert np.array_equal(y, model.knob(1).forward(run["q1"]))
        assert E.condition_knob(K1, (eff,), Shape(), float(cond)) is K1


def test_stretch_without_condition_metadata_follows_the_shape_curvature():
    # a catheter run: the driver is the total curvature, like friction and deadzone
    st = Model({1: K1}, effects=(E.make_effect("stretch", compliance=2.0).spec(),))
    run = _stretch_run(None, "alpha=90,theta=0")
    kn = E.condition_knob(K1, (E.make_effect("stretch", compliance=2.0),), Shape.parse("alpha=90,theta=0"))
    # 2 deg/rad * pi/2 rad = pi deg on both heights, nothing else changed
    assert kn.h_pos == pytest.approx(K1.h_pos + math.pi, abs=1e-12)
    assert kn.h_neg == pytest.approx(K1.h_neg + math.pi, abs=1e-12)
    assert (kn.d_pos, kn.d_neg, kn.b_pos, kn.b_neg, kn.omega) == (K1.d_pos, K1.d_neg, K1.b_pos, K1.b_neg, K1.omega)
    assert np.array_equal(E.predict(st, run)[1], kn.forward(run["q1"]))


def test_inverse_with_stretch_undoes_it_exactly():
    t = np.arange(0, 20.0, 0.01)
    r = 40 * np.sin(2 * np.pi * 0.1 * t)
    model = Model({1: K1}, effects=(E.make_effect("stretch", compliance=5.0, reference=20.0).spec(),))
    traj = Run({"t": t, "r1": r}, {"condition": "70"})
    q = E.inverse(model, traj).q[1]
    y = E.predict(model, Run({"t": t, "q1": q}, traj.meta))[1]
    assert np.allclose(y, r, rtol=0, atol=1e-9)
