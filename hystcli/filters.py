"""Signal conditioning shared by identification, shift detection and the twin.

The paper filters every measured signal with a 3rd-order Butterworth low-pass at 20 Hz
(section II-C-2). Offline we filter zero-phase (forward-backward), so edges found on a filtered
current are not delayed; live we can only filter causally.
"""
from __future__ import annotations

import numpy as np

from .errors import DataError

PAPER_CUTOFF_HZ = 20.0
PAPER_ORDER = 3

MAX_SAMPLE_RATE_HZ = 1e6
"""Fastest sample rate the filter accepts. Far above any lab recorder; beyond about 1e8 Hz the
Butterworth design for 20 Hz is numerically singular, and such a rate means the time column is
not in seconds."""


def butter_sos(fs: float, cutoff: float = PAPER_CUTOFF_HZ, order: int = PAPER_ORDER) -> np.ndarray:
    """Second-order sections of the Butterworth low-pass (cutoff in Hz, sample rate ``fs``)."""
    if not fs > 0:
        raise DataError(f"sample rate must be positive, got {fs}")
    if fs > MAX_SAMPLE_RATE_HZ:
        raise DataError(f"sample rate {fs:.6g} Hz is beyond {MAX_SAMPLE_RATE_HZ:g} Hz: is the time column t "
                        "in seconds?")
    from scipy import signal  # here: scipy.signal takes longer to import than the whole CLI may
    nyq = 0.5 * fs
    if cutoff >= nyq:
        # Sampled too slowly for the filter to do anything: the signal is already band-limited.
        return np.array([[1.0, 0, 0, 1.0, 0, 0]])
    return signal.butter(order, cutoff / nyq, btype="low", output="sos")


def lowpass(x: np.ndarray, fs: float, cutoff: float = PAPER_CUTOFF_HZ, order: int = PAPER_ORDER,
            zero_phase: bool = True) -> np.ndarray:
    """Butterworth low-pass of ``x`` sampled at ``fs`` Hz.

    Parameters
    ----------
    x : array_like
        Signal.
    fs : float
        Sample rate (Hz).
    cutoff : float
        Cut-off frequency (Hz); the paper's 20 Hz by default.
    order : int
        Filter order; the paper's 3 by default.
    zero_phase : bool
        Forward-backward filtering (offline) when True, causal (live) when False.
    """
    from scipy import signal

    x = np.asarray(x, dtype=float)
    sos = butter_sos(fs, cutoff, order)
    if zero_phase:
        padlen = min(3 * (2 * sos.shape[0] + 1), max(x.size - 1, 0))
        if x.size < 2:
            return x.copy()
        return signal.sosfiltfilt(sos, x, padlen=padlen)
    zi = signal.sosfilt_zi(sos) * (x[0] if x.size else 0.0)
    y, _ = signal.sosfilt(sos, x, zi=zi)
    return y
