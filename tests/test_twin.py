"""The virtual catheter: determinism, the base model and current of docs/design.md sections 3-4, the
protocol's runs, and the live twin matching a batch simulation of the same motion."""
from __future__ import annotations

import math

import numpy as np
import pytest

from hystcli.core import effects as E
from hystcli.sim import live as live_twin
from hystcli.sim import twin
from hystcli.errors import DataError, ModelError
from hystcli.filters import lowpass
from hystcli.core.run import Run
from hystcli.core.params import Shape

CAT = twin.get_catheter("example-a")


def test_unknown_catheter_names_the_known_ones():
    with pytest.raises(ModelError, match="example-a, example-b"):
        twin.get_catheter("ice-z")


def test_same_seed_same_run_other_seed_other_noise():
    t, q = twin.sweep(fs=200.0)
    a = twin.simulate(CAT, t, {1: q}, seed=4)
    b = twin.simulate(CAT, t, {1: q}, seed=4)
    c = twin.simulate(CAT, t, {1: q}, seed=5)
    for col in ("y1", "c1"):
        assert np.array_equal(a[col], b[col])
        assert not np.array_equal(a[col], c[col])
    assert dict(a.meta) == dict(b.meta)


def test_noise_free_twin_is_the_shifted_base_model():
    t, q = twin.sweep(fs=200.0)
    shape = Shape.parse("alpha=45,theta=0")
    run = twin.simulate(CAT, t, {1: q}, shape=shape, noise=False)
    # paper eq. 3 by hand: (180/pi) * 1.2 mm * (pi/4) / 8 mm = 6.75 deg
    off = CAT.true_offsets(shape)[1]
    assert off == pytest.approx(6.75, abs=1e-12)
    assert float(run.meta["true_offset1"]) == pytest.approx(6.75, abs=1e-6)
    assert np.array_equal(run["y1"], CAT.knobs[1].with_offset(off).forward(q))


def test_current_is_flat_in_the_dead_zone_and_rises_with_the_tendon_taut():
    t = np.arange(4001) / 100.0
    q = -35.0 + 1.75 * t  # slow ascending pass, 1.75 deg/s: the Coulomb term saturated
    c = twin.simulate(CAT, t, {1: q}, noise=False)["c1"]
    dead = (q > -5) & (q < 5)
    assert np.ptp(c[dead]) < 1e-9
    assert c[dead][0] == pytest.approx(120.0 + 6.0 * math.tanh(1.75 / 0.5), abs=1e-9)  # no_load + coulomb
    taut = (q > 12) & (q < 30)
    # past d_pos = 9.1, after the play has settled: k_load (1 + mu) = 4 * 1.25 mA/deg
    assert np.polyfit(q[taut], c[taut], 1)[0] == pytest.approx(5.0, rel=1e-6)


def test_simulate_refuses_mismatched_commands():
    t = np.arange(10) / 100.0
    with pytest.raises(DataError, match="knob 1 commands have 5 samples"):
        twin.simulate(CAT, t, {1: np.zeros(5)})


def test_simulate_records_effects_metadata_that_parses_back():
    t, q = twin.periodic(fs=50.0)
    effs = (E.make_effect("friction", mu=0.2), E.make_effect("latency", delay=0.05))
    run = twin.simulate(CAT, t, {1: q}, effects=effs, shape=Shape.parse("alpha=90"))
    assert E.parse_effects(run.meta["effects"]) == effs


# --------------------------------------------------------------------------------------------
# the paper's protocol
# --------------------------------------------------------------------------------------------
def test_periodic_run_of_the_protocol_has_full_metadata():
    run = twin.simulate_motion(CAT, Shape.parse("alpha=90"), "periodic", seed=2, trial=3,
                               effects=(E.make_effect("creep"),))
    for key, value in {"catheter": "example-a", "controller": "none", "shape": "alpha=90,theta=0",
                       "motion": "periodic", "trial": "3", "seed": "2",
                       "effects": "creep(fraction=0.2,tau=3)"}.items():
        assert run.meta[key] == value
    assert float(run.meta["true_offset1"]) == pytest.approx(13.5, abs=1e-6)  # 2 x 6.75
    assert np.array_equal(run["q1"], run["r1"])  # controller none: q = r
    # 60 deg at 0.04 Hz, 2 cycles (docs/design.md section 7)
    assert run.t[-1] == pytest.approx(50.0) and np.max(run["r1"]) == pytest.approx(60.0, abs=1e-3)
    other = twin.simulate_motion(CAT, Shape.parse("alpha=90"), "periodic", seed=2, trial=4)
    assert not np.array_equal(run["y1"], other["y1"])  # trials differ


def test_nonperiodic_two_dof_runs_knob_2_twice_as_fast():
    run = twin.simulate_motion(CAT, Shape(), "nonperiodic", noise=False)
    t = run.t
    f = 0.02
    expected2 = 30 * (np.sin(2 * np.pi * f * 2 * t) + np.sin(2 * np.pi * f * math.sqrt(3) * 2 * t))
    assert run.knobs("q") == [1, 2]
    assert np.allclose(run["r2"], expected2, atol=1e-9)


def test_generated_motion_refuses_another_controller():
    with pytest.raises(DataError, match="needs the commands"):
        twin.simulate_motion(CAT, Shape(), "periodic", controller="comp")
    with pytest.raises(DataError, match="unknown motion"):
        twin.simulate_motion(CAT, Shape(), "zigzag")


def test_commands_are_played_with_their_controller_and_offsets():
    t = np.arange(200) / 100.0
    cmds = Run({"t": t, "r1": 10 * t, "q1": 12 * t}, {"controller": "comp+shift", "motion": "periodic",
                                                   "offset1": "6.5"})
    run = twin.simulate_motion(CAT, Shape.parse("alpha=45"), commands=cmds, noise=False)
    assert run.meta["controller"] == "comp+shift" and run.meta["offset1"] == "6.5"
    assert np.array_equal(run["q1"], 12 * t) and np.array_equal(run["r1"], 10 * t)
    with pytest.raises(DataError, match="q2"):
        twin.simulate_motion(CAT, Shape(), commands=cmds, knobs=(2,))


# --------------------------------------------------------------------------------------------
# the live twin
# --------------------------------------------------------------------------------------------
MOVES = [(1, 15.0, 20.0), (2, -12.0, 40.0), (1, -25.0, 30.0), (1, 5.0, 10.0), (2, 20.0, 25.0),
         (1, 30.0, 20.0)]


@pytest.mark.parametrize("effects", [
    (),
    (E.make_effect("rate", tau=0.2), E.make_effect("coupling", gain=0.2),
     E.make_effect("creep", fraction=0.3, tau=1.0), E.make_effect("latency", delay=0.08),
     E.make_effect("friction", mu=0.4), E.make_effect("saturation", limit=40.0),
     E.make_effect("contact", wall=12.0)),
])
def test_live_twin_matches_a_batch_simulation_of_the_concatenated_motion(effects):
    shape = Shape.parse("alpha=60,theta=20")
    live = live_twin.LiveTwin(CAT, shape=shape, effects=effects, noise=False, record=True)
    readings = [live.move(k, q, speed_deg_s=v) for k, q, v in MOVES]
    live.hold(1.5)
    rec = live.recorded()
    assert len(rec) > 5000 and np.all(np.diff(rec.t) > 0)
    batch = twin.simulate(CAT, rec.t, {1: rec["q1"], 2: rec["q2"]}, shape=shape, effects=effects,
                          noise=False)
    for k in (1, 2):
        assert np.array_equal(batch[f"y{k}"], rec[f"y{k}"])
        assert np.array_equal(batch[f"c{k}"], rec[f"c{k}"])
        # the live current goes through the causal 20 Hz filter, as a robot's would
        assert np.allclose(rec[f"cf{k}"], lowpass(batch[f"c{k}"], 1000.0, zero_phase=False),
                           rtol=0, atol=1e-9)
    # each move ends where it was sent, reading the last sample
    ends = {}
    for (k, q, _), (qa, c, y) in zip(MOVES, readings):
        assert qa == q
        ends[k] = q
    assert live.state(1)[0] == 30.0 and live.state(2)[0] == 20.0


def test_live_twin_current_reads_while_moving_and_flat_at_rest_in_the_dead_zone():
    live = live_twin.LiveTwin(CAT, noise=False, knobs=(1,))
    _, c_moving, _ = live.move(1, 3.0, speed_deg_s=20.0)
    # in the dead zone: no tension, the Coulomb term of a moving motor
    assert c_moving == pytest.approx(120.0 + 6.0 * math.tanh(20.0 / 0.5), abs=0.05)
    assert live.tip_available and live.state(1)[2] == 0.0
    with pytest.raises(DataError, match="no knob 2"):
        live.move(2, 1.0)


def test_live_twin_keeps_the_samples_of_its_last_move_or_hold():
    live = live_twin.LiveTwin(CAT, noise=False, filter_hz=None, knobs=(1,))
    assert live.last_samples(1)[0].size == 0
    # 0 -> 1 deg at 5 deg/s sampled every 1 ms: 200 samples at q_i = i / 200 (i = 1..200); the
    # robot's first sample at rest (q = 0) is not part of the move
    live.move(1, 1.0, speed_deg_s=5.0)
    q, c = live.last_samples(1)
    np.testing.assert_allclose(q, np.arange(1, 201) / 200, atol=1e-12)
    # in the dead zone, unfiltered and noise-free: no-load 120 mA + the Coulomb term of a motor
    # moving at 5 deg/s (6 tanh(5 / 0.5)), and its last value is what the move reported
    np.testing.assert_allclose(c, 120.0 + 6.0 * math.tanh(5.0 / 0.5), atol=1e-9)
    assert c[-1] == live.state(1)[1]
    live.hold(0.05)
    q, c = live.last_samples(1)
    assert q.size == 50 and np.all(q == 1.0)


def test_live_twin_is_deterministic_under_a_seed_and_can_lack_a_tracker():
    def session(seed, **kw):
        live = live_twin.LiveTwin(CAT, seed=seed, **kw)
        return [live.move(1, q) for q in (10.0, 25.0, -5.0)]

    a, b, c = session(7), session(7), session(8)
    assert a == b and a != c
    blind = session(7, tip_available=False)
    assert all(math.isnan(y) for _, _, y in blind)
    assert [x[:2] for x in blind] == [x[:2] for x in a]


def test_live_twin_shape_change_shifts_the_dead_zone_under_the_knob():
    live = live_twin.LiveTwin(CAT, noise=False, knobs=(1,))
    live.set_shape(Shape.parse("alpha=90,theta=0"))  # offset 13.5 deg (paper eq. 3)
    assert live.true_offsets[1] == pytest.approx(13.5)
    # the bend pulls the anterior-negative tendon taut under the knob at 0: u = -13.5 is on L8,
    # f_dn(-13.5) = h_neg + omega (u - d_neg) = 4.2 + 1.45 (-13.5 + 8.7) = -2.76
    _, _, y = live.move(1, 20.0)  # u = 6.5 < d_pos = 9.1: held
    assert y == pytest.approx(-2.76, abs=1e-9)
    _, _, y = live.move(1, 30.0)  # u = 16.5: on L4, h_pos + omega (u - d_pos)
    assert y == pytest.approx(-4.0 + 1.45 * (16.5 - 9.1), abs=1e-9)
