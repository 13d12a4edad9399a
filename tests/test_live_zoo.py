"""The live path on plants our code did not make.

An independent plant of :mod:`plants.zoo.plants` (written from the physics by an author who
never read hystcli.shift) is served by the serial emulator on a real pseudo-terminal; the host's
driver and probe search it with the model a user would have: ``identify`` from the motor current
of that plant's straight sweep. The decisions are the ones the replays go through (one search
code), so the issue's rule holds live too: an offset returned is within 0.5 deg of the plant's
true shift, or the search refuses with the reason; the knob ends where it began either way.
"""
from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from hystcli.cli import app
from hystcli.device import open_probe
from hystcli.device.emulator import serve
from hystcli.errors import ShiftDetectionError
from hystcli.identification import identify
from hystcli.core.run import Run
from hystcli.io import load_model, parse_run, save_model
from hystcli.shift import detect_shift
from plants.zoo import plants
from simrobot import TIMEOUT, sim_robot

LIVE = Path(__file__).resolve().parents[1] / "bench" / "plants" / "live.py"
"""The file `hyst sim-robot --plant` loads the zoo's live plant from (the plants are not installed)."""

runner = CliRunner()


def sweep_model(case):
    """``identify`` on the plant's straight sweep, its motor current alone."""
    run = parse_run(case.straight_sweep.csv_text(), source="sweep")
    run = Run({k: v for k, v in run.columns.items() if not k.startswith("y")}, run.meta, run.source)
    return identify(run, use_tip=False).model


def search_live(seed: int, direction: int):
    """The search on the live plant of zoo replay ``seed``: ``(offset or None, true offset)``."""
    case = plants.replay_case(seed)
    model = sweep_model(case)
    plant = plants.live_plant(seed, case.family, offset=case.offset)
    server = serve(plant[0] if isinstance(plant, tuple) else plant)
    try:
        probe = open_probe(server.path, knob=1, timeout=float(TIMEOUT))
        try:
            try:
                offset = detect_shift(model, probe, 1, direction=direction).offset
            except ShiftDetectionError as exc:
                # refused mid-search (the knob went back) or before the knob moved at all
                assert "returned to 0 deg" in str(exc) or "no offset can be taken" in str(exc), str(exc)
                offset = None
            assert abs(probe.device.state(1).angle) < 1e-3      # the knob back where it began
        finally:
            probe.device.close()
    finally:
        server.shutdown()
    return offset, case.offset


# Zoo plants of several families whose search ends right (measured: within 0.2 deg both ways),
# and plants whose edge no search can place (a sweep whose current fixes neither take-up, a
# stiffening cable whose kink is too rounded to place within 0.5 deg): refused both ways.
LIVE_RIGHT = [pytest.param(11, id="tip-load"), pytest.param(1260, id="coulomb-viscous"),
              pytest.param(563, id="tip-load-far-negative"), pytest.param(831, id="tip-load-positive"),
              pytest.param(3533, id="tip-load-wide-shift"), pytest.param(23, id="stretch-shift-beyond-the-reach")]
LIVE_REFUSED = [pytest.param(26, id="stiffening-no-sweep-edge"), pytest.param(2, id="stiffening-rounded-kink")]


@pytest.mark.parametrize("seed", LIVE_RIGHT)
@pytest.mark.parametrize("direction", [1, -1])
def test_live_search_on_an_independent_plant_is_right(seed, direction):
    offset, truth = search_live(seed, direction)
    assert offset is not None and abs(offset - truth) <= 0.5, (seed, direction, offset, truth)


@pytest.mark.parametrize("seed", LIVE_REFUSED)
@pytest.mark.parametrize("direction", [1, -1])
def test_live_search_refuses_an_edge_it_cannot_place(seed, direction):
    offset, truth = search_live(seed, direction)
    assert offset is None, (seed, direction, offset, truth)


@pytest.mark.slow
def test_detect_shift_on_sim_robot_serving_an_independent_plant(tmp_path):
    # the command line against `hyst sim-robot --plant bench/plants/live.py` in its own process, as a user runs it, on
    # the tip-load plant the search reads right both ways
    seed = LIVE_RIGHT[0].values[0]
    case = plants.replay_case(seed)
    save_model(tmp_path / "model.json", sweep_model(case))
    out = tmp_path / "shifted.json"
    with sim_robot("--plant", f"{LIVE}:{seed}:{case.family}:{case.offset!r}") as port:
        res = runner.invoke(app, ["detect-shift", "--model", str(tmp_path / "model.json"), "--port", port,
                                  "-o", str(out), "--timeout", TIMEOUT, "-q"])
    assert res.exit_code == 0, res.output
    assert abs(load_model(out).knob(1).offset - case.offset) <= 0.5


def test_a_take_up_seen_on_the_first_stretch_only_is_no_reference():
    # a zoo plant whose straight sweep's current shows the negative take-up on its first stretch
    # only (from a start state the record cannot tell) and the positive one nowhere: the model
    # leaves both edges open, and the live search refuses before the knob moves
    case = plants.replay_case(14)
    ident = sweep_model(case).identification[1]
    assert {"d_pos", "d_neg"} <= set(ident.unfixed)
    for direction in (1, -1):
        assert search_live(14, direction)[0] is None
