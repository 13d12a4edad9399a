"""Every timing the README quotes, measured the same way: whole commands, median of several runs.

Each figure is the wall time of a fresh process (``python -m hystcli ...`` or a script), as a
user would see it, the median of ``--runs`` runs after one warm-up (numba's cache filled), with
the machine's load average printed before and after. ``--hogs N`` runs N busy loops beside the
commands (``python3 -c 'while True: pass'``), the "busy machine" of issue 12.

Run: ``python bench/timings.py`` (about two minutes idle), ``--hogs 2``, ``--only demo``.
"""
from __future__ import annotations

import argparse
import contextlib
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Iterator

ROOT = Path(__file__).resolve().parents[1]
PY = sys.executable


def _demo(tmp: Path) -> list[str]:
    return [PY, "-m", "hystcli", "demo", "-q", "--out", str(tmp / "demo")]


def _identify(tmp: Path) -> list[str]:
    return [PY, "-m", "hystcli", "identify", str(ROOT / "sample_data/ice-a/sweep_knob1.csv"), "-o",
            str(tmp / "m.json"), "-q"]


def _detect(tmp: Path) -> list[str]:
    model = tmp / "m0.json"
    if not model.exists():
        subprocess.run(_identify(tmp)[:-3] + ["-o", str(model), "-q"], check=True, cwd=ROOT)
    return [PY, "-m", "hystcli", "detect-shift", "--model", str(model), "--replay",
            str(ROOT / "sample_data/ice-a/replay_alpha90_knob1.csv"), "-o", str(tmp / "s.json"), "-q"]


def _real_study(tmp: Path) -> list[str]:
    return [PY, str(ROOT / "scripts/real_study.py"), "--out", str(tmp / "STUDY.md")]


def _help(tmp: Path) -> list[str]:
    return [PY, "-m", "hystcli", "--help"]


COMMANDS = {
    "help": ("hyst --help", _help),
    "identify": ("hyst identify sample_data/ice-a/sweep_knob1.csv", _identify),
    "detect-shift": ("hyst detect-shift --replay sample_data/ice-a/replay_alpha90_knob1.csv", _detect),
    "demo": ("hyst demo (144 runs, with the diagnosis)", _demo),
    "real-study": ("python scripts/real_study.py", _real_study),
}


@contextlib.contextmanager
def hogs(n: int) -> Iterator[None]:
    procs = [subprocess.Popen([PY, "-c", "while True: pass"]) for _ in range(n)]
    try:
        yield
    finally:
        for p in procs:
            p.kill()
            p.wait()


def measure(argv: list[str], runs: int) -> list[float]:
    subprocess.run(argv, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)  # warm-up
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        subprocess.run(argv, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)
        times.append(time.perf_counter() - t0)
    return times


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--hogs", type=int, default=0)
    ap.add_argument("--only", nargs="*", choices=sorted(COMMANDS), default=None)
    args = ap.parse_args(argv)
    names = args.only or list(COMMANDS)
    print(f"{os.cpu_count()} CPUs, load average {' '.join(f'{v:.2f}' for v in os.getloadavg())} before; "
          f"{args.hogs} CPU hog(s) beside the commands; median of {args.runs} runs after a warm-up")
    with tempfile.TemporaryDirectory() as tmp, hogs(args.hogs):
        for name in names:
            label, make = COMMANDS[name]
            if name == "real-study" and not (ROOT / "scripts/real_study.py").exists():
                continue
            t = measure(make(Path(tmp)), args.runs)
            print(f"{label:70s} {statistics.median(t):7.2f} s  (min {min(t):.2f}, max {max(t):.2f})", flush=True)
    print(f"load average after: {' '.join(f'{v:.2f}' for v in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
