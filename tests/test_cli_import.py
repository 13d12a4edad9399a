"""CLI tests of `hyst import` (CliRunner) on the committed real excerpt and small synthetic logs.

docs/design.md section 10: bad input -> exit 1 with one line ``Error: ...``, no traceback, nothing
written; usage errors exit 2.
"""
from __future__ import annotations

import gzip
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from hystcli.cli import app
from hystcli.io import read_run

DATA = Path(__file__).parent / "data" / "mrdlab"
LOAD41 = DATA / "load_freq" / "41_first6000.TXT.gz"
PITCH3 = DATA / "pitch_3" / "010_first1000.TXT.gz"

runner = CliRunner()


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def assert_error(res, fragment):
    assert res.exit_code == 1, res.output
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("Error: "), res.stderr
    assert fragment in lines[0], lines[0]
    assert "Traceback" not in res.output


def test_preset_import_reports_what_was_done(tmp_path):
    out = tmp_path / "41.csv"
    res = invoke("import", LOAD41, "--preset", "mrdlab", "-o", out)
    assert res.exit_code == 0, res.output
    run = read_run(out, require=("q1", "y1", "c1"))
    # raw row "1.990,63.00,1972.00,0.121,817.00,...": q1 = 63*360/8192, y1 = -(817*0.09),
    # c1 = 0.121 A = 121 mA
    assert run["q1"][1990] == 2.7685546875
    assert run["y1"][1990] == pytest.approx(-73.53, abs=1e-12)
    assert run["c1"][1990] == pytest.approx(121.0, abs=1e-12)
    assert run.meta["current_unit"] == "mA" and run.meta["load_pct"] == "20.00"
    text = res.stdout
    assert "rows 6000 read, 6000 written" in text
    assert "1000 Hz" in text
    assert "output flipped" in text and "zero: none" in text and "drift" in text
    assert "ranges: t 0 .. 5.999" in text


def test_user_map_equals_preset(tmp_path):
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    assert invoke("import", LOAD41, "--preset", "mrdlab", "-o", a).exit_code == 0
    res = invoke("import", LOAD41, "--map", "t=1,q1=2:360/8192,y1=5:0.09,c1=4", "--comment", "%",
                 "--flip-output", "-o", b)
    assert res.exit_code == 0, res.output
    assert "states no current unit: the current is taken to be in mA" in res.stderr
    res = invoke("import", LOAD41, "--map", "t=1,q1=2:360/8192,y1=5:0.09,c1=4", "--comment", "%",
                 "--flip-output", "--meta", "current_unit=A", "-o", b)
    assert res.exit_code == 0, res.output
    ra, rb = read_run(a), read_run(b)
    for name in ("t", "q1", "y1", "c1"):
        np.testing.assert_array_equal(ra[name], rb[name])


def test_map_overrides_preset_column(tmp_path):
    out = tmp_path / "ma.csv"
    res = invoke("import", LOAD41, "--preset", "mrdlab", "--map", "c1=4:1000", "--meta", "current_unit=mA",
                 "-o", out)
    assert res.exit_code == 0, res.output
    run = read_run(out)
    assert run["c1"][1990] == pytest.approx(121.0)  # 0.121 A = 121 mA
    assert run.meta["current_unit"] == "mA"


@pytest.mark.parametrize("unit, expected", [("uA", 0.000121), ("mA", 0.121), ("A", 121.0)])
def test_current_is_written_in_ma_from_the_unit_the_log_states(tmp_path, unit, expected):
    out = tmp_path / "c.csv"
    res = invoke("import", LOAD41, "--preset", "mrdlab", "--meta", f"current_unit={unit}", "-o", out)
    assert res.exit_code == 0, res.output
    run = read_run(out)
    assert run["c1"][1990] == pytest.approx(expected, rel=1e-12) and run.meta["current_unit"] == "mA"
    res = invoke("import", LOAD41, "--preset", "mrdlab", "--meta", "current_unit=kA", "-o", out)
    assert_error(res, "current_unit 'kA' is not one of A, mA, uA")


def test_show_mapping_round_trips_through_mapping_file(tmp_path):
    res = invoke("import", LOAD41, "--preset", "mrdlab", "--show-mapping")
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    assert doc["columns"]["y1"] == {"column": 5, "scale": 0.09, "offset": 0.0}
    mfile = tmp_path / "m.json"
    mfile.write_text(res.stdout)
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    assert invoke("import", LOAD41, "--preset", "mrdlab", "-o", a).exit_code == 0
    assert invoke("import", LOAD41, "--mapping", mfile, "-o", b).exit_code == 0
    np.testing.assert_array_equal(read_run(a)["y1"], read_run(b)["y1"])


def test_meta_options_and_header_pattern(tmp_path):
    out = tmp_path / "p.csv"
    res = invoke("import", PITCH3, "--preset", "mrdlab", "--meta", "trial=2", "--meta", "rig=mrd-{tool}",
                 "--meta-from-header", "lot=Lot (\\w+)", "-o", out)
    assert res.exit_code == 0, res.output
    meta = read_run(out).meta
    # header: "...tool number 4 Lot N10150901 729 ..." and pitch_3/ReadME.txt: "pitch of 0 degrees"
    assert meta["trial"] == "2" and meta["rig"] == "mrd-4" and meta["lot"] == "N10150901"
    assert meta["pitch_deg"] == "0"


def test_zero_and_resample_options(tmp_path):
    out = tmp_path / "z.csv"
    res = invoke("import", LOAD41, "--preset", "mrdlab", "--zero", "first", "--resample", "200",
                 "--decimals", "4", "-o", out)
    assert res.exit_code == 0, res.output
    run = read_run(out)
    assert len(run) == 1200  # 0 .. 5.995 s at 200 Hz
    assert run["q1"][0] == 0.0 and run["y1"][0] == 0.0
    assert "-> 200 Hz (anti-alias low-pass)" in res.stdout
    assert "q1" in res.stdout and "subtracted" in res.stdout


def test_out_dir_many_files_and_json(tmp_path):
    raw = tmp_path / "raw"
    raw.mkdir()
    shutil.copy(LOAD41, raw / "41.TXT.gz")
    (raw / "41b.TXT").write_bytes(gzip.decompress(LOAD41.read_bytes()))
    outdir = tmp_path / "out"
    outdir.mkdir()
    res = invoke("import", raw / "41.TXT.gz", raw / "41b.TXT", "--preset", "mrdlab", "--out-dir", outdir,
                 "--format", "json")
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    assert [Path(d["output"]).name for d in data] == ["41.csv", "41b.csv"]
    assert data[0]["rows_out"] == 6000 and data[0]["knobs"][0]["flipped"] is True
    assert data[0]["meta"]["frequency_hz"] == "0.50"
    np.testing.assert_array_equal(read_run(outdir / "41.csv")["y1"], read_run(outdir / "41b.csv")["y1"])


@pytest.mark.parametrize("args, fragment", [
    (["--map", "t=1,q1=11"], "reads column 11"),
    (["--preset", "mrdlab", "--meta", "catheter=x-{serial}"], "{serial}"),
])
def test_mappings_the_file_does_not_fit_exit_1_nothing_written(tmp_path, args, fragment):
    out = tmp_path / "out.csv"
    res = invoke("import", LOAD41, *args, "--comment", "%", "-o", out)
    assert_error(res, fragment)
    assert not out.exists()


@pytest.mark.parametrize("args, fragment", [
    (["--map", "t=1,w1=2"], "unknown target column 'w1'"),
    (["--map", "t=1,q1=2:abc"], "'abc' is not a number"),
    (["--map", "t=1,q1=2:0"], "scale 0"),
    (["--preset", "nope"], "unknown preset 'nope'"),
    (["--map", "q1=2"], "no time column"),
    (["--preset", "mrdlab", "--meta", "bad key=1"], "expected key=value"),
    (["--preset", "mrdlab", "--meta-from-header", "(?P<x"], "not a valid regular expression"),
    (["--preset", "mrdlab", "--sep", ""], "separator"),
])
def test_malformed_mapping_options_are_usage_errors(tmp_path, args, fragment):
    # a malformed option value is the user's typing (exit 2, issue 12), not bad data
    out = tmp_path / "out.csv"
    res = invoke("import", LOAD41, *args, "--comment", "%", "-o", out)
    assert res.exit_code == 2, res.output
    errors = [ln for ln in res.output.splitlines() if ln.startswith("Error")]
    assert len(errors) == 1 and fragment in errors[0], res.output
    assert "Traceback" not in res.output
    assert not out.exists()


@pytest.mark.parametrize("content, fragment", [
    (b"", "empty file"),
    (b"\x1f\x8b\x08\x00broken", "corrupt gzip"),
    (b"% header\n0.0,1,2,3,4\n0.001,1,2,oops,4\n", "'oops' is not a number"),
    (b"% header\n0.0,1,2,3,4\n0.0,1,2,3,4\n", "time repeats at line 3 (0.0 then 0.0;"),
])
def test_bad_files_exit_1_keep_existing_output(tmp_path, content, fragment):
    raw = tmp_path / "raw.txt"
    raw.write_bytes(content)
    out = tmp_path / "out.csv"
    out.write_text("keep me\n")
    res = invoke("import", raw, "--preset", "mrdlab", "-o", out)
    assert_error(res, fragment)
    assert out.read_text() == "keep me\n"


def test_one_bad_file_among_many_writes_nothing(tmp_path):
    bad = tmp_path / "bad.txt"
    bad.write_text("% header\n")
    outdir = tmp_path / "out"
    outdir.mkdir()
    res = invoke("import", LOAD41, bad, "--preset", "mrdlab", "--out-dir", outdir)
    assert_error(res, "no data rows")
    assert list(outdir.iterdir()) == []


def test_missing_input_and_overwrite_of_input(tmp_path):
    assert_error(invoke("import", tmp_path / "nope.txt", "--preset", "mrdlab", "-o", tmp_path / "o.csv"),
                 "no such file")
    raw = tmp_path / "raw.TXT.gz"
    shutil.copy(LOAD41, raw)
    assert_error(invoke("import", raw, "--preset", "mrdlab", "-o", raw), "refusing to overwrite an input")
    assert raw.read_bytes() == LOAD41.read_bytes()


def test_time_repair_drop_via_cli(tmp_path):
    raw = tmp_path / "raw.txt"
    raw.write_text("% h\n0.0,0,0,0.1,0\n0.001,1,0,0.1,-1\n0.001,2,0,0.1,-2\n0.002,3,0,0.1,-3\n")
    out = tmp_path / "o.csv"
    res = invoke("import", raw, "--preset", "mrdlab", "--time-repair", "drop", "-o", out)
    assert res.exit_code == 0, res.output
    assert "1 dropped" in res.stdout
    # no header sentence: the preset's catheter template cannot be filled, a warning says so
    assert "catheter" in res.stderr and "left out" in res.stderr
    assert "catheter" not in read_run(out).meta
    np.testing.assert_array_equal(read_run(out)["t"], [0.0, 0.001, 0.002])


@pytest.mark.parametrize("args", [
    [],                                                          # no output at all
    ["--preset", "mrdlab"],                                      # no -o nor --out-dir
    ["--preset", "mrdlab", "--zero", "median", "-o", "x.csv"],   # not a zero mode
    ["--preset", "mrdlab", "--resample", "-5", "-o", "x.csv"],
    ["--preset", "mrdlab", "--mapping", "m.json", "-o", "x.csv"],
    ["--preset", "mrdlab", "--format", "latex", "-o", "x.csv"],
])
def test_usage_errors_exit_2(tmp_path, args):
    res = invoke("import", LOAD41, *args)
    assert res.exit_code == 2, res.output


def test_many_inputs_need_out_dir_and_distinct_names(tmp_path):
    res = invoke("import", LOAD41, PITCH3, "--preset", "mrdlab", "-o", tmp_path / "x.csv")
    assert res.exit_code == 2
    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir()
    b.mkdir()
    shutil.copy(LOAD41, a / "41.TXT.gz")
    shutil.copy(LOAD41, b / "41.TXT.gz")
    res = invoke("import", a / "41.TXT.gz", b / "41.TXT.gz", "--preset", "mrdlab", "--out-dir", tmp_path)
    assert res.exit_code == 2
    assert "would both be written" in res.output


def test_help_has_an_example():
    res = invoke("import", "--help")
    assert res.exit_code == 0
    assert "hyst import" in res.stdout and "--preset" in res.stdout
