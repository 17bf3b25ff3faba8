"""Setpoints the mechanism cannot honour: clear errors, no NaN, the next good one still served."""
from mechanisms import four_bar, from_yaml, slider_crank
import numpy as np
import pytest

import cog_id_ros


def make(params):
    return cog_id_ros.InverseDynamics(cog_id_ros.Mechanism.from_parameters(params))


def long_ground():
    """Ground 0.9 m, other links 0.5 m, driven at joint1: the crank cannot point backwards."""
    return make(four_bar(ground=0.9, active=('joint1',), init=[1.2, -1.2332, 2.0244, 2.0575]))


def test_unreachable_pose_raises_closure_error_with_residual_and_keeps_the_branch():
    s = long_ground()
    good = s.solve_positions([1.3])
    with pytest.raises(cog_id_ros.ClosureError) as info:
        s.torques([np.pi], [0.0], [0.0])
    assert info.value.residual > 1e-3
    # far from the last pose the core says it cannot reach it ('unreachable', bounded
    # continuation); a pose that cannot exist at all is 'closure'
    assert info.value.reason in ('closure', 'unreachable')
    assert ('cannot be closed' in str(info.value) or 'cannot reach' in str(info.value))
    # the warm start is untouched: the next good setpoint lands on the same branch
    assert np.allclose(s.solve_positions([1.3]), good, atol=1e-9)


def test_singular_pose_raises_with_the_condition_number():
    s = make(from_yaml('config/paper_four_bar_a.yaml'))
    with pytest.raises(cog_id_ros.SingularConfigurationError) as info:
        s.torques([0.0], [0.0], [0.0])      # parallelogram flat: a change point
    assert info.value.condition_number > s.mechanism.max_condition_number
    assert 'condition number' in str(info.value)
    assert np.all(np.isfinite(s.torques([1.5], [0.0], [0.0])))


def test_redundant_setpoints_small_disagreement_projected_large_rejected():
    s = make(from_yaml('config/paper_four_bar_b.yaml'))
    th = 1.4
    exact = s.torques([th, th], [0.2, 0.2], [0.1, 0.1])
    nudged = s.torques([th + 2e-5, th], [0.2, 0.2], [0.1, 0.1])   # halfway point is th + 1e-5
    assert np.allclose(nudged, exact, atol=1e-3 * np.max(np.abs(exact)))
    ev = s.evaluate([th + 2e-5, th])
    assert np.allclose(ev.active_positions[0], [th + 1e-5, th + 1e-5], atol=1e-10)
    with pytest.raises(cog_id_ros.ClosureError) as info:
        s.torques([th + 0.01, th], [0.0, 0.0], [0.0, 0.0])
    assert abs(info.value.residual - 0.005) < 1e-6
    assert 'setpoint_tolerance' in str(info.value)


@pytest.mark.parametrize('bad', [[np.nan], [np.inf]])
def test_non_finite_setpoints_are_rejected(bad):
    s = make(from_yaml('config/paper_four_bar_a.yaml'))
    with pytest.raises(cog_id_ros.SetpointError, match='finite'):
        s.torques(bad, [0.0], [0.0])
    with pytest.raises(cog_id_ros.SetpointError, match='sample 1: qd of joint3'):
        s.torques([[1.5], [1.6]], [[0.0], bad], [[0.0], [0.0]])
    # one sample: a bad velocity or acceleration is refused too, not turned into NaN torques
    with pytest.raises(cog_id_ros.SetpointError, match='qd of joint3'):
        s.torques([1.5], bad, [0.0])
    with pytest.raises(cog_id_ros.SetpointError, match='qdd of joint3'):
        s.torques([1.5], [0.0], bad)


def test_wrong_shapes_are_rejected_with_the_expected_shape():
    s = make(from_yaml('config/paper_four_bar_b.yaml'))
    with pytest.raises(cog_id_ros.SetpointError, match=r'expected shape \(2,\)'):
        s.torques([1.5], [0.0], [0.0])
    with pytest.raises(cog_id_ros.SetpointError, match=r'qd: expected shape \(3, 2\)'):
        s.torques(np.ones((3, 2)), np.ones((2, 2)), np.ones((3, 2)))


def test_skip_mode_marks_bad_samples_and_serves_the_rest():
    s = long_ground()
    q = np.array([[1.3], [1.35], [np.pi], [np.nan], [1.4], [1.45]])
    ev = s.evaluate(q, on_invalid='skip')
    assert ev.valid.tolist() == [True, True, False, False, True, True]
    assert isinstance(ev.errors[2], cog_id_ros.ClosureError)
    assert isinstance(ev.errors[3], cog_id_ros.SetpointError)
    assert np.all(np.isfinite(ev.torques)) and np.all(ev.torques[~ev.valid] == 0.0)
    assert np.all(np.isfinite(ev.closure_residual)) or np.all(~np.isnan(ev.closure_residual))
    reference = make(four_bar(ground=0.9, active=('joint1',), init=[1.2, -1.2332, 2.0244, 2.0575]))
    assert np.allclose(ev.torques[ev.valid], reference.torques(q[ev.valid]), atol=1e-10)
    with pytest.raises(cog_id_ros.ClosureError) as info:
        s.torques(q[:3])
    assert info.value.sample == 2


def test_the_loops_never_wrap_angles_and_batch_equals_per_sample():
    s = make(slider_crank())
    t = np.linspace(0.0, 1.0, 501)
    crank = 3 * np.pi * t + 0.2 * np.sin(5 * t)          # 1.5 turns: 9.4 rad, never wrapped
    batch = s.solve_positions(crank[:, None])
    assert abs(batch[-1, 0] - crank[-1]) < 1e-12 and batch[-1, 0] > 9.0
    assert abs(batch[-1, 2] + crank[-1]) < 0.5          # the pin follows the crank: ~ -9.4 rad
    s.reset()
    serial = np.array([s.solve_positions([c]) for c in crank])
    assert np.max(np.abs(batch - serial)) < 1e-9
    s.reset()
    tau_batch = s.torques(crank[:, None], np.full((501, 1), 3.0), np.zeros((501, 1)))
    s.reset()
    tau_serial = np.array([s.torques([c], [3.0], [0.0]) for c in crank])
    assert np.max(np.abs(tau_batch - tau_serial)) < 1e-9 * np.max(np.abs(tau_serial))


def test_each_assembly_mode_is_kept_along_the_motion_and_across_calls():
    open_mode = make(four_bar(ground=0.6, crank=0.2, coupler=0.6, rocker=0.4, active=('joint1',),
                              init=[1.0, -0.6127, 1.4111, 1.0238]))
    crossed = make(four_bar(ground=0.6, crank=0.2, coupler=0.6, rocker=0.4, active=('joint1',),
                            init=[1.0, -2.0465, -2.0703, -1.0238]))
    crank = np.linspace(1.0, 1.0 + 4 * np.pi, 400)[:, None]    # two full turns
    a, b = open_mode.solve_positions(crank), crossed.solve_positions(crank)
    assert np.all(a[:, 3] > 0) and np.all(b[:, 3] < 0)        # joint4 keeps its sign per branch
    # a single far jump is followed in continuation steps, staying on the branch
    far = open_mode.solve_positions([1.0 + 4 * np.pi + 3.0])
    near = open_mode.solve_positions([1.0 + 4 * np.pi + 3.0 + 1e-3])
    assert far[3] > 0 and np.max(np.abs(far - near)) < 1e-2
