"""How long cog_id_node takes to exit on SIGINT, in every lifecycle state, cycle after cycle.

    .venv/bin/python bench/bench_sigint.py [--cycles 10] [--bound 2.0] [--json F]

Per cycle, for each state (a plain node serving; a managed node unconfigured, inactive,
active, and active again after deactivate, cleanup, configure, activate), one
``cog_id_node`` (config/paper_four_bar_a.yaml, gravity_compensation, a namespace and the
DDS domain of this run, localhost only) is started, driven there through
``~/change_state``, given SIGINT 0.3 s later, and timed until it exits. Reported per
state: runs, median and max seconds, exit statuses other than 0. A node still running
``--bound`` s after SIGINT is a failure: it gets SIGUSR1 (its Python stacks to its log,
faulthandler), then SIGKILL, the log is kept beside the JSON (or in the working
directory) and the exit status is 1, naming the run. Run a CPU hog beside it for the
loaded figure (``python3 -c "while True: pass" &``).
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

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
CONFIG = os.path.join(REPO, 'config', 'paper_four_bar_a.yaml')


def states():
    from lifecycle_msgs.msg import Transition as T
    configure, activate = T.TRANSITION_CONFIGURE, T.TRANSITION_ACTIVATE
    return {'plain': None, 'unconfigured': [], 'inactive': [configure],
            'active': [configure, activate],
            'cycled': [configure, activate, T.TRANSITION_DEACTIVATE, T.TRANSITION_CLEANUP,
                       configure, activate]}


def one(node, name, steps, k, bound, keep):
    """(seconds to exit, exit status, the transitions' answers) of one run."""
    from lifecycle_msgs.srv import ChangeState
    ns = f'/sigint_{name}_{k}'
    managed = ['-p', 'managed:=true'] if steps is not None else []
    proc = subprocess.Popen(
        [os.path.join(os.path.dirname(sys.executable), 'cog_id_node'), '--ros-args',
         '--params-file', CONFIG, '-r', f'__ns:={ns}', '-p', 'control_mode:=gravity_compensation',
         *managed], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    log: list[str] = []
    threading.Thread(target=lambda: log.extend(proc.stdout), daemon=True).start()
    answers = []
    if steps is None:
        end = time.monotonic() + 60
        while not any("mechanism '" in line for line in log) and time.monotonic() < end:
            time.sleep(0.05)
    else:
        client = node.create_client(ChangeState, f'{ns}/cog_id_node/change_state')
        client.wait_for_service(60)
        for step in steps:
            request = ChangeState.Request()
            request.transition.id = step
            response = None
            for _ in range(3):
                response = client.call(request, timeout_sec=60)
                if response is not None:
                    break
            answers.append(None if response is None else response.success)
        node.destroy_client(client)
    time.sleep(0.3)
    start = time.monotonic()
    proc.send_signal(signal.SIGINT)
    try:
        proc.wait(timeout=bound)
        return time.monotonic() - start, proc.returncode, answers
    except subprocess.TimeoutExpired:
        proc.send_signal(signal.SIGUSR1)
        time.sleep(2.0)
        proc.kill()
        proc.wait()
        time.sleep(0.2)
        path = os.path.join(keep, f'bench_sigint_{name}_{k}.log')
        with open(path, 'w', encoding='utf-8') as out:
            out.writelines(log)
        return None, path, answers


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--cycles', type=int, default=10)
    parser.add_argument('--bound', type=float, default=2.0)
    parser.add_argument('--json')
    args = parser.parse_args(argv)
    os.environ.setdefault('ROS_DOMAIN_ID', str(1 + os.getpid() % 101))
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    rclpy.init()
    node = rclpy.create_node('sigint_bench')
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    threading.Thread(target=executor.spin, daemon=True).start()
    keep = os.path.dirname(os.path.abspath(args.json)) if args.json else os.getcwd()
    table = states()
    times: dict[str, list[float]] = {name: [] for name in table}
    bad: list[str] = []
    print(f'load average {os.getloadavg()[0]:.2f}; {args.cycles} cycles', flush=True)
    try:
        for k in range(args.cycles):
            for name, steps in table.items():
                seconds, status, answers = one(node, name, steps, k, args.bound, keep)
                if seconds is None:
                    bad.append(f'{name} cycle {k}: still running {args.bound:g} s after '
                               f'SIGINT (stacks and log: {status})')
                    continue
                times[name].append(seconds)
                if status != 0 or not all(answers):
                    bad.append(f'{name} cycle {k}: exit status {status}, transitions '
                               f'{answers}')
    finally:
        executor.shutdown()
        rclpy.shutdown()
    print(f"{'state':<14} {'runs':>4} {'median s':>9} {'max s':>7}")
    rows = []
    for name, values in times.items():
        row = {'state': name, 'runs': len(values),
               'median': float(np.median(values)) if values else None,
               'max': max(values) if values else None}
        rows.append(row)
        if values:
            print(f"{name:<14} {len(values):>4} {row['median']:>9.3f} {row['max']:>7.3f}")
    print(f'load average {os.getloadavg()[0]:.2f}')
    if args.json:
        with open(args.json, 'w', encoding='utf-8') as out:
            json.dump(rows, out, indent=1)
    for line in bad:
        print(f'bench_sigint: {line}', file=sys.stderr)
    return 1 if bad else 0


if __name__ == '__main__':
    sys.exit(main())
