"""Record-by-record comparison of two ``bench/zoo.py --cases`` files (two codes on the same seeds).

Every change to identify or detect-shift is judged per record, not on a rate: a rate that stays
put can hide a right answer lost for a wrong one mended. This lists, per kind of case (tip-fit
identify, current-only identify, detect-shift, live), how many records moved from one outcome to
another, and each record whose outcome changed or whose estimate moved (an offset by more than
``--tol`` deg, any parameter by more than that), with the refusal messages where one side refused.

Run: ``python bench/zoo_compare.py before.jsonl after.jsonl [--tol 0.01] [--quiet]``.
"""
from __future__ import annotations

import argparse
import json
import sys
from collections import Counter
from pathlib import Path


def kind(rec: dict) -> str:
    """Which bench a record came from."""
    if rec.get("live"):
        return "live"
    if "tip" in rec:
        return "identify, tip" if rec["tip"] else "identify, current only"
    return "detect-shift" if rec.get("straight", "tip") == "tip" else "detect-shift, current-only models"


def load(path: Path) -> dict[tuple[str, int], dict]:
    """The records of one ``--cases`` file, keyed by (kind, seed)."""
    out = {}
    with open(path) as f:
        for line in f:
            if line.strip():
                rec = json.loads(line)
                out[(kind(rec), int(rec["seed"]))] = rec
    return out


def moved(a: dict, b: dict, tol: float) -> str | None:
    """How the estimate moved between two records with the same outcome, or None."""
    if "offset" in a and "offset" in b and abs(a["offset"] - b["offset"]) > tol:
        return f"offset {a['offset']:+.3f} -> {b['offset']:+.3f} (true {a['truth']:+.3f})"
    pa, pb = a.get("params") or {}, b.get("params") or {}
    diffs = [f"{p} {pa[p]:+.3f} -> {pb[p]:+.3f} (true {a['truth'][p]:+.3f})"
             for p in pa if p in pb and abs(pa[p] - pb[p]) > tol]
    if set(a.get("stderr", {})) != set(b.get("stderr", {})):
        diffs.append(f"claimed {sorted(a.get('stderr', {}))} -> {sorted(b.get('stderr', {}))}")
    return "; ".join(diffs) or None


def summary(rec: dict) -> str:
    """A record's outcome with its estimate or the start of its refusal."""
    if "offset" in rec:
        return f"{rec['outcome']} ({rec['offset']:+.3f}, true {rec['truth']:+.3f})"
    if "error" in rec:
        worst = max(rec["error"].items(), key=lambda kv: abs(kv[1]), default=("", 0.0))
        return f"{rec['outcome']} (worst {worst[0]} {worst[1]:+.2f})"
    msg = rec.get("message", "")
    msg = " ".join(msg) if isinstance(msg, list) else msg
    return f"{rec['outcome']}: {msg[:160]}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("before", type=Path)
    ap.add_argument("after", type=Path)
    ap.add_argument("--tol", type=float, default=0.01, help="smallest move (deg) of an estimate listed")
    ap.add_argument("--quiet", action="store_true", help="the transition counts only")
    args = ap.parse_args(argv)
    a, b = load(args.before), load(args.after)
    common = sorted(set(a) & set(b))
    if not common:
        print("no record in common", file=sys.stderr)
        return 1
    trans: dict[str, Counter] = {}
    lines = []
    for key in common:
        ra, rb = a[key], b[key]
        trans.setdefault(key[0], Counter())[(ra["outcome"], rb["outcome"])] += 1
        if ra["outcome"] != rb["outcome"]:
            lines.append(f"{key[0]:24s} {key[1]} {ra['family']:16s} {summary(ra)}\n{'':24s} {'':{len(str(key[1]))}s} "
                         f"{'':16s} -> {summary(rb)}")
        else:
            m = moved(ra, rb, args.tol)
            if m:
                lines.append(f"{key[0]:24s} {key[1]} {ra['family']:16s} {ra['outcome']}: {m}")
    for k, c in sorted(trans.items()):
        same = sum(v for (x, y), v in c.items() if x == y)
        print(f"{k}: {sum(c.values())} records, {same} with the same outcome")
        for (x, y), v in sorted(c.items()):
            if x != y:
                print(f"  {x} -> {y}: {v}")
    if not args.quiet:
        for line in lines:
            print(line)
    only = len(set(a) ^ set(b))
    if only:
        print(f"({only} records in one file only, not compared)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
