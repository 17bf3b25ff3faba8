"""The setpoint acceleration estimator (cog_id_ros.setpoint_filter): pure numpy, no ROS."""
import math

import numpy as np
import pytest

from cog_id_ros.ros.setpoint_filter import NANOSECONDS, SetpointFilter, StampError

# a stamp in 2025: float seconds would lose ~0.2 us of resolution here, integers lose none
EPOCH_NS = 1_750_000_000 * NANOSECONDS


def target(t):
    """The paper's target motion and its derivatives."""
    w = math.pi
    return (math.pi / 2 + 0.5 * math.sin(w * t), 0.5 * w * math.cos(w * t),
            -0.5 * w * w * math.sin(w * t))


def run(filt, times, with_velocity, epoch_ns=EPOCH_NS):
    """Feed the target motion at ``times`` (s); returns the estimates (N, 2) and exact (N, 2)."""
    est, exact = [], []
    for t in times:
        q, v, a = target(t)
        stamp = epoch_ns + int(round(t * NANOSECONDS))
        vel = [v] if with_velocity else None
        ve, ae = filt.estimate(stamp, [q], vel)
        filt.accept(stamp, [q], vel)
        est.append((ve[0], ae[0]))
        exact.append((v, a))
    return np.array(est), np.array(exact)


@pytest.mark.parametrize('with_velocity', [False, True])
def test_paper_motion_at_1khz_is_accurate_after_warm_up(with_velocity):
    filt = SetpointFilter(1)
    times = np.arange(0, 2.0001, 1e-3)
    est, exact = run(filt, times, with_velocity)
    warm = filt.window
    # no lag: the error is a truncation error of order h^2, far below the 1 % target
    assert np.max(np.abs(est[warm:, 1] - exact[warm:, 1])) < 5e-5
    assert np.max(np.abs(est[warm:, 0] - exact[warm:, 0])) < 1e-7


def test_first_sample_has_zero_acceleration_and_velocity_from_the_message():
    filt = SetpointFilter(2)
    v, a = filt.estimate(EPOCH_NS, [1.0, 2.0], [0.5, -0.5])
    assert v == [0.5, -0.5] and a == [0.0, 0.0]
    v, a = filt.estimate(EPOCH_NS, [1.0, 2.0])
    assert v == [0.0, 0.0] and a == [0.0, 0.0]


def test_two_positions_give_a_velocity_and_no_acceleration():
    filt = SetpointFilter(1)
    filt.accept(EPOCH_NS, [1.0])
    v, a = filt.estimate(EPOCH_NS + NANOSECONDS // 100, [1.02])
    assert v[0] == pytest.approx(2.0) and a[0] == 0.0


@pytest.mark.parametrize('window', [3, 4, 5, 6])
def test_polynomials_are_exact_on_uneven_stamps(window):
    """Positions of degree window-1 are differentiated exactly, whatever the spacing."""
    rng = np.random.default_rng(window)
    times = np.cumsum(rng.uniform(0.5e-3, 2e-3, size=12))
    coef = rng.normal(size=window)            # degree window - 1
    dcoef, ddcoef = np.polyder(coef), np.polyder(coef, 2)
    filt = SetpointFilter(1, window=window)
    for k, t in enumerate(times):
        stamp = EPOCH_NS + int(round(t * NANOSECONDS))
        ts = (stamp - EPOCH_NS) / NANOSECONDS   # the time the filter sees, exactly
        v, a = filt.estimate(stamp, [np.polyval(coef, ts) + 40.0])   # large unwrapped angle
        filt.accept(stamp, [np.polyval(coef, ts) + 40.0])
        if k >= window - 1:
            assert v[0] == pytest.approx(np.polyval(dcoef, ts), abs=1e-6)
            assert a[0] == pytest.approx(np.polyval(ddcoef, ts), abs=1e-3)


def test_velocity_stream_uses_velocities_for_the_acceleration():
    """With velocities given, a quadratic velocity is differentiated exactly."""
    filt = SetpointFilter(1)   # window 4: 3 velocities
    for k in range(6):
        t = k * 1e-3
        stamp = EPOCH_NS + k * 1_000_000
        # positions deliberately inconsistent with the velocities: they must not be used
        v, a = filt.estimate(stamp, [0.0], [3 * t * t + 2 * t])
        filt.accept(stamp, [0.0], [3 * t * t + 2 * t])
        if k >= 2:
            assert a[0] == pytest.approx(6 * t + 2, rel=1e-9)


def test_mixed_stream_falls_back_to_positions():
    filt = SetpointFilter(1)
    for k in range(4):
        stamp = EPOCH_NS + k * 1_000_000
        t = k * 1e-3
        filt.accept(stamp, [t * t], None if k == 2 else [2 * t])
    stamp = EPOCH_NS + 4 * 1_000_000
    # the newest history entry has a velocity but the one before has not: only 1 velocity
    # of history is used (a backward difference), positions are not mixed in
    v, a = filt.estimate(stamp, [16e-6], [8e-3])
    assert v[0] == 8e-3 and a[0] == pytest.approx(2.0)


@pytest.mark.parametrize('offset_ns, word', [(0, 'repeats'), (-1, 'goes back')])
def test_stamp_that_does_not_increase_is_rejected_and_changes_nothing(offset_ns, word):
    filt = SetpointFilter(1)
    filt.accept(EPOCH_NS, [0.0])
    filt.accept(EPOCH_NS + 1_000_000, [1e-3])
    with pytest.raises(StampError, match=word):
        filt.estimate(EPOCH_NS + 1_000_000 + offset_ns, [5.0])
    assert filt.history == 2 and filt.last_stamp_ns == EPOCH_NS + 1_000_000
    v, _ = filt.estimate(EPOCH_NS + 2_000_000, [2e-3])
    assert v[0] == pytest.approx(1.0)


def test_gap_restarts_the_estimator_cleanly():
    filt = SetpointFilter(1, max_interval=0.05)
    times = np.arange(0, 0.02, 1e-3)
    run(filt, times, False)
    late = EPOCH_NS + int(0.5 * NANOSECONDS)
    assert filt.restarts_at(late)
    v, a = filt.estimate(late, [3.0])
    assert v[0] == 0.0 and a[0] == 0.0        # no difference across the gap
    filt.accept(late, [3.0])
    assert filt.history == 1
    # and it converges again from there on
    est, exact = run(filt, 0.5 + 1e-3 * np.arange(1, 10), False)
    assert abs(est[-1, 1] - exact[-1, 1]) < 1e-4


def test_reset_accepts_any_stamp():
    filt = SetpointFilter(1)
    filt.accept(EPOCH_NS, [0.0])
    filt.reset()
    filt.check_stamp(EPOCH_NS - NANOSECONDS)   # a stream that starts over: no error
    assert filt.history == 0


def test_arguments_are_checked():
    with pytest.raises(ValueError, match='window'):
        SetpointFilter(1, window=2)
    with pytest.raises(ValueError, match='max_interval'):
        SetpointFilter(1, max_interval=0.0)
