"""How the reference fits (bench/reference.py) do on a plant module's cases: resolution, coverage,
time.

For every case (seeds ``--seed`` .. ``--seed + n - 1``, seed s of family ``FAMILIES[s % len]``) and
each part asked for:

* ``tip``: :func:`reference.tip_reference` on the sweep's tip; per parameter, whether its 95 %
  interval is resolved at 0.5 deg (0.05 for omega) and whether it contains the truth.
* ``current``: :func:`reference.current_reference` on the sweep's current; ``d_pos``/``d_neg``
  resolved at 1 deg and covered (against the current's own edges ``current_edge_pos/neg`` where
  the module's factors give them apart from the tip's); ``b_pos``/``b_neg`` the same, counted only on plants whose
  current law carries the backlash (``current_shows_backlash`` where the module says).
* ``shift``: :func:`reference.shift_reference` on ``replay_case``: the replay's offset against
  the current reference of its straight sweep; resolved at 0.5 deg and covered.

Coverage is given over every case (an open interval covers) and over the resolved ones.
Times are CPU seconds of the fitting process (``time.process_time``), medians per case.

Run: ``python bench/reference_study.py --n 200 --jobs 2 [--only tip current shift]
[--plants plants.zoo.plants | bench/plants/wild.py] [--seed 0] [--cases FILE]``;
``--report FILE...`` pools the cases of earlier ``--cases`` files and prints the tables.
"""
from __future__ import annotations

import argparse
import importlib
import importlib.util
import json
import math
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import reference as R  # noqa: E402

TIP_TOL = {"omega": 0.05}
TIP_TOL_DEG = 0.5
CURRENT_TOL = 1.0
SHIFT_TOL = 0.5


def load_plants(spec: str):
    """A plant module by dotted name or by file path."""
    if spec.endswith(".py"):
        path = Path(spec).resolve()
        if (path.parent / "__init__.py").exists():     # a module of a package: import it as such
            sys.path.insert(0, str(path.parent.parent))
            return importlib.import_module(f"{path.parent.name}.{path.stem}")
        mod_spec = importlib.util.spec_from_file_location(path.stem, path)
        mod = importlib.util.module_from_spec(mod_spec)
        sys.modules[path.stem] = mod
        mod_spec.loader.exec_module(mod)
        return mod
    return importlib.import_module(spec)


def _iv(iv: R.ParamInterval) -> dict:
    return {"estimate": iv.estimate, "lo": iv.lo, "hi": iv.hi}


def _timed(out: dict, part: str, fit_fn, *args):
    """fit_fn(*args) with its CPU time (and terms, or refusal) noted in out under part."""
    c0 = time.process_time()
    fit = None
    try:
        fit = fit_fn(*args)
        out[f"{part}_terms"] = list(fit.terms)
    except R.RefFitError as exc:
        out[f"{part}_error"] = str(exc)
    out[f"{part}_cpu"] = time.process_time() - c0
    return fit


def run_case(seed: int, family: str, spec: str, parts: tuple[str, ...]) -> dict:
    mod = load_plants(spec)
    out: dict = {"seed": seed, "family": family}
    sweep_fit = col = None
    if "tip" in parts or "current" in parts:
        case = mod.sweep_case(seed, family)
        col = case.record.columns
        truth = case.truth.as_dict() if hasattr(case.truth, "as_dict") else dict(case.truth)
        out["truth"] = truth
        out["shows_backlash"] = bool(getattr(case, "current_shows_backlash", True))
        f = getattr(case, "factors", {}) or {}
        if "current_edge_pos" in f:      # a plant whose current's edges are not the tip's
            out["current_truth"] = {"d_pos": float(f["current_edge_pos"]), "d_neg": float(f["current_edge_neg"])}
        if "tip" in parts and "y1" in col:
            fit = _timed(out, "tip", R.tip_reference, col["t"], col["q1"], col["y1"])
            if fit is not None:
                out["tip"] = {p: _iv(fit[p]) for p in R.TIP_PARAMS}
        if "current" in parts:
            fit = sweep_fit = _timed(out, "current", R.current_reference, col["t"], col["q1"], col["c1"])
            if fit is not None:
                out["current"] = {p: _iv(fit[p]) for p in R.CURRENT_PARAMS}
    if "shift" in parts:
        rc = mod.replay_case(seed, family)
        sw, rp = rc.straight_sweep.columns, rc.replay.columns
        out["offset"] = float(rc.offset)
        c0 = time.process_time()
        try:
            # the replay's straight sweep is the sweep case's record: its fit is reused
            same = sweep_fit is not None and all(np.array_equal(sw[k], col[k]) for k in ("t", "q1", "c1"))
            ref = sweep_fit if same else R.current_reference(sw["t"], sw["q1"], sw["c1"])
            off, lo, hi = R.shift_reference(ref, rp["t"], rp["q1"], rp["c1"])
            out["shift"] = {"estimate": off, "lo": lo, "hi": hi}
        except R.RefFitError as exc:
            out["shift_error"] = str(exc)
        out["shift_cpu"] = time.process_time() - c0
    return out


def _call(args):
    return run_case(*args)


def _resolved(iv: dict, tol: float) -> bool:
    return math.isfinite(iv["lo"]) and math.isfinite(iv["hi"]) and 0.5 * (iv["hi"] - iv["lo"]) <= tol


def _covers(iv: dict, truth: float) -> bool:
    return iv["lo"] <= truth <= iv["hi"]


def _table(title: str, stats: dict) -> str:
    lines = [title, f"{'group':28s}{'n':>6s}{'resolved':>10s}{'covered':>10s}{'cov|res':>10s}{'|err| med res':>15s}"]
    for key in sorted(stats):
        s = stats[key]
        n, nr = s["n"], s["nres"]
        med = float(np.median(s["err"])) if s["err"] else math.nan
        lines.append(f"{key:28s}{n:6d}{nr / n if n else math.nan:10.3f}{s['cov'] / n if n else math.nan:10.3f}"
                     f"{s['covres'] / nr if nr else math.nan:10.3f}{med:15.3f}")
    return "\n".join(lines)


def report(rows: list[dict]) -> str:
    out = []
    for part, names in (("tip", R.TIP_PARAMS), ("current", R.CURRENT_PARAMS), ("shift", ("offset",))):
        stats: dict = defaultdict(lambda: {"n": 0, "nres": 0, "cov": 0, "covres": 0, "err": []})
        cpu = [r[f"{part}_cpu"] for r in rows if f"{part}_cpu" in r]
        errors = sum(f"{part}_error" in r for r in rows)
        if not cpu:
            continue
        for r in rows:
            if part not in r:
                continue
            for p in names:
                if part == "current" and p.startswith("b_") and not r["shows_backlash"]:
                    continue
                iv = r[part] if part == "shift" else r[part][p]
                truth = r["offset"] if part == "shift" else r["truth"][p]
                if part == "current" and p in r.get("current_truth", {}):
                    truth = r["current_truth"][p]
                tol = {"tip": TIP_TOL.get(p, TIP_TOL_DEG), "current": CURRENT_TOL, "shift": SHIFT_TOL}[part]
                res, cov = _resolved(iv, tol), _covers(iv, truth)
                for key in (p, f"{p} / {r['family']}"):
                    s = stats[key]
                    s["n"] += 1
                    s["nres"] += res
                    s["cov"] += cov
                    s["covres"] += res and cov
                    if res:
                        s["err"].append(abs(iv["estimate"] - truth))
        out.append(_table(f"== {part}: {len(cpu)} cases, {errors} refused by the reference; CPU s per case "
                          f"median {np.median(cpu):.2f}, p90 {np.quantile(cpu, 0.9):.2f}, max {max(cpu):.2f}",
                          stats))
    return "\n\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=200)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--plants", default="plants.zoo.plants")
    ap.add_argument("--only", nargs="+", choices=("tip", "current", "shift"), default=("tip", "current", "shift"))
    ap.add_argument("--cases", type=Path, default=None, help="write every case as a JSON line")
    ap.add_argument("--report", type=Path, nargs="+", default=None,
                    help="only pool and print the cases of these --cases files")
    args = ap.parse_args(argv)
    if args.report:
        rows = [json.loads(line) for f in args.report for line in f.read_text().splitlines() if line]
        print(f"{len(rows)} cases from {' '.join(str(f) for f in args.report)}")
        print(report(rows))
        return 0
    mod = load_plants(args.plants)
    fams = tuple(mod.FAMILIES)
    jobs = [(s, fams[s % len(fams)], args.plants, tuple(args.only))
            for s in range(args.seed, args.seed + args.n)]
    t0 = time.perf_counter()
    if args.jobs > 1:
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(args.jobs) as pool:
            rows = list(pool.map(_call, jobs, chunksize=1))
    else:
        rows = [_call(j) for j in jobs]
    if args.cases:
        tmp = args.cases.with_suffix(args.cases.suffix + ".tmp")
        tmp.write_text("".join(json.dumps(r) + "\n" for r in rows))
        tmp.replace(args.cases)
    print(f"{args.plants}: {args.n} cases from seed {args.seed}, parts {' '.join(args.only)}, "
          f"{args.jobs} jobs, {time.perf_counter() - t0:.0f} s wall")
    print(report(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
