"""The sim-to-real gap: where the model departs from measurement, which effect causes it, how far
adding that effect closes it, checked on whole runs the fit never saw (docs/design.md section 8).

Three questions, one :func:`diagnose` call:

WHERE
    The residual ``e = y - predict(model, run)`` (deg), broken down by the phase of the
    hysteresis loop the model itself is in at each sample (backlash plateau, unloading slope,
    dead zone, loading slope: the paper's lines L1/L5, L2/L6, L3/L7, L4/L8), the knob direction,
    the shaft shape, the knob speed band, the amplitude band (knob angle from the offset),
    whether the other knob moves, and the time within the run. Each level gets its share of
    the samples, its share of the residual energy ``sum(e**2)`` and its RMSE; the level with the
    largest energy-to-sample ratio is the dominant finding.

WHICH, before any fit
    What physical quantity the residual follows, whatever the form of the effect behind it
    (:mod:`.attribution`): the other knob's angle and bend, knob velocity, time since a
    reversal, elapsed time, curvature, the stated condition, the tip angle, each scored by the
    share of the residual it explains on held-out runs. Reported in WHERE; it orders the
    candidates, and what it still finds after the chosen effects is named in the verdict
    ("Unexplained: the residual follows ...").

WHICH, fitted
    Every effect of :data:`hystcli.core.effects.EFFECTS` is a candidate family (one driven by a
    stated ``condition`` only when a run states one). Nothing here knows one effect from another:
    each family's forms bring their grids, bounds and the runs they act on
    (:mod:`hystcli.core.effects.base`), and :mod:`.search` makes the table of every run's SSE
    at every grid point of every form, so a fit on any set of training runs is a weighted column
    sum and a pick (no refit per fold): by BIC among forms, only where enough runs see a form,
    between the grid's neighbours along a one-parameter form's axis. Whole runs are held out:
    leave-one-run-out by default, or ``key=value`` (train on the runs whose metadata ``key``
    differs, test on the others). Families are ranked by the held-out RMSE they reach; a training
    information criterion (BIC, with AIC beside it) must improve too. Greedy forward selection
    adds the best family (in the form the all-run fit picks, refined by Gauss-Newton) while its
    held-out RMSE shrink is at least :data:`MIN_GAIN_PCT` % of the current held-out RMSE, at most
    ``max_effects`` effects. In the second and later rounds the effects already chosen keep
    their all-run fit (a small optimism in the *selection* only; the figures of HOW FAR refit
    everything per fold). ``bootstrap > 0`` resamples the runs with replacement: the whole
    selection is repeated for the inclusion frequency of each effect, the chosen set refitted for
    95 % intervals. When nothing passes the threshold the report says so and describes the
    residual that remains instead of naming a cause.

HOW FAR
    Per fold, the chosen effects are refitted jointly on the training runs (bounded Gauss-Newton
    from the better, on the training runs, of the fold's own picks and the all-run fit) and predict
    the held-out runs at full rate: held-out RMSE (pooled over samples) and PTPE (mean over run
    and knob) before and after, shrink in %.

Runs at 100 Hz or faster are decimated for the search (to at least 50 Hz); the figures of WHERE and
HOW FAR use every sample. The search is deterministic; only the bootstrap draws, from ``seed``.

Modules: :mod:`.pipeline` (the entry point), :mod:`.result` (the result types), :mod:`.where`
(WHERE and the runs' validation), :mod:`.select` (the folds and the selection), :mod:`.search`
(the SSE table), :mod:`.attribution` (what the residual follows), :mod:`.drive` (which side of
the tendons a delay sits), :mod:`.refit` (the loop re-identified under a lag), :mod:`.figure`.
"""
from __future__ import annotations

from .figure import diagnosis_axes, diagnosis_figure
from .pipeline import diagnose
from .result import (MIN_GAIN_PCT, PHASES, Breakdown, Candidate, Diagnosis, HowFar, Residual, Round, RunFigures,
                     Selected, Where)

__all__ = ["MIN_GAIN_PCT", "PHASES", "Breakdown", "Candidate", "Diagnosis", "HowFar", "Residual", "Round",
           "RunFigures", "Selected", "Where", "diagnose", "diagnosis_axes", "diagnosis_figure"]
