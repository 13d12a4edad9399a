"""Identification and prediction on a committed excerpt of real hardware data (issue 6, Must-show 3)."""
from pathlib import Path

import numpy as np

from hystcli.identify import identify
from hystcli.importer import convert, get_preset
from hystcli.io import Run

EXCERPT = Path(__file__).parent / "data" / "mrdlab" / "load_freq" / "41_first6000.TXT.gz"


def test_real_excerpt_tip_fit_beats_a_linear_fit_in_sample_and_held_out():
    run = convert(EXCERPT, get_preset("mrdlab")).run
    n = len(run)
    cut = int(0.6 * n)
    train = Run({k: np.asarray(v)[:cut] for k, v in run.columns.items()}, dict(run.meta), "train")
    test = {k: np.asarray(v)[cut:] for k, v in run.columns.items()}
    fit = identify(train).fits[1]
    assert fit.method == "tip"
    q, y = train["q1"], train["y1"]
    g = np.polyfit(q, y, 1)  # the static linear fit (gain and offset) of issue 6
    lin = np.sqrt(np.mean((np.polyval(g, q) - y) ** 2))
    ours = np.sqrt(np.mean((fit.model.forward(q, float(y[0])) - y) ** 2))
    assert ours <= 0.4 * lin
    # held-out cycles: the model continues from the last training output
    yh = fit.model.forward(np.concatenate([q, test["q1"]]), float(y[0]))[cut:]
    lin_h = np.sqrt(np.mean((np.polyval(g, test["q1"]) - test["y1"]) ** 2))
    ours_h = np.sqrt(np.mean((yh - test["y1"]) ** 2))
    assert ours_h <= 0.5 * lin_h
