"""Setpoint-to-command latency and lost messages of cog_id_node, beside an echo node.

    .venv/bin/python bench/bench_node_latency.py [--rates 1000 2000] [--duration 10]
                                                 [--params-file config/paper_four_bar_a.yaml]

Starts two subprocesses on a DDS domain of its own (localhost only):
  * ``cog_id_node`` from the params file, in namespace /cog;
  * an echo node (this file with ``--echo``), in namespace /echo, that only copies the
    setpoint's positions into a Float64MultiArray: the floor of rclpy on this machine.
Both use the node's control QoS (reliable, keep-last ``CONTROL_QOS_DEPTH``) and a
SingleThreadedExecutor. For each rate, a driver in this process plays the paper's target
motion ``pi/2 + 0.5 sin(pi t)`` into each node in turn for ``--duration`` seconds (stamps on
the nominal schedule) and takes the time from just before ``publish`` of a setpoint to the
arrival of its ``effort_command``. The echo node's command carries the setpoint's sequence
number (an extra joint, which cog_id_node ignores). cog_id_node's command carries only
torques: the k-th command that arrives answers the k-th setpoint when every setpoint was
answered (the topic is reliable and ordered, and every setpoint here is valid). A run
that lost commands reports the loss and no percentiles. The driver subscribes to nothing
else, so it is not the bottleneck at 2 kHz. Messages
lost = setpoints sent - commands received after a 1 s drain. The first 100 answers of each
run are left out of the percentiles (warm-up). After each cog_id_node run the node's own
compute time per setpoint (receipt to publication, from its /diagnostics) is reported
too, which separates the node's work from transport and executor. Not a test: it prints a table (and
``--json`` writes one).
"""
import argparse
import json
import math
import os
import subprocess
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
NS = 1_000_000_000
WARM_UP = 100


def echo_main():
    """The echo node: joint_setpoint positions -> effort_command, nothing else."""
    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray

    from cog_id_ros.node import control_qos

    rclpy.init()
    node = rclpy.create_node('echo_node')
    pub = node.create_publisher(Float64MultiArray, 'effort_command', control_qos())
    out = Float64MultiArray()

    def on_setpoint(msg):
        out.data = msg.position
        pub.publish(out)

    node.create_subscription(JointState, 'joint_setpoint', on_setpoint, control_qos())
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    print('echo node ready', flush=True)
    try:
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


class Driver:
    """Publishes setpoints on schedule and timestamps the answers, in one thread."""

    def __init__(self):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
        from diagnostic_msgs.msg import DiagnosticArray
        from sensor_msgs.msg import JointState
        from std_msgs.msg import Float64MultiArray

        from cog_id_ros.node import control_qos

        self.JointState = JointState
        self.node = rclpy.create_node('bench_driver', start_parameter_services=False)
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        reader = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10000,
                            reliability=ReliabilityPolicy.RELIABLE)
        self.pubs = {ns: self.node.create_publisher(JointState, f'{ns}/joint_setpoint',
                                                    control_qos()) for ns in ('/echo', '/cog')}
        self.node.create_subscription(Float64MultiArray, '/echo/effort_command',
                                      self._on_echo, reader)
        self.node.create_subscription(Float64MultiArray, '/cog/effort_command',
                                      self._on_cog, reader)
        self.recv = None
        self.commands = []          # arrival times of cog_id_node's effort_command
        self.diagnostics = {}       # key -> value of cog_id_node's latest DiagnosticStatus
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self._on_diagnostics, 10)
        self.start_ns = 0
        self.period_ns = 1

    def _on_echo(self, msg):
        t = time.perf_counter()
        if self.recv is not None:
            self.recv[int(msg.data[-1])] = t

    def _on_cog(self, msg):
        t = time.perf_counter()
        if self.recv is not None:
            self.commands.append(t)

    def _on_diagnostics(self, msg):
        for status in msg.status:
            if status.name.startswith('/cog/'):
                self.diagnostics = {kv.key: kv.value for kv in status.values}

    def node_compute_time(self):
        """cog_id_node's own median and max compute time per setpoint (its /diagnostics,
        over its last 1000 setpoints), from a report made after the run."""
        self.diagnostics = {}
        self.spin_for(1.2)
        get = self.diagnostics.get
        return float(get('compute_time_median_us') or 'nan'), float(get('compute_time_max_us') or 'nan')

    def spin_for(self, seconds):
        end = time.perf_counter() + seconds
        while (left := end - time.perf_counter()) > 0:
            self.executor.spin_once(timeout_sec=left)

    def wait_for(self, ns, timeout=30.0):
        end = time.perf_counter() + timeout
        while time.perf_counter() < end:
            if self.pubs[ns].get_subscription_count() > 0:
                self.spin_for(0.5)
                return
            self.spin_for(0.05)
        raise RuntimeError(f'no subscriber on {ns}/joint_setpoint')

    def run(self, ns, rate, duration):
        """Play the target motion into ``ns`` at ``rate`` Hz; returns (sent, arrivals, late, matched)."""
        n = int(rate * duration)
        self.period_ns = int(round(NS / rate))
        self.start_ns = self.node.get_clock().now().nanoseconds
        sent = np.zeros(n)
        self.recv = np.full(n, np.nan)
        self.commands = []
        late = np.zeros(n)
        msg = self.JointState()
        msg.name = ['joint3', 'joint1', 'bench_seq']
        pub = self.pubs[ns]
        t0 = time.perf_counter()
        for i in range(n):
            t = i / rate
            due = t0 + t
            while (left := due - time.perf_counter()) > 0:
                self.executor.spin_once(timeout_sec=left)
            theta = math.pi / 2 + 0.5 * math.sin(math.pi * t)
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(
                self.start_ns + i * self.period_ns, NS)
            msg.position = [theta, theta, float(i)]
            now = time.perf_counter()
            late[i] = now - due
            sent[i] = now
            pub.publish(msg)
        self.spin_for(1.0)
        recv, self.recv = self.recv, None
        if ns == '/echo':
            return sent, recv, late, True
        commands = np.array(self.commands)      # the k-th answers the k-th if none was lost
        return sent, commands, late, len(commands) == n


def summarize(sent, recv, late, matched):
    """Loss and latency percentiles of one run (no percentiles when commands were lost and
    cannot be matched to their setpoints)."""
    if matched:
        ok = ~np.isnan(recv)
        lost, lat = int((~ok).sum()), (recv - sent)[ok][WARM_UP:] * 1e6
    else:
        lost, lat = int(sent.size - len(recv)), np.array([])
    p = np.percentile(lat, [50, 90, 99]) if lat.size else [math.nan] * 3
    return {'sent': int(sent.size), 'lost': lost,
            'p50_us': float(p[0]), 'p90_us': float(p[1]), 'p99_us': float(p[2]),
            'max_us': float(lat.max()) if lat.size else math.nan,
            'driver_late_p99_us': float(np.percentile(late, 99) * 1e6)}


def start(args, env, ready):
    """Start a node; wait for the line that says it is ready."""
    proc = subprocess.Popen(args, env=env, cwd=REPO, stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    line = proc.stdout.readline()
    if ready not in line:
        proc.kill()
        raise RuntimeError(f'{args[0]} did not start: {line}{proc.stdout.read()}')
    return proc


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--echo', action='store_true', help=argparse.SUPPRESS)
    parser.add_argument('--rates', type=float, nargs='+', default=[1000.0, 2000.0])
    parser.add_argument('--duration', type=float, default=10.0, help='s per run')
    parser.add_argument('--params-file',
                        default=os.path.join(REPO, 'config', 'paper_four_bar_a.yaml'))
    parser.add_argument('--json', help='also write the results to this file')
    from rclpy.utilities import remove_ros_args
    args = parser.parse_args(remove_ros_args(sys.argv if argv is None else argv)[1:])
    if args.echo:
        return echo_main()

    env = dict(os.environ)
    env.setdefault('ROS_DOMAIN_ID', str(102 + os.getpid() % 100))
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env['PYTHONUNBUFFERED'] = '1'
    os.environ.update({k: env[k] for k in ('ROS_DOMAIN_ID', 'ROS_AUTOMATIC_DISCOVERY_RANGE')})
    bindir = os.path.dirname(sys.executable)
    procs = [
        start([sys.executable, os.path.abspath(__file__), '--echo', '--ros-args',
               '-r', '__ns:=/echo'], env, 'echo node ready'),
        start([os.path.join(bindir, 'cog_id_node'), '--ros-args', '--params-file',
               args.params_file, '-r', '__ns:=/cog', '-p', 'timeout_behavior:=none'], env,
              "mechanism '"),
    ]
    import rclpy
    rclpy.init()
    results = []
    try:
        driver = Driver()
        for ns in ('/echo', '/cog'):
            driver.wait_for(ns)
        for rate in args.rates:
            for ns, label in (('/echo', 'echo node'), ('/cog', 'cog_id_node')):
                driver.spin_for(0.5)
                row = summarize(*driver.run(ns, rate, args.duration))
                row.update(node=label, rate_hz=rate)
                if ns == '/cog':
                    row['node_compute_p50_us'], row['node_compute_max_us'] = \
                        driver.node_compute_time()
                results.append(row)
                print(f'{label:12s} {rate:6.0f} Hz: sent {row["sent"]:6d} lost {row["lost"]:5d}  '
                      f'latency p50 {row["p50_us"]:7.0f} p90 {row["p90_us"]:7.0f} '
                      f'p99 {row["p99_us"]:7.0f} max {row["max_us"]:7.0f} us  '
                      f'(driver late p99 {row["driver_late_p99_us"]:.0f} us)', flush=True)
    finally:
        rclpy.try_shutdown()
        for proc in procs:
            proc.send_signal(2)
            proc.wait(timeout=15)
    print()
    print('| rate | node | sent | lost | p50 us | p90 us | p99 us | max us |')
    print('|---|---|---|---|---|---|---|---|')
    by = {(r['rate_hz'], r['node']): r for r in results}
    for r in results:
        print(f"| {r['rate_hz']:.0f} Hz | {r['node']} | {r['sent']} | {r['lost']} | "
              f"{r['p50_us']:.0f} | {r['p90_us']:.0f} | {r['p99_us']:.0f} | {r['max_us']:.0f} |")
    for rate in args.rates:
        echo, cog = by[(rate, 'echo node')], by[(rate, 'cog_id_node')]
        print(f'{rate:.0f} Hz: cog_id_node median latency {cog["p50_us"] - echo["p50_us"]:+.0f} us '
              f'over the echo node (target <= +100 us); lost {cog["lost"]} (target 0); '
              f'its own compute time per setpoint (diagnostics, last 1000): median '
              f'{cog["node_compute_p50_us"]:.0f} us, max {cog["node_compute_max_us"]:.0f} us')
    if args.json:
        with open(args.json, 'w', encoding='utf-8') as f:
            json.dump(results, f, indent=1)
    return 0


if __name__ == '__main__':
    sys.exit(main())
