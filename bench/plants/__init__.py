"""Test plants for the tests and the bench: simulated catheter knobs written from the physics alone.

They are not part of the installed package (the wheel holds ``hystcli`` only); tests and benches
import them as ``plants`` with the bench folder on ``sys.path`` (tests/conftest.py does it).

`zoo` is the independent plant zoo: one-knob plants (`zoo.plants`) and two-knob catheters with
effects of their own (`zoo.catheters`). `live` hands the zoo's live plant to
``hyst sim-robot --plant bench/plants/live.py:SEED[:FAMILY[:OFFSET]]``.

`wild` (with its sample-by-sample core `wild_kernel`) simulates a tendon-driven knob whose tip
follows dead-zone + backlash hysteresis and whose motor current breaks, family by family, the
premises an earlier plant set shared with the method under test. `show_wild` prints one line per
drawn case. Nothing here imports hystcli: the plants are independent of the code they test.
"""
