"""Soak: cog_id_node served a smooth setpoint stream for a long time, with a long trajectory
solved mid-stream.

    .venv/bin/python bench/bench_soak.py [--duration 600] [--rate 1000]
        [--params-file config/paper_four_bar_a.yaml] [--second-params-file FILE]
        [--trajectory-at S] [--trajectory-points 100000] [--sample-every 5]
        [--png out/soak.png] [--json out/soak.json]

Starts cog_id_node on the params file (namespace /soak; with ``--second-params-file`` a
second node in /soak2 gets the same stream) on a DDS domain of its own (localhost only).
A publisher thread in this process, sleeping between setpoints, streams the motion
``q_k(t) = home_k + 0.5 sin(pi t)`` on every active joint (``home`` the assembled pose; for
the paper four-bars the paper's target motion) at ``--rate``, each setpoint stamped with its
schedule; receiver threads (cog_id_ros.setpoint_loop, outside any executor) timestamp every
``effort_command`` and ``joint_effort``. Every ``--sample-every`` s the RSS and CPU% of the
node and of its child processes (the trajectory worker) are read from /proc.

At ``--trajectory-at`` s (default: a third of the run) a helper process (this file with
``--trajectory-helper``, so that building, serializing and receiving the long message never
holds up this process's threads) publishes one ``joint_trajectory`` of
``--trajectory-points`` points of the same motion (1 ms apart, with velocities and
accelerations) to the first node and waits for its ``effort_trajectory``.

Reported: setpoints sent / answered / lost (answered: a joint_effort came back with its
stamp; lost = sent - answered); latency percentiles from publish to the arrival of the
``effort_command`` (paired with the setpoints by order, which is exact when nothing was
lost; else to the arrival of the ``joint_effort``); the worst gap between consecutive
commands over the whole run, during the trajectory (from its publication to its answer
plus 1 s) and outside it; the publisher's own worst gap (a gap the driver made, not the
node); NaN/Inf in any output; RSS and CPU over time (a table, and a PNG with ``--png``);
the node's /diagnostics counts at the end. Not a test: it prints a report (``--json``
writes it too).
"""
import argparse
import json
import math
import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
NS = 1_000_000_000
CLK_TCK = os.sysconf('SC_CLK_TCK')
PAGE = os.sysconf('SC_PAGE_SIZE')


# --- the motion ---------------------------------------------------------------------------------

def motion(home, t):
    """(q, qd, qdd) of every active joint at times ``t``: home + 0.5 sin(pi t)."""
    t = np.asarray(t, float)[:, None]
    w = math.pi
    h = np.asarray(home, float)[None, :]
    return h + 0.5 * np.sin(w * t), 0.5 * w * np.cos(w * t) + 0 * h, -0.5 * w * w * np.sin(w * t) + 0 * h


def home_of(params_file):
    import cog_id_ros
    mech = cog_id_ros.Mechanism.from_params_file(params_file)
    index = [mech.joints.index(j) for j in mech.active_joints]
    return list(mech.active_joints), [float(mech.assembled_positions[i]) for i in index]


# --- /proc ----------------------------------------------------------------------------------------

def children(pid):
    """Child pids of ``pid`` (every thread's children)."""
    out = set()
    try:
        for tid in os.listdir(f'/proc/{pid}/task'):
            with open(f'/proc/{pid}/task/{tid}/children') as f:
                out.update(int(x) for x in f.read().split())
    except OSError:
        pass
    return sorted(out)


def cpu_seconds(pid):
    try:
        with open(f'/proc/{pid}/stat') as f:
            fields = f.read().rsplit(')', 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / CLK_TCK     # utime + stime
    except (OSError, IndexError, ValueError):
        return math.nan


def rss_mb(pid):
    try:
        with open(f'/proc/{pid}/statm') as f:
            return int(f.read().split()[1]) * PAGE / 2 ** 20
    except (OSError, IndexError, ValueError):
        return math.nan


class Sampler(threading.Thread):
    """RSS and CPU% of the node and its children every ``period`` s."""

    def __init__(self, pids, period, progress):
        super().__init__(daemon=True)
        self.pids = pids                 # label -> pid of the node
        self.period = period
        self.progress = progress         # () -> dict of counters to log with each sample
        self.rows = []
        self.stop_event = threading.Event()

    def snapshot(self):
        snap = {}
        for label, pid in self.pids.items():
            snap[label] = (cpu_seconds(pid), rss_mb(pid))
            kids = children(pid)
            cpu = sum(cpu_seconds(k) for k in kids) if kids else 0.0
            rss = sum(rss_mb(k) for k in kids) if kids else 0.0
            snap[label + ' children'] = (cpu, rss)
        return snap

    def run(self):
        t0 = time.monotonic()
        last_t, last = t0, self.snapshot()
        while not self.stop_event.wait(self.period):
            now, snap = time.monotonic(), self.snapshot()
            row = {'t': now - t0}
            for label, (cpu, rss) in snap.items():
                row[f'{label} rss MB'] = rss
                prev = last.get(label, (math.nan, 0))[0]
                row[f'{label} cpu %'] = 100.0 * (cpu - prev) / (now - last_t)
            row['load1'] = os.getloadavg()[0]
            row.update(self.progress())
            self.rows.append(row)
            last_t, last = now, snap


# --- the trajectory helper (a process of its own) -------------------------------------------------

def trajectory_helper(args):
    """Publish one long trajectory at monotonic time ``--at`` and wait for its answer; print
    one JSON line with the times (monotonic, comparable across processes)."""
    from builtin_interfaces.msg import Duration
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    from cog_id_ros.ros.node import control_qos

    names = args.joints.split(',')
    home = [float(x) for x in args.home.split(',')]
    rclpy.init()
    node = rclpy.create_node('soak_trajectory', start_parameter_services=False)
    pub = node.create_publisher(JointTrajectory, f'{args.namespace}/joint_trajectory', control_qos())
    got = {}
    done = threading.Event()

    def on_answer(msg):
        got['t'] = time.monotonic()
        efforts = np.array([p.effort for p in msg.points], float)
        got['points'] = len(msg.points)
        got['finite'] = bool(np.isfinite(efforts).all()) if efforts.size else True
        got['peak'] = float(np.abs(efforts).max()) if efforts.size else math.nan
        done.set()

    reader = control_qos()
    node.create_subscription(JointTrajectory, f'{args.namespace}/effort_trajectory', on_answer, reader)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    threading.Thread(target=executor.spin, daemon=True).start()
    built = time.monotonic()
    t = np.arange(args.points) * 1e-3
    q, qd, qdd = motion(home, t)
    msg = JointTrajectory()
    msg.joint_names = names
    points = []
    for i in range(args.points):
        p = JointTrajectoryPoint()
        p.positions, p.velocities, p.accelerations = q[i].tolist(), qd[i].tolist(), qdd[i].tolist()
        sec, nsec = divmod(i * 1_000_000, NS)
        p.time_from_start = Duration(sec=sec, nanosec=nsec)
        points.append(p)
    msg.points = points
    build_s = time.monotonic() - built
    while pub.get_subscription_count() == 0:
        time.sleep(0.05)
    left = args.at - time.monotonic()
    if left > 0:
        time.sleep(left)
    t_pub = time.monotonic()
    pub.publish(msg)
    t_published = time.monotonic()
    done.wait(args.timeout)
    print(json.dumps({'published': t_pub, 'publish_returned': t_published, 'build_s': build_s,
                      'answered': got.get('t'), 'points': got.get('points'),
                      'finite': got.get('finite'), 'peak_effort': got.get('peak')}), flush=True)
    executor.shutdown()
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


# --- the driver -------------------------------------------------------------------------------------

class Driver:
    """Streams setpoints into one or more nodes and records every answer."""

    def __init__(self, namespaces, joints, home, rate, duration):
        from diagnostic_msgs.msg import DiagnosticArray
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
        from sensor_msgs.msg import JointState
        from std_msgs.msg import Float64MultiArray

        from cog_id_ros.ros.node import control_qos
        from cog_id_ros.ros.setpoint_loop import SetpointLoop

        self.JointState = JointState
        self.joints, self.home, self.rate = list(joints), list(home), rate
        self.n = int(round(rate * duration))
        self.node = rclpy.create_node('soak_driver', start_parameter_services=False)
        reader = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10000,
                            reliability=ReliabilityPolicy.RELIABLE)
        self.namespaces = list(namespaces)
        self.pubs = [self.node.create_publisher(JointState, f'{ns}/joint_setpoint', control_qos())
                     for ns in namespaces]
        self.sent = np.full(self.n, np.nan)          # monotonic publish time per setpoint
        self.sent_count = 0
        self.start_ns = 0
        self.commands = {ns: [] for ns in namespaces}     # arrival times
        self.command_bad = dict.fromkeys(namespaces, 0)   # commands with NaN/Inf
        self.efforts = {ns: [] for ns in namespaces}      # (arrival, stamp index)
        self.effort_bad = dict.fromkeys(namespaces, 0)
        self.diagnostics = {ns: {} for ns in namespaces}
        self.loops = []
        for ns in namespaces:
            self.loops.append(SetpointLoop(self.node, Float64MultiArray, f'{ns}/effort_command',
                                           self._command_cb(ns), reader))
            self.loops.append(SetpointLoop(self.node, JointState, f'{ns}/joint_effort',
                                           self._effort_cb(ns), reader))
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self._on_diagnostics, 10)
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        for loop in self.loops:
            loop.start()
        threading.Thread(target=self._spin, daemon=True).start()

    def _spin(self):
        try:
            self.executor.spin()
        except Exception:   # noqa: BLE001 (shutdown at the end)
            pass

    def _command_cb(self, ns):
        arrivals, isfinite = self.commands[ns], math.isfinite

        def on_command(msg):
            arrivals.append(time.monotonic())
            if not all(map(isfinite, msg.data)):
                self.command_bad[ns] += 1
        return on_command

    def _effort_cb(self, ns):
        out, isfinite = self.efforts[ns], math.isfinite
        period = NS / self.rate

        def on_effort(msg):
            t = time.monotonic()
            stamp = msg.header.stamp.sec * NS + msg.header.stamp.nanosec
            out.append((t, int(round((stamp - self.start_ns) / period))))
            if not all(map(isfinite, msg.effort)):
                self.effort_bad[ns] += 1
        return on_effort

    def _on_diagnostics(self, msg):
        for status in msg.status:
            for ns in self.namespaces:
                if status.name.startswith(ns + '/'):
                    self.diagnostics[ns] = {kv.key: kv.value for kv in status.values}

    def wait_for_nodes(self, timeout=30.0):
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if all(p.get_subscription_count() > 0 for p in self.pubs):
                time.sleep(0.5)
                return
            time.sleep(0.05)
        raise RuntimeError('no node subscribed to joint_setpoint')

    def stream(self):
        """Publish the motion at the rate, sleeping between setpoints (run in a thread)."""
        msg = self.JointState()
        msg.name = self.joints
        period_ns = int(round(NS / self.rate))
        self.start_ns = self.node.get_clock().now().nanoseconds
        t = np.arange(self.n) / self.rate
        q = motion(self.home, t)[0]
        t0 = time.monotonic()
        sleep, now, pubs = time.sleep, time.monotonic, self.pubs
        for i in range(self.n):
            left = t0 + t[i] - now()
            if left > 0:
                sleep(left)
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(self.start_ns + i * period_ns, NS)
            msg.position = q[i].tolist()
            self.sent[i] = now()
            for pub in pubs:
                pub.publish(msg)
            self.sent_count = i + 1

    def close(self):
        for loop in self.loops:
            loop.stop()


def gaps_in(times, lo=-math.inf, hi=math.inf):
    """(largest gap between consecutive times within [lo, hi], where it starts)."""
    t = np.asarray(times)
    t = t[(t >= lo) & (t <= hi)]
    if t.size < 2:
        return math.nan, math.nan
    d = np.diff(t)
    k = int(np.argmax(d))
    return float(d[k]), float(t[k])


def analyse(driver, ns, traj, t0):
    sent = driver.sent[:driver.sent_count]
    efforts = driver.efforts[ns]
    commands = np.array(driver.commands[ns])
    idx = np.array([i for _, i in efforts], int)
    arrive = np.array([t for t, _ in efforts])
    ok = (idx >= 0) & (idx < sent.size)
    answered = np.unique(idx[ok]).size
    row = {'namespace': ns, 'sent': int(sent.size), 'answered': int(answered),
           'lost': int(sent.size - answered), 'commands': int(commands.size),
           'non_finite_commands': driver.command_bad[ns], 'non_finite_efforts': driver.effort_bad[ns]}
    if commands.size == len(efforts) and ok.all():
        latency = (commands - sent[idx]) * 1e6       # k-th command answers the k-th joint_effort
        sent_at = sent[idx]
        row['latency_to'] = 'effort_command'
    else:
        latency = (arrive[ok] - sent[idx[ok]]) * 1e6
        sent_at = sent[idx[ok]]
        row['latency_to'] = 'joint_effort'
    warm = latency[50:] if latency.size > 100 else latency
    for p in (50, 90, 99, 99.9):
        row[f'p{p:g}_us'] = float(np.percentile(warm, p)) if warm.size else math.nan
    row['max_us'] = float(warm.max()) if warm.size else math.nan
    row['worst_gap_ms'], at = gaps_in(commands)
    row['worst_gap_at_s'] = at - t0 if math.isfinite(at) else math.nan
    if traj and traj.get('published'):
        lo = traj['published']
        hi = (traj.get('answered') or lo + 60.0) + 1.0
        row['gap_during_trajectory_ms'], at = gaps_in(commands, lo, hi)
        row['gap_during_trajectory_at_s'] = at - t0 if math.isfinite(at) else math.nan
        before, after = gaps_in(commands, hi=lo), gaps_in(commands, lo=hi)
        row['worst_gap_outside_trajectory_ms'], at = max(before, after, key=lambda g: (
            math.isfinite(g[0]), g[0]))
        row['worst_gap_outside_trajectory_at_s'] = at - t0 if math.isfinite(at) else math.nan
        late = (commands >= lo) & (commands <= hi)
        if row['latency_to'] == 'effort_command':
            during = latency[late[:latency.size]] if latency.size == commands.size else latency[:0]
            row['max_latency_during_trajectory_us'] = float(during.max()) if during.size else math.nan
    for key in ('worst_gap_ms', 'gap_during_trajectory_ms', 'worst_gap_outside_trajectory_ms'):
        if key in row and math.isfinite(row[key]):
            row[key] *= 1e3
    return row, (sent_at - t0, latency)


def start_node(params_file, namespace, env):
    bindir = os.path.dirname(sys.executable)
    args = [os.path.join(bindir, 'cog_id_node'), '--ros-args', '--params-file', params_file,
            '-r', f'__ns:={namespace}', '-p', 'timeout_behavior:=none']
    log = open(os.path.join('/tmp', f'soak_node_{namespace.strip("/")}_{os.getpid()}.log'), 'w')
    proc = subprocess.Popen(args, env=env, cwd=REPO, stdin=subprocess.DEVNULL, stdout=log,
                            stderr=subprocess.STDOUT, text=True)
    end = time.monotonic() + 60
    while time.monotonic() < end:
        with open(log.name) as f:
            if "mechanism '" in f.read():
                return proc, log.name
        if proc.poll() is not None:
            break
        time.sleep(0.1)
    proc.kill()
    with open(log.name) as f:
        raise RuntimeError(f'cog_id_node did not start:\n{f.read()}')


def plot(path, rows, latency_series, traj_window, title):
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    t = [r['t'] for r in rows]
    fig, axes = plt.subplots(3, 1, figsize=(9, 9), sharex=True)
    for key in rows[0]:
        if key.endswith('rss MB'):
            axes[0].plot(t, [r[key] for r in rows], label=key.replace(' rss MB', ''))
        if key.endswith('cpu %'):
            axes[1].plot(t, [r[key] for r in rows], label=key.replace(' cpu %', ''))
    axes[0].set_ylabel('RSS [MB]')
    axes[1].set_ylabel('CPU [% of a core]')
    for label, (ts, lat) in latency_series.items():
        axes[2].plot(ts, lat, '.', ms=2, label=label)
    axes[2].set_yscale('log')
    axes[2].set_ylabel('latency p99 / max per s [ms]')
    axes[2].set_xlabel('time since the stream started [s]')
    for ax in axes:
        if traj_window:
            ax.axvspan(*traj_window, color='orange', alpha=0.2, label='trajectory solved')
        ax.legend(fontsize=7, loc='upper right')
        ax.grid(alpha=0.3)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    fig.savefig(path, dpi=110)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--duration', type=float, default=600.0, help='s of setpoint stream')
    parser.add_argument('--rate', type=float, default=1000.0, help='setpoints per second')
    parser.add_argument('--params-file', default=os.path.join(REPO, 'config', 'paper_four_bar_a.yaml'))
    parser.add_argument('--second-params-file', help='a second node, in /soak2, gets the same stream')
    parser.add_argument('--trajectory-at', type=float, help='s into the stream (default duration / 3; '
                                                             'negative: no trajectory)')
    parser.add_argument('--trajectory-points', type=int, default=100_000)
    parser.add_argument('--sample-every', type=float, default=5.0, help='s between RSS/CPU samples')
    parser.add_argument('--png', help='plot RSS, CPU and latency over time here')
    parser.add_argument('--json', help='write the report here')
    # the trajectory helper process
    parser.add_argument('--trajectory-helper', action='store_true', help=argparse.SUPPRESS)
    parser.add_argument('--namespace', help=argparse.SUPPRESS)
    parser.add_argument('--joints', help=argparse.SUPPRESS)
    parser.add_argument('--home', help=argparse.SUPPRESS)
    parser.add_argument('--points', type=int, help=argparse.SUPPRESS)
    parser.add_argument('--at', type=float, help=argparse.SUPPRESS)
    parser.add_argument('--timeout', type=float, default=300.0, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.trajectory_helper:
        return trajectory_helper(args)

    env = dict(os.environ)
    env.setdefault('ROS_DOMAIN_ID', str(150 + os.getpid() % 80))
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env['PYTHONUNBUFFERED'] = '1'
    os.environ.update({k: env[k] for k in ('ROS_DOMAIN_ID', 'ROS_AUTOMATIC_DISCOVERY_RANGE')})
    joints, home = home_of(args.params_file)
    nodes = [('/soak', args.params_file)]
    if args.second_params_file:
        joints2, _ = home_of(args.second_params_file)
        if set(joints2) - set(joints):
            # one stream for both: name every joint either node needs, same motion
            _, home2 = home_of(args.second_params_file)
            extra = [j for j in joints2 if j not in joints]
            joints = joints + extra
            home = home + [home2[joints2.index(j)] for j in extra]
        nodes.append(('/soak2', args.second_params_file))
    commit = subprocess.run(['git', 'log', '-1', '--format=%h'], cwd=REPO, capture_output=True,
                            text=True).stdout.strip()
    dirty = bool(subprocess.run(['git', 'status', '--porcelain', '--', 'cog_id_ros'], cwd=REPO,
                                capture_output=True, text=True).stdout.strip())
    started = time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())
    print(f'soak {started}: commit {commit}{" (cog_id_ros/ modified)" if dirty else ""}, '
          f'{args.duration:g} s at {args.rate:g} Hz, joints {joints}, nodes '
          f'{[ns for ns, _ in nodes]}, domain {env["ROS_DOMAIN_ID"]}', flush=True)

    procs, logs = {}, {}
    for ns, path in nodes:
        procs[ns], logs[ns] = start_node(path, ns, env)
    import rclpy
    rclpy.init()
    driver = helper = None
    traj = {}
    report = {}
    try:
        driver = Driver([ns for ns, _ in nodes], joints, home, args.rate, args.duration)
        driver.wait_for_nodes()

        def progress():
            out = {'sent': driver.sent_count}
            for ns in driver.namespaces:
                out[f'{ns} answered'] = len(driver.efforts[ns])
            return out

        sampler = Sampler({ns: p.pid for ns, p in procs.items()}, args.sample_every, progress)
        traj_at = args.duration / 3 if args.trajectory_at is None else args.trajectory_at
        streamer = threading.Thread(target=driver.stream, daemon=True)
        t0 = time.monotonic()
        sampler.start()
        streamer.start()
        if 0 <= traj_at < args.duration:
            helper_log = open(f'/tmp/soak_trajectory_{os.getpid()}.log', 'w+')
            helper = subprocess.Popen(
                [sys.executable, os.path.abspath(__file__), '--trajectory-helper', '--namespace', '/soak',
                 '--joints', ','.join(joints), '--home', ','.join(map(repr, home)),
                 '--points', str(args.trajectory_points), '--at', repr(t0 + traj_at),
                 '--timeout', repr(max(60.0, args.duration - traj_at + 60))],
                env=env, cwd=REPO, stdout=subprocess.PIPE, stderr=helper_log, text=True)
        while streamer.is_alive():
            streamer.join(timeout=10.0)
            print(f'  {time.monotonic() - t0:6.0f} s: sent {driver.sent_count}, answered '
                  + ', '.join(f'{ns} {len(driver.efforts[ns])}' for ns in driver.namespaces), flush=True)
        time.sleep(1.5)   # the last answers and a diagnostics report
        sampler.stop_event.set()
        sampler.join()
        if helper is not None:
            out, _ = helper.communicate(timeout=max(60.0, args.duration))
            lines = [line for line in out.splitlines() if line.startswith('{')]
            helper_log.seek(0)
            traj = json.loads(lines[-1]) if lines else {'error': helper_log.read()[-2000:]}
        traj_window = None
        if traj.get('published'):
            traj['solve_s'] = (traj['answered'] - traj['published']) if traj.get('answered') else None
            traj_window = (traj['published'] - t0, (traj.get('answered') or traj['published']) - t0)
        rows, series = [], {}
        for ns in driver.namespaces:
            row, (sent_at, latency) = analyse(driver, ns, traj if ns == '/soak' else None, t0)
            rows.append(row)
            # per-second p99 and max of the latency (by the setpoint's send time), for the plot
            second = np.floor(sent_at).astype(int)
            secs, p99, top = [], [], []
            for s in np.unique(second):
                block = latency[second == s] / 1e3
                secs.append(s + 0.5)
                p99.append(np.percentile(block, 99))
                top.append(block.max())
            series[f'{ns} p99'] = (secs, p99)
            series[f'{ns} max'] = (secs, top)
        publisher_gap, publisher_gap_at = gaps_in(driver.sent[:driver.sent_count])
        publisher_gap *= 1e3
        publisher_gap_at -= t0
        report = {'date': started, 'commit': commit, 'cog_id_ros_modified': dirty,
                  'command': 'python bench/bench_soak.py ' + ' '.join(sys.argv[1:] if argv is None else argv),
                  'duration_s': args.duration, 'rate_hz': args.rate, 'nodes': dict(nodes),
                  'results': rows, 'publisher_worst_gap_ms': publisher_gap,
                  'publisher_worst_gap_at_s': publisher_gap_at, 'trajectory': traj,
                  'samples': sampler.rows,
                  'diagnostics': {ns: driver.diagnostics[ns] for ns in driver.namespaces}}
        if args.png and sampler.rows:
            plot(args.png, sampler.rows, series, traj_window,
                 f'cog_id_node soak, {started}, commit {commit}: {args.duration:g} s at '
                 f'{args.rate:g} Hz, {args.trajectory_points} point trajectory at {traj_at:g} s')
    finally:
        if driver is not None:
            driver.close()
        rclpy.try_shutdown()
        for ns, proc in procs.items():
            proc.send_signal(signal.SIGINT)
            try:
                report.setdefault('exit_status', {})[ns] = proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                proc.kill()
                report.setdefault('exit_status', {})[ns] = 'killed after SIGINT'
        if helper is not None and helper.poll() is None:
            helper.kill()
    print_report(report, logs)
    if args.json:
        os.makedirs(os.path.dirname(os.path.abspath(args.json)), exist_ok=True)
        with open(args.json, 'w', encoding='utf-8') as f:
            json.dump(report, f, indent=1, default=str)
    return 0


def print_report(report, logs):
    if not report.get('results'):
        print('no results', report)
        return
    print(f"\nsoak of {report['date']}, commit {report['commit']}"
          f"{' (cog_id_ros/ modified)' if report['cog_id_ros_modified'] else ''}: "
          f"{report['duration_s']:g} s at {report['rate_hz']:g} Hz")
    print(f"command: {report['command']}")
    print('\n| node | sent | answered | lost | p50 µs | p90 µs | p99 µs | p99.9 µs | max µs | '
          'worst gap ms (at s) | NaN/Inf out |')
    print('|---|---|---|---|---|---|---|---|---|---|---|')
    for r in report['results']:
        print(f"| {r['namespace']} | {r['sent']} | {r['answered']} | {r['lost']} | {r['p50_us']:.0f} | "
              f"{r['p90_us']:.0f} | {r['p99_us']:.0f} | {r['p99.9_us']:.0f} | {r['max_us']:.0f} | "
              f"{r['worst_gap_ms']:.1f} ({r['worst_gap_at_s']:.0f}) | "
              f"{r['non_finite_commands'] + r['non_finite_efforts']} |")
    print(f"(latency to {report['results'][0]['latency_to']}; the publisher's own worst gap "
          f"{report['publisher_worst_gap_ms']:.1f} ms at "
          f"{report.get('publisher_worst_gap_at_s', math.nan):.1f} s: a gap of the driver, not "
          f"of the node)")
    traj = report.get('trajectory') or {}
    if traj.get('published'):
        r = report['results'][0]
        solve = traj.get('solve_s')
        print(f"\ntrajectory: {traj.get('points')} points answered "
              f"{'in %.2f s' % solve if solve is not None else 'NEVER'} after publication "
              f"(built in {traj.get('build_s', math.nan):.1f} s by the helper), efforts finite: "
              f"{traj.get('finite')}; worst command gap during it (publication to answer + 1 s): "
              f"{r.get('gap_during_trajectory_ms', math.nan):.1f} ms at "
              f"{r.get('gap_during_trajectory_at_s', math.nan):.1f} s; worst gap outside it "
              f"{r.get('worst_gap_outside_trajectory_ms', math.nan):.1f} ms at "
              f"{r.get('worst_gap_outside_trajectory_at_s', math.nan):.1f} s; max latency during it "
              f"{r.get('max_latency_during_trajectory_us', math.nan) / 1e3:.1f} ms")
    elif traj:
        print(f'\ntrajectory: {traj}')
    rows = report['samples']
    if rows:
        keys = [k for k in rows[0] if k != 't']
        print('\n| t s | ' + ' | '.join(keys) + ' |')
        print('|' + '---|' * (len(keys) + 1))
        step = max(1, len(rows) // 20)
        for row in rows[::step] + ([rows[-1]] if (len(rows) - 1) % step else []):
            print(f"| {row['t']:.0f} | " + ' | '.join(
                f'{row[k]:.1f}' if isinstance(row[k], float) else str(row[k]) for k in keys) + ' |')
    for ns, diag in report['diagnostics'].items():
        keys = [k for k, v in diag.items() if k.startswith(('setpoints', 'rejected', 'trajector',
                                                            'internal', 'timeouts', 'compute',
                                                            'effort_clipped'))
                and v not in ('0', '')]
        print(f'\n/diagnostics of {ns} at the end: ' + ', '.join(f'{k} {diag[k]}' for k in keys))
    print(f"exit status of the nodes on SIGINT: {report.get('exit_status')}; logs: {logs}")


if __name__ == '__main__':
    sys.exit(main())
