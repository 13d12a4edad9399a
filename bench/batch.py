"""`hyst batch` against a shell loop of single commands, on local processes and on a dask cluster.

Run on demand (minutes; nothing here is a test):

    python bench/batch.py --n 200 --identify-n 24 --loop-n 30 --workdir /tmp/hyst-batch-bench

1. Runs: ``--n`` evaluate runs and ``--identify-n`` sweeps. The evaluate runs are 8 distinct
   ``hyst simulate`` runs (two catheters, four shapes, seeded), each replicated with a
   ``# replica: i`` metadata line; the sweeps are the four sample sweeps
   (``sample_data/ice-*/sweep_knob*.csv``) replicated the same way. A replica differs from its
   original in its bytes (so its hash, so it is a task of its own) and not in its numbers: every
   task does the whole work of its run.
2. For each command: wall time of ``hyst batch CMD`` on 2 local processes, of the same with
   ``--scheduler`` on a 2-worker ``distributed.LocalCluster`` (started once, warm), and of a
   shell loop of ``hyst CMD RUN.csv`` over the first ``--loop-n`` runs, projected to all of
   them (the loop's cost per run times N). Each batch starts from an empty output (no resume).
   The two tables are compared byte for byte.
3. Per task: the median of the timing table's seconds; the peak Python memory of one task
   (tracemalloc, in this process, after one warm-up task) and the peak RSS of a fresh process
   that runs one task (imports included).
4. The engine's per-task overhead: ``--overhead-n`` tasks that do nothing (a payload of real
   run bytes, the function ``len``) through the same dask engine: ``o = wall / M``.
5. The projection for W workers: ``throughput(W) = min(W / t_task, 1 / o)`` tasks per second,
   ``t_task`` the median per-task seconds on a worker, ``o`` the per-task overhead of the client
   and scheduler (one client and one scheduler serve every worker, so their cost per task caps
   the rate whatever W is).
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SHAPES = ("straight", "alpha=45,theta=0", "alpha=90,theta=0", "alpha=90,theta=90")


def sh(*args: str) -> float:
    """Run a command (no shell); its wall seconds. A failure stops the bench."""
    t0 = time.perf_counter()
    subprocess.run(args, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - t0


def replicate(sources: list[Path], folder: Path, n: int) -> None:
    """``n`` files in ``folder``: the sources in turn, each with a ``# replica: i`` line after its first."""
    folder.mkdir(parents=True, exist_ok=True)
    texts = [s.read_text().split("\n", 1) for s in sources]
    for i in range(n):
        head, rest = texts[i % len(texts)]
        (folder / f"run{i:05d}.csv").write_text(f"{head}\n# replica: {i}\n{rest}")


def generate(work: Path, n: int, n_identify: int) -> tuple[Path, Path]:
    base = work / "distinct"
    base.mkdir(parents=True, exist_ok=True)
    srcs = []
    for j, (cath, shape) in enumerate((c, s) for c in ("ice-a", "ice-b") for s in SHAPES):
        p = base / f"sim{j}.csv"
        if not p.exists():
            sh("hyst", "simulate", "--catheter", cath, "--shape", shape, "--motion", "periodic", "--trial",
               str(j + 1), "--seed", str(1000 + j), "-o", str(p), "-q")
        srcs.append(p)
    ev, idf = work / "evaluate", work / "identify"
    for d in (ev, idf):
        shutil.rmtree(d, ignore_errors=True)
    replicate(srcs, ev, n)
    replicate(sorted((ROOT / "sample_data").glob("ice-*/sweep_knob*.csv")), idf, n_identify)
    return ev, idf


def batch(cmd: str, folder: Path, out: Path, *extra: str) -> float:
    for p in (out, out.with_name(out.name + ".parts"), out.with_name(out.stem + ".timing" + out.suffix)):
        shutil.rmtree(p, ignore_errors=True) if p.is_dir() else p.unlink(missing_ok=True)
    return sh("hyst", "batch", cmd, str(folder / "*.csv"), "-o", str(out), "-q", *extra)


def loop(cmd: str, folder: Path, k: int) -> float:
    files = sorted(folder.glob("*.csv"))[:k]
    t0 = time.perf_counter()
    for f in files:
        # what a user's shell loop runs: one process per run (identify without -o only prints)
        subprocess.run(["hyst", cmd, str(f), "-q"], check=False, stdout=subprocess.DEVNULL,
                       stderr=subprocess.DEVNULL)
    return (time.perf_counter() - t0) / len(files)


def task_memory(cmd: str, path: Path) -> tuple[float, float]:
    """Peak traced Python memory (MiB) of one task in this process (after a warm-up), and the
    peak RSS (MiB) of a fresh process that runs one task."""
    import tracemalloc

    from hystcli.batch.tasks import Payload, canonical_settings, execute

    data = path.read_bytes()
    pay = Payload(cmd, canonical_settings(cmd, {}), ((str(path), hashlib.sha256(data).hexdigest(), data),))
    execute(pay)
    tracemalloc.start()
    execute(pay)
    peak = tracemalloc.get_traced_memory()[1] / 2 ** 20
    tracemalloc.stop()
    code = ("import hashlib;from hystcli.batch.tasks import Payload,canonical_settings,execute;"
            f"d=open({str(path)!r},'rb').read();execute(Payload({cmd!r},canonical_settings({cmd!r},{{}}),"
            f"(({str(path)!r},hashlib.sha256(d).hexdigest(),d),)));"
            # VmHWM, not ru_maxrss: the latter carries over the (large) parent's peak across fork + exec
            "print(next(int(x.split()[1]) for x in open('/proc/self/status') if x.startswith('VmHWM')))")
    rss = int(subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True).stdout) / 1024
    return peak, rss


def overhead(address: str, folder: Path, m: int) -> float:
    """Seconds per task of the engine alone: m tasks of real payload bytes whose work is ``len``."""
    from hystcli.batch.engine import DaskEngine, Job

    files = sorted(folder.glob("*.csv"))
    jobs = [Job(str(i), (lambda p=files[i % len(files)]: p.read_bytes())) for i in range(m)]
    t0 = time.perf_counter()
    n = sum(1 for _ in DaskEngine(address).map(len, jobs))
    assert n == m
    return (time.perf_counter() - t0) / m


def timing_median(out: Path) -> float:
    import pyarrow.parquet as pq

    return statistics.median(r["seconds"] for r in pq.read_table(out.with_name(out.stem + ".timing.parquet"))
                             .to_pylist())


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=200, help="evaluate runs")
    ap.add_argument("--identify-n", type=int, default=24, help="identify sweeps")
    ap.add_argument("--loop-n", type=int, default=30, help="runs the shell loop times (projected to all)")
    ap.add_argument("--overhead-n", type=int, default=400, help="no-op tasks for the engine's overhead")
    ap.add_argument("--workers", type=int, default=100, help="cluster size to project to")
    ap.add_argument("--workdir", type=Path, default=Path("/tmp/hyst-batch-bench"))
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--commands", default="evaluate,identify",
                    help="which batches to time, comma-separated (the projection needs both)")
    args = ap.parse_args(argv)
    from distributed import LocalCluster

    work = args.workdir
    ev, idf = generate(work, args.n, args.identify_n)
    load = os.getloadavg()
    res: dict = {"n": args.n, "identify_n": args.identify_n, "load_before": load}
    with LocalCluster(n_workers=2, processes=True, threads_per_worker=1, dashboard_address=":0",
                      silence_logs=50) as lc:
        wanted = set(args.commands.split(","))
        for cmd, folder, n in (("evaluate", ev, args.n), ("identify", idf, args.identify_n)):
            if cmd not in wanted:
                continue
            lo, da = work / f"{cmd}_local.parquet", work / f"{cmd}_dask.parquet"
            load_local = os.getloadavg()[0]
            t_local = batch(cmd, folder, lo, "-j", "2")
            load_dask = os.getloadavg()[0]
            t_dask = batch(cmd, folder, da, "--scheduler", lc.scheduler_address)
            load_end = os.getloadavg()[0]
            k = min(args.loop_n, n)
            per_run = loop(cmd, folder, k)
            peak, rss = task_memory(cmd, sorted(folder.glob("*.csv"))[0])
            res[cmd] = {"runs": n, "local_s": t_local, "dask_s": t_dask, "loop_per_run_s": per_run,
                        "loop_runs_timed": k, "loop_projected_s": per_run * n,
                        "local_runs_per_s": n / t_local, "dask_runs_per_s": n / t_dask, "loop_runs_per_s": 1 / per_run,
                        "identical": lo.read_bytes() == da.read_bytes(),
                        "task_median_s": timing_median(da), "task_peak_traced_mib": peak,
                        "task_process_rss_mib": rss,
                        # 1-minute load at the start and end of each batch: the machine the figures came from
                        "load_1min_local_start_dask_start_end": (load_local, load_dask, load_end)}
            print(json.dumps({cmd: res[cmd]}), flush=True)
        o = overhead(lc.scheduler_address, ev, args.overhead_n)
    res["overhead_s_per_task"] = o
    for cmd in ("evaluate", "identify"):
        if cmd not in res:
            continue
        t = res[cmd]["task_median_s"]
        res[cmd]["projected_runs_per_s"] = min(args.workers / t, 1 / o)
        res[cmd]["projection"] = f"min({args.workers} / {t:.4f} s, 1 / {o:.5f} s)"
    res["load_after"] = os.getloadavg()
    print(json.dumps(res, indent=1))
    if args.json:
        args.json.write_text(json.dumps(res, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
