"""The viscous backlash (``rate`` form ``backlash``) and the moving-edge kernels it generalises:
the coupling's dead-zone form keeps its numbers bit for bit, a constant knob speed lengthens the
backlash plateau by ``c_visc * v``, at rest it is the base model, the inverse is exact (for
``c_visc <= SPEED_TAU``) and stable beyond, the streaming compensator gives the batch inverse's
commands, and ``diagnose`` names the form on runs simulated with it."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import hystcli
from hystcli.core import effects as E
from hystcli.sim import twin
from hystcli.core.effects import kernels
from hystcli.core.effects.chain import ChainState, tip_chain
from hystcli.core.run import Run
from hystcli.core.model import Model
from hystcli.core.params import KnobModel

KN = KnobModel(d_pos=5.0, d_neg=-5.0, b_pos=6.0, b_neg=6.0, omega=1.45, h_pos=1.0, h_neg=-1.0)
NONE = np.empty(0)


def _viscous(c: float) -> E.Effect:
    return E.make_effect("rate", "backlash", c_visc=c)


# --------------------------------------------------------------------------------------------
# the kernels: existing callers keep their numbers
# --------------------------------------------------------------------------------------------
def _old_forward(x, args, dp, dn, y0):
    # forward_edges_kernel before the plateau moves (the same IEEE operations, in Python floats)
    offset, d_pos, d_neg, dhat_pos, dhat_neg, omega, h_pos, h_neg = args
    out, y = np.empty_like(x), y0
    for i in range(x.size):
        u = x[i] - offset
        a, b = dn[i], dp[i]
        lo = h_pos + omega * (min(u - dhat_pos - a, 0.0) + max(u - d_pos - b, 0.0))
        hi = h_neg + omega * (min(u - d_neg - a, 0.0) + max(u - dhat_neg - b, 0.0))
        y = min(max(y, lo), hi)
        out[i] = y
    return out


def _old_inverse(r, args, dp, dn, y0, x0):
    offset, d_pos, d_neg, dhat_pos, dhat_neg, omega, h_pos, h_neg = args
    out, y, x = np.empty_like(r), y0, x0
    for i in range(r.size):
        ri, a, b = r[i], dn[i], dp[i]
        if ri > y:
            x = (d_pos + b + (ri - h_pos) / omega + offset if ri > h_pos
                 else dhat_pos + a + (ri - h_pos) / omega + offset)
            y = ri
        elif ri < y:
            x = (d_neg + a + (ri - h_neg) / omega + offset if ri < h_neg
                 else dhat_neg + b + (ri - h_neg) / omega + offset)
            y = ri
        out[i] = x
    return out


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_moving_edge_kernels_keep_the_dead_zone_forms_numbers_bit_for_bit(seed):
    rng = np.random.default_rng(seed)
    n = 2000
    x = np.cumsum(rng.normal(0, 1.0, n))
    half = 0.5 * 0.2 * np.abs(np.cumsum(rng.normal(0, 1.0, n)))
    dp, dn = half, -half
    args = KN.with_offset(1.5)._kernel_args()
    out = np.empty(n)
    kernels.forward_edges_kernel(x, *args, dp, dn, NONE, NONE, 0.3, out)
    assert out.tobytes() == _old_forward(x, args, dp, dn, 0.3).tobytes()
    r = out
    q = np.empty(n)
    kernels.inverse_edges_kernel(r, *args, dp, dn, NONE, NONE, 0.0, 30.0, NONE, kernels.new_speed_state(),
                                 0.3, 2.0, q)
    assert q.tobytes() == _old_inverse(r, args, dp, dn, 0.3, 2.0).tobytes()


def test_plateau_moves_apart_from_the_edges():
    # ep moves dhat_pos only: the ascending slope below the plateau shifts, the edge d_pos stays
    x = np.linspace(-30, 30, 601)
    ep = np.full(x.size, 2.0)
    out = np.empty_like(x)
    kernels.forward_edges_kernel(x, *KN._kernel_args(), NONE, NONE, ep, -ep, -100.0, out)
    base = KN.forward(x, -100.0)
    below = x < KN.dhat_pos
    np.testing.assert_allclose(out[below], np.minimum(base[below] - KN.omega * 2.0, KN.h_pos), atol=1e-12)
    beyond = x > KN.d_pos
    np.testing.assert_array_equal(out[beyond], base[beyond])


# --------------------------------------------------------------------------------------------
# forward
# --------------------------------------------------------------------------------------------
def _ramp_run(v: float, fs: float = 200.0):
    # down to -40 deg at speed v, then up again: the reversal at -40 deg
    t1 = 60.0 / v
    t = np.arange(0.0, 2 * t1, 1.0 / fs)
    q = np.where(t < t1, 20.0 - v * t, -40.0 + v * (t - t1))
    return t, q, t1


@pytest.mark.parametrize("v", [10.0, 25.0])
@pytest.mark.parametrize("c", [0.02, 0.1])
def test_a_constant_speed_lengthens_the_backlash_plateau_by_c_v(v, c):
    t, q, t1 = _ramp_run(v)
    y = tip_chain(KN, 1, {1: q}, t, [_viscous(c)]).y
    base = KN.forward(q)
    rev = int(np.searchsorted(t, t1))

    def leave(yy):
        # knob travel after the reversal until the tip rises off its plateau
        j = rev + int(np.argmax(yy[rev:] > yy[rev] + 1e-9))
        return q[j] - q[rev]

    assert leave(base) == pytest.approx(KN.b_neg, abs=v / 200.0 * 1.01)
    assert leave(y) - leave(base) == pytest.approx(c * v, abs=v / 200.0 * 1.01 + 0.01 * c * v)


def test_at_rest_and_crawling_it_is_the_base_model():
    t = np.arange(0.0, 20.0, 0.01)
    q = np.full(t.size, 12.0)
    np.testing.assert_array_equal(tip_chain(KN, 1, {1: q}, t, [_viscous(0.5)]).y, KN.forward(q))
    v = 0.01
    q = 10.0 * np.sin(v / 10.0 * t)  # at most 0.01 deg/s
    y = tip_chain(KN, 1, {1: q}, t, [_viscous(0.5)]).y
    assert np.max(np.abs(y - KN.forward(q))) <= KN.omega * 0.5 * v * 1.01


@pytest.mark.parametrize("cuts", [[1], [7, 400], [250, 251, 999]])
def test_the_chain_in_pieces_gives_the_samples_of_one_call(cuts):
    t = np.arange(0.0, 12.0, 0.01)
    q = 30.0 * np.sin(t) + 8.0 * np.sin(4.1 * t)
    eff = [_viscous(0.08)]
    whole = tip_chain(KN, 1, {1: q}, t, eff).y
    state = ChainState()
    parts = [tip_chain(KN, 1, {1: q[a:b]}, t[a:b], eff, state=state).y
             for a, b in zip([0] + cuts, cuts + [t.size])]
    np.testing.assert_array_equal(np.concatenate(parts), whole)


# --------------------------------------------------------------------------------------------
# inverse and streaming
# --------------------------------------------------------------------------------------------
def _forward_of_inverse(model: Model, r: np.ndarray, t: np.ndarray):
    inv = E.inverse(model, Run({"t": t, "r1": r}, {}, "ref"))
    return inv, E.predict(model, Run({"t": t, "q1": inv.q[1]}, {}, "cmd"))[1]


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(c=st.floats(0.0, kernels.SPEED_TAU), fs=st.sampled_from([50.0, 200.0, 1000.0]),
       amps=st.lists(st.floats(1.0, 30.0), min_size=2, max_size=2),
       periods=st.lists(st.floats(0.5, 10.0), min_size=2, max_size=2), offset=st.floats(-8.0, 8.0))
def test_forward_of_inverse_is_the_reference(c, fs, amps, periods, offset):
    t = np.arange(0.0, 12.0, 1.0 / fs)
    r = sum(a * np.sin(2 * np.pi * t / p) for a, p in zip(amps, periods))
    model = Model({1: KN.with_offset(offset)}, effects=(_viscous(c).spec(),))
    inv, y = _forward_of_inverse(model, r, t)
    assert not inv.warnings
    np.testing.assert_allclose(y, r, atol=1e-9)


@pytest.mark.parametrize("c", [0.1, 0.3, 3.0])
def test_beyond_speed_tau_the_inverse_is_stable_and_better_than_none(c):
    t = np.arange(0.0, 16.0, 0.01)
    r = 30 * np.sin(2 * np.pi * t / 8) + 5 * np.sin(2 * np.pi * t / 1.3)
    model = Model({1: KN}, effects=(_viscous(c).spec(),))
    inv, y = _forward_of_inverse(model, r, t)
    q0 = Model({1: KN}).knob(1).inverse(r)
    y0 = E.predict(model, Run({"t": t, "q1": q0}, {}, "cmd"))[1]
    assert np.ptp(inv.q[1]) < np.ptp(q0) + 5.0  # no ringing into the lead limit
    assert np.sqrt(np.mean((y - r) ** 2)) < 0.9 * np.sqrt(np.mean((y0 - r) ** 2))


@pytest.mark.parametrize("c", [0.03, 0.3])
def test_streaming_gives_the_batch_inverses_commands(c):
    cat = twin.get_catheter("example-a")
    model = Model(cat.knobs, cat.geometry, effects=(_viscous(c).spec(),))
    ref = hystcli.read_run("sample_data/reference_nonperiodic.csv")
    batch = E.inverse(model, ref, knobs=[1]).q[1]
    comp = hystcli.Compensator(model, knobs=[1])
    q = np.array([comp.step(float(r), float(tt)) for r, tt in zip(ref["r1"], ref.t)])
    np.testing.assert_array_equal(q, batch)
    comp.reset()
    np.testing.assert_array_equal(comp.steps(ref["r1"], ref.t), batch)


def test_streaming_with_a_coupling_gives_the_batch_inverses_commands():
    cat = twin.get_catheter("example-a")
    effs = (_viscous(0.04), E.make_effect("coupling", "deadzone", gain=0.1))
    model = Model(cat.knobs, cat.geometry, effects=tuple(e.spec() for e in effs))
    ref = hystcli.read_run("sample_data/reference_nonperiodic.csv")
    batch = E.inverse(model, ref)
    comp = hystcli.Compensator(model)
    q = np.array([comp.step((float(a), float(b)), float(tt)) for a, b, tt in zip(ref["r1"], ref["r2"], ref.t)])
    np.testing.assert_allclose(q[:, 0], batch.q[1], atol=1e-9)
    np.testing.assert_allclose(q[:, 1], batch.q[2], atol=1e-9)


# --------------------------------------------------------------------------------------------
# diagnose
# --------------------------------------------------------------------------------------------
def test_diagnose_names_the_viscous_backlash():
    from test_diagnose import BASE, make_runs
    from hystcli.diagnosis import diagnose

    d = diagnose(BASE, make_runs([_viscous(0.1)], seed=3), max_effects=1)
    assert [(s.name, s.effect().form) for s in d.selected] == [("rate", "backlash")]
    assert d.selected[0].params["c_visc"] == pytest.approx(0.1, rel=0.3)
    assert d.how_far.rmse_shrink_pct > 50.0
