"""cog_id_ros.ros.conversions: core errors mapped to rejection reasons by their ``reason``
attribute."""
import pytest

pytest.importorskip('rclpy')

from cog_id_ros.core import ClosureError, SetpointError  # noqa: E402
from cog_id_ros.ros.conversions import REASONS, rejection  # noqa: E402


@pytest.mark.parametrize('exc, reason', [
    (SetpointError('torques overflow', reason='out_of_range'), 'out_of_range'),
    (SetpointError('some finite words', reason='malformed'), 'malformed'),
    (ClosureError('cannot reach it', 1.0, reason='unreachable'), 'unreachable'),
    (ClosureError('redundant setpoint disagrees', 1.0, reason='inconsistent'), 'inconsistent'),
    (SetpointError('q of joint3 is 2.1, outside its position limits', reason='limit'), 'limit'),
])
def test_core_errors_map_by_their_reason_not_their_text(exc, reason):
    """Reliability mapping: rejection() searched the message text ('finite' in the text
    made any SetpointError 'non_finite', a ClosureError was 'closure' or 'inconsistent');
    it maps exc.reason, and REASONS has the core's new reasons."""
    assert reason in REASONS
    assert rejection(exc).reason == reason


def test_every_core_reason_is_a_reason_of_the_node():
    from cog_id_ros.core.errors import REASONS as CORE_REASONS
    assert set(CORE_REASONS) <= set(REASONS)


def test_an_error_without_a_known_reason_is_solver():
    """Reliability mapping: anything else the solver raises is 'solver'."""
    assert rejection(RuntimeError('boom')).reason == 'solver'
    assert {'out_of_range', 'unreachable', 'jump'} <= set(REASONS)


def test_a_wrapped_trajectory_is_unwrapped_before_it_is_differentiated():
    """Reliability item 11 (trajectories): a revolute position reported in another 2 pi
    range mid-trajectory was differentiated as a jump of 2 pi (huge torques); it is
    unwrapped first, answered with the positions as received, and without unwrapping
    the step is refused as 'jump'."""
    import math

    from conftest import REPO
    import numpy as np
    from rclpy.serialization import deserialize_message, serialize_message
    from test_node import make_trajectory
    from trajectory_msgs.msg import JointTrajectory

    import cog_id_ros
    from cog_id_ros.ros.conversions import JointSelector, Rejected, solve_trajectory_message

    mech = cog_id_ros.Mechanism.from_params_file(f'{REPO}/config/paper_four_bar_a.yaml')
    t = np.arange(201) * 0.01
    th = 1.4 + 0.01 * t
    reported = np.where(t > 1.0, th - 2 * math.pi, th)
    raw = serialize_message(make_trajectory(['joint3'], reported[:, None], times=t))
    solver = cog_id_ros.InverseDynamics(mech)
    out, _, points = solve_trajectory_message(raw, solver, JointSelector(['joint3']),
                                              unwrap=[True], max_step=[1.0])
    answer = deserialize_message(out, JointTrajectory)
    effort = np.array([p.effort[0] for p in answer.points])
    np.testing.assert_allclose(effort, 9.81 * np.cos(th), atol=1e-6)   # 2 m g L cos, at rest
    assert answer.points[150].positions[0] == pytest.approx(reported[150])
    with pytest.raises(Rejected) as info:
        solve_trajectory_message(raw, solver, JointSelector(['joint3']), unwrap=[False],
                                 max_step=[1.0])
    assert info.value.reason == 'jump'


def test_a_core_message_said_of_a_measured_state():
    """Issue 22, adversarial check: a measured state the solver could not follow was logged
    with the core's setpoint advice ("Send setpoints closer together"). Said of the measured
    state now, parameter names untouched; the advice replaced is the core's own text."""
    from conftest import REPO

    import cog_id_ros
    from cog_id_ros.core.solve.sample_solve import unreachable
    from cog_id_ros.ros.conversions import MEASURED_ADVICE, UNREACHABLE_ADVICE, of_measured_state

    mech = cog_id_ros.Mechanism.from_params_file(f'{REPO}/config/paper_four_bar_a.yaml')
    start = (list(mech.assembled_positions), [0.0] * len(mech.joints))
    core = str(unreachable(mech, start, [2.0], None, 'the loops stop closing'))
    assert UNREACHABLE_ADVICE in core
    said = of_measured_state(core)
    assert said.startswith('cannot reach the measured state [2') and MEASURED_ADVICE in said
    assert 'setpoint' not in said
    inconsistent = ('the redundant setpoint disagrees with the loop closure by 0.1 (rad or m), '
                    'more than mechanism.setpoint_tolerance 0.001')
    assert of_measured_state(inconsistent) == inconsistent.replace(
        'redundant setpoint', 'redundant measured state')
