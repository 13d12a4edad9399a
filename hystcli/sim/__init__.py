"""Simulation: the virtual catheter and the paper's experiment run on it.

* :mod:`.twin`: the virtual catheter (the dead-zone + backlash tip of :mod:`hystcli.core`, the
  motor current of its tendons, the effects of :mod:`hystcli.core.effects`), the paper's motions and
  one simulated run;
* :mod:`.live`: the same catheter stepped move by move, what ``hyst sim-robot`` serves;
* :mod:`.calibration`: the calibrated catheters ice-a and ice-b the sample data was recorded on;
* :mod:`.scenarios`: the paper's published values, the demo's settings, shaft scenarios and
  recordings;
* :mod:`.experiment`: the paper's whole protocol (``hyst demo``) and its results;
* :mod:`.render`: its tables beside the paper's, its figures and the files it writes.

Nothing here prints; the CLI renders. Only the command line imports this package.
"""
