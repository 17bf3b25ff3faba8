"""cog_id_torques on a floating-base robot (docs/cli.md, "Floating base"): the base's columns
in, the efforts, the contacts' wrenches and the base wrench out, equal to
``InverseDynamics.whole_body_torques`` on the same samples; at rest the feet carry the
weight; the base's absent rates estimated to the stencils' order; --contacts and the base
columns refused where they cannot be honoured, with the exit statuses of the tool.
"""
import json
import math
from pathlib import Path

import numpy as np
import pytest

import cog_id_ros
from cog_id_ros.offline import base_samples, cli, plotting
from cog_id_ros.offline import trajectory_io as tio

ROOT = Path(__file__).resolve().parents[2]
BIPED = ROOT / 'config' / 'digit_biped.yaml'
FOUR_BAR = ROOT / 'config' / 'paper_four_bar_a.yaml'
FOUR_BAR_TARGET = ROOT / 'config' / 'paper_four_bar_target.csv'
POSE, VELOCITY, ACCELERATION = (base_samples.POSE, base_samples.VELOCITY,
                                base_samples.ACCELERATION)
WRENCH = ('fx', 'fy', 'fz', 'mx', 'my', 'mz')


@pytest.fixture(scope='module')
def biped():
    return cog_id_ros.Mechanism.from_params_file(str(BIPED))


def assembled(mech):
    return np.array([mech.assembled_positions[j] for j in mech.active_index])


def quaternion_x(angle):
    """(N, 4) quaternions (qx, qy, qz, qw) of rotations by ``angle`` (N,) about x."""
    zero = np.zeros_like(angle)
    return np.column_stack([np.sin(angle / 2), zero, zero, np.cos(angle / 2)])


def rotation_x(angle):
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def motion(mech, t):
    """A small sway at 1 Hz: the motors about their assembled pose, the base 0.67 m up,
    tilted about x by 0.05 + 0.02 sin(2 pi t) rad and moving; every rate exact.
    Returns (theta, theta_dot, theta_ddot, base_pose, base_velocity, base_acceleration)."""
    w = 2.0 * math.pi
    s, c = np.sin(w * t), np.cos(w * t)
    scale = np.linspace(0.5, 1.0, len(mech.active_joints))
    theta = assembled(mech) + 0.02 * s[:, None] * scale
    theta_dot = 0.02 * w * c[:, None] * scale
    theta_ddot = -0.02 * w * w * s[:, None] * scale
    a, da, dda = 0.05 + 0.02 * s, 0.02 * w * c, -0.02 * w * w * s
    p = np.column_stack([0.01 * t, 0.005 * s, 0.67 + 0.0 * t])
    dp = np.column_stack([0.01 + 0.0 * t, 0.005 * w * c, 0.0 * t])
    ddp = np.column_stack([0.0 * t, -0.005 * w * w * s, 0.0 * t])
    pose = np.hstack([p, quaternion_x(a)])
    v = np.array([rotation_x(ai).T @ dpi for ai, dpi in zip(a, dp)])
    omega = np.column_stack([da, 0.0 * t, 0.0 * t])
    # d/dt (R^T p') = R^T p'' + (dR^T/dt) p', dR^T/dt = -da [x]_x R^T about x
    dv = np.array([rotation_x(ai).T @ ddpi for ai, ddpi in zip(a, ddp)]) - np.cross(omega, v)
    domega = np.column_stack([dda, 0.0 * t, 0.0 * t])
    return (theta, theta_dot, theta_ddot, pose, np.hstack([v, omega]),
            np.hstack([dv, domega]))


def write_csv(path, columns):
    names = list(columns)
    cells = [list(map(repr, np.asarray(columns[n], dtype=float).tolist())) for n in names]
    path.write_text(','.join(names) + '\n' + '\n'.join(map(','.join, zip(*cells))) + '\n')
    return path


def biped_csv(path, mech, t, theta, pose, theta_rates=None, base_rates=None):
    """The trajectory file: positions always; ``theta_rates`` (theta_dot, theta_ddot) and
    ``base_rates`` (velocity, acceleration) as columns when given."""
    columns = {'time': t}
    for k, joint in enumerate(mech.active_joints):
        columns[f'{joint}.position'] = theta[:, k]
        if theta_rates is not None:
            columns[f'{joint}.velocity'] = theta_rates[0][:, k]
            columns[f'{joint}.acceleration'] = theta_rates[1][:, k]
    groups = [(POSE, pose)] + ([] if base_rates is None else
                               [(VELOCITY, base_rates[0]), (ACCELERATION, base_rates[1])])
    for names, values in groups:
        for k, name in enumerate(names):
            columns[name] = values[:, k]
    return write_csv(path, columns)


def run_torques(capsys, *args):
    status = cli.main([str(a) for a in args])
    out, err = capsys.readouterr()
    assert 'Traceback' not in err
    return status, out, err


def error_lines(err):
    return [line for line in err.splitlines() if line.startswith('cog_id_torques: error:')]


def expected_header(mech, contacts):
    return (['time'] + [f'{j}.effort' for j in mech.active_joints]
            + [f'{c}.{f}' for c in contacts for f in WRENCH[:mech.contacts[c].size]]
            + [f'base_wrench.{f}' for f in WRENCH])


# --- results ---------------------------------------------------------------------------------

@pytest.mark.parametrize('option, contacts', [
    ((), ['right_foot', 'left_foot']),
    (('--contacts', 'left_foot'), ['left_foot']),
    (('--contacts', 'left_foot,right_foot'), ['left_foot', 'right_foot']),
    (('--contacts', 'none'), []),
], ids=['default-all', 'one-foot', 'reordered', 'none'])
def test_columns_equal_whole_body_torques(tmp_path, capsys, biped, option, contacts):
    t = np.linspace(0.0, 0.06, 7)
    theta, thd, thdd, pose, vel, acc = motion(biped, t)
    src = biped_csv(tmp_path / 'walk.csv', biped, t, theta, pose, (thd, thdd), (vel, acc))
    out = tmp_path / 'torques.csv'
    status, stdout, err = run_torques(capsys, '--params-file', BIPED, '--input', src,
                                      '--output', out, '--json', *option)
    assert status == 0, err
    assert json.loads(stdout)['contacts'] == contacts
    header, time, values = tio.read_efforts(out)
    assert header == expected_header(biped, contacts)
    np.testing.assert_array_equal(time, t)
    ref = cog_id_ros.InverseDynamics(biped).whole_body_torques(
        pose, vel, acc, theta, thd, thdd, contacts=contacts)
    m = len(biped.active_joints)
    np.testing.assert_array_equal(values[:, :m], ref.efforts)       # same samples, same numbers
    start = m
    for name in contacts:
        size = biped.contacts[name].size
        np.testing.assert_array_equal(values[:, start:start + size], ref.wrenches[name])
        start += size
    np.testing.assert_array_equal(values[:, start:], ref.base_wrench)
    # the numbers are the motion's: the base wrench is zero only when feet balance it
    no_feet = np.abs(values[:, -6:]).max()
    assert (no_feet > 100.0) if not contacts else (no_feet < 1e-6)


def test_at_rest_the_feet_carry_the_weight(tmp_path, capsys, biped):
    """Positions only (every rate estimated: exactly zero at rest): the feet's vertical
    forces add up to the weight, nothing else is left; without contacts the base wrench is
    the weight, in the base frame."""
    n, tilt = 6, 0.04
    t = np.arange(n) * 0.01
    theta = np.tile(assembled(biped) + 0.01, (n, 1))
    pose = np.tile(np.r_[0.0, 0.0, 0.67, quaternion_x(np.array([tilt]))[0]], (n, 1))
    src = biped_csv(tmp_path / 'rest.csv', biped, t, theta, pose)
    weight = (sum(biped.link_mass) + biped.base_mass) * -biped.gravity[2]
    assert weight > 190.0                       # the biped's 19.8 kg
    status, _, err = run_torques(capsys, '--params-file', BIPED, '--input', src,
                                 '--output', tmp_path / 'both.csv')
    assert status == 0, err
    assert 'base.vx' in err and 'base.dwz' in err           # the estimate is noted
    header, _, values = tio.read_efforts(tmp_path / 'both.csv')
    col = {name: values[:, k] for k, name in enumerate(header[1:])}
    np.testing.assert_allclose(col['right_foot.fz'] + col['left_foot.fz'], weight, rtol=1e-9)
    for f in ('fx', 'fy'):
        np.testing.assert_allclose(col[f'right_foot.{f}'] + col[f'left_foot.{f}'], 0.0,
                                   atol=1e-9)
    assert min(col['right_foot.fz'].min(), col['left_foot.fz'].min()) > 0.3 * weight
    np.testing.assert_allclose(values[:, -6:], 0.0, atol=1e-9)
    status, _, err = run_torques(capsys, '--params-file', BIPED, '--input', src,
                                 '--output', tmp_path / 'none.csv', '--contacts', 'none')
    assert status == 0, err
    _, _, values = tio.read_efforts(tmp_path / 'none.csv')
    held = rotation_x(tilt).T @ np.array([0.0, 0.0, weight])      # world holds it up
    np.testing.assert_allclose(values[:, -6:-3], np.tile(held, (n, 1)), rtol=0, atol=1e-9)


def test_estimated_base_rates_have_the_stencils_order():
    """base_samples.estimate on a tumbling, moving base (rotation about z then the body x,
    the quaternion's sign flipped every third row): velocity O(h^4), acceleration O(h^3)
    against the exact ones; from given velocities, the acceleration is their derivative."""
    def exact(t):
        a, da, dda = 0.4 * np.sin(t), 0.4 * np.cos(t), -0.4 * np.sin(t)
        b, db, ddb = 0.3 * np.sin(2 * t) + 0.1, 0.6 * np.cos(2 * t), -1.2 * np.sin(2 * t)
        qz = np.column_stack([0 * t, 0 * t, np.sin(a / 2), np.cos(a / 2)])
        qx = quaternion_x(b)
        q = np.column_stack([qz[:, 3] * qx[:, 0], qz[:, 2] * qx[:, 0], qz[:, 2] * qx[:, 3],
                             qz[:, 3] * qx[:, 3]])            # qz * qx
        p = np.column_stack([0.1 * np.sin(t), 0.05 * t * t, 0.67 + 0.02 * np.cos(2 * t)])
        dp = np.column_stack([0.1 * np.cos(t), 0.1 * t, -0.04 * np.sin(2 * t)])
        rz = [np.array([[math.cos(x), -math.sin(x), 0], [math.sin(x), math.cos(x), 0],
                        [0, 0, 1]]) for x in a]
        v = np.array([(r @ rotation_x(x)).T @ d for r, x, d in zip(rz, b, dp)])
        w = np.column_stack([db, da * np.sin(b), da * np.cos(b)])
        dw = np.column_stack([ddb, dda * np.sin(b) + da * db * np.cos(b),
                              dda * np.cos(b) - da * db * np.sin(b)])
        return np.hstack([p, q]), np.hstack([v, w]), dw

    errors = []
    for h in (0.02, 0.01, 0.005):
        t = np.arange(0.0, 1.0 + h / 2, h)
        pose, twist, dw = exact(t)
        e = 1e-5
        dv = (exact(t + e)[1][:, :3] - exact(t - e)[1][:, :3]) / (2 * e)
        flipped = pose.copy()
        flipped[::3, 3:] *= -1.0
        vel, acc = base_samples.estimate(t, flipped, None, None)
        _, acc_from_v = base_samples.estimate(t, flipped, twist, None)
        errors.append([np.abs(vel - twist).max(), np.abs(acc[:, :3] - dv).max(),
                       np.abs(acc[:, 3:] - dw).max(),
                       np.abs(acc_from_v - np.hstack([dv, dw])).max()])
    errors = np.array(errors)
    assert errors[0, 0] < 1e-5 and errors[0, 2] < 1e-3
    orders = np.log2(errors[:-1] / errors[1:])
    assert (orders[:, 0] > 3.7).all(), orders           # O(h^4)
    assert (orders[:, 1:3] > 2.7).all(), orders         # O(h^3)
    assert (orders[:, 3] > 3.7).all(), orders           # from velocities: O(h^4)


def test_estimated_base_rates_give_the_torques_of_the_exact_ones(tmp_path, capsys, biped):
    t = np.linspace(0.0, 0.1, 21)
    theta, thd, thdd, pose, vel, acc = motion(biped, t)
    exact = biped_csv(tmp_path / 'exact.csv', biped, t, theta, pose, (thd, thdd), (vel, acc))
    bare = biped_csv(tmp_path / 'bare.csv', biped, t, theta, pose, (thd, thdd))
    for src in (exact, bare):
        status, _, err = run_torques(capsys, '--params-file', BIPED, '--input', src,
                                     '--output', src.with_suffix('.out'))
        assert status == 0, err
    _, _, a = tio.read_efforts(exact.with_suffix('.out'))
    _, _, b = tio.read_efforts(bare.with_suffix('.out'))
    assert 0.0 < np.abs(a - b).max() < 1e-3 * np.abs(a).max()


def test_skipped_row_leaves_every_column_empty(tmp_path, capsys, biped):
    t = np.linspace(0.0, 0.06, 7)
    theta, thd, thdd, pose, vel, acc = motion(biped, t)
    theta[3, biped.active_joints.index('motor_knee')] = 2.5       # the loops cannot close
    src = biped_csv(tmp_path / 'bad.csv', biped, t, theta, pose, (thd, thdd), (vel, acc))
    status, _, err = run_torques(capsys, '--params-file', BIPED, '--input', src,
                                 '--output', tmp_path / 'x.csv', '--max-step', 'inf')
    assert status == 1 and not (tmp_path / 'x.csv').exists()
    assert 'row 4 (line 5 of the file)' in error_lines(err)[0]
    status, _, err = run_torques(capsys, '--params-file', BIPED, '--input', src,
                                 '--output', tmp_path / 'x.csv', '--max-step', 'inf',
                                 '--skip-invalid')
    assert status == 0, err
    _, _, values = tio.read_efforts(tmp_path / 'x.csv')
    assert np.isnan(values[3]).all() and np.isfinite(np.delete(values, 3, axis=0)).all()
    keep = np.arange(7) != 3
    ref = cog_id_ros.InverseDynamics(biped).whole_body_torques(
        pose[keep], vel[keep], acc[keep], theta[keep], thd[keep], thdd[keep])
    np.testing.assert_allclose(values[keep, :len(biped.active_joints)], ref.efforts,
                               rtol=0, atol=1e-9)


def test_a_base_value_out_of_range_is_named(tmp_path, capsys, biped):
    t = np.linspace(0.0, 0.06, 7)
    theta, thd, thdd, pose, vel, acc = motion(biped, t)
    acc[2, 0] = 1e307
    src = biped_csv(tmp_path / 'huge.csv', biped, t, theta, pose, (thd, thdd), (vel, acc))
    status, _, err = run_torques(capsys, '--params-file', BIPED, '--input', src,
                                 '--output', tmp_path / 'x.csv')
    assert status == 1
    line, = error_lines(err)
    assert "row 3 (line 4 of the file), column(s) 'base.dvx'" in line


def test_plot_shows_the_contacts_vertical_forces(tmp_path, capsys, biped, monkeypatch):
    pytest.importorskip('matplotlib')
    seen = {}
    draw = plotting.plot_efforts

    def spy(*args, **kwargs):
        seen.update(efforts=np.array(args[2]), forces=kwargs.get('forces'))
        return draw(*args, **kwargs)

    monkeypatch.setattr(plotting, 'plot_efforts', spy)
    t = np.linspace(0.0, 0.06, 7)
    theta, thd, thdd, pose, vel, acc = motion(biped, t)
    src = biped_csv(tmp_path / 'walk.csv', biped, t, theta, pose, (thd, thdd), (vel, acc))
    status, _, err = run_torques(capsys, '--params-file', BIPED, '--input', src,
                                 '--output', tmp_path / 'x.csv', '--plot', tmp_path / 'x.png')
    assert status == 0, err
    assert (tmp_path / 'x.png').stat().st_size > 10_000
    header, _, values = tio.read_efforts(tmp_path / 'x.csv')
    assert seen['efforts'].shape == (7, len(biped.active_joints))
    assert list(seen['forces']) == ['right_foot', 'left_foot']
    for name, fz in seen['forces'].items():
        np.testing.assert_array_equal(fz, values[:, header.index(f'{name}.fz') - 1])


# --- refusals --------------------------------------------------------------------------------

@pytest.mark.parametrize('option, says', [
    ('right_foot,nose', "'nose' is not a contact of digit_biped"),
    ('left_foot,left_foot', "'left_foot' twice"),
    ('right_foot,', 'an empty name'),
], ids=['unknown', 'twice', 'empty'])
def test_contacts_option_errors(tmp_path, capsys, biped, option, says):
    t = np.linspace(0.0, 0.06, 7)
    theta, _, _, pose, _, _ = motion(biped, t)
    src = biped_csv(tmp_path / 'walk.csv', biped, t, theta, pose)
    status, _, err = run_torques(capsys, '--params-file', BIPED, '--input', src,
                                 '--output', tmp_path / 'x.csv', '--contacts', option)
    assert status == 2 and not (tmp_path / 'x.csv').exists()
    line, = err.strip().splitlines()
    assert says in line and 'right_foot, left_foot' in line


def test_a_fixed_base_refuses_contacts_and_base_columns(tmp_path, capsys):
    status, _, err = run_torques(capsys, '--params-file', FOUR_BAR, '--input', FOUR_BAR_TARGET,
                                 '--output', tmp_path / 'x.csv', '--contacts', 'none')
    assert status == 2 and not (tmp_path / 'x.csv').exists()
    line, = err.strip().splitlines()
    assert 'fixed base' in line and 'mechanism.floating_base' in line and '--contacts' in line
    text = FOUR_BAR_TARGET.read_text().splitlines()
    src = tmp_path / 'with_base.csv'
    src.write_text('\n'.join([text[0] + ',base.z'] + [row + ',0.5' for row in text[1:]]) + '\n')
    status, _, err = run_torques(capsys, '--params-file', FOUR_BAR, '--input', src,
                                 '--output', tmp_path / 'x.csv')
    assert status == 1 and not (tmp_path / 'x.csv').exists()
    line, = error_lines(err)
    assert "column 'base.z'" in line and 'fixed base' in line


def test_space_joint_is_refused_for_a_floating_base(tmp_path, capsys, biped):
    t = np.linspace(0.0, 0.06, 7)
    theta, _, _, pose, _, _ = motion(biped, t)
    src = biped_csv(tmp_path / 'walk.csv', biped, t, theta, pose)
    status, _, err = run_torques(capsys, '--params-file', BIPED, '--input', src,
                                 '--output', tmp_path / 'x.csv', '--space', 'joint')
    assert status == 2 and '--space joint' in error_lines(err)[0]


def _edit(src, dst, header=None, drop=(), cell=None):
    """A copy of the CSV ``src``: header names replaced ({old: new}), columns dropped, one
    cell (row, column name, text) replaced."""
    rows = [line.split(',') for line in src.read_text().splitlines()]
    names = rows[0]
    if cell is not None:
        rows[cell[0]][names.index(cell[1])] = cell[2]
    keep = [k for k, name in enumerate(names) if name not in drop]
    rows[0] = [(header or {}).get(name, name) for name in names]
    dst.write_text('\n'.join(','.join(row[k] for k in keep) for row in rows) + '\n')
    return dst


@pytest.mark.parametrize('edit, says', [
    (dict(drop=('base.qw',)), "column 'base.qw': missing column 'base.qw'"),
    (dict(drop=('base.wz',)), "missing column 'base.wz': the base velocity columns come six"),
    (dict(drop=('base.dvy',)), "missing column 'base.dvy': the base acceleration columns"),
    (dict(header={'base.wz': 'base.wzz'}), "unknown base column 'base.wzz'"),
    (dict(cell=(3, 'base.qw', '0.9')), 'row 3 (line 4 of the file)'),
], ids=['no-qw', 'five-velocities', 'five-accelerations', 'typo', 'not-unit'])
def test_base_column_errors(tmp_path, capsys, biped, edit, says):
    t = np.linspace(0.0, 0.06, 7)
    theta, thd, thdd, pose, vel, acc = motion(biped, t)
    good = biped_csv(tmp_path / 'good.csv', biped, t, theta, pose, (thd, thdd), (vel, acc))
    src = _edit(good, tmp_path / 'bad.csv', **edit)
    status, _, err = run_torques(capsys, '--params-file', BIPED, '--input', src,
                                 '--output', tmp_path / 'x.csv')
    assert status == 1 and not (tmp_path / 'x.csv').exists()
    line, = error_lines(err)
    assert says in line, line
    status, _, err = run_torques(capsys, '--params-file', BIPED, '--input', good,
                                 '--output', tmp_path / 'x.csv')
    assert status == 0, err                     # the same file unedited is fine
