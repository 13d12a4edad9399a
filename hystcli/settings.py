"""Every number that steers a decision of identify, the current reading and Algorithm 1.

One frozen :class:`Settings` object, shared by the command line and the Python surface
(``hystcli.identify(run, settings=...)``, ``detect_shift(..., settings=...)``). Each field is one
of three kinds, and says which:

* a **statistical level**: the confidence level of every interval, the false-alarm rate of a
  change-point test;
* a **physical quantity** with its unit: how precisely an offset must be known before it moves
  the robot, how far a current's take-up may lie from the tip's edge and still be the same
  tendon;
* a **parameter of an estimator**: how many straight pieces a stretch of current may be read
  with, the loss that keeps outliers from pulling a fit, the low-pass the current is read through.

Nothing else in the estimation code is a tuning constant: the rest are budgets of computation
(how many samples a fit evaluates), and those do not decide anything a user sees.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace
from typing import Any

from .errors import HystError

CURRENT_SIGNS = ("auto", "signed", "magnitude")
"""How a drive reports its motor current: ``signed`` (below the no-load level while the negative
tendon pulls), ``magnitude`` (|I|: never below it), or ``auto`` (read from the sweep)."""


@dataclass(frozen=True)
class Settings:
    """The settings of hyst's estimators, with their defaults.

    Attributes
    ----------
    level : float
        *Statistical level.* Confidence level of every interval hyst reports: a parameter's
        interval holds the values whose best fit stays within the chi-square(1) quantile at this
        level of the best fit's deviance (profile likelihood). 0.95 gives the usual 3.84.
    ambiguity_level : float
        *Statistical level.* A distinct loop (another local optimum of the fit) whose deviance lies
        within the chi-square(1) quantile at this level of the best's makes every parameter where
        the two differ not fixed: both predict the record, and a parameter reported as fixed
        must not hang on which of two near-equal optima the search ended in.
    false_alarm : float
        *Statistical level.* Algorithm 1: the probability that a search along a stretch with no
        edge in it declares one (the change-point test's size, spread over every step and every
        candidate edge position by Bonferroni).
    max_offset_halfwidth : float
        *Physical quantity, deg of knob.* Algorithm 1 returns an offset only when its interval at
        :attr:`level` lies within this of it (the paper's 0.5 deg): a less certain offset moves the
        robot by more than it corrects, so the search refuses it.
    max_fixed_halfwidth : float
        *Physical quantity, deg.* A parameter counts as fixed by the record when its interval is
        closed and the tip it predicts moves by less than this across the interval (knob-angle
        parameters directly; the heights in tip degrees; omega over half the swept range): a
        record that bounds a parameter only more loosely leaves it not fixed, with its interval.
    max_edge_gap : float
        *Physical quantity, deg of knob.* How far the motor current's take-up may lie from the tip
        model's dead-zone edge and still be read as the same tendon event (a tendon takes up load
        a little before the tip moves, or after, by the bending section's friction and the
        sheath's compliance). Farther apart, Algorithm 1 refuses an offset from that side: the
        current's kink there is something else.
    contact_factor : float
        *Physical quantity, a ratio of slopes.* A current slope at least this many times the
        tendon's loaded slope is a contact (the paper's eps_upper): the search reverses.
    max_pieces : int
        *Estimator parameter.* Most straight pieces a monotone stretch of current is read with
        (held load, unloading, dead zone, take-up, a stiffening or a wall); the number used is
        chosen by BIC below it.
    loss : str
        *Estimator parameter.* The robust loss of every least-squares fit of the current
        (``scipy.optimize.least_squares``): spikes and logging outliers do not pull the fit.
    filter_hz : float or None
        *Estimator parameter.* Cut-off (Hz) of the paper's 3rd-order Butterworth low-pass the
        current is read through (zero phase offline); None reads it as recorded.
    current_sign : str
        *Estimator parameter.* ``"auto"`` (read from the sweep), ``"signed"`` or ``"magnitude"``
        (:data:`CURRENT_SIGNS`).
    """

    level: float = 0.95
    ambiguity_level: float = 0.999
    false_alarm: float = 1e-3
    max_offset_halfwidth: float = 0.5
    max_fixed_halfwidth: float = 1.0
    max_edge_gap: float = 2.0
    contact_factor: float = 4.0
    max_pieces: int = 5
    loss: str = "soft_l1"
    filter_hz: float | None = 20.0
    current_sign: str = "auto"

    def __post_init__(self) -> None:
        if not 0.5 <= self.level < 1.0:
            raise HystError(f"level must be in [0.5, 1), got {self.level}")
        if not self.level <= self.ambiguity_level < 1.0:
            raise HystError(f"ambiguity_level must be in [level, 1), got {self.ambiguity_level}")
        if not 0.0 < self.false_alarm < 0.5:
            raise HystError(f"false_alarm must be in (0, 0.5), got {self.false_alarm}")
        for name in ("max_offset_halfwidth", "max_fixed_halfwidth", "max_edge_gap", "contact_factor"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise HystError(f"{name} must be a positive number, got {v}")
        if self.contact_factor <= 1.0:
            raise HystError(f"contact_factor must exceed 1 (a contact is steeper than the tendon), "
                            f"got {self.contact_factor}")
        if not (isinstance(self.max_pieces, int) and 2 <= self.max_pieces <= 8):
            raise HystError(f"max_pieces must be a whole number in 2..8, got {self.max_pieces}")
        if self.loss not in ("linear", "soft_l1", "huber", "cauchy", "arctan"):
            raise HystError(f"loss must be one of linear, soft_l1, huber, cauchy, arctan; got {self.loss!r}")
        if self.filter_hz is not None and not (math.isfinite(self.filter_hz) and self.filter_hz > 0):
            raise HystError(f"filter_hz must be a positive number or None, got {self.filter_hz}")
        if self.current_sign not in CURRENT_SIGNS:
            raise HystError(f"current_sign must be one of {', '.join(CURRENT_SIGNS)}; got {self.current_sign!r}")

    @property
    def chi2(self) -> float:
        """The chi-square(1) quantile at :attr:`level`: the deviance rise that bounds an interval."""
        from scipy.stats import chi2

        return float(chi2.ppf(self.level, 1))

    @property
    def chi2_ambiguity(self) -> float:
        """The chi-square(1) quantile at :attr:`ambiguity_level`."""
        from scipy.stats import chi2

        return float(chi2.ppf(self.ambiguity_level, 1))

    def get_params(self) -> dict[str, Any]:
        """The settings as a plain dict (scikit-learn's ``get_params``)."""
        return asdict(self)

    def set_params(self, **changes: Any) -> "Settings":
        """A copy with ``changes`` applied (validated); unknown names are an error."""
        known = {f.name for f in fields(self)}
        bad = sorted(set(changes) - known)
        if bad:
            raise HystError(f"unknown setting(s) {', '.join(bad)}; known: {', '.join(sorted(known))}")
        return replace(self, **changes)


DEFAULT = Settings()
"""The defaults every command and function uses unless told otherwise."""
