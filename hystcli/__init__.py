"""hyst: shape-adaptive hysteresis calibration and evaluation for tendon-driven catheter robots.

The Python surface (DESIGN.md section 9)::

    import hystcli
    m = hystcli.load_model("model.json")     # -> Model
    k = m.knob(1)                             # -> KnobModel
    y = k.forward(q)                          # numpy in, numpy out
    q = k.inverse(r)
    pred = m.predict(run)                     # with the model's effects: what `hyst predict` writes
    cmd = m.compensate(reference).run         # with the model's effects: what `hyst compensate` writes
"""
from .errors import (DataError, DeviceError, HystError, IdentificationError, LinkError, ModelError,
                     SafetyStop, ShiftDetectionError)
from .io import Run, load_model, read_run, save_model, write_run
from .model import EffectSpec, Geometry, KnobModel, Model, Shape

__version__ = "0.1.0"

__all__ = [
    "DataError", "DeviceError", "EffectSpec", "Geometry", "HystError", "IdentificationError",
    "KnobModel", "LinkError", "Model", "ModelError", "Run", "SafetyStop", "Shape",
    "ShiftDetectionError", "load_model", "read_run", "save_model", "write_run", "__version__",
]
