"""`hyst diagnose` core (issue 5): a withheld effect is named and fitted on held-out runs, an
effect-free data set is reported as such, the loop phases are the paper's lines, the inverse with
effects undoes the forward chain, and compensation with the diagnosed effects tracks better."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hystcli import compensation
from hystcli.core import effects as E
from hystcli.sim import twin
from hystcli.diagnosis import MIN_GAIN_PCT, PHASES, diagnose
from hystcli.diagnosis.where import _phase
from hystcli.errors import DataError, ModelError
from hystcli.core.run import Run
from hystcli.core.model import Model
from hystcli.core.params import KnobModel, Shape

CAT = twin.get_catheter("example-a")
BASE = Model(CAT.knobs, CAT.geometry, meta={"catheter": "example-a"})
FS = 50.0
T = np.arange(0, 40.0 + 1e-9, 1 / FS)


def _reference(kind: str) -> dict[int, np.ndarray]:
    if kind == "periodic":
        return {1: 50.0 * np.sin(2 * np.pi * 0.05 * T)}
    # two incommensurate sines per knob, knob 2 twice as fast (the paper's 2-DoF motion, shorter)
    return {k: 25.0 * (np.sin(2 * np.pi * 0.05 * k * T) + np.sin(2 * np.pi * 0.05 * math.sqrt(3) * k * T))
            for k in (1, 2)}


def make_runs(effects=(), seed=0, catheter=CAT, two_dof=1):
    """Four short runs: sine straight / alpha=90, a 2-DoF motion, a compensated sine (command
    jumps); ``two_dof=2`` adds a second 2-DoF run."""
    base = Model(catheter.knobs, catheter.geometry)
    plan = [("periodic", "straight", False), ("periodic", "alpha=90,theta=0", False),
            ("nonperiodic", "alpha=45,theta=0;alpha=45,theta=90", False), ("periodic", "alpha=45,theta=0", True)]
    plan += [("nonperiodic", "alpha=90,theta=0", False)] * (two_dof - 1)
    runs = []
    for i, (motion, shape, comp) in enumerate(plan):
        r = _reference(motion)
        q = r
        if comp:
            traj = Run({"t": T, **{f"r{k}": v for k, v in r.items()}}, {"shape": shape})
            cr = compensation.compensate(base, traj).run
            q = {k: cr[f"q{k}"] for k in r}
        runs.append(twin.simulate(catheter, T, q, shape=Shape.parse(shape), effects=tuple(effects),
                                  seed=seed * 10 + i, meta={"motion": motion, "trial": i + 1,
                                                            "controller": "comp+shift" if comp else "none"}))
    return runs


# --------------------------------------------------------------------------------------------
# which / how far
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("effect, check", [
    (E.make_effect("latency", delay=0.3), ("delay", 0.3, 0.03)),
    (E.make_effect("creep", fraction=0.25, tau=3.0), ("fraction", 0.25, 0.05)),
])
def test_a_withheld_effect_is_named_fitted_and_shrinks_the_heldout_error(effect, check):
    d = diagnose(BASE, make_runs([effect], seed=1))
    assert d.ranking[0].name == effect.name
    assert [s.name for s in d.selected][:1] == [effect.name]
    param, true, tol = check
    assert abs(d.selected[0].params[param] - true) < tol
    assert d.how_far.rmse_shrink_pct > 50.0
    assert d.how_far.rmse_after < d.how_far.rmse_before
    # the augmented model carries it, after the model's own (none here)
    assert [e.name for e in d.model.effects][:1] == [effect.name]
    assert d.holdout.startswith("leave-one-run-out (4 folds)")
    # the summary: the verdict, then the effect added with its fitted value
    lines = d.summary().splitlines()
    assert lines[0] == d.verdict and lines[1].startswith(f"added {effect.name}") and f"{param} = " in lines[1]


def test_effect_free_data_reports_no_effect_and_describes_the_residual():
    d = diagnose(BASE, make_runs((), seed=2))
    assert d.selected == ()
    assert d.model.effects == ()
    assert d.rounds[0].chosen is None
    assert all(c.gain_pct < MIN_GAIN_PCT for c in d.rounds[0].candidates)
    assert "No candidate effect explains the gap" in d.verdict
    # filtered EM noise (0.3 deg rms before a 20 Hz filter at 50 Hz sampling): what remains is
    # about that, and white at 1 s
    assert d.residual.rmse < 0.35
    assert abs(d.residual.autocorr_1s) < 0.2
    assert d.how_far.rmse_shrink_pct == 0.0
    assert d.summary() == f"{d.verdict}\nno effect added"


def test_the_figure_draws_small_shares_small():
    # effect-free runs: what the residual follows explains a few percent at most; on the figure's
    # 0-100 % axis such a bar stays a sliver, labelled with its value
    from matplotlib.figure import Figure

    import hystcli

    runs = make_runs((), seed=2)
    d = diagnose(BASE, runs)
    fig = d.plot(runs)
    assert isinstance(fig, Figure) and len(fig.axes) == 4
    # the estimator object holds diagnose's options and calls it: the same diagnosis
    assert hystcli.Diagnoser().diagnose(BASE, runs) == d
    shares, speeds, follows = fig.axes[:3]
    assert shares.get_ylim() == speeds.get_ylim() == (0.0, 100.0)
    assert follows.get_xlim() == (0.0, 100.0)
    widths = [p.get_width() for p in follows.patches]
    assert widths and max(widths) < 10.0
    assert [t.get_text() for t in follows.texts] == [f"{a.explained_pct:.1f} %" for a in d.where.follows]


def _load_runs(loads, stretch, seed=0):
    """Sine runs of knob 1 at the given load conditions (metadata ``condition``), tip from the
    model with ``stretch`` plus 0.2 deg of seeded noise."""
    rng = np.random.default_rng(seed)
    truth = Model(CAT.knobs, CAT.geometry, effects=(stretch.spec(),))
    runs = []
    for i, load in enumerate(loads):
        run = Run({"t": T, "q1": _reference("periodic")[1]}, {"condition": f"{load:g}", "catheter": "example-a",
                                                            "trial": str(i + 1)}, f"load{load:g}")
        y = E.predict(truth, run)[1] + rng.normal(0.0, 0.2, T.size)
        runs.append(Run({**run.columns, "y1": y}, run.meta, run.source))
    return runs


def test_a_load_stretch_is_named_with_the_load_the_model_holds_at():
    # the base model holds at 40 % (reference): the runs at 10 and 80 % sit lower and higher
    truth = E.make_effect("stretch", compliance=4.0, reference=40.0)
    d = diagnose(BASE, _load_runs((10.0, 40.0, 80.0), truth, seed=4), max_effects=1)
    assert [s.name for s in d.selected] == ["stretch"]
    fit = d.selected[0].params
    assert abs(fit["compliance"] - 4.0) < 0.2 and abs(fit["reference"] - 40.0) < 3.0
    # 4 deg/rad * 30 deg = 2.1 deg at 10 %, 2.8 deg at 80 %: the held-out error falls to the noise
    assert d.how_far.rmse_before > 1.5 and d.how_far.rmse_after < 0.4


def test_stretch_is_a_default_candidate_only_when_a_run_states_a_condition():
    runs = make_runs((), seed=2)[:2]  # catheter runs: their condition is the shape
    d = diagnose(BASE, runs, max_effects=1)
    assert "stretch" not in {c.name for c in d.rounds[0].candidates}
    d = diagnose(BASE, runs, candidates=["stretch"], max_effects=1)  # asked for: tried
    assert [c.name for c in d.rounds[0].candidates] == ["stretch"]
    stated = [runs[0].with_meta(condition="30"), runs[1]]
    assert "stretch" in {c.name for c in diagnose(BASE, stated, max_effects=1).rounds[0].candidates}


def test_latency_residual_sits_where_the_tip_moves_not_on_the_plateaus():
    # a delay changes the tip only where it moves: the backlash plateau and the dead zone (tip
    # held, paper lines L1/L5, L3/L7) carry less than their share of the residual energy
    d = diagnose(BASE, make_runs([E.make_effect("latency", delay=0.4)], seed=3), max_effects=1)
    phase = {g.level: g for g in d.where.factor("phase")}
    held = [phase[p] for p in ("backlash plateau", "dead zone") if p in phase]
    assert sum(g.energy_share for g in held) < 0.5 * sum(g.sample_share for g in held)
    assert sum(g.sample_share for g in d.where.factor("phase")) == pytest.approx(1.0)
    assert sum(g.energy_share for g in d.where.factor("phase")) == pytest.approx(1.0)
    assert d.where.finding.startswith("The residual (RMSE")


def test_coupling_is_not_claimed_from_a_single_two_knob_run():
    # with one 2-DoF run, held out it is the only run coupling acts on, and its training folds
    # cannot see the gain: no held-out evidence, so no claim
    d = diagnose(BASE, make_runs([E.make_effect("coupling", gain=0.2)], seed=4), max_effects=1)
    assert d.selected == ()
    other = {g.level: g for g in d.where.factor("other knob")}
    # only the 2-DoF run has a moving other knob; all of the coupling error is there
    assert other["moving"].energy_share > 0.9
    assert "other knob" in d.where.finding


def test_coupling_shows_up_when_the_other_knob_moves():
    d = diagnose(BASE, make_runs([E.make_effect("coupling", gain=0.2)], seed=4, two_dof=2), max_effects=1)
    other = {g.level: g for g in d.where.factor("other knob")}
    assert other["moving"].energy_share > 0.9
    assert d.ranking[0].name == "coupling"
    assert abs(d.selected[0].params["gain"] - 0.2) < 0.03


def test_holdout_by_metadata_and_bootstrap():
    runs = make_runs([E.make_effect("latency", delay=0.25)], seed=5)
    d = diagnose(BASE, runs, holdout="motion=nonperiodic", bootstrap=4, seed=1, max_effects=1)
    assert d.holdout.startswith("motion=nonperiodic (1 test run(s), 3 training)")
    assert [f.run for f in d.how_far.per_run] == ["run 3", "run 3"]  # both knobs of the 2-DoF run
    s = d.selected[0]
    assert s.name == "latency" and s.inclusion == 1.0
    lo, hi = s.interval["delay"]
    assert lo - 0.02 <= 0.25 <= hi + 0.02
    rep = d.report()
    assert rep["which"]["selected"][0]["inclusion"] == 1.0
    # the same seed gives the same report
    assert diagnose(BASE, runs, holdout="motion=nonperiodic", bootstrap=4, seed=1, max_effects=1).report() == rep


def test_candidates_can_be_restricted():
    d = diagnose(BASE, make_runs([E.make_effect("latency", delay=0.3)], seed=6), candidates=["creep", "friction"])
    assert {c.name for c in d.rounds[0].candidates} == {"creep", "friction"}


# --------------------------------------------------------------------------------------------
# bad input
# --------------------------------------------------------------------------------------------
def test_bad_inputs_raise_typed_errors_naming_the_problem():
    runs = make_runs((), seed=7)
    with pytest.raises(DataError, match="at least 2 runs"):
        diagnose(BASE, runs[:1])
    no_y = Run({c: v for c, v in runs[0].columns.items() if c != "y1"}, runs[0].meta, "a.csv")
    with pytest.raises(DataError, match="a.csv: no measured tip angle y1"):
        diagnose(BASE, [no_y, runs[1]])
    other = make_runs((), seed=7, catheter=twin.get_catheter("example-b"))
    with pytest.raises(DataError, match="different catheters"):
        diagnose(BASE, [runs[0], other[1]])
    with pytest.raises(ModelError, match="no knob 2"):
        diagnose(Model({1: CAT.knobs[1]}, CAT.geometry), runs)
    with pytest.raises(DataError, match="no run has metadata motion"):
        diagnose(BASE, runs, holdout="motion=spiral")
    with pytest.raises(DataError, match="every run matches"):
        diagnose(BASE, runs, holdout="catheter=example-a")
    with pytest.raises(DataError, match="key=value"):
        diagnose(BASE, runs, holdout="motion")
    with pytest.raises(ModelError, match="unknown candidate effect 'wobble'"):
        diagnose(BASE, runs, candidates=["wobble"])


# --------------------------------------------------------------------------------------------
# the loop phases (hand computed)
# --------------------------------------------------------------------------------------------
def test_phases_are_the_paper_lines_on_a_hand_computed_loop():
    # docs/design.md example knob: dhat_pos = (-4-4.2)/1.45 - 8.7 + 5.9 = -8.455,
    # dhat_neg = (4.2+4)/1.45 + 9.1 - 6.2 = 8.555. From y0 = 0 up to u = 40: y is held at 0 (between
    # the envelopes: backlash plateau) until f_up = 0 at u = 9.1 + 4/1.45 = 11.86, then loading
    # slope; y(40) = -4 + 1.45*30.9 = 40.805. Down from 40: held until f_dn = 40.805 at
    # u = 8.555 + 36.605/1.45 = 33.80 (plateau), unloading slope to 8.555, dead zone to -8.7,
    # then loading slope (negative tendon).
    kn = KnobModel(d_pos=9.1, d_neg=-8.7, b_pos=6.2, b_neg=5.9, omega=1.45, h_pos=-4.0, h_neg=4.2)
    x = np.array([0.0, 5.0, 11.0, 12.5, 40.0, 36.0, 30.0, 9.0, 0.0, -8.0, -9.5, -20.0])
    want = ["backlash plateau", "backlash plateau", "backlash plateau", "loading slope", "loading slope",
            "backlash plateau", "unloading slope", "unloading slope", "dead zone", "dead zone",
            "loading slope", "loading slope"]
    got = [PHASES[i] for i in _phase(kn, x, kn.forward(x, 0.0))]
    assert got == want


# --------------------------------------------------------------------------------------------
# the inverse with effects
# --------------------------------------------------------------------------------------------
TI = np.arange(0, 30.0, 0.01)
RI = {1: 40 * np.sin(2 * np.pi * 0.05 * TI) + 10 * np.sin(2 * np.pi * 0.13 * TI),
      2: 30 * np.sin(2 * np.pi * 0.08 * TI + 0.5)}
EXACT = ["friction", "deadzone", "coupling", "saturation", "creep", "latency"]


@settings(max_examples=25, deadline=None)
@given(st.lists(st.sampled_from(EXACT), unique=True, min_size=1, max_size=3), st.data())
def test_forward_with_effects_undoes_inverse_with_effects(names, data):
    effs = []
    for n in names:
        et = E.EFFECTS[n]
        lo_hi = {"friction": {"mu": (0.0, 0.6)}, "deadzone": {"width": (-2.0, 8.0)},
                 "coupling": {"gain": (-0.4, 0.4)}, "saturation": {"limit": (150.0, 400.0)},
                 "creep": {"fraction": (0.0, 0.6), "tau": (0.2, 30.0)}, "latency": {"delay": (0.0, 1.0)}}[n]
        effs.append(E.make_effect(n, **{p: data.draw(st.floats(*lo_hi[p])) for p in lo_hi}))
    model = Model(CAT.knobs, CAT.geometry, effects=tuple(e.spec() for e in effs))
    traj = Run({"t": TI, "r1": RI[1], "r2": RI[2]}, {"shape": "alpha=90,theta=30"})
    inv = E.inverse(model, traj)
    # limits well above the reference (|r| <= 50 deg, and un-creeping leads it by at most a
    # factor 1/(1 - fraction) = 2.5): nothing to clip
    assert inv.warnings == ()
    ys = E.predict(model, Run({"t": TI, **{f"q{k}": inv.q[k] for k in (1, 2)}}, traj.meta))
    delay = next((e["delay"] for e in effs if e.name == "latency"), 0.0)
    # before the delay the tracker still shows the start; in the last delay seconds the reference
    # beyond the end is unknown (held). A delay between samples is a linear interpolation both
    # ways, each off by at most dt^2/8 * |r''| = (0.01 s)^2/8 * ~11 deg/s^2 = 1.4e-4 deg for RI;
    # otherwise the inverse is exact to float precision
    keep = (TI >= delay + 0.01) & (TI <= TI[-1] - delay)
    tol = 1e-3 if delay > 0 else 1e-6
    for k in (1, 2):
        assert np.max(np.abs(ys[k] - RI[k])[keep]) < tol


def test_rate_inverse_leads_the_lag_up_to_its_limit():
    model = Model(CAT.knobs, CAT.geometry, effects=(E.make_effect("rate", tau=0.3).spec(),))
    traj = Run({"t": TI, "r1": RI[1]}, {"shape": "straight"})
    inv = E.inverse(model, traj)
    ys = E.predict(model, Run({"t": TI, "q1": inv.q[1]}, traj.meta))[1]
    plain = E.predict(model, compensation.compensate(Model(CAT.knobs, CAT.geometry), traj).run)[1]
    # without the lead the tip trails by about tau*speed (0.3 s * up to ~40 deg/s of tip)
    assert np.sqrt(np.mean((plain - RI[1]) ** 2)) > 3.0
    assert np.sqrt(np.mean((ys - RI[1]) ** 2)) < 0.2
    assert np.max(np.abs(inv.q[1] - model.knob(1).inverse(RI[1]))) <= 30.0 + 1e-9  # max_lead


def test_contact_inverse_clips_at_the_wall_with_a_warning():
    model = Model(CAT.knobs, CAT.geometry, effects=(E.make_effect("contact", wall=30.0).spec(),))
    res = compensation.compensate(model, Run({"t": TI, "r1": RI[1]}, {"shape": "straight"}))
    assert any("wall at 30 deg" in w for w in res.warnings)


@pytest.mark.parametrize("effect", [E.make_effect("latency", delay=0.3), E.make_effect("creep", fraction=0.3, tau=3.0)])
def test_compensating_with_the_diagnosed_effect_tracks_the_twin_better(effect):
    d = diagnose(BASE, make_runs([effect], seed=8), max_effects=1)
    assert d.selected and d.selected[0].name == effect.name
    t, r = twin.periodic(fs=50.0)
    shape = Shape.parse("alpha=90,theta=0")
    traj = Run({"t": t, "r1": r}, {"shape": str(shape), "motion": "periodic"})
    errs = []
    for m in (BASE, d.model):
        cmd = compensation.compensate(m, traj).run
        run = twin.simulate_motion(CAT, shape, commands=cmd, effects=[effect], seed=3)
        errs.append(float(np.sqrt(np.mean((run["y1"] - r) ** 2))))
    assert errs[1] < 0.5 * errs[0]


def test_a_compensation_only_run_is_predicted_with_the_shafts_shift():
    # Compensation-Only commands ignore the shift, but the tip still undergoes it: the run must
    # carry the shift in effect (offset1 = the geometry's, paper eqs. 1-4: 1.2/8 * 45 = 6.75 deg
    # on ice-a) so that prediction and diagnosis see the bent shaft, not offset 0
    cat = twin.get_catheter("example-a")
    model = Model(cat.knobs, cat.geometry)
    shape = "alpha=45,theta=0"
    t, r = twin.periodic()
    traj = Run({"t": t, "r1": r}, {"shape": shape, "motion": "periodic"})
    cmd = compensation.compensate(model, traj, ignore_shift=True).run
    assert float(cmd.meta["offset1"]) == pytest.approx(6.75) and cmd.meta["shift_ignored"] == "true"
    run = twin.simulate_motion(cat, Shape.parse(shape), commands=cmd, controller="comp", effects=(),
                               noise=False)
    predicted = E.predict(model, run)[1]
    np.testing.assert_allclose(predicted, run["y1"], atol=1e-6)
    # and the effect-free diagnosis finds nothing to add to it
    runs = [run, twin.simulate_motion(cat, Shape.parse(shape), commands=cmd, controller="comp",
                                      effects=(), seed=1)]
    assert diagnose(model, runs, candidates=["friction", "deadzone"]).selected == ()
