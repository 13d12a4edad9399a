"""The parts of a catheter's model below the effect chain: one knob's hysteresis, the shaft.

This module owns the equations of the paper's section II (Kim & Mansi) as fixed by docs/design.md
section 3: the two envelopes, the forward clamp recursion, its exact inverse (compensation), the
shift of the model by an ``offset``, the shift a known shaft shape causes (paper eqs. 1-4) and the
update of both knobs' offsets for a bulk rotation of the catheter body. It also holds the records
a model carries beside its knobs: an effect's spec (:class:`EffectSpec`) and what identification
learnt of each knob (:class:`KnobIdentification`, with Algorithm 1's :class:`Calibration` of the
motor current). The effect chain (:mod:`hystcli.core.effects`) builds on these; the whole
catheter, :class:`hystcli.core.model.Model`, builds on both.

Symbols (paper eq. D_hats and eq. model_eqs)::

    D_pos, D_neg   dead-zone edges            -> d_pos, d_neg
    B_pos, B_neg   backlash widths            -> b_pos, b_neg
    omega          slope of the loaded lines  -> omega
    H_pos, H_neg   dead-zone heights          -> h_pos, h_neg
    Dhat_pos/neg   far edges of the dead zone -> dhat_pos, dhat_neg (derived)
    q_init         shift of the model         -> offset

The forward and inverse recursions themselves are :mod:`hystcli.core.kernel`'s (compiled with
numba, loaded on the first prediction).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import Mapping, Sequence

import numpy as np

from ..errors import ModelError
from ..estimate import Estimate

PARAM_NAMES = ("d_pos", "d_neg", "b_pos", "b_neg", "omega", "h_pos", "h_neg", "offset")
"""The parameters of one knob in file order (docs/design.md section 6)."""

PAPER_OMEGA = 1.45
"""The paper's average slope omega (section III: "We used omega as 1.45 as the average value")."""

MAX_PARAM = 1e6
"""Largest magnitude of a knob parameter (deg, or deg/deg for omega) or a geometry length (mm).
A knob turns a few turns at most (thousands of degrees); a value like 1e308 is a corrupt model
file, refused rather than overflowing the envelopes to infinity."""

MAX_SEGMENT_BEND = 360.0
"""Largest |alpha| of one shaft segment (deg): a full loop. More is not a shape but a typo."""

# Tolerance of the validity checks: parameters that come out of a least-squares fit may sit on a
# constraint to within rounding; anything beyond this is a real violation.
_TOL = 1e-9


def _check_finite(values: np.ndarray, where: str, what: str) -> None:
    # NaN would pass through the clamp recursion silently (every comparison with NaN is false, so
    # the output holds its last value): an error names the first bad sample instead
    bad = ~np.isfinite(values)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ModelError(f"{where}: {what} must be finite, sample {i} is {float(values[i])!r}")


# --------------------------------------------------------------------------------------------
# one knob
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class KnobModel:
    """Dead-zone + backlash hysteresis of one knob (paper eqs. D_hats and model_eqs).

    Parameters
    ----------
    d_pos, d_neg : float
        Dead-zone edges :math:`D_{pos}`, :math:`D_{neg}` (deg of knob).
    b_pos, b_neg : float
        Backlash widths :math:`B_{pos}`, :math:`B_{neg}` (deg of knob), >= 0.
    omega : float
        Slope :math:`\\omega` of the loaded lines (deg of tip per deg of knob), > 0.
    h_pos, h_neg : float
        Dead-zone heights :math:`H_{pos}`, :math:`H_{neg}` (deg of tip).
    offset : float
        Shift :math:`q_{init}` of the whole model along the knob axis (deg), 0 for the straight
        shaft. The shifted edges are :math:`\\tilde D = D + offset` (Algorithm 1).

    Raises
    ------
    ModelError
        When a parameter is not finite or the parameters violate a validity condition of
        docs/design.md section 3 (the message names the condition).
    """

    d_pos: float
    d_neg: float
    b_pos: float
    b_neg: float
    omega: float = PAPER_OMEGA
    h_pos: float = 0.0
    h_neg: float = 0.0
    offset: float = 0.0

    def __post_init__(self) -> None:
        for name in PARAM_NAMES:
            value = getattr(self, name)
            try:
                value = float(value)
            except (TypeError, ValueError):
                raise ModelError(f"parameter {name} must be a number, got {value!r}") from None
            if not math.isfinite(value):
                raise ModelError(f"parameter {name} must be finite, got {value}")
            if abs(value) > MAX_PARAM:
                raise ModelError(f"parameter {name} = {value:g} is beyond +-{MAX_PARAM:g} "
                                 f"(not a knob angle or slope)")
            object.__setattr__(self, name, value)
        if not self.omega > 0:
            raise ModelError(f"invalid model: omega > 0 is violated (omega = {self.omega:g})")
        if self.b_pos < 0:
            raise ModelError(f"invalid model: b_pos >= 0 is violated (b_pos = {self.b_pos:g})")
        if self.b_neg < 0:
            raise ModelError(f"invalid model: b_neg >= 0 is violated (b_neg = {self.b_neg:g})")
        if self.dhat_pos > self.d_pos + _TOL:
            raise ModelError(
                "invalid model: dhat_pos <= d_pos is violated "
                f"(dhat_pos = {self.dhat_pos:g} > d_pos = {self.d_pos:g})"
            )
        if self.d_neg > self.dhat_neg + _TOL:
            raise ModelError(
                "invalid model: d_neg <= dhat_neg is violated "
                f"(d_neg = {self.d_neg:g} > dhat_neg = {self.dhat_neg:g})"
            )
        # Both envelopes are piecewise linear with equal outer slopes, so f_up <= f_dn everywhere
        # exactly when it holds at the four breakpoints (scalar arithmetic: a model is built for
        # every condition the diagnosis tries, and numpy's per-call cost dominated it)
        us = (self.dhat_pos, self.d_pos, self.d_neg, self.dhat_neg)
        gaps = [self._gap(u) for u in us]
        worst_gap = min(gaps)
        if worst_gap < -_TOL * max(1.0, max(abs(u) for u in us)):
            worst = us[gaps.index(worst_gap)]
            raise ModelError(
                "invalid model: f_up <= f_dn everywhere is violated "
                f"(the ascending envelope passes the descending one by {-worst_gap:.3g} deg "
                f"at u = {worst:g})"
            )

    def _gap(self, u: float) -> float:
        # f_dn(u) - f_up(u) for one u, as f_dn and f_up compute it
        up = self.h_pos + self.omega * (min(u - self.dhat_pos, 0.0) + max(u - self.d_pos, 0.0))
        dn = self.h_neg + self.omega * (min(u - self.d_neg, 0.0) + max(u - self.dhat_neg, 0.0))
        return dn - up

    # -- derived parameters -------------------------------------------------------------------
    @property
    def dhat_pos(self) -> float:
        """:math:`\\hat D_{pos} = (H_{pos}-H_{neg})/\\omega + D_{neg} + B_{neg}` (paper eq. D_hats)."""
        return (self.h_pos - self.h_neg) / self.omega + self.d_neg + self.b_neg

    @property
    def dhat_neg(self) -> float:
        """:math:`\\hat D_{neg} = (H_{neg}-H_{pos})/\\omega + D_{pos} - B_{pos}` (paper eq. D_hats)."""
        return (self.h_neg - self.h_pos) / self.omega + self.d_pos - self.b_pos

    @property
    def shifted_d_pos(self) -> float:
        """:math:`\\tilde D_{pos} = D_{pos} + offset` (Algorithm 1)."""
        return self.d_pos + self.offset

    @property
    def shifted_d_neg(self) -> float:
        """:math:`\\tilde D_{neg} = D_{neg} + offset` (Algorithm 1)."""
        return self.d_neg + self.offset

    def params(self) -> dict[str, float]:
        """The eight parameters as a plain dict, in file order."""
        return {name: getattr(self, name) for name in PARAM_NAMES}

    # -- envelopes ----------------------------------------------------------------------------
    def f_up(self, u: np.ndarray | float) -> np.ndarray:
        """Ascending (loading) envelope of the unshifted model, lines L2, L3, L4."""
        u = np.asarray(u, dtype=float)
        return self.h_pos + self.omega * (np.minimum(u - self.dhat_pos, 0.0) + np.maximum(u - self.d_pos, 0.0))

    def f_dn(self, u: np.ndarray | float) -> np.ndarray:
        """Descending (unloading) envelope of the unshifted model, lines L8, L7, L6."""
        u = np.asarray(u, dtype=float)
        return self.h_neg + self.omega * (np.minimum(u - self.d_neg, 0.0) + np.maximum(u - self.dhat_neg, 0.0))

    # -- forward and inverse ------------------------------------------------------------------
    def _kernel_args(self):
        return (self.offset, self.d_pos, self.d_neg, self.dhat_pos, self.dhat_neg,
                self.omega, self.h_pos, self.h_neg)

    def forward(self, q: np.ndarray | Sequence[float], y0: float = 0.0) -> np.ndarray:
        """Tip angle the model predicts for knob commands ``q``.

        Implements the clamp recursion
        :math:`y_t = \\min(\\max(y_{t-1}, f_{up}(x_t - offset)), f_{dn}(x_t - offset))`.

        Parameters
        ----------
        q : array_like, shape (n,)
            Knob angles :math:`x_t` (deg).
        y0 : float
            The output before the first sample, :math:`y_{-1}` (deg); 0 is the straight tip.

        Returns
        -------
        numpy.ndarray, shape (n,)
            Predicted tip angle (deg).
        """
        x = np.ascontiguousarray(q, dtype=np.float64)
        if x.ndim != 1:
            raise ModelError(f"forward expects a 1-D array of knob angles, got shape {x.shape}")
        _check_finite(x, "forward", "knob angles")
        if not math.isfinite(y0):
            raise ModelError(f"forward: the initial output y0 must be finite, got {y0}")
        out = np.empty_like(x)
        from . import kernel  # numba loads on the first prediction, not on import

        kernel.forward(x, *self._kernel_args(), float(y0), out)
        return out

    def inverse(self, r: np.ndarray | Sequence[float], y0: float = 0.0,
                q0: float | None = None) -> np.ndarray:
        """Knob commands that make the model produce exactly the desired tip angles ``r``.

        When :math:`r_t` rises above the present output the command is the smallest ``x`` on the
        ascending envelope that reaches it (jumping across the dead zone and the backlash
        plateau); when it falls, the largest ``x`` on the descending envelope; when it is equal,
        the command is held. ``forward(inverse(r, y0), y0) == r`` to float precision.

        Parameters
        ----------
        r : array_like, shape (n,)
            Desired tip angles (deg).
        y0 : float
            The output before the first sample (deg).
        q0 : float, optional
            The knob angle before the first sample; only used when ``r[0] == y0`` (the command
            is then held). Default: the middle of the knob range that holds ``y0``.

        Returns
        -------
        numpy.ndarray, shape (n,)
            Knob commands (deg).
        """
        rr = np.ascontiguousarray(r, dtype=np.float64)
        if rr.ndim != 1:
            raise ModelError(f"inverse expects a 1-D array of tip angles, got shape {rr.shape}")
        _check_finite(rr, "inverse", "desired tip angles")
        if not (math.isfinite(y0) and (q0 is None or math.isfinite(q0))):
            raise ModelError(f"inverse: the initial output y0 and knob angle q0 must be finite, got {y0}, {q0}")
        if q0 is None:
            q0 = self.holding_knob_angle(y0)
        out = np.empty_like(rr)
        from . import kernel

        kernel.inverse(rr, *self._kernel_args(), float(y0), float(q0), out)
        return out

    def holding_knob_angle(self, y: float) -> float:
        """Middle of the knob interval (shifted) over which the output ``y`` is held.

        The set of ``u`` with :math:`f_{up}(u) \\le y \\le f_{dn}(u)` is an interval
        ``[a, b]``: ``a`` is the smallest ``u`` with ``f_dn(u) >= y``, ``b`` the largest with
        ``f_up(u) <= y``. Used as the command before a trajectory starts, when nothing else is
        known of the knob.
        """
        y = float(y)
        a = (self.d_neg + (y - self.h_neg) / self.omega) if y < self.h_neg else (
            self.dhat_neg + (y - self.h_neg) / self.omega if y > self.h_neg else self.d_neg)
        b = (self.dhat_pos + (y - self.h_pos) / self.omega) if y < self.h_pos else (
            self.d_pos + (y - self.h_pos) / self.omega if y > self.h_pos else self.d_pos)
        return 0.5 * (a + b) + self.offset

    # -- shift --------------------------------------------------------------------------------
    def with_offset(self, offset: float) -> "KnobModel":
        """The same knob shifted by ``offset`` (absolute, not added)."""
        return replace(self, offset=float(offset))

    def shifted(self, delta: float) -> "KnobModel":
        """The same knob with its offset moved by ``delta`` (deg)."""
        return replace(self, offset=self.offset + float(delta))


# --------------------------------------------------------------------------------------------
# shaft shape -> shift (paper eqs. 1-4)
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Segment:
    """One bent segment of the proximal shaft, :math:`S_i = (\\alpha_i, \\theta_i)` in degrees."""

    alpha: float
    theta: float = 0.0


@dataclass(frozen=True)
class Shape:
    """Shape of the proximal shaft: a sequence of bent segments (empty for a straight shaft)."""

    segments: tuple[Segment, ...] = ()

    @classmethod
    def parse(cls, text: str | None) -> "Shape":
        """Parse the ``shape`` metadata value (``straight`` or ``alpha=90,theta=0;alpha=45,...``).

        Raises
        ------
        ModelError
            On a malformed segment (names it).
        """
        if text is None:
            return cls()
        text = text.strip()
        if text == "" or text.lower() in ("straight", "none"):
            return cls()
        segs = []
        for part in text.split(";"):
            part = part.strip()
            if not part:
                continue
            values: dict[str, float] = {}
            for item in part.split(","):
                if "=" not in item:
                    raise ModelError(f"bad shape segment {part!r}: expected alpha=DEG[,theta=DEG]")
                key, _, val = item.partition("=")
                key = key.strip().lower()
                if key not in ("alpha", "theta"):
                    raise ModelError(f"bad shape segment {part!r}: unknown key {key!r}")
                if key in values:
                    # 'alpha=90,alpha=45' is a typo for two segments, not the last value
                    raise ModelError(f"bad shape segment {part!r}: {key} is given twice "
                                     "(segments are separated by ';')")
                try:
                    values[key] = float(val)
                except ValueError:
                    raise ModelError(f"bad shape segment {part!r}: {val.strip()!r} is not a number") from None
                if not math.isfinite(values[key]):
                    raise ModelError(f"bad shape segment {part!r}: {key} must be finite")
                if key == "alpha" and abs(values[key]) > MAX_SEGMENT_BEND:
                    raise ModelError(f"bad shape segment {part!r}: |alpha| <= {MAX_SEGMENT_BEND:g} deg "
                                     f"(one full loop) is violated")
                if key == "theta" and abs(values[key]) > MAX_PARAM:
                    raise ModelError(f"bad shape segment {part!r}: theta beyond +-{MAX_PARAM:g} deg")
            if "alpha" not in values:
                raise ModelError(f"bad shape segment {part!r}: alpha is missing")
            segs.append(Segment(values["alpha"], values.get("theta", 0.0)))
        return cls(tuple(segs))

    def __str__(self) -> str:
        if not self.segments:
            return "straight"
        return ";".join(f"alpha={s.alpha:g},theta={s.theta:g}" for s in self.segments)

    @property
    def total_curvature(self) -> float:
        """:math:`\\sum_i |\\alpha_i|` in degrees (drives the ``friction`` effect)."""
        return float(sum(abs(s.alpha) for s in self.segments))

    def projected(self, k: int) -> float:
        """The bend projected on knob ``k``'s bending plane, deg (signed): :math:`\\sum_i \\alpha_i
        \\cos\\theta_i` for knob 1, :math:`\\sum_i \\alpha_i \\sin\\theta_i` for knob 2, the sums
        of paper eqs. 3 and 4 (drives the ``deadzone`` forms that follow the bend's side)."""
        trig = math.cos if k == 1 else math.sin
        return float(sum(s.alpha * trig(math.radians(s.theta)) for s in self.segments))

    def rotated(self, delta_deg: float) -> "Shape":
        """The shape seen after a bulk rotation of the catheter body by ``delta_deg``."""
        return Shape(tuple(Segment(s.alpha, s.theta - delta_deg) for s in self.segments))


@dataclass(frozen=True)
class Geometry:
    """Tendon geometry of a catheter (paper section II-B).

    Parameters
    ----------
    beta_catheter_mm : float
        :math:`\\beta_{catheter}`, distance from the backbone centre to each tendon (mm).
    beta_knob_mm : float
        :math:`\\beta_{knob}`, radius of the knob pulley (mm).
    """

    beta_catheter_mm: float
    beta_knob_mm: float

    def __post_init__(self) -> None:
        for name in ("beta_catheter_mm", "beta_knob_mm"):
            v = getattr(self, name)
            try:
                v = float(v)
            except (TypeError, ValueError):
                raise ModelError(f"geometry {name} must be a number, got {v!r}") from None
            if not (math.isfinite(v) and v > 0):
                raise ModelError(f"invalid geometry: {name} > 0 is violated ({name} = {v:g})")
            if v > MAX_PARAM:
                raise ModelError(f"invalid geometry: {name} <= {MAX_PARAM:g} mm is violated ({name} = {v:g})")
            object.__setattr__(self, name, v)

    def offsets(self, shape: Shape) -> tuple[float, float]:
        """Shift of knob 1 and knob 2 caused by ``shape`` (paper eqs. 3 and 4).

        :math:`offset_1 = \\frac{180}{\\pi}\\,\\beta_{catheter}\\sum_i \\alpha_i\\cos\\theta_i/\\beta_{knob}`,
        :math:`offset_2` likewise with :math:`\\sin\\theta_i`; :math:`\\alpha_i` in radians.
        """
        s1 = sum(math.radians(s.alpha) * math.cos(math.radians(s.theta)) for s in shape.segments)
        s2 = sum(math.radians(s.alpha) * math.sin(math.radians(s.theta)) for s in shape.segments)
        k = math.degrees(1.0) * self.beta_catheter_mm / self.beta_knob_mm
        return k * s1, k * s2


def rotate_offsets(offset1: float, offset2: float, delta_deg: float) -> tuple[float, float]:
    """Offsets after a bulk rotation of the catheter body by ``delta_deg``.

    Rotating the body by :math:`\\delta` turns every segment's :math:`\\theta_i` into
    :math:`\\theta_i - \\delta` in the handle's frame, which rotates the vector
    :math:`(offset_1, offset_2)` of eqs. 3-4 by :math:`-\\delta` (docs/design.md section 3; the paper
    leaves this case out).
    """
    c, s = math.cos(math.radians(delta_deg)), math.sin(math.radians(delta_deg))
    return c * offset1 + s * offset2, -s * offset1 + c * offset2


# --------------------------------------------------------------------------------------------
# what a model carries beside its knobs: effects, identification
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class EffectSpec:
    """An unmodelled effect attached to a model (docs/design.md section 8): its name, parameters and
    form ("" for the effect's default form, which is what a version 1 entry without one means)."""

    name: str
    params: Mapping[str, float] = field(default_factory=dict)
    form: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "params", MappingProxyType(dict(self.params)))


@dataclass(frozen=True)
class Calibration:
    """Algorithm 1's calibration record of one knob: how the straight sweep's motor current reads.

    ``detect-shift`` measures a shift from these (with nothing else given); a sweep without a
    current leaves them empty (``current_sign`` None). In a model file they stand beside the rest
    of the knob's identification, under the same names.

    Attributes
    ----------
    current_sign : str or None
        How the drive reports its current: ``"signed"`` or ``"magnitude"`` (None: no current).
    current_edges : mapping of str to Estimate
        ``"pos"``/``"neg"``: where the sweep's current takes each tendon up from slack (deg), with
        its interval: what Algorithm 1 measures an offset from.
    no_load_rising, no_load_falling : float or None
        The current in the dead zone while the knob turns positive / negative (the motor's own
        friction moves it with the direction).
    slope_dead_zone : float
        The current's slope in the dead zone, in load coordinates (current unit per deg).
    slope_loaded_pos, slope_loaded_neg : float or None
        Its slope just past each take-up, in load coordinates.
    edge_level_pos, edge_level_neg : float or None
        The current where each tendon is taken up, moving toward it (a bend moves the take-up along
        the knob, not this level): how Algorithm 1 tells a take-up from a held load.
    current_noise : float or None
        Per-sample noise of the conditioned current.
    current_min, current_max : float or None
        The sweep's lowest and highest current: the most it loaded each tendon (Algorithm 1 loads
        none further).
    cogging_period, cogging_sin, cogging_cos : float or None
        The motor's cogging ripple (period, deg; amplitudes), None where the sweep showed none.
    """

    current_sign: str | None = None
    current_edges: Mapping[str, "Estimate"] = field(default_factory=dict)
    no_load_rising: float | None = None
    no_load_falling: float | None = None
    slope_dead_zone: float = 0.0
    slope_loaded_pos: float | None = None
    slope_loaded_neg: float | None = None
    edge_level_pos: float | None = None
    edge_level_neg: float | None = None
    current_noise: float | None = None
    current_min: float | None = None
    current_max: float | None = None
    cogging_period: float | None = None
    cogging_sin: float | None = None
    cogging_cos: float | None = None

    OPTIONAL = ("no_load_rising", "no_load_falling", "slope_loaded_pos", "slope_loaded_neg", "edge_level_pos",
                "edge_level_neg", "current_noise", "current_min", "current_max",
                "cogging_period", "cogging_sin", "cogging_cos")
    """Numeric fields a model file may leave out."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "current_edges", MappingProxyType(dict(self.current_edges)))
        if self.current_sign not in (None, "signed", "magnitude"):
            raise ModelError(f"identification: current_sign must be signed or magnitude, got {self.current_sign!r}")
        bad = [k for k in self.current_edges if k not in ("pos", "neg")]
        if bad:
            raise ModelError(f"identification: current_edges keys must be pos/neg, got {', '.join(bad)}")
        cog = (self.cogging_period, self.cogging_sin, self.cogging_cos)
        if any(v is not None for v in cog):
            if any(v is None for v in cog):
                raise ModelError("identification: cogging_period, cogging_sin and cogging_cos go together "
                                 "(a model file gives all three or none)")
            if not (math.isfinite(self.cogging_period) and self.cogging_period > 0):
                raise ModelError(f"identification: cogging_period must be a positive number of deg, "
                                 f"got {self.cogging_period!r}")
            if not (math.isfinite(self.cogging_sin) and math.isfinite(self.cogging_cos)):
                raise ModelError("identification: cogging_sin and cogging_cos must be finite")

    @property
    def ripple(self):  # noqa: ANN201 - hystcli.signal.condition.Ripple or None
        """The cogging ripple, None when the sweep showed none."""
        if self.cogging_period is None:
            return None
        from ..signal.condition import Ripple

        return Ripple(self.cogging_period, self.cogging_sin, self.cogging_cos)

    @property
    def slope_loaded(self) -> float:
        """The tendons' loaded slope (the smaller side's; 0 when neither was read)."""
        v = [s for s in (self.slope_loaded_pos, self.slope_loaded_neg) if s is not None]
        return min(v) if v else 0.0

    @property
    def current_dead_zone(self) -> float | None:
        """The current with no tendon taut: the mean of the two directions' levels."""
        v = [s for s in (self.no_load_rising, self.no_load_falling) if s is not None]
        return sum(v) / len(v) if v else None


@dataclass(frozen=True)
class KnobIdentification:
    """What ``hyst identify`` learnt about one knob beyond its eight parameters.

    Stored in the model file so that ``detect-shift`` runs with nothing given, and so that every
    command knows what the record fixed.

    Attributes
    ----------
    q_min, q_max : float
        Knob range the model was identified on (deg).
    method : str
        ``"tip"``, ``"current"`` or ``"given"`` (a model read against a record it did not come from).
    rmse : float or None
        RMSE of the model against the measured tip angle (deg), when the sweep had one.
    estimates : mapping of str to Estimate
        The seven parameters with their intervals; ``fixed`` False for what the sweep did not fix.
    calibration : Calibration
        How the sweep's motor current reads, for Algorithm 1 (empty without a current).
    """

    q_min: float
    q_max: float
    method: str = "tip"
    rmse: float | None = None
    estimates: Mapping[str, "Estimate"] = field(default_factory=dict)
    calibration: Calibration = Calibration()

    def __post_init__(self) -> None:
        object.__setattr__(self, "estimates", MappingProxyType(dict(self.estimates)))
        if not isinstance(self.calibration, Calibration):
            raise ModelError(f"identification: calibration must be a Calibration, got {self.calibration!r}")

    @property
    def unfixed(self) -> tuple[str, ...]:
        """Parameters the sweep did not fix."""
        return tuple(n for n, e in self.estimates.items() if not e.fixed)

    @property
    def stderr(self) -> dict[str, float]:
        """One-sigma uncertainties of the fixed parameters (from their intervals)."""
        return {n: e.stderr for n, e in self.estimates.items() if e.fixed and math.isfinite(e.stderr)}
