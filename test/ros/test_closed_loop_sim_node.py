"""cog_id_node's feedback modes closing the loop through cog_sim_node, over real topics.

The plant is ``cog_sim_node`` (a subprocess: ``cog_id_ros.Simulation`` stepped by its own
thread at ``real_time_factor`` 0.2, publishing ``joint_states`` after every step, stamped
with simulated time) and the controller ``cog_id_node`` in the same namespace with
``-r measured_joint_states:=joint_states`` (its ``effort_command`` is the simulator's
input without a remap): the two connect as a robot and its controller would. Each run
starts from ``~/reset`` (the simulator back at ``initial_positions`` at rest, simulated
time 0) once the controller hears the simulator; a recorder in this process keeps the
simulated joint states. On the paper four-bar, the five-bar and the Stewart platform,
computed torque (kp 400, kd 40) brings a start error of 0.1 rad (0.01 m) below 1e-3 rad (1e-4 m) within 0.5 s and
holds it there. The commands act a step late or so (the simulator holds the newest effort
it has at each step, and none for the first steps after a reset), which the loop corrects;
0.2 of real time leaves the controller five times a step's time to answer.

Gravity compensation holds the tilted paper four-bar (where zero effort falls) to 1e-4 rad
over 2 s of simulated time, the simulator given ``wait_for_effort:=true``: it has no
stiffness, so without that hold the velocity the first steps after ``~/reset`` pick up with
no effort held (until the first command arrives) would stay, and the pose drift with it.
"""
import threading
import time

import numpy as np
import pytest
import yaml

rclpy = pytest.importorskip('rclpy')

from conftest import wait_until  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

import cog_id_ros  # noqa: E402
from cog_id_ros.ros.player import RECORDER_QOS  # noqa: E402
from cog_id_ros.ros.topics import control_qos  # noqa: E402

NS = 1_000_000_000
CONFIGS = {'four_bar': 'config/paper_four_bar_a.yaml', 'five_bar': 'config/five_bar.yaml',
           'stewart': 'config/stewart_6ups_spherical.yaml'}
START = {'revolute': 0.1, 'prismatic': 0.01}
BOUND = {'revolute': 1e-3, 'prismatic': 1e-4}


class Pair:
    """cog_sim_node and cog_id_node in one namespace, and a recorder of joint_states."""

    def __init__(self, ros_process, context, key, namespace, *controller, params=None,
                 sim_extra=()):
        self.params = params or CONFIGS[key]
        self.mech = cog_id_ros.Mechanism.from_params_file(self.params)
        self.sim = ros_process(['cog_sim_node', '--ros-args', '--params-file', self.params,
                                '-r', f'__ns:={namespace}', '-p', 'real_time_factor:=0.2',
                                '-p', 'joint_states_period:=0.0',
                                '-p', 'effort_timeout:=0.0', *sim_extra])
        self.node = ros_process(['cog_id_node', '--ros-args', '--params-file', self.params,
                                 '-r', f'__ns:={namespace}',
                                 '-r', 'measured_joint_states:=joint_states',
                                 '-p', 'measurement_timeout:=2.0',
                                 '-p', 'setpoint_timeout:=0.0',
                                 '-p', 'max_measurement_step:=[.inf]', *controller])
        self.probe = rclpy.create_node(f'probe{namespace.replace("/", "_")}',
                                       namespace=namespace, context=context)
        self.states = []
        self.probe.create_subscription(JointState, 'joint_states', self.states.append,
                                       RECORDER_QOS)
        self.setpoints = self.probe.create_publisher(JointState, 'joint_setpoint',
                                                     control_qos())
        self.reset_client = self.probe.create_client(Trigger, 'cog_sim_node/reset')
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.probe)
        threading.Thread(target=self.executor.spin, daemon=True).start()
        assert self.node.wait_for_output("mechanism '", timeout=60), self.node.output
        joint_states = self.probe.resolve_topic_name('joint_states')
        effort = self.probe.resolve_topic_name('effort_command')
        assert wait_until(lambda: self.probe.count_subscribers(joint_states) >= 2
                          and self.probe.count_subscribers(effort) >= 1
                          and self.reset_client.service_is_ready(), timeout=60), \
            self.sim.output + self.node.output
        index = [self.mech.joints.index(j) for j in self.mech.active_joints]
        self.index = index
        self.units = np.array([self.mech.joint_types[i] for i in index])
        self.q0 = np.array([self.mech.assembled_positions[i] for i in index])

    def scale(self, table):
        return np.array([table[u] for u in self.units])

    def send_setpoint(self, q):
        msg = JointState()
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(time.time_ns(), NS)
        msg.name = list(self.mech.active_joints)
        msg.position = [float(x) for x in q]
        msg.velocity = [0.0] * len(q)
        self.setpoints.publish(msg)

    def reset_and_record(self, seconds):
        """~/reset, then the active positions over ``seconds`` of simulated time:
        (times, positions) from the reset on."""
        start = len(self.states)
        assert self.reset_client.call(Trigger.Request(), timeout_sec=30).success

        def simulated(msg):
            return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9

        def enough():
            after = self.states[start:]
            return bool(after) and simulated(after[-1]) >= seconds
        assert wait_until(enough, timeout=seconds / 0.2 * 4 + 30), self.sim.output
        after = [m for m in self.states[start:] if simulated(m) <= seconds]
        zero = max(k for k, m in enumerate(after) if simulated(m) == 0.0)
        after = after[zero:]
        t = np.array([simulated(m) for m in after])
        q = np.array([[m.position[i] for i in self.index] for m in after])
        return t, q

    def close(self):
        self.executor.shutdown()
        self.probe.destroy_node()
        assert self.node.stop() == 0, self.node.output
        assert self.sim.stop() == 0, self.sim.output


@pytest.mark.parametrize('key', list(CONFIGS))
def test_computed_torque_through_the_simulator_brings_the_error_down(ros_process,
                                                                     rclpy_context, key):
    pair = Pair(ros_process, rclpy_context, key, f'/sn_ct_{key}',
                '-p', 'control_mode:=computed_torque', '-p', 'kp:=[400.0]',
                '-p', 'kd:=[40.0]')
    try:
        goal = pair.q0 + pair.scale(START)
        for _ in range(20):         # more than once: the node may not have matched us yet
            pair.send_setpoint(goal)
            time.sleep(0.05)
        t, q = pair.reset_and_record(1.5)
        error = np.abs(q - goal)
        assert np.allclose(error[0], pair.scale(START))
        assert (error[t >= 0.5] < pair.scale(BOUND)).all(), error[t >= 0.5].max(axis=0)
    finally:
        pair.close()


TILT = 1.2      # rad: the paper four-bar (a)'s parallelogram away from its upright pose


def tilted_four_bar(tmp_path):
    with open(CONFIGS['four_bar'], encoding='utf-8') as stream:
        doc = yaml.safe_load(stream)
    doc['/**']['ros__parameters']['mechanism']['initial_positions'] = [TILT, -TILT, TILT,
                                                                     TILT]
    path = tmp_path / 'tilted.yaml'
    path.write_text(yaml.safe_dump(doc))
    return str(path)


def test_gravity_compensation_through_the_simulator_holds_a_pose_where_zero_effort_falls(
        ros_process, rclpy_context, tmp_path):
    params = tilted_four_bar(tmp_path)
    falling = cog_id_ros.Simulation(cog_id_ros.Mechanism.from_params_file(params))
    for _ in range(200):
        falling.step([0.0])
    assert abs(falling.positions[0] - TILT) > 1e-2      # zero effort: it falls at once
    pair = Pair(ros_process, rclpy_context, 'four_bar', '/sn_gc', '-p',
                'control_mode:=gravity_compensation', params=params,
                sim_extra=('-p', 'wait_for_effort:=true'))
    try:
        t, q = pair.reset_and_record(2.0)
        assert t[-1] >= 1.99 and len(t) >= 1900, (t[-1], len(t))
        assert np.allclose(q[0], TILT, rtol=0, atol=1e-12)
        drift = np.abs(q - TILT).max()
        assert drift < 1e-4, drift
    finally:
        pair.close()
