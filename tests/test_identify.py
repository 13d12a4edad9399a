"""Tests of hystcli.identification: the loop that predicts a sweep, each parameter with its interval, an
interval (not a refusal) where the record cannot fix a parameter, walls, the current-only path
and its refusal, the model file, the command line, sweep checks, determinism and the figure.

References: the twin's true parameters (hystcli.sim.twin's example catheters, the calibrated ice-a
written out below), the independent plant zoo's truths (plants.zoo.plants), and currents and tips
built in the tests; never an output of identify.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from hystcli.sim import twin
from hystcli.cli import app
from hystcli.errors import DataError, IdentificationError
from hystcli.identification import check_sweep, find_reversals, identify, plot_identification
from hystcli.core.run import Run
from hystcli.io import load_model, parse_run, read_run, save_model, write_run
from hystcli.core.params import Geometry, KnobModel, PAPER_OMEGA
from hystcli.settings import DEFAULT
from plants.zoo import plants

ROOT = Path(__file__).resolve().parents[1]
SWEEP = ROOT / "sample_data" / "ice-a" / "sweep_knob1.csv"
runner = CliRunner()

# The calibrated ice-a's knob 1 (hystcli/sim/calibration.py), written out so that the reference does
# not come from the code: dead zone +-18.8 deg, backlash 9.88 deg, omega 1.45, heights from the
# taut-tendon rule h = omega (b_pos + b_neg) / 4 = 7.163 deg.
ICE_A_1 = dict(d_pos=18.8, d_neg=-18.8, b_pos=9.88, b_neg=9.88, omega=1.45,
               h_pos=-0.25 * 1.45 * 19.76, h_neg=0.25 * 1.45 * 19.76)
LAG_S = 0.025   # the calibrated catheters' tendon lag (their `rate` effect, tau)

EXAMPLE_A = twin.get_catheter("example-a")   # knob 1: d 9.1 / -8.7, b 6.2 / 5.9, omega 1.45, h -4.0 / 4.2


def sine_sweep(lo: float, hi: float, cycles: float = 2.0, speed: float = 40.0, fs: float = 1000.0):
    """A sine between ``lo`` and ``hi`` starting at the middle going up."""
    amp, mid = 0.5 * (hi - lo), 0.5 * (hi + lo)
    w = speed / amp
    t = np.arange(int(round(cycles * 2 * math.pi / w * fs)) + 1) / fs
    return t, mid + amp * np.sin(w * t)


def example_run(lo: float, hi: float, cycles: float = 2.0, seed: int = 3) -> Run:
    """Knob 1 of the twin's example-a (no unmodelled effects) swept between ``lo`` and ``hi``."""
    t, q = sine_sweep(lo, hi, cycles)
    return twin.simulate(EXAMPLE_A, t, {1: q}, seed=seed, effects=())


def truth_loop(params: dict, q: np.ndarray, y0: float) -> np.ndarray:
    """The tip a loop predicts, by the independent zoo's clamp recursion (not hystcli.core)."""
    return plants.KnobTruth(**params).forward(q, y0)


# --------------------------------------------------------------------------------------------
# the sample sweep (the twin with its unmodelled effects) and the same protocol without them
# --------------------------------------------------------------------------------------------
def test_the_truth_written_here_is_the_calibrations():
    from hystcli.sim.calibration import calibrated_catheter

    got = calibrated_catheter("ice-a").knobs[1]
    for name, v in ICE_A_1.items():
        assert getattr(got, name) == pytest.approx(v, abs=1e-9), name


@pytest.fixture(scope="module")
def sample():
    run = read_run(SWEEP)
    return run, identify(run), identify(run, use_tip=False)


def test_the_sample_sweep_gives_the_loop_that_predicts_it(sample):
    # The sample sweep carries the calibrated catheter's unmodelled effects (26 % of every tip
    # move arrives with a 3.35 s creep, a 25 ms tendon lag): the base loop with the true
    # parameters predicts it at about 4 deg RMS, and the loop that predicts it best is wider and
    # flatter. identify must return that loop, not the truth, and say that something outside
    # the loop is at work. Tolerances: the effects' size (edges 2 deg, backlash 3 deg, omega
    # 0.25, heights 1 deg), where the interval does not hold the truth.
    run, res, _ = sample
    fit = res.fits[1]
    q, y = run["q1"], run["y1"]
    truth_rmse = float(np.sqrt(np.mean((truth_loop(ICE_A_1, q, y[0]) - y) ** 2)))
    assert truth_rmse > 3.0
    assert fit.method == "tip" and fit.rmse < 0.25 * truth_rmse
    tol = {"d_pos": 2.0, "d_neg": 2.0, "b_pos": 3.0, "b_neg": 3.0, "omega": 0.25, "h_pos": 1.0, "h_neg": 1.0}
    for name, e in fit.estimates.items():
        true = ICE_A_1[name]
        assert e.contains(true) or abs(e.value - true) <= tol[name], (name, e)
        assert e.lo <= e.value <= e.hi, (name, e)
        assert e.lo <= getattr(fit.model, name) <= e.hi, (name, e)
    assert any("hyst diagnose" in w for w in fit.warnings)
    # what detect-shift needs is stored with it
    assert res.model.identification[1] is fit.ident and fit.ident.calibration.current_sign == "signed"
    assert set(fit.ident.calibration.current_edges) == {"pos", "neg"}


@pytest.mark.slow
def test_the_same_protocol_without_the_effects_is_recovered_within_every_interval():
    # the calibrated ice-a's knob 1 on the paper's sweep (+-40 deg, 2 cycles, 40 deg/s, 1 kHz),
    # the tracker's noise and filter, no unmodelled effect: the loop is the truth, and every
    # interval holds it (measured: all seven, each within 0.03 deg)
    from hystcli.sim.calibration import calibrated_catheter

    t, q = twin.sweep()
    run = twin.simulate(calibrated_catheter("ice-a"), t, {1: q}, seed=5, effects=())
    fit = identify(run).fits[1]
    for name, e in fit.estimates.items():
        assert e.fixed and e.contains(ICE_A_1[name]), (name, e)
        assert e.halfwidth < 0.1, (name, e)
    # the loop's residual is the tracker's filtered noise: 0.3 deg through a 20 Hz band at 1 kHz
    assert fit.rmse == pytest.approx(0.3 * math.sqrt(40.0 / 1000.0), rel=0.5)


def test_current_only_on_the_sample_sweep_reads_the_edges_late_by_the_tendons_lag(sample):
    # From the current alone: the take-up shows where the tendon, lagging the knob by 25 ms, is
    # taken up; at the edge the sine moves at 40 cos(asin(18.8 / 40)) = 35.3 deg/s, so each edge
    # reads 0.88 deg outward of the truth (the live search, at rest, reads it where it is).
    run, _, res = sample
    fit = res.fits[1]
    assert fit.method == "current" and fit.rmse is not None
    lag = LAG_S * 40.0 * math.cos(math.asin(18.8 / 40.0))
    assert fit.estimates["d_pos"].value - ICE_A_1["d_pos"] == pytest.approx(lag, abs=0.3)
    assert ICE_A_1["d_neg"] - fit.estimates["d_neg"].value == pytest.approx(lag, abs=0.3)
    # the backlash: where the held load after each reversal ends, within a degree (the lag and the
    # sheath's friction flip over 0.5 deg blur its end)
    for name in ("b_pos", "b_neg"):
        e = fit.estimates[name]
        assert e.fixed and abs(e.value - ICE_A_1[name]) <= 1.0, (name, e)
    # omega is given and the heights follow the documented current-only rule: centred, their gap
    # omega times the mean backlash
    m = fit.model
    assert m.omega == PAPER_OMEGA
    assert m.h_pos == pytest.approx(-m.h_neg, abs=1e-12)
    assert m.h_neg - m.h_pos == pytest.approx(m.omega * 0.5 * (m.b_pos + m.b_neg), rel=1e-12)
    assert any("omega 1.45 is assumed" in w for w in fit.warnings)
    assert identify(run, use_tip=False, omega=1.6).model.knob(1).omega == 1.6


def test_a_magnitude_current_is_read_as_one_with_the_same_edges(sample):
    # the same sweep from a drive that reports |I - no-load| (the twin's no-load level is 120 mA)
    run, _, signed = sample
    mag = run.with_columns(c1=np.abs(run["c1"] - 120.0))
    fit = identify(mag, use_tip=False).fits[1]
    assert fit.current.sign == "magnitude" and fit.ident.calibration.current_sign == "magnitude"
    for name in ("d_pos", "d_neg"):
        e, ref = fit.estimates[name], signed.fits[1].estimates[name]
        assert e.fixed and abs(e.value - ref.value) <= 0.1, (name, e, ref)
    # read as signed against the evidence, the falling take-up is not there: no edge is made up,
    # d_neg is left open at the sweep's reach
    forced = identify(mag, use_tip=False, settings=DEFAULT.set_params(current_sign="signed")).fits[1]
    assert forced.current.sign == "signed" and "d_neg" in forced.unfixed
    assert forced.estimates["d_neg"].lo == -math.inf


def test_the_model_file_keeps_the_estimates_and_the_current_edges(sample, tmp_path):
    _, res, _ = sample
    fit = res.fits[1]
    save_model(tmp_path / "m.json", res.model)
    back = load_model(tmp_path / "m.json").identification[1]
    assert dict(back.estimates) == fit.estimates
    assert dict(back.calibration.current_edges) == fit.current.edges
    assert back.method == "tip" and back.rmse == fit.rmse and back.calibration.current_sign == "signed"
    assert back.unfixed == fit.unfixed
    assert back.q_min == pytest.approx(-40.0, abs=1e-6) and back.q_max == pytest.approx(40.0, abs=1e-6)


# --------------------------------------------------------------------------------------------
# what the record cannot fix is an interval; what it cannot show at all is a refusal
# --------------------------------------------------------------------------------------------
@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason=(
    "known limit of the profile walk: on this record d_neg, h_neg and b_pos trade along a ridge of "
    "separate valleys; the walk from the best fit stays in its own valley and its b_pos interval "
    "[8.2, 23.5] misses the truth 6.2, which a refit started at the truth reaches at the best "
    "deviance. A profile that searches across valleys (the global grid with the parameter held) "
    "is the fix; refits from the grid's and the starts' optima did not reach it"))
def test_a_backlash_plateau_the_tip_never_leaves_is_an_open_interval_not_a_refusal():
    # example-a knob 1 swept -40..12: at the top reversal the tip has risen to 1.45 (12 - 9.1)
    # - 4.0 = 0.2 deg, below the falling dead zone's height 4.2, so coming down it stays put until
    # the falling envelope's lower branch (past d_neg) takes it; the branch that starts b_pos
    # below a reversal never touches it. Every b_pos above a bound predicts the record as well.
    fit = identify(example_run(-40.0, 12.0)).fits[1]
    true = EXAMPLE_A.knobs[1]
    b = fit.estimates["b_pos"]
    assert not b.fixed and b.reason and b.hi - b.lo > 2.0
    assert b.contains(true.b_pos)    # b_pos does not change the record's prediction at all
    assert any("does not fix b_pos" in w for w in fit.warnings)
    # what the record does show stays fixed and right
    for name in ("d_pos", "b_neg", "omega", "h_pos"):
        e = fit.estimates[name]
        assert e.fixed and abs(e.value - getattr(true, name)) <= 0.1, (name, e)
    # the model predicts the record as well as the best fit: the chosen b_pos is one of those
    assert fit.rmse < 0.1


@pytest.mark.slow
def test_a_sweep_that_stops_short_of_an_edge_leaves_it_open():
    # up to 8 deg only: the positive edge (9.1) is never reached
    fit = identify(example_run(-40.0, 8.0)).fits[1]
    e = fit.estimates["d_pos"]
    assert not e.fixed and e.lo <= EXAMPLE_A.knobs[1].d_pos <= e.hi and e.lo > 7.0
    assert fit.estimates["b_neg"].fixed


@pytest.mark.slow
def test_a_wall_is_clipped_with_a_warning_and_the_free_loop_recovered():
    # an independent zoo plant whose tip meets a rigid wall on its positive side at 4.92 deg
    case = plants.sweep_case(669)
    assert case.family == "wall" and case.factors["wall_side"] > 0
    fit = identify(parse_run(case.record.csv_text(), source="wall")).fits[1]
    assert any("a wall holds the tip" in w and "hyst diagnose" in w for w in fit.warnings)
    assert fit.tip.walls[0] is None and fit.tip.walls[1] == pytest.approx(case.factors["wall_y"], abs=0.1)
    for name in ("d_pos", "d_neg", "b_pos", "b_neg"):
        e = fit.estimates[name]
        assert e.fixed and abs(e.value - getattr(case.truth, name)) <= 0.1, (name, e)


@pytest.mark.slow
def test_one_cycle_started_at_rest_is_enough():
    # rest -> +40 -> -40 -> rest: no complete ascending branch, yet the output-error fit sees both
    # edges and both backlash plateaus
    fit = identify(example_run(-40.0, 40.0, cycles=1.0)).fits[1]
    true = EXAMPLE_A.knobs[1]
    for name, e in fit.estimates.items():
        assert e.fixed and abs(e.value - getattr(true, name)) <= 0.05, (name, e)


@pytest.mark.slow
def test_y0_is_the_first_measured_tip_angle():
    # crop the paper's sweep at its first descending zero crossing (t = pi): the tip then sits on
    # the descending dead zone at h_neg = 4.2 deg (example-a knob 1), not at the straight tip
    t, q = twin.sweep()
    run = twin.simulate(EXAMPLE_A, t, {1: q}, seed=5, effects=())
    start = int(np.argmin(np.abs(run["t"] - math.pi)))
    cropped = Run({n: v[start:] for n, v in run.columns.items()})
    q, y = cropped["q1"], cropped["y1"]
    assert abs(y[0] - 4.2) < 0.3
    fit = identify(cropped).fits[1]
    assert abs(fit.model.d_pos - 9.1) <= 0.1 and abs(fit.model.b_pos - 6.2) <= 0.1
    head = slice(0, 100)
    assert np.max(np.abs(fit.model.forward(q, y[0])[head] - y[head])) < 0.5
    assert np.min(np.abs(fit.model.forward(q, 0.0)[head] - y[head])) > 3.0


# --------------------------------------------------------------------------------------------
# recovery over random twins (slow: two tip fits per set)
# --------------------------------------------------------------------------------------------
N_SETS = 12


def random_catheter(rng: np.random.Generator, name: str = "random") -> twin.VirtualCatheter:
    """A virtual catheter with random valid parameters on both knobs.

    d_pos in [5, 14], d_neg in [-14, -5], b in [3, 9], omega in [1.2, 1.8]; the dead-zone heights
    are set through dh = (h_neg - h_pos)/omega = mean backlash * U(0.7, 1.3) >= 0 around a random
    centre, which keeps every model valid. The motor-current parameters are drawn too.
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


@pytest.mark.slow
@pytest.mark.parametrize("i", range(N_SETS))
def test_random_twins_are_recovered_by_the_tip_and_by_the_current(i):
    cat = random_catheter(np.random.default_rng(1000 + i), f"random-{i}")
    run = paper_sweep(cat, seed=i)
    tip, cur = identify(run), identify(run, use_tip=False)
    for k in (1, 2):
        true = cat.knobs[k]
        for name, e in tip.fits[k].estimates.items():
            tol = 0.02 * true.omega if name == "omega" else 0.5
            assert e.contains(getattr(true, name)) or abs(e.value - getattr(true, name)) <= tol, (k, name, e)
        # the current alone: the edges where each tendon is taken up, the backlash where the
        # twin's held load after a reversal ends, within a degree; where the current blurs the
        # held load's end, an interval that holds the truth
        for name in ("d_pos", "d_neg", "b_pos", "b_neg"):
            e = cur.fits[k].estimates[name]
            assert (e.fixed and abs(e.value - getattr(true, name)) <= 1.0) or \
                (not e.fixed and e.contains(getattr(true, name))), (k, name, e)


def test_stored_levels_for_detect_shift():
    # the twin's current model (example-a: no-load 120 mA, Coulomb 6 mA, k_load 4 mA/deg, sheath
    # friction mu 0.25): loading slope k_load (1 + mu) = 5 mA/deg once a tendon is taut; moving,
    # the dead zone's current is the no-load level +- the Coulomb friction
    run = example_run(-40.0, 40.0)
    res = identify(run, use_tip=False)
    ident = res.fits[1].ident
    cur = EXAMPLE_A.current
    assert ident.calibration.current_sign == "signed"
    for s in (ident.calibration.slope_loaded_pos, ident.calibration.slope_loaded_neg):
        assert s == pytest.approx(cur.k_load * (1 + cur.mu), rel=0.1)
    assert abs(ident.calibration.slope_dead_zone) < 0.1 * cur.k_load
    assert ident.calibration.no_load_rising == pytest.approx(cur.no_load + cur.coulomb, abs=1.5)
    assert ident.calibration.no_load_falling == pytest.approx(cur.no_load - cur.coulomb, abs=1.5)
    for side, true in (("pos", 9.1), ("neg", -8.7)):
        e = ident.calibration.current_edges[side]
        assert e.fixed and abs(e.value - true) <= 0.5
    assert ident.q_min == pytest.approx(-40.0, abs=1e-3) and ident.q_max == pytest.approx(40.0, abs=1e-3)
    assert dict(res.model.identification) == {k: f.ident for k, f in res.fits.items()}
    assert res.model.meta["method"] == "current"


# --------------------------------------------------------------------------------------------
# the command line
# --------------------------------------------------------------------------------------------
def test_identify_without_output_prints_and_writes_nothing(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    res = runner.invoke(app, ["identify", str(SWEEP), "--current-only"])
    assert res.exit_code == 0, res.output
    assert "d_pos = " in res.stdout and "b_neg = " in res.stdout
    assert list(tmp_path.iterdir()) == []


def test_identify_level_sets_every_interval(tmp_path):
    def intervals(level: str) -> dict:
        res = runner.invoke(app, ["identify", str(SWEEP), "--current-only", "--level", level, "-f", "json"])
        assert res.exit_code == 0, res.output
        return json.loads(res.stdout)["1"]["intervals"]

    lo, mid, hi = intervals("0.9"), intervals("0.95"), intervals("0.99")
    for name in ("d_pos", "d_neg", "b_pos", "b_neg"):
        widths = [d[name]["hi"] - d[name]["lo"] for d in (lo, mid, hi)]
        assert widths[0] < widths[1] < widths[2], (name, widths)
        assert [d[name]["level"] for d in (lo, mid, hi)] == [0.9, 0.95, 0.99]
    res = runner.invoke(app, ["identify", str(SWEEP), "--level", "1.5", "-o", str(tmp_path / "m.json")])
    assert res.exit_code == 2 and "--level" in res.output and not (tmp_path / "m.json").exists()


def test_identify_current_sign_is_read_or_taken_as_told(tmp_path):
    run = read_run(SWEEP)
    write_run(tmp_path / "mag.csv", run.with_columns(c1=np.abs(run["c1"] - 120.0)))

    def sign(*extra: str) -> str:
        res = runner.invoke(app, ["identify", str(tmp_path / "mag.csv"), "--current-only", "-f", "json", *extra])
        assert res.exit_code == 0, res.output
        return json.loads(res.stdout)["1"]["current_sign"]

    assert sign() == "magnitude" and sign("--current-sign", "auto") == "magnitude"
    assert sign("--current-sign", "signed") == "signed"
    out = tmp_path / "m.json"
    res = runner.invoke(app, ["identify", str(tmp_path / "mag.csv"), "--current-only", "--current-sign",
                              "magnitude", "-o", str(out), "-q"])
    assert res.exit_code == 0 and load_model(out).identification[1].calibration.current_sign == "magnitude"
    res = runner.invoke(app, ["identify", str(SWEEP), "--current-sign", "both", "-o", str(tmp_path / "x.json")])
    assert res.exit_code == 2 and not (tmp_path / "x.json").exists()


def test_a_refused_record_is_one_error_line_and_no_file(tmp_path):
    # a drive that logged a constant current: nothing to read a tendon from
    t, q = sine_sweep(-40.0, 40.0)
    write_run(tmp_path / "flat.csv", Run({"t": t, "q1": q, "c1": np.full(t.size, 120.0)}))
    out = tmp_path / "m.json"
    res = runner.invoke(app, ["identify", str(tmp_path / "flat.csv"), "--current-only", "-o", str(out)])
    assert res.exit_code == 1 and "Traceback" not in res.output
    errors = [ln for ln in res.stderr.splitlines() if ln.startswith("Error:")]
    assert len(errors) == 1 and "current c1 is constant" in errors[0], res.stderr
    assert not out.exists()


# --------------------------------------------------------------------------------------------
# sweep checks: every way a sweep can fail to identify, with a message saying what is missing
# --------------------------------------------------------------------------------------------
def test_never_reverses():
    t = np.linspace(0, 4, 4001)
    run = twin.simulate(EXAMPLE_A, t, {1: np.linspace(-40, 40, t.size)}, effects=())
    with pytest.raises(IdentificationError, match="never reverses"):
        identify(run)


def test_constant_signals_and_too_few_samples():
    t, q = twin.sweep()
    with pytest.raises(IdentificationError, match="current c1 is constant"):
        identify(Run({"t": t, "q1": q, "c1": np.full(t.size, 100.0)}))
    with pytest.raises(IdentificationError, match="tip angle y1 is constant"):
        identify(Run({"t": t, "q1": q, "y1": np.full(t.size, 3.0)}))
    good = paper_sweep(EXAMPLE_A, 0, knobs=(1,))
    short = Run({n: v[:50] for n, v in good.columns.items()})
    with pytest.raises(IdentificationError, match=r"too few samples \(50\)"):
        identify(short)


@pytest.mark.slow
def test_knob_columns_and_arguments():
    good = paper_sweep(EXAMPLE_A, 0, knobs=(1,))
    no_c = Run({"t": good["t"], "q1": good["q1"], "y1": good["y1"]}, source="s.csv")
    # the current-only path needs the current ...
    with pytest.raises(IdentificationError, match="s.csv: no knob to identify"):
        identify(no_c, use_tip=False)
    with pytest.raises(IdentificationError, match="column 'c1' is missing"):
        identify(no_c, knobs=[1], use_tip=False)
    # ... the tip fit does not: without a current nothing is read of it
    fit = identify(no_c).fits[1]
    assert fit.method == "tip" and fit.current is None and fit.ident.calibration.current_sign is None
    assert fit.ident.calibration.current_edges == {}
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
    assert set(identify(paper_sweep(EXAMPLE_A, 0), knobs=[2], use_tip=False).fits) == {2}


def test_check_sweep_reports_reversals():
    chk = check_sweep(paper_sweep(EXAMPLE_A, 0, knobs=(1,)), 1)
    # sin over 2 cycles from 0: tops at 1/4 and 5/4 of the period, bottoms at 3/4 and 7/4
    assert list(chk.tops) == [True, False, True, False]
    assert [d for _, _, d in chk.branches] == [-1, 1, -1]
    assert chk.n_cycles == 1


@pytest.mark.slow
def test_identify_is_deterministic():
    run = example_run(-40.0, 40.0, cycles=1.0)
    a, b = identify(run), identify(run)
    assert a.fits[1].estimates == b.fits[1].estimates and a.fits[1].model == b.fits[1].model
    c, d = identify(run, use_tip=False), identify(run, use_tip=False)
    assert c.fits[1].estimates == d.fits[1].estimates


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
def test_plot_identification_writes_a_png(sample, tmp_path):
    run, res, _ = sample
    out = tmp_path / "fit.png"
    plot_identification(run, res, out)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert [p.name for p in tmp_path.iterdir()] == ["fit.png"]  # no temporary left behind
    with pytest.raises(DataError, match="does not exist"):
        plot_identification(run, res, tmp_path / "missing" / "fit.png")
