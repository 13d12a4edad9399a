"""Algorithm 1 (hystcli.shift): accuracy on the twin, the replay probe, contact, a start outside
the dead zone, limits, and the return of the knob on every failure.

Reference values: the twin's true shift (paper eqs. 3-4, ``run.meta["true_offset<k>"]``), and
edges placed by hand in the function probes below.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from hystcli import twin
from hystcli.errors import DataError, LinkError, ShiftDetectionError
from hystcli.io import Run
from hystcli.model import Geometry, KnobIdentification, KnobModel, Model, Shape
from hystcli.shift import (AFTER_STEPS, DEFAULT_MAX_TRAVEL, ProbeSample, ReplayExhausted, ReplayProbe, ShiftResult,
                           apply_shift, default_max_travel, detect_shift, plot_shift, resolve_thresholds)

# A catheter of the twin fixed here (docs/design.md section 6's example knob and a second knob like
# it), so these tests do not move when the shared virtual catheters are recalibrated.
CURRENT = twin.CurrentParams()  # no_load 120 mA, coulomb 6 mA, k_load 4 mA/deg, mu 0.25, noise 3 mA
CATHETER = twin.VirtualCatheter(
    "test-cath",
    {1: KnobModel(d_pos=9.1, d_neg=-8.7, b_pos=6.2, b_neg=5.9, omega=1.45, h_pos=-4.0, h_neg=4.2),
     2: KnobModel(d_pos=8.4, d_neg=-9.3, b_pos=5.6, b_neg=6.4, omega=1.40, h_pos=-3.6, h_neg=3.9)},
    Geometry(beta_catheter_mm=1.2, beta_knob_mm=8.0), CURRENT)


def ident(cur: twin.CurrentParams = CURRENT) -> dict[int, KnobIdentification]:
    """What identification would store, from the twin's known current model: the loaded slope
    lies between k_load(1-mu) and k_load(1+mu); the dead zone is flat up to noise."""
    return {k: KnobIdentification(slope_dead_zone=0.5, slope_loaded=cur.k_load, q_min=-40.0,
                                  q_max=40.0, current_dead_zone=cur.no_load) for k in (1, 2)}


MODEL = Model(dict(CATHETER.knobs), CATHETER.geometry, identification=ident())


def slow_ramp(amplitude: float = 26.0, speed: float = 1.0, fs: float = 500.0):
    """What a lab records for the search: from rest at 0, slowly out to +A and over to -A."""
    pts = [0.0, amplitude, -amplitude]
    path = np.concatenate([[0.0], np.cumsum(np.abs(np.diff(pts)))])
    t = np.arange(int(round(path[-1] / speed * fs)) + 1) / fs
    return t, np.interp(t * speed, path, pts)


# --------------------------------------------------------------------------------------------
# Must-show 2 of issue 3: the grid of shapes on the twin without effects
# --------------------------------------------------------------------------------------------
def test_offset_within_half_degree_over_the_shape_grid():
    # issue 3's grid, with the search of issue 10: a start with a tendon taut (every bent shape
    # here but the straight one puts the knob's rest outside the new dead zone or near it) goes
    # through the dead zone to the far edge, so the replay reaches +-45 deg and the travel is
    # bounded by the physics: the shift plus the dead zone's width plus the few degrees that
    # confirm an edge
    t, q = slow_ramp(amplitude=45.0)
    worst = 0.0
    seed = 0
    for alpha in (0, 45, 90, 135):
        for theta in (0, 90, 180, 270):
            seed += 1
            shape = Shape.parse(f"alpha={alpha},theta={theta}")
            run = twin.simulate(CATHETER, t, {1: q, 2: q}, shape=shape, effects=(), seed=seed)
            for k in (1, 2):
                true = float(run.meta[f"true_offset{k}"])
                # the reference itself, from paper eqs. 3-4 by hand: 1.2/8 mm * alpha(rad) * trig
                by_hand = math.degrees(1.2 / 8.0 * math.radians(alpha)) * (
                    math.cos(math.radians(theta)) if k == 1 else math.sin(math.radians(theta)))
                assert true == pytest.approx(by_hand, abs=1e-5)
                r = detect_shift(MODEL, ReplayProbe(run, k), k)
                err = abs(r.offset - true)
                worst = max(worst, err)
                assert err < 0.5, (shape, k, r.offset, true)
                width = CATHETER.knobs[k].d_pos - CATHETER.knobs[k].d_neg
                assert r.travel <= abs(true) + width + 6.0, (shape, k, r.travel)
                assert r.d_pos == pytest.approx(CATHETER.knobs[k].d_pos + r.offset)
                assert r.d_neg == pytest.approx(CATHETER.knobs[k].d_neg + r.offset)
    assert worst > 0  # noise was on


def test_start_outside_is_recognised_on_the_twin():
    # alpha=90: shift 13.5 deg. theta=0 puts the new dead zone at [4.8, 22.6]: at q=0 the
    # negative tendon is taut, and the search crosses the dead zone to its positive edge;
    # theta=180 puts it at [-22.2, -4.4]: the positive one is, and it goes to the negative edge.
    # Where the unloading tendon meets the dead zone is never taken as the edge (issue 10).
    # (The record goes up first: at theta=0 its own way is already toward the dead zone, at
    # theta=180 the search must turn round.)
    t, q = slow_ramp(amplitude=45.0)
    for theta, edge in ((0, "pos"), (180, "neg")):
        run = twin.simulate(CATHETER, t, {1: q}, shape=Shape.parse(f"alpha=90,theta={theta}"),
                            effects=(), seed=7)
        r = detect_shift(MODEL, ReplayProbe(run, 1), 1)
        assert r.transition == "rise" and r.edge == edge
        assert r.start_outside == (theta == 180)
        assert r.offset == pytest.approx(float(run.meta["true_offset1"]), abs=0.5)
        assert r.evidence is not None and r.evidence.clarity >= 7.0


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


def test_replay_probe_average_sits_on_a_linear_current():
    # c = 2 q + 5 exactly: the mean over a step and its mean angle lie on the same line
    t = np.arange(2001) / 100.0
    q = 0.5 * t
    run = Run({"t": t, "q1": q, "c1": 2 * q + 5}, {}, None)
    p = ReplayProbe(run, 1)
    for target in (0.5, 1.0, 1.5):
        s = p.step_to(target)
        assert target - 0.5 < s.q < target
        assert s.current == pytest.approx(2 * s.q + 5, abs=1e-9)


def test_replay_probe_names_a_missing_column():
    run = Run({"t": np.arange(3.0), "q1": np.arange(3.0)}, {}, "r.csv")
    with pytest.raises(DataError, match="r.csv.*'c1'"):
        ReplayProbe(run, 1)
    with pytest.raises(DataError, match="'q2'"):
        ReplayProbe(_tiny_run(), 2)


def test_replay_that_never_leaves_the_dead_zone_is_an_error_not_an_offset():
    t, q = slow_ramp(amplitude=5.0)
    run = twin.simulate(CATHETER, t, {1: q}, effects=(), seed=3)   # straight: dead zone [-8.7, 9.1]
    with pytest.raises(ShiftDetectionError, match=r"no edge found within \d+ steps / [\d.]+ deg"):
        detect_shift(MODEL, ReplayProbe(run, 1), 1)


# --------------------------------------------------------------------------------------------
# a probe over a current law written by hand (edges known exactly)
# --------------------------------------------------------------------------------------------
class LawProbe:
    """Signed motor current of docs/design.md section 4 with edges ``[dn, dp]``, an optional wall,
    Coulomb friction by direction, and seeded noise."""

    def __init__(self, dn, dp, start=0.0, wall=None, noise=0.3, seed=0, fail_at=None,
                 interrupt_at=None):
        self.dn, self.dp, self.wall = dn, dp, wall
        self.q = start
        self.rng = np.random.default_rng(seed)
        self.noise = noise
        self.moves: list[float] = []
        self.stopped = False
        self.fail_at, self.interrupt_at = fail_at, interrupt_at

    def current(self, q, d):
        c = 120.0 + 6.0 * d + 4.0 * (max(q - self.dp, 0.0) - max(self.dn - q, 0.0))
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
# what identify would store for the law below: no-load 120 mA, 126 moving up and 114 down
LAW_MODEL = Model({1: STRAIGHT}, identification={1: KnobIdentification(
    0.5, 4.0, -40, 40, current_dead_zone=120.0, no_load_rising=126.0, no_load_falling=114.0)})


def test_paper_case_rise_at_the_positive_edge():
    # true dead zone [-6, 8]: the straight one [-5, 9] shifted by -1
    p = LawProbe(-6.0, 8.0)
    r = detect_shift(LAW_MODEL, p, 1)
    assert (r.edge, r.transition, r.direction) == ("pos", "rise", 1)
    assert r.offset == pytest.approx(-1.0, abs=0.1)
    assert r.d_pos == pytest.approx(8.0, abs=0.1) and r.d_neg == pytest.approx(-6.0, abs=0.1)
    assert p.q == 0.0 and r.returned                 # knob back where it began
    assert r.steps == len(r.trace) and r.travel == pytest.approx(0.5 * r.steps)


def test_contact_reverses_and_finds_the_other_edge():
    # a wall at +4 deg inside the dead zone [-6, 8]: the slope jumps past eps_upper (20 mA/deg),
    # the search turns and takes the negative edge (paper, Discussion)
    p = LawProbe(-6.0, 8.0, wall=4.0, seed=1)
    r = detect_shift(LAW_MODEL, p, 1)
    assert len(r.contacts) == 1 and 4.0 < r.contacts[0] <= 5.0
    assert (r.edge, r.direction) == ("neg", -1)
    assert r.offset == pytest.approx(-1.0, abs=0.1)
    assert max(p.moves) <= 5.0                        # never pressed more than a step into the wall
    assert p.q == 0.0


def test_contact_on_both_sides_is_an_error():
    class Walled(LawProbe):
        def current(self, q, d):
            return 120.0 + 6.0 * d + 100.0 * (max(q - 3.0, 0.0) - max(-3.0 - q, 0.0))

    p = Walled(-20.0, 20.0)
    with pytest.raises(ShiftDetectionError, match="contact in both directions.*returned to 0"):
        detect_shift(LAW_MODEL, p, 1)
    assert p.q == 0.0


@pytest.mark.parametrize("dn,edge", [
    (3.0, "pos"),      # negative tendon taut at 0 (16 mA): cross the dead zone to dp = 17
    (-17.0, "neg"),    # positive tendon taut (dp = -3): turn and cross to dn = -17
    (1.0, None),       # barely taut (4 mA, below the Coulomb friction): the level cannot tell;
    (-15.0, None),     # either edge is fine, the offset must be right
])
def test_start_outside_the_dead_zone(dn, edge):
    dp = dn + (STRAIGHT.d_pos - STRAIGHT.d_neg)      # the straight width, shifted
    offset = dn - STRAIGHT.d_neg
    p = LawProbe(dn, dp, seed=2)
    r = detect_shift(LAW_MODEL, p, 1)
    if edge is not None:
        assert (r.edge, r.transition) == (edge, "rise")
        assert r.edge_found_at == pytest.approx(dn if edge == "neg" else dp, abs=0.15)
    assert r.offset == pytest.approx(offset, abs=0.15)
    assert r.travel <= 25.0 and p.q == 0.0


def test_an_unloading_tendon_is_not_an_edge():
    # the issue-10 failure: the knob rests with the negative tendon taut and the tip on its
    # backlash plateau; moving up, the current holds, then moves back toward its no-load level
    # (a kink out of a flat stretch!) and flattens at it. The search must not take that kink.
    class Plateau(LawProbe):
        def current(self, q, d):
            # load held until q = 2 (the plateau), unloading to the no-load level at q = 6,
            # the dead zone [6, 20], the positive tendon from 20 on
            unload = -4.0 * min(max(6.0 - q, 0.0), 4.0)
            return 120.0 + unload + 4.0 * max(q - 20.0, 0.0) + self.rng.normal(0.0, self.noise)

    p = Plateau(-8.0, 20.0, seed=3)
    r = detect_shift(LAW_MODEL, p, 1)
    assert r.edge == "pos" and r.edge_found_at == pytest.approx(20.0, abs=0.2)
    assert r.start_outside and r.offset == pytest.approx(20.0 - STRAIGHT.d_pos, abs=0.2)


def test_weak_evidence_is_refused_with_the_reason():
    # a kink too small for the noise: a jump in slope of 0.6 mA/deg under 2 mA of noise per step
    class Faint(LawProbe):
        def current(self, q, d):
            return 120.0 + 0.6 * max(q - 6.0, 0.0) + self.rng.normal(0.0, 2.0)

    model = Model({1: STRAIGHT}, identification={1: KnobIdentification(0.05, 0.6, -40, 40, current_dead_zone=120.0)})
    with pytest.raises(ShiftDetectionError, match="no edge found"):
        detect_shift(model, Faint(-8.0, 6.0, seed=4), 1)


def test_travel_and_step_limits_are_never_exceeded():
    # no edge within 10 deg either side: out to the travel limit, back across the start toward
    # the other edge (the walk back), stopped by the step limit (2 x 20 + 6) at the other side
    p = LawProbe(-40.0, 40.0)
    with pytest.raises(ShiftDetectionError, match=r"no edge found within 46 steps / 23.0 deg.*step limit is 46.*"
                                                  r"stopped there \(the travel limit is 10 deg.*turned back across"):
        detect_shift(LAW_MODEL, p, 1, max_travel=10.0)
    assert max(abs(m) for m in p.moves[:-1]) <= 10.0 and p.q == 0.0
    assert len(p.moves) == 46 + 1                     # 46 steps, then the return
    p = LawProbe(-40.0, 40.0)
    with pytest.raises(ShiftDetectionError, match=r"within 7 steps.*step limit is 7"):
        detect_shift(LAW_MODEL, p, 1, max_steps=7)
    assert len(p.moves) == 7 + 1                      # seven steps, then the return


def test_default_travel_limit_is_the_identification_sweeps_reach_and_half_the_dead_zone():
    # reach 38 deg, dead zone [-5, 9]: 38 + 7 = 45 deg (a taut start crosses the dead zone)
    ident = KnobIdentification(0.5, 4.0, -35.0, 38.0, current_dead_zone=120.0)
    assert default_max_travel(Model({1: STRAIGHT}, identification={1: ident}), 1) == 45.0
    assert default_max_travel(Model({1: STRAIGHT}), 1) == DEFAULT_MAX_TRAVEL == 25.0
    # a search with no edge inside stops at that limit (45 / 0.5 = 90 steps out), walks back
    # across the start, and never goes past it on the other side either
    p = LawProbe(-60.0, 60.0)
    model = Model({1: STRAIGHT}, identification={1: ident})
    with pytest.raises(ShiftDetectionError, match=r"no edge found within 186 steps.*the travel limit is 45 deg"):
        detect_shift(model, p, 1)
    assert max(p.moves[:-1]) == 45.0 and min(p.moves[:-1]) >= -45.0


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


# --------------------------------------------------------------------------------------------
# thresholds, apply, plot
# --------------------------------------------------------------------------------------------
def test_thresholds_come_from_the_model_or_the_options():
    th = resolve_thresholds(LAW_MODEL, 1)
    assert th.eps_lower == pytest.approx(math.sqrt(0.5 * 4.0))   # KnobIdentification.eps_lower
    assert th.eps_upper == pytest.approx(20.0) and th.current_dead_zone == 120.0
    assert resolve_thresholds(LAW_MODEL, 1, eps_lower=2.0).eps_lower == 2.0
    bare = Model({1: STRAIGHT})
    with pytest.raises(ShiftDetectionError, match="give --eps-lower and --eps-upper"):
        resolve_thresholds(bare, 1)
    with pytest.raises(ShiftDetectionError, match="give --eps-upper"):
        resolve_thresholds(bare, 1, eps_lower=1.0)
    with pytest.raises(ShiftDetectionError, match="greater than eps_lower"):
        resolve_thresholds(bare, 1, eps_lower=3.0, eps_upper=2.0)
    # a sweep whose current was no steeper past the edges than in the dead zone (real pitch_3:
    # 4.85 in the dead zone, 0.06 loaded): the defaults are 4.85 and 0.30, and the reason is the
    # current, not an option the user gave
    flat = Model({1: STRAIGHT}, identification={1: KnobIdentification(4.85, 0.06, -40.0, 40.0)})
    with pytest.raises(ShiftDetectionError, match="shows no tendon taken up"):
        resolve_thresholds(flat, 1)
    assert resolve_thresholds(flat, 1, eps_lower=1.0, eps_upper=20.0).eps_upper == 20.0
    r = detect_shift(bare, LawProbe(-6.0, 8.0), 1, eps_lower=1.5, eps_upper=20.0)
    assert r.offset == pytest.approx(-1.0, abs=0.1)


def test_apply_shift_sets_offsets_and_shifted_edges():
    model = MODEL
    res = ShiftResult(knob=2, offset=3.25, d_pos=0, d_neg=0, edge="pos", edge_found_at=0,
                      direction=1, transition="rise", start=0, travel=0, steps=0)
    shifted = apply_shift(model, [res])
    assert shifted.knob(2).offset == 3.25 and shifted.knob(1).offset == 0.0
    assert shifted.knob(2).shifted_d_pos == pytest.approx(8.4 + 3.25)
    assert shifted.knob(2).shifted_d_neg == pytest.approx(-9.3 + 3.25)
    assert shifted.knob(2).b_pos == model.knob(2).b_pos


def test_plot_shift_writes_a_png_and_never_over_an_input(tmp_path):
    r = detect_shift(LAW_MODEL, LawProbe(-6.0, 8.0, wall=4.0), 1)
    out = tmp_path / "fig.png"
    plot_shift([r], out, model=LAW_MODEL)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    src = tmp_path / "in.csv"
    src.write_text("t\n0\n")
    with pytest.raises(DataError, match="refusing to overwrite"):
        plot_shift([r], src, inputs=[src])
    assert src.read_text() == "t\n0\n"


def test_end_to_end_with_the_model_identify_makes():
    # identify on the straight sweep of the paper's protocol, then detect on bent shafts: the
    # thresholds and the dead-zone level are the identified ones, nothing is given by hand
    from hystcli.identify import identify

    t, q = twin.sweep()
    model = identify(twin.simulate(CATHETER, t, {1: q, 2: q}, effects=(), seed=11)).model
    assert set(model.identification) == {1, 2}
    t, q = slow_ramp(amplitude=45.0)
    for shape in ("alpha=90,theta=0", "alpha=135,theta=200", "alpha=45,theta=120"):
        run = twin.simulate(CATHETER, t, {1: q, 2: q}, shape=Shape.parse(shape), effects=(), seed=5)
        for k in (1, 2):
            r = detect_shift(model, ReplayProbe(run, k), k)
            assert r.offset == pytest.approx(float(run.meta[f"true_offset{k}"]), abs=0.5), (shape, k)


def test_an_edge_in_the_last_steps_before_the_travel_limit_is_judged_on_the_readings_there():
    # dead zone [-20, 8] (the positive edge the straight one's, 9, shifted by -1; the negative
    # one out of reach): the search meets the positive tendon at 8 deg. A kink waits for four
    # readings over 1.5 deg past it before it is judged; with a travel limit of 9.5 deg there are
    # three (8.5, 9.0, 9.5), and the kink is judged on them once the search can go no further
    p = LawProbe(-20.0, 8.0, seed=5)
    r = detect_shift(LAW_MODEL, p, 1, max_travel=9.5)
    assert r.edge == "pos" and r.evidence.n_after == 3 < AFTER_STEPS
    assert r.offset == pytest.approx(-1.0, abs=0.1)
    assert max(p.moves) <= 9.5 and p.q == 0.0
    # two readings past it (a limit of 9 deg) are too few: the search refuses
    p = LawProbe(-20.0, 8.0, seed=5)
    with pytest.raises(ShiftDetectionError, match="no edge found"):
        detect_shift(LAW_MODEL, p, 1, max_travel=9.0)
    assert max(p.moves[:-1]) <= 9.0 and p.q == 0.0


class _UnloadsIntoTheDeadZone(LawProbe):
    """The knob rests with the positive tendon taut whose load follows the tip: moving down it
    unloads until ``u0``, a degree short of the negative edge ``dn`` (the tip settles on its
    dead-zone plateau only there), and is taken up again at ``dp`` once the knob has been below
    ``u0``. ``level``: how far the dead zone's current sits off the no-load level (mA)."""

    def __init__(self, dn, dp, u0, level=0.0, **kw):
        super().__init__(dn, dp, **kw)
        self.u0, self.level, self.low = u0, level, math.inf

    def current(self, q, d):
        self.low = min(self.low, q)
        pos = max(q - self.u0, 0.0) if self.low > self.u0 else max(q - self.dp, 0.0)
        c = 120.0 + 6.0 * d + 4.0 * (pos - max(self.dn - q, 0.0))
        return c + (self.level if self.dn < q < self.dp else 0.0) + self.rng.normal(0.0, self.noise)


def test_a_short_dead_zone_flat_after_a_taut_starts_unloading_is_read_by_its_level():
    # dead zone [-6, 8] (the straight one shifted by -1); the positive tendon unloads down to -5,
    # leaving two readings of the dead zone's flat (-5.5, -6.0) before the negative edge. Too
    # short a flat to tell from the current's waviness by its slope, but it sits at the no-load
    # level after an unloading that arrived there: held in reserve, and taken at the travel limit
    p = _UnloadsIntoTheDeadZone(-6.0, 8.0, -5.0, seed=6)
    r = detect_shift(LAW_MODEL, p, 1, max_travel=20.0)
    assert r.start_outside and r.edge == "neg" and r.evidence.n_before < AFTER_STEPS
    assert r.offset == pytest.approx(-1.0, abs=0.15)
    assert p.q == 0.0
    # the same short flat 12 mA off the no-load level (beyond the kink's own band) is no dead
    # zone the level can vouch for: no offset from it
    p = _UnloadsIntoTheDeadZone(-6.0, 8.0, -5.0, level=12.0, seed=6)
    try:
        r = detect_shift(LAW_MODEL, p, 1, max_travel=20.0)
    except ShiftDetectionError:
        return
    assert r.edge_found_at != pytest.approx(-6.0, abs=0.5)
