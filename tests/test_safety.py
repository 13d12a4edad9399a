"""hystcli.safety: what a command trajectory asks of a motor, against the limits.

Figures are worked by hand on small trajectories; the properties (scaling, the mean-value bound,
ramps) are checked with hypothesis over many.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hystcli.errors import DataError, SafetyStop
from hystcli.core.run import Run
from hystcli.safety import (DEFAULT_MAX_SPEED, DEFAULT_TRAVEL, LimitExceeded, Limits, RateLimiter,
                            check_motion, check_target, knob_motion, plan_motion, rate_limit,
                            require_within)


def test_peaks_by_hand():
    # q: 0, 1, 3, 3 at t 0, 1, 2, 4: steps of 1, 2, 0 deg over 1, 1, 2 s -> speeds 1, 2, 0 deg/s;
    # accelerations between steps: (2 - 1) / 1 = 1 and (0 - 2) / 1.5 = -1.333 deg/s^2
    m = knob_motion([0, 1, 2, 4], [0, 1, 3, 3], 1)
    assert (m.q_min, m.q_max) == (0.0, 3.0)
    assert m.peak_speed == pytest.approx(2.0) and m.peak_speed_t == 1.0 and m.peak_speed_row == 1
    assert m.peak_accel == pytest.approx(4 / 3) and m.peak_accel_t == 2.0
    assert m.peak_angle == 3.0


def test_a_jump_is_its_size_over_one_sample():
    # the inverse model's reversal: 40 deg within one 10 ms sample = 4000 deg/s
    t = np.arange(6) * 0.01
    q = np.array([0.0, 0.1, 0.2, 40.2, 40.1, 40.0])
    m = knob_motion(t, q, 2)
    assert m.peak_speed == pytest.approx(4000.0) and m.peak_speed_t == pytest.approx(0.02)
    check = check_motion(Run({"t": t, "q2": q}), Limits())
    assert [(v.knob, v.limit, v.count) for v in check.violations] == [(2, "speed", 1)]
    assert check.violations[0].value == pytest.approx(4000.0)
    assert "knob 2 moves at 4000.0 deg/s at t=0.02 s, beyond the speed limit 360 deg/s" in \
        check.violations[0].message


def test_limits_defaults_and_validation():
    lim = Limits()
    assert (lim.travel, lim.max_speed, lim.max_accel) == (DEFAULT_TRAVEL, DEFAULT_MAX_SPEED, None)
    for bad in (dict(travel=0), dict(max_speed=-1), dict(max_speed=math.nan), dict(travel=math.inf),
                dict(max_accel=0.0)):
        with pytest.raises(DataError, match="limit must be a positive number"):
            Limits(**bad)
    # a device's own limits tighten, never loosen
    assert Limits(100, 50).tightened(travel=170, max_speed=20) == Limits(100, 20)
    assert Limits(100, 50).tightened() == Limits(100, 50)


@pytest.mark.parametrize("t, q, words", [
    ([0, 1, 2], [0, math.nan, 1], "column q1 has a non-finite value (nan) at row 1"),
    ([0, 1, 2], [0, 1, math.inf], "at row 2"),
    ([0, math.nan, 2], [0, 1, 1], "column t has a non-finite value"),
    ([0, 1, 1], [0, 1, 2], "strictly increasing (row 2"),
    ([0], [0], "at least 2 samples"),
])
def test_bad_values_are_data_errors_naming_the_row(t, q, words):
    with pytest.raises(DataError) as exc:
        knob_motion(t, q, 1, "cmds.csv")
    assert "cmds.csv" in str(exc.value) and words in str(exc.value)


def test_huge_finite_commands_are_beyond_limits_not_nan():
    # 1e308 - (-1e308) overflows: still a violation of every limit, never a NaN that passes
    t = np.array([0.0, 1.0, 2.0])
    q = np.array([-1e308, 1e308, -1e308])
    check = check_motion(Run({"t": t, "q1": q}), Limits(max_accel=1.0))
    assert {v.limit for v in check.violations} == {"travel", "speed", "accel"}
    assert check.knobs[1].peak_speed == math.inf


def test_travel_violation_reports_the_worst_sample_and_counts():
    t = np.arange(5.0)
    q = np.array([0.0, 120.0, -190.0, 185.0, 10.0])
    check = check_motion(Run({"t": t, "q1": q}), Limits(travel=180, max_speed=1e6))
    (v,) = check.violations
    assert (v.limit, v.value, v.t, v.count) == ("travel", 190.0, 2.0, 2)
    assert "knob 1 reaches 190.0 deg at t=2 s, beyond the travel limit +-180 deg (2 samples)" == v.message


def test_require_within_refuses_or_lets_through():
    t = np.arange(4) * 0.01
    run = Run({"t": t, "q1": [0.0, 10.0, 10.0, 10.0], "q2": [0.0, 0.0, 0.0, 200.0]}, source="c.csv")
    check = check_motion(run, Limits())
    assert {(v.knob, v.limit) for v in check.violations} == {(1, "speed"), (2, "speed"), (2, "travel")}
    with pytest.raises(LimitExceeded, match=r"refusing to play c.csv: knob 1 moves at 1000.0 deg/s.*"
                                            r"\(and 2 more\)") as exc:
        require_within(check, name="c.csv")
    assert exc.value.check is check and isinstance(exc.value, SafetyStop)
    # fast steps may be allowed; travel never
    with pytest.raises(LimitExceeded, match="knob 2 reaches 200.0 deg"):
        require_within(check, allow=("speed", "accel"), name="c.csv")
    ok = check_motion(Run({"t": t, "q1": [0.0, 1.0, 2.0, 3.0]}), Limits())
    assert ok.ok and require_within(ok) is ok
    assert ok.to_dict()["within_limits"] is True and ok.to_dict()["knobs"]["1"]["peak_speed"] == pytest.approx(100)


def test_check_motion_needs_a_command_column():
    with pytest.raises(DataError, match="no knob command column"):
        check_motion(Run({"t": [0.0, 1.0], "r1": [0.0, 1.0]}))


def test_check_target():
    assert check_target(1, 10, Limits(travel=20)) == 10.0
    with pytest.raises(SafetyStop, match=r"knob 2: target \+25.00 deg is beyond the travel limit \+-20 deg; nothing moved"):
        check_target(2, 25.0, Limits(travel=20))
    with pytest.raises(DataError, match="not a finite number"):
        check_target(1, math.nan, Limits())


# ------------------------------------------------------------------------------------------
# properties
# ------------------------------------------------------------------------------------------
times = st.lists(st.floats(1e-3, 10.0), min_size=1, max_size=40).map(lambda d: np.cumsum([0.0, *d]))


@st.composite
def trajectories(draw):
    t = draw(times)
    q = np.array(draw(st.lists(st.floats(-170.0, 170.0), min_size=len(t), max_size=len(t))))
    return t, q


@settings(max_examples=200, deadline=None)
@given(trajectories(), st.floats(-20.0, 20.0).filter(lambda c: abs(c) > 1e-3))
def test_scaling_the_commands_scales_speed_and_acceleration(tq, c):
    t, q = tq
    a, b = knob_motion(t, q, 1), knob_motion(t, c * q, 1)
    assert b.peak_speed == pytest.approx(abs(c) * a.peak_speed, rel=1e-9, abs=1e-9)
    assert b.peak_accel == pytest.approx(abs(c) * a.peak_accel, rel=1e-9, abs=1e-6)


@settings(max_examples=200, deadline=None)
@given(trajectories())
def test_peak_speed_bounds_the_mean_speed(tq):
    # mean-value bound: somewhere the knob moves at least as fast as on average, and the
    # speed check agrees with the measurement exactly at the peak
    t, q = tq
    m = knob_motion(t, q, 1)
    assert m.peak_speed >= abs(q[-1] - q[0]) / (t[-1] - t[0]) * (1 - 1e-12)
    assert m.q_min <= q[0] <= m.q_max
    run = Run({"t": t, "q1": q})
    # (a peak speed in the subnormal range has no float just below it: nothing to refuse there)
    if m.peak_speed > 1e-300:
        assert check_motion(run, Limits(max_speed=m.peak_speed * 1.000001)).ok
        assert check_motion(run, Limits(max_speed=m.peak_speed * 0.999999)).exceeds("speed")


@settings(max_examples=100, deadline=None)
@given(times.filter(lambda t: len(t) >= 3), st.floats(-300.0, 300.0))
def test_a_ramp_has_its_slope_and_no_acceleration(t, v):
    m = knob_motion(t, v * (t - t[0]), 1)
    assert m.peak_speed == pytest.approx(abs(v), rel=1e-9, abs=1e-9)
    assert m.peak_accel == pytest.approx(0.0, abs=1e-6 * max(1.0, abs(v)) / min(np.diff(t)))


# ------------------------------------------------------------------------------------------
# rate limiting
# ------------------------------------------------------------------------------------------
def test_a_jump_is_crossed_at_the_speed_limit_by_hand():
    # a 10 deg jump at 100 Hz under 360 deg/s: 3.6 deg a sample, so 3 samples to land (3.6, 7.2,
    # then the rest), after which the commands are the asked ones again
    t = np.arange(8) * 0.01
    q = np.array([0.0, 0.1, 10.2, 10.3, 10.4, 10.5, 10.6, 10.7])
    out, c = rate_limit(t, q, 1, Limits())
    np.testing.assert_allclose(out[:5], [0.0, 0.1, 0.1 + 3.6, 0.1 + 7.2, 10.4], atol=1e-6)
    np.testing.assert_array_equal(out[4:], q[4:])
    # lagging at samples 2 and 3 (t=0.02 and 0.03), landed at t=0.04
    assert (c.episodes, c.samples, c.caught_up) == (1, 2, True)
    assert c.longest == pytest.approx(0.02) and c.longest_t == pytest.approx(0.02)
    assert c.total == pytest.approx(0.02)
    assert c.largest_gap == pytest.approx(10.2 - 3.7, abs=1e-6)
    assert "by up to 0.02 s (from t=0.02 s)" in c.message and "once" in c.message
    # within limits: nothing to say
    assert rate_limit(t, np.linspace(0, 1, 8), 1, Limits())[1] is None


def test_a_catch_up_under_way_at_the_end_counts_to_the_last_sample():
    t = np.arange(4) * 0.01
    out, c = rate_limit(t, [0.0, 0.0, 50.0, 50.0], 2, Limits())
    assert out[-1] == pytest.approx(7.2, abs=1e-6)
    assert not c.caught_up and c.longest == pytest.approx(0.01) and "had not caught up" in c.message


_targets = st.lists(st.floats(-60, 60), min_size=3, max_size=60)


@settings(max_examples=150, deadline=None)
@given(_targets, st.floats(5.0, 2000.0), st.one_of(st.none(), st.floats(50.0, 1e5)),
       st.floats(0.001, 0.05))
def test_rate_limited_commands_keep_to_the_limits_and_land_on_a_resting_target(qs, vmax, amax, dt):
    """Any commands, any limits: what the limiter sends passes the same check that refuses the
    asked ones, and a target that then rests long enough is reached exactly."""
    rest = 2 * (120.0 / (vmax * dt) + (vmax / amax / dt if amax else 0.0)) + 10
    q = np.array(qs + [qs[-1]] * int(rest))
    t = np.arange(q.size) * dt
    out, _ = rate_limit(t, q, 1, Limits(max_speed=vmax, max_accel=amax))
    check = check_motion(Run({"t": t, "q1": out}), Limits(travel=1e9, max_speed=vmax, max_accel=amax))
    assert check.ok, check.violations
    assert out[-1] == q[-1]
    if amax is None:  # without an acceleration limit the knob never passes what it was asked
        assert out.min() >= q.min() and out.max() <= q.max()


@settings(max_examples=100, deadline=None)
@given(st.floats(-30, 30), st.floats(1.0, 30.0), st.floats(50.0, 1e4))
def test_with_an_acceleration_limit_a_moving_command_is_caught_without_overshoot(jump, speed, amax):
    """A ramp (a command moving at its own speed) with one jump, once the knob has taken up the
    ramp's speed (from rest, with the lag that builds meanwhile, about 2 speed / amax: under
    1.2 s here): the knob brakes in time and lands
    on the ramp, never beyond it in the jump's direction."""
    dt = 0.01
    t = np.arange(4000) * dt
    q = speed * t + np.where(t >= 5.0, jump, 0.0)
    out, c = rate_limit(t, q, 1, Limits(max_speed=360.0, max_accel=amax))
    assert out[-1] == q[-1] and (c is None or c.caught_up)
    assert np.all(out[(t > 3.0) & (t < 5.0)] == q[(t > 3.0) & (t < 5.0)])
    past = ((out - q) * np.sign(jump))[t >= 5.0]
    assert past.max() <= 1e-9


def test_the_limiter_steps_as_the_batch_runs():
    t = np.arange(50) * 0.02
    q = np.where(t > 0.3, 30.0, 0.0) + 5 * np.sin(t)
    batch, c = rate_limit(t, q, 1, Limits(max_accel=3000.0))
    lim = RateLimiter(1, 360.0, 3000.0)
    assert [lim.step(a, b) for a, b in zip(q, t)] == batch.tolist()
    assert lim.catch_up() == c
    lim.reset()
    assert lim.step(99.0, 5.0) == 99.0 and lim.catch_up() is None


def test_plan_motion_by_mode():
    t = np.arange(12) * 0.01
    run = Run({"t": t, "q1": np.where(t > 0.015, 20.0, 0.0), "q2": np.zeros(t.size)})
    with pytest.raises(LimitExceeded, match="beyond the speed limit 360"):
        plan_motion(run, Limits(), "strict")
    fast = plan_motion(run, Limits(), "fast")
    assert fast.run is run and not fast.sent.ok and not fast.catch_ups
    limited = plan_motion(run, Limits(), "limit")
    assert limited.sent.ok and not limited.check.ok and set(limited.catch_ups) == {1}
    np.testing.assert_array_equal(limited.run["q2"], run["q2"])  # a knob within the limits is kept
    assert limited.run["q1"][-1] == 20.0 and limited.run["q1"][2] < 20.0
    # travel is never waived, whatever the mode
    for mode in ("strict", "fast", "limit"):
        with pytest.raises(LimitExceeded, match="travel limit"):
            plan_motion(run, Limits(travel=10.0), mode)
    with pytest.raises(DataError, match="speed mode"):
        plan_motion(run, Limits(), "slow")
