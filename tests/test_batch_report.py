"""`hyst report`: summaries per group, drift over time, outliers by median and MAD."""
from __future__ import annotations

import json

import pandas as pd
import pytest
from typer.testing import CliRunner

pytest.importorskip("pyarrow")

from hystcli.batch import report as R  # noqa: E402
from hystcli.batch import table as T  # noqa: E402
from hystcli.cli import app  # noqa: E402

runner = CliRunner()


def frame() -> pd.DataFrame:
    # two robots, six days each; robot R1's RMSE rises 0.5 deg a day; one run (day 4 of R2) is off by far
    rows = []
    for i in range(12):
        robot, day = ("R1", "R2")[i % 2], i // 2 + 1
        rmse = 1.0 + 0.5 * (day - 1) if robot == "R1" else 1.0 + 0.01 * i
        if robot == "R2" and day == 4:
            rmse = 40.0
        rows.append({"path": f"r{i:02d}.csv", "status": "ok", "command": "evaluate", "manifest_robot": robot,
                     "manifest_day": f"2026-03-{day:02d}", "k1_rmse": rmse, "k1_ptpe": 2 * rmse})
    rows.append({"path": "bad.csv", "status": "refused", "command": "evaluate", "reason": "empty file",
                 "manifest_robot": "R1", "manifest_day": "2026-03-01"})
    return pd.DataFrame(rows)


def test_summary_drift_and_outliers_by_hand():
    rep = R.report(frame(), by="manifest_robot", time="manifest_day")
    assert set(rep.values) == {"k1_rmse", "k1_ptpe"}
    s = {r["group"]: r for r in rep.summary}
    assert (s["R1"]["runs"], s["R1"]["failed"], s["R2"]["failed"]) == (7, 1, 0)
    assert s["R1"]["k1_rmse_mean"] == pytest.approx(sum(1 + 0.5 * d for d in range(6)) / 6)  # the bad run is left out
    d = {(x["group"], x["value"]): x for x in rep.drift}
    assert d[("R1", "k1_rmse")]["slope"] == pytest.approx(0.5) and d[("R1", "k1_rmse")]["unit"] == "per day"
    assert (d[("R1", "k1_rmse")]["first"], d[("R1", "k1_rmse")]["last"]) == (1.0, 3.5)
    # the one far run is flagged on both columns, nothing else: R1's drift (up to 3.5) is within 3.5 MADs
    assert {(o["path"], o["value"]) for o in rep.outliers} == {("r07.csv", "k1_rmse"), ("r07.csv", "k1_ptpe")}
    z, med, mad = R.robust_z([1.0, 2.0, 3.0, 4.0, 100.0])
    assert (med, mad) == (3.0, 1.0) and z[-1] == pytest.approx(0.6745 * 97)


def test_a_constant_column_flags_nothing_and_says_why():
    df = frame()
    df["k1_rmse"] = 1.0
    rep = R.report(df, values=["k1_rmse"])
    assert not rep.outliers and any("MAD is 0" in n for n in rep.notes)


def test_bad_columns_are_errors_naming_them():
    with pytest.raises(R.DataError, match="no column 'meta_nothing'"):
        R.report(frame(), by="meta_nothing")
    with pytest.raises(R.DataError, match="not numeric"):
        R.report(frame(), values=["manifest_robot"])


def test_report_command_over_a_written_table(tmp_path):
    df = frame()
    path = tmp_path / "t.parquet"
    T.write_table(T.arrow_table(df.where(df.notna(), None).to_dict("records")), path)
    r = runner.invoke(app, ["report", str(path), "--by", "manifest_robot", "--time", "manifest_day",
                            "-o", str(tmp_path / "drift.png"), "-f", "json"])
    assert r.exit_code == 0, r.output
    rep = json.loads(r.stdout)
    assert rep["runs"] == 13 and rep["ok"] == 12 and rep["outliers"][0]["path"] == "r07.csv"
    assert (tmp_path / "drift.png").read_bytes()[:4] == b"\x89PNG"
    r = runner.invoke(app, ["report", str(path)])
    assert r.exit_code == 0 and "r07.csv" in r.stdout and "Iglewicz" in r.stdout
    r = runner.invoke(app, ["report", str(path), "-o", str(tmp_path / "x.png")])
    assert r.exit_code == 2 and "--time" in r.output
    (tmp_path / "junk.parquet").write_text("not a table")
    r = runner.invoke(app, ["report", str(tmp_path / "junk.parquet")])
    assert r.exit_code == 1 and r.stderr.startswith("Error: ") and "not a readable results table" in r.stderr
