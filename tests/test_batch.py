"""`hyst batch`: one row per run, bad runs as rows, resume without recomputing, engines that agree.

The runs are small synthetic CSVs written here (t, q1, y1, r1 and metadata); `hyst batch
evaluate` on them costs milliseconds per task, so what these tests time is the engines, not the
fits. Local batches run on real spawned processes; the cluster tests in
``test_batch_cluster.py`` run on a real ``distributed.LocalCluster``.
"""
from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

pytest.importorskip("pyarrow")  # the batch extra is part of [test]; a bare install has its own test below
import pyarrow.parquet as pq  # noqa: E402

from hystcli.batch import core  # noqa: E402
from hystcli.batch import table as T  # noqa: E402
from hystcli.cli import app  # noqa: E402

runner = CliRunner()


def write_run(path: Path, seed: int, rows: int = 400, catheter: str = "ice-a", controller: str = "none",
              trial: int = 1, bias: float = 0.0) -> Path:
    """A run whose error y - r is seeded noise plus ``bias`` (deg)."""
    rng = np.random.default_rng(seed)
    t = np.arange(rows) * 0.01
    r = 30 * np.sin(2 * np.pi * 0.2 * t)
    y = r + bias + rng.normal(0, 1.0, rows)
    body = "\n".join(f"{a:.3f},{b:.4f},{c:.4f},{b:.4f}" for a, b, c in zip(t, r, y))
    path.write_text(f"# catheter: {catheter}\n# controller: {controller}\n# shape: straight\n# motion: periodic\n"
                    f"# trial: {trial}\nt,q1,y1,r1\n{body}\n")
    return path


BAD = {
    "empty.csv": "",
    "blank.csv": "\n\n",
    "header_only.csv": "t,q1,y1,r1\n",
    "nan.csv": "t,q1,y1,r1\n0,0,nan,0\n0.01,1,1,1\n0.02,2,2,2\n",
    "wrong_columns.csv": "t,a,b\n0,1,2\n0.01,2,3\n",
    "text_cell.csv": "t,q1,y1,r1\n0,0,0,0\n0.01,x,1,1\n",
    "time_back.csv": "t,q1,y1,r1\n0,0,0,0\n0.02,1,1,1\n0.01,2,2,2\n",
    "binary.csv": b"\xff\xfe\x00\x01garbage".decode("latin-1"),
    "no_reference.csv": "t,q1,y1\n0,0,0\n0.01,1,1\n",
    "bad_shape.csv": "# shape: banana\nt,q1,y1,r1\n0,0,0,0\n0.01,1,1,1\n",
}


@pytest.fixture
def mixed(tmp_path):
    """3 good runs and the 10 bad ones of :data:`BAD` in ``runs/``."""
    d = tmp_path / "runs"
    d.mkdir()
    for i in range(3):
        write_run(d / f"good{i}.csv", seed=i, trial=i + 1)
    for name, text in BAD.items():
        (d / name).write_bytes(text.encode("latin-1"))
    return d


def rows(path: Path) -> list[dict]:
    return pq.read_table(path).to_pylist() if path.suffix == ".parquet" else __import__("csv").DictReader(
        path.open())


def test_ten_bad_runs_are_ten_rows_with_reasons_and_the_batch_exits_0(mixed, tmp_path):
    out = tmp_path / "res.parquet"
    r = runner.invoke(app, ["batch", "evaluate", str(mixed / "*.csv"), "-o", str(out), "-j", "1", "-f", "json"])
    assert r.exit_code == 0, r.output
    summary = json.loads(r.stdout)
    assert (summary["runs"], summary["failed"], summary["computed"]) == (13, 10, 13)
    table = pq.read_table(out).to_pylist()
    assert [Path(x["path"]).name for x in table] == sorted(Path(x["path"]).name for x in table)  # sorted by path
    by = {Path(x["path"]).name: x for x in table}
    assert {n for n, x in by.items() if x["status"] != "ok"} == set(BAD)
    for name in BAD:
        assert by[name]["status"] == "refused" and by[name]["reason"], name
    assert "empty" in by["empty.csv"]["reason"]
    assert "NaN" in by["nan.csv"]["reason"] or "nan" in by["nan.csv"]["reason"].lower()
    assert "r1" in by["wrong_columns.csv"]["reason"] and "r1" in by["no_reference.csv"]["reason"]
    assert "UTF-8" in by["binary.csv"]["reason"]
    assert "banana" in by["bad_shape.csv"]["reason"]
    for i in range(3):
        g = by[f"good{i}.csv"]
        assert g["status"] == "ok" and g["reason"] is None and 0.5 < g["k1_rmse"] < 1.5
        assert g["meta_catheter"] == "ice-a" and g["meta_trial"] == str(i + 1)
        assert g["sha256"] == hashlib.sha256((mixed / f"good{i}.csv").read_bytes()).hexdigest()
    # --strict: the same failures exit 1 (and nothing is computed again)
    r = runner.invoke(app, ["batch", "evaluate", str(mixed / "*.csv"), "-o", str(out), "--strict", "-f", "json"])
    assert r.exit_code == 1
    assert json.loads(r.stdout)["computed"] == 0 and "10 of 13 run(s) failed (--strict)" in r.stderr


def _parts(out: Path) -> dict[str, tuple[int, int]]:
    return {p.name: (p.stat().st_ino, p.stat().st_mtime_ns) for p in T.parts_dir(out).glob("*.json")}


def test_resume_after_ctrl_c_recomputes_nothing_that_was_done(tmp_path):
    d = tmp_path / "runs"
    d.mkdir()
    for i in range(10):
        write_run(d / f"r{i:02d}.csv", seed=100 + i)
    out = tmp_path / "res.parquet"
    pl = core.plan("evaluate", [str(d / "*.csv")])
    calls = []

    def ctrl_c_after_four(message, done, total):
        calls.append(done)
        if len(calls) == 4:
            raise KeyboardInterrupt  # what Ctrl-C raises in the client's loop

    first = core.run_batch(pl, out, jobs=2, progress=ctrl_c_after_four)
    assert first.interrupted and first.computed == 4 and not out.exists()
    before = _parts(out)
    assert len(before) == 4  # each finished task was written when it came back
    second = core.run_batch(pl, out, jobs=2)
    assert (second.skipped, second.computed, second.runs, second.failed) == (4, 6, 10, 0)
    after = _parts(out)
    assert len(after) == 10
    # the four parts of the first run are the same files, untouched: not one recomputed
    assert {k: after[k] for k in before} == before
    # and the table equals the one an uninterrupted batch writes, byte for byte
    fresh = tmp_path / "fresh.parquet"
    core.run_batch(pl, fresh, jobs=1)
    assert fresh.read_bytes() == out.read_bytes()


def test_a_killed_local_worker_is_retried_and_every_run_has_one_row(tmp_path):
    psutil = pytest.importorskip("psutil")
    d = tmp_path / "runs"
    d.mkdir()
    for i in range(12):
        write_run(d / f"r{i:02d}.csv", seed=200 + i)
    out = tmp_path / "res.parquet"
    killed = []

    def kill_a_worker(message, done, total):
        if killed:
            return
        # the pool's workers are the fork server's children
        server = [p for p in psutil.Process().children() if "forkserver" in " ".join(p.cmdline())]
        workers = [w for s in server for w in s.children()]
        assert workers
        workers[0].kill()
        killed.append(workers[0].pid)

    res = core.run_batch(core.plan("evaluate", [str(d / "*.csv")]), out, jobs=2, progress=kill_a_worker)
    assert killed and res.retried >= 1
    table = pq.read_table(out).to_pylist()
    assert sorted(x["path"] for x in table) == sorted(str(p) for p in d.glob("*.csv"))
    assert all(x["status"] == "ok" for x in table)
    timing = pq.read_table(T.timing_path(out)).to_pylist()
    assert len(timing) == 12 and sum(t["attempts"] > 1 for t in timing) == res.retried


def test_identical_files_are_one_task_and_each_keeps_its_row(tmp_path):
    d = tmp_path / "runs"
    d.mkdir()
    write_run(d / "a.csv", seed=1)
    (d / "copy_of_a.csv").write_bytes((d / "a.csv").read_bytes())
    write_run(d / "b.csv", seed=2)
    pl = core.plan("evaluate", [str(d / "*.csv")])
    assert len(pl.entries) == 3 and len(pl.tasks) == 2
    out = tmp_path / "res.csv"
    res = core.run_batch(pl, out, jobs=1)
    assert res.runs == 3 and res.computed == 2
    got = {Path(r["path"]).name: r for r in rows(out)}
    assert got["a.csv"]["k1_rmse"] == got["copy_of_a.csv"]["k1_rmse"] != got["b.csv"]["k1_rmse"]


def test_new_settings_or_a_changed_file_are_new_tasks(tmp_path):
    d = tmp_path / "runs"
    d.mkdir()
    run = write_run(d / "a.csv", seed=1)
    k1 = core.plan("identify", [str(run)]).tasks[0].key
    assert core.plan("identify", [str(run)], settings={"level": 0.9}).tasks[0].key != k1
    assert core.plan("identify", [str(run)]).tasks[0].key == k1  # same inputs, same key
    write_run(run, seed=2)
    assert core.plan("identify", [str(run)]).tasks[0].key != k1


def test_manifest_names_runs_models_and_extra_columns(tmp_path):
    d = tmp_path / "runs"
    d.mkdir()
    write_run(d / "a.csv", seed=1)
    write_run(d / "b.csv", seed=2)
    man = tmp_path / "manifest.csv"
    man.write_text("run,robot,day\nruns/a.csv,R1,2026-01-02\nruns/b.csv,R2,2026-01-03\nruns/missing.csv,R3,x\n")
    out = tmp_path / "res.parquet"
    r = runner.invoke(app, ["batch", "evaluate", "--manifest", str(man), "-o", str(out), "-j", "1", "-q"])
    assert r.exit_code == 0, r.output
    got = {Path(x["path"]).name: x for x in pq.read_table(out).to_pylist()}
    assert got["a.csv"]["manifest_robot"] == "R1" and got["b.csv"]["manifest_day"] == "2026-01-03"
    assert got["missing.csv"]["status"] == "refused" and "cannot read" in got["missing.csv"]["reason"]


def test_usage_errors(tmp_path):
    r = runner.invoke(app, ["batch", "evaluate", "-o", str(tmp_path / "x.parquet")])
    assert r.exit_code == 2 and "--manifest" in r.output
    r = runner.invoke(app, ["batch", "evaluate", str(tmp_path / "nothing*.csv"), "-o", str(tmp_path / "x.parquet")])
    assert r.exit_code == 1 and "no file matches" in r.stderr
    r = runner.invoke(app, ["batch", "detect-shift", str(tmp_path / "*.csv"), "-o", str(tmp_path / "x.parquet")])
    assert r.exit_code == 2 and "--model" in r.output


def test_a_missing_extra_is_one_line_naming_it(tmp_path, monkeypatch):
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "pyarrow" else real(name, *a))
    write_run(tmp_path / "a.csv", seed=1)
    r = runner.invoke(app, ["batch", "evaluate", str(tmp_path / "a.csv"), "-o", str(tmp_path / "x.parquet")])
    assert r.exit_code == 1
    assert r.stderr.strip() == "Error: hyst batch needs pyarrow: pip install 'hystcli[batch]'"


def test_the_table_is_sorted_typed_and_the_same_bytes_in_any_order(tmp_path):
    a = [{"path": "b", "status": "ok", "k1_x": 1.5, "k1_f": True, "k10_x": 2, "meta_z": "1", "k2_x": None},
         {"path": "a", "status": "refused", "reason": "bad", "k1_x": 1, "k1_f": None, "meta_z": None}]
    cols = T.column_order(a)
    assert cols[:len(T.IDENTITY)] == list(T.IDENTITY)
    assert cols[len(T.IDENTITY):] == ["meta_z", "k1_f", "k1_x", "k2_x", "k10_x"]
    t = T.arrow_table(sorted(a, key=lambda r: r["path"]))
    types = {f.name: str(f.type) for f in t.schema}
    assert (types["k1_x"], types["k1_f"], types["k10_x"], types["k2_x"]) == ("double", "bool", "int64", "string")
    T.write_table(t, tmp_path / "1.parquet")
    T.write_table(T.arrow_table(sorted(reversed(a), key=lambda r: r["path"])), tmp_path / "2.parquet")
    assert (tmp_path / "1.parquet").read_bytes() == (tmp_path / "2.parquet").read_bytes()


def test_a_part_is_whole_or_absent(tmp_path):
    folder = tmp_path / "p"
    T.write_part(folder, "k1", {"key": "k1", "rows": {}})
    (folder / "k2.json").write_text('{"key": "k2", "rows": {')  # torn by hand: not ours, ignored
    (folder / ".k3.123.tmp").write_text("{}")
    assert set(T.read_parts(folder)) == {"k1"}
    assert not [p for p in folder.iterdir() if p.suffix == ".tmp" and p.name.startswith(".k1")]


def test_imap_keeps_the_order_of_its_arguments():
    from hystcli.batch.engine import imap

    assert list(imap(abs, [-3, 1, -2, 5, -8], jobs=2)) == [3, 1, 2, 5, 8]


def test_the_batch_commands_help_fits_80_columns():
    for args in (["batch"], ["batch", "identify"], ["batch", "evaluate"], ["batch", "detect-shift"],
                 ["batch", "diagnose"], ["report"]):
        text = runner.invoke(app, [*args, "--help"], terminal_width=80).stdout
        assert "Usage:" in text and max(map(len, text.splitlines())) <= 80, args


def test_diagnose_sessions_by_a_metadata_key_across_folders(tmp_path):
    # two robots' runs mixed in one folder: only robot "a" has the tracker's 0.3 s latency, so a
    # session per robot finds it on a's rows alone; a run without the key is a row saying so
    from hystcli.core import effects as E
    from hystcli.core.model import Model
    from hystcli.core.params import Shape
    from hystcli.io import save_model, write_run as save_run
    from hystcli.sim import twin

    cat = twin.get_catheter("example-a")
    save_model(tmp_path / "model.json", Model(cat.knobs, cat.geometry, meta={"catheter": "example-a"}))
    d = tmp_path / "runs"
    d.mkdir()
    t = np.arange(0, 20.0 + 1e-9, 0.02)
    shapes = ["straight", "alpha=90,theta=0", "alpha=45,theta=0"]
    for robot, effects in (("a", (E.make_effect("latency", delay=0.3),)), ("b", ())):
        for i, shape in enumerate(shapes):
            q = {1: 50 * np.sin(2 * np.pi * (0.05 + 0.01 * i) * t)}
            meta = {"motion": "periodic", "trial": i + 1, "robot": robot}
            save_run(d / f"{robot}{i}.csv", twin.simulate(cat, t, q, shape=Shape.parse(shape), effects=effects,
                                                          seed=i, meta=meta))
    save_run(d / "nokey.csv", twin.simulate(cat, t, {1: 40 * np.sin(0.3 * t)}, seed=9))
    out = tmp_path / "diag.parquet"
    res = runner.invoke(app, ["batch", "diagnose", str(d / "*.csv"), "-m", str(tmp_path / "model.json"),
                              "--candidates", "latency", "--session-by", "robot", "-o", str(out), "-j", "1",
                              "-q", "-f", "json"])
    assert res.exit_code == 0, res.output
    table = {Path(r["path"]).stem: r for r in pq.read_table(out).to_pylist()}
    assert len(table) == 7
    assert table["nokey"]["status"] == "refused" and "'# robot: ...'" in table["nokey"]["reason"]
    assert table["nokey"]["session"] is None
    assert table["nokey"]["sha256"] == hashlib.sha256((d / "nokey.csv").read_bytes()).hexdigest()
    for robot, top in (("a", "latency"), ("b", "none")):
        group = [table[f"{robot}{i}"] for i in range(3)]
        assert {r["session"] for r in group} == {f"robot={robot}"}
        assert {r["status"] for r in group} == {"ok"}, group
        assert {r["top_effect"] for r in group} == {top}
        assert len({r["key"] for r in group}) == 1  # one diagnosis per session
    assert json.loads(res.stdout)["failed"] == 1
