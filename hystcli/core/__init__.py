"""The core: the hysteresis recursion every other layer runs.

``hystcli.core.kernel`` owns the dead-zone + backlash recursion of docs/design.md section 3: the
envelopes, the clamp update (forward), the one-sample inverse and the whole-run kernels built from
them. Prediction (:mod:`hystcli.model`), the effect chain (:mod:`hystcli.effects`), the streaming
compensator (:mod:`hystcli.stream`), the tip fit (:mod:`hystcli.identification.tip`) and the twin
(:mod:`hystcli.sim.twin`) all call it, so a change to the model is made once.

Importing this package loads nothing: the kernels compile with numba on first use.
"""
