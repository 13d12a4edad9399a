#!/usr/bin/env python
"""Import the real MRDLab EndoWrist measurements into ``sample_data/real/`` (issue 6).

Reads every ``load_freq/*.TXT.gz`` and ``pitch_*/*.TXT.gz`` of the MRDLab data set
(``sample_data/real/PROVENANCE.md``; ``--src``, by default the folder ``shared/real/mrdlab``
beside the repository) with the built-in ``mrdlab`` preset of
:mod:`hystcli.io.importer`, resamples to 200 Hz (anti-alias low-pass first) and rounds to 4 decimals
so the whole copy stays a few MB, adds the condition metadata (``series``, ``setting`` in words,
``condition`` = ``load_pct`` (the driver of the condition effects), ``frequency_hz``,
``pitch_deg``; ``motion: periodic``; ``catheter: endowrist-tool5`` / ``endowrist-tool4``), writes
one run CSV per file plus PROVENANCE.md (with its ODbL notice and a note on this conversion) and
the folders' ReadME.txt, and prints a summary table.

    python scripts/import_real.py                      # the default --src -> sample_data/real
    python scripts/import_real.py --src DIR --out DIR --rate 200 --zero none

Same input, same bytes: nothing here is random and no wall-clock time is written.
"""
from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from hystcli.io import importer  # noqa: E402
from hystcli.errors import HystError  # noqa: E402
from hystcli.io import atomic_write_text, write_run  # noqa: E402

SERIES = ("load_freq", "pitch_1", "pitch_2", "pitch_3", "pitch_4", "pitch_5")

CONVERSION_NOTE = """
## This copy (`sample_data/real/`)

Derived from the files above by `scripts/import_real.py` (hyst's `mrdlab` import preset); it is a
derived database and stays under the ODbL 1.0 (contents: DbCL 1.0), with the attribution above.

- One run CSV per original file, same folder and number (`load_freq/00.TXT.gz` -> `load_freq/00.csv`).
- Columns: `t` (s, from 0), `q1` = input spindle angle (deg, col2 * 360/8192), `y1` = jaw angle
  (deg, col5 * 360/4000, **negated**: the jaw encoder counts against the spindle, raw gain -0.85 ..
  -0.91, and the hysteresis model needs an output that rises with its input), `c1` = back-end
  motor current (mA, metadata `current_unit: mA`: col4 is in A, converted x1000).
- **Decimated from 1 kHz to {rate:g} Hz**: zero-phase 3rd-order Butterworth anti-alias low-pass at
  {cutoff:g} Hz, then linear interpolation; values rounded to {decimals} decimals (the current in A,
  before its conversion to mA).
- Encoder zeros: `--zero {zero}`{zero_note}.
- Metadata per run: `catheter` (endowrist-tool5 / endowrist-tool4), `motion: periodic`, `series`
  (folder), `setting` (frequency, load and pitch in words), and from the file's header line `tool`,
  `spindle`, `frequency_hz`, `amplitude_deg`, `load_pct` (resistive torque level, %) and
  `condition` (the same load level: the driver of hyst's condition effects, e.g. `stretch`), and
  from the folder's ReadME.txt `pitch_deg`, `roll_deg`; `import` says how the file was converted.
  Every pitch_5 run carries a `caution` with the owners' collision warning (their ReadME names
  `1##.TXT` files; which files of this subset it meant is not certain).
- The torque, command and motor-encoder columns of the originals are not kept.
"""


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--src", type=Path, default=REPO.parent / "shared" / "real" / "mrdlab",
                    help="the MRDLab data set folder (default: shared/real/mrdlab beside the repository)")
    ap.add_argument("--out", type=Path, default=REPO / "sample_data" / "real",
                    help="output folder (default: <repo>/sample_data/real)")
    ap.add_argument("--rate", type=float, default=200.0, help="output sample rate, Hz (default 200)")
    ap.add_argument("--decimals", type=int, default=4, help="decimals kept (default 4)")
    ap.add_argument("--zero", choices=importer.ZERO_MODES, default="none",
                    help="encoder zeroing (default none: offsets between runs are kept)")
    return ap.parse_args(argv)


def condition_meta(series: str, raw: Path) -> dict[str, str]:
    """Metadata the preset cannot read from one file: its series, and the owners' caution."""
    meta = {"series": series, "source_file": f"{series}/{raw.name}"}
    if series == "pitch_5":
        # the owners' ReadME names "1##.TXT" files, which this subset does not hold under that name;
        # every pitch_5 run carries the warning rather than guessing which one it meant
        meta["caution"] = ("owners' ReadME: the second half of the 1##.TXT data came dangerously close "
                           "to a mechanical collision")
    return meta


def setting(meta: dict) -> str:
    """The run's experimental setting in words (``condition`` itself is the load: a number)."""
    parts = [f"f={float(meta['frequency_hz']):g}Hz", f"load={float(meta['load_pct']):g}%"]
    if "pitch_deg" in meta:
        parts.append(f"pitch={float(meta['pitch_deg']):+g}")
    return ",".join(parts)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    src, out = args.src, args.out
    if not (src / "PROVENANCE.md").is_file():
        print(f"Error: {src}: not the MRDLab data set (no PROVENANCE.md); give --src", file=sys.stderr)
        return 1
    files = [(s, p) for s in SERIES for p in sorted((src / s).glob("*.TXT.gz"))]
    if not files:
        print(f"Error: {src}: no */*.TXT.gz files", file=sys.stderr)
        return 1
    mapping = importer.get_preset("mrdlab")
    done = []
    try:
        for series, raw in files:
            opts = importer.ImportOptions(zero=args.zero, resample=args.rate, decimals=args.decimals,
                                          meta=condition_meta(series, raw))
            imp = importer.convert(raw, mapping, opts, source=f"{series}/{raw.name}")
            run = imp.run.with_meta(setting=setting(dict(imp.run.meta)))
            done.append((series, raw, run, imp.report))
    except HystError as exc:
        print(f"Error: {exc}", file=sys.stderr)
        return 1

    for series, raw, run, _ in done:
        (out / series).mkdir(parents=True, exist_ok=True)
        write_run(out / series / importer.output_name(raw), run)
    for series in SERIES:
        for readme in sorted((src / series).glob("[Rr][Ee][Aa][Dd][Mm][Ee]*")):
            (out / series).mkdir(parents=True, exist_ok=True)
            shutil.copyfile(readme, out / series / readme.name)
    zero_note = {"none": " (nothing subtracted: within a folder the zeros look shared, the mean jaw "
                         "angle moving steadily with the load level at every frequency, and a per-file "
                         "re-zero would erase that offset)",
                 "first": " (first sample of q1 and y1 subtracted per file)",
                 "mean": " (mean of q1 and y1 subtracted per file)"}[args.zero]
    note = CONVERSION_NOTE.format(rate=args.rate, cutoff=importer.ANTI_ALIAS_FRACTION * args.rate,
                                  decimals=args.decimals, zero=args.zero, zero_note=zero_note)
    atomic_write_text(out / "PROVENANCE.md", (src / "PROVENANCE.md").read_text(encoding="utf-8").rstrip("\n")
                      + "\n" + note)

    header = (f"{'file':<20} {'setting':<28} {'rows':>5} {'Hz':>5} {'q1 range':>15} {'y1 range':>17} "
              f"{'gain':>6} {'drift':>8} {'lin RMSE':>8}")
    print(header)
    print("-" * len(header))
    total = 0
    for series, raw, run, rep in done:
        q, y = run["q1"], run["y1"]
        coef = np.polyfit(q, y, 1)
        lin = float(np.sqrt(np.mean((np.polyval(coef, q) - y) ** 2)))
        k = rep.knobs[0]
        print(f"{series + '/' + raw.name:<20} {run.meta['setting']:<28} {len(run):>5} {rep.rate_out:>5g} "
              f"{q.min():>7.2f}..{q.max():<6.2f} {y.min():>8.2f}..{y.max():<7.2f} "
              f"{k.gain:>+6.3f} {k.drift:>+8.4f} {lin:>8.3f}")
        total += (out / series / importer.output_name(raw)).stat().st_size
    print(f"\n{len(done)} runs written to {out} ({total / 1e6:.2f} MB); gain = raw slope y/q before the flip "
          f"(deg/deg), drift = output drift after it (deg/s), lin RMSE = static linear fit (deg)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
