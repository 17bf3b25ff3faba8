"""The node's topics, written once: name, message type, direction, QoS and meaning.

``TOPICS`` is the one table (and ``FEEDBACK_TOPICS``, those of the feedback modes, and
``FLOATING_TOPICS``, those of a floating base): the node creates its publishers and
subscriptions with these names and QoS, and docs/node.md's topic table is generated from
it (a test compares)::

    python -m cog_id_ros.ros.topics --markdown
    python -m cog_id_ros.ros.topics --write docs/node.md

Importing this needs no ROS; :func:`control_qos` imports rclpy when it is called.
"""
import dataclasses
import sys
from typing import TYPE_CHECKING

from .parameters import docs_main

if TYPE_CHECKING:
    from rclpy.qos import QoSProfile

#: keep-last depth of the control topics: 100 setpoints are 50-100 ms of a 2-1 kHz stream.
#: Deep enough that a Python pause (garbage collection, a busy core) or a burst from the
#: setpoint source loses nothing, and that a reliable writer still holds a sample when a
#: reader asks for it again; shallow enough that a node that cannot keep up drops stale
#: setpoints instead of queueing them for seconds. Keep-last, not keep-all: a slow reader
#: never blocks the publisher. Override per topic (depth 1: only the newest setpoint).
CONTROL_QOS_DEPTH = 100
#: keep-last depth of /diagnostics (rclpy's default profile otherwise)
DIAGNOSTICS_QOS_DEPTH = 10


def control_qos() -> 'QoSProfile':
    """The QoS of the control topics (a new profile each call: QoS overrides modify it)."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=CONTROL_QOS_DEPTH,
                      reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)


def stream_qos() -> 'QoSProfile':
    """The QoS of the control-rate inputs (setpoints, measured states, efforts): best
    effort, keep-last CONTROL_QOS_DEPTH, volatile. Best effort because a reliable reader
    that missed samples (its process stopped, a starved core) delivers nothing newer until
    the writer's next heartbeat has filled the gap (up to seconds, as the writer is set):
    it matches reliable and best-effort publishers alike, and every sample it missed is
    counted from the publisher's sequence numbers (``*_lost`` in diagnostics)."""
    from rclpy.qos import ReliabilityPolicy
    qos = control_qos()
    qos.reliability = ReliabilityPolicy.BEST_EFFORT
    return qos


@dataclasses.dataclass(frozen=True)
class Topic:
    """One topic of the node. ``qos``: 'control' (:func:`control_qos`, overridable),
    'stream' (:func:`stream_qos`, overridable) or 'diagnostics' (keep-last
    DIAGNOSTICS_QOS_DEPTH, not overridable)."""

    name: str
    type: str
    direction: str
    qos: str
    description: str


_CONTROL = 'control'
#: the control-rate inputs: :func:`stream_qos`
STREAM = 'stream'

#: the node's topics, in the order they are documented
TOPICS: dict[str, Topic] = {t.name: t for t in (
    Topic('joint_setpoint', 'sensor_msgs/JointState', 'in', STREAM,
          'names must include every active joint (any order; extra names ignored); '
          '`position` required; `velocity` optional (empty: estimated, see "Setpoints: the '
          'acceleration estimator"); `effort` ignored'),
    Topic('joint_trajectory', 'trajectory_msgs/JointTrajectory', 'in', _CONTROL,
          'a whole trajectory, at most `max_trajectory_points` points: positions, velocities '
          'and accelerations per point (velocities/accelerations may be left out on every '
          'point, then they are estimated as the offline tool does, 5+ points, after '
          'unwrapping revolute joints)'),
    Topic('effort_command', 'std_msgs/Float64MultiArray', 'out', _CONTROL,
          'one per accepted setpoint: efforts in `mechanism.active_joints` order'),
    Topic('joint_effort', 'sensor_msgs/JointState', 'out', _CONTROL,
          "one per accepted setpoint: active joint names, the setpoint's header (stamp and "
          'frame, unchanged), the positions **as received** (not unwrapped) and the '
          'velocities used (given or estimated), the efforts'),
    Topic('joint_states', 'sensor_msgs/JointState', 'out', _CONTROL,
          'every `joint_states_decimation`-th accepted setpoint (none when 0): every joint of '
          '`mechanism.joints` (revolute and prismatic, passive ones solved) by name, '
          'positions of the closed pose the efforts were computed at and velocities '
          '`qdot = S thetadot` (thetadot: the velocities used), stamped with the '
          "setpoint's stamp (the receipt time when that is zero) and frame: for "
          'robot_state_publisher and RViz'),
    Topic('effort_trajectory', 'trajectory_msgs/JointTrajectory', 'out', _CONTROL,
          'the received trajectory (same header, same `time_from_start`, positions as '
          'received), active joints only in `active_joints` order, with `effort` filled on '
          "every point; computed in one vectorised solver call in the node's trajectory "
          'process'),
    Topic('/diagnostics', 'diagnostic_msgs/DiagnosticArray', 'out', 'diagnostics',
          'once a `diagnostics_period`, see "Diagnostics" below'),
)}


#: topics of the feedback modes (control_mode other than feedforward) only
FEEDBACK_TOPICS: dict[str, Topic] = {t.name: t for t in (
    Topic('measured_joint_states', 'sensor_msgs/JointState', 'in (feedback modes)', STREAM,
          "the robot's measured state (remap it to the robot's `/joint_states`): names must "
          'include every active joint (any order; extra names ignored); `position` required, '
          '`velocity` required except in `gravity_compensation`; each one accepted gets one '
          '`effort_command` and one `joint_effort` (its header, the measured positions and '
          'velocities, the efforts) from the latest setpoint in force; a stale, jumping, '
          'non-finite or unclosable one gets none and a count that says why '
          '(docs/control.md)'),
)}


#: topics of a floating base (mechanism.floating_base: true) only
FLOATING_TOPICS: dict[str, Topic] = {t.name: t for t in (
    Topic('base_state', 'nav_msgs/Odometry', 'in (floating base)', STREAM,
          "the base's state (the root link of the mechanism): `pose.pose` its pose in the "
          'world frame `header.frame_id` (x, y, z, unit quaternion world from base), '
          '`twist.twist` its linear and angular velocity in the base frame (`child_frame_id`, '
          "Odometry's convention); covariances ignored; each setpoint is served with the "
          'latest one (see "Floating base")'),
    Topic('contact_wrenches/<name>', 'geometry_msgs/WrenchStamped', 'out (floating base)',
          _CONTROL,
          'one per served setpoint for each active contact (`active_contacts`; none for the '
          'others): the wrench the ground applies to the robot, force and moment about the '
          "contact point, in world axes (`frame_id`: base_state's `header.frame_id`, `world` "
          "when empty); the setpoint's stamp; a `3d` contact's moment is 0"),
    Topic('base_wrench', 'geometry_msgs/WrenchStamped', 'out (floating base)', _CONTROL,
          'one per served setpoint: what the world must still apply at the base for the '
          'motion (`whole_body_torques`: zero when the contacts balance it), force and moment '
          'in the base frame at its origin (`frame_id`: the base link)'),
)}


#: cog_transmission_node's topics (docs/node.md, "Joint space (command_space) and
#: cog_transmission_node")
TRANSMISSION_TOPICS: dict[str, Topic] = {t.name: t for t in (
    Topic('joint_command', 'sensor_msgs/JointState', 'in', STREAM,
          'joint-space command: names include every joint of `mechanism.joint_space` (any '
          'order, extra names ignored); any of positions, velocities, efforts, positions '
          'required when velocities or efforts are given (the map needs the pose)'),
    Topic('actuator_command', 'sensor_msgs/JointState', 'out', _CONTROL,
          'one per accepted joint_command: its header, `mechanism.active_joints`, each field '
          'it carried mapped (`to_actuator_space`, `actuator_velocities`, `actuator_efforts`)'),
    Topic('actuator_states', 'sensor_msgs/JointState', 'in', STREAM,
          "the motors' measured state: names include every active joint; positions "
          'required, velocities and efforts optional'),
    Topic('joint_states', 'sensor_msgs/JointState', 'out', _CONTROL,
          'one per accepted actuator_states: every joint of `mechanism.joints` (the joint '
          'space and every passive joint solved), velocities `S thetadot`, efforts '
          '`joint_efforts` on the joint space (the measured one on a motor outside it, 0 '
          'on a passive joint)'),
    Topic('/diagnostics', 'diagnostic_msgs/DiagnosticArray', 'out', 'diagnostics',
          'once a `diagnostics_period`: counts per input and reason'),
)}


def qos_text(topic: Topic) -> str:
    if topic.qos == _CONTROL:
        return f'reliable, keep-last {CONTROL_QOS_DEPTH}, volatile (overridable)'
    if topic.qos == STREAM:
        return f'best effort, keep-last {CONTROL_QOS_DEPTH}, volatile (overridable)'
    return f'reliable, keep-last {DIAGNOSTICS_QOS_DEPTH}'


def markdown_table() -> str:
    """docs/node.md's topic table, generated from TOPICS."""
    rows = ['| topic | type | dir | QoS | what |', '|---|---|---|---|---|']
    for t in (*TOPICS.values(), *FEEDBACK_TOPICS.values(), *FLOATING_TOPICS.values()):
        rows.append(f'| `{t.name}` | {t.type} | {t.direction} | {qos_text(t)} | '
                    f'{t.description} |')
    return '\n'.join(rows) + '\n'


if __name__ == '__main__':
    sys.exit(docs_main('cog_id_ros.ros.topics', markdown_table(), sys.argv[1:]))
