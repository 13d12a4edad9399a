"""The figure of a shift search: current against knob angle with the detected edges (Fig. 5b).

Draws only; :func:`hystcli.shift.plot_shift` writes the PNG and :meth:`ShiftResult.plot` returns
the Figure. matplotlib loads when a figure is drawn, never on import.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Mapping, Sequence

import numpy as np

from ..errors import ShiftDetectionError

if TYPE_CHECKING:
    from ..core.model import Model


def shift_figure(results: Sequence, model: "Model | None" = None,
                 background: Mapping[int, tuple[np.ndarray, np.ndarray]] | None = None):  # noqa: ANN201
    """One panel per knob of ``results`` (:class:`~.result.ShiftResult`, whose ``plot`` calls
    this, so nothing here imports it): the search's steps (current vs angle), the edge it found
    (dot), the shifted dead zone :math:`[\\tilde D_{neg}, \\tilde D_{pos}]` (shaded) and, with ``model``, the
    straight-shaft edges (dotted); ``background`` (knob to (q, current)) draws a replay's whole
    record faintly behind the steps.

    Returns
    -------
    matplotlib.figure.Figure
    """
    from ..report import style

    results = list(results)
    if not results:
        raise ShiftDetectionError("nothing to plot: no knob was searched")
    fig, axes = style.new_figure(1, len(results))
    for ax, r in zip(axes[0], results):
        if background and r.knob in background:
            bq, bc = background[r.knob]
            ax.plot(bq, bc, **style.line("background"), label="record")
        tq = np.array([p[0] for p in r.trace])
        tc = np.array([p[1] for p in r.trace])
        ax.plot(tq, tc, **style.line("measured", linewidth=style.THIN_WIDTH), marker=".", ms=style.MARKER_SIZE,
                label="search steps")
        ax.axvspan(r.d_neg, r.d_pos, **style.band("shifted"), label=f"new dead zone [{r.d_neg:.1f}, {r.d_pos:.1f}]")
        if model is not None and r.knob in model.knobs:
            km = model.knob(r.knob)
            for i, d in enumerate((km.d_neg, km.d_pos)):
                ax.axvline(d, **style.line("edge"), label=None if i else "straight-shaft edges")
        edge_c = float(np.interp(r.edge_found_at, *_sorted(tq, tc))) if tq.size else 0.0
        ax.plot([r.edge_found_at], [edge_c], "o", color=style.COLOURS["shifted"], ms=style.EDGE_MARKER_SIZE,
                label=f"edge {r.edge} at {r.edge_found_at:.2f} deg")
        if r.evidence is not None:
            ax.axvspan(r.evidence.edge_lo, r.evidence.edge_hi, **style.band("interval"), label="edge interval")
        for i, cq in enumerate(r.contacts):
            ax.axvline(cq, **style.line("warning"), label=None if i else "contact")
        ax.set_xlabel(f"knob {r.knob} angle (deg)")
        ax.set_ylabel("motor current (mA)")
        style.title(ax, f"knob {r.knob}: offset {r.offset:+.2f} deg [{r.offset_lo:+.2f}, {r.offset_hi:+.2f}]")
        style.legend(ax)
    style.finish(fig)
    return fig


def _sorted(q: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    order = np.argsort(q, kind="stable")
    return q[order], c[order]
