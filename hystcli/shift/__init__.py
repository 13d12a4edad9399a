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

from ..errors import ShiftDetectionError
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
        One panel per knob: the search's steps (current vs angle), the edge it found (dot), the
        shifted dead zone :math:`[\\tilde D_{neg}, \\tilde D_{pos}]` (shaded) and, with
        ``model``, the straight-shaft edges (dotted).
    path : path-like
        The PNG file (written through a temporary file and a rename).
    background : mapping of knob to (q, current), optional
        The whole recorded current (a replay), drawn faintly behind the steps.
    inputs : iterable of path-like
        The command's inputs, never overwritten.
    """
    from matplotlib.figure import Figure

    from ..io import atomic_write
    from ..report.figures import figure_bytes

    results = list(results)
    if not results:
        raise ShiftDetectionError("nothing to plot: no knob was searched")
    fig = Figure(figsize=(5.5 * len(results), 4.0))
    axes = fig.subplots(1, len(results), squeeze=False)
    for ax, r in zip(axes[0], results):
        if background and r.knob in background:
            bq, bc = background[r.knob]
            ax.plot(bq, bc, color="0.8", lw=0.8, label="record")
        tq = np.array([p[0] for p in r.trace])
        tc = np.array([p[1] for p in r.trace])
        ax.plot(tq, tc, ".-", color="tab:blue", ms=3, lw=0.8, label="search steps")
        ax.axvspan(r.d_neg, r.d_pos, color="tab:green", alpha=0.12,
                   label=f"new dead zone [{r.d_neg:.1f}, {r.d_pos:.1f}]")
        if model is not None and r.knob in model.knobs:
            km = model.knob(r.knob)
            for d in (km.d_neg, km.d_pos):
                ax.axvline(d, color="0.4", ls=":", lw=1)
        edge_c = float(np.interp(r.edge_found_at, *_sorted(tq, tc))) if tq.size else 0.0
        ax.plot([r.edge_found_at], [edge_c], "o", color="tab:red", ms=8,
                label=f"edge {r.edge} at {r.edge_found_at:.2f} deg")
        if r.evidence is not None:
            ax.axvspan(r.evidence.edge_lo, r.evidence.edge_hi, color="tab:red", alpha=0.15)
        for cq in r.contacts:
            ax.axvline(cq, color="tab:orange", ls="--", lw=1)
        ax.set_xlabel(f"knob {r.knob} angle (deg)")
        ax.set_ylabel("motor current (mA)")
        ax.set_title(f"knob {r.knob}: offset {r.offset:+.2f} deg [{r.offset_lo:+.2f}, {r.offset_hi:+.2f}]")
        ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    data = figure_bytes(fig, "png")
    atomic_write(path, lambda f: f.write(data), inputs=inputs)


def _sorted(q: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    order = np.argsort(q, kind="stable")
    return q[order], c[order]
