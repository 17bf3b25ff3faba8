"""cog_id_node under input that used to crash it, stall it or make it mislead (the issue
"Reliability: no input crashes, hangs or misleads the node").

Each node is started with ``python -m cog_id_ros.node`` from this checkout (cwd: the
repository of this file), in a namespace of its own; a probe node in this process talks
to it over DDS. Waits are generous upper bounds; the one timing bound (the hold command
while a long trajectory is solved) is ten times what the node needs.
"""
import math
import sys
import time

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')

from conftest import wait_until  # noqa: E402
from diagnostic_msgs.msg import DiagnosticStatus  # noqa: E402
from rcl_interfaces.msg import Parameter as ParameterMsg  # noqa: E402
from rcl_interfaces.msg import ParameterType, ParameterValue  # noqa: E402
from rcl_interfaces.srv import SetParameters  # noqa: E402
from test_node import NS, Probe, call, make_trajectory, values  # noqa: E402
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint  # noqa: E402

CONFIG_A = 'config/paper_four_bar_a.yaml'
M, L, G = 1.0, 0.5, 9.81


def hold(theta):
    return 2.0 * M * G * L * math.cos(theta)


def start(ros_process, namespace, *extra):
    proc = ros_process([sys.executable, '-m', 'cog_id_ros.node', '--ros-args', '--params-file',
                        CONFIG_A, '-r', f'__ns:={namespace}', '-p', 'diagnostics_period:=0.2',
                        *extra])
    assert proc.wait_for_output("mechanism '"), proc.output
    return proc


@pytest.fixture
def probe_for(rclpy_context, request):
    made = []

    def make(namespace):
        probe = Probe(rclpy_context, namespace, f'probe_{namespace.strip("/")}')
        made.append(probe)
        assert probe.connected()
        assert wait_until(lambda: probe.trajectories.get_subscription_count() > 0)
        return probe
    yield make
    for probe in made:
        probe.close()


def stream(probe, thetas, start_ns, step_ns=1_000_000, names=('joint3',), pause=0.0):
    stamps = []
    for k, th in enumerate(thetas):
        stamp = start_ns + k * step_ns
        probe.send(stamp, list(names), [th])
        stamps.append(stamp)
        if pause:
            time.sleep(pause)
    return stamps


def wait_values(probe, predicate, timeout=20.0):
    """The values of the first diagnostics status from now on for which ``predicate(values)``
    holds (the node reports every 0.2 s); the last one seen if none does in ``timeout``."""
    after = time.monotonic()
    seen = {}

    def check():
        for t, status in list(probe.diagnostics):
            if t > after:
                seen.update(values(status))
                if predicate(values(status)):
                    seen.clear()
                    seen.update(values(status))
                    return True
        return False
    wait_until(check, timeout)
    return seen


# --- item 1: no exception ends the node -------------------------------------------------------

def test_trajectory_with_a_huge_position_does_not_end_the_node(ros_process, probe_for):
    """Reliability item 1: a joint_trajectory with a position of 1e308 once killed the node
    (OverflowError out of on_trajectory); now it is answered or refused and the node
    goes on serving setpoints."""
    proc = start(ros_process, '/huge', '-p', 'setpoint_timeout:=0.0')
    probe = probe_for('/huge')
    q = np.full((6, 1), 1.4)
    q[2, 0] = 1e308
    probe.trajectories.publish(make_trajectory(['joint3'], q, q * 0, q * 0))
    probe.trajectories.publish(make_trajectory(['joint3'], q))   # derivatives estimated
    time.sleep(2.0)
    assert proc.proc.poll() is None, proc.output
    stamp = time.time_ns()
    probe.send(stamp, ['joint3'], [1.4])
    assert probe.wait_effort(stamp).effort[0] == pytest.approx(hold(1.4), abs=1e-9)
    assert 'Traceback' not in proc.output


# --- item 14: use_sim_time is read-only --------------------------------------------------------

def test_use_sim_time_cannot_be_switched_on_at_runtime(ros_process, probe_for):
    """Reliability item 14: use_sim_time could be set at runtime (then, without /clock,
    /diagnostics and the hold command went silent); it is refused with a reason."""
    start(ros_process, '/simtime')
    probe = probe_for('/simtime')
    request = SetParameters.Request(parameters=[ParameterMsg(
        name='use_sim_time', value=ParameterValue(type=ParameterType.PARAMETER_BOOL,
                                                  bool_value=True))])
    result = call(probe.node, SetParameters, '/simtime/cog_id_node/set_parameters', request)
    assert not result.results[0].successful
    assert 'use_sim_time' in result.results[0].reason
    # the node's clock still runs: diagnostics keep coming
    now = time.monotonic()
    probe.status_after(now)
    probe.status_after(time.monotonic())


# --- item 11: wrapped angles and jumps ----------------------------------------------------------

def test_wrapped_angles_are_unwrapped_and_a_jump_is_rejected(ros_process, probe_for):
    """Reliability item 11: a revolute joint reported in another 2 pi range mid-stream
    (an encoder that wraps) gave ~1e5 N m from the differentiated jump; now it is
    unwrapped (torques stay near the holding torque), and a real jump larger than
    max_setpoint_step is rejected as 'jump' with the estimator restarted."""
    proc = start(ros_process, '/wrap', '-p', 'setpoint_timeout:=0.0')
    probe = probe_for('/wrap')
    base = time.time_ns()
    # a slow motion 1.40 -> 1.42 rad at 1 kHz; from sample 10 on reported minus 2 pi
    thetas = [1.40 + 0.001 * k for k in range(20)]
    reported = [th - 2 * math.pi if k >= 10 else th for k, th in enumerate(thetas)]
    stamps = stream(probe, reported, base, pause=0.002)
    msgs = [probe.wait_effort(s) for s in stamps]
    efforts = np.array([m.effort[0] for m in msgs])
    assert np.abs(efforts - hold(1.41)).max() < 0.5, efforts   # no 1e5 N m spike
    assert msgs[15].position[0] == pytest.approx(reported[15])    # as received
    # a jump of 1.2 rad (default max_setpoint_step 1 rad): rejected, then a new stream
    jump = stamps[-1] + 1_000_000
    probe.send(jump, ['joint3'], [2.62])
    after = jump + 1_000_000
    probe.send(after, ['joint3'], [2.62])
    msg = probe.wait_effort(after)
    assert probe.effort_at(jump) is None
    assert msg.effort[0] == pytest.approx(hold(2.62), abs=1e-9)     # a fresh stream: a = 0
    kv = wait_values(probe, lambda kv: int(kv['rejected.jump']) >= 1)
    assert int(kv['rejected.jump']) == 1
    assert 'no command (jump)' in proc.output


# --- item 12: far-future stamps -----------------------------------------------------------------

def test_a_far_future_stamp_does_not_block_the_stream(ros_process, probe_for):
    """Reliability item 12: a setpoint stamped in 2038 was served, and every later
    setpoint rejected (forever with setpoint_timeout 0); now it is rejected (stamp, more
    than max_stamp_lead ahead) and the stream goes on."""
    start(ros_process, '/future', '-p', 'setpoint_timeout:=0.0')
    probe = probe_for('/future')
    now = time.time_ns()
    probe.send(now, ['joint3'], [1.4])
    probe.wait_effort(now)
    future = 2_147_000_000 * NS
    probe.send(future, ['joint3'], [1.4])
    later = [now + k * 1_000_000 for k in range(1, 6)]
    for stamp in later:
        probe.send(stamp, ['joint3'], [1.4])
    for stamp in later:
        probe.wait_effort(stamp)
    assert probe.effort_at(future) is None
    kv = wait_values(probe, lambda kv: int(kv['rejected.stamp']) >= 1)
    assert int(kv['rejected.stamp']) == 1


def test_a_stream_whose_clock_went_back_recovers(ros_process, probe_for):
    """Reliability item 12: after a stamp slightly ahead (within max_stamp_lead) was
    accepted, a stream stamped before it was rejected until the timeout (forever with
    setpoint_timeout 0); after max_stamp_rejections (5) in a row the estimator restarts."""
    proc = start(ros_process, '/goesback', '-p', 'setpoint_timeout:=0.0')
    probe = probe_for('/goesback')
    now = time.time_ns()
    probe.send(now + NS // 2, ['joint3'], [1.4])          # 0.5 s ahead: accepted
    probe.wait_effort(now + NS // 2)
    stamps = [now + k * 1_000_000 for k in range(1, 11)]
    for stamp in stamps:
        probe.send(stamp, ['joint3'], [1.4])
    probe.wait_effort(stamps[-1])
    served = [s for s in stamps if probe.effort_at(s) is not None]
    assert served == stamps[4:], 'the 5th in a row starts a new stream'
    kv = wait_values(probe, lambda kv: int(kv['stamp_restarts']) >= 1)
    assert int(kv['rejected.stamp']) == 4 and int(kv['stamp_restarts']) == 1
    assert 'the estimator restarts' in proc.output


# --- item 13: setpoints lost before the node took them ------------------------------------------

def test_setpoints_lost_in_the_queue_are_counted(ros_process, probe_for):
    """Reliability item 13: a burst that overflowed the subscription queue lost thousands
    of setpoints while diagnostics said nothing; now setpoints_lost counts them (gaps in
    the single publisher's sequence numbers)."""
    start(ros_process, '/burst', '-p', 'setpoint_timeout:=0.0',
          '-p', 'qos_overrides./burst/joint_setpoint.subscription.depth:=1')
    probe = probe_for('/burst')
    base = time.time_ns() - NS
    probe.send(base, ['joint3'], [1.4])        # matched both ways once this is answered
    probe.wait_effort(base)
    n = 3001
    stream(probe, [1.4 + 1e-6 * k for k in range(1, n)], base + 100_000, step_ns=100_000)
    kv = wait_values(probe, lambda kv: sum(int(kv[k]) for k in (
        'setpoints_accepted', 'setpoints_rejected', 'setpoints_lost')) >= n - 100, timeout=30)
    accepted, lost = int(kv['setpoints_accepted']), int(kv['setpoints_lost'])
    rejected = int(kv['setpoints_rejected'])
    assert lost > 0
    # none is counted twice; the last ones of the burst may go uncounted (nothing follows)
    assert accepted + rejected + lost <= n
    assert accepted + rejected + lost >= n - 100, kv


# --- item 15: two nodes with the same name -----------------------------------------------------

def test_two_nodes_with_the_same_name_are_reported(ros_process, probe_for):
    """Reliability item 15: two nodes with the same full name ran silently (every setpoint
    got two commands); now each warns and its diagnostics say WARN."""
    first = start(ros_process, '/twins')
    second = start(ros_process, '/twins')
    probe = probe_for('/twins')
    for proc in (first, second):
        assert proc.wait_for_output('2 nodes named /twins/cog_id_node', timeout=20), proc.output
    # (a status computed before a node saw the other can still arrive after both said so,
    # late under load, as a CI run saw once: the first WARN one is waited for)
    after = time.monotonic()

    def warned():
        return any(t > after and s.level == DiagnosticStatus.WARN
                   and values(s)['nodes_with_this_name'] == '2'
                   for t, s in list(probe.diagnostics))
    assert wait_until(warned, 20), [(s.level, s.message) for t, s in probe.diagnostics
                                    if t > after][:5]


# --- item 9: trajectories do not stall the setpoint stream --------------------------------------

def long_trajectory(n):
    msg = JointTrajectory()
    msg.joint_names = ['joint3']
    t = np.arange(n) * 1e-3
    th = (np.pi / 2 + 0.5 * np.sin(np.pi * t)).tolist()
    from builtin_interfaces.msg import Duration
    msg.points = [JointTrajectoryPoint(positions=[a], velocities=[0.0], accelerations=[0.0],
                                       time_from_start=Duration(sec=int(x), nanosec=int(x % 1 * 1e9)))
                  for a, x in zip(th, t.tolist())]
    return msg


def test_a_long_trajectory_does_not_delay_the_hold_command(ros_process, probe_for):
    """Reliability item 9: while a 100,000-point trajectory was solved the setpoint stream
    stalled and the timeout's hold command came ~5 s late; the trajectory is now solved
    in a process of its own, so the hold command comes on time and the trajectory is
    answered."""
    # (max_setpoint_age 10 s: beside a loaded suite the node, taking the 3 MB trajectory
    # in, once took the setpoint after more than the default 0.5 s and refused it as
    # stale: no command, no stream, no hold. The hold's lateness is what is measured.)
    proc = start(ros_process, '/longtraj', '-p', 'setpoint_timeout:=0.3',
                 '-p', 'max_setpoint_age:=10.0')
    probe = probe_for('/longtraj')
    msg = long_trajectory(60_000)
    probe.trajectories.publish(msg)         # the node takes seconds to solve it
    stamp = time.time_ns()
    n_commands = len(probe.commands)
    probe.send(stamp, ['joint3'], [1.3])     # then the stream stops: the hold follows
    sent = time.monotonic()
    assert wait_until(lambda: len(probe.commands) >= n_commands + 2, timeout=30), \
        (len(probe.commands) - n_commands, proc.output)
    late = time.monotonic() - sent
    assert probe.effort_at(stamp) is not None
    assert probe.commands[n_commands + 1].data[0] == pytest.approx(hold(1.3), abs=1e-9)
    assert late < 2.0, f'hold command {late:.2f} s after the last setpoint (timeout 0.3 s)'
    assert not probe.effort_trajectories, 'the hold came after the trajectory: test too short'
    assert wait_until(lambda: probe.effort_trajectories, timeout=120)
    assert len(probe.effort_trajectories[-1].points) == 60_000


def test_too_long_a_trajectory_is_rejected_with_a_reason(ros_process, probe_for):
    """Reliability item 9: trajectories had no length bound; max_trajectory_points
    refuses longer ones (too_long), counted in diagnostics, without solving them."""
    proc = start(ros_process, '/toolong', '-p', 'max_trajectory_points:=100')
    probe = probe_for('/toolong')
    q = np.full((101, 1), 1.4)
    probe.trajectories.publish(make_trajectory(['joint3'], q, q * 0, q * 0))
    probe.trajectories.publish(make_trajectory(['joint3'], q[:100], q[:100] * 0, q[:100] * 0))
    # (an upper bound: the node's trajectory process starts beside it, a new Python that
    # imports and loads the kernels; under a loaded machine that has taken over 20 s)
    assert wait_until(lambda: probe.effort_trajectories, timeout=90), proc.output
    assert len(probe.effort_trajectories[0].points) == 100
    kv = wait_values(probe, lambda kv: kv['trajectories_rejected.too_long'] != '0')
    assert kv['trajectories_rejected.too_long'] == '1', (kv, proc.output)
    assert 'trajectory of 101 points rejected (too_long)' in proc.output


def test_a_second_trajectory_waits_and_a_third_replaces_it(ros_process, probe_for):
    """Reliability item 9: what happens to trajectories that arrive while one is solved
    was undefined (each held up the node in turn); one waits, a newer one replaces it
    and the replaced one is counted as rejected (busy)."""
    start(ros_process, '/queue')
    probe = probe_for('/queue')
    probe.trajectories.publish(long_trajectory(30_000))   # solved: it came first
    q = np.full((6, 1), 1.4)
    probe.trajectories.publish(make_trajectory(['joint3'], q, q * 0, q * 0))
    probe.trajectories.publish(make_trajectory(['joint3'], q[:5], q[:5] * 0, q[:5] * 0))
    assert wait_until(lambda: len(probe.effort_trajectories) >= 2, timeout=120)
    time.sleep(0.5)
    assert [len(m.points) for m in probe.effort_trajectories] == [30_000, 5]
    kv = wait_values(probe, lambda kv: kv['trajectories_rejected.busy'] != '0')
    assert kv['trajectories_rejected.busy'] == '1'


def test_an_exception_in_a_timer_callback_is_counted_not_raised(rclpy_context):
    """Reliability item 1: an exception in a timer callback (diagnostics, timeout) went out
    of executor.spin() and ended the node; now it is counted in internal_errors and
    logged, and the callback returns."""
    from mechanisms import from_yaml
    from rclpy.parameter import Parameter

    from cog_id_ros.ros.node import CogIdNode

    overrides = [Parameter(name, value=value) for name, value in from_yaml(CONFIG_A).items()]
    node = CogIdNode(context=rclpy_context, parameter_overrides=overrides, namespace='/unit')
    try:
        def broken(*args):
            raise ZeroDivisionError('a bug')
        node.report.closure_health = broken
        node.publish_diagnostics()
        node._check_timeout = broken
        node.check_timeout()
        assert node.counts.totals['internal_errors'] == 2
    finally:
        node.destroy_node()


def test_a_killed_trajectory_process_is_replaced(ros_process, probe_for):
    """Reliability item 9: trajectories are solved in a process of their own; if it dies
    (killed, out of memory) the node goes on and the next trajectory is answered by a
    new one."""
    import os
    import signal as signals
    import subprocess

    proc = start(ros_process, '/killed')
    probe = probe_for('/killed')
    children = subprocess.run(['pgrep', '-P', str(proc.proc.pid)], capture_output=True,
                              text=True).stdout.split()
    assert children, 'no trajectory process'
    for pid in children:
        os.kill(int(pid), signals.SIGKILL)
    time.sleep(0.5)
    q = np.full((6, 1), 1.4)
    probe.trajectories.publish(make_trajectory(['joint3'], q, q * 0, q * 0))
    assert wait_until(lambda: probe.effort_trajectories, timeout=60), proc.output
    assert proc.proc.poll() is None
