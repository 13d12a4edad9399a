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
   (:func:`hystcli.sim.twin.simulate_motion`), several trials with different sensor noise;
5. evaluate every run (:func:`hystcli.report.metrics.evaluate_runs`) into the cells of Table I (1-DoF,
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

import json
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Callable, Mapping, Sequence

import numpy as np
from threadpoolctl import threadpool_limits

from ..report import metrics
from ..compensation import compensate
from ..core.model import Model
from ..core.params import PAPER_OMEGA
from ..core.run import Run
from ..diagnosis import diagnose as _diagnose
from ..errors import DataError, ShiftDetectionError
from ..identification import identify
from ..shift import ReplayProbe, ShiftResult, detect_shift
from .calibration import calibrated_catheter
from .scenarios import (BEYOND_FACTOR, CONTROLLERS, DETECT_MAX_TRAVEL, DETECT_STEP, DIAGNOSED, KNOBS, PAPER_CELLS,
                        PAPER_IMPROVEMENT, SCENARIOS, TOLERANCE, Scenario, _Source, _seed)
from .twin import VirtualCatheter, simulate_motion


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
        What the virtual catheter really has (:mod:`hystcli.sim.calibration`), for comparison.
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
        from ..io import model_to_dict

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
    omega = 1.45 (:data:`hystcli.core.params.PAPER_OMEGA`); the heights follow from them
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
        Calibrated virtual catheters (:mod:`hystcli.sim.calibration`).
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


