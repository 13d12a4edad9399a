"""The judgements bench/zoo.py makes on the plant's truth before it scores detect-shift: how well
any method could place the kink the search needs (:func:`zoo.hinge_bound`, the Cramer-Rao bound,
and :func:`zoo.edge_placeable_se` on a zoo replay). A bound that is too small would count cases
no method can read against the search; one too large would excuse the search's failures."""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from hystcli.io import parse_run
from hystcli.zoo import plants

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
import zoo  # noqa: E402


def _kink_by_grid(x: np.ndarray, ys: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """Least-squares kink of every column of ``ys`` by brute force over ``grid`` (written here
    apart from the bench: projection residuals of the three-column design at each kink)."""
    best = np.full(ys.shape[1], np.inf)
    at = np.zeros(ys.shape[1])
    for e in grid:
        a = np.column_stack([np.ones_like(x), x - e, np.maximum(x - e, 0.0)])
        q, _ = np.linalg.qr(a)
        r = ys - q @ (q.T @ ys)
        sse = np.sum(r * r, axis=0)
        better = sse < best
        best[better], at[better] = sse[better], e
    return at


def test_hinge_bound_is_the_spread_of_a_least_squares_kink():
    # readings every 0.5 deg, a flat 10 deg long and a loaded stretch 6 deg long rising 4 mA/deg,
    # noise 1 mA: the least-squares kink of many noisy draws spreads as the bound says (the
    # estimator is asymptotically efficient: within 15 % on 600 draws)
    x = np.arange(-10.0, 6.0, 0.5) + 0.13
    true = 5.0 + 4.0 * np.maximum(x, 0.0)
    sig = 1.0
    bound = zoo.hinge_bound(x, true, sig)
    rng = np.random.default_rng(7)
    ys = true[:, None] + sig * rng.standard_normal((x.size, 600))
    est = _kink_by_grid(x, ys, np.arange(-2.0, 2.0, 0.005))
    assert 0.85 * bound < float(np.std(est)) < 1.15 * bound
    # it scales with the noise and shrinks with the slope change
    assert zoo.hinge_bound(x, true, 2 * sig) == pytest.approx(2 * bound)
    assert zoo.hinge_bound(x, 5.0 + 8.0 * np.maximum(x, 0.0), sig) < bound


def test_a_kink_with_one_side_unread_has_no_bound():
    x = np.array([-1.0, 0.5, 1.0, 1.5])
    assert math.isinf(zoo.hinge_bound(x, np.maximum(x, 0.0), 1.0))


def test_edge_placeable_on_a_zoo_replay():
    # design replay 1 (pretension): its edge lies within the travel limit, and the search reads it
    case = plants.replay_case(1)
    rep = parse_run(case.replay.csv_text(), source="replay-1")
    bound = zoo.edge_placeable_se(case, rep, 54.0)
    assert 0.0 < bound <= zoo.PLACEABLE_SE
    # a travel limit of one step reads no loaded stretch past an edge away from the start
    assert math.isinf(zoo.edge_placeable_se(case, rep, 0.5))


def _replay_q(seed: int):
    case = plants.replay_case(seed)
    return case, np.asarray(parse_run(case.replay.csv_text(), source=f"replay-{seed}")["q1"], float)


@pytest.mark.parametrize("seed, travel, expected", [
    # design replay 0: the positive tendon taut at the start (edge -11.16, the knob at 0); the
    # record goes down to -57.4, past where that tendon is slack on any law (-11.16 - 4.70 - 2.5),
    # and back up past -11.16 + 3: a walk back can read it, within a travel of 40 deg, not of 5
    (0, 40.0, True), (0, 5.0, False),
    # 76: the negative tendon taut (edge 5.01, backlash 23.16): slack only from 30.7 deg on, and
    # the record turns at 21.6
    (76, 40.0, False),
    # 932: the positive tendon taut (edge -21.23, backlash 8.59); the record never goes below -11.6
    (932, 40.0, False),
    # 1281: a slack start (the positive edge at 0.65 lies ahead of the knob at 0): no walk back
    (1281, 40.0, False),
])
def test_a_walk_back_is_counted_only_where_the_replay_lets_the_tendon_go_slack_and_return(seed, travel, expected):
    case, q = _replay_q(seed)
    assert zoo.walk_back_reachable(case, q, travel) is expected
