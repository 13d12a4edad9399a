"""Algorithm 1 (hystcli.shift) where the plant zoo found it refusing a readable edge or taking a
wrong one (issue 10): an edge too close to the start, an unloading tendon led into a steep edge,
an identification whose figures are whole-sweep upper bounds, quantised readings, a no-load level
that lies off the sweep's, a tendon's backlash plateau, and an edge the model itself does not pin.

Every current below is a law written here by hand, so the true edges are known exactly; every
reference value is from that law (or the straight model's numbers), never from the code tested.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from hystcli.current import kink_fit, loading_edge, pieces
from hystcli.errors import ShiftDetectionError
from hystcli.model import KnobIdentification, KnobModel, Model
from hystcli.shift import AFTER_STEPS, ProbeSample, detect_shift

# the straight model: dead zone [-5, 9] (14 deg wide)
STRAIGHT = KnobModel(d_pos=9.0, d_neg=-5.0, b_pos=3.0, b_neg=3.0, omega=1.45, h_pos=-2.0, h_neg=2.0)
WIDTH = STRAIGHT.d_pos - STRAIGHT.d_neg


def model(slope_dead_zone: float = 0.5, slope_loaded: float = 4.0, **ident) -> Model:
    """The straight model with what identify would store: no-load 120 mA, 126 moving up and 114
    down (a Coulomb friction of 6 mA), the given slopes (eps_lower is their geometric mean,
    eps_upper five times the loaded one)."""
    kw = dict(current_dead_zone=120.0, no_load_rising=126.0, no_load_falling=114.0)
    kw.update(ident)
    return Model({1: STRAIGHT}, identification={1: KnobIdentification(slope_dead_zone, slope_loaded, -40.0, 40.0,
                                                                      **kw)})


class Knob:
    """One knob read at rest after each step: current ``law(q, d)`` (``d`` the direction of the
    step just made) plus seeded white noise, optionally quantised to ``quantum`` mA."""

    def __init__(self, law, start: float = 0.0, noise: float = 0.3, seed: int = 0,
                 quantum: float | None = None) -> None:
        self.law, self.q, self.noise, self.quantum = law, float(start), noise, quantum
        self.rng = np.random.default_rng(seed)
        self.moves: list[float] = []

    def position(self) -> float:
        return self.q

    def step_to(self, q: float) -> ProbeSample:
        d = 1.0 if q > self.q else -1.0
        self.q = float(q)
        self.moves.append(self.q)
        c = self.law(self.q, d) + self.rng.normal(0.0, self.noise)
        if self.quantum:
            c = self.quantum * round(c / self.quantum)
        return ProbeSample(self.q, c)

    def stop(self) -> None:
        pass


def right_or_refused(m: Model, probe, seeds: int, offset: float, refusal: str | None = None, **kw) -> int:
    """Over ``seeds`` noise draws of ``probe(seed)``, each search returns ``offset`` within 0.5 deg
    or refuses (with ``refusal`` in its message, when given); the number that returned."""
    taken = 0
    for seed in range(seeds):
        try:
            r = detect_shift(m, probe(seed), 1, **kw)
        except ShiftDetectionError as exc:
            assert refusal is None or refusal in str(exc), seed
            continue
        taken += 1
        assert r.offset == pytest.approx(offset, abs=0.5), seed
    return taken


def tendons(dn: float, dp: float, k: float = 4.0, pre: float = 0.0, coulomb: float = 6.0):
    """Signed current with the dead zone [dn, dp]: loaded slope ``k`` past either edge, a
    pretension slope ``pre`` everywhere, the motor's Coulomb friction with the direction."""
    mid = 0.5 * (dn + dp)

    def law(q: float, d: float) -> float:
        return 120.0 + coulomb * d + pre * (q - mid) + k * (max(q - dp, 0.0) - max(dn - q, 0.0))
    return law


# --------------------------------------------------------------------------------------------
# an edge a step or two from where the knob rests
# --------------------------------------------------------------------------------------------
def test_a_kink_with_no_dead_zone_behind_it_is_not_taken_the_far_edge_is():
    # the knob rests 1.3 deg short of the positive edge (dead zone [-12.7, 1.3]: the straight one
    # shifted by -7.7), a pretensioned current (0.5 mA/deg across the dead zone): two readings
    # before the edge are no dead zone to read a kink out of. The search meets the taut tendon,
    # turns, and takes the negative edge after a long flat stretch.
    dn, dp = -12.7, 1.3
    law = tendons(dn, dp, pre=0.5)
    for seed in range(8):
        r = detect_shift(model(slope_dead_zone=0.5), Knob(law, seed=seed), 1)
        assert r.edge == "neg" and r.direction == -1, seed
        assert r.evidence.n_before >= 4, seed
        assert r.offset == pytest.approx(dn - STRAIGHT.d_neg, abs=0.25), seed



def test_an_edge_at_the_start_on_the_no_load_level_is_taken_when_the_far_edge_is_out_of_reach():
    # the knob rests 1.8 deg short of the positive edge (dead zone [-12.2, 1.8]: the straight one
    # shifted by -7.2); three or four readings before the edge are too short a flat to read by its
    # slope, but they sit at the no-load level the identification measured. With the far edge
    # beyond the travel limit (8 deg), that edge is the evidence there is: held in reserve, it is
    # taken when the search can go no further (the old search refused every draw).
    dn, dp = -12.2, 1.8
    law = tendons(dn, dp)
    taken = 0
    for seed in range(16):
        try:
            r = detect_shift(model(), Knob(law, seed=seed), 1, max_travel=8.0)
        except ShiftDetectionError as exc:
            assert "no edge found" in str(exc), seed
            continue
        taken += 1
        assert r.edge == "pos" and r.offset == pytest.approx(dp - STRAIGHT.d_pos, abs=0.5), seed
    assert taken >= 8, taken

# --------------------------------------------------------------------------------------------
# reading a stepping search's few readings (hystcli.current.loading_edge)
# --------------------------------------------------------------------------------------------
def test_the_flat_stretch_of_a_kink_fit_leaves_out_the_unloading_that_led_into_it():
    # readings every 0.5 deg: a negative tendon unloading at 12 mA/deg up to q=3, the dead zone
    # to q=14, the positive tendon at 41 mA/deg (the unloading slope is under 0.35 of the loaded
    # one, so the reading made for a sweep's many points once counted it as flat and took it into
    # the kink fit). Both readings now leave it out: the strict one by its slope's standard error,
    # the sweep's because the unloading is clearly steeper than the flat (beyond three standard
    # errors and a fifth of the jump)
    rng = np.random.default_rng(12)
    q = np.arange(0.0, 19.01, 0.5)
    c = 120.0 - 12.0 * np.maximum(3.0 - q, 0.0) + 41.0 * np.maximum(q - 14.0, 0.0) + rng.normal(0, 0.2, q.size)
    loose = loading_edge(q, c, 1, 0.2, resolution=0.02)
    strict = loading_edge(q, c, 1, 0.2, resolution=0.02, strict_flat=True)
    n_flat = int(np.sum((q >= 3.0) & (q < 14.0)))            # 22 readings
    for kink in (loose, strict):
        assert kink is not None and kink.n_before <= n_flat
        assert kink.at == pytest.approx(14.0, abs=0.05) and abs(kink.before) < 0.3
        assert kink.residual < 2 * 0.2


def test_a_corner_between_two_readings_does_not_stop_the_kink_fit_before_the_loaded_run():
    # a stretch current stepped every 0.5 deg: flat at 180 mA, 6.9 mA/deg past q = 7.4, so the
    # reading at 7.5 is barely loaded. In some draws the readings at 7.0-8.0 make a piece of their
    # own, steeper than the flat and gentler than the loaded run, which the sweep's reading then
    # took for a wall after a loaded run: the kink fit stopped there, two points past the kink,
    # and a search that needs four waited at that kink to the travel limit (design replays 1531
    # and 1898). With ``min_run`` (what the search passes, AFTER_STEPS) the loaded run is the
    # steeper piece and the kink sits at the edge, every reading past it in the fit
    q = np.arange(0.0, 14.01, 0.5)
    past = int(np.sum(q > 7.4))                                   # 14 readings
    stopped = placed = 0
    for seed in range(100):
        rng = np.random.default_rng(seed)
        c = 180.0 + 6.9 * np.maximum(q - 7.4, 0.0) + rng.normal(0.0, 0.1, q.size)
        loose = loading_edge(q, c, 1, 0.1, minlen=2, resolution=0.02, convex=True)
        stopped += loose is None or loose.n_after < 4
        k = loading_edge(q, c, 1, 0.1, minlen=2, resolution=0.02, convex=True, min_run=AFTER_STEPS)
        placed += k is not None and abs(k.at - 7.4) <= 0.1 and k.n_after == past
    assert placed == 100
    assert stopped >= 4, stopped


def test_the_motors_cogging_ripple_is_taken_out_of_the_readings():
    # the dead zone [-3, 11] (the straight [-5, 9] shifted by +2), the loaded slope 4 mA/deg,
    # and the motor's cogging: 2.5 mA at a 5 deg period of knob angle, whose steepest slope
    # (2 pi 2.5 / 5 = 3.1 mA/deg) is past eps_lower (1.41). Read as it comes, the ripple bends
    # the loaded line and the kink lands 0.65-0.9 deg early, with exit 0. The identification
    # read that ripple on the sweep's dead zone (KnobIdentification.cogging_*): taken out of
    # every reading, the edge gives the offset
    base = tendons(-3.0, 11.0)

    def law(q: float, d: float) -> float:
        return base(q, d) + 2.5 * math.sin(2 * math.pi * q / 5.0)

    cogged = model(cogging_period=5.0, cogging_sin=2.5, cogging_cos=0.0)
    refused = 0
    for seed in range(8):
        r = detect_shift(cogged, Knob(law, seed=seed), 1)
        assert r.offset == pytest.approx(2.0, abs=0.15), seed
        # without it no draw is right: most kinks land early (exit 0); since the negative
        # tendon's kink may keep its curvature, a few are refused as no two straight lines
        try:
            plain = detect_shift(model(), Knob(law, seed=seed), 1)
        except ShiftDetectionError as exc:
            refused += 1
            assert "not two straight lines" in str(exc), seed
        else:
            assert abs(plain.offset - 2.0) > 0.5, seed
    assert refused <= 4


def test_quantised_readings_are_split_into_as_many_pieces_as_their_noise_pays_for():
    # 1 mA quantisation on a pretensioned current, 1 mA/deg, and 3.5 mA/deg past q = 7: five
    # pieces spend themselves on the staircase of the dead zone, and in a third of the draws the
    # edge is lost among them; as many pieces as the readings' noise pays for find it
    found = {False: 0, True: 0}
    for seed in range(30):
        rng = np.random.default_rng(seed)
        q = np.arange(0.5, 13.01, 0.5)
        c = np.round(120.0 + q + 2.5 * np.maximum(q - 7.0, 0.0) + rng.normal(0, 0.3, q.size))
        sig = 0.45                  # 0.3 mA of noise and the rounding's 1/sqrt(12) mA
        for select in (False, True):
            k = loading_edge(q, c, 1, sig, resolution=0.02, select=select)
            found[select] += k is not None and abs(k.at - 7.0) <= 0.3
    assert found[True] >= 24 and found[True] >= found[False] + 5, found


def test_a_loaded_side_may_stiffen_but_a_sag_is_not_fitted_as_one():
    # a stiffening tendon (4 mA/deg at the edge, +0.2 mA/deg per deg past it) keeps its quadratic
    # term; a loaded current that sags over its last 3 deg (a replay slowing into its own turn,
    # its friction fading) is fitted straight, as no tendon softens
    rng = np.random.default_rng(15)
    q = np.arange(0.0, 20.01, 0.5)
    x = np.maximum(q - 10.0, 0.0)
    stiff = 100.0 + 4.0 * x + 0.1 * x ** 2 + rng.normal(0, 0.2, q.size)
    assert kink_fit(q, stiff, 1, min_side=2, resolution=0.02, convex=True) == \
        kink_fit(q, stiff, 1, min_side=2, resolution=0.02)
    sag = 100.0 + 4.0 * x - 1.0 * np.maximum(x - 7.0, 0.0) ** 2 + rng.normal(0, 0.2, q.size)
    assert kink_fit(q, sag, 1, min_side=2, resolution=0.02, convex=True) == \
        kink_fit(q, sag, 1, min_side=2, resolution=0.02, curved=False)
    # on a short loaded stretch the quadratic term is loose, and is left alone
    short = q <= 14.0
    assert kink_fit(q[short], sag[short], 1, min_side=2, resolution=0.02, convex=True) == \
        kink_fit(q[short], sag[short], 1, min_side=2, resolution=0.02)


def test_a_negative_tendon_may_stiffen_too():
    # the mirror image: moving down past d_neg = -10 the negative tendon's current falls, 4 mA/deg
    # at the edge and steeper by 0.2 mA/deg per deg past it (c = 100 - 4 x - 0.1 x^2, x = -10 - q).
    # Read with the quadratic term's sign unturned by the direction, this stiffening was taken
    # for a sag and fitted straight, the edge put late (design replays 1228 and 3400497: 0.92
    # and 1.5 deg off, exit 0)
    rng = np.random.default_rng(15)
    q = -np.arange(0.0, 20.01, 0.5)
    x = np.maximum(-10.0 - q, 0.0)
    stiff = 100.0 - 4.0 * x - 0.1 * x ** 2 + rng.normal(0, 0.2, q.size)
    k = kink_fit(q, stiff, -1, min_side=2, resolution=0.02, convex=True)
    assert k == kink_fit(q, stiff, -1, min_side=2, resolution=0.02)
    assert k.at == pytest.approx(-10.0, abs=0.2)
    assert k.after == pytest.approx(4.0, abs=0.5)
    straight = kink_fit(q, stiff, -1, min_side=2, resolution=0.02, curved=False)
    assert abs(straight.at + 10.0) > abs(k.at + 10.0)
    # and a sag moving down (the fall easing off over the last 3 deg) is still fitted straight
    sag = 100.0 - 4.0 * x + 1.0 * np.maximum(x - 7.0, 0.0) ** 2 + rng.normal(0, 0.2, q.size)
    assert kink_fit(q, sag, -1, min_side=2, resolution=0.02, convex=True) == \
        kink_fit(q, sag, -1, min_side=2, resolution=0.02, curved=False)


# --------------------------------------------------------------------------------------------
# the identification's figures are whole-sweep upper bounds
# --------------------------------------------------------------------------------------------
def test_a_wall_in_the_sweep_does_not_hide_the_edge():
    # the sweep met a wall: its 'loaded' slope is 300 mA/deg, so the identification's no-load
    # band is 300 mA wide; this tendon loads at 25 mA/deg. The edge at -17 (dead zone [-17, -3])
    # is read anyway, on the band of the search's own readings
    m = model(slope_dead_zone=2.0, slope_loaded=300.0)
    r = detect_shift(m, Knob(tendons(-17.0, -3.0, k=25.0), start=-10.0, seed=4), 1, direction=-1)
    assert r.edge == "neg" and r.edge_found_at == pytest.approx(-17.0, abs=0.15)
    assert r.offset == pytest.approx(-12.0, abs=0.15)


def test_a_noisy_sweep_does_not_hide_an_edge_at_the_travel_limit():
    # the sweep's dead-zone slope (noise included) was 3 mA/deg: a swing of 21 mA across the
    # half-width, where this flat current does not move at all. The edge at 6 (dead zone
    # [-8, 6]) is 3.5 deg short of the travel limit: the current never leaves the sweep's band
    # before the limit, but it does leave the search's own, and the edge is taken there
    m = model(slope_dead_zone=3.0, slope_loaded=4.0)
    p = Knob(tendons(-8.0, 6.0), seed=5)
    r = detect_shift(m, p, 1, max_travel=9.5)
    assert r.edge == "pos" and r.edge_found_at == pytest.approx(6.0, abs=0.2)
    assert r.offset == pytest.approx(-3.0, abs=0.2)
    assert max(p.moves) <= 9.5


# --------------------------------------------------------------------------------------------
# quantised readings of a pretensioned current
# --------------------------------------------------------------------------------------------
def test_quantised_readings_are_not_cut_into_little_steep_pieces():
    # 1 mA quantisation on a pretensioned current (1 mA/deg everywhere, 5 mA/deg past an edge):
    # a split into five pieces spends them on the staircase of the dead zone
    law = tendons(-2.4, 11.6, k=4.0, pre=1.0)
    for seed in range(4):
        r = detect_shift(model(slope_dead_zone=1.0), Knob(law, noise=0.3, seed=seed, quantum=1.0), 1)
        assert r.offset == pytest.approx(2.6, abs=0.3), seed


# --------------------------------------------------------------------------------------------
# the no-load level of the search lies off the sweep's
# --------------------------------------------------------------------------------------------
def test_a_dead_zone_below_the_sweeps_no_load_level_is_read_by_how_far_the_current_goes():
    # the search's dead zone sits 25 mA below the sweep's level moving up (a replay slower than
    # the sweep, less viscous friction): the flat before the edge looks like a negative tendon's
    # plateau, but the current then climbs as far past the sweep's level again and on, which no
    # unloading tendon does (it stops at the no-load level)
    base = tendons(-3.0, 11.0, k=8.0)

    def law(q, d):
        return base(q, d) - 25.0

    r = detect_shift(model(slope_loaded=8.0), Knob(law, seed=6), 1)
    assert r.edge == "pos" and r.offset == pytest.approx(2.0, abs=0.15)
    assert r.evidence.level < 126.0 - 20.0          # the flat was well below the sweep's level


def test_an_unloading_tendon_that_stops_at_the_no_load_level_is_still_no_edge():
    # the mirror case: the negative tendon's plateau 25 mA below, then its unloading up to the
    # no-load level, flat there: no edge (the positive one at 30 is beyond the travel limit).
    # Moving down from the dead zone the tendon is taken up at its edge, q = 2 (where the
    # plateau ended: a tip-load current, slack from q = 7)
    def law(q, d):
        if d < 0:
            return 114.0 - 5.0 * max(2.0 - q, 0.0)
        unload = -25.0 + 5.0 * min(max(q - 2.0, 0.0), 5.0)     # plateau to q=2, slack at q=7
        return 126.0 + unload + 4.0 * max(q - 30.0, 0.0)

    # the search walked 20 deg away, past the model's 3 deg backlash of that tendon: it turns
    # back at the travel limit and reads the edge from the dead zone, never where the unloading
    # met the no-load level
    probe = Knob(law, seed=7)
    r = detect_shift(model(), probe, 1, max_travel=20.0)
    assert r.edge == "neg" and r.edge_found_at == pytest.approx(2.0, abs=0.2) and r.walked_back
    assert r.offset == pytest.approx(2.0 - STRAIGHT.d_neg, abs=0.2)
    assert max(probe.moves) <= 20.0 + 1e-9

    # the same tendon unloading slowly, slack only at q = 15, past the travel limit of 12: where
    # the search stops its current still climbs toward the no-load level (inside the band the
    # start is read by), the tendon still loaded. A walk back would take it up again where the
    # knob turned, not at its edge: refused
    def slow(q, d):
        if d < 0:
            return 114.0 - 5.0 * max(2.0 - q, 0.0)
        return 126.0 - 25.0 + 25.0 / 13.0 * min(max(q - 2.0, 0.0), 13.0)

    with pytest.raises(ShiftDetectionError, match="no edge found"):
        detect_shift(model(), Knob(slow, seed=7), 1, max_travel=12.0)
    r = detect_shift(model(), Knob(slow, seed=7), 1, max_travel=20.0)    # slack by then: it turns back
    assert r.edge_found_at == pytest.approx(2.0, abs=0.2)


def test_a_search_from_the_dead_zone_whose_edge_is_out_of_reach_walks_back_to_the_other():
    # dead zone [-3, 11] (the straight one shifted by +2), the knob resting at 0: the search goes
    # up first, and the positive edge lies past its travel limit (11 deg + 3 to confirm, against
    # 10). The negative edge lies 3 deg behind the start; the search turns back once across the
    # dead zone's whole flat and reads it there (the old search refused every draw)
    law = tendons(-3.0, 11.0)
    for seed in range(4):
        r = detect_shift(model(), Knob(law, seed=seed), 1, max_travel=10.0, max_steps=80)
        assert r.edge == "neg" and r.walked_back and not r.start_outside, seed
        assert r.edge_found_at == pytest.approx(-3.0, abs=0.2), seed
        assert r.offset == pytest.approx(2.0, abs=0.2), seed


def test_a_pretensioned_dead_zone_climbing_toward_the_no_load_level_is_no_tendon_still_unloading():
    # dead zone [2, 16] (shift +7) with a pretension of 3 mA/deg across it, the negative tendon
    # taut where the knob rests (-3): the search crosses toward the positive edge, beyond its
    # travel limit of 9 deg, and stops at 6, where the dead zone's current climbs toward the
    # no-load level (126 mA at the middle, 9) at its own slope. That is no unloading: the tendon
    # behind is slack, and the walk back reads its edge at 2 (the old search refused every draw)
    law = tendons(2.0, 16.0, k=12.0, pre=3.0)
    m = model(slope_dead_zone=3.0, slope_loaded=15.0)
    for seed in range(4):
        r = detect_shift(m, Knob(law, start=-3.0, seed=seed), 1, max_travel=9.0)
        assert r.start_outside and r.walked_back and r.edge == "neg", seed
        assert r.offset == pytest.approx(7.0, abs=0.2), seed


# --------------------------------------------------------------------------------------------
# a tendon's backlash plateau
# --------------------------------------------------------------------------------------------
def test_a_plateau_of_the_tendon_ahead_is_not_its_edge():
    # the positive tendon holds 8 mA (2 deg of its 4 mA/deg) since before the search, its tip
    # on the backlash plateau: moving up, the current stays flat until the knob passes where
    # that stretch ended (q = 6, the edge at 4 plus the 2 deg), then loads. Within the no-load
    # tolerance, but 2 deg of the loaded slope above: not taken; the search turns and takes the
    # negative edge (dead zone [-10, 4])
    def law(q, d):
        if d > 0:
            return 126.0 + 8.0 + 4.0 * max(q - 6.0, 0.0)
        return tendons(-10.0, 4.0)(q, d)

    r = detect_shift(model(), Knob(law, seed=8), 1)
    assert r.edge == "neg" and r.offset == pytest.approx(-5.0, abs=0.15)


# --------------------------------------------------------------------------------------------
# how surely the offset is placed
# --------------------------------------------------------------------------------------------
def test_an_edge_the_model_itself_does_not_pin_gives_no_offset_the_other_edge_does():
    # the identification placed d_pos only to +-1.2 deg (beyond MAX_MODEL_SE, 1 deg): the
    # positive edge is not used, the negative one (+-0.05) is
    m = model(stderr={"d_pos": 1.2, "d_neg": 0.05})
    r = detect_shift(m, Knob(tendons(-6.0, 8.0), seed=9), 1)
    assert r.edge == "neg" and r.offset == pytest.approx(-1.0, abs=0.15)
    # +-0.6 deg (a fast sweep's fit on the twin states +-0.5): the edge is the user's model, and
    # the search answers for its own kink: the positive edge is taken
    m = model(stderr={"d_pos": 0.6, "d_neg": 0.05})
    r = detect_shift(m, Knob(tendons(-6.0, 8.0), seed=9), 1)
    assert r.edge == "pos" and r.offset == pytest.approx(-1.0, abs=0.15)


def test_an_edge_the_identification_could_not_place_gives_way_to_the_other():
    m = model(unfixed=("d_pos",))
    r = detect_shift(m, Knob(tendons(-6.0, 8.0), seed=10), 1)
    assert r.edge == "neg" and r.offset == pytest.approx(-1.0, abs=0.15)


def test_a_faint_edge_is_placed_within_half_a_degree_or_refused():
    # 1.5 mA/deg past the edge at 6 against 1.5 mA of noise per reading, the travel limit 4 deg
    # past it: a kink the readings place only loosely is no offset
    law = tendons(-8.0, 6.0, k=1.5)
    m = model(slope_dead_zone=0.2, slope_loaded=1.5)
    right_or_refused(m, lambda seed: Knob(law, noise=1.5, seed=seed), 8, -3.0, "no edge found", max_travel=10.0)


# --------------------------------------------------------------------------------------------
# both tendons stiffer than the sweep's: each edge rises as steeply as a contact
# --------------------------------------------------------------------------------------------
def test_two_steep_rises_a_dead_zone_apart_are_the_two_edges_not_two_walls():
    # the sweep's loaded slope 4 mA/deg (eps_upper 20), the tendons now 40 mA/deg: each edge of
    # the dead zone [-7, 7] (the straight [-5, 9] shifted by -2) rises past eps_upper straight
    # out of the flat no-load stretch, so the search turns at each as at a contact. A shift
    # moves both edges by one offset and keeps the width (14 deg): two rises exactly that far
    # apart are the two tendons taken up; two walls would not stand at the width by chance.
    law = tendons(-7.0, 7.0, k=40.0)
    for seed in range(6):
        r = detect_shift(model(), Knob(law, seed=seed), 1)
        assert len(r.contacts) == 2, seed
        assert r.offset == pytest.approx(-2.0, abs=0.25), seed
    # the same steep rises 10 deg apart (a dead zone 4 deg narrower than the model's): walls or
    # stops, not the tendons of this model: no offset
    law = tendons(-5.0, 5.0, k=40.0)
    for seed in range(3):
        with pytest.raises(ShiftDetectionError, match="contact in both directions"):
            detect_shift(model(), Knob(law, seed=seed), 1)


# --------------------------------------------------------------------------------------------
# where an unloading tendon's current met the dead zone gives no offset and vetoes none
# --------------------------------------------------------------------------------------------
def test_the_loading_edge_stands_whatever_the_sweep_put_the_unloading_tendons_arrival_at():
    # the dead zone [2, 16] (the straight [-5, 9] shifted by +7), the knob resting at -5 with
    # the negative tendon taut: moving up, its current unloads (4 mA/deg) and meets the no-load
    # level at 2, the edge; the positive tendon is taken up at 16. Where an unloading current
    # meets the dead zone depends on the current law, so the sweep's arrival reference (here -30,
    # where a wall held the tip, or 0, 5 deg into the straight dead zone as a load-following
    # current arrives) gives no offset. Until stop 25 an arrival reference where a tendon can go
    # slack (0) was compared with the loading edge and a disagreement past 2 deg refused; on the
    # plant zoo's design replays the arrival was the one off in all 20 such refusals
    law = tendons(2.0, 16.0)
    for rising in (-30.0, 0.0, None):
        m = model(current_arrive_rising=rising, current_arrive_falling=9.0)
        for seed in range(4):
            r = detect_shift(m, Knob(law, start=-5.0, seed=seed), 1)
            assert r.start_outside and r.edge == "pos", (rising, seed)
            assert r.offset == pytest.approx(7.0, abs=0.25), (rising, seed)


# --------------------------------------------------------------------------------------------
# the tendon behind still taut on its backlash plateau, its unloading handed straight over
# --------------------------------------------------------------------------------------------
def test_the_end_of_the_plateau_of_the_tendon_behind_is_no_edge():
    # the dead zone [-8, 6] (the straight [-5, 9] shifted by -3); the knob rests at 0 with the
    # positive tendon taut and the tip held on its backlash plateau (b_pos = 3): its load (25 mA)
    # stays until -3.5, then unloads at 6 mA/deg and is gone at -7.67, where the negative tendon
    # is already (nearly) loading at 3 mA/deg: no flat at the no-load level between. The kink
    # at -3.5 rises (loading-positive) out of a flat, and the current runs on past the no-load
    # level as far as that flat sat short of it; but the flat sits 19 mA off the no-load level
    # on the taut side, no longer than the backlash, and the line changes slope where it meets
    # the no-load level (two tendons): an offset from it (-3.5 + 5 = +1.5) would be 4.5 deg off.
    def law(q: float, d: float) -> float:
        pos = 25.0 if q >= -3.5 else max(25.0 - 6.0 * (-3.5 - q), 0.0)
        return 120.0 + 6.0 * d + pos - 3.0 * max(-8.0 - q, 0.0)

    right_or_refused(model(), lambda seed: Knob(law, seed=seed), 6, -3.0, direction=-1)

    # the same flat with the negative tendon taken up at -3.5 and loading at 6 mA/deg in one
    # straight line through the no-load level (a dead zone whose no-load level lies 19 mA off
    # the sweep's) reads exactly as the positive tendon, held taut on its plateau, unloading at
    # 6 mA/deg and handing over to the negative one at the same slope where it meets the no-load
    # level (held-out null replay 1000327, read as a -2.1 deg shift): the edge lies at -3.5 or
    # at -6.67, and the readings cannot tell which. Refused, with that reason. (Until stop 21
    # this returned the first: one tendon, one slope.)
    def off_level(q: float, d: float) -> float:
        return 120.0 + 6.0 * d + 25.0 - 6.0 * max(-3.5 - q, 0.0)

    for seed in range(4):
        with pytest.raises(ShiftDetectionError, match="still taut on its backlash plateau"):
            detect_shift(model(), Knob(off_level, seed=seed), 1, direction=-1)

    # a flat 3 mA off the no-load level, within the search's own band: a dead zone; its edge
    # gives the offset (-3.5 + 5 = +1.5)
    def near_level(q: float, d: float) -> float:
        return 120.0 + 6.0 * d + 3.0 - 6.0 * max(-3.5 - q, 0.0)

    for seed in range(4):
        r = detect_shift(model(), Knob(near_level, seed=seed), 1, direction=-1)
        assert r.offset == pytest.approx(1.5, abs=0.25), seed


# --------------------------------------------------------------------------------------------
# an edge the identification could not place, met on the way, against the one it did
# --------------------------------------------------------------------------------------------
def test_an_unplaced_edge_met_on_the_way_must_agree_with_the_placed_one():
    # the true dead zone [-5, 6], no shift. The identification could not place d_pos on the tip
    # (its guess 9 is unused), but the sweep's current showed the positive tendon taken up at 6;
    # its d_neg is -8, 3 deg off. The search takes up the positive tendon at 6 (no offset from
    # the unplaced d_pos), crosses the dead zone and finds the negative edge at -5: an offset of
    # -5 - (-8) = +3. A shift moves both edges alike, so the positive tendon, met at 6 where the
    # sweep's current had it, says 0: the two disagree by 3 deg and the model's d_neg (or the
    # current's reading) is wrong: no offset.
    def ident_model(d_neg: float) -> Model:
        km = KnobModel(d_pos=9.0, d_neg=d_neg, b_pos=3.0, b_neg=3.0, omega=1.45, h_pos=-2.0, h_neg=2.0)
        return Model({1: km}, identification={1: KnobIdentification(
            0.5, 4.0, -40.0, 40.0, current_dead_zone=120.0, no_load_rising=126.0, no_load_falling=114.0,
            unfixed=("d_pos",), current_edge_pos=6.0)})

    law = tendons(-5.0, 6.0)
    for seed in range(4):
        with pytest.raises(ShiftDetectionError, match="readings disagree"):
            detect_shift(ident_model(-8.0), Knob(law, seed=seed), 1)
        # with d_neg where the tendon is, the two agree and the offset (0) stands
        r = detect_shift(ident_model(-5.0), Knob(law, seed=seed), 1)
        assert r.edge == "neg" and r.offset == pytest.approx(0.0, abs=0.25), seed


def test_an_edge_the_tip_fit_could_not_place_is_measured_from_where_the_current_showed_it():
    # The tip fit could not place d_pos (its 15 deg is a guess: a tip sampled too coarsely for
    # its dead-zone corner), but the sweep's current showed the positive tendon taken up at 6.0,
    # +-0.05 (its reading claims it), and the negative one at -4.8, where the tip fit placed
    # d_neg (-5.0, within CURRENT_AGREE). The dead zone has shifted by +2: [-3, 8]. The search
    # moves positive and takes the tendon up at 8: the offset is 8 - 6 = +2, measured from the
    # current's edge. Without the reading's standard error (an older model file, or an edge only
    # the record's first stretch showed), or with the current's d_neg 0.8 deg off the tip's,
    # that edge gives none: the search crosses the dead zone and measures the same +2 from the
    # negative edge, -3 - (-5).
    def ident_model(se: float | None, current_neg: float | None = -4.8) -> Model:
        km = KnobModel(d_pos=15.0, d_neg=-5.0, b_pos=3.0, b_neg=3.0, omega=1.45, h_pos=-2.0, h_neg=2.0)
        return Model({1: km}, identification={1: KnobIdentification(
            0.5, 4.0, -40.0, 40.0, current_dead_zone=120.0, no_load_rising=126.0, no_load_falling=114.0,
            unfixed=("d_pos",), current_edge_pos=6.0, current_edge_pos_se=se, current_edge_neg=current_neg,
            stderr={"d_neg": 0.05})})

    law = tendons(-3.0, 8.0)
    for seed in range(4):
        r = detect_shift(ident_model(0.05), Knob(law, seed=seed), 1)
        assert (r.edge, r.reference) == ("pos", "current"), seed
        assert r.offset == pytest.approx(2.0, abs=0.25), seed
        # the shifted model moves the tip fit's edges by that offset (its d_pos stays a guess)
        assert r.d_neg == pytest.approx(-3.0, abs=0.25) and r.d_pos == pytest.approx(17.0, abs=0.25)
        r = detect_shift(ident_model(None), Knob(law, seed=seed), 1)
        assert (r.edge, r.reference) == ("neg", "model"), seed
        assert r.offset == pytest.approx(2.0, abs=0.25), seed
    # a current edge known only to +-1.5 deg (beyond MAX_MODEL_SE) gives no offset either, nor
    # one whose reading of the placed edge is 0.8 deg off it or missing
    for m in (ident_model(1.5), ident_model(0.05, -5.8), ident_model(0.05, None)):
        r = detect_shift(m, Knob(law, seed=0), 1)
        assert (r.edge, r.reference) == ("neg", "model")


# --------------------------------------------------------------------------------------------
# a taut start's whole unloading in the stretch the search reads
# --------------------------------------------------------------------------------------------
def test_the_tail_of_an_unloading_is_not_merged_into_the_dead_zone():
    # readings every 0.5 deg from a taut start: the tendon behind holds 1400 mA to q = 5, unloads
    # at 200 mA/deg to q = 10 and then eases into the dead zone (400 exp(-(q - 10)) mA, a tail of
    # a few degrees); the dead zone is flat to the edge at q = 24, past which the tendon ahead
    # loads at 35 mA/deg, stiffening to 70 past q = 27. Seven straight pieces: split into five,
    # the tail is fitted as part of the dead zone and the two-line fit misses the readings by
    # four times their noise (a refusal); as many pieces as the noise pays for place the edge.
    q = np.arange(0.5, 32.01, 0.5)
    law = (np.where(q < 5, 1400.0, np.where(q < 10, 1400.0 - 200.0 * (q - 5.0), 400.0 * np.exp(-(q - 10.0))))
           + 35.0 * np.maximum(q - 24.0, 0.0) + 35.0 * np.maximum(q - 27.0, 0.0))
    for seed in range(4):
        c = law + np.random.default_rng(seed).normal(0.0, 1.5, q.size)
        k = loading_edge(q, c, 1, 1.5, resolution=0.02, strict_flat=True, select=True, convex=True)
        assert k is not None, seed
        assert k.at == pytest.approx(24.0, abs=0.15), seed
        assert k.residual < 2.0 * 1.5 and k.se < 0.1, seed


# --------------------------------------------------------------------------------------------
# a taut start whose current runs back into the no-load band before it steepens
# --------------------------------------------------------------------------------------------
def test_a_flat_that_runs_from_the_taut_side_into_the_no_load_band_is_an_unloading():
    # (design seed 1304 of bench/zoo.py, by hand.) The true dead zone is [-12, 2] (the straight
    # [-5, 9] shifted by -7) and the true no-load level 100 mA; the sweep's identification says
    # 120 (114 moving down, 126 up): a band of 120 +- 13.5 mA read at rest. The knob rests at 0
    # with the positive tendon taut: its current eases off at 2.5 mA/deg from 145 mA (off the
    # band) to 130 at -6 (inside it), then the tip leaves its backlash plateau and the tendon
    # unloads at 8 mA/deg down to the true no-load level at -9.75; the dead zone is flat to -12,
    # where the negative tendon loads at 4 mA/deg. The kink at -6 rises (loading-positive) out
    # of a gentle stretch and the current then runs past the sweep's band: taken, it gives an
    # offset of -6 - (-5) = -1, 6 deg off. Its flat began on the positive tendon's taut side and
    # ran into the band in one line: the current moving back toward its no-load level, a
    # tendon unloading. The edge at -12 gives the offset, -7.
    def law(q: float, d: float) -> float:
        pos = 145.0 + 2.5 * q if q >= -6.0 else max(130.0 - 8.0 * (-6.0 - q), 100.0)
        return pos - 4.0 * max(-12.0 - q, 0.0)

    right_or_refused(model(), lambda seed: Knob(law, seed=seed), 6, -7.0, direction=-1)
    r = detect_shift(model(), Knob(law, seed=0), 1, direction=-1)
    assert r.edge == "neg" and r.start_outside and r.offset == pytest.approx(-7.0, abs=0.25)


def test_a_held_load_beyond_the_band_must_run_past_both_no_load_levels():
    # (design seed 3533 of bench/zoo.py, by hand.) Readings taken moving (a replay). The sweep's
    # identification put the no-load level moving down at 160 mA and moving up at 90 (the true
    # one, for both: the sweep misread a held load as Coulomb friction). The true dead zone is
    # [-14, 0] (the straight [-5, 9] shifted by -9). The knob rests at 0 with the positive
    # tendon taut, its load held on the tip's backlash plateau (180 mA) to -3.5, where it
    # unloads at 12 mA/deg in one line through the sweep's 160 down to the true 90 (at -11),
    # flat to -14, where the negative tendon loads at 4 mA/deg. The rise out of the held flat
    # runs in one line through 160 mA and on past it as far as the flat sat beyond it: taken,
    # an offset of -3.5 - (-5) = +1.5, 10.5 deg off. Until it has run past the other direction's
    # level (90) as well, it may be an unloading; it flattens there, and the edge at -14 gives
    # the offset, -9.
    class Moving(Knob):
        reads_moving = True

    def law(q: float, d: float) -> float:
        pos = 180.0 if q >= -3.5 else max(180.0 - 12.0 * (-3.5 - q), 90.0)
        return pos - 4.0 * max(-14.0 - q, 0.0)

    m = model(current_dead_zone=125.0, no_load_rising=90.0, no_load_falling=160.0)
    right_or_refused(m, lambda seed: Moving(law, seed=seed), 6, -9.0, direction=-1)
    r = detect_shift(m, Moving(law, seed=0), 1, direction=-1)
    assert r.edge == "neg" and r.offset == pytest.approx(-9.0, abs=0.25)
