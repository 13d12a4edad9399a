"""The core: the model of a catheter and the one hysteresis kernel every other layer runs.

* :mod:`.kernel` owns the dead-zone + backlash recursion of docs/design.md section 3: the
  envelopes, the clamp update (forward), the one-sample inverse and the whole-run kernels built
  from them. Prediction, the effect chain, the streaming compensator (:mod:`hystcli.stream`), the
  tip fit (:mod:`hystcli.identification.tip`) and the twin (:mod:`hystcli.sim.twin`) all call it,
  so a change to the model is made once;
* :mod:`.params`: one knob's model (envelopes, forward, inverse, shift), the shaft's shape and
  geometry (shape -> offset, rotation), an effect's spec, what identification learnt per knob;
* :mod:`.run`: the run container every layer passes (its CSV format is :mod:`hystcli.io`'s);
* :mod:`.effects`: one module per effect the base model leaves out, and their chain, forward and
  inverse;
* :mod:`.model`: the catheter's :class:`~hystcli.core.model.Model`, its prediction and its exact
  inverse (compensation without a motor's limits, which :mod:`hystcli.compensation` adds).

Each module imports only the ones listed before it. Importing this package loads nothing: the
kernels compile with numba on first use.
"""
