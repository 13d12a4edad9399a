"""Held-out prediction on the real MRDLab data (issue 6, Must-show 1): writes sample_data/real/STUDY.md.

Conditions. Every file of the real data has its own (frequency, load, pitch), so a "condition" is
a group of files that share everything but one factor, and the held-out files differ from the
identification file in that factor only:

- ``load_freq``: one condition per load level (10, 20, 30, 40 %); identified on the 0.3 Hz file,
  held out the 0.1 Hz and 0.5 Hz files (the frequency varies).
- ``pitch_N``: one condition per wrist pitch; identified on the 0.3 Hz, 40 % file, held out the
  20 % and 80 % files at 0.3 Hz and the 20 % file at 0.5 Hz (load and frequency vary).

The identification file is the middle of its condition, so the held-out files lie on both sides.

Columns (held-out RMSE of the jaw angle, deg, pooled over the held-out samples):
(a) static linear fit ``y = g q + o`` (numpy.polyfit on the identification file);
(b) ``identify(run)`` (the tip fit of the DESIGN.md model) on the identification file, then
    ``predict_tip`` on the held-out files (each starts from its own first measured y, as
    ``hyst predict`` does);
(c) (b) plus the effects ``diagnose`` adds, diagnosed on the identification file alone (cut into
    two halves, so the held-out files stay unseen), then predicted the same way.

Run: ``python scripts/real_study.py [--no-diagnose]`` (after ``python scripts/import_real.py``).
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from hystcli.compensation import predict_tip  # noqa: E402
from hystcli.identify import identify  # noqa: E402
from hystcli.io import Run, atomic_write_text, read_run  # noqa: E402

REAL = ROOT / "sample_data" / "real"

# (series, condition label, identification file, held-out files)
CONDITIONS: list[tuple[str, str, str, tuple[str, ...]]] = [
    ("load_freq", f"load {10 * (y + 1)} %", f"2{y}.csv", (f"0{y}.csv", f"4{y}.csv")) for y in range(4)
] + [
    (f"pitch_{n}", f"pitch {p:+d} deg", "001.csv", ("000.csv", "003.csv", "010.csv"))
    for n, p in zip(range(1, 6), (60, 30, 0, -30, -60))
]


def halves(run: Run) -> list[Run]:
    """The run cut in two at its middle sample (two runs for diagnose)."""
    n = len(run)
    out = []
    for i, sl in enumerate((slice(0, n // 2), slice(n // 2, n))):
        cols = {k: np.asarray(v)[sl] for k, v in run.columns.items()}
        cols["t"] = cols["t"] - cols["t"][0]
        meta = dict(run.meta)
        meta["condition"] = f"{meta.get('condition', '')} half {i + 1}"
        out.append(Run(cols, meta, f"{run.source}[half {i + 1}]"))
    return out


def sse(pred: np.ndarray, y: np.ndarray) -> float:
    e = np.asarray(pred) - np.asarray(y)
    return float(e @ e)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--no-diagnose", action="store_true", help="leave column (c) out")
    ap.add_argument("--out", default=str(REAL / "STUDY.md"))
    args = ap.parse_args(argv)
    diagnose = None
    if not args.no_diagnose:
        try:
            from hystcli.diagnose import diagnose
        except ImportError:  # pragma: no cover
            diagnose = None
    rows = []
    tot = {"a": 0.0, "b": 0.0, "c": 0.0, "n": 0}
    t0 = time.time()
    for series, label, ident_name, held in CONDITIONS:
        run = read_run(REAL / series / ident_name)
        q, y = run["q1"], run["y1"]
        g = np.polyfit(q, y, 1)
        ident = identify(run)
        fit, model = ident.fits[1], ident.model
        ins_lin = math.sqrt(sse(np.polyval(g, q), y) / q.size)
        aug, effects = None, "-"
        if diagnose is not None:
            diag = diagnose(model, halves(run))
            aug = diag.model
            effects = ", ".join(f"{e.name}({', '.join(f'{k}={v:.3g}' for k, v in e.params.items())})"
                                for e in aug.effects) or "none"
        s = {"a": 0.0, "b": 0.0, "c": 0.0, "n": 0}
        for name in held:
            h = read_run(REAL / series / name)
            s["a"] += sse(np.polyval(g, h["q1"]), h["y1"])
            s["b"] += sse(predict_tip(model, h)[1], h["y1"])
            if aug is not None:
                s["c"] += sse(predict_tip(aug, h)[1], h["y1"])
            s["n"] += len(h)
        for key in tot:
            tot[key] += s[key]
        r = {key: math.sqrt(s[key] / s["n"]) for key in "abc"}
        rows.append((series, label, ident_name, ", ".join(held), fit.start, fit.rmse / ins_lin,
                     r["a"], r["b"], r["c"] if aug is not None else None, effects))
        print(f"{series} {label}: a={r['a']:.3f} b={r['b']:.3f}"
              + (f" c={r['c']:.3f} [{effects}]" if aug is not None else ""), file=sys.stderr)
    ra, rb = (math.sqrt(tot[k] / tot["n"]) for k in "ab")
    rc = math.sqrt(tot["c"] / tot["n"]) if diagnose is not None else None
    has_c = diagnose is not None
    lines = ["# Held-out prediction on the real MRDLab data (issue 6, Must-show 1)", "",
             "Made by `python scripts/real_study.py` (see its docstring for the conditions). Jaw angle "
             "RMSE (deg) on the held-out files of each condition, pooled over their samples. (a) static "
             "linear fit on the identification file; (b) `identify` (tip fit of the DESIGN.md model) on "
             "the identification file, `predict` on the held-out files; "
             + ("(c) (b) plus the effects `diagnose` adds, diagnosed on the identification file alone "
                "(its two halves as two runs)." if has_c else "(c) left out (`--no-diagnose`)."), "",
             "| series | condition | identified on | held out | start | in-sample (b)/(a) | (a) linear | "
             "(b) model | " + ("(c) model + effects | effects | (b)/(a) | (c)/(a) |" if has_c else "(b)/(a) |"),
             "|---|---|---|---|---|---|---|---|" + ("---|---|---|---|" if has_c else "---|")]
    for series, label, iname, held, start, ins, a, b, c, eff in rows:
        line = f"| {series} | {label} | {iname} | {held} | {start} | {ins:.2f} | {a:.3f} | {b:.3f} | "
        line += f"{c:.3f} | {eff} | {b / a:.2f} | {c / a:.2f} |" if has_c else f"{b / a:.2f} |"
        lines.append(line)
    lines += ["", f"Overall (pooled over all held-out samples): (a) {ra:.3f} deg, (b) {rb:.3f} deg, "
              f"(b)/(a) = {rb / ra:.2f} (target <= 0.40)"
              + (f", (c) {rc:.3f} deg, (c)/(a) = {rc / ra:.2f} (target <= 0.30)." if has_c else "."), ""]
    text = "\n".join(lines)
    print(text)
    print(f"({time.time() - t0:.0f} s)", file=sys.stderr)
    atomic_write_text(args.out, text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
