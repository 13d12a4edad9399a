"""Where the batch's tasks run: local processes, or a dask.distributed cluster.

Both engines take the same jobs and yield the same :class:`Outcome` objects in the order tasks
finish; the caller writes each one as it comes. Both keep only a window of tasks in flight
(a few per worker), so a batch of thousands of runs never holds thousands of files' contents in
memory, and both retry a task whose worker died:

- :class:`LocalEngine`: a :class:`concurrent.futures.ProcessPoolExecutor` (processes forked by
  a fork server, no network server). A worker that dies breaks the whole pool: the pool is made anew and every task
  that was in flight is sent again (any of them may have been the one running in the dead
  process).
- :class:`DaskEngine`: a ``distributed.Client`` on ``tcp://host:port``. The scheduler reschedules
  the tasks of a worker that died (up to its ``allowed-failures``, then ``KilledWorker``); a
  ``KilledWorker`` is sent again under a new key up to ``retries`` times. Which tasks were rerun
  is read from the scheduler (its count of the workers that died running a task).

A task whose workers died more than ``retries`` times is an :class:`Outcome` with an error.
"""
from __future__ import annotations

import multiprocessing
import os
from dataclasses import dataclass
from typing import Any, Callable, Iterator, Sequence

from .. import HystError


class EngineError(HystError):
    """The engine could not start (no scheduler at the address, dask not installed, ...)."""


@dataclass(frozen=True)
class Job:
    """One task to run: ``make()`` builds its argument when it is sent (its files read then)."""

    tag: str
    make: Callable[[], Any]


@dataclass(frozen=True)
class Outcome:
    """A finished task.

    Attributes
    ----------
    tag : str
        The job's tag.
    value : object or None
        What the task function returned; None when ``error`` is set.
    error : str or None
        Why no value came back: the workers running it died ``attempts`` times, the argument
        could not be built, or the task function raised.
    attempts : int
        How many times it was sent (1 unless a worker died running it).
    """

    tag: str
    value: Any
    error: str | None
    attempts: int


@dataclass
class EngineStats:
    """What the engine saw: workers, tasks rerun after a worker died, workers lost."""

    workers: int = 0
    retried: int = 0
    workers_lost: int = 0
    description: str = ""


def _build(job: Job) -> tuple[Any, str | None]:
    try:
        return job.make(), None
    except HystError as exc:
        return None, str(exc).splitlines()[0] if str(exc).strip() else type(exc).__name__
    except OSError as exc:
        return None, f"{exc.filename or ''}: cannot read ({exc.strerror or exc})"


PRELOAD = ("hystcli.batch.tasks", "hystcli.io", "hystcli.report.metrics")
"""What the fork server imports once, so that each worker it forks starts with numpy and pandas loaded."""


def _context() -> Any:
    # A fork server, not a plain fork: a fork of this process, which may run threads (a progress
    # bar's, numba's), may hang; the server is forked before any of them, single-threaded. Its
    # preloaded imports make every worker after the first start at once (a new pool after a
    # worker died, a second batch in the same process) instead of importing numpy again (spawn).
    if "forkserver" not in multiprocessing.get_all_start_methods():  # pragma: no cover - not Linux
        return multiprocessing.get_context("spawn")
    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload(list(PRELOAD))
    return ctx


class LocalEngine:
    """Local worker processes (no server).

    Parameters
    ----------
    jobs : int
        Worker processes.
    retries : int
        How many times a task is sent again after its worker died.
    window : int, optional
        Tasks in flight (default: 2 per worker + 1).
    """

    def __init__(self, jobs: int = 2, retries: int = 2, window: int | None = None) -> None:
        self.jobs = max(1, int(jobs))
        self.retries = max(0, int(retries))
        self.window = window or 2 * self.jobs + 1
        self.stats = EngineStats(workers=self.jobs, description=f"{self.jobs} local process(es)")

    def _pool(self) -> Any:
        from concurrent.futures import ProcessPoolExecutor

        return ProcessPoolExecutor(self.jobs, mp_context=_context(), initializer=_ignore_ctrl_c)

    def map(self, func: Callable[[Any], Any], jobs: Sequence[Job]) -> Iterator[Outcome]:
        """Run ``func`` on every job's argument; yield each :class:`Outcome` as it finishes."""
        from concurrent.futures import FIRST_COMPLETED, wait
        from concurrent.futures.process import BrokenProcessPool

        todo = iter(jobs)
        pool = self._pool()
        flight: dict[Any, tuple[Job, Any, int]] = {}  # future -> (job, argument, attempts)
        queue: list[tuple[Job, Any, int]] = []  # built, not yet accepted by a pool
        exhausted = False
        try:
            while True:
                while not exhausted and len(flight) + len(queue) < self.window:
                    job = next(todo, None)
                    if job is None:
                        exhausted = True
                        break
                    arg, err = _build(job)
                    if err is not None:
                        yield Outcome(job.tag, None, err, 0)
                        continue
                    queue.append((job, arg, 1))
                broken = False
                while queue and not broken:
                    try:
                        flight[pool.submit(func, queue[0][1])] = queue[0]
                        queue.pop(0)
                    except BrokenProcessPool:  # a worker died since the last look
                        broken = True
                if not broken:
                    if not flight:
                        return
                    done, _ = wait(list(flight), return_when=FIRST_COMPLETED)
                    for fut in done:
                        job, arg, attempts = flight.pop(fut)
                        try:
                            value = fut.result()
                        except BrokenProcessPool:
                            broken = True
                            flight[fut] = (job, arg, attempts)  # sent again below with the others
                            continue
                        except Exception as exc:  # the function raised: pickling, a bug
                            yield Outcome(job.tag, None, f"{type(exc).__name__}: {exc}", attempts)
                            continue
                        yield Outcome(job.tag, value, None, attempts)
                if broken:
                    # a dead worker breaks every future of the pool: a new pool, and every task
                    # that was in flight sent again (any of them may have killed it)
                    self.stats.workers_lost += 1
                    _kill(pool)
                    pool = self._pool()
                    again = list(flight.values())
                    flight.clear()
                    for job, arg, attempts in again:
                        if attempts > self.retries:
                            yield Outcome(job.tag, None, f"a worker died running it {attempts} time(s)", attempts)
                            continue
                        self.stats.retried += 1
                        queue.append((job, arg, attempts + 1))
        finally:
            if flight:
                _kill(pool)  # interrupted: what is in flight is lost, what was written is not
            else:
                pool.shutdown(wait=True)


def _ignore_ctrl_c() -> None:
    # Ctrl-C on a terminal reaches the whole process group: the client handles it (keeps what
    # is written, ends the workers); a worker that handled it too would print a traceback
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _kill(pool: Any) -> None:
    # end the pool's processes now rather than wait for the tasks they run (their results would
    # be dropped anyway); _processes is the executor's own table of them
    procs = list(getattr(pool, "_processes", {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for p in procs:
        try:
            p.terminate()
        except (OSError, ValueError, AttributeError):
            pass
    for p in procs:
        try:
            p.join(timeout=5)
        except (OSError, ValueError, AttributeError, AssertionError):
            pass


def _suspicious(dask_scheduler: Any = None, keys: Sequence[str] = ()) -> dict[str, int]:
    """On the scheduler: how many workers died while each task ran there."""
    out = {}
    for k in keys:
        ts = dask_scheduler.tasks.get(k)
        if ts is not None:
            out[k] = int(getattr(ts, "suspicious", 0) or 0)
    return out


class DaskEngine:
    """A dask.distributed cluster at ``address`` (``tcp://host:8786``).

    Parameters
    ----------
    address : str
        The scheduler's address (``dask://host:port`` is taken as ``tcp://host:port``).
    retries : int
        How many times a task that ended in ``KilledWorker`` (its workers died) is sent again;
        also dask's own ``retries=`` of each task.
    window : int, optional
        Tasks in flight (default: 2 per worker + 2, at least 4).
    timeout : float
        Seconds to wait for the scheduler.
    """

    def __init__(self, address: str, retries: int = 2, window: int | None = None, timeout: float = 20.0) -> None:
        if address.startswith("dask://"):
            address = "tcp://" + address[len("dask://"):]
        self.address = address
        self.retries = max(0, int(retries))
        self._window = window
        self.timeout = timeout
        self.stats = EngineStats(description=f"dask scheduler {address}")

    def map(self, func: Callable[[Any], Any], jobs: Sequence[Job]) -> Iterator[Outcome]:
        """Run ``func`` on every job's argument on the cluster; yield each :class:`Outcome` as it finishes."""
        try:
            from distributed import Client, as_completed
            from distributed.client import FutureCancelledError  # noqa: F401 - dask's own name
        except ImportError as exc:  # pragma: no cover - the CLI checks first
            raise EngineError(f"--scheduler needs dask.distributed ({exc}); pip install 'hystcli[batch]'") from None
        from distributed import KilledWorker

        try:
            client = Client(self.address, timeout=self.timeout, set_as_default=False)
        except (OSError, TimeoutError) as exc:
            raise EngineError(f"cannot reach the dask scheduler at {self.address}: {exc}") from None
        try:
            workers = len(client.scheduler_info(n_workers=-1).get("workers", {})) if _takes_n(client) else \
                len(client.scheduler_info().get("workers", {}))
            self.stats.workers = workers
            self.stats.description = f"dask scheduler {self.address} ({workers} worker(s))"
            window = self._window or max(4, 2 * workers + 2)
            todo = iter(jobs)
            flight: dict[str, tuple[Job, Any, int, Any]] = {}  # key -> (job, argument, attempts, future)
            ac = as_completed(loop=client.loop)
            exhausted = False
            seq = 0

            def send(job: Job, arg: Any, attempts: int) -> None:
                nonlocal seq
                seq += 1
                key = f"hyst-batch-{job.tag}-{attempts}-{os.getpid()}-{seq}"
                fut = client.submit(func, arg, key=key, pure=False, retries=self.retries)
                flight[key] = (job, arg, attempts, fut)
                ac.add(fut)

            def fill() -> Iterator[Outcome]:
                nonlocal exhausted
                while not exhausted and len(flight) < window:
                    job = next(todo, None)
                    if job is None:
                        exhausted = True
                        return
                    arg, err = _build(job)
                    if err is not None:
                        yield Outcome(job.tag, None, err, 0)
                        continue
                    send(job, arg, 1)

            yield from fill()
            while flight:
                batch = next(ac.batches(), [])
                if not batch:
                    break
                keys = [f.key for f in batch]
                try:
                    reruns = client.run_on_scheduler(_suspicious, keys=keys)
                except Exception:  # a scheduler that refuses run_on_scheduler: no rerun count
                    reruns = {}
                for fut in batch:
                    job, arg, attempts, _ = flight.pop(fut.key)
                    lost = int(reruns.get(fut.key, 0))
                    try:
                        value = fut.result()
                    except KilledWorker:
                        self.stats.retried += 1
                        if attempts > self.retries:
                            yield Outcome(job.tag, None, f"workers died running it (KilledWorker, {attempts} "
                                                         f"time(s))", attempts)
                        else:
                            send(job, arg, attempts + 1)
                        continue
                    except Exception as exc:
                        yield Outcome(job.tag, None, f"{type(exc).__name__}: {exc}", attempts)
                        continue
                    finally:
                        fut.release()
                    if lost:
                        self.stats.retried += 1
                    yield Outcome(job.tag, value, None, attempts + lost)
                yield from fill()
        finally:
            try:
                pending = [v[3] for v in flight.values()] if "flight" in locals() else []
                if pending:
                    client.cancel(pending)
            finally:
                client.close()


def _takes_n(client: Any) -> bool:
    import inspect

    try:
        return "n_workers" in inspect.signature(client.scheduler_info).parameters
    except (TypeError, ValueError):
        return False


def make_engine(scheduler: str | None, jobs: int, retries: int) -> Any:
    """The engine for ``--scheduler`` (a dask address) or ``--jobs`` local processes."""
    if scheduler:
        return DaskEngine(scheduler, retries=retries)
    return LocalEngine(jobs, retries=retries)


def imap(func: Callable[[Any], Any], args: Sequence[Any], jobs: int = 2, scheduler: str | None = None,
         retries: int = 2) -> Iterator[Any]:
    """``func`` over ``args`` on the batch's engine, results in the order of ``args``.

    For studies that only need a parallel map (``bench/zoo.py``, ``bench/withheld.py``): the
    same local processes or dask cluster as ``hyst batch``, the same retries after a worker
    died, no table. Each result is yielded as soon as it and all before it are in.

    Raises
    ------
    EngineError
        A task that could not be run (its workers died ``retries + 1`` times, or it raised).
    """
    engine = make_engine(scheduler, jobs, retries)
    got: dict[int, Any] = {}
    nxt = 0
    for out in engine.map(func, [Job(str(i), (lambda a=a: a)) for i, a in enumerate(args)]):
        if out.error is not None:
            raise EngineError(f"task {out.tag}: {out.error}")
        got[int(out.tag)] = out.value
        while nxt in got:
            yield got.pop(nxt)
            nxt += 1
