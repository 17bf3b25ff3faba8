"""The paper's Fig. 4 over real ROS 2 topics: torques of the four-bar (a) and (b).

    python -m cog_id_ros.demos.fig4 [--output out/fig4_torques.png] [--rate 1000]

What it does, end to end, as a user would:
  1. starts two ``cog_id_node`` processes, one per parameter file
     (config/paper_four_bar_a.yaml in namespace /fig4_a, paper_four_bar_b.yaml in /fig4_b),
     reporting /diagnostics every 0.2 s and keeping the whole run in ``joint_effort``'s
     writer history (so a late recorder is sent again what it missed);
  2. plays the paper's target motion ``theta(t) = pi/2 + 0.5 sin(pi t)``, t in [0, 2] s, at
     ``--rate`` setpoints per second into each node's ``joint_setpoint`` with the player of
     ``cog_id_player`` (positions only: the node estimates velocities and accelerations),
     once the node's subscription and the recorder's are matched and the node has answered
     the first setpoint;
  3. records ``joint_effort`` in a process of its own (``cog_id_ros.ros.recorder``, a queue
     as deep as the run) and compares it with the exact torques of the parallelogram,
     ``tau3 = (5/3) m L^2 thetaddot + 2 m g L cos(theta)`` for (a), half of it on each
     actuator for (b);
  4. writes the torque curves of (a) and (b) side by side to a PNG and the recorded
     efforts to CSVs beside it (format of ``cog_id_torques``), prints a summary table and,
     per node, the setpoints sent, what the node says it did with them (its
     /diagnostics counters, read before it is stopped) and the efforts recorded.

Exit status: 0 when every setpoint was answered and recorded and every torque after the
first samples is within 1 % of the peak; 1 when a torque is not (or a node did not exit
cleanly); 3 when any setpoint went unanswered or unrecorded, with one line per node
saying where (``/fig4_a: node: 16 setpoints lost before the node took them``,
``/fig4_b: recorder: 343 efforts the node sent were not recorded``).

It uses ROS_DOMAIN_ID from the environment (or picks one from the process id when unset, and
says which), with discovery limited to this machine.
"""
import argparse
import math
import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np

from ..offline import trajectory_io
from ..ros import recorder as recording
from ..ros.parameters import MAX_QOS_DEPTH
from .paper_four_bar import DURATION, ConfigNotFound, config_dir, exact_torque, target_motion

WARM_UP = 3                       # samples the estimator needs before it is exact
TOLERANCE = 0.01                  # of the peak torque
LOST = 3                          # exit status: setpoints went unanswered or unrecorded
REFUSED = 2                       # exit status: did not run (no config files)
#: s between the nodes' /diagnostics reports: their counters are read once a run is over
DIAGNOSTICS_PERIOD = 0.2

CASES = (
    # key, params file, namespace, active joints, share of the single-actuator torque
    ('a', 'paper_four_bar_a.yaml', '/fig4_a', ['joint3'], 1.0),
    ('b', 'paper_four_bar_b.yaml', '/fig4_b', ['joint1', 'joint3'], 0.5),
)


class NodeProcess:
    """A cog_id_node subprocess whose log lines are collected (so its pipe never fills)."""

    def __init__(self, params_file, namespace, env, extra=()):
        exe = os.path.join(os.path.dirname(sys.executable), 'cog_id_node')
        cmd = [exe] if os.path.exists(exe) else [sys.executable, '-m', 'cog_id_ros.node']
        self.namespace = namespace
        self.proc = subprocess.Popen(
            cmd + ['--ros-args', '--params-file', params_file, '-r', f'__ns:={namespace}',
                   *extra],
            env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
            text=True)
        self.lines = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self):
        for line in self.proc.stdout:
            self.lines.append(line.rstrip())

    def wait_started(self, timeout=30.0):
        """The node's first log line (its mechanism) once it is up; raises if it is not."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if self.lines and "mechanism '" in self.lines[0]:
                return self.lines[0]
            if self.proc.poll() is not None:
                self._reader.join(timeout=2)
                break
            time.sleep(0.02)
        raise RuntimeError('cog_id_node did not start:\n' + '\n'.join(self.lines))

    def stop(self):
        """SIGINT, like Ctrl-C; returns the exit status."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._reader.join(timeout=2)
        if not self._reader.is_alive():
            self.proc.stdout.close()       # read to its end
        return self.proc.returncode

    def warnings(self):
        return [line for line in self.lines if '[WARN]' in line or '[ERROR]' in line]


def node_arguments(n_setpoints):
    """ROS arguments of the node in ``namespace`` for a run of ``n_setpoints``: returns
    ``namespace -> [arguments]``."""
    def extra(namespace):
        # joint_effort's writer keeps the whole run (at most the node's bound on depths): a
        # reliable writer resends only what its history still holds, so with the default
        # 100 a recorder stalled for 0.1 s at 1 kHz would lose efforts for good. The
        # setpoint side keeps the node's own QoS: what the node drops there is its own
        # behaviour under load, which the demo reports.
        return ['-p', f'diagnostics_period:={DIAGNOSTICS_PERIOD}',
                '-p', f'qos_overrides.{namespace}/joint_effort.publisher.depth:='
                      f'{min(n_setpoints, MAX_QOS_DEPTH)}']
    return extra


def connect(player, recorder, namespace):
    """Wait until the player's setpoints reach the node and the node's efforts the
    recorder, both as far as matching can tell (see Recorder.answer_first for the rest)."""
    if not player.wait_for_node(30.0):
        raise RuntimeError(f'no cog_id_node subscribes to {namespace}/joint_setpoint')
    if not recorder.wait_matched([f'{namespace}/joint_effort'], 30.0):
        raise RuntimeError(f'the recorder does not receive {namespace}/joint_effort')


def run_case(player, recorder, case, t, theta):
    """Play the target motion into one node; returns the recorded efforts, which setpoints
    have one, and the run's :class:`~cog_id_ros.ros.recorder.Account`."""
    from ..ros.player import play_recorded
    _, _, namespace, joints, _ = case
    effort_topic = f'{namespace}/joint_effort'
    positions = np.repeat(theta[:, None], len(joints), axis=1)
    stamps, result, received = play_recorded(
        player, recorder, effort_topic, recording.diagnostics_name(namespace), t, positions,
        where=namespace)
    found = np.array([s in received for s in stamps])
    names = next((received[s][0] for s in stamps if s in received), list(joints))
    if list(names) != list(joints):
        raise RuntimeError(f'{effort_topic} names {names}, expected {joints}')
    efforts = np.full((len(stamps), len(joints)), np.nan)
    for i, s in enumerate(stamps):
        if s in received:
            efforts[i] = received[s][1]
    return efforts, found, result


def settled(found):
    """Samples whose WARM_UP predecessors all came back: the estimator's window is full of
    consecutive setpoints there. The first samples, and any just after a lost setpoint,
    carry the estimator's warm-up error and are not judged."""
    ok = found.copy()
    ok[:WARM_UP] = False
    for k in range(1, WARM_UP + 1):
        ok[k:] &= found[:-k]
    return ok


def statistics(t, efforts, found, exact):
    """Per joint: peak, max and RMS error after the warm-up, against ``exact`` (N,)."""
    rows = []
    peak_exact = float(np.abs(exact).max())
    use = settled(found)
    for k in range(efforts.shape[1]):
        err = np.abs(efforts[use, k] - exact[use])
        rows.append({
            'peak': float(np.nanmax(np.abs(efforts[:, k]))),
            'peak_exact': peak_exact,
            'max_error': float(err.max()) if err.size else math.nan,
            'rms_error': float(np.sqrt(np.mean(err ** 2))) if err.size else math.nan,
            'within': bool(err.size and err.max() <= TOLERANCE * peak_exact),
        })
    return rows


def plot(path, t, results, rate):
    """Fig. 4: (a) and (b) side by side, published torques over the exact ones."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(12.0, 4.6), layout='constrained')
    axes = fig.subplots(1, 2, sharey=True)
    titles = {'a': '(a) one actuator: \u03b8m = \u03b83',
              'b': '(b) redundant actuation: \u03b8m = (\u03b81, \u03b83)'}
    colors = {'joint1': 'C1', 'joint3': 'C0'}
    for ax, (key, case, efforts, found, exact, stats) in zip(axes, results):
        joints = case[3]
        ax.axhline(0.0, color='0.8', lw=0.8, zorder=0)
        for k, joint in enumerate(joints):
            curve = np.where(found, efforts[:, k], np.nan)
            ax.plot(t, curve, color=colors.get(joint, f'C{k + 2}'), lw=2.4 if k == 0 else 1.4,
                    ls='-' if k == 0 else (0, (4, 3)),
                    label=f'\u03c4{joint[-1]} from cog_id_node '
                          f'(peak {stats[k]["peak"]:.3f} N m)')
        ax.plot(t, exact, color='k', lw=0.9, ls=':',
                label='exact' + (' (half of (a))' if case[4] != 1.0 else ''))
        ax.set_title(titles[key], fontsize=11)
        ax.set_xlabel('time t [s]')
        ax.grid(True, color='0.92')
        ax.legend(loc='upper left', fontsize=8.5, framealpha=0.9)
        worst = max(s['max_error'] for s in stats)
        ax.text(0.98, 0.03, f'{int(found.sum())}/{found.size} setpoints at {rate:g} Hz\n'
                f'max |error| after warm-up: {worst:.2e} N m',
                transform=ax.transAxes, ha='right', va='bottom', fontsize=8.5,
                bbox={'boxstyle': 'round', 'fc': 'white', 'ec': '0.8'})
    axes[0].set_ylabel('actuator torque [N m]')
    fig.suptitle('Paper four-bar, target motion \u03b8(t) = \u03c0/2 + 0.5 sin(\u03c0t): '
                 'torques published by cog_id_node (Fig. 4)', fontsize=12)
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    fig.savefig(path, dpi=110)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog='python -m cog_id_ros.demos.fig4',
                                     description=__doc__.split('\n\n')[0])
    parser.add_argument('--output', default=os.path.join('out', 'fig4_torques.png'),
                        help='PNG to write (default %(default)s); CSVs go beside it')
    parser.add_argument('--rate', type=float, default=1000.0,
                        help='setpoints per second (default %(default)s)')
    args = parser.parse_args(argv)

    try:
        cfg = config_dir()
    except ConfigNotFound as exc:
        print(f'fig4: {exc}', file=sys.stderr)
        return REFUSED
    env = dict(os.environ)
    if not env.get('ROS_DOMAIN_ID'):
        env['ROS_DOMAIN_ID'] = str(1 + os.getpid() % 101)
        print(f'ROS_DOMAIN_ID not set: using {env["ROS_DOMAIN_ID"]}')
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    env['PYTHONUNBUFFERED'] = '1'
    os.environ.update({k: env[k] for k in ('ROS_DOMAIN_ID', 'ROS_AUTOMATIC_DISCOVERY_RANGE')})

    started = time.monotonic()
    t = np.arange(int(round(DURATION * args.rate)) + 1) / args.rate
    extra = node_arguments(len(t))
    procs = {case[0]: NodeProcess(os.path.join(cfg, case[1]), case[2], env, extra(case[2]))
             for case in CASES}
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    from ..ros.player import Player
    context = rclpy.Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    theta, _, thetaddot = target_motion(t)
    exact_a = exact_torque(theta, thetaddot)
    results = []
    accounts = []
    recorder = None
    players = {}
    try:
        # one effort per setpoint at most: a queue of len(t) never pushes one out
        recorder = recording.Recorder([f'{case[2]}/joint_effort' for case in CASES], len(t))
        for key, _, namespace, joints, _ in CASES:
            # the publisher's history holds the whole run: a setpoint the node was slow to
            # acknowledge is resent, so what is lost is lost in the node's own queue (which
            # it counts); both players exist from the start so both discoveries overlap
            players[key] = Player(joints, topic=f'{namespace}/joint_setpoint',
                                  node_name=f'fig4_player_{key}', context=context,
                                  depth=len(t))
        for case in CASES:
            print(f'{case[2]}: {procs[case[0]].wait_started()}')
        for case in CASES:
            connect(players[case[0]], recorder, case[2])
        for case in CASES:
            efforts, found, account = run_case(players[case[0]], recorder, case, t, theta)
            exact = case[4] * exact_a
            accounts.append(account)
            results.append((case[0], case, efforts, found, exact,
                            statistics(t, efforts, found, exact)))
    finally:
        for player in players.values():
            player.destroy_node()
        if recorder is not None:
            recorder.close()
        context.try_shutdown()
        codes = {key: proc.stop() for key, proc in procs.items()}
    plot(args.output, t, results, args.rate)
    base = os.path.splitext(args.output)[0]
    for key, case, efforts, found, _, _ in results:
        trajectory_io.write_efforts(f'{base}_{key}.csv', t, efforts, found, case[3])

    print()
    print(f'Paper four-bar driven along its target motion at {args.rate:g} Hz over ROS 2 topics')
    print(f'(error = |published - exact| once {WARM_UP} consecutive setpoints came before; '
          f'criterion {TOLERANCE:.0%} of peak)')
    header = ('case', 'joint', 'received', 'peak |tau| N m', 'max error N m', 'rms error N m',
              'within 1%')
    print('  '.join(f'{h:>15s}' for h in header))
    ok = True
    for key, case, efforts, found, exact, stats in results:
        for joint, st in zip(case[3], stats):
            ok &= st['within']
            cells = (f'({key})', joint, f'{int(found.sum())}/{found.size}', f'{st["peak"]:.4f}',
                     f'{st["max_error"]:.2e}', f'{st["rms_error"]:.2e}',
                     'yes' if st['within'] else 'NO')
            print('  '.join(f'{c:>15s}' for c in cells))
    for account in accounts:
        node = ('no report from the node' if not account.reported else
                f'node answered {account.accepted}, rejected {account.rejected}, '
                f'counted {account.lost} lost')
        print(f'{account.where}: sent {account.sent}, {node}, recorded {account.recorded}')
    print(f'wrote {args.output} and {base}_a.csv, {base}_b.csv '
          f'in {time.monotonic() - started:.1f} s')
    for proc in procs.values():
        for line in proc.warnings():
            print(f'{proc.namespace}: {line}')
    if any(code != 0 for code in codes.values()):
        print(f'a node did not exit cleanly: {codes}', file=sys.stderr)
        ok = False
    # a setpoint without its recorded effort is a hole in the figure and the CSVs: never a
    # success, whichever side lost it
    losses = [f'{a.where}: {a.losses()}' for a in accounts if not a.complete]
    for line in losses:
        print(line, file=sys.stderr)
    if losses:
        return LOST
    return 0 if ok else 1


if __name__ == '__main__':
    sys.exit(main())
