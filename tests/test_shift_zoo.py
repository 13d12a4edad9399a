"""Algorithm 1 (hystcli.shift) on replays of the independent plant zoo (issue 10): design seeds
whose replays the search once read wrong, each with the model a user would have (identified on
the plant's straight sweep, ``bench/zoo.py``'s ``straight_model``). The rule asserted is the
issue's: an offset returned is within 0.5 deg of the plant's true shift, or the search refuses.
"""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

from hystcli import shift
from hystcli.errors import ShiftDetectionError
from hystcli.io import parse_run
from hystcli.zoo import plants

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from zoo import straight_model  # noqa: E402


def _detect(seed: int):
    """The zoo replay ``seed`` and Algorithm 1 on it with the straight model a user would have."""
    case = plants.replay_case(seed)
    model, _ = straight_model(case)
    rep = parse_run(case.replay.csv_text(), source=f"replay-{seed}")
    return case, lambda: shift.detect_shift(model, shift.ReplayProbe(rep, 1), 1)


def test_a_taut_start_whose_current_runs_back_into_the_no_load_band_is_no_edge():
    # design seed 1304 (a wall plant, load-following current): the knob rests with the positive
    # tendon taut; moving down, its current eases off in one line from 208 mA (off the sweep's
    # no-load band, 64 +- 96 mA) into the band, and the tip then leaves its backlash plateau and
    # the tendon unloads steeply through the sweep's no-load level toward the true one (-143 mA).
    # The kink at -20.2 deg where the unloading steepens was taken for the negative tendon's
    # edge: an offset of +11.43 deg where the true shift is -0.75. The negative tendon is taken
    # up at -32.35 deg, out of the dead zone's flat at the true no-load level.
    case, detect = _detect(1304)
    try:
        r = detect()
    except ShiftDetectionError:
        pytest.fail("the edge at -32.35 deg is readable (the replay goes to -66 deg)")
    assert r.edge == "neg" and r.start_outside
    assert r.offset == pytest.approx(case.offset, abs=0.5)


def test_a_held_load_whose_unloading_runs_through_a_misread_no_load_level_is_no_edge():
    # design seed 3533 (a tip-load plant; the sweep could not be identified, so the model is the
    # true loop with the current levels read on the sweep, which put the no-load level moving
    # down at 356 mA and moving up at 84, the true one): the knob rests with the positive tendon
    # taut, its load held on the backlash plateau (435 mA) to -18.3 deg; it then unloads at
    # 56 mA/deg in one line through 356 mA toward 84. The rise was taken for the negative
    # tendon's edge: an offset of -2.88 deg where the true shift is -15.73. The true edge,
    # -31.5 deg, lies at the travel limit (31.1 deg): a refusal is the right answer.
    case, detect = _detect(3533)
    try:
        r = detect()
    except ShiftDetectionError:
        return
    assert r.offset == pytest.approx(case.offset, abs=0.5)
