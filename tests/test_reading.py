"""What read_current (hystcli.signal.reading) makes of a sweep's motor current, on currents built
here from the tendon mechanics.

Every current is written in this file from the physics of a tendon drive, with its truth:

* the stretch law: a signed current ``c0 + k (u - d_pos)+ - k (d_neg - u)+`` (each tendon pulls
  once the knob passes its edge; the motor feels only the stretch, so the load follows the knob);
* its magnitude: ``c0 + k (u - d_pos)+ + k (d_neg - u)+`` (a drive that reports |I|);
* a held load: each tendon's load passes through a play of the backlash's width (after a
  reversal the sheath friction holds the load while the knob travels ``b`` back, then it unloads);
* pretension (a slope everywhere, the edge a change of slope), the motor's Coulomb friction (a
  step with the direction of motion), a cogging ripple (periodic in the knob angle).

The sweep is a triangle of +-30 deg at 20 deg/s sampled at 500 Hz; the edges are 8 and -6 deg,
the loaded slope 3 mA/deg, the noise 0.5 mA (white, before the reading's own 20 Hz low-pass).
Each estimate is held to the precision the record carries (a kink of 3 mA/deg under this noise is
placed to a few hundredths of a degree), and each interval must hold the truth.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from hystcli.settings import DEFAULT
from hystcli.signal.reading import read_current

D_POS, D_NEG, K, C0, NOISE = 8.0, -6.0, 3.0, 100.0, 0.5
B_POS, B_NEG = 5.0, 4.0
EDGE_TOL = 0.1     # deg: the estimate's distance from the true edge (signed currents)


def triangle(amplitude: float = 30.0, cycles: float = 2.25, speed: float = 20.0, fs: float = 500.0):
    """Time and knob angle of a triangle sweep from 0, up first; 2.25 cycles end at the top."""
    period = 4.0 * amplitude / speed
    t = np.arange(0.0, cycles * period, 1.0 / fs)
    s = (t / period) % 1.0
    q = amplitude * np.where(s < 0.25, 4 * s, np.where(s < 0.75, 2 - 4 * s, 4 * s - 4))
    return t, q


def play(u: np.ndarray, width: float, pulls_up: bool) -> np.ndarray:
    """A backlash (play) of ``width``: the output is pushed along by ``u`` and otherwise held.

    For the positive tendon (``pulls_up``) the output follows a rising ``u`` and, after a
    reversal, stays until ``u`` has come back ``width``; the negative tendon mirrored.
    """
    out = np.empty_like(u)
    p = float(u[0])
    for i, x in enumerate(u):
        p = max(min(p, x + width), x) if pulls_up else min(max(p, x - width), x)
        out[i] = p
    return out


T, Q = triangle()
STRETCH = C0 + K * np.maximum(Q - D_POS, 0.0) - K * np.maximum(D_NEG - Q, 0.0)
HELD = C0 + K * np.maximum(play(Q, B_POS, True) - D_POS, 0.0) - K * np.maximum(D_NEG - play(Q, B_NEG, False), 0.0)


def noisy(clean: np.ndarray, seed: int = 0) -> np.ndarray:
    return clean + np.random.default_rng(seed).normal(0.0, NOISE, clean.size)


def assert_edges(reading, tol: float = EDGE_TOL) -> None:
    for side, true in (("pos", D_POS), ("neg", D_NEG)):
        e = reading.edges[side]
        assert e.fixed and math.isfinite(e.lo) and math.isfinite(e.hi), (side, e)
        assert abs(e.value - true) <= tol, (side, e)
        assert e.lo <= true <= e.hi, (side, e)
        assert e.hi - e.lo < 1.0, (side, e)


@pytest.fixture(scope="module")
def stretch():
    return read_current(Q, noisy(STRETCH), T)


def test_a_signed_stretch_current_gives_its_sign_edges_slopes_and_levels(stretch):
    r = stretch
    assert r.sign == "signed"
    assert_edges(r)
    assert r.loaded_slope["pos"] == pytest.approx(K, rel=0.05)
    assert r.loaded_slope["neg"] == pytest.approx(K, rel=0.05)
    assert r.no_load[1] == pytest.approx(C0, abs=0.2) and r.no_load[-1] == pytest.approx(C0, abs=0.2)
    assert r.edge_level["pos"] == pytest.approx(C0, abs=0.5) and r.edge_level["neg"] == pytest.approx(C0, abs=0.5)
    assert abs(r.dead_slope) < 0.05
    # the conditioned current's noise about the broken lines: the 20 Hz low-pass keeps about
    # sqrt(2 x 20 / 500) of the 0.5 mA white noise
    assert r.noise == pytest.approx(NOISE * math.sqrt(40.0 / 500.0), rel=0.3)


def test_a_current_that_follows_the_stretch_shows_no_backlash_and_says_why(stretch):
    assert stretch.backlash == {}
    for name in ("b_pos", "b_neg"):
        assert "unloads at once" in stretch.notes[name], stretch.notes


def test_a_magnitude_current_is_read_as_one_with_the_same_edges():
    magnitude = C0 + K * np.maximum(Q - D_POS, 0.0) + K * np.maximum(D_NEG - Q, 0.0)
    r = read_current(Q, noisy(magnitude), T)
    assert r.sign == "magnitude" and "magnitude" in r.sign_note
    assert_edges(r)
    # asked to read it as signed, the reading says so and does not take the sign from the record
    forced = read_current(Q, noisy(magnitude), T, DEFAULT.set_params(current_sign="signed"))
    assert forced.sign == "signed" and forced.sign_note == "read as signed, as asked"


def test_a_held_load_after_each_reversal_gives_the_backlash():
    r = read_current(Q, noisy(HELD), T)
    assert r.sign == "signed"
    assert_edges(r)
    for side, true in (("pos", B_POS), ("neg", B_NEG)):
        b = r.backlash[side]
        assert b.fixed and abs(b.value - true) <= EDGE_TOL and b.hi - b.lo < 1.0, (side, b)
    assert "b_pos" not in r.notes and "b_neg" not in r.notes


def test_edge_and_backlash_intervals_cover_the_truth_at_about_their_level():
    # 20 draws of the held-load current, four intervals each: a 95 % procedure covers at least
    # binom.ppf(1e-3, 80, 0.95) = 69 of the 80 except with probability 1e-3 (measured on this
    # code: 78 of 80)
    from scipy.stats import binom

    covered = 0
    for seed in range(20):
        r = read_current(Q, noisy(HELD, seed), T)
        covered += sum(r.edges[s].contains(t) for s, t in (("pos", D_POS), ("neg", D_NEG)))
        covered += sum(s in r.backlash and r.backlash[s].contains(t) for s, t in (("pos", B_POS), ("neg", B_NEG)))
    assert covered >= binom.ppf(1e-3, 80, 0.95)


def test_pretension_tilts_the_dead_zone_and_the_edge_is_the_change_of_slope():
    # both tendons pretensioned: 0.9 mA/deg everywhere, the tendon ahead adds K at its edge
    r = read_current(Q, noisy(STRETCH + 0.9 * Q), T)
    assert r.sign == "signed"
    assert_edges(r)
    assert r.dead_slope == pytest.approx(0.9, abs=0.05)
    assert r.loaded_slope["pos"] == pytest.approx(K + 0.9, rel=0.05)


def test_coulomb_friction_moves_the_levels_with_the_direction_not_the_edges():
    v = np.gradient(Q, T)
    r = read_current(Q, noisy(STRETCH + 8.0 * np.tanh(v / 0.5)), T)
    assert r.sign == "signed"
    assert_edges(r)
    assert r.no_load[1] == pytest.approx(C0 + 8.0, abs=0.3)
    assert r.no_load[-1] == pytest.approx(C0 - 8.0, abs=0.3)


def test_a_cogging_ripple_is_read_and_taken_out():
    # 1.5 mA at a period of 3.7 deg of knob, phase 0.4 rad: sin amplitude 1.5 cos 0.4, cos 1.5 sin 0.4
    r = read_current(Q, noisy(STRETCH + 1.5 * np.sin(2 * np.pi * Q / 3.7 + 0.4)), T)
    assert r.ripple is not None
    assert r.ripple.period == pytest.approx(3.7, abs=0.03)
    assert r.ripple.sin == pytest.approx(1.5 * math.cos(0.4), abs=0.1)
    assert r.ripple.cos == pytest.approx(1.5 * math.sin(0.4), abs=0.1)
    assert_edges(r)


def test_no_ripple_of_consequence_where_there_is_none(stretch):
    # white noise can lend a sinusoid a little of its power; what the reading takes must stay
    # below the noise, never a ripple that would move an edge
    assert stretch.ripple is None or stretch.ripple.amplitude < NOISE / 2


def test_a_sweep_that_never_leaves_the_dead_zone_shows_no_edge_and_says_where_to_sweep():
    t, q = triangle(amplitude=5.0, speed=5.0)
    c = C0 + K * np.maximum(q - D_POS, 0.0) - K * np.maximum(D_NEG - q, 0.0)
    r = read_current(q, noisy(c), t)
    assert r.edges == {} and r.backlash == {}
    for name in ("d_pos", "d_neg"):
        assert "sweep further" in r.notes[name], r.notes
