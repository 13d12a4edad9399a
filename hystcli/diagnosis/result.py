"""What a diagnosis answers: its thresholds and the result types (WHERE, WHICH, HOW FAR, the
verdict)."""
from __future__ import annotations

import math
import textwrap
from dataclasses import dataclass, field, replace
from typing import Mapping, Sequence

import numpy as np

from ..core import effects as E
from ..core.model import Model
from ..core.run import Run
from . import attribution as A
from . import drive as D


MIN_GAIN_PCT = 5.0
"""Smallest held-out RMSE shrink (%) for a candidate to join the model.

Sensor noise alone leaves every candidate within about 1 % of the base model on held-out runs
(the fit finds nothing that generalises); a real effect of the magnitudes a catheter shows gives
tens of %. 5 % sits between with room on both sides (bench/withheld.py measures both)."""

MOVING_DEG_S = 0.5
"""A knob moves when its speed exceeds this (deg/s)."""

SPEED_BANDS = (1.0, 5.0, 15.0, 40.0)
"""Edges of the knob-speed bands (deg/s)."""

AMPLITUDE_BANDS = (10.0, 20.0, 40.0)
"""Edges of the amplitude bands: knob angle from the offset (deg)."""

TIME_BINS = 5
"""Equal parts of each run's duration for the time breakdown."""

PHASES = ("backlash plateau", "unloading slope", "dead zone", "loading slope")


# --------------------------------------------------------------------------------------------
# results
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Breakdown:
    """One level of one factor of the residual (WHERE).

    Attributes
    ----------
    factor, level : str
    samples : int
    sample_share, energy_share : float
        Fractions (0..1) of all samples and of the residual energy ``sum(e**2)``.
    rmse : float
        RMSE of the residual within the level (deg).
    """

    factor: str
    level: str
    samples: int
    sample_share: float
    energy_share: float
    rmse: float

    @property
    def lift(self) -> float:
        """Energy share over sample share: > 1 where the residual concentrates."""
        return self.energy_share / self.sample_share if self.sample_share > 0 else 0.0


@dataclass(frozen=True)
class Where:
    """Where the residual lies: ``rmse`` overall and every factor's levels; ``finding`` in words."""

    rmse: float
    samples: int
    groups: tuple[Breakdown, ...]
    finding: str
    follows: tuple[A.Attribution, ...] = ()
    """What the residual follows: physical regressors ranked by the held-out share they explain."""

    def factor(self, name: str) -> tuple[Breakdown, ...]:
        """The levels of one factor."""
        return tuple(g for g in self.groups if g.factor == name)


@dataclass(frozen=True)
class Candidate:
    """One candidate effect in one round of the selection (WHICH).

    Attributes
    ----------
    name : str
    params : mapping
        Fitted on all runs (the selection's training fit).
    heldout_rmse : float
        Pooled RMSE on the held-out runs, each fold fitted without them (deg).
    gain_pct : float
        Held-out RMSE shrink against the round's base (%).
    delta_bic, delta_aic : float
        Change of the training information criteria against the round's base (< 0: better).
    rank : int
        1 = best held-out RMSE among the candidates whose BIC improves.
    form : str
        The family's form the all-run fit chose (the name is the physics, the form how it shows).
    """

    name: str
    params: Mapping[str, float]
    heldout_rmse: float
    gain_pct: float
    delta_bic: float
    delta_aic: float
    rank: int
    form: str = ""


@dataclass(frozen=True)
class Round:
    """One step of the greedy forward selection."""

    base: tuple[str, ...]
    base_heldout_rmse: float
    candidates: tuple[Candidate, ...]
    chosen: str | None


@dataclass(frozen=True)
class Selected:
    """An effect the diagnosis adds, with its bootstrap interval and inclusion frequency."""

    name: str
    params: Mapping[str, float]
    interval: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    inclusion: float | None = None
    form: str = ""

    def effect(self) -> E.Effect:
        return E.make_effect(self.name, self.form or None, **self.params)


@dataclass(frozen=True)
class RunFigures:
    """HOW FAR for one held-out run and knob."""

    run: str
    knob: int
    rmse_before: float
    rmse_after: float
    ptpe_before: float
    ptpe_after: float


@dataclass(frozen=True)
class HowFar:
    """Held-out RMSE (pooled) and PTPE (mean over runs and knobs) before and after, deg and %."""

    rmse_before: float
    rmse_after: float
    ptpe_before: float
    ptpe_after: float
    per_run: tuple[RunFigures, ...]

    @property
    def rmse_shrink_pct(self) -> float:
        return _shrink(self.rmse_before, self.rmse_after)

    @property
    def ptpe_shrink_pct(self) -> float:
        return _shrink(self.ptpe_before, self.ptpe_after)


@dataclass(frozen=True)
class Residual:
    """What remains after the chosen effects: its size and what it follows (correlations)."""

    rmse: float
    noise_rmse: float
    autocorr_1s: float
    corr_speed: float
    corr_abs_speed: float
    corr_other_knob: float | None
    corr_command: float
    description: str


@dataclass(frozen=True)
class Diagnosis:
    """Result of :func:`diagnose`: the augmented model and the three answers.

    Attributes
    ----------
    model : Model
        The input model with the chosen effects appended to ``effects``.
    where : Where
    rounds : tuple of Round
        Round 1 ranks every candidate against the base model.
    selected : tuple of Selected
    how_far : HowFar
    residual : Residual
        After the chosen effects (the base model's residual when none was chosen).
    holdout : str
        The hold-out scheme in words.
    verdict : str
        The answer in one or two sentences.
    """

    model: Model
    where: Where
    rounds: tuple[Round, ...]
    selected: tuple[Selected, ...]
    how_far: HowFar
    residual: Residual
    holdout: str
    verdict: str
    runs: tuple[str, ...] = ()
    bootstrap: int = 0
    left: tuple[A.Attribution, ...] = ()
    """What the residual still follows after the chosen effects (held out)."""
    drive: D.TipBehindCurrent | None = None
    """How long the sweep's tip trails its motor current at the edges (given a sweep with current):
    the evidence on which side of the tendons a delay sits (:mod:`hystcli.diagnosis.drive`)."""

    def summary(self) -> str:
        """The verdict, then each effect added with its parameters."""
        added = [f"added {s.name}{f' ({s.form})' if s.form else ''}: "
                 + ", ".join(f"{k} = {v:.4g}" for k, v in s.params.items()) for s in self.selected]
        return "\n".join([self.verdict] + (added or ["no effect added"]))

    def plot(self, runs: Sequence[Run]):  # noqa: ANN201 - matplotlib.figure.Figure, imported only when drawn
        """The diagnosis figure: WHERE (energy vs sample share per factor, %), what the residual
        follows (held-out %), and the held-out run the effects improve most, measured beside the
        model before and after (deg against s). matplotlib's Figure API: no global backend is
        switched, nothing is shown.

        The shares and the explained energy are drawn on a 0-100 % axis (each explained-energy bar
        labelled with its value): a 0.2 % bar looks like 0.2 %, not like the panel's full height.

        Parameters
        ----------
        runs : sequence of Run
            The runs diagnosed, in the order given to :func:`diagnose` (the result keeps their
            names, not their samples).

        Returns
        -------
        matplotlib.figure.Figure
            What ``hyst diagnose --plot`` saves.
        """
        from ..report import style

        fig, axes = style.new_figure(2, 2)
        for ax, factor in zip(axes.flat[:2], ("phase", "speed")):
            gs = self.where.factor(factor)
            x = np.arange(len(gs))
            ax.bar(x - 0.2, [100 * g.sample_share for g in gs], 0.4, color=style.series_colour(0), label="samples")
            ax.bar(x + 0.2, [100 * g.energy_share for g in gs], 0.4, color=style.series_colour(1),
                   label="residual energy")
            ax.set_xticks(x, [g.level for g in gs], rotation=20)
            ax.set_ylim(0, 100)
            ax.set_ylabel("share (%)")
            style.title(ax, f"residual by {factor}")
            style.legend(ax)
        ax = axes.flat[2]
        follows = list(self.where.follows)
        if follows:
            y = np.arange(len(follows))
            bars = ax.barh(y, [max(a.explained_pct, 0.0) for a in follows], color=style.series_colour(2))
            ax.bar_label(bars, [f"{a.explained_pct:.1f} %" for a in follows], padding=3, fontsize=style.NOTE_SIZE)
            ax.set_yticks(y, [a.regressor for a in follows])
            ax.invert_yaxis()
        ax.set_xlim(0, 100)
        ax.set_xlabel("residual energy explained, held out (%)")
        style.title(ax, "what the base model's residual follows")
        ax = axes.flat[3]
        if self.how_far.per_run:
            best = max(self.how_far.per_run, key=lambda f: f.rmse_before - f.rmse_after)
            i = list(self.runs).index(best.run)
            run = runs[i]
            base = self.model.effects[:len(self.model.effects) - len(self.selected)]
            base_model = replace(self.model, effects=base)
            before = E.predict(base_model, run)[best.knob]
            after = E.predict(self.model, run)[best.knob]
            t = run.t
            ax.plot(t, run[f"y{best.knob}"], **style.line("measured"), label="measured")
            ax.plot(t, before, **style.line("model"), label=f"model (RMSE {best.rmse_before:.2f} deg)")
            ax.plot(t, after, **style.line("augmented"), label=f"+ effects (RMSE {best.rmse_after:.2f} deg)")
            ax.set_xlabel("time t (s)")
            ax.set_ylabel(f"tip angle y{best.knob} (deg)")
            name = best.run if len(best.run) < 40 else "..." + best.run[-37:]
            style.title(ax, f"held out: {name}")
            style.legend(ax)
        # the verdict, wrapped to the figure's width (a long one is cut after three lines)
        lines = textwrap.wrap(self.verdict, 110)
        fig.suptitle("\n".join(lines[:3]) + (" ..." if len(lines) > 3 else ""), fontsize=style.SUPTITLE_SIZE)
        style.finish(fig)
        return fig

    @property
    def ranking(self) -> tuple[Candidate, ...]:
        """Round 1's candidates, best first."""
        return tuple(sorted(self.rounds[0].candidates, key=lambda c: c.rank)) if self.rounds else ()

    def report(self) -> dict:
        """A JSON-able dict of everything (the ``-o REPORT.json`` file)."""
        hf = self.how_far
        return {
            "format": "hyst-diagnosis", "version": 1,
            "runs": list(self.runs),
            "holdout": self.holdout,
            "verdict": self.verdict,
            "where": {
                "rmse": _r(self.where.rmse), "samples": self.where.samples,
                "finding": self.where.finding,
                "follows": [{"regressor": a.regressor, "explained_pct": _r(a.explained_pct, 2)}
                            for a in self.where.follows],
                "factors": _factors_dict(self.where.groups),
            },
            "which": {
                "min_gain_pct": MIN_GAIN_PCT,
                "rounds": [{
                    "base": list(rd.base), "base_heldout_rmse": _r(rd.base_heldout_rmse),
                    "chosen": rd.chosen,
                    "candidates": [{"rank": c.rank, "name": c.name, "form": c.form, "params": _rd(c.params),
                                    "heldout_rmse": _r(c.heldout_rmse), "gain_pct": _r(c.gain_pct),
                                    "delta_bic": _r(c.delta_bic), "delta_aic": _r(c.delta_aic)}
                                   for c in sorted(rd.candidates, key=lambda c: c.rank)],
                } for rd in self.rounds],
                "selected": [{"name": s.name, "form": s.form or s.effect().form, "params": _rd(s.params),
                              "interval95": {p: [_r(a), _r(b)] for p, (a, b) in s.interval.items()},
                              "inclusion": s.inclusion} for s in self.selected],
                "bootstrap": self.bootstrap,
                "delay_side": None if self.drive is None else {
                    "tip_behind_current_s": _r(self.drive.delay), "speed_deg_s": _r(self.drive.speed, 3),
                    "readings": [{"knob": k, "side": sd, "tip_minus_current_deg": _r(dd, 4), "speed_deg_s": _r(v, 3)}
                                 for k, sd, dd, v in self.drive.readings]},
            },
            "how_far": {
                "rmse_before": _r(hf.rmse_before), "rmse_after": _r(hf.rmse_after),
                "rmse_shrink_pct": _r(hf.rmse_shrink_pct),
                "ptpe_before": _r(hf.ptpe_before), "ptpe_after": _r(hf.ptpe_after),
                "ptpe_shrink_pct": _r(hf.ptpe_shrink_pct),
                "per_run": [{"run": f.run, "knob": f.knob, "rmse_before": _r(f.rmse_before),
                             "rmse_after": _r(f.rmse_after), "ptpe_before": _r(f.ptpe_before),
                             "ptpe_after": _r(f.ptpe_after)} for f in hf.per_run],
            },
            "residual": {
                "rmse": _r(self.residual.rmse), "noise_rmse": _r(self.residual.noise_rmse),
                "autocorr_1s": _r(self.residual.autocorr_1s),
                "corr_speed": _r(self.residual.corr_speed),
                "corr_abs_speed": _r(self.residual.corr_abs_speed),
                "corr_other_knob": _r(self.residual.corr_other_knob),
                "corr_command": _r(self.residual.corr_command),
                "description": self.residual.description,
                "follows": [{"regressor": a.regressor, "explained_pct": _r(a.explained_pct, 2)} for a in self.left],
            },
            "effects": [{"name": e.name, **({"form": e.form} if e.form else {}), "params": _rd(e.params)}
                        for e in self.model.effects],
        }


def _r(x: float | None, nd: int = 6) -> float | None:
    if x is None or not math.isfinite(x):
        return None
    return round(float(x), nd)


def _rd(params: Mapping[str, float]) -> dict:
    return {k: (_r(v) if math.isfinite(v) else ("inf" if v > 0 else "-inf")) for k, v in params.items()}


def _factors_dict(groups: Sequence[Breakdown]) -> dict:
    out: dict[str, list] = {}
    for g in groups:
        out.setdefault(g.factor, []).append({
            "level": g.level, "samples": g.samples, "sample_share": _r(g.sample_share),
            "energy_share": _r(g.energy_share), "rmse": _r(g.rmse)})
    return out


def _shrink(before: float, after: float) -> float:
    return 100.0 * (before - after) / before if before > 0 else 0.0
