"""Cost of the streaming compensator (hystcli.Compensator): the median time of one ``step`` from
Python, and the rate of ``steps`` over a block, per model, with the machine's load.

Run: python bench/bench_stream.py [--samples N] [--repeats R]

A step is timed one call at a time (``time.perf_counter_ns`` around each call; the median of
N calls, after a warm-up that also compiles the numba kernels), so a scheduler hiccup moves the
tail, not the median. The block rate is samples per second of ``steps`` on the whole reference,
the median of R repeats. The load is ``os.getloadavg()`` before and after (1-minute average).
"""
from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np

import hystcli
from hystcli.core import effects as E
from hystcli.sim import twin
from hystcli.core.model import Model

CAT = twin.get_catheter("example-a")

CASES = [
    ("base model, 1 knob", (), [1]),
    ("base model, 2 knobs", (), [1, 2]),
    ("rate (input lag), 1 knob", (E.make_effect("rate", "input", tau=0.2),), [1]),
    ("creep + saturation, 1 knob", (E.make_effect("creep", "relax"), E.make_effect("saturation", "smooth")), [1]),
    ("latency 0.05 s (lookahead 5), 1 knob", (E.make_effect("latency", "tracker", delay=0.05),), [1]),
    ("coupling (input) + rate, 2 knobs", (E.make_effect("coupling", "input", gain=0.15),
                                          E.make_effect("rate", "input", tau=0.2)), [1, 2]),
]


def _reference(n: int, knobs: list[int]) -> np.ndarray:
    t = np.arange(n) * 0.01
    r1 = 50 * np.sin(2 * np.pi * 0.04 * t) + 8 * np.sin(2 * np.pi * 0.3 * t)
    if len(knobs) == 1:
        return r1
    return np.column_stack([r1, 30 * np.sin(2 * np.pi * 0.02 * np.sqrt(3) * t)])


def bench(effects, knobs, samples: int, repeats: int) -> tuple[float, float]:
    model = Model(CAT.knobs, CAT.geometry, effects=tuple(e.spec() for e in effects))
    r = _reference(samples, knobs)
    c = hystcli.Compensator(model, knobs, dt=0.01)
    items = [float(x) for x in r] if len(knobs) == 1 else [(float(a), float(b)) for a, b in r]
    for x in items[:2000]:       # warm up (and compile what steps() uses)
        c.step(x)
    c.steps(r[:100])
    c.reset()
    clock = time.perf_counter_ns
    step = c.step
    cost = []
    append = cost.append
    for x in items:
        t0 = clock()
        step(x)
        append(clock() - t0)
    per_step_us = statistics.median(cost) / 1e3
    rates = []
    for _ in range(repeats):
        c.reset()
        t0 = time.perf_counter()
        c.steps(r)
        rates.append(samples / (time.perf_counter() - t0))
    return per_step_us, statistics.median(rates)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=20_000)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    load0 = os.getloadavg()[0]
    print(f"streaming compensator, {args.samples} samples at 100 Hz; {os.cpu_count()} CPUs, "
          f"load average {load0:.2f} (1 min) before")
    print(f"{'model':42s} {'step (median)':>14s} {'steps block rate':>18s}")
    for name, effs, knobs in CASES:
        us, rate = bench(effs, knobs, args.samples, args.repeats)
        print(f"{name:42s} {us:11.2f} us {rate / 1e6:13.3f} M/s")
    print(f"load average {os.getloadavg()[0]:.2f} (1 min) after")


if __name__ == "__main__":
    main()
