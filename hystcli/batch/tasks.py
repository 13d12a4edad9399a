"""The batch's tasks: one command of hyst on one run (or one session of runs), as a plain function.

This is the only module of :mod:`hystcli.batch` that imports the rest of hyst (the fits, the
readers, the model); the engine, the table and the report see plain dicts. A task is a
:class:`Payload` of bytes (the run files' and the model's contents, read by the client), so a
worker needs no view of the client's file system, and its answer is a JSON-able dict:

``{"rows": {sha256: row}, "seconds": float, "worker": str}``

where each row holds the run's metadata (``meta_<key>``), the result's numbers, ``status``
(``ok``, ``refused`` for a :class:`~hystcli.errors.HystError`, ``error`` for anything else),
``reason`` and ``warnings``. A task never raises for bad data: a bad run is a row.
"""
from __future__ import annotations

import json
import math
import os
import socket
import time
from dataclasses import dataclass
from typing import Any, Callable, Sequence

COMMANDS = ("identify", "evaluate", "detect-shift", "diagnose")
"""The commands ``hyst batch`` runs; diagnose runs on sessions of runs, the others on one run each."""

NEEDS_MODEL = ("detect-shift", "diagnose")
"""Commands whose task needs a model (``--model`` or the manifest's ``model`` column)."""

DEFAULTS: dict[str, dict[str, Any]] = {
    "identify": {"omega": None, "current_only": False, "level": 0.95, "current_sign": "auto"},
    "evaluate": {},
    "detect-shift": {"false_alarm": 1e-3, "step": 0.5, "max_steps": None, "max_travel": None,
                     "eps_upper": None},
    "diagnose": {"holdout": None, "candidates": None, "max_effects": 3, "bootstrap": 0, "seed": 0},
}
"""Each command's settings and their defaults (the options of the single command of that name)."""


@dataclass(frozen=True)
class Payload:
    """What a worker needs for one task: no paths to open, only contents.

    Attributes
    ----------
    command : str
        One of :data:`COMMANDS`.
    settings : str
        The command's settings as canonical JSON (:func:`canonical_settings`).
    runs : tuple of (str, str, bytes)
        ``(name, sha256, contents)`` of each run: one, or a diagnose session's several.
    model : bytes or None
        The model file's contents (detect-shift, diagnose).
    model_name : str or None
        The model's file name, for messages.
    """

    command: str
    settings: str
    runs: tuple[tuple[str, str, bytes], ...]
    model: bytes | None = None
    model_name: str | None = None


def version() -> str:
    """hyst's version: part of every task's key, so an upgrade recomputes rather than mixes results."""
    from .. import __version__

    return __version__


def canonical_settings(command: str, given: dict[str, Any]) -> str:
    """The command's settings (defaults filled in, unknown names refused) as sorted, compact JSON.

    Raises
    ------
    ValueError
        A setting the command does not have (a programming error of the caller: the CLI only
        passes the command's own options).
    """
    base = dict(DEFAULTS[command])
    unknown = set(given) - set(base)
    if unknown:
        raise ValueError(f"{command} has no setting {sorted(unknown)[0]!r}")
    base.update({k: v for k, v in given.items()})
    base["hyst"] = version()
    return json.dumps(base, sort_keys=True, separators=(",", ":"))


_PINNED = False


def _pin() -> None:
    # A dask worker is not started by `hyst`: pin the numeric libraries' threads as the command
    # line does (hystcli.__main__), before numba/BLAS load, so that a worker computes what a
    # single command computes, bit for bit, and two workers on two cores do not fight.
    global _PINNED
    if not _PINNED:
        from ..threads import pin_threads

        pin_threads()
        _PINNED = True


def execute(payload: Payload) -> dict:
    """Run one task; never raises for bad data (see the module docstring).

    Parameters
    ----------
    payload : Payload

    Returns
    -------
    dict
        ``{"rows": {sha256: row}, "seconds": float, "worker": "host:pid"}``.
    """
    _pin()
    from threadpoolctl import threadpool_limits

    t0 = time.perf_counter()
    settings = json.loads(payload.settings)
    settings.pop("hyst", None)
    with threadpool_limits(limits=int(os.environ.get("HYST_THREADS", "1") or 1)):
        rows = _rows(payload, settings)
    return {"rows": rows, "seconds": time.perf_counter() - t0, "worker": f"{socket.gethostname()}:{os.getpid()}"}


def _failed(exc: BaseException) -> dict:
    from ..errors import HystError

    text = str(exc).strip()
    reason = text.splitlines()[0] if text else type(exc).__name__
    if not isinstance(exc, HystError):
        reason = f"{type(exc).__name__}: {reason}"
    return {"status": "refused" if isinstance(exc, HystError) else "error", "reason": reason}


def _rows(payload: Payload, settings: dict) -> dict[str, dict]:
    runs: dict[str, Any] = {}
    out: dict[str, dict] = {}
    for name, sha, data in payload.runs:
        try:
            runs[sha] = _parse(name, data)
            out[sha] = {"status": "ok", "reason": None, **_meta(runs[sha])}
        except Exception as exc:  # a bad file is a row, whatever broke
            out[sha] = _failed(exc)
    if payload.command == "diagnose":
        _diagnose(payload, settings, runs, out)
        return out
    work = _SINGLE[payload.command]
    for name, sha, _ in payload.runs:
        if sha not in runs:
            continue
        warnings: list[str] = []
        try:
            out[sha].update(work(runs[sha], payload, settings, warnings))
        except Exception as exc:
            out[sha].update(_failed(exc))
        out[sha]["warnings"] = "\n".join(warnings) if warnings else None
    return out


def _parse(name: str, data: bytes) -> Any:
    from ..errors import DataError
    from ..io import parse_run

    if not data.strip():
        raise DataError(f"{name}: empty file")
    try:
        # utf-8-sig: as read_run, a spreadsheet's byte-order mark is not part of 't'
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise DataError(f"{name}: not a text CSV file (not UTF-8)") from None
    return parse_run(text, source=name)


def _meta(run: Any) -> dict:
    return {f"meta_{k}": str(v) for k, v in run.meta.items()}


def _model(payload: Payload) -> Any:
    from ..errors import ModelError
    from ..io import model_from_dict

    if payload.model is None:
        raise ModelError("no model given (--model, or a model column in the manifest)")
    try:
        data = json.loads(payload.model.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ModelError(f"{payload.model_name}: not a model JSON file ({exc})") from None
    return model_from_dict(data, payload.model_name or "<model>")


def _num(x: Any) -> float | None:
    # infinities (an interval open on one side) and NaN are stored as null: a table's number is
    # finite or missing, never a sentinel a mean would swallow
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


def _identify(run: Any, payload: Payload, s: dict, warnings: list[str]) -> dict:
    from ..identification import identify
    from ..settings import Settings

    result = identify(run, omega=s["omega"], use_tip=not s["current_only"],
                      settings=Settings(level=s["level"], current_sign=s["current_sign"]))
    row: dict[str, Any] = {}
    for k, fit in result.fits.items():
        warnings.extend(str(w) for w in fit.warnings)  # each names its file and knob already
        row[f"k{k}_method"] = str(fit.method)
        row[f"k{k}_rmse"] = _num(fit.rmse)
        # the values the model file holds (what `hyst identify -o` writes); the intervals are the
        # profile likelihood's, around its own optimum, which may differ from them in the 4th digit
        for pname, value in fit.model.params().items():
            row[f"k{k}_{pname}"] = _num(value)
        for pname, e in fit.estimates.items():
            row[f"k{k}_{pname}_lo"] = _num(e.lo)
            row[f"k{k}_{pname}_hi"] = _num(e.hi)
            row[f"k{k}_{pname}_fixed"] = bool(e.fixed)
    return row


def _evaluate(run: Any, payload: Payload, s: dict, warnings: list[str]) -> dict:
    from ..io.check import require_shape
    from ..report.metrics import evaluate_runs

    evaluation = evaluate_runs([require_shape(run)], group_by=())
    warnings.extend(w for w in evaluation.warnings if "metadata (grouped as 'unknown')" not in w)
    row: dict[str, Any] = {}
    for r in evaluation.results:
        row[f"k{r.knob}_ptpe"] = _num(r.ptpe)
        row[f"k{r.knob}_rmse"] = _num(r.rmse)
        row[f"k{r.knob}_n"] = int(r.n)
    return row


def _detect_shift(run: Any, payload: Payload, s: dict, warnings: list[str]) -> dict:
    from ..errors import DataError
    from ..settings import Settings
    from ..shift import ReplayProbe, detect_shift

    model = _model(payload)
    knobs = [k for k in model.knobs if f"q{k}" in run]
    if not knobs:
        raise DataError(f"{run.source}: the replay records none of the model's knobs "
                        f"(no column {' or '.join(f'q{k}' for k in model.knobs)})")
    row: dict[str, Any] = {}
    for k in knobs:
        r = detect_shift(model, ReplayProbe(run, k), k, eps_upper=s["eps_upper"],
                         settings=Settings(false_alarm=s["false_alarm"]), step=s["step"],
                         max_steps=s["max_steps"], max_travel=s["max_travel"])
        row.update({f"k{k}_offset": _num(r.offset), f"k{k}_offset_lo": _num(r.offset_lo),
                    f"k{k}_offset_hi": _num(r.offset_hi), f"k{k}_d_neg": _num(r.d_neg),
                    f"k{k}_d_pos": _num(r.d_pos), f"k{k}_edge": str(r.edge), f"k{k}_steps": int(r.steps),
                    f"k{k}_travel": _num(r.travel)})
        if r.contacts:
            warnings.append(f"knob {k}: contact at " + ", ".join(f"{c:.1f}" for c in r.contacts) + " deg, reversed")
    return row


def _diagnose(payload: Payload, s: dict, runs: dict[str, Any], out: dict[str, dict]) -> None:
    # one diagnosis per session, its findings on every run of it; a run that cannot be read is
    # left out of the session (its own row says why) rather than failing the others
    from ..io.check import require_shape
    from ..diagnosis import diagnose

    good = [sha for _, sha, _ in payload.runs if sha in runs]
    try:
        model = _model(payload)
        session = [require_shape(runs[sha]) for sha in good]
        cands = None if s["candidates"] is None else [c.strip() for c in str(s["candidates"]).split(",") if c.strip()]
        diag = diagnose(model, session, holdout=s["holdout"], candidates=cands, max_effects=s["max_effects"],
                        bootstrap=s["bootstrap"], seed=s["seed"])
    except Exception as exc:
        for sha in good:
            out[sha].update(_failed(exc))
            out[sha]["warnings"] = None
        return
    rep = diag.report()
    hf = rep["how_far"]
    chosen = [x["name"] for x in rep["which"]["selected"]]
    common = {"session_runs": len(good), "top_effect": chosen[0] if chosen else "none",
              "effects": ",".join(chosen) if chosen else "none",
              "session_rmse_before": hf["rmse_before"], "session_rmse_after": hf["rmse_after"],
              "gap_shrink_pct": hf["rmse_shrink_pct"], "session_ptpe_shrink_pct": hf["ptpe_shrink_pct"]}
    names = {runs[sha].source: sha for sha in good}
    for sha in good:
        out[sha].update(common)
        out[sha]["warnings"] = None
    for f in hf["per_run"]:
        sha = names.get(f["run"])
        if sha is not None:
            k = f["knob"]
            out[sha].update({f"k{k}_rmse_before": f["rmse_before"], f"k{k}_rmse_after": f["rmse_after"],
                             f"k{k}_ptpe_before": f["ptpe_before"], f"k{k}_ptpe_after": f["ptpe_after"]})


def text_table(columns: Sequence[str], headers: Sequence[str], rows: Sequence[tuple], notes: Sequence[str] = ()) -> Any:
    """A :class:`hystcli.report.table.Table` (what ``--format`` table/markdown/csv renders), for ``hyst report``."""
    from ..report.table import Table

    return Table(tuple(columns), tuple(headers), tuple(rows), tuple(notes))


_SINGLE: dict[str, Callable[..., dict]] = {"identify": _identify, "evaluate": _evaluate,
                                           "detect-shift": _detect_shift}
