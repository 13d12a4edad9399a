"""Algorithm 1 of the paper (gradient-based shift detection) over a probe, and its result.

This package owns the search for the shifted dead zone :math:`\\tilde D_{pos}, \\tilde D_{neg}`
of one knob after the shaft took an unknown shape (paper section II-C, Algorithm 1):

* :mod:`.probe`: what the search steps and reads (a recorded replay, a live knob);
* :mod:`.search`: the stepping, and the statistical decisions on the readings;
* :mod:`.result`: the offset with its interval and the evidence for it;
* :mod:`.request`: what a detection is asked to do, checked before anything moves;
* :mod:`.run`: the detection on every chosen knob of a replay or a live robot
  (:func:`run_detect_shift`, what ``hyst detect-shift`` calls).

One algorithm, several sources: the search talks to a probe, and replay and live run the same code.
"""
from __future__ import annotations

import os
from typing import Iterable, Mapping, Sequence

import numpy as np

import importlib
from typing import Any

from .probe import Probe, ProbeSample, ReplayExhausted, ReplayProbe, return_knob
from .result import Evidence, ShiftResult

# the search reads the current with the compiled broken-line fits: imported on first use, so that
# the device layer (which needs only the probe's sample) and `hyst --help` do not load numba
_LAZY = {name: "search" for name in ("DEFAULT_MAX_TRAVEL", "Reference", "apply_shift", "default_max_travel",
                                     "detect_shift", "detect_shifts", "reference_of")}
_LAZY.update({name: "request" for name in ("ProbeSource", "ShiftRequest", "select_knobs")}, run_detect_shift="run")


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'hystcli.shift' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value

__all__ = ["DEFAULT_MAX_TRAVEL", "Evidence", "Probe", "ProbeSample", "ProbeSource", "Reference", "ReplayExhausted",
           "ReplayProbe", "ShiftRequest", "ShiftResult", "apply_shift", "default_max_travel", "detect_shift",
           "detect_shifts", "plot_shift", "reference_of", "return_knob", "run_detect_shift", "select_knobs"]


def plot_shift(results: Sequence[ShiftResult], path: str | os.PathLike, model: "Model | None" = None,
               background: Mapping[int, tuple[np.ndarray, np.ndarray]] | None = None,
               inputs: Iterable[str | os.PathLike] = ()) -> None:
    """Current against knob angle with the detected edges (the paper's Fig. 5b); PNG, atomic.

    Parameters
    ----------
    results : sequence of ShiftResult
        One panel per knob (:func:`.figure.shift_figure`).
    path : path-like
        The PNG file (written through a temporary file and a rename).
    background : mapping of knob to (q, current), optional
        The whole recorded current (a replay), drawn faintly behind the steps.
    inputs : iterable of path-like
        The command's inputs, never overwritten.
    """
    from ..report.figures import save_figure
    from .figure import shift_figure

    save_figure(shift_figure(results, model, background), path, inputs=inputs, fmt="png")
