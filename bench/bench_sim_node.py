"""Speed of cog_sim_node as fast as possible, beside Simulation.step in one process.

    .venv/bin/python bench/bench_sim_node.py [CONFIG ...]     (also run by ./dev bench)

For each parameter file (default: the paper four-bar (a), its cranks tilted to 1.2 rad so
that it swings under gravity for minutes; a file given on the command line is simulated
from its initial_positions): the real-time factor of ``Simulation.step`` alone (1 ms steps,
zero efforts, for 6 s of wall time), then of ``cog_sim_node`` with ``real_time_factor:=0``
in three set-ups -- the defaults (joint_states every 10 ms), with ``publish_clock``, and
with a ``joint_states`` and a ``/clock`` after every step -- read from its
``real_time_factor_achieved`` in /diagnostics (the median of the reports over 6 s, each
over 0.5 s; a mechanism that falls to a pose it cannot go on from stops, and the reports
while stopped are left out: a mechanism that falls under gravity to such a pose at once,
as the Stewart platform does without efforts, reports nothing). Runs on ROS_DOMAIN_ID 97
unless one is set.
"""
import os
import statistics
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.join(HERE, '..')
sys.path.insert(0, REPO)
os.environ.setdefault('ROS_DOMAIN_ID', '97')
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
import rclpy  # noqa: E402

import cog_id_ros  # noqa: E402

TILT = 1.2
#: (parameter file, its initial active positions or None, the node's extra arguments)
DEFAULT = [('config/paper_four_bar_a.yaml', [TILT],
            ['-p', f'mechanism.initial_positions:=[{TILT},{-TILT},{TILT},{TILT}]'])]
SETUPS = [('defaults', []), ('publish_clock', ['-p', 'publish_clock:=true']),
          ('every step', ['-p', 'publish_clock:=true', '-p', 'joint_states_period:=0.0'])]
SECONDS = 6.0
#: s of wall time Simulation.step runs alone (as long as the node's reports, so that both
#: see the same load of a shared machine)
API_SECONDS = 6.0


def api_factor(path, positions):
    sim = cog_id_ros.Simulation(cog_id_ros.Mechanism.from_params_file(path), time_step=0.001)
    sim.reset(positions=positions)
    zeros = [0.0] * len(sim.positions)
    start = time.perf_counter()
    try:
        while time.perf_counter() - start < API_SECONDS:
            for _ in range(100):
                sim.step(zeros)
    except cog_id_ros.CogIdError:
        pass
    return sim.time / (time.perf_counter() - start), sim.backend


def node_factor(node, path, extra):
    reports = []

    def heard(msg):
        for status in msg.status:
            if status.name.startswith('/cog_sim_node'):
                value = {kv.key: kv.value for kv in status.values}['real_time_factor_achieved']
                if value:
                    reports.append(float(value))
    sub = node.create_subscription(DiagnosticArray, '/diagnostics', heard, 10)
    proc = subprocess.Popen([sys.executable, '-m', 'cog_id_ros.ros.sim_main', '--ros-args',
                             '--params-file', path, '-p', 'real_time_factor:=0.0',
                             '-p', 'diagnostics_period:=0.5', *extra],
                            cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        end = time.monotonic() + SECONDS + 5.0          # start-up, then the reports
        while time.monotonic() < end and len(reports) < SECONDS / 0.5:
            rclpy.spin_once(node, timeout_sec=0.1)
    finally:
        proc.send_signal(2)
        proc.wait(timeout=30)
        node.destroy_subscription(sub)
    return statistics.median(reports[1:] or reports) if reports else float('nan'), len(reports)


def main(argv):
    configs = [(path, None, []) for path in argv] or DEFAULT
    rclpy.init()
    node = rclpy.create_node('bench_sim_node')
    try:
        for path, positions, extra in configs:
            factor, backend = api_factor(path, positions)
            print(f'{os.path.basename(path)} ({backend}): Simulation.step alone {factor:.0f}x '
                  'real time')
            for name, more in SETUPS:
                got, count = node_factor(node, path, [*extra, *more])
                print(f'  cog_sim_node, {name}: {got:.1f}x real time ({count} reports)')
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
