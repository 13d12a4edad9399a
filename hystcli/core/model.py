"""The catheter's model: its knobs, geometry, effects and identification, and what it does with a run.

:class:`Model` holds one :class:`~hystcli.core.params.KnobModel` per knob and what goes with them;
:meth:`Model.predict` runs the model's effect chain (:mod:`hystcli.core.effects`) forward on a run's
commands (the "sim" that the evaluation and the diagnosis compare with measurement), and
:meth:`Model.compensate` runs it backward from desired tip angles ``r<k>`` to knob commands
``q<k>``, shifted by the offset in effect for the trajectory (the paper's Compensation+Shift) or
not shifted at all (``ignore_shift``: the paper's Compensation-Only). Both come back as runs, with
the metadata and warnings a file needs. What to do with the inverse's jumps given a motor's limits
(rate-limit, refuse, keep) is :func:`hystcli.compensation.compensate`'s, a layer up.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import Mapping, Sequence

import numpy as np

from ..errors import DataError, ModelError
from ..safety import MotionCheck
from .params import EffectSpec, Geometry, KnobIdentification, KnobModel, Shape, rotate_offsets
from .run import Run


@dataclass(frozen=True)
class Model:
    """A catheter's hysteresis model: one :class:`KnobModel` per knob, plus optional extras.

    Attributes
    ----------
    knobs : mapping of int to KnobModel
        Knob index (1 = anterior-posterior, 2 = right-left) to its model.
    geometry : Geometry or None
        Tendon geometry, for the shift a known shape causes.
    effects : tuple of EffectSpec
        Unmodelled effects added by ``hyst diagnose``.
    meta : mapping
        Free-form provenance (catheter, source, sha256, source_modified).
    identification : mapping of int to KnobIdentification
        What identification learnt per knob (current-slope levels, range, uncertainties).
    """

    knobs: Mapping[int, KnobModel]
    geometry: Geometry | None = None
    effects: tuple[EffectSpec, ...] = ()
    meta: Mapping[str, object] = field(default_factory=dict)
    identification: Mapping[int, KnobIdentification] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not self.knobs:
            raise ModelError("a model needs at least one knob")
        for k, v in self.knobs.items():
            if k not in (1, 2):
                raise ModelError(f"knob {k!r} is not a knob of a two-knob catheter (1 or 2)")
            if not isinstance(v, KnobModel):
                raise ModelError(f"knob {k} is not a KnobModel")
        object.__setattr__(self, "knobs", MappingProxyType(dict(sorted(self.knobs.items()))))
        object.__setattr__(self, "effects", tuple(self.effects))
        object.__setattr__(self, "meta", MappingProxyType(dict(self.meta)))
        object.__setattr__(self, "identification", MappingProxyType(dict(self.identification)))

    def require_loop(self, knobs: Sequence[int], what: str) -> None:
        """Refuse to predict or compensate with a knob whose backlash is a placeholder: a
        current-only identification whose current did not show it (the model keeps 0 deg there,
        which predicts nothing). A tip identification's unfixed backlash predicts its record as
        well as the best fit and is used.

        Raises
        ------
        ModelError
            When such a knob is among ``knobs``.
        """
        for k in knobs:
            ident = self.identification.get(int(k))
            if ident is None or ident.method != "current":
                continue
            unfixed = [u for u in ("b_pos", "b_neg") if u in ident.unfixed]
            if unfixed:
                raise ModelError(
                    f"cannot {what} with this model: knob {k}'s {' and '.join(unfixed)} "
                    f"{'were' if len(unfixed) > 1 else 'was'} not fixed by its sweep (the motor current "
                    "does not show the backlash), and the model keeps 0 deg in its place; identify knob "
                    f"{k} with the tip angle measured. detect-shift can still use this model")

    def knob(self, k: int) -> KnobModel:
        """The model of knob ``k`` (1 or 2)."""
        try:
            return self.knobs[int(k)]
        except (KeyError, ValueError):
            raise ModelError(f"the model has no knob {k} (it has knobs {', '.join(map(str, self.knobs))})") from None

    def with_knob(self, k: int, knob: KnobModel) -> "Model":
        """A copy with knob ``k`` replaced."""
        knobs = dict(self.knobs)
        knobs[int(k)] = knob
        return replace(self, knobs=knobs)

    def with_offsets(self, offsets: Mapping[int, float]) -> "Model":
        """A copy whose knobs carry the given absolute offsets (others unchanged)."""
        knobs = dict(self.knobs)
        for k, o in offsets.items():
            knobs[int(k)] = self.knob(k).with_offset(o)
        return replace(self, knobs=knobs)

    def without_shift(self) -> "Model":
        """The straight-shaft model: every offset set to 0 (the paper's Compensation-Only)."""
        return self.with_offsets({k: 0.0 for k in self.knobs})

    def rotated(self, delta_deg: float) -> "Model":
        """Both knobs' offsets after a bulk body rotation by ``delta_deg`` (see :func:`rotate_offsets`)."""
        o1 = self.knobs[1].offset if 1 in self.knobs else 0.0
        o2 = self.knobs[2].offset if 2 in self.knobs else 0.0
        n1, n2 = rotate_offsets(o1, o2, delta_deg)
        offs = {}
        if 1 in self.knobs:
            offs[1] = n1
        if 2 in self.knobs:
            offs[2] = n2
        return self.with_offsets(offs)

    def predict(self, run: Run) -> Run:
        """The run with ``y<k>`` replaced by what the model and its effects predict for its
        commands (a measured ``y<k>`` kept as ``y<k>_measured``): what ``hyst predict`` writes.
        The same as :func:`predict`.
        """
        return predict(self, run)

    def compensate(self, reference: Run, ignore_shift: bool = False) -> "Compensation":
        """Knob commands that make the model and its effects follow ``reference``'s ``r<k>``:
        what ``hyst compensate`` writes, with its warnings.

        Without effects this is the exact inverse of docs/design.md section 3; with the effects
        ``hyst diagnose`` added to the model, :func:`hystcli.core.effects.inverse` undoes them
        stage by stage as well (the same call: no effects is the chain with no stage). The
        commands are not checked against a motor's limits: :func:`hystcli.compensation.compensate`
        does that.

        Parameters
        ----------
        reference : Run
            Desired tip angles ``r1`` and/or ``r2`` with time ``t``.
        ignore_shift : bool
            Use offset 0 for every knob (Compensation-Only) instead of the offset in effect
            (Compensation+Shift; which offset is docs/design.md section 6's rule, :meth:`offsets_for`).

        Returns
        -------
        Compensation
            Its ``run`` is the file.

        Notes
        -----
        The output's ``offset<k>`` is the shift in effect for the reference even when
        ``ignore_shift`` leaves it out of the commands (then ``shift_ignored: true`` says so): a
        run played from these commands is then predicted, evaluated and diagnosed with the
        shaft's shift, which the tip undergoes whatever the controller assumed. (docs/design.md
        section 6 calls ``offset<k>`` "the shift in effect for this run, as detected" and also
        "the offsets compensate used"; for Compensation-Only the two differ, and the first is
        what predictions need.)
        """
        from .effects import chain  # numba loads on the first compensation, not with the model

        knobs = knobs_of(self, reference, "r", "desired tip angle")
        in_effect = {k: v for k, v in self.offsets_for(reference.meta).items() if k in knobs}
        offsets = {k: 0.0 for k in knobs} if ignore_shift else in_effect
        new_cols: dict[str, np.ndarray] = {}
        inv = chain.inverse(self, reference, offsets=offsets, knobs=knobs)
        warnings: list[str] = list(inv.warnings)
        for k in knobs:
            q = inv.q[k]
            new_cols[f"q{k}"] = q
            ident = self.identification.get(k)
            if ident is not None:
                u = q - offsets[k]
                lo, hi = float(np.min(u)), float(np.max(u))
                if lo < ident.q_min - 1e-9 or hi > ident.q_max + 1e-9:
                    warnings.append(
                        f"knob {k}: commands reach {lo:.1f}..{hi:.1f} deg (relative to the offset), outside "
                        f"the identified range {ident.q_min:.1f}..{ident.q_max:.1f} deg: the model is extrapolated")
        controller = "comp" if ignore_shift or all(o == 0.0 for o in offsets.values()) else "comp+shift"
        cols = {"t": reference.t}
        for col, values in reference.columns.items():
            if col != "t" and not (col.startswith("q") and col[1:] in ("1", "2")):
                cols[col] = values
        cols.update(new_cols)
        meta = dict(reference.meta)
        meta["controller"] = controller
        for k in knobs:
            meta[f"offset{k}"] = repr(float(in_effect[k]))
        if ignore_shift:
            meta["shift_ignored"] = "true"
        else:
            meta.pop("shift_ignored", None)
        return Compensation(Run(cols, meta, reference.source), offsets, tuple(warnings))

    def offsets_for(self, meta: Mapping[str, str]) -> dict[int, float]:
        """Which offset each knob uses for a run with metadata ``meta`` (docs/design.md section 6).

        The run's ``offsetK`` when present, else the shift the model's geometry gives for the
        run's ``shape``, else the model's own offset.
        """
        result: dict[int, float] = {}
        shape_offsets = None
        if self.geometry is not None and meta.get("shape") not in (None, ""):
            shape_offsets = self.geometry.offsets(Shape.parse(meta["shape"]))
        for k, knob in self.knobs.items():
            key = f"offset{k}"
            if key in meta and str(meta[key]).strip() != "":
                try:
                    result[k] = float(meta[key])
                except ValueError:
                    raise ModelError(f"run metadata {key}: {meta[key]!r} is not a number") from None
                if not math.isfinite(result[k]):
                    raise ModelError(f"run metadata {key} must be finite")
            elif shape_offsets is not None:
                result[k] = shape_offsets[k - 1]
            else:
                result[k] = knob.offset
        return result


@dataclass(frozen=True)
class Compensation:
    """Result of :meth:`Model.compensate`, and of :func:`hystcli.compensation.compensate`, which
    given a motor's limits also fills ``check``, ``catch_ups`` and ``sent``.

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


def predict_tip(model: Model, run: Run) -> dict[int, np.ndarray]:
    """Tip angle the model (with its effects, if any) predicts for the run's commands ``q<k>``.

    Each knob uses the offset in effect for the run (:meth:`Model.offsets_for`) and starts from
    the run's first measured ``y<k>`` when there is one, else from 0 (docs/design.md section 3).
    """
    knobs = knobs_of(model, run, "q", "knob command")
    from .effects import chain  # numba loads on the first prediction, not with the model

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
