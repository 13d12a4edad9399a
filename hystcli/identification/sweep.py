"""What a recorded sweep offers an identification: its reversals, its branches, a decimation.

A record identifies a knob when the knob moves both ways and passes both dead-zone edges; how
many cycles it holds, where it starts and in which state the tip is then do not matter to the
output-error fit (:mod:`.tip`). :func:`check_sweep` refuses, before anything is fitted, only what
no fit could use (missing or non-finite columns, too few samples, a knob that never moves or
never reverses); whether the edges were passed is judged once the loop is fitted.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.run import Run
from ..errors import IdentificationError
from ..signal.stretches import find_reversals

MIN_SAMPLES = 100
"""Fewest samples of a sweep :func:`check_sweep` accepts."""


@dataclass(frozen=True)
class SweepCheck:
    """What :func:`check_sweep` learnt of one knob's command: its reversals and branches.

    Attributes
    ----------
    knob : int
    reversals : numpy.ndarray of int
        Sample indices of the reversals, in time order.
    tops : numpy.ndarray of bool
        True where the reversal is a top (the knob turns from ascending to descending).
    q_min, q_max : float
        Range of the knob command (deg).
    n : int
        Samples in the record.
    """

    knob: int
    reversals: np.ndarray
    tops: np.ndarray
    q_min: float
    q_max: float
    n: int = 0

    @property
    def branches(self) -> list[tuple[int, int, int]]:
        """Complete branches ``(start, stop, direction)`` between two consecutive reversals."""
        out = []
        for a, b, top in zip(self.reversals[:-1], self.reversals[1:], self.tops[:-1]):
            out.append((int(a), int(b), -1 if top else +1))
        return out

    @property
    def segments(self) -> list[tuple[int, int, int]]:
        """Every monotone stretch ``(start, stop, direction)``, the partial first and last included."""
        if self.reversals.size == 0:
            return []
        bounds = [0] + [int(r) for r in self.reversals] + [max(self.n - 1, 0)]
        dirs = [(+1 if top else -1) for top in self.tops]   # direction before each reversal
        dirs = dirs + [-dirs[-1]]
        out = []
        for (a, b), d in zip(zip(bounds[:-1], bounds[1:]), dirs):
            if b > a:
                out.append((a, b, d))
        return out

    @property
    def n_cycles(self) -> int:
        """Full cycles: pairs of complete branches (one each way)."""
        return len(self.branches) // 2


# --------------------------------------------------------------------------------------------
# checks
# --------------------------------------------------------------------------------------------
def check_sweep(run: Run, knob: int, need_current: bool = True) -> SweepCheck:
    """Check that a run's sweep of one knob could identify anything, before anything is fitted.

    Needs the columns ``q<k>`` and ``c<k>`` (``y<k>`` instead when ``need_current`` is False:
    the tip fit), all finite; at least :data:`MIN_SAMPLES` samples; a knob that moves and
    reverses at least once (one cycle, started anywhere, is enough); a current (or tip) that
    is not constant. Whether the knob passes both dead-zone edges is judged by the fit.

    Raises
    ------
    IdentificationError
        Naming what is missing.
    """
    where = f"{run.source}: " if run.source else ""
    qn, cn, yn = f"q{knob}", f"c{knob}", f"y{knob}"
    required = (qn, cn) if need_current else (qn, yn)
    for name in required:
        if name not in run:
            why = "" if need_current else " (the tip fit reads the loop from the tip angle)"
            raise IdentificationError(f"{where}knob {knob}: column {name!r} is missing{why} "
                                      f"(columns: {', '.join(run.columns) or 'none'})")
    n = len(run)
    if n < MIN_SAMPLES:
        raise IdentificationError(f"{where}knob {knob}: too few samples ({n}); a sweep needs at "
                                  f"least {MIN_SAMPLES}")
    for name in [qn] + [nm for nm in (cn, yn) if nm in run]:
        if not np.all(np.isfinite(run[name])):
            row = int(np.flatnonzero(~np.isfinite(run[name]))[0])
            raise IdentificationError(f"{where}column {name!r} has a non-finite value at row {row + 1}")
    q = run[qn]
    if np.ptp(q) < 1.0:
        raise IdentificationError(f"{where}knob {knob} never moves: {qn} spans {np.ptp(q):.3g} deg")
    sig, what = (cn, "the motor current") if need_current else (yn, "the tip angle")
    s = run[sig]
    if np.ptp(s) <= 1e-9 * max(1.0, float(np.max(np.abs(s)))):
        raise IdentificationError(f"{where}knob {knob}: {what} {sig} is constant ({s[0]:g}); "
                                  "it carries no hysteresis to identify")
    rev, tops = find_reversals(q)
    if rev.size == 0:
        raise IdentificationError(
            f"{where}knob {knob}: the sweep never reverses ({qn} goes from {q[0]:.1f} to {q[-1]:.1f} deg "
            "once); identification needs the knob to go both ways past the dead zone")
    return SweepCheck(knob, rev, tops, float(np.min(q)), float(np.max(q)), n)
