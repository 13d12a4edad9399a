"""Compensation of desired trajectories and the model's prediction of a run, as run files.

``compensate`` turns desired tip angles ``r<k>`` into knob commands ``q<k>`` through the inverse
of the model's chain (docs/design.md section 3 and the model's effects, :func:`hystcli.effects.inverse`;
with no effects, exactly each knob's inverse), shifted by the offset in effect for the trajectory
(the paper's Compensation+Shift) or not shifted at all (``ignore_shift``: the paper's
Compensation-Only). ``predict`` runs the chain forward on a run's commands: the "sim" that the
evaluation and the diagnosis compare with measurement. This module adds what a file needs around
the chain: which knobs, the metadata, the warnings, and, given a motor's limits, what to do with
the inverse's jumps (across the dead zone, across the backlash at a reversal: within one sample):
rate-limit them (:func:`hystcli.safety.plan_motion`) and say what the knob's lag costs the tip on
the model, refuse them, or keep them. :meth:`Model.predict` and :meth:`Model.compensate` are these
two functions.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .effects import chain
from .errors import DataError, ModelError
from .io import Run
from .model import Model
from .safety import CatchUp, Limits, MotionCheck, plan_motion


@dataclass(frozen=True)
class Compensation:
    """Result of :func:`compensate`.

    Attributes
    ----------
    run : Run
        The trajectory with ``q<k>`` added and metadata ``controller``, ``offset<k>`` (the shift
        in effect, docs/design.md section 6) and, for Compensation-Only, ``shift_ignored: true``.
    offsets : dict of int to float
        Offset the commands used per knob (deg): the shift in effect, or 0 with ``ignore_shift``.
    warnings : tuple of str
        Things the user should know (e.g. commands outside the identified range).
    check : MotionCheck or None
        The exact inverse's commands against the limits, when limits were given.
    catch_ups : dict of int to CatchUp
        Per knob whose commands were rate-limited (``speed="limit"``), how long the knob lags the
        exact inverse and the tip error that causes on the model.
    sent : MotionCheck or None
        The written commands against the limits, when limits were given.
    """

    run: Run
    offsets: dict
    warnings: tuple = ()
    check: MotionCheck | None = None
    catch_ups: dict = field(default_factory=dict)
    sent: MotionCheck | None = None

    def summary(self) -> str:
        """One line per knob (its commands' range and the offset they used), then the warnings."""
        lines = []
        for k, off in sorted(self.offsets.items()):
            q = np.asarray(self.run[f"q{k}"], dtype=float)
            lines.append(f"knob {k}: {q.size} commands in [{q.min():+.2f}, {q.max():+.2f}] deg, "
                         f"offset {off:+.2f} deg" if q.size else f"knob {k}: no commands")
        return "\n".join(lines + [f"warning: {w}" for w in self.warnings])


def knobs_of(model: Model, run: Run, prefix: str, what: str, name: str | None = None) -> list[int]:
    """Knobs with a ``{prefix}<k>`` column in ``run``, each checked to be a knob of ``model``.

    Raises :class:`DataError` when the run has no such column and :class:`ModelError` when the
    model lacks one of the run's knobs; ``name`` (default: the run's source) names the run.
    """
    name = name or run.source or "run"
    knobs = run.knobs(prefix)
    if not knobs:
        raise DataError(f"{name}: no {what} column ({prefix}1 or {prefix}2)")
    for k in knobs:
        if k not in model.knobs:
            raise ModelError(f"{name} has column {prefix}{k} but the model has no knob {k} "
                             f"(it has knobs {', '.join(map(str, model.knobs))})")
    return knobs


def compensate(model: Model, trajectory: Run, ignore_shift: bool = False, *, limits: Limits | None = None,
               speed: str = "limit", name: str | None = None) -> Compensation:
    """Knob commands that make the model (with its effects, if any) follow the desired tip angles.

    Without effects this is the exact inverse of docs/design.md section 3; with the effects
    ``hyst diagnose`` added to the model, :func:`hystcli.effects.inverse` undoes them stage by
    stage as well (the same call: no effects is the chain with no stage).

    Parameters
    ----------
    model : Model
        Identified (and possibly shifted) model.
    trajectory : Run
        Desired tip angles ``r1`` and/or ``r2`` with time ``t``.
    ignore_shift : bool
        Use offset 0 for every knob (Compensation-Only) instead of the offset in effect
        (Compensation+Shift; which offset is docs/design.md section 6's rule, :meth:`Model.offsets_for`).
    limits : Limits, optional
        A motor's limits: the commands are checked against them (travel is never waived) and a
        step beyond the speed (acceleration) limit is dealt with as ``speed`` says. None: the
        exact inverse, unchecked.
    speed : {"limit", "strict", "fast"}
        With ``limits``: rate-limit the knob across such a step and let it catch up with the
        exact inverse (the catch-up and the tip error it causes on the model come back in
        ``catch_ups`` and as a warning), refuse the commands, or keep the exact inverse
        (:func:`hystcli.safety.plan_motion`).
    name : str, optional
        How a refusal names the commands (default: the trajectory's source), e.g. the file they
        were to be written to.

    Returns
    -------
    Compensation

    Raises
    ------
    LimitExceeded
        With ``limits``: a command beyond the travel limit, or with ``speed="strict"`` a step
        beyond the speed or acceleration limit.

    Notes
    -----
    The output's ``offset<k>`` is the shift in effect for the trajectory even when
    ``ignore_shift`` leaves it out of the commands (then ``shift_ignored: true`` says so): a run
    played from these commands is then predicted, evaluated and diagnosed with the shaft's shift,
    which the tip undergoes whatever the controller assumed. (docs/design.md section 6 calls
    ``offset<k>`` "the shift in effect for this run, as detected" and also "the offsets compensate
    used"; for Compensation-Only the two differ, and the first is what predictions need.)
    """
    knobs = knobs_of(model, trajectory, "r", "desired tip angle")
    in_effect = {k: v for k, v in model.offsets_for(trajectory.meta).items() if k in knobs}
    offsets = {k: 0.0 for k in knobs} if ignore_shift else in_effect
    new_cols: dict[str, np.ndarray] = {}
    inv = chain.inverse(model, trajectory, offsets=offsets, knobs=knobs)
    warnings: list[str] = list(inv.warnings)
    for k in knobs:
        q = inv.q[k]
        new_cols[f"q{k}"] = q
        ident = model.identification.get(k)
        if ident is not None:
            u = q - offsets[k]
            lo, hi = float(np.min(u)), float(np.max(u))
            if lo < ident.q_min - 1e-9 or hi > ident.q_max + 1e-9:
                warnings.append(
                    f"knob {k}: commands reach {lo:.1f}..{hi:.1f} deg (relative to the offset), outside "
                    f"the identified range {ident.q_min:.1f}..{ident.q_max:.1f} deg: the model is extrapolated")
    controller = "comp" if ignore_shift or all(o == 0.0 for o in offsets.values()) else "comp+shift"
    cols = {"t": trajectory.t}
    for col, values in trajectory.columns.items():
        if col != "t" and not (col.startswith("q") and col[1:] in ("1", "2")):
            cols[col] = values
    cols.update(new_cols)
    meta = dict(trajectory.meta)
    meta["controller"] = controller
    for k in knobs:
        meta[f"offset{k}"] = repr(float(in_effect[k]))
    if ignore_shift:
        meta["shift_ignored"] = "true"
    else:
        meta.pop("shift_ignored", None)
    result = Compensation(Run(cols, meta, trajectory.source), offsets, tuple(warnings))
    return result if limits is None else _within(model, result, limits, speed, name)


def _within(model: Model, result: Compensation, limits: Limits, speed: str, name: str | None) -> Compensation:
    """``result`` checked against ``limits``, its fast steps dealt with as ``speed`` says; each
    rate-limited knob's catch-up carries the largest change of the model's tip it causes."""
    plan = plan_motion(result.run, limits, speed, name=name, action="write")
    catch_ups: dict[int, CatchUp] = {}
    if plan.catch_ups:
        exact, limited = predict_tip(model, result.run), predict_tip(model, plan.run)
        for k, c in plan.catch_ups.items():
            catch_ups[k] = replace(c, tip_error=float(np.max(np.abs(limited[k] - exact[k]))))
    warnings = result.warnings + tuple(c.message for c in catch_ups.values())
    return replace(result, run=plan.run, warnings=warnings, check=plan.check, catch_ups=catch_ups,
                   sent=plan.sent)


def predict_tip(model: Model, run: Run) -> dict[int, np.ndarray]:
    """Tip angle the model (with its effects, if any) predicts for the run's commands ``q<k>``.

    Each knob uses the offset in effect for the run (:meth:`Model.offsets_for`) and starts from
    the run's first measured ``y<k>`` when there is one, else from 0 (docs/design.md section 3).
    """
    knobs = knobs_of(model, run, "q", "knob command")
    ys = chain.predict(model, run)
    return {k: ys[k] for k in knobs}


def predict(model: Model, run: Run) -> Run:
    """The run with ``y<k>`` replaced by the model's prediction.

    A measured ``y<k>`` is kept as ``y<k>_measured`` so that the file shows sim beside real.
    """
    ys = predict_tip(model, run)
    cols: dict[str, np.ndarray] = {}
    for name, values in run.columns.items():
        if name in (f"y{k}" for k in ys):
            cols[f"{name}_measured"] = values
        else:
            cols[name] = values
    for k, y in ys.items():
        cols[f"y{k}"] = y
    meta = dict(run.meta)
    meta["predicted_by"] = "hyst predict"
    offsets = model.offsets_for(run.meta)
    for k in ys:
        meta.setdefault(f"offset{k}", repr(float(offsets[k])))
    return Run(cols, meta, run.source)
