"""Compensation within a motor's limits: the model's commands, and what to do with their jumps.

:meth:`Model.compensate` (:mod:`hystcli.core.model`) turns desired tip angles into knob commands
through the inverse of the model's chain. Its commands jump where the inverse must cross a flat
part of the loop (the dead zone, the backlash at a reversal: within one sample). Given a motor's
limits, this module decides what happens to those jumps: rate-limit them
(:func:`hystcli.safety.plan_motion`) and say what the knob's lag costs the tip on the model,
refuse them, or keep them.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from .core.model import Compensation, Model, predict_tip
from .core.run import Run
from .safety import CatchUp, Limits, plan_motion


def compensate(model: Model, trajectory: Run, ignore_shift: bool = False, *, limits: Limits | None = None,
               speed: str = "limit", name: str | None = None) -> Compensation:
    """Knob commands that make the model (with its effects, if any) follow the desired tip angles.

    The commands are :meth:`Model.compensate`'s (the exact inverse of the model and its
    effects); given ``limits``, they are checked against a motor's limits and their fast steps
    dealt with as ``speed`` says.

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
    ``offset<k>`` in the output is the shift in effect even with ``ignore_shift``
    (:meth:`Model.compensate` says why).
    """
    result = model.compensate(trajectory, ignore_shift=ignore_shift)
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
