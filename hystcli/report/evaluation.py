"""The evaluation's figure: time and input against output per controller, like the paper's Figs. 6
and 7 (``hyst evaluate --plot``, the demo's figures, ``Evaluation.plot``).

The drawing only: which run stands for which panel is the evaluation's choice
(:func:`hystcli.report.metrics.figure_columns`), so this module does not import the metrics and the
metrics' result can draw itself."""
from __future__ import annotations

from typing import Sequence

import numpy as np

from ..core.run import Run
from . import style

PLOT_POINTS = 4000
"""Samples per drawn line at most: a 420-pixel panel shows no more, and Agg renders 10 000-sample
lines several times slower."""


def _thin(*series: np.ndarray) -> tuple[np.ndarray, ...]:
    """Every k-th sample of each series (the last one kept), so a line has at most PLOT_POINTS."""
    n = len(series[0])
    if n <= PLOT_POINTS:
        return series
    idx = np.unique(np.r_[np.arange(0, n, int(np.ceil(n / PLOT_POINTS))), n - 1])
    return tuple(np.asarray(s)[idx] for s in series)


Columns = Sequence[tuple[tuple[str, str, int], Sequence[tuple[str, str, Run]]]]
"""The figure's columns: ((motion, shape, knob), ((controller, label, run), ...)), in order."""


def evaluation_axes(columns: Columns):  # noqa: ANN201 - matplotlib.figure.Figure
    """Time-vs-output and input-vs-output panels like the paper's Figs. 6 and 7, as a matplotlib
    ``Figure`` (:meth:`hystcli.report.metrics.Evaluation.plot`; the file is
    :func:`hystcli.report.metrics.evaluation_figure`'s).

    One column per (motion, shape, knob); in it, for each controller, one run; top: ``r`` (ground
    truth, the style's reference) and each controller's ``y`` against time; bottom: ``y`` against
    the input ``r``, with the ideal ``y = r`` as reference. Colours are the paper's
    (:data:`.style.CONTROLLER_COLOURS`): none blue, comp red, comp+shift green.

    Parameters
    ----------
    columns : sequence of ((motion, shape, knob), sequence of (controller, label, run))
        The panels' columns in order, each with its controllers in order (which run stands for
        which cell is the evaluation's choice, :func:`hystcli.report.metrics.figure_columns`).

    Returns
    -------
    matplotlib.figure.Figure
    """
    order = [c for c, _ in columns]
    motions = {c[0] for c in order}

    fig, axes = style.new_figure(2, len(order))
    extra: dict[str, str] = {}
    for j, ckey in enumerate(order):
        motion, shape, k = ckey
        by_ctrl = {c: run for c, _, run in columns[j][1]}
        labels = {c: label for c, label, _ in columns[j][1]}
        ctrls = list(by_ctrl)
        top, bottom = axes[0][j], axes[1][j]
        ref = by_ctrl[ctrls[0]]
        # ground truth drawn last and dashed, so a controller that tracks it perfectly hides nothing
        top.plot(*_thin(ref.t, ref[f"r{k}"]), **style.line("reference"), zorder=3, label="ground truth (r)")
        lo = min(float(np.min(by_ctrl[c][f"r{k}"])) for c in ctrls)
        hi = max(float(np.max(by_ctrl[c][f"r{k}"])) for c in ctrls)
        bottom.plot([lo, hi], [lo, hi], **style.line("reference"), zorder=3, label="ground truth (y = r)")
        for c in ctrls:
            run = by_ctrl[c]
            colour = style.controller_colour(c, extra)
            label = labels[c]
            top.plot(*_thin(run.t, run[f"y{k}"]), **style.line("measured", color=colour), label=label)
            bottom.plot(*_thin(run[f"r{k}"], run[f"y{k}"]), **style.line("measured", color=colour), label=label)
        style.title(top, f"{shape}, knob {k}" + (f", {motion}" if len(motions) > 1 else ""))
        top.set_xlabel("time (s)")
        top.set_ylabel(f"output angle y{k} (deg)")
        bottom.set_xlabel(f"input angle r{k} (deg)")
        bottom.set_ylabel(f"output angle y{k} (deg)")
    # one legend for the whole figure: the first column (often the straight shaft) lacks the
    # controllers that only the bent shapes run (Compensation+Shift, the diagnosed one)
    legend: dict[str, object] = {}
    for ax in axes[0]:
        for handle, label in zip(*ax.get_legend_handles_labels()):
            legend.setdefault(label, handle)
    width, height = fig.get_size_inches()
    ncol = min(len(legend), 5, max(2, int(width // 2.4)))   # a label is about 2.4 in wide
    rows = -(-len(legend) // ncol)
    style.legend(fig, list(legend.values()), list(legend), ncol=ncol)
    # fixed margins in inches rather than tight_layout, which draws the whole figure once more
    # just to measure its labels (a second of the demo)
    panel_w, panel_h = style.PANEL_SIZE
    fig.subplots_adjust(left=0.75 / width, right=1.0 - 0.15 / width, bottom=(0.75 + 0.2 * rows) / height,
                        top=1.0 - 0.3 / height, wspace=0.85 / panel_w / 0.8, hspace=0.65 / (panel_h - 0.5))
    return fig


__all__ = ["evaluation_axes"]
