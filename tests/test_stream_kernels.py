"""The coupling's compiled per-sample fixed point (hystcli/stream/kernels.py) gives the Python
passes of hystcli/stream/compensator.py bit for bit: every coupled chain it takes, through reset, set_offset
and rotate between steps; a chain it has no op for keeps the Python passes."""
from __future__ import annotations

import numpy as np
import pytest

import hystcli
from hystcli.core import effects as E
from hystcli.sim import twin
from hystcli.io import read_run
from hystcli.core.model import Model

CAT = twin.get_catheter("example-a")
REF = read_run("sample_data/reference_nonperiodic.csv").with_meta(shape="alpha=45,theta=30")

CHAINS = {
    "input+rate": (E.make_effect("coupling", "input", gain=0.15), E.make_effect("rate", "input", tau=0.2)),
    "magnitude+input2": (E.make_effect("coupling", "input-magnitude", gain=0.15),
                         E.make_effect("rate", "input2", tau=0.1)),
    "deadzone": (E.make_effect("coupling", "deadzone", gain=0.15),),
    "deadzone-magnitude+rate+creep": (E.make_effect("coupling", "deadzone-magnitude", gain=0.15),
                                      E.make_effect("rate", "input", tau=0.1), E.make_effect("creep", "relax")),
    "input+saturation+output lag": (E.make_effect("coupling", "input", gain=0.2),
                                    E.make_effect("saturation", "smooth", limit=80.0),
                                    E.make_effect("rate", "output", tau=0.1)),
}


def _model(effects) -> Model:
    return Model(CAT.knobs, CAT.geometry, effects=tuple(e.spec() for e in effects))


def _drive(c: hystcli.Compensator) -> np.ndarray:
    out = []
    n = len(REF)
    for i in range(n):
        if i == n // 3:
            c.set_offset(1, c.offsets[1] + 4.0)
        if i == n // 2:
            c.rotate(20.0)
        if i == 2 * n // 3:
            c.reset((3.0, -2.0))
        out.append(c.step((float(REF["r1"][i]), float(REF["r2"][i])), None))
    return np.asarray(out)


@pytest.mark.parametrize("name", list(CHAINS))
def test_compiled_fixed_point_is_the_python_passes(name):
    model = _model(CHAINS[name])
    fast = hystcli.Compensator.for_run(model, REF.meta, dt=0.01)
    slow = hystcli.Compensator.for_run(model, REF.meta, dt=0.01)
    assert fast._fast is not None
    slow._fast = None  # the Python passes
    np.testing.assert_array_equal(_drive(fast), _drive(slow))
    assert fast.warnings == slow.warnings


def test_a_chain_without_ops_keeps_the_python_passes():
    # an output coupling: its hysteresis starts behind the other knob's push (no op for that)
    c = hystcli.Compensator(_model((E.make_effect("coupling", "output", gain=0.05),)), dt=0.01)
    assert c._fast is None
    assert len(c.steps(np.zeros((5, 2)))) == 5
