"""Test plants for the bench: simulated catheter knobs written from the physics alone.

`wild` (with its sample-by-sample core `wild_kernel`) simulates a tendon-driven knob whose tip
follows dead-zone + backlash hysteresis and whose motor current breaks, family by family, the
premises an earlier plant set shared with the method under test. `show_wild` prints one line per
drawn case. Nothing here imports hystcli: the plants are independent of the code they test.
"""
