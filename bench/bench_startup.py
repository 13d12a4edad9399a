#!/usr/bin/env python
"""Start-up time of the command line against `python -c "import numpy"` (issue 12).

Target: `hyst --help`, `hyst --version` and `hyst <cmd> --help` within 4x the time numpy takes to
import. Each command is a fresh process, run in turn with the reference (A B A B ...) so a drift
of the machine's speed hits both alike; the figures are medians over the runs, wall clock, and
the ratio is the median of the per-pair ratios. The machine's load average is printed with them:
on a shared machine the absolute times move, the ratio much less.

Usage:

    python bench/bench_startup.py [--runs 15]
"""
from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import time

REFERENCE = [sys.executable, "-c", "import numpy"]
REFERENCE_NAME = 'python -c "import numpy"'
TARGET = 4.0


def _hyst() -> list[str]:
    exe = shutil.which("hyst")
    return [exe] if exe else [sys.executable, "-m", "hystcli"]


def _wall(argv: list[str]) -> float:
    start = time.perf_counter()
    subprocess.run(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)
    return time.perf_counter() - start


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=15, help="runs of each command (after one warm-up)")
    args = ap.parse_args(argv)
    hyst = _hyst()
    commands = {"hyst --help": hyst + ["--help"], "hyst --version": hyst + ["--version"],
                "hyst identify --help": hyst + ["identify", "--help"],
                "hyst diagnose --help": hyst + ["diagnose", "--help"]}
    load = os.getloadavg()
    print(f"{os.cpu_count()} CPUs, load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} (1, 5, 15 min); "
          f"{args.runs} runs each, medians of wall time")
    worst = 0.0
    ref_all: list[float] = []
    rows = []
    for name, cmd in commands.items():
        _wall(cmd), _wall(REFERENCE)  # warm-up: file caches, numba's and Python's bytecode caches
        pairs = [(_wall(cmd), _wall(REFERENCE)) for _ in range(args.runs)]
        ref_all += [b for _, b in pairs]
        a = statistics.median(p[0] for p in pairs)
        ratio = statistics.median(p[0] / p[1] for p in pairs)
        worst = max(worst, ratio)
        rows.append((name, a, ratio))
    ref = statistics.median(ref_all)
    print(f"{REFERENCE_NAME:24s} {ref * 1000:8.0f} ms")
    for name, a, ratio in rows:
        print(f"{name:24s} {a * 1000:8.0f} ms   {ratio:5.2f}x numpy")
    load = os.getloadavg()
    print(f"worst ratio {worst:.2f} (target <= {TARGET:g}); load average at the end {load[0]:.2f}")
    return 0 if worst <= TARGET else 1


if __name__ == "__main__":
    raise SystemExit(main())
