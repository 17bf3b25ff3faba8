"""cog_id_torques against the reliability issue: wrapped angles and jumps, special output
files, stop signals, values beyond a double, unusable time steps, write errors naming the
user's path, huge positions, and inputs that must never end in a traceback.

Every test runs the console script as a subprocess (helpers from test_cli).
"""
import json
import math
import os
import resource
import signal
import stat
import subprocess
import time

import numpy as np
import pytest
from test_cli import (
    CONFIG,
    PARAMS_A,
    TARGET,
    core_torques,
    error_lines,
    run_tool,
    target,
    tool_command,
    write_csv,
)

from cog_id_ros.offline import samples
from cog_id_ros.offline import trajectory_io as tio

SLIDER_CRANK = CONFIG / 'slider_crank.yaml'


def crank_motion(t):
    """The slider-crank's test motion (config/slider_crank.yaml): 1.6 turns, through +-pi."""
    w = math.pi
    return (0.3 + 5.0 * t + 0.4 * np.sin(w * t), 5.0 + 0.4 * w * np.cos(w * t),
            -0.4 * w * w * np.sin(w * t))


def wrap(theta):
    return np.arctan2(np.sin(theta), np.cos(theta))


def strict_json(text):
    def refuse(name):
        raise ValueError(f'not JSON: {name}')
    return json.loads(text, parse_constant=refuse)


# --- item 11: wrapped angles and jumps -----------------------------------------------------------

def wrapped_crank_files(tmp_path):
    """The slider-crank's crank over 2 s at 1 kHz: true.csv unwrapped, wrapped.csv as an
    encoder in (-pi, pi] reports it, and ref.csv the tool's efforts for the true motion.
    Returns the true angles."""
    t = np.arange(2001) * 1e-3
    theta = crank_motion(t)[0]
    write_csv(tmp_path / 'true.csv', {'time': t, 'crank_joint.position': theta})
    write_csv(tmp_path / 'wrapped.csv', {'time': t, 'crank_joint.position': wrap(theta)})
    ref = run_tool('--params-file', SLIDER_CRANK, '--input', 'true.csv', '--output', 'ref.csv',
                   cwd=tmp_path)
    assert ref.returncode == 0, ref.stderr
    return theta


def test_unwrap_gives_the_torques_of_the_unwrapped_motion(tmp_path):
    """Reliability item 11: --unwrap takes each revolute position as the 2 pi equivalent
    nearest the previous row's, and says how many rows it shifted."""
    theta = wrapped_crank_files(tmp_path)
    proc = run_tool('--params-file', SLIDER_CRANK, '--input', 'wrapped.csv', '--output',
                    'tau.csv', '--unwrap', '--json', cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    s = strict_json(proc.stdout)
    shifted = int(np.count_nonzero(np.abs(wrap(theta) - theta) > 1.0))
    wraps = int(np.count_nonzero(np.abs(np.diff(wrap(theta))) > math.pi))
    assert shifted > 100 and wraps >= 1
    assert s['unwrap'] is True
    assert s['unwrapped'] == {'crank_joint.position': {'rows': shifted, 'wraps': wraps}}
    assert f'{shifted:,} row(s) shifted' in proc.stderr
    _, _, tau = tio.read_efforts(tmp_path / 'tau.csv')
    _, _, expected = tio.read_efforts(tmp_path / 'ref.csv')
    np.testing.assert_allclose(tau, expected, rtol=0, atol=1e-6 * np.max(np.abs(expected)))


def test_a_wrapped_angle_without_unwrap_is_a_bad_row(tmp_path):
    """Reliability item 11: the 2 pi jump of a wrapped encoder stops the run (exit 1) with
    the row and the column, instead of 400,000 N m torques."""
    t = np.arange(2001) * 1e-3
    theta = crank_motion(t)[0]
    write_csv(tmp_path / 'wrapped.csv', {'time': t, 'crank_joint.position': wrap(theta)})
    proc = run_tool('--params-file', SLIDER_CRANK, '--input', 'wrapped.csv', '--output',
                    'tau.csv', cwd=tmp_path)
    assert proc.returncode == 1
    [line] = error_lines(proc)
    row = int(np.argmax(theta > math.pi)) + 1         # the first row past +pi
    assert f"row {row} (line {row + 1} of the file), column 'crank_joint.position': jumps by" in line
    assert '--max-step' in line and '--unwrap' in line
    assert sorted(os.listdir(tmp_path)) == ['wrapped.csv']


def test_skip_invalid_skips_a_jump_with_reason_jump(tmp_path):
    """Reliability item 11: with --skip-invalid a jump is a skipped row (reason 'jump'); the
    next row is compared with the last row that was not a jump."""
    t = np.arange(200) * 1e-3
    theta, dtheta, ddtheta = target(t)
    glitch = theta.copy()
    glitch[57] += 2.0                                   # row 58: one wild encoder reading
    src = write_csv(tmp_path / 'traj.csv', {'time': t, 'joint3.position': glitch,
                                            'joint3.velocity': dtheta,
                                            'joint3.acceleration': ddtheta})
    proc = run_tool('--params-file', PARAMS_A, '--input', src, '--output', 'tau.csv',
                    '--skip-invalid', '--json', cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    s = strict_json(proc.stdout)
    assert s['skipped_rows'] == [58] and s['skipped_reasons'] == {'jump': 1}
    assert s['skipped_row_reasons'] == ['jump'] and s['solved'] == 199
    assert "row 58 (line 59 of the file): column 'joint3.position': jumps by 2.0" in proc.stderr
    assert 'from row 57 (limit 1 rad per row, --max-step)' in proc.stderr
    _, _, tau = tio.read_efforts(tmp_path / 'tau.csv')
    assert np.isnan(tau[57, 0])
    keep = np.arange(200) != 57
    clean = write_csv(tmp_path / 'clean.csv', {'time': t[keep], 'joint3.position': theta[keep],
                                               'joint3.velocity': dtheta[keep],
                                               'joint3.acceleration': ddtheta[keep]})
    _, _, _, ref = core_torques(PARAMS_A, clean)
    np.testing.assert_allclose(tau[keep], ref, rtol=0, atol=1e-9)


def test_max_step_option_sets_the_limit(tmp_path):
    """Reliability item 11: --max-step RAD per row (inf: no limit) is the threshold."""
    t = np.arange(6) * 0.1
    q = np.array([1.5, 1.5, 1.8, 1.8, 1.8, 1.8])        # one step of 0.3 rad
    src = write_csv(tmp_path / 'traj.csv', {'time': t, 'joint3.position': q,
                                            'joint3.velocity': np.zeros(6),
                                            'joint3.acceleration': np.zeros(6)})
    tight = run_tool('--params-file', PARAMS_A, '--input', src, '--output', 'tau.csv',
                     '--max-step', '0.2', cwd=tmp_path)
    assert tight.returncode == 1
    [line] = error_lines(tight)
    assert "row 3 (line 4 of the file), column 'joint3.position': jumps by 0.3 rad" in line
    assert 'limit 0.2 rad per row' in line
    for limit in ('0.5', 'inf'):
        ok = run_tool('--params-file', PARAMS_A, '--input', src, '--output', 'tau.csv',
                      '--max-step', limit, cwd=tmp_path)
        assert ok.returncode == 0, ok.stderr
    bad = run_tool('--params-file', PARAMS_A, '--input', src, '--output', 'tau.csv',
                   '--max-step', '-1', cwd=tmp_path)
    assert bad.returncode == 2 and '--max-step' in bad.stderr and 'Traceback' not in bad.stderr


# --- item 16: special output files ---------------------------------------------------------------

@pytest.mark.parametrize('option, name', [('--output', 'tau.csv'), ('--plot', 'tau.png')])
def test_a_symlinked_output_is_written_through(tmp_path, option, name):
    """Reliability item 16: a symlink is written through (its target replaced atomically),
    the link stays a link."""
    (tmp_path / 'data').mkdir()
    real = tmp_path / 'data' / name
    real.write_text('old')
    os.symlink(os.path.join('data', name), tmp_path / name)
    args = ['--output', 'tau.csv', '--plot', 'tau.png'] if option == '--plot' else \
        ['--output', 'tau.csv']
    proc = run_tool('--params-file', PARAMS_A, '--input', TARGET, *args, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert os.path.islink(tmp_path / name)
    assert real.read_bytes() != b'old' and real.stat().st_size > 1000
    assert sorted(os.listdir(tmp_path / 'data')) == [name]      # no temporary left


@pytest.mark.parametrize('option, name', [('--output', 'tau.csv'), ('--plot', 'tau.png')])
def test_a_fifo_output_is_refused(tmp_path, option, name):
    """Reliability item 16: a FIFO is never replaced by a regular file: exit 2, one line."""
    os.mkfifo(tmp_path / name)
    args = ['--output', 'tau.csv', '--plot', 'tau.png'] if option == '--plot' else \
        ['--output', 'tau.csv']
    proc = run_tool('--params-file', PARAMS_A, '--input', TARGET, *args, cwd=tmp_path)
    assert proc.returncode == 2
    [line] = error_lines(proc)
    assert f'{option} {name}: is a FIFO' in line
    assert stat.S_ISFIFO(os.lstat(tmp_path / name).st_mode)
    assert os.listdir(tmp_path) == [name]


def test_a_symlink_to_a_fifo_is_refused(tmp_path):
    """Reliability item 16: the check follows the link; neither the link nor the FIFO changes."""
    os.mkfifo(tmp_path / 'pipe')
    os.symlink('pipe', tmp_path / 'tau.csv')
    proc = run_tool('--params-file', PARAMS_A, '--input', TARGET, '--output', 'tau.csv',
                    cwd=tmp_path)
    assert proc.returncode == 2
    [line] = error_lines(proc)
    assert '--output tau.csv: is a FIFO' in line
    assert os.path.islink(tmp_path / 'tau.csv') and stat.S_ISFIFO(os.stat(tmp_path / 'pipe').st_mode)


# --- item 17: SIGTERM and SIGHUP during the write ------------------------------------------------

@pytest.mark.parametrize('signame, delay', [('SIGTERM', 0.0), ('SIGTERM', 0.1), ('SIGHUP', 0.05)])
def test_a_stop_signal_during_the_write_leaves_no_temporary_file(tmp_path, signame, delay):
    """Reliability item 17: SIGTERM (or SIGHUP) while the outputs are written (as the
    temporary file appears, or `delay` s later, while the CSV and the plot are written):
    the temporary files are removed, exit 128 + signum, one line on stderr."""
    n = 200_000
    t = np.arange(n) * 1e-3
    theta, dtheta, ddtheta = target(t)
    src = write_csv(tmp_path / 'long.csv', {'time': t, 'joint3.position': theta,
                                            'joint3.velocity': dtheta,
                                            'joint3.acceleration': ddtheta})
    proc = subprocess.Popen(tool_command() + ['--params-file', str(PARAMS_A), '--input', str(src),
                                              '--output', 'tau.csv', '--plot', 'tau.png'],
                            cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    deadline = time.monotonic() + 240
    try:
        while time.monotonic() < deadline and proc.poll() is None:
            if any(name.endswith('.tmp') for name in os.listdir(tmp_path)):
                break
            time.sleep(0.002)
        time.sleep(delay)
        assert proc.poll() is None, 'the run ended before the signal could be sent'
        proc.send_signal(getattr(signal, signame))
        out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    signum = getattr(signal, signame)
    assert proc.returncode == 128 + signum, err
    assert 'Traceback' not in err
    assert err.strip().splitlines()[-1] == \
        f'cog_id_torques: interrupted by {signame}; no output written'
    assert sorted(os.listdir(tmp_path)) == ['long.csv']
    assert out == ''


# --- item 18: values beyond a double in the summary and the JSON ---------------------------------

def _huge_efforts(tmp_path):
    # accelerations of 4e299 rad/s^2 give efforts near 1.7e299 N m (finite); a velocity of
    # 1e20 rad/s makes their power (1.7e319 W) beyond a double
    return write_csv(tmp_path / 'huge.csv', {
        'time': [0.0, 0.1, 0.2], 'joint3.position': [1.0, 1.0, 1.0],
        'joint3.velocity': [1e20, 0.0, 0.0], 'joint3.acceleration': [4e299, 1e299, 0.0]})


def test_rms_of_huge_efforts_is_finite_and_the_json_is_json(tmp_path):
    """Reliability item 18: RMS scaled by the peak (no overflow); --json never writes
    Infinity or NaN: a value beyond a double is null, with a note."""
    src = _huge_efforts(tmp_path)
    proc = run_tool('--params-file', PARAMS_A, '--input', src, '--output', 'tau.csv', '--json',
                    cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert 'Warning' not in proc.stderr
    s = strict_json(proc.stdout)
    [j] = s['joints']
    _, _, tau = tio.read_efforts(tmp_path / 'tau.csv')
    e = tau[:, 0]
    peak = np.max(np.abs(e))
    assert peak > 1e299 and j['peak_effort'] == peak
    assert j['rms_effort'] == pytest.approx(peak * np.sqrt(np.mean((e / peak) ** 2)), rel=1e-12)
    assert j['peak_power'] is None and j['peak_power_row'] == 1
    assert any('peak_power' in note and 'beyond the range of a double' in note
               for note in s['notes'])


def test_text_summary_of_huge_efforts_has_no_inf(tmp_path):
    """Reliability item 18: the table says n/a for a value beyond a double, never inf."""
    src = _huge_efforts(tmp_path)
    proc = run_tool('--params-file', PARAMS_A, '--input', src, '--output', 'tau.csv', cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    row = [line for line in proc.stdout.splitlines() if line.startswith('joint3')][0]
    assert 'inf' not in row and 'n/a' in row and 'e+299 N m' in row
    assert 'Warning' not in proc.stderr


# --- item 20: unusable time steps ----------------------------------------------------------------

@pytest.mark.parametrize('times, words', [
    ([0.0, 1e-300, 2e-300, 3e-300, 4e-300, 5e-300], 'too small'),
    ([0.0, 1e300, 2e300, 3e300, 4e300, 5e300], 'too large'),
])
def test_time_steps_too_small_or_too_large_to_estimate(tmp_path, times, words):
    """Reliability item 20: one line naming row 2 and column 'time' and the usable range;
    no RuntimeWarning, no 'qd is nan'."""
    src = write_csv(tmp_path / 'traj.csv', {'time': times, 'joint3.position': np.full(6, 1.5)})
    proc = run_tool('--params-file', PARAMS_A, '--input', src, '--output', 'tau.csv', cwd=tmp_path)
    assert proc.returncode == 1
    assert 'Warning' not in proc.stderr and 'nan' not in proc.stderr
    [line] = error_lines(proc)
    assert "row 2 (line 3 of the file), column 'time'" in line and words in line
    assert f'{samples.MIN_ESTIMATE_STEP:g} .. {samples.MAX_ESTIMATE_STEP:g} s' in line
    assert sorted(os.listdir(tmp_path)) == ['traj.csv']


# --- item 23: write errors name the user's path --------------------------------------------------

def _limit_file_size(limit):
    def apply():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)     # EFBIG instead of a kill
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    return apply


@pytest.mark.parametrize('option, path, limit', [('--output', 'tau.csv', 100),
                                                 ('--plot', 'tau.png', 5000)])
def test_a_write_error_names_the_users_path(tmp_path, option, path, limit):
    """Reliability item 23: the message names --output or --plot as given, never the
    temporary file; exit 4 and nothing left behind. (Files are limited to `limit` bytes:
    20 rows of efforts take ~800, the plot far more.)"""
    t = np.arange(20) * 0.01
    theta, dtheta, ddtheta = target(t)
    (tmp_path / 'in').mkdir()
    src = write_csv(tmp_path / 'in' / 'traj.csv', {'time': t, 'joint3.position': theta,
                                                   'joint3.velocity': dtheta,
                                                   'joint3.acceleration': ddtheta})
    (tmp_path / 'out').mkdir()
    proc = subprocess.run(tool_command() + ['--params-file', str(PARAMS_A), '--input', str(src),
                                            '--output', 'tau.csv', '--plot', 'tau.png'],
                          cwd=tmp_path / 'out', text=True, capture_output=True, timeout=300,
                          preexec_fn=_limit_file_size(limit))
    assert proc.returncode == 4, proc.stderr
    [line] = error_lines(proc)
    assert f'{option} {path}: cannot write: File too large' in line
    assert '.tmp' not in line
    assert os.listdir(tmp_path / 'out') == []


# --- item 6: huge positions ----------------------------------------------------------------------

@pytest.mark.parametrize('value', [1e6, 1e12, 1e300])
def test_huge_positions_end_quickly_without_a_traceback(tmp_path, value):
    """Reliability item 6: a CSV at 1e6, 1e12 or 1e300 rad finishes within seconds with
    exit 0 or 1 (one line naming row 1 and a column), never a hang or a traceback."""
    src = write_csv(tmp_path / 'far.csv', {'time': [0.0, 0.1, 0.2, 0.3],
                                           'joint3.position': [value] * 4,
                                           'joint3.velocity': [0.0] * 4,
                                           'joint3.acceleration': [0.0] * 4})
    proc = subprocess.run(tool_command() + ['--params-file', str(PARAMS_A), '--input', str(src),
                                            '--output', 'tau.csv'],
                          cwd=tmp_path, text=True, capture_output=True, timeout=30)
    assert 'Traceback' not in proc.stderr
    assert proc.returncode in (0, 1)
    if proc.returncode == 1:
        [line] = error_lines(proc)
        assert "row 1 (line 2 of the file), column(s) 'joint3.position'" in line
    else:
        _, _, tau = tio.read_efforts(tmp_path / 'tau.csv')
        assert np.isfinite(tau).all()


# --- no traceback, a useful line, for odd inputs -------------------------------------------------

def test_a_utf16_file_is_named_as_such(tmp_path):
    """Reliability item 6 (no input misleads): a UTF-16 file says so and how to fix it."""
    src = tmp_path / 'traj.csv'
    src.write_text('time,joint3.position\n0,1\n', encoding='utf-16')
    proc = run_tool('--params-file', PARAMS_A, '--input', src, '--output', 'tau.csv', cwd=tmp_path)
    assert proc.returncode == 1
    [line] = error_lines(proc)
    assert 'UTF-16' in line and 'save it as UTF-8' in line


def test_a_huge_cell_is_quoted_short_and_named_beyond_a_double(tmp_path):
    """Reliability item 6: a 5,000,000-digit number is beyond a double (not 'infinite'),
    and the message quotes 40 characters of it, not 5 MB."""
    src = tmp_path / 'traj.csv'
    src.write_text('time,joint3.position\n0,1\n0.1,' + '1' * 5_000_000 + '\n')
    proc = run_tool('--params-file', PARAMS_A, '--input', src, '--output', 'tau.csv', cwd=tmp_path)
    assert proc.returncode == 1
    [line] = error_lines(proc)
    assert len(line) < 500
    assert "row 2 (line 3 of the file), column 'joint3.position'" in line
    assert 'beyond the range of a double' in line


def test_a_million_ignored_columns_make_one_short_note(tmp_path):
    """Reliability item 6: the note on ignored columns lists ten names and a count."""
    n = 1_000_000
    header = 'time,joint3.position,' + ','.join(f'c{i}' for i in range(n))
    zeros = ','.join(['0'] * n)
    rows = [f'{0.1 * k!r},1.5,{zeros}' for k in range(6)]
    src = tmp_path / 'wide.csv'
    src.write_text(header + '\n' + '\n'.join(rows) + '\n')
    proc = run_tool('--params-file', PARAMS_A, '--input', src, '--output', 'tau.csv', cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[:500]
    assert len(proc.stderr) < 2000
    assert '(999,990 more)' in proc.stderr


def test_a_binary_parameter_file_is_one_line_with_status_3(tmp_path):
    """Reliability item 6: a parameter file that is not text: exit 3, one line, no traceback."""
    params = tmp_path / 'bad.yaml'
    params.write_bytes(b'\xff\xfe\x00\x01binary\xc6\x00')
    proc = run_tool('--params-file', params, '--input', TARGET, '--output', 'tau.csv', cwd=tmp_path)
    assert proc.returncode == 3
    [line] = error_lines(proc)
    assert str(params) in line and 'UTF-8' in line


def test_skipped_jumps_never_feed_estimates_across_a_gap(tmp_path):
    """Reliability item 11: with --skip-invalid and no --unwrap, a wrapped crank skips every
    row until the angle comes back near the last accepted one; the rows solved after that
    gap get derivatives estimated from their own piece of the trajectory, not across the
    gap (which hides a whole turn), so their torques are those of the true motion."""
    theta = wrapped_crank_files(tmp_path)
    proc = run_tool('--params-file', SLIDER_CRANK, '--input', 'wrapped.csv', '--output',
                    'tau.csv', '--skip-invalid', '--json', cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    s = strict_json(proc.stdout)
    assert set(s['skipped_reasons']) == {'jump'} and s['skipped'] > 100
    _, _, tau = tio.read_efforts(tmp_path / 'tau.csv')
    _, _, expected = tio.read_efforts(tmp_path / 'ref.csv')
    solved = ~np.isnan(tau[:, 0])
    later = np.flatnonzero(solved & (np.arange(theta.size) > np.flatnonzero(~solved)[0]))
    assert later.size > 0                     # rows solved after the first gap
    scale = np.max(np.abs(expected))
    np.testing.assert_allclose(tau[solved], expected[solved], rtol=0, atol=1e-6 * scale)


@pytest.mark.parametrize('args, words', [
    (['--output', ''], '--output: the path is empty'),
    (['--output', 'tau.csv', '--plot', ''], '--plot: the path is empty'),
    (['--output', 'nodir/'], '--output nodir/: ends with /'),
    (['--output', 'params.yaml'], '--output params.yaml: is the parameter file'),
])
def test_output_paths_that_cannot_be_meant_are_refused_before_any_work(tmp_path, args, words):
    """Reliability item 16: an empty path (--plot '' used to draw nothing, silently), a
    directory-like path, or the parameter file itself: exit 2 and one line, nothing written."""
    params = tmp_path / 'params.yaml'
    params.write_text(PARAMS_A.read_text())
    proc = run_tool('--params-file', 'params.yaml', '--input', TARGET, *args, cwd=tmp_path)
    assert proc.returncode == 2
    [line] = error_lines(proc)
    assert words in line
    assert os.listdir(tmp_path) == ['params.yaml']
    assert params.read_text() == PARAMS_A.read_text()


def test_times_near_the_largest_double_still_give_a_plot(tmp_path):
    """Reliability item 20 (and 6): times of 1e308 s overflowed matplotlib's tick
    computation ('arange: cannot compute length', no output at all); the plot is then
    drawn against the row number."""
    src = write_csv(tmp_path / 'traj.csv', {'time': [1e308, 1.7e308], 'joint3.position': [1.0, 1.0],
                                            'joint3.velocity': [0.0, 0.0],
                                            'joint3.acceleration': [0.0, 0.0]})
    proc = run_tool('--params-file', PARAMS_A, '--input', src, '--output', 'tau.csv', '--plot',
                    'tau.png', cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / 'tau.png').read_bytes()[:4] == b'\x89PNG'
    _, t, tau = tio.read_efforts(tmp_path / 'tau.csv')
    assert t.tolist() == [1e308, 1.7e308] and np.isfinite(tau).all()


def test_torques_beyond_a_double_are_a_bad_row_or_skipped_as_out_of_range(tmp_path):
    """Reliability item 18: a row whose torques would overflow (velocity 1e160 rad/s) is a
    bad row like others: exit 1 naming the row and the column holding the huge value, or
    with --skip-invalid skipped with the core's reason 'out_of_range'; never inf in the file."""
    src = write_csv(tmp_path / 'traj.csv', {'time': [0.0, 0.1, 0.2],
                                            'joint3.position': [1.0, 1.0, 1.0],
                                            'joint3.velocity': [0.0, 1e160, 0.0],
                                            'joint3.acceleration': [0.0, 0.0, 0.0]})
    proc = run_tool('--params-file', PARAMS_A, '--input', src, '--output', 'tau.csv', cwd=tmp_path)
    assert proc.returncode == 1
    [line] = error_lines(proc)
    assert "row 2 (line 3 of the file), column(s) 'joint3.velocity'" in line
    assert not (tmp_path / 'tau.csv').exists()
    proc = run_tool('--params-file', PARAMS_A, '--input', src, '--output', 'tau.csv',
                    '--skip-invalid', '--json', cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    s = strict_json(proc.stdout)
    assert s['skipped_rows'] == [2] and s['skipped_reasons'] == {'out_of_range': 1}
    _, _, tau = tio.read_efforts(tmp_path / 'tau.csv')
    assert np.isnan(tau[1, 0]) and np.isfinite(tau[[0, 2], 0]).all()


def test_a_row_error_raised_in_skip_mode_skips_only_that_row():
    """Reliability item 18: should the core raise a row-level error (with its sample and
    reason) instead of marking the row, --skip-invalid still skips just that row, keyed by
    the error's reason, and solves the rest of the chunk."""
    import cog_id_ros
    from cog_id_ros.offline import solving

    class Evaluation:
        def __init__(self, q):
            self.torques = 2.0 * q
            self.valid = np.ones(len(q), bool)
            self.errors = [None] * len(q)

    class Solver:
        class mechanism:
            active_joints = ['j']

        def evaluate(self, q, qd, qdd, on_invalid):
            bad = np.flatnonzero(q[:, 0] > 100.0)
            if bad.size:
                raise cog_id_ros.SetpointError('too large', sample=int(bad[0]),
                                               reason='out_of_range')
            return Evaluation(q)

    class NoBar:
        def update(self, done):
            pass

        def close(self):
            pass

    q = np.arange(10.0).reshape(10, 1)
    q[[3, 7]] = 1e3
    zeros = np.zeros_like(q)
    efforts, valid, skipped = solving.solve(Solver(), q, zeros, zeros, 4, True, NoBar(), 'f.csv')
    assert [(s.row, s.reason) for s in skipped] == [(4, 'out_of_range'), (8, 'out_of_range')]
    assert valid.tolist() == [i not in (3, 7) for i in range(10)]
    np.testing.assert_array_equal(efforts[valid], 2.0 * q[valid])


def test_help_documents_the_new_options_and_statuses(tmp_path):
    """Reliability items 11, 16, 17, 18, 20: --help names --unwrap and --max-step with their
    defaults and units, special output files, the signal statuses and the estimate range."""
    proc = run_tool('--help', cwd=tmp_path)
    assert proc.returncode == 0
    text = ' '.join(proc.stdout.split())
    for words in ('--unwrap', '--max-step RAD', '--max-step-linear M', 'default 1.0 rad',
                  'default 0.1 m', "reason 'jump'", 'per row, not per second',
                  'a FIFO, device or socket is refused', '143 SIGTERM', '129 SIGHUP',
                  '1e-09 .. 1e+09 s', 'null in the JSON'):
        assert words in text, words


def test_a_closed_or_full_stdout_is_not_an_internal_error(tmp_path):
    """No traceback, no 'internal error' (found by the adversarial test): a closed stdout is
    a closed pipe (141); a full one is a write error (4) after complete outputs."""
    from test_cli import tool_command
    args = tool_command() + ['--params-file', str(PARAMS_A), '--input', str(TARGET),
                             '--output', 'tau.csv', '--json']
    closed = subprocess.run(args, cwd=tmp_path, text=True, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, timeout=300,
                            preexec_fn=lambda: os.close(1))
    assert closed.returncode == 141 and 'Traceback' not in closed.stderr, closed.stderr
    with open('/dev/full', 'w') as full:
        proc = subprocess.run(args, cwd=tmp_path, text=True, stdout=full,
                              stderr=subprocess.PIPE, timeout=300)
    assert proc.returncode == 4 and 'internal error' not in proc.stderr
    assert 'summary cannot be printed' in proc.stderr
    assert (tmp_path / 'tau.csv').exists()


def test_a_usage_mistake_is_one_line():
    """Every refusal is one line: argparse printed its whole usage block before the error."""
    proc = run_tool('--params-file', PARAMS_A, '--input', TARGET, '--output', 'x.csv',
                    '--chunk-size', '0', cwd='/tmp')
    assert proc.returncode == 2
    [line] = proc.stderr.strip().splitlines()
    assert '--chunk-size' in line and '--help' in line


def test_efforts_near_the_largest_double_are_drawn_in_powers_of_ten(tmp_path):
    """Efforts of +-7.5e307 N m made matplotlib fail ('arange: cannot compute length') and
    the run exit 4, after RuntimeWarnings on stderr (found by the adversarial test)."""
    import warnings

    from cog_id_ros.offline import plotting
    efforts = np.array([[7.5e307], [-7.5e307], [1e307]])
    stats = [{'peak_effort': 7.5e307, 'peak_effort_signed': 7.5e307, 'peak_effort_time': 0.0,
              'peak_effort_row': 1, 'rms_effort': 6.2e307}]
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        plotting.plot_efforts(tmp_path / 'p.png', [0.0, 1.0, 2.0], efforts, None, ['joint3'],
                              stats, title='heavy', units=['N m'])
    assert (tmp_path / 'p.png').stat().st_size > 1000
