"""A node stopped for a while (SIGSTOP, SIGCONT) while its input streams: how soon after
it runs again the fresh messages are answered, and whether every message was answered,
rejected or counted lost.

    .venv/bin/python bench/bench_stall.py [--repeats 5] [--stall 3] [--rate 200]
        [--cases setpoints measured efforts] [--reliable] [--json F]

Per case, ``--repeats`` runs, each with a node of its own (DDS domain of its own,
localhost only) on config/paper_four_bar_a.yaml:

* ``setpoints``: cog_id_node (feed-forward), setpoints at ``--rate`` Hz; the answer to a
  setpoint is its ``joint_effort`` (same stamp);
* ``measured``: cog_id_node in ``gravity_compensation``, measured states at ``--rate``;
  the answer is the ``joint_effort`` with the measured state's stamp;
* ``efforts``: cog_sim_node (no gravity), efforts at ``--rate``, each a value of its own;
  the answer is the first ``joint_states`` whose effort is that value.

The stream starts once the node answered one message (what was sent before cannot be
told from what was sent before the node matched: not counted); 1 s later the node is stopped for
``--stall`` s, and the stream goes on for 2 s after SIGCONT. Reported per case: the time
from SIGCONT to the first answer of a message sent after it (median and max over the
runs), the share of the messages sent from 0.2 s after SIGCONT on that were answered,
and the messages sent that the node's /diagnostics neither accepted, rejected nor
counted lost (must be 0: otherwise exit status 1, naming the run). ``--reliable`` gives
the node's subscription reliable QoS, as it was before (for the comparison).
"""
import argparse
import json
import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np

from cog_id_ros.demos.closed_loop import stop

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
CONFIG = os.path.join(REPO, 'config', 'paper_four_bar_a.yaml')
NS = 1_000_000_000
CASES = {
    # case: (program, extra parameters, input topic, /diagnostics counts prefix)
    'setpoints': ('cog_id_node', ['-p', 'joint_states_decimation:=0'], 'joint_setpoint',
                  'setpoints'),
    'measured': ('cog_id_node', ['-p', 'control_mode:=gravity_compensation'],
                 'measured_joint_states', 'measurements'),
    'efforts': ('cog_sim_node', ['-p', 'mechanism.gravity:=[0.0, 0.0, 0.0]',
                                 '-p', 'joint_states_period:=0.0'],   # every step's effort
                'effort_command', 'efforts'),
}


class Probe:
    """Publishes into one namespace and records the answers (arrival time by key)."""

    def __init__(self, namespace, case):
        from diagnostic_msgs.msg import DiagnosticArray
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import QoSProfile
        from sensor_msgs.msg import JointState
        from std_msgs.msg import Float64MultiArray
        self.case, self.namespace = case, namespace
        self.node = rclpy.create_node('stall_probe', namespace=namespace)
        qos = QoSProfile(depth=100)
        topic = CASES[case][2]
        self.msg_type = Float64MultiArray if case == 'efforts' else JointState
        self.publisher = self.node.create_publisher(self.msg_type, topic, qos)
        self.answers, self.status = {}, {}
        if case == 'efforts':           # 1000 states a second: a deep queue, none lost here
            self.node.create_subscription(JointState, 'joint_states', self._on_state,
                                          QoSProfile(depth=10000))
        else:
            self.node.create_subscription(JointState, 'joint_effort', self._on_answer, qos)
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self._on_status, 10)
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        threading.Thread(target=self.executor.spin, daemon=True).start()

    def _on_answer(self, msg):
        self.answers.setdefault(msg.header.stamp.sec * NS + msg.header.stamp.nanosec,
                                time.monotonic())

    def _on_state(self, msg):
        self.answers.setdefault(max(msg.effort, key=abs) if msg.effort else 0.0,
                                time.monotonic())

    def _on_status(self, msg):
        for status in msg.status:
            if status.name.startswith(self.namespace + '/'):
                self.status = dict({kv.key: kv.value for kv in status.values},
                                   _time=time.monotonic())

    def message(self, k):
        """The k-th message and its key (the stamp, or the effort's value)."""
        msg = self.msg_type()
        if self.case == 'efforts':
            value = (-1) ** k * (1e-3 + k * 1e-6)       # tiny, alternating, each its own
            msg.data = [value]
            return msg, value
        stamp = time.time_ns()
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp, NS)
        msg.name, msg.position = ['joint3'], [1.5707963267948966 + 1e-3 * np.sin(k / 50)]
        msg.velocity = [0.0]
        return msg, stamp

    def counted(self, timeout=10.0):
        """accepted + rejected + lost, from a /diagnostics report newer than now."""
        now = time.monotonic()
        end = now + timeout
        while self.status.get('_time', 0) <= now and time.monotonic() < end:
            time.sleep(0.05)
        prefix = CASES[self.case][3]
        return sum(int(self.status.get(f'{prefix}_{what}', 0))
                   for what in ('accepted', 'rejected', 'lost'))

    def close(self):
        self.executor.shutdown()
        self.node.destroy_node()


def run_once(case, stall, rate, reliable, k_run):
    program, params, topic, _ = CASES[case]
    namespace = f'/stall_{case}_{k_run}'
    extra = ['-p', f'qos_overrides.{namespace}/{topic}.subscription.reliability:=reliable'] \
        if reliable else []
    proc = subprocess.Popen(
        [os.path.join(os.path.dirname(sys.executable), program), '--ros-args',
         '--params-file', CONFIG, '-r', f'__ns:={namespace}', '-p', 'diagnostics_period:=0.2',
         *params, *extra], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    probe = Probe(namespace, case)
    sent = []
    try:
        k = 0
        end = time.monotonic() + 60
        while not probe.answers:               # connected: one message answered
            if time.monotonic() > end or proc.poll() is not None:
                raise RuntimeError(f'{case}: the node did not answer')
            msg, key = probe.message(k)
            probe.publisher.publish(msg)
            sent.append((time.monotonic(), key))
            k += 1
            time.sleep(0.1)
        time.sleep(0.5)
        # what was sent before the node took its first message cannot be told from what
        # it never saw (not matched yet): counted from here
        before, sent = probe.counted(), []
        start, period = time.monotonic(), 1.0 / rate
        stopped = resumed = None
        while (now := time.monotonic()) < start + 1.0 + stall + 2.0:
            if stopped is None and now >= start + 1.0:
                os.kill(proc.pid, signal.SIGSTOP)
                stopped = now
            if stopped is not None and resumed is None and now >= stopped + stall:
                os.kill(proc.pid, signal.SIGCONT)
                resumed = time.monotonic()
            msg, key = probe.message(k)
            probe.publisher.publish(msg)
            sent.append((time.monotonic(), key))
            k += 1
            time.sleep(max(0.0, start + (len(sent)) * period - time.monotonic()))
        time.sleep(0.5)
        counted = probe.counted() - before
        answered = probe.answers
        first = min((answered[key] for at, key in sent if at > resumed and key in answered),
                    default=float('inf')) - resumed
        fresh = [key for at, key in sent if at >= resumed + 0.2]
        share = sum(key in answered for key in fresh) / max(1, len(fresh))
        return {'first': first, 'share': share, 'uncounted': len(sent) - counted,
                'sent': len(sent)}
    finally:
        probe.close()
        stop(proc)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--repeats', type=int, default=5)
    parser.add_argument('--stall', type=float, default=3.0)
    parser.add_argument('--rate', type=float, default=200.0)
    parser.add_argument('--cases', nargs='+', choices=list(CASES), default=list(CASES))
    parser.add_argument('--reliable', action='store_true',
                        help="the node's input subscription reliable (as before)")
    parser.add_argument('--json')
    args = parser.parse_args(argv)
    os.environ.setdefault('ROS_DOMAIN_ID', str(1 + os.getpid() % 101))
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    import rclpy
    rclpy.init()
    print(f"load average {os.getloadavg()[0]:.2f}; {args.stall:g} s stall, {args.rate:g} Hz, "
          f"{'reliable' if args.reliable else 'default (best effort)'} subscription")
    print(f"{'case':<10} {'runs':>4} {'first answer median s':>22} {'max s':>7} "
          f"{'answered after +0.2 s':>22} {'uncounted':>9}")
    rows, bad = [], []
    try:
        for case in args.cases:
            runs = [run_once(case, args.stall, args.rate, args.reliable, k)
                    for k in range(args.repeats)]
            firsts = [r['first'] for r in runs]
            row = {'case': case, 'runs': len(runs), 'first_median': float(np.median(firsts)),
                   'first_max': max(firsts), 'share_min': min(r['share'] for r in runs),
                   'uncounted': sum(r['uncounted'] for r in runs)}
            rows.append(row)
            bad += [f'{case} run {k}: {r["uncounted"]} of {r["sent"]} messages neither '
                    'accepted, rejected nor counted lost' for k, r in enumerate(runs)
                    if r['uncounted']]
            print(f"{case:<10} {row['runs']:>4} {row['first_median']:>22.3f} "
                  f"{row['first_max']:>7.3f} {100 * row['share_min']:>21.1f}% "
                  f"{row['uncounted']:>9}")
    finally:
        rclpy.shutdown()
    print(f'load average {os.getloadavg()[0]:.2f}')
    if args.json:
        with open(args.json, 'w', encoding='utf-8') as out:
            json.dump(rows, out, indent=1)
    for line in bad:
        print(f'bench_stall: {line}', file=sys.stderr)
    return 1 if bad else 0


if __name__ == '__main__':
    sys.exit(main())
