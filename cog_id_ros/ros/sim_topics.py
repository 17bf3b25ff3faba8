"""cog_sim_node's topics and service, written once: name, type, direction, QoS and meaning.

``SIM_TOPICS`` is the one table, of the same :class:`~.topics.Topic` entries as
cog_id_node's: the node creates its publishers, subscriptions and service with these names
and QoS, and docs/sim_node.md's topic table is generated from it (a test compares)::

    python -m cog_id_ros.ros.sim_topics --markdown
    python -m cog_id_ros.ros.sim_topics --write docs/sim_node.md

``effort_command`` is the name and type cog_id_node publishes its efforts on, so the two
connect without a remap. Importing this needs no ROS; :func:`clock_qos` imports rclpy when
it is called.
"""
import sys
from typing import Any

from .parameters import docs_main
from .topics import STREAM, TOPICS, Topic
from .topics import qos_text as node_qos_text

_CONTROL = 'control'
CLOCK = 'clock'
SERVICE = 'service'


def clock_qos() -> Any:
    """The QoS of ``/clock``: reliable, keep-last 1, volatile: the newest time only, heard
    by rclpy's time source (best effort) and by reliable readers alike."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                      reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)


#: the simulator's topics and its service, in the order they are documented
SIM_TOPICS: dict[str, Topic] = {t.name: t for t in (
    Topic('effort_command', 'std_msgs/Float64MultiArray', 'in', STREAM,
          'efforts, one per active joint in `mechanism.active_joints` order (`layout` '
          "ignored): cog_id_node's `effort_command`, no remap needed. Checked, then held "
          'from the next step on (zero-order hold; the newest accepted message wins); a '
          'rejected one is counted and never integrated'),
    Topic('joint_effort_command', 'sensor_msgs/JointState', 'in', STREAM,
          'the same with names: `name` must hold every active joint once (any order; '
          'other names ignored), `effort` one entry per name; `position` and `velocity` '
          'ignored'),
    Topic('joint_states', 'sensor_msgs/JointState', 'out', _CONTROL,
          'every `joint_states_period` of simulated time: every joint of `mechanism.joints` '
          '(passive ones solved from the closure) with its position and velocity; `effort`: '
          'the efforts that acted over the last step on the active joints (after clipping), '
          '0 on the passive ones (0 everywhere at time 0); stamped with the simulated time, '
          'frame_id empty'),
    Topic('/clock', 'rosgraph_msgs/Clock', 'out', CLOCK,
          'with `publish_clock`: the simulated time after every step, at start and after a '
          'reset (which sets it back to 0)'),
    Topic('/diagnostics', 'diagnostic_msgs/DiagnosticArray', 'out', 'diagnostics',
          TOPICS['/diagnostics'].description),
    Topic('~/reset', 'std_srvs/Trigger', 'service', SERVICE,
          'back to `initial_positions` at rest, time 0, no effort held; ends a stop (a '
          'singular or unreachable pose)'),
)}


def qos_text(topic: Topic) -> str:
    if topic.qos == CLOCK:
        return 'reliable, keep-last 1, volatile'
    if topic.qos == SERVICE:
        return "rclpy's services default"
    return node_qos_text(topic)


def markdown_table() -> str:
    """docs/sim_node.md's topic table, generated from SIM_TOPICS."""
    rows = ['| topic | type | dir | QoS | what |', '|---|---|---|---|---|']
    for t in SIM_TOPICS.values():
        rows.append(f'| `{t.name}` | {t.type} | {t.direction} | {qos_text(t)} | '
                    f'{t.description} |')
    return '\n'.join(rows) + '\n'


if __name__ == '__main__':
    sys.exit(docs_main('cog_id_ros.ros.sim_topics', markdown_table(), sys.argv[1:]))
