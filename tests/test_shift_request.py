"""The checks of a shift detection, called as a library (no command line): each refusal is the
typed error `hyst detect-shift` shows, with the same words (tests/test_cli_detect_shift.py and
tests/test_live_detect.py pin the command's side), and it comes before anything moves."""
from __future__ import annotations

import contextlib
import math
import pickle
from pathlib import Path

import numpy as np
import pytest

import hystcli
from hystcli.device import LiveProbes
from hystcli.errors import DataError, ModelError, ParameterError
from hystcli.identification import identify
from hystcli.core.run import Run
from hystcli.io import read_run
from hystcli.core.model import Model
from hystcli.core.params import KnobModel
from hystcli.shift import ShiftRequest, apply_shift, detect_shift, run_detect_shift, select_knobs

SAMPLES = Path(__file__).resolve().parents[1] / "sample_data" / "ice-a"
KNOB = KnobModel(d_pos=9.0, d_neg=-5.0, b_pos=3.0, b_neg=3.0, omega=1.45, h_pos=-2.0, h_neg=2.0)
ONE, TWO = Model({1: KNOB}), Model({1: KNOB, 2: KNOB})


@pytest.fixture(scope="module")
def sample_model() -> Model:
    """The straight-shaft model of the sample sweep, with its reading of the current."""
    return identify(read_run(SAMPLES / "sweep_knob1.csv"), use_tip=False).model


class Source:
    """A live source that records whether it was opened and closed, and yields no probes."""

    def __init__(self) -> None:
        self.opened: list[list[int]] = []
        self.closed = 0

    @contextlib.contextmanager
    def open(self, knobs):
        self.opened.append(list(knobs))
        try:
            yield {}
        finally:
            self.closed += 1


# the words of `hyst detect-shift`'s usage errors (tests/test_cli_detect_shift.py, test_live_detect.py)
REQUESTS = [
    ({"step": -1.0}, "step", "must be a positive number, got -1.0"),
    ({"step": math.nan}, "step", "must be a positive number, got nan"),
    ({"max_travel": 0.0}, "max_travel", "must be a positive number, got 0.0"),
    ({"max_steps": 0}, "max_steps", "must be at least 1, got 0"),
    ({"eps_upper": -3.0}, "eps_upper", "must be a positive number, got -3.0"),
    ({"false_alarm": 0.7}, "false_alarm", "must be in (0, 0.5), got 0.7"),
    ({"false_alarm": 0.0}, "false_alarm", "must be in (0, 0.5), got 0.0"),
    ({"direction": 2}, "direction", "must be +1 or -1, got 2"),
]


@pytest.mark.parametrize("kw, parameter, reason", REQUESTS, ids=[r[1] + str(i) for i, r in enumerate(REQUESTS)])
def test_a_request_refuses_each_setting_out_of_its_domain(kw, parameter, reason):
    with pytest.raises(ParameterError) as info:
        ShiftRequest(**kw)
    assert (info.value.parameter, info.value.reason) == (parameter, reason)
    assert str(info.value) == f"{parameter}: {reason}"


def test_a_request_gives_the_search_its_options():
    options = ShiftRequest(step=0.25, max_steps=9, false_alarm=1e-4, direction=-1).options()
    assert options["settings"].false_alarm == 1e-4
    assert (options["step"], options["max_steps"], options["direction"]) == (0.25, 9, -1)
    assert ShiftRequest().options()["settings"] == hystcli.Settings()  # no false_alarm: the settings' own


LIVE = [
    ({"current_ceiling": -2.0}, "current_ceiling", "must be a positive number, got -2.0"),
    ({"speed": math.inf}, "speed", "must be a positive number, got inf"),
    ({"timeout": 0.0}, "timeout", "must be a positive number, got 0.0"),
    ({"dwell": -1.0}, "dwell", "must be between 0 and 10 s, got -1.0"),
    ({"mean": 11.0}, "mean", "must be between 0 and 10 s, got 11.0"),
    ({"dwell": math.nan}, "dwell", "must be between 0 and 10 s, got nan"),
    ({"baud": -9600}, "baud", "must be a positive number, got -9600"),
]


@pytest.mark.parametrize("kw, parameter, reason", LIVE, ids=[r[1] + str(i) for i, r in enumerate(LIVE)])
def test_live_settings_are_refused_before_a_port_is_opened(kw, parameter, reason):
    # the port does not exist: a check that opened it would fail with a link error instead
    with pytest.raises(ParameterError) as info:
        LiveProbes("/dev/null-no-port", **kw)
    assert (info.value.parameter, info.value.reason) == (parameter, reason)


def test_knobs_default_to_what_the_source_has_and_must_be_the_models():
    run = Run({"t": np.arange(3.0), "q2": np.zeros(3), "c2": np.zeros(3)})
    assert select_knobs(TWO) == [1, 2]                          # live: every knob of the model
    assert select_knobs(TWO, replay=run) == [2]                 # a replay: the knobs it records
    assert select_knobs(TWO, [2, 1]) == [2, 1]                  # asked for: in that order
    with pytest.raises(ModelError, match=r"^the model has no knob 2 \(it has knobs 1\)$"):
        select_knobs(ONE, [2])
    with pytest.raises(DataError, match=r"^r\.csv: the replay records none of the model's knobs \(no column q1\)$"):
        select_knobs(ONE, replay=run, name="r.csv")
    with pytest.raises(DataError, match=r"^the replay records none"):
        select_knobs(ONE, replay=run)


@pytest.mark.parametrize("kw, parameter", [({}, "replay"), ({"replay": "x.csv", "live": Source()}, "replay"),
                                           ({"live": Source(), "request": ShiftRequest(), "step": 1.0}, "request"),
                                           ({"live": Source(), "step": 0.0}, "step"),
                                           ({"live": Source(), "request": ShiftRequest(), "knobs": [3]}, None)])
def test_run_refuses_before_the_source_is_opened(kw, parameter):
    source = kw.get("live")
    with pytest.raises(ModelError if parameter is None else ParameterError) as info:
        run_detect_shift(TWO, **kw)
    if parameter is not None:
        assert info.value.parameter == parameter
    assert source is None or source.opened == []


def test_run_on_a_replay_file_is_detect_shift_per_knob(sample_model):
    path = SAMPLES / "replay_alpha45_knob1.csv"
    seen = []
    results = run_detect_shift(sample_model, path, step=0.5, started=seen.append)
    assert list(results) == [1] and seen == [1]
    alone = detect_shift(sample_model, read_run(path), 1)
    assert results[1].offset == alone.offset and results[1].offset_lo == alone.offset_lo
    # the same search reached through the top-level name, as a script writes it: a file, no knob
    assert hystcli.detect_shift(sample_model, str(path)).offset == alone.offset


def test_run_closes_a_live_source_when_the_search_fails():
    source = Source()
    with pytest.raises(KeyError):  # the source gave no probe for the knob
        run_detect_shift(ONE, live=source)
    assert source.opened == [[1]] and source.closed == 1


def test_detect_shift_for_a_script(sample_model):
    with pytest.raises(ParameterError, match=r"^false_alarm: must be in \(0, 0\.5\), got 0\.9$"):
        hystcli.detect_shift(sample_model, SAMPLES / "replay_alpha45_knob1.csv", false_alarm=0.9)
    two = Run({"t": np.arange(3.0), "q1": np.zeros(3), "c1": np.zeros(3), "q2": np.zeros(3), "c2": np.zeros(3)})
    with pytest.raises(ParameterError, match=r"^knob: the replay records knobs 1, 2: say which to search$"):
        detect_shift(TWO, two)


def test_a_shifted_model_says_what_shifted_it(sample_model):
    r = run_detect_shift(sample_model, SAMPLES / "replay_alpha45_knob1.csv")
    shifted = apply_shift(sample_model, r, source="replay.csv", sha256="ab12")
    assert shifted.knob(1).offset == r[1].offset
    assert (shifted.meta["shift_source"], shifted.meta["shift_sha256"]) == ("replay.csv", "ab12")
    assert "shift_source" not in apply_shift(sample_model, r).meta


def test_a_parameter_error_survives_pickling():
    # a batch worker's error reaches the client pickled
    err = pickle.loads(pickle.dumps(ParameterError("step", "must be a positive number, got -1.0")))
    assert (err.parameter, err.reason, str(err)) == ("step", "must be a positive number, got -1.0",
                                                     "step: must be a positive number, got -1.0")


def test_the_command_line_shows_a_parameter_error_against_its_option():
    import typer

    from hystcli.cli.app import parameter_errors

    with pytest.raises(typer.BadParameter) as info:
        with parameter_errors({"mean": "--mean-window"}):
            LiveProbes("x", mean=11.0)
    assert info.value.param_hint == "--mean-window" and info.value.message == "must be between 0 and 10 s, got 11.0"
    with pytest.raises(ParameterError):  # no option of the command's: stays a hyst error (exit 1)
        with parameter_errors({}):
            ShiftRequest(step=0.0)
