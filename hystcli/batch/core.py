"""``hyst batch``: plan the tasks of many runs, run them on an engine, keep every result.

:func:`plan` expands the inputs (globs, or a manifest CSV naming runs, models and sessions),
hashes every file and gives each task its key: the SHA-256 of the command, its settings (with
hyst's version), the model's hash and the runs' hashes. Two files with the same contents are
one task (their rows share its result). :func:`run_batch` skips every task whose key already
has a part, sends the others to the engine, writes each part as it comes back
(:mod:`hystcli.batch.table`) and, once all are in, writes the table: one row per run.
"""
from __future__ import annotations

import csv
import glob
import hashlib
import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

from .. import DataError
from ..io.runs import read_meta
from . import table as T
from .engine import Job, make_engine
from .tasks import COMMANDS, NEEDS_MODEL, Payload, canonical_settings, execute

ProgressFn = Callable[[str, int, int], None]


@dataclass(frozen=True)
class Entry:
    """One run of the batch: one row of the table.

    ``sha256`` is None (and ``reason`` says why) for a file that cannot be read at all; a run
    that is read but cannot be placed (a diagnose session key it lacks) keeps its hash and says why.
    """

    path: str
    sha256: str | None
    model: str | None = None
    model_sha256: str | None = None
    session: str | None = None
    extra: tuple[tuple[str, str], ...] = ()
    reason: str | None = None


@dataclass(frozen=True)
class Task:
    """One unit of work: one run (or a diagnose session of runs), under one key."""

    key: str
    members: tuple[Entry, ...]


@dataclass(frozen=True)
class Plan:
    """What a batch will do: its entries (rows) and tasks, under one command and settings."""

    command: str
    settings: str
    entries: tuple[Entry, ...]
    tasks: tuple[Task, ...]
    key_of: tuple[tuple[str, str], ...] = ()  # (path, task key) for every readable entry


@dataclass(frozen=True)
class BatchResult:
    """What :func:`run_batch` did.

    Attributes
    ----------
    table, timing, parts : Path
        The results table, the timing table, the parts folder.
    runs : int
        Rows of the table (one per run).
    tasks, computed, skipped : int
        Tasks of the plan; those computed now; those whose part was already written.
    failed : int
        Rows whose status is not ``ok`` (refused, error, lost).
    retried : int
        Tasks sent again because a worker died running them.
    seconds : float
        Wall time of the batch.
    engine : str
        Which engine ran it.
    failures : tuple of (str, str, str)
        ``(path, status, reason)`` of each failed row, in table order.
    interrupted : bool
        Stopped by Ctrl-C: the parts written so far are kept; no table was written.
    """

    table: Path
    timing: Path
    parts: Path
    runs: int
    tasks: int
    computed: int
    skipped: int
    failed: int
    retried: int
    seconds: float
    engine: str
    failures: tuple[tuple[str, str, str], ...] = field(default=())
    interrupted: bool = False


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _expand(patterns: Sequence[str]) -> list[str]:
    # a name that exists is itself (a shell may have expanded the glob already); otherwise a
    # glob, ** included; a pattern that matches nothing is a usage mistake, not an empty batch
    out: list[str] = []
    for pat in patterns:
        if Path(pat).exists() and not glob.has_magic(pat):
            if Path(pat).is_dir():
                raise DataError(f"{pat}: is a directory; give a glob such as '{pat}/*.csv'")
            out.append(pat)
            continue
        found = sorted(p for p in glob.glob(pat, recursive=True) if Path(p).is_file())
        if not found:
            raise DataError(f"{pat}: no file matches")
        out.extend(found)
    return out


def read_manifest(path: Path) -> list[dict[str, str]]:
    """The rows of a manifest CSV: a ``run`` column (required), ``model`` and ``session``
    (optional), any other column kept in the table as ``manifest_<name>``. Relative paths are
    relative to the manifest's folder.

    Raises
    ------
    DataError
        No such file, no ``run`` column, an empty ``run`` cell.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except OSError as exc:
        raise DataError(f"{path}: cannot read ({exc.strerror or exc})") from None
    rows = list(csv.DictReader(line for line in text.splitlines() if not line.startswith("#")))
    if not rows or "run" not in (rows[0].keys()):
        raise DataError(f"{path}: a manifest needs a header with a 'run' column (and optional model, session)")
    base = path.parent
    out = []
    for i, r in enumerate(rows, start=2):
        run = (r.get("run") or "").strip()
        if not run:
            raise DataError(f"{path}: line {i}: empty 'run'")
        item = {k.strip(): (v or "").strip() for k, v in r.items() if k is not None}
        item["run"] = str(run if Path(run).is_absolute() else base / run)
        if item.get("model"):
            m = item["model"]
            item["model"] = str(m if Path(m).is_absolute() else base / m)
        out.append(item)
    return out


def plan(command: str, inputs: Sequence[str] = (), manifest: Path | None = None, model: Path | None = None,
         settings: dict[str, Any] | None = None, session_by: str | None = None) -> Plan:
    """Expand the inputs, hash every file, group diagnose sessions, key every task.

    Parameters
    ----------
    command : str
        One of :data:`hystcli.batch.tasks.COMMANDS`.
    inputs : sequence of str
        Run files or globs (``runs/**/*.csv``).
    manifest : Path, optional
        A manifest CSV instead of (or as well as) ``inputs``.
    model : Path, optional
        The model of every run (detect-shift, diagnose) unless the manifest names one.
    settings : dict, optional
        The command's settings (:data:`hystcli.batch.tasks.DEFAULTS`).
    session_by : str, optional
        diagnose: the runs whose ``# KEY: value`` metadata line has one value are one session
        (a robot, a day, a procedure), wherever their files lie. A run without that line is a
        row refused with the reason. Default: the manifest's ``session`` column, else the folder.

    Returns
    -------
    Plan

    Raises
    ------
    DataError
        No runs, a glob that matches nothing, an unreadable manifest or model.
    """
    if command not in COMMANDS:
        raise DataError(f"unknown batch command {command!r} (one of {', '.join(COMMANDS)})")
    canon = canonical_settings(command, settings or {})
    items: list[dict[str, str]] = [{"run": p} for p in _expand(inputs)]
    if manifest is not None:
        items += read_manifest(manifest)
    if not items:
        raise DataError("no runs given (RUN.csv globs or --manifest)")
    model_hash: dict[str, str] = {}

    def hash_model(p: str) -> str:
        if p not in model_hash:
            try:
                model_hash[p] = _sha256(Path(p))
            except OSError as exc:
                raise DataError(f"{p}: cannot read the model ({exc.strerror or exc})") from None
        return model_hash[p]

    entries: list[Entry] = []
    seen: set[str] = set()
    for it in items:
        path = it["run"]
        real = str(Path(path).resolve())
        if real in seen:  # the same file twice (two globs) is one run, one row
            continue
        seen.add(real)
        m = it.get("model") or (str(model) if model is not None else None)
        if command not in NEEDS_MODEL:
            m = None
        extra = tuple(sorted((f"manifest_{k}", v) for k, v in it.items() if k not in ("run", "model", "session")))
        session = it.get("session") or str(Path(path).parent)
        try:
            sha = _sha256(Path(path))
            reason = None
        except OSError as exc:
            sha, reason = None, f"{path}: cannot read ({exc.strerror or exc})"
        if sha is not None and session_by is not None and command == "diagnose":
            value = read_meta(path).get(session_by, "").strip()
            if value:
                session = f"{session_by}={value}"
            else:  # in no session: not its folder's either, which --session-by set aside
                session, reason = None, f"{path}: no '# {session_by}: ...' metadata line to put it in a session by"
        entries.append(Entry(path, sha, m, hash_model(m) if m else None, session if command == "diagnose" else None,
                             extra, reason))
    entries.sort(key=lambda e: e.path)

    groups: dict[tuple, list[Entry]] = {}
    for e in entries:
        if e.sha256 is None or e.reason is not None:
            continue
        gk = (e.session, e.model_sha256) if command == "diagnose" else (e.sha256, e.model_sha256)
        groups.setdefault(gk, []).append(e)
    tasks: dict[str, Task] = {}
    key_of: list[tuple[str, str]] = []
    for gk, members in groups.items():
        shas = sorted({e.sha256 for e in members if e.sha256})
        h = hashlib.sha256("\n".join([command, canon, members[0].model_sha256 or "", *shas]).encode())
        key = h.hexdigest()[:40]
        uniq = {}
        for e in members:
            uniq.setdefault(e.sha256, e)  # one copy of each content per task
        tasks.setdefault(key, Task(key, tuple(uniq.values())))
        key_of += [(e.path, key) for e in members]
    return Plan(command, canon, tuple(entries), tuple(sorted(tasks.values(), key=lambda t: t.key)),
                tuple(sorted(key_of)))


def _payload(plan_: Plan, task: Task) -> Payload:
    runs = []
    for e in task.members:
        data = Path(e.path).read_bytes()
        if hashlib.sha256(data).hexdigest() != e.sha256:
            raise DataError(f"{e.path}: changed while the batch ran; run the batch again")
        runs.append((e.path, e.sha256, data))
    m = task.members[0].model
    model = Path(m).read_bytes() if m else None
    return Payload(plan_.command, plan_.settings, tuple(runs), model, m)


def run_batch(plan_: Plan, output: Path, scheduler: str | None = None, jobs: int = 2, retries: int = 2,
              progress: ProgressFn | None = None) -> BatchResult:
    """Run the plan's tasks not yet done and write the results table.

    Parameters
    ----------
    plan_ : Plan
        From :func:`plan`.
    output : Path
        The table (``.parquet``, or ``.csv``); its parts are kept in ``OUTPUT.parts/``.
    scheduler : str, optional
        A dask scheduler's address; default: ``jobs`` local processes.
    jobs : int
        Local worker processes.
    retries : int
        Times a task is sent again after its worker died.
    progress : callable, optional
        ``progress(message, done, total)`` after each task.

    Returns
    -------
    BatchResult
        With ``interrupted`` set when Ctrl-C stopped it (the parts written are kept).
    """
    t0 = time.perf_counter()
    output = Path(output)
    parts = T.parts_dir(output)
    folder = output.parent if str(output.parent) else Path(".")
    if not folder.is_dir():
        raise DataError(f"{output}: the folder {folder} does not exist")
    done = T.read_parts(parts)
    todo = [t for t in plan_.tasks if t.key not in done]
    skipped = len(plan_.tasks) - len(todo)
    engine = make_engine(scheduler, jobs, retries)
    lost: dict[str, str] = {}
    computed = 0
    total = len(plan_.tasks)
    by_key = {t.key: t for t in todo}
    jobs_ = [Job(t.key, (lambda t=t: _payload(plan_, t))) for t in todo]
    interrupted = False
    if progress is not None and skipped:
        progress(f"{skipped} task(s) already done", skipped, total)
    try:
        for out in engine.map(execute, jobs_):
            if out.error is not None:
                lost[out.tag] = out.error
            else:
                task = by_key[out.tag]
                T.write_part(parts, out.tag, {"key": out.tag, "command": plan_.command, "settings": plan_.settings,
                                              "rows": out.value["rows"], "seconds": out.value["seconds"],
                                              "worker": out.value["worker"], "attempts": out.attempts,
                                              "runs": [e.path for e in task.members]})
                computed += 1
            if progress is not None:
                progress(f"{plan_.command} {by_key[out.tag].members[0].path}", skipped + computed + len(lost), total)
    except KeyboardInterrupt:
        interrupted = True
    if interrupted:
        return BatchResult(output, T.timing_path(output), parts, len(plan_.entries), total, computed, skipped,
                           0, engine.stats.retried, time.perf_counter() - t0, engine.stats.description,
                           interrupted=True)
    done = T.read_parts(parts)
    rows, failures = _rows(plan_, done, lost)
    T.write_table(T.arrow_table(rows), output)
    timing = [{"key": k, "seconds": float(done[k].get("seconds", 0.0)), "attempts": int(done[k].get("attempts", 1)),
               "worker": str(done[k].get("worker", ""))} for k in sorted({k for _, k in plan_.key_of}) if k in done]
    T.write_table(T.arrow_table(timing, T.TIMING), T.timing_path(output))
    return BatchResult(output, T.timing_path(output), parts, len(rows), total, computed, skipped, len(failures),
                       engine.stats.retried, time.perf_counter() - t0, engine.stats.description, tuple(failures))


def _rows(plan_: Plan, parts: dict[str, dict], lost: dict[str, str]) -> tuple[list[dict], list[tuple[str, str, str]]]:
    key_of = dict(plan_.key_of)
    rows = []
    failures = []
    for e in plan_.entries:  # sorted by path
        key = key_of.get(e.path)
        row: dict[str, Any] = {"path": e.path, "sha256": e.sha256, "command": plan_.command, "model": e.model,
                               "model_sha256": e.model_sha256, "key": key, "warnings": None}
        row.update(dict(e.extra))
        if e.session is not None:
            row["session"] = e.session
        if e.reason is not None:
            row.update(status="refused", reason=e.reason)
        elif key in parts and e.sha256 in parts[key].get("rows", {}):
            row.update(parts[key]["rows"][e.sha256])
        else:
            row.update(status="lost", reason=lost.get(key, "no result (the batch stopped before it)"))
        if row.get("status") != "ok":
            failures.append((e.path, str(row.get("status")), str(row.get("reason"))))
        rows.append(row)
    return rows, failures


def settings_json(plan_: Plan) -> dict:
    """The plan's settings as a dict (for messages and the docs)."""
    return json.loads(plan_.settings)
