"""hystcli.io.check: every problem of a run file at once, and the statistics behind the physical ones."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hystcli.io import check
from hystcli.io import importer
from hystcli.io.check import ERROR, WARNING, Problem, check_file, check_run
from hystcli.errors import DataError
from hystcli.core.run import Run
from hystcli.io import read_run, write_run

SWEEP = Path(__file__).resolve().parents[1] / "sample_data" / "ice-a" / "sweep_knob1.csv"


@pytest.fixture(scope="module")
def sweep():
    return read_run(SWEEP)


def _problems(report, level=None):
    return [(p.where, p.message) for p in report.problems if level is None or p.level == level]


def test_the_sample_sweep_has_no_problem():
    report = check_file(SWEEP)
    assert report.problems == () and report.ok
    assert report.rows == 12567 and report.columns == ("t", "q1", "y1", "c1")
    assert report.rate == pytest.approx(1000.0) and report.jitter < 1e-6


def test_every_problem_of_a_file_is_listed_at_once(tmp_path):
    rows = ["t,q1,y1,c1"]
    for i in range(40):
        rows.append(f"{i * 0.01:.2f},{np.sin(i / 6):.4f},{np.sin(i / 6) / 2:.4f},{i:.1f}")
    # rows[k] is line k + 2 of the file (a metadata line, then the header)
    rows[6] = "0.04,abc,0.1,2"           # line 8: text in q1, and time repeats 0.04
    rows[10] = "0.09,0.5,,3"             # line 12: an empty y1
    rows[12] = "0.11,0.5,0.2,1e308"      # line 14: a corrupt current
    rows[20] = "0.19,0.5,nan,inf"        # line 22: NaN tip, infinite current
    p = tmp_path / "bad.csv"
    p.write_bytes(b"\xef\xbb\xbf# shape: bent\n" + "\n".join(rows).encode() + b"\n")
    report = check_file(p)
    found = _problems(report)
    assert ("file", "the file starts with a byte-order mark (Excel's UTF-8): hyst reads it, some other tools take "
                    "it for part of the first name") in found
    assert ("meta:shape", "metadata shape 'bent' is not a shape (bad shape segment 'bent': expected "
                          "alpha=DEG[,theta=DEG]): write 'straight' or alpha=DEG,theta=DEG segments separated by ';'") \
        in found
    assert ("t", "1 time step(s) do not increase, the first at line 8 (0.04 then 0.04)") in found
    assert ("q1", "1 cell(s) are not numbers, the first at line 8 ('abc')") in found
    assert ("y1", "2 missing value(s) (empty or NaN), the first at line 12") in found
    assert ("c1", "1 infinite value(s), the first at line 22 ('inf')") in found
    assert ("c1", "1 value(s) beyond +-1e+10, not a plausible angle, current or time, the first at line 14 "
                  "('1e308')") in found
    assert not report.ok
    # the repeated time stamp also leaves a step twice as long: a gap, with its jitter figure
    assert [p.where for p in report.problems if p.level == WARNING] == ["file", "t"]
    assert "1 gap(s) over 1.5 steps" in dict(_problems(report, WARNING))["t"]
    # the file problems first, then the columns in the run's order
    assert [p.where for p in report.problems][:3] == ["file", "meta:shape", "t"]


def test_a_users_own_columns_are_named_with_a_suggestion(tmp_path, sweep):
    p = tmp_path / "mine.tsv"
    body = "\n".join(f"{t!r}\t{q!r}\t{y!r}\t{c!r}" for t, q, y, c in
                     zip(*(sweep[n].tolist() for n in ("t", "q1", "y1", "c1"))))
    p.write_text("# my bench\ntime_s\tknob_deg\ttip_deg\tcurrent_mA\n" + body + "\n")
    found = _problems(check_file(p), ERROR)
    assert found == [
        ("file", "the columns are separated by tabs, not commas: read it with --columns (any separator), or "
                 "convert it with hyst import"),
        ("header", "no time column t (the file has time_s, knob_deg, tip_deg, current_mA); name yours with "
                   "--columns t=time_s,q1=knob_deg,y1=tip_deg,c1=current_mA"),
        ("header", "no knob angle q1 or q2, nor a reference r1 or r2 (columns found: none)")]
    report = check_file(p, importer.columns_mapping("t=time_s,q1=knob_deg,y1=tip_deg,c1=current_mA"))
    assert report.problems == () and report.rows == len(sweep)
    report = check_file(p, importer.columns_mapping("t=time,q1=knob_deg"))
    assert _problems(report) == [("header", "no column 'time' for t (the file has time_s, knob_deg, tip_deg, "
                                            "current_mA); did you mean 'time_s'?")]


def test_unreadable_files_are_one_problem(tmp_path):
    assert _problems(check_file(tmp_path / "nope.csv")) == [("file", "no such file")]
    (tmp_path / "e.csv").write_text("\n")
    assert _problems(check_file(tmp_path / "e.csv")) == [("file", "empty file")]
    (tmp_path / "n.csv").write_text("0,1\n1,2\n" * 10)
    assert _problems(check_file(tmp_path / "n.csv"))[0][0] == "header"
    (tmp_path / "short.csv").write_text("t,q1,c1\n0,1,2\n1,2,3\n")
    assert ("file", "only 2 data row(s): a run needs at least 10") in _problems(check_file(tmp_path / "short.csv"))


def test_physical_problems_of_a_sweep(sweep):
    t, q, y, c = (sweep[n] for n in ("t", "q1", "y1", "c1"))
    rng = np.random.default_rng(3)
    # the no-load level: the current where the knob sits in the middle of its dead zone
    c0 = float(np.median(c[np.abs(q) < 3.0]))
    cases = {
        "magnitude": Run({"t": t, "q1": q, "y1": y, "c1": c0 + np.abs(c - c0)}),
        "flat tip": Run({"t": t, "q1": q, "y1": 0.01 * rng.standard_normal(t.size), "c1": c}),
        "one way": Run({"t": t[:1500], "q1": q[:1500], "c1": c[:1500]}),  # 0 to +40 deg, past d_pos
        "no edge": Run({"t": t, "q1": q, "c1": 2.0 * q + rng.standard_normal(t.size)}),
        "jitter": Run({"t": np.cumsum(0.001 * (1 + 0.2 * rng.standard_normal(t.size)).clip(0.1)), "q1": q, "c1": c}),
    }
    got = {name: [(p.level, p.where) for p in check_run(run)] for name, run in cases.items()}
    assert got == {"magnitude": [(WARNING, "c1")], "flat tip": [(WARNING, "y1")], "one way": [(WARNING, "q1")],
                   "no edge": [(WARNING, "c1")], "jitter": [(WARNING, "t")]}
    message = check_run(cases["magnitude"])[0].message
    assert message.startswith("the current never goes below its no-load level") and \
        "--current-sign magnitude is the option for such drives" in message
    # said to be signed, a magnitude is an error; said to be a magnitude, it is not looked for
    assert [(p.level, p.where) for p in check_run(cases["magnitude"], current_sign="signed")] == [(ERROR, "c1")]
    assert check_run(cases["magnitude"], current_sign="magnitude") == ()
    assert check_run(sweep, current_sign="signed") == ()
    assert check_run(sweep) == ()
    assert "20.0 % jitter" in check_run(cases["jitter"])[0].message


def test_units_left_off_are_warned(sweep):
    # a log in ms and A read as s and mA: the 40 deg/s sweep turns at 0.04 deg/s, and a current of
    # about 125 mA reads 0.125 (the sample sweep's own figures)
    t, q, y, c = (sweep[n] for n in ("t", "q1", "y1", "c1"))
    ms = [(p.where, p.message) for p in check_run(Run({"t": 1000.0 * t, "q1": q, "y1": y, "c1": c}))]
    assert [w for w, _ in ms] == ["t"] and "is t in milliseconds?" in ms[0][1] and ":ms" in ms[0][1]
    amps = [(p.where, p.message) for p in check_run(Run({"t": t, "q1": q, "y1": y, "c1": c / 1000.0}))]
    assert [w for w, _ in amps] == ["c1"] and "in amperes?" in amps[0][1]
    # the same figures with their units named are clean (the unit conversion of --columns)
    assert check_run(Run({"t": t, "q1": q, "y1": y, "c1": c})) == ()


def test_an_edge_is_a_slope_change_and_noise_is_none():
    rng = np.random.default_rng(11)
    q = np.concatenate([np.linspace(-20, 20, 400), np.linspace(20, -20, 400)])
    line = [check.passes_an_edge(q, 1.5 * q + rng.standard_normal(q.size)) for _ in range(20)]
    hinge = [check.passes_an_edge(q, 0.1 * q + 3 * np.maximum(q - 5, 0) + rng.standard_normal(q.size))
             for _ in range(20)]
    assert line == [(False, 2)] * 20
    assert hinge == [(True, 1)] * 20  # the first stretch shows it: no need to read the second


def test_noise_is_read_from_second_differences():
    rng = np.random.default_rng(5)
    x = np.linspace(0, 40, 5000) + 0.3 * rng.standard_normal(5000)  # a ramp does not enter it
    assert check.noise(x) == pytest.approx(0.3, rel=0.1)


def test_require_shape_names_the_file(tmp_path):
    run = Run({"t": [0.0, 1.0], "q1": [0.0, 1.0]}, {"shape": "bent"}, source="runs/a.csv")
    with pytest.raises(DataError, match=r"^runs/a\.csv: metadata shape 'bent' is not a shape"):
        check.require_shape(run)
    assert check.require_shape(run.with_meta(shape="alpha=45")).meta["shape"] == "alpha=45"


def test_problem_is_a_frozen_record():
    p = Problem(WARNING, "t", "x")
    with pytest.raises(AttributeError):
        p.level = ERROR  # type: ignore[misc]
    with pytest.raises(ValueError):
        Problem("fatal", "t", "x")
    assert p.to_dict() == {"level": "warning", "where": "t", "message": "x"}


def test_a_written_run_checks_clean(tmp_path, sweep):
    write_run(tmp_path / "copy.csv", sweep)
    assert check_file(tmp_path / "copy.csv").problems == ()
