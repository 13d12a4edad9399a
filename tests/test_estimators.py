"""The estimator objects (hystcli.estimators): settings as constructor parameters, read from the one
registry of defaults, and the same results as the library functions they hold settings for; and
the results' ``.plot()`` figures."""
from __future__ import annotations

import inspect
from dataclasses import fields
from pathlib import Path

import pytest

import hystcli
from hystcli.errors import HystError
from hystcli.settings import DEFAULT, Settings

ROOT = Path(__file__).resolve().parents[1]
SWEEP = ROOT / "sample_data" / "ice-a" / "sweep_knob1.csv"
REPLAY = ROOT / "sample_data" / "ice-a" / "replay_alpha90_knob1.csv"
ESTIMATORS = (hystcli.Identifier, hystcli.ShiftDetector, hystcli.Diagnoser)


@pytest.fixture(scope="module")
def sweep():
    return hystcli.read_run(SWEEP)


@pytest.mark.parametrize("cls", ESTIMATORS)
def test_get_params_are_exactly_the_constructor_parameters_and_round_trip(cls):
    est = cls()
    params = est.get_params()
    assert list(params) == list(inspect.signature(cls).parameters)
    assert cls(**params) == est
    # set_params returns the estimator, changed in place; get_params gives back what was set
    name = next(n for n in params if n in ("level", "max_effects"))
    value = 0.9 if name == "level" else 1
    assert est.set_params(**{name: value}) is est
    assert est.get_params() == {**params, name: value}
    assert cls(**est.get_params()) == est and est != cls()


@pytest.mark.parametrize("cls", [hystcli.Identifier, hystcli.ShiftDetector])
def test_the_defaults_are_the_settings_registry_s(cls):
    # one registry: every Settings field is a parameter, with the default Settings gives it
    params = cls().get_params()
    assert {f.name: params[f.name] for f in fields(Settings)} == DEFAULT.get_params()
    assert cls().settings == DEFAULT
    assert cls(level=0.9, loss="huber").settings == Settings(level=0.9, loss="huber")


def test_the_function_options_keep_the_function_s_defaults():
    for cls, fn in ((hystcli.Identifier, hystcli.identify), (hystcli.ShiftDetector, hystcli.detect_shift),
                    (hystcli.Diagnoser, hystcli.diagnose)):
        own = inspect.signature(fn).parameters
        settings = {f.name for f in fields(Settings)}
        for name, p in inspect.signature(cls).parameters.items():
            # a function's shortcut for a Settings field (detect_shift's false_alarm=None: "the
            # settings' value") is that field, with the registry's default
            if name in own and name not in settings:
                assert p.default == own[name].default, (cls, name)
            elif name in settings:
                assert p.default == getattr(DEFAULT, name), (cls, name)


@pytest.mark.parametrize("cls", ESTIMATORS)
def test_an_unknown_parameter_is_a_type_error_naming_the_known_ones(cls):
    with pytest.raises(TypeError, match=r"has no parameter 'levle'; its parameters are "):
        cls(levle=0.9)
    est = cls()
    with pytest.raises(TypeError, match="levle"):
        est.set_params(levle=0.9)
    assert est == cls()


def test_a_bad_value_is_refused_at_once_and_leaves_the_estimator_as_it_was():
    est = hystcli.Identifier(level=0.9)
    with pytest.raises(HystError, match="level must be in"):
        est.set_params(level=1.5)
    assert est.get_params()["level"] == 0.9
    with pytest.raises(HystError, match="loss must be one of"):
        hystcli.ShiftDetector(loss="l3")


def test_the_repr_shows_what_differs_from_the_defaults():
    assert repr(hystcli.Identifier()) == "Identifier()"
    assert repr(hystcli.Identifier(level=0.9, use_tip=False)) == "Identifier(level=0.9, use_tip=False)"


def test_identifier_fit_is_identify_with_those_settings(sweep):
    got = hystcli.Identifier(level=0.9).fit(sweep)
    want = hystcli.identify(sweep, settings=Settings(level=0.9))
    assert got.intervals == want.intervals
    assert {k: got.model.knob(k).params() for k in got.fits} == {k: want.model.knob(k).params() for k in want.fits}
    assert got.summary() == want.summary()
    # the level reached the fit: the default level gives other intervals
    default = hystcli.identify(sweep)
    assert got.intervals != default.intervals


def test_shift_detector_detect_is_detect_shift_with_those_settings(sweep):
    model = hystcli.identify(sweep).model
    replay = hystcli.read_run(REPLAY)
    got = hystcli.ShiftDetector(step=0.25).detect(model, replay, knob=1)
    want = hystcli.detect_shift(model, replay, knob=1, step=0.25)
    assert (got.offset, got.offset_lo, got.offset_hi) == (want.offset, want.offset_lo, want.offset_hi)


def test_the_estimators_are_lazy_top_level_names():
    for name in ("Identifier", "ShiftDetector", "Diagnoser"):
        assert name in hystcli.__all__ and getattr(hystcli, name).__module__ == "hystcli.estimators"


def test_identification_plot_is_a_figure_with_a_row_per_knob(sweep, tmp_path):
    from matplotlib.figure import Figure

    ident = hystcli.Identifier().fit(sweep)
    fig = ident.plot(sweep)
    assert isinstance(fig, Figure) and len(fig.axes) == 2 * len(ident.fits)
    assert fig.axes[0].get_xlabel() == "knob angle q1 (deg)"
    fig.savefig(tmp_path / "fit.png")
    assert (tmp_path / "fit.png").stat().st_size > 0


def test_the_identify_plot_file_is_the_figure_s_png(sweep, tmp_path):
    # `hyst identify --plot` writes the bytes of the very figure .plot() returns
    from hystcli.identification import plot_identification
    from hystcli.report.figures import figure_bytes

    ident = hystcli.identify(sweep)
    plot_identification(sweep, ident, tmp_path / "fit.png")
    assert (tmp_path / "fit.png").read_bytes() == figure_bytes(ident.plot(sweep), "png")


def test_evaluation_plot_is_the_figure_hyst_evaluate_saves(sweep):
    from matplotlib.figure import Figure

    from hystcli.report.metrics import evaluation_figure
    from hystcli.report.figures import figure_bytes

    model = hystcli.identify(sweep).model.with_offsets({1: 3.0})
    reference = hystcli.read_run(ROOT / "sample_data" / "reference_periodic.csv")
    runs = [hystcli.predict(model, hystcli.compensate(model, reference, ignore_shift=ignore).run)
            for ignore in (True, False)]
    fig = hystcli.evaluate(runs).plot(runs)
    assert isinstance(fig, Figure) and len(fig.axes) == 2  # one (motion, shape, knob) column, two rows
    assert evaluation_figure(runs, "svg") == figure_bytes(fig, "svg")


def test_the_shift_plot_is_the_figure_detect_shift_saves(sweep, tmp_path):
    # ShiftResult.plot() is the one panel `hyst detect-shift --plot` writes for that knob
    from matplotlib.figure import Figure

    from hystcli.report.figures import figure_bytes
    from hystcli.shift import plot_shift

    model = hystcli.identify(sweep).model
    result = hystcli.detect_shift(model, REPLAY, knob=1)
    fig = result.plot(model)
    assert isinstance(fig, Figure) and len(fig.axes) == 1
    assert "offset" in fig.axes[0].get_title() and fig.axes[0].get_xlabel() == "knob 1 angle (deg)"
    plot_shift([result], tmp_path / "shift.png", model=model)
    assert (tmp_path / "shift.png").read_bytes() == figure_bytes(fig, "png")
