"""The Fig. 4 demo and cog_id_player: every setpoint answered and recorded, or a non-zero exit
that says where they went (the issue "Reliability 2", item 13).

The demo runs as a user runs it (``python -m cog_id_ros.demos.fig4`` from this checkout);
losses are forced by stopping a process with SIGSTOP for a while, the way a loaded machine
stops it, only longer. The CPU hogs and stopped processes are this test's own children
and always ended.
"""
import contextlib
import os
import re
import signal
import subprocess
import sys
import threading

import numpy as np
import pytest

pytest.importorskip('rclpy')

from conftest import BIN, REPO  # noqa: E402

from cog_id_ros.offline import trajectory_io  # noqa: E402
from cog_id_ros.ros.recorder import Account, account  # noqa: E402

ACCOUNT_LINE = re.compile(r'^(/fig4_[ab]): sent (\d+), node answered (\d+), rejected (\d+), '
                          r'counted (\d+) lost, recorded (\d+)$', re.M)


# --- the account: where missing setpoints went (no ROS) ---------------------------------------

def test_account_places_every_missing_setpoint():
    """Reliability 2, item 13: the three numbers (sent, the node's counters, recorded) say
    whether the node or the recorder lost a setpoint; the places add up to what is missing."""
    full = account('/a', 2001, 2001, None, {'setpoints_accepted': 2001,
                                            'setpoints_rejected': 0, 'setpoints_lost': 0})
    assert full.complete and full.losses() == ''
    # the node's counters run since its start: a report before the run is subtracted
    before = {'setpoints_accepted': 50, 'setpoints_rejected': 2, 'setpoints_lost': 1}
    after = {'setpoints_accepted': 50 + 1640, 'setpoints_rejected': 2 + 3,
             'setpoints_lost': 1 + 16}
    mixed = account('/a', 2001, 1297, before, after)
    assert (mixed.accepted, mixed.rejected, mixed.lost) == (1640, 3, 16)
    assert not mixed.complete
    text = mixed.losses()
    assert 'node: 16 setpoints lost before the node took them' in text
    # the way out, with this run's numbers (the topic is the player's, when it says it)
    assert 'qos_overrides./<namespace>/joint_setpoint.subscription.depth:=2001' in text
    mixed.setpoint_topic = '/arm/joint_setpoint'
    assert 'qos_overrides./arm/joint_setpoint.subscription.depth:=2001' in mixed.losses()
    assert 'node: 3 setpoints rejected' in text
    assert 'node: 342 setpoints never reached the node' in text       # 2001 - 1640 - 3 - 16
    assert 'recorder: 343 efforts the node sent were not recorded' in text
    assert 16 + 3 + 342 + 343 == 2001 - 1297
    # no report from the node: the loss is still a loss, its place unknown
    blind = account('/a', 2001, 1990, None, None)
    assert not blind.complete and '11 of 2001 setpoints have no recorded effort' in blind.losses()
    # counters that do not add up are not guessed into a place
    odd = Account('/a', 2001, 1990, accepted=2005, rejected=0, lost=0)
    assert 'do not tell where' in odd.losses()
    # a full recording with a node that says it dropped some is not complete either
    assert not Account('/a', 2001, 2001, accepted=2001, rejected=0, lost=3).complete


# --- helpers: children of a process, pausing one, CPU hogs ------------------------------------

def children(pid):
    """The pids of ``pid``'s children (Linux /proc)."""
    found = []
    with contextlib.suppress(OSError):
        for task in os.listdir(f'/proc/{pid}/task'):
            with contextlib.suppress(OSError), open(f'/proc/{pid}/task/{task}/children') as f:
                found += [int(c) for c in f.read().split()]
    return found


def cmdline(pid):
    with contextlib.suppress(OSError), open(f'/proc/{pid}/cmdline', 'rb') as f:
        return f.read().replace(b'\0', b' ').decode(errors='replace')
    return ''


@contextlib.contextmanager
def stalling(find_pid, stopped=0.4, running=0.2):
    """While the block runs: the process ``find_pid()`` returns (polled until it exists) is
    stopped ``stopped`` s out of every ``stopped + running`` s, like a process starved by the
    scheduler. Yields a list that gets the pid once found; always continued at the end."""
    done = threading.Event()
    found = []

    def stall():
        while not done.is_set() and not found:
            pid = find_pid()
            if pid:
                found.append(pid)
            done.wait(0.01)
        while not done.is_set():
            try:
                os.kill(found[0], signal.SIGSTOP)
                done.wait(stopped)
                os.kill(found[0], signal.SIGCONT)
            except ProcessLookupError:
                return
            done.wait(running)

    thread = threading.Thread(target=stall, daemon=True)
    thread.start()
    try:
        yield found
    finally:
        done.set()
        thread.join(timeout=5)
        for pid in found:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGCONT)


@contextlib.contextmanager
def cpu_hogs(per_core=2):
    """``per_core`` busy Python processes per core (the issue's load 4-7 on 2 cores)."""
    hogs = [subprocess.Popen([sys.executable, '-c', 'while True: pass'])
            for _ in range(per_core * (os.cpu_count() or 1))]
    try:
        yield
    finally:
        for hog in hogs:
            hog.kill()
            hog.wait()


def run_fig4(env, output, timeout=240):
    return subprocess.Popen([sys.executable, '-m', 'cog_id_ros.demos.fig4', '--output',
                             str(output)], cwd=REPO, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def missing_in_csv(path):
    """Rows of an efforts CSV without an effort."""
    _, _, efforts = trajectory_io.read_efforts(path)
    return int(np.isnan(efforts).any(axis=1).sum())


def check_demo_result(returncode, stdout, stderr, tmp_path):
    """The demo's rule: exit 0 only with every effort recorded; otherwise exit 3 and one line
    per node with losses, placing every missing setpoint. Returns {namespace: missing}."""
    output = stdout + stderr
    missing = {ns: missing_in_csv(tmp_path / f'fig4_{ns[-1]}.csv') for ns in ('/fig4_a',
                                                                             '/fig4_b')}
    if returncode == 0:
        assert missing == {'/fig4_a': 0, '/fig4_b': 0}, output
        rows = [line.split() for line in stdout.splitlines()
                if line.strip().startswith(('(a)', '(b)'))]
        assert [r[2] for r in rows] == ['2001/2001'] * 3, output
        return missing
    assert returncode == 3, output
    accounts = {m[0]: tuple(int(x) for x in m[1:]) for m in ACCOUNT_LINE.findall(stdout)}
    assert set(accounts) == {'/fig4_a', '/fig4_b'}, output
    for ns, (sent, accepted, rejected, lost, recorded) in accounts.items():
        assert sent == 2001 and sent - recorded == missing[ns], output
        lines = [line for line in stderr.splitlines() if line.startswith(f'{ns}: ')]
        if not missing[ns]:
            assert not lines, output
            continue
        assert len(lines) == 1, output
        # every missing setpoint is placed: the numbers of the line add up to them
        placed = sum(int(n) for n in re.findall(r'(?:node|recorder): (\d+) ', lines[0]))
        assert placed == missing[ns], output
    assert any(missing.values()), output
    return missing


# --- the demo under load, and with a stalled node -----------------------------------------------

def test_fig4_under_load_answers_and_records_every_setpoint(ros_env, tmp_path):
    """Reliability 2, item 13: on a loaded machine the demo lost up to 343 of 2001 setpoints
    and exited 0; then it exited 3 saying where (the node's own queue of 100). Since the
    demo gives the node's setpoint queue the whole run (a CI run of the suite in two
    workers lost 77 of 1001 there), two busy processes per core beside it change nothing:
    2001/2001 of both nodes recorded, exit 0."""
    with cpu_hogs():
        proc = run_fig4(ros_env, tmp_path / 'fig4.png')
        stdout, stderr = proc.communicate(timeout=240)
    assert proc.returncode == 0, stdout + stderr
    check_demo_result(proc.returncode, stdout, stderr, tmp_path)


def test_fig4_with_a_stalled_node_still_answers_every_setpoint(ros_env, tmp_path):
    """Node (b) stopped 0.4 s out of every 0.6 s: with the node's default queue (100
    setpoints) it dropped setpoints and the demo exited 3 (Reliability 2, item 13). The
    demo now starts its nodes with a setpoint queue as deep as the run: the stalled node
    answers late, every setpoint is answered and recorded, exit 0."""
    proc = run_fig4(ros_env, tmp_path / 'fig4.png')

    def node_b():
        return next((c for c in children(proc.pid) if '__ns:=/fig4_b' in cmdline(c)), None)

    with stalling(node_b) as found:
        stdout, stderr = proc.communicate(timeout=240)
    assert found, 'node (b) was never found to stall'
    assert proc.returncode == 0, stdout + stderr
    check_demo_result(proc.returncode, stdout, stderr, tmp_path)


def test_fig4_with_a_stalled_recorder_exits_non_zero_and_names_the_recorder(
        ros_env, tmp_path, monkeypatch, capsys):
    """Reliability 2, item 13: a recorder that falls behind (its queue cut to one message and
    its process stopped 0.4 s out of every 0.6 s while (a) plays) loses efforts the node
    sent; the demo exits 3 and the line of /fig4_a says the recorder lost them."""
    from cog_id_ros.demos import fig4
    from cog_id_ros.ros import recorder as recording

    stall = contextlib.ExitStack()

    class FallingBehind(recording.Recorder):
        def __init__(self, topics, depth, **kwargs):
            super().__init__(topics, 1, **kwargs)

        def first_report(self, name, timeout=30.0):
            # called just before a node's run starts: stall during (a)'s run only
            stall.close()
            if name.startswith('/fig4_a/'):
                stall.enter_context(stalling(lambda: self.pid))
            return super().first_report(name, timeout)

        def settle(self, *args, **kwargs):
            stall.close()
            return super().settle(*args, **kwargs)

    monkeypatch.setattr(recording, 'Recorder', FallingBehind)
    try:
        code = fig4.main(['--output', str(tmp_path / 'fig4.png')])
    finally:
        stall.close()
    out = capsys.readouterr()
    missing = check_demo_result(code, out.out, out.err, tmp_path)
    assert code == 3 and missing['/fig4_a'] > 0, out.out + out.err
    # (under load the node may lose setpoints too: its part comes first on the line)
    assert re.search(r'^/fig4_a: (node: .*; )?recorder: \d+ efforts the node sent were not '
                     r'recorded$',
                     out.err, re.M), out.err


# --- cog_id_player: the same rule ---------------------------------------------------------------

def test_player_with_a_stalled_node_exits_non_zero_and_names_the_node(ros_process, ros_env,
                                                                       tmp_path):
    """Reliability 2, item 13: cog_id_player --output wrote what came back and exited 0
    whatever was missing. Now, with the node stopped 0.4 s out of every 0.6 s: the CSV is
    written with its empty cells, exit 3, and a line says the node lost the setpoints."""
    node = ros_process(['cog_id_node', '--ros-args', '--params-file',
                        'config/paper_four_bar_a.yaml', '-r', '__ns:=/player_stall',
                        '-p', 'diagnostics_period:=0.2'])
    assert node.wait_for_output("mechanism '"), node.output
    out = tmp_path / 'efforts.csv'
    with stalling(lambda: node.proc.pid):
        result = subprocess.run(
            [f'{BIN}/cog_id_player', '--input', 'config/paper_four_bar_target.csv',
             '--output', str(out), '--ros-args', '-r', '__ns:=/player_stall'],
            cwd=REPO, env=ros_env, capture_output=True, text=True, timeout=120)
    assert result.returncode == 3, result.stderr
    missing = missing_in_csv(out)
    assert missing > 0
    assert f'{2001 - missing} of 2001 efforts recorded' in result.stderr
    line = re.search(r'^cog_id_player: cog_id_node: (node: .*)$', result.stderr, re.M)
    assert line and 'lost before the node took them' in line[1], result.stderr
    assert sum(int(n) for n in re.findall(r'(?:node|recorder): (\d+) ', line[1])) == missing
