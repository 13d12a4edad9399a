"""Reading a stepping search's few noisy readings (hystcli.current.loading_edge's stricter
options), where the plant zoo found the reading made for a sweep's many points missing or
misplacing an edge (issue 10).

Every current below is a law written here by hand, so the true edges are known exactly; every
reference value is from that law, never from the code tested.
"""
from __future__ import annotations

import numpy as np
import pytest

from hystcli.current import loading_edge, pieces


# --------------------------------------------------------------------------------------------
# reading a stepping search's few readings (hystcli.current.loading_edge)
# --------------------------------------------------------------------------------------------
def test_the_flat_stretch_of_a_kink_fit_leaves_out_the_unloading_that_led_into_it():
    # readings every 0.5 deg: a negative tendon unloading at 12 mA/deg up to q=3, the dead zone
    # to q=14, the positive tendon at 41 mA/deg (the unloading slope is under 0.35 of the loaded
    # one, so the reading made for a sweep's many points counts it as flat)
    rng = np.random.default_rng(12)
    q = np.arange(0.0, 19.01, 0.5)
    c = 120.0 - 12.0 * np.maximum(3.0 - q, 0.0) + 41.0 * np.maximum(q - 14.0, 0.0) + rng.normal(0, 0.2, q.size)
    loose = loading_edge(q, c, 1, 0.2, resolution=0.02)
    strict = loading_edge(q, c, 1, 0.2, resolution=0.02, strict_flat=True)
    n_flat = int(np.sum((q >= 3.0) & (q < 14.0)))            # 22 readings
    assert loose is not None and loose.n_before > n_flat      # the unloading is in its fit ...
    assert strict is not None and strict.n_before <= n_flat   # ... not in this one
    assert strict.at == pytest.approx(14.0, abs=0.05) and abs(strict.before) < 0.3
    assert strict.residual < 2 * 0.2 < loose.residual


def test_quantised_readings_are_split_into_as_many_pieces_as_their_noise_pays_for():
    # 1 mA quantisation on a pretensioned current, 1 mA/deg, and 3.5 mA/deg past q = 7: five
    # pieces spend themselves on the staircase of the dead zone, and in a third of the draws the
    # edge is lost among them; as many pieces as the readings' noise pays for find it
    found = {False: 0, True: 0}
    for seed in range(30):
        rng = np.random.default_rng(seed)
        q = np.arange(0.5, 13.01, 0.5)
        c = np.round(120.0 + q + 2.5 * np.maximum(q - 7.0, 0.0) + rng.normal(0, 0.3, q.size))
        sig = 0.45                  # 0.3 mA of noise and the rounding's 1/sqrt(12) mA
        for select in (False, True):
            k = loading_edge(q, c, 1, sig, resolution=0.02, select=select)
            found[select] += k is not None and abs(k.at - 7.0) <= 0.3
    assert found[True] >= 24 and found[True] >= found[False] + 5, found


def test_a_loaded_side_may_stiffen_but_a_sag_is_not_fitted_as_one():
    # a stiffening tendon (4 mA/deg at the edge, +0.2 mA/deg per deg past it) keeps its quadratic
    # term; a loaded current that sags over its last 3 deg (a replay slowing into its own turn,
    # its friction fading) is fitted straight, as no tendon softens
    from hystcli.current import kink_fit

    rng = np.random.default_rng(15)
    q = np.arange(0.0, 20.01, 0.5)
    x = np.maximum(q - 10.0, 0.0)
    stiff = 100.0 + 4.0 * x + 0.1 * x ** 2 + rng.normal(0, 0.2, q.size)
    assert kink_fit(q, stiff, 1, min_side=2, resolution=0.02, convex=True) == \
        kink_fit(q, stiff, 1, min_side=2, resolution=0.02)
    sag = 100.0 + 4.0 * x - 1.0 * np.maximum(x - 7.0, 0.0) ** 2 + rng.normal(0, 0.2, q.size)
    assert kink_fit(q, sag, 1, min_side=2, resolution=0.02, convex=True) == \
        kink_fit(q, sag, 1, min_side=2, resolution=0.02, curved=False)
    # on a short loaded stretch the quadratic term is loose, and is left alone
    short = q <= 14.0
    assert kink_fit(q[short], sag[short], 1, min_side=2, resolution=0.02, convex=True) == \
        kink_fit(q[short], sag[short], 1, min_side=2, resolution=0.02)
