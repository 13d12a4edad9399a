"""The paper's protocol as data: its published values, the demo's settings, the shaft scenarios and
the recordings (sweeps, replays, references) the experiment runs on."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Mapping, Sequence

import numpy as np

from ..core.params import Shape
from ..core.run import Run
from ..errors import DataError
from ..io import read_run
from .calibration import CALIBRATED_NAMES, calibrated_catheter
from .twin import VirtualCatheter, nonperiodic, periodic, simulate, sweep


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
