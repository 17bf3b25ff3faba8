"""Soak of cog_id_node in a feedback mode: a closed loop at 1 kHz for minutes, 0 lost, RSS flat.

    .venv/bin/python bench/bench_control_soak.py [--minutes 10] [--rate 1000]
        [--params-file config/paper_four_bar_a.yaml] [--mode computed_torque] [--json F]

Starts one ``cog_id_node`` (``--mode``, kp 100 and kd 20 for computed torque) on a DDS
domain of its own and closes it in real time through a plant in this process: a
``cog_id_ros.Simulation`` of the same mechanism stepped once a period with the latest
command received (zero-order hold, as a motor driver holds one), whose state is published
on ``measured_joint_states`` every period after the setpoint of the paper-like motion
(every active joint at its initial position plus 0.3 rad or 3 cm times sin(pi t)).
Every 10 s it reads the node's resident memory (VmRSS of /proc/<pid>/status) and its
/diagnostics counters; at the end it prints the states sent, the commands received (lost =
sent - received after a drain), the node's own counts (accepted, rejected by reason,
timeouts), the largest gap between two commands, the RSS at each minute and its growth
over the second half, and the worst tracking error. Exit status 0 when nothing was lost or
rejected and the RSS grew by less than 5 MB over the second half; 1 otherwise.
"""
import argparse
import json
import math
import os
import subprocess
import sys
import threading
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
NS = 1_000_000_000


def rss_mb(pid):
    try:
        with open(f'/proc/{pid}/status', encoding='ascii') as stream:
            for line in stream:
                if line.startswith('VmRSS:'):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return math.nan


class Plant:
    """The real-time plant: publishers, the latest command, the commands' arrival times."""

    def __init__(self, mechanism):
        from diagnostic_msgs.msg import DiagnosticArray
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from sensor_msgs.msg import JointState
        from std_msgs.msg import Float64MultiArray

        from cog_id_ros.ros.topics import control_qos
        rclpy.init()
        self.node = rclpy.create_node('control_soak_plant')
        self.mechanism = mechanism
        self.setpoints = self.node.create_publisher(JointState, '/soak/joint_setpoint',
                                                    control_qos())
        self.states = self.node.create_publisher(JointState, '/soak/measured_joint_states',
                                                 control_qos())
        self.latest = [0.0] * len(mechanism.active_joints)
        self.received = 0
        self.last_arrival = None
        self.worst_gap = 0.0
        self.diagnostics = {}
        self.node.create_subscription(Float64MultiArray, '/soak/effort_command',
                                      self._on_command, control_qos())
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self._on_diagnostics, 10)
        self.msg = JointState
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        threading.Thread(target=self.executor.spin, daemon=True).start()

    def _on_command(self, msg):
        now = time.monotonic()
        if self.last_arrival is not None:
            self.worst_gap = max(self.worst_gap, now - self.last_arrival)
        self.last_arrival = now
        self.latest = list(msg.data)
        self.received += 1

    def _on_diagnostics(self, msg):
        for status in msg.status:
            if status.name.startswith('/soak/'):
                self.diagnostics = {kv.key: kv.value for kv in status.values}

    def message(self, stamp, names, q, qd):
        msg = self.msg()
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp, NS)
        msg.name, msg.position, msg.velocity = names, q, qd
        return msg


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--minutes', type=float, default=10.0)
    parser.add_argument('--rate', type=float, default=1000.0)
    parser.add_argument('--params-file',
                        default=os.path.join(REPO, 'config', 'paper_four_bar_a.yaml'))
    parser.add_argument('--mode', default='computed_torque')
    parser.add_argument('--json')
    args = parser.parse_args(argv)
    os.environ.setdefault('ROS_DOMAIN_ID', str(150 + os.getpid() % 80))
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    import cog_id_ros
    mech = cog_id_ros.Mechanism.from_params_file(args.params_file)
    period = 1.0 / args.rate
    sim = cog_id_ros.Simulation(mech, period)
    q0 = np.array(sim.positions)
    amplitude = np.array([0.3 if mech.joint_types[mech.joints.index(j)] == 'revolute'
                          else 0.03 for j in mech.active_joints])
    node = subprocess.Popen(
        [sys.executable, '-m', 'cog_id_ros.node', '--ros-args', '--params-file',
         args.params_file, '-r', '__ns:=/soak', '-p', f'control_mode:={args.mode}',
         '-p', 'kp:=[100.0]', '-p', 'kd:=[20.0]', '-p', 'measurement_timeout:=0.5'],
        stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT, cwd=REPO)
    plant = Plant(mech)
    active, every = list(mech.active_joints), list(mech.joints)
    samples, sent, resets, worst_error = [], 0, 0, 0.0
    try:
        end = time.monotonic() + 60
        while not (plant.states.get_subscription_count() and
                   plant.node.count_publishers('/soak/effort_command')):
            if time.monotonic() > end:
                print('the node did not connect', file=sys.stderr)
                return 1
            time.sleep(0.1)
        time.sleep(1.0)
        steps = int(round(args.minutes * 60 * args.rate))
        t0, stamp0 = time.perf_counter(), time.time_ns()
        next_sample = 0.0
        for k in range(steps):
            due = t0 + k * period
            while (now := time.perf_counter()) < due:
                if due - now > 0.0005:
                    time.sleep(due - now - 0.0004)
            t = k * period
            stamp = stamp0 + int(t * NS)
            q_d = q0 + amplitude * math.sin(math.pi * t)
            qd_d = amplitude * math.pi * math.cos(math.pi * t)
            plant.setpoints.publish(plant.message(stamp, active, q_d.tolist(), qd_d.tolist()))
            plant.states.publish(plant.message(stamp, every, sim.joint_positions().tolist(),
                                               sim.joint_velocities().tolist()))
            sent += 1
            worst_error = max(worst_error, float(np.abs(q_d - sim.positions).max()))
            try:
                sim.step(plant.latest)
            except cog_id_ros.CogIdError:
                resets += 1
                sim.reset()
            if t >= next_sample:
                samples.append((t, rss_mb(node.pid), dict(plant.diagnostics)))
                next_sample += 10.0
        time.sleep(1.0)
        samples.append((args.minutes * 60, rss_mb(node.pid), dict(plant.diagnostics)))
    finally:
        node.send_signal(2)
        try:
            node.wait(15)
        except subprocess.TimeoutExpired:
            node.kill()
    return report(args, sent, plant, samples, resets, worst_error)


def report(args, sent, plant, samples, resets, worst_error):
    lost = sent - plant.received
    last = samples[-1][2]
    rejected = int(last.get('measurements_rejected', 0) or 0)
    rss = [(t, r) for t, r, _ in samples]
    half = [r for t, r in rss if t >= args.minutes * 30]
    growth = (half[-1] - half[0]) if len(half) > 1 else math.nan
    print(f'{os.path.basename(args.params_file)}, {args.mode}, {args.rate:g} Hz, '
          f'{args.minutes:g} min')
    print(f'measured states sent {sent}, commands received {plant.received}, lost {lost}; '
          f"node: accepted {last.get('measurements_accepted')}, rejected {rejected}, "
          f"timeouts {last.get('timeouts')}, setpoints lost {last.get('setpoints_lost')}")
    print(f'worst gap between commands {plant.worst_gap * 1e3:.1f} ms; worst tracking error '
          f'{worst_error:.3g}; plant resets {resets}; node compute median '
          f"{last.get('compute_time_median_us')} us")
    print('RSS (MB) every minute: ' + ', '.join(f'{r:.1f}' for t, r in rss
                                                  if abs(t / 60 - round(t / 60)) < 1e-6 or
                                                  t == rss[-1][0]))
    print(f'RSS growth over the second half: {growth:+.2f} MB')
    if args.json:
        with open(args.json, 'w', encoding='utf-8') as stream:
            json.dump({'sent': sent, 'received': plant.received, 'lost': lost,
                       'rejected': rejected, 'rss': rss, 'growth_mb': growth,
                       'worst_gap_s': plant.worst_gap, 'worst_error': worst_error,
                       'resets': resets, 'diagnostics': last}, stream, indent=1)
    return 0 if lost == 0 and rejected == 0 and growth < 5.0 else 1


if __name__ == '__main__':
    sys.exit(main())
