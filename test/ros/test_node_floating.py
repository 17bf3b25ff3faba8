"""cog_id_node with a floating base (config/digit_biped.yaml) over real DDS traffic.

How we know: a setpoint is served with the latest ``base_state`` (nav_msgs/Odometry), and
its ``joint_effort``, ``effort_command``, ``contact_wrenches/<name>`` and ``base_wrench``
equal ``InverseDynamics.whole_body_torques`` computed here for the same base state, motion
and contacts, to 1e-9 (the base acceleration estimated from the twists of base_state as
well); ``active_contacts`` changes at run time (the only parameter that does), an unknown
contact is refused with the reason, and with the right foot alone only its wrench is
published, its fz the robot's weight at rest; a setpoint without a base state in force,
a bad base state and a trajectory get no output and a counted reason; a floating base
without contacts (or with a feedback mode, or an unknown active contact) is refused at
start-up, exit status 2 and one line naming the parameter; a managed node serves it
after configure and keeps its contacts across cleanup. The probe and helpers are
test_node.py's.
"""
import math
import subprocess
import sys
import time

import numpy as np
import pytest
import yaml

rclpy = pytest.importorskip('rclpy')

from conftest import REPO, wait_until  # noqa: E402
from geometry_msgs.msg import WrenchStamped  # noqa: E402
from lifecycle_msgs.msg import Transition  # noqa: E402
from lifecycle_msgs.srv import ChangeState  # noqa: E402
from nav_msgs.msg import Odometry  # noqa: E402
from rcl_interfaces.msg import Parameter as ParameterMsg  # noqa: E402
from rcl_interfaces.msg import ParameterType, ParameterValue  # noqa: E402
from rcl_interfaces.srv import SetParameters  # noqa: E402
from test_node import NS, Probe, _ns, call, fresh_stamp, make_trajectory, values  # noqa: E402

import cog_id_ros  # noqa: E402
from cog_id_ros.ros.node import control_qos  # noqa: E402
from cog_id_ros.ros.player import RECORDER_QOS  # noqa: E402

BIPED = 'config/digit_biped.yaml'
NAMESPACE = '/floating'
TOL = 1e-9
#: s: the node compiles the biped's kernels on its first load (tens of s on 2 cores)
START_WAIT = 300.0
#: base_state_timeout of the node under test: generous (a loaded machine), and waited out
#: once to see a setpoint rejected for a base state too old
BASE_STATE_TIMEOUT = 3.0


@pytest.fixture(scope='module')
def biped():
    return cog_id_ros.Mechanism.from_params_file(BIPED)


class FloatingProbe(Probe):
    """test_node's probe, plus base_state out and the wrenches in."""

    def __init__(self, context, namespace, name, contacts):
        super().__init__(context, namespace, name)
        self.base_states = self.node.create_publisher(Odometry, 'base_state', control_qos())
        self.wrenches = {name: [] for name in (*contacts, 'base_wrench')}
        for contact in contacts:
            self.node.create_subscription(WrenchStamped, f'contact_wrenches/{contact}',
                                          self.wrenches[contact].append, RECORDER_QOS)
        self.node.create_subscription(WrenchStamped, 'base_wrench',
                                      self.wrenches['base_wrench'].append, RECORDER_QOS)

    def send_base(self, stamp_ns, pose, twist, frame_id='odom'):
        msg = Odometry()
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, NS)
        msg.header.frame_id, msg.child_frame_id = frame_id, 'torso'
        p, o = msg.pose.pose.position, msg.pose.pose.orientation
        p.x, p.y, p.z, o.x, o.y, o.z, o.w = (float(x) for x in pose)
        lin, ang = msg.twist.twist.linear, msg.twist.twist.angular
        lin.x, lin.y, lin.z, ang.x, ang.y, ang.z = (float(x) for x in twist)
        self.base_states.publish(msg)

    def wrench_at(self, name, stamp_ns):
        return next((m for m in self.wrenches[name] if _ns(m.header.stamp) == stamp_ns), None)

    def status_now(self):
        return values(self.status_after(time.monotonic()))


@pytest.fixture(scope='module')
def floating(ros_process, rclpy_context, biped):
    proc = ros_process(['cog_id_node', '--ros-args', '--params-file', BIPED,
                        '-r', f'__ns:={NAMESPACE}', '-p', 'effort_limits:=[1e6]',
                        '-p', 'setpoint_timeout:=0.0',
                        '-p', f'base_state_timeout:={BASE_STATE_TIMEOUT}'])
    assert proc.wait_for_output("mechanism '", timeout=START_WAIT), proc.output
    probe = FloatingProbe(rclpy_context, NAMESPACE, 'probe_floating', list(biped.contacts))
    assert probe.connected(), proc.output
    assert wait_until(lambda: probe.base_states.get_subscription_count() > 0), proc.output
    assert wait_until(lambda: int(probe.status_now().get('base_state_publishers', 0)) > 0), \
        proc.output
    yield proc, probe
    for msgs in (probe.commands, probe.efforts):
        assert all(np.isfinite(getattr(m, 'data', getattr(m, 'effort', []))).all()
                   for m in msgs)
    assert all(math.isfinite(x) for msgs in probe.wrenches.values() for m in msgs
               for x in (m.wrench.force.x, m.wrench.force.z, m.wrench.torque.y))
    probe.close()
    assert proc.stop() == 0, f'the node did not exit cleanly on SIGINT:\n{proc.output}'


def rest_pose(mech):
    return np.array([mech.assembled_positions[mech.joints.index(j)]
                     for j in mech.active_joints])


def tilted(angle, xyz=(0.1, -0.2, 0.9)):
    """A base pose pitched by ``angle`` about y (x, y, z, qx, qy, qz, qw), unit as the node
    makes it (divided by its norm)."""
    q = np.array([0.0, math.sin(angle / 2), 0.0, math.cos(angle / 2)])
    return np.concatenate([xyz, q / math.sqrt(sum(x * x for x in q))])


def send_base_and_wait(probe, stamp, pose, twist, more=()):
    """Publish a base state (and ``more``: (stamp, pose, twist) after it, back to back) and
    wait until the node accepted them all (its count went up)."""
    before = int(probe.status_now()['base_states_accepted'])
    for args in ((stamp, pose, twist), *more):
        probe.send_base(*args)
    assert wait_until(lambda: int(probe.status_now()['base_states_accepted'])
                      >= before + 1 + len(more), timeout=10), 'base state(s) not accepted'


def check_served(probe, mech, q, v, pose, twist, acceleration, contacts):
    """Send a setpoint starting a stream (given velocities, zero joint acceleration) and
    check every output against whole_body_torques; returns its stamp and the API's answer."""
    stamp = fresh_stamp()
    probe.send(stamp, mech.active_joints, q, v)
    msg = probe.wait_effort(stamp)
    api = cog_id_ros.InverseDynamics(mech).whole_body_torques(
        pose, twist, acceleration, q, v, np.zeros(len(q)), contacts=contacts)
    np.testing.assert_allclose(msg.effort, api.efforts, rtol=0, atol=TOL)
    assert wait_until(lambda: any(list(c.data) == list(msg.effort) for c in probe.commands))
    for name, wrench in api.wrenches.items():
        assert wait_until(lambda: probe.wrench_at(name, stamp) is not None), name
        got = probe.wrench_at(name, stamp)
        assert got.header.frame_id == 'odom'
        np.testing.assert_allclose(_six(got), wrench, rtol=0, atol=TOL)
    assert wait_until(lambda: probe.wrench_at('base_wrench', stamp) is not None)
    base = probe.wrench_at('base_wrench', stamp)
    assert base.header.frame_id == mech.base_link
    np.testing.assert_allclose(_six(base), api.base_wrench, rtol=0, atol=TOL)
    return stamp, api


def _six(msg):
    f, m = msg.wrench.force, msg.wrench.torque
    return [f.x, f.y, f.z, m.x, m.y, m.z]


def set_active_contacts(probe, names, namespace=NAMESPACE):
    request = SetParameters.Request(parameters=[ParameterMsg(
        name='active_contacts', value=ParameterValue(
            type=ParameterType.PARAMETER_STRING_ARRAY, string_array_value=list(names)))])
    return call(probe.node, SetParameters, f'{namespace}/cog_id_node/set_parameters',
                request).results[0]


def rejected_setpoint(probe, mech, reason):
    """Send a setpoint that is to be rejected for ``reason``: no output, counted."""
    before = int(probe.status_now()[f'rejected.{reason}'])
    stamp = fresh_stamp()
    probe.send(stamp, mech.active_joints, rest_pose(mech))
    assert wait_until(lambda: int(probe.status_now()[f'rejected.{reason}']) == before + 1,
                      timeout=10)
    time.sleep(0.2)
    assert probe.effort_at(stamp) is None
    assert all(probe.wrench_at(name, stamp) is None for name in probe.wrenches)
    return stamp


# --- first: before any base state --------------------------------------------------------------

def test_a_setpoint_before_any_base_state_is_rejected_and_counted(floating, biped):
    proc, probe = floating
    rejected_setpoint(probe, biped, 'base_state')
    status = probe.diagnostics[-1][1]
    assert 'no base_state received yet' in values(status)['last_rejection']
    assert values(status)['active_contacts'] == 'right_foot, left_foot'
    assert proc.proc.poll() is None


# --- served setpoints ---------------------------------------------------------------------------

def test_efforts_and_wrenches_are_whole_body_torques(floating, biped):
    _, probe = floating
    q0 = rest_pose(biped)
    for k, (angle, twist) in enumerate((
            (0.0, [0.0] * 6),
            (0.2, [0.1, 0.0, -0.05, 0.02, 0.1, -0.03]),
            (-0.15, [-0.2, 0.1, 0.0, 0.3, -0.1, 0.05]))):
        pose = tilted(angle)
        send_base_and_wait(probe, fresh_stamp(), pose, twist)   # a new stream: acceleration 0
        q = q0 + 0.02 * np.sin(np.arange(len(q0)) + k)
        v = 0.3 * np.cos(np.arange(len(q0)) + k)
        check_served(probe, biped, q, v, pose, twist, [0.0] * 6, None)
    assert int(probe.status_now()['rejected.base_state']) == 1


def test_the_base_acceleration_is_the_derivative_of_the_twists(floating, biped):
    """Five base states 10 ms apart whose twist grows linearly: the node serves the next
    setpoint with that slope as base_acceleration (the estimator is exact on a line)."""
    _, probe = floating
    pose = tilted(0.1)
    twist0 = np.array([0.1, -0.05, 0.02, 0.2, -0.1, 0.3])
    slope = np.array([0.5, -1.0, 2.0, 3.0, -2.0, 1.5])
    start = fresh_stamp()
    states = [(start + k * NS // 100, pose, twist0 + slope * k * 0.01) for k in range(5)]
    send_base_and_wait(probe, *states[0], more=states[1:])
    twist = twist0 + slope * 0.04
    q = rest_pose(biped) + 0.01
    _, api = check_served(probe, biped, q, [0.1] * len(q), pose, twist, slope, None)
    at_zero = cog_id_ros.InverseDynamics(biped).whole_body_torques(
        pose, twist, [0.0] * 6, q, [0.1] * len(q), np.zeros(len(q)))
    assert np.abs(api.efforts - at_zero.efforts).max() > 1e-3     # the slope matters


# --- active_contacts, at run time ------------------------------------------------------------------

def test_active_contacts_changes_at_run_time(floating, biped):
    _, probe = floating
    mass = biped.base_mass + sum(biped.link_mass)
    gravity = -biped.gravity[2]
    pose, rest = tilted(0.0), [0.0] * 6
    q = rest_pose(biped)
    try:
        result = set_active_contacts(probe, ['right_foot'])
        assert result.successful, result.reason
        send_base_and_wait(probe, fresh_stamp(), pose, rest)
        stamp, api = check_served(probe, biped, q, [0.0] * len(q), pose, rest, rest,
                                  ['right_foot'])
        assert list(api.wrenches) == ['right_foot']
        right = probe.wrench_at('right_foot', stamp)
        assert right.wrench.force.z == pytest.approx(mass * gravity, rel=1e-9)
        time.sleep(0.3)
        assert probe.wrench_at('left_foot', stamp) is None    # an inactive contact: nothing
        assert probe.status_now()['active_contacts'] == 'right_foot'
        # an unknown name is refused with the reason; the contacts stay as they were
        result = set_active_contacts(probe, ['right_foot', 'nose'])
        assert not result.successful
        assert "'nose'" in result.reason and 'mechanism.contacts' in result.reason, \
            result.reason
        assert result.reason.startswith('active_contacts: '), result.reason
        assert probe.status_now()['active_contacts'] == 'right_foot'
        # every other parameter stays read-only
        request = SetParameters.Request(parameters=[ParameterMsg(
            name='base_state_timeout',
            value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=1.0))])
        refused = call(probe.node, SetParameters, f'{NAMESPACE}/cog_id_node/set_parameters',
                       request).results[0]
        assert not refused.successful and 'read-only' in refused.reason, refused.reason
        # none: the robot in flight, everything in base_wrench
        result = set_active_contacts(probe, [])
        assert result.successful, result.reason
        send_base_and_wait(probe, fresh_stamp(), pose, rest)
        stamp, api = check_served(probe, biped, q, [0.0] * len(q), pose, rest, rest, [])
        assert api.base_wrench[2] == pytest.approx(mass * gravity, rel=1e-9)   # the weight
        time.sleep(0.3)
        assert all(probe.wrench_at(name, stamp) is None for name in biped.contacts)
    finally:
        assert set_active_contacts(probe, list(biped.contacts)).successful
    send_base_and_wait(probe, fresh_stamp(), pose, rest)
    check_served(probe, biped, q, [0.0] * len(q), pose, rest, rest, None)


# --- what is rejected -----------------------------------------------------------------------------

def test_bad_base_states_are_rejected_and_counted(floating, biped):
    _, probe = floating
    good = tilted(0.0)
    before = probe.status_now()
    probe.send_base(fresh_stamp(), [math.nan, *good[1:]], [0.0] * 6)
    probe.send_base(fresh_stamp(), good, [0.0, math.inf, 0.0, 0.0, 0.0, 0.0])
    again = fresh_stamp()
    probe.send_base(again, good, [0.0] * 6)
    probe.send_base(again, good, [0.0] * 6)                         # the same stamp
    close = fresh_stamp()       # a twist 0.1 m/s off 1 us later: 1e5 m/s^2, a jump
    probe.send_base(close, good, [0.0] * 6)
    probe.send_base(close + 1000, good, [0.1, 0.0, 0.0, 0.0, 0.0, 0.0])
    probe.send_base(fresh_stamp(), [*good[:3], 0.0, 0.0, 0.0, 0.5], [0.0] * 6)
    expected = {'non_finite': 2, 'stamp': 1, 'malformed': 1, 'jump': 1}

    def counted():
        now = probe.status_now()
        return all(int(now[f'base_states_rejected.{k}']) ==
                   int(before[f'base_states_rejected.{k}']) + n for k, n in expected.items())
    assert wait_until(counted, timeout=10), probe.status_now()
    status = probe.status_now()
    assert int(status['base_states_rejected']) == int(before['base_states_rejected']) + 5
    assert status['last_base_state_rejection'].startswith('malformed: '), status
    assert 'norm 0.5' in status['last_base_state_rejection'], status


def test_a_trajectory_is_rejected_with_a_floating_base(floating, biped):
    _, probe = floating
    before = int(probe.status_now()['trajectories_rejected.base_state'])
    q = np.tile(rest_pose(biped), (5, 1))
    t = np.arange(5) * 0.01
    probe.trajectories.publish(make_trajectory(biped.active_joints, q, 0 * q, 0 * q, t))
    assert wait_until(lambda: int(probe.status_now()['trajectories_rejected.base_state'])
                      == before + 1, timeout=10)
    assert not probe.effort_trajectories


def test_a_setpoint_after_base_state_timeout_is_rejected(floating, biped):
    _, probe = floating
    send_base_and_wait(probe, fresh_stamp(), tilted(0.0), [0.0] * 6)
    time.sleep(BASE_STATE_TIMEOUT + 0.5)
    rejected_setpoint(probe, biped, 'base_state')
    assert 'more than base_state_timeout' in probe.status_now()['last_rejection']
    # the next base state serves again
    pose, rest = tilted(0.05), [0.0] * 6
    send_base_and_wait(probe, fresh_stamp(), pose, rest)
    q = rest_pose(biped)
    check_served(probe, biped, q, [0.0] * len(q), pose, rest, rest, None)


def test_diagnostics_count_the_base_states(floating):
    _, probe = floating
    status = probe.status_now()
    assert int(status['base_states_accepted']) >= 10
    assert int(status['rejected.base_state']) == 2
    assert int(status['internal_errors']) == 0
    assert status['base_state_age'] != ''
    assert int(status['base_state_publishers']) >= 1


# --- a managed node ------------------------------------------------------------------------------

def change_state(probe, namespace, transition):
    client = probe.node.create_client(ChangeState, f'{namespace}/cog_id_node/change_state')
    try:
        assert client.wait_for_service(timeout_sec=60)
        request = ChangeState.Request()
        request.transition.id = transition
        future = client.call_async(request)
        assert wait_until(future.done, timeout=START_WAIT)   # configure compiles kernels
        return future.result().success
    finally:
        probe.node.destroy_client(client)


def test_a_managed_node_serves_a_floating_base_and_keeps_its_contacts(ros_process,
                                                                     rclpy_context, biped):
    """managed:=true: configure makes the base_state thread, the wrench topics and the
    changeable active_contacts; cleanup releases them (a change is refused meanwhile); a
    new configure serves again with the contacts set before."""
    namespace = '/floating_managed'
    proc = ros_process(['cog_id_node', '--ros-args', '--params-file', BIPED,
                        '-r', f'__ns:={namespace}', '-p', 'managed:=true',
                        '-p', 'effort_limits:=[1e6]', '-p', 'setpoint_timeout:=0.0',
                        '-p', f'base_state_timeout:={BASE_STATE_TIMEOUT}'])
    probe = FloatingProbe(rclpy_context, namespace, 'probe_floating_managed',
                          list(biped.contacts))
    pose, rest = tilted(0.0), [0.0] * 6
    q = rest_pose(biped)
    try:
        for step in (Transition.TRANSITION_CONFIGURE, Transition.TRANSITION_ACTIVATE):
            assert change_state(probe, namespace, step), proc.output
        assert probe.connected(), proc.output
        assert wait_until(lambda: int(probe.status_now()['base_state_publishers']) > 0)
        assert set_active_contacts(probe, ['left_foot'], namespace).successful
        send_base_and_wait(probe, fresh_stamp(), pose, rest)
        check_served(probe, biped, q, [0.0] * len(q), pose, rest, rest, ['left_foot'])
        for step in (Transition.TRANSITION_DEACTIVATE, Transition.TRANSITION_CLEANUP):
            assert change_state(probe, namespace, step), proc.output
        refused = set_active_contacts(probe, ['right_foot'], namespace)
        assert not refused.successful and 'read-only' in refused.reason, refused.reason
        for step in (Transition.TRANSITION_CONFIGURE, Transition.TRANSITION_ACTIVATE):
            assert change_state(probe, namespace, step), proc.output
        assert wait_until(lambda: probe.status_now()['active_contacts'] == 'left_foot')
        assert wait_until(lambda: int(probe.status_now()['base_state_publishers']) > 0)
        send_base_and_wait(probe, fresh_stamp(), pose, rest)
        stamp, _ = check_served(probe, biped, q, [0.0] * len(q), pose, rest, rest,
                                ['left_foot'])
        time.sleep(0.3)
        assert probe.wrench_at('right_foot', stamp) is None
        assert probe.status_now()['internal_errors'] == '0'
    finally:
        probe.close()
    assert proc.stop() == 0, proc.output


# --- refused at start-up --------------------------------------------------------------------------

def biped_file(tmp_path, edit):
    """config/digit_biped.yaml in tmp_path, its files by absolute path, ``edit`` applied to
    its mechanism parameters."""
    with open(f'{REPO}/{BIPED}', encoding='utf-8') as f:
        doc = yaml.safe_load(f)
    params = doc['/**']['ros__parameters']
    mech = params['mechanism']
    for key in ('urdf_file', 'loop_closure_file'):
        mech[key] = f'{REPO}/config/{mech[key]}'
    edit(params)
    path = tmp_path / 'biped.yaml'
    path.write_text(yaml.safe_dump(doc))
    return str(path)


def refused_line(ros_env, *ros_args):
    result = subprocess.run([sys.executable, '-m', 'cog_id_ros.node', '--ros-args', *ros_args,
                             '-r', '__ns:=/floating_refused'], cwd=REPO, env=ros_env,
                            stdin=subprocess.DEVNULL, capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 2, result.stdout + result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, result.stderr
    return lines[0]


def test_a_floating_base_without_contacts_is_refused(tmp_path, ros_env):
    line = refused_line(ros_env, '--params-file',
                        biped_file(tmp_path, lambda p: p['mechanism'].pop('contacts')))
    assert 'mechanism.contacts' in line and 'floating_base' in line, line


@pytest.mark.parametrize('args, parameter, detail', [
    (('-p', 'control_mode:=computed_torque'), 'control_mode', 'feedforward'),
    (('-p', 'active_contacts:=[nose]'), 'active_contacts', "'nose'"),
])
def test_what_a_floating_base_cannot_be_served_with_is_refused(ros_env, args, parameter,
                                                               detail):
    line = refused_line(ros_env, '--params-file', BIPED, *args)
    assert f'{parameter}:' in line and detail in line, line


def test_active_contacts_of_a_fixed_base_are_refused(ros_env):
    line = refused_line(ros_env, '--params-file', 'config/paper_four_bar_a.yaml',
                        '-p', 'active_contacts:=[foot]')
    assert 'active_contacts' in line and 'floating_base is false' in line, line
