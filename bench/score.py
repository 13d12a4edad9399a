"""Scoring one case against the truth and the reference fit, and pooling the scores (bench only).

Pure functions on plain data; nothing here imports ``hystcli`` or runs a fit.

A method's result for one case is either ``{param: {"value": v, "lo": lo, "hi": hi, "fixed": bool}}``
(``lo``/``hi`` may be ``None`` or infinite; an optional ``"se"`` is a stated standard error) or a
refusal ``{"refused": reason, "names": [params it names]}``. The reference is, per parameter,
anything with ``estimate``, ``lo``, ``hi`` (attributes or keys), e.g. a
:class:`reference.ParamInterval`.

Outcomes per parameter (:data:`OUTCOMES`):

``right`` / ``wrong``
    returned as fixed, within / beyond ``tol`` of the truth (``silent`` marks a wrong one more
    than :data:`SILENT_DEG` off: a silent failure when the method exited 0);
``refused-right`` / ``refused-wrong``
    refused, left out, or returned unfixed without an interval, where the reference does not /
    does resolve the parameter (interval half-width at most ``tol``);
``interval-right`` / ``interval-wrong``
    returned unfixed with an interval (at least one finite end) that does / does not contain
    the truth.
"""
from __future__ import annotations

import math
from collections import defaultdict
from typing import Any, Iterable, Mapping

OUTCOMES = ("right", "wrong", "refused-right", "refused-wrong", "interval-right", "interval-wrong")
SILENT_DEG = 2.0
"""deg: a fixed parameter off by more than this, returned with exit 0, is a silent failure."""


def _get(obj: Any, name: str, default=None):
    if isinstance(obj, Mapping):
        return obj.get(name, default)
    return getattr(obj, name, default)


def _num(v) -> float:
    return math.nan if v is None else float(v)


def ref_resolves(ref_entry: Any, tol: float) -> bool:
    """True when the reference's interval is finite and at most ``tol`` in half-width."""
    if ref_entry is None:
        return False
    lo, hi = _num(_get(ref_entry, "lo")), _num(_get(ref_entry, "hi"))
    return bool(math.isfinite(lo) and math.isfinite(hi) and 0.5 * (hi - lo) <= tol)


def in_interval(truth: float, lo, hi) -> bool:
    """Truth within [lo, hi]; a missing end is open (None counts as infinite)."""
    lo = -math.inf if lo is None else float(lo)
    hi = math.inf if hi is None else float(hi)
    return bool(lo <= truth <= hi)


def within_2se(truth: float, value: float, se) -> bool:
    """Truth within two stated standard errors of the value (False without a finite se)."""
    if se is None or not math.isfinite(float(se)):
        return False
    return bool(abs(float(value) - truth) <= 2.0 * float(se))


def outcome(truth: float, entry: Mapping | None, ref_entry: Any, tol: float) -> str:
    """The outcome of one parameter (see the module docstring).

    Parameters
    ----------
    truth : float
        The plant's true value.
    entry : mapping or None
        The method's ``{"value", "lo", "hi", "fixed"}`` for this parameter, or None when it
        refused or left the parameter out.
    ref_entry
        The reference's interval for this parameter (None: not resolved).
    tol : float
        deg: how close a fixed value must be, and the reference's resolution half-width.
    """
    if entry is not None and entry.get("fixed"):
        return "right" if abs(float(entry["value"]) - truth) <= tol else "wrong"
    if entry is not None:
        lo, hi = entry.get("lo"), entry.get("hi")
        if any(v is not None and math.isfinite(float(v)) for v in (lo, hi)):
            return "interval-right" if in_interval(truth, lo, hi) else "interval-wrong"
    return "refused-wrong" if ref_resolves(ref_entry, tol) else "refused-right"


def score_case(truth: Mapping[str, float], result: Mapping, reference: Mapping[str, Any], tol: float,
               params: Iterable[str], *, family: str = "", exit_code: int = 0) -> list[dict]:
    """One row per parameter: outcome, errors of the method and the reference, coverage flags.

    ``result`` is the method's per-parameter mapping or a refusal (``"refused"`` key).
    """
    refused = "refused" in result
    rows = []
    for p in params:
        tv = float(truth[p])
        entry = None if refused else result.get(p)
        ref = reference.get(p) if reference is not None else None
        out = outcome(tv, entry, ref, tol)
        fixed = entry is not None and bool(entry.get("fixed"))
        err = float(entry["value"]) - tv if fixed else math.nan
        ref_est = _num(_get(ref, "estimate")) if ref is not None else math.nan
        rows.append({
            "family": family, "param": p, "outcome": out,
            "silent": bool(out == "wrong" and exit_code == 0 and abs(err) > SILENT_DEG),
            "error": err,
            "ref_error": ref_est - tv,
            "ref_resolved": ref_resolves(ref, tol),
            "ref_covers": bool(ref is not None and in_interval(tv, _get(ref, "lo"), _get(ref, "hi"))),
            "covered": bool(entry is not None and in_interval(tv, entry.get("lo"), entry.get("hi"))
                            if entry is not None and (entry.get("lo") is not None or entry.get("hi") is not None)
                            else False),
            "covered_2se": bool(entry is not None and fixed and within_2se(tv, entry["value"], entry.get("se"))),
        })
    return rows


def _rms(xs: list[float]) -> float:
    return math.sqrt(sum(x * x for x in xs) / len(xs)) if xs else math.nan


def summarize(rows: Iterable[Mapping]) -> dict:
    """Pool rows of :func:`score_case`: counts per outcome overall, per parameter and per family;
    the rate of ``right`` among the parameters the reference resolves; RMS error of the method and
    of the reference on the parameters both fixed (method) and resolved (reference); silent
    failures; the reference's coverage."""
    rows = list(rows)
    counts: dict[str, dict[str, int]] = defaultdict(lambda: {o: 0 for o in OUTCOMES})
    by_fam: dict[str, dict[str, int]] = defaultdict(lambda: {o: 0 for o in OUTCOMES})
    total = {o: 0 for o in OUTCOMES}
    for r in rows:
        counts[r["param"]][r["outcome"]] += 1
        by_fam[r["family"]][r["outcome"]] += 1
        total[r["outcome"]] += 1
    resolved = [r for r in rows if r["ref_resolved"]]
    both = [r for r in resolved if math.isfinite(r["error"])]
    return {
        "n": len(rows),
        "total": total,
        "per_param": {k: dict(v) for k, v in counts.items()},
        "per_family": {k: dict(v) for k, v in by_fam.items()},
        "resolved": len(resolved),
        "right_of_resolved": (sum(r["outcome"] == "right" for r in resolved) / len(resolved)
                              if resolved else math.nan),
        "rms_method": _rms([r["error"] for r in both]),
        "rms_reference": _rms([r["ref_error"] for r in both]),
        "silent": sum(bool(r["silent"]) for r in rows),
        "reference_coverage": (sum(r["ref_covers"] for r in rows) / len(rows)) if rows else math.nan,
    }


def format_summary(summary: Mapping) -> str:
    """The pooled summary as a plain-text table."""
    head = "group".ljust(22) + "".join(o.rjust(16) for o in OUTCOMES)
    lines = [head, "-" * len(head)]
    lines.append("all".ljust(22) + "".join(str(summary["total"][o]).rjust(16) for o in OUTCOMES))
    for kind in ("per_param", "per_family"):
        for name, c in sorted(summary[kind].items()):
            lines.append(f"{name}".ljust(22) + "".join(str(c[o]).rjust(16) for o in OUTCOMES))
    lines.append(f"right of what the reference resolves: {summary['right_of_resolved']:.3f} "
                 f"({summary['resolved']} resolved); silent failures {summary['silent']}")
    lines.append(f"RMS error on the resolved set: method {summary['rms_method']:.3f} deg, "
                 f"reference {summary['rms_reference']:.3f} deg; reference coverage "
                 f"{summary['reference_coverage']:.3f}")
    return "\n".join(lines)
