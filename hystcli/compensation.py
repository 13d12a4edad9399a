"""Compensation of desired trajectories and the model's prediction of a run, as run files.

``compensate`` turns desired tip angles ``r<k>`` into knob commands ``q<k>`` through the inverse
of the model's chain (docs/design.md section 3 and the model's effects, :func:`hystcli.effects.inverse`;
with no effects, exactly each knob's inverse), shifted by the offset in effect for the trajectory
(the paper's Compensation+Shift) or not shifted at all (``ignore_shift``: the paper's
Compensation-Only). ``predict`` runs the chain forward on a run's commands: the "sim" that the
evaluation and the diagnosis compare with measurement. This module adds what a file needs around
the chain: which knobs, the metadata, the warnings. :meth:`Model.predict` and
:meth:`Model.compensate` are these two functions.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .effects import chain
from .errors import DataError, ModelError
from .io import Run
from .model import Model


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
    """

    run: Run
    offsets: dict
    warnings: tuple = ()


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


def compensate(model: Model, trajectory: Run, ignore_shift: bool = False) -> Compensation:
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

    Returns
    -------
    Compensation

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
    for name, values in trajectory.columns.items():
        if name != "t" and not (name.startswith("q") and name[1:] in ("1", "2")):
            cols[name] = values
    cols.update(new_cols)
    meta = dict(trajectory.meta)
    meta["controller"] = controller
    for k in knobs:
        meta[f"offset{k}"] = repr(float(in_effect[k]))
    if ignore_shift:
        meta["shift_ignored"] = "true"
    else:
        meta.pop("shift_ignored", None)
    return Compensation(Run(cols, meta, trajectory.source), offsets, tuple(warnings))


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
