"""What Algorithm 1 returns for one knob: the offset with its interval, and the evidence for it."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

__all__ = ["Evidence", "ShiftResult"]


@dataclass(frozen=True)
class Evidence:
    """Why an offset was believed: the change point it came from.

    Attributes
    ----------
    statistic : float
        The change point's likelihood-ratio statistic (deviance drop over the readings'
        correlation time) when the edge was declared.
    threshold : float
        The statistic's threshold at the settings' false-alarm rate.
    edge_lo, edge_hi : float
        The edge's profile interval (deg of knob).
    level : float
        Current at the edge (mA).
    expected_level : float or None
        Where the identification sweep's current took that tendon up (mA).
    slope_before, slope_after : float
        dC/dq either side of the edge, in load coordinates (mA/deg).
    n_before, n_after : int
        Readings either side.
    noise : float
        Noise of one reading about the fitted broken line (mA).
    """

    statistic: float
    threshold: float
    edge_lo: float
    edge_hi: float
    level: float
    expected_level: float | None
    slope_before: float
    slope_after: float
    n_before: int
    n_after: int
    noise: float

    def to_dict(self) -> dict:
        return {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                for k, v in self.__dict__.items()}


@dataclass(frozen=True)
class ShiftResult:
    """What Algorithm 1 found for one knob.

    Attributes
    ----------
    knob : int
    offset : float
        The shift :math:`q_{init}` (deg): the edge found minus the same edge on the straight shaft.
    offset_lo, offset_hi : float
        The offset's interval at the settings' level (the edge's and the reference's combined).
    d_pos, d_neg : float
        The shifted dead-zone edges :math:`\\tilde D = D + offset` (deg).
    edge : str
        Which edge was found: ``"pos"`` or ``"neg"``.
    edge_found_at : float
        Knob angle of the edge (deg).
    direction : int
        Direction of motion when it was found.
    reference : str
        What the offset is measured from: ``"current"`` (where the identification sweep's current
        took that tendon up) or ``"model"`` (the model's edge, for a model without a current).
    start, travel : float
        Where the search began (the knob is returned there) and its knob travel (deg).
    steps : int
    contacts : tuple of float
        Knob angles where a contact made the search reverse.
    start_outside : bool
        The search began with the tendon ahead taut and turned to cross the dead zone.
    returned : bool
        The knob was returned to ``start``.
    step : float
        The unit step (deg).
    evidence : Evidence
    trace : tuple of (q, current, slope)
        Every step: knob angle, current, slope of the last readings (NaN before three).
    """

    knob: int
    offset: float
    offset_lo: float
    offset_hi: float
    d_pos: float
    d_neg: float
    edge: str
    edge_found_at: float
    direction: int
    reference: str
    start: float
    travel: float
    steps: int
    contacts: tuple[float, ...] = ()
    start_outside: bool = False
    returned: bool = True
    step: float = math.nan
    evidence: Evidence | None = None
    trace: tuple[tuple[float, float, float], ...] = field(default=(), repr=False)

    @property
    def halfwidth(self) -> float:
        """The larger distance from the offset to an end of its interval (deg)."""
        return max(self.offset - self.offset_lo, self.offset_hi - self.offset)

    def summary(self) -> str:
        return (f"knob {self.knob}: offset {self.offset:+.2f} deg [{self.offset_lo:+.2f}, {self.offset_hi:+.2f}] "
                f"from the {self.edge} edge at {self.edge_found_at:.2f} deg ({self.steps} steps, "
                f"{self.travel:.1f} deg of travel)")

    def plot(self, model=None, background=None):  # noqa: ANN001, ANN201 - matplotlib Figure, loaded when drawn
        """The search's current against knob angle with the edge it found (the paper's Fig. 5b).

        Parameters
        ----------
        model : Model, optional
            The straight-shaft model, whose edges are drawn dotted.
        background : tuple of numpy.ndarray, optional
            ``(q, current)`` of a replay's whole record, drawn faintly behind the steps.

        Returns
        -------
        matplotlib.figure.Figure
            What ``hyst detect-shift --plot`` saves for this knob.
        """
        from .figure import shift_figure

        return shift_figure([self], model, None if background is None else {self.knob: background})

    def to_dict(self, trace: bool = False) -> dict:
        """Plain JSON-ready dict (the trace only when asked; NaN slopes as null)."""
        out = {k: getattr(self, k) for k in ("knob", "offset", "offset_lo", "offset_hi", "d_pos", "d_neg", "edge",
                                             "edge_found_at", "direction", "reference", "start", "travel", "steps",
                                             "start_outside", "returned", "step")}
        out["contacts"] = list(self.contacts)
        out["evidence"] = None if self.evidence is None else self.evidence.to_dict()
        if trace:
            out["trace"] = [[q, c, None if math.isnan(s) else s] for q, c, s in self.trace]
        return out
