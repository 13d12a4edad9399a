"""`hyst demo` on the command line: output, files, bad input."""
from __future__ import annotations

import json

import pytest

from typer.testing import CliRunner

from hystcli.cli import app

runner = CliRunner()


def test_missing_data_dir_is_one_error_line_and_writes_nothing(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    res = runner.invoke(app, ["demo", "--data", "nowhere", "--out", "out"])
    assert res.exit_code == 1
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("Error: nowhere: no such data directory")
    assert "Traceback" not in res.output
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_demo_runs_from_a_folder_without_sample_data(tmp_path, monkeypatch):
    # an installed hyst has no sample_data/: the demo records the same data from the twin (issue 12)
    monkeypatch.chdir(tmp_path)
    res = runner.invoke(app, ["demo", "--trials", "1", "--no-diagnose", "--no-figures", "--format", "json",
                              "--out", "out"])
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    assert data["config"]["data"] == "twin (simulated recordings, seed 0)"  # the sample data's seed
    assert data["config"]["input_files"] == []
    assert "no sample_data/ in this folder" in res.stderr
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["results.json", "tables.md"]
    # the progress shows as plain lines when stderr is not a terminal, never with an unknown total
    steps = [ln for ln in res.stderr.splitlines() if ln.startswith("[")]
    assert steps and steps[0].startswith("[1/") and "None" not in res.stderr
    total = steps[0].split("/")[1].split("]")[0]
    assert steps[-1].startswith(f"[{total}/{total}]")


def test_out_that_is_a_file_is_an_error(tmp_path):
    target = tmp_path / "file.txt"
    target.write_text("keep me")
    res = runner.invoke(app, ["demo", "--simulate", "--trials", "1", "--out", str(target)])
    assert res.exit_code == 1
    assert res.stderr.startswith("Error: ") and "not a directory" in res.stderr
    assert target.read_text() == "keep me"


def test_usage_error_exits_2(tmp_path):
    res = runner.invoke(app, ["demo", "--trials", "0", "--out", str(tmp_path / "o")])
    assert res.exit_code == 2
    res = runner.invoke(app, ["demo", "--format", "latex", "--out", str(tmp_path / "o")])
    assert res.exit_code == 2


@pytest.mark.slow
def test_demo_json_and_files(tmp_path):
    out = tmp_path / "o"
    res = runner.invoke(app, ["demo", "--simulate", "--trials", "1", "--format", "json", "--out", str(out),
                              "--no-figures", "--quiet"])
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    assert data["format"] == "hyst-demo" and data["config"]["trials"] == 1
    assert [c["controller"] for c in data["table_II"]] == ["none", "comp", "comp+shift", "comp+shift+diag"]
    beyond = data["beyond_paper"]
    assert [d["catheter"] for d in beyond["diagnoses"]] == ["ice-a", "ice-b"]
    # targets: half the paper's Compensation+Shift RMSE (Kim & Mansi, Tables I and II)
    assert [t["target"] for t in beyond["targets"]] == pytest.approx([3.95, 4.0, 5.05])
    assert sorted(beyond["augmented_models"]) == ["ice-a", "ice-b"]
    cell = data["table_I"][0]
    assert cell["paper"]["source"] == "Kim & Mansi, Table I"
    assert cell["ratio"]["ptpe"] == cell["ptpe"]["mean"] / cell["paper"]["ptpe"]["mean"]
    # stdout and the results file are the same JSON; no figure asked for
    assert json.loads((out / "results.json").read_text()) == data
    assert sorted(p.name for p in out.iterdir()) == ["results.json", "tables.md"]
    assert res.stderr == ""  # --quiet


@pytest.mark.slow
def test_demo_markdown_shows_paper_beside_ours(tmp_path):
    res = runner.invoke(app, ["demo", "--simulate", "--trials", "1", "--format", "markdown",
                              "--out", str(tmp_path / "o"), "--no-figures"])
    assert res.exit_code == 0, res.output
    text = res.stdout
    assert "**Table I: PTPE and RMSE for 1-DoF, periodic inputs**" in text
    assert "**Table II" in text
    # the paper's No Compensation straight cell, Kim & Mansi Table I: (57.2, 4.2) and (18.5, 3.4)
    row = next(ln for ln in text.splitlines() if ln.startswith("| No Compensation | straight |"))
    assert "(57.2, 4.2)" in row and "(18.5, 3.4)" in row
    assert "paper values matched within 30%" in text
    assert "**Beyond the paper: Compensation+Shift (C+S) with the model `hyst diagnose` augmented**" in text
    # the paper's Compensation+Shift at alpha=45 (Kim & Mansi Table I: RMSE (7.9, 1.3)), target 7.9 / 2
    row = next(ln for ln in text.splitlines() if ln.startswith("| alpha=45 | (7.9, 1.3) |"))
    assert "<= 3.95" in row
    # Algorithm 1's detections, with the true edge beside the found one
    assert "**Algorithm 1 on the replays**" in text and "| edge error |" in text
    assert "demo took" in res.stderr


@pytest.mark.slow
def test_demo_without_diagnosis_has_only_the_papers_tables(tmp_path):
    res = runner.invoke(app, ["demo", "--simulate", "--trials", "1", "--no-diagnose", "--out",
                              str(tmp_path / "o"), "--no-figures"])
    assert res.exit_code == 0, res.output
    assert "Table II" in res.stdout and "Beyond the paper" not in res.stdout
    # -q: nothing but errors (the tables are in the --out folder)
    res = runner.invoke(app, ["demo", "--simulate", "--trials", "1", "--no-diagnose", "--out",
                              str(tmp_path / "q"), "--no-figures", "-q"])
    assert res.exit_code == 0, res.output
    assert res.stdout == "" and res.stderr == ""
    assert "Table II" in (tmp_path / "q" / "tables.md").read_text()
