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

    ident = hystcli.identify(sweep)           # -> Identification: .model, .intervals, .summary()
    shift = hystcli.detect_shift(ident.model, replay, knob=1)  # -> ShiftResult (offset, interval)
    comp = hystcli.compensate(model, reference)  # -> Compensation: .run, .warnings, .summary()
    pred = hystcli.predict(model, run)        # -> Run, as Model.predict
    report = hystcli.evaluate(runs)           # -> Evaluation: .groups, .summary()
    diag = hystcli.diagnose(model, runs)      # -> Diagnosis: .model, .verdict, .summary()

    est = hystcli.Identifier(level=0.9)       # the estimators as objects: settings in the constructor
    ident = est.fit(sweep)                    # as hystcli.identify(sweep, settings=Settings(level=0.9))
    est.get_params()                          # {"level": 0.9, ...}; also ShiftDetector, Diagnoser

docs/library.md runs a whole session of these as a script.

``import hystcli`` loads only the error classes: every other name is imported on first use
(module ``__getattr__``), so that ``hyst --help`` and a script that needs one function do not
pay for numpy, pandas and numba up front.

Layers
------
The package is cut in layers, :data:`LAYERS`, lowest first. A module imports only from its own
layer or the ones below, never from a layer above, and no two modules import each other round a
circle (tests/test_layers.py reads every import with ``ast`` and fails on either). The core
imports neither typer, rich nor matplotlib.

1. foundation: errors, estimates, settings, names, filters, thread pools, the motion limits of a
   knob trajectory (:mod:`hystcli.safety`);
2. signal: conditioning and reading the motor current;
3. core (:mod:`hystcli.core`): the one hysteresis kernel, each knob's model and the shaft's shape
   (:mod:`hystcli.core.params`), the run a model works on (:mod:`hystcli.core.run`), the effects and
   their chain (:mod:`hystcli.core.effects`), and the catheter's model with its prediction and
   inverse (:mod:`hystcli.core.model`);
4. io: runs and models in files, the import of foreign logs, checks of a data set
   (:mod:`hystcli.io`);
5. use: compensation within a motor's limits, streaming compensation (:mod:`hystcli.stream`),
   reports (:mod:`hystcli.report`: tables, formats, figures, the evaluation's metrics, what
   ``hyst show`` and ``hyst diff`` print);
6. estimation: identification, shift detection, diagnosis (search, attribution, drive, refit), and
   the estimator objects around them (:mod:`hystcli.estimators`);
7. device: the robot protocol, driver, probe, motions, tracking and emulator;
8. studies: the twin, its calibrated catheters and the paper's experiment (:mod:`hystcli.sim`),
   batches of runs;
9. cli: the command line (options, one library call, rendering).
"""
from __future__ import annotations

import importlib
from typing import Any

from .errors import (DataError, DeviceError, HystError, IdentificationError, LinkError, ModelError,
                     ParameterError, SafetyStop, ShiftDetectionError)

__version__ = "0.1.0"

LAYERS: tuple[tuple[str, ...], ...] = (
    ("errors", "estimate", "settings", "names", "filters", "threads", "safety"),
    ("signal",),
    ("core",),
    ("io",),
    ("compensation", "stream", "report"),
    ("identification", "shift", "diagnosis", "estimators"),
    ("device",),
    ("sim", "batch"),
    ("cli", "__main__"),
)
"""The layers of the package, lowest first: each names the modules and subpackages directly under
``hystcli`` that belong to it (the module notes)."""

# public name -> submodule that defines it (imported when the name is first asked for)
_LAZY = {
    "Compensator": "stream", "Run": "core.run", "load_model": "io", "read_run": "io", "save_model": "io",
    "write_run": "io", "EffectSpec": "core.params", "Geometry": "core.params", "KnobModel": "core.params",
    "Model": "core.model", "Shape": "core.params", "Settings": "settings", "identify": "identification",
    "detect_shift": "shift", "compensate": "compensation", "predict": "core.model", "evaluate": "report.metrics",
    "diagnose": "diagnosis",
    "Identifier": "estimators", "ShiftDetector": "estimators", "Diagnoser": "estimators",
}

__all__ = [
    "Compensator", "DataError", "DeviceError", "Diagnoser", "EffectSpec", "Geometry", "HystError",
    "IdentificationError", "Identifier", "KnobModel", "LinkError", "Model", "ModelError", "ParameterError", "Run",
    "SafetyStop", "Settings", "Shape", "ShiftDetectionError", "ShiftDetector", "compensate", "detect_shift",
    "diagnose", "evaluate", "identify", "load_model", "predict", "read_run", "save_model", "write_run",
    "__version__",
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
