"""cog_id_torques followed by cog_id_simulate reproduces the motion, on every example config,
to the error of the hold: first order in the step with the contract's hold (each row's effort
from its own time on: half a step late), second order with ``--between-rows linear``; every
joint's output checked against the position solver and its own finite differences; the
initial state rules; Ctrl-C leaves no output.
"""
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from trajectories import TRAJECTORIES, config_path

import cog_id_ros
from cog_id_ros.offline import cli, simulate
from cog_id_ros.offline import trajectory_io as tio

#: the motions are replayed over this long (s): long enough for thousands of steps' error to
#: add up, short enough that no example's open-loop instability amplifies it much
HORIZON = 0.2
STEP = 0.002
CONFIGS = sorted(TRAJECTORIES)


def write_motion(path, t, joints, q, qd, qdd):
    columns = {'time': t}
    for k, joint in enumerate(joints):
        columns.update({f'{joint}.position': q[:, k], f'{joint}.velocity': qd[:, k],
                        f'{joint}.acceleration': qdd[:, k]})
    names = list(columns)
    cols = [list(map(repr, np.asarray(columns[n], float).tolist())) for n in names]
    path.write_text(','.join(names) + '\n' + '\n'.join(map(','.join, zip(*cols))) + '\n')
    return path


def run(capsys, module, *args):
    status = module.main([str(a) for a in args])
    out, err = capsys.readouterr()
    assert status == 0, err
    return out, err


def read_motion(path):
    header, t, values = tio.read_efforts(path)
    return header, t, values


def replay(tmp_path, capsys, name, h, between):
    """(times, the simulated motion (header, values), the mechanism, the target's active q)."""
    mech = cog_id_ros.Mechanism.from_params_file(config_path(name))
    t = np.round(np.arange(0.0, HORIZON + h / 2, h), 12)
    q, qd, qdd = TRAJECTORIES[name](t)
    traj = write_motion(tmp_path / f'traj_{h}.csv', t, mech.active_joints, q, qd, qdd)
    efforts = tmp_path / f'efforts_{h}.csv'
    if mech.floating_base:
        # cog_id_torques answers a floating robot's whole-body efforts from its base columns
        # (test_floating_base_csv.py); cog_id_simulate holds the base fixed
        # (docs/floating_base.md), so its efforts are the fixed-base torques, which
        # cog_id_torques writes for a fixed base (test_cli.py: equal to the core's)
        tio.write_efforts(efforts, t, cog_id_ros.InverseDynamics(mech).torques(q, qd, qdd),
                          None, mech.active_joints)
    else:
        run(capsys, cli, '--params-file', config_path(name), '--input', traj,
            '--output', efforts)
    motion = tmp_path / f'motion_{h}_{between}.csv'
    run(capsys, simulate, '--params-file', config_path(name), '--input', efforts,
        '--initial-state', traj, '--output', motion, '--time-step', repr(h),
        '--between-rows', between)
    header, t_out, values = read_motion(motion)
    np.testing.assert_allclose(t_out, t, rtol=0, atol=1e-12)
    return header, values, mech, q


def active_error(header, values, mech, q):
    cols = [header.index(f'{j}.position') - 1 for j in mech.active_joints]
    return float(np.abs(values[:, cols] - q).max())


@pytest.mark.parametrize('name', CONFIGS)
def test_torques_then_simulate_reproduce_the_motion_to_the_error_of_the_hold(tmp_path, capsys,
                                                                            name):
    """Halving the step (and the rows' spacing) halves the error of the contract's hold and
    quarters that of --between-rows linear: the motion is reproduced up to the hold's
    truncation error, which vanishes with the step (a wrong hold rule, initial state or
    effort would leave an error that does not)."""
    errors = {}
    for h in (STEP, STEP / 2):
        for between in ('hold', 'linear'):
            header, values, mech, q = replay(tmp_path, capsys, name, h, between)
            errors[h, between] = active_error(header, values, mech, q)
    span = float(np.ptp(TRAJECTORIES[name](np.linspace(0, HORIZON, 50))[0], axis=0).max())
    hold = errors[STEP / 2, 'hold'] / errors[STEP, 'hold']
    linear = errors[STEP / 2, 'linear'] / errors[STEP, 'linear']
    assert 0.45 < hold < 0.55, (errors, hold)           # 0.4986 .. 0.5055 on the examples
    assert 0.22 < linear < 0.28, (errors, linear)       # 0.24999 .. 0.25001
    # and small: the hold's lag of half a step costs at most 2 % of the motion's range in
    # 0.2 s (1.1 % at most on the examples), the line's mean 1/20 of that (1/40 at most)
    assert errors[STEP, 'hold'] < 0.02 * span, errors
    assert errors[STEP, 'linear'] < 0.05 * errors[STEP, 'hold'], errors


@pytest.mark.parametrize('name', ['five_bar.yaml', 'stewart_6ups_spherical.yaml',
                                  'paper_four_bar_b.yaml'])
def test_every_joint_of_the_output_is_closed_and_its_velocity_is_its_rate(tmp_path, capsys,
                                                                          name):
    """The passive joints of the output are where the position solver puts them for the
    active ones (the loops closed), and every velocity column is the rate of its position
    column (central differences, second order)."""
    h = STEP / 2
    header, values, mech, _ = replay(tmp_path, capsys, name, h, 'linear')
    assert header == ['time'] + [f'{j}.{f}' for j in mech.joints
                                 for f in ('position', 'velocity')]
    pos = values[:, 0::2]
    vel = values[:, 1::2]
    active = [list(mech.joints).index(j) for j in mech.active_joints]
    solved = cog_id_ros.InverseDynamics(mech).solve_positions(pos[:, active])
    np.testing.assert_allclose(pos, solved, rtol=0, atol=1e-8)
    rate = (pos[2:] - pos[:-2]) / (2 * h)
    scale = np.abs(vel).max()
    np.testing.assert_allclose(vel[1:-1], rate, rtol=0, atol=1e-3 * scale)


# --- the initial state ------------------------------------------------------------------------

PARAMS_A = config_path('paper_four_bar_a.yaml')
PARAMS_B = config_path('paper_four_bar_b.yaml')


def efforts(tmp_path, extra=None, rows=3):
    columns = {'time': [0.001 * k for k in range(rows)], 'joint3.effort': [0.0] * rows}
    columns.update(extra or {})
    names = list(columns)
    text = ','.join(names) + '\n' + '\n'.join(
        ','.join(repr(float(columns[n][k])) for n in names) for k in range(rows)) + '\n'
    path = tmp_path / 'efforts.csv'
    path.write_text(text)
    return path


def first_row(tmp_path, capsys, params, src, *options):
    out, err = run(capsys, simulate, '--params-file', params, '--input', src, '--output',
                   tmp_path / 'm.csv', *options)
    header, _, values = read_motion(tmp_path / 'm.csv')
    return dict(zip(header[1:], values[0])), out


def test_without_state_columns_the_motion_starts_at_initial_positions_at_rest(tmp_path,
                                                                              capsys):
    mech = cog_id_ros.Mechanism.from_params_file(PARAMS_A)
    row, out = first_row(tmp_path, capsys, PARAMS_A, efforts(tmp_path))
    for joint, q in zip(mech.joints, mech.assembled_positions):
        assert row[f'{joint}.position'] == pytest.approx(q, abs=1e-12)
        assert row[f'{joint}.velocity'] == 0.0
    assert 'initial state: initial_positions, at rest' in out


def test_the_first_rows_positions_and_velocities_are_the_initial_state(tmp_path, capsys):
    src = efforts(tmp_path, {'joint3.position': [1.2, 9.0, 9.0],
                             'joint3.velocity': [0.5, 9.0, 9.0]})
    row, out = first_row(tmp_path, capsys, PARAMS_A, src)
    assert row['joint3.position'] == 1.2 and row['joint3.velocity'] == 0.5
    # the other rows' cells are not read: empty is fine
    src.write_text(src.read_text().replace(',9.0,9.0\n', ',,\n'))
    assert ',,' in src.read_text()
    row, out = first_row(tmp_path, capsys, PARAMS_A, src)
    assert row['joint3.position'] == 1.2 and row['joint3.velocity'] == 0.5
    # the parallelogram: joint1 follows joint3, the coupler stays horizontal
    assert row['joint1.position'] == pytest.approx(1.2, abs=1e-12)
    assert row['joint1.velocity'] == pytest.approx(0.5, abs=1e-12)
    assert 'positions and velocities of row 1 of efforts.csv' in out
    # velocities alone: positions initial_positions
    src = efforts(tmp_path, {'joint3.velocity': [0.5, 0.0, 0.0]})
    row, out = first_row(tmp_path, capsys, PARAMS_A, src)
    assert row['joint3.position'] == pytest.approx(np.pi / 2, abs=1e-12)
    assert row['joint3.velocity'] == 0.5
    assert 'velocities of row 1 of efforts.csv, positions initial_positions' in out


def test_initial_state_option_takes_the_first_row_of_a_trajectory(tmp_path, capsys):
    src = efforts(tmp_path, {'joint3.position': [1.2] * 3, 'joint3.velocity': [0.5] * 3})
    traj = write_motion(tmp_path / 'traj.csv', np.arange(6) * 0.001, ['joint3'],
                        np.full((6, 1), 1.4), np.full((6, 1), -0.25), np.zeros((6, 1)))
    row, out = first_row(tmp_path, capsys, PARAMS_A, src, '--initial-state', traj)
    assert row['joint3.position'] == 1.4 and row['joint3.velocity'] == -0.25
    assert 'row 1 of traj.csv (velocities given)' in out


def test_an_initial_state_that_does_not_close_is_named(tmp_path, capsys):
    """The redundant parallelogram (b): joint1 and joint3 must agree."""
    src = tmp_path / 'e.csv'
    src.write_text('time,joint1.effort,joint3.effort,joint1.position,joint3.position\n'
                   '0.0,0.0,0.0,1.0,1.6\n0.001,0.0,0.0,1.0,1.6\n')
    status = simulate.main(['--params-file', str(PARAMS_B), '--input', str(src),
                            '--output', str(tmp_path / 'm.csv')])
    err = capsys.readouterr().err
    assert status == 1
    assert 'the initial state (positions of row 1 of e.csv, at rest) cannot be used' in err
    assert not (tmp_path / 'm.csv').exists()


# --- --reference and --plot ------------------------------------------------------------------

def test_reference_prints_the_largest_difference_and_plot_draws_it(tmp_path, capsys):
    name = 'paper_four_bar_a.yaml'
    header, values, mech, q = replay(tmp_path, capsys, name, STEP, 'linear')
    motion = tmp_path / f'motion_{STEP}_linear.csv'
    out, _ = run(capsys, simulate, '--params-file', PARAMS_A, '--input',
                 tmp_path / f'efforts_{STEP}.csv', '--initial-state', tmp_path / f'traj_{STEP}.csv',
                 '--between-rows', 'linear', '--time-step', STEP, '--output', tmp_path / 'm2.csv',
                 '--reference', motion, '--plot', tmp_path / 'm2.png')
    line = next(x for x in out.splitlines() if x.startswith('joint3'))
    assert line.split()[3] == '0' and 'rad' in line       # against itself: 0 rad
    assert (tmp_path / 'm2.png').read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    out, _ = run(capsys, simulate, '--params-file', PARAMS_A, '--input',
                 tmp_path / f'efforts_{STEP}.csv', '--time-step', STEP,
                 '--output', tmp_path / 'm3.csv', '--reference', tmp_path / f'traj_{STEP}.csv')
    line = next(x for x in out.splitlines() if x.startswith('joint3'))
    # from rest instead of the motion's initial velocity: off by about v0 * T
    assert float(line.split()[3]) == pytest.approx(np.pi / 2 * HORIZON, rel=0.2)


# --- Ctrl-C ----------------------------------------------------------------------------------

def test_a_stop_signal_leaves_no_output_file(tmp_path):
    """A long run (a hanging four-bar swinging freely for 10 minutes of simulated time)
    stopped by SIGINT while its output is being written: exit 130, one line, nothing left."""
    params = tmp_path / 'hanging.yaml'
    with open(PARAMS_A, encoding='utf-8') as f:
        text = f.read()
    assert 'gravity: [0.0, -9.81, 0.0]' in text
    params.write_text(text.replace('gravity: [0.0, -9.81, 0.0]', 'gravity: [0.0, 9.81, 0.0]'))
    src = tmp_path / 'efforts.csv'
    src.write_text('time,joint3.effort\n0.0,0.0\n600.0,0.0\n')
    script = os.path.join(os.path.dirname(sys.executable), 'cog_id_simulate')
    # what this (test) process passes on to its children: a SIGINT ignored or blocked here
    # is ignored or blocked in the tool too (it keeps an ignored one ignored, as under
    # nohup), and the full suite once ran this test so (exit 0, the SIGINT never seen;
    # the culprit among the tests before it not found). The tool is started with SIGINT as
    # a terminal gives it: default action, unblocked
    inherited = (signal.getsignal(signal.SIGINT), signal.pthread_sigmask(signal.SIG_BLOCK, []))
    shim = ('import os, signal, sys; signal.signal(signal.SIGINT, signal.SIG_DFL); '
            'signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT}); '
            'os.execv(sys.argv[1], sys.argv[1:])')
    proc = subprocess.Popen([sys.executable, '-c', shim, script, '--params-file', str(params),
                             '--input', str(src), '--output', 'm.csv', '--plot', 'm.png'],
                            cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None:
            if any(n.endswith('.tmp') for n in os.listdir(tmp_path)):
                break
            time.sleep(0.01)
        time.sleep(0.3)
        assert proc.poll() is None, proc.communicate()
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 130, (err, 'SIGINT here (handler, blocked):', inherited)
    assert err.strip().splitlines()[-1] == \
        'cog_id_simulate: interrupted by SIGINT; no output written'
    assert sorted(os.listdir(tmp_path)) == ['efforts.csv', 'hanging.yaml'] and out == ''
