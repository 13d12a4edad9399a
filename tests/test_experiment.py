"""The protocol runner behind `hyst demo` (hystcli/sim/experiment.py) and the calibrated catheters."""
from __future__ import annotations

import importlib.util
import json
import math
from pathlib import Path

import pytest

from hystcli.sim import experiment as ex
from hystcli.sim import render
from hystcli.sim import scenarios as sc
from hystcli.sim.calibration import CALIBRATED_NAMES, DEFAULT_EFFECTS, calibrated_catheter
from hystcli.errors import DataError
from hystcli.core.params import Shape

ROOT = Path(__file__).resolve().parent.parent
SAMPLE = ROOT / "sample_data"


@pytest.fixture(scope="module")
def small():
    # 1 catheter, 1 trial, every scenario: 2 knobs x (2 + 3 + 3) 1-DoF runs + 3 2-DoF runs = 19
    return ex.run_protocol(catheters=("ice-a",), trials=1, seed=0)


@pytest.mark.slow
def test_reduced_protocol_has_the_tables_structure(small):
    t1 = [c for c in small.table("I") if c.controller != sc.DIAGNOSED]
    t2 = [c for c in small.table("II") if c.controller != sc.DIAGNOSED]
    # Table I: none and comp at the straight shaft (comp+shift is the paper's "-"), all three
    # controllers at 45 and 90 deg; Table II: the three controllers.
    assert sorted((c.scenario, c.controller) for c in t1) == sorted(
        [("straight", "none"), ("straight", "comp")]
        + [(s, c) for s in ("alpha=45", "alpha=90") for c in ("none", "comp", "comp+shift")])
    assert [c.controller for c in t2] == ["none", "comp", "comp+shift"]
    # beyond the paper: the diagnosed controller wherever comp+shift ran, with no paper value
    diag = [c for c in small.cells if c.controller == sc.DIAGNOSED]
    assert sorted(c.scenario for c in diag) == sorted(["alpha=45", "alpha=90", sc.SCENARIO_2DOF])
    assert all(c.paper_rmse is None and c.ratio("rmse") is None for c in diag)
    # 1-DoF cells pool 1 catheter x 2 knobs x 1 trial; the 2-DoF run has both knobs in it
    assert all(c.n == 2 for c in small.cells)
    for c in t1 + t2:
        assert c.paper_ptpe is not None and c.paper_rmse is not None
        assert c.ratio("ptpe") == pytest.approx(c.ptpe[0] / c.paper_ptpe[0])
        assert c.ratio("rmse") == pytest.approx(c.rmse[0] / c.paper_rmse[0])
        assert c.ptpe[0] > c.rmse[0] > 0  # PTPE of a zero-mean-ish error exceeds its RMSE
    # 19 runs of the paper's protocol + the diagnosed controller's 2 + 2 (1-DoF) + 1 (2-DoF)
    assert len(small.runs) == 19 + 5
    # one detection per (scenario, knob)
    assert len(small.shifts) == 4 * 2


def test_compensation_with_shift_beats_compensation_only_on_bent_shapes(small):
    for scen in ("alpha=45", "alpha=90", sc.SCENARIO_2DOF):
        shift, only = small.cell("comp+shift", scen), small.cell("comp", scen)
        assert shift.rmse[0] < 0.7 * only.rmse[0], scen
        assert shift.ptpe[0] < only.ptpe[0], scen
        assert shift.improvement["comp"]["rmse"] == pytest.approx(
            (only.rmse[0] - shift.rmse[0]) / only.rmse[0] * 100)


def test_diagnosed_controller_beats_compensation_with_shift(small):
    # issue 5: the diagnosis is fitted on the 5 Compensation+Shift runs (leave one run out)
    (row,) = small.diagnoses
    assert row.catheter == "ice-a" and row.runs == 5
    # it must add the catheter's dominant effect (creep, calibration.DEFAULT_EFFECTS). It may add
    # one more: the model's own error in D (the paper's current-only identification reads the
    # edges on the 40 deg/s sweep, where the tendon's lag moves them out by ~0.9 deg, so every
    # offset carries -0.4 to -1.3 deg) shows up as a dead-zone shift, which is what that gap is
    true = {name for name, _ in row.true_effects}
    assert true == {e.name for e in DEFAULT_EFFECTS}
    names = {name for name, _ in row.effects}
    assert "creep" in names and len(names - true) <= 1
    # the diagnosis' own held-out RMSE: 0.45 of before while the dead zone had two forms; with
    # deadzone one-edge a candidate too, the fold that holds out the 2-DoF run picks it (the four
    # one-plane runs cannot tell it from centre) and the shift's held-out gain falls under the
    # 5 % bar (9.4 -> 4.3 %): creep alone, 0.50. What the controller makes of it on fresh trials,
    # asserted below at half of Compensation+Shift, did not change (1.64/1.63/5.64 deg, was
    # 1.76/1.52/5.64).
    assert row.rmse_after < 0.55 * row.rmse_before
    assert [e.name for e in small.augmented["ice-a"].effects] == [name for name, _ in row.effects]
    for scen in ("alpha=45", "alpha=90"):
        diag, shift = small.cell(sc.DIAGNOSED, scen), small.cell("comp+shift", scen)
        assert diag.rmse[0] < 0.5 * shift.rmse[0], scen
    # one trial has a single 2-DoF run: coupling shows only in it, so leaving that run out
    # leaves no evidence for it and the diagnosis rightly does not add it; the 2-DoF run still
    # gains from what the 1-DoF runs taught (the full demo, 3 trials, adds coupling)
    assert "coupling" not in {name for name, _ in row.effects}
    assert small.cell(sc.DIAGNOSED, sc.SCENARIO_2DOF).rmse[0] < small.cell("comp+shift", sc.SCENARIO_2DOF).rmse[0]
    # its runs have fresh noise: never the same seed as a Compensation+Shift run
    seeds = lambda ctrl: {r.meta["seed"] for r in small.runs if r.meta["controller"] == ctrl}  # noqa: E731
    assert seeds(sc.DIAGNOSED).isdisjoint(seeds("comp+shift"))


def test_protocol_without_diagnosis_runs_the_papers_three_controllers():
    res = ex.run_protocol(catheters=("ice-b",), trials=1, seed=0, scenarios=["alpha=45"], diagnose=False)
    assert {c.controller for c in res.cells} == set(sc.CONTROLLERS)
    assert res.diagnoses == () and res.beyond() == []
    # one run of comp+shift alone cannot be diagnosed (no run to hold out)
    with pytest.raises(DataError, match="at least two Compensation\\+Shift runs"):
        ex.run_protocol(catheters=("ice-b",), trials=1, scenarios=[sc.SCENARIO_2DOF])


def test_detected_shift_is_near_the_geometry_of_the_shape(small):
    cat = calibrated_catheter("ice-a")
    ratio = cat.geometry.beta_catheter_mm / cat.geometry.beta_knob_mm
    for row in small.shifts:
        shape = Shape.parse(row.shape)
        # paper eqs. 3-4 by hand: (180/pi) * beta_c * sum alpha_i[rad] cos/sin(theta_i) / beta_k
        cos_sin = math.cos if row.knob == 1 else math.sin
        expected = ratio * sum(s.alpha * cos_sin(math.radians(s.theta)) for s in shape.segments)
        assert row.true_offset == pytest.approx(expected, abs=1e-5)
        # the calibrated twin has unmodelled effects (rate lag biases the current's edges a little)
        assert abs(row.result.offset - expected) < 2.5, row.to_dict()
        # the edge itself is found close to where the twin has it: the true offset plus ice-a's
        # true d_pos / d_neg (calibration.py: knob 1 +-18.8, knob 2 +17.8 / -19.8); most of the
        # offset's error is the identified D's (offset = edge - D of the identified model)
        d_true = {(1, "pos"): 18.8, (1, "neg"): -18.8, (2, "pos"): 17.8, (2, "neg"): -19.8}
        assert row.true_edge == pytest.approx(expected + d_true[(row.knob, row.result.edge)], abs=1e-5)
        assert abs(row.edge_error) < 0.75, row.to_dict()
        assert row.result.travel <= sc.DETECT_MAX_TRAVEL


@pytest.mark.slow
def test_same_seed_same_bytes_other_seed_other_noise():
    a = ex.run_protocol(catheters=("ice-b",), trials=2, seed=7, scenarios=["alpha=45"])
    b = ex.run_protocol(catheters=("ice-b",), trials=2, seed=7, scenarios=["alpha=45"])
    c = ex.run_protocol(catheters=("ice-b",), trials=2, seed=8, scenarios=["alpha=45"])
    assert a.to_json() == b.to_json()
    assert a.to_json() != c.to_json()
    # the trials differ by their noise: a non-zero spread over the 2 knobs x 2 trials
    assert all(cell.rmse[1] is not None and cell.rmse[1] > 0 for cell in a.cells)


def test_paper_constants_are_consistent_with_the_papers_improvement_rates():
    # Kim & Mansi give the improvement rate (base - new) / base * 100 of Compensation+Shift;
    # recomputing it from the transcribed means checks the transcription. Table II's PTPE rate
    # against No Compensation (45.8) does not follow from its own means ((55.6-25.1)/55.6 = 54.9):
    # an inconsistency of the paper, left out.
    papers = {**sc.PAPER_TABLE_I, **sc.PAPER_TABLE_II}
    for scen, rates in sc.PAPER_IMPROVEMENT.items():
        for metric, (vs_none, vs_comp) in rates.items():
            new = papers[("comp+shift", scen)][metric][0]
            for base_ctrl, rate in (("none", vs_none), ("comp", vs_comp)):
                if scen == sc.SCENARIO_2DOF and metric == "ptpe" and base_ctrl == "none":
                    continue
                base = papers[(base_ctrl, scen)][metric][0]
                assert (base - new) / base * 100 == pytest.approx(rate, abs=0.7), (scen, metric, base_ctrl)


def test_bad_input_is_a_data_error(tmp_path):
    with pytest.raises(DataError, match="no such data directory"):
        ex.run_protocol(data_dir=tmp_path / "missing")
    with pytest.raises(DataError, match="missing from the data directory"):
        ex.run_protocol(data_dir=tmp_path)  # exists, but empty
    with pytest.raises(DataError, match="trials"):
        ex.run_protocol(trials=0)
    with pytest.raises(DataError, match="unknown scenario"):
        ex.run_protocol(scenarios=["alpha=30"])


def test_write_outputs(tmp_path, small):
    written = render.write_outputs(small, tmp_path / "out")
    names = sorted(p.name for p in written)
    assert names == ["fig6_periodic_1dof.png", "fig7_nonperiodic_2dof.png", "results.json", "tables.md"]
    data = json.loads((tmp_path / "out" / "results.json").read_text())
    assert data["format"] == "hyst-demo"
    # the paper's 8 + 3 cells and the diagnosed controller's 2 + 1
    assert len(data["table_I"]) == 8 + 2 and len(data["table_II"]) == 3 + 1
    assert (tmp_path / "out" / "fig6_periodic_1dof.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(DataError, match="not a directory"):
        render.write_outputs(small, tmp_path / "out" / "results.json")


def test_calibrated_catheters_have_physical_effects_only():
    names = {e.name for e in DEFAULT_EFFECTS}
    assert names <= {"creep", "friction", "rate", "coupling", "deadzone", "saturation", "latency"}
    assert "contact" not in names  # a wall is a safety case, not a default of the catheter
    for name in CALIBRATED_NAMES:
        cat = calibrated_catheter(name)
        assert {e.name for e in cat.default_effects} == names
        for kn in cat.knobs.values():
            # the paper: "the dead zone value is less than 20 deg" (section IV)
            assert kn.d_pos < 20 and kn.d_neg > -20
            # the tip moves only while a tendon is taut: dhat_pos = d_neg, dhat_neg = d_pos
            # when b_pos = b_neg (paper eq. D_hats with H_neg - H_pos = omega * B)
            assert kn.h_neg - kn.h_pos == pytest.approx(kn.omega * (kn.b_pos + kn.b_neg) / 2)


def _load_script():
    spec = importlib.util.spec_from_file_location("make_sample_data", ROOT / "scripts" / "make_sample_data.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_committed_sample_data_is_what_the_script_makes(tmp_path):
    assert SAMPLE.is_dir(), "sample_data/ is committed with the repository"
    _load_script().main(["--out", str(tmp_path / "sd"), "--seed", "0"])
    made = sorted(p.relative_to(tmp_path / "sd") for p in (tmp_path / "sd").rglob("*") if p.is_file())
    assert len(made) == 23
    for rel in made:
        assert (SAMPLE / rel).read_bytes() == (tmp_path / "sd" / rel).read_bytes(), rel
    total = sum(p.stat().st_size for p in SAMPLE.rglob("*") if p.is_file() and "real" not in p.parts)
    assert total < 5_000_000


@pytest.mark.slow
def test_full_demo_lands_within_30_percent_of_every_paper_cell():
    # Issue 3, Must-show 1: Tables I and II of the demo (sample_data, 2 catheters x 3 trials)
    # within 30 % of every cell of the paper's (Kim & Mansi, Tables I and II).
    res = ex.run_protocol(data_dir=SAMPLE, trials=3, seed=0)
    assert res.compared() == 22  # 8 Table I cells x 2 metrics + 3 Table II cells x 2
    assert res.misses() == []
    # Issue 5, Must-show 2: Compensation+Shift with the diagnosed model at most half the paper's
    # Compensation+Shift RMSE: 7.9 / 2 and 8.0 / 2 (Table I), 10.1 / 2 (Table II)
    targets = {s: t for s, _, t in res.beyond()}
    assert targets == pytest.approx({"alpha=45": 3.95, "alpha=90": 4.0, sc.SCENARIO_2DOF: 5.05})
    for s, target in targets.items():
        assert res.cell(sc.DIAGNOSED, s).rmse[0] <= target, s
    assert res.beyond_misses() == []
    # and the recordings read from the files are exactly what the twin records
    sim = ex.run_protocol(data_dir=None, trials=3, seed=0)
    strip = lambda d: {k: v for k, v in d.items() if k != "config"}  # noqa: E731
    assert strip(res.to_dict()) == strip(sim.to_dict())
