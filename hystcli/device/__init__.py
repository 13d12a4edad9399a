"""The live robot: the line protocol, the driver, the probe of Algorithm 1, motions, the emulator.

This package owns everything that talks to a robot over a serial link (docs/protocol.md):

* :mod:`.protocol`: the frame codec both ends share, the handshake and position replies;
* :mod:`.driver`: :class:`Device`, the host-side driver (deadlines, sequence numbers, faults kept
  apart as :class:`~hystcli.errors.DeviceError` and :class:`~hystcli.errors.LinkError`);
* :mod:`.probe`: :class:`DeviceProbe`, one knob as Algorithm 1's live probe, with a current ceiling,
  and :class:`LiveProbes`, a robot as a shift detection's source (one connection, a probe per knob);
* :mod:`.robot`: status, homing, jogging and playing a trajectory within the motion limits
  (:mod:`hystcli.safety`);
* :mod:`.tracking`: the closed loop that plays a reference through the streaming compensator;
* :mod:`.emulator`: a device served on a pseudo-terminal (``hyst sim-robot``) over a plant.

The names a host program needs are here: ``from hystcli.device import Device, DeviceProbe``.
Nothing here prints; the CLI renders.
"""
from __future__ import annotations

from .driver import Device, open_port
from .probe import DEFAULT_DWELL, DEFAULT_MEAN, DeviceProbe, LiveProbes, open_probe
from .protocol import (FEATURES, MAX_DWELL, MAX_FRAME, PROTOCOL_VERSION, DeviceInfo, Frame, FrameError, Sample, crc8,
                       decode_frame, encode_frame, parse_pos)

__all__ = ["DEFAULT_DWELL", "DEFAULT_MEAN", "FEATURES", "MAX_DWELL", "MAX_FRAME", "PROTOCOL_VERSION", "Device",
           "DeviceInfo", "DeviceProbe", "Frame", "FrameError", "LiveProbes", "Sample", "crc8", "decode_frame", "encode_frame",
           "open_port", "open_probe", "parse_pos"]
