"""The effect registry (hystcli/core/effects/registry.py): forms by name in files, on the command line
and in run metadata; version 1 model files stay valid; every form's search grid sits in its bounds."""
from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hystcli.core import effects as E
from hystcli.sim import twin
from hystcli.errors import ModelError
from hystcli.io import load_model, save_model
from hystcli.core.model import Model
from hystcli.core.params import EffectSpec

CAT = twin.get_catheter("example-a")
FORMS = [(n, f.name) for n, et in E.EFFECTS.items() for f in et.forms]


@pytest.mark.parametrize("name, form", FORMS)
def test_every_form_is_complete_and_its_grid_within_bounds(name, form):
    f = E.EFFECTS[name].get_form(form)
    assert f.switch in f.params and f.stage in E.STAGES
    for p in f.params:
        lo, hi = f.bounds[p]
        assert lo < hi and lo <= f.typical[p] <= hi
        assert f.domain[p][0] <= lo and hi <= f.domain[p][1]
    for p, axis in f.axes.items():
        finite = axis[np.isfinite(axis)]
        assert np.all((finite >= f.bounds[p][0]) & (finite <= f.bounds[p][1]))
    # the grid holds the null setting (so "no effect" is always a candidate point)
    assert any(f.null_distance(g) == 0.0 for g in f.grid())
    assert set(f.fit) <= set(f.params)


def test_the_name_is_the_physics_and_the_default_form_comes_first():
    assert E.make_effect("lag", tau=0.2).name == "rate"  # an alias
    c = E.make_effect("coupling", "deadzone-magnitude", gain=0.1)
    assert (c.name, c.form, c.label()) == ("coupling", "deadzone-magnitude", "coupling[deadzone-magnitude]")
    assert E.make_effect("coupling").form == "input" and E.make_effect("coupling").spec().form == ""
    with pytest.raises(ModelError, match="unknown form 'sideways'"):
        E.make_effect("coupling", "sideways")
    with pytest.raises(ModelError, match="unknown parameter 'ratio'"):
        E.make_effect("saturation", "smooth", ratio=2.0)


@settings(max_examples=40, deadline=None)
@given(st.sampled_from(FORMS), st.data())
def test_forms_round_trip_through_text(nf, data):
    name, form = nf
    f = E.EFFECTS[name].get_form(form)
    params = {p: data.draw(st.floats(*f.bounds[p], allow_nan=False)) for p in f.params}
    eff = E.make_effect(name, form, **params)
    back = E.parse_effects(E.format_effects([eff]))[0]
    assert (back.name, back.form) == (name, form)
    for p in f.params:
        assert back[p] == pytest.approx(params[p], rel=1e-5, abs=1e-9)
    cli = E.parse_effect(f"{name}:form={form}," + ",".join(f"{p}={v!r}" for p, v in params.items()))
    assert cli == eff


def test_model_files_keep_forms_and_version_1_entries_stay_valid(tmp_path):
    # a version 1 file as the project wrote it before forms existed
    v1 = {"format": "hyst-model", "version": 1,
          "knobs": {"1": CAT.knobs[1].params(), "2": CAT.knobs[2].params()},
          "effects": [{"name": "coupling", "params": {"gain": 0.1}}, {"name": "creep",
                                                                      "params": {"fraction": 0.2, "tau": 3.0}}]}
    (tmp_path / "v1.json").write_text(json.dumps(v1))
    m = load_model(tmp_path / "v1.json")
    assert [E.as_effect(e).form for e in m.effects] == ["input", "relax"]
    new = Model(CAT.knobs, effects=(EffectSpec("coupling", {"gain": 0.1}, "output-magnitude"),
                                    E.make_effect("rate").spec()))
    save_model(tmp_path / "new.json", new)
    data = json.loads((tmp_path / "new.json").read_text())
    assert data["effects"][0]["form"] == "output-magnitude" and "form" not in data["effects"][1]
    assert load_model(tmp_path / "new.json").effects == new.effects
    (tmp_path / "bad.json").write_text(json.dumps({**v1, "effects": [{"name": "rate", "form": 2, "params": {}}]}))
    with pytest.raises(ModelError, match="form"):
        load_model(tmp_path / "bad.json")


def test_a_twin_run_records_a_form_that_parses_back():
    eff = E.make_effect("coupling", "deadzone-magnitude", gain=0.2)
    run = twin.simulate(CAT, np.arange(0, 2, 0.01), {1: np.zeros(200), 2: np.zeros(200)}, effects=(eff,), noise=False)
    assert E.parse_effects(run.meta["effects"]) == (eff,)
