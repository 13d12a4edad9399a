"""Effects the base model leaves out (DESIGN.md section 8), shared by the twin and the diagnosis.

Placeholder pipeline: with no effects, the twin's signals are exactly the base model's output and
the motor current of :func:`hystcli.twin.motor_current`.
"""
from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from .errors import ModelError
from .model import EffectSpec, KnobModel, Shape


def apply(effects: Sequence[EffectSpec], catheter, knobs: Mapping[int, KnobModel],
          q: Mapping[int, np.ndarray], t: np.ndarray, shape: Shape):
    """Noise-free tip angle and motor current per knob, with ``effects`` switched on."""
    from .twin import motor_current

    if effects:
        raise ModelError(f"unknown effect {effects[0].name!r}")
    ys = {k: knobs[k].forward(q[k]) for k in knobs}
    cs = {k: motor_current(knobs[k], catheter.current, q[k], t) for k in knobs}
    return ys, cs
