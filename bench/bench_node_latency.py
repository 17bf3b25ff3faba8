"""Setpoint-to-command latency and lost messages of cog_id_node, beside an echo node.

    .venv/bin/python bench/bench_node_latency.py [--rates 1000 2000] [--duration 10]
        [--block 1] [--lean-echo] [--params-file config/paper_four_bar_a.yaml] [--json F]
        [--compare DIR]

Starts subprocesses on a DDS domain of its own (localhost only):
  * ``cog_id_node`` from the params file, in namespace /cog;
  * an echo node (this file with ``--echo``), in namespace /echo, that only copies the
    setpoint's positions into a Float64MultiArray from a plain rclpy callback on a
    SingleThreadedExecutor: the floor of an ordinary rclpy node on this machine, and the
    reference of the latency target;
  * with ``--lean-echo``, the same echo served by the node's own dedicated setpoint loop
    (cog_id_ros/setpoint_loop.py), in /lean: the floor of that loop, so the node's own
    work shows as the difference to it;
  * with ``--compare DIR``, cog_id_node from the package in DIR (a checkout of another
    commit, e.g. ``git worktree add /tmp/before <commit>``), in /before: before and after
    a change in the same rounds.
Every node uses the node's control QoS (reliable, keep-last ``CONTROL_QOS_DEPTH``).

For each rate, a driver in this process (publishing from its main thread, receiving on
threads of its own: it adds no executor of its own to what is measured) plays the paper's target motion
``pi/2 + 0.5 sin(pi t)`` into the nodes in interleaved blocks of ``--block`` seconds (echo,
cog, [lean], then the next round in the opposite order), ``--duration`` seconds per node
in all, and takes the time from just before ``publish`` of a setpoint to the arrival of
its ``effort_command``. This VM's speed drifts from one minute to the next; blocks a
second apart see the same machine, so the difference of the medians is measured within
each round and its median over the rounds is reported beside the pooled percentiles.

The echo nodes' commands carry the setpoint's sequence number (an extra joint, which
cog_id_node ignores). cog_id_node's command carries only torques: the k-th command of a
block answers its k-th setpoint when every setpoint was answered (reliable and ordered;
every setpoint here is valid). A block that lost commands counts the loss and gives no
latencies. Messages lost = setpoints sent - commands received after a drain of 0.3 s per
block. The first ``WARM_UP`` answers of each block are left out of the percentiles (a
block starts a new stream: the node's estimator restarts). After each rate, the own
compute time per setpoint of each cog_id_node (the ``--compare`` one too; receipt to the
command ready to send, from its /diagnostics) and the time of the command's publish after
it are reported too, which separates the node's work from transport and executor. Not a test: it prints a table (and ``--json`` writes the rows).
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
WARM_UP = 50
ECHOES = ('/echo', '/lean')   # namespaces of the echo nodes (their answers carry a sequence number)
DRAIN = 0.3


def echo_main(mode, qos='control'):
    """An echo node: joint_setpoint positions -> effort_command, nothing else.

    ``mode`` 'executor': a subscription callback on a SingleThreadedExecutor (plain rclpy);
    'loop': the node's dedicated setpoint loop around the same copy. ``qos``: its input's,
    'control' (reliable, topics.control_qos) or 'stream' (best effort, topics.stream_qos:
    the node's control-rate inputs); the output is reliable, as the node's.
    """
    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray

    from cog_id_ros.ros.topics import control_qos, stream_qos

    rclpy.init()
    node = rclpy.create_node('echo_node')
    pub = node.create_publisher(Float64MultiArray, 'effort_command', control_qos())
    out = Float64MultiArray()
    reader = stream_qos() if qos == 'stream' else control_qos()

    def on_setpoint(msg):
        out.data = msg.position
        pub.publish(out)

    loop = None
    if mode == 'loop':
        from cog_id_ros.ros.setpoint_loop import SetpointLoop
        loop = SetpointLoop(node, JointState, 'joint_setpoint', on_setpoint, reader)
        loop.start()
    else:
        node.create_subscription(JointState, 'joint_setpoint', on_setpoint, reader)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    print('echo node ready', flush=True)
    try:
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if loop is not None:
            loop.stop()
        node.destroy_node()
        rclpy.try_shutdown()


def reader_qos():
    """The driver's subscriptions to the commands: reliable, deep enough for a whole block."""
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10000,
                      reliability=ReliabilityPolicy.RELIABLE)


class Driver:
    """Publishes setpoints on schedule (main thread, sleeping between them) and timestamps
    the answers (one SetpointLoop thread per command topic, and one for /diagnostics:
    bench/receivers.py; no executor, so the driver's own executor is not what is
    measured)."""

    def __init__(self, namespaces, names=('joint3', 'joint1'), positions=None):
        import rclpy
        from receivers import Diagnostics, listen
        from sensor_msgs.msg import JointState
        from std_msgs.msg import Float64MultiArray

        from cog_id_ros.ros.topics import control_qos

        self.JointState = JointState
        self.names = list(names)
        self.positions = positions or (lambda t: [math.pi / 2 + 0.5 * math.sin(math.pi * t)] * 2)
        self.node = rclpy.create_node('bench_driver', start_parameter_services=False)
        self.pubs = {ns: self.node.create_publisher(JointState, f'{ns}/joint_setpoint',
                                                    control_qos()) for ns in namespaces}
        self.recv = None            # arrival times by sequence number (echo nodes)
        self.commands = []          # arrival times in order (cog_id_node)
        self.reports = Diagnostics(self.node)
        self.loops = [listen(self.node, Float64MultiArray, f'{ns}/effort_command',
                             self._on_command, reader_qos()) for ns in namespaces]

    def close(self):
        for loop in self.loops:
            loop.stop()
        self.reports.close()

    def _on_command(self, msg):
        t = time.perf_counter()
        if self.recv is not None:
            data = msg.data
            if len(data) == len(self.names) + 1:   # an echo: the sequence number rides along
                self.recv[int(data[-1])] = t
            else:                    # cog_id_node: torques only, matched by order
                self.commands.append(t)

    def node_compute_times(self, namespaces):
        """{namespace: (median, max, publish median)}: each cog_id_node's own compute time
        per setpoint, receipt to command ready to send, and the time of the command's publish
        after it (its /diagnostics, over its last 1000 setpoints), from reports made after
        the run."""
        reports = self.reports.wait(namespaces, time.perf_counter(), 3.0)
        out = {}
        for ns in namespaces:
            get = reports[ns].get
            out[ns] = (float(get('compute_time_median_us') or 'nan'),
                       float(get('compute_time_max_us') or 'nan'),
                       float(get('publish_time_median_us') or 'nan'))
        return out

    def wait_for(self, ns, timeout=30.0):
        end = time.perf_counter() + timeout
        while time.perf_counter() < end:
            if self.pubs[ns].get_subscription_count() > 0:
                time.sleep(0.5)
                return
            time.sleep(0.05)
        raise RuntimeError(f'no subscriber on {ns}/joint_setpoint')

    def block(self, ns, rate, duration):
        """Play the target motion into ``ns`` for ``duration`` s at ``rate`` Hz (a new
        stream); returns (latencies in us after the warm-up, or None when commands were
        lost, number sent, number lost)."""
        n = int(round(rate * duration))
        period_ns = int(round(NS / rate))
        start_ns = self.node.get_clock().now().nanoseconds
        sent = np.zeros(n)
        self.commands = []
        self.recv = np.full(n, np.nan)
        msg = self.JointState()
        msg.name = self.names + ['bench_seq']
        pub = self.pubs[ns]
        t0 = time.perf_counter()
        for i in range(n):
            t = i / rate
            left = t0 + t - time.perf_counter()
            if left > 0:
                time.sleep(left)
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(start_ns + i * period_ns, NS)
            msg.position = self.positions(t) + [float(i)]
            sent[i] = time.perf_counter()
            pub.publish(msg)
        time.sleep(DRAIN)
        recv, self.recv = self.recv, None
        commands = np.array(self.commands)
        if ns in ECHOES:
            ok = ~np.isnan(recv)
            return (recv - sent)[ok][WARM_UP:] * 1e6, n, int(n - ok.sum())
        if commands.size != n:    # the k-th answers the k-th only when none was lost
            return None, n, int(n - commands.size)
        return (commands - sent)[WARM_UP:] * 1e6, n, 0


def motion_of(params_file):
    """(active joint names, positions(t)) to play: the paper's target motion for the paper
    four-bar, else the file's test motion (test/trajectories.py) swept back and forth."""
    name = os.path.basename(params_file)
    if name.startswith('paper_four_bar'):
        return ('joint3', 'joint1'), None
    sys.path.insert(0, os.path.join(REPO, 'test'))
    from trajectories import T_END, TRAJECTORIES

    import cog_id_ros
    mech = cog_id_ros.Mechanism.from_params_file(params_file)
    law = TRAJECTORIES[name]

    def positions(t):
        s = 0.5 * T_END * (1.0 - math.cos(math.pi * t / T_END))   # there and back, smoothly
        return [float(x) for x in law(np.array([s]))[0][0]]
    return tuple(mech.active_joints), positions


def percentiles(lat):
    p = np.percentile(lat, [50, 90, 99]) if lat.size else [math.nan] * 3
    return {'p50_us': float(p[0]), 'p90_us': float(p[1]), 'p99_us': float(p[2]),
            'max_us': float(lat.max()) if lat.size else math.nan}


def start(args, env, ready):
    """Start a node; wait for the line that says it is ready. What it prints after that
    is read by a thread (a pipe nobody reads fills up and stops the node) and kept in
    ``proc.lines``."""
    import threading
    proc = subprocess.Popen(args, env=env, cwd=REPO, stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    line = proc.stdout.readline()
    if ready not in line:
        proc.kill()
        raise RuntimeError(f'{args[0]} did not start: {line}{proc.stdout.read()}')
    proc.lines = []
    threading.Thread(target=lambda: proc.lines.extend(proc.stdout), daemon=True).start()
    return proc


def measure(driver, peers, rate, duration, block):
    """Interleaved blocks at one rate: {label: row}, and per-round median differences."""
    rounds = max(1, int(round(duration / block)))
    lat = {label: [] for _, label in peers}
    sent = {label: 0 for _, label in peers}
    lost = {label: 0 for _, label in peers}
    medians = []                          # per round: {label: block median}
    for r in range(rounds):
        order = peers if r % 2 == 0 else peers[::-1]
        medians.append({})
        for ns, label in order:
            time.sleep(0.2)
            values, n, n_lost = driver.block(ns, rate, duration / rounds)
            sent[label] += n
            lost[label] += n_lost
            if values is not None and values.size:
                lat[label].append(values)
                medians[-1][label] = float(np.median(values))
    rows = {}
    for _, label in peers:
        values = np.concatenate(lat[label]) if lat[label] else np.array([])
        rows[label] = dict(node=label, rate_hz=rate, sent=sent[label], lost=lost[label],
                           blocks=rounds, **percentiles(values))
    return rows, medians


def round_differences(medians, label, reference):
    """Per-round difference of the block medians, label minus reference (us)."""
    return [m[label] - m[reference] for m in medians if label in m and reference in m]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--echo', choices=('executor', 'loop'), help=argparse.SUPPRESS)
    parser.add_argument('--echo-qos', choices=('control', 'stream'), default='control',
                        help=argparse.SUPPRESS)
    parser.add_argument('--rates', type=float, nargs='+', default=[1000.0, 2000.0])
    parser.add_argument('--duration', type=float, default=10.0, help='s per node and rate')
    parser.add_argument('--block', type=float, default=1.0,
                        help='s per block; the nodes take turns block by block')
    parser.add_argument('--lean-echo', action='store_true',
                        help="also run the echo on the node's dedicated setpoint loop")
    parser.add_argument('--compare', metavar='DIR',
                        help='also run cog_id_node from the cog_id_ros package in DIR (a '
                             'checkout of another commit), as one more node in the same rounds')
    parser.add_argument('--params-file',
                        default=os.path.join(REPO, 'config', 'paper_four_bar_a.yaml'))
    parser.add_argument('--json', help='also write the results to this file')
    from rclpy.utilities import remove_ros_args
    args = parser.parse_args(remove_ros_args(sys.argv if argv is None else argv)[1:])
    if args.echo:
        return echo_main(args.echo, args.echo_qos)

    env = dict(os.environ)
    env.setdefault('ROS_DOMAIN_ID', str(102 + os.getpid() % 100))
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env['PYTHONUNBUFFERED'] = '1'
    os.environ.update({k: env[k] for k in ('ROS_DOMAIN_ID', 'ROS_AUTOMATIC_DISCOVERY_RANGE')})
    bindir = os.path.dirname(sys.executable)
    me = os.path.abspath(__file__)
    node_args = ['--ros-args', '--params-file', args.params_file, '-p', 'timeout_behavior:=none']
    peers = [('/echo', 'echo node'), ('/cog', 'cog_id_node')]
    procs = [
        start([sys.executable, me, '--echo', 'executor', '--ros-args', '-r', '__ns:=/echo'],
              env, 'echo node ready'),
        start([os.path.join(bindir, 'cog_id_node'), *node_args, '-r', '__ns:=/cog'], env,
              "mechanism '"),
    ]
    if args.compare:
        root = os.path.abspath(args.compare)
        peers.append(('/before', f'cog_id_node of {os.path.basename(root)}'))
        procs.append(start([sys.executable, '-m', 'cog_id_ros.node', *node_args,
                            '-r', '__ns:=/before'], dict(env, PYTHONPATH=root), "mechanism '"))
    if args.lean_echo:
        peers.append(('/lean', 'echo on setpoint loop'))
        procs.append(start([sys.executable, me, '--echo', 'loop', '--ros-args',
                            '-r', '__ns:=/lean'], env, 'echo node ready'))
    import rclpy
    rclpy.init()
    results, summary = [], []
    driver = None
    try:
        driver = Driver([ns for ns, _ in peers], *motion_of(args.params_file))
        for ns, _ in peers:
            driver.wait_for(ns)
        for rate in args.rates:
            rows, medians = measure(driver, peers, rate, args.duration, args.block)
            nodes = [(ns, label) for ns, label in peers if ns not in ECHOES]
            times = driver.node_compute_times([ns for ns, _ in nodes])
            for ns, label in nodes:
                (rows[label]['node_compute_p50_us'], rows[label]['node_compute_max_us'],
                 rows[label]['node_publish_p50_us']) = times[ns]
            for row in rows.values():
                results.append(row)
                print(f'{row["node"]:22s} {rate:6.0f} Hz: sent {row["sent"]:6d} lost '
                      f'{row["lost"]:5d}  latency p50 {row["p50_us"]:7.0f} p90 '
                      f'{row["p90_us"]:7.0f} p99 {row["p99_us"]:7.0f} max {row["max_us"]:7.0f} us',
                      flush=True)
            for label in rows:
                if label == 'echo node':
                    continue
                diffs = round_differences(medians, label, 'echo node')
                summary.append(dict(rate_hz=rate, node=label, rounds=len(diffs),
                                    median_diff_us=float(np.median(diffs)) if diffs else math.nan,
                                    min_diff_us=min(diffs, default=math.nan),
                                    max_diff_us=max(diffs, default=math.nan),
                                    pooled_diff_us=rows[label]['p50_us'] - rows['echo node']['p50_us'],
                                    lost=rows[label]['lost']))
    finally:
        if driver is not None:
            driver.close()
        rclpy.try_shutdown()
        for proc in procs:
            proc.send_signal(2)
            proc.wait(timeout=15)
    print()
    print('| rate | node | sent | lost | p50 us | p90 us | p99 us | max us |')
    print('|---|---|---|---|---|---|---|---|')
    for r in results:
        print(f"| {r['rate_hz']:.0f} Hz | {r['node']} | {r['sent']} | {r['lost']} | "
              f"{r['p50_us']:.0f} | {r['p90_us']:.0f} | {r['p99_us']:.0f} | {r['max_us']:.0f} |")
    print()
    print('median latency over the echo node, within each round of blocks (target <= +100 us):')
    for s in summary:
        print(f"  {s['rate_hz']:.0f} Hz {s['node']}: median {s['median_diff_us']:+.0f} us over "
              f"{s['rounds']} rounds (range {s['min_diff_us']:+.0f} .. {s['max_diff_us']:+.0f}); "
              f"pooled medians {s['pooled_diff_us']:+.0f} us; lost {s['lost']} (target 0)")
    for r in results:
        if 'node_compute_p50_us' in r:
            print(f"  {r['rate_hz']:.0f} Hz {r['node']}'s own compute time per setpoint, "
                  f"receipt to command ready to send (diagnostics, last 1000): median "
                  f"{r['node_compute_p50_us']:.0f} us, max {r['node_compute_max_us']:.0f} us; "
                  f"then the command's publish: median {r['node_publish_p50_us']:.0f} us")
    if args.json:
        with open(args.json, 'w', encoding='utf-8') as f:
            json.dump({'rows': results, 'differences': summary}, f, indent=1)
    return 0


if __name__ == '__main__':
    sys.exit(main())
