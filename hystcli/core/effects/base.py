"""The effect unit: what every effect of docs/design.md section 8 owns, and the object that carries its
parameter values.

An effect type (one subclass of :class:`EffectType` per module of this package) owns

* its **forms** (:class:`Form`): the family of ways the same physics can show on a catheter
  (a lag on the input side or on the output side, a coupling that shifts the input or moves the
  dead zone, ...). Each form has its own stage in the tip chain, parameters, null setting,
  physical domain, fitting bounds and search grid. The first form is the default; a model file
  entry without a ``form`` is that one (version 1 files stay valid).
* its **stages**: ``condition`` (edit the knob's parameters for the run's shape or load),
  ``forward``/``inverse`` of the signal stages (``input``, ``output``, ``contact``, ``sensor``),
  ``edges`` (dead-zone edges that move sample by sample). Each signal stage takes an explicit
  state (:meth:`EffectType.new_state`), so a run processed in pieces, down to one sample at a
  time, gives the numbers of one batch call: the path a streaming compensator takes.
* how diagnosis **searches** it: the grid of each form (:meth:`Form.grid`), the parameters that
  move the tip, their scales and bounds, which runs it can act on (:meth:`EffectType.acts_on`), and
  which physical regressors its residual follows (:attr:`EffectType.regressors`, for the
  form-agnostic "which" stage of the diagnosis). Two optional hooks let the search skip work
  without changing a number: where a stage is the identity (:meth:`EffectType.identity_range`)
  and what it does to each knob alone (:meth:`EffectType.knob_key`).

The chain that runs the stages in order, forward and inverse, is :mod:`hystcli.core.effects.chain`;
the registry that lists the effect types is :mod:`hystcli.core.effects.registry`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, Mapping

import numpy as np

from ...errors import ModelError
from ..params import EffectSpec

STAGES = ("condition", "input", "edges", "output", "contact", "sensor")
"""The stages of one knob's tip chain, in forward order (the hysteresis sits between ``edges``
and ``output``)."""

_INF = math.inf


@dataclass(frozen=True)
class Form:
    """One form of an effect family: where it acts and what it needs.

    Attributes
    ----------
    name : str
        The form's name (``input``, ``output-magnitude``, ...).
    stage : str
        One of :data:`STAGES`.
    rank : int
        Order within the stage (lower first), fixed so the chain is the same whatever order a
        model lists its effects in.
    params, units : tuple of str
    switch : str
        The parameter whose ``null`` value turns the effect off (the stage is then skipped, so the
        output is the base model's bit for bit).
    null : float
    typical : mapping
        A typical switched-on value per parameter: the default, and an optimiser's step scale.
    bounds : mapping
        The range diagnosis searches, per parameter.
    domain : mapping
        The physically valid range (inclusive); outside it is an error.
    axes : mapping
        The search grid per fitted parameter (parameters not listed keep their typical value).
    summary : str
        The physics of this form in one line.
    fit : tuple of str
        Parameters that move the tip (default: all; contact's stiffness moves only the current).
    """

    name: str
    stage: str
    rank: int
    params: tuple[str, ...]
    units: tuple[str, ...]
    switch: str
    null: float
    typical: Mapping[str, float]
    bounds: Mapping[str, tuple[float, float]]
    domain: Mapping[str, tuple[float, float]]
    axes: Mapping[str, Any]
    summary: str
    fit: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        for name in ("typical", "bounds", "domain"):
            object.__setattr__(self, name, MappingProxyType(dict(getattr(self, name))))
        object.__setattr__(self, "axes", MappingProxyType({k: np.asarray(v, dtype=float)
                                                          for k, v in self.axes.items()}))
        if not self.fit:
            object.__setattr__(self, "fit", tuple(self.params))
        if self.stage not in STAGES:  # pragma: no cover - a programming error in a plug-in
            raise ValueError(f"form {self.name}: unknown stage {self.stage!r}")

    def null_params(self) -> dict[str, float]:
        """A full parameter set that switches the effect off."""
        p = dict(self.typical)
        p[self.switch] = self.null
        return p

    def grid(self) -> list[dict[str, float]]:
        """Every point of the search grid (the product of :attr:`axes`), typical values elsewhere."""
        names = list(self.axes)
        mesh = np.meshgrid(*[self.axes[n] for n in names], indexing="ij")
        base = dict(self.typical)
        return [{**base, **{n: float(m.flat[i]) for n, m in zip(names, mesh)}} for i in range(mesh[0].size)]

    def scale(self, p: str) -> float:
        """Step scale of a parameter for an optimiser: its typical value, or a tenth of its
        fitting range when the typical value is 0 (stretch's reference for a catheter)."""
        if self.typical[p] != 0.0:
            return max(abs(self.typical[p]), 1e-3)
        lo, hi = self.bounds[p]
        return (hi - lo) / 10.0

    def null_distance(self, params: Mapping[str, float]) -> float:
        """How far ``params`` are from switching the effect off (0: off), in typical units."""
        v = params[self.switch]
        scale = max(abs(self.typical[self.switch]), 1e-9)
        if math.isinf(self.null):
            return 0.0 if math.isinf(v) else scale / max(abs(v), 1e-12)
        return abs(v - self.null) / scale


@dataclass(frozen=True)
class Signals:
    """What a stage may read besides the signal it transforms (one knob of one run).

    Attributes
    ----------
    k : int
        The knob (1 or 2).
    t : numpy.ndarray or None
        Sample times (s).
    other : numpy.ndarray or None
        The other knob's command (deg; forward), or the estimate of it the inverse iterates on;
        None when the run has one knob.
    other_offset : float
        The other knob's offset in the run (deg): where its tendons are both slack.
    y0 : float
        The reported tip before the first sample (deg).
    source : str
        The run's name, for messages.
    other_tip : numpy.ndarray or None
        The other section's bend as the model sees it: its knob's base hysteresis (with its
        offset) run on ``other`` (deg). Read by the couplings driven by the bend's size; None when
        nothing reads it or the model has no such knob.
    """

    k: int
    t: np.ndarray | None
    other: np.ndarray | None = None
    other_offset: float = 0.0
    y0: float = 0.0
    source: str = "run"
    other_tip: np.ndarray | None = None

    def need_t(self, name: str) -> np.ndarray:
        if self.t is None:
            from ...errors import DataError

            raise DataError(f"effect {name} needs the time column t")
        return self.t


class EffectType:
    """The interface of one effect family (subclass one per module; register it in the registry).

    Subclasses set :attr:`name`, :attr:`summary`, :attr:`driver`, :attr:`regressors` and
    :attr:`forms`, and implement the stage methods of the stages their forms use.
    """

    name: str = ""
    summary: str = ""
    driver: str = ""
    """What drives the effect: ``shape``, ``condition``, ``other knob``, ``speed``, ``time``, ``tip``."""
    regressors: tuple[str, ...] = ()
    """The physical regressors (:data:`hystcli.diagnosis.attribution.REGRESSORS`) its residual follows."""
    forms: tuple[Form, ...] = ()

    # -- the default form, for code that knows one form per effect ------------------------------
    @property
    def form(self) -> Form:
        return self.forms[0]

    def get_form(self, name: str | None) -> Form:
        """The form called ``name`` (None or "": the default). Raises :class:`ModelError`."""
        if not name:
            return self.forms[0]
        for f in self.forms:
            if f.name == name:
                return f
        raise ModelError(f"effect {self.name}: unknown form {name!r} "
                         f"(forms: {', '.join(f.name for f in self.forms)})")

    @property
    def stage(self) -> str:
        return self.form.stage

    @property
    def params(self) -> tuple[str, ...]:
        return self.form.params

    @property
    def units(self) -> tuple[str, ...]:
        return self.form.units

    @property
    def switch(self) -> str:
        return self.form.switch

    @property
    def null(self) -> float:
        return self.form.null

    @property
    def typical(self) -> Mapping[str, float]:
        return self.form.typical

    @property
    def bounds(self) -> Mapping[str, tuple[float, float]]:
        return self.form.bounds

    @property
    def domain(self) -> Mapping[str, tuple[float, float]]:
        return self.form.domain

    @property
    def scale(self) -> dict[str, float]:
        """Typical magnitude of each parameter of the default form."""
        return {p: abs(v) for p, v in self.typical.items()}

    def null_params(self) -> dict[str, float]:
        return self.form.null_params()

    def __repr__(self) -> str:
        return f"<effect type {self.name}: {', '.join(f.name for f in self.forms)}>"

    # -- stages (override what the forms use) ---------------------------------------------------
    def condition(self, eff: "Effect", p: dict[str, float], cond_deg: float, bend_deg: float = 0.0) -> bool:
        """Edit the knob parameters ``p`` in place for the run's condition (deg of curvature, or
        the run's stated ``condition``); True when something changed. ``bend_deg`` is the bend
        projected on this knob's plane (:meth:`hystcli.core.params.Shape.projected`; 0 without a shape
        or a knob), for forms that depend on which side the shaft bends to."""
        raise NotImplementedError

    def forward(self, eff: "Effect", z: np.ndarray, sig: Signals, state: Any) -> np.ndarray:
        """The signal after this stage (input, output, contact or sensor stage)."""
        raise NotImplementedError

    def inverse(self, eff: "Effect", z: np.ndarray, sig: Signals, state: Any,
                warnings: list[str], options: Mapping[str, float]) -> np.ndarray:
        """The signal before this stage that makes :meth:`forward` give ``z``."""
        raise NotImplementedError

    def edges(self, eff: "Effect", n: int, sig: Signals) -> tuple[np.ndarray, np.ndarray] | None:
        """Per-sample moves ``(dp, dn)`` of the dead-zone edges d_pos, d_neg (edges stage)."""
        raise NotImplementedError

    def widening(self, eff: "Effect") -> float:
        """Growth of both backlash widths with knob speed (s; edges stage): the plateau ends
        ``dhat_pos``/``dhat_neg`` move apart from ``d_pos``/``d_neg`` by ``widening * |v|``, v the
        knob-speed estimate of :data:`hystcli.core.effects.kernels.SPEED_TAU` (0: none)."""
        return 0.0

    def delay_side(self, form: str, params: Mapping[str, float]) -> tuple[float | None, float]:
        """Where the form puts a delay between the knob command and the tip, and how long it is:
        ``(share, trail)``, the share of it in the drive (1: before the tendons, which the motor
        current then shows too; 0: after them, the tip or the tracker) and the trail in seconds
        at constant speed. ``(None, 0.0)``: the form makes no such claim (:mod:`hystcli.diagnosis.drive`)."""
        return None, 0.0

    def at_rest(self, eff: "Effect", y: float, sig: Signals) -> float:
        """The input of an output stage that holds its output at ``y`` at rest (the hysteresis
        state behind a reading); the identity unless the stage bends the static map."""
        return y

    def knob_key(self, eff: "Effect", k: int) -> Any:
        """A hashable key of what this stage does on knob ``k`` alone: two effects of this type
        with equal keys predict knob ``k`` of any run alike, given the same other effects (the
        diagnosis' search computes such a knob once, :func:`hystcli.diagnosis.search.table`); None (the
        default): no such promise."""
        return None

    def identity_range(self, eff: "Effect", k: int) -> tuple[float, float] | None:
        """The closed interval of its input on which this output stage on knob ``k`` is the
        identity, its :meth:`at_rest` too; None where there is none (the default). A run whose
        input to the stage stays inside it is predicted exactly as without the effect, so the
        diagnosis' search takes the base SSE there without running the chain
        (:func:`hystcli.diagnosis.search.table`)."""
        return None

    def new_state(self, eff: "Effect") -> Any:
        """A fresh state of this effect's forward stage (None: it carries none)."""
        return None

    def new_inverse_state(self, eff: "Effect") -> Any:
        """A fresh state of this effect's inverse stage (None: it carries none)."""
        return None

    def cross_knob(self, eff: "Effect") -> bool:
        """Whether the stage reads the other knob (its inverse then iterates over both knobs)."""
        return False

    def reads_bend(self, eff: "Effect") -> bool:
        """Whether the stage reads the other section's bend (:attr:`Signals.other_tip`), which the
        chain then computes from the other knob's base model."""
        return False

    def acts_on(self, form: Form, curvature: float, condition: float | None, two_knobs: bool) -> bool:
        """Whether the form can change the prediction of a run with this total curvature (deg),
        stated condition and number of knobs: when not, diagnosis reuses the base prediction."""
        return True

    # -- one sample at a time (the streaming compensator, hystcli/stream/) ----------------------
    def stepper(self, eff: "Effect", k: int, options: Mapping[str, float], warnings: list[str]) -> Any:
        """A one-sample inverse of this signal stage, or None when it has none.

        The object has ``step(z, t, other) -> float`` (the signal before the stage that makes it
        give ``z`` at time ``t``; ``other`` is the other knob's command as the stage reads it, or
        None), ``reset()``, and ``save()``/``load(state)`` (a coupling's per-sample fixed point
        tries a sample several times). Stepping a whole run through it gives :meth:`inverse`'s
        numbers. ``warnings`` collects what the batch inverse would warn about.
        """
        return None

    def preview(self, eff: "Effect") -> float:
        """How far ahead (s) of the sample it returns this stage's inverse reads its target (0: a
        causal inverse; ``latency`` needs the reference ``delay`` seconds ahead)."""
        return 0.0


@dataclass(frozen=True)
class Effect:
    """An effect type in one of its forms with parameter values (build with ``make_effect``)."""

    type: EffectType
    params: Mapping[str, float]
    form: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "params", MappingProxyType(dict(self.params)))
        f = self.type.get_form(self.form)
        object.__setattr__(self, "form", f.name)
        # looked up on every prediction the diagnosis makes: resolve it once
        object.__setattr__(self, "_form", f)
        object.__setattr__(self, "_key", (STAGES.index(f.stage), f.rank, self.type.name))

    @property
    def name(self) -> str:
        return self.type.name

    @property
    def spec_form(self) -> Form:
        return self._form

    @property
    def order(self) -> tuple:
        """Where the effect sits in the chain: (stage, rank, name)."""
        return self._key

    @property
    def is_default_form(self) -> bool:
        return self.form == self.type.forms[0].name

    def __getitem__(self, param: str) -> float:
        return self.params[param]

    @property
    def is_null(self) -> bool:
        """True when the effect is switched off (its stage is skipped)."""
        f = self._form
        v = self.params[f.switch]
        if math.isinf(f.null):
            return math.isinf(v)
        return v == f.null

    def spec(self) -> EffectSpec:
        """The :class:`EffectSpec` to store in a model file (the form only when not the default)."""
        return EffectSpec(self.name, dict(self.params), "" if self.is_default_form else self.form)

    def label(self) -> str:
        """``name`` or ``name[form]``: the physics, with the form when it is not the default."""
        return self.name if self.is_default_form else f"{self.name}[{self.form}]"

    def __str__(self) -> str:
        body = [] if self.is_default_form else [f"form={self.form}"]
        body += [f"{p}={v:g}" for p, v in self.params.items()]
        return f"{self.name}(" + ",".join(body) + ")"


__all__ = ["Effect", "EffectType", "Form", "STAGES", "Signals"]
