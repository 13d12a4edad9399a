"""The paper's whole experiment (Kim & Mansi, section III) on the virtual catheters: Tables I and II.

This module owns the protocol runner behind ``hyst demo`` and the recordings it starts from:

1. per catheter, identify the straight-shaft model on the identification sweep (one per knob),
   as the paper does: dead-zone edges and backlash from the motor current, omega = 1.45
   (:func:`hystcli.identification.identify`);
2. per shape, detect the shift with Algorithm 1 on a slow sweep recorded under that shape
   (:func:`hystcli.shift.detect_shift` over a :class:`hystcli.shift.ReplayProbe`);
3. compensate the reference (:func:`hystcli.compensation.compensate`): ``comp`` ignores the
   shift (Compensation-Only), ``comp+shift`` uses the detected offsets;
4. run each controller (``none``: q = r; ``comp``; ``comp+shift``) on the twin
   (:func:`hystcli.twin.simulate_motion`), several trials with different sensor noise;
5. evaluate every run (:func:`hystcli.metrics.evaluate_runs`) into the cells of Table I (1-DoF,
   periodic, shapes straight / alpha = 45 / alpha = 90) and Table II (2-DoF, non-periodic, shape
   alpha_1 = 45, theta_1 = 0; alpha_2 = 45, theta_2 = 90), beside the paper's values;
6. beyond the paper: diagnose the Compensation+Shift runs of each catheter
   (:func:`hystcli.diagnosis.diagnose`, leave one run out), compensate again with the augmented
   model (the base model plus the effects the diagnosis found, detected offsets unchanged) and
   run that fourth controller, ``comp+shift+diag``, on fresh trials whose noise the diagnosis
   never saw; :func:`beyond_table` sets it beside the paper's Compensation+Shift RMSE and the
   target of half of it.

Every step is the core function the matching command uses (identify, detect-shift, compensate,
simulate, evaluate), so the demo exercises the same code a lab would.

The 1-DoF runs use both knobs, one at a time, as the paper did ("we used both AP bending section
and LR bending section"): knob 1 under the bend ``alpha=A,theta=0`` and knob 2 under
``alpha=A,theta=90`` (each knob's bend lies in its own tendon plane, so each sees the shift of
an ``alpha = A`` bend). A cell pools 2 catheters x 2 knobs x the trials, as the paper pools its
two catheters and three trials.

Files of a data directory (``sample_data/``, made by ``scripts/make_sample_data.py``)::

    reference_periodic.csv          t, r1: 60 deg at 0.04 Hz, 2 cycles, 100 Hz
    reference_nonperiodic.csv       t, r1, r2: two sines of 30 deg at 0.02, 0.02*sqrt(3) Hz,
                                    100 s, 100 Hz; r2 runs twice as fast (the 2-DoF case)
    <catheter>/sweep_knob<k>.csv    identification sweep of knob k, straight shaft (1 kHz)
    <catheter>/replay_<scenario>_knob<k>.csv
                                    slow sweep of knob k under a shape, for Algorithm 1 (200 Hz)

with ``<scenario>`` one of ``straight``, ``alpha45``, ``alpha90``, ``2dof``.
"""
from __future__ import annotations

import io as _io
import json
import math
import textwrap
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Callable, Mapping, Sequence

import numpy as np
from threadpoolctl import threadpool_limits

from . import metrics
from .report.evaluation import evaluation_figure
from .report.table import TEXT_WIDTH, Table, format_markdown, format_text
from .calibration import CALIBRATED_NAMES, calibrated_catheter
from .compensation import compensate
from .diagnosis import diagnose as _diagnose
from .errors import DataError
from .identification import identify
from .io import Run, all_or_none, read_run
from .model import PAPER_OMEGA, Model, Shape
from .errors import ShiftDetectionError
from .shift import ReplayProbe, ShiftResult, detect_shift
from .twin import VirtualCatheter, nonperiodic, periodic, simulate, simulate_motion, sweep

# --------------------------------------------------------------------------------------------
# the paper's values
# --------------------------------------------------------------------------------------------
CONTROLLERS = ("none", "comp", "comp+shift")
"""The paper's three controllers: No Compensation, Compensation-Only, Compensation+Shift."""

DIAGNOSED = "comp+shift+diag"
"""Beyond the paper: Compensation+Shift with the model ``hyst diagnose`` augmented."""

BEYOND_FACTOR = 0.5
"""The target beyond the paper: the diagnosed controller's RMSE at most half the paper's
Compensation+Shift."""

SCENARIOS_1DOF = ("straight", "alpha=45", "alpha=90")
"""Columns of Table I: the shaft shapes of the 1-DoF periodic runs (paper section III-A)."""

SCENARIO_2DOF = "alpha=45,theta=0;alpha=45,theta=90"
"""The one column of Table II: two bent segments, one in each tendon plane."""

# Kim & Mansi, Table I ("PTPE and RMSE for 1-DoF: periodic inputs"), (mean, std) in deg.
# Compensation+Shift on the straight shaft is "-" in the paper (nothing to shift).
PAPER_TABLE_I: Mapping[tuple[str, str], Mapping[str, tuple[float, float]]] = MappingProxyType({
    ("none", "straight"): {"ptpe": (57.2, 4.2), "rmse": (18.5, 3.4)},
    ("none", "alpha=45"): {"ptpe": (61.9, 2.1), "rmse": (25.4, 1.5)},
    ("none", "alpha=90"): {"ptpe": (75.0, 10.1), "rmse": (38.2, 5.5)},
    ("comp", "straight"): {"ptpe": (18.6, 2.3), "rmse": (7.7, 1.5)},
    ("comp", "alpha=45"): {"ptpe": (30.12, 2.5), "rmse": (24.2, 3.5)},
    ("comp", "alpha=90"): {"ptpe": (45.0, 5.6), "rmse": (31.3, 4.1)},
    ("comp+shift", "alpha=45"): {"ptpe": (24.3, 2.3), "rmse": (7.9, 1.3)},
    ("comp+shift", "alpha=90"): {"ptpe": (26.0, 3.2), "rmse": (8.0, 1.2)},
})
"""The paper's Table I (source: Kim & Mansi, Table I), keyed by (controller, scenario)."""

# Kim & Mansi, Table II ("RMSE for 2-DoF: non-periodic inputs"), (mean, std) in deg.
PAPER_TABLE_II: Mapping[tuple[str, str], Mapping[str, tuple[float, float]]] = MappingProxyType({
    ("none", SCENARIO_2DOF): {"ptpe": (55.6, 8.3), "rmse": (18.0, 3.2)},
    ("comp", SCENARIO_2DOF): {"ptpe": (30.5, 3.9), "rmse": (16.0, 3.3)},
    ("comp+shift", SCENARIO_2DOF): {"ptpe": (25.1, 3.4), "rmse": (10.1, 3.7)},
})
"""The paper's Table II (source: Kim & Mansi, Table II), keyed by (controller, scenario)."""

PAPER_CELLS: Mapping[tuple[str, str], Mapping[str, tuple[float, float]]] = MappingProxyType(
    {**PAPER_TABLE_I, **PAPER_TABLE_II})
"""Every cell of the paper's Tables I and II, keyed by (controller, scenario)."""

# Kim & Mansi, Tables I and II, row "Improvement rate (%)" of Compensation+Shift, given in the
# paper as "<against No Compensation> and <against Compensation-Only>".
PAPER_IMPROVEMENT: Mapping[str, Mapping[str, tuple[float, float]]] = MappingProxyType({
    "alpha=45": {"ptpe": (60.74, 19.3), "rmse": (68.9, 67.3)},
    "alpha=90": {"ptpe": (65.3, 42.2), "rmse": (79.0, 74.4)},
    SCENARIO_2DOF: {"ptpe": (45.8, 17.7), "rmse": (44.0, 37.5)},
})
"""The paper's improvement rates of Compensation+Shift (vs none, vs comp), source: Kim & Mansi."""

TOLERANCE = 0.30
"""How close every cell must come to the paper's: within 30 %."""

DETECT_MAX_TRAVEL = 60.0
"""Travel limit of Algorithm 1 in the demo (deg of knob). The calibrated catheters have dead
zones of about +-19 deg and shifts up to 27.5 deg of knob, so the edge a search from q = 0 meets
can lie up to 47 deg away (at 90 deg of bend the search starts with the posterior tendon taut, a
few degrees outside the new dead zone, inside the backlash of the sheath friction: the fall into
the dead zone is then hard to see and the search may go on to the far edge); the replays cover
+-60 deg."""

DETECT_STEP = 0.5
"""Unit step u of Algorithm 1 (deg), the shift module's default."""

SWEEP_FS = 1000.0
"""Sample rate of the identification sweeps (Hz): the paper's sweep at a motor-driver rate."""

REPLAY_AMPLITUDE = 60.0
REPLAY_SPEED = 10.0
REPLAY_FS = 200.0
"""The detection replay: a slow triangle 0 -> +60 -> -60 -> 0 deg at 10 deg/s, 200 Hz. Slow so
the viscous lag of the tendon moves the edge the current shows by well under a unit step."""

# What the lab's recorder keeps: time to 1 us, knob encoder to 1e-4 deg, EM tip to 1e-3 deg,
# motor current to 0.01 mA. Simulated and file-read recordings are rounded alike, so the demo
# gives the same numbers from sample_data/ as from the twin directly.
_RESOLUTION = {"t": 6, "q": 4, "r": 4, "y": 3, "c": 2}


def _quantize(run: Run) -> Run:
    cols = {}
    for name, values in run.columns.items():
        digits = _RESOLUTION.get(name[:1]) if name == "t" or name[1:] in ("1", "2") else None
        cols[name] = np.round(values, digits) + 0.0 if digits is not None else values
    return Run(cols, run.meta, run.source)


def _seed(seed: int, *keys: int) -> int:
    """A seed per (experiment seed, keys...): independent streams, reproducible."""
    return int(np.random.SeedSequence([int(seed), *map(int, keys)]).generate_state(1)[0])


# --------------------------------------------------------------------------------------------
# scenarios and recordings
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Scenario:
    """One column of Table I or II.

    Attributes
    ----------
    name : str
        ``straight``, ``alpha=45``, ``alpha=90`` or :data:`SCENARIO_2DOF`.
    table : str
        ``"I"`` or ``"II"``.
    motion : str
        ``periodic`` (1-DoF) or ``nonperiodic`` (2-DoF).
    file_tag : str
        Name part of its replay files.
    """

    name: str
    table: str
    motion: str
    file_tag: str

    def shape(self, knob: int) -> Shape:
        """The shaft shape of a run of knob ``knob`` (the 2-DoF shape whatever the knob)."""
        if self.table == "II":
            return Shape.parse(SCENARIO_2DOF)
        if self.name == "straight":
            return Shape()
        alpha = float(self.name.split("=")[1])
        return Shape.parse(f"alpha={alpha:g},theta={0 if knob == 1 else 90}")

    @property
    def knobs_together(self) -> bool:
        """Both knobs in one run (2-DoF) rather than one knob per run."""
        return self.table == "II"

    @property
    def knob_groups(self) -> list[tuple[int, ...]]:
        """The knobs of each run: both in one run (2-DoF), else one run per knob."""
        return [tuple(KNOBS)] if self.knobs_together else [(k,) for k in KNOBS]

    @property
    def bent(self) -> bool:
        """Whether the shaft is bent (there is a shift: Compensation+Shift runs)."""
        return self.name != "straight"


SCENARIOS: tuple[Scenario, ...] = (
    Scenario("straight", "I", "periodic", "straight"),
    Scenario("alpha=45", "I", "periodic", "alpha45"),
    Scenario("alpha=90", "I", "periodic", "alpha90"),
    Scenario(SCENARIO_2DOF, "II", "nonperiodic", "2dof"),
)
"""The four columns of Tables I and II, in the paper's order."""

KNOBS = (1, 2)


def sweep_path(data_dir: Path, catheter: str, knob: int) -> Path:
    """Where a data directory keeps the identification sweep of ``knob``."""
    return Path(data_dir) / catheter / f"sweep_knob{knob}.csv"


def replay_path(data_dir: Path, catheter: str, scenario: Scenario, knob: int) -> Path:
    """Where a data directory keeps the detection replay of ``knob`` under ``scenario``."""
    return Path(data_dir) / catheter / f"replay_{scenario.file_tag}_knob{knob}.csv"


def reference_path(data_dir: Path, motion: str) -> Path:
    """Where a data directory keeps the reference trajectory of ``motion``."""
    return Path(data_dir) / f"reference_{motion}.csv"


def replay_motion() -> tuple[np.ndarray, np.ndarray]:
    """The detection replay's knob motion: 0 -> +A -> -A -> 0 at constant speed. Returns (t, q)."""
    a, v = REPLAY_AMPLITUDE, REPLAY_SPEED
    n = int(round(4 * a / v * REPLAY_FS)) + 1
    t = np.arange(n) / REPLAY_FS
    s = v * t
    q = np.where(s <= a, s, np.where(s <= 3 * a, 2 * a - s, s - 4 * a))
    return t, q


def record_sweep(catheter: VirtualCatheter, knob: int, seed: int = 0) -> Run:
    """The identification sweep of one knob on the straight shaft (paper section II-C-2).

    +-40 deg, 2 cycles, 40 deg/s peak, sampled at 1 kHz, with tip angle and motor current,
    rounded to the recorder's resolution.
    """
    t, q = sweep(fs=SWEEP_FS)
    run = simulate(catheter, t, {knob: q}, seed=_seed(seed, 1, knob),
                   meta={"motion": "sweep", "controller": "none", "knob": knob})
    return _quantize(run)


def record_replay(catheter: VirtualCatheter, scenario: Scenario, knob: int, seed: int = 0) -> Run:
    """A slow sweep of ``knob`` under the scenario's shape, for Algorithm 1 (the other knob at rest)."""
    t, q = replay_motion()
    tag = SCENARIOS.index(scenario)
    run = simulate(catheter, t, {knob: q}, shape=scenario.shape(knob), seed=_seed(seed, 2, tag, knob),
                   meta={"motion": "replay", "controller": "none", "knob": knob})
    return _quantize(run)


def reference_periodic() -> Run:
    """The paper's periodic reference for knob 1 (60 deg, 0.04 Hz, 2 cycles, 100 Hz)."""
    t, r = periodic()
    return _quantize(Run({"t": t, "r1": r}, {"motion": "periodic"}))


def reference_nonperiodic() -> Run:
    """The paper's non-periodic 2-DoF reference: r2 runs twice as fast as r1 (100 s, 100 Hz)."""
    t, r1 = nonperiodic(speed=1.0)
    _, r2 = nonperiodic(speed=2.0)
    return _quantize(Run({"t": t, "r1": r1, "r2": r2}, {"motion": "nonperiodic"}))


SAMPLE_DATA = Path("sample_data")
"""The repository's data directory, relative to its root (where ``hyst demo`` reads it)."""

SAMPLE_DATA_SEED = 0
"""The seed ``scripts/make_sample_data.py`` recorded the committed ``sample_data/`` with."""


def default_data_dir(cwd: str | Path | None = None) -> Path | None:
    """``sample_data/`` when the folder ``cwd`` (default: the current one) holds the demo's
    recordings, else None: the demo then records them from the twin.

    An installed ``hyst`` ships no data files: the recordings are seeded, so recording them again
    gives the very same runs (:func:`sample_data_runs`; a test holds them to the committed files
    byte for byte).
    """
    folder = Path(cwd) / SAMPLE_DATA if cwd is not None else SAMPLE_DATA
    return folder if reference_path(folder, "periodic").is_file() else None


def sample_data_runs(seed: int = SAMPLE_DATA_SEED) -> dict[Path, Run]:
    """Every recording of the demo's data directory, keyed by its path relative to it.

    What ``scripts/make_sample_data.py`` writes (with ``seed`` 0 the committed ``sample_data/``)
    and what :func:`run_protocol` records itself when it has no data directory.
    """
    runs: dict[Path, Run] = {reference_path(Path(), "periodic"): reference_periodic(),
                             reference_path(Path(), "nonperiodic"): reference_nonperiodic()}
    for name in CALIBRATED_NAMES:
        cat = calibrated_catheter(name)
        for k in KNOBS:
            runs[sweep_path(Path(), name, k)] = record_sweep(cat, k, seed)
        for s in SCENARIOS:
            for k in KNOBS:
                runs[replay_path(Path(), name, s, k)] = record_replay(cat, s, k, seed)
    return runs


class _Source:
    """Where the recordings come from: a data directory, or the twin directly."""

    def __init__(self, data_dir: Path | None, seed: int) -> None:
        self.data_dir = None if data_dir is None else Path(data_dir)
        self.seed = seed
        self.files: list[Path] = []
        if self.data_dir is not None and not self.data_dir.is_dir():
            raise DataError(f"{self.data_dir}: no such data directory (give a folder made by "
                            f"scripts/make_sample_data.py, or none to record from the twin)")

    def _read(self, path: Path, require: Sequence[str]) -> Run:
        if not path.exists():
            raise DataError(f"{path}: missing from the data directory "
                            f"(make it with scripts/make_sample_data.py)")
        self.files.append(path)
        return read_run(path, require=require)

    def sweep(self, cat: VirtualCatheter, knob: int) -> Run:
        if self.data_dir is None:
            return record_sweep(cat, knob, self.seed)
        return self._read(sweep_path(self.data_dir, cat.name, knob), (f"q{knob}", f"c{knob}"))

    def replay(self, cat: VirtualCatheter, scenario: Scenario, knob: int) -> Run:
        if self.data_dir is None:
            return record_replay(cat, scenario, knob, self.seed)
        return self._read(replay_path(self.data_dir, cat.name, scenario, knob), (f"q{knob}", f"c{knob}"))

    def reference(self, motion: str) -> Run:
        if self.data_dir is None:
            return reference_periodic() if motion == "periodic" else reference_nonperiodic()
        need = ("r1",) if motion == "periodic" else ("r1", "r2")
        return self._read(reference_path(self.data_dir, motion), need)


# --------------------------------------------------------------------------------------------
# results
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Cell:
    """One cell of Table I or II: our (mean, std) beside the paper's.

    Attributes
    ----------
    table : str
        ``"I"`` or ``"II"``.
    scenario, controller : str
    n : int
        Pooled run-knob results (catheters x knobs x trials).
    ptpe, rmse : tuple of (float, float or None)
        Ours: mean and sample std (deg).
    paper_ptpe, paper_rmse : tuple of (float, float) or None
        The paper's (mean, std); None where the paper has "-".
    improvement : mapping
        Ours, in %, ``{"none": {"ptpe": .., "rmse": ..}, "comp": {...}}`` (what exists).
    """

    table: str
    scenario: str
    controller: str
    n: int
    ptpe: tuple[float, float | None]
    rmse: tuple[float, float | None]
    paper_ptpe: tuple[float, float] | None = None
    paper_rmse: tuple[float, float] | None = None
    improvement: Mapping[str, Mapping[str, float | None]] = field(default_factory=dict)

    def ratio(self, metric: str) -> float | None:
        """Ours / paper for ``metric`` (``ptpe`` or ``rmse``) on the means; None without a paper value."""
        paper = self.paper_ptpe if metric == "ptpe" else self.paper_rmse
        ours = self.ptpe if metric == "ptpe" else self.rmse
        return None if paper is None else ours[0] / paper[0]

    def within(self, metric: str, tol: float = TOLERANCE) -> bool | None:
        """Whether ours is within ``tol`` (relative) of the paper's mean; None without a paper value."""
        r = self.ratio(metric)
        return None if r is None else abs(r - 1.0) <= tol + 1e-12

    def to_dict(self) -> dict:
        out = {"table": self.table, "scenario": self.scenario, "controller": self.controller,
               "n": self.n,
               "ptpe": {"mean": self.ptpe[0], "std": self.ptpe[1]},
               "rmse": {"mean": self.rmse[0], "std": self.rmse[1]},
               "improvement": {b: dict(v) for b, v in self.improvement.items()}}
        if self.paper_ptpe is not None:
            out["paper"] = {"ptpe": {"mean": self.paper_ptpe[0], "std": self.paper_ptpe[1]},
                            "rmse": {"mean": self.paper_rmse[0], "std": self.paper_rmse[1]},
                            "source": f"Kim & Mansi, Table {self.table}"}
            out["ratio"] = {"ptpe": self.ratio("ptpe"), "rmse": self.ratio("rmse")}
            out["within_tolerance"] = {"ptpe": self.within("ptpe"), "rmse": self.within("rmse")}
        return out


@dataclass(frozen=True)
class ShiftRow:
    """Algorithm 1 on one replay: the detected offset beside the twin's true one.

    Attributes
    ----------
    catheter, scenario : str
    knob : int
    shape : str
    true_offset : float or None
        From the replay's ``true_offset<k>`` metadata (deg).
    result : ShiftResult or None
        None where Algorithm 1 refused (``refused`` says why): the comp+shift runs then apply no
        shift on that knob (Compensation-Only), as a robot whose search refused would.
    true_edge : float or None
        Where the twin really has the edge the search found (deg): the true offset plus the
        catheter's true ``d_pos`` or ``d_neg``.
    """

    catheter: str
    scenario: str
    knob: int
    shape: str
    true_offset: float | None
    result: ShiftResult | None
    true_edge: float | None = None
    refused: str | None = None

    @property
    def error(self) -> float | None:
        """Detected minus true offset (deg): the search's error plus the identification's error
        in the edge it measures from (``offset = edge - D`` of the identified model)."""
        if self.true_offset is None or self.result is None:
            return None
        return self.result.offset - self.true_offset

    @property
    def edge_error(self) -> float | None:
        """Found minus true edge (deg): the search's own error, whatever the identified D."""
        if self.true_edge is None or self.result is None:
            return None
        return self.result.edge_found_at - self.true_edge

    def to_dict(self) -> dict:
        r = self.result
        if r is None:
            return {"catheter": self.catheter, "scenario": self.scenario, "knob": self.knob, "shape": self.shape,
                    "true_offset": self.true_offset, "refused": self.refused}
        return {"catheter": self.catheter, "scenario": self.scenario, "knob": self.knob,
                "shape": self.shape, "offset": r.offset, "true_offset": self.true_offset,
                "error": self.error, "edge": r.edge, "edge_found_at": r.edge_found_at,
                "true_edge": self.true_edge, "edge_error": self.edge_error,
                "offset_lo": r.offset_lo, "offset_hi": r.offset_hi, "start_outside": r.start_outside,
                "travel": r.travel, "steps": r.steps}


@dataclass(frozen=True)
class DiagnosisRow:
    """The diagnosis of one catheter's Compensation+Shift runs (beyond the paper).

    Attributes
    ----------
    catheter : str
    runs : int
        Compensation+Shift runs diagnosed.
    effects : tuple of (str, mapping)
        The effects the diagnosis added, with their fitted parameters.
    true_effects : tuple of (str, mapping)
        What the virtual catheter really has (:mod:`hystcli.calibration`), for comparison.
    rmse_before, rmse_after : float
        Held-out (leave one run out) RMSE of the tip prediction without and with the effects (deg).
    holdout : str
        The hold-out scheme in words.
    forms : tuple of str
        The form of each added effect (its family's first form when empty).
    """

    catheter: str
    runs: int
    effects: tuple[tuple[str, Mapping[str, float]], ...]
    true_effects: tuple[tuple[str, Mapping[str, float]], ...]
    rmse_before: float
    rmse_after: float
    holdout: str
    forms: tuple[str, ...] = ()

    def to_dict(self) -> dict:
        forms = self.forms or ("",) * len(self.effects)
        return {"catheter": self.catheter, "runs": self.runs,
                "effects": [{"name": n, **({"form": f} if f else {}), "params": dict(p)}
                            for (n, p), f in zip(self.effects, forms)],
                "true_effects": [{"name": n, "params": dict(p)} for n, p in self.true_effects],
                "heldout_rmse": {"before": self.rmse_before, "after": self.rmse_after},
                "holdout": self.holdout}


@dataclass(frozen=True)
class ExperimentResult:
    """What :func:`run_protocol` returns.

    Attributes
    ----------
    cells : tuple of Cell
        Table I cells (scenario order, then controller order), then Table II's.
    shifts : tuple of ShiftRow
        Every detection (catheter, scenario, knob).
    models : mapping of str to Model
        The identified straight-shaft model of each catheter.
    runs : tuple of Run
        Every evaluation run (for figures; not in :meth:`to_dict`).
    config : mapping
        Catheters, trials, seed, data source (with the input files' names), calibration.
    warnings : tuple of str
    diagnoses : tuple of DiagnosisRow
        Beyond the paper: one per catheter when the protocol ran the diagnosis.
    augmented : mapping of str to Model
        The augmented model of each diagnosed catheter.
    """

    cells: tuple[Cell, ...]
    shifts: tuple[ShiftRow, ...]
    models: Mapping[str, Model]
    runs: tuple[Run, ...] = field(repr=False, default=())
    config: Mapping[str, object] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()
    diagnoses: tuple[DiagnosisRow, ...] = ()
    augmented: Mapping[str, Model] = field(default_factory=dict)

    def table(self, name: str) -> tuple[Cell, ...]:
        """The cells of Table ``"I"`` or ``"II"``."""
        return tuple(c for c in self.cells if c.table == name)

    def cell(self, controller: str, scenario: str) -> Cell:
        """The cell of ``controller`` under ``scenario`` (KeyError when absent)."""
        for c in self.cells:
            if c.controller == controller and c.scenario == scenario:
                return c
        raise KeyError((controller, scenario))

    def beyond(self) -> list[tuple[str, Cell, float]]:
        """Beyond the paper: per scenario with a Compensation+Shift value in the paper, the
        diagnosed controller's cell and its target (``BEYOND_FACTOR`` x the paper's RMSE)."""
        out = []
        for c in self.cells:
            if c.controller != DIAGNOSED:
                continue
            paper = PAPER_CELLS.get(("comp+shift", c.scenario))
            if paper is not None:
                out.append((c.scenario, c, BEYOND_FACTOR * paper["rmse"][0]))
        return out

    def beyond_misses(self) -> list[tuple[str, Cell, float]]:
        """The scenarios where the diagnosed controller's RMSE is above its target."""
        return [(s, c, target) for s, c, target in self.beyond() if c.rmse[0] > target]

    def misses(self, tol: float = TOLERANCE) -> list[tuple[Cell, str, float]]:
        """Cells (and metric, ratio) more than ``tol`` away from the paper's value."""
        out = []
        for c in self.cells:
            for m in ("ptpe", "rmse"):
                if c.within(m, tol) is False:
                    out.append((c, m, c.ratio(m)))
        return out

    def compared(self) -> int:
        """How many (cell, metric) pairs have a paper value."""
        return sum(1 for c in self.cells for m in ("ptpe", "rmse") if c.ratio(m) is not None)

    def to_dict(self) -> dict:
        from .io import model_to_dict

        return {
            "format": "hyst-demo",
            "version": 1,
            "config": dict(self.config),
            "tolerance": TOLERANCE,
            "within_tolerance": f"{self.compared() - len(self.misses())}/{self.compared()}",
            "table_I": [c.to_dict() for c in self.table("I")],
            "table_II": [c.to_dict() for c in self.table("II")],
            "paper_improvement": {s: {m: {"none": v[0], "comp": v[1]} for m, v in d.items()}
                                  for s, d in PAPER_IMPROVEMENT.items()},
            "shifts": [s.to_dict() for s in self.shifts],
            "models": {name: model_to_dict(m) for name, m in self.models.items()},
            "beyond_paper": {
                "controller": DIAGNOSED,
                "diagnoses": [d.to_dict() for d in self.diagnoses],
                "augmented_models": {name: model_to_dict(m) for name, m in self.augmented.items()},
                "targets": [{"scenario": sc, "rmse": c.rmse[0], "target": tg, "met": c.rmse[0] <= tg}
                            for sc, c, tg in self.beyond()],
            },
            "warnings": list(self.warnings),
        }

    def to_json(self) -> str:
        """The results as JSON text (same inputs and seed: same bytes)."""
        return json.dumps(self.to_dict(), indent=2, allow_nan=False, default=_json_default) + "\n"


def _json_default(obj: object) -> object:
    if isinstance(obj, np.generic):
        return obj.item()
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


# --------------------------------------------------------------------------------------------
# the protocol
# --------------------------------------------------------------------------------------------
def identify_catheter(sweeps: Mapping[int, Run], name: str) -> Model:
    """The straight-shaft model of one catheter from one identification sweep per knob.

    As in the paper (section III): dead-zone edges and backlash widths from the motor current,
    omega = 1.45 (:data:`hystcli.model.PAPER_OMEGA`); the heights follow from them
    (:func:`hystcli.identification.identify` on its current path).
    """
    knobs, ident = {}, {}
    for k, run in sorted(sweeps.items()):
        fit = identify(run, knobs=[k], omega=PAPER_OMEGA, use_tip=False).model
        knobs[k] = fit.knob(k)
        ident[k] = fit.identification[k]
    return Model(knobs, meta={"catheter": name, "method": "current, omega = 1.45 (paper section III)"},
                 identification=ident)


def _commands(model: Model, reference: Run, controller: str, offsets: Mapping[int, float],
              scenario: Scenario, knobs: Sequence[int]) -> Run:
    """The knob commands of one controller for the reference's knobs ``knobs``."""
    cols = {"t": reference.t}
    for k in knobs:
        cols[f"r{k}"] = reference[f"r{k}" if scenario.knobs_together else "r1"]
    meta = {"motion": scenario.motion}
    traj = Run(cols, meta)
    if controller == "none":
        return Run({**cols, **{f"q{k}": cols[f"r{k}"] for k in knobs}}, {**meta, "controller": "none"})
    # the detected offsets ride in the trajectory's metadata, the first source of docs/design.md
    # section 6's rule, so compensate uses exactly what Algorithm 1 found
    traj = traj.with_meta(**{f"offset{k}": repr(float(offsets[k])) for k in knobs})
    comp = compensate(model, traj, ignore_shift=(controller == "comp")).run
    return comp.with_meta(controller=controller)


def run_protocol(catheters: Sequence[str] = ("ice-a", "ice-b"), trials: int = 3, seed: int = 0,
                 data_dir: str | Path | None = None,
                 progress: Callable[[str, int, int], None] | None = None,
                 scenarios: Sequence[str] | None = None,
                 duration_scale: float = 1.0, diagnose: bool = True,
                 recording_seed: int | None = None) -> ExperimentResult:
    """Run the paper's experiment on the calibrated virtual catheters: Tables I and II.

    Parameters
    ----------
    catheters : sequence of str
        Calibrated virtual catheters (:mod:`hystcli.calibration`).
    trials : int
        Trials per (catheter, scenario, knob, controller); each has its own sensor noise.
    seed : int
        Seed of the trials' noise (and of the recordings when ``data_dir`` is None).
    data_dir : path, optional
        A data directory (``sample_data/``) holding the sweeps, replays and references; None
        records them from the twin (the same recordings ``scripts/make_sample_data.py`` writes
        when ``seed`` is 0).
    progress : callable, optional
        Called as ``progress(what, done, total)`` after every step.
    scenarios : sequence of str, optional
        A subset of the table columns (``straight``, ``alpha=45``, ``alpha=90``,
        :data:`SCENARIO_2DOF`); default all.
    duration_scale : float
        Shorten the evaluation runs (0 < scale <= 1) for quick checks; the tables' comparison
        with the paper needs 1.
    diagnose : bool
        Beyond the paper: diagnose each catheter's Compensation+Shift runs and run the
        ``comp+shift+diag`` controller (needs at least two such runs per catheter).
    recording_seed : int, optional
        Seed of the recordings when ``data_dir`` is None (default ``seed``);
        :data:`SAMPLE_DATA_SEED` records exactly the committed ``sample_data/``.

    Returns
    -------
    ExperimentResult

    Raises
    ------
    DataError
        A missing data directory or file, a bad option.
    IdentificationError, ShiftDetectionError
        When a recording cannot identify a model or show an edge.
    """
    # one BLAS thread: the protocol's linear algebra is many small products, where a threaded
    # BLAS spends its time waking (and, on a shared 2-core machine, fighting for) threads
    with threadpool_limits(limits=1):
        return _run_protocol(catheters, trials, seed, data_dir, progress, scenarios, duration_scale, diagnose,
                             recording_seed)


def _run_protocol(catheters, trials, seed, data_dir, progress, scenarios, duration_scale,
                  diagnose, recording_seed) -> ExperimentResult:
    if int(trials) < 1:
        raise DataError(f"trials must be at least 1, got {trials}")
    if not catheters:
        raise DataError("no catheter to run")
    if not (0 < duration_scale <= 1):
        raise DataError(f"duration_scale must be in (0, 1], got {duration_scale}")
    wanted = [s for s in SCENARIOS if scenarios is None or s.name in scenarios]
    if scenarios is not None:
        unknown = set(scenarios) - {s.name for s in SCENARIOS}
        if unknown:
            raise DataError(f"unknown scenario {sorted(unknown)[0]!r} "
                            f"(known: {', '.join(s.name for s in SCENARIOS)})")
    cats = [calibrated_catheter(name) for name in catheters]
    source = _Source(None if data_dir is None else Path(data_dir),
                     int(seed if recording_seed is None else recording_seed))

    def runs_per_catheter() -> int:
        return sum((len(CONTROLLERS) - (0 if s.bent else 1)) * len(s.knob_groups) for s in wanted)

    n_diag = int(trials) * sum(len(s.knob_groups) for s in wanted if s.bent) if diagnose else 0
    if diagnose and n_diag < 2:
        raise DataError("the diagnosis needs at least two Compensation+Shift runs per catheter: "
                        "add a bent scenario or trials, or leave the diagnosis out")
    total = len(cats) * (1 + len(wanted) * len(KNOBS) + int(trials) * runs_per_catheter()
                         + (1 + n_diag if diagnose else 0))
    done = 0

    def tick(what: str) -> None:
        nonlocal done
        done += 1
        if progress is not None:
            progress(what, done, total)

    refs = {}
    for motion in sorted({s.motion for s in wanted}):
        ref = source.reference(motion)
        if duration_scale < 1:
            n = max(int(len(ref) * duration_scale), 10)
            ref = Run({c: v[:n] for c, v in ref.columns.items()}, ref.meta, ref.source)
        refs[motion] = ref

    models: dict[str, Model] = {}
    augmented: dict[str, Model] = {}
    diagnoses: list[DiagnosisRow] = []
    shifts: list[ShiftRow] = []
    runs: list[Run] = []
    warnings: list[str] = []
    detected: dict[tuple[str, str], dict[int, float]] = {}

    def play(ci: int, cat: VirtualCatheter, s: Scenario, knobs: tuple[int, ...], trial: int, model: Model,
             ctrl: str, label: str, stream: int) -> None:
        """Compensate the reference with ``model`` as controller ``ctrl``, run it on the twin as
        ``label`` with noise from ``stream``, and keep the run."""
        cmd = _commands(model, refs[s.motion], ctrl, detected[cat.name, s.name], s, knobs)
        run = simulate_motion(cat, s.shape(knobs[0]), commands=cmd, controller=label,
                              seed=_seed(seed, stream, ci, SCENARIOS.index(s), knobs[0]), trial=trial)
        runs.append(run.with_meta(scenario=s.name))
        tick(f"{cat.name} {s.name}: trial {trial} {label}")

    for ci, cat in enumerate(cats):
        model = identify_catheter({k: source.sweep(cat, k) for k in KNOBS}, cat.name)
        models[cat.name] = model
        tick(f"{cat.name}: identified")
        for s in wanted:
            offsets: dict[int, float] = {}
            detected[cat.name, s.name] = offsets
            for k in KNOBS:
                replay = source.replay(cat, s, k)
                true = replay.meta.get(f"true_offset{k}")
                true = None if true is None else float(true)
                try:
                    res = detect_shift(model, ReplayProbe(replay, k), k, step=DETECT_STEP,
                                       max_travel=DETECT_MAX_TRAVEL)
                except ShiftDetectionError as exc:
                    # a robot whose search refuses applies no shift on that knob
                    shifts.append(ShiftRow(cat.name, s.name, k, str(s.shape(k)), true, None, None, str(exc)))
                    offsets[k] = 0.0
                    tick(f"{cat.name} {s.name}: knob {k} shift refused")
                    continue
                d_true = cat.knobs[k].d_pos if res.edge == "pos" else cat.knobs[k].d_neg
                shifts.append(ShiftRow(cat.name, s.name, k, str(s.shape(k)), true, res,
                                       None if true is None else true + d_true))
                offsets[k] = res.offset
                tick(f"{cat.name} {s.name}: knob {k} shift {res.offset:+.2f} deg")
            for trial in range(1, int(trials) + 1):
                for knobs in s.knob_groups:
                    for ctrl in CONTROLLERS:
                        if ctrl == "comp+shift" and not s.bent:
                            continue  # the paper's "-": no shift to apply on the straight shaft
                        # common noise across controllers within a cell (a paired comparison),
                        # independent across catheters, scenarios, knobs and trials
                        play(ci, cat, s, knobs, trial, model, ctrl, ctrl, stream=3)
        if diagnose:
            aug, row = _diagnose_catheter(cat, model, [r for r in runs if r.meta.get("catheter") == cat.name
                                                       and r.meta.get("controller") == "comp+shift"])
            augmented[cat.name] = aug
            diagnoses.append(row)
            tick(f"{cat.name}: diagnosed " + (", ".join(n for n, _ in row.effects) or "no effect"))
            for s in (s for s in wanted if s.bent):
                for trial in range(1, int(trials) + 1):
                    for knobs in s.knob_groups:
                        # fresh noise (stream 4): the diagnosis was fitted on the stream-3 runs
                        play(ci, cat, s, knobs, trial, aug, "comp+shift", DIAGNOSED, stream=4)

    cells: list[Cell] = []
    for s in wanted:
        sel = [r for r in runs if r.meta.get("scenario") == s.name]
        ev = metrics.evaluate_runs(sel, group_by=("controller",))
        warnings.extend(ev.warnings)
        for g in ev.groups:
            ctrl = g.value("controller")
            p = PAPER_CELLS.get((ctrl, s.name))
            imp = {i.baseline: {"ptpe": i.ptpe, "rmse": i.rmse} for i in g.improvements}
            cells.append(Cell(s.table, s.name, ctrl, g.n, (g.ptpe_mean, g.ptpe_std), (g.rmse_mean, g.rmse_std),
                              None if p is None else p["ptpe"], None if p is None else p["rmse"], imp))

    config = {
        "catheters": list(catheters), "trials": int(trials), "seed": int(seed),
        "data": (f"twin (simulated recordings, seed {source.seed})" if data_dir is None else str(data_dir)),
        "input_files": [str(p) for p in source.files],
        "scenarios": [s.name for s in wanted],
        "duration_scale": float(duration_scale),
        "identification": "current (edges, backlash), omega = 1.45",
        "detection": {"step": DETECT_STEP, "max_travel": DETECT_MAX_TRAVEL},
        "calibration": {c.name: _catheter_dict(c) for c in cats},
    }
    if diagnose:
        config["diagnosis"] = {"runs": "Compensation+Shift runs of each catheter (all its bent scenarios)",
                               "holdout": "leave one run out",
                               "evaluation": f"{DIAGNOSED} on fresh trials (noise stream 4)"}
    return ExperimentResult(tuple(cells), tuple(shifts), MappingProxyType(models), tuple(runs),
                            MappingProxyType(config), tuple(dict.fromkeys(warnings)), tuple(diagnoses),
                            MappingProxyType(augmented))


def _diagnose_catheter(cat: VirtualCatheter, model: Model, runs: Sequence[Run]) -> tuple[Model, DiagnosisRow]:
    """Diagnose one catheter's Compensation+Shift runs: the augmented model and its summary.

    The runs carry the detected offsets (``offset<k>``, what the controller used), so the
    diagnosis explains the residual the paper's method leaves, offset errors included.
    """
    d = _diagnose(model, runs)
    row = DiagnosisRow(cat.name, len(runs), tuple((s.name, dict(s.params)) for s in d.selected),
                       tuple((e.name, dict(e.params)) for e in cat.default_effects),
                       d.how_far.rmse_before, d.how_far.rmse_after, d.holdout,
                       tuple(s.form for s in d.selected))
    return d.model, row


def _catheter_dict(cat: VirtualCatheter) -> dict:
    return {"knobs": {str(k): kn.params() for k, kn in cat.knobs.items()},
            "geometry": {"beta_catheter_mm": cat.geometry.beta_catheter_mm,
                         "beta_knob_mm": cat.geometry.beta_knob_mm},
            "effects": [{"name": e.name, "params": dict(e.params)} for e in cat.default_effects]}


# --------------------------------------------------------------------------------------------
# rendering (pure text) and figures
# --------------------------------------------------------------------------------------------
_LABELS = metrics.CONTROLLER_LABELS


def _pair(v: tuple[float, float | None] | None) -> str:
    if v is None:
        return "-"
    return f"({v[0]:.1f}, {v[1]:.1f})" if v[1] is not None else f"({v[0]:.1f}, -)"


def _ratio_text(c: Cell, metric: str) -> str:
    r = c.ratio(metric)
    if r is None:
        return "-"
    return f"{r:.2f} " + ("ok" if c.within(metric) else "MISS")


def comparison_table(result: ExperimentResult, table: str) -> Table:
    """Table I or II as rows: controller, shape, ours and the paper's (mean, std), ratio, mark."""
    cols = ("controller", "shape", "ptpe_ours", "ptpe_paper", "ptpe_ratio", "rmse_ours", "rmse_paper",
            "rmse_ratio")
    heads = ("controller", "shaft shape", "PTPE ours", "PTPE paper", "ours/paper",
             "RMSE ours", "RMSE paper", "ours/paper")
    rows = []
    # the paper's layout: one block of rows per controller, the shapes in order within it
    order = {c: i for i, c in enumerate(CONTROLLERS)}
    scen = {s.name: i for i, s in enumerate(SCENARIOS)}
    cells = sorted((c for c in result.table(table) if c.controller in order),
                   key=lambda c: (order[c.controller], scen.get(c.scenario, len(scen))))
    for c in cells:
        rows.append((_LABELS.get(c.controller, c.controller), c.scenario, _pair(c.ptpe), _pair(c.paper_ptpe),
                     _ratio_text(c, "ptpe"), _pair(c.rmse), _pair(c.paper_rmse), _ratio_text(c, "rmse")))
    for c in result.table(table):
        if c.controller != "comp+shift":
            continue
        ours = c.improvement
        paper = PAPER_IMPROVEMENT.get(c.scenario)

        def imp(metric: str) -> str:
            vals = [ours.get(b, {}).get(metric) for b in ("none", "comp")]
            return " and ".join("-" if v is None else f"{v:.1f}" for v in vals)

        def pimp(metric: str) -> str:
            return "-" if paper is None else " and ".join(f"{v:g}" for v in paper[metric])

        rows.append(("Improvement rate (%)", c.scenario, imp("ptpe"), pimp("ptpe"), "", imp("rmse"),
                     pimp("rmse"), ""))
    title = ("Table I: PTPE and RMSE for 1-DoF, periodic inputs" if table == "I"
             else "Table II: PTPE and RMSE for 2-DoF, non-periodic inputs")
    notes = (title,
             "(mean, std) in deg over catheters x knobs x trials; paper: Kim & Mansi, Table " + table
             + f"; ok = ours within {TOLERANCE:.0%} of the paper's mean; improvement rate of "
               "Compensation+Shift against No Compensation and Compensation-Only")
    return Table(cols, heads, tuple(rows), notes, keys=2)


def _effects_text(effects: Sequence[tuple[str, Mapping[str, float]]], forms: Sequence[str] = ()) -> str:
    # a form other than the family's first is named: deadzone(shift=...) is centre or centre-bend
    if not effects:
        return "none"
    forms = tuple(forms) or ("",) * len(effects)
    return ", ".join(f"{n}{f'[{f}]' if f else ''}(" + ", ".join(f"{k}={v:.3g}" for k, v in p.items()) + ")"
                     for (n, p), f in zip(effects, forms))


def beyond_table(result: ExperimentResult) -> Table:
    """Beyond the paper: Compensation+Shift with the diagnosed model beside the paper's.

    One row per bent scenario: the paper's Compensation+Shift RMSE and PTPE, ours, ours after
    the diagnosis (``comp+shift+diag``), and the target (half the paper's RMSE). The notes name
    the effects the diagnosis found per catheter beside the ones the catheter really has.
    """
    cols = ("scenario", "rmse_paper", "rmse_ours", "rmse_diag", "rmse_target", "met", "ptpe_paper",
            "ptpe_ours", "ptpe_diag")
    heads = ("shaft shape", "RMSE paper C+S", "RMSE ours C+S", "RMSE ours C+S+diagnosis", "target",
             "met", "PTPE paper C+S", "PTPE ours C+S", "PTPE ours C+S+diagnosis")
    rows = []
    for scenario, c, target in result.beyond():
        paper = PAPER_CELLS[("comp+shift", scenario)]
        ours = result.cell("comp+shift", scenario)  # ran wherever the diagnosed controller did
        rows.append((scenario, _pair(paper["rmse"]), _pair(ours.rmse), _pair(c.rmse), f"<= {target:.2f}",
                     "yes" if c.rmse[0] <= target else "NO", _pair(paper["ptpe"]), _pair(ours.ptpe),
                     _pair(c.ptpe)))
    notes = ["Beyond the paper: Compensation+Shift (C+S) with the model `hyst diagnose` augmented",
             "(mean, std) in deg; target: half the paper's C+S RMSE; the diagnosis is fitted on the "
             "C+S runs, the diagnosed controller runs on fresh trials"]
    for d in result.diagnoses:
        notes.append(f"{d.catheter}: diagnosis of {d.runs} C+S runs added {_effects_text(d.effects, d.forms)}; "
                     f"held-out tip RMSE {d.rmse_before:.2f} -> {d.rmse_after:.2f} deg ({d.holdout}); "
                     f"the catheter has {_effects_text(d.true_effects)}")
    return Table(cols, heads, tuple(rows), tuple(notes))


def shift_table(result: ExperimentResult) -> Table:
    """Algorithm 1 per catheter, scenario and knob: detected and true offsets."""
    cols = ("catheter", "scenario", "knob", "offset", "offset_lo", "offset_hi", "true_offset", "error", "edge",
            "edge_found_at", "true_edge", "edge_error", "travel")
    heads = ("catheter", "scenario", "knob", "offset", "low", "high", "true offset", "error", "edge", "found at",
             "true edge", "edge error", "travel")
    rows = tuple((s.catheter, s.scenario, s.knob, s.result.offset, s.result.offset_lo, s.result.offset_hi,
                  s.true_offset, s.error, s.result.edge, s.result.edge_found_at, s.true_edge,
                  s.edge_error, s.result.travel) if s.result is not None else
                 (s.catheter, s.scenario, s.knob, None, None, None, s.true_offset, None, "refused", None, None, None,
                  None) for s in result.shifts)
    return Table(cols, heads, rows, (
        "Algorithm 1 on the replays",
        "deg; low/high: the offset's 95 % interval; error = detected - true offset; edge error = found - true "
        "edge (the search's own error; the offset is measured from where the sweep's current took the same "
        "tendon up)"), keys=3)


def _section(table: Table, fmt: str) -> str:
    """One titled table: ``notes[0]`` is the title, ``notes[1]`` the note under it, any further
    notes a list below that."""
    title, note, *items = table.notes
    body = Table(table.columns, table.headers, table.rows, keys=table.keys)
    if fmt == "markdown":
        listed = "".join(f"- {line}\n" for line in items)
        return f"**{title}**\n\n" + format_markdown(body) + f"\n{note}\n" + (f"\n{listed}" if items else "")
    width = TEXT_WIDTH
    listed = "".join(textwrap.fill(line, width, initial_indent="  ", subsequent_indent="    ",
                                   break_on_hyphens=False) + "\n" for line in items)
    return (f"{title}\n\n" + format_text(body) + "\n"
            + textwrap.fill(note, width, break_on_hyphens=False) + f"\n{listed}")


def render(result: ExperimentResult, fmt: str = "table") -> str:
    """Tables I and II beside the paper's values, the diagnosed controller beside the paper's
    Compensation+Shift, and Algorithm 1's detections, as text (``table``, ``markdown``) or ``json``."""
    if fmt == "json":
        return result.to_json()
    if fmt not in ("table", "markdown"):
        raise DataError(f"unknown format {fmt!r}: choose among table, markdown, json")
    tables = [comparison_table(result, "I"), comparison_table(result, "II"), beyond_table(result),
              shift_table(result)]
    parts = [_section(t, fmt) for t in tables if t.rows]
    compared = result.compared()
    summary = f"{compared - len(result.misses())}/{compared} paper values matched within {TOLERANCE:.0%}"
    if result.beyond():
        met = len(result.beyond()) - len(result.beyond_misses())
        summary += f"; beyond the paper: {met}/{len(result.beyond())} diagnosed RMSE at most half the paper's"
    parts.append(summary + "\n")
    return "\n".join(parts)


FIGURES = {"fig6_periodic_1dof": ("I", 1), "fig7_nonperiodic_2dof": ("II", None)}
"""Figure files: the paper's Fig. 6 (1-DoF, one catheter, knob 1, each shape) and Fig. 7 (2-DoF)."""


def figures(result: ExperimentResult, fmt: str = "png") -> dict[str, bytes]:
    """Figures like the paper's Figs. 6 and 7 of the first catheter's first trial, as file bytes.

    Keys are file names (``fig6_periodic_1dof.png``, ``fig7_nonperiodic_2dof.png``); a figure
    whose scenarios were not run is left out.
    """
    if not result.runs:
        return {}
    first = result.runs[0].meta.get("catheter")
    out = {}
    for name, (table, knob) in FIGURES.items():
        scen = {s.name for s in SCENARIOS if s.table == table}
        sel = [r for r in result.runs
               if r.meta.get("scenario") in scen and r.meta.get("catheter") == first
               and r.meta.get("trial") == "1" and (knob is None or f"q{knob}" in r)]
        if sel:
            out[f"{name}.{fmt}"] = evaluation_figure(sel, fmt)
    return out


def write_outputs(result: ExperimentResult, out_dir: str | Path, with_figures: bool = True,
                  fmt: str = "png") -> list[Path]:
    """Write ``results.json``, ``tables.md`` and the figures into ``out_dir`` (atomically).

    Returns the paths written.
    """
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise DataError(f"{out}: exists and is not a directory")
    files: dict[str, bytes] = {"results.json": result.to_json().encode("utf-8"),
                               "tables.md": render(result, "markdown").encode("utf-8")}
    if with_figures:
        files.update(figures(result, fmt))
    out.mkdir(parents=True, exist_ok=True)
    # every file or none: an error leaves the folder's old results whole, not half replaced
    with all_or_none() as pending:
        for name, data in files.items():
            pending.write_bytes(out / name, data)
    return [out / name for name in files]


__all__ = [
    "BEYOND_FACTOR", "CONTROLLERS", "Cell", "DIAGNOSED", "DiagnosisRow", "PAPER_CELLS", "beyond_table", "DETECT_MAX_TRAVEL", "ExperimentResult", "PAPER_IMPROVEMENT", "PAPER_TABLE_I",
    "PAPER_TABLE_II", "SCENARIOS", "SCENARIOS_1DOF", "SCENARIO_2DOF", "Scenario", "ShiftRow", "TOLERANCE",
    "comparison_table", "figures", "identify_catheter", "record_replay", "record_sweep",
    "reference_nonperiodic", "reference_path", "reference_periodic", "render", "replay_motion",
    "replay_path", "run_protocol", "SAMPLE_DATA", "SAMPLE_DATA_SEED", "default_data_dir", "sample_data_runs", "shift_table",
    "sweep_path", "write_outputs",
]
