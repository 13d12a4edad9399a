"""WHERE: the residual broken down by loop phase, direction, shape, speed, amplitude and time;
what it follows; and the validation of the runs before any of it."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from ..core import effects as E
from ..core.model import knobs_of
from ..core.model import Model
from ..core.params import KnobModel
from ..core.run import Run
from ..errors import DataError
from .result import AMPLITUDE_BANDS, MOVING_DEG_S, PHASES, SPEED_BANDS, TIME_BINS, Breakdown, Residual, Where
from .search import Prep


def _phase(kn: KnobModel, x: np.ndarray, yh: np.ndarray) -> np.ndarray:
    u = x - kn.offset
    lo, hi = kn.f_up(u), kn.f_dn(u)
    tol = 1e-7 * (1.0 + np.abs(yh))
    on_up, on_dn = np.abs(yh - lo) <= tol, np.abs(yh - hi) <= tol
    flat_up = on_up & (u >= kn.dhat_pos) & (u <= kn.d_pos)
    flat_dn = on_dn & (u >= kn.d_neg) & (u <= kn.dhat_neg)
    out = np.full(u.shape, 0, dtype=np.int8)  # backlash plateau: held between the envelopes
    out[(on_up & (u < kn.dhat_pos)) | (on_dn & (u > kn.dhat_neg))] = 1    # unloading slope
    out[flat_up | flat_dn] = 2                                             # dead zone
    out[(on_up & (u > kn.d_pos)) | (on_dn & (u < kn.d_neg))] = 3           # loading slope
    return out


def _band(values: np.ndarray, edges: Sequence[float], unit: str) -> np.ndarray:
    labels = [f"<{edges[0]:g} {unit}"] + [f"{a:g}-{b:g} {unit}" for a, b in zip(edges[:-1], edges[1:])] \
        + [f">={edges[-1]:g} {unit}"]
    return np.array(labels, dtype=object)[np.searchsorted(np.asarray(edges), values, side="right")]


def _speed(q: np.ndarray, t: np.ndarray) -> np.ndarray:
    return np.gradient(q, t) if q.size > 1 else np.zeros_like(q)


@dataclass
class _Samples:
    e: list = field(default_factory=list)
    labels: dict = field(default_factory=dict)
    # for the residual description
    v: list = field(default_factory=list)
    q: list = field(default_factory=list)
    other: list = field(default_factory=list)


def _collect(preps: Sequence[Prep], effects: Sequence[E.Effect]) -> _Samples:
    s = _Samples()
    factors = ("phase", "direction", "shape", "speed", "amplitude", "other knob", "time", "knob")
    for f in factors:
        s.labels[f] = []
    for p in preps:
        pred = p.predict(effects)
        tt = p.t
        dur = float(tt[-1] - tt[0]) if tt.size > 1 else 1.0
        tbin = np.minimum(((tt - tt[0]) / max(dur, 1e-12) * TIME_BINS).astype(int), TIME_BINS - 1)
        for k, kn in p.knobs.items():
            e = p.y[k] - pred[k]
            if effects:
                tr = p.trace(effects, k)
                kc, x = tr.knob, tr.x
            else:
                kc, x = kn, p.q[k]
            yh = kc.forward(x, float(p.y[k][0]))
            v = _speed(p.q[k], tt)
            s.e.append(e)
            s.labels["phase"].append(np.array(PHASES, dtype=object)[_phase(kc, x, yh)])
            s.labels["direction"].append(np.where(v > MOVING_DEG_S, "increasing",
                                                  np.where(v < -MOVING_DEG_S, "decreasing", "holding")).astype(object))
            s.labels["shape"].append(np.full(e.size, str(p.shape), dtype=object))
            s.labels["speed"].append(_band(np.abs(v), SPEED_BANDS, "deg/s"))
            s.labels["amplitude"].append(_band(np.abs(p.q[k] - kn.offset), AMPLITUDE_BANDS, "deg"))
            o = 3 - k
            if o in p.q:
                vo = _speed(p.q[o], tt)
                s.labels["other knob"].append(np.where(np.abs(vo) > MOVING_DEG_S, "moving", "still").astype(object))
                s.other.append(p.q[o])
            else:
                s.labels["other knob"].append(np.full(e.size, "absent", dtype=object))
                s.other.append(np.full(e.size, np.nan))
            s.labels["time"].append(np.array([f"{100 * i // TIME_BINS}-{100 * (i + 1) // TIME_BINS} %"
                                              for i in range(TIME_BINS)], dtype=object)[tbin])
            s.labels["knob"].append(np.full(e.size, f"knob {k}", dtype=object))
            s.v.append(v)
            s.q.append(p.q[k] - kn.offset)
    return s


_FACTOR_WORDS = {
    "phase": "in the {level}",
    "direction": "while the knob is {level}",
    "shape": "with the shaft {level}",
    "speed": "at knob speeds {level}",
    "amplitude": "at knob angles {level} from the offset",
    "other knob": "while the other knob is {level}",
    "time": "in the {level} of the runs' duration",
    "knob": "on {level}",
}


def _where(samples: _Samples) -> Where:
    e = np.concatenate(samples.e)
    energy = float(e @ e)
    n = e.size
    groups = []
    for factor, parts in samples.labels.items():
        lab = np.concatenate(parts)
        levels = list(dict.fromkeys(lab.tolist()))
        if factor == "phase":
            levels = [p for p in PHASES if p in levels]
        elif factor in ("speed", "amplitude", "time"):
            levels = sorted(levels, key=lambda s: float(s.lstrip("<>=").split("-")[0].split()[0]))
            levels = [l for l in levels if l.startswith("<")] + [l for l in levels if not l.startswith("<")]
        for level in levels:
            m = lab == level
            c = int(m.sum())
            en = float(e[m] @ e[m])
            groups.append(Breakdown(factor, level, c, c / n, en / energy if energy > 0 else 0.0,
                                    math.sqrt(en / c) if c else 0.0))
    rmse = math.sqrt(energy / n) if n else 0.0
    # "knob" is reported but not a finding: a knob that only moves in 2-DoF runs would mask
    # the physical factor (the other knob moving) behind the bookkeeping one
    pool = [g for g in groups if g.factor != "knob" and g.sample_share >= 0.05
            and len({h.level for h in groups if h.factor == g.factor}) > 1]
    best = max(pool, key=lambda g: g.lift, default=None)
    if best is None or best.lift < 1.3:
        finding = (f"The residual (RMSE {rmse:.2f} deg) is spread evenly: no loop phase, direction, shape, "
                   f"speed, amplitude or time band holds markedly more than its share of the samples.")
    else:
        finding = (f"The residual (RMSE {rmse:.2f} deg) concentrates "
                   f"{_FACTOR_WORDS[best.factor].format(level=best.level)}: "
                   f"{100 * best.energy_share:.0f} % of its energy in {100 * best.sample_share:.0f} % of the "
                   f"samples (RMSE {best.rmse:.2f} deg there).")
    return Where(rmse, n, tuple(groups), finding)


def _corr(a: np.ndarray, b: np.ndarray) -> float | None:
    m = np.isfinite(a) & np.isfinite(b)
    if m.sum() < 3:
        return None
    a, b = a[m] - a[m].mean(), b[m] - b[m].mean()
    d = math.sqrt(float(a @ a) * float(b @ b))
    return float(a @ b) / d if d > 0 else 0.0


def _residual(preps: Sequence[Prep], samples: _Samples) -> Residual:
    e = np.concatenate(samples.e)
    rmse = math.sqrt(float(e @ e) / e.size) if e.size else 0.0
    ac_num = ac_den = 0.0
    hf = []
    i = 0
    for p in preps:
        dt = float(np.median(np.diff(p.t))) if p.t.size > 1 else 1.0
        lag = max(int(round(1.0 / dt)), 1)
        for _k in p.knobs:
            ek = samples.e[i] - samples.e[i].mean()
            i += 1
            if ek.size > lag:
                ac_num += float(ek[lag:] @ ek[:-lag])
                ac_den += float(ek @ ek)
            # sample-to-sample differences see the fast part only (noise), not slow model error
            hf.append(np.diff(samples.e[i - 1]))
    ac = ac_num / ac_den if ac_den > 0 else 0.0
    d = np.concatenate(hf) if hf else np.zeros(1)
    noise = float(np.std(d) / math.sqrt(2.0)) if d.size else 0.0
    v, q, other = np.concatenate(samples.v), np.concatenate(samples.q), np.concatenate(samples.other)
    cs, cas = _corr(e, v) or 0.0, _corr(e, np.abs(v)) or 0.0
    co = _corr(e, other)
    cq = _corr(e, q) or 0.0
    parts = [f"RMSE {rmse:.2f} deg", f"autocorrelation {ac:+.2f} at 1 s",
             f"correlation with knob speed {cs:+.2f}, with |speed| {cas:+.2f}",
             f"with the knob angle {cq:+.2f}"]
    if co is not None:
        parts.append(f"with the other knob {co:+.2f}")
    text = "What remains: " + ", ".join(parts) + "."
    follows = [(abs(c), what) for c, what in ((cs, "the knob speed"), (cas, "the knob speed's size"),
                                              (co or 0.0, "the other knob"), (cq, "the knob angle")) if abs(c) >= 0.3]
    if follows:
        text += f" It follows {max(follows)[1]}: an effect outside the catalogue, or one the data cannot pin down."
    elif abs(ac) < 0.2:
        text += " It is close to white: sensor noise, nothing a model term would explain."
    else:
        text += " It drifts slowly without following speed, angle or the other knob."
    return Residual(rmse, noise, ac, cs, cas, co, cq, text)


# --------------------------------------------------------------------------------------------
# validation
# --------------------------------------------------------------------------------------------
def _validate(model: Model, runs: Sequence[Run]) -> list[str]:
    names = []
    for i, r in enumerate(runs):
        names.append(r.source or f"run {i + 1}")
    if len(runs) < 2:
        raise DataError(f"diagnose needs at least 2 runs to hold whole runs out, got {len(runs)}: with a "
                        "single run nothing is left to test the fitted effects on")
    catheters = {}
    for name, r in zip(names, runs):
        c = str(r.meta.get("catheter", "")).strip()
        if c:
            catheters.setdefault(c, name)
    if len(catheters) > 1:
        pairs = ", ".join(f"{n} is {c}" for c, n in catheters.items())
        raise DataError(f"runs of different catheters are mixed ({pairs}): diagnose one catheter at a time")
    mc = str(model.meta.get("catheter", "") or "").strip()
    if mc and catheters and mc not in catheters:
        raise DataError(f"the model is of catheter {mc} but the runs are of {next(iter(catheters))}")
    model.require_loop(list(model.knobs), "diagnose")
    for name, r in zip(names, runs):
        r.require("t")
        for k in knobs_of(model, r, "q", "knob command", name=name):
            if f"y{k}" not in r:
                raise DataError(f"{name}: no measured tip angle y{k} (diagnose compares the model with "
                                f"measurement; q{k} is there but y{k} is not)")
            if not np.all(np.isfinite(r[f"y{k}"])) or not np.all(np.isfinite(r[f"q{k}"])):
                raise DataError(f"{name}: q{k} or y{k} holds NaN or infinite values")
        if len(r) < 3:
            raise DataError(f"{name}: needs at least 3 samples, has {len(r)}")
    return names
