"""cog_transmission_node over real DDS traffic: the map alone, joint space <-> motors.

How we know: every output equals the core's Transmission (and the actuators' solve for the
passive joints) to 1e-9 on the parallel ankle and the TALOS-like leg; a bad message (wrong
names, NaN, velocities or efforts without positions, a singular pose of the four-bar knee)
gets no output and a counted reason in /diagnostics; no NaN is ever published; a flood is
survived (the node answers afterwards) and SIGINT exits 0.
"""
import math
import os
import sys
import threading
import time

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')

from conftest import BIN, wait_until  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

import cog_id_ros  # noqa: E402
from cog_id_ros.ros.player import RECORDER_QOS  # noqa: E402
from cog_id_ros.ros.topics import control_qos  # noqa: E402

ANKLE = 'config/parallel_ankle.yaml'
LEG = 'config/talos_like_leg.yaml'
KNEE = 'config/four_bar_knee.yaml'
TOL = 1e-9
WAIT = 20.0


def command(params_file, namespace, *extra):
    """The node's command line: the console script when installed, else its main."""
    exe = os.path.join(BIN, 'cog_transmission_node')
    head = [exe] if os.path.exists(exe) else [
        sys.executable, '-c',
        'import sys; from cog_id_ros.ros.main import transmission_main; '
        'sys.exit(transmission_main())']
    return [*head, '--ros-args', '--params-file', params_file, '-r', f'__ns:={namespace}',
            *extra]


def values(status):
    return {kv.key: kv.value for kv in status.values}


class Probe:
    """Publishes joint_command and actuator_states into one node's namespace, records its
    actuator_command, joint_states and /diagnostics."""

    def __init__(self, context, namespace):
        self.namespace = namespace
        self.node = rclpy.create_node(f'probe{namespace.replace("/", "_")}',
                                      namespace=namespace, context=context)
        self.commands = self.node.create_publisher(JointState, 'joint_command', control_qos())
        self.states = self.node.create_publisher(JointState, 'actuator_states', control_qos())
        self.out = {'actuator_command': [], 'joint_states': []}
        for topic, got in self.out.items():
            self.node.create_subscription(JointState, topic, got.append, RECORDER_QOS)
        self.diagnostics = []
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self._on_diagnostics, 10)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        threading.Thread(target=self.executor.spin, daemon=True).start()
        self.stamp = 1000

    def _on_diagnostics(self, msg):
        for status in msg.status:
            if status.name.startswith(self.namespace + '/cog_transmission_node'):
                self.diagnostics.append((time.monotonic(), status))

    def close(self):
        self.executor.shutdown()
        self.node.destroy_node()

    def connected(self):
        return wait_until(lambda: self.commands.get_subscription_count() > 0
                          and self.states.get_subscription_count() > 0
                          and self.node.count_publishers(f'{self.namespace}/joint_states') > 0
                          and any(int(values(s).get('commands_publishers', 0)) > 0
                                  and int(values(s).get('states_publishers', 0)) > 0
                                  for _, s in list(self.diagnostics)), WAIT)

    def send(self, topic, names, q=(), v=(), e=()):
        """Publish; the stamp (seconds) that tells its answer."""
        self.stamp += 1
        msg = JointState(name=list(names), position=list(q), velocity=list(v), effort=list(e))
        msg.header.stamp.sec = self.stamp
        (self.commands if topic == 'joint_command' else self.states).publish(msg)
        return self.stamp

    def answer(self, topic, stamp, timeout=WAIT):
        out = 'actuator_command' if topic == 'joint_command' else 'joint_states'
        found = []
        wait_until(lambda: found.extend(m for m in list(self.out[out])
                                        if m.header.stamp.sec == stamp) or found, timeout)
        return found[0] if found else None

    def status_after(self, after):
        assert wait_until(lambda: any(t > after for t, _ in list(self.diagnostics)), WAIT)
        return next(s for t, s in list(self.diagnostics) if t > after)


@pytest.fixture(scope='module')
def mechanisms():
    return {key: cog_id_ros.Mechanism.from_params_file(path)
            for key, path in (('ankle', ANKLE), ('leg', LEG), ('knee', KNEE))}


@pytest.fixture(scope='module')
def nodes(ros_process, rclpy_context):
    fast = ('-p', 'diagnostics_period:=0.2')
    procs = {'ankle': ros_process(command(ANKLE, '/tr_ankle', *fast)),
             'leg': ros_process(command(LEG, '/tr_leg', *fast)),
             'knee': ros_process(command(KNEE, '/tr_knee', *fast,
                                         '-p', 'mechanism.max_condition_number:=1000.0'))}
    for proc in procs.values():
        assert proc.wait_for_output("mechanism '", timeout=60), proc.output
    probes = {key: Probe(rclpy_context, f'/tr_{key}') for key in procs}
    for key, probe in probes.items():
        assert probe.connected(), procs[key].output
    yield procs, probes
    for probe in probes.values():
        for got in probe.out.values():
            for msg in got:
                for field in (msg.position, msg.velocity, msg.effort):
                    assert np.isfinite(field).all()
        probe.close()
    for key, proc in procs.items():
        assert proc.stop() == 0, f'{key}: no clean exit on SIGINT:\n{proc.output}'


def joint_space_pose(mech, offset):
    q0 = np.array([mech.assembled_positions[mech.joints.index(j)] for j in mech.joint_space])
    return q0 + offset


@pytest.mark.parametrize('key', ['ankle', 'leg'])
def test_joint_command_to_actuator_command_equals_the_api(nodes, mechanisms, key):
    _, probes = nodes
    probe, mech = probes[key], mechanisms[key]
    tr = cog_id_ros.Transmission(mech)
    d = len(mech.joint_space)
    for k, offset in enumerate((0.0, 0.1, -0.15)):
        q = joint_space_pose(mech, offset * np.cos(np.arange(d)))
        v, e = 0.5 * np.sin(np.arange(d) + k), 3.0 * np.cos(np.arange(d) - k)
        # any order, extra names ignored
        names = [*reversed(mech.joint_space), 'extra']
        stamp = probe.send('joint_command', names, [*q[::-1], 9.0], [*v[::-1], 9.0],
                           [*e[::-1], 9.0])
        msg = probe.answer('joint_command', stamp)
        assert msg is not None
        assert list(msg.name) == list(mech.active_joints)
        theta = tr.to_actuator_space(q)
        np.testing.assert_allclose(msg.position, theta, rtol=0, atol=TOL)
        np.testing.assert_allclose(msg.velocity, tr.actuator_velocities(q, v), rtol=0, atol=TOL)
        np.testing.assert_allclose(msg.effort, tr.actuator_efforts(theta, e), rtol=0, atol=TOL)
    # positions alone: positions alone out
    stamp = probe.send('joint_command', mech.joint_space, q)
    msg = probe.answer('joint_command', stamp)
    assert len(msg.velocity) == 0 and len(msg.effort) == 0
    np.testing.assert_allclose(msg.position, tr.to_actuator_space(q), rtol=0, atol=TOL)


@pytest.mark.parametrize('key', ['ankle', 'leg'])
def test_actuator_states_to_joint_states_equals_the_api(nodes, mechanisms, key):
    _, probes = nodes
    probe, mech = probes[key], mechanisms[key]
    tr = cog_id_ros.Transmission(mech)
    m = len(mech.active_joints)
    for k, offset in enumerate((0.0, 0.05, -0.1)):
        theta = tr.to_actuator_space(joint_space_pose(mech, offset * np.sin(
            np.arange(len(mech.joint_space)) + 1.0)))
        theta_dot, tau = 0.4 * np.cos(np.arange(m) + k), 2.0 * np.sin(np.arange(m) + k)
        stamp = probe.send('actuator_states', mech.active_joints, theta, theta_dot, tau)
        msg = probe.answer('actuator_states', stamp)
        assert msg is not None
        assert list(msg.name) == list(mech.joints)
        every = tr.actuators.solve_positions(theta)
        np.testing.assert_allclose(msg.position, every, rtol=0, atol=TOL)
        rows = [mech.joints.index(j) for j in mech.joint_space]
        position, velocity, effort = (np.array(f) for f in (msg.position, msg.velocity,
                                                            msg.effort))
        np.testing.assert_allclose(position[rows], tr.to_joint_space(theta), rtol=0, atol=TOL)
        np.testing.assert_allclose(velocity[rows], tr.joint_velocities(theta, theta_dot),
                                   rtol=0, atol=TOL)
        np.testing.assert_allclose(velocity, tr.actuators.joint_rate_map(theta) @ theta_dot,
                                   rtol=0, atol=TOL)
        np.testing.assert_allclose(effort[rows], tr.joint_efforts(theta, tau), rtol=0,
                                   atol=TOL)
        for a, joint in enumerate(mech.active_joints):
            if joint not in mech.joint_space:
                assert effort[mech.joints.index(joint)] == tau[a]


BAD = {
    # key: (node, topic, names, positions, velocities, efforts, reason)
    'wrong_names': ('ankle', 'joint_command', ['motor_left', 'motor_right'], [0.0, 0.0], [],
                    [], 'missing_joint'),
    'nan': ('ankle', 'joint_command', None, [math.nan, 0.0], [], [], 'non_finite'),
    'nan_effort': ('ankle', 'actuator_states', 'motors', [0.0, 0.0], [], [0.0, math.inf],
                   'non_finite'),
    'efforts_without_positions': ('ankle', 'joint_command', None, [], [], [1.0, 2.0],
                                  'malformed'),
    'velocities_without_positions': ('ankle', 'actuator_states', 'motors', [], [0.1, 0.2],
                                     [], 'malformed'),
    'singular': ('knee', 'joint_command', None, [0.7712], [], [1.0], 'singular'),
}


@pytest.mark.parametrize('case', list(BAD))
def test_a_bad_message_gets_no_output_and_a_counted_reason(nodes, mechanisms, case):
    procs, probes = nodes
    key, topic, names, q, v, e, reason = BAD[case]
    probe, mech = probes[key], mechanisms[key]
    names = mech.joint_space if names is None else \
        mech.active_joints if names == 'motors' else names
    prefix = 'commands' if topic == 'joint_command' else 'states'
    counter = f'{prefix}_rejected.{reason}'
    before = int(values(probe.status_after(time.monotonic()))[counter])
    stamp = probe.send(topic, names, q, v, e)
    assert wait_until(lambda: int(values(probe.status_after(time.monotonic()))[counter])
                      == before + 1, WAIT)
    assert probe.answer(topic, stamp, timeout=0.2) is None
    good_names = mech.joint_space if topic == 'joint_command' else mech.active_joints
    good = probe.send(topic, good_names, [0.1] * len(good_names))
    assert probe.answer(topic, good) is not None         # the next good one is served
    assert values(probe.status_after(time.monotonic()))['last_' + prefix + '_rejection'] \
        .startswith(reason)
    assert procs[key].proc.poll() is None


def test_it_survives_a_flood_and_answers_afterwards(nodes, mechanisms):
    procs, probes = nodes
    probe, mech = probes['ankle'], mechanisms['ankle']
    # 10x the subscription's depth in a burst (no more: the suite's other nodes share the
    # machine, and a longer flood starves their 1 kHz streams)
    for k in range(1000):
        probe.send('joint_command', mech.joint_space, [0.001 * (k % 100), 0.0],
                   [0.1, 0.0], [1.0, 1.0])
        if k % 2:
            probe.send('actuator_states', mech.active_joints, [0.0, 0.0], [0.0, 0.0])
    time.sleep(0.5)
    assert procs['ankle'].proc.poll() is None
    stamp = probe.send('joint_command', mech.joint_space, [0.2, 0.1])
    msg = probe.answer('joint_command', stamp)
    assert msg is not None
    np.testing.assert_allclose(msg.position, cog_id_ros.Transmission(mech).to_actuator_space(
        [0.2, 0.1]), rtol=0, atol=TOL)
    status = values(probe.status_after(time.monotonic()))
    assert int(status['internal_errors']) == 0


def test_a_mechanism_without_joint_space_is_refused(ros_process):
    proc = ros_process(command('config/paper_four_bar_a.yaml', '/tr_refused'))
    proc.proc.wait(timeout=60)
    assert proc.proc.returncode == 2, proc.output
    assert 'mechanism.joint_space' in proc.output
