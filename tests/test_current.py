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


def test_too_few_samples_or_one_direction_read_no_ripple():
    q, c, g = _dead_zone(lambda q, g: 2.0 * np.sin(2 * np.pi * q / 4.7), n=20)
    assert cogging_ripple(q, c, g) is None
    q, c, g = _dead_zone(lambda q, g: 2.0 * np.sin(2 * np.pi * q / 4.7))
    up = g == 0
    assert cogging_ripple(q[up], c[up], g[up]) is None


@given(st.floats(0.5, 20.0), st.floats(-5.0, 5.0), st.floats(-5.0, 5.0), st.floats(-100.0, 100.0))
def test_a_ripple_repeats_with_its_period(period, a_sin, a_cos, q):
    r = Ripple(period, a_sin, a_cos)
    assert r(q + period) == pytest.approx(r(q), abs=1e-9 * (1.0 + abs(q) / period))
    assert abs(r(q)) <= r.amplitude + 1e-12
