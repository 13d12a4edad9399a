"""An estimate with its interval: what every fit of hyst returns for a parameter.

:class:`Estimate` is a value, its profile-likelihood interval at a stated level, and whether the
record fixes it. A parameter the record cannot fix is not an error: it is an estimate whose
interval is open on a side (``b_pos >= 5.4``) or that the fit marks as not fixed with the reason,
and whose value is one inside the interval that predicts the record as well as the best fit.
Model files store estimates in this form (:meth:`Estimate.to_dict`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping

from .errors import ModelError


def _num(v: float) -> float | None:
    return None if not math.isfinite(v) else float(v)


@dataclass(frozen=True)
class Estimate:
    """A parameter's value and interval.

    Attributes
    ----------
    value : float
        The value a model uses (the best fit's, or one inside the interval that predicts the record
        as well).
    lo, hi : float
        The interval at :attr:`level` (``-inf`` / ``inf`` where it is open).
    level : float
        Confidence level of the interval.
    fixed : bool
        Whether the record fixes the parameter (a closed interval).
    reason : str or None
        Why the record does not fix it (None when it does).
    """

    value: float
    lo: float
    hi: float
    level: float = 0.95
    fixed: bool = True
    reason: str | None = None

    def __post_init__(self) -> None:
        if not math.isfinite(self.value):
            raise ModelError(f"an estimate's value must be finite, got {self.value}")
        if math.isnan(self.lo) or math.isnan(self.hi) or self.lo > self.hi:
            raise ModelError(f"an estimate's interval must be ordered, got [{self.lo}, {self.hi}]")

    @property
    def halfwidth(self) -> float:
        """The larger distance from the value to an end of the interval (``inf`` when open)."""
        return max(self.value - self.lo, self.hi - self.value)

    @property
    def stderr(self) -> float:
        """The one-sigma uncertainty the interval implies (its half-width over the normal quantile
        of :attr:`level`); ``inf`` when the interval is open."""
        from statistics import NormalDist

        z = NormalDist().inv_cdf(0.5 + 0.5 * self.level)
        return self.halfwidth / z

    def contains(self, v: float) -> bool:
        return self.lo <= v <= self.hi

    def describe(self, name: str, unit: str = "deg", digits: int = 2) -> str:
        """One line: ``d_pos = 12.31 deg [11.95, 12.70]`` or ``b_pos >= 5.40 deg (not fixed: ...)``."""
        f = f"{{:.{digits}f}}"
        lo_open, hi_open = not math.isfinite(self.lo), not math.isfinite(self.hi)
        u = f" {unit}" if unit else ""
        if lo_open and hi_open:
            text = f"{name} = {f.format(self.value)}{u} (any value fits)"
        elif hi_open:
            text = f"{name} >= {f.format(self.lo)}{u} (used: {f.format(self.value)})"
        elif lo_open:
            text = f"{name} <= {f.format(self.hi)}{u} (used: {f.format(self.value)})"
        else:
            text = f"{name} = {f.format(self.value)}{u} [{f.format(self.lo)}, {f.format(self.hi)}]"
        if not self.fixed and self.reason:
            text += f"; not fixed: {self.reason}"
        return text

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"value": float(self.value), "lo": _num(self.lo), "hi": _num(self.hi),
                               "level": float(self.level), "fixed": bool(self.fixed)}
        if self.reason:
            out["reason"] = self.reason
        return out

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], where: str = "estimate") -> "Estimate":
        try:
            lo = -math.inf if d.get("lo") is None else float(d["lo"])
            hi = math.inf if d.get("hi") is None else float(d["hi"])
            return cls(value=float(d["value"]), lo=lo, hi=hi, level=float(d.get("level", 0.95)),
                       fixed=bool(d.get("fixed", True)), reason=d.get("reason"))
        except (KeyError, TypeError, ValueError) as exc:
            raise ModelError(f"{where}: an interval needs value, lo, hi ({exc})") from None
