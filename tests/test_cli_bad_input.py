"""Issue 12, "Bad input, no tracebacks": one test per case of the issue's list.

Every case gives exit 1 and one line ``Error: ...`` naming the file for bad data, or exit 2 and
one ``Error:`` line (under typer's usage line) for a usage error; never a traceback, never an
output file. (The cases of `detect-shift --port`, `compensate` and `play` are tested with those
commands.)
"""
from __future__ import annotations

import json
import re
import shlex
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from hystcli.cli import app
from hystcli.core.run import Run
from hystcli.io import model_to_dict, read_run, save_model, write_run
from hystcli.core.model import Model
from hystcli.core.params import Geometry, KnobModel

runner = CliRunner()
ROOT = Path(__file__).resolve().parents[1]
SWEEP = ROOT / "sample_data" / "ice-a" / "sweep_knob1.csv"
EXAMPLE = dict(d_pos=9.1, d_neg=-8.7, b_pos=6.2, b_neg=5.9, omega=1.45, h_pos=-4.0, h_neg=4.2)


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def data_error(res, *fragments):
    """Exit 1, exactly one line on stderr, ``Error: ...`` with every fragment, no traceback."""
    assert res.exit_code == 1, res.output
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("Error: "), res.stderr
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    assert "Traceback" not in res.output and "np.float64" not in res.output
    return lines[0]


def usage_error(res, *fragments):
    """Exit 2, one ``Error:`` line with every fragment, no traceback."""
    assert res.exit_code == 2, res.output
    errors = [ln for ln in res.output.splitlines() if ln.startswith("Error")]
    assert len(errors) == 1, res.output
    for fragment in fragments:
        assert fragment in errors[0], (fragment, errors[0])
    assert "Traceback" not in res.output
    return errors[0]


@pytest.fixture
def runs(tmp_path):
    t = np.arange(0, 20, 0.01)
    r = 30 * np.sin(2 * np.pi * 0.1 * t)
    paths = []
    for ctrl, gain in (("none", 0.7), ("comp", 0.95)):
        p = tmp_path / f"run_{ctrl}.csv"
        write_run(p, Run({"t": t, "r1": r, "q1": r, "y1": gain * r},
                         {"controller": ctrl, "shape": "straight", "motion": "periodic"}))
        paths.append(p)
    return paths


def with_cell(src: Path, dst: Path, column: str, row: int, value: str) -> Path:
    """A copy of the run CSV ``src`` with one cell replaced (as a text edit: what a corrupt file is)."""
    lines = src.read_text().splitlines()
    head = next(i for i, ln in enumerate(lines) if not ln.startswith("#"))
    cells = lines[head + 1 + row].split(",")
    cells[lines[head].split(",").index(column)] = value
    lines[head + 1 + row] = ",".join(cells)
    dst.write_text("\n".join(lines) + "\n")
    return dst


# -- tracebacks today ---------------------------------------------------------------------------
def test_identify_refuses_1e308_in_a_run(tmp_path):
    bad = with_cell(SWEEP, tmp_path / "big.csv", "y1", 100, "1e308")
    res = invoke("identify", bad, "-o", tmp_path / "m.json")
    data_error(res, str(bad), "column 'y1'", "1e+308 is beyond")
    assert not (tmp_path / "m.json").exists()


def test_evaluate_json_refuses_1e308_in_a_run(runs, tmp_path):
    bad = with_cell(runs[0], tmp_path / "big.csv", "y1", 5, "-1e308")
    res = invoke("evaluate", bad, runs[1], "-f", "json", "-o", tmp_path / "e.json")
    data_error(res, str(bad), "column 'y1', line")
    assert res.stdout == "" and not (tmp_path / "e.json").exists()


def test_simulate_refuses_a_segment_bent_1e9_degrees(tmp_path):
    res = invoke("simulate", "--shape", "alpha=1e9", "-o", tmp_path / "s.csv")
    usage_error(res, "--shape", "|alpha| <= 360 deg")
    assert not (tmp_path / "s.csv").exists()


def test_rotate_shift_refuses_an_infinite_rotation(tmp_path):
    save_model(tmp_path / "m.json", Model({1: KnobModel(**EXAMPLE)}))
    res = invoke("rotate-shift", "--model", tmp_path / "m.json", "--degrees", "1e309", "-o", tmp_path / "r.json")
    usage_error(res, "--degrees", "finite")
    assert not (tmp_path / "r.json").exists()


# -- silently accepted today ----------------------------------------------------------------------
def test_a_model_with_d_pos_1e308_is_refused(runs, tmp_path):
    d = model_to_dict(Model({1: KnobModel(**EXAMPLE)}))
    d["knobs"]["1"]["d_pos"] = 1e308
    (tmp_path / "m.json").write_text(json.dumps(d))
    res = invoke("predict", runs[0], "--model", tmp_path / "m.json", "-o", tmp_path / "p.csv")
    data_error(res, str(tmp_path / "m.json"), "d_pos = 1e+308 is beyond")
    assert not (tmp_path / "p.csv").exists()


def test_hyst_never_writes_a_run_it_would_refuse(tmp_path):
    # `simulate` once wrote an empty current (NaN) that read_run then rejected: the writer refuses
    run = Run({"t": [0.0, 0.1, 0.2], "q1": [0.0, 1.0, 2.0], "c1": [120.0, np.nan, 121.0]})
    with pytest.raises(Exception, match="refusing to write column 'c1', sample 1: NaN"):
        write_run(tmp_path / "r.csv", run)
    assert list(tmp_path.iterdir()) == []
    # and every motion hyst simulate makes reads back, current included
    for motion, knobs in (("sweep", "1,2"), ("periodic", "2"), ("nonperiodic", "1,2")):
        out = tmp_path / f"{motion}.csv"
        res = invoke("simulate", "--motion", motion, "--knobs", knobs, "--effect", "contact", "-o", out, "-q")
        assert res.exit_code == 0, res.output
        back = read_run(out)
        assert all(np.isfinite(back[f"c{k}"]).all() for k in back.knobs("c"))


# -- files Excel and others write ----------------------------------------------------------------
def test_a_utf8_bom_csv_reads(runs, tmp_path):
    bom = tmp_path / "excel.csv"
    bom.write_bytes(b"\xef\xbb\xbf" + runs[0].read_bytes())
    assert read_run(bom).t.size == read_run(runs[0]).t.size
    res = invoke("evaluate", bom, runs[1], "-f", "csv")
    assert res.exit_code == 0, res.output


def test_a_semicolon_csv_gets_the_import_command_that_converts_it(tmp_path):
    semi = tmp_path / "semi.csv"
    semi.write_text("# catheter: x\nt;q1;y1;c1\n0;0;0;120\n0,1;1;0,5;121\n")
    res = invoke("identify", semi, "-o", tmp_path / "m.json")
    line = data_error(res, str(semi), "separated by semicolons",
                      "hyst import", "--sep ';' --skip 2 --map t=1,q1=2,y1=3,c1=4")
    assert not (tmp_path / "m.json").exists()
    # the hint is a command that works (here the decimal commas are then the file's next problem)
    command = shlex.split(re.search(r"`hyst (import .*?)`", line).group(1))
    fixed = invoke(*command[:-1], tmp_path / "converted.csv")
    assert fixed.exit_code == 1 and "'0,1' is not a number" in fixed.stderr


# -- messages -------------------------------------------------------------------------------------
def test_messages_show_plain_numbers_and_name_the_file(tmp_path):
    bad = tmp_path / "back.csv"
    bad.write_text("t,q1,y1\n0,0,0\n0.099,1,1\n0.05,2,2\n")
    line = data_error(invoke("predict", bad, "--model", tmp_path / "m.json", "-o", tmp_path / "p.csv"))
    assert "no such model file" in line  # the model is read first
    save_model(tmp_path / "m.json", Model({1: KnobModel(**EXAMPLE)}))
    line = data_error(invoke("predict", bad, "--model", tmp_path / "m.json", "-o", tmp_path / "p.csv"),
                      str(bad), "(0.099 then 0.05)")
    # an error found deep in the core names the input file too
    fast = tmp_path / "fast.csv"
    write_run(fast, Run({"t": np.arange(400) * 1e-9, "q1": 30 * np.sin(np.arange(400) / 20), "c1": np.zeros(400)}))
    data_error(invoke("simulate", "--commands", fast, "-o", tmp_path / "f.csv"), str(fast), "sample rate 1e+09 Hz")


def test_messages_never_show_a_temporary_file(tmp_path, monkeypatch):
    import os

    real = os.replace

    def full_disk(src, dst):
        raise OSError(28, "No space left on device", src)

    # the same command once first, so numba's kernels are compiled and cached: numba writes its
    # cache through os.replace as well, and on a fresh checkout this test would otherwise see the
    # full disk in numba's cache file, not in our output (order-dependent: it failed once that way)
    assert invoke("simulate", "--motion", "periodic", "-o", tmp_path / "warm.csv").exit_code == 0
    (tmp_path / "warm.csv").unlink()
    monkeypatch.setattr(os, "replace", full_disk)
    res = invoke("simulate", "--motion", "periodic", "-o", tmp_path / "s.csv")
    monkeypatch.setattr(os, "replace", real)
    line = data_error(res, str(tmp_path / "s.csv"), "No space left on device")
    assert ".tmp" not in line
    assert list(tmp_path.iterdir()) == []  # and the temporary file is gone


# -- outputs that collide -------------------------------------------------------------------------
def test_identify_output_and_plot_on_one_path_is_a_usage_error(tmp_path):
    res = invoke("identify", SWEEP, "-o", tmp_path / "x", "--plot", tmp_path / "x")
    usage_error(res, "--output and --plot name the same file")
    assert not (tmp_path / "x").exists()


def test_evaluate_output_and_plot_on_one_path_is_a_usage_error(runs, tmp_path):
    res = invoke("evaluate", *runs, "-o", tmp_path / "x.png", "--plot", tmp_path / "x.png")
    usage_error(res, "--output and --plot name the same file")
    assert not (tmp_path / "x.png").exists()


def test_the_same_run_given_twice_is_a_usage_error(runs, tmp_path):
    # refused, not counted once: a repeated name is usually a typo for another run
    res = invoke("evaluate", runs[0], runs[1], str(runs[0]).replace("/run_", "/./run_"), "-o", tmp_path / "e.txt")
    usage_error(res, "are the same file")
    assert not (tmp_path / "e.txt").exists()


def test_a_shape_key_given_twice_is_a_usage_error(tmp_path):
    res = invoke("simulate", "--shape", "alpha=90,alpha=45", "-o", tmp_path / "s.csv")
    usage_error(res, "alpha is given twice", "segments are separated by ';'")
    assert not (tmp_path / "s.csv").exists()


# -- usage errors found after parsing exit 2 -------------------------------------------------------
@pytest.mark.parametrize("args, fragment", [
    (["simulate", "--shape", "alpha=abc"], "'abc' is not a number"),
    (["simulate", "--knobs", "3"], "expected 1, 2 or 1,2"),
    (["simulate", "--effect", "stiction"], "unknown effect"),
    (["identify", SWEEP, "--beta-catheter-mm", "-1", "--beta-knob-mm", "6"], "beta_catheter_mm > 0"),
    (["identify", SWEEP, "--omega", "inf"], "--omega"),
    (["evaluate", SWEEP, "--group-by", "colour"], "colour"),
    (["demo", "--simulate", "--data", "sample_data"], "--data DIR or --simulate"),
])
def test_option_values_found_wrong_after_parsing_exit_2(tmp_path, args, fragment):
    out = tmp_path / "out"
    res = invoke(*args, *(["-o", out] if args[0] in ("simulate", "identify") else []))
    usage_error(res, fragment)
    assert not out.exists()


# -- options that were ignored -------------------------------------------------------------------
@pytest.mark.parametrize("fmt, marker", [("csv", "knob,parameter,value,lo,hi,fixed"), ("markdown", "| knob |"),
                                         ("latex", r"\begin{tabular}"), ("json", '"params"')])
def test_identify_format_is_honoured(tmp_path, fmt, marker):
    res = invoke("identify", SWEEP, "--current-only", "-o", tmp_path / "m.json", "--format", fmt)
    assert res.exit_code == 0, res.output
    assert marker in res.stdout
    if fmt == "csv":
        rows = res.stdout.splitlines()
        assert len(rows) == 1 + 7 and rows[1].startswith("1,d_pos,")


def test_evaluate_quiet_prints_nothing_but_writes(runs, tmp_path):
    res = invoke("evaluate", *runs, "-q")
    assert res.exit_code == 0 and res.stdout == "" and res.stderr == ""
    res = invoke("evaluate", *runs, "-q", "-o", tmp_path / "t.txt")
    assert res.exit_code == 0 and res.stdout == "" and res.stderr == ""
    assert "none" in (tmp_path / "t.txt").read_text()
    # a machine format asked for is still printed
    assert invoke("evaluate", *runs, "-q", "-f", "csv").stdout.startswith("controller,")
