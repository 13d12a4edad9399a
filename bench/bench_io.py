#!/usr/bin/env python
"""Reading a big run CSV: `read_run` (what `hyst identify` does before its fit) and `hyst import`.

Targets (issue 51): a 2M-row run CSV (t, q1, y1, c1) is read in under 3 s, with a peak memory
under 4x the file's size, by `read_run` and by `hyst import` (whole process: read, convert,
write). The file is made here once (seeded: the same bytes every time) in the folder given.

Each figure is a fresh process timed from outside, wall clock and peak resident memory (the
kernel's ru_maxrss of the child), run in turn with `python -c "import numpy"` (A B A B ...) so a
drift of the machine's speed hits both alike; medians over the runs are printed with the load
average. The reading process does nothing but read, so its peak is the reader's.

Usage:

    python bench/bench_io.py [--rows 2000000] [--runs 5] [--dir /tmp/hyst-bench-io]
"""
from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

REFERENCE = [sys.executable, "-c", "import numpy"]


def make_csv(path: Path, rows: int, seed: int = 0) -> None:
    """A sweep-like run: t at 1 kHz, a knob sine, a tip and a current with noise; 4 decimals."""
    import numpy as np

    rng = np.random.default_rng(seed)
    t = np.arange(rows) / 1000.0
    q = 40.0 * np.sin(2 * np.pi * 0.05 * t)
    y = 1.3 * np.clip(np.abs(q) - 9.0, 0.0, None) * np.sign(q) + rng.normal(0.0, 0.3, rows)
    c = 100.0 + 2.0 * q + rng.normal(0.0, 1.0, rows)
    tmp = path.with_suffix(".part")
    with open(tmp, "w") as f:
        f.write("# motion: sweep\n# catheter: bench\nt,q1,y1,c1\n")
        step = 200_000
        for i in range(0, rows, step):
            block = np.column_stack([t[i:i + step], q[i:i + step], y[i:i + step], c[i:i + step]])
            np.savetxt(f, block, fmt=("%.3f", "%.4f", "%.4f", "%.3f"), delimiter=",")
    tmp.replace(path)


def _run(argv: list[str], env: dict | None = None) -> tuple[float, float]:
    """Wall seconds and peak resident MiB (the kernel's ru_maxrss of this child) of one run."""
    start = time.perf_counter()
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - start
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(argv)} exited {proc.returncode}")
    return wall, usage.ru_maxrss / 1024.0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=2_000_000)
    ap.add_argument("--runs", type=int, default=5, help="runs of each command (after one warm-up)")
    ap.add_argument("--dir", type=Path, default=Path("/tmp/hyst-bench-io"))
    args = ap.parse_args(argv)
    args.dir.mkdir(parents=True, exist_ok=True)
    csv = args.dir / f"run_{args.rows}.csv"
    if not csv.exists():
        make_csv(csv, args.rows)
    size = csv.stat().st_size / 2**20
    hyst = [shutil.which("hyst") or sys.executable, *([] if shutil.which("hyst") else ["-m", "hystcli"])]
    out = args.dir / "imported.csv"
    commands = {
        "read_run": [sys.executable, "-c", "import sys; from hystcli.io import read_run; read_run(sys.argv[1])",
                     str(csv)],
        "hyst import": hyst + ["import", str(csv), "--map", "t=1,q1=2,y1=3,c1=4", "--skip", "3", "-o", str(out),
                               "-q"],
    }
    load = os.getloadavg()
    print(f"{os.cpu_count()} CPUs, load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}; {csv.name}: "
          f"{args.rows} rows, {size:.1f} MiB; {args.runs} runs each, medians")
    print(f"{'command':<14} {'wall s':>8} {'peak MiB':>9} {'peak/size':>9} {'import numpy s':>15} {'ratio':>7}")
    for name, cmd in commands.items():
        _run(cmd), _run(REFERENCE)  # warm-up: file cache, bytecode caches
        pairs = [(_run(cmd), _run(REFERENCE)) for _ in range(args.runs)]
        wall = statistics.median(a[0] for a, _ in pairs)
        peak = statistics.median(a[1] for a, _ in pairs)
        ref = statistics.median(b[0] for _, b in pairs)
        ratio = statistics.median(a[0] / b[0] for a, b in pairs)
        print(f"{name:<14} {wall:>8.2f} {peak:>9.0f} {peak / size:>9.2f} {ref:>15.3f} {ratio:>7.1f}")
    load = os.getloadavg()
    print(f"load average after: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
