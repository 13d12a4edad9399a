"""Signal conditioning (hystcli.filters): the paper's 3rd-order Butterworth low-pass at 20 Hz.

Reference values are computed by hand from the filter's magnitude response.
"""
from __future__ import annotations

import numpy as np
import pytest

from hystcli.errors import DataError
from hystcli.filters import butter_sos, lowpass


def test_lowpass_passes_a_constant_and_damps_a_fast_sine():
    fs = 1000.0
    t = np.arange(0.0, 1.0, 1.0 / fs)
    assert lowpass(np.full(t.size, 3.0), fs) == pytest.approx(np.full(t.size, 3.0))
    fast = np.sin(2 * np.pi * 200.0 * t)
    # |H(f)|^2 = 1 / (1 + (f / 20)^6) for a 3rd-order Butterworth: at 200 Hz 1e-6, and
    # forward-backward squares the magnitude again, so the 200-Hz sine leaves about 1e-6
    assert np.max(np.abs(lowpass(fast, fs)[100:-100])) < 1e-3


def test_lowpass_at_the_cutoff_halves_the_power_each_pass():
    # at 20 Hz |H| = 1/sqrt(2) per pass: causal, one pass; zero-phase, two (1/2 in amplitude)
    fs = 1000.0
    t = np.arange(0.0, 4.0, 1.0 / fs)
    x = np.sin(2 * np.pi * 20.0 * t)
    mid = slice(1000, 3000)
    assert np.max(np.abs(lowpass(x, fs, zero_phase=False)[mid])) == pytest.approx(2 ** -0.5, abs=0.01)
    assert np.max(np.abs(lowpass(x, fs)[mid])) == pytest.approx(0.5, abs=0.01)


def test_a_sample_rate_below_twice_the_cutoff_passes_the_signal_and_a_bad_one_is_refused():
    x = np.array([1.0, 5.0, -2.0, 4.0])
    assert lowpass(x, 30.0) == pytest.approx(x)        # Nyquist 15 Hz < 20 Hz: nothing to filter
    with pytest.raises(DataError, match="sample rate must be positive"):
        butter_sos(0.0)
    with pytest.raises(DataError, match="is the time column t in seconds"):
        butter_sos(1e9)
