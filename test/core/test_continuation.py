"""Continuation (core/closure/continuation.py): the solver follows the assembly branch in bounded
work, whatever the setpoint: angles wrap by 2 pi, every joint's step is bounded, and the
batch path keeps only samples that sample-by-sample continuation would reach."""
import math
import time

from mechanisms import from_yaml, with_changes
import numpy as np
import pytest
from trajectories import TRAJECTORIES

import cog_id_ros


def solver(name='slider_crank', **changes):
    params = with_changes(from_yaml(f'config/{name}.yaml'), **changes)
    return cog_id_ros.InverseDynamics(cog_id_ros.Mechanism.from_parameters(params))


def elapsed(call):
    start = time.perf_counter()
    call()
    return time.perf_counter() - start


def test_a_far_revolute_setpoint_costs_what_a_near_one_does():
    """Reliability item 6: the crank 1e5 rad away is reached by the multiple of 2 pi that
    leaves at most pi to go, not in 1e6 steps of 0.1 rad (on main: seconds to minutes)."""
    s = solver()
    s.sample_torques([1.3], [0.0], [0.0])          # warm up the caches
    near = min(elapsed(lambda: (s.reset(), s.sample_torques([3.3], [0.0], [0.0])))
               for _ in range(3))
    far = min(elapsed(lambda: (s.reset(), s.sample_torques([1e5], [0.0], [0.0])))
              for _ in range(3))
    assert far < 20 * near + 0.05
    # and it is the same pose as 1e5 - 2 pi k, by a different route
    k = round((1e5 - 0.3) / (2 * math.pi))
    s.reset()
    wrapped = s.sample_torques([1e5 - 2 * math.pi * k], [0.0], [0.0])
    s.reset()
    assert s.sample_torques([1e5], [0.0], [0.0]) == pytest.approx(wrapped, rel=1e-7, abs=1e-9)


@pytest.mark.parametrize('target', [1e6, 1e300, -1e308, 1e307])
def test_huge_setpoints_are_refused_or_served_at_once(target):
    """Reliability item 6: no call hangs or grows memory on a huge setpoint; beyond
    MAX_ANGLE a revolute coordinate is out of range (SetpointError)."""
    s = solver()
    start = time.perf_counter()
    try:
        tau = s.sample_torques([target], [0.0], [0.0])
    except cog_id_ros.SetpointError as exc:
        assert exc.reason == 'out_of_range' and abs(target) > 1e9
    else:
        assert abs(target) <= 1e9 and all(map(math.isfinite, tau))
    assert time.perf_counter() - start < 2.0


def test_an_unreachable_prismatic_target_fails_at_the_first_step():
    """Reliability item 6: a slider driven 1e6 m away is refused at once as 'unreachable'."""
    s = solver(mechanism__active_joints=['slide'])
    start = time.perf_counter()
    with pytest.raises(cog_id_ros.ClosureError) as info:
        s.torques([1e6], [0.0], [0.0])
    assert time.perf_counter() - start < 1.0
    assert info.value.reason == 'unreachable'
    assert 'singular' not in str(info.value)        # item 19: not reported as singular


def test_a_trajectory_far_from_initial_positions_costs_what_a_near_one_does():
    """Reliability item 7: each trajectory starts from initial_positions; its first point
    1,900 rad away must not be walked to in 0.1 rad steps."""
    s = solver('spatial_rsur')
    t = np.linspace(0.0, 1.0, 300)
    base = (0.5 + 3.5 * t)[:, None]
    times = []
    for offset in (0.0, 2 * math.pi * 300):
        s.reset()
        times.append(elapsed(lambda: s.torques(base + offset, np.full_like(base, 3.5),
                                               np.zeros_like(base))))
    s.reset()
    near = s.torques(base, np.full_like(base, 3.5), np.zeros_like(base))
    s.reset()
    far = s.torques(base + 2 * math.pi * 300, np.full_like(base, 3.5), np.zeros_like(base))
    assert times[1] < 5 * times[0] + 0.05
    assert np.max(np.abs(far - near)) < 1e-7 * np.max(np.abs(near))


def slider_motion(s0, travel, n=201):
    """The slider moved by ``travel`` m in 2 s along a smooth cosine ramp."""
    t = np.linspace(0.0, 2.0, n)
    q = (s0 + travel * (0.5 - 0.5 * np.cos(np.pi * t / 2)))[:, None]
    qd = (travel * 0.5 * np.pi / 2 * np.sin(np.pi * t / 2))[:, None]
    qdd = (travel * 0.5 * (np.pi / 2) ** 2 * np.cos(np.pi * t / 2))[:, None]
    return q, qd, qdd


def test_the_batch_path_stays_on_the_branch_serial_continuation_follows():
    """Reliability item 10: driving the slider of slider_crank.yaml 5 cm towards its dead
    centre, the batch path returned the other assembly branch on 39 of 201 samples (4.5 N
    off), all marked valid. Every valid sample must match sample-by-sample continuation."""
    batch = solver(mechanism__active_joints=['slide'])
    s0 = batch.mechanism.assembled_positions[batch.mechanism.joints.index('slide')]
    q, qd, qdd = slider_motion(s0, -0.05)
    ev = batch.evaluate(q, qd, qdd, on_invalid='skip')
    serial = solver(mechanism__active_joints=['slide'])
    expected = np.array([serial.torques(a, b, c) for a, b, c in zip(q, qd, qdd)])
    peak = np.max(np.abs(expected))
    assert ev.valid.all()
    assert np.max(np.abs(ev.torques - expected)) < 1e-6 * peak
    # the end pose: a fresh solver asked for it at once lands where continuation did
    fresh = solver(mechanism__active_joints=['slide'])
    assert np.allclose(fresh.solve_positions(q[-1]), serial.solve_positions(q[-1]), atol=1e-8)


def test_a_continuation_step_bounds_the_passive_joints_too():
    """Reliability item 10: one call for the whole 5 cm move (steps of 0.1 m on the slider
    alone would let the passive joints jump 60 rad/m near the dead centre) ends on the
    branch of the sample-by-sample motion."""
    s = solver(mechanism__active_joints=['slide'])
    s0 = s.mechanism.assembled_positions[s.mechanism.joints.index('slide')]
    q, _, _ = slider_motion(s0, -0.05)
    step_by_step = solver(mechanism__active_joints=['slide'])
    for row in q:
        end = step_by_step.solve_positions(row)
    assert np.allclose(s.solve_positions(q[-1]), end, atol=1e-8)


def test_wrapped_encoder_angles_give_the_torques_of_the_unwrapped_motion():
    """Reliability item 11 (core side): a crank reported in (-pi, pi] is the same pose; the
    core serves each wrapped setpoint as that pose (the node and the tool add the
    unwrapping of velocities and accelerations)."""
    s, w = solver(), solver()
    t = np.linspace(0.0, 2.0, 401)
    q = 0.3 + 5.0 * t
    wrapped = (q + math.pi) % (2 * math.pi) - math.pi
    for a, b in zip(q, wrapped):
        assert s.sample_torques([a], [5.0], [0.0]) == pytest.approx(
            w.sample_torques([b], [5.0], [0.0]), rel=1e-7, abs=1e-9)


@pytest.mark.parametrize('target', [[1.5707963267948966, 1.8207963267948966],
                                    [2.5707963267948966, 1.5707963267948966]])
def test_an_inconsistent_redundant_setpoint_is_refused_as_such_in_a_few_steps(target):
    """Reliability items 6 and 19: only the primary actuators are followed by continuation,
    so a redundant setpoint the closure cannot honour is 'inconsistent' at once, not walked
    towards for the whole step budget and then called 'unreachable'."""
    s = solver('paper_four_bar_b')
    start = time.process_time()
    with pytest.raises(cog_id_ros.ClosureError) as info:
        s.torques(target)
    assert info.value.reason == 'inconsistent'
    assert time.process_time() - start < 0.5
    assert np.isfinite(s.torques([1.6, 1.6])).all()


def test_a_crank_a_million_radians_out_closes_as_near_zero_does():
    """The Newton stagnation bound scales with the coordinates Newton moves, not with a held
    actuator's angle: the Watt six-bar driven along its motion a whole number of turns away
    (about 1e6 rad) closes every sample sample by sample, with the torques of the motion
    near zero (a crank at 1e6 rad once gave up at a residual of 3e-10, 'closure')."""
    t = np.linspace(0.0, 2.0, 400)
    q, qd, qdd = TRAJECTORIES['watt_six_bar.yaml'](t)
    turns = 2.0 * math.pi * round(1e6 / (2.0 * math.pi))
    near, far = solver('watt_six_bar'), solver('watt_six_bar')
    for i in range(len(t)):
        a = near.sample_torques(q[i].tolist(), qd[i].tolist(), qdd[i].tolist())
        b = far.sample_torques((q[i] + turns).tolist(), qd[i].tolist(), qdd[i].tolist())
        assert b == pytest.approx(a, rel=1e-6, abs=1e-9), i
