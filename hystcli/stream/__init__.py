"""Streaming compensation: the model's inverse chain one reference sample at a time, for a robot's
own control loop (``hystcli.Compensator``, docs/streaming.md).

* :mod:`.compensator`: :class:`~.compensator.Compensator`, the chain ``hyst compensate`` runs over a
  whole file, fed and answering one sample at a time, within a motor's limits when given them;
* :mod:`.stages`: its stages: the hysteresis inverse, a knob's bend as the other knob's coupling
  reads it, one knob's chain, and the coupled chains' fixed point;
* :mod:`.kernels`: that fixed point compiled (numba), loaded only when a compensator has a coupled
  chain.

The names below are the package's surface (``from hystcli.stream import Compensator``).
"""
from __future__ import annotations

from .compensator import LATENCY_MODES, Compensator

__all__ = ["Compensator", "LATENCY_MODES"]
