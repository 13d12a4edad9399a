"""Speed of effects.predict (what the diagnosis calls thousands of times) and of the live twin.

Run: python bench/bench_effects.py   (prints milliseconds per call)
"""
from __future__ import annotations

import time

import numpy as np

from hystcli.core import effects as E
from hystcli.sim import live as live_twin
from hystcli.sim import twin
from hystcli.core.run import Run
from hystcli.core.model import Model

CAT = twin.get_catheter("example-a")


def _time(f, n):
    f()  # compile / warm up
    t0 = time.perf_counter()
    for _ in range(n):
        f()
    return (time.perf_counter() - t0) / n * 1e3


def main() -> None:
    t = np.arange(50_000) / 500.0
    q1 = 40 * np.sin(0.5 * t) + 10 * np.sin(1.3 * t)
    q2 = 30 * np.sin(0.8 * t)
    run = Run({"t": t, "q1": q1, "q2": q2, "y1": np.zeros_like(t)}, {"shape": "alpha=90,theta=0"})
    print(f"predict, 2 knobs x {t.size} samples:")
    for names in ([], ["friction"], ["rate"], ["creep"], ["latency"], ["coupling"], ["saturation"],
                  ["contact"], list(E.EFFECTS)):
        effs = tuple(E.make_effect(n, **({"wall": 30.0} if n == "contact" else {})) for n in names)
        m = Model(CAT.knobs, CAT.geometry, effects=tuple(e.spec() for e in effs))
        ms = _time(lambda: E.predict(m, run), 20)
        print(f"  {'+'.join(names) or 'base model':60s} {ms:7.2f} ms")
    live = live_twin.LiveTwin(CAT, seed=0)
    ms = _time(lambda: live.move(1, float(np.random.uniform(-30, 30))), 50)
    print(f"LiveTwin.move (~1000 samples at dt=1 ms, both knobs): {ms:.2f} ms")


if __name__ == "__main__":
    main()
