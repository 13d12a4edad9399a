"""`hyst evaluate` through the command line: formats, output files, plots, bad input.

Runs are tiny CSVs written here; the expected figures are worked out by hand in the comments.
"""
from __future__ import annotations

import csv
import io
import json

import pytest
from typer.testing import CliRunner

from hystcli.cli import app

runner = CliRunner()

# Two controllers, one trial each, r = [0, 10, 20, 10]:
#   none: y = [3, 14, 20, 10] -> e = [3, 4, 0, 0]: PTPE 4, RMSE sqrt(25/4) = 2.5
#   comp: y = [1, 9, 21, 9]   -> e = [1, -1, 1, -1]: PTPE 2, RMSE 1
#   comp vs none: PTPE (4 - 2)/4*100 = 50 %, RMSE (2.5 - 1)/2.5*100 = 60 %
NONE_CSV = """# catheter: ice-a
# controller: none
# shape: alpha=45,theta=0
# motion: periodic
# trial: 1
t,q1,r1,y1
0,0,0,3
0.01,10,10,14
0.02,20,20,20
0.03,10,10,10
"""
COMP_CSV = NONE_CSV.replace("controller: none", "controller: comp").replace(
    "0,0,0,3\n0.01,10,10,14\n0.02,20,20,20\n0.03,10,10,10", "0,0,0,1\n0.01,10,10,9\n0.02,20,20,21\n0.03,10,10,9")


@pytest.fixture
def runs(tmp_path):
    a, b = tmp_path / "none.csv", tmp_path / "comp.csv"
    a.write_text(NONE_CSV)
    b.write_text(COMP_CSV)
    return [str(a), str(b)]


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def test_help_has_an_example():
    res = invoke("evaluate", "--help")
    assert res.exit_code == 0
    assert "Example" in res.output and "hyst evaluate" in res.output


def test_table_on_stdout(runs):
    res = invoke("evaluate", *runs)
    assert res.exit_code == 0, res.output
    # a table wider than 100 columns comes in slices, each beginning with the key columns (3 here)
    rows: dict = {}
    for line in res.stdout.splitlines():
        if line[:5] in ("none ", "comp "):
            parts = line.split()
            rows.setdefault(parts[0], parts[:3]).extend(parts[3:])
    # controller shape motion n PTPE-mean PTPE-std RMSE-mean RMSE-std vs-none(PTPE, RMSE) vs-comp
    assert rows["none"][3:8] == ["1", "4.00", "-", "2.50", "-"]
    assert rows["comp"][3:10] == ["1", "2.00", "-", "1.00", "-", "50.00", "60.00"]


def test_json_and_csv_and_markdown(runs):
    res = invoke("evaluate", *runs, "--format", "json")
    assert res.exit_code == 0
    data = json.loads(res.stdout)
    comp = next(g for g in data["groups"] if g["key"]["controller"] == "comp")
    assert comp["improvement"]["none"] == {"ptpe": pytest.approx(50.0), "rmse": pytest.approx(60.0)}
    assert {(r["controller"], r["ptpe"], r["rmse"]) for r in data["runs"]} == {("none", 4.0, 2.5), ("comp", 2.0, 1.0)}

    res = invoke("evaluate", *runs, "-f", "csv")
    rows = list(csv.DictReader(io.StringIO(res.stdout)))
    assert [(r["controller"], float(r["ptpe_mean"]), float(r["rmse_mean"])) for r in rows] == [
        ("none", 4.0, 2.5), ("comp", 2.0, 1.0)]
    assert float(rows[1]["ptpe_improvement_vs_none"]) == pytest.approx(50.0)

    res = invoke("evaluate", *runs, "-f", "markdown")
    assert "| comp | alpha=45,theta=0 | periodic | 1 | 2.00 | - | 1.00 | - | 50.00 | 60.00 | - | - |" in res.stdout


def test_latex_to_file_and_plot(runs, tmp_path):
    out, fig = tmp_path / "table.tex", tmp_path / "fig.png"
    res = invoke("evaluate", *runs, "-f", "latex", "-o", out, "--plot", fig)
    assert res.exit_code == 0, res.output
    assert res.stdout == ""  # the result went to the file
    tex = out.read_text()
    assert r"$\alpha = 45^\circ$" in tex
    assert r"Compensation-Only (deg) & (2.0, -) & (1.0, -)" in tex
    assert r"Improvement rate ($\%$) & 50.0 & 60.0" in tex
    assert fig.read_bytes()[:4] == b"\x89PNG"


def test_group_by_and_per_run(runs):
    # everything pooled: PTPE [4, 2] -> mean 3, sample std sqrt((1 + 1)/1) = 1.41
    res = invoke("evaluate", *runs, "--group-by", "motion")
    line = next(line for line in res.stdout.splitlines() if line.startswith("periodic"))
    assert line.split() == ["periodic", "2", "3.00", "1.41", "1.75", "1.06"]  # RMSE [2.5, 1] -> 1.75, 1.06
    res = invoke("evaluate", *runs, "--per-run", "-f", "csv")
    rows = list(csv.DictReader(io.StringIO(res.stdout)))
    assert [(r["source"].endswith("none.csv"), float(r["ptpe"])) for r in rows] == [(True, 4.0), (False, 2.0)]


def test_missing_metadata_warns_and_works(tmp_path):
    p = tmp_path / "bare.csv"
    p.write_text("t,r1,y1\n0,0,3\n1,10,14\n2,20,20\n3,10,10\n")
    res = invoke("evaluate", p, "-f", "json")
    assert res.exit_code == 0
    assert json.loads(res.stdout)["groups"][0]["key"] == {"controller": "unknown", "shape": "unknown",
                                                          "motion": "unknown"}
    assert "Warning:" in res.stderr


BAD = {
    "empty": ("", "empty"),
    "missing_column": ("t,q1,y1\n0,0,1\n1,1,2\n", "'r1'"),
    "nan": ("t,r1,y1\n0,0,1\n1,1,nan\n", "NaN"),
    "non_increasing_t": ("t,r1,y1\n0,0,1\n1,1,2\n1,2,3\n", "'t'"),
    "text": ("t,r1,y1\n0,0,1\n1,abc,2\n", "abc"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_input_exit_1_one_line_no_output(runs, tmp_path, case):
    text, needle = BAD[case]
    bad = tmp_path / f"{case}.csv"
    bad.write_text(text)
    out, fig = tmp_path / "out.txt", tmp_path / "fig.png"
    res = invoke("evaluate", runs[0], bad, "-o", out, "--plot", fig)
    assert res.exit_code == 1
    assert res.stderr.startswith("Error: ") and len(res.stderr.strip().splitlines()) == 1
    assert needle in res.stderr and bad.name in res.stderr
    assert "Traceback" not in res.output
    assert not out.exists() and not fig.exists()


def test_missing_file(tmp_path, runs):
    out = tmp_path / "out.txt"
    res = invoke("evaluate", runs[0], tmp_path / "nope.csv", "-o", out)
    assert res.exit_code == 1 and "nope.csv" in res.stderr and "Error: " in res.stderr
    assert not out.exists()


def test_refuses_to_overwrite_an_input(runs):
    before = open(runs[0]).read()
    res = invoke("evaluate", *runs, "-o", runs[0])
    assert res.exit_code == 1 and "input" in res.stderr
    assert open(runs[0]).read() == before


@pytest.mark.parametrize("args", [
    ["evaluate"],                                   # no runs
    ["evaluate", "{run}", "--format", "xml"],
    ["evaluate", "{run}", "--group-by", "colour"],
    ["evaluate", "{run}", "--plot", "fig.gif"],
])
def test_usage_errors_exit_2(runs, args):
    res = invoke(*[a.format(run=runs[0]) for a in args])
    assert res.exit_code == 2, res.output
