"""Benchmark of ``identify`` on a 10-minute 1 kHz sweep (issue 2, Must-show 5: target < 2 s).

Run on demand: ``python bench/bench_identify.py``. Simulates the paper's sweep (+-40 deg, 40 deg/s
peak) on the virtual catheter ``ice-a`` for 600 s at 1 kHz (about 95 cycles, 600k samples, one
knob) with sensor noise and the 20 Hz filter, then times ``identify`` with the tip angle and on
the current alone (best of a few repeats, after one warm-up call that compiles the numba
kernels), once with a 20-replicate bootstrap, and prints the seconds and the recovered parameters
against the true ones.
"""
from __future__ import annotations

import math
import time

from hystcli.sim import twin
from hystcli.identification import identify

DURATION_S = 600.0
FS = 1000.0
REPEATS = 3


def main() -> None:
    cat = twin.get_catheter("example-a")
    amplitude, peak_speed = 40.0, 40.0
    cycles = DURATION_S * (peak_speed / amplitude) / (2 * math.pi)
    t, q = twin.sweep(amplitude=amplitude, cycles=cycles, peak_speed=peak_speed, fs=FS)
    run = twin.simulate(cat, t, {1: q}, seed=0, effects=())
    print(f"sweep: {len(run)} samples, {t[-1]:.0f} s at {FS:.0f} Hz, {cycles:.1f} cycles")
    identify(run)  # warm-up: numba compilation and caches
    true = cat.knobs[1]
    for label, kwargs in (("with tip angle", {}), ("current only", {"use_tip": False})):
        best = math.inf
        for _ in range(REPEATS):
            t0 = time.perf_counter()
            res = identify(run, **kwargs)
            best = min(best, time.perf_counter() - t0)
        m = res.fits[1].model
        print(f"identify ({label}): {best:.3f} s (best of {REPEATS}; target < 2 s)")
        for name in ("d_pos", "d_neg", "b_pos", "b_neg", "omega"):
            err = res.fits[1].stderr.get(name)
            unc = f"+- {err:.3f}" if err is not None else "(fixed, not identified)"
            print(f"  {name:6s} true {getattr(true, name):8.3f}  identified {getattr(m, name):8.3f}  {unc}")
    t0 = time.perf_counter()
    identify(run, bootstrap=20, seed=0)
    print(f"identify (with tip angle, bootstrap 20 over cycles): {time.perf_counter() - t0:.3f} s")


if __name__ == "__main__":
    main()
