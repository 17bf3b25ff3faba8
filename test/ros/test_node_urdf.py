"""cog_id_node on a mechanism in the URDF form: a URDF file or robot_description, plus loop
closures (docs/urdf.md).

Nodes run as subprocesses (cwd: the repository, conftest.py) on config/crank_rocker_urdf.yaml
(``mechanism.urdf_file`` relative to the params file, not to the working directory), on a
params file with the URDF as the string ``robot_description``, with ``effort_limits``
given, and on config/five_bar_robot.yaml (a URDF with ``mechanism.loop_closure_file``,
joint names with '/'). Each serves torques equal to the API's (Mechanism.from_params_file) and publishes
joint_states by the mechanism's joint names; the effort limit defaults to the URDF's
``<limit effort>`` and the node's parameter wins over it.
"""
import os
import time

import numpy as np
import pytest
import yaml

rclpy = pytest.importorskip('rclpy')

from conftest import REPO, wait_until  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from test_node import Probe as NodeProbe  # noqa: E402

import cog_id_ros  # noqa: E402
from cog_id_ros.ros.command_line import urdf_base_dir  # noqa: E402
from cog_id_ros.ros.player import RECORDER_QOS  # noqa: E402

NS = 1_000_000_000
CONFIG = os.path.join('config', 'crank_rocker_urdf.yaml')
URDF = os.path.join(REPO, 'config', 'crank_rocker.urdf')
#: a URDF with a loop-closure file (docs/loading_a_closed_loop_urdf.md), names with '/'
FIVE_BAR = os.path.join('config', 'five_bar_robot.yaml')
#: crank positions (rad) and rates (rad/s) sent: each setpoint starts a stream of its own
#: (stamps 0.15 s apart, more than max_setpoint_interval), so it is served at its own
#: velocity and zero acceleration, which the API computes alike
CRANK = [(1.5708, 0.0), (1.62, 2.0), (1.70, -1.5), (1.80, 4.0), (1.75, 0.5)]


class Probe(NodeProbe):
    """test_node's probe (both sides matched before anything is sent), joint_states too."""

    def __init__(self, context, namespace):
        super().__init__(context, namespace, 'urdf_probe' + namespace.replace('/', '_'))
        self.states = []
        self.node.create_subscription(JointState, 'joint_states', self.states.append,
                                      RECORDER_QOS)

    def play(self, joint):
        start = time.time_ns()
        stamps = [start + k * 150_000_000 for k in range(len(CRANK))]
        for stamp, (q, v) in zip(stamps, CRANK):
            msg = JointState()
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp, NS)
            msg.name, msg.position, msg.velocity = [joint], [q], [v]
            self.setpoints.publish(msg)
        assert wait_until(lambda: len(self.efforts) >= len(stamps) and
                          len(self.commands) >= len(stamps))
        return stamps


def description_file(tmp_path):
    """crank_rocker_urdf.yaml with the URDF given as robot_description instead of a file."""
    with open(os.path.join(REPO, CONFIG), encoding='utf-8') as f:
        doc = yaml.safe_load(f)
    params = doc['/**']['ros__parameters']
    del params['mechanism']['urdf_file']
    with open(URDF, encoding='utf-8') as f:
        params['robot_description'] = f.read()
    path = tmp_path / 'crank_rocker_description.yaml'
    path.write_text(yaml.safe_dump(doc))
    return str(path)


@pytest.fixture(scope='module')
def nodes(ros_process, rclpy_context, tmp_path_factory):
    described = description_file(tmp_path_factory.mktemp('urdf'))
    specs = {
        'file': [CONFIG],
        'description': [described],
        'limited': [CONFIG, '-p', 'effort_limits:=[0.3]'],
        'loops': [FIVE_BAR],
    }
    procs = {key: ros_process(['cog_id_node', '--ros-args', '--params-file', *args,
                               '-r', f'__ns:=/urdf_{key}', '-p', 'setpoint_timeout:=0.0',
                               '-p', 'joint_states_decimation:=1'])
             for key, args in specs.items()}
    for key, proc in procs.items():
        assert proc.wait_for_output("mechanism '", timeout=120), proc.output
    probes = {key: Probe(rclpy_context, f'/urdf_{key}') for key in procs}
    for key, probe in probes.items():
        assert probe.connected(), procs[key].output
    yield procs, probes
    for probe in probes.values():
        probe.close()
    for key, proc in procs.items():
        assert proc.stop() == 0, f'{key}:\n{proc.output}'


@pytest.fixture(scope='module')
def api_torques():
    """The API's torques along CRANK, and its mechanism."""
    mechanism = cog_id_ros.Mechanism.from_params_file(os.path.join(REPO, CONFIG))
    solver = cog_id_ros.InverseDynamics(mechanism)
    return mechanism, [solver.torques([q], [v], [0.0]) for q, v in CRANK]


@pytest.mark.parametrize('key', ['file', 'description'])
def test_the_node_serves_the_apis_torques(nodes, api_torques, key):
    procs, probes = nodes
    probe, proc = probes[key], procs[key]
    mechanism, expected = api_torques
    assert "mechanism 'crank_rocker': 3 links, 4 joints, 1 DOF" in proc.output
    # the URDF's <limit effort="20.0"> is the node's effort limit when none is given
    assert 'effort limits: crank_joint 20;' in proc.output
    stamps = probe.play('crank_joint')
    got = {m.header.stamp.sec * NS + m.header.stamp.nanosec: m for m in probe.efforts}
    for stamp, tau in zip(stamps, expected):
        assert list(got[stamp].name) == ['crank_joint']
        np.testing.assert_allclose(got[stamp].effort, tau, rtol=1e-12, atol=1e-12)
    assert wait_until(lambda: len(probe.states) >= len(stamps))
    assert list(probe.states[-1].name) == list(mechanism.joints) == \
        ['crank_joint', 'coupler_joint', 'rocker_joint', 'closing_joint']


def test_the_nodes_effort_limits_win_over_the_urdfs(nodes, api_torques):
    procs, probes = nodes
    probe = probes['limited']
    assert 'effort limits: crank_joint 0.3;' in procs['limited'].output
    _, expected = api_torques
    probe.play('crank_joint')
    commands = [c.data[0] for c in probe.commands]
    np.testing.assert_allclose(commands, np.clip([t[0] for t in expected], -0.3, 0.3),
                               rtol=1e-12, atol=1e-12)
    assert any(abs(t[0]) > 0.3 for t in expected)


def test_the_urdf_file_is_relative_to_the_params_file_that_gives_it(tmp_path):
    config = os.path.join(REPO, CONFIG)
    native = os.path.join(REPO, 'config', 'paper_four_bar_a.yaml')
    here = os.path.dirname(config)
    assert urdf_base_dir(['--ros-args', '--params-file', config], 'cog_id_node') == here
    assert urdf_base_dir(['--ros-args', '--params-file', config, '--params-file', native],
                         'cog_id_node') == here
    assert urdf_base_dir(['--ros-args', '--params-file', config, '-p',
                          'mechanism.urdf_file:=x.urdf'], 'cog_id_node') is None
    assert urdf_base_dir(['--ros-args', '-p', 'mechanism.urdf_file:=x.urdf', '--params-file',
                          config], 'cog_id_node') == here
    assert urdf_base_dir(None, 'cog_id_node') is None


def test_the_node_serves_a_urdf_with_its_loop_closure_file(nodes):
    """config/five_bar_robot.yaml: both files relative to the params file; the actuators
    from the file's name_mot; names with '/' in joint_effort and joint_states."""
    procs, probes = nodes
    probe, proc = probes['loops'], procs['loops']
    mechanism = cog_id_ros.Mechanism.from_params_file(os.path.join(REPO, FIVE_BAR))
    solver = cog_id_ros.InverseDynamics(mechanism)
    assert "mechanism 'five_bar_robot'" in proc.output
    start = time.time_ns()
    sent = [(start + k * 150_000_000, [0.1 * k, -0.05 * k], [0.5, -0.3 * k]) for k in range(3)]
    for stamp, q, v in sent:
        msg = JointState()
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp, NS)
        msg.name, msg.position, msg.velocity = ['motor/1', 'motor/2'], q, v
        probe.setpoints.publish(msg)
    assert wait_until(lambda: len(probe.efforts) >= len(sent)), proc.output
    got = {m.header.stamp.sec * NS + m.header.stamp.nanosec: m for m in probe.efforts}
    for stamp, q, v in sent:
        assert list(got[stamp].name) == ['motor/1', 'motor/2']
        np.testing.assert_allclose(got[stamp].effort, solver.torques([q], [v], [[0.0, 0.0]])[0],
                                   rtol=1e-12, atol=1e-12)
    assert wait_until(lambda: len(probe.states) >= len(sent))
    assert list(probe.states[-1].name) == mechanism.joints == \
        ['motor/1', 'elbow/1', 'motor/2', 'elbow/2']


def test_the_loop_closure_file_is_relative_to_the_params_file_that_gives_it():
    here = os.path.join(REPO, 'config')
    five_bar = os.path.join(REPO, FIVE_BAR)
    assert urdf_base_dir(['--ros-args', '--params-file', five_bar], 'cog_id_node',
                         'mechanism.loop_closure_file') == here
    assert urdf_base_dir(['--ros-args', '--params-file', five_bar, '-p',
                          'mechanism.loop_closure_file:=x.yaml'], 'cog_id_node',
                         'mechanism.loop_closure_file') is None
