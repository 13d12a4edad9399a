"""Draw the hysteresis loop of one knob with its parameters marked: docs/figures/loop.svg.

The loop is the model itself (:class:`hystcli.core.params.KnobModel`: the envelopes and the clamp
recursion of the Method page) driven through one full sweep, so the figure cannot drift from the
equations. The parameters are round numbers close to what ``hyst identify`` reads from the
sample sweep. Run from the repository root; the same command writes the same bytes::

    python docs/figures/make_loop_figure.py
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from hystcli.core.params import KnobModel

OUT = Path(__file__).with_name("loop.svg")

# an illustrative knob: dead zone +-20 deg, backlash 12 deg, slope 1.25, heights -+6.5 deg
KNOB = KnobModel(d_pos=20.0, d_neg=-20.0, b_pos=12.0, b_neg=12.0, omega=1.25, h_pos=-6.5, h_neg=6.5)
REACH = 40.0  # the sweep's amplitude (deg of knob)
SHIFT = 14.0  # the offset drawn as a shifted copy of the loop (deg of knob)


def sweep(n: int = 4001) -> tuple[np.ndarray, int]:
    """Knob angles 0 -> +REACH -> -REACH -> +REACH, and the index of the first reversal (the
    rise from rest before it is not part of the loop)."""
    up = np.linspace(-REACH, REACH, n)
    first = np.linspace(0.0, REACH, n // 2)
    return np.concatenate([first, up[::-1], up]), len(first) - 1


def draw(path: Path) -> None:
    """Write the figure to ``path`` (SVG, or PNG by the suffix; reproducible: no date, a fixed
    hash salt)."""
    import matplotlib
    from matplotlib.figure import Figure

    matplotlib.rcParams["svg.hashsalt"] = "hyst-loop"
    k = KNOB
    q, start = sweep()
    y = k.forward(q)
    keep = slice(start, None)

    fig = Figure(figsize=(6.4, 4.0), layout="constrained")
    ax = fig.add_subplot()
    shifted = k.with_offset(SHIFT)
    ax.plot(q[keep] + SHIFT, shifted.forward(q + SHIFT)[keep], color="0.75", lw=1.2, ls="--",
            label=f"the same loop with offset = {SHIFT:g} deg")
    ax.plot(q[keep], y[keep], color="tab:blue", lw=2, label="tip angle y, straight shaft (offset = 0)")

    top = k.omega * (REACH - k.d_pos) + k.h_pos     # the tip at the top of the sweep
    bottom = k.omega * (-REACH - k.d_neg) + k.h_neg  # and at the bottom
    grey = dict(color="0.35", lw=0.8, ls=":")
    arrow = dict(arrowstyle="<->", color="tab:red", lw=1.2, shrinkA=0, shrinkB=0)
    text = dict(color="tab:red", fontsize=10)

    # the dead-zone edges: where the tip leaves its dead-zone height
    ax.axvline(k.d_pos, **grey)
    ax.axvline(k.d_neg, **grey)
    ax.annotate("d_pos", (k.d_pos, k.h_pos), (k.d_pos - 12, k.h_pos - 9), arrowprops=dict(
        arrowstyle="->", color="tab:red"), **text)
    ax.annotate("d_neg", (k.d_neg, k.h_neg), (k.d_neg - 12, k.h_neg + 8), arrowprops=dict(
        arrowstyle="->", color="tab:red"), **text)
    # the heights of the two dead-zone flats
    ax.axhline(k.h_pos, **grey)
    ax.axhline(k.h_neg, **grey)
    ax.text(-REACH - 1, k.h_pos - 2.3, "h_pos", **text)
    ax.text(-REACH - 1, k.h_neg + 0.8, "h_neg", **text)
    # the backlash plateaus after each reversal
    ax.annotate("", (REACH - k.b_pos, top + 2.5), (REACH, top + 2.5), arrowprops=arrow)
    ax.text(REACH - k.b_pos / 2, top + 3.5, "b_pos", ha="center", **text)
    ax.annotate("", (-REACH, bottom - 2.5), (-REACH + k.b_neg, bottom - 2.5), arrowprops=arrow)
    ax.text(-REACH + k.b_neg / 2, bottom - 5.8, "b_neg", ha="center", **text)
    # the slope of the loaded lines
    x0, run = 26.0, 6.0
    y0 = k.omega * (x0 - k.d_pos) + k.h_pos
    ax.plot([x0, x0 + run, x0 + run], [y0, y0, y0 + k.omega * run], color="tab:red", lw=1)
    ax.text(x0 + run + 1, y0 + 1.5, "omega", **text)
    # the offset moves the whole loop along the knob axis
    ax.annotate("", (k.d_pos + SHIFT, k.h_pos - 4), (k.d_pos, k.h_pos - 4), arrowprops=dict(
        arrowstyle="->", color="0.45", lw=1.2))
    ax.text(k.d_pos + SHIFT / 2, k.h_pos - 7.5, "offset", ha="center", color="0.35", fontsize=10)

    ax.set_xlabel("knob angle q (deg)")
    ax.set_ylabel("tip angle y (deg)")
    ax.set_xlim(-REACH - 4, REACH + SHIFT + 2)
    ax.set_ylim(bottom - 9, top + 8)
    ax.legend(loc="upper left", fontsize=8, frameon=False)
    svg = path.suffix.lower() == ".svg"
    fig.savefig(path, format="svg" if svg else "png", dpi=120,
                metadata={"Date": None} if svg else {"Software": None})


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-o", "--out", type=Path, default=OUT,
                    help="the file to write (.svg, or .png to preview)")
    args = ap.parse_args(argv)
    draw(args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
