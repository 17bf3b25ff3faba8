"""The node's tools as a user runs them: cog_id_player on a CSV, and the Fig. 4 demo."""
import os
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip('rclpy')

from conftest import BIN  # noqa: E402

from cog_id_ros.offline import trajectory_io  # noqa: E402


def exact_a(theta, thetaddot):
    return (5.0 / 3.0) * 0.25 * thetaddot + 9.81 * np.cos(theta)


def test_player_plays_a_csv_and_records_the_efforts(ros_process, ros_env, tmp_path):
    """A 100 Hz CSV (positions and velocities) resampled to 1 kHz; efforts recorded to CSV.
    The node queues the whole recording, as node.md tells users to on a busy machine (the
    suite runs in two workers: 0.1 s without CPU would drop setpoints from the default 100)."""
    node = ros_process(['cog_id_node', '--ros-args', '--params-file',
                        'config/paper_four_bar_a.yaml', '-r', '__ns:=/player_test',
                        '-p', 'qos_overrides./player_test/joint_setpoint.subscription.depth:=400'])
    assert node.wait_for_output("mechanism '"), node.output
    t = np.arange(0.0, 0.3001, 0.01)
    theta = np.pi / 2 + 0.5 * np.sin(np.pi * t)
    thetadot = 0.5 * np.pi * np.cos(np.pi * t)
    csv = tmp_path / 'motion.csv'
    csv.write_text('time,joint3.position,joint3.velocity,label\n' + ''.join(
        f'{a!r},{b!r},{c!r},x\n' for a, b, c in zip(t.tolist(), theta.tolist(), thetadot.tolist())))
    out = tmp_path / 'efforts.csv'
    result = subprocess.run(
        [f'{BIN}/cog_id_player', '--input', str(csv), '--rate', '1000', '--output', str(out),
         '--ros-args', '-r', '__ns:=/player_test'],
        env=ros_env, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert 'playing 301 setpoints of joint3' in result.stderr
    header, time, efforts = trajectory_io.read_efforts(out)
    assert header == ['time', 'joint3.effort']
    np.testing.assert_allclose(time, np.arange(301) / 1000.0 + 0.0, atol=1e-12)
    ok = ~np.isnan(efforts[:, 0])
    assert ok.sum() >= 270
    th = np.pi / 2 + 0.5 * np.sin(np.pi * time)
    exact = exact_a(th, -0.5 * np.pi ** 2 * np.sin(np.pi * time))
    # the spline through 100 Hz samples is not the sine: a few per mille of the peak
    assert np.abs(efforts[ok, 0][5:] - exact[ok][5:]).max() < 0.01 * 6.76


def test_player_without_a_node_says_so(ros_env, tmp_path):
    csv = tmp_path / 'motion.csv'
    csv.write_text('time,joint3.position\n0.0,1.0\n0.1,1.1\n')
    result = subprocess.run(
        [f'{BIN}/cog_id_player', '--input', str(csv), '--wait', '1',
         '--ros-args', '-r', '__ns:=/nobody_here'],
        env=ros_env, capture_output=True, text=True, timeout=60)
    assert result.returncode == 1
    assert 'nothing subscribes to /nobody_here/joint_setpoint' in result.stderr


def test_player_rejects_a_bad_csv(ros_env, tmp_path):
    csv = tmp_path / 'motion.csv'
    csv.write_text('time,joint3.position\n0.0,1.0\n0.0,1.1\n')
    result = subprocess.run([f'{BIN}/cog_id_player', '--input', str(csv)], env=ros_env,
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 2
    assert 'does not increase strictly' in result.stderr


def test_fig4_demo_writes_the_figure_and_the_efforts(ros_env, tmp_path):
    png = tmp_path / 'fig4.png'
    result = subprocess.run([sys.executable, '-m', 'cog_id_ros.demos.fig4', '--output', str(png),
                             '--rate', '500'], env=ros_env, capture_output=True, text=True,
                            timeout=180)
    assert result.returncode == 0, result.stdout + result.stderr
    assert png.stat().st_size > 20_000
    with open(png, 'rb') as f:
        assert f.read(8) == b'\x89PNG\r\n\x1a\n'
    for key, joints in (('a', ['joint3']), ('b', ['joint1', 'joint3'])):
        header, time, efforts = trajectory_io.read_efforts(tmp_path / f'fig4_{key}.csv')
        assert header == ['time'] + [f'{j}.effort' for j in joints]
        assert len(time) == 1001
    lines = result.stdout.splitlines()
    rows = [line.split() for line in lines if line.strip().startswith(('(a)', '(b)'))]
    assert [r[:2] for r in rows] == [['(a)', 'joint3'], ['(b)', 'joint1'], ['(b)', 'joint3']]
    assert all(r[-1] == 'yes' for r in rows)
    assert os.path.basename(str(png)) in result.stdout


def test_dev_without_a_command_prints_its_usage():
    """Reliability item 25: ./dev with no argument printed lines of its own shell code
    (and exit status 2); now a usage text and exit status 0, an unknown command exit 2."""
    repo = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    result = subprocess.run([os.path.join(repo, 'dev')], capture_output=True, text=True,
                            timeout=30)
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith('usage: ./dev')
    assert 'set -euo' not in result.stdout and 'here=' not in result.stdout
    result = subprocess.run([os.path.join(repo, 'dev'), 'bogus'], capture_output=True,
                            text=True, timeout=30)
    assert result.returncode == 2 and "unknown command 'bogus'" in result.stderr
