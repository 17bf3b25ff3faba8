"""Latency of cog_id_node's feedback modes: from a measured state's publish to its command,
beside feed-forward's setpoint-to-command latency, at 1 kHz.

    .venv/bin/python bench/bench_control_latency.py [--params-file config/stewart_6ups.yaml]
        [--mode computed_torque] [--rate 1000] [--duration 10] [--block 1] [--json F]

Starts two ``cog_id_node`` processes on a DDS domain of their own (localhost only) from the
same params file: /ff in ``control_mode: feedforward`` and /fb in ``--mode``. A driver in
this process (publishing from its main thread, receiving on a thread of its own) plays the
mechanism's motion (every active joint at its initial position plus a small sine: 0.05 rad
or 5 mm, period 2 s) in interleaved blocks of ``--block`` seconds (ff, fb, then the next
round in the opposite order), ``--duration`` seconds per node in all:

* /ff gets one setpoint per period; the latency is from just before its ``publish`` to the
  arrival of its ``effort_command``;
* /fb gets, per period, the setpoint and then the measured state (the same pose and
  velocity, positions and velocities of the active joints on ``measured_joint_states``);
  the latency is from just before the measured state's ``publish`` to the arrival of its
  command (the node also serves the setpoint queued before it: that is part of it).

No timeout fires between blocks (``setpoint_timeout`` 0, ``measurement_timeout`` an hour:
a hold command would be one answer too many). Every message here is valid, the topics
reliable and ordered: the k-th command of a block
answers its k-th message when none was lost (a block that lost one counts the loss and
gives no latencies). The first ``WARM_UP`` answers of each block are left out. Lost =
sent - received after a drain of 0.3 s per block. After the run each node's own compute
time (receipt to the command ready to send, its /diagnostics) is reported too. Not a test:
it prints a table (``--json`` writes the rows).
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
WARM_UP = 50
DRAIN = 0.3


class Driver:
    """Publishers into /ff and /fb, and the arrival time of every command."""

    def __init__(self, mechanism):
        from diagnostic_msgs.msg import DiagnosticArray
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from sensor_msgs.msg import JointState
        from std_msgs.msg import Float64MultiArray

        from cog_id_ros.ros.topics import control_qos
        rclpy.init()
        self.node = rclpy.create_node('control_latency_driver')
        self.joints = list(mechanism.active_joints)
        self.pub = {ns: self.node.create_publisher(JointState, f'{ns}/joint_setpoint',
                                                   control_qos()) for ns in ('/ff', '/fb')}
        self.measured = self.node.create_publisher(JointState, '/fb/measured_joint_states',
                                                   control_qos())
        self.arrivals = {'/ff': [], '/fb': []}
        self.diagnostics = {}
        for ns in ('/ff', '/fb'):
            self.node.create_subscription(
                Float64MultiArray, f'{ns}/effort_command',
                lambda msg, ns=ns: self.arrivals[ns].append(time.perf_counter()),
                control_qos())
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self._on_diagnostics, 10)
        self.msg = JointState
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        threading.Thread(target=self.executor.spin, daemon=True).start()

    def _on_diagnostics(self, msg):
        for status in msg.status:
            ns = status.name.split('/cog_id_node')[0]
            self.diagnostics[ns] = {kv.key: kv.value for kv in status.values}

    def connected(self, timeout=60.0):
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if all(p.get_subscription_count() for p in self.pub.values()) and \
                    self.measured.get_subscription_count() and \
                    all(self.node.count_publishers(f'{ns}/effort_command') for ns in self.pub):
                return True
            time.sleep(0.05)
        return False

    def state(self, stamp_ns, q, qd):
        msg = self.msg()
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, NS)
        msg.name = self.joints
        msg.position = q
        msg.velocity = qd
        return msg

    def block(self, ns, seconds, rate, q0, amplitude):
        """Play one block into ``ns``; (send times, arrival times) of the timed messages."""
        arrivals = self.arrivals[ns]
        start = len(arrivals)
        period = 1.0 / rate
        n = int(round(seconds * rate))
        sent = np.zeros(n)
        t0 = time.perf_counter()
        stamp0 = time.time_ns()
        for k in range(n):
            due = t0 + k * period
            while (now := time.perf_counter()) < due:
                if due - now > 0.0005:
                    time.sleep(due - now - 0.0004)
            t = k * period
            w = math.pi
            q = (q0 + amplitude * math.sin(w * t)).tolist()
            qd = (amplitude * w * math.cos(w * t)).tolist()
            stamp = stamp0 + int(t * NS)
            setpoint = self.state(stamp, q, qd)
            if ns == '/ff':
                sent[k] = time.perf_counter()
                self.pub[ns].publish(setpoint)
            else:
                self.pub[ns].publish(setpoint)
                measured = self.state(stamp, q, qd)
                sent[k] = time.perf_counter()
                self.measured.publish(measured)
        time.sleep(DRAIN)
        return sent, np.array(arrivals[start:])


def start_node(params_file, ns, mode, env):
    return subprocess.Popen(
        [sys.executable, '-m', 'cog_id_ros.node', '--ros-args', '--params-file', params_file,
         '-r', f'__ns:={ns}', '-p', f'control_mode:={mode}', '-p', 'setpoint_timeout:=0.0',
         '-p', 'measurement_timeout:=3600.0', '-p', 'diagnostics_period:=0.5'],
        env=env, stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT, cwd=REPO)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--params-file', default=os.path.join(REPO, 'config', 'stewart_6ups.yaml'))
    parser.add_argument('--mode', default='computed_torque',
                        choices=('computed_torque', 'pd_feedforward', 'gravity_compensation'))
    parser.add_argument('--rate', type=float, default=1000.0)
    parser.add_argument('--duration', type=float, default=10.0)
    parser.add_argument('--block', type=float, default=1.0)
    parser.add_argument('--json')
    args = parser.parse_args(argv)
    os.environ.setdefault('ROS_DOMAIN_ID', str(150 + os.getpid() % 80))
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    import cog_id_ros
    mech = cog_id_ros.Mechanism.from_params_file(args.params_file)
    q0 = np.array([mech.assembled_positions[mech.joints.index(j)] for j in mech.active_joints])
    amplitude = np.array([0.05 if mech.joint_types[mech.joints.index(j)] == 'revolute'
                          else 0.005 for j in mech.active_joints])
    procs = {ns: start_node(args.params_file, ns, mode, dict(os.environ))
             for ns, mode in (('/ff', 'feedforward'), ('/fb', args.mode))}
    rows = []
    try:
        driver = Driver(mech)
        if not driver.connected():
            print('nodes did not connect', file=sys.stderr)
            return 1
        time.sleep(1.0)
        latencies = {'/ff': [], '/fb': []}
        lost = {'/ff': 0, '/fb': 0}
        rounds = int(round(args.duration / args.block))
        for r in range(rounds):
            for ns in (('/ff', '/fb') if r % 2 == 0 else ('/fb', '/ff')):
                sent, arrived = driver.block(ns, args.block, args.rate, q0, amplitude)
                if len(arrived) != len(sent):
                    lost[ns] += len(sent) - len(arrived)
                    continue
                latencies[ns].extend((arrived - sent)[WARM_UP:] * 1e6)
        time.sleep(1.0)
        print(f'{os.path.basename(args.params_file)} at {args.rate:g} Hz, '
              f'{args.duration:g} s per node in blocks of {args.block:g} s')
        print(f"{'node':<34} {'median us':>10} {'p99 us':>10} {'max us':>10} {'lost':>6} "
              f"{'compute median us':>18}")
        for ns, label in (('/ff', 'feedforward: setpoint -> command'),
                          ('/fb', f'{args.mode}: measured -> command')):
            lat = np.array(latencies[ns])
            compute = driver.diagnostics.get(ns, {}).get('compute_time_median_us', '')
            row = {'node': label, 'median_us': float(np.median(lat)) if lat.size else None,
                   'p99_us': float(np.percentile(lat, 99)) if lat.size else None,
                   'max_us': float(lat.max()) if lat.size else None, 'lost': lost[ns],
                   'samples': int(lat.size), 'compute_median_us': compute}
            rows.append(row)
            print(f"{label:<34} {row['median_us'] or 0:10.0f} {row['p99_us'] or 0:10.0f} "
                  f"{row['max_us'] or 0:10.0f} {lost[ns]:6d} {compute:>18}")
    finally:
        for proc in procs.values():
            proc.send_signal(2)
        for proc in procs.values():
            try:
                proc.wait(15)
            except subprocess.TimeoutExpired:
                proc.kill()
    if args.json:
        with open(args.json, 'w', encoding='utf-8') as stream:
            json.dump(rows, stream, indent=1)
    return 0


if __name__ == '__main__':
    sys.exit(main())
