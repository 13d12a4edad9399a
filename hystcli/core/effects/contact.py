"""``contact``: the tip meets a wall and stops there (the safety case).

``y = min(y, wall)`` for a wall at a positive tip angle, ``max(y, wall)`` for a negative one; the
motor current rises by ``stiffness`` mA per degree of knob pushed past it (the blocked tip angle
over the loaded slope omega), which the twin adds to its current. Only ``wall`` moves the tip, so
diagnosis fits only it. Compensation cannot pass the wall: the target is clipped there.
"""
from __future__ import annotations

import math

import numpy as np

from .base import EffectType, Form

_INF = math.inf


class Contact(EffectType):
    name = "contact"
    summary = "a wall at tip angle wall stops the tip; the current rises by stiffness per knob deg"
    driver = "tip"
    regressors = ("tip angle",)
    forms = (
        Form("wall", "contact", 0, ("wall", "stiffness"), ("deg", "mA/deg"), "wall", _INF,
             {"wall": 40.0, "stiffness": 60.0}, {"wall": (-120.0, 120.0), "stiffness": (0.0, 500.0)},
             {"wall": (-_INF, _INF), "stiffness": (0.0, _INF)},
             {"wall": np.concatenate([np.arange(-120.0, -1.0, 5.0), np.arange(5.0, 121.0, 5.0), [math.inf]])},
             "the tip stops at the wall", fit=("wall",)),
    )

    def forward(self, eff, z, sig, state):
        w = eff["wall"]
        return np.minimum(z, w) if w > 0 else np.maximum(z, w)

    def inverse(self, eff, z, sig, state, warnings, options):
        w = eff["wall"]
        clipped = np.minimum(z, w) if w > 0 else np.maximum(z, w)
        if np.any(clipped != z):
            warnings.append(f"knob {sig.k}: the reference passes the wall at {w:g} deg: clipped there")
        return clipped

    @staticmethod
    def current(eff, free: np.ndarray, tip: np.ndarray, omega: float) -> np.ndarray:
        """Extra motor current (mA) while the wall blocks the tip: stiffness per deg of knob past it."""
        return eff["stiffness"] * np.abs(free - tip) / omega

    # -- one sample at a time (hystcli/stream/) --------------------------------------------------
    def stepper(self, eff, k, options, warnings):
        """The target clipped at the wall, one sample at a time (warns once, as :meth:`inverse`)."""
        from .kernels import StatelessStep

        w = float(eff["wall"])
        said = []

        def clip(z, other):
            c = min(z, w) if w > 0 else max(z, w)
            if c != z and not said:
                said.append(True)
                warnings.append(f"knob {k}: the reference passes the wall at {w:g} deg: clipped there")
            return c

        return StatelessStep(clip)
