"""The one place that lists the effects (docs/design.md section 8), and how effects are named in files
and on the command line.

A new effect is one module of this package with one :class:`~hystcli.core.effects.base.EffectType`
subclass, added to :data:`EFFECTS` below, and its tests.
"""
from __future__ import annotations

import math
import re
from types import MappingProxyType
from typing import Mapping, Sequence

from ...errors import ModelError
from ..params import EffectSpec
from .base import Effect, EffectType
from .contact import Contact
from .coupling import Coupling
from .creep import Creep
from .deadzone import Deadzone
from .friction import Friction
from .latency import Latency
from .rate import Rate
from .saturation import Saturation
from .stretch import Stretch

EFFECTS: Mapping[str, EffectType] = MappingProxyType({e.name: e for e in (
    Friction(), Deadzone(), Stretch(), Coupling(), Rate(), Saturation(), Creep(), Contact(), Latency(),
)})
"""Every effect by name (the physics); each holds its family of forms."""

ALIASES: Mapping[str, str] = MappingProxyType({"lag": "rate"})
"""Other names the physics goes by."""


def effect_type(name: str) -> EffectType:
    """The effect type called ``name`` (or an alias). Raises :class:`ModelError`."""
    key = str(name).strip().lower()
    etype = EFFECTS.get(ALIASES.get(key, key))
    if etype is None:
        raise ModelError(f"unknown effect {name!r} (known: {', '.join(EFFECTS)})")
    return etype


def make_effect(name: str, form: str | None = None, **params: float) -> Effect:
    """Build and validate an effect; omitted parameters take the form's typical value.

    Parameters
    ----------
    name : str
        One of :data:`EFFECTS` (or an alias: ``lag`` is ``rate``).
    form : str, optional
        One of the effect's forms (default: its first).
    **params : float
        Parameter values of that form.

    Raises
    ------
    ModelError
        Unknown effect, form or parameter, a value that is not a number, or outside its domain.
    """
    etype = effect_type(name)
    f = etype.get_form(form)
    values = dict(f.typical)
    for p, v in params.items():
        if p not in f.params:
            raise ModelError(f"effect {etype.name}: unknown parameter {p!r} "
                             f"(parameters: {', '.join(f.params)})")
        try:
            fv = float(v)
        except (TypeError, ValueError):
            raise ModelError(f"effect {etype.name}: parameter {p} must be a number, got {v!r}") from None
        inf_off = p == f.switch and math.isinf(f.null)
        if math.isnan(fv) or (math.isinf(fv) and not inf_off):
            raise ModelError(f"effect {etype.name}: parameter {p} must be finite, got {v!r}")
        lo, hi = f.domain[p]
        if not (lo <= fv <= hi) and not (inf_off and math.isinf(fv)):
            raise ModelError(f"effect {etype.name}: parameter {p} = {fv:g} is outside its valid "
                             f"range [{lo:g}, {hi:g}]")
        values[p] = fv
    return Effect(etype, values, f.name)


def as_effect(e: "Effect | EffectSpec") -> Effect:
    """An :class:`Effect` from an :class:`Effect` or a stored :class:`EffectSpec` (validated)."""
    if isinstance(e, Effect):
        return e
    if isinstance(e, EffectSpec):
        return make_effect(e.name, e.form or None, **dict(e.params))
    raise ModelError(f"not an effect: {e!r}")


def as_effects(effects: Sequence["Effect | EffectSpec"] | None) -> tuple[Effect, ...]:
    """Validated effects; each name at most once (the same physics twice is ambiguous)."""
    out = tuple(as_effect(e) for e in (effects or ()))
    seen: set[str] = set()
    for e in out:
        if e.name in seen:
            raise ModelError(f"effect {e.name} is given twice")
        seen.add(e.name)
    return out


_EFFECT_RE = re.compile(r"^\s*([A-Za-z_]+)\s*(?:[:(]\s*(.*?)\s*\)?)?\s*$")


def parse_effect(text: str) -> Effect:
    """Parse ``name``, ``name:p=v,p=v`` (command line) or ``name(p=v,p=v)`` (run metadata);
    ``form=NAME`` among the pairs picks a form.

    Raises
    ------
    ModelError
        Malformed text, unknown effect, form or parameter, bad value.
    """
    m = _EFFECT_RE.match(text or "")
    if not m:
        raise ModelError(f"bad effect {text!r}: expected NAME or NAME:param=value[,param=value]")
    name, body = m.group(1), m.group(2) or ""
    params: dict[str, str] = {}
    for item in filter(None, (s.strip() for s in body.split(","))):
        key, eq, val = item.partition("=")
        if not eq or not key.strip():
            raise ModelError(f"bad effect {text!r}: {item!r} is not param=value")
        params[key.strip()] = val.strip()
    form = params.pop("form", None)
    return make_effect(name, form, **params)


def parse_effects(text: str) -> tuple[Effect, ...]:
    """Parse a ``;``-separated list of effects (the ``effects`` metadata of a simulated run)."""
    if text is None or text.strip().lower() in ("", "none"):
        return ()
    return as_effects([parse_effect(part) for part in text.split(";") if part.strip()])


def format_effects(effects: Sequence[Effect | EffectSpec]) -> str:
    """The ``effects`` metadata value, readable back by :func:`parse_effects`."""
    return ";".join(str(as_effect(e)) for e in effects) or "none"
