"""What a shift detection is asked to do, checked before anything moves: :class:`ShiftRequest` (the
search's settings), :func:`select_knobs` (the knobs a source can search) and :class:`ProbeSource`
(what a live robot offers :func:`hystcli.shift.run_detect_shift`).

Every check raises a typed error (:class:`~hystcli.errors.ParameterError` for a setting out of its
domain, :class:`~hystcli.errors.ModelError` or :class:`~hystcli.errors.DataError` for knobs the
model or the replay lacks), so a script and ``hyst detect-shift`` refuse the same things with the
same words.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, replace
from typing import Any, ContextManager, Mapping, Protocol, Sequence

from ..core.model import Model
from ..core.run import Run
from ..errors import DataError, ParameterError
from ..settings import DEFAULT, Settings
from .probe import Probe

__all__ = ["ProbeSource", "ShiftRequest", "positive", "select_knobs"]


def positive(parameter: str, value: float | None) -> None:
    """Raise :class:`ParameterError` unless ``value`` is None or a positive finite number.

    ``nan`` is refused too: it passes every comparison's ``not``, and a search limit of ``nan``
    would never stop.
    """
    if value is not None and not (math.isfinite(value) and value > 0):
        raise ParameterError(parameter, f"must be a positive number, got {value}")


@dataclass(frozen=True)
class ShiftRequest:
    """The settings of one shift search (Algorithm 1), checked when made.

    Parameters
    ----------
    step : float
        Unit step :math:`u` (deg).
    max_steps : int, optional
        Step limit (default: room to cross the dead zone and back).
    max_travel : float, optional
        Knob travel limit (deg; default: the reach of the model's identification sweep).
    eps_upper : float, optional
        Contact slope (mA/deg; default: the settings' contact factor times the sweep's loaded slope).
    false_alarm : float, optional
        Probability that a search along a stretch with no edge declares one; replaces
        ``settings.false_alarm`` when given.
    direction : int, optional
        Initial direction, +1 or -1 (default: the way a replay's record goes first, else +1).
    settings : Settings
        The level, the false-alarm rate, the widest offset interval returned.

    Raises
    ------
    ParameterError
        A setting outside its domain; :attr:`~hystcli.errors.ParameterError.parameter` names it.

    Examples
    --------
    >>> ShiftRequest(step=0.25).step
    0.25
    >>> ShiftRequest(false_alarm=0.7)
    Traceback (most recent call last):
    ...
    hystcli.errors.ParameterError: false_alarm: must be in (0, 0.5), got 0.7
    """

    step: float = 0.5
    max_steps: int | None = None
    max_travel: float | None = None
    eps_upper: float | None = None
    false_alarm: float | None = None
    direction: int | None = None
    settings: Settings = DEFAULT

    def __post_init__(self) -> None:
        positive("step", self.step)
        positive("max_travel", self.max_travel)
        if self.max_steps is not None and self.max_steps < 1:
            raise ParameterError("max_steps", f"must be at least 1, got {self.max_steps}")
        positive("eps_upper", self.eps_upper)
        if self.false_alarm is not None and not 0.0 < self.false_alarm < 0.5:
            raise ParameterError("false_alarm", f"must be in (0, 0.5), got {self.false_alarm}")
        if self.direction is not None and self.direction not in (1, -1):
            raise ParameterError("direction", f"must be +1 or -1, got {self.direction}")

    def options(self) -> dict[str, Any]:
        """The keyword arguments of :func:`hystcli.shift.detect_shift` this request gives."""
        settings = self.settings
        if self.false_alarm is not None:
            settings = replace(settings, false_alarm=float(self.false_alarm))
        return dict(settings=settings, eps_upper=self.eps_upper, step=self.step, max_steps=self.max_steps,
                    max_travel=self.max_travel, direction=self.direction)


class ProbeSource(Protocol):
    """Where live probes come from: one connection, a probe per knob (``hystcli.device.LiveProbes``).

    ``open(knobs)`` is a context manager yielding ``{knob: probe}``; leaving it stops the motors
    and closes the connection.
    """

    def open(self, knobs: Sequence[int]) -> ContextManager[Mapping[int, Probe]]: ...


def select_knobs(model: Model, knobs: Sequence[int] | None = None, replay: Run | None = None,
                 name: str | os.PathLike | None = None) -> list[int]:
    """The knobs to search: those asked for, else every knob of the model the replay records
    (a live source: every knob of the model).

    Parameters
    ----------
    model : Model
    knobs : sequence of int, optional
    replay : Run, optional
        The recorded replay (its ``q<k>`` columns say which knobs it records).
    name : path-like, optional
        The replay's file, named in the error.

    Raises
    ------
    ModelError
        A knob asked for that the model does not have.
    DataError
        No knob asked for, and the replay records none of the model's knobs.
    """
    if knobs is None:
        if replay is None:
            knobs = list(model.knobs)
        else:
            knobs = [k for k in model.knobs if f"q{k}" in replay]
            if not knobs:
                where = f"{name}: " if name is not None else ""
                raise DataError(f"{where}the replay records none of the model's knobs "
                                f"(no column {' or '.join(f'q{k}' for k in model.knobs)})")
    knobs = [int(k) for k in knobs]
    for k in knobs:
        model.knob(k)  # a knob the model lacks: ModelError, naming the knobs it has
    return knobs
