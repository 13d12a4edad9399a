"""hystcli.current's cogging ripple: read on a dead zone's samples, taken out of a search's readings.

Reference values are the ones each synthetic current is built with.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from hystcli.current import Ripple, cogging_ripple


def _dead_zone(wave, n: int = 3000, seed: int = 0, noise: float = 0.5):
    """A sweep's dead-zone samples, -10 to 10 deg up then down: levels 120 +- 20 mA (the motor's
    Coulomb friction with the direction), a pretension slope of 0.5 mA/deg, ``wave(q, group)``."""
    rng = np.random.default_rng(seed)
    q = np.concatenate([np.linspace(-10.0, 10.0, n), np.linspace(10.0, -10.0, n)])
    g = np.r_[np.zeros(n), np.ones(n)].astype(int)
    c = 120.0 + 20.0 * (1 - 2 * g) + 0.5 * q + wave(q, g) + rng.normal(0.0, noise, q.size)
    return q, c, g


def test_a_cogging_ripple_is_read_with_its_period_and_phase():
    # 2 mA at a 4.7 deg period, phase 0.3 rad: sin amplitude 2 cos 0.3 = 1.911, cos 2 sin 0.3 = 0.591
    q, c, g = _dead_zone(lambda q, g: 2.0 * np.sin(2 * np.pi * q / 4.7 + 0.3))
    r = cogging_ripple(q, c, g)
    assert r is not None
    assert r.period == pytest.approx(4.7, abs=0.02)
    assert r.sin == pytest.approx(2.0 * math.cos(0.3), abs=0.05)
    assert r.cos == pytest.approx(2.0 * math.sin(0.3), abs=0.05)
    assert r.amplitude == pytest.approx(2.0, abs=0.05)


def test_no_ripple_is_read_where_there_is_none():
    # white noise on the levels and slope; a pretensioned dead zone that curves (0.05 mA/deg^2);
    # a wave whose phase turns with the direction of motion (a load that follows the knob's
    # travel, not the motor shaft's position): none is cogging
    for wave in (lambda q, g: 0.0 * q,
                 lambda q, g: 0.05 * q ** 2,
                 lambda q, g: 2.0 * np.sin(2 * np.pi * q / 4.7 + np.pi * g)):
        q, c, g = _dead_zone(wave)
        assert cogging_ripple(q, c, g) is None


def _narrow(width: float, period: float, noise: float, seed: int = 1):
    """A dead zone ``width`` deg wide read both ways, a 2.9-mA ripple of ``period`` deg on it."""
    rng = np.random.default_rng(seed)
    q = np.concatenate([np.linspace(-width / 2, width / 2, 400), np.linspace(width / 2, -width / 2, 300)])
    g = np.r_[np.zeros(400), np.ones(300)].astype(int)
    c = -110.0 + 56.0 * (1 - 2 * g) + 1.1 * q + 2.9 * np.sin(2 * np.pi * q / period + 4.3)
    return q, c + rng.normal(0.0, noise, q.size), g


def test_a_clear_ripple_over_fewer_than_one_and_a_half_periods_is_read():
    # design sweep 1871 of bench/zoo.py: a 4.9-deg cogging period over a 6.8-deg dead zone
    # (1.4 periods), 2.9 mA against 0.3 mA of noise; the search's edge was 1.1 deg off without it
    q, c, g = _narrow(6.8, 4.9, 0.3)
    r = cogging_ripple(q, c, g)
    assert r is not None
    assert r.period == pytest.approx(4.9, abs=0.15)
    assert r.amplitude == pytest.approx(2.9, abs=0.2)
    # the same wave half drowned (it explains under 0.9 of the variance): too little to take a
    # wave of barely more than one period for the motor's
    assert cogging_ripple(*_narrow(6.8, 4.9, 2.5)) is None


def test_too_few_samples_or_one_direction_over_few_periods_read_no_ripple():
    q, c, g = _dead_zone(lambda q, g: 2.0 * np.sin(2 * np.pi * q / 4.7), n=20)
    assert cogging_ripple(q, c, g) is None
    # read moving one way only there is no second direction to compare it with: 1.7 periods of
    # a 12-deg wave over the 20-deg flat could be a load following the knob
    q, c, g = _dead_zone(lambda q, g: 2.0 * np.sin(2 * np.pi * q / 12.0))
    up = g == 0
    assert cogging_ripple(q[up], c[up], g[up]) is None


def test_a_clear_ripple_read_moving_one_way_over_two_periods_or_more_is_read():
    # design sweeps 258, 351, 893 of bench/zoo.py: flats read only rising or only falling, ripples
    # of 1.6-3.8 mA explaining 0.99 of the variance over 3.5-4 periods (here 2 mA over 0.2 mA
    # of noise, 0.98 of it, over 4.3 periods)
    q, c, g = _dead_zone(lambda q, g: 2.0 * np.sin(2 * np.pi * q / 4.7 + 0.3), noise=0.2)
    for way in (0, 1):
        m = g == way
        r = cogging_ripple(q[m], c[m], g[m])
        assert r is not None
        assert r.period == pytest.approx(4.7, abs=0.05)
        assert r.sin == pytest.approx(2.0 * math.cos(0.3), abs=0.1)
        assert r.cos == pytest.approx(2.0 * math.sin(0.3), abs=0.1)


@given(st.floats(0.5, 20.0), st.floats(-5.0, 5.0), st.floats(-5.0, 5.0), st.floats(-100.0, 100.0))
def test_a_ripple_repeats_with_its_period(period, a_sin, a_cos, q):
    r = Ripple(period, a_sin, a_cos)
    assert r(q + period) == pytest.approx(r(q), abs=1e-9 * (1.0 + abs(q) / period))
    assert abs(r(q)) <= r.amplitude + 1e-12
