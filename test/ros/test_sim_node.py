"""cog_sim_node over real DDS traffic: a free swing sample for sample against Simulation,
bad effort messages counted and never integrated, a stop at a pose that cannot be closed and
~/reset, /clock and a use_sim_time node that follows it, the real-time factor, and
cog_id_node's efforts reaching it without a remap.

Each node runs as a subprocess (conftest.py: the session's ROS_DOMAIN_ID); a probe node in
this process records what it publishes and publishes efforts. The reference is
``cog_id_ros.Simulation`` in this process, stepped as the node steps it. Waits are generous
upper bounds; the timing assertions (the real-time factor) have wide margins.
"""
import math
import threading
import time

import numpy as np
import pytest
import yaml

rclpy = pytest.importorskip('rclpy')

from conftest import wait_until  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

import cog_id_ros  # noqa: E402
from cog_id_ros.ros.player import RECORDER_QOS  # noqa: E402
from cog_id_ros.ros.sim_topics import clock_qos  # noqa: E402
from cog_id_ros.ros.topics import control_qos  # noqa: E402

NS = 1_000_000_000
WAIT = 30.0
PAPER_A = 'config/paper_four_bar_a.yaml'
TILT = 1.2      # rad: the paper four-bar (a) started away from its upright equilibrium


def ns(stamp):
    return stamp.sec * NS + stamp.nanosec


def values(status):
    return {kv.key: kv.value for kv in status.values}


class SimProbe:
    """Publishes efforts into one simulator's namespace, calls its ~/reset, records its
    joint_states, /diagnostics and (when asked) /clock."""

    def __init__(self, context, namespace, clock=False):
        self.namespace = namespace
        self.node = rclpy.create_node(f'probe{namespace.replace("/", "_")}', namespace=namespace,
                                      context=context)
        self.commands = self.node.create_publisher(Float64MultiArray, 'effort_command',
                                                   control_qos())
        self.named = self.node.create_publisher(JointState, 'joint_effort_command', control_qos())
        self.states, self.diagnostics, self.clocks = [], [], []
        self.node.create_subscription(JointState, 'joint_states', self._on_state, RECORDER_QOS)
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self._on_diagnostics, 10)
        if clock:
            self.node.create_subscription(Clock, '/clock', self._on_clock, clock_qos())
        self.reset_client = self.node.create_client(Trigger, 'cog_sim_node/reset')
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self._thread = threading.Thread(target=self.executor.spin, daemon=True)
        self._thread.start()

    def _on_state(self, msg):
        self.states.append((time.monotonic(), msg))

    def _on_clock(self, msg):
        self.clocks.append((time.monotonic(), ns(msg.clock)))

    def _on_diagnostics(self, msg):
        for status in msg.status:
            if status.name.startswith(self.namespace + '/cog_sim_node'):
                self.diagnostics.append((time.monotonic(), status))

    def close(self):
        self.executor.shutdown()
        self.node.destroy_node()

    def connected(self, states=True):
        """Both effort topics matched (and, with ``states``, a joint_states received)."""
        return wait_until(lambda: self.commands.get_subscription_count() > 0
                          and self.named.get_subscription_count() > 0
                          and (self.states or not states), WAIT)

    def status_after(self, after, until=lambda status: True):
        """The first status received after monotonic ``after`` for which ``until`` holds."""
        def found():
            return next((s for t, s in list(self.diagnostics) if t > after and until(s)), None)
        assert wait_until(lambda: found() is not None, WAIT), \
            [values(s) for _, s in self.diagnostics[-2:]]
        return found()

    def send(self, *efforts):
        self.commands.publish(Float64MultiArray(data=list(efforts)))

    def send_named(self, names, efforts):
        self.named.publish(JointState(name=list(names), effort=list(efforts)))

    def reset(self):
        assert self.reset_client.wait_for_service(timeout_sec=WAIT)
        future = self.reset_client.call_async(Trigger.Request())
        assert wait_until(future.done, WAIT)
        return future.result()

    def by_stamp(self):
        return {ns(m.header.stamp): m for _, m in list(self.states)}


def tilted_params(tmp_path_factory, name='paper_a_tilted.yaml', theta=TILT):
    """The paper four-bar (a) with its cranks at ``theta`` (the parallelogram: joint1 =
    joint3 = joint4 = theta, joint2 = -theta), so that it swings under gravity."""
    with open(PAPER_A, encoding='utf-8') as stream:
        doc = yaml.safe_load(stream)
    doc['/**']['ros__parameters']['mechanism']['initial_positions'] = [theta, -theta, theta,
                                                                     theta]
    path = tmp_path_factory.mktemp('sim_params') / name
    path.write_text(yaml.safe_dump(doc))
    return str(path)


def start_sim(ros_process, params_file, namespace, *extra):
    proc = ros_process(['cog_sim_node', '--ros-args', '--params-file', params_file,
                        '-r', f'__ns:={namespace}', *extra])
    assert proc.wait_for_output("mechanism '", timeout=60), proc.output
    return proc


def reference(params_file, backend):
    return cog_id_ros.Simulation(cog_id_ros.Mechanism.from_params_file(params_file),
                                 time_step=0.001, backend=backend)


def assert_matches_simulation(states, simulation, until_ns):
    """Every joint_states message stamped up to ``until_ns`` is the Simulation's state after
    as many steps (positions and velocities of every joint; efforts 0)."""
    simulation.reset()
    stamps = sorted(s for s in states if s <= until_ns)
    assert len(stamps) >= 20, sorted(states)[:5]
    steps = 0
    for stamp in stamps:
        k = round(stamp / 1e6)
        assert stamp == k * 1_000_000, stamp
        while steps < k:
            simulation.step([0.0])
            steps += 1
        msg = states[stamp]
        np.testing.assert_allclose(msg.position, simulation.joint_positions(), rtol=0,
                                   atol=1e-12, err_msg=f'positions at step {k}')
        np.testing.assert_allclose(msg.velocity, simulation.joint_velocities(), rtol=0,
                                   atol=1e-12, err_msg=f'velocities at step {k}')
        assert list(msg.effort) == [0.0] * 4
    return stamps


def assert_finite(probe):
    for _, msg in list(probe.states):
        assert all(map(math.isfinite, [*msg.position, *msg.velocity, *msg.effort])), msg


# --- a free swing, and bad messages during it ---------------------------------------------

@pytest.fixture(scope='module')
def swing(ros_process, rclpy_context, tmp_path_factory):
    params = tilted_params(tmp_path_factory)
    proc = start_sim(ros_process, params, '/swing', '-p', 'joint_states_period:=0.005')
    probe = SimProbe(rclpy_context, '/swing')
    assert probe.connected(), proc.output
    yield proc, probe, params
    probe.close()
    assert proc.stop() == 0, f'cog_sim_node did not exit cleanly on SIGINT:\n{proc.output}'


def test_free_swing_matches_simulation_sample_for_sample(swing):
    """Every joint_states of a second of swing (from whenever the probe heard the first)."""
    proc, probe, params = swing
    first = min(probe.by_stamp())
    assert wait_until(lambda: max(probe.by_stamp()) >= first + NS, WAIT), proc.output
    status = values(probe.status_after(0.0))
    simulation = reference(params, status['backend'])
    states = probe.by_stamp()
    stamps = assert_matches_simulation(states, simulation, max(states))
    assert len(stamps) >= 150                           # 200 in the second, at 5 ms
    first = states[stamps[0]]
    assert list(first.name) == ['joint1', 'joint2', 'joint3', 'joint4']
    assert np.ptp([states[s].position[2] for s in stamps]) > 0.1    # it moved
    assert_finite(probe)
    # the Simulation's accuracy, from the integration thread: no effort, no work, and the
    # energy of a free swing kept (its drift far below the energy itself)
    got = values(probe.status_after(time.monotonic(),
                                    lambda st: values(st)['energy_drift'] != ''))
    assert float(got['work']) == 0.0 and float(got['energy']) != 0.0
    assert abs(float(got['energy_drift'])) < 1e-6 * abs(float(got['energy'])), got
    assert 0.0 <= float(got['error_estimate_total']) < 1e-3 and int(got['divided_steps']) >= 0


BAD = [  # (topic, efforts or (names, efforts), reason)
    ('command', [1.0, 2.0], 'length'),
    ('command', [], 'length'),
    ('command', [math.nan], 'non_finite'),
    ('command', [math.inf], 'non_finite'),
    ('command', [1e300], 'magnitude'),
    ('named', (['joint1'], [1.0]), 'names'),
    ('named', (['joint3', 'joint3'], [1.0, 1.0]), 'names'),
    ('named', (['joint3'], []), 'length'),
    ('named', (['joint3'], [-math.inf]), 'non_finite'),
    ('named', (['joint2', 'joint3'], [0.0, -2e6]), 'magnitude'),
]


def test_bad_messages_are_counted_and_never_integrated(swing):
    proc, probe, params = swing
    for topic, efforts, _ in BAD:
        if topic == 'command':
            probe.send(*efforts)
        else:
            probe.send_named(*efforts)
    expected = {reason: sum(1 for *_, r in BAD if r == reason)
                for reason in ('length', 'non_finite', 'magnitude', 'names')}
    sent = time.monotonic()

    def counted(status):
        return values(status)['efforts_rejected'] == str(len(BAD))
    status = probe.status_after(sent, counted)
    got = values(status)
    assert {r: int(got[f'rejected.{r}']) for r in expected} == expected
    assert got['efforts_accepted'] == '0' and got['integrating'] == 'true'
    assert got['effort_stream'] == 'no effort yet'
    assert got['last_rejection'].startswith('magnitude: ')
    assert status.level == DiagnosticStatus.WARN or any(
        s.level == DiagnosticStatus.WARN for t, s in probe.diagnostics if t > sent)
    # none acted: the motion after them is still the free swing, sample for sample
    now = max(probe.by_stamp())
    assert wait_until(lambda: max(probe.by_stamp()) >= now + NS // 2, WAIT)
    assert_matches_simulation(probe.by_stamp(), reference(params, got['backend']),
                              max(probe.by_stamp()))
    assert_finite(probe)
    assert 'rejected, not integrated (magnitude)' in proc.output


def test_an_effort_stream_that_stops_is_zeroed_after_effort_timeout(swing):
    """One message (after the free-swing tests: it ends the free swing): it acts for
    effort_timeout (0.5 s) of simulated time, then zeros act (effort_timeout_behavior)."""
    proc, probe, params = swing
    sent = time.monotonic()
    probe.send_named(['joint1', 'joint3'], [9.0, 1.25])

    def acted():
        return sorted(ns(m.header.stamp) for t, m in list(probe.states)
                      if t > sent and m.effort[2] == 1.25)
    status = probe.status_after(sent, lambda s: values(s)['effort_timeouts'] == '1')
    got = values(status)
    assert got['effort_stream'] == 'stopped (zero)' and got['efforts_accepted'] == '1'
    stamps = acted()
    assert stamps, proc.output[-2000:]
    # every joint_states from the first with the effort to the last: 5 ms apart, 0.5 s long
    assert np.diff(stamps).tolist() == [5_000_000] * (len(stamps) - 1)
    assert 0.49 * NS <= stamps[-1] - stamps[0] <= 0.5 * NS
    after = [m for _, m in list(probe.states) if ns(m.header.stamp) > stamps[-1]]
    assert after and all(list(m.effort) == [0.0] * 4 for m in after)
    assert [m.effort for _, m in probe.states if ns(m.header.stamp) == stamps[0]][0][0] == 0.0


# --- a stop at a pose that cannot be closed; ~/reset ---------------------------------------

NON_GRASHOF = """
/**:
  ros__parameters:
    mechanism:
      name: non_grashof
      gravity: [0.0, -9.81, 0.0]
      links: [link1, link2, link3]
      joints: [joint1, joint2, joint3, joint4]
      active_joints: [joint1]
      initial_positions: [0.5, 3.3166, 2.9666, -0.85]
    links:
      link1: {mass: 1.0, com: [0.25, 0.0, 0.0], inertia: [0.0, 0.02, 0.02, 0.0, 0.0, 0.0]}
      link2: {mass: 1.0, com: [0.15, 0.0, 0.0], inertia: [0.0, 0.01, 0.01, 0.0, 0.0, 0.0]}
      link3: {mass: 1.0, com: [0.15, 0.0, 0.0], inertia: [0.0, 0.01, 0.01, 0.0, 0.0, 0.0]}
    joints:
      joint1: {type: revolute, parent: ground, child: link1}
      joint2: {type: revolute, parent: link1, child: link2, parent_xyz: [0.5, 0.0, 0.0]}
      joint3: {type: revolute, parent: ground, child: link3, parent_xyz: [0.5, 0.0, 0.0]}
      joint4: {type: revolute, parent: link2, child: link3, parent_xyz: [0.3, 0.0, 0.0],
               child_xyz: [0.3, 0.0, 0.0]}
"""


def test_a_pose_that_cannot_be_closed_stops_it_and_reset_recovers(ros_process, rclpy_context,
                                                                   tmp_path_factory):
    """A non-Grashof four-bar falls under gravity to its dead point (about 0.42 s): the
    integration stops with an ERROR naming the closure and the time; ~/reset starts again."""
    path = tmp_path_factory.mktemp('sim_params') / 'non_grashof.yaml'
    path.write_text(NON_GRASHOF)
    proc = start_sim(ros_process, str(path), '/stop', '-p', 'diagnostics_period:=0.2')
    probe = SimProbe(rclpy_context, '/stop')
    try:
        assert probe.connected(states=False), proc.output
        status = probe.status_after(0.0, lambda s: s.level == DiagnosticStatus.ERROR)
        got = values(status)
        assert got['integrating'] == 'false' and got['stops'] == '1'
        assert 'closure' in status.message and 'simulation stopped at t = ' in status.message
        assert 'cannot go past' in got['stop_reason'] or 'cannot be closed' in got['stop_reason']
        stopped_at = float(got['sim_time'])
        assert 0.3 < stopped_at < 0.6
        count = len(probe.states)
        time.sleep(0.5)
        assert len(probe.states) == count              # nothing published while stopped
        before = time.monotonic()
        answer = probe.reset()
        assert answer.success, answer.message
        assert wait_until(lambda: any(t > before and ns(m.header.stamp) == 0
                                      for t, m in probe.states), WAIT)
        again = probe.status_after(before, lambda s: values(s)['resets'] == '1')
        assert values(again)['stops'] in ('1', '2')     # it may have fallen again already
        restarted = [m for t, m in probe.states if t > before]
        assert restarted[0].position[0] == pytest.approx(0.5, abs=1e-9)
        assert_finite(probe)
    finally:
        probe.close()
        assert proc.stop() == 0, proc.output


# --- /clock, use_sim_time, the real-time factor --------------------------------------------

def test_clock_follows_sim_time_at_the_real_time_factor(ros_process, rclpy_context,
                                                       tmp_path_factory):
    params = tilted_params(tmp_path_factory, 'clock.yaml')
    proc = start_sim(ros_process, params, '/clocked', '-p', 'publish_clock:=true',
                     '-p', 'real_time_factor:=0.5', '-p', 'diagnostics_period:=0.5')
    probe = SimProbe(rclpy_context, '/clocked', clock=True)
    follower = rclpy.create_node('sim_time_follower', context=rclpy_context,
                                 parameter_overrides=[Parameter('use_sim_time', value=True)])
    executor = SingleThreadedExecutor(context=rclpy_context)
    executor.add_node(follower)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    try:
        assert probe.connected(), proc.output
        assert wait_until(lambda: len(probe.clocks) > 100, WAIT)
        start = time.monotonic()
        time.sleep(2.0)
        clocks = [c for c in list(probe.clocks) if c[0] >= start]
        stamps = [c[1] for c in clocks]
        assert stamps == sorted(stamps) and len(set(stamps)) == len(stamps)   # advancing
        # at most what was asked (wall time of the sample +- the 0.1 s of delivery), and
        # not much less on a loaded machine
        rate = (stamps[-1] - stamps[0]) / NS / (clocks[-1][0] - clocks[0][0])
        assert 0.25 < rate < 0.6, rate
        # the simulated time, step by step: whole time steps (1 ms), as joint_states' stamps
        assert all(s % 1_000_000 == 0 for s in stamps)
        assert all(s % 1_000_000 == 0 for s in probe.by_stamp())
        # a node with use_sim_time follows it
        now = follower.get_clock().now().nanoseconds
        assert abs(now - probe.clocks[-1][1]) < 0.2 * NS and now > NS // 2
        got = values(probe.status_after(time.monotonic()))
        assert 0.25 < float(got['real_time_factor_achieved']) < 0.6, got
        assert got['real_time_factor'] == '0.5'
    finally:
        executor.shutdown()
        follower.destroy_node()
        probe.close()
        assert proc.stop() == 0, proc.output


def test_as_fast_as_possible_runs_faster_than_real_time(ros_process, rclpy_context,
                                                        tmp_path_factory):
    # swinging about its hanging pose: from the tilted upright one, as fast as possible, the
    # four-bar reaches its flat (singular) pose within a second or two and stops there
    params = tilted_params(tmp_path_factory, 'fast.yaml', theta=-math.pi / 2 + 0.2)
    proc = start_sim(ros_process, params, '/fast', '-p', 'real_time_factor:=0.0',
                     '-p', 'diagnostics_period:=0.5', '-p', 'joint_states_period:=0.1')
    probe = SimProbe(rclpy_context, '/fast')
    try:
        assert probe.connected(), proc.output
        # the first report has no factor yet (nothing to compare with): the next one
        got = values(probe.status_after(time.monotonic() + 0.6, lambda status: (
            values(status)['real_time_factor_achieved'] != ''
            or values(status)['integrating'] == 'false')))
        assert got['integrating'] == 'true', got
        assert float(got['real_time_factor_achieved']) > 1.0, got
        assert got['real_time_factor'] == '0'
    finally:
        probe.close()
        assert proc.stop() == 0, proc.output


def test_wait_for_effort_holds_the_state_until_the_first_effort(ros_process, rclpy_context,
                                                                 tmp_path_factory):
    """wait_for_effort: the tilted four-bar (which falls at once without it) stays at time
    0 and its initial pose, joint_states and /clock repeated at 0, until an effort comes;
    then it integrates from there, sample for sample as Simulation; after ~/reset it holds
    again."""
    params = tilted_params(tmp_path_factory, 'held.yaml')
    proc = start_sim(ros_process, params, '/held', '-p', 'wait_for_effort:=true',
                     '-p', 'publish_clock:=true', '-p', 'joint_states_period:=0.005')
    probe = SimProbe(rclpy_context, '/held', clock=True)
    initial = [TILT, -TILT, TILT, TILT]

    def held_since(start):
        states = [m for t, m in list(probe.states) if t >= start]
        clocks = [c for t, c in list(probe.clocks) if t >= start]
        assert len(states) >= 5 and len(clocks) >= 5, (len(states), len(clocks))
        assert all(ns(m.header.stamp) == 0 for m in states), [ns(m.header.stamp)
                                                             for m in states][-3:]
        assert clocks == [0] * len(clocks), clocks[-3:]
        for msg in states:
            np.testing.assert_allclose(msg.position, initial, rtol=0, atol=1e-9)
            assert list(msg.velocity) == [0.0] * 4
    try:
        assert probe.connected(), proc.output
        start = time.monotonic()
        time.sleep(1.0)                 # the held state is published again every 0.1 s
        held_since(start)
        probe.send(0.0)                 # the first effort: the brakes release
        assert wait_until(lambda: max(probe.by_stamp()) >= NS // 2, WAIT), proc.output
        status = values(probe.status_after(0.0))
        simulation = reference(params, status['backend'])
        simulation.reset()
        np.testing.assert_allclose(simulation.joint_positions(), initial, atol=1e-9)
        assert_matches_simulation(probe.by_stamp(), simulation, NS // 2)
        assert probe.reset().success
        start = time.monotonic() + 0.05     # what was in flight before the reset
        time.sleep(1.0)
        held_since(start)
        assert_finite(probe)
    finally:
        probe.close()
        assert proc.stop() == 0, proc.output


# --- cog_id_node's efforts, no remap -------------------------------------------------------

def test_cog_id_node_efforts_reach_it_without_remap(ros_process, rclpy_context):
    """Both nodes from the same parameter file in one namespace: cog_id_node's
    effort_command is the simulator's input as it is (cog_id_node's own joint_states off)."""
    id_node = ros_process(['cog_id_node', '--ros-args', '--params-file', PAPER_A,
                           '-r', '__ns:=/pair', '-p', 'joint_states_decimation:=0',
                           '-p', 'setpoint_timeout:=0.0'])
    assert id_node.wait_for_output("mechanism '", timeout=60), id_node.output
    sim = start_sim(ros_process, PAPER_A, '/pair', '-p', 'effort_timeout_behavior:=hold',
                    '-p', 'diagnostics_period:=0.3')
    probe = SimProbe(rclpy_context, '/pair')
    setpoints = probe.node.create_publisher(JointState, 'joint_setpoint', control_qos())
    try:
        assert probe.connected(), sim.output
        assert wait_until(lambda: setpoints.get_subscription_count() > 0, WAIT)
        theta = 1.0
        # a resting setpoint: cog_id_node commands the gravity torque 2 m g L cos(theta)
        expected = 2.0 * 1.0 * 9.81 * 0.5 * math.cos(theta)
        sent = time.monotonic()

        def applied():
            return [m for t, m in list(probe.states) if t > sent and m.effort[2] != 0.0]
        # sent again every 0.5 s until it acts: cog_id_node's publisher may not have
        # matched the simulator's subscription yet (the command would be lost), and a
        # loaded machine may make cog_id_node reject a setpoint as stale
        end = time.monotonic() + WAIT
        while not applied() and time.monotonic() < end:
            msg = JointState(name=['joint3'], position=[theta], velocity=[0.0])
            msg.header.stamp = probe.node.get_clock().now().to_msg()
            setpoints.publish(msg)
            wait_until(lambda: applied(), 0.5)
        assert applied(), (id_node.output[-2000:], sim.output[-2000:])
        assert applied()[0].effort[2] == pytest.approx(expected, rel=1e-6)
        assert [m.effort[i] for m in applied() for i in (0, 1, 3)] == \
            [0.0] * (3 * len(applied()))
        got = values(probe.status_after(sent, lambda s: values(s)['efforts_accepted'] != '0'))
        assert int(got['efforts_accepted']) >= 1 and got['efforts_rejected'] == '0'
        assert got['joint_states_publishers'] == '1'
    finally:
        probe.close()
        assert sim.stop() == 0, sim.output
        assert id_node.stop() == 0, id_node.output


def test_a_parameter_it_cannot_honour_is_one_line_and_exit_status_2(ros_process):
    proc = ros_process(['cog_sim_node', '--ros-args', '--params-file', PAPER_A,
                        '-p', 'real_time_factor:=-1.0'])
    assert proc.proc.wait(timeout=60) == 2
    assert 'cog_sim_node: cannot start: real_time_factor: must be from 0.001 to 1000' \
        in proc.output


def test_help_and_no_parameters(ros_env):
    import subprocess
    import sys
    exe = [sys.executable, '-m', 'cog_id_ros.ros.sim_main']
    shown = subprocess.run([*exe, '--help'], env=ros_env, capture_output=True, text=True,
                           timeout=60)
    assert shown.returncode == 0 and shown.stdout.startswith('usage: cog_sim_node')
    bare = subprocess.run(exe, env=ros_env, capture_output=True, text=True, timeout=60)
    assert bare.returncode == 2
    assert bare.stderr.startswith('cog_sim_node: cannot start: no mechanism parameters given')
