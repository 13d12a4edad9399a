"""The effect chain (hystcli/core/effects/chain.py): every form of every effect is the base model bit for
bit when off, its inverse undoes its forward, the chain gives the same samples in pieces as in one
call (the streaming path), and Model.predict / Model.compensate are what the CLI writes."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

import hystcli
from hystcli.core import effects as E
from hystcli.sim import twin
from hystcli.cli import app
from hystcli.core.run import Run
from hystcli.io import read_run, save_model, write_run
from hystcli.core.model import Model
from hystcli.core.params import Shape

CAT = twin.get_catheter("example-a")
T = np.arange(0, 30.0, 0.01)
Q = {1: 40 * np.sin(2 * np.pi * 0.05 * T) + 10 * np.sin(2 * np.pi * 0.13 * T),
     2: 30 * np.sin(2 * np.pi * 0.08 * T + 0.5)}
BENT = Shape.parse("alpha=90,theta=30;alpha=40,theta=200")
FORMS = [(n, f.name) for n, et in E.EFFECTS.items() for f in et.forms]

# switched-on parameters per form that keep every reference below reach of a limit or a wall
ON = {("saturation", "smooth"): {"limit": 400.0}, ("saturation", "hard"): {"limit": 400.0},
      ("saturation", "asymmetric"): {"limit": 400.0, "ratio": 1.5}, ("contact", "wall"): {"wall": 300.0},
      ("saturation", "smooth-knobs"): {"limit": 400.0, "knob2": 0.8},
      ("saturation", "hard-knobs"): {"limit": 400.0, "knob2": 0.8},
      ("saturation", "knee"): {"limit": 400.0, "slope": 0.5},
      ("stretch", "stiffening"): {"compliance": 3.0, "reference": 10.0, "stiffening": 1.0},
      ("friction", "capstan"): {"mu": 0.2}, ("friction", "backlash"): {"mu": 0.2}, ("friction", "slope"): {"mu": 0.2},
      ("deadzone", "width"): {"width": 2.0}, ("deadzone", "centre"): {"shift": 1.5}}


def _on(name: str, form: str) -> E.Effect:
    return E.make_effect(name, form, **ON.get((name, form), {}))


def _model(*effects: E.Effect) -> Model:
    return Model(CAT.knobs, CAT.geometry, effects=tuple(e.spec() for e in effects))


@pytest.mark.parametrize("name, form", FORMS)
def test_every_form_off_is_the_base_model_bit_for_bit(name, form):
    f = E.EFFECTS[name].get_form(form)
    eff = E.make_effect(name, form, **f.null_params())
    assert eff.is_null
    run = Run({"t": T, "q1": Q[1], "q2": Q[2], "y1": np.full_like(T, 2.0)}, {"shape": str(BENT)})
    base = E.predict(Model(CAT.knobs, CAT.geometry), run)
    null = E.predict(_model(eff), run)
    for k in (1, 2):
        assert np.array_equal(null[k], base[k])
    sim = twin.simulate(CAT, T, Q, shape=BENT, effects=(eff,), noise=False)
    plain = twin.simulate(CAT, T, Q, shape=BENT, effects=(), noise=False)
    for k in (1, 2):
        assert np.array_equal(sim[f"y{k}"], plain[f"y{k}"])


@pytest.mark.parametrize("name, form", FORMS)
def test_every_form_switched_on_changes_the_prediction(name, form):
    eff = _on(name, form)
    if name == "contact":
        eff = E.make_effect("contact", wall=20.0)
    if name == "saturation":
        eff = E.make_effect(name, form, **{**ON[(name, form)], "limit": 40.0})
    run = Run({"t": T, "q1": Q[1], "q2": Q[2]}, {"shape": str(BENT), "condition": "60"})
    base = E.predict(Model(CAT.knobs, CAT.geometry), run)
    on = E.predict(_model(eff), run)
    assert max(float(np.max(np.abs(on[k] - base[k]))) for k in (1, 2)) > 0.1


INVERTIBLE = [(n, f) for n, f in FORMS if n not in ("rate", "latency") and not f.startswith("output")] + [
    ("coupling", "output-magnitude")]  # its drive, the other bend, holds where the other's command jumps


@pytest.mark.parametrize("name, form", INVERTIBLE)
def test_forward_of_inverse_is_the_identity_for_every_form(name, form):
    eff = _on(name, form)
    model = _model(eff)
    traj = Run({"t": T, "r1": Q[1], "r2": Q[2]}, {"shape": str(BENT), "condition": "60"})
    inv = E.inverse(model, traj)
    assert inv.warnings == ()
    ys = E.predict(model, Run({"t": T, **{f"q{k}": inv.q[k] for k in (1, 2)}}, traj.meta))
    # a coupling is solved by fixed-point iteration to 1e-10 deg; every other stage exactly
    for k in (1, 2):
        assert np.max(np.abs(ys[k] - Q[k])) < 1e-6


@pytest.mark.parametrize("form", ["output", "output2"])
def test_an_output_lag_is_undone_exactly_once_its_start_has_passed(form):
    model = _model(E.make_effect("rate", form, tau=0.2))
    traj = Run({"t": T, "r1": Q[1]}, {"shape": "straight"})
    q = E.inverse(model, traj).q[1]
    y = E.predict(model, Run({"t": T, "q1": q}, traj.meta))[1]
    # the second order's start from rest needs more than the 30 deg of lead: a transient of
    # about 25 tau; afterwards exact
    assert np.max(np.abs(y - Q[1])[T > 8.0]) < 1e-6


def test_an_input_lag_is_undone_but_where_a_command_jump_needs_more_lead():
    model = _model(E.make_effect("rate", "input", tau=0.2))
    traj = Run({"t": T, "r1": Q[1]}, {"shape": "straight"})
    q = E.inverse(model, traj).q[1]
    y = E.predict(model, Run({"t": T, "q1": q}, traj.meta))[1]
    err = np.abs(y - Q[1])
    # the hysteresis inverse jumps across the dead zone at each reversal; the lead is limited to
    # 30 deg, so the tip catches up over a few tau there, and is exact elsewhere
    assert np.mean(err > 1e-6) < 0.1
    assert np.sqrt(np.mean(err ** 2)) < 0.3


def test_a_second_order_input_lag_is_compensated_better_than_ignored():
    # the exact inverse of two lags after the hysteresis inverse's jumps rings (the discrete
    # inverse has a pole near -1) and hits the lead limit: approximate, but far better than none
    model = _model(E.make_effect("rate", "input2", tau=0.2))
    traj = Run({"t": T, "r1": Q[1]}, {"shape": "straight"})
    rms = []
    for m in (model, Model(CAT.knobs, CAT.geometry)):
        q = E.inverse(m, traj).q[1]
        y = E.predict(model, Run({"t": T, "q1": q}, traj.meta))[1]
        rms.append(float(np.sqrt(np.mean((y - Q[1]) ** 2))))
    assert rms[0] < 0.5 * rms[1]


@pytest.mark.parametrize("form", ["output", "output-magnitude"])
def test_an_output_coupling_is_undone_to_a_fraction_of_a_degree_and_says_so(form):
    model = _model(E.make_effect("coupling", form, gain=0.15))
    traj = Run({"t": T, "r1": Q[1], "r2": Q[2]}, {"shape": str(BENT)})
    inv = E.inverse(model, traj)
    ys = E.predict(model, Run({"t": T, **{f"q{k}": inv.q[k] for k in (1, 2)}}, traj.meta))
    plain = E.predict(model, Run({"t": T, **{f"q{k}": E.inverse(Model(CAT.knobs, CAT.geometry), traj).q[k]
                                               for k in (1, 2)}}, traj.meta))
    for k in (1, 2):
        rmse = float(np.sqrt(np.mean((ys[k] - Q[k]) ** 2)))
        assert rmse < 0.3 < float(np.sqrt(np.mean((plain[k] - Q[k]) ** 2)))
    assert all("did not converge" in w for w in inv.warnings)


MAGNITUDE = ["input-magnitude", "output-magnitude", "deadzone-magnitude"]


@pytest.mark.parametrize("form", MAGNITUDE)
def test_a_knob_resting_in_its_dead_zone_drives_no_magnitude_coupling(form):
    # a bent one-knob run: knob 2 rests at 0, inside its dead zone, with the shift's offset on it;
    # its section does not bend, so nothing moves knob 1's loop (its travel from the offset did)
    model = Model(CAT.knobs, CAT.geometry)
    run = Run({"t": T, "q1": Q[1], "q2": np.zeros_like(T)}, {"shape": str(BENT)})
    o2 = model.offsets_for(run.meta)[2]
    assert 1.0 < abs(o2) and CAT.knobs[2].d_neg < -o2 < CAT.knobs[2].d_pos
    assert np.all(CAT.knobs[2].with_offset(o2).forward(run["q2"]) == 0.0)
    eff = E.make_effect("coupling", form, gain=0.3)
    base = E.predict(model, run)
    on = E.predict(_model(eff), run)
    assert np.array_equal(on[1], base[1])
    # the twin's own data the same
    sim = twin.simulate(CAT, T, {1: Q[1], 2: run["q2"]}, shape=BENT, effects=(eff,), noise=False)
    plain = twin.simulate(CAT, T, {1: Q[1], 2: run["q2"]}, shape=BENT, effects=(), noise=False)
    assert np.array_equal(sim["y1"], plain["y1"])


@pytest.mark.parametrize("form", MAGNITUDE)
def test_the_magnitude_drive_is_the_other_sections_bend(form):
    # D = |yhat_o|: the other knob's base model (with its offset) on its command, from its first
    # reading; on its backlash plateaus after a reversal the drive holds while the command moves
    g = 0.2
    run = Run({"t": T, "q1": Q[1], "q2": Q[2], "y1": np.full_like(T, 1.0), "y2": np.full_like(T, -2.0)},
              {"shape": str(BENT)})
    model = Model(CAT.knobs, CAT.geometry)
    offs = model.offsets_for(run.meta)
    kn = {k: CAT.knobs[k].with_offset(offs[k]) for k in (1, 2)}
    bend = kn[2].forward(Q[2], -2.0)
    plateau = np.r_[False, np.diff(bend) == 0.0] & np.r_[False, np.diff(Q[2]) != 0.0]
    assert plateau.sum() > 50  # the drive holds there while |q2 - offset2| moves
    on = E.predict(_model(E.make_effect("coupling", form, gain=g)), run)[1]
    if form == "input-magnitude":
        want = kn[1].forward(Q[1] - g * np.abs(bend), 1.0)
    elif form == "output-magnitude":
        want = E.tip_chain(kn[1], 1, Q, T, (), BENT, 1.0 - g * abs(bend[0])).y + g * np.abs(bend)
    else:
        # the edges move by half the drive each way
        sig = E.Signals(1, T, Q[2], offs[2], 1.0, "run", bend)
        dp, dn = E.EFFECTS["coupling"].edges(E.make_effect("coupling", form, gain=g), T.size, sig)
        assert np.array_equal(dp, 0.5 * g * np.abs(bend)) and np.array_equal(dn, -dp)
        want = E.tip_chain(kn[1], 1, Q, T, (E.make_effect("coupling", form, gain=g),), BENT, 1.0,
                           other_knob=kn[2], other_y0=-2.0).y
    np.testing.assert_allclose(on, want, rtol=0, atol=1e-12)


@settings(max_examples=15, deadline=None)
@given(st.sampled_from(MAGNITUDE), st.lists(st.integers(1, len(T) - 1), min_size=1, max_size=5, unique=True))
def test_the_bend_drive_in_pieces_gives_the_samples_of_one_call(form, cuts):
    # the live twin: the other section's bend carried in the ChainState across pieces
    effs = (E.make_effect("coupling", form, gain=0.2),)
    kn = {k: CAT.knobs[k].with_offset(o) for k, o in zip((1, 2), CAT.true_offsets(BENT).values())}
    bounds = [0, *sorted(cuts), len(T)]
    for k in (1, 2):
        whole = E.tip_chain(kn[k], k, Q, T, effs, BENT, 0.0, other_knob=kn[3 - k], other_y0=1.5).y
        state = E.ChainState()
        parts = [E.tip_chain(kn[k], k, {j: Q[j][a:b] for j in (1, 2)}, T[a:b], effs, BENT, 0.0, state,
                             other_knob=kn[3 - k], other_y0=1.5).y
                 for a, b in zip(bounds[:-1], bounds[1:]) if b > a]
        assert np.array_equal(np.concatenate(parts), whole)


@settings(max_examples=20, deadline=None)
@given(st.sampled_from(MAGNITUDE), st.floats(-0.4, 0.4), st.floats(-15.0, 15.0), st.floats(-15.0, 15.0))
def test_forward_of_inverse_is_the_identity_for_the_magnitude_drive(form, gain, o1, o2):
    # compensation solves both knobs by fixed point, the other bend from the other's last commands
    model = _model(E.make_effect("coupling", form, gain=gain))
    meta = {"shape": str(BENT), "offset1": str(o1), "offset2": str(o2)}
    traj = Run({"t": T, "r1": Q[1], "r2": Q[2]}, meta)
    inv = E.inverse(model, traj)
    assert inv.warnings == ()
    ys = E.predict(model, Run({"t": T, **{f"q{k}": inv.q[k] for k in (1, 2)}}, meta))
    for k in (1, 2):
        assert np.max(np.abs(ys[k] - Q[k])) < 1e-6


@settings(max_examples=25, deadline=None)
@given(st.lists(st.sampled_from(FORMS), min_size=1, max_size=4, unique_by=lambda nf: nf[0]),
       st.lists(st.integers(1, len(T) - 1), min_size=1, max_size=5, unique=True))
def test_the_chain_in_pieces_gives_the_samples_of_one_call(forms, cuts):
    # the streaming path: a ChainState carried across pieces, down to single samples
    effs = tuple(_on(n, f) for n, f in forms)
    kn = {k: CAT.knobs[k].with_offset(o) for k, o in zip((1, 2), CAT.true_offsets(BENT).values())}
    bounds = [0, *sorted(cuts), len(T)]
    for k in (1, 2):
        whole = E.tip_chain(kn[k], k, Q, T, effs, BENT, 0.0, condition=60.0, other_offset=kn[3 - k].offset).y
        state = E.ChainState()
        parts = [E.tip_chain(kn[k], k, {j: Q[j][a:b] for j in (1, 2)}, T[a:b], effs, BENT, 0.0, state,
                             condition=60.0, other_offset=kn[3 - k].offset).y
                 for a, b in zip(bounds[:-1], bounds[1:]) if b > a]
        assert np.array_equal(np.concatenate(parts), whole)


@pytest.mark.parametrize("kind", ["rate", "creep"])
def test_inverse_stages_in_single_samples_equal_the_batch(kind):
    # what a streaming compensator does: one sample in, one out, the stage's state carried
    eff = E.make_effect("rate", "input", tau=0.3) if kind == "rate" else E.make_effect("creep", fraction=0.3, tau=2.0)
    sig = E.Signals(1, T)
    opts = {"max_lead": 30.0}
    batch = eff.type.inverse(eff, Q[1], sig, eff.type.new_inverse_state(eff), [], opts)
    state = eff.type.new_inverse_state(eff)
    single = np.concatenate([eff.type.inverse(eff, Q[1][i:i + 1], E.Signals(1, T[i:i + 1]), state, [], opts)
                             for i in range(200)])
    assert np.allclose(single, batch[:200], rtol=0, atol=1e-9)


def test_stages_run_in_a_fixed_order_whatever_the_listing():
    a = (E.make_effect("creep"), E.make_effect("rate"), E.make_effect("saturation", limit=60.0),
         E.make_effect("coupling", "output", gain=0.1), E.make_effect("friction"))
    plan = E.Plan.of(a)
    assert [e.name for e in plan.input] == ["rate"]
    assert [e.name for e in plan.output] == ["saturation", "creep", "coupling"]
    run = Run({"t": T, "q1": Q[1], "q2": Q[2]}, {"shape": str(BENT)})
    assert np.array_equal(E.predict(_model(*a), run)[1], E.predict(_model(*reversed(a)), run)[1])


# --------------------------------------------------------------------------------------------
# the Python surface matches the command line byte for byte
# --------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("api")
    model = _model(E.make_effect("creep", fraction=0.2, tau=3.0), E.make_effect("coupling", "deadzone-magnitude",
                                                                                 gain=0.1))
    save_model(d / "model.json", model)
    run = twin.simulate(CAT, T, Q, shape=BENT, seed=3)
    write_run(d / "run.csv", run)
    write_run(d / "ref.csv", Run({"t": T, "r1": Q[1], "r2": Q[2]}, {"shape": str(BENT)}))
    return d


def test_load_model_predict_is_what_hyst_predict_writes(files, tmp_path):
    d = files
    res = CliRunner().invoke(app, ["predict", str(d / "run.csv"), "--model", str(d / "model.json"),
                                   "-o", str(tmp_path / "cli.csv")])
    assert res.exit_code == 0, res.output
    m = hystcli.load_model(d / "model.json")
    assert [(e.name, e.form) for e in m.effects] == [("creep", ""), ("coupling", "deadzone-magnitude")]
    hystcli.write_run(tmp_path / "api.csv", m.predict(hystcli.read_run(d / "run.csv")))
    assert (tmp_path / "api.csv").read_bytes() == (tmp_path / "cli.csv").read_bytes()


def test_model_compensate_is_what_hyst_compensate_writes(files, tmp_path):
    d = files
    res = CliRunner().invoke(app, ["compensate", str(d / "ref.csv"), "--model", str(d / "model.json"),
                                   "-o", str(tmp_path / "cli.csv"), "--allow-fast"])
    assert res.exit_code == 0, res.output
    m = hystcli.load_model(d / "model.json")
    hystcli.write_run(tmp_path / "api.csv", m.compensate(read_run(d / "ref.csv")).run)
    assert (tmp_path / "api.csv").read_bytes() == (tmp_path / "cli.csv").read_bytes()


def test_knob_model_is_the_no_effect_case():
    m = Model(CAT.knobs, CAT.geometry)
    run = Run({"t": T, "q1": Q[1], "y1": np.full_like(T, 1.5)}, {"offset1": "4.0"})
    assert np.array_equal(m.predict(run)["y1"], m.knob(1).with_offset(4.0).forward(Q[1], 1.5))
    ref = Run({"t": T, "r1": Q[1]}, {"offset1": "4.0"})
    assert np.array_equal(m.compensate(ref).run["q1"], m.knob(1).with_offset(4.0).inverse(Q[1]))
    assert math.isfinite(float(m.compensate(ref).run.meta["offset1"]))


def test_shape_effects_read_the_curvature_beside_a_stated_load():
    # friction grows along the bent sheath, not with a tip load: with the shape stated, the run's
    # condition (a load) does not drive it; without one (a tool whose runs state only the load) it does
    m = _model(E.make_effect("friction", mu=0.4), E.make_effect("stretch", compliance=3.0, reference=0.0))
    straight = Run({"t": T, "q1": Q[1]}, {"shape": "straight", "condition": "40"})
    bent = Run({"t": T, "q1": Q[1]}, {"shape": "alpha=90,theta=0", "condition": "40"})
    unstated = Run({"t": T, "q1": Q[1]}, {"condition": "40"})
    only_stretch = _model(E.make_effect("stretch", compliance=3.0, reference=0.0))
    # straight shaft, load 40: the stretch acts, the friction does not
    assert np.array_equal(m.predict(straight)["y1"], only_stretch.predict(straight)["y1"])
    # bent: the friction acts on top
    assert not np.allclose(m.predict(bent)["y1"], only_stretch.predict(bent)["y1"])
    # no shape stated: the load drives both, as before
    assert not np.allclose(m.predict(unstated)["y1"], only_stretch.predict(unstated)["y1"])


def test_stretch_slack_widens_the_dead_zone_with_the_load():
    kn = CAT.knobs[1]
    e = E.make_effect("stretch", "slack", compliance=4.0, reference=20.0)
    at = E.condition_knob(kn, [e], Shape(), condition=20.0 + math.degrees(1.0))   # 1 rad above the reference
    assert at.d_pos == pytest.approx(kn.d_pos + 2.0) and at.d_neg == pytest.approx(kn.d_neg - 2.0)
    assert (at.h_pos, at.h_neg, at.b_pos, at.b_neg) == (kn.h_pos, kn.h_neg, kn.b_pos, kn.b_neg)
    assert E.condition_knob(kn, [e], Shape(), condition=20.0) is kn   # at the reference: the base model
