"""Identification and shift detection on independent plants, scored per parameter, end to end.

The plants come from modules written from the physics by authors who never read the code under
test (``--plants zoo``: ``plants.zoo.plants``; ``--plants wild``: ``bench/plants/wild.py``, which
breaks the premises the zoo shares with the method). Their records reach the code under test as
run CSV text, as a user's logs would.

Commands scored (``--only``, default all):

* ``identify-tip``: ``identify`` with the tip angle; per parameter d_pos, d_neg, b_pos, b_neg;
* ``identify-current``: ``identify`` from the motor current alone (the paper's procedure);
* ``shift-tip`` / ``shift-current``: the straight sweep identified (tip / current only) by the code
  under test, then ``detect_shift`` on the replay with THAT model (never the true loop): the
  pipeline end to end.

Outcome of each parameter (or offset): **right** (returned as fixed, within the tolerance: 0.5 deg
tip and offsets, 1 deg current-only edges), **wrong** (returned as fixed, off by more), **silent**
(wrong by more than 2 deg at exit 0: the worst outcome), **unfixed** (returned with the record's
interval marked not fixed), **refused** (exit 1). With ``--reference``, every case also gets the
form-agnostic reference fit (``bench/reference.py``), and every unfixed or refused parameter is
split by whether the reference resolves it and holds the truth (the data allow it: ``-allowed``)
or not (``-beyond``).
Coverage: the share of fixed estimates whose interval holds the truth (nominal 95 %).

Run: ``python bench/zoo.py --n 200 --seed 9100000 --jobs 2 [--plants zoo|wild] [--only ...]
[--cases FILE]``; every scored case can be written as a JSON line (``--cases``), and stored case
files pooled and summarised again (``--load FILE [FILE ...]``).
"""
from __future__ import annotations

import argparse
import importlib
import json
import math
import sys
import time
from collections import defaultdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from hystcli.errors import HystError  # noqa: E402
from hystcli.identification import identify  # noqa: E402
from hystcli.io import parse_run  # noqa: E402
from hystcli.shift import ReplayProbe, detect_shift  # noqa: E402

EDGES = ("d_pos", "d_neg", "b_pos", "b_neg")
TOL = {"identify-tip": 0.5, "identify-current": 1.0, "shift-tip": 0.5, "shift-current": 0.5}
SILENT = 2.0
COMMANDS = ("identify-tip", "identify-current", "shift-tip", "shift-current")


def plants_module(name: str):  # noqa: ANN201
    if name == "zoo":
        return importlib.import_module("plants.zoo.plants")
    return importlib.import_module("plants.wild")


def _run(record, name: str, drop_tip: bool = False):  # noqa: ANN001, ANN202
    text = record.csv_text()
    if drop_tip:
        lines = text.splitlines()
        body = [ln for ln in lines if not ln.startswith("#")]
        head = body[0].split(",")
        keep = [i for i, h in enumerate(head) if not h.startswith("y")]
        text = "\n".join([ln for ln in lines if ln.startswith("#")]
                         + [",".join(r.split(",")[i] for i in keep) for r in body]) + "\n"
    return parse_run(text, source=name)


def _ref_dict(fit, names) -> dict:  # noqa: ANN001
    return {n: {"value": fit[n].estimate, "lo": _finite(fit[n].lo), "hi": _finite(fit[n].hi)}
            for n in names if n in fit.params}


def _finite(v: float) -> float | None:
    return float(v) if math.isfinite(v) else None


def reference_identify(case, use_tip: bool) -> dict:  # noqa: ANN001
    """The form-agnostic reference fit of the sweep (bench/reference.py), or the reason it failed."""
    import reference

    col = case.record.columns
    try:
        if use_tip:
            return _ref_dict(reference.tip_reference(col["t"], col["q1"], col["y1"]), EDGES)
        return _ref_dict(reference.current_reference(col["t"], col["q1"], col["c1"]), EDGES)
    except Exception as exc:  # noqa: BLE001 - the reference's own failure is a row, never the end of a run
        return {"failed": str(exc)}


def reference_shift(case) -> dict:  # noqa: ANN001
    import reference

    sw, rp = case.straight_sweep.columns, case.replay.columns
    try:
        sref = reference.current_reference(sw["t"], sw["q1"], sw["c1"])
        off, lo, hi = reference.shift_reference(sref, rp["t"], rp["q1"], rp["c1"])
        return {"offset": {"value": off, "lo": _finite(lo), "hi": _finite(hi)}}
    except Exception as exc:  # noqa: BLE001
        return {"failed": str(exc)}


def score_identify(plants: str, seed: int, use_tip: bool, with_reference: bool = False) -> dict:
    mod = plants_module(plants)
    case = mod.sweep_case(seed)
    truth = case.truth
    out = {"seed": seed, "family": case.family, "command": "identify-tip" if use_tip else "identify-current",
           "truth": {n: getattr(truth, n) for n in EDGES}}
    if with_reference:
        out["reference"] = reference_identify(case, use_tip)
    t0 = time.perf_counter()
    try:
        res = identify(_run(case.record, f"zoo-{seed}", drop_tip=not use_tip), use_tip=use_tip)
        fit = res.fits[1]
        out["result"] = {n: fit.estimates[n].to_dict() for n in EDGES}
        out["warnings"] = list(fit.warnings)
    except HystError as exc:
        out["refused"] = str(exc)
    out["seconds"] = time.perf_counter() - t0
    return out


def score_shift(plants: str, seed: int, use_tip: bool, with_reference: bool = False) -> dict:
    mod = plants_module(plants)
    case = mod.replay_case(seed)
    out = {"seed": seed, "family": case.family, "command": "shift-tip" if use_tip else "shift-current",
           "truth": {"offset": case.offset}}
    if with_reference:
        out["reference"] = reference_shift(case)
    t0 = time.perf_counter()
    try:
        res = identify(_run(case.straight_sweep, f"zoo-{seed}-sweep", drop_tip=not use_tip), use_tip=use_tip)
    except HystError as exc:
        out["refused"] = f"identify: {exc}"
        out["seconds"] = time.perf_counter() - t0
        return out
    try:
        r = detect_shift(res.model, ReplayProbe(_run(case.replay, f"zoo-{seed}-replay"), 1), 1)
        out["result"] = {"offset": {"value": r.offset, "lo": r.offset_lo, "hi": r.offset_hi, "fixed": True}}
    except HystError as exc:
        out["refused"] = str(exc)
    out["seconds"] = time.perf_counter() - t0
    return out


def score_case(args: tuple[str, str, int, bool]) -> dict:
    plants, command, seed, with_reference = args
    if command.startswith("identify"):
        return score_identify(plants, seed, command == "identify-tip", with_reference)
    return score_shift(plants, seed, command == "shift-tip", with_reference)


def reference_allows(case: dict, name: str, tol: float) -> bool | None:
    """Whether the reference resolves ``name`` (half-width within ``tol``) and its interval holds
    the truth: None where the case has no reference. Where the reference misses the truth it is no
    yardstick, and a refusal there is counted as right."""
    ref = case.get("reference")
    if ref is None:
        return None
    e = ref.get(name)
    if e is None or e["lo"] is None or e["hi"] is None:
        return False
    true = case["truth"][name]
    return 0.5 * (e["hi"] - e["lo"]) <= tol and e["lo"] <= true <= e["hi"]


def outcomes(case: dict) -> dict[str, str]:
    """Per parameter: right / wrong / silent, or unfixed / refused, split by whether the reference
    says the data allow the parameter (``-allowed``) or not (``-beyond``) where it was run."""
    tol = TOL[case["command"]]
    out = {}
    for name, true in case["truth"].items():
        allowed = reference_allows(case, name, tol)
        tag = "" if allowed is None else ("-allowed" if allowed else "-beyond")
        if "refused" in case:
            out[name] = "refused" + tag
            continue
        e = case["result"][name]
        if not e["fixed"]:
            out[name] = "unfixed" + tag
            continue
        err = abs(e["value"] - true)
        out[name] = "right" if err <= tol else ("silent" if err > SILENT else "wrong")
    return out


def covered(case: dict) -> dict[str, bool]:
    """Per fixed estimate: whether its interval holds the truth."""
    if "refused" in case:
        return {}
    out = {}
    for name, true in case["truth"].items():
        e = case["result"][name]
        if e["fixed"]:
            lo = -math.inf if e["lo"] is None else e["lo"]
            hi = math.inf if e["hi"] is None else e["hi"]
            out[name] = lo <= true <= hi
    return out


def _rms_lines(cs: list[dict]) -> list[str]:
    """RMS error of the fixed estimates beside the reference's on the same cases (where the
    reference resolves the parameter): the ratio the issue bounds at 1.5."""
    out = []
    names = sorted({n for c in cs for n in c["truth"]})
    for name in names:
        ours, ref = [], []
        for c in cs:
            if "result" not in c or not c["result"][name]["fixed"]:
                continue
            r = (c.get("reference") or {}).get(name)
            if not reference_allows(c, name, TOL[c["command"]]) or r is None:
                continue
            ours.append(c["result"][name]["value"] - c["truth"][name])
            ref.append(r["value"] - c["truth"][name])
        if ours:
            a = math.sqrt(sum(e * e for e in ours) / len(ours))
            b = math.sqrt(sum(e * e for e in ref) / len(ref))
            out.append(f"  {name:7s} RMS error {a:.3f} deg, reference's {b:.3f} deg on the same {len(ours)} cases"
                       + (f" (ratio {a / b:.2f})" if b > 0 else ""))
    return out


def summarise(cases: list[dict]) -> str:
    lines = []
    by_cmd = defaultdict(list)
    for c in cases:
        by_cmd[c["command"]].append(c)
    for cmd, cs in by_cmd.items():
        lines.append(f"== {cmd}: {len(cs)} cases, median {sorted(c['seconds'] for c in cs)[len(cs) // 2]:.2f} s")
        counts = defaultdict(lambda: defaultdict(int))
        cover = defaultdict(lambda: [0, 0])
        worst = defaultdict(float)
        resolved = defaultdict(lambda: [0, 0])
        for c in cs:
            for name, o in outcomes(c).items():
                counts[name][o] += 1
                if reference_allows(c, name, TOL[cmd]):
                    resolved[name][0] += int(o == "right")
                    resolved[name][1] += 1
                if o in ("wrong", "silent"):
                    worst[name] = max(worst[name], abs(c["result"][name]["value"] - c["truth"][name]))
            for name, ok in covered(c).items():
                cover[name][0] += int(ok)
                cover[name][1] += 1
        for name, cnt in counts.items():
            n = sum(cnt.values())
            right = cnt["right"]
            fixed = right + cnt["wrong"] + cnt["silent"]
            cov = cover[name]
            unfixed = sum(v for k, v in cnt.items() if k.startswith("unfixed"))
            refused = sum(v for k, v in cnt.items() if k.startswith("refused"))
            lines.append(f"  {name:7s} right {right}/{n} ({100 * right / n:.1f} %), of fixed {right}/{fixed}; "
                         f"wrong {cnt['wrong']}, silent {cnt['silent']} (worst {worst[name]:.2f}), "
                         f"unfixed {unfixed}, refused {refused}; "
                         f"coverage {cov[0]}/{cov[1]}" + (f" ({100 * cov[0] / cov[1]:.1f} %)" if cov[1] else ""))
            if any("reference" in c for c in cs):
                got, allowed = resolved[name]
                share = f" ({100 * got / allowed:.1f} %)" if allowed else ""
                lines.append(f"          where the reference resolves it: right {got}/{allowed}{share}; not fixed or "
                             f"refused where it does not: {cnt['unfixed-beyond'] + cnt['refused-beyond']}")
        lines += _rms_lines(cs)
        if cmd.startswith("shift"):
            nulls = [c for c in cs if c["truth"]["offset"] == 0.0 and "result" in c]
            if nulls:
                worst_null = max(abs(c["result"]["offset"]["value"]) for c in nulls)
                lines.append(f"  nulls: {len(nulls)} returned, worst |offset| {worst_null:.2f} deg")
        fam = defaultdict(lambda: defaultdict(int))
        for c in cs:
            for o in outcomes(c).values():
                fam[c["family"]][o] += 1
        lines.append("  per family (right/wrong+silent/unfixed+refused): " + "; ".join(
            f"{f} {d['right']}/{d['wrong'] + d['silent']}/{d['unfixed'] + d['refused']}" for f, d in sorted(fam.items())))
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plants", choices=("zoo", "wild"), default="zoo")
    ap.add_argument("--n", type=int, default=100)
    ap.add_argument("--seed", type=int, default=100000)
    ap.add_argument("--only", choices=COMMANDS, action="append")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--scheduler", default=None, help="a dask scheduler (tcp://host:8786) instead of local processes")
    ap.add_argument("--cases", type=Path)
    ap.add_argument("--load", type=Path, nargs="+", help="summarise stored --cases files (pooled) instead of running")
    ap.add_argument("--reference", action="store_true",
                    help="also fit bench/reference.py's form-agnostic reference to every case (slow)")
    args = ap.parse_args()
    if args.load:
        print(summarise([json.loads(ln) for f in args.load for ln in f.read_text().splitlines() if ln.strip()]))
        return
    commands = args.only or list(COMMANDS)
    work = [(args.plants, cmd, s, args.reference) for cmd in commands for s in range(args.seed, args.seed + args.n)]
    t0 = time.perf_counter()
    if args.jobs > 1 or args.scheduler:
        from hystcli.batch.engine import imap  # hyst batch's engine: local processes or a dask cluster

        cases = list(imap(score_case, work, jobs=args.jobs, scheduler=args.scheduler))
    else:
        cases = [score_case(w) for w in work]
    if args.cases is not None:
        args.cases.write_text("".join(json.dumps(c) + "\n" for c in cases))
    print(f"plants {args.plants}, seeds {args.seed}..{args.seed + args.n - 1}, {time.perf_counter() - t0:.0f} s")
    print(summarise(cases))


if __name__ == "__main__":
    main()
