"""Typed errors of hyst.

Every failure a user can cause (bad data, a bad model, a device that misbehaves) is raised as a
subclass of :class:`HystError`. The command-line layer turns any of them into one line
``Error: ...`` on stderr and exit code 1, in one place (``hystcli.cli.app``); the core never
prints.
"""
from __future__ import annotations


class HystError(Exception):
    """Base class of every error hyst reports to its user."""


class DataError(HystError):
    """A run CSV (or other input data) is missing, unreadable or inconsistent."""


class ParameterError(HystError, ValueError):
    """A setting given to a library function is outside its domain (a step that is not positive, a
    false-alarm rate of 0.7).

    Parameters
    ----------
    parameter : str
        The parameter at fault, as the library function names it (``"step"``, ``"false_alarm"``).
    reason : str
        What is wrong with its value, e.g. ``"must be a positive number, got -1.0"``.

    The message is ``"parameter: reason"``; the command line shows :attr:`reason` against the
    option the user typed for :attr:`parameter` (a usage error, exit 2).
    """

    def __init__(self, parameter: str, reason: str) -> None:
        super().__init__(f"{parameter}: {reason}")
        self.parameter = parameter
        self.reason = reason

    def __reduce__(self) -> tuple:
        # two arguments, not the one message: keeps the error intact through pickling (a batch
        # worker's error comes back to the client pickled)
        return type(self), (self.parameter, self.reason)


class ModelError(HystError):
    """A model file or model parameters are invalid (names the violated condition)."""


class IdentificationError(HystError):
    """The data cannot identify the requested parameters (says what is missing)."""


class ShiftDetectionError(HystError):
    """Algorithm 1 could not find a dead-zone edge within its limits."""


class DeviceError(HystError):
    """The device answered, and its answer reports an error (a device-side fault)."""


class LinkError(HystError):
    """The link to the device failed: no reply, a corrupt frame, a disconnect."""


class SafetyStop(HystError):
    """A live procedure was stopped by a safety limit (travel, steps, current ceiling)."""
