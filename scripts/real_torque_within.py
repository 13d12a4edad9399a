#!/usr/bin/env python
"""Can one real file tell the cable's compliance? (issue 11, the real-data target)

Across the files of a pitch session the jaw loop moves with the mean back-end torque (STUDY.md
section 1: 0.067 .. 0.098 deg per mN m). Within one file the torque swings far more (about -60 ..
+115 mN m: the brake resists the motion, so it follows the direction). If the identification
file alone fixed the compliance, each session's held-out loads could be predicted without any
other session's diagnosis. This script asks it of each pitch session's identification files
(001, 40 %; 000, 20 %): the in-sample RMSE of the jaw with a stretch that follows the measured
torque sample by sample, ``y = H(q) + c (T(t) - mean T)``, where for each ``c`` on a grid the loop
``H`` is re-identified (``identify``, the tip fit) on ``y - c (T - mean T)``. A compliance the file
can fix shows as a minimum of that profile; a flat profile means the loop takes the torque's
swing up (the torque follows the direction, as the backlash does).

    python scripts/real_torque_within.py          # about 3 minutes; prints one row per file

Reads ``sample_data/real`` (the runs) and the original MRDLab files (the torque column, which the
import does not keep). Deterministic.
"""
from __future__ import annotations

import math
import sys
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "scripts"))

from hystcli.core.model import predict_tip  # noqa: E402
from hystcli.identification import identify  # noqa: E402
from hystcli.io import read_run  # noqa: E402
from real_study import BE_NM_PER_COUNT, REAL, SETTLE_S, back_end_torque_counts  # noqa: E402

GRID = np.linspace(0.0, 0.12, 13)  # deg per mN m; the across-file slopes are 0.067 .. 0.098


def torque_at(series: str, stem: str, t: np.ndarray) -> np.ndarray:
    """The back-end torque (mN m) of the original 1 kHz file at the run's times."""
    a = back_end_torque_counts(series, stem)
    return np.interp(t, a[:, 0], a[:, 1] * BE_NM_PER_COUNT * 1000.0)


def profile(series: str, stem: str) -> list[float]:
    """In-sample jaw RMSE (deg, after SETTLE_S) for each compliance of GRID."""
    run = read_run(REAL / series / f"{stem}.csv")
    t = np.asarray(run["t"], float)
    y = np.asarray(run["y1"], float)
    keep = t >= SETTLE_S
    T = torque_at(series, stem, t)
    dT = T - T[keep].mean()
    out = []
    for c in GRID:
        cols = dict(run.columns)
        cols["y1"] = y - c * dT
        shifted = replace(run, columns=cols)
        # a c far from the truth leaves the loop misfitting; its RMSE is the answer, not a refusal
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            model = identify(shifted, refuse_unfixed=False, max_misfit=math.inf).model
        pred = predict_tip(model, shifted)[1] + c * dT
        e = (pred - y)[keep]
        out.append(float(np.sqrt(np.mean(e * e))))
    return out


def main() -> int:
    print("in-sample jaw RMSE (deg) against the compliance c (deg per mN m) of a stretch that "
          "follows the measured torque sample by sample, the loop re-identified at each c")
    print("series   file  " + " ".join(f"{c:6.3f}" for c in GRID) + "   best c")
    for n in range(1, 6):
        for stem in ("001", "000"):
            prof = profile(f"pitch_{n}", stem)
            best = GRID[int(np.argmin(prof))]
            print(f"pitch_{n}  {stem}   " + " ".join(f"{r:6.3f}" for r in prof) + f"   {best:.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
