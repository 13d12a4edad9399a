"""Benchmark of a fresh `hyst sim-robot`'s readiness: how long after it prints its device path
it answers the handshake, its first MOVE and a later MOVE.

Run: ``python bench/bench_first_move.py`` (``--runs N``, 7 by default; about 3 s a run). Each
run starts a new `hyst sim-robot` (the calibrated ice-a with its default effects, as users get
it), waits for its path (its readiness signal), connects and times, over the real pty:
HELLO, STATE of knob 1, the first MOVE (0.5 deg at 20 deg/s) and a second one. Prints the median
and the range of each, and the machine's load average.

Why (issue 12): the host's default reply deadline is 1 s, and the device tests failed under
load with "no reply to MOVE ... within 1 s": the first MOVE of a fresh robot used to load (or,
with a cold cache, compile) the twin's numba functions. The emulator now warms a copy of its
twin before it prints its path. To measure the code before that change, run this script with
``PYTHONPATH`` pointing at a checkout of the older code.
"""
from __future__ import annotations

import argparse
import os
import select
import signal
import statistics
import subprocess
import sys
import tempfile
import time

from hystcli.device import Device


def one_run() -> dict[str, float]:
    import hystcli

    # the robot runs the hystcli this script imported (``python -m`` would put the current
    # folder first on its path: a checkout there would shadow PYTHONPATH)
    root = os.path.dirname(os.path.dirname(os.path.abspath(hystcli.__file__)))
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([root, os.environ.get("PYTHONPATH", "")]))
    t0 = time.monotonic()
    proc = subprocess.Popen([sys.executable, "-m", "hystcli", "sim-robot", "--quiet"], env=env,
                            cwd=tempfile.gettempdir(), stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL, text=True)
    try:
        ready, _, _ = select.select([proc.stdout], [], [], 300)
        if not ready:
            raise SystemExit("sim-robot printed no path within 300 s")
        path = proc.stdout.readline().strip()
        out = {"path printed": time.monotonic() - t0}
        t = time.monotonic()
        with Device(path, timeout=60) as dev:
            out["HELLO"] = time.monotonic() - t
            t = time.monotonic()
            dev.state(1)
            out["STATE"] = time.monotonic() - t
            t = time.monotonic()
            dev.move(1, 0.5, 20.0)
            out["first MOVE"] = time.monotonic() - t
            t = time.monotonic()
            dev.move(1, 1.0, 20.0)
            out["second MOVE"] = time.monotonic() - t
        return out
    finally:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        proc.stdout.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=7)
    args = ap.parse_args()
    import hystcli

    print(f"hystcli from {os.path.dirname(hystcli.__file__)}; load average before: "
          f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}; {os.cpu_count()} CPUs")
    runs = [one_run() for _ in range(args.runs)]
    print(f"{'what':<14} {'median':>9} {'min':>9} {'max':>9}   ({args.runs} fresh robots)")
    for key in runs[0]:
        xs = [r[key] for r in runs]
        unit, scale = ("s", 1.0) if key == "path printed" else ("ms", 1000.0)
        print(f"{key:<14} {statistics.median(xs) * scale:>8.1f}{unit} {min(xs) * scale:>8.1f}{unit} "
              f"{max(xs) * scale:>8.1f}{unit}")
    print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
