"""`hyst rotate-shift` against shifts detected live on the twin after the same body rotation
(issue 4, Must-show 4).

The shaft keeps one shape ('alpha=60,theta=45': both knob offsets non-zero, 12.94 deg each by
paper eqs. 1-4 on the calibrated ice-a: 1.83 / 6.0 x 60 x cos 45). `hyst detect-shift --port` on
`hyst sim-robot --rotation 0` gives the shifted model; `hyst rotate-shift --degrees D` turns it
into a prediction for the body rotated by D, which must agree with `detect-shift` run on `hyst
sim-robot --rotation D`. Neither side is the code under test's own reference: both are measured
on the twin through the pty.
"""
from __future__ import annotations

import math

import pytest

from hystcli.cli import app
from hystcli.io import load_model
from hystcli.core.params import Shape
from test_live_detect import CAT, detect, model_path, runner, start_sim_robot, stop  # noqa: F401

SHAPE = "alpha=60,theta=45"

pytestmark = pytest.mark.slow   # each detection drives both knobs of a robot in another process


def _detect_at(model_path, folder, rotation: float):
    out = folder / f"shift_{rotation:g}.json"
    proc, path = start_sim_robot("--shape", SHAPE, "--rotation", f"{rotation:g}", "--seed", "4")
    try:
        # the default travel limit (the sweep's 40 deg reach plus half the dead zone) reaches the
        # farthest shifted edge, 18.8 + 17.7 = 36.5 deg at a rotation of 30 deg
        res = detect(model_path, path, out)
    finally:
        stop(proc)
    assert res.exit_code == 0, res.output
    return out


@pytest.fixture(scope="module")
def shifted_at_zero(model_path, tmp_path_factory):  # noqa: F811 - the fixture of test_live_detect
    return _detect_at(model_path, tmp_path_factory.mktemp("rot"), 0.0)


def test_shape_has_both_offsets():
    # by hand: theta=45 puts the bend halfway between the two tendon planes: o1 = o2 = o/sqrt(2)
    o = CAT.true_offsets(Shape.parse(SHAPE))
    assert o[1] > 5 and o[2] > 5 and math.isclose(o[1], o[2], rel_tol=1e-9)


@pytest.mark.parametrize("delta", [30.0, 90.0, 180.0])
def test_rotate_shift_matches_detection_after_rotation(model_path, shifted_at_zero, tmp_path, delta):  # noqa: F811
    rotated = tmp_path / "rotated.json"
    res = runner.invoke(app, ["rotate-shift", "--model", str(shifted_at_zero), "--degrees",
                              f"{delta:g}", "-o", str(rotated), "--quiet"])
    assert res.exit_code == 0, res.output
    predicted = load_model(rotated)
    measured = load_model(_detect_at(model_path, tmp_path, delta))
    for k in (1, 2):
        assert abs(predicted.knob(k).offset - measured.knob(k).offset) <= 0.7, (
            delta, k, predicted.knob(k).offset, measured.knob(k).offset)
    # and the prediction is the rotation of the true vector (sanity of the twin itself):
    true = CAT.true_offsets(Shape.parse(SHAPE), rotation=delta)
    for k in (1, 2):
        assert abs(predicted.knob(k).offset - true[k]) <= 1.0
