"""The unmodelled effects of the zoo catheters, each written from its physics in several forms.

Written from docs/design.md sections 2, 3 and 8 and the paper alone; imports numpy, scipy and the
zoo's own kernel. Nothing here knows how the tool under test models these effects.

Every form has one *strength scalar* (``STRENGTH_KEY``): the catheter builder draws the form's
other constants, then solves the scalar so that the effect changes the tip by a drawn amount
(see ``VISIBLE``) on the runs where its driver acts. Where an effect acts:

``static``  (per run, from the shaft shape and the stated load): friction, deadzone, stretch
``input``   (on the knob command before the hysteresis): lag (input side), viscous backlash
``kernel``  (inside the clamp recursion, sample by sample): coupling on the input / dead zone
``output``  (on the tip after the hysteresis, in this order): coupling on the output,
            saturation, creep, lag (output side), latency

Forms (y: tip angle from the hysteresis, q: knob command, kappa: total shaft curvature in rad,
p: the bend projected on the knob's axis, L: the run's load in %, L0: the sweep's):

coupling (shared backbone / handle; both directions, the reverse ``back_ratio`` times as strong)
    output-angle      y_i += k y_j                     (tendon routing cross-talk)
    output-magnitude  y_i += k |y_j|                   (backbone shortening drags the tip)
    input-angle       loop i slides by k y_j           (the other bend pulls tendon i)
    input-magnitude   loop i slides by k |y_j|
    input-command     loop i slides by k q_j           (coaxial knobs drag each other's spool)
    deadzone-width    dead zone i widens by k |y_j| per side (narrows when k < 0)
lag (viscous tendon/sheath, motor servo, tip or tracker dynamics)
    input-first / input-second    the knob's effective position lags the command (1st order
                                  tau, or 2nd order with the same low-frequency delay tau_eq)
    output-first / output-second  the reported tip lags the bend
    viscous-backlash              both backlash widths grow by c_visc |dq/dt|
creep (viscoelastic bending section; fraction f, time constants tau)
    kelvin            y + f (LP_tau(y) - y): part of a new bend arrives at once, the rest creeps in
    prony             two such terms (fast and slow)
    relaxation        y - f (LP_tau(y) - y): the tip overshoots and relaxes back
    loaded            only the bend the tendons hold (beyond the plateau band) creeps
friction (tendon-sheath capstan friction against kappa; never a plain exponential)
    linear, saturating, quadratic: backlash times g(kappa) = 1 + a kappa, 1 + a k0 (1 - e^-kappa/k0),
                      1 + a kappa^2; slope divided by 1 + slope_ratio (g - 1)
    width-only        backlash + a_deg kappa
    slope-only        slope / (1 + c kappa)
deadzone (the shape changes the dead zone beyond the paper's shift)
    widen             both edges out by a_deg kappa;  widen-saturating: a_deg k0 (1 - e^-kappa/k0)
    narrow            both edges in (the bend takes up slack, at most half the width)
    centre            both edges move by +-a_deg kappa (a shift the stated offset misses)
    one-edge          only the edge on the side of p moves out, by a_deg |p|
saturation (the bending section stiffens near its largest bend; static, on the tip)
    tanh, hard (clip), asymmetric (one side limits at y_max, the other at other_ratio y_max),
    knee (slope_after beyond y_knee), rational (y / (1 + (|y|/y_max)^n)^(1/n))
stretch (a steady load stretches the cable; compliance in knob deg per % of load)
    linear            the loop slides by +-compliance (L - L0)
    stiffening        the same with a cable that stiffens: load_scale ln(1 + L/load_scale)
    outward, outward-stiffening: the loaded tendon on either side stretches: edges move out
latency (the tracker reports late)
    pure              y(t - delay);   frame-hold: also held frame by frame at frame_rate
"""
from __future__ import annotations

import math

import numpy as np
from scipy import signal

from . import catheters_kernel as _ck

EFFECTS: tuple[str, ...] = ("coupling", "lag", "creep", "friction", "deadzone", "saturation",
                            "stretch", "latency")

FORMS: dict[str, tuple[str, ...]] = {
    "coupling": ("output-angle", "output-magnitude", "input-angle", "input-magnitude",
                 "input-command", "deadzone-width"),
    "lag": ("input-first", "input-second", "output-first", "output-second", "viscous-backlash"),
    "creep": ("kelvin", "prony", "relaxation", "loaded"),
    "friction": ("linear", "saturating", "quadratic", "width-only", "slope-only"),
    "deadzone": ("widen", "widen-saturating", "narrow", "centre", "one-edge"),
    "saturation": ("tanh", "hard", "asymmetric", "knee", "rational"),
    "stretch": ("linear", "stiffening", "outward", "outward-stiffening"),
    "latency": ("pure", "frame-hold"),
}

STRENGTHS: tuple[str, ...] = ("weak", "mid", "strong")

# RMS change of the tip (deg) the builder aims at, on the runs where the effect's driver acts
VISIBLE: dict[str, tuple[float, float]] = {"weak": (0.9, 1.5), "mid": (2.0, 3.2),
                                           "strong": (4.0, 7.0)}

# the runs an effect is seen on: curvature-driven effects on bent runs, load-driven on runs whose
# load differs from the reference, coupling on runs that move both knobs, the rest on every run
DRIVER: dict[str, str] = {"coupling": "both", "friction": "bent", "deadzone": "bent",
                          "stretch": "load", "lag": "any", "creep": "any", "saturation": "any",
                          "latency": "any"}

# strength scalar per (effect, form): name in params, search range, True if the effect grows with it
STRENGTH_KEY: dict[tuple[str, str], tuple[str, float, float, bool]] = {
    ("coupling", "output-angle"): ("k", 0.002, 0.6, True),
    ("coupling", "output-magnitude"): ("k", 0.002, 0.6, True),
    # a shift driven by the other bend feeds back (loop gain omega^2 k^2 back_ratio): kept < 0.4
    ("coupling", "input-angle"): ("k", 0.002, 0.3, True),
    ("coupling", "input-magnitude"): ("k", 0.002, 0.3, True),
    ("coupling", "input-command"): ("k", 0.002, 0.6, True),
    ("coupling", "deadzone-width"): ("k", 0.002, 0.8, True),
    ("lag", "input-first"): ("tau", 0.003, 3.0, True),
    ("lag", "output-first"): ("tau", 0.003, 3.0, True),
    ("lag", "input-second"): ("tau_eq", 0.003, 3.0, True),
    ("lag", "output-second"): ("tau_eq", 0.003, 3.0, True),
    ("lag", "viscous-backlash"): ("c_visc", 0.002, 3.0, True),
    **{("creep", f): ("fraction", 0.1, 0.4, True) for f in FORMS["creep"]},
    ("friction", "linear"): ("a", 0.003, 4.0, True),
    ("friction", "saturating"): ("a", 0.003, 4.0, True),
    ("friction", "quadratic"): ("a", 0.003, 4.0, True),
    ("friction", "width-only"): ("a_deg", 0.03, 40.0, True),
    ("friction", "slope-only"): ("c", 0.003, 4.0, True),
    **{("deadzone", f): ("a_deg", 0.03, 40.0, True) for f in FORMS["deadzone"]},
    ("saturation", "tanh"): ("y_max", 12.0, 3000.0, False),
    ("saturation", "hard"): ("y_max", 12.0, 3000.0, False),
    ("saturation", "asymmetric"): ("y_max", 12.0, 3000.0, False),
    ("saturation", "rational"): ("y_max", 12.0, 3000.0, False),
    ("saturation", "knee"): ("y_knee", 5.0, 3000.0, False),
    **{("stretch", f): ("compliance", 2e-4, 0.6, True) for f in FORMS["stretch"]},
    ("latency", "pure"): ("delay", 0.003, 2.0, True),
    ("latency", "frame-hold"): ("delay", 0.001, 2.0, True),
}

# creep time constants per strength (s): a slow creep of a given fraction moves the tip more
_CREEP_TAU = {"weak": (0.5, 1.2), "mid": (1.0, 4.0), "strong": (2.0, 20.0)}


def draw_form_params(rng, name: str, form: str, strength: str) -> dict:
    """The form's constants other than its strength scalar (a fixed draw order per effect)."""
    u = [float(x) for x in rng.random(6)]        # always six draws: the order never depends on form
    sign = 1.0 if u[0] < 0.5 else -1.0
    p: dict = {}
    if name == "coupling":
        # how strongly knob 1 acts on knob 2, relative to knob 2 on knob 1 (k)
        p["back_ratio"] = 0.5 + 0.8 * u[1]
        if form == "deadzone-width":
            # mostly more slack, sometimes less (but there is only so much slack to take up:
            # a strong one always adds slack)
            sign = 1.0 if (u[0] < 0.75 or strength == "strong") else -1.0
        p["sign"] = sign
    elif name == "lag":
        p["knob2_ratio"] = 0.8 + 0.45 * u[1]
        if form.endswith("second"):
            p["zeta"] = 0.35 + 0.65 * u[2]
        if form == "viscous-backlash":
            p["speed_smoothing"] = 0.05
    elif name == "creep":
        lo, hi = _CREEP_TAU[strength]
        p["tau"] = float(math.exp(math.log(lo) + (math.log(hi) - math.log(lo)) * u[1]))
        if form == "prony":
            # a fast and a slow relaxation of the backbone (two Kelvin elements in series)
            p["tau_fast"] = max(0.5, p["tau"] * (0.25 + 0.35 * u[2]))
            p["tau_slow"] = min(20.0, p["tau"] * (2.0 + 3.0 * u[3]))
            p["split"] = 0.3 + 0.4 * u[4]       # share of the fraction on the fast term
            del p["tau"]
    elif name == "friction":
        p["slope_ratio"] = 0.3 + 0.7 * u[1]     # how much of the capstan factor shows as slope
        if form == "saturating":
            p["kappa0"] = 0.4 + 0.6 * u[2]      # rad of total curvature to saturate
        p["knob2_ratio"] = 0.8 + 0.4 * u[3]
    elif name == "deadzone":
        if form == "widen-saturating":
            p["kappa0"] = 0.4 + 0.6 * u[2]
        if form == "centre":
            p["sign"] = sign
        p["knob2_ratio"] = 0.8 + 0.4 * u[3]
    elif name == "saturation":
        if form == "asymmetric":
            p["side"] = sign                    # the side that stiffens first
            p["other_ratio"] = 1.8 + 2.2 * u[2]  # the other side's limit, times y_max
        if form == "knee":
            p["slope_after"] = 0.2 + 0.4 * u[2]
        if form == "rational":
            p["order"] = 2.0 + 2.0 * u[2]
        p["knob2_ratio"] = 0.85 + 0.3 * u[3]
    elif name == "stretch":
        p["sign"] = sign
        p["knob2_ratio"] = 0.7 + 0.6 * u[1]
        if form.endswith("stiffening"):
            p["load_scale"] = 15.0 + 30.0 * u[2]  # % of load over which the cable stiffens
    elif name == "latency":
        if form == "frame-hold":
            p["frame_rate"] = 10.0 + 20.0 * u[1]
    return p


# --------------------------------------------------------------------------------------------
# static stage: shape and load of the run move the envelope parameters
# --------------------------------------------------------------------------------------------
def _knob_scale(params: dict, knob: int) -> float:
    return float(params.get("knob2_ratio", 1.0)) if knob == 2 else 1.0


def static_params(effects, base: np.ndarray, knob: int, kappa: float, proj: float,
                  load: float, load_ref: float) -> np.ndarray:
    """Envelope parameters [d_pos, d_neg, b_pos, b_neg, omega, h_pos, h_neg] for one run.

    kappa: total shaft curvature sum |alpha_i| (rad); proj: the bend projected on this knob's
    axis (rad, signed); load, load_ref: the run's stated load and the sweep's, in %.
    """
    p = base.astype(float).copy()
    width0 = p[0] - p[1]
    for e in effects:
        pr = e.params
        s = _knob_scale(pr, knob)
        if e.name == "friction" and kappa > 0:
            # tendon-sheath capstan friction: the friction force grows with the wrap angle; the
            # loop widens (backlash) and less of the knob's pull reaches the tip (slope)
            if e.form == "linear":
                g = 1.0 + s * pr["a"] * kappa
            elif e.form == "saturating":
                k0 = pr["kappa0"]
                g = 1.0 + s * pr["a"] * k0 * (1.0 - math.exp(-kappa / k0))
            elif e.form == "quadratic":
                g = 1.0 + s * pr["a"] * kappa * kappa
            else:
                g = 1.0
            if e.form == "width-only":
                p[2] += s * pr["a_deg"] * kappa
                p[3] += s * pr["a_deg"] * kappa
            elif e.form == "slope-only":
                p[4] /= 1.0 + s * pr["c"] * kappa
            else:
                p[2] *= g
                p[3] *= g
                p[4] /= 1.0 + pr["slope_ratio"] * (g - 1.0)
        elif e.name == "deadzone" and kappa > 0:
            a = s * pr["a_deg"]
            if e.form == "widen":
                w = a * kappa
                p[0] += w
                p[1] -= w
            elif e.form == "widen-saturating":
                k0 = pr["kappa0"]
                w = a * k0 * (1.0 - math.exp(-kappa / k0))
                p[0] += w
                p[1] -= w
            elif e.form == "narrow":
                wmax = 0.5 * width0           # the slack taken up cannot exceed what is there
                w = wmax * math.tanh(a * kappa / wmax)
                p[0] -= w
                p[1] += w
            elif e.form == "centre":
                p[0] += pr["sign"] * a * kappa
                p[1] += pr["sign"] * a * kappa
            elif e.form == "one-edge":
                # the tendon on the inside of the bend gains slack beyond the paper's shift
                if proj > 0:
                    p[0] += a * abs(proj)
                elif proj < 0:
                    p[1] -= a * abs(proj)
        elif e.name == "stretch" and load != load_ref:
            c = s * pr["compliance"]
            if e.form.endswith("stiffening"):
                ls = pr["load_scale"]
                dl = ls * (math.log1p(load / ls) - math.log1p(load_ref / ls))
            else:
                dl = load - load_ref
            if e.form.startswith("outward"):
                # a load resisting the bend either way stretches whichever tendon pulls
                w = max(c * dl, -0.3 * width0)
                p[0] += w
                p[1] -= w
            else:
                # a load in one direction keeps one tendon stretched: the whole loop slides
                p[0] += pr["sign"] * c * dl
                p[1] += pr["sign"] * c * dl
    # the loop stays a loop: backlash no wider than the dead zone and plateau band allow
    room = (p[0] - p[1]) + (p[6] - p[5]) / p[4]
    p[2] = min(p[2], 0.97 * room)
    p[3] = min(p[3], 0.97 * room)
    return p


# --------------------------------------------------------------------------------------------
# linear time-invariant pieces
# --------------------------------------------------------------------------------------------
def lowpass1(x: np.ndarray, tau: float, dt: float) -> np.ndarray:
    """First-order low-pass (unit DC gain) starting at rest at x[0]."""
    if tau <= 0:
        return x.copy()
    a = math.exp(-dt / tau)
    y, _ = signal.lfilter([1.0 - a], [1.0, -a], x, zi=[a * x[0]])
    return y


def lowpass2(x: np.ndarray, tau_eq: float, zeta: float, dt: float) -> np.ndarray:
    """Second-order low-pass wn^2/(s^2 + 2 zeta wn s + wn^2), wn = 2 zeta / tau_eq (the same
    low-frequency delay tau_eq as a first-order lag), starting at rest at x[0]."""
    if tau_eq <= 0:
        return x.copy()
    wn = 2.0 * zeta / tau_eq
    b, a, _ = signal.cont2discrete(([wn * wn], [1.0, 2.0 * zeta * wn, wn * wn]), dt,
                                   method="bilinear")
    b = np.ravel(b)
    zi = signal.lfilter_zi(b, a) * x[0]
    y, _ = signal.lfilter(b, a, x, zi=zi)
    return y


# --------------------------------------------------------------------------------------------
# input stage
# --------------------------------------------------------------------------------------------
def input_stage(effects, q: np.ndarray, knob: int, dt: float):
    """(effective knob position, extra backlash per sample or None)."""
    qe = q
    eb = None
    for e in effects:
        if e.name != "lag":
            continue
        pr = e.params
        s = _knob_scale(pr, knob)
        if e.form == "input-first":
            # the motor and tendon follow the command through a viscous first-order lag
            qe = lowpass1(qe, s * pr["tau"], dt)
        elif e.form == "input-second":
            qe = lowpass2(qe, s * pr["tau_eq"], pr["zeta"], dt)
        elif e.form == "viscous-backlash":
            # viscous tendon-sheath drag: the knob must travel further before the tip follows,
            # in proportion to the knob speed
            v = np.gradient(q, dt)
            v = lowpass1(np.abs(v), pr["speed_smoothing"], dt)
            eb = s * pr["c_visc"] * v
    return qe, eb


def input_coupling(effects, q1: np.ndarray, q2: np.ndarray):
    """Knob-axis shifts (of knob 1, of knob 2) driven by the other knob's command, or None.

    The two knobs sit coaxially in the handle: turning one drags the other's tendon spool a
    little (shared bearing friction, tendons routed past each other), as if that knob had
    turned by k times the other's angle.
    """
    for e in effects:
        if e.name == "coupling" and e.form == "input-command":
            pr = e.params
            k = pr["sign"] * pr["k"]
            return k * q2, k * pr["back_ratio"] * q1
    return None


def kernel_coupling(effects):
    """(mode, k12, k21) for the clamp kernel."""
    for e in effects:
        if e.name != "coupling":
            continue
        pr = e.params
        mode = {"input-angle": _ck.COUPLE_SHIFT_ANGLE,
                "input-magnitude": _ck.COUPLE_SHIFT_MAGNITUDE,
                "deadzone-width": _ck.COUPLE_WIDTH}.get(e.form, _ck.COUPLE_NONE)
        if mode:
            k = pr["sign"] * pr["k"]
            return mode, k, k * pr["back_ratio"]
    return _ck.COUPLE_NONE, 0.0, 0.0


# --------------------------------------------------------------------------------------------
# output stage
# --------------------------------------------------------------------------------------------
def _saturate(y: np.ndarray, form: str, pr: dict, s: float) -> np.ndarray:
    if form == "knee":
        yk = s * pr["y_knee"]
        a = np.abs(y)
        return np.where(a <= yk, y, np.sign(y) * (yk + pr["slope_after"] * (a - yk)))
    ym = s * pr["y_max"]
    if form == "tanh":
        return ym * np.tanh(y / ym)
    if form == "hard":
        return np.clip(y, -ym, ym)
    if form == "asymmetric":
        side = pr["side"]
        lim = np.where(np.sign(y) == side, ym, ym * pr["other_ratio"])
        return lim * np.tanh(y / lim)
    if form == "rational":
        n = pr["order"]
        return y / (1.0 + (np.abs(y) / ym) ** n) ** (1.0 / n)
    raise ValueError(form)


def output_stage(effects, yh: dict, t: np.ndarray, band: dict) -> dict:
    """Tip as the tracker reports it, from the hysteresis outputs yh[1], yh[2].

    band[knob] = (h_pos, h_neg): the tip's plateau band, inside which no tendon loads the tip.
    """
    dt = float(t[1] - t[0])
    y = {k: v.copy() for k, v in yh.items()}
    by = {e.name: e for e in effects}
    e = by.get("coupling")
    if e is not None and e.form.startswith("output"):
        # the shared backbone: bending one plane bends the other (routing cross-talk) or, driven
        # by the bend's size, drags the other plane's tip one way (backbone shortening)
        pr = e.params
        k = pr["sign"] * pr["k"]
        f = (lambda v: v) if e.form == "output-angle" else np.abs
        y[1] = y[1] + k * f(yh[2])
        y[2] = y[2] + k * pr["back_ratio"] * f(yh[1])
    e = by.get("saturation")
    if e is not None:
        # the bending section stiffens near its largest bend
        for kb in (1, 2):
            y[kb] = _saturate(y[kb], e.form, e.params, _knob_scale(e.params, kb))
    e = by.get("creep")
    if e is not None:
        pr = e.params
        f = pr["fraction"]
        for kb in (1, 2):
            v = y[kb]
            if e.form == "kelvin":
                # viscoelastic backbone: part f of a new bend arrives at once, the rest creeps in
                y[kb] = v + f * (lowpass1(v, pr["tau"], dt) - v)
            elif e.form == "prony":
                fs = f * pr["split"]
                y[kb] = (v + fs * (lowpass1(v, pr["tau_fast"], dt) - v)
                         + (f - fs) * (lowpass1(v, pr["tau_slow"], dt) - v))
            elif e.form == "relaxation":
                # the tendon's tension relaxes: the tip overshoots then relaxes back
                y[kb] = v - f * (lowpass1(v, pr["tau"], dt) - v)
            elif e.form == "loaded":
                # only the bend the tendons hold (beyond the plateau band) creeps
                lo, hi = band[kb]
                sl = v - np.clip(v, lo, hi)
                y[kb] = v + f * (lowpass1(sl, pr["tau"], dt) - sl)
    e = by.get("lag")
    if e is not None and e.form.startswith("output"):
        # the tip's own dynamics or the tracker's filter
        pr = e.params
        for kb in (1, 2):
            s = _knob_scale(pr, kb)
            if e.form == "output-first":
                y[kb] = lowpass1(y[kb], s * pr["tau"], dt)
            else:
                y[kb] = lowpass2(y[kb], s * pr["tau_eq"], pr["zeta"], dt)
    e = by.get("latency")
    if e is not None:
        # the tracker reports the tip late (and, frame by frame, held)
        pr = e.params
        ts = t - pr["delay"]
        if e.form == "frame-hold":
            fr = pr["frame_rate"]
            ts = np.floor((ts - t[0]) * fr) / fr + t[0]
        for kb in (1, 2):
            y[kb] = np.interp(ts, t, y[kb])
    return y
