"""Does a long trajectory hold up the setpoint stream? Setpoints lost and the worst gap.

    .venv/bin/python bench/bench_trajectory_stall.py [--points 100000] [--rate 1000]
        [--before 2] [--after 1] [--params-file config/paper_four_bar_a.yaml] [--node-cwd DIR]

Starts ``python -m cog_id_ros.node`` (from ``--node-cwd``, default this checkout: pass a
``git worktree`` of another commit to measure it) on a DDS domain of its own (localhost
only), streams the paper's target motion into ``joint_setpoint`` at ``--rate`` Hz from a
thread of this process, and ``--before`` seconds into the stream publishes one
``--points``-point JointTrajectory (serialized beforehand, published as bytes, so building
it does not stall this process's own stream). The stream goes on until the
``effort_trajectory`` arrives (taken as bytes, never deserialised here) and ``--after``
seconds more. Reported:

* setpoints sent, commands received, lost (sent - received);
* the worst gap between consecutive ``effort_command`` arrivals while the trajectory was
  being solved (from its publication to the arrival of its answer) and over the whole
  run, beside the worst gap between this process's own publications (a gap there is
  this process's, not the node's);
* the time from publishing the trajectory to its answer, and the node's
  ``setpoints_lost`` and ``trajectories_rejected`` from /diagnostics.

Not a test: it prints a table. Exit status 0.
"""
import argparse
import os
import subprocess
import sys
import threading
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
NS = 1_000_000_000


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--points', type=int, default=100_000)
    parser.add_argument('--rate', type=float, default=1000.0)
    parser.add_argument('--before', type=float, default=2.0)
    parser.add_argument('--after', type=float, default=1.0)
    parser.add_argument('--params-file', default=os.path.join(REPO, 'config',
                                                              'paper_four_bar_a.yaml'))
    parser.add_argument('--node-cwd', default=REPO)
    parser.add_argument('--timeout', type=float, default=120.0)
    parser.add_argument('--no-answer', action='store_true',
                        help='do not subscribe to effort_trajectory (the answer is seen in '
                             '/diagnostics): separates the transport of the 7 MB answer from '
                             'the node')
    args = parser.parse_args(argv)

    os.environ.setdefault('ROS_DOMAIN_ID', str(150 + os.getpid() % 70))
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    from builtin_interfaces.msg import Duration
    from diagnostic_msgs.msg import DiagnosticArray
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                     reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
    node_args = [sys.executable, '-m', 'cog_id_ros.node', '--ros-args', '--params-file',
                 os.path.abspath(args.params_file), '-r', '__ns:=/stall', '-p',
                 'diagnostics_period:=0.1', '-p',
                 'setpoint_timeout:=0.0', '-p', f'max_trajectory_points:={max(args.points, 1)}']
    node = subprocess.Popen(node_args, cwd=args.node_cwd, stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    node_output = []
    threading.Thread(target=lambda: node_output.extend(node.stdout), daemon=True).start()

    # the trajectory, serialized before the stream starts
    t = np.arange(args.points) * 1e-3
    th = (np.pi / 2 + 0.5 * np.sin(np.pi * t)).tolist()
    traj = JointTrajectory(joint_names=['joint3'])
    traj.points = [JointTrajectoryPoint(positions=[a], velocities=[0.0], accelerations=[0.0],
                                        time_from_start=Duration(sec=int(x),
                                                                 nanosec=int(x % 1 * 1e9)))
                   for a, x in zip(th, t.tolist())]
    raw = serialize_message(traj)
    del traj

    rclpy.init()
    probe = rclpy.create_node('stall_probe', namespace='/stall')
    setpoints = probe.create_publisher(JointState, 'joint_setpoint', qos)
    trajectories = probe.create_publisher(JointTrajectory, 'joint_trajectory', qos)
    arrivals, answers, diagnostics = [], [], []
    probe.create_subscription(Float64MultiArray, 'effort_command',
                              lambda m: arrivals.append(time.monotonic()), qos)
    if not args.no_answer:
        probe.create_subscription(JointTrajectory, 'effort_trajectory',
                                  lambda m: answers.append((time.monotonic(), len(m))), qos,
                                  raw=True)

    def on_diagnostics(msg):
        diagnostics.append(msg)
        for status in msg.status:
            if args.no_answer and not answers and status.name.startswith('/stall/cog_id_node') \
                    and any(v.key == 'trajectories_accepted' and v.value != '0'
                            for v in status.values):
                answers.append((time.monotonic(), 0))
    probe.create_subscription(DiagnosticArray, '/diagnostics', on_diagnostics, 10)
    executor = SingleThreadedExecutor()
    executor.add_node(probe)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    try:
        end = time.monotonic() + 60
        while time.monotonic() < end and not (
                setpoints.get_subscription_count() and trajectories.get_subscription_count()
                and probe.count_publishers('/stall/effort_command')):
            time.sleep(0.05)
        time.sleep(1.0)

        sends = []
        state = {'stop': False, 'traj_sent': None}
        period = 1.0 / args.rate

        def stream():
            msg = JointState(name=['joint3'])
            start = time.monotonic()
            k = 0
            while not state['stop']:
                due = start + k * period
                delay = due - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
                stamp = time.time_ns()
                msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp, NS)
                msg.position = [float(np.pi / 2 + 0.5 * np.sin(np.pi * k * period))]
                sends.append(time.monotonic())
                setpoints.publish(msg)
                k += 1

        streamer = threading.Thread(target=stream, daemon=True)
        streamer.start()
        time.sleep(args.before)
        state['traj_sent'] = time.monotonic()
        trajectories.publish(raw)
        end = time.monotonic() + args.timeout
        while not answers and time.monotonic() < end:
            time.sleep(0.01)
        time.sleep(args.after)
        state['stop'] = True
        streamer.join()
        time.sleep(0.5)                                   # drain
    finally:
        node.send_signal(2)
        try:
            node.wait(20)
        except subprocess.TimeoutExpired:
            node.kill()

    sent, received = len(sends), len(arrivals)
    t0 = state['traj_sent']
    t1 = answers[0][0] if answers else max(arrivals[-1], t0)
    arr = np.array(arrivals)
    gaps = np.diff(arr)
    during = [g for a, g in zip(arr[1:], gaps) if t0 <= a <= t1 + 0.05]
    send_gaps = np.diff(np.array(sends))
    kv = {}
    for msg in diagnostics:
        for status in msg.status:
            if status.name.startswith('/stall/cog_id_node'):
                kv = {v.key: v.value for v in status.values}
    print(f'node: {" ".join(node_args[1:3])} (cwd {args.node_cwd}); {args.points} points, '
          f'{args.rate:g} Hz; load average {os.getloadavg()[0]:.2f}')
    print(f'  setpoints sent {sent}, commands received {received}, lost {sent - received}')
    print(f'  trajectory answered: {"yes" if answers else "no"}'
          + (f', {answers[0][0] - t0:.2f} s after it was published '
             f'({answers[0][1] / 1e6:.1f} MB)' if answers else ''))
    print(f'  worst gap between commands while it was solved: '
          f'{1e3 * max(during, default=float("nan")):.1f} ms; whole run: '
          f'{1e3 * gaps.max():.1f} ms (p99.9 {1e3 * np.percentile(gaps, 99.9):.2f} ms)')
    worst = int(np.argmax(gaps))
    print(f"  the worst gap ended {arr[worst + 1] - t0:+.3f} s from the trajectory's "
          f'publication ({arr[worst + 1] - t1:+.3f} s from its answer)')
    print(f"  worst gap between this process's own publications: {1e3 * send_gaps.max():.1f} ms")
    print(f"  node diagnostics: setpoints_lost {kv.get('setpoints_lost', 'n/a')}, "
          f"trajectories_accepted {kv.get('trajectories_accepted', 'n/a')}, "
          f"trajectories_rejected {kv.get('trajectories_rejected', 'n/a')}")
    if node.returncode not in (0, None):
        print(f'  node exit status {node.returncode}:\n' + ''.join(node_output[-20:]))
    executor.shutdown()
    spinner.join(5)
    probe.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
