"""Algorithm 1 on every chosen knob of one source: :func:`run_detect_shift`, what ``hyst
detect-shift`` calls (a recorded replay, or a live robot through a :class:`.request.ProbeSource`).
"""
from __future__ import annotations

import contextlib
import os
from typing import Any, Callable, Iterator, Mapping, Sequence

from ..core.model import Model
from ..core.run import Run
from ..errors import ParameterError
from ..io import read_run
from .probe import ProbeSample, ReplayProbe
from .request import ProbeSource, ShiftRequest, select_knobs
from .result import ShiftResult
from .search import detect_shift

__all__ = ["run_detect_shift"]


@contextlib.contextmanager
def _opened(replay: Run | None, live: ProbeSource | None, knobs: list[int]) -> Iterator[Mapping[int, Any]]:
    if replay is not None:
        yield {k: ReplayProbe(replay, k) for k in knobs}
    else:
        with live.open(knobs) as probes:
            yield probes


def run_detect_shift(model: Model, replay: Run | str | os.PathLike | None = None, *,
                     live: ProbeSource | None = None, knobs: Sequence[int] | None = None,
                     request: ShiftRequest | None = None, name: str | os.PathLike | None = None,
                     started: Callable[[int], None] | None = None,
                     progress: Callable[[int, ProbeSample, float], None] | None = None,
                     **search: Any) -> dict[int, ShiftResult]:
    """Algorithm 1 on every chosen knob of one source, one knob after the other.

    Everything is checked before the first step: the settings, the knobs against the model and
    the replay. A live source is opened once for every knob and closed (motors stopped) on the way
    out, failed or not.

    Parameters
    ----------
    model : Model
        The straight-shaft model, with the identification sweep's reading of the current.
    replay : Run or path-like, optional
        A run recorded under the new shape (a slow sweep from the rest position); a path is read
        with :func:`hystcli.io.read_run`.
    live : ProbeSource, optional
        A live robot (``hystcli.device.LiveProbes``); exactly one of ``replay`` and ``live``.
    knobs : sequence of int, optional
        The knobs to search (default: every knob of the model the source has).
    request : ShiftRequest, optional
        The search's settings; or give them as keywords (``step=0.25``, ``false_alarm=1e-4``, ...),
        not both.
    name : path-like, optional
        The replay's file, named in errors (default: the path given as ``replay``).
    started : callable, optional
        Called with each knob before its search.
    progress : callable, optional
        Called with the knob, each :class:`ProbeSample` and the slope of the last readings.

    Returns
    -------
    dict of int to ShiftResult
        One result per knob searched, in the order searched.

    Raises
    ------
    ParameterError
        A setting outside its domain, no source or two.
    ModelError, DataError
        A knob the model or the replay lacks; a replay that cannot be read.
    ShiftDetectionError, SafetyStop, LinkError, DeviceError
        From the search (:func:`hystcli.shift.detect_shift`); the knob is returned first.
    """
    if request is not None and search:
        raise ParameterError("request", f"give the settings as a request or as keywords, not both "
                                        f"(got {', '.join(sorted(search))} too)")
    request = ShiftRequest(**search) if request is None else request
    if (replay is None) == (live is None):
        raise ParameterError("replay", "give exactly one source: a replay or a live robot")
    if replay is not None and not isinstance(replay, Run):
        name = replay if name is None else name
        replay = read_run(replay)
    knobs = select_knobs(model, knobs, replay, name)
    options = request.options()
    results: dict[int, ShiftResult] = {}
    with _opened(replay, live, knobs) as probes:
        for k in knobs:
            if started is not None:
                started(k)
            each = None if progress is None else (lambda s, w, k=k: progress(k, s, w))
            results[k] = detect_shift(model, probes[k], k, progress=each, **options)
    return results
