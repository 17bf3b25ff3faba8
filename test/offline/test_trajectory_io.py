"""CSV trajectories: parsing, every rejection with its row and column, derivative filling,
and atomic writing (cog_id_ros.offline.trajectory_io, samples, jumps, atomic_files; no solver
involved)."""
import os
import stat

import numpy as np
import pytest

from cog_id_ros.offline import atomic_files, derivatives, samples
from cog_id_ros.offline import trajectory_io as tio
from cog_id_ros.offline.jumps import find_jumps, unwrap_positions

JOINTS = ['joint1', 'joint2', 'joint3', 'joint4']
ACTIVE = ['joint3']


def write(tmp_path, text, name='traj.csv', mode='w'):
    path = tmp_path / name
    if mode == 'wb':
        path.write_bytes(text)
    else:
        path.write_text(text, encoding='utf-8', newline='')
    return path


def read(path, active=ACTIVE):
    return tio.read_trajectory(path, JOINTS, active)


GOOD = ('time,joint3.position,joint3.velocity\n'
        '0.0,1.5,0.0\n'
        '0.1,1.6,1.0\n'
        '0.25,1.8,1.5\n')


def test_reads_the_used_columns(tmp_path):
    traj = read(write(tmp_path, GOOD))
    assert len(traj) == 3
    np.testing.assert_array_equal(traj.time, [0.0, 0.1, 0.25])
    assert sorted(traj.columns) == ['joint3.position', 'joint3.velocity']
    np.testing.assert_array_equal(traj.columns['joint3.position'], [1.5, 1.6, 1.8])
    assert traj.notes == []


def test_tolerates_bom_crlf_quotes_spaces_and_trailing_blank_lines(tmp_path):
    text = ('\ufeff"time", "joint3.position"\r\n'
            '0.0 , "1.5"\r\n'
            ' 0.1,1.6\r\n'
            '\r\n\r\n')
    traj = read(write(tmp_path, text))
    np.testing.assert_array_equal(traj.time, [0.0, 0.1])
    np.testing.assert_array_equal(traj.columns['joint3.position'], [1.5, 1.6])


def test_columns_of_inactive_joints_and_other_columns_are_ignored_with_a_note(tmp_path):
    text = ('time,joint1.position,joint3.position,label,joint3.effort\n'
            '0.0,not parsed,1.5,a,\n'
            '0.1,,1.6,"b, with a comma",x\n')
    traj = read(write(tmp_path, text))
    assert sorted(traj.columns) == ['joint3.position']
    assert any('joint1.position' in n and 'not an active joint' in n for n in traj.notes)
    assert any('label' in n and 'joint3.effort' in n for n in traj.notes)


def test_angles_are_not_wrapped(tmp_path):
    traj = read(write(tmp_path, 'time,joint3.position\n0,40.0\n1,-1000.5\n'))
    np.testing.assert_array_equal(traj.columns['joint3.position'], [40.0, -1000.5])


# (file text, row or None for the header, column, words in the message)
BAD = {
    'missing time': ('t,joint3.position\n0,1\n', None, 'time', 'missing column'),
    'missing position': ('time,joint3.velocity\n0,1\n', None, 'joint3.position',
                         "missing column 'joint3.position'"),
    'unknown joint': ('time,joint3.position,jointX.position\n0,1,2\n', None, 'jointX.position',
                      "unknown joint 'jointX'"),
    'unknown joint, velocity': ('time,joint3.position,link1.velocity\n0,1,2\n', None,
                                'link1.velocity', "unknown joint 'link1'"),
    'duplicate column': ('time,joint3.position,joint3.position\n0,1,2\n', None,
                         'joint3.position', 'duplicate column'),
    'non-numeric cell': ('time,joint3.position\n0,1\n0.1,abc\n0.2,1\n', 2, 'joint3.position',
                         "'abc' is not a number"),
    'non-numeric time': ('time,joint3.position\n0,1\n0.1,1\nlater,1\n', 3, 'time',
                         "'later' is not a number"),
    'empty cell': ('time,joint3.position\n0,1\n0.1,\n', 2, 'joint3.position', 'empty cell'),
    'underscore number': ('time,joint3.position\n0,1_0\n', 1, 'joint3.position', 'not a number'),
    'nan': ('time,joint3.position\n0,1\n0.1,1\n0.2,nan\n', 3, 'joint3.position', 'NaN'),
    'nan in an optional column': ('time,joint3.position,joint3.acceleration\n0,1,0\n0.1,1,NaN\n',
                                  2, 'joint3.acceleration', 'NaN'),
    'infinity': ('time,joint3.position\n0,1\n0.1,-inf\n', 2, 'joint3.position', 'infinite'),
    'time repeated': ('time,joint3.position\n0,1\n0.1,1\n0.1,1\n', 3, 'time',
                      'does not increase strictly'),
    'time decreasing': ('time,joint3.position\n0,1\n0.2,1\n0.1,1\n0.3,1\n', 3, 'time',
                        'does not increase strictly'),
    'short row': ('time,joint3.position\n0,1\n0.1\n', 2, None, 'expected 2 cells'),
    'long row': ('time,joint3.position\n0,1\n0.1,1,7\n', 2, None, 'found 3'),
    'long row, quoted file': ('"time",joint3.position\n0,1\n0.1,1,"7"\n', 2, None, 'found 3'),
    'blank line': ('time,joint3.position\n0,1\n\n0.2,1\n', 2, None, 'blank line'),
    'header only': ('time,joint3.position\n', None, None, 'no data rows'),
}


@pytest.mark.parametrize('case', sorted(BAD))
def test_rejections_name_the_row_and_the_column(tmp_path, case):
    text, row, column, words = BAD[case]
    with pytest.raises(tio.TrajectoryError) as info:
        read(write(tmp_path, text))
    err = info.value
    message = str(err)
    assert '\n' not in message
    assert words in message
    assert err.row == row and err.column == column
    if row is not None:
        assert f'row {row} (line {row + 1} of the file)' in message
    elif case != 'header only':
        assert 'header (line 1 of the file)' in message
    if column is not None:
        assert f"column '{column}'" in message
    assert message.startswith(str(tmp_path / 'traj.csv') + ': ')


def test_empty_file_and_bad_encoding(tmp_path):
    with pytest.raises(tio.TrajectoryError, match='empty'):
        read(write(tmp_path, ''))
    with pytest.raises(tio.TrajectoryError, match=r'row 2 \(line 3 of the file\): not UTF-8'):
        read(write(tmp_path, b'time,joint3.position\n0,1\n0.1,\xff\n', mode='wb'))


def test_the_first_problem_in_file_order_is_reported(tmp_path):
    text = 'time,joint3.position\n' + ''.join(f'{k},1\n' for k in range(500)) + '500,x\n501,y\n'
    with pytest.raises(tio.TrajectoryError, match=r"row 501 \(line 502 of the file\), column 'joint3.position': 'x'"):
        read(write(tmp_path, text))


def test_setpoints_estimate_what_is_absent(tmp_path):
    t = np.linspace(0.0, 1.0, 41) ** 1.2             # uneven steps
    q = np.sin(2.0 * t)
    v = 2.0 * np.cos(2.0 * t)
    rows = '\n'.join(f'{a!r},{b!r},{c!r}' for a, b, c in zip(t.tolist(), q.tolist(), v.tolist()))
    # positions only: velocity and acceleration both from the positions
    traj = read(write(tmp_path, 'time,joint3.position\n' + '\n'.join(
        f'{a!r},{b!r}' for a, b in zip(t.tolist(), q.tolist())) + '\n', name='p.csv'))
    pos, vel, acc, est = samples.setpoints(traj, ACTIVE)
    assert est == ['joint3.velocity', 'joint3.acceleration']
    np.testing.assert_array_equal(vel[:, 0], derivatives.first_derivative(t, q))
    np.testing.assert_array_equal(acc[:, 0], derivatives.second_derivative(t, q))
    # velocity given: the acceleration is its derivative
    traj = read(write(tmp_path, 'time,joint3.position,joint3.velocity\n' + rows + '\n', name='pv.csv'))
    pos, vel, acc, est = samples.setpoints(traj, ACTIVE)
    assert est == ['joint3.acceleration']
    np.testing.assert_array_equal(vel[:, 0], v)
    np.testing.assert_array_equal(acc[:, 0], derivatives.first_derivative(t, v))
    np.testing.assert_allclose(acc[:, 0], -4.0 * np.sin(2.0 * t), atol=2e-3)


def test_setpoints_use_given_columns_verbatim_and_order_joints_as_active(tmp_path):
    text = ('time,joint3.acceleration,joint1.position,joint3.position,joint3.velocity,'
            'joint1.velocity,joint1.acceleration\n'
            '0,0.5,1.0,2.0,0.25,0.125,0.0625\n')
    traj = read(write(tmp_path, text), active=['joint3', 'joint1'])
    q, qd, qdd, est = samples.setpoints(traj, ['joint3', 'joint1'])
    assert est == []
    assert q.tolist() == [[2.0, 1.0]]
    assert qd.tolist() == [[0.25, 0.125]]
    assert qdd.tolist() == [[0.5, 0.0625]]


def test_estimating_needs_five_rows_and_says_which_column(tmp_path):
    traj = read(write(tmp_path, 'time,joint3.position,joint3.velocity\n0,1,0\n1,1,0\n2,1,0\n'))
    with pytest.raises(tio.TrajectoryError, match="column 'joint3.acceleration': absent.*at least 5 rows"):
        samples.setpoints(traj, ACTIVE)


def test_efforts_round_trip_at_full_precision_with_empty_skipped_cells(tmp_path):
    rng = np.random.default_rng(1)
    time = np.cumsum(rng.random(250))
    efforts = rng.normal(size=(250, 2)) * 10.0 ** rng.integers(-12, 12, size=(250, 2))
    valid = np.ones(250, bool)
    valid[[3, 100, 249]] = False
    out = tmp_path / 'out.csv'
    tio.write_efforts(out, time, efforts, valid, ['joint1', 'joint3'])
    lines = out.read_text().splitlines()
    assert lines[0] == 'time,joint1.effort,joint3.effort'
    assert lines[4] == f'{float(time[3])!r},,'
    header, t, e = tio.read_efforts(out)
    np.testing.assert_array_equal(t, time)
    np.testing.assert_array_equal(e[valid], efforts[valid])
    assert np.isnan(e[~valid]).all()


def test_atomic_output_leaves_nothing_on_failure_and_keeps_an_old_file(tmp_path):
    out = tmp_path / 'out.csv'
    with pytest.raises(RuntimeError):
        with atomic_files.atomic_output(out) as tmp:
            with open(tmp, 'w') as f:
                f.write('partial')
            raise RuntimeError('boom')
    assert os.listdir(tmp_path) == []
    out.write_text('old')
    with pytest.raises(RuntimeError):
        with atomic_files.atomic_output(out) as tmp:
            raise RuntimeError('boom')
    assert out.read_text() == 'old'
    assert os.listdir(tmp_path) == ['out.csv']


def test_atomic_output_replaces_and_honours_the_umask(tmp_path):
    out = tmp_path / 'out.csv'
    out.write_text('old')
    old_mask = os.umask(0o022)
    try:
        with atomic_files.atomic_output(out) as tmp:
            with open(tmp, 'w') as f:
                f.write('new')
    finally:
        os.umask(old_mask)
    assert out.read_text() == 'new'
    assert stat.S_IMODE(out.stat().st_mode) == 0o644
    assert os.listdir(tmp_path) == ['out.csv']


def test_first_problem_in_file_order_whatever_its_kind(tmp_path):
    # a NaN before a non-numeric cell is reported first, quoted file or not
    for quote in ('', '"'):
        text = f'{quote}time{quote},joint3.position\n0,1\n0.1,nan\n0.2,abc\n'
        with pytest.raises(tio.TrajectoryError, match=r"row 2 .*'joint3.position': NaN"):
            read(write(tmp_path, text))


def test_find_jumps_compares_with_the_last_accepted_row():
    """Reliability item 11: a jump beyond the per-row limit of its column is reported with
    its row (1-based), column, step and reference row; after a jump, rows are compared with
    the last row that was not one (one wild row is one jump, a lasting offset is many)."""
    q = np.array([[1.0, 0.00], [1.1, 0.00], [7.4, 0.00], [1.2, 0.00], [1.3, 0.50],
                  [1.3, 0.55], [1.3, 0.60]])
    jumps = find_jumps(q, [0.5, 0.1])
    assert [(row, k, ref) for row, k, _, ref in jumps] == [(3, 0, 2), (5, 1, 4), (6, 1, 4),
                                                           (7, 1, 4)]
    assert jumps[0][2] == pytest.approx(6.3) and jumps[1][2] == pytest.approx(0.5)
    assert find_jumps(q, [np.inf, np.inf]) == []


def test_unwrap_positions_takes_the_nearest_2pi_equivalent(tmp_path):
    """Reliability item 11: each unwrapped angle is the 2 pi equivalent nearest the previous
    row's; other columns are untouched; returns (rows shifted, wraps) per column."""
    theta = 2.8 + 0.2 * np.arange(12)                 # passes +pi at row 3
    wrapped = np.arctan2(np.sin(theta), np.cos(theta))
    text = 'time,joint3.position,joint1.position\n' + ''.join(
        f'{0.1 * k!r},{w!r},{w!r}\n' for k, w in enumerate(wrapped.tolist()))
    traj = read(write(tmp_path, text), active=['joint1', 'joint3'])
    counts = unwrap_positions(traj, ['joint3'])
    assert counts == {'joint3.position': (10, 1)}
    np.testing.assert_allclose(traj.columns['joint3.position'], theta, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(traj.columns['joint1.position'], wrapped)


def test_output_target_follows_links_and_refuses_special_files(tmp_path):
    """Reliability item 16: atomic_output writes through a symlink (the link stays) and
    never replaces a FIFO by a regular file."""
    (tmp_path / 'real.csv').write_text('old')
    os.symlink('real.csv', tmp_path / 'link.csv')
    with atomic_files.atomic_output(tmp_path / 'link.csv') as tmp:
        with open(tmp, 'w') as f:
            f.write('new')
    assert os.path.islink(tmp_path / 'link.csv')
    assert (tmp_path / 'real.csv').read_text() == 'new'
    os.mkfifo(tmp_path / 'pipe')
    with pytest.raises(atomic_files.OutputPathError, match='FIFO'):
        with atomic_files.atomic_output(tmp_path / 'pipe'):
            pass
    assert stat.S_ISFIFO(os.lstat(tmp_path / 'pipe').st_mode)
    assert sorted(os.listdir(tmp_path)) == ['link.csv', 'pipe', 'real.csv']


@pytest.mark.parametrize('step, words', [(1e-300, 'too small'), (1e12, 'too large')])
def test_setpoints_refuse_time_steps_outside_the_estimate_range(tmp_path, step, words):
    """Reliability item 20: the row after the step and the column 'time' are named, with the
    usable range; no floating-point warning."""
    text = 'time,joint3.position\n' + ''.join(f'{k * step!r},1.5\n' for k in range(6))
    traj = read(write(tmp_path, text))
    with np.errstate(all='raise'):
        with pytest.raises(tio.TrajectoryError, match=words) as info:
            samples.setpoints(traj, ACTIVE)
    assert info.value.row == 2 and info.value.column == 'time'
    assert f'{samples.MIN_ESTIMATE_STEP:g} .. {samples.MAX_ESTIMATE_STEP:g} s' in str(info.value)


def test_setpoints_name_the_row_where_an_estimate_overflows(tmp_path):
    """Reliability item 20: an estimate beyond the range of a double names its row and the
    position column instead of passing inf or NaN on."""
    q = [0.0, 0.0, 0.0, 1e300, -1e300, 0.0, 0.0, 0.0]
    text = 'time,joint3.position\n' + ''.join(f'{k * 1e-8!r},{v!r}\n' for k, v in enumerate(q))
    traj = read(write(tmp_path, text))
    with np.errstate(all='raise'):
        with pytest.raises(tio.TrajectoryError, match='beyond the range of a double') as info:
            samples.setpoints(traj, ACTIVE)
    assert info.value.column == 'joint3.position' and info.value.row is not None


def test_a_non_ascii_digit_is_named_as_not_a_number(tmp_path):
    """Reliability item 6 (no input misleads): a full-width digit (read by Python's float,
    not by numpy) is named with its row and column, not as numpy's 'cannot parse'."""
    text = 'time,joint3.position\n0,1\n0.1,\uff11\n0.2,1\n'
    with pytest.raises(tio.TrajectoryError) as info:
        read(write(tmp_path, text))
    assert info.value.row == 2 and info.value.column == 'joint3.position'
    assert "'\uff11' is not a number" in str(info.value)


def test_any_joint_name_round_trips_through_the_csv_files(tmp_path):
    """Issue 23: a joint name is any name ('/', a leading digit, ',', '"', non-ASCII); the
    output header quotes what CSV needs quoted, and an input header read back finds the
    joints by their names."""
    odd = ['motor/1', '2nd,arm "left"', 'pivot_\u00e4']
    text = ''.join(tio.format_efforts(np.array([0.0, 0.1]), np.ones((2, 3)), None, odd))
    path = write(tmp_path, text, 'efforts.csv')
    header, _, efforts = tio.read_efforts(path)
    assert header == ['time'] + [f'{name}.effort' for name in odd]
    assert efforts.shape == (2, 3)
    traj = tio.read_trajectory(write(tmp_path, text.replace('.effort', '.position')), odd, odd)
    np.testing.assert_array_equal(traj.columns['2nd,arm "left".position'], [1.0, 1.0])
