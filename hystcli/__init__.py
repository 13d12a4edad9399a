"""hyst: shape-adaptive hysteresis calibration and evaluation for tendon-driven catheter robots.

The Python surface (docs/design.md section 9)::

    import hystcli
    m = hystcli.load_model("model.json")     # -> Model
    k = m.knob(1)                             # -> KnobModel
    y = k.forward(q)                          # numpy in, numpy out
    q = k.inverse(r)
    pred = m.predict(run)                     # with the model's effects: what `hyst predict` writes
    cmd = m.compensate(reference).run         # with the model's effects: what `hyst compensate` writes
    c = hystcli.Compensator(m, dt=0.01)       # streaming, for a robot's own control loop
    q_t = c.step(r_t)                         # one sample in, one command out, causal

``import hystcli`` loads only the error classes: every other name is imported on first use
(module ``__getattr__``), so that ``hyst --help`` and a script that needs one function do not
pay for numpy, pandas and numba up front.
"""
from __future__ import annotations

import importlib
from typing import Any

from .errors import (DataError, DeviceError, HystError, IdentificationError, LinkError, ModelError,
                     SafetyStop, ShiftDetectionError)

__version__ = "0.1.0"

# public name -> submodule that defines it (imported when the name is first asked for)
_LAZY = {
    "Compensator": "stream", "Run": "io", "load_model": "io", "read_run": "io", "save_model": "io", "write_run": "io",
    "EffectSpec": "model", "Geometry": "model", "KnobModel": "model", "Model": "model", "Shape": "model",
}

__all__ = [
    "Compensator", "DataError", "DeviceError", "EffectSpec", "Geometry", "HystError", "IdentificationError",
    "KnobModel", "LinkError", "Model", "ModelError", "Run", "SafetyStop", "Shape",
    "ShiftDetectionError", "load_model", "read_run", "save_model", "write_run", "__version__",
]


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'hystcli' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value  # later look-ups skip this function
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
