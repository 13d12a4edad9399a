"""Algorithm 1 (hystcli.shift): the replay probe, offsets on the sample replays, which side an
offset may come from, refusals with their reasons, limits, and the knob's return on every outcome.

References: the twin's true shift (paper eqs. 3-4, in each sample replay's metadata), and edges
placed by hand in the probes below (a signed current law written here, with its truth).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from hystcli.errors import DataError, LinkError, ShiftDetectionError
from hystcli.estimate import Estimate
from hystcli.identification import identify
from hystcli.core.run import Run
from hystcli.io import read_run
from hystcli.core.model import Model
from hystcli.core.params import Calibration, KnobIdentification, KnobModel
from hystcli.shift import (DEFAULT_MAX_TRAVEL, ProbeSample, ReplayExhausted, ReplayProbe, ShiftResult,
                           apply_shift, default_max_travel, detect_shift, plot_shift, reference_of)

SAMPLES = Path(__file__).resolve().parents[1] / "sample_data" / "ice-a"


# --------------------------------------------------------------------------------------------
# the replay probe
# --------------------------------------------------------------------------------------------
def _tiny_run(**extra) -> Run:
    cols = {"t": np.arange(7.0), "q1": np.array([0, 1, 2, 3, 2, 1, 0.0]),
            "c1": np.array([10, 11, 12, 13, 14, 15, 16.0])}
    cols.update(extra)
    return Run(cols, {}, "tiny.csv")


def test_replay_probe_walks_the_record_forward_only():
    p = ReplayProbe(_tiny_run(), 1, average=False)
    assert p.position() == 0.0
    s = p.step_to(0.5)
    assert (s.q, s.current) == (0.5, 10.5)           # halfway between samples 0 and 1
    assert p.step_to(2.5).current == 12.5
    # going back: the record goes on up to 3 and comes down; q=1.5 is met between q=2 (c=14)
    # and q=1 (c=15)
    s = p.step_to(1.5)
    assert (s.q, s.current) == (1.5, 14.5)
    assert p.recorded_travel == pytest.approx(2.5 + 0.5 + 1.5)
    with pytest.raises(ReplayExhausted, match="ends before knob 1 reaches 2.50 deg"):
        p.step_to(2.5)                                # the record never rises again
    assert p.return_to_start() and p.position() == 0.0


def test_replay_probe_average_sits_on_a_linear_current():
    # c = 2 q + 5 exactly: the median over a step and its median angle lie on the same line
    t = np.arange(2001) / 100.0
    q = 0.5 * t
    run = Run({"t": t, "q1": q, "c1": 2 * q + 5}, {}, None)
    p = ReplayProbe(run, 1)
    for target in (0.5, 1.0, 1.5):
        s = p.step_to(target)
        assert target - 0.5 < s.q < target
        assert s.current == pytest.approx(2 * s.q + 5, abs=1e-9)


def test_replay_probe_median_ignores_a_spike_within_a_step():
    t = np.arange(2001) / 100.0
    q = 0.5 * t
    c = 2 * q + 5
    c[95] += 500.0                                    # one logging glitch at q = 0.475
    p = ReplayProbe(Run({"t": t, "q1": q, "c1": c}, {}, None), 1)
    s = p.step_to(0.5)
    assert s.current == pytest.approx(2 * s.q + 5, abs=1e-9)


def test_replay_probe_names_a_missing_column():
    run = Run({"t": np.arange(3.0), "q1": np.arange(3.0)}, {}, "r.csv")
    with pytest.raises(DataError, match="r.csv.*'c1'"):
        ReplayProbe(run, 1)
    with pytest.raises(DataError, match="'q2'"):
        ReplayProbe(_tiny_run(), 2)


# --------------------------------------------------------------------------------------------
# the sample replays: the sweep identified from its current, then the search on each replay
# --------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def sample_models():
    return {k: identify(read_run(SAMPLES / f"sweep_knob{k}.csv"), use_tip=False).model for k in (1, 2)}


@pytest.mark.parametrize("knob", [1, 2])
@pytest.mark.parametrize("name", ["straight", "alpha45", "alpha90", "2dof"])
def test_sample_replays_give_their_true_offset(sample_models, name, knob):
    # within 1 deg: the sweep's current reads each take-up late by the tendon's 25 ms lag at its
    # 35 deg/s (about 0.9 deg), the slow replay hardly at all, and the offset carries that
    # difference; the interval no wider than the settings allow
    run = read_run(SAMPLES / f"replay_{name}_knob{knob}.csv")
    true = float(run.meta[f"true_offset{knob}"])
    model = sample_models[knob]
    probe = ReplayProbe(run, knob)
    r = detect_shift(model, probe, knob)
    assert abs(r.offset - true) <= 1.0, (r.summary(), true)
    assert r.halfwidth <= 0.5 and r.offset_lo <= r.offset <= r.offset_hi
    assert r.reference == "current" and r.returned and probe.position() == r.start == 0.0
    km = model.knob(knob)
    assert r.d_pos == pytest.approx(km.d_pos + r.offset) and r.d_neg == pytest.approx(km.d_neg + r.offset)
    edge = model.identification[knob].calibration.current_edges[r.edge]
    assert r.offset == pytest.approx(r.edge_found_at - edge.value)
    ev = r.evidence
    assert ev.statistic > ev.threshold and ev.edge_lo <= r.edge_found_at <= ev.edge_hi
    assert r.steps == len(r.trace) - 1 and r.travel == pytest.approx(r.step * r.steps)


# --------------------------------------------------------------------------------------------
# a probe over a current law written by hand (edges known exactly)
# --------------------------------------------------------------------------------------------
NO_LOAD, COULOMB, K_LOAD = 120.0, 6.0, 5.0


class LawProbe:
    """A signed motor current with edges ``[dn, dp]``: no-load 120 mA, +-6 mA of Coulomb friction
    with the direction of motion (a probe that reads moving), 5 mA per deg past an edge, an
    optional wall 100 mA/deg steep, seeded noise; faults on request."""

    def __init__(self, dn, dp, wall=None, noise=0.3, seed=0, fail_at=None, interrupt_at=None):
        self.dn, self.dp, self.wall = dn, dp, wall
        self.q = 0.0
        self.rng = np.random.default_rng(seed)
        self.noise = noise
        self.moves: list[float] = []
        self.stopped = False
        self.fail_at, self.interrupt_at = fail_at, interrupt_at

    def current(self, q, d):
        c = NO_LOAD + COULOMB * d + K_LOAD * (max(q - self.dp, 0.0) - max(self.dn - q, 0.0))
        if self.wall is not None:
            c += 100.0 * max(q - self.wall, 0.0)
        return c + self.rng.normal(0.0, self.noise)

    def position(self):
        return self.q

    def step_to(self, q):
        if self.fail_at is not None and len(self.moves) == self.fail_at:
            self.fail_at = None
            raise LinkError("no reply from the device within 1 s")
        if self.interrupt_at is not None and len(self.moves) == self.interrupt_at:
            self.interrupt_at = None
            raise KeyboardInterrupt
        d = 1.0 if q > self.q else -1.0
        self.q = q
        self.moves.append(q)
        return ProbeSample(q, self.current(q, d))

    def stop(self):
        self.stopped = True


STRAIGHT = KnobModel(d_pos=9.0, d_neg=-5.0, b_pos=3.0, b_neg=3.0, omega=1.45, h_pos=-2.0, h_neg=2.0)


def law_model(edges=None, q_range=(-40.0, 40.0), estimates=None, method="given") -> Model:
    """What identify stores for the law above on a straight shaft with edges [-5, 9]: the take-ups
    there, the dead zone's current 126 mA rising and 114 falling, loaded slope 5 mA/deg."""
    if edges is None:
        edges = {"pos": Estimate(9.0, 8.95, 9.05), "neg": Estimate(-5.0, -5.05, -4.95)}
    ident = KnobIdentification(q_range[0], q_range[1], method=method, estimates=estimates or {},
                               calibration=Calibration(
                                   current_sign="signed", current_edges=edges,
                                   no_load_rising=NO_LOAD + COULOMB, no_load_falling=NO_LOAD - COULOMB,
                                   slope_loaded_pos=K_LOAD, slope_loaded_neg=K_LOAD,
                                   edge_level_pos=NO_LOAD + COULOMB, edge_level_neg=NO_LOAD - COULOMB))
    return Model({1: STRAIGHT}, identification={1: ident})


LAW_MODEL = law_model()


def test_the_paper_case_rise_at_the_positive_edge():
    # true dead zone [-6, 8]: the straight one [-5, 9] shifted by -1
    p = LawProbe(-6.0, 8.0)
    r = detect_shift(LAW_MODEL, p, 1)
    assert (r.edge, r.direction) == ("pos", 1)
    assert r.offset_lo <= -1.0 <= r.offset_hi and abs(r.offset + 1.0) <= 0.1
    assert r.d_pos == pytest.approx(9.0 + r.offset) and r.d_neg == pytest.approx(-5.0 + r.offset)
    assert p.q == 0.0 and r.returned                  # knob back where it began
    assert max(p.moves) <= 8.0 + 0.5 * (5 + 16)       # a few readings past the edge, never far beyond


def test_without_return_home_the_knob_stays_where_the_search_ended():
    p = LawProbe(-6.0, 8.0)
    r = detect_shift(LAW_MODEL, p, 1, return_home=False)
    assert not r.returned and p.q == p.moves[-1] > 8.0


@pytest.mark.parametrize("dn,edge", [
    (-20.0, "neg"),    # the positive tendon taut at 0 by 6 deg (30 mA over no-load): turn, cross to -20
    (6.0, "pos"),      # the negative tendon taut at 0 by 6 deg: going up unloads it, then the dead zone
])
def test_a_start_with_a_tendon_taut(dn, edge):
    dp = dn + 14.0                                     # the straight width, shifted
    p = LawProbe(dn, dp, seed=2)
    r = detect_shift(LAW_MODEL, p, 1)
    assert r.edge == edge and r.edge_found_at == pytest.approx(dn if edge == "neg" else dp, abs=0.2)
    assert abs(r.offset - (dn + 5.0)) <= 0.2 and r.offset_lo <= dn + 5.0 <= r.offset_hi
    assert r.start_outside == (edge == "neg")          # turned round only where the tendon ahead was taut
    if edge == "neg":
        assert max(p.moves) <= 0.5 * 5                 # a few steps into the taut tendon at most
    assert p.q == 0.0


def test_a_side_whose_current_edge_the_sweep_left_open_gives_no_offset():
    # the sweep's current bounded the positive take-up only from below: the search measures from
    # the negative edge, though the positive one is nearer
    open_pos = {"pos": Estimate(9.0, 8.0, math.inf, fixed=False, reason="seen at the stretch's end"),
                "neg": Estimate(-5.0, -5.05, -4.95)}
    model = law_model(open_pos)
    ref = reference_of(model, 1)
    assert set(ref.edges) == {-1} and "did not fix" in ref.why_not[1]
    p = LawProbe(-6.0, 8.0)
    r = detect_shift(model, p, 1)
    assert r.edge == "neg" and abs(r.offset + 1.0) <= 0.1 and p.q == 0.0


def test_a_current_edge_the_tip_model_disagrees_with_gives_no_offset():
    # the tip's fixed d_pos is 9.0, the current took the positive tendon up at 12.5: more than
    # max_edge_gap (2 deg) apart, the current's kink there is not the tip's edge
    edges = {"pos": Estimate(12.5, 12.45, 12.55), "neg": Estimate(-5.0, -5.05, -4.95)}
    model = law_model(edges, estimates={"d_pos": Estimate(9.0, 8.9, 9.1), "d_neg": Estimate(-5.0, -5.1, -4.9)},
                      method="tip")
    ref = reference_of(model, 1)
    assert set(ref.edges) == {-1} and "disagree" in ref.why_not[1]
    r = detect_shift(model, LawProbe(-6.0, 8.0), 1)
    assert r.edge == "neg" and abs(r.offset + 1.0) <= 0.1


def test_no_side_with_a_reference_is_refused_before_the_knob_moves():
    p = LawProbe(-6.0, 8.0)
    with pytest.raises(ShiftDetectionError, match="no offset can be taken from either side"):
        detect_shift(law_model({}), p, 1)
    assert p.moves == []


def test_an_edge_too_noisy_to_place_is_refused_with_its_interval():
    # 4 mA of noise per reading against 5 mA/deg: the change point is found but its interval
    # is a degree or more wide; the offset is refused, not returned
    p = LawProbe(-6.0, 8.0, noise=4.0, seed=3)
    with pytest.raises(ShiftDetectionError, match=r"known only to \[[-+]\d+\.\d+, [-+]\d+\.\d+\] at 95%, wider "
                                                  r"than \+-0.5 deg.*returned to 0 deg"):
        detect_shift(LAW_MODEL, p, 1)
    assert p.q == 0.0


def test_travel_and_step_limits_are_never_exceeded():
    # no edge within 10 deg either side: out to the travel limit, across to the other side's
    p = LawProbe(-40.0, 40.0)
    with pytest.raises(ShiftDetectionError, match=r"no edge that gives an offset was found within the travel limit "
                                                  r"\(10 deg from 0\).*returned to 0 deg"):
        detect_shift(LAW_MODEL, p, 1, max_travel=10.0)
    assert max(abs(m) for m in p.moves[:-1]) <= 10.0 and p.q == 0.0 and p.stopped
    p = LawProbe(-40.0, 40.0)
    with pytest.raises(ShiftDetectionError, match=r"the step limit \(7\) was reached"):
        detect_shift(LAW_MODEL, p, 1, max_steps=7)
    # the first reading where the knob stands, seven steps, then the return
    assert p.moves == [0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 0.0]


def test_bad_search_options_are_refused_before_the_knob_moves():
    for kw, msg in (({"step": 0.0}, "unit step"), ({"step": math.nan}, "unit step"),
                    ({"max_travel": -1.0}, "travel limit"), ({"max_steps": 0}, "step limit"),
                    ({"direction": 2}, "direction")):
        p = LawProbe(-6.0, 8.0)
        with pytest.raises(ShiftDetectionError, match=msg):
            detect_shift(LAW_MODEL, p, 1, **kw)
        assert p.moves == []


def test_the_default_travel_limit_is_twice_the_sweeps_reach_and_half_the_dead_zone():
    # reach 38 deg, dead zone [-5, 9]: a bend moves the edges by up to the reach again, and a taut
    # start crosses the dead zone: 2 x 38 + 7 = 83 deg
    model = law_model(q_range=(-35.0, 38.0))
    assert default_max_travel(model, 1) == 83.0
    assert default_max_travel(Model({1: STRAIGHT}), 1) == DEFAULT_MAX_TRAVEL == 25.0
    p = LawProbe(-90.0, 90.0)
    with pytest.raises(ShiftDetectionError, match=r"travel limit \(83 deg from 0\)"):
        detect_shift(model, p, 1)
    assert max(p.moves[:-1]) == 83.0 and min(p.moves[:-1]) >= -83.0


def test_a_wall_is_never_pressed_more_than_a_step_and_the_knob_comes_back():
    # a wall at +4 deg inside the dead zone [-6, 8]: its slope (100 mA/deg) is far past the contact
    # slope (four times the loaded 5 mA/deg); whatever the search concludes, it never drives the
    # knob more than one step into the wall, and the knob ends where it began
    p = LawProbe(-6.0, 8.0, wall=4.0, seed=1)
    try:
        r = detect_shift(LAW_MODEL, p, 1)
    except ShiftDetectionError:
        r = None
    assert max(p.moves) <= 4.0 + 0.5
    assert p.q == 0.0
    if r is not None:
        assert r.contacts and abs(r.offset + 1.0) <= 0.2


def test_a_fault_stops_and_returns_the_knob_and_says_so():
    p = LawProbe(-6.0, 8.0, fail_at=5)
    with pytest.raises(LinkError, match="no reply.*returned to 0 deg"):
        detect_shift(LAW_MODEL, p, 1)
    assert p.stopped and p.q == 0.0


def test_an_interrupt_returns_the_knob_and_is_re_raised():
    p = LawProbe(-6.0, 8.0, interrupt_at=3)
    with pytest.raises(KeyboardInterrupt) as info:
        detect_shift(LAW_MODEL, p, 1)
    assert p.q == 0.0 and any("returned to 0" in n for n in info.value.__notes__)


def test_a_probe_that_cannot_return_is_reported():
    class Stuck(LawProbe):
        def return_to_start(self):
            return False

    with pytest.raises(LinkError, match="could NOT be confirmed back at 0 deg"):
        detect_shift(LAW_MODEL, Stuck(-6.0, 8.0, fail_at=2), 1)
    # after a success too: the offset is not returned when the knob is not back
    with pytest.raises(ShiftDetectionError, match="edge found at .* but the knob could NOT be confirmed"):
        detect_shift(LAW_MODEL, Stuck(-6.0, 8.0), 1)


def test_every_reading_reaches_the_progress_callback():
    seen = []
    r = detect_shift(LAW_MODEL, LawProbe(-6.0, 8.0), 1, progress=lambda s, slope: seen.append((s.q, s.current)))
    assert seen == [(q, c) for q, c, _ in r.trace]


# --------------------------------------------------------------------------------------------
# results, apply, plot
# --------------------------------------------------------------------------------------------
def test_apply_shift_sets_offsets_and_shifted_edges():
    res = ShiftResult(knob=1, offset=3.25, offset_lo=3.0, offset_hi=3.5, d_pos=0, d_neg=0, edge="pos",
                      edge_found_at=0, direction=1, reference="current", start=0, travel=0, steps=0)
    assert res.halfwidth == 0.25
    shifted = apply_shift(LAW_MODEL, [res])
    assert shifted.knob(1).offset == 3.25
    assert shifted.knob(1).shifted_d_pos == pytest.approx(9.0 + 3.25)
    assert shifted.knob(1).shifted_d_neg == pytest.approx(-5.0 + 3.25)
    assert shifted.knob(1).b_pos == STRAIGHT.b_pos and shifted.identification == LAW_MODEL.identification


def test_the_result_as_json():
    r = detect_shift(LAW_MODEL, LawProbe(-6.0, 8.0), 1)
    d = r.to_dict(trace=True)
    assert d["offset"] == r.offset and d["offset_lo"] == r.offset_lo and d["reference"] == "current"
    assert d["evidence"]["statistic"] == r.evidence.statistic
    assert len(d["trace"]) == len(r.trace) and d["trace"][0][2] is None     # no slope before three readings
    assert "trace" not in r.to_dict()


def test_plot_shift_writes_a_png_and_never_over_an_input(tmp_path):
    r = detect_shift(LAW_MODEL, LawProbe(-6.0, 8.0), 1)
    out = tmp_path / "fig.png"
    plot_shift([r], out, model=LAW_MODEL)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    src = tmp_path / "in.csv"
    src.write_text("t\n0\n")
    with pytest.raises(DataError, match="refusing to overwrite"):
        plot_shift([r], src, inputs=[src])
    assert src.read_text() == "t\n0\n"
