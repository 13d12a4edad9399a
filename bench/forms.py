"""Every form of every effect family, withheld: does `hyst diagnose` name the physics when the form
is not the default one?

Each data set is the five runs of bench/withheld.py (the twin, seeded noise) with one effect in one
of its forms at a typical strength; the diagnosis sees the catheter's true base model. Printed: the
effect and form chosen first, and the held-out RMSE before and after. This checks our own forms;
the independent suite (issue 11, item 4) checks forms we did not write.

Run: python bench/forms.py [--seed 0]
"""
from __future__ import annotations

import argparse
import time

from hystcli.core import effects as E
from hystcli.sim import twin
from hystcli.diagnosis import diagnose

from withheld import data_set

CASES = [
    ("friction", "capstan", {"mu": 0.3}), ("friction", "backlash", {"mu": 0.4}), ("friction", "slope", {"mu": 0.3}),
    ("deadzone", "width", {"width": 5.0}), ("deadzone", "centre", {"shift": 3.0}),
    ("coupling", "input", {"gain": 0.15}), ("coupling", "input-magnitude", {"gain": 0.15}),
    ("coupling", "output", {"gain": 0.1}), ("coupling", "output-magnitude", {"gain": 0.1}),
    ("coupling", "deadzone", {"gain": 0.2}), ("coupling", "deadzone-magnitude", {"gain": 0.3}),
    ("rate", "input", {"tau": 0.2}), ("rate", "input2", {"tau": 0.15}), ("rate", "output", {"tau": 0.5}),
    ("rate", "output2", {"tau": 0.3}),
    ("saturation", "smooth", {"limit": 70.0}), ("saturation", "hard", {"limit": 45.0}),
    ("saturation", "asymmetric", {"limit": 80.0, "ratio": 0.6}),
    ("creep", "relax", {"fraction": 0.25, "tau": 6.0}), ("creep", "relax", {"fraction": -0.25, "tau": 6.0}),
    ("contact", "wall", {"wall": 45.0}), ("latency", "tracker", {"delay": 0.3}),
]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    hits = 0
    t0 = time.perf_counter()
    for i, (name, form, params) in enumerate(CASES):
        cat = twin.get_catheter("example-a" if i % 2 == 0 else "example-b")
        eff = E.make_effect(name, form, **params)
        base, runs = data_set(cat, [eff], seed=args.seed * 1000 + i)
        d = diagnose(base, runs)
        first = d.selected[0] if d.selected else None
        got = "none" if first is None else first.effect().label()
        hits += first is not None and first.name == name
        print(f"{str(eff):55s} chosen {' + '.join(s.effect().label() for s in d.selected) or 'none':45s} "
              f"RMSE {d.how_far.rmse_before:6.2f} -> {d.how_far.rmse_after:5.2f} deg", flush=True)
    print(f"physics named first: {hits}/{len(CASES)} ({time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    main()
