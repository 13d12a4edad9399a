"""Tests of the model (hystcli.core): the eight lines, the inverse, validation, shape and rotation."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from hystcli.errors import ModelError
from hystcli.core import kernel
from hystcli.core.model import Model
from hystcli.core.params import Geometry, KnobModel, Shape, rotate_offsets

# docs/design.md section 6's example knob.
EXAMPLE = dict(d_pos=9.1, d_neg=-8.7, b_pos=6.2, b_neg=5.9, omega=1.45, h_pos=-4.0, h_neg=4.2)


def eight_lines(x, X, p, offset=0.0):
    """The paper's L1..L8 (eq. model_eqs) written out by hand for one full sweep.

    The sweep starts at -X on the descending branch, rises to +X, and falls back to -X. The region
    boundaries are worked out by hand from eq. D_hats:
      ascending:  L1 on [-X, -X + B_neg]  (plateau: the output held since -X)
                  L2 on [-X + B_neg, Dhat_pos], L3 on [Dhat_pos, D_pos], L4 on [D_pos, X]
      descending: L5 on [X - B_pos, X], L6 on [Dhat_neg, X - B_pos], L7 on [D_neg, Dhat_neg],
                  L8 on [-X, D_neg]
    (-X + B_neg: where omega(u - Dhat_pos) + H_pos equals L1's value; X - B_pos likewise for L5.)
    """
    w, dp, dn, bp, bn, hp, hn = (p["omega"], p["d_pos"], p["d_neg"], p["b_pos"], p["b_neg"],
                                 p["h_pos"], p["h_neg"])
    dhp = (hp - hn) / w + dn + bn
    dhn = (hn - hp) / w + dp - bp
    out = []
    rising = True
    prev = None
    for xi in x:
        u = xi - offset
        if prev is not None and xi < prev:
            rising = False
        prev = xi
        if rising:
            if u <= -X + bn:
                out.append(w * (-X - dn) + hn)          # L1
            elif u <= dhp:
                out.append(w * (u - dhp) + hp)          # L2
            elif u <= dp:
                out.append(hp)                          # L3
            else:
                out.append(w * (u - dp) + hp)           # L4
        else:
            if u >= X - bp:
                out.append(w * (X - dp) + hp)           # L5
            elif u >= dhn:
                out.append(w * (u - dhn) + hn)          # L6
            elif u >= dn:
                out.append(hn)                          # L7
            else:
                out.append(w * (u - dn) + hn)           # L8
    return np.array(out)


PARAM_SETS = [
    EXAMPLE,
    dict(d_pos=12.0, d_neg=-6.0, b_pos=3.0, b_neg=8.0, omega=1.2, h_pos=-2.0, h_neg=1.0),
    dict(d_pos=5.0, d_neg=-11.0, b_pos=9.0, b_neg=4.0, omega=1.8, h_pos=-6.0, h_neg=6.5),
    dict(d_pos=8.0, d_neg=-8.0, b_pos=0.0, b_neg=0.0, omega=1.45, h_pos=0.0, h_neg=0.0),
]


@pytest.mark.parametrize("p", PARAM_SETS)
@pytest.mark.parametrize("offset", [0.0, 7.5, -13.0])
def test_forward_walks_the_eight_lines_on_a_full_sweep(p, offset):
    X = 40.0
    up = np.linspace(-X, X, 4001)
    x = np.concatenate([up, up[::-1][1:]]) + offset
    y_start = p["omega"] * (-X - p["d_neg"]) + p["h_neg"]  # L8 at -X: the loop's lower corner
    knob = KnobModel(**p, offset=offset)
    y = knob.forward(x, y0=y_start)
    expected = eight_lines(x, X, p, offset)
    np.testing.assert_allclose(y, expected, rtol=0, atol=1e-9)


def test_design_example_derived_edges():
    # docs/design.md eq. D_hats by hand: (-4 - 4.2)/1.45 - 8.7 + 5.9 = -8.4551724...
    k = KnobModel(**EXAMPLE)
    assert k.dhat_pos == pytest.approx(-8.2 / 1.45 - 2.8, abs=1e-12)
    assert k.dhat_neg == pytest.approx(8.2 / 1.45 + 2.9, abs=1e-12)


def test_partial_reversal_gives_a_minor_loop_inside_the_major_one():
    k = KnobModel(**EXAMPLE)
    x = np.concatenate([np.linspace(0, 30, 301), np.linspace(30, 20, 101), np.linspace(20, 30, 101)])
    y = k.forward(x)
    # after the reversal at 30 the output holds (the backlash plateau L5) ...
    top = 1.45 * (30 - 9.1) - 4.0
    assert y[300] == pytest.approx(top)
    # ... for the first b_pos = 6.2 deg of return, then falls with slope omega
    back = x[301:402]
    expected_down = np.where(back >= 30 - 6.2, top, 1.45 * (back - k.dhat_neg) + 4.2)
    np.testing.assert_allclose(y[301:402], expected_down, atol=1e-9)
    # rising again from 20 the output holds until f_up catches up, then rejoins L4 at 30
    assert y[-1] == pytest.approx(top)
    assert np.all(np.diff(y[402:]) >= -1e-12)


def valid_knobs():
    @st.composite
    def build(draw):
        d_neg = draw(st.floats(-20, 0))
        d_pos = draw(st.floats(0, 20))
        b_pos = draw(st.floats(0, 10))
        b_neg = draw(st.floats(0, 10))
        omega = draw(st.floats(0.3, 3.0))
        h_pos = draw(st.floats(-8, 8))
        h_neg = draw(st.floats(-8, 8))
        offset = draw(st.floats(-30, 30))
        try:
            return KnobModel(d_pos, d_neg, b_pos, b_neg, omega, h_pos, h_neg, offset)
        except ModelError:
            assume(False)
    return build()


@settings(max_examples=300, deadline=None)
@given(knob=valid_knobs(),
       r=st.lists(st.floats(-80, 80, allow_nan=False), min_size=1, max_size=60),
       y0=st.floats(-10, 10))
def test_forward_of_inverse_is_identity(knob, r, y0):
    r = np.array(r)
    q = knob.inverse(r, y0=y0)
    np.testing.assert_allclose(knob.forward(q, y0=y0), r, rtol=0, atol=1e-9)


@settings(max_examples=100, deadline=None)
@given(knob=valid_knobs(), seed=st.integers(0, 2**32 - 1))
def test_forward_of_inverse_on_smooth_trajectories(knob, seed):
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 50, 5000)
    r = 60 * np.sin(2 * np.pi * rng.uniform(0.01, 0.2) * t + rng.uniform(0, 6)) + rng.normal(0, 0.5, t.size)
    np.testing.assert_allclose(knob.forward(knob.inverse(r)), r, rtol=0, atol=1e-9)


def test_inverse_jumps_the_dead_zone_and_backlash():
    k = KnobModel(**EXAMPLE)
    # from y = -10 (below the band), asking for 1 deg above h_pos: the smallest x on f_up is
    # past the dead zone, d_pos + 1/omega
    q = k.inverse([-4.0 + 1.0], y0=-10.0)
    assert q[0] == pytest.approx(9.1 + 1.0 / 1.45)
    # then asking for less: largest x on f_dn reaching it
    q = k.inverse([10.0, 5.0])
    assert q[1] == pytest.approx(k.dhat_neg + (5.0 - 4.2) / 1.45)


def test_inverse_holds_when_reference_is_constant():
    k = KnobModel(**EXAMPLE)
    q = k.inverse([10.0, 10.0, 10.0])
    assert q[0] == q[1] == q[2]


@pytest.mark.parametrize("change, condition", [
    (dict(omega=0.0), "omega > 0"),
    (dict(omega=-1.0), "omega > 0"),
    (dict(b_pos=-0.1), "b_pos >= 0"),
    (dict(b_neg=-2.0), "b_neg >= 0"),
    (dict(d_pos=-20.0), "dhat_pos <= d_pos"),
    (dict(d_neg=8.7), "d_neg <= dhat_neg"),
    # both far edges in order, yet the dead zone of f_up (height 5) lies above f_dn (4.5 at u=0.5)
    (dict(d_pos=1.0, d_neg=-10.0, b_pos=0.0, b_neg=0.0, omega=1.0, h_pos=5.0, h_neg=-5.0),
     "f_up <= f_dn everywhere"),
    (dict(d_pos=float("nan")), "finite"),
    (dict(omega="abc"), "must be a number"),
    (dict(d_pos=1e308), "d_pos = 1e+308 is beyond"),  # a corrupt file, not a knob angle (issue 12)
    (dict(offset=-2e6), "offset = -2e+06 is beyond"),
])
def test_invalid_parameters_name_the_violated_condition(change, condition):
    p = dict(EXAMPLE)
    p.update(change)
    with pytest.raises(ModelError, match=condition.replace("+", r"\+")):
        KnobModel(**p)


def test_shape_offset_by_hand():
    # eq. 3: (180/pi) * 1.2 mm * (pi/2) / 8 mm = 13.5 deg for alpha = 90, theta = 0
    g = Geometry(1.2, 8.0)
    o1, o2 = g.offsets(Shape.parse("alpha=90,theta=0"))
    assert o1 == pytest.approx(13.5)
    assert o2 == pytest.approx(0.0, abs=1e-12)
    # the paper's 2-DoF shape: 45 deg toward anterior and 45 deg toward right: 6.75 each
    o1, o2 = g.offsets(Shape.parse("alpha=45,theta=0;alpha=45,theta=90"))
    assert (o1, o2) == pytest.approx((6.75, 6.75))
    assert g.offsets(Shape.parse("straight")) == (0.0, 0.0)


@pytest.mark.parametrize("text", ["alpha", "alpha=x", "beta=3", "theta=30", "alpha=inf", "alpha=1e9",
                                  "alpha=90,alpha=45", "alpha=90,theta=0,theta=5"])
def test_bad_shape_text(text):
    with pytest.raises(ModelError, match="bad shape segment"):
        Shape.parse(text)


@settings(max_examples=100, deadline=None)
@given(alphas=st.lists(st.tuples(st.floats(-180, 180), st.floats(-360, 360)), min_size=1, max_size=4),
       delta=st.floats(-360, 360))
def test_rotation_of_offsets_matches_rotating_the_shape(alphas, delta):
    g = Geometry(1.2, 8.0)
    shape = Shape.parse(";".join(f"alpha={a},theta={t}" for a, t in alphas))
    rotated = rotate_offsets(*g.offsets(shape), delta)
    np.testing.assert_allclose(rotated, g.offsets(shape.rotated(delta)), atol=1e-9)


def test_model_rotation_and_offsets_for():
    g = Geometry(1.2, 8.0)
    m = Model({1: KnobModel(**EXAMPLE, offset=13.5), 2: KnobModel(**EXAMPLE)}, g)
    r = m.rotated(90.0)
    assert r.knob(1).offset == pytest.approx(0.0, abs=1e-12)
    assert r.knob(2).offset == pytest.approx(-13.5)
    # precedence (docs/design.md section 6): offsetK, then geometry from shape, then the model's own
    assert m.offsets_for({"offset1": "2.5", "shape": "alpha=90,theta=0"})[1] == 2.5
    assert m.offsets_for({"shape": "alpha=90,theta=90"}) == pytest.approx({1: 0.0, 2: 13.5})
    assert m.offsets_for({}) == {1: 13.5, 2: 0.0}
    assert m.without_shift().knob(1).offset == 0.0
    with pytest.raises(ModelError, match="no knob 3"):
        m.knob(3)


def test_shifted_edges():
    k = KnobModel(**EXAMPLE).with_offset(5.0)
    assert k.shifted_d_pos == pytest.approx(14.1)
    assert k.shifted_d_neg == pytest.approx(-3.7)
    assert k.shifted(1.0).offset == 6.0


# --------------------------------------------------------------------------------------------
# the compiled kernels (issue 12): NaN refused, the numba and plain-Python paths agree
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_forward_and_inverse_refuse_non_finite_input_naming_the_sample(bad):
    knob = KnobModel(**EXAMPLE)
    x = np.array([0.0, 5.0, bad, 1.0])
    # without the check NaN would pass the clamp silently: every comparison with it is false
    with pytest.raises(ModelError, match="forward: knob angles must be finite, sample 2 is"):
        knob.forward(x)
    with pytest.raises(ModelError, match="inverse: desired tip angles must be finite, sample 2 is"):
        knob.inverse(x)
    with pytest.raises(ModelError, match="y0"):
        knob.forward(np.zeros(3), y0=float(bad))


def _plain_forward(x, offset, d_pos, d_neg, dhat_pos, dhat_neg, omega, h_pos, h_neg, y0, out):
    # the forward recursion from the kernel's one-sample functions run as plain Python (the
    # streaming compensator's path)
    y = y0
    for i in range(x.shape[0]):
        u = x[i] - offset
        lo, hi = kernel.envelopes_py(u - dhat_pos, u - d_pos, u - d_neg, u - dhat_neg, omega, h_pos, h_neg)
        y = out[i] = kernel.clamp_py(y, lo, hi)
    return y


def _plain_inverse(r, offset, d_pos, d_neg, dhat_pos, dhat_neg, omega, h_pos, h_neg, y0, x0, out):
    y, x = y0, x0
    for i in range(r.shape[0]):
        x = out[i] = kernel.inverse_step_py(r[i], y, x, d_pos, dhat_pos, d_neg, dhat_neg, omega, h_pos, h_neg,
                                            offset, False)
        y = r[i] if r[i] != y else y
    return y


@settings(max_examples=100, deadline=None)
@given(knob=valid_knobs(), seed=st.integers(0, 2**32 - 1), y0=st.floats(-10, 10))
def test_compiled_kernels_agree_with_the_plain_python_ones(knob, seed, y0):
    rng = np.random.default_rng(seed)
    x = np.cumsum(rng.normal(0, 4, 200))
    args = knob._kernel_args()
    for compiled_fn, plain_fn, data, extra in (
            (kernel.forward, _plain_forward, x, (y0,)),
            (kernel.inverse, _plain_inverse, x, (y0, knob.holding_knob_angle(y0)))):
        compiled, plain = np.empty_like(data), np.empty_like(data)
        last_c = compiled_fn(data, *args, *extra, compiled)
        last_p = plain_fn(data, *args, *extra, plain)
        # same operations in the same order: bit for bit, not approximately
        assert np.array_equal(compiled, plain) and last_c == last_p


def test_a_model_whose_backlash_its_sweep_left_unfixed_refuses_to_predict_or_compensate():
    from hystcli.diagnosis import diagnose
    from hystcli.estimate import Estimate
    from hystcli.core.run import Run
    from hystcli.core.params import KnobIdentification
    from hystcli.stream import Compensator

    # a current-only identification whose current unloads at once after each reversal keeps
    # b_neg as 0 deg, not fixed: every use of the loop on the tip refuses it, naming the knob
    unshown = Estimate(0.0, 0.0, math.inf, fixed=False, reason="the current does not show it")
    ident = KnobIdentification(-40.0, 40.0, method="current", estimates={"b_neg": unshown})
    knob = KnobModel(9.1, -8.7, 6.0, 0.0, 1.45, -4.0, 4.0)
    model = Model({1: knob, 2: knob}, identification={1: ident})
    t = np.arange(0.0, 1.0, 0.01)
    run = Run({"t": t, "q1": 10 * np.sin(t), "y1": np.zeros_like(t), "r1": np.sin(t)})
    with pytest.raises(ModelError, match="cannot predict the tip .*knob 1's b_neg was not fixed by its sweep"):
        model.predict(run)
    with pytest.raises(ModelError, match="cannot compensate .*knob 1's b_neg"):
        model.compensate(run)
    with pytest.raises(ModelError, match="cannot compensate .*knob 1's b_neg"):
        Compensator(model, knobs=[1], dt=0.01)
    with pytest.raises(ModelError, match="cannot diagnose .*knob 1's b_neg"):
        diagnose(model, [run, run])
    # knob 2's loop is whole: it predicts and compensates as before
    run2 = Run({"t": t, "q2": 10 * np.sin(t), "r2": np.sin(t)})
    assert np.array_equal(model.predict(run2)["y2"], knob.forward(run2["q2"]))
    Compensator(model, knobs=[2], dt=0.01)
    # a tip identification's unfixed backlash is a value that predicts its record as well as the
    # best fit: it is used, not refused
    tip = Model({1: knob}, identification={1: KnobIdentification(-40.0, 40.0, method="tip",
                                                                  estimates={"b_neg": unshown})})
    assert np.array_equal(tip.predict(run)["y1"], knob.forward(run["q1"], 0.0))
