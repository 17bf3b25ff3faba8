"""cog_id_node with ``command_space: joint`` over real DDS traffic: setpoints, trajectories
and measured states name mechanism.joint_space, efforts go to the motors.

How we know: every output equals the core API's, ``InverseDynamics.torques(q, qd, qdd,
space='joint')`` and ``Transmission`` (the motors' positions and rates of joint_effort), to
1e-9 on the parallel ankle and the TALOS-like leg; bad setpoints (motor names in joint
space, NaN, a singular pose of the four-bar knee) get no output and a counted reason; no
NaN is published; a mechanism without a joint space is refused at start-up naming both
parameters. The probe and helpers are test_node.py's.
"""
import math
import subprocess
import sys
import time

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')

from conftest import REPO, wait_until  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from test_node import (  # noqa: E402
    NS,
    Probe,
    _ns,
    fresh_stamp,
    make_trajectory,
    start_node,
    values,
)

import cog_id_ros  # noqa: E402
from cog_id_ros.ros.node import control_qos  # noqa: E402
from cog_id_ros.ros.player import RECORDER_QOS  # noqa: E402

ANKLE = 'config/parallel_ankle.yaml'
LEG = 'config/talos_like_leg.yaml'
KNEE = 'config/four_bar_knee.yaml'
TOL = 1e-9


@pytest.fixture(scope='module')
def mechanisms():
    return {'ankle': cog_id_ros.Mechanism.from_params_file(ANKLE),
            'leg': cog_id_ros.Mechanism.from_params_file(LEG),
            'knee': cog_id_ros.Mechanism.from_params_file(KNEE)}


@pytest.fixture(scope='module')
def nodes(ros_process, rclpy_context):
    joint = ('-p', 'command_space:=joint', '-p', 'setpoint_timeout:=0.0')
    procs = {
        'ankle': start_node(ros_process, ANKLE, '/js_ankle', *joint,
                            '-p', 'joint_states_decimation:=1'),
        'leg': start_node(ros_process, LEG, '/js_leg', *joint, '-p', 'effort_limits:=[1e6]'),
        'knee': start_node(ros_process, KNEE, '/js_knee', *joint,
                           '-p', 'mechanism.max_condition_number:=1000.0'),
    }
    probes = {k: Probe(rclpy_context, f'/js_{k}', f'probe_js_{k}') for k in procs}
    for k, probe in probes.items():
        assert probe.connected(), procs[k].output
    yield procs, probes
    for probe in probes.values():
        assert all(np.isfinite(c.data).all() for c in probe.commands)
        assert all(np.isfinite(m.effort).all() for m in probe.efforts)
        probe.close()
    for name, proc in procs.items():
        assert proc.stop() == 0, f'node {name} did not exit cleanly on SIGINT:\n{proc.output}'


def at_rest_of_stream(mechanism, q, v):
    """The API's motor efforts and state of a setpoint that starts a stream (given
    velocities, zero acceleration)."""
    solver = cog_id_ros.InverseDynamics(mechanism)
    q, v = np.asarray(q, float), np.asarray(v, float)
    tau = solver.torques(q, v, np.zeros(len(q)), space='joint')
    tr = solver.transmission
    return tau, tr.to_actuator_space(q), tr.actuator_velocities(q, v)


def check_served(probe, mechanism, q, v):
    stamp = fresh_stamp()
    probe.send(stamp, mechanism.joint_space, q, v)
    msg = probe.wait_effort(stamp)
    tau, theta, theta_dot = at_rest_of_stream(mechanism, q, v)
    assert list(msg.name) == list(mechanism.active_joints)
    np.testing.assert_allclose(msg.effort, tau, rtol=0, atol=TOL)
    np.testing.assert_allclose(msg.position, theta, rtol=0, atol=TOL)
    np.testing.assert_allclose(msg.velocity, theta_dot, rtol=0, atol=TOL)
    assert wait_until(lambda: any(list(c.data) == list(msg.effort) for c in probe.commands))
    return stamp


def test_ankle_setpoints_in_joint_space_get_the_apis_motor_efforts(nodes, mechanisms):
    _, probes = nodes
    for q, v in (([0.0, 0.0], [0.0, 0.0]), ([0.3, -0.2], [0.5, 1.0]),
                 ([-0.4, 0.25], [-1.0, 0.3])):
        check_served(probes['ankle'], mechanisms['ankle'], q, v)
    status = values(probes['ankle'].status_after(time.monotonic()))
    assert status['active_joints'] == 'motor_left, motor_right'
    assert status['internal_errors'] == '0'
    assert float(status['last_closure_residual']) < 1e-9     # of the last joint-space pose


def test_joint_states_carry_every_joint_of_the_served_pose(nodes, mechanisms, rclpy_context):
    _, probes = nodes
    mech = mechanisms['ankle']
    states = []
    probes['ankle'].node.create_subscription(JointState, 'joint_states', states.append,
                                             RECORDER_QOS)
    time.sleep(0.5)
    q, v = [0.2, 0.1], [0.3, -0.4]
    stamp = check_served(probes['ankle'], mech, q, v)
    assert wait_until(lambda: any(_ns(m.header.stamp) == stamp for m in states))
    msg = next(m for m in states if _ns(m.header.stamp) == stamp)
    assert list(msg.name) == list(mech.joints)
    solver = cog_id_ros.InverseDynamics(mech).transmission.joints
    pose = solver.solve_positions(q)
    np.testing.assert_allclose(msg.position, pose, rtol=0, atol=TOL)
    np.testing.assert_allclose(msg.velocity, solver.joint_rate_map(q) @ np.array(v),
                               rtol=0, atol=TOL)


def test_talos_leg_setpoint_in_joint_space(nodes, mechanisms):
    _, probes = nodes
    mech = mechanisms['leg']
    q0 = np.array([mech.assembled_positions[mech.joints.index(j)] for j in mech.joint_space])
    check_served(probes['leg'], mech, (q0 + 0.05).tolist(), [0.1] * len(q0))


@pytest.mark.parametrize('case', ['motor_names', 'nan', 'efforts_length', 'singular'])
def test_a_bad_joint_space_setpoint_gets_no_output_and_a_counted_reason(nodes, mechanisms,
                                                                        case):
    procs, probes = nodes
    key = 'knee' if case == 'singular' else 'ankle'
    probe, mech = probes[key], mechanisms[key]
    good = [0.3] if key == 'knee' else [0.1, 0.1]
    names, q, efforts, reason = {
        'motor_names': (mech.active_joints, [0.0, 0.0], [], 'missing_joint'),
        'nan': (mech.joint_space, [math.nan, 0.0], [], 'non_finite'),
        'efforts_length': (mech.joint_space, [0.1, 0.1], [1.0], 'malformed'),
        'singular': (mech.joint_space, [0.7712], [], 'singular'),
    }[case]
    before = int(values(probe.status_after(time.monotonic())).get(f'rejected.{reason}'))
    check_served(probe, mech, good, [0.0] * len(good))
    n = len(probe.commands)
    stamp = fresh_stamp()
    probe.send(stamp, names, q, efforts=efforts)
    check_served(probe, mech, good, [0.0] * len(good))
    assert probe.effort_at(stamp) is None and len(probe.commands) == n + 1
    assert wait_until(lambda: int(values(probe.status_after(time.monotonic()))
                                  [f'rejected.{reason}']) == before + 1, timeout=10)
    assert procs[key].proc.poll() is None


def test_a_joint_space_trajectory_gets_the_apis_motor_efforts(nodes, mechanisms):
    _, probes = nodes
    probe, mech = probes['ankle'], mechanisms['ankle']
    t = np.arange(41) * 0.02
    q = np.column_stack([0.3 * np.sin(2 * t), 0.2 * np.sin(3 * t)])
    qd = np.column_stack([0.6 * np.cos(2 * t), 0.6 * np.cos(3 * t)])
    qdd = np.column_stack([-1.2 * np.sin(2 * t), -1.8 * np.sin(3 * t)])
    n = len(probe.effort_trajectories)
    probe.trajectories.publish(make_trajectory(mech.joint_space, q, qd, qdd, t))
    assert wait_until(lambda: len(probe.effort_trajectories) > n)
    out = probe.effort_trajectories[-1]
    assert list(out.joint_names) == list(mech.active_joints)
    solver = cog_id_ros.InverseDynamics(mech)
    np.testing.assert_allclose([p.effort for p in out.points],
                               solver.torques(q, qd, qdd, space='joint'), rtol=0, atol=TOL)
    np.testing.assert_allclose([p.positions for p in out.points],
                               solver.transmission.to_actuator_space(q), rtol=0, atol=TOL)


def test_computed_torque_on_joint_space_measured_states(ros_process, rclpy_context,
                                                        mechanisms):
    """The feedback law in joint space: qdd = qdd_d + kd (qd_d - qd_m) + kp (q_d - q_m),
    the motors' efforts of (q_m, qd_m, qdd)."""
    mech = mechanisms['ankle']
    proc = start_node(ros_process, ANKLE, '/js_ct', '-p', 'command_space:=joint',
                      '-p', 'control_mode:=computed_torque', '-p', 'kp:=[100.0]',
                      '-p', 'kd:=[20.0]', '-p', 'setpoint_timeout:=0.0',
                      '-p', 'measurement_timeout:=5.0')
    probe = Probe(rclpy_context, '/js_ct', 'probe_js_ct')
    measured = probe.node.create_publisher(JointState, 'measured_joint_states', control_qos())
    try:
        assert probe.connected(), proc.output
        assert wait_until(lambda: measured.get_subscription_count() > 0)
        q_d = [0.2, -0.1]
        probe.send(fresh_stamp(), mech.joint_space, q_d, [0.0, 0.0])
        time.sleep(0.3)
        solver = cog_id_ros.InverseDynamics(mech)
        for q_m, qd_m in (([0.19, -0.09], [0.1, 0.0]), ([0.18, -0.1], [0.2, -0.1])):
            n = len(probe.commands)
            msg = JointState(name=list(mech.joint_space), position=q_m, velocity=qd_m)
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(time.time_ns(), NS)
            measured.publish(msg)
            assert wait_until(lambda: len(probe.commands) > n), proc.output
            qdd = [20.0 * (0.0 - v) + 100.0 * (d - m) for d, m, v in zip(q_d, q_m, qd_m)]
            np.testing.assert_allclose(probe.commands[-1].data,
                                       solver.torques(q_m, qd_m, qdd, space='joint'),
                                       rtol=0, atol=TOL)
    finally:
        probe.close()
    assert proc.stop() == 0, proc.output


def test_a_mechanism_without_joint_space_is_refused_naming_both(ros_env):
    result = subprocess.run(
        [sys.executable, '-m', 'cog_id_ros.node', '--ros-args', '--params-file',
         'config/paper_four_bar_a.yaml', '-p', 'command_space:=joint', '-r',
         '__ns:=/js_refused'], cwd=REPO, env=ros_env, capture_output=True, text=True,
        timeout=60)
    assert result.returncode == 2, result.stdout + result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, result.stderr
    assert 'command_space' in lines[0] and 'mechanism.joint_space' in lines[0]


@pytest.mark.parametrize('mode', ['computed_torque', 'pd_feedforward', 'gravity_compensation'])
def test_feedback_laws_in_joint_space_are_the_apis(mechanisms, mode):
    """Each feedback law with the joint-space solver (no ROS): computed_torque the motors'
    efforts of the commanded joint-space acceleration; pd_feedforward the setpoint's motor
    efforts plus J^T of the joint-space pd efforts at the measured pose;
    gravity_compensation the motors' efforts at rest at the measured pose."""
    from types import SimpleNamespace

    from cog_id_ros.ros.joint_space_solver import JointSpaceSolver
    from cog_id_ros.ros.modes import make_mode
    from cog_id_ros.ros.parameters import NODE_PARAMETERS
    mech = mechanisms['ankle']
    given = {'control_mode': mode, 'command_space': 'joint', 'kp': [50.0], 'kd': [10.0],
             'pd_kp': [30.0, 40.0], 'pd_kd': [2.0, 3.0]}
    kinds = ['revolute', 'revolute']
    config = SimpleNamespace(active_joints=tuple(mech.joint_space), unwrap=[True, True],
                             joint_space=True,
                             **{n: p.check(given.get(n, p.default), kinds)
                                for n, p in NODE_PARAMETERS.items()})
    law = make_mode(config, JointSpaceSolver(mech), lambda: JointSpaceSolver(mech))
    q_d, qd_d, qdd_d = [0.2, -0.1], [0.3, 0.1], [1.0, -2.0]
    q_m, qd_m = [0.18, -0.08], [0.25, 0.2]
    law.efforts(q_d, qd_d, qdd_d)
    got = np.array(law.command(q_m, qd_m))
    api = cog_id_ros.InverseDynamics(mech)
    e, de = np.subtract(q_d, q_m), np.subtract(qd_d, qd_m)
    if mode == 'computed_torque':
        expected = api.torques(q_m, qd_m, np.add(qdd_d, 10.0 * de + 50.0 * e), space='joint')
    elif mode == 'pd_feedforward':
        tr = api.transmission
        pd = np.array([30.0, 40.0]) * e + np.array([2.0, 3.0]) * de
        expected = api.torques(q_d, qd_d, qdd_d, space='joint') + \
            tr.actuator_efforts(tr.to_actuator_space(q_m), pd)
    else:
        expected = api.torques(q_m, [0.0, 0.0], [0.0, 0.0], space='joint')
    np.testing.assert_allclose(got, expected, rtol=0, atol=TOL)
