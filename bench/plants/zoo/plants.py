"""One-knob test catheters ("plants") written from the physics alone.

Nothing here imports :mod:`hystcli`; the plants were written from docs/design.md sections
1-4 and 6 and the paper (section II equations, section III protocol).

The tip
=======
The tip angle follows docs/design.md section 3 exactly: parameters ``d_pos, d_neg, b_pos, b_neg,
omega, h_pos, h_neg, offset``, derived ``dhat_pos = (h_pos-h_neg)/omega + d_neg + b_neg`` and
``dhat_neg = (h_neg-h_pos)/omega + d_pos - b_pos``, envelopes ``f_up``/``f_dn`` on
``u = q - offset`` and the clamp recursion ``y_t = min(max(y_{t-1}, f_up(u_t)), f_dn(u_t))``.
A mechanical reading that guides the current laws below: the bending section has its own
Coulomb friction, a band of half-width ``(h_neg - h_pos)/2`` around its neutral angle: a tendon
moving the tip up needs a tip-end tension ``k (y - h_pos)``, one holding it while it comes down
``k (y - h_neg)``; the sheath friction between each tendon and its sheath adds the backlash
``b``: after a reversal the knob must travel ``b`` before the tip starts to move back.

Only the ``wall`` family departs from the recursion: a rigid wall stops the tip at ``wall_y``.

The motor current
=================
The current is the knob motor's signed torque current in mA. With no tendon taut it sits near
its no-load level ``c0``. **Taking up the positive tendon (knob past d_pos) makes the current
rise above c0; taking up the negative tendon (knob below d_neg) makes it fall below c0.**
Each tendon's load is kept in knob degrees of stretch-equivalent: on the loading path it is how
far the knob is past the edge where that tendon became taut (``u - d_pos`` or ``d_neg - u``), so
the loaded slope ``k_pos`` / ``k_neg`` (mA/deg, 2-50) turns it into current. All tendon terms
are functions of ``u``: a bend moves the current loop along the knob axis by ``offset`` exactly
as it moves the tip loop (only the motor's own cogging ripple, a function of ``q``, does not).

Base tendon laws (how a tendon's load comes back down after a reversal at knob ``x_r`` with
load ``P_r``):

``stretch``
    The motor feels the stretch of the taut tendon and nothing else (a stiff tip, negligible
    friction at the handle): load ``max(u - d_pos, 0)`` and ``max(d_neg - u, 0)``, a function of
    the knob alone. The current is the same on both directions of travel; it carries the dead
    zone but not the backlash.
``tip-load``
    The motor feels the load the tip puts on the taut tendon. After a reversal the tip rests on
    its backlash plateau, held by friction, and the tendon keeps its load: the current stays at
    its peak while the knob travels ``b`` back (``u_pe = x_r - b``). Only then, as the tip comes
    down, does the tendon unload, linearly in the knob (linearly in the tip angle on a full
    excursion), reaching no-load where the tip settles on its dead-zone plateau
    (``dhat_neg`` for the positive tendon) or, on a small excursion that never lifts the tip past
    that plateau, after an elastic release of at least ``rho`` (0.15-0.5) times the loaded
    stretch. The current carries the backlash.
``drop-at-reversal``
    The force the motor feels is the tip load plus the sheath friction while pulling, minus it
    while releasing: when the knob reverses, the friction flips and the force drops at once by
    a fraction ``drop_frac`` (0.25-0.8) of the load within ``drop_travel`` (0.05-0.6 deg) of
    knob travel. Then it unloads: either it holds (tip stuck) until the backlash is taken up
    and then unloads as in ``tip-load`` (``drop_hold``), or it unloads linearly at once down to
    the same slack point.

Families (``FAMILIES``); a family is a base law plus overlays, mixed at random:

``stretch``, ``tip-load``, ``drop-at-reversal``
    The base laws above, alone.
``pretension``
    Both tendons are pre-tensioned (a tensioner spring per tendon): moving the knob loads one
    and relaxes the other, so the current has a small slope ``pre_slope`` (0.1-0.5 of the
    loaded slope) everywhere, the dead zone included; at an edge only the slope changes. On a
    random base law.
``coulomb-viscous``
    The motor and gearbox friction on top of a random base law (sometimes pretensioned):
    Coulomb ``coulomb * tanh(v / v_eps)`` (5-60 mA, a jump with the sign of the knob velocity
    ``v``), viscous ``viscous * v`` (0.02-0.8 mA per deg/s), and in half the cases a cogging
    ripple ``ripple_amp * sin(2 pi q / ripple_period + phase)`` (0.5-4 mA, 0.5-5 deg period).
``spiky``
    Stiction on a random base law (sometimes pretensioned, sometimes with Coulomb friction):
    a burst ``spike_amp * sign(v) * exp(-(t - t_k)/spike_tau)`` (15-250 mA, 4-40 ms) each time
    the knob reverses or starts to move after resting at least ``spike_rest`` s; plus isolated
    outliers (one-sample logging glitches, rate 0.02-0.3 %, 40-600 mA, either sign) added after
    any filtering.
``stiffening``
    A stiffening tendon: the load ``P`` becomes ``P + P**2 / (2 stiff_scale)`` (``stiff_scale``
    4-30 deg): the slope at the edge is ``k``, and it grows with stretch.
``wall``
    The tip meets a rigid wall on one side (placed on the outer part of the sweep): the tip
    angle stops at ``wall_y``; the knob keeps stretching the tendon against it, so the current
    rises ``wall_slope_factor`` (5-20) times more steeply beyond the contact knob position.
    On a random base law. The true parameters are those of the free tip.

Measurement: white current noise (0.2-6 mA, lowered when needed so that the identification
sweep's loaded ends rise at least 6 sigma above the no-load level on both sides; after an optional quantisation of 0.1 or 1 mA) and
tracker noise (0.02-0.5 deg); in half the cases the lab's 3rd-order Butterworth low-pass at
20 Hz, zero-phase offline (``scipy.signal.sosfiltfilt``) on current and tip; the live plant
filters its current causally instead. Sampling 50 Hz-2 kHz, sometimes with timing jitter
(+-0.25 sample) and a non-zero start time; records are capped at 20000 samples (the sampling
rate is lowered to fit, never below 50 Hz).

Drawn truths
============
Dead-zone width ``d_pos - d_neg`` 2-25 deg; ``d_pos / -d_neg`` log-uniform in 1/3-3, and in 10 %
of the plants the whole dead zone is moved off the knob's zero (1.05-1.6 times one edge); mean
backlash 0-0.75 of the width (exactly 0 in 5 %), ``b_pos / b_neg`` log-uniform in 1/3-3;
``omega`` 0.8-2.0; ``h_neg - h_pos = omega * (max(0, max(b) - width) + U(0, 10))`` (the lowest
value validity allows, plus up to 10 deg of knob), centred on -4..4 deg. Every truth passes
the section 3 validity checks (``KnobTruth`` raises ``ValueError`` naming the violated one).

Sweeps, start states, shifts
============================
A sweep is 1-3 cycles of a sine or triangle of amplitude ``A`` = the farther edge + a margin of
1-45 deg, peak speed 3-80 deg/s, started at any phase. Its start state is what a simulated
history leaves (a fresh catheter at u = 0 with a straight tip, then 1-2 random knob moves that
end at rest where the sweep starts): at rest in the dead zone, or with either tendon taut.

A bend while the knob rests at 0 acts on the tendons as a knob motion from u = 0 to
u = -offset; it is simulated as such (one tendon may end up taut and the tip held on its
backlash plateau). A replay is a slow (3-20 deg/s) sine or triangle from the rest position 0,
either direction first, amplitude 10-70 deg, 0.5-2 cycles, recorded after the bend.

Determinism: every draw comes from ``numpy.random.default_rng(seed)`` in a fixed order (the
same order for every family), so the same call gives the same bytes; ``replay_case(s, f)``
starts with exactly the draws of ``sweep_case(s, f)`` (same plant, same straight sweep) and
``live_plant(s, f)`` is that same plant.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Sequence

import numpy as np
from scipy import signal

from . import plants_kernel as _k

FAMILIES: tuple[str, ...] = (
    "stretch",
    "tip-load",
    "drop-at-reversal",
    "pretension",
    "coulomb-viscous",
    "spiky",
    "stiffening",
    "wall",
)
_BASES = ("stretch", "tip-load", "drop")
_BASE_CODE = {"stretch": _k.BASE_STRETCH, "tip-load": _k.BASE_TIP_LOAD, "drop": _k.BASE_DROP}
MAX_SAMPLES = 20000
_PRE_STEP = 0.05  # deg between samples of a simulated (unrecorded) history


# --------------------------------------------------------------------------------------------
# Truth
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class KnobTruth:
    """True docs/design.md section 3 parameters of one knob. Invalid sets raise ValueError."""

    d_pos: float
    d_neg: float
    b_pos: float
    b_neg: float
    omega: float
    h_pos: float
    h_neg: float
    offset: float = 0.0

    def __post_init__(self):
        vals = self.as_dict()
        for k, v in vals.items():
            if not math.isfinite(v):
                raise ValueError(f"{k} must be finite, got {v}")
        if not self.omega > 0:
            raise ValueError(f"omega > 0 violated (omega={self.omega})")
        if self.b_pos < 0:
            raise ValueError(f"b_pos >= 0 violated (b_pos={self.b_pos})")
        if self.b_neg < 0:
            raise ValueError(f"b_neg >= 0 violated (b_neg={self.b_neg})")
        tol = 1e-9 * (1.0 + abs(self.d_pos) + abs(self.d_neg))
        if self.dhat_pos > self.d_pos + tol:
            raise ValueError(f"dhat_pos <= d_pos violated ({self.dhat_pos} > {self.d_pos})")
        if self.d_neg > self.dhat_neg + tol:
            raise ValueError(f"d_neg <= dhat_neg violated ({self.d_neg} > {self.dhat_neg})")
        # both envelopes are piecewise linear with equal end slopes: checking the breakpoints
        # (and b >= 0 at +-infinity) checks f_up <= f_dn everywhere
        pts = np.array([self.dhat_pos, self.d_pos, self.d_neg, self.dhat_neg]) + self.offset
        gap = self.f_dn(pts) - self.f_up(pts)
        if np.any(gap < -1e-9 * (1.0 + abs(self.h_pos) + abs(self.h_neg))):
            raise ValueError(f"f_up <= f_dn violated (f_dn - f_up = {gap.min():.6g} at a breakpoint)")

    @property
    def dhat_pos(self) -> float:
        return (self.h_pos - self.h_neg) / self.omega + self.d_neg + self.b_neg

    @property
    def dhat_neg(self) -> float:
        return (self.h_neg - self.h_pos) / self.omega + self.d_pos - self.b_pos

    def f_up(self, x):
        """Ascending envelope at knob x (the offset applied)."""
        u = np.asarray(x, dtype=float) - self.offset
        w = self.omega
        return np.where(u < self.dhat_pos, w * (u - self.dhat_pos) + self.h_pos,
                        np.where(u <= self.d_pos, self.h_pos, w * (u - self.d_pos) + self.h_pos))

    def f_dn(self, x):
        """Descending envelope at knob x (the offset applied)."""
        u = np.asarray(x, dtype=float) - self.offset
        w = self.omega
        return np.where(u < self.d_neg, w * (u - self.d_neg) + self.h_neg,
                        np.where(u <= self.dhat_neg, self.h_neg, w * (u - self.dhat_neg) + self.h_neg))

    def forward(self, q: np.ndarray, y0: float) -> np.ndarray:
        """Tip angle for knob commands q from y_{-1} = y0 (the clamp recursion)."""
        u = np.ascontiguousarray(np.asarray(q, dtype=np.float64) - self.offset)
        return _k.tip_forward(u, self.d_pos, self.d_neg, self.omega, self.h_pos, self.h_neg,
                              self.dhat_pos, self.dhat_neg, float(y0))

    def as_dict(self) -> dict[str, float]:
        return {"d_pos": float(self.d_pos), "d_neg": float(self.d_neg),
                "b_pos": float(self.b_pos), "b_neg": float(self.b_neg),
                "omega": float(self.omega), "h_pos": float(self.h_pos),
                "h_neg": float(self.h_neg), "offset": float(self.offset)}

    def shifted(self, offset: float) -> "KnobTruth":
        return replace(self, offset=float(offset))


def _loguniform(rng, lo, hi):
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def _draw_truth(rng) -> KnobTruth:
    width = rng.uniform(2.0, 25.0)                  # dead-zone width d_pos - d_neg
    ratio = _loguniform(rng, 1 / 3, 3.0)            # d_pos / -d_neg
    d_pos = width * ratio / (1 + ratio)
    d_neg = -width / (1 + ratio)
    off_zero = rng.random() < 0.1                   # a dead zone that misses the knob's zero
    side = rng.random() < 0.5
    how_far = rng.uniform(1.05, 1.6)
    if off_zero:
        s = how_far * (-d_neg) if side else -how_far * d_pos
        d_pos, d_neg = d_pos + s, d_neg + s
    no_backlash = rng.random() < 0.05
    b_mean = rng.uniform(0.0, 0.75 * width)
    if no_backlash:
        b_mean = 0.0
    rb = _loguniform(rng, 1 / 3, 3.0)
    b_pos = 2 * b_mean * rb / (1 + rb)
    b_neg = 2 * b_mean / (1 + rb)
    omega = rng.uniform(0.8, 2.0)
    lb = max(0.0, omega * (max(b_pos, b_neg) - width))   # validity: dh/omega >= max(b) - width
    dh = lb + omega * rng.uniform(0.0, 10.0)
    centre = rng.uniform(-4.0, 4.0)
    return KnobTruth(d_pos=float(d_pos), d_neg=float(d_neg), b_pos=float(b_pos),
                     b_neg=float(b_neg), omega=float(omega), h_pos=float(centre - dh / 2),
                     h_neg=float(centre + dh / 2))


# --------------------------------------------------------------------------------------------
# Current law
# --------------------------------------------------------------------------------------------
def _draw_law(rng, family: str) -> dict:
    """Every factor is drawn for every family (fixed draw order), then the family picks."""
    d = {}
    k_mean = _loguniform(rng, 2.5, 40.0)
    r = _loguniform(rng, 0.5, 2.0)
    d["k_pos"], d["k_neg"] = k_mean * math.sqrt(r), k_mean / math.sqrt(r)
    d["c0"] = rng.uniform(-150.0, 250.0)
    d["noise_c"] = _loguniform(rng, 0.2, 6.0)
    d["noise_y"] = _loguniform(rng, 0.02, 0.5)
    d["filtered"] = bool(rng.random() < 0.5)
    d["lsb"] = float(rng.choice([0.0, 0.0, 0.0, 0.1, 1.0]))
    any_base = str(rng.choice(_BASES))
    d["rho"] = rng.uniform(0.15, 0.5)
    d["drop_frac"] = rng.uniform(0.25, 0.8)
    d["drop_travel"] = rng.uniform(0.05, 0.6)
    d["drop_hold"] = bool(rng.random() < 0.6)
    pre_frac = rng.uniform(0.1, 0.5)
    extra_pre = rng.random() < 0.3
    extra_coulomb = rng.random() < 0.3
    d["stiff_scale"] = _loguniform(rng, 4.0, 30.0)
    d["coulomb"] = rng.uniform(5.0, 60.0)
    d["viscous"] = _loguniform(rng, 0.02, 0.8)
    d["v_eps"] = rng.uniform(0.2, 2.0)
    ripple_on = rng.random() < 0.5
    d["ripple_amp"] = rng.uniform(0.5, 4.0)
    d["ripple_period"] = rng.uniform(0.5, 5.0)
    d["ripple_phase"] = rng.uniform(0, 2 * math.pi)
    d["spike_amp"] = _loguniform(rng, 15.0, 250.0)
    d["spike_tau"] = rng.uniform(0.004, 0.04)
    d["spike_rest"] = rng.uniform(0.02, 0.3)
    d["outlier_rate"] = _loguniform(rng, 2e-4, 3e-3)
    d["outlier_amp"] = _loguniform(rng, 40.0, 600.0)
    d["wall_side"] = float(rng.choice([-1.0, 1.0]))
    d["wall_frac"] = rng.uniform(0.45, 0.85)
    d["wall_slope_factor"] = rng.uniform(5.0, 20.0)

    base = {"stretch": "stretch", "tip-load": "tip-load", "drop-at-reversal": "drop",
            "stiffening": any_base if any_base != "drop" else "stretch"}.get(family, any_base)
    d["base"] = base
    if base != "drop":
        d["drop_frac"] = d["drop_travel"] = 0.0
        d["drop_hold"] = True
    if base == "stretch":
        d["rho"] = 0.0
    d["pre_slope"] = (pre_frac * min(d["k_pos"], d["k_neg"])
                      if family == "pretension" or (family in ("coulomb-viscous", "spiky", "wall") and extra_pre)
                      else 0.0)
    if not (family == "coulomb-viscous" or (family == "spiky" and extra_coulomb)):
        d["coulomb"] = d["viscous"] = 0.0
    if not (family == "coulomb-viscous" and ripple_on):
        d["ripple_amp"] = 0.0
    if family != "stiffening":
        d["stiff_scale"] = 0.0
    if family != "spiky":
        d["spike_amp"] = d["outlier_rate"] = d["outlier_amp"] = 0.0
    if family != "wall":
        d["wall_side"] = 0.0
        d["wall_frac"] = d["wall_slope_factor"] = 0.0
    d["wall_y"] = 0.0
    d["wall_u"] = 0.0
    d["current_shows_backlash"] = base == "tip-load" or (base == "drop" and d["drop_hold"])
    return {k: (float(v) if isinstance(v, (float, np.floating)) else v) for k, v in d.items()}


def _place_wall(law: dict, truth: KnobTruth, amplitude: float) -> None:
    """Put the wall on the outer part of a sweep of this amplitude (free-tip truth, offset 0).

    The wall stands beyond both dead-zone plateaus (the tip meets it only while a tendon pulls
    it there): its knob gap past the edge is at least (h_neg - h_pos)/omega + 1 deg.
    """
    g0 = max(0.0, (truth.h_neg - truth.h_pos) / truth.omega) + 1.0
    if law["wall_side"] > 0:
        gap = g0 + law["wall_frac"] * max(amplitude - truth.d_pos - g0, 2.0)
        law["wall_u"] = float(truth.d_pos + gap)
        law["wall_y"] = float(truth.h_pos + truth.omega * gap)
    elif law["wall_side"] < 0:
        gap = g0 + law["wall_frac"] * max(amplitude + truth.d_neg - g0, 2.0)
        law["wall_u"] = float(truth.d_neg - gap)
        law["wall_y"] = float(truth.h_neg - truth.omega * gap)


def _params(truth: KnobTruth, law: dict) -> np.ndarray:
    p = np.zeros(_k.PARAM_LEN)
    p[:9] = [truth.d_pos, truth.d_neg, truth.b_pos, truth.b_neg, truth.omega, truth.h_pos,
             truth.h_neg, truth.dhat_pos, truth.dhat_neg]
    p[9] = _BASE_CODE[law["base"]]
    p[10] = law["rho"]
    p[11] = law["drop_frac"]
    p[12] = law["drop_travel"]
    p[13] = 1.0 if law["drop_hold"] else 0.0
    p[14] = law["wall_side"]
    p[15] = law["wall_y"]
    return p


def _shape(load: np.ndarray, stiff: float) -> np.ndarray:
    return load + load * load / (2.0 * stiff) if stiff > 0 else load


def _tendon_current(law: dict, truth: KnobTruth, u, q, vel, pos, neg) -> np.ndarray:
    """Noise-free current without stiction spikes: c0 + tendons + pretension + wall + motor."""
    c = law["c0"] + law["k_pos"] * _shape(pos, law["stiff_scale"]) \
        - law["k_neg"] * _shape(neg, law["stiff_scale"])
    if law["pre_slope"]:
        c = c + law["pre_slope"] * (u - 0.5 * (truth.d_pos + truth.d_neg))
    if law["wall_side"] > 0:
        c = c + law["wall_slope_factor"] * law["k_pos"] * np.maximum(u - law["wall_u"], 0.0)
    elif law["wall_side"] < 0:
        c = c - law["wall_slope_factor"] * law["k_neg"] * np.maximum(law["wall_u"] - u, 0.0)
    if law["coulomb"] or law["viscous"]:
        c = c + law["coulomb"] * np.tanh(vel / law["v_eps"]) + law["viscous"] * vel
    if law["ripple_amp"]:
        c = c + law["ripple_amp"] * np.sin(2 * np.pi * q / law["ripple_period"] + law["ripple_phase"])
    return c


def _spikes(law: dict, t: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Stiction bursts at every reversal and every start after a rest (the record starts from rest)."""
    out = np.zeros_like(t)
    if not law["spike_amp"] or t.size < 2:
        return out
    dq = np.diff(q)
    idx = np.flatnonzero(dq != 0.0) + 1          # samples that moved
    if idx.size == 0:
        return out
    dirs = np.sign(dq[idx - 1])
    prev_dir = np.concatenate(([0.0], dirs[:-1]))
    gap = np.concatenate(([np.inf], t[idx[1:] - 1] - t[idx[:-1]]))
    ev = (dirs != prev_dir) | (gap >= law["spike_rest"])
    for i, s in zip(idx[ev], dirs[ev]):
        tt = t[i:] - t[i]
        m = tt < 10 * law["spike_tau"]
        out[i:i + int(m.sum())] += law["spike_amp"] * s * np.exp(-tt[m] / law["spike_tau"])
    return out


def _measure(law: dict, rng, t, c_clean, y_clean, noiseless: bool):
    """Tracker and current sensor, optional offline zero-phase filter, logging outliers."""
    n = t.size
    nc = rng.standard_normal(n)
    ny = rng.standard_normal(n)
    r_out = rng.random(n)
    s_out = rng.choice([-1.0, 1.0], size=n)
    c = c_clean.copy()
    y = y_clean.copy()
    if not noiseless:
        c = c + law["noise_c"] * nc
        if law["lsb"]:
            c = np.round(c / law["lsb"]) * law["lsb"]
        y = y + law["noise_y"] * ny
    if law["filtered"]:
        fs = (n - 1) / (t[-1] - t[0])
        if fs > 40.0 and n > 30:
            sos = signal.butter(3, 20.0, fs=fs, output="sos")
            c = signal.sosfiltfilt(sos, c)
            y = signal.sosfiltfilt(sos, y)
    if law["outlier_rate"] and not noiseless:
        hit = r_out < law["outlier_rate"]
        c = c + hit * s_out * law["outlier_amp"]
    return c, y


def _dense_path(waypoints: Sequence[float]) -> np.ndarray:
    """Fine knob steps through waypoints: an unrecorded history (the clamp is rate-independent)."""
    parts = [np.array([waypoints[0]], dtype=float)]
    for a, b in zip(waypoints[:-1], waypoints[1:]):
        m = max(1, int(math.ceil(abs(b - a) / _PRE_STEP)))
        parts.append(np.linspace(a, b, m + 1)[1:])
    return np.concatenate(parts)


def _taut(st: np.ndarray) -> str:
    if st[3] > 0:
        return "pos"
    if st[10] > 0:
        return "neg"
    return "none"


# --------------------------------------------------------------------------------------------
# Records
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Record:
    """One recorded run: docs/design.md section 6 columns and metadata."""

    columns: dict[str, np.ndarray]
    meta: dict[str, str] = field(default_factory=dict)

    def csv_text(self) -> str:
        lines = [f"# {k}: {v}" for k, v in self.meta.items()]
        names = list(self.columns)
        lines.append(",".join(names))
        arr = np.column_stack([np.asarray(self.columns[k], dtype=float) for k in names])
        lines.extend(",".join(map(repr, row)) for row in arr.tolist())
        return "\n".join(lines) + "\n"


def _wave(kind: str, theta):
    if kind == "sine":
        return np.sin(theta)
    return (2.0 / np.pi) * np.arcsin(np.clip(np.sin(theta), -1.0, 1.0))


def _times(rng, duration: float, fs_drawn: float):
    """Sampling instants 0..duration (plus jitter) and the actual rate after the sample cap."""
    fs = fs_drawn
    if duration * fs + 1 > MAX_SAMPLES:
        fs = max(50.0, (MAX_SAMPLES - 1) / duration)
    if duration * fs + 1 < 300:
        fs = min(2000.0, 299.0 / duration)
    n = int(math.floor(duration * fs)) + 1
    jitter_on = rng.random() < 0.5
    jit = rng.uniform(-0.25, 0.25, size=n) / fs
    tau = np.arange(n) / fs
    if jitter_on:
        tau = tau + jit
        tau[0] = 0.0
    t0 = 0.0 if rng.random() < 0.5 else float(rng.uniform(0.0, 500.0))
    return tau, fs, n, jitter_on, t0


def _record_run(truth, law, rng, st, q, tau, t0, knob, tip, meta, noiseless):
    """Simulate the recorded samples q(tau) from state st (advanced in place)."""
    u = q - truth.offset
    y, pos, neg = _k.run(u, _params(truth, law), st)
    vel = np.gradient(q, tau) if q.size > 1 else np.zeros_like(q)
    c = _tendon_current(law, truth, u, q, vel, pos, neg) + _spikes(law, tau, q)
    c_meas, y_meas = _measure(law, rng, tau, c, y, noiseless)
    cols = {"t": tau + t0, f"q{knob}": q}
    if tip:
        cols[f"y{knob}"] = y_meas
    cols[f"c{knob}"] = c_meas
    return Record(columns=cols, meta=meta), y, c


# --------------------------------------------------------------------------------------------
# Sweep cases
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SweepCase:
    seed: int
    family: str
    truth: KnobTruth
    record: Record
    factors: dict
    current_shows_backlash: bool


def _start(seed: int, family: str | None):
    rng = np.random.default_rng(seed)
    fam_draw = str(rng.choice(FAMILIES))
    fam = family if family is not None else fam_draw
    if fam not in FAMILIES:
        raise ValueError(f"unknown family {fam!r}; known: {', '.join(FAMILIES)}")
    truth = _draw_truth(rng)
    law = _draw_law(rng, fam)
    return rng, fam, truth, law


def _draw_sweep(rng, truth: KnobTruth):
    edge = max(truth.d_pos, -truth.d_neg)
    g = {}
    g["margin"] = _loguniform(rng, 1.0, 45.0)
    g["amplitude"] = min(edge + g["margin"], 90.0)
    g["waveform"] = str(rng.choice(["sine", "triangle"]))
    g["cycles"] = int(rng.integers(1, 4))
    g["speed"] = _loguniform(rng, 3.0, 80.0)        # peak knob speed, deg/s
    g["fs_drawn"] = _loguniform(rng, 50.0, 2000.0)
    g["start_region"] = str(rng.choice(["dead-zone", "pos", "neg"], p=[0.4, 0.3, 0.3]))
    g["first_direction"] = int(rng.choice([-1, 1]))
    g["u_frac"] = rng.random()
    p_up = {"pos": 0.7, "neg": 0.3}.get(g["start_region"], 0.5)
    g["approach"] = int(1 if rng.random() < p_up else -1)  # +1: the knob came up into the start
    g["approach_travel"] = rng.uniform(0.5, 30.0)
    g["extra_waypoint"] = bool(rng.random() < 0.4)
    g["waypoint0"] = rng.uniform(-g["amplitude"] - 5, g["amplitude"] + 5)
    return g


def _fit_to_sweep(law: dict, truth: KnobTruth, g: dict) -> None:
    """Where the lab's identification sweep fixes the plant's setting: the wall's place, and a
    current noise low enough that the sweep's loaded ends rise 6 sigma above it on both sides
    (a lab would not keep a sweep that shows no edge at all)."""
    if law["wall_side"] != 0:
        _place_wall(law, truth, g["amplitude"])
    law["noise_c_drawn"] = law["noise_c"]
    A = g["amplitude"]
    rise = min(law["k_pos"] * (A - truth.d_pos), law["k_neg"] * (A + truth.d_neg))
    law["noise_c"] = float(min(law["noise_c"], rise / 6.0))


def _sweep_from(rng, fam, truth, law, knob, tip, noiseless, overrides, seed=0):
    g = _draw_sweep(rng, truth)
    _fit_to_sweep(law, truth, g)
    family_wall = law["wall_side"] != 0
    if overrides:
        law.update({k: v for k, v in overrides.items() if k in law})
        g.update({k: v for k, v in overrides.items() if k in g})
        law["current_shows_backlash"] = law["base"] == "tip-load" or (
            law["base"] == "drop" and bool(law["drop_hold"]))
    A = g["amplitude"]
    lo, hi = {"pos": (truth.d_pos, A), "neg": (-A, truth.d_neg),
              "dead-zone": (max(truth.d_neg, -A), min(truth.d_pos, A))}[g["start_region"]]
    q0 = lo + (0.02 + 0.96 * g["u_frac"]) * (hi - lo)
    s0 = g["first_direction"]
    a = math.asin(max(-1.0, min(1.0, q0 / A)))
    if g["waveform"] == "sine":
        theta0 = a if s0 > 0 else math.pi - a
        f = g["speed"] / (2 * math.pi * A)
    else:
        theta0 = (math.pi / 2) * (q0 / A) if s0 > 0 else math.pi - (math.pi / 2) * (q0 / A)
        f = g["speed"] / (4 * A)
    duration = g["cycles"] / f
    tau, fs, n, jitter_on, t0 = _times(rng, duration, g["fs_drawn"])
    q = A * _wave(g["waveform"], 2 * math.pi * f * tau + theta0)
    # history: a fresh catheter at rest at 0 (straight tip), random moves ending at rest at q[0]
    way = [0.0] + ([g["waypoint0"]] if g["extra_waypoint"] else []) \
        + [q[0] - g["approach"] * g["approach_travel"], q[0]]
    st = _k.new_state(0.0, 0.0)
    hist = _dense_path(way)
    _k.run(hist, _params(truth, law), st)
    start_taut = _taut(st)
    y_start = float(st[1])
    meta = {"catheter": f"zoo-{seed}", "controller": "none", "shape": "straight", "motion": "sweep",
            "trial": "1"}
    rec, _, _ = _record_run(truth, law, rng, st, q, tau, t0, knob, tip, meta, noiseless)
    factors = dict(law)
    factors.update(g)
    factors.update(family=fam, fs=fs, n=n, duration=duration, frequency=f, phase=theta0,
                   q_start=float(q[0]), history=[float(w) for w in way], start_taut=start_taut,
                   y_start=y_start, jitter=jitter_on, t0=t0, knob=knob, tip=tip,
                   noiseless=noiseless, wall=family_wall)
    return rec, factors, st


def sweep_case(seed: int, family: str | None = None, *, knob: int = 1, tip: bool = True,
               noiseless: bool = False, overrides: dict | None = None) -> SweepCase:
    """An identification sweep on the straight shaft.

    ``noiseless`` drops the sensor noise, quantisation and logging outliers (the physics, the
    stiction spikes and the filter stay); ``overrides`` replaces drawn factors by name (after all
    draws, so the rest of the case is unchanged).
    """
    rng, fam, truth, law = _start(seed, family)
    rec, factors, _ = _sweep_from(rng, fam, truth, law, knob, tip, noiseless, overrides, seed)
    return SweepCase(seed=seed, family=fam, truth=truth, record=rec, factors=factors,
                     current_shows_backlash=bool(factors["current_shows_backlash"]))


def sweep_cases(n: int, seed: int = 0, families: Sequence[str] | None = None, **kw) -> list[SweepCase]:
    """Cases seed, seed+1, ..., families cycled in order."""
    fams = tuple(families) if families else FAMILIES
    return [sweep_case(seed + i, fams[i % len(fams)], **kw) for i in range(n)]


# --------------------------------------------------------------------------------------------
# Replay cases
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ReplayCase:
    seed: int
    family: str
    truth: KnobTruth
    offset: float
    straight_sweep: Record
    replay: Record
    factors: dict


def _bend(truth0: KnobTruth, law: dict, st: np.ndarray, q_rest: float, offset: float) -> None:
    """The shaft bends while the knob rests at q_rest: u moves from q_rest to q_rest - offset."""
    _k.run(_dense_path([q_rest, q_rest - offset]), _params(truth0, law), st)


def replay_case(seed: int, family: str | None = None, *, knob: int = 1,
                noiseless: bool = False, overrides: dict | None = None) -> ReplayCase:
    """The plant of ``sweep_case(seed, family)`` (same straight sweep), then a bend and a replay."""
    rng, fam, truth, law = _start(seed, family)
    sweep, sfac, st = _sweep_from(rng, fam, truth, law, knob, True, noiseless, overrides, seed)
    r = {}
    r["null"] = bool(rng.random() < 0.1)
    off = rng.uniform(-30.0, 30.0)
    r["offset"] = 0.0 if r["null"] else float(off)
    r["return_overshoot"] = bool(rng.random() < 0.5)
    r["overshoot_to"] = rng.uniform(-40.0, 40.0)
    r["replay_amplitude"] = rng.uniform(10.0, 70.0)
    r["replay_speed"] = rng.uniform(3.0, 20.0)
    r["replay_waveform"] = str(rng.choice(["sine", "triangle"]))
    r["replay_cycles"] = float(rng.choice([0.5, 1.0, 1.5, 2.0], p=[0.15, 0.45, 0.15, 0.25]))
    r["first_direction"] = int(rng.choice([-1, 1]))
    r["fs_drawn"] = _loguniform(rng, 50.0, 2000.0)
    if overrides:
        r.update({k: v for k, v in overrides.items() if k in r})
    offset = float(r["offset"])
    # back to rest at 0 after the sweep (perhaps via an overshoot), then the bend
    q_end = float(sweep.columns[f"q{knob}"][-1])
    way = [q_end] + ([r["overshoot_to"]] if r["return_overshoot"] else []) + [0.0]
    _k.run(_dense_path(way), _params(truth, law), st)
    _bend(truth, law, st, 0.0, offset)
    start_taut = _taut(st)
    y_start = float(st[1])
    A, s0 = r["replay_amplitude"], r["first_direction"]
    if r["replay_waveform"] == "sine":
        f = r["replay_speed"] / (2 * math.pi * A)
    else:
        f = r["replay_speed"] / (4 * A)
    duration = r["replay_cycles"] / f
    tau, fs, n, jitter_on, t0 = _times(rng, duration, r["fs_drawn"])
    q = s0 * A * _wave(r["replay_waveform"], 2 * math.pi * f * tau)
    q[0] = 0.0
    bent = truth.shifted(offset)
    meta = {"catheter": f"zoo-{seed}", "controller": "none", "motion": "replay", "trial": "1"}
    rec, _, _ = _record_run(bent, law, rng, st, q, tau, t0, knob, True, meta, noiseless)
    factors = dict(r)
    factors.update(family=fam, fs=fs, n=n, duration=duration, frequency=f, jitter=jitter_on,
                   t0=t0, start_taut=start_taut, y_start=y_start, return_path=way,
                   reaches_pos_edge=bool(q.max() > truth.d_pos + offset),
                   reaches_neg_edge=bool(q.min() < truth.d_neg + offset),
                   knob=knob, noiseless=noiseless, sweep=sfac)
    return ReplayCase(seed=seed, family=fam, truth=truth, offset=offset, straight_sweep=sweep,
                      replay=rec, factors=factors)


def replay_cases(n: int, seed: int = 0, families: Sequence[str] | None = None, **kw) -> list[ReplayCase]:
    fams = tuple(families) if families else FAMILIES
    return [replay_case(seed + i, fams[i % len(fams)], **kw) for i in range(n)]


# --------------------------------------------------------------------------------------------
# Live plant
# --------------------------------------------------------------------------------------------
class LivePlant:
    """The plant stepped move by move, as a robot drives it (a serial emulator can serve it).

    At construction the catheter is fresh at rest at knob 0 on a straight shaft; it makes a
    random excursion and comes back to rest at 0; then the shaft bends by ``truth.offset``
    (simulated as a knob motion from u = 0 to u = -offset). The current is filtered causally
    (20 Hz, 3rd-order Butterworth) when the drawn law says ``filtered``; ``tip`` is the tracker
    reading (with noise). ``noiseless`` drops sensor noise, quantisation and outliers.
    """

    def __init__(self, truth: KnobTruth, family: str, seed: int = 0, *, knob: int = 1,
                 law: dict | None = None, noiseless: bool = False):
        if family not in FAMILIES:
            raise ValueError(f"unknown family {family!r}; known: {', '.join(FAMILIES)}")
        self.truth = truth
        self.family = family
        self.knob = int(knob)
        self.knobs = (self.knob,)
        rng = np.random.default_rng(seed)
        self.law = dict(law) if law is not None else _draw_law(rng, family)
        if self.law["wall_side"] != 0 and self.law["wall_u"] == 0.0:
            _place_wall(self.law, replace(truth, offset=0.0), max(truth.d_pos, -truth.d_neg) + 20.0)
        self._rng = np.random.default_rng([seed, 7])
        self.noiseless = noiseless
        self._p = _params(truth, self.law)
        self._st = _k.new_state(0.0, 0.0)
        excursion = float(self._rng.uniform(-40.0, 40.0))
        straight = _params(replace(truth, offset=0.0), self.law)
        _k.run(_dense_path([0.0, excursion, 0.0]), straight, self._st)
        _k.run(_dense_path([0.0, -truth.offset]), straight, self._st)
        self.history = {"excursion": excursion}
        self.t = 0.0
        self.q = 0.0
        self._y = float(self._st[1])
        self._last_dir = 0.0
        self._t_last_move = -np.inf
        self._spike = 0.0
        self._sos_cache: dict[float, np.ndarray] = {}
        self._zi = None
        self._zi_dt = None
        c, y = self._sample(np.array([0.0]), np.array([0.0]), 1.0)
        self._c = float(c[-1])
        self._ym = float(y[-1])
        self._last_q = np.array([self.q])
        self._last_c = np.array([self._c])

    def _check(self, knob: int) -> None:
        if knob != self.knob:
            raise ValueError(f"this plant drives knob {self.knob}, not {knob}")

    def _sample(self, q: np.ndarray, vel: np.ndarray, dt: float):
        law = self.law
        u = q - self.truth.offset
        y, pos, neg = _k.run(u, self._p, self._st)
        c = _tendon_current(law, self.truth, u, q, vel, pos, neg)
        if law["spike_amp"]:
            sp = np.empty(q.size)
            decay = math.exp(-dt / law["spike_tau"])
            for i in range(q.size):
                self._spike *= decay
                d = float(np.sign(vel[i]))
                if d != 0.0:
                    if d != self._last_dir or self.t - dt * (q.size - 1 - i) - self._t_last_move >= law["spike_rest"]:
                        self._spike += law["spike_amp"] * d
                    self._last_dir = d
                    self._t_last_move = self.t - dt * (q.size - 1 - i)
                sp[i] = self._spike
            c = c + sp
        n = q.size
        if not self.noiseless:
            c = c + law["noise_c"] * self._rng.standard_normal(n)
            if law["lsb"]:
                c = np.round(c / law["lsb"]) * law["lsb"]
        if law["filtered"] and dt < 1.0 / 40.0:
            sos = self._sos_cache.get(dt)
            if sos is None:
                sos = self._sos_cache[dt] = signal.butter(3, 20.0, fs=1.0 / dt, output="sos")
            if self._zi is None or self._zi_dt != dt:
                self._zi = signal.sosfilt_zi(sos) * (self._c if hasattr(self, "_c") else c[0])
                self._zi_dt = dt
            c, self._zi = signal.sosfilt(sos, c, zi=self._zi)
        ym = y.copy()
        if not self.noiseless:
            ym = ym + law["noise_y"] * self._rng.standard_normal(n)
            if law["outlier_rate"]:
                hit = self._rng.random(n) < law["outlier_rate"]
                c = c + hit * self._rng.choice([-1.0, 1.0], size=n) * law["outlier_amp"]
        self._y = float(y[-1])
        return c, ym

    def move(self, knob: int, q_target: float, speed_deg_s: float = 20.0, dt: float = 0.001):
        """Turn the knob to q_target at constant speed sampling every dt; (q, current, tip) at the end."""
        self._check(knob)
        if not speed_deg_s > 0 or not dt > 0:
            raise ValueError("speed_deg_s and dt must be > 0")
        dq = float(q_target) - self.q
        m = max(1, int(math.ceil(abs(dq) / (speed_deg_s * dt) - 1e-9)))
        q = self.q + dq * np.arange(1, m + 1) / m
        vel = np.full(m, dq / (m * dt))
        self.t += m * dt
        c, ym = self._sample(q, vel, dt)
        self.q = float(q_target)
        self._c, self._ym = float(c[-1]), float(ym[-1])
        self._last_q, self._last_c = q, c
        return self.q, self._c, self._ym

    def hold(self, duration: float, dt: float = 0.001) -> None:
        """Time passes with the knob still (the current is still sampled)."""
        if not dt > 0:
            raise ValueError("dt must be > 0")
        m = max(1, int(round(duration / dt)))
        q = np.full(m, self.q)
        self.t += m * dt
        c, ym = self._sample(q, np.zeros(m), dt)
        self._c, self._ym = float(c[-1]), float(ym[-1])
        self._last_q, self._last_c = q, c

    def state(self, knob: int) -> tuple[float, float, float]:
        self._check(knob)
        return self.q, self._c, self._ym

    def last_samples(self, knob: int) -> tuple[np.ndarray, np.ndarray]:
        self._check(knob)
        return self._last_q.copy(), self._last_c.copy()

    def true_tip(self, knob: int) -> float:
        """The tip angle without tracker noise (for scoring)."""
        self._check(knob)
        return self._y


def live_plant(seed: int, family: str | None = None, *, offset: float = 0.0, knob: int = 1,
               noiseless: bool = False) -> tuple[LivePlant, KnobTruth]:
    """The plant of ``sweep_case(seed, family)``, bent by ``offset``, ready at rest at knob 0."""
    rng, fam, truth, law = _start(seed, family)
    g = _draw_sweep(rng, truth)
    _fit_to_sweep(law, truth, g)
    bent = truth.shifted(offset)
    return LivePlant(bent, fam, seed, knob=knob, law=law, noiseless=noiseless), bent
