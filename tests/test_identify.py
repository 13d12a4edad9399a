"""Tests of hystcli.identify: recovery of known parameters (issue 2, Must-show 3), sweep checks,
uncertainties, the levels stored for detect-shift, determinism and the figure.

Synthetic sweeps come from the virtual catheter (hystcli.twin) with the paper's protocol: a
+-40 deg sine, 2 cycles, 40 deg/s peak, 1 kHz, EM noise 0.3 deg rms, current noise, 3rd-order
Butterworth at 20 Hz (twin.simulate with noise=True). The true parameters are drawn at random
(seeded) over many sets, so the tolerances are checked on many loops, not one.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hystcli import twin
from hystcli.errors import DataError, IdentificationError
from hystcli.identify import check_sweep, find_reversals, identify, plot_identification
from hystcli.io import Run
from hystcli.model import PAPER_OMEGA, Geometry, KnobModel, Model

N_SETS = 12


def random_catheter(rng: np.random.Generator, name: str = "random") -> twin.VirtualCatheter:
    """A virtual catheter with random valid parameters on both knobs.

    d_pos in [5, 14], d_neg in [-14, -5], b in [3, 9], omega in [1.2, 1.8]; the dead-zone heights
    are set through dh = (h_neg - h_pos)/omega = mean backlash * U(0.7, 1.3) >= 0 around a random
    centre, which keeps every model valid (the dead zone, >= 10 deg wide, exceeds any b - dh).
    The motor-current parameters are drawn too, so the current signature varies as well.
    """
    knobs = {}
    for k in (1, 2):
        b_pos, b_neg = rng.uniform(3.0, 9.0, 2)
        omega = rng.uniform(1.2, 1.8)
        dh = 0.5 * (b_pos + b_neg) * rng.uniform(0.7, 1.3)
        h_mid = rng.uniform(-1.0, 1.0)
        knobs[k] = KnobModel(d_pos=rng.uniform(5.0, 14.0), d_neg=rng.uniform(-14.0, -5.0),
                             b_pos=b_pos, b_neg=b_neg, omega=omega,
                             h_pos=h_mid - 0.5 * omega * dh, h_neg=h_mid + 0.5 * omega * dh)
    current = twin.CurrentParams(no_load=rng.uniform(80, 160), coulomb=rng.uniform(3, 9),
                                 k_load=rng.uniform(3, 5), mu=rng.uniform(0.15, 0.3),
                                 noise=rng.uniform(2, 4))
    return twin.VirtualCatheter(name, knobs, Geometry(1.2, 8.0), current)


def paper_sweep(cat: twin.VirtualCatheter, seed: int, knobs=(1, 2)) -> Run:
    t, q = twin.sweep()  # +-40 deg, 2 cycles, 40 deg/s, 1 kHz (paper section II-C-2)
    return twin.simulate(cat, t, {k: q for k in knobs}, seed=seed, effects=(), noise=True)


_CASES: dict[int, tuple] = {}


def case(i: int):
    """(catheter, run, tip identification, current-only identification) of random set ``i``."""
    if i not in _CASES:
        cat = random_catheter(np.random.default_rng(1000 + i), f"random-{i}")
        run = paper_sweep(cat, seed=i)
        _CASES[i] = (cat, run, identify(run), identify(run, use_tip=False))
    return _CASES[i]


def sine_sweep(lo: float, hi: float, cycles: float = 2.0, speed: float = 40.0, fs: float = 1000.0):
    """A sine between ``lo`` and ``hi`` starting at the middle going up."""
    amp, mid = 0.5 * (hi - lo), 0.5 * (hi + lo)
    w = speed / amp
    t = np.arange(int(round(cycles * 2 * math.pi / w * fs)) + 1) / fs
    return t, mid + amp * np.sin(w * t)


ICE_A = twin.get_catheter("example-a")


def ice_a_run(lo: float, hi: float, cycles: float = 2.0) -> Run:
    t, q = sine_sweep(lo, hi, cycles)
    return twin.simulate(ICE_A, t, {1: q}, seed=3, effects=())


def _fit_or_refusal(run: Run, knob: int = 1):
    """identify's fit of ``knob``, or None where it refuses naming what the record cannot fix.

    On records whose tip fit has near-equal optima (within a fraction of a percent in cost),
    which one the local search lands on follows the platform's floating-point kernels (numpy's
    SIMD dispatch: AVX-512 and AVX2 can differ); on one the fit's degenerate directions leave
    parameters unfixed and identify refuses, naming them. Both outcomes are honest; a test of
    what must never be *claimed* takes either, and checks the claim where one is made.
    """
    try:
        return identify(run).fits[knob]
    except IdentificationError as e:
        assert "cannot fix" in str(e), str(e)
        return None


# --------------------------------------------------------------------------------------------
# Must-show 3: recovery of known parameters over many sets
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("i", range(N_SETS))
def test_tip_fit_recovers_all_parameters(i):
    cat, run, res, _ = case(i)
    for k in (1, 2):
        true, got = cat.knobs[k], res.fits[k].model
        assert res.fits[k].method == "tip"
        for name in ("d_pos", "d_neg", "b_pos", "b_neg"):
            assert abs(getattr(got, name) - getattr(true, name)) <= 0.5, (k, name, got, true)
        assert abs(got.omega - true.omega) <= 0.02 * true.omega, (k, got.omega, true.omega)
        # heights: not in the list, but the fit has them; 0.5 deg of tip
        assert abs(got.h_pos - true.h_pos) <= 0.5 and abs(got.h_neg - true.h_neg) <= 0.5


@pytest.mark.parametrize("i", range(N_SETS))
def test_current_only_recovers_edges_and_backlash(i):
    cat, run, _, res = case(i)
    for k in (1, 2):
        true, got = cat.knobs[k], res.fits[k].model
        assert res.fits[k].method == "current"
        assert abs(got.d_pos - true.d_pos) <= 1.0, (k, got.d_pos, true.d_pos)
        assert abs(got.d_neg - true.d_neg) <= 1.0, (k, got.d_neg, true.d_neg)
        # backlash from the current alone: the width of the steep stretch after each reversal
        assert abs(got.b_pos - true.b_pos) <= 1.0, (k, got.b_pos, true.b_pos)
        assert abs(got.b_neg - true.b_neg) <= 1.0, (k, got.b_neg, true.b_neg)


def test_current_only_heights_follow_the_documented_assumption():
    _, _, _, res = case(0)
    for fit in res.fits.values():
        m = fit.model
        assert m.omega == PAPER_OMEGA
        # loop centred on the straight tip, H_neg - H_pos = omega * (B_pos + B_neg) / 2
        assert m.h_pos == pytest.approx(-m.h_neg, abs=1e-12)
        assert m.h_neg - m.h_pos == pytest.approx(m.omega * 0.5 * (m.b_pos + m.b_neg), rel=1e-12)
        assert set(fit.stderr) == {"d_pos", "d_neg", "b_pos", "b_neg"}
    _, run, _, _ = case(0)
    m = identify(run, use_tip=False, omega=1.6).model
    assert m.knob(1).omega == 1.6 and m.knob(2).omega == 1.6


@pytest.mark.parametrize("seed", [11, 12])
def test_current_only_reads_the_take_up_past_a_bend_of_the_dead_zone(seed):
    # The paper's protocol on the calibrated twin ice-b (hyst demo --simulate --seed 11 or 12):
    # knob 1's dead-zone current bends with the sine's speed (the motor's viscous term), and one
    # stretch from a reversal split it into a flat piece and one tilted at 0.1-0.4 mA/deg, the
    # flattest start before the take-up at 4.5 mA/deg. That stretch read no edge, and with it the
    # first stretch's edge was not taken either: "never clearly shows the positive tendon taken
    # up" (stop 30's code). The twin's own edges (its true model) are the reference.
    from hystcli import experiment as ex

    cat = ex.calibrated_catheter("ice-b")
    true = cat.knobs[1]
    fit = identify(ex.record_sweep(cat, 1, seed), knobs=[1], omega=PAPER_OMEGA, use_tip=False).fits[1]
    assert abs(fit.model.d_pos - true.d_pos) <= 1.0, (fit.model.d_pos, true.d_pos)
    assert abs(fit.model.d_neg - true.d_neg) <= 1.0, (fit.model.d_neg, true.d_neg)
    assert "d_pos" in fit.stderr and not any("d_pos" in w for w in fit.warnings)


def test_tip_fit_rmse_is_at_the_noise_level_and_uncertainties_are_sane():
    cat, run, res, _ = case(1)
    for k, fit in res.fits.items():
        # filtered EM noise: 0.3 deg * sqrt(2 * 20 Hz / 1000 Hz) = 0.06 deg rms (white noise
        # through a ~20 Hz band); a correct model leaves about that, a wrong one far more
        assert 0.03 < fit.rmse < 0.15
        assert set(fit.stderr) == {"d_pos", "d_neg", "b_pos", "b_neg", "omega", "h_pos", "h_neg"}
        for name, se in fit.stderr.items():
            assert math.isfinite(se) and se > 0, name
            # within 6 sigma of the truth (a sigma far too small would fail here)
            assert abs(getattr(fit.model, name) - getattr(cat.knobs[k], name)) <= 6 * se + 1e-3, name
        assert fit.ident.rmse == fit.rmse


def test_stored_levels_for_detect_shift():
    cat, run, res, _ = case(2)
    for k, fit in res.fits.items():
        cur = cat.current
        ident = fit.ident
        # twin current model: loading slope k_load (1 + mu) once a tendon is taut
        assert ident.slope_loaded == pytest.approx(cur.k_load * (1 + cur.mu), rel=0.1)
        # flat dead zone: only noise; far below the loaded slope
        assert ident.slope_dead_zone < 0.2 * ident.slope_loaded
        assert ident.slope_dead_zone < ident.eps_lower < ident.slope_loaded < ident.eps_upper
        # the dead-zone current is the no-load level +- the motor's Coulomb friction
        assert abs(ident.current_dead_zone - cur.no_load) <= cur.coulomb + 2.0
        assert ident.q_min == pytest.approx(-40.0, abs=1e-3)
        assert ident.q_max == pytest.approx(40.0, abs=1e-3)
    assert dict(res.model.identification) == {k: f.ident for k, f in res.fits.items()}
    assert res.model.meta["method"] == "tip"
    assert all(res.model.knob(k).offset == 0.0 for k in (1, 2))


def test_y0_is_the_first_measured_tip_angle():
    # crop the paper's sweep at its first descending zero crossing (t = pi): the tip then sits on
    # the descending dead zone at H_neg = 4.2 deg (ice-a knob 1), not at the straight tip y = 0
    run = paper_sweep(ICE_A, 5, knobs=(1,))
    start = int(np.argmin(np.abs(run["t"] - math.pi)))
    cropped = Run({n: v[start:] for n, v in run.columns.items()})
    q, y = cropped["q1"], cropped["y1"]
    assert abs(y[0] - 4.2) < 0.3
    fit = identify(cropped).fits[1]
    assert fit.rmse < 0.15
    assert abs(fit.model.d_pos - 9.1) <= 0.5 and abs(fit.model.b_pos - 6.2) <= 0.5
    # the model started from y[0] follows the first dead-zone stretch; from 0 it would sit 4 deg off
    head = slice(0, 100)
    assert np.max(np.abs(fit.model.forward(q, y[0])[head] - y[head])) < 0.5
    assert np.min(np.abs(fit.model.forward(q, 0.0)[head] - y[head])) > 3.0


# --------------------------------------------------------------------------------------------
# determinism
# --------------------------------------------------------------------------------------------
def test_identify_is_deterministic():
    _, run, res, _ = case(3)
    again = identify(run)
    for k in res.fits:
        assert again.fits[k].model == res.fits[k].model
        assert again.fits[k].stderr == res.fits[k].stderr
    a = identify(run, bootstrap=5, seed=7, use_tip=False)
    b = identify(run, bootstrap=5, seed=7, use_tip=False)
    assert a.fits[1].stderr == b.fits[1].stderr
    assert a.fits[1].bootstrap == 5


def test_bootstrap_over_cycles_uses_the_seed():
    t, q = sine_sweep(-40, 40, cycles=6)
    run = twin.simulate(ICE_A, t, {1: q}, seed=11, effects=())
    a = identify(run, bootstrap=8, seed=1).fits[1]
    b = identify(run, bootstrap=8, seed=1).fits[1]
    c = identify(run, bootstrap=8, seed=2).fits[1]
    assert a.stderr == b.stderr
    assert a.stderr != c.stderr
    assert a.model == c.model  # the estimate itself does not depend on the bootstrap
    # 6 sine cycles from 0: 12 reversals, 11 complete branches, 5 full cycles (pairs of them)
    assert a.n_reversals == 12 and a.n_cycles == 5


# --------------------------------------------------------------------------------------------
# sweep checks: every way a sweep can fail to identify, with a message saying what is missing
# --------------------------------------------------------------------------------------------
def test_never_reverses():
    t = np.linspace(0, 4, 4001)
    run = twin.simulate(ICE_A, t, {1: np.linspace(-40, 40, t.size)}, effects=())
    with pytest.raises(IdentificationError, match="never reverses"):
        identify(run)


def test_one_cycle_started_at_rest_is_enough():
    # rest -> +40 -> -40 -> rest (issue 10: a real log holds one such cycle): no complete
    # ascending branch, yet the output-error fit sees both edges and both backlash plateaus
    run = ice_a_run(-40, 40, cycles=1.0)
    true = ICE_A.knobs[1]
    fit = identify(run).fits[1]
    for name in ("d_pos", "d_neg", "b_pos", "b_neg"):
        assert abs(getattr(fit.model, name) - getattr(true, name)) <= 0.5, name
    assert abs(fit.model.omega - true.omega) <= 0.02 * true.omega
    cur_fit = identify(run, use_tip=False).fits[1]
    cur = cur_fit.model
    assert abs(cur.d_pos - true.d_pos) <= 1.0 and abs(cur.d_neg - true.d_neg) <= 1.0
    # the current alone sees the positive edge on the first stretch only (the last one returns to
    # rest before it), from a start state it cannot tell: an estimate, named, not claimed
    assert "d_pos" not in cur_fit.stderr and "d_neg" in cur_fit.stderr
    assert any("only the record's first stretch shows the positive tendon" in w for w in cur_fit.warnings)
    assert cur_fit.ident.unfixed == ("d_pos",)


def test_a_parameter_the_record_cannot_fix_is_named():
    # 0 -> +40 -> -40: the knob never rises again after the bottom reversal, so the tip never
    # leaves that plateau: b_neg is not in the record, and identify says so rather than guess
    with pytest.raises(IdentificationError, match="cannot fix .*b_neg"):
        identify(ice_a_run(-40, 40, cycles=0.75))


def test_never_past_the_dead_zone():
    # ice-a knob 1: dead zone [-8.7, 9.1]
    with pytest.raises(IdentificationError, match="d_pos .*never moves the tip positive past the dead zone"):
        identify(ice_a_run(-40, 8))
    with pytest.raises(IdentificationError, match="d_neg .*never moves the tip negative past the dead zone"):
        identify(ice_a_run(-8, 40))
    # the current alone: no loading edge on the side the knob never takes up
    with pytest.raises(IdentificationError, match="never clearly shows the positive tendon taken up"):
        identify(ice_a_run(-40, 6), use_tip=False)


def test_past_the_dead_zone_but_not_the_backlash():
    # ice-a knob 1: the tip leaves its plateau after the top reversal only from d_pos plus
    # (h_neg - h_pos)/omega = 9.1 + 5.66 = 14.8 deg on
    # the record is as well explained by a family of loops (every b_pos past the sweep's top, with
    # d_neg and h_neg trading against it); which member the optimiser lands on depends on the
    # scipy release, so the message may name more parameters with it, but b_pos always
    with pytest.raises(IdentificationError, match="cannot fix .*b_pos"):
        identify(ice_a_run(-40, 12))
    # a little beyond is enough, and still accurate
    m = identify(ice_a_run(-40, 17)).fits[1].model
    assert abs(m.b_pos - ICE_A.knobs[1].b_pos) <= 0.5 and abs(m.d_pos - 9.1) <= 0.5


def test_constant_current_and_too_few_samples():
    t, q = twin.sweep()
    run = Run({"t": t, "q1": q, "c1": np.full(t.size, 100.0)})
    with pytest.raises(IdentificationError, match="current c1 is constant"):
        identify(run)
    good = paper_sweep(ICE_A, 0, knobs=(1,))
    short = Run({n: v[:50] for n, v in good.columns.items()})
    with pytest.raises(IdentificationError, match=r"too few samples \(50\)"):
        identify(short)


def test_knob_columns_and_arguments():
    good = paper_sweep(ICE_A, 0, knobs=(1,))
    no_c = Run({"t": good["t"], "q1": good["q1"], "y1": good["y1"]}, source="s.csv")
    # the current-only path needs the current ...
    with pytest.raises(IdentificationError, match="s.csv: no knob to identify"):
        identify(no_c, use_tip=False)
    with pytest.raises(IdentificationError, match="column 'c1' is missing"):
        identify(no_c, knobs=[1], use_tip=False)
    # ... the tip fit does not (issue 6): it starts from the q-y loop and says so
    fit = identify(no_c).fits[1]
    assert fit.method == "tip" and fit.ident is None
    no_y = Run({"t": good["t"], "q1": good["q1"]}, source="s.csv")
    with pytest.raises(IdentificationError, match="needs a pair of columns q1,c1 or q2,c2 \\(or q1,y1"):
        identify(no_y)
    with pytest.raises(IdentificationError, match="knob 3"):
        identify(good, knobs=[3])
    with pytest.raises(IdentificationError, match="omega must be a positive number"):
        identify(good, omega=-1.0)
    bad = good.with_columns(c1=np.where(np.arange(len(good)) == 10, np.nan, good["c1"]))
    with pytest.raises(IdentificationError, match="'c1' has a non-finite value at row 11"):
        identify(bad)
    # identify only the knob asked for
    assert set(identify(paper_sweep(ICE_A, 0), knobs=[2]).fits) == {2}


def test_check_sweep_reports_reversals():
    chk = check_sweep(paper_sweep(ICE_A, 0, knobs=(1,)), 1)
    # sin over 2 cycles from 0: tops at 1/4 and 5/4 of the period, bottoms at 3/4 and 7/4
    assert list(chk.tops) == [True, False, True, False]
    assert [d for _, _, d in chk.branches] == [-1, 1, -1]
    assert chk.n_cycles == 1


# --------------------------------------------------------------------------------------------
# reversals
# --------------------------------------------------------------------------------------------
def test_find_reversals_by_hand():
    q = np.array([0, 1, 2, 3, 2, 1, 0, 1, 2, 2.1, 2.0])
    idx, top = find_reversals(q, tol=0.5)
    assert list(idx) == [3, 6]  # 2.1 -> 2.0 is a wiggle below the tolerance
    assert list(top) == [True, False]


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(1.0, 50.0), min_size=1, max_size=8), st.booleans(),
       st.integers(3, 40))
def test_find_reversals_finds_every_turning_point(legs, up, n):
    # a zig-zag of legs longer than the tolerance: every corner but the last end is a reversal
    q, corners, level, d = [0.0], [], 0.0, (1 if up else -1)
    for leg in legs:
        seg = level + d * leg * np.arange(1, n + 1) / n
        q.extend(seg)
        level = seg[-1]
        corners.append(len(q) - 1)
        d = -d
    idx, top = find_reversals(np.array(q), tol=0.5)
    assert list(idx) == corners[:-1]
    assert list(top) == [(i % 2 == 0) == up for i in range(len(corners) - 1)]


# --------------------------------------------------------------------------------------------
# figure
# --------------------------------------------------------------------------------------------
def test_plot_identification_writes_a_png(tmp_path):
    _, run, res, _ = case(0)
    out = tmp_path / "fit.png"
    plot_identification(run, res, out)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert [p.name for p in tmp_path.iterdir()] == ["fit.png"]  # no temporary left behind
    with pytest.raises(DataError, match="does not exist"):
        plot_identification(run, res, tmp_path / "missing" / "fit.png")


# independent plants (hystcli.zoo.plants, written without reading identify) whose tip meets a
# rigid wall on one side; seeds of its design set. The wall's level is the plant's, not ours.
# 427-2769: walls the tip meets within a degree or so of the knob's reversal (0.5-1.4 deg of
# advancing knob at the wall); before they were not seen as walls (the travel floor was 1.5 deg,
# and a noisy sample out of the band split a stroke's stretch in two) and the plain fits returned
# d/b 0.5-1.2 deg off with exit 0. 669 and 775: noisy trackers (0.4 deg on 669), 1.5-2 deg of knob
# at the wall, under the former 5 sigmas of travel.
WALL_SEEDS = (7, 32, 33, 39, 124, 161, 179, 292, 427, 527, 669, 775, 1563, 1846, 2769)


@pytest.mark.parametrize("seed", WALL_SEEDS)
def test_a_wall_that_holds_the_tip_is_censored_and_the_free_loop_recovered(seed):
    from hystcli.io import parse_run
    from hystcli.zoo import plants

    case = plants.sweep_case(seed)
    assert case.family == "wall"
    fit = identify(parse_run(case.record.csv_text(), source="wall")).fits[1]
    truth = case.truth.as_dict()
    # the plant's truth is its free tip's loop (plants.py: "The true parameters are those of the
    # free tip"); before the censoring these fits were refused, or off by 0.6-9 deg
    for name in ("d_pos", "d_neg", "b_pos", "b_neg"):
        assert abs(getattr(fit.model, name) - truth[name]) <= 0.5, (seed, name)
    assert any("a wall holds the tip" in w for w in fit.warnings)
    # the level the warning names is within a few noise sigmas of the plant's wall
    from hystcli.identify.tip import wall_levels

    lvl = [v for v in wall_levels(fit.tip.walls, np.asarray(case.record.columns["y1"], float)) if v is not None]
    assert len(lvl) == 1 and abs(lvl[0] - case.factors["wall_y"]) <= 4 * max(case.factors["noise_y"], 0.1) + 0.5


def test_a_loop_the_first_starts_miss_is_found_by_searching_further():
    # zoo sweep 3500061 (a drop-at-reversal plant, tip noise 0.44 deg, backlash plateaus 7.4 and
    # 9.0 deg on a 13-deg dead zone): the six best grid points all led the local fit to an
    # optimum 2 deg off (d_neg -1.28 against -3.31), whose misfit identify refused. Identify now
    # searches further batches of starts when the first fit leaves the tip
    from hystcli.identify.tip import fit_tip
    from hystcli.io import parse_run
    from hystcli.zoo import plants

    case = plants.sweep_case(3500061)
    run = parse_run(case.record.csv_text(), source="zoo")
    q, y = np.asarray(run["q1"], float), np.asarray(run["y1"], float)
    first, more = fit_tip(q, y), fit_tip(q, y, batches=4)
    # the plant's tracker noise is 0.44 deg: the first optimum leaves far more
    assert first.noise > 1.5 * more.noise
    assert more.noise == pytest.approx(case.factors["noise_y"], rel=0.1)
    fit = identify(run).fits[1]
    truth = case.truth.as_dict()
    for name in ("d_pos", "d_neg", "b_pos", "b_neg", "omega"):
        assert name in fit.stderr and abs(getattr(fit.model, name) - truth[name]) <= 0.5, name


def test_further_starts_never_trade_a_whole_loop_for_a_degenerate_one():
    # withheld catheter 12003 (hystcli.zoo.catheters, suite seed 12: a viscous backlash, whose
    # sweep the loop cannot follow; identify keeps it when asked). Its further starts reach a
    # loop 0.002 deg closer that leaves d_pos and both backlashes undetermined; taken, that
    # refused the sweep (and the diagnosis lost the case). The first loop is kept
    import math

    from hystcli.identify.tip import fit_tip
    from hystcli.io import parse_run
    from hystcli.zoo import catheters

    case = catheters.make_case(12003, dict(catheters.suite_specs(12))[12003])
    run = parse_run(case.sweep, source="zoo")
    q, y = np.asarray(run["q1"], float), np.asarray(run["y1"], float)
    first = fit_tip(q, y)
    if first.unidentified:
        # the platform's kernels landed the first search in a degenerate optimum of its own
        # (_fit_or_refusal): then identify must refuse, naming it, not return a further start's
        with pytest.raises(IdentificationError, match="cannot fix"):
            identify(run, max_misfit=math.inf)
        return
    assert fit_tip(q, y, batches=4).unidentified
    fit = identify(run, max_misfit=math.inf).fits[1]
    for name in ("d_pos", "d_neg", "b_pos", "b_neg", "omega"):
        assert getattr(fit.model, name) == pytest.approx(getattr(first.model, name), abs=1e-6), name


def test_a_record_that_starts_at_a_wall_is_refused_not_returned_wrong():
    from hystcli.io import parse_run
    from hystcli.zoo import plants

    # design seed 1501: the tip starts held at a wall (the knob already past it) and meets it
    # again 1.2 deg before each top reversal. Before: no wall seen, and the fit returned b_neg
    # 16.8 deg and d_pos 8.6 deg off with exit 0. The wall found, the grid search used to rank
    # its candidates without the held samples (and with a few held samples that noise put below
    # a threshold taken from the wall's noisy peak counted as free tip 2.7 deg off), and the fit
    # stayed in the wrong basin. Now the held samples rank the candidates too, and the fit says
    # the record cannot place the falling edge's plateau.
    case = plants.sweep_case(1501)
    assert case.family == "wall" and case.factors["start_taut"] == "pos"
    with pytest.raises(IdentificationError, match="cannot fix b_neg"):
        identify(parse_run(case.record.csv_text(), source="wall"))


def test_the_wall_threshold_sits_below_the_samples_the_wall_holds():
    from hystcli.identify.tip import WALL_HOLD, find_walls

    # a tip held at a wall at 5.0 deg for a long stretch, noise 0.1: the censoring threshold is the
    # wall's level less WALL_HOLD sigmas, so (almost) every held sample lies above it; from the
    # noisy peak (about 5.0 + 3.5 sigma for 2000 samples, less 3 sigma) it cut through them
    rng = np.random.default_rng(3)
    q = np.concatenate([np.linspace(-20, 20, 2000), np.linspace(20, -20, 2000)])
    free = 1.2 * q
    y = np.minimum(free, 5.0) + rng.normal(0, 0.1, q.size)
    bottom, top = find_walls(q, y, 0.1)
    assert bottom is None and top is not None
    held = y[(free > 5.0)]
    assert 5.0 - (WALL_HOLD + 0.5) * 0.1 <= top <= 5.0 - (WALL_HOLD - 0.5) * 0.1
    assert np.mean(held >= top) >= 0.95


def test_a_wall_on_a_fast_sweep_is_censored_though_its_quarter_second_misfit_is_small():
    from hystcli.identify import WALL_MISFIT, systematic_misfit
    from hystcli.identify.tip import fit_tip
    from hystcli.io import parse_run
    from hystcli.zoo import plants

    # held-out plant 4900388 (examined after 4900000's figures, stop 43): a compliant wall at
    # -5.7 deg of tip, swept at 57 deg/s and sampled at 73 Hz, so a quarter second spans 14 deg
    # of knob and the plain fit's systematic misfit is under WALL_MISFIT; that fit bent the loop
    # to the wall (omega 10 % low) and returned d_pos 0.57 and b_neg 0.65 deg off at +-0.07
    case = plants.sweep_case(4900388)
    assert case.family == "wall" and case.factors["speed"] > 50
    run = parse_run(case.record.csv_text(), source="wall")
    q, y = np.asarray(run["q1"], float), np.asarray(run["y1"], float)
    plain = fit_tip(q, y)
    assert systematic_misfit(plain.model.forward(q, float(y[0])) - y, run.sample_rate) < WALL_MISFIT
    fit = identify(run).fits[1]
    assert any("a wall holds the tip" in w for w in fit.warnings)
    truth = case.truth.as_dict()
    for name in ("d_pos", "d_neg", "b_pos", "b_neg"):
        assert abs(getattr(fit.model, name) - truth[name]) <= 0.5, name
        # the plant's truth within two of the stated standard errors (or 0.05 deg)
        assert abs(getattr(fit.model, name) - truth[name]) <= max(2 * fit.stderr[name], 0.05), name
    assert fit.model.omega == pytest.approx(truth["omega"], rel=0.02)


def test_no_wall_on_a_free_loop_or_a_dead_zone_flat():
    from hystcli.identify.tip import find_walls

    # a free loop: the tip rises with the knob up to each reversal
    run = ice_a_run(-40, 40)
    q, y = np.asarray(run["q1"]), np.asarray(run["y1"])
    assert find_walls(q, y, 0.1) == (None, None)
    # a sweep that never passes d_pos ends each rise on the dead zone's flat: the same shape as a
    # wall, but the plain fit explains it, so identify never censors it and still says why
    with pytest.raises(IdentificationError, match="d_pos .*never moves the tip positive past the dead zone"):
        identify(ice_a_run(-40, 8))


@pytest.mark.parametrize("seed,family,name", [
    # the tip meets a wall: the load rose steeply at the top of the stroke and falls back as
    # steeply after the reversal, which is not the sheath friction flipping over the backlash
    # (before: b_pos 17.0 and 24.5 returned against a true 5.7 and 8.3)
    (45, "wall", "b_pos"), (371, "wall", "b_pos"),
    # the same wall after the record's first stretch, too short to read its end slope: the other
    # stretches that turned at the same knob angle met the same wall there (before: b_pos 9.46
    # returned on a stretch law whose current carries no backlash, 5.2 deg off the true loop's)
    (826, "wall", "b_pos"),
    # a current that follows the tendon's stretch carries no backlash; a plateau-like piece after
    # fewer than half of the loaded reversals is not one (before: b_neg 5.97 returned against
    # 2.44; b_pos now shows after one of three reversals, and the reading stops there)
    (294, "stretch", "b_pos"),
    # a stiffening cable on a stretch law (held-out 4100412, looked at after that range's figures):
    # from the negative reversal the current falls back down its own stiffening curve, steeply
    # and then gentler, and stop 35's first code read that as the sheath's flip over a backlash,
    # b_neg 9.49 +- 0.44 (RETRACE)
    (4100412, "stiffening", "b_neg"),
])
def test_current_only_does_not_read_a_backlash_the_current_does_not_hold(seed, family, name):
    from hystcli.io import parse_run
    from hystcli.zoo import plants

    # independent plants (hystcli.zoo.plants, design seeds): their truth says which law holds
    case = plants.sweep_case(seed, tip=False)
    assert case.family == family
    fit = identify(parse_run(case.record.csv_text(), source="z"), use_tip=False).fits[1]
    _assert_backlash_unfixed(fit, case.truth, name)


@pytest.mark.parametrize("seed", [271, 471])
def test_an_edge_the_tip_and_the_current_place_apart_is_not_claimed_when_both_loops_fit(seed):
    from hystcli.io import parse_run
    from hystcli.zoo import plants

    # independent plants (design seeds) where a loop with d_neg 6.9 / 1.9 deg off fits the tip as
    # well as the true one (RMS within 25 %), and the current reads the true edge: before, the
    # tip's d_neg was returned with a 0.06-deg uncertainty
    case = plants.sweep_case(seed)
    fit = _fit_or_refusal(parse_run(case.record.csv_text(), source="z"))
    if fit is None:     # refused, naming what it cannot fix: nothing claimed (see _fit_or_refusal)
        return
    assert not {"d_neg", "b_pos", "b_neg"} & set(fit.stderr)
    # said either way: the current's edge fits as well, or (seed 471, heights 10 deg apart) the
    # fitted edge sits on a flat too narrow to fix it (FLAT_WIDTH)
    assert any("cannot tell them apart" in w or "is not fixed by this record" in w for w in fit.warnings)
    assert "d_neg" in fit.ident.unfixed
    # what stays claimed is right
    for name in ("d_pos", "omega"):
        if name in fit.stderr:
            assert abs(getattr(fit.model, name) - getattr(case.truth, name)) <= 0.5

def _zoo_current_fit(seed: int):
    """An independent zoo plant's sweep (design seed), its motor current only, and identify's fit."""
    from hystcli.io import parse_run
    from hystcli.zoo import plants

    case = plants.sweep_case(seed, tip=False)
    return case, identify(parse_run(case.record.csv_text(), source="z"), use_tip=False).fits[1]


def _assert_backlash_unfixed(fit, truth, name: str):
    """The current did not fix backlash ``name``: the model comes back for its edges (claimed, and
    within a degree), with ``name`` unclaimed, listed as unfixed and said so, and a model that
    refuses to predict the tip."""
    from hystcli.errors import ModelError

    assert name not in fit.stderr and name in fit.ident.unfixed
    assert any("the current cannot fix" in w and name in w for w in fit.warnings)
    _assert_within(fit, truth, ("d_pos", "d_neg"))
    model = Model({1: fit.model}, identification={1: fit.ident})
    with pytest.raises(ModelError, match=f"knob 1's .*{name}.* not fixed by its sweep"):
        model.predict(Run({"t": np.arange(3.0), "q1": np.zeros(3)}))


def _assert_within(fit, truth, names, tol: float = 1.0):
    """Every one of ``names`` claimed (with a standard error) and within ``tol`` deg of the truth."""
    for name in names:
        assert name in fit.stderr
        assert abs(getattr(fit.model, name) - getattr(truth, name)) <= tol, name


@pytest.mark.parametrize("seed", [295, 478])
def test_current_only_ignores_a_kink_where_a_held_load_starts_to_unload(seed):
    # independent tip-load plants (design seeds): on the last stretch, after the reversal, the
    # current holds the other tendon's load and then unloads; that kink (far from the no-load
    # level) disagreed with the true edges and made identify refuse the whole record
    case, fit = _zoo_current_fit(seed)
    for name in ("d_pos", "d_neg", "b_pos", "b_neg"):
        assert abs(getattr(fit.model, name) - getattr(case.truth, name)) <= 1.0, name


@pytest.mark.parametrize("seed,family", [(88, "coulomb-viscous"), (660, "pretension"), (253, "coulomb-viscous")])
def test_current_only_reads_a_plateau_tilted_like_the_dead_zone(seed, family):
    # independent plants (design seeds): a pretensioned tendon's spring, or the motor's viscous
    # term following the sine's speed, tilts the backlash plateau as much as the dead zone; the
    # load itself holds. Before, the plateau had to be flat against the unloading slope and
    # identify refused "no backlash plateau" on all three.
    case, fit = _zoo_current_fit(seed)
    assert case.family == family and case.current_shows_backlash
    _assert_within(fit, case.truth, ("d_pos", "d_neg", "b_pos", "b_neg"))


@pytest.mark.parametrize("seed", [474, 149])
def test_current_only_reads_the_plateau_before_the_next_reversal_drop(seed):
    # independent drop-at-reversal plants (design seeds): the load drops at once at each
    # reversal, and the zero-phase filter spreads the next reversal's drop back into the end of
    # the stretch; that drop took one of the five pieces the plateau, the unloading, the dead
    # zone and the loading need, and identify refused "no backlash plateau"
    case, fit = _zoo_current_fit(seed)
    assert case.family == "drop-at-reversal" and case.current_shows_backlash
    _assert_within(fit, case.truth, ("d_pos", "d_neg", "b_pos", "b_neg"))


@pytest.mark.parametrize("seed,name", [(85, "d_pos"), (179, "d_pos"), (502, "d_pos"), (152, "d_neg")])
def test_current_only_edge_uncertainty_is_no_finer_than_its_bins(seed, name):
    # independent plants (design seeds): the kink fits gave the current's edge a standard error
    # of 0.014-0.021 deg where it sat 0.03-0.16 deg from the truth (the current law rounds the
    # corner); the reading cannot be finer than the knob-angle bins it is made on
    case, fit = _zoo_current_fit(seed)
    err = getattr(fit.model, name) - getattr(case.truth, name)
    assert abs(err) <= 2 * fit.stderr[name]
    assert fit.stderr[name] <= 0.5


def test_an_edge_on_a_flat_a_few_hundredths_wide_is_not_claimed():
    from hystcli.io import parse_run
    from hystcli.zoo import plants

    # independent plant (design seed 1130): its tip never reaches either dead zone (heights 8 deg
    # apart, backlash 0.1 deg), so a loop with 17-deg backlash and heights 1 deg apart fits as
    # well; that fit left d_neg on a 0.04-deg flat and claimed it to +-0.04 deg, 2.94 deg from
    # the truth (and detect-shift then measured from it)
    case = plants.sweep_case(1130)
    fit = _fit_or_refusal(parse_run(case.record.csv_text(), source="z"))
    if fit is None:     # refused, naming what it cannot fix: nothing claimed (see _fit_or_refusal)
        return
    for name in ("d_pos", "d_neg"):
        if name in fit.stderr:
            assert abs(getattr(fit.model, name) - getattr(case.truth, name)) <= 0.5, name
    assert "d_neg" not in fit.stderr


def test_an_edge_the_record_cannot_place_within_half_a_degree_is_not_claimed():
    from hystcli.io import parse_run
    from hystcli.zoo import plants

    import numpy as np

    from hystcli.identify import tip
    from hystcli.identify.sweep import decimation_index

    # independent plant (design seed 1803, the straight sweep of a replay case): the fit put
    # d_neg 3.3 deg off with a stated standard error of 0.01 deg (the Jacobian sees the slide
    # direction only through the few samples its own flat holds); sliding the edge 0.5 deg along
    # its loaded line changes the fit by less than one noise variance, so it is not claimed.
    # Since stop 22 the flat check names the cause first (the tip sat at the flat's level from the
    # record's start); the slide test, the net behind it, still sees the same on its own
    case = plants.replay_case(1803)
    run = parse_run(case.straight_sweep.csv_text(), source="z")
    fit = identify(run).fits[1]
    assert "d_neg" not in fit.stderr
    assert any("d_neg is not fixed by this record" in w and "record's start" in w for w in fit.warnings)
    assert abs(fit.model.d_pos - case.truth.d_pos) <= 0.5 and "d_pos" in fit.stderr
    q, y = np.asarray(run["q1"], float), np.asarray(run["y1"], float)
    idx = decimation_index(q, tip.MAX_SAMPLES)
    slid = tip._slides_unseen(fit.tip.theta, q[idx], y[idx], None, fit.tip.noise, set(), fit.tip.tau)
    assert set(slid) == {"d_neg"} and "sliding the edge 0.5 deg" in slid["d_neg"]


def test_a_flat_no_longer_than_the_trackers_memory_does_not_place_its_edge():
    from hystcli.io import parse_run
    from hystcli.zoo import plants

    # held-out plant 1400295 (examined in stop 21; a filtered tracker at 1.8 kHz, residual
    # autocorrelation 20 samples): the fit put d_pos 3.69 deg off (20.55, true 24.24) with a
    # stated standard error of 0.013 deg, on a rising flat seen over 0.37 deg of knob, while
    # the knob travels 0.87 deg within the tracker's memory: the filter's rounding of a corner.
    # The model fits the record better than the truth does (RMS 0.0292 against 0.0321 deg).
    case = plants.sweep_case(1400295)
    fit = identify(parse_run(case.record.csv_text(), source="z")).fits[1]
    assert "d_pos" not in fit.stderr
    assert any("d_pos is not fixed by this record" in w and "tracker's own memory" in w for w in fit.warnings)
    for name in ("d_neg", "b_pos", "b_neg"):
        assert abs(getattr(fit.model, name) - getattr(case.truth, name)) <= 0.5, name


def test_a_flat_of_the_records_last_few_samples_does_not_place_its_edge():
    from hystcli.io import parse_run
    from hystcli.zoo import plants

    # held-out replay 1000343's straight sweep (examined in stop 20): it ends 0.09 deg of knob
    # into the fitted loop's falling flat, 5 samples that are one noise draw of a filtered
    # tracker (autocorrelation 12.5 samples); the fit put d_neg 4.5 deg off (-1.74, true -6.27)
    # and claimed it to +-0.025 deg; detect-shift measured from it (2.4 deg off, exit 0)
    case = plants.replay_case(1000343)
    fit = identify(parse_run(case.straight_sweep.csv_text(), source="z")).fits[1]
    assert "d_neg" not in fit.stderr
    assert abs(fit.model.d_pos - case.truth.d_pos) <= 0.5 and "d_pos" in fit.stderr


def test_no_load_levels_are_read_where_the_tip_rests_on_a_dead_zone_flat():
    from hystcli.identify import current_levels
    from hystcli.io import parse_run
    from hystcli.zoo import plants

    # held-out replay 1400205 (examined in stop 21): a tip-load plant (the tendon keeps the tip's
    # load while the tip rests on its backlash plateau) with b_pos 15.7 deg across a 17-deg dead
    # zone. Read inside the knob's dead zone alone, its straight sweep gave the held load as the
    # no-load level moving down: 67.2 mA, where the plant's no-load current c0 is -30.2 mA; the
    # search then took the positive tendon's unloading for the negative edge (7.7 deg off).
    case = plants.replay_case(1400205)
    tr = case.truth
    km = KnobModel(d_pos=tr.d_pos, d_neg=tr.d_neg, b_pos=tr.b_pos, b_neg=tr.b_neg, omega=tr.omega,
                   h_pos=tr.h_pos, h_neg=tr.h_neg)
    lv = current_levels(parse_run(case.straight_sweep.csv_text(), source="z"), 1, km)
    c0 = case.factors["sweep"]["c0"]
    noise = case.factors["sweep"]["noise_c"]
    for level in (lv.no_load_rising, lv.no_load_falling):
        assert abs(level - c0) <= 4 * noise


def test_current_only_a_stretch_ending_in_the_dead_zone_starts_its_dead_zone_after_the_unloading():
    # held-out plant 1500263 (examined in stop 21; pretensioned tip-load, one cycle): the stretch
    # down from the top reversal holds the load for 5.8 deg, unloads at 10 mA/deg over 6 deg and
    # ends in the dead zone (0.7 mA/deg), whose last 1.6 deg the segmentation split off as a still
    # flatter piece. Taken for the dead zone, that left the dead zone itself as the unloading and
    # the true unloading as the backlash: b_pos 12.00 +- 0.3 deg, true 5.84.
    case, fit = _zoo_current_fit(1500263)
    _assert_within(fit, case.truth, ("b_pos", "b_neg", "d_pos"))


def test_current_only_judges_a_wall_against_the_loaded_slope_of_the_reversal_stretches():
    from hystcli.io import parse_run
    from hystcli.zoo import plants

    # independent wall plant (design seed 1732): the record's first stretch took the wall's own
    # steep rise for its edge, so the wall's steep fall after the next reversal did not look
    # elastic against it and was read as the sheath friction flipping: b_pos 8.3 deg too wide
    # (found on held-out seed 400166, checked on this design seed)
    case = plants.sweep_case(1732, tip=False)
    fit = identify(parse_run(case.record.csv_text(), source="z"), use_tip=False).fits[1]
    _assert_backlash_unfixed(fit, case.truth, "b_pos")


def test_a_stiffening_cables_steep_unloading_after_a_held_plateau_is_unloading_not_backlash():
    # read_current's pieces of one stretch from a reversal (hand-built, bins of 0.5 deg): a held
    # plateau (slope 0.5 mA/deg, 0-5.5 deg), then a stiffening cable's unloading split in two, steep
    # where the load is largest (126) and softer (78), the dead zone (9), the loading (50). The
    # longest unloading piece is the soft one; the steep one is 1.6x it, short of a friction flip
    # (2x): the backlash ends where the held plateau does, (5.5 + 6.0) / 2 = 5.75 deg (the reading
    # before took the steep piece as backlash and ended it at 14.75)
    from hystcli.identify import current as IC

    xb = np.arange(0.0, 60.0, 0.5)
    pieces = [(0, 12), (12, 30), (30, 50), (50, 76), (76, 106)]
    width, held, span = IC._plateau(pieces, [0.5, 126.0, 78.0, 9.0, 50.0], xb, 1.0, True, 3)
    assert held and width == pytest.approx(5.75)
    # the two pieces either side of the end, where _refine_end places it by a two-line fit
    assert span == (0.0, 14.5)
    # without a held plateau before it the steep piece may be the friction's flip and stays the
    # backlash phase; with neither a held plateau nor a 2x flip there is no backlash to read
    width, held, span = IC._plateau(pieces, [40.0, 126.0, 78.0, 9.0, 50.0], xb, 1.0, True, 3)
    assert width is None and not held and span is None
    # softening in turn over three pieces (210 -> 150 -> 96, each less than twice the next): all
    # unloading, though the first is more than twice the last
    pieces3 = [(0, 12), (12, 20), (20, 30), (30, 50), (50, 76), (76, 106)]
    width, held, _ = IC._plateau(pieces3, [0.5, 210.0, 150.0, 96.0, 9.0, 50.0], xb, 1.0, True, 4)
    assert held and width == pytest.approx(5.75)


# --------------------------------------------------------------------------------------------
# current only: readings that contradict each other are refused, not returned (branch cur-silent)
# --------------------------------------------------------------------------------------------
def _zoo_reading(seed: int):
    """The current reading of a zoo sweep as identify makes it (and the sweep's case)."""
    from hystcli.current import condition
    from hystcli.identify.current import read_current
    from hystcli.io import parse_run
    from hystcli.zoo import plants

    case = plants.sweep_case(seed, tip=False)
    run = parse_run(case.record.csv_text(), source="z")
    chk = check_sweep(run, 1, need_current=True)
    q = np.asarray(run["q1"], float)
    c = condition(np.asarray(run["c1"], float), run.sample_rate, 20.0)
    return case, run, read_current(q, c, np.asarray(run["t"], float), chk)


@pytest.mark.parametrize("seed, name", [(2796, "d_neg")])
def test_current_only_refuses_an_edge_whose_dead_zone_is_a_curve(seed, name):
    # design seed 2796 (pretension) took a kink between two loaded slopes (15.8 and 28.8 mA/deg)
    # for the negative edge, 3.4 deg out. The piece before the kink climbs at a fifth of the
    # loaded slope or more and several times the other side's dead zone: no dead zone. (Design
    # seed 2010, a stiffening cable refused here for the same reason, 1.0 deg late, is now read
    # again around its kink and returned right: test_current_only_reads_a_stiffening_take_up...)
    # Since stop 44 the true take-up, whose climb a short corner piece had split off
    # (edge_pieces), is read instead: the kink between the loaded slopes is never returned; where
    # no true take-up is read, the refusal gives the curve as the reason.
    case, run, reading = _zoo_reading(seed)
    side = name[2:]
    if side in reading.edges:
        assert abs(reading.edges[side] - getattr(case.truth, name)) <= 0.5
        fit = identify(run, use_tip=False).fits[1]
        assert abs(getattr(fit.model, name) - getattr(case.truth, name)) <= 0.5
        return
    assert name in reading.doubts
    assert "times the other side's dead zone" in reading.doubts[name]
    with pytest.raises(IdentificationError, match=f"the current's {name} is not an edge .*a curve, not the edge"):
        identify(run, use_tip=False)


@pytest.mark.parametrize("seed", [1042])
def test_current_only_keeps_an_edge_whose_dead_zone_tilts_less_than_a_fifth_of_its_loading(seed):
    # 1042: its positive dead-zone piece is 5.9x the negative one's but only 0.165 of the loaded
    # slope (DEAD_SHARE 0.2): still read, within 0.6 deg

    case, fit = _zoo_current_fit(seed)
    truth = case.truth.as_dict()
    for name, value in fit.model.params().items():
        if name in fit.stderr:
            assert abs(value - truth[name]) <= 1.0, name


@pytest.mark.parametrize("seed,family", [(561, "tip-load"), (211, None), (496, None)])
def test_current_only_reads_a_plateau_longer_than_each_unloading_piece(seed, family):
    # independent plants (design seeds): the held load after a reversal is longer than the
    # tendon's unloading, or than each piece the segmentation split the unloading into (561:
    # a 12 deg plateau before 6 + 6 deg of unloading); the reading took the longest piece before
    # the dead zone for the unloading, found the plateau itself, and refused "no backlash plateau"
    case, fit = _zoo_current_fit(seed)
    assert case.current_shows_backlash and (family is None or case.family == family)
    _assert_within(fit, case.truth, ("d_pos", "d_neg", "b_pos", "b_neg"))


def test_current_only_refuses_a_plateau_many_times_its_unloading():
    from hystcli.errors import IdentificationError
    from hystcli.io import parse_run
    from hystcli.zoo import plants

    # independent plant (design seed 255, tip-load): after each reversal the current holds for
    # three times the travel over which it then unloads, and the held travel is short of the
    # backlash (10.2 deg read against b_neg 12.0): a tendon that must let go before the knob has
    # travelled the whole backlash. A plateau more than HELD_RATIO times its unloading is not
    # taken for the backlash: left unfixed, not returned 1.8 deg short
    case = plants.sweep_case(255, tip=False)
    fit = identify(parse_run(case.record.csv_text(), source="z"), use_tip=False).fits[1]
    _assert_backlash_unfixed(fit, case.truth, "b_neg")


def test_current_only_reads_a_pretensioned_plateau_against_the_dead_zone_slope():
    # independent plant (design seed 1, pretension on a drop-at-reversal law): the pretension
    # slope (2.5 mA/deg) is more than half the unloading's (5.0), so the plateau's tilt was
    # judged against zero and the plateau refused; and the kink fit took the unloading piece
    # (twice the dead zone's slope) for part of the dead zone and put d_pos 1.9 deg late
    case, fit = _zoo_current_fit(1)
    assert case.family == "pretension"
    _assert_within(fit, case.truth, ("d_pos", "d_neg", "b_pos", "b_neg"))


def test_current_only_edge_is_not_read_out_of_a_reversal_before_a_held_load():
    # independent plant (design seed 28, pretensioned drop-at-reversal law): after the bottom
    # reversal the first half degree is flatter than the held plateau's pretension slope, so the
    # reversal was taken for the dead zone and the plateau (6 mA/deg) for the loading, with the
    # unloading (29) and the real dead zone (6) after it; the loading edge d_pos went unread from
    # every stretch from a reversal and identify refused "never clearly shows the positive tendon"
    case, fit = _zoo_current_fit(28)
    assert abs(fit.model.d_pos - case.truth.d_pos) <= 1.0


def test_the_end_of_a_held_plateau_is_placed_by_a_two_line_fit():
    from hystcli.identify import current as IC

    # binned current every 0.5 deg of travel: held at 100 mA to 7.3 deg, then unloading at
    # 5 mA/deg (by hand: the kink of the two lines is at 7.3). The segmentation's boundary sits
    # between bins (7.25 here); the fit finds 7.3, with a standard error below a bin
    rng = np.random.default_rng(3)
    xb = np.arange(0.0, 15.01, 0.5)
    vb = 100.0 + 5.0 * np.maximum(xb - 7.3, 0.0) + rng.normal(0.0, 0.05, xb.size)
    at, se = IC._refine_end(xb, vb, 7.25, (0.0, 15.0), 0.5)
    assert at == pytest.approx(7.3, abs=0.05) and se is not None and se < 0.5
    # no kink in the span: the boundary is kept, without a standard error of its own
    flat = 100.0 + rng.normal(0.0, 0.05, xb.size)
    at, se = IC._refine_end(xb, flat, 7.25, (0.0, 15.0), 0.5)
    assert at == 7.25 and se is None


def test_current_only_backlash_from_a_noisy_plateau_end_is_within_a_degree():
    # independent plant (design seed 867, Coulomb-viscous, current noise 0.7 mA): the plateaus'
    # ends read at the segmentation's boundaries put b_pos 1.7 deg and b_neg 1.2 deg off, each from
    # one stretch, with a stated standard error of 0.3; placed by a two-line fit: within 0.6 deg
    case, fit = _zoo_current_fit(867)
    for name in ("b_pos", "b_neg"):
        assert abs(getattr(fit.model, name) - getattr(case.truth, name)) <= 1.0, name


def test_a_gentle_unloading_after_a_held_plateau_is_not_taken_into_the_dead_zone():
    # read_current's pieces of one stretch from a reversal (hand-built from design seed 2098's,
    # bins of 0.5 deg): an immediate drop (234 mA/deg, 0-1 deg), the held plateau (0.01, 1-16.5),
    # the unloading (4.01 mA/deg over 41 deg: a capstan's friction makes it five times gentler
    # than the loading), the dead zone (-0.01), the loading (20.5). The unloading is flatter than
    # FLAT_AFTER (0.35) of the loading; taken into the dead zone it left no backlash, and the
    # record was refused. The backlash ends between the plateau and the unloading pieces:
    # (16.0 + 16.5) / 2 = 16.25 deg
    from hystcli.identify import current as IC

    xb = np.arange(0.0, 123.0, 0.5)
    pieces = [(0, 2), (2, 33), (33, 116), (116, 136), (136, 246)]
    width, held, _ = IC._plateau(pieces, [234.0, 0.01, 4.01, -0.01, 20.5], xb, 0.05, True, 3)
    assert held and width == pytest.approx(16.25)
    # a pretensioned dead zone that softens piece by piece (design seed 1752, a stretch-following
    # current: no backlash in it) has no level piece before its gentle pieces: no plateau is read
    assert IC._plateau([(0, 12), (12, 26), (26, 45), (45, 52), (52, 62)], [4.56, 1.59, 1.28, 0.45, 5.81],
                       xb, 0.05, True, 3)[0] is None


def test_a_motor_friction_flip_spread_by_a_slow_turn_is_no_backlash():
    # read_current's pieces of one stretch from a reversal (hand-built from held-out 2100090's,
    # bins of 0.5 deg): a steep fall (11.9 mA/deg, 0.25-2.25 deg), the unloading (4.5 over 42 deg),
    # the dead zone (1.0), the loading (3.8). A sine sweep of 51 deg amplitude at 3.2 deg/s turns
    # so slowly that the motor's own Coulomb friction flips over the first 1.6 deg (where the knob
    # is slower than a quarter of its peak speed): the fall is that flip, 2.0 deg long, no
    # sheath's. The plant's current follows the tendon's stretch and carries no backlash; read as
    # a flip, b_pos came back 2.44 deg against the tip's 7.81.
    from hystcli.identify import current as IC

    xb = np.arange(0.25, 103.0, 0.5)
    pieces = [(0, 5), (5, 90), (90, 107), (107, 200), (200, 205)]
    slopes = [11.87, 4.48, 0.99, 3.8, -3.75]
    assert IC._plateau(pieces, slopes, xb, 0.05, True, 2, slow_until=1.6)[0] is None
    # the same fall where the knob was brisk from the reversal on goes past the motor's flip: a
    # sheath's flip over the backlash, which ends where the unloading begins, (2.25 + 2.75) / 2
    width, held, _ = IC._plateau(pieces, slopes, xb, 0.05, True, 2, slow_until=0.0)
    assert width == pytest.approx(2.5) and not held


def test_current_only_refuses_the_backlash_of_a_slow_turn_on_a_stretch_law():
    # held-out plant 2100090 (examined after the 2100000 range's figures; design data since): its
    # current follows the tendon's stretch, so no backlash is in it; stop 22's code returned b_pos
    # 5.4 deg off at +-0.25 (exit 0)
    from hystcli.io import parse_run
    from hystcli.zoo import plants

    case = plants.sweep_case(2100090, tip=False)
    fit = identify(parse_run(case.record.csv_text(), source="z"), use_tip=False).fits[1]
    _assert_backlash_unfixed(fit, case.truth, "b_pos")


def test_a_loading_edge_after_a_gentle_unloading_is_fitted_on_the_dead_zone_alone():
    from hystcli.current import loading_edge

    # one ascending stretch from a reversal, by hand: the other tendon's load held at -75 mA over
    # 16 deg, unloaded at 3 mA/deg to the no-load level 0 at 41 deg, the dead zone to 50 deg, the
    # tendon taken up at 20 mA/deg. The unloading is within a fifth of the jump of the dead zone's
    # slope; fitted as part of the flat it put the edge 0.4 deg late with a residual of 34 noise
    # sigmas
    rng = np.random.default_rng(0)
    x = np.arange(0.0, 70.0, 0.5)
    c = np.where(x < 16, -75.0, np.where(x < 41, -75.0 + 3.0 * (x - 16), 0.0)) + np.where(x > 50, 20.0 * (x - 50), 0.0)
    kink = loading_edge(x, c + rng.normal(0.0, 0.2, x.size), 1, 0.2, minlen=2, resolution=0.05)
    assert abs(kink.at - 50.0) < 0.1
    assert kink.residual < 2 * 0.2


def test_a_loading_edge_after_an_unloading_from_the_reversal_is_fitted_on_the_dead_zone_alone():
    from hystcli.current import loading_edge

    # as above without the held load: a drop law's tendon unloading from the reversal on, at
    # 6 mA/deg over 30 deg (0.15 of the jump, so it may pass for a tilted dead zone, and no level
    # piece before it to call it an unloading), the dead zone to 43 deg, the tendon taken up at
    # 40 mA/deg (design sweep 3800430: fitted as one line with the dead zone it put d_pos 1.1 deg
    # late, at a residual of 60 noise sigmas)
    rng = np.random.default_rng(1)
    x = np.arange(0.0, 62.0, 0.5)
    c = np.where(x < 30, -180.0 + 6.0 * x, 0.0) + np.where(x > 43, 40.0 * (x - 43), 0.0)
    kink = loading_edge(x, c + rng.normal(0.0, 0.2, x.size), 1, 0.2, minlen=2, resolution=0.05)
    assert abs(kink.at - 43.0) < 0.1
    assert kink.residual < 2 * 0.2


@pytest.mark.parametrize("seed", [3800430, 2109, 1691])
def test_current_only_places_an_edge_after_an_unloading_from_the_reversal_on_the_dead_zone(seed):
    # independent plants (design seeds: a spiky drop law, a drop law, a coulomb-viscous one): the
    # stretch from each reversal unloads the other tendon at once, at a share of its loaded
    # slope, into the dead zone; stop 32's code fitted that unloading as part of the flat and
    # returned an edge 1.1, 1.0 and 1.9 deg late at +-0.25 (exit 0)
    case, fit = _zoo_current_fit(seed)
    names = [n for n in ("d_pos", "d_neg") if n in fit.stderr]
    assert names
    _assert_within(fit, case.truth, names, tol=0.25)


def test_current_only_reads_a_held_plateau_before_a_gentle_unloading():
    # independent drop-at-reversal plant (design seed 2098): after each reversal the current drops,
    # holds for the backlash (10.6 and 16.4 deg) and unloads five times more gently than it loads.
    # The reading took that unloading into the dead zone and refused both backlashes
    case, fit = _zoo_current_fit(2098)
    _assert_within(fit, case.truth, ("d_pos", "d_neg", "b_pos", "b_neg"), tol=0.25)


def test_current_only_an_unloading_kink_does_not_pull_the_no_load_level_off_the_true_edges():
    # independent tip-load plant (design seed 1802): after one reversal the other tendon's held
    # load starts to unload with a kink that looks like an edge. The no-load level was the median
    # of the edges' levels alone, halfway between that kink and the true edge, and both fell
    # outside it; the record's first stretch, the fallback, then carried the unloading kink too
    case, fit = _zoo_current_fit(1802)
    _assert_within(fit, case.truth, ("d_pos", "b_pos", "b_neg"))


def test_current_only_refuses_an_edge_that_most_stretches_through_it_did_not_show(monkeypatch):
    # independent pretensioned plant (design seed 742): of the three stretches from a reversal that
    # moved through d_pos, one showed a kink (0.65 deg early); it was returned as d_pos, and b_neg
    # read with it 1.1 deg short. Since stop 31 a second stretch shows the take-up past a bend of
    # its dead zone (read_current's second reading), and the two agree with the truth
    from hystcli.identify import current as reading
    from hystcli.io import parse_run
    from hystcli.zoo import plants

    case = plants.sweep_case(742, tip=False)
    run = parse_run(case.record.csv_text(), source="z")
    fit = identify(run, use_tip=False).fits[1]
    err = abs(fit.model.d_pos - case.truth.d_pos)
    assert err <= 0.5 and err <= 2.0 * fit.stderr["d_pos"]
    assert "b_neg" not in fit.stderr or abs(fit.model.b_neg - case.truth.b_neg) <= 1.0
    # the rule itself, on the stretches as read without the second reading: one kink of the three
    # stretches through the edge is refused
    first_reading = reading.read_stretch

    def without_second_reading(*args, **kw):
        kw.pop("fallback", None)
        kw.pop("edge_after", None)
        return first_reading(*args, **kw)

    monkeypatch.setattr(reading, "read_stretch", without_second_reading)
    with pytest.raises(IdentificationError, match=r"d_pos is not an edge \(only 1 of the 3 stretches"):
        identify(run, use_tip=False)


def test_a_flat_the_tip_sat_at_since_the_records_start_does_not_place_its_edge():
    from hystcli.io import parse_run
    from hystcli.zoo import plants

    # held-out plant 1900387 (examined in stop 22; pretensioned, one cycle, started with the
    # negative tendon taut at -2.51 deg, the tip held at 1.90 deg): its only rising pass through
    # the dead zone is from that start. The fit joined its rising flat 0.014 deg of tip above the
    # start and put d_pos 0.68 deg off (2.15, true 1.47) at +-0.01 deg: a start state held above
    # a lower flat, with the edge slid along the same loaded line, fits the record as well
    case = plants.sweep_case(1900387)
    fit = _fit_or_refusal(parse_run(case.record.csv_text(), source="z"))
    if fit is None:     # refused, naming what it cannot fix: nothing claimed (see _fit_or_refusal)
        return
    assert "d_pos" not in fit.stderr
    assert any("d_pos is not fixed by this record" in w and "record's start" in w for w in fit.warnings)
    for name in ("d_neg", "omega"):
        assert abs(getattr(fit.model, name) - getattr(case.truth, name)) <= 0.5, name


def test_current_only_a_plateau_on_the_records_last_stretch_alone_is_weighed_with_the_complete_ones():
    # independent plant (design seed 184, drop-at-reversal law without a hold: no backlash in its
    # current): neither of the two complete stretches down from the top reversal showed a
    # plateau, and the stretch cut by the record's end did (8.2 deg against no backlash); taken
    # alone because no complete one showed it, b_pos came back 4.9 deg off the tip's b_pos. It
    # is one of three now, and left unfixed
    case, fit = _zoo_current_fit(184)
    assert not case.current_shows_backlash
    _assert_backlash_unfixed(fit, case.truth, "b_pos")


@pytest.mark.parametrize("seed", [312, 992])
def test_current_only_a_corner_piece_at_the_edge_is_no_loaded_run_before_a_wall(seed):
    from hystcli.identify import current as IC

    # independent stretch-law plants (design seeds): the corner at each edge made a 0.5-1 deg
    # piece of its own between the flat and the loaded slope (312: 1.8-2.1 mA/deg before 10.5);
    # read as the loaded run, with the loaded slope after it for a wall, it left the kink too few
    # points: 312's stretches down read no edge, 992's up read none on two and 0.43 deg early on
    # the third. A wall ends the loaded run only after WALL_MIN_RUN deg of it: every stretch through
    # each edge now reads it, and both edges are claimed within 0.2 deg
    case, fit = _zoo_current_fit(seed)
    assert case.family == "stretch" and IC.WALL_MIN_RUN == 3.0
    for side, d in (("pos", 1), ("neg", -1)):
        through = [s for s in fit.current.stretches if s.direction == d and s.from_reversal]
        assert through and all(s.edge is not None for s in through[:2]), (side, [s.edge for s in through])
    _assert_within(fit, case.truth, ("d_pos", "d_neg"), tol=0.2)


def test_current_only_a_fall_on_the_records_cut_stretch_alone_is_no_backlash():
    # independent plant (3000175, a pretensioned drop law whose current carries no backlash;
    # looked at after the 3000000 range's figures): the complete stretch up from the bottom
    # reversal showed no plateau, the stretch cut by the record's end a 28.9-deg "fall", and one
    # of two loaded reversals passed the half-of-them rule (b_neg 21.6 deg off, exit 0). Where a
    # complete stretch could have shown it, only a held plateau on the cut one counts
    case, fit = _zoo_current_fit(3000175)
    assert not case.current_shows_backlash
    _assert_backlash_unfixed(fit, case.truth, "b_neg")


@pytest.mark.parametrize("seed,name,edges", [
    # design sweep 1990 (a Coulomb-viscous stretch law, whose current carries no backlash): on the
    # stretch cut by the record's end the motor's own flip fell too briefly for its slope to be read,
    # and b_pos came back 2.21 deg against the true loop's 7.24 (exit 0)
    (1990, "b_pos", ("d_pos",)),
    # zoo sweep 4400423 (a wall plant, looked at after the 4400000 range's figures): after the
    # record's first stretch, too short to read its end slope, the wall's elastic give fell at 216
    # mA/deg (the loaded slope 21) and was read as the sheath friction flipping: b_neg 9.41
    # against 2.01 (exit 0)
    (4400423, "b_neg", ("d_pos", "d_neg")),
])
def test_current_only_a_fall_that_cannot_be_weighed_is_no_backlash(seed, name, edges):
    # a fall is told from a load coming back down its own curve (a wall, a stiffening cable) only
    # against the slope the load rose with before the reversal, and its own slope; where either is
    # unknown the fall is not read as a backlash
    case, fit = _zoo_current_fit(seed)
    side = -1 if name == "b_pos" else 1
    falls = [s for s in fit.current.stretches if s.direction == side and s.plateau is not None and not s.plateau_held]
    assert falls and all(abs(s.plateau - getattr(case.truth, name)) > 2.0 for s in falls)
    assert name not in fit.stderr and name in fit.ident.unfixed
    assert any("the current cannot fix" in w and name in w for w in fit.warnings)
    _assert_within(fit, case.truth, edges)


@pytest.mark.parametrize("seed", [2010, 2513, 4500265])
def test_current_only_reads_a_stiffening_take_up_again_around_its_kink(seed):
    # a stiffening stretch law swept far past its edges (design sweep 2513, +-34 deg; zoo sweep
    # 4500265, +-44 deg, looked at after the 4500000 range's figures): the segmentation spent its
    # pieces on the loaded curves, and one piece ran from the other tendon's unloading through
    # the flat into the take-up, read as a dead zone climbing at 11-12.5 mA/deg; the kink out of
    # it was 1.4-1.5 deg late (returned at +-0.25-0.28, exit 0). Read again around the kink, the
    # take-up comes out of a flat piece. Design sweep 2010 (its soft take-up read 1.0 deg late,
    # then refused as a curve by DEAD_TILT) comes out right the same way
    case, fit = _zoo_current_fit(seed)
    assert case.family == "stiffening"
    read = [s.edge for s in fit.current.stretches if s.edge is not None and s.from_reversal]
    assert read and all(abs(k.before) < 0.1 * k.after for k in read)
    _assert_within(fit, case.truth, ("d_pos", "d_neg"), tol=0.3)


def test_current_only_a_kink_before_its_own_stretchs_arrival_is_no_loading_edge():
    # independent plant (3000219, drop law with a hold, one cycle of +-7.6 deg at 77 deg/s; looked
    # at after the 3000000 range's figures): on the one stretch up from the bottom reversal the
    # negative tendon's held load ends at -3.3 deg and its unloading meets the dead zone at -0.5;
    # the stretch turns 0.7 deg past d_pos (5.1). The kink where the hold ended was taken for d_pos,
    # 8.4 deg off at +-0.09. A tendon is taken up after the other one has unloaded, never before:
    # the edge is not read, and the record cannot show d_pos
    from hystcli.io import parse_run
    from hystcli.zoo import plants

    case = plants.sweep_case(3000219, tip=False)
    with pytest.raises(IdentificationError, match="never clearly shows the positive tendon taken up"):
        identify(parse_run(case.record.csv_text(), source="z"), use_tip=False)


def test_current_only_judges_a_one_cycle_kink_against_the_first_stretchs_level():
    # zoo sweep 4600157 (a drop law holding a 16-deg backlash; one slow sine cycle; looked at after
    # the 4600000 range's figures): on the one stretch up from the bottom reversal the negative
    # tendon's held load ends at +1.4 deg, 96 mA below the no-load level, and that kink was read as
    # d_pos (true +12.0), returned at +-0.11 with exit 0; detect-shift then put the shift 10.6 deg
    # off. With no other stretch from a reversal the kink had been judged against its own level;
    # the first stretch's take-up gives the no-load level, the kink is a hold ending, and d_pos is
    # refused
    from hystcli.io import parse_run
    from hystcli.zoo import plants

    case = plants.sweep_case(4600157, tip=False)
    with pytest.raises(IdentificationError, match="never clearly shows the positive tendon taken up"):
        identify(parse_run(case.record.csv_text(), source="z"), use_tip=False)


def test_current_only_refuses_a_dead_zone_narrower_than_its_edges_can_tell():
    # independent plant (3100394, a drop law with a steep pretension, 4.6 mA/deg in a 13.5-deg dead
    # zone, two cycles of +-10 deg at 70 deg/s; looked at after the 3100000 range's figures): the
    # kink where the negative tendon's unloading ended was read as d_pos, 0.25 deg from d_neg,
    # and returned 12.5 deg off. A dead zone that narrow cannot tell the two kinks apart: refused
    from hystcli.io import parse_run
    from hystcli.zoo import plants

    case = plants.sweep_case(3100394, tip=False)
    with pytest.raises(IdentificationError, match=r"leave a dead zone of 0\.\d\d deg .* narrower than"):
        identify(parse_run(case.record.csv_text(), source="z"), use_tip=False)


@pytest.mark.parametrize("seed,name", [
    # independent plants whose current carries no backlash, with a pretensioned (tilted) dead zone,
    # design seeds looked at for this rule: after the top reversal the current fell straight back
    # to the dead zone, and the segmentation took that fall for the sheath friction flipping over a
    # backlash, with the dead zone's tilt as the "unloading" (before: b_pos 8.02 / 13.06 / 5.21
    # returned, 7.3, 12.1 and 2.7 deg off the true loop's backlash, exit 0)
    (199, "b_pos"), (1411, "b_pos"), (2017, "b_pos"),
])
def test_current_only_a_fall_into_a_tilted_dead_zone_is_no_backlash(seed, name):
    # a flip over the backlash is followed by the tendon unloading, clearly steeper than the dead
    # zone; an "unloading" no steeper than the dead zone is the dead zone itself
    case, fit = _zoo_current_fit(seed)
    assert not case.current_shows_backlash
    _assert_backlash_unfixed(fit, case.truth, name)


def test_current_only_a_kink_with_a_tenth_of_the_records_loaded_slope_is_no_edge():
    # independent plant (design seed 2863, a stretch law, two cycles of +-8.6 deg): the only
    # positive kink left after the level rules sat on the stretch cut by the record's end, 0.1
    # mA/deg after it against 3.4 to 6.7 on the record's other take-ups; returned as d_pos, 2.5 deg
    # off at exit 0. A tendon loads the motor at its stiffness on every take-up: refused instead
    from hystcli.io import parse_run
    from hystcli.zoo import plants

    case = plants.sweep_case(2863, tip=False)
    with pytest.raises(IdentificationError, match="never clearly shows the positive tendon taken up"):
        identify(parse_run(case.record.csv_text(), source="z"), use_tip=False)


def test_current_only_a_weak_kink_does_not_outvote_the_edge():
    # independent plant (design seed 2594, spiky): one stretch read a kink 16 deg off the negative
    # edge with a loaded slope of 0.03 mA/deg (the record's take-ups: 4 to 10); with it among the
    # readings the edge was refused. Left out, d_neg is read within a degree
    case, fit = _zoo_current_fit(2594)
    _assert_within(fit, case.truth, ("d_pos", "d_neg"))


def test_a_kink_on_the_records_cut_last_stretch_does_not_outvote_the_first_stretch():
    # zoo sweep 3600467 (a stiffening cable whose current follows its stretch): one cycle from
    # -10.3 deg up to +18.2, down to -18.2, and up again to -10.5 where the record ends. That last
    # stretch, cut 5.3 deg into the dead zone, showed a kink at -14.1 deg, the only edge read
    # moving up from a reversal, and identify --current-only returned d_pos -14.1 with a standard
    # error of 0.18 against a true +8.13 (the first stretch had it at +8.06). A cut stretch cannot
    # show that no flat follows its kink; against the first stretch's edge, neither is trusted:
    # the first stretch's edge is returned as an estimate, unclaimed
    case, fit = _zoo_current_fit(3600467)
    last = fit.current.stretches[-1]
    assert last.direction == 1 and last.edge is not None and abs(last.edge.at - case.truth.d_pos) > 20
    assert "d_pos" not in fit.stderr and "d_pos" in fit.ident.unfixed
    assert any("only the record's first stretch shows the positive tendon" in w for w in fit.warnings)
    assert abs(fit.model.d_pos - case.truth.d_pos) <= 0.5
    _assert_within(fit, case.truth, ("d_neg",))


def test_current_only_does_not_read_the_low_pass_ringing_after_a_drop_as_a_held_load():
    from hystcli.io import parse_run
    from hystcli.zoo import plants

    # design sweep 3800181 (a drop law, examined in stop 32): the force drops by 300 mA as the
    # knob reverses at 47 deg/s, holds for b_pos = 0.39 deg and unloads. Our 20 Hz conditioning
    # low-pass undershoots after that step and recovers over 50 ms, 2.3 deg of knob, which lay
    # level as a held load does: b_pos was returned 2.34 deg at +-0.3 (1.96 off, exit 0). The
    # plateau after a step must now go on past the filter's ringing; this one does not show
    case = plants.sweep_case(3800181, tip=False)
    assert case.family == "drop-at-reversal"
    fit = identify(parse_run(case.record.csv_text(), source="z"), use_tip=False).fits[1]
    _assert_within(fit, case.truth, ("d_pos", "d_neg"))
    assert "b_pos" not in fit.stderr or abs(fit.model.b_pos - case.truth.b_pos) <= 1.0


def test_the_ringing_guard_follows_a_step_only():
    from hystcli.current import condition
    from hystcli.identify.current import _ring_until

    # a knob turning back at 40 deg/s from a reversal at t = 0.2 s, sampled at 1 kHz; the current
    # unloads at 10 mA/deg, after a 200 mA drop at the reversal or without one. The 20 Hz low-pass
    # rings for 1/20 s after a step: 2 deg of knob from the step on (hand-computed: 40 * 0.05)
    t = np.arange(0.0, 1.0, 1e-3)
    x = 40.0 * np.clip(t - 0.2, 0.0, None)
    ramp = 500.0 - 10.0 * x
    stretch = t >= 0.2
    for drop, expect in ((200.0, 2.0), (0.0, 0.0)):
        c = condition(np.where(stretch, ramp - drop, 500.0 + 10.0 * 40.0 * (t - 0.2)), 1000.0, 20.0)
        got = _ring_until(x[stretch], c[stretch], t[stretch], 1.0 / 20.0)
        assert got == pytest.approx(expect, abs=0.15), drop
    # without the low-pass there is nothing to ring
    assert _ring_until(x[stretch], np.where(stretch, ramp - 200.0, 0.0)[stretch], t[stretch], 0.0) == 0.0


def _cogging_record(seed: int, phase: float, amplitude: float = 3.0, period: float = 3.6) -> Run:
    """A current-only sweep written here from the physics: two cycles of +-25 deg, a current that
    follows the tendon's stretch past d_pos = 6 and d_neg = -9 deg (9 and 7 mA/deg, no backlash
    in it), the motor's Coulomb friction (25 mA, spread over 1.5 deg/s) and its cogging: a ripple
    of ``amplitude`` mA every ``period`` deg of knob, plus 0.5 mA of noise, logged to 0.1 mA."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 2 * 2 * np.pi / 0.3 + 1.0, 1 / 200.0)
    q = 25.0 * np.sin(0.3 * t + 0.4)
    v = np.gradient(q, t)
    c = (20.0 + 9.0 * np.maximum(q - 6.0, 0.0) - 7.0 * np.maximum(-9.0 - q, 0.0) + 25.0 * np.tanh(v / 1.5)
         + amplitude * np.sin(2 * np.pi * q / period + phase) + rng.normal(0.0, 0.5, q.size))
    return Run({"t": t, "q1": q, "c1": np.round(c, 1)})


@pytest.mark.parametrize("phase", [1.5, 3.0, 4.5])
def test_current_only_reads_the_edges_with_the_motors_cogging_taken_out(phase):
    # the ripple's crests and troughs bend the current beside each edge: read as it is, stop 34's
    # code put d_neg at -7.90 (phase 1.5) and -8.84 (3.0) against -9, and refused the record at
    # phase 4.5 (the crest before d_pos read as a dead zone that curves into the edge). The
    # ripple is read on the dead zone the first reading bounds, and the current read again
    fit = identify(_cogging_record(0, phase), use_tip=False).fits[1]
    assert fit.model.d_pos == pytest.approx(6.0, abs=0.1)
    assert fit.model.d_neg == pytest.approx(-9.0, abs=0.1)
    # a current that follows the tendon's stretch carries no backlash: none is claimed
    assert "b_pos" not in fit.stderr and "b_neg" not in fit.stderr
    # the model keeps the ripple for detect-shift (it is taken out of the search's readings too)
    assert fit.ident.cogging_period == pytest.approx(3.6, rel=0.02)


def test_a_ripples_trough_after_a_reversal_is_no_backlash_plateau():
    # design plant 566 (coulomb-viscous on a stretch law, a 3.7-mA ripple every 3.83 deg): the
    # ripple's trough after the negative reversal lay flat for 2 deg, and stop 34's code returned
    # b_neg 1.98 +- 0.38 against 13.05 (a current that follows the stretch carries no backlash)
    from hystcli.io import parse_run
    from hystcli.zoo import plants

    case = plants.sweep_case(566, tip=False)
    fit = identify(parse_run(case.record.csv_text(), source="z"), use_tip=False).fits[1]
    _assert_backlash_unfixed(fit, case.truth, "b_neg")
    _assert_within(fit, case.truth, ("d_pos", "d_neg"), tol=0.25)


def test_a_dead_zone_that_bends_over_two_periods_is_not_read_as_cogging():
    # design plant 3900435 (stiffening): a dead zone 26 deg wide whose current bends once across
    # it fits a 13.8-deg "ripple" of 15 mA; taken out, the current showed no edge at all. Cogging
    # repeats: fewer than three periods over the dead zone are not read as it
    from hystcli.io import parse_run
    from hystcli.zoo import plants

    case = plants.sweep_case(3900435, tip=False)
    fit = identify(parse_run(case.record.csv_text(), source="z"), use_tip=False).fits[1]
    # its d_pos (18.65 against 15.04) only the record's first stretch shows: an estimate, unclaimed
    assert "d_pos" not in fit.stderr
    _assert_within(fit, case.truth, ("d_neg",), tol=0.1)


def test_current_only_a_walls_steep_take_up_out_of_a_loaded_slope_is_read_again_before_it():
    # zoo sweep 4600064 (a wall on the negative side, a stretch law, noise 0.005 mA): on both
    # stretches down from the top reversal the segmentation merged the dead zone's flat and the
    # negative tendon's loading (18 mA/deg) into one piece at 5.9 mA/deg, and read the wall's
    # contact at -13.77 deg (296 mA/deg after it) as the take-up. d_neg came back 9.35 deg off at
    # +-0.21, exit 0. A take-up more than LOADED_BAND times steeper than the record's other ones,
    # out of a slope already a tenth of theirs, is a wall's; the stretch is read again before it
    from hystcli.identify.current import LOADED_BAND

    case, fit = _zoo_current_fit(4600064)
    down = [s for s in fit.current.stretches if s.from_reversal and s.direction == -1 and s.edge is not None]
    ups = [s.loaded_slope for s in fit.current.stretches if s.from_reversal and s.direction == 1]
    assert down and all(abs(s.edge.at - case.truth.d_neg) <= 0.5 for s in down)
    assert all(s.loaded_slope <= LOADED_BAND * float(np.median(ups)) for s in down)
    _assert_within(fit, case.truth, ("d_pos", "d_neg"), tol=0.5)


def test_current_only_a_faint_kink_on_one_stretch_carries_an_honest_uncertainty():
    # design sweep 2391 (Coulomb and viscous friction): each edge read by one stretch from a
    # reversal, at clarities of 10.7 (d_pos) and 7.6 (d_neg), 0.71 and 0.52 deg off, with standard
    # errors of 0.13 and 0.20 from the two-line fit: 5.5 and 2.6 sigma out. A faint kink is placed
    # no better than KINK_SPAN over its clarity: the truth is now within two standard errors
    from hystcli.identify.current import KINK_SPAN

    case, fit = _zoo_current_fit(2391)
    for name, d in (("d_pos", 1), ("d_neg", -1)):
        at = getattr(fit.model, name)
        ks = [s.edge for s in fit.current.stretches if s.from_reversal and s.direction == d and s.edge is not None
              and abs(s.edge.at - at) <= 1.0]
        assert len(ks) == 1 and ks[0].clarity < 15
        assert abs(at - getattr(case.truth, name)) > 0.5
        assert fit.stderr[name] >= KINK_SPAN / ks[0].clarity
        assert abs(at - getattr(case.truth, name)) <= 2 * fit.stderr[name]


def test_a_cogging_ripple_is_read_on_the_knobs_dead_zone_where_the_tips_flats_are_short():
    # held-out zoo replay 4800006's straight sweep (hystcli.zoo.plants, coulomb-viscous: a cogging
    # ripple of 1.446 mA every 3.0015 deg of knob, the plant's drawn factors): backlash plateaus of
    # 4.9 and 2.0 deg in an 11.8-deg dead zone leave the tip's flats 3 deg long, one period, where
    # no ripple is read; the knob's dead zone holds four
    from hystcli.identify import current_levels
    from hystcli.io import parse_run
    from hystcli.zoo import plants

    case = plants.replay_case(4800006)
    law, tr = case.factors["sweep"], case.truth
    run = parse_run(case.straight_sweep.csv_text(), source="straight-4800006")
    km = KnobModel(d_pos=tr.d_pos, d_neg=tr.d_neg, b_pos=tr.b_pos, b_neg=tr.b_neg, omega=tr.omega,
                   h_pos=tr.h_pos, h_neg=tr.h_neg)
    ripple = current_levels(run, 1, km).ripple
    assert ripple is not None
    assert ripple.period == pytest.approx(law["ripple_period"], rel=0.02)
    assert math.hypot(ripple.sin, ripple.cos) == pytest.approx(law["ripple_amp"], rel=0.1)


def test_a_wave_of_fewer_than_three_periods_on_the_knobs_dead_zone_is_no_cogging():
    # design replay 3900435's straight sweep (hystcli.zoo.plants, a stiffening cable holding the
    # tip's load on backlash plateaus of 14.2 and 10.7 deg in a 22.5-deg dead zone; the plant
    # draws no cogging: ripple_amp 0): on the knob's whole dead zone the held loads and the
    # stiffening bend fit a 16-mA wave every 13.5 deg, 1.6 periods of it, both ways alike. Taken
    # for cogging it moved detect-shift's offset from 0.15 to 0.32 deg off
    from hystcli.identify import current_levels
    from hystcli.io import parse_run
    from hystcli.zoo import plants

    case = plants.replay_case(3900435)
    assert case.factors["sweep"]["ripple_amp"] == 0.0
    tr = case.truth
    run = parse_run(case.straight_sweep.csv_text(), source="straight-3900435")
    km = KnobModel(d_pos=tr.d_pos, d_neg=tr.d_neg, b_pos=tr.b_pos, b_neg=tr.b_neg, omega=tr.omega,
                   h_pos=tr.h_pos, h_neg=tr.h_neg)
    assert current_levels(run, 1, km).ripple is None


def test_a_take_up_split_off_by_a_short_corner_piece_is_still_read():
    # independent plant (zoo seed 5000211, examined at stop 44, design data since): a one-cycle
    # tip-load sweep whose only pass up through d_pos = 15.01 deg is its first stretch. The
    # segmentation split a 0.5-deg corner piece (7 mA/deg) off before the loaded 18 mA/deg, and
    # the clear take-up out of the flat was dropped: identify refused "never clearly shows the
    # positive tendon taken up". Read over the corner and the piece after it, the edge is found;
    # it comes from the first stretch only, so it is an estimate, unclaimed.
    case, fit = _zoo_current_fit(5000211)
    assert abs(fit.model.d_pos - case.truth.d_pos) <= 0.1
    assert "d_pos" not in fit.stderr and "d_pos" in fit.ident.unfixed
    assert any("only the record's first stretch shows the positive" in w for w in fit.warnings)
    assert abs(fit.model.d_neg - case.truth.d_neg) <= 3 * fit.stderr["d_neg"] + 0.1


def test_walls_that_hold_every_sample_are_no_wall_the_plain_fit_stands():
    from hystcli.io import parse_run
    from hystcli.zoo import plants

    # fresh zoo range 5100000, sweep 5100482 (a drop law whose sweep reaches each edge by under
    # a degree): the walls find_walls reported censored every sample of the tip fit's search, and
    # the grid kernel divided by zero (a traceback out of identify). Such walls are no wall: the
    # plain fit stands, and it says the sweep does not pass the edges.
    case = plants.sweep_case(5100482)
    with pytest.raises(IdentificationError, match="cannot fix d_pos"):
        identify(parse_run(case.record.csv_text(), source="zoo"))


def test_fit_tip_refuses_walls_that_leave_no_free_loop():
    from hystcli.errors import ModelError
    from hystcli.identify.tip import NoFreeLoop, fit_tip

    q = np.concatenate([np.linspace(0, 30, 200), np.linspace(30, -30, 400), np.linspace(-30, 0, 200)])
    y = np.clip(q, -10, 10)
    # a bottom wall above every sample: each one is "held", none is free
    with pytest.raises(NoFreeLoop, match="free samples") as err:
        fit_tip(q, y, walls=(20.0, None))
    assert isinstance(err.value, ModelError)      # a HystError still, should it reach the CLI
