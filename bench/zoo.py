"""Identification and shift detection on the independent plant zoo (issue 10), per plant family.

The plants (:mod:`hystcli.zoo.plants`) were written from the physics by an author who never read
identify.py, shift.py or the twin; their records reach the code under test as run CSV text, as a
user's logs would. Seeds from ``--seed`` on (default 100000) were never looked at while the
method was designed (the design used seeds below 5000): the figures are held-out.

What counts, per case:

* **identify** (tip fit, and current only): *success* when every parameter the record can fix is
  within 0.5 deg (tip) or 1 deg (current only) of the truth; *refused* when identify stops with an
  error (split by whether the truth itself shows the record cannot fix a parameter: a *right*
  refusal, or a *wrong* one); *silent failure* when it returns a parameter off by more than that.
  Whether a record can fix a parameter is judged on the *true* loop with the same rules identify
  applies to its fit (a loaded stretch past each edge, samples on each dead-zone flat, the tip
  leaving each backlash plateau, and no exact null direction of the true loop's Jacobian on the
  record moving it: then no method could fix it), which is the plant's truth, not our estimate.
  For the current alone two more limits hold whatever the current law: a law that does not carry
  the backlash cannot give it, and an edge is shown only where a stretch takes its tendon up,
  moving through it from the dead zone with a degree to spare on each side
  (:func:`current_cannot_fix`; a record started past an edge with the tendon taut shows only that
  tendon unloading there, where the tip settles), and a backlash the plant's own current law cuts
  short (its tendon must release over at least a quarter of the way to slack, so a backlash longer
  than the other three quarters shows as that) is not in the current.
* 2-sigma coverage: the share of returned parameters whose truth lies within two standard errors.

* **detect-shift** (replays): *within 0.5 deg* of the plant's true shift, *0.5-2 deg*, or a *silent
  failure* (exit 0, more than 2 deg off); refusals are split by whether the edge the search has
  to find lies within its travel limit and the replay (*reach*, :func:`edge_reachable`: the
  issue's denominator) or not; where that edge is out of reach, another counts as reachable where
  the search's walk back could read it (:func:`walk_back_reachable`): from a taut start the edge
  of the tendon it started on, where the replay goes on until that tendon is slack and then comes
  back across its edge; from a start in the dead zone the edge on its other side, where the
  replay crosses it later. The bench says how many cases only that makes reachable (and how many
  of them started slack), so the rate without them can be read. A second rate keeps, of the reachable cases, those whose edge
  *any* method could place: the plant's own noiseless replay, read the way the search reads,
  places the kink to +-0.25 deg at the Cramer-Rao bound (:func:`edge_placeable_se`), and the
  straight model has that edge (its identification did not leave it unplaced). Offsets returned
  more than 0.5 deg off count against both rates, whatever the information.

* **live**: the same replay plants served by ``hyst sim-robot --zoo`` behind a pseudo-terminal and
  searched by ``hyst detect-shift --port`` (the first 40 of ``--n``). ``--only live-direct``
  searches all ``--n`` of them with the same device driver, probe, codec and emulator, the bytes
  passed in memory instead of through a pty (:class:`EmulatorPort`): forty plants show a silent
  failure rate of one in a few hundred no better than none.

* ``--straight current``: the shift bench identifies the straight model from the sweep's motor
  current alone (the paper's protocol) instead of the tip fit, and counts the plants whose sweep
  identify refuses apart (no true-loop stand-in).

Run: ``python bench/zoo.py`` (500 sweeps and 500 replays, several minutes on 2 cores); ``--n``,
``--seed``, ``--only identify|identify-tip|identify-current|shift|live``, ``--straight tip|current``; ``--jobs 2`` scores the
cases over two processes (the same figures); ``--cases FILE`` writes every scored case as a JSON
line, and ``bench/zoo_compare.py A B`` lists the records whose outcome or estimate differ between
two such files (two codes, record by record).
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

from hystcli import shift
from hystcli.errors import HystError
from hystcli.identify import current_levels, identify, tip
from hystcli.identify.sweep import decimation_index
from hystcli.io import Run, parse_run
from hystcli.model import KnobModel, Model
from hystcli.zoo import plants

PARAMS = ("d_pos", "d_neg", "b_pos", "b_neg")


def truth_can_fix(case: plants.SweepCase) -> tuple[set[str], set[str]]:
    """(parameters the record cannot fix, edges that only slide) on the true loop."""
    tr = case.truth
    if "y1" not in case.record.columns:
        case = plants.sweep_case(case.seed, case.family)   # the same plant, its tip recorded
    m = KnobModel(d_pos=tr.d_pos, d_neg=tr.d_neg, b_pos=tr.b_pos, b_neg=tr.b_neg, omega=tr.omega,
                  h_pos=tr.h_pos, h_neg=tr.h_neg)
    col = case.record.columns
    q = np.asarray(col["q1"], float)
    y0 = float(case.factors.get("y_start", 0.0))
    th = tip.theta_from_model(m, (y0 - 0.5 * (m.h_pos + m.h_neg)) / m.omega)
    noise = float(case.factors.get("noise_y", 0.1))
    # the record's information at the true loop: a direction of the true loop's Jacobian that
    # moves no sample (an exact null) leaves what it moves unfixed for any method; the rest of
    # the rules need no uncertainty (zero), only where the samples lie
    idx = decimation_index(q, tip.MAX_SAMPLES)
    stderr, _ = tip._stderr(th, q[idx], np.zeros(idx.size), np.full(idx.size, noise), noise)
    null = {name: 0.0 if math.isfinite(v) else math.inf for name, v in stderr.items()}
    unfixed, sliding = tip._unidentified(th, m, q, null, float(np.ptp(q)), noise)
    return set(unfixed), set(sliding)


EDGE_MARGIN = 1.0
"""Knob travel (deg) a loading stretch must run on each side of an edge for a current to show it."""


def monotone_stretches(q: np.ndarray, dead_band: float = 0.5) -> list[tuple[int, int, int]]:
    """(start, stop, direction) of the knob's monotone stretches: a reversal is a turn of more
    than ``dead_band`` deg from the running extremum (the jitter of a held knob is no reversal)."""
    out, start, d, ext, at = [], 0, 0, float(q[0]), 0
    for i in range(1, q.size):
        v = float(q[i])
        if d >= 0 and v > ext or d <= 0 and v < ext:
            ext, at = v, i
        if d == 0 and abs(v - q[start]) > dead_band:
            d = 1 if v > q[start] else -1
            ext, at = v, i
        elif d != 0 and d * (ext - v) > dead_band:
            out.append((start, at, d))
            start, d, ext = at, -d, v
            at = i
    out.append((start, q.size - 1, d if d else 1))
    return out


def current_cannot_fix(case: plants.SweepCase) -> set[str]:
    """Edges a current cannot show on this record, whatever its law: a tendon is taken up (the
    current's slope jumps) only on a stretch that moves through the edge toward it, from the
    dead zone; a record that starts past an edge and never comes back through it loading (one
    cycle started with the tendon taut) shows the tendon unloading there, which is where the tip
    settles, not where the tendon is taken up. Judged on the true loop and the knob's samples."""
    tr = case.truth
    u = np.asarray(case.record.columns["q1"], float) - tr.offset
    shown = set()
    capped = set()
    f = case.factors
    holds = f.get("base") == "tip-load" or (f.get("base") == "drop" and f.get("drop_hold"))
    stretches = monotone_stretches(u)
    for i, (a, b, d) in enumerate(stretches):
        lo, hi = float(u[a:b + 1].min()), float(u[a:b + 1].max())
        if d > 0 and lo <= tr.d_pos - EDGE_MARGIN and hi >= tr.d_pos + EDGE_MARGIN:
            shown.add("d_pos")
        if d < 0 and hi >= tr.d_neg + EDGE_MARGIN and lo <= tr.d_neg - EDGE_MARGIN:
            shown.add("d_neg")
        # the held load after this stretch's reversal, by the plant's own law: the tendon holds
        # its load while the knob travels b back, but must release over at least a quarter of the
        # way down to where it is slack (plants_kernel._tendon_step); where b is longer than the
        # other three quarters, the current's plateau is that, not b
        if holds and i + 1 < len(stretches):
            if d > 0 and u[b] > tr.d_pos:
                xr, e, bb, shat, other = float(u[b]), tr.d_pos, tr.b_pos, tr.dhat_neg, tr.d_neg
                name = "b_pos"
            elif d < 0 and u[b] < tr.d_neg:
                xr, e, bb, shat, other = -float(u[b]), -tr.d_neg, tr.b_neg, -tr.dhat_pos, -tr.d_pos
                name = "b_neg"
            else:
                continue
            upe = xr - bb
            us = min(max(min(upe - f["rho"] * (xr - e), shat), other), xr)
            if upe < us + 0.25 * (xr - us) - 1e-9:
                capped.add(name)
    return ({"d_pos", "d_neg"} - shown) | capped


def run_cases(score, seeds: range, jobs: int, *args):  # noqa: ANN001, ANN201 - an iterator of dicts
    """``score(seed, *args)`` for every seed, in seed order, over ``jobs`` processes (each case is
    generated from its seed alone, so the records are the same whatever ``jobs`` is)."""
    if jobs <= 1:
        for s in seeds:
            yield score(s, *args)
        return
    from concurrent.futures import ProcessPoolExecutor
    from functools import partial

    with ProcessPoolExecutor(jobs) as pool:
        yield from pool.map(partial(_call, score, args), seeds, chunksize=4)


def _call(score, args: tuple, s: int) -> dict:  # noqa: ANN001
    return score(s, *args)


def score_identify(s: int, use_tip: bool) -> dict:
    """One sweep of the zoo through ``identify``, scored on the plant's truth (a JSON-able record:
    its seed, family, outcome, and what identify returned or why it refused)."""
    tol = 0.5 if use_tip else 1.0
    case = plants.sweep_case(s, tip=use_tip)
    fam = case.family
    run = parse_run(case.record.csv_text(), source=f"zoo-{s}")
    # the loop's own limits (edges passed, plateaus left) hold for the current too; a current
    # that does not carry the backlash cannot give it
    unfixed, sliding = truth_can_fix(case)
    if not use_tip and not case.current_shows_backlash:
        unfixed |= {"b_pos", "b_neg"}
    if not use_tip:
        unfixed |= current_cannot_fix(case)
    truth = case.truth.as_dict()
    rec: dict = {"seed": s, "family": fam, "tip": use_tip, "truth": {p: truth[p] for p in PARAMS},
                 "unfixed": sorted(unfixed)}
    try:
        fit = identify(run, use_tip=use_tip).fits[1]
    except HystError as exc:
        rec["outcome"] = "refused, rightly" if unfixed else "refused, wrongly"
        rec["message"] = str(exc)
        # a current that unloads at once after a reversal is what a backlash narrower than
        # the current can resolve gives, and what a stretch law gives for any backlash: the
        # wrong refusals of a narrow backlash are counted apart (still wrong)
        tr = case.truth
        rec["narrow_b"] = bool(not unfixed and not use_tip and "shows no backlash plateau" in str(exc)
                               and all(getattr(tr, b) < 1.0 for b in ("b_pos", "b_neg") if b in str(exc)))
        return rec
    # parameters identify leaves without an uncertainty (an edge it warns it cannot place,
    # and what moves with it) are not claimed: not judged
    judged = [p for p in PARAMS if p in fit.stderr]
    params = fit.model.params()
    e = {p: params[p] - truth[p] for p in judged}
    rec.update(outcome="success" if all(abs(v) <= tol for v in e.values()) else "silent failure",
               warned=bool(fit.warnings), params={p: params[p] for p in PARAMS},
               stderr={p: fit.stderr[p] for p in judged}, error=e)
    return rec


def bench_identify(n: int, seed: int, use_tip: bool, jobs: int = 1, cases: list | None = None) -> None:
    stats: dict = defaultdict(lambda: defaultdict(int))
    errs: dict = defaultdict(lambda: defaultdict(list))
    cover: list[bool] = []
    t0 = time.perf_counter()
    for rec in run_cases(score_identify, range(seed, seed + n), jobs, use_tip):
        if cases is not None:
            cases.append(rec)
        fam = rec["family"]
        stats[fam][rec["outcome"]] += 1
        if rec.get("narrow_b"):
            stats[fam]["wrongly, narrow b"] += 1
        if rec.get("warned"):
            stats[fam]["warned"] += 1
        for p, v in rec.get("error", {}).items():
            errs[fam][p].append(abs(v))
            cover.append(abs(v) <= 2 * rec["stderr"][p])
    dt = time.perf_counter() - t0
    label = "tip angle" if use_tip else "current only"
    print(f"\nidentify ({label}), {n} zoo sweeps from seed {seed}, {dt:.1f} s "
          f"({1e3 * dt / n:.0f} ms per sweep with the record's generation)")
    print(f"{'family':18s} {'success':>8s} {'refused':>16s} {'silent':>7s} {'warned':>7s}  "
          f"{'median |err| deg':>17s} {'worst':>7s}")
    total: dict = defaultdict(int)
    allerr: list[float] = []
    for fam in sorted(stats):
        st = stats[fam]
        for k, v in st.items():
            total[k] += v
        ee = [v for p in errs[fam].values() for v in p]
        allerr += ee
        print(f"{fam:18s} {st['success']:>8d} {st['refused, rightly']:>7d} r {st['refused, wrongly']:>5d} w "
              f"{st['silent failure']:>7d} {st['warned']:>7d}  {np.median(ee) if ee else math.nan:>17.3f} "
              f"{max(ee) if ee else math.nan:>7.2f}")
    returned = total["success"] + total["silent failure"]
    fixable = returned + total["refused, wrongly"]
    print(f"{'all':18s} {total['success']:>8d} {total['refused, rightly']:>7d} r "
          f"{total['refused, wrongly']:>5d} w {total['silent failure']:>7d} {total['warned']:>7d}  "
          f"{np.median(allerr):>17.3f} {max(allerr):>7.2f}")
    print(f"success {total['success']}/{returned} returned ({100 * total['success'] / max(returned, 1):.1f} %), "
          f"{total['success']}/{fixable} of the records whose truth can be identified "
          f"({100 * total['success'] / max(fixable, 1):.1f} %); 2-sigma coverage "
          f"{100 * np.mean(cover):.1f} % of {len(cover)} parameters")
    if not use_tip:
        print(f"of the {total['refused, wrongly']} wrong refusals, {total['wrongly, narrow b']} are 'no backlash "
              "plateau' where every refused backlash is narrower than 1 deg")


def starts_slack(case: plants.ReplayCase, q: np.ndarray) -> bool:
    """Whether the replay starts with the knob inside the plant's true (shifted) dead zone."""
    return case.truth.d_neg + case.offset < float(q[0]) < case.truth.d_pos + case.offset


def needed_edge(case: plants.ReplayCase, q: np.ndarray) -> tuple[str, float, float, float]:
    """The edge the search has to find, from the true state at the replay's start.

    In the shifted dead zone the search goes the way the record goes first, to that edge; with
    the positive tendon taut it goes through the dead zone to the negative edge, with the
    negative one taut to the positive edge. Returns (its name, ``"d_pos"`` or ``"d_neg"``; where
    it lies; where the dead zone's flat begins on the way there, the start or the other edge;
    the other edge)."""
    tr, o = case.truth, case.offset
    start = float(q[0])
    e_pos, e_neg = tr.d_pos + o, tr.d_neg + o
    moves = np.flatnonzero(np.abs(q - start) > 1e-9)
    first = int(np.sign(q[moves[0]] - start)) if moves.size else 1
    if starts_slack(case, q):                      # slack: the way the record goes first
        return ("d_pos", e_pos, start, e_neg) if first > 0 else ("d_neg", e_neg, start, e_pos)
    if start >= e_pos:                             # taut: through the dead zone to the other edge
        return "d_neg", e_neg, e_pos, e_pos
    return "d_pos", e_pos, e_neg, e_neg


def edge_reachable(case: plants.ReplayCase, q: np.ndarray, travel: float) -> bool:
    """Whether the edge the search has to find (:func:`needed_edge`) lies within its travel limit
    and the replay: within the travel limit of the start (3 deg past it to confirm it), and the
    replay goes that far: the denominator of the detection rate."""
    start = float(q[0])
    need = needed_edge(case, q)[1]
    d = 1 if need > start else -1
    far = need + 3.0 * d
    covered = float(np.max(q)) >= far if d > 0 else float(np.min(q)) <= far
    return abs(far - start) <= travel and covered


def walk_back_reachable(case: plants.ReplayCase, q: np.ndarray, travel: float) -> bool:
    """Whether a search whose edge lies beyond reach could read another by walking back to it
    (``hystcli.shift``'s walk back, taken when the edge it went for is out of reach).

    From a taut start, the edge of the tendon it started on: the replay goes on away from that
    edge until the tendon is slack on any current law (past the edge by the true backlash of that
    side, where the tip is back in the dead zone) and 2.5 deg more (the readings that show it
    stays slack), within the travel limit, and later comes back past the edge by 3 deg (to confirm
    it). From a start in the dead zone, the edge on the other side of it from the one the record
    goes to first: within the travel limit of the start (3 deg past it), and the replay goes 3 deg
    past it at some time (after its turn)."""
    tr, o = case.truth, case.offset
    start = float(q[0])
    e_pos, e_neg = tr.d_pos + o, tr.d_neg + o
    if starts_slack(case, q):
        name, _, _, other = needed_edge(case, q)
        side = -1 if name == "d_pos" else 1
        far = other + 3.0 * side
        return abs(far - start) <= travel and bool(np.any(side * (q - far) >= 0))
    if start >= e_pos:
        side, near, b = 1, e_pos, tr.b_pos
    else:
        side, near, b = -1, e_neg, tr.b_neg
    slack = near - side * (b + 2.5)
    if abs(slack - start) > travel or abs(near + 3.0 * side - start) > travel:
        return False
    away = np.flatnonzero(side * (q - slack) <= 0)
    if away.size == 0:
        return False
    back = q[int(away[0]):]
    return bool(np.any(side * (back - (near + 3.0 * side)) >= 0))


PLACEABLE_SE = 0.25
"""Largest standard error (deg) at which the true kink could still be placed within 0.5 deg (two
of them): the same half degree the rate is judged at."""


def _probe_readings(rep, start: float, d: int, far: float, step: float = 0.5) -> np.ndarray:
    """(q, current) of the probe at ``start`` and stepped from there toward ``far`` by ``step``, as
    far as the record goes: the readings any search that way could have."""
    probe = shift.ReplayProbe(rep, 1)
    first = probe.read()
    out = [(first.q, first.current)]
    k = 1
    while d * (start + d * step * k - far) <= 1e-9:
        try:
            s = probe.step_to(start + d * step * k)
        except shift.ReplayExhausted:
            break
        out.append((s.q, s.current))
        k += 1
    return np.array(out, dtype=float).reshape(-1, 2)


def _kink_bound(rep, rep0, start: float, need: float, begin: float, travel: float) -> float:
    """Cramer-Rao bound (deg) of the kink at ``need`` on the pass from ``start`` (see
    :func:`edge_placeable_se`); ``begin``: where the dead zone's flat begins on that pass."""
    d = 1 if need > start else -1
    noisy = _probe_readings(rep, start, d, start + d * travel)
    true = _probe_readings(rep0, start, d, start + d * travel)
    m = min(len(noisy), len(true))
    x = d * (true[:m, 0] - need)
    sel = x >= d * (begin - need) - 1e-9
    if np.sum(sel & (x < 0)) < 2 or np.sum(sel & (x > 0)) < 2:
        return math.inf
    dev = noisy[:m, 1] - true[:m, 1]
    sig = 1.4826 * float(np.median(np.abs(dev - np.median(dev))))
    return hinge_bound(x[sel], true[:m, 1][sel], sig)


def hinge_bound(x: np.ndarray, c: np.ndarray, sig: float) -> float:
    """Cramer-Rao bound (deg) of the kink of ``c = a + s0 x + s1 x+`` at ``x = 0`` from readings
    at ``x`` (deg from the true kink) whose true values are ``c`` (mA), with white noise ``sig``.

    The lines are the least-squares ones through ``c`` with the kink held at 0; the bound is the
    kink's entry of the inverse Fisher information of (a, s0, s1, kink) at those lines."""
    x = np.asarray(x, float)
    a = np.column_stack([np.ones_like(x), x, np.maximum(x, 0.0)])
    beta, *_ = np.linalg.lstsq(a, np.asarray(c, float), rcond=None)
    jac = np.column_stack([a, -(beta[1] + beta[2] * (x > 0))])
    try:
        var = float(np.linalg.inv(jac.T @ jac)[3, 3])
    except np.linalg.LinAlgError:
        return math.inf
    return max(sig, 1e-12) * math.sqrt(max(var, 0.0))


def edge_placeable_se(case: plants.ReplayCase, rep: Run, travel: float) -> float:
    """How well *any* method could place the kink at an edge the search can use, on the truth.

    The plant's own noiseless replay (the same draws without the sensor's noise) stepped the way
    the search goes (:func:`edge_reachable`) gives the true readings; the noisy replay stepped the
    same way gives their noise. A continuous two-line fit through the true readings at the true
    edge (the whole dead-zone flat of that pass, the whole loaded stretch up to the travel limit)
    then gives, from its Fisher information at the readings' noise, the smallest standard error an
    unbiased estimate of the kink can have on these readings (the Cramer-Rao bound). Where the
    edge the record goes to first is too near the start for a flat before it (fewer than two
    readings), the search crosses the dead zone to the other edge, and that edge's bound counts.
    ``inf`` when neither has two readings on each side within the travel limit. The bound is
    optimistic where the current is not two straight lines, so it counts such a case placeable:
    it never leaves out a case a method could have got right. ``rep``: the case's (noisy) replay,
    parsed."""
    case0 = plants.replay_case(case.seed, case.family, noiseless=True)
    rep0 = parse_run(case0.replay.csv_text(), source="noiseless")
    q = np.asarray(rep["q1"], float)
    start = float(q[0])
    _, need, begin, other = needed_edge(case, q)
    bound = _kink_bound(rep, rep0, start, need, begin, travel)
    if math.isinf(bound) and begin == start:
        bound = _kink_bound(rep, rep0, start, other, start, travel)
    return bound


def model_lacks_edge(model: Model, case: plants.ReplayCase, q: np.ndarray) -> bool:
    """Whether the straight model's identification left the edge the search needs unplaced (its
    sweep could not fix it): then no offset can be measured from it, whatever the replay shows."""
    ident = (model.identification or {}).get(1)
    return ident is not None and needed_edge(case, q)[0] in ident.unfixed


def straight_model(case: plants.ReplayCase, use_tip: bool = True) -> tuple[Model | None, str]:
    """The model a user would have: identified on the straight sweep (tip fit); when the sweep
    cannot identify it, the true loop with the current levels read on that sweep. With
    ``use_tip`` False, identified from the sweep's current alone (the paper's protocol), and None
    where identify refuses."""
    run = parse_run(case.straight_sweep.csv_text(), source="straight")
    try:
        return identify(run, use_tip=use_tip).model, "identified"
    except HystError:
        if not use_tip:
            return None, "refused"
        tr = case.truth
        km = KnobModel(d_pos=tr.d_pos, d_neg=tr.d_neg, b_pos=tr.b_pos, b_neg=tr.b_neg, omega=tr.omega,
                       h_pos=tr.h_pos, h_neg=tr.h_neg)
        return Model({1: km}, identification={1: current_levels(run, 1, km)}), "true loop"


def score_shift(s: int, use_tip: bool = True) -> dict:
    """One replay of the zoo through ``detect_shift``, scored on the plant's truth (a JSON-able
    record: its seed, family, the straight model's source, reach, and the outcome)."""
    case = plants.replay_case(s)
    fam = case.family
    rec: dict = {"seed": s, "family": fam, "truth": case.offset, "straight": "tip" if use_tip else "current"}
    model, how = straight_model(case, use_tip)
    rec["how"] = how
    if model is None:
        rec["outcome"] = "identify refused"
        return rec
    rep = parse_run(case.replay.csv_text(), source=f"replay-{s}")
    travel = shift.default_max_travel(model, 1)
    q = np.asarray(rep["q1"], float)
    reach = edge_reachable(case, q, travel)
    back_only = not reach and walk_back_reachable(case, q, travel)
    rec.update(key="reach" if reach or back_only else "beyond", back_only=back_only,
               slack=bool(back_only and starts_slack(case, q)))
    # whether the truth's readings could place the edge at all, and whether the model has it
    why_not = None
    if reach:
        if model_lacks_edge(model, case, q):
            why_not = "model"
        elif edge_placeable_se(case, rep, travel) > PLACEABLE_SE:
            why_not = "readings"
    rec["why_not"] = why_not
    try:
        r = shift.detect_shift(model, shift.ReplayProbe(rep, 1), 1)
    except HystError as exc:
        rec.update(outcome="refused", message=str(exc))
        return rec
    e = r.offset - case.offset
    rec.update(offset=r.offset, error=e, edge=r.edge, walked_back=r.walked_back)
    # the offset's own standard error: its kink's and its model edge's (identify's), combined
    ident = (model.identification or {}).get(1)
    m_se = (ident.stderr.get(f"d_{r.edge}", 0.0) if ident is not None and ident.stderr else 0.0)
    if r.evidence is not None:
        rec["se"] = math.hypot(r.evidence.edge_se, m_se)
    rec["outcome"] = "ok" if abs(e) <= 0.5 else ("0.5-2 deg" if abs(e) <= 2.0 else "silent > 2 deg")
    return rec


def bench_shift(n: int, seed: int, use_tip: bool = True, jobs: int = 1, cases: list | None = None) -> None:
    stats: dict = defaultdict(lambda: defaultdict(int))
    errs: list[float] = []
    nulls: list[float] = []
    silent: list[str] = []
    unplaceable: dict = defaultdict(int)
    cover: list[bool] = []
    t0 = time.perf_counter()
    for rec in run_cases(score_shift, range(seed, seed + n), jobs, use_tip):
        if cases is not None:
            cases.append(rec)
        fam, out = rec["family"], rec["outcome"]
        if out == "identify refused":
            stats[fam][out] += 1
            continue
        key, back_only, why_not = rec["key"], rec["back_only"], rec["why_not"]
        if rec["slack"]:
            unplaceable["back, slack"] += 1
        if out == "refused":
            stats[fam][f"refused ({key})"] += 1
            if back_only:
                unplaceable["back, refused"] += 1
            if why_not:
                unplaceable[f"refused, {why_not}"] += 1
            continue
        e = rec["error"]
        errs.append(abs(e))
        if rec["truth"] == 0.0:
            nulls.append(abs(rec["offset"]))
        if "se" in rec:
            cover.append(abs(e) <= 2.0 * rec["se"])
        if back_only:
            unplaceable["back, " + ("ok" if abs(e) <= 0.5 else "off")] += 1
        if out == "ok":
            stats[fam][f"ok ({key})"] += 1
            if why_not:
                unplaceable[f"ok, {why_not}"] += 1
        else:
            stats[fam][out] += 1
            if out == "silent > 2 deg":
                silent.append(f"seed {rec['seed']} ({fam}, {rec['how']}): offset {rec['offset']:+.2f}, "
                              f"true {rec['truth']:+.2f}")
    dt = time.perf_counter() - t0
    cols = ("ok (reach)", "refused (reach)", "ok (beyond)", "refused (beyond)", "0.5-2 deg", "silent > 2 deg") + (
        () if use_tip else ("identify refused",))
    print(f"\ndetect-shift on replays, {n} zoo plants from seed {seed} (the straight model identified on "
          f"the plant's straight sweep, {'tip fit' if use_tip else 'current only'}), {dt:.1f} s")
    print("reach: the replay crosses the edge the search has to find within the travel limit, or the search "
          "could read another on a walk back (a taut start: the replay goes on until the tendon is slack "
          "and comes back across its edge; a slack start: it crosses the other edge later); beyond: neither")
    print(f"{'family':18s} " + " ".join(f"{c:>16s}" for c in cols))
    total: dict = defaultdict(int)
    for fam in sorted(stats):
        st = stats[fam]
        for k, v in st.items():
            total[k] += v
        print(f"{fam:18s} " + " ".join(f"{st[c]:>16d}" for c in cols))
    print(f"{'all':18s} " + " ".join(f"{total[c]:>16d}" for c in cols))
    reach_n = total["ok (reach)"] + total["refused (reach)"] + sum(
        1 for _ in ())  # off/silent are counted below with their own columns
    print(f"within 0.5 deg: {total['ok (reach)']} of the {reach_n + total['0.5-2 deg'] + total['silent > 2 deg']} "
          f"cases whose edge is reachable or that returned an offset; silent failures (exit 0, error > 2 deg): "
          f"{total['silent > 2 deg']}; median |error| {np.median(errs) if errs else math.nan:.3f} deg, "
          f"worst {max(errs) if errs else math.nan:.2f}")
    print(f"of those, reachable only on a walk back (the edge it went for beyond reach): "
          f"{unplaceable['back, ok'] + unplaceable['back, refused'] + unplaceable['back, off']} "
          f"({unplaceable['back, slack']} of them from a start in the dead zone, to the edge on its other "
          f"side; the rest from a taut start, to the edge it started beside), "
          f"{unplaceable['back, ok']} within 0.5 deg, {unplaceable['back, refused']} refused, "
          f"{unplaceable['back, off']} off by more")
    # the same rate over the reachable cases whose edge the readings could place at all (judged on
    # the plant's truth) and the straight model has; returned offsets off by more than 0.5 deg count
    # whatever the information was
    ok_p = total["ok (reach)"] - unplaceable["ok, readings"] - unplaceable["ok, model"]
    ref_p = total["refused (reach)"] - unplaceable["refused, readings"] - unplaceable["refused, model"]
    den_p = ok_p + ref_p + total["0.5-2 deg"] + total["silent > 2 deg"]
    print(f"placeable (the true readings place the needed edge to +-{PLACEABLE_SE} deg at the Cramer-Rao "
          f"bound, and the straight model has that edge): {ok_p} of {den_p} within 0.5 deg "
          f"({100 * ok_p / max(den_p, 1):.1f} %), {ref_p} refused; the reachable cases left out: "
          f"readings too weak {unplaceable['refused, readings']} refused and {unplaceable['ok, readings']} right, "
          f"edge unplaced by the straight sweep's identification {unplaceable['refused, model']} refused "
          f"and {unplaceable['ok, model']} right")
    if cover:
        print(f"the true shift within two of the offset's standard errors (its kink's edge_se and its "
              f"model edge's, combined): {100 * np.mean(cover):.1f} % of {len(cover)} offsets")
    if nulls:
        print(f"null cases (no shift): {len(nulls)} returned, |offset| worst {max(nulls):.3f} deg")
    for line in silent:
        print("  silent: " + line)


def bench_live(n: int, seed: int, cases: list | None = None) -> None:
    """The live path: ``hyst sim-robot --zoo`` behind a real pty, ``hyst detect-shift --port``."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    import tempfile

    from simrobot import sim_robot
    from typer.testing import CliRunner

    from hystcli.cli import app
    from hystcli.io import load_model, save_model

    runner = CliRunner()
    counts: dict = defaultdict(int)
    errs: list[float] = []
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        for s in range(seed, seed + n):
            case = plants.replay_case(s)
            model, _ = straight_model(case)
            mp, out = Path(tmp) / f"m{s}.json", Path(tmp) / f"o{s}.json"
            save_model(mp, model)
            with sim_robot("--zoo", f"{s}:{case.family}:{case.offset!r}") as port:
                res = runner.invoke(app, ["detect-shift", "--model", str(mp), "--port", port, "-o", str(out),
                                          "--timeout", "10", "-q"])
            rec: dict = {"seed": s, "family": case.family, "live": True, "truth": case.offset}
            if res.exit_code != 0:
                counts["refused"] += 1
                rec.update(outcome="refused", message=res.output.strip().splitlines()[-1:])
            else:
                offset = load_model(out).knob(1).offset
                e = abs(offset - case.offset)
                errs.append(e)
                rec.update(offset=offset, error=offset - case.offset,
                           outcome="ok" if e <= 0.5 else ("0.5-2 deg" if e <= 2 else "silent > 2 deg"))
                counts[rec["outcome"]] += 1
            if cases is not None:
                cases.append(rec)
    dt = time.perf_counter() - t0
    print(f"\nlive detect-shift (sim-robot --zoo over a pty), {n} plants from seed {seed}, {dt:.0f} s: "
          + ", ".join(f"{k} {v}" for k, v in sorted(counts.items()))
          + (f"; median |error| {np.median(errs):.3f} deg, worst {max(errs):.2f}" if errs else ""))


class EmulatorPort:
    """A byte pipe to a :class:`hystcli.emulator.DeviceEmulator` in this process: what the host
    writes is handed to the emulator line by line, its replies are read back (their latency
    dropped). Below the transport only: the host's :class:`hystcli.device.Device` and
    :class:`~hystcli.device.DeviceProbe`, the protocol codec and the emulator are the ones the pty
    path runs, so the search makes the same decisions on the same samples, many times faster."""

    def __init__(self, emulator) -> None:  # noqa: ANN001 - hystcli.emulator.DeviceEmulator
        self.emulator = emulator
        self.timeout = 0.05
        self.name = "emulator"
        self._in = bytearray()
        self._out = bytearray()

    @property
    def in_waiting(self) -> int:
        return len(self._out)

    def write(self, data: bytes) -> int:
        self._in.extend(data)
        while (nl := self._in.find(b"\n")) >= 0:
            line = bytes(self._in[:nl + 1])
            del self._in[:nl + 1]
            for reply, _ in self.emulator.handle_line(line):
                self._out.extend(reply)
        return len(data)

    def read(self, n: int = 1) -> bytes:
        chunk = bytes(self._out[:n])
        del self._out[:n]
        return chunk

    def reset_input_buffer(self) -> None:
        self._out.clear()


def score_live_direct(s: int) -> dict:
    """One replay plant searched live as ``hyst detect-shift --port`` searches it against
    ``hyst sim-robot --zoo`` (the CLI's probe options), over :class:`EmulatorPort` instead of a
    pty, scored on the plant's truth."""
    from hystcli import device
    from hystcli.emulator import DeviceEmulator

    case = plants.replay_case(s)
    model, how = straight_model(case)
    plant, _ = plants.live_plant(s, case.family, offset=case.offset)
    rec: dict = {"seed": s, "family": case.family, "live": True, "direct": True, "truth": case.offset, "how": how}
    dev = device.Device(EmulatorPort(DeviceEmulator(plant)), timeout=10.0)
    try:
        # the probe reads the knob at rest first: a current past the ceiling stops it there
        probe = device.DeviceProbe(dev, 1, current_ceiling=2000.0, speed=5.0)
        r = shift.detect_shift(model, probe, 1)
    except HystError as exc:
        rec.update(outcome="refused", message=str(exc))
        return rec
    e = r.offset - case.offset
    rec.update(offset=r.offset, error=e, edge=r.edge,
               outcome="ok" if abs(e) <= 0.5 else ("0.5-2 deg" if abs(e) <= 2.0 else "silent > 2 deg"))
    return rec


def bench_live_direct(n: int, seed: int, jobs: int = 1, cases: list | None = None) -> None:
    """The live search's decisions on many plants: :func:`score_live_direct` per seed."""
    counts: dict = defaultdict(lambda: defaultdict(int))
    errs: list[float] = []
    silent: list[str] = []
    t0 = time.perf_counter()
    for rec in run_cases(score_live_direct, range(seed, seed + n), jobs):
        if cases is not None:
            cases.append(rec)
        counts[rec["family"]][rec["outcome"]] += 1
        if "error" in rec:
            errs.append(abs(rec["error"]))
        if rec["outcome"] == "silent > 2 deg":
            silent.append(f"seed {rec['seed']} ({rec['family']}, {rec['how']}): offset {rec['offset']:+.2f}, "
                          f"true {rec['truth']:+.2f}")
    dt = time.perf_counter() - t0
    cols = ("ok", "refused", "0.5-2 deg", "silent > 2 deg")
    print(f"\nlive detect-shift, the emulator in process (the pty's device, probe and codec; "
          f"--only live runs the pty), {n} plants from seed {seed}, {dt:.0f} s")
    print(f"{'family':18s} " + " ".join(f"{c:>15s}" for c in cols))
    total: dict = defaultdict(int)
    for fam in sorted(counts):
        for k, v in counts[fam].items():
            total[k] += v
        print(f"{fam:18s} " + " ".join(f"{counts[fam][c]:>15d}" for c in cols))
    print(f"{'all':18s} " + " ".join(f"{total[c]:>15d}" for c in cols))
    if errs:
        print(f"median |error| {np.median(errs):.3f} deg, worst {max(errs):.2f}")
    for line in silent:
        print("  silent: " + line)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=500)
    ap.add_argument("--seed", type=int, default=100_000)
    ap.add_argument("--only", choices=("identify", "identify-tip", "identify-current", "shift", "live",
                                       "live-direct"),
                    default=None, help="one part (identify: both its benches; live-direct: the live search "
                                       "over the emulator in process, --n plants, not part of the default run)")
    ap.add_argument("--straight", choices=("tip", "current"), default="tip",
                    help="how the shift bench identifies the straight model (default: the tip fit)")
    ap.add_argument("--jobs", type=int, default=1,
                    help="processes scoring cases (the same figures for any number; live runs alone)")
    ap.add_argument("--cases", type=Path, default=None,
                    help="also write every scored case as a JSON line here (seed, family, outcome, "
                         "estimate, error, refusal message), for comparing two codes record by record")
    args = ap.parse_args(argv)
    cases: list | None = [] if args.cases is not None else None
    if args.only in (None, "identify", "identify-tip"):
        bench_identify(args.n, args.seed, use_tip=True, jobs=args.jobs, cases=cases)
    if args.only in (None, "identify", "identify-current"):
        bench_identify(args.n, args.seed, use_tip=False, jobs=args.jobs, cases=cases)
    if args.only in (None, "shift"):
        bench_shift(args.n, args.seed, use_tip=args.straight == "tip", jobs=args.jobs, cases=cases)
    if args.only in (None, "live"):
        bench_live(min(args.n, 40), args.seed, cases=cases)
    if args.only == "live-direct":
        bench_live_direct(args.n, args.seed, jobs=args.jobs, cases=cases)
    if cases is not None:
        import json

        with open(args.cases, "w") as f:
            for rec in cases:
                f.write(json.dumps(rec, default=float) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
