"""ros_conversions: core errors mapped to rejection reasons by their ``reason`` attribute."""
import pytest

pytest.importorskip('rclpy')

from cog_id_ros.core import ClosureError, SetpointError  # noqa: E402
from cog_id_ros.ros_conversions import REASONS, rejection  # noqa: E402


@pytest.mark.parametrize('exc, reason', [
    (SetpointError('torques overflow', reason='out_of_range'), 'out_of_range'),
    (SetpointError('some finite words', reason='malformed'), 'malformed'),
    (ClosureError('cannot reach it', 1.0, reason='unreachable'), 'unreachable'),
    (ClosureError('redundant setpoint disagrees', 1.0, reason='inconsistent'), 'inconsistent'),
])
def test_core_errors_map_by_their_reason_not_their_text(exc, reason):
    """Reliability mapping: rejection() searched the message text ('finite' in the text
    made any SetpointError 'non_finite', a ClosureError was 'closure' or 'inconsistent');
    it maps exc.reason, and REASONS has the core's new reasons."""
    assert reason in REASONS
    assert rejection(exc).reason == reason


def test_an_error_without_a_known_reason_is_solver():
    """Reliability mapping: anything else the solver raises is 'solver'."""
    assert rejection(RuntimeError('boom')).reason == 'solver'
    assert {'out_of_range', 'unreachable', 'jump'} <= set(REASONS)
