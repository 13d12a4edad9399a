"""One figure style (hystcli.report.style) for every figure hyst draws, and one writer of figure
files (hystcli.report.figures.save_figure): same bytes for the same figure, whole files only."""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from matplotlib.colors import to_rgba
from matplotlib.figure import Figure

import hystcli
from hystcli.errors import DataError
from hystcli.report import style
from hystcli.report.figures import figure_bytes, save_figure

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = ROOT / "sample_data" / "ice-a"


@pytest.fixture(scope="module")
def fitted():
    sweep = hystcli.read_run(SAMPLES / "sweep_knob1.csv")
    return sweep, hystcli.identify(sweep)


def _same_colour(a, b) -> bool:
    return to_rgba(a)[:3] == to_rgba(b)[:3]


def _lines_of(fig: Figure, role: str) -> list:
    return [ln for ax in fig.axes for ln in ax.get_lines() if _same_colour(ln.get_color(), style.COLOURS[role])]


def _check_frame(fig: Figure, rows: int, cols: int) -> None:
    """Size per panel, dpi, grid and fonts are the style's."""
    assert isinstance(fig, Figure)
    assert fig.dpi == style.DPI
    w, h = style.PANEL_SIZE
    assert tuple(fig.get_size_inches()) == pytest.approx((w * cols, h * rows))
    ax = fig.axes[0]
    assert ax.xaxis.label.get_fontsize() == style.LABEL_SIZE
    assert ax.xaxis.get_major_ticks()[0].label1.get_fontsize() == style.TICK_SIZE
    assert all(g.get_visible() for g in ax.get_xgridlines())
    titled = [a for a in fig.axes if a.get_title()]
    assert titled and all(a.title.get_fontsize() == style.TITLE_SIZE for a in titled)
    legends = [a.get_legend() for a in fig.axes if a.get_legend() is not None] + list(fig.legends)
    assert legends and all(t.get_fontsize() == style.LEGEND_SIZE for lg in legends for t in lg.get_texts())


def test_the_identification_figure_is_in_the_style(fitted):
    sweep, ident = fitted
    fig = ident.plot(sweep)
    _check_frame(fig, rows=len(ident.fits), cols=2)
    ax = fig.axes[0]
    measured, model = ax.get_lines()[:2]
    assert _same_colour(measured.get_color(), style.COLOURS["measured"])
    assert _same_colour(model.get_color(), style.COLOURS["model"])
    assert model.get_linewidth() == style.LINE_WIDTH
    assert _lines_of(fig, "edge") and all(ln.get_linestyle() == "--" for ln in _lines_of(fig, "edge"))


def test_the_shift_figure_is_in_the_style(fitted):
    _, ident = fitted
    result = hystcli.detect_shift(ident.model, hystcli.read_run(SAMPLES / "replay_alpha90_knob1.csv"), knob=1)
    fig = result.plot(ident.model)
    _check_frame(fig, rows=1, cols=1)
    ax = fig.axes[0]
    steps = [ln for ln in ax.get_lines() if ln.get_label() == "search steps"]
    assert steps and _same_colour(steps[0].get_color(), style.COLOURS["measured"])
    found = [ln for ln in ax.get_lines() if ln.get_label().startswith("edge ")]
    assert found and _same_colour(found[0].get_color(), style.COLOURS["shifted"])
    zone = [p for p in ax.patches if p.get_label().startswith("new dead zone")]
    assert zone and _same_colour(zone[0].get_facecolor(), style.COLOURS["shifted"])
    assert zone[0].get_alpha() == style.BAND_ALPHA


def test_the_evaluation_figure_is_in_the_style(fitted):
    _, ident = fitted
    model = ident.model.with_offsets({1: 3.0})
    reference = hystcli.read_run(ROOT / "sample_data" / "reference_periodic.csv")
    runs = [hystcli.predict(model, hystcli.compensate(model, reference, ignore_shift=ignore).run)
            for ignore in (True, False)]
    fig = hystcli.evaluate(runs).plot(runs)
    _check_frame(fig, rows=2, cols=1)
    truth = [ln for ln in fig.axes[0].get_lines() if ln.get_label() == "ground truth (r)"]
    assert truth and _same_colour(truth[0].get_color(), style.COLOURS["reference"])
    assert truth[0].get_linestyle() == "--"
    comp = [ln for ln in fig.axes[0].get_lines() if ln.get_label() == "Compensation-Only"]
    assert comp and _same_colour(comp[0].get_color(), style.COLOURS["compensated"])


def test_the_diagnosis_figure_is_in_the_style():
    from test_diagnose import BASE, make_runs

    runs = make_runs(seed=2)
    fig = hystcli.diagnose(BASE, runs).plot(runs)
    _check_frame(fig, rows=2, cols=2)
    assert fig.texts[0].get_fontsize() == style.SUPTITLE_SIZE  # the verdict
    held_out = fig.axes[3]
    by_label = {ln.get_label().split(" (")[0]: ln for ln in held_out.get_lines()}
    for label, role in (("measured", "measured"), ("model", "model"), ("+ effects", "augmented")):
        assert _same_colour(by_label[label].get_color(), style.COLOURS[role]), label


def test_the_envelope_figure_is_in_the_style(fitted):
    from hystcli.report.inspection import envelope_figure

    _, ident = fitted
    fig = envelope_figure(ident.model)
    _check_frame(fig, rows=1, cols=len(ident.model.knobs))
    up, dn = fig.axes[0].get_lines()[:2]
    assert _same_colour(up.get_color(), style.COLOURS["loading"])
    assert _same_colour(dn.get_color(), style.COLOURS["unloading"])


def test_the_drift_figure_is_in_the_style():
    pd = pytest.importorskip("pandas")
    from hystcli.batch.report import drift_figure

    df = pd.DataFrame({"status": ["ok"] * 4, "day": [1.0, 2.0, 3.0, 4.0], "robot": ["A", "B", "A", "B"],
                       "k1_rmse": [1.0, 1.2, 1.5, 1.1]})
    fig = drift_figure(df, "day", ["k1_rmse"], by="robot")
    assert fig.dpi == style.DPI
    assert tuple(fig.get_size_inches()) == pytest.approx(style.PANEL_SIZE)
    colours = [ln.get_color() for ln in fig.axes[0].get_lines()]
    assert [to_rgba(c) for c in colours] == [to_rgba(style.series_colour(i)) for i in range(2)]


def test_no_figure_module_sets_its_own_colours_or_sizes():
    # every colour, figure size and font size comes from the style: a literal one in a figure
    # function is a figure that looks unlike the others
    files = ["report/evaluation.py", "shift/figure.py", "diagnosis/result.py", "diagnosis/figure.py",
             "identification/__init__.py", "report/inspection.py", "batch/report.py", "report/metrics.py"]
    literal = re.compile(r"""(color\s*=\s*["'])|(["']tab:)|(\bfigsize\s*=)|(fontsize\s*=\s*\d)|(\blw\s*=\s*\d)"""
                         r"""|(linewidth\s*=\s*\d)|(\bdpi\s*=\s*\d)|(Figure\()|(\.savefig\()""")
    found = []
    for name in files:
        for i, text in enumerate((ROOT / "hystcli" / name).read_text().splitlines(), 1):
            if literal.search(text):
                found.append(f"{name}:{i}: {text.strip()}")
    assert not found, "\n".join(found)


def _figure() -> Figure:
    fig, axes = style.new_figure(1, 2)
    x = np.linspace(0, 1, 50)
    axes[0, 0].plot(x, x ** 2, **style.line("model"), label="model")
    style.legend(axes[0, 0])
    return fig


def test_two_saves_of_one_figure_are_the_same_bytes(tmp_path, monkeypatch):
    fig = _figure()
    for fmt in ("png", "svg", "pdf"):
        # a different clock for each save: a date stamped into the file would show as a difference
        monkeypatch.setenv("SOURCE_DATE_EPOCH", "1000000000")
        save_figure(fig, tmp_path / f"a.{fmt}")
        monkeypatch.setenv("SOURCE_DATE_EPOCH", "1700000000")
        save_figure(fig, tmp_path / f"b.{fmt}")
        assert (tmp_path / f"a.{fmt}").read_bytes() == (tmp_path / f"b.{fmt}").read_bytes(), fmt
    png = (tmp_path / "a.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and b"matplotlib" not in png  # no version stamp
    assert _figure() is not fig and figure_bytes(_figure(), "png") == png  # drawn again: the same bytes


def test_save_figure_writes_whole_files_or_nothing(tmp_path):
    fig = _figure()
    target = tmp_path / "fig.png"
    target.write_bytes(b"old")
    with pytest.raises(DataError, match="gif"):
        save_figure(fig, tmp_path / "fig.gif")
    assert not (tmp_path / "fig.gif").exists()

    class Broken(Figure):
        def savefig(self, *args, **kwargs):  # noqa: ANN002, ANN003
            raise RuntimeError("the renderer broke")

    with pytest.raises(RuntimeError):
        save_figure(Broken(), target)
    assert target.read_bytes() == b"old" and sorted(p.name for p in tmp_path.iterdir()) == ["fig.png"]
    src = tmp_path / "in.csv"
    src.write_text("t\n0\n")
    with pytest.raises(DataError, match="refusing to overwrite"):
        save_figure(fig, src.with_suffix(".png"), inputs=[src.with_suffix(".png")])
    save_figure(fig, target, fmt="png")
    assert target.read_bytes() == figure_bytes(fig, "png")
