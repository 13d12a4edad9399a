"""Speed of `hyst diagnose` on demo-sized data (issue 5, must-show 3): target < 60 s on 2 cores.

The data are the size of the demo's experiment: 2 catheters x 3 shapes (straight, alpha=45,
alpha=90) x 3 controllers (none, comp, comp+shift) x 3 trials of the paper's periodic run (60 deg,
0.04 Hz, 50 s at 100 Hz), made by the twin with each calibrated catheter's default effects
(hystcli.sim.calibration). Diagnose refuses mixed catheters, so each catheter's
27 runs are one diagnosis with leave-one-run-out (27 folds), against the catheter's true
straight-shaft model; the figure is the sum of both (one process, one core), data generation
excluded.

Run: python bench/bench_diagnose.py [--trials 3] [--bootstrap 0]
"""
from __future__ import annotations

import argparse
import time

from hystcli import compensation
from hystcli.sim import twin
from hystcli.sim.calibration import calibrated_catheter
from hystcli.diagnosis import diagnose
from hystcli.core.run import Run
from hystcli.core.model import Model
from hystcli.core.params import Shape

SHAPES = ("straight", "alpha=45,theta=0", "alpha=90,theta=0")


def experiment_runs(cat: twin.VirtualCatheter, trials: int) -> tuple[Model, list[Run]]:
    base = Model(cat.knobs, cat.geometry, meta={"catheter": cat.name})
    t, r = twin.periodic()
    runs = []
    for shape in SHAPES:
        sh = Shape.parse(shape)
        traj = Run({"t": t, "r1": r}, {"shape": shape, "motion": "periodic"})
        for controller in ("none", "comp", "comp+shift"):
            cmd = None if controller == "none" else compensation.compensate(
                base, traj, ignore_shift=controller == "comp").run
            for trial in range(1, trials + 1):
                run = twin.simulate_motion(cat, sh, "periodic", commands=cmd, controller=controller,
                                           seed=7, trial=trial)
                runs.append(run)
    return base, runs


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=3)
    ap.add_argument("--bootstrap", type=int, default=0)
    args = ap.parse_args()
    total = 0.0
    n_runs = n_samples = 0
    for name in ("ice-a", "ice-b"):
        cat = calibrated_catheter(name)
        base, runs = experiment_runs(cat, args.trials)
        n_runs += len(runs)
        n_samples += sum(len(r) for r in runs)
        t0 = time.perf_counter()
        d = diagnose(base, runs, bootstrap=args.bootstrap)
        dt = time.perf_counter() - t0
        total += dt
        true = ", ".join(e.name for e in cat.default_effects) or "none"
        print(f"{name}: {len(runs)} runs, true effects [{true}], chosen "
              f"[{', '.join(s.name for s in d.selected) or 'none'}], held-out RMSE "
              f"{d.how_far.rmse_before:.2f} -> {d.how_far.rmse_after:.2f} deg "
              f"({d.how_far.rmse_shrink_pct:.0f} %), {dt:.1f} s")
    print(f"diagnose of {n_runs} runs ({n_samples} samples) in {total:.1f} s "
          f"(target < 30 s on a busy machine){' with bootstrap ' + str(args.bootstrap) if args.bootstrap else ''}")


if __name__ == "__main__":
    main()
