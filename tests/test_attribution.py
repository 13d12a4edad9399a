"""The form-agnostic which stage (hystcli/diagnosis/attribution.py): the residual of a withheld effect is
attributed to the physical quantity that drives it, whatever the effect's form."""
from __future__ import annotations

import numpy as np
import pytest

from hystcli.diagnosis import attribution as A
from hystcli.core import effects as E
from hystcli.diagnosis import search as S
from hystcli.diagnosis import diagnose
from hystcli.diagnosis.select import _folds
from test_diagnose import BASE, make_runs


def _ranking(effect, two_dof=2, seed=1):
    runs = make_runs([effect], seed=seed, two_dof=two_dof)
    names = [f"r{i}" for i in range(len(runs))]
    folds, _ = _folds(runs, names, None)
    preps = [S.prepare(BASE, r, n, True) for r, n in zip(runs, names)]
    return A.attribute(preps, (), folds, np.ones(len(runs)))


@pytest.mark.parametrize("effect, regressor", [
    (E.make_effect("coupling", gain=0.2), "other knob angle"),
    (E.make_effect("coupling", "output-magnitude", gain=0.1), "other knob magnitude"),
    (E.make_effect("coupling", "deadzone-magnitude", gain=0.3), "other knob magnitude"),
])
def test_a_coupling_in_any_form_is_attributed_to_the_other_knob(effect, regressor):
    ranking = _ranking(effect)
    assert ranking[0].regressor == regressor and ranking[0].explained_pct > 10.0


@pytest.mark.parametrize("effect, regressor", [
    (E.make_effect("creep", fraction=0.3, tau=3.0), "time since reversal"),
    (E.make_effect("saturation", limit=45.0), "tip angle"),
    (E.make_effect("friction", mu=0.4), "curvature"),
])
def test_beyond_the_loop_shape_the_residual_follows_its_driver(effect, regressor):
    # the loop-shape terms (knob direction) come first for any effect that widens the loop;
    # beyond them, the effect's own driver leads
    ranking = [a for a in _ranking(effect) if a.regressor != "knob direction"]
    assert ranking[0].regressor == regressor and ranking[0].explained_pct > 3.0


def test_noise_is_attributed_to_nothing():
    runs = make_runs((), seed=2)
    names = [f"r{i}" for i in range(len(runs))]
    folds, _ = _folds(runs, names, None)
    preps = [S.prepare(BASE, r, n, True) for r, n in zip(runs, names)]
    assert all(a.explained_pct < 3.0 for a in A.attribute(preps, (), folds, np.ones(len(runs))))


def test_a_curvature_shared_by_every_run_is_not_a_regressor():
    runs = [r.with_meta(shape="alpha=90,theta=0", offset1="13.725", offset2="0") for r in make_runs((), seed=3)]
    names = [f"r{i}" for i in range(len(runs))]
    folds, _ = _folds(runs, names, None)
    preps = [S.prepare(BASE, r, n, True) for r, n in zip(runs, names)]
    assert "curvature" not in {a.regressor for a in A.attribute(preps, (), folds, np.ones(len(runs)))}


def test_what_no_candidate_closes_is_named_in_the_verdict():
    runs = make_runs([E.make_effect("coupling", "output-magnitude", gain=0.15)], seed=4, two_dof=2)
    d = diagnose(BASE, runs, candidates=["friction", "latency"])
    assert d.selected == ()
    assert "Unexplained: the residual follows other knob magnitude" in d.verdict
    assert d.report()["where"]["follows"][0]["regressor"] == "other knob magnitude"
