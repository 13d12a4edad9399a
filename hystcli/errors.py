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
