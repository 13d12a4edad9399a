"""Print one line per drawn wild sweep case, to eyeball the variety of the plants.

Usage: python bench/plants/show_wild.py [N] [FIRST_SEED]   (defaults 40 and 0)

Each line: seed, family, the tip's true edges, the current's true edges (departure from no-load),
current sign, sampling rate, samples, which tip edges the sweep passes, the state it starts from.
A last line gives the median time sweep_case took per case (after one warm-up call, which loads
the compiled kernels) and the machine's load average.
"""

from __future__ import annotations

import os
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from plants import wild  # noqa: E402


def line(case: wild.SweepCase) -> str:
    """One summary line for `case`."""
    f, t = case.factors, case.truth
    return (f"{case.seed:>6} {case.family:<13} tip [{t.d_neg:7.2f},{t.d_pos:7.2f}] "
            f"cur [{f['current_edge_neg']:7.2f},{f['current_edge_pos']:7.2f}] "
            f"{f['current_sign']:<9} fs {f['fs']:7.1f} n {f['n']:>5} "
            f"pass +{'Y' if f['passes_pos_edge'] else 'n'} -{'Y' if f['passes_neg_edge'] else 'n'} "
            f"start {f['start_state']}")


def main(argv: list[str]) -> None:
    n = int(argv[0]) if argv else 40
    first = int(argv[1]) if len(argv) > 1 else 0
    wild.sweep_case(first)
    times = []
    for seed in range(first, first + n):
        start = time.perf_counter()
        case = wild.sweep_case(seed)
        times.append(time.perf_counter() - start)
        print(line(case))
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    print(f"median sweep_case time {1e3 * statistics.median(times):.1f} ms over {n} cases "
          f"(load average {load})")


if __name__ == "__main__":
    main(sys.argv[1:])
