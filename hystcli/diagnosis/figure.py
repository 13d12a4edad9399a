"""The diagnosis figure: WHERE's breakdown and HOW FAR's runs, before and after the chosen effects."""
from __future__ import annotations

from dataclasses import replace
from typing import Sequence

import numpy as np

from .. import effects as E
from ..io import Run
from .result import Diagnosis


def diagnosis_figure(diag: Diagnosis, runs: Sequence[Run]) -> bytes:
    """PNG bytes of :func:`diagnosis_axes`' figure."""
    import io as _io

    fig = diagnosis_axes(diag, runs)
    buf = _io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    return buf.getvalue()


def diagnosis_axes(diag: Diagnosis, runs: Sequence[Run]):  # noqa: ANN201 - matplotlib.figure.Figure
    """The diagnosis figure: WHERE (energy vs sample share per factor, %), what the residual follows
    (held-out %), and the held-out run the effects improve most, measured beside the model before
    and after (deg against s). matplotlib's Figure API: no global backend is switched.

    The shares and the explained energy are drawn on a 0-100 % axis (each explained-energy bar
    labelled with its value): a 0.2 % bar looks like 0.2 %, not like the panel's full height.
    """
    import textwrap

    from matplotlib.figure import Figure

    fig = Figure(figsize=(12, 8.5))
    axes = fig.subplots(2, 2)
    for ax, factor in zip(axes.flat[:2], ("phase", "speed")):
        gs = diag.where.factor(factor)
        x = np.arange(len(gs))
        ax.bar(x - 0.2, [100 * g.sample_share for g in gs], 0.4, label="samples")
        ax.bar(x + 0.2, [100 * g.energy_share for g in gs], 0.4, label="residual energy")
        ax.set_xticks(x, [g.level for g in gs], rotation=20, fontsize=8)
        ax.set_ylim(0, 100)
        ax.set_ylabel("share (%)")
        ax.set_title(f"residual by {factor}", fontsize=10)
        ax.legend(fontsize=8)
    ax = axes.flat[2]
    follows = list(diag.where.follows)
    if follows:
        y = np.arange(len(follows))
        bars = ax.barh(y, [max(a.explained_pct, 0.0) for a in follows], color="tab:green")
        ax.bar_label(bars, [f"{a.explained_pct:.1f} %" for a in follows], padding=3, fontsize=8)
        ax.set_yticks(y, [a.regressor for a in follows], fontsize=8)
        ax.invert_yaxis()
    ax.set_xlim(0, 100)
    ax.set_xlabel("residual energy explained, held out (%)")
    ax.set_title("what the base model's residual follows", fontsize=10)
    ax = axes.flat[3]
    if diag.how_far.per_run:
        best = max(diag.how_far.per_run, key=lambda f: f.rmse_before - f.rmse_after)
        i = list(diag.runs).index(best.run)
        run = runs[i]
        base_model = replace(diag.model, effects=diag.model.effects[:len(diag.model.effects) - len(diag.selected)])
        before = E.predict(base_model, run)[best.knob]
        after = E.predict(diag.model, run)[best.knob]
        t = run.t
        ax.plot(t, run[f"y{best.knob}"], "k", lw=1, label="measured")
        ax.plot(t, before, lw=1, label=f"model (RMSE {best.rmse_before:.2f} deg)")
        ax.plot(t, after, lw=1, label=f"+ effects (RMSE {best.rmse_after:.2f} deg)")
        ax.set_xlabel("time t (s)")
        ax.set_ylabel(f"tip angle y{best.knob} (deg)")
        name = best.run if len(best.run) < 50 else "..." + best.run[-47:]
        ax.set_title(f"held out: {name}", fontsize=9)
        ax.legend(fontsize=8)
    # the verdict, wrapped to the figure's width (a long one is cut after three lines)
    lines = textwrap.wrap(diag.verdict, 150)
    fig.suptitle("\n".join(lines[:3]) + (" ..." if len(lines) > 3 else ""), fontsize=9)
    fig.tight_layout(rect=(0, 0, 1, 0.93))
    return fig
