"""Tests of hystcli.io: run CSV and model JSON readers/writers, validation, atomic writes."""
from __future__ import annotations

import json
import math
import os
import re
from pathlib import Path
from unittest import mock

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hystcli.errors import DataError, ModelError
from hystcli.estimate import Estimate
from hystcli.core.run import Run
from hystcli.io import (MAX_ABS_VALUE, dumps_model, format_run, load_model, model_from_dict, model_to_dict, parse_run,
                        read_run, save_model, write_run)
from hystcli.core.model import Model
from hystcli.core.params import Calibration, EffectSpec, Geometry, KnobIdentification, KnobModel

GOOD = "# catheter: ice-a\n# shape: alpha=90,theta=0\n# lab_note: kept\nt,q1,y1\n0,0,0\n0.1,1.5,0.2\n0.2,3,0.4\n"


def test_read_run_keeps_metadata_and_columns(tmp_path):
    p = tmp_path / "run.csv"
    p.write_text(GOOD)
    run = read_run(p, require=("q1",))
    assert list(run.columns) == ["t", "q1", "y1"]
    assert run.meta["catheter"] == "ice-a"
    assert run.meta["shape"] == "alpha=90,theta=0"
    assert run.unknown_meta() == ["lab_note"]
    np.testing.assert_array_equal(run["q1"], [0, 1.5, 3])
    assert run.knobs() == [1]


@pytest.mark.parametrize("prefix, newline", [("", "\n"), ("\ufeff", "\r\n"), ("\ufeff", "\n"), ("\n", "\r\n")])
def test_read_meta_reads_the_head_as_read_run_does(tmp_path, prefix, newline):
    # an Excel byte-order mark, CRLF or a leading blank line must not hide the first metadata line
    from hystcli.io.runs import read_meta

    p = tmp_path / "run.csv"
    p.write_bytes((prefix + GOOD.replace("\n", newline)).encode("utf-8"))
    assert read_meta(p) == read_run(p).meta == {"catheter": "ice-a", "shape": "alpha=90,theta=0", "lab_note": "kept"}


@pytest.mark.parametrize("text, message", [
    ("", "empty file"),
    ("# catheter: x\n", "empty file"),
    ("t,q1\n", "no data rows"),
    ("t,q1\n0,1\n0.1,nan\n", "column 'q1', line 3: NaN"),
    ("t,q1\n0,1\n0.1,\n", "column 'q1', line 3: NaN"),
    ("t,q1\n0,1\n0.1,abc\n", "column 'q1', line 3: 'abc' is not a number"),
    ("t,q1\n0,1\n0.1,inf\n", "infinite"),
    ("t,q1\n0,1\n0,2\n", "not strictly increasing at line 3"),
    ("t,q1\n0.2,1\n0.1,2\n", "not strictly increasing"),
    ("q1,y1\n0,1\n", "missing column 't'"),
    ("t,q1,q1\n0,1,2\n", "appears twice"),
    ("t,q1\n0,1,5\n", "line 2 has 3 fields, the header has 2"),
    ("t,q1,y1\n0,1\n", "line 2 has 2 fields, the header has 3"),
])
def test_bad_runs_are_refused_with_a_clear_message(text, message):
    with pytest.raises(DataError, match=message):
        parse_run(text, source="x.csv", require=())


def test_missing_required_column_and_file(tmp_path):
    p = tmp_path / "run.csv"
    p.write_text(GOOD)
    with pytest.raises(DataError, match="missing column 'c1'"):
        read_run(p, require=("c1",))
    with pytest.raises(DataError, match="no such file"):
        read_run(tmp_path / "nope.csv")
    with pytest.raises(DataError, match="is a directory"):
        read_run(tmp_path)
    (tmp_path / "bin.csv").write_bytes(b"\xff\xfe\x00\x01")
    with pytest.raises(DataError, match="not a text CSV"):
        read_run(tmp_path / "bin.csv")


# any value a run may hold: finite and within the plausibility bound of io.MAX_ABS_VALUE
finite = st.floats(-MAX_ABS_VALUE, MAX_ABS_VALUE, allow_nan=False, allow_infinity=False, width=64)


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(n=st.integers(1, 30), data=st.data(),
       meta=st.dictionaries(st.from_regex(r"[a-z][a-z0-9_]{0,8}", fullmatch=True),
                            st.from_regex(r"[A-Za-z0-9=,;.+\- ]{0,20}", fullmatch=True).map(str.strip),
                            max_size=5))
def test_run_round_trip_is_lossless(tmp_path, n, data, meta):
    t = np.cumsum(data.draw(st.lists(st.floats(1e-6, 10), min_size=n, max_size=n)))
    cols = {"t": t}
    for name in ("q1", "y1", "c2"):
        cols[name] = np.array(data.draw(st.lists(finite, min_size=n, max_size=n)))
    run = Run(cols, meta)
    p = tmp_path / "rt.csv"
    write_run(p, run)
    back = read_run(p)
    assert dict(back.meta) == dict(run.meta)
    assert list(back.columns) == list(run.columns)
    for name in cols:
        np.testing.assert_array_equal(back[name], cols[name])  # bit-exact, not approximately


def sample_model():
    return Model(
        {1: KnobModel(9.1, -8.7, 6.2, 5.9, 1.45, -4.0, 4.2, 1.25),
         2: KnobModel(8.0, -9.0, 5.0, 6.0, 1.5, -3.0, 3.5)},
        Geometry(1.2, 8.0),
        (EffectSpec("friction", {"mu": 0.3}),),
        {"catheter": "ice-a", "source": "sweep.csv"},
        {1: KnobIdentification(-40.0, 40.0, method="tip", rmse=0.31,
                               estimates={"d_pos": Estimate(9.1, 9.06, 9.14),
                                          "b_pos": Estimate(6.2, 5.0, math.inf, fixed=False, reason="open above")},
                               calibration=Calibration(current_sign="signed",
                                                       current_edges={"pos": Estimate(9.3, 9.2, 9.4)},
                                                       slope_dead_zone=0.05, slope_loaded_pos=4.8,
                                                       no_load_rising=126.0, no_load_falling=114.0))},
    )


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(vals=st.lists(st.floats(-50, 50), min_size=3, max_size=3), offset=st.floats(-40, 40))
def test_model_round_trip_is_lossless(tmp_path, vals, offset):
    base = sample_model()
    k = KnobModel(9.1 + abs(vals[0]), -8.7 - abs(vals[1]), 6.2, 5.9, 1.45, -4.0, 4.2, offset)
    m = base.with_knob(1, k)
    p = tmp_path / "m.json"
    save_model(p, m)
    back = load_model(p)
    assert model_to_dict(back) == model_to_dict(m)
    assert back.knob(1) == k
    assert dumps_model(back) == p.read_text()


@pytest.mark.parametrize("mutate, message", [
    (lambda d: d.update(version=2), "unknown model version 2"),
    (lambda d: d.update(format="other"), "not a hyst model"),
    (lambda d: d["knobs"]["1"].pop("omega"), "missing parameter omega"),
    (lambda d: d["knobs"]["1"].update(omega=-1), "omega > 0 is violated"),
    (lambda d: d["knobs"]["1"].update(b_pos=-1), "b_pos >= 0 is violated"),
    (lambda d: d["knobs"]["1"].update(d_pos="9"), "must be a number"),
    (lambda d: d["knobs"]["1"].update(gain=2), "unknown parameter 'gain'"),
    (lambda d: d["knobs"].update({"3": d["knobs"]["1"]}), "unknown knob '3'"),
    (lambda d: d.update(knobs={}), "knobs"),
    (lambda d: d["geometry"].update(beta_knob_mm=0), "beta_knob_mm > 0"),
])
def test_bad_models_are_refused(mutate, message):
    d = model_to_dict(sample_model())
    mutate(d)
    with pytest.raises(ModelError, match=message):
        model_from_dict(d)


def test_bad_model_files(tmp_path):
    with pytest.raises(ModelError, match="no such model file"):
        load_model(tmp_path / "nope.json")
    (tmp_path / "e.json").write_text("")
    with pytest.raises(ModelError, match="empty model file"):
        load_model(tmp_path / "e.json")
    (tmp_path / "b.json").write_text("{not json")
    with pytest.raises(ModelError, match="not valid JSON"):
        load_model(tmp_path / "b.json")
    d = model_to_dict(sample_model())
    d["knobs"]["1"]["d_pos"] = float("nan")
    (tmp_path / "n.json").write_text(json.dumps(d))
    with pytest.raises(ModelError, match="finite"):
        load_model(tmp_path / "n.json")


def test_atomic_write_leaves_nothing_on_failure(tmp_path):
    p = tmp_path / "out.csv"
    p.write_text("old contents")

    class Boom(Run):
        pass

    run = Run({"t": [0.0, 1.0]}, {})
    # a failure inside the writer leaves the old file intact and no temporary file behind
    from hystcli import io as hio

    def bad_writer(f):
        f.write(b"partial")
        raise RuntimeError("disk on fire")

    with pytest.raises(RuntimeError):
        hio.atomic_write(p, bad_writer)
    assert p.read_text() == "old contents"
    assert sorted(os.listdir(tmp_path)) == ["out.csv"]
    write_run(p, run)
    assert read_run(p)["t"].tolist() == [0.0, 1.0]


def test_refuses_to_overwrite_an_input(tmp_path):
    p = tmp_path / "run.csv"
    p.write_text(GOOD)
    with pytest.raises(DataError, match="refusing to overwrite an input"):
        write_run(p, read_run(p), inputs=[p])
    assert p.read_text() == GOOD


def test_format_run_text():
    text = format_run(Run({"t": [0.0, 0.5], "q1": [0.1, -2.0]}, {"catheter": "x"}))
    assert text == "# catheter: x\nt,q1\n0.0,0.1\n0.5,-2.0\n"


# --------------------------------------------------------------------------------------------
# issue 12: files follow the umask, several outputs all or none, the caller's arrays untouched
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("umask, mode", [(0o022, 0o644), (0o027, 0o640), (0o077, 0o600), (0o002, 0o664)])
def test_output_files_follow_the_umask(tmp_path, umask, mode):
    from hystcli.io import all_or_none

    old = os.umask(umask)
    try:
        write_run(tmp_path / "a.csv", Run({"t": [0.0, 1.0]}))
        save_model(tmp_path / "m.json", sample_model())
        with all_or_none() as out:
            out.write_text(tmp_path / "b.txt", "b")
    finally:
        os.umask(old)
    for name in ("a.csv", "m.json", "b.txt"):
        assert (tmp_path / name).stat().st_mode & 0o777 == mode, name


def test_several_outputs_are_written_all_or_none(tmp_path):
    from hystcli.io import all_or_none

    (tmp_path / "report.json").write_text("old report")
    with pytest.raises(RuntimeError, match="plot failed"):
        with all_or_none() as out:
            out.write_text(tmp_path / "report.json", "new report")
            out.write_text(tmp_path / "model.json", "new model")
            raise RuntimeError("plot failed")  # e.g. the third output cannot be drawn
    assert sorted(os.listdir(tmp_path)) == ["report.json"]  # no new file, no temporary file
    assert (tmp_path / "report.json").read_text() == "old report"
    with all_or_none() as out:
        out.write_text(tmp_path / "report.json", "new report")
        path = out.path(tmp_path / "fig.png")
        assert path.endswith(".png") and "fig.png" in path  # writers that choose by the suffix
        Path(path).write_bytes(b"png")
        assert not (tmp_path / "fig.png").exists()  # nothing lands before the end
    assert (tmp_path / "report.json").read_text() == "new report"
    assert (tmp_path / "fig.png").read_bytes() == b"png"
    assert sorted(os.listdir(tmp_path)) == ["fig.png", "report.json"]


def test_an_error_names_the_target_not_the_temporary_file(tmp_path):
    from hystcli.io import all_or_none

    with pytest.raises(DataError) as err:
        with all_or_none() as out:
            tmp = out.path(tmp_path / "fig.png")
            raise DataError(f"{tmp}: cannot draw")  # what a writer given the temporary path says
    assert str(err.value) == f"{tmp_path / 'fig.png'}: cannot draw"
    with pytest.raises(DataError, match="the folder .* does not exist"):
        write_run(tmp_path / "nope" / "r.csv", Run({"t": [0.0]}))
    with pytest.raises(DataError, match="is a directory"):
        write_run(tmp_path, Run({"t": [0.0]}))
    assert os.listdir(tmp_path) == []


def test_run_does_not_freeze_the_callers_array():
    q = np.array([0.0, 1.0, 2.0])
    run = Run({"t": [0.0, 0.1, 0.2], "q1": q})
    q[0] = 5.0  # still the caller's to change ...
    assert q.flags.writeable
    assert run["q1"][0] == 0.0  # ... without changing the run
    with pytest.raises(ValueError):
        run["q1"][0] = 1.0  # the run's own copy is read-only
    # a run's read-only arrays are shared by the runs made from it, not copied again
    assert run.with_meta(x=1)["q1"] is run["q1"]


def test_a_byte_order_mark_is_not_part_of_the_first_column(tmp_path):
    (tmp_path / "bom.csv").write_bytes(b"\xef\xbb\xbf" + GOOD.encode())
    assert read_run(tmp_path / "bom.csv").meta["catheter"] == "ice-a"
    assert list(parse_run("\ufeff" + GOOD).columns) == ["t", "q1", "y1"]


@pytest.mark.parametrize("header, hint", [("t;q1;y1", "--sep ';' --skip 1 --map t=1,q1=2,y1=3"),
                                          ("t\tq1\tc1", "--sep tab --skip 1 --map t=1,q1=2,c1=3")])
def test_a_file_with_another_separator_gets_the_import_command(header, hint):
    with pytest.raises(DataError, match=re.escape(hint)):
        parse_run(f"{header}\n0;0;0\n", source="x.csv")


def test_values_beyond_the_plausible_are_refused_on_read_and_on_write(tmp_path):
    with pytest.raises(DataError, match=r"column 'y1', line 3: 1e\+308 is beyond"):
        parse_run("t,q1,y1\n0,0,0\n0.1,1,1e308\n")
    # an unknown column is kept as it is (hyst computes nothing on it)
    assert parse_run("t,serial\n0,1e300\n")["serial"][0] == 1e300
    with pytest.raises(DataError, match="refusing to write column 'c1', sample 0"):
        format_run(Run({"t": [0.0], "c1": [2e10]}))


def test_a_cogging_ripple_round_trips_through_the_model_file(tmp_path):
    ident = KnobIdentification(-40.0, 40.0, calibration=Calibration(
        current_sign="signed", no_load_rising=120.0, cogging_period=4.7, cogging_sin=1.9, cogging_cos=-0.6))
    m = Model({1: KnobModel(9.1, -8.7, 6.2, 5.9, 1.45, -4.0, 4.2)}, identification={1: ident})
    p = tmp_path / "m.json"
    save_model(p, m)
    back = load_model(p).identification[1]
    cal = back.calibration
    assert (cal.cogging_period, cal.cogging_sin, cal.cogging_cos) == (4.7, 1.9, -0.6)
    assert cal.ripple(4.7 / 4) == pytest.approx(1.9)    # sin(pi/2) = 1, cos(pi/2) = 0
    # a model without one writes no cogging keys (older files read the same)
    save_model(p, sample_model())
    assert "cogging" not in p.read_text()


@pytest.mark.parametrize("fields, message", [
    ({"cogging_period": 0.0, "cogging_sin": 1.0, "cogging_cos": 0.0}, "cogging_period must be a positive"),
    ({"cogging_period": -3.0, "cogging_sin": 1.0, "cogging_cos": 0.0}, "cogging_period must be a positive"),
    ({"cogging_period": 4.0, "cogging_sin": 1.0}, "go together"),
    ({"current_sign": "both"}, "current_sign must be signed or magnitude"),
    ({"current_edges": {"up": {"value": 1.0, "lo": 0.0, "hi": 2.0}}}, "current_edges keys must be pos/neg"),
    ({"estimates": {"d_pos": 5}}, "must map names to intervals"),
    ({"estimates": {"d_pos": {"lo": 1.0, "hi": 2.0}}}, "estimates d_pos: an interval needs value"),
    ({"estimates": {"d_pos": {"value": 2.5, "lo": 3.0, "hi": 2.0}}}, "interval must be ordered"),
    ({"q_min": "a"}, "q_min must be a number"),
])
def test_a_bad_identification_field_in_a_model_file_is_one_clear_error(tmp_path, fields, message):
    p = tmp_path / "m.json"
    save_model(p, sample_model())
    d = json.loads(p.read_text())
    d["identification"]["1"].update(fields)
    p.write_text(json.dumps(d))
    with pytest.raises(ModelError, match=message):
        load_model(p)


def test_open_intervals_round_trip_through_the_model_file_as_null(tmp_path):
    # a current edge the record bounds on one side only, and a backlash the current did not show
    ident = KnobIdentification(
        -40.0, 40.0, method="current",
        estimates={"b_pos": Estimate(0.0, 0.0, math.inf, fixed=False, reason="not shown by the current"),
                   "d_pos": Estimate(11.7, 11.5, 11.9)},
        calibration=Calibration(
            current_sign="magnitude",
            current_edges={"pos": Estimate(11.7, 11.5, 11.9), "neg": Estimate(-12.4, -math.inf, -12.0, fixed=False,
                                                                               reason="seen at the stretch's end")}))
    m = Model({1: KnobModel(11.7, -12.4, 0.0, 0.6, 1.45, -4.0, 4.2)}, identification={1: ident})
    p = tmp_path / "m.json"
    save_model(p, m)
    raw = json.loads(p.read_text())["identification"]["1"]
    assert raw["current_edges"]["neg"]["lo"] is None and raw["estimates"]["b_pos"]["hi"] is None
    back = load_model(p).identification[1]
    edge = back.calibration.current_edges["neg"]
    assert edge == ident.calibration.current_edges["neg"]
    assert edge.lo == -math.inf and not edge.fixed
    assert back.estimates["b_pos"].reason == "not shown by the current"
    assert back.unfixed == ("b_pos",) and back.calibration.current_sign == "magnitude" and back.method == "current"
    assert back.stderr == {"d_pos": pytest.approx(0.2 / 1.959964, rel=1e-5)}
    assert back == ident


def test_a_current_only_model_without_its_backlash_refuses_to_predict(tmp_path):
    # the backlash stays in the file as 0 deg, marked not fixed; predicting with it would be
    # predicting with a placeholder, so the model says so (detect-shift can still use it)
    est = {n: Estimate(0.0, 0.0, math.inf, fixed=False, reason="not shown") for n in ("b_pos", "b_neg")}
    ident = KnobIdentification(-40.0, 40.0, method="current", estimates=est,
                               calibration=Calibration(current_sign="signed"))
    m = Model({1: KnobModel(9.1, -8.7, 0.0, 0.0, 1.45, 0.0, 0.0)}, identification={1: ident})
    p = tmp_path / "m.json"
    save_model(p, m)
    back = load_model(p)
    assert back.identification[1].unfixed == ("b_pos", "b_neg")
    with pytest.raises(ModelError, match="b_pos and b_neg were not fixed"):
        back.require_loop([1], "predict")
    back.require_loop([2], "predict")        # another knob is not refused


# ------------------------------------------------------------------------------------------
# read_run's block reader says what parse_run says
# ------------------------------------------------------------------------------------------
def _read_both(tmp_path, data: bytes):
    """read_run of the file and parse_run of its text: each the run or the error message."""
    p = tmp_path / "run.csv"
    p.write_bytes(data)
    out = []
    for read in (lambda: read_run(p, require=()),
                 lambda: parse_run(data.decode("utf-8-sig"), source=str(p), require=())):
        try:
            out.append(read())
        except DataError as exc:
            out.append(str(exc))
        except UnicodeDecodeError:
            out.append(f"{p}: not a text CSV file (not UTF-8)")
    return out


@pytest.mark.parametrize("data", [
    b"t,q1\n0,1\n0.1,nan\n", b"t,q1\n0,1\n0.1,\n", b"t,q1\n0,1\n0.1,abc\n", b"t,q1\n0,1\n0,2\n",
    b"t,q1\n0,1,5\n", b"t,q1,y1\n0,1\n", b"t,q1\n0,1,\n0.1,2,\n",   # a surplus first field: no index
    b"t,q1\n0,1\n0.1,2,3\n", b't,q1\n0,"1"\n', b"t,q1\n0,1\n\n0.1,2\n", b"t,q1\n0,1\r\n0.1,2\r\n",
    b"t,q1\n0,1\r0.1,2\n", b"t,q1\n0,1\x0c\n0.1,2\n", b"t,q1\n0,1\n0.1,1e308\n", b"t,q1\n0,1\n  \n0.1,2\n",
    b"\xef\xbb\xbf# catheter: x\n\nt,q1\n0,1\n", b"\xef\xbb\xbf\xef\xbb\xbft,q1\n0,1\n", b"t,q1\n", b"# a: b\n",
    b"t,q1\n0,\xe4\n", b"t,q1\n0,1\n0.1,inf\n",
    b"t,q1\n# note\n0,1\n", b"t;q1\n0;1\n", b"t,q1\n 0 , 1 \n0.1,2\n", b"t,q1\n0,1\n0.1,2",
])
def test_the_block_reader_reads_or_refuses_as_parse_run(tmp_path, data):
    fast, slow = _read_both(tmp_path, data)
    if isinstance(slow, str):
        assert fast == slow
    else:
        assert isinstance(fast, Run), fast
        assert dict(fast.meta) == dict(slow.meta) and list(fast.columns) == list(slow.columns)
        for name in slow.columns:
            np.testing.assert_array_equal(fast[name], slow[name])


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(st.tuples(st.floats(1e-6, 1e3), finite, finite), min_size=1, max_size=30), st.booleans(),
       st.booleans())
def test_any_good_run_reads_the_same_in_blocks(tmp_path, rows, crlf, meta):
    t = np.cumsum([r[0] for r in rows])
    text = ("# catheter: x\n" if meta else "") + "t,q1,note\n" + "".join(
        f"{a!r},{r[1]!r},{r[2]!r}\n" for a, r in zip(t.tolist(), rows))
    data = text.replace("\n", "\r\n").encode() if crlf else text.encode()
    (tmp_path / "run.csv").write_bytes(data)
    with mock.patch("hystcli.io.runs.parse_run", side_effect=AssertionError("read twice")):
        fast = read_run(tmp_path / "run.csv")  # in blocks: a good file needs no second reading
    slow = parse_run(data.decode(), require=())
    assert dict(fast.meta) == dict(slow.meta)
    for name in slow.columns:
        np.testing.assert_array_equal(fast[name], slow[name])


def test_a_big_file_is_read_in_blocks_with_progress_and_without_parse_run(tmp_path, monkeypatch):
    import hystcli.io.runs as io_mod

    monkeypatch.setattr(io_mod, "READ_CHUNK_ROWS", 7)
    monkeypatch.setattr(io_mod, "READ_PROGRESS_BYTES", 0)

    def never(*a, **k):
        raise AssertionError("a good file needs no second reading")

    monkeypatch.setattr(io_mod, "parse_run", never)
    n = 100
    p = tmp_path / "run.csv"
    p.write_text("# motion: sweep\nt,q1,c1\n" + "".join(f"{i / 100!r},{float(np.sin(i))!r},{i}\n\n" for i in range(n)))
    seen = []
    run = read_run(p, progress=lambda done, total: seen.append((done, total)))
    assert len(run) == n and run.meta["motion"] == "sweep"
    np.testing.assert_array_equal(run["q1"], np.sin(np.arange(n)))
    assert not run["q1"].flags.writeable
    # one call per block of 7 rows, bytes growing to the file's size
    size = p.stat().st_size
    assert len(seen) == -(-n // 7) and all(total == size for _, total in seen)
    assert [d for d, _ in seen] == sorted(d for d, _ in seen) and seen[-1][0] == size


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(finite, finite), min_size=0, max_size=40), st.booleans())
def test_a_run_is_written_as_pandas_writes_it(rows, meta):
    """The writer joins float reprs piece by piece; pandas' to_csv (what it replaced) is the
    reference for the bytes."""
    import io as _io

    import pandas as pd

    cols = {"t": np.arange(len(rows)) * 0.01, "q1": [r[0] for r in rows], "c1": [r[1] for r in rows]}
    run = Run(cols, {"catheter": "x\ny"} if meta else {})
    buf = _io.StringIO()
    pd.DataFrame({k: np.asarray(v, dtype=float) for k, v in cols.items()}).to_csv(buf, index=False, lineterminator="\n")
    assert format_run(run) == ("# catheter: x y\n" if meta else "") + buf.getvalue()


def test_a_long_run_is_written_in_pieces_that_read_back(tmp_path, monkeypatch):
    import hystcli.io.runs as io_mod

    monkeypatch.setattr(io_mod, "_WRITE_ROWS", 3)
    run = Run({"t": np.arange(10) / 7, "q1": np.sin(np.arange(10))}, {"motion": "sweep"})
    write_run(tmp_path / "r.csv", run)
    back = read_run(tmp_path / "r.csv")
    assert (tmp_path / "r.csv").read_text() == format_run(run) and back.meta["motion"] == "sweep"
    np.testing.assert_array_equal(back["q1"], run["q1"])
    with pytest.raises(DataError, match="refusing to write column 'q1', sample 9"):
        write_run(tmp_path / "bad.csv", Run({"t": np.arange(10.0), "q1": np.r_[np.zeros(9), np.nan]}))
    assert not (tmp_path / "bad.csv").exists() and sorted(p.name for p in tmp_path.iterdir()) == ["r.csv"]
