"""Independent plants: test catheters written from the physics alone.

The code under test (identification, shift detection, the twin and its effects, diagnosis) must
hold on catheters we did not build. The plants in this package were written from the physics of
docs/design.md sections 2-4 and 6 and the paper, by authors who did not read that code, and they
import nothing from :mod:`hystcli` (tests/test_plants_apart.py). Tests and benches feed their records to the
commands exactly as a user's logs would be: as run CSV text.

Modules
-------
plants
    One-knob plants: the dead-zone + backlash tip of docs/design.md section 3 under many motor-current
    laws, samplings, noise levels, sweeps and start states; straight sweeps for identification,
    replays recorded after a bend for shift detection, and a steppable plant for the live path.
catheters
    Two-knob catheters with unmodelled effects in forms of their own, as run sets for diagnosis.
"""
