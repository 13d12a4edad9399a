"""Benchmark: forward and inverse throughput of one knob's model (issue 2, Must-show 5).

Run on demand, not in CI:  python bench/bench_model.py [--samples 10000000] [--repeat 5]
Prints samples per second (best of --repeat) on one core. Targets: forward >= 50 M/s,
inverse >= 20 M/s.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from hystcli.core.params import KnobModel


def best_rate(fn, arg, n, repeat):
    fn(arg[:16])  # compile (numba) outside the timing
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn(arg)
        best = min(best, time.perf_counter() - t0)
    return n / best, best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--samples", type=int, default=10_000_000)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    n = args.samples
    # a realistic knob trajectory: slow sines with noise, many reversals
    t = np.arange(n) / 1000.0
    q = 40 * np.sin(2 * np.pi * 0.1 * t) + 10 * np.sin(2 * np.pi * 1.3 * t) + rng.normal(0, 0.2, n)
    knob = KnobModel(d_pos=9.1, d_neg=-8.7, b_pos=6.2, b_neg=5.9, omega=1.45, h_pos=-4.0, h_neg=4.2, offset=3.0)
    r = knob.forward(q)
    fwd, tf = best_rate(knob.forward, q, n, args.repeat)
    inv, ti = best_rate(knob.inverse, r, n, args.repeat)
    print(f"samples: {n:,}")
    print(f"forward: {fwd / 1e6:8.1f} M samples/s  ({tf * 1e3:.1f} ms)   target >= 50")
    print(f"inverse: {inv / 1e6:8.1f} M samples/s  ({ti * 1e3:.1f} ms)   target >= 20")
    err = np.max(np.abs(knob.forward(knob.inverse(r)) - r))
    print(f"max |forward(inverse(r)) - r| = {err:.2e} deg")


if __name__ == "__main__":
    main()
