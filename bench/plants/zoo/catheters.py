"""Two-knob test catheters with unmodelled effects ("catheter zoo"), as run sets for diagnosis.

Written from the physics alone (docs/design.md sections 1-3, 6 and 8, and the paper's sections II-III);
imports only numpy, scipy, the standard library and the zoo's own modules (``plants``,
``plants_kernel``, ``catheters_kernel``, ``catheters_effects``). Nothing here knows how the tool
under test models, simulates or diagnoses these effects.

A catheter
==========
Two knobs (1 anterior-posterior, 2 right-left), each a dead-zone + backlash hysteresis of docs/design.md
section 3 (``plants.KnobTruth``, straight shaft), drawn near the paper's catheters: dead-zone edges
3-13 deg either side, backlash 2-8 deg, omega 1.2-1.7, plateau band (h_neg - h_pos) of 2-8 deg of
knob times omega. A bent shaft moves each knob's loop along its axis by the paper's shift,
``offset_1 = g * sum alpha_i cos(theta_i)`` and ``offset_2 = g * sum alpha_i sin(theta_i)``
(g = 0.2-0.35 deg of knob per deg of bend, drawn per catheter); the runs state that offset.

On top of the base model a case carries zero, one or two unmodelled effects
(``catheters_effects``, whose docstring lists the forms and their physics): ``coupling``,
``lag``, ``creep``, ``friction``, ``deadzone``, ``saturation``, ``stretch``, ``latency``, each in
several forms and at a strength ``weak``,
``mid`` or ``strong``. A strength is the RMS change of the tip (noise-free, with the effect
against without) on the runs where the effect's driver acts, drawn in
``catheters_effects.VISIBLE`` (weak 0.9-1.5 deg, mid 2-3.2 deg, strong 4-7 deg) and reached by
solving the form's strength scalar within its physical range (``factors['visibility']`` gives
what was reached).

A case's records (run CSV text of docs/design.md section 6)
=====================================================
``sweep``: the identification sweep on the straight shaft at the reference load: one knob at a
time (or, in 20 % of cases, both at once, knob 2 at 3/4 of knob 1's frequency), a sine of
+-40 deg, 2 cycles, at 40 deg/s and 1 kHz (the paper's protocol) or at 15-25 deg/s and 250 Hz;
columns ``t, q1, q2, y1, y2, c1, c2``. Every effect is in it, at its straight / reference setting.
The motor current follows a law written from docs/design.md section 4 on the tendon loads of
``plants_kernel`` (a stretch, tip-load or drop-at-reversal tendon, sometimes pretension,
motor Coulomb/viscous friction or a stiffening tendon), with current noise, quantisation and,
in half the cases, the lab's zero-phase 20 Hz Butterworth filter on current and tip.

``runs``: 8-10 evaluation runs at 100 Hz, columns ``t, q1, q2, y1, y2`` (a knob that does not move
rests at 0), tracker noise 0.1-0.3 deg: periodic 1-DoF runs (55-65 deg, 0.036-0.044 Hz,
2-2.5 cycles), nonperiodic 1-DoF runs (two sines of 27-33 deg at f and f*sqrt(3),
f = 0.018-0.022 Hz) and nonperiodic 2-DoF runs (the same input on both knobs, one twice as fast,
as in the paper), on a straight shaft and on bends of 30-120 deg in several directions, one of
them the paper's two-segment shape. Metadata: ``catheter, controller (none), motion, trial,
shape, offset1, offset2`` and, for a case with a load-driven effect (``stretch``), ``condition``
(load in %, several values including the reference). Before each run the catheter rests at knob
0 (tip somewhere on its plateau), then the shaft bends (1 s) and it rests 3 s more; that
unrecorded history is simulated.

Determinism: ``make_case(seed, effects)`` draws the catheter, its current law, its runs and its
noise from ``numpy.random.default_rng(seed)`` first, the effects after, so the same seed gives the
same catheter and the same noise whatever its effects; the same call gives the same bytes.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
from scipy import signal

from . import catheters_effects as _fx
from . import catheters_kernel as _ck
from . import plants_kernel as _pk
from .catheters_effects import EFFECTS, FORMS, STRENGTHS, VISIBLE
from .plants import KnobTruth

__all__ = ["EFFECTS", "FORMS", "STRENGTHS", "VISIBLE", "Effect", "CatheterCase", "make_case",
           "withheld_suite", "suite_specs", "simulate_tip", "parse_run"]

FS_RUN = 100.0
PRE_ROLL = 4.0          # s of unrecorded rest + bend before every record
BEND_TIME = 1.0         # s the bend takes, at the start of the pre-roll


@dataclass(frozen=True)
class Effect:
    """One effect as built into a case."""

    name: str
    form: str
    strength: str
    params: dict = field(default_factory=dict, hash=False, compare=True)


@dataclass(frozen=True)
class CatheterCase:
    seed: int
    name: str
    effects: tuple
    knobs: dict
    sweep: str
    runs: tuple
    factors: dict


# --------------------------------------------------------------------------------------------
# drawing the catheter
# --------------------------------------------------------------------------------------------
def _lu(rng, lo, hi):
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def _draw_knob(rng) -> KnobTruth:
    d_pos = rng.uniform(3.0, 13.0)
    d_neg = -rng.uniform(3.0, 13.0)
    b_pos = rng.uniform(2.0, 8.0)
    b_neg = rng.uniform(2.0, 8.0)
    omega = rng.uniform(1.2, 1.7)
    width = d_pos - d_neg
    band_knob = max(rng.uniform(2.0, 8.0), max(b_pos, b_neg) - width + 1.0)
    dh = omega * band_knob
    centre = rng.uniform(-2.0, 2.0)
    return KnobTruth(d_pos=float(d_pos), d_neg=float(d_neg), b_pos=float(b_pos),
                     b_neg=float(b_neg), omega=float(omega), h_pos=float(centre - dh / 2),
                     h_neg=float(centre + dh / 2))


def _draw_law(rng) -> dict:
    """Motor current law of one knob (docs/design.md section 4), drawn in a fixed order."""
    d = {}
    d["base"] = str(rng.choice(["stretch", "tip-load", "drop"]))
    k_mean = _lu(rng, 3.0, 30.0)
    r = _lu(rng, 0.6, 1.7)
    d["k_pos"], d["k_neg"] = k_mean * math.sqrt(r), k_mean / math.sqrt(r)
    d["c0"] = float(rng.uniform(-100.0, 200.0))
    d["noise_c"] = _lu(rng, 0.3, 4.0)
    d["lsb"] = float(rng.choice([0.0, 0.0, 0.1, 1.0]))
    d["rho"] = float(rng.uniform(0.15, 0.5))
    d["drop_frac"] = float(rng.uniform(0.25, 0.8))
    d["drop_travel"] = float(rng.uniform(0.05, 0.6))
    d["drop_hold"] = bool(rng.random() < 0.6)
    pre = rng.random() < 0.3
    d["pre_slope"] = float(rng.uniform(0.1, 0.4) * min(d["k_pos"], d["k_neg"])) if pre else 0.0
    fric = rng.random() < 0.3
    d["coulomb"] = float(rng.uniform(5.0, 40.0)) if fric else 0.0
    d["v_eps"] = float(rng.uniform(0.3, 2.0))
    d["viscous"] = _lu(rng, 0.02, 0.3) if fric else 0.0
    stiff = rng.random() < 0.2
    d["stiff_scale"] = _lu(rng, 5.0, 30.0) if stiff else 0.0
    if d["base"] != "drop":
        d["drop_frac"] = d["drop_travel"] = 0.0
        d["drop_hold"] = True
    if d["base"] == "stretch":
        d["rho"] = 0.0
    return d


def _kernel_params(k: KnobTruth, law: dict) -> np.ndarray:
    p = np.zeros(_pk.PARAM_LEN)
    p[:9] = [k.d_pos, k.d_neg, k.b_pos, k.b_neg, k.omega, k.h_pos, k.h_neg, k.dhat_pos,
             k.dhat_neg]
    p[_pk.P_BASE] = {"stretch": _pk.BASE_STRETCH, "tip-load": _pk.BASE_TIP_LOAD,
                     "drop": _pk.BASE_DROP}[law["base"]]
    p[_pk.P_RHO] = law["rho"]
    p[_pk.P_PHI] = law["drop_frac"]
    p[_pk.P_DELTA] = law["drop_travel"]
    p[_pk.P_HOLD] = 1.0 if law["drop_hold"] else 0.0
    return p


def _current(k: KnobTruth, law: dict, u: np.ndarray, dt: float, y0: float) -> np.ndarray:
    """Noise-free motor current (mA) for the knob's effective shifted position u."""
    st = _pk.new_state(float(u[0]), float(y0))
    _, pos, neg = _pk.run(u, _kernel_params(k, law), st)
    if law["stiff_scale"] > 0:
        pos = pos + pos * pos / (2 * law["stiff_scale"])
        neg = neg + neg * neg / (2 * law["stiff_scale"])
    c = law["c0"] + law["k_pos"] * pos - law["k_neg"] * neg
    if law["pre_slope"]:
        c = c + law["pre_slope"] * (u - 0.5 * (k.d_pos + k.d_neg))
    if law["coulomb"] or law["viscous"]:
        v = np.gradient(u, dt)
        c = c + law["coulomb"] * np.tanh(v / law["v_eps"]) + law["viscous"] * v
    return c


# --------------------------------------------------------------------------------------------
# shapes and runs
# --------------------------------------------------------------------------------------------
def shape_text(segments) -> str:
    if not segments:
        return "straight"
    return ";".join(f"alpha={_num(a)},theta={_num(th)}" for a, th in segments)


def _num(x: float) -> str:
    return str(int(x)) if float(x).is_integer() else f"{x:g}"


def _geometry(segments):
    """(total curvature, projection on knob 1, projection on knob 2), rad."""
    kap = sum(abs(math.radians(a)) for a, _ in segments)
    p1 = sum(math.radians(a) * math.cos(math.radians(th)) for a, th in segments)
    p2 = sum(math.radians(a) * math.sin(math.radians(th)) for a, th in segments)
    return kap, p1, p2


@dataclass
class _Run:
    motion: str
    dof: str                 # "1", "2" or "both"
    segments: tuple
    trial: int
    load: float
    t: np.ndarray
    q1: np.ndarray
    q2: np.ndarray
    offsets: tuple
    y0: tuple
    info: dict

    @property
    def moving(self) -> tuple:
        return {"1": (1,), "2": (2,), "both": (1, 2)}[self.dof]


def _periodic(rng, t):
    A = rng.uniform(55.0, 65.0)
    f = rng.uniform(0.036, 0.044)
    s = float(rng.choice([-1.0, 1.0]))
    return s * A * np.sin(2 * np.pi * f * t), {"amplitude": A, "frequency": f, "sign": s}


def _nonperiodic_params(rng):
    return {"a1": rng.uniform(27.0, 33.0), "a2": rng.uniform(27.0, 33.0),
            "f1": rng.uniform(0.018, 0.022), "sign": float(rng.choice([-1.0, 1.0]))}


def _nonperiodic(pr, t):
    f1 = pr["f1"]
    return pr["sign"] * (pr["a1"] * np.sin(2 * np.pi * f1 * t)
                         + pr["a2"] * np.sin(2 * np.pi * f1 * math.sqrt(3.0) * t))


def _draw_shapes(rng):
    a1 = float(rng.choice([30.0, 45.0, 60.0]))
    th1 = float(rng.choice([0.0, 180.0]))
    a2 = float(rng.choice([75.0, 90.0, 120.0]))
    th2 = float(rng.choice([90.0, -90.0]))
    a3 = float(rng.choice([30.0, 45.0, 60.0]))
    a4 = float(rng.choice([90.0, 120.0]))
    th4 = 180.0 - th1
    a5 = float(rng.choice([45.0, 60.0, 90.0]))
    th5 = float(rng.choice([45.0, 135.0, -45.0, -135.0]))
    return {"S1": ((a1, th1),), "S2": ((a2, th2),), "S3": ((a3, 0.0), (a3, 90.0)),
            "S4": ((a4, th4),), "S5": ((a5, th5),)}


# (motion, dof, shape key); the first eight are every case's, the last two optional repeats
_PLAN = (("periodic", "1", None), ("periodic", "2", None), ("periodic", "1", "S1"),
         ("periodic", "2", "S2"), ("nonperiodic", "both", None), ("nonperiodic", "both", "S3"),
         ("nonperiodic", "1", "S4"), ("nonperiodic", "both", "S5"),
         ("periodic", "1", None), ("nonperiodic", "both", None))


def _draw_runs(rng, knobs, g_offset):
    shapes = _draw_shapes(rng)
    n_runs = 8 + int(rng.integers(0, 3))
    load_ref = float(rng.choice([0.0, 0.0, 10.0, 20.0]))
    others = [25.0, 50.0, 75.0, 100.0, 40.0, 60.0, 90.0, 15.0]
    steps = [0.0, 0.0] + [others[int(i)] for i in rng.permutation(len(others))[:n_runs - 2]]
    loads = [min(100.0, load_ref + s) for s in steps]
    order = rng.permutation(len(loads))
    runs = []
    seen: dict = {}
    for i, (motion, dof, skey) in enumerate(_PLAN[:n_runs]):
        segs = shapes[skey] if skey else ()
        dur = float(rng.uniform(45.0, 70.0)) if motion == "periodic" else float(rng.uniform(60.0, 90.0))
        n = int(round(dur * FS_RUN)) + 1
        t = np.arange(n) / FS_RUN
        info = {}
        if motion == "periodic":
            q, info = _periodic(rng, t)
            info["cycles"] = dur * info["frequency"]
        else:
            info = _nonperiodic_params(rng)
            q = _nonperiodic(info, t)
        fast = int(rng.choice([1, 2]))
        y0 = tuple(float(rng.uniform(k.h_pos, k.h_neg)) for k in (knobs[1], knobs[2]))
        z = np.zeros(n)
        if dof == "1":
            q1, q2 = q, z
        elif dof == "2":
            q1, q2 = z, q
        else:
            qf = _nonperiodic(info, 2.0 * t)
            q1, q2 = (qf, q) if fast == 1 else (q, qf)
            info["fast_knob"] = fast
        _, p1, p2 = _geometry(segs)
        offsets = (round(g_offset * math.degrees(p1), 3) + 0.0,
                   round(g_offset * math.degrees(p2), 3) + 0.0)
        key = (motion, dof, shape_text(segs))
        seen[key] = seen.get(key, 0) + 1
        runs.append(_Run(motion, dof, segs, seen[key], loads[int(order[i])], t, q1, q2,
                         offsets, y0, info))
    return runs, load_ref


def _draw_sweep_plan(rng):
    s = {}
    s["protocol"] = "paper" if rng.random() < 0.6 else "slow"
    s["speed"] = 40.0 if s["protocol"] == "paper" else float(rng.uniform(15.0, 25.0))
    s["fs"] = 1000.0 if s["protocol"] == "paper" else 250.0
    s["amplitude"] = 40.0
    s["cycles"] = 2
    s["mode"] = "both" if rng.random() < 0.2 else "sequential"
    s["first"] = int(rng.choice([1, 2]))
    s["sign"] = float(rng.choice([-1.0, 1.0]))
    s["filtered"] = bool(rng.random() < 0.5)
    s["y0"] = (float(rng.random()), float(rng.random()))
    return s


# --------------------------------------------------------------------------------------------
# simulation
# --------------------------------------------------------------------------------------------
def _base_vec(k: KnobTruth) -> np.ndarray:
    return np.array([k.d_pos, k.d_neg, k.b_pos, k.b_neg, k.omega, k.h_pos, k.h_neg])


def _simulate(knobs, effects, t, q1, q2, segments=(), offsets=(0.0, 0.0), load=0.0,
              load_ref=0.0, y0=(0.0, 0.0), pre_roll=PRE_ROLL):
    """Noise-free tip of both knobs (and the effective knob positions) for commands q1, q2.

    The catheter rests at the commands' first values for ``pre_roll`` s before t[0], its shaft
    bending from straight to ``segments`` over the first ``BEND_TIME`` s of that rest.
    """
    dt = float(t[1] - t[0])
    npre = int(round(pre_roll / dt))
    tt = np.concatenate([t[0] + dt * np.arange(-npre, 0), t])
    Q = {1: np.concatenate([np.full(npre, q1[0]), q1]),
         2: np.concatenate([np.full(npre, q2[0]), q2])}
    ramp = np.clip((tt - tt[0]) / BEND_TIME, 0.0, 1.0)
    kap, p1, p2 = _geometry(segments)
    proj = {1: p1, 2: p2}
    P, U, EB = {}, {}, {}
    for kb in (1, 2):
        P[kb] = _fx.static_params(effects, _base_vec(knobs[kb]), kb, kap, proj[kb], load,
                                  load_ref)
        qe, eb = _fx.input_stage(effects, Q[kb], kb, dt)
        U[kb] = qe - offsets[kb - 1] * ramp
        EB[kb] = eb
    drag = _fx.input_coupling(effects, Q[1], Q[2])
    if drag is not None:
        U[1] = U[1] + drag[0]
        U[2] = U[2] + drag[1]
    mode, k12, k21 = _fx.kernel_coupling(effects)
    yh1, yh2, s1, s2 = _ck.run_two(U[1], U[2], P[1], P[2], EB[1], EB[2], mode, k12, k21, y0)
    band = {kb: (P[kb][5], P[kb][6]) for kb in (1, 2)}
    y = _fx.output_stage(effects, {1: yh1, 2: yh2}, tt, band)
    sl = slice(npre, None)
    return {"y1": y[1][sl], "y2": y[2][sl], "u1": (U[1] - s1)[sl], "u2": (U[2] - s2)[sl],
            "yh1": yh1[sl], "yh2": yh2[sl], "y_pre": (float(yh1[npre - 1]), float(yh2[npre - 1])),
            "u_full": (U[1] - s1, U[2] - s2), "npre": npre, "y0": y0}


def _sim_run(knobs, effects, run: _Run, load_ref: float):
    return _simulate(knobs, effects, run.t, run.q1, run.q2, run.segments, run.offsets, run.load,
                     load_ref, run.y0)


def _relevant(name: str, runs, load_ref):
    drv = _fx.DRIVER[name]
    out = []
    for i, r in enumerate(runs):
        if drv == "both":
            if r.dof == "both":
                out.append((i, (1, 2)))
        elif drv == "bent":
            if r.segments:
                out.append((i, r.moving))
        elif drv == "load":
            if r.load != load_ref:
                out.append((i, r.moving))
        else:
            out.append((i, r.moving))
    return out


def _visibility(knobs, effects, runs, load_ref, rel, ref_sims) -> float:
    ss, n = 0.0, 0
    for i, cols in rel:
        sim = _sim_run(knobs, effects, runs[i], load_ref)
        for kb in cols:
            d = sim[f"y{kb}"] - ref_sims[i][f"y{kb}"]
            if not np.all(np.isfinite(d)) or np.max(np.abs(d)) > 1e4:
                return math.inf
            ss += float(np.dot(d, d))
            n += d.size
    return math.sqrt(ss / n) if n else 0.0


def _calibrate(knobs, name, form, strength, shape_params, target, runs, load_ref, null_sims):
    """Solve the form's strength scalar so the tip changes by ``target`` deg RMS."""
    key, lo, hi, increasing = _fx.STRENGTH_KEY[(name, form)]
    rel = _relevant(name, runs, load_ref)

    def make(x):
        return Effect(name, form, strength, {**shape_params, key: float(x)})

    def vis(x):
        return _visibility(knobs, (make(x),), runs, load_ref, rel, null_sims)

    # search in z = log(strength) (growing effect) or log(1/strength) (saturation limits)
    zlo, zhi = (math.log(lo), math.log(hi)) if increasing else (-math.log(hi), -math.log(lo))
    to_x = (lambda z: math.exp(z)) if increasing else (lambda z: math.exp(-z))
    v_hi = vis(to_x(zhi))
    if v_hi <= target:
        x = to_x(zhi)
        return make(x), v_hi
    v_lo = vis(to_x(zlo))
    if v_lo >= target:
        x = to_x(zlo)
        return make(x), v_lo
    best = (zhi, v_hi)
    for _ in range(22):
        zm = 0.5 * (zlo + zhi)
        vm = vis(to_x(zm))
        if abs(vm - target) < abs(best[1] - target):
            best = (zm, vm)
        if abs(vm - target) < 0.03 * target:
            break
        if vm < target:
            zlo = zm
        else:
            zhi = zm
    x = to_x(best[0])
    # round the scalar to 4 significant digits, keeping what it gives
    x = float(f"{x:.4g}")
    return make(x), vis(x)


# --------------------------------------------------------------------------------------------
# records
# --------------------------------------------------------------------------------------------
def _csv(meta: dict, cols: Sequence[tuple]) -> str:
    """Run CSV text: '# key: value' lines, a header, rows formatted per column."""
    lines = [f"# {k}: {v}" for k, v in meta.items()]
    lines.append(",".join(name for name, _, _ in cols))
    fmt = ",".join(f for _, _, f in cols)
    arr = np.column_stack([np.asarray(a, dtype=float) for _, a, _ in cols])
    body = "\n".join(fmt % tuple(r) for r in arr.tolist())
    return "\n".join(lines) + "\n" + body + "\n"


def _noise_rng(seed: int, which: int):
    return np.random.default_rng([int(seed) & 0xFFFFFFFF, 77, which])


def _build_sweep(seed, knobs, effects, laws, sw, noise_y, load_ref, has_load, name):
    fs = sw["fs"]
    A = sw["amplitude"]
    f = sw["speed"] / (2 * math.pi * A)
    T = sw["cycles"] / f
    dt = 1.0 / fs
    seg = np.arange(int(round(T * fs))) / fs
    wave = sw["sign"] * A * np.sin(2 * math.pi * f * seg)
    rest = np.zeros(int(round(1.0 * fs)))
    if sw["mode"] == "sequential":
        a = np.concatenate([rest, wave, rest, np.zeros_like(wave), rest])
        b = np.concatenate([rest, np.zeros_like(wave), rest, wave, rest])
        q1, q2 = (a, b) if sw["first"] == 1 else (b, a)
    else:
        w2 = sw["sign"] * A * np.sin(2 * math.pi * 0.75 * f * seg)
        q1 = np.concatenate([rest, wave, rest])
        q2 = np.concatenate([rest, w2, rest])
    t = np.arange(q1.size) / fs
    y0 = tuple(knobs[kb].h_pos + sw["y0"][kb - 1] * (knobs[kb].h_neg - knobs[kb].h_pos)
               for kb in (1, 2))
    sim = _simulate(knobs, effects, t, q1, q2, (), (0.0, 0.0), load_ref, load_ref, y0)
    rng = _noise_rng(seed, 0)
    cols = [("t", t, "%.3f"), ("q1", q1, "%.4f"), ("q2", q2, "%.4f")]
    ys, cs = {}, {}
    for kb in (1, 2):
        law = dict(laws[kb])
        k = knobs[kb]
        rise = min(law["k_pos"] * (A - k.d_pos), law["k_neg"] * (A + k.d_neg))
        law["noise_c"] = float(min(law["noise_c"], rise / 6.0))
        uf = sim["u_full"][kb - 1]
        c = _current(k, law, uf, dt, y0[kb - 1])[sim["npre"]:]
        c = c + law["noise_c"] * rng.standard_normal(c.size)
        if law["lsb"]:
            c = np.round(c / law["lsb"]) * law["lsb"]
        y = sim[f"y{kb}"] + noise_y * rng.standard_normal(c.size)
        if sw["filtered"]:
            sos = signal.butter(3, 20.0, fs=fs, output="sos")
            c = signal.sosfiltfilt(sos, c)
            y = signal.sosfiltfilt(sos, y)
        ys[kb], cs[kb] = y, c
        laws[kb]["noise_c_used"] = law["noise_c"]
    cols += [("y1", ys[1], "%.4f"), ("y2", ys[2], "%.4f"), ("c1", cs[1], "%.3f"),
             ("c2", cs[2], "%.3f")]
    meta = {"catheter": name, "controller": "none", "shape": "straight", "motion": "sweep",
            "trial": 1, "offset1": 0.0, "offset2": 0.0}
    if has_load:
        meta["condition"] = _num(load_ref)
    return _csv(meta, cols)


def _run_csv(name, run: _Run, sim, noise_y, rng, has_load) -> str:
    n = run.t.size
    y1 = sim["y1"] + noise_y * rng.standard_normal(n)
    y2 = sim["y2"] + noise_y * rng.standard_normal(n)
    meta = {"catheter": name, "controller": "none", "motion": run.motion, "trial": run.trial,
            "shape": shape_text(run.segments), "offset1": run.offsets[0],
            "offset2": run.offsets[1]}
    if has_load:
        meta["condition"] = _num(run.load)
    cols = [("t", run.t, "%.2f"), ("q1", run.q1, "%.4f"), ("q2", run.q2, "%.4f"),
            ("y1", y1, "%.3f"), ("y2", y2, "%.3f")]
    return _csv(meta, cols)


def parse_run(text: str):
    """(metadata dict, columns dict of arrays) from run CSV text (plain csv/numpy)."""
    meta, rows = {}, []
    lines = text.splitlines()
    i = 0
    while i < len(lines) and lines[i].startswith("#"):
        k, _, v = lines[i][1:].partition(":")
        meta[k.strip()] = v.strip()
        i += 1
    header = lines[i].split(",")
    arr = np.loadtxt(lines[i + 1:], delimiter=",", ndmin=2)
    return meta, {h: arr[:, j] for j, h in enumerate(header)}


# --------------------------------------------------------------------------------------------
# public API
# --------------------------------------------------------------------------------------------
def _check_effects(effects):
    out = []
    names = set()
    for item in effects:
        if len(item) != 3:
            raise ValueError(f"an effect is (name, form or None, strength), got {item!r}")
        name, form, strength = item
        if name not in EFFECTS:
            raise ValueError(f"unknown effect {name!r}; known: {', '.join(EFFECTS)}")
        if form is not None and form not in FORMS[name]:
            raise ValueError(f"unknown form {form!r} of {name}; known: {', '.join(FORMS[name])}")
        if strength not in STRENGTHS:
            raise ValueError(f"unknown strength {strength!r}; known: {', '.join(STRENGTHS)}")
        if name in names:
            raise ValueError(f"effect {name!r} given twice")
        names.add(name)
        out.append((name, form, strength))
    return out


def make_case(seed: int, effects: Sequence[tuple] = ()) -> CatheterCase:
    """One catheter with its effects, seeded. effects: (name, form or None, strength)."""
    spec = _check_effects(effects)
    seed = int(seed)
    name = f"zoo-{seed}"
    rng = np.random.default_rng(seed)
    knobs = {1: _draw_knob(rng), 2: _draw_knob(rng)}
    laws = {1: _draw_law(rng), 2: _draw_law(rng)}
    noise_y = float(rng.uniform(0.1, 0.3))
    g_offset = float(rng.uniform(0.2, 0.35))
    runs, load_ref = _draw_runs(rng, knobs, g_offset)
    sw = _draw_sweep_plan(rng)
    has_load = any(n == "stretch" for n, _, _ in spec)
    if not has_load:
        for r in runs:
            r.load = load_ref
    built = []
    vis = {}
    null_sims = None
    for name_e, form, strength in spec:
        erng = np.random.default_rng([seed & 0xFFFFFFFF, 2, EFFECTS.index(name_e)])
        form_drawn = str(erng.choice(FORMS[name_e]))
        form = form or form_drawn
        target = float(erng.uniform(*VISIBLE[strength]))
        shape_params = _fx.draw_form_params(erng, name_e, form, strength)
        if null_sims is None:
            null_sims = [_sim_run(knobs, (), r, load_ref) for r in runs]
        eff, v = _calibrate(knobs, name_e, form, strength, shape_params, target, runs, load_ref,
                            null_sims)
        built.append(eff)
        vis[name_e] = {"target": target, "reached": v}
    built_t = tuple(built)
    nrng = _noise_rng(seed, 1)
    run_texts = []
    for r in runs:
        sim = _sim_run(knobs, built_t, r, load_ref)
        r.info["y_start"] = sim["y_pre"]      # the hysteresis state just before the record
        run_texts.append(_run_csv(name, r, sim, noise_y, nrng, has_load))
    sweep = _build_sweep(seed, knobs, built_t, laws, sw, noise_y, load_ref, has_load, name)
    factors = {
        "knobs": {kb: knobs[kb].as_dict() for kb in (1, 2)},
        "laws": laws,
        "noise_y": noise_y,
        "offset_per_deg": g_offset,
        "load_reference": load_ref if has_load else None,
        "sweep": sw,
        "runs": [{"motion": r.motion, "dof": r.dof, "shape": shape_text(r.segments),
                  "trial": r.trial, "offsets": r.offsets, "load": r.load if has_load else None,
                  "y0": r.y0, "duration": float(r.t[-1]), **r.info} for r in runs],
        "effects": [{"name": e.name, "form": e.form, "strength": e.strength,
                     "params": dict(e.params)} for e in built],
        "visibility": vis,
    }
    return CatheterCase(seed=seed, name=name, effects=built_t, knobs=knobs, sweep=sweep,
                        runs=tuple(run_texts), factors=factors)


def simulate_tip(case: CatheterCase, t, q1, q2, shape: str = "straight",
                 condition: float | None = None, effects=None, y0=None) -> tuple:
    """Noise-free tip (y1, y2) of the case's catheter for new commands (for checks and plots).

    shape uses the run metadata syntax; the offsets follow the catheter's own geometry;
    condition defaults to the reference load; effects defaults to the case's (pass () for the
    base catheter).
    """
    segs = _parse_shape(shape)
    g = case.factors["offset_per_deg"]
    _, p1, p2 = _geometry(segs)
    offsets = (round(g * math.degrees(p1), 3), round(g * math.degrees(p2), 3))
    ref = case.factors["load_reference"] or 0.0
    load = ref if condition is None else float(condition)
    eff = case.effects if effects is None else tuple(effects)
    if y0 is None:
        y0 = tuple(0.5 * (case.knobs[kb].h_pos + case.knobs[kb].h_neg) for kb in (1, 2))
    sim = _simulate(case.knobs, eff, np.asarray(t, float), np.asarray(q1, float),
                    np.asarray(q2, float), segs, offsets, load, ref, y0)
    return sim["y1"], sim["y2"]


def _parse_shape(text: str):
    text = (text or "").strip()
    if not text or text == "straight":
        return ()
    segs = []
    for part in text.split(";"):
        kv = dict(x.split("=") for x in part.split(","))
        segs.append((float(kv["alpha"]), float(kv["theta"])))
    return tuple(segs)


def suite_specs(seed: int = 0) -> list[tuple[int, tuple]]:
    """(case seed, effects) of every case of ``withheld_suite(seed)``, in its order.

    Per effect max(#forms, 3) + 1 single cases, strengths cycling weak, mid, strong from a drawn
    start and forms covering all of the effect's forms; 12 pairs of different effects (random
    forms and strengths); 12 null cases. Case seeds are ``1000 * seed + i``; the order of the
    cases is shuffled.
    """
    rng = np.random.default_rng([int(seed), 4242])
    specs: list[tuple] = []
    for name in EFFECTS:
        forms = list(FORMS[name])
        n = max(len(forms), 3) + 1
        perm = [forms[int(i)] for i in rng.permutation(len(forms))]
        extra = [forms[int(i)] for i in rng.integers(0, len(forms), size=n - len(forms))]
        fl = perm + extra
        s0 = int(rng.integers(0, 3))
        for j in range(n):
            specs.append(((name, fl[j], STRENGTHS[(s0 + j) % 3]),))
    pairs = set()
    while len(pairs) < 12:
        a, b = sorted(int(i) for i in rng.choice(len(EFFECTS), size=2, replace=False))
        pairs.add((a, b))
    for a, b in sorted(pairs):
        sa, sb = (STRENGTHS[int(i)] for i in rng.integers(0, 3, size=2))
        specs.append(((EFFECTS[a], None, sa), (EFFECTS[b], None, sb)))
    specs += [()] * 12
    order = rng.permutation(len(specs))
    return [(1000 * int(seed) + i, specs[int(j)]) for i, j in enumerate(order)]


def withheld_suite(seed: int = 0) -> list[CatheterCase]:
    """The withheld test set (see ``suite_specs``): 68 cases, deterministic."""
    return [make_case(s, eff) for s, eff in suite_specs(seed)]
