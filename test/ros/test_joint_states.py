"""cog_id_node's joint_states: the closed pose of every joint, for robot_state_publisher.

Nodes run as subprocesses (conftest.py) on the paper's four-bar (a) and the Stewart
platform; a probe in this process plays a short motion into each and records
joint_effort and joint_states. What the node publishes is checked against the core: the
names are Mechanism.joints, the positions those of solve_positions along the same
setpoints, which close every loop to the closure tolerance, and the velocities the joint
rates S thetadot of the velocities the node used (they satisfy A qdot = 0). Then
decimation: every Nth served setpoint, the first included, and 0 turns the topic off.
"""
import threading
import time

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')

from conftest import wait_until  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from trajectories import TRAJECTORIES  # noqa: E402

import cog_id_ros  # noqa: E402
from cog_id_ros.core.closure import closure  # noqa: E402
from cog_id_ros.core.kinematics import kinematics  # noqa: E402
from cog_id_ros.core.linalg import spatial  # noqa: E402
from cog_id_ros.ros.node import control_qos  # noqa: E402
from cog_id_ros.ros.player import RECORDER_QOS  # noqa: E402

NS = 1_000_000_000
STEP_NS = 1_000_000          # 1 kHz stamps
FOUR_BAR = 'paper_four_bar_a.yaml'
STEWART = 'stewart_6ups.yaml'


class Probe:
    """Publishes setpoints into one node's namespace; records joint_effort and joint_states."""

    def __init__(self, context, namespace):
        self.namespace = namespace
        self.node = rclpy.create_node('joint_states_probe' + namespace.replace('/', '_'),
                                      namespace=namespace, context=context)
        self.setpoints = self.node.create_publisher(JointState, 'joint_setpoint', control_qos())
        self.efforts, self.states = [], []
        self.node.create_subscription(JointState, 'joint_effort', self.efforts.append,
                                      RECORDER_QOS)
        self.node.create_subscription(JointState, 'joint_states', self.states.append,
                                      RECORDER_QOS)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self._thread = threading.Thread(target=self.executor.spin, daemon=True)
        self._thread.start()

    def close(self):
        self.executor.shutdown()
        self.node.destroy_node()

    def connected(self, joint_states=True):
        ns = self.namespace
        return wait_until(lambda: self.setpoints.get_subscription_count() > 0
                          and self.node.count_publishers(f'{ns}/joint_effort') > 0
                          and (not joint_states
                               or self.node.count_publishers(f'{ns}/joint_states') > 0))

    def play(self, names, q, qd=None):
        """Setpoints 1 ms apart (stamps from now on); returns their stamps once every one
        was answered on joint_effort."""
        start = time.time_ns()
        stamps = [start + k * STEP_NS for k in range(len(q))]
        for k, stamp in enumerate(stamps):
            msg = JointState()
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp, NS)
            msg.header.frame_id = 'base'
            msg.name = list(names)
            msg.position = [float(x) for x in q[k]]
            msg.velocity = [] if qd is None else [float(x) for x in qd[k]]
            self.setpoints.publish(msg)
        assert wait_until(lambda: {_ns(m) for m in self.efforts} >= set(stamps)), \
            f'{len(self.efforts)} of {len(stamps)} setpoints answered'
        return stamps


def _ns(msg):
    return msg.header.stamp.sec * NS + msg.header.stamp.nanosec


def motion(name, n):
    """(q, qd) of the test motion of config ``name``: its first n ms."""
    q, qd, _ = TRAJECTORIES[name](np.arange(n) * 1e-3)
    return q, qd


@pytest.fixture(scope='module')
def nodes(ros_process, rclpy_context):
    """name -> (process, probe): four-bar and Stewart publishing every setpoint, the
    four-bar every 3rd, and with the topic off."""
    specs = {
        'every': (FOUR_BAR, '1'),
        'stewart': (STEWART, '1'),
        'third': (FOUR_BAR, '3'),
        'off': (FOUR_BAR, '0'),
    }
    procs = {}
    for key, (config, decimation) in specs.items():
        procs[key] = ros_process(['cog_id_node', '--ros-args', '--params-file',
                                  f'config/{config}', '-r', f'__ns:=/js_{key}',
                                  '-p', f'joint_states_decimation:={decimation}',
                                  '-p', 'setpoint_timeout:=0.0'])
    for key, proc in procs.items():
        assert proc.wait_for_output("mechanism '", timeout=120), proc.output
    probes = {key: Probe(rclpy_context, f'/js_{key}') for key in procs}
    for key, probe in probes.items():
        assert probe.connected(joint_states=key != 'off'), procs[key].output
    yield {key: (procs[key], probes[key]) for key in procs}
    for probe in probes.values():
        probe.close()
    for key, proc in procs.items():
        assert proc.stop() == 0, f'{key}:\n{proc.output}'


@pytest.fixture(scope='module')
def mechanisms():
    return {name: cog_id_ros.Mechanism.from_params_file(f'config/{name}')
            for name in (FOUR_BAR, STEWART)}


def check_poses(mechanism, setpoints, efforts, states):
    """Every joint_states message against the core, along the setpoints in order.

    ``setpoints``: the active positions sent, by stamp (in order); ``efforts``: the
    joint_effort of each stamp (its velocities are the ones the node used).
    """
    reference = cog_id_ros.InverseDynamics(mechanism)
    model = mechanism.model
    tolerance = mechanism.closure_tolerance
    by_stamp = {_ns(m): m for m in states}
    checked = 0
    for stamp, q in setpoints.items():
        expected = reference.solve_positions(q)          # the warm start follows the stream
        msg = by_stamp.get(stamp)
        if msg is None:
            continue
        checked += 1
        assert list(msg.name) == list(mechanism.joints)
        assert msg.header.frame_id == 'base'
        positions = np.array(msg.position)
        np.testing.assert_allclose(positions, expected, rtol=0, atol=1e-9)
        by_name = reference.solve_positions_by_name(q)
        assert [by_name[j] for j in mechanism.joints] == pytest.approx(msg.position, abs=1e-9)
        # the loops close at the published positions
        q_all = positions.tolist()
        frames = kinematics.forward_kinematics(model, q_all, spatial.ScalarOps)
        loops = closure.loop_closure(model, frames, q_all, spatial.ScalarOps)
        residual = max(abs(r) for loop in loops for r in loop.residual)
        assert residual < tolerance, (stamp, residual)
        # velocities: S thetadot of the velocities used; they keep the loops closed
        used = list(efforts[stamp].velocity)
        velocities = np.array(msg.velocity)
        assert velocities.shape == positions.shape
        np.testing.assert_allclose(velocities, reference.last_pose(used)[1], rtol=0, atol=1e-9)
        np.testing.assert_allclose(velocities[mechanism.active_index], used, rtol=0,
                                   atol=1e-9)
        jacobian, _ = closure.closure_jacobian_matrix(model, q_all)
        scale = 1.0 + np.abs(velocities).max()
        assert np.abs(jacobian @ velocities).max() < 1e-8 * scale
    return checked


@pytest.mark.parametrize('key, config, with_velocity', [
    ('every', FOUR_BAR, False), ('stewart', STEWART, True)])
def test_joint_states_is_the_closed_pose_of_every_joint(nodes, mechanisms, key, config,
                                                        with_velocity):
    proc, probe = nodes[key]
    mechanism = mechanisms[config]
    q, qd = motion(config, 40)
    stamps = probe.play(mechanism.active_joints, q, qd if with_velocity else None)
    assert wait_until(lambda: {_ns(m) for m in probe.states} >= set(stamps)), proc.output[-2000:]
    efforts = {_ns(m): m for m in probe.efforts}
    checked = check_poses(mechanism, dict(zip(stamps, q)), efforts, probe.states)
    assert checked == len(stamps)
    # published after the command: one joint_states per joint_effort, in the same order
    assert [_ns(m) for m in probe.states] == [_ns(m) for m in probe.efforts]


def test_decimation_publishes_every_nth_served_setpoint(nodes, mechanisms):
    """joint_states_decimation 3: setpoints 0, 3, 6, ... of the node's stream, each the
    closed pose of its own setpoint."""
    proc, probe = nodes['third']
    mechanism = mechanisms[FOUR_BAR]
    q, _ = motion(FOUR_BAR, 20)
    stamps = probe.play(mechanism.active_joints, q)
    assert wait_until(lambda: len(probe.states) >= 7), proc.output[-2000:]
    time.sleep(0.3)                             # nothing more comes
    assert [_ns(m) for m in probe.states] == stamps[::3]
    efforts = {_ns(m): m for m in probe.efforts}
    assert check_poses(mechanism, dict(zip(stamps, q)), efforts, probe.states) == 7


def test_decimation_0_turns_the_topic_off(nodes, mechanisms):
    proc, probe = nodes['off']
    q, _ = motion(FOUR_BAR, 10)
    probe.play(mechanisms[FOUR_BAR].active_joints, q)
    time.sleep(0.3)
    assert probe.states == []
    assert probe.node.count_publishers('/js_off/joint_states') == 0
    assert probe.node.count_publishers('/js_off/joint_effort') == 1


def test_the_default_decimation_is_documented_and_every_tenth():
    from cog_id_ros.ros.parameters import NODE_PARAMETERS
    param = NODE_PARAMETERS['joint_states_decimation']
    assert param.default == 10 and param.check(0, ['revolute']) == 0
    assert '100 Hz at a 1 kHz' in param.description
