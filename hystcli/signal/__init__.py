"""Reading a motor current (DESIGN section 4 of the method): conditioning, and the statistical
model of a monotone stretch of current against knob angle.

* :mod:`.pwl` fits continuous broken lines (robust loss, pieces by BIC, knot intervals);
* :mod:`.reading` reads a sweep's current with them: its sign convention, the loading edges with
  their intervals, the no-load levels, the slopes, and the backlash where the current shows it;
* :mod:`.result` holds what a reading returns (:class:`~.result.CurrentReading`, one
  :class:`~.result.StretchReading` per monotone stretch).
"""
