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
/diagnostics counters. At the end it accounts for every message: each measured state sent
is accepted or rejected by the node (else lost on the way to it), each accepted one and
each timeout is answered by a command the plant received (else lost on the way back). It
prints that, the largest gap between two commands, every gap longer than 10 ms (whether
the plant itself was late then, or the node and DDS), how far this process (the plant) ever
fell behind its own clock, the RSS at each minute and its growth over the second half,
and the worst tracking error. Exit status 0 when nothing was lost or rejected, the RSS grew
by less than 5 MB over the second half, and no measurement_timeout went off during the run
that the plant's own lateness does not explain (one goes off after the last state: the
stream stopped, and the drain waits for it); 1 otherwise (the line says which).
"""
import argparse
import gc
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
#: s: the node's measurement_timeout in the soak
MEASUREMENT_TIMEOUT = 0.5
#: s: a gap between two commands longer than this is counted (and said whose it was)
GAP = 0.010
#: s: the plant sending a state this late counts as the plant's own stall
LATE = 0.002
#: s: a bare process sleeping 1 ms at a time that wakes this late: the machine stalled
PROBE_LATE = 0.005
#: the bare process: prints "<monotonic woke> <s late>" for every oversleep, until SIGTERM
PROBE = f"""
import signal, sys, time
late = []
signal.signal(signal.SIGTERM, lambda *a: (print("\\n".join(late), flush=True), sys.exit(0)))
while True:
    before = time.monotonic()
    time.sleep(0.001)
    woke = time.monotonic()
    if woke - before - 0.001 > {PROBE_LATE}:
        late.append(f"{{woke}} {{woke - before - 0.001}}")
"""


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
        self.worst_gap, self.worst_gap_at = 0.0, 0.0        # s, and when (since started)
        self.started = time.monotonic()         # reset when the run starts
        self.running = True                     # False once the last state was sent
        self.worst_late, self.worst_late_at = 0.0, 0.0     # s the plant was behind, when
        self.diagnostics = {}
        self.msg = JointState
        self.gaps = []                          # (ending at s since started, length s)
        self.late = []                          # (monotonic, s) the plant sent late by > LATE
        # no rclpy executor here (bench/receivers.py): its delays would count as the node's
        from receivers import listen
        self.loops = [listen(self.node, Float64MultiArray, '/soak/effort_command',
                             self._on_command, control_qos()),
                      listen(self.node, DiagnosticArray, '/diagnostics', self._on_diagnostics,
                             10)]

    def stop(self):
        for loop in self.loops:
            loop.stop()

    def _on_command(self, msg):
        now = time.monotonic()
        if self.running and self.last_arrival is not None:
            gap = now - self.last_arrival
            if gap > self.worst_gap:
                self.worst_gap, self.worst_gap_at = gap, now - self.started
            if gap > GAP:
                self.gaps.append((now - self.started, gap, self.last_arrival))
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
         '-p', 'kp:=[100.0]', '-p', 'kd:=[20.0]',
         '-p', f'measurement_timeout:={MEASUREMENT_TIMEOUT}'],
        stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT, cwd=REPO)
    probe = subprocess.Popen([sys.executable, '-c', PROBE], stdout=subprocess.PIPE, text=True)
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
        plant.started = time.monotonic()
        next_sample = 0.0
        gc.collect()
        gc.freeze()         # the plant's start-up objects: no full collection walks them
        for k in range(steps):
            due = t0 + k * period
            while (now := time.perf_counter()) < due:
                if due - now > 0.0005:
                    time.sleep(due - now - 0.0004)
            if now - due > plant.worst_late:     # this process itself behind its clock
                plant.worst_late, plant.worst_late_at = now - due, k * period
            if now - due > LATE:
                plant.late.append((time.monotonic(), now - due))
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
        plant.running = False       # gaps from here on are the end of the stream
        # the drain: the commands of the last states, then the node's timeout of the stopped
        # stream (measurement_timeout after the last state) and a report after it
        time.sleep(MEASUREMENT_TIMEOUT + 2.0)
        samples.append((args.minutes * 60, rss_mb(node.pid), dict(plant.diagnostics)))
    finally:
        probe.terminate()
        plant.machine = [tuple(map(float, line.split())) for line in probe.communicate()[0].split('\n')
                         if line.strip()]
        plant.stop()
        node.send_signal(2)
        try:
            node.wait(15)
        except subprocess.TimeoutExpired:
            node.kill()
    return report(args, sent, plant, samples, resets, worst_error)


def count(values, key):
    try:
        return int(values.get(key, 0) or 0)
    except ValueError:
        return 0


def report(args, sent, plant, samples, resets, worst_error):
    """Print the account; the exit status. Every measured state is accounted for by the
    node's counters (accepted or rejected: else lost on the way to it) and every command
    by the plant (the node's accepted states plus one per timeout: else lost on the way
    back)."""
    last = samples[-1][2]
    accepted = count(last, 'measurements_accepted')
    rejected = count(last, 'measurements_rejected')
    timeouts = count(last, 'timeouts')
    to_node = sent - accepted - rejected
    to_plant = accepted + timeouts - plant.received
    rss = [(t, r) for t, r, _ in samples]
    half = [r for t, r in rss if t >= args.minutes * 30]
    growth = (half[-1] - half[0]) if len(half) > 1 else math.nan
    print(f'{os.path.basename(args.params_file)}, {args.mode}, {args.rate:g} Hz, '
          f'{args.minutes:g} min')
    print(f'measured states sent {sent}: node accepted {accepted}, rejected {rejected}, '
          f'lost on the way to it {to_node}; commands received {plant.received} '
          f'(timeout commands {timeouts}: the end of the stream is one), lost on the way '
          f"back {to_plant}; setpoints lost {last.get('setpoints_lost')}")
    print(f'worst gap between commands {plant.worst_gap * 1e3:.1f} ms (ending at t = '
          f'{plant.worst_gap_at:.3f} s); the plant (this '
          f'process) at worst {plant.worst_late * 1e3:.1f} ms behind its clock (t = '
          f'{plant.worst_late_at:.1f} s); worst tracking error {worst_error:.3g}; plant '
          f"resets {resets}; node compute median {last.get('compute_time_median_us')} us")
    # a gap whose time the plant itself spent late (sending its states) is the plant's; one
    # during which a bare sleeping process (PROBE) overslept too is the machine's
    plants = [(at, gap) for at, gap, start in plant.gaps
              if any(start - LATE <= t <= start + gap for t, _ in plant.late)]
    machine = [(at, gap) for at, gap, start in plant.gaps
               if any(woke - late <= start + gap and woke >= start
                      for woke, late in getattr(plant, 'machine', ()))]
    neither = [(at, gap) for at, gap, _ in plant.gaps
               if (at, gap) not in plants and (at, gap) not in machine]
    print(f'gaps between commands longer than {GAP * 1e3:g} ms: {len(plant.gaps)}: '
          f'{len(plants)} while the plant itself was more than {LATE * 1e3:g} ms late, '
          f'{len(machine)} while a bare sleeping process overslept more than '
          f'{PROBE_LATE * 1e3:g} ms (the machine), {len(neither)} neither (the node or DDS); '
          + ', '.join(f'{gap * 1e3:.1f} ms at t = {at:.1f} s' for at, gap, _ in plant.gaps[:10]))
    # one timeout is the end of the stream (the drain waits for it); others, in the run
    in_run = max(0, timeouts - 1)
    if in_run:
        cause = ('the plant itself was late by more than measurement_timeout'
                 if plant.worst_late >= MEASUREMENT_TIMEOUT else
                 'the plant was never that late: the node or DDS held the states')
        print(f'measurement_timeout ({MEASUREMENT_TIMEOUT:g} s) went off {in_run} time(s) '
              f'during the run (besides the end of the stream): {cause}')
    print('RSS (MB) every minute: ' + ', '.join(f'{r:.1f}' for t, r in rss
                                                  if abs(t / 60 - round(t / 60)) < 1e-6 or
                                                  t == rss[-1][0]))
    print(f'RSS growth over the second half: {growth:+.2f} MB')
    if args.json:
        with open(args.json, 'w', encoding='utf-8') as stream:
            json.dump({'sent': sent, 'received': plant.received, 'accepted': accepted,
                       'lost_to_node': to_node, 'lost_to_plant': to_plant,
                       'rejected': rejected, 'timeouts': timeouts, 'rss': rss,
                       'growth_mb': growth, 'worst_gap_s': plant.worst_gap,
                       'gaps': [(at, gap) for at, gap, _ in plant.gaps],
                       'plant_gaps': plants, 'machine_gaps': machine,
                       'node_gaps': neither,
                       'worst_late_s': plant.worst_late, 'worst_error': worst_error,
                       'resets': resets, 'diagnostics': last}, stream, indent=1)
    stalled_node = in_run != 0 and plant.worst_late < MEASUREMENT_TIMEOUT
    ok = to_node == 0 and to_plant == 0 and rejected == 0 and growth < 5.0 and not stalled_node
    return 0 if ok else 1


if __name__ == '__main__':
    sys.exit(main())
