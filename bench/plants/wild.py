"""Wild test plants: a tendon-driven catheter knob whose records break the method's premises.

Physics simulated
-----------------
*Tip.* The knob angle q (deg) moves the tip's bending angle y (deg) through dead-zone + backlash
hysteresis (`KnobTruth`): with u = q - offset, the tip follows the clamp recursion
y_t = min(max(y_{t-1}, f_up(u_t)), f_dn(u_t)) of the ascending and descending envelopes. A shaft bend
moves the whole loop (tip and tendons) along the knob axis by `offset`; it is applied to the
plant's state as the knob motion u: 0 -> -offset would be, so it may leave a tendon taut and the
tip held.

*Tendons and current.* Each tendon is taken up from slack at its own current edge k_pos / k_neg
(`current_edge_pos/neg`, straight shaft). Its stretch passes through a play operator of width beta:
beta = 0 makes the load a function of the knob angle alone (the current shows the dead zone but no
backlash, mode 'follow'); beta = the tip's backlash (capped so that the two tendons are never both
taut) holds the load while the tip rests on its plateau and unloads it afterwards (modes 'hold'
and 'drop'). The load grows from the edge along a take-up curve (sharp, or a quadratic / cubic
onset over a width w: it departs from zero exactly at k and reaches slope 1 at k + w), optionally
stiffening (T + kappa T^2). The sheath's capstan friction multiplies the positive tendon's motor
load by exp(mu s) and the negative one's by exp(-mu s), where s (-1..1) is the direction of the
knob's recent travel, flipping over eps of travel: in mode 'drop' the load falls at once at a
reversal (sheath friction flips) before the plateau ends. The motor current is

    c = c0 + G_pos T_pos exp(mu s) - G_neg T_neg exp(-mu s) + p (u - u_mid)
           + c_f tanh(v / v_s) + c_v v

(p: tendon pretension, so the current never goes flat; c_f, c_v: motor/gearbox Coulomb and viscous
friction). A rigid wall on one side (family `wall`) stops the tip at a drawn angle and adds a
tendon load wall_gain times steeper from the knob angle of contact on. A magnitude drive reports
c0 + |c - c0| (never below no-load).

*Instrument.* The logged knob angle is the command; the motor may follow it through a first-order
servo lag or a pure delay, and the current and tip may be logged late. The current carries white
and coloured (AR(1) or 1/f-like sum of AR(1)) noise, cogging ripple periodic in the knob angle,
decaying stiction bursts at reversals, isolated outliers, drift of the no-load level (linear or
exponential), quantisation and an offline zero-phase 3rd-order Butterworth 20 Hz low-pass; the tip
carries tracker noise, drift, quantisation and the same filter. Sampling 30 Hz - 5 kHz, sometimes
jittered, at most 50 000 samples. The plant is integrated on a grid at least as fine as 0.05 deg of
knob travel and read at the sample instants. Outside `weak-current` the current's noise puts the
larger loaded rise 3-300 sigma above no-load (the smaller side as the asymmetry leaves it).

*Runs.* A sweep is a sine, a triangle or a decaying sine (its envelope ends at the drawn extent),
0.5-4 cycles (at least 1.25 when it covers both edges) at a peak speed of 2-150 deg/s (at
most 1 Hz). In about 90 % of cases it goes past
both tip edges by reach + a margin of 0.5-40 deg, where reach = (h_neg - h_pos)/omega is the
travel past an edge the tip needs before it comes back to the other flat; the others cover one
edge or none. It starts at any phase or back at its rest point, after a rest in the dead zone
and maybe an excursion past an edge (so a tendon may be taut and the tip held).

Families (each breaks one premise of an earlier plant set; every case also mixes in each other
break with probability `MIX`)
----------------------------------------------------------------------------------------------
kink-offset    the current's kink lies up to 2 deg before (tension overcoming the bending section's
               friction) or after (sheath compliance) the tip's edge, per side.
rounded        the load grows over a take-up width of 0.5-5 deg, not with a corner.
drift          the no-load level drifts 2-60 mA and the tracker 0.05-2 deg over a record.
coloured       the noise on current and tip is mostly AR(1) / 1/f with correlation times 5-500 ms.
latency        servo lag or delay of 5-200 ms and/or logging delays of 5-150 ms.
load-friction  capstan friction (mu 0.15-0.8): the loaded current differs between directions.
asymmetric     edge distances d_pos/(-d_neg), backlash and current gains 3:1 to 10:1 either way.
weak-current   the noise is set so that a loaded end rises only 1.5-3 sigma (one or both sides).
magnitude      the drive reports |c - c0|.
wall           the tip meets a rigid wall on one side within the sweep (truth: the free tip).

Factors
-------
`factors` holds every drawn value under its name, and these derived truths: `breaks` (the family
and the mixed-in breaks), `current_sign`, `current_edge_pos/neg` (knob angle, straight shaft,
where each tendon's current departs from no-load when taken up from slack), `current_knee_pos/neg`
(where the loaded line's extension meets no-load: the edge moved by the take-up's rounding),
`current_shows_backlash` (the load holds over the tip's plateau before it unloads), `no_load`,
`gain_pos/neg` (mA per deg of stretch), `rise_pos/neg` and `rise_sigma_pos/neg` (the clean loaded
rise at the sweep's extreme, in mA and in current-noise sigmas), `wall_side/knob/tip`,
`passes_pos/neg_edge` (the tip, having rested on its dead-zone flat, goes on along the loading
branch at least `PASS_MIN` past that edge: the record can fix it), `start_state` (the tendon that
carries load when the record starts, else the side the tip is held on, else 'slack'),
`tip_before` (the tip before the first sample), `fs`, `n`. A replay adds `offset` and the same
run factors prefixed `replay_`, with `replay_current_edge_pos/neg` on the bent shaft.

`noiseless=True` records an ideal instrument on the same plant: the plant evaluated at the logged
instants, no servo lag or logging delay, no noise, drift, cogging, stiction bursts, outliers,
quantisation or filter. Its tip is then exactly the clamp recursion of the logged knob angle.

Every draw comes from `numpy.random.SeedSequence(seed)` children in a fixed order: the family, the
plant and sweep, the sweep's noise, the replay, the replay's noise and the live plant each have
their own stream, so the same call gives the same bytes and `replay_case(seed)` shares the plant
and straight sweep of `sweep_case(seed)`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import signal

from . import wild_kernel as K

FAMILIES: tuple[str, ...] = (
    "kink-offset",
    "rounded",
    "drift",
    "coloured",
    "latency",
    "load-friction",
    "asymmetric",
    "weak-current",
    "magnitude",
    "wall",
)

MIX = 0.15
"""Probability that a case mixes in each break other than its family's."""
PASS_MIN = 0.5
"""Knob travel (deg) on the loading branch past a tip edge that counts as passing it."""
MAX_N = 50_000
"""Most samples in a record."""
MAX_STEP_DEG = 0.05
"""Finest knob travel between two points of the integration grid."""
LIVE_T_REF = 300.0
"""Time (s) by which a live plant's drift reaches its drawn amount."""
_TOL = 1e-9

_STREAM_FAMILY = 0
_STREAM_PLANT = 1
_STREAM_SWEEP_NOISE = 2
_STREAM_REPLAY = 3
_STREAM_REPLAY_NOISE = 4
_STREAM_LIVE = 5
_N_STREAMS = 6


def _rngs(seed: int) -> list[np.random.Generator]:
    if not isinstance(seed, (int, np.integer)) or isinstance(seed, bool) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    return [np.random.default_rng(s) for s in np.random.SeedSequence(int(seed)).spawn(_N_STREAMS)]


# --------------------------------------------------------------------------- the tip's truth


@dataclass(frozen=True)
class KnobTruth:
    """Dead-zone + backlash hysteresis of one knob's tip (deg).

    Parameters
    ----------
    d_pos, d_neg : float
        Dead-zone edges: where the tip leaves its flat on the way up (down).
    b_pos, b_neg : float
        Backlash widths: knob travel the tip rests on its plateau after a reversal at the top
        (bottom).
    omega : float
        Slope of the loaded branches.
    h_pos, h_neg : float
        Heights of the ascending and descending dead-zone flats.
    offset : float
        Shift of the whole loop along the knob axis (0 on a straight shaft).

    Raises
    ------
    ValueError
        If the parameters are not finite or break validity (omega > 0, b >= 0,
        dhat_pos <= d_pos, d_neg <= dhat_neg, f_up <= f_dn everywhere).
    """

    d_pos: float
    d_neg: float
    b_pos: float
    b_neg: float
    omega: float
    h_pos: float
    h_neg: float
    offset: float = 0.0

    def __post_init__(self) -> None:
        for name in ("d_pos", "d_neg", "b_pos", "b_neg", "omega", "h_pos", "h_neg", "offset"):
            value = getattr(self, name)
            if not math.isfinite(value):
                raise ValueError(f"KnobTruth.{name} must be finite, got {value!r}")
            object.__setattr__(self, name, float(value))
        if self.omega <= 0:
            raise ValueError(f"KnobTruth invalid: omega must be > 0, got {self.omega}")
        if self.b_pos < 0 or self.b_neg < 0:
            raise ValueError(f"KnobTruth invalid: backlash must be >= 0 ({self.b_pos}, {self.b_neg})")
        if self.dhat_pos > self.d_pos + _TOL:
            raise ValueError(
                f"KnobTruth invalid: dhat_pos {self.dhat_pos} > d_pos {self.d_pos}")
        if self.d_neg > self.dhat_neg + _TOL:
            raise ValueError(
                f"KnobTruth invalid: d_neg {self.d_neg} > dhat_neg {self.dhat_neg}")
        # f_dn - f_up is piecewise linear with its corners at the four breakpoints and constant
        # (omega*b >= 0) beyond them, so checking the corners checks everywhere.
        corners = np.array([self.dhat_pos, self.d_pos, self.d_neg, self.dhat_neg]) + self.offset
        gap = self.f_dn(corners) - self.f_up(corners)
        if np.any(gap < -_TOL * (1.0 + abs(self.h_pos) + abs(self.h_neg))):
            raise ValueError(f"KnobTruth invalid: f_up > f_dn at knob angles {corners[gap < 0]}")

    @property
    def dhat_pos(self) -> float:
        """Knob angle (u) where the ascending branch reaches the flat h_pos."""
        return (self.h_pos - self.h_neg) / self.omega + self.d_neg + self.b_neg

    @property
    def dhat_neg(self) -> float:
        """Knob angle (u) where the descending branch reaches the flat h_neg."""
        return (self.h_neg - self.h_pos) / self.omega + self.d_pos - self.b_pos

    def f_up(self, x):
        """Ascending envelope at knob angle(s) `x` (offset applied)."""
        u = np.asarray(x, dtype=float) - self.offset
        dhat = self.dhat_pos
        return np.where(u < dhat, self.omega * (u - dhat) + self.h_pos,
                        np.where(u > self.d_pos, self.omega * (u - self.d_pos) + self.h_pos,
                                 self.h_pos))

    def f_dn(self, x):
        """Descending envelope at knob angle(s) `x` (offset applied)."""
        u = np.asarray(x, dtype=float) - self.offset
        dhat = self.dhat_neg
        return np.where(u < self.d_neg, self.omega * (u - self.d_neg) + self.h_neg,
                        np.where(u > dhat, self.omega * (u - dhat) + self.h_neg, self.h_neg))

    def forward(self, q, y0: float) -> np.ndarray:
        """Tip along the knob angles `q` from the tip `y0` before the first one."""
        u = np.ascontiguousarray(q, dtype=float) - self.offset
        return _clamp(self, u, y0)[0]

    def as_dict(self) -> dict:
        """The parameters and the derived dhat_pos / dhat_neg as plain floats."""
        return {"d_pos": self.d_pos, "d_neg": self.d_neg, "b_pos": self.b_pos,
                "b_neg": self.b_neg, "omega": self.omega, "h_pos": self.h_pos,
                "h_neg": self.h_neg, "offset": self.offset, "dhat_pos": self.dhat_pos,
                "dhat_neg": self.dhat_neg}

    def shifted(self, offset: float) -> KnobTruth:
        """The same knob with its loop at `offset` (replacing this one's offset)."""
        return replace(self, offset=offset)


def _clamp(truth: KnobTruth, u: np.ndarray, y0: float):
    return K.clamp_path(u, float(y0), truth.d_pos, truth.d_neg, truth.dhat_pos, truth.dhat_neg,
                        truth.omega, truth.h_pos, truth.h_neg, PASS_MIN)


# --------------------------------------------------------------------------- records and cases


@dataclass(frozen=True, eq=False)
class Record:
    """One recorded run: columns 't' (s), 'q<k>' (deg), optional 'y<k>' (deg), 'c<k>' (mA)."""

    columns: dict[str, np.ndarray]
    meta: dict[str, str]

    def csv_text(self) -> str:
        """The record as CSV: '# key: value' lines, a header row, rows of repr() floats."""
        names = list(self.columns)
        lines = [f"# {k}: {v}" for k, v in self.meta.items()]
        lines.append(",".join(names))
        rows = zip(*(self.columns[c].tolist() for c in names))
        lines.extend(",".join(map(repr, row)) for row in rows)
        return "\n".join(lines) + "\n"


@dataclass(frozen=True, eq=False)
class SweepCase:
    """A calibration sweep of a drawn plant, with the truth and every drawn factor."""

    seed: int
    family: str
    truth: KnobTruth
    record: Record
    factors: dict


@dataclass(frozen=True, eq=False)
class ReplayCase:
    """The straight sweep of a plant, then a slow replay after the shaft bent by `offset`."""

    seed: int
    family: str
    truth: KnobTruth
    offset: float
    straight_sweep: Record
    replay: Record
    factors: dict


# --------------------------------------------------------------------------- drawn parameters


class _Draws:
    """Draws from one generator, recording each value under its name in `factors`."""

    def __init__(self, rng: np.random.Generator, factors: dict):
        self.rng = rng
        self.factors = factors

    def uniform(self, name: str, lo: float, hi: float) -> float:
        value = float(self.rng.uniform(lo, hi))
        self.factors[name] = value
        return value

    def loguniform(self, name: str, lo: float, hi: float) -> float:
        value = float(math.exp(self.rng.uniform(math.log(lo), math.log(hi))))
        self.factors[name] = value
        return value

    def choice(self, name: str, options: tuple, p=None):
        value = options[int(self.rng.choice(len(options), p=p))]
        self.factors[name] = value
        return value

    def chance(self, name: str, p: float) -> bool:
        value = bool(self.rng.random() < p)
        self.factors[name] = value
        return value


@dataclass(frozen=True)
class _Drive:
    """Tendons, motor and wall: what turns the knob's path into a clean current (mA)."""

    sign: str
    mode: str
    edge_pos: float
    edge_neg: float
    take_shape: str
    take_w_pos: float
    take_w_neg: float
    gain_pos: float
    gain_neg: float
    stiffening: float
    mu: float
    eps_dir: float
    beta_pos: float
    beta_neg: float
    pretension: float
    no_load: float
    coulomb: float
    v_stribeck: float
    viscous: float
    wall_side: int = 0
    wall_knob: float = 0.0
    wall_tip: float = 0.0
    wall_gain: float = 0.0

    def tendon_loads(self, zp, zn):
        """Loads (deg of stretch, wall included) of the positive and negative tendons."""
        tp = _take(zp - self.edge_pos, self.take_w_pos, self.take_shape)
        tn = _take(self.edge_neg - zn, self.take_w_neg, self.take_shape)
        tp = tp + self.stiffening * tp * tp
        tn = tn + self.stiffening * tn * tn
        if self.wall_side > 0:
            tp = tp + self.wall_gain * np.maximum(zp - max(self.edge_pos, self.wall_knob), 0.0)
        elif self.wall_side < 0:
            tn = tn + self.wall_gain * np.maximum(min(self.edge_neg, self.wall_knob) - zn, 0.0)
        return tp, tn

    def deviation(self, u, v, zp, zn, s):
        """Clean current minus the no-load level."""
        tp, tn = self.tendon_loads(zp, zn)
        cap = np.exp(self.mu * s)
        mid = 0.5 * (self.edge_pos + self.edge_neg)
        return (self.gain_pos * tp * cap - self.gain_neg * tn / cap
                + self.pretension * (u - mid)
                + self.coulomb * np.tanh(v / self.v_stribeck) + self.viscous * v)


@dataclass(frozen=True)
class _Instrument:
    """How the run is recorded: timing, latencies and every disturbance."""

    fs: float
    jitter: float
    servo: str
    servo_time: float
    lat_c: float
    lat_y: float
    sigma_c: float
    col_frac_c: float
    col_taus: tuple
    sigma_y: float
    sigma_y_col: float
    drift_c: float
    drift_y: float
    drift_shape: str
    drift_tau_frac: float
    outlier_rate: float
    outlier_mag: float
    stiction_amp: float
    stiction_tau: float
    cog_amp: float
    cog_period: float
    cog_phase: float
    lsb_c: float
    lsb_y: float
    filter_c: bool
    filter_y: bool


@dataclass(frozen=True)
class _Wave:
    """A commanded knob path q(t) (deg): sine, triangle or decaying sine (signed amplitude)."""

    kind: str
    centre: float
    amp: float
    freq: float
    phase: float
    decay: float = math.inf

    def pos(self, t):
        th = 2 * math.pi * self.freq * t + self.phase
        if self.kind == "triangle":
            return self.centre + self.amp * (2 / math.pi) * np.arcsin(np.sin(th))
        return self.centre + self.amp * np.exp(-t / self.decay) * np.sin(th)

    def vel(self, t):
        w = 2 * math.pi * self.freq
        th = w * t + self.phase
        if self.kind == "triangle":
            return self.amp * (2 / math.pi) * w * np.sign(np.cos(th))
        env = self.amp * np.exp(-t / self.decay)
        return env * (w * np.cos(th) - np.sin(th) / self.decay)


@dataclass(frozen=True)
class _Sweep:
    """The calibration sweep: path, duration, sampling and the history before it."""

    wave: _Wave
    duration: float
    fs: float
    v_peak: float
    rest: float
    tip_rest: float
    excursion: float | None


@dataclass(frozen=True)
class _Plant:
    """Everything drawn for one seed and family (before any noise realisation)."""

    seed: int
    family: str
    truth: KnobTruth
    drive: _Drive
    inst: _Instrument
    sweep: _Sweep
    factors: dict = field(default_factory=dict)


def _take(e, w: float, shape: str):
    """Tendon load for stretch `e`: zero below 0, a quadratic or cubic onset over `w`, slope 1."""
    e = np.maximum(e, 0.0)
    if w <= 0:
        return e
    if shape == "quadratic":
        return np.where(e < w, e * e / (2 * w), e - w / 2)
    return np.where(e < w, e ** 3 / (3 * w * w), e - 2 * w / 3)


def _ratio_pair(dr: _Draws, name: str, big: float, ratio: float) -> tuple[float, float]:
    """(pos, neg) with one of them `big` and the other big/ratio, the larger side drawn."""
    if dr.chance(f"{name}_pos_larger", 0.5):
        return big, big / ratio
    return big / ratio, big


def _draw_truth(dr: _Draws, on: dict) -> KnobTruth:
    width = dr.loguniform("dead_zone_width", 1.0, 40.0)
    if on["asymmetric"]:
        r = dr.loguniform("edge_distance_ratio", 3.0, 10.0)
        if dr.chance("edge_distance_ratio_inverted", 0.5):
            r = 1.0 / r
        d_pos = width * r / (1 + r)
    else:
        d_pos = dr.uniform("dead_zone_centre", -20.0, 20.0) + width / 2
    d_neg = d_pos - width
    big = 0.0 if dr.chance("no_backlash", 0.1) else dr.uniform("backlash_larger", 0, 1.2 * width)
    ratio = dr.loguniform("backlash_ratio", *((3.0, 10.0) if on["asymmetric"] else (1.0, 2.5)))
    b_pos, b_neg = _ratio_pair(dr, "backlash", big, ratio)
    omega = dr.loguniform("omega", 0.3, 3.0)
    h_pos = dr.uniform("h_pos", -20.0, 20.0)
    # h_neg - h_pos >= omega*(b - width) keeps dhat_pos <= d_pos and d_neg <= dhat_neg.
    gap = max(0.0, max(b_pos, b_neg) - width) + dr.uniform("height_gap_frac", 0.0, 0.3) * width
    return KnobTruth(d_pos=d_pos, d_neg=d_neg, b_pos=b_pos, b_neg=b_neg, omega=omega,
                     h_pos=h_pos, h_neg=h_pos + omega * gap)


def _draw_drive(dr: _Draws, on: dict, truth: KnobTruth) -> _Drive:
    f = dr.factors
    ratio = dr.loguniform("gain_ratio", *((3.0, 10.0) if on["asymmetric"] else (1.0, 2.5)))
    gain_pos, gain_neg = _ratio_pair(dr, "gain", dr.loguniform("gain_larger", 0.5 * ratio, 80.0),
                                     ratio)
    width = truth.d_pos - truth.d_neg
    # lead > 0: the tendon's current departs before the tip leaves its flat (travelling outwards).
    lead_pos = lead_neg = 0.0
    if on["kink-offset"]:
        lead_pos = dr.uniform("kink_lead_pos_drawn", -2.0, 2.0)
        lead_neg = dr.uniform("kink_lead_neg_drawn", -2.0, 2.0)
        inward = max(lead_pos, 0.0) + max(lead_neg, 0.0)
        room = min(width - 0.5, 0.5 * width)
        if inward > room:  # the two current edges keep at least half the dead zone between them
            lead_pos = lead_pos * room / inward if lead_pos > 0 else lead_pos
            lead_neg = lead_neg * room / inward if lead_neg > 0 else lead_neg
    f["kink_lead_pos"], f["kink_lead_neg"] = lead_pos, lead_neg
    edge_pos, edge_neg = truth.d_pos - lead_pos, truth.d_neg + lead_neg
    shape = dr.choice("take_up_shape", ("quadratic", "cubic"))
    if on["rounded"]:
        w_pos = dr.uniform("take_up_width_pos", 0.5, 5.0)
        w_neg = dr.uniform("take_up_width_neg", 0.5, 5.0)
    else:
        w_pos = w_neg = 0.0
        f["take_up_width_pos"] = f["take_up_width_neg"] = 0.0
    mode = dr.choice("current_mode", ("hold", "drop", "follow"))
    if on["load-friction"]:
        mu = dr.uniform("capstan_mu", 0.15, 0.8)
    elif mode == "drop":
        mu = dr.uniform("capstan_mu", 0.08, 0.3)
    else:
        mu = dr.uniform("capstan_mu", 0.0, 0.04)
    eps_dir = dr.loguniform("capstan_flip_deg", 0.05, 1.0)
    if mode == "follow":
        beta_pos = beta_neg = 0.0
    else:
        beta_pos = min(truth.b_pos, edge_pos - edge_neg)
        beta_neg = min(truth.b_neg, edge_pos - edge_neg)
    f["current_play_pos"], f["current_play_neg"] = beta_pos, beta_neg
    pre = 0.0
    if dr.chance("pretensioned", 0.35):
        pre = dr.uniform("pretension_frac", 0.02, 0.25) * min(gain_pos, gain_neg)
    f["pretension_slope"] = pre
    stiff = dr.uniform("stiffening", 0.0, 0.03) if dr.chance("stiffens", 0.3) else 0.0
    f["stiffening"] = stiff
    no_load = dr.uniform("no_load", -500.0, 500.0)
    coulomb = dr.uniform("motor_coulomb", 0.0, 30.0) if dr.chance("has_coulomb", 0.6) else 0.0
    v_s = dr.loguniform("motor_stribeck_speed", 0.2, 3.0)
    viscous = dr.uniform("motor_viscous", 0.0, 0.3) if dr.chance("has_viscous", 0.5) else 0.0
    sign = "magnitude" if on["magnitude"] else "signed"
    return _Drive(sign=sign, mode=mode, edge_pos=edge_pos, edge_neg=edge_neg, take_shape=shape,
                  take_w_pos=w_pos, take_w_neg=w_neg, gain_pos=gain_pos, gain_neg=gain_neg,
                  stiffening=stiff, mu=mu, eps_dir=eps_dir, beta_pos=beta_pos,
                  beta_neg=beta_neg, pretension=pre, no_load=no_load, coulomb=coulomb,
                  v_stribeck=v_s, viscous=viscous)


def _draw_sweep(dr: _Draws, on: dict, truth: KnobTruth, drive: _Drive) -> _Sweep:
    d_pos, d_neg = truth.d_pos, truth.d_neg
    width = d_pos - d_neg
    if on["wall"]:
        coverage = dr.choice("coverage", ("both",))
    else:
        coverage = dr.choice("coverage", ("both", "pos-only", "neg-only", "none"),
                             p=(0.9, 0.035, 0.035, 0.03))
    m_pos = dr.loguniform("margin_pos", 0.5, 40.0)
    m_neg = dr.loguniform("margin_neg", 0.5, 40.0)
    inside = dr.uniform("inside_frac", 0.05, 0.45)
    # The tip comes back to the other flat only once the knob is past an edge by more than the
    # flats' height gap in knob degrees: the margins count from there.
    reach = (truth.h_neg - truth.h_pos) / truth.omega
    if coverage == "both":
        q_max, q_min = d_pos + reach + m_pos, d_neg - reach - m_neg
    elif coverage == "pos-only":
        q_max, q_min = d_pos + reach + m_pos, d_neg + 2 * inside * width
    elif coverage == "neg-only":
        q_max, q_min = d_pos - 2 * inside * width, d_neg - reach - m_neg
    elif dr.chance("none_outside", 0.5):  # the sweep stays beyond one edge, never on the flat
        if dr.chance("none_outside_pos", 0.5):
            q_min = d_pos + m_pos
            q_max = q_min + m_neg + 1.0
        else:
            q_max = d_neg - m_neg
            q_min = q_max - m_pos - 1.0
    else:
        q_max, q_min = d_pos - inside * width, d_neg + inside * width
    dr.factors["sweep_max_deg"], dr.factors["sweep_min_deg"] = q_max, q_min
    kind = dr.choice("waveform", ("sine", "triangle", "decaying-sine"), p=(0.45, 0.35, 0.2))
    amp = 0.5 * (q_max - q_min)
    decay = math.inf
    if kind == "decaying-sine":
        # The envelope ends at the drawn extent, so the margins hold to the last cycle.
        amp /= dr.uniform("decay_end_frac", 0.5, 0.95)
    v_peak = dr.loguniform("peak_speed_drawn", 2.0, 150.0)
    per_cycle = 4.0 if kind == "triangle" else 2 * math.pi
    freq = min(v_peak / (per_cycle * amp), 1.0)
    v_peak = freq * per_cycle * amp
    dr.factors["peak_speed"], dr.factors["sweep_freq"] = v_peak, freq
    cycles = dr.uniform("cycles", 1.25 if coverage == "both" else 0.5, 4.0)
    duration = cycles / freq
    if kind == "decaying-sine":
        decay = duration / math.log(amp / (0.5 * (q_max - q_min)))
    fs = dr.loguniform("fs_drawn", 30.0, 5000.0)
    fs = min(max(fs, 300.0 / duration), (MAX_N - 1) / duration)
    # History: rest with both tendons slack, then maybe an excursion past an edge, then the
    # sweep's first point: anywhere on the path, or back at the rest point in the dead zone.
    rest = dr.uniform("rest_knob", *_slack_interval(truth, drive))
    tip_rest = dr.uniform("rest_tip", truth.h_pos, truth.h_neg)
    centre = 0.5 * (q_max + q_min)
    phase = dr.uniform("phase_drawn", 0.0, 2 * math.pi)
    if dr.chance("starts_at_rest_point", 0.35) and abs(rest - centre) < amp:
        x = (rest - centre) / amp
        phase = math.asin(x) if kind != "triangle" else 0.5 * math.pi * x
        if dr.chance("starts_downwards", 0.5):
            phase = math.pi - phase
    dr.factors["phase"] = phase
    wave = _Wave(kind=kind, centre=centre, amp=amp, freq=freq, phase=phase, decay=decay)
    q_start = float(wave.pos(0.0))
    history = dr.choice("history", ("rest", "pos-excursion", "neg-excursion"), p=(0.4, 0.3, 0.3))
    past = dr.uniform("excursion_past_edge", 0.5, 25.0)
    # A sweep covering one side only shows that edge in the tip when an excursion to the other
    # side has brought the tip to the near flat's height: force that history.
    if coverage in ("pos-only", "neg-only"):
        history = dr.factors["history"] = "neg-excursion" if coverage == "pos-only" \
            else "pos-excursion"
        past += reach
    excursion = None
    if history == "pos-excursion":
        excursion = max(q_start, d_pos) + past
    elif history == "neg-excursion":
        excursion = min(q_start, d_neg) - past
    return _Sweep(wave=wave, duration=duration, fs=fs, v_peak=v_peak, rest=rest,
                  tip_rest=tip_rest, excursion=excursion)


def _slack_interval(truth: KnobTruth, drive: _Drive) -> tuple[float, float]:
    """Knob angles where the tip can rest on a flat with both tendons slack (the tip's dead zone
    where the current edges leave none of it)."""
    lo, hi = max(truth.d_neg, drive.edge_neg), min(truth.d_pos, drive.edge_pos)
    return (lo, hi) if lo < hi else (truth.d_neg, truth.d_pos)


def _draw_wall(dr: _Draws, on: dict, truth: KnobTruth, drive: _Drive) -> _Drive:
    f = dr.factors
    lo, hi = f["sweep_min_deg"], f["sweep_max_deg"]
    sides = [s for s, ok in ((1, hi > truth.d_pos + PASS_MIN), (-1, lo < truth.d_neg - PASS_MIN))
             if ok]
    if not on["wall"] or not sides:
        f["wall_side"] = "none"
        return drive
    side = sides[int(dr.rng.integers(len(sides)))]
    frac = dr.uniform("wall_contact_frac", 0.4, 0.85)
    gain = dr.loguniform("wall_gain", 5.0, 30.0)
    if side > 0:
        knob = truth.d_pos + frac * (hi - truth.d_pos)
        tip = float(truth.f_up(knob))
    else:
        knob = truth.d_neg - frac * (truth.d_neg - lo)
        tip = float(truth.f_dn(knob))
    f["wall_side"], f["wall_knob"], f["wall_tip"] = ("pos" if side > 0 else "neg"), knob, tip
    return replace(drive, wall_side=side, wall_knob=knob, wall_tip=tip, wall_gain=gain)


def _draw_instrument(dr: _Draws, on: dict, sweep: _Sweep, drive: _Drive) -> _Instrument:
    f = dr.factors
    fs = sweep.fs
    jitter = dr.uniform("jitter_frac", 0.05, 0.4) / fs if dr.chance("jittered", 0.3) else 0.0
    servo, servo_time, lat_c, lat_y = "none", 0.0, 0.0, 0.0
    if on["latency"]:
        servo = dr.choice("servo", ("lag", "delay", "none"), p=(0.4, 0.3, 0.3))
        servo_time = dr.loguniform("servo_time", 0.005, 0.2)
        if servo == "none" or dr.chance("logged_late", 0.6):
            lat_c = dr.loguniform("latency_current", 0.005, 0.15)
            lat_y = dr.loguniform("latency_tip", 0.005, 0.15) if dr.chance("tip_late", 0.7) else 0.0
    f["servo"], f["servo_time"] = servo, servo_time if servo != "none" else 0.0
    f["latency_current"], f["latency_tip"] = lat_c, lat_y
    # The loaded rise each side shows at the sweep's extreme (static, no capstan, no wall).
    ext = np.array([f["sweep_max_deg"], f["sweep_min_deg"]])
    tp, tn = replace(drive, wall_side=0).tendon_loads(ext, ext)
    rise_pos = float(drive.gain_pos * tp[0])
    rise_neg = float(drive.gain_neg * tn[1])
    f["rise_pos"], f["rise_neg"] = rise_pos, rise_neg
    if on["weak-current"]:
        weak = dr.choice("weak_side", ("pos", "neg", "both"))
        target = dr.uniform("weak_rise_sigmas", 1.5, 3.0)
        rise = {"pos": rise_pos, "neg": rise_neg, "both": max(rise_pos, rise_neg)}[weak]
        rise = rise if rise > 0 else max(rise_pos, rise_neg)
    else:
        rise = max(rise_pos, rise_neg)
        target = dr.loguniform("rise_sigmas_drawn", 3.0, 300.0)
    fallback = dr.loguniform("sigma_if_no_rise", 0.3, 10.0)
    sigma_c = max(rise / target if rise > 0 else fallback, 0.01)
    f["sigma_current"] = sigma_c
    f["rise_sigma_pos"], f["rise_sigma_neg"] = rise_pos / sigma_c, rise_neg / sigma_c
    sigma_y = dr.loguniform("sigma_tip", 0.005, 0.2)
    col_frac, taus, sigma_y_col = 0.0, (), 0.0
    if on["coloured"]:
        col_frac = dr.uniform("coloured_variance_frac", 0.6, 1.0)
        tau = dr.loguniform("coloured_tau", 0.005, 0.5)
        if dr.choice("coloured_kind", ("ar1", "pink")) == "ar1":
            taus = (tau,)
        else:  # equal variance per AR(1) with log-spaced times: about 1/f between them
            taus = tuple(float(x) for x in np.geomspace(tau, min(30 * tau, 0.5), 4))
        sigma_y_col = dr.uniform("sigma_tip_coloured_ratio", 0.5, 2.0) * sigma_y
    f["coloured_taus"] = ",".join(f"{t:.4g}" for t in taus)
    drift_c = drift_y = 0.0
    if on["drift"]:
        drift_c = dr.loguniform("drift_current_abs", 2.0, 60.0) * (
            1 if dr.chance("drift_current_up", 0.5) else -1)
        drift_y = dr.loguniform("drift_tip_abs", 0.05, 2.0) * (
            1 if dr.chance("drift_tip_up", 0.5) else -1)
    f["drift_current"], f["drift_tip"] = drift_c, drift_y
    drift_shape = dr.choice("drift_shape", ("linear", "exponential"))
    drift_tau = dr.uniform("drift_tau_frac", 0.2, 2.0)
    outlier_rate = dr.loguniform("outlier_rate", 1e-4, 3e-3) if dr.chance("outliers", 0.3) else 0.0
    outlier_mag = dr.uniform("outlier_sigmas", 5.0, 30.0) * sigma_c
    stiction = dr.uniform("stiction_sigmas", 1.0, 6.0) * sigma_c if dr.chance("stiction", 0.35) \
        else 0.0
    stiction_tau = dr.uniform("stiction_tau", 0.01, 0.1)
    cog = dr.uniform("cogging_sigmas", 0.3, 2.0) * sigma_c if dr.chance("cogging", 0.3) else 0.0
    cog_period = dr.loguniform("cogging_period_deg", 0.2, 5.0)
    cog_phase = dr.uniform("cogging_phase", 0.0, 2 * math.pi)
    lsb_c = dr.loguniform("lsb_current_sigmas", 0.1, 2.0) * sigma_c \
        if dr.chance("quantised_current", 0.5) else 0.0
    lsb_y = dr.loguniform("lsb_tip", 0.001, 0.05) if dr.chance("quantised_tip", 0.3) else 0.0
    filter_c = dr.chance("lowpass_current", 0.5)
    filter_y = dr.chance("lowpass_tip", 0.3)
    f["outlier_rate"], f["stiction_amp"], f["cogging_amp"] = outlier_rate, stiction, cog
    f["lsb_current"], f["lsb_tip"] = lsb_c, lsb_y
    return _Instrument(fs=fs, jitter=jitter, servo=servo, servo_time=servo_time, lat_c=lat_c,
                       lat_y=lat_y, sigma_c=sigma_c, col_frac_c=col_frac, col_taus=taus,
                       sigma_y=sigma_y, sigma_y_col=sigma_y_col, drift_c=drift_c,
                       drift_y=drift_y, drift_shape=drift_shape, drift_tau_frac=drift_tau,
                       outlier_rate=outlier_rate, outlier_mag=outlier_mag, stiction_amp=stiction,
                       stiction_tau=stiction_tau, cog_amp=cog, cog_period=cog_period,
                       cog_phase=cog_phase, lsb_c=lsb_c, lsb_y=lsb_y, filter_c=filter_c,
                       filter_y=filter_y)


def _family(family: str | None, rngs) -> str:
    if family is None:
        return FAMILIES[int(rngs[_STREAM_FAMILY].integers(len(FAMILIES)))]
    if family not in FAMILIES:
        raise ValueError(f"unknown family {family!r}; known: {', '.join(FAMILIES)}")
    return family


def _draw_plant(seed: int, family: str | None) -> tuple[_Plant, list]:
    rngs = _rngs(seed)
    family = _family(family, rngs)
    rng = rngs[_STREAM_PLANT]
    factors: dict = {"family": family}
    mixed = rng.random(len(FAMILIES)) < MIX
    on = {b: b == family or bool(m) for b, m in zip(FAMILIES, mixed)}
    factors["breaks"] = ",".join(b for b in FAMILIES if on[b])
    dr = _Draws(rng, factors)
    truth = _draw_truth(dr, on)
    drive = _draw_drive(dr, on, truth)
    sweep = _draw_sweep(dr, on, truth, drive)
    drive = _draw_wall(dr, on, truth, drive)
    inst = _draw_instrument(dr, on, sweep, drive)
    factors.update(current_sign=drive.sign, current_edge_pos=drive.edge_pos,
                   current_edge_neg=drive.edge_neg,
                   current_knee_pos=drive.edge_pos + _knee(drive.take_w_pos, drive.take_shape),
                   current_knee_neg=drive.edge_neg - _knee(drive.take_w_neg, drive.take_shape),
                   current_shows_backlash=bool(drive.beta_pos > 0 or drive.beta_neg > 0),
                   gain_pos=drive.gain_pos, gain_neg=drive.gain_neg, no_load=drive.no_load)
    plant = _Plant(seed=int(seed), family=family, truth=truth, drive=drive, inst=inst,
                   sweep=sweep, factors=factors)
    return plant, rngs


def _knee(w: float, shape: str) -> float:
    """Where the loaded line's extension meets zero load, measured from the departure point."""
    return w / 2 if shape == "quadratic" else 2 * w / 3


# --------------------------------------------------------------------------- simulation engine


def _params(truth: KnobTruth, drive: _Drive, inst: _Instrument, offset: float,
            ideal: bool) -> np.ndarray:
    """Kernel parameters; `ideal` leaves out the servo lag and the stiction bursts."""
    prm = np.zeros(K.N_PRM)
    prm[K.P_OFFSET] = offset
    prm[K.P_D_POS], prm[K.P_D_NEG] = truth.d_pos, truth.d_neg
    prm[K.P_DHAT_POS], prm[K.P_DHAT_NEG] = truth.dhat_pos, truth.dhat_neg
    prm[K.P_OMEGA], prm[K.P_H_POS], prm[K.P_H_NEG] = truth.omega, truth.h_pos, truth.h_neg
    prm[K.P_WALL_SIDE], prm[K.P_WALL_Y] = drive.wall_side, drive.wall_tip
    prm[K.P_BETA_POS], prm[K.P_BETA_NEG] = drive.beta_pos, drive.beta_neg
    prm[K.P_EPS_DIR] = drive.eps_dir
    if not ideal:
        prm[K.P_SERVO_TAU] = inst.servo_time if inst.servo == "lag" else 0.0
        prm[K.P_STICTION_AMP] = inst.stiction_amp
        prm[K.P_STICTION_TAU] = inst.stiction_tau
    return prm


def _walk(plant: _Plant, st: np.ndarray, path) -> None:
    """Move the straight-shaft plant quasi-statically through the knob angles `path`.

    The state's recursions are rate-independent, so the path's corners are all it needs.
    """
    path = np.asarray(path, dtype=float)
    zeros = np.zeros_like(path)
    K.advance(zeros + st[K.S_T], path, zeros, st,
              _params(plant.truth, plant.drive, plant.inst, 0.0, ideal=True))


def _rest_state(rest: float, tip: float) -> np.ndarray:
    st = np.zeros(K.N_STATE)
    st[K.S_Q] = st[K.S_ZP] = st[K.S_ZN] = rest
    st[K.S_Y] = tip
    return st


def _start_state(plant: _Plant, st: np.ndarray) -> str:
    """The tendon that carries load, else the side the tip is held on, else 'slack'."""
    tp, tn = plant.drive.tendon_loads(st[K.S_ZP], st[K.S_ZN])
    y = st[K.S_Y]
    if tp > 0:
        return "pos-taut"
    if tn > 0:
        return "neg-taut"
    if y > plant.truth.h_neg + _TOL:
        return "pos-taut"
    if y < plant.truth.h_pos - _TOL:
        return "neg-taut"
    return "slack"


class _Trace:
    """Time series kept to read values at earlier instants (delays), trimmed to `keep` s."""

    def __init__(self, keep: float | None):
        self.keep = keep
        self.t = np.empty(0)
        self.cols: dict[str, np.ndarray] = {}

    def append(self, t: np.ndarray, **cols: np.ndarray) -> None:
        if self.keep is not None and self.t.size:
            cut = np.searchsorted(self.t, t[0] - self.keep)
            cut = min(cut, self.t.size - 1)
            self.t = self.t[cut:]
            self.cols = {k: v[cut:] for k, v in self.cols.items()}
        self.t = np.concatenate([self.t, t])
        for k, v in cols.items():
            self.cols[k] = np.concatenate([self.cols.get(k, np.empty(0)), v])

    def at(self, name: str, t: np.ndarray) -> np.ndarray:
        return np.interp(t, self.t, self.cols[name])


class _Noise:
    """White plus AR(1) components, continued across calls (for a live plant's chunks)."""

    def __init__(self, rng: np.random.Generator, sigma: float, col_frac: float, taus: tuple):
        self.rng = rng
        var_col = col_frac * sigma * sigma
        self.sigma_white = math.sqrt(max(sigma * sigma - var_col, 0.0))
        self.taus = taus
        self.sigma_comp = math.sqrt(var_col / len(taus)) if taus else 0.0
        self.state = [self.sigma_comp * float(rng.standard_normal()) for _ in taus]

    def draw(self, n: int, dt: float) -> np.ndarray:
        x = self.sigma_white * self.rng.standard_normal(n)
        for k, tau in enumerate(self.taus):
            a = math.exp(-dt / tau)
            e = self.sigma_comp * math.sqrt(1 - a * a) * self.rng.standard_normal(n)
            comp, _ = signal.lfilter([1.0], [1.0, -a], e, zi=[a * self.state[k]])
            self.state[k] = float(comp[-1])
            x += comp
        return x


def _ramp(t: np.ndarray, inst: _Instrument, t_ref: float) -> np.ndarray:
    """Drift's shape: 0 at t = 0, 1 at `t_ref` (a record's end), linear (then flat) or
    exponential."""
    if inst.drift_shape == "linear":
        return np.minimum(t / t_ref, 1.0)
    tau = inst.drift_tau_frac * t_ref
    return -np.expm1(-t / tau) / -math.expm1(-t_ref / tau)


def _quantise(x: np.ndarray, lsb: float) -> np.ndarray:
    return np.round(x / lsb) * lsb if lsb > 0 else x


class _Engine:
    """The plant integrated chunk by chunk and read through the instrument.

    Parameters
    ----------
    plant : _Plant
    st : ndarray
        Kernel state to start from (copied).
    offset : float
        The shaft bend's shift of the loop.
    rng : numpy.random.Generator
        The noise stream of this run.
    noiseless : bool
        Ideal instrument (see the module docstring).
    t_ref : float
        Time over which drift develops.
    keep : float or None
        Seconds of history to keep (None: all, for a whole record in one chunk).
    """

    def __init__(self, plant: _Plant, st: np.ndarray, offset: float, rng: np.random.Generator,
                 noiseless: bool, t_ref: float, keep: float | None = None):
        self.inst = plant.inst
        self.drive = plant.drive
        self.offset = offset
        self.st = st.copy()
        self.noiseless = noiseless
        self.t_ref = t_ref
        self.rng = rng
        self.prm = _params(plant.truth, plant.drive, plant.inst, offset, ideal=noiseless)
        self.cmd = _Trace(keep)
        self.out = _Trace(keep)
        if not noiseless:
            self.noise_c = _Noise(rng, self.inst.sigma_c, self.inst.col_frac_c, self.inst.col_taus)
            col_frac_y = (self.inst.sigma_y_col ** 2
                          / (self.inst.sigma_y ** 2 + self.inst.sigma_y_col ** 2))
            self.noise_y = _Noise(rng, math.hypot(self.inst.sigma_y, self.inst.sigma_y_col),
                                  col_frac_y, self.inst.col_taus)

    def run(self, t: np.ndarray, q_cmd: np.ndarray, v_cmd: np.ndarray) -> None:
        """Integrate the plant over commanded points and keep what the instrument reads."""
        if not self.noiseless and self.inst.servo == "delay":
            self.cmd.append(t, q=q_cmd, v=v_cmd)
            q_cmd = self.cmd.at("q", t - self.inst.servo_time)
            v_cmd = self.cmd.at("v", t - self.inst.servo_time)
        out = K.advance(t, q_cmd, v_cmd, self.st, self.prm)
        q_act, v, y, zp, zn, s, burst = out
        dev = self.drive.deviation(q_act - self.offset, v, zp, zn, s)
        nuisance = burst
        if self.inst.cog_amp > 0:
            nuisance = nuisance + self.inst.cog_amp * np.sin(
                2 * math.pi * q_act / self.inst.cog_period + self.inst.cog_phase)
        self.out.append(t, dev=dev, nuisance=nuisance, y=y)

    def read(self, t: np.ndarray, offline: bool) -> tuple[np.ndarray, np.ndarray]:
        """Current (mA) and tip (deg) logged at the instants `t`."""
        inst, c0 = self.inst, self.drive.no_load
        if self.noiseless:
            dev = self.out.at("dev", t)
            c = c0 + (np.abs(dev) if self.drive.sign == "magnitude" else dev)
            return c, self.out.at("y", t)
        n = t.size
        dt = float(np.mean(np.diff(t))) if n > 1 else 1.0 / inst.fs
        x = self.out.at("dev", t - inst.lat_c) + self.out.at("nuisance", t - inst.lat_c)
        x = x + self.noise_c.draw(n, dt)
        y = self.out.at("y", t - inst.lat_y) + self.noise_y.draw(n, dt)
        if offline and 1.0 / dt > 60.0:
            sos = signal.butter(3, 20.0, fs=1.0 / dt, output="sos")
            if inst.filter_c:
                x = signal.sosfiltfilt(sos, x)
            if inst.filter_y:
                y = signal.sosfiltfilt(sos, y)
        hits = self.rng.random(n) < inst.outlier_rate
        x = x + hits * inst.outlier_mag * self.rng.choice((-1.0, 1.0), n)
        ramp = _ramp(t, inst, self.t_ref)
        level = c0 + inst.drift_c * ramp
        if self.drive.sign == "magnitude":
            c = level + _quantise(np.abs(x), inst.lsb_c)
        else:
            c = _quantise(level + x, inst.lsb_c)
        y = _quantise(y + inst.drift_y * ramp, inst.lsb_y)
        return c, y


def _record(columns: dict, meta: dict, knob: int, tip: bool) -> Record:
    cols = {"t": columns["t"], f"q{knob}": columns["q"]}
    if tip:
        cols[f"y{knob}"] = columns["y"]
    cols[f"c{knob}"] = columns["c"]
    return Record(columns=cols, meta={k: str(v) for k, v in meta.items()})


def _run_record(plant: _Plant, st: np.ndarray, wave: _Wave, duration: float, fs: float,
                v_peak: float, offset: float, rng: np.random.Generator, noiseless: bool):
    """Record one run of `wave` from state `st`; returns columns, run factors and final state."""
    inst = plant.inst
    n = int(math.floor(duration * fs)) + 1
    t = np.arange(n) / fs
    jit = rng.uniform(-inst.jitter, inst.jitter, n) if inst.jitter > 0 else np.zeros(n)
    jit[0] = 0.0
    t = t + jit
    step = min(1.0 / fs, MAX_STEP_DEG / max(v_peak, 1e-9))
    t_dense = np.arange(int(math.ceil(t[-1] / step)) + 2) * step
    # Which tip edges the command passes, judged on the dense path so it does not depend on
    # the sampling or the instrument.
    _, passes_pos, passes_neg = _clamp(plant.truth, wave.pos(t_dense) - offset, st[K.S_Y])
    factors = {"fs": float(fs), "n": int(n), "duration": float(t[-1]),
               "tip_before": float(st[K.S_Y]), "start_state": _start_state(plant, st),
               "passes_pos_edge": bool(passes_pos), "passes_neg_edge": bool(passes_neg)}
    eng = _Engine(plant, st, offset, rng, noiseless, t_ref=max(float(t[-1]), 1e-9))
    t_phys = t if noiseless else t_dense
    eng.run(t_phys, wave.pos(t_phys), wave.vel(t_phys))
    c, y = eng.read(t, offline=True)
    columns = {"t": t, "q": wave.pos(t), "y": y, "c": c}
    return columns, factors, eng.st


def _meta(seed: int, case: str, knob: int) -> dict:
    return {"source": "bench.plants.wild", "case": case, "seed": seed, "knob": knob,
            "units": "t s, q deg, y deg, c mA"}


def _straight(plant: _Plant, rngs, noiseless: bool):
    sw = plant.sweep
    st = _rest_state(sw.rest, sw.tip_rest)
    q0 = float(sw.wave.pos(0.0))
    _walk(plant, st, [sw.rest] + ([sw.excursion] if sw.excursion is not None else []) + [q0])
    st[K.S_T] = 0.0
    return _run_record(plant, st, sw.wave, sw.duration, sw.fs, sw.v_peak, 0.0,
                       rngs[_STREAM_SWEEP_NOISE], noiseless)


def sweep_case(seed: int, family: str | None = None, *, knob: int = 1, tip: bool = True,
               noiseless: bool = False) -> SweepCase:
    """A calibration sweep of the plant drawn for `seed` (and `family`, else drawn from the seed).

    Parameters
    ----------
    seed : int
        Non-negative seed; the same arguments give the same bytes.
    family : str or None
        One of `FAMILIES`, or None to draw it from the seed.
    knob : int
        Knob number used in the column names.
    tip : bool
        Whether the record has the tracker's tip column.
    noiseless : bool
        Ideal instrument on the same plant and path.

    Returns
    -------
    SweepCase
    """
    plant, rngs = _draw_plant(seed, family)
    columns, run, _ = _straight(plant, rngs, noiseless)
    factors = {**plant.factors, **run, "noiseless": bool(noiseless)}
    return SweepCase(seed=plant.seed, family=plant.family, truth=plant.truth,
                     record=_record(columns, _meta(plant.seed, "sweep", knob), knob, tip),
                     factors=factors)


def _cycle(n: int, seed: int, families) -> list[tuple[int, str]]:
    fams = tuple(FAMILIES if families is None else families)
    if not fams:
        raise ValueError("families must not be empty")
    return [(seed + i, fams[i % len(fams)]) for i in range(n)]


def sweep_cases(n: int, seed: int = 0, families=None, **kw) -> list[SweepCase]:
    """`n` sweep cases with seeds seed, seed+1, ... and the families cycled."""
    return [sweep_case(s, f, **kw) for s, f in _cycle(n, seed, families)]


def replay_case(seed: int, family: str | None = None, *, knob: int = 1,
                noiseless: bool = False) -> ReplayCase:
    """The plant and straight sweep of `sweep_case(seed, family)`, then a replay on a bent shaft.

    After the sweep the knob returns to rest (0), the shaft bends by a drawn offset (-30..30 deg,
    exactly 0 in about 10 % of cases) acting on the state as a knob motion u: 0 -> -offset, and a
    slow replay (2-25 deg/s, 0.5-2 cycles, amplitude 5-70 deg, either direction first) is
    recorded from rest at knob 0.
    """
    plant, rngs = _draw_plant(seed, family)
    columns, run, st = _straight(plant, rngs, noiseless)
    factors = {**plant.factors, **run, "noiseless": bool(noiseless)}
    dr = _Draws(rngs[_STREAM_REPLAY], factors)
    offset = 0.0 if dr.chance("offset_zero", 0.1) else dr.uniform("offset_drawn", -30.0, 30.0)
    factors["offset"] = offset
    speed = dr.uniform("replay_speed", 2.0, 25.0)
    cycles = dr.uniform("replay_cycles", 0.5, 2.0)
    amp = dr.uniform("replay_amplitude", 5.0, 70.0)
    first = dr.choice("replay_first", ("up", "down"))
    wave = _Wave(kind="sine", centre=0.0, amp=amp if first == "up" else -amp,
                 freq=speed / (2 * math.pi * amp), phase=0.0)
    duration = cycles / wave.freq
    fs = min(max(plant.inst.fs, 300.0 / duration), (MAX_N - 1) / duration)
    _walk(plant, st, [st[K.S_Q], 0.0, -offset])  # back to rest, then the bend
    st[K.S_Q], st[K.S_T], st[K.S_BURST] = 0.0, 0.0, 0.0
    rcols, rrun, _ = _run_record(plant, st, wave, duration, fs, speed, offset,
                                 rngs[_STREAM_REPLAY_NOISE], noiseless)
    factors.update({f"replay_{k}": v for k, v in rrun.items()})
    factors["replay_current_edge_pos"] = plant.drive.edge_pos + offset
    factors["replay_current_edge_neg"] = plant.drive.edge_neg + offset
    return ReplayCase(seed=plant.seed, family=plant.family, truth=plant.truth, offset=offset,
                      straight_sweep=_record(columns, _meta(plant.seed, "sweep", knob), knob,
                                             True),
                      replay=_record(rcols, _meta(plant.seed, "replay", knob), knob, True),
                      factors=factors)


def replay_cases(n: int, seed: int = 0, families=None, **kw) -> list[ReplayCase]:
    """`n` replay cases with seeds seed, seed+1, ... and the families cycled."""
    return [replay_case(s, f, **kw) for s, f in _cycle(n, seed, families)]


# --------------------------------------------------------------------------- live plant


class LivePlant:
    """The plant stepped move by move, as a robot drives it.

    At construction it has made a random excursion, returned to knob 0 and been bent by
    `offset`; it then rests at knob 0 with one reading taken. Times start at 0 and advance with
    every sample; drift reaches its drawn amount at `LIVE_T_REF` seconds.
    """

    def __init__(self, plant: _Plant, rng: np.random.Generator, offset: float, knob: int,
                 noiseless: bool):
        self.knob = knob
        self.knobs = (knob,)
        self.truth = plant.truth.shifted(offset)
        truth = plant.truth
        rest = float(rng.uniform(*_slack_interval(truth, plant.drive)))
        st = _rest_state(rest, float(rng.uniform(truth.h_pos, truth.h_neg)))
        excursion = float(rng.uniform(truth.d_neg - 25.0, truth.d_pos + 25.0))
        _walk(plant, st, [rest, excursion, 0.0, -offset])
        st[K.S_Q], st[K.S_T] = 0.0, 0.0
        keep = 1.0 + plant.inst.lat_c + plant.inst.lat_y + plant.inst.servo_time
        self._eng = _Engine(plant, st, offset, rng, noiseless, t_ref=LIVE_T_REF, keep=keep)
        self._t = 0.0
        self._q = 0.0
        self._last = (np.empty(0), np.empty(0))
        self._reading = (0.0, 0.0, 0.0)
        self._step(np.array([0.0]), np.array([0.0]), 0.0)

    def _check(self, knob: int) -> None:
        if knob not in self.knobs:
            raise ValueError(f"no knob {knob}; this plant has knobs {self.knobs}")

    def _step(self, t: np.ndarray, q: np.ndarray, v: float) -> None:
        self._eng.run(t, q, np.full(t.size, v))
        c, y = self._eng.read(t, offline=False)
        self._t, self._q = float(t[-1]), float(q[-1])
        self._last = (q, c)
        self._reading = (float(q[-1]), float(c[-1]), float(y[-1]))

    def move(self, knob: int, q_target: float, speed_deg_s: float = 20.0,
             dt: float = 0.001) -> tuple[float, float, float]:
        """Drive `knob` to `q_target` at `speed_deg_s`, sampling every `dt` s.

        Returns
        -------
        tuple of float
            The last reading: logged knob angle, current (mA), tip (deg).
        """
        self._check(knob)
        if not (math.isfinite(q_target) and math.isfinite(speed_deg_s) and speed_deg_s > 0
                and math.isfinite(dt) and dt > 0):
            raise ValueError("move needs a finite target, speed > 0 and dt > 0")
        dist = q_target - self._q
        steps = max(1, int(math.ceil(abs(dist) / (speed_deg_s * dt))))
        k = np.arange(1, steps + 1)
        q = self._q + dist * k / steps
        q[-1] = q_target
        self._step(self._t + k * dt, q, math.copysign(speed_deg_s, dist) if dist else 0.0)
        return self._reading

    def hold(self, duration: float, dt: float = 0.001) -> None:
        """Keep the knob still for `duration` s, sampling every `dt` s."""
        if not (math.isfinite(duration) and duration >= 0 and math.isfinite(dt) and dt > 0):
            raise ValueError("hold needs a duration >= 0 and dt > 0")
        steps = max(1, int(math.ceil(duration / dt)))
        k = np.arange(1, steps + 1)
        self._step(self._t + k * dt, np.full(steps, self._q), 0.0)

    def state(self, knob: int) -> tuple[float, float, float]:
        """The last reading of `knob`: logged knob angle, current (mA), tip (deg)."""
        self._check(knob)
        return self._reading

    def last_samples(self, knob: int) -> tuple[np.ndarray, np.ndarray]:
        """Logged knob angles and currents of the last move (or hold)."""
        self._check(knob)
        return self._last[0].copy(), self._last[1].copy()

    def true_tip(self, knob: int) -> float:
        """The tip's physical angle now (no tracker noise, delay or drift)."""
        self._check(knob)
        return float(self._eng.st[K.S_Y])


def live_plant(seed: int, family: str | None = None, *, offset: float = 0.0, knob: int = 1,
               noiseless: bool = False) -> tuple[LivePlant, KnobTruth]:
    """The plant of `sweep_case(seed, family)` as a live plant bent by `offset`.

    Returns
    -------
    plant : LivePlant
    truth : KnobTruth
        The knob's truth with its loop at `offset` (the plant as it is now).
    """
    if not math.isfinite(offset):
        raise ValueError(f"offset must be finite, got {offset!r}")
    plant, rngs = _draw_plant(seed, family)
    live = LivePlant(plant, rngs[_STREAM_LIVE], float(offset), knob, noiseless)
    return live, live.truth
