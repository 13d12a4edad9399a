#!/usr/bin/env python
"""Write sample_data/: the recordings `hyst demo` runs the paper's experiment on.

Seeded and deterministic: the same command writes the same bytes. Every recording comes from the
calibrated virtual catheters (hystcli/sim/calibration.py) through the very function the demo uses
when it records from the twin itself (hystcli/sim/experiment.py: sample_data_runs), so `hyst demo` on
these files, `hyst demo` where there are none (an installed hyst) and `hyst demo --simulate` give
the same tables.

Usage (from the repository root):

    python scripts/make_sample_data.py [--out sample_data] [--seed 0]

sample_data/real/ (real recordings, another task's) is never touched.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from hystcli.sim.calibration import CALIBRATED_NAMES
from hystcli.sim.scenarios import (REPLAY_AMPLITUDE, REPLAY_FS, REPLAY_SPEED, SCENARIOS, SWEEP_FS,
                                sample_data_runs)
from hystcli.io import atomic_write_text, write_run

COMMAND = "python scripts/make_sample_data.py --out sample_data --seed 0"


def readme(seed: int) -> str:
    """The README.md of the data directory: what each file is and how it was made."""
    scen = "\n".join(f"  - `{s.file_tag}`: {s.name if s.name != 'straight' else 'straight shaft'}"
                     + (" (knob 1 bent in its plane theta=0, knob 2 in its plane theta=90)"
                        if s.table == "I" and s.name != "straight" else "")
                     for s in SCENARIOS)
    cats = ", ".join(f"`{c}`" for c in CALIBRATED_NAMES)
    return f"""# sample_data

Recordings of the calibrated virtual catheters ({cats}; `hystcli/sim/calibration.py`) that
`hyst demo` runs the paper's whole experiment on (Kim & Mansi, section III, Tables I and II).

Made by (seeded, deterministic; the same command writes the same bytes):

    {COMMAND.replace("--seed 0", f"--seed {seed}")}

Run the experiment on them from the repository root:

    hyst demo                   # reads sample_data/, prints Tables I and II beside the paper's
    hyst demo --format markdown

Files (run CSVs, [docs/file-formats.md](../docs/file-formats.md): `# key: value` metadata,
then `t` in s, knob `q<k>` and tip `y<k>` in deg, motor current `c<k>` in mA, reference `r<k>` in
deg; the metadata holds the catheter, shape, effects and the twin's true offsets
`true_offset<k>`):

- `reference_periodic.csv`: the periodic reference `r1` (60 deg amplitude, 0.04 Hz, 2 cycles,
  100 Hz), played on knob 1 and on knob 2 in turn (1-DoF, Table I).
- `reference_nonperiodic.csv`: the non-periodic 2-DoF reference (two sines of 30 deg at 0.02
  and 0.02*sqrt(3) Hz, 100 s, 100 Hz); `r2` runs twice as fast as `r1` (Table II).
- `<catheter>/sweep_knob<k>.csv`: the identification sweep of knob k on the straight shaft
  (+-40 deg sine, 2 cycles, 40 deg/s peak, {SWEEP_FS:g} Hz) with tip angle and motor current:
  what `hyst identify` reads.
- `<catheter>/replay_<scenario>_knob<k>.csv`: a slow sweep of knob k under a shaft shape
  (0 -> +{REPLAY_AMPLITUDE:g} -> -{REPLAY_AMPLITUDE:g} -> 0 deg at {REPLAY_SPEED:g} deg/s,
  {REPLAY_FS:g} Hz, the other knob at rest): what `hyst detect-shift REPLAY.csv` reads. Scenarios:
{scen}

Values are rounded to a lab recorder's resolution (time 1 us, knob 1e-4 deg, tip 1e-3 deg,
current 0.01 mA). `real/`, when present, holds real recordings and is not made by this script.
"""


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("sample_data"), help="data directory to write")
    ap.add_argument("--seed", type=int, default=0, help="seed of the recordings' sensor noise")
    args = ap.parse_args(argv)
    out: Path = args.out
    written: list[Path] = []

    def put_run(path: Path, run) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_run(path, run)
        written.append(path)

    for rel, run in sample_data_runs(args.seed).items():
        put_run(out / rel, run)
    readme_path = out / "README.md"
    atomic_write_text(readme_path, readme(args.seed))
    written.append(readme_path)
    total = sum(p.stat().st_size for p in written)
    print(f"wrote {len(written)} files, {total / 1e6:.2f} MB, into {out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
