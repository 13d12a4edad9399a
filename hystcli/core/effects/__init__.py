"""Effects the base model leaves out (docs/design.md section 8), as plug-ins shared by the twin, the
model's prediction and compensation, and the diagnosis.

One module per effect owns its physics (forward and inverse stage, each with an explicit state),
its family of forms, its parameter domain and how diagnosis searches it; :mod:`.registry` lists
them; :mod:`.chain` runs a model's effects in fixed stages, forward and inverse.

==========  =====================================================  ===============================
name        physics                                                 forms (first: the default)
==========  =====================================================  ===============================
friction    capstan friction grows with the total curvature         capstan, backlash, slope
deadzone    the shape changes the dead zone                          width, centre, one-edge,
                                                                     centre-bend
stretch     a stated load stretches the cable: the output moves     linear, stiffening, slack
coupling    the other knob moves this knob's loop                    input, output, deadzone
                                                                     (each also -magnitude)
rate        viscous lag of the tip behind the knob                   input, input2, output, output2,
                                                                     backlash
saturation  the bending section stiffens near its largest bend       smooth, hard, asymmetric,
                                                                     smooth-knobs, hard-knobs, knee
creep       slow relaxation: a fraction of each move arrives late    relax
contact     the tip meets a wall                                     wall
latency     the tracker reports the tip late                         tracker
==========  =====================================================  ===============================

Every effect has a null setting under which its stage is skipped, so the chain is the base model
bit for bit (:meth:`hystcli.core.params.KnobModel.forward`). A model file's effect entry names the
physics and, when it is not the default, the form: ``{"name": "coupling", "form":
"deadzone-magnitude", "params": {"gain": 0.1}}``; on the command line and in run metadata
``coupling:form=deadzone-magnitude,gain=0.1``.
"""
from .base import STAGES, Effect, EffectType, Form, Signals
from .chain import (ChainState, Inverse, KnobTrace, Plan, condition_knob, contact_current, inverse, predict,
                    rest_input, run_condition, run_signals, step_index, tip_chain)
from .registry import (ALIASES, EFFECTS, as_effect, as_effects, effect_type, format_effects, make_effect,
                       parse_effect, parse_effects)

__all__ = [
    "ALIASES", "ChainState", "EFFECTS", "Effect", "EffectType", "Form", "Inverse", "KnobTrace", "Plan", "STAGES",
    "Signals", "as_effect", "as_effects", "condition_knob", "contact_current", "effect_type", "format_effects",
    "inverse", "make_effect", "parse_effect", "parse_effects", "predict", "rest_input", "run_condition", "run_signals",
    "step_index", "tip_chain",
]
