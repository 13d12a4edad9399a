"""The live path on plants our code did not make (issue 10, Must-show 4).

`hyst sim-robot --zoo SEED:FAMILY:OFFSET` serves an independent plant of :mod:`hystcli.zoo.plants`
(written from the physics by an author who never read shift.py) behind a real pseudo-terminal;
`hyst detect-shift --port` searches it with the model a user would have (identified on that
plant's straight sweep, or its true loop where the sweep cannot identify it, with the current
levels read on the sweep). The decisions are the ones the replays go through (one search code),
so the same rule holds: an offset returned is right within 0.5 deg of the plant's true shift, or
the search refuses with the reason and the knob returned; never a wrong offset with exit 0.
"""
from __future__ import annotations

import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from hystcli.cli import app
from hystcli.io import load_model, save_model
from hystcli.zoo import plants
from simrobot import TIMEOUT, sim_robot

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from zoo import straight_model  # noqa: E402

runner = CliRunner()

# replay cases of the zoo, families varied; the test only asserts what the rule above says and
# how many of them succeed (measured: 10, 11 succeed within 0.1 deg; 2, 14, 23, 26 are refused:
# their far edge lies beyond the travel limit, or the kink is not two straight lines)
SEEDS = (2, 10, 11, 14, 23, 26)


def _search_live(seed: int, tmp_path: Path) -> tuple[float | None, float]:
    """``hyst detect-shift --port`` against ``hyst sim-robot --zoo`` for zoo replay plant ``seed``
    with the model a user would have: (the offset returned, or None on a refusal, which must be
    exit 1 with one ``Error:`` line, no output and the knob returned; the plant's true shift)."""
    case = plants.replay_case(seed)
    model, _ = straight_model(case)
    model_path = tmp_path / "model.json"
    save_model(model_path, model)
    out = tmp_path / "shifted.json"
    with sim_robot("--zoo", f"{seed}:{case.family}:{case.offset!r}") as port:
        res = runner.invoke(app, ["detect-shift", "--model", str(model_path), "--port", port, "-o", str(out),
                                  "--timeout", TIMEOUT, "-q"])
    if res.exit_code == 0:
        return load_model(out).knob(1).offset, case.offset
    assert res.exit_code == 1 and not out.exists()
    line = [ln for ln in res.stderr.splitlines() if ln.startswith("Error:")]
    assert len(line) == 1 and "knob returned to 0 deg" in line[0], res.stderr
    return None, case.offset


@pytest.mark.parametrize("seed", SEEDS)
def test_live_search_on_an_independent_plant_is_right_or_refuses(seed, tmp_path):
    offset, truth = _search_live(seed, tmp_path)
    if offset is not None:
        assert abs(offset - truth) <= 0.5, (seed, offset, truth)
        if seed in (10, 11):
            assert abs(offset - truth) <= 0.2
    else:
        assert seed not in (10, 11)


@pytest.mark.parametrize("seed", (1307, 1411, 1260, 4800006))
def test_live_design_plants_once_read_wrong_are_right_or_refused(seed, tmp_path):
    # found in stop 41 by searching design plants 0-1999 live (bench/zoo.py --only live-direct):
    # 1307 (a load-following current) rests with the positive tendon taut on its backlash
    # plateau; the robot's reading at rest turned the search before its first step, and that
    # segment was then not "from the start", so the rule that a flat off the no-load band on the
    # side of the tendon behind is that tendon still held did not apply: the end of the held
    # plateau was taken for the negative edge, 2.8 deg off. 1411 (spiky, pretensioned, 56 mA of
    # Coulomb friction): at rest the no-load band holds the motor's whole static friction, and
    # readings climbing at 3.7 mA/deg from the start passed for a dead zone's flat by their level;
    # a stiction step at their end was kept as an edge at the start, 15.6 deg off. 1260 and
    # 4800006 (coulomb-viscous, the bench's true-loop stand-in; 4800006 from the held-out range,
    # looked at after its figures): wide backlash plateaus left the tip's dead-zone flats too
    # short for the motor's cogging ripple to be read there, and a trough of it on a loaded line
    # was taken for the edge, 4.8 and 11.4 deg off; the ripple is now read on the knob's dead
    # zone. All exit 0 before; the rule asserted is the issue's: right within 0.5 deg, or refused
    offset, truth = _search_live(seed, tmp_path)
    assert offset is None or abs(offset - truth) <= 0.5


@pytest.mark.parametrize("seed", (1307, 4700229))
def test_a_taut_start_at_rest_is_searched_the_same_whichever_way_the_search_was_pointed(seed):
    # a robot whose reading at rest shows a tendon taut: the search heads into the dead zone from
    # it, whichever direction it was given; before stop 41 the segment it then walked counted as
    # "from the start" only when that direction already pointed there, and as the one "a taut
    # start turned into" only when it did not, so the same plant gave two answers (1307: 2.8 deg
    # off one way, refused the other; 4700229: right one way, refused the other). Searched here
    # through the host's real driver and probe, the emulator's bytes passed in memory
    # (bench/zoo.py's EmulatorPort) instead of through a pty
    from zoo import EmulatorPort

    from hystcli import device, shift
    from hystcli.emulator import DeviceEmulator
    from hystcli.errors import ShiftDetectionError

    case = plants.replay_case(seed)
    model, _ = straight_model(case)
    answers = []
    for direction in (1, -1):
        plant, _ = plants.live_plant(seed, case.family, offset=case.offset)
        probe = device.DeviceProbe(device.Device(EmulatorPort(DeviceEmulator(plant)), timeout=float(TIMEOUT)),
                                   1, current_ceiling=2000.0, speed=5.0)
        try:
            r = shift.detect_shift(model, probe, 1, direction=direction)
            answers.append((r.edge, round(r.offset, 9)))
        except ShiftDetectionError as exc:
            answers.append(("refused", str(exc)))
        assert probe.position() == pytest.approx(0.0)     # the knob back where it began
    assert answers[0] == answers[1]
    assert answers[0][0] == "refused" or abs(answers[0][1] - case.offset) <= 0.5
