"""Latency of cog_id_node's feedback mode beside an echo node and feed-forward, at 1 kHz.

    .venv/bin/python bench/bench_control_latency.py [--params-file config/stewart_6ups.yaml]
        [--mode computed_torque] [--rate 1000] [--duration 10] [--block 1]
        [--compare DIR] [--json F]

Starts on a DDS domain of its own (localhost only), from the same params file:

* /echo: the echo node of bench_node_latency.py (JointState in, its positions copied into
  a Float64MultiArray out, from a plain rclpy callback on a SingleThreadedExecutor), its
  input best effort as the node's control-rate inputs: the floor of an ordinary rclpy
  node on this machine, and the reference of the target;
* /ff: ``cog_id_node`` in ``control_mode: feedforward``;
* /fb: ``cog_id_node`` in ``--mode``;
* with ``--compare DIR``, /ff_before and /fb_before: the same two from the cog_id_ros
  package in DIR (``git worktree add /tmp/before HEAD``): before and after a change in
  the same rounds.

A driver in this process publishes from its main thread (sleeping between messages) and
receives on threads of its own, one per topic (bench/receivers.py: no rclpy executor in
the driver, whose delays would count as the nodes'). It plays the mechanism's motion
(every active joint at its initial position plus a small sine: 0.05 rad or 5 mm, period
2 s) into the nodes in interleaved blocks of ``--block`` seconds (each round in the
opposite order of the one before), ``--duration`` seconds per node in all. Per period:

* /echo gets one state; the latency is from just before its ``publish`` to the arrival of
  its echo (matched by a sequence number riding along as an extra joint, which the nodes
  ignore);
* /ff gets one setpoint; the latency is from just before its ``publish`` to the arrival of
  its ``effort_command``;
* /fb gets the setpoint and then the measured state (the same pose and velocity on
  ``measured_joint_states``); the latency is from just before the measured state's
  ``publish`` to the arrival of its command (the setpoint queued before it is put in
  force first: that is part of it).

No timeout fires between blocks (``setpoint_timeout`` 0, ``measurement_timeout`` an hour).
Every message here is valid; a node's k-th command of a block answers the k-th timed
message when none was lost. Lost data is a failure: a block that lost a message counts it
and gives no latencies, and after the run each node's /diagnostics says where it was lost
(on the way to the node: sent - accepted - rejected, and the node's own count from the
publisher's sequence numbers; on the way back: accepted - received); the exit status is 1.
The first ``WARM_UP`` answers of each block are left out. Each node's own compute time
(receipt to the command ready to send, its /diagnostics over its last 1000 messages) is
read after each of its blocks. Not a test: it prints a table (``--json`` writes the rows).
"""
import argparse
import json
import math
import os
import sys
import time

from bench_node_latency import DRAIN, NS, WARM_UP, percentiles, reader_qos, start
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
#: p99 latency of the feedback mode over the echo node's: the target
TARGET_P99_RATIO = 2.0


def _stamper(arrivals):
    """A callback that appends each message's arrival time (perf_counter) to ``arrivals``."""
    def on_command(msg, now=time.perf_counter, append=arrivals.append):
        append(now())
    return on_command


class Driver:
    """Publishers into the nodes; the arrival times of their answers; their /diagnostics."""

    def __init__(self, mechanism, nodes):
        import rclpy
        from receivers import Diagnostics, listen
        from sensor_msgs.msg import JointState
        from std_msgs.msg import Float64MultiArray

        from cog_id_ros.ros.topics import control_qos
        self.node = rclpy.create_node('control_latency_driver', start_parameter_services=False)
        self.names = list(mechanism.active_joints) + ['bench_seq']
        self.kinds = {ns: kind for ns, kind, _ in nodes}
        publisher = self.node.create_publisher
        self.setpoints = {ns: publisher(JointState, f'{ns}/joint_setpoint', control_qos())
                          for ns, kind, _ in nodes}
        self.measured = {ns: publisher(JointState, f'{ns}/measured_joint_states', control_qos())
                         for ns, kind, _ in nodes if kind == 'fb'}
        self.arrivals = {ns: [] for ns in self.kinds}
        self.echoed = None                  # the echo's arrival times by sequence number
        self.reports = Diagnostics(self.node)
        self.loops = [listen(self.node, Float64MultiArray, f'{ns}/effort_command',
                             self._on_echo if kind == 'echo' else _stamper(self.arrivals[ns]),
                             reader_qos()) for ns, kind, _ in nodes]
        self.JointState = JointState

    def _on_echo(self, msg):
        t = time.perf_counter()
        if self.echoed is not None:
            self.echoed[int(msg.data[-1])] = t

    def close(self):
        for loop in self.loops:
            loop.stop()
        self.reports.close()

    def connected(self, timeout=60.0):
        end = time.monotonic() + timeout
        count = self.node.count_publishers
        while time.monotonic() < end:
            if all(p.get_subscription_count() for p in (*self.setpoints.values(),
                                                         *self.measured.values())) and \
                    all(count(f'{ns}/effort_command') for ns in self.kinds):
                return True
            time.sleep(0.05)
        return False

    def state(self, stamp_ns, q, qd, seq):
        msg = self.JointState()
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, NS)
        msg.name = self.names
        msg.position = q + [float(seq)]
        msg.velocity = qd + [0.0]
        return msg

    def block(self, ns, seconds, rate, q0, amplitude):
        """Play one block into ``ns``: (latencies in us after the warm-up, or None when an
        answer was lost; messages timed; answers missing; setpoints sent)."""
        kind = self.kinds[ns]
        arrivals = self.arrivals[ns]
        start = len(arrivals)
        n = int(round(seconds * rate))
        sent = np.zeros(n)
        if kind == 'echo':
            self.echoed = np.full(n, np.nan)
        t0, stamp0 = time.perf_counter(), time.time_ns()
        for k in range(n):
            t = k / rate
            left = t0 + t - time.perf_counter()
            if left > 0:
                time.sleep(left)
            q = (q0 + amplitude * math.sin(math.pi * t)).tolist()
            qd = (amplitude * math.pi * math.cos(math.pi * t)).tolist()
            msg = self.state(stamp0 + int(t * NS), q, qd, k)
            if kind == 'fb':
                self.setpoints[ns].publish(msg)
                sent[k] = time.perf_counter()
                self.measured[ns].publish(msg)
            else:
                sent[k] = time.perf_counter()
                self.setpoints[ns].publish(msg)
        time.sleep(DRAIN)
        if kind == 'echo':
            echoed, self.echoed = self.echoed, None
            ok = ~np.isnan(echoed)
            return (echoed - sent)[ok][WARM_UP:] * 1e6, n, int(n - ok.sum()), 0
        answers = np.array(arrivals[start:])
        setpoints = n           # ff and fb: one setpoint per period
        if answers.size != n:
            return None, n, n - answers.size, setpoints
        return (answers - sent)[WARM_UP:] * 1e6, n, 0, setpoints


def node_arguments(params_file, mode):
    return ['--ros-args', '--params-file', params_file, '-p', f'control_mode:={mode}',
            '-p', 'setpoint_timeout:=0.0', '-p', 'measurement_timeout:=3600.0']


def start_nodes(args, env):
    """[(namespace, kind, label)] and the processes: echo, ff, fb (and the --compare pair)."""
    me = os.path.join(HERE, 'bench_node_latency.py')
    nodes = [('/echo', 'echo', 'echo node: state -> echo'),
             ('/ff', 'ff', 'feedforward: setpoint -> command'),
             ('/fb', 'fb', f'{args.mode}: measured -> command')]
    procs = [start([sys.executable, me, '--echo', 'executor', '--echo-qos', 'stream',
                    '--ros-args', '-r', '__ns:=/echo'], env, 'echo node ready')]
    for ns, mode in (('/ff', 'feedforward'), ('/fb', args.mode)):
        procs.append(start([sys.executable, '-m', 'cog_id_ros.node',
                            *node_arguments(args.params_file, mode), '-r', f'__ns:={ns}'],
                           env, "mechanism '"))
    if args.compare:
        root = os.path.abspath(args.compare)
        tag = os.path.basename(root)
        for ns, kind, mode, what in (('/ff_before', 'ff', 'feedforward', 'setpoint'),
                                     ('/fb_before', 'fb', args.mode, 'measured')):
            nodes.append((ns, kind, f'{mode} of {tag}: {what} -> command'))
            procs.append(start([sys.executable, '-m', 'cog_id_ros.node',
                                *node_arguments(args.params_file, mode), '-r', f'__ns:={ns}'],
                               dict(env, PYTHONPATH=root), "mechanism '"))
    return nodes, procs


def motion(params_file):
    """(mechanism, initial positions of the active joints, amplitudes)."""
    import cog_id_ros
    mech = cog_id_ros.Mechanism.from_params_file(params_file)
    q0 = np.array([mech.assembled_positions[mech.joints.index(j)] for j in mech.active_joints])
    amplitude = np.array([0.05 if mech.joint_types[mech.joints.index(j)] == 'revolute'
                          else 0.005 for j in mech.active_joints])
    return mech, q0, amplitude


def run(args, driver, nodes):
    """The interleaved rounds: {ns: row}."""
    rows = {ns: dict(node=label, sent=0, setpoints=0, lost=0, latencies=[], compute=[],
                     rounds={}) for ns, _, label in nodes}
    _, q0, amplitude = motion(args.params_file)
    rounds = max(1, int(round(args.duration / args.block)))
    ended = {}
    for r in range(rounds):
        for ns, kind, _ in (nodes if r % 2 == 0 else nodes[::-1]):
            if kind != 'echo' and ns in ended:      # the node's report on its last block
                rows[ns]['compute'].append(driver.reports.first_after(ns, ended[ns]))
            time.sleep(0.2)
            values, n, missing, setpoints = driver.block(ns, args.block, args.rate, q0,
                                                         amplitude)
            ended[ns] = time.perf_counter()
            row = rows[ns]
            row['sent'] += n
            row['setpoints'] += setpoints
            row['lost'] += missing
            if values is not None:
                row['latencies'].append(values)
                row['rounds'][r] = values
    last = driver.reports.wait([ns for ns, kind, _ in nodes if kind != 'echo'],
                               max(ended.values()), 5.0)
    for ns, report in last.items():
        rows[ns]['compute'].append(report)
        rows[ns]['final'] = report
    return rows


def summarise(rows):
    """Percentiles, compute times and where anything was lost, per row (in place); the
    ratio of each block's p99 to the echo's block of the same round, its median over the
    rounds (a load that comes and goes hits blocks, not nodes: within a round the nodes
    saw about the same machine)."""
    echo = rows['/echo'].get('rounds', {})
    for ns, row in rows.items():
        lat = np.concatenate(row.pop('latencies')) if row['latencies'] else np.array([])
        row.update(percentiles(lat), samples=int(lat.size))
        rounds = row.pop('rounds')
        ratios = [np.percentile(v, 99) / np.percentile(echo[r], 99)
                  for r, v in rounds.items() if r in echo and v.size and echo[r].size]
        row['round_p99_ratio'] = float(np.median(ratios)) if ratios else math.nan
        reports = [r for r in row.pop('compute') if r]
        medians = [float(r['compute_time_median_us']) for r in reports
                   if r.get('compute_time_median_us')]
        maxima = [float(r['compute_time_max_us']) for r in reports
                  if r.get('compute_time_max_us')]
        row['compute_p50_us'] = float(np.median(medians)) if medians else math.nan
        row['compute_max_us'] = max(maxima, default=math.nan)
        final = row.pop('final', None)
        if final is not None:
            row['where_lost'] = where_lost(row, final)


def where_lost(row, final):
    """What the node's counters say of the messages the driver sent it."""
    def get(key):
        try:
            return int(final.get(key) or 0)
        except ValueError:
            return 0
    out = {}
    if 'measurements_accepted' in final:
        accepted, rejected = get('measurements_accepted'), get('measurements_rejected')
        out['measured_to_node'] = row['sent'] - accepted - rejected
        out['measured_lost_counted_by_node'] = get('measurements_lost')
        out['commands_back'] = accepted - (row['sent'] - row['lost'])
        out['rejected'] = rejected
        setpoints_in = row['setpoints']
    else:
        out['commands_back'] = get('setpoints_accepted') - (row['sent'] - row['lost'])
        setpoints_in = row['sent']
    out['setpoints_to_node'] = setpoints_in - get('setpoints_accepted') - \
        get('setpoints_rejected')
    out['setpoints_lost_counted_by_node'] = get('setpoints_lost')
    return out


def print_table(args, rows):
    print(f'{os.path.basename(args.params_file)} at {args.rate:g} Hz, {args.duration:g} s per '
          f'node in blocks of {args.block:g} s; load average {os.getloadavg()[0]:.2f} '
          f'(1 min) at the end')
    print('| node | sent | lost | p50 us | p90 us | p99 us | max us | compute p50 us | '
          'compute max us |')
    print('|---|---|---|---|---|---|---|---|---|')
    for row in rows.values():
        print(f"| {row['node']} | {row['sent']} | {row['lost']} | {row['p50_us']:.0f} | "
              f"{row['p90_us']:.0f} | {row['p99_us']:.0f} | {row['max_us']:.0f} | "
              f"{row['compute_p50_us']:.0f} | {row['compute_max_us']:.0f} |")
    echo = rows['/echo']
    for ns, row in rows.items():
        if ns != '/echo':
            ratio = row['p99_us'] / echo['p99_us'] if echo['p99_us'] else math.nan
            print(f"  {row['node']}: p99 {ratio:.2f}x the echo's (target <= "
                  f"{TARGET_P99_RATIO:g}x), {row['round_p99_ratio']:.2f}x by the median "
                  f"over the rounds of the ratio within each; median "
                  f"{row['p50_us'] - echo['p50_us']:+.0f} us over the echo's")


def lost_lines(rows):
    """A line per node that lost a message, saying where."""
    out = []
    for row in rows.values():
        where = {k: v for k, v in row.get('where_lost', {}).items() if v}
        if row['lost'] or where:
            out.append(f"LOST: {row['node']}: {row['lost']} answer(s) missing of "
                       f"{row['sent']}; " + (', '.join(f'{k} {v}' for k, v in where.items())
                                            or 'the echo node does not count its own'))
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--params-file', default=os.path.join(REPO, 'config', 'stewart_6ups.yaml'))
    parser.add_argument('--mode', default='computed_torque',
                        choices=('computed_torque', 'pd_feedforward', 'gravity_compensation'))
    parser.add_argument('--rate', type=float, default=1000.0)
    parser.add_argument('--duration', type=float, default=10.0, help='s per node')
    parser.add_argument('--block', type=float, default=1.0)
    parser.add_argument('--compare', metavar='DIR',
                        help='also run both nodes from the cog_id_ros package in DIR')
    parser.add_argument('--json')
    args = parser.parse_args(argv)
    env = dict(os.environ)
    env.setdefault('ROS_DOMAIN_ID', str(150 + os.getpid() % 80))
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env['PYTHONUNBUFFERED'] = '1'
    os.environ.update({k: env[k] for k in ('ROS_DOMAIN_ID', 'ROS_AUTOMATIC_DISCOVERY_RANGE')})
    import rclpy
    mech = motion(args.params_file)[0]
    nodes, procs = start_nodes(args, env)
    rclpy.init()
    driver = None
    try:
        driver = Driver(mech, nodes)
        if not driver.connected():
            print('nodes did not connect', file=sys.stderr)
            return 1
        time.sleep(1.0)
        load = os.getloadavg()[0]
        rows = run(args, driver, nodes)
    finally:
        if driver is not None:
            driver.close()
        rclpy.try_shutdown()
        for proc in procs:
            proc.send_signal(2)
        for proc in procs:
            proc.wait(15)
    summarise(rows)
    print(f'load average {load:.2f} (1 min) at the start')
    print_table(args, rows)
    for (_, _, label), proc in zip(nodes, procs):    # a node that logs in the run says why
        logged = [line.rstrip() for line in proc.lines if 'WARN' in line or 'ERROR' in line]
        if logged:
            print(f'  {label} logged {len(logged)} warning(s) or error(s), the first: '
                  f'{logged[0]}')
    lost = lost_lines(rows)
    print('\n'.join(lost))
    if args.json:
        with open(args.json, 'w', encoding='utf-8') as stream:
            json.dump(list(rows.values()), stream, indent=1)
    return 1 if lost else 0


if __name__ == '__main__':
    sys.exit(main())
