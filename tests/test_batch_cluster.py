"""`hyst batch --scheduler`: the same tasks on a real dask.distributed ``LocalCluster``.

Two worker processes, one thread each, started once for this module: no mock of the scheduler,
the workers or the network between them. Readiness is waited for (the cluster's workers, the
batch's progress), never slept for.
"""
from __future__ import annotations

import json
import os
import signal
from pathlib import Path

import pytest
from typer.testing import CliRunner

distributed = pytest.importorskip("distributed")
pq = pytest.importorskip("pyarrow.parquet")

from hystcli.batch import core  # noqa: E402
from hystcli.batch import table as T  # noqa: E402
from hystcli.cli import app  # noqa: E402

from test_batch import BAD, write_run  # noqa: E402

runner = CliRunner()


@pytest.fixture(scope="module")
def cluster():
    with distributed.LocalCluster(n_workers=2, processes=True, threads_per_worker=1, dashboard_address=":0",
                                  silence_logs=50) as lc:
        with distributed.Client(lc) as client:
            client.wait_for_workers(2, timeout=120)
            yield lc, client


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    d = tmp_path_factory.mktemp("cluster") / "runs"
    d.mkdir()
    for i in range(14):
        write_run(d / f"r{i:02d}.csv", seed=300 + i, trial=i % 3 + 1, controller=("none", "comp")[i % 2])
    for name in ("empty.csv", "nan.csv", "wrong_columns.csv"):
        (d / name).write_text(BAD[name])
    return d


def test_local_and_cluster_tables_are_byte_identical(cluster, runs, tmp_path):
    lc, _ = cluster
    local, remote = tmp_path / "local.parquet", tmp_path / "remote.parquet"
    r1 = runner.invoke(app, ["batch", "evaluate", str(runs / "*.csv"), "-o", str(local), "-j", "2", "-q"])
    r2 = runner.invoke(app, ["batch", "evaluate", str(runs / "*.csv"), "-o", str(remote), "--scheduler",
                             lc.scheduler_address, "-q"])
    assert r1.exit_code == 0 and r2.exit_code == 0, (r1.output, r2.output)
    assert local.read_bytes() == remote.read_bytes()
    table = pq.read_table(remote).to_pylist()
    assert len(table) == 17 and sum(x["status"] != "ok" for x in table) == 3
    # the timing table is where the engines differ: the workers that ran the tasks
    workers = {t["worker"] for t in pq.read_table(T.timing_path(remote)).to_pylist()}
    assert workers.isdisjoint({t["worker"] for t in pq.read_table(T.timing_path(local)).to_pylist()})
    # CSV on request, the same rows in the same order
    csv_out = tmp_path / "remote.csv"
    core.run_batch(core.plan("evaluate", [str(runs / "*.csv")]), csv_out, scheduler=lc.scheduler_address)
    assert csv_out.read_text().splitlines()[0].startswith('"path","sha256","command","status","reason"')
    assert len(csv_out.read_text().splitlines()) == 18


def test_a_worker_killed_mid_batch_still_gives_one_row_per_run(cluster, tmp_path):
    lc, client = cluster
    d = tmp_path / "runs"
    d.mkdir()
    for i in range(12):
        # big enough (60k rows, about 0.1 s to parse) that a worker is busy when it is killed
        write_run(d / f"r{i:02d}.csv", seed=400 + i, rows=60_000)
    out = tmp_path / "res.parquet"
    pids = client.run(os.getpid)  # worker address -> its process id
    killed = []

    def kill_a_busy_worker(message, done, total):
        if killed:
            return
        for addr, keys in client.processing().items():
            if keys and addr in pids:
                os.kill(pids[addr], signal.SIGKILL)
                killed.append(addr)
                return

    res = core.run_batch(core.plan("evaluate", [str(d / "*.csv")]), out, scheduler=lc.scheduler_address,
                         progress=kill_a_busy_worker)
    assert killed
    table = pq.read_table(out).to_pylist()
    assert sorted(x["path"] for x in table) == sorted(str(p) for p in d.glob("*.csv"))  # exactly one row each
    assert all(x["status"] == "ok" for x in table), [x["reason"] for x in table if x["status"] != "ok"]
    assert res.retried >= 1 and res.failed == 0
    timing = pq.read_table(T.timing_path(out)).to_pylist()
    assert sum(t["attempts"] > 1 for t in timing) == res.retried
    client.wait_for_workers(2, timeout=120)  # the nanny brings the worker back for the next test


def test_an_unreachable_scheduler_is_a_hyst_error():
    from hystcli.batch.engine import DaskEngine, EngineError, Job

    with pytest.raises(EngineError, match="cannot reach the dask scheduler at tcp://127.0.0.1:9"):
        list(DaskEngine("dask://127.0.0.1:9", timeout=1).map(len, [Job("a", lambda: b"")]))


SAMPLE = Path(__file__).resolve().parents[1] / "sample_data" / "ice-a"


@pytest.mark.slow
def test_identify_and_detect_shift_on_both_engines_agree_with_the_single_commands(cluster, tmp_path):
    lc, _ = cluster
    sweeps = [str(SAMPLE / "sweep_knob1.csv"), str(SAMPLE / "sweep_knob2.csv")]
    local, remote = tmp_path / "id_local.parquet", tmp_path / "id_remote.parquet"
    core.run_batch(core.plan("identify", sweeps), local, jobs=2)
    core.run_batch(core.plan("identify", sweeps), remote, scheduler=lc.scheduler_address)
    assert local.read_bytes() == remote.read_bytes()
    single = runner.invoke(app, ["identify", sweeps[0], "-f", "json", "-o", str(tmp_path / "m.json")])
    assert single.exit_code == 0, single.output
    want = json.loads(single.stdout)["1"]
    row = pq.read_table(remote).to_pylist()[0]
    assert row["status"] == "ok" and row["k1_method"] == want["method"]
    for name, value in want["params"].items():
        assert row[f"k1_{name}"] == value, name  # the same numbers, not close ones
    for name, iv in want["intervals"].items():
        assert row[f"k1_{name}_fixed"] == iv["fixed"]

    replay = str(SAMPLE / "replay_alpha90_knob1.csv")
    out = tmp_path / "shift.parquet"
    core.run_batch(core.plan("detect-shift", [replay], model=tmp_path / "m.json"), out,
                   scheduler=lc.scheduler_address)
    single = runner.invoke(app, ["detect-shift", replay, "-m", str(tmp_path / "m.json"), "-o",
                                 str(tmp_path / "s.json"), "-f", "json"])
    want = json.loads(single.stdout)["knobs"]["1"]
    row = pq.read_table(out).to_pylist()[0]
    assert (row["k1_offset"], row["k1_offset_lo"], row["k1_offset_hi"]) == (
        want["offset"], want["offset_lo"], want["offset_hi"])


def _wait_for(predicate, what: str, timeout: float = 120.0) -> None:
    """Poll until ``predicate()`` (readiness, not a fixed sleep); fail after ``timeout`` seconds."""
    import time

    end = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > end:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.05)


@pytest.mark.slow
def test_kill_a_worker_then_ctrl_c_then_rerun_every_run_once_nothing_recomputed(cluster, tmp_path):
    import subprocess
    import sys

    lc, client = cluster
    client.wait_for_workers(2, timeout=120)
    d = tmp_path / "runs"
    d.mkdir()
    for i in range(30):
        write_run(d / f"r{i:02d}.csv", seed=500 + i, rows=60_000)
    for name in ("empty.csv", "nan.csv"):
        (d / name).write_text(BAD[name])
    out = tmp_path / "res.parquet"
    parts = T.parts_dir(out)
    cmd = [sys.executable, "-m", "hystcli", "batch", "evaluate", str(d / "*.csv"), "-o", str(out),
           "--scheduler", lc.scheduler_address, "-f", "json"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        count = lambda: len(list(parts.glob("*.json"))) if parts.is_dir() else 0  # noqa: E731
        _wait_for(lambda: count() >= 3, "3 parts")
        pid = next(iter(client.run(os.getpid).values()))
        os.kill(pid, signal.SIGKILL)  # a worker dies mid-batch
        _wait_for(lambda: count() >= 8, "8 parts")
        proc.send_signal(signal.SIGINT)  # then Ctrl-C
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130 and "the same command resumes" in err
    before = {p.name: (p.stat().st_ino, p.stat().st_mtime_ns) for p in parts.glob("*.json")}
    assert 8 <= len(before) < 32 and not out.exists()
    client.wait_for_workers(2, timeout=120)
    rerun = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert rerun.returncode == 0, rerun.stderr
    summary = json.loads(rerun.stdout)
    assert (summary["skipped"], summary["computed"]) == (len(before), 32 - len(before))
    assert summary["runs"] == 32 and summary["failed"] == 2
    after = {p.name: (p.stat().st_ino, p.stat().st_mtime_ns) for p in parts.glob("*.json")}
    assert {k: after[k] for k in before} == before and len(after) == 32
    table = pq.read_table(out).to_pylist()
    assert sorted(x["path"] for x in table) == sorted(str(p) for p in d.glob("*.csv"))
