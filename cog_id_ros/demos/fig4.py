"""The paper's Fig. 4 over real ROS 2 topics: torques of the four-bar (a) and (b).

    python -m cog_id_ros.demos.fig4 [--output out/fig4_torques.png] [--rate 1000]

What it does, end to end, as a user would:
  0. looks for another run of the demo (or nodes with its nodes' names) in its
     ROS_DOMAIN_ID, and refuses to start beside one (below);
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

Exit status:
  0  every setpoint answered and recorded, and every torque after the first samples within
     1 % of the peak;
  1  a torque is not, or a node did not exit cleanly;
  2  it did not run, or its data are not its own, with one line saying why: the config files
     are in none of the places looked in (listed), or another run of the demo (or nodes with
     its nodes' names, or other publishers of its topics) is in its ROS_DOMAIN_ID
     (``fig4: ROS_DOMAIN_ID 7 is in use by another run of this demo or nodes with its
     nodes' names (1 other node named /fig4_a/cog_id_node): ... Set another ROS_DOMAIN_ID
     ... or wait for the other run to end``). Two runs in one domain would each answer and
     record the other's setpoints. The demo looks before it starts its nodes (its players'
     names in the domain for LISTEN s), again before it plays, and after its runs (what its
     recording and its nodes saw: setpoints answered twice, efforts for setpoints it never
     sent); discovery can take seconds, so a run found only after playing ends with the
     figure and CSVs written and this line;
  3  a setpoint went unanswered or unrecorded, with one line per node saying where
     (``/fig4_a: node: 16 setpoints lost before the node took them``,
     ``/fig4_b: recorder: 343 efforts the node sent were not recorded``).

It uses ROS_DOMAIN_ID from the environment (or picks one from the process id when unset, and
says which), with discovery limited to this machine.
"""
import argparse
import collections
import math
import os
import re
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
REFUSED = 2                       # exit status: did not run (no config files, domain in use)
#: s the demo's players' names are in its ROS_DOMAIN_ID before it starts its nodes, looking
#: for another run (look_around). Discovery is not instant: against a running demo (four
#: participants) a fresh one here saw the first of them after 0-1.5 s (within 1 s in 8 of 10
#: tries) and all of them after 0.1-3 s (Fast DDS announces a participant every 3 s). What
#: is seen late is caught before playing or after the runs (others_in_domain,
#: mixed_answers), with the same exit status
LISTEN = 1.0
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
        """The node's line naming its mechanism once it is up (other lines may come first:
        rcl's warning that ROS_LOCALHOST_ONLY is deprecated); raises if it is not."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            started = next((line for line in list(self.lines) if "mechanism '" in line), None)
            if started is not None:
                return started
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


#: the nodes' max_setpoint_age (s): a setpoint answered this late still counts
LATE_ANSWERS = 60.0


def node_arguments(n_setpoints):
    """ROS arguments of the node in ``namespace`` for a run of ``n_setpoints``: returns
    ``namespace -> [arguments]``."""
    def extra(namespace):
        # Both queues of the node hold the whole run (at most the node's bound on depths).
        # joint_effort's writer: a reliable writer resends only what its history still
        # holds, so with the default 100 a recorder stalled for 0.1 s at 1 kHz would lose
        # efforts for good. joint_setpoint's subscription: the default 100 is 0.1-0.2 s of
        # this stream, and a node starved of CPU that long (a loaded 2-core machine: 77 of
        # 1001 lost in one CI run) would drop setpoints the figure needs; with the whole
        # run queued it answers them late instead. A controller wants the opposite (drop
        # stale setpoints, the node's default); the demo wants every one, and so answers
        # late ones too (max_setpoint_age: a node stalled 0.4 s out of every 0.6 s fell
        # 0.6 s behind; the torques follow the stamps, not the arrival).
        depth = min(n_setpoints, MAX_QOS_DEPTH)
        return ['-p', f'diagnostics_period:={DIAGNOSTICS_PERIOD}',
                '-p', f'max_setpoint_age:={LATE_ANSWERS}',
                '-p', f'qos_overrides.{namespace}/joint_setpoint.subscription.depth:={depth}',
                '-p', f'qos_overrides.{namespace}/joint_effort.publisher.depth:={depth}']
    return extra


def node_name(name, namespace):
    """The fully qualified name of a node of the graph."""
    return f"{namespace.rstrip('/')}/{name}"


def others_in_domain(graph, running):
    """What in the domain would mix its data with the demo's: one clause each, [] when none.

    ``graph``: a node of the demo (its participant's view of the domain). ``running``: the
    demo's cog_id_node processes are up and its players publish (they are then counted as
    its own); else only the players' names are the demo's (:func:`look_around`). Another
    node named as one of the demo's (``/fig4_a/cog_id_node``, the players
    ``/fig4_player_a``, ...: another run of the demo has them all), another publisher of
    the setpoints (its setpoints would reach the demo's nodes) or of the efforts (its
    efforts would be recorded as the demo's nodes' answers). Subscribers are not counted:
    one that only listens (``ros2 topic echo``) changes nothing.
    """
    own = 1 if running else 0
    names = collections.Counter(node_name(name, namespace)
                                for name, namespace in graph.get_node_names_and_namespaces())
    expected = {}
    for key, _, namespace, _, _ in CASES:
        expected[f'/fig4_player_{key}'] = 1
        expected[f'{namespace}/cog_id_node'] = own
    found = [f'{names[name] - count} other node{"s" if names[name] - count > 1 else ""} '
             f'named {name}' for name, count in expected.items() if names[name] > count]
    for _, _, namespace, _, _ in CASES:
        for topic in (f'{namespace}/joint_setpoint', f'{namespace}/joint_effort'):
            extra = graph.count_publishers(topic) - own
            if extra > 0:
                found.append(f'{extra} other publisher{"s" if extra > 1 else ""} of {topic}')
    return found


#: the node's warning when it sees others with its name (ros/diagnostics.py)
SAME_NAME = re.compile(r'(\d+) nodes named (\S+) in the ROS graph')


def same_name_nodes(procs):
    """What the demo's nodes said so far of others with their names, one clause per node:
    each watches the graph from its start, so it may see another run before the players
    do."""
    found = []
    for proc in procs.values():
        seen = [match for line in list(proc.lines) if (match := SAME_NAME.search(line))]
        if seen:
            count, name = max(seen, key=lambda m: int(m[1])).groups()
            found.append(f'{name} saw {count} nodes with its name')
    return found


def look_around(seconds):
    """:func:`others_in_domain` before the demo starts anything: its players' names join the
    domain for ``seconds`` (so that another run starting meanwhile sees this one) and leave.

    A participant of its own, gone before the nodes start: the players' participant is
    created after the nodes, as a newcomer discovers the participants already there at
    once, while a participant that is there first discovered the nodes 2-2.6 s late in
    most tries here (0.4 s in the other order).
    """
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    context = rclpy.Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    nodes = []
    try:
        nodes = [rclpy.create_node(f'fig4_player_{case[0]}', context=context)
                 for case in CASES]
        time.sleep(seconds)            # DDS's own threads keep the graph up to date
        return others_in_domain(nodes[0], running=False)
    finally:
        for node in nodes:
            node.destroy_node()
        context.try_shutdown()


def refusal(others, domain, during=False):
    """The one line the demo says when its domain is in use (``others``: others_in_domain);
    ``during``: found only once the run was over (mixed_answers, or late discovery)."""
    try:
        example = f' (e.g. ROS_DOMAIN_ID={int(domain) % 101 + 1} ./dev run)'
    except ValueError:
        example = ''
    what = ('the efforts above are mixed with theirs' if during else
            "their data would mix with this run's")
    if len(others) > 4:            # one line that still reads as one
        others = others[:3] + [f'and {len(others) - 3} more']
    return (f'fig4: ROS_DOMAIN_ID {domain} is in use by another run of this demo or nodes '
            f"with its nodes' names ({'; '.join(others)}): {what}. Set another "
            f'ROS_DOMAIN_ID{example} or wait for the other run to end')


def connect(player, recorder, namespace):
    """Wait until the player's setpoints reach the node and the node's efforts the
    recorder, both as far as matching can tell (see Recorder.answer_first for the rest)."""
    if not player.wait_for_subscriber(30.0):
        raise RuntimeError(f'no cog_id_node subscribes to {namespace}/joint_setpoint')
    if not recorder.wait_matched([f'{namespace}/joint_effort'], 30.0):
        raise RuntimeError(f'the recorder does not receive {namespace}/joint_effort')


def run_case(player, recorder, case, t, theta):
    """Play the target motion into one node; returns the recorded efforts, which setpoints
    have one, the run's :class:`~cog_id_ros.ros.recorder.Account` and the setpoints' stamps."""
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
    return efforts, found, result, stamps


def mixed_answers(recorder, stamps):
    """What the recording shows of another run in the domain (``stamps``: effort topic ->
    the stamps of the setpoints this run sent there): one clause per topic, [] when none.
    A node answers a stamp once (a repeated one is rejected), so an effort for a setpoint
    this run never sent came from another player's setpoint, and a setpoint answered twice
    from another node."""
    found = []
    for topic, sent in stamps.items():
        received, messages = recorder.efforts(topic)
        foreign = len(received.keys() - set(sent))
        twice = messages - len(received)
        if foreign:
            found.append(f'{topic}: {foreign} efforts for setpoints this run never sent')
        if twice > 0:
            found.append(f'{topic}: {twice} setpoints answered twice')
    return found


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


def build_parser():
    parser = argparse.ArgumentParser(prog='python -m cog_id_ros.demos.fig4',
                                     description=__doc__.split('\n\n')[0])
    parser.add_argument('--output', default=os.path.join('out', 'fig4_torques.png'),
                        help='PNG to write (default %(default)s); CSVs go beside it')
    parser.add_argument('--rate', type=float, default=1000.0,
                        help='setpoints per second (default %(default)s)')
    return parser


def ros_environment():
    """The environment of the nodes (and of this process's own ROS 2 participants): the
    ROS_DOMAIN_ID given, or one picked from the process id (said); discovery on this
    machine only."""
    env = dict(os.environ)
    if not env.get('ROS_DOMAIN_ID'):
        env['ROS_DOMAIN_ID'] = str(1 + os.getpid() % 101)
        print(f'ROS_DOMAIN_ID not set: using {env["ROS_DOMAIN_ID"]}')
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    env['PYTHONUNBUFFERED'] = '1'
    os.environ.update({k: env[k] for k in ('ROS_DOMAIN_ID', 'ROS_AUTOMATIC_DISCOVERY_RANGE')})
    return env


def run_cases(procs, t):
    """Play the target motion into every node once it is up and connected: returns the
    results per case ``(key, case, efforts, found, exact, statistics)``, the runs'
    accounts, the nodes' exit statuses (each stopped like Ctrl-C, whatever happened), and
    the other runs or nodes found in the domain before playing or during the runs (nothing
    is played, and no result returned, when found before)."""
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
    others = []
    try:
        # one effort per setpoint at most: a queue of len(t) never pushes one out
        recorder = recording.Recorder([f'{case[2]}/joint_effort' for case in CASES], len(t))
        for key, _, namespace, joints, _ in CASES:
            # the publisher's history holds the whole run, as the node's queue does: a
            # setpoint the node was slow to acknowledge is resent, and what the node still
            # lost it counts; both players exist from the start so both discoveries overlap
            players[key] = Player(joints, topic=f'{namespace}/joint_setpoint',
                                  node_name=f'fig4_player_{key}', context=context,
                                  depth=len(t))
        for case in CASES:
            print(f'{case[2]}: {procs[case[0]].wait_started()}')
        for case in CASES:
            connect(players[case[0]], recorder, case[2])
        others = others_in_domain(players['a'], running=True) + same_name_nodes(procs)
        if others:
            return results, accounts, {}, others
        stamps = {}
        for case in CASES:
            efforts, found, account, stamps[f'{case[2]}/joint_effort'] = run_case(
                players[case[0]], recorder, case, t, theta)
            exact = case[4] * exact_a
            accounts.append(account)
            results.append((case[0], case, efforts, found, exact,
                            statistics(t, efforts, found, exact)))
        # what joined the domain during the runs (discovery may have been late), or left a
        # trace in the recording before it left
        others = (others_in_domain(players['a'], running=True) + same_name_nodes(procs)
                  + mixed_answers(recorder, stamps))
    finally:
        for player in players.values():
            player.destroy_node()
        if recorder is not None:
            recorder.close()
        context.try_shutdown()
        codes = {key: proc.stop() for key, proc in procs.items()}
    return results, accounts, codes, others


def print_table(rate, results, accounts):
    """The summary table and, per node, where its setpoints went; whether every torque is
    within TOLERANCE."""
    print()
    print(f'Paper four-bar driven along its target motion at {rate:g} Hz over ROS 2 topics')
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
    return ok


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        cfg = config_dir()
    except ConfigNotFound as exc:
        print(f'fig4: {exc}', file=sys.stderr)
        return REFUSED
    env = ros_environment()
    started = time.monotonic()
    t = np.arange(int(round(DURATION * args.rate)) + 1) / args.rate
    # another run in this domain (or nodes with these names) would answer this run's
    # setpoints and publish on its topics: refuse before starting a node that would disturb
    # it in turn; look again before playing, and after (discovery can take seconds)
    others = look_around(LISTEN)
    if others:
        print(refusal(others, env['ROS_DOMAIN_ID']), file=sys.stderr)
        return REFUSED
    extra = node_arguments(len(t))
    procs = {case[0]: NodeProcess(os.path.join(cfg, case[1]), case[2], env, extra(case[2]))
             for case in CASES}
    results, accounts, codes, others = run_cases(procs, t)
    if others and not results:
        print(refusal(others, env['ROS_DOMAIN_ID']), file=sys.stderr)
        return REFUSED
    plot(args.output, t, results, args.rate)
    base = os.path.splitext(args.output)[0]
    for key, case, efforts, found, _, _ in results:
        trajectory_io.write_efforts(f'{base}_{key}.csv', t, efforts, found, case[3])
    ok = print_table(args.rate, results, accounts)
    print(f'wrote {args.output} and {base}_a.csv, {base}_b.csv '
          f'in {time.monotonic() - started:.1f} s')
    for proc in procs.values():
        for line in proc.warnings():
            print(f'{proc.namespace}: {line}')
    if any(code != 0 for code in codes.values()):
        print(f'a node did not exit cleanly: {codes}', file=sys.stderr)
        ok = False
    if others:
        # the counts and losses above are two runs' together: none of them says where this
        # run's setpoints went
        print(refusal(others, env['ROS_DOMAIN_ID'], during=True), file=sys.stderr)
        return REFUSED
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
